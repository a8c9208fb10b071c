"""Quantified set inversion ``{x : ∀w ∈ W ∃u ∈ U : f(x, u, w) ∈ Y}`` (Alg 5.1, 5.2).

Soundness is checked against sets known in closed form: every inner box must lie inside the
exact set and every excluded box outside it (exactly, with fractions, at the corners of the
boxes — the exact sets here are convex — and at sampled points). A nonlinear example is
checked by sampling: points of inner boxes have a valid u for every sampled w; points of
excluded boxes have a sampled w for which no sampled u works.
"""

from __future__ import annotations

import itertools
import warnings
from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.exceptions import CmpcWarning, DimensionError, UnsupportedOperationError
from casadi_cmpc.solvers.engine import Status
from casadi_cmpc.solvers.quantified import quantified_sivia

x1, u1, w1 = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("w")
SUM = ca.Function("sum3", [x1, u1, w1], [x1 + u1 + w1])


def Fr(v) -> Fraction:
    return Fraction(float(v))


# ================================================================== 1-D: x + u + w
def exact_sum_set(a, b, U, W):
    """∀w ∃u: x + u + w ∈ [a, b]  <=>  x ∈ [a - w1 - u2, b - w2 - u1] (possibly empty)."""
    return (Fr(a) - Fr(W[0]) - Fr(U[1]), Fr(b) - Fr(W[1]) - Fr(U[0]))


def check_1d(P, lo, hi):
    for B in P.inner:
        assert Fr(B[0, 0]) >= lo and Fr(B[0, 1]) <= hi
    for B in P.outside:
        assert Fr(B[0, 1]) < lo or Fr(B[0, 0]) > hi


interval = st.tuples(st.floats(-2, 2), st.floats(0, 2)).map(lambda t: (t[0], t[0] + t[1]))


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(interval, interval, interval, st.sampled_from(["alg5.1", "alg5.2"]))
def test_sum_exact_interval(Yab, U, W, method):
    a, b = Yab
    lo, hi = exact_sum_set(a, b, U, W)
    eps = 0.02
    P = quantified_sivia(SUM, cm.Box([-8], [8]), cm.Box([U[0]], [U[1]]),
                         cm.Box([W[0]], [W[1]]), cm.Box([a], [b]), eps, method=method,
                         progress=False)
    assert P.status == Status.PROVED
    check_1d(P, lo, hi)
    # near-complete: only boxes within eps of the two ends stay undecided
    for B in P.boundary:
        near = min(abs(Fr(B[0, 0]) - lo), abs(Fr(B[0, 1]) - hi), abs(Fr(B[0, 0]) - hi),
                   abs(Fr(B[0, 1]) - lo))
        assert near <= 2 * eps
    if hi - lo > 4 * eps:
        assert P.volume(view="inner") >= float(hi - lo) - 4 * eps


def test_alg51_and_alg52_agree_in_1d():
    args = (SUM, cm.Box([-5], [5]), cm.Box([-1], [0.5]), cm.Box([-0.25], [0.75]),
            cm.Box([-1], [2]))
    P1 = quantified_sivia(*args, 0.01, method="alg5.1", progress=False)
    P2 = quantified_sivia(*args, 0.01, method="alg5.2", progress=False)
    lo, hi = exact_sum_set(-1, 2, (-1, 0.5), (-0.25, 0.75))
    check_1d(P1, lo, hi)
    check_1d(P2, lo, hi)
    assert P1.method == "alg5.1" and P2.method == "alg5.2"
    # no point proven inside by one and outside by the other, and the same inner set
    xs = np.linspace(-5, 5, 4001)
    assert not (P1.contains(xs[:, None], view="inner")
                & P2.contains(xs[:, None], view="outside")).any()
    assert not (P2.contains(xs[:, None], view="inner")
                & P1.contains(xs[:, None], view="outside")).any()
    assert abs(P1.volume(view="inner") - P2.volume(view="inner")) <= 0.02


def test_nested_u_bisection_proves_more_than_alg51():
    # ∀x ∃u ∈ [-1, 1]: x + u^2 ∈ [0, 1]  <=>  x ∈ [-1, 1] (no w). f is not monotone in u
    # on U: Alg 5.1 (whole U) proves only x ∈ [0, 1]; Alg 5.2 bisects U and proves [-1, 1].
    x, u = ca.SX.sym("x"), ca.SX.sym("u")
    f = ca.Function("f", [x, u], [x + u ** 2])
    args = (f, cm.Box([-3], [3]), cm.Box([-1], [1]), None, cm.Box([0], [1]))
    P1 = quantified_sivia(*args, 0.01, method="alg5.1", progress=False)
    P2 = quantified_sivia(*args, 0.01, progress=False)
    for P in (P1, P2):
        check_1d(P, Fraction(-1), Fraction(1))
    assert P2.volume(view="inner") >= 1.9
    assert 0.9 <= P1.volume(view="inner") <= 1.05


