"""Polytope: representation conversions, LP queries, box tests, set operations.

Results are checked against the definitions by sampling and by independent LPs
(scipy.optimize.linprog called directly, not through the library).
"""

import doctest
import itertools
import math
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

import casadi_cmpc as cm
from casadi_cmpc.exceptions import (
    DimensionError,
    EmptySetError,
    InvalidBoundsError,
    UnboundedSetError,
)
from casadi_cmpc.sets import polytope as polytope_module

TOL = 1e-7


# ----------------------------------------------------------------- helpers
def random_hull(rng, n, k, scale=1.0, centre=None):
    """Convex hull of k random Gaussian points."""
    c = np.zeros(n) if centre is None else np.asarray(centre, float)
    return cm.Polytope.from_vertices(c + scale * rng.normal(size=(k, n)))


def random_halfspaces(rng, n, m, box=1.0):
    """m random half-spaces through a neighbourhood of 0, intersected with [-box, box]^n."""
    A = rng.normal(size=(m, n))
    b = rng.uniform(0.2, 1.0, m) * np.linalg.norm(A, axis=1)
    B = cm.Polytope.from_box(cm.Box(-box * np.ones(n), box * np.ones(n)))
    return cm.Polytope(A, b) & B


def sample_in(P, k, rng, tries=200):
    """Uniform rejection samples of a bounded full-dimensional polytope (k, n)."""
    B = P.bounding_box()
    out = []
    for _ in range(tries):
        x = B.lo + (B.hi - B.lo) * rng.random((max(4 * k, 100), P.dim))
        out.append(x[P.contains(x)])
        if sum(len(o) for o in out) >= k:
            break
    pts = np.vstack(out)[:k]
    assert len(pts) == k
    return pts


def lp_feasible(A_ub, b_ub, A_eq=None, b_eq=None, bounds=(None, None)):
    res = linprog(np.zeros(np.shape(A_ub)[1] if A_ub is not None else np.shape(A_eq)[1]),
                  A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method="highs")
    return res.status == 0


def lp_max(c, A, b, bounds=(None, None)):
    res = linprog(-np.asarray(c, float), A_ub=A, b_ub=b, bounds=bounds, method="highs")
    if res.status == 3:
        return np.inf
    assert res.status == 0
    return -res.fun


def in_hull_lp(V, x, tol=1e-9):
    """x in conv(V), by the LP lambda >= 0, sum lambda = 1, V^T lambda = x (with slack)."""
    k = V.shape[0]
    A_eq = np.vstack([V.T, np.ones((1, k))])
    b_eq = np.concatenate([x, [1.0]])
    # allow a tiny slack s: |V^T lambda - x| <= s, minimise s
    n = V.shape[1]
    c = np.zeros(k + 1)
    c[-1] = 1.0
    A_ub = np.vstack([np.hstack([V.T, -np.ones((n, 1))]), np.hstack([-V.T, -np.ones((n, 1))])])
    b_ub = np.concatenate([x, -x])
    A_eq2 = np.hstack([np.ones((1, k)), np.zeros((1, 1))])
    res = linprog(c, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq2, b_eq=[1.0],
                  bounds=[(0, None)] * (k + 1), method="highs")
    del A_eq, b_eq
    return res.status == 0 and res.fun <= tol


def corners(box):
    lo, hi = box[:, 0], box[:, 1]
    n = len(lo)
    bits = np.array(list(itertools.product((0, 1), repeat=n)), dtype=bool)
    return np.where(bits, hi, lo)


# ------------------------------------------------------------ construction
def test_protocol_and_backward_compatible_surface():
    P = cm.Polytope([[1, 0], [-1, 0], [0, 1], [0, -1]], [1, 2, 3, 4])
    assert isinstance(P, cm.SetBase)
    assert P.dim == 2 and P.n_constraints == 4
    assert P.contains([0.0, 0.0]) is True
    np.testing.assert_array_equal(P.contains([[1.0, 3.0], [1.5, 0.0]]), [True, False])
    assert P.contains([1.0 + 1e-9, 0.0], tol=1e-8)
    assert repr(P) == "Polytope(dim=2, constraints=4)"
    assert "hull" in polytope_module.__all__


