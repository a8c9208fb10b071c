"""Local laws and invariance certificates (thesis §4.2.6, Alg 4.3).

* :func:`local_lqr` — the LQR gain of the linearisation at an equilibrium (python-control);
* :func:`certify_invariant` — proves ``f(x, law(x), w) in S`` and ``law(x) in U`` for every
  ``x in S`` and ``w in W`` by set inversion over sub-zonotopes of S (Alg 4.3), or refutes it
  with a counterexample point.
"""

from __future__ import annotations

import time
from typing import Any

import casadi as ca
import numpy as np

from .._validate import float_vector as _vector
from .._validate import weight_matrix as _weight
from ..exceptions import DimensionError, ModelError, UnsupportedOperationError
from ..model import Model
from ..sets.polytope import Polytope
from ..solvers.result import Certificate

__all__ = ["certify_invariant", "local_lqr"]


def local_lqr(model: Model, Q: Any, R: Any, x_eq: Any = None, u_eq: Any = None,
              w: Any = None) -> np.ndarray:
    """LQR gain ``K`` (u = u_eq + K (x - x_eq)) of the linearisation at an equilibrium.

    Parameters
    ----------
    model : Model
    Q : array_like (n, n)
        State weight, symmetric positive semidefinite (a scalar or a diagonal vector too).
    R : array_like (m, m)
        Input weight, symmetric positive definite.
    x_eq, u_eq : array_like, optional
        The equilibrium (default: the origin); checked, with a clear error when
        ``f(x_eq, u_eq, w) != x_eq``.
    w : array_like (l,), optional
        Disturbance of the linearisation (default: the centre of W).

    Returns
    -------
    ndarray, shape (m, n)
        ``K`` with the sign convention of this library (``u = K x``): python-control's
        ``dlqr`` returns ``-K``.

    Raises
    ------
    ValueError
        Not an equilibrium; bad weights; the linearisation is not stabilisable.
    """
    import control

    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    if model.m == 0:
        raise ModelError(f"model '{model.name}' has no input")
    n, m = model.n, model.m
    xe = _vector(x_eq, n, "x_eq", np.zeros(n))
    ue = _vector(u_eq, m, "u_eq", np.zeros(m))
    we = _vector(w, model.l, "w", model.W.mid) if model.l else np.zeros(0)
    Qm = _weight(Q, n, "Q", definite=False, default=None)
    Rm = _weight(R, m, "R", definite=True, default=None)
    model.check_equilibrium(xe, ue, we if model.l else None)
    A = np.asarray(model.jacobian_function("x")(xe, ue, we), dtype=float)
    B = np.asarray(model.jacobian_function("u")(xe, ue, we), dtype=float)
    try:
        K, _, _ = control.dlqr(A, B, Qm, Rm)
    except Exception as exc:  # python-control raises several types for this
        raise ValueError(f"no LQR gain for the linearisation of '{model.name}' at "
                         f"x_eq = {xe.tolist()}: {exc}") from exc
    return -np.asarray(K, dtype=float).reshape(m, n)


def _law_expr(model: Model, law: Any) -> ca.SX:
    if isinstance(law, ca.SX):
        if law.numel() != model.m:
            raise DimensionError(f"the law must have {model.m} elements")
        return ca.reshape(law, model.m, 1)
    K = np.atleast_2d(np.asarray(law, dtype=float))
    if K.shape != (model.m, model.n):
        raise DimensionError(f"the gain must have shape ({model.m}, {model.n}); got {K.shape}")
    return ca.mtimes(ca.DM(K), model.x)


