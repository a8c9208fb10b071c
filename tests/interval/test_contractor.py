"""Forward-backward (HC4Revise) contractors of ``casadi_cmpc.interval.contractor``.

Soundness is checked by sampling: for random boxes and targets, every sampled point of the
original box whose value (evaluated by CasADi) lies in the target must lie in the contracted
box, and a box declared empty must hold no such point. The target is shrunk by a relative
1e-9 for this membership test, so that float evaluation errors of CasADi cannot turn a point
just outside the exact solution set into a counterexample. Exact contractions are checked
against closed-form answers, with outward rounding of at most 1e-12.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.exceptions import DimensionError, EmptySetError, InvalidBoundsError
from casadi_cmpc.interval.contractor import Contractor, contractor

INF = math.inf
SETTINGS = settings(max_examples=30, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
N_BOXES = 6
N_POINTS = 300  # per box, corners and centre included

X = ca.SX.sym("x", 2)
x, y = X[0], X[1]
XY, SIN_X = x * y, ca.sin(x)  # shared nodes


def _fun(expr) -> ca.Function:
    return ca.Function("f", [X], [expr])


def _routh():
    return ca.vertcat(x + y + 2, (x - 1) ** 2 + (y - 1) ** 2 - 1,
                      2 * (x + 3) * (y + 3) - 15)


# name -> (expression, fixed target or None, box region (lo, hi))
CASES = {
    "routh": (_routh(), [[0.0, INF]] * 3, (-3.0, 9.0)),
    "product": (x * y, [[1.0, 2.0]], (-3.0, 3.0)),
    "exp_sq": (ca.exp(x) + y ** 2, [[-INF, 1.0]], (-4.0, 4.0)),
    "sqrt_log": (ca.sqrt(x) + ca.log(y), None, (-2.0, 6.0)),
    "quotient": (x / y, None, (-3.0, 3.0)),
    "monotone": (ca.tanh(x) - ca.sinh(y) + ca.expm1(x * y) - ca.log1p(ca.fabs(y)), None,
                 (-2.0, 2.0)),
    "inverse": (1 / x + x * x - 2 * x * y, None, (-3.0, 3.0)),
    "repeated": (ca.vertcat(x * (1 - x) + y * x, y - 0.5 * x ** 2), None, (-3.0, 3.0)),
    "twice_neg": (ca.vertcat(-(2 * x) + 3, (x - y) / 4), None, (-3.0, 3.0)),
    # undefined operands absorbed by fmin / if_else: not strict, must not be narrowed
    "absorbing": (ca.fmin(ca.sqrt(x), y) + ca.if_else(x > 0, ca.log(x), 0), None,
                  (-3.0, 3.0)),
    "domains": (x ** 2.5 + ca.asin(y / 4) * ca.sqrt(y + 1), None, (-5.0, 5.0)),
}
CONTRACTORS: dict[str, tuple[ca.Function, ca.Function]] = {}


def _functions(name: str) -> tuple[ca.Function, ca.Function]:
    if name not in CONTRACTORS:
        f = _fun(CASES[name][0])
        CONTRACTORS[name] = (f, f.map(N_BOXES * N_POINTS))
    return CONTRACTORS[name]


def _eval(f: ca.Function, pts: np.ndarray) -> np.ndarray:
    return np.array(f(pts.T)).T.reshape(pts.shape[0], -1)


@st.composite
def problems(draw, name: str):
    expr, fixed, (rlo, rhi) = CASES[name]
    f, fmap = _functions(name)
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    scale = draw(st.sampled_from([0.0, 1e-3, 0.05, 0.5, 2.0, 8.0]))
    w = rng.uniform(0.0, 1.0, (N_BOXES, 2)) * scale
    lo = rng.uniform(rlo, rhi, (N_BOXES, 2))
    hi = lo + w
    m = f.numel_out(0)
    if fixed is not None and draw(st.booleans()):
        Y = np.array(fixed, dtype=float)
    else:  # around the value at a point of the first box: that box holds solutions
        c = lo[0] + rng.uniform(0.0, 1.0, 2) * w[0]
        v = _eval(f, c[None])[0]
        v = np.where(np.isfinite(v), v, 0.0)
        radii = [0.0, 1e-3, 0.1, 1.0, INF]
        r1 = np.array([draw(st.sampled_from(radii)) for _ in range(m)])
        r2 = np.array([draw(st.sampled_from(radii)) for _ in range(m)])
        Y = np.stack([v - r1, v + r2], axis=1)
    return f, fmap, Y, lo, hi, rng


def _samples(lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, P, 2) points of each box: its corners, centre and uniform samples."""
    u = rng.uniform(0.0, 1.0, (lo.shape[0], N_POINTS, 2))
    u[:, :5] = [[0, 0], [0, 1], [1, 0], [1, 1], [0.5, 0.5]]
    pts = lo[:, None] + u * (hi - lo)[:, None]
    return np.clip(pts, lo[:, None], hi[:, None])


