"""The thesis examples closed by the contractive MPC each example configures (info['mpc'])."""

from __future__ import annotations

import numpy as np
import pytest

import casadi_cmpc as cm


def _controller(name: str):
    ex = cm.models.load(name)
    return ex, cm.ContractiveMPC(ex.model, **ex.info["mpc"])


def test_e1_lp_reaches_the_sliding_domain_then_the_origin():
    ex, ctrl = _controller("linear_sliding")
    assert ctrl.solver == "lp"
    for x0 in ex.x0s:
        ctrl.reset()
        traj = cm.simulate(ex.model, ctrl, x0, steps=40, progress=False)
        inside = np.flatnonzero(np.asarray(ex.terminal.contains(traj.x)))
        assert inside.size > 0, "never reached S"
        assert traj.violations["state"] == 0 and traj.violations["input"] == 0
        assert np.abs(traj.x[-1]).max() < 1e-2
        # every MPC step before S was verified; inside S the local law ran
        for c, mode in zip(traj.certificate, traj.mode, strict=True):
            assert (c, mode) in (("verified", "mpc"), ("local_law", "local_law"))


def test_e7_grimm_reaches_the_origin_with_every_step_verified():
    ex, ctrl = _controller("grimm")
    traj = cm.simulate(ex.model, ctrl, ex.x0s[0], steps=60, progress=False,
                       stop_when=lambda x: np.abs(x).max() < 1e-3)
    assert traj.stop_reason == "stop_when"
    assert np.abs(traj.x[-1]).max() < 1e-3
    assert traj.violations["state"] == 0 and traj.violations["input"] == 0
    assert set(traj.certificate) == {"verified"}
    assert 2 in traj.horizon  # horizon 1 is proven infeasible from (2, 2)


def test_e13_mirosot_reaches_the_target_and_avoids_the_obstacles():
    ex, ctrl = _controller("mirosot")
    target, obs, D = ex.info["target"], ex.info["obstacles"], ex.info["D"]

    def arrived(z):
        return np.hypot(z[0] - target[0], z[1] - target[1]) < 1.0 and abs(z[2]) < 0.05

    traj = cm.simulate(ex.model, ctrl, ex.x0s[0], steps=80, stop_when=arrived,
                       progress=False)
    assert traj.stop_reason == "stop_when"
    dist = np.linalg.norm(traj.x[:, None, :2] - obs[None], axis=2)
    assert (dist >= D).all()
    assert traj.violations["state"] == 0 and traj.violations["input"] == 0
    assert set(traj.certificate) == {"verified"}


def test_cannon_from_thesis_state_converges():
    ex, ctrl = _controller("cannon")
    traj = cm.simulate(ex.model, ctrl, ex.x0s[0], steps=60, progress=False)
    assert traj.violations["state"] == 0 and traj.violations["input"] == 0
    assert np.abs(traj.x[-1]).max() < 1e-2
    assert set(traj.certificate) <= {"verified", "local_law"}
    assert traj.certificate[0] == "verified"


@pytest.mark.parametrize("name", ["cstr", "cannon_robust"])
def test_examples_with_nonzero_reference_or_disturbance(name):
    ex, ctrl = _controller(name)
    dist = ex.info["run"].get("disturbance")
    traj = cm.simulate(ex.model, ctrl, ex.x0s[0], steps=80, disturbance=dist, seed=3,
                       progress=False)
    assert traj.violations["state"] == 0 and traj.violations["input"] == 0
    assert np.abs(traj.x[-1] - ctrl.x_ref).max() < 2e-2
