"""Soundness of the interval operations of ``casadi_cmpc.interval.arith``.

Each operation is evaluated on batches of random boxes (thin, wide, far from zero, tiny,
straddling zero, with endpoints at 0 or at points where the function is special). At points
inside each box (endpoints included) the exact real value, computed with mpmath at 300 bits
from the exactly converted float point, must lie inside the returned bounds (compared
exactly). Where the real function is undefined at a point of the box, the result must carry
no information (the whole line, or NaN), as the documented domain convention says.

The tests that take the fixture ``A`` run twice: on the numpy operations of ``arith`` and on
the scalar (Python float) operations of the small-batch backend, element by element.
"""

from __future__ import annotations

import math

import mp_reference as R
import mpmath
import numpy as np
import pytest
from backends import ARITH, BACKENDS
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from casadi_cmpc.interval import arith as A
from casadi_cmpc.interval import ops

# the raw operations report floating-point exceptions as numpy warnings; they are expected
pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

INF = math.inf
NAN = math.nan
SETTINGS = settings(max_examples=40, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

# float approximations of k*pi/2 (the extrema and zeros of sin/cos, the poles of tan)
HALF_PI_MULTS = [float(k * mpmath.pi / 2)
                 for k in [*range(-8, 9), 1_000_001, -2_000_003, 12_345_678, 63_661_977]]
UNIT = [-1.0, 0.0, 1.0]


@pytest.fixture(scope="module", params=BACKENDS, name="A")
def _backend_ops(request):
    """The interval operations of one backend (``arith`` or the scalar ones); the tests that
    take it shadow the module name ``A`` (``arith``)."""
    return ARITH[request.param]


# ------------------------------------------------------------------------ strategies
def _step(x: float, k: int) -> float:
    """k ulps up (k < 0: down) from x."""
    for _ in range(abs(k)):
        x = float(np.nextafter(x, INF if k > 0 else -INF))
    return x


def _signed(s):
    return st.tuples(s, st.booleans()).map(lambda t: -t[0] if t[1] else t[0])


def _magnitude(e_lo: float, e_hi: float):
    return st.tuples(st.floats(e_lo, e_hi), st.floats(1.0, 9.99)).map(
        lambda t: t[1] * 10.0 ** t[0])


def _near_special(specials):
    return st.tuples(st.sampled_from(specials), st.integers(-2, 2)).map(
        lambda t: _step(t[0], t[1]))


def anchors(specials=()):
    parts = [
        st.floats(-10.0, 10.0),
        _signed(_magnitude(6, 12)),  # far from zero
        _signed(_magnitude(-300, -200)),  # tiny (normal)
        _signed(_magnitude(-3, 3)),
        _signed(_magnitude(12, 307)),  # huge (overflow paths)
        _signed(_magnitude(-323, -308)),  # subnormal
        st.just(0.0),
    ]
    if specials:
        parts += [st.sampled_from(list(specials)), _near_special(list(specials))]
    return st.one_of(parts)


@st.composite
def box(draw, specials=()):
    kinds = ["thin", "ulps", "near", "wide", "straddle", "zero_end"]
    if specials:
        kinds += ["special_end", "special_end"]
    kind = draw(st.sampled_from(kinds))
    if kind == "straddle":
        return -draw(_magnitude(-3, 3)), draw(_magnitude(-3, 3))
    if kind == "zero_end":
        m = draw(_magnitude(-300, 3))
        return (0.0, m) if draw(st.booleans()) else (-m, 0.0)
    if kind == "special_end":
        s = draw(st.sampled_from(list(specials)))
        w = draw(st.one_of(_magnitude(-15, 1), _magnitude(-15, -1).map(lambda r: r * abs(s))))
        return (s, s + w) if draw(st.booleans()) else (s - w, s)
    a = draw(anchors(specials))
    if kind == "thin":
        return a, a
    if kind == "ulps":
        return a, _step(a, draw(st.integers(1, 4)))
    if kind == "near":  # relative width 1e-15 .. 1e-1
        r = 10.0 ** draw(st.floats(-15, -1))
        hi = a + (abs(a) * r if a != 0 else r)
        return (a, hi) if math.isfinite(hi) else (a, a)
    b = draw(anchors(specials))
    return min(a, b), max(a, b)


def boxes(specials=(), max_size=5):
    return st.lists(box(specials), min_size=1, max_size=max_size)


def points(lo: float, hi: float, specials, rng, n_random: int = 2, cap: int = 9) -> list[float]:
    """Floats inside [lo, hi]: endpoints, their neighbours, midpoint, 0, specials, random."""
    pts = [lo, hi]
    if lo < hi:
        pts += [_step(lo, 1), _step(hi, -1)]
    mid = 0.5 * lo + 0.5 * hi
    pts.append(min(max(mid, lo), hi))
    if lo <= 0.0 <= hi:
        pts.append(0.0)
    inner = [s for s in specials if lo <= s <= hi]
    if inner:
        pts += list(rng.choice(inner, size=min(2, len(inner)), replace=False))
    for u in rng.random(n_random):
        p = lo + (hi - lo) * u
        if not math.isfinite(p):
            p = lo * (1 - u) + hi * u
        pts.append(min(max(p, lo), hi))
    if lo < 0.0 < hi:  # log-uniform points of both signs
        e = math.log10(max(-lo, hi))
        p = float(rng.choice([-1.0, 1.0])) * 10.0 ** rng.uniform(min(-320.0, e), e)
        if lo <= p <= hi:
            pts.append(p)
    out = []
    for p in pts:
        p = float(p)
        if math.isfinite(p) and p not in out:
            out.append(p)
    return out[:cap]


def seeds():
    return st.integers(0, 2**32 - 1).map(np.random.default_rng)


# --------------------------------------------------------------------------- checks
def check(lo, hi, value_fn, args, ctx=""):
    """Assert that the exact value of value_fn(*args) is inside [lo, hi]."""
    lo, hi = float(lo), float(hi)
    try:
        v = value_fn(*[R.F(a) for a in args])
    except R.Undefined:
        assert R.uninformative(lo, hi), (
            f"{ctx}: undefined at {args!r} but the result is [{lo!r}, {hi!r}]")
        return
    assert R.inside(lo, hi, v), (
        f"{ctx}: exact value {mpmath.nstr(v, 25)} at {args!r} is outside [{lo!r}, {hi!r}]")


def _arrays(bs):
    return np.array([b[0] for b in bs]), np.array([b[1] for b in bs])


def _bcast(lo, hi, shape):
    return np.broadcast_to(lo, shape), np.broadcast_to(hi, shape)


# ------------------------------------------------------------------------- unary ops
UNARY = {
    "neg": (R.neg, [0.0]),
    "twice": (R.twice, [0.0]),
    "sq": (R.sq, [0.0]),
    "inv": (R.inv, [0.0, 1.0]),
    "sqrt": (R.sqrt, [0.0, 1.0]),
    "exp": (R.exp, [0.0, 709.782712893384, -745.1332191019411]),
    "expm1": (R.expm1, [0.0, 709.782712893384]),
    "log": (R.log, [0.0, 1.0]),
    "log1p": (R.log1p, [-1.0, 0.0]),
    "sin": (R.sin, HALF_PI_MULTS),
    "cos": (R.cos, HALF_PI_MULTS),
    "tan": (R.tan, HALF_PI_MULTS),
    "asin": (R.asin, UNIT),
    "acos": (R.acos, UNIT),
    "atan": (R.atan, [0.0]),
    "sinh": (R.sinh, [0.0, 710.4758600739439]),
    "cosh": (R.cosh, [0.0, 710.4758600739439]),
    "tanh": (R.tanh, [0.0, 19.0, -19.0]),
    "asinh": (R.asinh, [0.0]),
    "acosh": (R.acosh, [1.0]),
    "atanh": (R.atanh, UNIT),
    "erf": (R.erf, [0.0, 6.0, -6.0]),
    "erfinv": (R.erfinv, UNIT),
    "fabs": (R.fabs, [0.0]),
    "floor": (R.floor, [-2.0, -1.0, 0.0, 1.0, 2.0, 0.5]),
    "ceil": (R.ceil, [-2.0, -1.0, 0.0, 1.0, 2.0, 0.5]),
    "sign": (R.sign, [0.0]),
    "not_": (R.not_, [0.0]),
}


@pytest.mark.parametrize("name", sorted(UNARY))
@SETTINGS
@given(data=st.data())
def test_unary_sound(name, data, A):
    ref, specials = UNARY[name]
    bs = data.draw(boxes(specials), label="boxes")
    rng = data.draw(seeds(), label="rng")
    al, ah = _arrays(bs)
    lo, hi = _bcast(*getattr(A, name)(al, ah), al.shape)
    for i, (a, b) in enumerate(bs):
        for p in points(a, b, specials, rng):
            check(lo[i], hi[i], ref, (p,), f"{name}([{a!r}, {b!r}])")


# ------------------------------------------------------------------------ binary ops
BINARY = {
    "add": (R.add, [0.0], [0.0]),
    "sub": (R.sub, [0.0], [0.0]),
    "mul": (R.mul, [0.0], [0.0]),
    "div": (R.div, [0.0], [0.0, 1.0, -1.0]),
    "fmin": (R.fmin, [0.0], [0.0]),
    "fmax": (R.fmax, [0.0], [0.0]),
    "copysign": (R.copysign, [0.0], [0.0]),
    "fmod": (R.fmod, [0.0, 1.0, 1.5, 2.0, -3.0], [0.0, 1.0, 2.0, -1.0, 3.0]),
    "remainder": (R.remainder, [0.0, 1.0, 1.5, 2.0, 2.5, -3.0], [0.0, 1.0, 2.0, -1.0, 3.0]),
    "hypot": (R.hypot, [0.0], [0.0]),
    "atan2": (R.atan2, [0.0], [0.0, -1.0, 1.0]),
    "pow": (R.pow, [0.0, 1.0, -1.0], [0.0, 0.5, 2.0, 3.0, -1.0, -2.0, 2.5, -0.5]),
    "lt": (R.lt, [0.0, 1.0], [0.0, 1.0]),
    "le": (R.le, [0.0, 1.0], [0.0, 1.0]),
    "eq": (R.eq, [0.0, 1.0], [0.0, 1.0]),
    "ne": (R.ne, [0.0, 1.0], [0.0, 1.0]),
    "and_": (R.and_, [0.0], [0.0]),
    "or_": (R.or_, [0.0], [0.0]),
    "if_else_zero": (R.if_else_zero, [0.0], [0.0]),
}


@pytest.mark.parametrize("name", sorted(BINARY))
@SETTINGS
@given(data=st.data())
def test_binary_sound(name, data, A):
    ref, spec_a, spec_b = BINARY[name]
    ba = data.draw(boxes(spec_a, max_size=4), label="a")
    if data.draw(st.booleans(), label="same"):
        bb = list(ba)  # x op x: the same box for both operands
    else:
        bb = data.draw(st.lists(box(spec_b), min_size=len(ba), max_size=len(ba)), label="b")
    rng = data.draw(seeds(), label="rng")
    al, ah = _arrays(ba)
    bl, bh = _arrays(bb)
    lo, hi = _bcast(*getattr(A, name)(al, ah, bl, bh), al.shape)
    for i in range(len(ba)):
        pa = points(*ba[i], spec_a, rng, cap=5)
        pb = points(*bb[i], spec_b, rng, cap=5)
        pairs = [(x, y) for x in pa for y in pb]
        if bb[i] == ba[i]:
            pairs += [(x, x) for x in pa]
        ctx = f"{name}({ba[i]!r}, {bb[i]!r})"
        for x, y in pairs:
            check(lo[i], hi[i], ref, (x, y), ctx)


# ------------------------------------------------------------ operations with constants
CONSTS = st.one_of(anchors([0.0, 1.0, -1.0, 0.5, 3.0]), st.sampled_from([0.0, -0.0]))


@pytest.mark.parametrize("name", ["addc", "mulc", "divc", "csub", "cdiv"])
@SETTINGS
@given(data=st.data())
def test_constant_ops_sound(name, data, A):
    bs = data.draw(boxes([0.0, 1.0, -1.0]), label="boxes")
    c = data.draw(CONSTS, label="c")
    rng = data.draw(seeds(), label="rng")
    al, ah = _arrays(bs)
    fn = getattr(A, name)
    if name in ("csub", "cdiv"):
        lo, hi = fn(c, al, ah)
        ref = {"csub": lambda x: R.sub(R.F(c), x), "cdiv": lambda x: R.div(R.F(c), x)}[name]
    else:
        lo, hi = fn(al, ah, c)
        ref = {"addc": lambda x: R.add(x, R.F(c)), "mulc": lambda x: R.mul(x, R.F(c)),
               "divc": lambda x: R.div(x, R.F(c))}[name]
    lo, hi = _bcast(lo, hi, al.shape)
    for i, (a, b) in enumerate(bs):
        for p in points(a, b, [0.0], rng):
            check(lo[i], hi[i], ref, (p,), f"{name}([{a!r}, {b!r}], c={c!r})")


@SETTINGS
@given(bs=boxes([0.0, 1.0, -1.0]), n=st.integers(-7, 9), rng=seeds())
def test_powi_sound(bs, n, rng, A):
    al, ah = _arrays(bs)
    lo, hi = _bcast(*A.powi(al, ah, n), al.shape)
    for i, (a, b) in enumerate(bs):
        for p in points(a, b, [0.0], rng):
            check(lo[i], hi[i], lambda x: R.powi(x, n), (p,), f"powi([{a!r}, {b!r}], {n})")


POWC_EXPONENTS = st.one_of(
    st.sampled_from([0.5, 1.5, 2.5, -0.5, -1.5, 1.0 / 3.0, 0.1, 0.0, 1.0, 2.0, 3.0, -1.0,
                     -2.0, 7.0, 2.0**31, 1e300]),
    st.floats(-4.0, 4.0))


@SETTINGS
@given(bs=boxes([0.0, 1.0, -1.0]), c=POWC_EXPONENTS, rng=seeds())
def test_powc_sound(bs, c, rng, A):
    al, ah = _arrays(bs)
    lo, hi = _bcast(*A.powc(al, ah, c), al.shape)
    for i, (a, b) in enumerate(bs):
        for p in points(a, b, [0.0, 1.0], rng):
            check(lo[i], hi[i], lambda x: R.pow(x, R.F(c)), (p,), f"powc([{a!r}, {b!r}], {c!r})")


# --------------------------------------------------------------- domain convention
WHOLE = (-INF, INF)
CONVENTION = [
    # division by an interval containing 0 -> NaN (possibly undefined)
    ("div", (1.0, 2.0, -1.0, 1.0), (NAN, NAN)),
    ("div", (1.0, 2.0, 0.0, 1.0), (NAN, NAN)),
    ("div", (1.0, 2.0, -1.0, 0.0), (NAN, NAN)),
    ("div", (1.0, 2.0, 0.0, 0.0), (NAN, NAN)),
    ("div", (0.0, 0.0, 0.0, 0.0), (NAN, NAN)),
    ("div", (1.0, 2.0, -0.0, 3.0), (NAN, NAN)),
    ("inv", (-1.0, 1.0), (NAN, NAN)),
    ("inv", (0.0, 0.0), (NAN, NAN)),
    ("inv", (0.0, 5.0), (NAN, NAN)),
    ("cdiv", (1.0, -1.0, 1.0), (NAN, NAN)),
    ("cdiv", (0.0, 0.0, 2.0), (NAN, NAN)),
    ("divc", (1.0, 2.0, 0.0), (NAN, NAN)),
    ("powi", (-1.0, 1.0, -1), (NAN, NAN)),
    ("powi", (0.0, 1.0, -2), (NAN, NAN)),
    ("fmod", (1.0, 2.0, -1.0, 1.0), (NAN, NAN)),
    ("remainder", (1.0, 2.0, 0.0, 0.0), (NAN, NAN)),
    # partly outside the domain -> NaN (possibly undefined)
    ("log", (-1.0, 1.0), (NAN, NAN)),
    ("log", (0.0, 1.0), (NAN, NAN)),
    ("log1p", (-2.0, 0.0), (NAN, NAN)),
    ("log1p", (-1.0, 0.0), (NAN, NAN)),
    ("sqrt", (-1.0, 4.0), (NAN, NAN)),
    ("sqrt", (-1e-300, 0.0), (NAN, NAN)),
    ("asin", (0.5, 1.5), (NAN, NAN)),
    ("asin", (-1.5, 0.0), (NAN, NAN)),
    ("acos", (0.5, 1.5), (NAN, NAN)),
    ("acos", (-1.0000000000000002, 1.0), (NAN, NAN)),
    ("acosh", (0.0, 2.0), (NAN, NAN)),
    ("atanh", (0.5, 1.0), (NAN, NAN)),
    ("atanh", (-1.0, 0.0), (NAN, NAN)),
    ("erfinv", (0.0, 1.0), (NAN, NAN)),
    ("tan", (1.0, 2.0), (NAN, NAN)),
    ("tan", (-2.0, -1.5), (NAN, NAN)),
    ("tan", (0.0, 4.0), (NAN, NAN)),
    ("powc", (-1.0, 1.0, 0.5), (NAN, NAN)),
    ("powc", (0.0, 1.0, -0.5), (NAN, NAN)),
    ("pow", (-1.0, 1.0, 0.5, 0.5), (NAN, NAN)),
    ("pow", (-1.0, 1.0, 0.5, 1.5), (NAN, NAN)),
    ("pow", (0.0, 1.0, -1.5, -0.5), (NAN, NAN)),
    ("pow", (0.0, 1.0, -1.0, 1.0), (NAN, NAN)),
    # entirely outside the domain -> NaN
    ("log", (-2.0, -1.0), (NAN, NAN)),
    ("log", (-1.0, 0.0), (NAN, NAN)),
    ("log", (0.0, 0.0), (NAN, NAN)),
    ("log1p", (-3.0, -1.0), (NAN, NAN)),
    ("sqrt", (-2.0, -1.0), (NAN, NAN)),
    ("asin", (1.5, 2.0), (NAN, NAN)),
    ("asin", (-3.0, -1.0000000000000002), (NAN, NAN)),
    ("acos", (1.0000000000000002, 2.0), (NAN, NAN)),
    ("acosh", (-1.0, 0.5), (NAN, NAN)),
    ("atanh", (1.0, 2.0), (NAN, NAN)),
    ("erfinv", (-2.0, -1.0), (NAN, NAN)),
    ("powc", (-2.0, -1.0, 0.5), (NAN, NAN)),
    ("powc", (-2.0, 0.0, -0.5), (NAN, NAN)),
]


@pytest.mark.parametrize(("name", "args", "expected"), CONVENTION,
                         ids=[f"{c[0]}{c[1]}" for c in CONVENTION])
def test_domain_convention(name, args, expected, A):
    if name == "cdiv":  # the constant comes first
        arrays = [args[0], np.array([args[1]]), np.array([args[2]])]
    elif name in ("divc", "powc", "powi"):  # the constant (or exponent) comes last
        arrays = [np.array([args[0]]), np.array([args[1]]), args[2]]
    else:
        arrays = [np.array([a]) for a in args]
    lo, hi = getattr(A, name)(*arrays)
    got = (float(np.asarray(lo).reshape(-1)[0]), float(np.asarray(hi).reshape(-1)[0]))
    np.testing.assert_array_equal(got, expected)


def test_domain_inside_is_informative(A):
    """Boxes inside the (closed) domain are not sent to the whole line."""
    one = np.array([1.0])
    for name, (a, b) in [("sqrt", (0.0, 4.0)), ("log", (1e-300, 1.0)), ("asin", (-1.0, 1.0)),
                         ("acos", (-1.0, 1.0)), ("acosh", (1.0, 2.0)),
                         ("atanh", (-0.9999999999999999, 0.9999999999999999)),
                         ("log1p", (-0.9999999999999999, 1.0)), ("tan", (-1.5, 1.5)),
                         ("erfinv", (-0.999, 0.999))]:
        lo, hi = getattr(A, name)(a * one, b * one)
        assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)), name
    lo, hi = A.powc(np.array([0.0]), np.array([4.0]), 2.5)
    assert lo[0] == 0.0 and 32.0 <= hi[0] < 32.001
    lo, hi = A.div(one, 2 * one, np.array([1e-300]), one)
    assert np.isfinite(hi[0])


