"""Moore-Greitzer jet engine compressor — a validated sampled-data model (not a thesis example).

The two-state Moore-Greitzer model of surge in an axial compressor, as in the ``engine2dRS``
example of the ROCS controller-synthesis tool: ``x1`` the mass flow, ``x2`` the pressure
rise (both normalised, no unit), ``u1`` a control of the flow (added to its derivative),
``u2`` the throttle opening::

    dx1/dt = (a + H + H/(2 W^3) (x1 - W)(3 W^2 - (x1 - W)^2) - x2) / lc + u1 + w1
    dx2/dt = (x1 - u2 sqrt(x2)) / (4 lc B^2) + w2

with ``a = 1/3.5``, ``B = 2``, ``H = 0.18``, ``W = 0.25``, ``lc = 8``; constraints
``X = [0.44, 0.54] x [0.6, 0.7]``, ``u1 in [-0.05, 0.05]``, ``u2 in [0.5, 0.8]``; sampling
time ``tau = 0.1`` (time units of the ODE). Goal box ``(0.5039, 0.6605) ± 0.003``, obstacle
``[0.520, 0.526] x [0.658, 0.664]`` (both in ``info``).

The model is built with ``Model.from_ode(method="taylor", order=4)``: its map ``f`` is the
Taylor polynomial of the flow (u and w held constant over the sample), and every interval
evaluation encloses the true flow of the ODE (``model.discretisation`` says so).

Choice (not from ROCS): the disturbance ``w = (w1, w2)`` is additive on the state
derivative, constant over each sample, with ``|w1|, |w2| <= 1e-4`` (state units per time
unit). The pressure rise moves at most about 1.6e-3 per time unit under the admissible
throttle, so a disturbance of 1e-2 (the order of the control ``u1``) would dominate it;
1e-4 is a small fraction of the control authority of both states.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..control.law import LinearLaw
from ..model import Model
from ..sets.box import Box
from ..sets.polytope import Polytope
from . import Example

A_PSI = 1.0 / 3.5  # a (psi_c0)
B_GREITZER = 2.0  # B
H_PSI = 0.18  # H
W_PSI = 0.25  # W
L_C = 8.0  # lc
TAU = 0.1  # sampling time (time units of the ODE)
ORDER = 4  # Taylor order of the validated model
X_RANGE = ((0.44, 0.54), (0.6, 0.7))
U_RANGE = ((-0.05, 0.05), (0.5, 0.8))
W_MAX = 1e-4  # choice, see the module docstring
GOAL_CENTRE = np.array([0.5039, 0.6605])
GOAL_RADIUS = 0.003
OBSTACLE = np.array([[0.520, 0.526], [0.658, 0.664]])
STATE_NAMES = ["mass flow", "pressure rise"]
INPUT_NAMES = ["flow control", "throttle"]
X0S = np.array([[0.45, 0.62]])
# the terminal set and local law: cm.terminal_set(model, x_eq=GOAL_CENTRE,
# u_eq=equilibrium_input(GOAL_CENTRE), Q=diag(1e3, 1e3), R=diag(1, 1), max_scale=0.55)
# ("modal" shape, robust for every w in W, S inside the goal box; proven in 9 s, re-proven
# in tests/test_validated_ode_mg.py). Stored here so that the import stays fast.
LQR_Q = np.diag([1e3, 1e3])
LQR_R = np.diag([1.0, 1.0])
TERMINAL_SCALE = 0.55
TERMINAL_A = np.array([[-192.27771798295902, -7.371517392372808],
                       [-0.1187888400451436, -256.8153891388998],
                       [192.27771798295902, 7.371517392372808],
                       [0.1187888400451436, 256.8153891388998]])
TERMINAL_B = np.array([-101.20762932927529, -169.13642222274203, 102.30762932927529,
                       170.23642222274205])
LOCAL_K = np.array([[-9.158619192909207, -0.2198993206033424],
                    [0.013800232726146883, 30.823179663164915]])


def rhs(x: ca.SX, u: ca.SX, w: ca.SX) -> ca.SX:
    """Right-hand side (2, 1) of the ODE at state x (2, 1), input u (2, 1), disturbance w
    (2, 1)."""
    d = x[0] - W_PSI
    psi = A_PSI + H_PSI + H_PSI / (2 * W_PSI ** 3) * d * (3 * W_PSI ** 2 - d ** 2)
    dx1 = (psi - x[1]) / L_C + u[0] + w[0]
    dx2 = (x[0] - u[1] * ca.sqrt(x[1])) / (4 * L_C * B_GREITZER ** 2) + w[1]
    return ca.vertcat(dx1, dx2)


def rhs_numpy(x: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The same right-hand side in numpy (for an ODE integrator), x, u, w of shape (2,)."""
    d = x[0] - W_PSI
    psi = A_PSI + H_PSI + H_PSI / (2 * W_PSI ** 3) * d * (3 * W_PSI ** 2 - d ** 2)
    return np.array([(psi - x[1]) / L_C + u[0] + w[0],
                     (x[0] - u[1] * np.sqrt(x[1])) / (4 * L_C * B_GREITZER ** 2) + w[1]])


