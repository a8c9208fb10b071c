"""Contractive MPC (thesis §4.3, Alg 4.5): verified sequences, horizon search, proofs."""

from __future__ import annotations

from fractions import Fraction

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.exceptions import DimensionError, ModelError
from casadi_cmpc.mpc.contractive import ContractiveMPC


def _norm(e: np.ndarray, p: float) -> float:
    return float(np.linalg.norm(e, ord=p))


def _check_sequence(model, x0, useq, alpha, p, x_ref=None, C=None):
    """Float re-simulation of a verified sequence: X, U and the contraction hold."""
    x_ref = np.zeros(model.n) if x_ref is None else np.asarray(x_ref)
    C = np.eye(model.n) if C is None else C
    assert ((useq >= model.U.lo) & (useq <= model.U.hi)).all()
    x = np.asarray(x0, float)
    for u in useq:
        x = model.step(x, u)
        assert ((x >= model.X.lo) & (x <= model.X.hi)).all()
    assert _norm(C @ (x - x_ref), p) <= alpha * _norm(C @ (np.asarray(x0) - x_ref), p) + 1e-12


@pytest.fixture(scope="module")
def cannon():
    return cm.models.load("cannon").model


@pytest.mark.parametrize("solver", ["ipopt", "sqp"])
@pytest.mark.parametrize("p", [1, 2, np.inf])
def test_verified_sequence_satisfies_constraints(cannon, solver, p):
    ctrl = ContractiveMPC(cannon, horizon=6, alpha=0.8, norm=p, solver=solver)
    for x0 in ([0.3, -0.2], [1.9, -1.5], [-1.0, 1.2]):
        r = ctrl.solve(x0)
        assert r.certificate.label == "verified" and r.certificate.proved is True
        assert r.success and r.status == cm.Status.PROVED
        assert r.u_seq.shape == (6, 1) and r.x_pred.shape == (7, 2)
        _check_sequence(cannon, x0, r.u_seq, 0.8, p)
        # the prediction is the float simulation of the sequence
        x = np.asarray(x0, float)
        for i, u in enumerate(r.u_seq):
            x = cannon.step(x, u)
            np.testing.assert_allclose(r.x_pred[i + 1], x, rtol=1e-12, atol=1e-14)
        assert r.certificate.details["contraction_upper"] <= 0


def test_cost_matches_formula(cannon):
    Q, R, P = np.diag([1.0, 2.0]), np.array([[0.5]]), np.diag([3.0, 1.0])
    ctrl = ContractiveMPC(cannon, horizon=4, alpha=0.9, Q=Q, R=R, P=P)
    x0 = np.array([0.8, -0.4])
    r = ctrl.solve(x0)
    xs = r.x_pred
    want = sum(float(u @ R @ u) for u in r.u_seq)
    want += sum(float(x @ Q @ x) for x in xs[1:-1]) + float(xs[-1] @ P @ xs[-1])
    assert r.cost == pytest.approx(want, rel=1e-9)


def test_first_move_and_warm_start(cannon):
    ctrl = ContractiveMPC(cannon, horizon=5, alpha=0.9, solver="sqp", mode="receding")
    x = np.array([1.5, -1.0])
    us = []
    for _ in range(40):
        u = ctrl(x)
        assert u.shape == (1,)
        assert ctrl.last_info["certificate"] == "verified"
        assert ctrl.last_info["horizon"] == 5
        us.append(u)
        x = cannon.step(x, u)
    assert np.abs(x).max() < 0.15


