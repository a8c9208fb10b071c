"""``cmpc run`` / ``cmpc export`` of the structured examples of thesis chapter 6.

``khalil_affine_control`` (E12): T proven robustly invariant, quasi 2-step robust
controllable sets (Alg 6.7) and the quasi multi-step MPC (Alg 6.8); ``khalil_affine_state``
(E11): T proven, the affine-state controllable sets (Alg 6.4-6.6) and the one-step MPC along
them. The sets of each example are computed once per process (the CLI keeps them), so the
run, the extra closed loops and the export below share one computation.
"""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc import cli
from casadi_cmpc.cli import main
from casadi_cmpc.codegen.export import can_build
from casadi_cmpc.control.invariance import check_about
from casadi_cmpc.mpc.quasi import QuasiMultiStepMPC

STEPS = 40  # closed-loop steps per initial state: T is reached after about 16 (Fig 6.15)


def _run(args: list[str]) -> tuple[int, str]:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(args)
    return code, buf.getvalue()


@pytest.fixture(scope="module")
def e12_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("e12_run")
    code, out = _run(["run", "khalil_affine_control", "--out", str(d), "--steps", str(STEPS),
                      "--no-progress"])
    return code, out, d


def _pngs(d, summary):
    for f in summary["figures"]:
        assert (d / f).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_e12_run_proves_terminal_set_and_states_the_claims(e12_run):
    code, out, d = e12_run
    assert code == 0, out
    ex = cm.models.load("khalil_affine_control")
    assert "controller: QuasiMultiStepMPC" in out
    assert "terminal set proven robustly invariant under the local law" in out
    summary = json.loads((d / "summary.json").read_text())
    assert summary["total_violations"] == 0 and summary["robust"] is True
    seq = summary["sequence"]
    assert seq["pipeline"] == "quasi" and seq["quasi_steps"] == 2
    assert seq["terminal_certificate"] == "proved" and seq["status"] == "converged"
    assert seq["converged_at"] == seq["steps"] >= 2
    # the areas of P_0 .. P_M grow (the recursion stops when they no longer do)
    assert np.all(np.diff(seq["areas"][:-1]) > 0)
    assert seq["W"] == [[-0.01, 0.01], [0.9, 1.0]]
    # both initial states of Fig 6.15 lie in a set
    assert all(isinstance(lv, int) and lv >= 1 for lv in seq["levels_x0"])
    report = (d / "report.txt").read_text()
    foot = report[report.index("What the certificates prove"):]
    assert "proved robustly invariant under the local law" in foot
    assert "for all w in W = [[-0.01, 0.9], [0.01, 1.0]]" in foot
    assert "within 2 steps" in foot and "model 'khalil_affine_control'" in foot
    assert "zonotope evolution with outward rounding" in foot
    for r, x0 in zip(summary["runs"], ex.x0s, strict=True):
        np.testing.assert_allclose(r["x0"], x0)
        assert r["violations"] == {"state": 0, "input": 0}
        assert r["steps"] == STEPS and set(r["certificates"]) <= {"verified", "local_law"}
        # T reached and kept: the final state is in T
        assert bool(ex.terminal.contains(np.asarray(r["final_state"])))
    assert {"sets.png", "phase_plane.png", "run1.png", "run2.png"} <= set(summary["figures"])
    _pngs(d, summary)


def test_e12_closed_loops_have_no_violation_under_many_disturbances(e12_run):
    """The controller of the run (sets reused): every disturbance sequence drawn (uniform
    and at the vertices of W) keeps X and U, and every step outside T is proven."""
    assert e12_run[0] == 0
    ex = cm.models.load("khalil_affine_control")
    ctrl, seqs = cli._quasi_controller(ex, progress=False)
    assert isinstance(ctrl, QuasiMultiStepMPC) and seqs.info["terminal_certificate"] == "proved"
    T = ex.terminal
    for x0 in ex.x0s:
        for disturbance in ("uniform", "vertices"):
            for seed in range(3):
                ctrl.reset()
                tr = cm.simulate(ex.model, ctrl, x0, 30, disturbance=disturbance, seed=seed)
                assert tr.stop_reason == "steps"
                assert tr.violations["state"] == 0 and tr.violations["input"] == 0
                for c, x in zip(tr.certificate, tr.x[:-1], strict=True):
                    assert c == "verified" or (c == "local_law" and T.contains(x))
                assert bool(T.contains(tr.x[-1]))


def test_e12_more_seeds_through_the_cli(e12_run, tmp_path):
    assert e12_run[0] == 0
    for seed in (1, 2):
        code, out = _run(["run", "khalil_affine_control", "--steps", "25", "--seed",
                          str(seed), "--no-progress", "--out", str(tmp_path / str(seed))])
        assert code == 0 and "sets reused" in out
        s = json.loads((tmp_path / str(seed) / "summary.json").read_text())
        assert s["total_violations"] == 0 and s["seed"] == seed


