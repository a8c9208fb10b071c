"""Interval operations at extreme magnitudes: overflow, underflow, subnormals, infinite bounds.

Two facts are checked for every operation the compiler supports (and the constant
specialisations it emits), on boxes far from the origin (1e8, 1e15, 1e300, the largest
float), very thin (zero width, one ulp) or very wide, half-infinite or the whole line, with
endpoints at subnormals, at 0 or -0.0, and at the special points of the operation:

* the **invariant** of every result: either both bounds are NaN ("possibly undefined, no
  information") or neither is, and then ``lo <= hi``, ``lo < +inf`` and ``hi > -inf``;
* **soundness**: at sampled points of the operand boxes (corners, float neighbours of the
  corners, midpoints, special points, random and extreme points) the exact real value
  (mpmath, 300 bits) lies in ``[lo, hi]``; where the function is undefined at such a point
  the result is ``[nan, nan]``.

Composites of two or three operations compiled from CasADi graphs are checked the same way
through :func:`casadi_cmpc.interval.inclusion` (whose outputs carry no NaN: "possibly
undefined" is the whole line there).

Both evaluators are checked: the operations that take the fixture ``A`` run on the numpy
operations of ``arith`` and on the scalar (Python float) operations of the small-batch
backend; the compiled composites take the fixture ``backend`` and are evaluated by the numpy
evaluator and by the scalar one (which then may not fall back to numpy).
"""

from __future__ import annotations

import math

import casadi as ca
import mp_reference as R
import mpmath
import numpy as np
import pytest
from backends import ARITH, BACKENDS, COMPILED_BACKENDS, compiled
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from casadi_cmpc.interval import arith as A
from casadi_cmpc.interval import ops

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

INF = math.inf
NAN = math.nan
MAX = float(np.finfo(float).max)


@pytest.fixture(scope="module", params=BACKENDS, name="A")
def _backend_ops(request):
    """The interval operations of one backend; the tests that take it shadow the module name
    ``A`` (``arith``)."""
    return ARITH[request.param]


@pytest.fixture(scope="module", params=COMPILED_BACKENDS)
def backend(request):
    """The evaluator of the compiled inclusion functions."""
    return request.param


def _needs(ops_ns, name):
    if not hasattr(ops_ns, name):
        pytest.skip(f"{name} is a helper of the numpy compiler only")
