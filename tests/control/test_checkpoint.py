"""Resumable controllable-set sequences: ``controllable_sets(..., checkpoint=PATH)``.

A run killed (SIGKILL, also in the middle of writing the checkpoint), interrupted (Ctrl-C) or
stopped by its time limit resumes from its last completed step, and the result equals an
uninterrupted run bit for bit; a checkpoint of another problem is refused and left as it is.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import casadi_cmpc as cm
import casadi_cmpc.control.controllable as controllable
from casadi_cmpc.control._checkpoint import CheckpointError, progress_text
from casadi_cmpc.control.linear_sets import SetSequence

EPS = 0.1  # E9 at this eps: 31 steps, 2605 boxes, about a second


@pytest.fixture(scope="module")
def ex():
    return cm.models.load("cannon_robust")


def run(ex, **kw):
    kw = {"robust": True, "law": ex.local_law, "progress": False, **kw}
    eps = kw.pop("eps", EPS)
    return cm.controllable_sets(ex.model, ex.terminal, eps, **kw)


@pytest.fixture(scope="module")
def ref(ex):
    """The uninterrupted run without checkpoint."""
    seq = run(ex)
    assert seq.status == "converged" and len(seq.steps) > 10
    return seq


def assert_same_steps(a, b, n=None):
    """The first n steps (all: also the same number) hold the same boxes and controls,
    bit for bit."""
    if n is None:
        assert len(a.steps) == len(b.steps) and len(a.sets) == len(b.sets)
        n = len(a.steps)
    for i in range(n):
        sa, sb = a.steps[i], b.steps[i]
        for k in ("boxes", "witness"):
            assert sa[k].dtype == sb[k].dtype, (i, k)
            assert np.array_equal(sa[k], sb[k]), (i, k)
        assert sa["boundary"] == sb["boundary"]
        assert sa.get("polytope") is sb.get("polytope") is None


def assert_same(a, b):
    """Equal sequences: statuses, steps, and every set's boxes."""
    assert (a.status, a.converged_at) == (b.status, b.converged_at)
    assert_same_steps(a, b)
    for Ka, Kb in zip(a.sets[1:], b.sets[1:], strict=True):
        Pa, Pb = Ka.members[1], Kb.members[1]
        assert np.array_equal(Pa.inner, Pb.inner) and Pa.inner.dtype == Pb.inner.dtype
        assert np.array_equal(Ka.members[0].A, Kb.members[0].A)


def saved_steps(path: Path) -> int:
    """Completed steps in the checkpoint file (0 while there is none)."""
    if not path.exists():
        return 0
    return len(SetSequence.load(path).steps)


# the child: E9 with a pause before each step (so that the parent kills it mid-run)
CHILD = """
import sys, time
import casadi_cmpc as cm
import casadi_cmpc.control.controllable as C

search = C._search

def slow(*a, **k):
    time.sleep(0.3)
    return search(*a, **k)

C._search = slow
ex = cm.models.load("cannon_robust")
cm.controllable_sets(ex.model, ex.terminal, {eps}, robust=True, law=ex.local_law,
                     progress=False, checkpoint=sys.argv[1])
"""


