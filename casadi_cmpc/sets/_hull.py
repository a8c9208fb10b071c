"""Convex hulls of points (Qhull) and double-description conversions (pycddlib).

All conversions work in floating point: ``pycddlib-standalone`` ships the float
arithmetic of cddlib only (no GMP rationals).  Every H-representation built here has its
right-hand sides recomputed from the input points (``b_k = max_i a_k.p_i``), so the hull
contains every input point up to the rounding of that evaluation, whatever the rounding
inside Qhull or cddlib.
"""

from __future__ import annotations

import numpy as np

from ..exceptions import EmptySetError, SolverError, UnboundedSetError

__all__: list[str] = []

#: Relative tolerance for the numerical rank of a point cloud (affine hull detection).
RANK_RTOL = 1e-10


def affine_hull(points: np.ndarray, rtol: float = RANK_RTOL
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Affine hull of points.

    Parameters
    ----------
    points : ndarray, shape (N, n)

    Returns
    -------
    origin : ndarray, shape (n,)
        The mean of the points.
    U : ndarray, shape (n, r)
        Orthonormal basis of the directions of the hull (``r`` its dimension).
    N : ndarray, shape (n, n - r)
        Orthonormal basis of the orthogonal complement.
    """
    P = np.asarray(points, dtype=float)
    n = P.shape[1]
    origin = P.mean(axis=0)
    D = P - origin
    scale = max(float(np.abs(P).max(initial=0.0)), 1e-300)
    if P.shape[0] <= 1 or float(np.abs(D).max(initial=0.0)) <= rtol * scale:
        return origin, np.zeros((n, 0)), np.eye(n)
    _, s, Vt = np.linalg.svd(D, full_matrices=True)
    r = int(np.sum(s > rtol * max(scale * np.sqrt(P.shape[0]), s[0])))
    return origin, Vt[:r].T.copy(), Vt[r:].T.copy()


def _merge_rows(A: np.ndarray, decimals: int = 9) -> np.ndarray:
    """Drop duplicate unit normals (Qhull triangulates non-simplicial facets)."""
    if A.shape[0] <= 1:
        return A
    _, idx = np.unique(np.round(A, decimals), axis=0, return_index=True)
    return A[np.sort(idx)]


def _qhull(Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Facet normals (unit, outward) and hull vertex indices of full-dimensional points Z."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        h = ConvexHull(Z)
    except QhullError:
        try:
            h = ConvexHull(Z, qhull_options="QJ")
        except QhullError as exc:  # pragma: no cover - Qhull failing twice is exceptional
            raise SolverError(f"Qhull could not compute a convex hull: {exc}") from exc
    normals = h.equations[:, :-1]
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    return _merge_rows(normals), np.asarray(h.vertices, dtype=np.int64)


def hull_hrep(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H-representation of the convex hull of points.

    Parameters
    ----------
    points : ndarray, shape (N, n), N >= 1, finite

    Returns
    -------
    A : ndarray, shape (k, n)
        Unit facet normals; for a hull of dimension ``r < n`` also the pairs ``±v`` of
        the normals ``v`` of its affine hull.
    b : ndarray, shape (k,)
        ``b_k = max_i A_k . points_i``.
    vertices : ndarray, shape (v, n)
        The extreme points among ``points``.
    """
    P = np.unique(np.asarray(points, dtype=float), axis=0)
    n = P.shape[1]
    origin, U, Nc = affine_hull(P)
    r = U.shape[1]
    if r == 0:
        A = np.vstack([np.eye(n), -np.eye(n)])
        return A, (P @ A.T).max(axis=0), P[:1].copy()
    Z = (P - origin) @ U
    if r == 1:
        z = Z[:, 0]
        A_sub = np.array([[1.0], [-1.0]])
        vidx = np.unique([int(np.argmax(z)), int(np.argmin(z))])
    else:
        A_sub, vidx = _qhull(Z)
    A = A_sub @ U.T
    if Nc.shape[1]:
        A = np.vstack([A, Nc.T, -Nc.T])
    A = A / np.linalg.norm(A, axis=1, keepdims=True)
    b = (P @ A.T).max(axis=0)
    return A, b, P[np.sort(vidx)]


def _cdd_matrix(A: np.ndarray, b: np.ndarray):
    import cdd

    arr = np.hstack([b[:, None], -A])
    return cdd.matrix_from_array(arr, rep_type=cdd.RepType.INEQUALITY)


def cdd_vertices(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Vertices of the bounded polytope ``{A x <= b}`` by the double-description method.

    Raises
    ------
    EmptySetError
        cddlib finds no generator.
    UnboundedSetError
        cddlib finds a ray or a line.
    """
    import cdd

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
    import cdd

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
