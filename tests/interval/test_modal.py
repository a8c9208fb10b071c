"""Modal (Kaucher) interval arithmetic and the semantic extension (``interval/modal.py``).

The reference for every binary operation is the *definition* (5.11) of the semantic extension,
``f*(X, Y) = [min_{proper} max_{improper} f, max_{proper} min_{improper} f]``, evaluated
exactly with fractions over candidate points that contain the optimisers (the endpoints of
``Prop`` and 0: ``x * y`` and ``x / y`` are monotone in each variable on each side of 0). The
float operations are checked against it in the modal inclusion order: outer rounding must
contain it, inner rounding must be contained in it.
"""

from __future__ import annotations

import itertools
import math
from fractions import Fraction

import casadi as ca
import mpmath
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from casadi_cmpc.exceptions import (
    DimensionError,
    InvalidBoundsError,
    UnsupportedOperationError,
)
from casadi_cmpc.interval import modal as M

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
FEW = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# ------------------------------------------------------------------------ strategies
_special = st.sampled_from([0.0, -0.0, 1.0, -1.0, 0.1, -0.1, 3.0, -2.5, 1e-300, -1e-300])
_float = st.one_of(
    _special,
    st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False),
    st.floats(-1e-3, 1e-3, allow_nan=False, allow_infinity=False),
)
modal_iv = st.tuples(_float, _float)  # any order: proper, improper or point
proper_iv = modal_iv.map(lambda t: (min(t), max(t)))


def _nonzero(t):
    a, b = t
    return (min(a, b) > 0) or (max(a, b) < 0)


# ------------------------------------------------------------------------ references
def F(x) -> Fraction:
    """Exact conversion of a float (fractions are kept)."""
    if isinstance(x, Fraction):
        return x
    return Fraction(float(x))


def _candidates(a, b, extra=()):
    lo, hi = min(a, b), max(a, b)
    c = {F(a), F(b)}
    for e in extra:
        if lo <= e <= hi:
            c.add(F(e))
    return sorted(c)


def semantic(f, ivs, extras=None):
    """Exact f*(X1, ..., Xk) of (5.11) over candidate points (fractions).

    ``ivs``: list of (Lb, Ub); a component with Lb > Ub is improper. ``extras``: per
    component, extra candidate points (e.g. 0) at which the optimisers may lie.
    """
    extras = extras or [()] * len(ivs)
    cands = [_candidates(a, b, e) for (a, b), e in zip(ivs, extras, strict=True)]
    prop_ix = [i for i, (a, b) in enumerate(ivs) if a <= b]
    imp_ix = [i for i, (a, b) in enumerate(ivs) if a > b]

    def value(pp, ii):
        z = [None] * len(ivs)
        for i, v in zip(prop_ix, pp, strict=True):
            z[i] = v
        for i, v in zip(imp_ix, ii, strict=True):
            z[i] = v
        return f(*z)

    P = list(itertools.product(*[cands[i] for i in prop_ix]))
    Ii = list(itertools.product(*[cands[i] for i in imp_ix]))
    lo = min(max(value(pp, ii) for ii in Ii) for pp in P)
    hi = max(min(value(pp, ii) for ii in Ii) for pp in P)
    return lo, hi


def kaucher_mul_ref(X, Y):
    """Kaucher's table with fractions (a second, independent statement of the product)."""
    a, b = F(X[0]), F(X[1])
    c, d = F(Y[0]), F(Y[1])

    def cls(p, q):
        if p >= 0 and q >= 0:
            return "P"
        if p <= 0 and q <= 0:
            return "N"
        return "Z" if p < 0 < q else "D"

    t = {
        ("P", "P"): (a * c, b * d), ("P", "Z"): (b * c, b * d), ("P", "N"): (b * c, a * d),
        ("P", "D"): (a * c, a * d), ("Z", "P"): (a * d, b * d),
        ("Z", "Z"): (min(a * d, b * c), max(a * c, b * d)), ("Z", "N"): (b * c, a * c),
        ("Z", "D"): (0, 0), ("N", "P"): (a * d, b * c), ("N", "Z"): (a * d, a * c),
        ("N", "N"): (b * d, a * c), ("N", "D"): (b * d, b * c), ("D", "P"): (a * c, b * c),
        ("D", "Z"): (0, 0), ("D", "N"): (b * d, a * d),
        ("D", "D"): (max(a * c, b * d), min(a * d, b * c)),
    }
    return t[(cls(a, b), cls(c, d))]


