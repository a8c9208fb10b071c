"""Exceptions and warnings of casadi_cmpc.

Every exception derives from :class:`CmpcError` and also from the builtin it
refines, so callers may catch either.
"""

from __future__ import annotations

__all__ = [
    "CmpcError",
    "DimensionError",
    "EmptySetError",
    "UnboundedSetError",
    "InvalidBoundsError",
    "FreeSymbolError",
    "ModelError",
    "UnsupportedOperationError",
    "SolverError",
    "NotControllableError",
    "CmpcWarning",
]


class CmpcError(Exception):
    """Base class of all casadi_cmpc errors."""


class DimensionError(CmpcError, ValueError):
    """An array or expression has the wrong shape."""


class EmptySetError(CmpcError, ValueError):
    """A set that must be non-empty is empty (e.g. a box with lo > hi)."""


class UnboundedSetError(CmpcError, ValueError):
    """A set that must be bounded is not (e.g. a model box with an infinite bound)."""


class InvalidBoundsError(CmpcError, ValueError):
    """Bounds contain NaN or are otherwise unusable."""


class FreeSymbolError(CmpcError, ValueError):
    """An expression depends on symbols that are not declared inputs."""


class ModelError(CmpcError, ValueError):
    """A model definition is inconsistent (e.g. ``w`` given without ``W``)."""


class UnsupportedOperationError(CmpcError, NotImplementedError):
    """A CasADi operation has no interval extension."""


class SolverError(CmpcError, RuntimeError):
    """A numerical solver failed."""


class NotControllableError(CmpcError, ValueError):
    """A set-sequence controller was asked for a control at a state that lies in no set of
    its sequence: not controllable as far as the sequence proves. :func:`~casadi_cmpc
    .simulate` ends the run there (``stop_reason == "not_controllable"``)."""


class CmpcWarning(UserWarning):
    """Warning issued by casadi_cmpc (ignored arguments, unknown options, ...)."""