def test_validation_errors():
    with pytest.raises(DimensionError, match="2-D"):
        cm.Polytope([1.0, 0.0], [1.0])
    with pytest.raises(InvalidBoundsError, match="NaN"):
        cm.Polytope([[np.nan, 0.0]], [1.0])
    P = cm.Polytope.from_box(cm.Box([0, 0], [1, 1]))
    with pytest.raises(DimensionError, match="wrong dimension"):
        P.contains_box(np.zeros((3, 3, 2)))
    with pytest.raises(DimensionError, match="columns"):
        P.affine_map(np.eye(3))
    with pytest.raises(ValueError, match="distinct coordinates"):
        P.project([0, 0])
    with pytest.raises(ValueError, match="Unknown projection method"):
        P.project([0], method="magic")
    with pytest.raises(DimensionError, match="wrong dimension"):
        P & cm.Polytope.from_box(cm.Box([0], [1]))
    with pytest.raises(TypeError, match="Polytope or a Box"):
        P.intersect("not a set")
    with pytest.raises(DimensionError, match="non-empty"):
        cm.Polytope.from_vertices(np.zeros((0, 2)))
    with pytest.raises(InvalidBoundsError):
        cm.Polytope.from_vertices([[0.0, np.inf]])


def test_vertices_of_box_simplex_and_degenerate_hulls():
    B = cm.Polytope.from_box(cm.Box([-1, 0, 2], [1, 3, 5]))
    V = B.vertices()
    assert V.shape == (8, 3)
    np.testing.assert_allclose(np.sort(V, axis=0), np.sort(cm.Box([-1, 0, 2], [1, 3, 5])
                                                           .vertices(), axis=0), atol=1e-12)
    S = cm.Polytope(np.vstack([-np.eye(4), np.ones((1, 4))]), np.r_[np.zeros(4), 1.0])
    Vs = S.vertices()
    assert Vs.shape == (5, 4)
    assert {tuple(np.round(v, 12)) for v in Vs} == {tuple(r) for r in
                                                    np.vstack([np.zeros(4), np.eye(4)])}
    # hull of points: interior points are dropped and the vertices come back
    rng = np.random.default_rng(0)
    pts = np.vstack([np.eye(3), -np.eye(3), 0.1 * rng.normal(size=(20, 3))])
    O = cm.Polytope.from_vertices(pts)
    assert len(O.vertices()) == 6
    assert O.contains(pts, tol=1e-12).all()
    O2 = cm.Polytope(O.A, O.b)  # forget the cached vertices: enumerate with cddlib
    np.testing.assert_allclose(np.sort(O2.vertices(), axis=0), np.sort(O.vertices(), axis=0),
                               atol=1e-10)
    # a segment and a triangle embedded in higher dimensions
    seg = cm.Polytope.from_vertices([[0.0, 0.0], [1.0, 2.0], [0.5, 1.0]])
    assert len(seg.vertices()) == 2 and not seg.is_full_dimensional()
    assert seg.contains([0.25, 0.5], tol=1e-12) and not seg.contains([0.25, 0.6], tol=1e-9)
    tri = cm.Polytope.from_vertices([[0, 0, 1], [1, 0, 1], [0, 1, 1]])
    assert len(tri.vertices()) == 3 and tri.volume() == 0.0
    pt = cm.Polytope.from_vertices([[1.0, 2.0]])
    np.testing.assert_allclose(pt.vertices(), [[1.0, 2.0]])
    assert pt.chebyshev_ball()[1] == 0.0


