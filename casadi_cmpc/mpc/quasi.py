r"""MPC along polytopic quasi i-step robust controllable sets (thesis Alg 6.8, (6.22)-(6.23)).

With the sets ``P_0 = T, P_1, ..., P_M`` of
:func:`~casadi_cmpc.control.quasi.quasi_controllable_sets`, a state ``x`` in
``P_j \ P_{j-1}`` gets an i-step control sequence

    min  x_i' P0 x_i + sum_{k=1}^{i-1} x_k' Q x_k + sum_{k=0}^{i-1} u_k' R u_k      (6.22)
    s.t. x_k in X (k = 1..i-1),  x_i in P_{j-1},  u_k in U                           (6.23)

whose controls are applied one after the other (Alg 6.8); in ``T = P_0`` the local law is
applied. The optimiser (IPOPT or SQP through CasADi) works on the nominal prediction (w at
the centre of W); every sequence is applied only after the sound zonotope evolution of the
current state under it, for all disturbance sequences in W, is proven to stay in X and to
enter ``P_{j-1}`` (:func:`~casadi_cmpc.sets._reach.reach`'s kernels, outward rounding).
When the optimiser's sequence fails that proof, blends with the stored sequence of the
state's box and the stored sequence itself are tried, each proven the same way.
"""

from __future__ import annotations

import time
from typing import Any

import casadi as ca
import numpy as np

from .._validate import float_vector, weight_matrix
from ..control.law import law_expr
from ..control.quasi import (
    QuasiSequence,
    _check_model,
    _in_box,
    _inside_rows,
    _lp_rows,
    lp_controls,
)
from ..control.quasi import _step as _zstep
from ..exceptions import DimensionError, ModelError, NotControllableError
from ..model import Model
from ..sets._reach import box_of
from ..solvers.engine import Status
from ..solvers.result import Certificate
from .contractive import MPCResult, _solver_options
from .spec import QuasiSpec

__all__ = ["QuasiMultiStepMPC"]

_BLENDS = (0.75, 0.5, 0.25)


