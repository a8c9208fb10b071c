"""Sets: boxes and pavings, polytopes and their unions, zonotopes.

All set types follow the protocol of :mod:`casadi_cmpc.sets.base`.
"""

from .base import *  # noqa: F401,F403
from .base import __all__ as _base_all
from .box import *  # noqa: F401,F403
from .box import __all__ as _box_all
from .paving import *  # noqa: F401,F403
from .paving import __all__ as _paving_all
from .polytope import *  # noqa: F401,F403
from .polytope import __all__ as _polytope_all
from .union import *  # noqa: F401,F403
from .union import __all__ as _union_all
from .zonotope import *  # noqa: F401,F403
from .zonotope import __all__ as _zonotope_all

__all__ = (list(_base_all) + list(_box_all) + list(_paving_all) + list(_polytope_all)
           + list(_zonotope_all) + list(_union_all))