def test_empty_and_unbounded_errors():
    E = cm.Polytope([[1, 0], [-1, 0]], [0, -1])  # x <= 0 and x >= 1
    assert E.is_empty() and E.is_bounded()
    for call in (E.vertices, E.volume, E.chebyshev_ball, E.bounding_box):
        with pytest.raises(EmptySetError):
            call()
    assert cm.Polytope([[0.0, 0.0]], [-1.0]).is_empty()
    assert cm.Polytope([[1.0, 0.0]], [-np.inf]).is_empty()
    assert cm.Polytope.empty(3).is_empty()
    np.testing.assert_array_equal(E.support([[1, 0], [0, 1]]), [-np.inf, -np.inf])
    np.testing.assert_array_equal(E.contains_box([[[0, 1], [0, 1]]]), [False])
    np.testing.assert_array_equal(E.intersects_box([[[-5, 5], [-5, 5]]]), [False])
    H = cm.Polytope([[1, 0], [0, 1]], [1, 1])  # a quadrant
    assert not H.is_empty() and not H.is_bounded()
    with pytest.raises(UnboundedSetError, match="unbounded"):
        H.vertices()
    with pytest.raises(UnboundedSetError):
        H.volume()
    with pytest.raises(UnboundedSetError, match="every radius"):
        H.chebyshev_ball()
    # a strip contains balls of radius 1 only
    assert cm.Polytope([[1.0, 0.0], [-1.0, 0.0]], [1.0, 1.0]).chebyshev_ball()[1] == \
        pytest.approx(1.0)
    with pytest.raises(UnboundedSetError, match="plot"):
        H.plot()
    np.testing.assert_array_equal(H.support([[1, 1], [-1, 0]]), [2.0, np.inf])
    B = H.bounding_box()
    assert B.hi[0] >= 1.0 and B.lo[0] == -np.inf
    assert cm.Polytope(np.zeros((0, 2)), np.zeros(0)).is_bounded() is False
    # a strip is bounded in no direction along it; its Chebyshev radius is finite
    strip = cm.Polytope([[1.0, 0.0], [-1.0, 0.0]], [1.0, 1.0])
    assert not strip.is_bounded()
    assert strip.is_full_dimensional()


def test_chebyshev_ball_and_full_dimension():
    c, r = cm.Polytope.from_box(cm.Box([0, 0], [4, 2])).chebyshev_ball()
    assert r == pytest.approx(1.0)
    assert c[1] == pytest.approx(1.0) and 1.0 - 1e-9 <= c[0] <= 3.0 + 1e-9
    T = cm.Polytope.from_vertices([[0, 0], [3, 0], [0, 4]])  # inradius (3+4-5)/2
    c, r = T.chebyshev_ball()
    assert r == pytest.approx(1.0)
    np.testing.assert_allclose(c, [1.0, 1.0], atol=1e-9)
    flat = cm.Polytope([[1, 0], [-1, 0], [0, 1], [0, -1]], [1, 1, 0, 0])  # a segment
    assert not flat.is_empty() and not flat.is_full_dimensional()
    assert flat.volume() == 0.0


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_volume_of_box_and_simplex(n):
    rng = np.random.default_rng(n)
    lo = rng.uniform(-2, 0, n)
    hi = lo + rng.uniform(0.5, 2, n)
    assert cm.Polytope.from_box(cm.Box(lo, hi)).volume() == pytest.approx(np.prod(hi - lo))
    S = cm.Polytope(np.vstack([-np.eye(n), np.ones((1, n))]), np.r_[np.zeros(n), 2.0])
    assert S.volume() == pytest.approx(2.0 ** n / math.factorial(n))


def test_volume_of_polygons():
    th = np.linspace(0, 2 * np.pi, 7)[:-1]
    hexagon = cm.Polytope.from_vertices(np.c_[np.cos(th), np.sin(th)])
    assert hexagon.volume() == pytest.approx(3 * np.sqrt(3) / 2)
    # shoelace formula on a random convex polygon
    rng = np.random.default_rng(3)
    P = random_hull(rng, 2, 15)
    V = P.vertices()
    c = V.mean(axis=0)
    V = V[np.argsort(np.arctan2(V[:, 1] - c[1], V[:, 0] - c[0]))]
    area = 0.5 * abs(np.dot(V[:, 0], np.roll(V[:, 1], -1)) - np.dot(V[:, 1], np.roll(V[:, 0],
                                                                                      -1)))
    assert P.volume() == pytest.approx(area)


def test_support_bounding_box_and_minimal_form():
    rng = np.random.default_rng(4)
    P = random_halfspaces(rng, 3, 12)
    V = P.vertices()
    D = rng.normal(size=(20, 3))
    fresh = cm.Polytope(P.A, P.b)  # support by LP (no cached vertices)
    np.testing.assert_allclose(fresh.support(D), (V @ D.T).max(axis=0), atol=1e-9)
    assert isinstance(fresh.support(D[0]), float)
    B = P.bounding_box()
    pts = rng.uniform(V.min(axis=0) - 0.1, V.max(axis=0) + 0.1, (20000, 3))
    inside = pts[P.contains(pts)]
    assert inside.shape[0] > 100 and B.contains(inside).all()
    np.testing.assert_allclose(B.lo, V.min(axis=0), atol=1e-9)
    np.testing.assert_allclose(B.hi, V.max(axis=0), atol=1e-9)
    # redundant rows: duplicates, a scaled copy, a loose row, an implied row
    A = np.vstack([P.A, P.A[:2], 3 * P.A[[3]], [[1.0, 1.0, 1.0]], P.A[[0]] + P.A[[1]]])
    b = np.concatenate([P.b, P.b[:2], 3 * P.b[[3]], [100.0], [P.b[0] + P.b[1]]])
    Q = cm.Polytope(A, b)
    M = Q.minimal()
    assert M.n_constraints <= P.minimal().n_constraints
    assert M == P and Q == P
    assert M.minimal() is M
    assert cm.Polytope(M.A, M.b).minimal().n_constraints == M.n_constraints
    assert P.remove_redundant().n_constraints == P.minimal().n_constraints


