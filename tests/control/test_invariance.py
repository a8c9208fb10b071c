"""local_lqr, certify_invariant and largest_invariant_zonotope (thesis §4.2.6-4.2.7,
Alg 4.3 and 4.4)."""

from __future__ import annotations

from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

import casadi_cmpc as cm
from casadi_cmpc.solvers.engine import INNER, OUTER
from casadi_cmpc.solvers.zonotope_sivia import ZonotopeFrontier, zonotope_classifier


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
    assert isinstance(K, cm.LinearLaw) and np.array_equal(K.x_eq, xe)
    law = ca.DM(ue) + ca.mtimes(ca.DM(K.K), model.x - ca.DM(xe))  # the same law as K
    r = 0.05
    S = cm.Polytope.from_box(cm.Box(xe - r, xe + r))
    c = cm.certify_invariant(model, S, law, eps=0.01)
    if c.proved is True:
        rng = np.random.default_rng(2)
        pts = _sample_in(S, 2000, rng)
        us = ue + (pts - xe) @ K.K.T
        assert S.contains(model.step(pts, us)).all()
    elif c.proved is False:  # a box need not be invariant: the counterexample must be real
        xc = c.counterexample
        uc = ue + (xc - xe) @ K.K.T
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
    with pytest.raises(cm.UnsupportedOperationError, match="Polytope.from_box"):
        cm.certify_invariant(ex.model, cm.Box([-1, -1], [1, 1]), ex.local_law, 0.1)
    with pytest.raises(cm.UnsupportedOperationError, match="flat zonotope"):
        cm.certify_invariant(ex.model, cm.Zonotope([0, 0], [[1.0, 2.0], [1.0, 2.0]]),
                             ex.local_law, 0.1)
    with pytest.raises(cm.DimensionError):
        cm.certify_invariant(ex.model, cm.Zonotope([0, 0, 0], np.eye(3)), ex.local_law, 0.1)
    with pytest.raises(cm.DimensionError):
        cm.certify_invariant(ex.model, ex.terminal, np.ones((1, 3)), 0.1)


# ------------------------------------------------------------------ zonotope targets
def _zono_norm(Z, P):
    """min ||a||_inf with Z.center + G a = p for every row p of P (LP, HiGHS)."""
    G = Z.generators
    n, m = G.shape
    cost = np.zeros(m + 1)
    cost[-1] = 1.0
    eye = np.eye(m)
    A_ub = np.block([[eye, -np.ones((m, 1))], [-eye, -np.ones((m, 1))]])
    A_eq = np.hstack([G, np.zeros((n, 1))])
    out = []
    for p in np.atleast_2d(P):
        r = linprog(cost, A_ub=A_ub, b_ub=np.zeros(2 * m), A_eq=A_eq, b_eq=p - Z.center,
                    bounds=[(None, None)] * m + [(0, None)], method="highs")
        assert r.status == 0
        out.append(r.fun)
    return np.array(out)


