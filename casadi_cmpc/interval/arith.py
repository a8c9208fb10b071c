"""Vectorised interval arithmetic with outward rounding.

Every function here works on pairs of numpy arrays ``(lo, hi)`` of any common (broadcastable)
shape, typically ``(N,)`` for one scalar over a batch of ``N`` boxes. The public wrappers in
:mod:`casadi_cmpc.interval.ops` take arrays whose last axis holds ``[lo, hi]``.

Rounding
--------
numpy computes in round-to-nearest. Each result is widened outward so that the exact real
result of the operation on *any* reals inside the operand intervals lies inside:

* ``+``, ``-``: ``lo - |lo| * 2**-52`` (and ``hi + |hi| * 2**-52``). This moves a normal
  number by at least one ulp; a result in the subnormal range is exact, a zero stays zero
  (so sums of non-negative intervals stay non-negative).
* ``*``, ``/``, ``sqrt``: as above plus ``2**-1074`` (the smallest subnormal), which covers
  underflow.
* libm-type functions (exp, log, sin, ..., via numpy/scipy): relative margin ``2**-44``
  (256 ulps of the result) plus an absolute ``2**-1060``; the results are then intersected
  with the mathematical range of the function (e.g. ``[-1, 1]`` for ``sin``), which is sound.

Exact operations (negation, doubling, ``fabs``, ``floor``, ``ceil``, ``sign``, ``fmin``,
``fmax``, comparisons) are not widened.

Domains and undefined results
-----------------------------
* Division by an interval containing 0, ``inv`` of such an interval, ``tan`` over a pole,
  and any function on an interval that is only **partly** inside its domain (``log``,
  ``sqrt``, ``asin``, ``acos``, ``acosh``, ``atanh``, ``erfinv``, real powers) return the
  whole real line ``[-inf, inf]``.
* An interval entirely outside the domain gives ``[nan, nan]``.
* A NaN bound means *no information*: NaN propagates through every operation here (numpy's
  ``minimum``/``maximum`` propagate it, and every case test is written so that NaN falls into
  the "unknown" branch). Compiled inclusion functions replace NaN bounds by ``-inf``/``+inf``
  on output, so callers never see NaN.

This is deliberately never narrower than the true range over the whole box: a box containing
points where the function is undefined cannot be certified by any predicate.
"""

from __future__ import annotations

import numpy as np
from scipy import special as _special

__all__: list[str] = []

U = 2.0 ** -52  # relative margin for basic operations (>= 1 ulp for normal numbers)
TINY = 2.0 ** -1074  # smallest positive subnormal
REL_LIBM = 2.0 ** -44  # relative margin for libm functions
ABS_LIBM = 2.0 ** -1060  # absolute margin for libm functions (subnormal results)
INF = np.inf
PI_LO = 3.141592653589793  # float(pi) < pi
PI_HI = np.nextafter(PI_LO, 4.0)  # > pi
HALF_PI_HI = np.nextafter(1.5707963267948966, 2.0)
_SIN_SAFE = 1e8  # beyond this magnitude, sin/cos/tan return their full range

_abs = np.abs
_min = np.minimum
_max = np.maximum
_where = np.where


# ---------------------------------------------------------------------------- rounding
def dn(x):
    """Round a sum/difference result down (sound for + and -)."""
    return x - _abs(x) * U


def up(x):
    """Round a sum/difference result up."""
    return x + _abs(x) * U


def dnm(x):
    """Round a product/quotient/sqrt result down (covers underflow)."""
    return x - (_abs(x) * U + TINY)


def upm(x):
    """Round a product/quotient/sqrt result up (covers underflow)."""
    return x + (_abs(x) * U + TINY)


def dnf(x):
    """Round a libm result down."""
    return x - (_abs(x) * REL_LIBM + ABS_LIBM)


def upf(x):
    """Round a libm result up."""
    return x + (_abs(x) * REL_LIBM + ABS_LIBM)


def _whole_where(mask, lo, hi):
    """Set [-inf, inf] where mask is True."""
    if np.any(mask):
        lo = _where(mask, -INF, lo)
        hi = _where(mask, INF, hi)
    return lo, hi


def _nan_where(mask, lo, hi):
    if np.any(mask):
        lo = _where(mask, np.nan, lo)
        hi = _where(mask, np.nan, hi)
    return lo, hi


