"""MPC along quasi i-step robust controllable sets (thesis Alg 6.8, (6.22)-(6.23))."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.control.quasi import quasi_controllable_sets
from casadi_cmpc.exceptions import ModelError
from casadi_cmpc.mpc.quasi import QuasiMultiStepMPC


@pytest.fixture(scope="module")
def e12(e12_quasi4_sets):
    return e12_quasi4_sets[0]


@pytest.fixture(scope="module")
def e12_sets(e12_quasi4_sets):
    # coarse and fast: quasi 4-step sets (eps 0.05) until both initial states of Fig 6.15
    # have a level; computed once per session (tests/conftest.py), shared with the C export
    return e12_quasi4_sets[1]


@pytest.fixture(scope="module")
def e12_ctrl(e12, e12_sets):
    return QuasiMultiStepMPC(e12.model, e12_sets, P0=np.eye(2), Q=np.zeros((2, 2)), R=0.1,
                             local_law=e12.local_law)


def test_sets_hold_both_initial_states(e12, e12_sets):
    assert all(e12_sets.level(x) is not None for x in e12.x0s)


@pytest.mark.parametrize("k", [0, 1])
@pytest.mark.parametrize("disturbance", ["uniform", "vertices"])
def test_e12_closed_loops_have_no_violation(e12, e12_ctrl, k, disturbance):
    x0 = e12.x0s[k]
    T = e12.terminal
    for seed in range(3):
        e12_ctrl.reset()
        tr = cm.simulate(e12.model, e12_ctrl, x0, 30, disturbance=disturbance, seed=seed)
        assert tr.stop_reason == "steps"
        assert tr.violations["state"] == 0 and tr.violations["input"] == 0
        # every step outside T is a proven plan step; T is reached and (here) kept
        inside = np.flatnonzero(T.contains(tr.x[:-1]))
        assert inside.size and np.all(T.contains(tr.x[inside[0]:]))
        for c, x in zip(tr.certificate, tr.x[:-1], strict=True):
            if not T.contains(x):
                assert c == "verified"


def test_solve_reports_plan_and_claim(e12, e12_ctrl):
    e12_ctrl.reset()
    x0 = e12.x0s[0]
    res = e12_ctrl.solve(x0)
    assert res.success and res.certificate.label == "verified"
    assert "for all w in W" in res.certificate.claim
    assert 1 <= res.u_seq.shape[0] <= 4 and np.allclose(res.u, res.u_seq[0])
    # the plan itself: proven again from the point with the stored rest
    j = res.horizon - 1
    assert e12_ctrl.prove(x0, res.u_seq, j) >= 1
    # a control sequence out of U is never proven
    assert e12_ctrl.prove(x0, np.full((2, 1), 10.0), j) == 0


def test_not_controllable_state_raises(e12, e12_ctrl):
    e12_ctrl.reset()
    x = np.array([0.999, 0.999])
    assert e12_ctrl.level(x) is None
    res = e12_ctrl.solve(x)
    assert res.certificate.label == "not_controllable" and not res.success
    with pytest.raises(cm.NotControllableError):  # a ValueError
        e12_ctrl(x)
    with pytest.warns(cm.CmpcWarning, match="lies in no set"):
        traj = cm.simulate(e12.model, e12_ctrl, x, steps=3, progress=False)
    assert traj.stop_reason == "not_controllable" and traj.steps == 0


def _three_state():
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u", 2)
    w = ca.SX.sym("w")
    f = ca.vertcat(x[0] + 0.1 * x[1] + 0.02 * ca.sin(x[2]),
                   x[1] + 0.1 * (x[0] ** 2 + u[0]),
                   x[2] + 0.1 * (u[1] - x[1] * x[2]) + w)
    return cm.Model(x=x, u=u, w=w, f=f, X=cm.Box([-1, -1, -1], [1, 1, 1]),
                    U=cm.Box([-2, -2], [2, 2]), W=cm.Box([-0.01], [0.01]), name="three_state")


def test_three_state_closed_loop():
    model = _three_state()
    T = cm.Polytope.from_box(cm.Box([-0.5] * 3, [0.5] * 3))
    seqs = quasi_controllable_sets(model, T, steps=2, eps=0.25, max_sets=2)
    res1 = seqs.results[0]
    x0 = res1.inner[np.argmax(np.abs(res1.inner).max(axis=(1, 2)))].mean(axis=1)
    assert not T.contains(x0)
    ctrl = QuasiMultiStepMPC(model, seqs, R=0.1 * np.eye(2))
    for seed in range(3):
        ctrl.reset()
        tr = cm.simulate(model, ctrl, x0, 6, disturbance="uniform", seed=seed)
        assert tr.violations["state"] == 0 and tr.violations["input"] == 0
        assert tr.certificate[0] == "verified"
        k = int(np.flatnonzero(T.contains(tr.x))[0])
        assert k <= 2 and all(c == "verified" for c in tr.certificate[:k])


def test_refused_bad_input(e12, e12_sets):
    with pytest.raises(TypeError):
        QuasiMultiStepMPC(e12.model, [e12.terminal])
    with pytest.raises(ValueError):
        QuasiMultiStepMPC(e12.model, e12_sets, solver="lbfgs")
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    other = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * u),
                     X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]), name="other")
    with pytest.raises(ModelError, match="computed for model"):
        QuasiMultiStepMPC(other, e12_sets)
    bilinear = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * x[0] * u),
                        X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))
    with pytest.raises(ModelError, match="affine control part"):
        QuasiMultiStepMPC(bilinear, e12_sets)
