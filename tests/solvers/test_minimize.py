"""Interval global minimisation (``casadi_cmpc/solvers/minimize.py``, thesis Alg 4.2)."""

from __future__ import annotations

import dataclasses
import itertools

import casadi as ca
import numpy as np
import pytest
import scipy.optimize as so
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from casadi_cmpc.exceptions import DimensionError, UnboundedSetError
from casadi_cmpc.solvers.engine import Status
from casadi_cmpc.solvers.minimize import MinimizeResult, minimize

Z = ca.SX.sym("z", 2)
BOX2 = np.array([[-2.0, 2.0], [-2.0, 2.0]])


def _e3_residuals(z):
    x, y = z[0], z[1]
    return ca.vertcat(x - ca.sin(2 * x + 3 * y) - ca.cos(3 * x - 5 * y),
                      y - ca.sin(x - 2 * y) + ca.cos(x + 3 * y))


E3 = ca.Function("e3", [Z], [ca.sumsqr(_e3_residuals(Z))])
E3_RES = ca.Function("e3_res", [Z], [_e3_residuals(Z)])
E3_APPROX = [(-0.1733, -0.2561), (0.7927, 0.1381), (0.8388, 0.5371)]


@pytest.fixture(scope="module")
def e3_minimisers():
    """The three global minimisers of E3 (f = 0), refined from the thesis' approximations."""
    pts = []
    for p0 in E3_APPROX:
        sol = so.root(lambda p: np.asarray(E3_RES(p)).ravel(), p0, tol=1e-14)
        assert float(E3(sol.x)) < 1e-24
        assert np.max(np.abs(sol.x - p0)) < 1e-3
        pts.append(sol.x)
    return np.array(pts)


def _covered(boxes, point, tol=1e-9):
    inside = ((boxes[:, :, 0] - tol <= point) & (point <= boxes[:, :, 1] + tol)).all(axis=1)
    return bool(inside.any())


def _check_point(res, f, X0, g=None):
    assert res.x is not None and res.x_feasible
    assert res.x.shape == (X0.shape[0],)
    assert np.all(X0[:, 0] <= res.x) and np.all(res.x <= X0[:, 1])
    assert float(f(res.x)) <= res.upper
    if g is not None:
        assert np.all(np.asarray(g(res.x)) <= 0)


# ------------------------------------------------------------------------------- E3
@pytest.mark.parametrize("local_solver, eps", [("ipopt", 1e-3), (None, 1e-4)])
def test_e3_certified_bracket_is_narrow_and_covers_all_minimisers(local_solver, eps,
                                                                   e3_minimisers):
    res = minimize(E3, BOX2, eps, kind="centered", local_solver=local_solver)
    assert isinstance(res, MinimizeResult)
    assert res.success and res.status == Status.PROVED
    assert res.lower <= 0.0 <= res.upper
    assert res.upper - res.lower < 1e-6
    assert res.fun == res.upper
    _check_point(res, E3, BOX2)
    c = res.candidates
    assert c.ndim == 3 and c.shape[1:] == (2, 2) and c.shape[0] > 0
    assert np.all(c[:, :, 1] - c[:, :, 0] <= eps)
    for p in e3_minimisers:
        assert _covered(c, p), p
    # every candidate lies close to one of the minimisers (the rest was discarded)
    d = np.abs(0.5 * (c[:, None, :, 0] + c[:, None, :, 1]) - e3_minimisers[None]).max(axis=2)
    assert np.all(d.min(axis=1) < 0.05)
    # x is one of the three global minimisers
    assert np.min(np.abs(e3_minimisers - res.x).max(axis=1)) < 10 * eps
    assert res.nit > 0 and res.n_boxes >= res.nit and res.elapsed > 0
    assert (res.n_local > 0) == (local_solver is not None)


def test_e3_at_the_thesis_resolution(e3_minimisers):
    res = minimize(E3, BOX2, 0.2, kind="natural")
    assert res.success and res.lower <= 0.0 <= res.upper
    for p in e3_minimisers:
        assert _covered(res.candidates, p)


# ----------------------------------------------------------------------- constrained
DISK = ca.Function("disk", [Z], [Z[0] ** 2 + Z[1] ** 2 - 1])  # x^2 + y^2 <= 1
LIN = ca.Function("lin", [Z], [Z[0] + Z[1]])
FAR = ca.Function("far", [Z], [(Z[0] - 2) ** 2 + (Z[1] - 1) ** 2])  # minimiser (2, 1) infeasible