# ------------------------------------------------------------- box tests
def _lp_box_max(P, box):
    """max over the box of each row of P, by LP."""
    return np.array([lp_max(a, None, None, bounds=list(map(tuple, box))) for a in P.A])


def _lp_depth(P, box):
    """max r s.t. a_i.x + r <= b_i (unit rows), x in the box: >= 0 iff the box meets P."""
    norms = np.linalg.norm(P.A, axis=1)
    An, bn = P.A / norms[:, None], P.b / norms
    res = linprog(np.r_[np.zeros(P.dim), -1.0], A_ub=np.hstack([An, np.ones((len(bn), 1))]),
                  b_ub=bn, bounds=[*map(tuple, box), (None, 1.0)], method="highs")
    assert res.status == 0
    return -res.fun


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), n=st.integers(1, 4), width=st.floats(0.01, 1.5))
def test_box_tests_agree_with_lp(seed, n, width):
    rng = np.random.default_rng(seed)
    P = random_halfspaces(rng, n, 2 * n + 2)
    c = rng.uniform(-1.3, 1.3, (6, n))
    r = width * rng.random((6, n))
    boxes = np.stack([c - r, c + r], axis=-1)
    inside = P.contains_box(boxes)
    meets = P.intersects_box(boxes)
    for k, box in enumerate(boxes):
        gap = _lp_box_max(P, box) - P.b
        if abs(gap.max()) > 1e-9:
            assert inside[k] == (gap.max() <= 0)
        depth = _lp_depth(P, box)
        if depth > 1e-9:
            assert meets[k]
        elif depth < -1e-7:
            assert not meets[k]


@pytest.mark.parametrize("n", [2, 3, 4, 8])
def test_contains_box_never_true_with_a_corner_outside(n):
    rng = np.random.default_rng(10 + n)
    P = random_hull(rng, n, 4 * n) if n <= 4 else random_halfspaces(rng, n, 4 * n)
    V = P.vertices()
    # boxes around vertices and around points near the boundary: the hardest cases
    base = np.vstack([V, 0.999 * V, 1.001 * V, 0.5 * V])
    base = base[rng.integers(0, len(base), 4000)]
    r = 10.0 ** rng.uniform(-12, -1, (4000, n))
    boxes = np.stack([base - r * rng.random((4000, n)), base + r * rng.random((4000, n))],
                     axis=-1)
    res = P.contains_box(boxes)
    for box in boxes[res]:
        assert P.contains(corners(box)).all()
    assert res.any() and not res.all()
    # intersects_box: never False for a box that holds a point of P
    pts = sample_in(P, 200, rng) if n <= 4 else V[rng.integers(0, len(V), 200)] * 0.99
    rr = 10.0 ** rng.uniform(-12, -1, (200, n))
    boxes = np.stack([pts - rr * rng.random((200, n)), pts + rr * rng.random((200, n))],
                     axis=-1)
    assert P.intersects_box(boxes).all()


