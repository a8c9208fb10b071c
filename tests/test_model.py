"""Tests of casadi_cmpc.model.Model: validation, evaluation, discretisation, closed loop,
inclusion functions and detected structure."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import scipy.linalg
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.exceptions import (
    DimensionError,
    EmptySetError,
    FreeSymbolError,
    InvalidBoundsError,
    ModelError,
    UnboundedSetError,
)

X2 = cm.Box([-2.0, -2.0], [2.0, 2.0])
U1 = cm.Box([-2.0], [2.0])
W1 = cm.Box([0.85], [0.95])


def _cannon_like(name: str = "cannon"):
    """Cannon et al. dynamics with an extra transcendental term; returns (model, numpy f)."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    w = ca.SX.sym("mu")
    f = ca.vertcat(
        x[0] + 0.1 * x[1] + 0.1 * (w + (1 - w) * x[0]) * u,
        0.1 * x[0] + x[1] + 0.1 * (w - 4 * (1 - w) * x[1]) * u + 0.05 * w * ca.sin(x[0]),
    )
    model = cm.Model(x=x, u=u, f=f, w=w, X=X2, U=U1, W=W1, name=name)

    def f_np(xs: np.ndarray, us: np.ndarray, ws: np.ndarray) -> np.ndarray:
        x0, x1, uu, mu = xs[:, 0], xs[:, 1], us[:, 0], ws[:, 0]
        return np.stack([
            x0 + 0.1 * x1 + 0.1 * (mu + (1 - mu) * x0) * uu,
            0.1 * x0 + x1 + 0.1 * (mu - 4 * (1 - mu) * x1) * uu + 0.05 * mu * np.sin(x0),
        ], axis=1)

    return model, f_np


@pytest.fixture(scope="module")
def cannon():
    return _cannon_like()


@pytest.fixture
def syms():
    return ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("w")


# --------------------------------------------------------------------------- validation

def test_free_symbol_in_f_is_named(syms):
    x, u, _ = syms
    p = ca.SX.sym("gain_p")
    with pytest.raises(FreeSymbolError, match="gain_p"):
        cm.Model(x=x, u=u, f=x + p * u, X=X2, U=U1)


def test_free_symbol_detected_by_identity_not_name(syms):
    x, u, _ = syms
    other = ca.SX.sym("x", 2)  # same names x_0, x_1 as the declared state, other symbols
    with pytest.raises(FreeSymbolError, match="x_0"):
        cm.Model(x=x, u=u, f=other + u, X=X2, U=U1)


def test_f_shape_mismatch(syms):
    x, u, _ = syms
    with pytest.raises(DimensionError, match="expected 2"):
        cm.Model(x=x, u=u, f=ca.vertcat(x, u), X=X2, U=U1)


@pytest.mark.parametrize("box", ["X", "U"])
def test_box_dimension_mismatch(syms, box):
    x, u, _ = syms
    boxes = {"X": X2, "U": U1}
    boxes[box] = cm.Box([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0])
    with pytest.raises(DimensionError, match=f"{box} has the wrong dimension"):
        cm.Model(x=x, u=u, f=x + u, **boxes)


def test_empty_box_lo_greater_than_hi(syms):
    x, u, _ = syms
    with pytest.raises(EmptySetError, match="empty"):
        cm.Model(x=x, u=u, f=x + u, X=np.array([[1.0, -1.0], [0.0, 1.0]]), U=U1)


def test_nan_bounds(syms):
    x, u, _ = syms
    with pytest.raises(InvalidBoundsError, match="NaN"):
        cm.Model(x=x, u=u, f=x + u, X=X2, U=([np.nan], [1.0]))


@pytest.mark.parametrize("which", ["X", "U", "W"])
def test_infinite_bounds_refused(syms, which):
    x, u, w = syms
    boxes = {"X": X2, "U": U1, "W": W1}
    boxes[which] = {"X": cm.Box([-1.0, -np.inf], [1.0, 1.0]),
                    "U": cm.Box([-1.0], [np.inf]),
                    "W": cm.Box([0.0], [np.inf])}[which]
    with pytest.raises(UnboundedSetError, match=f"{which} must be bounded"):
        cm.Model(x=x, u=u, w=w, f=x + w * u, **boxes)


def test_w_without_W(syms):
    x, u, w = syms
    with pytest.raises(ModelError, match="W is missing"):
        cm.Model(x=x, u=u, w=w, f=x + w * u, X=X2, U=U1)


