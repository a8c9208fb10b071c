"""local_lqr and certify_invariant (thesis §4.2.6, Alg 4.3)."""

from __future__ import annotations

from fractions import Fraction

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm


def _sample_in(S, k, rng):
    lo, hi = S.bounding_box().lo, S.bounding_box().hi
    P = lo + (hi - lo) * rng.random((k, S.dim))
    return P[np.asarray(S.contains(P), dtype=bool)]


def test_e5_level_09_is_proved_and_level_1_refuted_by_the_input_bound():
    ex = cm.models.load("cannon_001")
    V, K = ex.info["V"], ex.local_law
    S09 = cm.Polytope(np.vstack([V, -V]), np.full(4, 0.9))
    c = cm.certify_invariant(ex.model, S09, K, eps=0.1)
    assert c.proved is True and c.label == "proved"
    rng = np.random.default_rng(0)
    x = _sample_in(S09, 4000, rng)
    assert S09.contains(ex.model.step(x, x @ K.T)).all()
    assert (np.abs(x @ K.T) <= 2).all()
    S10 = cm.Polytope(np.vstack([V, -V]), np.full(4, 1.0))
    r = cm.certify_invariant(ex.model, S10, K, eps=0.1)
    assert r.proved is False and "input bound" in r.reason
    xc = r.counterexample
    # exact check: x in S10 and |K x| > 2
    xf = [Fraction(v) for v in xc]
    for a, b in zip(S10.A, S10.b, strict=True):
        assert sum(Fraction(ai) * xi for ai, xi in zip(a, xf, strict=True)) <= Fraction(b)
    kx = sum(Fraction(ki) * xi for ki, xi in zip(K[0], xf, strict=True))
    assert abs(kx) > 2
    assert abs(float(kx)) == pytest.approx(2.0002, abs=2e-4)


@pytest.mark.parametrize("name", ["cannon", "cannon_robust"])
def test_terminal_sets_of_e8_and_e9_are_proved_robustly_invariant(name):
    ex = cm.models.load(name)
    c = cm.certify_invariant(ex.model, ex.terminal, ex.local_law, eps=0.01)
    assert c.proved is True
    rng = np.random.default_rng(1)
    x = _sample_in(ex.terminal, 3000, rng)
    u = x @ ex.local_law.T
    assert (np.abs(u) <= 2).all()
    ws = [None] if not ex.model.l else [ex.model.W.lo, ex.model.W.hi, ex.model.W.mid]
    for w in ws:
        wb = None if w is None else np.broadcast_to(w, (x.shape[0], 1))
        assert ex.terminal.contains(ex.model.step(x, u, wb)).all()


def test_a_set_that_is_not_invariant_is_refuted_with_a_state_counterexample():
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    f = ca.vertcat(1.1 * x[0] + 0.1 * x[1], 0.9 * x[1] + 0.1 * u, 0.5 * x[2] + 0.1 * x[0] ** 2)
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-2] * 3, [2] * 3), U=cm.Box([-5], [5]))
    S = cm.Polytope.from_box(cm.Box([-1] * 3, [1] * 3))
    c = cm.certify_invariant(model, S, np.zeros((1, 3)), eps=0.1)  # no control: x1 grows
    assert c.proved is False and "state set" in c.reason
    xc = c.counterexample
    assert S.contains(xc[None, :])[0] and not S.contains(model.step(xc, [0.0])[None, :])[0]


def test_lqr_makes_a_small_box_invariant_on_a_3_state_model_with_nonzero_equilibrium():
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * (-ca.sin(x[0]) + u), 0.8 * x[2] + 0.2 * x[0])
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-2] * 3, [2] * 3), U=cm.Box([-2], [2]))
    a = 0.5
    xe, ue = np.array([a, 0.0, a]), np.array([np.sin(a)])
    K = cm.local_lqr(model, np.eye(3), 1.0, x_eq=xe, u_eq=ue)
    assert K.shape == (1, 3)
    A = np.asarray(model.jacobian_function("x")(xe, ue, np.zeros(0)))
    B = np.asarray(model.jacobian_function("u")(xe, ue, np.zeros(0)))
    assert np.abs(np.linalg.eigvals(A + B @ K)).max() < 1  # stabilising, u = K x sign
    law = ca.DM(ue) + ca.mtimes(ca.DM(K), model.x - ca.DM(xe))
    r = 0.05
    S = cm.Polytope.from_box(cm.Box(xe - r, xe + r))
    c = cm.certify_invariant(model, S, law, eps=0.01)
    if c.proved is True:
        rng = np.random.default_rng(2)
        pts = _sample_in(S, 2000, rng)
        us = ue + (pts - xe) @ K.T
        assert S.contains(model.step(pts, us)).all()
    elif c.proved is False:  # a box need not be invariant: the counterexample must be real
        xc = c.counterexample
        uc = ue + (xc - xe) @ K.T
        assert S.contains(xc[None, :])[0]
        assert not S.contains(model.step(xc, uc)[None, :])[0] or np.abs(uc).max() > 2



def test_local_lqr_refuses_a_non_equilibrium_and_bad_weights():
    ex = cm.models.load("cannon")
    with pytest.raises(ValueError, match="not an equilibrium"):
        cm.local_lqr(ex.model, np.eye(2), 1.0, x_eq=[0.5, 0.0])
    with pytest.raises(ValueError, match="positive definite"):
        cm.local_lqr(ex.model, np.eye(2), 0.0)
    K = cm.local_lqr(ex.model, np.eye(2), 1.0)
    A = np.asarray(ex.model.jacobian_function("x")([0, 0], [0], np.zeros(0)))
    B = np.asarray(ex.model.jacobian_function("u")([0, 0], [0], np.zeros(0)))
    assert np.abs(np.linalg.eigvals(A + B @ K)).max() < 1


def test_certify_invariant_refuses_bad_inputs():
    ex = cm.models.load("cannon")
    with pytest.raises(cm.UnsupportedOperationError):
        cm.certify_invariant(ex.model, cm.Zonotope([0, 0], np.eye(2)), ex.local_law, 0.1)
    with pytest.raises(cm.DimensionError):
        cm.certify_invariant(ex.model, ex.terminal, np.ones((1, 3)), 0.1)
