r"""Zonotopes ``p ⊕ H B^m`` (thesis §4.2): construction, bisection, inclusion, evolution.

A zonotope of order ``n x m`` is the set (4.10)-(4.11)

.. math:: \mathcal Z = p \oplus H \mathbf B^m
          = \{p + \textstyle\sum_{j=1}^m \alpha_j h_j : -1 \le \alpha_j \le 1\},

a centrally symmetric convex polytope. This module provides the class :class:`Zonotope`
(the full set protocol of :mod:`casadi_cmpc.sets.base`, bisection Thm 4.1/4.2, exact H- and
V-representations, parallelotope bounding §4.2.5, Fig 4.7) and three functions:

* :func:`zonotope_inclusion` - Kühn's zonotope inclusion ``◇(p ⊕ M B^m)`` of a family with
  an interval matrix (Thm 4.3, (4.14)-(4.15));
* :func:`kuhn_inclusion` - a zonotope containing ``{M x : M in [M], x in Z}``;
* :func:`evolve` - one step of uncertain evolution ``f(Z, u, W)`` by the mean-value form and
  Kühn's inclusion (Thm 4.4, (4.16));
* :func:`reach` (defined in :mod:`casadi_cmpc.sets._reach`) - outer bounds of the reachable
  sets over a given control sequence, by zonotopes or intervals (Def 6.2, Fig 6.10).

Rounding
--------
Every result called an *enclosure* or *outer* bound contains the exact set although it is
computed in floating point: interval parts use the outward-rounded operations of
:mod:`casadi_cmpc.interval.arith`, sums of magnitudes are rounded upward, and linear solves
are verified. Predicates (``contains_box``, ``contained_in``, ``intersects_box`` returning
False) are True only when proven. Facet normals are enclosed exactly (the normal of a
subset of generators is enclosed by a verified linear solve, with an exact rational fallback
for ill-conditioned subsets), so the proofs use the true facets of the zonotope.
"""

from __future__ import annotations

import itertools
from math import comb
from typing import Any

import numpy as np

from .._validate import as_boxes, as_points
from ..exceptions import (
    DimensionError,
    EmptySetError,
    InvalidBoundsError,
    ModelError,
    SolverError,
    UnboundedSetError,
    UnsupportedOperationError,
)
from ..interval import arith as ia
from . import _zono_num as zn
from .base import SetBase
from .box import Box
from .polytope import Polytope

__all__ = ["Zonotope", "zonotope_inclusion", "kuhn_inclusion", "evolve", "reach"]

#: Largest number of (n-1)-subsets of generators enumerated for facets (H-representation).
MAX_FACETS = 20000
_PARALLELOTOPE_METHODS = ("svd", "pca", "norm", "volume", "box")
_CHUNK = 2048


# ----------------------------------------------------------------------------- helpers
def _as_center(center: Any) -> np.ndarray:
    c = np.array(center, dtype=float)
    if c.ndim == 0:
        c = c.reshape(1)
    if c.ndim != 1:
        raise DimensionError(f"Zonotope center must be a vector (n,); got shape {c.shape}")
    if c.size == 0:
        raise DimensionError("Zonotope center must have at least one component (n >= 1)")
    if np.isnan(c).any():
        raise InvalidBoundsError("Zonotope center contains NaN")
    if not np.isfinite(c).all():
        raise UnboundedSetError("Zonotope center has an infinite component; a zonotope is "
                                "bounded")
    return c


def _as_generators(G: Any, n: int) -> np.ndarray:
    H = np.array(G, dtype=float)
    if H.ndim == 1 and n == 1:
        H = H.reshape(1, -1)
    if H.ndim != 2:
        raise DimensionError(
            f"Zonotope generators must be a matrix (n, p); got shape {H.shape}")
    if H.shape[0] != n:
        raise DimensionError(
            f"Zonotope generators have the wrong number of rows; expected {n} (the length "
            f"of the center) instead of {H.shape[0]}")
    if np.isnan(H).any():
        raise InvalidBoundsError("Zonotope generators contain NaN")
    if not np.isfinite(H).all():
        raise UnboundedSetError("Zonotope generators contain an infinite entry")
    return H