# ------------------------------------------------------------- NaN means no information
ALL_UNARY = sorted(UNARY)
ALL_BINARY = sorted(BINARY)
SAMPLE = [-1e10, -3.0, -1.0, -0.5, 0.0, 0.25, 0.5, 1.0, 1.5, 2.0, 7.0, 1e10]


@pytest.mark.parametrize("name", ALL_UNARY)
def test_nan_input_unary_is_no_information(name, A):
    """A NaN box stands for any real: the result must contain the value at every point."""
    ref = UNARY[name][0]
    lo, hi = getattr(A, name)(np.array([NAN]), np.array([NAN]))
    for p in SAMPLE:
        try:
            v = ref(R.F(p))
        except R.Undefined:
            continue
        assert R.inside(float(lo[0]), float(hi[0]), v), (name, p, lo, hi)


@pytest.mark.parametrize("name", ALL_BINARY)
def test_nan_input_binary_is_no_information(name, A):
    ref = BINARY[name][0]
    nan = np.array([NAN])
    for other in [(-1.0, 2.0), (0.0, 0.0), (2.0, 3.0)]:
        ol, oh = np.array([other[0]]), np.array([other[1]])
        for first in (True, False):
            args = (nan, nan, ol, oh) if first else (ol, oh, nan, nan)
            lo, hi = getattr(A, name)(*args)
            for p in SAMPLE:
                for q in (other[0], other[1], 0.5 * (other[0] + other[1])):
                    x, y = (p, q) if first else (q, p)
                    try:
                        v = ref(R.F(x), R.F(y))
                    except R.Undefined:
                        continue
                    assert R.inside(float(lo[0]), float(hi[0]), v), (name, x, y, lo, hi)


