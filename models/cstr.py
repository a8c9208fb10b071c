"""E6 / E14 — continuous stirred-tank reactor (thesis §4.2.7, §7.2, (4.19)-(4.20), (7.8)-(7.9)).

ODE (7.8) for an exothermic irreversible reaction A -> B::

    dC_A/dt = q/V (C_Af - C_A) - k0 exp(-E/(R T)) C_A
    dT/dt   = q/V (T_f - T) + (-dH)/(rho C_p) k0 exp(-E/(R T)) C_A + UA/(V rho C_p) (T_c - T)

In the scaled coordinates ``x = [C_A - 0.5, (T - 350)/100]``, ``u = (T_c - 300)/100`` and
with explicit Euler, dt = 0.03 min, this is (7.9)::

    x1+ = x1 + 0.03   (q/V (C_Af - (x1 + 0.5)) - k0 exp(-E/(R (100 x2 + 350))) (x1 + 0.5))
    x2+ = x2 + 0.0003 (q/V (T_f - (100 x2 + 350)) + (-dH)/(rho C_p) k0 exp(...) (x1 + 0.5)
                       + UA/(V rho C_p) (100 u + 300 - (100 x2 + 350)))

Constraints 0 <= C_A <= 1 mol/l, 280 <= T <= 370 K, 280 <= T_c <= 370 K become
``x1 in [-0.5, 0.5]``, ``x2 in [-0.7, 0.2]``, ``u in [-0.2, 0.7]``.

E6 (Alg 4.4, Fig 4.10): largest control-invariant zonotope under ``u = K x`` from the
search matrix M0, giving ``Z = M B^4``, whose H-representation is the terminal polytope
(7.10). E14 (Fig 7.4-7.6): polytopic controllable sets towards (7.10), K1 with
eps = 0.001, and the dual-mode closed loop from (C_A, T) = (0.4 mol/l, 326 K).
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

# Parameters of (4.19) / (7.8), §4.2.7 and §7.2
Q_FLOW = 100.0  # q, l/min
C_AF = 1.0  # C_Af, mol/l
T_F = 350.0  # T_f, K
VOLUME = 100.0  # V, l
RHO = 1000.0  # rho, g/l
C_P = 0.239  # C_p, J/(g K)
DELTA_H = -5.0e4  # dH, J/mol
E_OVER_R = 8750.0  # E/R, K
K0 = 7.2e10  # k0, 1/min
UA = 5.0e4  # UA, J/(min K)
# Unstable equilibrium used as origin
C_A_EQ = 0.5  # mol/l
T_EQ = 350.0  # K
T_C_EQ = 300.0  # K
DT = 0.03  # sampling time, min (Euler), (4.20) / (7.9)
DT_SECONDS = 1.8  # the same in seconds
# The validated variant (cstr_validated): Taylor order, sampling time (min) and state box
# around the equilibrium. Over the thesis box X with dt = 0.03 min the flow runs away in the
# hot corner (from C_A = 0.95 mol/l, T = 370 K, T_c = 370 K the temperature passes 500 K
# within one sample) and the best remainder enclosure found is wider than 1e4; here it is
# about 4e-5.
VALIDATED_ORDER = 4
VALIDATED_DT = 0.01  # min
VALIDATED_X = ((-0.1, -0.1), (0.1, 0.05))  # (lo, hi): C_A in [0.4, 0.6], T in [340, 355]
# Names of the scaled state x = [C_A - C_A_eq, (T - T_eq)/100] and input (T_c - T_c_eq)/100
STATE_NAMES = ["C_A - 0.5", "(T - 350)/100"]
INPUT_NAMES = ["(T_c - 300)/100"]
# Physical constraints
C_A_RANGE = (0.0, 1.0)  # mol/l
T_RANGE = (280.0, 370.0)  # K
T_C_RANGE = (280.0, 370.0)  # K

# Local law u = K x (LQ design on the linearisation, Magni et al. 2001), §4.2.7 / §7.2
K_LOCAL = np.array([[-0.0690, -4.3387]])

# Terminal polytope (7.10)
H_TERMINAL = np.array([
    [0.31623, -0.94868],
    [-0.31623, 0.94868],
    [-0.70711, -0.70711],
    [0.70711, 0.70711],
    [-1.0, 0.0],
    [1.0, 0.0],
    [0.0, 1.0],
    [0.0, -1.0],
])
B_TERMINAL = np.array([0.037947, 0.037947, 0.056569, 0.056569, 0.06, 0.06, 0.04, 0.04])

# Alg 4.4 (§4.2.7): search interval matrix M0 (n, m, 2), tolerances, and the result
M0_SEARCH = np.array([[[0.0, 0.04], [-0.04, 0.0]], [[0.0, 0.04], [0.0, 0.04]]])
EPS_OPT = 0.005
EPS_SIVIA = 0.05
M_ZONOTOPE = np.array([[0.03, -0.01, 0.02, 0.0], [0.01, 0.01, 0.0, 0.02]])
EPS_E14 = 0.001  # Fig 7.4

X0_PHYSICAL = np.array([[0.4, 326.0]])  # (C_A, T) of Fig 7.6


def from_physical(c_a: Any, temp: Any) -> np.ndarray:
    """Scaled state ``[C_A - 0.5, (T - 350)/100]``; shape (N, 2) or (2,)."""
    return np.stack([np.asarray(c_a, float) - C_A_EQ,
                     (np.asarray(temp, float) - T_EQ) / 100.0], axis=-1)


def to_physical(x: Any) -> np.ndarray:
    """``(C_A, T)`` from scaled states ``x`` of shape (N, 2) or (2,)."""
    x = np.asarray(x, dtype=float)
    return np.stack([x[..., 0] + C_A_EQ, 100.0 * x[..., 1] + T_EQ], axis=-1)


def input_to_physical(u: Any) -> np.ndarray:
    """Coolant temperature ``T_c = 100 u + 300`` (K)."""
    return 100.0 * np.asarray(u, dtype=float) + T_C_EQ


def rhs(x: ca.SX, u: ca.SX) -> ca.SX:
    """Right-hand side of the ODE (7.8) in scaled coordinates (time unit: min)."""
    c_a = x[0] + C_A_EQ
    temp = 100 * x[1] + T_EQ
    t_c = 100 * u + T_C_EQ
    rate = K0 * ca.exp(-E_OVER_R / temp) * c_a
    dc_a = Q_FLOW / VOLUME * (C_AF - c_a) - rate
    dtemp = (Q_FLOW / VOLUME * (T_F - temp) + (-DELTA_H) / (RHO * C_P) * rate
             + UA / (VOLUME * RHO * C_P) * (t_c - temp))
    return ca.vertcat(dc_a, dtemp / 100)


def build(validated: bool = False, order: int = VALIDATED_ORDER) -> Example:
    """Build E6/E14: the thesis' Euler model (7.9), or with ``validated=True`` the
    validated sampled-data model of the ODE (7.8) (``Model.from_ode(method="taylor")``,
    Taylor order ``order``; registered as ``cstr_validated``) with dt = ``VALIDATED_DT``
    and the state box ``VALIDATED_X`` around the equilibrium (see the notes at their
    definitions). The terminal set (7.10) and the local law are those of the thesis,
    computed for the Euler model (not certified for the validated one)."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    X = Box([C_A_RANGE[0] - C_A_EQ, (T_RANGE[0] - T_EQ) / 100],
            [C_A_RANGE[1] - C_A_EQ, (T_RANGE[1] - T_EQ) / 100])
    U = Box([(T_C_RANGE[0] - T_C_EQ) / 100], [(T_C_RANGE[1] - T_C_EQ) / 100])
    units = dict(zip(STATE_NAMES + INPUT_NAMES, ("mol/l", "K", "K"), strict=True))
    if validated:
        name = "cstr_validated"
        model = Model.from_ode(x=x, u=u, rhs=rhs(x, u), dt=VALIDATED_DT, method="taylor",
                               order=order, X=Box(*VALIDATED_X), U=U, name=name,
                               state_names=STATE_NAMES, input_names=INPUT_NAMES, units=units,
                               time_unit=60.0)
    else:
        name = "cstr"
        sampled = Model.from_ode(x=x, u=u, rhs=rhs(x, u), dt=DT, method="euler", X=X, U=U,
                                 name="cstr")
        # the same map with the names and units of the scaled coordinates (T in K, C_A in
        # mol/l: x2 = (T - 350)/100 and u = (T_c - 300)/100 are in K) and the sampling time
        # in seconds (dt = 0.03 min)
        model = Model(x=sampled.x, u=sampled.u, f=sampled.f, X=X, U=U, name="cstr",
                      state_names=STATE_NAMES, input_names=INPUT_NAMES, units=units,
                      dt=DT_SECONDS)
        model._discretisation = sampled.discretisation
    x_eq = model.equilibrium(np.zeros(1), x0=np.zeros(2))
    return Example(
        name=name,
        model=model,
        terminal=Polytope(H_TERMINAL, B_TERMINAL),
        local_law=K_LOCAL.copy(),
        x0s=(from_physical(X0_PHYSICAL[:, 0], X0_PHYSICAL[:, 1]) if not validated
             else from_physical(np.array([0.45]), np.array([345.0]))),
        info={
            "example": "E6, E14" if not validated else "extra",
            "mpc": {"horizon": 10, "alpha": 0.9, "x_ref": x_eq, "u_ref": np.zeros(1),
                    "local_law": LinearLaw(K_LOCAL, x_eq=x_eq, u_eq=np.zeros(1)),
                    "local_set": Polytope(H_TERMINAL, B_TERMINAL),
                    # whole plans (alpha = 0.9 per 10 steps) reach the terminal set too
                    # slowly for the 100 steps of Fig 7.6: the first move is applied
                    "mode": "receding"},
            "sequence": {"eps": 0.002, "robust": False,
                         "note": "one-step MPC along the controllable sets (§7.2), then "
                                 "u = K x inside (7.10)"},
            "run": {"steps": 100, "note": "contractive MPC towards the exact equilibrium of "
                    "the Euler model (8e-5 from the origin of the scaled coordinates, whose "
                    "printed parameters are rounded), then u = K (x - x_eq) inside (7.10)"},
            "section": "4.2.7, 7.2",
            "equation": "(4.19)-(4.20) = (7.8)-(7.9); terminal (7.10)",
            "figures": ["4.10", "7.4", "7.5", "7.6"],
            "dt": DT if not validated else VALIDATED_DT,
            "dt_unit": "min",
            "equilibrium_physical": {"C_A": C_A_EQ, "T": T_EQ, "T_c": T_C_EQ},
            "x0s_physical": X0_PHYSICAL.copy(),
            "M0_search": M0_SEARCH.copy(),
            "eps_opt": EPS_OPT,
            "eps_sivia": EPS_SIVIA,
            "zonotope_generators": M_ZONOTOPE.copy(),
            "eps_e14": EPS_E14,
            "unspecified": ["weights Q, R of the one-step MPC of §7.2"],
            "choices": {},
        },
    )
