"""Control-set computations: pre-sets, controllable-set sequences, polytopic approximation,
invariance certificates, the search for certified terminal sets, and quasi multi-step
robust controllable sets."""

from .controllable import *  # noqa: F401,F403
from .controllable import __all__ as _controllable_all  # noqa: F401
from .invariance import *  # noqa: F401,F403
from .invariance import __all__ as _invariance_all  # noqa: F401
from .law import *  # noqa: F401,F403
from .law import __all__ as _law_all  # noqa: F401
from .linear_sets import *  # noqa: F401,F403
from .linear_sets import __all__ as _linear_all  # noqa: F401
from .polytopic import *  # noqa: F401,F403
from .polytopic import __all__ as _polytopic_all  # noqa: F401
from .quasi import *  # noqa: F401,F403
from .quasi import __all__ as _quasi_all  # noqa: F401
from .terminal import *  # noqa: F401,F403
from .terminal import __all__ as _terminal_all  # noqa: F401

__all__ = (list(_law_all) + list(_controllable_all) + list(_linear_all)
           + list(_invariance_all) + list(_polytopic_all) + list(_terminal_all)
           + list(_quasi_all))
