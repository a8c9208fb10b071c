"""Control-set computations: pre-sets and controllable-set sequences."""

from .invariance import *  # noqa: F401,F403
from .invariance import __all__ as _invariance_all  # noqa: F401
from .linear_sets import *  # noqa: F401,F403
from .linear_sets import __all__ as _linear_all  # noqa: F401

__all__ = list(_linear_all) + list(_invariance_all)