def _le(x: float, q: Fraction) -> bool:
    """float x <= exact q (x may be infinite)."""
    return x == -np.inf or (x != np.inf and F(x) <= q)


def _ge(x: float, q: Fraction) -> bool:
    return x == np.inf or (x != -np.inf and F(x) >= q)


def bracket(res, exact, inner):
    """Modal inclusion checked exactly: inner ⊆ exact (inner) or exact ⊆ outer.

    NaN bounds mean "no information" and are read as such for the direction.
    """
    lo, hi = (float(v) for v in M.no_nan(np.asarray(res, dtype=float),
                                        "inner" if inner else "outer"))
    if inner:
        return _ge(lo, exact[0]) and _le(hi, exact[1])
    return _le(lo, exact[0]) and _ge(hi, exact[1])


def arr(t):
    return np.array(t, dtype=float)


# ============================================================ structure and ordering
@SETTINGS
@given(modal_iv)
def test_dual_prop_mode(X):
    x = arr(X)
    assert M.dual(M.dual(x)).tolist() == x.tolist()
    p = M.prop(x)
    assert p[0] <= p[1] and {p[0], p[1]} == {x[0], x[1]}
    m = int(M.mode(x))
    assert m == (1 if x[0] < x[1] else -1 if x[0] > x[1] else 0)
    assert bool(M.is_proper(x)) == (x[0] <= x[1])
    assert bool(M.is_improper(x)) == (x[0] >= x[1])
    # (5.7): Inn ⊆ X ⊆ Out (5.10) and Dual reverses inclusion
    assert M.modal_subset(M.round_inner(x), x) and M.modal_subset(x, M.round_outer(x))
    assert M.modal_subset(M.dual(M.round_outer(x)), M.dual(x))


def test_mode_refuses_nan():
    with pytest.raises(InvalidBoundsError, match="NaN"):
        M.mode(np.array([np.nan, 1.0]))
    with pytest.raises(DimensionError, match=r"\(\.\.\., 2\)"):
        M.dual(np.zeros(3))


def test_inclusion_examples_of_the_thesis():
    # [2, 3] ⊆ [1, 5]; [5, 1] ⊆ [3, 2] (both improper); a proper interval in an improper one
    # only when all four bounds are equal; an improper one in a proper one when Prop meet
    assert M.modal_subset(arr([2, 3]), arr([1, 5]))
    assert M.modal_subset(arr([5, 1]), arr([3, 2]))
    assert not M.modal_subset(arr([2, 3]), arr([3, 2]))
    assert M.modal_subset(arr([2, 2]), arr([2, 2]))
    assert M.modal_subset(arr([3, 2]), arr([1, 5]))
    assert not M.modal_subset(arr([7, 6]), arr([1, 5]))


@SETTINGS
@given(modal_iv, modal_iv)
def test_meet_join_bounds(X, Y):
    x, y = arr(X), arr(Y)
    mt, jn = M.meet(x, y), M.join(x, y)
    assert M.modal_subset(mt, x) and M.modal_subset(mt, y)
    assert M.modal_subset(x, jn) and M.modal_subset(y, jn)


def test_no_nan():
    x = np.array([[np.nan, 1.0], [2.0, np.nan]])
    assert M.no_nan(x, "outer").tolist() == [[-np.inf, 1.0], [2.0, np.inf]]
    assert M.no_nan(x, "inner").tolist() == [[np.inf, 1.0], [2.0, -np.inf]]
    with pytest.raises(ValueError, match="rounding"):
        M.no_nan(x, "sideways")


