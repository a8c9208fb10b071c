"""The ``>>>`` examples in the public docstrings are run and must hold."""

import doctest
import importlib

import pytest

MODULES = [
    "casadi_cmpc.sets.box",
    "casadi_cmpc.model",
    "casadi_cmpc.interval.compiler",
    "casadi_cmpc.interval.contractor",
    "casadi_cmpc.interval.ops",
    "casadi_cmpc.sets.polytope",
    "casadi_cmpc.sets._poly_ops",
    "casadi_cmpc.sets._poly_union",
    "casadi_cmpc.sets.paving",
    "casadi_cmpc.sets._boxes",
    "casadi_cmpc.sets.zonotope",
    "casadi_cmpc.sets._reach",
    "casadi_cmpc.control.quasi",
    "casadi_cmpc.solvers.sivia",
    "casadi_cmpc.solvers.minimize",
    "casadi_cmpc.solvers.quantified",
    "casadi_cmpc.solvers.minimax",
    "casadi_cmpc.solvers.result",
    "casadi_cmpc.interval.modal",
    "casadi_cmpc.interval._kaucher",
    "casadi_cmpc.solvers._zbatch",
    "casadi_cmpc.mpc.contractive",
    "casadi_cmpc.mpc.linear",
    "casadi_cmpc.mpc.simulate",
]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    mod = importlib.import_module(name)
    result = doctest.testmod(mod, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0, f"{name} has no examples"
    assert result.failed == 0
