"""Exact tests on finite unions of closed boxes (batches ``(N, n, 2)``).

* :func:`_pairs`: all intersecting pairs of two batches, by a sweep line along the first
  coordinate (per class of widths) for large batches;
* :func:`_covered`: ``Q ⊆ ∪ U`` by subtracting boxes from pieces of the queries;
* :class:`_BoxGrid`: an exact index of a union on the grid of its own bounds (prefix sums of
  the covered cells) for many queries against one union;
* :func:`_union_volume`: the volume of a union, overlaps counted once.

These are the machinery of :class:`~casadi_cmpc.Paving`.
"""

from __future__ import annotations

import ctypes
import itertools
from typing import Any

import numpy as np

from ._boxes import _PAIR_BUDGET, box_volume

__all__: list[str] = []


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
    """The candidate pairs ``(ia, ib)`` (index arrays of equal length) whose boxes ``A[ia]``,
    ``B[ib]`` meet: closed boxes (``strict=False``) or in a set of positive volume."""
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


# The grid tests of :class:`_BoxGrid` as one C loop over the queries (binary searches in the
# edges and the 2**n look-ups of the count table of each query in registers): the same
# exact comparisons as the numpy code below, which evaluates where no C compiler is found.
_GRID_C = r"""
#include <math.h>
#include <stdint.h>

/* The index searches start from a hint when the edges of a coordinate lie on a uniform
   grid glo + k h (hint[k]: the number of edges below grid point k), found in O(1); the
   walks then end on the exact answer whatever the hint (comparisons with the edges only).
   ginv == 0: no hint, binary search. */
static int64_t hint_of(double x, double glo, double ginv, const int64_t *hint, int64_t K)
{
    double t = (x - glo) * ginv;
    int64_t k;
    if (!(t >= 0.0)) k = 0; else if (t >= (double)K) k = K; else k = (int64_t)t;
    return hint[k];
}

static int64_t lower_bound(const double *e, int64_t m, double x, double glo, double ginv,
                           const int64_t *hint, int64_t K)
{   /* first i with e[i] >= x */
    if (ginv != 0.0) {
        int64_t i = hint_of(x, glo, ginv, hint, K);
        while (i > 0 && e[i - 1] >= x) i--;
        while (i < m && e[i] < x) i++;
        return i;
    }
    int64_t lo = 0, hi = m;
    while (lo < hi) {
        int64_t mid = lo + (hi - lo) / 2;
        if (e[mid] < x) lo = mid + 1; else hi = mid;
    }
    return lo;
}

static int64_t upper_bound(const double *e, int64_t m, double x, double glo, double ginv,
                           const int64_t *hint, int64_t K)
{   /* first i with e[i] > x */
    if (ginv != 0.0) {
        int64_t i = hint_of(x, glo, ginv, hint, K);
        while (i > 0 && e[i - 1] > x) i--;
        while (i < m && e[i] <= x) i++;
        return i;
    }
    int64_t lo = 0, hi = m;
    while (lo < hi) {
        int64_t mid = lo + (hi - lo) / 2;
        if (e[mid] <= x) lo = mid + 1; else hi = mid;
    }
    return lo;
}

/* one loop over the queries; n is a constant where the dispatcher below inlines it, so
   that the loops over the coordinates and the 2**n corners are unrolled */
static inline __attribute__((always_inline)) void grid_query(
    int64_t N, const int64_t n, const double *q, const double *edges, const int64_t *off,
    const int64_t *table, const int64_t *stride, int64_t contains, int8_t *out,
    const double *glo, const double *ginv, const int64_t *hints, const int64_t *hoff)
{
    int64_t a[32], b[32];
    for (int64_t k = 0; k < N; k++) {
        const double *Q = q + 2 * n * k;
        int fin = 1, ok = 1;
        int64_t vol = 1;
        for (int64_t j = 0; j < n; j++) {
            const double lo = Q[2 * j], hi = Q[2 * j + 1];
            const double *e = edges + off[j];
            const int64_t m = off[j + 1] - off[j];
            const int64_t *h = hints + hoff[j], K = hoff[j + 1] - hoff[j] - 1;
            int64_t aj, bj;
            if (lo != lo || hi != hi) fin = 0;  /* NaN: possibly anything */
            if (m == 1) {  /* every box flat in j */
                if (contains) ok = 0; else ok &= (hi >= e[0]) && (lo <= e[0]);
                aj = 0; bj = 1;
            } else {
                if (contains) {
                    ok &= (lo >= e[0]) && (hi <= e[m - 1]);
                    aj = upper_bound(e, m, lo, glo[j], ginv[j], h, K) - 1;  /* e[a] <= lo */
                    bj = lower_bound(e, m, hi, glo[j], ginv[j], h, K);      /* e[b] >= hi */
                } else {
                    ok &= (hi >= e[0]) && (lo <= e[m - 1]);
                    aj = lower_bound(e, m, lo, glo[j], ginv[j], h, K) - 1;
                    bj = upper_bound(e, m, hi, glo[j], ginv[j], h, K);
                }
                if (aj < 0) aj = 0;
                if (aj > m - 2) aj = m - 2;
                if (bj < aj + 1) bj = aj + 1;
                if (bj > m - 1) bj = m - 1;
                vol *= bj - aj;
            }
            a[j] = aj; b[j] = bj;
        }
        if (!fin) { out[k] = contains ? 0 : 1; continue; }
        if (!ok) { out[k] = 0; continue; }
        int64_t tot = 0;
        for (int64_t c = 0; c < ((int64_t)1 << n); c++) {
            int64_t idx = 0; int na = 0;
            for (int64_t j = 0; j < n; j++) {
                if ((c >> j) & 1) idx += b[j] * stride[j]; else { idx += a[j] * stride[j]; na++; }
            }
            tot += (na & 1) ? -table[idx] : table[idx];
        }
        out[k] = contains ? (tot == vol) : (tot > 0);
    }
}

void cmpc_grid_query(int64_t N, int64_t n, const double *q, const double *edges,
                     const int64_t *off, const int64_t *table, const int64_t *stride,
                     int64_t contains, int8_t *out, const double *glo, const double *ginv,
                     const int64_t *hints, const int64_t *hoff)
{
#define CMPC_GQ(NN) grid_query(N, NN, q, edges, off, table, stride, contains, out, glo, \
                               ginv, hints, hoff)
    switch (n) {
    case 1: CMPC_GQ(1); break;
    case 2: CMPC_GQ(2); break;
    case 3: CMPC_GQ(3); break;
    case 4: CMPC_GQ(4); break;
    default: CMPC_GQ(n);
    }
#undef CMPC_GQ
}
"""
_GRID_MAX_N = 16  # dimensions of the C loop (2**n look-ups per query)