# ---------------------------------------------------------------------------- roundings
@SETTINGS
@given(modal_iv, st.one_of(st.none(), st.integers(0, 6)))
def test_roundings_are_sound(X, digits):
    x = arr(X)
    out = M.round_outer(x, digits)
    inn = M.round_inner(x, digits)
    # exact comparisons: Left(a) <= a, Right(b) >= b
    assert F(out[0]) <= F(x[0]) and F(out[1]) >= F(x[1])
    assert F(inn[0]) >= F(x[0]) and F(inn[1]) <= F(x[1])
    # (5.9)
    assert inn.tolist() == M.dual(M.round_outer(M.dual(x), digits)).tolist()


def test_rounding_example_of_the_thesis():
    assert M.round_inner(arr([1.346, 1.347]), digits=2).tolist() == [1.35, 1.34]
    assert M.round_outer(arr([1.346, 1.347]), digits=2).tolist() == [1.34, 1.35]
    x = arr([1.0, 2.0])
    o = M.round_outer(x)
    assert o[0] == np.nextafter(1.0, 0) and o[1] == np.nextafter(2.0, 3)


# ============================================================== Kaucher arithmetic
@SETTINGS
@given(modal_iv, modal_iv)
def test_add_sub_agree_with_definition(X, Y):
    add = semantic(lambda x, y: x + y, [X, Y])
    sub = semantic(lambda x, y: x - y, [X, Y])
    assert (F(X[0]) + F(Y[0]), F(X[1]) + F(Y[1])) == add
    for r in ("outer", "inner"):
        assert bracket(M.kaucher_add(arr(X), arr(Y), r), add, r == "inner")
        assert bracket(M.kaucher_sub(arr(X), arr(Y), r), sub, r == "inner")


@SETTINGS
@given(modal_iv, modal_iv)
def test_mul_agrees_with_definition(X, Y):
    exact = semantic(lambda x, y: x * y, [X, Y], [(0.0,), (0.0,)])
    assert kaucher_mul_ref(X, Y) == exact  # Kaucher's table is the semantic extension
    for r in ("outer", "inner"):
        assert bracket(M.kaucher_mul(arr(X), arr(Y), r), exact, r == "inner")


@SETTINGS
@given(modal_iv, modal_iv.filter(_nonzero))
def test_div_agrees_with_definition(X, Y):
    exact = semantic(lambda x, y: x / y, [X, Y], [(0.0,), ()])
    for r in ("outer", "inner"):
        assert bracket(M.kaucher_div(arr(X), arr(Y), r), exact, r == "inner")


def test_div_by_interval_holding_zero_is_no_information():
    r = M.kaucher_div(arr([1, 2]), arr([-1, 1]))
    assert np.isnan(r).all()
    r = M.kaucher_div(arr([1, 2]), arr([1, -1]))  # improper, 0 in Prop
    assert np.isnan(r).all()


@SETTINGS
@given(proper_iv, proper_iv)
def test_proper_operands_give_classical_arithmetic(X, Y):
    from casadi_cmpc.interval import ops

    x, y = arr(X), arr(Y)
    for kop, cop in ((M.kaucher_add, ops.add), (M.kaucher_sub, ops.sub),
                     (M.kaucher_mul, ops.mul)):
        k = kop(x, y)
        c = cop(x, y)
        assert k.tolist() == c.tolist() or np.allclose(k, c, rtol=1e-15, atol=1e-300)


@SETTINGS
@given(modal_iv, modal_iv, modal_iv)
def test_group_properties(X, Y, Z):
    x = arr(X)
    for r in ("outer", "inner"):
        # X + Dual(-X) = [0, 0] and X - Dual(X) = [0, 0] (exact in floating point too)
        assert M.kaucher_add(x, M.dual(M.kaucher_neg(x)), r).tolist() == [0.0, 0.0]
        assert M.kaucher_sub(x, M.dual(x), r).tolist() == [0.0, 0.0]
    # commutativity and associativity of + and commutativity of * (exact, with fractions)
    fx, fy, fz = [(F(t[0]), F(t[1])) for t in (X, Y, Z)]
    s1 = (fx[0] + fy[0] + fz[0], fx[1] + fy[1] + fz[1])
    assert s1 == ((fx[0] + fy[0]) + fz[0], (fx[1] + fy[1]) + fz[1])
    assert kaucher_mul_ref(X, Y) == kaucher_mul_ref(Y, X)


