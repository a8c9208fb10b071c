"""Closed-loop simulation (cm.simulate, cm.Trajectory) and its plot."""

from __future__ import annotations

import dataclasses
import doctest
import importlib
import json

import casadi as ca
import matplotlib
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.exceptions import DimensionError, ModelError

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

A2 = np.array([[1.0, 0.1], [0.0, 1.0]])
B2 = np.array([[0.005], [0.1]])
K2 = np.array([[-3.0, -3.5]])


def linear_model(A=A2, B=B2, E=None, x_max=10.0, u_max=50.0, W=None, name="lin"):
    """x+ = A x + B u (+ E w) with boxes |x| <= x_max, |u| <= u_max."""
    n, m = B.shape
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u", m)
    f = ca.mtimes(ca.DM(A), x) + ca.mtimes(ca.DM(B), u)
    w = None
    if E is not None:
        w = ca.SX.sym("w", E.shape[1])
        f = f + ca.mtimes(ca.DM(E), w)
    return cm.Model(x=x, u=u, f=f, w=w, X=cm.Box(-x_max * np.ones(n), x_max * np.ones(n)),
                    U=cm.Box(-u_max * np.ones(m), u_max * np.ones(m)), W=W, name=name)


def integrator(W=None):
    """Scalar x+ = x + u (+ w), X = U = [-1, 1]."""
    x = ca.SX.sym("x")
    u = ca.SX.sym("u")
    w = ca.SX.sym("w") if W is not None else None
    return cm.Model(x=x, u=u, w=w, f=x + u + (w if w is not None else 0),
                    X=cm.Box([-1], [1]), U=cm.Box([-1], [1]), W=W, name="integrator")


def disturbed_model(W=None):
    """2 states, 1 input, 2 additive disturbances."""
    W = cm.Box([-0.1, 0.2], [0.05, 0.3]) if W is None else W
    return linear_model(E=np.eye(2), W=W, name="disturbed")


# ------------------------------------------------------------------- trajectories
@settings(max_examples=25)
@given(x0=st.lists(st.floats(-5, 5), min_size=2, max_size=2),
       steps=st.integers(0, 40), flat_gain=st.booleans())
