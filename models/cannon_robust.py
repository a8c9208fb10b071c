"""E9 — E8 with the uncertain parameter mu in [0.85, 0.95] (thesis §5.2.5, (5.22)).

mu is the model's disturbance ``w`` (l = 1). Robust invariance of (5.23) under
``u = K x``; robust K1 with eps = 0.05; maximal robust set when K48 = K49; robust closed
loop from (1.75, -1.6) with mu random in [0.85, 0.95] at each step and Q = R = 1.
"""

from __future__ import annotations

import numpy as np

from . import Example
from ._cannon import H_TERMINAL, K_CANNON, cannon_model, cannon_terminal

DT = 0.1  # (5.22)
MU_RANGE = (0.85, 0.95)  # §5.2.5
X_MAX = 2.0  # |x|_inf <= 2, §5.2.5
X0S = np.array([[1.75, -1.6]])  # Fig 5.6


def build() -> Example:
    """Build E9."""
    return Example(
        name="cannon_robust",
        model=cannon_model(DT, X_MAX, mu_range=MU_RANGE, name="cannon_robust"),
        terminal=cannon_terminal(),
        local_law=K_CANNON.copy(),
        x0s=X0S.copy(),
        info={
            "example": "E9",
            "mpc": {"horizon": 10, "alpha": 0.9, "local_law": K_CANNON.copy(),
                    "local_set": cannon_terminal()},
            "run": {"steps": 60, "disturbance": "uniform",
                    "note": "nominal contractive MPC (mu = 0.9 in the prediction) with mu drawn "
                            "uniformly in [0.85, 0.95] at each step; its certificates hold for "
                            "the nominal mu only"},
            "sequence": {"eps": 0.05, "robust": True, "Q": np.eye(2), "R": np.eye(1),
                         "note": "robust one-step MPC along the robust controllable sets "
                                 "(Alg 5.4), mu drawn uniformly in [0.85, 0.95] at each step; "
                                 "every control certified for all mu; u = K x inside T"},
            "section": "5.2.5",
            "equation": "(5.22), terminal (5.23)",
            "figures": ["5.3", "5.4", "5.5", "5.6"],
            "dt": DT,
            "mu_range": MU_RANGE,
            "H_terminal": H_TERMINAL.copy(),
            "eps": 0.05,
            "expected_converged_at": 48,  # K48 = K49
            "Q": np.eye(2),
            "R": np.eye(1),
            "disturbance": "mu uniform in [0.85, 0.95], drawn at every step",
            "notes": ["row 2 of (5.23) is printed as -0.8199 (the other rows suggest -0.8190);"
                      " kept as printed"],
            "choices": {},
        },
    )
