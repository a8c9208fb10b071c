"""Nonlinear MPC with a compulsory contractive constraint (thesis §4.3, Alg 4.5).

At each state ``x(k)`` the controller solves, for a horizon ``N`` (problem (4.22)-(4.23))::

    min  sum_{i=1}^{N-1} e_i' Q e_i + e_N' P e_N + sum_{i=0}^{N-1} v_i' R v_i
    s.t. x(i+1) = f(x(i), u(i), w_nom),  u(i) in U,  x(i) in X   (i = 1..N)
         ||C e_N||_p <= alpha ||C e_0||_p                          (contraction)
         g(x(i), u(i)) <= 0,  x(N) in S                            (optional)

with ``e_i = x(i) - x_ref`` and ``v_i = u(i) - u_ref``. IPOPT (or CasADi ``sqpmethod`` with
``qrqp``) finds a sequence; interval arithmetic then re-evaluates the whole prediction from
the exact ``x(k)`` and only a sequence that passes is reported *verified*. When the local
solver fails, a search over ``U^N`` (the library's SIVIA) finds a feasible sequence or proves
that none exists (Alg 4.5: a horizon is left only when it is proven infeasible).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .._interrupt import solver_call
from .._validate import float_vector as _vector
from .._validate import weight_matrix as _weight
from ..exceptions import DimensionError, ModelError
from ..interval.compiler import InclusionFunction, _op_name
from ..model import Model
from ..sets.box import Box
from ..sets.polytope import Polytope
from ..solvers.engine import Status
from ..solvers.result import Certificate, Result
from ._fastcall import BufferedCall
from ._stepcheck import NativeAfter
from .spec import ContractiveSpec, HorizonProblem

__all__ = ["ContractiveMPC", "MPCResult"]

_SOLVERS = ("ipopt", "sqp", "lp")
#: Contracted distances below this are treated as 0 (their reciprocal would overflow).
_TINY = 1e-250
_MODES = ("receding", "sequence")


# ----------------------------------------------------------------------------- results
@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class MPCResult(Result):
    """One solve of :class:`ContractiveMPC` from the state ``x``.

    ``status``: ``PROVED`` the returned sequence is verified feasible; ``DISPROVED`` every
    horizon tried is proven infeasible; ``BUDGET`` a search budget ran out; ``UNDECIDED``
    the sequence could not be verified; ``NUMERICAL`` the local solver failed and no search
    was made.

    Attributes
    ----------
    x : ndarray (n,)
        The state solved from.
    u : ndarray (m,)
        The first move (what ``ctrl(x)`` applies).
    u_seq : ndarray (N, m)
        The control sequence (the best available one; see ``certificate``).
    x_pred : ndarray (N + 1, n)
        Predicted states ``x(0) = x, ..., x(N)`` with the nominal w: for a verified
        sequence the midpoints of the verified enclosures (the exact prediction lies within
        half their width, usually a few ulps; more where the model is ill-conditioned),
        otherwise the float simulation.
    cost : float
        Value of (4.22) at ``u_seq`` (NaN when there is no sequence).
    horizon : int or None
        Horizon ``N`` of ``u_seq`` and ``x_pred`` (everything in the result belongs to
        it); when a horizon search ends without a verified sequence, the last horizon
        tried.
    certificate : Certificate
    stats : dict
        ``solver`` (name), ``solve_time`` (s, the local solver), ``verify_time`` (s),
        ``search_time`` (s), ``horizons_tried``; ``return_status``, ``success`` and
        ``iter_count`` of the local solver when the sequence was not verified, or always
        with ``solver_stats=True``.
    mode : str
        ``"mpc"``, ``"at_reference"``, ``"local_law"`` or ``"nothing_to_contract"``
        (``C (x - x_ref)`` is 0 or underflows while ``x != x_ref``).
    """

    x: np.ndarray
    u: np.ndarray
    u_seq: np.ndarray
    x_pred: np.ndarray
    cost: float
    horizon: int | None
    certificate: Certificate
    stats: dict
    mode: str = "mpc"

    def _repr_parts(self) -> list[str]:
        return [f"horizon={self.horizon}", f"certificate={self.certificate.label!r}",
                f"cost={self.cost:.6g}"]


# ------------------------------------------------------------------------ argument checks
def _norm(norm: Any) -> float:
    if isinstance(norm, str):
        key = norm.strip().lower()
        table = {"1": 1.0, "2": 2.0, "inf": math.inf, "infinity": math.inf}
        if key not in table:
            raise ValueError(f"norm must be 1, 2 or inf; got {norm!r}")
        return table[key]
    try:
        p = float(norm)
    except (TypeError, ValueError):
        raise ValueError(f"norm must be 1, 2 or inf; got {norm!r}") from None
    if p not in (1.0, 2.0, math.inf):
        raise ValueError(f"norm must be 1, 2 or inf (np.inf); got {norm!r}")
    return p


def _alpha(alpha: Any) -> float:
    if isinstance(alpha, (str, bytes)):
        raise ValueError(f"alpha must be a number in (0, 1], not the string {alpha!r}")
    try:
        a = float(alpha)
    except (TypeError, ValueError):
        raise ValueError(f"alpha must be a number in (0, 1]; got {alpha!r}") from None
    if isinstance(alpha, (bool, np.bool_)) or not (0.0 < a <= 1.0):
        raise ValueError(f"the contraction parameter alpha must lie in (0, 1]; got {alpha!r}")
    return a


def _state(x: Any, n: int, name: str = "x") -> np.ndarray:
    if x is None or isinstance(x, (str, bytes)):
        raise TypeError(f"{name} must be a numeric array of {n} elements; got {x!r}")
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a numeric array of {n} elements; got {x!r}") from None
    if a.size != n or a.ndim > 2 or (a.ndim == 2 and 1 not in a.shape):
        raise DimensionError(f"{name} must have shape ({n},); got {a.shape}")
    a = a.reshape(n)
    if not np.isfinite(a).all():
        raise ValueError(f"{name} must be finite; got {a.tolist()}")
    return a


def _find_undefined(expr: ca.SX, syms: list[ca.SX], vals: list[np.ndarray]) -> str:
    """Name the innermost operation of ``expr`` that is not finite at the point ``vals``."""
    def value(e: ca.SX) -> np.ndarray:
        fn = ca.Function("v", syms, [e])
        return np.asarray(fn(*vals), dtype=float).ravel()

    out = value(expr)
    k = int(np.flatnonzero(~np.isfinite(out))[0])
    node = expr[k]
    for _ in range(10000):
        deps = [node.dep(i) for i in range(node.n_dep())]
        bad = [d for d in deps if not np.isfinite(value(d)).all()]
        if not bad:
            args = ", ".join(f"{float(value(d)[0]):.6g}" for d in deps)
            return (f"{_op_name(node.op())}({args}) = {float(value(node)[0])} in output "
                    f"component {k}")
        node = bad[0]
    return f"output component {k}"  # pragma: no cover


def check_defined(model: Model, w_nom: np.ndarray, samples: int = 512, seed: int = 0) -> None:
    """Raise ModelError when f is undefined (NaN or infinite) at a sampled point of X x U.

    Sampled: the centre, the vertices (up to 2^10 of them) and ``samples`` random points of
    X x U with ``w = w_nom``. Sampling can miss a small undefined region; the interval
    verification of every solve still reports undefined predictions.
    """
    rng = np.random.default_rng(seed)
    lo = np.concatenate([model.X.lo, model.U.lo])
    hi = np.concatenate([model.X.hi, model.U.hi])
    d = lo.size
    pts = [0.5 * (lo + hi)[None, :], lo + (hi - lo) * rng.random((samples, d))]
    if d <= 10:
        corners = (np.arange(2 ** d)[:, None] >> np.arange(d)) & 1
        pts.append(np.where(corners == 1, hi, lo))
    P = np.concatenate(pts)
    n = model.n
    with np.errstate(all="ignore"):
        Y = model.step(P[:, :n], P[:, n:], np.broadcast_to(w_nom, (P.shape[0], model.l))
                       if model.l else None)
    bad = ~np.isfinite(Y).all(axis=1)
    if bad.any():
        p = P[int(np.flatnonzero(bad)[0])]
        syms = [model.x, model.u] + ([model.w] if model.l else [])
        vals = [p[:n], p[n:]] + ([w_nom] if model.l else [])
        where = _find_undefined(model.f, syms, vals)
        raise ModelError(
            f"the model '{model.name}' is undefined at x = {p[:n].tolist()}, "
            f"u = {p[n:].tolist()} inside X x U: {where}. Restrict X or U, or rewrite f so "
            "that it is defined on the whole box")


def _solver_options(solver: str, user: dict | None) -> tuple[str, dict]:
    if solver == "ipopt":
        opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                "ipopt.max_iter": 300, "ipopt.warm_start_init_point": "yes",
                "ipopt.mu_init": 1e-4}
        plugin = "ipopt"
    else:
        opts = {"qpsol": "qrqp", "print_header": False, "print_iteration": False,
                "print_status": False, "print_time": False, "error_on_fail": False,
                "max_iter": 100,
                "qpsol_options": {"print_iter": False, "print_header": False,
                                  "error_on_fail": False}}
        plugin = "sqpmethod"
    if user:
        opts.update(user)
    return plugin, opts


def _read_stats(stats: dict) -> None:
    """Fill ``return_status``, ``success`` and ``iter_count`` from the solver's stats."""
    fun = stats.pop("_fun", None)
    if fun is None:
        return
    st = fun.stats()
    it = st.get("iter_count", 0)
    it = int(it) if isinstance(it, (int, np.integer)) and 0 <= it < 10 ** 7 else 0
    stats.update(return_status=st.get("return_status", ""),
                 success=bool(st.get("success", False)), iter_count=it)