def test_linear_gain_reproduces_analytic_trajectory(x0, steps, flat_gain):
    model = linear_model()
    K = K2.ravel() if flat_gain else K2
    traj = cm.simulate(model, K, x0, steps)
    Acl = A2 + B2 @ K2
    expected = np.array([np.linalg.matrix_power(Acl, k) @ np.asarray(x0) for k in
                         range(steps + 1)])
    assert traj.x.shape == (steps + 1, 2) and traj.u.shape == (steps, 1)
    assert traj.w.shape == (steps, 0)
    np.testing.assert_allclose(traj.x, expected, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(traj.u, (K2 @ expected[:-1].T).T, rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(traj.t, np.arange(steps + 1))
    assert traj.steps == steps and traj.stop_reason == "steps"


def test_callable_and_gain_and_casadi_law_agree():
    model = linear_model()
    x0 = [1.0, -2.0]
    by_gain = cm.simulate(model, K2, x0, 20)
    by_fun = cm.simulate(model, lambda x: K2 @ x, x0, 20)
    law = ca.mtimes(ca.DM(K2), model.x)
    by_sx = cm.simulate(model, law, x0, 20)
    by_function = cm.simulate(model, ca.Function("k", [model.x], [law]), x0, 20)
    for other in (by_fun, by_sx, by_function):
        np.testing.assert_allclose(other.x, by_gain.x, rtol=1e-13, atol=1e-15)


def test_cannon_local_gain_from_terminal_set_stays_in_X_and_contracts():
    ex = cm.models.load("cannon")
    model, T, K = ex.model, ex.terminal, ex.local_law
    rng = np.random.default_rng(3)
    starts = list(0.95 * T.vertices())
    cand = T.bounding_box().sample(400, rng)
    starts += list(cand[T.contains(cand)][:10])
    assert len(starts) >= 12
    for x0 in starts:
        traj = cm.simulate(model, K, x0, 60)
        assert traj.violations["state"] == 0 and traj.violations["input"] == 0
        assert traj.violations["state_steps"] == () and traj.violations["input_steps"] == ()
        assert T.contains(traj.x).all()
        norms = np.abs(traj.x).max(axis=1)
        assert norms[-1] < 0.1 * norms[0]
        assert norms[30] < norms[0]


# ------------------------------------------------------------------- disturbances
@settings(max_examples=30)
@given(lo=st.lists(st.floats(-1e6, 1e6), min_size=2, max_size=2),
       width=st.lists(st.floats(0, 1e6), min_size=2, max_size=2),
       seed=st.integers(0, 2**32 - 1))
def test_uniform_draws_lie_in_W(lo, width, seed):
    lo = np.array(lo)
    W = cm.Box(lo, lo + np.array(width))
    model = disturbed_model(W)
    traj = cm.simulate(model, K2, [0.0, 0.0], 30, disturbance="uniform", seed=seed,
                       check_x0=False)
    assert W.contains(traj.w).all()
    assert traj.disturbance == "uniform" and traj.seed == seed


def test_uniform_draws_reproducible_and_seed_dependent():
    model = disturbed_model()
    a = cm.simulate(model, K2, [1.0, 0.0], 50, disturbance="uniform", seed=7)
    b = cm.simulate(model, K2, [1.0, 0.0], 50, disturbance="uniform", seed=7)
    c = cm.simulate(model, K2, [1.0, 0.0], 50, disturbance="uniform", seed=8)
    np.testing.assert_array_equal(a.w, b.w)
    np.testing.assert_array_equal(a.x, b.x)
    assert not np.array_equal(a.w, c.w)
    # not a degenerate draw: the values spread over W
    assert len(np.unique(a.w[:, 0])) == 50
    gen = cm.simulate(model, K2, [1.0, 0.0], 50, disturbance="uniform",
                      seed=np.random.default_rng(7))
    np.testing.assert_array_equal(gen.w, a.w)
    assert gen.seed is None


def test_vertex_draws_are_vertices():
    model = disturbed_model()
    W = model.W
    traj = cm.simulate(model, K2, [1.0, 0.0], 80, disturbance="vertices", seed=2)
    verts = {tuple(v) for v in W.vertices()}
    rows = {tuple(r) for r in traj.w}
    assert rows <= verts
    assert rows == verts  # 80 draws reach all 4 vertices
    again = cm.simulate(model, K2, [1.0, 0.0], 80, disturbance="vertices", seed=2)
    np.testing.assert_array_equal(again.w, traj.w)


def _replay(model, traj):
    """Re-simulate the recorded inputs and disturbances with model.step."""
    x = traj.x[0]
    out = [x]
    for u, w in zip(traj.u, traj.w, strict=True):
        x = model.step(x, u, w if model.l else None)
        out.append(x)
    return np.array(out)


def test_array_disturbance_used_exactly():
    model = disturbed_model()
    rng = np.random.default_rng(0)
    ws = model.W.sample(25, rng)
    traj = cm.simulate(model, K2, [1.0, -1.0], 25, disturbance=ws)
    np.testing.assert_array_equal(traj.w, ws)
    np.testing.assert_allclose(traj.x, _replay(model, traj), rtol=0, atol=0)
    assert traj.disturbance == "array"
    const = cm.simulate(model, K2, [1.0, -1.0], 5, disturbance=[0.0, 0.25])
    np.testing.assert_array_equal(const.w, np.tile([0.0, 0.25], (5, 1)))


def test_array_disturbance_scalar_forms():
    model = integrator(W=cm.Box([-0.1], [0.1]))
    seq = np.array([0.1, -0.1, 0.05])
    traj = cm.simulate(model, lambda x: 0.0, [0.0], 3, disturbance=seq)
    np.testing.assert_array_equal(traj.w[:, 0], seq)
    np.testing.assert_allclose(traj.x[:, 0], [0.0, 0.1, 0.0, 0.05], atol=1e-15)
    const = cm.simulate(model, lambda x: 0.0, [0.0], 3, disturbance=0.1)
    np.testing.assert_array_equal(const.w[:, 0], [0.1, 0.1, 0.1])


def test_callable_disturbance_used_exactly():
    model = disturbed_model()
    calls = []

    def dist(k, x):
        calls.append((k, np.array(x)))
        return [0.05 * (-1) ** k, 0.2 + 0.001 * k]

    traj = cm.simulate(model, K2, [1.0, -1.0], 12, disturbance=dist)
    assert [k for k, _ in calls] == list(range(12))
    for k, x in calls:
        np.testing.assert_array_equal(x, traj.x[k])
        np.testing.assert_array_equal(traj.w[k], [0.05 * (-1) ** k, 0.2 + 0.001 * k])
    np.testing.assert_allclose(traj.x, _replay(model, traj), rtol=0, atol=0)
    assert traj.disturbance == "callable"


def test_no_disturbance_means_centre_of_W():
    model = disturbed_model()
    traj = cm.simulate(model, K2, [1.0, -1.0], 4)
    np.testing.assert_array_equal(traj.w, np.tile(model.W.mid, (4, 1)))
    assert traj.disturbance == "centre"
    named = cm.simulate(model, K2, [1.0, -1.0], 4, disturbance="centre")
    np.testing.assert_array_equal(named.x, traj.x)


# ----------------------------------------------------------------- refused inputs
def test_x0_outside_X_is_refused_naming_components():
    model = linear_model(x_max=2.0)
    with pytest.raises(ValueError, match=r"x0\[1\] = 2.5 > 2 \(upper bound\)") as err:
        cm.simulate(model, K2, [0.0, 2.5], 5)
    assert "x0[0]" not in str(err.value) and "check_x0=False" in str(err.value)
    with pytest.raises(ValueError, match=r"x0\[0\] = -3 < -2.*x0\[1\] = 2.5 > 2"):
        cm.simulate(model, K2, [-3.0, 2.5], 5)
    traj = cm.simulate(model, K2, [0.0, 2.5], 5, check_x0=False)
    assert traj.steps == 5
    assert 0 not in traj.violations["state_steps"]


@pytest.mark.parametrize("x0, exc", [
    ([0.0, 0.0, 0.0], DimensionError),
    ([[0.0, 0.0]], DimensionError),
    ([np.nan, 0.0], ValueError),
    ([np.inf, 0.0], ValueError),
    (["a", 0.0], ValueError),
])
def test_bad_x0_is_refused(x0, exc):
    with pytest.raises(exc, match="x0"):
        cm.simulate(linear_model(), K2, x0, 3)


@pytest.mark.parametrize("steps, exc", [(-1, ValueError), (2.5, TypeError), (True, TypeError),
                                        ("3", TypeError)])
def test_bad_steps_is_refused(steps, exc):
    with pytest.raises(exc, match="steps"):
        cm.simulate(linear_model(), K2, [0.0, 0.0], steps)


def test_numpy_integer_steps_accepted():
    assert cm.simulate(linear_model(), K2, [0.0, 0.0], np.int64(3)).steps == 3


def test_disturbance_without_w_is_refused():
    for dist in ("uniform", "vertices", [0.0], lambda k, x: [0.0]):
        with pytest.raises(ModelError, match="no disturbance"):
            cm.simulate(linear_model(), K2, [0.0, 0.0], 3, disturbance=dist)


def test_disturbance_outside_W_is_refused_naming_the_step():
    model = disturbed_model()
    ws = np.tile(model.W.mid, (6, 1))
    ws[4, 1] = 0.31
    with pytest.raises(ValueError, match=r"step 4 lies outside W: w\[1\] = 0.31"):
        cm.simulate(model, K2, [0.0, 0.0], 6, disturbance=ws)
    with pytest.raises(ValueError, match="step 2 lies outside W"):
        cm.simulate(model, K2, [0.0, 0.0], 6,
                    disturbance=lambda k, x: [0.0, 0.25] if k != 2 else [0.06, 0.25])
    with pytest.raises(ValueError, match="step 0 is not finite"):
        cm.simulate(model, K2, [0.0, 0.0], 6, disturbance=lambda k, x: [np.nan, 0.25])


def test_bad_disturbance_shapes_and_names():
    model = disturbed_model()
    with pytest.raises(DimensionError, match=r"\(5, 2\)"):
        cm.simulate(model, K2, [0.0, 0.0], 5, disturbance=np.zeros((4, 2)))
    with pytest.raises(DimensionError, match="step 1"):
        cm.simulate(model, K2, [0.0, 0.0], 5,
                    disturbance=lambda k, x: [0.0, 0.25] if k == 0 else [0.0])
    with pytest.raises(ValueError, match="unknown disturbance 'gauss'"):
        cm.simulate(model, K2, [0.0, 0.0], 5, disturbance="gauss")


def test_controller_nan_and_wrong_shape_name_the_step():
    model = linear_model()

    def nan_at_3(x, k=[0]):  # noqa: B006 - a call counter
        k[0] += 1
        return np.array([np.nan]) if k[0] == 4 else np.array([0.0])

    with pytest.raises(ValueError, match="step 3 is not finite"):
        cm.simulate(model, nan_at_3, [0.0, 0.0], 10)
    with pytest.raises(DimensionError, match=r"step 0 has shape \(2,\)"):
        cm.simulate(model, lambda x: np.zeros(2), [0.0, 0.0], 10)
    with pytest.raises(TypeError, match="step 0 is not numeric"):
        cm.simulate(model, lambda x: "u", [0.0, 0.0], 10)


def test_bad_controllers_are_refused():
    model = linear_model()
    with pytest.raises(TypeError, match="ctrl is None"):
        cm.simulate(model, None, [0.0, 0.0], 3)
    with pytest.raises(DimensionError, match=r"shape \(m, n\) = \(1, 2\)"):
        cm.simulate(model, np.ones((2, 2)), [0.0, 0.0], 3)
    with pytest.raises(ValueError, match="NaN"):
        cm.simulate(model, [[np.nan, 0.0]], [0.0, 0.0], 3)
    with pytest.raises(ModelError, match="depends on"):
        cm.simulate(model, ca.SX.sym("z"), [0.0, 0.0], 3)
    with pytest.raises(TypeError, match="Model"):
        cm.simulate("model", K2, [0.0, 0.0], 3)
    with pytest.raises(TypeError, match="ctrl must be a callable"):
        cm.simulate(model, {"K": K2}, [0.0, 0.0], 3)


def test_controller_exception_propagates_with_the_step():
    def failing(x, k=[0]):  # noqa: B006 - a call counter
        k[0] += 1
        if k[0] == 3:
            raise RuntimeError("solver failed")
        return 0.0

    with pytest.raises(RuntimeError, match="solver failed") as err:
        cm.simulate(linear_model(), failing, [0.0, 0.0], 5)
    notes = getattr(err.value, "__notes__", ["at step 2"])
    assert any("at step 2" in s for s in notes)


# --------------------------------------------------------------------- violations
def test_state_violations_counted_with_step_indices():
    model = integrator()
    traj = cm.simulate(model, lambda x: 0.4, [0.0], 6)
    np.testing.assert_allclose(traj.x[:, 0], 0.4 * np.arange(7), atol=1e-14)
    assert traj.violations["state"] == 4
    assert traj.violations["state_steps"] == (3, 4, 5, 6)
    assert traj.violations["input"] == 0
    assert traj.summary()["violations"]["state_steps"] == [3, 4, 5, 6]


def test_boundary_is_not_a_violation():
    traj = cm.simulate(integrator(), lambda x: 0.5, [0.0], 2)
    assert traj.x[-1, 0] == 1.0 and traj.violations["state"] == 0


def test_input_outside_U_applied_unclipped_and_counted():
    model = integrator()
    us = {0: 0.2, 1: -1.5, 2: 0.1, 3: 1.25}
    step = iter(range(100))
    traj = cm.simulate(model, lambda x: us[next(step)], [0.0], 4, check_x0=True)
    np.testing.assert_array_equal(traj.u[:, 0], [0.2, -1.5, 0.1, 1.25])
    np.testing.assert_allclose(traj.x[:, 0], np.cumsum([0.0, 0.2, -1.5, 0.1, 1.25]),
                               atol=1e-14)
    assert traj.violations["input"] == 2 and traj.violations["input_steps"] == (1, 3)
    assert traj.violations["state_steps"] == (2, 3)  # -1.3, -1.2


# ----------------------------------------------------------------------- last_info
class ReportingController:
    """Gain controller that reports like the library's controllers."""

    def __init__(self):
        self.k = 0
        self.last_info = None

    def __call__(self, x):
        self.k += 1
        if self.k % 3 == 0:
            self.last_info = {"status": "PROVED", "certificate": "verified",
                              "horizon": np.int64(4), "solve_time": 0.5, "mode": "mpc"}
        elif self.k % 3 == 1:
            self.last_info = {"status": "ok", "certificate": "local_law", "mode": "local_law"}
        else:
            self.last_info = {"certificate": "unverified", "horizon": 6}
        return K2 @ x


def test_last_info_is_recorded():
    ctrl = ReportingController()
    traj = cm.simulate(linear_model(), ctrl, [1.0, 0.0], 6)
    assert traj.certificate == ("local_law", "unverified", "verified") * 2
    assert traj.status == ("ok", None, "PROVED") * 2
    assert traj.horizon == (None, 6, 4) * 2
    assert all(type(h) is int for h in traj.horizon if h is not None)
    assert traj.mode == ("local_law", None, "mpc") * 2
    # reported solve time used where present, measured call time elsewhere
    np.testing.assert_array_equal(traj.solve_time[[2, 5]], [0.5, 0.5])
    np.testing.assert_array_equal(traj.solve_time[[0, 1, 3, 4]], traj.call_time[[0, 1, 3, 4]])
    assert (traj.call_time >= 0).all() and traj.call_time.shape == (6,)
    s = traj.summary()
    assert s["certificates"] == {"local_law": 2, "unverified": 2, "verified": 2}
    assert s["horizons"] == {"4": 2, "6": 2, "none": 2}
    assert s["statuses"] == {"PROVED": 2, "none": 2, "ok": 2}
    # solve times over the two "mpc" steps only (0.5 s each); the others are not solves
    assert traj.step_kind == ("local_law", "other", "solver") * 2
    assert s["step_kinds"] == {"solver": 2, "local_law": 2, "other": 2}
    assert s["solve_time"] == {"min": 0.5, "median": 0.5, "max": 0.5, "mean": 0.5,
                               "total": 1.0, "steps": 2}
    assert s["call_time"]["total"] == pytest.approx(float(traj.call_time.sum()))
    assert traj.level == (None,) * 6 and s["levels"] == {}


def test_plain_callable_defaults():
    traj = cm.simulate(linear_model(), lambda x: K2 @ x, [1.0, 0.0], 3)
    assert traj.status == ("ok",) * 3 and traj.certificate == (None,) * 3
    assert traj.horizon == (None,) * 3 and traj.mode == ("feedback",) * 3
    np.testing.assert_array_equal(traj.solve_time, traj.call_time)


# ------------------------------------------------------------- stopping and runs
def test_stop_when_shortens_the_trajectory():
    model = linear_model()
    full = cm.simulate(model, K2, [1.0, 0.0], 200)
    norms = np.abs(full.x).max(axis=1)
    first = int(np.argmax(norms < 0.1))
    assert 0 < first < 200
    traj = cm.simulate(model, K2, [1.0, 0.0], 200,
                       stop_when=lambda x: np.abs(x).max() < 0.1)
    assert traj.stop_reason == "stop_when" and traj.steps == first
    assert traj.x.shape == (first + 1, 2) and traj.u.shape == (first, 1)
    assert len(traj.certificate) == first and traj.solve_time.shape == (first,)
    np.testing.assert_array_equal(traj.x, full.x[:first + 1])
    at_start = cm.simulate(model, K2, [0.0, 0.0], 10, stop_when=lambda x: True)
    assert at_start.steps == 0 and at_start.x.shape == (1, 2)


def test_zero_steps():
    traj = cm.simulate(linear_model(), K2, [1.0, 2.0], 0)
    assert traj.x.shape == (1, 2) and traj.u.shape == (0, 1) and traj.steps == 0
    s = traj.summary()
    assert s["solve_time"]["median"] is None and s["final_state"] == [1.0, 2.0]
    json.dumps(s, allow_nan=False)


def test_keyboard_interrupt_returns_partial_trajectory():
    def ctrl(x, k=[0]):  # noqa: B006 - a call counter
        k[0] += 1
        if k[0] == 6:
            raise KeyboardInterrupt
        return K2 @ x

    traj = cm.simulate(linear_model(), ctrl, [1.0, 0.0], 50)
    assert traj.interrupted and traj.stop_reason == "interrupted"
    assert traj.steps == 5 and traj.x.shape == (6, 2) and len(traj.status) == 5
    assert traj.summary()["interrupted"] is True


def test_divergence_stops_with_the_non_finite_state():
    x = ca.SX.sym("x")
    u = ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=1e200 * x + u, X=cm.Box([-1], [1]), U=cm.Box([-1], [1]))
    with pytest.warns(RuntimeWarning, match="non-finite at step 2"):
        traj = cm.simulate(model, lambda x: 0.0, [0.5], 10)
    assert traj.stop_reason == "diverged" and traj.steps == 2
    assert np.isinf(traj.x[-1, 0])
    assert traj.violations["state_steps"] == (1, 2)
    s = traj.summary()
    assert s["final_norm_inf"] is None
    json.dumps(s, allow_nan=False)


def test_autonomous_model_with_ctrl_none():
    model = linear_model().closed_loop(K2)
    traj = cm.simulate(model, None, [1.0, 0.0], 10)
    ref = cm.simulate(linear_model(), K2, [1.0, 0.0], 10)
    np.testing.assert_allclose(traj.x, ref.x, rtol=1e-13, atol=1e-15)
    assert traj.u.shape == (10, 0) and traj.mode == ("autonomous",) * 10


def test_progress_bar_forced(capsys):
    cm.simulate(linear_model(), K2, [1.0, 0.0], 20, progress=True)
    assert "simulate lin" in capsys.readouterr().err
    cm.simulate(linear_model(), K2, [1.0, 0.0], 20, progress=False)
    assert capsys.readouterr().err == ""


# ------------------------------------------------------------ larger state spaces
def _three_state():
    """Nonlinear 3-state, 2-input model with equilibrium x_eq = (1, -0.5, 2), u_eq."""
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u", 2)
    f = ca.vertcat(x[0] + 0.1 * x[1] + 0.05 * ca.sin(x[2] - 2) + 0.1 * u[0],
                   0.9 * x[1] + 0.1 * x[0] * x[0] + 0.1 * u[1],
                   0.8 * x[2] + 0.1 * u[0] + 0.05 * u[1] + 0.425)
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-3, -3, -3], [5, 5, 5]),
                     U=cm.Box([-10, -10], [10, 10]), name="three")
    x_eq = np.array([1.0, -0.5, 2.0])
    # f(x_eq, u_eq) = x_eq: 0.1 u0 = -0.1 x1, 0.1 u1 = 0.1 x1 - 0.1 x0^2 - 0.9 x1 + ...,
    # and the constant 0.425 = 0.2 x2 - 0.1 u0 - 0.05 u1
    u_eq = np.array([0.5, -1.5])

    def numpy_f(xv, uv):
        return np.array([xv[0] + 0.1 * xv[1] + 0.05 * np.sin(xv[2] - 2) + 0.1 * uv[0],
                         0.9 * xv[1] + 0.1 * xv[0] ** 2 + 0.1 * uv[1],
                         0.8 * xv[2] + 0.1 * uv[0] + 0.05 * uv[1] + 0.425])

    return model, x_eq, u_eq, numpy_f


