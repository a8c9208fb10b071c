"""Summaries say what was proven: solve times over solver steps only, levels of a set
sequence named as levels, footnotes that match the controller, statuses by name, volumes
of the proven part, progress bars that end at the steps done."""

from __future__ import annotations

import json
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest
import tqdm.auto

import casadi_cmpc as cm
from casadi_cmpc.cli import _report, main
from casadi_cmpc.mpc.simulate import _summary_lines
from casadi_cmpc.solvers.engine import Status
from casadi_cmpc.solvers.result import SetResult

W_HALF = 0.05  # disturbance bound of the scalar model


def scalar_model(w: bool = False) -> cm.Model:
    """x+ = x + u (+ w), X = [-1, 1], U = [-0.5, 0.5], W = [-0.05, 0.05]."""
    x = ca.SX.sym("x")
    u = ca.SX.sym("u")
    wv = ca.SX.sym("w") if w else None
    return cm.Model(x=x, u=u, w=wv, f=x + u + (wv if w else 0), X=cm.Box([-1], [1]),
                    U=cm.Box([-0.5], [0.5]),
                    W=cm.Box([-W_HALF], [W_HALF]) if w else None,
                    name="scalar_w" if w else "scalar")


T_SCALAR = cm.Polytope(np.array([[1.0], [-1.0]]), np.array([0.2, 0.2]))
LAW = np.array([[-1.0]])  # u = -x: f = w in T, u in U on T


@pytest.fixture(scope="module")
def scalar_seq():
    model = scalar_model()
    return model, cm.controllable_sets(model, T_SCALAR, 0.1, law=LAW, progress=False)


@pytest.fixture(scope="module")
def disturbed_seq():
    model = scalar_model(w=True)
    return model, cm.controllable_sets(model, T_SCALAR, 0.1, law=LAW, robust=True,
                                       progress=False)


def trajectory(modes, solve_time, horizon=None, level=None):
    K = len(modes)
    return cm.Trajectory(x=np.zeros((K + 1, 1)), u=np.zeros((K, 1)), w=np.zeros((K, 0)),
                         status=("ok",) * K, certificate=(None,) * K,
                         horizon=tuple(horizon or (None,) * K), solve_time=solve_time,
                         call_time=np.full(K, 1e-3), mode=tuple(modes),
                         level=tuple(level or ()))


# ------------------------------------------------------------ solve time and step kinds
def test_median_solve_time_is_over_the_solver_steps_only():
    # 7 local-law steps of 1 us, 3 solver steps of 0.2, 0.3 and 0.7 s, 1 queued move
    modes = ["local_law"] * 4 + ["mpc", "local_law", "mpc", "sequence"] + ["local_law"] * 2 \
        + ["mpc"]
    times = np.array([1e-6] * 4 + [0.2, 1e-6, 0.7, 1e-6, 1e-6, 1e-6, 0.3])
    traj = trajectory(modes, times)
    assert traj.step_kind[4] == "solver" and traj.step_kind[7] == "other"
    s = traj.summary()
    assert s["step_kinds"] == {"solver": 3, "local_law": 7, "other": 1}
    st = s["solve_time"]
    assert st["median"] == 0.3 and st["min"] == 0.2 and st["max"] == 0.7
    assert st["steps"] == 3 and st["total"] == pytest.approx(1.2)
    assert np.median(times) == 1e-6  # what the median over all steps would have said
    assert s["call_time"]["total"] == pytest.approx(11e-3)  # all steps, as measured
    lines = _summary_lines(s)
    assert lines[0] == ("steps: 11, of which 3 used the solver, 7 the local law (no solver), "
                        "1 neither (mode sequence: 1)")
    assert lines[1] == "solve time per solver step (3 steps): median 300 ms, max 700 ms"


def test_a_run_without_solver_step_has_no_solve_time():
    s = trajectory(["feedback"] * 3, np.full(3, 0.5)).summary()
    assert s["step_kinds"] == {"solver": 0, "local_law": 0, "other": 3}
    assert s["solve_time"]["median"] is None and s["solve_time"]["steps"] == 0
    assert s["call_time"]["median"] == 1e-3
    assert "no step used the solver" in _summary_lines(s)[1]