@SETTINGS
@given(modal_iv.filter(_nonzero))
def test_multiplicative_inverse(X):
    # X * Dual(1/X) = [1, 1] exactly; the float results bracket it
    x = arr(X)
    a, b = F(x[0]), F(x[1])
    assert kaucher_mul_ref((a, b), (1 / a, 1 / b)) == (1, 1)
    out = M.kaucher_mul(x, M.dual(M.kaucher_inv(x, "inner")), "outer")
    inn = M.kaucher_mul(x, M.dual(M.kaucher_inv(x, "outer")), "inner")
    assert bracket(out, (1, 1), inner=False)
    assert bracket(inn, (1, 1), inner=True)


@SETTINGS
@given(modal_iv, modal_iv, st.floats(0, 1), st.floats(0, 1), st.floats(0, 1),
       st.floats(0, 1))
def test_mul_is_inclusion_isotone(X, Y, s1, s2, s3, s4):
    # X' ⊆ X and Y' ⊆ Y  =>  X' * Y' ⊆ X * Y (exact table)
    def shrink(t, s, r):  # a modal sub-interval: raise Lb, lower Ub
        a, b = F(t[0]), F(t[1])
        return (a + abs(b - a) * F(s), b - abs(b - a) * F(r))

    Xs, Ys = shrink(X, s1, s2), shrink(Y, s3, s4)
    big = kaucher_mul_ref(X, Y)
    small = kaucher_mul_ref(Xs, Ys)
    assert small[0] >= big[0] and small[1] <= big[1]


@SETTINGS
@given(proper_iv, modal_iv)
def test_centered_product_is_the_kaucher_product(G, D):
    # the specialised product of the mean-value form equals the table when 0 is in Prop D
    d0, d1 = D
    if d0 <= d1:
        d0, d1 = min(d0, 0.0), max(d1, 0.0)
    else:
        d0, d1 = max(d0, 0.0), min(d1, 0.0)
    g, d = arr(G), arr([d0, d1])
    lo, hi = M._kmul_centered(g[0], g[1], d[0], d[1])
    ref = M.kaucher_mul(g, d, "outer")
    assert [float(lo), float(hi)] == ref.tolist()


# ---------------------------------------------------------------------------- unary
def _unary_semantic(fn, X, crit=()):
    """Exact-enough f* of a one-variable function with mpmath: range over Prop (proper) or
    its dual (improper), over the endpoints and the critical points inside."""
    a, b = X
    lo, hi = min(a, b), max(a, b)
    pts = [lo, hi] + [c for c in crit if lo <= c <= hi]
    vals = [fn(mpmath.mpf(p)) for p in pts]
    rng = (min(vals), max(vals))
    return rng if a <= b else (rng[1], rng[0])


def _mp_bracket(res, exact, inner):
    lo, hi = mpmath.mpf(float(res[0])), mpmath.mpf(float(res[1]))
    if inner:
        return lo >= exact[0] and hi <= exact[1]
    return lo <= exact[0] and hi >= exact[1]


@SETTINGS
@given(modal_iv)
def test_even_and_odd_functions(X):
    mpmath.mp.prec = 200
    x = arr(X)
    cases = [
        (M.kaucher_sq(x, "outer"), M.kaucher_sq(x, "inner"), lambda v: v * v, (0.0,)),
        (M.kaucher_fabs(x, "outer"), M.kaucher_fabs(x, "inner"), abs, (0.0,)),
        (M.kaucher_powi(x, 3, "outer"), M.kaucher_powi(x, 3, "inner"), lambda v: v ** 3, ()),
        (M.kaucher_powi(x, 4, "outer"), M.kaucher_powi(x, 4, "inner"), lambda v: v ** 4,
         (0.0,)),
    ]
    for out, inn, fn, crit in cases:
        exact = _unary_semantic(fn, X, crit)
        assert _mp_bracket(out, exact, inner=False)
        assert _mp_bracket(inn, exact, inner=True)


