"""The Moore-Greitzer example: its stored terminal set is proven for the ODE, and a
set-sequence controller along certified robust controllable sets (obstacle removed) keeps
the true ODE, integrated by ``solve_ivp`` with the input and the disturbance held over
each sample, in X, out of the obstacle and its inputs in U.
"""

from __future__ import annotations

import numpy as np
import pytest
from casadi_cmpc.models import moore_greitzer as mg
from scipy.integrate import solve_ivp

import casadi_cmpc as cm


@pytest.fixture(scope="module")
def example():
    return cm.models.load("moore_greitzer")


def _flow(x: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    sol = solve_ivp(lambda t, y: mg.rhs_numpy(y, u, w), (0.0, mg.TAU), x, method="DOP853",
                    rtol=1e-11, atol=1e-13)
    assert sol.success
    return sol.y[:, -1]


def test_terminal_set_is_robustly_invariant_for_the_ode_and_inside_the_goal(example) -> None:
    model, T = example.model, example.terminal
    assert example.info["goal"].contains(np.asarray(T.vertices())).all()
    cert = cm.certify_invariant(model, T, example.local_law, 0.5)
    assert cert.proved is True and model.discretisation in cert.claim
    # sampled states of T stay in T under the true flow and the worst disturbances
    rng = np.random.default_rng(3)
    box = T.bounding_box()
    P = rng.uniform(box.lo, box.hi, (400, 2))
    P = P[T.contains(P)][:40]
    law = example.local_law
    for x in P:
        u = law.u_eq + law.K @ (x - law.x_eq)
        assert model.U.contains(u)
        for w in model.W.vertices():
            assert T.contains(_flow(x, u, np.asarray(w)))


def test_set_sequence_closed_loop_on_the_ode(example) -> None:
    model = example.model
    c = example.info["x_ref"]
    obstacle = example.info["obstacle"]
    near = cm.Box(c - 0.006, c + 0.006)
    seq = cm.controllable_sets(model, example.terminal, 2.5e-4, robust=True,
                               law=example.local_law, X=near, obstacles=[obstacle],
                               max_steps=1, progress=False)
    assert len(seq) == 2 and seq.steps[0]["boxes"].shape[0] > 0
    ctrl = cm.SetSequenceMPC(model, seq, Q=np.eye(2), R=1e-3 * np.eye(2), robust=True,
                             x_ref=c, minimax="vertices")
    boxes = np.asarray(seq.steps[0]["boxes"])
    rng = np.random.default_rng(0)
    for i in range(10):
        b = boxes[rng.integers(len(boxes))]
        x0 = rng.uniform(b[:, 0], b[:, 1])
        ctrl.reset()
        tr = cm.simulate(model, ctrl, x0, 4, disturbance="uniform", seed=i, plant=_flow,
                         progress=False)
        assert tr.violations["state"] == 0 and tr.violations["input"] == 0
        assert not obstacle.contains(tr.x).any()
        # from K_1 the proven step lands in T = K_0, which the local law keeps
        assert example.terminal.contains(tr.x[1:]).all()