@pytest.mark.parametrize("local_solver", ["ipopt", None])
def test_linear_objective_on_the_disk(local_solver):
    res = minimize(LIN, BOX2, 1e-3, constraints=DISK, local_solver=local_solver)
    true = -np.sqrt(2.0)
    assert res.success
    assert res.lower <= true <= res.upper
    assert res.upper - res.lower < 5e-3
    _check_point(res, LIN, BOX2, DISK)
    assert _covered(res.candidates, np.array([true / 2, true / 2]))
    if local_solver == "ipopt":
        assert res.upper - true < 1e-6
        assert np.allclose(res.x, [true / 2, true / 2], atol=1e-6)


@pytest.mark.parametrize("local_solver", ["ipopt", None])
def test_unconstrained_minimiser_infeasible(local_solver):
    X0 = np.array([[-3.0, 3.0], [-3.0, 3.0]])
    res = minimize(FAR, X0, 1e-3, constraints=DISK, local_solver=local_solver)
    true = 6 - 2 * np.sqrt(5.0)  # (distance from (2, 1) to the unit circle)^2
    xstar = np.array([2.0, 1.0]) / np.sqrt(5.0)
    assert res.success
    assert res.lower <= true <= res.upper
    assert res.upper - res.lower < 5e-3
    _check_point(res, FAR, X0, DISK)
    assert _covered(res.candidates, xstar)
    assert not _covered(res.candidates, np.array([2.0, 1.0]), tol=0.0)
    if local_solver == "ipopt":
        assert res.upper - true < 1e-6


def test_vector_constraints_and_natural_form():
    # min (x - 1)^2 + (y - 1)^2  s.t.  x + y <= 1, x >= 0.8  ->  x = 0.8, y = 0.2
    g = ca.Function("g", [Z], [ca.vertcat(Z[0] + Z[1] - 1, 0.8 - Z[0])])
    f = ca.Function("f", [Z], [(Z[0] - 1) ** 2 + (Z[1] - 1) ** 2])
    res = minimize(f, BOX2, 1e-3, constraints=g, kind="natural")
    true = 0.2 ** 2 + 0.8 ** 2
    assert res.success and res.lower <= true <= res.upper
    assert res.upper - true < 1e-6
    _check_point(res, f, BOX2, g)


def test_minimum_on_the_boundary_of_the_box_is_found_by_vertices():
    f = ca.Function("f", [Z], [Z[0] - 2 * Z[1]])
    res = minimize(f, BOX2, 0.5, local_solver=None)
    assert res.success and res.lower <= -6.0 <= res.upper
    assert res.upper == pytest.approx(-6.0, abs=1e-12)
    assert np.allclose(res.x, [-2.0, 2.0])


def test_one_dimensional_mx_function():
    x = ca.MX.sym("x")
    f = ca.Function("f1", [x], [ca.cos(3 * x) + 0.1 * x ** 2])
    res = minimize(f, np.array([[-4.0, 4.0]]), 1e-4)
    grid = np.linspace(-4, 4, 400001)
    true = float(np.min(np.cos(3 * grid) + 0.1 * grid ** 2))
    assert res.success and res.lower <= true + 1e-9 and true - 1e-9 <= res.upper
    assert res.upper - res.lower < 1e-6


# --------------------------------------------------------------- failure outcomes
@pytest.mark.parametrize("g", [
    ca.Function("never", [Z], [Z[0] ** 2 + Z[1] ** 2 + 1]),            # g > 0 everywhere
    ca.Function("split", [Z], [ca.vertcat(1 - Z[0], Z[0] + 1)]),       # x >= 1 and x <= -1
])
def test_infeasible_problem_is_disproved(g):
    res = minimize(FAR, BOX2, 1e-2, constraints=g)
    assert res.status == Status.DISPROVED and not res.success
    assert res.lower == np.inf and res.upper == np.inf and res.fun == np.inf
    assert res.x is None and not res.x_feasible
    assert res.candidates.shape == (0, 2, 2)
    assert "infeasible" in res.message


def test_no_certified_feasible_point_gives_infinite_upper_bound():
    # x^2 + y^2 = 1 written as two inequalities: the feasible set has no interior
    g = ca.Function("circle", [Z], [ca.vertcat(Z[0] ** 2 + Z[1] ** 2 - 1,
                                               1 - Z[0] ** 2 - Z[1] ** 2)])
    res = minimize(LIN, BOX2, 1e-2, constraints=g)
    assert res.status == Status.UNDECIDED and not res.success
    assert res.upper == np.inf and res.fun == np.inf
    assert res.lower <= -np.sqrt(2.0)
    assert "no feasible point could be certified" in res.message
    assert not res.x_feasible and res.x is not None  # IPOPT's solution, as a guess
    assert _covered(res.candidates, np.array([-1.0, -1.0]) / np.sqrt(2.0))