def test_W_without_w(syms):
    x, u, _ = syms
    with pytest.raises(ModelError, match="no disturbance symbol"):
        cm.Model(x=x, u=u, f=x + u, X=X2, U=U1, W=W1)


def test_non_symbolic_x(syms):
    x, u, _ = syms
    with pytest.raises(ModelError, match="pure symbols"):
        cm.Model(x=2 * x, u=u, f=x + u, X=X2, U=U1)


def test_python_list_as_x_is_type_error(syms):
    x, u, _ = syms
    with pytest.raises(TypeError, match="x must be a casadi.SX"):
        cm.Model(x=[1.0, 2.0], u=u, f=x + u, X=X2, U=U1)


def test_mx_model_is_converted_to_sx_and_agrees():
    x = ca.MX.sym("x", 2)
    u = ca.MX.sym("u")
    w = ca.MX.sym("w")
    f = ca.vertcat(ca.sin(x[0]) * u + w * x[1], x[0] * x[1] - ca.exp(-u))
    model = cm.Model(x=x, u=u, w=w, f=f, X=X2, U=U1, W=W1)
    assert isinstance(model.x, ca.SX) and isinstance(model.u, ca.SX)
    assert isinstance(model.w, ca.SX) and isinstance(model.f, ca.SX)
    assert (model.n, model.m, model.l) == (2, 1, 1)
    F = ca.Function("F", [x, u, w], [f])
    rng = np.random.default_rng(0)
    xs, us, ws = rng.uniform(-2, 2, (20, 2)), rng.uniform(-2, 2, (20, 1)), rng.uniform(0.85, 0.95,
                                                                                        (20, 1))
    expected = np.asarray(F.map(20)(xs.T, us.T, ws.T)).T
    np.testing.assert_allclose(model.step(xs, us, ws), expected, rtol=0, atol=1e-14)


def test_mx_free_symbol_is_free_symbol_error():
    x = ca.MX.sym("x", 2)
    u = ca.MX.sym("u")
    p = ca.MX.sym("gain_p")
    with pytest.raises(FreeSymbolError, match="gain_p"):
        cm.Model(x=x, u=u, f=x * p + u, X=X2, U=U1)


# --------------------------------------------------------------------------------- step

def test_step_batched_with_broadcast_u(cannon):
    model, f_np = cannon
    rng = np.random.default_rng(1)
    xs = rng.uniform(-2, 2, (7, 2))
    ws = rng.uniform(0.85, 0.95, (7, 1))
    out = model.step(xs, np.array([0.3]), ws)
    assert out.shape == (7, 2)
    np.testing.assert_allclose(out, f_np(xs, np.full((7, 1), 0.3), ws), rtol=0, atol=1e-14)


def test_step_unbatched_returns_vector(cannon):
    model, _ = cannon
    out = model.step([1.0, 2.0], [0.5], [0.9])
    assert out.shape == (2,)
    # hand computation: x0 + 0.1 x1 + 0.1 (mu + (1-mu) x0) u and the second component
    e0 = 1.0 + 0.2 + 0.1 * (0.9 + 0.1 * 1.0) * 0.5
    e1 = 0.1 + 2.0 + 0.1 * (0.9 - 0.4 * 2.0) * 0.5 + 0.05 * 0.9 * np.sin(1.0)
    np.testing.assert_allclose(out, [e0, e1], rtol=0, atol=1e-14)


def test_step_batched_w_and_broadcast_x(cannon):
    model, f_np = cannon
    ws = np.array([[0.85], [0.9], [0.95]])
    out = model.step([0.5, -0.5], [1.0], ws)
    assert out.shape == (3, 2)
    np.testing.assert_allclose(out, f_np(np.tile([0.5, -0.5], (3, 1)), np.ones((3, 1)), ws),
                               rtol=0, atol=1e-14)


def test_step_missing_u(cannon):
    model, _ = cannon
    with pytest.raises(ModelError, match="u is required"):
        model.step([0.0, 0.0], w=[0.9])


def test_step_missing_w(cannon):
    model, _ = cannon
    with pytest.raises(ModelError, match="w is required"):
        model.step([0.0, 0.0], [0.0])


def test_step_batch_sizes_must_broadcast(cannon):
    model, _ = cannon
    with pytest.raises(DimensionError, match="does not broadcast"):
        model.step(np.zeros((3, 2)), np.zeros((2, 1)), [0.9])


# ------------------------------------------------------------------------------ from_ode

