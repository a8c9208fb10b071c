"""Robust one-step MPC (5.20) of models not affine in w: interval minimax (Alg 5.3) inside
SetSequenceMPC (Alg 5.4), and the ``params``/``points`` arguments of cm.minimax it uses.

The models: a 2-state system whose control gain ``b(w) = 1 - w^2 / 2`` peaks at w = 0, inside
W = [-0.6, 1] (the vertices give b = 0.82 and 0.5: the overshoot of a large control, worst at
b = 1, is invisible to the vertices), and a 3-state system with a non-zero equilibrium, the
same kind of gain and a ``sin`` of the disturbance. The true worst case over W of a control
is computed on a dense grid of W that holds the interior maximiser of b.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.exceptions import CmpcWarning, DimensionError
from casadi_cmpc.interval.modal import SemanticExtension
from casadi_cmpc.solvers.engine import Status
from casadi_cmpc.solvers.minimax import minimax

# ============================================================================ 2-state model
K2 = np.array([[-3.979, -5.333]])  # poles -0.25, 0.65 of the linear part at b = 0.75
H2 = np.array([[5.0, 1.6001], [4.3752, 5.0], [-5.0, -1.6001], [-4.3752, -5.0]])
R2 = 0.01  # a cheap control: the optimiser drives x2+ to 0 and may overshoot
W2 = (-0.6, 1.0)


def gain_model() -> cm.Model:
    """x1+ = x1 + 0.4 x2 + 0.05 x2^2, x2+ = x2 + 0.1 x1 + 0.4 (1 - w^2/2) u."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    b = 1 - 0.5 * w ** 2
    f = ca.vertcat(x[0] + 0.4 * x[1] + 0.05 * x[1] ** 2, x[1] + 0.1 * x[0] + 0.4 * b * u)
    return cm.Model(x=x, u=u, w=w, f=f, X=cm.Box([-2, -2], [2, 2]), U=cm.Box([-2], [2]),
                    W=cm.Box([W2[0]], [W2[1]]), name="gain_w2")


@pytest.fixture(scope="module")
def gain():
    model = gain_model()
    T = cm.Polytope(H2, np.ones(4))
    cert = cm.certify_invariant(model, T, K2, 0.005, progress=False)
    assert cert.label == "proved"
    seq = cm.controllable_sets(model, T, 0.1, robust=True, certificate=cert, max_steps=30,
                               progress=False)
    return model, T, cert, seq


@pytest.fixture(scope="module")
def gain_poly(gain):
    model, T, cert, _ = gain
    seq = cm.controllable_sets(model, T, 0.05, robust=True, certificate=cert, max_steps=2,
                               polytopic=True, progress=False)
    return model, seq


WS2 = np.union1d(np.linspace(W2[0], W2[1], 2001), [0.0])


def worst_cost(model, x, u, ws, Q, R, x_ref=None):
    """max over the points ws (l, k) of (f - x_ref)' Q (f - x_ref) + u' R u."""
    ws = np.atleast_2d(ws)
    k = ws.shape[1]
    u = np.asarray(u, dtype=float).reshape(-1)
    Y = np.asarray(model.function.map(k)(np.repeat(np.asarray(x)[:, None], k, 1),
                                         np.repeat(u[:, None], k, 1), ws))
    if x_ref is not None:
        Y = Y - np.asarray(x_ref)[:, None]
    return float(np.einsum("ik,ij,jk->k", Y, Q, Y).max() + u @ R @ u)


def states(seq, rng, k, lo, hi, levels=(1, None)):
    """k random states of X with a level in [levels[0], levels[1]]."""
    P = rng.uniform(lo, hi, size=(40 * k, len(lo)))
    lv = seq.level(P)
    keep = lv >= levels[0]
    if levels[1] is not None:
        keep &= lv <= levels[1]
    return P[keep][:k]