def _domain(xl, xh, dlo, dhi, lo, hi, open_lo=False, open_hi=False):
    """Apply the domain convention for a function defined on [dlo, dhi] (or open ends).

    Entirely outside -> NaN; partly outside -> whole line. NaN inputs stay NaN.
    """
    below_part = (xl <= dlo) if open_lo else (xl < dlo)
    above_part = (xh >= dhi) if open_hi else (xh > dhi)
    outside_all = ((xh <= dlo) if open_lo else (xh < dlo)) | (
        (xl >= dhi) if open_hi else (xl > dhi))
    lo, hi = _whole_where(below_part | above_part, lo, hi)
    return _nan_where(outside_all, lo, hi)


def _mono_inc(fn, xl, xh, rlo=-INF, rhi=INF):
    """Increasing libm function: [fn(lo), fn(hi)] widened and clipped to [rlo, rhi]."""
    with np.errstate(all="ignore"):
        lo = dnf(fn(xl))
        hi = upf(fn(xh))
    if rlo != -INF:
        lo = _max(lo, rlo)
    if rhi != INF:
        hi = _min(hi, rhi)
    return lo, hi


def _mono_dec(fn, xl, xh, rlo=-INF, rhi=INF):
    with np.errstate(all="ignore"):
        lo = dnf(fn(xh))
        hi = upf(fn(xl))
    if rlo != -INF:
        lo = _max(lo, rlo)
    if rhi != INF:
        hi = _min(hi, rhi)
    return lo, hi


# ------------------------------------------------------------------------- arithmetic
def add(al, ah, bl, bh):
    with np.errstate(all="ignore"):
        return dn(al + bl), up(ah + bh)


def sub(al, ah, bl, bh):
    with np.errstate(all="ignore"):
        return dn(al - bh), up(ah - bl)


def addc(al, ah, c):
    """x + c for a float constant c."""
    with np.errstate(all="ignore"):
        return dn(al + c), up(ah + c)


def csub(c, bl, bh):
    """c - x for a float constant c."""
    with np.errstate(all="ignore"):
        return dn(c - bh), up(c - bl)


def neg(al, ah):
    return -ah, -al


def twice(al, ah):
    return al + al, ah + ah  # exact (overflow gives inf, still sound)


def mul(al, ah, bl, bh):
    with np.errstate(all="ignore"):
        p1 = al * bl
        p2 = al * bh
        p3 = ah * bl
        p4 = ah * bh
        lo = _min(_min(p1, p2), _min(p3, p4))
        hi = _max(_max(p1, p2), _max(p3, p4))
        return dnm(lo), upm(hi)


def mulc(al, ah, c):
    """x * c for a float constant c (exact real constant)."""
    with np.errstate(all="ignore"):
        if c > 0:
            return dnm(al * c), upm(ah * c)
        if c < 0:
            return dnm(ah * c), upm(al * c)
        if c == 0:
            z = np.zeros(np.broadcast(al, ah).shape)
            return z, z.copy()
        return np.full_like(al, np.nan), np.full_like(ah, np.nan)


def sq(al, ah):
    with np.errstate(all="ignore"):
        mig = _max(_max(al, -ah), 0.0)  # distance of the interval from 0 (NaN propagates)
        mag = _max(-al, ah)
        return _max(dnm(mig * mig), 0.0), upm(mag * mag)


def div(al, ah, bl, bh):
    with np.errstate(all="ignore"):
        q1 = al / bl
        q2 = al / bh
        q3 = ah / bl
        q4 = ah / bh
        lo = dnm(_min(_min(q1, q2), _min(q3, q4)))
        hi = upm(_max(_max(q1, q2), _max(q3, q4)))
    return _whole_where((bl <= 0) & (bh >= 0), lo, hi)


def divc(al, ah, c):
    """x / c for a float constant c."""
    with np.errstate(all="ignore"):
        if c > 0:
            return dnm(al / c), upm(ah / c)
        if c < 0:
            return dnm(ah / c), upm(al / c)
    shape = np.broadcast(al, ah).shape
    return np.full(shape, -INF), np.full(shape, INF)


def cdiv(c, bl, bh):
    """c / x for a float constant c."""
    with np.errstate(all="ignore"):
        q1 = c / bl
        q2 = c / bh
        lo = dnm(_min(q1, q2))
        hi = upm(_max(q1, q2))
    return _whole_where((bl <= 0) & (bh >= 0), lo, hi)


def inv(al, ah):
    return cdiv(1.0, al, ah)


def sqrt(al, ah):
    with np.errstate(all="ignore"):
        lo = _max(dnm(np.sqrt(al)), 0.0)
        hi = upm(np.sqrt(ah))
    return _domain(al, ah, 0.0, INF, lo, hi)


