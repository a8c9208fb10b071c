"""Soundness of inclusion functions compiled from CasADi SX expressions.

Random expression trees over ``x = (x0, x1)`` and ``p`` are built twice: as CasADi SX (then
compiled with ``cm.interval.inclusion``, natural and centered) and as an mpmath evaluator.
At points inside random boxes the exact value must lie in every enclosure. The exact value of
the compiled graph itself (CasADi folds and simplifies while building, e.g.
``sqrt(x) * sqrt(x) -> x``) is checked too, by evaluating its instruction list in mpmath.
Where the tree is undefined at a point, the innermost undefined sub-expression (an operation
whose operands are defined) must have the whole line as enclosure, per the domain convention.

The tests that take the fixture ``backend`` run with the numpy evaluator and with the scalar
(Python float) one, forced (the scalar one may not fall back to numpy).
"""

from __future__ import annotations

import math
import warnings

import casadi as ca
import mp_reference as R
import mpmath
import numpy as np
import pytest
from backends import COMPILED_BACKENDS, compiled
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.exceptions import DimensionError, UnsupportedOperationError

SETTINGS = settings(max_examples=100, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@pytest.fixture(scope="module", params=COMPILED_BACKENDS)
def backend(request):
    """The evaluator of the compiled inclusion functions."""
    return request.param

# constants whose products are exact: CasADi folds c1 * (c2 * e) into (c1 * c2) * e
CONSTS = [0.5, 2.0, 3.0, -2.5, 0.25, 7.0, -3.0, 1.5, -0.75]

UN_SX = {
    "neg": lambda a: -a, "sq": lambda a: a**2, "sqrt": ca.sqrt, "exp": ca.exp, "log": ca.log,
    "sin": ca.sin, "cos": ca.cos, "atan": ca.atan, "tanh": ca.tanh, "fabs": ca.fabs,
    "pow25": lambda a: a**2.5, "cube": lambda a: a**3,
}
UN_MP = {
    "neg": R.neg, "sq": R.sq, "sqrt": R.sqrt, "exp": R.exp, "log": R.log, "sin": R.sin,
    "cos": R.cos, "atan": R.atan, "tanh": R.tanh, "fabs": R.fabs,
    "pow25": lambda a: R.pow(a, R.F(2.5)), "cube": lambda a: R.powi(a, 3),
}
BIN_SX = {
    "add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
    "div": lambda a, b: a / b, "fmin": ca.fmin, "fmax": ca.fmax, "atan2": ca.atan2,
    "atan2p": lambda a, b: ca.atan2(a, ca.exp(b)),  # continuous: the x argument is > 0
    "ifmin": lambda a, b: ca.if_else(a < b, a, b),
}
BIN_MP = {
    "add": R.add, "sub": R.sub, "mul": R.mul, "div": R.div, "fmin": R.fmin, "fmax": R.fmax,
    "atan2": R.atan2, "atan2p": lambda a, b: R.atan2(a, R.exp(b)),
    "ifmin": lambda a, b: a if a < b else b,
}
BIN_CONTINUOUS = ["add", "sub", "mul", "div", "fmin", "fmax"]
BIN_ALL = [*BIN_CONTINUOUS, "atan2", "atan2p", "ifmin"]


# ------------------------------------------------------------------- expression trees
def expressions(continuous: bool):
    """Trees with variables at the leaves; constants only next to a variable sub-tree (so
    that CasADi never folds a constant sub-expression with double rounding).

    ``continuous``: no if_else and no atan2 (which jumps across the negative x axis), so that
    the centered form applies.
    """
    leaf = st.integers(0, 2).map(lambda i: ("x", i))
    const = st.sampled_from(CONSTS).map(lambda c: ("c", c))
    bins = BIN_CONTINUOUS if continuous else BIN_ALL

    def extend(children):
        opts = [
            st.tuples(st.just("u"), st.sampled_from(sorted(UN_SX)), children),
            st.tuples(st.just("b"), st.sampled_from(bins), children, children),
            st.tuples(st.just("b"), st.sampled_from(bins), children, const),
            st.tuples(st.just("b"), st.sampled_from(bins), const, children),
        ]
        if not continuous:  # if_else(a < b, t, e): may jump
            opts.append(st.tuples(st.just("if"), children, children, children, children))
        return st.one_of(opts)

    return st.recursive(leaf, extend, max_leaves=8)


def to_sx(node, syms, memo):
    key = id(node)
    if key in memo:
        return memo[key][1]
    kind = node[0]
    if kind == "x":
        e = syms[node[1]]
    elif kind == "c":
        e = node[1]
    elif kind == "u":
        e = UN_SX[node[1]](to_sx(node[2], syms, memo))
    elif kind == "b":
        e = BIN_SX[node[1]](to_sx(node[2], syms, memo), to_sx(node[3], syms, memo))
    else:
        a, b, t, f = (to_sx(n, syms, memo) for n in node[1:])
        e = ca.if_else(a < b, t, f)
    memo[key] = (node, e)
    return e


class UndefinedAt(Exception):
    """The tree is undefined at the point; ``node`` is the innermost undefined operation."""

    def __init__(self, node):
        super().__init__(repr(node))
        self.node = node


def mp_eval(node, vals, memo):
    key = id(node)
    if key in memo:
        v = memo[key][1]
        if isinstance(v, UndefinedAt):
            raise v
        return v
    try:
        v = _mp_eval(node, vals, memo)
    except UndefinedAt as exc:
        memo[key] = (node, exc)
        raise
    memo[key] = (node, v)
    return v


def _mp_eval(node, vals, memo):
    kind = node[0]
    if kind == "x":
        return vals[node[1]]
    if kind == "c":
        return R.F(node[1])
    if kind == "if":
        a, b = mp_eval(node[1], vals, memo), mp_eval(node[2], vals, memo)
        return mp_eval(node[3] if a < b else node[4], vals, memo)
    args = [mp_eval(n, vals, memo) for n in node[2:]]
    fn = UN_MP[node[1]] if kind == "u" else BIN_MP[node[1]]
    try:
        return fn(*args)
    except R.Undefined:
        raise UndefinedAt(node) from None


def graph_value(fun, point):
    """Exact value of the (1x1) output of the compiled graph at point (x0, x1, p)."""
    out = R.eval_function(fun, [[point[0], point[1]], [point[2]]])[0]
    return out[0] if out else R.ZERO  # a structurally zero output is 0


# ------------------------------------------------------------------------- boxes, points
interval_1d = st.tuples(
    st.one_of(st.floats(-3.0, 3.0), st.sampled_from([0.0, 1.0, -1.0, 0.5, -2.0])),
    st.one_of(st.just(0.0), st.floats(-12.0, 0.3).map(lambda e: 10.0**e)),
).map(lambda t: (t[0], t[0] + t[1]))


@st.composite
def batches(draw):
    n = draw(st.integers(1, 4))
    X = np.array([[draw(interval_1d), draw(interval_1d)] for _ in range(n)])
    if draw(st.booleans()):
        P = np.array([[draw(interval_1d)]])  # one box for p, broadcast against the batch
    else:
        P = np.array([[draw(interval_1d)] for _ in range(n)])
    seed = draw(st.integers(0, 2**32 - 1))
    return X, P, np.random.default_rng(seed)


def box_points(X, P, i, rng, n_random=3):
    p_row = P[i if P.shape[0] > 1 else 0]
    bounds = [X[i, 0], X[i, 1], p_row[0]]
    pts = [tuple(float(b[k]) for b, k in zip(bounds, ks, strict=True))
           for ks in np.ndindex(2, 2, 2)]
    pts.append(tuple(float(min(max(0.5 * b[0] + 0.5 * b[1], b[0]), b[1])) for b in bounds))
    for _ in range(n_random):
        pts.append(tuple(float(min(max(b[0] + (b[1] - b[0]) * rng.random(), b[0]), b[1]))
                         for b in bounds))
    return list(dict.fromkeys(pts))


# ---------------------------------------------------------------------- the checks
def _function(tree):
    x = ca.SX.sym("x", 2)
    p = ca.SX.sym("p")
    syms = [x[0], x[1], p]
    memo: dict = {}
    e = to_sx(tree, syms, memo)
    return ca.Function("f", [x, p], [e], ["x", "p"], ["y"]), (x, p), memo


def _check_tree(tree, X, P, rng, kinds, continuous=False, backend="numpy"):
    fun, (x, p), sx_memo = _function(tree)
    # CasADi turns e.g. x - x into 0 and then folds cos(0), atan(1), ... into rounded doubles:
    # the compiled graph then differs from the tree by that rounding, and only the exact
    # value of the graph is a valid reference
    folded = any(n[0] != "c" and e.is_constant() for n, e in sx_memo.values())
    encs = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cm.CmpcWarning)
        for kind in kinds:
            F = compiled(fun, kind, backend)
            if kind == "centered" and continuous:
                assert not getattr(F, "centered_fallback", False), "not a continuous tree"
            out = F(X, P)
            assert len(out) == 1 and out[0].shape == (X.shape[0], 1, 2)
            assert not np.isnan(out[0]).any(), "an inclusion function returned NaN"
            encs[kind] = out[0][:, 0, :]
    sub_cache: dict = {}
    for i in range(X.shape[0]):
        for pt in box_points(X, P, i, rng):
            vals = [R.F(v) for v in pt]
            g = graph_value(fun, pt)
            try:
                t = mp_eval(tree, vals, {})
            except UndefinedAt as exc:
                t = exc
            for kind, enc in encs.items():
                lo, hi = float(enc[i, 0]), float(enc[i, 1])
                ctx = f"{kind} enclosure [{lo!r}, {hi!r}] of {tree} at {pt}"
                if g is not R.UNDEF:
                    assert R.inside(lo, hi, g), f"{ctx}: graph value {mpmath.nstr(g, 20)}"
                if not isinstance(t, UndefinedAt) and not folded:
                    _check_tree_value(tree, vals, t, lo, hi, ctx)
            if isinstance(t, UndefinedAt):
                _check_undefined_node(t.node, sx_memo, (x, p), X, P, i, pt, sub_cache, backend)


