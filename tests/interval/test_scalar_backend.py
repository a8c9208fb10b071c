"""The small-batch (Python float) backend of the interval compiler against the numpy one.

* Property tests: on random expression graphs and random boxes (ordinary, huge, tiny,
  half-infinite), the enclosures of both backends contain the exact value (mpmath, 300 bits)
  of the compiled graph at sampled points, for the natural and the centered form; graphs made
  only of correctly rounded operations give bit-for-bit the same enclosures.
* The automatic choice: batches of at most ``scalar_max_batch`` boxes go to the scalar
  evaluator, larger ones to numpy; a Function with an operation the scalar evaluator lacks,
  and a batch on which Python raises, are evaluated by numpy.
* The checked call: the cheap checks of small batches raise the same errors as before.
* The cache of :func:`casadi_cmpc.interval.inclusion`.
"""

from __future__ import annotations

import math
import warnings

import casadi as ca
import mp_reference as R
import mpmath
import numpy as np
import pytest
from backends import compiled
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_extreme import SAFE_OPS, _TooBig

import casadi_cmpc as cm
from casadi_cmpc.exceptions import DimensionError, EmptySetError, InvalidBoundsError
from casadi_cmpc.interval import compiler
from casadi_cmpc.interval.compiler import InclusionFunction, _InclusionCache

