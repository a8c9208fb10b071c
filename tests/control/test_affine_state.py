"""One-step and controllable sets by the affine-state method (thesis §6.2, Alg 6.4-6.6)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

import casadi_cmpc as cm
from casadi_cmpc.control.affine_state import inner_boxes
from casadi_cmpc.exceptions import ModelError


@pytest.fixture(scope="module")
def e11():
    return cm.models.load("khalil_affine_state")


def _sample_pieces(res, k: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, n) drawn in the pieces (rejection from each piece's bounding box) and the
    index of a piece holding each."""
    pts, idx = [], []
    for j, P in enumerate(res.pieces):
        bb = P.bounding_box()
        X = bb.lo + rng.random((k, bb.dim)) * (bb.hi - bb.lo)
        ok = P.contains(X)
        pts.append(X[ok])
        idx.append(np.full(int(ok.sum()), j))
    return np.concatenate(pts), np.concatenate(idx)


def _w_vertices(model) -> np.ndarray:
    return np.asarray(model.W.vertices()) if model.l else np.zeros((1, 0))


def _successors_in(model, X, U, target) -> np.ndarray:
    """Whether f(x, u, w) lies in the target for every vertex w of W (N,); enough for a
    model affine in w."""
    ok = np.ones(X.shape[0], dtype=bool)
    for w in _w_vertices(model):
        Y = model.step(X, U, np.broadcast_to(w, (X.shape[0], w.size)))
        ok &= np.asarray(target.contains(Y), dtype=bool)
    return ok


def test_e11_pieces_reach_the_target_with_their_controls_for_all_w(e11):
    m, T = e11.model, e11.terminal
    res = cm.one_step_set(m, T, 0.1, robust=True, progress=False)
    assert res.method.startswith("affine state")  # auto: E11 has an affine state part
    assert len(res.pieces) > 10 and res.witness.shape == (len(res.pieces), 1)
    assert "every w in W" in res.message and "discrete model" in res.message
    rng = np.random.default_rng(0)
    X, k = _sample_pieces(res, 40, rng)
    assert X.shape[0] > 500
    U = res.witness[k]
    assert np.all(np.abs(U) <= 3.0)
    assert _successors_in(m, X, U, T).all()
    assert res.contains(X).all()


def test_e11_pieces_pass_the_lp_check_of_some_admissible_control(e11):
    """The acceptance check of the issue: for sampled points, some u in U sends x into T for
    all w (the model is affine in u and w: an LP in u)."""
    m, T = e11.model, e11.terminal
    res = cm.one_step_set(m, T, 0.1, robust=True, progress=False)
    X, _ = _sample_pieces(res, 5, np.random.default_rng(1))
    H, h = T.A, T.b
    wmax = np.abs(H[:, 1]) * 0.01  # w enters x2+ additively, |w| <= 0.01
    for x in X[:200]:
        a = m.step(x, [0.0], [0.0])  # f(x, 0, 0)
        b = m.step(x, [1.0], [0.0]) - a  # df/du at x
        r = linprog([0.0], A_ub=(H @ b)[:, None], b_ub=h - H @ a - wmax, bounds=[(-3, 3)],
                    method="highs")
        assert r.status == 0


def test_method_auto_and_refusals(e11):
    cannon = cm.models.load("cannon")
    assert not cannon.model.has_affine_state_part
    r = cm.one_step_set(cannon.model, cannon.terminal, 0.2, progress=False)
    assert r.pieces is None and "general" in r.method
    with pytest.raises(ModelError, match="no state that enters f only linearly"):
        cm.one_step_set(cannon.model, cannon.terminal, 0.2, method="affine_state")
    Z = cm.Zonotope(np.zeros(2), 0.1 * np.eye(2))
    with pytest.raises(TypeError, match="polytopic target"):
        cm.one_step_set(e11.model, Z, 0.1, method="affine_state")
    with pytest.raises(ValueError, match="obstacles"):
        cm.one_step_set(e11.model, e11.terminal, 0.1, method="affine_state",
                        obstacles=cm.Box([0.5, 0.5], [0.6, 0.6]))
    with pytest.raises(ValueError, match="u_eps"):
        cm.one_step_set(e11.model, e11.terminal, 0.1, method="affine_state", u_eps=0)
    # with obstacles, auto falls back to the general method
    r = cm.one_step_set(e11.model, e11.terminal, 0.25, progress=False,
                        obstacles=cm.Box([0.5, 0.5], [0.6, 0.6]))
    assert r.pieces is None


