"""E12 — Khalil (2002) system with an affine control part (thesis §6.3.5, (6.24)).

::

    x1+ = x1 + 0.1 x2 + w
    x2+ = x2 + 0.1 (x1^2 + p x2^2 + u),     |u| <= 3,  |x|_inf <= 1,
                                             |w| <= 0.01,  p in [0.9, 1.0].

The model's disturbance is ``w = (w, p)`` with ``W = [-0.01, 0.01] x [0.9, 1.0]``. The
input enters through the constant ``B = [[0], [0.1]]``: ``f = g(x, w) + B u`` (thesis
(6.18)). ``f`` is bilinear in ``(x, p)`` through ``p x2^2``.

Choices (the thesis draws its terminal set Omega only in Fig 6.12, "enlarged from a
low-complexity polytope as well as a control invariant sliding domain"):

* local law ``u = K x``, ``K = [-9.873, -7.7381]``: discrete LQR of the linearisation at
  the origin (``A0 = [[1, 0.1], [0, 1]]``, ``B0 = [[0], [0.1]]``) with ``Q = diag(3, 1)``
  (x1 weighted more: the additive disturbance acts on x1), ``R = 0.01``, rounded to 4
  decimals; closed-loop eigenvalues 0.839 and 0.387;
* terminal polytope ``Omega = {x : |T_V x|_inf <= 1}`` (low complexity, four facets) along
  the left eigenvectors of ``A0 + B0 K``, scaled so that the worst case of the successor
  of every facet under ``u = K x`` (the nonlinear term ``0.1 (x1^2 + p x2^2)`` bounded over
  Omega, w and p at their extremes) is at most 0.947. On Omega, ``|K x| <= 1.70``,
  ``|x1| <= 0.219``, ``|x2| <= 0.499``.

Omega is **proven** robustly invariant under ``u = K x`` for all ``(w, p)`` in W, with
``K x`` in U: :func:`casadi_cmpc.certify_invariant` (set inversion over sub-zonotopes of
Omega, outward rounding) at ``eps = 0.05`` answers ``proved``, and ``Omega ⊆ X`` holds
(its bounding box: ``|x1| <= 0.219``, ``|x2| <= 0.499``). The thesis' own test, ``Omega ⊆``
its quasi one-step set (:func:`casadi_cmpc.control.quasi.quasi_invariance`), also proves
it at ``eps = 0.02``. ``cmpc run khalil_affine_control`` repeats the first proof before it
computes the quasi 2-step sets (``info["quasi"]``: eps = 0.05, polytopes by Alg 6.2; the
recursion stops at P_15, where the thesis reports P20 = P21) and runs the quasi multi-step
MPC (Alg 6.8) from both initial states of Fig 6.15.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..model import Model
from ..sets.box import Box
from ..sets.polytope import Polytope
from . import Example

U_MAX = 3.0  # |u| <= 3, §6.3.5
X_MAX = 1.0  # |x|_inf <= 1, §6.3.5
W_MAX = 0.01  # |w| <= 0.01, §6.3.5
P_RANGE = (0.9, 1.0)  # p in [0.9, 1.0], §6.3.5
X0S = np.array([[-0.7, -0.9], [0.77, 0.6]])  # Fig 6.15
B_INPUT = np.array([[0.0], [0.1]])  # constant input matrix of (6.24) in the form (6.18)

# Choices (not in the thesis), see the module docstring
LQR_Q = np.diag([3.0, 1.0])
LQR_R = np.array([[0.01]])
K_LOCAL = np.array([[-9.873, -7.7381]])
T_V = np.array([[7.266, 1.186], [11.087, 6.88]])  # terminal set |T_V x|_inf <= 1
TERMINAL_EPS = 0.05  # certify_invariant proves Omega at this resolution
QUASI_EPS = 0.05  # resolution of the quasi 2-step sets of `cmpc run`


def terminal_set() -> Polytope:
    """The chosen terminal polytope ``[T_V; -T_V] x <= 1``."""
    return Polytope(np.vstack([T_V, -T_V]), np.ones(4))


def build() -> Example:
    """Build E12."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w", 2)  # (additive w, parameter p)
    f = ca.vertcat(
        x[0] + 0.1 * x[1] + w[0],
        x[1] + 0.1 * (x[0] ** 2 + w[1] * x[1] ** 2 + u),
    )
    model = Model(x=x, u=u, f=f, w=w, X=Box([-X_MAX, -X_MAX], [X_MAX, X_MAX]),
                  U=Box([-U_MAX], [U_MAX]), W=Box([-W_MAX, P_RANGE[0]], [W_MAX, P_RANGE[1]]),
                  name="khalil_affine_control", disturbance_names=["w", "p"])
    return Example(
        name="khalil_affine_control",
        model=model,
        terminal=terminal_set(),
        local_law=K_LOCAL.copy(),
        x0s=X0S.copy(),
        info={
            "example": "E12",
            "mpc": {"horizon": 10, "alpha": 0.9, "local_law": K_LOCAL.copy(),
                    "local_set": terminal_set()},
            "run": {"steps": 100, "disturbance": "uniform",
                    "note": "nominal contractive MPC (w = 0, p = 0.95 in the prediction) with "
                            "(w, p) drawn uniformly at each step; u = K x inside the terminal "
                            "polytope (proven robustly invariant under it)"},
            # the structured pipeline of `cmpc run` (thesis §6.3.4-6.3.5, Alg 6.7, 6.8)
            "quasi": {"eps": QUASI_EPS, "steps": 2, "polytopic_method": "separating",
                      "max_sets": 40,
                      "P0": np.eye(2), "Q": np.zeros((2, 2)), "R": np.array([[0.1]]),
                      "solver": "ipopt",
                      "note": "robust quasi 2-step MPC (Alg 6.8) along polytopic quasi "
                              "2-step robust controllable sets; (w, p) drawn uniformly at "
                              "each step; every applied sequence proven for all (w, p) in W; "
                              "u = K x inside Omega"},
            "section": "6.3.5",
            "equation": "(6.24); Alg 6.7, MPC (6.22)-(6.23), Alg 6.8",
            "figures": ["6.10", "6.11", "6.12", "6.13", "6.14", "6.15"],
            "input_matrix": B_INPUT.copy(),
            "w_components": ("w (additive on x1)", "p (parameter of x2^2)"),
            "steps": 2,  # quasi 2-step sets
            "expected_converged_at": 20,  # P20 = P21
            "P0": np.eye(2),  # P0 = 1
            "Q": np.zeros((2, 2)),  # Q = 0
            "R": np.array([[0.1]]),  # R = 0.1
            "disturbance": "w and p uniform in their ranges, drawn at every step",
            "unspecified": ["terminal polytope Omega (only drawn in Fig 6.12)", "local law",
                            "bisection tolerance eps"],
            "choices": {
                "local_law": "discrete LQR of the linearisation at 0, Q = diag(3, 1), "
                             "R = 0.01, rounded to 4 decimals",
                "lqr_Q": LQR_Q.copy(),
                "lqr_R": LQR_R.copy(),
                "terminal": "low-complexity polytope |T_V x|_inf <= 1 along the left "
                            "eigenvectors of the linearised closed loop",
                "T_V": T_V.copy(),
                "terminal_status": "proven robustly invariant under u = K x for all (w, p) "
                                   "in W (certify_invariant, eps = 0.05; Omega in X); also "
                                   "by quasi_invariance (Omega inside its quasi one-step "
                                   "set, eps = 0.02)",
                "terminal_certificate": {"method": "certify_invariant", "eps": TERMINAL_EPS,
                                         "robust": True, "law": "u = K x"},
            },
        },
    )