def test_default_mode_carries_the_closed_loop_guarantee(cannon):
    """The default (sequence) mode: at the j-th solve instant the contracted distance is at
    most alpha^j times the first one, as its guarantee says; receding mode says that it
    promises the plan only."""
    ctrl = ContractiveMPC(cannon, horizon=4, alpha=0.8)
    assert ctrl.mode == "sequence" and "shrinks by the factor" in ctrl.guarantee
    x = np.array([1.2, -0.8])
    d0, solves = float(np.linalg.norm(x)), 0
    for _ in range(24):
        u = ctrl(x)
        if ctrl.last_info["mode"] == "mpc":
            assert ctrl.last_info["certificate"] == "verified"
            assert np.linalg.norm(x) <= 0.8 ** solves * d0 * (1 + 1e-9)
            solves += 1
        x = cannon.step(x, u)
    assert solves == 6  # one solve per plan of 4 moves
    rec = ContractiveMPC(cannon, horizon=4, alpha=0.8, mode="receding")
    assert "NOT guaranteed" in rec.guarantee and "plan" in rec.guarantee


def test_sequence_mode_applies_whole_sequence(cannon):
    ctrl = ContractiveMPC(cannon, horizon=4, alpha=0.9, mode="sequence")
    x = np.array([1.0, -0.5])
    r = None
    modes = []
    for _ in range(8):
        u = ctrl(x)
        if ctrl.last_info["mode"] == "mpc":
            r = ctrl.last_result
            assert np.array_equal(u, r.u_seq[0])
            k = 0
        else:
            k += 1
            assert np.array_equal(u, r.u_seq[k])
        modes.append(ctrl.last_info["mode"])
        x = cannon.step(x, u)
    assert modes == ["mpc", "sequence", "sequence", "sequence"] * 2


def test_terminal_polytope_constraint(cannon):
    T = cm.models.load("cannon").terminal
    ctrl = ContractiveMPC(cannon, horizon=8, alpha=0.9, terminal=T)
    r = ctrl.solve([1.2, -0.6])
    assert r.certificate.label == "verified"
    assert T.contains(r.x_pred[-1][None, :])[0]
    # exact check of the terminal rows in rationals
    xN = [Fraction(v) for v in r.x_pred[-1]]
    for a, b in zip(T.A, T.b, strict=True):
        assert sum(Fraction(ai) * xi for ai, xi in zip(a, xN, strict=True)) <= Fraction(b)


def test_path_constraints_hold():
    # a 3-state model, obstacle-like constraint on (x1, x2)
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u", 2)
    f = ca.vertcat(x[0] + 0.1 * u[0], x[1] + 0.1 * u[1], 0.9 * x[2] + 0.05 * x[0])
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-3] * 3, [3] * 3), U=cm.Box([-1, -1], [1, 1]))
    g = 0.3 ** 2 - ((x[0] - 1.0) ** 2 + (x[1] - 0.9) ** 2)  # keep out of a disc
    ctrl = ContractiveMPC(model, horizon=6, alpha=0.95, constraints=g)
    xk = np.array([2.0, 1.8, 0.0])
    for _ in range(60):
        r = ctrl.solve(xk)
        assert r.certificate.label == "verified"
        for xp in r.x_pred[1:]:
            assert (xp[0] - 1.0) ** 2 + (xp[1] - 0.9) ** 2 >= 0.3 ** 2
        xk = model.step(xk, r.u)
    assert np.abs(xk).max() < 0.2


def test_grimm_horizon_search_proves_short_horizons_infeasible():
    ex = cm.models.load("grimm")
    ctrl = ContractiveMPC(ex.model, horizon=None, alpha=0.5, horizon_max=4)
    r = ctrl.solve([2.0, 2.0])
    assert r.certificate.label == "verified" and r.horizon == 2
    proofs = r.certificate.details["proofs"]
    assert proofs[0]["horizon"] == 1 and proofs[0]["result"] == "infeasible"
    assert proofs[0]["boxes"] >= 1 and proofs[0]["elapsed"] >= 0
    # horizon 1 really is infeasible: min_u |x+|^2 / |x|^2 = x1^2 / (x1^2 + |x|^2) = 1/3
    us = np.linspace(0, 1, 2001)
    nxt = ex.model.step(np.tile([2.0, 2.0], (us.size, 1)), us[:, None])
    assert (np.linalg.norm(nxt, axis=1) > 0.5 * np.linalg.norm([2.0, 2.0])).all()