def test_three_state_model_with_nonzero_equilibrium():
    model, x_eq, u_eq, numpy_f = _three_state()
    np.testing.assert_allclose(model.step(x_eq, u_eq), x_eq, atol=1e-15)
    K = np.array([[-3.0, -1.0, 0.0], [-2.0, -2.0, 0.0]])

    def law(x):
        return u_eq + K @ (x - x_eq)

    x0 = np.array([1.5, 0.0, 1.0])
    traj = cm.simulate(model, law, x0, 120)
    xr = [x0]
    for _ in range(120):
        xr.append(numpy_f(xr[-1], law(xr[-1])))
    np.testing.assert_allclose(traj.x, np.array(xr), rtol=1e-12, atol=1e-12)
    assert np.abs(traj.x[-1] - x_eq).max() < 1e-6
    assert traj.violations["state"] == 0 and traj.violations["input"] == 0
    fig = traj.plot(dims=(0, 2))
    phase = fig.axes[0]
    assert (phase.get_xlabel(), phase.get_ylabel()) == ("x1", "x3")
    plt.close(fig)


def test_four_state_model_with_nonzero_equilibrium_and_disturbance():
    # x+ = A (x - x_eq) + x_eq + B (u - u_eq) + w, stable under u = u_eq + K (x - x_eq)
    A = np.array([[1.0, 0.1, 0.0, 0.0], [0.0, 1.0, 0.1, 0.0],
                  [0.0, 0.0, 0.9, 0.1], [0.1, 0.0, 0.0, 0.8]])
    B = np.array([[0.0], [0.0], [0.1], [0.1]])
    x_eq = np.array([2.0, -1.0, 0.5, 3.0])
    u_eq = 1.5
    x = ca.SX.sym("x", 4)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w", 4)
    f = ca.mtimes(ca.DM(A), x - ca.DM(x_eq)) + ca.DM(x_eq) + ca.mtimes(ca.DM(B), u - u_eq) + w
    W = cm.Box(-1e-3 * np.ones(4), 1e-3 * np.ones(4))
    model = cm.Model(x=x, u=u, w=w, f=f, X=cm.Box(-10 * np.ones(4), 10 * np.ones(4)),
                     U=cm.Box([-100], [100]), W=W, name="four")
    import control

    K = -np.asarray(control.dlqr(A, B, np.eye(4), np.eye(1))[0])
    traj = cm.simulate(model, lambda xv: u_eq + K @ (xv - x_eq), x_eq + 0.5, 150,
                       disturbance="uniform", seed=4)
    xr = [x_eq + 0.5]
    for k in range(150):
        xv = xr[-1]
        uv = u_eq + K @ (xv - x_eq)
        xr.append(A @ (xv - x_eq) + x_eq + B @ (uv - u_eq) + traj.w[k])
    np.testing.assert_allclose(traj.x, np.array(xr), rtol=1e-12, atol=1e-12)
    assert np.abs(traj.x[-1] - x_eq).max() < 0.05
    assert traj.violations["state"] == 0


