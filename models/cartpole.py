"""Cart-pole — a pole balanced upright on a force-driven cart (not a thesis example).

State ``x = (p, v, theta, omega)``: cart position (m), cart velocity (m/s), pole angle from
the upright (rad, positive when the pole leans towards +p) and its rate (rad/s); input
``u = F``, the horizontal force on the cart (N); disturbance ``w``, an unmeasured force
added to F (N). Frictionless cart-pole of Barto, Sutton & Anderson (1983) with the
equations of Florian (2007), the pole a uniform rod pivoted at its end::

    a     = (F + w + m_p l omega^2 sin(theta)) / (m_c + m_p)
    alpha = (g sin(theta) - cos(theta) a) / (l (4/3 - m_p cos(theta)^2 / (m_c + m_p)))
    dp/dt = v,   dv/dt = a - m_p l alpha cos(theta) / (m_c + m_p),
    dtheta/dt = omega,   domega/dt = alpha

with m_c = 1 kg, m_p = 0.1 kg, l = 0.5 m (pivot to the pole's centre of mass: a rod of
1 m), g = 9.81 m/s^2, sampled by classical Runge-Kutta 4 with dt = 0.05 s (F and w held
over the sample). Constraints ``|p| <= 2.4 m``, ``|v| <= 3 m/s``, ``|theta| <= 0.4 rad``,
``|omega| <= 3 rad/s``, ``|F| <= 10 N``; disturbance ``|w| <= 0.02 N``.

Equilibrium: the upright pole at rest, ``x_eq = 0``, ``u_eq = 0``. Local law: the LQR law
of the linearisation (``cm.local_lqr``) with Bryson's weights ``Q = diag(1/2.4^2, 1/3^2,
1/0.4^2, 1/3^2)``, ``R = 1/10^2``. Terminal set: a box in the real modal coordinates of
the linearised closed loop (``cm.terminal_set``, shape "modal"; the ellipsoidal shapes do
not contract even for the linearisation at this sampling time), **certified robustly
invariant** for every ``|w| <= 0.02 N`` by ``cm.certify_invariant``, inside X and with
the law inside U. Its numbers are stored below; :func:`compute_terminal` recomputes them.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from ..control.law import LinearLaw
from ..model import Model
from ..sets.box import Box
from ..sets.polytope import Polytope
from . import Example

M_CART = 1.0  # m_c, kg
M_POLE = 0.1  # m_p, kg
L_POLE = 0.5  # l, m: pivot to the pole's centre of mass (half of a 1 m rod)
G = 9.81  # m/s^2
DT = 0.05  # s, RK4
F_MAX = 10.0  # |F| <= 10 N
W_MAX = 0.02  # |w| <= 0.02 N
X_MAX = np.array([2.4, 3.0, 0.4, 3.0])  # |p| m, |v| m/s, |theta| rad, |omega| rad/s
STATE_NAMES = ["p", "v", "theta", "omega"]
STATE_UNITS = ["m", "m/s", "rad", "rad/s"]

# Bryson's weights of the local LQR law (1 / squared bound)
LQR_Q = np.diag(1.0 / X_MAX ** 2)
LQR_R = np.array([[1.0 / F_MAX ** 2]])

# ---- computed by compute_terminal() (cm.terminal_set), stored for a fast import ----
# the local law u = K x (N per state unit)
K_LOCAL = np.array([[2.916408833843852, 5.211951002279503, 47.32266355884037,
                     11.509941214791468]])
# rows of the modal box: terminal set {x : |H_MODAL x|_inf <= SCALE}
H_MODAL = np.array([
    [0.4384434305548582, 0.5169445318852551, 1.5046768944461133, -0.5517468220587637],
    [3.5923810972524755, 5.833342327635122, 35.40782873556727, 7.694090617174047],
    [-0.2923428274319726, -1.4391067552123382, -4.113159641655013, -1.2780286746732368],
    [2.7512110154261906, 2.7013804329383717, 7.900443733462438, 2.250327308200874],
])
SCALE = 0.7224204421399181
# wall-clock time of compute_terminal() on 2 cores (9.3 s the first time, when the native
# interval kernels are compiled and cached)
TERMINAL_SECONDS = 4.7
# -------------------------------------------------------------------------------------------

X0S = np.array([[-1.0, 0.0, 0.25, 0.0]])  # pole leaning 0.25 rad, cart 1 m off


def rhs(x: ca.SX, u: ca.SX, w: ca.SX) -> ca.SX:
    """Right-hand side (4, 1) of the cart-pole ODE (time in s) at state x (4, 1), force u
    (N) and disturbance force w (N)."""
    theta, omega = x[2], x[3]
    total = M_CART + M_POLE
    a = (u + w + M_POLE * L_POLE * omega ** 2 * ca.sin(theta)) / total
    alpha = (G * ca.sin(theta) - ca.cos(theta) * a) / (
        L_POLE * (4.0 / 3.0 - M_POLE * ca.cos(theta) ** 2 / total))
    return ca.vertcat(x[1], a - M_POLE * L_POLE * alpha * ca.cos(theta) / total, omega, alpha)


def cartpole_model() -> Model:
    """The sampled cart-pole (n = 4, m = 1, l = 1) with its boxes, names and units."""
    x = ca.SX.sym("x", 4)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    return Model.from_ode(
        x=x, u=u, w=w, rhs=rhs(x, u, w), dt=DT, method="rk4",
        X=Box(-X_MAX, X_MAX), U=Box([-F_MAX], [F_MAX]), W=Box([-W_MAX], [W_MAX]),
        name="cartpole", time_unit=1.0, state_names=STATE_NAMES, input_names=["F"],
        disturbance_names=["w"],
        units=dict(zip(STATE_NAMES + ["F", "w"], STATE_UNITS + ["N", "N"], strict=True)))


def local_law() -> LinearLaw:
    """The stored local law ``u = K x``."""
    return LinearLaw(K_LOCAL)


def terminal_set() -> Polytope:
    """The stored terminal set ``{x : |H_MODAL x|_inf <= SCALE}`` (robustly invariant
    under :func:`local_law` for ``|w| <= W_MAX``, proven by ``cm.certify_invariant``)."""
    return Polytope(np.vstack([H_MODAL, -H_MODAL]), SCALE * np.ones(8))


def compute_terminal(**options: Any) -> Any:
    """Recompute the local law and the terminal set with :func:`casadi_cmpc.terminal_set`
    (robust over the model's W; 5-10 s): returns its TerminalSetResult, whose
    ``law.K``, ``unit.A[:4]`` and ``scale`` are the constants ``K_LOCAL``, ``H_MODAL`` and
    ``SCALE`` of this module."""
    from ..control.terminal import terminal_set as search

    kw = {"shape": "modal", "Q": LQR_Q, "R": LQR_R, "eps": 0.02, "progress": False}
    kw.update(options)
    return search(cartpole_model(), **kw)


def build() -> Example:
    """Build the cart-pole example."""
    model = cartpole_model()
    law = local_law()
    T = terminal_set()
    return Example(
        name="cartpole",
        model=model,
        terminal=T,
        local_law=law,
        x0s=X0S.copy(),
        info={
            "example": "extra",
            "description": "cart-pole balanced upright by a force on the cart, RK4 dt = "
                           "0.05 s, certified terminal set (not from the thesis)",
            "section": "",
            "equation": "Barto et al. (1983) / Florian (2007) cart-pole, RK4",
            "mpc": {"horizon": 15, "alpha": 0.5, "Q": LQR_Q.copy(), "R": LQR_R.copy(),
                    "local_law": law, "local_set": T},
            "run": {"steps": 100, "disturbance": "uniform",
                    "note": "nominal contractive MPC (w = 0 in the prediction) with the "
                            "force disturbance w drawn uniformly in [-0.02, 0.02] N; "
                            "u = K x inside the terminal set, robustly invariant under it"},
            "dt": DT,
            "parameters": {"m_cart": M_CART, "m_pole": M_POLE, "l": L_POLE, "g": G},
            "x_eq": np.zeros(4),
            "u_eq": np.zeros(1),
            "lqr_Q": LQR_Q.copy(),
            "lqr_R": LQR_R.copy(),
            "terminal_scale": SCALE,
            "terminal_shape": "modal",
            "terminal_status": "certified robustly invariant for |w| <= 0.02 N (and inside "
                               "X, law inside U) by cm.terminal_set / cm.certify_invariant",
            "terminal_seconds": TERMINAL_SECONDS,
            "choices": {
                "parameters": "standard cart-pole benchmark values",
                "dt": "0.05 s, RK4",
                "boxes": "|p| <= 2.4 m, |v| <= 3 m/s, |theta| <= 0.4 rad, "
                         "|omega| <= 3 rad/s, |F| <= 10 N, |w| <= 0.02 N",
                "local_law": "LQR of the linearisation at the upright, Bryson's weights",
            },
        },
    )