# --------------------------------------------------------------- sign facts
nonneg_boxes = st.tuples(
    st.one_of(st.just(0.0), _magnitude(-323, 300), st.floats(0.0, 1e3)),
    st.one_of(st.just(0.0), _magnitude(-323, 300), st.floats(0.0, 1e3)),
).map(sorted)


@settings(max_examples=200, deadline=None)
@given(a=nonneg_boxes, b=nonneg_boxes)
def test_sum_of_nonnegative_is_nonnegative(a, b, A):
    lo, _ = A.add(np.array([a[0]]), np.array([a[1]]), np.array([b[0]]), np.array([b[1]]))
    assert lo[0] >= 0.0
    lo, _ = A.addc(np.array([a[0]]), np.array([a[1]]), b[0])
    assert lo[0] >= 0.0
    lo, _ = A.sub(np.array([a[0]]), np.array([a[1]]), np.array([-b[1]]), np.array([-b[0]]))
    assert lo[0] >= 0.0


@settings(max_examples=200, deadline=None)
@given(bs=boxes([0.0]))
def test_sign_definite_results(bs, A):
    al, ah = _arrays(bs)
    # (a NaN bound, "possibly undefined", is not a negative bound; an overflowed square
    # has the finite lower bound MAX_FLOAT, not NaN)
    with np.errstate(invalid="ignore"):
        assert not np.any(A.sq(al, ah)[0] < 0.0)
        assert not np.any(np.isnan(A.sq(al, ah)[0]))
        assert not np.any(np.isnan(A.powi(al, ah, 4)[0]))
        assert not np.any(np.isnan(A.exp(al, ah)[0]))
        assert np.all(A.fabs(al, ah)[0] >= 0.0)
        assert not np.any(A.powi(al, ah, 4)[0] < 0.0)
        assert not np.any(A.hypot(al, ah, ah, al)[0] < 0.0)
        assert not np.any(A.exp(al, ah)[0] < 0.0)
        assert not np.any(A.sqrt(np.abs(al), np.abs(al))[0] < 0.0)
        assert not np.any(A.cosh(al, ah)[0] < 1.0)
        for name, bound in [("sin", 1.0), ("cos", 1.0), ("tanh", 1.0), ("erf", 1.0),
                            ("atan", float(np.nextafter(math.pi / 2, 2.0)))]:
            lo, hi = getattr(A, name)(al, ah)
            assert np.all(lo >= -bound) and np.all(hi <= bound), name