# ================================================================== 2-D: coupled u
X2 = ca.SX.sym("x", 2)
COUPLED = ca.Function("coupled", [X2, u1, w1], [ca.vertcat(X2[0] + u1 + w1, X2[1] - u1)])


def in_coupled_set(p):
    """∀w ∈ [-0.2, 0.2] ∃u ∈ [-1, 1]: x1 + u + w ∈ [-1, 1] and x2 - u ∈ [-1, 1]  <=>
    |x1| <= 1.8, |x2| <= 2, |x1 + x2| <= 1.8 (the intervals of valid u meet pairwise)."""
    a, b = Fr(p[0]), Fr(p[1])
    lim = Fraction(18, 10)
    return abs(a) <= lim and abs(b) <= 2 and abs(a + b) <= lim


@pytest.fixture(scope="module")
def coupled_paving():
    return quantified_sivia(COUPLED, cm.Box([-3, -3], [3, 3]), cm.Box([-1], [1]),
                            cm.Box([-0.2], [0.2]), cm.Box([-1, -1], [1, 1]), 0.05,
                            progress=False)


def test_coupled_2d_inner_and_outer_are_sound(coupled_paving):
    P = coupled_paving
    assert P.status == Status.PROVED and P.method == "alg5.2"
    # the exact set is convex: an inner box is inside iff its four corners are
    for B in P.inner:
        for c in itertools.product(*B):
            assert in_coupled_set(c)
    # excluded boxes: sampled points (and corners) outside
    rng = np.random.default_rng(0)
    for B in P.outside:
        pts = list(itertools.product(*B)) + list(rng.uniform(B[:, 0], B[:, 1], (8, 2)))
        assert not any(in_coupled_set(p) for p in pts)


def test_coupled_2d_is_nearly_complete(coupled_paving):
    P = coupled_paving
    # exact area: the square [-1.8, 1.8] x [-2, 2] cut by |x1 + x2| <= 1.8
    g = np.linspace(-3, 3, 1201)
    xx, yy = np.meshgrid(g, g)
    exact = ((np.abs(xx) <= 1.8) & (np.abs(yy) <= 2) & (np.abs(xx + yy) <= 1.8)).mean() * 36
    assert P.volume(view="inner") <= exact + 0.05
    assert P.volume(view="inner") >= exact - 1.0
    # the coupling (|x1 + x2| > 1.8) is excluded through shared witnesses of w
    assert P.contains(np.array([[1.5, 1.5], [-1.5, -1.5]]), view="outside").all()


def test_witnesses_off_is_sound_but_excludes_less(coupled_paving):
    P = quantified_sivia(COUPLED, cm.Box([-3, -3], [3, 3]), cm.Box([-1], [1]),
                         cm.Box([-0.2], [0.2]), cm.Box([-1, -1], [1, 1]), 0.1,
                         options={"witnesses": False}, progress=False)
    for B in P.inner:
        assert all(in_coupled_set(c) for c in itertools.product(*B))
    for B in P.outside:
        assert not any(in_coupled_set(c) for c in itertools.product(*B))
    # points (1.5, 1.5): every single component can be met, only their coupling fails
    assert not P.contains(np.array([[1.5, 1.5]]), view="outside")[0]


# ========================================================== nonlinear, by sampling
def test_cannon_robust_one_step_set_by_sampling():
    x = ca.SX.sym("x", 2)
    u, mu = ca.SX.sym("u"), ca.SX.sym("mu")
    fx = ca.vertcat(x[0] + 0.1 * x[1] + 0.1 * (mu + (1 - mu) * x[0]) * u,
                    0.1 * x[0] + x[1] + 0.1 * (mu - 4 * (1 - mu) * x[1]) * u)
    f = ca.Function("cannon", [x, u, mu], [fx])
    P = quantified_sivia(f, cm.Box([-2, -2], [2, 2]), cm.Box([-2], [2]),
                         cm.Box([0.85], [0.95]), cm.Box([-0.5, -0.5], [0.5, 0.5]), 0.1,
                         progress=False)
    assert len(P.inner) > 10 and len(P.outside) > 10
    rng = np.random.default_rng(3)
    us = np.linspace(-2, 2, 4001)
    F = f.map(us.size)

    def some_u(xp, w):
        y = np.asarray(F(np.repeat(xp[:, None], us.size, 1), us[None],
                         np.full((1, us.size), w)))
        return bool((np.abs(y) <= 0.5).all(axis=0).any())

    for B in P.inner[rng.choice(len(P.inner), 25, replace=False)]:
        xp = rng.uniform(B[:, 0], B[:, 1])
        assert all(some_u(xp, w) for w in (0.85, 0.9, 0.95, rng.uniform(0.85, 0.95)))
    for B in P.outside[rng.choice(len(P.outside), 25, replace=False)]:
        xp = rng.uniform(B[:, 0], B[:, 1])
        assert not all(some_u(xp, w) for w in np.linspace(0.85, 0.95, 11))