def _zono_samples(Z, k, rng):
    a = rng.uniform(-1, 1, (k, Z.n_generators))
    a[: k // 2] = np.sign(a[: k // 2])
    return Z.center + a @ Z.generators.T


def _rotation_model(scale, theta=0.3):
    """x+ = A x + u with u = K x giving x+ = scale R(theta) x (known truth)."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u", 2)
    A = np.array([[1.0, 0.1], [0.0, 1.0]])
    f = ca.mtimes(ca.DM(A), x) + u
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-5, -5], [5, 5]), U=cm.Box([-10, -10], [10, 10]))
    R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    return model, scale * R - A


def _octagon(c=(0.0, 0.0)):
    ang = np.pi * np.arange(4) / 4
    return cm.Zonotope(list(c), np.stack([np.cos(ang), np.sin(ang)]))


def test_zonotope_S_is_proved_invariant_under_a_contraction():
    # x+ = 0.5 R(0.3) x maps the octagon (centred at the origin) into half of its outer
    # ball, which lies inside its inner ball: invariant
    model, K = _rotation_model(0.5)
    S = _octagon((0.0, 0.0))
    c = cm.certify_invariant(model, S, K, eps=0.5)
    assert c.proved is True and c.label == "proved"
    rng = np.random.default_rng(3)
    P = _zono_samples(S, 500, rng)
    # gauge of the image <= 0.5 * (outer / inner radius) = 0.5 / cos(pi / 8) < 0.55
    assert (_zono_norm(S, model.step(P, P @ K.T)) <= 0.55).all()


def test_zonotope_S_is_refuted_with_a_counterexample_proven_inside():
    # x+ = 1.1 R(0.3) x expands every set around the origin: the octagon is not invariant
    model, K = _rotation_model(1.1)
    S = _octagon((0.0, 0.0))
    c = cm.certify_invariant(model, S, K, eps=0.2)
    assert c.proved is False and "state set" in c.reason
    xc = c.counterexample
    assert _zono_norm(S, xc)[0] <= 1.0
    assert S.contains_box(np.stack([xc, xc], axis=-1)[None])[0]  # proven inside
    assert _zono_norm(S, model.step(xc, K @ xc))[0] > 1.0


def test_off_centre_zonotope_under_a_contraction_towards_the_origin_is_refuted():
    # the contraction pulls the octagon centred at (3, 0) towards the origin, out of itself
    model, K = _rotation_model(0.5)
    S = _octagon((3.0, 0.0))
    c = cm.certify_invariant(model, S, K, eps=0.5)
    assert c.proved is False
    xc = c.counterexample
    assert _zono_norm(S, xc)[0] <= 1.0 and _zono_norm(S, model.step(xc, K @ xc))[0] > 1.0


def test_thesis_zonotope_of_e6_is_proved_invariant_for_the_cstr():
    ex = cm.models.load("cstr")
    Z = cm.Zonotope([0.0, 0.0], ex.info["zonotope_generators"])
    c = cm.certify_invariant(ex.model, Z, ex.local_law, eps=0.005)
    assert c.proved is True
    rng = np.random.default_rng(4)
    P = _zono_samples(Z, 300, rng)
    assert Z.contains(ex.model.step(P, P @ ex.local_law.T)).all()
    # four times as large it is not: a point of it is proven to leave it
    Z4 = cm.Zonotope([0.0, 0.0], 4 * Z.generators)
    c4 = cm.certify_invariant(ex.model, Z4, ex.local_law, eps=0.01)
    assert c4.proved is False
    xc = c4.counterexample
    uc = ex.local_law @ xc
    assert _zono_norm(Z4, xc)[0] <= 1.0
    assert not ex.model.U.contains(uc) or _zono_norm(Z4, ex.model.step(xc, uc))[0] > 1.0


def _model3():
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    f = ca.vertcat(0.5 * x[0] + 0.05 * x[1] ** 2 + 0.1 * u,
                   0.5 * x[1] + 0.05 * ca.sin(x[0]) * x[2],
                   0.4 * x[2] + 0.1 * x[0] * x[1] + 0.05 * u)
    return cm.Model(x=x, u=u, f=f, X=cm.Box([-3] * 3, [3] * 3), U=cm.Box([-1], [1]))


def test_3_state_zonotope_proved_and_a_larger_one_refuted():
    model = _model3()
    K = np.array([[-0.2, 0.0, 0.1]])
    S = cm.Zonotope([0.0, 0.0, 0.0], [[0.5, 0.2, 0.0, 0.1],
                                       [0.0, 0.4, 0.2, -0.1],
                                       [0.1, 0.0, 0.5, 0.2]])
    c = cm.certify_invariant(model, S, K, eps=0.2)
    assert c.proved is True
    rng = np.random.default_rng(5)
    P = _zono_samples(S, 300, rng)
    nxt = model.step(P, P @ K.T)
    assert (_zono_norm(S, nxt) <= 1.0).all()
    # 8 times larger: the quadratic terms push the successors out (or |u| > 1)
    big = cm.Zonotope(S.center, 8 * S.generators)
    r = cm.certify_invariant(model, big, K, eps=0.5)
    assert r.proved is False
    xc = r.counterexample
    assert _zono_norm(big, xc)[0] <= 1.0
    uc = K @ xc
    assert np.abs(uc).max() > 1 or _zono_norm(big, model.step(xc, uc))[0] > 1.0


@settings(max_examples=30)
@given(seed=st.integers(0, 2**32 - 1), n=st.sampled_from([2, 3]),
       p=st.integers(0, 3), scale=st.sampled_from([1e-3, 0.05, 0.3]))
def test_zonotope_target_never_claims_a_wrong_inclusion_or_disjointness(seed, n, p, scale):
    rng = np.random.default_rng(seed)
    G = rng.uniform(-1, 1, (n, n + p))
    if np.linalg.svd(G, compute_uv=False)[-1] < 0.05:
        G[:, :n] += np.eye(n)
    S = cm.Zonotope(rng.uniform(-1, 1, n), G)
    N = 24
    # pieces centred around the boundary of S (some parameters at +-1, some beyond)
    a = rng.uniform(-1.15, 1.15, (N, S.n_generators))
    a[: N // 2, 0] = np.sign(a[: N // 2, 0])
    C = S.center + a @ S.generators.T
    q = int(rng.integers(1, 4))
    H = scale * rng.uniform(-1, 1, (N, n, q))
    R = np.where(rng.random((N, n)) < 0.3, scale * rng.random((N, n)) * 0.1, 0.0)
    fr = ZonotopeFrontier(C, H, R)
    labels = zonotope_classifier(None, S, n=n)(fr)
    for i in np.flatnonzero((labels == INNER) | (labels == OUTER)):
        Zi = fr.zonotope(i)
        pts = np.vstack([Zi.center, _zono_samples(Zi, 6, rng)])
        t = _zono_norm(S, pts)
        if labels[i] == INNER:
            assert (t <= 1.0 + 1e-9).all(), (i, t.max())
        else:
            assert (t >= 1.0 - 1e-9).all(), (i, t.min())


def test_zonotope_target_inclusion_is_exact_up_to_rounding_and_never_outward():
    # S.to_polytope() rounds its offsets outward: a piece slightly larger than S can pass
    # against it, never against the zonotope test
    S = cm.Zonotope([0.1, 0.2], [[0.3, 0.1, 0.7], [0.1, 0.3, -0.2]])
    labels = zonotope_classifier(None, S, n=2)(ZonotopeFrontier(
        np.array([S.center, S.center, S.center]),
        np.stack([S.generators, (1 + 1e-12) * S.generators, 0.99 * S.generators])))
    assert labels[1] != INNER and labels[2] == INNER


# ------------------------------------------------------------------ Alg 4.4
def test_e6_largest_invariant_zonotope_is_at_least_the_thesis_zonotope():
    ex = cm.models.load("cstr")
    info = ex.info
    res = cm.largest_invariant_zonotope(ex.model, ex.local_law, info["M0_search"],
                                        info["eps_opt"], info["eps_sivia"], progress=False)
    thesis = cm.Zonotope([0.0, 0.0], info["zonotope_generators"]).volume()
    assert res.success and res.zonotope is not None
    assert res.certificate.proved is True
    assert res.volume == pytest.approx(res.zonotope.volume())
    assert res.volume >= thesis - 1e-12
    assert res.zonotope.n_generators == 4  # Mid(M) (2 columns) and Kuhn's diagonal (2)
    M = res.M
    assert M.shape == (2, 2, 2) and (M[..., 1] - M[..., 0]).max() <= 0.04
    Zk = cm.zonotope_inclusion([0.0, 0.0], M[..., 0], M[..., 1])
    np.testing.assert_array_equal(Zk.generators, res.zonotope.generators)
    assert res.zonotope.contained_in(ex.model.X)
    rng = np.random.default_rng(6)
    P = _zono_samples(res.zonotope, 500, rng)
    u = P @ ex.local_law.T
    assert ex.model.U.contains(u).all()
    assert res.zonotope.contains(ex.model.step(P, u)).all()
    assert res.stats["proved"] == 1 and res.nit == res.stats["iterations"]


def test_largest_invariant_zonotope_on_a_3_state_model():
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.1 * x[1],
                   x[1] + 0.1 * (u + 0.5 * ca.sin(x[0]) + 0.2 * x[2]),
                   0.7 * x[2] + 0.1 * x[0] ** 2 + 0.1 * x[1])
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-1] * 3, [1] * 3), U=cm.Box([-2], [2]))
    K = cm.local_lqr(model, np.eye(3), 1.0)
    M0 = [[[0.0, 0.4], [0.0, 0.0]], [[-0.4, 0.0], [0.0, 0.4]], [[0.0, 0.0], [0.0, 0.4]]]
    res = cm.largest_invariant_zonotope(model, K, M0, eps_opt=0.1, eps_sivia=0.1,
                                        progress=False)
    assert res.status == cm.Status.PROVED and res.certificate.proved is True
    Z = res.zonotope
    assert Z.dim == 3 and Z.n_generators == 5 and res.volume > 0
    rng = np.random.default_rng(7)
    P = _zono_samples(Z, 500, rng)
    us = P @ K.K.T
    assert (np.abs(us) <= 2).all()
    assert (_zono_norm(Z, model.step(P, us)) <= 1.0).all()
    # a budget stops the search early; what it returns is still proven
    short = cm.largest_invariant_zonotope(model, K, M0, eps_opt=0.1, eps_sivia=0.1,
                                          max_iter=3, progress=False)
    assert short.status == cm.Status.BUDGET and short.nit == 3
    assert short.zonotope is None or short.certificate.proved is True


def test_largest_invariant_zonotope_reports_when_nothing_is_proven():
    model, K = _rotation_model(1.1)  # expanding: no invariant zonotope around the origin
    res = cm.largest_invariant_zonotope(model, K, [[[0.5, 1.0], [0, 0]], [[0, 0], [0.5, 1.0]]],
                                        eps_opt=0.25, eps_sivia=0.2, progress=False)
    assert res.zonotope is None and res.certificate is None and res.volume == 0.0
    assert res.status == cm.Status.UNDECIDED and not res.success
    assert "no zonotope" in res.message and res.stats["refuted"] == res.stats["tested"] > 0


def test_largest_invariant_zonotope_refuses_bad_inputs():
    model, K = _rotation_model(0.5)
    with pytest.raises(cm.DimensionError, match="shape"):
        cm.largest_invariant_zonotope(model, K, np.zeros((3, 2, 2)), 0.1, 0.1)
    with pytest.raises(ValueError, match="empty"):
        cm.largest_invariant_zonotope(model, K, [[[1.0, 0.0]], [[0.0, 1.0]]], 0.1, 0.1)
    with pytest.raises(ValueError, match="eps_opt"):
        cm.largest_invariant_zonotope(model, K, [[[0.0, 1.0]], [[0.0, 1.0]]], 0.0, 0.1)


def test_largest_invariant_zonotope_centres_at_the_laws_equilibrium():
    """Without ``center`` the candidates are centred at the LinearLaw's x_eq (3, 3), where
    the contracting closed loop keeps them; at the origin they would lie outside X."""
    import casadi as ca

    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    xe = np.array([3.0, 3.0])
    f = xe + 0.5 * (x - xe) + ca.vertcat(0, 0.1) * u
    m = cm.Model(x, u, f, X=cm.Box([2, 2], [4, 4]), U=cm.Box([-1], [1]), name="shifted")
    law = cm.LinearLaw(np.zeros((1, 2)), x_eq=xe, u_eq=[0.0])
    M0 = np.zeros((2, 2, 2))
    M0[0, 0] = M0[1, 1] = [0.0, 0.5]
    r = cm.largest_invariant_zonotope(m, law, M0, eps_opt=0.05, eps_sivia=0.05,
                                      progress=False)
    assert r.status == cm.Status.PROVED
    np.testing.assert_array_equal(r.zonotope.center, xe)