@SETTINGS
@given(modal_iv, st.sampled_from(["exp", "atan", "tanh", "sqrt", "log", "asinh"]))
def test_monotone_functions(X, name):
    mpmath.mp.prec = 200
    fns = {"exp": mpmath.exp, "atan": mpmath.atan, "tanh": mpmath.tanh, "sqrt": mpmath.sqrt,
           "log": mpmath.log, "asinh": mpmath.asinh}
    x = arr(X)
    if name in ("exp",):
        x = np.clip(x, -700, 700)
    out = M.kaucher_monotone(x, name, rounding="outer")
    inn = M.kaucher_monotone(x, name, rounding="inner")
    lo = min(x)
    if (name == "sqrt" and lo < 0) or (name == "log" and lo <= 0):
        assert np.isnan(out).all() and np.isnan(inn).all()
        return
    exact = _unary_semantic(fns[name], tuple(x))
    assert _mp_bracket(out, exact, inner=False)
    assert _mp_bracket(inn, exact, inner=True)


def test_unary_errors():
    with pytest.raises(ValueError, match="unknown monotone function"):
        M.kaucher_monotone(arr([0, 1]), "sin")
    with pytest.raises(ValueError, match="n >= 0"):
        M.kaucher_powi(arr([1, 2]), -1)
    with pytest.raises(ValueError, match="unknown rounding"):
        M.kaucher_add(arr([0, 1]), arr([0, 1]), "upward")


# ============================================================ semantic extension
x_, u_, w_ = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("w")
# (name, casadi expression, exact python function, extra candidate points per variable)
EXAMPLES = {
    "x+u": (x_ + u_, lambda x, u: x + u, lambda X, U: [(), ()]),
    "x*u": (x_ * u_, lambda x, u: x * u, lambda X, U: [(0.0,), (0.0,)]),
    "x^2+u": (x_ ** 2 + u_, lambda x, u: x * x + u, lambda X, U: [(0.0,), ()]),
    # optimisers of (x - u)^2 in one variable: the other's endpoints or centre
    "(x-u)^2": ((x_ - u_) ** 2, lambda x, u: (x - u) ** 2,
                lambda X, U: [(U[0], U[1], 0.5 * U[0] + 0.5 * U[1]),
                              (X[0], X[1], 0.5 * X[0] + 0.5 * X[1])]),
}
EXTS = {k: M.SemanticExtension(ca.Function(f"example{i}", [x_, u_], [v[0]]))
        for i, (k, v) in enumerate(EXAMPLES.items())}


def _exact_fstar(name, X, U):
    _, fn, extra = EXAMPLES[name]
    return semantic(fn, [X, U], extra(X, U))


@FEW
@given(st.sampled_from(sorted(EXAMPLES)), proper_iv, proper_iv,
       st.sampled_from([(0, 0), (1, 2), (3, 3)]))
def test_semantic_extension_brackets_forall_exists(name, X, U, splits):
    # ∀x ∃u: x proper, u improper
    X = tuple(np.clip(X, -10, 10))
    U = tuple(np.clip(U, -10, 10))
    Ui = (U[1], U[0])
    exact = _exact_fstar(name, X, Ui)
    inn, out = EXTS[name].bounds(arr([X])[None], arr([Ui])[None], splits=splits)
    assert bracket(out[0, 0], exact, inner=False)
    assert bracket(inn[0, 0], exact, inner=True)


@FEW
@given(st.sampled_from(sorted(EXAMPLES)), modal_iv, modal_iv)
def test_semantic_extension_any_modality(name, X, U):
    X = tuple(np.clip(X, -10, 10))
    U = tuple(np.clip(U, -10, 10))
    exact = _exact_fstar(name, X, U)
    inn, out = EXTS[name].bounds(arr([X])[None], arr([U])[None])
    assert bracket(out[0, 0], exact, inner=False)
    assert bracket(inn[0, 0], exact, inner=True)


