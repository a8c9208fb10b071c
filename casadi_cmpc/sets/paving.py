"""Batched box helpers and pavings (finite unions of boxes labelled inner / boundary / outside).

A batch of boxes is a float array of shape ``(N, n, 2)``: ``[..., 0]`` lower bounds,
``[..., 1]`` upper bounds. The helpers of this module work on whole batches at once.

A :class:`Paving` is what set inversion (SIVIA, thesis §4.1.2, Alg. 4.1) returns: the boxes of
the initial domain sorted into ``inner`` (proven inside the target set), ``boundary``
(undecided at the resolution ``eps``) and ``outside`` (proven outside, discarded).

Examples
--------
>>> import numpy as np
>>> import casadi_cmpc as cm
>>> from casadi_cmpc.sets.paving import bisect_boxes
>>> left, right = bisect_boxes(np.array([[[0.0, 4.0], [0.0, 2.0]]]))
>>> left[0].tolist(), right[0].tolist()
([[0.0, 2.0], [0.0, 2.0]], [[2.0, 4.0], [0.0, 2.0]])
>>> P = cm.Paving(inner=left, boundary=right, domain=cm.Box([0, 0], [4, 2]))
>>> P.volume(), P.volume(view="outer")
(4.0, 8.0)
>>> P.contains([[1.0, 1.0], [5.0, 1.0]])
array([ True, False])
>>> bool(P.contains_box(np.array([[[1.0, 3.0], [0.5, 1.5]]]))[0])
True
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._validate import as_boxes, as_points
from ..exceptions import DimensionError, EmptySetError, InvalidBoundsError, UnboundedSetError
from .base import SetBase, held_set
from .box import Box

__all__ = [
    "Paving",
    "bisect_boxes",
    "box_volume",
    "box_width",
    "box_diam",
    "box_mid",
    "boxes_contain_points",
    "hull_of_boxes",
]

_BISECTION_RULES = ("widest",)
_VIEWS = ("outer", "inner", "boundary", "outside")
# largest number of (box, box) pairs examined in one vectorised step
_PAIR_BUDGET = 1 << 18
_DEFAULT_COLORS = {"inner": "#6abf69", "boundary": "#ffe066", "outside": "#c9d6e3"}
_DEFAULT_LABELS = {"inner": "inner", "boundary": "boundary", "outside": "outside"}


def _warn_outer(what: str, stacklevel: int = 3) -> None:
    """The DeprecationWarning of the old name ``outer`` of the proven-outside boxes."""
    warnings.warn(
        f"{what} is deprecated: the proven-outside boxes are now called 'outside' (the "
        "view 'outer' is inner ∪ boundary, the outer approximation); use 'outside'",
        DeprecationWarning, stacklevel=stacklevel)


def _outside_keyword(outside: Any, outer: Any, what: str) -> Any:
    """``outside``, or the deprecated keyword ``outer`` (with a warning); not both."""
    if outer is None:
        return outside
    _warn_outer(f"the keyword outer= of {what}", stacklevel=4)
    if outside is not None:
        raise TypeError(f"{what} got both outside= and its deprecated alias outer=; "
                        "pass outside= only")
    return outer


# ============================================================== batched box helpers
def _scale_widths(scale: Any, n: int) -> np.ndarray:
    """Normalise ``scale`` (widths (n,), a Box or an (n, 2) box) to non-negative widths."""
    if isinstance(scale, Box):
        s = scale.diam
    else:
        s = np.asarray(scale, dtype=float)
        if s.ndim == 3 and s.shape[0] == 1:
            s = s[0]
        if s.ndim == 2 and s.shape == (n, 2):
            s = s[:, 1] - s[:, 0]
    if s.shape != (n,):
        raise DimensionError(
            f"scale must be widths of shape ({n},) or an initial box of shape ({n}, 2); "
            f"got shape {np.shape(scale)}")
    if not np.isfinite(s).all() or (s < 0).any():
        raise InvalidBoundsError(
            f"scale must hold finite non-negative widths; got {s.tolist()}")
    return s


def _rel_widths(b: np.ndarray, scale: Any) -> np.ndarray:
    with np.errstate(over="ignore"):
        w = b[..., 1] - b[..., 0]
    if scale is None:
        return w
    s = _scale_widths(scale, b.shape[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        r = w / s
    return np.where(w == 0, 0.0, r)


def _split_point(lo: np.ndarray, hi: np.ndarray, r: float) -> np.ndarray:
    """``lo + r (hi - lo)`` computed without overflow and clipped to ``[lo, hi]``."""
    with np.errstate(over="ignore", invalid="ignore"):
        c = (lo + hi) / 2.0 if r == 0.5 else lo + r * (hi - lo)
        huge = ~np.isfinite(c) & np.isfinite(lo) & np.isfinite(hi)
        if huge.any():
            c = np.where(huge, (1.0 - r) * lo + r * hi, c)
    return np.clip(c, lo, hi)


def box_diam(boxes: Any) -> np.ndarray:
    """Widths of every component.

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box

    Returns
    -------
    ndarray, shape (N, n)
        ``hi - lo`` per component (``inf`` for an infinite bound).
    """
    b = as_boxes(boxes, name="boxes")
    return b[..., 1] - b[..., 0]


def box_width(boxes: Any, scale: Any = None) -> np.ndarray:
    """Width of each box: its largest component width, thesis eq. (4.2).

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box
    scale : array_like, shape (n,), or Box, optional
        Widths of a reference (initial) box; when given the widths are measured relative to
        it, ``max_i (hi_i - lo_i) / scale_i``.

    Returns
    -------
    ndarray, shape (N,)

    See Also
    --------
    box_diam : the widths of all components, shape (N, n).
    """
    b = as_boxes(boxes, name="boxes")
    if b.shape[0] == 0:
        return np.zeros(0)
    return _rel_widths(b, scale).max(axis=1)


def box_volume(boxes: Any) -> np.ndarray:
    """Volume (product of the widths) of each box.

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box

    Returns
    -------
    ndarray, shape (N,)
        ``0`` for a box with a zero width (even when another width is infinite).
    """
    b = as_boxes(boxes, name="boxes")
    w = b[..., 1] - b[..., 0]
    flat = (w == 0).any(axis=1)
    with np.errstate(invalid="ignore"):
        v = np.prod(w, axis=1)
    return np.where(flat, 0.0, v)


def box_mid(boxes: Any) -> np.ndarray:
    """Midpoint of each box.

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box

    Returns
    -------
    ndarray, shape (N, n)
        ``(lo + hi) / 2``, inside the box even for huge or subnormal bounds; NaN for
        ``(-inf, inf)``.
    """
    b = as_boxes(boxes, name="boxes")
    with np.errstate(invalid="ignore"):
        return _split_point(b[..., 0], b[..., 1], 0.5)


def hull_of_boxes(boxes: Any) -> np.ndarray:
    """Interval hull (smallest enclosing box) of a batch of boxes.

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box
        At least one box.

    Returns
    -------
    ndarray, shape (n, 2)

    Raises
    ------
    EmptySetError
        The batch holds no box.
    """
    b = as_boxes(boxes, name="boxes")
    if b.shape[0] == 0:
        raise EmptySetError("hull_of_boxes needs at least one box; got an empty batch")
    return np.stack([b[..., 0].min(axis=0), b[..., 1].max(axis=0)], axis=-1)


def boxes_contain_points(boxes: Any, points: Any) -> np.ndarray:
    """Membership matrix of points in boxes (closed boxes, bounds included).

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box
    points : array_like, shape (P, n) or (n,)

    Returns
    -------
    ndarray of bool, shape (N, P), or (N,) for a single point ``(n,)``
        Entry ``[i, k]`` is True when point ``k`` lies in box ``i``.
    """
    b = as_boxes(boxes, name="boxes")
    p, batched = as_points(points, b.shape[1], name="points")
    out = np.empty((b.shape[0], p.shape[0]), dtype=bool)
    step = max(1, _PAIR_BUDGET // max(1, b.shape[0] * b.shape[1]))
    for k0 in range(0, p.shape[0], step):
        q = p[None, k0:k0 + step, :]
        out[:, k0:k0 + step] = ((b[:, None, :, 0] <= q) & (q <= b[:, None, :, 1])).all(axis=2)
    return out if batched else out[:, 0]


def bisect_boxes(boxes: Any, rule: str = "widest", scale: Any = None,
                 split_ratio: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Bisect every box of a batch along its widest component (thesis eqs. (4.2)-(4.4)).

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box
        Bounded boxes that are not single points.
    rule : {"widest"}
        Choice of the split component: the widest one, ties going to the lowest index
        (eq. (4.3)).
    scale : array_like, shape (n,), or Box, or array_like, shape (n, 2), optional
        Widths of the initial box (or the initial box itself). When given, the widest
        component is the one with the largest ``width_i / scale_i`` (widths relative to the
        initial box). A zero scale makes a positive width infinitely wide.
    split_ratio : float
        Position of the cut in ``(0, 1)``: ``lo_j + split_ratio * (hi_j - lo_j)``. ``0.5`` is
        the midpoint of eq. (4.4); a value such as ``0.49`` (codac's default) avoids cutting
        at points of symmetry.

    Returns
    -------
    left, right : ndarray, shape (N, n, 2)
        ``left`` keeps ``[lo_j, c]`` and ``right`` keeps ``[c, hi_j]`` in the split
        component ``j``; the other components are copied. Both share the face ``x_j = c``.

    Raises
    ------
    UnboundedSetError
        A box has an infinite bound.
    InvalidBoundsError
        A box is a single point, or its split component is too narrow to hold a float
        strictly between its bounds.
    ValueError
        Unknown ``rule`` or ``split_ratio`` outside ``(0, 1)``.

    Examples
    --------
    >>> import numpy as np
    >>> from casadi_cmpc.sets.paving import bisect_boxes
    >>> L, R = bisect_boxes(np.array([[[0.0, 1.0], [0.0, 1.0]]]))
    >>> L[0, 0].tolist(), R[0, 0].tolist()
    ([0.0, 0.5], [0.5, 1.0])
    >>> L, R = bisect_boxes(np.array([[[0.0, 1.0], [0.0, 1.0]]]), scale=[4.0, 1.0])
    >>> L[0, 1].tolist()
    [0.0, 0.5]
    """
    meth = str(rule).lower()
    if meth not in _BISECTION_RULES:
        raise ValueError(f"Unknown bisection rule {rule!r}; valid rules: {_BISECTION_RULES}")
    r = float(split_ratio)
    if not 0.0 < r < 1.0:
        raise ValueError(f"split_ratio must lie strictly between 0 and 1; got {split_ratio}")
    b = as_boxes(boxes, name="boxes")
    N = b.shape[0]
    if N == 0:
        return b.copy(), b.copy()
    bad = ~np.isfinite(b).all(axis=2)
    if bad.any():
        i, k = np.argwhere(bad)[0]
        raise UnboundedSetError(
            f"cannot bisect an unbounded box: box {i} has component {k} = "
            f"[{b[i, k, 0]}, {b[i, k, 1]}]; bisect bounded boxes only")
    rel = _rel_widths(b, scale)
    j = np.argmax(rel, axis=1)  # first maximum: the lowest index on ties, eq. (4.3)
    rows = np.arange(N)
    lo, hi = b[rows, j, 0], b[rows, j, 1]
    point = lo == hi
    if point.any():
        i = int(np.flatnonzero(point)[0])
        raise InvalidBoundsError(
            f"cannot bisect box {i}: all its widths are zero (it is the point "
            f"{b[i, :, 0].tolist()})")
    c = _split_point(lo, hi, r)
    narrow = ~((lo < c) & (c < hi))
    if narrow.any():
        i = int(np.flatnonzero(narrow)[0])
        raise InvalidBoundsError(
            f"cannot bisect box {i}: component {int(j[i])} = [{lo[i]!r}, {hi[i]!r}] holds no "
            "float strictly between its bounds")
    left = b.copy()
    right = b.copy()
    left[rows, j, 1] = c
    right[rows, j, 0] = c
    return left, right


