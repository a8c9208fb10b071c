"""Sound, batched interval arithmetic and the CasADi -> inclusion-function compiler.

Interval batches are float arrays of shape ``(N, d, 2)``: ``[..., 0]`` lower bounds,
``[..., 1]`` upper bounds.
"""

from . import arith, modal  # noqa: F401
from .compiler import *  # noqa: F401,F403
from .compiler import __all__ as _compiler_all
from .contractor import *  # noqa: F401,F403
from .contractor import __all__ as _contractor_all
from .ops import *  # noqa: F401,F403
from .ops import __all__ as _ops_all

__all__ = list(_compiler_all) + list(_contractor_all) + list(_ops_all)
