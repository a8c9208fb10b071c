"""Bisection of batches of boxes along their widest coordinate (thesis eqs. (4.2)-(4.4)).

Every box bisection of the library goes through :func:`bisect_widest`: the batched box
helpers (:func:`casadi_cmpc.sets.paving.bisect_boxes`), the frontiers of the
branch-and-bound engine (state boxes and control cells), the partitions of the semantic
extension of modal intervals and the interval matrices of the invariant-zonotope search.
The rule is the same everywhere:

* the split coordinate is the *first* one holding the largest width (:func:`widest`);
  what a width is (absolute, relative to a reference box, masked) is the caller's
  choice, passed as the ``widths`` array;
* the cut lies at ``ratio`` of the split coordinate, ``lo + ratio (hi - lo)``
  (:func:`cut_points`);
* the left halves ``[lo, c]`` come first, then the right halves ``[c, hi]``.

It lives at the top of the package because every layer (``interval``, ``sets``,
``solvers``, ``control``) bisects boxes.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np

__all__: list[str] = []

# The same rules as one C loop over the boxes (compiled once and cached like the interval
# kernels, :func:`casadi_cmpc.interval._native.load_symbol`): the widest coordinate of each
# box, and the halves of each box. Every operation is the one numpy performs below (IEEE
# double, no contraction), so both give the same bits; numpy answers where no compiler is
# found and while the loop compiles.
#: The rules as C functions, for every C loop that bisects (this module's and the pair
#: frontier's): ``cmpc_widest_row`` (the first widest coordinate of one box and its width,
#: widths divided by ``sc`` unless it is NULL; a NaN width propagates to the width, as
#: numpy.maximum does, and does not take the index) and ``cmpc_cut`` (the cut of [a, b] at
#: ratio r, ``0.5 a + 0.5 b`` for ``mid``, with the fallbacks of :func:`cut_points`).
RULES_C = r"""
#include <stdint.h>
#include <math.h>
static inline int64_t cmpc_widest_row(const double *l, const double *h, const double *sc,
                                      int64_t n, double *width)
{
    double b = h[0] - l[0];
    if (sc) b = b / sc[0];
    int64_t kk = 0;
    for (int64_t j = 1; j < n; ++j) {
        double w = h[j] - l[j];
        if (sc) w = w / sc[j];
        if (w > b) kk = j;
        if (w > b || isnan(w)) b = w;  /* numpy.maximum: a NaN propagates */
    }
    *width = b;
    return kk;
}
static inline int cmpc_cut(double a, double b, double r, int mid, double *cut)
{
    double c = mid ? 0.5 * a + 0.5 * b : a + r * (b - a);
    int good = (a < c) && (c < b);
    if (!good) {
        c = (1.0 - r) * a + r * b;  /* b - a may overflow for huge boxes */
        good = (a < c) && (c < b);
    }
    if (!good) {  /* a few ulps wide: the float after a, if it lies below b */
        c = nextafter(a, INFINITY);
        good = (a < c) && (c < b);
    }
    *cut = c;
    return good;
}
"""
_BISECT_C = RULES_C + r"""
void cmpc_widest(int64_t N, int64_t n, int64_t ld, const double *lo, const double *hi,
                 const double *scale, double *best, int64_t *k)
{
    for (int64_t i = 0; i < N; ++i)
        k[i] = cmpc_widest_row(lo + i * ld, hi + i * ld, scale, n, best + i);
}
void cmpc_bisect(int64_t N, int64_t n, const double *lo, const double *hi, const int64_t *k,
                 double r, int64_t mid, double *lo2, double *hi2, unsigned char *ok)
{
    for (int64_t i = 0; i < N; ++i) {
        double *l1 = lo2 + i * n, *l2 = lo2 + (N + i) * n;
        double *h1 = hi2 + i * n, *h2 = hi2 + (N + i) * n;
        for (int64_t d = 0; d < n; ++d) {
            l1[d] = l2[d] = lo[i * n + d];
            h1[d] = h2[d] = hi[i * n + d];
        }
        const int64_t j = k[i];
        double c;
        ok[i] = (unsigned char)cmpc_cut(lo[i * n + j], hi[i * n + j], r, (int)mid, &c);
        h1[j] = c;
        l2[j] = c;
    }
}
"""
#: batches below this many boxes stay in numpy (the C call's fixed cost)
NATIVE_MIN = 16
#: the column loop of :func:`widest` (and its C twin) serves up to this many coordinates
_COLUMN_MAX = 8


_I64, _PTR = ctypes.c_int64, ctypes.c_void_p
_ARGS = {"cmpc_widest": [_I64, _I64, _I64, _PTR, _PTR, _PTR, _PTR, _PTR],
         "cmpc_bisect": [_I64, _I64, _PTR, _PTR, _PTR, ctypes.c_double, _I64, _PTR, _PTR, _PTR]}
_native: list[Any] = []  # [c_function, address] of interval._native (which imports this)


def _kernel(name: str, wait: bool = False) -> Any:
    """The C function ``name`` of :data:`_BISECT_C`, or None (no compiler, ``CMPC_NATIVE=0``,
    or, with ``wait=False``, still compiling in the background)."""
    if not _native:
        from .interval._native import address, c_function

        _native[:] = [c_function, address]
    return _native[0](_BISECT_C, name, _ARGS[name], wait)


def widest_of(lo: np.ndarray, hi: np.ndarray, scale: np.ndarray | None = None,
              start: int = 0, stop: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`widest` of the widths ``hi - lo`` of the coordinates ``start:stop`` of boxes
    ``lo``, ``hi`` (N, n), divided by ``scale`` (one entry per coordinate of the range) when
    given: the same result (indices within the range), by one C loop when available."""
    N, n_all = lo.shape
    stop = n_all if stop is None else stop
    n = stop - start
    if N >= NATIVE_MIN and 0 < n <= _COLUMN_MAX:
        fn = _kernel("cmpc_widest")
        if fn is not None:
            a = _native[1]
            lo = np.ascontiguousarray(lo, dtype=np.float64)
            hi = np.ascontiguousarray(hi, dtype=np.float64)
            sc = None if scale is None else np.ascontiguousarray(
                np.broadcast_to(scale, (n,)), dtype=np.float64)
            best = np.empty(N)
            k = np.empty(N, dtype=np.int64)
            off = 8 * start
            fn(N, n, n_all, a(lo) + off, a(hi) + off, None if sc is None else a(sc), a(best),
               a(k))
            return best, k.view(np.intp)
    with np.errstate(over="ignore", invalid="ignore"):
        w = hi[:, start:stop] - lo[:, start:stop]
        if scale is not None:
            w = w / scale
    return widest(w)