# ------------------------------------------------------------------------ one horizon
class _Consts:
    """Constants of a graph: DM numbers (float graph) or symbols with recorded values.

    The exact graph keeps every constant as a symbol, so that CasADi cannot fold products
    of constants in floating point while the model is composed with itself; the recorded
    values enter the interval evaluation as thin intervals.
    """

    def __init__(self, exact: bool) -> None:
        self.exact = exact
        self.syms: list[ca.SX] = []
        self.los: list[np.ndarray] = []
        self.his: list[np.ndarray] = []

    def __call__(self, value: Any, name: str) -> Any:
        """The constant ``value``: a number (float graph) or a symbol (exact graph)."""
        a = np.asarray(value, dtype=float)
        if not self.exact:
            return float(a) if a.ndim == 0 else ca.DM(a)
        shape = (1, 1) if a.ndim == 0 else ((a.size, 1) if a.ndim == 1 else a.shape)
        v = np.reshape(a, shape).ravel(order="F")
        return self._symbol(name, shape, v, v)

    def _symbol(self, name: str, shape: tuple[int, ...], lo: np.ndarray,
                hi: np.ndarray) -> ca.SX:
        sym = ca.SX.sym(name, *shape)
        self.syms.append(ca.vec(sym))
        self.los.append(np.asarray(lo, dtype=float))
        self.his.append(np.asarray(hi, dtype=float))
        return sym

    def successor(self, model: Model) -> Any:
        """A callable ``(x, u, w) -> [x_next]``: of the float graph the model's numeric map
        (:attr:`Model.function`, e.g. the Taylor polynomial of a validated ODE model), of
        the exact graph its interval source (:meth:`Model.interval_expr`: every literal a
        thin parameter, the proven remainder of a validated model interval valued).

        In the exact graph of a validated model every call (every step of a prediction)
        gets parameters of its own: the remainder takes its own value in its interval at
        each step, so a search that treats the parameters as variables (the optimality
        bracket bisects them) must not tie the steps to one shared value. The parameters
        of other models are fixed numbers, shared by the steps."""
        if not self.exact:
            fun = model.function
            return lambda *args: fun.call(list(args))
        expr, P, Pb = model.interval_expr()
        g = ca.Function("f_interval", [model.x, model.u, model._w_sym, P], [expr])
        if not model.is_validated:  # fixed numbers (thin, or widened roundings): shared
            cp = self._symbol("f_par", (Pb.shape[0], 1), Pb[:, 0], Pb[:, 1])
            return lambda *args: g.call(list(args) + [cp])

        def step(*args: Any) -> list[Any]:
            k = len(self.syms)
            cp = self._symbol(f"f_par_{k}", (Pb.shape[0], 1), Pb[:, 0], Pb[:, 1])
            return g.call(list(args) + [cp])

        return step

    def function(self, fun: ca.Function, name: str) -> Any:
        """A callable ``(*args) -> list of outputs`` equal to ``fun`` with its literals as
        constants of this graph."""
        if not self.exact:
            return lambda *args: fun.call(list(args))
        from ..interval._derivative import ParamGraph

        pg = ParamGraph(fun)
        g = ca.Function(name, pg.inputs + [pg.params], pg.outputs)
        cp = self(pg.values, f"{name}_lit")
        return lambda *args: g.call(list(args) + [cp])

    @property
    def params(self) -> ca.SX:
        return ca.vertcat(*self.syms) if self.syms else ca.SX(0, 1)

    @property
    def lo(self) -> np.ndarray:
        """Lower bounds of the parameters (equal to :attr:`hi` but for interval-valued
        ones, such as a validated model's remainder)."""
        return np.concatenate(self.los) if self.los else np.zeros(0)

    @property
    def hi(self) -> np.ndarray:
        return np.concatenate(self.his) if self.his else np.zeros(0)


def _graph(mpc: ContractiveMPC, N: int, exact: bool, states: Any = None) -> dict[str, Any]:
    """Prediction, cost (4.22), constraint rows and contraction value at horizon N.

    With ``states`` (an (n, N) SX symbol, float graph only) the predicted states are those
    symbols (multiple shooting) and ``"defects"`` holds ``x(i+1) - f(x(i), u(i), w)``
    (n N rows, zero on a prediction); otherwise the model is composed with itself."""
    model = mpc.model
    n, m = model.n, model.m
    K = _Consts(exact)
    us = ca.SX.sym("u", N * m)
    x0 = ca.SX.sym("x0", n)
    f = K.successor(model)
    w = K(mpc.w_nominal, "w_nom") if model.l else ca.DM.zeros(0, 1)
    xs = [x0]
    defects = []
    for i in range(N):
        xn = f(xs[-1], us[i * m:(i + 1) * m], w)[0]
        if states is None:
            xs.append(xn)
        else:
            defects.append(states[:, i] - xn)
            xs.append(states[:, i])
    xr, ur = K(mpc.x_ref, "x_ref"), K(mpc.u_ref, "u_ref")
    Q, R, P = K(mpc.Q, "Q"), K(mpc.R, "R"), K(mpc.P, "P")
    cost = 0
    for i in range(N):
        v = us[i * m:(i + 1) * m] - ur
        e = xs[i + 1] - xr
        cost = cost + ca.mtimes([v.T, R, v]) + ca.mtimes([e.T, P if i == N - 1 else Q, e])
    C = K(mpc.contract, "C")
    eN = ca.mtimes(C, xs[N] - xr)
    e0 = ca.mtimes(C, x0 - xr)
    parts, lo, hi, labels = [], [], [], []
    for i in range(1, N + 1):
        parts.append(xs[i])
        lo.append(model.X.lo)
        hi.append(model.X.hi)
        labels += [f"state x{j + 1}({i}) in X" for j in range(n)]
    g_x, g_xu = mpc._path
    gx = K.function(g_x, "g_x") if g_x is not None else None
    gxu = K.function(g_xu, "g_xu") if g_xu is not None else None
    for i in range(N):
        if gxu is not None:
            parts.append(gxu(xs[i], us[i * m:(i + 1) * m])[0])
            k = g_xu.numel_out(0)
            lo.append(np.full(k, -np.inf))
            hi.append(np.zeros(k))
            labels += [f"constraint g_xu[{j}](x({i}), u({i})) <= 0" for j in range(k)]
        if gx is not None:
            parts.append(gx(xs[i + 1])[0])
            k = g_x.numel_out(0)
            lo.append(np.full(k, -np.inf))
            hi.append(np.zeros(k))
            labels += [f"constraint g_x[{j}](x({i + 1})) <= 0" for j in range(k)]
    if mpc.terminal is not None:
        Ht, ht = mpc.terminal.A, mpc.terminal.b
        parts.append(ca.mtimes(K(Ht, "H"), xs[N]) - K(ht, "h"))
        lo.append(np.full(Ht.shape[0], -np.inf))
        hi.append(np.zeros(Ht.shape[0]))
        labels += [f"terminal row {r}: H x({N}) <= h" for r in range(Ht.shape[0])]
    alpha = K(mpc.alpha, "alpha")
    if mpc.gauge is not None:
        Pa, Pb = K(mpc.gauge.A, "gauge_A"), K(mpc.gauge.b, "gauge_b")
        scale = Pb - ca.mtimes(Pa, xr)  # the gauge's level 1 is the polytope
        gN = ca.mmax(ca.mtimes(Pa, xs[N] - xr) / scale)
        g0 = ca.fmax(0, ca.mmax(ca.mtimes(Pa, x0 - xr) / scale))
        c_val = gN - alpha * g0
    elif mpc.norm == 2:
        c_val = ca.sqrt(ca.sumsqr(eN)) - alpha * ca.sqrt(ca.sumsqr(e0))
    elif mpc.norm == 1:
        c_val = ca.sum1(ca.fabs(eN)) - alpha * ca.sum1(ca.fabs(e0))
    else:
        c_val = ca.mmax(ca.fabs(eN)) - alpha * ca.mmax(ca.fabs(e0))
    labels.append("contraction ||C (x(N) - x_ref)|| - alpha ||C (x(k) - x_ref)|| <= 0")
    return {"us": us, "x0": x0, "xs": xs, "cost": cost, "eN": eN,
            "common": ca.vertcat(*parts), "c_lo": np.concatenate(lo),
            "c_hi": np.concatenate(hi), "c_val": c_val, "labels": labels,
            "params": K.params, "p_lo": K.lo, "p_hi": K.hi,
            "defects": ca.vertcat(*defects) if defects else ca.SX(0, 1)}


