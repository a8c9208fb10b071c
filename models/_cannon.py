"""The input-affine system of Cannon et al. (2003), shared by E5, E8, E9 and E10.

Thesis (4.17), (4.28), (5.22), (6.9)::

    x1+ = x1 + dt x2 + dt (mu + (1 - mu) x1) u
    x2+ = dt x1 + x2 + dt (mu - 4 (1 - mu) x2) u

with dt = 0.01 in (4.17) and dt = 0.1 in the other three. ``mu`` is either a fixed
number or the uncertain parameter ``w`` of the model.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..model import Model
from ..sets.box import Box
from ..sets.polytope import Polytope

# Local law u = K x of Cannon et al. (2003), thesis §4.2.6, (4.29), (5.23), (6.10)
K_CANNON = np.array([[-1.2131, -1.2128]])

# Terminal polytope T = {x : H x <= 1} of (4.29) = (5.23) = (6.10), as printed. Row 2
# reads -0.8199 where symmetry (H = 5 V with V of §4.2.6) suggests -0.8190.
H_TERMINAL = np.array([
    [0.8190, -1.9655],
    [-0.8199, 1.9655],
    [3.033, 3.033],
    [-3.033, -3.033],
])

U_MAX = 2.0  # |u| <= 2 in every Cannon example


def cannon_terminal() -> Polytope:
    """The terminal polytope ``{x : H x <= 1}`` of (4.29)/(5.23)/(6.10)."""
    return Polytope(H_TERMINAL, np.ones(H_TERMINAL.shape[0]))


def cannon_model(dt: float, x_max: float, mu: float | None = None,
                 mu_range: tuple[float, float] | None = None, name: str = "cannon") -> Model:
    """Build the Cannon system.

    Parameters
    ----------
    dt : float
        Step of the discretisation (0.01 or 0.1).
    x_max : float
        State box ``|x|_inf <= x_max``.
    mu : float, optional
        Fixed value of mu (substituted as a number; the model has no ``w``).
    mu_range : (lo, hi), optional
        Range of an uncertain mu, which becomes the model's disturbance ``w`` (l = 1).
    """
    if (mu is None) == (mu_range is None):
        raise ValueError("give exactly one of mu (fixed) and mu_range (uncertain)")
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    if mu_range is not None:
        w = ca.SX.sym("mu")
        m_ = w
        W = Box([mu_range[0]], [mu_range[1]])
    else:
        w = None
        m_ = float(mu)
        W = None
    f = ca.vertcat(
        x[0] + dt * x[1] + dt * (m_ + (1 - m_) * x[0]) * u,
        dt * x[0] + x[1] + dt * (m_ - 4 * (1 - m_) * x[1]) * u,
    )
    # the thesis gives no units and no sampling time (dt is a coefficient of the map):
    # default names x1, x2, u1, time in steps
    return Model(x=x, u=u, f=f, w=w, X=Box([-x_max, -x_max], [x_max, x_max]),
                 U=Box([-U_MAX], [U_MAX]), W=W, name=name,
                 disturbance_names=["mu"] if w is not None else None)