def _tree_value_inside(t, lo, hi, rel_exp):
    tol = abs(t) * mpmath.mpf(2) ** rel_exp  # rounding of the op-by-op evaluation
    return R.F(lo) <= t + tol and t - tol <= R.F(hi)


def _check_tree_value(tree, vals, t, lo, hi, ctx):
    """The tree's value at 300 bits, or if that is outside (CasADi may have simplified e.g.
    log(exp(x)) to x, giving a bound that is exactly the value, which exp then hides in
    1 + x at 300 bits), at 2000 bits, must lie inside [lo, hi]. The relative tolerances
    2**-250 and 2**-900 are far below any floating-point rounding (2**-53 relative, or
    2**-1074 absolute for the smallest values)."""
    if _tree_value_inside(t, lo, hi, -250):
        return
    with mpmath.workprec(2000):
        t2 = mp_eval(tree, vals, {})
        assert _tree_value_inside(t2, lo, hi, -900), f"{ctx}: tree value {mpmath.nstr(t2, 20)}"


def _check_undefined_node(node, sx_memo, syms, X, P, i, pt, cache, backend="numpy"):
    """The innermost undefined operation must be enclosed by the whole line."""
    key = id(node)
    if key not in cache:
        sub = ca.Function("g", list(syms), [sx_memo[key][1]])
        cache[key] = (sub, compiled(sub, "natural", backend))
    sub, G = cache[key]
    if graph_value(sub, pt) is not R.UNDEF:
        return  # CasADi simplified the undefined operation away (e.g. e / e -> 1)
    out = G(X[i:i + 1], P[i:i + 1] if P.shape[0] > 1 else P)[0][0, 0]
    assert out[0] == -math.inf and out[1] == math.inf, (
        f"{node} is undefined at {pt} but its enclosure is {out}")