# --------------------------------------------------------------------------- plots
def _texts(fig):
    labels = [(a.get_xlabel(), a.get_ylabel()) for a in fig.axes]
    legends = [t.get_text() for a in fig.axes if a.get_legend() for t in
               a.get_legend().get_texts()]
    return labels, legends


def test_plot_two_states():
    ex = cm.models.load("cannon")
    traj = cm.simulate(ex.model, ex.local_law, [0.2, 0.1], 20)
    fig = traj.plot(sets={"terminal": ex.terminal}, obstacles=[(0.5, 0.5, 0.1)])
    assert isinstance(fig, Figure) and len(fig.axes) == 3
    labels, legends = _texts(fig)
    assert labels == [("x1", "x2"), ("step k", "state"), ("step k", "input")]
    for text in ("X", "terminal", "obstacle", "trajectory", "start x(0)", "end x(20)", "x1",
                 "x2", "u1", "u1 bounds (U)"):
        assert text in legends
    # the U bounds are drawn as dashed lines at the box
    uax = fig.axes[2]
    dashed = [ln.get_ydata()[0] for ln in uax.get_lines() if ln.get_linestyle() == "--"]
    assert sorted(dashed) == [-2.0, 2.0]
    plt.close(fig)


def test_plot_one_state_and_violations():
    traj = cm.simulate(integrator(), lambda x: 0.4, [0.0], 5)
    fig = traj.plot(state_names=["position"], input_names=["force"], title="run")
    assert len(fig.axes) == 2
    labels, legends = _texts(fig)
    assert labels == [("step k", "position"), ("step k", "input")]
    for text in ("X", "position", "outside X", "start x(0)", "end x(5)", "force"):
        assert text in legends
    assert fig._suptitle.get_text() == "run"
    plt.close(fig)