def _interval_matrix(lo: Any, hi: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    lo_a = np.array(lo, dtype=float)
    hi_a = np.array(hi, dtype=float)
    if lo_a.shape != hi_a.shape or lo_a.ndim != 2:
        raise DimensionError(
            f"{name}: lower and upper bounds must be matrices of one shape; got "
            f"{lo_a.shape} and {hi_a.shape}")
    if np.isnan(lo_a).any() or np.isnan(hi_a).any():
        raise InvalidBoundsError(f"{name} contains NaN bounds")
    if not (np.isfinite(lo_a).all() and np.isfinite(hi_a).all()):
        raise UnboundedSetError(f"{name} has an infinite bound")
    if (lo_a > hi_a).any():
        i, j = np.argwhere(lo_a > hi_a)[0]
        raise EmptySetError(f"{name} is empty at entry ({i}, {j}): {lo_a[i, j]} > "
                            f"{hi_a[i, j]}")
    return lo_a, hi_a


def _drop_zero_columns(G: np.ndarray) -> np.ndarray:
    return G[:, np.any(G != 0.0, axis=0)]


def _family_to_zonotope(q_lo: np.ndarray, q_hi: np.ndarray, M_lo: np.ndarray,
                        M_hi: np.ndarray) -> Zonotope:
    """Zonotope ⊇ ``[q] ⊕ [M] B^m`` for an interval vector [q] and interval matrix [M]."""
    q, qrad = zn.midrad(q_lo, q_hi)
    Mmid, Mrad = zn.midrad(M_lo, M_hi)
    diag = zn.add_up(qrad, zn.sum_up(Mrad, axis=1))
    if not (np.isfinite(q).all() and np.isfinite(diag).all() and np.isfinite(Mmid).all()):
        raise UnboundedSetError("the enclosure is unbounded (an interval bound is infinite)")
    D = np.diag(diag)
    return Zonotope(q, np.hstack([_drop_zero_columns(Mmid), D[:, diag > 0]]))


# ----------------------------------------------------------------------------- class
class Zonotope(SetBase):
    r"""The zonotope ``p ⊕ H B^m = {p + H z : z in [-1, 1]^m}`` (thesis (4.10)-(4.11)).

    Parameters
    ----------
    center : array_like, shape (n,)
        The centre ``p``.
    generators : array_like, shape (n, m)
        The line segment generators ``h_1, ..., h_m`` as columns (``m = 0`` gives the point
        ``{p}``).

    Raises
    ------
    DimensionError
        Wrong shapes (the generators must have ``n`` rows).
    InvalidBoundsError
        NaN entries.
    UnboundedSetError
        Infinite entries.

    See Also
    --------
    zonotope_inclusion, kuhn_inclusion, evolve

    Notes
    -----
    A zonotope is a box when ``H`` is diagonal (:meth:`from_box`), and a parallelotope when
    ``H`` is square and invertible. Facets are normal to the spans of ``(n-1)``-subsets of
    generators, so the H-representation has at most ``2 C(m, n-1)`` rows; in 2-D the
    ``2 m`` vertices follow from the generators sorted by angle.

    Examples
    --------
    >>> import numpy as np
    >>> import casadi_cmpc as cm
    >>> Z = cm.Zonotope([2.0, 2.0], [[0.6414, 0.5855], [-0.4016, 0.7930]])
    >>> Z.dim, Z.n_generators
    (2, 2)
    >>> Z.contains([[2.0, 2.0], [4.0, 4.0]])
    array([ True, False])
    >>> len(Z.vertices())
    4
    >>> L, R = Z.bisect()
    >>> L.center
    array([1.70725, 1.6035 ])
    """

    def __init__(self, center: Any, generators: Any) -> None:
        c = _as_center(center)
        G = _as_generators(generators, c.size)
        c.setflags(write=False)
        G.setflags(write=False)
        self._c = c
        self._G = G
        self._cache: dict[str, Any] = {}

    # ------------------------------------------------------------ construction
    @classmethod
    def from_box(cls, box: Any) -> Zonotope:
        """The box as a zonotope with a diagonal generator matrix.

        Parameters
        ----------
        box : Box or array_like, shape (n, 2)
            A bounded box.

        Returns
        -------
        Zonotope
            ``mid ⊕ diag(rad) B^n`` (zero-width components give no generator). The radius
            is rounded upward, so the zonotope contains the box and equals it whenever the
            midpoint and radius are exact floats.
        """
        b = as_boxes(box, None, "box")
        if b.shape[0] != 1:
            raise DimensionError(f"from_box takes one box; got a batch of {b.shape[0]}")
        b = b[0]
        if not np.isfinite(b).all():
            raise UnboundedSetError("from_box needs a bounded box (finite bounds)")
        c, r = zn.midrad(b[:, 0], b[:, 1])
        D = np.diag(r)
        return cls(c, D[:, r > 0])

    @classmethod
    def outer_parallelotope(cls, points: Any, center: Any = None,
                            method: str = "svd") -> Zonotope:
        """A parallelotope containing a finite point set (e.g. the vertices of a polytope).

        Parameters
        ----------
        points : array_like, shape (N, n)
            The points; the result contains their convex hull.
        center : array_like, shape (n,), optional
            Centre of the parallelotope. Default: the midpoint of the points' bounding box
            (§4.2.5 suggests the centre of the largest inscribed ball of a polytope).
        method : {"svd", "pca", "box"}
            Directions: principal axes of the centred points, or the coordinate axes.

        Returns
        -------
        Zonotope
            ``c ⊕ T diag(s) B^n`` with ``s_i = max_k |(T^{-1}(v_k - c))_i|`` (the smallest
            scaling with these directions), verified like
            :meth:`reduce_to_parallelotope`: every point is proven inside.
        """
        V, _ = as_points(points, None, name="points")
        if not np.isfinite(V).all():
            raise InvalidBoundsError("points must be finite (no NaN or inf)")
        n = V.shape[1]
        if center is None:
            lo, hi = V.min(axis=0), V.max(axis=0)
            c = zn.midrad(lo, hi)[0]
        else:
            c = _as_center(center)
            if c.size != n:
                raise DimensionError(f"center has {c.size} components; expected {n}")
        meth = str(method).lower()
        if meth in ("svd", "pca"):
            T = _svd_directions((V - c).T, n)
        elif meth == "box":
            T = np.eye(n)
        else:
            raise ValueError(f"Unknown method '{method}'; valid: svd, pca, box")
        # v - c = fl(v - c) + err exactly (TwoSum); both parts are carried as "generators"
        D = V - c
        err = zn.two_sum_error(V, -np.broadcast_to(c, V.shape))
        return cls(c, _outer_parallelotope(T, np.hstack([D.T, err.T]), points=True))

    # -------------------------------------------------------------- properties
    @property
    def center(self) -> np.ndarray:
        """The centre ``p``, shape (n,)."""
        return self._c

    @property
    def generators(self) -> np.ndarray:
        """The generator matrix ``H``, shape (n, m)."""
        return self._G

    @property
    def dim(self) -> int:
        """Ambient dimension n."""
        return int(self._c.size)

    @property
    def n_generators(self) -> int:
        """Number m of generators (columns of ``H``)."""
        return int(self._G.shape[1])

    @property
    def order(self) -> float:
        """Order ``m / n`` (generators per dimension)."""
        return self.n_generators / self.dim

    def _cached(self, key: str, build: Any) -> Any:
        if key not in self._cache:
            self._cache[key] = build()
        return self._cache[key]

    @property
    def _Gnz(self) -> np.ndarray:
        return self._cached("Gnz", lambda: _drop_zero_columns(self._G))

    @property
    def _float_rank(self) -> int:
        def build() -> int:
            G = self._Gnz
            if G.shape[1] == 0:
                return 0
            s = np.linalg.svd(G, compute_uv=False)
            return int((s > s[0] * max(G.shape) * np.finfo(float).eps).sum())

        return self._cached("rank", build)

    @property
    def _full_rank(self) -> bool:
        """True when ``rank(H) = n`` is proven."""
        return self._cached("full_rank", lambda: zn.proven_full_rank(self._Gnz))

    def is_full_dimensional(self) -> bool:
        """True when the generators are proven to span R^n (the zonotope has an interior)."""
        return bool(self._full_rank)

    # ------------------------------------------------------- sound supports
    def _support_bounds(self, Dlo: np.ndarray, Dhi: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Enclosure of ``h_Z(a) = a.p + sum_j |a.h_j|`` over interval directions (k, n)."""
        c = self._c[:, None]
        aclo, achi = zn.imatmul(Dlo, Dhi, c, c)  # (k, 1)
        G = self._Gnz
        aglo, aghi = zn.imatmul(Dlo, Dhi, G, G)  # (k, p)
        ablo, abhi = zn.iabs(aglo, aghi)
        slo, shi = zn.isum(ablo, abhi, axis=1)
        return ia.add(aclo[:, 0], achi[:, 0], slo, shi)

    def _support_upper(self, D: np.ndarray) -> np.ndarray:
        """Upper bound of the exact support function at float directions (k, n)."""
        return self._support_bounds(D, D)[1]

    # ---------------------------------------------------------------- facets
    def _facet_data(self, with_axes: bool = False) -> dict[str, np.ndarray] | None:
        """Exact facet normals (intervals) and enclosures of ``h_Z(±a)``; None if too many."""

        def build() -> dict[str, np.ndarray] | None:
            G = self._Gnz
            dirs = np.hstack([G, np.eye(self.dim)]) if with_axes else G
            if not with_axes and not self._full_rank:
                return None
            normals = zn.facet_normals(dirs, MAX_FACETS)
            if normals is None:
                return None
            Nlo, Nhi = normals
            plo, phi = self._support_bounds(Nlo, Nhi)
            mlo, mhi = self._support_bounds(-Nhi, -Nlo)
            return {"Nlo": Nlo, "Nhi": Nhi, "hp_lo": plo, "hp_hi": phi,
                    "hm_lo": mlo, "hm_hi": mhi}

        return self._cached("facets_axes" if with_axes else "facets", build)

    @staticmethod
    def _box_dot(Nlo: np.ndarray, Nhi: np.ndarray, b: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Enclosure of ``{a.x : a in [N_f], x in box}`` for boxes (N, n, 2) -> (N, F)."""
        lo = hi = None
        for i in range(Nlo.shape[1]):
            pl, ph = ia.mul(Nlo[None, :, i], Nhi[None, :, i], b[:, None, i, 0],
                            b[:, None, i, 1])
            if lo is None:
                lo, hi = pl, ph
            else:
                lo, hi = ia.add(lo, hi, pl, ph)
        return lo, hi

    def _classify(self, b: np.ndarray, data: dict[str, np.ndarray]
                  ) -> tuple[np.ndarray, np.ndarray]:
        """(proven inside, proven disjoint) for boxes (N, n, 2) against the facets."""
        N = b.shape[0]
        inside = np.zeros(N, dtype=bool)
        disjoint = np.zeros(N, dtype=bool)
        with np.errstate(invalid="ignore"):
            for s in range(0, N, _CHUNK):
                bb = b[s:s + _CHUNK]
                tlo, thi = self._box_dot(data["Nlo"], data["Nhi"], bb)
                ins = (thi <= data["hp_lo"]) & (-tlo <= data["hm_lo"])
                out = (tlo > data["hp_hi"]) | (-thi > data["hm_hi"])
                inside[s:s + _CHUNK] = ins.all(axis=1)
                disjoint[s:s + _CHUNK] = out.any(axis=1)
        return inside, disjoint

    # -------------------------------------------------------------- protocol
    def is_empty(self) -> bool:
        """Always False: a zonotope contains its centre."""
        return False

    def contains(self, points: Any) -> np.ndarray | bool:
        """Membership of points.

        Parameters
        ----------
        points : array_like, shape (N, n) or (n,)

        Returns
        -------
        bool or ndarray of bool, shape (N,)
            False only when the point is proven outside (a point within rounding distance of
            the boundary counts as inside; use :meth:`contains_box` with a degenerate box for
            a proof of membership).

        Notes
        -----
        Full-dimensional zonotopes with at most ``MAX_FACETS`` facet candidates are tested
        against the exact facets; otherwise each point solves the LP
        ``min t s.t. H a = x - p, |a_j| <= t`` (scipy ``linprog``, HiGHS) and is inside
        when ``t <= 1 + 1e-9``.
        """
        p, batched = as_points(points, self.dim, name="points")
        if np.isnan(p).any():
            raise InvalidBoundsError("points contain NaN")
        data = self._facet_data() if self._float_rank == self.dim else None
        if data is not None:
            b = np.stack([p, p], axis=-1)
            inside = ~self._classify(b, data)[1]
        else:
            inside = self._contains_lp(p)
        return inside if batched else bool(inside[0])

    def _contains_lp(self, p: np.ndarray) -> np.ndarray:
        G = self._Gnz
        n, m = G.shape
        out = np.zeros(p.shape[0], dtype=bool)
        if m == 0:
            return np.all(p == self._c, axis=1)
        from scipy.optimize import linprog

        cost = np.zeros(m + 1)
        cost[-1] = 1.0
        eye = np.eye(m)
        A_ub = np.block([[eye, -np.ones((m, 1))], [-eye, -np.ones((m, 1))]])
        b_ub = np.zeros(2 * m)
        A_eq = np.hstack([G, np.zeros((n, 1))])
        bounds = [(None, None)] * m + [(0, None)]
        for i, x in enumerate(p):
            res = linprog(cost, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=x - self._c,
                          bounds=bounds, method="highs")
            out[i] = res.status == 0 and res.fun <= 1.0 + 1e-9
        return out

    def contains_box(self, boxes: Any) -> np.ndarray:
        """Proven inclusion of boxes in the zonotope.

        Parameters
        ----------
        boxes : Box or array_like, shape (N, n, 2) or (n, 2)

        Returns
        -------
        ndarray of bool, shape (N,)
            True only when ``box ⊆ Z`` is proven: for every exact facet normal ``a``
            (both signs) ``max_{x in box} a.x <= h_Z(a)`` holds in outward-rounded
            arithmetic. Flat zonotopes (rank < n) and zonotopes with more than
            ``MAX_FACETS`` facet candidates give False.
        """
        b = as_boxes(boxes, self.dim, "boxes")
        data = self._facet_data()
        if data is None:
            return np.zeros(b.shape[0], dtype=bool)
        return self._classify(b, data)[0]

    def intersects_box(self, boxes: Any) -> np.ndarray:
        """Possible intersection of boxes with the zonotope.

        Parameters
        ----------
        boxes : Box or array_like, shape (N, n, 2) or (n, 2)

        Returns
        -------
        ndarray of bool, shape (N,)
            False only when ``box ∩ Z = ∅`` is proven by a separating direction: the
            axes, or an exact facet normal of ``Z ⊕ box`` (normals of (n-1)-subsets of the
            generators and the coordinate axes), rounded outward.
        """
        b = as_boxes(boxes, self.dim, "boxes")
        bb = self.bounding_box()
        meets = ((b[..., 0] <= bb.hi) & (b[..., 1] >= bb.lo)).all(axis=1)
        data = self._facet_data(with_axes=True)
        if data is not None and meets.any():
            idx = np.flatnonzero(meets)
            meets[idx] = ~self._classify(b[idx], data)[1]
        return meets

    def support(self, directions: Any) -> np.ndarray | float:
        """Support function ``h_Z(d) = d.p + sum_j |d.h_j|``.

        Parameters
        ----------
        directions : array_like, shape (k, n) or (n,)

        Returns
        -------
        ndarray, shape (k,), or float
            Evaluated in floating point (round to nearest).
        """
        D = np.asarray(directions, dtype=float)
        single = D.ndim == 1
        D = np.atleast_2d(D)
        if D.ndim != 2 or D.shape[1] != self.dim:
            raise DimensionError(
                f"directions must have {self.dim} columns; got shape {np.shape(directions)}")
        if np.isnan(D).any():
            raise InvalidBoundsError("directions contain NaN")
        val = D @ self._c + np.abs(D @ self._G).sum(axis=1)
        return float(val[0]) if single else val

    def bounding_box(self) -> Box:
        """Smallest axis-aligned box containing the zonotope, ``p ± sum_j |h_j|``.

        Returns
        -------
        Box
            Bounds rounded outward (exact when the sums are exact floats).
        """

        def build() -> Box:
            r = zn.sum_up(np.abs(self._G), axis=1)
            return Box(zn.sub_dn(self._c, r), zn.add_up(self._c, r))

        return self._cached("bbox", build)

    def to_box(self) -> Box:
        """Alias of :meth:`bounding_box` (interval hull of the zonotope)."""
        return self.bounding_box()

    # -------------------------------------------------------------- vertices
    def vertices(self) -> np.ndarray:
        """The vertices of the zonotope.

        Returns
        -------
        ndarray, shape (k, n)
            In 2-D the ``2 m'`` vertices in counter-clockwise order (``m'`` = number of
            distinct generator directions). In n-D every vertex ``p + H s`` (``s`` a sign
            vector) is listed once; the sign vectors are found exactly from the facets:
            the vertices of the facet with normal ``a`` are
            ``p + sum_{a.h_j != 0} sign(a.h_j) h_j + sum_{a.h_j = 0} ±h_j``.

        Raises
        ------
        UnsupportedOperationError
            More than ``MAX_FACETS`` facet candidates (n >= 3).
        """
        return self._cached("vertices", self._compute_vertices)

    def _compute_vertices(self) -> np.ndarray:
        S = self._vertex_signs()
        return self._c + S.astype(float) @ self._Gnz.T

    def _vertex_signs(self) -> np.ndarray:
        """Sign vectors ``s`` (k, m') of the vertices ``p + H' s`` (H' = nonzero generators)."""
        G = self._Gnz
        n, m = G.shape
        if m == 0:
            return np.zeros((1, 0), dtype=np.int8)
        if n == 1:
            s = np.where(G[0] > 0, 1, -1).astype(np.int8)
            return np.stack([-s, s])
        r = self._float_rank
        if r < n:  # flat: the same sign vectors as in an orthonormal basis of the span
            U = np.linalg.svd(G)[0][:, :r]
            return Zonotope(np.zeros(r), U.T @ G)._vertex_signs()
        if n == 2:
            return _vertex_signs_2d(G)
        return self._vertex_signs_nd()

    def _vertex_signs_nd(self) -> np.ndarray:
        G = self._Gnz
        n, m = G.shape
        normals = zn.facet_normals(G, MAX_FACETS)
        if normals is None:
            raise UnsupportedOperationError(
                f"vertices(): {comb(m, n - 1)} facet candidates exceed MAX_FACETS = "
                f"{MAX_FACETS}; reduce the order first (reduce_order)")
        Nlo, Nhi = normals
        alo, ahi = zn.imatmul(Nlo, Nhi, G, G)  # (F, m)
        sgn = np.where(alo > 0, 1, np.where(ahi < 0, -1, 0)).astype(np.int8)
        signs = []
        degenerate = False
        for row in sgn:
            zero = np.flatnonzero(row == 0)
            if zero.size > 16:
                raise UnsupportedOperationError(
                    f"vertices(): a facet holds {zero.size} generators; reduce the order")
            degenerate |= zero.size > n - 1
            combos = np.array(list(itertools.product((-1, 1), repeat=zero.size)),
                              dtype=np.int8).reshape(-1, zero.size)
            block = np.repeat(row[None], combos.shape[0], axis=0)
            block[:, zero] = combos
            signs.append(block)
            signs.append(-block)
        S = np.unique(np.concatenate(signs), axis=0)
        if degenerate and len(S) > n + 1:
            try:
                from scipy.spatial import ConvexHull

                V = S.astype(float) @ G.T
                S = S[np.sort(ConvexHull(V).vertices)]
            except Exception:  # keep all candidates: their hull is still the zonotope
                pass
        return S

    def to_vpolytope(self) -> np.ndarray:
        """V-representation: the vertices, shape (k, n) (see :meth:`vertices`)."""
        return self.vertices()

    # ------------------------------------------------------- H-representation
    def to_polytope(self) -> Polytope:
        """H-representation ``{x : A x <= b}`` of the zonotope.

        Returns
        -------
        Polytope
            Rows ``±a`` for every facet normal (normals of the spans of (n-1)-subsets of
            generators; in 2-D the rotated generators ``(-h_2j, h_1j)``), with
            ``b = h_Z(a)`` rounded upward, so the polytope contains the zonotope and its
            facets coincide with the zonotope's up to the rounding of the normals. For a
            flat zonotope (rank r < n) the normals are taken in an orthonormal basis of its
            span, plus the rows of the orthogonal complement.

        Raises
        ------
        UnsupportedOperationError
            More than ``MAX_FACETS`` facet candidates.
        """
        return self._cached("polytope", self._compute_polytope)

    def _compute_polytope(self) -> Polytope:
        n = self.dim
        G = self._Gnz
        r = self._float_rank
        if r == n:
            normals = zn.facet_normals(G, MAX_FACETS)
            if normals is None:
                raise UnsupportedOperationError(
                    f"to_polytope(): {comb(G.shape[1], n - 1)} facet candidates exceed "
                    f"MAX_FACETS = {MAX_FACETS}; reduce the order first (reduce_order)")
            A = zn.midrad(*normals)[0]
        else:
            U = np.linalg.svd(G)[0] if G.shape[1] else np.eye(n)
            rows = [U[:, r:].T]
            if r > 0:
                sub = Zonotope(np.zeros(r), U[:, :r].T @ G)
                rows.append(sub.to_polytope().A @ U[:, :r].T)
            A = np.vstack(rows)
        A = np.unique(np.vstack([A, -A]), axis=0)
        return Polytope(A, self._support_upper(A))

    def contained_in(self, other: Any) -> bool:
        """Proven inclusion of the zonotope in a polytope, a box or another zonotope.

        Parameters
        ----------
        other : Polytope, Box, Zonotope or PolytopeUnion

        Returns
        -------
        bool
            True only when ``Z ⊆ other`` is proven: ``h_Z(a_i) <= b_i`` for every row of a
            polytope ``{A x <= b}`` (exact criterion; ``h_Z`` rounded upward); for a
            zonotope ``h_Z(a) <= h_other(a)`` for all exact facet normals ``a`` of
            ``other``; for a union, inclusion in one member.
        """
        if isinstance(other, Box):
            if other.dim != self.dim:
                raise DimensionError(
                    f"other has dimension {other.dim}; expected {self.dim}")
            bb = self.bounding_box()
            return bool(np.all(bb.lo >= other.lo) and np.all(bb.hi <= other.hi))
        if isinstance(other, Zonotope):
            if other.dim != self.dim:
                raise DimensionError(
                    f"other has dimension {other.dim}; expected {self.dim}")
            data = other._facet_data()
            if data is None:
                return False
            up_p = self._support_bounds(data["Nlo"], data["Nhi"])[1]
            up_m = self._support_bounds(-data["Nhi"], -data["Nlo"])[1]
            return bool(np.all(up_p <= data["hp_lo"]) and np.all(up_m <= data["hm_lo"]))
        members = getattr(other, "polytopes", None)
        if members is not None:
            return any(self.contained_in(P) for P in members)
        if hasattr(other, "A") and hasattr(other, "b"):
            A = np.asarray(other.A, dtype=float)
            b = np.asarray(other.b, dtype=float)
            if A.ndim != 2 or A.shape[1] != self.dim:
                raise DimensionError(
                    f"polytope has dimension {A.shape[-1]}; expected {self.dim}")
            if A.shape[0] == 0:
                return True
            with np.errstate(invalid="ignore"):
                return bool(np.all(self._support_upper(A) <= b))
        raise TypeError(f"contained_in() takes a Polytope, Box or Zonotope; got "
                        f"{type(other).__name__}")

    def contains_polytope(self, P: Polytope) -> bool | None:
        """Proven inclusion ``P ⊆ Z`` of a bounded polytope in this zonotope.

        ``Z`` is the intersection of its facet slabs ``-h_Z(-a) <= a.x <= h_Z(a)`` over the
        exact facet normals ``a`` (each enclosed by an interval ``[Nlo, Nhi]``). For each
        facet, ``h_P(a) <= h_P(m) + sum_j max|a_j - m_j| max(|lo_j|, |hi_j|)`` with ``m`` a
        float direction inside the interval, ``h_P(m)`` the rigorous LP-dual upper bound of
        :meth:`Polytope._support_upper` and ``[lo, hi]`` a rigorous bounding box of P; the
        sum is evaluated in exact rational arithmetic and compared with the lower bound of
        ``h_Z(a)``. No floating-point vertex or inverse enters the decision.

        Parameters
        ----------
        P : Polytope
            Of the zonotope's dimension.

        Returns
        -------
        bool or None
            True: ``P ⊆ Z`` is proven. None: not proven (the zonotope is flat or has too
            many facets, P is unbounded or an LP failed, or the bounds are too loose);
            the inclusion may still hold. False is never returned.
        """
        from fractions import Fraction

        if not isinstance(P, Polytope):
            raise TypeError(f"contains_polytope() takes a Polytope; got {type(P).__name__}")
        if P.dim != self.dim:
            raise DimensionError(f"P has dimension {P.dim}; expected {self.dim}")
        if not self._full_rank:
            return None
        data = self._facet_data()
        if data is None:
            return None
        n = self.dim
        Nlo, Nhi = data["Nlo"], data["Nhi"]
        M = 0.5 * Nlo + 0.5 * Nhi
        M = np.where((M >= Nlo) & (M <= Nhi), M, Nlo)
        E = np.vstack([np.eye(n), -np.eye(n)])
        try:
            h = P._support_upper(np.vstack([E, M, -M]))
        except Exception:  # an LP the solver could not take: not proven
            return None
        if not (np.isfinite(h).all() and np.isfinite(data["hp_lo"]).all()
                and np.isfinite(data["hm_lo"]).all() and np.isfinite(M).all()):
            return None
        hi, lo = h[:n], -h[n:2 * n]
        F = M.shape[0]
        hp, hm = h[2 * n:2 * n + F], h[2 * n + F:]
        ext = [max(abs(Fraction(float(a))), abs(Fraction(float(b))))
               for a, b in zip(lo, hi, strict=True)]
        for f in range(F):
            r = sum((max(abs(Fraction(float(Nlo[f, j])) - Fraction(float(M[f, j]))),
                         abs(Fraction(float(Nhi[f, j])) - Fraction(float(M[f, j]))))
                     * ext[j] for j in range(n)), Fraction(0))
            if Fraction(float(hp[f])) + r > Fraction(float(data["hp_lo"][f])):
                return None
            if Fraction(float(hm[f])) + r > Fraction(float(data["hm_lo"][f])):
                return None
        return True

    # --------------------------------------------------------------- bisection
    def bisect(self, index: int | None = None, cover: bool = True
               ) -> tuple[Zonotope, Zonotope]:
        r"""Bisect along one generator (thesis Thm 4.1).

        Parameters
        ----------
        index : int, optional
            Generator to split. Default: ``k`` of (4.13), the first generator holding the
            largest ``|h_ij|`` (4.12).
        cover : bool
            True (default): when the new centres ``p ∓ h_k/2`` (or ``h_k/2``) are not exact
            floats, each half receives one more generator holding the exact rounding error,
            so that ``LZ ∪ RZ ⊇ Z`` holds exactly; no generator is added when they are
            exact. False: the plain floating-point halves with the same number of
            generators; their union may then miss points of ``Z`` near the split (e.g.
            ``Zonotope([1e16], [[3.0]])``, whose centres ``1e16 ∓ 1.5`` round).

        Returns
        -------
        (Zonotope, Zonotope)
            ``LZ = (p - h_k/2) ⊕ [h_1 ... h_k/2 ... h_m] B^m`` and
            ``RZ = (p + h_k/2) ⊕ [h_1 ... h_k/2 ... h_m] B^m`` with ``LZ ∪ RZ ⊇ Z`` (equal up
            to the rounding-error generators). The halves overlap when the generators are
            linearly dependent (Fig 4.4); for independent generators they share only a facet
            (Thm 4.2, Fig 4.5; see :meth:`bisect_complete`).
        """
        G = self._G
        m = G.shape[1]
        if m == 0:
            raise ValueError("a zonotope without generators (a point) cannot be bisected")
        k = None
        if index is not None:
            k = int(index)
            if not -m <= k < m:
                raise IndexError(f"index {index} out of range for {m} generators")
            k = np.array([k % m])
        H2, centres, errors, extra = zn.halve_generator(self._c[None], G[None], k)
        H2, extra = H2[0], extra[0]
        if not cover:
            return Zonotope(centres[0][0], H2), Zonotope(centres[1][0], H2)
        out = []
        for cc, err in zip(centres, errors, strict=True):
            cols = [H2] + [v[:, None] for v in (err[0], extra) if np.any(v != 0)]
            out.append(Zonotope(cc[0], np.hstack(cols)))
        return out[0], out[1]

    def bisect_complete(self, method: str = "svd", cover: bool = True
                        ) -> tuple[Zonotope, Zonotope]:
        """Complete bisection (thesis Thm 4.2): halves that share only a facet.

        Parameters
        ----------
        method : str
            Parallelotope bounding used when the generators are not ``n`` linearly
            independent vectors (see :meth:`reduce_to_parallelotope`).
        cover : bool
            See :meth:`bisect`.

        Returns
        -------
        (Zonotope, Zonotope)
            The Thm 4.1 halves of the zonotope itself when it is a parallelotope, else of
            its bounding parallelotope (§4.2.5); their union contains the zonotope.
        """
        P = self if self.is_parallelotope() else self.reduce_to_parallelotope(method)
        return P.bisect(cover=cover)

    def is_parallelotope(self) -> bool:
        """True when there are exactly n generators, proven linearly independent."""
        return self.n_generators == self.dim and self._Gnz.shape[1] == self.dim and \
            self._full_rank

    # ----------------------------------------------------------------- bounding
    def reduce_to_parallelotope(self, method: str = "svd") -> Zonotope:
        """Outer bound by a parallelotope (n linearly independent generators), §4.2.5.

        Parameters
        ----------
        method : {"svd", "pca", "norm", "volume", "box"}
            Directions ``T`` of the parallelotope:

            * ``"svd"`` (alias ``"pca"``): left singular vectors of ``H`` (the thesis'
              suggestion in §4.2.5; the principal axes of the generators);
            * ``"norm"``: the n longest generators that are linearly independent (greedy);
            * ``"volume"``: among all n-subsets of generators (at most 5000, else the
              candidates of the other methods) and the SVD/box directions, the one of
              least volume;
            * ``"box"``: the coordinate axes (the interval hull).

        Returns
        -------
        Zonotope
            ``p ⊕ T diag(s) B^n`` with ``s_i = sum_j |(T^{-1} H)_ij|``, the support of the
            zonotope in the direction of row ``i`` of ``T^{-1}`` (the smallest scaling with
            these directions). ``T^{-1} H`` is enclosed by a verified solve and the
            containment of the zonotope in the returned parallelotope is verified the same
            way before returning.

        Raises
        ------
        ValueError
            Unknown method.
        SolverError
            The containment could not be verified (ill-conditioned directions).
        """
        meth = str(method).lower()
        if meth not in _PARALLELOTOPE_METHODS:
            raise ValueError(f"Unknown method '{method}'; valid: "
                             f"{', '.join(_PARALLELOTOPE_METHODS)}")
        G = self._Gnz
        n = self.dim
        if meth in ("svd", "pca"):
            T = _svd_directions(G, n)
        elif meth == "norm":
            T = _norm_directions(G, n)
        elif meth == "box":
            T = np.eye(n)
        else:
            T = self._volume_directions()
        return Zonotope(self._c, _outer_parallelotope(T, G))

    def _volume_directions(self) -> np.ndarray:
        G = self._Gnz
        n, m = G.shape
        cands = [_svd_directions(G, n), _norm_directions(G, n), np.eye(n)]
        if m >= n and comb(m, n) <= 5000:
            cands += [G[:, list(S)] for S in itertools.combinations(range(m), n)]
        best, best_vol = cands[0], np.inf
        for T in cands:
            with np.errstate(all="ignore"):
                if np.linalg.cond(T) > 1e10:
                    continue
                s = np.abs(np.linalg.solve(T, G)).sum(axis=1)
                s = np.maximum(s, 1e-300)
                vol = abs(np.linalg.det(T)) * np.prod(s)
            if vol < best_vol:
                best, best_vol = T, vol
        return best

    def reduce_order(self, order: float, method: str = "girard") -> Zonotope:
        """Outer bound with at most ``floor(order * n)`` generators.

        Parameters
        ----------
        order : float
            Largest admitted order ``m / n`` (at least 1).
        method : {"girard"}
            Keep the ``floor(order n) - n`` generators of largest ``||h||_1 - ||h||_inf``
            and replace the others by the box ``diag(sum_j |h_ij|)`` (sums rounded
            upward), which contains their zonotope.

        Returns
        -------
        Zonotope
            ``self`` when it already has few enough generators.
        """
        if str(method).lower() != "girard":
            raise ValueError(f"Unknown method '{method}'; valid: girard")
        order = float(order)
        if not order >= 1.0:
            raise ValueError(f"order must be at least 1; got {order}")
        G = self._Gnz
        n, m = G.shape
        cap = int(np.floor(order * n))
        if m <= cap:
            return self if m == self.n_generators else Zonotope(self._c, G)
        keep_n = cap - n
        score = np.abs(G).sum(axis=0) - np.abs(G).max(axis=0)
        idx = np.argsort(-score, kind="stable")
        keep, rest = np.sort(idx[:keep_n]), idx[keep_n:]
        d = zn.sum_up(np.abs(G[:, rest]), axis=1)
        D = np.diag(d)[:, d > 0]
        return Zonotope(self._c, np.hstack([G[:, keep], D]))

    # -------------------------------------------------------------- operations
    def volume(self) -> float:
        """Volume (area in 2-D): ``2^n sum_{|S| = n} |det H_S|`` (floating point)."""
        G = self._Gnz
        n, m = G.shape
        if m < n:
            return 0.0
        if n == 2:
            cr = np.abs(np.outer(G[0], G[1]) - np.outer(G[1], G[0]))
            return float(4.0 * np.triu(cr, 1).sum())
        if comb(m, n) > 200000:
            raise UnsupportedOperationError(
                f"volume(): {comb(m, n)} generator subsets; reduce the order first")
        S = np.array(list(itertools.combinations(range(m), n)))
        dets = np.linalg.det(np.transpose(G[:, S], (1, 0, 2)))
        return float(2.0 ** n * np.abs(dets).sum())

    def linear_map(self, A: Any) -> Zonotope:
        """Image ``A p ⊕ A H B^m`` evaluated in floating point (not an enclosure).

        Parameters
        ----------
        A : array_like, shape (k, n)

        Returns
        -------
        Zonotope
            For a rounding-proof image use ``kuhn_inclusion(A, A, Z)``.
        """
        A = np.asarray(A, dtype=float)
        if A.ndim != 2 or A.shape[1] != self.dim:
            raise DimensionError(f"A must have shape (k, {self.dim}); got {A.shape}")
        return Zonotope(A @ self._c, A @ self._G)

    def minkowski_sum(self, other: Zonotope | Any) -> Zonotope:
        """Minkowski sum with a zonotope, a box or a vector (exact).

        Parameters
        ----------
        other : Zonotope, Box or array_like, shape (n,)

        Returns
        -------
        Zonotope
            Generators concatenated; when the sum of the centres is not an exact float its
            error becomes one more generator, so the result contains the exact sum.
        """
        if isinstance(other, Box):
            other = Zonotope.from_box(other)
        if isinstance(other, Zonotope):
            oc, oG = other.center, other.generators
        else:
            oc = _as_center(other)
            oG = np.zeros((oc.size, 0))
        if oc.size != self.dim:
            raise DimensionError(f"other has dimension {oc.size}; expected {self.dim}")
        c = self._c + oc
        err = zn.two_sum_error(self._c, oc)
        cols = [self._G, oG] + ([err[:, None]] if np.any(err != 0) else [])
        return Zonotope(c, np.hstack(cols))

    __array_ufunc__ = None  # ``ndarray + Zonotope`` dispatches to __radd__

    def __add__(self, other: Any) -> Zonotope:
        return self.minkowski_sum(other)

    __radd__ = __add__

    # ------------------------------------------------------------- persistence
    def _state(self) -> dict[str, Any]:
        return {"center": np.array(self._c), "generators": np.array(self._G)}

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> Zonotope:
        c = np.asarray(state["center"], dtype=float)
        G = np.asarray(state["generators"], dtype=float).reshape(c.size, -1)
        return cls(c, G)

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, Zonotope) and np.array_equal(self._c, other._c)
                and np.array_equal(self._G, other._G))

    def __hash__(self) -> int:
        return hash((self._c.tobytes(), self._G.tobytes(), self._G.shape))

    def __repr__(self) -> str:
        return f"Zonotope(dim={self.dim}, generators={self.n_generators})"