@SETTINGS
@given(tree=expressions(continuous=False), batch=batches())
def test_natural_random_expressions(tree, batch, backend):
    X, P, rng = batch
    _check_tree(tree, X, P, rng, ["natural"], backend=backend)


@SETTINGS
@given(tree=expressions(continuous=True), batch=batches())
def test_natural_and_centered_random_continuous_expressions(tree, batch, backend):
    X, P, rng = batch
    _check_tree(tree, X, P, rng, ["natural", "centered"], continuous=True, backend=backend)


@settings(max_examples=40, deadline=None)
@given(tree=expressions(continuous=False), batch=batches())
def test_centered_falls_back_soundly_on_jumps(tree, batch, backend):
    """Trees with if_else or atan2 (which may jump) are still enclosed by "centered"."""
    X, P, rng = batch
    _check_tree(tree, X, P, rng, ["centered"], backend=backend)


# --------------------------------------------------------------- targeted behaviour
def _single(fun, kind, *boxes, backend="numpy"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cm.CmpcWarning)
        F = compiled(fun, kind, backend)
    return F(*[np.array([[list(b)]], dtype=float) for b in boxes])[0][0, 0]


def test_unsupported_operation_raises():
    x = ca.SX.sym("x")
    y = ca.SX.sym("y")
    fun = ca.Function("f", [x, y], [x.printme(y) + 1])  # OP_PRINTME has no interval extension
    with pytest.raises(UnsupportedOperationError, match="OP_PRINTME"):
        cm.interval.inclusion(fun, "natural")
    with pytest.raises(UnsupportedOperationError):
        cm.interval.inclusion(fun, "centered")