@pytest.mark.parametrize("h", [0.1, 0.25, 0.7])
def test_from_ode_euler_and_rk4_scalar_decay(h):
    x = ca.SX.sym("x")
    u = ca.SX.sym("u")
    X, U = cm.Box([-1.0], [1.0]), cm.Box([-1.0], [1.0])
    euler = cm.Model.from_ode(x=x, u=u, rhs=-x, dt=h, method="euler", X=X, U=U)
    rk4 = cm.Model.from_ode(x=x, u=u, rhs=-x, dt=h, method="rk4", X=X, U=U)
    assert abs(euler.step([1.0], [0.0])[0] - (1 - h)) <= 1e-15
    poly = 1 - h + h**2 / 2 - h**3 / 6 + h**4 / 24
    assert abs(rk4.step([1.0], [0.0])[0] - poly) <= 1e-15
    # linear in x: the successor of x0 is poly * x0
    assert abs(rk4.step([0.5], [0.3])[0] - 0.5 * poly) <= 1e-15


def test_from_ode_rk4_substeps_matches_expm_to_fourth_order():
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    A = np.array([[-1.0, 2.0], [-0.5, -1.5]])
    dt = 0.5
    exact = scipy.linalg.expm(A * dt)
    errs = []
    for s in (1, 2, 4, 8):
        model = cm.Model.from_ode(x=x, u=u, rhs=ca.mtimes(ca.DM(A), x), dt=dt, method="rk4",
                                  substeps=s, X=X2, U=U1)
        Phi = model.step(np.eye(2), [0.0]).T  # columns: successors of the unit vectors
        errs.append(np.abs(Phi - exact).max())
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert errs[-1] < 1e-6
    assert np.all(orders[1:] > 3.7) and np.all(orders < 4.6), (errs, orders)


def test_from_ode_bad_method():
    x, u = ca.SX.sym("x"), ca.SX.sym("u")
    with pytest.raises(ValueError, match="unknown method 'rk45'"):
        cm.Model.from_ode(x=x, u=u, rhs=-x, dt=0.1, method="rk45", X=cm.Box([-1], [1]),
                          U=cm.Box([-1], [1]))


@pytest.mark.parametrize("dt", [0.0, -0.1, np.nan])
def test_from_ode_nonpositive_dt(dt):
    x, u = ca.SX.sym("x"), ca.SX.sym("u")
    with pytest.raises(ValueError, match="dt must be a positive"):
        cm.Model.from_ode(x=x, u=u, rhs=-x, dt=dt, X=cm.Box([-1], [1]), U=cm.Box([-1], [1]))


@pytest.mark.parametrize("substeps", [0, -1, 2.5])
def test_from_ode_nonpositive_substeps(substeps):
    x, u = ca.SX.sym("x"), ca.SX.sym("u")
    with pytest.raises(ValueError, match="substeps"):
        cm.Model.from_ode(x=x, u=u, rhs=-x, dt=0.1, substeps=substeps, X=cm.Box([-1], [1]),
                          U=cm.Box([-1], [1]))


def test_from_ode_free_symbol():
    x, u = ca.SX.sym("x"), ca.SX.sym("u")
    p = ca.SX.sym("gain_p")
    with pytest.raises(FreeSymbolError, match="gain_p"):
        cm.Model.from_ode(x=x, u=u, rhs=-p * x + u, dt=0.1, X=cm.Box([-1], [1]),
                          U=cm.Box([-1], [1]))


# --------------------------------------------------------------------------- closed loop

def test_closed_loop_with_gain(cannon):
    model, f_np = cannon
    K = np.array([[-1.2, -0.4]])
    cl = model.closed_loop(K)
    rng = np.random.default_rng(2)
    xs = rng.uniform(-2, 2, (15, 2))
    ws = rng.uniform(0.85, 0.95, (15, 1))
    expected = f_np(xs, xs @ K.T, ws)
    np.testing.assert_allclose(cl.step(xs, w=ws), expected, rtol=0, atol=1e-14)
    np.testing.assert_allclose(cl.step(xs, w=ws), model.step(xs, xs @ K.T, ws), rtol=0,
                               atol=1e-14)