# ------------------------------------------------------------- not absurdly loose
def _rel_width(lo, hi, v):
    return (float(hi) - float(lo)) / max(abs(v), 1e-300)


THIN_UNARY = {
    "neg": 1.3, "twice": 1.3, "sq": 1.3, "inv": 1.3, "sqrt": 1.3, "exp": 1.3, "expm1": 0.3,
    "log": 1.3, "log1p": 0.3, "sin": 1.3, "cos": 1.3, "tan": 1.3, "asin": 0.3, "acos": 0.3,
    "atan": 1.3, "sinh": 1.3, "cosh": 1.3, "tanh": 1.3, "asinh": 1.3, "acosh": 1.3,
    "atanh": 0.3, "erf": 0.3, "erfinv": 0.3, "fabs": -1.3, "floor": 1.3, "ceil": 1.3,
    "sign": -1.3, "not_": 1.3,
}


@pytest.mark.parametrize("name", sorted(THIN_UNARY))
@pytest.mark.parametrize("scale", [1.0, 1e-7, 7e5])
def test_thin_box_gives_thin_result(name, scale, A):
    x = THIN_UNARY[name]
    if name in ("neg", "twice", "sq", "inv", "sqrt", "log", "atan", "asinh", "fabs", "sign",
                "not_"):
        x *= scale
    elif name in ("exp", "expm1", "sinh", "cosh"):
        x *= min(scale, 100.0)
    a, b = x, x * (1 + 1e-15) if x > 0 else x
    lo, hi = getattr(A, name)(np.array([min(a, b)]), np.array([max(a, b)]))
    v = float(UNARY[name][0](R.F(x)))
    assert np.isfinite(lo[0]) and np.isfinite(hi[0])
    assert _rel_width(lo[0], hi[0], v) < 1e-10, (name, x, lo, hi)


