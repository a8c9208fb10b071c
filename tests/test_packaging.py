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


# distributions on PyPI as source archives only (their install compiles C): none may be in
# the default dependencies or the test extra, which must install with python3 and pip alone
_NEEDS_A_COMPILER = ("pycddlib",)


def test_the_test_extra_needs_no_compiler():
    import pytest

    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    reqs = list(meta["dependencies"]) + list(meta["optional-dependencies"]["test"])
    bad = [r for r in reqs if r.lower().startswith(_NEEDS_A_COMPILER)]
    assert not bad, f"needs a C compiler to install: {bad}"
    assert any(r.startswith("pycddlib") for r in meta["optional-dependencies"]["cdd"])
