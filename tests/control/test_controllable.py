"""One-step and controllable sets of nonlinear models (thesis Alg 4.6, 5.2, 6.1) and the
one-step MPC along them (Alg 4.7, 5.4, 6.3), checked against an exact membership oracle.

The oracle: the models used here are affine in u for fixed (x, w) and affine in w for fixed
(x, u) (the Cannon systems: mu enters as ``mu * (...) u``; the 3-state model: ``E w``). For
a polytope ``T = {y : H y <= h}`` and a box W, a state x lies in

* the robust one-step set (exists u for all w) iff one u in U satisfies
  ``H f(x, u, w_v) <= h`` at every vertex ``w_v`` of W (T convex, f affine in w): an LP in u;
* the modal set (for all w exists u) of a model with additive w iff the same LP is feasible
  at every vertex separately (the set of good w is a projection of a polytope, so convex):
  one block-diagonal LP with a separate u per vertex;
* the nominal set iff the LP at the centre of W (or without w) is feasible.

The affine form ``f(x, u, w) = a(x, w) + B(x, w) u`` is obtained numerically from
``model.step`` at ``u = 0`` and ``u = e_j`` (and checked at random u).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import linprog

import casadi_cmpc as cm

GOOD = {"verified", "local_law"}


# ============================================================================ oracle
def affine_forms(model, X, w):
    """``a`` (P, n) and ``B`` (P, n, m) with ``f(x, u, w) = a + B u`` at the points X."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    P, m = X.shape[0], model.m
    wb = None if w is None else np.broadcast_to(np.asarray(w, dtype=float), (P, model.l))
    a = model.step(X, np.zeros((P, m)), wb).reshape(P, model.n)
    B = np.empty((P, model.n, m))
    for j in range(m):
        e = np.zeros((P, m))
        e[:, j] = 1.0
        B[:, :, j] = model.step(X, e, wb).reshape(P, model.n) - a
    return a, B


def w_points(model, kind):
    """The disturbances the oracle quantifies over: W's vertices, its centre, or none."""
    if model.l == 0:
        return [None]
    if kind == "nominal":
        return [0.5 * (model.W.lo + model.W.hi)]
    return list(np.asarray(model.W.vertices(), dtype=float))