THIN_BINARY = {
    "add": (1.3, -0.7), "sub": (1.3, 0.7), "mul": (1.3, -0.7), "div": (1.3, -0.7),
    "fmin": (1.3, 0.7), "fmax": (1.3, 0.7), "copysign": (1.3, -0.7), "hypot": (1.3, -0.7),
    "atan2": (1.3, -0.7), "pow": (1.3, 2.7),
    "lt": (1.3, 0.7), "le": (1.3, 0.7), "eq": (1.3, 0.7), "ne": (1.3, 0.7),
    "and_": (1.3, 0.7), "or_": (1.3, 0.0), "if_else_zero": (1.3, 0.7),
    "fmod": (1.3, 2.0), "remainder": (0.7, 2.0),  # |x| < |y|, |x| <= |y|/2: the result is x
}


@pytest.mark.parametrize("name", sorted(THIN_BINARY))
def test_thin_binary_gives_thin_result(name, A):
    x, y = THIN_BINARY[name]
    lo, hi = getattr(A, name)(*(np.array([v]) for v in (x, x, y, y)))
    v = float(BINARY[name][0](R.F(x), R.F(y)))
    assert np.isfinite(lo[0]) and np.isfinite(hi[0])
    assert _rel_width(lo[0], hi[0], v) < 1e-10, (name, lo, hi)
    assert lo[0] <= v <= hi[0]