def test_simulate_classifies_steps_from_the_reported_mode():
    class Stub:
        """Solves (0.4 s reported) above |x| = 0.3, applies its local law below."""

        last_info = None

        def __call__(self, x):
            inside = abs(float(x[0])) <= 0.3
            self.last_info = {"mode": "local_law" if inside else "mpc",
                              "solve_time": 1e-7 if inside else 0.4,
                              "certificate": "local_law" if inside else "verified"}
            return np.array([-0.5 * float(x[0])])

    traj = cm.simulate(scalar_model(), Stub(), [0.9], 6)
    # x: 0.9, 0.45, 0.225, ...: two solver steps, then the local law
    assert traj.step_kind == ("solver",) * 2 + ("local_law",) * 4
    s = traj.summary()
    assert s["solve_time"]["median"] == 0.4 and s["solve_time"]["steps"] == 2


# ------------------------------------------------------------------- levels, not horizons
def test_set_sequence_run_records_levels_and_says_level(scalar_seq):
    model, seq = scalar_seq
    ctrl = cm.SetSequenceMPC(model, seq)
    traj = cm.simulate(model, ctrl, [0.95], 6)
    assert traj.level[0] == seq.level([0.95]) == 2
    assert traj.level == (2, 1, 0, 0, 0, 0)  # one level down per step, then T
    assert traj.horizon == traj.level  # the numbers the controller reports
    s = traj.summary()
    assert s["levels"] == {"0": 4, "1": 1, "2": 1} and s["horizons"] == {}
    text = "\n".join(_summary_lines(s))
    assert "level i(k) of the set sequence" in text and "i = 2..1: 1 step each" in text
    assert "horizon" not in text
    # a contractive-MPC-like controller reports horizons: no level
    plain = trajectory(["mpc"] * 3, np.ones(3), horizon=[2, 2, 3])
    ps = plain.summary()
    assert ps["levels"] == {} and ps["horizons"] == {"2": 2, "3": 1}
    assert "prediction horizons used: N = 2: 2 steps, N = 3: 1 step" in _summary_lines(ps)


def test_a_reported_level_key_is_recorded_and_saved(tmp_path):
    class Stub:
        last_info = None

        def __call__(self, x):
            self.last_info = {"mode": "mpc", "level": np.int64(3), "horizon": 1}
            return np.zeros(1)

    traj = cm.simulate(scalar_model(), Stub(), [0.5], 2)
    assert traj.level == (3, 3) and traj.horizon == (1, 1)
    assert traj.summary()["levels"] == {"3": 2} and traj.summary()["horizons"] == {}
    back = cm.Trajectory.load(traj.save(tmp_path / "t.json"))
    assert back.level == (3, 3) and back.summary() == traj.summary()


# ---------------------------------------------------------------------- report footnote
def _summary_of(traj, ctrl, seq=None):
    s = traj.summary()
    run = {"x0": traj.x[0], "final_state": traj.x[-1], "final_distance_to_reference": 0.0,
           "steps": traj.steps, "stop_reason": traj.stop_reason,
           "violations": {"state": 0, "input": 0}, "certificates": s["certificates"],
           "disturbance": traj.disturbance, **{k: s[k] for k in (
               "horizons", "levels", "step_kinds", "modes", "solve_time")}}
    out = {"controller": repr(ctrl), "note": "", "runs": [run]}
    if seq is not None:
        out["sequence"] = {"semantics": seq.info.get("semantics"),
                           "terminal_certificate": seq.info.get("terminal_certificate")}
    return out


@pytest.mark.parametrize("robust", [True, False])
def test_report_footnote_states_the_disturbances_the_controller_covers(disturbed_seq,
                                                                       robust):
    model, seq = disturbed_seq
    ctrl = cm.SetSequenceMPC(model, seq, robust=robust)
    traj = cm.simulate(model, ctrl, [0.95], 5, disturbance="uniform", seed=2)
    assert set(traj.certificate) == {"verified", "local_law"}
    ex = SimpleNamespace(name="scalar_w", info={}, model=model)
    text = _report(ex, ctrl, _summary_of(traj, ctrl, seq))
    foot = text[text.index("What the certificates prove"):]
    if robust:
        assert "robust controller" in foot and "for all w in W = [[-0.05], [0.05]]" in foot
        assert "nominal" not in foot
    else:
        assert "for all w" not in foot.split("sets K_i")[0]  # the controller's claim
        assert "'verified'" in foot and "for the nominal w = [0.0] only" in foot
        assert "not covered" in foot
    assert "'local_law': x(k) was in T = K_0" in foot