SUB = 5e-324
SETTINGS = settings(max_examples=30, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# ------------------------------------------------------------ references at extremes
# Values beyond the float range stand in for the exact ones where only their position
# relative to floats matters: a real above MAX lies in [lo, hi] (lo, hi floats or +-inf)
# exactly when 2**1100 does, a real in (0, 2**-1074) exactly when 2**-1100 does. This
# keeps mpmath from computing exp(1e300) to 300 bits for every sample.
HUGE = mpmath.mpf(2) ** 1100
TINY_POS = mpmath.mpf(2) ** -1100
_BIG_ARG = 1000


def _exp(a):
    if a > _BIG_ARG:
        return HUGE
    if a < -_BIG_ARG:
        return TINY_POS
    return R.exp(a)


def _expm1(a):
    if a > _BIG_ARG:
        return HUGE
    if a < -_BIG_ARG:
        return -1 + mpmath.mpf(2) ** -200  # in (-1, -1 + ulp(1)) like the exact value
    return R.expm1(a)


def _sinh(a):
    if abs(a) > _BIG_ARG:
        return HUGE if a > 0 else -HUGE
    return R.sinh(a)


def _cosh(a):
    return HUGE if abs(a) > _BIG_ARG else R.cosh(a)


def _pow(a, b):
    if a > 0 and not (b == mpmath.floor(b) and abs(b) < 2 ** 62):
        t = b * mpmath.log(a, 2)
        if t > 1200:
            return HUGE
        if t < -1200:
            return TINY_POS
    return R.pow(a, b)


def _powi(a, n):
    if a != 0 and abs(n * mpmath.log(abs(a), 2)) > 1200:
        big = n * mpmath.log(abs(a), 2) > 0
        v = HUGE if big else TINY_POS
        return -v if (a < 0 and n % 2) else v
    return R.powi(a, n)


UNARY_REF = {
    "assign": lambda a: a, "neg": R.neg, "sq": R.sq, "twice": R.twice, "inv": R.inv,
    "sqrt": R.sqrt, "exp": _exp, "expm1": _expm1, "log": R.log, "log1p": R.log1p,
    "sin": R.sin, "cos": R.cos, "tan": R.tan, "asin": R.asin, "acos": R.acos,
    "atan": R.atan, "sinh": _sinh, "cosh": _cosh, "tanh": R.tanh, "asinh": R.asinh,
    "acosh": R.acosh, "atanh": R.atanh, "fabs": R.fabs, "floor": R.floor, "ceil": R.ceil,
    "sign": R.sign, "not_": R.not_, "erf": R.erf, "erfinv": R.erfinv,
}
BINARY_REF = {
    "add": R.add, "sub": R.sub, "mul": R.mul, "div": R.div, "pow": _pow, "atan2": R.atan2,
    "fmin": R.fmin, "fmax": R.fmax, "lt": R.lt, "le": R.le, "eq": R.eq, "ne": R.ne,
    "and_": R.and_, "or_": R.or_, "if_else_zero": R.if_else_zero, "copysign": R.copysign,
    "fmod": R.fmod, "remainder": R.remainder, "hypot": R.hypot,
}

HALF_PI_MULTS = [float(k * mpmath.pi / 2) for k in
                 [-3, -1, 1, 3, 63_661_977, 63_661_979, -63_661_977, 2**40 + 1, 2**60 + 1]]
UNARY_SPECIAL = {
    "exp": [709.782712893384, 709.7827128933841, -745.1332191019411, -708.4, 1e3],
    "expm1": [709.782712893384, -37.0, -1e3],
    "sinh": [710.4758600739439, 710.475860073944, -710.4758600739439],
    "cosh": [710.4758600739439, 710.475860073944, -710.4758600739439],
    "sin": HALF_PI_MULTS, "cos": HALF_PI_MULTS, "tan": HALF_PI_MULTS,
    "asin": [-1.0, 1.0], "acos": [-1.0, 1.0], "atanh": [-1.0, 1.0], "erfinv": [-1.0, 1.0],
    "acosh": [1.0], "log": [1.0], "log1p": [-1.0],
    "floor": [-1.0, 1.0, 2.0**52, 2.0**53 + 2, -2.0**52 - 0.5],
    "ceil": [-1.0, 1.0, 2.0**52, 2.0**53 + 2, -2.0**52 - 0.5],
    "sq": [1.3407807929942596e154, 1e200],
}
EXTREMES = [0.0, -0.0, SUB, -SUB, 1e-320, -1e-320, 2.2250738585072014e-308, 1e-300, 1.0,
            -1.0, 1e8, -1e8, 1e15, -1e15, 1e300, -1e300, MAX, -MAX]


# ----------------------------------------------------------------------------- boxes
def _step(x: float, k: int) -> float:
    for _ in range(abs(k)):
        x = float(np.nextafter(x, INF if k > 0 else -INF))
    return x


def _value(specials):
    mag = st.tuples(st.floats(-323.0, 308.0), st.floats(1.0, 1.79),
                    st.booleans()).map(lambda t: (-1 if t[2] else 1) * t[1] * 10.0 ** t[0])
    parts = [st.sampled_from(EXTREMES), mag, st.floats(-4.0, 4.0)]
    if specials:
        sp = list(specials)
        parts += [st.sampled_from(sp),
                  st.tuples(st.sampled_from(sp), st.integers(-2, 2)).map(
                      lambda t: _step(t[0], t[1]))]
    return st.one_of(parts).filter(math.isfinite)


@st.composite
def xbox(draw, specials=()):
    kind = draw(st.sampled_from(["thin", "ulp", "pair", "pair", "left_inf", "right_inf",
                                 "whole", "rel"]))
    if kind == "whole":
        return -INF, INF
    a = draw(_value(specials))
    if kind == "thin":
        return a, a
    if kind == "ulp":
        return a, _step(a, draw(st.integers(1, 3)))
    if kind == "left_inf":
        return -INF, a
    if kind == "right_inf":
        return a, INF
    if kind == "rel":
        w = abs(a) * 10.0 ** draw(st.floats(-16.0, 0.0))
        b = a + w
        return (a, b) if math.isfinite(b) and b > a else (a, a)
    b = draw(_value(specials))
    return min(a, b), max(a, b)


def _points(lo: float, hi: float, specials, rng, cap: int = 8) -> list[float]:
    """Finite floats inside [lo, hi], the most telling first."""
    cand = [lo, hi]
    if lo < hi:
        cand += [_step(lo, 1), _step(hi, -1)]
    if math.isfinite(lo) and math.isfinite(hi):
        cand.append(0.5 * lo + 0.5 * hi)
    cand += list(specials)
    cand += [0.0]
    u = rng.random()
    if math.isfinite(lo) and math.isfinite(hi):
        cand.append(lo + (hi - lo) * u if math.isfinite(hi - lo) else lo * (1 - u) + hi * u)
    cand += [float(rng.choice([-1.0, 1.0])) * 10.0 ** rng.uniform(-323, 308)]
    cand += list(rng.permutation(EXTREMES))
    out: list[float] = []
    for p in cand:
        p = float(p)
        if math.isfinite(p) and lo <= p <= hi and p not in out:
            out.append(p)
        if len(out) >= cap:
            break
    return out


def seeds():
    return st.integers(0, 2**32 - 1).map(np.random.default_rng)


# ---------------------------------------------------------------------------- checks
def check_invariant(lo, hi, ctx=""):
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    ln, hn = np.isnan(lo), np.isnan(hi)
    assert np.array_equal(ln, hn), f"{ctx}: one-sided NaN [{lo!r}, {hi!r}]"
    ok = ~ln
    assert np.all(lo[ok] <= hi[ok]), f"{ctx}: lo > hi in [{lo!r}, {hi!r}]"
    assert not np.any(lo[ok] == INF), f"{ctx}: lower bound +inf in [{lo!r}, {hi!r}]"
    assert not np.any(hi[ok] == -INF), f"{ctx}: upper bound -inf in [{lo!r}, {hi!r}]"


def check_point(lo, hi, ref, args, ctx, undefined_ok=("nan",)):
    """The exact value at args is inside [lo, hi]; where undefined, no information."""
    lo, hi = float(lo), float(hi)
    try:
        v = ref(*[R.F(a) for a in args])
    except R.Undefined:
        nan = math.isnan(lo) and math.isnan(hi)
        whole = "whole" in undefined_ok and lo == -INF and hi == INF
        assert nan or whole, f"{ctx}: undefined at {args!r} but the result is [{lo!r}, {hi!r}]"
        return
    assert R.inside(lo, hi, v), (
        f"{ctx}: exact value {mpmath.nstr(v, 20)} at {args!r} is outside [{lo!r}, {hi!r}]")


def _arr(bs):
    return np.array([b[0] for b in bs]), np.array([b[1] for b in bs])


def _bc(lo, hi, n):
    return np.broadcast_to(lo, (n,)), np.broadcast_to(hi, (n,))


# ------------------------------------------------------------------------ unary ops
@pytest.mark.parametrize("name", sorted(UNARY_REF))
@SETTINGS
@given(data=st.data())
def test_unary_extreme(name, data, A):
    specials = UNARY_SPECIAL.get(name, [])
    bs = data.draw(st.lists(xbox(specials), min_size=1, max_size=4), label="boxes")
    rng = data.draw(seeds(), label="rng")
    al, ah = _arr(bs)
    lo, hi = _bc(*getattr(A, name)(al, ah), len(bs))
    for i, (a, b) in enumerate(bs):
        ctx = f"{name}([{a!r}, {b!r}])"
        check_invariant(lo[i], hi[i], ctx)
        for p in _points(a, b, specials, rng):
            check_point(lo[i], hi[i], UNARY_REF[name], (p,), ctx)


# ----------------------------------------------------------------------- binary ops
BINARY_SPECIAL = {
    "pow": ([0.0, 1.0, -1.0, -2.0, 2.0], [0.0, 0.5, 2.0, 3.0, -1.0, -2.0, 2.5, 1e300]),
    "atan2": ([0.0, -0.0, 1.0, -1.0], [0.0, -0.0, -1.0, 1.0]),
    "fmod": ([0.0, 1.0, 3.0, 1e300], [0.0, 1.0, 2.0, -3.0, SUB]),
    "remainder": ([0.0, 1.5, 2.5, 1e300, 2 * SUB], [0.0, 1.0, 2.0, -3.0, 3 * SUB]),
    "div": ([0.0, 1.0], [0.0, 1.0, -1.0]),
}


@pytest.mark.parametrize("name", sorted(BINARY_REF))
@SETTINGS
@given(data=st.data())
def test_binary_extreme(name, data, A):
    sa, sb = BINARY_SPECIAL.get(name, ([0.0, 1.0], [0.0, 1.0]))
    n = data.draw(st.integers(1, 3), label="n")
    ba = data.draw(st.lists(xbox(sa), min_size=n, max_size=n), label="a")
    bb = data.draw(st.lists(xbox(sb), min_size=n, max_size=n), label="b")
    rng = data.draw(seeds(), label="rng")
    al, ah = _arr(ba)
    bl, bh = _arr(bb)
    lo, hi = _bc(*getattr(A, name)(al, ah, bl, bh), n)
    for i in range(n):
        ctx = f"{name}({ba[i]!r}, {bb[i]!r})"
        check_invariant(lo[i], hi[i], ctx)
        pa = _points(*ba[i], sa, rng, cap=5)
        pb = _points(*bb[i], sb, rng, cap=5)
        for x in pa:
            for y in pb:
                check_point(lo[i], hi[i], BINARY_REF[name], (x, y), ctx)


# ------------------------------------------------------------ constant specialisations
CONST = st.one_of(st.sampled_from(EXTREMES + [0.5, 2.0, 3.0, -2.5]), _value([]))


@pytest.mark.parametrize("name", ["addc", "csub", "mulc", "divc", "cdiv", "mulci", "powc",
                                  "powi"])
@SETTINGS
@given(data=st.data())
def test_constant_ops_extreme(name, data, A):
    bs = data.draw(st.lists(xbox([0.0, 1.0, -1.0]), min_size=1, max_size=4), label="boxes")
    rng = data.draw(seeds(), label="rng")
    al, ah = _arr(bs)
    if name == "mulci":
        c1 = data.draw(CONST.filter(lambda v: v != 0.0), label="c1")
        c2 = data.draw(CONST.filter(lambda v: v != 0.0 and (v > 0) == (c1 > 0)), label="c2")
        cl, ch = min(c1, c2), max(c1, c2)
        lo, hi = A.mulci(al, ah, cl, ch)
        mid = 0.5 * cl + 0.5 * ch
        cs = [cl, ch] + ([mid] if cl <= mid <= ch and mid != 0.0 else [])
        def ref(x):
            return [R.mul(x, R.F(c)) for c in cs]
    elif name == "powi":
        k = data.draw(st.one_of(st.integers(-5, 9), st.sampled_from([101, -101, 2**20])),
                      label="n")
        lo, hi = A.powi(al, ah, k)
        def ref(x):
            return [_powi(x, k)]
    else:
        c = data.draw(CONST if name != "powc" else st.one_of(
            CONST, st.sampled_from([0.5, -0.5, 1.5, -2.5, 1 / 3, 1e-300, 2.0**31 + 0.5])),
            label="c")
        fn = getattr(A, name)
        lo, hi = fn(c, al, ah) if name in ("csub", "cdiv") else fn(al, ah, c)
        C = R.F(c)
        one = {"addc": lambda x: R.add(x, C), "csub": lambda x: R.sub(C, x),
               "mulc": lambda x: R.mul(x, C), "divc": lambda x: R.div(x, C),
               "cdiv": lambda x: R.div(C, x), "powc": lambda x: _pow(x, C)}[name]
        def ref(x):
            return [one(x)]
    lo, hi = _bc(lo, hi, len(bs))
    for i, (a, b) in enumerate(bs):
        ctx = f"{name}([{a!r}, {b!r}])"
        check_invariant(lo[i], hi[i], ctx)
        for p in _points(a, b, [0.0, 1.0, -1.0], rng, cap=6):
            try:
                vals = ref(R.F(p))
            except R.Undefined:
                assert math.isnan(lo[i]) and math.isnan(hi[i]), f"{ctx}: undefined at {p!r}"
                continue
            for v in vals:
                assert R.inside(lo[i], hi[i], v), f"{ctx}: {mpmath.nstr(v, 20)} at {p!r}"


# --------------------------------------------------------- NaN in any bound widens
# Operations that branch on (or combine) both bounds of an operand give [nan, nan] for a NaN
# in any operand bound. The others (sums, monotone functions) compute each bound from the
# matching operand bounds, so they keep the invariant for operands that satisfy it.
CASE_BASED_UNARY = ["tan", "sin", "cos", "floor", "ceil", "sign", "fabs", "sq", "not_",
                    "cosh"]
CASE_BASED_BINARY = ["fmin", "fmax", "copysign", "fmod", "remainder", "atan2", "hypot", "pow",
                     "lt", "le", "eq", "ne", "and_", "or_", "if_else_zero", "intersect",
                     "hull", "mul", "div"]


@pytest.mark.parametrize("name", sorted(UNARY_REF))
def test_nan_operand_unary(name, A):
    lo, hi = getattr(A, name)(np.array([NAN, 1.0]), np.array([NAN, 2.0]))
    assert math.isnan(lo[0]) and math.isnan(hi[0]), (name, lo, hi)
    check_invariant(lo, hi, name)


@pytest.mark.parametrize("name", sorted(BINARY_REF))
@pytest.mark.parametrize("other", [(-1.0, 2.0), (0.0, 0.0), (-INF, INF), (2.0, INF)])
def test_nan_operand_binary(name, other, A):
    fn = getattr(A, name)
    n, o = (np.array([NAN]), np.array([NAN])), (np.array([other[0]]), np.array([other[1]]))
    for args in ((*n, *o), (*o, *n)):
        lo, hi = fn(*args)
        assert math.isnan(lo[0]) and math.isnan(hi[0]), (name, args, lo, hi)


@pytest.mark.parametrize("name", CASE_BASED_UNARY)
@pytest.mark.parametrize("other", [(-1.0, 2.0), (0.0, 0.0), (1.0, 2.0), (-INF, INF),
                                   (710.0, 711.0), (-1e300, 1e300)])
def test_nan_in_one_bound_unary(name, other, A):
    fn = getattr(A, name)
    for args in ((NAN, other[1]), (other[0], NAN), (NAN, NAN)):
        lo, hi = fn(np.array([args[0]]), np.array([args[1]]))
        lo, hi = float(np.reshape(lo, -1)[0]), float(np.reshape(hi, -1)[0])
        assert math.isnan(lo) and math.isnan(hi), (name, args, lo, hi)


@pytest.mark.parametrize("name", CASE_BASED_BINARY)
@pytest.mark.parametrize("other", [(-1.0, 2.0), (0.0, 0.0), (1.0, 2.0), (-INF, INF),
                                   (2.0, 2.0)])
def test_nan_in_one_bound_binary(name, other, A):
    _needs(A, name)
    fn = getattr(A, name)
    o = [np.array([v]) for v in other]
    for nan_pair in ((NAN, other[1]), (other[0], NAN), (NAN, NAN)):
        n = [np.array([v]) for v in nan_pair]
        for args in ((*n, *o), (*o, *n)):
            lo, hi = fn(*args)
            lo, hi = float(np.reshape(lo, -1)[0]), float(np.reshape(hi, -1)[0])
            assert math.isnan(lo) and math.isnan(hi), (name, args, lo, hi)


def test_ops_wrappers_make_one_sided_nan_two_sided():
    r = ops.exp(np.array([[NAN, 1.0], [0.0, 1.0]]))
    assert np.isnan(r[0]).all() and np.isfinite(r[1]).all()
    r = ops.add(np.array([1.0, NAN]), np.array([0.0, 1.0]))
    assert np.isnan(r).all()


# ---------------------------------------------------------------- known cases
def _one(fn, *vals):
    lo, hi = fn(*(np.array([v]) for v in vals))
    return float(np.reshape(lo, -1)[0]), float(np.reshape(hi, -1)[0])


@pytest.mark.parametrize(("name", "args"), [
    ("exp", (710.0, 711.0)), ("expm1", (710.0, 711.0)), ("sinh", (711.0, 712.0)),
    ("cosh", (-712.0, -711.0)), ("sq", (1e200, 1e201)), ("twice", (1e308, MAX)),
    ("mul", (1e200, 1e201, 1e200, 1e201)), ("div", (1e300, 1e301, 1e-10, 1e-9)),
    ("add", (MAX, MAX, MAX, MAX)), ("hypot", (1e308, MAX, 1e308, MAX)),
    ("powi3", (1e200, 1e201)), ("powc", (1e200, 1e201)), ("pow", (1e200, 1e201, 2.5, 3.5)),
])
def test_overflow_keeps_a_finite_lower_bound(name, args, A):
    """An overflowed value is a finite real above the largest float: its lower bound is
    below the exact value (at most MAX), never +inf or NaN."""
    if name == "powi3":
        lo, hi = _one(lambda a, b: A.powi(a, b, 3), *args)
    elif name == "powc":
        lo, hi = _one(lambda a, b: A.powc(a, b, 2.5), *args)
    else:
        lo, hi = _one(getattr(A, name), *args)
    assert not math.isnan(lo) and lo <= MAX and hi == INF, (name, lo, hi)
    assert lo > 1e300, (name, lo)  # still informative


@pytest.mark.parametrize(("name", "args"), [
    ("sinh", (-712.0, -711.0)), ("mul", (-1e201, -1e200, 1e200, 1e201)),
    ("sub", (-MAX, -MAX, MAX, MAX)), ("powi3", (-1e201, -1e200)),
])
def test_negative_overflow_keeps_a_finite_upper_bound(name, args, A):
    if name == "powi3":
        lo, hi = _one(lambda a, b: A.powi(a, b, 3), *args)
    else:
        lo, hi = _one(getattr(A, name), *args)
    assert lo == -INF and not math.isnan(hi) and -MAX <= hi < -1e300, (name, lo, hi)


def test_sin_cos_of_unbounded_box_is_the_range(A):
    for fn in (A.sin, A.cos):
        assert _one(fn, -INF, 0.0) == (-1.0, 1.0)
        assert _one(fn, 1e300, INF) == (-1.0, 1.0)


# --------------------------------------------------------------- compiled composites
X0, X1 = ca.SX.sym("x0"), ca.SX.sym("x1")
_U = {
    "exp": ca.exp, "log": ca.log, "sin": ca.sin, "cos": ca.cos, "tan": ca.tan,
    "sqrt": ca.sqrt, "sq": lambda a: a * a, "inv": lambda a: 1 / a, "neg": lambda a: -a,
    "floor": ca.floor, "ceil": ca.ceil, "sign": ca.sign, "fabs": ca.fabs, "atan": ca.atan,
    "sinh": ca.sinh, "cosh": ca.cosh, "tanh": ca.tanh, "asin": ca.asin, "acos": ca.acos,
    "atanh": ca.atanh, "acosh": ca.acosh, "asinh": ca.asinh, "erf": ca.erf,
    "erfinv": ca.erfinv, "expm1": ca.expm1, "log1p": ca.log1p, "not": ca.logic_not,
    "twice": lambda a: 2 * a, "cube": lambda a: a ** 3, "sqrtc": lambda a: a ** 0.5,
    "rpow": lambda a: a ** -2.5,
}
_B = {
    "add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
    "div": lambda a, b: a / b, "pow": lambda a, b: a ** b, "atan2": ca.atan2,
    "fmin": ca.fmin, "fmax": ca.fmax, "hypot": ca.hypot, "copysign": ca.copysign,
    "fmod": ca.fmod, "remainder": ca.remainder, "lt": lambda a, b: a < b,
    "le": lambda a, b: a <= b, "eq": lambda a, b: a == b, "ne": lambda a, b: a != b,
    "and": ca.logic_and, "or": ca.logic_or, "if_else": lambda a, b: ca.if_else(a, b, -b),
}
_LEAF = st.sampled_from(["x0", "x1", "c"])


@st.composite
def trees(draw, depth=3):
    if depth == 0:
        return draw(_LEAF)
    k = draw(st.sampled_from(["u", "b", "b"]))
    if k == "u":
        return (draw(st.sampled_from(sorted(_U))), draw(trees(depth - 1)))
    return (draw(st.sampled_from(sorted(_B))), draw(trees(depth - 1)),
            draw(trees(draw(st.integers(0, depth - 1)))))


def _build(t, c):
    if isinstance(t, str):
        return {"x0": X0, "x1": X1, "c": ca.SX(c)}[t]
    if len(t) == 2:
        return _U[t[0]](_build(t[1], c))
    return _B[t[0]](_build(t[1], c), _build(t[2], c))


class _TooBig(Exception):
    """The exact value at this point is too expensive for mpmath (e.g. exp(exp(1e300)))."""


_BIG_MPF = mpmath.mpf(2) ** 4000


def _guard(fn, limit=_BIG_MPF):
    def g(*args):
        if any(abs(a) > limit for a in args):
            raise _TooBig
        return fn(*args)
    return g


def _guarded_pow(a, b):
    if a != 0 and abs(b * mpmath.log(abs(a), 2)) > 1e6:
        raise _TooBig
    return R.pow(a, b)


# exact semantics, except that points whose evaluation needs astronomically large
# intermediate values are skipped
SAFE_OPS = {
    ca.OP_EXP: _guard(R.exp, 1e5), ca.OP_EXPM1: _guard(R.expm1, 1e5),
    ca.OP_SINH: _guard(R.sinh, 1e5), ca.OP_COSH: _guard(R.cosh, 1e5),
    ca.OP_SIN: _guard(R.sin, 1e300), ca.OP_COS: _guard(R.cos, 1e300),
    ca.OP_TAN: _guard(R.tan, 1e300), ca.OP_POW: _guarded_pow, ca.OP_CONSTPOW: _guarded_pow,
    **{op: _guard(R._OPS[op]) for op in (
        ca.OP_SQ, ca.OP_MUL, ca.OP_DIV, ca.OP_INV, ca.OP_ERF, ca.OP_ERFINV, ca.OP_FMOD,
        ca.OP_REMAINDER, ca.OP_ATAN2, ca.OP_HYPOT, ca.OP_TANH, ca.OP_ATAN, ca.OP_ASINH,
        ca.OP_LOG, ca.OP_LOG1P, ca.OP_SQRT, ca.OP_ACOSH, ca.OP_FLOOR, ca.OP_CEIL)},
}


def _check_compiled(f, boxes, rng, ctx, n_pts=5, backend="numpy"):
    F = compiled(f, backend=backend)
    X = np.array([[b0, b1] for b0, b1 in boxes])
    out = F(X)[0][:, 0, :]
    assert not np.isnan(out).any(), f"{ctx}: NaN in a compiled result {out!r}"
    for i, (b0, b1) in enumerate(boxes):
        lo, hi = float(out[i, 0]), float(out[i, 1])
        c = f"{ctx} on {b0!r} x {b1!r}"
        if not (f.n_instructions() == 2 and math.isinf(lo) and lo == hi):
            check_invariant(lo, hi, c)  # (CasADi may fold the whole graph to inf: [inf, inf])
        p0 = _points(*b0, [], rng, cap=n_pts)
        p1 = _points(*b1, [], rng, cap=n_pts)
        for x in p0:
            for y in p1:
                try:
                    # enough bits for the fractional part of sums near the largest float
                    # (fmod(asin(1) + x0, 1) at x0 = -MAX needs more than 1024 bits)
                    with mpmath.workprec(2400):
                        v = R.eval_function(f, [[x, y]], SAFE_OPS)[0]
                except _TooBig:
                    continue
                v = v[0] if v else R.ZERO
                if v is R.UNDEF:
                    assert lo == -INF and hi == INF, f"{c}: undefined at {(x, y)} but [{lo}, {hi}]"
                else:
                    assert R.inside(lo, hi, v), (
                        f"{c}: exact value {mpmath.nstr(v, 20)} at {(x, y)} outside [{lo}, {hi}]")


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(tree=trees(), c=st.sampled_from([0.0, 1.0, -2.5, 1e300, 710.0, 1e-320, 3.0]),
       data=st.data())
def test_compiled_composites_extreme(tree, c, data, backend):
    f = ca.Function("f", [ca.vertcat(X0, X1)], [_build(tree, c)])
    n = data.draw(st.integers(1, 3), label="n")
    boxes = [(data.draw(xbox([0.0, 1.0]), label="b0"), data.draw(xbox([0.0, 1.0]), label="b1"))
             for _ in range(n)]
    rng = data.draw(seeds(), label="rng")
    _check_compiled(f, boxes, rng, f"{tree} (c={c})", n_pts=3, backend=backend)


def test_overflow_does_not_narrow_tan_fmin_exp(backend):
    """tan(fmin(exp(x0), x1)) on [710, 711] x [1, 2]: fmin is x1 there, and tan has a pole in
    [1, 2], so the enclosure must be the whole line (it was [-inf, -2.185], which contains
    neither tan(1.5) = 14.1 nor tan(1) = 1.56)."""
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [ca.tan(ca.fmin(ca.exp(x[0]), x[1]))])
    F = compiled(f, backend=backend)
    out = F(np.array([[[710.0, 711.0], [1.0, 2.0]]]))[0][0, 0]
    assert out[0] == -INF and out[1] == INF
    # and with x1 below the pole, the enclosure is bounded and contains tan(x1)
    out = F(np.array([[[710.0, 711.0], [1.0, 1.5]]]))[0][0, 0]
    assert out[0] <= math.tan(1.0) and out[1] >= math.tan(1.5) and np.isfinite(out).all()
    _check_compiled(f, [((710.0, 711.0), (1.0, 2.0)), ((710.0, 711.0), (1.0, 1.5)),
                        ((-INF, 711.0), (-1.0, 1.0))], np.random.default_rng(0), "tan-fmin-exp",
                    backend=backend)


