"""Validated sampled-data model of an ODE: Taylor map of the flow with a proven remainder.

For ``dx/dt = F(x, p)`` with ``p = (u, w)`` held constant over the sample (zero-order
hold of u, w constant over the sample), the flow after ``dt`` is

    phi(dt; x, p) = T_k(x, p) + R(x, p),   T_k = x + sum_{i=1..k} dt^i / i! F^[i](x, p)

with the Lie derivatives ``F^[1] = F``, ``F^[i+1] = (dF^[i]/dx) F``. On a domain ``D`` (the
boxes X, U, W inflated by a margin) the remainder is enclosed in the mean-value form

    R(z) in rho + M (z - z_c)     for every z = (x, u, w) in D,

``rho`` enclosing ``R(z_c)`` and ``M`` enclosing ``DR(D)``, both interval valued:

* Lagrange form of the Taylor remainder in time, row by row:
  ``R_j(z) = dt^(k+1)/(k+1)! F_j^[k+1](phi(xi_j; z), p)`` for some ``xi_j`` in [0, dt], so
  ``R(z_c) in [dt^(k+1)/(k+1)!] F^[k+1](B_c, p_c)`` with ``B_c`` an a-priori enclosure of
  the trajectory from ``z_c`` on [0, dt];
* the same for the sensitivity ``d phi/dz``, whose (k+1)-th time derivative is
  ``D G^[k+1](phi) Y`` (``G = (F, 0)`` the field of the augmented state (x, p), ``Y`` the
  solution of the variational equation ``Y' = DG(phi) Y``, ``Y(0) = I``):
  ``DR(z) in [dt^(k+1)/(k+1)!] (A_x Y_b + [0, A_p])`` with ``(A_x, A_p)`` an enclosure of
  ``dF^[k+1]/d(x, p)`` over the a-priori enclosure of the trajectories and ``Y_b`` an
  a-priori enclosure of ``Y``. This is done per box of a paving of D (a box is bisected
  where an enclosure cannot be found, or while its slope term is wide and the budget
  allows), and ``M`` is the hull over the boxes.

A-priori enclosures come from the interval Picard operator: a box ``E`` with
``Y0 + [0, h] g(E) ⊆ E`` holds every solution of ``y' = g(t, y)`` from ``Y0`` on [0, h]
(and so does the left-hand side, which is kept). [0, dt] is cut into 1, 2, 4, ... 64 pieces
as needed, the enclosure at the end of a piece being ``Y_j + [h] g(E_j)``. Every interval
operation is that of :mod:`casadi_cmpc.interval.arith` (outward rounded); the literals of F
are exact parameters and the coefficients ``dt^i / i!`` are enclosed from their exact
rational values.

The remainder is global over D: its width at any point is about the width of ``R(D)``
(:attr:`Model.validation` ``["remainder_width"]``), so a fast or stiff ODE (large
``dt |dF/dx|``) gives a wide remainder, and a flow that runs away within a sample, or meets
a point where rhs is undefined, cannot be validated at all (a ModelError says so).

The interval source of the model is ``T_k + rho + M (z - z_c) + 0 * guard(z)`` with every
constant a parameter (``rho``, ``M`` and the coefficients interval valued, see
:class:`~casadi_cmpc.interval._derivative.ParamFunction`); ``guard(z)`` is a sum of square
roots of the distances of z to the faces of D, undefined (NaN, read as ``[-inf, inf]``)
on boxes that leave D, exactly 0 times a finite number inside.
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Any

import casadi as ca
import numpy as np

from .exceptions import ModelError, UnsupportedOperationError
from .interval import arith
from .interval._derivative import ParamGraph, exact_function, guard_flags

__all__ = ["taylor_model", "NONSMOOTH_OPS"]

# Operations through which the right-hand side may jump or lose smoothness: the Taylor
# remainder needs F of class C^(k+2) on the validated domain.
NONSMOOTH_OPS = {
    ca.OP_FLOOR: "floor", ca.OP_CEIL: "ceil", ca.OP_SIGN: "sign", ca.OP_NOT: "not",
    ca.OP_LT: "<", ca.OP_LE: "<=", ca.OP_EQ: "==", ca.OP_NE: "!=", ca.OP_AND: "and",
    ca.OP_OR: "or", ca.OP_IF_ELSE_ZERO: "if_else", ca.OP_COPYSIGN: "copysign",
    ca.OP_FMOD: "fmod", ca.OP_REMAINDER: "remainder", ca.OP_ATAN2: "atan2",
    ca.OP_FABS: "fabs", ca.OP_FMIN: "fmin", ca.OP_FMAX: "fmax", ca.OP_HYPOT: "hypot",
}

MAX_ORDER = 12
_PICARD_ITERATIONS = 40
_NOT_VALIDATED = "the ODE cannot be validated on its domain: "


def _coefficient(dt: float, i: int) -> tuple[float, float]:
    """Floats ``lo <= dt^i / i! <= hi`` (from the exact rational value of the float dt)."""
    q = Fraction(dt) ** i / math.factorial(i)
    v = float(q)  # nearest (or a neighbour): step outward once more to be sure
    lo, hi = np.nextafter(v, -np.inf), np.nextafter(v, np.inf)
    if Fraction(v) == q:
        lo = hi = v
    return float(lo), float(hi)


# ------------------------------------------------------------- interval array helpers
def _add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        lo, hi = arith.add(a[..., 0], a[..., 1], b[..., 0], b[..., 1])
    return np.stack([lo, hi], axis=-1)


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        lo, hi = arith.mul(a[..., 0], a[..., 1], b[..., 0], b[..., 1])
    return np.stack([lo, hi], axis=-1)


def _matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Interval product of batches of (r, k, 2) and (k, c, 2) matrices: (..., r, c, 2)."""
    k = A.shape[-2]
    out = None
    for j in range(k):
        t = _mul(A[..., :, j:j + 1, :], B[..., j:j + 1, :, :])
        out = t if out is None else _add(out, t)
    assert out is not None
    return out


