"""C export: the compiled controller agrees with the Python one; bad input is refused."""

from __future__ import annotations

import shutil
import subprocess

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.codegen import build, export_c, load
from casadi_cmpc.codegen.export import ExportError, can_build, check_build_tools
from casadi_cmpc.mpc.sequence import SetSequenceMPC

needs_cc = pytest.mark.skipif(not can_build(),
                              reason="building the export needs make and a C compiler")


@pytest.fixture(scope="module")
def e9(tmp_path_factory):
    """E9's robust one-step controller (solver sqp) exported; its sequence (the example's
    settings) comes from the session's cache of set sequences, shared with the CLI tests
    (computed by whichever module needs it first)."""
    from casadi_cmpc.cli import export_controller

    ex = cm.models.load("cannon_robust")
    cache = tmp_path_factory.getbasetemp() / "cmpc_sequences"
    cache.mkdir(exist_ok=True)
    ctrl = export_controller(ex, cache=str(cache), progress=False)
    assert isinstance(ctrl, SetSequenceMPC) and ctrl.solver == "sqp" and ctrl.robust
    seq = ctrl.seq
    assert seq.status == "converged" and seq.info["eps"] == ex.info["sequence"]["eps"]
    d = tmp_path_factory.mktemp("e9")
    info = ctrl.export_c(d / "c", x0=[1.75, -1.6], steps=25)
    return ex, seq, ctrl, info


@needs_cc
def test_e9_compiled_agrees_with_python_on_1000_states(e9):
    ex, seq, ctrl, info = e9
    C = load(info.directory)
    B = np.concatenate([s["boxes"] for s in seq.steps])
    rng = np.random.default_rng(7)
    pts = rng.uniform(B[:, :, 0], B[:, :, 1])[rng.choice(len(B), 1000)]
    pts[:50] = rng.uniform(ex.terminal.bounding_box().lo, ex.terminal.bounding_box().hi,
                           (50, 2))
    levels = set()
    for x in pts:
        r = ctrl.solve(x)
        u, code = C.step(x)
        d = C.decode(code)
        assert d["level"] == r.horizon == C.level(x) == seq.level(x)
        levels.add(d["level"])
        assert np.abs(u - r.u).max() <= 1e-6
        # the applied control is certified by Python: the successor lies in K_{i-1}
        if r.horizon:
            assert r.certificate.label == "verified"
    assert len(levels) > 20 and 0 in levels
    # a state outside every set, and a NaN state
    u, code = C.step([5.0, 5.0])
    assert code == -1 and np.isnan(u).all() and ctrl.solve([5.0, 5.0]).horizon is None
    assert C.step([np.nan, 0.0])[1] == -2


@needs_cc
def test_e9_closed_loop_matches_python_step_by_step(e9):
    ex, seq, ctrl, info = e9
    C = load(info.directory)
    rng = np.random.default_rng(3)
    x = xc = np.array([1.75, -1.6])
    for _ in range(40):
        w = rng.uniform(ex.model.W.lo, ex.model.W.hi)
        r = ctrl.solve(x)
        u, code = C.step(xc)
        assert C.decode(code)["level"] == r.horizon
        assert np.abs(u - r.u).max() <= 1e-6
        x = ex.model.step(x, r.u, w)
        xc = C.model(xc, u, w)
        assert np.abs(x - xc).max() <= 1e-9 * (1 + np.abs(x).max())
    assert seq.level(x) == 0  # the loop reached the terminal set


@needs_cc
def test_generated_code_is_strict_c99_standalone_and_the_example_runs(e9):
    *_, info = e9
    d = info.directory
    mk = (d / "Makefile").read_text()
    assert "-std=c99 -Wall -Wextra -Werror -O2" in mk
    assert "CC ?= cc" in mk and "\t$(CC) $(CFLAGS)" in mk
    subprocess.run(["make", "-C", str(d)], check=True, capture_output=True)
    ldd = subprocess.run(["ldd", str(d / "libcmpc.so")], capture_output=True, text=True)
    libs = [ln.split()[0] for ln in ldd.stdout.splitlines() if ln.strip()]
    assert all(any(k in lib for k in ("linux-vdso", "libc.so", "libm.so", "ld-linux"))
               for lib in libs), libs
    out = subprocess.run([str(d / "example"), "25"], capture_output=True, text=True,
                         check=True).stdout.splitlines()
    rows = [ln.split() for ln in out[1:]]
    assert len(rows) == 25
    levels = [int(r[1]) for r in rows]
    assert levels[0] > 0 and levels[-1] == 0
    assert all(b <= a - 1 or b == 0 for a, b in zip(levels[:-1], levels[1:], strict=True)
               if a > 0)