def test_grimm_closed_loop_converges_verified():
    ex = cm.models.load("grimm")
    model = ex.model
    ctrl = ContractiveMPC(model, horizon=None, alpha=0.5, horizon_max=4)
    x = ex.x0s[0].copy()
    for _ in range(60):
        u = ctrl(x)
        assert ctrl.last_info["certificate"] == "verified"
        x = model.step(x, u)
        assert ((x >= model.X.lo) & (x <= model.X.hi)).all()
        if np.abs(x).max() < 1e-3:
            break
    assert np.abs(x).max() < 1e-3


def test_unreachable_contraction_is_proved_infeasible():
    x = ca.SX.sym("x")
    u = ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=2 * x + u, X=cm.Box([-50], [50]), U=cm.Box([-0.1], [0.1]))
    ctrl = ContractiveMPC(model, horizon=None, alpha=0.9, horizon_max=3)
    r = ctrl.solve([1.0])
    assert r.certificate.label == "proved_infeasible"
    assert r.certificate.proved is False and r.status == cm.Status.DISPROVED
    proofs = r.certificate.details["proofs"]
    assert [p["horizon"] for p in proofs] == [1, 2, 3]
    assert all(p["result"] == "infeasible" for p in proofs)
    # ground truth: |x_N| >= 2^N - 0.1 (2^N - 1) > 0.9 for every sequence
    for N in (1, 2, 3):
        assert 2 ** N - 0.1 * (2 ** N - 1) > 0.9
    # a fixed horizon gets the same proof
    r2 = ContractiveMPC(model, horizon=2, alpha=0.9).solve([1.0])
    assert r2.certificate.label == "proved_infeasible"


@pytest.mark.parametrize("p", [1, np.inf])
def test_lp_form_proves_infeasibility_with_farkas_certificates(p):
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(2 * x[0] + 0.1 * x[1], 1.5 * x[1] + u)
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-50, -50], [50, 50]), U=cm.Box([-0.1], [0.1]))
    ctrl = ContractiveMPC(model, horizon=None, alpha=0.9, norm=p, solver="lp", horizon_max=4)
    r = ctrl.solve([1.0, 0.5])
    assert r.certificate.label == "proved_infeasible"
    proofs = r.certificate.details["proofs"]
    assert [q["horizon"] for q in proofs] == [1, 2, 3, 4]
    assert all("Farkas" in q["how"] for q in proofs)
    # ground truth: x1 grows by 2 per step whatever u does, |x(N)|_1 >= |x1(N)| >= 2^N
    assert 2 ** 1 > 0.9 * 1.5


def test_lp_form_is_verified_like_the_nlp():
    ex = cm.models.load("linear_sliding")
    ctrl = ContractiveMPC(ex.model, horizon=None, alpha=0.5, norm=ex.info["terminal_hull"],
                          solver="lp", horizon_max=6)
    hull = ex.info["terminal_hull"]

    def g(z):
        return max(0.0, float(np.max(hull.A @ z / hull.b)))

    for x0 in ex.x0s:
        r = ctrl.solve(x0)
        assert r.certificate.label == "verified"
        assert g(r.x_pred[-1]) <= 0.5 * g(np.asarray(x0))
        for q in r.certificate.details.get("proofs", []):
            assert q["result"] == "infeasible" and q["horizon"] < r.horizon


def test_unreachable_4_state_is_proved_infeasible():
    x = ca.SX.sym("x", 4)
    u = ca.SX.sym("u")
    f = ca.vertcat(1.5 * x[0] + 0.01 * u, 1.2 * x[1] + x[0] ** 2, 0.5 * x[2], x[3] + 0.1 * x[1])
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-9] * 4, [9] * 4), U=cm.Box([-1], [1]))
    ctrl = ContractiveMPC(model, horizon=None, alpha=0.95, norm=np.inf, horizon_max=2)
    r = ctrl.solve([1.0, 0.0, 0.0, 0.0])
    assert r.certificate.label == "proved_infeasible"


