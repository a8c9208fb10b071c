import contextlib
import io
import json
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.cli import main
from casadi_cmpc.codegen.export import can_build

# closed-loop steps per example in the suite (the examples' own counts run in CI of the
# notebooks' full mode and by hand)
STEPS = {"mirosot": 4, "cannon_001": 4}


SEQUENCE_EXAMPLES = [n for n in cm.models.names() if "sequence" in cm.models.load(n).info]
# the structured set pipelines of thesis chapter 6 (E11, E12): run and exported in
# tests/test_cli_structured.py; here with their contractive MPC
STRUCTURED_EXAMPLES = [n for n in cm.models.names()
                       if {"quasi", "affine_state"} & set(cm.models.load(n).info)]




@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """The cache of set sequences shared by the CLI and export tests of the session (the
    session's base temporary directory): each sequence is computed once, by the first test
    that needs it, and loaded from the cache by the others."""
    d = tmp_path_factory.getbasetemp() / "cmpc_sequences"
    d.mkdir(exist_ok=True)
    return str(d)


# the builds of the exported examples (make and the C compiler, the longest part of
# test_export_every_listed_example) run on one background thread while the Python tests of
# this module go on; every test that changes PATH or CC waits for them first
_BUILDS: list[Future] = []


def _wait_for_builds() -> None:
    for fut in _BUILDS:
        fut.exception()  # wait (a failed build is reported by the test of its example)


@pytest.fixture(scope="module")
def exports(tmp_path_factory, cache):
    """``cmpc export`` of every listed example, each into its own directory, with the
    options of test_export_every_listed_example; the build of libcmpc.so of each export
    (when a C compiler is available) is started at once on a background thread.

    Returns a dict ``name -> (exit code, stdout, stderr, directory, build future or None)``,
    or ``name -> exception`` when the export raised (raised again by the test of that
    example). Contractive examples are exported first: their builds take longest and then
    overlap with the computation of the set sequences (which the run tests read from the
    cache)."""
    from casadi_cmpc.codegen.export import build

    names = cm.models.names()
    order = ([n for n in names if n not in SEQUENCE_EXAMPLES]
             + [n for n in names if n in SEQUENCE_EXAMPLES])
    builder = ThreadPoolExecutor(max_workers=1)
    out = {}
    try:
        for name in order:
            d = tmp_path_factory.mktemp(f"export_{name}") / "c"
            # the structured examples' own controllers: tests/test_cli_structured.py
            controller = "contractive" if name in STRUCTURED_EXAMPLES else "auto"
            so, se = io.StringIO(), io.StringIO()
            try:
                with contextlib.redirect_stdout(so), contextlib.redirect_stderr(se):
                    code = main(["export", name, "--out", str(d), "--cache", cache,
                                 "--no-progress", "--controller", controller])
            except Exception as exc:  # noqa: BLE001 - reported by the example's own test
                out[name] = exc
                continue
            fut = None
            if code == 0 and can_build():
                fut = builder.submit(build, d, "libcmpc.so")
                _BUILDS.append(fut)
            out[name] = (code, so.getvalue(), se.getvalue(), d, fut)
        yield out
    finally:
        builder.shutdown(wait=True)
        _BUILDS.clear()


def test_the_set_pipeline_covers_e8_e9_e10_e14():
    assert SEQUENCE_EXAMPLES == ["cstr", "cannon", "cannon_robust", "cannon_robust_wide"]
    assert STRUCTURED_EXAMPLES == ["khalil_affine_state", "khalil_affine_control"]


# every example with 'auto' (the structured ones in test_cli_structured.py); the
# set-pipeline examples also with the contractive MPC
RUNS = ([(n, "auto") for n in cm.models.names() if n not in STRUCTURED_EXAMPLES]
        + [(n, "contractive") for n in SEQUENCE_EXAMPLES + STRUCTURED_EXAMPLES])