def test_closed_loop_with_sx_law(cannon):
    model, f_np = cannon
    law = -ca.tanh(model.x[0] + 0.5 * model.x[1] ** 2)
    cl = model.closed_loop(law)
    rng = np.random.default_rng(3)
    xs = rng.uniform(-2, 2, (15, 2))
    ws = rng.uniform(0.85, 0.95, (15, 1))
    us = -np.tanh(xs[:, :1] + 0.5 * xs[:, 1:] ** 2)
    np.testing.assert_allclose(cl.step(xs, w=ws), f_np(xs, us, ws), rtol=0, atol=1e-14)


def test_closed_loop_attributes(cannon):
    model, _ = cannon
    cl = model.closed_loop(np.array([[-1.0, -0.5]]))
    assert cl.m == 0 and cl.n == 2 and cl.l == 1
    assert cl.law is not None and cl.law.shape == (1, 1)
    assert cl.input_box == model.U
    assert cl.X == model.X and cl.W == model.W
    assert model.law is None and model.input_box is None
    assert "closed loop" in cl.summary()


def test_law_inclusion_encloses_gain(cannon):
    model, _ = cannon
    K = np.array([[-1.2, 0.7]])
    cl = model.closed_loop(K)
    boxes = np.array([[[0.4, 0.8], [-0.6, -0.2]],
                      [[-2.0, 2.0], [-2.0, 2.0]],
                      [[1.0, 1.0], [0.3, 0.3]]])
    L = cl.law_inclusion()(boxes)
    assert L.shape == (3, 1, 2)
    rng = np.random.default_rng(4)
    for b, enc in zip(boxes, L, strict=True):
        pts = b[:, 0] + (b[:, 1] - b[:, 0]) * rng.random((200, 2))
        vals = pts @ K.T
        assert np.all(vals >= enc[:, 0]) and np.all(vals <= enc[:, 1])
    # linear law: the natural enclosure is tight up to rounding
    np.testing.assert_allclose(L[1, 0], [-3.8, 3.8], rtol=1e-12)


def test_law_inclusion_requires_closed_loop(cannon):
    model, _ = cannon
    with pytest.raises(ModelError, match="closed-loop"):
        model.law_inclusion()


def test_closed_loop_wrong_gain_shape(cannon):
    model, _ = cannon
    with pytest.raises(DimensionError, match=r"gain K must have shape \(m, n\) = \(1, 2\)"):
        model.closed_loop(np.ones((2, 1)))


def test_closed_loop_foreign_symbol(cannon):
    model, _ = cannon
    q = ca.SX.sym("q_foreign")
    with pytest.raises(FreeSymbolError, match="q_foreign"):
        model.closed_loop(model.x[0] * q)


def test_closed_loop_law_may_not_use_w(cannon):
    model, _ = cannon
    with pytest.raises(FreeSymbolError, match="mu"):
        model.closed_loop(model.x[0] * model.w)


def test_closed_loop_of_autonomous_model(cannon):
    model, _ = cannon
    cl = model.closed_loop(np.array([[-1.0, -0.5]]))
    with pytest.raises(ModelError, match="no input"):
        cl.closed_loop(np.zeros((0, 2)))


def test_closed_loop_mx_law_is_type_error(cannon):
    model, _ = cannon
    xm = ca.MX.sym("x", 2)
    with pytest.raises(TypeError, match="casadi.SX"):
        model.closed_loop(-xm[0])


# ----------------------------------------------------------------------------- inclusion

def _boxes_strategy(lo, hi):
    """Sub-boxes of [lo, hi] (per component), as a (d, 2) array."""
    comps = [
        st.tuples(st.floats(0, 1), st.floats(0, 1)).map(
            lambda t, a=a, b=b: [a + (b - a) * min(t), a + (b - a) * max(t)])
        for a, b in zip(lo, hi, strict=True)
    ]
    return st.tuples(*comps).map(np.array)


