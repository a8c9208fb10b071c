"""Claims of certificates follow what was checked: the law T was proven with, the
disturbances covered (robust or nominal), and exact membership behind "x in T".

Every "proved" answer below is re-checked exactly (rational arithmetic: the models are
affine, so the successor of a vertex of W is computed exactly with Fractions).
"""

from __future__ import annotations

import math
from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.control.linear_sets import SetSequence

F = Fraction


def _model(w: bool = True) -> cm.Model:
    """x1+ = 0.5 x1 + u (+ w), x2+ = 0.5 x2 (+ w): affine, exactly computable."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    if w:
        ww = ca.SX.sym("w")
        f = ca.vertcat(0.5 * x[0] + u + ww, 0.5 * x[1] + ww)
        return cm.Model(x=x, u=u, w=ww, f=f, X=cm.Box([-4, -4], [4, 4]),
                        U=cm.Box([-3.0], [3.0]), W=cm.Box([-0.1], [0.1]))
    f = ca.vertcat(0.5 * x[0] + u, 0.5 * x[1])
    return cm.Model(x=x, u=u, f=f, X=cm.Box([-4, -4], [4, 4]), U=cm.Box([-3.0], [3.0]))


def _succ(x: np.ndarray, u: np.ndarray, w: float) -> list[Fraction]:
    x1, x2, uu, ww = F(float(x[0])), F(float(x[1])), F(float(u[0])), F(float(w))
    return [F(1, 2) * x1 + uu + ww, F(1, 2) * x2 + ww]


def _in_poly(P: cm.Polytope, y: list[Fraction]) -> bool:
    return all(sum((F(float(a)) * v for a, v in zip(row, y, strict=True)), F(0)) <= F(float(b))
               for row, b in zip(P.A, P.b, strict=True))


def _in_set(S: object, y: list[Fraction]) -> bool:
    """Exact membership in a polytope, a box or a union of them (SetUnion/Paving)."""
    if isinstance(S, cm.Polytope):
        return _in_poly(S, y)
    members = getattr(S, "members", None)
    if members is not None:
        return any(_in_set(M, y) for M in members)
    inner = getattr(S, "inner", None)
    if inner is not None:
        B = np.asarray(inner)
        return any(all(F(float(b[i, 0])) <= y[i] <= F(float(b[i, 1])) for i in range(2))
                   for b in B)
    raise TypeError(type(S).__name__)


T = cm.Polytope.from_box(cm.Box([-1.0, -1.0], [1.0, 1.0]))


@pytest.fixture(scope="module")
def robust_seq() -> SetSequence:
    return cm.controllable_sets(_model(), T, 0.25, robust=True, law=np.zeros((1, 2)),
                                max_steps=2, progress=False)


def test_the_sequence_keeps_the_law_it_was_proven_with(robust_seq: SetSequence) -> None:
    info = robust_seq.info
    assert info["terminal_certificate"] == "proved"
    assert info["terminal_law_key"] and "0" in info["terminal_law"]
    assert info["terminal_W"] == [[-0.1], [0.1]]
    # a different law is refused
    with pytest.raises(ValueError, match="not the law the terminal set was proven"):
        cm.SetSequenceMPC(_model(), robust_seq, local_law=np.array([[3.0, 0.0]]),
                          solver="sqp")
    # without local_law the proven law is applied, and its claim holds exactly
    ctrl = cm.SetSequenceMPC(_model(), robust_seq, solver="sqp")
    x = np.array([1.0, 0.0])
    r = ctrl.solve(x)
    assert r.certificate.label == "local_law" and r.certificate.proved is True
    assert "for all w in W" in r.certificate.claim
    for w in (-0.1, 0.1):
        assert _in_poly(T, _succ(x, r.u, w))
    # the same law given explicitly is accepted
    assert cm.SetSequenceMPC(_model(), robust_seq, local_law=np.zeros((1, 2)),
                             solver="sqp").solve(x).certificate.proved is True


def test_a_law_never_proven_is_not_reported_proved() -> None:
    seq = cm.controllable_sets(_model(w=False), T, 0.25, assume_invariant=True,
                               max_steps=1, progress=False)
    ctrl = cm.SetSequenceMPC(_model(w=False), seq, local_law=np.array([[3.0, 0.0]]),
                             solver="sqp")
    r = ctrl.solve([1.0, 0.0])
    assert r.certificate.label == "local_law"
    assert r.certificate.proved is None and "not proven" in r.certificate.reason
    assert not _in_poly(T, _succ(np.array([1.0, 0.0]), r.u, 0.0))  # the law does leave T


def test_controllable_sets_checks_what_a_certificate_is_about() -> None:
    m = _model()
    cert = cm.certify_invariant(m, T, np.zeros((1, 2)), eps=0.25, progress=False)
    assert cert.proved is True and cert.about["kind"] == "invariance"
    assert cert.about["robust"] is True and "for every x in S and every w in W" in cert.claim
    # accepted for its own T, model and W
    seq = cm.controllable_sets(m, T, 0.5, robust=True, certificate=cert, max_steps=1,
                               progress=False)
    assert seq.info["terminal_law_key"] == cert.about["law_key"]
    # another set (even a subset of S, which need not be invariant)
    T2 = cm.Polytope.from_box(cm.Box([-0.5, -0.5], [0.5, 0.5]))
    with pytest.raises(ValueError, match="another set"):
        cm.controllable_sets(m, T2, 0.5, robust=True, certificate=cert, progress=False)
    # another law than the one named
    with pytest.raises(ValueError, match="proves the law"):
        cm.controllable_sets(m, T, 0.5, robust=True, certificate=cert,
                             law=np.array([[0.1, 0.0]]), progress=False)
    # a nominal certificate does not support a robust sequence
    nom = cm.certify_invariant(m, T, np.zeros((1, 2)), eps=0.25, W=cm.Box([0.0], [0.0]),
                               progress=False)
    assert nom.proved is True and nom.about["robust"] is False
    assert "only (nominal" in nom.claim and "every w in W" not in nom.claim
    with pytest.raises(ValueError, match="covers w in"):
        cm.controllable_sets(m, T, 0.5, robust=True, certificate=nom, progress=False)
    # another model
    other = cm.Model(x=m.x, u=m.u, w=m.w, f=m.f * 1.0 + ca.vertcat(0, 1e-3 * m.x[0]),
                     X=m.X, U=m.U, W=m.W)
    with pytest.raises(ValueError, match="another model"):
        cm.controllable_sets(other, T, 0.5, robust=True, certificate=cert, progress=False)
    # a certificate that says nothing of what it is about
    bare = cm.Certificate("proved", True, "T is invariant", "by hand")
    with pytest.raises(ValueError, match="does not say what it is about"):
        cm.controllable_sets(m, T, 0.5, robust=True, certificate=bare, progress=False)


@pytest.mark.parametrize("robust", [True, False])
def test_sequence_claims_follow_the_robust_flag(robust: bool) -> None:
    m = _model()
    seq = cm.controllable_sets(m, T, 0.25, robust=robust, law=np.zeros((1, 2)),
                               max_steps=2, progress=False)
    ctrl = cm.SetSequenceMPC(m, seq, solver="sqp", robust=robust)
    rng = np.random.default_rng(0)
    checked = 0
    for x in rng.uniform(-2.0, 2.0, (60, 2)):
        r = ctrl.solve(x)
        c = r.certificate
        if c.proved is not True:
            continue
        lvl = r.horizon
        if robust:
            assert "for all w in W" in c.claim and "nominal" not in c.claim
            ws = (-0.1, 0.1)
        else:
            assert "for all w" not in c.claim and "only (nominal" in c.claim
            ws = (0.0,)
        target = T if c.label == "local_law" else seq.sets[lvl - 1]
        for w in ws:
            assert _in_set(target, _succ(x, r.u, w)), (x, r.u, w, c.claim)
        checked += 1
    assert checked > 10


def _nudge(x: np.ndarray, a: np.ndarray, steps: int) -> np.ndarray:
    """Move x by ``steps`` ulps along the sign of a (outward for a row a.x <= b)."""
    y = x.copy()
    for _ in range(steps):
        y = np.array([math.nextafter(v, math.inf if s > 0 else -math.inf) if s != 0 else v
                      for v, s in zip(y, np.sign(a), strict=True)])
    return y


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 4), st.integers(0, 10_000), st.integers(-2, 3))
def test_level_of_T_is_exact(n: int, seed: int, steps: int) -> None:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(2 * n + 1, n))
    A = np.vstack([A, np.eye(n), -np.eye(n)])
    b = np.abs(rng.normal(size=A.shape[0])) + 0.5
    P = cm.Polytope(A, b)
    seq = SetSequence(sets=[P])
    # a point near the facet of row 0: the projection of a random interior point
    x0 = np.zeros(n)
    a = A[0]
    x = x0 + (b[0] - a @ x0) / (a @ a) * a
    x = _nudge(x, a, steps) if steps > 0 else _nudge(x, -a, -steps)
    exact = _in_poly(P, [F(float(v)) for v in x])
    assert bool(P.contains(x)) == exact
    assert (seq.level(x) == 0) == exact
    assert (seq.locate(x)[0] == 0) == exact


def test_contractive_claims_name_the_nominal_w_and_hold_exactly() -> None:
    m = _model()
    ctrl = cm.ContractiveMPC(m, horizon=3, alpha=0.9, norm=2, solver="sqp")
    rng = np.random.default_rng(1)
    n_ver = 0
    for x in rng.uniform(-3.0, 3.0, (20, 2)):
        r = ctrl.solve(x)
        c = r.certificate
        if c.label != "verified":
            continue
        assert "nominal disturbance w = [0.0] only" in c.claim and "for all w" not in c.claim
        # the sequence from x with w = 0, exactly: every state in X, contraction of |x|_2
        xs = [[F(float(v)) for v in x]]
        for u in r.u_seq:
            xs.append([F(1, 2) * xs[-1][0] + F(float(u[0])), F(1, 2) * xs[-1][1]])
        for y in xs[1:]:
            assert all(F(-4) <= v <= F(4) for v in y)
        sq = [sum(v * v for v in y) for y in xs]
        assert sq[-1] <= F(0.9) ** 2 * sq[0]
        n_ver += 1
    assert n_ver > 5


def test_a_sequence_of_another_model_claims_no_step_bound() -> None:
    """A sequence computed for one map f, used by a controller of another: a warning, a
    guarantee without the bound on the steps to T, local-law steps "not proven"; the
    steps this controller certifies hold for its own model."""
    m = _model()
    seq = cm.controllable_sets(m, T, 0.25, robust=True, law=np.zeros((1, 2)), max_steps=2,
                               progress=False)
    same = cm.SetSequenceMPC(m, seq, solver="sqp")
    assert "reached in at most i steps" in same.guarantee
    other = cm.Model(x=m.x, u=m.u, w=m.w, f=m.f + ca.vertcat(0.08, 0.0), X=m.X, U=m.U,
                     W=m.W, name="shifted")
    with pytest.warns(cm.CmpcWarning, match="another map f"):
        ctrl = cm.SetSequenceMPC(other, seq, solver="sqp")
    assert "at most i steps" not in ctrl.guarantee and "not guaranteed" in ctrl.guarantee
    r = ctrl.solve(np.zeros(2))
    assert r.certificate.label == "local_law" and r.certificate.proved is None
    assert "another map f" in r.certificate.reason


@pytest.mark.parametrize("robust_seq, scale", [(True, 3.0), (True, 1.0), (False, 1.0),
                                               (True, 0.5)])
def test_a_sequence_for_a_smaller_w_claims_no_step_bound(robust_seq, scale) -> None:
    """The sets must be proven for every w the controller claims: a sequence computed for
    W (or nominally) used by a robust controller of the same f with a W scaled by
    ``scale``: the step bound only when the sets cover the controller's W; otherwise a
    warning and "not guaranteed". The sequence says for which w its sets hold."""
    m = _model()
    seq = cm.controllable_sets(m, T, 0.25, robust=robust_seq, law=np.zeros((1, 2)),
                               max_steps=2, progress=False)
    expect = [[-0.1], [0.1]] if robust_seq else [[0.0], [0.0]]
    assert seq.info["proof_W"] == expect
    W2 = cm.Box(m.W.lo * scale, m.W.hi * scale)
    m2 = cm.Model(x=m.x, u=m.u, w=m.w, f=m.f, X=m.X, U=m.U, W=W2, name=m.name)
    covered = robust_seq and scale <= 1.0
    if covered:
        ctrl = cm.SetSequenceMPC(m2, seq, solver="sqp")
        assert "reached in at most i steps" in ctrl.guarantee
    else:
        with pytest.warns(cm.CmpcWarning, match="not for every w"):
            ctrl = cm.SetSequenceMPC(m2, seq, solver="sqp", robust=True)
        assert "at most i steps" not in ctrl.guarantee and "not guaranteed" in ctrl.guarantee

def test_a_saved_sequence_keeps_the_w_of_its_proofs(tmp_path) -> None:
    m = _model()
    seq = cm.controllable_sets(m, T, 0.25, robust=True, law=np.zeros((1, 2)), max_steps=2,
                               progress=False)
    seq.save(tmp_path / "s.npz")
    back = SetSequence.load(tmp_path / "s.npz")
    assert back.info["proof_W"] == [[-0.1], [0.1]]
    big = cm.Model(x=m.x, u=m.u, w=m.w, f=m.f, X=m.X, U=m.U, W=cm.Box([-0.2], [0.2]))
    with pytest.warns(cm.CmpcWarning, match="not for every w"):
        cm.SetSequenceMPC(big, back, solver="sqp")


def test_the_reference_defaults_to_the_local_laws_equilibrium(tmp_path) -> None:
    """SetSequenceMPC regulates to the equilibrium of a LinearLaw local law (not to 0),
    and a run's summary gives the final error from that reference beside the norm of x."""
    m = _model()
    seq = cm.controllable_sets(m, T, 0.25, robust=True, law=np.zeros((1, 2)), max_steps=2,
                               progress=False)
    law = cm.LinearLaw(np.zeros((1, 2)), x_eq=[0.25, -0.5], u_eq=[0.0])
    ctrl = cm.SetSequenceMPC(m, seq, solver="sqp", local_law=law)
    np.testing.assert_array_equal(ctrl.x_ref, [0.25, -0.5])
    assert np.array_equal(cm.SetSequenceMPC(m, seq, solver="sqp", x_ref=[0.0, 0.0]).x_ref,
                          [0.0, 0.0])
    tr = cm.simulate(m, ctrl, x0=[0.5, 0.5], steps=3, progress=False)
    s = tr.summary()
    xK = tr.x[-1]
    assert s["final_norm_inf"] == pytest.approx(np.abs(xK).max())
    assert s["final_error_inf"] == pytest.approx(np.abs(xK - [0.25, -0.5]).max())
    back = type(tr).load(tr.save(tmp_path / "t.json"))
    assert back.summary()["final_error_inf"] == s["final_error_inf"]


def test_linear_sequences_say_for_which_w_and_model_their_sets_hold() -> None:
    """linear_controllable_sets records proof_W and the model key, so a controller with a
    larger W warns and claims no step bound (it accepted any W)."""
    m = _model()
    seq = cm.linear_controllable_sets(m, T, max_steps=2)
    assert seq.info["proof_W"] == [[-0.1], [0.1]] and seq.info["model_key"]
    big = cm.Model(x=m.x, u=m.u, w=m.w, f=m.f, X=m.X, U=m.U, W=cm.Box([-1.0], [1.0]))
    with pytest.warns(cm.CmpcWarning, match="not for every w"):
        ctrl = cm.SetSequenceMPC(big, seq, solver="lp")
    assert "at most i steps" not in ctrl.guarantee
