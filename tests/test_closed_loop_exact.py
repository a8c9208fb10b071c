"""Proofs about a closed loop or a nominal disturbance are about the user's model.

Substituting numbers into a CasADi expression folds every subexpression that becomes
constant in floating point: with ``u = 0``, ``exp(u + 0.1)`` becomes ``fl(exp(0.1))``. A
model with a cancelling term ``F (exp(u + 0.1) - fl(exp(0.1)))`` then loses a coefficient of
order ``F * 1e-17``, and a proof made on the rounded graph is about another system. These
tests take such models and check every claim against the exact value (mpmath, 60 digits):
the closed loop's interval evaluators (:meth:`Model.closed_loop`), its structure tests,
``certify_invariant`` on it, and the nominal and robust modal one-step sets.
"""

from __future__ import annotations

import casadi as ca
import mpmath
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm

DPS = 60


def mp(v: float) -> mpmath.mpf:
    """The float ``v`` as an exact mpmath number."""
    return mpmath.mpf(float(v))


def within(value: mpmath.mpf, lo: float, hi: float) -> bool:
    """``lo <= value <= hi`` with the float bounds taken exactly."""
    return mp(lo) <= value <= mp(hi)


# ----------------------------------------------------------------------- reproduction
F_EXP = 1e17
REF_EXP = float(np.exp(0.1))  # what CasADi folds exp(0 + 0.1) to


def rounding_model() -> cm.Model:
    """x+ = (c(u) x1, x2 / 2) with c(u) = 0.5 + 1e17 (exp(u + 0.1) - fl(exp(0.1)))."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] * (0.5 + F_EXP * (ca.exp(u + 0.1) - REF_EXP)), 0.5 * x[1])
    return cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))


def exact_gain() -> mpmath.mpf:
    """c(0), the exact coefficient of x1 in the closed loop under u = 0."""
    with mpmath.workdps(DPS):
        return mp(0.5) + mp(F_EXP) * (mpmath.exp(mp(0.1)) - mp(REF_EXP))


def test_the_exact_gain_makes_the_box_not_invariant():
    c = exact_gain()
    assert c < -7  # about -7.65: x = (1, 0) maps to (c, 0), far outside [-1, 1]^2
    cl = rounding_model().closed_loop(np.zeros((1, 2)))
    # the numeric closed loop is CasADi's folded one (documented): 0.5 x1
    assert cl.step(np.array([1.0, 0.0]))[0] == 0.5


def test_closed_loop_inclusions_contain_the_exact_successor():
    cl = rounding_model().closed_loop(np.zeros((1, 2)))
    c = exact_gain()
    X = np.array([[[1.0, 1.0], [0.0, 0.0]]])
    for kind in ("natural", "centered"):
        enc = cl.inclusion(kind)(X)[0]
        assert within(c, *enc[0]), kind
    J = cl.jacobian_inclusion("x")(np.array([[[0.5, 1.0], [-1.0, 1.0]]]))[0]
    assert within(c, *J[0, 0])
    assert within(mp(0.5), *J[1, 1])
    # a consumer of the model's inclusions: zonotope evolution (Thm 4.4)
    Z = cm.evolve(cl, cm.Zonotope([1.0, 0.0], 1e-6 * np.eye(2)))
    bb = Z.bounding_box()
    assert within(c, bb.lo[0], bb.hi[0])


def test_certify_invariant_does_not_prove_the_rounded_model():
    model = rounding_model()
    S = cm.Polytope.from_box(cm.Box([-1, -1], [1, 1]))
    cert = cm.certify_invariant(model, S, np.zeros((1, 2)), eps=0.1)
    assert cert.proved is not True
    if cert.proved is False:  # a counterexample must be one for the exact model
        x = cert.counterexample
        assert S.contains(x[None])[0]
        c = exact_gain()
        with mpmath.workdps(DPS):
            nxt = (c * mp(x[0]), mp(0.5) * mp(x[1]))
        assert any(abs(v) > 1 for v in nxt)


# ------------------------------------------------------- constants CasADi creates
def test_constants_created_by_the_composition_are_widened():
    """With u = x1, acos(u - x1) becomes acos(0), folded to fl(pi/2) < pi/2."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    ref = float(np.pi / 2)
    f = ca.vertcat(x[1] * (1e16 * (ca.acos(u - x[0]) - ref)), 0.5 * x[0])
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))
    cl = model.closed_loop(x[0])
    with mpmath.workdps(DPS):
        exact = mp(1e16) * (mpmath.pi / 2 - mp(ref))  # about 0.61, f1 = exact * x2
    assert exact > 0.5
    X = np.array([[[0.25, 0.25], [1.0, 1.0]]])
    for kind in ("natural", "centered"):
        assert within(exact, *cl.inclusion(kind)(X)[0, 0]), kind
    J = cl.jacobian_inclusion("x")(np.array([[[0.0, 0.5], [0.5, 1.0]]]))[0]
    assert within(exact, *J[0, 1])