def test_report_footnote_without_disturbance_and_guarantee_line(scalar_seq):
    model, seq = scalar_seq
    ctrl = cm.SetSequenceMPC(model, seq)
    traj = cm.simulate(model, ctrl, [0.95], 4)
    ex = SimpleNamespace(name="scalar", info={}, model=model)
    text = _report(ex, ctrl, _summary_of(traj, ctrl, seq))
    assert "the model has no disturbance" in text and "for all w" not in text
    assert "f(x(k), u(k)) lies in K_(i-1)" in text
    guarantee = getattr(ctrl, "guarantee", None)
    if guarantee:  # printed under the controller line
        lines = text.splitlines()
        k = lines.index(f"controller: {repr(ctrl)}")
        assert lines[k + 1] == f"  guarantee: {guarantee}"


def test_cli_report_of_a_nominal_contractive_mpc(tmp_path, capsys):
    """khalil_affine_state: a model with w and a nominal contractive MPC."""
    assert main(["run", "khalil_affine_state", "--controller", "contractive", "--steps", "3",
                 "--no-progress", "--out",
                 str(tmp_path)]) == 0
    out = capsys.readouterr().out
    report = (tmp_path / "report.txt").read_text()
    summary = json.loads((tmp_path / "summary.json").read_text())
    foot = report[report.index("What the certificates prove"):]
    assert "for all w" not in foot and "nominal controller" in foot
    assert summary["robust"] is False
    ex = cm.models.load("khalil_affine_state")
    guarantee = getattr(cm.ContractiveMPC(ex.model, **ex.info["mpc"]), "guarantee", None)
    assert summary["guarantee"] == guarantee
    if guarantee:
        assert f"  guarantee: {guarantee}" in out and f"  guarantee: {guarantee}" in report
    r = summary["runs"][0]
    assert sum(r["step_kinds"].values()) == r["steps"] == 3
    assert r["solve_time"]["steps"] == r["step_kinds"]["solver"]


def test_cli_grimm_prints_the_solver_steps(tmp_path, capsys):
    assert main(["run", "grimm", "--steps", "5", "--no-progress", "--out",
                 str(tmp_path)]) == 0
    out = capsys.readouterr().out
    r = json.loads((tmp_path / "summary.json").read_text())["runs"][0]
    k = r["step_kinds"]
    assert sum(k.values()) == 5 and r["solve_time"]["steps"] == k["solver"] >= 1
    assert f"of which {k['solver']} used the solver" in out
    assert f"solve time per solver step ({k['solver']} step" in out
    assert "level" not in r or r["levels"] == {}
    assert "prediction horizons used: N = " in out


# ------------------------------------------------------------- statuses and set results
@pytest.mark.parametrize("status", list(Status))
def test_status_prints_its_name(status):
    assert str(status) == f"{status}" == status.name
    assert status == status.value and f"{status:d}" == str(status.value)


def _disk():
    p = ca.SX.sym("p", 2)
    return ca.Function("disk", [p], [p[0] ** 2 + p[1] ** 2])


def test_a_proved_result_without_inner_box_says_what_it_is():
    far = cm.sivia(_disk(), cm.Box([5, 5], [6, 6]), cm.Box([0], [1]), eps=0.5,
                   progress=False)
    assert far.status == Status.PROVED and far.n_inner == 0 and far.n_boundary == 0
    assert far.verdict.startswith("proved: the set is empty")
    assert "verdict='proved: the set is empty" in repr(far)
    # the circle |p| = 1 has no interior: nothing inside, undecided boxes remain
    thin = cm.sivia(_disk(), cm.Box([-2, -2], [2, 2]), cm.Box([1], [1]), eps=0.5,
                    progress=False)
    assert thin.status == Status.PROVED and thin.n_inner == 0 and thin.n_boundary > 0
    assert thin.verdict == (f"no box proven inside: {thin.n_boundary} undecided boxes "
                            "(narrower than eps)")
    assert "no box proven inside" in repr(thin) and "empty" not in repr(thin)
    # with inner boxes the repr is unchanged; the verdict counts them
    disk = cm.sivia(_disk(), cm.Box([-2, -2], [2, 2]), cm.Box([0], [1]), eps=0.5,
                    progress=False)
    assert "verdict" not in repr(disk)
    assert disk.verdict == f"{disk.n_inner} boxes proven inside, {disk.n_boundary} undecided"


def test_a_stopped_search_without_inner_box_is_not_called_empty():
    pav = cm.Paving(boundary=[cm.Box([0, 0], [1, 1])], domain=cm.Box([0, 0], [1, 1]))
    res = SetResult(status=Status.BUDGET, message="max_boxes", method="demo", nit=1,
                    n_boxes=1, elapsed=0.0, paving=pav)
    assert res.verdict == "no box proven inside: 1 undecided box (the search was stopped)"


