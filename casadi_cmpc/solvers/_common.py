"""Private argument checks and array helpers shared by the branch-and-bound solvers."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from .._validate import as_boxes
from ..exceptions import DimensionError, UnboundedSetError
from ..interval.compiler import InclusionFunction, inclusion

__all__: list[str] = []


def split_inclusion(fun: Any, name: str) -> tuple[Any, InclusionFunction | None]:
    """``(function, compiled)`` of a solver argument that may be a compiled inclusion.

    For an :class:`~casadi_cmpc.interval.InclusionFunction`: its (SX) casadi.Function and
    the object itself, which the solver then evaluates instead of compiling the Function
    again; for anything else: ``(fun, None)`` (checked by the caller). An inclusion built
    with ``derived_outputs`` or ``evaluate`` (a restricted, internal form) is refused with
    a ValueError.
    """
    if isinstance(fun, InclusionFunction):
        if fun._keep is not None or fun._widen:
            raise ValueError(
                f"{name} is an InclusionFunction restricted with derived_outputs/evaluate; "
                "pass the casadi.Function or cm.interval.inclusion(fun) instead")
        return fun.fun, fun
    return fun, None


def inclusion_of(fun: ca.Function, kind: str, given: InclusionFunction | None
                 ) -> InclusionFunction:
    """The inclusion of ``fun`` of ``kind``: ``given`` when it is of that kind, else the
    (cached) :func:`~casadi_cmpc.interval.inclusion`, with the backend of ``given``."""
    if given is not None and given.kind == kind:
        return given
    backend = given.backend if given is not None else "auto"
    return inclusion(fun, kind, backend=backend)


def one_output_function(fun: Any, name: str, inputs: tuple[str, ...]) -> ca.Function:
    """Return ``fun`` after checking it is a casadi.Function of ``inputs`` with one output.

    Raises TypeError when ``fun`` is not a casadi.Function and :class:`DimensionError` when
    it has another number of inputs than ``len(inputs)`` or more than one output.
    """
    if not isinstance(fun, ca.Function):
        raise TypeError(f"{name} must be a casadi.Function (or an InclusionFunction); got "
                        f"{type(fun).__name__}")
    if fun.n_in() != len(inputs) or fun.n_out() != 1:
        takes = "one input" if len(inputs) == 1 else f"({', '.join(inputs)})"
        raise DimensionError(
            f"{name} must take {takes} and return one output; '{fun.name()}' has "
            f"{fun.n_in()} inputs and {fun.n_out()} outputs (use casadi.vertcat to stack "
            "them)")
    return fun


def single_box(data: Any, name: str, d: int | None = None) -> np.ndarray:
    """Return one bounded box of shape ``(d, 2)`` from ``data`` (a Box or array).

    Raises :class:`DimensionError` when ``data`` holds several boxes or a box of another
    dimension than ``d``, and :class:`UnboundedSetError` on an infinite bound.
    """
    b = as_boxes(data, d, name)
    if b.shape[0] != 1:
        raise DimensionError(f"{name} must be a single box; got {b.shape[0]} boxes")
    if not np.isfinite(b).all():
        raise UnboundedSetError(
            f"{name} must be bounded; got bounds {b[0].tolist()} (intersect it with a "
            "finite box)")
    return b[0]


def positive_eps(eps: Any, name: str = "eps") -> float:
    """Return ``eps`` as a float, raising ValueError unless it is a finite positive number
    (a string such as ``"0.1"`` or a bool is refused, not converted)."""
    if isinstance(eps, (str, bytes, bool, np.bool_)):
        raise ValueError(
            f"{name} must be a positive number; got the {type(eps).__name__} {eps!r} "
            f"(write {name}=0.1, not {name}='0.1')")
    try:
        value = float(eps)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number; got {eps!r}") from None
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a positive number; got {eps!r}")
    return value


def thin(points: np.ndarray) -> np.ndarray:
    """Degenerate boxes ``[p, p]``, shape ``(..., d, 2)``, of points of shape ``(..., d)``."""
    return np.stack([points, points], axis=-1)
