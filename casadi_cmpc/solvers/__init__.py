"""Interval solvers built on one batched branch-and-bound engine."""

from .engine import Status  # noqa: F401
from .minimax import *  # noqa: F401,F403
from .minimax import __all__ as _minimax_all  # noqa: F401
from .minimize import *  # noqa: F401,F403
from .minimize import __all__ as _minimize_all  # noqa: F401
from .quantified import *  # noqa: F401,F403
from .quantified import __all__ as _quantified_all  # noqa: F401
from .result import *  # noqa: F401,F403
from .result import __all__ as _result_all  # noqa: F401
from .sivia import *  # noqa: F401,F403
from .sivia import __all__ as _sivia_all  # noqa: F401
from .zonotope_sivia import *  # noqa: F401,F403
from .zonotope_sivia import __all__ as _zsivia_all  # noqa: F401

__all__ = (["Status"] + list(_result_all) + list(_sivia_all) + list(_minimize_all)
           + list(_zsivia_all) + list(_quantified_all) + list(_minimax_all))