_GRID_ARGS = [ctypes.c_int64, ctypes.c_int64] + [ctypes.c_void_p] * 5 + [ctypes.c_int64] \
    + [ctypes.c_void_p] * 5


def _grid_kernel(wait: bool = False) -> Any:
    """The C grid query, or None (no compiler, ``CMPC_NATIVE=0``, or, with ``wait=False``,
    still compiling: the numpy code answers meanwhile, with the same exact answers)."""
    from ..interval._native import c_function

    return c_function(_GRID_C, "cmpc_grid_query", _GRID_ARGS, wait)


def _unique_inverse(B: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, tuple[float, float, np.ndarray] | None]:
    """The distinct bounds of the intervals ``B`` (N, 2), sorted, and the index of each of
    the ``2 N`` bounds among them (``np.unique(B.ravel(), return_inverse=True)``).

    In linear time when the bounds lie on the grid ``min + k h`` of the smallest positive
    width ``h`` (a paving made by bisection): the codes ``k = rint((v - min) / h)`` are
    accepted only if ``min + k h`` gives every bound back exactly, and then they are a
    function of the value, injective (equal codes give equal values) and monotone, so
    they order the bounds as the values do. Otherwise by sorting. Third: ``(min, h, codes
    of the distinct bounds)`` on the fast path, else None."""
    v = B.ravel()
    if B.shape[0] > 128 and np.isfinite(v).all():
        w = B[:, 1] - B[:, 0]
        w = w[w > 0]
        if w.size:
            lo, h = float(v.min()), float(w.min())
            k = np.rint((v - lo) / h)
            if k.max() <= 4 * v.size + 64:
                k = k.astype(np.int64)
                if (lo + k * h == v).all():
                    present = np.bincount(k) > 0
                    rank = np.cumsum(present) - 1
                    codes = np.flatnonzero(present)
                    return lo + codes * h, rank[k], (lo, h, codes)
    e, inv = np.unique(v, return_inverse=True)
    return e, inv.reshape(-1), None


