"""Polytopes in H-representation ``{x : A x <= b}`` and finite unions of them.

Numerics
--------
* **Closed-form box tests are rounding-safe.** ``contains_box`` and the first stage of
  ``intersects_box`` bound ``max/min_{x in box} a.x`` in closed form with an a-priori
  bound on the floating-point error (:mod:`casadi_cmpc.sets._boxkernel`): a ``True`` of
  ``Polytope.contains_box`` and a ``False`` of ``intersects_box`` are proofs.
* **LP decisions use a tolerance.** Emptiness, boundedness, redundancy, projection,
  subset tests and the exact "box inside a union" test solve LPs with HiGHS
  (``scipy.optimize.linprog(method="highs")``, feasibility tolerances ``1e-10``) on the
  rows scaled to unit Euclidean norm, and decide with the tolerance
  ``tol = 1e-9 * s`` (a distance in the units of ``x``). The LPs run in coordinates
  ``z = (x - c0) / s`` shifted to a reference point of the polytope and scaled to its
  extent; the offsets ``b - A c0`` are computed in doubled precision and rounded outward,
  so a thin set far from the origin stays feasible. An LP that HiGHS cannot solve is
  retried on rows relaxed by the tolerance; where it still fails, the box tests return
  the safe answer and :meth:`Polytope.bounding_box` an outward box (multipliers of
  relaxed LPs are admissible certificates: they are checked exactly).
* **V/H conversions run in floating point.** ``pycddlib-standalone`` provides cddlib's
  float arithmetic only (no GMP fractions); vertex enumeration uses cddlib (the
  vertices are checked against the inequalities afterwards), convex hulls use Qhull,
  and the right-hand sides of every hull are recomputed from the points and rounded
  upward (``b_k >= max_i a_k.v_i`` exactly), so a hull always contains its input points.
  The affine dimension of a point cloud is the numerical rank of the differences to one
  of its points (translation invariant), at most ``N - 1`` for ``N`` points; a cloud
  thinner than ``1e-12`` of its spread or than the rounding of its coordinates is flat
  and gets a slab as thick as the points (outward). When Qhull gives up on a nearly
  degenerate cloud, the cloud is described as one dimension flatter the same way.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Iterator, Sequence
from fractions import Fraction
from typing import Any, NamedTuple

import numpy as np

from .._validate import as_boxes, as_float_array, as_points
from ..exceptions import (
    DimensionError,
    EmptySetError,
    InvalidBoundsError,
    SolverError,
    UnboundedSetError,
)
from . import _hull, _lp
from ._boxkernel import BoxKernel, points_le
from ._exact import rat_nullspace
from .base import SetBase
from .box import Box

__all__ = ["Polytope", "PolytopeUnion", "hull"]

#: Relative LP decision tolerance (multiplied by the scale of the data).
RTOL = 1e-9
_U = 2.0 ** -53
_MAX_VERTEX_SUMS = 200_000


class _Rows(NamedTuple):
    """The rows of a polytope that constrain anything, raw and normalised.

    LPs run in the coordinates ``z = (x - c0) / s`` (``An z <= bz``): translating or
    scaling the polytope translates/scales ``c0`` and ``s`` and leaves the LP unchanged.
    """

    A: np.ndarray  # (k, n) raw finite rows with finite b and a != 0
    b: np.ndarray
    An: np.ndarray  # rows scaled to unit 2-norm
    bn: np.ndarray
    empty: bool  # trivially empty (a row 0.x <= b < 0 or b = -inf)
    tol: float  # heuristic tolerance RTOL * s (a distance in the units of x)
    c0: np.ndarray  # (n,) reference point
    s: float  # scale > 0
    bz: np.ndarray  # (bn - An c0) / s, rounded outward (for the LPs)
    bz0: np.ndarray  # (bn - An c0) / s, rounded to nearest (for vertex enumeration)


def _gamma(k: int) -> float:
    return k * _U / (1.0 - k * _U)


def _as_matrix(M: Any, n: int, name: str) -> np.ndarray:
    arr = as_float_array(M, name)
    if arr.ndim == 0:
        arr = float(arr) * np.eye(n)
    if arr.ndim != 2:
        raise DimensionError(f"{name} must be a 2-D array; got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise InvalidBoundsError(f"{name} contains NaN or an infinite entry")
    return arr


def _as_vector(t: Any, p: int, name: str) -> np.ndarray:
    if t is None:
        return np.zeros(p)
    arr = as_float_array(t, name).ravel()
    if arr.shape != (p,):
        raise DimensionError(f"{name} must have shape ({p},); got {np.shape(t)}")
    if not np.isfinite(arr).all():
        raise InvalidBoundsError(f"{name} contains NaN or an infinite entry")
    return arr


class Polytope(SetBase):
    """The polyhedron ``{x in R^n : A x <= b}``.

    Parameters
    ----------
    A : array_like, shape (k, n)
        Constraint normals, one row per half-space. ``k = 0`` (no row) gives ``R^n``.
    b : array_like, shape (k,)
        Right-hand sides. ``+inf`` makes a row vacuous; ``-inf`` makes the set empty.

    Raises
    ------
    DimensionError
        ``A`` is not 2-D, ``b`` is not 1-D, or their numbers of rows differ.
    InvalidBoundsError
        ``A`` or ``b`` contains NaN, or ``A`` contains an infinite entry.

    Notes
    -----
    Thesis §3.2 (polytope geometry): intersection, set difference (a union of polytopes
    built from the complement of the subtrahend row by row), convex hull of a union;
    §3.4 pre-sets by projection; §6.1.4 box tests against unions of polytopes.
    Unbounded polyhedra are allowed wherever the operation makes sense; operations that
    need a bounded non-empty set (vertices, volume, Chebyshev ball, plotting) raise
    :class:`~casadi_cmpc.exceptions.UnboundedSetError` or
    :class:`~casadi_cmpc.exceptions.EmptySetError`.

    Examples
    --------
    >>> import casadi_cmpc as cm
    >>> P = cm.Polytope([[1, 0], [-1, 0], [0, 1], [0, -1]], [1, 1, 1, 1])
    >>> P.dim
    2
    >>> P.contains([[0.5, 0.5], [2.0, 0.0]])
    array([ True, False])
    >>> P.contains_box([[[0, 1], [-1, 0.5]], [[0, 2], [0, 1]]])
    array([ True, False])
    >>> float(P.volume())
    4.0
    >>> Q = P.project([0])
    >>> Q.bounding_box()
    Box([-1], [1])
    """

    __array_ufunc__ = None  # numpy defers ``M @ P``, ``t + P`` to the Polytope

    def __init__(self, A: Any, b: Any) -> None:
        A_a = np.array(as_float_array(A, "Polytope A"))
        b_a = np.array(as_float_array(b, "Polytope b"))
        if A_a.ndim != 2:
            raise DimensionError(f"Polytope A must be a 2-D array (k, n); got shape {A_a.shape}")
        if b_a.ndim != 1:
            raise DimensionError(f"Polytope b must be a 1-D array (k,); got shape {b_a.shape}")
        if A_a.shape[0] != b_a.shape[0]:
            raise DimensionError(
                f"Polytope A has {A_a.shape[0]} rows but b has {b_a.shape[0]} entries")
        if A_a.shape[1] == 0:
            raise DimensionError("Polytope A must have at least one column (n >= 1)")
        if np.isnan(A_a).any() or np.isnan(b_a).any():
            raise InvalidBoundsError("Polytope A or b contains NaN")
        if not np.isfinite(A_a).all():
            raise InvalidBoundsError("Polytope A contains an infinite entry")
        A_a.setflags(write=False)
        b_a.setflags(write=False)
        self.A = A_a
        self.b = b_a
        self._cache: dict[str, Any] = {}

    # ------------------------------------------------------------ constructors
    @classmethod
    def from_vertices(cls, V: Any) -> Polytope:
        """Convex hull of points, in H-representation.

        Parameters
        ----------
        V : array_like, shape (N, n)
            At least one finite point. Points that are not extreme are dropped.

        Returns
        -------
        Polytope
            Unit-norm rows; a hull of affine dimension ``r < n`` also gets the pairs of
            rows ``±v`` of the normals of its affine hull. The extreme points are cached
            as :meth:`vertices`.

        Raises
        ------
        DimensionError
            ``V`` is not a non-empty 2-D array.
        InvalidBoundsError
            ``V`` contains NaN or an infinite entry.
        """
        P = np.asarray(V, dtype=float)
        if P.ndim == 1:
            P = P[None]
        if P.ndim != 2 or P.shape[0] == 0 or P.shape[1] == 0:
            raise DimensionError(
                f"points must be a non-empty array of shape (N, n); got {np.shape(V)}")
        if not np.isfinite(P).all():
            raise InvalidBoundsError("points contain NaN or an infinite entry")
        A, b, verts = _hull.hull_hrep(P)
        out = cls(A, b)
        out._cache.update(vertices=verts, empty=False, bounded=True)
        return out

    @classmethod
    def convex_hull(cls, points: Any) -> Polytope:
        """Convex hull of points (same as :meth:`from_vertices`).

        Parameters
        ----------
        points : array_like, shape (N, n)

        Returns
        -------
        Polytope
        """
        return cls.from_vertices(points)

    @classmethod
    def from_box(cls, box: Any) -> Polytope:
        """The box ``[lo, hi]`` as ``{x : x <= hi, -x <= -lo}`` (infinite bounds allowed).

        Parameters
        ----------
        box : Box or array_like, shape (n, 2)

        Returns
        -------
        Polytope
        """
        arr = as_boxes(box, None, "box")
        if arr.shape[0] != 1:
            raise DimensionError(f"box must be one box; got a batch of {arr.shape[0]}")
        lo, hi = arr[0, :, 0], arr[0, :, 1]
        n = lo.size
        return cls(np.vstack([np.eye(n), -np.eye(n)]), np.concatenate([hi, -lo]))

    @classmethod
    def empty(cls, n: int) -> Polytope:
        """The empty set of ``R^n`` (the single row ``0.x <= -1``).

        Parameters
        ----------
        n : int
            Dimension.

        Returns
        -------
        Polytope
        """
        out = cls(np.zeros((1, int(n))), [-1.0])
        out._cache.update(empty=True, bounded=True)
        return out

    @classmethod
    def _coerce(cls, other: Any, n: int, name: str = "other") -> Polytope:
        if isinstance(other, Polytope):
            P = other
        elif isinstance(other, Box):
            P = cls.from_box(other)
        elif hasattr(other, "to_polytope"):
            P = other.to_polytope()
        else:
            raise TypeError(f"{name} must be a Polytope or a Box; got {type(other).__name__}")
        if P.dim != n:
            raise DimensionError(f"{name} has the wrong dimension; expected {n} instead of {P.dim}")
        return P

    # --------------------------------------------------------------- basics
    @property
    def dim(self) -> int:
        """Dimension n of the ambient space."""
        return int(self.A.shape[1])

    @property
    def n_constraints(self) -> int:
        """Number k of half-spaces (rows of A)."""
        return int(self.A.shape[0])

    def _rows(self) -> _Rows:
        r = self._cache.get("rows")
        if r is not None:
            return r
        A, b = self.A, self.b
        norms = np.linalg.norm(A, axis=1)
        trivially_empty = bool(np.any(b == -np.inf) or np.any((norms == 0) & (b < 0)))
        keep = np.isfinite(b) & (norms > 0)
        A_k, b_k, nk = A[keep], b[keep], norms[keep]
        An = A_k / nk[:, None]
        bn = b_k / nk
        n = A.shape[1]
        if "vertices" in self._cache and len(self._cache["vertices"]):
            c0 = np.asarray(self._cache["vertices"], dtype=float).mean(axis=0)
        elif An.shape[0]:
            c0 = np.linalg.lstsq(An, bn, rcond=None)[0]
        else:
            c0 = np.zeros(n)
        if not np.isfinite(c0).all():
            c0 = np.zeros(n)
        with np.errstate(over="ignore", invalid="ignore"):
            dev = np.abs(bn - An @ c0)
            scale = float(dev.max(initial=0.0))
            if "vertices" in self._cache and len(self._cache["vertices"]):
                # the extent of the set, not only the offsets of its rows (a sliver
                # has rows through its centre)
                ext = np.abs(np.asarray(self._cache["vertices"], dtype=float) - c0)
                scale = max(scale, float(ext.max(initial=0.0)))
        if not np.isfinite(scale) or scale <= 0.0:
            scale = 1.0
        # b - A c0 in doubled precision (far from the origin its plain rounding error
        # exceeds the thickness of a thin set); bz is rounded outward: every point of the
        # stored rows' set satisfies the scaled rows up to the rounding of a.z
        with np.errstate(over="ignore", invalid="ignore"):
            res, res_err = _residual(A_k, b_k, c0)
            bz0 = res / nk / scale
            slack = (_gamma(n + 4) * (np.abs(bz0) + np.abs(An).sum(axis=1))
                     + res_err / nk / scale * (1 + 4 * _U))
            bz = bz0 + slack
            bz = np.where(np.isfinite(bz), bz, (bn - An @ c0) / scale)
            bz0 = np.where(np.isfinite(bz0), bz0, bz)
        r = _Rows(A_k, b_k, An, bn, trivially_empty, RTOL * scale, c0, scale, bz, bz0)
        self._cache["rows"] = r
        return r

    def _kernel(self) -> BoxKernel:
        k = self._cache.get("kernel")
        if k is None:
            R = self._rows()
            k = self._cache["kernel"] = BoxKernel(R.A, R.b)
        return k

    def contains(self, points: Any, tol: float = 0.0) -> np.ndarray | bool:
        """Membership of points: ``A p <= b + tol`` row by row.

        Parameters
        ----------
        points : array_like, shape (N, n) or (n,)
        tol : float, optional
            Absolute tolerance added to every right-hand side (a plain floating-point
            test, nothing claimed). With the default 0 the test is exact: ``A p <= b`` for
            the stored float ``A``, ``b`` and ``p`` taken as exact numbers (a floating-point
            test with an error bound decides the points away from the facets, exact
            rational arithmetic the others), so that a point one ulp outside a facet is
            outside.

        Returns
        -------
        bool or ndarray of bool, shape (N,)
            A single bool for one unbatched point.
        """
        p, batched = as_points(points, self.dim, name="points")
        if tol != 0.0:
            inside = points_le(p, self.A, self.b + float(tol))
        else:
            inside = exact_points_le(p, self.A, self.b)
        return inside if batched else bool(inside[0])

    # ------------------------------------------------------ LP-based queries
    def _chebyshev(self) -> tuple[np.ndarray, float]:
        """Chebyshev centre and signed radius (negative: empty; inf: unbounded radius)."""
        c = self._cache.get("cheb")
        if c is not None:
            return c
        R = self._rows()
        n = self.dim
        if R.empty:
            c = (np.full(n, np.nan), -np.inf)
        elif R.An.shape[0] == 0:
            c = (np.zeros(n), np.inf)
        else:
            cap = 1e6  # in the scaled coordinates z
            rows = np.hstack([R.An, np.ones((R.An.shape[0], 1))])
            cost = np.zeros(n + 1)
            cost[-1] = -1.0
            ub = np.full(n + 1, np.inf)
            ub[-1] = cap
            st, x, f, y = _lp.lp(cost, rows, R.bz, -np.inf, ub)
            if st == _lp.INFEASIBLE:  # HiGHS proved r <= cap infeasible: cannot happen
                st = _lp.NUMERICAL  # pragma: no cover
            if st != _lp.OPTIMAL:
                # numerical trouble: nothing is claimed (not proven empty)
                c = (R.c0.copy(), 0.0)
                self._cache["cheb"] = c
                self._cache["cheb_y"] = None
                return c
            r = float(x[-1])
            c = (R.c0 + R.s * x[:n], np.inf if r >= cap * (1 - 1e-9) else r * R.s)
            self._cache["cheb_y"] = y
        self._cache["cheb"] = c
        return c

    def is_empty(self) -> bool:
        """True only when the polytope is proven empty.

        A row ``0.x <= b < 0`` or ``b = -inf`` proves it at once. Otherwise the Chebyshev
        LP ``max r s.t. a_i.x + r ||a_i|| <= b_i`` (scaled coordinates) is solved; when its
        optimum is negative, its multipliers point at an infeasible subsystem, for which
        a Farkas certificate ``y >= 0, A^T y = 0, b.y < 0`` is computed and checked in
        exact rational arithmetic on the stored rows. ``False`` means "not proven empty"
        (a set that is empty only by rounding-level amounts may answer ``False``).

        Returns
        -------
        bool
        """
        e = self._cache.get("empty")
        if e is None:
            R = self._rows()
            if R.empty:
                e = True
            elif R.An.shape[0] == 0:
                e = False
            else:
                r = self._chebyshev()[1]
                y = self._cache.get("cheb_y")
                e = bool(r < 0.0 and y is not None
                         and _farkas_empty(R.A, R.b, np.asarray(y) / np.linalg.norm(
                             R.A, axis=1)))
            self._cache["empty"] = e
        return e

    def is_full_dimensional(self) -> bool:
        """True when the polytope has an interior point (Chebyshev radius ``> tol``).

        Returns
        -------
        bool
        """
        return bool(self._chebyshev()[1] > self._rows().tol)

    def chebyshev_ball(self) -> tuple[np.ndarray, float]:
        """Centre and radius of the largest Euclidean ball inside the polytope.

        Returns
        -------
        center : ndarray, shape (n,)
        radius : float
            ``>= 0``; 0 for a polytope without interior.

        Raises
        ------
        EmptySetError
            The polytope is empty.
        UnboundedSetError
            Balls of every radius fit (e.g. a half-space).
        """
        if self.is_empty():
            raise EmptySetError("the Chebyshev ball of an empty polytope does not exist")
        c, r = self._chebyshev()
        if not np.isfinite(r):
            raise UnboundedSetError(
                "the polyhedron contains balls of every radius; intersect it with a Box")
        return c.copy(), max(float(r), 0.0)

    def is_bounded(self) -> bool:
        """True when the polyhedron is bounded (the empty set is bounded).

        A non-empty ``{A x <= b}`` is bounded iff its recession cone ``{d : A d <= 0}`` is
        ``{0}``: ``A`` has rank n and ``max -1^T A d`` over ``{A d <= 0, |d|_inf <= 1}``
        is 0 (one LP).

        Returns
        -------
        bool
        """
        bnd = self._cache.get("bounded")
        if bnd is not None:
            return bnd
        R = self._rows()
        n = self.dim
        if self.is_empty():
            bnd = True
        elif R.An.shape[0] < n + 1 or np.linalg.matrix_rank(R.An) < n:
            bnd = False
        else:
            cost = R.An.sum(axis=0)  # minimise 1^T A d  <=>  maximise -1^T A d
            st, _, f, _ = _lp.lp(cost, R.An, np.zeros(R.An.shape[0]), -1.0, 1.0)
            _lp.check_status(st, "the boundedness test")
            bnd = bool(-f <= 1e-9 * R.An.shape[0])
        self._cache["bounded"] = bnd
        return bnd

    def _require_bounded_nonempty(self, what: str) -> None:
        if self.is_empty():
            raise EmptySetError(f"{what} of an empty polytope is not defined")
        if not self.is_bounded():
            raise UnboundedSetError(
                f"{what} needs a bounded polytope; this one is unbounded "
                "(intersect it with a Box first)")

    def _max_lp(self, D: np.ndarray, multipliers_only: bool = False
                ) -> tuple[np.ndarray, np.ndarray]:
        """``max d.x`` over the polytope for each row of D (K, n): values and maximisers.

        Solved in the scaled coordinates ``z`` of :class:`_Rows` (translation and scale
        invariant); the LP multipliers of the unit rows are kept in ``self._last_y``.
        An LP that HiGHS cannot solve is solved again on the rows relaxed by the decision
        tolerance (values up to ``tol`` too large). With ``multipliers_only`` (the
        multipliers serve as certificates that are checked exactly, so any ``y >= 0``
        is admissible) larger relaxations are tried too, and LPs that still fail get
        NaN values and multipliers instead of an error.
        """
        R = self._rows()
        K, n = D.shape
        m = R.An.shape[0]
        res = _lp.block_lp(-D, np.tile(R.An, (K, 1)), np.tile(R.bz0, K),
                           np.repeat(np.arange(K), m))
        status, fun = res.status.copy(), res.fun.copy()
        Xz = res.x.copy()
        Y = res.y.reshape(K, m).copy() if m else np.zeros((K, 0))
        bounded = self._cache.get("bounded") is True
        relax = (0.0, RTOL, 1e-6, 1e-3) if multipliers_only else (0.0, RTOL)
        for k, eps in enumerate(relax):
            # first retry: the rows rounded outward (a thin set that rounding made
            # infeasible); then relaxed by a tolerance
            bad = (status == _lp.NUMERICAL) | (bounded & (status == _lp.UNBOUNDED))
            if k == 0:
                bad |= status == _lp.INFEASIBLE
            redo = np.flatnonzero(bad)
            if redo.size == 0:
                break
            r2 = _lp.block_lp(-D[redo], np.tile(R.An, (redo.size, 1)),
                              np.tile(R.bz + eps, redo.size), np.repeat(np.arange(redo.size), m))
            ok = r2.status == _lp.OPTIMAL
            if k == 0:
                keep = r2.status == _lp.INFEASIBLE
                status[redo[keep]] = _lp.INFEASIBLE
                fun[redo[keep]] = np.inf
            status[redo[ok]] = _lp.OPTIMAL
            fun[redo[ok]] = r2.fun[ok]
            Xz[redo[ok]] = r2.x[ok]
            if m:
                Y[redo[ok]] = r2.y.reshape(redo.size, m)[ok]
        failed = (status == _lp.NUMERICAL) | (bounded & (status == _lp.UNBOUNDED))
        if not multipliers_only:
            _lp.check_status(np.where(failed, _lp.NUMERICAL, status), "a support function")
        vals = -fun * R.s + D @ R.c0
        vals[status == _lp.UNBOUNDED] = np.inf
        vals[status == _lp.INFEASIBLE] = -np.inf
        vals[failed] = np.nan
        X = R.c0 + R.s * Xz
        Y[failed] = np.nan
        self._last_y = Y
        return vals, X

    def _support_upper(self, D: np.ndarray) -> np.ndarray:
        """Rigorous upper bounds of ``h(d) = max_{x in P} d.x`` for a bounded non-empty P.

        From LP multipliers ``y >= 0`` of the raw rows: ``d.x = y^T A x + rho.x <=
        y.b + rho.x`` with ``rho = d - A^T y``; ``rho.x`` is bounded on the box
        ``|x - c0| <= W`` around the reference point, and W itself comes from the same
        bound in the axis directions (``W <= B + |R| W`` solved with ``||R|| < 1``).
        All sums are evaluated in exact rational arithmetic and rounded upward.

        Parameters
        ----------
        D : ndarray, shape (K, n)

        Returns
        -------
        ndarray, shape (K,)
            ``+inf`` where no bound could be established.
        """
        R = self._rows()
        K, n = D.shape
        E = np.vstack([np.eye(n), -np.eye(n)])
        self._max_lp(np.vstack([E, D]), multipliers_only=True)
        Y = np.asarray(self._last_y, dtype=float)
        norms = np.linalg.norm(R.A, axis=1)
        Y = np.where(np.isfinite(Y), np.maximum(Y, 0.0), 0.0) / norms
        A = [[Fraction(float(v)) for v in row] for row in R.A]
        b = [Fraction(float(v)) for v in R.b]
        c0 = [Fraction(float(v)) for v in R.c0]
        DD = np.vstack([E, D])
        beta: list[Fraction] = []
        rho: list[list[Fraction]] = []
        for k in range(DD.shape[0]):
            y = [Fraction(float(v)) for v in Y[k]]
            idx = [i for i, v in enumerate(y) if v != 0]
            g = [sum((y[i] * A[i][j] for i in idx), Fraction(0)) for j in range(n)]
            r_k = [Fraction(float(DD[k, j])) - g[j] for j in range(n)]
            beta.append(sum((y[i] * b[i] for i in idx), Fraction(0))
                        + sum((r_k[j] * c0[j] for j in range(n)), Fraction(0)))
            rho.append([abs(v) for v in r_k])
        # W_j >= max |x_j - c0_j|:  W <= B + Rm W
        B = [max(beta[j] - c0[j], beta[n + j] + c0[j]) for j in range(n)]
        q = max(sum(max(rho[j][i], rho[n + j][i]) for i in range(n)) for j in range(n))
        out = np.full(K, np.inf)
        if q >= Fraction(1, 2):
            return out
        Bmax = max(max(B), Fraction(0))
        W = [max(Bj, Fraction(0)) + q * Bmax / (1 - q) for Bj in B]
        for k in range(K):
            kk = 2 * n + k
            val = beta[kk] + sum((rho[kk][j] * W[j] for j in range(n)), Fraction(0))
            out[k] = _frac_up(val)
        return out

    def support(self, directions: Any) -> np.ndarray | float:
        """Support function ``h(d) = max_{x in P} d.x``.

        Parameters
        ----------
        directions : array_like, shape (k, n) or (n,)

        Returns
        -------
        float or ndarray, shape (k,)
            ``-inf`` for an empty polytope, ``+inf`` in directions of unboundedness.
            Values come from the cached vertices when available, else from LPs.
        """
        D = np.asarray(directions, dtype=float)
        single = D.ndim == 1
        D = np.atleast_2d(D)
        if D.ndim != 2 or D.shape[1] != self.dim:
            raise DimensionError(
                f"directions must have shape (k, {self.dim}) or ({self.dim},); "
                f"got {np.shape(directions)}")
        if self.is_empty():
            val = np.full(D.shape[0], -np.inf)
        elif "vertices" in self._cache:
            val = (self._cache["vertices"] @ D.T).max(axis=0)
        elif self._rows().An.shape[0] == 0:
            val = np.where(np.any(D != 0, axis=1), np.inf, 0.0)
        else:
            val = self._max_lp(D)[0]
        return float(val[0]) if single else val

    def bounding_box(self) -> Box:
        """Smallest box containing the polytope (infinite bounds where unbounded).

        For a bounded polytope the bounds are rigorous: LP multipliers turned into upper
        bounds of the support function evaluated in exact rational arithmetic
        (:meth:`_support_upper`). Unbounded directions give infinite bounds.

        Returns
        -------
        Box

        Raises
        ------
        EmptySetError
            The polytope is empty.
        """
        if self.is_empty():
            raise EmptySetError("an empty polytope has no bounding box")
        n = self.dim
        E = np.vstack([np.eye(n), -np.eye(n)])
        try:
            bounded = self.is_bounded()
        except SolverError:
            bounded = None  # undecided: the LP values below tell
        if bounded is not False and self._rows().An.shape[0]:
            h = self._support_upper(E)
            if not np.isfinite(h).all() and "vertices" in self._cache:
                # from_vertices: the rows describe the hull of the points up to rounding
                hv = np.asarray(self.support(E))
                with np.errstate(invalid="ignore"):
                    hv = hv + (1e-12 * np.abs(hv) + 4 * np.abs(np.spacing(hv)))
                h = np.where(np.isfinite(h), h, hv)
            if not np.isfinite(h).all():
                h = np.where(np.isfinite(h), h, self._support_lp_outward(E))
        else:
            h = self._support_lp_outward(E)
        hi, lo = h[:n], -h[n:]
        hi = np.where(np.isnan(hi), np.inf, hi)
        lo = np.where(np.isnan(lo), -np.inf, lo)
        return Box(np.minimum(lo, hi), hi)

    def _support_lp_outward(self, E: np.ndarray) -> np.ndarray:
        """LP values of the support function in the directions E, widened outward by
        ``1e-12`` relative (``+inf`` where unbounded or where no LP could be solved)."""
        vals, _ = self._max_lp(E, multipliers_only=True)
        h = np.where(np.isnan(vals), np.inf, vals)
        with np.errstate(invalid="ignore"):
            h = h + (1e-12 * np.abs(h) + 4 * np.abs(np.spacing(h)))
        return np.where(np.isnan(h), np.inf, h)

    def vertices(self) -> np.ndarray:
        """Vertices of the bounded polytope.

        With pycddlib: cddlib's double description (float) in the scaled coordinates;
        without: Qhull's half-space intersection, or LPs for a polytope without interior.
        Floating-point results: each vertex satisfies ``A v <= b`` up to ``100 tol``
        (``tol = 1e-9`` times the scale of the polytope) and vertices closer than ``tol``
        are merged; polytopes built by :meth:`from_vertices` return their input extreme
        points exactly.

        Returns
        -------
        ndarray, shape (k, n)
            The extreme points.

        Raises
        ------
        EmptySetError
            The polytope is empty.
        UnboundedSetError
            The polytope is unbounded (it has no finite vertex description).
        """
        V = self._cache.get("vertices")
        if V is not None:
            return V.copy()
        self._require_bounded_nonempty("the vertex list")
        R = self._rows()
        V = None
        if _hull._cdd() is not None:
            # rows rounded to nearest, then outward (a thin set far from the origin may
            # lose its thickness to rounding), then the LP route
            for bz in (R.bz0, R.bz):
                try:
                    V = R.c0 + R.s * _hull.cdd_vertices(R.An, bz)
                    break
                except (EmptySetError, SolverError):
                    continue
        if V is None:
            V = self._vertices_fallback()
        V = _dedupe(V, R.tol)
        res = V @ R.An.T - R.bn
        rnd = 16 * _U * (np.abs(V) @ np.abs(R.An).T + np.abs(R.bn))
        viol = (res - rnd).max(initial=-np.inf)
        if viol > 100 * R.tol:
            raise SolverError(
                f"vertex enumeration is inaccurate (a vertex violates a row by {viol:.3g}); "
                "rescale the polytope data")
        V.setflags(write=False)
        self._cache["vertices"] = V
        return V.copy()

    def _vertices_fallback(self) -> np.ndarray:
        """Vertices without pycddlib: Qhull's half-space intersection around the
        Chebyshev centre (full-dimensional P), else the support-LP hull of
        :meth:`_project_support` in the affine hull of P."""
        R = self._rows()
        c, r = self._chebyshev()
        if np.isfinite(r) and r > 1e-7 * R.s and self.dim > 1:
            return _hull.halfspace_vertices(R.An, R.bn, c)
        Q = self._project_support(list(range(self.dim)))
        return np.array(Q._cache["vertices"])

    def volume(self) -> float:
        """Lebesgue measure (Qhull triangulation of the vertices; 0 without interior).

        Returns
        -------
        float

        Raises
        ------
        EmptySetError, UnboundedSetError
            The polytope is empty or unbounded.
        """
        self._require_bounded_nonempty("the volume")
        if not self.is_full_dimensional():
            return 0.0
        V = self.vertices()
        if self.dim == 1:
            return float(V.max() - V.min())
        from scipy.spatial import ConvexHull

        return float(ConvexHull(V).volume)

    # ------------------------------------------------------------ box tests
    def contains_box(self, boxes: Any) -> np.ndarray:
        """Inclusion of boxes in the polytope, in closed form.

        ``box ⊆ P`` iff ``max_{x in box} a_i.x <= b_i`` for every row, and the maximum is
        ``a_i^+ . hi - a_i^- . lo``. The test adds an a-priori bound on the rounding error
        of that evaluation, so ``True`` is a proof; the few rows that the bound cannot
        decide (a box touching a facet) are decided exactly with error-free products and a
        correctly rounded sum, so the answer is exact for finite boxes.

        Parameters
        ----------
        boxes : array_like, shape (N, n, 2) or (n, 2), or Box

        Returns
        -------
        ndarray of bool, shape (N,)
        """
        b = as_boxes(boxes, self.dim, "boxes")
        R = self._rows()
        if R.empty:
            return np.zeros(b.shape[0], dtype=bool)
        if R.A.shape[0] == 0:
            return np.ones(b.shape[0], dtype=bool)
        return self._kernel().all_le(b)

    def intersects_box(self, boxes: Any) -> np.ndarray:
        """Whether boxes meet the polytope; ``False`` only when ``box ∩ P = ∅`` is proven.

        Stages (each on the boxes still undecided):

        1. a row separates the box: ``min_{x in box} a_i.x > b_i`` with the rigorous
           rounding bound -> ``False``;
        2. for a bounded full-dimensional P with ``n <= 3`` (together with stage 1, in one
           closed-form pass): the complete set of separating directions, i.e. the facet
           normals of the projections of P on every proper subset of coordinates (facets
           of ``P ⊕ box`` have such normals), with rigorous offsets -> ``False``,
           otherwise ``True``; on the line stage 1 alone is complete;
        3. otherwise, a point of the box (its centre, the point of the box nearest to the
           Chebyshev centre) lies in P -> ``True``;
        4. the rest: one LP per box (stacked into block LPs): ``max r`` s.t.
           ``a_i.x + r <= b_i`` (unit rows, scaled coordinates), ``x`` in the box.
           ``r >= 0`` -> ``True``; else the LP multipliers ``y >= 0`` give the implied inequality
           ``y^T A x <= y^T b``, which is checked to separate the box with a rigorous
           rounding bound -> ``False`` (``True`` if the check fails).

        Parameters
        ----------
        boxes : array_like, shape (N, n, 2) or (n, 2), or Box

        Returns
        -------
        ndarray of bool, shape (N,)
        """
        bx = as_boxes(boxes, self.dim, "boxes")
        N = bx.shape[0]
        R = self._rows()
        if R.empty:
            return np.zeros(N, dtype=bool)
        out = np.ones(N, dtype=bool)
        if R.A.shape[0] == 0 or N == 0:
            return out
        if self.dim in (2, 3):
            sat = self._sat()
            if sat is not None:  # stages 1 and 2 in one closed-form pass
                return ~sat.separates(bx)
        sep = self._kernel().separates(bx)
        out[sep] = False
        und = np.flatnonzero(~sep)
        if und.size == 0 or self.dim == 1:  # stage 1 is complete on the line
            return out
        if self.is_empty():
            out[und] = False
            return out
        sub = bx[und]
        lo, hi = sub[..., 0], sub[..., 1]
        with np.errstate(invalid="ignore"):
            mid = 0.5 * (lo + hi)
        mid = np.where(np.isfinite(mid), mid, np.clip(0.0, lo, hi))
        near = np.clip(self._chebyshev()[0], lo, hi)
        hit = points_le(mid, R.A, R.b) | points_le(near, R.A, R.b)
        und = und[~hit]
        if und.size:
            out[und] = ~self._lp_separated(bx[und])
        return out

    def _sat(self) -> BoxKernel | None:
        """Rows of P and separating directions of its projections (n = 2, 3), or None.

        For a bounded full-dimensional P the facet normals of ``P ⊕ box`` are facet
        normals of P or (lifted) facet normals of the projections of P on proper subsets
        of the coordinates, whatever the box; so a box misses P iff one of these rows
        separates it. The offsets of the lifted rows are rigorous upper bounds of the
        support function (:meth:`_support_upper`), so a separation is a proof.
        """
        if "sat" in self._cache:
            return self._cache["sat"]
        n = self.dim
        sat = None
        try:
            if n in (2, 3) and not self.is_empty() and self.is_bounded() \
                    and self.is_full_dimensional():
                R = self._rows()
                rows, rhs = [R.A], [R.b]
                for k in range(1, n):
                    for T in itertools.combinations(range(n), k):
                        # a bounded effort: an ill-conditioned P whose projection does
                        # not settle falls back to the general stages (conservative)
                        Q = self._project_support(list(T), max_rounds=60)
                        QR = Q._rows()
                        lifted = np.zeros((QR.A.shape[0], n))
                        lifted[:, list(T)] = QR.A
                        h = self._support_upper(lifted)
                        ok = np.isfinite(h)
                        if not ok.all():
                            # a missing direction would make "not separated" no proof of
                            # intersection: use the general stages instead
                            raise SolverError("no rigorous offset for a projection facet")
                        rows.append(lifted)
                        rhs.append(h)
                sat = BoxKernel(np.vstack(rows), np.concatenate(rhs))
        except SolverError:
            sat = None  # the general stages of intersects_box decide (conservatively)
        self._cache["sat"] = sat
        return sat

    def _lp_separated(self, bx: np.ndarray) -> np.ndarray:
        """Stage 4 of :meth:`intersects_box`: proven separation by LP multipliers."""
        R = self._rows()
        K, n = bx.shape[0], self.dim
        m = R.An.shape[0]
        rows = np.hstack([R.An, np.ones((m, 1))])
        C = np.zeros((K, n + 1))
        C[:, -1] = -1.0
        with np.errstate(invalid="ignore", over="ignore"):
            zlo = (bx[..., 0] - R.c0) / R.s
            zhi = (bx[..., 1] - R.c0) / R.s
        lb = np.hstack([zlo, np.full((K, 1), -np.inf)])
        ub = np.hstack([zhi, np.zeros((K, 1))])
        res = _lp.block_lp(C, np.tile(rows, (K, 1)), np.tile(R.bz, K),
                           np.repeat(np.arange(K), m), lb, ub)
        r = res.x[:, -1]
        cand = (res.status == _lp.OPTIMAL) & (r < 0.0)
        proven = np.zeros(K, dtype=bool)
        idx = np.flatnonzero(cand)
        if idx.size == 0:
            return proven
        norms = np.linalg.norm(R.A, axis=1)
        Y = res.y.reshape(K, m)[idx] / norms  # multipliers of the raw rows
        Y = np.where(np.isfinite(Y), np.maximum(Y, 0.0), 0.0)
        proven[idx] = _certify_separation(Y, R.A, R.b, bx[idx])
        return proven

    # --------------------------------------------------------- redundancy
    def minimal(self) -> Polytope:
        """The same set without redundant rows (LP test per row, tolerance ``tol``).

        Row ``i`` is redundant when ``max a_i.x`` over the other rows (with row ``i``
        relaxed by 1) is ``<= b_i + tol``, in the scaled coordinates of the polytope
        (``tol = 1e-9`` times its scale: translation and scale invariant). This errs
        outward: a row that is only nearly redundant may be removed, which can enlarge
        the set by up to ``tol`` -- the wrong direction for an inner set, so do not feed
        the result of ``minimal()`` to an inner (certified) test when that matters; keep
        the original rows there (the box tests are fast with redundant rows anyway).
        Rows that are redundant only together (e.g. duplicates) are removed one at a time,
        so one of each group is kept. Vacuous rows (``b = inf``, ``0.x <= b >= 0``) are
        dropped.

        Returns
        -------
        Polytope
            The kept rows, unscaled. An empty polytope gives :meth:`empty`.
        """
        if self._cache.get("minimal") is True:
            return self
        m_cached = self._cache.get("minimal_poly")
        if m_cached is not None:
            return m_cached
        n = self.dim
        if self.is_empty():
            return Polytope.empty(n)
        R = self._rows()
        A, b, An, bn, tol = R.A, R.b, R.An, R.bz0, RTOL
        m = An.shape[0]
        # exact duplicate normals: keep the smallest right-hand side
        order = np.lexsort((bn, *An.T[::-1]))
        keep = np.ones(m, dtype=bool)
        same = np.all(An[order][1:] == An[order][:-1], axis=1)
        keep[order[1:][same]] = False
        idx = np.flatnonzero(keep)
        vals = self._row_maxima(An, bn, idx, idx)
        essential = idx[vals > bn[idx] + tol]
        cand = idx[vals <= bn[idx] + tol]
        if cand.size:
            vals2 = self._row_maxima(An, bn, cand, essential)
            cand = cand[vals2 > bn[cand] + tol]
            alive = set(cand.tolist())
            for i in cand.tolist():
                others = np.array(sorted(set(essential.tolist()) | (alive - {i})), dtype=int)
                v = self._row_maxima(An, bn, np.array([i]), others)[0]
                if v <= bn[i] + tol:
                    alive.discard(i)
            essential = np.array(sorted(set(essential.tolist()) | alive), dtype=int)
        out = Polytope(A[essential], b[essential])
        for key in ("empty", "bounded", "cheb", "vertices"):
            if key in self._cache:
                out._cache[key] = self._cache[key]
        out._cache["minimal"] = True
        self._cache["minimal_poly"] = out
        return out

    def remove_redundant(self) -> Polytope:
        """Alias of :meth:`minimal`.

        Returns
        -------
        Polytope
        """
        return self.minimal()

    @staticmethod
    def _row_maxima(An: np.ndarray, bn: np.ndarray, test: np.ndarray,
                    against: np.ndarray) -> np.ndarray:
        """``max a_i.x`` s.t. rows ``against`` (row i itself relaxed by 1), i in ``test``."""
        K = test.size
        if K == 0:
            return np.zeros(0)
        blocks_A, blocks_b, blk = [], [], []
        for k, i in enumerate(test.tolist()):
            rows = against[against != i]
            blocks_A.append(An[rows])
            blocks_b.append(bn[rows])
            blocks_A.append(An[[i]])
            blocks_b.append(bn[[i]] + max(1.0, abs(bn[i])))
            blk.append(np.full(rows.size + 1, k))
        res = _lp.block_lp(-An[test], np.vstack(blocks_A), np.concatenate(blocks_b),
                           np.concatenate(blk))
        _lp.check_status(res.status, "the redundancy test")
        vals = -res.fun
        vals[res.status == _lp.UNBOUNDED] = np.inf
        return vals

    # ----------------------------------------------------- set operations
    def intersect(self, other: Any) -> Polytope:
        """Intersection ``P ∩ Q`` (rows stacked, redundant rows kept).

        Parameters
        ----------
        other : Polytope or Box

        Returns
        -------
        Polytope
        """
        Q = Polytope._coerce(other, self.dim)
        return Polytope(np.vstack([self.A, Q.A]), np.concatenate([self.b, Q.b]))

    def __and__(self, other: Any) -> Polytope:
        if isinstance(other, (Polytope, Box)) or hasattr(other, "to_polytope"):
            return self.intersect(other)
        return NotImplemented

    __rand__ = __and__

    def hull(self, *others: Any) -> Polytope:
        """Convex hull of this polytope and others (see :func:`hull`).

        Parameters
        ----------
        *others : Polytope, Box or PolytopeUnion

        Returns
        -------
        Polytope
        """
        return hull(self, *others)

    def translate(self, t: Any) -> Polytope:
        """The translate ``P + t = {x + t : x in P}``.

        Parameters
        ----------
        t : array_like, shape (n,)

        Returns
        -------
        Polytope
        """
        t = _as_vector(t, self.dim, "t")
        with np.errstate(invalid="ignore"):
            b = self.b + self.A @ t
        out = Polytope(self.A, np.where(np.isnan(b), self.b, b))
        if "vertices" in self._cache:
            out._cache["vertices"] = self._cache["vertices"] + t
        return out

    def affine_map(self, M: Any, t: Any = None) -> Polytope:
        """Image ``{M x + t : x in P}`` under an affine map.

        Invertible square ``M`` (condition number ``< 1e10``): the H-representation
        ``{y : A M^{-1} y <= b + A M^{-1} t}`` computed in floating point (equal to the
        image up to rounding; not a proven inner or outer set). Otherwise the image of the
        vertices (bounded P) or the projection of the lifted set
        ``{(x, y) : A x <= b, y = M x + t}``
        (unbounded P, by block elimination).

        Parameters
        ----------
        M : array_like, shape (p, n), or a scalar (``M = s I``)
        t : array_like, shape (p,), optional

        Returns
        -------
        Polytope
            A polytope of dimension p.
        """
        n = self.dim
        M = _as_matrix(M, n, "M")
        if M.shape[1] != n:
            raise DimensionError(f"M must have {n} columns; got shape {M.shape}")
        p = M.shape[0]
        t = _as_vector(t, p, "t")
        if self.is_empty():
            return Polytope.empty(p)
        R = self._rows()
        if p == n and np.linalg.cond(M) < 1e10:
            AMi = np.linalg.solve(M.T, R.A.T).T
            out = Polytope(AMi, R.b + AMi @ t)
            if "vertices" in self._cache:
                out._cache["vertices"] = self._cache["vertices"] @ M.T + t
            return out
        if self.is_bounded():
            return Polytope.from_vertices(self.vertices() @ M.T + t)
        lifted_A = np.vstack([np.hstack([R.A, np.zeros((R.A.shape[0], p))]),
                              np.hstack([-M, np.eye(p)]), np.hstack([M, -np.eye(p)])])
        lifted_b = np.concatenate([R.b, t, -t])
        return Polytope(lifted_A, lifted_b).project(list(range(n, n + p)),
                                                    method="elimination")

    def inverse_image(self, M: Any, t: Any = None) -> Polytope:
        """Pre-image ``{x : M x + t in P}`` in floating point (rows ``A M`` and offsets
        ``b - A t`` rounded to nearest: equal to the exact pre-image up to that rounding,
        not a proven inner or outer set; :func:`casadi_cmpc.pre_set` gives a proven one).

        Parameters
        ----------
        M : array_like, shape (n, p), or a scalar (``M = s I``)
        t : array_like, shape (n,), optional

        Returns
        -------
        Polytope
            ``{x in R^p : (A M) x <= b - A t}``.
        """
        n = self.dim
        M = _as_matrix(M, n, "M")
        if M.shape[0] != n:
            raise DimensionError(f"M must have {n} rows; got shape {M.shape}")
        t = _as_vector(t, n, "t")
        return Polytope(self.A @ M, self.b - self.A @ t)

    def minkowski_sum(self, other: Any) -> Polytope:
        """Minkowski sum ``P ⊕ Q = {x + y : x in P, y in Q}``.

        Bounded operands: convex hull of the pairwise sums of vertices (when there are at
        most 200 000 sums), otherwise projection of the lifted set
        ``{(x, z) : A_P x <= b_P, A_Q (z - x) <= b_Q}`` on z.

        Parameters
        ----------
        other : Polytope or Box

        Returns
        -------
        Polytope
        """
        n = self.dim
        Q = Polytope._coerce(other, n)
        if self.is_empty() or Q.is_empty():
            return Polytope.empty(n)
        if self.is_bounded() and Q.is_bounded():
            V1, V2 = self.vertices(), Q.vertices()
            if V1.shape[0] * V2.shape[0] <= _MAX_VERTEX_SUMS:
                return Polytope.from_vertices((V1[:, None, :] + V2[None]).reshape(-1, n))
        R1, R2 = self._rows(), Q._rows()
        lifted_A = np.vstack([np.hstack([R1.A, np.zeros((R1.A.shape[0], n))]),
                              np.hstack([-R2.A, R2.A])])
        lifted_b = np.concatenate([R1.b, R2.b])
        return Polytope(lifted_A, lifted_b).project(list(range(n, 2 * n)))

    def pontryagin_difference(self, other: Any) -> Polytope:
        """Pontryagin difference ``P ⊖ Q = {x : x + Q ⊆ P}``, never larger than the truth.

        ``{x : a_i.x <= b_i - h_i}`` with ``h_i >= h_Q(a_i)`` a rigorous upper bound of the
        support function of Q (exact LP-dual bounds for a Polytope, outward-rounded sums for
        a Box or a Zonotope) and the offsets rounded downward: an inner approximation of the
        exact difference, equal to it up to these roundings. For other sets the support
        value is widened by ``1e-12`` relative (not a proof).

        Parameters
        ----------
        other : set with ``dim`` and ``support`` (Polytope, Box, Zonotope, ...)

        Returns
        -------
        Polytope
            ``R^n`` (no finite row) when Q is empty.
        """
        n = self.dim
        if not hasattr(other, "support") or getattr(other, "dim", None) != n:
            raise TypeError(
                f"other must be a set of dimension {n} with a support function; "
                f"got {type(other).__name__}")
        R = self._rows()
        if R.empty:
            return Polytope.empty(n)
        h = _support_up(other, R.A) if R.A.shape[0] else np.zeros(0)
        with np.errstate(invalid="ignore"):
            b = np.nextafter(R.b - h, -np.inf)
        return Polytope(R.A, np.where(np.isnan(b), -np.inf, b))

    def __add__(self, other: Any) -> Polytope:
        if isinstance(other, (Polytope, Box)) or hasattr(other, "to_polytope"):
            return self.minkowski_sum(other)
        try:
            return self.translate(other)
        except (TypeError, ValueError):
            return NotImplemented

    __radd__ = __add__

    def __sub__(self, other: Any) -> Polytope:
        if isinstance(other, SetBase):
            return self.pontryagin_difference(other)
        try:
            return self.translate(-np.asarray(other, dtype=float))
        except (TypeError, ValueError):
            return NotImplemented

    def __neg__(self) -> Polytope:
        return self.affine_map(-np.eye(self.dim))

    def __rmatmul__(self, M: Any) -> Polytope:
        return self.affine_map(M)

    def __mul__(self, s: Any) -> Polytope:
        if np.ndim(s) != 0:
            return NotImplemented
        return self.affine_map(float(s) * np.eye(self.dim))

    __rmul__ = __mul__

    # -------------------------------------------------------- projection
    def project(self, dims: Sequence[int], method: str = "auto") -> Polytope:
        """Projection ``{x_dims : x in P}`` onto a subset of the coordinates, in floating
        point (LPs and vertex enumeration, equal to the projection up to the tolerances
        below; not a proven inner or outer set).

        Parameters
        ----------
        dims : sequence of int
            Distinct coordinates kept, in the order of the result.
        method : {"auto", "support", "vertices", "elimination"}
            ``"support"``: iterative hull by LPs (bounded P): LP maximisers in
            ``±e_i`` and a few fixed random directions give points of the projection;
            the facets of their convex hull are checked one by one by an LP in the facet
            normal; a facet whose LP value exceeds its offset yields a new point and the
            hull is rebuilt, until every facet is confirmed (LP value ``<= offset + tol``).
            A projection of lower dimension is found first (LPs in the normals of the
            affine hull of the points) and handled in its affine hull. About
            ``#facets + #vertices`` LPs of the projection, stacked per round.
            ``"vertices"``: vertex enumeration of P, then the hull of the projected
            vertices. ``"elimination"``: cddlib block elimination (Fourier–Motzkin by the
            double description of the dual cone) and redundancy removal; works for
            unbounded P. ``"auto"``: ``"elimination"`` for unbounded P, ``"support"``
            for ``len(dims) <= 4``, else ``"vertices"``.

        Returns
        -------
        Polytope
            Of dimension ``len(dims)``; vertices are cached for the bounded methods.

        Raises
        ------
        ValueError
            Bad ``dims`` or unknown ``method``.
        UnboundedSetError
            ``"support"`` or ``"vertices"`` on an unbounded polytope.
        """
        n = self.dim
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
        if self.is_empty():
            return Polytope.empty(d)
        if dl == list(range(n)):
            return Polytope(self.A, self.b)
        if meth == "auto":
            if not self.is_bounded():
                meth = "elimination"
            else:
                meth = "support" if d <= 4 else "vertices"
        if meth == "elimination":
            R = self._rows()
            if _hull._cdd() is not None:
                A_p, b_p = _hull.cdd_eliminate(R.An, R.bn, dl)
            else:
                A_p, b_p = _hull.fm_eliminate(R.An, R.bn, dl, _prune_rows)
            return Polytope(A_p, b_p)
        self._require_bounded_nonempty(f"the projection by method '{meth}'")
        if meth == "vertices":
            return Polytope.from_vertices(self.vertices()[:, dl])
        return self._project_support(dl)

    def _project_support(self, dims: list[int], max_rounds: int = 100_000) -> Polytope:
        """Projection by support LPs (see :meth:`project`); SolverError after
        ``max_rounds`` rounds of new points."""
        n, d = self.dim, len(dims)
        R = self._rows()
        # LP accuracy (scaled coordinates) plus the rounding of coordinates of size |c0|
        tol = R.tol + 64 * _U * float(np.abs(R.c0).max(initial=0.0))

        def lp_max(Dy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            D = np.zeros((Dy.shape[0], n))
            D[:, dims] = Dy
            vals, X = self._max_lp(D)
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

    # ------------------------------------------------------ comparisons
    def is_subset(self, other: Any, tol: float | None = None) -> bool:
        """Whether ``P ⊆ other``.

        For a polytope Q: ``max_{x in P} a_j.x <= b_j + tol`` for every (unit-scaled) row
        j of Q, by LPs. This comparison errs toward ``True`` by ``tol`` (a distance): it
        is used to compare sets computed in floating point (e.g. to detect that a sequence
        of pre-sets has converged), not as a certificate. With ``tol=0`` a ``True`` is
        still only as accurate as the LP solution. For a union (full-dimensional bounded
        P only, else ``False``): proven like :meth:`PolytopeUnion.contains_box`.

        Parameters
        ----------
        other : Polytope, Box or PolytopeUnion
        tol : float, optional
            Default: ``1e-9`` times the scale of ``other`` (the largest distance from
            its reference point to its facets: translation and scale invariant).

        Returns
        -------
        bool
        """
        n = self.dim
        if isinstance(other, PolytopeUnion):
            if other.dim != n:
                raise DimensionError(
                    f"other has the wrong dimension; expected {n} instead of {other.dim}")
            if self.is_empty():
                return True
            R = self._rows()
            if not self.is_bounded():
                return False
            if not self.is_full_dimensional():
                return self._flat_subset_of_union(other)
            box = self.bounding_box().as_array()[None]
            centre = self._chebyshev()[0][None]
            return _uncovered(other._members(), box, centre, [(R.A, R.b)])[0] is None
        Q = Polytope._coerce(other, n)
        if self.is_empty():
            return True
        QR = Q._rows()
        if Q.is_empty():
            return False
        tol_ = QR.tol if tol is None else float(tol)
        if QR.An.shape[0] == 0:
            return True
        h = np.asarray(self.support(QR.An))
        return bool(np.all(h <= QR.bn + tol_))

    def _flat_subset_of_union(self, U: PolytopeUnion) -> bool:
        """``P ⊆ U`` for a bounded P without interior, decided in the affine hull of P.

        The members are restricted to the affine hull ``{o + Q t}`` of the vertices of P
        (rows ``A Q``, ``b - A o``, rounded), where P has an interior, and the covering
        engine runs there: a proof up to the rounding of that restriction only.
        """
        V = self.vertices()
        o, Q, _ = _hull.affine_hull(V)
        r = Q.shape[1]
        if r == 0:
            return bool(U.contains(V[0]))
        T = (V - o) @ Q
        R = self._rows()
        members = []
        for M in U._members():
            MR = M._rows()
            Mt = Polytope(MR.A @ Q, MR.b - MR.A @ o)
            if not Mt.is_empty():
                members.append(Mt)
        box = np.stack([T.min(axis=0), T.max(axis=0)], axis=-1)[None]
        hard = [(R.A @ Q, R.b - R.A @ o)]
        return _uncovered(members, box, T.mean(axis=0)[None], hard)[0] is None

    def __eq__(self, other: object) -> bool:
        if isinstance(other, (Polytope, Box)):
            if other.dim != self.dim:
                return False
            O = Polytope._coerce(other, self.dim)
            return self.is_subset(O) and O.is_subset(self)
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def difference(self, other: Any) -> PolytopeUnion:
        """Set difference ``P \\ Q`` as a union of polytopes (closure).

        With ``J`` the rows of Q that cut P (``max_P a_j.x > b_j``), the pieces are
        ``P ∩ {a_j.x >= b_j} ∩ {a_l.x <= b_l, l in J before j}``. For a full-dimensional
        P, pieces without interior (Chebyshev radius ``<= tol``) are dropped, so the
        union is the closure of ``P \\ Q``; for a lower-dimensional P only empty pieces
        are dropped.

        Parameters
        ----------
        other : Polytope or Box

        Returns
        -------
        PolytopeUnion
            Possibly with no member (``P ⊆ Q``).
        """
        n = self.dim
        Q = Polytope._coerce(other, n)
        if self.is_empty():
            return PolytopeUnion([], dim=n)
        if Q.is_empty():
            return PolytopeUnion([Polytope(self.A, self.b)], dim=n)
        QR = Q._rows()
        tol = self._rows().tol
        h = np.asarray(self.support(QR.An)) if QR.An.shape[0] else np.zeros(0)
        J = np.flatnonzero(h > QR.bn + tol)
        full = self.is_full_dimensional()
        pieces = []
        for k, j in enumerate(J.tolist()):
            prev = J[:k]
            Pk = Polytope(np.vstack([self.A, -QR.A[[j]], QR.A[prev]]),
                          np.concatenate([self.b, -QR.b[[j]], QR.b[prev]]))
            r = Pk._chebyshev()[1]
            if (r > tol) if full else (r >= -tol):
                pieces.append(Pk)
        return PolytopeUnion(pieces, dim=n)

    # ---------------------------------------------------------- plotting
    def _plot_points(self, dims: tuple[int, int]) -> np.ndarray:
        if self.is_empty():
            return np.zeros((0, 2))
        if not self.is_bounded():
            raise UnboundedSetError(
                "cannot plot an unbounded polyhedron; intersect it with a Box first")
        if self.dim <= 2:
            return super()._plot_points(dims)
        return self.project(list(dims)).vertices()

    # ------------------------------------------------------- persistence
    def _state(self) -> dict[str, Any]:
        return {"A": np.array(self.A), "b": np.array(self.b)}

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> Polytope:
        return cls(state["A"], state["b"])

    def __repr__(self) -> str:
        return f"Polytope(dim={self.dim}, constraints={self.n_constraints})"


def _prune_rows(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Redundant rows removed (:meth:`Polytope.minimal`); an empty set as one row."""
    P = Polytope(A, b)
    if P.is_empty():
        return np.zeros((1, A.shape[1])), np.array([-1.0])
    M = P.minimal()
    return np.array(M.A), np.array(M.b)