def test_structure_tests_see_what_folding_hides():
    """x1^2 (exp(u + 0.1) - fl(exp(0.1))) folds to 0 under u = 0; exactly it is not 0."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] ** 2 * (ca.exp(u + 0.1) - REF_EXP) + 0.5 * x[0], 0.5 * x[1])
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))
    cl = model.closed_loop(np.zeros((1, 2)))
    assert not cl.is_linear
    assert cl.nonlinear_states == (0,)
    assert cl.linear_states == (1,)


def test_closed_loop_of_a_model_with_a_kept_call():
    """A call kept by never_inline has no interval form: the loop still closes (for
    simulation) and the structure tests take it as nonlinear, as for the open loop."""
    t = ca.SX.sym("t")
    G = ca.Function("G", [t], [2 * t], {"never_inline": True})
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + G(x[1]), x[1] + u),
                     X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))
    cl = model.closed_loop(np.array([[0.0, -0.5]]))
    assert np.allclose(cl.step(np.array([1.0, 1.0])), [3.0, 0.5])
    assert not cl.is_linear


def test_interval_map():
    model = rounding_model()
    cl = model.closed_loop(np.zeros((1, 2)))
    g = cl.interval_map("x")
    assert g.n_in() == 1 and g.numel_in(0) == 2 and g.numel_out(0) == 2
    F = cm.interval.InclusionFunction(g)
    assert within(exact_gain(), *F(np.array([[[1.0, 1.0], [0.0, 0.0]]]))[0][0, 0])
    assert cl.interval_map("xuw", joined=True).numel_in(0) == 2
    assert model.interval_map() is model.function
    with pytest.raises(cm.ModelError, match="depends on u"):
        model.interval_map("x")
    with pytest.raises(ValueError, match="in this order"):
        cl.interval_map("wx")


# ------------------------------------------------------------------ modal one-step sets
def nominal_model(op: str) -> tuple[cm.Model, mpmath.mpf]:
    """x+ = (c(w) x1, x2 / 2 + u), W = [-0.1, 0.1]; the nominal w = 0 folds c(w)."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    if op == "exp":
        F, a, fn, mfn = F_EXP, 0.1, ca.exp, mpmath.exp
    else:
        F, a, fn, mfn = 2e16, 2.0, ca.sqrt, mpmath.sqrt
    ref = float(fn(a))
    f = ca.vertcat(x[0] * (0.5 + F * (fn(w + a) - ref)), 0.5 * x[1] + u)
    model = cm.Model(x=x, u=u, w=w, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]),
                     W=cm.Box([-0.1], [0.1]))
    with mpmath.workdps(DPS):
        c = mp(0.5) + mp(F) * (mfn(mp(a)) - mp(ref))
    return model, c


def box_points(box: np.ndarray, rng: np.random.Generator, k: int = 4) -> np.ndarray:
    """Corners, centre and k random points of a box (d, 2): (2^d + 1 + k, d)."""
    lo, hi = box[:, 0], box[:, 1]
    d = lo.size
    corners = np.array([[hi[j] if (i >> j) & 1 else lo[j] for j in range(d)]
                        for i in range(2 ** d)])
    return np.vstack([corners, 0.5 * (lo + hi), lo + (hi - lo) * rng.random((k, d))])


@pytest.mark.parametrize("op", ["exp", "sqrt"])
def test_modal_nominal_claims_hold_for_the_exact_model(op):
    model, c = nominal_model(op)
    assert abs(c) > 1.2  # the rounded model has c = 0.5: it would claim all of X
    T = cm.Polytope.from_box(cm.Box([-1, -1], [1, 1]))
    eps = 0.25 if op == "exp" else 0.1
    res = cm.one_step_set(model, T, eps, method="modal", robust=False, progress=False,
                          options={"u_depth": 4})
    assert res.semantics == "exists u, w at its nominal value"
    if op == "sqrt":
        assert res.paving.n_inner > 0  # the exact proofs still prove something
    rng = np.random.default_rng(1)
    grid = np.linspace(-1.0, 1.0, 201)
    with mpmath.workdps(DPS):
        for box in res.paving.inner:
            for x in box_points(box, rng):
                # some u in U must put f(x, u, 0) into T; the first component is c x1
                assert abs(c * mp(x[0])) <= 1, (box.tolist(), x.tolist())
                cands = np.concatenate([[np.clip(-0.5 * x[1], -1.0, 1.0)], grid])
                assert any(abs(mp(0.5) * mp(x[1]) + mp(v)) <= 1 for v in cands)


