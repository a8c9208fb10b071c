r"""Set inversion via zonotope geometry (SIVZG, thesis §4.2.5, Alg 4.3).

The paving elements are zonotopes instead of boxes. A batch of zonotopes with a common
number of generators is a :class:`ZonotopeFrontier`; it implements the frontier protocol of
:func:`~casadi_cmpc.solvers.engine.branch_and_bound` (``take``, ``width``, ``bisect`` by
Thm 4.1, ``concat``), so Alg 4.3 is the engine with a zonotope classifier
(:func:`zonotope_classifier`):

* the image ``f(Z)`` of every zonotope ``Z = c ⊕ H B^p`` of the frontier is enclosed by the
  mean-value form with an interval Jacobian over the bounding box of ``Z``, bounded by Kühn's
  zonotope inclusion (thesis (4.14)-(4.16), Thm 4.4);
* ``Z`` is INNER when the enclosure is proven inside the target ``Y`` (support functions of
  the enclosure against the rows of a polytope, or against lower bounds of the supports of
  a zonotope target in its exact facet normals), OUTER when it is proven disjoint from ``Y``
  (a separating inequality implied by the rows of ``Y``, or a separating direction of two
  zonotopes), else UNDECIDED; undecided
  zonotopes whose largest ``|h_ij|`` (4.12) is at most ``eps`` are kept as boundary, the
  others bisected along the generator holding it (4.13).

:func:`inner_zonotopes` is the special case ``f = identity`` of Fig 4.8: a polytope is
approximated from inside by a union of zonotopes, starting from a parallelotope bounding it.

Rounding
--------
Each element of a frontier is ``c ⊕ H B^p ⊕ [-r, r]``: besides its generators it carries a
box of radii ``r`` (usually zero or a few ulps) that absorbs the rounding errors of the
bisection, so that the two halves provably cover their parent, and every enclosure below
is computed with outward rounding. INNER is therefore a proof for every point of the
zonotope (box included); OUTER is a proof that no point of it is in the solution set.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from math import comb
from typing import Any

import casadi as ca
import numpy as np

from ..exceptions import (
    CmpcError,
    CmpcWarning,
    DimensionError,
    EmptySetError,
    InvalidBoundsError,
    ModelError,
    UnboundedSetError,
)
from ..interval import arith as ia
from ..interval._derivative import JacobianInclusion
from ..interval.compiler import InclusionFunction, _discontinuous_ops
from ..model import Model
from ..sets import _zono_num as zn
from ..sets.base import HoldsSetMeta, SetBase
from ..sets.box import Box
from ..sets.paving import _outside_keyword, _warn_outer
from ..sets.polytope import Polytope, PolytopeUnion
from ..sets.zonotope import Zonotope
from ._common import inclusion_of, split_inclusion
from .engine import INNER, OUTER, branch_and_bound
from .result import SetResult

__all__ = ["ZonotopeFrontier", "ZonotopePaving", "zonotope_classifier", "zonotope_sivia",
           "inner_zonotopes"]

#: Largest number of (n-1)-subsets of generators used as separating directions (n >= 3).
MAX_NORMAL_SUBSETS = 64


# ----------------------------------------------------------------------------- helpers
def _two_sum_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact ``(a + b) - fl(a + b)`` (Knuth's TwoSum; finite operands)."""
    s = a + b
    z = s - a
    return (a - (s - z)) + (b - z)


def _spread_up(G: np.ndarray, R: np.ndarray, Dlo: np.ndarray, Dhi: np.ndarray) -> np.ndarray:
    """Upper bound of ``sum_j |d.g_j| + sum_i |d_i| r_i`` over all ``d`` in ``[Dlo, Dhi]``.

    ``G`` (N, n, p), ``R`` (N, n); ``D`` of shape (k, n) (common) or (N, k, n) -> (N, k).
    """
    N = G.shape[0]
    k = Dlo.shape[-2]
    if G.shape[2]:
        glo, ghi = zn.imatmul(Dlo, Dhi, G, G)  # (N, k, p)
        s = zn.sum_up(np.maximum(np.abs(glo), np.abs(ghi)), axis=-1)
    else:
        s = np.zeros((N, k))
    if np.any(R):
        mag = np.maximum(np.abs(Dlo), np.abs(Dhi))  # (k, n) or (N, k, n)
        s = zn.add_up(s, zn.sum_up(zn.mul_up(mag, R[:, None, :]), axis=-1))
    return np.broadcast_to(s, (N, k))


