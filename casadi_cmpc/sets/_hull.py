"""Convex hulls of points and double-description conversions.

Backends: pycddlib (``pip install casadi_cmpc[cdd]``; the ``cdd`` module, imported only
when first needed, see :func:`_cdd`) when it is importable, otherwise scipy's Qhull
(``ConvexHull``, ``HalfspaceIntersection``) and LPs.  Both give the same sets up to the
outward tolerances documented in :mod:`casadi_cmpc.sets.polytope`.

All conversions work in floating point (``pycddlib-standalone`` ships the float arithmetic
of cddlib only).  Every H-representation of a hull built here has its right-hand sides
recomputed from the input points and rounded upward (``b_k >= max_i a_k.p_i`` exactly),
so the hull contains every input point exactly.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from types import ModuleType
from typing import Any

import numpy as np

from ..exceptions import EmptySetError, SolverError, UnboundedSetError

__all__: list[str] = []

#: Relative tolerance for the numerical rank of a point cloud, relative to its spread
#: (largest singular value of the differences): translation and scale invariant.
RANK_RTOL = 1e-12
#: Points whose thickness (a singular value of their differences) is below
#: ``FLAT_ULPS * 2**-53 * sqrt(N) * max |p|`` (about the rounding of their coordinates)
#: are flat, whatever their spread.
FLAT_ULPS = 2
_U = 2.0 ** -53


def _cdd() -> ModuleType | None:
    """The ``cdd`` module (pycddlib) when importable, else None (scipy/LP fallback)."""
    try:
        import cdd
    except ImportError:
        return None
    return cdd


def dot_upper(P: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Right-hand sides ``b_k >= max_i A_k . P_i`` holding exactly (not only in floats).

    ``b_k`` is the floating-point maximum when it is exact enough (checked for every
    point within the rounding bound of the maximum by error-free products and a
    correctly rounded sum), else that maximum plus a rigorous bound of its rounding
    error.

    Parameters
    ----------
    P : ndarray, shape (N, n)
    A : ndarray, shape (k, n)

    Returns
    -------
    ndarray, shape (k,)
    """
    from ._boxkernel import exact_dot_le

    n = P.shape[1]
    val = P @ A.T  # (N, k)
    err = (np.abs(P) @ np.abs(A).T) * (2 * (n + 2) * _U) + 1e-300
    b = val.max(axis=0)
    ii, kk = np.nonzero(val + err > b)
    if ii.size:
        ok = exact_dot_le(P[ii], A[kk], b[kk])
        bad = np.unique(kk[~ok])
        if bad.size:
            b[bad] = np.nextafter((val[:, bad] + err[:, bad]).max(axis=0), np.inf)
    return b