def test_plot_three_states_dims_and_axes_argument():
    model = linear_model(A=np.eye(3) * 0.9, B=np.ones((3, 2)) * 0.1, name="l3")
    traj = cm.simulate(model, np.zeros((2, 3)), [1.0, 2.0, 3.0], 10)
    fig = traj.plot(dims=(2, 1), sets=[cm.Box([-1, -1, -1], [1, 1, 1])])
    labels, legends = _texts(fig)
    assert labels[0] == ("x3", "x2")
    assert "Box" in legends and "x3" in legends and "u2" in legends
    plt.close(fig)
    fig, ax = plt.subplots()
    out = traj.plot(ax=ax)
    assert out is fig and ax.get_xlabel() == "x1" and ax.get_ylabel() == "x2"
    plt.close(fig)
    with pytest.raises(ValueError, match="dims"):
        traj.plot(dims=(1, 1))
    with pytest.raises(ValueError, match="state_names"):
        traj.plot(state_names=["a"])


def test_plot_of_empty_and_loaded_trajectories(tmp_path):
    traj = cm.simulate(linear_model(), K2, [1.0, 0.0], 0)
    fig = traj.plot()
    assert len(fig.axes) == 3
    plt.close(fig)
    traj = cm.simulate(linear_model(), K2, [1.0, 0.0], 5)
    loaded = cm.Trajectory.load(traj.save(tmp_path / "t.json"))
    fig = loaded.plot()  # no model: no boxes, still labelled
    labels, legends = _texts(fig)
    assert labels[0] == ("x1", "x2") and "X" not in legends
    plt.close(fig)