# ------------------------------------------------------------------------ 2-D and misc
def _vertex_signs_2d(G: np.ndarray) -> np.ndarray:
    """Sign vectors of the vertices of a 2-D zonotope (nonzero generators G (2, m)), in
    counter-clockwise order: generators turned into the upper half-plane and sorted by angle;
    from the lowest vertex each one is switched from -1 to +1 in turn, then back."""
    flip = np.where((G[1] < 0) | ((G[1] == 0) & (G[0] < 0)), -1, 1).astype(np.int8)
    H = G * flip
    ang = np.arctan2(H[1], H[0])
    order = np.argsort(ang, kind="stable")
    # groups of exactly parallel generators switch together (no collinear vertices)
    groups: list[list[int]] = []
    for pos, j in enumerate(order):
        if pos and ang[j] == ang[order[pos - 1]] and \
                H[0, j] * H[1, order[pos - 1]] - H[1, j] * H[0, order[pos - 1]] == 0.0:
            groups[-1].append(int(j))
        else:
            groups.append([int(j)])
    s = -np.ones(G.shape[1], dtype=np.int8)
    rows = []
    for value in (1, -1):
        for grp in groups:
            rows.append(s.copy())
            s[grp] = value
    return np.array(rows) * flip


def _svd_directions(G: np.ndarray, n: int) -> np.ndarray:
    if G.shape[1] == 0:
        return np.eye(n)
    return np.linalg.svd(G)[0]


