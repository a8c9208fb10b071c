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

Layout
------
:class:`Polytope` is defined here and calls, by job: :mod:`casadi_cmpc.sets._poly_lp` (LP
queries: emptiness, boundedness, Chebyshev ball, support, bounding box, redundancy),
:mod:`casadi_cmpc.sets._poly_box` (``intersects_box``; the closed-form kernels are in
:mod:`casadi_cmpc.sets._boxkernel`), :mod:`casadi_cmpc.sets._poly_project` (vertices and
projection) and :mod:`casadi_cmpc.sets._poly_ops` (set operations and :func:`hull`).
:class:`PolytopeUnion` and the covering engine behind its box test are in
:mod:`casadi_cmpc.sets._poly_union`; ``PolytopeUnion`` and ``hull`` are exported here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from .._validate import as_boxes, as_float_array, as_points
from ..exceptions import DimensionError, EmptySetError, InvalidBoundsError, UnboundedSetError
from . import _hull, _poly_box, _poly_lp, _poly_ops, _poly_project
from ._boxkernel import _U, BoxKernel, _gamma, _two_prod, exact_points_le, points_le
from ._poly_lp import RTOL
from ._poly_ops import _as_matrix, _as_vector, hull
from ._poly_union import PolytopeUnion
from .base import SetBase
from .box import Box

__all__ = ["Polytope", "PolytopeUnion", "hull"]


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
    ex: np.ndarray  # (k,) int: An = A 2**-ex / ns (an exact power of two, then the norm)
    ns: np.ndarray  # (k,) the norms of the rows A 2**-ex, in [0.5, sqrt(n)]

    def raw_multipliers(self, y: np.ndarray) -> np.ndarray:
        """Multipliers of the raw rows ``A`` from those ``y`` (..., k) of the unit rows
        ``An``: ``y 2**-ex / ns``, made finite and non-negative (an entry that over- or
        underflows becomes 0; what the multipliers certify is checked exactly afterwards,
        so any finite choice is sound)."""
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            r = np.ldexp(np.asarray(y, dtype=float) / self.ns, -self.ex)
        return np.where(np.isfinite(r), np.maximum(r, 0.0), 0.0)


def _residual(A: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``b - A c`` row by row in doubled precision (error-free products and sums), and a
    bound of its error (the rounding to double plus the second-order terms)."""
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
        # a row constrains iff one of its entries is nonzero: decided exactly (its norm
        # computed in floating point underflows to 0 for entries below about 1e-154)
        nonzero = (A != 0).any(axis=1)
        trivially_empty = bool(np.any(b == -np.inf) or np.any(~nonzero & (b < 0)))
        keep = np.isfinite(b) & nonzero
        A_k, b_k = A[keep], b[keep]
        # every row scaled by an exact power of two (its largest entry into [0.5, 1))
        # before its norm is taken: neither the norm nor the unit row under- or overflows,
        # whatever the magnitudes of the entries
        _, ex = np.frexp(np.abs(A_k).max(axis=1, initial=0.0))
        ex = ex.astype(np.int64)
        As = np.ldexp(A_k, -ex[:, None])
        ns = np.linalg.norm(As, axis=1)  # in [0.5, sqrt(n)]
        An = As / ns[:, None]
        with np.errstate(over="ignore"):
            # +inf where b / |a| lies beyond the largest double: such a row excludes no
            # point of the double range, and the LPs drop it (a superset: sound for what
            # they prove, emptiness, separation and upper support bounds); -inf where it
            # lies below -DBL_MAX: no double point satisfies it (see bz below)
            bn = np.ldexp(b_k, -ex) / ns
        far = ~np.isfinite(bn)
        n = A.shape[1]
        if "vertices" in self._cache and len(self._cache["vertices"]):
            c0 = np.asarray(self._cache["vertices"], dtype=float).mean(axis=0)
        elif (~far).any():
            c0 = np.linalg.lstsq(An[~far], bn[~far], rcond=None)[0]
        else:
            c0 = np.zeros(n)
        if not np.isfinite(c0).all():
            c0 = np.zeros(n)
        with np.errstate(over="ignore", invalid="ignore"):
            dev = np.abs(bn - An @ c0)[~far]
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
            bz0 = np.ldexp(res, -ex) / ns / scale
            slack = (_gamma(n + 4) * (np.abs(bz0) + np.abs(An).sum(axis=1))
                     + np.ldexp(res_err, -ex) / ns / scale * (1 + 4 * _U))
            bz = bz0 + slack
            bz = np.where(np.isfinite(bz), bz, (bn - An @ c0) / scale)
            bz0 = np.where(np.isfinite(bz0), bz0, bz)
            # beyond the double range: +inf, a row that excludes no double point (the LPs
            # leave it out); -inf, a row no double point satisfies (the LPs refuse it with
            # a clear error rather than read it as vacuous)
            bz[far] = bz0[far] = np.where(bn[far] > 0, np.inf, -np.inf)
        r = _Rows(A_k, b_k, An, bn, trivially_empty, RTOL * scale, c0, scale, bz, bz0, ex,
                  ns)
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
        return _poly_lp.chebyshev(self)

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
        return _poly_lp.is_empty(self)

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
        return _poly_lp.is_bounded(self)

    def _require_bounded_nonempty(self, what: str) -> None:
        if self.is_empty():
            raise EmptySetError(f"{what} of an empty polytope is not defined")
        if not self.is_bounded():
            raise UnboundedSetError(
                f"{what} needs a bounded polytope; this one is unbounded "
                "(intersect it with a Box first)")

    def _max_lp(self, D: np.ndarray, multipliers_only: bool = False
                ) -> tuple[np.ndarray, np.ndarray]:
        """``max d.x`` over P for each row of D (K, n): values (K,) and maximisers (K, n)
        (:func:`~casadi_cmpc.sets._poly_lp.max_lp`)."""
        return _poly_lp.max_lp(self, D, multipliers_only)

    def _support_upper(self, D: np.ndarray) -> np.ndarray:
        """Rigorous upper bounds (K,) of the support function in the directions D (K, n)
        (:func:`~casadi_cmpc.sets._poly_lp.support_upper`)."""
        return _poly_lp.support_upper(self, D)

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
        return _poly_lp.bounding_box(self)

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
        return _poly_project.vertices(self)

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
        return _poly_box.intersects_box(self, boxes)

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
        return _poly_lp.minimal(self)

    def remove_redundant(self) -> Polytope:
        """Alias of :meth:`minimal`.

        Returns
        -------
        Polytope
        """
        return self.minimal()

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
        return _poly_ops.affine_map(self, M, t)

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
        return _poly_ops.minkowski_sum(self, other)

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
        return _poly_ops.pontryagin_difference(self, other)

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
        return _poly_project.project(self, dims, method)

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
        return _poly_ops.is_subset(self, other, tol)

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
        return _poly_ops.difference(self, other)

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