def test_constant_ops_thin(A):
    x = np.array([1.3])
    for lo, hi, v in [(*A.addc(x, x, 0.1), 1.4), (*A.csub(0.1, x, x), -1.2),
                      (*A.mulc(x, x, -3.0), -3.9), (*A.divc(x, x, 4.0), 0.325),
                      (*A.cdiv(2.6, x, x), 2.0), (*A.powi(x, x, -3), 1.3**-3),
                      (*A.powc(x, x, 2.5), 1.3**2.5), (*A.powc(x, x, -0.5), 1.3**-0.5)]:
        assert lo[0] <= v <= hi[0] and _rel_width(lo[0], hi[0], v) < 1e-10


def test_ranges_are_tight_on_wide_boxes(A):
    """Extremum handling: the bounds are the true extrema up to rounding, not the range."""
    def close(got, want):
        return abs(float(got) - want) <= 1e-12 * max(1.0, abs(want))

    one = np.array([1.0])
    lo, hi = A.sin(0.2 * one, 1.0 * one)
    assert close(lo[0], math.sin(0.2)) and close(hi[0], math.sin(1.0))
    lo, hi = A.sin(1.0 * one, 2.0 * one)
    assert close(lo[0], math.sin(1.0)) and hi[0] == 1.0
    lo, hi = A.cos(2.0 * one, 4.0 * one)
    assert lo[0] == -1.0 and close(hi[0], math.cos(2.0))
    lo, hi = A.sq(-2.0 * one, 1.0 * one)
    assert lo[0] == 0.0 and close(hi[0], 4.0)
    lo, hi = A.mul(-2.0 * one, 3.0 * one, -1.0 * one, 5.0 * one)
    assert close(lo[0], -10.0) and close(hi[0], 15.0)
    lo, hi = A.atan2(one, one, -one, one)  # y = 1, x in [-1, 1]
    assert close(lo[0], math.pi / 4) and close(hi[0], 3 * math.pi / 4)
    lo, hi = A.cosh(-1.0 * one, 2.0 * one)
    assert lo[0] == 1.0 and close(hi[0], math.cosh(2.0))
    lo, hi = A.remainder(0.0 * one, 10.0 * one, 3.0 * one, 3.0 * one)
    assert lo[0] >= -1.5 - 1e-15 and hi[0] <= 1.5 + 1e-15