def test_undefined_constant_subexpression_stays_undefined(backend):
    """A subexpression folded at compile time to "possibly undefined" (log(-2.5)) must not
    turn into "any real" that a bounded operation (sin, atan) then makes informative."""
    x = ca.SX.sym("x")
    for e in (ca.sin(ca.log((x - x) - 2.5)) + x, ca.atan(ca.sqrt(ca.SX(-1.0))) * x,
              ca.tanh(ca.log(ca.SX(-1.0)) * x)):
        f = ca.Function("f", [x], [e])
        out = compiled(f, backend=backend)(np.array([[[1.0, 2.0]]]))[0][0, 0]
        assert out[0] == -INF and out[1] == INF, (e, out)


@pytest.mark.parametrize(("expr", "box"), [
    (lambda a, b: ca.exp(a) - ca.exp(b), ((710.0, 711.0), (709.0, 709.5))),
    (lambda a, b: ca.fmax(-ca.exp(a), b), ((710.0, 711.0), (-2.0, -1.0))),
    (lambda a, b: ca.sin(ca.fmin(a * b, 3.0)), ((1e200, 1e201), (1e200, 1e201))),
    (lambda a, b: ca.floor(ca.fmin(ca.sinh(a), b)), ((711.0, 712.0), (0.5, 2.5))),
    (lambda a, b: ca.atan2(ca.fmin(ca.exp(a), b), -1.0), ((710.0, 711.0), (-1.0, 1.0))),
    (lambda a, b: ca.sign(ca.fmin(ca.exp(a), b)), ((710.0, 711.0), (-1.0, 1.0))),
    (lambda a, b: ca.fmod(ca.fmin(ca.exp(a), b), 3.0), ((710.0, 711.0), (-5.0, 5.0))),
    (lambda a, b: ca.if_else(ca.exp(a) < b, 1.0, -1.0), ((710.0, 711.0), (-1.0, 1.0))),
    (lambda a, b: ca.fmin(ca.hypot(a, b), 1.0), ((1e308, MAX), (1e308, MAX))),
    (lambda a, b: ca.tan(ca.fmin(ca.exp(a), b)), ((-INF, 711.0), (1.0, 2.0))),
    (lambda a, b: ca.cos(ca.fmin(2 * a, b)), ((1e308, MAX), (0.0, 4.0))),
])
def test_compiled_overflow_cases(expr, box, backend):
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [expr(x[0], x[1])])
    _check_compiled(f, [box], np.random.default_rng(1), "case", backend=backend)