# --------------------------------------------------------------------- transcendental
def exp(al, ah):
    return _mono_inc(np.exp, al, ah, 0.0)


def expm1(al, ah):
    return _mono_inc(np.expm1, al, ah, -1.0)


def log(al, ah):
    lo, hi = _mono_inc(np.log, al, ah)
    return _domain(al, ah, 0.0, INF, lo, hi, open_lo=True)


def log1p(al, ah):
    lo, hi = _mono_inc(np.log1p, al, ah)
    return _domain(al, ah, -1.0, INF, lo, hi, open_lo=True)


def _contains_point(al, ah, offset, period):
    """Conservative test: does [al, ah] contain offset + k*period for an integer k?

    May answer True when it does not (which only widens results); never False when it does.
    """
    with np.errstate(all="ignore"):
        kl = (al - offset) / period
        kh = (ah - offset) / period
        slack = 1e-9 + 1e-15 * (_abs(kl) + _abs(kh))
        return np.floor(kh + slack) >= np.ceil(kl - slack)


def _sincos(fn, al, ah, max_off, min_off):
    with np.errstate(all="ignore"):
        fl = fn(al)
        fh = fn(ah)
        lo = _max(dnf(_min(fl, fh)), -1.0)
        hi = _min(upf(_max(fl, fh)), 1.0)
    two_pi = 2.0 * PI_LO
    big = (ah - al >= two_pi) | (_abs(al) > _SIN_SAFE) | (_abs(ah) > _SIN_SAFE)
    has_max = big | _contains_point(al, ah, max_off, two_pi)
    has_min = big | _contains_point(al, ah, min_off, two_pi)
    hi = _where(has_max, _where(np.isnan(hi), np.nan, 1.0), hi)
    lo = _where(has_min, _where(np.isnan(lo), np.nan, -1.0), lo)
    return lo, hi


def sin(al, ah):
    return _sincos(np.sin, al, ah, 0.5 * PI_LO, -0.5 * PI_LO)


def cos(al, ah):
    return _sincos(np.cos, al, ah, 0.0, PI_LO)


def tan(al, ah):
    lo, hi = _mono_inc(np.tan, al, ah)
    pole = ((ah - al) >= PI_LO) | _contains_point(al, ah, 0.5 * PI_LO, PI_LO)
    pole |= (_abs(al) > _SIN_SAFE) | (_abs(ah) > _SIN_SAFE)
    return _whole_where(pole, lo, hi)


def asin(al, ah):
    lo, hi = _mono_inc(np.arcsin, al, ah, -HALF_PI_HI, HALF_PI_HI)
    return _domain(al, ah, -1.0, 1.0, lo, hi)


def acos(al, ah):
    lo, hi = _mono_dec(np.arccos, al, ah, 0.0, PI_HI)
    return _domain(al, ah, -1.0, 1.0, lo, hi)


def atan(al, ah):
    return _mono_inc(np.arctan, al, ah, -HALF_PI_HI, HALF_PI_HI)


def sinh(al, ah):
    return _mono_inc(np.sinh, al, ah)


def tanh(al, ah):
    return _mono_inc(np.tanh, al, ah, -1.0, 1.0)


def asinh(al, ah):
    return _mono_inc(np.arcsinh, al, ah)


def acosh(al, ah):
    lo, hi = _mono_inc(np.arccosh, al, ah, 0.0)
    return _domain(al, ah, 1.0, INF, lo, hi)


def atanh(al, ah):
    lo, hi = _mono_inc(np.arctanh, al, ah)
    return _domain(al, ah, -1.0, 1.0, lo, hi, open_lo=True, open_hi=True)


def erf(al, ah):
    return _mono_inc(_special.erf, al, ah, -1.0, 1.0)


def erfinv(al, ah):
    lo, hi = _mono_inc(_special.erfinv, al, ah)
    return _domain(al, ah, -1.0, 1.0, lo, hi, open_lo=True, open_hi=True)


def cosh(al, ah):
    ml, mh = fabs(al, ah)
    lo, hi = _mono_inc(np.cosh, ml, mh, 1.0)
    return lo, hi


# ------------------------------------------------------------------------ piecewise
def fabs(al, ah):
    return _max(_max(al, -ah), 0.0), _max(-al, ah)  # exact; NaN propagates


def fmin(al, ah, bl, bh):
    return _min(al, bl), _min(ah, bh)