def test_budget_stops_early_with_a_sound_bracket(e3_minimisers):
    res = minimize(E3, BOX2, 1e-6, max_boxes=300, local_solver=None)
    assert res.status == Status.BUDGET and not res.success
    assert "max_boxes" in res.message
    assert res.lower <= 0.0 <= res.upper
    for p in e3_minimisers:
        assert _covered(res.candidates, p)
    res = minimize(E3, BOX2, 1e-6, time_limit=0.0)
    assert res.status == Status.BUDGET and res.lower <= 0.0


def test_undefined_objective_is_reported():
    f = ca.Function("lg", [Z], [ca.log(Z[0]) + Z[1]])
    res = minimize(f, np.array([[0.0, 1.0], [0.0, 1.0]]), 1e-2, local_solver=None)
    assert res.status == Status.NUMERICAL and res.lower == -np.inf
    assert np.isfinite(res.upper)


# ------------------------------------------------------------------------ bad input
def test_bad_input_raises_clear_errors():
    with pytest.raises(TypeError, match="casadi.Function"):
        minimize(lambda z: z, BOX2, 0.1)
    with pytest.raises(DimensionError, match="scalar"):
        minimize(ca.Function("v", [Z], [Z]), BOX2, 0.1)
    with pytest.raises(DimensionError, match="one input"):
        minimize(ca.Function("two", [Z, ca.SX.sym("w")], [Z[0]]), BOX2, 0.1)
    with pytest.raises(DimensionError, match="expected 2 instead of 3"):
        minimize(LIN, np.zeros((3, 2)), 0.1)
    with pytest.raises(DimensionError, match="single box"):
        minimize(LIN, np.stack([BOX2, BOX2]), 0.1)
    with pytest.raises(DimensionError, match="constraints takes an input of 3"):
        minimize(LIN, BOX2, 0.1, ca.Function("g3", [ca.SX.sym("w", 3)], [1]))
    with pytest.raises(TypeError, match="constraints must be"):
        minimize(LIN, BOX2, 0.1, constraints=np.ones(2))
    with pytest.raises(UnboundedSetError, match="bounded"):
        minimize(LIN, np.array([[-np.inf, 1.0], [0.0, 1.0]]), 0.1)
    for eps in (0.0, -1.0, np.nan, np.inf, "a"):
        with pytest.raises(ValueError, match="eps"):
            minimize(LIN, BOX2, eps)
    with pytest.raises(ValueError, match="valid kinds: centered, natural"):
        minimize(LIN, BOX2, 0.1, kind="taylor")
    with pytest.raises(ValueError, match="local_solver"):
        minimize(LIN, BOX2, 0.1, local_solver="snopt")
    with pytest.raises(ValueError, match="max_boxes"):
        minimize(LIN, BOX2, 0.1, max_boxes=0)
    with pytest.raises(TypeError):
        minimize(LIN, BOX2, 0.1, method="ipopt")  # no catch-all keywords


def test_result_is_a_frozen_dataclass():
    res = minimize(LIN, BOX2, 0.1, kind="NATURAL", local_solver="IPOPT")
    assert dataclasses.is_dataclass(res)
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.upper = 0.0
    assert res.success == (res.status == Status.PROVED)
    assert res.method == "natural+ipopt"
    assert res.width == res.upper - res.lower
    assert "PROVED" in repr(res) and "certified" in res.message


# ----------------------------------------------------------- random quadratics
def _box_qp_minimum(Q, c, lo, hi):
    """Exact minimum of 0.5 x'Qx + c'x (Q positive definite) over [lo, hi]: the minimiser is
    the unconstrained minimiser on the face that holds it; enumerate all 3^n faces."""
    n = len(c)
    best = np.inf
    for face in itertools.product((0, 1, 2), repeat=n):  # 0: at lo, 1: at hi, 2: free
        x = np.where(np.array(face) == 0, lo, hi).astype(float)
        free = np.array(face) == 2
        if free.any():
            fixed = ~free
            rhs = -(c[free] + Q[np.ix_(free, fixed)] @ x[fixed])
            x[free] = np.linalg.solve(Q[np.ix_(free, free)], rhs)
            if np.any(x < lo - 1e-12) or np.any(x > hi + 1e-12):
                continue
            x = np.clip(x, lo, hi)
        best = min(best, 0.5 * x @ Q @ x + c @ x)
    return best


