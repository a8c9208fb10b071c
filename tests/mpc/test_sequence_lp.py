"""One-step control along the exact pre-sets of a linear model: the LP (3.9)-(3.10) of
``SetSequenceMPC(..., solver="lp")`` and the candidates the NLP solvers fall back on.

A solver's answer is a candidate; a step is labelled ``verified`` only when the interval
test ``f(x, u, W) ⊆ K_{i-1}`` passes. These tests recheck every verified step in exact
rational arithmetic, and require states that lie in ``K_1`` with some room to spare to be
verified (a target tightened by more than the room, or a solver tolerance taken as exact,
gives "unverified" steps there).
"""

from __future__ import annotations

from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.exceptions import ModelError


def _fr(a) -> list:
    a = np.asarray(a, dtype=float)
    return [Fraction(float(v)) for v in a.ravel()]


def exact_successors(model: cm.Model, x, u) -> tuple[list[list[Fraction]], list, list]:
    """Exact ``A x + B u + E w`` at every vertex of W (one point without w), and the exact
    enclosure ``[c_lo, c_hi]`` of the constant term."""
    A, B, E, c = model.linear_enclosures()
    for M in (A, B, E):
        assert (M[..., 0] == M[..., 1]).all()  # literal coefficients: known exactly
    n, m, l = model.n, model.m, model.l
    A, B, E = A[..., 0], B[..., 0].reshape(n, m), E[..., 0].reshape(n, l)
    xs, us = _fr(x), _fr(u)
    ws = [_fr(w) for w in np.asarray(model.W.vertices())] if l else [[]]
    out = []
    for w in ws:
        y = []
        for i in range(n):
            v = sum((Fraction(float(A[i, j])) * xs[j] for j in range(n)), Fraction(0))
            v += sum((Fraction(float(B[i, j])) * us[j] for j in range(m)), Fraction(0))
            v += sum((Fraction(float(E[i, j])) * w[j] for j in range(l)), Fraction(0))
            y.append(v)
        out.append(y)
    return out, _fr(c[:, 0]), _fr(c[:, 1])


def exactly_in(P: cm.Polytope, y: list[Fraction], clo: list, chi: list) -> bool:
    """``P.A (y + c) <= P.b`` for every c in [clo, chi], the float data taken as exact."""
    for row, b in zip(P.A, P.b, strict=True):
        a = [Fraction(float(v)) for v in row]
        val = sum((ai * yi + max(ai * lo, ai * hi)
                   for ai, yi, lo, hi in zip(a, y, clo, chi, strict=True)), Fraction(0))
        if val > Fraction(float(b)):
            return False
    return True


def exactly_mapped_into(model: cm.Model, S, x, u) -> bool:
    """Every successor (each vertex of W, hence all of W by convexity) lies in one member of
    S (a union only without disturbance), and u lies in U."""
    if not (model.U.lo <= u).all() or not (u <= model.U.hi).all():
        return False
    members = list(getattr(S, "polytopes", None) or [S])
    ys, clo, chi = exact_successors(model, x, u)
    return any(all(exactly_in(P, y, clo, chi) for y in ys) for P in members)


# ----------------------------------------------------------------------------- E1
@pytest.fixture(scope="module")
def e1():
    ex = cm.models.load("linear_sliding")
    seq = cm.linear_controllable_sets(ex.model, ex.terminal, max_steps=30, until=ex.x0s)
    return ex, seq


@pytest.mark.parametrize("solver", ["lp", "ipopt", "sqp"])
def test_e1_closed_loop_along_the_pre_sets_has_no_unverified_step(e1, solver):
    """Fig 3.4: both thesis states reach S, then the origin, every MPC step verified (the
    quadratic cost of 'ipopt' too: x(3) from (-7.2, -5.8) leaves 7e-6 of room in S)."""
    ex, seq = e1
    ctrl = cm.SetSequenceMPC(ex.model, seq, np.eye(2), 1.0, local_law=ex.local_law,
                             solver=solver)
    for x0 in ex.x0s:
        traj = cm.simulate(ex.model, ctrl, x0, steps=30, progress=False)
        assert set(traj.certificate) == {"verified", "local_law"}, traj.summary()
        lv = np.asarray(traj.horizon)
        assert lv[0] == seq.level(x0) >= 1
        assert (np.diff(lv)[lv[:-1] > 0] == -1).all()  # one set per step
        assert np.abs(traj.x[-1]).max() < 0.05
        for k in np.flatnonzero(lv > 0):  # the exact successor lies in K_(level - 1)
            assert exactly_mapped_into(ex.model, seq.sets[lv[k] - 1], traj.x[k], traj.u[k])