def test_sparse_input_raises_dimension_error():
    x = ca.SX.sym("x", ca.Sparsity.diag(2))
    fun = ca.Function("f", [x], [ca.sum1(ca.sum2(x))])
    with pytest.raises(DimensionError, match="sparse"):
        cm.interval.inclusion(fun)


def test_unknown_kind_and_wrong_shapes_raise():
    x = ca.SX.sym("x", 2)
    fun = ca.Function("f", [x], [x[0] * x[1]])
    with pytest.raises(ValueError, match="kind"):
        cm.interval.inclusion(fun, "affine")
    F = cm.interval.inclusion(fun)
    with pytest.raises(DimensionError):
        F(np.zeros((4, 3, 2)))


@pytest.mark.parametrize("kind", ["natural", "centered"])
def test_mx_function_is_expanded(kind, backend):
    x = ca.MX.sym("x", 2)
    p = ca.MX.sym("p")
    e = ca.vertcat(ca.sin(x[0]) * p + x[1] ** 2, ca.exp(x[0] - x[1]) / (2 + p))
    fun = ca.Function("f", [x, p], [e])
    F = compiled(fun, kind, backend)
    assert F.fun.is_a("SXFunction")
    rng = np.random.default_rng(5)
    c = rng.uniform(-1, 1, (6, 2))
    X = np.stack([c, c + rng.uniform(0, 0.3, (6, 2))], axis=-1)
    P = np.array([[[0.5, 0.75]]])
    out = F(X, P)[0]
    assert out.shape == (6, 2, 2)
    for i in range(6):
        for _ in range(5):
            pt = [rng.uniform(X[i, 0, 0], X[i, 0, 1]), rng.uniform(X[i, 1, 0], X[i, 1, 1])]
            q = rng.uniform(0.5, 0.75)
            vals = R.eval_function(F.fun, [pt, [q]])[0]
            for k in range(2):
                assert R.inside(out[i, k, 0], out[i, k, 1], vals[k])
        assert np.all(out[i, :, 1] - out[i, :, 0] < 10.0)


