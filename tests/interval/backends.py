"""The two evaluators of the interval compiler, for tests parametrised over them.

* :data:`ARITH` maps a backend name to a namespace of interval operations with the calling
  conventions of :mod:`casadi_cmpc.interval.arith` (arrays of lower and upper bounds):
  ``"numpy"`` is ``arith`` itself, ``"scalar"`` is :class:`ScalarArith`, which applies the
  Python float code of :mod:`casadi_cmpc.interval._scalar` (the very source lines that the
  scalar compiler inlines) element by element.
* :func:`compiled` builds an :class:`~casadi_cmpc.interval.InclusionFunction` that evaluates
  every batch with the given backend; the scalar one raises instead of falling back to
  numpy, so that a test of it really tests the scalar code. :data:`COMPILED_BACKENDS` adds
  ``"native"`` (the fused C loop) where a C compiler is installed; a native inclusion of a
  Function whose operations all have a C rule is checked to really run the C kernel.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from casadi_cmpc.interval import arith
from casadi_cmpc.interval._cgen import unsupported_ops
from casadi_cmpc.interval._native import native_available
from casadi_cmpc.interval._scalar import scalar_op
from casadi_cmpc.interval.compiler import InclusionFunction

BACKENDS = ["numpy", "scalar"]  # operation-level backends (ARITH)
COMPILED_BACKENDS = BACKENDS + (["native"] if native_available() else [])

_WITH_CONSTANT_LAST = ("addc", "mulc", "divc", "powc", "powi")
_WITH_CONSTANT_FIRST = ("csub", "cdiv")


def _map(op: Any, *arrays: Any) -> tuple[np.ndarray, np.ndarray]:
    """Apply a scalar operation ``op(al, ah[, bl, bh]) -> (lo, hi)`` element by element to
    broadcast arrays; returns two arrays of the broadcast shape."""
    arrs = np.broadcast_arrays(*[np.asarray(a, dtype=float) for a in arrays])
    shape = arrs[0].shape
    lo = np.empty(shape)
    hi = np.empty(shape)
    flat = [a.reshape(-1) for a in arrs]
    for i in range(lo.size):
        lo.flat[i], hi.flat[i] = op(*[float(a[i]) for a in flat])
    return lo, hi


class ScalarArith:
    """The operations of ``arith`` computed by the scalar backend, element by element."""

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        if name in _WITH_CONSTANT_LAST:
            def f(al: Any, ah: Any, c: float) -> tuple[np.ndarray, np.ndarray]:
                return _map(scalar_op(name, c), al, ah)
        elif name in _WITH_CONSTANT_FIRST:
            def f(c: float, bl: Any, bh: Any) -> tuple[np.ndarray, np.ndarray]:
                return _map(scalar_op(name, c), bl, bh)
        elif name == "mulci":
            def f(al: Any, ah: Any, cl: float, ch: float) -> tuple[np.ndarray, np.ndarray]:
                return _map(scalar_op("mulci", float(cl), float(ch)), al, ah)
        else:
            try:
                op = scalar_op(name)
            except KeyError:
                raise AttributeError(f"the scalar backend has no operation {name!r}") from None

            def f(*args: Any) -> tuple[np.ndarray, np.ndarray]:
                return _map(op, *args)
        return f

    def __repr__(self) -> str:
        return "<scalar interval operations>"


ARITH: dict[str, Any] = {"numpy": arith, "scalar": ScalarArith()}


def compiled(fun: Any, kind: str = "natural", backend: str = "numpy") -> InclusionFunction:
    """An uncached inclusion of ``fun`` forced to ``backend`` (scalar: never falls back)."""
    F = InclusionFunction(fun, kind, backend=backend)
    if backend == "scalar":
        assert not F.scalar_unsupported, F.scalar_unsupported
        F._scalar_strict = True
    if backend == "native" and F._is_natural:
        try:
            ok = not unsupported_ops(F.fun)
        except ValueError:  # a ParamFunction or a restricted form: the kernel decides
            ok = True
        assert (F._native_kernel() is not None) or not ok, "the native kernel was not built"
    return F