def test_e1_lp_minimises_the_gauge_of_the_terminal_hull(e1):
    """(3.9): the applied control minimises max_k T_k x+ over the feasible controls (a grid
    of U gives no smaller value among the controls that reach K_(i-1))."""
    ex, seq = e1
    ctrl = cm.SetSequenceMPC(ex.model, seq, local_law=ex.local_law, solver="lp")
    hull = ex.info["terminal_hull"]
    G = hull.A / hull.b[:, None]
    x = ex.x0s[1]
    r = ctrl.solve(x)
    assert r.certificate.label == "verified"
    lvl = r.horizon
    us = np.linspace(-2, 2, 4001)[:, None]
    Y = ex.model.step(np.repeat(x[None], us.shape[0], 0), us)
    ok = seq.sets[lvl - 1].contains(Y)
    best = (Y[ok] @ G.T).max(axis=1).min()
    assert r.cost <= best + 1e-6
    assert abs(r.cost - (ex.model.step(x, r.u) @ G.T).max()) < 1e-9


def test_lp_refuses_what_it_cannot_solve(e1):
    ex, seq = e1
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    nonlin = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + 0.1 * x[1] ** 2, x[1] + u),
                      X=cm.Box([-8, -8], [8, 8]), U=cm.Box([-2], [2]))
    with pytest.raises(ModelError, match="nonlinear"):
        cm.SetSequenceMPC(nonlin, seq, local_law=np.zeros((1, 2)), solver="lp")
    with pytest.raises(ValueError, match="x_ref strictly inside"):
        cm.SetSequenceMPC(ex.model, seq, local_law=ex.local_law, solver="lp",
                          x_ref=[7.9, 7.9])
    with pytest.raises(ValueError, match="takes none"):
        cm.SetSequenceMPC(ex.model, seq, local_law=ex.local_law, solver="lp",
                          solver_options={"ipopt.max_iter": 3})
    with pytest.raises(ValueError, match="objective of solver='lp'"):
        cm.SetSequenceMPC(ex.model, seq, local_law=ex.local_law,
                          gauge=ex.info["terminal_hull"])
    ctrl = cm.SetSequenceMPC(ex.model, seq, local_law=ex.local_law, solver="lp")
    with pytest.raises(NotImplementedError, match="sqp"):
        ctrl.export_spec()
    # a state outside every set: no control is claimed
    r = ctrl.solve([7.9, 7.9])
    assert r.certificate.label == "not_controllable" and not np.isfinite(r.u).any()


def test_lp_refuses_box_union_sequences():
    x = ca.SX.sym("x")
    u = ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=0.5 * x + u, X=cm.Box([-4], [4]), U=cm.Box([-1], [1]))
    T = cm.Polytope.from_box(cm.Box([-0.5], [0.5]))
    seq = cm.controllable_sets(model, T, 0.1, law=np.zeros((1, 1)), max_steps=2,
                               progress=False)
    with pytest.raises(ValueError, match="polytopes"):
        cm.SetSequenceMPC(model, seq, solver="lp")