def _norm_directions(G: np.ndarray, n: int) -> np.ndarray:
    """n longest generators that are linearly independent, completed by SVD directions."""
    idx = np.argsort(-np.linalg.norm(G, axis=0), kind="stable")
    chosen: list[np.ndarray] = []
    for j in idx:
        cand = chosen + [G[:, j]]
        M = np.array(cand).T
        s = np.linalg.svd(M, compute_uv=False)
        if s[-1] > 1e-8 * s[0]:
            chosen = cand
        if len(chosen) == n:
            break
    if len(chosen) < n:  # complete with an orthonormal basis of the complement
        M = np.array(chosen).T if chosen else np.zeros((n, 0))
        U = np.linalg.svd(M)[0] if chosen else np.eye(n)
        scale = np.linalg.norm(M, axis=0).max() if chosen else 1.0
        chosen += [U[:, k] * scale for k in range(len(chosen), n)]
    return np.array(chosen).T


def _outer_parallelotope(T: np.ndarray, G: np.ndarray, points: bool = False) -> np.ndarray:
    """Generators ``T'`` (n, n) of a parallelotope ``p ⊕ T' B^n`` proven to contain a set.

    The set is ``p ⊕ G B^m`` or, with ``points=True``, the points ``p + d_k + e_k`` where
    ``G = [d_1 ... d_N, e_1 ... e_N]``. The scaling is ``s_i = sum_j |(T^{-1} G)_ij|``
    (resp. ``max_k |(T^{-1}(d_k + e_k))_i|``) from a verified solve; ``T' = T diag(s)`` is
    then checked by a second verified solve, inflating ``s`` until the check holds.
    """
    n = T.shape[0]

    def needed(M: np.ndarray) -> np.ndarray | None:
        X, E, ok = zn.verified_solve(M[None], G[None])
        if not ok[0]:
            return None
        mag = zn.add_up(np.abs(X[0]), E[0])  # (n, columns) upper bounds of |M^{-1} G|
        if not points:
            return zn.sum_up(mag, axis=1)
        N = mag.shape[1] // 2
        per_point = zn.add_up(mag[:, :N], mag[:, N:])
        return per_point.max(axis=1) if N else np.zeros(n)

    s = needed(T)
    if s is None:
        raise SolverError("parallelotope directions are (numerically) singular")
    floor = max(float(s.max()) * 2.0 ** -30, 1e-300)
    s = np.maximum(s, floor)  # flat directions get a tiny thickness: full rank
    # a relative margin of 2^-40 keeps the set off the facets by far more than the
    # rounding of later support-function tests, so containment stays provable
    s = zn.mul_up(s, 1.0 + 2.0 ** -40)
    for attempt in range(8):
        Tp = T * s[None, :]
        check = needed(Tp)
        if check is not None and np.all(check <= 1.0):
            return Tp
        s = zn.mul_up(s, 1.0 + 2.0 ** (-46 + 4 * attempt))
    raise SolverError("could not verify the parallelotope bound (ill-conditioned "
                      f"directions, cond = {np.linalg.cond(T):.3g}; n = {n})")