# ------------------------------------------------------------ Trajectory object
def test_trajectory_is_read_only():
    traj = cm.simulate(linear_model(), K2, [1.0, 0.0], 5)
    with pytest.raises(ValueError):
        traj.x[0, 0] = 3.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        traj.x = np.zeros((6, 2))
    with pytest.raises(TypeError):
        traj.violations["state"] = 5


def test_controller_cannot_alter_the_recorded_state():
    def mutating(x):
        u = K2 @ x
        x[:] = 100.0
        return u

    traj = cm.simulate(linear_model(), mutating, [1.0, 0.0], 5)
    ref = cm.simulate(linear_model(), K2, [1.0, 0.0], 5)
    np.testing.assert_array_equal(traj.x, ref.x)


@pytest.mark.parametrize("suffix", [".json", ".npz"])
def test_save_load_round_trip(tmp_path, suffix):
    model = disturbed_model()
    traj = cm.simulate(model, ReportingController(), [1.0, 0.0], 9, disturbance="uniform",
                       seed=5)
    path = traj.save(tmp_path / f"traj{suffix}")
    back = cm.Trajectory.load(path, model=model)
    for name in ("x", "u", "w", "solve_time", "call_time"):
        np.testing.assert_array_equal(getattr(back, name), getattr(traj, name))
    for name in ("status", "certificate", "horizon", "mode", "stop_reason", "disturbance",
                 "seed", "model_name"):
        assert getattr(back, name) == getattr(traj, name)
    assert dict(back.violations) == dict(traj.violations)
    assert back.summary() == traj.summary()
    with pytest.raises(ValueError, match=r"\.json or \.npz"):
        traj.save(tmp_path / "traj.txt")