def _check_sound(f, fmap, Y, lo, hi, rng, n_iter=1):
    C = contractor(f, Y, n_iter=n_iter)
    lo2, hi2, empty = C(lo, hi)
    ok = ~empty
    assert not np.isnan(lo2[ok]).any() and not np.isnan(hi2[ok]).any()
    assert (lo2[ok] >= lo[ok]).all() and (hi2[ok] <= hi[ok]).all()
    assert (lo2[ok] <= hi2[ok]).all()
    pts = _samples(lo, hi, rng)
    vals = _eval(fmap, pts.reshape(-1, 2)).reshape(lo.shape[0], N_POINTS, -1)
    delta = 1e-9 * (1.0 + np.abs(np.where(np.isfinite(Y), Y, 0.0)))
    ylo, yhi = Y[:, 0] + delta[:, 0], Y[:, 1] - delta[:, 1]
    with np.errstate(invalid="ignore"):
        sol = ((vals >= ylo) & (vals <= yhi)).all(axis=2)  # NaN values are no solutions
    for i in range(lo.shape[0]):
        if not sol[i].any():
            continue
        assert not empty[i], f"box {i} declared empty but holds {pts[i][sol[i]][0]}"
        p = pts[i][sol[i]]
        inside = (p >= lo2[i]).all(axis=1) & (p <= hi2[i]).all(axis=1)
        assert inside.all(), (
            f"solution {p[~inside][0]} of box {lo[i]}..{hi[i]} lost; "
            f"contracted to {lo2[i]}..{hi2[i]}")
    return lo2, hi2, empty


@pytest.mark.parametrize("name", sorted(CASES))
@SETTINGS
@given(data=st.data())
def test_sound_by_sampling(name, data):
    f, fmap, Y, lo, hi, rng = data.draw(problems(name))
    _check_sound(f, fmap, Y, lo, hi, rng, n_iter=data.draw(st.sampled_from([1, 4])))


def test_routh_contracts_and_discards():
    f, fmap = _functions("routh")
    rng = np.random.default_rng(1)
    w = rng.uniform(0.05, 1.0, (N_BOXES, 2))
    lo = rng.uniform(-3.0, 9.0 - w)
    hi = lo + w
    lo[0], hi[0] = [-2.0, -2.0], [-1.5, -1.5]  # x + y + 2 < 0 on the whole box
    lo[1], hi[1] = [0.5, -1.5], [1.5, 0.5]  # the circle cuts off the top part
    lo2, hi2, empty = _check_sound(f, fmap, np.array([[0.0, INF]] * 3), lo, hi, rng)
    assert empty[0] and not empty[1]
    assert hi2[1, 1] <= 0.5 - 0.1


# ----------------------------------------------------------------- exact contractions
def _one(expr, Y, lo, hi, **kw):
    C = contractor(_fun(expr), Y, **kw)
    lo2, hi2, empty = C(np.array([lo], dtype=float), np.array([hi], dtype=float))
    return lo2[0], hi2[0], bool(empty[0])


def _close_outward(lo2, hi2, lo_exact, hi_exact, tol=1e-12):
    lo_exact, hi_exact = np.asarray(lo_exact, float), np.asarray(hi_exact, float)
    assert (lo2 <= lo_exact).all() and (hi2 >= hi_exact).all(), (lo2, hi2)
    scale = 1.0 + np.abs(lo_exact) + np.abs(hi_exact)
    assert (lo2 >= lo_exact - tol * scale).all() and (hi2 <= hi_exact + tol * scale).all(), \
        (lo2, hi2)