def fmax(al, ah, bl, bh):
    return _max(al, bl), _max(ah, bh)


def floor(al, ah):
    return np.floor(al), np.floor(ah)


def ceil(al, ah):
    return np.ceil(al), np.ceil(ah)


def sign(al, ah):
    return np.sign(al), np.sign(ah)


def copysign(al, ah, bl, bh):
    ml, mh = fabs(al, ah)
    pos = bl >= 0
    negv = bh < 0
    lo = _where(pos, ml, _where(negv, -mh, -mh))
    hi = _where(pos, mh, _where(negv, -ml, mh))
    lo = _where(np.isnan(bl) | np.isnan(bh), np.nan, lo)
    return lo, hi


def fmod(al, ah, bl, bh):
    """fmod(x, y): same sign as x, magnitude below |y|."""
    ml, mh = fabs(bl, bh)
    xl_in = (al >= 0) & (ah < ml)
    xn_in = (ah <= 0) & (-al < ml)
    with np.errstate(all="ignore"):
        lo = _where(al >= 0, 0.0, _max(al, -mh))
        hi = _where(ah <= 0, 0.0, _min(ah, mh))
    lo = _where(xl_in | xn_in, al, lo)
    hi = _where(xl_in | xn_in, ah, hi)
    lo = _where(np.isnan(al) | np.isnan(ah), np.nan, lo)
    return _whole_where((bl <= 0) & (bh >= 0), lo, hi)


def remainder(al, ah, bl, bh):
    """IEEE remainder(x, y): x itself when |x| <= |y|/2, else magnitude at most
    min(|x|, |y|/2), of either sign (remainder(2, 3) = -1)."""
    ml, mh = fabs(bl, bh)
    xm = _max(-al, ah)  # max |x|
    with np.errstate(all="ignore"):
        half = mh * 0.5 + TINY  # >= |y|/2 also when the halving rounds (subnormal y)
        inside = (-2.0 * al <= ml) & (2.0 * ah <= ml)  # exact doubling, no rounded halving
    bound = _min(half, xm)
    lo = _where(inside, al, -bound)
    hi = _where(inside, ah, bound)
    lo = _where(np.isnan(al) | np.isnan(ah), np.nan, lo)
    return _whole_where((bl <= 0) & (bh >= 0), lo, hi)


def hypot(al, ah, bl, bh):
    xl, xh = fabs(al, ah)
    yl, yh = fabs(bl, bh)
    with np.errstate(all="ignore"):
        lo = _max(dnf(np.hypot(xl, yl)), 0.0)
        hi = upf(np.hypot(xh, yh))
    return lo, hi


def atan2(yl, yh, xl, xh):
    """atan2(y, x) in [-pi, pi]; corners where the box avoids the branch cut and origin."""
    with np.errstate(all="ignore"):
        y0 = yl + 0.0  # turn -0.0 into +0.0
        y1 = yh + 0.0
        c1 = np.arctan2(y0, xl)
        c2 = np.arctan2(y0, xh)
        c3 = np.arctan2(y1, xl)
        c4 = np.arctan2(y1, xh)
        lo = _max(dnf(_min(_min(c1, c2), _min(c3, c4))), -PI_HI)
        hi = _min(upf(_max(_max(c1, c2), _max(c3, c4))), PI_HI)
    cut = (xl <= 0) & (yl < 0) & (yh >= 0)
    origin = (xl <= 0) & (xh >= 0) & (yl <= 0) & (yh >= 0)
    full = cut | origin
    if np.any(full):
        lo = _where(full & ~np.isnan(lo), -PI_HI, lo)
        hi = _where(full & ~np.isnan(hi), PI_HI, hi)
    return lo, hi


# ----------------------------------------------------------------------------- powers
def powi(al, ah, n: int):
    """x**n for an integer n."""
    n = int(n)
    shape = np.broadcast(al, ah).shape
    if n == 0:
        return np.ones(shape), np.ones(shape)
    if n == 1:
        lo, hi = np.broadcast_arrays(al, ah)
        return lo.copy(), hi.copy()
    if n == 2:
        return sq(al, ah)
    if n < 0:
        pl, ph = powi(al, ah, -n)
        return inv(pl, ph)
    if n % 2 == 1:
        with np.errstate(all="ignore"):  # overflow: inf - inf is NaN (no information)
            return dnf(np.power(al, n)), upf(np.power(ah, n))
    ml, mh = fabs(al, ah)
    with np.errstate(all="ignore"):
        lo = _max(dnf(np.power(ml, n)), 0.0)
        hi = upf(np.power(mh, n))
    return lo, hi


