"""Local laws and invariance certificates (thesis §4.2.6-4.2.7, Alg 4.3 and 4.4).

* :func:`local_lqr` — the LQR gain of the linearisation at an equilibrium (python-control);
* :func:`certify_invariant` — proves ``f(x, law(x), w) in S`` and ``law(x) in U`` for every
  ``x in S`` and ``w in W`` (S a polytope or a zonotope) by set inversion over
  sub-zonotopes of S (Alg 4.3), or refutes it with a counterexample point;
* :func:`largest_invariant_zonotope` — global search over an interval generator matrix for
  the largest zonotope proven invariant under a given law (Alg 4.4).
"""

from __future__ import annotations

import heapq
import itertools
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from .._bisect import bisect_widest
from .._interrupt import InterruptScope
from .._validate import float_vector as _vector
from .._validate import weight_matrix as _weight
from ..exceptions import CmpcWarning, DimensionError, ModelError, UnsupportedOperationError
from ..model import Model
from ..sets.box import Box
from ..sets.polytope import Polytope
from ..sets.zonotope import Zonotope, zonotope_inclusion
from ..solvers._common import positive_eps
from ..solvers.engine import Status
from ..solvers.result import Certificate, Result
from .law import LinearLaw, law_expr

__all__ = ["certify_invariant", "local_lqr", "largest_invariant_zonotope",
           "InvariantZonotopeResult"]


