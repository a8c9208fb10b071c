"""E8 — Cannon et al. (2003) system with dt = 0.1, mu = 0.9 (thesis §4.4.4, (4.28)).

Nonlinear one-step MPC along controllable sets: terminal polytope (4.29) with the local
law ``u = K x``; first controllable set by Alg 4.6; maximal controllable set with
eps = 0.05 reached at step 41 (Fig 4.14); closed loop from (1.9, -1.5) (Fig 4.15).
"""

from __future__ import annotations

import numpy as np

from . import Example
from ._cannon import H_TERMINAL, K_CANNON, cannon_model, cannon_terminal

DT = 0.1  # (4.28)
MU = 0.9  # §4.4.4
X_MAX = 2.0  # |x|_inf <= 2, §4.4.4
X0S = np.array([[1.9, -1.5]])  # Fig 4.15


def build() -> Example:
    """Build E8."""
    return Example(
        name="cannon",
        model=cannon_model(DT, X_MAX, mu=MU, name="cannon"),
        terminal=cannon_terminal(),
        local_law=K_CANNON.copy(),
        x0s=X0S.copy(),
        info={
            "example": "E8",
            "mpc": {"horizon": 10, "alpha": 0.9, "local_law": K_CANNON.copy(),
                    "local_set": cannon_terminal()},
            "run": {"steps": 60, "note": "contractive MPC (N = 10, alpha = 0.9), then u = K x "
                    "inside T"},
            "sequence": {"eps": 0.05, "robust": False, "Q": np.eye(2), "R": np.eye(1),
                         "note": "one-step MPC along the controllable sets (Alg 4.7), then "
                                 "u = K x inside T"},
            "section": "4.4.4",
            "equation": "(4.28), terminal (4.29)",
            "figures": ["4.12", "4.13", "4.14", "4.15"],
            "dt": DT,
            "mu": MU,
            "H_terminal": H_TERMINAL.copy(),
            "eps": 0.05,
            "expected_converged_at": 41,
            "notes": ["row 2 of (4.29) is printed as -0.8199 (the other rows suggest -0.8190);"
                      " kept as printed"],
            "choices": {},
        },
    )
