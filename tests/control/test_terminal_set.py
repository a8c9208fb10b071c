"""cm.terminal_set: the set it returns is proven again by certify_invariant, sampled points
stay in it under the closed loop, in n = 2, 3 and 4; bad input is refused."""

import doctest
import importlib

import numpy as np
import pytest
from test_law_convention import A_EQ, _pendulum  # held at 45 degrees

import casadi_cmpc as cm
from casadi_cmpc.control import terminal as terminal_module
from casadi_cmpc.control.invariance import check_about
from casadi_cmpc.exceptions import DimensionError, ModelError

cartpole = importlib.import_module("casadi_cmpc.models.cartpole")
three_tank = importlib.import_module("casadi_cmpc.models.three_tank")


def _sample_inside(P: cm.Polytope, k: int, rng: np.random.Generator) -> np.ndarray:
    """k points of P (rejection from its bounding box)."""
    bb = P.bounding_box()
    out = np.zeros((0, P.dim))
    while out.shape[0] < k:
        pts = rng.uniform(bb.lo, bb.hi, (20 * k, P.dim))
        out = np.vstack([out, pts[P.contains(pts)]])
    return out[:k]


def _check_result(model: cm.Model, res, eps: float, n_samples: int = 500) -> None:
    """The result is proven, about what it says, proven again, and holds on samples."""
    assert res.status == cm.Status.PROVED and res.success
    T = res.terminal
    assert isinstance(T, cm.Polytope) and T.dim == model.n and res.scale > 0
    assert res.certificate.proved is True
    assert check_about(res.certificate, model, T, res.W, res.law) is None
    assert res.certificate.about["robust"] == res.robust
    assert res.claim.startswith(res.certificate.claim)
    assert any(c["verdict"] == "proved" and c["scale"] == res.scale for c in res.candidates)
    assert res.nit == len(res.candidates) >= 1
    assert res.stop_reason in ("resolution", "scale_limit")
    # S inside X (rigorous bounding box) and centred at the equilibrium
    bb = T.bounding_box()
    assert np.all(bb.lo >= model.X.lo) and np.all(bb.hi <= model.X.hi)
    assert T.contains(res.x_eq)
    # proven again, independently of the search
    again = cm.certify_invariant(model, T, res.law, eps=eps, W=res.W)
    assert again.proved is True, again.reason
    # sampled points and disturbances: the successor stays in S, the input in U
    rng = np.random.default_rng(0)
    x = _sample_inside(T, n_samples, rng)
    law = cm.LinearLaw(res.law.K, res.law.x_eq, res.law.u_eq)
    u = np.array([law(xi) for xi in x])
    w = rng.uniform(res.W.lo, res.W.hi, (n_samples, model.l)) if model.l else None
    if w is not None:  # the corners of W too
        w[: 2 ** model.l] = res.W.vertices()
    nxt = model.step(x, u, w)
    tol = 1e-9 * (1.0 + np.abs(T.b).max())
    assert T.contains(nxt, tol=tol).all()
    assert model.U.contains(u).all()


def test_two_states_non_zero_equilibrium():
    model = _pendulum()
    xe, ue = np.array([A_EQ, 0.0]), np.array([-np.sin(A_EQ)])
    res = cm.terminal_set(model, x_eq=xe, u_eq=ue, progress=False)
    assert isinstance(res, cm.TerminalSetResult) and isinstance(res, cm.Result)
    assert np.array_equal(res.x_eq, xe) and np.allclose(res.u_eq, ue)
    assert isinstance(res.law, cm.LinearLaw) and np.array_equal(res.law.x_eq, xe)
    # the default law is the LQR law at the equilibrium with Bryson's weights
    dx = np.minimum(xe - model.X.lo, model.X.hi - xe)
    du = np.minimum(ue - model.U.lo, model.U.hi - ue)
    lqr = cm.local_lqr(model, np.diag(1 / dx ** 2), np.diag(1 / du ** 2), x_eq=xe, u_eq=ue)
    np.testing.assert_allclose(res.law.K, lqr.K, rtol=1e-9)
    assert not res.robust and res.W is None
    assert set(res.contraction) == {"ellipsoid", "parallelotope", "modal"}
    # "auto" searched every contracting shape and kept the largest proven set
    searched = res.stats["searches"]
    assert set(searched) == {k for k, g in res.contraction.items() if g < 1}
    vol = {k: s["unit_volume"] * s["scale"] ** 2 for k, s in searched.items()}
    assert vol[res.shape] == max(vol.values())
    _check_result(model, res, eps=0.002)


