"""The systems of the thesis examples, ready to use.

Each example lives in its own module with a ``build()`` function returning an
:class:`Example`; :func:`load` looks one up by name::

    import casadi_cmpc as cm
    ex = cm.models.load("cannon_robust")
    ex.model, ex.terminal, ex.local_law, ex.x0s, ex.info

Names and thesis examples (numbers as in the example catalogue)::

    linear_sliding      E1   linear system, sliding-domain terminal set (§3.3.4, §3.4.4)
    cannon_001          E5   Cannon et al. system, dt = 0.01 (§4.2.4-4.2.6)
    cstr                E6/E14  CSTR, Euler dt = 0.03 min (§4.2.7, §7.2)
    grimm               E7   Grimm et al. system (§4.3.4)
    cannon              E8   Cannon et al. system, dt = 0.1 (§4.4.4)
    cannon_robust       E9   E8 with mu in [0.85, 0.95] (§5.2.5)
    cannon_robust_wide  E10  E8 with mu in [0.75, 0.95], |x| <= 4 (§6.1.6)
    khalil_affine_state     E11  Khalil system with affine state part (§6.2.5)
    khalil_affine_control   E12  Khalil system with affine control part (§6.3.5)
    mirosot             E13  MiroSot robot ARX model with input delay (§7.1)

Further examples, not from the thesis (``info["example"] == "extra"``), each with a
terminal set certified by :func:`casadi_cmpc.terminal_set` (its numbers stored in the
module, so that the import stays fast) and the local law that proves it::

    cartpole            4 states: cart-pole balanced upright, RK4 dt = 0.05 s
    three_tank          3 states: three tanks in a cascade, sqrt outflows, levels held at
                        a non-zero equilibrium, RK4 dt = 5 s
    moore_greitzer      2 states: Moore-Greitzer jet engine (ROCS engine2dRS), tau = 0.1,
                        a validated sampled-data model (see below)

Validated sampled-data models of ODEs (``Model.from_ode(method="taylor")``: every interval
evaluation encloses the true flow; ``model.discretisation`` says so). ``moore_greitzer`` is
listed with the others; ``cstr_validated`` is loaded by name and listed by
``names(validated=True)`` only (its set configuration is the thesis CSTR's, with a terminal
set not certified for the validated model)::

    moore_greitzer      2 states: Moore-Greitzer jet engine (ROCS engine2dRS), tau = 0.1
    cstr_validated      the CSTR ODE of E6/E14 around its equilibrium, dt = 0.01 min

Terminal sets given here are the thesis data where the thesis prints them; where it
does not (E11, E12) they are choices recorded in ``info["choices"]`` and are *not*
certified by this module.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from ..control.law import LinearLaw
from ..model import Model
from ..sets.polytope import Polytope, PolytopeUnion

__all__ = ["Example", "load", "names"]

# name -> module (inside this package) holding its build() function
_REGISTRY: dict[str, str] = {
    "linear_sliding": "linear_sliding",
    "cannon_001": "cannon_001",
    "cstr": "cstr",
    "grimm": "grimm",
    "cannon": "cannon",
    "cannon_robust": "cannon_robust",
    "cannon_robust_wide": "cannon_robust_wide",
    "khalil_affine_state": "khalil_affine_state",
    "khalil_affine_control": "khalil_affine_control",
    "mirosot": "mirosot",
    "cartpole": "cartpole",
    "three_tank": "three_tank",
    "moore_greitzer": "moore_greitzer",
}
# validated sampled-data models of ODEs (Model.from_ode(method="taylor")) that are loaded by
# name but listed only by names(validated=True): the validated CSTR carries the thesis
# CSTR's set configuration, whose terminal set is not certified for it
_VALIDATED: dict[str, str] = {
    "cstr_validated": "cstr_validated",
}


@dataclass(frozen=True, eq=False)
class Example:
    """One example (of the thesis, or an extra one): a model with its terminal set, local
    law and initial states.

    Attributes
    ----------
    name : str
        Registry name (see :func:`names`).
    model : Model
        The discrete-time system with its boxes X, U (and W).
    terminal : Polytope, PolytopeUnion or None
        Terminal set of the dual-mode scheme; ``None`` when the example has none.
    local_law : LinearLaw, ndarray (m, n) (u = K x), casadi.SX (m, 1) in ``model.x``, or None
        Local stabilising law on the terminal set: a gain ``K`` (``u = K x``) or an
        expression of the model's state symbols.
    x0s : ndarray, shape (k, n)
        Initial states of the thesis closed-loop runs (``k = 0`` when there are none).
    info : dict
        Everything else: ``"example"`` (E-number), ``"section"``, ``"equation"``, the
        thesis parameters of the runs, and ``"choices"`` for values the thesis leaves open.
    """

    name: str
    model: Model
    terminal: Polytope | PolytopeUnion | None = None
    local_law: Any = None
    x0s: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    info: dict[str, Any] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        n, m = self.model.n, self.model.m
        x0s = np.array(self.x0s, dtype=float)
        if x0s.size == 0:
            x0s = np.zeros((0, n))
        x0s = np.atleast_2d(x0s)
        if x0s.ndim != 2 or x0s.shape[1] != n:
            raise ValueError(f"x0s of example '{self.name}' must have shape (k, {n}); "
                             f"got {np.shape(self.x0s)}")
        x0s.setflags(write=False)
        object.__setattr__(self, "x0s", x0s)
        if self.terminal is not None:
            if not isinstance(self.terminal, (Polytope, PolytopeUnion)):
                raise TypeError("terminal must be a Polytope, a PolytopeUnion or None")
            if self.terminal.dim != n:
                raise ValueError(f"terminal set of example '{self.name}' has dimension "
                                 f"{self.terminal.dim}, the model has n = {n}")
        law = self.local_law
        if isinstance(law, LinearLaw):
            if law.shape != (m, n):
                raise ValueError(f"local law of example '{self.name}' must have a gain of "
                                 f"shape ({m}, {n}); got {law.shape}")
        elif law is not None and not isinstance(law, ca.SX):
            K = np.array(law, dtype=float)
            if K.shape != (m, n):
                raise ValueError(f"local gain of example '{self.name}' must have shape "
                                 f"({m}, {n}); got {K.shape}")
            K.setflags(write=False)
            object.__setattr__(self, "local_law", K)
        elif isinstance(law, ca.SX) and law.numel() != m:
            raise ValueError(f"local law of example '{self.name}' must have {m} elements")


def names(validated: bool = False) -> list[str]:
    """Names of the examples: the thesis examples in their order, then the further
    examples (the last one, ``moore_greitzer``, a validated sampled-data ODE model); with
    ``validated=True`` also ``cstr_validated``, which :func:`load` accepts as well."""
    return list(_REGISTRY) + (list(_VALIDATED) if validated else [])


def load(name: str) -> Example:
    """Build the example called ``name`` (a fresh model on every call).

    Raises
    ------
    ValueError
        ``name`` is not one of :func:`names`.
    """
    key = str(name)
    table = {**_REGISTRY, **_VALIDATED}
    if key not in table:
        raise ValueError(f"unknown example '{name}'; valid names: {', '.join(table)}")
    module = importlib.import_module(f"{__name__}.{table[key]}")
    return module.build()
