"""Clear errors and quiet solvers where a new user meets them."""

from __future__ import annotations

import casadi as ca
import pytest

import casadi_cmpc as cm
from casadi_cmpc.exceptions import FreeSymbolError


def test_inclusion_names_the_free_symbol():
    x = ca.SX.sym("x")
    gain = ca.SX.sym("gain")
    f = ca.Function("f", [x], [gain * x + 1], {"allow_free": True})
    for kind in ("natural", "centered"):
        with pytest.raises(FreeSymbolError, match="gain"):
            cm.interval.inclusion(f, kind)
    with pytest.raises(FreeSymbolError, match="gain"):
        cm.sivia(f, cm.Box([0], [1]), cm.Box([0], [1]), eps=0.1)


def test_minimize_on_a_partly_undefined_domain_prints_no_solver_warnings(capfd):
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [ca.log(x[0]) + ca.sqrt(x[1]) + x[0]])
    res = cm.minimize(f, cm.Box([-2, -2], [1, 1]), eps=1e-2)
    out, err = capfd.readouterr()
    assert "NaN detected" not in out + err
    assert res.lower <= res.upper  # still a bracket (the minimum is -inf near x0 = 0)


@pytest.mark.parametrize("A, b, bad", [
    ([["1", "0"], ["0", "1"]], [1, 1], "Polytope A"),
    ([[1, 0], [0, "a"]], [1, 1], "'a'"),
    ([[1, 0], [0, 1]], [1, "2"], "Polytope b"),
])
def test_polytope_refuses_strings_naming_the_argument(A, b, bad):
    from casadi_cmpc.exceptions import InvalidBoundsError

    with pytest.raises(InvalidBoundsError, match=bad):
        cm.Polytope(A, b)
    assert cm.Polytope([[1, 0], [0, 1]], [1, 2]).contains([0.5, 1.5])  # numbers still work