def test_ipopt_failure_is_not_infeasibility():
    # feasible inputs exist (3 u near pi, i.e. u near 1.047), but IPOPT started at u = 0,
    # a stationary point of the constraint, fails
    x = ca.SX.sym("x")
    u = ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=0.5 * x + 0.1 * u, X=cm.Box([-5], [5]), U=cm.Box([-2], [2]))
    g = ca.cos(3 * u) + 0.9
    ctrl = ContractiveMPC(model, horizon=1, alpha=1.0, constraints=g,
                          solver_options={"ipopt.max_iter": 3})
    r = ctrl.solve([1.0])
    assert r.certificate.label == "verified"
    assert np.cos(3 * r.u[0]) + 0.9 <= 0
    assert r.stats["return_status"] != "Solve_Succeeded"


def test_nonzero_equilibrium_reference_3_states():
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * (-ca.sin(x[0]) - 0.5 * x[1] + u),
                   0.8 * x[2] + 0.2 * x[0])
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-2] * 3, [2] * 3), U=cm.Box([-1.5], [1.5]))
    a = 0.6
    x_ref, u_ref = np.array([a, 0.0, a]), np.array([np.sin(a)])
    ctrl = ContractiveMPC(model, horizon=8, alpha=0.9, x_ref=x_ref, u_ref=u_ref)
    xk = np.array([-0.5, 0.3, 0.2])
    for _ in range(150):
        xk = model.step(xk, ctrl(xk))
        assert ctrl.last_info["certificate"] in ("verified", "at_reference")
    assert np.abs(xk - x_ref).max() < 1e-3


def test_reference_that_is_not_an_equilibrium_is_refused(cannon):
    with pytest.raises(ValueError, match="not an equilibrium"):
        ContractiveMPC(cannon, horizon=3, x_ref=[0.5, 0.0], u_ref=[0.0])


@pytest.mark.parametrize("kw, err, match", [
    ({"alpha": 0.0}, ValueError, "alpha"),
    ({"alpha": 1.5}, ValueError, "alpha"),
    ({"alpha": -0.2}, ValueError, "alpha"),
    ({"horizon": 0}, ValueError, "horizon"),
    ({"horizon": 2.5}, ValueError, "horizon"),
    ({"Q": [[1, 2], [0, 1]]}, ValueError, "symmetric"),
    ({"Q": -np.eye(2)}, ValueError, "semidefinite"),
    ({"R": 0.0}, ValueError, "positive definite"),
    ({"R": np.eye(2)}, DimensionError, "R"),
    ({"Q": np.eye(3)}, DimensionError, "Q"),
    ({"x_ref": [0, 0, 0]}, DimensionError, "x_ref"),
    ({"x_ref": [5.0, 0.0]}, ValueError, "outside X"),
    ({"norm": 3}, ValueError, "norm"),
    ({"solver": "snopt"}, ValueError, "solver"),
    ({"mode": "batch"}, ValueError, "mode"),
    ({"contract": np.ones((1, 3))}, DimensionError, "contract"),
    ({"shooting": "direct"}, ValueError, "shooting"),
])
def test_bad_arguments_are_refused(cannon, kw, err, match):
    args = {"horizon": 3, "alpha": 0.9}
    args.update(kw)
    with pytest.raises(err, match=match):
        ContractiveMPC(cannon, **args)


def test_bad_state_is_refused(cannon):
    ctrl = ContractiveMPC(cannon, horizon=3)
    with pytest.raises(DimensionError):
        ctrl.solve([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="finite"):
        ctrl.solve([np.nan, 0.0])


def test_undefined_model_names_the_operation():
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.1 * ca.log(x[1]), x[1] + 0.1 * u)
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))
    with pytest.raises(ModelError, match="OP_LOG"):
        ContractiveMPC(model, horizon=3)