def test_given_law_and_shape_and_the_search_bounds():
    model = _pendulum()
    xe, ue = np.array([A_EQ, 0.0]), np.array([-np.sin(A_EQ)])
    law = cm.local_lqr(model, np.eye(2), 1.0, x_eq=xe, u_eq=ue)
    res = cm.terminal_set(model, law, shape="parallelotope", max_scale=0.2, progress=False)
    assert res.law is law and res.shape == "parallelotope"
    assert res.scale <= res.scale_limit <= 0.2
    assert res.unit.A.shape == (4, 2)  # a parallelotope: two pairs of opposite rows
    # the unit set circumscribes the Lyapunov ellipsoid {dx' P dx <= 1}
    lam, V = np.linalg.eigh(res.P)
    axes = V / np.sqrt(lam)  # the semi-axes, as columns
    assert res.unit.contains(np.hstack([axes, -axes]).T, tol=1e-9).all()
    _check_result(model, res, eps=0.002)


def test_three_states_robust():
    model = three_tank.three_tank_model()
    x_eq = model.equilibrium([three_tank.Q_EQ], x0=three_tank.continuous_equilibrium())
    res = cm.terminal_set(model, x_eq=x_eq, u_eq=[three_tank.Q_EQ], shape="parallelotope",
                          progress=False)
    assert res.robust and res.W == model.W
    assert "robustly" in res.message and res.certificate.about["robust"] is True
    assert np.any(res.law.x_eq != 0)  # a law about a non-zero equilibrium
    _check_result(model, res, eps=0.02 * float(np.max(res.terminal.bounding_box().rad)))


def test_four_states_cartpole():
    model = cartpole.cartpole_model()
    res = cm.terminal_set(model, Q=cartpole.LQR_Q, R=cartpole.LQR_R, eps=0.02, rtol=0.2,
                          progress=False)
    # only the modal box contracts for the linearisation: "auto" searches it alone
    assert res.contraction["modal"] < 1 <= min(res.contraction["ellipsoid"],
                                               res.contraction["parallelotope"])
    assert res.shape == "modal" and list(res.stats["searches"]) == ["modal"]
    assert res.robust and res.unit.A.shape == (8, 4)
    _check_result(model, res, eps=0.02 * float(np.max(res.terminal.bounding_box().rad)))


def test_nothing_proven_is_never_claimed():
    model = cartpole.cartpole_model()
    # a disturbance the linearisation cannot absorb inside X and U: no candidate at all
    res = cm.terminal_set(model, W=cm.Box([-2.0], [2.0]), progress=False)
    assert res.status == cm.Status.UNDECIDED and not res.success
    assert res.terminal is None and res.certificate is None and res.scale == 0.0
    assert res.stop_reason == "min_scale" and res.claim == ""
    assert "absorbs W only from" in res.message
    assert res.stats["disturbance_floor"] > res.scale_limit
    # budgets that run out before any proof: BUDGET, nothing claimed
    pend, xe, ue = _pendulum(), [A_EQ, 0.0], [-np.sin(A_EQ)]
    res = cm.terminal_set(pend, x_eq=xe, u_eq=ue, time_limit=1e-9, progress=False)
    assert res.status == cm.Status.BUDGET and res.stop_reason == "time_limit"
    assert res.terminal is None and res.nit == 0 and "time_limit" in res.message
    # the largest scale allowed is not invariant (the law reaches U's bound there)
    res = cm.terminal_set(pend, x_eq=xe, u_eq=ue, shape="ellipsoid", max_candidates=1,
                          progress=False)
    assert res.candidates[0]["verdict"] != "proved"
    assert res.status == cm.Status.BUDGET and res.stop_reason == "max_candidates"
    assert res.terminal is None and res.certificate is None


def test_nominal_proof_on_a_model_with_w():
    model = three_tank.three_tank_model()
    x_eq = model.equilibrium([three_tank.Q_EQ], x0=three_tank.continuous_equilibrium())
    res = cm.terminal_set(model, x_eq=x_eq, u_eq=[three_tank.Q_EQ], W=cm.Box([0.0], [0.0]),
                          shape="modal", rtol=0.3, progress=False)
    assert res.success and not res.robust
    assert "nominally at w = [0.0] only" in res.message
    assert res.certificate.about["robust"] is False


def test_refused_inputs():
    model = _pendulum()
    xe, ue = [A_EQ, 0.0], [-np.sin(A_EQ)]
    with pytest.raises(DimensionError, match="shape"):
        cm.terminal_set(model, np.zeros((1, 3)), x_eq=xe)  # wrong law shape
    with pytest.raises(DimensionError):
        cm.terminal_set(model, x_eq=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="not an equilibrium"):
        cm.terminal_set(model, x_eq=[0.5, 0.0], u_eq=[0.0])
    law = cm.local_lqr(model, np.eye(2), 1.0, x_eq=xe, u_eq=ue)
    with pytest.raises(ValueError, match="not an equilibrium"):
        cm.terminal_set(model, cm.LinearLaw(law.K, xe, [0.0]))  # law(x_eq) is not u_eq
    with pytest.raises(ValueError, match="not u_eq"):
        cm.terminal_set(model, law, u_eq=[0.3])
    with pytest.raises(ValueError, match="differs from the law's x_eq"):
        cm.terminal_set(model, law, x_eq=[0.7, 0.0])
    with pytest.raises(ValueError, match="bare gain"):
        cm.terminal_set(model, np.asarray(law), x_eq=xe)  # u = K x, about the origin
    with pytest.raises(ValueError, match="does not stabilise"):
        cm.terminal_set(model, cm.LinearLaw([[0.0, 0.0]], xe, ue))
    with pytest.raises(ValueError, match="interior"):
        cm.terminal_set(model, x_eq=[A_EQ + 1.0, 0.0], u_eq=[-np.sin(A_EQ + 1.0)])
    with pytest.raises(ValueError, match="shape must be one of"):
        cm.terminal_set(model, x_eq=xe, u_eq=ue, shape="sphere")
    with pytest.raises(ModelError, match="no disturbance"):
        cm.terminal_set(model, x_eq=xe, u_eq=ue, W=cm.Box([0.0], [0.0]))
    with pytest.raises(TypeError):
        cm.terminal_set("pendulum")
    with pytest.raises(ValueError, match="rtol"):
        cm.terminal_set(model, x_eq=xe, u_eq=ue, rtol=0.0)