def test_contains_box_is_exact_on_touching_boxes():
    # the boxes of a regular subdivision of P itself touch its facets: all are inside
    P = cm.Polytope.from_box(cm.Box([-1.0, -0.3], [0.7, 1.1]))
    g0 = np.linspace(-1.0, 0.7, 18)
    g1 = np.linspace(-0.3, 1.1, 15)
    boxes = np.array([[[a, b], [c, d]] for a, b in zip(g0[:-1], g0[1:], strict=True)
                      for c, d in zip(g1[:-1], g1[1:], strict=True)])
    assert P.contains_box(boxes).all()
    last = boxes[-1].copy()
    last[0, 1] = np.nextafter(last[0, 1], np.inf)
    assert not P.contains_box(last)[0]
    # a row with inexact decimal data: 0.1 x + 0.2 y <= 0.30000000000000004 holds the
    # unit box exactly, 0.1 x + 0.2 y <= 0.3 does not
    assert cm.Polytope([[0.1, 0.2]], [0.30000000000000004]).contains_box(
        [[0, 1], [0, 1]])[0]
    assert not cm.Polytope([[0.1, 0.2]], [0.3]).contains_box([[0, 1], [0, 1]])[0]
    # a box touching a facet from outside still meets P
    assert P.intersects_box([[[0.7, 2.0], [0.0, 0.1]]])[0]
    # a gap of 1e-12 is proven; a gap of one ulp may be answered either way (False must
    # be a proof, so it needs a margin)
    assert not P.intersects_box([[[0.7 + 1e-12, 2.0], [0.0, 0.1]]])[0]


def test_box_tests_with_infinite_bounds_and_unbounded_polyhedra():
    H = cm.Polytope([[1.0, 0.0]], [1.0])  # x <= 1
    boxes = np.array([[[-np.inf, 0.5], [-np.inf, np.inf]], [[0, 2], [0, 1]],
                      [[2, np.inf], [0, 1]], [[1.0, 1.0], [-np.inf, 3.0]]])
    np.testing.assert_array_equal(H.contains_box(boxes), [True, False, False, True])
    np.testing.assert_array_equal(H.intersects_box(boxes), [True, True, False, True])
    Q = cm.Polytope([[1.0, 1.0], [-1.0, 0.0], [0.0, -1.0]], [np.inf, 0.0, 0.0])  # quadrant
    np.testing.assert_array_equal(Q.contains_box([[[0, np.inf], [1, 2]], [[-1, 1], [1, 2]]]),
                                  [True, False])
    assert cm.Polytope(np.zeros((0, 2)), np.zeros(0)).contains_box([[[-1, 1], [0, 1]]])[0]


def test_intersects_box_in_eight_dimensions_uses_certified_lps():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(32, 8))
    P = cm.Polytope(A, np.linalg.norm(A, axis=1))
    V = P.vertices()
    c = V[rng.integers(0, len(V), 60)] * rng.uniform(0.9, 1.1, (60, 1))
    r = rng.uniform(0.01, 0.2, (60, 8))
    boxes = np.stack([c - r, c + r], axis=-1)
    res = P.intersects_box(boxes)
    for k, box in enumerate(boxes):
        depth = _lp_depth(P, box)
        if depth > 1e-9:
            assert res[k]
        elif depth < -1e-6:
            assert not res[k]  # proven by the LP multipliers
    assert res.any() and not res.all()


# ------------------------------------------------------------ set operations
@pytest.mark.parametrize("seed", [0, 1])
def test_intersection_and_hull_by_sampling(seed):
    rng = np.random.default_rng(seed)
    P = random_hull(rng, 2, 10)
    Q = random_hull(rng, 2, 10, centre=[0.5, 0.3])
    I = P & Q
    X = rng.uniform(-3, 3, (3000, 2))
    np.testing.assert_array_equal(I.contains(X), P.contains(X) & Q.contains(X))
    assert I == P.intersect(Q)
    H = cm.hull(P, Q)
    assert H == P.hull(Q)
    VP, VQ = P.vertices(), Q.vertices()
    assert H.contains(np.vstack([VP, VQ]), tol=1e-12).all()
    # points of the defining set (convex combinations of points of P and Q) are in H
    lam = rng.random((300, 1))
    combos = lam * sample_in(P, 300, rng) + (1 - lam) * sample_in(Q, 300, rng)
    assert H.contains(combos, tol=1e-12).all()
    # points sampled in H are convex combinations of the vertices of P and Q
    V = np.vstack([VP, VQ])
    for x in sample_in(H, 40, rng):
        assert in_hull_lp(V, x)
    # and the hull of a 4-D point cloud contains exactly the cloud's hull
    H4 = cm.hull(random_hull(rng, 4, 12), random_hull(rng, 4, 12, centre=np.ones(4)))
    for x in sample_in(H4, 10, rng):
        assert in_hull_lp(H4.vertices(), x)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_difference_by_sampling(seed):
    rng = np.random.default_rng(seed)
    P = random_halfspaces(rng, 2, 6)
    Q = random_hull(rng, 2, 8, scale=0.6, centre=rng.uniform(-0.5, 0.5, 2))
    D = P.difference(Q)
    assert isinstance(D, cm.PolytopeUnion)
    X = rng.uniform(-1.2, 1.2, (5000, 2))
    in_D = D.contains(X, tol=1e-12)
    strictly_in_Q = (X @ Q.A.T < Q.b - 1e-9).all(axis=1)
    # result points satisfy the definition (closure of P minus Q)
    assert (P.contains(X[in_D], tol=1e-9)).all()
    assert not (in_D & strictly_in_Q).any()
    # points of P outside Q are in the result
    np.testing.assert_array_equal(in_D[P.contains(X) & ~Q.contains(X, tol=1e-9)], True)
    vol = sum(piece.volume() for piece in D)
    assert vol == pytest.approx(P.volume() - (P & Q).volume(), rel=1e-9, abs=1e-12)
    # the pieces do not overlap (their pairwise intersections have no interior)
    for A, B in itertools.combinations(D.polytopes, 2):
        assert not (A & B).is_full_dimensional()
    assert len(P.difference(cm.hull(P, Q))) == 0
    assert len(P.difference(P.translate([10.0, 0.0]))) == 1


