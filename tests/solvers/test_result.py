"""The shared solver result (``casadi_cmpc/solvers/result.py``)."""

from __future__ import annotations

import dataclasses
import re

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.exceptions import DimensionError
from casadi_cmpc.solvers.engine import Status
from casadi_cmpc.solvers.minimax import MinimaxResult, minimax
from casadi_cmpc.solvers.minimize import MinimizeResult, minimize
from casadi_cmpc.solvers.result import Result

BASE = {"message": "m", "method": "demo", "nit": 2, "n_boxes": 7, "elapsed": 0.5}
BASE_FIELDS = ("success", "status", "message", "method", "nit", "n_boxes", "elapsed")


def _bracket(**kw):
    args = {"status": Status.PROVED, "lower": 0.0, "upper": 1.0, "x": np.array([0.5]),
            "x_feasible": True, "candidates": np.zeros((0, 1, 2)), "n_local": 0, **BASE}
    args.update(kw)
    return MinimizeResult(**args)


@pytest.fixture(scope="module")
def minimize_result():
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [(x[0] - 0.5) ** 2 + (x[1] + 0.25) ** 2 + 1])
    return minimize(f, cm.Box([-1, -1], [1, 1]), 1e-2, local_solver=None, progress=False)


@pytest.fixture(scope="module")
def minimax_result():
    u, w = ca.SX.sym("u"), ca.SX.sym("w")
    f = ca.Function("sq", [u, w], [(u - w) ** 2])
    return minimax(f, cm.Box([-1], [1]), cm.Box([-0.5], [0.5]), 1e-2, progress=False)


# ------------------------------------------------------------------------- the base
def test_exported_and_base_fields():
    assert cm.Result is Result and "Result" in cm.__all__
    names = [f.name for f in dataclasses.fields(Result)]
    assert sorted(names) == sorted(BASE_FIELDS)
    for cls in (MinimizeResult, MinimaxResult):
        assert issubclass(cls, Result)
        sub = [f.name for f in dataclasses.fields(cls)]
        assert set(BASE_FIELDS) <= set(sub)


@pytest.mark.parametrize("status", list(Status))
def test_success_is_derived_from_status(status):
    r = Result(status=status, **BASE)
    assert r.success is (status == Status.PROVED)
    assert r.status is status and isinstance(r.status, Status)
    # the consistent value is accepted as well
    assert Result(status=status, success=status == Status.PROVED, **BASE).success == r.success


def test_int_status_is_converted():
    r = Result(status=1, **BASE)
    assert r.status is Status.BUDGET and not r.success
    assert Result(status=np.int64(0), **BASE).success is True


@pytest.mark.parametrize("status", list(Status))
def test_inconsistent_success_is_refused(status):
    wrong = status != Status.PROVED
    with pytest.raises(ValueError, match=f"disagrees with status={status.name}"):
        Result(status=status, success=wrong, **BASE)


@pytest.mark.parametrize("field, value, error, match", [
    ("status", 5, ValueError, "status must be one of"),
    ("status", "PROVED", ValueError, "status must be one of"),
    ("nit", -1, ValueError, "nit must be >= 0"),
    ("n_boxes", -3, ValueError, "n_boxes must be >= 0"),
    ("nit", 1.5, TypeError, "nit must be an integer"),
    ("elapsed", -0.1, ValueError, "elapsed"),
    ("elapsed", float("nan"), ValueError, "elapsed"),
    ("message", None, TypeError, "message must be a str"),
    ("method", 3, TypeError, "method must be a str"),
])
def test_invalid_fields_are_refused(field, value, error, match):
    args = {"status": Status.PROVED, **BASE, field: value}
    with pytest.raises(error, match=match):
        Result(**args)


def test_fields_are_keyword_only():
    with pytest.raises(TypeError):
        Result(True, Status.PROVED, "m", "demo", 0, 0, 0.0)


def test_frozen():
    r = Result(status=Status.PROVED, **BASE)
    for name, value in (("success", False), ("status", Status.BUDGET), ("nit", 0)):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(r, name, value)
    assert r.success and r.status is Status.PROVED and r.nit == 2


def test_base_repr():
    r = Result(status=Status.UNDECIDED, **BASE)
    assert repr(r) == "Result(status=UNDECIDED, nit=2, n_boxes=7, elapsed=0.5)"