def _hull(A: np.ndarray) -> np.ndarray:
    """Interval hull over the first axis."""
    return np.stack([A[..., 0].min(axis=0), A[..., 1].max(axis=0)], axis=-1)


def _inflate(B: np.ndarray, scale: float) -> np.ndarray:
    """B widened by ``scale`` times its width (and a small absolute amount) on each side."""
    w = B[..., 1] - B[..., 0]
    pad = scale * w + 1e-9 * (1.0 + np.abs(B).max(axis=-1)) + 1e-300
    return np.stack([B[..., 0] - pad, B[..., 1] + pad], axis=-1)


def _rows_ok(C: np.ndarray, B: np.ndarray | None = None) -> np.ndarray:
    """Per batch row: C finite (and inside B)."""
    ax = tuple(range(1, C.ndim))
    ok = np.isfinite(C).all(axis=ax)
    if B is not None:
        ok &= (C[..., 0] >= B[..., 0]).all(axis=ax[:-1]) & (C[..., 1] <= B[..., 1]).all(
            axis=ax[:-1])
    return ok


def _picard(start: np.ndarray, step: Any) -> tuple[np.ndarray, np.ndarray]:
    """Batched a-priori enclosures ``E`` with ``start + step(E) ⊆ E``.

    ``start`` (N, ..., 2); ``step(B)`` must enclose ``[0, dt] * (the derivative over B)``
    row by row. Returns ``(start + step(E), found)``: rows where ``found`` is False have no
    enclosure (their values are meaningless).
    """
    N = start.shape[0]
    B = start.copy()
    out = np.zeros_like(start)
    found = np.zeros(N, dtype=bool)
    todo = np.arange(N)
    for it in range(_PICARD_ITERATIONS):
        if todo.size == 0:
            break
        trial = _inflate(B[todo], 0.1 if it < 10 else 1.0)
        C = _add(start[todo], step(trial, todo))
        ok = _rows_ok(C, trial)
        out[todo[ok]] = C[ok]
        found[todo[ok]] = True
        fin = _rows_ok(C)
        keep = ~ok & fin
        Bt = B[todo[keep]]
        Ck = C[keep]
        B[todo[keep]] = np.stack([np.minimum(Ck[..., 0], Bt[..., 0]),
                                  np.maximum(Ck[..., 1], Bt[..., 1])], axis=-1)
        todo = todo[keep]
    return out, found


class _Eval:
    """Batched natural interval enclosure of an exact Function of ``(x, p)``."""

    def __init__(self, name: str, x: ca.SX, p: ca.SX, expr: ca.SX, params: ca.SX,
                 values: np.ndarray) -> None:
        from .interval.compiler import InclusionFunction

        pf = exact_function(name, [x, p], [ca.densify(expr)], params, values)
        self.F = InclusionFunction(pf, "natural", backend="numpy")
        self.shape = expr.shape

    def __call__(self, Bx: np.ndarray, Bp: np.ndarray) -> np.ndarray:
        """Boxes (N, n, 2), (N, q, 2) -> (N, r, c, 2)."""
        out = np.asarray(self.F(Bx, Bp)[0], dtype=float)
        N = out.shape[0]
        r, c = self.shape
        return out.reshape(N, c, r, 2).transpose(0, 2, 1, 3)