@pytest.mark.parametrize("seed", [0, 1])
def test_minkowski_and_pontryagin_by_sampling(seed):
    rng = np.random.default_rng(seed)
    P = random_hull(rng, 2, 12)
    Q = random_hull(rng, 2, 6, scale=0.2)
    Q = Q.translate(-Q.vertices().mean(axis=0))
    S = P + Q
    assert S == P.minkowski_sum(Q)
    sums = sample_in(P, 400, rng) + sample_in(Q, 400, rng)
    assert S.contains(sums, tol=1e-9).all()
    # points of S are sums: z - x in Q for some x in P (LP on the stacked rows)
    for z in sample_in(S, 30, rng):
        A_ub = np.vstack([P.A, -Q.A])
        b_ub = np.concatenate([P.b, Q.b - Q.A @ z])
        assert lp_feasible(A_ub, b_ub + 1e-9)
    # the lifted (projection) route agrees with the vertex-sum route
    lifted = cm.Polytope(np.vstack([np.hstack([P.A, np.zeros((P.n_constraints, 2))]),
                                    np.hstack([-Q.A, Q.A])]), np.concatenate([P.b, Q.b]))
    assert lifted.project([2, 3]) == S
    D = P - Q
    VQ = Q.vertices()
    for x in sample_in(D, 200, rng):
        assert P.contains(x + VQ, tol=1e-9).all()
    X = rng.uniform(-3, 3, (3000, 2))
    ok = np.array([P.contains(x + VQ, tol=-1e-9).all() for x in X])
    assert D.contains(X[ok]).all()
    assert (D + Q).is_subset(P)
    # against a Box: P ⊖ [-e, e]^2 shrinks each row by e |a|_1
    E = cm.Box([-0.05, -0.05], [0.05, 0.05])
    PB = P - E
    np.testing.assert_allclose(PB.b, P.b - 0.05 * np.abs(P.A).sum(axis=1))
    assert (PB + E).is_subset(P)
    # translations and scalars
    np.testing.assert_allclose((P + np.array([1.0, 2.0])).vertices().mean(axis=0),
                               P.vertices().mean(axis=0) + [1, 2])
    assert (P - np.array([1.0, 2.0])) == P.translate([-1, -2])
    assert (2.0 * P).volume() == pytest.approx(4 * P.volume())
    assert (-P).contains(-P.vertices(), tol=1e-12).all()