def test_e12_export_writes_the_quasi_controller_and_it_compiles(e12_run, tmp_path):
    assert e12_run[0] == 0
    out = tmp_path / "c"
    code, text = _run(["export", "khalil_affine_control", "--out", str(out),
                       "--no-progress"])
    assert code == 0, text
    assert "(quasi, solver sqp)" in text
    hdr = (out / "cmpc_controller.h").read_text()
    assert '#define CMPC_KIND "quasi"' in hdr and "#define CMPC_NX 2" in hdr
    assert "int cmpc_step(const double *x, double *u);" in hdr
    if not can_build():
        pytest.skip("building the export needs make and a C compiler")
    from casadi_cmpc.codegen import load
    from casadi_cmpc.codegen.export import build

    build(out)
    C = load(out)
    ex = cm.models.load("khalil_affine_control")
    model, T = ex.model, ex.terminal
    for k, x0 in enumerate(ex.x0s):
        C.reset()
        rng = np.random.default_rng(k)
        x = x0.copy()
        for _ in range(30):
            u, c = C.step(x)
            d = C.decode(c)
            assert c >= 0 and not d["unverified"]
            assert np.all(model.U.contains(u))
            x = C.model(x, u, rng.uniform(model.W.lo, model.W.hi))
            assert np.all(model.X.contains(x))
        assert bool(T.contains(x))


def test_contractive_controller_is_still_available(tmp_path):
    code, out = _run(["run", "khalil_affine_control", "--controller", "contractive",
                      "--steps", "2", "--no-progress"])
    assert code == 0 and "controller: ContractiveMPC" in out


def test_bad_eps_is_refused(capsys):
    with pytest.raises(SystemExit):
        main(["run", "khalil_affine_control", "--eps", "-0.1"])
    # the contractive MPC has no resolution to set
    assert main(["run", "khalil_affine_control", "--controller", "contractive", "--eps",
                 "0.05", "--no-progress"]) == 2
    assert "--eps" in capsys.readouterr().err
    assert main(["export", "khalil_affine_control", "--out", "unused", "--eps", "0"]) == 2
    assert "--eps" in capsys.readouterr().err


def test_affine_state_sets_have_no_c_export_and_say_so(capsys, tmp_path):
    """Refused before anything is computed (the C export reads proving boxes)."""
    out = tmp_path / "c"
    assert main(["export", "khalil_affine_state", "--controller", "sequence", "--out",
                 str(out), "--no-progress"]) == 2
    assert "--controller contractive" in capsys.readouterr().err and not out.exists()


def test_structured_pipelines_refuse_checkpoint(capsys, tmp_path):
    assert main(["run", "khalil_affine_control", "--checkpoint", str(tmp_path / "c.npz"),
                 "--no-progress"]) == 2
    assert "general controllable sets" in capsys.readouterr().err


def test_examples_record_their_proven_terminal_sets():
    for name in ("khalil_affine_state", "khalil_affine_control"):
        ex = cm.models.load(name)
        ch = ex.info["choices"]
        assert "proven robustly invariant" in ch["terminal_status"]
        assert ch["terminal_certificate"]["method"] == "certify_invariant"
        cert = cm.certify_invariant(ex.model, ex.terminal, ex.local_law,
                                    ch["terminal_certificate"]["eps"], progress=False)
        assert cert.proved is True
        # about this model, this set, the whole W and the example's law
        assert check_about(cert, ex.model, ex.terminal, ex.model.W, ex.local_law) is None


# ------------------------------------------------------------------------- E11
@pytest.fixture(scope="module")
def e11_run(tmp_path_factory):
    """E11's pipeline with the recursion stopped as soon as the initial state lies in a set
    (``until_x0s``: 13 of the 23 sets at eps = 0.05; the run to convergence takes about two
    minutes and is left to ``cmpc run khalil_affine_state``)."""
    d = tmp_path_factory.mktemp("e11_run")
    load = cm.models.load

    def quick(name):
        ex = load(name)
        if name == "khalil_affine_state":
            ex.info["affine_state"] = dict(ex.info["affine_state"], until_x0s=True)
        return ex

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cm.models, "load", quick)
        code, out = _run(["run", "khalil_affine_state", "--out", str(d), "--steps", "40",
                          "--no-progress"])
    return code, out, d


def _check_e11(code, out, d, status="until"):
    assert code == 0, out
    assert "controller: SetSequenceMPC" in out and "affine-state controllable sets" in out
    summary = json.loads((d / "summary.json").read_text())
    assert summary["total_violations"] == 0 and summary["robust"] is True
    seq = summary["sequence"]
    assert seq["pipeline"] == "affine_state" and "affine state" in seq["method"]
    assert seq["terminal_certificate"] == "proved" and seq["status"] == status
    assert isinstance(seq["levels_x0"][0], int) and seq["levels_x0"][0] >= 1
    report = (d / "report.txt").read_text()
    foot = report[report.index("What the certificates prove"):]
    assert "for all w in W = [[-0.01], [0.01]]" in foot
    assert "proved invariant under the local law" in foot
    r = summary["runs"][0]
    np.testing.assert_allclose(r["x0"], [-0.5, -0.8])
    assert r["violations"] == {"state": 0, "input": 0}
    assert set(r["certificates"]) <= {"verified", "local_law"}
    assert r["certificates"].get("verified", 0) >= 1
    ex = cm.models.load("khalil_affine_state")
    assert bool(ex.terminal.contains(np.asarray(r["final_state"])))
    assert "sets.png" in summary["figures"]
    _pngs(d, summary)


def test_e11_run_proves_terminal_set_and_states_the_claims(e11_run):
    _check_e11(*e11_run, status="until")