def test_area_is_that_of_the_inner_boxes_and_at_least_the_general_one(e11):
    m, T = e11.model, e11.terminal
    res = cm.one_step_set(m, T, 0.05, robust=True, method="affine_state", progress=False)
    B = inner_boxes(res.details, m.X)
    assert B.shape[0] > 0
    # the boxes are inside the pieces (inward rounding) and cover the same area
    rng = np.random.default_rng(2)
    P = B[:, :, 0] + rng.random((B.shape[0], 2)) * (B[:, :, 1] - B[:, :, 0])
    assert res.contains(P).all()
    vol = float(np.prod(B[:, :, 1] - B[:, :, 0], axis=1).sum())
    assert res.area() == pytest.approx(vol, rel=1e-9)
    gen = cm.one_step_set(m, T, 0.05, robust=True, method="general", progress=False)
    assert res.area() >= gen.area()  # 0.2617 against 0.2441 (only x1 is bisected)


def test_nominal_semantics_uses_the_centre_of_w(e11):
    m, T = e11.model, e11.terminal
    rob = cm.one_step_set(m, T, 0.1, robust=True, progress=False)
    nom = cm.one_step_set(m, T, 0.1, robust=False, progress=False)
    assert "centre of W" in nom.message and nom.semantics != rob.semantics
    assert nom.area() >= rob.area()
    X, k = _sample_pieces(nom, 20, np.random.default_rng(3))
    Y = m.step(X, nom.witness[k], np.zeros((X.shape[0], 1)))
    assert T.contains(Y).all()


def _random_model(seed: int):
    """x+ = A x + g(x1, u, w): 3 states, x2 and x3 linear (not from the thesis), a
    non-zero equilibrium-like offset, w additive."""
    rng = np.random.default_rng(seed)
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    a = np.round(rng.uniform(-0.3, 0.3, 6), 3)
    f = ca.vertcat(
        0.9 * x[0] + a[0] * x[0] ** 2 + 0.1 * x[1] + a[1] * ca.sin(x[0]) * u,
        a[2] * x[0] ** 2 + 0.95 * x[1] + 0.1 * x[2] + a[3] * u,
        a[4] * x[0] + 0.9 * x[2] + 0.2 * u + w + a[5],
    )
    return cm.Model(x=x, u=u, f=f, w=w, X=cm.Box([-1, -1, -1], [1, 1, 1]),
                    U=cm.Box([-1], [1]), W=cm.Box([-0.01], [0.01]), name="rand3")


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000), r=st.floats(0.3, 0.8), c=st.floats(-0.2, 0.2))
def test_three_states_two_linear_pieces_verified_by_sampling(seed, r, c):
    m = _random_model(seed)
    assert m.nonlinear_states == (0,) and m.linear_states == (1, 2)
    # a box target around an off-centre point, as a polytope with rows of other norms
    T = cm.Polytope(np.vstack([np.eye(3) * 3.0, -np.eye(3) / 3.0]),
                    np.concatenate([3.0 * (c + r) * np.ones(3), -(c - r) / 3.0 * np.ones(3)]))
    res = cm.one_step_set(m, T, 0.25, robust=True, method="affine_state", u_eps=1 / 8,
                          progress=False)
    if not len(res.pieces):
        return
    X, k = _sample_pieces(res, 30, np.random.default_rng(seed))
    assert _successors_in(m, X, res.witness[k], T).all()


def test_three_state_area_of_polytope_slices_matches_sampling():
    m = _random_model(7)
    T = cm.Polytope.from_box(cm.Box([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]))
    res = cm.one_step_set(m, T, 0.25, robust=True, method="affine_state", u_eps=1 / 4,
                          progress=False)
    assert len(res.pieces) > 0
    rng = np.random.default_rng(0)
    P = -1 + 2 * rng.random((40_000, 3))
    est = 8.0 * res.contains(P).mean()
    assert res.area() == pytest.approx(est, abs=0.05 + 0.05 * est)