@pytest.mark.parametrize("expr, Y, lo, hi, lo_exact, hi_exact", [
    (x + y, [[3, 4]], [0, 0], [2, 2], [1, 1], [2, 2]),
    (x - y, [[3, 4]], [0, -2], [5, 5], [1, -2], [5, 2]),
    (x ** 2 + 0 * y, [[4, 9]], [0, 0], [10, 1], [2, 0], [3, 1]),
    (x ** 2 + 0 * y, [[4, 9]], [-10, 0], [10, 1], [-3, 0], [3, 1]),
    (x ** 2 + 0 * y, [[4, 9]], [-10, 0], [1, 1], [-3, 0], [-2, 1]),
    (x * 2 + 0 * y, [[1, 1]], [-5, 0], [5, 1], [0.5, 0], [0.5, 1]),
    (x * y, [[1, 2]], [1, 0], [2, 10], [1, 0.5], [2, 2]),
    (x * y, [[1, 2]], [-INF, 1], [INF, 2], [0.5, 1], [2, 2]),
    (x * y, [[1, 2]], [-5, 0], [5, 2], [0.5, 0.2], [5, 2]),  # extended division
    (x * y, [[-2, -1]], [-5, -1], [5, 0], [1, -1], [5, -0.2]),
    (x * y, [[1, 2]], [-5, -1], [5, 2], [-5, -1], [5, 2]),  # two rays: hull
    (x / y, [[1, 2]], [1, -5], [2, 5], [1, 0.5], [2, 2]),
    (2 / y + 0 * x, [[-2, 1]], [0, -3], [1, 3], [0, -3], [1, 3]),
    (2 / y + 0 * x, [[1, 4]], [0, -3], [1, 3], [0, 0.5], [1, 2]),
    (x / y, [[2, 4]], [1, 0.1], [2, 10], [1, 0.25], [2, 1]),
    (x / y, [[1, 2]], [1, -1], [2, 1], [1, 0.5], [2, 1]),
    (ca.exp(x) + 0 * y, [[1, math.exp(2)]], [-10, 0], [10, 1], [0, 0], [2, 1]),
    (ca.log(x) + 0 * y, [[0, 1]], [-5, 0], [5, 1], [1, 0], [math.e, 1]),
    (ca.sqrt(x) + 0 * y, [[2, 3]], [-10, 0], [100, 1], [4, 0], [9, 1]),
    (ca.fabs(x) + y, [[2, 3]], [-10, 0], [10, 0], [-3, 0], [3, 0]),
    (-x + 0 * y, [[1, 2]], [-5, 0], [5, 1], [-2, 0], [-1, 1]),
    (1 / x + 0 * y, [[2, 4]], [-5, 0], [5, 1], [0.25, 0], [0.5, 1]),
    (ca.vertcat(x + y, x - y), [[2, 2], [0, 0]], [0, 0], [1, 1], [1, 1], [1, 1]),
])
def test_known_contractions(expr, Y, lo, hi, lo_exact, hi_exact):
    lo2, hi2, empty = _one(expr, Y, lo, hi)
    assert not empty
    _close_outward(lo2, hi2, lo_exact, hi_exact)


def test_box_target_and_infinite_bounds():
    C = contractor(_fun(_routh()), cm.Box([0, 0, 0], [INF, INF, INF]))
    lo2, hi2, empty = C(np.array([[-3.0, -3.0]]), np.array([[9.0, 9.0]]))
    assert not empty[0]
    # x + y >= -2 and y <= 9 give x >= -11; 2 (x + 3)(y + 3) >= 15 with y + 3 <= 12 gives
    # x + 3 >= 15 / 24
    _close_outward(lo2[0], hi2[0], [-3 + 15 / 24, -3 + 15 / 24], [9, 9])


