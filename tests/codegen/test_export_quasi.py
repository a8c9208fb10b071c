"""C export of the quasi multi-step controller (Alg 6.8): the compiled closed loops of E12
stay in X and U and reach T, its levels agree with Python's, its claims are labelled."""

from __future__ import annotations

import numpy as np
import pytest

from casadi_cmpc.codegen import load
from casadi_cmpc.codegen.export import can_build
from casadi_cmpc.mpc.quasi import QuasiMultiStepMPC
from casadi_cmpc.mpc.spec import QuasiSpec

needs_cc = pytest.mark.skipif(not can_build(),
                              reason="building the export needs make and a C compiler")


@pytest.fixture(scope="module")
def e12(tmp_path_factory, e12_quasi4_sets):
    # quasi 4-step sets at eps 0.05 until both initial states have a level: computed once per
    # session (tests/conftest.py), shared with tests/mpc/test_quasi_mpc.py
    ex, seqs = e12_quasi4_sets
    ctrl = QuasiMultiStepMPC(ex.model, seqs, P0=np.eye(2), Q=np.zeros((2, 2)), R=0.1,
                             local_law=ex.local_law, solver="sqp")
    d = tmp_path_factory.mktemp("quasi")
    info = ctrl.export_c(d / "c", x0=ex.x0s[0], steps=30)
    return ex, seqs, ctrl, info


def test_spec_and_files(e12):
    ex, seqs, ctrl, info = e12
    spec = ctrl.export_spec()
    assert isinstance(spec, QuasiSpec) and spec.kind == "quasi" and spec.steps == 4
    assert len(spec.polytopes) == len(seqs.polytopes) == len(spec.boxes) + 1
    assert info.kind == "quasi"
    assert info.tables["boxes"] == sum(r.n_inner for r in seqs.results)
    hdr = (info.directory / "cmpc_controller.h").read_text()
    assert "quasi 4-step" in hdr and "CMPC_FLAG_WITNESS" in hdr


@needs_cc
def test_compiled_levels_agree_with_python(e12):
    ex, seqs, ctrl, info = e12
    C = load(info.directory)
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1, 1, (400, 2))
    for x in pts:
        lv = ctrl.level(x)
        assert C.level(x) == (-1 if lv is None else lv)


@needs_cc
@pytest.mark.parametrize("k", [0, 1])
def test_compiled_closed_loops(e12, k):
    ex, seqs, ctrl, info = e12
    C = load(info.directory)
    model, T = ex.model, ex.terminal
    for seed in range(3):
        C.reset()
        rng = np.random.default_rng(seed)
        x = ex.x0s[k].copy()
        reached = False
        for _ in range(40):
            u, code = C.step(x)
            d = C.decode(code)
            assert code >= 0 and not d["unverified"]
            assert np.all(model.U.contains(u))
            reached |= d["level"] == 0
            w = rng.uniform(model.W.lo, model.W.hi)
            x = C.model(x, u, w)
            assert np.all(model.X.contains(x))
        assert reached and bool(T.contains(x))


@needs_cc
def test_compiled_refuses_bad_state(e12):
    ex, seqs, ctrl, info = e12
    C = load(info.directory)
    C.reset()
    u, code = C.step([np.nan, 0.0])
    assert code == -2 and np.isnan(u).all()
    x_far = np.array([0.999, 0.999])
    if ctrl.level(x_far) is None:
        u, code = C.step(x_far)
        assert code == -1 and np.isnan(u).all()
