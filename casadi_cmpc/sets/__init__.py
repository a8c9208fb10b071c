"""Sets: boxes and polytopes (and, later, pavings, zonotopes)."""

from .box import *  # noqa: F401,F403
from .box import __all__ as _box_all
from .polytope import *  # noqa: F401,F403
from .polytope import __all__ as _polytope_all

__all__ = list(_box_all) + list(_polytope_all)