def affine_hull(points: np.ndarray, rtol: float = RANK_RTOL, max_rank: int | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Affine hull of points.

    The differences are taken to one of the points (the one nearest to their mean), so
    they carry relative rounding errors only: a common translation of the points does not
    change them (the rounding error of a mean far from the origin would add a spurious
    direction). The rank is read from their singular values relative to the largest one
    (translation and scale invariant), ``s_k > rtol s_1``, and is at most ``N - 1`` for
    ``N`` distinct points (and at most ``max_rank`` when given).

    Parameters
    ----------
    points : ndarray, shape (N, n)
    rtol : float
    max_rank : int, optional

    Returns
    -------
    origin : ndarray, shape (n,)
        One of the points (exactly).
    U : ndarray, shape (n, r)
        Orthonormal basis of the directions of the hull (``r`` its dimension).
    N : ndarray, shape (n, n - r)
        Orthonormal basis of the orthogonal complement.
    """
    P = np.asarray(points, dtype=float)
    n = P.shape[1]
    if P.shape[0] == 0:
        return np.zeros(n), np.zeros((n, 0)), np.eye(n)
    with np.errstate(over="ignore", invalid="ignore"):
        mean = P.mean(axis=0)
        dist = np.abs(P - mean).max(axis=1)
    k0 = int(np.argmin(np.where(np.isfinite(dist), dist, np.inf)))
    origin = P[k0].copy()
    if P.shape[0] <= 1 or not np.any(P != origin):
        return origin, np.zeros((n, 0)), np.eye(n)
    D = P - origin
    # scale first: differences of huge coordinates must not overflow inside the SVD
    dmax = float(np.abs(D).max())
    D = D / dmax
    # the complement needs all n right singular vectors, never the N x N left ones
    _, s, Vt = np.linalg.svd(D, full_matrices=D.shape[0] < n)
    n_distinct = np.unique(P, axis=0).shape[0]
    # thickness at the rounding level of the coordinates themselves is no dimension
    floor = FLAT_ULPS * _U * math.sqrt(P.shape[0]) * float(np.abs(P).max()) / dmax
    r = max(1, int(np.sum(s > max(rtol * s[0], floor))))
    r = min(r, n_distinct - 1, n if max_rank is None else max(1, int(max_rank)))
    return origin, Vt[:r].T.copy(), Vt[r:].T.copy()


def _merge_rows(A: np.ndarray, decimals: int = 9) -> np.ndarray:
    """Drop duplicate unit normals (Qhull triangulates non-simplicial facets)."""
    if A.shape[0] <= 1:
        return A
    _, idx = np.unique(np.round(A, decimals), axis=0, return_index=True)
    return A[np.sort(idx)]


def _convex_hull(Z: np.ndarray) -> Any:
    """scipy's ConvexHull of Z, retried with joggled input ("QJ") for degenerate points."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        return ConvexHull(Z)
    except (QhullError, ValueError):
        try:
            return ConvexHull(Z, qhull_options="QJ")
        except (QhullError, ValueError) as exc:
            raise SolverError(f"Qhull could not compute a convex hull: {exc}") from exc


def _qhull(Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Facet normals (unit, outward) and hull vertex indices of full-dimensional points Z."""
    Z = Z / max(float(np.abs(Z).max()), 1e-300)
    if Z.shape[0] <= Z.shape[1]:
        raise SolverError(f"Qhull needs at least {Z.shape[1] + 1} points in {Z.shape[1]}-D "
                          f"to build a simplex; got {Z.shape[0]}")
    h = _convex_hull(Z)
    normals = h.equations[:, :-1]
    if not np.isfinite(normals).all():
        raise SolverError("Qhull returned non-finite facet normals")
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    return _merge_rows(normals), np.asarray(h.vertices, dtype=np.int64)


def _polygon_normals(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit outward edge normals of the convex hull of 2-D points, and its vertices.

    Each normal is computed from the two end points of its edge as ``(dy, -dx)`` and
    normalised: two polygons sharing an edge get exactly opposite rows (floating-point
    subtraction and the norm are symmetric), so they tile the plane along the edge
    without a rounding-level gap.
    """
    Z = P - P[0]  # the combinatorics only: translation and scale invariant
    Z = Z / max(float(np.abs(Z).max()), 1e-300)
    h = _convex_hull(Z)
    Hv = P[h.vertices]
    rows = []
    for i, j in h.simplices:
        p, q = P[i], P[j]
        nrm = np.array([q[1] - p[1], p[0] - q[0]])
        # orientation from the hull vertex farthest from the edge's line (differences of
        # input points, not a rounded centre: thin polygons far away keep their sign)
        side = (Hv - p) @ nrm
        if side[int(np.argmax(np.abs(side)))] > 0:
            nrm = -nrm
        rows.append(nrm / np.hypot(nrm[0], nrm[1]))
    A = np.unique(np.array(rows), axis=0)
    return A, np.asarray(h.vertices, dtype=np.int64)


def hull_hrep(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H-representation of the convex hull of points.

    The affine dimension ``r`` is the numerical rank of the differences (see
    :func:`affine_hull`). A hull found flat (``r < n``) gets the pairs of rows ``±v`` of
    the normals of its affine hull; when the points are flat only up to the rank
    tolerance, these pairs are a slab as thick as the points (an outer description), and
    every input point that is extreme in the flat hull is returned as a vertex. When
    Qhull fails on a nearly degenerate cloud, ``r`` is lowered by one (the same outer
    description, one dimension flatter) until it succeeds.

    Parameters
    ----------
    points : ndarray, shape (N, n), N >= 1, finite

    Returns
    -------
    A : ndarray, shape (k, n)
        Unit facet normals; for a hull of dimension ``r < n`` also the pairs ``±v`` of
        the normals ``v`` of its affine hull.
    b : ndarray, shape (k,)
        ``b_k >= max_i A_k . points_i`` (rounded upward: every point is inside exactly).
    vertices : ndarray, shape (v, n)
        The extreme points among ``points``.
    """
    P = np.unique(np.asarray(points, dtype=float), axis=0)
    n = P.shape[1]
    origin, U, Nc = affine_hull(P)
    r = U.shape[1]
    if r == 0:
        A = np.vstack([np.eye(n), -np.eye(n)])
        return A, dot_upper(P, A), P[:1].copy()
    while True:
        try:
            A_sub, vidx, U = _hull_in_flat(P, origin, U)
            break
        except SolverError:
            # Qhull gave up on a nearly degenerate cloud: describe it as one dimension
            # flatter, with a slab as thick as the points (outward, contains every point)
            if r <= 1:  # pragma: no cover - the 1-D hull needs no Qhull
                raise
            r -= 1
            origin, U, Nc = affine_hull(P, max_rank=r)
    if U is None:  # full-dimensional polygon: rows built from the edges
        return A_sub, dot_upper(P, A_sub), P[np.sort(vidx)]
    A = A_sub @ U.T
    if Nc.shape[1] and U.shape[1] < n:
        A = np.vstack([A, Nc.T, -Nc.T])
    A = A / np.linalg.norm(A, axis=1, keepdims=True)
    # exact axis directions stay exact (their rows then describe the flat exactly)
    A = np.where(np.abs(A) < 1e-15, 0.0, A)
    A = A / np.linalg.norm(A, axis=1, keepdims=True)
    return A, dot_upper(P, A), P[np.sort(vidx)]


def _hull_in_flat(P: np.ndarray, origin: np.ndarray, U: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Facet normals (in the coordinates of U) and vertex indices of the hull of P in
    its affine hull ``origin + span(U)``; U is returned (the identity when ``r = n``,
    None for a full-dimensional polygon, whose rows are in R^2 already)."""
    n, r = P.shape[1], U.shape[1]
    if r == n == 2:
        A, vidx = _polygon_normals(P)
        return A, vidx, None
    if r == 1:  # a segment (or an interval when n = 1): its two end points
        U = np.eye(1) if n == 1 else U  # n = 1: keep the axis, the facets stay exact
        # n = 1: the coordinates themselves (subtracting the origin would round points
        # that differ by less than an ulp of it onto each other and lose an end point)
        z = P[:, 0] if n == 1 else ((P - origin) @ U)[:, 0]
        return (np.array([[1.0], [-1.0]]),
                np.unique([int(np.argmax(z)), int(np.argmin(z))]), U)
    if r == n:  # full-dimensional: no rotation (keeps axis-aligned facets exact)
        A_sub, vidx = _qhull(P - origin)
        return A_sub, vidx, np.eye(n)
    Z = (P - origin) @ U
    A_sub, vidx = _qhull(Z)
    return A_sub, vidx, U


def halfspace_vertices(A: np.ndarray, b: np.ndarray, interior: np.ndarray) -> np.ndarray:
    """Vertices of the bounded full-dimensional ``{A x <= b}`` by scipy's Qhull.

    Parameters
    ----------
    A : ndarray, shape (m, n), unit rows
    b : ndarray, shape (m,)
    interior : ndarray, shape (n,)
        A point strictly inside (e.g. the Chebyshev centre).

    Returns
    -------
    ndarray, shape (k, n)
        The extreme points of the intersection.
    """
    from scipy.spatial import HalfspaceIntersection, QhullError

    c = np.asarray(interior, dtype=float)
    bs = b - A @ c
    scale = float(np.abs(bs).max(initial=0.0)) or 1.0
    hs = np.hstack([A, -(bs / scale)[:, None]])
    try:
        pts = HalfspaceIntersection(hs, np.zeros(A.shape[1])).intersections
    except (QhullError, ValueError) as exc:
        raise SolverError(f"Qhull could not intersect the half-spaces: {exc}") from exc
    pts = pts[np.isfinite(pts).all(axis=1)]
    # Each intersection is the vertex of one facet of the dual hull, so every point is
    # extreme; a degenerate vertex (more than n active rows) comes once per dual facet.
    # Merge the copies (in the scaled coordinates, where the polytope has size ~1) instead
    # of a convex hull of them, which is very slow in higher dimensions.
    if pts.shape[0] > 1:
        _, idx = np.unique(np.round(pts * 1e12), axis=0, return_index=True)
        pts = pts[np.sort(idx)]
    return pts * scale + c


def fm_eliminate(A: np.ndarray, b: np.ndarray, keep: list[int],
                 prune: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Project ``{A x <= b}`` onto the coordinates ``keep`` by Fourier–Motzkin elimination.

    Each eliminated variable combines every row with a positive coefficient with every
    row with a negative one; ``prune(A, b)`` removes redundant rows after each step.
    Exact in exact arithmetic; in floating point each combined right-hand side is rounded
    upward (the projection can only grow by rounding).

    Returns
    -------
    A_out : ndarray, shape (k, len(keep))
    b_out : ndarray, shape (k,)
        In the order of ``keep``.
    """
    n = A.shape[1]
    drop = [j for j in range(n) if j not in keep]
    cols = list(range(n))
    for j in drop:
        c = cols.index(j)
        pos = np.flatnonzero(A[:, c] > 0)
        neg = np.flatnonzero(A[:, c] < 0)
        zer = np.flatnonzero(A[:, c] == 0)
        rows = [A[zer]]
        rhs = [b[zer]]
        if pos.size and neg.size:
            lp_ = -A[neg, c][None, :]  # (1, q) > 0
            la = A[pos, c][:, None]  # (p, 1) > 0
            comb = (lp_[..., None] * A[pos][:, None, :] + la[..., None] * A[neg][None])
            comb = comb.reshape(-1, A.shape[1])
            cb = (lp_ * b[pos][:, None] + la * b[neg][None]).ravel()
            err = (np.abs(lp_ * b[pos][:, None]) + np.abs(la * b[neg][None])).ravel()
            cb = np.nextafter(cb + 4 * _U * err, np.inf)
            comb[:, c] = 0.0
            nrm = np.abs(comb).max(axis=1)
            ok = nrm > 0
            cb = np.where(ok, cb / np.where(ok, nrm, 1.0), cb)
            cb = np.nextafter(cb, np.inf)
            comb = np.where(ok[:, None], comb / np.where(ok, nrm, 1.0)[:, None], comb)
            rows.append(comb)
            rhs.append(cb)
        A = np.delete(np.vstack(rows), c, axis=1)
        b = np.concatenate(rhs)
        cols.pop(c)
        zero = ~np.any(A != 0.0, axis=1)
        if np.any(b[zero] < 0.0):
            return np.zeros((1, len(keep))), np.array([-1.0])
        A, b = A[~zero], b[~zero]
        if A.shape[0] > 1:
            A, b = prune(A, b)
    order = [cols.index(j) for j in keep]
    return A[:, order], b


def _cdd_matrix(A: np.ndarray, b: np.ndarray):
    cdd = _require_cdd()

    arr = np.hstack([b[:, None], -A])
    return cdd.matrix_from_array(arr, rep_type=cdd.RepType.INEQUALITY)


def _require_cdd() -> ModuleType:
    cdd = _cdd()
    if cdd is None:
        raise SolverError("pycddlib is not installed (pip install 'casadi_cmpc[cdd]')")
    return cdd


def cdd_vertices(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Vertices of the bounded polytope ``{A x <= b}`` by the double-description method.

    Raises
    ------
    EmptySetError
        cddlib finds no generator.
    UnboundedSetError
        cddlib finds a ray or a line.
    """
    cdd = _require_cdd()
    mat = _cdd_matrix(A, b)
    try:
        gen = cdd.copy_generators(cdd.polyhedron_from_matrix(mat))
    except Exception as exc:  # pragma: no cover - cddlib float failures are rare
        raise SolverError(f"cddlib vertex enumeration failed: {exc}") from exc
    arr = np.array(gen.array, dtype=float).reshape(-1, A.shape[1] + 1)
    if arr.shape[0] == 0:
        raise EmptySetError("the polytope is empty (no vertex)")
    if gen.lin_set or np.any(arr[:, 0] == 0.0):
        raise UnboundedSetError("the polyhedron is unbounded (it has a ray or a line)")
    return arr[:, 1:]


def cdd_eliminate(A: np.ndarray, b: np.ndarray, keep: list[int]
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Project ``{A x <= b}`` onto the coordinates ``keep`` by block elimination (cddlib).

    Returns the H-representation ``(A', b')`` of the projection (redundant rows removed,
    implicit equalities as pairs of inequalities) in the order of ``keep``.
    """
    cdd = _require_cdd()
    n = A.shape[1]
    drop = [j for j in range(n) if j not in keep]
    mat = _cdd_matrix(A, b)
    kept = sorted(keep)
    try:
        out = cdd.block_elimination(mat, {j + 1 for j in drop})
    except Exception as exc:  # pragma: no cover
        raise SolverError(f"cddlib block elimination failed: {exc}") from exc
    arr = np.array(out.array, dtype=float).reshape(-1, len(kept) + 1)
    lin = sorted(out.lin_set)
    rows = np.vstack([arr, -arr[lin]]) if lin else arr
    # rows 0 <= b_i: vacuous (b_i >= 0) or infeasible (b_i < 0); cddlib's redundancy
    # removal must not see them
    zero = ~np.any(rows[:, 1:] != 0.0, axis=1)
    if np.any(rows[zero, 0] < 0.0):
        return np.zeros((1, len(keep))), np.array([-1.0])
    rows = np.unique(rows[~zero], axis=0)
    if rows.shape[0] > 1:
        red = cdd.matrix_from_array(rows, rep_type=cdd.RepType.INEQUALITY)
        try:
            cdd.matrix_canonicalize(red)
        except Exception as exc:  # pragma: no cover
            raise SolverError(f"cddlib redundancy removal failed: {exc}") from exc
        arr = np.array(red.array, dtype=float).reshape(-1, len(kept) + 1)
        lin = sorted(red.lin_set)
        rows = np.vstack([arr, -arr[lin]]) if lin else arr
    b_out = rows[:, 0]
    A_out = -rows[:, 1:][:, [kept.index(j) for j in keep]]
    return A_out, b_out