# ======================================================================== contract
def test_budget_stop_is_sound():
    P = quantified_sivia(COUPLED, cm.Box([-3, -3], [3, 3]), cm.Box([-1], [1]),
                         cm.Box([-0.2], [0.2]), cm.Box([-1, -1], [1, 1]), 0.01,
                         max_boxes=200, progress=False)
    assert P.status == Status.BUDGET
    for B in P.inner:
        assert all(in_coupled_set(c) for c in itertools.product(*B))


def test_infinite_target_bounds():
    # ∀w ∃u: x + u + w >= 0, u ∈ [-1, 1], w ∈ [-0.5, 0.5]  <=>  x >= -0.5
    P = quantified_sivia(SUM, cm.Box([-3], [3]), cm.Box([-1], [1]), cm.Box([-0.5], [0.5]),
                         cm.Box([0], [np.inf]), 0.01, progress=False)
    check_1d(P, Fraction(-1, 2), Fraction(10 ** 9))
    assert P.volume(view="inner") >= 3.5 - 0.03


def test_errors_and_warnings():
    box = cm.Box([-1], [1])
    with pytest.raises(ValueError, match="Unknown method"):
        quantified_sivia(SUM, box, box, box, box, 0.1, method="newton")
    with pytest.raises(ValueError, match="1-dimensional"):
        quantified_sivia(COUPLED, cm.Box([-1, -1], [1, 1]), box, box,
                         cm.Box([-1, -1], [1, 1]), 0.1, method="alg5.1")
    with pytest.raises(DimensionError, match="3 inputs"):
        quantified_sivia(SUM, box, box, None, box, 0.1)
    with pytest.raises(DimensionError, match="dimension 2"):
        quantified_sivia(SUM, box, box, box, cm.Box([-1, -1], [1, 1]), 0.1)
    with pytest.raises(DimensionError, match="X0"):
        quantified_sivia(SUM, cm.Box([-1, -1], [1, 1]), box, box, box, 0.1)
    with pytest.raises(TypeError, match="Box"):
        quantified_sivia(SUM, box, box, box, np.array([[-1.0, 1.0]]), 0.1)
    with pytest.raises(cm.UnboundedSetError, match="U"):
        quantified_sivia(SUM, box, cm.Box([-np.inf], [1]), box, box, 0.1)
    with pytest.raises(ValueError, match="eps"):
        quantified_sivia(SUM, box, box, box, box, 0.0)
    with pytest.raises(UnsupportedOperationError, match="jump"):
        g = ca.Function("g", [x1, u1, w1], [ca.floor(x1) + u1 + w1])
        quantified_sivia(g, box, box, box, box, 0.1)
    with pytest.warns(CmpcWarning, match="unknown options"):
        quantified_sivia(SUM, box, box, box, box, 0.5, options={"depth": 3}, progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        quantified_sivia(SUM, box, box, box, box, 0.5, options={"u_depth": 2},
                         progress=False)



# ====================================================== coupled outputs, any magnitudes
def _coupled_oracle(p, a, b, r, t):
    """∀w ∈ [-r, r] ∃u ∈ [-1, 1]: x1 + a u + w ∈ [-1, 1] and x2 - b u ∈ [t - 1, t + 1]
    (a, b > 0), decided exactly: the u-intervals of the three constraints meet for every w
    iff they meet at w = ±r (max of the lower ends minus min of the upper ends is convex
    in w)."""
    x, y = Fr(p[0]), Fr(p[1])
    a, b, r, t = Fr(a), Fr(b), Fr(r), Fr(t)
    for w in (-r, r):
        lo = max((-1 - x - w) / a, (y - t - 1) / b, Fraction(-1))
        hi = min((1 - x - w) / a, (y - t + 1) / b, Fraction(1))
        if lo > hi:
            return False
    return True


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(a=st.floats(0.3, 3), b=st.floats(0.3, 3), r=st.floats(0, 0.6), t=st.floats(-2, 2),
       witnesses=st.booleans())
def test_coupled_outputs_sound_for_all_w_exists_u(a, b, r, t, witnesses):
    """The class of the shared-witness exclusion: an x-box is outside only through a point
    of W at which every U-cell fails; inner boxes hold for every w with some u."""
    f = ca.Function("cp", [X2, u1, w1], [ca.vertcat(X2[0] + a * u1 + w1, X2[1] - b * u1)])
    D = cm.Box([-4, t - 4], [4, t + 4])
    P = quantified_sivia(f, D, cm.Box([-1], [1]), cm.Box([-r], [r]),
                         cm.Box([-1, t - 1], [1, t + 1]), 0.25, relative=False,
                         options={"witnesses": witnesses}, progress=False)
    for B in P.inner:  # the exact set is convex: corners suffice
        assert all(_coupled_oracle(c, a, b, r, t) for c in itertools.product(*B))
    rng = np.random.default_rng(0)
    for B in P.outside[: 60]:
        pts = list(itertools.product(*B)) + list(rng.uniform(B[:, 0], B[:, 1], (4, 2)))
        assert not any(_coupled_oracle(p, a, b, r, t) for p in pts)