def local_lqr(model: Model, Q: Any, R: Any, x_eq: Any = None, u_eq: Any = None,
              w: Any = None) -> LinearLaw:
    """The LQR law ``u = u_eq + K (x - x_eq)`` of the linearisation at an equilibrium.

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
    LinearLaw
        The law ``u = u_eq + K (x - x_eq)``, carrying ``K`` (m, n) and the equilibrium, so
        that every function it is passed to (``certify_invariant``, ``controllable_sets``,
        ``ContractiveMPC``, ``SetSequenceMPC``, ``simulate``) applies the same law.
        ``np.asarray(law)`` (or ``law.K``) is the gain alone, with the sign convention of
        this library (python-control's ``dlqr`` returns ``-K``).

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
    return LinearLaw(-np.asarray(K, dtype=float).reshape(m, n), xe, ue)


_law_expr = law_expr


def _check_target(S: Any, n: int) -> None:
    """S must be a bounded Polytope or a full-dimensional Zonotope of dimension n."""
    if isinstance(S, Zonotope):
        if S.dim != n:
            raise DimensionError(f"S has dimension {S.dim}, the model has n = {n}")
        if not S.is_full_dimensional():
            raise UnsupportedOperationError(
                "S is a flat zonotope (its generators are not proven to span R^n): its "
                "interior is empty and set inversion cannot prove f(S) ⊆ S; give a "
                "full-dimensional zonotope")
        if S._facet_data() is None:
            raise UnsupportedOperationError(
                f"S has too many generators ({S.n_generators}) to enumerate its facets in "
                f"dimension {n}; bound it by a zonotope of lower order first")
        return
    if not isinstance(S, Polytope):
        hint = " (convert it with Polytope.from_box)" if isinstance(S, Box) else ""
        raise UnsupportedOperationError(
            f"certify_invariant needs S as a Polytope or a Zonotope; got "
            f"{type(S).__name__}{hint}")
    if S.dim != n:
        raise DimensionError(f"S has dimension {S.dim}, the model has n = {n}")


_WIDEN = (1e-9, 1e-6, 1e-3, 1e-1)


def _domain(S: Any) -> tuple[Zonotope | None, str]:
    """A zonotope proven to contain S, and how it was obtained (None: no cover proven).

    A Zonotope S is its own domain (exactly: only its zero generators are dropped). For a
    Polytope S, candidates are tried in turn, each with its generators widened by
    ``1e-9``, ``1e-6``, ``1e-3`` and ``0.1`` relative: the parallelotope of a polytope
    with n pairs of opposite rows (from a floating-point inverse of the row matrix), a
    parallelotope around the floating-point vertices (§4.2.5), and the bounding box of S
    (rigorous LP-dual bounds). Floating-point inverses and vertices only *propose* a
    candidate: each is accepted only when ``S ⊆ candidate`` is proven by
    :meth:`Zonotope.contains_polytope` (exact rational bounds, no vertex enumeration).
    """
    if isinstance(S, Zonotope):
        G = S.generators
        return Zonotope(S.center, G[:, np.any(G != 0.0, axis=0)]), "S itself"
    for make, how in ((_row_parallelotope, "parallelotope of the row pairs of S"),
                      (_vertex_parallelotope, "parallelotope around the vertices of S"),
                      (_box_parallelotope, "bounding box of S")):
        try:
            Z = make(S)
        except Exception:  # a float construction that failed proposes nothing
            Z = None
        if Z is None or not np.isfinite(Z.generators).all() or not np.isfinite(Z.center).all():
            continue
        for w in _WIDEN:
            cand = Zonotope(Z.center, Z.generators * (1.0 + w))
            if cand.contains_polytope(S) is True:
                return cand, f"{how} (widened by {w:g} relative; S inside it proven)"
    return None, "no zonotope proven to contain S"


def _row_parallelotope(S: Polytope) -> Zonotope | None:
    """For n pairs of opposite rows ``lo <= V x <= hi``: the zonotope ``V^-1 (mid + diag(half)
    B)`` from a floating-point inverse (a proposal, checked by the caller)."""
    A, b = S.A, S.b
    n = S.dim
    if A.shape[0] != 2 * n:
        return None
    pairs, used = [], set()
    for i in range(2 * n):
        if i in used:
            continue
        j = next((j for j in range(i + 1, 2 * n) if j not in used
                  and np.array_equal(A[j], -A[i])), None)
        if j is None:
            return None
        used.update((i, j))
        pairs.append((i, j))
    V = np.array([A[i] for i, _ in pairs])
    lo = np.array([-b[j] for _, j in pairs])
    hi = np.array([b[i] for i, _ in pairs])
    if np.linalg.matrix_rank(V) < n or not (hi > lo).all():
        return None
    Vi = np.linalg.inv(V)
    return Zonotope(Vi @ (0.5 * (lo + hi)), Vi * (0.5 * (hi - lo))[None, :])


def _vertex_parallelotope(S: Polytope) -> Zonotope:
    """A parallelotope around the floating-point vertices of S (a proposal)."""
    from ..solvers.zonotope_sivia import _bounding_parallelotope

    return _bounding_parallelotope(S)


def _box_parallelotope(S: Polytope) -> Zonotope | None:
    """The bounding box of S from rigorous LP-dual support bounds, as a zonotope."""
    n = S.dim
    h = S._support_upper(np.vstack([np.eye(n), -np.eye(n)]))
    if not np.isfinite(h).all():
        return None
    hi, lo = h[:n], -h[n:]
    return Zonotope(0.5 * lo + 0.5 * hi, np.diag(np.maximum(0.5 * hi - 0.5 * lo, 0.0)))


def _disjoint(fr: Any, S: Any) -> np.ndarray:
    """Per element of a ZonotopeFrontier: proven disjoint from S."""
    if len(fr) == 0:
        return np.zeros(0, dtype=bool)
    if isinstance(S, Zonotope):
        from ..solvers._ztargets import _ZonotopeTest

        return _ZonotopeTest(S).disjoint(fr.centers, fr.generators, fr.radii)
    _, hi = fr.support_bounds(-S.A)  # h_Z(-a) <= hi, so min_Z a.x >= -hi
    return (-hi > S.b[None, :]).any(axis=1)


def _proven_in(S: Any, P: np.ndarray) -> np.ndarray:
    """Points proven inside S (a degenerate box certified inside)."""
    if P.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    return np.asarray(S.contains_box(np.stack([P, P], axis=-1)), dtype=bool)


def _sample_points(S: Any, Z0: Zonotope, k: int, rng: np.random.Generator) -> np.ndarray:
    """Candidates for counterexamples: vertices of S (of its cover ``Z0`` when S's vertices
    cannot be enumerated) pulled slightly inwards, its centre, and ``k`` random points of
    the cover (half of them at sign vectors of its generators). Points outside S are
    filtered out later (``_proven_in``)."""
    try:
        V = np.asarray(S.vertices(), dtype=float)
    except Exception:  # float vertex enumeration failed on an ill-conditioned S
        V = np.zeros((0, S.dim))
    if V.shape[0] == 0 or not np.isfinite(V).all():
        try:
            V = np.asarray(Z0.vertices(), dtype=float)
        except Exception:
            V = Z0.center[None, :]
    c = Z0.center if isinstance(S, Zonotope) else V.mean(axis=0)
    G = Z0.generators
    a = rng.uniform(-1.0, 1.0, (k, G.shape[1]))
    a[: k // 2] = np.sign(a[: k // 2])
    R = Z0.center + (1.0 - 1e-7) * (a @ G.T)
    pts = np.concatenate([V, c + (1 - 1e-9) * (V - c), c + (1 - 1e-6) * (V - c), c[None],
                          Z0.center[None], R])
    return pts[np.isfinite(pts).all(axis=1)]


def _point_counterexample(P: np.ndarray, S: Any, model: Model, cl: Model, law_fun: Any,
                          w_pts: np.ndarray, claim: str, details: dict
                          ) -> Certificate | None:
    """A refutation by one of the points P, each proven inside S and proven (by interval
    evaluations at the point) to have its input outside U or a successor outside S."""
    P = P[_proven_in(S, P)]
    if P.shape[0] == 0:
        return None
    u = np.asarray(law_fun.map(P.shape[0])(P.T), dtype=float).T.reshape(-1, model.m)
    UL = cl.law_inclusion()(np.stack([P, P], axis=-1))
    # the enclosure of law(x) at the point proven outside U; the point reported is the
    # one with the largest proven excess (never a point merely sampled)
    with np.errstate(invalid="ignore"):
        excess = np.maximum(model.U.lo - UL[:, :, 1], UL[:, :, 0] - model.U.hi)
    excess = np.where(np.isnan(excess), -np.inf, excess).max(axis=1)
    out_u = excess > 0.0
    if out_u.any():
        k = int(np.argmax(np.where(out_u, excess, -np.inf)))
        return Certificate(
            "refuted", False, claim,
            f"input bound: law(x) in [{UL[k, :, 0].tolist()}, {UL[k, :, 1].tolist()}] "
            f"(≈ {u[k].tolist()}) lies outside U = [{model.U.lo.tolist()}, "
            f"{model.U.hi.tolist()}] at x = {P[k].tolist()}",
            details, counterexample=P[k])
    for wv in w_pts:
        nxt = cl.step(P, None, np.broadcast_to(wv, (P.shape[0], model.l))
                      if model.l else None)
        Wt = (np.broadcast_to(np.stack([wv, wv], axis=-1), (P.shape[0], model.l, 2))
              if model.l else None)
        enc = cl.inclusion("natural")(np.stack([P, P], axis=-1), None, Wt)
        # proven disjoint from S (for a polytope: one row separates the enclosure, with
        # rigorous rounding; cheap, and a proof)
        out_s = (np.asarray(S._kernel().separates(enc), dtype=bool)
                 if isinstance(S, Polytope) else
                 ~np.asarray(S.intersects_box(enc), dtype=bool))
        if out_s.any():
            k = int(np.flatnonzero(out_s)[0])
            ws = f" with w = {wv.tolist()}" if model.l else ""
            val = (f"= {nxt[k].tolist()}" if not model.is_validated else
                   f"in [{enc[k, :, 0].tolist()}, {enc[k, :, 1].tolist()}] (the enclosure "
                   f"of the flow)")
            return Certificate(
                "refuted", False, claim,
                f"state set: f(x, law(x)){ws} {val} lies outside S at "
                f"x = {P[k].tolist()}", details, counterexample=P[k])
    return None


def certify_invariant(model: Model, S: Any, law: Any, eps: float, *, W: Any = None,
                      max_boxes: int = 200_000, time_limit: float | None = None,
                      samples: int = 64, seed: int = 0,
                      progress: bool | None = None, executor: Any = None) -> Certificate:
    """Prove that ``S`` is (robustly) invariant under ``u = law(x)`` (thesis Alg 4.3).

    The claim: for every ``x in S`` and every ``w in W``, ``f(x, law(x), w) in S`` and
    ``law(x) in U``. Two set inversions over sub-zonotopes of S (the successor into S, the
    law into U) decide it piece by piece (:func:`casadi_cmpc.solvers.zonotope_sivia`).
    ``S ⊆ X`` (the model's state box) is not part of the claim: check it apart.

    Parameters
    ----------
    model : Model
    S : Polytope or Zonotope
        A bounded polytope, or a full-dimensional zonotope (with at most
        ``casadi_cmpc.sets.zonotope.MAX_FACETS`` facet candidates). For a zonotope the
        pieces are sub-zonotopes of S itself (its generators widened by 1e-9 relative) and
        ``f(piece) ⊆ S`` is proven against the exact facets of S: an upper bound of the
        support of the enclosure of ``f(piece)`` must not exceed a *lower* bound of the
        support of S in each facet normal (never ``S.to_polytope()``, whose outward-rounded
        offsets describe a slightly larger set, nor a bounding box).
    law : LinearLaw, array_like (m, n) or casadi.SX (m, 1)
        The local law: a :class:`LinearLaw` ``u = u_eq + K (x - x_eq)`` (what
        :func:`local_lqr` returns), a bare gain ``K`` (``u = K x``) or an expression of
        ``model.x``.
    eps : float
        Pieces whose largest generator entry is at most ``eps`` are not split further.
    W : Box, optional
        Disturbance box (default: the model's W).
    max_boxes, time_limit, progress
        Budget and progress bar of each set inversion.
    samples, seed
        Random points of S, and points per unresolved piece, tried as counterexamples.

    executor : concurrent.futures.Executor, optional
        Run the two set inversions' large levels on this executor
        (``ProcessPoolExecutor(n)``, or ``distributed.Client(address).get_executor()``);
        the certificate is that of the serial run.

    Returns
    -------
    Certificate
        ``proved`` True (every piece meeting S proven good), False (a point of S whose
        input or successor is proven to violate a condition, by an interval evaluation at
        the point or by the enclosure of a piece containing it: the ``counterexample`` and
        the violated condition are given; such points are searched first, among the
        vertices of S and random points of S, and then in the undecided pieces), or None
        (undecided: ``details["undecided_pieces"]`` holds their number and bounding boxes).
        A counterexample is always proven to lie in S (a degenerate box certified inside
        by ``S.contains_box``).

    Raises
    ------
    UnsupportedOperationError
        S is neither a Polytope nor a Zonotope, or a flat zonotope, or one with too many
        facets.
    DimensionError
        S or the law has the wrong dimension.
    """
    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    _check_target(S, model.n)
    if W is not None and model.l and isinstance(W, Box) and W.dim == model.l and not (
            np.all(model.W.lo <= W.lo) and np.all(W.hi <= model.W.hi)):
        warnings.warn(f"W = {_box_text(W)} is not inside the model's W = "
                      f"{_box_text(model.W)}: the certificate is about the W given",
                      CmpcWarning, stacklevel=2)
    return _certify(model, _closed(model, law), S, eps, W, max_boxes, time_limit, samples,
                    seed, progress, law=law, executor=executor)


def _closed(model: Model, law: Any) -> tuple[Model, Any]:
    """The closed loop and the law as a Function (compiled once, reused by searches)."""
    expr = _law_expr(model, law)
    return model.closed_loop(expr), ca.Function("law", [model.x], [expr])


def model_key(model: Model) -> str:
    """A hash of what the model's proofs read: :meth:`Model.interval_key`, the model's
    interval source with the intervals of its parameters (of a validated ODE model the
    Taylor map and its proven remainder, so two such models differing only in the
    remainder, e.g. in order, dt or domain, do not share certificates)."""
    return model.interval_key()


def law_identity(model: Model, law: Any) -> dict[str, str]:
    """The law as stored with a certificate: ``law`` (text), ``law_key`` (a hash of its
    expression in the model's x) and ``law_function`` (the serialized Function ``x -> u``).

    Two laws have the same key when they are the same expression of x (a gain matrix K
    and ``K @ x`` written as an SX expression are the same expression)."""
    import hashlib

    expr = _law_expr(model, law)
    fun = ca.Function("law", [model.x], [expr])
    ser = fun.serialize()
    return {"law": str(expr), "law_key": hashlib.sha256(ser.encode()).hexdigest()[:20],
            "law_function": ser}


def law_from_function(model: Model, serialized: str) -> ca.SX:
    """The law expression in ``model.x`` of a serialized law Function (see
    :func:`law_identity`)."""
    return ca.Function.deserialize(serialized)(model.x)


def _claim(model: Model, Wb: Any) -> str:
    """The invariance claim, saying which disturbances it covers and, for a model that is
    not a plain discrete one, what its map f is (:attr:`Model.discretisation`)."""
    body = ": f(x, law(x), w) in S and law(x) in U = " + _box_text(model.U)
    if model.discretisation != "discrete model":
        body += f", f being {model.discretisation}"
    if not model.l:
        return "for every x in S" + body.replace(", w)", ")")
    if np.array_equal(Wb.lo, Wb.hi):
        return (f"for every x in S with w = {Wb.lo.tolist()} only (nominal: no other w "
                "is covered)" + body)
    return f"for every x in S and every w in W = {_box_text(Wb)} (robust)" + body


def _box_text(B: Any) -> str:
    return f"[{np.asarray(B.lo).tolist()}, {np.asarray(B.hi).tolist()}]"


def check_about(cert: Any, model: Model, S: Any, W: Any, law: Any = None) -> str | None:
    """Why an invariance certificate does not support "S is invariant for ``model`` under
    its law for every w in W" (None when it does).

    The certificate must be a proved one of :func:`certify_invariant` about the same
    model (map), the very set S (same rows), a disturbance box containing W (W None: no
    disturbance), and, when ``law`` is given, the same law expression."""
    if not isinstance(cert, Certificate) or cert.proved is not True:
        return "it is not a proved Certificate"
    ab = cert.about or {}
    if ab.get("kind") != "invariance":
        return ("it does not say what it is about (a Certificate of cm.certify_invariant "
                "records the model, the set, the law and W)")
    if ab.get("model_key") != model_key(model):
        if ab.get("model") == model.name:  # one name, two maps
            return (f"it is about another model of the same name '{model.name}' (another "
                    "map f, or other parameters)")
        return f"it is about another model ('{ab.get('model')}'), not '{model.name}'"
    T = ab.get("set")
    same = T is S or (type(T) is type(S) and all(
        np.array_equal(np.asarray(getattr(T, a)), np.asarray(getattr(S, a)))
        for a in (("A", "b") if isinstance(S, Polytope) else ("center", "generators"))))
    if not same:
        return "it is about another set than this one"
    if law is not None and law_identity(model, law)["law_key"] != ab.get("law_key"):
        return (f"it proves the law u = {ab.get('law')}, not the one given "
                f"(u = {law_identity(model, law)['law']})")
    Wc = ab.get("W")
    if model.l and W is not None:
        if Wc is None or not (np.all(np.asarray(Wc.lo) <= np.asarray(W.lo))
                              and np.all(np.asarray(W.hi) <= np.asarray(Wc.hi))):
            return (f"it covers w in {None if Wc is None else _box_text(Wc)} only, not "
                    f"W = {_box_text(W)}")
    return None


def _certify(model: Model, closed: tuple[Model, Any], S: Any, eps: float, W: Any,
             max_boxes: int, time_limit: float | None, samples: int, seed: int,
             progress: bool | None, law: Any = None, executor: Any = None) -> Certificate:
    """certify_invariant after validation, with the closed loop given; the certificate
    records what it is about (see :attr:`Certificate.about`)."""
    import dataclasses

    Wb = W if W is not None else model.W
    cert = _certify_core(model, closed, S, eps, Wb, max_boxes, time_limit, samples, seed,
                         progress, executor)
    about: dict[str, Any] = {"kind": "invariance", "model": model.name,
                             "model_key": model_key(model), "set": S,
                             "W": Wb if model.l else None,
                             "robust": bool(model.l) and not np.array_equal(Wb.lo, Wb.hi),
                             "U": model.U}
    if law is not None:
        about.update(law_identity(model, law))
    return dataclasses.replace(cert, about=about)


def _certify_core(model: Model, closed: tuple[Model, Any], S: Any, eps: float, Wb: Any,
                  max_boxes: int, time_limit: float | None, samples: int, seed: int,
                  progress: bool | None, executor: Any = None) -> Certificate:
    from ..solvers.zonotope_sivia import zonotope_sivia

    t0 = time.perf_counter()
    cl, law_fun = closed
    claim = _claim(model, Wb)
    rng = np.random.default_rng(seed)
    w_pts = (np.asarray(Wb.vertices()) if model.l else np.zeros((1, 0)))
    details: dict[str, Any] = {}
    # the pieces cover a zonotope proven to contain S; pieces proven disjoint from S are
    # left out, the others must satisfy the conditions on the whole piece (sufficient)
    Z0, how = _domain(S)
    details["domain"] = how
    # a cheap search first: vertices and random points of S
    pts = _sample_points(S, Z0 if Z0 is not None else S if isinstance(S, Zonotope)
                         else Zonotope(np.zeros(model.n), np.eye(model.n)), samples, rng)
    cert = _point_counterexample(pts, S, model, cl, law_fun, w_pts, claim, details)
    if cert is not None:
        details["seconds"] = time.perf_counter() - t0
        details["stage"] = "sampled points of S (before the set inversion)"
        return cert
    if Z0 is None:
        details["seconds"] = time.perf_counter() - t0
        return Certificate(
            "undecided", None, claim,
            "no zonotope could be proven to contain S (an ill-conditioned S: floating-point "
            "inverses and vertices do not enclose it provably), so no part of S can be "
            "skipped; no counterexample found among sampled points", details)
    runs = {
        "state set": zonotope_sivia(cl, Z0, S, eps, W=Wb, max_boxes=max_boxes,
                                    time_limit=time_limit, progress=progress,
                                    executor=executor),
        "input bound": zonotope_sivia(law_fun, Z0, model.U, eps, max_boxes=max_boxes,
                                      time_limit=time_limit, progress=progress,
                                      executor=executor),
    }
    unresolved = []
    for name, pav in runs.items():
        bad = ~_disjoint(pav.outside, S) if len(pav.outside) else np.zeros(0, dtype=bool)
        details[name] = {"inner": len(pav.inner), "boundary": len(pav.boundary),
                         "outside": int(pav.n_discarded), "status": pav.status.name,
                         "seconds": pav.elapsed}
        if bad.any():
            unresolved.append((name, pav.outside, bad, True))
        if len(pav.boundary):
            meet = ~_disjoint(pav.boundary, S)
            if meet.any():
                unresolved.append((name, pav.boundary, meet, False))
    # look for a concrete counterexample in the proven-bad pieces first, then in the
    # undecided ones
    cands = [np.zeros((0, model.n))]
    for _, fr, mask, _ in unresolved:
        cands += [np.asarray(fr.centers)[mask],
                  fr.sample(samples, rng=rng)[mask].reshape(-1, model.n)]
    cert = _point_counterexample(np.concatenate(cands), S, model, cl, law_fun, w_pts, claim,
                                 details)
    details["seconds"] = time.perf_counter() - t0
    if cert is not None:
        return cert
    # a proven-bad piece refutes the claim only where it is proven to meet S: its centre
    # (a point of the piece) proven inside S is a counterexample by the piece's enclosure
    still = []
    for name, fr, mask, proven in unresolved:
        if proven:
            idx = np.flatnonzero(mask)
            C = np.asarray(fr.centers)[idx]
            ins = _proven_in(S, C)
            if ins.any():
                x = C[int(np.flatnonzero(ins)[0])]
                what = ("law(x) lies outside U" if name == "input bound" else
                        "f(x, law(x), w) lies outside S" + (" for every w in W" if model.l
                                                             else ""))
                return Certificate(
                    "refuted", False, claim,
                    f"{name}: {what} at x = {x.tolist()} (x proven inside S; the enclosure "
                    "over a piece of S containing x is proven disjoint from the target)",
                    details, counterexample=x)
            mask = np.zeros(len(fr), dtype=bool)
            mask[idx] = True
        still.append((name, fr, mask))
    if still:
        boxes = np.concatenate([fr.bounding_boxes()[mask] for _, fr, mask in still])
        details["undecided_pieces"] = int(boxes.shape[0])
        details["undecided_boxes"] = boxes
        budget = any(p.status.name == "BUDGET" for p in runs.values())
        return Certificate("undecided", None, claim,
                           _undecided_reason(still, eps, budget, model), details)
    return Certificate("proved", True, claim,
                       "set inversion over sub-zonotopes of S (Alg 4.3): every piece meeting "
                       "S has its successor inside S and its input inside U, with outward "
                       "rounding", details)


def _undecided_reason(still: list, eps: float, budget: bool, model: Model) -> str:
    """Which condition is undecided where, and what to try."""
    parts, total = [], 0
    for name, fr, mask in still:
        bb = fr.bounding_boxes()[mask]
        total += bb.shape[0]
        lo, hi = bb[:, :, 0].min(axis=0), bb[:, :, 1].max(axis=0)
        what = ("law(x) in U" if name == "input bound" else
                "f(x, law(x), w) in S for all w in W" if model.l else "f(x, law(x)) in S")
        parts.append(f"{what} undecided on {bb.shape[0]} pieces within "
                     f"[{np.round(lo, 6).tolist()}, {np.round(hi, 6).tolist()}]")
    tries = [f"a smaller eps (e.g. {eps / 4:g})"]
    if budget:
        tries.insert(0, "a larger max_boxes or time_limit (the budget was reached)")
    if any(name != "input bound" for name, _, _ in still):
        tries.append("a smaller S, or one shaped by a Lyapunov level set of the closed loop "
                     "(the successors of these pieces reach S's boundary)")
    if any(name == "input bound" for name, _, _ in still):
        tries.append("a smaller S or a gentler gain (law(x) reaches U's bounds there)")
    return (f"{total} pieces of S left undecided at eps = {eps}"
            + (" (budget reached)" if budget else "") + ": " + "; ".join(parts)
            + "; no counterexample found. Try " + ", or ".join(tries))


# ------------------------------------------------------------------- Alg 4.4
@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class InvariantZonotopeResult(Result):
    """Result of :func:`largest_invariant_zonotope`.

    Attributes
    ----------
    zonotope : Zonotope or None
        The largest zonotope found that is PROVEN invariant (its ``certificate`` has
        ``proved is True``); ``None`` when no zonotope of the search was proven invariant.
    volume : float
        Its volume (area in 2-D), 0.0 when ``zonotope`` is None.
    certificate : Certificate or None
        The certificate of :func:`certify_invariant` for ``zonotope``.
    M : ndarray, shape (n, m, 2), or None
        The interval matrix whose zonotope inclusion ``center ⊕ ◇(M B^m)`` is ``zonotope``.
    stats : dict
        ``iterations`` (families taken from the queue), ``tested`` (families certified),
        ``proved``, ``refuted``, ``undecided``, ``outside_X`` (zonotopes not proven inside
        the model's X, hence not tested), ``queued`` (families left when the search
        stopped), ``seconds``, ``certify_seconds``.
    status, success, message, method, nit, n_boxes, elapsed
        See :class:`~casadi_cmpc.solvers.result.Result`: ``PROVED`` (0) the search
        completed and found a zonotope proven invariant; ``BUDGET`` (1) ``max_iter``,
        ``time_limit`` or an interruption stopped it (``zonotope``, if any, is still
        proven invariant, but a larger one may exist); ``UNDECIDED`` (3) the search
        completed and no zonotope was proven invariant. ``nit`` counts iterations,
        ``n_boxes`` the families certified.
    """

    zonotope: Zonotope | None
    volume: float
    certificate: Certificate | None
    M: np.ndarray | None
    stats: dict = field(default_factory=dict)

    def _repr_parts(self) -> list[str]:
        return [f"volume={self.volume:.6g}",
                f"generators={None if self.zonotope is None else self.zonotope.n_generators}"]


def _interval_matrix(M0: Any, n: int) -> np.ndarray:
    M = np.array(M0, dtype=float)
    if M.ndim != 3 or M.shape[2] != 2 or M.shape[0] != n or M.shape[1] < 1:
        raise DimensionError(
            f"M0 must be an interval matrix of shape (n, m, 2) = ({n}, m, 2) (entries as "
            f"[lo, hi]); got shape {M.shape}")
    if not np.isfinite(M).all():
        raise ValueError("M0 has a NaN or infinite bound")
    if (M[..., 0] > M[..., 1]).any():
        i, j = np.argwhere(M[..., 0] > M[..., 1])[0]
        raise ValueError(f"M0 is empty at entry ({i}, {j}): {M[i, j, 0]} > {M[i, j, 1]}")
    return M


def largest_invariant_zonotope(model: Model, law: Any, M0: Any, eps_opt: float,
                               eps_sivia: float, *, W: Any = None, center: Any = None,
                               relative_eps: bool = True, max_iter: int = 100_000,
                               time_limit: float | None = None, max_boxes: int = 200_000,
                               samples: int = 64, seed: int = 0,
                               progress: bool | None = None,
                               executor: Any = None) -> InvariantZonotopeResult:
    r"""The largest zonotope proven invariant under ``u = law(x)`` (thesis Alg 4.4, GOF SIVZG).

    Candidates are the zonotope inclusions ``Z_k = center ⊕ ◇(M_k B^m)`` (Thm 4.3:
    ``Mid(M_k) B^m ⊕ G B^n``, ``G`` diagonal with ``G_ii = sum_j Rad(M_k)_ij``, i.e.
    ``m + n`` generators) of interval matrices ``M_k`` obtained from ``M0`` by bisecting the
    widest entry. Each candidate is tested by :func:`certify_invariant` (set inversion via
    zonotope geometry, Alg 4.3) and must lie inside the model's state box X; the largest
    candidate proven invariant is returned.

    Parameters
    ----------
    model : Model
    law : LinearLaw, array_like (m, n) or casadi.SX (m, 1)
        The local law: a :class:`LinearLaw` ``u = u_eq + K (x - x_eq)`` (what
        :func:`local_lqr` returns), a bare gain ``K`` (``u = K x``) or an expression of
        ``model.x``.
    M0 : array_like, shape (n, m, 2)
        The initial interval generator matrix, entry ``(i, j)`` as ``[lo, hi]``.
    eps_opt : float
        Interval matrices whose widest entry is at most ``eps_opt`` are not bisected.
    eps_sivia : float
        Tolerance of the set inversion of each test: pieces whose largest generator entry
        is at most ``eps_sivia * Max(H_k)`` (``relative_eps=True``, the default, with
        ``Max(H_k)`` the largest generator entry of the candidate) or ``eps_sivia``
        (``relative_eps=False``) are not split.
    W : Box, optional
        Disturbance box (default: the model's W): robust invariance.
    center : array_like (n,), optional
        Centre of the candidates (default: the equilibrium ``x_eq`` of a
        :class:`LinearLaw`, else the origin).
    relative_eps : bool
        See ``eps_sivia``. The thesis' value for E6 (0.05) exceeds the generators of every
        candidate there, so read as an absolute tolerance it would allow no bisection at
        all; read relative to the candidate it is a resolution of 1/20 of its size.
    max_iter, time_limit : optional
        Limits on the families taken from the queue and on the wall-clock time (s); a
        stopped search returns its best proven zonotope with status BUDGET.
    max_boxes : int
        Budget of each set inversion (pieces classified).
    samples, seed
        Random points tried as counterexamples (see :func:`certify_invariant`).
    progress : bool or None
        tqdm progress bar (None: only for searches longer than 2 s).

    executor : concurrent.futures.Executor, optional
        Run the large levels of each candidate's certification on this executor
        (:func:`certify_invariant`); the result is that of the serial run.

    Returns
    -------
    InvariantZonotopeResult
        ``zonotope`` (proven invariant, or None), ``volume``, ``certificate``, ``M``,
        ``stats``, ``status`` (see the class).

    Notes
    -----
    The inclusion ``◇`` is monotone: ``M' ⊆ M`` gives ``◇(M' B^m) ⊆ ◇(M B^m)`` (each
    support function decreases), so ``Vol(◇(M_k B^m))`` bounds the volume of every
    candidate below ``M_k``. The queue is therefore ordered by that volume (largest first;
    the thesis pops a stack) and the search stops as soon as the next bound does not
    exceed the volume of the best proven candidate: the result is the largest proven
    candidate of the thesis' search tree, without testing the (smaller) children of proven
    families. A candidate refuted by a counterexample or left undecided is bisected, as in
    Alg 4.4. Only ``certify_invariant`` proofs count: the returned zonotope is proven
    invariant (with outward rounding); that no larger candidate is invariant is NOT
    claimed (undecided candidates may be).

    Examples
    --------
    >>> import casadi as ca, numpy as np, casadi_cmpc as cm
    >>> x = ca.SX.sym("x", 2); u = ca.SX.sym("u")
    >>> f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * (u + 0.2 * ca.sin(x[0])))
    >>> model = cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-2], [2]))
    >>> K = cm.local_lqr(model, np.eye(2), 1.0)
    >>> M0 = [[[0.0, 0.4], [-0.4, 0.0]], [[0.0, 0.4], [0.0, 0.4]]]
    >>> res = cm.largest_invariant_zonotope(model, K, M0, eps_opt=0.1, eps_sivia=0.1,
    ...                                     progress=False)
    >>> res.status.name, res.certificate.proved, round(res.volume, 4)
    ('PROVED', True, 1.12)
    >>> res.zonotope.generators  # Mid(M) and Kuhn's diagonal
    array([[ 0.35, -0.25,  0.1 ,  0.  ],
           [ 0.15,  0.35,  0.  ,  0.1 ]])
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from tqdm.auto import tqdm

    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    n = model.n
    M0a = _interval_matrix(M0, n)
    eps_opt = positive_eps(eps_opt, "eps_opt")
    eps_sivia = positive_eps(eps_sivia, "eps_sivia")
    if center is None:  # the equilibrium of a LinearLaw, when it names one
        center = getattr(law, "x_eq", None)
    c = _vector(center, n, "center", np.zeros(n))
    closed = _closed(model, law)  # compiled once for all the tests
    X = getattr(model, "X", None)
    t0 = time.perf_counter()
    counter = itertools.count()
    heap: list[tuple[float, int, np.ndarray, Zonotope]] = []

    def push(M: np.ndarray) -> None:
        Z = zonotope_inclusion(c, M[..., 0], M[..., 1])
        v = Z.volume()
        if v > 0.0:  # flat families stay flat below: never larger than anything
            heapq.heappush(heap, (-v, next(counter), M, Z))

    push(M0a)
    best: tuple[Zonotope, float, Certificate, np.ndarray] | None = None
    st = {"iterations": 0, "tested": 0, "proved": 0, "refuted": 0, "undecided": 0,
          "outside_X": 0, "certify_seconds": 0.0}
    status, message = Status.PROVED, "search completed"
    bar = tqdm(total=None, desc="invariant zonotope", unit="family",
               disable=progress is False, delay=0 if progress else 2.0, leave=False)
    scope = InterruptScope()
    try:
        while heap:
            if best is not None and -heap[0][0] <= best[1]:
                break  # nothing left can be larger than the best proven candidate
            if st["iterations"] >= max_iter:
                status, message = Status.BUDGET, f"max_iter = {max_iter} reached"
                break
            elapsed = time.perf_counter() - t0
            if time_limit is not None and elapsed > time_limit:
                status, message = Status.BUDGET, f"time_limit = {time_limit} s reached"
                break
            negv, _, M, Z = heapq.heappop(heap)
            st["iterations"] += 1
            proved = False
            if X is not None and not Z.contained_in(X):
                st["outside_X"] += 1
            elif Z.is_full_dimensional() and Z._facet_data() is not None:
                G = Z.generators
                eps = eps_sivia * float(np.abs(G).max()) if relative_eps else eps_sivia
                left = None if time_limit is None else max(time_limit - elapsed, 1e-3)
                t1 = time.perf_counter()
                cert = _certify(model, closed, Z, eps, W, max_boxes, left, samples, seed,
                                False, law=law, executor=executor)
                st["certify_seconds"] += time.perf_counter() - t1
                st["tested"] += 1
                if cert.proved is True:
                    st["proved"] += 1
                    proved = True
                    best = (Z, -negv, cert, M)
                elif cert.proved is False:
                    st["refuted"] += 1
                else:
                    st["undecided"] += 1
            if not bar.disable:
                bar.update(1)
                bar.set_postfix(best=0.0 if best is None else best[1], queue=len(heap),
                                refresh=False)
            if proved:
                continue  # the children are inside Z: none is larger
            w = M[..., 1] - M[..., 0]
            if w.max() <= eps_opt:
                continue
            # the widest entry (first in row order) is halved
            lo2, hi2, _, _ = bisect_widest(M[..., 0].reshape(1, -1), M[..., 1].reshape(1, -1),
                                           w.reshape(1, -1))
            for half in range(2):
                push(np.stack([lo2[half], hi2[half]], axis=-1).reshape(M.shape))
    except KeyboardInterrupt:
        scope.reraise_if_nested()
        status, message = Status.BUDGET, "interrupted"
    finally:
        scope.close()
        bar.close()
    st["queued"] = len(heap)
    st["seconds"] = time.perf_counter() - t0
    if best is None:
        if status == Status.PROVED:
            status = Status.UNDECIDED
            message = ("search completed: no zonotope of the search was proven invariant "
                       f"({st['refuted']} refuted, {st['undecided']} undecided, "
                       f"{st['outside_X']} not inside X)")
        else:
            message += "; no zonotope proven invariant so far"
        zon, vol, cert, Mb = None, 0.0, None, None
    else:
        zon, vol, cert, Mb = best
        if status == Status.PROVED:
            message = (f"search completed: the largest candidate proven invariant has volume "
                       f"{vol:.6g}")
        else:
            message += f"; best zonotope proven invariant so far has volume {vol:.6g}"
    return InvariantZonotopeResult(
        status=status, message=message, method="GOF SIVZG (Alg 4.4)", nit=st["iterations"],
        n_boxes=st["tested"], elapsed=st["seconds"], zonotope=zon, volume=float(vol),
        certificate=cert, M=None if Mb is None else Mb.copy(), stats=st)