@pytest.mark.parametrize("kind", ["natural", "centered"])
def test_outputs_never_contain_nan(kind, backend):
    x = ca.SX.sym("x")
    y = ca.SX.sym("y")
    exprs = [ca.log(x), ca.sqrt(x) * y, x * ca.log(y), ca.exp(ca.exp(x)) - ca.exp(ca.exp(y)),
             ca.asin(x) + 1, 0 * ca.log(x) + x * ca.sqrt(-y), ca.atan(ca.log(x)), x**2.5, x / y]
    fun = ca.Function("f", [x, y], exprs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cm.CmpcWarning)
        F = compiled(fun, kind, backend)
    boxes = np.array([[-2.0, -1.0], [-1.0, 1.0], [0.0, 0.0], [0.0, 2.0], [800.0, 900.0],
                      [-np.inf, 0.0], [3.0, np.inf], [1e300, 1.7e308]])
    X = boxes[:, None, :]
    for Y in (X, X[::-1]):
        outs = F(X, Y)
        assert len(outs) == len(exprs)
        for o in outs:
            assert o.shape == (len(boxes), 1, 2)
            assert not np.isnan(o).any()


@pytest.mark.parametrize("kind", ["natural", "centered"])
def test_single_box_broadcasts_against_batch(kind, backend):
    x = ca.SX.sym("x", 2)
    p = ca.SX.sym("p", 2)
    e = ca.vertcat(x[0] * p[0] + ca.sin(x[1] * p[1]), ca.exp(p[0]) - x[0] ** 2)
    F = compiled(ca.Function("f", [x, p], [e]), kind, backend)
    rng = np.random.default_rng(7)
    c = rng.uniform(-1, 1, (9, 2))
    X = np.stack([c, c + rng.uniform(0, 0.2, (9, 2))], axis=-1)
    Pone = np.array([[0.1, 0.3], [-0.2, 0.0]])
    tiled = np.broadcast_to(Pone, (9, 2, 2))
    expected = F(X, tiled)[0]
    for P in (Pone, Pone[None], cm.Box(Pone[:, 0], Pone[:, 1])):
        got = F(X, P)[0]
        assert got.shape == (9, 2, 2)
        np.testing.assert_array_equal(got, expected)
    # and a single x box against a batch of p boxes
    got = F(X[:1], np.broadcast_to(Pone, (4, 2, 2)))[0]
    assert got.shape == (4, 2, 2)
    np.testing.assert_array_equal(got, np.broadcast_to(F(X[:1], Pone)[0], (4, 2, 2)))
    with pytest.raises(DimensionError):
        F(X, np.broadcast_to(Pone, (4, 2, 2)))


@pytest.mark.parametrize("kind", ["natural", "centered"])
def test_constant_outputs(kind, backend):
    x = ca.SX.sym("x", 2)
    one = ca.SX(1.0)
    outs = [ca.SX(2.5), ca.vertcat(x[0] + 1, ca.SX(-7.0)), ca.sin(one), ca.SX(ca.inf) + 0 * one,
            ca.SX(math.nan) + 0 * one]
    F = compiled(ca.Function("f", [x], outs), kind, backend)
    X = np.array([[[0.0, 1.0], [2.0, 3.0]]] * 3)
    r = F(X)
    assert [o.shape for o in r] == [(3, 1, 2), (3, 2, 2), (3, 1, 2), (3, 1, 2), (3, 1, 2)]
    np.testing.assert_array_equal(r[0][..., 0, :], [[2.5, 2.5]] * 3)
    np.testing.assert_array_equal(r[1][:, 1, :], [[-7.0, -7.0]] * 3)
    assert np.all(r[1][:, 0, 0] <= 1.0) and np.all(r[1][:, 0, 1] >= 2.0)
    c = float(ca.sin(one))  # CasADi folds sin(1) to this double
    np.testing.assert_array_equal(r[2][..., 0, :], [[c, c]] * 3)
    np.testing.assert_array_equal(r[3][..., 0, :], [[np.inf, np.inf]] * 3)
    np.testing.assert_array_equal(r[4][..., 0, :], [[-np.inf, np.inf]] * 3)