def lp_member(model, x, H, h, ws, slack=0.0, modal=False, forms=None):
    """Exact LP membership test of one state x in the one-step set of T = {H y <= h}.

    ``modal=False``: one u for all the w of ``ws`` (exists u for all w); ``modal=True``:
    a separate u for each w (for all w exists u). ``slack`` is added to h.
    """
    m = model.m
    if forms is None:
        forms = [affine_forms(model, x, w) for w in ws]
    rows, rhs = [], []
    k = len(forms)
    for v, (a, B) in enumerate(forms):
        HB = H @ B[0]
        if modal:
            blk = np.zeros((H.shape[0], k * m))
            blk[:, v * m:(v + 1) * m] = HB
            HB = blk
        rows.append(HB)
        rhs.append(h + slack - H @ a[0])
    nu = k * m if modal else m
    bounds = list(zip(model.U.lo, model.U.hi, strict=True)) * (nu // m)
    res = linprog(np.zeros(nu), A_ub=np.vstack(rows), b_ub=np.concatenate(rhs),
                  bounds=bounds, method="highs")
    assert res.status in (0, 2), res.message  # feasible or infeasible, nothing else
    return res.status == 0


def interval_member(model, X, H, h, ws, slack=0.0, tol=0.0):
    """Vectorised exact version of :func:`lp_member` (robust, m = 1): the LP in the scalar u
    is an intersection of half-lines. ``tol`` relaxes ``lo <= hi`` (rounding of a, B)."""
    assert model.m == 1
    X = np.atleast_2d(X)
    P = X.shape[0]
    lo = np.full(P, model.U.lo[0])
    hi = np.full(P, model.U.hi[0])
    ok = np.ones(P, dtype=bool)
    for w in ws:
        a, B = affine_forms(model, X, w)
        c = B[:, :, 0] @ H.T  # (P, r)
        d = h[None] + slack - a @ H.T
        zero = np.abs(c) <= 1e-13
        ok &= np.where(zero, d >= -tol, True).all(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            q = d / c
        hi = np.minimum(hi, np.where((c > 0) & ~zero, q, np.inf).min(axis=1))
        lo = np.maximum(lo, np.where((c < 0) & ~zero, q, -np.inf).max(axis=1))
    return ok & (lo <= hi + tol)


def sample_boxes(boxes, k, rng):
    """k uniform points spread over the boxes (a box chosen uniformly, then a point)."""
    idx = rng.integers(0, boxes.shape[0], size=k)
    lo, hi = boxes[idx, :, 0], boxes[idx, :, 1]
    return lo + (hi - lo) * rng.random(lo.shape), idx


def corners(boxes):
    """All corners of the boxes, (N 2**n, n), and the box of each."""
    N, n, _ = boxes.shape
    bits = (np.arange(2 ** n)[:, None] >> np.arange(n)) & 1  # (2**n, n)
    pts = np.where(bits[None].astype(bool), boxes[:, None, :, 1], boxes[:, None, :, 0])
    return pts.reshape(-1, n), np.repeat(np.arange(N), 2 ** n)


def check_affine(model, rng, k=50):
    """The oracle's premise: f is affine in u for fixed (x, w) and affine in w for fixed
    (x, u) (checked at random points)."""
    X = model.X.sample(k, rng)
    U = model.U.sample(k, rng)
    W = model.W.sample(k, rng) if model.l else None
    a, B = affine_forms(model, X, W)
    assert np.allclose(model.step(X, U, W), a + np.einsum("pij,pj->pi", B, U),
                       rtol=0, atol=1e-12)
    if model.l:
        V = np.asarray(model.W.vertices())
        # affine in w: f at a random w is the matching convex combination of f at the
        # vertices (for a box: multilinear interpolation; exact for affine f)
        t = (W - model.W.lo) / (model.W.hi - model.W.lo)
        lam = np.ones((k, V.shape[0]))
        for j in range(model.l):
            at_hi = V[:, j] == model.W.hi[j]
            lam *= np.where(at_hi[None], t[:, j:j + 1], 1 - t[:, j:j + 1])
        fv = np.stack([model.step(X, U, np.broadcast_to(v, (k, model.l))) for v in V], 1)
        assert np.allclose(model.step(X, U, W), np.einsum("pv,pvi->pi", lam, fv),
                           rtol=0, atol=1e-12)


def check_one_step_sound(model, res, T, kind, rng, k_inner=2000, k_outer=1000, n_lp=300,
                         modal=False, obstacles=()):
    """Inner boxes in the set, outer boxes outside it, stored witnesses valid. Points of
    the (closed) obstacle boxes are outside the set by definition."""
    H, h = np.asarray(T.A, float), np.asarray(T.b, float)
    ws = w_points(model, kind)
    I, O = res.paving.inner, res.paving.outside
    assert I.shape[0] > 0 and O.shape[0] > 0
    # ---------------------------------------------------------------- inner boxes
    Xs, idx = sample_boxes(I, k_inner, rng)
    Xc, idc = corners(I)
    Xi, ii = np.vstack([Xs, Xc]), np.concatenate([idx, idc])
    assert model.X.contains(Xi).all()
    if not modal and model.m == 1:
        assert interval_member(model, Xi, H, h, ws, tol=1e-12).all()
    sub = rng.choice(Xi.shape[0], size=min(n_lp, Xi.shape[0]), replace=False)
    if modal or model.m > 1:
        sub = np.arange(Xi.shape[0]) if Xi.shape[0] <= n_lp else sub
    bad = [Xi[p] for p in sub if not lp_member(model, Xi[p], H, h, ws, modal=modal)]
    assert not bad, f"{len(bad)} points of inner boxes outside the set, e.g. {bad[:3]}"
    # ---------------------------------------------------------------- witnesses
    if modal:
        assert res.witness is None
    else:
        Wt = res.witness
        assert Wt.shape == (I.shape[0], model.m)
        assert model.U.contains(Wt).all()
        u = Wt[ii]
        wl = list(ws) if kind == "nominal" or model.l == 0 else (
            list(ws) + list(model.W.sample(4, rng)))
        for w in wl:
            wb = None if w is None else np.broadcast_to(w, (Xi.shape[0], model.l))
            Y = model.step(Xi, u, wb)
            worst = (Y @ H.T - h).max()
            assert worst <= 1e-12, (w, worst)
    # ---------------------------------------------------------------- outer boxes
    Xo, _ = sample_boxes(O, k_outer, rng)
    for ob in obstacles:
        Xo = Xo[~((Xo >= ob.lo) & (Xo <= ob.hi)).all(axis=1)]
    if not modal and model.m == 1:
        inside = interval_member(model, Xo, H, h, ws, slack=1e-9)
        assert not inside.any(), f"points of outer boxes in the set: {Xo[inside][:5]}"
    sub = rng.choice(Xo.shape[0], size=min(n_lp, Xo.shape[0]), replace=False)
    bad = [Xo[p] for p in sub if lp_member(model, Xo[p], H, h, ws, slack=1e-9, modal=modal)]
    assert not bad, f"{len(bad)} points of outer boxes in the set, e.g. {bad[:3]}"
    return Xi


# ============================================================================ examples
@pytest.fixture(scope="module")
def examples():
    return {name: cm.models.load(name)
            for name in ("cannon", "cannon_robust", "cannon_robust_wide")}


CASES = [  # (example, robust, oracle kind)
    ("cannon", False, "robust"),  # E8: no w, mu = 0.9 fixed
    ("cannon_robust", True, "robust"),  # E9 robust
    ("cannon_robust", False, "nominal"),  # E9 with mu at the centre of W
    ("cannon_robust_wide", True, "robust"),  # E10 robust K1
]


def test_oracle_premise_and_oracles_agree(examples):
    rng = np.random.default_rng(0)
    for ex in examples.values():
        check_affine(ex.model, rng)
    # the vectorised oracle and the LP give the same answers
    ex = examples["cannon_robust"]
    T = ex.terminal
    H, h = np.asarray(T.A), np.asarray(T.b)
    X = ex.model.X.sample(300, rng) * 0.4
    ws = w_points(ex.model, "robust")
    fast = interval_member(ex.model, X, H, h, ws)
    slow = np.array([lp_member(ex.model, x, H, h, ws) for x in X])
    assert 20 < fast.sum() < 280
    assert (fast == slow).all()
    # the terminal set itself: its vertices pulled inwards are in K(T) (T is invariant)
    V = T.vertices()
    assert interval_member(ex.model, 0.999 * V, H, h, ws).all()


@pytest.mark.parametrize("name, robust, kind", CASES)
def test_one_step_set_is_sound(examples, name, robust, kind):
    ex = examples[name]
    res = cm.one_step_set(ex.model, ex.terminal, 0.05, robust=robust, method="general",
                          progress=False)
    assert isinstance(res, cm.OneStepSet)
    assert res.status == cm.Status.PROVED
    expected = {"robust": "exists u for all w", "nominal": "exists u, w at its nominal value"}
    assert res.semantics == (expected[kind] if ex.model.l else "exists u (no disturbance)")
    rng = np.random.default_rng(1)
    Xi = check_one_step_sound(ex.model, res, ex.terminal, kind, rng)
    # contains() and control() agree with the boxes and witnesses
    assert np.all(res.contains(Xi[:200]))
    u = res.control(Xi[0])
    assert u is not None and u.shape == (1,)
    assert res.control(np.array([1e3, 1e3])) is None
    # the set is not trivial: it strictly extends beyond T
    assert (~ex.terminal.contains(Xi)).sum() > 100


def test_robust_set_is_inside_nominal_set(examples):
    """Robust inner boxes (E9) are in the nominal set (w = centre), and the robust K1
    inner boxes of E10 (wider W) fail the E9 oracle nowhere (W_E9 ⊂ W_E10)."""
    ex9, ex10 = examples["cannon_robust"], examples["cannon_robust_wide"]
    T = ex9.terminal
    H, h = np.asarray(T.A), np.asarray(T.b)
    r10 = cm.one_step_set(ex10.model, T, 0.05, robust=True, progress=False)
    rng = np.random.default_rng(2)
    X, _ = sample_boxes(r10.paving.inner, 1000, rng)
    X = X[ex9.model.X.contains(X)]
    assert interval_member(ex9.model, X, H, h, w_points(ex9.model, "robust"), tol=1e-12).all()
    assert interval_member(ex9.model, X, H, h, w_points(ex9.model, "nominal"),
                           tol=1e-12).all()


def test_obstacles_are_avoided(examples):
    ex = examples["cannon"]
    ob1 = cm.Box([-0.3, -0.25], [0.15, 0.05])
    ob2 = cm.Box([0.4, -0.45], [0.6, -0.3])
    free = cm.one_step_set(ex.model, ex.terminal, 0.05, progress=False)
    res = cm.one_step_set(ex.model, ex.terminal, 0.05, obstacles=[ob1, ob2], progress=False)
    I = res.paving.inner
    assert I.shape[0] > 20
    for ob in (ob1, ob2):
        # exact closed-box test: no inner box shares a point with the obstacle
        meets = ((I[:, :, 0] <= ob.hi) & (ob.lo <= I[:, :, 1])).all(axis=1)
        assert not meets.any(), I[meets]
        # the obstacle did cut the obstacle-free set
        Ifree = free.paving.inner
        assert ((Ifree[:, :, 0] < ob.hi) & (ob.lo < Ifree[:, :, 1])).all(axis=1).any()
    assert res.area() < free.area()
    # boxes buried in an obstacle are outside, never inner or boundary
    for B in (res.paving.boundary, res.paving.inner):
        if B.shape[0]:
            inside = ((B[:, :, 0] >= ob1.lo) & (B[:, :, 1] <= ob1.hi)).all(axis=1)
            assert not inside.any()
    # what is left is still sound
    check_one_step_sound(ex.model, res, ex.terminal, "robust", np.random.default_rng(3),
                         k_inner=800, k_outer=400, n_lp=100, obstacles=(ob1, ob2))
    # a single Box and a Polytope obstacle are accepted as well
    r2 = cm.one_step_set(ex.model, ex.terminal, 0.1, obstacles=cm.Polytope.from_box(ob1),
                         progress=False)
    I2 = r2.paving.inner
    assert not ((I2[:, :, 0] <= ob1.hi) & (ob1.lo <= I2[:, :, 1])).all(axis=1).any()


def test_state_box_argument_restricts_the_search(examples):
    ex = examples["cannon"]
    D = cm.Box([-1.0, -1.0], [0.3, 0.5])
    res = cm.one_step_set(ex.model, ex.terminal, 0.05, X=D, progress=False)
    I = res.paving.inner
    assert I.shape[0] > 10
    assert ((I[:, :, 0] >= D.lo) & (I[:, :, 1] <= D.hi)).all()
    check_one_step_sound(ex.model, res, ex.terminal, "robust", np.random.default_rng(14),
                         k_inner=500, k_outer=300, n_lp=50)


def test_modal_method_respects_obstacles(examples):
    ex = examples["cannon_robust"]
    ob = cm.Box([-0.3, -0.25], [0.15, 0.05])
    try:
        res = cm.one_step_set(ex.model, ex.terminal, 0.1, robust=True, method="modal",
                              obstacles=ob, progress=False, options={"u_depth": 3})
    except (ValueError, TypeError):
        return  # refusing the argument would be acceptable too
    I = res.paving.inner
    assert I.shape[0] > 0
    assert not ((I[:, :, 0] <= ob.hi) & (ob.lo <= I[:, :, 1])).all(axis=1).any()


# ============================================================================ 3-state model
XE = np.array([0.5, -0.3, 0.2])


def three_state_model():
    """x+ = x + 0.1 (A (x - xe) + g(x - xe) + B(x) u + E w): equilibrium xe != 0 (u = 0,
    w = 0), nonlinear in x, affine in u and in w."""
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
    f = x + 0.1 * (ca.mtimes(A, dx) + g + ca.mtimes(B, u) + ca.mtimes(E, w))
    return cm.Model(x=x, u=u, f=f, w=w, X=cm.Box(XE - 0.6, XE + 0.6),
                    U=cm.Box([-1.0, -1.0], [1.0, 1.0]), W=cm.Box([-0.1, -0.1], [0.1, 0.1]),
                    name="three_state")


def three_state_target():
    """A box around xe cut by one oblique face (a polytope that is not a box)."""
    Tb = cm.Polytope.from_box(cm.Box(XE - 0.25, XE + 0.25))
    a = np.array([[1.0, 1.0, 1.0]])
    return cm.Polytope(np.vstack([Tb.A, a]), np.concatenate([Tb.b, a @ XE + 0.5]))


@pytest.fixture(scope="module")
def tri():
    model = three_state_model()
    T = three_state_target()
    gen = cm.one_step_set(model, T, 0.1, robust=True, method="general", u_eps=1 / 8,
                          progress=False)
    modal = cm.one_step_set(model, T, 0.15, robust=True, method="modal", progress=False,
                            options={"u_depth": 3})
    return model, T, gen, modal


def test_three_state_model_premise(tri):
    model, T, _, _ = tri
    assert np.allclose(model.step(XE, np.zeros(2), np.zeros(2)), XE, atol=1e-15)
    check_affine(model, np.random.default_rng(4))
    assert T.contains(XE) and not T.contains(XE + 0.24)  # the oblique face is active


def test_three_state_general_is_sound(tri):
    model, T, gen, _ = tri
    assert gen.semantics == "exists u for all w"
    check_one_step_sound(model, gen, T, "robust", np.random.default_rng(5), k_inner=500,
                         k_outer=300, n_lp=1000)


def test_three_state_modal_is_sound(tri):
    model, T, gen, modal = tri
    assert modal.semantics == "for all w exists u (u may depend on w)"
    assert modal.control(XE) is None
    check_one_step_sound(model, modal, T, "robust", np.random.default_rng(6), k_inner=400,
                         k_outer=300, n_lp=1000, modal=True)


def test_three_state_sequence_with_assumed_terminal(tri):
    model, T, _, _ = tri
    seq = cm.controllable_sets(model, T, 0.15, robust=True, assume_invariant=True,
                               max_steps=2, u_eps=1 / 8, progress=False)
    assert seq.info["terminal_certificate"] == "assumed"
    assert len(seq.sets) == 3 and len(seq.steps) == 2
    rng = np.random.default_rng(7)
    V = list(np.asarray(model.W.vertices())) + list(model.W.sample(3, rng))
    for i, st in enumerate(seq.steps, start=1):
        B, Wt = st["boxes"], st["witness"]
        assert B.shape[0] > 0 and model.U.contains(Wt).all()
        X, idx = sample_boxes(B, 300, rng)
        for w in V:
            Y = model.step(X, Wt[idx], np.broadcast_to(w, (X.shape[0], 2)))
            lv = seq.level(Y)
            assert ((lv >= 0) & (lv <= i - 1)).all(), (i, w)


# ============================================================================ sequences
@pytest.fixture(scope="module")
def e8_seq(examples):
    ex = examples["cannon"]
    return ex, cm.controllable_sets(ex.model, ex.terminal, 0.1, law=ex.local_law,
                                    progress=False)


@pytest.fixture(scope="module")
def e9_seq(examples):
    ex = examples["cannon_robust"]
    return ex, cm.controllable_sets(ex.model, ex.terminal, 0.1, robust=True,
                                    law=ex.local_law, until=ex.x0s, progress=False)


@pytest.fixture(scope="module")
def e10_seq(examples):
    ex = examples["cannon_robust_wide"]
    return ex, cm.controllable_sets(ex.model, ex.terminal, 0.05, robust=True,
                                    law=ex.local_law, until=ex.x0s, progress=False)


def points_of_K(seq, i, rng, k=200):
    """Points of K_i: of T (rejection in X) and of the boxes of steps 1..i."""
    T = seq.sets[0]
    bb = T.bounding_box()
    Pt = rng.uniform(bb.lo, bb.hi, size=(4 * k, T.dim))
    Pt = Pt[T.contains(Pt)][:k]
    parts = [Pt]
    boxes = [st["boxes"] for st in seq.steps[:i] if st["boxes"].shape[0]]
    if boxes:
        parts.append(sample_boxes(np.concatenate(boxes), k, rng)[0])
    return np.vstack(parts)


def test_e8_sequence_converges_and_is_nested(e8_seq):
    ex, seq = e8_seq
    assert isinstance(seq, cm.SetSequence)
    assert seq.status == "converged"
    assert seq.converged_at == len(seq.sets) - 1 == len(seq.steps)
    assert seq.steps[-1]["boxes"].shape[0] == 0
    assert all(st["boxes"].shape[0] > 0 for st in seq.steps[:-1])
    assert seq.info["terminal_certificate"] == "proved"
    rng = np.random.default_rng(8)
    for i in range(len(seq.sets) - 1):
        P = points_of_K(seq, i, rng, k=60)
        assert seq.sets[i].contains(P).all()
        assert seq.sets[i + 1].contains(P).all(), i  # K_i ⊆ K_{i+1} (then by induction)
        lv = seq.level(P)
        assert ((lv >= 0) & (lv <= i)).all()
    # the closed-loop initial state of the thesis is reached
    assert seq.level(ex.x0s[0]) is not None


def test_level_batched_agrees_with_single_points(e8_seq):
    ex, seq = e8_seq
    rng = np.random.default_rng(9)
    P = np.vstack([ex.model.X.sample(300, rng), points_of_K(seq, len(seq.sets) - 1, rng, 100),
                   [[1e3, 1e3]]])
    lv = seq.level(P)
    assert lv.dtype.kind == "i" and lv.shape == (P.shape[0],)
    single = [seq.level(p) for p in P]
    assert all((s is None and b == -1) or (s == b and isinstance(s, int))
               for s, b in zip(single, lv, strict=True))
    assert (lv == -1).any() and (lv == 0).any() and (lv > 5).any()
    # the definition: smallest i with x in K_i
    for p, b in zip(P[:80], lv[:80], strict=True):
        hits = [i for i, S in enumerate(seq.sets) if S.contains(p)]
        assert (hits[0] if hits else -1) == b


def _check_witness_steps(seq, model, rng, ws, k=150, steps=None):
    """Every box of step i with its stored control maps into K_{i-1} (for every w in ws),
    and seq.witness(x) agrees with seq.level(x)."""
    n_checked = 0
    for i, st in enumerate(seq.steps, start=1):
        if steps is not None and i not in steps:
            continue
        B, Wt = st["boxes"], st["witness"]
        if B.shape[0] == 0:
            continue
        assert Wt.shape == (B.shape[0], model.m) and model.U.contains(Wt).all()
        X, idx = sample_boxes(B, k, rng)
        Xc, idc = corners(B[:20])
        X, idx = np.vstack([X, Xc]), np.concatenate([idx, idc])
        for w in ws:
            wb = None if w is None else np.broadcast_to(w, (X.shape[0], model.l))
            lv = seq.level(model.step(X, Wt[idx], wb))
            assert ((lv >= 0) & (lv <= i - 1)).all(), (i, w, X[(lv < 0) | (lv > i - 1)][:3])
        lvx = seq.level(X)
        assert (lvx <= i).all() and (lvx >= 0).all()
        for x, lx in zip(X[:25], lvx[:25], strict=True):
            wit = seq.witness(x)
            if lx == 0 and wit is None:
                continue
            j, u = wit
            assert j <= i and (lx == 0 or j == lx)
            for w in ws:
                lv = seq.level(model.step(x, u, w))
                assert lv is not None and lv <= j - 1
        n_checked += 1
    assert n_checked > 0


def test_e8_witnesses_reach_the_previous_set(e8_seq):
    ex, seq = e8_seq
    _check_witness_steps(seq, ex.model, np.random.default_rng(10), [None], k=100)


def test_e9_robust_witnesses_reach_the_previous_set_for_every_mu(e9_seq):
    ex, seq = e9_seq
    assert seq.status == "until" and seq.level(ex.x0s[0]) is not None
    assert seq.info["semantics"] == "exists u for all w" and seq.info["robust"] is True
    rng = np.random.default_rng(11)
    ws = list(np.asarray(ex.model.W.vertices())) + list(ex.model.W.sample(2, rng))
    _check_witness_steps(seq, ex.model, rng, ws, k=100)


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_save_load_round_trip(e8_seq, tmp_path, suffix):
    ex, seq = e8_seq
    path = tmp_path / f"seq{suffix}"
    seq.save(path)
    back = cm.SetSequence.load(path)
    assert isinstance(back, cm.SetSequence)
    assert back.status == seq.status and back.converged_at == seq.converged_at
    assert len(back.sets) == len(seq.sets) and len(back.steps) == len(seq.steps)
    rng = np.random.default_rng(12)
    P = np.vstack([ex.model.X.sample(500, rng), points_of_K(seq, len(seq.sets) - 1, rng)])
    assert np.array_equal(back.level(P), seq.level(P))
    for a, b in zip(seq.steps, back.steps, strict=True):
        assert np.array_equal(a["boxes"], b["boxes"])
        assert np.array_equal(a["witness"], b["witness"])
    x = P[seq.level(P) > 3][0]
    assert back.witness(x)[0] == seq.witness(x)[0]
    assert np.array_equal(back.witness(x)[1], seq.witness(x)[1])


def test_plot_draws(e8_seq):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _, seq = e8_seq
    ax = seq.plot()
    assert len(ax.patches) + len(ax.collections) > 0
    plt.close("all")


def test_terminal_set_must_be_proven_invariant(examples):
    ex = examples["cannon"]
    with pytest.raises(ValueError, match="assume_invariant"):
        cm.controllable_sets(ex.model, ex.terminal, 0.1, progress=False)
    # 6 T leaves X: refused whatever the caller asks
    for kw in ({"law": ex.local_law}, {"assume_invariant": True}):
        with pytest.raises(ValueError, match="inside the state box X"):
            cm.controllable_sets(ex.model, ex.terminal * 6, 0.1, progress=False, **kw)
    # not invariant under the law: a box away from the origin (the law pulls the state out)
    away = cm.Polytope.from_box(cm.Box([1.0, 0.5], [1.4, 0.9]))
    for T in (away,):
        with pytest.raises(ValueError, match="assume_invariant"):
            cm.controllable_sets(ex.model, T, 0.1, law=ex.local_law, progress=False)
        seq = cm.controllable_sets(ex.model, T, 0.1, law=ex.local_law, assume_invariant=True,
                                   max_steps=1, progress=False)
        assert seq.info["terminal_certificate"] == "assumed" and len(seq.sets) == 2
    with pytest.raises(ValueError, match="max_steps"):
        cm.controllable_sets(ex.model, ex.terminal, 0.1, law=ex.local_law, max_steps=0)


def test_budget_stop_is_sound(examples):
    ex = examples["cannon"]
    seq = cm.controllable_sets(ex.model, ex.terminal, 0.05, law=ex.local_law, max_boxes=3000,
                               progress=False)
    assert seq.status == "budget" and seq.converged_at is None
    assert len(seq.sets) == len(seq.steps) + 1
    _check_witness_steps(seq, ex.model, np.random.default_rng(15), [None], k=200)


def test_terminal_set_outside_X_is_not_accepted(examples):
    ex = examples["cannon"]
    T4 = ex.terminal * 4  # proven invariant under the law, but it leaves X = [-2, 2]^2
    assert not ex.model.X.contains(T4.vertices()).all()
    x = np.array([2.3, -1.0])
    assert T4.contains(x) and not ex.model.X.contains(x)
    try:
        seq = cm.controllable_sets(ex.model, T4, 0.1, law=ex.local_law, max_steps=1,
                                   progress=False)
    except ValueError:
        return
    assert seq.level(x) is None


# ============================================================================ MPC
def run_closed_loop(ex, seq, ctrl, x0, steps, rng=None):
    model = ex.model
    x = np.asarray(x0, dtype=float)
    lvl = seq.level(x)
    assert lvl is not None and lvl > 0
    levels = []
    for _ in range(steps):
        res = ctrl.solve(x)
        lvl = seq.level(x)
        assert lvl is not None
        assert res.horizon == lvl
        assert res.certificate.label in GOOD, (x, res.certificate)
        assert res.mode == ("local_law" if lvl == 0 else "mpc")
        u = np.asarray(res.u, dtype=float).reshape(model.m)
        assert model.U.contains(u)
        w = None if model.l == 0 else rng.uniform(model.W.lo, model.W.hi)
        xn = model.step(x, u, w)
        assert model.X.contains(xn)
        ln = seq.level(xn)
        assert ln is not None
        if lvl > 0:
            assert ln <= lvl - 1, (x, lvl, xn, ln)  # contractive: one level per step
        else:
            assert ln == 0  # T is (robustly) invariant under the law
        levels.append(lvl)
        x = xn
    return x, levels


@pytest.mark.parametrize("solver", ["ipopt", "sqp"])
def test_e8_closed_loop(e8_seq, solver):
    ex, seq = e8_seq
    ctrl = cm.SetSequenceMPC(ex.model, seq, np.eye(2), np.eye(1), ex.local_law, solver=solver)
    x0 = np.array([1.9, -1.5])
    assert np.array_equal(ctrl(x0), ctrl.solve(x0).u)
    xf, levels = run_closed_loop(ex, seq, ctrl, x0, 60)
    assert levels[0] == seq.level(x0) and levels[-1] == 0
    assert np.linalg.norm(xf) < 0.02


def test_e9_robust_closed_loops(e9_seq):
    ex, seq = e9_seq
    ctrl = cm.SetSequenceMPC(ex.model, seq, np.eye(2), np.eye(1), ex.local_law)  # Q = R = 1
    assert ctrl.robust
    for seed in (0, 1, 2):
        xf, levels = run_closed_loop(ex, seq, ctrl, np.array([1.75, -1.6]), 60,
                                     np.random.default_rng(seed))
        assert levels[-1] == 0 and np.linalg.norm(xf) < 0.05


@pytest.mark.parametrize("x0", [(-1.5, 1.1), (0.3, -2.1)])
def test_e10_robust_closed_loops(e10_seq, x0):
    ex, seq = e10_seq
    ctrl = cm.SetSequenceMPC(ex.model, seq, np.eye(2), np.eye(1), ex.local_law)
    xf, levels = run_closed_loop(ex, seq, ctrl, np.array(x0), 60, np.random.default_rng(13))
    assert levels[-1] == 0 and np.linalg.norm(xf) < 0.05


@pytest.mark.parametrize("which", ["e8", "e10"])
def test_not_controllable_state(e8_seq, e10_seq, which):
    ex, seq = e8_seq if which == "e8" else e10_seq
    ctrl = cm.SetSequenceMPC(ex.model, seq, None, None, ex.local_law)
    V = np.asarray(ex.model.X.vertices())
    far = [v for v in V if seq.level(v) is None]
    assert far, "some corner of X should lie outside every set"
    x = far[0]
    res = ctrl.solve(x)
    assert res.certificate.label == "not_controllable"
    assert res.horizon is None and not np.isfinite(res.u).any()
    with pytest.raises(ValueError):
        ctrl(x)


def test_e14_cstr_terminal_set_sets_and_closed_loop():
    """E14: the CSTR's terminal polytope (7.10) is proven invariant (its certificate needs
    pieces of 5e-4 relative size), the sets reach (0.4 mol/l, 326 K), and the dual-mode loop
    drives it into T with every step certified."""
    ex = cm.models.load("cstr")
    seq = cm.controllable_sets(ex.model, ex.terminal, 0.004, law=ex.local_law,
                               until=ex.x0s, progress=False)
    assert seq.info["terminal_certificate"] == "proved" and seq.status == "until"
    x0 = ex.x0s[0]
    assert ex.info["x0s_physical"][0].tolist() == [0.4, 326.0]
    ctrl = cm.SetSequenceMPC(ex.model, seq, local_law=ex.local_law)
    xf, levels = run_closed_loop(ex, seq, ctrl, x0, 40, np.random.default_rng(0))
    assert levels[0] == seq.level(x0) >= 1 and levels[-1] == 0
    assert np.abs(xf).max() < 1e-2


def test_e14_one_step_set_is_sound():
    """E14's K1 (Alg 4.6) against the exact LP oracle (the CSTR is affine in u)."""
    ex = cm.models.load("cstr")
    res = cm.one_step_set(ex.model, ex.terminal, 0.004, progress=False)
    assert res.semantics == "exists u (no disturbance)"
    check_one_step_sound(ex.model, res, ex.terminal, "robust", np.random.default_rng(4),
                         k_inner=1000, k_outer=500, n_lp=50)


def test_a_search_that_proves_nothing_is_not_proved():
    """The status reads what was proven: a completed search with no inner box is UNDECIDED
    (boxes left undecided) or DISPROVED (every box outside), never PROVED."""
    import casadi as ca

    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    m = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + 0.5 * x[1], x[1] + 0.1 * u),
                 X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-0.1], [0.1]))
    far = cm.Polytope.from_box(cm.Box([5, 5], [6, 6]))  # out of reach from every state
    r = cm.one_step_set(m, far, 0.25, progress=False)
    assert r.paving.n_inner == 0 and r.status == cm.Status.DISPROVED and not r.success
    coarse = cm.one_step_set(m, cm.Polytope.from_box(cm.Box([-0.05, -0.05], [0.05, 0.05])),
                             0.5, progress=False, u_eps=0.5, max_cells=1)
    assert coarse.paving.n_inner == 0 and coarse.status == cm.Status.UNDECIDED
    assert "no state box proven" in coarse.message and coarse.volume() == 0.0


