"""The floating-point environment of the interval computations.

The outward rounding of the numpy and scalar rules (:mod:`.arith`, :mod:`._scalar`) and of
the set tests built on them is proven for the default environment: round to nearest,
subnormal numbers kept. Another library loaded in the same process may leave another one
behind: codac rounds upward, a library built with ``-ffast-math`` sets flush-to-zero and
denormals-are-zero. There an overflow rounds to the largest float instead of infinity (a
bound that should be infinite stays finite) and a subnormal bound becomes 0, so an
enclosure could miss the exact value. The native kernels set the default environment
themselves; the Python evaluators check it (:func:`is_default`, a few float operations) and,
when it is not the default, run in the default environment and give the caller's back
afterwards (:func:`call_in_default`). Where the environment cannot be switched, they raise
rather than compute unsoundly.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import sys
from collections.abc import Callable
from typing import Any, TypeVar

from ..exceptions import CmpcError

__all__ = ["is_default", "call_in_default", "default_env", "FPUStateError"]

R = TypeVar("R")

# The check of the environment, as source: generated evaluators inline it with these
# operands as local defaults (read at run time: a literal expression would be folded by
# the compiler, in the compiler's environment). 1 +- 1e-20 rounds to 1 in no directed
# mode; half the smallest normal is a subnormal result (flush-to-zero makes it 0); the
# smallest subnormal read as an operand (denormals-are-zero makes it 0).
CHECK_OPERANDS = {"_O": 1.0, "_E": 1e-20, "_T": 2.2250738585072014e-308, "_H": 0.5,
                  "_S": 5e-324, "_Z": 0.0}
NOT_DEFAULT = "_O + _E != _O or _O - _E != _O or _T * _H == _Z or _S + _Z == _Z"
CHECK_PARAMS = ", ".join(f"{k}={v!r}" for k, v in CHECK_OPERANDS.items())


class FPUStateError(CmpcError):
    """The floating-point environment is not the default and cannot be switched here."""


def _make_is_default() -> Callable[[], bool]:
    ns: dict[str, Any] = {}
    exec(f"def is_default({CHECK_PARAMS}):\n    return not ({NOT_DEFAULT})\n", ns)  # noqa: S102
    fn = ns["is_default"]
    fn.__doc__ = ("True when this thread computes in the default floating-point environment:"
                  " round to nearest, subnormal results kept (no flush-to-zero) and subnormal"
                  " operands read (no denormals-are-zero).")
    return fn


is_default = _make_is_default()


_ENV_BYTES = 512  # larger than the fenv_t of any C library
_libm: list[Any] = []  # [(fegetenv, fesetenv, default env pointer)] once loaded


def _load() -> tuple[Any, Any, Any]:
    if _libm:
        return _libm[0]
    name = ctypes.util.find_library("m") or ("libm.so.6" if sys.platform.startswith("linux")
                                             else None)
    lib = ctypes.CDLL(name) if name else ctypes.CDLL(None)
    get, put = lib.fegetenv, lib.fesetenv
    get.argtypes = put.argtypes = [ctypes.c_void_p]
    get.restype = put.restype = ctypes.c_int
    if sys.platform == "darwin":  # FE_DFL_ENV is &_FE_DFL_ENV
        dfl: Any = ctypes.c_void_p(ctypes.addressof(ctypes.c_char.in_dll(lib, "_FE_DFL_ENV")))
    else:  # glibc and musl: FE_DFL_ENV is ((const fenv_t *) -1)
        dfl = ctypes.c_void_p(-1 & (2 ** (8 * ctypes.sizeof(ctypes.c_void_p)) - 1))
    _libm.append((get, put, dfl))
    return _libm[0]


def call_in_default(fn: Callable[..., R], *args: Any, **kwargs: Any) -> R:
    """``fn(*args)`` in the default floating-point environment, the caller's environment
    restored afterwards (also when ``fn`` raises).

    Raises
    ------
    FPUStateError
        The environment could not be switched to the default (no C math library with
        ``fesetenv`` reachable, or a platform whose default environment is not known here).
    """
    try:
        get, put, dfl = _load()
        saved = ctypes.create_string_buffer(_ENV_BYTES)
        ok = get(saved) == 0 and put(dfl) == 0
    except (OSError, AttributeError, ValueError) as exc:
        raise FPUStateError(_WHY + f" ({exc})") from exc
    try:
        if not ok or not is_default():
            raise FPUStateError(_WHY)
        return fn(*args, **kwargs)
    finally:
        put(saved)


def default_env(fn: Callable[..., R]) -> Callable[..., R]:
    """``fn`` run in the default floating-point environment (see :func:`call_in_default`);
    a check of a few float operations when it already is the default."""
    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> R:
        if is_default():
            return fn(*args, **kwargs)
        return call_in_default(fn, *args, **kwargs)

    return wrapper


_WHY = ("the floating-point environment of this thread is not the default (a directed "
        "rounding mode, or flush-to-zero / denormals-are-zero, left by another library) and "
        "could not be switched to the default: interval bounds computed here would not be "
        "sound. Restore it (e.g. fesetround(FE_TONEAREST)) before calling casadi_cmpc")
