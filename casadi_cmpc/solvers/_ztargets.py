"""Target sets of zonotope SIVIA: proofs of ``Z ⊆ Y`` and ``Z ∩ Y = ∅`` for zonotope batches.

A batch is given as centres ``C`` (N, n), generators ``G`` (N, n, p) and radii ``R``
(N, n) of an added box (see :class:`~casadi_cmpc.solvers._zbatch.ZonotopeFrontier`).
:class:`_PolytopeTest` decides against the rows of a polytope (or a box),
:class:`_ZonotopeTest` against a zonotope through its exact facet normals, and
:class:`_Target` combines them for any target set (unions, other sets through their box
tests). Every bound is rounded the safe way, so each answer is a proof.
"""

from __future__ import annotations

import itertools
from math import comb
from typing import Any

import numpy as np

from ..exceptions import CmpcError, DimensionError
from ..interval import arith as ia
from ..sets import _zono_num as zn
from ..sets.base import SetBase
from ..sets.box import Box
from ..sets.polytope import Polytope, PolytopeUnion
from ..sets.zonotope import Zonotope
from ._zbatch import _dot_center, _spread_up

__all__: list[str] = []

#: Largest number of (n-1)-subsets of generators used as separating directions (n >= 3).
MAX_NORMAL_SUBSETS = 64


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
        # a row constrains iff an entry is nonzero, decided exactly (a norm computed in
        # floating point underflows to 0 for entries below about 1e-154)
        nonzero = (A != 0).any(axis=1)
        self.empty = bool(np.any(b == -np.inf) or np.any(~nonzero & (b < 0)))
        keep = np.isfinite(b) & nonzero
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
        R = Pm._rows()
        if R.A.shape != Am.shape:  # a row of Pm that constrains nothing: rows alone
            return
        An, bn = R.An, R.bn  # unit rows, without under- or overflow
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
        """Proven ``Z_i ⊆ {A x <= b}`` for the batch (C (N, n), G (N, n, p), R (N, n)): (N,)."""
        N = C.shape[0]
        if self.empty:
            return np.zeros(N, dtype=bool)
        if self.A.shape[0] == 0:
            return np.ones(N, dtype=bool)
        _, dhi = _dot_center(C, self.A, self.A)
        up = zn.add_up(dhi, _spread_up(G, R, self.A, self.A))
        return np.all(up <= self.b[None, :], axis=1)

    def disjoint(self, C: np.ndarray, G: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Proven ``Z_i ∩ {A x <= b} = ∅`` for the batch (C, G, R as in :meth:`inside`): (N,)."""
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
        """Proven ``Z_i ⊆ S`` for the batch (C (N, n), G (N, n, p), R (N, n)): (N,) bool."""
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
        """Proven ``Z_i ∩ S = ∅`` for the batch (C, G, R as in :meth:`inside`): (N,) bool."""
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
    """The finite rows ``(A, b)`` of the box ``Y``: ``x <= hi``, ``-x <= -lo``; (k, n), (k,)."""
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