def widest(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row of ``w``: the largest entry and the lowest index holding it.

    Parameters
    ----------
    w : ndarray, shape (N, n)
        Widths (any measure; NaN-free).

    Returns
    -------
    best : ndarray, shape (N,)
    k : ndarray of intp, shape (N,)
        Ties go to the lowest index (thesis eq. (4.3)); zeros for ``n = 0``.

    Notes
    -----
    Column by column for ``n <= 8``: numpy reductions along a short last axis are slow.
    """
    N, n = w.shape
    if n == 0:
        return np.zeros(N), np.zeros(N, dtype=np.intp)
    if n > 8:
        k = np.argmax(w, axis=1)
        return w[np.arange(N), k], k
    best = w[:, 0].copy()
    k = np.zeros(N, dtype=np.intp)
    for j in range(1, n):
        col = w[:, j]
        np.putmask(k, col > best, j)  # strictly greater: ties keep the lowest index
        np.maximum(best, col, out=best)
    return best, k


def midpoint(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``(lo + hi) / 2`` rounded to nearest, inside ``[lo, hi]`` even for huge bounds.

    Parameters
    ----------
    lo, hi : ndarray, same shape
        Bounds with ``lo <= hi``.

    Returns
    -------
    ndarray, same shape
        The correctly rounded midpoint; ``0.5 lo + 0.5 hi`` where ``lo + hi`` overflows;
        clipped to ``[lo, hi]``. NaN for ``(-inf, inf)``.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        c = (lo + hi) / 2.0
        huge = ~np.isfinite(c) & np.isfinite(lo) & np.isfinite(hi)
        if huge.any():
            c = np.where(huge, 0.5 * lo + 0.5 * hi, c)
    return np.clip(c, lo, hi)


def cut_points(a: np.ndarray, b: np.ndarray, ratio: float = 0.5, exact_mid: bool = False
               ) -> tuple[np.ndarray, np.ndarray]:
    """Cuts ``a + ratio (b - a)`` of intervals ``[a, b]`` and where they split them.

    Parameters
    ----------
    a, b : ndarray, shape (N,)
        Bounds of the split coordinate, ``a <= b``.
    ratio : float
        Position of the cut in ``(0, 1)``.
    exact_mid : bool
        For ``ratio == 0.5``: True gives the correctly rounded midpoint :func:`midpoint`
        (the public helper :func:`casadi_cmpc.sets.paving.bisect_boxes`); False gives
        ``0.5 a + 0.5 b`` (the solvers' frontiers), which never overflows. The two differ
        only when a bound is below ``2**-1021`` in magnitude (halving a subnormal rounds).

    Returns
    -------
    c : ndarray, shape (N,)
    ok : ndarray of bool, shape (N,)
        ``a < c < b``: the cut splits the interval into two proper halves. Where the first
        formula misses (``b - a`` overflows, or the rounding lands on a bound), the cut is
        computed again as ``(1 - ratio) a + ratio b``, and where that misses too (an
        interval a few ulps wide) it is the float after ``a``. ``ok`` is False only for an
        interval that holds no float strictly between its bounds.
    """
    r = float(ratio)
    with np.errstate(over="ignore", invalid="ignore"):
        if r != 0.5:
            c = a + r * (b - a)
        elif exact_mid:
            c = midpoint(a, b)
        else:
            c = 0.5 * a  # 0.5 a + 0.5 b cannot overflow
            c += 0.5 * b
        ok = (a < c) & (c < b)
        if not ok.all():
            alt = (1.0 - r) * a + r * b  # b - a may overflow for huge boxes
            c = np.where(ok, c, alt)
            ok = (a < c) & (c < b)
        if not ok.all():  # a few ulps wide: the float after a, if it lies below b
            c = np.where(ok, c, np.nextafter(a, np.inf))
            ok = (a < c) & (c < b)
    return c, ok


def bisect_widest(lo: np.ndarray, hi: np.ndarray, widths: np.ndarray | None = None, *,
                  k: np.ndarray | None = None, ratio: float = 0.5, exact_mid: bool = False
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Bisect every box ``[lo_i, hi_i]`` along its widest coordinate.

    Parameters
    ----------
    lo, hi : ndarray, shape (N, n)
        Bounds of the boxes (C-contiguous float arrays).
    widths : ndarray, shape (N, n), optional
        The widths compared to choose the split coordinate (:func:`widest`): absolute
        ``hi - lo``, relative to a reference box, or masked (e.g. ``-1`` for coordinates
        that must not be split). Default: ``hi - lo``.
    k : ndarray of int, shape (N,), optional
        The split coordinates, when already known (``widths`` is then not used).
    ratio : float
        Position of the cut in ``(0, 1)`` (0.5: the midpoint).
    exact_mid : bool
        Midpoint rule for ``ratio == 0.5``, see :func:`cut_points`.

    Returns
    -------
    lo2, hi2 : ndarray, shape (2N, n)
        The left halves (rows ``0..N-1``: ``[lo_k, c]`` in coordinate ``k``) then the right
        halves (rows ``N..2N-1``: ``[c, hi_k]``); the other coordinates are copied.
    k : ndarray of intp, shape (N,)
        The split coordinates.
    ok : ndarray of bool, shape (N,)
        Where the cut lies strictly inside the split coordinate. Elsewhere the halves are
        built all the same (with a cut at or beyond a bound); callers drop or keep them.
    """
    N, n = lo.shape
    if k is None:
        k = widest_of(lo, hi)[1] if widths is None else widest(widths)[1]
    if N >= NATIVE_MIN and not (exact_mid and ratio == 0.5):
        fn = _kernel("cmpc_bisect")
        if fn is not None:
            a = _native[1]
            lo = np.ascontiguousarray(lo, dtype=np.float64)
            hi = np.ascontiguousarray(hi, dtype=np.float64)
            kk = np.ascontiguousarray(k, dtype=np.int64)
            lo2 = np.empty((2 * N, n))
            hi2 = np.empty((2 * N, n))
            ok = np.empty(N, dtype=bool)
            r = float(ratio)
            fn(N, n, a(lo), a(hi), a(kk), r, int(r == 0.5), a(lo2), a(hi2), a(ok))
            return lo2, hi2, k, ok
    flat = np.arange(N) * n + k  # position of the split bound in lo.ravel()
    a = lo.take(flat)
    b = hi.take(flat)
    c, ok = cut_points(a, b, ratio, exact_mid)
    lo2 = np.concatenate([lo, lo])
    hi2 = np.concatenate([hi, hi])
    hi2.ravel()[flat] = c
    lo2.ravel()[flat + lo.size] = c
    return lo2, hi2, k, ok