@pytest.mark.parametrize("name, controller", RUNS)
def test_run_every_listed_example(name, controller, tmp_path, capsys, cache, exports):
    """Every example that ``cmpc list`` shows runs with each controller it has, exits 0 and
    writes its outputs."""
    steps = STEPS.get(name, 6)
    assert main(["run", name, "--out", str(tmp_path), "--steps", str(steps),
                 "--no-progress", "--controller", controller, "--cache", cache]) == 0
    text = capsys.readouterr().out
    kind = ("SetSequenceMPC" if name in SEQUENCE_EXAMPLES and controller == "auto"
            else "ContractiveMPC")
    assert f"controller: {kind}" in text and "violations: state 0, input 0" in text
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
    if kind == "SetSequenceMPC":
        assert "sets.png" in summary["figures"]
        seq = summary["sequence"]
        assert seq["terminal_certificate"] == "proved" and seq["status"] == "converged"
        assert all(lv is not None and lv >= 0 for lv in seq["levels_x0"])
    report = (tmp_path / "report.txt").read_text()
    assert name in report and "violations counted by the simulator" in report
    # the claim follows the model: which map the certificates are about, what ran
    m = ex.model
    assert f"they are about {m.discretisation}" in report
    assert summary["model_map"] == m.discretisation
    if ex.info["run"].get("plant") is not None:  # an ODE integrated, not the model's map
        assert summary["simulated_on"].startswith("the plant ")
        assert m.discretisation.startswith("the sampled-data ODE (validated")
    else:
        assert summary["simulated_on"] == f"the model's own map ({m.discretisation})"


def test_default_example_is_the_robust_set_pipeline_and_says_what_it_runs(capsys, cache):
    assert main(["run", "--steps", "3", "--no-progress", "--cache", cache]) == 0
    out = capsys.readouterr().out
    assert "cannon_robust" in out and "SetSequenceMPC" in out
    assert "proved invariant" in out and "exists u for all w" in out
    assert "certified for all mu" in out and "uniform" in out
    # the second run loads the cached sequence
    assert main(["run", "--steps", "3", "--no-progress", "--cache", cache]) == 0
    assert "loaded from the cache" in capsys.readouterr().out


