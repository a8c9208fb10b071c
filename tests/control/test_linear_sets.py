"""Exact pre-sets of linear models (thesis §3.4) checked against their definition by LP."""

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import linprog

import casadi_cmpc as cm


def _controllable(model, x, target_members, margin=0.0):
    """Is there u in U with A x + B u + c (+ E w for all w in W) in one of the members?"""
    A, B, E, c = model.linear_matrices()
    for P in target_members:
        H, h = np.asarray(P.A), np.asarray(P.b)
        if model.l:
            HE = H @ E
            h = h - np.maximum(HE * model.W.lo, HE * model.W.hi).sum(axis=1)
        res = linprog(np.zeros(model.m), A_ub=H @ B, b_ub=h - H @ (A @ x + c) - margin,
                      bounds=list(zip(model.U.lo, model.U.hi, strict=True)), method="highs")
        if res.status == 0:
            return True
    return False


@pytest.fixture(scope="module")
def e1_sequence():
    ex = cm.models.load("linear_sliding")
    seq = cm.linear_controllable_sets(ex.model, ex.terminal, max_steps=20, until=ex.x0s)
    return ex, seq


def test_e1_reaches_both_thesis_initial_states(e1_sequence):
    ex, seq = e1_sequence
    last = seq.sets[-1]
    assert np.all(last.contains(ex.x0s))
    assert seq.level(ex.x0s[0]) is not None and seq.level(ex.x0s[1]) is not None
    # neither initial state is in the terminal set itself
    assert not np.any(ex.terminal.contains(ex.x0s))
    assert seq.level(np.array([100.0, 100.0])) is None


def test_e1_pre_sets_match_the_definition(e1_sequence):
    ex, seq = e1_sequence
    model = ex.model
    rng = np.random.default_rng(1)
    pts = model.X.sample(400, rng)
    for i in (1, 2):
        K, prev = seq.sets[i], seq.sets[i - 1]
        members = prev.polytopes
        inside = K.contains(pts)
        for x, flag in zip(pts, inside, strict=True):
            if flag:
                assert _controllable(model, x, members), (i, x)
            else:
                # outside K_i within X: no admissible input reaches K_{i-1}; allow points on
                # the boundary (tiny margin) to go either way
                assert not _controllable(model, x, members, margin=-1e-7) or \
                    np.min(np.abs(np.concatenate([P.A @ x - P.b for P in K.polytopes]))) < 1e-6


def test_e1_sets_are_nested(e1_sequence):
    ex, seq = e1_sequence
    rng = np.random.default_rng(2)
    for i in range(len(seq.sets) - 1):
        S, nxt = seq.sets[i], seq.sets[i + 1]
        pts = ex.model.X.sample(4000, rng)
        pts = pts[S.contains(pts)]
        assert pts.shape[0] > 0
        assert np.all(nxt.contains(pts, tol=1e-9))


def test_robust_pre_set_of_a_polytope():
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    f = ca.vertcat(x[0] + 0.5 * x[1], x[1] + 0.5 * u + w)
    model = cm.Model(x=x, u=u, w=w, f=f, X=cm.Box([-5, -5], [5, 5]), U=cm.Box([-1], [1]),
                     W=cm.Box([-0.1], [0.1]))
    T = cm.Polytope.from_box(cm.Box([-1, -1], [1, 1]))
    K = cm.pre_set(model, T)
    rng = np.random.default_rng(3)
    pts = model.X.sample(300, rng)
    inside = K.contains(pts)
    assert inside.any() and (~inside).any()
    for xv, flag in zip(pts, inside, strict=True):
        if flag:
            assert _controllable(model, xv, [T])
            # and the robust statement holds at the extreme disturbances with that input
    # the nominal pre-set is strictly larger than the robust one
    nominal = cm.Model(x=x, u=u, f=ca.substitute(f, w, 0), X=model.X, U=model.U)
    Kn = cm.pre_set(nominal, T)
    assert K.is_subset(Kn) and not Kn.is_subset(K)


def test_pre_set_refuses_nonlinear_models_and_robust_unions():
    ex = cm.models.load("cannon")
    with pytest.raises(cm.ModelError, match="linear"):
        cm.pre_set(ex.model, ex.terminal)
    x = ca.SX.sym("x", 1)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    model = cm.Model(x=x, u=u, w=w, f=x + u + w, X=cm.Box([-5], [5]), U=cm.Box([-1], [1]),
                     W=cm.Box([-0.1], [0.1]))
    U2 = cm.PolytopeUnion([cm.Polytope.from_box(cm.Box([-1], [0])),
                           cm.Polytope.from_box(cm.Box([0.5], [1]))])
    with pytest.raises(cm.ModelError, match="union"):
        cm.pre_set(model, U2)


def test_scalar_pre_set_is_the_expected_interval():
    # x+ = 2 x + u, |u| <= 1, T = [-1, 1]  ->  Pre(T) = [-1, 1] (|2x| <= 2)
    x = ca.SX.sym("x", 1)
    u = ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=2 * x + u, X=cm.Box([-10], [10]), U=cm.Box([-1], [1]))
    K = cm.pre_set(model, cm.Polytope.from_box(cm.Box([-1], [1])))
    B = K.bounding_box()
    np.testing.assert_allclose([B.lo[0], B.hi[0]], [-1.0, 1.0], atol=1e-9)
