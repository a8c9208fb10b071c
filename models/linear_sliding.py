"""E1 — linear system with a sliding-domain terminal set (thesis §3.3.4, §3.4.4, (3.7)).

::

    x1+ = 0.9 x1 + 0.1 x2
    x2+ = -0.5 x1 + 0.2 x2 + u,        |u| <= 2,  |x|_inf <= 8.

Terminal set: the sliding domain ``S = {x : c x1 + x2 = 0 for some c in [1, 2],
|x1|, |x2| <= 4}``, i.e. the cone between the lines ``x2 = -x1`` and ``x2 = -2 x1``
clipped by the box. It is the union of two triangles (``x1 >= 0`` and ``x1 <= 0``), used
as such by the controllable sets of §3.4; its convex hull (a parallelogram,
``info["terminal_hull"]``) configures the LP of §3.3.

Local law: the equivalent control of sliding mode. For a fixed ``c`` it keeps
``s = c x1 + x2 = 0``: ``c x1+ + x2+ = 0`` gives ``u = (0.5 - 0.9 c) x1 - (0.2 + 0.1 c) x2``.
On S the state fixes ``c = -x2 / x1``, which gives the law of the thesis,
``u_eq(x) = 0.5 x1 + 0.7 x2 + 0.1 x2^2 / x1`` (set to 0 at ``x1 = 0``, where S has only
the origin). It keeps the ratio ``x2 / x1`` and contracts ``x1`` by ``0.9 - 0.1 c`` in
[0.7, 0.8]; on S, ``|u_eq| <= 1``. The linear law ``u = [0.3, 0.4] x`` coincides with
``u_eq`` on both boundary lines (c = 1 and c = 2) and also maps S into itself; it is given
as ``info["local_gain"]`` for algorithms that need a gain.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..model import Model
from ..sets.box import Box
from ..sets.polytope import Polytope, PolytopeUnion
from . import Example

# (3.7): x+ = A x + B u
A = np.array([[0.9, 0.1], [-0.5, 0.2]])
B = np.array([[0.0], [1.0]])
U_MAX = 2.0  # u in [-2, 2], §3.3.4
X_MAX = 8.0  # |x|_inf <= 8, §3.3.4
C_RANGE = (1.0, 2.0)  # c in [1, 2], sliding domain of §3.3.4
S_BOX = 4.0  # x1, x2 in [-4, 4] in the sliding domain
X0S = np.array([[6.8, 7.2], [-7.2, -5.8]])  # Fig 3.2, 3.4

# The two pieces of S: triangles (0,0), (2,-4), (4,-4) and (0,0), (-2,4), (-4,4)
S_RIGHT = (np.array([[1.0, 1.0], [-2.0, -1.0], [0.0, -1.0]]), np.array([0.0, 0.0, S_BOX]))
S_LEFT = (np.array([[-1.0, -1.0], [2.0, 1.0], [0.0, 1.0]]), np.array([0.0, 0.0, S_BOX]))
# Convex hull of S: parallelogram with vertices (2,-4), (4,-4), (-2,4), (-4,4)
HULL = (np.array([[0.0, 1.0], [0.0, -1.0], [4.0, 3.0], [-4.0, -3.0]]),
        np.array([S_BOX, S_BOX, 4.0, 4.0]))
# Linear law equal to u_eq on the lines c = 1 and c = 2
K_BOUNDARY = np.array([[0.3, 0.4]])


def equivalent_control_gain(c: float) -> np.ndarray:
    """Gain (1, 2) of the equivalent control that keeps ``c x1 + x2 = 0`` (fixed c)."""
    return np.array([[0.5 - 0.9 * c, -(0.2 + 0.1 * c)]])


def build() -> Example:
    """Build E1."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.mtimes(ca.DM(A), x) + ca.mtimes(ca.DM(B), u)
    model = Model(x=x, u=u, f=f, X=Box([-X_MAX, -X_MAX], [X_MAX, X_MAX]),
                  U=Box([-U_MAX], [U_MAX]), name="linear_sliding")
    u_eq = ca.if_else(x[0] != 0, 0.5 * x[0] + 0.7 * x[1] + 0.1 * x[1] ** 2 / x[0], 0)
    terminal = PolytopeUnion([Polytope(*S_RIGHT), Polytope(*S_LEFT)])
    return Example(
        name="linear_sliding",
        model=model,
        terminal=terminal,
        local_law=u_eq,
        x0s=X0S.copy(),
        info={
            "example": "E1",
            "mpc": {"solver": "lp", "norm": Polytope(*HULL), "alpha": 0.9, "horizon": None,
                    "horizon_max": 12, "local_law": u_eq, "local_set": terminal},
            "run": {"steps": 30, "note": "contractive MPC by LP (3.5)-(3.6), gauge of the "
                    "convex hull of S; the equivalent control u_eq inside S"},
            "section": "3.3.4, 3.4.4",
            "equation": "(3.7); MPC (3.5)-(3.6) and (3.9)-(3.10)",
            "figures": ["3.1", "3.2", "3.3", "3.4"],
            "A": A.copy(),
            "B": B.copy(),
            "c_range": C_RANGE,
            "terminal_hull": Polytope(*HULL),
            "local_gain": K_BOUNDARY.copy(),
            "local_law_formula": "u_eq = 0.5 x1 + 0.7 x2 + 0.1 x2^2 / x1 (c = -x2/x1)",
            "unspecified": ["contraction parameter alpha of (3.6)",
                            "initial state x(0) = (3, 3) of the text is not used in the figures"],
            "choices": {},
        },
    )
