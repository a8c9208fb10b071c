"""Set operations on polytopes: images, Minkowski and Pontryagin sums, comparisons,
differences and convex hulls.

The results are floating-point H-representations equal to the exact sets up to the
tolerances documented in each method of :class:`~casadi_cmpc.sets.polytope.Polytope`
(``pontryagin_difference`` is a proven inner approximation, ``is_subset`` of a union a
proof); the methods of the class call these functions.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .._validate import as_float_array
from ..exceptions import DimensionError, InvalidBoundsError, UnboundedSetError
from . import _hull
from ._boxkernel import _gamma
from ._poly_union import CoverBudget, PolytopeUnion, _uncovered
from .box import Box

if TYPE_CHECKING:
    from .polytope import Polytope

__all__ = ["hull"]

_MAX_VERTEX_SUMS = 200_000


def _as_matrix(M: Any, n: int, name: str) -> np.ndarray:
    """``M`` as a finite 2-D float array; a scalar ``s`` gives ``s I`` of shape (n, n)."""
    arr = as_float_array(M, name)
    if arr.ndim == 0:
        arr = float(arr) * np.eye(n)
    if arr.ndim != 2:
        raise DimensionError(f"{name} must be a 2-D array; got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise InvalidBoundsError(f"{name} contains NaN or an infinite entry")
    return arr


def _as_vector(t: Any, p: int, name: str) -> np.ndarray:
    """``t`` as a finite float vector of shape (p,); None gives zeros."""
    if t is None:
        return np.zeros(p)
    arr = as_float_array(t, name).ravel()
    if arr.shape != (p,):
        raise DimensionError(f"{name} must have shape ({p},); got {np.shape(t)}")
    if not np.isfinite(arr).all():
        raise InvalidBoundsError(f"{name} contains NaN or an infinite entry")
    return arr


def affine_map(P: Polytope, M: Any, t: Any = None) -> Polytope:
    """The image ``{M x + t : x in P}`` (:meth:`Polytope.affine_map`): M of shape (p, n) or a
    scalar, t of shape (p,); a polytope of dimension p."""
    from .polytope import Polytope

    n = P.dim
    M = _as_matrix(M, n, "M")
    if M.shape[1] != n:
        raise DimensionError(f"M must have {n} columns; got shape {M.shape}")
    p = M.shape[0]
    t = _as_vector(t, p, "t")
    if P.is_empty():
        return Polytope.empty(p)
    R = P._rows()
    if p == n and np.linalg.cond(M) < 1e10:
        AMi = np.linalg.solve(M.T, R.A.T).T
        out = Polytope(AMi, R.b + AMi @ t)
        if "vertices" in P._cache:
            out._cache["vertices"] = P._cache["vertices"] @ M.T + t
        return out
    if P.is_bounded():
        return Polytope.from_vertices(P.vertices() @ M.T + t)
    lifted_A = np.vstack([np.hstack([R.A, np.zeros((R.A.shape[0], p))]),
                          np.hstack([-M, np.eye(p)]), np.hstack([M, -np.eye(p)])])
    lifted_b = np.concatenate([R.b, t, -t])
    return Polytope(lifted_A, lifted_b).project(list(range(n, n + p)),
                                                method="elimination")


def minkowski_sum(P: Polytope, other: Any) -> Polytope:
    """The Minkowski sum ``P ⊕ Q`` (:meth:`Polytope.minkowski_sum`)."""
    from .polytope import Polytope

    n = P.dim
    Q = Polytope._coerce(other, n)
    if P.is_empty() or Q.is_empty():
        return Polytope.empty(n)
    if P.is_bounded() and Q.is_bounded():
        V1, V2 = P.vertices(), Q.vertices()
        if V1.shape[0] * V2.shape[0] <= _MAX_VERTEX_SUMS:
            return Polytope.from_vertices((V1[:, None, :] + V2[None]).reshape(-1, n))
    R1, R2 = P._rows(), Q._rows()
    lifted_A = np.vstack([np.hstack([R1.A, np.zeros((R1.A.shape[0], n))]),
                          np.hstack([-R2.A, R2.A])])
    lifted_b = np.concatenate([R1.b, R2.b])
    return Polytope(lifted_A, lifted_b).project(list(range(n, 2 * n)))


def pontryagin_difference(P: Polytope, other: Any) -> Polytope:
    """An inner approximation of ``P ⊖ Q`` (:meth:`Polytope.pontryagin_difference`)."""
    from .polytope import Polytope

    n = P.dim
    if not hasattr(other, "support") or getattr(other, "dim", None) != n:
        raise TypeError(
            f"other must be a set of dimension {n} with a support function; "
            f"got {type(other).__name__}")
    R = P._rows()
    if R.empty:
        return Polytope.empty(n)
    h = _support_up(other, R.A) if R.A.shape[0] else np.zeros(0)
    with np.errstate(invalid="ignore"):
        b = np.nextafter(R.b - h, -np.inf)
    return Polytope(R.A, np.where(np.isnan(b), -np.inf, b))


def is_subset(P: Polytope, other: Any, tol: float | None = None) -> bool:
    """Whether ``P ⊆ other`` (:meth:`Polytope.is_subset`).

    For a union, ``True`` is a proof and ``False`` means "not proven" (see
    :func:`subset_of_union`, which also says why).
    """
    from .polytope import Polytope

    n = P.dim
    if isinstance(other, PolytopeUnion):
        return subset_of_union(P, other) == "proved"
    Q = Polytope._coerce(other, n)
    if P.is_empty():
        return True
    QR = Q._rows()
    if Q.is_empty():
        return False
    tol_ = QR.tol if tol is None else float(tol)
    if QR.An.shape[0] == 0:
        return True
    h = np.asarray(P.support(QR.An))
    # an unbounded direction of P is never inside a row, even one whose offset lies
    # beyond the double range (bn = +inf): the real half-space still ends
    return bool(np.all((h <= QR.bn + tol_) & (h < np.inf)))


def subset_of_union(P: Polytope, U: PolytopeUnion, budget: CoverBudget | None = None,
                    stats: dict[str, Any] | None = None) -> str:
    """Three-valued covering test ``P ⊆ U`` by the covering engine.

    Parameters
    ----------
    P : Polytope
        Dimension n.
    U : PolytopeUnion
        Dimension n.
    budget : CoverBudget, optional
        Limits of the proof (default: the engine's default budget).
    stats : dict, optional
        Filled with the engine's counters (see ``_uncovered``).

    Returns
    -------
    str
        ``"proved"`` (``P ⊆ U`` proven on the stored rows), ``"not proven"`` (a piece
        could not be proven empty: usually a point of P outside U, or P unbounded) or
        ``"budget exhausted"`` (the proof was stopped: nothing is known). Neither of the
        last two is a proof that ``P`` is not a subset.

    Raises
    ------
    DimensionError
        ``U`` has another dimension.
    """
    n = P.dim
    if U.dim != n:
        raise DimensionError(f"other has the wrong dimension; expected {n} instead of {U.dim}")
    if P.is_empty():
        return "proved"
    if not P.is_bounded():
        return "not proven"
    st: dict[str, Any] = {} if stats is None else stats
    if not P.is_full_dimensional():
        ok = flat_subset_of_union(P, U, budget, st)
    else:
        R = P._rows()
        box = P.bounding_box().as_array()[None]
        centre = P._chebyshev()[0][None]
        ok = _uncovered(U._members(), box, centre, [(R.A, R.b)], budget, st)[0] is None
    if ok:
        return "proved"
    return "budget exhausted" if st.get("exhausted") else "not proven"


def flat_subset_of_union(P: Polytope, U: PolytopeUnion, budget: CoverBudget | None = None,
                         stats: dict[str, Any] | None = None) -> bool:
    """``P ⊆ U`` for a bounded P without interior, decided in the affine hull of P.

    The members are restricted to the affine hull ``{o + Q t}`` of the vertices of P
    (rows ``A Q``, ``b - A o``, rounded), where P has an interior, and the covering
    engine runs there: a proof up to the rounding of that restriction only. ``False``
    means "not proven" (also when the ``budget`` runs out; ``stats`` says so).
    """
    from .polytope import Polytope

    V = P.vertices()
    o, Q, _ = _hull.affine_hull(V)
    r = Q.shape[1]
    if r == 0:
        return bool(U.contains(V[0]))
    T = (V - o) @ Q
    R = P._rows()
    members = []
    for M in U._members():
        MR = M._rows()
        Mt = Polytope(MR.A @ Q, MR.b - MR.A @ o)
        if not Mt.is_empty():
            members.append(Mt)
    box = np.stack([T.min(axis=0), T.max(axis=0)], axis=-1)[None]
    hard = [(R.A @ Q, R.b - R.A @ o)]
    return _uncovered(members, box, T.mean(axis=0)[None], hard, budget, stats)[0] is None


def difference(P: Polytope, other: Any) -> PolytopeUnion:
    """The closure of ``P \\ Q`` as a union of polytopes (:meth:`Polytope.difference`)."""
    from .polytope import Polytope

    n = P.dim
    Q = Polytope._coerce(other, n)
    if P.is_empty():
        return PolytopeUnion([], dim=n)
    if Q.is_empty():
        return PolytopeUnion([Polytope(P.A, P.b)], dim=n)
    QR = Q._rows()
    tol = P._rows().tol
    h = np.asarray(P.support(QR.An)) if QR.An.shape[0] else np.zeros(0)
    J = np.flatnonzero(h > QR.bn + tol)
    full = P.is_full_dimensional()
    pieces = []
    for k, j in enumerate(J.tolist()):
        prev = J[:k]
        Pk = Polytope(np.vstack([P.A, -QR.A[[j]], QR.A[prev]]),
                      np.concatenate([P.b, -QR.b[[j]], QR.b[prev]]))
        r = Pk._chebyshev()[1]
        if (r > tol) if full else (r >= -tol):
            pieces.append(Pk)
    return PolytopeUnion(pieces, dim=n)


def hull(*sets: Any) -> Polytope:
    """Convex hull of the union of bounded sets (thesis §3.2).

    Parameters
    ----------
    *sets : Polytope, Box, PolytopeUnion, or any set with ``vertices()``
        At least one, all of the same dimension; empty polytopes are ignored.

    Returns
    -------
    Polytope
        The empty polytope when every set is empty.

    Raises
    ------
    UnboundedSetError
        A set is unbounded.

    Examples
    --------
    >>> import casadi_cmpc as cm
    >>> T1 = cm.Polytope.from_vertices([[0, 0], [1, 0], [0, 1]])
    >>> T2 = T1.translate([1, 1])
    >>> float(round(cm.hull(T1, T2).volume(), 12))
    2.5
    """
    from .polytope import Polytope

    if not sets:
        raise ValueError("hull needs at least one set")
    dims = {s.dim for s in sets}
    if len(dims) != 1:
        raise DimensionError(f"hull: the sets differ in dimension: {sorted(dims)}")
    n = dims.pop()
    pts = []
    for s in sets:
        if isinstance(s, Box):
            if not s.is_bounded():
                raise UnboundedSetError("hull: a Box has an infinite bound")
            pts.append(s.vertices())
        elif isinstance(s, (Polytope, PolytopeUnion)):
            if not s.is_empty():
                pts.append(s.vertices())
        else:
            pts.append(np.asarray(s.vertices(), dtype=float))
    if not pts:
        return Polytope.empty(n)
    return Polytope.from_vertices(np.vstack(pts))


def _support_up(Q: Any, D: np.ndarray) -> np.ndarray:
    """Upper bounds (k,) of the support function of Q in the directions D (k, n)."""
    from .polytope import Polytope
    from .zonotope import Zonotope

    if isinstance(Q, Polytope):
        if Q.is_empty():
            return np.full(D.shape[0], -np.inf)
        return Q._support_upper(D)
    if isinstance(Q, Zonotope):
        return Q._support_upper(D)
    if isinstance(Q, Box):
        with np.errstate(invalid="ignore"):
            t = np.where(D == 0, 0.0, np.maximum(D * Q.lo, D * Q.hi))
            s = t.sum(axis=1)
            return s + (_gamma(D.shape[1] + 1) * np.abs(t).sum(axis=1) + 1e-300)
    h = np.atleast_1d(np.asarray(Q.support(D), dtype=float))
    with np.errstate(invalid="ignore"):
        return h + (1e-12 * np.abs(h) + 4 * np.abs(np.spacing(h)))
