"""Constrained minimax (thesis Alg 5.3): the certified bracket contains the known value."""

from __future__ import annotations

from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.exceptions import CmpcWarning, DimensionError
from casadi_cmpc.solvers.engine import Status
from casadi_cmpc.solvers.minimax import MinimaxResult, minimax

u, w = ca.SX.sym("u"), ca.SX.sym("w")
U1 = cm.Box([-1], [1])
SQ = ca.Function("sq", [u, w], [(u - w) ** 2])


def check_point(f, g, r, W, k=201):
    """The returned u: max_w f(u, w) <= upper on a grid of W, and the constraints hold."""
    ws = np.linspace(W[0], W[1], k)
    us = np.repeat(r.u[None], k, axis=0)
    fv = np.asarray(f.map(k)(us.T, ws[None])).ravel()
    assert fv.max() <= r.upper + 1e-12
    if g is not None:
        gv = np.asarray(g.map(k)(us.T, ws[None]))
        assert (gv <= 1e-12).all()


def test_saddle_value_of_the_square():
    # min_u max_{|w| <= 1/2} (u - w)^2 = 1/4 at u = 0
    r = minimax(SQ, U1, cm.Box([-0.5], [0.5]), 1e-3, progress=False)
    assert isinstance(r, MinimaxResult)
    assert r.status == Status.PROVED and r.success
    assert r.lower <= 0.25 <= r.upper and r.width < 1e-3
    assert r.u_feasible and abs(r.u[0]) < 1e-2 and r.fun == r.upper
    assert abs(abs(r.w[0]) - 0.5) < 1e-12  # a worst case is an end of W
    assert r.candidates.shape[1:] == (1, 2)
    assert any(B[0, 0] <= 0 <= B[0, 1] for B in r.candidates)
    check_point(SQ, None, r, (-0.5, 0.5))
    assert "certified" in r.message and "PROVED" in repr(r)


def test_bilinear():
    # (u - 0.3) w + 0.5 u on [-1, 1]^2: max_w = |u - 0.3| + 0.5 u, minimum 0.15 at u = 0.3
    f = ca.Function("bil", [u, w], [(u - 0.3) * w + 0.5 * u])
    r = minimax(f, U1, cm.Box([-1], [1]), 1e-4, progress=False)
    assert r.lower <= 0.15 <= r.upper and r.width < 1e-3
    assert abs(r.u[0] - 0.3) < 1e-2
    check_point(f, None, r, (-1, 1))


def test_interior_worst_case():
    # f = u^2 - (w - 0.3 u)^2 + 0.1 w: the max over w is interior, w = 0.3 u + 0.05;
    # max_w f = u^2 + 0.03 u + 0.0025, minimum 0.002275 at u = -0.015
    f = ca.Function("conc", [u, w], [u ** 2 - (w - 0.3 * u) ** 2 + 0.1 * w])
    r = minimax(f, U1, cm.Box([-1], [1]), 1e-3, progress=False)
    assert r.lower <= 0.002275 <= r.upper and r.width < 2e-3
    r2 = minimax(f, U1, cm.Box([-1], [1]), 1e-3, options={"w_depth": 6}, progress=False)
    assert r2.lower <= 0.002275 <= r2.upper and r2.width <= r.width


def test_constraint_for_all_w():
    # g = 0.2 + w - u <= 0 for all |w| <= 1/2  <=>  u >= 0.7; then (0.7 + 0.5)^2 = 1.44
    g = ca.Function("g", [u, w], [0.2 + w - u])
    r = minimax(SQ, U1, cm.Box([-0.5], [0.5]), 1e-4, constraints=g, progress=False)
    assert r.status == Status.PROVED
    assert r.lower <= 1.44 <= r.upper and r.width < 1e-3
    assert r.u[0] >= 0.7
    check_point(SQ, g, r, (-0.5, 0.5))