class QuasiMultiStepMPC:
    """Robust dual-mode MPC along quasi i-step controllable sets (Alg 6.8).

    Parameters
    ----------
    model : Model
        ``x+ = g(x, w) + B u`` (affine control part), the model the sets were computed for.
    seqs : QuasiSequence
        From :func:`~casadi_cmpc.control.quasi.quasi_controllable_sets`.
    P0 : array_like (n, n), optional
        Weight of the last predicted state (default identity).
    Q : array_like (n, n), optional
        Weight of the intermediate states (default zero).
    R : array_like (m, m), optional
        Weight of the controls (default identity).
    local_law : LinearLaw, array_like (m, n) or casadi.SX, optional
        The law applied in ``T = P_0`` (a gain K: ``u = K x``). Without one, the LP
        control (6.20) of the point is used in T.
    solver : {"ipopt", "sqp"}
        Local solver of (6.22).
    solver_options : dict, optional
        Passed to ``casadi.nlpsol``.

    Notes
    -----
    **Plans.** A sequence of length ``a <= i`` proven at ``x(k)`` is a plan: its controls
    are applied at the next ``a`` calls, and at every call the rest of the plan is proven
    again from the measured state (point zonotope evolution for all w in W); a plan that
    cannot be proven again (the state was not produced by the planned step, e.g. a new
    run) is dropped and a new one is computed. The controller is therefore stateful:
    :meth:`reset` forgets the plan.

    **Labels.** ``verified``: the applied control starts a sequence proven, from the
    measured state, to keep the state in X and reach ``P_{j-1}`` within its length for all
    disturbance sequences in W (or, in T, proven to map the state into T for all w).
    ``local_law`` with ``proved=None``: in T, the local law's step could not be proven to
    stay in T (applied anyway). ``not_controllable``: x lies in no set (``ctrl(x)`` raises).
    ``unverified``: no candidate could be proven (the stored control is applied).
    """

    def __init__(self, model: Model, seqs: QuasiSequence, P0: Any = None, Q: Any = None,
                 R: Any = None, local_law: Any = None, solver: str = "ipopt", *,
                 solver_options: dict | None = None) -> None:
        B = _check_model(model)
        if not isinstance(seqs, QuasiSequence):
            raise TypeError(f"seqs must be a QuasiSequence (from quasi_controllable_sets); "
                            f"got {type(seqs).__name__}")
        if seqs.polytopes[0].dim != model.n:
            raise DimensionError(f"the sets have dimension {seqs.polytopes[0].dim}; the "
                                 f"model has n = {model.n}")
        if seqs.info.get("model") not in (None, model.name):
            raise ModelError(f"the sets were computed for model '{seqs.info.get('model')}', "
                             f"not '{model.name}'")
        if len(seqs.polytopes) < 2:
            raise ValueError("seqs holds no quasi set (only the target)")
        solver = str(solver).lower()
        if solver not in ("ipopt", "sqp"):
            raise ValueError(f"solver must be 'ipopt' or 'sqp'; got {solver!r}")
        n, m = model.n, model.m
        self.model, self.seqs, self.solver = model, seqs, solver
        self.steps = int(seqs.steps)
        self.P0 = weight_matrix(P0, n, "P0", definite=False, default=np.eye(n))
        self.Q = weight_matrix(Q, n, "Q", definite=False, default=np.zeros((n, n)))
        self.R = weight_matrix(R, m, "R", definite=False, default=np.eye(m))
        self.B = B
        W = np.asarray(seqs.info.get("W", model.W_box.as_array() if model.l else
                                     np.zeros((0, 2))), dtype=float)
        self._W = W[None] if model.l else np.zeros((1, 0, 2))
        self._wc = 0.5 * (W[:, 0] + W[:, 1]) if model.l else np.zeros(0)
        self._X = model.X.as_array()
        self._law = None
        if local_law is not None:
            self._law = ca.Function("law", [model.x], [law_expr(model, local_law)])
        self._rmax = max(P.A.shape[0] for P in seqs.polytopes)
        self._nlp_spec = self._build(solver_options or {})
        self._nlp = ca.nlpsol("quasi_mpc", self._nlp_spec[1], self._nlp_spec[0],
                              self._nlp_spec[2])
        self._plan: dict[str, Any] | None = None
        self.last_info: dict[str, Any] = {}
        # the cost (6.22) drives the state to the origin; all of it (for reports)
        self.x_ref = np.zeros(n)
        self.contract = np.eye(n)
        self.robust = model.l > 0  # the proofs cover every disturbance sequence in W
        self._claim = (f" for all w in W = [{W[:, 0].tolist()}, {W[:, 1].tolist()}] (robust)"
                       if model.l else " (no disturbance)")

    # ------------------------------------------------------------ the NLP (6.22)
    def _build(self, opts: dict) -> tuple[dict, str, dict]:
        model, i = self.model, self.steps
        n, m, r = model.n, model.m, self._rmax
        x0 = ca.SX.sym("x0", n)
        H = ca.SX.sym("H", r, n)
        h = ca.SX.sym("h", r)
        useq = ca.SX.sym("u", m * i)
        f = model.function
        wc = ca.DM(self._wc) if model.l else ca.DM.zeros(0)
        x = x0
        cost = 0
        g = []
        P0, Q, R = ca.DM(self.P0), ca.DM(self.Q), ca.DM(self.R)
        for k in range(i):
            u = useq[k * m:(k + 1) * m]
            cost += ca.mtimes([u.T, R, u])
            x = f(x, u, wc)
            if k < i - 1:
                cost += ca.mtimes([x.T, Q, x])
                g.append(x)
        cost += ca.mtimes([x.T, P0, x])
        g.append(ca.mtimes(H, x) - h)
        nlp = {"x": useq, "f": cost, "g": ca.vertcat(*g), "p": ca.vertcat(x0, ca.vec(H), h)}
        X = model.X
        self._lbg = np.concatenate([np.tile(X.lo, i - 1), np.full(r, -np.inf)])
        self._ubg = np.concatenate([np.tile(X.hi, i - 1), np.zeros(r)])
        self._lbx = np.tile(model.U.lo, i)
        self._ubx = np.tile(model.U.hi, i)
        plugin, base = _solver_options(self.solver, opts)
        return nlp, plugin, base

    def _rows(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """``(H, h)`` of ``P_j`` padded to r rows, offsets tightened by 1e-6 of their scale
        (the tightening claims nothing: the sequence is proven afterwards)."""
        P = self.seqs.polytopes[j]
        n, r = self.model.n, self._rmax
        H = np.zeros((r, n))
        h = np.ones(r)
        H[:P.A.shape[0]] = P.A
        h[:P.b.shape[0]] = P.b - 1e-6 * np.maximum(np.abs(P.b), 1.0)
        return H, h

    def _solve_nlp(self, x: np.ndarray, j: int, u0: np.ndarray | None,
                   stats: dict) -> np.ndarray | None:
        H, h = self._rows(j)
        p = np.concatenate([x, H.ravel(order="F"), h])
        m, i = self.model.m, self.steps
        z0 = np.tile(self.model.U.mid, i) if u0 is None else u0.reshape(-1)
        try:
            sol = self._nlp(x0=z0, p=p, lbx=self._lbx, ubx=self._ubx, lbg=self._lbg,
                            ubg=self._ubg)
        except RuntimeError as exc:
            stats["return_status"] = str(exc)
            return None
        stats["return_status"] = self._nlp.stats().get("return_status")
        z = np.asarray(sol["x"], dtype=float).reshape(i, m)
        if not np.isfinite(z).all():
            return None
        return np.clip(z, self.model.U.lo, self.model.U.hi)

    # ------------------------------------------------------------ proofs
    def prove(self, x: Any, u_seq: Any, j: int) -> int:
        """Prove that ``u_seq`` (L, m) from the point x keeps the state in X and brings it
        into ``P_j`` within L steps for all disturbance sequences in W.

        Returns
        -------
        int
            The first step ``a`` (1..L) at which the state is proven in ``P_j`` (the
            states before it proven in X), or 0 when not proven (also for controls outside
            U or not finite).
        """
        x = np.asarray(x, dtype=float).reshape(-1)
        useq = np.asarray(u_seq, dtype=float).reshape(-1, self.model.m)
        U = self.model.U
        if not (np.isfinite(useq).all() and np.all(useq >= U.lo) and np.all(useq <= U.hi)):
            return 0
        P = self.seqs.polytopes[j]
        A, b = np.asarray(P.A, dtype=float), np.asarray(P.b, dtype=float)
        C = x[None].copy()
        G = np.zeros((1, x.size, 0))
        for k in range(useq.shape[0]):
            if k > 0 and not _in_box(C, G, self._X)[0]:
                return 0
            u = useq[k]
            C, G = _zstep(self.model, C, G, np.stack([u, u], axis=-1)[None], self._W, None,
                          True, None, "natural")
            if _inside_rows(C, G, A, b)[0]:
                return k + 1
        return 0

    def _lp_control(self, x: np.ndarray, j: int) -> np.ndarray:
        """The LP control (6.20)-(6.21) at the point x towards ``P_j``."""
        P = self.seqs.polytopes[j]
        An, bn = _lp_rows(np.asarray(P.A, dtype=float), np.asarray(P.b, dtype=float))
        C, G = _zstep(self.model, x[None], np.zeros((1, x.size, 0)),
                      np.zeros((1, self.model.m, 2)), self._W, None, True, None, "natural")
        Y = box_of(C, G)
        if not np.isfinite(Y).all():
            return np.asarray(self.model.U.mid, dtype=float)
        return lp_controls(An, bn, An @ self.B, Y, self.model.U)[0]

    # ------------------------------------------------------------ calls
    def reset(self) -> None:
        """Forget the current plan and the last call."""
        self._plan = None
        self.last_info = {}

    def __call__(self, x: Any) -> np.ndarray:
        """The control to apply at x (m,); raises NotControllableError (a ValueError) where x
        lies in no set."""
        res = self.solve(x)
        if res.u is None or not np.isfinite(res.u).all():
            if res.certificate.label == "not_controllable":
                raise NotControllableError(res.certificate.reason)
            raise ValueError(res.certificate.reason)
        return res.u

    def level(self, x: Any) -> int | None:
        """The smallest j with x in ``P_j`` (None: in no set)."""
        return self.seqs.level(x)

    def solve(self, x: Any) -> MPCResult:
        """One call of Alg 6.8 at x; see the class notes."""
        t0 = time.perf_counter()
        n, m = self.model.n, self.model.m
        x = float_vector(x, n, "x", None)
        stats: dict[str, Any] = {"solver": self.solver}
        in_T = bool(self.seqs.polytopes[0].contains(x))
        # --- in T: the local law, proven for this step when possible (Alg 6.8 step 3)
        if in_T:
            u_law = (np.asarray(self._law(x), dtype=float).reshape(m)
                     if self._law is not None else None)
            if u_law is not None and self.prove(x, u_law[None], 0):
                self._plan = None
                return self._done(x, u_law, None, 0, Certificate(
                    "local_law", True, "f(x, u, w) in T" + self._claim,
                    "local law; its step proven into T by zonotope evolution at x"),
                    stats, "local_law", Status.PROVED, t0)
            u_lp = self._lp_control(x, 0)
            if self.prove(x, u_lp[None], 0):
                self._plan = None
                return self._done(x, u_lp, None, 0, Certificate(
                    "verified", True, "f(x, u, w) in T" + self._claim,
                    "the local law's step could not be proven; the LP control (6.20) at x "
                    "is proven into T by zonotope evolution"), stats, "local_lp",
                    Status.PROVED, t0)
        # --- a plan in progress, proven again from the measured state
        plan = self._plan
        if plan is not None and plan["rest"].shape[0]:
            a = self.prove(x, plan["rest"], plan["target"])
            if a:
                useq = plan["rest"][:a]
                self._plan = {"rest": useq[1:], "target": plan["target"],
                              "level": plan["level"]}
                return self._done(x, useq[0], useq, plan["level"], Certificate(
                    "verified", True,
                    f"x stays in X and enters P_{plan['target']} within {a} steps"
                    + self._claim, "rest of the plan proven again from the measured state "
                    "by zonotope evolution", {"steps": a}), stats, "plan", Status.PROVED, t0)
        self._plan = None
        if in_T:
            if u_law is None:
                u_law = self._lp_control(x, 0)
            return self._done(x, u_law, None, 0, Certificate(
                "local_law", None, "f(x, u, w) in T" + self._claim,
                "x in T: the local law is applied, but its step could not be proven to stay "
                "in T (T's invariance under the law is not proven here)"), stats,
                "local_law", Status.UNDECIDED, t0)
        lvl = self.seqs.level(x)
        if lvl is None:
            cert = Certificate("not_controllable", None, "x lies in a set of the sequence",
                               f"x = {x.tolist()} lies in no set P_0..P_{len(self.seqs) - 1}"
                               ": not controllable as far as the sets prove")
            return self._done(x, np.full(m, np.nan), None, None, cert, stats,
                              "not_controllable", Status.UNDECIDED, t0)
        j = lvl - 1
        res = self.seqs.results[lvl - 1]
        stored = res.control_sequence(x)
        stats["level"] = lvl
        ts = time.perf_counter()
        u_opt = self._solve_nlp(x, j, None if stored is None or stored.shape[0] < self.steps
                                else stored, stats)
        stats["solve_time"] = time.perf_counter() - ts
        cands: list[tuple[np.ndarray, str]] = []
        if u_opt is not None:
            cands.append((u_opt, "solver"))
        if stored is not None:
            if u_opt is not None:
                L = stored.shape[0]
                for t in _BLENDS:
                    cands.append((stored + t * (u_opt[:L] - stored),
                                  "blend of solver and stored sequence"))
            cands.append((stored, "stored sequence of the state's box"))
        for useq, src in cands:
            a = self.prove(x, useq, j)
            if a:
                useq = useq[:a]
                self._plan = {"rest": useq[1:], "target": j, "level": lvl}
                cert = Certificate("verified", True,
                                   f"x stays in X and enters P_{j} within {a} steps"
                                   + self._claim,
                                   f"sequence from the {src}, proven by zonotope evolution "
                                   "from x", {"source": src, "steps": a})
                return self._done(x, useq[0], useq, lvl, cert, stats, "mpc", Status.PROVED,
                                  t0)
        u = cands[-1][0][0] if cands else np.full(m, np.nan)
        cert = Certificate("unverified", None, f"x enters P_{j}" + self._claim,
                           "no candidate sequence could be proven")
        return self._done(x, u, None, lvl, cert, stats, "mpc", Status.UNDECIDED, t0)

    def _done(self, x: np.ndarray, u: np.ndarray, useq: np.ndarray | None, lvl: int | None,
              cert: Certificate, stats: dict, mode: str, status: Status,
              t0: float) -> MPCResult:
        el = time.perf_counter() - t0
        useq = u[None] if useq is None else np.asarray(useq, dtype=float)
        xp = np.full((useq.shape[0] + 1, self.model.n), np.nan)
        xp[0] = x
        cost = np.nan
        if np.isfinite(useq).all():
            c = 0.0
            for k in range(useq.shape[0]):
                c += float(useq[k] @ self.R @ useq[k])
                xp[k + 1] = self.model.step(xp[k], useq[k], self._wc if self.model.l else None)
                W = self.P0 if k == useq.shape[0] - 1 else self.Q
                c += float(xp[k + 1] @ W @ xp[k + 1])
            cost = c
        self.last_info = {"status": "ok" if status == Status.PROVED else status.name.lower(),
                          "certificate": cert.label, "horizon": int(useq.shape[0]),
                          "level": lvl, "mode": mode, "solve_time": el}
        return MPCResult(status=status, message=cert.reason, method="quasi i-step MPC "
                         "(Alg 6.8)", nit=0, n_boxes=0, elapsed=el, x=x, u=np.asarray(u),
                         u_seq=useq, x_pred=xp, cost=float(cost), horizon=lvl,
                         certificate=cert, stats=stats, mode=mode)

    # ------------------------------------------------------------ export
    def export_spec(self) -> QuasiSpec:
        """The data the C export is generated from (see :mod:`casadi_cmpc.mpc.spec`).

        Returns
        -------
        QuasiSpec
        """
        seqs = self.seqs
        boxes = [(np.asarray(r.inner, dtype=float), np.asarray(r.controls, dtype=float),
                  np.asarray(r.arrival, dtype=int)) for r in seqs.results]
        nlp, plugin, options = self._nlp_spec
        return QuasiSpec(model=self.model, steps=self.steps, polytopes=list(seqs.polytopes),
                         boxes=boxes, local_law=self._law, nlp=nlp, plugin=plugin,
                         options=dict(options), rows=self._rmax,
                         nlp_rows=[self._rows(j) for j in range(len(seqs.polytopes) - 1)],
                         lbx=self._lbx.copy(), ubx=self._ubx.copy(), lbg=self._lbg.copy(),
                         ubg=self._ubg.copy(), W=self._W[0].copy())

    def export_c(self, directory: Any, solver: str = "sqp", **kw: Any) -> Any:
        """Write this controller as standalone C (the NLP (6.22), the model, the local law,
        the polytopes and the stored box sequences, the interval proof of a plan); see
        :func:`casadi_cmpc.codegen.export_c`. Returns an
        :class:`~casadi_cmpc.codegen.ExportInfo`."""
        from ..codegen import export_c

        return export_c(self, directory, solver=solver, **kw)

    @property
    def proof_w(self) -> np.ndarray:
        """The disturbances its proven steps hold for, as a box (l, 2): the W of its
        sets."""
        return np.array(self._W[0], dtype=float).reshape(self.model.l, 2)

    @property
    def guarantee(self) -> str:
        """What the closed loop is guaranteed (one sentence)."""
        return ("from x in P_j every applied sequence is proven (zonotope evolution, "
                f"outward rounding) to keep the state in X and bring it into P_(j-1) within "
                f"{self.steps} steps{self._claim}, so T = P_0 is reached; inside T a step of "
                "the local law is labelled verified only when proven to stay in T")

    def __repr__(self) -> str:
        return (f"QuasiMultiStepMPC(model='{self.model.name}', sets={len(self.seqs)}, "
                f"steps={self.steps}, solver='{self.solver}')")

