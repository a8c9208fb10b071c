import json

import pytest

from casadi_cmpc.cli import main


def test_run_default_example_checks_samples_and_writes_json(tmp_path, capsys):
    assert main(["run", "--out", str(tmp_path), "--samples", "2000"]) == 0
    text = capsys.readouterr().out
    assert "cannon_robust" in text and "natural" in text and "centered" in text
    report = json.loads((tmp_path / "run.json").read_text())
    assert report["example"] == "cannon_robust"
    for kind in ("natural", "centered"):
        assert report[kind]["samples_inside"] is True
        enc = report[kind]["enclosure"]
        assert len(enc) == 2 and all(lo <= hi for lo, hi in enc)
    # the centered enclosure is never wider than the natural one (it is intersected with it)
    for (nl, nh), (cl, ch) in zip(report["natural"]["enclosure"],
                                  report["centered"]["enclosure"], strict=True):
        assert cl >= nl and ch <= nh


@pytest.mark.parametrize("name", __import__("casadi_cmpc").models.names())
def test_run_every_listed_example(name, tmp_path, capsys):
    """Every example that ``cmpc list`` shows runs, and its enclosures hold the samples."""
    assert main(["run", name, "--out", str(tmp_path), "--samples", "500"]) == 0
    report = json.loads((tmp_path / "run.json").read_text())
    assert report["example"] == name
    assert report["natural"]["samples_inside"] and report["centered"]["samples_inside"]


def test_run_unknown_example_fails_cleanly(capsys):
    assert main(["run", "no_such_model"]) == 2
    assert "no_such_model" in capsys.readouterr().err


def test_list_names_every_example(capsys):
    assert main(["list"]) == 0
    names = capsys.readouterr().out.split()
    assert "cstr" in names and "mirosot" in names and len(names) == 10


def test_missing_command_is_an_error():
    with pytest.raises(SystemExit):
        main([])
