"""Vertex enumeration and projection of polytopes.

:func:`vertices` enumerates the vertices of a bounded polytope (cddlib in the scaled
coordinates of ``P._rows()``, else Qhull or support LPs) and checks them against the rows;
:func:`project` projects on a subset of the coordinates by support LPs
(:func:`project_support`), by vertex enumeration or by block elimination. Floating-point
results: equal to the exact sets up to the tolerances documented in
:mod:`casadi_cmpc.sets.polytope`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import EmptySetError, SolverError
from . import _hull
from ._boxkernel import _U

if TYPE_CHECKING:
    from .polytope import Polytope

__all__: list[str] = []


def vertices(P: Polytope) -> np.ndarray:
    """The vertices of a bounded P, shape (k, n) (:meth:`Polytope.vertices`; cached on P,
    a copy is returned)."""
    V = P._cache.get("vertices")
    if V is not None:
        return V.copy()
    P._require_bounded_nonempty("the vertex list")
    R = P._rows()
    if (R.bn == -np.inf).any() or (
            not np.isfinite(R.bn).all()
            and not np.isfinite(P.bounding_box().as_array()).all()):
        raise SolverError("the polytope reaches beyond the floating-point range (a row "
                          "with b / |a| above 1.8e308): its vertices cannot be "
                          "represented; rescale the data")
    V = None
    if _hull._cdd() is not None:
        # rows rounded to nearest, then outward (a thin set far from the origin may
        # lose its thickness to rounding), then the LP route
        fin = R.bz < np.inf  # (rows beyond the double range constrain nothing)
        for bz in (R.bz0, R.bz):
            try:
                V = R.c0 + R.s * _hull.cdd_vertices(R.An[fin], bz[fin])
                break
            except (EmptySetError, SolverError):
                continue
    if V is None:
        V = vertices_fallback(P)
    V = _dedupe(V, R.tol)
    res = V @ R.An.T - R.bn
    rnd = 16 * _U * (np.abs(V) @ np.abs(R.An).T + np.abs(R.bn))
    viol = (res - rnd).max(initial=-np.inf)
    if viol > 100 * R.tol:
        raise SolverError(
            f"vertex enumeration is inaccurate (a vertex violates a row by {viol:.3g}); "
            "rescale the polytope data")
    V.setflags(write=False)
    P._cache["vertices"] = V
    return V.copy()


def vertices_fallback(P: Polytope) -> np.ndarray:
    """Vertices without pycddlib: Qhull's half-space intersection around the
    Chebyshev centre (full-dimensional P), else the support-LP hull of
    :func:`project_support` in the affine hull of P; shape (k, n)."""
    R = P._rows()
    c, r = P._chebyshev()
    if np.isfinite(r) and r > 1e-7 * R.s and P.dim > 1:
        fin = R.bn < np.inf  # (rows beyond the double range constrain nothing)
        return _hull.halfspace_vertices(R.An[fin], R.bn[fin], c)
    Q = project_support(P, list(range(P.dim)))
    return np.array(Q._cache["vertices"])


def project(P: Polytope, dims: Sequence[int], method: str = "auto") -> Polytope:
    """The projection of P on the coordinates ``dims`` (:meth:`Polytope.project`), a
    polytope of dimension ``len(dims)``."""
    from .polytope import Polytope

    n = P.dim
    try:
        dl = [int(d) for d in dims]
    except TypeError as exc:
        raise ValueError(f"dims must be a sequence of ints; got {dims!r}") from exc
    if not dl or len(set(dl)) != len(dl) or min(dl) < 0 or max(dl) >= n:
        raise ValueError(
            f"dims must be distinct coordinates in 0..{n - 1}; got {list(dims)}")
    meth = str(method).lower()
    valid = ("auto", "support", "vertices", "elimination")
    if meth not in valid:
        raise ValueError(f"Unknown projection method '{method}'; valid: {', '.join(valid)}")
    d = len(dl)
    if P.is_empty():
        return Polytope.empty(d)
    if dl == list(range(n)):
        return Polytope(P.A, P.b)
    if meth == "auto":
        if not P.is_bounded():
            meth = "elimination"
        else:
            meth = "support" if d <= 4 else "vertices"
    if meth == "elimination":
        R = P._rows()
        if _hull._cdd() is not None:
            A_p, b_p = _hull.cdd_eliminate(R.An, R.bn, dl)
        else:
            A_p, b_p = _hull.fm_eliminate(R.An, R.bn, dl, _prune_rows)
        return Polytope(A_p, b_p)
    P._require_bounded_nonempty(f"the projection by method '{meth}'")
    if meth == "vertices":
        return Polytope.from_vertices(P.vertices()[:, dl])
    return project_support(P, dl)


def project_support(P: Polytope, dims: list[int], max_rounds: int = 100_000) -> Polytope:
    """Projection of a bounded non-empty P on ``dims`` by support LPs (the method
    ``"support"`` of :meth:`Polytope.project`); SolverError after ``max_rounds`` rounds of
    new points. The vertices of the result are cached on it."""
    from .polytope import Polytope

    n, d = P.dim, len(dims)
    R = P._rows()
    # LP accuracy (scaled coordinates) plus the rounding of coordinates of size |c0|
    tol = R.tol + 64 * _U * float(np.abs(R.c0).max(initial=0.0))

    def lp_max(Dy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Support values (K,) of P in the directions Dy (K, d) of the projection and
        the projected maximisers (K, d)."""
        D = np.zeros((Dy.shape[0], n))
        D[:, dims] = Dy
        vals, X = P._max_lp(D)
        if not np.isfinite(vals).all():
            raise SolverError("a projection LP did not reach a finite optimum")
        return vals, X[:, dims]

    rng = np.random.default_rng(0)
    dirs = np.vstack([np.eye(d), -np.eye(d), rng.standard_normal((2 * d, d))])
    _, Y = lp_max(dirs)
    # affine hull of the projection
    for _ in range(d + 1):
        origin, U, Nc = _hull.affine_hull(Y)
        if Nc.shape[1] == 0:
            break
        vmax, Ymax = lp_max(Nc.T)
        vmin, Ymin = lp_max(-Nc.T)
        if np.all(vmax + vmin <= tol):
            break
        Y = np.vstack([Y, Ymax, Ymin])
    else:  # pragma: no cover
        raise SolverError("could not determine the affine hull of the projection")
    r = U.shape[1]
    rows_y: list[np.ndarray] = []
    rhs_y: list[np.ndarray] = []
    if Nc.shape[1]:
        rows_y += [Nc.T, -Nc.T]
        rhs_y += [np.maximum(vmax, (Y @ Nc).max(axis=0)),
                  np.maximum(vmin, (-Y @ Nc).max(axis=0))]
    if r == 0:
        out = Polytope(np.vstack(rows_y), np.concatenate(rhs_y))
        out._cache.update(vertices=Y[:1].copy(), empty=False, bounded=True)
        return out
    if r == 1:
        u = U[:, 0]
        vals, Ye = lp_max(np.vstack([u, -u]))
        rows_y += [u[None], -u[None]]
        rhs_y += [np.array([max(vals[0], (Y @ u).max())]),
                  np.array([max(vals[1], (-Y @ u).max())])]
        verts = Ye
    else:
        confirmed: dict[tuple, float] = {}
        for _ in range(max_rounds):
            Z = (Y - origin) @ U
            normals, vidx = _hull._qhull(Z)
            offs = (Z @ normals.T).max(axis=0)
            keys = [tuple(np.round(a, 9)) for a in normals]
            todo = [i for i, k in enumerate(keys) if k not in confirmed]
            if not todo:
                break
            Dy = normals[todo] @ U.T
            vals, Ynew = lp_max(Dy)
            vals_z = vals - Dy @ origin
            new = vals_z > offs[todo] + tol
            for j, i in enumerate(todo):
                if not new[j]:
                    confirmed[keys[i]] = max(float(vals_z[j]), float(offs[i]))
            if not new.any():
                break
            Y = np.vstack([Y, Ynew[new]])
        else:
            raise SolverError("projection by support LPs did not converge")
        final = np.array([max(confirmed.get(k, o), o) for k, o in zip(keys, offs,
                                                                       strict=True)])
        Ay = normals @ U.T
        rows_y.append(Ay)
        rhs_y.append(final + Ay @ origin)
        verts = Y[np.sort(vidx)]
    out = Polytope(np.vstack(rows_y), np.concatenate(rhs_y))
    out._cache.update(vertices=_dedupe(verts, tol), empty=False, bounded=True)
    return out


def _prune_rows(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Redundant rows of ``{A x <= b}`` (A (m, n), b (m,)) removed (:meth:`Polytope.minimal`);
    an empty set as the one row ``0.x <= -1``."""
    from .polytope import Polytope

    P = Polytope(A, b)
    if P.is_empty():
        return np.zeros((1, A.shape[1])), np.array([-1.0])
    M = P.minimal()
    return np.array(M.A), np.array(M.b)


def _dedupe(V: np.ndarray, tol: float) -> np.ndarray:
    """Drop points closer than ``tol`` (inf-norm) to an earlier point."""
    if V.shape[0] <= 1:
        return V.copy()
    key = np.round(V / max(tol, 1e-300))
    _, idx = np.unique(key, axis=0, return_index=True)
    return V[np.sort(idx)].copy()