def test_affine_sequence_levels_decrease_along_stored_controls(e11):
    m, T = e11.model, e11.terminal
    seq = cm.controllable_sets(m, T, 0.05, robust=True, method="affine_state",
                               law=e11.local_law, max_steps=3, progress=False)
    assert seq.info["terminal_certificate"] == "proved" and "Alg 6.5" in seq.info["method"]
    assert len(seq.sets) == 4 and all(isinstance(S, cm.Polytope) for S in seq.sets)
    assert seq.sets[-1].volume() > 2.5 * T.volume()  # 0.102 -> 0.305 (P_3)
    rng = np.random.default_rng(4)
    for i in range(1, len(seq.sets)):
        P, prev = seq.sets[i], seq.sets[i - 1]
        bb = P.bounding_box()
        X = bb.lo + rng.random((3000, 2)) * (bb.hi - bb.lo)
        X = X[P.contains(X) & ~prev.contains(X)]
        pieces, wit = seq.steps[i - 1]["pieces"], seq.steps[i - 1]["witness"]
        X = X[:150]
        if X.shape[0] == 0:
            continue
        # (pieces, points): exact membership of every point in every piece
        hit = np.array([Q.contains(X) for Q in pieces], dtype=bool).reshape(-1, X.shape[0])
        assert hit.any(axis=0).all(), "a state of P_i outside P_{i-1} lies in no piece"
        u = np.asarray(wit)[hit.argmax(axis=0)]  # the control of the first piece holding x
        assert _successors_in(m, X, u, prev).all()


def test_separating_approximation_of_the_pieces_is_proven_inside(e11):
    """Alg 6.2 on the first step's pieces (Fig 6.7's other polytope)."""
    m, T = e11.model, e11.terminal
    seq = cm.controllable_sets(m, T, 0.1, robust=True, method="affine_state",
                               polytopic_method="separating", law=e11.local_law,
                               max_steps=1, progress=False)
    P1, pieces = seq.sets[1], seq.steps[0]["pieces"]
    X = P1.bounding_box().lo + np.random.default_rng(5).random((4000, 2)) * (
        P1.bounding_box().hi - P1.bounding_box().lo)
    X = X[P1.contains(X)]
    assert X.shape[0] > 100
    assert (pieces.contains(X) | T.contains(X)).all()


def test_affine_sequence_refuses_general_only_options(e11):
    with pytest.raises(ValueError, match="method='general'"):
        cm.controllable_sets(e11.model, e11.terminal, 0.1, method="affine_state",
                             law=e11.local_law, checkpoint="x.npz")
    with pytest.raises(ValueError, match="unknown method"):
        cm.controllable_sets(e11.model, e11.terminal, 0.1, method="boxes",
                             law=e11.local_law)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 4), st.integers(1, 5), st.booleans())
def test_union_area_of_two_linear_states_equals_the_exact_decomposition(seed, t, K, shared):
    """The slab sweep of union_volume (two linear states) against the disjoint
    decomposition by polytope differences, on random polygons in a box (axis-parallel
    rows included)."""
    from casadi_cmpc.control.affine_state import _union_area_2d, _union_of

    rng = np.random.default_rng(seed)
    D = cm.Box([-1.0, -0.5], [1.0, 2.0])
    I = np.eye(2)
    Ms = [rng.normal(size=(t, 2))] * K if shared else [rng.normal(size=(t, 2))
                                                        for _ in range(K)]
    if seed % 3 == 0:
        Ms = [np.vstack([[0.0, 1.0], M[1:]]) for M in Ms]  # a horizontal edge
    if seed % 4 == 0:
        Ms = [np.vstack([[1.0, 0.0], M[1:]]) for M in Ms]  # a vertical edge
    cs = [0.8 * rng.normal(size=t) for _ in range(K)]
    polys = [cm.Polytope(np.vstack([M, I, -I]), np.concatenate([c, D.hi, -D.lo]))
             for M, c in zip(Ms, cs, strict=True)]
    exact = _union_of(polys)
    assert _union_area_2d(Ms, cs, D) == pytest.approx(exact, rel=1e-9, abs=1e-12)