def _domain(S: Polytope) -> Any:
    """A zonotope covering S: S itself when S is a parallelotope (n pairs of opposite rows),
    else a bounding parallelotope; generators widened by 1e-9 relative in both cases."""
    from ..sets.zonotope import Zonotope
    from ..solvers.zonotope_sivia import _bounding_parallelotope

    A, b = S.A, S.b
    n = S.dim
    if A.shape[0] == 2 * n:
        pairs, used = [], set()
        for i in range(2 * n):
            if i in used:
                continue
            j = next((j for j in range(i + 1, 2 * n) if j not in used
                      and np.array_equal(A[j], -A[i])), None)
            if j is None:
                break
            used.update((i, j))
            pairs.append((i, j))
        if len(pairs) == n:
            V = np.array([A[i] for i, _ in pairs])
            lo = np.array([-b[j] for _, j in pairs])
            hi = np.array([b[i] for i, _ in pairs])
            if np.linalg.matrix_rank(V) == n and (hi > lo).all():
                Vi = np.linalg.inv(V)
                c = Vi @ (0.5 * (lo + hi))
                G = Vi * (0.5 * (hi - lo))[None, :]
                return Zonotope(c, G * (1.0 + 1e-9))
    return _bounding_parallelotope(S)


def _disjoint(fr: Any, S: Polytope) -> np.ndarray:
    """Per element of a ZonotopeFrontier: proven disjoint from S (a row separates)."""
    if len(fr) == 0:
        return np.zeros(0, dtype=bool)
    _, hi = fr.support_bounds(-S.A)  # h_Z(-a) <= hi, so min_Z a.x >= -hi
    return (-hi > S.b[None, :]).any(axis=1)