def test_target_rows_up_to_sign_describe_the_same_polytope():
    """`_signed_rows` (a row and its negation enclosed once, repeated rows merged) keeps
    exactly the set {A x <= b}: random rows with negated copies, repeats, zero rows and
    -0.0 entries, tested on points."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from casadi_cmpc.control.controllable import _signed_rows

    @settings(max_examples=150, deadline=None)
    @given(seed=st.integers(0, 10 ** 6), r=st.integers(1, 12), n=st.integers(1, 4))
    def check(seed, r, n):
        rng = np.random.default_rng(seed)
        # dyadic entries and points: every product and sum below is exact, whatever the
        # order of summation
        A = rng.integers(-3, 4, (r, n)).astype(float) * rng.choice([1.0, 0.5, 2.0 ** -10],
                                                                   (r, 1))
        pick = rng.integers(0, r, r)
        extra = np.where(rng.random((r, 1)) < 0.5, -A[pick], A[pick])  # negated / repeated
        A = np.vstack([A, extra, np.zeros((1, n)), -np.zeros((1, n))])
        b = rng.normal(size=A.shape[0])
        D, lower, upper = _signed_rows(A, b)
        assert D.shape[0] <= A.shape[0] and (lower <= upper).sum() <= D.shape[0]
        P = rng.integers(-64, 65, (400, n)) / 16.0
        want = (P @ A.T <= b).all(axis=1)
        V = P @ D.T
        got = ((V <= upper) & (V >= lower)).all(axis=1)
        assert (want == got).all()

    check()


def test_box_union_target_tests_on_undefined_and_infinite_enclosures():
    """The target tests of a box union (through its exact grid index) on enclosures with
    NaN (possibly undefined) bounds: never inside, never proven outside; with infinite
    bounds (a real beyond the largest float, as the evaluators return them: a lower bound
    is never +inf, an upper one never -inf) never inside the bounded union and proven
    outside exactly when the closed query misses it; on finite enclosures the exact
    answers of the union's own contains / intersects tests."""
    from casadi_cmpc.control.controllable import _Target

    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    m = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + u, x[1]), X=cm.Box([-1, -1], [1, 1]),
                 U=cm.Box([-1], [1]))
    k = np.arange(10) / 10.0
    lo = np.stack(np.meshgrid(k, k, indexing="ij"), -1).reshape(-1, 2)
    lo = lo[(lo.sum(axis=1) < 1.0)]  # a staircase of 55 cells: more than one box needed
    P = cm.Paving(inner=np.stack([lo, lo + 0.1], -1))
    T = _Target(m, P)
    rng = np.random.default_rng(3)
    c = rng.uniform(-0.2, 1.2, (300, 2))
    Y = np.stack([c - 0.03, c + 0.03], -1)
    Y[:40, 0, 0] = np.nan
    Y[40:60, 1, 1] = np.inf
    Y[60:70, 0, 0] = -np.inf
    Y[70:80] = np.nan
    Y[80:90, 1, 1] = np.inf
    Y[80:85, 1, 0] = 5.0  # [5, inf]: misses the union
    bad = ~np.isfinite(Y).all(axis=(1, 2))
    nan = np.isnan(Y).any(axis=(1, 2))
    inside = T.inside_of([], Y)
    outside = T.outside_of([], Y)
    assert not inside[bad].any() and not outside[nan].any()
    inf = bad & ~nan
    meets = ((Y[inf][:, None, :, 0] <= P.inner[None, :, :, 1])
             & (P.inner[None, :, :, 0] <= Y[inf][:, None, :, 1])).all(axis=2).any(axis=1)
    assert np.array_equal(outside[inf], ~meets) and outside[80:85].all()
    fin = ~bad
    assert np.array_equal(inside[fin], P.contains_box(Y[fin], view="inner"))
    assert np.array_equal(outside[fin], ~P.intersects_box(Y[fin], view="inner"))
    assert inside[fin].any() and outside[fin].any() and not (inside & outside).any()
