"""Three-tank cascade — gravity-drained tanks in series fed by one pump (not a thesis example).

State ``x = (h1, h2, h3)``: the water levels (cm) of three tanks of cross-section
``A = 154 cm^2`` in a cascade: the pump feeds tank 1, tank i drains into tank i + 1 through
an orifice (Torricelli), tank 3 drains out. Input ``u = q``, the pump flow (cm^3/s);
disturbance ``w``, an unmeasured inflow into tank 1 (cm^3/s)::

    dh1/dt = (q + w - c1 sqrt(2 g h1)) / A
    dh2/dt = (c1 sqrt(2 g h1) - c2 sqrt(2 g h2)) / A
    dh3/dt = (c2 sqrt(2 g h2) - c3 sqrt(2 g h3)) / A

with the effective orifice areas ``c = (0.25, 0.225, 0.2) cm^2`` and ``g = 981 cm/s^2``,
sampled by classical Runge-Kutta 4 with dt = 5 s. Constraints ``5 <= h_i <= 60 cm``,
``0 <= q <= 100 cm^3/s``; disturbance ``|w| <= 0.5 cm^3/s``.

Equilibrium: ``q_eq = 50 cm^3/s`` and ``h_i = (q_eq / c_i)^2 / (2 g)`` (20.39, 25.17 and
31.86 cm for the continuous system; ``X_EQ`` is the equilibrium of the sampled map, equal
to it up to rounding). Local law ``u = u_eq + K (x - x_eq)``: the LQR law of the
linearisation there (``cm.local_lqr``) with Bryson's weights (1 / squared distance to the
nearer bound). Terminal set: the box ``|V (x - x_eq)|_inf <= s`` along the eigenvectors
of the closed loop's quadratic Lyapunov matrix ``P = V' V`` (``cm.terminal_set``, shape
"parallelotope": of the shapes searched it is the largest proven; it reaches ``h1 = 5
cm``), **certified robustly invariant** for every ``|w| <= 0.5 cm^3/s`` by
``cm.certify_invariant``, inside X and with the law inside U. Its numbers are stored
below; :func:`compute_terminal` recomputes them.
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

AREA = 154.0  # A, cm^2
C_OUT = (0.25, 0.225, 0.2)  # effective orifice areas c_i, cm^2
G = 981.0  # cm/s^2
DT = 5.0  # s, RK4
H_RANGE = (5.0, 60.0)  # cm
Q_RANGE = (0.0, 100.0)  # cm^3/s
Q_EQ = 50.0  # cm^3/s
W_MAX = 0.5  # |w| <= 0.5 cm^3/s
STATE_NAMES = ["h1", "h2", "h3"]

# ---- computed by compute_terminal() (cm.terminal_set), stored for a fast import ----
# equilibrium of the sampled map at q = Q_EQ (cm)
X_EQ = np.array([20.387359836901123, 25.16958004555694, 31.855249745158])
# the local law u = Q_EQ + K (x - X_EQ) (cm^3/s per cm)
K_LOCAL = np.array([[-2.443534151481763, -0.9386097545539407, -0.2653619896629084]])
# rows V (V' V = P, along the eigenvectors of the Lyapunov matrix P): terminal set
# {x : |H_BOX (x - X_EQ)|_inf <= SCALE}, i.e. [H_BOX; -H_BOX] x <= B_TERMINAL
H_BOX = np.array([
    [0.03633031678618764, -0.07400319043612394, 0.11525317871345823],
    [-0.14436838048338177, 0.044951474077106174, 0.07437106367966756],
    [-0.10869065424722187, -0.19674942076870444, -0.0920696424280475],
])
SCALE = 1.7613774689083797
# SCALE + [H_BOX; -H_BOX] X_EQ as computed (the offsets of the certified polytope, bit for bit)
B_TERMINAL = np.array([4.31084627674892, 2.3186058792013835, -8.339539758585655,
                       -0.7880913389321615, 1.204149058615376, 11.862294696402415])
TERMINAL_SECONDS = 2.7  # wall-clock time of compute_terminal() on 2 cores
# -------------------------------------------------------------------------------------------

X0S = np.array([[10.0, 15.0, 20.0]])  # tanks low, e.g. after a drain


def rhs(x: ca.SX, u: ca.SX, w: ca.SX) -> ca.SX:
    """Right-hand side (3, 1) of the ODE (cm/s) at levels x (3, 1) in cm, pump flow u and
    disturbance inflow w (cm^3/s)."""
    out = [c * ca.sqrt(2.0 * G * x[i]) for i, c in enumerate(C_OUT)]
    return ca.vertcat(u + w - out[0], out[0] - out[1], out[1] - out[2]) / AREA


def continuous_equilibrium(q: float = Q_EQ) -> np.ndarray:
    """Levels (3,) in cm at which the ODE rests with the pump flow ``q`` (cm^3/s)."""
    return (q / np.array(C_OUT)) ** 2 / (2.0 * G)


def three_tank_model() -> Model:
    """The sampled three-tank cascade (n = 3, m = 1, l = 1) with its boxes, names, units."""
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    return Model.from_ode(
        x=x, u=u, w=w, rhs=rhs(x, u, w), dt=DT, method="rk4",
        X=Box([H_RANGE[0]] * 3, [H_RANGE[1]] * 3), U=Box([Q_RANGE[0]], [Q_RANGE[1]]),
        W=Box([-W_MAX], [W_MAX]), name="three_tank", time_unit=1.0,
        state_names=STATE_NAMES, input_names=["q"], disturbance_names=["w"],
        units={"h1": "cm", "h2": "cm", "h3": "cm", "q": "cm^3/s", "w": "cm^3/s"})


def local_law() -> LinearLaw:
    """The stored local law ``u = Q_EQ + K (x - X_EQ)``."""
    return LinearLaw(K_LOCAL, x_eq=X_EQ, u_eq=[Q_EQ])


def terminal_set() -> Polytope:
    """The stored terminal set ``{x : |H_BOX (x - X_EQ)|_inf <= SCALE}`` (robustly
    invariant under :func:`local_law` for ``|w| <= W_MAX``, proven by
    ``cm.certify_invariant``)."""
    return Polytope(np.vstack([H_BOX, -H_BOX]), B_TERMINAL)


def compute_terminal(**options: Any) -> Any:
    """Recompute the equilibrium, the local law and the terminal set with
    :func:`casadi_cmpc.terminal_set` (robust over the model's W): returns its
    TerminalSetResult, whose ``x_eq``, ``law.K``, ``unit.A[:3]``, ``scale`` and
    ``terminal.b`` are the constants ``X_EQ``, ``K_LOCAL``, ``H_BOX``, ``SCALE`` and
    ``B_TERMINAL`` of this module."""
    from ..control.terminal import terminal_set as search

    model = three_tank_model()
    x_eq = model.equilibrium([Q_EQ], x0=continuous_equilibrium())
    kw = {"x_eq": x_eq, "u_eq": [Q_EQ], "shape": "parallelotope", "progress": False}
    kw.update(options)
    return search(model, **kw)


def build() -> Example:
    """Build the three-tank example."""
    model = three_tank_model()
    law = local_law()
    T = terminal_set()
    return Example(
        name="three_tank",
        model=model,
        terminal=T,
        local_law=law,
        x0s=X0S.copy(),
        info={
            "example": "extra",
            "description": "three-tank cascade, one pump, sqrt outflows, non-zero "
                           "equilibrium, RK4 dt = 5 s, certified terminal set (not from "
                           "the thesis)",
            "section": "",
            "equation": "Torricelli outflows, RK4",
            "mpc": {"horizon": 10, "alpha": 0.9, "x_ref": X_EQ.copy(),
                    "u_ref": np.array([Q_EQ]),
                    "Q": np.eye(3), "R": np.array([[1e-3]]),
                    "local_law": law, "local_set": T},
            "run": {"steps": 150, "disturbance": "uniform",
                    "note": "nominal contractive MPC towards the equilibrium (w = 0 in the "
                            "prediction) with the inflow disturbance w drawn uniformly in "
                            "[-0.5, 0.5] cm^3/s; u = u_eq + K (x - x_eq) inside the "
                            "terminal set, robustly invariant under it"},
            "dt": DT,
            "parameters": {"A": AREA, "c": C_OUT, "g": G},
            "x_eq": X_EQ.copy(),
            "u_eq": np.array([Q_EQ]),
            "x_eq_continuous": continuous_equilibrium(),
            "terminal_scale": SCALE,
            "terminal_shape": "parallelotope",
            "terminal_status": "certified robustly invariant for |w| <= 0.5 cm^3/s (and "
                               "inside X, law inside U) by cm.terminal_set / "
                               "cm.certify_invariant",
            "terminal_seconds": TERMINAL_SECONDS,
            "choices": {
                "parameters": "tank section and orifices of a laboratory three-tank rig, "
                              "the tanks in a cascade",
                "dt": "5 s, RK4",
                "boxes": "5 <= h <= 60 cm, 0 <= q <= 100 cm^3/s, |w| <= 0.5 cm^3/s",
                "local_law": "LQR of the linearisation at the equilibrium, Bryson's "
                             "weights",
            },
        },
    )