# ----------------------------------------------------------------------- inclusions
def zonotope_inclusion(center: Any, Mlo: Any, Mhi: Any) -> Zonotope:
    r"""Kühn's zonotope inclusion ``◇(p ⊕ M B^m)`` of an interval-matrix family (Thm 4.3).

    Parameters
    ----------
    center : array_like, shape (n,)
        The point ``p``.
    Mlo, Mhi : array_like, shape (n, m)
        Bounds of the interval matrix ``M``.

    Returns
    -------
    Zonotope
        ``p ⊕ [Mid(M)  G] B^{m+n}`` with ``G`` diagonal, ``G_ii = sum_j Diam(M_ij) / 2``
        ((4.14)-(4.15)); it contains ``p + M z`` for every ``M in [M]`` and
        ``z in B^m``. Mid and radius are rounded so that ``[M] ⊆ Mid ± Rad`` exactly and
        the sums are rounded upward.

    Examples
    --------
    >>> import casadi_cmpc as cm
    >>> Z = cm.zonotope_inclusion([0.0, 0.0], [[0.9, 0.0], [0.0, 1.0]], [[1.1, 0.0], [0.0, 1.0]])
    >>> Z.generators
    array([[1. , 0. , 0.1],
           [0. , 1. , 0. ]])
    """
    lo, hi = _interval_matrix(Mlo, Mhi, "M")
    p = _as_center(center)
    if lo.shape[0] != p.size:
        raise DimensionError(f"M must have {p.size} rows (the length of center); got "
                             f"{lo.shape[0]}")
    return _family_to_zonotope(p, p, lo, hi)