def test_reference_treats_a_nan_constant_as_undefined(backend):
    """CasADi folds log((x0 - x0) - 2.5) to the constant NaN: the reference value of that
    graph is "undefined", not the number NaN (which no enclosure can contain)."""
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [ca.log((x[0] - x[0]) + -2.5)])
    assert R.eval_function(f, [[1.0, 2.0]])[0][0] is R.UNDEF
    out = compiled(f, backend=backend)(np.array([[[1.0, 2.0], [0.0, 1.0]]]))[0][0, 0]
    assert out[0] == -INF and out[1] == INF


@settings(max_examples=300, deadline=None)
@given(k=st.one_of(st.integers(-63_661_977, 63_661_977),
                   st.integers(63_000_000, 63_661_977), st.integers(-10, 10)),
       which=st.sampled_from(["sin_max", "sin_min", "cos_max", "cos_min", "tan_pole"]))
def test_contains_point_is_conservative_up_to_the_safe_magnitude(k, which):
    """The tightest float box around an exact extremum of sin/cos or pole of tan with
    |x| <= 1e8 (beyond, the full range is used) is recognised as containing it, whatever
    the rounding of (x - offset) / period."""
    pi = mpmath.pi
    off, period, a_off, a_period = {
        "sin_max": (pi / 2, 2 * pi, 0.5 * A.PI_LO, 2.0 * A.PI_LO),
        "sin_min": (-pi / 2, 2 * pi, -0.5 * A.PI_LO, 2.0 * A.PI_LO),
        "cos_max": (mpmath.mpf(0), 2 * pi, 0.0, 2.0 * A.PI_LO),
        "cos_min": (pi, 2 * pi, A.PI_LO, 2.0 * A.PI_LO),
        "tan_pole": (pi / 2, pi, 0.5 * A.PI_LO, A.PI_LO),
    }[which]
    x = off + k * period
    if abs(x) > 1e8:
        return
    f = float(x)
    lo = f if R.F(f) <= x else float(np.nextafter(f, -INF))
    hi = f if R.F(f) >= x else float(np.nextafter(f, INF))
    assert R.F(lo) <= x <= R.F(hi)
    got = A._contains_point(np.array([lo]), np.array([hi]), a_off, a_period)
    assert bool(got[0]), (which, k, lo, hi)
    if which == "tan_pole":
        r = A.tan(np.array([lo]), np.array([hi]))
        assert np.isnan(r[0][0]) and np.isnan(r[1][0])
    else:
        fn = A.sin if which.startswith("sin") else A.cos
        r = fn(np.array([lo]), np.array([hi]))
        assert (r[1][0] == 1.0) if which.endswith("max") else (r[0][0] == -1.0)


