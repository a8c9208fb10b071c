r"""Batches of zonotopes ``c_i ⊕ H_i B^p ⊕ [-r_i, r_i]``: the frontier of zonotope SIVIA.

:class:`ZonotopeFrontier` implements the frontier protocol of
:func:`~casadi_cmpc.solvers.engine.branch_and_bound` (``take``, ``width``, ``bisect`` by
thesis Thm 4.1, ``concat``) and the geometry the classifiers and the drawings need
(bounding boxes, support-function enclosures, volumes, polygons). The helpers
:func:`_spread_up` and :func:`_dot_center` bound support functions of whole batches with
outward rounding. Importable from :mod:`casadi_cmpc.solvers.zonotope_sivia`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import DimensionError
from ..interval import arith as ia
from ..sets import _zono_num as zn
from ..sets.box import Box
from ..sets.zonotope import Zonotope

__all__ = ["ZonotopeFrontier"]


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
        if self.n_generators == 0:
            raise ValueError("zonotopes without generators (points) cannot be bisected")
        H2, centres, errors, extra = zn.halve_generator(self.centers, self.generators)
        extra = np.abs(extra)
        out_r = []
        for err in errors:
            err = np.abs(err)
            rr = self.radii
            if np.any(err):
                rr = zn.add_up(rr, err)
            if np.any(extra):
                rr = zn.add_up(rr, extra)
            out_r.append(rr)
        return ZonotopeFrontier(np.concatenate(centres), np.concatenate([H2, H2]),
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
