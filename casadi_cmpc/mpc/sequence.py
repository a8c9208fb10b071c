"""One-step MPC along a sequence of controllable sets (thesis Alg 4.7, 5.4, 6.3; (5.20)).

In ``K_i \\ K_{i-1}`` the controller solves the one-step problem (4.26)-(4.27)

    min_u max_{w in W}  f(x,u,w)' Q f(x,u,w) + u' R u   s.t.  f(x, u, w) in K_{i-1} for all w,

and applies the local law inside the terminal set ``K_0 = T``. Every applied control is
certified by interval arithmetic: ``f(x, u, W) ⊆ K_{i-1}``; when the solver's control cannot
be certified, the proving control stored with the sequence is applied instead.
"""

from __future__ import annotations

import time
from typing import Any

import casadi as ca
import numpy as np

from .._validate import float_vector, weight_matrix
from ..exceptions import DimensionError, ModelError
from ..model import Model
from ..sets.polytope import Polytope
from ..solvers.engine import Status
from ..solvers.result import Certificate
from .contractive import MPCResult, _solver_options

__all__ = ["SetSequenceMPC"]


def _members(S: Any) -> list[Any]:
    return list(getattr(S, "members", None) or getattr(S, "polytopes", None) or [S])


class SetSequenceMPC:
    """Dual-mode one-step MPC along a controllable-set sequence (Alg 4.7, 5.4, 6.3).

    Parameters
    ----------
    model : Model
    seq : SetSequence
        From :func:`casadi_cmpc.controllable_sets` (box unions with proving controls, or
        polytopes) or :func:`casadi_cmpc.linear_controllable_sets` (polytopes).
    Q : array_like (n, n), optional
        Weight of the successor state (default identity).
    R : array_like (m, m), optional
        Weight of the control (default identity).
    local_law : array_like (m, n) or casadi.SX, optional
        The law applied inside ``T = seq[0]`` (default: ``seq.info["law"]`` if present); a
        gain ``K`` (``u = K x``) or an expression of ``model.x``.
    solver : {"ipopt", "sqp"}
        Local solver of the one-step problem (built once, the state as parameter).
    robust : bool, optional
        Certify and optimise for all w in W (default: ``seq.info["robust"]``, else True
        when the model has a disturbance); False uses the centre of W.
    x_ref : array_like (n,), optional
        The cost penalises ``f - x_ref`` (default 0).
    solver_options : dict, optional
        Passed to ``casadi.nlpsol``.

    Notes
    -----
    **Robust minimax (5.20).** The cost's maximum over the vertices of W is taken through an
    epigraph variable, and for polytopic sets the constraint is imposed at every vertex. For a
    model affine in w this is exact (a convex set holds the image of W iff it holds the
    images of its vertices; the cost is convex in the successor). For other models the
    vertex maximum is a lower estimate of the worst-case cost; feasibility is not affected,
    since every applied control is certified by intervals over the whole W.

    **Sets held as box unions.** The solver minimises the cost over U; the control applied is
    the first of ``u*``, ``u_w + t (u* - u_w)`` (t = 3/4, 1/2, 1/4) and the stored proving
    control ``u_w`` that is certified to map ``x`` into ``K_{i-1}`` for all w.
    """

    def __init__(self, model: Model, seq: Any, Q: Any = None, R: Any = None,
                 local_law: Any = None, solver: str = "ipopt", *, robust: bool | None = None,
                 x_ref: Any = None, solver_options: dict | None = None) -> None:
        from ..control.controllable import _Target, _w_setup
        from ..control.invariance import _law_expr

        if not isinstance(model, Model):
            raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
        if model.m == 0:
            raise ModelError(f"model '{model.name}' has no input")
        sets = getattr(seq, "sets", None)
        if not sets:
            raise TypeError("seq must be a SetSequence (from cm.controllable_sets)")
        if sets[0].dim != model.n:
            raise DimensionError(f"the sequence has dimension {sets[0].dim}; the model has "
                                 f"n = {model.n}")
        solver = str(solver).lower()
        if solver not in ("ipopt", "sqp"):
            raise ValueError(f"solver must be 'ipopt' or 'sqp'; got {solver!r}")
        n, m = model.n, model.m
        self.model, self.seq, self.solver = model, seq, solver
        self.Q = weight_matrix(Q, n, "Q", definite=False, default=np.eye(n))
        self.R = weight_matrix(R, m, "R", definite=False, default=np.eye(m))
        self.x_ref = float_vector(x_ref, n, "x_ref", np.zeros(n))
        if robust is None:
            robust = bool(seq.info.get("robust", model.l > 0))
        self.robust = bool(robust) and model.l > 0
        law = local_law if local_law is not None else seq.info.get("law")
        self._law = None
        if law is not None:
            self._law = ca.Function("law", [model.x], [_law_expr(model, law)])
        self._Wbox, _, _ = _w_setup(model, self.robust, None)
        self._w_vertices = (np.asarray(model.W.vertices()) if self.robust else
                            self._Wbox[:, 0][None]) if model.l else np.zeros((1, 0))
        self._targets: dict[int, Any] = {}
        self._target_cls = _Target
        self._polytopic = all(isinstance(M, Polytope) for S in sets[1:] for M in _members(S))
        self._rmax = 0
        if self._polytopic:
            self._rmax = max(M.A.shape[0] for S in sets for M in _members(S)
                             if isinstance(M, Polytope))
        self._nlp = self._build(solver_options or {})
        self.contract = np.eye(n)  # the whole state is driven to x_ref (for reports)
        self.last_info: dict[str, Any] = {}
        self._xnext: np.ndarray | None = None

    # ---------------------------------------------------------------- solver
    def _build(self, opts: dict) -> Any:
        model = self.model
        n, m = model.n, model.m
        u = ca.SX.sym("u", m)
        t = ca.SX.sym("t")
        x = ca.SX.sym("x", n)
        r = self._rmax
        Hs = ca.SX.sym("H", r, n)
        hs = ca.SX.sym("h", r)
        f = model.function
        g, costs = [], []
        Q, R = ca.DM(self.Q), ca.DM(self.R)
        for wv in self._w_vertices:
            xn = f(x, u, ca.DM(wv)) if model.l else f(x, u, ca.DM.zeros(0))
            e = xn - ca.DM(self.x_ref)
            cost = ca.mtimes([e.T, Q, e]) + ca.mtimes([u.T, R, u])
            costs.append(cost)
            g.append(cost - t)
            if r:
                g.append(ca.mtimes(Hs, xn) - hs)
        p = ca.vertcat(x, ca.vec(Hs), hs)
        nlp = {"x": ca.vertcat(u, t), "f": t, "g": ca.vertcat(*g), "p": p}
        # one control, a few constraints: a short iteration budget (the applied control is
        # certified whatever the solver returns)
        short = {"ipopt.max_iter": 50} if self.solver == "ipopt" else {
            "max_iter": 10, "tol_du": 1e-6}
        plugin, base = _solver_options(self.solver, {**short, **opts})
        self._ng = int(nlp["g"].numel())
        V = len(self._w_vertices)
        lam = np.zeros(self._ng)
        stride = 1 + r
        lam[::stride] = 1.0 / V
        self._lam0 = lam
        wn = ca.DM(self._Wbox[:, 0] * 0.5 + self._Wbox[:, 1] * 0.5) if model.l else \
            ca.DM.zeros(0)
        self._costfun = ca.Function("cost", [x, u], [ca.mmax(ca.vertcat(*costs)),
                                                      f(x, u, wn)])
        return ca.nlpsol("set_sequence_mpc", plugin, nlp, base)

    def _target(self, i: int) -> Any:
        if i not in self._targets:
            self._targets[i] = self._target_cls(self.model, self.seq.sets[i])
        return self._targets[i]

    def _certify(self, x: np.ndarray, U: np.ndarray, i: int) -> np.ndarray:
        """Proven ``f(x, u, W) ⊆ K_i`` and ``u in U`` per candidate row of ``U``."""
        U = np.atleast_2d(U)
        inU = self.model.U.contains(U) & np.isfinite(U).all(axis=1)
        ok = np.zeros(U.shape[0], dtype=bool)
        idx = np.flatnonzero(inU)
        if idx.size:
            X = np.broadcast_to(np.stack([x, x], axis=-1), (idx.size, x.size, 2))
            Ub = np.stack([U[idx], U[idx]], axis=-1)
            W = self._Wbox[None]
            ok[idx] = self._target(i).inside(np.ascontiguousarray(X), Ub, W)
        return ok

    def _cost(self, x: np.ndarray, u: np.ndarray) -> float:
        """The cost's maximum over the vertices of W (the nominal w when not robust)."""
        c, xn = self._costfun(x, u)
        self._xnext = np.asarray(xn, dtype=float).reshape(-1)
        return float(c)

    def __repr__(self) -> str:
        return (f"SetSequenceMPC(model='{self.model.name}', sets={len(self.seq)}, "
                f"solver='{self.solver}', robust={self.robust})")

    def reset(self) -> None:
        """Forget the previous call (the controller keeps no state between calls)."""
        self.last_info = {}

    # ---------------------------------------------------------------- calls
    def __call__(self, x: Any) -> np.ndarray:
        """The control to apply at ``x`` (m,); raises ValueError when x is not controllable
        as far as the sequence proves."""
        res = self.solve(x)
        if res.u is None or not np.isfinite(res.u).all():
            raise ValueError(res.certificate.reason)
        return res.u

    def solve(self, x: Any) -> MPCResult:
        """Solve the one-step problem at ``x``; see the class notes."""
        t0 = time.perf_counter()
        model = self.model
        n, m = model.n, model.m
        x = float_vector(x, n, "x", None)
        if hasattr(self.seq, "locate"):
            lvl, wit = self.seq.locate(x)
        else:
            lvl, wit = self.seq.level(x), None
        nan_u = np.full(m, np.nan)
        stats: dict[str, Any] = {"solver": self.solver, "level": lvl}
        if lvl is None:
            cert = Certificate("not_controllable", None,
                               "x lies in a set of the sequence",
                               f"x = {x.tolist()} lies in no set K_0..K_{len(self.seq) - 1} "
                               "of the sequence: not controllable from here as far as the "
                               "sequence proves (the maximal set may be larger than its "
                               "inner approximation)")
            return self._done(x, nan_u, np.nan, None, cert, stats, "not_controllable",
                              Status.UNDECIDED, t0)
        if lvl == 0:
            if self._law is None:
                raise ValueError("x lies in the terminal set but no local_law was given")
            u = np.asarray(self._law(x), dtype=float).reshape(m)
            cert = Certificate("local_law", True if self.seq.info.get(
                "terminal_certificate") == "proved" else None,
                "x in T: the local law keeps the state in T",
                "T is proven invariant under the local law" if self.seq.info.get(
                    "terminal_certificate") == "proved" else
                "the invariance of T under the law was not proven here")
            return self._done(x, u, self._cost(x, u), 0, cert, stats, "local_law",
                              Status.PROVED, t0)
        # ---------------- one-step problem into K_{lvl - 1}
        ts = time.perf_counter()
        u0 = wit[1] if wit is not None else None
        u_opt = self._solve_nlp(x, lvl - 1, stats, u0)
        stats["solve_time"] = time.perf_counter() - ts
        u_w = None if wit is None else wit[1]
        cands = []
        if u_opt is not None:
            cands.append(u_opt)
        if u_w is not None:
            if u_opt is not None:
                cands += [u_w + tt * (u_opt - u_w) for tt in (0.75, 0.5, 0.25)]
            cands.append(u_w)
        if not cands:
            cert = Certificate("undecided", None, f"f(x, u, W) in K_{lvl - 1}",
                               "the solver failed and no proving control is stored")
            return self._done(x, nan_u, np.nan, lvl, cert, stats, "mpc", Status.NUMERICAL,
                              t0)
        C = np.asarray(cands, dtype=float).reshape(-1, m)
        tv = time.perf_counter()
        ok = np.zeros(C.shape[0], dtype=bool)
        ok[0] = self._certify(x, C[:1], lvl - 1)[0]  # the solver's control first
        if not ok[0] and C.shape[0] > 1:
            ok[1:] = self._certify(x, C[1:], lvl - 1)
        # the witness proves x's box into the target of its own step (a subset of K_{lvl-1})
        if u_w is not None and not ok[-1] and wit[0] <= lvl:
            ok[-1] = self._certify(x, C[-1:], wit[0] - 1)[0]
        stats["verify_time"] = time.perf_counter() - tv
        k = np.flatnonzero(ok)
        if k.size == 0:
            u = C[-1] if u_w is not None else C[0]
            cert = Certificate("unverified", None, f"f(x, u, W) in K_{lvl - 1}",
                               "no candidate control could be certified")
            return self._done(x, u, self._cost(x, u), lvl, cert, stats, "mpc",
                              Status.UNDECIDED, t0)
        u = C[k[0]]
        src = "solver" if (u_opt is not None and k[0] == 0) else (
            "stored control" if k[0] == C.shape[0] - 1 and u_w is not None else
            "blend of solver and stored control")
        cert = Certificate("verified", True, f"f(x, u, w) in K_{lvl - 1} for all w in W",
                           f"interval evaluation at x with u from the {src}",
                           {"candidates": int(C.shape[0]), "chosen": int(k[0])})
        return self._done(x, u, self._cost(x, u), lvl, cert, stats, "mpc", Status.PROVED, t0)

    def _solve_nlp(self, x: np.ndarray, j: int, stats: dict,
                   u0: np.ndarray | None) -> np.ndarray | None:
        m, n, r = self.model.m, self.model.n, self._rmax
        H = np.zeros((r, n))
        h = np.ones(r)
        if r:
            S = self.seq.sets[j]
            polys = [M for M in _members(S) if isinstance(M, Polytope)]
            P = polys[-1]  # the latest polytope of K_j (P_j, or T)
            H[: P.A.shape[0]] = P.A
            # tightened by 1e-6 of each row's scale, so that the optimum (on a facet) passes
            # the interval check; the tightening claims nothing
            scale = np.abs(P.A) @ np.maximum(np.abs(self.model.X.lo), np.abs(self.model.X.hi))
            h[: P.b.shape[0]] = P.b - 1e-6 * np.maximum(scale, np.abs(P.b))
        p = np.concatenate([x, H.ravel(order="F"), h])
        lbx = np.concatenate([self.model.U.lo, [-np.inf]])
        ubx = np.concatenate([self.model.U.hi, [np.inf]])
        try:
            ug = self.model.U.mid if u0 is None else u0
            # multipliers 1/V on the epigraph rows: a positive definite Hessian from the
            # first iteration (with zero multipliers the Hessian in u vanishes)
            sol = self._nlp(x0=np.concatenate([ug, [self._cost(x, ug)]]), p=p, lbx=lbx,
                            ubx=ubx, lbg=-np.inf, ubg=0.0, lam_g0=self._lam0)
        except RuntimeError as exc:
            stats["return_status"] = str(exc)
            return None
        st = self._nlp.stats()
        stats["return_status"] = st.get("return_status")
        u = np.asarray(sol["x"], dtype=float).reshape(-1)[:m]
        return u if np.isfinite(u).all() else None

    def _done(self, x: np.ndarray, u: np.ndarray, cost: float, lvl: int | None,
              cert: Certificate, stats: dict, mode: str, status: Status,
              t0: float) -> MPCResult:
        el = time.perf_counter() - t0
        model = self.model
        xp = np.full((2, model.n), np.nan)
        xp[0] = x
        if np.isfinite(u).all():
            if self._xnext is None:
                self._cost(x, u)
            xp[1] = self._xnext
        self._xnext = None
        self.last_info = {"status": "ok" if status == Status.PROVED else status.name.lower(),
                          "certificate": cert.label, "horizon": lvl, "mode": mode,
                          "solve_time": el}
        return MPCResult(status=status, message=cert.reason, method="set sequence one-step",
                         nit=0, n_boxes=0, elapsed=el, x=x, u=u, u_seq=u[None],
                         x_pred=xp, cost=float(cost), horizon=lvl, certificate=cert,
                         stats=stats, mode=mode)
