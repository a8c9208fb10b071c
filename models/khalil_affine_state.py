"""E11 — Khalil (2002) system with an affine state part (thesis §6.2.5, (6.14)).

::

    x1+ = x1 + 0.1 x1^2 - 0.1 u x1^3 + 0.1 x2
    x2+ = x2 + 0.1 u + w,          |u| <= 3,  |x|_inf <= 1,  w in [-0.01, 0.01].

Only x1 enters nonlinearly, so ``f = A x + g(x1, u, w)`` with ``A = [[0, 0.1], [0, 1]]``
(columns of the linear states) and only x1 is bisected (Alg 6.4).

Choices (the thesis shows its terminal polytope only in Fig 6.6):

* local law ``u = K x``, ``K = [-5.8909, -7.1188]``: discrete LQR of the linearisation at
  the origin (``A0 = [[1, 0.1], [0, 1]]``, ``B0 = [[0], [0.1]]``) with ``Q = I``,
  ``R = 0.01``, rounded to 4 decimals; closed-loop eigenvalues 0.904 and 0.384;
* terminal polytope ``T = {x : |T_V x|_inf <= 1}`` (low complexity, four facets) with the
  rows of ``T_V`` along the left eigenvectors of ``A0 + B0 K``, scaled so that the worst
  case of the successor of every facet under ``u = K x``, with the nonlinear terms bounded
  over T and ``w`` at its extremes, is at most 0.951 (robust contraction of the facets by
  about 5 %). On T, ``|K x| <= 1.30`` and ``|x1| <= 0.193``, ``|x2| <= 0.342``.

T is **proven** robustly invariant under ``u = K x`` for all w in W, with ``K x`` in U:
:func:`casadi_cmpc.certify_invariant` (set inversion over sub-zonotopes of T, outward
rounding) at ``eps = 0.05`` answers ``proved``, and ``T ⊆ X`` holds (``|x1| <= 0.193``,
``|x2| <= 0.342``). ``cmpc run khalil_affine_state`` repeats the proof before it computes
the controllable sets (``info["affine_state"]``: eps = 0.05, polytopes by Alg 6.5; the
recursion stops at P_23, where the thesis reports P39 = P40) and runs the robust one-step
MPC along them from (-0.5, -0.8).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..model import Model
from ..sets.box import Box
from ..sets.polytope import Polytope
from . import Example

U_MAX = 3.0  # |u| <= 3, §6.2.5
X_MAX = 1.0  # |x|_inf <= 1, §6.2.5
W_MAX = 0.01  # w in [-0.01, 0.01], §6.2.5
X0S = np.array([[-0.5, -0.8]])  # Fig 6.9
# Affine state part of (6.14): columns of the linear states (x2), zero for x1
A_AFFINE = np.array([[0.0, 0.1], [0.0, 1.0]])

# Choices (not in the thesis), see the module docstring
LQR_Q = np.eye(2)
LQR_R = np.array([[0.01]])
K_LOCAL = np.array([[-5.8909, -7.1188]])
T_V = np.array([[7.307, 1.186], [6.073, 6.353]])  # terminal set |T_V x|_inf <= 1
TERMINAL_EPS = 0.05  # certify_invariant proves T at this resolution
AFFINE_EPS = 0.05  # resolution of the affine-state controllable sets of `cmpc run`


def terminal_set() -> Polytope:
    """The chosen terminal polytope ``[T_V; -T_V] x <= 1``."""
    return Polytope(np.vstack([T_V, -T_V]), np.ones(4))


def build() -> Example:
    """Build E11."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    f = ca.vertcat(
        x[0] + 0.1 * x[0] ** 2 - 0.1 * u * x[0] ** 3 + 0.1 * x[1],
        x[1] + 0.1 * u + w,
    )
    model = Model(x=x, u=u, f=f, w=w, X=Box([-X_MAX, -X_MAX], [X_MAX, X_MAX]),
                  U=Box([-U_MAX], [U_MAX]), W=Box([-W_MAX], [W_MAX]),
                  name="khalil_affine_state", disturbance_names=["w"])
    return Example(
        name="khalil_affine_state",
        model=model,
        terminal=terminal_set(),
        local_law=K_LOCAL.copy(),
        x0s=X0S.copy(),
        info={
            "example": "E11",
            "mpc": {"horizon": 10, "alpha": 0.9, "local_law": K_LOCAL.copy(),
                    "local_set": terminal_set()},
            "run": {"steps": 60, "disturbance": "uniform",
                    "note": "nominal contractive MPC (w = 0 in the prediction) with w drawn "
                            "uniformly in [-0.01, 0.01]; u = K x inside the terminal polytope "
                            "(proven robustly invariant under it)"},
            # the structured pipeline of `cmpc run` (thesis §6.2.4-6.2.5, Alg 6.4-6.6)
            "affine_state": {"eps": AFFINE_EPS, "robust": True,
                             "polytopic_method": "scaling", "max_steps": 60,
                             "Q": np.eye(2),
                             "R": np.array([[0.01]]), "solver": "ipopt",
                             "note": "robust one-step MPC along the polytopic robust "
                                     "controllable sets of the affine-state method (Alg "
                                     "6.4-6.6); w drawn uniformly in [-0.01, 0.01]; every "
                                     "applied control proven for all w in W; u = K x in T"},
            "section": "6.2.5",
            "equation": "(6.14); Alg 6.4, 6.5, 6.6",
            "figures": ["6.6", "6.7", "6.8", "6.9"],
            "affine_state_matrix": A_AFFINE.copy(),
            "nonlinear_states": (0,),
            "expected_converged_at": 39,  # P39 = P40
            "unspecified": ["terminal polytope (only drawn in Fig 6.6)", "local law",
                            "bisection tolerance eps", "weights Q, R of (6.12)"],
            "choices": {
                "local_law": "discrete LQR of the linearisation at 0, Q = I, R = 0.01, "
                             "rounded to 4 decimals",
                "lqr_Q": LQR_Q.copy(),
                "lqr_R": LQR_R.copy(),
                "terminal": "low-complexity polytope |T_V x|_inf <= 1 along the left "
                            "eigenvectors of the linearised closed loop",
                "T_V": T_V.copy(),
                "terminal_status": "proven robustly invariant under u = K x for all w in W "
                                   "(certify_invariant, eps = 0.05; T in X)",
                "terminal_certificate": {"method": "certify_invariant", "eps": TERMINAL_EPS,
                                         "robust": True, "law": "u = K x"},
            },
        },
    )