def test_a_completed_one_step_search_without_inner_box_is_not_called_stopped():
    """A one-step search that ran to completion and proved nothing: UNDECIDED, and its
    undecided boxes are at eps, not left by a stop."""
    ex = cm.models.load("cannon_robust")
    K = cm.one_step_set(ex.model, ex.terminal, eps=5.0, robust=True, progress=False)
    assert K.status == Status.UNDECIDED and K.paving.n_inner == 0
    assert K.verdict.endswith("(narrower than eps)") and "stopped" not in K.verdict
    assert "search completed" in K.message


def test_volume_of_a_result_is_the_proven_one_by_default():
    res = cm.sivia(_disk(), cm.Box([-2, -2], [2, 2]), cm.Box([0], [1]), eps=0.1,
                   progress=False)
    inner, outer = res.volume("inner"), res.volume("outer")
    assert res.volume() == inner and res.area() == inner
    assert inner <= np.pi <= outer and inner < outer
    assert outer == pytest.approx(inner + res.volume("boundary"), rel=1e-12)


# ---------------------------------------------------------------------- progress bars
@pytest.fixture
def bars(monkeypatch):
    """The (total, n, desc) of every shown tqdm bar when it is first closed."""
    closed: list[tuple] = []

    class Recording(tqdm.auto.tqdm):
        def close(self):
            if not self.disable and not getattr(self, "_recorded", False):
                self._recorded = True
                closed.append((self.total, self.n, self.desc))
            super().close()

    monkeypatch.setattr(tqdm.auto, "tqdm", Recording)
    return closed


def _gain_model():
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * u)
    return cm.Model(x=x, u=u, f=f, X=cm.Box([-5, -5], [5, 5]), U=cm.Box([-50], [50]),
                    name="lin")


def test_simulate_bar_ends_at_the_steps_done(bars):
    model, K = _gain_model(), np.array([[-3.0, -3.5]])
    traj = cm.simulate(model, K, [1.0, 0.0], 200, progress=True,
                       stop_when=lambda x: np.abs(x).max() < 0.1)
    assert traj.stop_reason == "stop_when" and 0 < traj.steps < 200
    assert bars == [(traj.steps, traj.steps, "simulate lin")]
    bars.clear()
    full = cm.simulate(model, K, [1.0, 0.0], 7, progress=True)
    assert bars == [(7, 7, "simulate lin")] and full.steps == 7


def test_simulate_bar_keeps_its_total_when_interrupted(bars):
    def ctrl(x, k=[0]):  # noqa: B006 - a call counter
        k[0] += 1
        if k[0] == 4:
            raise KeyboardInterrupt
        return np.zeros(1)

    traj = cm.simulate(_gain_model(), ctrl, [1.0, 0.0], 10, progress=True)
    assert traj.interrupted and bars == [(10, 3, "simulate lin")]


def test_controllable_sets_bar_counts_the_steps_done(bars):
    model = scalar_model()
    seq = cm.controllable_sets(model, T_SCALAR, 0.1, law=LAW, max_steps=100, progress=True)
    assert seq.status == "converged" and len(seq) - 1 == 3
    rec = [v for v in bars if v[2] == "controllable sets"]
    assert len(rec) == 1
    total, n, _ = rec[0]
    assert n == len(seq) - 1 and total in (None, n)  # never 3/100


def test_summary_says_which_steps_were_proven():
    """Steps whose status is not PROVED are counted apart, by certificate label (a
    local-law step in a set whose invariance is not proven keeps the label local_law)."""
    K = 5
    traj = cm.Trajectory(x=np.zeros((K + 1, 1)), u=np.zeros((K, 1)), w=np.zeros((K, 0)),
                         status=("PROVED", "PROVED", "UNDECIDED", "PROVED", "ok"),
                         certificate=("verified", "local_law", "local_law", "local_law", None),
                         horizon=(None,) * K, solve_time=np.full(K, 1e-3),
                         call_time=np.full(K, 1e-3), mode=("mpc",) + ("local_law",) * 3
                         + ("feedback",), level=())
    s = traj.summary()
    assert s["certificates"] == {"local_law": 3, "none": 1, "verified": 1}
    assert s["proven_steps"] == 3
    assert s["not_proven"] == {"local_law": 1, "none": 1}
    assert _summary_lines(s)[-1] == ("proven steps: 3 of 5; not proven: local_law: 1, "
                                     "no certificate: 1")