@pytest.mark.parametrize("robust", [False, True])
def test_modal_rows_with_a_constant_component(robust):
    """A constant component f3 = 0.7 against the row 3 x3 <= fl(3 * 0.7): the folded
    product fl(3 * 0.7) meets it, the exact 3 * 0.7 does not, so no state is controllable."""
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    f = ca.vertcat(0.5 * x[0] + u + 0.01 * w, 0.5 * x[1], 0.7)
    model = cm.Model(x=x, u=u, w=w, f=f, X=cm.Box([-1] * 3, [1] * 3), U=cm.Box([-1], [1]),
                     W=cm.Box([-1], [1]))
    A = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 3.0], [0, 0, -1]])
    b = np.array([1, 1, 1, 1, 3 * 0.7, 1])
    with mpmath.workdps(DPS):
        assert 3 * mp(0.7) > mp(b[4])
    res = cm.one_step_set(model, cm.Polytope(A, b), 1.0, method="modal", robust=robust,
                          progress=False, options={"u_depth": 2})
    assert res.paving.n_inner == 0


# ------------------------------------------------------------------ property test
_OPS = {  # name: (casadi, mpmath, numpy, range of the argument)
    "exp": (ca.exp, mpmath.exp, np.exp, (-2.0, 2.0)),
    "sin": (ca.sin, mpmath.sin, np.sin, (-3.0, 3.0)),
    "cos": (ca.cos, mpmath.cos, np.cos, (-3.0, 3.0)),
    "tanh": (ca.tanh, mpmath.tanh, np.tanh, (-3.0, 3.0)),
    "sqrt": (ca.sqrt, mpmath.sqrt, np.sqrt, (0.1, 3.0)),
    "log": (ca.log, mpmath.log, np.log, (0.1, 3.0)),
}


@st.composite
def cancelling_models(draw):
    """A closed loop whose folded graph differs from the exact one, and a state.

    Row ``r``: ``x_k (0.5 + F (op(v + c) - fl(op(a + c)))) + x_j / 4`` with ``v`` the input
    (under the constant law ``u = a``) or the disturbance (evaluated at ``w = a``); the
    other rows ``x_i / 2 + x_{i+1} / 8``, row 0 plus ``u / 10``.
    """
    n = draw(st.integers(2, 4))
    op = draw(st.sampled_from(sorted(_OPS)))
    via = draw(st.sampled_from(["u", "w"]))
    lo, hi = _OPS[op][3]
    fl = st.floats(lo / 2, hi / 2, allow_nan=False, allow_infinity=False)
    a, c = draw(fl), draw(fl)
    F = draw(st.sampled_from([1e8, 1e12, 1e15, 1e17]))
    r, k, j = (draw(st.integers(0, n - 1)) for _ in range(3))
    point = np.array(draw(st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=n,
                                   max_size=n)))
    return n, op, via, a, c, F, r, k, j, point


@settings(max_examples=60)
@given(cancelling_models())
def test_closed_loop_inclusion_contains_the_exact_value(case):
    n, op, via, a, c, F, r, k, j, point = case
    cafn, mpfn, npfn, _ = _OPS[op]
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    ref = float(npfn(a + c))  # the folded value of op(a + c)
    v = u if via == "u" else w
    rows = [0.5 * x[i] + 0.125 * x[(i + 1) % n] for i in range(n)]
    rows[r] = x[k] * (0.5 + F * (cafn(v + c) - ref)) + 0.25 * x[j]
    rows[0] = rows[0] + 0.1 * u
    model = cm.Model(x=x, u=u, w=w, f=ca.vertcat(*rows), X=cm.Box(-np.ones(n), np.ones(n)),
                     U=cm.Box([-5], [5]), W=cm.Box([a - 0.5], [a + 0.5]))
    cl = model.closed_loop(ca.SX(a))
    X = np.stack([point, point], axis=-1)[None]
    W = np.array([[[a, a]]])
    with mpmath.workdps(DPS):
        P = [mp(p) for p in point]
        exact = [mp(0.5) * P[i] + mp(0.125) * P[(i + 1) % n] for i in range(n)]
        exact[r] = P[k] * (mp(0.5) + mp(F) * (mpfn(mp(a) + mp(c)) - mp(ref))) \
            + mp(0.25) * P[j]
        exact[0] = exact[0] + mp(0.1) * mp(a)
        for kind in ("natural", "centered"):
            enc = cl.inclusion(kind)(X, None, W)[0]
            for i in range(n):
                assert within(exact[i], *enc[i]), (kind, i, float(exact[i]), enc[i])
