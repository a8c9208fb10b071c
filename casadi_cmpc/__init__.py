"""casadi_cmpc: computationally reliable contractive MPC from CasADi models.

Conventional aliases used throughout the documentation::

    import casadi as ca
    import numpy as np
    import casadi_cmpc as cm
"""

from . import codegen, interval  # noqa: F401
from .control import *  # noqa: F401,F403
from .control import __all__ as _control_all  # noqa: F401
from .exceptions import *  # noqa: F401,F403
from .exceptions import __all__ as _exc_all  # noqa: F401
from .model import *  # noqa: F401,F403
from .model import __all__ as _model_all  # noqa: F401
from .mpc import *  # noqa: F401,F403
from .mpc import __all__ as _mpc_all  # noqa: F401
from .sets import *  # noqa: F401,F403
from .sets import __all__ as _sets_all  # noqa: F401
from .solvers import *  # noqa: F401,F403
from .solvers import __all__ as _solvers_all  # noqa: F401

__version__ = "0.1.0"


def __getattr__(name: str):
    if name == "models":  # the model library is imported lazily (it builds CasADi graphs)
        import importlib

        return importlib.import_module("casadi_cmpc.models")
    raise AttributeError(f"module 'casadi_cmpc' has no attribute '{name}'")


__all__ = (["interval", "codegen"] + list(_exc_all) + list(_model_all) + list(_sets_all)
           + list(_solvers_all) + list(_control_all) + list(_mpc_all))