def test_premise_the_vertex_maximum_is_wrong(gain):
    model, *_ = gain
    assert not model.is_affine_in_w
    # b(w) has its maximum inside W: for a control overshooting x2+ = 0 the worst w is 0
    x, u = np.array([0.0, -0.3]), np.array([1.2])
    Q, R = np.eye(2), R2 * np.eye(1)
    at_vertices = worst_cost(model, x, u, np.array([W2]), Q, R)
    assert worst_cost(model, x, u, WS2[None], Q, R) > at_vertices + 0.01


# ============================================================================ the choice
def test_auto_resolves_by_affinity_in_w(gain):
    model, T, _, seq = gain
    ctrl = cm.SetSequenceMPC(model, seq, np.eye(2), R2, K2)
    assert ctrl.robust and ctrl.minimax == "interval"
    assert "minimax='interval'" in repr(ctrl)
    assert cm.SetSequenceMPC(model, seq, np.eye(2), R2, K2, robust=False).minimax == "vertices"
    assert cm.SetSequenceMPC(model, seq, np.eye(2), R2, K2,
                             minimax="Vertices").minimax == "vertices"
    # an affine model (E9, mu enters as mu * (...) u): the vertices are exact
    ex = cm.models.load("cannon_robust")
    assert ex.model.is_affine_in_w
    seq9 = cm.SetSequence(sets=[ex.terminal], info={"robust": True})
    c9 = cm.SetSequenceMPC(ex.model, seq9, local_law=ex.local_law)
    assert c9.robust and c9.minimax == "vertices" and "minimax='vertices'" in repr(c9)
    assert cm.SetSequenceMPC(ex.model, seq9, local_law=ex.local_law,
                             minimax="interval").minimax == "interval"


def test_bad_minimax_arguments_are_refused(gain):
    model, _, _, seq = gain
    mk = lambda **kw: cm.SetSequenceMPC(model, seq, np.eye(2), R2, K2, **kw)  # noqa: E731
    for bad in ("grid", "", 1, None):
        with pytest.raises(ValueError, match="minimax must be one of"):
            mk(minimax=bad)
    with pytest.raises(TypeError, match="minimax_options must be a dict"):
        mk(minimax_options=[("eps", 0.1)])
    with pytest.raises(ValueError, match=r"unknown minimax_options \['tol'\]"):
        mk(minimax_options={"tol": 0.1})
    for key, v in [("eps", -1.0), ("eps", "0.1"), ("eps", np.nan), ("eps", True),
                   ("time_limit", 0.0), ("time_limit", np.inf), ("max_boxes", 0),
                   ("max_boxes", 10.5), ("w_depth", -1), ("w_depth", True),
                   ("w_depth_final", 2.0), ("mean_value", "yes")]:
        with pytest.raises(ValueError, match=f"minimax_options\\['{key}'\\]"):
            mk(minimax_options={key: v})
    with pytest.raises(ValueError, match="w_depth_final"):
        mk(minimax_options={"w_depth": 3, "w_depth_final": 2})
    assert mk(minimax_options={"time_limit": None, "eps": 0.01}).minimax == "interval"
    with pytest.warns(CmpcWarning, match="not used"):
        mk(minimax="vertices", minimax_options={"eps": 0.1})
    # no disturbance: nothing to maximise over
    ex = cm.models.load("cannon")
    seq8 = cm.SetSequence(sets=[ex.terminal], info={"robust": False})
    with pytest.raises(ValueError, match="needs a disturbance"):
        cm.SetSequenceMPC(ex.model, seq8, local_law=ex.local_law, minimax="interval")
    assert cm.SetSequenceMPC(ex.model, seq8, local_law=ex.local_law).minimax == "vertices"