def test_closed_loop_of_default_example_reaches_the_origin(tmp_path, cache):
    assert main(["run", "--out", str(tmp_path), "--no-progress", "--cache", cache]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    r = summary["runs"][0]
    assert r["final_distance_to_reference"] < 1e-2
    assert r["violations"] == {"state": 0, "input": 0}
    # every step certified: the robust one-step control or the local law in T
    assert set(r["certificates"]) <= {"verified", "local_law"}
    assert r["certificates"].get("verified", 0) >= 10


def test_a_corrupt_cache_is_recomputed(tmp_path, capsys):
    from casadi_cmpc.cli import _cache_path

    ex = cm.models.load("cannon")
    path = _cache_path(ex, ex.info["sequence"], str(tmp_path))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"not a sequence")
    assert main(["run", "cannon", "--steps", "2", "--no-progress", "--cache",
                 str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "unreadable" in out and "sequence computed" in out


def test_run_unknown_example_fails_cleanly(capsys):
    assert main(["run", "no_such_model"]) == 2
    assert "no_such_model" in capsys.readouterr().err


def test_bad_steps_is_refused():
    with pytest.raises(SystemExit):
        main(["run", "grimm", "--steps", "0"])


def test_list_says_what_every_example_is(capsys):
    """One line per example: name, thesis example, dimensions, a description with the
    thesis section, and whether it has controllable sets."""
    assert main(["list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    names = [line.split()[0] for line in lines]
    # every example cmpc run accepts, the validated variant of the CSTR too
    assert names == cm.models.names(validated=True) and len(names) == 14
    assert names[-1] == "cstr_validated"
    for name, line in zip(names, lines, strict=True):
        ex = cm.models.load(name)
        n, m, nw = ex.model.n, ex.model.m, ex.model.l
        assert f" {ex.info['example']} " in line
        assert f"{n} states, {m} input{'s' * (m > 1)}" in line
        assert (f"{nw} disturbance" in line) == (nw > 0)
        if name == "cstr_validated":  # a thesis model in a validated form
            assert "not a thesis example" in line and "§4.2.7" in line
        elif ex.info["example"] == "extra":  # not from the thesis: no section
            assert "§" not in line and line.endswith(ex.info["description"])
        else:
            assert "§" + ex.info["section"].split(",")[0] in line
        assert line.endswith("; controllable sets") == ("sequence" in ex.info)
    by_name = dict(zip(names, lines, strict=True))
    assert "continuous stirred-tank reactor" in by_name["cstr"]
    assert "E6, E14" in by_name["cstr"]
    assert "mu in [0.85, 0.95]" in by_name["cannon_robust"]
    assert "8 states, 2 inputs" in by_name["mirosot"] and "obstacle" in by_name["mirosot"]


@pytest.mark.parametrize("args, says", [
    (["run", "grimm", "--seed", "-1"], "--seed must be a non-negative integer"),
    (["run", "grimm", "--eps", "nan"], "--eps must be a positive number"),
    (["run", "grimm", "--workers", "0"], "--workers must be at least 1"),
])
def test_bad_numbers_are_refused_by_the_parser(args, says, capsys):
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2 and says in capsys.readouterr().err


def test_unwritable_checkpoint_and_export_paths_are_refused_clearly(tmp_path, capsys):
    """A path under a regular file, a directory given as the checkpoint file, a file given
    as the export directory (with or without --overwrite): one clear line, exit code 2, no
    traceback, nothing computed."""
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    for ck, says in ((blocker / "x.npz", "is a file, not a directory"),
                     (tmp_path, "is a directory")):
        with pytest.raises(SystemExit) as exc:
            main(["run", "cannon", "--checkpoint", str(ck), "--no-progress"])
        assert exc.value.code == 2 and says in capsys.readouterr().err
    for out, extra in ((blocker, ["--overwrite"]), (blocker, []), (blocker / "sub", [])):
        assert main(["export", "cannon", "--out", str(out), "--no-progress", *extra]) == 2
        err = capsys.readouterr().err
        assert "is a file" in err and "Traceback" not in err
    assert blocker.read_text() == "not a directory"


def test_what_the_closed_loops_run_on_is_named_as_it_is():
    """cstr_validated has no plant: simulate() evaluates its Taylor polynomial (without the
    remainder), which the run must not call the validated ODE."""
    from casadi_cmpc.cli import _plant_text

    ex = cm.models.load("cstr_validated")
    assert ex.info["run"].get("plant") is None and ex.model.is_validated
    text = _plant_text(ex.model, ex.info["run"])
    assert text.startswith("the model's Taylor polynomial without its remainder")
    assert "validated" not in text
    mg = cm.models.load("moore_greitzer")
    assert _plant_text(mg.model, mg.info["run"]).startswith("the plant ")
    plain = cm.models.load("cannon")
    assert _plant_text(plain.model, plain.info["run"]) == \
        f"the model's own map ({plain.model.discretisation})"


def test_missing_command_is_an_error():
    with pytest.raises(SystemExit):
        main([])


def test_unwritable_out_is_refused_before_running(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    assert main(["run", "grimm", "--out", str(blocker / "sub"), "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert "cannot write" in captured.err and "run 1" not in captured.out


@pytest.mark.parametrize("name", cm.models.names())
def test_export_every_listed_example(name, cache, exports):
    """``cmpc export`` writes the C sources of every example's controller (the sequence
    examples from the cached sets); the header names the example's dimensions. (The export
    and the start of its build: the ``exports`` fixture.)"""
    if isinstance(exports[name], BaseException):
        raise exports[name]
    code, _, err, out, build = exports[name]
    controller = "contractive" if name in STRUCTURED_EXAMPLES else "auto"
    ex = cm.models.load(name)
    if ex.info["mpc"].get("solver") == "lp" and name not in SEQUENCE_EXAMPLES:
        # the LP form has no C export: a clear refusal, nothing written
        assert code == 2 and "solver='lp'" in err and not out.exists()
        return
    assert code == 0, err
    hdr = (out / "cmpc_controller.h").read_text()
    assert f"#define CMPC_NX {ex.model.n}" in hdr and f"#define CMPC_NU {ex.model.m}" in hdr
    kind = "set_sequence" if name in SEQUENCE_EXAMPLES else "contractive"
    assert f'#define CMPC_KIND "{kind}"' in hdr
    assert "int cmpc_step(const double *x, double *u);" in hdr
    if not can_build():
        return
    # built and loaded, it drives the example's closed loop like the Python controller
    from casadi_cmpc.cli import export_controller
    from casadi_cmpc.codegen import load

    ctrl = export_controller(ex, controller, cache=cache, progress=False)
    build.result()  # make of libcmpc.so (raises what build raises)
    C = load(out, build_first=False)
    x0s = np.asarray(ex.info.get("run", {}).get("x0s", ex.x0s), dtype=float)
    x = xc = x0s.reshape(-1, ex.model.n)[0]
    rng = np.random.default_rng(0)
    for _ in range(12):
        r = ctrl.solve(x)
        u, code = C.step(xc)
        if "search_time" in r.stats:  # a set inversion: Python only
            break
        assert np.abs(u - r.u).max() <= 1e-6, (name, x, r.u, u, hex(code))
        if kind == "set_sequence":
            assert C.decode(code)["level"] == r.horizon
        w = rng.uniform(ex.model.W.lo, ex.model.W.hi) if ex.model.l else None
        x, xc = ex.model.step(x, r.u, w), C.model(xc, u, w)


@pytest.mark.skipif(not can_build(), reason="needs make and a C compiler")
def test_export_build_runs_the_example_program(tmp_path, capsys, cache):
    out = tmp_path / "c"
    assert main(["export", "cstr", "--out", str(out), "--cache", cache, "--build",
                 "--no-progress"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = [ln.split() for ln in lines if ln[:1].isdigit()]
    assert len(rows) == 30 and int(rows[0][1]) > 0 and int(rows[-1][1]) == 0
    # a non-empty directory is refused without --overwrite
    assert main(["export", "cstr", "--out", str(out), "--cache", cache]) == 2
    assert "--overwrite" in capsys.readouterr().err


def test_export_build_without_make_is_refused_before_computing(tmp_path, monkeypatch,
                                                               capsys):
    """``--build`` on a machine without make (or without a C compiler) stops at once with
    exit code 2 and names what is missing: no example is loaded, no controller built,
    nothing written."""
    from casadi_cmpc import cli

    calls = []

    def record(what):
        def f(*a, **k):
            calls.append(what)
            raise AssertionError(f"{what} called")
        return f

    _wait_for_builds()  # no background build may see the PATH set below
    monkeypatch.setattr(cli, "export_controller", record("export_controller"))
    monkeypatch.setattr(cli, "_controller", record("_controller"))
    monkeypatch.setattr(cm.models, "load", record("models.load"))
    monkeypatch.delenv("CC", raising=False)
    empty = tmp_path / "bin"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))  # neither make nor a compiler
    out = tmp_path / "c"
    assert main(["export", "cstr", "--out", str(out), "--build", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "'make'" in err and "C compiler" in err and "Nothing was computed" in err
    # make alone: the compiler is named
    (empty / "make").write_text("#!/bin/sh\nexit 0\n")
    (empty / "make").chmod(0o755)
    assert main(["export", "cstr", "--out", str(out), "--build", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "'make'" not in err and "a C compiler ('cc', 'gcc' or 'clang')" in err
    assert calls == [] and not out.exists()


def test_the_cache_files_are_small(cache):
    """The cached sequences store every box once (compressed): at most 48 bytes per box
    (its bounds and its control take 40 uncompressed) plus 64 kB, where copying the
    boxes into every K_i made E14's file 892 MB for 68 658 boxes."""
    from casadi_cmpc.cli import _cache_path
    from casadi_cmpc.control.linear_sets import SetSequence

    checked = 0
    for name in SEQUENCE_EXAMPLES:
        ex = cm.models.load(name)
        path = _cache_path(ex, ex.info["sequence"], cache)
        if not path.is_file() and name == "cannon":  # E8 at least (a few seconds)
            assert main(["run", name, "--steps", "1", "--no-progress", "--cache", cache]) == 0
        if not path.is_file():  # not computed in this session
            continue
        seq = SetSequence.load(path)
        n_boxes = sum(st["boxes"].shape[0] for st in seq.steps)
        assert n_boxes > 0
        assert path.stat().st_size <= 48 * n_boxes + 64_000, (name, path.stat().st_size)
        checked += 1
    assert checked >= 1


def test_a_start_in_no_set_ends_the_run_with_a_report(tmp_path, capsys):
    """At a coarse eps the sets may not reach x0: the run stops there (not controllable as
    far as the sets prove), says so, and the summary and figures are still written."""
    out = tmp_path / "out"
    assert main(["run", "khalil_affine_state", "--eps", "0.1", "--out", str(out),
                 "--no-progress", "--cache", str(tmp_path / "c")]) == 0
    text = capsys.readouterr().out
    assert "lies in no set of the sequence" in text and "Traceback" not in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs"][0]["stop_reason"] == "not_controllable"
    assert summary["runs"][0]["steps"] == 0
    assert (out / "sets.png").is_file()