@pytest.fixture(scope="module")
def e8(tmp_path_factory):
    ex = cm.models.load("cannon")
    kw = dict(ex.info["mpc"])
    kw["solver"] = "sqp"
    kw["mode"] = "receding"  # what the C controller does: solve at every step
    ctrl = cm.ContractiveMPC(ex.model, **kw)
    d = tmp_path_factory.mktemp("e8")
    return ex, ctrl, ctrl.export_c(d / "c", x0=[1.9, -1.5])


@needs_cc
def test_e8_horizon_10_closed_loop_matches_python(e8):
    ex, ctrl, info = e8
    C = load(info.directory)
    ctrl.reset()
    x = xc = np.array([1.9, -1.5])
    for _ in range(40):
        r = ctrl.solve(x)
        u, code = C.step(xc)
        assert np.abs(u - r.u).max() <= 1e-6
        assert C.decode(code)["level"] == (0 if r.mode == "local_law" else 1)
        x = ex.model.step(x, r.u)
        xc = C.model(xc, u)
    assert np.abs(x).max() < 0.1


@needs_cc
def test_e8_states_solved_by_the_local_solver_agree(e8):
    """From a cold start at each state, wherever Python's local solver gives the verified
    sequence (no set inversion), the C controller returns the same move."""
    ex, ctrl, info = e8
    C = load(info.directory)
    rng = np.random.default_rng(11)
    n = 0
    for p in rng.uniform(ex.model.X.lo, ex.model.X.hi, (1000, 2)):
        ctrl.reset()
        C.reset()
        r = ctrl.solve(p)
        u, code = C.step(p)
        if r.certificate.label == "local_law" or (
                r.certificate.label == "verified" and "search_time" not in r.stats):
            n += 1
            assert np.abs(u - r.u).max() <= 1e-6, (p, r.u, u, hex(code))
    assert n >= 800


def test_bad_input_is_refused(e9, tmp_path):
    ex, seq, ctrl, info = e9
    with pytest.raises(ExportError, match="not empty"):
        export_c(ctrl, info.directory)
    with pytest.raises(ValueError, match="solver"):
        export_c(ctrl, tmp_path / "a", solver="qpoases")
    with pytest.raises(TypeError, match="SetSequenceMPC or a ContractiveMPC"):
        export_c(object(), tmp_path / "b")
    # a sequence with the terminal set only: the sets were never computed
    from casadi_cmpc.control.linear_sets import SetSequence
    bare = SetSequence(sets=[seq.sets[0]], converged_at=None)
    with pytest.raises((ExportError, TypeError)):
        export_c(SetSequenceMPC(ex.model, bare, local_law=ex.local_law, solver="sqp"),
                 tmp_path / "c")
    # a contractive MPC without a fixed horizon
    with pytest.raises(ExportError, match="fixed horizon"):
        export_c(cm.ContractiveMPC(cm.models.load("cannon").model, solver="sqp",
                                   mode="receding"),
                 tmp_path / "d")
    # overwrite=True replaces the contents
    (tmp_path / "e").mkdir()
    (tmp_path / "e" / "old.txt").write_text("x")
    info2 = export_c(ctrl, tmp_path / "e", overwrite=True)
    assert not (tmp_path / "e" / "old.txt").exists() and (info2.directory / "Makefile").exists()


class _Sq(ca.Callback):
    def __init__(self):
        ca.Callback.__init__(self)
        self.construct("sq", {})

    def get_n_in(self):
        return 1

    def get_n_out(self):
        return 1

    def eval(self, arg):
        return [arg[0] ** 2]


