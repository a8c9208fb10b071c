"""Interval operations on arrays whose last axis is ``[lo, hi]``.

Each function takes interval arrays of shape ``(..., 2)`` (e.g. ``(N, d, 2)`` batches) that
broadcast against each other, and returns one array of the broadcast shape. Rounding and
domain conventions are those of :mod:`casadi_cmpc.interval.arith`; an operand interval with a
NaN in either bound counts as ``[nan, nan]`` (possibly undefined), and every result is either
``[nan, nan]`` or NaN-free with ``lo <= hi``, ``lo < +inf``, ``hi > -inf``.

>>> import numpy as np, casadi_cmpc as cm
>>> r = cm.interval.mul(np.array([-1.0, 2.0]), np.array([3.0, 4.0]))
>>> bool(r[0] <= -4.0 and r[1] >= 8.0)
True
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from . import _fpu, arith

_UNARY_NAMES = [
    "neg", "sq", "twice", "inv", "sqrt", "exp", "expm1", "log", "log1p", "sin", "cos", "tan",
    "asin", "acos", "atan", "sinh", "cosh", "tanh", "asinh", "acosh", "atanh", "fabs", "floor",
    "ceil", "sign", "erf", "erfinv",
]
_BINARY_NAMES = [
    "add", "sub", "mul", "div", "pow", "atan2", "fmin", "fmax", "hypot", "copysign", "fmod",
    "remainder", "lt", "le", "eq", "ne", "if_else_zero", "hull", "intersect",
]
_RENAMED = {"not_": "logical_not", "and_": "logical_and", "or_": "logical_or"}

__all__ = _UNARY_NAMES + _BINARY_NAMES + list(_RENAMED.values()) + ["constpow", "powi"]


def _operand(a) -> np.ndarray:
    """An interval array with a NaN in either bound made NaN in both (the invariant of
    :mod:`~casadi_cmpc.interval.arith`: "possibly undefined" carries no bound at all)."""
    a = np.asarray(a, dtype=float)
    bad = np.isnan(a).any(axis=-1)
    if bad.any():
        a = a.copy()
        a[bad] = np.nan
    return a


def _unary(core: Callable) -> Callable:
    @_fpu.default_env  # the rules hold in the default floating-point environment
    def f(a):
        a = _operand(a)
        with np.errstate(all="ignore"):
            lo, hi = core(a[..., 0], a[..., 1])
        return np.stack(np.broadcast_arrays(lo, hi), axis=-1)

    f.__name__ = core.__name__.rstrip("_")
    f.__doc__ = (f"Interval extension of ``{f.__name__}`` on arrays of shape (..., 2).")
    return f


def _binary(core: Callable) -> Callable:
    @_fpu.default_env
    def f(a, b):
        a = _operand(a)
        b = _operand(b)
        with np.errstate(all="ignore"):
            lo, hi = core(a[..., 0], a[..., 1], b[..., 0], b[..., 1])
        return np.stack(np.broadcast_arrays(lo, hi), axis=-1)

    f.__name__ = core.__name__.rstrip("_")
    f.__doc__ = (f"Interval extension of ``{f.__name__}`` on arrays of shape (..., 2).")
    return f


for _n in _UNARY_NAMES + ["not_"]:
    globals()[_RENAMED.get(_n, _n)] = _unary(getattr(arith, _n))
for _n in _BINARY_NAMES + ["and_", "or_"]:
    globals()[_RENAMED.get(_n, _n)] = _binary(getattr(arith, _n))


@_fpu.default_env
def constpow(a, c: float) -> np.ndarray:
    """``a ** c`` for a real constant ``c``; a has shape (..., 2)."""
    a = _operand(a)
    with np.errstate(all="ignore"):
        lo, hi = arith.powc(a[..., 0], a[..., 1], c)
    return np.stack(np.broadcast_arrays(lo, hi), axis=-1)


@_fpu.default_env
def powi(a, n: int) -> np.ndarray:
    """``a ** n`` for an integer ``n``; a has shape (..., 2)."""
    a = _operand(a)
    with np.errstate(all="ignore"):
        lo, hi = arith.powi(a[..., 0], a[..., 1], n)
    return np.stack(np.broadcast_arrays(lo, hi), axis=-1)