# ----------------------------------------------------------------- the bracket part
def test_bracket_is_checked_and_normalised():
    r = _bracket(lower=np.float64(-1), upper=2)
    assert type(r.lower) is float and type(r.upper) is float
    assert r.fun == r.upper == 2.0 and r.width == 3.0
    r = _bracket(lower=np.inf, upper=np.inf, status=Status.DISPROVED, x=None)
    assert r.lower == r.upper == np.inf and not r.success
    with pytest.raises(ValueError, match="inverted"):
        _bracket(lower=1.0, upper=0.0)
    with pytest.raises(DimensionError, match=r"candidates must be boxes"):
        _bracket(candidates=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="disagrees"):
        _bracket(success=False)
    with pytest.raises(dataclasses.FrozenInstanceError):
        _bracket().fun = 0.0


def test_subclass_repr_keeps_its_numbers():
    r = _bracket(lower=0.125, upper=0.25, x=np.array([0.5, -0.25]),
                 candidates=np.zeros((4, 2, 2)))
    assert repr(r) == ("MinimizeResult(status=PROVED, lower=0.125, upper=0.25, "
                       "x=[ 0.5  -0.25], x_feasible=True, candidates=4, nit=2, n_boxes=7, "
                       "elapsed=0.5)")


# --------------------------------------------------------------- from the solvers
def _check_base(res, method):
    assert isinstance(res, Result)
    assert res.success is (res.status == Status.PROVED)
    assert isinstance(res.status, Status) and res.method == method
    assert isinstance(res.message, str) and res.message
    assert isinstance(res.nit, int) and res.nit >= 1
    assert isinstance(res.n_boxes, int) and res.n_boxes >= res.nit
    assert isinstance(res.elapsed, float) and 0.0 <= res.elapsed < 60.0


def _repr_numbers(res):
    text = repr(res)
    assert text.startswith(type(res).__name__ + "(status=")
    for key, value in (("lower", f"{res.lower:.10g}"), ("upper", f"{res.upper:.10g}"),
                       ("candidates", str(res.candidates.shape[0])), ("nit", str(res.nit)),
                       ("n_boxes", str(res.n_boxes))):
        assert re.search(rf"\b{key}={re.escape(value)}[,)]", text), (key, text)
    return text


def test_minimize_fills_the_base_fields(minimize_result):
    res = minimize_result
    assert isinstance(res, MinimizeResult)
    _check_base(res, "centered")
    assert res.success and res.lower <= 1.0 <= res.upper and res.fun == res.upper
    assert res.n_local == 0 and res.x_feasible
    text = _repr_numbers(res)
    assert "status=PROVED" in text and "x_feasible=True" in text
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.success = False


def test_minimize_failure_is_not_success():
    x = ca.SX.sym("x", 2)
    f = ca.Function("lin", [x], [x[0] + x[1]])
    never = ca.Function("never", [x], [x[0] ** 2 + x[1] ** 2 + 1])
    res = minimize(f, cm.Box([-1, -1], [1, 1]), 0.1, constraints=never, local_solver=None,
                   progress=False)
    _check_base(res, "centered")
    assert res.status == Status.DISPROVED and res.success is False
    assert "status=DISPROVED" in _repr_numbers(res) and "x=None" in repr(res)


def test_minimax_fills_the_base_fields(minimax_result):
    res = minimax_result
    assert isinstance(res, MinimaxResult)
    _check_base(res, "alg5.3")
    assert res.success and res.lower <= 0.25 <= res.upper and res.fun == res.upper
    text = _repr_numbers(res)
    assert "status=PROVED" in text and "u=[" in text
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.status = Status.BUDGET


def test_minimax_budget_is_not_success():
    u, w = ca.SX.sym("u"), ca.SX.sym("w")
    f = ca.Function("sq", [u, w], [(u - w) ** 2])
    res = minimax(f, cm.Box([-1], [1]), cm.Box([-0.5], [0.5]), 1e-9, max_boxes=5,
                  progress=False)
    _check_base(res, "alg5.3")
    assert res.status == Status.BUDGET and res.success is False
    assert "status=BUDGET" in _repr_numbers(res)