def test_iteration_reaches_a_fixpoint():
    # x = y / 2 and y = x / 2: each pass halves the box, the only solution is 0
    f = _fun(ca.vertcat(x - 0.5 * y, y - 0.5 * x))
    C = contractor(f, [[0, 0], [0, 0]])
    lo, hi = np.array([[-1.0, -1.0]]), np.array([[1.0, 1.0]])
    l1, h1, _ = C(lo, hi)
    l2, h2, e2 = C(lo, hi, n_iter=60, rtol=1e-3)
    assert not e2[0]
    assert (h1 - l1).max() >= 0.4
    assert (h2 - l2).max() <= 1e-3 and (l2 <= 0).all() and (h2 >= 0).all()
    C5 = contractor(f, [[0, 0], [0, 0]], n_iter=5)
    l5, h5, _ = C5(lo, hi)
    assert (h5 - l5).max() < (h1 - l1).max() / 8


# --------------------------------------------------------------------------- emptiness
@pytest.mark.parametrize("expr, Y, lo, hi", [
    (x ** 2 + 0 * y, [[-2, -1]], [-3, 0], [3, 1]),
    (x + y, [[10, 11]], [0, 0], [1, 1]),
    (x * y, [[5, 6]], [0, 0], [2, 2]),
    (x * y, [[1, 2]], [-5, 0], [5, 0]),
    (1 / x + 0 * y, [[-1, 1]], [-0.5, 0], [0.5, 1]),
    (3 / x + 0 * y, [[-1, 1]], [-0.5, 0], [0.5, 1]),
    (ca.exp(x) + y, [[-INF, -3]], [-10, -1], [10, 1]),
    (ca.sqrt(x) + y, [[-INF, INF]], [-2, 0], [-1, 1]),  # undefined on the whole box
    (ca.log(x) * y, [[-INF, INF]], [-2, 0], [0, 1]),
    (ca.vertcat(x, y, x + y), [[0, 1], [0, 1], [2.5, 3]], [-5, -5], [5, 5]),
    # a shared node narrowed to nothing by its two parents; its projections are not empty
    (ca.vertcat(XY, XY - 4), [[1, 2], [1, 2]], [1, 1], [10, 10]),
    (ca.vertcat(SIN_X, SIN_X - 0.5), [[0, 0.1], [0, 1]], [-3, 0], [3, 1]),
])
def test_proven_empty(expr, Y, lo, hi):
    assert _one(expr, Y, lo, hi)[2]


@pytest.mark.parametrize("expr, Y", [
    (ca.fmin(ca.sqrt(x), 1) + 0 * y, [[1, 1]]),  # fmin(nan, 1) = 1
    (ca.if_else(x >= 0, ca.sqrt(x), 0) + 0 * y, [[0, 0]]),
    (ca.power(ca.log(x), y), [[1, 1]]),  # pow(nan, 0) = 1
])
def test_absorbed_undefined_values_are_solutions(expr, Y):
    lo, hi = [-2.0, 0.0], [-1.0, 0.0]
    f = _fun(expr)
    assert float(f([-1.5, 0.0])) == Y[0][0]  # a solution where the inner node is undefined
    lo2, hi2, empty = _one(expr, Y, lo, hi)
    assert not empty
    assert lo2[0] <= -1.5 <= hi2[0]


def test_structural_zero_output():
    f = ca.Function("f", [X], [ca.vertcat(x + y, ca.SX(1, 1))])
    assert f.sparsity_out(0).nnz() == 1
    lo, hi = np.array([[0.0, 0.0]]), np.array([[1.0, 1.0]])
    assert contractor(f, [[0, 1], [1, 2]])(lo, hi)[2][0]
    lo2, hi2, empty = contractor(f, [[0, 0.5], [-1, 1]])(lo, hi)
    assert not empty[0]
    _close_outward(lo2[0], hi2[0], [0, 0], [0.5, 0.5])


def test_rows_with_no_real_point_are_empty():
    C = contractor(_fun(x + y), [[-INF, INF]])
    lo2, hi2, empty = C(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0], [INF, 0.0]]),
                        np.array([[1.0, 1.0], [0.0, 1.0], [1.0, 1.0], [INF, 1.0]]))
    assert empty.tolist() == [False, True, False, True]
    assert (lo2[[0, 2]] == 0).all() and (hi2[[0, 2]] == 1).all()
    # iterated passes on the remaining rows only
    C = contractor(_fun(ca.vertcat(x - 0.5 * y, y - 0.5 * x)), [[0, 0], [0, 0]])
    lo2, hi2, empty = C(np.array([[-1.0, -1.0], [1.0, 0.0], [-2.0, -1.0]]),
                        np.array([[1.0, 1.0], [0.0, 1.0], [2.0, 1.0]]), n_iter=80, rtol=0.0)
    assert empty.tolist() == [False, True, False]
    assert (hi2[[0, 2]] - lo2[[0, 2]]).max() <= 1e-6


