"""``cmpc run --workers N`` and ``--scheduler ADDRESS``: the sets are computed on worker
processes or a Dask cluster and are those of a serial run; bad values are refused."""

from __future__ import annotations

import numpy as np
import pytest

from casadi_cmpc.cli import main
from casadi_cmpc.control.linear_sets import SetSequence
from casadi_cmpc.solvers import _parallel


def _sequence(cache) -> SetSequence:
    files = sorted(cache.glob("cannon-*.npz"))
    assert len(files) == 1
    return SetSequence.load(files[0])


@pytest.fixture(autouse=True)
def small_tasks(monkeypatch):
    monkeypatch.setattr(_parallel, "TARGET_S", 0.002)  # the E8 levels are small


@pytest.fixture(scope="module")
def serial_cache(tmp_path_factory):
    """The session's cache of set sequences (shared with tests/test_cli.py and
    tests/codegen/test_export.py, which run them serially): the serial E8 sequence is
    computed once per session, by whichever test needs it first."""
    d = tmp_path_factory.getbasetemp() / "cmpc_sequences"
    d.mkdir(exist_ok=True)
    return d


def test_run_with_workers_and_on_a_dask_cluster_gives_the_serial_sets(tmp_path, capsys,
                                                                      serial_cache):
    serial, pooled, dasked = serial_cache, tmp_path / "pool", tmp_path / "dask"
    args = ["run", "cannon", "--steps", "3", "--no-progress"]
    assert main([*args, "--cache", str(serial)]) == 0
    assert main([*args, "--cache", str(pooled), "--workers", "2"]) == 0
    text = capsys.readouterr().out
    assert "violations: state 0, input 0" in text
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        assert main([*args, "--cache", str(dasked), "--scheduler",
                     cluster.scheduler_address]) == 0
    text = capsys.readouterr().out
    assert "Dask cluster" in text and "violations: state 0, input 0" in text
    ref = _sequence(serial)
    for d in (pooled, dasked):
        got = _sequence(d)
        assert len(got.steps) == len(ref.steps) > 3
        assert all(np.array_equal(a["boxes"], b["boxes"])
                   for a, b in zip(got.steps, ref.steps, strict=True))


def test_bad_worker_options_are_refused(capsys):
    with pytest.raises(SystemExit) as e:
        main(["run", "cannon", "--workers", "0"])
    assert e.value.code == 2 and "--workers must be at least 1" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["run", "cannon", "--workers", "2", "--scheduler", "tcp://x:1"])
    assert e.value.code == 2 and "not allowed with" in capsys.readouterr().err



@pytest.mark.parametrize("example, eps", [("khalil_affine_control", "0.1"),
                                          ("khalil_affine_state", "0.2")])
def test_structured_pipelines_run_with_workers_and_give_the_serial_sets(example, eps, capsys,
                                                                        monkeypatch):
    """E12 (quasi sets on the engine, with its executor) and E11 (the affine-state grid, T's
    proof on the executor): ``--workers 2`` prints the sets and the run of the serial
    command; ``--checkpoint`` stays for the general sets."""
    from casadi_cmpc import cli

    args = ["run", example, "--eps", eps, "--steps", "3", "--no-progress"]

    def sets_and_run(extra):
        monkeypatch.setattr(cli, "_SETS_OF_THIS_PROCESS", {})  # computed again
        assert main([*args, *extra]) == 0
        out = capsys.readouterr().out
        return [ln for ln in out.splitlines()
                if ln.startswith(("terminal set:", "  certificates", "  final state"))]

    serial = sets_and_run([])
    assert serial and any(ln.startswith("terminal set:") for ln in serial)
    assert sets_and_run(["--workers", "2"]) == serial
    assert main([*args, "--checkpoint", "x.npz"]) != 0
    out = capsys.readouterr()
    assert "--checkpoint is for the general" in out.err + out.out
