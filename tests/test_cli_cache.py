"""The cache of set sequences: ``cmpc run`` caches only complete sequences (an interruption
ends with code 130), ``cmpc cache`` shows and clears it, and a sequence file stores each box
once and restores an equal sequence."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

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


def test_cmpc_cache_lists_and_clears_only_its_files(tmp_path, monkeypatch, capsys):
    """``cmpc cache`` prints the directory and each cached file with its size;
    ``--clear`` deletes those files and leaves any other file alone."""
    ex = models.load("cannon")
    cfg = ex.info["sequence"]
    path = cli._cache_path(ex, cfg, str(tmp_path))
    _seq("converged", ex, cfg).save(path)
    other = tmp_path / "notes.txt"
    other.write_text("mine")
    size = path.stat().st_size
    assert cli.main(["cache", "--cache", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"cache directory: {tmp_path}" in out
    line = next(ln for ln in out.splitlines() if path.name in ln)
    assert line.split()[-2:] == cli._size(size).split()
    assert "1 cached sequence file," in out and "notes.txt" in out
    assert cli.main(["cache", "--cache", str(tmp_path), "--clear"]) == 0
    out = capsys.readouterr().out
    assert "removed 1 cached sequence file" in out
    assert not path.exists() and other.read_text() == "mine"
    assert cli.main(["cache", "--cache", str(tmp_path)]) == 0
    assert "0 cached sequence files, 0 B" in capsys.readouterr().out
    # without --cache: $XDG_CACHE_HOME/casadi_cmpc, the directory `cmpc run` uses
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cli.main(["cache"]) == 0
    out = capsys.readouterr().out
    assert f"cache directory: {tmp_path / 'xdg' / 'casadi_cmpc'}" in out
    assert "does not exist" in out
    assert cli._cache_path(ex, cfg, None).parent == tmp_path / "xdg" / "casadi_cmpc"


def test_sizes_are_printed_for_readers():
    assert [cli._size(b) for b in (0, 999, 1500, 500_564, 892_503_074, 2_000_000_000)] == [
        "0 B", "999 B", "1.5 kB", "500.6 kB", "892.5 MB", "2.0 GB"]


def test_a_sequence_for_another_local_law_is_not_reused():
    ex = models.load("cannon")
    cfg = ex.info["sequence"]
    seq = _seq("converged", ex, cfg)
    seq.info["terminal_law_key"] = cli._law_key(ex)
    assert cli._cache_mismatch(seq, ex, cfg) is None
    seq.info["terminal_law_key"] = "0" * 20
    assert "another local law" in cli._cache_mismatch(seq, ex, cfg)


def test_the_cache_is_written_whole_or_not_at_all(tmp_path, monkeypatch):
    """A failing write leaves neither the cache file nor a partial file behind."""
    ex = models.load("cannon")
    cfg = ex.info["sequence"]
    path = cli._cache_path(ex, cfg, str(tmp_path))
    seq = _seq("converged", ex, cfg)

    def failing_save(p):
        Path(p).write_bytes(b"PK half")
        raise OSError("disk full")

    monkeypatch.setattr(seq, "save", failing_save)
    with pytest.raises(OSError, match="disk full"):
        cli._save_atomically(seq, path)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    cli._save_atomically(seq, path)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]
    assert SetSequence.load(path).status == "converged"


# ------------------------------------------------------------- the file of a sequence
@pytest.fixture(scope="module")
def e8_short():
    """E8's sequence, 6 steps at eps 0.1 (about a second)."""
    ex = models.load("cannon")
    seq = controllable.controllable_sets(ex.model, ex.terminal, 0.1, law=ex.local_law,
                                         max_steps=6, progress=False)
    assert len(seq.steps) == 6 and all(st["boxes"].shape[0] for st in seq.steps)
    return ex, seq