def test_a_file_without_levels_loads_with_none_levels(tmp_path):
    traj = cm.simulate(linear_model(), ReportingController(), [1.0, 0.0], 4)
    path = traj.save(tmp_path / "t.json")
    data = json.loads(path.read_text())
    del data["level"]  # as written before levels were recorded
    path.write_text(json.dumps(data))
    back = cm.Trajectory.load(path)
    assert back.level == (None,) * 4 and back.horizon == traj.horizon
    with pytest.raises(DimensionError, match="level must have one entry per step"):
        dataclasses.replace(traj, level=(1, 2))


def test_summary_is_json_and_consistent():
    model = disturbed_model()
    traj = cm.simulate(model, K2, [1.0, 0.0], 30, disturbance="vertices", seed=1)
    s = json.loads(traj.to_json())
    assert s["steps"] == 30 and s["model"] == "disturbed" and s["disturbance"] == "vertices"
    assert s["final_state"] == traj.x[-1].tolist()
    assert s["final_norm_inf"] == float(np.abs(traj.x[-1]).max())
    assert s["violations"] == {"state": 0, "input": 0, "state_steps": [], "input_steps": []}
    st_ = s["call_time"]
    assert st_["min"] <= st_["median"] <= st_["max"]
    assert st_["total"] == pytest.approx(float(traj.call_time.sum()))


def test_docstring_examples():
    # the package attribute `simulate` is the function; the module is looked up by name
    sim_module = importlib.import_module("casadi_cmpc.mpc.simulate")
    result = doctest.testmod(sim_module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0