@pytest.mark.parametrize("kind", ["natural", "centered"])
def test_structural_zeros_are_exact_zeros(kind, backend):
    x = ca.SX.sym("x", 3)
    f = ca.vertcat(x[0] * x[1], ca.sin(x[0]), ca.exp(x[2]), x[1] ** 2)
    J = ca.jacobian(f, x)  # 4x3 with structural zeros
    assert J.nnz() < 12
    F = compiled(ca.Function("J", [x], [J]), kind, backend)
    rng = np.random.default_rng(11)
    c = rng.uniform(-2, 2, (5, 3))
    X = np.stack([c, c + rng.uniform(0, 0.5, (5, 3))], axis=-1)
    out = F(X)[0]
    assert out.shape == (5, 12, 2)
    dense = np.zeros(12, dtype=bool)
    dense[np.asarray(J.sparsity().find())] = True
    assert np.all(out[:, ~dense, :] == 0.0)
    assert not np.any(np.signbit(out[:, ~dense, :]))  # +0.0, not -0.0
    Jf = ca.Function("Jd", [x], [ca.densify(J)])
    for i in range(5):
        pt = [rng.uniform(X[i, k, 0], X[i, k, 1]) for k in range(3)]
        vals = R.eval_function(Jf, [pt])[0]  # dense, column-major
        for k in range(12):
            assert R.inside(out[i, k, 0], out[i, k, 1], vals[k])


def test_centered_is_tighter_than_natural_on_small_boxes(backend):
    x = ca.SX.sym("x", 2)
    e = x[0] * ca.exp(x[1]) - x[0] ** 2 * x[1] + ca.sin(x[0] * x[1])
    fun = ca.Function("f", [x], [e])
    c = np.array([0.7, -0.4])
    X = np.array([[[c[0] - 0.01, c[0] + 0.01], [c[1] - 0.01, c[1] + 0.01]]])
    nat = compiled(fun, "natural", backend)(X)[0][0, 0]
    cen = compiled(fun, "centered", backend)(X)[0][0, 0]
    assert nat[0] <= cen[0] <= cen[1] <= nat[1]
    assert cen[1] - cen[0] < 0.8 * (nat[1] - nat[0])


@pytest.mark.parametrize(("expr", "box", "point"), [
    ("if_else(x > 0, x + 1, x - 1)", (-1.0, 1.0), 1.0),
    ("floor(x)", (0.0, 2.0), 2.0),
    ("sign(x)", (-1.0, 1.0), 1.0),
])
def test_centered_contains_jumps(expr, box, point, backend):
    x = ca.SX.sym("x")
    e = {"if_else(x > 0, x + 1, x - 1)": ca.if_else(x > 0, x + 1, x - 1),
         "floor(x)": ca.floor(x), "sign(x)": ca.sign(x)}[expr]
    fun = ca.Function("f", [x], [e])
    lo, hi = _single(fun, "centered", box, backend=backend)
    v = float(fun(point))
    lo2, hi2 = _single(fun, "centered", (box[0], box[0]), backend=backend)
    assert lo <= v <= hi and lo <= float(fun(box[0])) <= hi and lo2 <= hi2


# ------------------------------------------------------ centered-form regressions
def test_centered_atan2_across_the_branch_cut(backend):
    """atan2 jumps by 2*pi across the negative x axis: no mean-value form through it."""
    y = ca.SX.sym("y")
    x = ca.SX.sym("x")
    fun = ca.Function("f", [y, x], [ca.atan2(y, x)])
    lo, hi = _single(fun, "centered", (-0.1, 0.1), (-2.0, -1.0), backend=backend)
    for v in (math.atan2(-0.05, -1.5), math.atan2(0.05, -1.5)):  # about -3.108 and 3.108
        assert lo <= v <= hi


def test_centered_not_wider_than_natural_with_a_thin_input():
    """An unbounded Jacobian entry times the zero radius of a thin input contributes
    nothing; the centered enclosure stays inside the natural one."""
    x = ca.SX.sym("x")
    y = ca.SX.sym("y")
    for e in (ca.fmin(x, y), x * ca.sqrt(y), ca.sqrt(x) + y):
        fun = ca.Function("f", [x, y], [e])
        for bx, by in [((1.0, 1.0), (0.0, 2.0)), ((0.0, 0.0), (1.0, 2.0))]:
            nat = _single(fun, "natural", bx, by)
            cen = _single(fun, "centered", bx, by)
            assert nat[0] <= cen[0] <= cen[1] <= nat[1], (e, bx, by, nat, cen)


