"""The horizon search of ContractiveMPC (Alg 4.5) reports, at every outcome, only what was
computed at the horizon it reports: ``u_seq`` of shape (horizon, m), ``x_pred`` its
prediction, the statistics of that horizon and a label that follows the proofs."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.mpc.contractive import ContractiveMPC


class _NaNSolver:
    """Stands in for the NLP solver of one horizon: it returns a non-finite point, as
    IPOPT does when the model overflows along its iterates."""

    def __init__(self, n_z: int) -> None:
        self.n_z = n_z
        self.calls = 0

    def __call__(self, **kw):
        self.calls += 1
        nan = np.full(self.n_z, np.nan)
        return {"x": nan, "f": np.nan, "g": np.nan, "lam_x": nan, "lam_g": np.nan}

    def stats(self) -> dict:
        return {"return_status": "Invalid_Number_Detected", "success": False,
                "iter_count": 0}


def _exp_model(m: int, gain: float = 10.0) -> cm.Model:
    """x+ = exp(gain x) - 1 + u1 + 1e-3 (u2 + ...): from x = 0.5 every horizon is
    infeasible (x(1) > 1), and IPOPT overflows at the longer horizons."""
    x = ca.SX.sym("x")
    u = ca.SX.sym("u", m)
    f = ca.exp(gain * x) - 1 + u[0]
    for j in range(1, m):
        f = f + 1e-3 * u[j]
    return cm.Model(x=x, u=u, f=f, X=cm.Box([-1], [1]), U=cm.Box(-np.ones(m), np.ones(m)))


def _assert_consistent(model: cm.Model, ctrl: ContractiveMPC, r) -> None:
    """Shapes, U, the prediction, the statistics and the label of one result."""
    N, m, n = r.horizon, model.m, model.n
    assert r.u_seq.shape == (N, m)
    assert r.x_pred.shape == (N + 1, n)
    np.testing.assert_array_equal(r.u, r.u_seq[0])
    np.testing.assert_array_equal(r.x_pred[0], r.x)
    assert np.all((r.u_seq >= model.U.lo) & (r.u_seq <= model.U.hi))
    tried = r.stats["horizons_tried"]
    assert tried == list(range(ctrl.horizon_min, N + 1))
    proofs = r.certificate.details.get("proofs", [])
    assert [p["horizon"] for p in proofs] == sorted({p["horizon"] for p in proofs})
    assert all(p["horizon"] <= N for p in proofs)
    label = r.certificate.label
    if label == "verified":
        assert r.status == cm.Status.PROVED and r.certificate.proved is True
        x = np.asarray(r.x, dtype=float)
        for i, u in enumerate(r.u_seq):  # the verified prediction is the simulation
            x = model.step(x, u)
            np.testing.assert_allclose(r.x_pred[i + 1], x, rtol=1e-9, atol=1e-12)
        assert np.all((r.x_pred[1:] >= model.X.lo) & (r.x_pred[1:] <= model.X.hi))
    elif label == "proved_infeasible":
        assert r.status == cm.Status.DISPROVED and r.certificate.proved is False
        assert [p["horizon"] for p in proofs] == tried
        assert all(p["result"] == "infeasible" for p in proofs)
    else:
        assert label in ("unverified", "undecided")
        assert r.certificate.proved is None
        assert all(p["result"] == "infeasible" for p in proofs[:-1])
        if label == "undecided":
            assert proofs[-1]["horizon"] == N and proofs[-1]["result"] == "undecided"
            assert r.status in (cm.Status.UNDECIDED, cm.Status.BUDGET)


@pytest.mark.parametrize("m", [1, 2, 3])
def test_search_ending_in_proofs_reports_the_last_horizon(m):
    model = _exp_model(m)
    ctrl = ContractiveMPC(model, horizon=None, horizon_min=1, horizon_max=4)
    r = ctrl.solve([0.5])
    assert r.certificate.label == "proved_infeasible"
    assert r.horizon == 4
    _assert_consistent(model, ctrl, r)
    # the prediction of the reported sequence (it leaves X at once and overflows)
    x = np.array([0.5])
    for i, u in enumerate(r.u_seq):
        x = model.step(x, u)
        np.testing.assert_allclose(r.x_pred[i + 1], x, rtol=1e-12)
    # a second solve (warm starts per horizon) is consistent too
    _assert_consistent(model, ctrl, ctrl.solve([0.4]))


def _build(m: int, kind: str, nmax: int, fail: set[int]) -> tuple[cm.Model, ContractiveMPC,
                                                                  np.ndarray]:
    """A model of the given kind with m inputs, its controller (horizons 1..nmax) whose
    local solver returns NaN at the horizons in ``fail``, and a start state.

    ``infeasible``: x1 doubles and more, every horizon is infeasible from x1 = 0.9;
    ``feasible``/``never``: stable and controllable, feasible at every horizon;
    ``thin``: one state, the admissible u1 form an interval of width about 1e-4 at
    horizon 1 (with a search budget of 2 boxes the search may stay undecided).
    """
    rng = np.random.default_rng(m * 100 + nmax)
    B = rng.uniform(0.2, 1.0, (2, m)) * np.sign(rng.standard_normal((2, m)))
    u = ca.SX.sym("u", m)
    if kind == "thin":
        x = ca.SX.sym("x")
        f = x + 0.1 * u[0]
        for j in range(1, m):
            f = f + 1e-5 * u[j]
        model = cm.Model(x=x, u=u, f=f, X=cm.Box([-1], [1]),
                         U=cm.Box(-np.ones(m), np.ones(m)))
        x0 = np.array([0.999])
    else:
        x = ca.SX.sym("x", 2)
        if kind == "infeasible":
            f = ca.vertcat(2.5 * x[0] + 0.1 * ca.mtimes(ca.DM(B[:1]), u),
                           0.5 * x[1] + ca.mtimes(ca.DM(B[1:]), u))
            x0 = np.array([0.9, -0.3])
        else:
            f = 0.6 * x + 0.1 * ca.mtimes(ca.DM(B), u)
            x0 = np.array([0.7, -0.5])
        model = cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -1], [1, 1]),
                         U=cm.Box(-np.ones(m), np.ones(m)))
    ctrl = ContractiveMPC(model, horizon=None, horizon_min=1, horizon_max=nmax,
                          alpha=0.9, search="never" if kind == "never" else "auto",
                          search_max_boxes=2 if kind == "thin" else 20000)
    for N in fail:
        h = ctrl._get(N)
        h.solver = _NaNSolver(h.n_z)
    return model, ctrl, x0


@settings(max_examples=30)
@given(m=st.integers(1, 3), nmax=st.integers(1, 4),
       kind=st.sampled_from(["infeasible", "never", "feasible", "thin"]),
       fail=st.sets(st.integers(1, 4)), last_fails=st.booleans())
def test_every_outcome_of_the_search_belongs_to_its_horizon(m, nmax, kind, fail, last_fails):
    fail = {N for N in fail if N < nmax} | ({nmax} if last_fails else set())
    if kind == "never":  # search="never" skips failing horizons: let the last one work
        fail.discard(nmax)
    model, ctrl, x0 = _build(m, kind, nmax, fail)
    reached = 0
    for x in (x0, 0.99 * x0):
        r = ctrl.solve(x)
        reached = max(reached, r.horizon)
        _assert_consistent(model, ctrl, r)
        if kind == "infeasible":
            assert r.certificate.label == "proved_infeasible" and r.horizon == nmax
        if kind in ("feasible", "never"):
            assert r.certificate.label == "verified"
        if r.certificate.label == "verified" and r.horizon in fail:
            # found by the search at a horizon whose local solver failed
            assert r.certificate.details.get("proofs")
    for N in fail:  # the failing horizons that the search reached were tried
        assert (ctrl._get(N).solver.calls >= 1) == (N <= reached)


def test_search_never_with_a_failing_last_horizon_falls_back_at_that_horizon():
    model, ctrl, x0 = _build(2, "infeasible", 3, {3})
    ctrl.search = "never"
    r = ctrl.solve(x0)
    assert r.horizon == 3 and r.certificate.label == "unverified"
    assert r.status == cm.Status.NUMERICAL  # no sequence at horizon 3 and no search
    _assert_consistent(model, ctrl, r)
    np.testing.assert_array_equal(r.u_seq, np.zeros((3, 2)))  # u_ref at horizon 3


def _double_integrator() -> cm.Model:
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    return cm.Model(x=x, u=u, f=ca.vertcat(x[0] + x[1], x[1] + u),
                    X=cm.Box([-2, -2], [2, 2]), U=cm.Box([-0.5], [0.5]))


def _undecided(self, x, r0, N, stats):  # a search that never decides (its budget is out)
    return None, {"horizon": N, "result": "undecided", "how": "budget reached",
                  "boxes": 1, "budget": True}


def test_an_undecided_horizon_does_not_stop_the_search(monkeypatch):
    """From x = (1, 0) with alpha = 0.4 horizons 1 and 2 are infeasible and horizon 3
    feasible: when the searches at 1 and 2 do not decide, the search goes on and verifies
    horizon 3."""
    model = _double_integrator()
    ctrl = ContractiveMPC(model, horizon=None, alpha=0.4, norm="inf", horizon_min=1,
                          horizon_max=4)
    real = ctrl.solve([1.0, 0.0])  # with the real searches: 1 and 2 proven infeasible
    assert real.horizon == 3 and real.certificate.label == "verified"
    assert [p["result"] for p in real.certificate.details["proofs"]] == ["infeasible"] * 2
    monkeypatch.setattr(ContractiveMPC, "_prove", _undecided)
    ctrl.reset()
    r = ctrl.solve([1.0, 0.0])
    assert r.horizon == 3 and r.certificate.label == "verified"
    assert r.stats["horizons_tried"] == [1, 2, 3]
    xN = r.x_pred[-1]
    assert np.abs(xN).max() <= 0.4 * 1.0 + 1e-9


def test_infeasible_is_claimed_only_when_every_horizon_is_proven(monkeypatch):
    model = _double_integrator()
    ctrl = ContractiveMPC(model, horizon=None, alpha=0.4, norm="inf", horizon_min=1,
                          horizon_max=2)
    assert ctrl.solve([1.0, 0.0]).certificate.label == "proved_infeasible"
    real = ContractiveMPC._prove

    def second_undecided(self, x, r0, N, stats):
        return _undecided(self, x, r0, N, stats) if N == 2 else real(self, x, r0, N, stats)

    monkeypatch.setattr(ContractiveMPC, "_prove", second_undecided)
    ctrl.reset()
    r = ctrl.solve([1.0, 0.0])
    assert r.certificate.label == "undecided" and r.certificate.proved is None
    assert r.horizon == 2 and r.u_seq.shape == (2, 1)
    assert "[1] proven infeasible" in r.certificate.reason
    monkeypatch.setattr(ContractiveMPC, "_prove", _undecided)
    ctrl.reset()
    r = ctrl.solve([1.0, 0.0])
    assert r.certificate.label == "undecided"
    assert r.stats["horizons_tried"] == [1, 2]
