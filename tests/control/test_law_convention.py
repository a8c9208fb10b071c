"""One law convention everywhere: ``u = u_eq + K (x - x_eq)`` carried by a LinearLaw, a
bare gain meaning ``u = K x``; a law other than the proven one is refused."""

import casadi as ca
import numpy as np
import pytest
import scipy.linalg as sl
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.control.invariance import law_identity
from casadi_cmpc.control.law import law_expr

A_EQ = np.pi / 4  # the pendulum is held at 45 degrees by a constant torque


def _pendulum() -> cm.Model:
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * (ca.sin(x[0]) - 0.2 * x[1] + u))
    return cm.Model(x=x, u=u, f=f, X=cm.Box([A_EQ - 1, -1.5], [A_EQ + 1, 1.5]),
                    U=cm.Box([-2.5], [1.0]), name="pendulum_45")


@pytest.fixture(scope="module")
def setup():
    model = _pendulum()
    xe, ue = np.array([A_EQ, 0.0]), np.array([-np.sin(A_EQ)])
    law = cm.local_lqr(model, np.eye(2), 1.0, x_eq=xe, u_eq=ue)
    A = np.asarray(model.jacobian_function("x")(xe, ue, np.zeros(0)))
    B = np.asarray(model.jacobian_function("u")(xe, ue, np.zeros(0)))
    P = sl.solve_discrete_lyapunov((A + B @ law.K).T, np.eye(2))
    th = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    H = np.stack([np.cos(th), np.sin(th)], 1) @ np.linalg.cholesky(P).T
    T = cm.Polytope(H, 0.15 + H @ xe)  # a polygon around a Lyapunov level set at x_eq
    seq = cm.controllable_sets(model, T, 0.02, robust=False, law=law, max_steps=3)
    return model, xe, ue, law, T, seq


def test_local_lqr_returns_the_law_with_its_equilibrium(setup):
    model, xe, ue, law, _, _ = setup
    assert isinstance(law, cm.LinearLaw)
    assert np.array_equal(law.x_eq, xe) and np.array_equal(law.u_eq, ue)
    assert np.array_equal(law(xe), ue)  # at the equilibrium the law gives u_eq
    assert np.asarray(law).shape == (1, 2)  # the gain alone
    A = np.asarray(model.jacobian_function("x")(xe, ue, np.zeros(0)))
    B = np.asarray(model.jacobian_function("u")(xe, ue, np.zeros(0)))
    assert np.abs(np.linalg.eigvals(A + B @ law.K)).max() < 1


def test_certify_invariant_applies_the_equilibrium(setup):
    model, xe, ue, law, T, _ = setup
    c = cm.certify_invariant(model, T, law, eps=3e-4)
    assert c.proved is True
    rng = np.random.default_rng(0)
    box = T.bounding_box()
    pts = rng.uniform(box.lo, box.hi, (4000, 2))
    pts = pts[T.contains(pts)]
    us = ue + (pts - xe) @ law.K.T
    assert T.contains(model.step(pts, us)).all()
    assert model.U.contains(us).all()
    # the same gain as a bare matrix is u = K x: far from u_eq near x_eq, refuted there
    bare = cm.certify_invariant(model, T, np.asarray(law), eps=3e-4)
    assert bare.proved is False
    xc = bare.counterexample
    uc = np.asarray(law) @ xc
    assert T.contains(xc[None])[0]
    assert not (T.contains(model.step(xc[None], uc[None]))[0] and model.U.contains(uc))