# ============================================================================ one step
def test_certified_bound_and_no_worse_than_the_vertices(gain):
    """Over random states of K_1..K_N: the reported upper bound holds over a dense grid of
    W, the applied control is certified, and its true worst case is never above the one of
    the vertex-epigraph control; strictly below where the vertex route applies its
    optimiser's control and the vertex maximum misses the worst case."""
    model, _, _, seq = gain
    Q, R = np.eye(2), R2 * np.eye(1)
    ci = cm.SetSequenceMPC(model, seq, Q, R, K2)
    cv = cm.SetSequenceMPC(model, seq, Q, R, K2, minimax="vertices")
    rng = np.random.default_rng(0)
    wrong = from_minimax = 0
    for x in states(seq, rng, 60, [-2, -2], [2, 2]):
        ri, rv = ci.solve(x), cv.solve(x)
        assert ri.certificate.label == rv.certificate.label == "verified"
        assert ri.status == Status.PROVED and ri.horizon == rv.horizon >= 1
        mm = ri.stats["minimax"]
        assert mm["status"] in {s.name for s in Status}
        assert mm["constrained"] == (ri.horizon == 1)  # rows only for K_0 = T
        assert mm["lower"] <= mm["upper"]
        assert "minimax" not in rv.stats and "cost_upper" not in rv.stats
        ti = worst_cost(model, x, ri.u, WS2[None], Q, R)
        tv = worst_cost(model, x, rv.u, WS2[None], Q, R)
        assert ri.stats["cost_upper"] >= ti  # certified worst case of the applied control
        src = ri.certificate.details["source"]
        if src == "interval minimax":
            from_minimax += 1
            assert ri.stats["cost_lower"] == mm["lower"]
            assert ri.stats["cost_upper"] == mm["upper"]
            assert np.array_equal(ri.u, mm["u"])
        else:
            assert "cost_lower" not in ri.stats
        assert ti <= tv + 1e-3 * (1 + tv)
        if rv.certificate.details["source"] == "solver" and tv > rv.cost + 1e-3:
            wrong += 1  # the vertex optimum, whose vertex maximum is wrong
            assert ti < tv - 1e-4, (x, ri.u, rv.u, ti, tv)
            assert "interval minimax" in src
    assert from_minimax >= 20 and wrong >= 3


def test_stats_and_timing_fields(gain):
    model, _, _, seq = gain
    ctrl = cm.SetSequenceMPC(model, seq, np.eye(2), R2, K2,
                             minimax_options={"eps": 0.01, "time_limit": 1.0})
    x = states(seq, np.random.default_rng(3), 1, [-2, -2], [2, 2], (3, None))[0]
    res = ctrl.solve(x)
    mm = res.stats["minimax"]
    assert set(mm) >= {"status", "lower", "upper", "u", "u_feasible", "constrained",
                       "n_boxes", "levels", "elapsed", "message"}
    assert mm["status"] == "PROVED" and mm["upper"] - mm["lower"] < 0.05 * (1 + mm["upper"])
    assert res.stats["minimax_time"] > 0 and res.stats["solve_time"] > 0
    assert ctrl.last_info["minimax"] == "interval"
    # the vertex maximum (the result's cost) is below the certified worst case here
    assert res.cost <= res.stats["cost_upper"]
    # inside T: the local law, no minimax
    r0 = ctrl.solve(np.zeros(2))
    assert r0.mode == "local_law" and "minimax" not in r0.stats


def closed_loop(model, seq, ctrl, x0, steps, rng, w_fixed=None):
    """Run under w drawn in W (or fixed); check every step; return the levels."""
    x = np.asarray(x0, dtype=float)
    levels = []
    for k in range(steps):
        lvl = seq.level(x)
        assert lvl is not None
        res = ctrl.solve(x)
        assert res.certificate.label in {"verified", "local_law"}, (x, res.certificate)
        assert model.U.contains(res.u)
        w = w_fixed if w_fixed is not None else rng.uniform(model.W.lo, model.W.hi)
        xn = model.step(x, res.u, w)
        ln = seq.level(xn)
        assert ln is not None and ln <= max(lvl - 1, 0), (k, x, lvl, xn, ln)
        levels.append(lvl)
        x = xn
    return x, levels


def test_closed_loops_box_union(gain):
    model, _, _, seq = gain
    ctrl = cm.SetSequenceMPC(model, seq, np.eye(2), R2, K2)
    rng = np.random.default_rng(5)
    x0s = states(seq, rng, 6, [-2, -2], [2, 2], (8, None))
    assert len(x0s) == 6
    # w uniform in W, and w = 0 (the interior maximiser of the gain) at every step
    runs = [(x0, None) for x0 in x0s[:4]] + [(x0, np.array([0.0])) for x0 in x0s[4:]]
    for x0, wf in runs:
        xf, levels = closed_loop(model, seq, ctrl, x0, 40, rng, wf)
        assert levels[0] >= 8 and levels[-1] == 0
        assert all(b <= a - 1 for a, b in zip(levels[:-1], levels[1:], strict=True) if a > 0)
        assert np.abs(xf).max() < 0.05


