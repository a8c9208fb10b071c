"""cmpc run caches only complete set sequences and ends an interruption with code 130."""

from __future__ import annotations

import casadi_cmpc.control.controllable as controllable
from casadi_cmpc import cli, models
from casadi_cmpc.control.linear_sets import SetSequence


def _seq(status: str, ex, cfg) -> SetSequence:
    from casadi_cmpc.control.invariance import model_key

    return SetSequence(sets=[ex.terminal], status=status, info={
        "eps": cfg["eps"], "robust": cfg["robust"], "model_key": model_key(ex.model),
        "terminal_certificate": "proved"})


def test_an_interrupted_sequence_is_not_cached_and_exits_130(tmp_path, monkeypatch, capsys):
    ex = models.load("cannon")
    cfg = ex.info["sequence"]
    monkeypatch.setattr(controllable, "controllable_sets",
                        lambda *a, **k: _seq("interrupted", ex, cfg))
    rc = cli.main(["run", "cannon", "--cache", str(tmp_path), "--no-progress"])
    assert rc == 130
    assert list(tmp_path.iterdir()) == []
    err = capsys.readouterr().err
    assert "interrupted" in err and "Traceback" not in err


def test_a_partial_cache_is_not_reused(tmp_path, monkeypatch):
    ex = models.load("cannon")
    cfg = ex.info["sequence"]
    path = cli._cache_path(ex, cfg, str(tmp_path))
    _seq("budget", ex, cfg).save(path)
    calls = []

    def fake(*a, **k):
        calls.append(1)
        raise KeyboardInterrupt

    monkeypatch.setattr(controllable, "controllable_sets", fake)
    rc = cli.main(["run", "cannon", "--cache", str(tmp_path), "--no-progress"])
    assert calls == [1] and rc == 130  # the stored partial sequence was not used
    assert cli._cache_mismatch(SetSequence.load(path), ex, cfg).startswith("its computation")
    ok = _seq("converged", ex, cfg)
    assert cli._cache_mismatch(ok, ex, cfg) is None
    ok.info["eps"] = cfg["eps"] * 2
    assert "other settings" in cli._cache_mismatch(ok, ex, cfg)