def test_set_sequence_mpc_drives_the_proven_law_with_no_violation(setup):
    model, xe, _, law, T, seq = setup
    assert seq.info["terminal_certificate"] == "proved"
    assert seq.info["terminal_law_key"] == law_identity(model, law)["law_key"]
    ctrl = cm.SetSequenceMPC(model, seq)  # the proven law by default
    same = cm.SetSequenceMPC(model, seq, local_law=law)  # the same law is accepted
    rng = np.random.default_rng(1)
    pts = rng.uniform(model.X.lo, model.X.hi, (4000, 2))
    top = len(seq) - 1
    x0s = [p for p in pts if seq.level(p) == top][:2]
    assert x0s, "no sample point in the largest set"
    for x0 in x0s:
        for c in (ctrl, same):
            c.reset()
            traj = cm.simulate(model, c, x0, 40)
            assert traj.violations["state"] == 0 and traj.violations["input"] == 0
            assert T.contains(traj.x[-1][None])[0]
            assert np.abs(traj.x[-1] - xe).max() < 0.05
    with pytest.raises(ValueError, match="not the law the terminal set was proven"):
        cm.SetSequenceMPC(model, seq, local_law=np.asarray(law))


def test_contractive_mpc_refuses_a_bare_gain_at_a_nonzero_reference(setup):
    model, xe, ue, law, T, _ = setup
    with pytest.raises(ValueError, match="bare gain"):
        cm.ContractiveMPC(model, horizon=3, x_ref=xe, u_ref=ue, local_law=np.asarray(law),
                          local_set=T)
    ctrl = cm.ContractiveMPC(model, horizon=3, x_ref=xe, u_ref=ue, local_law=law,
                             local_set=T)
    x = xe + np.array([0.01, -0.02])
    assert np.allclose(np.asarray(ctrl._law(x)).ravel(), law(x), rtol=0, atol=1e-15)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 4), m=st.integers(1, 2), seed=st.integers(0, 2**31 - 1))
def test_every_form_of_a_law_is_one_expression(n, m, seed):
    """LinearLaw, its expression and (at the origin) the bare gain agree everywhere, and
    two laws share a key exactly when they are the same expression."""
    rng = np.random.default_rng(seed)
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u", m)
    model = cm.Model(x=x, u=u, f=x + ca.DM(rng.normal(size=(n, m))) @ u,
                     X=cm.Box(-np.ones(n), np.ones(n)), U=cm.Box(-np.ones(m), np.ones(m)))
    K = rng.normal(size=(m, n))
    xe, ue = rng.normal(size=n), rng.normal(size=m)
    law = cm.LinearLaw(K, xe, ue)
    fun = ca.Function("u", [model.x], [law_expr(model, law)])
    for p in rng.normal(size=(5, n)):
        expect = ue + K @ (p - xe)
        assert np.allclose(np.asarray(fun(p)).ravel(), expect, rtol=1e-14, atol=1e-14)
        assert np.allclose(law(p), expect, rtol=1e-14, atol=1e-14)
    origin = cm.LinearLaw(K)
    assert law_identity(model, origin)["law_key"] == law_identity(model, K)["law_key"]
    assert law_identity(model, law)["law_key"] != law_identity(model, K)["law_key"]
    assert law_identity(model, law)["law_key"] == law_identity(
        model, cm.LinearLaw(K.copy(), xe.copy(), ue.copy()))["law_key"]


def test_bad_laws_are_refused_clearly():
    with pytest.raises(cm.exceptions.DimensionError, match="x_eq"):
        cm.LinearLaw(np.ones((1, 2)), x_eq=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="NaN"):
        cm.LinearLaw([[np.nan, 1.0]])
    model = _pendulum()
    with pytest.raises(cm.exceptions.DimensionError, match="shape"):
        law_expr(model, cm.LinearLaw(np.ones((1, 3))))
    with pytest.raises(cm.exceptions.DimensionError, match="shape"):
        model.closed_loop(np.ones((1, 3)))
    y = ca.SX.sym("y")
    with pytest.raises(cm.exceptions.FreeSymbolError, match="x only"):
        law_expr(model, y * model.x[0])


def test_closed_loop_applies_the_law_with_its_equilibrium(setup):
    model, xe, ue, law, _, _ = setup
    cl = model.closed_loop(law)
    rng = np.random.default_rng(3)
    pts = xe + 0.1 * rng.normal(size=(20, 2))
    expect = model.step(pts, ue + (pts - xe) @ law.K.T)
    np.testing.assert_allclose(cl.step(pts), expect, rtol=1e-14, atol=1e-14)
    assert tuple(cl.state_names) == tuple(model.state_names)
