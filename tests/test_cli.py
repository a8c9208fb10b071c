import json

import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.cli import main

# closed-loop steps per example in the suite (the examples' own counts run in CI of the
# notebooks' full mode and by hand)
STEPS = {"mirosot": 4, "cannon_001": 4}


@pytest.mark.parametrize("name", cm.models.names())
def test_run_every_listed_example(name, tmp_path, capsys):
    """Every example that ``cmpc list`` shows runs, exits 0 and writes its outputs."""
    steps = STEPS.get(name, 6)
    assert main(["run", name, "--out", str(tmp_path), "--steps", str(steps),
                 "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "controller: ContractiveMPC" in text and "violations: state 0, input 0" in text
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["example"] == name and summary["total_violations"] == 0
    ex = cm.models.load(name)
    x0s = np.asarray(ex.info["run"].get("x0s", ex.x0s)).reshape(-1, ex.model.n)
    assert len(summary["runs"]) == x0s.shape[0] >= 1
    for r, x0 in zip(summary["runs"], x0s, strict=True):
        np.testing.assert_allclose(r["x0"], x0)
        assert r["steps"] == steps
        assert sum(r["certificates"].values()) == steps
        # every step is either verified or the local law inside its set
        assert set(r["certificates"]) <= {"verified", "local_law", "at_reference"}
        assert len(r["horizon_per_step"]) == steps
    for f in summary["figures"]:
        assert (tmp_path / f).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "phase_plane.png" in summary["figures"]
    report = (tmp_path / "report.txt").read_text()
    assert name in report and "violations counted by the simulator" in report


def test_default_example_is_cannon_robust_and_says_what_it_runs(tmp_path, capsys):
    assert main(["run", "--steps", "3", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "cannon_robust" in out
    assert "nominal" in out and "uniform" in out  # says it runs the nominal MPC


def test_closed_loop_of_default_example_reaches_the_origin(tmp_path):
    assert main(["run", "--out", str(tmp_path), "--no-progress"]) == 0
    r = json.loads((tmp_path / "summary.json").read_text())["runs"][0]
    assert r["final_distance_to_reference"] < 1e-2
    assert r["violations"] == {"state": 0, "input": 0}


def test_run_unknown_example_fails_cleanly(capsys):
    assert main(["run", "no_such_model"]) == 2
    assert "no_such_model" in capsys.readouterr().err


def test_bad_steps_is_refused():
    with pytest.raises(SystemExit):
        main(["run", "grimm", "--steps", "0"])


def test_list_names_every_example(capsys):
    assert main(["list"]) == 0
    names = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert names == cm.models.names() and len(names) == 10


def test_missing_command_is_an_error():
    with pytest.raises(SystemExit):
        main([])


def test_unwritable_out_is_refused_before_running(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    assert main(["run", "grimm", "--out", str(blocker / "sub"), "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert "cannot write" in captured.err and "run 1" not in captured.out