def test_polytopic_sequence_uses_the_rows(gain_poly):
    """K_j held by polytopes: the minimax is constrained to the latest polytope of K_j."""
    model, seq = gain_poly
    assert all(isinstance(M, cm.Polytope) for S in seq.sets for M in getattr(
        S, "members", [S]))
    Q, R = np.eye(2), R2 * np.eye(1)
    ctrl = cm.SetSequenceMPC(model, seq, Q, R, K2)
    rng = np.random.default_rng(7)
    bb = seq.sets[-1].members[-1].bounding_box()
    xs = states(seq, rng, 12, bb.lo, bb.hi)
    assert len(xs) >= 6 and (seq.level(xs) == 2).any()
    for x in xs:
        res = ctrl.solve(x)
        assert res.certificate.label == "verified"
        assert res.stats["minimax"]["constrained"]
        assert res.stats["cost_upper"] >= worst_cost(model, x, res.u, WS2[None], Q, R)
        # the successor lies in K_{i-1} for every w of the dense grid
        Y = model.step(np.broadcast_to(x, (WS2.size, 2)),
                       np.broadcast_to(res.u, (WS2.size, 1)), WS2[:, None])
        lv = seq.level(Y)
        assert ((lv >= 0) & (lv <= res.horizon - 1)).all()
    x0 = xs[np.argmax(seq.level(xs))]
    _, levels = closed_loop(model, seq, ctrl, x0, 10, rng)
    assert levels[-1] == 0


# ============================================================================ 3-state model
XE = np.array([0.5, -0.3, 0.2])


def three_state_model() -> cm.Model:
    """x+ = x + 0.1 (A dx + g(dx) + b(w1) B(x) u + E [0.2 sin(2 w1), w2]), dx = x - xe,
    b(w1) = 1 - 0.3 w1^2: not affine in w, the gain's maximum at w1 = 0 inside W."""
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u", 2)
    w = ca.SX.sym("w", 2)
    dx = x - ca.DM(XE)
    A = ca.DM([[0.2, 1.0, 0.0], [0.0, 0.1, 1.0], [0.3, 0.0, -0.4]])
    g = ca.vertcat(0.3 * dx[1] ** 2, -0.2 * ca.sin(dx[0]) * dx[2], 0.1 * dx[0] * dx[1])
    B = ca.vertcat(ca.horzcat(1 + 0.2 * ca.cos(x[1]), 0),
                   ca.horzcat(0.1 * x[0], 1),
                   ca.horzcat(0, 0.8 + 0.1 * x[2] ** 2))
    E = ca.DM([[0.5, 0.0], [0.0, 0.3], [0.2, -0.2]])
    b = 1 - 0.3 * w[0] ** 2
    f = x + 0.1 * (ca.mtimes(A, dx) + g + b * ca.mtimes(B, u)
                   + ca.mtimes(E, ca.vertcat(0.2 * ca.sin(2 * w[0]), w[1])))
    return cm.Model(x=x, u=u, f=f, w=w, X=cm.Box(XE - 0.6, XE + 0.6),
                    U=cm.Box([-1.0, -1.0], [1.0, 1.0]), W=cm.Box([-0.6, -0.1], [1.0, 0.1]),
                    name="three_state_w2")


@pytest.fixture(scope="module")
def tri():
    model = three_state_model()
    Tb = cm.Polytope.from_box(cm.Box(XE - 0.25, XE + 0.25))
    a = np.array([[1.0, 1.0, 1.0]])
    T = cm.Polytope(np.vstack([Tb.A, a]), np.concatenate([Tb.b, a @ XE + 0.5]))
    seq = cm.controllable_sets(model, T, 0.15, robust=True, assume_invariant=True,
                               max_steps=1, u_eps=1 / 8, progress=False)
    return model, T, seq