def test_affine_map_and_inverse_image():
    rng = np.random.default_rng(7)
    P = random_hull(rng, 3, 15)
    M = rng.normal(size=(3, 3))
    t = rng.normal(size=3)
    Y = P.affine_map(M, t)
    X = sample_in(P, 300, rng)
    assert Y.contains(X @ M.T + t, tol=1e-9).all()
    assert Y.volume() == pytest.approx(abs(np.linalg.det(M)) * P.volume(), rel=1e-9)
    assert M @ P == P.affine_map(M)
    # rank-deficient and non-square maps
    M2 = rng.normal(size=(2, 3))
    Y2 = P.affine_map(M2, [1.0, -1.0])
    assert Y2 == cm.Polytope.from_vertices(P.vertices() @ M2.T + [1.0, -1.0])
    for y in sample_in(Y2, 20, rng):
        A_eq, b_eq = M2, y - np.array([1.0, -1.0])
        assert lp_feasible(P.A, P.b + 1e-9, A_eq=A_eq, b_eq=b_eq)
    M3 = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # singular
    Y3 = P.affine_map(M3)
    assert not Y3.is_full_dimensional()
    assert Y3.contains(X @ M3.T, tol=1e-9).all()
    # unbounded polyhedron through a singular map: a projection by elimination
    H = cm.Polytope([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0]], [1.0, 1.0, 1.0])  # x <= 1, |y| <= 1
    img = H.affine_map([[0.0, 2.0]])
    assert img.contains([[2.0], [-2.0], [0.0]]).all() and not img.contains([2.5])
    # inverse image: x in Pre iff M x + t in P, on random points
    Pre = P.inverse_image(M, t)
    Z = rng.uniform(-3, 3, (3000, 3))
    np.testing.assert_array_equal(Pre.contains(Z), P.contains(Z @ M.T + t))
    Pre2 = P.inverse_image(rng.normal(size=(3, 2)))
    assert Pre2.dim == 2


def test_projection_of_known_3d_polytopes():
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    cube = cm.Polytope.from_box(cm.Box([-1, -1, -1], [1, 1, 1]))
    sq = (Rz @ cube).project([0, 1])
    r2 = np.sqrt(2)
    assert sq == cm.Polytope.from_vertices([[r2, 0], [0, r2], [-r2, 0], [0, -r2]])
    assert sq.volume() == pytest.approx(4.0)
    octa = cm.Polytope.from_vertices(np.vstack([np.eye(3), -np.eye(3)]))
    for method in ("support", "vertices", "elimination"):
        diamond = octa.project([1, 2], method=method)
        assert diamond == cm.Polytope([[1, 1], [1, -1], [-1, 1], [-1, -1]], np.ones(4))
    # a lower-dimensional projection (a segment) and a 1-D projection
    tri = cm.Polytope.from_vertices([[0, 0, 0], [1, 1, 0], [2, 2, 1]])
    seg = tri.project([0, 1])
    assert not seg.is_full_dimensional()
    assert seg == cm.Polytope.from_vertices([[0, 0], [2, 2]])
    line = octa.project([2])
    assert line.bounding_box().lo[0] == pytest.approx(-1) and line.vertices().shape == (2, 1)
    # projection in a permuted order
    B = cm.Polytope.from_box(cm.Box([0, 1, 2], [1, 3, 6]))
    assert B.project([2, 0]) == cm.Polytope.from_box(cm.Box([2, 0], [6, 1]))
    # unbounded: by elimination
    H = cm.Polytope([[1.0, 1.0, 0.0], [-1.0, 0.0, 0.0]], [1.0, 0.0])
    Hp = H.project([0, 2])
    assert Hp.contains([[0.0, 5.0], [1.0, -3.0]]).all() and not Hp.contains([-0.1, 0.0])


def test_projection_of_random_8d_polytope_with_32_facets():
    rng = np.random.default_rng(8)
    A = rng.normal(size=(32, 8))
    P = cm.Polytope(A, np.linalg.norm(A, axis=1) * rng.uniform(0.5, 1.5, 32))
    t0 = time.perf_counter()
    Q = P.project([1, 4])
    elapsed = time.perf_counter() - t0
    assert elapsed < 5.0
    # compare with the hull of the projected vertices of P (vertex enumeration)
    ref = cm.Polytope.from_vertices(P.vertices()[:, [1, 4]])
    assert Q == ref
    np.testing.assert_allclose(Q.volume(), ref.volume(), rtol=1e-9)
    # and with support values of P in random directions of the plane (LP on P)
    D = rng.normal(size=(30, 2))
    D8 = np.zeros((30, 8))
    D8[:, [1, 4]] = D
    h = np.array([lp_max(d, P.A, P.b) for d in D8])
    np.testing.assert_allclose(Q.support(D), h, rtol=1e-9, atol=1e-9)
    # a 3-D projection as well
    Q3 = P.project([0, 2, 7])
    D3 = rng.normal(size=(10, 3))
    D8 = np.zeros((10, 8))
    D8[:, [0, 2, 7]] = D3
    h3 = np.array([lp_max(d, P.A, P.b) for d in D8])
    np.testing.assert_allclose(cm.Polytope(Q3.A, Q3.b).support(D3), h3, rtol=1e-8, atol=1e-8)