def _clip_block(a: np.ndarray, b: np.ndarray, n_edges: int) -> None:
    """In place: cell index ranges ``[a, b)`` clipped to the grid of ``n_edges`` edges and
    holding at least one cell (``a`` in ``[0, n_edges - 2]``, ``b`` in ``[a + 1, n_edges -
    1]``)."""
    np.maximum(a, 0, out=a)
    np.minimum(a, n_edges - 2, out=a)
    np.maximum(b, a + 1, out=b)
    np.minimum(b, n_edges - 1, out=b)


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
        """The index of the union of the boxes ``U`` (N, n, 2), or None (empty, infinite,
        all flat, or more than :data:`MAX_CELLS` cells)."""
        if U.shape[0] == 0 or not np.isfinite(U).all():
            return None
        n = U.shape[1]
        flat = (U[..., 1] <= U[..., 0]).any(axis=1)
        if flat.all():
            return None
        full = U
        U = U[~flat]
        # the distinct bounds per coordinate, and each bound's index among them (exactly
        # the searchsorted index of the bound: it is one of the edges)
        edges, a, b, grids = [], [], [], []
        for j in range(n):
            e, inv, grid = _unique_inverse(U[:, j, :])
            edges.append(e)
            grids.append(grid)
            a.append(inv[0::2])  # first cell
            b.append(inv[1::2])  # one past the last
        shape = tuple(max(e.size - 1, 1) for e in edges)
        if int(np.prod([s + 1 for s in shape], dtype=float)) > cls.MAX_CELLS:
            return None
        self = cls()
        self.all = full
        self.flat = full[flat]
        self.edges = edges
        self.shape = shape
        # difference array over the cells: +-1 at the 2**n corners of each box's index block
        keep = np.ones(U.shape[0], dtype=bool)
        for j in range(n):
            keep &= b[j] > a[j]  # flat boxes cover no cell
        dims = tuple(s + 1 for s in shape)
        size = int(np.prod(dims))
        diff = np.zeros(size, dtype=np.int64)
        for bits in itertools.product((0, 1), repeat=n):
            flat_idx = np.ravel_multi_index(
                tuple((b[j] if bit else a[j])[keep] for j, bit in enumerate(bits)), dims)
            count = np.bincount(flat_idx, minlength=size)
            if sum(bits) % 2:
                diff -= count
            else:
                diff += count
        diff = diff.reshape(dims)
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
        # the layout of the C loop: the edges end to end, their offsets, the table strides
        self._edges_cat = np.ascontiguousarray(np.concatenate(edges), dtype=np.float64)
        self._off = np.cumsum([0] + [e.size for e in edges]).astype(np.int64)
        self._stride = (np.asarray(table.strides, dtype=np.int64) // table.itemsize)
        # search hints of the coordinates whose edges lie on a uniform grid lo + k h: per
        # grid point k, the number of edges below it (see _GRID_C)
        glo, ginv, hints = np.zeros(n), np.zeros(n), []
        for j, grid in enumerate(grids):
            if grid is None or edges[j].size < 2:
                hints.append(np.zeros(1, dtype=np.int64))
                continue
            glo[j], ginv[j] = grid[0], 1.0 / grid[1]
            codes = grid[2]
            hints.append(np.searchsorted(codes, np.arange(codes[-1] + 1)).astype(np.int64))
        self._glo, self._ginv = glo, ginv
        self._hints = np.ascontiguousarray(np.concatenate(hints), dtype=np.int64)
        self._hoff = np.cumsum([0] + [h.size for h in hints]).astype(np.int64)
        self._addr = None  # the addresses of the arrays above for the C loop
        return self

    def __getstate__(self) -> dict[str, Any]:
        # a copy (a pickle sent to a worker, copy.copy) has arrays of its own: the addresses
        # of these are not its addresses
        return {**self.__dict__, "_addr": None}

    def _native(self, Q: np.ndarray, contains: bool) -> np.ndarray | None:
        """The C loop's answers for the queries ``Q`` (N, n, 2), or None (no kernel)."""
        n = Q.shape[1]
        if n > _GRID_MAX_N or Q.shape[0] == 0:
            return None
        fn = _grid_kernel()
        if fn is None:
            return None
        from ..interval._native import address as a

        Q = np.ascontiguousarray(Q, dtype=np.float64)
        out = np.empty(Q.shape[0], dtype=np.int8)
        if getattr(self, "_addr", None) is None:  # the index's arrays (never modified)
            self._addr = ((a(self._edges_cat), a(self._off), a(self.table), a(self._stride)),
                          (a(self._glo), a(self._ginv), a(self._hints), a(self._hoff)))
        fn(Q.shape[0], n, a(Q), *self._addr[0], int(contains), a(out), *self._addr[1])
        return out.view(bool)

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
        """Exact ``Q[i] ⊆ union`` for query boxes ``Q`` (N, n, 2): (N,) bool."""
        thin = (Q[..., 1] <= Q[..., 0]).any(axis=1)
        if thin.any():
            out = np.zeros(Q.shape[0], dtype=bool)
            out[thin] = _covered(Q[thin], self.all)
            if (~thin).any():
                out[~thin] = self.contains(Q[~thin])
            return out
        got = self._native(Q, True)
        if got is not None:
            return got
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
            _clip_block(a, b, e.size)
            i0.append(a)
            i1.append(b)
            vol *= b - a
        return ok & (self._count(i0, i1) == vol)

    def intersects(self, Q: np.ndarray) -> np.ndarray:
        """Exact ``Q[i] ∩ union ≠ ∅`` (closed boxes) for query boxes ``Q`` (N, n, 2): (N,)
        bool; exact for infinite bounds too, True for a query with a NaN bound (an
        enclosure that may be anything)."""
        got = self._native(Q, False)
        if got is None:
            got = self._intersects_numpy(Q)
        if self.flat.shape[0]:  # the boxes without cells, pair by pair
            ia, _ = _pairs(Q, self.flat)
            got[ia] = True
        return got

    def _intersects_numpy(self, Q: np.ndarray) -> np.ndarray:
        """:meth:`intersects` against the cells of the grid (the flat boxes aside)."""
        n = Q.shape[1]
        known = ~np.isnan(Q).any(axis=(1, 2))
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
            _clip_block(a, b, e.size)
            i0.append(a)
            i1.append(b)
        got = meet & (self._count(i0, i1) > 0)
        return np.where(known, got, True)


def _compact_union(U: np.ndarray) -> np.ndarray:
    """Boxes (K, n, 2) with the same closed union as ``U`` (N, n, 2), usually far fewer:
    the covered cells of the grid of ``U``'s bounds (:class:`_BoxGrid`), merged into runs
    along the last coordinate, each run one box whose bounds are bounds of ``U`` (exact);
    boxes of ``U`` of zero width in some coordinate are kept as they are. ``U`` itself when
    no grid is built (small, unbounded or too fine unions) or when the runs would not be
    fewer than the boxes."""
    G = _BoxGrid.build(U) if U.shape[0] >= 64 else None
    if G is None:
        return U
    n = U.shape[1]
    idx = np.argwhere(G.covered)  # (K, n), C order: runs along the last axis are adjacent
    if idx.shape[0] == 0:
        return G.flat
    last = idx[:, -1]
    brk = np.ones(idx.shape[0], dtype=bool)
    brk[1:] = (last[1:] != last[:-1] + 1) | (idx[1:, :-1] != idx[:-1, :-1]).any(axis=1)
    first = np.flatnonzero(brk)
    if first.size + G.flat.shape[0] >= U.shape[0]:  # no fewer boxes (e.g. tall thin ones)
        return U
    stop = np.append(first[1:], idx.shape[0]) - 1  # the last cell of each run
    out = np.empty((first.size, n, 2))
    for j in range(n):
        e = G.edges[j]
        out[:, j, 0] = e[idx[first, j]]
        out[:, j, 1] = e[idx[stop, j] + 1]
    return np.concatenate([out, G.flat]) if G.flat.shape[0] else out


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
