"""E13 — MiroSot robot with obstacle avoidance (thesis §7.1, ARX model (7.5)).

ARX model identified from the vision loop, with input delay d::

    x(k)     = 1.3724 x(k-1) - 0.3724 x(k-2)
               + (0.0096 u1(k-d) + 0.0119 u2(k-d)) cos(theta(k-1))
    y(k)     = 1.221 y(k-1) - 0.221 y(k-2)
               + (0.0117 u1(k-d) + 0.0121 u2(k-d)) sin(theta(k-1))
    theta(k) = 1.121 theta(k-1) - 0.121 theta(k-2) - 0.00396 u1(k-d) + 0.00422 u2(k-d)

(u1, u2: right and left motor commands). State-space form used here, with state at
step k::

    z(k) = [x(k), y(k), theta(k), x(k-1), y(k-1), theta(k-1),
            u1(k-d+1), u2(k-d+1), ..., u1(k-1), u2(k-1)]      (n = 6 + 2 (d - 1))

and input ``u(k) = (u1(k), u2(k))``. The successor applies (7.5) shifted by one step
(``u(k+1-d)`` is the oldest buffered input, or ``u(k)`` itself when d = 1) and shifts the
input buffer.

Controller of §7.1.2: cost (7.6) and constraints (7.7): ``|u|_inf <= U``, distance of
(x, y) to every obstacle ``>= D`` (the thesis prints "<= D"; the text means keeping
away), contraction of the distance to the target with alpha = 0.95, horizon n = 12.

Choices (the thesis gives no numbers for them):

* delay ``d = 2`` samples (vision and transmission delay of one extra frame);
* units: positions in cm on a 150 cm x 130 cm field (MiroSot small league), heading in
  rad; inputs in percent of the maximal motor voltage, ``U = 100``; with ``|u| <= 100``
  the model's top speed is about 3.4 cm per sample;
* state box: ``x in [0, 150]``, ``y in [0, 130]``, ``theta in [-2 pi, 2 pi]`` (the same
  for the delayed copies), buffered inputs in ``[-U, U]``;
* start pose (20, 20, 0) at rest, target pose ``(x_d, y_d, theta_d) = (120, 90, 0)``;
* two obstacles at (55, 45) and (85, 70), both near the straight line from the start to
  the target, and minimum distance ``D = 15`` cm between robot and obstacle centres.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from ..model import Model
from ..sets.box import Box
from . import Example

# ARX coefficients of (7.5)
A_X = (1.3724, -0.3724)  # x(k-1), x(k-2)
B_X = (0.0096, 0.0119)  # u1(k-d), u2(k-d), times cos(theta(k-1))
A_Y = (1.221, -0.221)  # y(k-1), y(k-2)
B_Y = (0.0117, 0.0121)  # u1(k-d), u2(k-d), times sin(theta(k-1))
A_TH = (1.121, -0.121)  # theta(k-1), theta(k-2)
B_TH = (-0.00396, 0.00422)  # u1(k-d), u2(k-d)

# MPC of §7.1.2-7.1.3
ALPHA = 0.95  # contraction of the distance to the target
HORIZON = 12  # control horizon n

# Choices (not in the thesis), see the module docstring
DELAY = 2
U_MAX = 100.0
FIELD = ((0.0, 150.0), (0.0, 130.0))  # x range, y range (cm)
THETA_MAX = 2 * np.pi
START_POSE = (20.0, 20.0, 0.0)
TARGET_POSE = (120.0, 90.0, 0.0)
OBSTACLES = np.array([[55.0, 45.0], [85.0, 70.0]])
D_MIN = 15.0
THETA_WEIGHT = 5.0  # cm per rad in the distance to the target pose


def state_dim(delay: int = DELAY) -> int:
    """Number of states ``6 + 2 (delay - 1)``."""
    return 6 + 2 * (int(delay) - 1)


def rest_state(pose: Any, delay: int = DELAY) -> np.ndarray:
    """State of a robot at rest at ``pose = (x, y, theta)``: equal past poses, zero inputs."""
    p = np.asarray(pose, dtype=float).reshape(3)
    return np.concatenate([p, p, np.zeros(2 * (int(delay) - 1))])


def state_names(delay: int = DELAY) -> list[str]:
    """Names of the states: the pose, the previous pose and the buffered inputs."""
    return (["x", "y", "theta", "x(k-1)", "y(k-1)", "theta(k-1)"]
            + [f"u{j}(k-{i})" for i in range(int(delay) - 1, 0, -1) for j in (1, 2)])


def pose(z: Any) -> np.ndarray:
    """The current pose ``(x, y, theta)`` of states ``z``, shape (N, 3) or (3,)."""
    return np.asarray(z, dtype=float)[..., :3]


def build(delay: int = DELAY) -> Example:
    """Build E13 with an input delay of ``delay >= 1`` samples."""
    d = int(delay)
    if d < 1:
        raise ValueError(f"the delay must be at least 1 sample; got {delay}")
    n = state_dim(d)
    z = ca.SX.sym("z", n)
    u = ca.SX.sym("u", 2)
    xk, yk, thk, xp, yp, thp = (z[i] for i in range(6))
    buf = [z[6 + i] for i in range(2 * (d - 1))]  # u1, u2 of k-d+1, ..., k-1
    u1d, u2d = (buf[0], buf[1]) if d > 1 else (u[0], u[1])  # u(k+1-d)
    x_next = A_X[0] * xk + A_X[1] * xp + (B_X[0] * u1d + B_X[1] * u2d) * ca.cos(thk)
    y_next = A_Y[0] * yk + A_Y[1] * yp + (B_Y[0] * u1d + B_Y[1] * u2d) * ca.sin(thk)
    th_next = A_TH[0] * thk + A_TH[1] * thp + B_TH[0] * u1d + B_TH[1] * u2d
    f = ca.vertcat(x_next, y_next, th_next, xk, yk, thk, *buf[2:],
                   *([u[0], u[1]] if d > 1 else []))
    pose_lo = [FIELD[0][0], FIELD[1][0], -THETA_MAX]
    pose_hi = [FIELD[0][1], FIELD[1][1], THETA_MAX]
    X = Box(pose_lo * 2 + [-U_MAX] * (2 * (d - 1)), pose_hi * 2 + [U_MAX] * (2 * (d - 1)))
    names = state_names(d)
    # units as chosen above (the thesis gives none); no sampling time is known
    units = {v: "cm" if v[0] in "xy" else "rad" if v.startswith("theta") else "%"
             for v in names}
    units.update({"u1": "%", "u2": "%"})
    model = Model(x=z, u=u, f=f, X=X, U=Box([-U_MAX, -U_MAX], [U_MAX, U_MAX]),
                  name="mirosot", state_names=names, input_names=["u1", "u2"], units=units)
    # MPC (7.6)-(7.7): distance to the target pose (x, y, THETA_WEIGHT theta) contracts;
    # keep-out discs of radius D around the obstacles
    C = np.zeros((3, n))
    C[0, 0] = C[1, 1] = 1.0
    C[2, 2] = THETA_WEIGHT
    Q = C.T @ C
    avoid = ca.vertcat(*[D_MIN ** 2 - ((z[0] - o[0]) ** 2 + (z[1] - o[1]) ** 2)
                         for o in OBSTACLES])
    return Example(
        name="mirosot",
        model=model,
        terminal=None,
        local_law=None,
        x0s=rest_state(START_POSE, d)[None, :],
        info={
            "example": "E13",
            "mpc": {"horizon": HORIZON, "alpha": ALPHA, "norm": 2, "contract": C, "Q": Q,
                    "R": 1e-3 * np.eye(2), "x_ref": rest_state(TARGET_POSE, d),
                    "u_ref": np.zeros(2), "constraints": avoid,
                    # applying whole plans reaches states where no horizon-12 plan exists
                    # (proven): the first move of each plan is applied instead
                    "mode": "receding"},
            "run": {"steps": 60, "obstacles": OBSTACLES.copy(), "D": D_MIN,
                    "note": "contractive MPC of the distance to the target pose (alpha = "
                            "0.95, N = 12) with keep-out discs of radius D around the "
                            "obstacles; the input delay is a state (buffer) of the model"},
            "section": "7.1",
            "equation": "(7.5); MPC (7.6)-(7.7)",
            "figures": ["7.2"],
            "alpha": ALPHA,
            "horizon": HORIZON,
            "state_layout": ["x(k)", "y(k)", "theta(k)", "x(k-1)", "y(k-1)", "theta(k-1)"]
            + [f"u{j}(k-{i})" for i in range(d - 1, 0, -1) for j in (1, 2)],
            "plot_states": [0, 1, 2],  # the current pose; the others are delayed copies
            "delay": d,
            "U": U_MAX,
            "D": D_MIN,
            "target": np.array(TARGET_POSE),
            "obstacles": OBSTACLES.copy(),
            "unspecified": ["delay d", "input bound U", "minimum distance D", "target pose",
                            "obstacles", "weights P0, Q, R of (7.6)", "units and field"],
            "choices": {
                "delay": d,
                "U": U_MAX,
                "D": D_MIN,
                "target": np.array(TARGET_POSE),
                "start": np.array(START_POSE),
                "obstacles": OBSTACLES.copy(),
                "units": "positions in cm, heading in rad, inputs in percent of the maximal "
                         "motor voltage",
                "field": FIELD,
                "theta_range": (-THETA_MAX, THETA_MAX),
                "theta_weight": THETA_WEIGHT,
                "weights": "Q = C' C on the pose error (C: x, y, 5 theta), R = 1e-3 I",
            },
        },
    )
