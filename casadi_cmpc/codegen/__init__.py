"""Export of controllers to standalone C (CasADi code generation plus the set tables).

:func:`export_c` writes the C sources, a header with the ``cmpc_step`` API, a Makefile and
an example program; :func:`build` compiles them and :func:`load` loads the shared library
through ctypes as a :class:`CompiledController`, for checking against the Python controller.

The exporter reads a controller through its ``export_spec()`` (see
:mod:`casadi_cmpc.mpc.spec`) only. Its module, :mod:`casadi_cmpc.codegen.export`, is
imported at the first use of one of these names, so that importing the package (or the
controllers) does not load it.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["export_c", "build", "load", "CompiledController", "ExportInfo"]


def __getattr__(name: str) -> Any:
    if name in __all__ or name == "export":
        module = importlib.import_module(f"{__name__}.export")
        return module if name == "export" else getattr(module, name)
    raise AttributeError(f"module '{__name__}' has no attribute '{name}'")


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