def _same(a, b) -> bool:
    """Equality of nested dicts, lists and arrays, arrays bit for bit."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(
            _same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(
            _same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def _content(seq: SetSequence) -> dict:
    """Everything a sequence holds, as plain values."""
    return {"sets": [(type(S).__name__, S._state()) for S in seq.sets],
            "steps": [{k: (v._state() if hasattr(v, "_state") else v)
                       for k, v in st.items() if v is not None} for st in seq.steps],
            "info": {k: v for k, v in seq.info.items()
                     if isinstance(v, (str, int, float, bool, list, np.ndarray))},
            "status": seq.status, "converged_at": seq.converged_at}


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_a_sequence_file_restores_an_equal_sequence(e8_short, tmp_path, suffix):
    """save/load give back the same sets (K_i = T plus the boxes of steps 1..i), steps,
    info and status, arrays bit for bit, through SetSequence.load and cm.load_set."""
    from casadi_cmpc import load_set

    ex, seq = e8_short
    path = seq.save(tmp_path / f"seq{suffix}")
    for back in (SetSequence.load(path), load_set(path)):
        assert isinstance(back, SetSequence)
        assert _same(_content(back), _content(seq))
        assert back.sets[3].members[0] is back.sets[0]  # T is stored once
        P = ex.model.X.sample(2000, np.random.default_rng(0))
        assert np.array_equal(back.level(P), seq.level(P))


def test_a_sequence_file_stores_each_box_once(e8_short, tmp_path):
    """The .npz holds the step boxes once, compressed: smaller than their raw bytes (the
    boxes copied into every K_i took the sum over i of all earlier boxes)."""
    ex, seq = e8_short
    path = seq.save(tmp_path / "seq.npz")
    boxes = sum(st["boxes"].nbytes for st in seq.steps)
    raw = boxes + sum(st["witness"].nbytes for st in seq.steps)
    copies = sum(S.members[1].inner.nbytes for S in seq.sets[1:])
    assert copies > 3 * boxes  # what the copies in every K_i would have cost
    assert path.stat().st_size < raw
    with np.load(path) as z:  # the arrays are binary entries, not JSON text
        assert len(str(z["__meta__"])) < 20_000


def test_sets_that_are_not_the_union_of_the_steps_are_stored_as_they_are(e8_short, tmp_path):
    """A K_i that is not T plus the boxes of steps 1..i (here one box less) is saved with
    its own boxes and comes back unchanged."""
    from casadi_cmpc.sets import Paving
    from casadi_cmpc.sets.union import SetUnion

    ex, seq = e8_short
    seq = SetSequence(sets=list(seq.sets), steps=seq.steps, info=dict(seq.info),
                      status=seq.status, converged_at=seq.converged_at)
    P = seq.sets[2].members[1]
    seq.sets[2] = SetUnion([seq.sets[0], Paving(inner=P.inner[:-1], domain=P.domain)])
    back = SetSequence.load(seq.save(tmp_path / "seq.npz"))
    assert _same(_content(back), _content(seq))
    assert back.sets[2].members[1].inner.shape[0] == P.inner.shape[0] - 1


def test_a_file_of_the_previous_layout_still_loads(e8_short, tmp_path):
    """Files written before (every K_i with its boxes, arrays as JSON text) load."""
    from pathlib import Path as P_

    from casadi_cmpc.sets.base import _save_state

    ex, seq = e8_short
    state = {"sets": [{"type": S._type_name, "state": S._state()} for S in seq.sets],
             "converged_at": -1 if seq.converged_at is None else seq.converged_at,
             "status": seq.status,
             "steps": [{k: v for k, v in st.items() if v is not None} for st in seq.steps],
             "info": {k: v for k, v in seq.info.items()
                      if isinstance(v, (str, int, float, bool, list, np.ndarray))}}
    path = _save_state("SetSequence", state, P_(tmp_path / "old.npz"))
    assert _same(_content(SetSequence.load(path)), _content(seq))


def test_cmpc_cache_counts_and_clears_the_compiled_interval_kernels(tmp_path, monkeypatch,
                                                                    capsys):
    """The native backend's kernels live in the default cache directory: `cmpc cache`
    counts them, `--clear` removes them (and nothing else there)."""
    import casadi as ca
    import numpy as np

    from casadi_cmpc.interval import InclusionFunction
    from casadi_cmpc.interval import _native as nat

    if not nat.native_available():
        return
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setattr(nat, "_loaded", {})
    x = ca.SX.sym("x", 2)
    F = InclusionFunction(ca.Function("kc", [x], [ca.exp(x[0]) - x[1]]), backend="native")
    F(np.array([[[0.0, 1.0], [2.0, 3.0]]]))
    kd = tmp_path / "casadi_cmpc" / "kernels"
    assert len(list(kd.glob("k*.so"))) == 1
    assert cli.main(["cache"]) == 0
    out = capsys.readouterr().out
    assert "1 compiled interval kernel in" in out and "left alone" not in out
    assert cli.main(["cache", "--clear"]) == 0
    assert "removed 1 compiled interval kernel" in capsys.readouterr().out
    assert not list(kd.glob("k*.so"))
