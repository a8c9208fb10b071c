"""E5 — Cannon et al. (2003) system with dt = 0.01 (thesis §4.2.4-4.2.6, (4.17)).

Zonotope vs interval evolution (Fig 4.6) and the invariance test of the low-complexity
polytope ``P = {x : |V x|_inf <= 0.9}`` under ``u = K x`` (Fig 4.9). The thesis notes that
``|V x|_inf <= 1`` (the set of Cannon et al.) is not admissible: ``max |K x| = 2.0002 > 2``
on it, so a certificate must refuse that set.

The initial box and control sequence of Fig 4.6 are not given numerically; no closed-loop
run belongs to this example, hence ``x0s`` is empty.
"""

from __future__ import annotations

import numpy as np

from ..sets.polytope import Polytope
from . import Example
from ._cannon import K_CANNON, cannon_model

DT = 0.01  # (4.17)
MU = 0.9  # §4.2.6
X_MAX = 4.0  # |x|_inf <= 4, §4.2.6
# Low-complexity polytope P = {x : |V x|_inf <= LEVEL}, §4.2.6
V = np.array([[0.1638, -0.3931], [0.6066, 0.6066]])
LEVEL = 0.9
LEVEL_CANNON = 1.0  # the original level of Cannon et al. (footnote of §4.2.6): not admissible


def low_complexity_polytope(level: float = LEVEL) -> Polytope:
    """``{x : |V x|_inf <= level}`` as ``[V; -V] x <= level``."""
    return Polytope(np.vstack([V, -V]), np.full(4, float(level)))


def build() -> Example:
    """Build E5."""
    model = cannon_model(DT, X_MAX, mu=MU, name="cannon_001")
    return Example(
        name="cannon_001",
        model=model,
        terminal=low_complexity_polytope(LEVEL),
        local_law=K_CANNON.copy(),
        x0s=np.zeros((0, 2)),
        info={
            "example": "E5",
            "mpc": {"horizon": 20, "alpha": 0.95, "local_law": K_CANNON.copy(),
                    "local_set": low_complexity_polytope(LEVEL)},
            "run": {"steps": 200, "x0s": [[2.0, -1.5]],
                    "note": "contractive MPC, then u = K x inside the terminal polytope; the "
                            "thesis gives no closed-loop run for E5: x0 = (2, -1.5) is a choice"},
            "section": "4.2.4-4.2.6",
            "equation": "(4.17)",
            "figures": ["4.6", "4.9"],
            "dt": DT,
            "mu": MU,
            "V": V.copy(),
            "level": LEVEL,
            "level_not_admissible": LEVEL_CANNON,
            "max_abs_Kx_at_level_1": 2.0002,  # thesis footnote of §4.2.6
            "terminal_not_admissible": low_complexity_polytope(LEVEL_CANNON),
            "unspecified": ["initial box and control sequence of Fig 4.6",
                            "bisection tolerance of the invariance test of Fig 4.9"],
            "choices": {},
        },
    )