def test_at_reference_applies_u_ref(cannon):
    ctrl = ContractiveMPC(cannon, horizon=3)
    r = ctrl.solve([0.0, 0.0])
    assert r.certificate.label == "at_reference" and np.array_equal(r.u, [0.0])


def test_local_law_in_local_set(cannon):
    ex = cm.models.load("cannon")
    ctrl = ContractiveMPC(cannon, horizon=4, local_law=ex.local_law, local_set=ex.terminal)
    x = np.array([0.1, -0.05])
    assert ex.terminal.contains(x[None, :])[0]
    r = ctrl.solve(x)
    assert r.mode == "local_law"
    np.testing.assert_allclose(r.u, ex.local_law @ x)


def test_failed_verification_is_reported(cannon):
    ctrl = ContractiveMPC(cannon, horizon=3, alpha=0.5)
    bad = np.full((3, 1), 2.0)  # pushes x away: no contraction
    ok, details = ctrl._check(np.array([1.0, 1.0]), 3, bad)
    assert not ok and "contraction" in details["failed"] or "state" in details["failed"]


def test_certify_optimal_brackets_the_cost():
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.2 * x[1], x[1] + 0.2 * u)
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-3, -3], [3, 3]), U=cm.Box([-1], [1]))
    ctrl = ContractiveMPC(model, horizon=2, alpha=0.99, certify_optimal=True,
                          optimal_eps=1e-3)
    r = ctrl.solve([1.0, -0.5])
    br = r.certificate.details["optimal_bracket"]
    assert br["lower"] <= r.cost + 1e-9
    assert br["width"] == pytest.approx(br["upper"] - br["lower"])
    # brute force over a grid of U^2: no feasible grid point beats the certified lower bound
    # (all 201^2 sequences at once through the model's batched step)
    g = np.linspace(-1, 1, 201)
    U1, U2 = np.meshgrid(g, g)
    a, b = U1.ravel(), U2.ravel()
    x1 = model.step(np.tile([1.0, -0.5], (a.size, 1)), a[:, None])  # (201^2, 2)
    x2 = model.step(x1, b[:, None])
    feasible = np.linalg.norm(x2, axis=1) <= 0.99 * np.linalg.norm([1.0, -0.5])
    assert feasible.any()
    cost = a * a + b * b + np.sum(x1 * x1, axis=1) + np.sum(x2 * x2, axis=1)
    best = cost[feasible].min()
    assert br["lower"] <= best + 1e-9


# ---------------------------------------------------------------- classes found by review
def test_certificate_is_not_built_on_folded_constants():
    # composing 0.667 x with itself lets CasADi fold 0.667^3 in floating point; the exact
    # graph keeps every literal as a symbol, so the check is about the model itself
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    f = ca.vertcat(0.667 * x[0], x[1] + 0.1 * x[2], x[2] + 0.1 * u)
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-2] * 3, [2] * 3), U=cm.Box([-1], [1]))
    exact = Fraction(0.667) ** 19  # |x1(19)| / |x1(0)|, u has no effect on x1
    alpha = float(exact)
    if Fraction(alpha) >= exact:
        alpha = float(np.nextafter(alpha, 0))
    r = ContractiveMPC(model, horizon=19, alpha=alpha, norm=np.inf,
                       search_max_boxes=50).solve([1.0, 0.0, 0.0])
    assert r.certificate.label != "verified"
    h = ContractiveMPC(model, horizon=3, alpha=0.9)._get(3)
    consts = {h.check_fun.instruction_constant(k) for k in range(h.check_fun.n_instructions())
              if h.check_fun.instruction_id(k) == ca.OP_CONST}
    assert not any(abs(c - 0.667 ** 2) < 1e-12 or abs(c - 0.667 ** 3) < 1e-12 for c in consts)