def test_infeasible_constraints():
    g = ca.Function("g", [u, w], [0.7 + w - u])  # needs u >= 1.2 > 1
    r = minimax(SQ, U1, cm.Box([-0.5], [0.5]), 1e-3, constraints=g, progress=False)
    assert r.status == Status.DISPROVED and not r.success
    assert r.u is None and r.lower == r.upper == np.inf
    assert "infeasible" in r.message


def test_two_dimensional():
    # sum_i (u_i - w_i)^2 on U = [-1, 1]^2, W = [-1/2, 1/2]^2: value 1/2 at u = 0
    U2, W2 = ca.SX.sym("u", 2), ca.SX.sym("w", 2)
    f = ca.Function("sq2", [U2, W2], [ca.sumsqr(U2 - W2)])
    r = minimax(f, cm.Box([-1, -1], [1, 1]), cm.Box([-0.5, -0.5], [0.5, 0.5]), 1e-3,
                progress=False)
    assert r.lower <= 0.5 <= r.upper and r.width < 1e-2
    assert np.abs(r.u).max() < 2e-2 and r.w.shape == (2,)


def _phi_min(a, b, c, d):
    """min over u in [-1, 1] of d u^2 + b u + |a u + c| (exact, fractions): the minimiser is an
    end point, the kink, or the vertex of one of the two quadratic pieces."""
    a, b, c, d = (Fraction(v) for v in (a, b, c, d))
    cands = [Fraction(-1), Fraction(1)]
    if a != 0:
        cands.append(-c / a)
    if d != 0:
        cands += [-(b + a) / (2 * d), -(b - a) / (2 * d)]
    cands = [t for t in cands if -1 <= t <= 1]
    return min(d * t * t + b * t + abs(a * t + c) for t in cands)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.floats(-2, 2), st.floats(-2, 2), st.floats(-2, 2), st.floats(0, 2))
def test_random_bilinear_quadratic(a, b, c, d):
    # f = a u w + b u + c w + d u^2 on [-1, 1]^2: max_w f = d u^2 + b u + |a u + c|
    f = ca.Function("f", [u, w], [a * u * w + b * u + c * w + d * u ** 2])
    r = minimax(f, U1, cm.Box([-1], [1]), 1e-3, progress=False)
    exact = _phi_min(a, b, c, d)
    assert Fraction(r.lower) <= exact <= Fraction(r.upper)
    assert r.width < 2e-2


def test_budget_stop_keeps_the_bracket():
    f = ca.Function("conc", [u, w], [u ** 2 - (w - 0.3 * u) ** 2 + 0.1 * w])
    r = minimax(f, U1, cm.Box([-1], [1]), 1e-9, max_boxes=40, progress=False)
    assert r.status == Status.BUDGET
    assert r.lower <= 0.002275 <= r.upper


def test_errors_and_warnings():
    W = cm.Box([-0.5], [0.5])
    with pytest.raises(ValueError, match="Unknown method"):
        minimax(SQ, U1, W, 0.1, method="grid")
    with pytest.raises(DimensionError, match="dimension"):
        minimax(SQ, cm.Box([-1, -1], [1, 1]), W, 0.1)
    with pytest.raises(DimensionError, match="scalar"):
        minimax(ca.Function("v", [u, w], [ca.vertcat(u, w)]), U1, W, 0.1)
    with pytest.raises(DimensionError, match=r"\(u, w\)"):
        minimax(ca.Function("h", [u], [u]), U1, W, 0.1)
    with pytest.raises(TypeError, match="casadi.Function"):
        minimax(lambda a, b: a, U1, W, 0.1)
    with pytest.raises(cm.UnboundedSetError, match="W"):
        minimax(SQ, U1, cm.Box([-np.inf], [0]), 0.1)
    with pytest.raises(ValueError, match="eps"):
        minimax(SQ, U1, W, -1.0)
    with pytest.warns(CmpcWarning, match="unknown options"):
        minimax(SQ, U1, W, 0.1, options={"cells": 3}, progress=False)