def taylor_model(x: ca.SX, u: ca.SX, w: ca.SX | None, rhs: ca.SX, dt: float, order: int,
                 X: Any, U: Any, W: Any, margin: float = 0.05, max_boxes: int = 1024
                 ) -> tuple[ca.SX, ca.SX, ca.SX, np.ndarray, dict[str, Any]]:
    """The order-``order`` Taylor map of ``dx/dt = rhs`` and its validated interval form.

    Parameters
    ----------
    x, u, w : casadi.SX, shapes (n, 1), (m, 1), (l, 1) (w may be None)
        Symbols of the state, input and disturbance.
    rhs : casadi.SX, shape (n, 1)
        Right-hand side, in state units per time unit; smooth (no jumps, no fabs, fmin,
        fmax) on the validated domain.
    dt : float
        Sampling time in time units of ``rhs``.
    order : int
        Taylor order k, 1 <= k <= 12.
    X, U, W : Box
        State, input and disturbance boxes (W None without w).
    margin : float
        The validated domain D is X, U, W each widened by ``margin`` times its width on
        every side (plus a small absolute amount).
    max_boxes : int
        Largest number of boxes of the paving of D over which the remainder's Jacobian is
        enclosed (D is bisected where an a-priori enclosure cannot be found).

    Returns
    -------
    f : casadi.SX, shape (n, 1)
        The Taylor polynomial with float coefficients (the numeric map).
    exact : casadi.SX, shape (n, 1)
        Expression in x, u, w and the parameters enclosing the flow on D (see the module).
    params : casadi.SX, shape (q, 1)
        Its parameter symbols.
    bounds : ndarray, shape (q, 2)
        The interval of every parameter.
    info : dict
        ``order``, ``dt``, ``domain`` (D as an (n + m + l, 2) array over (x, u, w)),
        ``rho`` (n, 2), ``M`` (n, n + m + l, 2), ``apriori`` (the enclosure of all
        trajectories from D on [0, dt], (n, 2)), ``remainder_width`` (the largest width of
        ``rho + M (D - z_c)``).

    Raises
    ------
    UnsupportedOperationError
        rhs holds an operation that may jump or is not smooth.
    ModelError
        The a-priori enclosures cannot be found, or rhs (or one of its derivatives) is not
        defined (or not finite) on the domain: "cannot be validated".
    """
    n, m = int(x.numel()), int(u.numel())
    ws = w if w is not None else ca.SX.sym("w", 0)
    l = int(ws.numel())
    if isinstance(order, (bool, np.bool_)) or not isinstance(order, (int, np.integer)):
        raise TypeError(f"order must be an integer; got {order!r}")
    k = int(order)
    if not 1 <= k <= MAX_ORDER:
        raise ValueError(f"order must be between 1 and {MAX_ORDER}; got {order}")
    if not (isinstance(margin, (int, float)) and np.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin must be a non-negative number; got {margin!r}")
    fun = ca.Function("rhs", [x, u, ws], [rhs])
    bad = sorted({NONSMOOTH_OPS[fun.instruction_id(i)] for i in range(fun.n_instructions())
                  if fun.instruction_id(i) in NONSMOOTH_OPS})
    if bad:
        raise UnsupportedOperationError(
            f"method='taylor' needs a smooth right-hand side, and rhs holds operations that "
            f"may jump or are not differentiable: {', '.join(bad)}; remove them (e.g. "
            "restrict X to one branch) or use method='euler'/'rk4' (no error bound)")
    pg = ParamGraph(fun)
    c = pg.params
    # F in the model's symbols, its literals as parameters (nothing folded)
    F = ca.Function("rhs_p", pg.inputs + [c], pg.outputs).call([x, u, ws, c])[0]
    lie = [F]
    for _ in range(k):
        lie.append(ca.jtimes(lie[-1], x, F))
    p = ca.vertcat(u, ws)
    q = m + l
    a = ca.SX.sym("a", k + 1)  # dt^i / i!
    coef = np.array([_coefficient(float(dt), i) for i in range(1, k + 2)])
    taylor = x
    for i in range(k):
        taylor = taylor + a[i] * lie[i]
    # numeric map: the same polynomial with float coefficients
    nominal = [float(Fraction(float(dt)) ** i / math.factorial(i)) for i in range(1, k + 2)]
    f_num = ca.substitute(taylor, ca.vertcat(c, a), ca.DM(np.concatenate([pg.values, nominal])))
    # ---- validated domain
    boxes = [X.as_array(), U.as_array()] + ([W.as_array()] if l else [])
    Dz = np.concatenate(boxes, axis=0)
    wid = Dz[:, 1] - Dz[:, 0]
    pad = margin * wid + 1e-6 * (1.0 + np.abs(Dz).max(axis=1))
    D = np.stack([Dz[:, 0] - pad, Dz[:, 1] + pad], axis=1)
    zc = 0.5 * D[:, 0] + 0.5 * D[:, 1]
    thin = np.stack([pg.values, pg.values], axis=1) if pg.values.size else np.zeros((0, 2))
    ev = _Evaluators(x, p, F, lie[k], c, thin, float(dt), pg, m)
    xc, pc = zc[:n], zc[n:]
    # rho: the remainder at the centre, over an a-priori enclosure of its trajectory
    pc_box = np.stack([pc, pc], axis=1)[None]
    Bc, found = _enclose(np.stack([xc, xc], axis=1)[None],
                         lambda B, idx: ev.F(B, pc_box)[:, :, 0], float(dt))
    if not found[0]:
        raise ModelError(_NOT_VALIDATED + "no a-priori enclosure of the trajectory from the "
                         f"centre {zc.tolist()} of the domain over one sample was found")
    rk = ev.Fk(Bc, pc_box)[0, :, 0]
    if not np.isfinite(rk).all():
        raise ModelError(_NOT_VALIDATED + f"the Taylor remainder of order {k} is not bounded "
                         f"along the trajectory from the centre {zc.tolist()} of the domain")
    ck = coef[k]
    rho = _mul(ck, rk)
    # M: over a paving of the domain (bisected where an enclosure cannot be found)
    M, B_D = _remainder_jacobian(ev, D, n, q, ck, max_boxes, 1e-6)
    # ---- exact (interval) form
    z = ca.vertcat(x, p)
    rho_s = ca.SX.sym("rho", n)
    M_s = ca.SX.sym("M", n, n + q)
    zc_s = ca.SX.sym("zc", n + q)
    dlo_s = ca.SX.sym("dlo", n + q)
    dhi_s = ca.SX.sym("dhi", n + q)
    zero_s = ca.SX.sym("g0")
    guard = 0
    for i in range(n + q):
        guard = guard + ca.sqrt(z[i] - dlo_s[i]) + ca.sqrt(dhi_s[i] - z[i])
    exact = taylor + rho_s + ca.mtimes(M_s, z - zc_s) + zero_s * guard
    params = ca.vertcat(c, a[:k], rho_s, ca.vec(M_s), zc_s, dlo_s, dhi_s, zero_s)
    bounds = np.concatenate([
        thin, coef[:k], rho, M.transpose(1, 0, 2).reshape(-1, 2),
        np.stack([zc, zc], axis=1), np.stack([D[:, 0], D[:, 0]], axis=1),
        np.stack([D[:, 1], D[:, 1]], axis=1), np.zeros((1, 2))])
    dev = _matmul(M, np.stack([D[:, 0] - zc, D[:, 1] - zc], axis=1)[:, None, :])[:, 0]
    rem = _add(rho, dev)
    info = {"order": k, "dt": float(dt), "domain": D, "centre": zc, "rho": rho, "M": M,
            "apriori": B_D, "remainder_width": float((rem[:, 1] - rem[:, 0]).max())}
    return f_num, exact, params, bounds, info


class _Evaluators:
    """The interval enclosures the remainder needs, batched over boxes (N, ., 2)."""

    def __init__(self, x: ca.SX, p: ca.SX, F: ca.SX, Fk: ca.SX, c: ca.SX, thin: np.ndarray,
                 dt: float, pg: ParamGraph, m: int) -> None:
        z = ca.vertcat(x, p)
        self.n = int(x.numel())
        self.m = int(m)
        self.F = _Eval("rhs_iv", x, p, F, c, thin)
        self.JF = _Eval("rhs_jac_iv", x, p, ca.jacobian(F, z), c, thin)
        self.Fk = _Eval("lie_iv", x, p, Fk, c, thin)
        self.JFk = _Eval("lie_jac_iv", x, p, ca.jacobian(Fk, z), c, thin)
        self.dt = dt
        self.pg = pg
        self.guards = None
        if pg.guards:
            from .interval.compiler import InclusionFunction

            g = pg.function("rhs_guards", pg.inputs, [pg.guard_exprs])
            self.guards = InclusionFunction(g, "natural", backend="numpy")

    def guard_ok(self, B: np.ndarray, P: np.ndarray) -> np.ndarray:
        """(N,) True where no operation of rhs may leave its domain (or meet a pole) on the
        boxes B x P."""
        N = B.shape[0]
        if self.guards is None:
            return np.ones(N, dtype=bool)
        m = self.m
        out = np.asarray(self.guards(B, P[:, :m], P[:, m:])[0], dtype=float)
        lo = [out[:, j, 0] for j in range(out.shape[1])]
        hi = [out[:, j, 1] for j in range(out.shape[1])]
        return ~guard_flags(self.pg, lo, hi, N).any(axis=1)


def _chain(start: np.ndarray, deriv: Any, dt: float, s: int
           ) -> tuple[np.ndarray, np.ndarray]:
    """A-priori enclosures of the solutions of ``y' = g(t, y)`` on [0, dt], batched.

    ``start`` (N, ..., 2) holds y(0); ``deriv(E, idx)`` encloses ``g`` over the boxes E of
    the rows ``idx``. [0, dt] is cut into s pieces of the exact length dt / s (in
    ``[h_lo, h_hi]``): on each, a Picard enclosure ``Y_j + [0, h_hi] g(E) ⊆ E`` holds the
    solution, and ``Y_(j+1) = Y_j + [h_lo, h_hi] g(E)`` holds it at the end of the piece.
    Returns the hull of the pieces' enclosures and where all were found (N,).
    """
    N = start.shape[0]
    h = dt / s
    h_iv = np.array([float(np.nextafter(h, -np.inf)), float(np.nextafter(h, np.inf))])
    t_piece = np.array([0.0, h_iv[1]])
    Yj = start.copy()
    hull = start.copy()
    ok = np.ones(N, dtype=bool)
    for _ in range(s):
        E, found = _picard(Yj, lambda Et, idx: _mul(t_piece, deriv(Et, idx)))
        ok &= found
        if not ok.any():
            break
        d = deriv(E, np.arange(N))
        Yj = _add(Yj, _mul(h_iv, d))
        hull = np.stack([np.minimum(hull[..., 0], E[..., 0]),
                         np.maximum(hull[..., 1], E[..., 1])], axis=-1)
        ok &= _rows_ok(Yj)
    return hull, ok


def _enclose(start: np.ndarray, deriv: Any, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_chain` with 1, 2, 4, ... 64 pieces, more where fewer fail (batched)."""
    N = start.shape[0]
    out = np.zeros_like(start)
    ok = np.zeros(N, dtype=bool)
    todo = np.arange(N)
    for s in (1, 2, 4, 8, 16, 32, 64):
        E, found = _chain(start[todo], lambda Et, idx, todo=todo: deriv(Et, todo[idx]), dt, s)
        out[todo[found]] = E[found]
        ok[todo[found]] = True
        todo = todo[~found]
        if todo.size == 0:
            break
    return out, ok


def _sensitivities(Jx: np.ndarray, Jp: np.ndarray, dt: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """A-priori enclosures of ``Y(t) = [dx/dx0, dx/dp]`` for all t in [0, dt], batched:
    ``Y' = J_x(t) Y + [0, J_p(t)]``, ``Y(0) = [I, 0]`` with ``J_x(t)``, ``J_p(t)`` in the
    interval matrices ``Jx`` (N, n, n, 2), ``Jp`` (N, n, q, 2). Returns (N, n, n + q, 2)
    and where they were found (N,)."""
    N, n = Jx.shape[:2]
    q = Jp.shape[2]
    Y0 = np.zeros((N, n, n + q, 2))
    Y0[:, np.arange(n), np.arange(n)] = 1.0

    def deriv(E: np.ndarray, idx: np.ndarray) -> np.ndarray:
        d = _matmul(Jx[idx], E)
        d[:, :, n:] = _add(d[:, :, n:], Jp[idx])
        return d

    return _enclose(Y0, deriv, dt)


def _remainder_jacobian(ev: _Evaluators, D: np.ndarray, n: int, q: int, ck: np.ndarray,
                        max_boxes: int, rtol: float) -> tuple[np.ndarray, np.ndarray]:
    """``M`` (n, n + q, 2) enclosing ``DR`` over the domain D (n + q, 2), and the hull of
    the a-priori enclosures of the trajectories (n, 2).

    Per box of a paving of D: the a-priori enclosure B of the trajectories (Picard), the
    domain guards of rhs on B, the a-priori enclosure Y of the sensitivities
    ``[dx/dx0, dx/dp]`` (Picard on the variational equation with ``J = dF/d(x, p)`` over
    B), then ``[c_k+1] (A_x Y + [0, A_p])`` with ``(A_x, A_p) = dF^[k+1]/d(x, p)`` over B.
    A box where one step fails is bisected (widest coordinate relative to D) and tried
    again, up to ``max_boxes`` boxes in all; so is, while that budget allows, a box whose
    slope term ``M_i (D - z_c)`` is wider than ``rtol`` times the width of D in some state.
    """
    from ._bisect import bisect_widest

    width = np.maximum(D[:, 1] - D[:, 0], 1e-300)
    zc = 0.5 * D[:, 0] + 0.5 * D[:, 1]
    dz = np.stack([D[:, 0] - zc, D[:, 1] - zc], axis=1)  # (n + q, 2)
    tol = rtol * width[:n]  # target width of the slope term per state
    todo = D[None].copy()
    Ms: list[np.ndarray] = []
    Bs: list[np.ndarray] = []
    used = 1
    reason = ""
    while todo.shape[0]:
        Bx0, P = todo[:, :n], todo[:, n:]
        B, ok = _enclose(Bx0, lambda Bt, idx, P=P: ev.F(Bt, P[idx])[:, :, 0], ev.dt)
        if not ok.all():
            reason = "no a-priori enclosure of the trajectories (interval Picard iteration)"
        good = np.flatnonzero(ok)
        if good.size:
            g_ok = ev.guard_ok(B[good], P[good])
            if not g_ok.all():
                reason = ("rhs is not defined (or not smooth: a square root or logarithm at "
                          "0, a pole, ...) on the reachable states")
            good = good[g_ok]
        M_ok = np.zeros(todo.shape[0], dtype=bool)
        if good.size:
            Bg, Pg = B[good], P[good]
            J = ev.JF(Bg, Pg)  # (N, n, n + q, 2)
            Jx, Jp = J[:, :, :n], J[:, :, n:]
            Y, y_ok = _sensitivities(Jx, Jp, ev.dt)
            if not y_ok.all():
                reason = ("no a-priori enclosure of the sensitivities d x(t) / d(x0, u, w) "
                          "(interval Picard iteration on the variational equation)")
            A = ev.JFk(Bg, Pg)
            DR = _matmul(A[:, :, :n], Y)
            DR[:, :, n:] = _add(DR[:, :, n:], A[:, :, n:])
            Mi = _mul(ck, DR)
            fin = y_ok & _rows_ok(Mi)
            if (y_ok & ~fin).any():
                reason = ("the Taylor remainder is not bounded on the reachable states (rhs "
                          "or its derivatives undefined or unbounded there)")
            # boxes whose remainder slope is wide: refined while the budget allows
            dev = _matmul(Mi, dz[None, :, None, :])[:, :, 0]
            wide = ((dev[..., 1] - dev[..., 0]) > tol).any(axis=1) & fin
            if used + int(wide.sum()) <= max_boxes:
                fin &= ~wide
            Ms.append(Mi[fin])
            Bs.append(Bg[fin])
            M_ok[good[fin]] = True
        bad = todo[~M_ok]
        if bad.shape[0] == 0:
            break
        used += bad.shape[0]
        if used > max_boxes:
            raise ModelError(
                _NOT_VALIDATED + f"{reason} on some boxes of the domain, even after splitting "
                f"it into {max_boxes} boxes; use a smaller dt, smaller boxes X, U, W, or a "
                "smaller domain_margin")
        lo, hi = bad[..., 0], bad[..., 1]
        lo2, hi2, _, _ = bisect_widest(np.ascontiguousarray(lo), np.ascontiguousarray(hi),
                                       (hi - lo) / width)
        todo = np.stack([lo2, hi2], axis=-1)
    M = _hull(np.concatenate(Ms))
    B_D = _hull(np.concatenate(Bs))
    return M, B_D