def test_docstring_example():
    result = doctest.testmod(terminal_module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0


def test_disturbance_floor_is_per_facet():
    """The linearisation's floor is max_i push_i / (1 - gamma_i), facet by facet: a model
    whose disturbance acts only on its fast mode (3 states, equilibrium away from 0) gets
    a robust terminal set, which certify_invariant proves again (with the floor formed
    from the slowest facet's contraction and the fastest facet's push, 0.3 / (1 - 0.97) =
    10, the search stopped before its first candidate)."""
    import casadi as ca

    xs, us = np.array([1.5, -0.7, 2.0]), np.array([0.2])
    x, u, w = ca.SX.sym("x", 3), ca.SX.sym("u"), ca.SX.sym("w")
    A = np.diag([0.3, 0.97, 0.9])
    f = xs + ca.mtimes(ca.DM(A), x - xs) + 0.1 * (u - us[0]) + ca.vertcat(w, 0, 0)
    m = cm.Model(x=x, u=u, w=w, f=f, X=cm.Box(xs - 1, xs + 1), U=cm.Box([-1], [1]),
                 W=cm.Box([-0.3], [0.3]))
    law = cm.LinearLaw(np.zeros((1, 3)), xs, us)
    Au = np.vstack([np.eye(3), -np.eye(3)])
    floor = terminal_module._disturbance_floor(m, Au, A, m.W, xs, us, np.zeros(1))
    assert floor == pytest.approx(0.3 / 0.7)  # the fast facet x_0: 0.3 s + 0.3 <= s
    res = cm.terminal_set(m, law, shape="modal", progress=False)
    _check_result(m, res, eps=0.05)


def _scaled_model3(s: float) -> tuple[cm.Model, np.ndarray, np.ndarray]:
    """A 3-state model with a non-zero equilibrium (1, -0.5, 2), u_eq = 2.25, an additive
    w on x3, in the coordinates ``z = s x``."""
    import casadi as ca

    z, u, w = ca.SX.sym("x", 3), ca.SX.sym("u"), ca.SX.sym("w")
    x = z / s
    f = ca.vertcat(x[0] + 0.1 * x[1] + 0.05 + 0.02 * ca.sin(x[2] - 2),
                   x[1] + 0.1 * x[2] - 0.2 - 0.05 * (x[0] - 1) ** 2,
                   0.9 * x[2] + 0.1 * u + 0.05 * x[0] * x[1] + w)
    lo, hi = np.array([0.0, -1.5, 1.0]), np.array([2.0, 0.5, 3.0])
    m = cm.Model(x=z, u=u, w=w, f=f * s, X=cm.Box(lo * s, hi * s), U=cm.Box([0.0], [4.5]),
                 W=cm.Box([-0.005], [0.005]), name="m3")
    return m, np.array([1.0, -0.5, 2.0]) * s, np.array([2.25])


@pytest.mark.parametrize("s", [1e-3, 1e3])
def test_terminal_set_does_not_depend_on_the_units_of_the_states(s):
    """The states in other units (z = s x): the same scale of the same shape is proven
    (the candidates' LPs are scaled; unscaled, HiGHS failed at s = 1e-3 and nothing was
    tried)."""
    ref_m, xe, ue = _scaled_model3(1.0)
    ref = cm.terminal_set(ref_m, cm.local_lqr(ref_m, Q=100 * np.eye(3), R=1.0, x_eq=xe,
                                              u_eq=ue), progress=False)
    m, xe, ue = _scaled_model3(s)
    res = cm.terminal_set(m, cm.local_lqr(m, Q=100 * np.eye(3) / s ** 2, R=1.0, x_eq=xe,
                                          u_eq=ue), progress=False)
    assert ref.status == res.status == cm.Status.PROVED
    assert res.scale == pytest.approx(ref.scale, rel=1e-6)
    assert res.scale_limit == pytest.approx(ref.scale_limit, rel=1e-6)