def powc(al, ah, c: float):
    """x**c for a real constant c (integer c uses :func:`powi`)."""
    c = float(c)
    if c.is_integer() and abs(c) < 2 ** 31:
        return powi(al, ah, int(c))
    if c > 0:
        lo, hi = _mono_inc(lambda v: np.power(v, c), al, ah, 0.0)
        return _domain(al, ah, 0.0, INF, lo, hi)
    lo, hi = _mono_dec(lambda v: np.power(v, c), al, ah, 0.0)
    return _domain(al, ah, 0.0, INF, lo, hi, open_lo=True)


def pow(al, ah, bl, bh):
    """x**y for interval y: exp(y * log(x)) on x > 0; thin integer exponents use :func:`powi`
    (so that negative bases are handled)."""
    shape = np.broadcast(al, ah, bl, bh).shape
    bl_b = np.broadcast_to(bl, shape)
    bh_b = np.broadcast_to(bh, shape)
    thin_int = (bl_b == bh_b) & (np.floor(bl_b) == bl_b) & (_abs(bl_b) < 2 ** 31)
    ll, lh = log(al, ah)
    pl, ph = mul(ll, lh, bl, bh)
    lo, hi = exp(pl, ph)
    # x partly negative, or 0 in x with a negative exponent: partly outside the domain (and
    # negative values are reached at integer y), so the whole line
    lo, hi = _whole_where(((al < 0) & (ah >= 0)) | ((al <= 0) & (ah >= 0) & (bl < 0)), lo, hi)
    lo = np.array(np.broadcast_to(lo, shape))
    hi = np.array(np.broadcast_to(hi, shape))
    if np.any(thin_int):
        al_b = np.broadcast_to(al, shape)
        ah_b = np.broadcast_to(ah, shape)
        for v in np.unique(bl_b[thin_int]):
            sel = thin_int & (bl_b == v)
            il, ih = powi(al_b[sel], ah_b[sel], int(v))
            lo[sel] = il
            hi[sel] = ih
    return lo, hi


# ------------------------------------------------------------------------- logic ops
def _bool_interval(true_sure, false_sure):
    lo = _where(true_sure, 1.0, 0.0)
    hi = _where(false_sure, 0.0, 1.0)
    return lo, hi


def lt(al, ah, bl, bh):
    return _bool_interval(ah < bl, al >= bh)


def le(al, ah, bl, bh):
    return _bool_interval(ah <= bl, al > bh)


def eq(al, ah, bl, bh):
    return _bool_interval((al == ah) & (bl == bh) & (al == bl), (ah < bl) | (al > bh))


def ne(al, ah, bl, bh):
    return _bool_interval((ah < bl) | (al > bh), (al == ah) & (bl == bh) & (al == bl))


def _nonzero_sure(al, ah):
    return (al > 0) | (ah < 0)


def _zero_sure(al, ah):
    return (al == 0) & (ah == 0)


def not_(al, ah):
    return _bool_interval(_zero_sure(al, ah), _nonzero_sure(al, ah))


def and_(al, ah, bl, bh):
    return _bool_interval(_nonzero_sure(al, ah) & _nonzero_sure(bl, bh),
                          _zero_sure(al, ah) | _zero_sure(bl, bh))


def or_(al, ah, bl, bh):
    return _bool_interval(_nonzero_sure(al, ah) | _nonzero_sure(bl, bh),
                          _zero_sure(al, ah) & _zero_sure(bl, bh))


def if_else_zero(cl, ch, xl, xh):
    """``c ? x : 0``: x when c is surely non-zero, 0 when surely zero, else hull(x, 0)."""
    sure = _nonzero_sure(cl, ch)
    zero = _zero_sure(cl, ch)
    lo = _where(sure, xl, _where(zero, 0.0, _min(xl, 0.0)))
    hi = _where(sure, xh, _where(zero, 0.0, _max(xh, 0.0)))
    return lo, hi


def assign(al, ah):
    return al, ah


def hull(al, ah, bl, bh):
    """Interval hull of two intervals (not a CasADi op; used by the compiler)."""
    return _min(al, bl), _max(ah, bh)


def intersect(al, ah, bl, bh):
    """Intersection; an empty intersection (which cannot happen for two sound enclosures of
    the same value) is reported as NaN (no information)."""
    lo = _max(al, bl)
    hi = _min(ah, bh)
    return _nan_where(lo > hi, lo, hi)