def test_disturbance_nominal_value_is_not_folded():
    import mpmath

    x, u, w = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("w")
    model = cm.Model(x=x, u=u, w=w, f=ca.exp(w) * x + (ca.exp(w) - 1) / w * u,
                     X=cm.Box([-10], [10]), U=cm.Box([-10], [10]),
                     W=cm.Box([0.5e-12], [1.5e-12]))
    r = ContractiveMPC(model, horizon=1, alpha=0.5, Q=0, R=100.0).solve([4.0])
    if r.certificate.label == "verified":
        mpmath.mp.dps = 60
        wn = mpmath.mpf(model.W.mid[0])
        x1 = mpmath.exp(wn) * 4 + (mpmath.exp(wn) - 1) / wn * mpmath.mpf(r.u[0])
        assert abs(x1) <= mpmath.mpf(0.5) * 4


def test_lp_refuses_what_it_cannot_represent_exactly():
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    box = {"X": cm.Box([-2, -2], [2, 2]), "U": cm.Box([-1], [1])}
    m1 = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + u, x[1]), **box)
    with pytest.raises(ValueError, match="contract"):
        ContractiveMPC(m1, horizon=1, alpha=0.5, norm=np.inf, solver="lp",
                       contract=[[1, 0]])
    m2 = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + u - 5e-10, x[1] * 0.5), **box)
    with pytest.raises(ModelError, match="constant term"):
        ContractiveMPC(m2, horizon=1, alpha=0.9, norm=np.inf, solver="lp")
    m3 = cm.Model(x=x, u=u, f=ca.vertcat(0.1 * x[0] + 0.2 * x[0] + u, 0.5 * x[1]), **box)
    with pytest.raises(ModelError, match="exact"):
        ContractiveMPC(m3, horizon=1, alpha=0.9, norm=np.inf, solver="lp")


def test_sequence_mode_does_not_replay_a_plan_from_another_state(cannon):
    ctrl = ContractiveMPC(cannon, horizon=4, alpha=0.9, mode="sequence")
    ctrl([1.0, -0.5])
    assert ctrl.last_info["mode"] == "mpc"
    u = ctrl([-0.8, 0.9])  # not the predicted state: a new solve
    assert ctrl.last_info["mode"] == "mpc"
    assert np.array_equal(u, ctrl.last_result.u)


def test_at_reference_only_at_the_reference(cannon):
    ctrl = ContractiveMPC(cannon, horizon=3)
    r = ctrl.solve([1e-170, 1e-170])  # the 2-norm underflows: nothing is claimed
    assert r.certificate.label == "unverified" and r.certificate.proved is None
    c2 = ContractiveMPC(cannon, horizon=3, contract=[[1.0, 1.0]])
    r2 = c2.solve([1.0, -1.0])  # C e = 0 but x is not the reference
    assert r2.certificate.label != "at_reference"


def test_last_info_follows_solve(cannon):
    ctrl = ContractiveMPC(cannon, horizon=3, alpha=0.9)
    ctrl([0.5, 0.2])
    r = ctrl.solve([0.0, 0.0])
    assert ctrl.last_info["certificate"] == r.certificate.label == "at_reference"


def test_local_set_membership_is_proven(cannon):
    T = cm.Polytope([[1.0, 1.0], [-1.0, 0.0], [0.0, -1.0]], [1.0, 0.0, 0.0])
    ctrl = ContractiveMPC(cannon, horizon=3, local_law=np.zeros((1, 2)), local_set=T)
    r = ctrl.solve([1.0, 2.0 ** -60])  # outside T exactly, inside in floating point
    assert r.mode != "local_law"


@pytest.mark.parametrize("kw", [{"alpha": "0.5"}, {"horizon": "3"}])
def test_strings_are_refused(cannon, kw):
    args = {"horizon": 3, "alpha": 0.9}
    args.update(kw)
    with pytest.raises(ValueError, match="string"):
        ContractiveMPC(cannon, **args)


def test_none_state_is_a_type_error(cannon):
    with pytest.raises(TypeError):
        ContractiveMPC(cannon, horizon=3).solve(None)