def _sample(box: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    lo, hi = box[:, 0], box[:, 1]
    pts = lo + (hi - lo) * rng.random((k, box.shape[0]))
    corners = np.array([lo, hi, np.where(np.arange(box.shape[0]) % 2, lo, hi)])
    return np.clip(np.vstack([pts, corners]), lo, hi)


_MODEL_FOR_HYPOTHESIS = _cannon_like("hyp")


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(Xb=_boxes_strategy([-2, -2], [2, 2]), Ub=_boxes_strategy([-2], [2]),
       Wb=_boxes_strategy([0.85], [0.95]), seed=st.integers(0, 2**32 - 1))
def test_inclusion_contains_step(Xb, Ub, Wb, seed):
    model, _ = _MODEL_FOR_HYPOTHESIS
    rng = np.random.default_rng(seed)
    xs, us, ws = _sample(Xb, 60, rng), _sample(Ub, 60, rng), _sample(Wb, 60, rng)
    ys = model.step(xs, us, ws)
    tol = 1e-13
    for kind in ("natural", "centered"):
        enc = model.inclusion(kind)(Xb, Ub, Wb)
        assert enc.shape == (1, 2, 2)
        assert np.all(enc[0, :, 0] <= enc[0, :, 1])
        assert np.all(ys >= enc[0, :, 0] - tol), kind
        assert np.all(ys <= enc[0, :, 1] + tol), kind


def test_inclusion_batched_and_defaults(cannon):
    model, _ = cannon
    F = model.inclusion("natural")
    Xs = np.array([[[0.4, 0.8], [-0.6, -0.2]], [[-1.0, 1.0], [0.0, 0.5]]])
    full = F(Xs, model.U.as_array(), model.W.as_array())
    assert full.shape == (2, 2, 2)
    np.testing.assert_array_equal(F(Xs), full)
    np.testing.assert_array_equal(F(Xs, model.U.as_array()), full)
    np.testing.assert_array_equal(F(Xs, W=model.W), full)
    # the default U really is the model's U: a smaller U gives a different (tighter) result
    small = F(Xs, np.array([[0.5, 0.7]]))
    assert not np.array_equal(small, full)
    assert np.all(small[..., 0] >= full[..., 0]) and np.all(small[..., 1] <= full[..., 1])
    # the default W really is the model's W
    smallw = F(Xs, W=np.array([[0.9, 0.9]]))
    assert not np.array_equal(smallw, full)


def test_inclusion_refuses_W_without_w():
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=x + u, X=X2, U=U1)
    with pytest.raises(ModelError, match="no disturbance"):
        model.inclusion()(X2, W=np.array([[0.0, 1.0]]))


def test_jacobian_inclusion_u(cannon):
    model, _ = cannon
    Xs = np.array([[[0.4, 0.8], [-0.6, -0.2]], [[-2.0, 2.0], [-2.0, 2.0]],
                   [[1.0, 1.5], [0.0, 0.1]]])
    Us = np.array([[[0.5, 0.7]]])
    Ws = np.array([[[0.85, 0.95]]])
    J = model.jacobian_inclusion("u")(Xs, Us, Ws)
    assert J.shape == (3, model.n, model.m, 2)
    rng = np.random.default_rng(5)
    for Xb, enc in zip(Xs, J, strict=True):
        xs, ws = _sample(Xb, 100, rng), _sample(Ws[0], 100, rng)
        # df/du by hand (does not depend on u)
        ju = np.stack([0.1 * (ws[:, 0] + (1 - ws[:, 0]) * xs[:, 0]),
                       0.1 * (ws[:, 0] - 4 * (1 - ws[:, 0]) * xs[:, 1])], axis=1)
        assert np.all(ju >= enc[:, 0, 0]) and np.all(ju <= enc[:, 0, 1])
    # on the first box: 0.1 (mu + (1 - mu) x0) over x0 in [0.4, 0.8], mu in [0.85, 0.95]
    np.testing.assert_allclose(J[0, 0, 0], [0.087, 0.107], rtol=1e-12)


def test_jacobian_inclusion_x_layout():
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    f = ca.vertcat(x[0] + 3 * x[1], x[1] * x[1] + u)
    model = cm.Model(x=x, u=u, f=f, X=X2, U=U1)
    J = model.jacobian_inclusion("x")(np.array([[0.5, 1.0], [2.0, 3.0]]))
    assert J.shape == (1, 2, 2, 2)
    np.testing.assert_allclose(J[0, :, :, 0], [[1.0, 3.0], [0.0, 4.0]], rtol=1e-12)
    np.testing.assert_allclose(J[0, :, :, 1], [[1.0, 3.0], [0.0, 6.0]], rtol=1e-12)


# ----------------------------------------------------------------------------- structure

def test_affine_in_u():
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    yes = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + x[1] * u, ca.sin(x[0]) * u), X=X2, U=U1)
    no = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + u**2, x[1]), X=X2, U=U1)
    assert yes.is_affine_in_u
    assert not no.is_affine_in_u


