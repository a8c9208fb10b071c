"""E7 — nonlinear system of Grimm et al. (2004) (thesis §4.3.4, (4.24)).

::

    x1+ = x1 (1 - u)
    x2+ = u sqrt(x1^2 + x2^2),         u in [0, 1],  |x|_inf <= 3.

Nonlinear MPC with a compulsory contractive constraint (4.22)-(4.23), the horizon found by
set inversion (Alg 4.5), from x(0) = (2, 2). No terminal set and no local law.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..model import Model
from ..sets.box import Box
from . import Example

U_RANGE = (0.0, 1.0)  # u in [0, 1], §4.3.4
X_MAX = 3.0  # |x|_inf <= 3, §4.3.4
X0S = np.array([[2.0, 2.0]])  # Fig 4.11


def build() -> Example:
    """Build E7."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] * (1 - u), u * ca.sqrt(x[0] ** 2 + x[1] ** 2))
    model = Model(x=x, u=u, f=f, X=Box([-X_MAX, -X_MAX], [X_MAX, X_MAX]),
                  U=Box([U_RANGE[0]], [U_RANGE[1]]), name="grimm")
    return Example(
        name="grimm",
        model=model,
        terminal=None,
        local_law=None,
        x0s=X0S.copy(),
        info={
            "example": "E7",
            "mpc": {"horizon": None, "alpha": 0.5, "norm": 2, "horizon_max": 4},
            "run": {"steps": 40, "note": "Alg 4.5: the smallest horizon not proven infeasible "
                    "is searched at every step; alpha = 0.5 (a choice) makes horizon 1 "
                    "infeasible from (2, 2)"},
            "section": "4.3.4",
            "equation": "(4.24); MPC (4.22)-(4.23), Alg 4.5",
            "figures": ["4.11"],
            "unspecified": ["contraction parameter alpha and norm p of (4.23)",
                            "weights P0, Q, R of (4.22)", "set-inversion tolerance eps"],
            "choices": {},
        },
    )