def kuhn_inclusion(Mlo: Any, Mhi: Any, Z: Zonotope) -> Zonotope:
    r"""Zonotope containing ``{M x : M in [Mlo, Mhi], x in Z}`` (Kühn's inclusion, Thm 4.3).

    Parameters
    ----------
    Mlo, Mhi : array_like, shape (k, n)
        Bounds of the interval matrix ``M``.
    Z : Zonotope
        ``p ⊕ H B^m`` of dimension n.

    Returns
    -------
    Zonotope
        With ``[q] ⊇ M p`` and ``[S] ⊇ M H`` computed in outward-rounded interval
        arithmetic: ``Mid[q] ⊕ Mid[S] B^m ⊕ diag(Rad[q] + sum_j Rad[S]_ij) B^k``, i.e. the
        zonotope inclusion (4.14)-(4.15) of the family ``[q] ⊕ [S] B^m``. A point matrix
        (``Mlo == Mhi``) gives a rounding-proof linear image.
    """
    if not isinstance(Z, Zonotope):
        raise TypeError(f"Z must be a Zonotope; got {type(Z).__name__}")
    lo, hi = _interval_matrix(Mlo, Mhi, "M")
    if lo.shape[1] != Z.dim:
        raise DimensionError(f"M must have {Z.dim} columns (the dimension of Z); got "
                             f"{lo.shape[1]}")
    c = Z.center[:, None]
    qlo, qhi = zn.imatmul(lo, hi, c, c)
    G = Z.generators
    Slo, Shi = zn.imatmul(lo, hi, G, G)
    return _family_to_zonotope(qlo[:, 0], qhi[:, 0], Slo, Shi)