def test_an_operation_the_generator_cannot_emit_is_refused(tmp_path):
    from casadi_cmpc.codegen.export import _generate

    x = ca.MX.sym("x")
    F = ca.Function("F", [x], [_Sq()(x) + x])
    with pytest.raises(ExportError, match="cannot generate C for 'F'"):
        _generate(tmp_path, [F])


@needs_cc
def test_terminal_membership_in_c_is_exact_on_facets(e9):
    """Points on the facets of T and one or two ulps off them: the C look-up says level 0
    exactly when the point lies in T in exact rational arithmetic (a plain floating-point
    sum, or numpy's, can put a point 1e-16 outside T inside it)."""
    from fractions import Fraction

    ex, seq, ctrl, info = e9
    C = load(info.directory)
    A, b = ex.terminal.A, ex.terminal.b
    rng = np.random.default_rng(21)
    bb = ex.terminal.bounding_box()
    n_in = n_out = 0
    for _ in range(400):
        k = rng.integers(len(b))
        x = rng.uniform(bb.lo, bb.hi)
        x = x - (A[k] @ x - b[k]) / (A[k] @ A[k]) * A[k]  # onto facet k (rounded)
        for _ in range(rng.integers(0, 3)):
            x = np.nextafter(x, x + rng.choice([-1.0, 1.0], 2))
        inside = all(sum(Fraction(a) * Fraction(v) for a, v in zip(A[r], x, strict=True))
                     <= Fraction(b[r]) for r in range(len(b)))
        assert (C.level(x) == 0) == inside, x
        n_in += inside
        n_out += not inside
    assert n_in > 50 and n_out > 50


def _executable(d, name):
    """An executable ``d/name`` that does nothing (a stand-in tool on a test PATH)."""
    f = d / name
    f.write_text("#!/bin/sh\nexit 0\n")
    f.chmod(0o755)
    return f


@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
def test_the_makefile_compiles_with_cc_unless_told_otherwise(e8, monkeypatch):
    """The Makefile calls $(CC): cc by default (what the README says), another compiler
    with make CC=... or the environment's CC (read from make's dry run)."""
    *_, info = e8
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.delenv("MAKEFLAGS", raising=False)

    def compilers(*extra):
        res = subprocess.run(["make", "-n", "-B", "-C", str(info.directory), *extra],
                             capture_output=True, text=True, check=True)
        return {ln.split()[0] for ln in res.stdout.splitlines()
                if "-std=c99" in ln and not ln.startswith("make")}

    assert compilers() == {"cc"}
    assert compilers("CC=gcc") == {"gcc"}
    monkeypatch.setenv("CC", "clang")
    assert compilers() == {"clang"}


def test_build_tools_are_checked_and_named(tmp_path, monkeypatch):
    """check_build_tools names every missing tool; build() refuses before running make."""
    empty = tmp_path / "empty"
    empty.mkdir()
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", str(empty))
    with pytest.raises(ExportError, match=r"'make' and a C compiler .* not installed"):
        check_build_tools()
    only_make = tmp_path / "only_make"
    only_make.mkdir()
    _executable(only_make, "make")
    monkeypatch.setenv("PATH", str(only_make))
    with pytest.raises(ExportError, match=r"^a C compiler \('cc', 'gcc' or 'clang'\) is not"):
        check_build_tools()
    _executable(only_make, "gcc")
    assert check_build_tools() == "gcc"  # no cc: the next compiler found
    _executable(only_make, "cc")
    assert check_build_tools() == "cc"
    monkeypatch.setenv("CC", "my-cc -O1")
    with pytest.raises(ExportError, match=r"the C compiler 'my-cc -O1' \(from \$CC\)"):
        check_build_tools()
    _executable(only_make, "my-cc")
    assert check_build_tools() == "my-cc -O1"
    assert check_build_tools(cc="gcc") == "gcc"
    # build() checks first: the stand-in make would have 'built' nothing either way, but
    # without make on PATH it is refused with the tools named, and nothing is written
    (tmp_path / "exp").mkdir()
    (tmp_path / "exp" / "Makefile").write_text("all:\n")
    monkeypatch.setenv("PATH", str(empty))
    with pytest.raises(ExportError, match="'make'"):
        build(tmp_path / "exp")
    assert sorted(p.name for p in (tmp_path / "exp").iterdir()) == ["Makefile"]