INF = math.inf
SETTINGS = settings(max_examples=80, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

X0, X1, P = ca.SX.sym("x0"), ca.SX.sym("x1"), ca.SX.sym("p")

# operations whose interval extensions use only correctly rounded float operations: both
# backends give the same bits
EXACT_U = {
    "neg": lambda a: -a, "sq": lambda a: a * a, "sqrt": ca.sqrt, "fabs": ca.fabs,
    "inv": lambda a: 1 / a, "twice": lambda a: 2 * a, "floor": ca.floor, "sign": ca.sign,
    "scale": lambda a: -0.3 * a, "shift": lambda a: a + 0.7, "csub": lambda a: 1.5 - a,
    "divc": lambda a: a / 3.0,
}
EXACT_B = {
    "add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
    "div": lambda a, b: a / b, "fmin": ca.fmin, "fmax": ca.fmax,
    "ifelse": lambda a, b: ca.if_else(a < b, a - b, b * a), "le": lambda a, b: a <= b,
}
LIBM_U = {
    "exp": ca.exp, "log": ca.log, "sin": ca.sin, "cos": ca.cos, "tan": ca.tan,
    "atan": ca.atan, "tanh": ca.tanh, "asin": ca.asin, "acos": ca.acos, "sinh": ca.sinh,
    "cosh": ca.cosh, "expm1": ca.expm1, "log1p": ca.log1p, "erf": ca.erf,
    "pow25": lambda a: a ** 2.5, "cube": lambda a: a ** 3, "rpow": lambda a: a ** -1.5,
}
LIBM_B = {"atan2": ca.atan2, "hypot": ca.hypot, "pow": lambda a, b: a ** b}


@st.composite
def graphs(draw, unary, binary, depth=3):
    """An expression of x0, x1, p: (tree, SX expression)."""
    if depth == 0 or draw(st.integers(0, 4)) == 0:
        leaf = draw(st.sampled_from(["x0", "x1", "p", "c"]))
        if leaf == "c":
            c = draw(st.sampled_from([0.5, -2.0, 3.0, 0.1, 1e-300, 1e300]))
            return str(c), ca.SX(c) + 0 * X0  # keep it a graph of the inputs
        return leaf, {"x0": X0, "x1": X1, "p": P}[leaf]
    if draw(st.booleans()):
        name = draw(st.sampled_from(sorted(unary)))
        t, e = draw(graphs(unary, binary, depth - 1))
        return (name, t), unary[name](e)
    name = draw(st.sampled_from(sorted(binary)))
    ta, ea = draw(graphs(unary, binary, depth - 1))
    tb, eb = draw(graphs(unary, binary, depth - 1))
    return (name, ta, tb), binary[name](ea, eb)


def _interval(draw, wide: bool):
    kind = draw(st.sampled_from(["unit", "unit", "thin", "far", "tiny", "half", "whole",
                                 "big"] if wide else ["unit", "unit", "thin", "small"]))
    if kind == "whole":
        return (-INF, INF)
    if kind == "half":
        a = draw(st.floats(-3.0, 3.0))
        return (-INF, a) if draw(st.booleans()) else (a, INF)
    if kind == "far":
        a = draw(st.floats(1e300, 1e305)) * draw(st.sampled_from([1.0, -1.0]))
    elif kind == "big":  # where exp, sinh, cosh and powers overflow
        a = draw(st.floats(-760.0, 760.0))
    elif kind == "tiny":
        a = draw(st.floats(-1e-300, 1e-300))
    else:
        a = draw(st.floats(-3.0, 3.0))
    if kind == "thin":
        return (a, a)
    w = draw(st.floats(0.0, 2.0)) if kind in ("unit", "far", "big") else \
        draw(st.floats(0.0, 1e-3))
    if kind == "far":
        w *= abs(a)
    if kind == "tiny":
        w = draw(st.floats(0.0, 1e-300))
    b = a + w
    return (a, b) if math.isfinite(b) else (a, a)


@st.composite
def batches(draw, wide=True):
    n = draw(st.integers(1, 5))
    X = np.array([[_interval(draw, wide), _interval(draw, wide)] for _ in range(n)])
    Pb = np.array([[_interval(draw, wide)]] * (1 if draw(st.booleans()) else n))
    if Pb.shape[0] != n:
        Pb = Pb[:1]
    return X, Pb


def _points(lo, hi, rng, k=3):
    pts = [lo, hi]
    if math.isfinite(lo) and math.isfinite(hi):
        pts += [min(max(lo + (hi - lo) * rng.random(), lo), hi) for _ in range(k)]
    elif math.isfinite(lo):
        pts += [lo + 10.0 ** rng.uniform(-3, 3)]
    elif math.isfinite(hi):
        pts += [hi - 10.0 ** rng.uniform(-3, 3)]
    else:
        pts += [rng.uniform(-5, 5), -1e300, 1e300]
    return [float(p) for p in pts if math.isfinite(p)]


def _check_contains(fun, out, X, Pb, rng, ctx):
    """Every exact value of the graph at sampled points lies in the enclosures ``out``."""
    for i in range(X.shape[0]):
        p_box = Pb[i if Pb.shape[0] > 1 else 0, 0]
        for x in _points(*X[i, 0], rng):
            for y in _points(*X[i, 1], rng, 1):
                for q in _points(*p_box, rng, 1)[:2]:
                    try:
                        # (points whose exact value needs astronomically large
                        # intermediates, e.g. exp(1e300), are skipped)
                        with mpmath.workprec(1200):
                            v = R.eval_function(fun, [[x, y], [q]], SAFE_OPS)[0]
                    except _TooBig:
                        continue
                    v = v[0] if v else R.ZERO
                    lo, hi = float(out[i, 0, 0]), float(out[i, 0, 1])
                    if v is R.UNDEF:
                        assert lo == -INF and hi == INF, f"{ctx}: undefined at {x, y, q}"
                    else:
                        assert R.inside(lo, hi, v), (
                            f"{ctx}: exact {mpmath.nstr(v, 17)} at {(x, y, q)} not in "
                            f"[{lo!r}, {hi!r}]")


def _function(expr):
    return ca.Function("g", [ca.vertcat(X0, X1), P], [expr])


@SETTINGS
@given(g=graphs({**EXACT_U, **LIBM_U}, {**EXACT_B, **LIBM_B}, depth=2), batch=batches(),
       seed=st.integers(0, 2**32 - 1))
def test_both_backends_contain_the_exact_values(g, batch, seed):
    tree, expr = g
    fun = _function(expr)
    X, Pb = batch
    rng = np.random.default_rng(seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cm.CmpcWarning)
        for kind in ("natural", "centered"):
            for backend in ("numpy", "scalar"):
                out = compiled(fun, kind, backend)(X, Pb)[0]
                assert out.shape == (X.shape[0], 1, 2)
                assert not np.isnan(out).any()
                _check_contains(fun, out, X, Pb, rng, f"{kind}/{backend} {tree}")


@SETTINGS
@given(g=graphs(EXACT_U, EXACT_B), batch=batches(), seed=st.integers(0, 2**32 - 1))
def test_correctly_rounded_graphs_give_the_same_bits(g, batch, seed):
    """Sums, products, quotients, square roots, comparisons: the scalar code performs the
    same IEEE operations as numpy, so the enclosures are identical (the sign of a zero
    aside), natural and centered."""
    tree, expr = g
    fun = _function(expr)
    X, Pb = batch
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cm.CmpcWarning)
        for kind in ("natural", "centered"):
            a = compiled(fun, kind, "numpy")(X, Pb)[0]
            b = compiled(fun, kind, "scalar")(X, Pb)[0]
            np.testing.assert_array_equal(a, b, err_msg=f"{kind} {tree}")