def evolve(model: Any, Z: Zonotope, u: Any = None, W: Any = None,
           max_order: float | None = None, inclusion: str = "natural") -> Zonotope:
    r"""One step of uncertain evolution: a zonotope containing ``f(Z, u, W)`` (Thm 4.4).

    Parameters
    ----------
    model : Model
        The system ``x+ = f(x, u, w)``.
    Z : Zonotope
        ``p ⊕ H B^m`` of dimension ``model.n``.
    u : array_like, shape (m,), or Box / array_like, shape (m, 2), optional
        A fixed control value or a box of controls (omit when ``model.m == 0``).
    W : Box or array_like, shape (l, 2), optional
        Disturbance box; defaults to ``model.W``.
    max_order : float, optional
        When given, the result is reduced to at most ``floor(max_order n)`` generators
        (:meth:`Zonotope.reduce_order`).
    inclusion : {"natural", "centered"}
        Inclusion function used for ``f(p, U, W)``.

    Returns
    -------
    Zonotope
        ``q ⊕ S B^n ⊕ ◇(M B^m)`` with ``q ⊕ S B^n ⊇ f(p, U, W)`` (``S`` diagonal, from the
        interval enclosure of ``f(p, U, W)``) and ``M = ∇_x f(□Z, U, W) H`` (interval
        Jacobian over the bounding box ``□Z`` of ``Z``, times ``H``), i.e. the mean-value
        form (4.16) bounded by Kühn's inclusion (4.14)-(4.15). Every interval operation is
        rounded outward, so ``f(x, u, w)`` lies inside for all ``x in Z``, ``u in U`` and
        ``w in W``. A row ``i`` for which the mean-value form is not valid on ``□Z`` (``f_i``
        may jump there: floor, sign, comparisons, if_else, fmod, a pole ...; see
        :meth:`Model.jacobian_inclusion`) or whose Jacobian is unbounded is the natural
        interval enclosure of ``f_i(□Z, U, W)`` instead (zero generator entries plus its own
        box generator).

    Raises
    ------
    DimensionError
        ``Z`` or ``u`` has the wrong dimension.
    ModelError
        ``u`` is missing for a model with inputs.
    UnboundedSetError
        A row has neither a bounded mean-value enclosure nor a bounded interval hull (e.g.
        a division by an interval containing 0).
    """
    if not isinstance(Z, Zonotope):
        raise TypeError(f"Z must be a Zonotope; got {type(Z).__name__}")
    n, m = model.n, model.m
    if Z.dim != n:
        raise DimensionError(f"Z has dimension {Z.dim}; the model has n = {n} states")
    Ub = _control_box(u, m)
    Wb = None
    if W is not None:
        if model.l == 0:
            raise ModelError(f"model '{model.name}' has no disturbance; do not pass W")
        Wb = as_boxes(W, model.l, "W")
    c = Z.center
    P = np.stack([c, c], axis=-1)[None]
    Xb = Z.bounding_box().as_array()[None]
    fp = model.inclusion(inclusion)(P, Ub, Wb)[0]  # (n, 2)
    J = model.jacobian_inclusion("x")(Xb, Ub, Wb)[0]  # (n, n, 2)
    G = Z.generators
    mvt = np.isfinite(fp).all(axis=1) & np.isfinite(J).all(axis=(1, 2))  # (n,)
    if not mvt.all():
        # rows that may jump on the bounding box of Z (or whose Jacobian is unbounded):
        # their interval hull, as independent box generators
        hull = model.inclusion("natural")(Xb, Ub, Wb)[0]  # (n, 2)
        if not np.isfinite(hull[~mvt]).all():
            raise UnboundedSetError(
                "evolve(): the interval enclosure of f over the bounding box of Z is "
                f"unbounded in rows {np.flatnonzero(~mvt).tolist()} (where the mean-value "
                "form is not available either); use a smaller zonotope")
        fp = np.where(mvt[:, None], fp, hull)
        J = np.where(mvt[:, None, None], J, 0.0)
    Mlo, Mhi = zn.imatmul(J[..., 0], J[..., 1], G, G)
    out = _family_to_zonotope(fp[:, 0], fp[:, 1], Mlo, Mhi)
    if max_order is not None:
        out = out.reduce_order(max_order)
    return out


def _control_box(u: Any, m: int) -> np.ndarray:
    if u is None:
        if m > 0:
            raise ModelError(f"u is required (the model has m = {m} inputs)")
        return np.zeros((1, 0, 2))
    if isinstance(u, Box):
        return as_boxes(u, m, "u")
    arr = np.asarray(u, dtype=float)
    if arr.ndim == 2 and arr.shape == (m, 2):
        return as_boxes(arr, m, "u")
    pt = np.atleast_1d(arr)
    if pt.ndim != 1 or pt.size != m:
        raise DimensionError(
            f"u must be a control value of shape ({m},) or a box of shape ({m}, 2); got "
            f"shape {arr.shape}")
    if np.isnan(pt).any():
        raise InvalidBoundsError("u contains NaN")
    return np.stack([pt, pt], axis=-1)[None]


# the reachable sets over a control sequence (Def 6.2) build on the evolution above
from ._reach import reach  # noqa: E402