def flow(x: np.ndarray, u: np.ndarray, w: np.ndarray, dt: float = TAU) -> np.ndarray:
    """The true successor: the ODE integrated over one sample by ``scipy.integrate.solve_ivp``
    (DOP853, rtol 1e-10, atol 1e-13) with u and w held; x, u, w of shape (2,). Pass it as
    ``cm.simulate(..., plant=flow)`` to run a controller on the ODE itself."""
    from scipy.integrate import solve_ivp

    sol = solve_ivp(lambda t, y: rhs_numpy(y, u, w), (0.0, dt), np.asarray(x, dtype=float),
                    method="DOP853", rtol=1e-10, atol=1e-13)
    if not sol.success:  # pragma: no cover - smooth ODE on a short interval
        raise RuntimeError(f"solve_ivp failed: {sol.message}")
    return sol.y[:, -1]


def equilibrium_input(x: np.ndarray) -> np.ndarray:
    """The input u with ``rhs(x, u, 0) = 0`` (a fixed point of the sampled model too)."""
    d = x[0] - W_PSI
    psi = A_PSI + H_PSI + H_PSI / (2 * W_PSI ** 3) * d * (3 * W_PSI ** 2 - d ** 2)
    return np.array([-(psi - x[1]) / L_C, x[0] / np.sqrt(x[1])])


def build(order: int = ORDER) -> Example:
    """Build the validated Moore-Greitzer example (Taylor order ``order``)."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u", 2)
    w = ca.SX.sym("w", 2)
    X = Box([r[0] for r in X_RANGE], [r[1] for r in X_RANGE])
    U = Box([r[0] for r in U_RANGE], [r[1] for r in U_RANGE])
    W = Box([-W_MAX, -W_MAX], [W_MAX, W_MAX])
    model = Model.from_ode(x, u, rhs(x, u, w), TAU, method="taylor", order=order, w=w, X=X,
                           U=U, W=W, name="moore_greitzer", state_names=STATE_NAMES,
                           input_names=INPUT_NAMES, disturbance_names=["w1", "w2"])
    u_ref = equilibrium_input(GOAL_CENTRE)
    goal = Box(GOAL_CENTRE - GOAL_RADIUS, GOAL_CENTRE + GOAL_RADIUS)
    law = LinearLaw(LOCAL_K.copy(), x_eq=GOAL_CENTRE.copy(), u_eq=u_ref)
    T = Polytope(TERMINAL_A.copy(), TERMINAL_B.copy())
    return Example(
        name="moore_greitzer",
        model=model,
        terminal=T,
        local_law=law,
        x0s=X0S.copy(),
        info={
            # a short horizon: the prediction composes the order-4 Taylor map, whose C
            # sources (cmpc export) grow with it (horizon 3: about 30 s to build)
            "mpc": {"horizon": 3, "alpha": 0.99, "x_ref": GOAL_CENTRE.copy(),
                    "u_ref": u_ref.copy(), "Q": LQR_Q.copy(), "R": LQR_R.copy(),
                    "local_law": law, "local_set": T, "mode": "receding"},
            "run": {"steps": 100, "disturbance": "uniform",
                    "note": "nominal contractive MPC towards the goal centre (w = 0 in the "
                            "prediction, every verified step proven for the true flow of "
                            "the ODE) with w drawn uniformly in W; u = u_ref + K (x - x_ref) "
                            "inside the terminal set, robustly invariant under it. The "
                            "simulation runs the model's Taylor map unless the ODE is "
                            "passed as the plant (cm.simulate(..., plant=info['run']"
                            "['plant']))",
                    "plant": flow},
            "terminal_scale": TERMINAL_SCALE,
            "lqr_Q": LQR_Q.copy(),
            "lqr_R": LQR_R.copy(),
            "example": "extra",
            "description": "Moore-Greitzer jet engine compressor (ROCS engine2dRS), "
                           "validated Taylor model of the ODE",
            "goal": goal,
            "obstacle": Box(OBSTACLE[:, 0], OBSTACLE[:, 1]),
            "x_ref": GOAL_CENTRE.copy(),
            "u_ref": u_ref,
            "tau": TAU,
            "order": order,
            "choices": {"W": f"additive on the state derivative, |w_i| <= {W_MAX:g} "
                             "(state units per time unit), constant over the sample",
                        "order": order},
        },
    )