# ----------------------------------------------------------------- automatic choice
def _spy(F):
    """Record the batch sizes that reach F's scalar evaluator."""
    calls = []
    ev = F._scalar()

    def spy(B, n):
        calls.append(n)
        return ev(B, n)

    F._scalar_fn = spy
    F._fast = None  # rebuilt around the spy
    return calls


@pytest.fixture(scope="module")
def cannon():
    return cm.models.load("cannon").model


def _model_boxes(model, n, rng, width=0.05):
    X = model.X.as_array()
    c = rng.uniform(X[:, 0], X[:, 1], (n, model.n))
    Xb = np.stack([c - width, c + width], axis=-1)
    Ub = np.broadcast_to(model.U.as_array(), (n, model.m, 2)).copy()
    Wb = np.zeros((n, 0, 2))
    return Xb, Ub, Wb


def test_auto_uses_the_scalar_evaluator_up_to_the_threshold(cannon):
    F = InclusionFunction(cannon.function)  # backend="auto"
    calls = _spy(F)
    rng = np.random.default_rng(0)
    limit = F.scalar_max_batch
    for n in (1, 2, limit, limit + 1, 200):
        args = _model_boxes(cannon, n, rng)
        got = F(*args)[0]
        ref = compiled(cannon.function, "natural", "numpy")(*args)[0]
        if n <= limit:
            assert calls[-1] == n
            # the exact operations of this model give the numpy bits
            np.testing.assert_array_equal(got, ref)
        else:
            assert calls[-1] != n
            np.testing.assert_array_equal(got, ref)
        F.evaluate_unchecked(list(args), n)
        assert (calls[-1] == n) == (n <= limit)
    calls.clear()
    F.scalar_max_batch = 4  # an instance setting moves the threshold
    F(*_model_boxes(cannon, 5, rng))
    F(*_model_boxes(cannon, 4, rng))
    assert calls == [4]


def test_forced_backends_and_their_containment(cannon):
    """Forcing each backend gives enclosures of the same exact values; "numpy" never runs
    the scalar evaluator and "scalar" runs it for any batch."""
    rng = np.random.default_rng(1)
    Fn = InclusionFunction(cannon.function, backend="numpy")
    Fs = InclusionFunction(cannon.function, backend="scalar")
    calls = _spy(Fs)
    for n in (1, 7, 40):
        args = _model_boxes(cannon, n, rng, width=0.3)
        a, b = Fn(*args)[0], Fs(*args)[0]
        assert calls[-1] == n
        for i in range(n):
            pt = [rng.uniform(args[0][i, k, 0], args[0][i, k, 1]) for k in range(2)]
            u = rng.uniform(args[1][i, 0, 0], args[1][i, 0, 1])
            v = R.eval_function(cannon.function, [pt, [u], []])[0]
            for k in range(2):
                assert R.inside(a[i, k, 0], a[i, k, 1], v[k])
                assert R.inside(b[i, k, 0], b[i, k, 1], v[k])
    assert Fn.scalar_source is None  # never generated


def test_centered_threshold_and_model_path(cannon):
    Fc = cannon.inclusion("centered")
    assert Fc.F.backend == "auto" and Fc.F._scalar_limit() == Fc.F.scalar_max_batch_centered
    rng = np.random.default_rng(2)
    X = _model_boxes(cannon, 3, rng, width=0.01)[0]
    got = Fc(X)
    ref = compiled(cannon.function, "centered", "numpy")(X, cannon.U.as_array()[None],
                                                          np.zeros((1, 0, 2)))[0]
    np.testing.assert_array_equal(got, ref)
    assert Fc.F._g_scalar_fn is not None  # the scalar centered form ran


def test_empty_batch_and_shapes():
    x = ca.SX.sym("x", 2)
    F = InclusionFunction(ca.Function("f", [x], [ca.vertcat(x[0] * x[1], 2.5, ca.sin(x[0]))]))
    out = F(np.zeros((0, 2, 2)))[0]
    assert out.shape == (0, 3, 2)
    one = F(np.array([[0.0, 1.0], [2.0, 3.0]]))[0]  # a single (d, 2) box
    assert one.shape == (1, 3, 2) and one.dtype == np.float64 and one.flags.c_contiguous
    one[0, 0, 0] = 99.0  # the result is a fresh array
    again = F(np.array([[0.0, 1.0], [2.0, 3.0]]))[0]
    assert again[0, 0, 0] <= 0.0 and again[0, 1, 0] == 2.5