def _residual(A: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``b - A c`` row by row in doubled precision (error-free products and sums), and a
    bound of its error (the rounding to double plus the second-order terms)."""
    from ._boxkernel import _two_prod

    m, n = A.shape
    if m == 0:
        return np.zeros(0), np.zeros(0)
    P, E, ok = _two_prod(A, np.broadcast_to(c, A.shape))
    terms = np.hstack([b[:, None], -P, -E])
    s = np.zeros(m)
    e = np.zeros(m)
    for j in range(terms.shape[1]):  # TwoSum accumulation (Ogita-Rump-Oishi Sum2)
        t = terms[:, j]
        x = s + t
        z = x - s
        e += (s - (x - z)) + (t - z)
        s = x
    res = s + e
    mag = np.abs(b) + np.abs(P).sum(axis=1) + np.abs(E).sum(axis=1)
    err = _U * np.abs(res) + 2 * _gamma(2 * n + 2) ** 2 * mag + 1e-300
    plain = ~ok.all(axis=1)
    if plain.any():  # products outside Dekker's range: the plain evaluation and its bound
        res[plain] = b[plain] - A[plain] @ c
        err[plain] = _gamma(n + 2) * (np.abs(b[plain]) + np.abs(A[plain]) @ np.abs(c)) + 1e-300
    return res, err


def _support_up(Q: Any, D: np.ndarray) -> np.ndarray:
    """Upper bounds of the support function of Q in the directions D (k, n)."""
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


def exact_points_le(X: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``all(A x <= b)`` decided exactly for each row x of X (N, n) -> (N,) bool.

    The floating-point residuals ``A x - b`` with the bound ``gamma_{n+2} (|A| |x| + |b|)``
    of their rounding error decide every row they can; a point with a row inside that
    bound is decided in exact rational arithmetic (the float data taken as exact). Rows
    with ``b = +inf`` hold everywhere, ``b = -inf`` nowhere; a non-finite point is decided
    in plain floating point.
    """
    N, n = X.shape
    if A.shape[0] == 0 or N == 0:
        return np.ones(N, dtype=bool)
    with np.errstate(over="ignore", invalid="ignore"):
        S = X @ A.T - b[None, :]
        mag = np.abs(X) @ np.abs(A).T + np.abs(b)[None, :]
        err = _gamma(n + 2) * mag + 1e-300
    sure_in = (S <= -err) | (b[None, :] == np.inf)
    sure_out = (S > err) | (b[None, :] == -np.inf)
    inside = sure_in.all(axis=1)
    out = sure_out.any(axis=1)
    undecided = np.flatnonzero(~inside & ~out)
    if undecided.size:
        finite = np.isfinite(X[undecided]).all(axis=1)
        plain = undecided[~finite]
        inside[plain] = ((X[plain] @ A.T) <= b[None, :]).all(axis=1)
        rows: dict[int, tuple[list[Fraction], Fraction]] = {}
        for k in undecided[finite]:
            xk = [Fraction(float(v)) for v in X[k]]
            ok = True
            for i in np.flatnonzero(~sure_in[k]).tolist():
                if i not in rows:
                    rows[i] = ([Fraction(float(a)) for a in A[i]], Fraction(float(b[i])))
                ai, bi = rows[i]
                if sum((a * x for a, x in zip(ai, xk, strict=True)), Fraction(0)) > bi:
                    ok = False
                    break
            inside[k] = ok
    return inside


def _frac_up(v: Fraction) -> float:
    """The smallest float ``>= v`` (up to one ulp)."""
    f = float(v)
    if Fraction(f) < v:
        f = math.nextafter(f, math.inf)
    return f


def _farkas_empty(A: np.ndarray, b: np.ndarray, y: np.ndarray) -> bool:
    """Exact proof that ``{x : A x <= b}`` is empty, guided by approximate multipliers.

    On the support of ``y`` (dropping its smallest entries one at a time), the exact
    null space of ``A_S^T`` is computed; a one-dimensional null space spanned by
    ``v >= 0`` with ``b_S.v < 0`` is a Farkas certificate: ``0 = v^T A x <= v.b < 0``.
    """
    y = np.where(np.isfinite(y), y, 0.0)
    if y.size == 0 or y.max(initial=0.0) <= 0.0:
        return False
    order = np.argsort(-y)
    S = [int(i) for i in order if y[i] > 1e-12 * y.max()]
    n = A.shape[1]
    while len(S) >= 1:
        k = len(S)
        M = [[Fraction(float(A[i, j])) for i in S] for j in range(n)]
        basis = rat_nullspace(M, k)
        if len(basis) == 1:
            v = basis[0]
            if sum(v) < 0:
                v = [-x for x in v]
            if all(x >= 0 for x in v) and \
                    sum((x * Fraction(float(b[i])) for x, i in zip(v, S, strict=True)),
                        Fraction(0)) < 0:
                return True
            return False
        if not basis:
            return False
        S = S[:-1]
    return False


def _exact_box_slack(y: np.ndarray, A: np.ndarray, b: np.ndarray, lo: np.ndarray,
                     hi: np.ndarray) -> Fraction | None:
    """Exact ``min_{x in [lo, hi]} (A^T y).x - y.b`` (None when it is ``-inf``)."""
    idx = np.flatnonzero(y != 0.0)
    yf = [Fraction(float(y[i])) for i in idx]
    beta = sum((v * Fraction(float(b[i])) for v, i in zip(yf, idx, strict=True)),
               Fraction(0))
    total = -beta
    for j in range(A.shape[1]):
        g = sum((v * Fraction(float(A[i, j])) for v, i in zip(yf, idx, strict=True)),
                Fraction(0))
        if g == 0:
            continue
        bound = lo[j] if g > 0 else hi[j]
        if not np.isfinite(bound):
            return None
        total += g * Fraction(float(bound))
    return total


def _dedupe(V: np.ndarray, tol: float) -> np.ndarray:
    """Drop points closer than ``tol`` (inf-norm) to an earlier point."""
    if V.shape[0] <= 1:
        return V.copy()
    key = np.round(V / max(tol, 1e-300))
    _, idx = np.unique(key, axis=0, return_index=True)
    return V[np.sort(idx)].copy()


def _certify_separation(Y: np.ndarray, A: np.ndarray, b: np.ndarray,
                        bx: np.ndarray, strict: bool = True) -> np.ndarray:
    """Rigorous check that ``y^T A x <= y^T b`` excludes each box.

    Parameters
    ----------
    Y : ndarray, shape (K, m), >= 0
    A, b : raw finite rows, shapes (m, n), (m,); or one set per box, (K, m, n), (K, m)
    bx : ndarray, shape (K, n, 2)

    Returns
    -------
    ndarray of bool, shape (K,)
        True where ``min_{x in box} (A^T y).x - y^T b > 0`` (``>= 0`` when not
        ``strict``) is proven: by a floating-point evaluation with a rigorous bound on its
        rounding error, or, when the value lies within that bound, in exact rational
        arithmetic.
    """
    K, m = Y.shape
    n = A.shape[-1]
    if A.ndim == 3:  # one row set per box: A (K, m, n), b (K, m)
        G = np.einsum("km,kmn->kn", Y, A)
        beta = (Y * b).sum(axis=1)
        Ge = _gamma(m + 2) * np.einsum("km,kmn->kn", Y, np.abs(A))
        be = _gamma(m + 2) * (Y * np.abs(b)).sum(axis=1)
    else:
        G = Y @ A
        beta = Y @ b
        Ge = _gamma(m + 2) * (Y @ np.abs(A))  # |G - exact| <= Ge
        be = _gamma(m + 2) * (Y @ np.abs(b))
    lo, hi = bx[..., 0], bx[..., 1]
    with np.errstate(invalid="ignore", over="ignore"):
        t = np.where(G > 0, G * lo, np.where(G < 0, G * hi, 0.0))
        M = np.maximum(np.abs(lo), np.abs(hi))
        L = t.sum(axis=1)
        err = (_gamma(n + 2) * np.where(np.isfinite(t), np.abs(t), 0.0).sum(axis=1)
               + np.where(Ge > 0, Ge * M, 0.0).sum(axis=1) + be)
        slack = L - beta
        err = (err + _gamma(4) * (np.abs(L) + np.abs(beta))) * (1 + 8 * _U) + 1e-300
        ok = slack > err if strict else slack >= err
        fin = np.isfinite(slack) & np.isfinite(err)
        amb = fin & ~ok & (slack >= -err)
    ok = np.where(fin, ok, False)
    for k in np.flatnonzero(amb).tolist():
        Ak, bk = (A[k], b[k]) if A.ndim == 3 else (A, b)
        v = _exact_box_slack(Y[k], Ak, bk, lo[k], hi[k])
        ok[k] = v is not None and (v > 0 if strict else v >= 0)
    return ok


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


# ============================================================ unions
class PolytopeUnion(SetBase):
    """A finite union ``P_1 ∪ ... ∪ P_p`` of polytopes of the same dimension.

    Parameters
    ----------
    polytopes : iterable of Polytope
        All of the same dimension. May be empty only when ``dim`` is given.
    dim : int, optional
        Dimension; required for a union without members (the empty set).

    Raises
    ------
    TypeError
        An element is not a :class:`Polytope`.
    ValueError
        The iterable is empty and ``dim`` is not given.
    DimensionError
        The polytopes have different dimensions, or differ from ``dim``.

    Examples
    --------
    >>> import casadi_cmpc as cm
    >>> L = cm.Polytope.from_box(cm.Box([0, 0], [1, 1]))
    >>> R = cm.Polytope.from_box(cm.Box([1, 0], [2, 1]))
    >>> S = cm.PolytopeUnion([L, R])
    >>> bool(L.contains_box(cm.Box([0.5, 0.2], [1.5, 0.8]))[0])
    False
    >>> S.contains_box(cm.Box([0.5, 0.2], [1.5, 0.8]))
    array([ True])
    """

    __array_ufunc__ = None

    def __init__(self, polytopes: Iterable[Polytope], dim: int | None = None) -> None:
        items = tuple(polytopes)
        for i, P in enumerate(items):
            if not isinstance(P, Polytope):
                raise TypeError(
                    f"PolytopeUnion element {i} is a {type(P).__name__}, not a Polytope")
        if not items and dim is None:
            raise ValueError("PolytopeUnion needs at least one polytope (or dim= for an "
                             "empty union)")
        dims = {P.dim for P in items}
        if dim is not None:
            dims.add(int(dim))
        if len(dims) != 1:
            raise DimensionError(
                f"PolytopeUnion polytopes differ in dimension: {sorted(dims)}")
        self.polytopes: tuple[Polytope, ...] = items
        self._dim = dims.pop()

    @property
    def dim(self) -> int:
        """Dimension n of the ambient space."""
        return self._dim

    def __len__(self) -> int:
        return len(self.polytopes)

    def __iter__(self) -> Iterator[Polytope]:
        return iter(self.polytopes)

    def _members(self) -> list[Polytope]:
        return [P for P in self.polytopes if not P.is_empty()]

    def contains(self, points: Any, tol: float = 0.0) -> np.ndarray | bool:
        """Membership of points in at least one of the polytopes.

        Parameters
        ----------
        points : array_like, shape (N, n) or (n,)
        tol : float, optional
            Absolute tolerance passed to :meth:`Polytope.contains`.

        Returns
        -------
        bool or ndarray of bool, shape (N,)
        """
        p, batched = as_points(points, self.dim, name="points")
        inside = np.zeros(p.shape[0], dtype=bool)
        for P in self.polytopes:
            inside |= P.contains(p, tol=tol)
        return inside if batched else bool(inside[0])

    def is_empty(self) -> bool:
        """True when every member is empty.

        Returns
        -------
        bool
        """
        return all(P.is_empty() for P in self.polytopes)

    def contains_box(self, boxes: Any, return_witness: bool = False
                     ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Exact test ``box ⊆ P_1 ∪ ... ∪ P_p`` (thesis §6.1.4).

        1. ``box ⊆ P_i`` for some i, in closed form (rounding-safe) -> ``True``;
        2. the centre or (for n <= 4) a corner of the box is outside every member ->
           ``False``;
        3. the rest: ``box ⊆ ∪ P_i`` iff ``box \\ P_1 \\ ... \\ P_p`` has no interior.
           The difference is built member by member, each piece ``R`` minus ``P_i``
           being split into ``R ∩ {a_j.x >= b_j} ∩ {a_l.x <= b_l, l < j}`` over the rows
           of ``P_i`` that cut the box (rows whose half-space holds the box, or members
           separated from the box, are skipped in closed form). After each member the new
           pieces of all boxes are pruned together by one stacked LP (``max r`` s.t.
           ``a.x + r <= b`` for the scaled rows of the piece, ``x`` in the box mapped to
           ``[-1, 1]^n``); a piece is dropped only when the LP multipliers give a
           certificate that the piece has no interior point, checked on the stored rows
           with a rigorous rounding bound or in exact rational arithmetic. ``True`` when
           no piece is left (for a box of positive widths, a non-empty ``box \\ ∪ P_i``
           would contain an interior point of some piece).

        ``True`` is therefore a proof of ``box ⊆ P_1 ∪ ... ∪ P_p`` for the stored
        ``(A_i, b_i)``; ``False`` means "not proven": the box has a point outside the
        union, or it could not be decided (e.g. a gap or overlap between members at the
        level of rounding, or a box of zero width). The witness of a ``False`` is a point
        of the box outside every member when one was found (stage 2, or an LP point of
        an undecided piece, which may lie on the boundary of a member).

        Parameters
        ----------
        boxes : array_like, shape (N, n, 2) or (n, 2), or Box
        return_witness : bool, optional
            Also return, per box, a point of the box outside the union (NaN where the box
            is contained).

        Returns
        -------
        ndarray of bool, shape (N,)
            And the witnesses ``(N, n)`` when ``return_witness``.
        """
        bx = as_boxes(boxes, self.dim, "boxes")
        N, n = bx.shape[0], self.dim
        members = self._members()
        out = np.zeros(N, dtype=bool)
        wit = np.full((N, n), np.nan)
        for P in members:
            und = np.flatnonzero(~out)
            if und.size == 0:
                break
            out[und[P.contains_box(bx[und])]] = True
        und = np.flatnonzero(~out)
        if und.size and members:
            sub = bx[und]
            lo, hi = sub[..., 0], sub[..., 1]
            with np.errstate(invalid="ignore"):
                mid = 0.5 * (lo + hi)
            cands = [np.where(np.isfinite(mid), mid, np.clip(0.0, lo, hi))]
            if n <= 4:
                for bits in itertools.product((0, 1), repeat=n):
                    cands.append(np.where(np.array(bits, dtype=bool), hi, lo))
            decided = np.zeros(und.size, dtype=bool)
            for c in cands:
                outside = ~self.contains(c) & np.isfinite(c).all(axis=1) & ~decided
                wit[und[outside]] = c[outside]
                decided |= outside
            und = und[~decided]
        elif und.size:  # empty union
            sub = bx[und]
            wit[und] = np.clip(0.0, sub[..., 0], sub[..., 1])
            und = und[:0]
        if und.size:
            sub = bx[und]
            with np.errstate(invalid="ignore"):
                mid = 0.5 * (sub[..., 0] + sub[..., 1])
            mid = np.where(np.isfinite(mid), mid, np.clip(0.0, sub[..., 0], sub[..., 1]))
            witnesses = _uncovered(members, sub, mid)
            for j, k in enumerate(und.tolist()):
                if witnesses[j] is None:
                    out[k] = True
                else:
                    wit[k] = witnesses[j]
        return (out, wit) if return_witness else out

    def intersects_box(self, boxes: Any) -> np.ndarray:
        """Whether boxes meet some member; ``False`` only when proven (see
        :meth:`Polytope.intersects_box`).

        Parameters
        ----------
        boxes : array_like, shape (N, n, 2) or (n, 2), or Box

        Returns
        -------
        ndarray of bool, shape (N,)
        """
        bx = as_boxes(boxes, self.dim, "boxes")
        out = np.zeros(bx.shape[0], dtype=bool)
        for P in self.polytopes:
            und = np.flatnonzero(~out)
            if und.size == 0:
                break
            out[und[P.intersects_box(bx[und])]] = True
        return out

    def support(self, directions: Any) -> np.ndarray | float:
        """Support function: the maximum over the members.

        Parameters
        ----------
        directions : array_like, shape (k, n) or (n,)

        Returns
        -------
        float or ndarray, shape (k,)
            ``-inf`` for an empty union.
        """
        D = np.asarray(directions, dtype=float)
        single = D.ndim == 1
        D = np.atleast_2d(D)
        if D.ndim != 2 or D.shape[1] != self.dim:
            raise DimensionError(
                f"directions must have shape (k, {self.dim}) or ({self.dim},); "
                f"got {np.shape(directions)}")
        val = np.full(D.shape[0], -np.inf)
        for P in self._members():
            val = np.maximum(val, np.asarray(P.support(D)))
        return float(val[0]) if single else val

    def bounding_box(self) -> Box:
        """Smallest box containing every member.

        Returns
        -------
        Box

        Raises
        ------
        EmptySetError
            The union is empty.
        """
        members = self._members()
        if not members:
            raise EmptySetError("an empty union of polytopes has no bounding box")
        boxes = [P.bounding_box() for P in members]
        return Box(np.min([B.lo for B in boxes], axis=0), np.max([B.hi for B in boxes], axis=0))

    def convex_hull(self) -> Polytope:
        """Convex hull of the union.

        Returns
        -------
        Polytope
        """
        return hull(self)

    def vertices(self) -> np.ndarray:
        """Vertices of the convex hull of the union.

        Returns
        -------
        ndarray, shape (k, n)

        Raises
        ------
        EmptySetError, UnboundedSetError
            The union is empty, or a member is unbounded.
        """
        members = self._members()
        if not members:
            raise EmptySetError("an empty union of polytopes has no vertex")
        pts = np.vstack([P.vertices() for P in members])
        return _hull.hull_hrep(pts)[2]

    def difference(self, other: Any) -> PolytopeUnion:
        """Set difference ``(∪ P_i) \\ Q`` as a union (closure), member by member.

        Parameters
        ----------
        other : Polytope or Box

        Returns
        -------
        PolytopeUnion
        """
        pieces: list[Polytope] = []
        for P in self._members():
            pieces.extend(P.difference(other).polytopes)
        return PolytopeUnion(pieces, dim=self.dim)

    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), **kw: Any) -> Any:
        """Draw every member in 2-D (projections on ``dims`` for n > 2).

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Created when omitted.
        dims : (int, int)
            Coordinates drawn on the horizontal and vertical axes.
        **kw
            Passed to matplotlib for every member.

        Returns
        -------
        matplotlib Axes
        """
        from ..plot import new_axes

        ax = new_axes(ax)
        for P in self._members():
            P.plot(ax=ax, dims=dims, **kw)
        return ax

    def _state(self) -> dict[str, Any]:
        n = self.dim
        A = np.vstack([P.A for P in self.polytopes]) if self.polytopes else np.zeros((0, n))
        b = np.concatenate([P.b for P in self.polytopes]) if self.polytopes else np.zeros(0)
        counts = np.array([P.n_constraints for P in self.polytopes], dtype=np.int64)
        return {"A": A, "b": b, "counts": counts, "dim": int(n)}

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> PolytopeUnion:
        n = int(state["dim"])
        A = np.asarray(state["A"], dtype=float).reshape(-1, n)
        b = np.asarray(state["b"], dtype=float).ravel()
        counts = np.asarray(state["counts"], dtype=np.int64).ravel()
        ends = np.cumsum(counts)
        starts = ends - counts
        return cls([Polytope(A[s:e], b[s:e]) for s, e in zip(starts, ends, strict=True)],
                   dim=n)

    def __repr__(self) -> str:
        return f"PolytopeUnion(dim={self.dim}, polytopes={len(self.polytopes)})"


# ===================================================== the covering engine
def _uncovered(members: list[Polytope], boxes: np.ndarray, centres: np.ndarray,
               hard: list[tuple[np.ndarray, np.ndarray]] | None = None
               ) -> list[np.ndarray | None]:
    """For each region, None when ``region ⊆ ∪ members`` is proven, else a point.

    The region ``box ∩ {hard rows}`` minus the members is split into pieces (see
    :meth:`PolytopeUnion.contains_box`); a piece is dropped only with a certificate that
    it has no interior point (:func:`_prune_pieces`). For a full-dimensional region,
    no piece left proves ``region ⊆ ∪ members``: ``region \\ ∪ members`` is relatively
    open, so if it were not empty it would contain an interior point of some piece.

    Parameters
    ----------
    members : list of Polytope
        Polytopes not proven empty.
    boxes : ndarray, shape (K, n, 2)
        The regions (or boxes containing them when ``hard`` is given); every width must
        be positive (a flat region is answered with its centre: undecided).
    centres : ndarray, shape (K, n)
        A point of each region (returned when it is not proven covered).
    hard : list of (A, b), optional
        Extra raw rows of each region (e.g. a full-dimensional polytope inside its
        bounding box).

    Returns
    -------
    list of (ndarray (n,) or None)
        A returned point lies in a piece that is not proven empty: it is usually outside
        every member, but not necessarily so (an undecided piece).
    """
    K, n = boxes.shape[0], boxes.shape[1]
    if hard is None:
        hard = [(np.zeros((0, n)), np.zeros(0))] * K
    flat = ~(boxes[..., 1] > boxes[..., 0]).all(axis=1)
    out: list[np.ndarray | None] = [None] * K
    piece_k: list[int] = []
    piece_A: list[np.ndarray] = []
    piece_b: list[np.ndarray] = []
    piece_c: list[np.ndarray] = []
    for k in range(K):
        if flat[k]:
            out[k] = np.asarray(centres[k], dtype=float)
        else:
            piece_k.append(k)
            piece_A.append(np.zeros((0, n)))
            piece_b.append(np.zeros(0))
            piece_c.append(centres[k])
    for P in members:
        if not piece_k:
            break
        PR = P._rows()
        kern = P._kernel()
        ks = np.array(sorted(set(piece_k)))
        relevant = ~kern.holds(boxes[ks])  # the half-space of row j may miss a point
        separated = kern.separates(boxes[ks])
        pos = {k: i for i, k in enumerate(ks.tolist())}
        new_k: list[int] = []
        new_A: list[np.ndarray] = []
        new_b: list[np.ndarray] = []
        kk: list[int] = []
        kA: list[np.ndarray] = []
        kb: list[np.ndarray] = []
        kc: list[np.ndarray] = []
        Js = [np.flatnonzero(row) for row in relevant]
        negA, negb = -PR.A, -PR.b
        for k, A_p, b_p, c_p in zip(piece_k, piece_A, piece_b, piece_c, strict=True):
            i = pos[k]
            if separated[i]:
                kk.append(k)
                kA.append(A_p)
                kb.append(b_p)
                kc.append(c_p)
                continue
            J = Js[i]
            for t, j in enumerate(J.tolist()):
                new_k.append(k)
                new_A.append(np.concatenate((A_p, negA[j:j + 1], PR.A[J[:t]])))
                new_b.append(np.concatenate((b_p, negb[j:j + 1], PR.b[J[:t]])))
        if new_k:
            gone, X = _prune_pieces(new_A, new_b, [hard[k] for k in new_k], boxes[new_k])
            for idx in np.flatnonzero(~gone).tolist():
                kk.append(new_k[idx])
                kA.append(new_A[idx])
                kb.append(new_b[idx])
                kc.append(X[idx])
        piece_k, piece_A, piece_b, piece_c = kk, kA, kb, kc
    for k, c in zip(piece_k, piece_c, strict=True):
        if out[k] is None:
            out[k] = np.asarray(c, dtype=float)
    return out


def _prune_pieces(As: list[np.ndarray], bs: list[np.ndarray],
                  hard: list[tuple[np.ndarray, np.ndarray]], boxes: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Which pieces ``{x in box : A x < b (soft, strict), H x <= g (hard)}`` are empty.

    One stacked LP (HiGHS) per batch, in the coordinates ``u`` of the box mapped to
    ``[-1, 1]^n`` (translation and scale invariant): ``max r`` s.t. ``a'.u + r <= b'``
    on the unit-scaled soft rows, the hard rows, ``u`` in the box, ``r <= 1``. Its
    multipliers ``y`` give the candidate certificate ``min_{x in box} (A^T y_s + H^T y_h)
    .x - b.y_s - g.y_h >= 0`` with ``y_s >= 0`` not zero, which is checked on the raw
    rows with a rigorous rounding bound and, when within that bound, in exact rational
    arithmetic (:func:`_certify_separation`). A certified piece has no point where the
    soft rows hold strictly; nothing is dropped on the LP value alone.

    Parameters
    ----------
    As, bs : lists of raw soft rows, shapes (m_k, n), (m_k,)
    hard : list of raw hard rows (H, g)
    boxes : ndarray, shape (K, n, 2), positive widths

    Returns
    -------
    gone : ndarray of bool, shape (K,)
        Proven without interior.
    X : ndarray, shape (K, n)
        The LP points (a point of each piece that is not proven empty, when its LP
        value is positive).
    """
    K = len(As)
    n = boxes.shape[1]
    lo, hi = boxes[..., 0], boxes[..., 1]
    fin = np.isfinite(lo) & np.isfinite(hi)
    with np.errstate(invalid="ignore", over="ignore"):
        c = np.where(fin, 0.5 * lo + 0.5 * hi, np.clip(0.0, lo, hi))
        D = np.where(fin, 0.5 * hi - 0.5 * lo, 1.0)
        ulo = np.where(np.isfinite(lo), (lo - c) / D, -np.inf)
        uhi = np.where(np.isfinite(hi), (hi - c) / D, np.inf)
    sizes = np.array([A.shape[0] + H.shape[0] for A, (H, _) in zip(As, hard, strict=True)],
                     dtype=np.int64)
    nsoft = np.array([A.shape[0] for A in As], dtype=np.int64)
    m = int(sizes.max(initial=0))
    Apad = np.zeros((K, m, n))
    bpad = np.zeros((K, m))
    for k, (A, b, (H, g)) in enumerate(zip(As, bs, hard, strict=True)):
        ms = A.shape[0]
        Apad[k, :ms] = A
        bpad[k, :ms] = b
        if H.shape[0]:
            Apad[k, ms:sizes[k]] = H
            bpad[k, ms:sizes[k]] = g
    valid = np.arange(m)[None, :] < sizes[:, None]
    soft = np.arange(m)[None, :] < nsoft[:, None]
    M = Apad * D[:, None, :]
    with np.errstate(over="ignore", invalid="ignore"):
        r_ = bpad - np.einsum("kmn,kn->km", Apad, c)
    nu = np.linalg.norm(M, axis=2)
    nu = np.where(nu > 0, nu, 1.0)
    rows = np.concatenate([(M / nu[..., None])[valid], soft[valid][:, None].astype(float)],
                          axis=1)
    rhs_all = (r_ / nu)[valid]
    C = np.zeros((K, n + 1))
    C[:, -1] = -1.0
    lb = np.hstack([ulo, np.full((K, 1), -np.inf)])
    ub = np.hstack([uhi, np.ones((K, 1))])
    good = np.isfinite(rhs_all)
    rhs_all = np.where(good, rhs_all, 0.0)
    res = _lp.block_lp(C, rows, rhs_all, np.repeat(np.arange(K), sizes), lb, ub)
    opt = res.status == _lp.OPTIMAL
    U = np.where(opt[:, None], res.x[:, :n], 0.0)
    X = np.clip(c + D * U, lo, hi)
    r = np.where(opt, res.x[:, -1], np.inf)
    gone = np.zeros(K, dtype=bool)
    cand = np.flatnonzero(opt & (r <= 1e-6))
    if cand.size == 0 or m == 0:
        return gone, X
    Y = np.zeros((K, m))
    Y[valid] = res.y
    Y = np.where(np.isfinite(Y), np.maximum(Y, 0.0), 0.0) / nu
    Y[~valid] = 0.0
    G = np.zeros((K, m), dtype=bool)
    G[valid] = good
    ok_soft = (np.where(soft, Y, 0.0).max(axis=1) > 0.0) & (G | ~valid).all(axis=1)
    Yc = Y[cand]
    proven = _certify_separation(Yc, Apad[cand], bpad[cand], boxes[cand], strict=False)
    gone[cand] = proven & ok_soft[cand]
    return gone, X