# an operation that overflows on the first box, a combination with a moderate second
# operand, then an operation that branches on its operand bounds or is bounded
_OVERFLOWING = {
    "exp": (ca.exp, (709.0, 712.0)), "sinh": (ca.sinh, (-712.0, 712.0)),
    "cosh": (ca.cosh, (-712.0, 712.0)), "sq": (lambda a: a * a, (1e150, 1e160)),
    "cube": (lambda a: a ** 3, (-1e110, 1e105)), "twice": (lambda a: 2 * a, (1e307, MAX)),
    "prod": (lambda a: a * a * 1e10, (-1e150, -1e149)), "expm1": (ca.expm1, (709.0, 712.0)),
    "inv": (lambda a: 1 / a, (SUB, 1e-300)), "neg_exp": (lambda a: -ca.exp(a), (709.0, 712.0)),
}
_COMBINE = {
    "fmin": ca.fmin, "fmax": ca.fmax, "add": lambda a, b: a + b, "sub": lambda a, b: b - a,
    "mul": lambda a, b: a * b, "hypot": ca.hypot, "atan2": ca.atan2,
    "atan2r": lambda a, b: ca.atan2(b, a), "copysign": lambda a, b: ca.copysign(b, a),
    "fmod": lambda a, b: ca.fmod(b, a), "remainder": lambda a, b: ca.remainder(b, a),
    "lt": lambda a, b: a < b, "if_else": lambda a, b: ca.if_else(a > b, b, -b),
    "div": lambda a, b: b / a, "pow": lambda a, b: b ** ca.fmin(a, 3.0),
}
_AFTER = {
    "tan": ca.tan, "sin": ca.sin, "cos": ca.cos, "floor": ca.floor, "ceil": ca.ceil,
    "sign": ca.sign, "atan": ca.atan, "tanh": ca.tanh, "erf": ca.erf, "sqrt": ca.sqrt,
    "log": ca.log, "fabs": ca.fabs, "asin": ca.asin, "not": ca.logic_not, "id": lambda a: a,
    "sq": lambda a: a * a, "exp": ca.exp,
}