def test_other_argument_types_give_the_same_result():
    x = ca.SX.sym("x", 2)
    p = ca.SX.sym("p")
    F = InclusionFunction(ca.Function("f", [x, p], [x[0] * p - ca.exp(x[1])]))
    X = np.array([[[-1.0, 2.0], [0.0, 0.5]]])
    Pb = np.array([[[1.0, 3.0]]])
    ref = F(X, Pb)[0]
    variants = [
        (X.tolist(), Pb.tolist()), (X.astype(np.float32), Pb), (X[0], Pb[0]),
        (cm.Box(X[0, :, 0], X[0, :, 1]), Pb), (np.asfortranarray(X), Pb),
        (np.array([[[-1, 2], [0, 0]]]), Pb),
    ]
    for args in variants[:5]:
        np.testing.assert_array_equal(F(*args)[0], ref)
    int_box = F(*variants[5])[0]
    assert int_box[0, 0, 0] <= -3.0 - math.exp(0.0)


def test_checked_call_raises_the_same_errors():
    x = ca.SX.sym("x", 2)
    p = ca.SX.sym("p")
    fun = ca.Function("f", [x, p], [x[0] * p])
    for backend in ("auto", "scalar", "numpy"):
        F = InclusionFunction(fun, backend=backend)
        Pb = np.array([[[1.0, 2.0]]])
        with pytest.raises(InvalidBoundsError, match="NaN"):
            F(np.array([[[0.0, np.nan], [0.0, 1.0]]]), Pb)
        with pytest.raises(InvalidBoundsError, match="NaN"):  # also in an unused bound
            F(np.array([[[0.0, 1.0], [np.nan, 1.0]]]), Pb)
        with pytest.raises(EmptySetError, match="empty"):
            F(np.array([[[1.0, 0.0], [0.0, 1.0]]]), Pb)
        with pytest.raises(DimensionError):
            F(np.zeros((1, 3, 2)), Pb)
        with pytest.raises(DimensionError, match="broadcast"):
            F(np.zeros((3, 2, 2)), np.zeros((2, 1, 2)))
        with pytest.raises(TypeError, match="2 box arguments"):
            F(np.zeros((1, 2, 2)))


def test_python_exceptions_fall_back_to_numpy():
    """Inverted bounds passed to evaluate_unchecked make Python divide by zero: the batch is
    then evaluated by numpy (no exception, the numpy result); a strict evaluator raises."""
    x = ca.SX.sym("x")
    fun = ca.Function("f", [x], [1 / x])
    boxes = [np.array([[[1.0, 0.0]]])]
    ref = compiled(fun, "natural", "numpy").evaluate_unchecked(boxes, 1)[0]
    got = InclusionFunction(fun, backend="scalar").evaluate_unchecked(boxes, 1)[0]
    np.testing.assert_array_equal(got, ref)
    with pytest.raises(ArithmeticError):
        compiled(fun, "natural", "scalar").evaluate_unchecked(boxes, 1)


def test_an_operation_without_scalar_code_falls_back_to_numpy(monkeypatch):
    monkeypatch.setattr(compiler, "_SCALAR_OPS", compiler._SCALAR_OPS - {ca.OP_SIN})
    x = ca.SX.sym("x")
    fun = ca.Function("f", [x], [ca.sin(x) * x + 1])
    F = InclusionFunction(fun, backend="scalar")
    assert F.scalar_unsupported == ["OP_SIN"]
    X = np.array([[[0.5, 2.0]], [[-1.0, 1.0]]])
    np.testing.assert_array_equal(F(X)[0], compiled(fun, "natural", "numpy")(X)[0])
    assert F.scalar_source is None
    Fc = InclusionFunction(fun, "centered", backend="scalar")
    assert "OP_SIN" in Fc.scalar_unsupported and Fc._g_scalar_fn is None
    Fc(X)
    assert Fc._g_scalar_fn is None


def test_hot_operations_are_inlined():
    x = ca.SX.sym("x", 2)
    e = (ca.sin(x[0]) * ca.cos(x[1]) + ca.exp(x[0] - x[1]) / (1 + x[1] ** 2)
         - ca.sqrt(ca.fmax(x[0], 0.5)) + ca.fmin(-x[0], x[1]) * 3.0 + 2 * x[0] - ca.log(2 + x[0]))
    F = InclusionFunction(ca.Function("f", [x], [e]))
    F(np.array([[[0.1, 0.2], [0.3, 0.4]]]))
    assert "_S_" not in F.scalar_source and "_A." not in F.scalar_source, F.scalar_source
    assert "_sin(" in F.scalar_source and "_exp(" in F.scalar_source