def test_centered_does_not_fold_constants_in_floating_point():
    """f(m), J and f(Z) must not be rebuilt in a way that lets CasADi fold a sub-expression
    (here e - e = 0, then atan(0.5 + 0)) into an unwidened double."""
    x = ca.SX.sym("x")
    e = ca.atan(0.5 + (ca.exp(ca.sin(x)) - ca.exp(ca.sin(x))))  # == atan(0.5) for all x
    fun = ca.Function("f", [x], [e])
    assert not e.is_constant() and fun.n_instructions() > 3
    for box in [(0.0, 1.0), (0.25, 0.25)]:
        lo, hi = _single(fun, "centered", box)
        assert R.inside(lo, hi, mpmath.atan(R.F(0.5)))


# ---------------------------------------------------------- known compiler problems
def test_undefined_on_part_of_the_box_gives_whole_line():
    x = ca.SX.sym("x")
    fun = ca.Function("f", [x], [ca.atan(ca.log(x))])
    lo, hi = _single(fun, "natural", (-1.0, 1.0))
    assert lo == -math.inf and hi == math.inf


def test_component_evaluator_equals_the_joint_evaluation():
    x = ca.SX.sym("x", 3)
    y = ca.vertcat(x[0] * x[1] - ca.sin(x[2]), ca.SX(1, 1), 2.5, ca.exp(x[0]) / (1 + x[1] ** 2))
    F = cm.interval.inclusion(ca.Function("f", [x], [y]))
    rng = np.random.default_rng(7)
    lo = rng.uniform(-2, 2, (300, 3))
    hi = lo + rng.uniform(0, 1, (300, 3))
    joint = F(np.stack([lo, hi], axis=-1))[0]
    for j in range(4):
        ev = F.component_evaluator(j)
        assert ev is F.component_evaluator(j)  # compiled once
        l, h = ev(lo, hi)
        np.testing.assert_array_equal(np.broadcast_to(l, (300,)), joint[:, j, 0])
        np.testing.assert_array_equal(np.broadcast_to(h, (300,)), joint[:, j, 1])
    assert F.component_evaluator(1)(lo, hi) == (0.0, 0.0)  # structural zero
    # only what the element depends on is evaluated: x2 enters element 0 only
    lo_nan = lo.copy()
    lo_nan[:, 2] = np.nan
    assert np.isfinite(F.component_evaluator(3)(lo_nan, hi)[0]).all()
    with pytest.raises(IndexError):
        F.component_evaluator(4)


def test_component_evaluator_unavailable_cases():
    x, p = ca.SX.sym("x", 2), ca.SX.sym("p")
    two_inputs = cm.interval.inclusion(ca.Function("g", [x, p], [x * p]))
    assert two_inputs.component_evaluator(0) is None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        centered = cm.interval.inclusion(ca.Function("h", [x], [x * x]), "centered")
    assert centered.component_evaluator(0) is None


def test_component_core_peels_affine_steps():
    x = ca.SX.sym("x", 2)
    y = ca.vertcat(3 * (x[0] ** 2 + 1) - 2, 5 + x[1], x[0] * x[1], -2 * x[0] + 1, x[0] - x[1])
    F = cm.interval.inclusion(ca.Function("f", [x], [y]))
    ev, steps = F.component_core(0)
    assert steps == [("add", -2.0), ("mul", 3.0), ("add", 1.0)]
    lo, hi = np.array([[-1.0, 0.0]]), np.array([[2.0, 1.0]])
    l, h = ev(lo, hi)
    assert l[0] <= 0.0 and 4.0 <= h[0] <= 4.0 + 1e-12  # the core is x0^2 on [-1, 2]
    assert F.component_core(1)[1] == [("add", 5.0)]
    assert F.component_core(2) is None  # no affine step
    core3 = F.component_core(3)  # negative factors are not peeled
    assert core3 is None or all(c > 0 for kind, c in core3[1] if kind == "mul")
    assert F.component_core(4) is None  # x0 - x1: no constant