@settings(max_examples=120, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(e=st.sampled_from(sorted(_OVERFLOWING)), h=st.sampled_from(sorted(_COMBINE)),
       g=st.sampled_from(sorted(_AFTER)), data=st.data())
def test_compiled_overflow_composites(e, h, g, data, backend):
    fe, (a, b) = _OVERFLOWING[e]
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [_AFTER[g](_COMBINE[h](fe(x[0]), x[1]))])
    u = data.draw(st.floats(0.0, 1.0), label="u")
    v = data.draw(st.floats(0.0, 1.0), label="v")
    lo0, hi0 = sorted((a + (b - a) * u, a + (b - a) * v))
    box1 = data.draw(st.one_of(
        st.sampled_from([(1.0, 2.0), (-2.0, -1.0), (-1.0, 1.0), (0.5, 1.5), (0.0, 0.0),
                         (1.5, 1.5), (-INF, 1.0), (1.0, INF), (3.0, 4.0)]),
        xbox([0.0, 1.0, float(mpmath.pi / 2)])), label="x1")
    rng = data.draw(seeds(), label="rng")
    _check_compiled(f, [((lo0, hi0), box1), ((a, b), box1)], rng, f"{g}({h}({e}(x0), x1))",
                    n_pts=4, backend=backend)


def test_fold_keeps_possibly_undefined_constants_undefined():
    """Compile-time folding follows the operations' rule: a folded result with a NaN bound is
    [nan, nan] (possibly undefined), which a later bounded operation keeps NaN, not "any
    real" that atan would turn into [-pi/2, pi/2]."""
    from casadi_cmpc.interval.compiler import _Codegen

    x = ca.SX.sym("x")
    cg = _Codegen(ca.Function("f", [x], [x]))
    cg.consts[0] = (-2.5, -2.5)
    cg._fold("log", 1, [0])
    assert all(math.isnan(v) for v in cg.consts[1])
    cg._fold("atan", 2, [1])
    assert all(math.isnan(v) for v in cg.consts[2])
    cg.consts[3] = (710.0, 711.0)
    cg._fold("exp", 4, [3])
    lo, hi = cg.consts[4]
    assert 1e308 < lo <= MAX and hi == INF
