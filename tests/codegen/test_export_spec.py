"""The exporter reads a controller through ``export_spec()`` only, and the controllers do
not load the exporter."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.codegen import export_c
from casadi_cmpc.mpc.sequence import SetSequenceMPC

EXPORT = Path(cm.__file__).parent / "codegen" / "export.py"


@pytest.mark.parametrize("module", ["casadi_cmpc.mpc", "casadi_cmpc.mpc.contractive",
                                    "casadi_cmpc.mpc.sequence", "casadi_cmpc"])
def test_importing_the_controllers_does_not_load_the_exporter(module):
    code = (f"import sys, {module}\n"
            "print('casadi_cmpc.codegen.export' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "False"


def test_the_exporter_loads_on_first_use():
    code = ("import sys, casadi_cmpc as cm\n"
            "f = cm.codegen.export_c\n"
            "from casadi_cmpc.codegen import ExportInfo\n"
            "print('casadi_cmpc.codegen.export' in sys.modules, f.__name__, "
            "ExportInfo.__name__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert out.stdout.strip().splitlines()[-1] == "True export_c ExportInfo", out.stderr
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        cm.codegen.nothing  # noqa: B018


def test_the_exporter_imports_no_controller_module_and_reads_no_private_name():
    tree = ast.parse(EXPORT.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            assert "mpc" not in (node.module or ""), ast.dump(node)
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            if node.value.id in ("ctrl", "spec", "h"):
                assert not node.attr.startswith("_"), f"{node.value.id}.{node.attr}"


class _SpecOnly:
    """A controller reduced to its export data."""

    def __init__(self, ctrl) -> None:
        self._spec = ctrl.export_spec()

    def export_spec(self):
        return self._spec


def _files(d: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in sorted(d.iterdir())}


def test_export_from_the_spec_alone_writes_the_same_files(tmp_path):
    ex8 = cm.models.load("cannon")
    kw = dict(ex8.info["mpc"], solver="sqp", mode="receding")
    c8 = cm.ContractiveMPC(ex8.model, **kw)
    export_c(c8, tmp_path / "a", x0=[1.9, -1.5])
    export_c(_SpecOnly(c8), tmp_path / "b", x0=[1.9, -1.5])
    assert _files(tmp_path / "a") == _files(tmp_path / "b")

    ex = cm.models.load("cannon_robust")
    cfg = ex.info["sequence"]
    seq = cm.controllable_sets(ex.model, ex.terminal, cfg["eps"], robust=True,
                               law=ex.local_law, progress=False, max_steps=3)
    c9 = SetSequenceMPC(ex.model, seq, Q=cfg["Q"], R=cfg["R"], local_law=ex.local_law,
                        solver="sqp", robust=True)
    info = export_c(c9, tmp_path / "c")
    export_c(_SpecOnly(c9), tmp_path / "d")
    assert _files(tmp_path / "c") == _files(tmp_path / "d")
    assert info.kind == "set_sequence" and info.tables["levels"] == len(seq.sets)


def test_a_non_controller_is_refused(tmp_path):
    with pytest.raises(TypeError, match="SetSequenceMPC or a ContractiveMPC; got ndarray"):
        export_c(np.zeros(2), tmp_path / "x")