def test_a_killed_run_resumes_to_the_uninterrupted_result(ex, ref, tmp_path):
    path = tmp_path / "e9.npz"
    proc = subprocess.Popen([sys.executable, "-c", CHILD.format(eps=EPS), str(path)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 45
        while saved_steps(path) < 1:
            assert proc.poll() is None, proc.communicate()[1].decode()[-2000:]
            assert time.monotonic() < deadline, "no completed step in the checkpoint"
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()
    assert proc.returncode == -signal.SIGKILL
    saved = SetSequence.load(path)
    k = len(saved.steps)
    assert 1 <= k < len(ref.steps) and saved.status == "interrupted"
    assert_same_steps(saved, ref, k)
    seq = run(ex, checkpoint=path)
    assert_same(seq, ref)
    assert seq.info["resumed_steps"] == k
    # the file now holds the complete sequence; a second call returns it without any
    # search and without certifying T again
    final = SetSequence.load(path)
    assert final.status == "converged"
    assert_same_steps(final, ref)


def test_a_run_killed_while_writing_keeps_the_previous_checkpoint(ex, ref, tmp_path):
    """SIGKILL after the partial file is half written, before the rename: the checkpoint
    of the step before is intact, the partial file is removed on resumption."""
    path = tmp_path / "e9.npz"
    child = CHILD.format(eps=EPS).replace("C._search = slow", """
import os, signal
from casadi_cmpc.control.linear_sets import SetSequence
save = SetSequence.save
calls = []

def dying_save(self, p, **kw):
    calls.append(p)
    save(self, p, **kw)
    if len(calls) == 3:  # the third checkpoint: cut short, then killed
        with open(p, "r+b") as fh:
            fh.truncate(os.path.getsize(p) // 2)
        os.kill(os.getpid(), signal.SIGKILL)

SetSequence.save = dying_save
""")
    proc = subprocess.run([sys.executable, "-c", child, str(path)], capture_output=True,
                          timeout=60)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-2000:]
    partial = [p for p in tmp_path.iterdir() if p.name.endswith(".partial.npz")]
    assert len(partial) == 1  # the cut-short write, under its own name
    saved = SetSequence.load(path)
    assert len(saved.steps) == 2
    assert_same_steps(saved, ref, 2)
    seq = run(ex, checkpoint=path)
    assert_same(seq, ref)
    assert seq.info["resumed_steps"] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_ctrl_c_keeps_the_completed_steps(ex, ref, tmp_path, monkeypatch, suffix):
    path = tmp_path / f"e9{suffix}"
    search = controllable._search
    calls = []

    def interrupted(*a, **k):
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return search(*a, **k)

    monkeypatch.setattr(controllable, "_search", interrupted)
    seq = run(ex, checkpoint=path)
    assert seq.status == "interrupted" and len(seq.steps) == 3
    saved = SetSequence.load(path)
    assert len(saved.steps) == 3 and saved.status == "interrupted"
    assert_same_steps(saved, ref, 3)
    monkeypatch.undo()
    seq = run(ex, checkpoint=path)
    assert_same(seq, ref)
    assert seq.info["resumed_steps"] == 3

    def fail(*a, **k):
        raise AssertionError("searched or certified again")

    # complete: returned as it is, with neither a search nor a certification of T
    monkeypatch.setattr(controllable, "_search", fail)
    monkeypatch.setattr(controllable, "_check_terminal", fail)
    again = run(ex, checkpoint=path)
    assert_same(again, ref)
    assert again.info["resumed_steps"] == len(ref.steps)
    # replayed under other stopping rules: the first steps of the same sequence
    short = run(ex, checkpoint=path, max_steps=5)
    assert short.status == "max_steps" and len(short.steps) == 5
    assert_same_steps(short, ref, 5)


def test_a_time_limit_keeps_the_completed_steps(ex, ref, tmp_path, monkeypatch):
    """A step stopped by its time limit is not written; the next run computes it."""
    path = tmp_path / "e9.npz"
    search = controllable._search
    calls = []

    def limited(*a, **k):
        calls.append(1)
        if len(calls) == 3:
            k["time_limit"] = 1e-9
        return search(*a, **k)

    monkeypatch.setattr(controllable, "_search", limited)
    seq = run(ex, checkpoint=path, time_limit=600)
    assert seq.status == "budget" and len(seq.steps) == 3
    saved = SetSequence.load(path)
    assert len(saved.steps) == 2 and saved.status == "interrupted"
    assert_same_steps(saved, ref, 2)
    monkeypatch.undo()
    seq = run(ex, checkpoint=path, time_limit=600)
    assert_same(seq, ref)
    assert seq.info["resumed_steps"] == 2


def test_a_checkpoint_of_another_problem_is_refused_and_kept(ex, tmp_path):
    path = tmp_path / "e9.npz"
    other = run(ex, eps=0.2, max_steps=2, checkpoint=path)
    assert len(other.steps) == 2
    before = path.read_bytes()
    with pytest.raises(CheckpointError, match=r"eps: 0\.2 in the checkpoint, 0\.1 here"):
        run(ex, checkpoint=path)
    with pytest.raises(ValueError, match=r"robust: True in the checkpoint, False here"):
        run(ex, eps=0.2, robust=False, checkpoint=path)
    with pytest.raises(CheckpointError, match="proof of T's invariance"):
        run(ex, eps=0.2, law=None, assume_invariant=True, checkpoint=path)
    assert path.read_bytes() == before
    # the same problem resumes it
    assert run(ex, eps=0.2, max_steps=3, checkpoint=path).info["resumed_steps"] == 2
    # a sequence file that is no checkpoint is refused, not overwritten
    plain = tmp_path / "plain.npz"
    other.save(plain)
    before = plain.read_bytes()
    with pytest.raises(CheckpointError, match="not a checkpoint"):
        run(ex, eps=0.2, checkpoint=plain)
    assert plain.read_bytes() == before
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"PK half")
    with pytest.raises(CheckpointError, match="cannot be read"):
        run(ex, checkpoint=bad)
    assert bad.read_bytes() == b"PK half"
    with pytest.raises(ValueError, match="must end in '.npz'"):
        run(ex, checkpoint=tmp_path / "e9.dat")


def test_progress_false_is_silent_and_the_bar_estimates_time_left(ex, tmp_path, capfd):
    run(ex, eps=0.2, max_steps=3, checkpoint=tmp_path / "e9.npz")
    assert capfd.readouterr() == ("", "")
    assert "not estimated" in progress_text(3, 60, [10, 20, 30], [1.0, 1.0, 1.0], 100)
    text = progress_text(8, 500, [10, 50, 100, 80, 60, 40, 30, 20], [1.0] * 8, 100)
    assert text.startswith("K_8: 500 boxes (+20), 1 s/step")
    assert "left (estimate: " in text