def test_large_batch_in_chunks_matches_single_rows():
    f = _fun(_routh())
    C = contractor(f, [[0, INF]] * 3)
    C.chunk = 7
    rng = np.random.default_rng(5)
    w = rng.uniform(0.05, 1.0, (40, 2))
    lo = rng.uniform(-3.0, 9.0 - w)
    l_all, h_all, e_all = C(lo, lo + w)
    for i in range(0, 40, 9):
        l1, h1, e1 = C(lo[i:i + 1], lo[i:i + 1] + w[i:i + 1])
        assert e1[0] == e_all[i]
        if not e1[0]:
            assert (l1[0] == l_all[i]).all() and (h1[0] == h_all[i]).all()


# ------------------------------------------------------------------------ NaN handling
def test_partly_undefined_sqrt():
    lo2, hi2, empty = _one(ca.sqrt(x) + 0 * y, [[0.5, 1.0]], [-1, 0], [1, 0])
    assert not empty
    _close_outward(lo2, hi2, [0.25, 0], [1, 0])


def test_no_nan_from_unbounded_quotients():
    C = contractor(_fun(ca.vertcat(x / y, x * y)), [[-INF, INF], [0, 1]])
    lo2, hi2, empty = C(np.array([[-INF, -1.0], [0.0, 0.0]]),
                        np.array([[INF, 1.0], [INF, INF]]))
    assert not empty.any()
    assert not np.isnan(lo2).any() and not np.isnan(hi2).any()


# ---------------------------------------------------------------------------- refusals
def test_refusals():
    f = _fun(ca.vertcat(x + y, x * y))
    with pytest.raises(DimensionError, match=r"expected \(2, 2\)"):
        contractor(f, [[0, 1]])
    with pytest.raises(DimensionError):
        contractor(f, cm.Box([0, 0, 0], [1, 1, 1]))
    with pytest.raises(DimensionError, match="one input and one output"):
        contractor(ca.Function("g", [x, y], [x + y]), [[0, 1]])
    with pytest.raises(InvalidBoundsError):
        contractor(f, [[0, np.nan], [0, 1]])
    with pytest.raises(EmptySetError):
        contractor(f, [[1, 0], [0, 1]])
    with pytest.raises(ValueError, match="n_iter"):
        contractor(f, [[0, 1], [0, 1]], n_iter=0)
    C = contractor(f, [[0, 1], [0, 1]])
    assert isinstance(C, Contractor) and (C.n, C.m) == (2, 2)
    with pytest.raises(DimensionError, match="same shape"):
        C(np.zeros((3, 2)), np.ones((2, 2)))
    with pytest.raises(DimensionError, match=r"shape \(N, 2\)"):
        C(np.zeros((3, 3)), np.ones((3, 3)))
    with pytest.raises(DimensionError):
        C(np.zeros(2), np.ones(2))
    with pytest.raises(InvalidBoundsError):
        C(np.array([[0.0, np.nan]]), np.ones((1, 2)))


def test_mx_function_is_expanded():
    z = ca.MX.sym("z", 2)
    f = ca.Function("g", [z], [z[0] + z[1]])
    lo2, hi2, empty = contractor(f, [[3, 4]])(np.zeros((1, 2)), np.full((1, 2), 2.0))
    assert not empty[0]
    _close_outward(lo2[0], hi2[0], [1, 1], [2, 2])


def test_operation_without_interval_extension_gives_no_information():
    f = _fun(x.printme(0) + y)  # OP_PRINTME: unknown to the interval arithmetic
    lo2, hi2, empty = contractor(f, [[3, 4]])(np.zeros((1, 2)), np.full((1, 2), 2.0))
    assert not empty[0]
    assert (lo2 == 0).all() and (hi2 == 2).all()
