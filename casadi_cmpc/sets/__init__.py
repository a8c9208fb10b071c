"""Sets: boxes (and, later, pavings, polytopes, zonotopes, unions)."""

from .box import *  # noqa: F401,F403
from .box import __all__ as _box_all

__all__ = list(_box_all)
