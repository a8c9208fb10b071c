"""Every certifying entry point reads a validated model's enclosure of the true flow.

A validated ODE model's numeric map ``f`` is only the Taylor polynomial; its proofs must
come from :meth:`Model.interval_expr` / :meth:`Model.interval_map` (Taylor polynomial plus
the proven remainder). Each test below builds a validated model, then a copy whose
remainder parameters are widened on purpose (same Taylor map, same ``f``): a proof that
still goes through on the copy was built from ``f`` alone. The original model proves the
statement, the copy must not.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.exceptions import ModelError, UnsupportedOperationError


def _stable(widen: float = 0.0) -> cm.Model:
    """A validated linear ODE, its remainder parameters widened by ``widen`` each side."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    model = cm.Model.from_ode(x, u, ca.vertcat(-x[0] + 0.2 * x[1], -x[1] + u), 0.2,
                              method="taylor", order=4, X=cm.Box([-2, -2], [2, 2]),
                              U=cm.Box([-3], [3]), name="stable")
    return _widened(model, widen)


def _pendulum(widen: float = 0.0) -> cm.Model:
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    model = cm.Model.from_ode(x, u, ca.vertcat(x[1], -ca.sin(x[0]) + u), 0.1,
                              method="taylor", order=4, X=cm.Box([-1, -1], [1, 1]),
                              U=cm.Box([-2], [2]), name="pendulum")
    return _widened(model, widen)


def _widened(model: cm.Model, widen: float) -> cm.Model:
    if widen:
        params, bounds = model._exact_params
        b = np.array(bounds, dtype=float)
        iv = b[:, 0] < b[:, 1]  # the remainder's interval-valued parameters
        assert iv.any()
        b[iv, 0] -= widen
        b[iv, 1] += widen
        model._exact_params = (params, b)
        model._cache.clear()
    return model


def test_the_widened_copy_has_the_same_map_and_a_wider_enclosure() -> None:
    a, b = _pendulum(), _pendulum(0.5)
    assert a.function.serialize() == b.function.serialize()
    box, ub = np.array([[[0.1, 0.1], [0.2, 0.2]]]), np.array([[[0.3, 0.3]]])
    wa = np.diff(a.inclusion("natural")(box, ub), axis=-1).max()
    wb = np.diff(b.inclusion("natural")(box, ub), axis=-1).max()
    assert wa < 1e-4 and wb >= 1.0


def test_certify_invariant_reads_the_enclosure_and_says_what_it_is_about() -> None:
    from casadi_cmpc.control.invariance import check_about, model_key

    S = cm.Polytope.from_box(cm.Box([-1, -1], [1, 1]))
    law = np.array([[0.0, -0.5]])
    good, bad = _stable(), _stable(2.0)
    cert = cm.certify_invariant(good, S, law, 0.25)
    assert cert.proved is True
    assert good.discretisation in cert.claim
    assert cm.certify_invariant(bad, S, law, 0.25).proved is not True
    # the key of what the certificate is about tells the two models apart
    assert model_key(good) != model_key(bad)
    assert check_about(cert, good, S, None) is None
    assert check_about(cert, bad, S, None) is not None


def test_contractive_mpc_verifies_with_the_enclosure() -> None:
    x0 = np.array([0.6, 0.0])
    good = cm.ContractiveMPC(_pendulum(), horizon=3, alpha=0.95, norm=2, solver="sqp")
    r = good.solve(x0)
    assert r.certificate.label == "verified"
    assert _pendulum().discretisation in r.certificate.claim
    h = good._get_check(3)
    # the remainder reaches the check, with values of its own at each of the 3 steps (a
    # search over the parameters must not tie the steps to one value)
    Pb = good.model.interval_expr()[2]
    per_step = int((Pb[:, 0] < Pb[:, 1]).sum())
    assert per_step > 0 and int((h.param_lo < h.param_hi).sum()) >= 3 * per_step
    bad = cm.ContractiveMPC(_pendulum(0.5), horizon=3, alpha=0.95, norm=2, solver="sqp")
    assert bad.solve(x0).certificate.label != "verified"


def test_c_export_checks_with_the_enclosure(tmp_path) -> None:
    from casadi_cmpc.codegen import export_c
    from casadi_cmpc.codegen.export import _model_interval_fun

    model = _pendulum(0.25)
    ctrl = cm.ContractiveMPC(model, horizon=2, alpha=0.95, norm=2, solver="sqp",
                             mode="receding")
    export_c(ctrl, tmp_path / "c", solver="sqp")
    text = (tmp_path / "c" / "cmpc_controller.c").read_text()
    tables = (tmp_path / "c" / "cmpc_tables.h").read_text()
    fun = _model_interval_fun(model)
    iv = fun.interval
    lo, hi = fun.bounds[iv][0]
    # the interval successor cmpc_f_iv holds the widened remainder as an interval constant
    assert lo.hex() in text and hi.hex() in text
    # and the check's parameter table its bounds (param_lo < param_hi somewhere)
    h = ctrl._get_check(2)
    assert (h.param_lo < h.param_hi).any()
    assert repr(float(h.param_hi[h.param_lo < h.param_hi][0])) in tables


def test_quantified_sivia_refuses_an_enclosure() -> None:
    from casadi_cmpc.solvers.quantified import quantified_sivia

    model = _pendulum()
    with pytest.raises(ModelError, match="interval-valued remainder"):
        quantified_sivia(model, Y=cm.Box([-0.5, -0.5], [0.5, 0.5]), eps=0.1)
    with pytest.raises(UnsupportedOperationError, match="interval-valued parameters"):
        quantified_sivia(model.interval_map("xu"), model.X, model.U,
                         Y=cm.Box([-0.5, -0.5], [0.5, 0.5]), eps=0.1)


def test_simulate_runs_a_given_plant() -> None:
    model = _stable()
    calls = []

    def plant(x, u, w):
        calls.append(1)
        return 0.5 * x

    tr = cm.simulate(model, np.array([[0.0, -0.5]]), [1.0, 1.0], 3, plant=plant)
    assert len(calls) == 3
    np.testing.assert_allclose(tr.x[-1], [0.125, 0.125])
    with pytest.raises(TypeError):
        cm.simulate(model, np.array([[0.0, -0.5]]), [1.0, 1.0], 3, plant=1.0)