@st.composite
def quadratics(draw):
    n = draw(st.integers(1, 3))
    floats = st.floats(-2, 2, allow_nan=False)
    A = np.array(draw(st.lists(floats, min_size=n * n, max_size=n * n))).reshape(n, n)
    Q = A @ A.T + 0.1 * np.eye(n)
    c = np.array(draw(st.lists(st.floats(-3, 3), min_size=n, max_size=n)))
    lo = np.array(draw(st.lists(st.floats(-2, 1), min_size=n, max_size=n)))
    width = np.array(draw(st.lists(st.floats(0.1, 2), min_size=n, max_size=n)))
    return Q, c, lo, lo + width


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(quadratics(), st.sampled_from([0.05, 0.005]), st.sampled_from(["centered", "natural"]),
       st.sampled_from(["ipopt", None]))
def test_bracket_is_sound_on_random_quadratics(qp, eps, kind, local_solver):
    Q, c, lo, hi = qp
    n = len(c)
    x = ca.SX.sym("x", n)
    f = ca.Function("q", [x], [0.5 * ca.bilin(ca.DM(Q), x, x) + ca.dot(ca.DM(c), x)])
    X0 = np.stack([lo, hi], axis=1)
    res = minimize(f, X0, eps, kind=kind, local_solver=local_solver, max_boxes=200_000)
    true = _box_qp_minimum(Q, c, lo, hi)
    tol = 1e-9 * (1 + abs(true))
    assert res.lower <= true + tol
    assert true - tol <= res.upper
    assert res.status in (Status.PROVED, Status.BUDGET)
    _check_point(res, f, X0)


def _box_qp_minimum_with_cut(Q, c, lo, hi, a, b):
    """Exact minimum of 0.5 x'Qx + c'x over {x in [lo, hi] : a'x <= b} (Q positive definite):
    enumerate the faces of the box, with the cut active or not, and keep the feasible
    stationary points."""
    n = len(c)
    best = np.inf
    for face in itertools.product((0, 1, 2), repeat=n):
        base = np.where(np.array(face) == 0, lo, hi).astype(float)
        free = np.array(face) == 2
        fixed = ~free
        for active in (False, True):
            x = base.copy()
            k = int(free.sum())
            if k:
                rhs = -(c[free] + Q[np.ix_(free, fixed)] @ x[fixed])
                if active:
                    aF = a[free]
                    if np.max(np.abs(aF)) < 1e-9:
                        continue
                    K = np.block([[Q[np.ix_(free, free)], aF[:, None]],
                                  [aF[None], np.zeros((1, 1))]])
                    sol = np.linalg.solve(K, np.append(rhs, b - a[fixed] @ x[fixed]))
                    x[free] = sol[:k]
                else:
                    x[free] = np.linalg.solve(Q[np.ix_(free, free)], rhs)
            elif active:
                continue
            if np.any(x < lo - 1e-12) or np.any(x > hi + 1e-12) or a @ x > b + 1e-12:
                continue
            best = min(best, 0.5 * x @ Q @ x + c @ x)
    return best


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(quadratics(), st.data())
def test_bracket_is_sound_on_random_quadratics_with_a_linear_cut(qp, data):
    Q, c, lo, hi = qp
    n = len(c)
    a = np.array(data.draw(st.lists(st.floats(-1, 1), min_size=n, max_size=n)))
    t = np.array(data.draw(st.lists(st.floats(0, 1), min_size=n, max_size=n)))
    b = float(a @ (lo + t * (hi - lo)) + data.draw(st.floats(0.05, 1)))  # feasible interior
    local_solver = data.draw(st.sampled_from(["ipopt", None]))
    x = ca.SX.sym("x", n)
    f = ca.Function("q", [x], [0.5 * ca.bilin(ca.DM(Q), x, x) + ca.dot(ca.DM(c), x)])
    g = ca.Function("cut", [x], [ca.dot(ca.DM(a), x) - b])
    X0 = np.stack([lo, hi], axis=1)
    res = minimize(f, X0, 0.01, constraints=g, local_solver=local_solver, max_boxes=200_000)
    true = _box_qp_minimum_with_cut(Q, c, lo, hi, a, b)
    tol = 1e-9 * (1 + abs(true))
    assert res.status in (Status.PROVED, Status.BUDGET)
    assert res.lower <= true + tol
    assert true - tol <= res.upper
    _check_point(res, f, X0, g)
