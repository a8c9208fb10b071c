"""The README's Python examples run, each on its own, and its quickstart matches .ci/run."""

import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
BLOCKS = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)

# facts checked after a block, in the same process (keyed by a line of the block): what the
# README says its examples show
CHECKS = {
    'res = cm.minimize(': "assert res.lower <= res.upper\nassert paving.n_inner > 0",
    'K1 = cm.one_step_set(ex9': (
        "x = [0.6, -0.2]\n"
        "u = K1.control(x)\n"
        "assert u is not None and not ex9.terminal.contains(x)\n"
        "for w in ex9.model.W.vertices():  # the model is affine in mu\n"
        "    assert ex9.terminal.contains(ex9.model.step(x, u, w))\n"
        "assert r.certificate.label == 'verified' and r.horizon >= 1\n"
        "assert seq9.status == 'converged' and cert1.proved is True\n"
        "import os\n"
        "assert os.path.isfile('e9_sets.npz')\n"),
    'r = ctrl.solve([2.0, 2.0])': "assert r.horizon == 2 and r.certificate.label == 'verified'",
    'cert = cm.certify_invariant(': "assert cert.proved is True",
    'K1 = cm.one_step_set(ex11.model': (
        "assert u is not None and K1.contains(x) and not ex11.terminal.contains(x)\n"
        "for w in ex11.model.W.vertices():  # affine in w: the vertices suffice\n"
        "    assert ex11.terminal.contains(ex11.model.step(x, u, w))\n"
        "assert mg.discretisation.startswith('the sampled-data ODE (validated')\n"),
}


def test_every_check_names_a_block():
    for key in CHECKS:
        assert sum(key in b for b in BLOCKS) == 1, key


@pytest.mark.parametrize("number", range(1, len(BLOCKS) + 1))
def test_readme_python_block_runs_on_its_own(number, tmp_path):
    """Block ``number`` (1-based, in README order) runs alone in a fresh interpreter (it
    has its own imports and data) in an empty directory; the facts the README states about
    its results hold; a comment line right under a block's first ``print`` starts with
    what that print printed."""
    block = BLOCKS[number - 1]
    checks = "\n".join(c for key, c in CHECKS.items() if key in block)
    res = subprocess.run([sys.executable, "-c", block + "\n" + checks], cwd=tmp_path,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, (
        f"README python block {number} failed when run on its own:\n{res.stderr}")
    lines = block.splitlines()
    first = next((i for i, ln in enumerate(lines) if ln.startswith("print(")), None)
    if first is not None and first + 1 < len(lines) and lines[first + 1].startswith("# "):
        shown = lines[first + 1][2:].split(":")[0]
        printed = res.stdout.splitlines()[0]
        assert printed == shown, (
            f"README python block {number} prints {printed!r}; the README shows {shown!r}")


def test_quickstart_test_command_is_what_ci_runs():
    text = (ROOT / "README.md").read_text()
    cmds = re.search(r"## Quickstart.*?```bash\n(.*?)```", text, re.S).group(1).splitlines()
    assert len(cmds) == 2 and "cmpc run" in cmds[0]
    ci = (ROOT / ".ci" / "run").read_text()
    assert cmds[1].strip() in ci