def test_membership_by_cells_equals_the_test_of_every_piece(e11):
    """contains() and control() ask only the pieces of the x_NL cells holding a point; the
    answers (and the first piece, whose control is returned) are those of asking every
    piece in order, also for points on the faces shared by two cells."""
    m, T = e11.model, e11.terminal
    res = cm.one_step_set(m, T, 0.1, robust=True, progress=False)
    rng = np.random.default_rng(4)
    X = m.X.lo + rng.random((3000, 2)) * (m.X.hi - m.X.lo)
    nl = list(res.details["nl"])
    edges = np.unique(res.details["boxes"][:, 0, :])  # one nonlinear state
    X[:600, nl[0]] = rng.choice(edges, 600)  # on the faces between cells
    first = res._first_piece(X)
    ref = np.full(X.shape[0], -1)
    for k, P in enumerate(res.pieces.polytopes):
        ref[(ref < 0) & P.contains(X)] = k
    assert np.array_equal(first, ref) and (ref[:600] >= 0).sum() > 20
    assert np.array_equal(res.contains(X), ref >= 0)
    i = int(np.flatnonzero(ref[:600] >= 0)[0])
    assert np.array_equal(res.control(X[i]), res.witness[ref[i]])


# ------------------------------------------------- Alg 6.5's closed-form slice ranges
def _exact_slice(A, b, x_nl, nl, j):
    """The exact x_j interval of ``{A x <= b}`` at the point x_nl (rationals): (lo, hi),
    None when empty."""
    from fractions import Fraction as F

    lo, hi = None, None
    for row, c in zip(A, b, strict=True):
        rest = F(float(c)) - sum((F(float(row[i])) * F(float(v)) for i, v in zip(nl, x_nl,
                                                                             strict=True)),
                                 F(0))
        a = F(float(row[j]))
        if a == 0:
            if rest < 0:
                return None
        elif a > 0:
            hi = rest / a if hi is None else min(hi, rest / a)
        else:
            lo = rest / a if lo is None else max(lo, rest / a)
    if lo is not None and hi is not None and lo > hi:
        return None
    return lo, hi


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2 ** 31), p=st.integers(1, 3), k=st.integers(1, 8),
       log_s=st.floats(-6, 6), shift=st.floats(-1e6, 1e6))
def test_slice_ranges_contain_the_exact_ranges(seed, p, k, log_s, shift):
    """The closed-form x_L range of every grid cell contains the exact range at every
    sampled x_NL of the cell (rationals), and a slice it calls empty has no point."""
    from casadi_cmpc.control.affine_state import _slice_range

    rng = np.random.default_rng(seed)
    n = p + 1
    s = 10.0 ** log_s
    A = rng.normal(size=(k, n))
    A[rng.random((k, n)) < 0.2] = 0.0
    c = shift * rng.uniform(-1, 1, n)
    b = A @ c + s * rng.uniform(-0.5, 2.0, k)
    nl, j = list(range(p)), p
    lo = c[nl] + s * rng.uniform(-2, 2, (12, p))
    cells = np.stack([lo, lo + s * rng.uniform(0.01, 1.0, (12, p))], axis=-1)
    L, H = _slice_range(A, b, cells, nl, j)
    for q in range(cells.shape[0]):
        pts = rng.uniform(cells[q, :, 0], cells[q, :, 1], (15, p))
        pts = np.vstack([pts, cells[q, :, 0], cells[q, :, 1]])
        for x in pts:
            got = _exact_slice(A, b, x, nl, j)
            if got is None:
                continue
            assert not L[q] > H[q]  # a slice called empty has this point's interval
            glo, ghi = got
            if glo is not None:
                assert L[q] <= glo
            if ghi is not None:
                assert ghi <= H[q]
            if glo is None:
                assert L[q] == -np.inf
            if ghi is None:
                assert H[q] == np.inf