def test_fixed_input_component_and_small_magnitudes():
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u", 2)
    s = 1e-6
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * x[2], x[2] + 0.1 * u[0] + u[1])
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-s] * 3, [s] * 3),
                     U=cm.Box([-10 * s, 0.0], [10 * s, 0.0]))
    ctrl = ContractiveMPC(model, horizon=6, alpha=0.95, norm=np.inf)
    r = ctrl.solve(np.array([0.2, 0.6, 0.9]) * s)
    assert r.nit >= 0
    assert r.certificate.label in ("verified", "undecided", "unverified")
    if r.certificate.label == "verified":
        _check_sequence(model, np.array([0.2, 0.6, 0.9]) * s, r.u_seq, 0.95, np.inf)


def test_constants_casadi_creates_while_composing_are_widened():
    # f1 = 0.3 is constant, so x1(1) - 0.3 simplifies to 0 and acos(0) folds to fl(pi/2):
    # the exact graph lifts such created constants and widens them
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=ca.vertcat(0.3, ca.acos(x[0] - 0.3) + u),
                     X=cm.Box([0, 0], [1, 3]), U=cm.Box([-0.5], [0.5]))
    half_pi = 1.5707963267948966  # fl(pi/2) = acos(0) in floats: f(x_ref, 0) == x_ref
    ctrl = ContractiveMPC(model, horizon=2, alpha=1e-3, norm=np.inf, x_ref=[0.3, half_pi])
    r = ctrl.solve([0.3, np.nextafter(half_pi, 9)])
    # exactly, x2(2) = pi/2 + u(1): |e_N| / |e_0| is about 0.276 > alpha for every u near 0
    assert r.certificate.label != "verified"
    h = ctrl._get(2)
    consts = [h.check_fun.instruction_constant(k) for k in range(h.check_fun.n_instructions())
              if h.check_fun.instruction_id(k) == ca.OP_CONST]
    assert not consts  # every constant is an input: thin (exact) or widened (created)
    assert h.n_created >= 1 and (h.param_lo <= h.param_hi).all()


@pytest.mark.parametrize("norm", [2, np.inf, 1])
def test_single_and_multiple_shooting_give_the_same_closed_loop(cannon, norm):
    """Where the problem has one local optimum the two NLP forms find the same solution:
    the verified closed loops from the same state agree (to the solver's tolerance), for
    each contraction norm. (On nonconvex problems they may end at different optima.)"""
    loops = []
    for shooting in ("single", "multiple"):
        ctrl = ContractiveMPC(cannon, horizon=6, alpha=0.9, norm=norm, solver="sqp",
                              shooting=shooting)
        x, us = np.array([1.2, -0.9]), []
        for _ in range(12):
            r = ctrl.solve(x)
            assert r.certificate.label == "verified"
            us.append(r.u[0])
            x = cannon.step(x, r.u)
        loops.append(np.array(us))
    assert np.abs(loops[0] - loops[1]).max() <= 1e-5


def test_reported_cost_is_that_of_the_returned_sequence(cannon):
    """With multiple shooting the solver's own states may leave defects open when it stops
    early; the reported cost is still that of the returned sequence predicted from x."""
    ctrl = ContractiveMPC(cannon, horizon=8, alpha=0.9, solver="sqp",
                          solver_options={"max_iter": 1})
    n = 0
    for x in ([1.2, -0.9], [-1.0, 1.1], [0.6, 0.4]):
        ctrl.reset()
        r = ctrl.solve(np.array(x))
        if r.certificate.label != "verified":
            continue
        n += 1
        cost, xp = ctrl._predict(r.horizon, r.u_seq, np.array(x))
        assert r.cost == pytest.approx(cost, rel=1e-12)
        assert np.allclose(r.x_pred, xp.T if xp.shape[0] != r.x_pred.shape[0] else xp)
    assert n >= 2
