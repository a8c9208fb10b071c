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
* Where an operation may be undefined somewhere on its operand box — division by an interval
  containing 0 (also ``inv``, ``fmod``, ``remainder``), ``tan`` over a pole, and any function
  on an interval that is not entirely inside its domain (``log``, ``sqrt``, ``asin``,
  ``acos``, ``acosh``, ``atanh``, ``erfinv``, real powers) — the result is ``[nan, nan]``.
* A NaN bound means *possibly undefined, no information*. NaN propagates through every
  operation here, including the bounded ones (``atan``, ``tanh``, comparisons, ``if_else``,
  multiplication by 0), so a composite function that may be undefined somewhere on a box
  gives NaN, not a deceptively bounded result. Compiled inclusion functions replace a result
  with a NaN bound by ``[-inf, inf]`` on output, so callers see the whole real line and never
  NaN.

This is deliberately never narrower than the true range over the whole box: a box containing
points where the function may be undefined cannot be certified by any predicate.

Invariant of every result
-------------------------
Each result ``(lo, hi)`` is, elementwise, either ``[nan, nan]`` ("possibly undefined, no
information") or NaN-free with ``lo <= hi``, ``lo < +inf`` and ``hi > -inf``. A bound is
never NaN on one side only: a NaN met in any operand bound, or produced inside an operation
(``inf - inf``, ``0 * inf``, ``inf / inf``), makes the result NaN on both sides, so that no
later operation (``fmin``, a comparison, a pole or branch test) can turn half of it into a
bound. Overflow is not NaN: a lower bound that overflows to ``+inf`` stands for a finite real
above the largest float, so it becomes ``MAX_FLOAT`` before it is rounded down (``exp`` of
``[710, 711]`` is ``[1.797e308, inf]``); an upper bound that overflows to ``-inf`` becomes
``-MAX_FLOAT``. Infinite bounds on the open side (``lo = -inf``, ``hi = +inf``) are
unbounded intervals and are valid operands and results.

Operations that branch on their operand bounds (``tan``, ``sin``, ``cos``, ``floor``,
``ceil``, ``sign``, ``fabs``, ``sq``, ``fmin``, ``fmax``, ``copysign``, ``fmod``,
``remainder``, ``atan2``, ``hypot``, ``pow``, comparisons, logic, ``if_else_zero``,
``hull``, ``intersect``) give ``[nan, nan]`` for a NaN in *any* operand bound. The others
(sums, products, monotone functions) compute each bound from the matching operand bounds
and keep the invariant for operands that satisfy it; the wrappers of
:mod:`~casadi_cmpc.interval.ops` make a one-sided NaN operand two-sided first. A constant
operand that is not a finite real (``x + inf``) gives ``[nan, nan]``.

Floating-point exceptions (overflow, invalid) are expected here and are not reported: callers
that evaluate many operations wrap them in one ``np.errstate(all="ignore")`` (the compiled
evaluators and :mod:`~casadi_cmpc.interval.ops` do).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special as _special

__all__: list[str] = []

U = 2.0 ** -52  # relative margin for basic operations (>= 1 ulp for normal numbers)
TINY = 2.0 ** -1074  # smallest positive subnormal
REL_LIBM = 2.0 ** -44  # relative margin for libm functions
ABS_LIBM = 2.0 ** -1060  # absolute margin for libm functions (subnormal results)
INF = np.inf
MAX_FLOAT = float(np.finfo(float).max)
PI_LO = 3.141592653589793  # float(pi) < pi
PI_HI = np.nextafter(PI_LO, 4.0)  # > pi
HALF_PI_HI = np.nextafter(1.5707963267948966, 2.0)
_SIN_SAFE = 1e8  # beyond this magnitude, sin/cos/tan return their full range

_abs = np.abs
_isfinite = math.isfinite  # for scalar constants (cheaper than the numpy ufunc)
_min = np.minimum
_max = np.maximum
_where = np.where


# ---------------------------------------------------------------------------- rounding
# The argument is the float result of ONE operation (correctly rounded, or a libm function
# within its error model), or an infinite bound. A lower bound computed as +inf is then an
# overflow: the exact value is a real above MAX_FLOAT (or +inf), so the lower bound becomes
# MAX_FLOAT before it is rounded down (``inf - inf`` would give NaN, and +inf itself is above
# the exact value). Likewise an upper bound of -inf becomes -MAX_FLOAT. NaN stays NaN
# (np.minimum / np.maximum propagate it). The cap is not valid for a value computed by
# several operations, where an intermediate overflow may hide a small exact result.
def dn(x):
    """Round a sum/difference result down (sound for + and -)."""
    x = _min(x, MAX_FLOAT)
    return x - _abs(x) * U


def up(x):
    """Round a sum/difference result up."""
    x = _max(x, -MAX_FLOAT)
    return x + _abs(x) * U


def dnm(x):
    """Round a product/quotient/sqrt result down (covers underflow)."""
    x = _min(x, MAX_FLOAT)
    return x - (_abs(x) * U + TINY)


def upm(x):
    """Round a product/quotient/sqrt result up (covers underflow)."""
    x = _max(x, -MAX_FLOAT)
    return x + (_abs(x) * U + TINY)


def _dn_(x):
    """In-place :func:`dn` of a freshly computed array (or scalar) owned by the caller."""
    if type(x) is np.ndarray:
        _min(x, MAX_FLOAT, out=x)
    else:
        x = _min(x, MAX_FLOAT)
    t = _abs(x)
    t *= U
    x -= t
    return x


def _up_(x):
    if type(x) is np.ndarray:
        _max(x, -MAX_FLOAT, out=x)
    else:
        x = _max(x, -MAX_FLOAT)
    t = _abs(x)
    t *= U
    x += t
    return x


def _dnm_(x):
    if type(x) is np.ndarray:
        _min(x, MAX_FLOAT, out=x)
    else:
        x = _min(x, MAX_FLOAT)
    t = _abs(x)
    t *= U
    t += TINY
    x -= t
    return x


def _upm_(x):
    if type(x) is np.ndarray:
        _max(x, -MAX_FLOAT, out=x)
    else:
        x = _max(x, -MAX_FLOAT)
    t = _abs(x)
    t *= U
    t += TINY
    x += t
    return x


# The same without the overflow cap, for results that cannot overflow towards the side
# being rounded (x + c with c <= 0, x * c with |c| <= 1, x / c with |c| >= 1): one numpy
# call less on the hot path of constant operands.
def _dn0_(x):
    t = _abs(x)
    t *= U
    x -= t
    return x


def _up0_(x):
    t = _abs(x)
    t *= U
    x += t
    return x


def _dnm0_(x):
    t = _abs(x)
    t *= U
    t += TINY
    x -= t
    return x


def _upm0_(x):
    t = _abs(x)
    t *= U
    t += TINY
    x += t
    return x


def dnf(x):
    """Round a libm result down."""
    x = _min(x, MAX_FLOAT)
    return x - (_abs(x) * REL_LIBM + ABS_LIBM)


def upf(x):
    """Round a libm result up."""
    x = _max(x, -MAX_FLOAT)
    return x + (_abs(x) * REL_LIBM + ABS_LIBM)


def _undefined_where(mask, lo, hi):
    """Set [nan, nan] (possibly undefined, no information) where mask is True."""
    if np.any(mask):
        lo = _where(mask, np.nan, lo)
        hi = _where(mask, np.nan, hi)
    return lo, hi


def _keep_nan(lo, hi, *operands):
    """Make the result NaN wherever an operand bound is NaN (for case-based operations)."""
    bad = np.isnan(operands[0])
    for o in operands[1:]:
        bad = bad | np.isnan(o)
    return _nan_where(bad, lo, hi)


def _nan_where(mask, lo, hi):
    if np.any(mask):
        lo = _where(mask, np.nan, lo)
        hi = _where(mask, np.nan, hi)
    return lo, hi


def _two_sided(lo, hi):
    """[nan, nan] wherever lo <= hi fails: a NaN on either side (or an inverted result).

    For operations whose lower bound carries every NaN of the lower operand bounds and the
    upper bound every NaN of the upper ones (fmin, floor, ...), this makes a NaN met in any
    operand bound a NaN on both sides."""
    return _nan_where(~(lo <= hi), lo, hi)


def _domain(xl, xh, dlo, dhi, lo, hi, open_lo=False, open_hi=False):
    """Apply the domain convention for a function defined on [dlo, dhi] (or open ends).

    Not entirely inside the domain -> NaN (possibly undefined). NaN inputs stay NaN.
    """
    below_part = (xl <= dlo) if open_lo else (xl < dlo)
    above_part = (xh >= dhi) if open_hi else (xh > dhi)
    return _undefined_where(below_part | above_part, lo, hi)


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
def _nan_pair(*args):
    shape = np.broadcast(*args).shape
    return np.full(shape, np.nan), np.full(shape, np.nan)


def add(al, ah, bl, bh):
    return _dn_(al + bl), _up_(ah + bh)


def sub(al, ah, bl, bh):
    return _dn_(al - bh), _up_(ah - bl)


def addc(al, ah, c):
    """x + c for a float constant c (a non-finite c is not a real: [nan, nan])."""
    if not _isfinite(c):
        return _nan_pair(al, ah)
    if c > 0:  # only the lower bound can overflow (to +inf)
        return _dn_(al + c), _up0_(ah + c)
    return _dn0_(al + c), _up_(ah + c)


def csub(c, bl, bh):
    """c - x for a float constant c."""
    if not _isfinite(c):
        return _nan_pair(bl, bh)
    if c > 0:
        return _dn_(c - bh), _up0_(c - bl)
    return _dn0_(c - bh), _up_(c - bl)


def neg(al, ah):
    return -ah, -al


def twice(al, ah):
    # exact, except for overflow: an overflowed lower bound becomes MAX_FLOAT (the exact
    # value is a real above it), an overflowed upper bound -MAX_FLOAT
    return _min(al + al, MAX_FLOAT), _max(ah + ah, -MAX_FLOAT)


def mul(al, ah, bl, bh):
    p1 = al * bl
    p2 = al * bh
    p3 = ah * bl
    p4 = ah * bh
    lo = _min(p1, p2)
    lo = _min(lo, _min(p3, p4), out=lo) if isinstance(lo, np.ndarray) else _min(
        lo, _min(p3, p4))
    hi = _max(p1, p2)
    hi = _max(hi, _max(p3, p4), out=hi) if isinstance(hi, np.ndarray) else _max(
        hi, _max(p3, p4))
    return _dnm_(lo), _upm_(hi)


def mulc(al, ah, c):
    """x * c for a float constant c (exact real constant)."""
    if not _isfinite(c):
        return _nan_pair(al, ah)
    small = -1.0 <= c <= 1.0  # |x * c| <= |x|: no overflow
    if c > 0:
        if small:
            return _dnm0_(al * c), _upm0_(ah * c)
        return _dnm_(al * c), _upm_(ah * c)
    if c < 0:
        if small:
            return _dnm0_(ah * c), _upm0_(al * c)
        return _dnm_(ah * c), _upm_(al * c)
    z = np.zeros(np.broadcast(al, ah).shape)  # c == 0: 0 * x = 0 for every real x
    return _keep_nan(z, z.copy(), al, ah)  # NaN (possibly undefined) stays NaN


def mulci(al, ah, cl, ch):
    """x * [cl, ch] for a constant interval of one sign (0 < cl <= ch or cl <= ch < 0)."""
    if not (_isfinite(cl) and _isfinite(ch)):
        return mul(al, ah, cl, ch)
    if cl > 0:
        return _dnm_(_min(al * cl, al * ch)), _upm_(_max(ah * cl, ah * ch))
    if ch < 0:
        return _dnm_(_min(ah * cl, ah * ch)), _upm_(_max(al * cl, al * ch))
    return mul(al, ah, cl, ch)


C_DN = 1.0 - 2.0 ** -51  # x * C_DN rounded is below x - ulp(x) for normal x >= 0
C_UP = 1.0 + 2.0 ** -51


def sq(al, ah):
    """x**2. Both products are of non-negative numbers, so their rounding needs no ``abs``:
    ``fl(fl(p) * (1 - 2**-51)) - 2**-1074`` is below the exact ``p`` (the relative step covers
    one rounding of a normal result, the absolute one underflow), and the lower bound is
    capped at the largest float (an overflowed square is only known to be huge)."""
    mig = _max(al, -ah)  # distance of the interval from 0 (NaN propagates)
    mag = _max(-al, ah)
    if isinstance(mig, np.ndarray):
        _max(mig, 0.0, out=mig)
        lo = mig * mig
        lo *= C_DN
        lo -= TINY
        _max(lo, 0.0, out=lo)
        _min(lo, MAX_FLOAT, out=lo)
        hi = mag * mag
        hi *= C_UP
        hi += TINY
        return lo, hi
    mig = _max(mig, 0.0)
    lo = _min(_max(mig * mig * C_DN - TINY, 0.0), MAX_FLOAT)
    return lo, mag * mag * C_UP + TINY


def div(al, ah, bl, bh):
    q1 = al / bl
    q2 = al / bh
    q3 = ah / bl
    q4 = ah / bh
    lo = _dnm_(_min(_min(q1, q2), _min(q3, q4)))
    hi = _upm_(_max(_max(q1, q2), _max(q3, q4)))
    return _undefined_where((bl <= 0) & (bh >= 0), lo, hi)


def divc(al, ah, c):
    """x / c for a float constant c."""
    if not _isfinite(c):
        return _nan_pair(al, ah)
    if c >= 1.0:  # |x / c| <= |x|: no overflow
        return _dnm0_(al / c), _upm0_(ah / c)
    if c <= -1.0:
        return _dnm0_(ah / c), _upm0_(al / c)
    if c > 0:
        return _dnm_(al / c), _upm_(ah / c)
    if c < 0:
        return _dnm_(ah / c), _upm_(al / c)
    return _nan_pair(al, ah)


def cdiv(c, bl, bh):
    """c / x for a float constant c."""
    if not _isfinite(c):
        return _nan_pair(bl, bh)
    q1 = c / bl
    q2 = c / bh
    lo = _dnm_(_min(q1, q2))
    hi = _upm_(_max(q1, q2))
    return _undefined_where((bl <= 0) & (bh >= 0), lo, hi)


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
    # written so that NaN and infinite bounds count as "big" (the full range [-1, 1])
    big = ~((ah - al < two_pi) & (_abs(al) <= _SIN_SAFE) & (_abs(ah) <= _SIN_SAFE))
    has_max = big | _contains_point(al, ah, max_off, two_pi)
    has_min = big | _contains_point(al, ah, min_off, two_pi)
    hi = _where(has_max, 1.0, hi)
    lo = _where(has_min, -1.0, lo)
    return _keep_nan(lo, hi, al, ah)  # sin of a possibly undefined value: possibly undefined


def sin(al, ah):
    return _sincos(np.sin, al, ah, 0.5 * PI_LO, -0.5 * PI_LO)


def cos(al, ah):
    return _sincos(np.cos, al, ah, 0.0, PI_LO)


def tan(al, ah):
    lo, hi = _mono_inc(np.tan, al, ah)
    # written so that NaN and infinite bounds count as "may contain a pole"
    no_pole = (ah - al < PI_LO) & (_abs(al) <= _SIN_SAFE) & (_abs(ah) <= _SIN_SAFE)
    pole = ~no_pole | _contains_point(al, ah, 0.5 * PI_LO, PI_LO)
    return _undefined_where(pole, lo, hi)


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
    return _two_sided(_min(al, bl), _min(ah, bh))


def fmax(al, ah, bl, bh):
    return _two_sided(_max(al, bl), _max(ah, bh))


def floor(al, ah):
    return _two_sided(np.floor(al), np.floor(ah))


def ceil(al, ah):
    return _two_sided(np.ceil(al), np.ceil(ah))


def sign(al, ah):
    return _two_sided(np.sign(al), np.sign(ah))


def copysign(al, ah, bl, bh):
    ml, mh = fabs(al, ah)
    pos = bl >= 0
    negv = bh < 0
    lo = _where(pos, ml, _where(negv, -mh, -mh))
    hi = _where(pos, mh, _where(negv, -ml, mh))
    return _keep_nan(lo, hi, al, ah, bl, bh)


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
    lo, hi = _keep_nan(lo, hi, al, ah, bl, bh)
    return _undefined_where((bl <= 0) & (bh >= 0), lo, hi)


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
    lo, hi = _keep_nan(lo, hi, al, ah, bl, bh)
    return _undefined_where((bl <= 0) & (bh >= 0), lo, hi)


def hypot(al, ah, bl, bh):
    xl, xh = fabs(al, ah)
    yl, yh = fabs(bl, bh)
    with np.errstate(all="ignore"):
        lo = _max(dnf(np.hypot(xl, yl)), 0.0)
        hi = upf(np.hypot(xh, yh))
    return _two_sided(lo, hi)  # hypot(nan, inf) is inf


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
    if n == 0:  # x**0 = 1 for every real x; NaN (possibly undefined) stays NaN
        return _keep_nan(np.ones(shape), np.ones(shape), al, ah)
    if n == 1:
        lo, hi = np.broadcast_arrays(al, ah)
        return lo.copy(), hi.copy()
    if n == 2:
        return sq(al, ah)
    if n < 0:
        pl, ph = powi(al, ah, -n)
        return inv(pl, ph)
    if n % 2 == 1:
        with np.errstate(all="ignore"):  # an overflowed bound is capped by dnf/upf
            return dnf(np.power(al, n)), upf(np.power(ah, n))
    ml, mh = fabs(al, ah)
    with np.errstate(all="ignore"):
        lo = _max(dnf(np.power(ml, n)), 0.0)
        hi = upf(np.power(mh, n))
    return lo, hi


def powc(al, ah, c: float):
    """x**c for a real constant c (integer c uses :func:`powi`)."""
    c = float(c)
    if not _isfinite(c):
        return _nan_pair(al, ah)
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
    lo, hi = _undefined_where(((al < 0) & (ah >= 0)) | ((al <= 0) & (ah >= 0) & (bl < 0)), lo, hi)
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
    return _keep_nan(lo, hi, al, ah, bl, bh)


# ------------------------------------------------------------------------- logic ops
def _bool_interval(true_sure, false_sure):
    lo = _where(true_sure, 1.0, 0.0)
    hi = _where(false_sure, 0.0, 1.0)
    return lo, hi


def lt(al, ah, bl, bh):
    return _keep_nan(*_bool_interval(ah < bl, al >= bh), al, ah, bl, bh)


def le(al, ah, bl, bh):
    return _keep_nan(*_bool_interval(ah <= bl, al > bh), al, ah, bl, bh)


def eq(al, ah, bl, bh):
    return _keep_nan(*_bool_interval((al == ah) & (bl == bh) & (al == bl),
                                     (ah < bl) | (al > bh)), al, ah, bl, bh)


def ne(al, ah, bl, bh):
    return _keep_nan(*_bool_interval((ah < bl) | (al > bh),
                                     (al == ah) & (bl == bh) & (al == bl)), al, ah, bl, bh)


def _nonzero_sure(al, ah):
    return (al > 0) | (ah < 0)


def _zero_sure(al, ah):
    return (al == 0) & (ah == 0)


def not_(al, ah):
    return _keep_nan(*_bool_interval(_zero_sure(al, ah), _nonzero_sure(al, ah)), al, ah)


def and_(al, ah, bl, bh):
    return _keep_nan(*_bool_interval(_nonzero_sure(al, ah) & _nonzero_sure(bl, bh),
                                     _zero_sure(al, ah) | _zero_sure(bl, bh)),
                     al, ah, bl, bh)


def or_(al, ah, bl, bh):
    return _keep_nan(*_bool_interval(_nonzero_sure(al, ah) | _nonzero_sure(bl, bh),
                                     _zero_sure(al, ah) & _zero_sure(bl, bh)),
                     al, ah, bl, bh)


def if_else_zero(cl, ch, xl, xh):
    """``c ? x : 0``: x when c is surely non-zero, 0 when surely zero, else hull(x, 0)."""
    sure = _nonzero_sure(cl, ch)
    zero = _zero_sure(cl, ch)
    lo = _where(sure, xl, _where(zero, 0.0, _min(xl, 0.0)))
    hi = _where(sure, xh, _where(zero, 0.0, _max(xh, 0.0)))
    return _keep_nan(lo, hi, cl, ch, xl, xh)


def assign(al, ah):
    return al, ah


def hull(al, ah, bl, bh):
    """Interval hull of two intervals (not a CasADi op; used by the compiler)."""
    return _two_sided(_min(al, bl), _max(ah, bh))


def intersect(al, ah, bl, bh):
    """Intersection; an empty intersection (which cannot happen for two sound enclosures of
    the same value) is reported as NaN (no information)."""
    return _two_sided(_max(al, bl), _min(ah, bh))