class _Horizon:
    """NLP (float graph) and verification/search functions (exact graph) of horizon N."""

    def __init__(self, mpc: ContractiveMPC, N: int, nlp: bool = True) -> None:
        self.N = N
        model = mpc.model
        n, m = model.n, model.m
        self.n, self.m = n, m
        # -- exact graph: the certificate, the search over U^N, the optimality bracket.
        # Every constant of the model, the constraints and the controller is a symbol fed as
        # a thin interval. Constants that CasADi still creates while simplifying the
        # composition (a - a -> 0, then acos(0) folded to a float) are lifted again and fed
        # as intervals widened like the compiler's derived constants.
        from ..interval._derivative import ParamGraph
        from ..interval.compiler import _widen_constant

        ex = _graph(mpc, N, exact=True)
        z = ca.vertcat(ex["us"], ex["x0"], ex["params"])
        raw = ca.Function(f"raw_{N}", [z], [ca.vertcat(ex["common"], ex["c_val"]),
                                            ex["cost"]])
        pg = ParamGraph(raw)
        full = ca.vertcat(pg.inputs[0], pg.params)
        made_lo, made_hi = (np.array([_widen_constant(v)[i] for v in pg.values])
                            for i in (0, 1))
        self.param_lo = np.concatenate([ex["p_lo"], made_lo])
        self.param_hi = np.concatenate([ex["p_hi"], made_hi])
        self.n_created = pg.values.size
        self.check_fun = ca.Function(f"check_{N}", [full], [pg.outputs[0]])
        self.check_lo = np.concatenate([ex["c_lo"], [-np.inf]])
        self.check_hi = np.concatenate([ex["c_hi"], [0.0]])
        # the bounds interleaved as the enclosures (lo, hi per row), and the signs that turn
        # enclosure - bound into the slacks Y_lo - lo and hi - Y_hi
        self.check_bounds = np.stack([self.check_lo, self.check_hi], axis=1).reshape(-1)
        self.check_signs = np.tile([1.0, -1.0], self.check_lo.size)
        self.labels = ex["labels"]
        self.n_state_rows = n * N
        self.exact_cost = ca.Function(f"cost_{N}", [full], [pg.outputs[1]])
        self._check_incl: InclusionFunction | None = None
        self._step_check: NativeAfter | None = None
        # -- float graph: the local solver, predictions and ranking of candidates
        fl = _graph(mpc, N, exact=False)
        us, x0, xs, cost = fl["us"], fl["x0"], fl["xs"], fl["cost"]
        self.cost_fun = ca.Function(f"costf_{N}", [ca.vertcat(us, x0)], [cost])
        self.pred_fun = ca.Function(f"pred_{N}", [us, x0], [ca.horzcat(*xs)])
        self.cost_pred = ca.Function(f"costpred_{N}", [us, x0], [cost, ca.horzcat(*xs)])
        # the states x(1..N) predicted from a control sequence, column after column: the
        # start of the multiple-shooting states (the same graph as pred_fun)
        self.start_states = ca.Function(f"start_{N}", [us, x0], [ca.vec(ca.horzcat(*xs[1:]))],
                                        ["u", "x0"], ["x"])
        self._batch: dict[int, ca.Function] = {}
        self._calls: _StepCalls | None = None
        self._pred_call: BufferedCall | None = None
        self._check_box: np.ndarray | None = None
        self.solver = None
        self.plugin, self.options = _solver_options(mpc.solver, mpc.solver_options)
        if not nlp:
            return
        # the NLP: contraction scaled by s = 1 / ||C e_0||_p, constraints tightened; with
        # multiple shooting the predicted states are variables tied by the defect rows
        # (a sparse, banded KKT system: about half the time of the condensed one at N = 10)
        multiple = mpc.shooting == "multiple"
        Xs = ca.SX.sym("X", n, N if multiple else 0)
        nl = _graph(mpc, N, exact=False, states=Xs) if multiple else fl
        eN, cost = nl["eN"], nl["cost"]
        q = mpc.contract.shape[0]
        b = mpc.backoff
        s = ca.SX.sym("s")
        a_eff = mpc.alpha * (1.0 - b)
        extra_x = ca.SX.sym("t", 0)
        if mpc.norm == 2:
            c_nlp = s * s * ca.sumsqr(eN)
            cl, ch = [-np.inf], [a_eff ** 2]
        elif mpc.norm == math.inf:
            c_nlp = s * eN
            cl, ch = [-a_eff] * q, [a_eff] * q
        else:
            extra_x = ca.SX.sym("t", q)
            c_nlp = ca.vertcat(s * eN - extra_x, -s * eN - extra_x, ca.sum1(extra_x))
            cl = [-np.inf] * (2 * q + 1)
            ch = [0.0] * (2 * q) + [a_eff]
        tight = b * np.concatenate([np.tile(model.X.hi - model.X.lo, N),
                                    np.tile(mpc._path_scale, N), mpc._terminal_scale])
        c_lo, c_hi = fl["c_lo"], fl["c_hi"]
        g_lo = np.where(np.isfinite(c_lo), c_lo + tight, c_lo)
        g_hi = np.where(np.isfinite(c_hi), c_hi - tight, c_hi)
        nd = nl["defects"].numel()
        self.lbg = np.concatenate([np.zeros(nd), g_lo, cl])
        self.ubg = np.concatenate([np.zeros(nd), g_hi, ch])
        # variables: u (N m), the 1-norm slacks (n_t), the predicted states (n_zx)
        zz = ca.vertcat(nl["us"], extra_x, ca.vec(Xs))
        self.n_z = zz.numel()
        self.n_t = extra_x.numel()
        self.n_zx = Xs.numel()
        self.lbz = np.concatenate([np.tile(model.U.lo, N), np.zeros(self.n_t),
                                   np.full(self.n_zx, -np.inf)])
        self.ubz = np.concatenate([np.tile(model.U.hi, N), np.full(self.n_t, np.inf),
                                   np.full(self.n_zx, np.inf)])
        self.nlp = {"x": zz, "p": ca.vertcat(nl["x0"], s), "f": cost,
                    "g": ca.vertcat(nl["defects"], nl["common"], c_nlp)}
        self.bounds = {"lbx": ca.DM(self.lbz), "ubx": ca.DM(self.ubz),
                       "lbg": ca.DM(self.lbg), "ubg": ca.DM(self.ubg)}
        self.solver = ca.nlpsol(f"cmpc_{model.name}_{N}", self.plugin, self.nlp, self.options)

    @property
    def check_inclusion(self) -> InclusionFunction:
        """The natural inclusion of :attr:`check_fun`."""
        if self._check_incl is None:
            self._check_incl = InclusionFunction(self.check_fun, "natural")
        return self._check_incl

    @property
    def step_check(self) -> NativeAfter:
        """:attr:`check_inclusion` for the check of one sequence per step (on the native
        backend after a few steps)."""
        sc = self._step_check
        if sc is None or sc.F is not self.check_inclusion:
            sc = self._step_check = NativeAfter(self.check_inclusion)
        return sc

    def calls(self) -> _StepCalls:
        """The per-step evaluations on preallocated arrays (built at the first use, and
        again when :attr:`solver` has been replaced)."""
        c = self._calls
        if c is None or c.solver is not self.solver:
            c = self._calls = _StepCalls(self)
        return c

    def predict(self, useq: np.ndarray, x: np.ndarray) -> tuple[float, np.ndarray]:
        """``(cost, x_pred)``: the cost (4.22) of ``useq`` (shape (N, m)) from ``x`` and the
        predicted states (N + 1, n), by the float graph (the values of :attr:`cost_pred`)."""
        call = self._pred_call
        if call is None:
            call = self._pred_call = BufferedCall(self.cost_pred)
        call.args[0][:] = useq.reshape(-1)
        call.args[1][:] = x
        call()
        return float(call.res[0][0]), call.res[1].reshape(self.N + 1, self.n).copy()

    def check_box(self, useq: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The box ``[u_seq, x, constants]`` of one sequence (shape (1, dim, 2), thin in
        ``u_seq`` and ``x``), written into an array kept between calls."""
        out = self._check_box
        if out is None:
            out = self._check_box = self.boxes(np.zeros((1, self.N * self.m)),
                                               np.zeros(self.n))
        j = self.N * self.m
        out[0, :j] = useq.reshape(-1, 1)
        out[0, j:j + self.n] = x.reshape(-1, 1)
        return out

    def boxes(self, useqs: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Boxes ``[u_seq, x, constants]`` of the exact graph's input, shape (K, dim, 2):
        thin in ``u_seq`` and ``x``."""
        k = useqs.shape[0]
        out = np.empty((k, useqs.shape[1] + x.size + self.param_lo.size, 2))
        j = useqs.shape[1]
        out[:, :j, 0] = useqs
        out[:, :j, 1] = useqs
        out[:, j:j + x.size, 0] = x
        out[:, j:j + x.size, 1] = x
        out[:, j + x.size:, 0] = self.param_lo
        out[:, j + x.size:, 1] = self.param_hi
        return out


class _StepCalls:
    """The evaluations of one controller step at horizon N on arrays kept between steps:
    the start states (:attr:`_Horizon.start_states`), the NLP solver and the cost of a
    sequence. The solver's ``x0`` and ``p`` inputs are :attr:`z0` and :attr:`p`, the start
    states read their inputs from them. A solver that is not a ``casadi.Function`` (a
    stand-in with the keyword interface of ``nlpsol`` and a ``stats()`` method) is called as
    such."""

    def __init__(self, h: _Horizon) -> None:
        n, nm = h.n, h.N * h.m
        self.solver = h.solver
        self.z0 = np.zeros(h.n_z)
        self.p = np.zeros(n + 1)
        self.lam_x0 = np.zeros(h.n_z)
        self.lam_g0 = np.zeros(h.lbg.size)
        # multiple shooting: the start states are written straight into z0
        res = {0: self.z0[nm + h.n_t:]} if h.n_zx else None
        self.start = BufferedCall(h.start_states, args={0: self.z0[:nm], 1: self.p[:n]},
                                  res=res)
        self.solve: BufferedCall | None = None
        self.out: dict[str, np.ndarray] = {}
        S = h.solver
        if isinstance(S, ca.Function):
            idx = {name: S.index_in(name) for name in S.name_in()}
            self.solve = BufferedCall(S, args={idx["x0"]: self.z0, idx["p"]: self.p,
                                               idx["lam_x0"]: self.lam_x0,
                                               idx["lam_g0"]: self.lam_g0},
                                      interruptible=True)
            for name, v in (("lbx", h.lbz), ("ubx", h.ubz), ("lbg", h.lbg), ("ubg", h.ubg)):
                self.solve.args[idx[name]][:] = v
            self.out = {name: self.solve.res[S.index_out(name)] for name in S.name_out()}
        self.bounds = h.bounds

    def run(self, warm: bool) -> tuple[np.ndarray, float, np.ndarray, np.ndarray, Any]:
        """Solve from :attr:`z0`, :attr:`p` and (``warm``) the multipliers in
        :attr:`lam_x0`, :attr:`lam_g0`: ``(x, f, lam_x, lam_g, stats source)``; the arrays
        are overwritten by the next call. Ctrl-C raises ``KeyboardInterrupt``."""
        if self.solve is not None:
            try:
                if not warm:
                    self.lam_x0.fill(0.0)
                    self.lam_g0.fill(0.0)
                self.solve()
                o = self.out
                return o["x"], float(o["f"][0]), o["lam_x"], o["lam_g"], self.solve
            except RuntimeError:
                pass  # the plain call below raises the solver's own error
        kw = {"lam_x0": self.lam_x0, "lam_g0": self.lam_g0} if warm else {}
        with solver_call():
            sol = self.solver(x0=self.z0, p=self.p, **kw, **self.bounds)
        return (np.asarray(sol["x"], dtype=float).ravel(),
                float(np.asarray(sol["f"], dtype=float).reshape(-1)[0]),
                np.asarray(sol["lam_x"], dtype=float).ravel(),
                np.asarray(sol["lam_g"], dtype=float).ravel(), self.solver)


# ------------------------------------------------------------------------- controller
class ContractiveMPC:
    """Contractive MPC of thesis §4.3 (Alg 4.5), verified by interval arithmetic.

    Parameters
    ----------
    model : Model
        The discrete-time model; its boxes X and U are the state and input constraints.
        A model with a disturbance ``w`` is predicted with ``w = w_nominal`` (default: the
        centre of W) and the certificates hold for that nominal value.
    horizon : int or None
        The horizon ``N >= 1``, or None to search for the smallest feasible one in
        ``[horizon_min, horizon_max]`` at every solve (Alg 4.5).
    alpha : float in (0, 1]
        Contraction parameter: ``||C (x(N) - x_ref)||_p <= alpha ||C (x(k) - x_ref)||_p``.
    Q, R, P : array_like, optional
        Weights of (4.22): ``Q`` (n, n) on ``x(1..N-1)``, ``P`` (n, n) on ``x(N)``
        (default ``Q``), symmetric positive semidefinite; ``R`` (m, m) on the inputs,
        symmetric positive definite. Defaults: identities. A scalar means that multiple of
        the identity, a vector a diagonal.
    norm : {1, 2, inf}
        The p-norm of the contraction. IPOPT gets smooth forms: the squared 2-norm, bounds
        for inf, and slack variables for 1.
    x_ref, u_ref : array_like, optional
        The reference equilibrium (default: the origin). ``f(x_ref, u_ref, w_nominal)`` must
        equal ``x_ref`` (relative tolerance 1e-9), ``u_ref`` must lie in U and ``x_ref`` in X.
    constraints : casadi.SX, optional
        Extra path constraints ``g(x, u) <= 0`` (a vector expression of the model's ``x``
        and ``u``, e.g. obstacle distances ``D^2 - |p - o|^2``). Components that depend on
        ``x`` only are imposed on ``x(1), ..., x(N)``; the others on ``(x(i), u(i))``,
        ``i = 0..N-1``.
    terminal : Polytope, optional
        Terminal constraint ``x(N) in terminal``.
    contract : array_like (q, n), optional
        The matrix ``C`` of the contraction (default: the identity); e.g. select the
        position components whose distance to the target must contract.
    local_law : LinearLaw, array_like (m, n) or casadi.SX, optional
        Dual mode: a :class:`~casadi_cmpc.LinearLaw` ``u = u_eq + K (x - x_eq)`` (what
        :func:`~casadi_cmpc.local_lqr` returns), or an expression of the model's ``x``,
        applied inside ``local_set``. A bare gain ``K`` means ``u = K x`` (as everywhere in
        the library) and is refused when ``x_ref`` or ``u_ref`` is not zero.
    local_set : Polytope, PolytopeUnion or Box, optional
        Where ``local_law`` is applied (default: ``terminal``).
    solver : {"ipopt", "sqp", "lp"}
        IPOPT (default), CasADi ``sqpmethod`` with ``qrqp``, or (linear models, ``norm`` 1
        or inf, or a Polytope gauge given as ``norm``) the LP form (3.5)-(3.6) by HiGHS.
    mode : {"sequence", "receding"}
        ``"sequence"`` (default, the scheme of thesis §2.4.1 whose closed loop carries a
        guarantee): apply the whole verified sequence before solving again. Each verified
        plan brings ``||C (x - x_ref)||`` down by the factor ``alpha`` after its N moves
        inside X with U respected (for ``w = w_nominal``), so the distance at the solve
        instants decays at least like ``alpha^j``. ``"receding"``: solve at every call and
        apply the first move only. Then "verified" promises that the plan computed at this
        step is feasible and contracting (constraint (2.8) holds for it); the next plan
        need not continue it, so neither the decrease of the distance nor recursive
        feasibility is guaranteed for the closed loop (see :attr:`guarantee`).
    horizon_min, horizon_max : int
        Range of the horizon search (``horizon=None``).
    verify : bool
        Re-evaluate every returned sequence in interval arithmetic (default True).
    search : {"auto", "always", "never"}
        Set inversion over ``U^N`` when the local solver gives no verified sequence
        (``"auto"``), before trusting any failure (``"always"``: same as auto), or never.
    search_eps : float, optional
        Width under which SIVIA stops bisecting (default: 1/64 of the widest input range).
    search_max_boxes, search_time_limit : int, float
        Budget of one set inversion; when it runs out the answer is "undecided".
    certify_optimal : bool
        Bracket the global optimum of (4.22) with :func:`casadi_cmpc.minimize` over
        ``U^N`` (small ``N m`` only); the bracket is in ``certificate.details``.
    solver_options : dict, optional
        Extra options of ``casadi.nlpsol``.
    solver_stats : bool
        Read the local solver's statistics (``return_status``, ``iter_count``) also for
        verified sequences (they are always read when a sequence is not verified; reading
        them costs about 40 µs after IPOPT).
    backoff : float
        Relative tightening of the constraints given to the local solver (default 1e-6):
        its solution then satisfies the exact constraints with a margin that survives the
        interval re-check. Nothing is claimed from the tightening itself.
    shooting : {"multiple", "single"}
        Form of the local solver's NLP. ``"multiple"`` (default): the predicted states are
        variables tied to the model by equality rows, started from the prediction of the
        warm-started sequence; the KKT systems are sparse and banded, which about halves the
        time of ``sqpmethod`` at N = 10. ``"single"``: the model is composed with itself and
        only the controls are variables. Either way the returned sequence is re-checked by
        intervals from x alone and its cost is evaluated from x (the states the solver
        returns are not used). On convex problems both forms have the same solution; on
        nonconvex ones (path constraints, obstacles) the local solver may end at
        different local optima in the two forms.

    Examples
    --------
    >>> import casadi_cmpc as cm, numpy as np
    >>> ex = cm.models.load("cannon")
    >>> ctrl = cm.ContractiveMPC(ex.model, horizon=5, alpha=0.9)
    >>> r = ctrl.solve([0.3, -0.2])
    >>> r.certificate.label, r.u_seq.shape
    ('verified', (5, 1))
    """

    def __init__(self, model: Model, horizon: int | None = None, alpha: float = 0.9,
                 Q: Any = None, R: Any = None, P: Any = None, norm: Any = 2, *,
                 x_ref: Any = None, u_ref: Any = None, w_nominal: Any = None,
                 constraints: Any = None, terminal: Polytope | None = None,
                 contract: Any = None, local_law: Any = None, local_set: Any = None,
                 solver: str = "ipopt", mode: str = "sequence", horizon_min: int = 1,
                 horizon_max: int = 10, verify: bool = True, search: str = "auto",
                 search_eps: float | None = None, search_max_boxes: int = 20000,
                 search_time_limit: float = 5.0, certify_optimal: bool = False,
                 optimal_eps: float | None = None, solver_options: dict | None = None,
                 backoff: float = 1e-6, solver_stats: bool = False,
                 shooting: str = "multiple") -> None:
        if not isinstance(model, Model):
            raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
        if model.m == 0:
            raise ModelError(f"model '{model.name}' has no input to control")
        self.model = model
        n, m = model.n, model.m
        self._n, self._m = n, m  # the model's sizes (read on every step)
        solver = str(solver).lower()
        if solver not in _SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(_SOLVERS)}; got {solver!r}")
        self.solver = solver
        mode = str(mode).lower()
        if mode not in _MODES:
            raise ValueError(f"mode must be one of {', '.join(_MODES)}; got {mode!r}")
        self.mode = mode
        self.alpha = _alpha(alpha)
        self.gauge: Polytope | None = None
        if isinstance(norm, Polytope):
            if solver != "lp":
                raise ValueError("a Polytope gauge as norm needs solver='lp'")
            self.gauge = norm
            self.norm = math.nan
        else:
            self.norm = _norm(norm)
        self.Q = _weight(Q, n, "Q", definite=False, default=None)
        self.R = _weight(R, m, "R", definite=True, default=None)
        self.P = _weight(P, n, "P", definite=False, default=self.Q)
        self.w_nominal = (_vector(w_nominal, model.l, "w_nominal", model.W.mid)
                          if model.l else np.zeros(0))
        if model.l and not model.W.contains(self.w_nominal[None, :])[0]:
            raise ValueError(f"w_nominal {self.w_nominal.tolist()} is outside W")
        self.x_ref = _vector(x_ref, n, "x_ref", np.zeros(n))
        self.u_ref = _vector(u_ref, m, "u_ref", np.zeros(m))
        check_defined(model, self.w_nominal)
        self._check_reference()
        self.contract = (np.eye(n) if contract is None
                         else np.atleast_2d(np.asarray(contract, dtype=float)))
        if self.contract.ndim != 2 or self.contract.shape[1] != n:
            raise DimensionError(f"contract must be a (q, {n}) matrix; got shape "
                                 f"{np.shape(contract)}")
        if not np.isfinite(self.contract).all() or not self.contract.any():
            raise ValueError("contract must be finite and non-zero")
        self._plain_distance = bool(np.array_equal(self.contract, np.eye(n))
                                    and not self.x_ref.any())
        if terminal is not None:
            if not isinstance(terminal, Polytope):
                raise TypeError("terminal must be a Polytope (use its convex hull for a "
                                f"union); got {type(terminal).__name__}")
            if terminal.dim != n:
                raise DimensionError(f"terminal has dimension {terminal.dim}, the model n = {n}")
        self.terminal = terminal
        self._path = self._path_functions(constraints)
        self.constraints = constraints
        self._path_scale, self._terminal_scale = self._scales()
        self.local_law = local_law
        self.local_set = local_set if local_set is not None else terminal
        self._law = self._law_function(local_law) if local_law is not None else None
        if self._law is not None and self.local_set is None:
            raise ValueError("local_law needs local_set (or terminal) to say where it applies")
        if horizon is not None:
            horizon = self._int(horizon, "horizon")
        self.horizon = horizon
        self.horizon_min = self._int(horizon_min, "horizon_min")
        self.horizon_max = self._int(horizon_max, "horizon_max")
        if self.horizon_max < self.horizon_min:
            raise ValueError(f"horizon_max ({horizon_max}) < horizon_min ({horizon_min})")
        self.verify = bool(verify)
        search = str(search).lower()
        if search not in ("auto", "always", "never"):
            raise ValueError(f"search must be 'auto', 'always' or 'never'; got {search!r}")
        self.search = search
        widest = float((model.U.hi - model.U.lo).max())
        self.search_eps = (float(search_eps) if search_eps is not None
                           else (widest / 64 if widest > 0 else 1.0))
        if not self.search_eps > 0:
            raise ValueError(f"search_eps must be positive; got {search_eps!r}")
        self.search_max_boxes = int(search_max_boxes)
        self.search_time_limit = float(search_time_limit)
        self.certify_optimal = bool(certify_optimal)
        self.optimal_eps = optimal_eps
        self.solver_options = dict(solver_options or {})
        self.backoff = float(backoff)
        self.solver_stats = bool(solver_stats)
        shooting = str(shooting).lower()
        if shooting not in ("multiple", "single"):
            raise ValueError(f"shooting must be 'multiple' or 'single'; got {shooting!r}")
        self.shooting = shooting
        if not 0 <= self.backoff < 0.1:
            raise ValueError(f"backoff must lie in [0, 0.1); got {backoff!r}")
        self._horizons: dict[int, Any] = {}
        self._warm: dict[int, np.ndarray] = {}
        self._lam: dict[int, bool] = {}  # horizons whose solver holds warm multipliers
        self._claims: dict[int, str] = {}
        self._queue: list[tuple[np.ndarray, np.ndarray, MPCResult]] = []
        self.last_result: MPCResult | None = None
        self.last_info: dict | None = None
        if solver == "lp":
            self._setup_lp()

    # ------------------------------------------------------------------ set-up helpers
    @staticmethod
    def _int(v: Any, name: str) -> int:
        if isinstance(v, (str, bytes)):
            raise ValueError(f"{name} must be an integer >= 1, not the string {v!r}")
        if isinstance(v, (bool, np.bool_)) or not float(v).is_integer():
            raise ValueError(f"{name} must be an integer >= 1; got {v!r}")
        k = int(v)
        if k < 1:
            raise ValueError(f"{name} must be an integer >= 1; got {v!r}")
        return k

    def _check_reference(self) -> None:
        model, xr, ur = self.model, self.x_ref, self.u_ref
        if not model.X.contains(xr[None, :])[0]:
            raise ValueError(f"x_ref {xr.tolist()} lies outside X = {model.X!r}")
        if not model.U.contains(ur[None, :])[0]:
            raise ValueError(f"u_ref {ur.tolist()} lies outside U = {model.U!r}")
        model.check_equilibrium(xr, ur, self.w_nominal if model.l else None, "x_ref, u_ref")

    def _path_functions(self, g: Any) -> tuple[ca.Function | None, ca.Function | None]:
        if g is None:
            return None, None
        model = self.model
        if isinstance(g, (list, tuple)):
            g = ca.vertcat(*g)
        if not isinstance(g, ca.SX):
            raise TypeError("constraints must be a casadi.SX expression of the model's x and "
                            f"u; got {type(g).__name__}")
        g = ca.reshape(ca.densify(g), g.numel(), 1)
        allowed = {s.__hash__() for s in ca.symvar(ca.vertcat(model.x, model.u))}
        free = [s for s in ca.symvar(g) if s.__hash__() not in allowed]
        if free:
            from ..exceptions import FreeSymbolError

            raise FreeSymbolError("constraints may depend on the model's x and u only; they "
                                  "depend on " + ", ".join(str(s) for s in free))
        dep_u = [bool(ca.depends_on(g[i], model.u)) for i in range(g.numel())]
        gx = [g[i] for i in range(g.numel()) if not dep_u[i]]
        gxu = [g[i] for i in range(g.numel()) if dep_u[i]]
        fx = ca.Function("g_x", [model.x], [ca.vertcat(*gx)]) if gx else None
        fxu = ca.Function("g_xu", [model.x, model.u], [ca.vertcat(*gxu)]) if gxu else None
        return fx, fxu

    def _scales(self) -> tuple[np.ndarray, np.ndarray]:
        """Ranges of the path constraints over X x U and of the terminal rows over X: the
        local solver's constraints are tightened by ``backoff`` times these."""
        model = self.model
        parts = []
        X, U = model.X.as_array(), model.U.as_array()
        for fun, args in ((self._path[1], (X, U)), (self._path[0], (X,))):
            if fun is None:
                continue
            Y = InclusionFunction(fun, "natural")(*args)[0][0]
            w = Y[:, 1] - Y[:, 0]
            parts.append(np.where(np.isfinite(w) & (w > 0), w, 1.0))
        path = np.concatenate(parts) if parts else np.zeros(0)
        term = (np.abs(self.terminal.A) @ (model.X.hi - model.X.lo)
                if self.terminal is not None else np.zeros(0))
        return path, term

    def _law_function(self, law: Any) -> ca.Function:
        """The local law as a Function ``x -> u`` (one convention: see
        :mod:`casadi_cmpc.control.law`). A bare gain is ``u = K x`` everywhere; at a
        reference other than the origin it is ambiguous and refused."""
        from ..control.law import LinearLaw, as_law, law_expr

        model = self.model
        lw = as_law(law, model.m, model.n)
        if (isinstance(lw, LinearLaw) and not isinstance(law, LinearLaw)
                and (np.any(self.x_ref) or np.any(self.u_ref))):
            raise ValueError(
                "local_law is a bare gain K and the reference is not the origin: a bare gain "
                "means u = K x everywhere in casadi_cmpc; give cm.LinearLaw(K, x_eq=x_ref, "
                "u_eq=u_ref) for u = u_ref + K (x - x_ref) (cm.local_lqr returns one)")
        return ca.Function("local_law", [model.x], [law_expr(model, lw)])

    def _setup_lp(self) -> None:
        if not self.model.is_linear:
            raise ModelError("solver='lp' needs a linear model (x+ = A x + B u)")
        if not np.array_equal(self.contract, np.eye(self.model.n)):
            raise ValueError("solver='lp' contracts the whole state (contract must be the "
                             "identity); use solver='ipopt' for a contraction matrix")
        A, B, _, c = self.model.linear_matrices()
        if np.any(c != 0):
            raise ModelError(
                f"solver='lp' needs f = A x + B u exactly; '{self.model.name}' has the "
                f"constant term {c.tolist()} (use solver='ipopt', which handles it)")
        # the LP and its Farkas proofs use A and B as exact numbers: the model's coefficients
        # must be floats, not sums of literals that CasADi rounded (0.1 x + 0.2 x)
        n, m = self.model.n, self.model.m
        J = self.model.jacobian_inclusion("x")(np.zeros((1, n, 2)), np.zeros((1, m, 2)))[0]
        Ju = self.model.jacobian_inclusion("u")(np.zeros((1, n, 2)), np.zeros((1, m, 2)))[0]
        if not (np.array_equal(J[..., 0], J[..., 1]) and np.array_equal(Ju[..., 0], Ju[..., 1])
                and np.array_equal(J[..., 0], A) and np.array_equal(Ju[..., 0], B)):
            raise ModelError(
                f"solver='lp' needs the coefficients of '{self.model.name}' to be exact "
                "floats; some are rounded sums or products of literals (e.g. 0.1 x + 0.2 x): "
                "write each coefficient as one number, or use solver='ipopt'")
        if self.gauge is None and self.norm == 2:
            raise ValueError("solver='lp' handles norm 1, inf or a Polytope gauge, not 2")
        if self._path != (None, None):
            raise ValueError("solver='lp' does not take nonlinear path constraints")
        if self.model.l:
            raise ModelError("solver='lp' is for models without disturbance")

    def _get(self, N: int) -> _Horizon:
        h = self._horizons.get(N)
        if h is None:
            h = self._horizons[N] = _Horizon(self, N)
        return h

    # ---------------------------------------------------------------------- solving
    def __call__(self, x: Any) -> np.ndarray:
        """The move to apply at state ``x``: shape (m,).

        In ``mode="sequence"`` the rest of the last verified sequence is applied move by
        move as long as the state equals its prediction (to 1e-9 relative); a state off the
        prediction (a disturbance, or a call from another state) triggers a new solve.
        """
        t0 = time.perf_counter()
        if self.mode == "sequence" and self._queue:
            xk = _state(x, self._n)
            u, x_pred, plan = self._queue[0]
            tol = 1e-9 * (1.0 + float(np.abs(x_pred).max()))
            if float(np.abs(xk - x_pred).max()) <= tol:
                self._queue.pop(0)
                self.last_info = {"status": plan.status.name,
                                  "certificate": plan.certificate.label,
                                  "horizon": plan.horizon,
                                  "solve_time": time.perf_counter() - t0, "mode": "sequence"}
                return u.copy()
            self._queue.clear()
        r = self.solve(x)
        if self.mode == "sequence" and r.mode == "mpc" and r.certificate.proved:
            self._queue = [(r.u_seq[i].copy(), r.x_pred[i].copy(), r)
                           for i in range(1, r.u_seq.shape[0])]
        self.last_info["solve_time"] = time.perf_counter() - t0
        return r.u.copy()

    def reset(self) -> None:
        """Forget warm starts and the queued sequence."""
        self._warm.clear()
        self._lam.clear()
        self._queue.clear()
        self.last_result = None
        self.last_info = None

    def solve(self, x: Any) -> MPCResult:
        """Solve at state ``x`` (shape (n,)) and return the :class:`MPCResult`.

        Also sets ``last_result`` and ``last_info`` (the dict :func:`casadi_cmpc.simulate`
        records: ``status``, ``certificate``, ``horizon``, ``solve_time``, ``mode``).
        """
        t0 = time.perf_counter()
        xk = _state(x, self._n)
        # C = I and x_ref = 0: C (x - x_ref) is x (up to the sign of zeros)
        e0 = xk if self._plain_distance else self.contract @ (xk - self.x_ref)
        r0 = self._norm_value(e0)
        # x = x_ref gives r0 = 0: the reference is tested among the small distances only
        if not r0 >= _TINY and np.array_equal(xk, self.x_ref):
            res = self._special(xk, self.u_ref.copy(), "at_reference",
                                "the state is the reference: u_ref is applied", t0)
        elif not r0 >= _TINY:
            res = self._special(
                xk, self.u_ref.copy(), "unverified",
                f"the contracted distance ||C (x - x_ref)|| = {r0:.3g} is 0 or below "
                f"{_TINY:g}: there is nothing to contract; u_ref is applied and nothing is "
                "claimed", t0, mode="nothing_to_contract")
        elif self._law is not None and self._in_local_set(xk):
            u = np.asarray(self._law(xk), dtype=float).reshape(self.model.m)
            res = self._special(xk, u, "local_law",
                                "the state is proven inside local_set: the local law is "
                                "applied", t0)
        elif self.horizon is not None:
            res = self._solve_fixed(xk, r0, self.horizon, t0)
        else:
            res = self._search_horizon(xk, r0, t0)
        self.last_result = res
        self.last_info = {"status": res.status.name, "certificate": res.certificate.label,
                          "horizon": res.horizon, "solve_time": time.perf_counter() - t0,
                          "mode": res.mode}
        return res

    def _norm_value(self, e: np.ndarray) -> float:
        if self.gauge is not None:
            P = self.gauge
            return float(max(0.0, np.max(P.A @ e / (P.b - P.A @ self.x_ref))))
        if self.norm == 2 and e.ndim == 1:  # what np.linalg.norm computes for a vector
            return math.sqrt(float(e.dot(e)))
        return float(np.linalg.norm(e, ord=self.norm))

    def _in_local_set(self, x: np.ndarray) -> bool:
        """Membership of x in local_set, proven (a thin box certified inside)."""
        S = self.local_set
        box = np.stack([x, x], axis=-1)[None]
        return bool(np.asarray(S.contains_box(box)).reshape(-1)[0])

    def _special(self, x: np.ndarray, u: np.ndarray, label: str, reason: str,
                 t0: float, mode: str | None = None) -> MPCResult:
        cert = Certificate(label, None, "no optimisation at this state", reason)
        xp = np.vstack([x, self.model.step(x, u, self.w_nominal if self.model.l else None)])
        return MPCResult(status=Status.UNDECIDED, message=reason, method="contractive_mpc",
                         nit=0, n_boxes=0, elapsed=time.perf_counter() - t0, x=x, u=u,
                         u_seq=u[None, :], x_pred=xp, cost=math.nan, horizon=None,
                         certificate=cert, stats={}, mode=mode or label)

    # one horizon ------------------------------------------------------------------
    def _local(self, x: np.ndarray, r0: float, N: int, start: np.ndarray | None
               ) -> tuple[np.ndarray | None, dict]:
        """Local solve at horizon N: (clipped sequence or None, stats)."""
        if self.solver == "lp":
            return self._local_lp(x, N)
        h = self._get(N)
        m, n = self._m, self._n
        nm = N * m
        c = h.calls()
        z0 = c.z0
        if start is not None:
            z0[:nm] = start.ravel()
        else:
            warm = self._warm.get(N)
            if warm is not None:  # the last sequence shifted by one move
                z0[:nm - m] = warm[1:].ravel()
                z0[nm - m:nm] = warm[-1]
            else:
                z0[:nm] = np.tile(np.clip(self.u_ref, self.model.U.lo, self.model.U.hi), N)
        c.p[:n] = x
        c.p[n] = 1.0 / r0
        if h.n_t or h.n_zx:
            # the states x(1..N) predicted from the start sequence (with multiple shooting
            # written into z0 as the start of the state variables)
            c.start()
            if h.n_t:  # 1-norm slacks
                eN = self.contract @ (c.start.res[0][-n:] - self.x_ref)
                z0[nm:nm + h.n_t] = np.abs(eN) / r0 + 1e-3
        # the multipliers of the last solve at this horizon are in c.lam_x0, c.lam_g0
        warm_lam = start is None and N in self._lam
        t = time.perf_counter()
        z, f, lam_x, lam_g, src = c.run(warm_lam)
        dt = time.perf_counter() - t
        stats = {"solver": self.solver, "solve_time": dt, "_fun": src}
        if not np.isfinite(z).all():
            self._lam.pop(N, None)
            _read_stats(stats)
            return None, stats
        np.copyto(c.lam_x0, lam_x)
        np.copyto(c.lam_g0, lam_g)
        self._lam[N] = True
        raw = z[:nm].reshape(N, m)
        u = np.clip(raw, self.model.U.lo, self.model.U.hi)
        if not h.n_zx and np.array_equal(u, raw):
            # the NLP's cost is the sequence's only when the states are the composed
            # prediction (with multiple shooting they are the solver's, defects open)
            stats["_cost"] = f
        return u, stats

    def _local_lp(self, x: np.ndarray, N: int) -> tuple[np.ndarray | None, dict]:
        from .linear import ContractiveLP

        key = ("lp", N)
        lp = self._horizons.get(key)
        if lp is None:
            A, B = self.model.linear_matrices()[:2]
            gauge = self.gauge if self.gauge is not None else self.norm
            lp = self._horizons[key] = ContractiveLP(
                A, B, self.model.X, self.model.U, N, self.alpha, gauge, x_ref=self.x_ref,
                u_ref=self.u_ref, terminal=self.terminal, backoff=self.backoff)
        t = time.perf_counter()
        step = lp.solve(x)
        stats = {"solver": "lp", "return_status": step.status, "success":
                 step.status == "optimal", "iter_count": 0,
                 "solve_time": time.perf_counter() - t}
        if step.status == "infeasible" and step.proof is not None:
            stats["_lp_proof"] = {
                "horizon": N, "result": "infeasible", "boxes": 0,
                "elapsed": stats["solve_time"],
                "how": "exactly checked Farkas certificate of the LP (3.5)-(3.6): "
                       + str(step.proof.get("statement", "")),
                "margin": float(step.proof.get("margin", np.nan))}
        if step.status != "optimal":
            return None, stats
        return np.asarray(step.u_seq, dtype=float), stats

    def _check(self, x: np.ndarray, N: int, useq: np.ndarray) -> tuple[bool, dict]:
        """Interval re-evaluation of ``useq`` from the exact ``x``: (verified, details)."""
        h = self._get_check(N)
        box = h.check_box(useq, x)
        Y = h.step_check.evaluate_unchecked([box], 1)[0][0]
        # slack >= 0 on every row <=> verified (NaN-free by the inclusion's contract): the
        # slacks Y_lo - lo and hi - Y_hi = -(Y_hi - hi), both columns in one pass
        with np.errstate(invalid="ignore"):  # inf - inf (an unbounded enclosure): NaN,
            slack = Y.reshape(-1) - h.check_bounds  # which fails the test below
        slack *= h.check_signs
        margin = float(slack.min())
        details = {"min_margin": margin, "contraction_upper": float(Y[-1, 1]), "_Y": Y}
        if margin >= 0:
            return True, details
        bad = int(np.flatnonzero(~(slack.reshape(-1, 2) >= 0).all(axis=1))[0])
        details["failed"] = self._describe_row(h, bad, Y[bad])
        return False, details

    def _get_check(self, N: int) -> _Horizon:
        if self.solver == "lp":
            key = ("lpcheck", N)
            h = self._horizons.get(key)
            if h is None:
                h = self._horizons[key] = _Horizon(self, N, nlp=False)
            return h
        return self._get(N)

    def _describe_row(self, h: Any, row: int, y: np.ndarray) -> str:
        lo, hi = h.check_lo[row], h.check_hi[row]
        want = f"<= {hi:.6g}" if not np.isfinite(lo) else f"in [{lo:.6g}, {hi:.6g}]"
        return f"{h.labels[row]}: enclosure [{y[0]:.6g}, {y[1]:.6g}], required {want}"

    def _attempt(self, x: np.ndarray, r0: float, N: int, start: np.ndarray | None = None
                 ) -> tuple[np.ndarray | None, bool, dict, dict]:
        """Local solve + verification at horizon N."""
        u, stats = self._local(x, r0, N, start)
        if u is None:
            return None, False, stats, {"failed": "the local solver returned no sequence"}
        if not self.verify:
            _read_stats(stats)
            if stats.get("success"):
                self._warm[N] = u.copy()
            return u, False, stats, {"failed": "verification switched off (verify=False)"}
        t = time.perf_counter()
        ok, details = self._check(x, N, u)
        stats["verify_time"] = time.perf_counter() - t
        if not ok or self.solver_stats:
            _read_stats(stats)
        return u, ok, stats, details

    def _solve_fixed(self, x: np.ndarray, r0: float, N: int, t0: float) -> MPCResult:
        u, ok, stats, details = self._attempt(x, r0, N)
        stats["horizons_tried"] = [N]
        if ok:
            return self._verified(x, N, u, stats, details, t0, [])
        proofs: list[dict] = []
        if self.search != "never" and self.verify:
            found, proof = self._prove(x, r0, N, stats)
            proofs.append(proof)
            stats["search_time"] = proof["elapsed"]
            if found is not None:
                return self._verified(x, N, found, stats, proof.get("details", {}), t0,
                                      proofs)
            if proof["result"] == "infeasible":
                return self._infeasible(x, [N], u, stats, proofs, t0)
        return self._unverified(x, N, u, stats, details, proofs, t0)

    def _search_horizon(self, x: np.ndarray, r0: float, t0: float) -> MPCResult:
        """Alg 4.5: the horizons ``horizon_min..horizon_max`` in turn, until one is
        verified. A horizon proven infeasible is left as in Alg 4.5; one whose search did
        not decide is left too (it proves nothing), and "infeasible" is claimed only when
        every horizon tried was proven infeasible.

        What is computed at one horizon (local sequence, solver statistics, check details)
        is used only at that horizon: the result reports the horizon its sequence belongs
        to. When the search ends without a verified sequence, that is the last horizon
        tried, with its own local sequence, or else the fallback of that horizon
        (:meth:`_fallback`); the proofs of all horizons tried are attached.
        """
        proofs: list[dict] = []
        tried: list[int] = []
        u: np.ndarray | None = None
        stats: dict = {}
        details: dict = {}
        for N in range(self.horizon_min, self.horizon_max + 1):
            tried.append(N)
            u, ok, stats, details = self._attempt(x, r0, N)
            stats["horizons_tried"] = list(tried)
            if ok:
                return self._verified(x, N, u, stats, details, t0, proofs)
            if self.search == "never" or not self.verify:
                continue
            found, proof = self._prove(x, r0, N, stats)
            proofs.append(proof)
            if found is not None:
                return self._verified(x, N, found, stats, proof.get("details", {}), t0,
                                      proofs)
            # an undecided horizon proves nothing: the search goes on to the next one
        if (self.search == "never" or not self.verify
                or any(p.get("result") != "infeasible" for p in proofs)):
            return self._unverified(x, tried[-1], u, stats, details, proofs, t0)
        return self._infeasible(x, tried, u, stats, proofs, t0)

    def _sequence(self, N: int, u: np.ndarray | None) -> None:
        """Refuse a sequence that does not belong to horizon N (shape (N, m))."""
        if u is not None and np.shape(u) != (N, self._m):
            raise RuntimeError(
                f"internal error: a control sequence of shape {np.shape(u)} was about to be "
                f"used at horizon {N} (shape ({N}, {self.model.m}) expected)")

    # set inversion over U^N -------------------------------------------------------
    def _prove(self, x: np.ndarray, r0: float, N: int, stats: dict
               ) -> tuple[np.ndarray | None, dict]:
        """An exact LP infeasibility certificate when the LP gave one, else set inversion."""
        lp_proof = stats.pop("_lp_proof", None)
        if lp_proof is not None:
            return None, lp_proof
        return self._set_inversion(x, r0, N)

    def _set_inversion(self, x: np.ndarray, r0: float, N: int
                       ) -> tuple[np.ndarray | None, dict]:
        """Find a verified sequence or prove that none exists at horizon N."""
        from ..solvers.sivia import sivia

        t = time.perf_counter()
        h = self._get_check(N)
        m = self.model.m
        F = h.check_inclusion
        Ulo, Uhi = np.tile(self.model.U.lo, N), np.tile(self.model.U.hi, N)
        # 1. cheap candidates: random sequences, checked in one batch
        rng = np.random.default_rng(0)
        K = 256
        cand = Ulo + (Uhi - Ulo) * rng.random((K, N * m))
        cand[0] = 0.5 * (Ulo + Uhi)
        found = self._best_verified(h, F, x, cand, N)
        if found is not None:
            return found, {"horizon": N, "result": "feasible", "boxes": 0,
                           "elapsed": time.perf_counter() - t,
                           "how": "a sampled sequence passed the interval check"}
        # 2. SIVIA over U^N x {x}
        Z = Box(np.concatenate([Ulo, x, h.param_lo]), np.concatenate([Uhi, x, h.param_hi]))
        Y = Box(h.check_lo, h.check_hi)
        pav = sivia(F, Z, Y, self.search_eps, max_boxes=self.search_max_boxes,
                    time_limit=self.search_time_limit, keep_outer=False, progress=False)
        n_boxes = int(getattr(pav, "n_classified", pav.n_boxes))
        proof = {"horizon": N, "boxes": n_boxes, "discarded": int(pav.n_discarded),
                 "elapsed": 0.0, "eps": self.search_eps}
        if pav.inner.shape[0]:
            mid = 0.5 * (pav.inner[:, :N * m, 0] + pav.inner[:, :N * m, 1])
            found = self._best_verified(h, F, x, mid, N)
            if found is not None:
                proof.update(result="feasible", how="an inner box of SIVIA over U^N")
                proof["elapsed"] = time.perf_counter() - t
                return found, proof
        if pav.inner.shape[0] == 0 and pav.boundary.shape[0] == 0:
            proof.update(result="infeasible",
                         how=f"SIVIA over U^{N} discarded every box: no sequence in U^{N} "
                             "satisfies the constraints")
            proof["elapsed"] = time.perf_counter() - t
            return None, proof
        # 3. undecided boxes: their midpoints, then local solves started from them
        if pav.boundary.shape[0]:
            mids = 0.5 * (pav.boundary[:, :N * m, 0] + pav.boundary[:, :N * m, 1])
            found = self._best_verified(h, F, x, mids, N)
            if found is None and self.solver != "lp":
                order = np.argsort(np.max(pav.boundary[:, :N * m, 1]
                                          - pav.boundary[:, :N * m, 0], axis=1))[::-1]
                for k in order[:3]:
                    u, ok, _, _ = self._attempt(x, r0, N, start=mids[k])
                    if ok:
                        found = u
                        break
            if found is not None:
                proof.update(result="feasible",
                             how="a sequence from an undecided box of SIVIA passed the check")
                proof["elapsed"] = time.perf_counter() - t
                return found, proof
        budget = pav.status == Status.BUDGET
        proof.update(result="undecided",
                     how=("the search budget ran out" if budget else
                          f"{pav.boundary.shape[0]} boxes narrower than eps stayed undecided"),
                     budget=bool(budget))
        proof["elapsed"] = time.perf_counter() - t
        return None, proof

    def _best_verified(self, h: Any, F: InclusionFunction, x: np.ndarray, cand: np.ndarray,
                       N: int) -> np.ndarray | None:
        if cand.shape[0] == 0:
            return None
        Y = F.evaluate_unchecked([h.boxes(cand, x)], cand.shape[0])[0]
        ok = ((Y[:, :, 0] >= h.check_lo) & (Y[:, :, 1] <= h.check_hi)).all(axis=1)
        if not ok.any():
            return None
        good = cand[ok]
        costs = self._costs(N, good, x)
        return good[int(np.argmin(costs))].reshape(N, self.model.m)

    def _costs(self, N: int, useqs: np.ndarray, x: np.ndarray) -> np.ndarray:
        h = self._get_check(N)
        fm = h._batch.get(useqs.shape[0])
        if fm is None:
            fm = h._batch[useqs.shape[0]] = h.cost_fun.map(useqs.shape[0])
        z = np.concatenate([useqs, np.broadcast_to(x, (useqs.shape[0], x.size))], axis=1)
        return np.asarray(fm(z.T), dtype=float).ravel()

    # results ------------------------------------------------------------------------
    def _predict(self, N: int, u: np.ndarray, x: np.ndarray) -> tuple[float, np.ndarray]:
        return self._get_check(N).predict(u, x)

    def _optimality(self, x: np.ndarray, N: int) -> dict:
        from ..solvers.minimize import minimize

        h = self._get_check(N)
        Z = Box(np.concatenate([np.tile(self.model.U.lo, N), x, h.param_lo]),
                np.concatenate([np.tile(self.model.U.hi, N), x, h.param_hi]))
        zs = ca.SX.sym("z", h.check_fun.numel_in(0))
        gv = h.check_fun(zs)
        rows = []
        for i in range(h.check_lo.size):
            if np.isfinite(h.check_hi[i]):
                rows.append(gv[i] - h.check_hi[i])
            if np.isfinite(h.check_lo[i]):
                rows.append(h.check_lo[i] - gv[i])
        g = ca.Function("g", [zs], [ca.vertcat(*rows)])
        eps = self.optimal_eps or self.search_eps
        r = minimize(h.exact_cost, Z, eps, constraints=g, max_boxes=self.search_max_boxes,
                     time_limit=self.search_time_limit, progress=False)
        out = {"lower": float(r.lower), "upper": float(r.upper),
               "width": float(r.upper - r.lower), "status": r.status.name,
               "boxes": int(r.n_boxes)}
        if self.model.is_validated:
            # the search also minimises over the remainder's interval parameters: its
            # lower bound holds for the true flow, its upper bound only for the Taylor
            # enclosure's best member, not for the flow
            out.update(upper=math.inf, width=math.inf,
                       note="validated ODE model: only the lower bound is proven")
        return out

    def _verified(self, x: np.ndarray, N: int, u: np.ndarray, stats: dict, details: dict,
                  t0: float, proofs: list[dict]) -> MPCResult:
        self._sequence(N, u)
        self._warm[N] = u.copy()
        details = dict(details)
        Y = details.pop("_Y", None)
        cost = stats.pop("_cost", None)
        stats.pop("_fun", None)
        if Y is None or cost is None:
            cost, xp = self._predict(N, u, x)
        else:  # the midpoints of the verified enclosures of x(1..N)
            k = N * self._n
            x_mid = 0.5 * Y[:k, 0] + 0.5 * Y[:k, 1]
            xp = np.vstack([x, x_mid.reshape(N, self._n)])
        if proofs:
            details["proofs"] = proofs
        claim = self._claims.get(N)
        if claim is None:
            w = (f" with the nominal disturbance w = {self.w_nominal.tolist()} only (other "
                 "w in W are not covered)" if self.model.l else "")
            about = ("" if self.model.discretisation == "discrete model"
                     else f" (model: {self.model.discretisation})")
            claim = self._claims[N] = (
                f"the sequence keeps x(1..{N}) in X, satisfies every extra constraint and "
                f"contracts the {self._norm_name()} by alpha = {self.alpha}{w}{about}")
        if self.certify_optimal:
            details["optimal_bracket"] = self._optimality(x, N)
        cert = Certificate("verified", True, claim,
                           "interval re-evaluation from the exact state, outward rounding",
                           details)
        n_boxes = sum(int(p.get("boxes", 0)) for p in proofs)
        return MPCResult(status=Status.PROVED, message=f"verified at horizon {N}",
                         method=f"contractive_mpc/{self.solver}",
                         nit=int(stats.get("iter_count") or 0), n_boxes=n_boxes,
                         elapsed=time.perf_counter() - t0, x=x, u=u[0].copy(), u_seq=u,
                         x_pred=xp, cost=cost, horizon=N, certificate=cert, stats=stats)

    def _norm_name(self) -> str:
        if self.gauge is not None:
            return "gauge of the given polytope around x_ref"
        p = {1.0: "1", 2.0: "2", math.inf: "inf"}[self.norm]
        return f"{p}-norm of C (x - x_ref)"

    def _fallback(self, x: np.ndarray, N: int, u: np.ndarray | None) -> np.ndarray:
        """The sequence applied when nothing is verified: the local solution, or the tail
        of the last verified sequence, or u_ref (all clipped into U); shape (N, m)."""
        self._sequence(N, u)
        if u is not None:
            return u
        warm = self._warm.get(N)
        if warm is not None:
            return np.concatenate([warm[1:], warm[-1:]])
        return np.tile(np.clip(self.u_ref, self.model.U.lo, self.model.U.hi), (N, 1))

    def _unverified(self, x: np.ndarray, N: int, u: np.ndarray | None, stats: dict,
                    details: dict, proofs: list[dict], t0: float) -> MPCResult:
        stats = {k: v for k, v in stats.items() if not k.startswith("_")}
        details = {k: v for k, v in details.items() if not k.startswith("_")}
        seq = self._fallback(x, N, u)
        cost, xp = self._predict(N, seq, x)
        budget = any(p.get("budget") for p in proofs)
        open_ = [p for p in proofs if p.get("result") != "infeasible"]
        undecided = bool(open_)
        label = "undecided" if undecided else "unverified"
        reason = details.get("failed", "")
        if undecided:
            hs = [int(p["horizon"]) for p in open_ if "horizon" in p]
            inf = [int(p["horizon"]) for p in proofs
                   if p.get("result") == "infeasible" and "horizon" in p]
            reason = (f"no verified sequence at horizon(s) {hs or [N]}: the local solver gave "
                      f"none and the search over U^N did not decide ({open_[-1]['how']})"
                      + (f"; horizon(s) {inf} proven infeasible" if inf else "")
                      + f"; the sequence applied is horizon {N}'s (not verified)")
        details = dict(details)
        if proofs:
            details["proofs"] = proofs
        cert = Certificate(label, None, f"a feasible sequence exists at horizon {N}",
                           reason, details)
        # NUMERICAL only when the local solver failed and no search ran at this horizon
        status = Status.BUDGET if budget else (Status.UNDECIDED if u is not None or undecided
                                               else Status.NUMERICAL)
        return MPCResult(status=status, message=reason or label,
                         method=f"contractive_mpc/{self.solver}",
                         nit=int(stats.get("iter_count") or 0),
                         n_boxes=sum(int(p.get("boxes", 0)) for p in proofs),
                         elapsed=time.perf_counter() - t0, x=x, u=seq[0].copy(), u_seq=seq,
                         x_pred=xp, cost=cost, horizon=N, certificate=cert, stats=stats)

    def _infeasible(self, x: np.ndarray, tried: list[int], u: np.ndarray | None,
                    stats: dict, proofs: list[dict], t0: float) -> MPCResult:
        N = tried[-1]
        stats = {k: v for k, v in stats.items() if not k.startswith("_")}
        seq = self._fallback(x, N, u)
        cost, xp = self._predict(N, seq, x)
        hs = ", ".join(str(k) for k in tried)
        reason = (f"proved: no admissible sequence satisfies the constraints at horizon(s) "
                  f"{hs} (one proof per horizon in details['proofs'])")
        cert = Certificate("proved_infeasible", False,
                           f"a feasible sequence exists at some horizon in {hs}", reason,
                           {"proofs": proofs})
        return MPCResult(status=Status.DISPROVED, message=reason,
                         method=f"contractive_mpc/{self.solver}",
                         nit=int(stats.get("iter_count") or 0),
                         n_boxes=sum(int(p.get("boxes", 0)) for p in proofs),
                         elapsed=time.perf_counter() - t0, x=x, u=seq[0].copy(), u_seq=seq,
                         x_pred=xp, cost=cost, horizon=N, certificate=cert, stats=stats)

    def export_spec(self) -> ContractiveSpec:
        """The data the C export is generated from (see :mod:`casadi_cmpc.mpc.spec`).

        Internal API shared with :mod:`casadi_cmpc.codegen`: the local problem of the fixed
        horizon (``problem``; None without a fixed horizon or for the LP form), the local
        law and its set, and the settings the generated controller follows.

        Returns
        -------
        ContractiveSpec
        """
        problem = None
        if self.horizon is not None and self.solver != "lp":
            h = self._get(self.horizon)
            problem = HorizonProblem(
                horizon=h.N, nlp=h.nlp, plugin=h.plugin, options=dict(h.options), n_z=h.n_z,
                n_t=h.n_t, n_zx=h.n_zx, lbz=h.lbz, ubz=h.ubz, lbg=h.lbg, ubg=h.ubg,
                predict_states=h.start_states, check_fun=h.check_fun, check_lo=h.check_lo,
                check_hi=h.check_hi, param_lo=h.param_lo, param_hi=h.param_hi)
        return ContractiveSpec(
            model=self.model, solver=self.solver, horizon=self.horizon, mode=self.mode,
            gauge=self.gauge, norm=self.norm, contract=self.contract, x_ref=self.x_ref,
            u_ref=self.u_ref, w_nominal=self.w_nominal, local_law=self._law,
            local_set=self.local_set, problem=problem)

    def export_c(self, directory: Any, solver: str = "sqp", **kw: Any) -> Any:
        """Write this controller as standalone C (fixed horizon, receding mode); see
        :func:`casadi_cmpc.codegen.export_c` for the files, the ``cmpc_step`` API and the
        options. Returns an :class:`~casadi_cmpc.codegen.ExportInfo`."""
        from ..codegen import export_c

        return export_c(self, directory, solver=solver, **kw)

    @property
    def proof_w(self) -> np.ndarray:
        """The disturbances its verified plans are proven for, as a box (l, 2): the thin
        box at ``w_nominal``."""
        w = np.asarray(self.w_nominal, dtype=float).reshape(self.model.l)
        return np.stack([w, w], axis=-1)

    @property
    def guarantee(self) -> str:
        """What the closed loop under this controller is guaranteed (one sentence)."""
        w = (f" for w = {np.asarray(self.w_nominal).tolist()} (the nominal disturbance) only"
             if self.model.l else "")
        law = ""
        if self._law is not None:
            law = ("; inside the local set the local law is applied (its invariance is not "
                   "checked by this controller: certify it with cm.certify_invariant)")
        dist = f"the {self._norm_name()}"
        if self.mode == "sequence":
            return (f"each verified plan is applied in full: {dist} shrinks by the factor "
                    f"alpha = {self.alpha} over each plan, with X and U respected along it"
                    f"{w}; a step labelled other than verified carries no such promise"
                    + law)
        return (f"receding mode: each step labelled verified has a plan that is feasible "
                f"and contracts {dist} by alpha = {self.alpha}{w}; only its first move is "
                "applied, so the decrease of the distance along the closed loop is NOT "
                "guaranteed (mode='sequence' guarantees it)" + law)

    def __repr__(self) -> str:
        hz = self.horizon if self.horizon is not None else \
            f"search {self.horizon_min}..{self.horizon_max}"
        return (f"ContractiveMPC('{self.model.name}', horizon={hz}, alpha={self.alpha}, "
                f"norm={self._norm_name()}, solver='{self.solver}', mode='{self.mode}')")