def test_affine_in_w():
    x, u, w = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("w")
    yes = cm.Model(x=x, u=u, w=w, f=ca.vertcat(x[0] * w + u, ca.sin(x[1]) + w), X=X2, U=U1,
                   W=W1)
    no = cm.Model(x=x, u=u, w=w, f=ca.vertcat(x[0] + u, x[1] + ca.sin(w)), X=X2, U=U1, W=W1)
    assert yes.is_affine_in_w
    assert not no.is_affine_in_w
    no_w = cm.Model(x=x, u=u, f=x + u, X=X2, U=U1)
    assert no_w.is_affine_in_w


def test_nonlinear_states():
    x, u = ca.SX.sym("x", 3), ca.SX.sym("u")
    X3 = cm.Box([-1.0] * 3, [1.0] * 3)
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * ca.sin(x[1]) + 2 * x[2], 0.5 * x[2] + u)
    model = cm.Model(x=x, u=u, f=f, X=X3, U=U1)
    assert model.nonlinear_states == (1,)
    assert model.linear_states == (0, 2)
    assert model.has_affine_state_part
    np.testing.assert_array_equal(model.affine_state_matrix,
                                  [[1.0, 0.0, 0.0], [0.0, 0.0, 2.0], [0.0, 0.0, 0.5]])
    # a state multiplied by the input is nonlinear
    bil = cm.Model(x=x, u=u, f=ca.vertcat(x[0] * u, x[1], x[2]), X=X3, U=U1)
    assert bil.nonlinear_states == (0,)
    lin = cm.Model(x=x, u=u, f=x + u, X=X3, U=U1)
    assert lin.nonlinear_states == ()
    assert not lin.has_affine_state_part


def test_affine_control_part_and_input_matrix():
    x, u, w = ca.SX.sym("x", 2), ca.SX.sym("u", 2), ca.SX.sym("w")
    U2 = cm.Box([-1.0, -1.0], [1.0, 1.0])
    f = ca.vertcat(x[0] + ca.sin(x[1]) + 2 * u[0], x[1] * w + 3 * u[1] - u[0])
    model = cm.Model(x=x, u=u, w=w, f=f, X=X2, U=U2, W=W1)
    assert model.has_affine_control_part
    np.testing.assert_array_equal(model.input_matrix, [[2.0, 0.0], [-1.0, 3.0]])
    # affine in u, but the input gain depends on w (and x): no constant B
    g = ca.vertcat(x[0] + w * u[0], x[1] + x[0] * u[1])
    other = cm.Model(x=x, u=u, w=w, f=g, X=X2, U=U2, W=W1)
    assert other.is_affine_in_u
    assert not other.has_affine_control_part
    with pytest.raises(ModelError, match="no affine control part"):
        other.input_matrix  # noqa: B018


def test_linear_matrices_reproduce_f():
    rng = np.random.default_rng(6)
    A, B, E, c = rng.normal(size=(3, 3)), rng.normal(size=(3, 2)), rng.normal(size=(3, 1)), \
        rng.normal(size=3)
    x, u, w = ca.SX.sym("x", 3), ca.SX.sym("u", 2), ca.SX.sym("w")
    f = ca.mtimes(ca.DM(A), x) + ca.mtimes(ca.DM(B), u) + ca.mtimes(ca.DM(E), w) + ca.DM(c)
    model = cm.Model(x=x, u=u, w=w, f=f, X=cm.Box([-1] * 3, [1] * 3), U=cm.Box([-1] * 2, [1] * 2),
                     W=cm.Box([-1], [1]))
    assert model.is_linear
    A2, B2, E2, c2 = model.linear_matrices()
    np.testing.assert_allclose(A2, A, rtol=0, atol=1e-15)
    np.testing.assert_allclose(B2, B, rtol=0, atol=1e-15)
    np.testing.assert_allclose(E2, E, rtol=0, atol=1e-15)
    np.testing.assert_allclose(c2, c, rtol=0, atol=1e-15)
    xs, us, ws = rng.normal(size=(10, 3)), rng.normal(size=(10, 2)), rng.normal(size=(10, 1))
    np.testing.assert_allclose(xs @ A2.T + us @ B2.T + ws @ E2.T + c2, model.step(xs, us, ws),
                               rtol=0, atol=1e-13)


def test_linear_matrices_without_w_and_nonlinear_refused(cannon):
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * u + 1.0), X=X2, U=U1)
    A, B, E, c = model.linear_matrices()
    np.testing.assert_array_equal(A, [[1.0, 0.1], [0.0, 1.0]])
    np.testing.assert_array_equal(B, [[0.0], [0.1]])
    assert E.shape == (2, 0)
    np.testing.assert_array_equal(c, [0.0, 1.0])
    nonlinear, _ = cannon
    assert not nonlinear.is_linear
    with pytest.raises(ModelError, match="not linear"):
        nonlinear.linear_matrices()