def test_logic_results_are_exact(A):
    def b(lo, hi):
        return np.array([float(lo)]), np.array([float(hi)])

    assert A.lt(*b(0, 1), *b(2, 3)) == (1.0, 1.0)
    assert A.lt(*b(2, 3), *b(0, 2)) == (0.0, 0.0)
    assert A.lt(*b(0, 2), *b(1, 3)) == (0.0, 1.0)
    assert A.le(*b(0, 2), *b(2, 3)) == (1.0, 1.0)
    assert A.eq(*b(2, 2), *b(2, 2)) == (1.0, 1.0)
    assert A.ne(*b(0, 1), *b(2, 3)) == (1.0, 1.0)
    assert A.not_(*b(0, 0)) == (1.0, 1.0)
    assert A.and_(*b(1, 2), *b(-2, -1)) == (1.0, 1.0)
    assert A.or_(*b(0, 0), *b(0, 0)) == (0.0, 0.0)
    assert A.if_else_zero(*b(0, 0), *b(5, 6)) == (0.0, 0.0)
    assert A.if_else_zero(*b(1, 2), *b(5, 6)) == (5.0, 6.0)
    assert A.if_else_zero(*b(0, 2), *b(5, 6)) == (0.0, 6.0)


# ------------------------------------------------------------------ batched shapes
def _batch_boxes(rng, n):
    c = rng.uniform(-3, 3, n)
    w = 10.0 ** rng.uniform(-15, 0.5, n)
    lo, hi = c - w * rng.random(n), c + w * rng.random(n)
    lo[0], hi[0] = 0.0, 0.0
    lo[1], hi[1] = -1.0, 1.0
    return lo, hi


def _same(x, y):
    np.testing.assert_array_equal(np.asarray(x, dtype=float), np.asarray(y, dtype=float))


UNARY_CALLS = {n: getattr(A, n) for n in ALL_UNARY}
UNARY_CALLS.update({
    "addc": lambda lo, hi: A.addc(lo, hi, 0.3), "csub": lambda lo, hi: A.csub(0.3, lo, hi),
    "mulc": lambda lo, hi: A.mulc(lo, hi, -0.3), "divc": lambda lo, hi: A.divc(lo, hi, 0.3),
    "cdiv": lambda lo, hi: A.cdiv(0.3, lo, hi), "powi3": lambda lo, hi: A.powi(lo, hi, 3),
    "powi-2": lambda lo, hi: A.powi(lo, hi, -2), "powc": lambda lo, hi: A.powc(lo, hi, 2.5),
    "mulc0": lambda lo, hi: A.mulc(lo, hi, 0.0), "powi0": lambda lo, hi: A.powi(lo, hi, 0),
})


@pytest.mark.parametrize("name", sorted(UNARY_CALLS))
def test_batched_unary_matches_elementwise(name):
    fn = UNARY_CALLS[name]
    lo, hi = _batch_boxes(np.random.default_rng(1), 16)
    bl, bh = fn(lo, hi)
    assert np.shape(bl) == (16,) and np.shape(bh) == (16,)
    for i in range(16):
        el, eh = fn(lo[i:i + 1], hi[i:i + 1])
        _same(bl[i], np.reshape(el, -1)[0])
        _same(bh[i], np.reshape(eh, -1)[0])


@pytest.mark.parametrize("name", ALL_BINARY)
def test_batched_binary_matches_elementwise_and_broadcasts(name, A):
    fn = getattr(A, name)
    rng = np.random.default_rng(2)
    al, ah = _batch_boxes(rng, 16)
    bl, bh = _batch_boxes(rng, 16)
    lo, hi = fn(al, ah, bl, bh)
    assert np.shape(lo) == (16,) and np.shape(hi) == (16,)
    for i in range(16):
        el, eh = fn(al[i:i + 1], ah[i:i + 1], bl[i:i + 1], bh[i:i + 1])
        _same(lo[i], el[0])
        _same(hi[i], eh[0])
    # a single box (python floats or 0-d arrays) against a batch
    for sl, sh in [(-0.5, 2.0), (1.5, 1.5), (0.0, 0.0)]:
        lo1, hi1 = _bcast(*fn(sl, sh, bl, bh), (16,))
        lo2, hi2 = fn(np.full(16, sl), np.full(16, sh), bl, bh)
        _same(lo1, lo2)
        _same(hi1, hi2)
        lo1, hi1 = _bcast(*fn(al, ah, np.float64(sl), np.float64(sh)), (16,))
        lo2, hi2 = fn(al, ah, np.full(16, sl), np.full(16, sh))
        _same(lo1, lo2)
        _same(hi1, hi2)