def _dot_center(C: np.ndarray, Dlo: np.ndarray, Dhi: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``d.c`` for ``d`` in ``[D]``: (N, k) lower and upper bounds."""
    c = C[:, :, None]
    lo, hi = zn.imatmul(Dlo, Dhi, c, c)  # (N, k, 1)
    return lo[..., 0], hi[..., 0]


def _facet_directions(G: np.ndarray) -> np.ndarray:
    """Normals of the spans of (n-1)-subsets of generators and the axes, (N, D, n).

    In 2-D these are the rotated generators ``(-g_2, g_1)`` (exact); in n-D the generalised
    cross products (cofactors) of at most :data:`MAX_NORMAL_SUBSETS` subsets. Zero normals
    (dependent subsets, zero generators) are harmless: they separate nothing.
    """
    N, n, p = G.shape
    dirs = [np.broadcast_to(np.eye(n), (N, n, n))]
    if n == 2 and p:
        dirs.append(np.stack([-G[:, 1, :], G[:, 0, :]], axis=-1))  # (N, p, 2)
    elif n >= 3 and p >= n - 1 and comb(p, n - 1) <= MAX_NORMAL_SUBSETS:
        normals = []
        for S in itertools.combinations(range(p), n - 1):
            M = G[:, :, list(S)]  # (N, n, n-1)
            cof = []
            for i in range(n):
                minor = np.delete(M, i, axis=1)
                cof.append((-1.0) ** i * np.linalg.det(minor))
            normals.append(np.stack(cof, axis=-1))
        dirs.append(np.stack(normals, axis=1))
    return np.concatenate(dirs, axis=1)


# ----------------------------------------------------------------------------- frontier
@dataclass
class ZonotopeFrontier:
    r"""A batch of zonotopes ``c_i ⊕ H_i B^p ⊕ [-r_i, r_i]`` with a common ``p``.

    Parameters
    ----------
    centers : ndarray, shape (N, n)
        The centres ``c_i``.
    generators : ndarray, shape (N, n, p)
        The generator matrices ``H_i`` (columns are generators).
    radii : ndarray, shape (N, n), optional
        Radii ``r_i >= 0`` of an axis-aligned box added to each zonotope (the accumulated
        rounding errors of the bisection; zero by default). It never counts in
        :meth:`width` and is never split.

    Notes
    -----
    Implements the frontier protocol of :func:`~casadi_cmpc.solvers.engine.branch_and_bound`:
    ``len``, :meth:`take`, :meth:`width` (Max(H) of (4.12)), :meth:`bisect` (Thm 4.1 on every
    element at once) and :meth:`concat`. Iterating yields :class:`~casadi_cmpc.Zonotope`
    objects (the box, when non-zero, as extra axis-aligned generators).

    Examples
    --------
    >>> import numpy as np, casadi_cmpc as cm
    >>> from casadi_cmpc.solvers.zonotope_sivia import ZonotopeFrontier
    >>> fr = ZonotopeFrontier.from_zonotopes([cm.Zonotope([2.0, 2.0], [[0.6414, 0.5855],
    ...                                                                [-0.4016, 0.7930]])])
    >>> halves = fr.bisect()
    >>> len(halves), halves.generators.shape
    (2, (2, 2, 2))
    >>> halves.generators[0]  # the second generator (holding Max(H) = 0.793) is halved
    array([[ 0.6414 ,  0.29275],
           [-0.4016 ,  0.3965 ]])
    """

    centers: np.ndarray
    generators: np.ndarray
    radii: np.ndarray | None = None

    def __post_init__(self) -> None:
        C = self.centers = np.asarray(self.centers, dtype=float)
        G = self.generators = np.asarray(self.generators, dtype=float)
        if C.ndim != 2 or G.ndim != 3 or G.shape[:2] != C.shape:
            raise DimensionError(
                f"centers must have shape (N, n) and generators (N, n, p); got {C.shape} "
                f"and {G.shape}")
        if self.radii is None:
            self.radii = np.zeros_like(C)
        self.radii = np.asarray(self.radii, dtype=float)
        if self.radii.shape != C.shape:
            raise DimensionError(f"radii must have shape {C.shape}; got {self.radii.shape}")

    # ------------------------------------------------------------ construction
    @classmethod
    def from_zonotopes(cls, zonotopes: Any, n_generators: int | None = None
                       ) -> ZonotopeFrontier:
        """A frontier from one zonotope, a Box, or a list of zonotopes.

        Parameters
        ----------
        zonotopes : Zonotope, Box or list of Zonotope
            Zonotopes of one dimension; fewer generators than the largest count are padded
            with zero columns.
        n_generators : int, optional
            Pad to at least this many generators.

        Returns
        -------
        ZonotopeFrontier
        """
        if isinstance(zonotopes, Box):
            zonotopes = Zonotope.from_box(zonotopes)
        if isinstance(zonotopes, Zonotope):
            zonotopes = [zonotopes]
        zs = list(zonotopes)
        for z in zs:
            if not isinstance(z, Zonotope):
                raise TypeError(f"expected Zonotope objects; got {type(z).__name__}")
        if not zs:
            raise ValueError("from_zonotopes needs at least one zonotope (the dimension "
                             "is unknown otherwise)")
        n = zs[0].dim
        if any(z.dim != n for z in zs):
            raise DimensionError(f"zonotopes of different dimensions: "
                                 f"{sorted({z.dim for z in zs})}")
        p = max(z.n_generators for z in zs)
        if n_generators is not None:
            p = max(p, int(n_generators))
        C = np.array([z.center for z in zs], dtype=float)
        G = np.zeros((len(zs), n, p))
        for i, z in enumerate(zs):
            G[i, :, :z.n_generators] = z.generators
        return cls(C, G)

    # -------------------------------------------------------------- properties
    def __len__(self) -> int:
        return int(self.centers.shape[0])

    @property
    def dim(self) -> int:
        """Ambient dimension n."""
        return int(self.centers.shape[1])

    @property
    def n_generators(self) -> int:
        """Common number p of generators (the radii box not counted)."""
        return int(self.generators.shape[2])

    def zonotope(self, i: int) -> Zonotope:
        """Element ``i`` as a :class:`~casadi_cmpc.Zonotope` (box radii as extra columns)."""
        r = self.radii[i]
        D = np.diag(r)[:, r > 0]
        return Zonotope(self.centers[i], np.hstack([self.generators[i], D]))

    def zonotopes(self) -> list[Zonotope]:
        """All elements as :class:`~casadi_cmpc.Zonotope` objects."""
        return [self.zonotope(i) for i in range(len(self))]

    def __iter__(self) -> Iterator[Zonotope]:
        return (self.zonotope(i) for i in range(len(self)))

    def __getitem__(self, i: int) -> Zonotope:
        if not -len(self) <= i < len(self):
            raise IndexError(f"index {i} out of range for {len(self)} zonotopes")
        return self.zonotope(i % len(self))

    def __repr__(self) -> str:
        return (f"ZonotopeFrontier(N={len(self)}, dim={self.dim}, "
                f"generators={self.n_generators})")

    # ---------------------------------------------------------- engine protocol
    def take(self, mask: np.ndarray) -> ZonotopeFrontier:
        """The elements selected by a boolean mask (or an index array)."""
        return ZonotopeFrontier(self.centers[mask], self.generators[mask], self.radii[mask])

    def width(self) -> np.ndarray:
        """``Max(H_i) = max_{j,k} |h_jk|`` of every element (thesis (4.12)), shape (N,)."""
        if self.n_generators == 0 or len(self) == 0:
            return np.zeros(len(self))
        return np.abs(self.generators).max(axis=(1, 2))

    def bisect(self) -> ZonotopeFrontier:
        r"""Thm 4.1 on every element: split along the first generator holding ``Max(H)``.

        Returns
        -------
        ZonotopeFrontier
            ``2N`` elements, the left halves ``(c - h_k/2) ⊕ [... h_k/2 ...] B^p`` first, then
            the right halves ``(c + h_k/2) ⊕ [... h_k/2 ...] B^p``. The generator count is
            unchanged; the exact rounding errors of the new centres (TwoSum) are added to the
            radii (rounded upward), so the union of the halves contains the parent.
        """
        C, H, r = self.centers, self.generators, self.radii
        N = len(self)
        if self.n_generators == 0:
            raise ValueError("zonotopes without generators (points) cannot be bisected")
        k = np.argmax(np.abs(H).max(axis=1), axis=1)  # (4.13): first column holding Max(H)
        rows = np.arange(N)
        h = H[rows, :, k]  # (N, n)
        half = 0.5 * h
        H2 = H.copy()
        H2[rows, :, k] = half
        extra = np.abs(h - 2.0 * half)  # nonzero only when halving a subnormal was inexact
        out_c, out_r = [], []
        for sgn in (-1.0, 1.0):
            step = sgn * half
            cc = C + step
            err = np.abs(_two_sum_error(C, step))
            rr = r
            if np.any(err):
                rr = zn.add_up(rr, err)
            if np.any(extra):
                rr = zn.add_up(rr, extra)
            out_c.append(cc)
            out_r.append(rr)
        return ZonotopeFrontier(np.concatenate(out_c), np.concatenate([H2, H2]),
                                np.concatenate(out_r))

    @staticmethod
    def concat(parts: list[ZonotopeFrontier]) -> ZonotopeFrontier:
        """One frontier from several with the same dimension and generator count."""
        if not parts:
            raise ValueError("nothing to concatenate")
        shapes = {p.generators.shape[1:] for p in parts}
        if len(shapes) != 1:
            raise DimensionError(f"frontiers with different (n, p): {sorted(shapes)}")
        return ZonotopeFrontier(np.concatenate([p.centers for p in parts]),
                                np.concatenate([p.generators for p in parts]),
                                np.concatenate([p.radii for p in parts]))

    # -------------------------------------------------------------- geometry
    def bounding_boxes(self) -> np.ndarray:
        """Interval hulls ``c ± (sum_j |h_j| + r)``, rounded outward, shape (N, n, 2)."""
        rad = zn.add_up(zn.sum_up(np.abs(self.generators), axis=-1), self.radii)
        return np.stack([zn.sub_dn(self.centers, rad), zn.add_up(self.centers, rad)], axis=-1)

    def support_bounds(self, directions: Any) -> tuple[np.ndarray, np.ndarray]:
        """Enclosure of the support functions ``h_Z(d) = d.c + sum_j |d.h_j| + |d|.r``.

        Parameters
        ----------
        directions : array_like, shape (k, n), or (N, k, n) (one set per element)

        Returns
        -------
        lo, hi : ndarray, shape (N, k)
            ``lo <= h_Z(d) <= hi`` for the exact support function of every element.
        """
        D = np.asarray(directions, dtype=float)
        if D.ndim not in (2, 3) or D.shape[-1] != self.dim:
            raise DimensionError(f"directions must have shape (k, {self.dim}) or "
                                 f"(N, k, {self.dim}); got {D.shape}")
        dlo, dhi = _dot_center(self.centers, D, D)
        s = _spread_up(self.generators, self.radii, D, D)
        # lower bound of the spread: the smallest magnitudes (mignitudes), rounded down
        glo, ghi = zn.imatmul(D, D, self.generators, self.generators)  # (N, k, p)
        mig = np.where(glo > 0, glo, np.where(ghi < 0, -ghi, 0.0))
        t = zn.sum_dn(mig, axis=-1) if mig.shape[-1] else np.zeros(dlo.shape)
        if np.any(self.radii):
            absd = np.abs(D)
            prod = absd * self.radii[:, None, :]
            t = zn.add_dn(t, zn.sum_dn(ia.dnm(prod) * (prod > 0), axis=-1))
        return zn.add_dn(dlo, np.maximum(t, 0.0)), zn.add_up(dhi, s)

    def sample(self, k: int, rng: Any = None) -> np.ndarray:
        """``k`` random points of every element (uniform generator weights), (N, k, n)."""
        rng = np.random.default_rng(rng)
        N, n, p = self.generators.shape
        a = rng.uniform(-1.0, 1.0, (N, k, p))
        b = rng.uniform(-1.0, 1.0, (N, k, n))
        return (self.centers[:, None, :] + np.einsum("nkp,nip->nki", a, self.generators)
                + b * self.radii[:, None, :])

    def _full_generators(self) -> np.ndarray:
        """Generators with the radii box appended as axis-aligned columns, (N, n, p + n)."""
        if not np.any(self.radii):
            return self.generators
        D = self.radii[:, :, None] * np.eye(self.dim)[None]
        return np.concatenate([self.generators, D], axis=2)

    def volumes(self) -> np.ndarray:
        """Volume (area in 2-D) of every element, shape (N,) (floating point).

        ``2^n sum_{|S| = n} |det G_S|`` over the generators and the radii box; batched in
        2-D, element by element otherwise.
        """
        if self.dim == 2:
            G = self._full_generators()
            cr = np.abs(G[:, 0, :, None] * G[:, 1, None, :] - G[:, 1, :, None] * G[:, 0, None, :])
            return 4.0 * np.triu(cr, 1).sum(axis=(1, 2)) if G.shape[2] else np.zeros(len(self))
        if self.dim == 1:
            return 2.0 * (np.abs(self.generators).sum(axis=(1, 2)) + self.radii[:, 0])
        return np.array([z.volume() for z in self])

    def polygons(self, dims: tuple[int, int] = (0, 1)) -> np.ndarray:
        """Boundary polygons of the projections on ``dims``, shape (N, 2q, 2), in order.

        ``q`` is the number of generators (radii box included); the generators are turned
        into the upper half plane and sorted by angle, and the lower chain starts at
        ``c - sum_j |g_j|`` (zero generators give repeated vertices).
        """
        if self.dim < 2:
            raise DimensionError("polygons() needs a dimension of at least 2")
        i, j = dims
        G = self._full_generators()[:, [i, j], :]  # (N, 2, q)
        c = self.centers[:, [i, j]]
        flip = np.where((G[:, 1] < 0) | ((G[:, 1] == 0) & (G[:, 0] < 0)), -1.0, 1.0)
        Gu = G * flip[:, None, :]
        ang = np.arctan2(Gu[:, 1], Gu[:, 0])
        order = np.argsort(ang, axis=1, kind="stable")
        Gs = np.take_along_axis(Gu, order[:, None, :], axis=2)  # (N, 2, q)
        start = c - Gs.sum(axis=2)
        steps = np.concatenate([2.0 * Gs, -2.0 * Gs], axis=2)  # (N, 2, 2q)
        V = start[:, :, None] + np.concatenate(
            [np.zeros((len(self), 2, 1)), np.cumsum(steps, axis=2)[:, :, :-1]], axis=2)
        return np.transpose(V, (0, 2, 1))

    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), **kw: Any) -> Any:
        """Draw every element as a polygon (one PolyCollection); returns the Axes.

        Defaults: ``facecolor="C0"``, ``edgecolor="k"``, ``linewidth=0.3``.
        """
        from matplotlib.collections import PolyCollection

        from ..plot import new_axes

        ax = new_axes(ax)
        if len(self) == 0:
            return ax
        polys = self.polygons(dims)
        label = kw.pop("label", None)
        kw.setdefault("facecolor", "C0")
        kw.setdefault("edgecolor", "k")
        kw.setdefault("linewidth", 0.3)
        coll = PolyCollection(list(polys), **kw)
        if label is not None:
            coll.set_label(label)
        ax.add_collection(coll)
        flat = polys.reshape(-1, 2)
        ax.update_datalim(np.array([flat.min(axis=0), flat.max(axis=0)]))
        ax.autoscale_view()
        return ax


# ----------------------------------------------------------------------------- targets
class _PolytopeTest:
    """Proofs of ``Z ⊆ {A x <= b}`` and ``Z ∩ {A x <= b} = ∅`` for a zonotope batch.

    Inclusion: ``h_Z(a_i) <= b_i`` for every row (exact criterion, rounded upward).
    Disjointness: a valid inequality ``(y^T A) x <= y^T b`` (``y >= 0``) of the polytope
    whose left side is proven larger on all of ``Z``: ``min_Z (y^T A) x > y^T b``, with
    ``y^T A`` enclosed in interval arithmetic so any float ``y >= 0`` gives a proof. The
    ``y`` tried are the unit vectors (the rows) and, for every facet normal ``w`` of ``Z``
    (both signs), the multipliers of the rows active at the vertex of the polytope that
    maximises ``w`` (so ``y^T A ≈ w``). In 2-D this is every candidate of the separating
    axis theorem, so a zonotope separated from the polytope by a margin larger than the
    rounding is proven disjoint.
    """

    def __init__(self, A: np.ndarray, b: np.ndarray) -> None:
        A = np.asarray(A, dtype=float)
        b = np.asarray(b, dtype=float)
        norms = np.linalg.norm(A, axis=1) if A.size else np.zeros(A.shape[0])
        self.empty = bool(np.any(b == -np.inf) or np.any((norms == 0) & (b < 0)))
        keep = np.isfinite(b) & (norms > 0)
        self.A, self.b = A[keep], b[keep]
        self.n = A.shape[1]
        self.cones: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        if not self.empty and self.A.shape[0]:
            self._build_cones()

    def _build_cones(self) -> None:
        """Per vertex: active rows (padded) and the pseudo-inverse of their normals."""
        try:
            P = Polytope(self.A, self.b)
            Pm = P.minimal()
            V = Pm.vertices()
        except (CmpcError, ValueError, RuntimeError):
            return  # unbounded, empty or numerically hard: the rows alone are used
        if len(V) == 0:
            return
        Am, bm = Pm.A, Pm.b
        nm = np.linalg.norm(Am, axis=1)
        An, bn = Am / nm[:, None], bm / nm
        scale = max(1.0, float(np.abs(bn).max(initial=0.0)), float(np.abs(V).max()))
        act = np.abs(V @ An.T - bn[None, :]) <= 1e-9 * scale  # (k_v, rows)
        kmax = max(int(act.sum(axis=1).max()), 1)
        idx = np.zeros((len(V), kmax), dtype=np.intp)
        pinv = np.zeros((len(V), kmax, self.n))
        for v in range(len(V)):
            rows = np.flatnonzero(act[v])
            if rows.size == 0:
                continue
            idx[v, :rows.size] = rows
            pinv[v, :rows.size] = np.linalg.pinv(Am[rows].T)
        self.cones = (V, idx, pinv)
        self.Am, self.bm = Am, bm

    def inside(self, C: np.ndarray, G: np.ndarray, R: np.ndarray) -> np.ndarray:
        N = C.shape[0]
        if self.empty:
            return np.zeros(N, dtype=bool)
        if self.A.shape[0] == 0:
            return np.ones(N, dtype=bool)
        _, dhi = _dot_center(C, self.A, self.A)
        up = zn.add_up(dhi, _spread_up(G, R, self.A, self.A))
        return np.all(up <= self.b[None, :], axis=1)

    def disjoint(self, C: np.ndarray, G: np.ndarray, R: np.ndarray) -> np.ndarray:
        N = C.shape[0]
        if self.empty:
            return np.ones(N, dtype=bool)
        if self.A.shape[0] == 0 or N == 0:
            return np.zeros(N, dtype=bool)
        # rows: min_Z a.x > b
        dlo, _ = _dot_center(C, self.A, self.A)
        low = zn.sub_dn(dlo, _spread_up(G, R, self.A, self.A))
        out = np.any(low > self.b[None, :], axis=1)
        if self.cones is None or out.all():
            return out
        und = np.flatnonzero(~out)
        Cu, Gu, Ru = C[und], G[und], R[und]
        W = _facet_directions(Gu)
        W = np.concatenate([W, -W], axis=1)  # (M, D, n)
        V, idx, pinv = self.cones
        iv = np.argmax(np.einsum("mdn,vn->mdv", W, V), axis=2)  # vertex maximising w
        y = np.maximum(np.einsum("mdkn,mdn->mdk", pinv[iv], W), 0.0)  # (M, D, kmax)
        rows = idx[iv]  # (M, D, kmax)
        dlo = dhi = blo = bhi = None
        for t in range(y.shape[2]):
            yt = y[..., t]
            a = self.Am[rows[..., t]]  # (M, D, n)
            pl, ph = ia.mul(yt[..., None], yt[..., None], a, a)
            ql, qh = ia.mul(yt, yt, self.bm[rows[..., t]], self.bm[rows[..., t]])
            if dlo is None:
                dlo, dhi, blo, bhi = pl, ph, ql, qh
            else:
                dlo, dhi = ia.add(dlo, dhi, pl, ph)
                blo, bhi = ia.add(blo, bhi, ql, qh)
        clo, _ = _dot_center(Cu, dlo, dhi)
        low = zn.sub_dn(clo, _spread_up(Gu, Ru, dlo, dhi))
        with np.errstate(invalid="ignore"):
            sep = np.any((low > bhi) & np.any(y > 0, axis=2), axis=1)
        out[und[sep]] = True
        return out


class _ZonotopeTest:
    """Proofs of ``Z ⊆ S`` and ``Z ∩ S = ∅`` for a zonotope batch and a zonotope target S.

    Inclusion (exact criterion for a full-dimensional S, rounded the safe way): for every
    exact facet normal ``a`` of S (both signs; enclosed in an interval vector ``[a]``),
    an upper bound of ``h_Z(a)`` over ``[a]`` is at most a *lower* bound of ``h_S(a)``
    (:meth:`~casadi_cmpc.Zonotope._facet_data`: ``hp_lo``, ``hm_lo``). S's outward-rounded
    H-representation (``S.to_polytope()``) is never used: it contains S and would prove
    inclusions in a slightly larger set. A flat S (rank < n) or one with too many facet
    candidates proves no inclusion.

    Disjointness: a direction ``d`` with ``min_Z d.x > h_S(d)``, the left side rounded down
    and the right side up. The directions tried are the facet normals of S (intervals, both
    signs), the coordinate axes and the facet normals of each element (float directions,
    both signs); in 2-D these are all the candidates of the separating axis theorem.
    """

    def __init__(self, S: Zonotope) -> None:
        self.S = S
        self.n = S.dim
        self.data = S._facet_data()
        self.c = np.asarray(S.center, dtype=float)
        G = np.asarray(S.generators, dtype=float)
        self.G = G[:, np.any(G != 0.0, axis=0)]

    def inside(self, C: np.ndarray, G: np.ndarray, R: np.ndarray) -> np.ndarray:
        N = C.shape[0]
        d = self.data
        if d is None or N == 0:
            return np.zeros(N, dtype=bool)
        ok = np.ones(N, dtype=bool)
        for Dlo, Dhi, bound in ((d["Nlo"], d["Nhi"], d["hp_lo"]),
                                (-d["Nhi"], -d["Nlo"], d["hm_lo"])):
            _, chi = _dot_center(C, Dlo, Dhi)
            up = zn.add_up(chi, _spread_up(G, R, Dlo, Dhi))  # >= h_Z(a) for all a in [a]
            with np.errstate(invalid="ignore"):
                ok &= np.all(up <= bound[None, :], axis=1)
        return ok

    def _support_S_up(self, D: np.ndarray) -> np.ndarray:
        """Upper bound of ``h_S(d)`` for float directions D of shape (N, k, n) -> (N, k)."""
        N = D.shape[0]
        C = np.broadcast_to(self.c, (N, self.n))
        G = np.broadcast_to(self.G, (N,) + self.G.shape)
        _, chi = _dot_center(C, D, D)
        return zn.add_up(chi, _spread_up(G, np.zeros((N, self.n)), D, D))

    def disjoint(self, C: np.ndarray, G: np.ndarray, R: np.ndarray) -> np.ndarray:
        N = C.shape[0]
        out = np.zeros(N, dtype=bool)
        if N == 0:
            return out
        d = self.data
        if d is not None:
            for Dlo, Dhi, bound in ((d["Nlo"], d["Nhi"], d["hp_hi"]),
                                    (-d["Nhi"], -d["Nlo"], d["hm_hi"])):
                clo, _ = _dot_center(C, Dlo, Dhi)
                low = zn.sub_dn(clo, _spread_up(G, R, Dlo, Dhi))  # <= min_Z a.x, all a
                with np.errstate(invalid="ignore"):
                    out |= np.any(low > bound[None, :], axis=1)
        und = np.flatnonzero(~out)
        if und.size == 0:
            return out
        Cu, Gu, Ru = C[und], G[und], R[und]
        W = _facet_directions(Gu)
        W = np.concatenate([W, -W], axis=1)  # (M, D, n) float directions
        clo, _ = _dot_center(Cu, W, W)
        low = zn.sub_dn(clo, _spread_up(Gu, Ru, W, W))
        with np.errstate(invalid="ignore"):
            sep = np.any(low > self._support_S_up(W), axis=1)
        out[und[sep]] = True
        return out


def _box_rows(Y: Box) -> tuple[np.ndarray, np.ndarray]:
    n = Y.dim
    eye = np.eye(n)
    A = np.vstack([eye, -eye])
    b = np.concatenate([Y.hi, -Y.lo])
    keep = np.isfinite(b)
    return A[keep], b[keep]


class _Target:
    """A target set Y: zonotope tests (polytopes, unions, boxes, zonotopes) and box tests
    (any set)."""

    def __init__(self, Y: Any, m: int, name: str = "Y") -> None:
        if isinstance(Y, Box):
            if Y.dim != m:
                raise DimensionError(f"target {name} has dimension {Y.dim}; expected {m}")
            self.members = [_PolytopeTest(*_box_rows(Y))]
            self.union = False
        elif isinstance(Y, Polytope):
            if Y.dim != m:
                raise DimensionError(f"target {name} has dimension {Y.dim}; expected {m}")
            self.members = [_PolytopeTest(Y.A, Y.b)]
            self.union = False
        elif isinstance(Y, Zonotope):
            if Y.dim != m:
                raise DimensionError(f"target {name} has dimension {Y.dim}; expected {m}")
            self.members = [_ZonotopeTest(Y)]
            self.union = False
        elif isinstance(Y, PolytopeUnion):
            if Y.dim != m:
                raise DimensionError(f"target {name} has dimension {Y.dim}; expected {m}")
            self.members = [_PolytopeTest(P.A, P.b) for P in Y]
            self.union = True
        elif isinstance(Y, SetBase):
            if Y.dim != m:
                raise DimensionError(f"target {name} has dimension {Y.dim}; expected {m}")
            self.members = []
            self.union = True
        else:
            raise TypeError(f"{name} must be a Box, Polytope, PolytopeUnion or another set; "
                            f"got {type(Y).__name__}")
        self.Y = Y

    def classify(self, C: np.ndarray, G: np.ndarray, R: np.ndarray,
                 boxes: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(proven inside, proven disjoint) for zonotopes (C, G, R) and optional boxes.

        ``boxes`` (N, n, 2) are other enclosures of the same sets: either proof counts.
        """
        N = C.shape[0]
        if self.members:
            ins = np.zeros(N, dtype=bool)
            dis = np.ones(N, dtype=bool)
            for T in self.members:
                ins |= T.inside(C, G, R)
                dis &= T.disjoint(C, G, R)
        else:
            ins = np.zeros(N, dtype=bool)
            dis = np.zeros(N, dtype=bool)
        if boxes is not None or not self.members:
            bx = boxes
            if bx is None:
                rad = zn.add_up(zn.sum_up(np.abs(G), axis=-1), R)
                bx = np.stack([zn.sub_dn(C, rad), zn.add_up(C, rad)], axis=-1)
            bi, bd = self.classify_boxes(bx)
            ins |= bi
            dis |= bd
        return ins, dis & ~ins

    def classify_boxes(self, bx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(proven inside, proven disjoint) for boxes (N, n, 2) by the set's own tests."""
        N = bx.shape[0]
        ins = np.zeros(N, dtype=bool)
        dis = np.zeros(N, dtype=bool)
        finite = np.isfinite(bx).all(axis=(1, 2))
        if finite.any():
            f = np.flatnonzero(finite)
            ins[f] = np.asarray(self.Y.contains_box(bx[f]), dtype=bool)
            dis[f] = ~np.asarray(self.Y.intersects_box(bx[f]), dtype=bool) & ~ins[f]
        return ins, dis


# ----------------------------------------------------------------------------- images
class _Image:
    """Enclosure of ``f(Z)`` (or ``f(Z, W)``) for a zonotope batch.

    Mean-value form with Kühn's inclusion (thesis (4.14)-(4.16), Thm 4.4): for ``x`` in
    ``Z = c ⊕ H B^p ⊕ [-r, r]`` and ``w`` in ``W``, row by row
    ``f_k(x, w) = f_k(c, w) + ∇_x f_k(ξ_k, w) (x - c)`` with ``ξ_k`` on the segment
    ``[c, x] ⊆ □Z`` (the bounding box). So ``f(x, w) ∈ [f(c, W)] + [J](H α + ρ)`` with
    ``[J] ⊇ ∇_x f(□Z, W)``, ``α ∈ B^p``, ``|ρ| <= r``. With ``[M] ⊇ [J] H`` (outward
    interval product) and ``Mid/Rad`` rounded so that ``[M] ⊆ Mid ± Rad``, the enclosure
    is the zonotope

    ``Mid[f(c, W)] ⊕ Mid[M] B^p ⊕ [-s, s]``,
    ``s = Rad[f(c, W)] + sum_j Rad[M]_{:j} + |[J]| r`` (sums rounded upward),

    i.e. Kühn's diagonal generator matrix G of (4.15) written as a box. The mean-value form
    of row ``k`` needs ``f_k`` continuous on ``□Z``: where an operation of ``f_k`` may jump
    on ``□Z`` (floor, sign, comparisons, if_else, fmod, a pole ...; decided per zonotope from
    interval enclosures of the operations' arguments) or its Jacobian is unbounded, row
    ``k`` is the interval enclosure of ``f_k(□Z, W)`` instead (zero generator row, its
    radius in ``s``).
    """

    def __init__(self, f: Any, n_x: int | None, W: Any, box_form: str | None) -> None:
        self.identity = f is None
        self.W = None
        if self.identity:
            if n_x is None:
                raise ValueError("the dimension of the identity map is unknown")
            self.n = self.m = n_x
            return
        given = None  # an InclusionFunction passed as f: evaluated as given
        if isinstance(f, InclusionFunction):
            f, given = split_inclusion(f, "f")
        source = None  # the SX Function of f, whose (cached) inclusions are evaluated
        if isinstance(f, ca.Function):
            if f.n_in() != 1 or f.n_out() != 1:
                raise DimensionError(
                    f"zonotope_sivia needs a Function with one input and one output; "
                    f"'{f.name()}' has {f.n_in()} inputs and {f.n_out()} outputs (use "
                    "casadi.vertcat to stack them)")
            if not f.is_a("SXFunction"):
                f = f.expand()
            source = f
            if W is not None:
                raise ModelError("W is only used with a Model that has a disturbance w")
            x = ca.SX.sym("x", f.numel_in(0))
            expr = ca.densify(ca.vec(f(x)))
            syms = [x]
            name = f.name()
        elif isinstance(f, Model):
            if f.m > 0:
                raise ModelError(
                    f"model '{f.name}' has {f.m} inputs; set inversion needs an autonomous "
                    "map: close the loop first (model.closed_loop(K))")
            x = f.x
            expr = f.f
            syms = [x]
            name = f.name
            if f.l > 0:
                Wb = f.W if W is None else W
                from .._validate import as_boxes

                self.W = as_boxes(Wb, f.l, "W")
                if self.W.shape[0] != 1 or not np.isfinite(self.W).all():
                    raise UnboundedSetError("W must be one bounded box")
                syms = [x, f.w]
            elif W is not None:
                raise ModelError(f"model '{f.name}' has no disturbance; do not pass W")
        else:
            raise TypeError(f"f must be None (identity), a casadi.Function, an "
                            f"InclusionFunction or a Model; got {type(f).__name__}")
        self.n = int(x.numel())
        self.m = int(expr.numel())
        if self.W is None:
            syms = [x]
        if isinstance(f, Model):  # exact literals (the f of a closed loop is rounded)
            fun = f.interval_map("xw" if self.W is not None else "x")
        else:
            fun = ca.Function(f"{name}_map", syms, [expr])
        self.fun = fun
        self.discontinuous = _discontinuous_ops(fun)
        if self.discontinuous:
            warnings.warn(
                f"'{name}' contains operations through which it may jump "
                f"({', '.join(self.discontinuous)}); the mean-value form is not valid on "
                "zonotopes whose bounding box reaches a jump: there the natural interval "
                "enclosure over the bounding box is used instead", CmpcWarning, stacklevel=4)
        # interval Jacobian whose rows are [-inf, inf] on boxes where they may jump
        self.jac = JacobianInclusion(fun, wrt=0)
        point = "centered" if self.W is not None and not self.discontinuous else "natural"
        # The inclusions of f itself (its output flattened column-major, structural zeros
        # [0, 0]: the layout of fun's dense vector) come from the cache of inclusion(), or are
        # the one given; a Model's map is compiled here.
        self._source, self._given = source, given
        self.point = self._inclusion(point)
        self.box = self._inclusion(box_form) if box_form else None
        self._hull: InclusionFunction | None = self.box

    def _inclusion(self, kind: str) -> InclusionFunction:
        if self._source is None:
            return InclusionFunction(self.fun, kind)
        return inclusion_of(self._source, kind, self._given)

    def __call__(self, fr: ZonotopeFrontier
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """(centres, generators, radii, valid, boxes) of the image enclosures."""
        C, H, r = fr.centers, fr.generators, fr.radii
        N = len(fr)
        if self.identity:
            return C, H, r, np.ones(N, dtype=bool), None
        Xb = fr.bounding_boxes()
        extra = [self.W] if self.W is not None else []
        boxes = None
        if self.box is not None:
            boxes = self.box.evaluate_unchecked([Xb] + extra, N)[0]
        P = np.stack([C, C], axis=-1)
        fp = self.point.evaluate_unchecked([P] + extra, N)[0]  # (N, m, 2)
        J = self.jac([Xb] + extra, N)  # (N, m, n, 2); [-inf, inf] rows where f may jump
        rows = np.isfinite(fp).all(axis=2) & np.isfinite(J).all(axis=(2, 3))  # (N, m)
        if not rows.all():
            # rows without a mean-value enclosure: the interval hull of f over the bounding
            # box, as an independent box generator (zero generator row)
            if self._hull is None:
                self._hull = self._inclusion("natural")
            hull = boxes if boxes is not None else \
                self._hull.evaluate_unchecked([Xb] + extra, N)[0]
            fp = np.where(rows[..., None], fp, hull)
            J = np.where(rows[..., None, None], J, 0.0)
        valid = np.isfinite(fp).all(axis=(1, 2))
        if not valid.all():
            fp = np.where(valid[:, None, None], fp, 0.0)
        Jlo, Jhi = J[..., 0], J[..., 1]
        Mlo, Mhi = zn.imatmul(Jlo, Jhi, H, H)  # (N, m, p)
        Mmid, Mrad = zn.midrad(Mlo, Mhi)
        q, qrad = zn.midrad(fp[..., 0], fp[..., 1])
        s = zn.add_up(qrad, zn.sum_up(Mrad, axis=-1))
        if np.any(r):
            mag = np.maximum(np.abs(Jlo), np.abs(Jhi))  # (N, m, n)
            s = zn.add_up(s, zn.sum_up(zn.mul_up(mag, r[:, None, :]), axis=-1))
        ok = np.isfinite(s).all(axis=1) & np.isfinite(Mmid).all(axis=(1, 2))
        valid &= ok
        if not ok.all():
            s = np.where(valid[:, None], s, 0.0)
            Mmid = np.where(valid[:, None, None], Mmid, 0.0)
        return q, Mmid, s, valid, boxes


def zonotope_classifier(f: Any, Y: Any, *, n: int | None = None, X: Any = None, W: Any = None,
                        box_form: str | None = "natural"):
    """Classifier of zonotopes ``Z`` by their image enclosure against a target ``Y``.

    Parameters
    ----------
    f : None, casadi.Function, InclusionFunction or Model
        ``None`` for the identity; a Function ``R^n -> R^m`` (one input, one output), or its
        compiled :class:`~casadi_cmpc.interval.InclusionFunction` (evaluated as given where
        its kind is used; its Function gives the Jacobian); or a Model without inputs (e.g.
        ``model.closed_loop(K)``), robust over its disturbance box ``W``.
    Y : Box, Polytope, PolytopeUnion, Zonotope or another set of dimension m
        The target.
    n : int, optional
        Dimension of ``Z`` (needed for the identity only).
    X : Polytope or Box, optional
        A constraint on ``x`` itself: INNER also needs ``Z ⊆ X`` proven, and ``Z ∩ X = ∅``
        proven makes ``Z`` OUTER.
    W : Box, optional
        Disturbance box of a Model (default: ``model.W``).
    box_form : {"natural", "centered", None}
        Also enclose ``f(□Z)`` by this interval inclusion over the bounding box; a proof by
        either enclosure counts (ignored for the identity).

    Returns
    -------
    callable
        ``classify(frontier) -> (N,) int8`` labels INNER / OUTER / UNDECIDED, for
        :func:`~casadi_cmpc.solvers.engine.branch_and_bound`.
    """
    if box_form is not None:
        box_form = str(box_form).lower()
        if box_form not in ("natural", "centered"):
            raise ValueError(f"Unknown box_form '{box_form}'; valid: natural, centered, None")
    img = _Image(f, n, W, box_form if f is not None else None)
    target = _Target(Y, img.m, "Y")
    dom = _Target(X, img.n, "X") if X is not None else None

    def classify(fr: ZonotopeFrontier) -> np.ndarray:
        N = len(fr)
        labels = np.zeros(N, dtype=np.int8)
        if N == 0:
            return labels
        c, G, R, valid, boxes = img(fr)
        ins = np.zeros(N, dtype=bool)
        dis = np.zeros(N, dtype=bool)
        if valid.any():
            v = np.flatnonzero(valid)
            ins[v], dis[v] = target.classify(c[v], G[v], R[v],
                                             None if boxes is None else boxes[v])
        if boxes is not None and not valid.all():
            # no zonotope enclosure (e.g. an unbounded Jacobian): the box may still decide
            b = np.flatnonzero(~valid)
            ins[b], dis[b] = target.classify_boxes(boxes[b])
        if dom is not None:
            din, ddis = dom.classify(fr.centers, fr.generators, fr.radii)
            ins &= din
            dis |= ddis
        labels[ins] = INNER
        labels[dis & ~ins] = OUTER
        return labels

    classify.n = img.n  # type: ignore[attr-defined]
    classify.m = img.m  # type: ignore[attr-defined]
    return classify


# ----------------------------------------------------------------------------- result
class ZonotopePaving(metaclass=HoldsSetMeta):
    """The zonotopes of :func:`zonotope_sivia` / :func:`inner_zonotopes`, by label.

    Held by their :class:`~casadi_cmpc.SetResult` as ``result.paving`` (the result acts as
    it: ``result.inner``, ``result.volume()``, ``result.plot()``, and
    ``isinstance(result, ZonotopePaving)`` is True).

    Parameters
    ----------
    inner, boundary, outside : ZonotopeFrontier
        See the attributes.
    domain : Zonotope
        The initial zonotope.
    n_discarded : int, optional
        Number of zonotopes proven outside (default ``len(outside)``).
    outer : deprecated
        Old name of ``outside`` (keyword only; emits a DeprecationWarning).

    Attributes
    ----------
    inner : ZonotopeFrontier
        Zonotopes proven inside the solution set (every point, rounding included); Alg
        4.3's Σ_x. Iterate to get :class:`~casadi_cmpc.Zonotope` objects.
    boundary : ZonotopeFrontier
        Undecided zonotopes with ``Max(H) <= eps`` (Σ_x^b), plus any leftovers of a search
        stopped by a limit.
    outside : ZonotopeFrontier
        Zonotopes proven outside (discarded); empty unless ``keep_outer``. ``outer`` is its
        deprecated alias.
    domain : Zonotope
    n_discarded : int
    """

    def __init__(self, inner: ZonotopeFrontier, boundary: ZonotopeFrontier,
                 outside: ZonotopeFrontier | None = None, domain: Zonotope | None = None,
                 n_discarded: int | None = None, *, outer: ZonotopeFrontier | None = None
                 ) -> None:
        outside = _outside_keyword(outside, outer, "ZonotopePaving()")
        if outside is None or domain is None:
            raise TypeError("ZonotopePaving needs inner, boundary, outside and domain")
        self.inner = inner
        self.boundary = boundary
        self.outside = outside
        self.domain = domain
        self.n_discarded = len(outside) if n_discarded is None else int(n_discarded)

    @property
    def outer(self) -> ZonotopeFrontier:
        """Deprecated alias of :attr:`outside` (the discarded zonotopes)."""
        _warn_outer("ZonotopePaving.outer")
        return self.outside

    def __repr__(self) -> str:
        return (f"ZonotopePaving(dim={self.domain.dim}, inner={len(self.inner)}, "
                f"boundary={len(self.boundary)}, outside={len(self.outside)}, "
                f"n_discarded={self.n_discarded})")

    def volume(self, view: str = "inner") -> float:
        """Sum of the volumes of the ``"inner"``, ``"boundary"`` or ``"outside"`` zonotopes.

        The halves of a parallelotope share only a facet (Thm 4.2), so for a parallelotope
        domain this is the volume of the union; with redundant generators the halves
        overlap and the sum counts overlaps more than once. The view ``"outer"`` is a
        deprecated name of ``"outside"`` here (for a :class:`~casadi_cmpc.Paving` the view
        ``"outer"`` is inner ∪ boundary).
        """
        v = str(view).lower()
        if v == "outer":
            _warn_outer("the view 'outer' of ZonotopePaving.volume")
            v = "outside"
        fr = {"inner": self.inner, "boundary": self.boundary, "outside": self.outside}.get(v)
        if fr is None:
            raise ValueError(f"Unknown view '{view}'; valid: inner, boundary, outside")
        return float(fr.volumes().sum()) if len(fr) else 0.0

    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), domain: bool = True,
             outer: bool = True) -> Any:
        """Draw the paving: inner (green), boundary (yellow), outside (light blue), domain.

        Parameters
        ----------
        ax : matplotlib Axes, optional
        dims : (int, int)
            Coordinates drawn.
        domain : bool
            Outline the initial zonotope.
        outer : bool
            Draw the discarded (outside) zonotopes, when kept.

        Returns
        -------
        matplotlib Axes
        """
        from ..plot import new_axes

        ax = new_axes(ax)
        if outer and len(self.outside):
            self.outside.plot(ax, dims, facecolor="lightsteelblue", edgecolor="0.5",
                              linewidth=0.2, label=f"outside ({len(self.outside)})")
        if len(self.boundary):
            self.boundary.plot(ax, dims, facecolor="gold", edgecolor="0.3", linewidth=0.2,
                               label=f"boundary ({len(self.boundary)})")
        if len(self.inner):
            self.inner.plot(ax, dims, facecolor="tab:green", edgecolor="k", linewidth=0.3,
                            label=f"inner ({len(self.inner)})")
        if domain:
            self.domain.plot(ax=ax, dims=dims, facecolor="none", edgecolor="k",
                             linewidth=1.2, alpha=1.0, linestyle="--", label="domain")
        return ax


def _zonotope_result(out: Any, Z0: Zonotope, method: str) -> SetResult:
    """The SetResult of a zonotope search from the engine's outcome."""
    paving = ZonotopePaving(out.inner, out.boundary, out.outer, Z0, out.n_discarded)
    return SetResult(status=out.status, message=out.message, method=method, nit=out.levels,
                     n_boxes=out.n_classified, elapsed=out.elapsed, paving=paving,
                     history=out.history)


# ----------------------------------------------------------------------------- solvers
def _as_domain(X0: Any) -> tuple[Zonotope, Polytope | None]:
    if isinstance(X0, Zonotope):
        return X0, None
    if isinstance(X0, Box):
        if not X0.is_bounded():
            raise UnboundedSetError(f"X0 must be bounded; got {X0!r}")
        return Zonotope.from_box(X0), None
    if isinstance(X0, Polytope):
        return _bounding_parallelotope(X0), X0
    raise TypeError(f"X0 must be a Zonotope, Box or Polytope; got {type(X0).__name__}")


def _bounding_parallelotope(P: Polytope, method: str = "svd",
                            center: str | Any = "chebyshev") -> Zonotope:
    """A parallelotope containing the vertices of P (§4.2.5, Fig 4.7(b)), widened by 1e-9."""
    if P.is_empty():
        raise EmptySetError("the polytope is empty")
    if not P.is_bounded():
        raise UnboundedSetError("the polytope is unbounded; intersect it with a Box")
    V = P.vertices()
    if isinstance(center, str):
        key = center.lower()
        if key == "chebyshev":
            c = P.chebyshev_ball()[0]
        elif key == "box":
            c = None
        else:
            raise ValueError(f"Unknown center '{center}'; valid: chebyshev, box, or a point")
    else:
        c = np.asarray(center, dtype=float)
    Z = Zonotope.outer_parallelotope(V, center=c, method=method)
    # the float vertices may miss the exact ones by a few ulps: widen slightly
    return Zonotope(Z.center, Z.generators * (1.0 + 1e-9))


def zonotope_sivia(f: Any, X0: Any, Y: Any, eps: float, *, W: Any = None,
                   box_form: str | None = "natural", max_boxes: int = 2_000_000,
                   time_limit: float | None = None, keep_outer: bool = True,
                   progress: bool | None = None) -> SetResult:
    r"""Set inversion via zonotope geometry: pave ``{x in X0 : f(x) in Y}`` (thesis Alg 4.3).

    Parameters
    ----------
    f : None, casadi.Function, InclusionFunction or Model
        The map: ``None`` for the identity (then the result approximates ``X0 ∩ Y``); a
        Function ``R^n -> R^m`` with one input and one output (stack several conditions
        with ``casadi.vertcat``), or its compiled InclusionFunction (see
        :func:`zonotope_classifier`); or a Model without inputs (a closed loop,
        ``model.closed_loop(K)``), whose successor must lie in Y for every disturbance in
        ``W``.
    X0 : Zonotope, Box or Polytope
        The initial admissible domain. A Polytope is bounded by a parallelotope (its
        Chebyshev centre as centre, SVD directions, §4.2.5) and ``x in X0`` is added as a
        condition.
    Y : Box, Polytope, PolytopeUnion, Zonotope or another set of dimension m
        The target (a Box may have infinite bounds).
    eps : float
        Undecided zonotopes with ``Max(H) = max |h_ij| <= eps`` (4.12) are not bisected
        (boundary).
    W : Box, optional
        Disturbance box for a Model with ``w`` (default: the model's W).
    box_form : {"natural", "centered", None}
        Additional interval enclosure of ``f`` over the bounding box of each zonotope; a
        proof by either enclosure counts.
    max_boxes, time_limit : optional
        Limits; a stopped search reports its leftovers as boundary (still sound).
    keep_outer : bool
        Keep the discarded zonotopes for drawing (always counted).
    progress : bool or None
        tqdm progress bar (None: only for searches longer than 2 s).

    Returns
    -------
    SetResult
        ``paving``: a :class:`ZonotopePaving` (the result acts as it) with ``inner`` (every
        point proven: ``f(x) in Y``, for every w in W for a Model with a disturbance, and
        ``x in X0`` for a Polytope ``X0``), ``boundary``, ``outside``, ``n_discarded``,
        ``volume()``, ``plot(ax)``; ``status`` is ``PROVED`` when the search ran to
        completion, ``BUDGET`` when a limit stopped it.

    Notes
    -----
    **Image enclosure** (thesis (4.16), Thm 4.4). For ``Z = c ⊕ H B^p`` the mean-value
    theorem gives ``f(Z) ⊆ f(c) + ∇f(□Z)(Z - c)`` with the interval Jacobian over the
    bounding box ``□Z``; the interval matrix ``[M] = ∇f(□Z) H`` is bounded by Kühn's
    zonotope inclusion ``◇([M] B^p) = Mid[M] B^p ⊕ diag(Σ_j Rad[M]_ij) B^m`` (4.14)-(4.15).
    Everything is evaluated with outward rounding, so the enclosure contains the exact
    image. Compared with the interval enclosure of ``J H`` times ``B^p`` this keeps the
    correlation between the outputs (only the Jacobian's *width* is wrapped into a box),
    and its overestimation shrinks quadratically with the size of ``Z``.

    **Tests.** INNER: the enclosure is inside every row of a polytope target,
    ``h(a_i) <= b_i`` with support functions rounded upward (for a union: inside one
    member). OUTER: a row of the target, or a combination of the rows active at the vertex
    of the target that maximises a facet normal of the enclosure, separates them (see the
    separating axis theorem: complete in 2-D up to rounding). A Zonotope target is tested
    against its exact facet normals (interval enclosures): INNER needs an upper bound of
    the enclosure's support below a *lower* bound of the target's support in every facet
    normal; OUTER a facet normal of either zonotope (or an axis) along which the
    enclosure's minimum, rounded down, exceeds the target's support, rounded up. Its
    outward-rounded H-representation is never used for INNER (it contains the target).

    **Bisection** (Thm 4.1) along the first generator holding ``Max(H)``. The halves of a
    parallelotope share only a facet (Thm 4.2); for a zonotope with redundant generators
    they overlap (Fig 4.4) - bound it first with ``Z.reduce_to_parallelotope()`` (§4.2.5)
    when a non-overlapping paving is wanted (this enlarges the domain).

    Examples
    --------
    >>> import casadi as ca, numpy as np, casadi_cmpc as cm
    >>> from casadi_cmpc.solvers.zonotope_sivia import zonotope_sivia
    >>> x = ca.SX.sym("x", 2)
    >>> f = ca.Function("f", [x], [x + 0.1 * ca.vertcat(x[0] ** 2, x[0] * x[1])])
    >>> Z0 = cm.Zonotope([0.0, 0.0], [[1.0, 0.5], [0.0, 1.0]])
    >>> res = zonotope_sivia(f, Z0, cm.Box([-1, -1], [1, 1]), eps=0.1)
    >>> bool(res.success and len(res.inner) > 0)
    True
    """
    Z0, Xc = _as_domain(X0)
    classify = zonotope_classifier(f, Y, n=Z0.dim, X=Xc, W=W, box_form=box_form)
    if classify.n != Z0.dim:
        raise DimensionError(f"X0 has dimension {Z0.dim}; f takes {classify.n} inputs")
    if Z0.n_generators == 0:
        raise InvalidBoundsError("X0 is a single point (a zonotope without generators)")
    fr = ZonotopeFrontier.from_zonotopes(Z0)
    out = branch_and_bound(fr, classify, eps, max_boxes=max_boxes, time_limit=time_limit,
                           keep_outer=keep_outer, progress=progress, desc="zonotope sivia")
    return _zonotope_result(out, Z0, "zonotope sivia (Alg 4.3)")


def inner_zonotopes(P: Polytope, eps: float, *, method: str = "svd",
                    center: str | Any = "chebyshev", max_boxes: int = 2_000_000,
                    time_limit: float | None = None, keep_outer: bool = True,
                    progress: bool | None = None) -> SetResult:
    """Inner approximation of a polytope by a union of zonotopes (thesis Fig 4.8).

    Alg 4.3 with ``f = identity``, started from a parallelotope bounding P (§4.2.5, Fig
    4.7(b)): INNER means ``Z ⊆ P`` proven, OUTER means ``Z ∩ P = ∅`` proven.

    Parameters
    ----------
    P : Polytope
        Bounded, non-empty.
    eps : float
        Zonotopes with ``Max(H) <= eps`` are not bisected further.
    method : {"svd", "pca", "box"}
        Directions of the bounding parallelotope (see
        :meth:`~casadi_cmpc.Zonotope.outer_parallelotope`).
    center : {"chebyshev", "box"} or array_like, shape (n,)
        Its centre: the centre of the largest inscribed ball (the thesis' choice), the
        midpoint of the bounding box, or a given point.
    max_boxes, time_limit, keep_outer, progress
        As in :func:`zonotope_sivia`.

    Returns
    -------
    SetResult
        ``paving``: a :class:`ZonotopePaving`; ``inner``: zonotopes proven inside P; as eps
        decreases their total volume tends to the volume of P (they are halves of halves of
        one parallelotope, so they do not overlap).

    Examples
    --------
    >>> import numpy as np, casadi_cmpc as cm
    >>> from casadi_cmpc.solvers.zonotope_sivia import inner_zonotopes
    >>> P = cm.Polytope.from_vertices([[0, 0], [2, 0], [2.5, 1], [1, 2], [-0.5, 1]])
    >>> res = inner_zonotopes(P, eps=0.05)
    >>> bool(0.9 * P.volume() < res.volume() <= P.volume())
    True
    """
    if not isinstance(P, Polytope):
        raise TypeError(f"P must be a Polytope; got {type(P).__name__}")
    Z0 = _bounding_parallelotope(P, method, center)
    classify = zonotope_classifier(None, P, n=P.dim)
    fr = ZonotopeFrontier.from_zonotopes(Z0)
    out = branch_and_bound(fr, classify, eps, max_boxes=max_boxes, time_limit=time_limit,
                           keep_outer=keep_outer, progress=progress, desc="inner zonotopes")
    return _zonotope_result(out, Z0, "inner zonotopes (Alg 4.3, f = identity)")