# -------------------------------------------------------------------------- cache
def test_inclusion_is_cached_per_function_kind_and_backend():
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [x * ca.exp(x)])
    F = cm.interval.inclusion(f)
    assert cm.interval.inclusion(f) is F
    assert cm.interval.inclusion(f, "natural", backend="auto") is F
    Fc = cm.interval.inclusion(f, "centered")
    Fn = cm.interval.inclusion(f, backend="numpy")
    assert len({id(F), id(Fc), id(Fn)}) == 3
    assert Fc.kind == "centered" and Fn.backend == "numpy"
    g = ca.Function("f", [x], [x * ca.exp(x)])  # equal but another object
    assert cm.interval.inclusion(g) is not F
    cm.interval.inclusion_cache_clear()
    assert cm.interval.inclusion(f) is not F


def test_cache_never_returns_the_evaluator_of_another_function():
    """An entry is returned only for the very Function it was compiled from, whatever the
    id (simulated here: an entry stored under the id of another Function)."""
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [x + 1])
    g = ca.Function("g", [x], [x - 1])
    Ff = InclusionFunction(f)
    compiler._CACHE._data[(id(g), "natural", "auto")] = (f, Ff)
    Fg = cm.interval.inclusion(g)
    assert Fg is not Ff and Fg.fun is g
    out = Fg(np.array([[[0.0, 0.0]]]))[0][0, 0]
    assert out[0] <= -1.0 <= out[1] and out[1] < 0.0


def test_cache_is_bounded_and_keeps_its_functions_alive():
    cache = _InclusionCache(maxsize=2)
    x = ca.SX.sym("x")
    funs = [ca.Function(f"f{i}", [x], [x * i]) for i in range(3)]
    Fs = [InclusionFunction(f) for f in funs]
    for f, F in zip(funs, Fs, strict=True):
        cache.put(f, "natural", "auto", F)
    assert len(cache) == 2
    assert cache.get(funs[0], "natural", "auto") is None  # least recently used: evicted
    assert cache.get(funs[2], "natural", "auto") is Fs[2]
    assert all(entry[0] is f for entry, f in zip(cache._data.values(), funs[1:], strict=True))


def test_cache_repeats_the_centered_fallback_warning():
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [ca.floor(x) * x])
    with pytest.warns(cm.CmpcWarning, match="jump"):
        F = cm.interval.inclusion(f, "centered")
    with pytest.warns(cm.CmpcWarning, match="jump"):
        assert cm.interval.inclusion(f, "centered") is F


def test_model_inclusion_goes_through_the_cache(cannon):
    F = cannon.inclusion("natural")
    assert F.F is cm.interval.inclusion(cannon.function, "natural")
    assert cannon.inclusion("natural").F is F.F


def test_unknown_backend_is_refused():
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [x])
    with pytest.raises(ValueError, match="backend"):
        cm.interval.inclusion(f, backend="cuda")
    with pytest.raises(ValueError, match="backend"):
        InclusionFunction(f, backend="fast")


def test_centered_jump_guard_of_the_scalar_path_equals_numpys():
    """The centered form's jump guard (poles and domain edges: the mean-value form is not
    used on rows that may reach them) decides the same with the scalar evaluator."""
    x = ca.SX.sym("x", 2)
    e = ca.vertcat(x[0] / x[1], ca.sqrt(x[0]) + ca.log(x[1] + 2), ca.tan(x[0]),
                   ca.asin(x[1] / 3) * x[0], x[0] * x[1])
    F = InclusionFunction(ca.Function("f", [x], [e]), "centered", backend="scalar")
    assert F._guard.active
    rng = np.random.default_rng(5)
    c = rng.uniform(-4, 4, (40, 2))
    X = np.stack([c, c + rng.uniform(0, 2, (40, 2)) ** 3], axis=-1)
    got = F._guard_scalar([X.tolist()], 40)
    want = F._guard([X], 40).tolist()
    assert got == want
    flags = np.array(got)
    assert flags.any() and not flags.all() and not flags[:, 4].any()
    ref = compiled(F.fun, "centered", "numpy")(X)[0]
    np.testing.assert_array_equal(F(X)[0][:, [0, 4]], ref[:, [0, 4]])  # correctly rounded rows
