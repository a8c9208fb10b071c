"""E10 — E8 with mu in [0.75, 0.95] and |x|_inf <= 4 (thesis §6.1.6, (6.9)).

Polytopic robust controllable sets: K1 with eps = 0.025 and 0.05 and their polytopic inner
approximations (Alg 6.2); with eps = 0.05 the terminal set is not inside P1 and the union
T ∪ P1 becomes the next target (6.8). Closed loops from (-1.5, 1.1) and (0.3, -2.1).
"""

from __future__ import annotations

import numpy as np

from . import Example
from ._cannon import H_TERMINAL, K_CANNON, cannon_model, cannon_terminal

DT = 0.1  # (6.9)
MU_RANGE = (0.75, 0.95)  # §6.1.6
X_MAX = 4.0  # |x|_inf <= 4, §6.1.6
X0S = np.array([[-1.5, 1.1], [0.3, -2.1]])  # Fig 6.5


def build() -> Example:
    """Build E10."""
    return Example(
        name="cannon_robust_wide",
        model=cannon_model(DT, X_MAX, mu_range=MU_RANGE, name="cannon_robust_wide"),
        terminal=cannon_terminal(),
        local_law=K_CANNON.copy(),
        x0s=X0S.copy(),
        info={
            "example": "E10",
            "mpc": {"horizon": 10, "alpha": 0.9, "local_law": K_CANNON.copy(),
                    "local_set": cannon_terminal()},
            "run": {"steps": 60, "disturbance": "uniform",
                    "note": "nominal contractive MPC (mu = 0.85 in the prediction), mu drawn "
                            "uniformly in [0.75, 0.95] at each step; certificates hold for the "
                            "nominal mu only"},
            "sequence": {"eps": 0.05, "robust": True, "Q": np.eye(2), "R": np.eye(1),
                         "note": "robust one-step MPC along the robust controllable sets "
                                 "(Alg 6.3), mu drawn uniformly in [0.75, 0.95] at each step; "
                                 "every control certified for all mu; u = K x inside T"},
            "section": "6.1.6",
            "equation": "(6.9), terminal (6.10)",
            "figures": ["6.2", "6.3", "6.4", "6.5"],
            "dt": DT,
            "mu_range": MU_RANGE,
            "H_terminal": H_TERMINAL.copy(),
            "eps": 0.05,
            "eps_values_fig_6_3": (0.025, 0.05),
            "notes": ["row 2 of (6.10) is printed as -0.8199 (the other rows suggest -0.8190);"
                      " kept as printed"],
            "choices": {},
        },
    )