def test_three_state_model(tri):
    model, T, seq = tri
    assert np.allclose(model.step(XE, np.zeros(2), np.zeros(2)), XE, atol=1e-15)
    Q, R = np.eye(3), 0.01 * np.eye(2)
    ci = cm.SetSequenceMPC(model, seq, Q, R, x_ref=XE)
    cv = cm.SetSequenceMPC(model, seq, Q, R, x_ref=XE, minimax="vertices")
    assert ci.minimax == "interval" and cv.minimax == "vertices"
    g1, g2 = np.meshgrid(np.union1d(np.linspace(-0.6, 1.0, 81), [0.0]),
                         np.linspace(-0.1, 0.1, 9))
    WS = np.vstack([g1.ravel(), g2.ravel()])
    rng = np.random.default_rng(11)
    B = seq.steps[0]["boxes"]
    idx = rng.integers(0, B.shape[0], 40)
    xs = rng.uniform(B[idx, :, 0], B[idx, :, 1])
    xs = xs[seq.level(xs) == 1][:12]
    assert len(xs) >= 8
    for x in xs:
        ri, rv = ci.solve(x), cv.solve(x)
        assert ri.certificate.label == "verified"
        assert ri.stats["minimax"]["constrained"]  # K_0 = T: its 7 rows
        ti = worst_cost(model, x, ri.u, WS, Q, R, XE)
        tv = worst_cost(model, x, rv.u, WS, Q, R, XE)
        assert ri.stats["cost_upper"] >= ti
        assert ti <= tv + 1e-3 * (1 + tv)
        # one step lands in T for every w of the grid
        k = WS.shape[1]
        Y = model.step(np.broadcast_to(x, (k, 3)), np.broadcast_to(ri.u, (k, 2)), WS.T)
        assert T.contains(Y).all()


# ============================================================================ cm.minimax
u_, w_, p_ = ca.SX.sym("u"), ca.SX.sym("w"), ca.SX.sym("p", 2)
F_P = ca.Function("fp", [u_, w_, p_], [(u_ - p_[0] * w_) ** 2 + p_[1] * u_])
G_P = ca.Function("gp", [u_, w_, p_], [p_[0] * w_ - u_ - 0.2])


def test_minimax_params_match_substitution():
    U, W = cm.Box([-1], [1]), cm.Box([-0.5], [0.5])
    for pv in ([1.0, 0.0], [0.7, 0.3], [-1.3, 0.1]):
        r = minimax(F_P, U, W, 1e-3, G_P, params=pv, progress=False)
        F = ca.Function("f", [u_, w_], [F_P(u_, w_, ca.DM(pv))])
        G = ca.Function("g", [u_, w_], [G_P(u_, w_, ca.DM(pv))])
        r0 = minimax(F, U, W, 1e-3, G, progress=False)
        assert r.status == r0.status == Status.PROVED
        # both brackets are certified for the same problem: they overlap and are narrow
        assert max(r.lower, r0.lower) <= min(r.upper, r0.upper) + 1e-12
        assert r.width < 5e-3 and r0.width < 5e-3
        ws = np.linspace(-0.5, 0.5, 401)
        assert (np.asarray(G(r.u[0], ws)) <= 0).all()
        assert np.asarray(F(r.u[0], ws)).max() <= r.upper


