"""CSTR of E6/E14 as a validated sampled-data model (not a thesis example).

The ODE (7.8) of :mod:`casadi_cmpc.models.cstr` in the same scaled coordinates and input
box, discretised by ``Model.from_ode(method="taylor", order=4)`` with dt = 0.01 min on the
state box ``[-0.1, 0.1] x [-0.1, 0.05]`` around the equilibrium (C_A in [0.4, 0.6] mol/l,
T in [340, 355] K): the map ``f`` is the Taylor polynomial of the flow (the coolant
temperature held over the sample), and every interval evaluation encloses the true flow of
the ODE (see ``model.discretisation``). The thesis' dt = 0.03 min over its whole box cannot
be validated usefully: the flow runs away in the hot corner (from C_A = 0.95 mol/l,
T = 370 K, T_c = 370 K the temperature passes 500 K within one sample). The thesis example
``cstr`` keeps its Euler map (7.9), about which its certificates speak. Terminal set
(7.10) and local law are the thesis' (computed for the Euler map, not certified for this
model).
"""

from __future__ import annotations

from . import Example
from .cstr import VALIDATED_ORDER
from .cstr import build as _build_cstr


def build(order: int = VALIDATED_ORDER) -> Example:
    """Build the validated CSTR (Taylor order ``order``)."""
    return _build_cstr(validated=True, order=order)