def test_ops_wrappers_shapes_and_values():
    rng = np.random.default_rng(3)
    lo, hi = _batch_boxes(rng, 24)
    a = np.stack([lo, hi], axis=-1).reshape(4, 6, 2)
    lo2, hi2 = _batch_boxes(rng, 6)
    b = np.stack([lo2, hi2], axis=-1)  # (6, 2): broadcasts against (4, 6, 2)
    for name in ["exp", "sin", "sq", "sqrt", "atan", "fabs", "logical_not"]:
        r = getattr(ops, name)(a)
        assert r.shape == (4, 6, 2)
        core = getattr(A, "not_" if name == "logical_not" else name)
        el, eh = core(a[..., 0], a[..., 1])
        _same(r[..., 0], np.broadcast_to(el, (4, 6)))
        _same(r[..., 1], np.broadcast_to(eh, (4, 6)))
    for name in ["add", "mul", "div", "atan2", "fmin", "pow", "lt", "hypot", "logical_and"]:
        r = getattr(ops, name)(a, b)
        assert r.shape == (4, 6, 2)
        core = getattr(A, "and_" if name == "logical_and" else name)
        el, eh = core(a[..., 0], a[..., 1], b[..., 0], b[..., 1])
        _same(r[..., 0], np.broadcast_to(el, (4, 6)))
        _same(r[..., 1], np.broadcast_to(eh, (4, 6)))
    r = ops.constpow(a, 2.5)
    assert r.shape == (4, 6, 2)
    r = ops.powi(a[0], 3)
    assert r.shape == (6, 2)
    r = ops.mul(np.array([2.0, 3.0]), a)  # a single interval against a batch
    assert r.shape == (4, 6, 2)
    corners = np.stack([c * a[..., k] for c in (2.0, 3.0) for k in (0, 1)])
    assert np.all(r[..., 0] <= corners.min(axis=0)) and np.all(r[..., 1] >= corners.max(axis=0))
    r = ops.mul(np.array([-1.0, 2.0]), np.array([3.0, 4.0]))
    assert r.shape == (2,) and r[0] <= -4.0 and r[1] >= 8.0


# ------------------------------------------------------------------------ regressions
def test_remainder_can_be_negative_for_positive_x(A):
    """remainder(2, 3) = -1: the result is not confined to the sign of x."""
    lo, hi = A.remainder(*(np.array([v]) for v in (2.0, 2.0, 3.0, 3.0)))
    assert lo[0] <= -1.0 <= hi[0]
    lo, hi = A.remainder(*(np.array([v]) for v in (0.0, 10.0, 3.0, 3.0)))
    assert lo[0] <= -1.5 and hi[0] >= 1.5
    lo, hi = A.remainder(*(np.array([v]) for v in (1.0, 1.0, 1.0, 1.0)))  # exact value 0
    assert lo[0] <= 0.0 <= hi[0]


def test_remainder_subnormal_halving(A):
    """|x| <= |y|/2 must not be decided with a rounded y/2 (3 * 2**-1074 / 2 rounds up)."""
    t = 2.0**-1074
    x, y = 2 * t, 3 * t  # remainder(x, y) = -t, not x
    lo, hi = A.remainder(*(np.array([v]) for v in (x, x, y, y)))
    assert R.inside(lo[0], hi[0], R.remainder(R.F(x), R.F(y)))
    lo, hi = A.remainder(*(np.array([v]) for v in (-3 * t, 3 * t, 5 * t, 5 * t)))
    assert lo[0] <= -2.5 * t and hi[0] >= 2.5 * t  # reals in the box reach |y|/2


def test_pow_negative_base_non_thin_exponent(A):
    """x**y with x partly negative and a non-integer exponent in y is undefined somewhere:
    no information (NaN), never a bounded interval that misses x**1 = -1e6."""
    for args in ((-1e6, 1.0, -1e6, 1.0), (-2.0, 3.0, 1.0, 3.0)):
        lo, hi = A.pow(*(np.array([v]) for v in args))
        assert np.isnan(lo[0]) and np.isnan(hi[0])


@settings(max_examples=100, deadline=None)
@given(a=box([0.0]), b=box([0.0]))
def test_hull_and_intersect(a, b):
    arr = [np.array([v]) for v in (*a, *b)]
    lo, hi = A.hull(*arr)
    assert lo[0] <= min(a[0], b[0]) and hi[0] >= max(a[1], b[1])
    lo, hi = A.intersect(*arr)
    if max(a[0], b[0]) <= min(a[1], b[1]):
        assert (lo[0], hi[0]) == (max(a[0], b[0]), min(a[1], b[1]))
    else:  # empty: no information
        assert np.isnan(lo[0]) and np.isnan(hi[0])
    lo, hi = A.assign(*arr[:2])
    assert (lo[0], hi[0]) == a
