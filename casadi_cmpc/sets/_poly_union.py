"""Finite unions of polytopes and the covering engine that proves ``region ⊆ ∪ P_i``.

:class:`PolytopeUnion` is importable from :mod:`casadi_cmpc.sets.polytope`. Its exact
``contains_box`` (thesis §6.1.4) and :meth:`Polytope.is_subset` of a union share the
covering engine :func:`_uncovered`: the region minus the members is split into pieces,
and a piece is dropped only with a certificate that it has no interior point
(:func:`_prune_pieces`: stacked LPs whose multipliers are checked rigorously).

The number of pieces can grow exponentially with the number of members, so every proof
has a budget (:class:`CoverBudget`: pieces alive, pieces handed to the LP, optionally
seconds). A proof that runs out of budget answers "not proven", exactly like an
undecided piece: no caller reads it as "not a subset".
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .._validate import as_boxes, as_points
from ..exceptions import DimensionError, EmptySetError
from . import _hull, _lp
from ._boxkernel import _certify_separation
from .base import SetBase
from .box import Box

if TYPE_CHECKING:
    from .polytope import Polytope

__all__ = ["CoverBudget", "PolytopeUnion"]


@dataclass(frozen=True)
class CoverBudget:
    """Limits of one run of the covering engine (:func:`_uncovered`).

    When a limit would be passed, the regions still undecided are answered "not proven"
    (a point is returned for them, as for an undecided piece), never "proven not
    covered".

    Parameters
    ----------
    max_pieces : int
        Pieces alive at once (all regions of the call together).
    max_lps : int
        Pieces handed to the pruning LPs in the whole call.
    max_seconds : float or None
        Wall-clock limit of the call (None: none; results then repeat from run to run).
    """

    max_pieces: int = 4096
    max_lps: int = 20_000
    max_seconds: float | None = None


DEFAULT_BUDGET = CoverBudget()


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
        from .polytope import Polytope

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
        """The members not proven empty."""
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
        level of rounding, a box of zero width, or the proof ran out of its budget,
        :class:`CoverBudget`). The witness of a ``False`` is a point
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
        from ._poly_ops import hull

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
        """Arrays for saving: all rows ``A`` (k, n), ``b`` (k,), rows per member, dim."""
        n = self.dim
        A = np.vstack([P.A for P in self.polytopes]) if self.polytopes else np.zeros((0, n))
        b = np.concatenate([P.b for P in self.polytopes]) if self.polytopes else np.zeros(0)
        counts = np.array([P.n_constraints for P in self.polytopes], dtype=np.int64)
        return {"A": A, "b": b, "counts": counts, "dim": int(n)}

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> PolytopeUnion:
        """The union saved by :meth:`_state`."""
        from .polytope import Polytope

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
               hard: list[tuple[np.ndarray, np.ndarray]] | None = None,
               budget: CoverBudget | None = None, stats: dict[str, Any] | None = None
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
    budget : CoverBudget, optional
        Limits of the call (default :data:`DEFAULT_BUDGET`). A region still undecided
        when a limit would be passed gets a point ("not proven").
    stats : dict, optional
        Filled with ``exhausted`` (bool: the budget ended the call), ``lp_pieces`` (pieces
        handed to the LPs), ``max_alive`` and ``refuted`` (regions stopped early because
        an interior LP point of a piece lies outside every member, in floating point).

    Returns
    -------
    list of (ndarray (n,) or None)
        None only for a region proven covered. A returned point lies in a piece that is
        not proven empty: it is usually outside every member, but not necessarily so (an
        undecided piece, or the budget ran out).
    """
    K, n = boxes.shape[0], boxes.shape[1]
    budget = DEFAULT_BUDGET if budget is None else budget
    st: dict[str, Any] = {"exhausted": False, "lp_pieces": 0, "max_alive": 0, "refuted": 0}
    if stats is not None:
        stats.clear()
        stats.update(st)
        st = stats
    t_start = time.perf_counter()
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
        over = (len(new_k) + len(kk) > budget.max_pieces
                or st["lp_pieces"] + len(new_k) > budget.max_lps
                or (budget.max_seconds is not None
                    and time.perf_counter() - t_start > budget.max_seconds))
        if over:  # "not proven" for every region still open, with its latest point
            st["exhausted"] = True
            for k, c_p in zip(piece_k, piece_c, strict=True):
                if out[k] is None:
                    out[k] = np.asarray(c_p, dtype=float)
            return out
        if new_k:
            gone, X, rad = _prune_pieces(new_A, new_b, [hard[k] for k in new_k],
                                         boxes[new_k])
            st["lp_pieces"] += len(new_k)
            keep = np.flatnonzero(~gone)
            # a piece with an interior LP point outside every member: its region is not
            # covered (up to floating point): stop working on it, answer the point
            deep = keep[np.isfinite(rad[keep]) & (rad[keep] > 1e-6)]
            if deep.size:
                inside = np.zeros(deep.size, dtype=bool)
                for M in members:
                    inside |= np.asarray(M.contains(X[deep]), dtype=bool)
                for idx in deep[~inside].tolist():
                    k = new_k[idx]
                    if out[k] is None:
                        out[k] = np.asarray(X[idx], dtype=float)
                        st["refuted"] += 1
            for idx in keep.tolist():
                if out[new_k[idx]] is not None:
                    continue
                kk.append(new_k[idx])
                kA.append(new_A[idx])
                kb.append(new_b[idx])
                kc.append(X[idx])
        keep_old = [i for i, k in enumerate(kk) if out[k] is None]
        piece_k = [kk[i] for i in keep_old]
        piece_A = [kA[i] for i in keep_old]
        piece_b = [kb[i] for i in keep_old]
        piece_c = [kc[i] for i in keep_old]
        st["max_alive"] = max(st["max_alive"], len(piece_k))
    for k, c in zip(piece_k, piece_c, strict=True):
        if out[k] is None:
            out[k] = np.asarray(c, dtype=float)
    return out


def _prune_pieces(As: list[np.ndarray], bs: list[np.ndarray],
                  hard: list[tuple[np.ndarray, np.ndarray]], boxes: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    r : ndarray, shape (K,)
        The LP values (distance of the point to the soft rows in the unit coordinates;
        +inf where the LP did not end optimal), a floating-point hint only.
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
        return gone, X, r
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
    return gone, X, r