def test_proven_steps_of_a_set_sequence_controller(scalar_seq):
    """The set-sequence controllers report a proven step with status "ok" and a
    certificate: every step of this run is proven (verified steps, then the local law in a
    T proven invariant); a plain gain reports no certificate: nothing is proven."""
    model, seq = scalar_seq
    ctrl = cm.SetSequenceMPC(model, seq, solver="sqp")
    traj = cm.simulate(model, ctrl, [0.9], 6, progress=False)
    s = traj.summary()
    assert set(traj.certificate) <= {"verified", "local_law"} and "verified" in traj.certificate
    assert s["proven_steps"] == 6 and s["not_proven"] == {}
    g = cm.simulate(model, np.array([[-1.0]]), [0.9], 3, progress=False).summary()
    assert g["proven_steps"] == 0 and g["not_proven"] == {"none": 3}


# ------------------------------------------------------- proofs about other disturbances
def test_steps_proven_for_the_nominal_w_only_do_not_count_when_another_w_is_applied(
        disturbed_seq, tmp_path):
    """A nominal controller proves its steps for the centre of W: run with the vertices of
    W none of them counts as proven (they count as proven for another w), run with the
    centre all do; a robust controller's steps count for every w of W. The guarantee of
    the controller travels with the run and with its file."""
    model, robust_seq = disturbed_seq
    nominal_seq = cm.controllable_sets(model, T_SCALAR, 0.1, law=LAW, progress=False)
    nominal = cm.SetSequenceMPC(model, nominal_seq, local_law=LAW)
    assert np.array_equal(nominal.proof_w, [[0.0, 0.0]])
    x0 = [0.9]
    off = cm.simulate(model, nominal, x0, 8, disturbance="vertices", progress=False)
    s = off.summary()
    assert s["proven_steps"] == 0 and s["proven_for_another_w"] == off.steps > 0
    assert off.proof_covers_w == (False,) * off.steps
    assert "for w = [0.0] only" in s["guarantee"]
    line = [ln for ln in _summary_lines(s) if ln.startswith("proven steps")][0]
    assert f"{off.steps} steps proven for other disturbances than the w applied" in line
    on = cm.simulate(model, nominal, x0, 8, disturbance="centre", progress=False).summary()
    assert on["proven_steps"] == 8 and on["proven_for_another_w"] == 0
    robust = cm.SetSequenceMPC(model, robust_seq, local_law=LAW, robust=True)
    assert np.array_equal(robust.proof_w, model.W.as_array())
    rob = cm.simulate(model, robust, x0, 8, disturbance="vertices", progress=False)
    assert rob.summary()["proven_steps"] == 8 and rob.proof_covers_w == (True,) * 8
    for suffix in (".json", ".npz"):
        back = cm.Trajectory.load(off.save(tmp_path / f"run{suffix}"))
        assert back.proof_covers_w == off.proof_covers_w and back.guarantee == off.guarantee
        assert back.summary()["proven_for_another_w"] == off.steps


def test_an_unproven_local_law_step_does_not_claim_the_robust_property(disturbed_seq):
    """A robust controller on a sequence whose T is proven for the nominal w only: in T
    its local-law step is not proven, and its claim says so instead of stating it."""
    model, _ = disturbed_seq
    nominal_seq = cm.controllable_sets(model, T_SCALAR, 0.1, law=LAW, progress=False)
    ctrl = cm.SetSequenceMPC(model, nominal_seq, local_law=LAW, robust=True)
    res = ctrl.solve([0.1])
    c = res.certificate
    assert c.label == "local_law" and c.proved is None
    assert "is NOT proven" in c.claim and "for all w in W" in c.claim


def test_one_step_control_refuses_anything_but_one_state():
    from casadi_cmpc.exceptions import DimensionError

    model = scalar_model()
    K = cm.one_step_set(model, T_SCALAR, 0.1, progress=False)
    assert K.control([0.1]) is not None and K.control([5.0]) is None
    for bad in (np.zeros((3, 1)), [0.1, 0.2]):
        with pytest.raises(DimensionError, match="one state of shape"):
            K.control(bad)


def test_certifying_for_a_w_outside_the_models_w_warns(disturbed_seq):
    model, _ = disturbed_seq
    with pytest.warns(cm.CmpcWarning, match="not inside the model's W"):
        cert = cm.certify_invariant(model, T_SCALAR, LAW, 0.05, W=cm.Box([0.5], [0.6]))
    assert "0.5" in cert.claim
