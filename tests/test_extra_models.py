"""The examples not from the thesis (cartpole, three_tank): equations, equilibrium, the
stored terminal set proven again, and closed loops of the local law that stay in it."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.cli import main
from casadi_cmpc.control.invariance import check_about

cartpole = importlib.import_module("casadi_cmpc.models.cartpole")
three_tank = importlib.import_module("casadi_cmpc.models.three_tank")

EXTRA = ["cartpole", "three_tank"]


@pytest.fixture(scope="module", params=EXTRA)
def example(request) -> cm.models.Example:
    return cm.models.load(request.param)


def _rk4(rhs, x: np.ndarray, u: float, w: float, dt: float) -> np.ndarray:
    k1 = rhs(x, u, w)
    k2 = rhs(x + dt / 2 * k1, u, w)
    k3 = rhs(x + dt / 2 * k2, u, w)
    k4 = rhs(x + dt * k3, u, w)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _cartpole_rhs(x: np.ndarray, u: float, w: float) -> np.ndarray:
    """Florian (2007), frictionless, written out independently of the module."""
    _, v, th, om = x
    mc, mp, ll, g = 1.0, 0.1, 0.5, 9.81
    s, c = np.sin(th), np.cos(th)
    tot = mc + mp
    acc_th = (g * s - c * (u + w + mp * ll * om ** 2 * s) / tot) / (
        ll * (4 / 3 - mp * c ** 2 / tot))
    acc_p = (u + w + mp * ll * (om ** 2 * s - acc_th * c)) / tot
    return np.array([v, acc_p, om, acc_th])


def _tank_rhs(x: np.ndarray, u: float, w: float) -> np.ndarray:
    q = np.array([0.25, 0.225, 0.2]) * np.sqrt(2 * 981.0 * x)
    return np.array([u + w - q[0], q[0] - q[1], q[1] - q[2]]) / 154.0


def test_registered_and_listed(capsys):
    names = cm.models.names()
    assert names[-3:] == EXTRA + ["moore_greitzer"]  # then the validated ODE model
    assert main(["list"]) == 0
    lines = {ln.split()[0]: ln for ln in capsys.readouterr().out.splitlines()}
    assert "4 states, 1 input, 1 disturbance" in lines["cartpole"]
    assert "3 states, 1 input, 1 disturbance" in lines["three_tank"]
    for name in EXTRA:
        assert " extra " in lines[name] and "certified terminal set" in lines[name]
        assert "not from the thesis" in lines[name]


def test_load_sizes_names_units(example):
    model = example.model
    n = {"cartpole": 4, "three_tank": 3}[example.name]
    assert (model.n, model.m, model.l) == (n, 1, 1)
    assert example.info["example"] == "extra" and isinstance(example.info["choices"], dict)
    assert all(v in model.units for v in model.state_names + model.input_names)
    assert isinstance(example.local_law, cm.LinearLaw)
    assert example.local_law.shape == (1, n)
    assert isinstance(example.terminal, cm.Polytope) and example.terminal.dim == n
    assert example.x0s.shape == (1, n) and model.X.contains(example.x0s).all()
    assert not example.terminal.contains(example.x0s[0])
    a = cm.models.load(example.name)
    assert a.model is not example.model  # fresh on every load
    assert np.array_equal(a.terminal.A, example.terminal.A)


def test_cartpole_equations():
    ex = cm.models.load("cartpole")
    model = ex.model
    assert model.dt == 0.05 and model.units["theta"] == "rad" and model.units["F"] == "N"
    np.testing.assert_array_equal(model.U.as_array(), [[-10.0, 10.0]])
    np.testing.assert_array_equal(model.W.as_array(), [[-0.02, 0.02]])
    rng = np.random.default_rng(1)
    x = rng.uniform(model.X.lo, model.X.hi, (20, 4))
    u = rng.uniform(-10, 10, 20)
    w = rng.uniform(-0.02, 0.02, 20)
    expected = np.array([_rk4(_cartpole_rhs, xi, ui, wi, 0.05) for xi, ui, wi in
                         zip(x, u, w, strict=True)])
    np.testing.assert_allclose(model.step(x, u[:, None], w[:, None]), expected, rtol=1e-12,
                               atol=1e-12)
    # upright at rest is an equilibrium; it is unstable, and a push to +p tips the pole
    # towards -p (theta < 0)
    model.check_equilibrium(np.zeros(4), np.zeros(1), np.zeros(1))
    A = np.asarray(model.jacobian_function("x")(np.zeros(4), 0.0, 0.0))
    assert np.abs(np.linalg.eigvals(A)).max() > 1
    assert model.step(np.zeros(4), [5.0], [0.0])[3] < 0
    assert np.abs(np.linalg.eigvals(A + np.asarray(model.jacobian_function("u")(
        np.zeros(4), 0.0, 0.0)) @ ex.local_law.K)).max() < 1


def test_three_tank_equations_and_equilibrium():
    ex = cm.models.load("three_tank")
    model = ex.model
    assert model.dt == 5.0 and model.units["h1"] == "cm" and model.units["q"] == "cm^3/s"
    rng = np.random.default_rng(2)
    x = rng.uniform(model.X.lo, model.X.hi, (20, 3))
    u = rng.uniform(0, 100, 20)
    w = rng.uniform(-0.5, 0.5, 20)
    expected = np.array([_rk4(_tank_rhs, xi, ui, wi, 5.0) for xi, ui, wi in
                         zip(x, u, w, strict=True)])
    np.testing.assert_allclose(model.step(x, u[:, None], w[:, None]), expected, rtol=1e-12,
                               atol=1e-12)
    # a non-zero equilibrium: the levels of the continuous system, held by q = 50 cm^3/s
    law = ex.local_law
    np.testing.assert_allclose(law.x_eq, [(50 / c) ** 2 / (2 * 981.0)
                                          for c in (0.25, 0.225, 0.2)], rtol=1e-12)
    assert law.u_eq.tolist() == [50.0]
    model.check_equilibrium(law.x_eq, law.u_eq, np.zeros(1))
    assert np.array_equal(ex.info["mpc"]["x_ref"], law.x_eq)


def test_stored_terminal_set_is_certified_again(example):
    """The stored numbers (computed once by cm.terminal_set) are proven again."""
    model, T, law = example.model, example.terminal, example.local_law
    bb = T.bounding_box()
    assert np.all(bb.lo >= model.X.lo) and np.all(bb.hi <= model.X.hi)  # S inside X
    eps = 0.02 * float(np.max(bb.rad))
    cert = cm.certify_invariant(model, T, law, eps=eps)  # robust: over the model's W
    assert cert.proved is True, cert.reason
    assert cert.about["robust"] is True
    assert check_about(cert, model, T, model.W, law) is None
    assert T.contains(law.x_eq)


def test_local_law_keeps_sampled_states_inside_for_50_steps(example):
    model, T, law = example.model, example.terminal, example.local_law
    rng = np.random.default_rng(3)
    V = T.vertices()
    x0s = rng.dirichlet(np.ones(len(V)), 4) @ V  # convex combinations of the vertices
    assert T.contains(x0s).all()
    tol = 1e-9 * (1.0 + np.abs(T.b).max())
    for i, x0 in enumerate(x0s):
        traj = cm.simulate(model, law, x0, 50, disturbance="uniform", seed=i,
                           progress=False)
        assert traj.x.shape == (51, model.n)
        assert T.contains(traj.x, tol=tol).all()
        assert model.U.contains(traj.u).all()
        assert np.all(np.abs(traj.w) <= model.W.hi)


def test_compute_terminal_reproduces_the_stored_numbers():
    """The three-tank constants are what cm.terminal_set returns (2-3 s), up to the last
    bits of the LQR gain, which LAPACK computes differently on different CPUs."""
    res = three_tank.compute_terminal()
    ex = cm.models.load("three_tank")
    assert res.success and res.robust and res.shape == "parallelotope"
    np.testing.assert_allclose(res.law.K, ex.local_law.K, rtol=1e-10)
    np.testing.assert_array_equal(res.law.x_eq, ex.local_law.x_eq)
    np.testing.assert_array_equal(res.law.u_eq, ex.local_law.u_eq)
    np.testing.assert_allclose(res.terminal.A, ex.terminal.A, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(res.terminal.b, ex.terminal.b, rtol=1e-9)
    assert res.scale == pytest.approx(three_tank.SCALE, rel=1e-9)


def test_cartpole_constants_match_the_local_lqr():
    model = cartpole.cartpole_model()
    law = cm.local_lqr(model, cartpole.LQR_Q, cartpole.LQR_R)
    np.testing.assert_allclose(law.K, cartpole.K_LOCAL, rtol=1e-10)
    T = cartpole.terminal_set()
    assert T.A.shape == (8, 4) and np.all(T.b == cartpole.SCALE)