def certify_invariant(model: Model, S: Polytope, law: Any, eps: float, *, W: Any = None,
                      max_boxes: int = 200_000, time_limit: float | None = None,
                      samples: int = 64, seed: int = 0,
                      progress: bool | None = None) -> Certificate:
    """Prove that ``S`` is (robustly) invariant under ``u = law(x)`` (thesis Alg 4.3).

    The claim: for every ``x in S`` and every ``w in W``, ``f(x, law(x), w) in S`` and
    ``law(x) in U``. Two set inversions over sub-zonotopes of S (the successor into S, the
    law into U) decide it piece by piece (:func:`casadi_cmpc.solvers.zonotope_sivia`).

    Parameters
    ----------
    model : Model
    S : Polytope
        A bounded polytope (a Zonotope target is not supported yet: pass its polytope only
        if you can prove the polytope is inside it).
    law : array_like (m, n) or casadi.SX (m, 1)
        Gain ``K`` (``u = K x``) or an expression of ``model.x``.
    eps : float
        Pieces whose largest generator entry is at most ``eps`` are not split further.
    W : Box, optional
        Disturbance box (default: the model's W).
    max_boxes, time_limit, progress
        Budget and progress bar of each set inversion.
    samples, seed
        Points tried per unresolved piece when looking for a counterexample.

    Returns
    -------
    Certificate
        ``proved`` True (every piece meeting S proven good), False (a piece meeting S
        proven bad, or a point of S whose input or successor is proven, by an interval
        evaluation at the point, to violate a condition: the ``counterexample`` and the
        violated condition are given), or None (undecided:
        ``details["undecided_pieces"]`` holds their number and bounding boxes).
    """
    from ..solvers.zonotope_sivia import zonotope_sivia

    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    if not isinstance(S, Polytope):
        raise UnsupportedOperationError(
            f"certify_invariant needs S as a Polytope; got {type(S).__name__}")
    if S.dim != model.n:
        raise DimensionError(f"S has dimension {S.dim}, the model has n = {model.n}")
    t0 = time.perf_counter()
    expr = _law_expr(model, law)
    cl = model.closed_loop(expr)
    law_fun = ca.Function("law", [model.x], [expr])
    Wb = W if W is not None else model.W
    claim = ("for every x in S" + (" and every w in W" if model.l else "")
             + ": f(x, law(x), w) in S and law(x) in U")
    # the pieces cover a parallelotope around S; pieces proven disjoint from S are left out,
    # the others must satisfy the conditions on the whole piece (sufficient)
    Z0 = _domain(S)
    runs = {
        "state set": zonotope_sivia(cl, Z0, S, eps, W=Wb, max_boxes=max_boxes,
                                    time_limit=time_limit, progress=progress),
        "input bound": zonotope_sivia(law_fun, Z0, model.U, eps, max_boxes=max_boxes,
                                      time_limit=time_limit, progress=progress),
    }
    details: dict[str, Any] = {}
    unresolved = []
    for name, pav in runs.items():
        bad = ~_disjoint(pav.outer, S) if len(pav.outer) else np.zeros(0, dtype=bool)
        details[name] = {"inner": len(pav.inner), "boundary": len(pav.boundary),
                         "outside": int(pav.n_discarded), "status": pav.status.name,
                         "seconds": pav.elapsed}
        if bad.any():
            unresolved.append((name, pav.outer, bad, True))
        if len(pav.boundary):
            meet = ~_disjoint(pav.boundary, S)
            if meet.any():
                unresolved.append((name, pav.boundary, meet, False))
    rng = np.random.default_rng(seed)
    w_pts = (np.asarray(Wb.vertices()) if model.l else np.zeros((1, 0)))
    # look for a concrete counterexample: proven-bad pieces first, then undecided ones,
    # and the vertices of S
    V = np.asarray(S.vertices())
    c = V.mean(axis=0)
    cands = [V, c + (1 - 1e-9) * (V - c), c + (1 - 1e-6) * (V - c)]
    for _, fr, mask, _ in unresolved:
        pts = fr.sample(samples, rng=rng)[mask].reshape(-1, model.n)
        centres = np.asarray(fr.centers)[mask]
        cands += [centres, pts]
    P = np.concatenate(cands)
    # candidates proven inside S (a thin box certified inside)
    P = P[np.asarray(S.contains_box(np.stack([P, P], axis=-1)), dtype=bool)]
    if P.shape[0]:
        u = np.asarray(law_fun.map(P.shape[0])(P.T), dtype=float).T.reshape(-1, model.m)
        # a violation counts only when an interval evaluation at the point confirms it
        UL = cl.law_inclusion()(np.stack([P, P], axis=-1))
        out_u = ((UL[:, :, 1] < model.U.lo) | (UL[:, :, 0] > model.U.hi)).any(axis=1)
        if out_u.any():
            k = int(np.argmax(np.abs(u).max(axis=1) * out_u))
            return Certificate(
                "refuted", False, claim,
                f"input bound: law(x) = {u[k].tolist()} lies outside U = "
                f"[{model.U.lo.tolist()}, {model.U.hi.tolist()}] at x = {P[k].tolist()}",
                details, counterexample=P[k])
        for wv in w_pts:
            nxt = cl.step(P, None, np.broadcast_to(wv, (P.shape[0], model.l))
                          if model.l else None)
            Wt = (np.broadcast_to(np.stack([wv, wv], axis=-1), (P.shape[0], model.l, 2))
                  if model.l else None)
            enc = cl.inclusion("natural")(np.stack([P, P], axis=-1), None, Wt)
            out_s = ~np.asarray(S.intersects_box(enc), dtype=bool)
            if out_s.any():
                k = int(np.flatnonzero(out_s)[0])
                ws = f" with w = {wv.tolist()}" if model.l else ""
                return Certificate(
                    "refuted", False, claim,
                    f"state set: f(x, law(x)){ws} = {nxt[k].tolist()} lies outside S at "
                    f"x = {P[k].tolist()}", details, counterexample=P[k])
    details["seconds"] = time.perf_counter() - t0
    proven_bad = [(name, fr, mask) for name, fr, mask, proven in unresolved if proven]
    if proven_bad:
        name, fr, mask = proven_bad[0]
        return Certificate(
            "refuted", False, claim,
            f"{name}: {int(mask.sum())} pieces of S proven to violate the condition (no "
            "sampled point found to show it numerically)", details)
    if unresolved:
        boxes = np.concatenate([fr.bounding_boxes()[mask] for _, fr, mask, _ in unresolved])
        details["undecided_pieces"] = int(boxes.shape[0])
        details["undecided_boxes"] = boxes
        budget = any(p.status.name == "BUDGET" for p in runs.values())
        return Certificate(
            "undecided", None, claim,
            f"{boxes.shape[0]} pieces of S left undecided at eps = {eps}"
            + (" (budget reached)" if budget else "") + "; no counterexample found", details)
    return Certificate("proved", True, claim,
                       "set inversion over sub-zonotopes of S (Alg 4.3): every piece meeting "
                       "S has its successor inside S and its input inside U, with outward "
                       "rounding", details)
