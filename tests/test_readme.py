"""The README's Python examples run, and its quickstart matches .ci/run."""

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_readme_python_blocks_run(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the examples write files
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks
    ns: dict = {}
    for b in blocks:
        exec(compile(b, "README.md", "exec"), ns)  # noqa: S102
    assert ns["res"].lower <= ns["res"].upper
    assert ns["paving"].n_inner > 0
    # the controllable-set example: a certified robust control from E9's initial state
    assert ns["r"].certificate.label == "verified" and ns["r"].horizon >= 1
    assert ns["seq9"].status == "converged" and ns["cert1"].proved is True
    assert (tmp_path / "e9_sets.npz").is_file()


def test_quickstart_test_command_is_what_ci_runs():
    text = (ROOT / "README.md").read_text()
    cmds = re.search(r"## Quickstart.*?```bash\n(.*?)```", text, re.S).group(1).splitlines()
    assert len(cmds) == 2 and "cmpc run" in cmds[0]
    ci = (ROOT / ".ci" / "run").read_text()
    assert cmds[1].strip() in ci
