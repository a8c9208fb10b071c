"""Control-set computations: pre-sets and controllable-set sequences."""

from .linear_sets import *  # noqa: F401,F403
from .linear_sets import __all__ as _linear_all  # noqa: F401

__all__ = list(_linear_all)