# ---------------------------------------------------------- property: random models
@st.composite
def linear_problems(draw):
    """A random linear model (n = 2 or 3, m = 1 or 2, maybe a disturbance) with literal
    coefficients, a target polytope around the origin, and its exact pre-set K_1."""
    n = draw(st.integers(2, 3))
    m = draw(st.integers(1, 2))
    robust = draw(st.booleans())
    coef = st.integers(-12, 12).map(lambda k: k / 8)
    A = np.array([[draw(coef) for _ in range(n)] for _ in range(n)])
    A += 0.5 * np.eye(n)
    B = np.array([[draw(coef) for _ in range(m)] for _ in range(n)])
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u", m)
    f = ca.mtimes(ca.DM(A), x) + ca.mtimes(ca.DM(B), u)
    kw = {}
    if robust:
        w = ca.SX.sym("w")
        E = np.array([draw(st.sampled_from([0.0, 0.1, -0.05, 0.2])) for _ in range(n)])
        f = f + ca.DM(E) * w
        kw = {"w": w, "W": cm.Box([-0.25], [0.25])}
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-4] * n, [4] * n), U=cm.Box([-1] * m, [1] * m),
                     name="random_linear", **kw)
    # target: a box or a random polytope around the origin (contains the ball of 0.6)
    if draw(st.booleans()):
        h = np.array([draw(st.sampled_from([0.75, 1.0, 1.5])) for _ in range(n)])
        T = cm.Polytope.from_box(cm.Box(-h, h))
    else:
        k = draw(st.integers(n + 2, 2 * n + 3))
        seed = draw(st.integers(0, 2 ** 16))
        N = np.random.default_rng(seed).normal(size=(k, n))
        N = np.vstack([N, -N])
        N /= np.linalg.norm(N, axis=1)[:, None]
        T = cm.Polytope(N, np.full(N.shape[0], 0.6) + np.random.default_rng(seed).uniform(
            0, 0.6, N.shape[0]))
    seq = cm.linear_controllable_sets(model, T, max_steps=1)
    return model, T, seq


def states_of(K: cm.Polytope, rng: np.random.Generator) -> list[tuple[np.ndarray, float]]:
    """Points of K: its vertices pulled toward its centre by lam (0: the vertex itself)."""
    V = np.asarray(K.vertices())
    c = V.mean(axis=0)
    out = []
    for v in V[rng.permutation(V.shape[0])[:6]]:
        for lam in (0.0, 1e-6, 0.3):
            out.append(((1 - lam) * v + lam * c, lam))
    return out


@settings(max_examples=20)
@given(linear_problems(), st.sampled_from(["lp", "sqp"]), st.integers(0, 1000))
def test_verified_steps_are_exactly_true_and_inner_states_are_verified(problem, solver, seed):
    model, T, seq = problem
    K1 = seq.sets[1]
    if K1.is_empty():
        return
    ctrl = cm.SetSequenceMPC(model, seq, local_law=np.zeros((model.m, model.n)),
                             solver=solver)
    rng = np.random.default_rng(seed)
    for x, lam in states_of(K1, rng):
        if seq.level(x) != 1:  # in T (the local law), or a rounded vertex outside K_1
            continue
        r = ctrl.solve(x)
        if r.certificate.label == "verified":
            assert exactly_mapped_into(model, T, x, r.u), (x, r.u)
        if lam > 0:  # room of about lam times the centre's: the step must be proven
            assert r.certificate.label == "verified", (x, lam, r.certificate, r.stats)


@pytest.mark.parametrize("solver", ["lp", "ipopt"])
def test_a_state_in_no_set_is_not_controllable_and_ends_a_simulation(e1, solver):
    """Outside every set of the sequence the controller raises NotControllableError (a
    ValueError); simulate ends the run there with stop_reason "not_controllable", a
    warning, and the steps made so far (none from such an x0)."""
    ex, seq = e1
    ctrl = cm.SetSequenceMPC(ex.model, seq, np.eye(2), 1.0, local_law=ex.local_law,
                             solver=solver)
    x0 = ex.model.X.hi * 0.999  # a corner of X, beyond the last set
    assert seq.level(x0) is None
    assert ctrl.solve(x0).certificate.label == "not_controllable"
    with pytest.raises(cm.NotControllableError, match="lies in no set"):
        ctrl(x0)
    with pytest.warns(cm.CmpcWarning, match="lies in no set"):
        traj = cm.simulate(ex.model, ctrl, x0, steps=5, progress=False)
    assert traj.stop_reason == "not_controllable" and traj.steps == 0
    assert np.array_equal(traj.x[-1], x0)
    assert issubclass(cm.NotControllableError, ValueError)