def test_monotone_functions_are_sharp():
    # x + u and x * u on sign-definite boxes: inner and outer within a few ulps of f*
    X = arr([[[1.0, 2.0]]])
    U = arr([[[3.0, 0.5]]])  # improper
    for name in ("x+u", "x*u"):
        exact = _exact_fstar(name, (1.0, 2.0), (3.0, 0.5))
        inn, out = EXTS[name].bounds(X, U)
        assert np.allclose(inn[0, 0], [float(e) for e in exact], rtol=1e-14)
        assert np.allclose(out[0, 0], [float(e) for e in exact], rtol=1e-14)


def test_partitions_tighten_the_inner_approximation():
    X = arr([[[-1.0, 2.0]]])
    U = M.dual(arr([[[0.0, 1.0]]]))
    ext = EXTS["x^2+u"]
    exact = _exact_fstar("x^2+u", (-1.0, 2.0), (1.0, 0.0))  # [1, 4]
    assert exact == (1, 4)
    widths = []
    for s in [(0, 0), (2, 0), (4, 0), (6, 0)]:
        inn, out = ext.bounds(X, U, splits=s)
        assert bracket(out[0, 0], exact, inner=False)
        assert bracket(inn[0, 0], exact, inner=True)
        widths.append(abs(inn[0, 0, 0] - 1.0))
    assert widths == sorted(widths, reverse=True) and widths[-1] < 1e-3


def test_three_inputs_forall_forall_exists():
    # f = x u + w, ∀x ∀w ∃u: f* = [min_x max_u x u + w_lo, max_x min_u x u + w_hi]
    ext = M.SemanticExtension(ca.Function("g", [x_, u_, w_], [x_ * u_ + w_]))
    X, U, W = (-1.0, 2.0), (1.5, -0.5), (0.0, 0.25)
    exact = semantic(lambda x, u, w: x * u + w, [X, U, W], [(0.0,), (0.0,), ()])
    for s in [(0, 0), (2, 2)]:
        inn, out = ext.bounds(arr([X])[None], arr([U])[None], arr([W])[None], splits=s)
        assert bracket(out[0, 0], exact, inner=False)
        assert bracket(inn[0, 0], exact, inner=True)


@FEW
@given(proper_iv, proper_iv, proper_iv)
def test_mean_value_extension_alone(X, U, W):
    # Theorem 2 in isolation: K(X*) ⊇ f* and Dual(K(Dual X*)) ⊆ f*, for f = x u + w x
    # (x, w proper; u improper)
    X, U, W = (tuple(np.clip(t, -5, 5)) for t in (X, U, W))
    ext = M.SemanticExtension(ca.Function("h", [x_, u_, w_], [x_ * u_ + w_ * x_]))
    Ui = (U[1], U[0])
    exact = semantic(lambda x, u, w: x * u + w * x, [X, Ui, W], [(0.0,), (0.0,), (0.0,)])
    Z = arr([[X, U, W]])
    imp = np.array([[False, True, False]])
    J = ext.jacobian_unchecked(Z)
    res = {"outer_lo": np.full((1, 1), -np.inf), "outer_hi": np.full((1, 1), np.inf),
           "inner_lo": np.full((1, 1), np.inf), "inner_hi": np.full((1, 1), -np.inf)}
    with np.errstate(all="ignore"):
        ext._mean_value(Z, imp, J, np.clip(0.5 * Z[..., 0] + 0.5 * Z[..., 1], Z[..., 0],
                                           Z[..., 1]), res, True, True)
    assert bracket((res["outer_lo"][0, 0], res["outer_hi"][0, 0]), exact, inner=False)
    assert bracket((res["inner_lo"][0, 0], res["inner_hi"][0, 0]), exact, inner=True)