def test_random_projection_by_sampling():
    rng = np.random.default_rng(9)
    P = random_halfspaces(rng, 4, 10)
    Q = P.project([0, 3])
    X = sample_in(P, 500, rng)
    assert Q.contains(X[:, [0, 3]], tol=1e-9).all()
    for y in sample_in(Q, 30, rng):
        A_eq = np.zeros((2, 4))
        A_eq[0, 0] = A_eq[1, 3] = 1.0
        assert lp_feasible(P.A, P.b + 1e-9, A_eq=A_eq, b_eq=y)


def test_subset_and_equality():
    B = cm.Polytope.from_box(cm.Box([0, 0], [1, 1]))
    T = cm.Polytope.from_vertices([[0, 0], [1, 0], [0, 1]])
    assert T.is_subset(B) and not B.is_subset(T)
    assert T.is_subset(cm.Box([0, 0], [1, 1])) and not B.is_subset(cm.Box([0, 0], [1, 0.5]))
    assert B == cm.Box([0, 0], [1, 1])
    assert B != T and B != cm.Polytope.from_box(cm.Box([0], [1]))
    assert cm.Polytope.empty(2).is_subset(T)
    assert not T.is_subset(cm.Polytope.empty(2))
    assert cm.Polytope.empty(2) == cm.Polytope([[1, 0], [-1, 0]], [0, -1])
    with pytest.raises(TypeError):
        hash(B)


def test_save_load_round_trip(tmp_path):
    P = cm.Polytope([[1.0, 0.1], [-0.3, 1.0 / 3.0], [0.0, -1.0]], [1.0 / 7.0, np.inf, 2.5])
    for suffix in (".npz", ".json"):
        path = P.save(tmp_path / f"p{suffix}")
        Q = cm.Polytope.load(path)
        assert isinstance(Q, cm.Polytope)
        np.testing.assert_array_equal(Q.A, P.A)
        np.testing.assert_array_equal(Q.b, P.b)
        assert cm.load_set(path).n_constraints == 3
    E = cm.Polytope(np.zeros((0, 3)), np.zeros(0))
    Q = cm.Polytope.load(E.save(tmp_path / "e.json"))
    assert Q.dim == 3 and Q.n_constraints == 0


def test_plot_two_and_three_dimensions():
    mpl = pytest.importorskip("matplotlib")
    mpl.use("Agg")
    import matplotlib.pyplot as plt

    P = cm.Polytope.from_box(cm.Box([0, 0], [1, 2]))
    ax = P.plot(facecolor="C1")
    assert len(ax.patches) == 1
    octa = cm.Polytope.from_vertices(np.vstack([np.eye(3), -np.eye(3)]))
    ax = octa.plot(dims=(0, 2))
    xy = ax.patches[0].get_xy()
    assert np.abs(xy).max() == pytest.approx(1.0)
    ax = cm.Polytope.empty(2).plot()
    assert len(ax.patches) == 0
    plt.close("all")


def test_docstring_examples():
    result = doctest.testmod(polytope_module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0


@settings(max_examples=60, deadline=None)
@given(pts=st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=12))
@example(pts=[0.0, 1.2712347629046543e-70, -1.0, -2.0])  # an end point within an ulp of 0
def test_hull_of_points_in_one_dimension_is_their_interval(pts):
    """n = 1: the hull of points is [min, max] exactly (no Qhull, which needs 2-D data),
    and the hull of intervals is the interval from the smallest to the largest end."""
    V = np.asarray(pts, dtype=float)[:, None]
    P = cm.Polytope.from_vertices(V)
    lo, hi = float(V.min()), float(V.max())
    assert P.contains(V).all()
    assert not P.contains(np.array([[np.nextafter(hi, np.inf)], [np.nextafter(lo, -np.inf)]])
                          ).any()
    assert sorted(P.vertices().ravel().tolist()) == sorted({lo, hi})
    Q = cm.Polytope.from_box(cm.Box([hi + 1.0], [hi + 2.0]))
    H = cm.hull(P, Q) if hasattr(cm, "hull") else P.hull(Q)
    assert H.contains(np.array([[lo], [hi + 2.0], [0.5 * (hi + hi + 1.0)]])).all()
    assert not H.contains(np.array([[hi + 2.0 + 1e-6 * (1 + abs(hi))]])).any()