def test_summary_mentions_sizes(cannon):
    model, _ = cannon
    s = model.summary()
    assert "'cannon'" in s
    assert "n = 2" in s and "m = 1" in s and "l = 1" in s
    assert "W = " in s
    x = ca.SX.sym("x", 3)
    auto = cm.Model(x=x, u=None, f=0.5 * x, X=cm.Box([-1] * 3, [1] * 3), name="auto")
    s2 = auto.summary()
    assert "n = 3" in s2 and "m = 0" in s2 and "l = 0" in s2
    assert "W = " not in s2


def test_equilibrium_solves_f_x_u_equals_x():
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * (-ca.sin(x[0]) + u), 0.5 * x[2] + x[0] ** 2)
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-2] * 3, [2] * 3), U=cm.Box([-1], [1]))
    xe = model.equilibrium([0.3], x0=[0.2, 0.0, 0.0])
    np.testing.assert_allclose(xe, [np.arcsin(0.3), 0.0, 2 * np.arcsin(0.3) ** 2], atol=1e-12)
    assert np.abs(model.step(xe, [0.3]) - xe).max() <= 1e-12
    with pytest.raises(cm.ModelError, match="no equilibrium"):
        model.equilibrium([1.5], x0=[0.2, 0.0, 0.0])  # sin(x0) = 1.5 has no solution


JUMP_OPS = {
    "if_else": lambda a: ca.if_else(a > 0.3, 0.05, 0.0),
    "floor": lambda a: 0.01 * ca.floor(10 * a),
    "sign": lambda a: 0.02 * ca.sign(a - 0.2),
    "fmod": lambda a: ca.fmod(a, 0.37),
    "less_than": lambda a: 0.03 * (a < 0.1),
    "fmax_step": lambda a: 0.04 * ca.ceil(a),
}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(op=st.sampled_from(sorted(JUMP_OPS)), var=st.sampled_from(["x0", "x1", "u", "w"]),
       gain=st.floats(0.1, 3.0), row=st.integers(0, 1))
def test_a_jump_makes_its_variable_enter_nonlinearly(op, var, gain, row):
    """CasADi differentiates a jump as 0, so a constant Jacobian alone would call
    x+ = A x + B u + E w + c * floor(w) affine in w (and linear), and the vertices of W would
    be taken to bound its image. Whatever the jump and the variable it acts on, the
    structure tests must say that this variable enters nonlinearly."""
    x, u, w = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("w")
    a = {"x0": x[0], "x1": x[1], "u": u, "w": w}[var] * gain
    f = ca.vertcat(x[0] + 0.1 * x[1] + 0.2 * w, x[1] + 0.1 * u)
    f[row] = f[row] + JUMP_OPS[op](a)
    M = cm.Model(x=x, u=u, w=w, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]),
                 W=cm.Box([-1], [1]))
    assert not M.is_linear
    assert M.is_affine_in_w == (var != "w")
    assert M.is_additive_in_w == (var != "w")
    assert M.is_affine_in_u == (var != "u")
    assert M.nonlinear_states == ((int(var[1]),) if var.startswith("x") else ())


def test_a_call_kept_by_never_inline_is_taken_as_nonlinear():
    """The structure tests cannot look inside a call that CasADi keeps (never_inline): they
    take every variable as entering nonlinearly (the safe side) instead of failing."""
    t = ca.SX.sym("t")
    G = ca.Function("G", [t], [2 * t], {"never_inline": True})
    x, u, w = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("w")
    M = cm.Model(x=x, u=u, w=w, f=ca.vertcat(x[0] + G(x[1]), x[1] + u + w),
                 X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]), W=cm.Box([-1], [1]))
    assert not M.is_linear and not M.is_affine_in_u and not M.is_affine_in_w
    assert M.nonlinear_states == (0, 1)
    assert "linear: False" in M.summary()


# ------------------------------------------------------------ names, units, sampling time
def _named(**kw):
    x, u, w = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("w")
    return cm.Model(x=x, u=u, w=w, f=ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * u + w),
                    X=X2, U=U1, W=cm.Box([-0.1], [0.1]), **kw)