def test_vector_output_and_batches():
    x2 = ca.SX.sym("x", 2)
    ext = M.semantic_extension(ca.Function("v", [x2, u_], [ca.vertcat(x2[0] + u_,
                                                                      x2[1] * u_)]))
    X = arr([[[0.0, 1.0], [1.0, 2.0]], [[-1.0, 0.0], [2.0, 3.0]]])  # (2, 2, 2)
    U = arr([[[2.0, 1.0]]])  # improper, broadcast
    inn, out = ext.bounds(X, U)
    assert inn.shape == out.shape == (2, 2, 2)
    for i in range(2):
        e0 = semantic(lambda x, u: x + u, [tuple(X[i, 0]), (2.0, 1.0)])
        e1 = semantic(lambda x, u: x * u, [tuple(X[i, 1]), (2.0, 1.0)], [(0.0,), ()])
        for j, e in enumerate((e0, e1)):
            assert bracket(out[i, j], e, inner=False)
            assert bracket(inn[i, j], e, inner=True)
    assert ext.outer(X, U).tolist() == out.tolist()
    assert ext.inner(X, U).tolist() == inn.tolist()


def test_semantic_extension_errors():
    with pytest.raises(UnsupportedOperationError, match="jump"):
        M.SemanticExtension(ca.Function("s", [x_], [ca.floor(x_)]))
    with pytest.raises(DimensionError, match="one output"):
        M.SemanticExtension(ca.Function("t", [x_], [x_, x_]))
    ext = EXTS["x+u"]
    with pytest.raises(TypeError, match="2 modal box"):
        ext.outer(arr([[[0.0, 1.0]]]))
    with pytest.raises(InvalidBoundsError, match="finite"):
        ext.outer(arr([[[0.0, np.inf]]]), arr([[[0.0, 1.0]]]))
    with pytest.raises(ValueError, match="non-negative"):
        ext.bounds(arr([[[0.0, 1.0]]]), arr([[[0.0, 1.0]]]), splits=(-1, 0))



# ------------------------------------------------------------- overflow is not NaN
_HUGE_IVS = [(710.0, 711.0), (711.0, 710.0), (1e200, 1e201), (1e201, 1e200),
             (-1e201, -1e200), (-1e200, -1e201), (1e308, 1.7976931348623157e308)]


@pytest.mark.parametrize("X", _HUGE_IVS)
def test_overflow_gives_finite_bounds_not_nan(X):
    """An overflowed bound is a real beyond the float range: outer rounding keeps a finite
    bound on the inner side of it (never NaN, never an infinite lower bound +inf), inner
    rounding stays inside the exact result."""
    mpmath.mp.prec = 200
    x = arr(X)
    cases = [(lambda r: M.kaucher_sq(x, r), lambda v: v * v, (0.0,)),
             (lambda r: M.kaucher_powi(x, 3, r), lambda v: v ** 3, ()),
             (lambda r: M.kaucher_powi(x, 4, r), lambda v: v ** 4, (0.0,))]
    if abs(x).max() < 1e3:
        cases += [(lambda r: M.kaucher_monotone(x, "exp", rounding=r), mpmath.exp, ()),
                  (lambda r: M.kaucher_monotone(x, "sinh", rounding=r), mpmath.sinh, ())]
    for fn, ref, crit in cases:
        exact = _unary_semantic(ref, tuple(x), crit)
        out, inn = fn("outer"), fn("inner")
        assert not np.isnan(out).any() and not np.isnan(inn).any(), (X, out, inn)
        assert _mp_bracket(out, exact, inner=False), (X, out)
        assert _mp_bracket(inn, exact, inner=True), (X, inn)
    y = arr((X[0] * 0.5, X[1] * 0.5))
    out = M.kaucher_mul(x, y, "outer")
    assert not np.isnan(out).any(), (X, out)


def test_semantic_extension_of_an_overflowing_composite():
    """tan(fmin(exp(x0), x1)) on [710, 711] x [1, 2]: exp overflows, fmin is x1, tan has a
    pole in [1, 2]. The outer approximation must contain every value (it was [-inf, -2.19],
    which misses tan(1.5) = 14.1)."""
    x0, x1 = ca.SX.sym("x0"), ca.SX.sym("x1")
    ext = M.SemanticExtension(ca.Function("f", [x0, x1], [ca.tan(ca.fmin(ca.exp(x0), x1))]))
    out = ext.outer(np.array([[[710.0, 711.0]]]), np.array([[[1.0, 2.0]]]))[0, 0]
    for v in (math.tan(1.0), math.tan(1.5), math.tan(2.0)):
        assert out[0] <= v <= out[1], out
