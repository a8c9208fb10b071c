"""Every subpackage of casadi_cmpc is listed in pyproject.toml: a non-editable install
(the README's first command) would silently miss an unlisted one."""

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_all_subpackages_are_packaged():
    text = (ROOT / "pyproject.toml").read_text()
    block = re.search(r"^packages = \[(.*?)\]", text, re.S | re.M).group(1)
    listed = set(re.findall(r'"([\w.]+)"', block))
    pkg = ROOT / "casadi_cmpc"
    found = {".".join(("casadi_cmpc",) + p.parent.relative_to(pkg).parts)
             for p in pkg.rglob("__init__.py")}
    assert found <= listed, f"not packaged: {sorted(found - listed)}"
    assert "casadi_cmpc.models" in listed
