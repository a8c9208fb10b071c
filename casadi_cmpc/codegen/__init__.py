"""Export of controllers to standalone C (CasADi code generation plus the set tables).

:func:`export_c` writes the C sources, a header with the ``cmpc_step`` API, a Makefile and
an example program; :func:`build` compiles them and :func:`load` loads the shared library
through ctypes as a :class:`CompiledController`, for checking against the Python controller.
"""

from .export import CompiledController, ExportInfo, build, export_c, load

__all__ = ["export_c", "build", "load", "CompiledController", "ExportInfo"]