def test_names_units_and_dt_default_and_are_stored():
    M = _named()
    assert M.state_names == ("x1", "x2") and M.input_names == ("u1",)
    assert M.disturbance_names == ("w1",) and M.units == {} and M.dt is None
    assert "sampling time: not given" in M.summary()
    M = _named(state_names=["C_A", "T"], input_names=["T_c"], disturbance_names=["q"],
               units={"C_A": "mol/l", "T": "K", "T_c": "K", "q": ""}, dt=1.8)
    assert M.state_names == ("C_A", "T") and M.input_names == ("T_c",)
    assert M.disturbance_names == ("q",)
    assert M.units == {"C_A": "mol/l", "T": "K", "T_c": "K"}  # an empty unit is no unit
    assert M.dt == 1.8
    s = M.summary()
    assert "x = (C_A [mol/l], T [K])" in s and "u = (T_c [K])" in s and "w = (q)" in s
    assert "dt = 1.8 s" in s


def test_names_of_the_wrong_length_are_refused():
    with pytest.raises(DimensionError, match="state_names .*expected 2 .* instead of 3"):
        _named(state_names=["a", "b", "c"])
    with pytest.raises(DimensionError, match="input_names .*expected 1 .* instead of 2"):
        _named(input_names=["a", "b"])
    with pytest.raises(DimensionError, match="disturbance_names .*expected 1 .* instead of 0"):
        _named(disturbance_names=[])
    with pytest.raises(TypeError, match="non-empty strings"):
        _named(state_names=["a", 3])
    with pytest.raises(TypeError, match="non-empty strings"):
        _named(state_names=["a", " "])
    with pytest.raises(ValueError, match="must all differ; repeated: a"):
        _named(state_names=["a", "b"], input_names=["a"])


@pytest.mark.parametrize("dt", [0, 0.0, -1.8, float("nan"), float("inf")])
def test_dt_must_be_positive_seconds(dt):
    with pytest.raises(ValueError, match="dt must be a positive finite number of seconds"):
        _named(dt=dt)


@pytest.mark.parametrize("dt", [True, "1.8", [1.8]])
def test_dt_must_be_a_number(dt):
    with pytest.raises(TypeError, match="dt must be a number of seconds or None"):
        _named(dt=dt)


def test_units_must_name_known_variables():
    with pytest.raises(ValueError, match="unknown variable 'T'.*x1, x2, u1, w1"):
        _named(units={"T": "K"})
    with pytest.raises(TypeError, match="mapping"):
        _named(units=["K", "K"])
    with pytest.raises(TypeError, match="unit of 'x1' must be a string"):
        _named(units={"x1": 3})


def test_from_ode_passes_names_units_and_the_sampling_time_in_seconds():
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    rhs = ca.vertcat(x[1], -x[0] + u)
    box = {"X": cm.Box([-1, -1], [1, 1]), "U": cm.Box([-1], [1])}
    m = cm.Model.from_ode(x, u, rhs, dt=0.03, time_unit=60.0, **box, state_names=["c", "T"],
                          input_names=["Tc"], units={"c": "mol/l", "T": "K", "Tc": "K"})
    assert m.dt == pytest.approx(1.8) and list(m.state_names) == ["c", "T"]
    assert m.units["T"] == "K" and list(m.input_names) == ["Tc"]
    assert cm.Model.from_ode(x, u, rhs, dt=0.1, **box).dt is None  # time unit unknown
    with pytest.raises(ValueError, match="time_unit"):
        cm.Model.from_ode(x, u, rhs, dt=0.1, time_unit=0.0, **box)
    with pytest.raises(TypeError, match="unexpected"):
        cm.Model.from_ode(x, u, rhs, dt=0.1, colour="red", **box)


@pytest.mark.parametrize("name", ["my model", "a-b", "a.b", "1a", "_a", "a__b", "a_", "aé"])
def test_a_name_casadi_cannot_carry_is_refused_at_once(name):
    """The generated functions carry the model's name: a name CasADi refuses is refused
    when the model is made, with a clear error (not at its first use, inside CasADi)."""
    x, u = ca.SX.sym("x"), ca.SX.sym("u")
    with pytest.raises(ModelError, match="is not usable"):
        cm.Model(x, u, x + u, X=cm.Box([-1], [1]), U=cm.Box([-1], [1]), name=name)
    ok = cm.Model(x, u, x + u, X=cm.Box([-1], [1]), U=cm.Box([-1], [1]), name="my_model_2")
    assert ok.name == "my_model_2" and ok.function.name().startswith("my_model_2")