# ================================================================= private machinery
def _pairs(A: np.ndarray, B: np.ndarray, strict: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(ia, ib)`` of boxes of ``A`` and ``B`` that intersect.

    ``strict=False``: the closed boxes share a point; ``strict=True``: the intersection has a
    non-empty interior (positive volume). Small batches are compared all against all. Large
    ones are swept along the first coordinate, separately for each class of widths of
    ``B`` (widths within a factor 2), so that the candidates examined stay close to the
    boxes that really overlap along that coordinate.
    """
    na, nb = A.shape[0], B.shape[0]
    empty = np.zeros(0, dtype=np.intp)
    if na == 0 or nb == 0:
        return empty, empty
    if na * nb <= _PAIR_BUDGET:
        return _filter_pairs(A, B, np.repeat(np.arange(na), nb), np.tile(np.arange(nb), na),
                             strict)
    w0 = B[:, 0, 1] - B[:, 0, 0]
    with np.errstate(divide="ignore"):
        cls = np.where(w0 > 0, np.floor(np.log2(np.where(w0 > 0, w0, 1.0))), -np.inf)
    out_a, out_b = [], []
    for c in np.unique(cls):
        ia, ib = _sweep_pairs(A, B, np.flatnonzero(cls == c), strict)
        out_a.append(ia)
        out_b.append(ib)
    return np.concatenate(out_a), np.concatenate(out_b)


def _sweep_pairs(A: np.ndarray, B: np.ndarray, sub: np.ndarray,
                 strict: bool) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_pairs` of ``A`` against the boxes ``B[sub]`` by a sweep on coordinate 0."""
    na = A.shape[0]
    order = sub[np.argsort(B[sub, 0, 0], kind="stable")]
    blo0 = B[order, 0, 0]
    end = np.searchsorted(blo0, A[:, 0, 1], side="right")
    with np.errstate(invalid="ignore", over="ignore"):
        maxw = float(np.max(B[sub, 0, 1] - B[sub, 0, 0]))
        if np.isfinite(maxw):
            # pad: a width rounded down or a difference rounded up must not lose a pair
            maxw = float(np.nextafter(maxw, np.inf)) * (1.0 + 2.0 ** -40)
            start = np.searchsorted(blo0, np.nextafter(A[:, 0, 0] - maxw, -np.inf),
                                    side="left")
        else:
            start = np.zeros(na, dtype=np.intp)
    start = np.minimum(start, end)
    counts = end - start
    csum = np.cumsum(counts)
    out_a = [np.zeros(0, dtype=np.intp)]
    out_b = [np.zeros(0, dtype=np.intp)]
    i0 = 0
    while i0 < na:
        base = csum[i0 - 1] if i0 else 0
        i1 = int(np.searchsorted(csum, base + _PAIR_BUDGET, side="right"))
        i1 = min(max(i1, i0 + 1), na)
        c = counts[i0:i1]
        tot = int(c.sum())
        if tot:
            ia = np.repeat(np.arange(i0, i1), c)
            off = np.arange(tot) - np.repeat(np.cumsum(c) - c, c)
            ib = order[np.repeat(start[i0:i1], c) + off]
            ia, ib = _filter_pairs(A, B, ia, ib, strict)
            out_a.append(ia)
            out_b.append(ib)
        i0 = i1
    return np.concatenate(out_a), np.concatenate(out_b)


def _filter_pairs(A: np.ndarray, B: np.ndarray, ia: np.ndarray, ib: np.ndarray,
                  strict: bool) -> tuple[np.ndarray, np.ndarray]:
    lo = np.maximum(A[ia, :, 0], B[ib, :, 0])
    hi = np.minimum(A[ia, :, 1], B[ib, :, 1])
    ok = (lo < hi).all(axis=1) if strict else (lo <= hi).all(axis=1)
    return ia[ok], ib[ok]


def _subtract_rows(pieces: np.ndarray, owner: np.ndarray,
                   bs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed pieces covering the closure of ``pieces[r] minus bs[r]``, for all rows at once.

    Every ``pieces[r]`` must meet ``bs[r]``. A box minus a box is split into at most ``2 n``
    boxes with disjoint interiors: for each component ``k`` the slabs below and above
    ``bs[r]`` are cut off, and the middle part goes on to the next component; what is left
    at the end lies in ``bs[r]`` and is dropped. The pieces are closed, so they cover the
    closure of the difference; ``owner`` tags each piece with the box it came from.
    """
    outp = []
    outo = []
    cur = pieces.copy()
    for k in range(pieces.shape[1]):
        blo, bhi = bs[:, k, 0], bs[:, k, 1]
        below = cur[:, k, 0] < blo
        if below.any():
            p = cur[below]
            p[:, k, 1] = blo[below]
            outp.append(p)
            outo.append(owner[below])
        above = cur[:, k, 1] > bhi
        if above.any():
            p = cur[above]
            p[:, k, 0] = bhi[above]
            outp.append(p)
            outo.append(owner[above])
        np.maximum(cur[:, k, 0], blo, out=cur[:, k, 0])
        np.minimum(cur[:, k, 1], bhi, out=cur[:, k, 1])
    if not outp:
        return pieces[:0], owner[:0]
    return np.concatenate(outp), np.concatenate(outo)


def _pick_one(ip: np.ndarray, P: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each piece index in ``ip``, the position of one pair to subtract.

    Preference: a box covering the piece, then the largest overlap.
    """
    lo = np.maximum(P[..., 0], B[..., 0])
    hi = np.minimum(P[..., 1], B[..., 1])
    cover = ((B[..., 0] <= P[..., 0]) & (P[..., 1] <= B[..., 1])).all(axis=1)
    with np.errstate(invalid="ignore"):
        ov = np.nan_to_num(np.prod(hi - lo, axis=1), nan=0.0)
    order = np.lexsort((-ov, ~cover, ip))
    first = np.ones(order.size, dtype=bool)
    first[1:] = ip[order][1:] != ip[order][:-1]
    sel = order[first]
    return ip[sel], sel


def _covered(Q: np.ndarray, U: np.ndarray) -> np.ndarray:
    """Exact test ``Q[i] ⊆ union of U`` for every query box (closed boxes).

    A query covered by a single box is found at once. For the others, pieces (initially
    the queries) are reduced in rounds: every piece subtracts one box of ``U`` that meets it
    in more than a face, in one vectorised step for all pieces. The union of the closed
    pieces of a query is the closure of what is not yet covered; since the union of ``U``
    is closed, the query is covered exactly when no piece is left. A piece that no box
    meets in more than a face is not covered (faces have no volume in the piece), which
    settles its query as False. Every box acts at most once on a chain of pieces, so the
    rounds end.
    """
    res = np.zeros(Q.shape[0], dtype=bool)
    if Q.shape[0] == 0 or U.shape[0] == 0:
        return res
    ia, ib = _pairs(Q, U)
    single = ((U[ib, :, 0] <= Q[ia, :, 0]) & (Q[ia, :, 1] <= U[ib, :, 1])).all(axis=1)
    res[ia[single]] = True
    todo = np.zeros(Q.shape[0], dtype=bool)
    todo[ia] = True
    todo &= ~res
    if not todo.any():
        return res
    V = U[np.unique(ib[todo[ia]])]
    idx = np.flatnonzero(todo)
    pieces = Q[idx].copy()
    owner = idx.copy()
    failed = np.zeros(Q.shape[0], dtype=bool)
    while pieces.shape[0]:
        ip, jb = _pairs(pieces, V)
        P, B = pieces[ip], V[jb]
        lo = np.maximum(P[..., 0], B[..., 0])
        hi = np.minimum(P[..., 1], B[..., 1])
        act = ~((lo == hi) & (P[..., 0] < P[..., 1])).any(axis=1)
        ip, P, B = ip[act], P[act], B[act]
        has = np.zeros(pieces.shape[0], dtype=bool)
        has[ip] = True
        failed[owner[~has]] = True
        rows, sel = _pick_one(ip, P, B)
        alive = ~failed[owner[rows]]
        pieces, owner = _subtract_rows(pieces[rows[alive]], owner[rows[alive]],
                                       B[sel[alive]])
        keep = ~failed[owner]
        pieces, owner = pieces[keep], owner[keep]
    res[idx] = ~failed[idx]
    return res


class _BoxGrid:
    """Exact index of a union of closed boxes on the grid of their own bounds.

    The sorted distinct bounds of the boxes, per coordinate, cut space into cells; each cell
    is either inside one of the boxes or has no interior point in common with any. A count
    table (n-D prefix sums of the covered cells) answers, for a query box, how many cells of
    an index range are covered, in ``2**n`` look-ups. The ranges come from exact
    comparisons with the bounds (``searchsorted``), so both tests below are exact:

    * ``contains``: the cells covering the query (the last bound ``<= lo`` to the first
      bound ``>= hi``) are all covered;
    * ``intersects``: some cell meeting the closed query (a shared face counts) is covered.

    Boxes of zero width in some coordinate (flat) cover no cell: they are kept aside and
    the tests use the exact pairwise routines for them (``intersects``) or for flat queries
    (``contains``: a query with interior is inside the closed union of the boxes with
    interior iff it is inside the union of all, since flat boxes have no volume).
    Built only when the table is small (:data:`MAX_CELLS`); otherwise ``None``.
    """

    MAX_CELLS = 4_000_000

    @classmethod
    def build(cls, U: np.ndarray) -> _BoxGrid | None:
        if U.shape[0] == 0 or not np.isfinite(U).all():
            return None
        n = U.shape[1]
        flat = (U[..., 1] <= U[..., 0]).any(axis=1)
        if flat.all():
            return None
        full = U
        U = U[~flat]
        edges = [np.unique(U[:, j, :]) for j in range(n)]
        shape = tuple(max(e.size - 1, 1) for e in edges)
        if int(np.prod([s + 1 for s in shape], dtype=float)) > cls.MAX_CELLS:
            return None
        self = cls()
        self.all = full
        self.flat = full[flat]
        self.edges = edges
        self.shape = shape
        # difference array over the cells: +-1 at the 2**n corners of each box's index block
        a = [np.searchsorted(edges[j], U[:, j, 0]) for j in range(n)]  # first cell
        b = [np.searchsorted(edges[j], U[:, j, 1]) for j in range(n)]  # one past the last
        keep = np.ones(U.shape[0], dtype=bool)
        for j in range(n):
            keep &= b[j] > a[j]  # flat boxes cover no cell
        diff = np.zeros(tuple(s + 1 for s in shape), dtype=np.int64)
        for bits in itertools.product((0, 1), repeat=n):
            idx = tuple((b[j] if bit else a[j])[keep] for j, bit in enumerate(bits))
            np.add.at(diff, idx, (-1) ** sum(bits))
        cover = diff
        for j in range(n):
            cover = np.cumsum(cover, axis=j)
        covered = (cover[tuple(slice(0, s) for s in shape)] > 0).astype(np.int64)
        self.covered = covered.astype(bool)
        table = np.zeros(tuple(s + 1 for s in shape), dtype=np.int64)
        inner = covered
        for j in range(n):
            inner = np.cumsum(inner, axis=j)
        table[tuple(slice(1, None) for _ in shape)] = inner
        self.table = table
        return self

    def polytope_inside(self, P: Any) -> bool:
        """Proven ``P ⊆ union`` for a bounded polytope P: P's rigorous bounding box lies in
        the grid and every uncovered cell meeting that box is proven disjoint from P
        (``P.intersects_box`` answers False only with a proof). False: not proven (a P that
        touches an uncovered cell on a face is not proven either)."""
        n = len(self.edges)
        if P.is_empty():
            return True
        if not P.is_bounded():
            return False
        D = np.vstack([np.eye(n), -np.eye(n)])
        up = P._support_upper(D)
        hi, lo = up[:n], -up[n:]
        i0, i1 = [], []
        for j in range(n):
            e = self.edges[j]
            if not (lo[j] >= e[0] and hi[j] <= e[-1]) or e.size < 2:
                return False
            a = max(int(np.searchsorted(e, lo[j], side="left")) - 1, 0)
            b = min(int(np.searchsorted(e, hi[j], side="right")), e.size - 1)
            i0.append(a)
            i1.append(max(b, a + 1))
        block = self.covered[tuple(slice(a, b) for a, b in zip(i0, i1, strict=True))]
        idx = np.argwhere(~block)
        if idx.shape[0] == 0:
            return True
        cells = np.empty((idx.shape[0], n, 2))
        for j in range(n):
            k = idx[:, j] + i0[j]
            cells[:, j, 0] = self.edges[j][k]
            cells[:, j, 1] = self.edges[j][k + 1]
        return not bool(np.asarray(P.intersects_box(cells), dtype=bool).any())

    def _count(self, i0: list[np.ndarray], i1: list[np.ndarray]) -> np.ndarray:
        """Covered cells in the index blocks ``i0[j] <= i < i1[j]`` (empty blocks give 0)."""
        n = len(i0)
        tot = np.zeros(i0[0].shape[0], dtype=np.int64)
        for bits in itertools.product((0, 1), repeat=n):
            idx = tuple(i1[j] if bit else i0[j] for j, bit in enumerate(bits))
            tot += (-1) ** (n - sum(bits)) * self.table[idx]
        return tot

    def contains(self, Q: np.ndarray) -> np.ndarray:
        thin = (Q[..., 1] <= Q[..., 0]).any(axis=1)
        if thin.any():
            out = np.zeros(Q.shape[0], dtype=bool)
            out[thin] = _covered(Q[thin], self.all)
            if (~thin).any():
                out[~thin] = self.contains(Q[~thin])
            return out
        n = Q.shape[1]
        ok = np.isfinite(Q).all(axis=(1, 2))
        i0, i1, vol = [], [], np.ones(Q.shape[0], dtype=np.int64)
        for j in range(n):
            e = self.edges[j]
            lo, hi = Q[:, j, 0], Q[:, j, 1]
            if e.size == 1:  # every box flat in j: only cells of no extent
                ok &= False
                i0.append(np.zeros(Q.shape[0], dtype=np.intp))
                i1.append(np.zeros(Q.shape[0], dtype=np.intp))
                continue
            ok &= (lo >= e[0]) & (hi <= e[-1])
            a = np.searchsorted(e, lo, side="right") - 1  # e[a] <= lo
            b = np.searchsorted(e, hi, side="left")  # e[b] >= hi
            a = np.clip(a, 0, e.size - 2)
            b = np.clip(b, a + 1, e.size - 1)
            i0.append(a)
            i1.append(b)
            vol *= b - a
        return ok & (self._count(i0, i1) == vol)

    def intersects(self, Q: np.ndarray) -> np.ndarray:
        n = Q.shape[1]
        fin = np.isfinite(Q).all(axis=(1, 2))
        meet = np.ones(Q.shape[0], dtype=bool)
        i0, i1 = [], []
        for j in range(n):
            e = self.edges[j]
            lo, hi = Q[:, j, 0], Q[:, j, 1]
            meet &= (hi >= e[0]) & (lo <= e[-1])
            if e.size == 1:
                i0.append(np.zeros(Q.shape[0], dtype=np.intp))
                i1.append(np.ones(Q.shape[0], dtype=np.intp))
                continue
            # cells [e[i], e[i+1]] with e[i+1] >= lo and e[i] <= hi
            a = np.searchsorted(e, lo, side="left") - 1
            b = np.searchsorted(e, hi, side="right")
            a = np.clip(a, 0, e.size - 2)
            b = np.clip(b, a + 1, e.size - 1)
            i0.append(a)
            i1.append(b)
        got = meet & (self._count(i0, i1) > 0)
        if self.flat.shape[0]:
            ia, _ = _pairs(Q, self.flat)
            got[ia] = True
        return np.where(fin, got, True)


def _union_volume(U: np.ndarray) -> float:
    """Exact volume of a union of boxes (overlaps counted once).

    Box ``j`` contributes the part of it not covered by the boxes ``i < j``; that part is
    computed only for the boxes that overlap an earlier one, by the rounds of
    :func:`_covered` restricted to overlaps with a non-empty interior.
    """
    if U.shape[0] == 0:
        return 0.0
    vols = box_volume(U)
    ia, ib = _pairs(U, U, strict=True)
    keep = ia < ib
    ia, ib = ia[keep], ib[keep]
    if ia.size == 0:
        return float(vols.sum())
    later = np.unique(ib)
    free = np.ones(U.shape[0], dtype=bool)
    free[later] = False
    total = float(vols[free].sum())
    vid = np.unique(ia)
    V = U[vid]
    pieces = U[later].copy()
    owner = later.copy()
    while pieces.shape[0]:
        ip, jb = _pairs(pieces, V, strict=True)
        ok = vid[jb] < owner[ip]
        ip, jb = ip[ok], jb[ok]
        has = np.zeros(pieces.shape[0], dtype=bool)
        has[ip] = True
        total += float(box_volume(pieces[~has]).sum())
        if ip.size == 0:
            break
        rows, sel = _pick_one(ip, pieces[ip], V[jb])
        pieces, owner = _subtract_rows(pieces[rows], owner[rows], V[jb[sel]])
    return total


def _box_array(data: Any, n: int | None, name: str) -> np.ndarray:
    if isinstance(data, Sequence) and not isinstance(data, str):
        if len(data) == 0 and n is not None:
            data = np.zeros((0, n, 2))
        elif len(data) and all(isinstance(x, Box) for x in data):
            data = np.stack([x.as_array() for x in data])
    arr = np.array(as_boxes(data, n, name), dtype=float)
    arr.setflags(write=False)
    return arr


def _support_of_boxes(U: np.ndarray, D: np.ndarray) -> np.ndarray:
    """``max_j sum_l max(D_il lo_jl, D_il hi_jl)`` for each direction ``i``: shape (k,)."""
    if U.shape[0] == 0:
        return np.full(D.shape[0], -np.inf)
    if np.isfinite(U).all():
        return (np.maximum(D, 0.0) @ U[..., 1].T + np.minimum(D, 0.0) @ U[..., 0].T).max(axis=1)
    out = np.full(D.shape[0], -np.inf)
    step = max(1, _PAIR_BUDGET // max(1, U.shape[0] * U.shape[1]))
    for k0 in range(0, D.shape[0], step):
        d = D[k0:k0 + step, None, :]
        with np.errstate(invalid="ignore"):
            s = np.where(d == 0, 0.0, np.maximum(d * U[None, :, :, 0], d * U[None, :, :, 1]))
        out[k0:k0 + step] = s.sum(axis=2).max(axis=1)
    return out


def _corners(U: np.ndarray) -> np.ndarray:
    n = U.shape[1]
    bits = ((np.arange(2 ** n)[:, None] >> np.arange(n)) & 1).astype(np.intp)
    return U[:, np.arange(n)[None, :], bits].reshape(-1, n)


# ======================================================================== Paving
class Paving(SetBase):
    """A finite union of boxes, labelled with the three views of set inversion.

    Parameters
    ----------
    inner : array_like, shape (N_i, n, 2), or Box, or list of Box, optional
        Boxes proven inside the target set (SIVIA's Σ).
    boundary : array_like, shape (N_b, n, 2), or Box, or list of Box, optional
        Undecided boxes, narrower than the resolution ``eps`` (SIVIA's Σ^b).
    outside : array_like, shape (N_o, n, 2), or Box, or list of Box, optional
        Boxes proven outside the target set (discarded). A solver may keep them to draw the
        complement, or drop them and only count them in ``n_discarded``.
    domain : Box or array_like, shape (n, 2), optional
        The initial box the paving was built from; every box must lie in it.
    n_discarded : int, optional
        Number of boxes discarded as proven outside; defaults to ``len(outside)``.
    outer : deprecated
        Old name of ``outside`` (keyword only; emits a DeprecationWarning).

    Attributes
    ----------
    inner, boundary, outside : ndarray, shape (N, n, 2)
        Read-only arrays (possibly with ``N = 0``). ``outer`` is a deprecated alias of
        ``outside`` (it emits a DeprecationWarning).
    domain : Box or None
    n_discarded : int

    Raises
    ------
    DimensionError
        The arrays disagree in dimension, or no argument fixes the dimension.
    InvalidBoundsError, EmptySetError
        NaN bounds, a box with ``lo > hi``, or a box outside ``domain``.

    Notes
    -----
    **Which set is represented.** A paving stands for the *outer approximation* of the
    target set, ``inner ∪ boundary``: the protocol members ``contains``, ``contains_box``,
    ``intersects_box``, ``support``, ``bounding_box``, ``vertices`` and ``is_empty`` use it
    by default. The measures :meth:`volume` and :meth:`area` are the exception: by default
    they count the proven part only (view ``"inner"``), never undecided boxes. Each of them
    takes ``view=`` to choose another union:

    ``"outer"`` (default, except for ``volume`` and ``area``)
        ``inner ∪ boundary``: every point of the target set in the domain is in it.
    ``"inner"`` (default of ``volume`` and ``area``)
        ``inner``: every point of it is proven inside the target set.
    ``"boundary"``
        ``boundary`` only.
    ``"outside"``
        the ``outside`` boxes: every point of them is proven outside the target set.

    The *view* ``"outer"`` is the outer approximation; the discarded boxes are the attribute
    and view ``outside`` (the attribute was called ``outer`` before, a name kept as a
    deprecated alias).
    :meth:`inner_set` and :meth:`outer_set` return the two approximations as pavings of
    their own.

    A subpaving from bisection (thesis §4.1.1) has boxes with disjoint interiors; the
    paving does not require it (after :meth:`union` boxes may overlap) and its volume
    counts overlaps once.

    Examples
    --------
    >>> import numpy as np
    >>> import casadi_cmpc as cm
    >>> P = cm.Paving(inner=cm.Box([0, 0], [1, 1]), boundary=[cm.Box([1, 0], [2, 1])])
    >>> P.n_boxes, P.volume(), P.volume(view="outer")
    (2, 1.0, 2.0)
    >>> P.contains([1.5, 0.5]), P.contains([1.5, 0.5], view="inner")
    (True, False)
    """

    def __init__(self, inner: Any = None, boundary: Any = None, outside: Any = None,
                 domain: Any = None, *, n_discarded: int | None = None,
                 outer: Any = None) -> None:
        outside = _outside_keyword(outside, outer, "Paving()")
        if domain is not None:
            if not isinstance(domain, Box):
                d = np.asarray(domain, dtype=float)
                if d.ndim == 3 and d.shape[0] == 1:
                    d = d[0]
                domain = Box.from_array(d)
        n = domain.dim if domain is not None else None
        arrays = {}
        for name, data in (("inner", inner), ("boundary", boundary), ("outside", outside)):
            if data is not None:
                arrays[name] = _box_array(data, n, name)
                n = arrays[name].shape[1]
        if n is None:
            raise DimensionError(
                "Paving needs its dimension: give a domain Box or at least one box array "
                "(an empty array of shape (0, n, 2) is fine)")
        for name in ("inner", "boundary", "outside"):
            if name not in arrays:
                arrays[name] = _box_array(np.zeros((0, n, 2)), n, name)
        if domain is not None:
            for name, arr in arrays.items():
                out = ~domain.contains_box(arr) if arr.shape[0] else np.zeros(0, dtype=bool)
                if out.any():
                    i = int(np.flatnonzero(out)[0])
                    raise InvalidBoundsError(
                        f"{name} box {i} = {arr[i].tolist()} is not inside the domain {domain}")
        if n_discarded is None:
            n_discarded = arrays["outside"].shape[0]
        if int(n_discarded) != n_discarded or n_discarded < 0:
            raise ValueError(f"n_discarded must be a non-negative integer; got {n_discarded!r}")
        self._n = int(n)
        self.inner: np.ndarray = arrays["inner"]
        self.boundary: np.ndarray = arrays["boundary"]
        self.outside: np.ndarray = arrays["outside"]
        self.domain: Box | None = domain
        self.n_discarded = int(n_discarded)
        self._cache: dict[str, Any] = {}

    @classmethod
    def _from_solver(cls, inner: np.ndarray, boundary: np.ndarray, outside: np.ndarray,
                     domain: Box, n_discarded: int) -> Paving:
        """A paving from boxes a solver produced by bisecting ``domain``: float arrays of
        shape (N, n, 2) with lo <= hi, each box inside the domain, so no checks are made."""
        self = cls.__new__(cls)
        for arr in (inner, boundary, outside):
            arr.setflags(write=False)
        self._n = domain.dim
        self.inner, self.boundary, self.outside = inner, boundary, outside
        self.domain = domain
        self.n_discarded = int(n_discarded)
        self._cache = {}
        return self

    @property
    def outer(self) -> np.ndarray:
        """Deprecated alias of :attr:`outside` (the proven-outside boxes).

        Not to be confused with the *view* ``"outer"`` (``inner ∪ boundary``).
        """
        _warn_outer("Paving.outer")
        return self.outside

    # ---------------------------------------------------------------- views
    @property
    def boxes(self) -> np.ndarray:
        """The boxes of the represented set, ``inner`` then ``boundary``; shape (N, n, 2)."""
        if "boxes" not in self._cache:
            b = np.concatenate([self.inner, self.boundary])
            b.setflags(write=False)
            self._cache["boxes"] = b
        return self._cache["boxes"]

    def view_boxes(self, view: str = "outer") -> np.ndarray:
        """The boxes of one view.

        Parameters
        ----------
        view : {"outer", "inner", "boundary", "outside"}
            ``"outer"``: ``inner ∪ boundary`` (the default, the represented set);
            ``"outside"``: the discarded boxes of the attribute ``outside``.

        Returns
        -------
        ndarray, shape (N, n, 2)
        """
        v = str(view).lower()
        if v == "outer":
            return self.boxes
        if v == "inner":
            return self.inner
        if v == "boundary":
            return self.boundary
        if v == "outside":
            return self.outside
        raise ValueError(f"Unknown view {view!r}; valid views: {_VIEWS} ('outer' is "
                         "inner ∪ boundary, 'outside' the discarded boxes)")

    def inner_set(self) -> Paving:
        """The inner approximation as a paving: only the ``inner`` boxes (all proven inside)."""
        return Paving(inner=self.inner, domain=self.domain, n_discarded=0)

    def outer_set(self) -> Paving:
        """The outer approximation as a paving: ``inner`` and ``boundary``, no outside boxes."""
        return Paving(inner=self.inner, boundary=self.boundary, domain=self.domain,
                      n_discarded=0)

    @property
    def n_inner(self) -> int:
        """Number of inner boxes."""
        return int(self.inner.shape[0])

    @property
    def n_boundary(self) -> int:
        """Number of boundary boxes."""
        return int(self.boundary.shape[0])

    @property
    def n_outside(self) -> int:
        """Number of stored outside (discarded) boxes."""
        return int(self.outside.shape[0])

    @property
    def n_outer(self) -> int:
        """Deprecated alias of :attr:`n_outside`."""
        _warn_outer("Paving.n_outer")
        return self.n_outside

    @property
    def n_boxes(self) -> int:
        """Number of boxes of the represented set, ``n_inner + n_boundary``."""
        return self.n_inner + self.n_boundary

    def __len__(self) -> int:
        return self.n_boxes

    # ------------------------------------------------------------- protocol
    @property
    def dim(self) -> int:
        """Dimension n."""
        return self._n

    def is_empty(self, view: str = "outer") -> bool:
        """True when the view holds no box (then it is empty; boxes are never empty)."""
        return self.view_boxes(view).shape[0] == 0

    def contains(self, points: Any, view: str = "outer") -> np.ndarray | bool:
        """Membership of points in the union of the boxes of a view (bounds included).

        Parameters
        ----------
        points : array_like, shape (P, n) or (n,)
        view : {"outer", "inner", "boundary", "outside"}

        Returns
        -------
        bool or ndarray of bool, shape (P,)
        """
        p, batched = as_points(points, self._n, name="points")
        U = self.view_boxes(view)
        pb = np.stack([p, p], axis=-1)
        res = np.zeros(p.shape[0], dtype=bool)
        ia, _ = _pairs(pb, U)
        res[ia] = True
        return res if batched else bool(res[0])

    def contains_box(self, boxes: Any, view: str = "outer") -> np.ndarray:
        """Exact test ``box ⊆ union of the boxes of a view``, for a batch of boxes.

        Parameters
        ----------
        boxes : array_like, shape (N, n, 2) or (n, 2), or Box
        view : {"outer", "inner", "boundary", "outside"}

        Returns
        -------
        ndarray of bool, shape (N,)

        Notes
        -----
        A box covered by one box of the union is found by one vectorised comparison. The
        others are covered by several boxes together or not at all: the boxes meeting them
        are subtracted one after another (a box minus a box is at most ``2 n`` boxes) until
        nothing or a part outside every box is left. The test is exact on closed boxes.
        """
        q = as_boxes(boxes, self._n, "boxes")
        grid = self._grid(view, q.shape[0])
        if grid is not None:
            return grid.contains(q)
        return _covered(q, self.view_boxes(view))

    def _grid(self, view: str, n_queries: int) -> _BoxGrid | None:
        """The exact grid index of a view (built once, for unions of 64 boxes or more)."""
        key = ("grid", str(view).lower())
        if key in self._cache:
            return self._cache[key]
        U = self.view_boxes(view)
        if U.shape[0] < 64:
            return None
        if key not in self._cache:
            self._cache[key] = _BoxGrid.build(U)
        return self._cache[key]

    def intersects_box(self, boxes: Any, view: str = "outer") -> np.ndarray:
        """Exact test ``box ∩ union ≠ ∅`` (closed boxes: a shared face counts).

        Parameters
        ----------
        boxes : array_like, shape (N, n, 2) or (n, 2), or Box
        view : {"outer", "inner", "boundary", "outside"}

        Returns
        -------
        ndarray of bool, shape (N,)
        """
        q = as_boxes(boxes, self._n, "boxes")
        grid = self._grid(view, q.shape[0])
        if grid is not None:
            return grid.intersects(q)
        res = np.zeros(q.shape[0], dtype=bool)
        ia, _ = _pairs(q, self.view_boxes(view))
        res[ia] = True
        return res

    def support(self, directions: Any, view: str = "outer") -> np.ndarray | float:
        """Support function ``h(d) = max over the boxes of the box support``.

        Parameters
        ----------
        directions : array_like, shape (k, n) or (n,)
        view : {"outer", "inner", "boundary", "outside"}

        Returns
        -------
        float or ndarray, shape (k,)
            ``-inf`` for an empty view.
        """
        D = np.asarray(directions, dtype=float)
        single = D.ndim == 1
        D = np.atleast_2d(D)
        if D.ndim != 2 or D.shape[1] != self._n:
            raise DimensionError(f"directions must have shape (k, {self._n}) or "
                                 f"({self._n},); got {np.shape(directions)}")
        val = _support_of_boxes(self.view_boxes(view), D)
        return float(val[0]) if single else val

    def bounding_box(self, view: str = "outer") -> Box:
        """Interval hull of the boxes of a view.

        Raises
        ------
        EmptySetError
            The view holds no box.
        """
        U = self.view_boxes(view)
        if U.shape[0] == 0:
            raise EmptySetError(f"the {view!r} view of this paving is empty; it has no "
                                "bounding box")
        return Box.from_array(hull_of_boxes(U))

    def vertices(self, view: str = "outer") -> np.ndarray:
        """Points whose convex hull is the convex hull of the union, shape (k, n).

        For ``n <= 3`` the vertices of the convex hull of all box corners (all distinct
        corners when the hull is flat or unbounded); for ``n > 3`` all distinct corners.
        ``(0, n)`` for an empty view.
        """
        U = self.view_boxes(view)
        n = self._n
        if U.shape[0] == 0:
            return np.zeros((0, n))
        if n == 1:
            h = hull_of_boxes(U)
            return np.unique(h.reshape(2, 1), axis=0)
        pts = np.unique(_corners(U), axis=0)
        if n <= 3 and len(pts) > n + 1 and np.isfinite(pts).all():
            from scipy.spatial import ConvexHull, QhullError

            try:
                return pts[np.sort(ConvexHull(pts).vertices)]
            except (QhullError, ValueError):
                return pts
        return pts

    # ------------------------------------------------------------- measures
    def volume(self, view: str = "inner") -> float:
        """Volume of the union of the boxes of a view (overlaps counted once).

        Parameters
        ----------
        view : {"inner", "outer", "boundary", "outside"}
            ``"inner"`` (default): the proven part only, a lower bound of the volume of the
            target set in the domain; ``"outer"``: inner and undecided boxes, an upper bound
            of it; ``"boundary"``: the undecided boxes; ``"outside"``: the boxes proven
            outside.

        Returns
        -------
        float
            In the units of the state product (e.g. an area in 2-D); 0.0 for an empty view.
        """
        v = str(view).lower()
        key = "volume:" + v
        if key not in self._cache:
            self._cache[key] = _union_volume(self.view_boxes(v))
        return self._cache[key]

    def area(self, view: str = "inner") -> float:
        """Area of a 2-D paving (alias of :meth:`volume`; by default of the proven part).

        Raises
        ------
        DimensionError
            The paving is not 2-dimensional.
        """
        if self._n != 2:
            raise DimensionError(
                f"area requires a paving of dimension 2 but received a {self._n}-dimensional "
                "one; use volume()")
        return self.volume(view)

    # ----------------------------------------------------------- operations
    def union(self, other: Paving | Box) -> Paving:
        """Union of two pavings (or a paving and a Box, taken as proven inside).

        ``inner`` and ``boundary`` boxes are concatenated; the outside boxes of the result
        are the intersections of the outside boxes of both (outside both sets); the domain
        is the hull of both domains (None when one is unknown).

        Parameters
        ----------
        other : Paving or Box

        Returns
        -------
        Paving
        """
        other = held_set(other)  # a solver's result: its paving
        if isinstance(other, Box):
            other = Paving(inner=other)
        if not isinstance(other, Paving):
            raise TypeError(f"cannot unite a Paving with a {type(other).__name__}")
        if other.dim != self._n:
            raise DimensionError(
                f"cannot unite pavings of dimensions {self._n} and {other.dim}")
        A, B = self.outside, other.outside
        ia, ib = _pairs(A, B)
        lo = np.maximum(A[ia, :, 0], B[ib, :, 0])
        hi = np.minimum(A[ia, :, 1], B[ib, :, 1])
        flat_a = A[ia, :, 0] == A[ia, :, 1]
        flat_b = B[ib, :, 0] == B[ib, :, 1]
        keep = ((lo < hi) | flat_a | flat_b).all(axis=1)  # drop mere face contacts
        outside = np.stack([lo[keep], hi[keep]], axis=-1).reshape(-1, self._n, 2)
        domain = None
        if self.domain is not None and other.domain is not None:
            domain = self.domain | other.domain
        return Paving(inner=np.concatenate([self.inner, other.inner]),
                      boundary=np.concatenate([self.boundary, other.boundary]),
                      outside=outside, domain=domain)

    def __or__(self, other: Any) -> Paving:
        if not isinstance(other, (Paving, Box)):
            return NotImplemented
        return self.union(other)

    def __ror__(self, other: Any) -> Paving:
        if not isinstance(other, (Paving, Box)):
            return NotImplemented
        return self.union(other)

    # ------------------------------------------------------------- plotting
    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), *,
             show_outer: bool = False, legend: bool = True,
             colors: dict[str, Any] | None = None, labels: dict[str, str] | None = None,
             **kw: Any) -> Any:
        """Draw the paving: inner (green), boundary (yellow), optionally outside (grey-blue).

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Created when omitted.
        dims : (int, int)
            Coordinates drawn for ``n >= 2``; for ``n > 2`` the boxes are projected on them
            (identical projections drawn once). A 1-D paving is drawn as intervals on a line.
        show_outer : bool
            Also draw the outside (discarded) boxes.
        legend : bool
            Add a legend with one entry per drawn category, outside the axes (right).
        colors, labels : dict, optional
            Face colour and legend label per category ``"inner"``, ``"boundary"``,
            ``"outside"`` (the old key ``"outer"`` is a deprecated alias of ``"outside"``).
        **kw
            Passed to every ``PatchCollection`` (``edgecolor``, ``linewidth``, ``alpha``,
            ...); a ``facecolor`` here overrides ``colors``.

        Returns
        -------
        matplotlib Axes
            One collection per non-empty category drawn (outside, boundary, inner, in
            that order), one rectangle per box.
        """
        from ..plot import legend_outside, new_axes, plot_boxes

        n = self._n
        if n >= 2:
            i, j = (int(dims[0]), int(dims[1]))
            if i == j or not (0 <= i < n and 0 <= j < n):
                raise DimensionError(
                    f"dims must be two distinct coordinates in 0..{n - 1}; got {tuple(dims)}")
            sel = [i, j]
        else:
            sel = [0]
        col = {**_DEFAULT_COLORS, **_outside_key(colors, "colors")}
        lab = {**_DEFAULT_LABELS, **_outside_key(labels, "labels")}
        cats = [("outside", self.outside)] if show_outer else []
        cats += [("boundary", self.boundary), ("inner", self.inner)]
        drawn = {name: arr[:, sel, :] for name, arr in cats if arr.shape[0]}
        if n > 2:
            drawn = {k: np.unique(v, axis=0) for k, v in drawn.items()}
        drawn = _clip_infinite(drawn, None if self.domain is None else
                               self.domain.as_array()[sel])
        ax = new_axes(ax)
        for name, arr in drawn.items():
            style = {k: v for k, v in kw.items() if k != "label"}
            style.setdefault("facecolor", col[name])
            plot_boxes(arr, ax=ax, dims=(0, 1), label=lab[name], **style)
        if legend and drawn:
            legend_outside(ax)
        return ax

    # ---------------------------------------------------------- persistence
    def _state(self) -> dict[str, Any]:
        return {
            "dim": self._n,
            "inner": np.array(self.inner),
            "boundary": np.array(self.boundary),
            "outside": np.array(self.outside),
            "domain": None if self.domain is None else self.domain.as_array(),
            "n_discarded": self.n_discarded,
        }

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> Paving:
        n = int(state["dim"])
        state = dict(state)
        if "outside" not in state and "outer" in state:  # files written before the rename
            state["outside"] = state["outer"]
        arrs = {k: np.asarray(state[k], dtype=float).reshape(-1, n, 2)
                for k in ("inner", "boundary", "outside")}
        dom = state.get("domain")
        domain = None if dom is None else Box.from_array(np.asarray(dom, dtype=float))
        return cls(**arrs, domain=domain, n_discarded=int(state["n_discarded"]))

    def __repr__(self) -> str:
        return (f"Paving(dim={self._n}, inner={self.n_inner}, boundary={self.n_boundary}, "
                f"outside={self.n_outside}, n_discarded={self.n_discarded}, "
                f"domain={self.domain!r})")


def _outside_key(d: dict[str, Any] | None, what: str) -> dict[str, Any]:
    """A copy of a per-category dict with the deprecated key ``"outer"`` renamed."""
    d = dict(d or {})
    if "outer" in d:
        _warn_outer(f"the key 'outer' of {what}=", stacklevel=4)
        d.setdefault("outside", d.pop("outer"))
    return d


def _clip_infinite(drawn: dict[str, np.ndarray], domain: np.ndarray | None
                   ) -> dict[str, np.ndarray]:
    """Replace infinite bounds by finite ones just beyond the finite data (for drawing)."""
    if all(np.isfinite(v).all() for v in drawn.values()):
        return drawn
    parts = list(drawn.values()) + ([] if domain is None else [domain[None]])
    allv = np.concatenate(parts)
    fin = np.isfinite(allv)
    lo = np.where(fin, allv, np.inf).min(axis=(0, 2))
    hi = np.where(fin, allv, -np.inf).max(axis=(0, 2))
    lo = np.where(np.isfinite(lo), lo, np.where(np.isfinite(hi), hi - 1.0, -1.0))
    hi = np.where(np.isfinite(hi), hi, lo + 2.0)
    pad = np.maximum(0.1 * (hi - lo), 1.0)
    return {k: np.clip(v, (lo - pad)[None, :, None], (hi + pad)[None, :, None])
            for k, v in drawn.items()}