def test_minimax_accepts_a_semantic_extension_and_seed_points():
    U, W = cm.Box([-1], [1]), cm.Box([-0.5], [0.5])
    ext = SemanticExtension(F_P)
    r1 = minimax(ext, U, W, 1e-3, SemanticExtension(G_P), params=[0.7, 0.3], progress=False)
    r2 = minimax(F_P, U, W, 1e-3, G_P, params=[0.7, 0.3], progress=False)
    assert (r1.lower, r1.upper) == (r2.lower, r2.upper) and np.array_equal(r1.u, r2.u)
    # a good seed gives the bracket's upper end at once, even without any bisection
    exact = 0.25  # (u - w)^2 with |w| <= 1/2: u = 0
    sq = ca.Function("sq", [u_, w_], [(u_ - w_) ** 2])
    r = minimax(sq, U, W, 1e-9, points=[[0.0]], max_boxes=1, progress=False)
    assert r.status == Status.BUDGET and r.upper <= exact + 1e-12 and r.u[0] == 0.0
    unseeded = minimax(sq, U, W, 1e-9, max_boxes=1, progress=False)
    assert unseeded.upper >= r.upper
    assert minimax(sq, U, W, 1e-9, points=np.array([0.0]), max_boxes=1,
                   progress=False).upper == r.upper
    # an infeasible seed does not count
    g = ca.Function("g", [u_, w_], [0.2 + w_ - u_])  # feasible iff u >= 0.7
    rg = minimax(sq, U, W, 1e-3, g, points=[[0.0], [0.9]], progress=False)
    assert rg.u[0] >= 0.7 and rg.lower <= 1.44 <= rg.upper


def test_minimax_new_arguments_are_checked():
    U, W = cm.Box([-1], [1]), cm.Box([-0.5], [0.5])
    with pytest.raises(DimensionError, match=r"three inputs \(u, w, p\): give params"):
        minimax(F_P, U, W, 0.1)  # a third input needs params
    sq = ca.Function("sq", [u_, w_], [(u_ - w_) ** 2])
    with pytest.raises(DimensionError, match=r"must take \(u, w, p\).* has 2 inputs"):
        minimax(sq, U, W, 0.1, params=[1.0])
    with pytest.raises(DimensionError, match="parameter input of 2 elements"):
        minimax(F_P, U, W, 0.1, params=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="params must be finite"):
        minimax(F_P, U, W, 0.1, params=[1.0, np.nan])
    with pytest.raises(ValueError, match="mean_value"):
        minimax(SemanticExtension(sq), U, W, 0.1, options={"mean_value": False})
    with pytest.raises(DimensionError, match="points must have shape"):
        minimax(sq, U, W, 0.1, points=[[0.0, 1.0]])
    with pytest.raises(ValueError, match="points must be finite"):
        minimax(sq, U, W, 0.1, points=[[np.inf]])


# ============================================================================ scaling
@pytest.mark.parametrize("s", [1e-6, 1e-3, 1.0, 1e3, 1e6])
@pytest.mark.parametrize("offset", [0.0, 5.0])
def test_one_step_solver_answer_at_every_magnitude_of_u_and_cost(s, offset):
    """The one-step NLP is solved in scaled unknowns (u = mid + half v, costs divided by
    their start value), so sqpmethod's absolute tolerances mean the same whatever the
    magnitude of U, of the gain and of R: the solver's control minimises the worst vertex
    cost over U (no point of a fine grid does better) at every scale and offset of U."""
    from casadi_cmpc.control.linear_sets import SetSequence

    x, u, w = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("w")
    c = offset * s
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * x[0] + 0.3 / s * (u - c) + w)
    model = cm.Model(x=x, u=u, w=w, f=f, X=cm.Box([-1, -1], [1, 1]),
                     U=cm.Box([c - s], [c + s]), W=cm.Box([-0.1], [0.1]), name="scaled")
    B = cm.Box([-1, -1], [1, 1])
    ctrl = cm.SetSequenceMPC(model, SetSequence(sets=[B, B]), R=0.01 / s ** 2,
                             x_ref=[0.0, 0.0], solver="sqp", robust=True,
                             minimax="vertices")
    rng = np.random.default_rng(2)
    G = np.linspace(c - s, c + s, 4001)
    F = ctrl._costfun.map(G.size)
    for xv in rng.uniform(-0.9, 0.9, (15, 2)):
        ug = np.array([c + s * rng.uniform(-1, 1)])
        uo = ctrl._solve_nlp(xv, 0, {}, ug)
        assert uo is not None and c - s <= uo[0] <= c + s
        best = float(np.min(np.asarray(F(np.repeat(xv[:, None], G.size, 1), G[None])[0])))
        got = ctrl._cost(xv, uo)
        assert got <= best + 1e-9 * (1 + best), (xv, uo, got, best)
