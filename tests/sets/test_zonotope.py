"""Zonotopes (thesis §4.2): E4 construction/bisection, Kühn inclusion, E5 evolution (Fig 4.6)."""

import doctest
import itertools

import matplotlib
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog
from scipy.spatial import ConvexHull

import casadi_cmpc as cm
from casadi_cmpc.sets import zonotope as zmod

matplotlib.use("Agg")

# E4 data (thesis §4.2.2-4.2.3)
P_E4 = np.array([2.0, 2.0])
H_E4 = np.array([[0.4414, -0.5855, -0.0484, 0.2570, 0.2293, 0.1498],
                 [-0.0016, -0.3930, 0.3526, -0.2396, 0.4257, -0.3117]])
H_E4_INDEPENDENT = np.array([[0.6414, 0.5855], [-0.4016, 0.7930]])

# Fig 4.6: the thesis gives neither the initial box nor the controls; these are our choice
FIG46_BOX = cm.Box([0.4, -0.5], [0.6, -0.3])
FIG46_U = [2.0, 1.0, 0.0, -1.0]


# ------------------------------------------------------------------- polygon helpers
def _area(poly):
    """Shoelace area of a polygon given by its vertices in order."""
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _ccw(poly):
    x, y = poly[:, 0], poly[:, 1]
    if np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)) < 0:
        return poly[::-1]
    return poly


def _clip(subject, clipper):
    """Sutherland-Hodgman intersection of two convex polygons (counter-clockwise)."""
    out = list(_ccw(subject))
    clipper = _ccw(clipper)
    for i in range(len(clipper)):
        a, b = clipper[i], clipper[(i + 1) % len(clipper)]
        inp, out = out, []
        if not inp:
            break

        def side(p, a=a, b=b):
            return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])

        for j in range(len(inp)):
            cur, prev = inp[j], inp[j - 1]
            sc, sp = side(cur), side(prev)
            if sc >= 0:
                if sp < 0:
                    out.append(prev + (cur - prev) * sp / (sp - sc))
                out.append(cur)
            elif sp >= 0:
                out.append(prev + (cur - prev) * sp / (sp - sc))
    return np.array(out).reshape(-1, 2)


def _random_zonotope(rng, n, p):
    return cm.Zonotope(rng.normal(size=n), rng.normal(size=(n, p)))


def _sample(Z, k, rng):
    return Z.center + rng.uniform(-1, 1, (k, Z.n_generators)) @ Z.generators.T


def _support_lp(Z, d):
    """max d.x over Z by linear programming over the generator coefficients."""
    res = linprog(-(d @ Z.generators), bounds=[(-1, 1)] * Z.n_generators, method="highs")
    return float(d @ Z.center - res.fun)


# ---------------------------------------------------------------------- E4 / Fig 4.3
def test_e4_vertices_match_brute_force_hull():
    Z = cm.Zonotope(P_E4, H_E4)
    V = Z.vertices()
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=6)))
    pts = P_E4 + signs @ H_E4.T
    hull = pts[ConvexHull(pts).vertices]
    assert len(V) == len(hull) == 12
    dist = np.linalg.norm(V[:, None] - hull[None], axis=2)
    assert dist.min(axis=1).max() < 1e-12 and dist.min(axis=0).max() < 1e-12
    # counter-clockwise polygon with the hull's area, equal to the zonotope volume formula
    x, y = V[:, 0], V[:, 1]
    assert np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)) > 0
    assert _area(V) == pytest.approx(ConvexHull(pts).volume, rel=1e-12)
    assert Z.volume() == pytest.approx(_area(V), rel=1e-12)
    assert Z.contains(V).all()
    # Minkowski construction of §4.2.2: Z = Z1 ⊕ Z2 ⊕ Z3
    Z123 = (cm.Zonotope(P_E4, H_E4[:, :2]) + cm.Zonotope([0, 0], H_E4[:, 2:4])
            + cm.Zonotope([0, 0], H_E4[:, 4:]))
    np.testing.assert_allclose(_area(Z123.vertices()), _area(V), rtol=1e-12)


def test_bisection_thm41_redundant_generators_overlap():
    """Fig 4.4: halves of the 2 x 6 zonotope overlap; their union is Z."""
    Z = cm.Zonotope(P_E4, H_E4)
    L, R = Z.bisect(cover=False)
    # (4.12)-(4.13): the largest |h_ij| is 0.5855, in generator k = 2 (index 1)
    np.testing.assert_array_equal(L.center, P_E4 - H_E4[:, 1] / 2)
    np.testing.assert_array_equal(R.center, P_E4 + H_E4[:, 1] / 2)
    np.testing.assert_array_equal(L.generators[:, 1], H_E4[:, 1] / 2)
    np.testing.assert_array_equal(np.delete(L.generators, 1, axis=1), np.delete(H_E4, 1, 1))
    aZ, aL, aR = _area(Z.vertices()), _area(L.vertices()), _area(R.vertices())
    inter = _area(_clip(L.vertices(), R.vertices()))
    assert inter > 0.05 * aZ  # real overlap
    assert aL + aR - inter == pytest.approx(aZ, rel=1e-9)
    assert Z.contains(L.vertices()).all() and Z.contains(R.vertices()).all()
    assert (L.contains(Z.vertices()) | R.contains(Z.vertices())).all()


def test_bisection_thm42_independent_generators_complete():
    """Fig 4.5: rank(H) = n, the halves share only a facet."""
    Z = cm.Zonotope(P_E4, H_E4_INDEPENDENT)
    assert Z.is_parallelotope()
    L, R = Z.bisect(cover=False)
    aZ, aL, aR = _area(Z.vertices()), _area(L.vertices()), _area(R.vertices())
    inter = _area(_clip(L.vertices(), R.vertices()))
    assert inter == pytest.approx(0.0, abs=1e-12 * aZ)
    assert aL + aR == pytest.approx(aZ, rel=1e-12)
    # complete bisection of the redundant zonotope through its bounding parallelotope
    Zr = cm.Zonotope(P_E4, H_E4)
    L2, R2 = Zr.bisect_complete(cover=False)
    assert L2.n_generators == R2.n_generators == 2
    assert _area(_clip(L2.vertices(), R2.vertices())) == pytest.approx(0.0, abs=1e-9)
    pts = _sample(Zr, 3000, np.random.default_rng(0))
    assert (L2.contains(pts) | R2.contains(pts)).all()


def test_bisect_cover_and_index():
    Z = cm.Zonotope([0.1, 0.7], [[0.3, 0.1], [0.0, 0.3]])
    L, R = Z.bisect(index=0, cover=True)
    assert L.n_generators >= 2 and R.n_generators >= 2
    pts = _sample(Z, 2000, np.random.default_rng(1))
    assert (L.contains(pts) | R.contains(pts)).all()
    with pytest.raises(IndexError):
        Z.bisect(index=5)
    with pytest.raises(ValueError, match="point"):
        cm.Zonotope([0.0], np.zeros((1, 0))).bisect()


# ------------------------------------------------------------------ set protocol
@pytest.mark.parametrize("n,p", [(1, 3), (2, 5), (3, 6), (4, 6)])
def test_support_matches_lp(n, p):
    rng = np.random.default_rng(n * 10 + p)
    Z = _random_zonotope(rng, n, p)
    D = rng.normal(size=(8, n))
    h = Z.support(D)
    for d, val in zip(D, h, strict=True):
        assert val == pytest.approx(_support_lp(Z, d), rel=1e-9, abs=1e-9)
    assert Z.support(D[0]) == pytest.approx(h[0])
    # sound upper bound
    assert np.all(Z._support_upper(D) >= h)
    bb = Z.bounding_box()
    np.testing.assert_allclose(bb.hi, Z.support(np.eye(n)), rtol=1e-12)
    np.testing.assert_allclose(bb.lo, -Z.support(-np.eye(n)), rtol=1e-12)


@pytest.mark.parametrize("n,p", [(2, 6), (3, 5), (3, 7), (4, 6)])
def test_to_polytope_agrees_with_membership(n, p):
    rng = np.random.default_rng(100 + n * 10 + p)
    Z = _random_zonotope(rng, n, p)
    P = Z.to_polytope()
    assert isinstance(P, cm.Polytope)
    bb = Z.bounding_box()
    pts = bb.sample(400, rng)
    inZ = Z.contains(pts)
    lp = Z._contains_lp(pts)
    assert 0.05 < inZ.mean() < 0.95
    np.testing.assert_array_equal(inZ, lp)
    np.testing.assert_array_equal(P.contains(pts), inZ)
    # every vertex satisfies the H-representation (it is an outer representation)
    assert P.contains(Z.vertices()).all()
    # and each row is tight: some vertex attains it up to rounding
    slack = P.b[None] - Z.vertices() @ P.A.T
    assert np.all(slack.min(axis=0) <= 1e-9 * (1 + np.abs(P.b)))


@pytest.mark.parametrize("n,p", [(3, 5), (3, 8), (4, 7)])
def test_vertices_nd_match_brute_force(n, p):
    rng = np.random.default_rng(7 + n + p)
    Z = _random_zonotope(rng, n, p)
    V = Z.vertices()
    pts = Z.center + np.array(list(itertools.product((-1.0, 1.0), repeat=p))) @ \
        Z.generators.T
    hull = pts[ConvexHull(pts).vertices]
    assert len(V) == len(hull)
    dist = np.linalg.norm(V[:, None] - hull[None], axis=2)
    assert dist.min(axis=1).max() < 1e-10 and dist.min(axis=0).max() < 1e-10
    assert Z.volume() == pytest.approx(ConvexHull(pts).volume, rel=1e-10)


def test_contained_in_agrees_with_vertex_check():
    rng = np.random.default_rng(3)
    decided = 0
    for trial in range(60):
        n = 2 if trial % 2 else 3
        Z = cm.Zonotope(rng.normal(size=n) * 0.3, rng.normal(size=(n, 4)) * 0.4)
        A = rng.normal(size=(6, n))
        b = np.abs(rng.normal(size=6)) * 2 + 0.5
        P = cm.Polytope(A, b)
        slack = b[None] - Z.vertices() @ A.T
        vertex_check = bool(np.all(slack >= 0))
        result = Z.contained_in(P)
        if np.abs(slack).min() > 1e-9:
            assert result == vertex_check
            decided += 1
        elif result:
            assert vertex_check
    assert decided > 50
    # exactly touching sets are refused unless proven: a box equal to the bounding box
    Z = cm.Zonotope([0.0, 0.0], [[1.0, 0.5], [0.0, 1.0]])
    assert Z.contained_in(Z.bounding_box())
    assert Z.contained_in(Z.to_polytope())
    assert Z.contained_in(cm.Zonotope([0.0, 0.0], [[2.0, 0.0], [0.0, 2.0]]))
    assert not Z.contained_in(cm.Zonotope([0.0, 0.0], [[1.0, 0.0], [0.0, 1.0]]))
    assert Z.contained_in(cm.PolytopeUnion([cm.Polytope([[1.0, 0.0]], [0.0]),
                                           Z.to_polytope()]))
    with pytest.raises(TypeError):
        Z.contained_in("box")


def test_contains_box_and_intersects_box_are_sound():
    rng = np.random.default_rng(11)
    for n in (2, 3):
        Z = _random_zonotope(rng, n, 5)
        bb = Z.bounding_box()
        lo = bb.sample(400, rng)
        w = rng.uniform(0, 0.3, (400, n)) * (bb.hi - bb.lo)
        boxes = np.stack([lo, lo + w], axis=-1)
        inside = Z.contains_box(boxes)
        meets = Z.intersects_box(boxes)
        assert inside.any() and (~meets).any() and (meets & ~inside).any()
        assert not (inside & ~meets).any()
        H = Z.to_polytope()  # outer: a point outside H is outside Z
        for i in range(len(boxes)):
            s = boxes[i, :, 0] + rng.random((100, n)) * (boxes[i, :, 1] - boxes[i, :, 0])
            corners = cm.Box(boxes[i, :, 0], boxes[i, :, 1]).vertices()
            if inside[i]:
                assert Z.contains(np.vstack([s, corners])).all()
                assert H.contains(np.vstack([s, corners]), tol=-1e-12).all()
            if not meets[i]:
                assert not H.contains(s).any()
        idx = np.flatnonzero(inside)[:5]
        corners = np.concatenate([cm.Box(b[:, 0], b[:, 1]).vertices() for b in boxes[idx]])
        assert Z._contains_lp(corners).all()
        # boxes well inside / far away are decided
        centre = np.stack([Z.center - 1e-3, Z.center + 1e-3], axis=-1)
        far = np.stack([bb.hi + 1.0, bb.hi + 2.0], axis=-1)
        assert Z.contains_box(centre)[0] and not Z.intersects_box(far)[0]


def test_intersects_box_separates_along_facets():
    # a thin diagonal zonotope and a box that meets its bounding box but not the zonotope
    Z = cm.Zonotope([0.0, 0.0], [[1.0, 0.01], [1.0, -0.01]])
    B = np.array([[0.5, 0.9], [-0.9, -0.5]])
    assert Z.bounding_box().intersects_box(B)[0]
    assert not Z.intersects_box(B)[0]
    assert Z.intersects_box(np.array([[-0.1, 0.1], [-0.1, 0.1]]))[0]


def test_flat_and_point_zonotopes():
    Z = cm.Zonotope([1.0, 2.0], [[1.0, 2.0], [1.0, 2.0]])  # a segment
    assert not Z.is_full_dimensional()
    V = Z.vertices()
    assert {tuple(v) for v in V} == {(4.0, 5.0), (-2.0, -1.0)}
    np.testing.assert_array_equal(Z.contains([[1, 2], [2.5, 3.5], [1, 2.001]]),
                                  [True, True, False])
    assert not Z.contains_box(np.array([[1.0, 1.0], [2.0, 2.0]]))[0]  # not proven: flat
    P = Z.to_polytope()
    assert P.contains(V, tol=1e-12).all() and not P.contains([1.0, 2.1])
    Pp = Z.reduce_to_parallelotope()
    assert Pp.is_parallelotope() and Z.contained_in(Pp)
    pt = cm.Zonotope([1.0, 2.0], np.zeros((2, 0)))
    np.testing.assert_array_equal(pt.vertices(), [[1.0, 2.0]])
    assert pt.contains([1.0, 2.0]) and not pt.contains([1.0, 2.5])
    assert pt.bounding_box() == cm.Box([1.0, 2.0], [1.0, 2.0])
    assert pt.volume() == 0.0 and not pt.is_empty()


def test_parallel_generators_use_exact_fallback():
    # (1, 1, 0) and (2, 2, 0) are parallel: their cross product is exactly zero, which the
    # verified solve cannot show; the rational fallback drops that subset
    Z = cm.Zonotope([0.0, 0.0, 0.0], [[1, 2, 0, 0], [1, 2, 1, 0], [0, 0, 0, 1]])
    assert Z.is_full_dimensional()
    V = Z.vertices()
    assert len(V) == 8 and Z.volume() == pytest.approx(24.0)
    assert Z.contains_box(np.array([[-0.4, 0.4]] * 3))[0]
    assert not Z.contains_box(np.array([[-1.5, 0.4]] * 3))[0]
    Z2 = cm.Zonotope([1.0, 1.0], [[1.0, 2.0, 0.0], [1.0, 2.0, 1.0]])
    assert len(Z2.vertices()) == 4 and Z2.volume() == pytest.approx(12.0)


def test_from_box_round_trip():
    B = cm.Box([-1.0, 0.5], [1.0, 0.75])
    Z = cm.Zonotope.from_box(B)
    np.testing.assert_array_equal(Z.generators, np.diag([1.0, 0.125]))
    assert Z.bounding_box() == B
    assert Z.volume() == pytest.approx(B.volume())
    B2 = cm.Box([0.4, -0.5], [0.6, -0.3])  # midpoint not exact: outer enclosure
    bb = cm.Zonotope.from_box(B2).bounding_box()
    assert np.all(bb.lo <= B2.lo) and np.all(bb.hi >= B2.hi)
    np.testing.assert_allclose(bb.as_array(), B2.as_array(), atol=1e-15)
    flat = cm.Zonotope.from_box(cm.Box([0.0, 1.0], [1.0, 1.0]))
    assert flat.n_generators == 1
    with pytest.raises(cm.UnboundedSetError):
        cm.Zonotope.from_box(cm.Box([0.0], [np.inf]))


def test_minkowski_sum_and_linear_map():
    Z = cm.Zonotope([0.1, 0.2], [[1.0, 0.5], [0.0, 1.0]])
    S = Z + cm.Box([-0.3, -0.1], [0.3, 0.1])
    pts = S.center + np.array(list(itertools.product((-1.0, 1.0), repeat=4))) @ \
        S.generators.T
    assert S.volume() == pytest.approx(ConvexHull(pts).volume, rel=1e-12)
    assert S.volume() == pytest.approx(5.92, rel=1e-12)  # 4 (1 + 0.1 + 0.3 + 0.05 + 0.03)
    T = np.array([0.3, 0.7]) + Z  # translation; inexact centre sums add an error generator
    assert isinstance(T, cm.Zonotope)
    assert T.contains(Z.vertices() + [0.3, 0.7]).all()
    A = np.array([[2.0, 0.0], [1.0, 1.0]])
    assert Z.linear_map(A).volume() == pytest.approx(2.0 * Z.volume())
    with pytest.raises(cm.DimensionError):
        Z.linear_map(np.eye(3))
    with pytest.raises(cm.DimensionError):
        Z + np.zeros(3)


# ------------------------------------------------------------ parallelotopes, order
@pytest.mark.parametrize("method", ["svd", "pca", "norm", "volume", "box"])
@pytest.mark.parametrize("n,p", [(2, 6), (3, 7)])
def test_parallelotope_bound_contains_zonotope(method, n, p):
    rng = np.random.default_rng(5 * n + p)
    Z = cm.Zonotope(P_E4, H_E4) if n == 2 else _random_zonotope(rng, n, p)
    P = Z.reduce_to_parallelotope(method)
    assert P.n_generators == n and P.is_parallelotope()
    assert np.linalg.matrix_rank(P.generators) == n
    np.testing.assert_array_equal(P.center, Z.center)
    D = rng.normal(size=(500, n))
    assert np.all(P.support(D) >= Z.support(D) - 1e-12)
    assert Z.contained_in(P)
    # the scaling is tight: each facet of P touches Z
    Tinv = np.linalg.inv(P.generators)
    np.testing.assert_allclose(Z.support(Tinv) - Tinv @ Z.center, 1.0, rtol=1e-9)
    np.testing.assert_allclose(Z.support(-Tinv) + Tinv @ Z.center, 1.0, rtol=1e-9)


def test_parallelotope_volume_method_is_smallest():
    Z = cm.Zonotope(P_E4, H_E4)
    vols = {m: Z.reduce_to_parallelotope(m).volume() for m in ("svd", "norm", "box",
                                                               "volume")}
    assert vols["volume"] <= min(vols.values()) * (1 + 1e-9)
    assert vols["volume"] >= Z.volume()
    with pytest.raises(ValueError, match="Unknown method"):
        Z.reduce_to_parallelotope("qr")


@pytest.mark.parametrize("method", ["svd", "box"])
def test_outer_parallelotope_of_points(method):
    """Fig 4.7(b): a polytope (given by its vertices) bounded by a parallelotope."""
    rng = np.random.default_rng(9)
    ang = np.sort(rng.uniform(0, 2 * np.pi, 7))
    V = np.c_[2 * np.cos(ang) + 0.3, np.sin(ang) + 0.1]
    P = cm.Zonotope.outer_parallelotope(V, method=method)
    assert P.is_parallelotope()
    assert P.contains_box(np.stack([V, V], axis=-1)).all()  # proven
    coef = np.linalg.solve(P.generators, (V - P.center).T)
    np.testing.assert_allclose(np.abs(coef).max(axis=1), 1.0, rtol=1e-9)  # tight
    P3 = cm.Zonotope.outer_parallelotope(rng.normal(size=(20, 3)), center=np.zeros(3))
    assert P3.n_generators == 3
    with pytest.raises(ValueError, match="Unknown method"):
        cm.Zonotope.outer_parallelotope(V, method="volume")


def test_reduce_order_is_outer():
    rng = np.random.default_rng(2)
    Z = _random_zonotope(rng, 3, 20)
    R = Z.reduce_order(3)
    assert R.n_generators <= 9
    D = rng.normal(size=(400, 3))
    assert np.all(R.support(D) >= Z.support(D) - 1e-12)
    assert Z.reduce_order(10) is Z
    assert Z.reduce_order(1).n_generators == 3
    with pytest.raises(ValueError):
        Z.reduce_order(0.5)


# ---------------------------------------------------------------- Kühn inclusion
def test_kuhn_inclusion_contains_images():
    rng = np.random.default_rng(4)
    Z = cm.Zonotope([1.0, -0.5], [[0.3, 0.1, -0.2], [0.05, 0.2, 0.1]])
    Mlo = np.array([[0.9, -0.2], [0.1, 0.7]])
    Mhi = Mlo + np.array([[0.2, 0.1], [0.05, 0.3]])
    K = cm.kuhn_inclusion(Mlo, Mhi, Z)
    xs = _sample(Z, 4000, rng)
    Ms = Mlo + rng.random((4000, 2, 2)) * (Mhi - Mlo)
    assert K.contains(np.einsum("kij,kj->ki", Ms, xs)).all()
    # vertices of the matrix box times vertices of the zonotope (extreme images)
    for corner in itertools.product((0, 1), repeat=4):
        M = np.where(np.array(corner).reshape(2, 2) == 1, Mhi, Mlo)
        assert K.contains(Z.vertices() @ M.T).all()
    # a point matrix gives the image up to rounding
    A = np.array([[0.5, 1.0], [-1.0, 2.0]])
    KA = cm.kuhn_inclusion(A, A, Z)
    assert KA.volume() == pytest.approx(Z.linear_map(A).volume(), rel=1e-12)
    assert KA.contains(Z.vertices() @ A.T).all()


def test_zonotope_inclusion_thm43():
    """◇(p ⊕ M B^m) = p ⊕ [Mid(M) G] B^{m+n}, G_ii = sum_j Diam(M_ij)/2 (4.14)-(4.15)."""
    rng = np.random.default_rng(6)
    p = np.array([0.5, -1.0])
    Mlo = rng.normal(size=(2, 3))
    Mhi = Mlo + rng.uniform(0, 0.2, (2, 3))
    Zi = cm.zonotope_inclusion(p, Mlo, Mhi)
    np.testing.assert_allclose(Zi.generators[:, :3], (Mlo + Mhi) / 2, rtol=1e-15)
    np.testing.assert_allclose(np.diag(Zi.generators[:, 3:]),
                               ((Mhi - Mlo) / 2).sum(axis=1), rtol=1e-12)
    Ms = Mlo + rng.random((3000, 2, 3)) * (Mhi - Mlo)
    z = rng.uniform(-1, 1, (3000, 3))
    assert Zi.contains(p + np.einsum("kij,kj->ki", Ms, z)).all()
    with pytest.raises(cm.EmptySetError):
        cm.zonotope_inclusion(p, Mhi, Mlo - 1)
    with pytest.raises(cm.DimensionError):
        cm.zonotope_inclusion([0.0], Mlo, Mhi)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2 ** 31), st.integers(1, 3), st.integers(1, 4))
def test_kuhn_inclusion_enclosure_property(seed, n, p):
    rng = np.random.default_rng(seed)
    Z = cm.Zonotope(rng.normal(size=n) * 10, rng.normal(size=(n, p)))
    Mlo = rng.normal(size=(n, n))
    Mhi = Mlo + rng.uniform(0, 0.5, (n, n)) * (rng.random((n, n)) < 0.7)
    K = cm.kuhn_inclusion(Mlo, Mhi, Z)
    Ms = Mlo + rng.random((300, n, n)) * (Mhi - Mlo)
    xs = _sample(Z, 300, rng)
    assert K.contains(np.einsum("kij,kj->ki", Ms, xs)).all()


# ------------------------------------------------------------ evolution, Fig 4.6
def _fig46():
    model = cm.models.load("cannon_001").model
    F = model.inclusion("natural")
    X = FIG46_BOX.as_array()[None]
    Z = cm.Zonotope.from_box(FIG46_BOX)
    pts = FIG46_BOX.sample(4000, 0)
    pts = np.vstack([pts, FIG46_BOX.vertices()])
    rows = []
    for u in FIG46_U:
        ub = np.array([[[u, u]]])
        X = F(X, ub)
        Z = cm.evolve(model, Z, [u])
        pts = model.step(pts, np.array([u]))
        rows.append((X[0].copy(), Z, pts.copy()))
    return rows


def test_fig_4_6_zonotope_vs_interval_evolution():
    rows = _fig46()
    ratios = []
    for step, (X, Z, pts) in enumerate(rows, start=1):
        box = cm.Box(X[:, 0], X[:, 1])
        assert box.contains(pts).all(), step
        assert Z.contains(pts).all(), step
        assert Z.contains_box(np.stack([pts, pts], axis=-1)[:50]).all()  # proven
        box_area = box.volume()
        ratios.append(Z.volume() / box_area)
        assert Z.volume() <= box_area, step
    assert ratios[-1] < 0.95 * ratios[0] and ratios[-1] < 0.9
    assert all(a > b for a, b in zip(ratios, ratios[1:], strict=False))


def test_evolve_robust_model_contains_true_successors():
    model = cm.models.load("cannon_robust").model
    rng = np.random.default_rng(8)
    Z = cm.Zonotope.from_box(cm.Box([0.3, -0.6], [0.7, -0.2]))
    pts = np.vstack([_sample(Z, 3000, rng), Z.vertices()])
    for _ in range(5):
        Z = cm.evolve(model, Z, [1.5], max_order=3)
        w = rng.uniform(0.85, 0.95, (len(pts), 1))
        w[:2] = [[0.85], [0.95]]
        pts = model.step(pts, np.array([1.5]), w)
        assert Z.n_generators <= 6
        assert Z.contains(pts).all()
    # a box of controls and an explicit disturbance box
    Ub = cm.Box([-0.5], [0.5])
    Wb = cm.Box([0.9], [0.95])
    Z2 = cm.evolve(model, Z, Ub, W=Wb, inclusion="centered")
    succ = model.step(pts, rng.uniform(-0.5, 0.5, (len(pts), 1)),
                      rng.uniform(0.9, 0.95, (len(pts), 1)))
    assert Z2.contains(succ).all()


def test_evolve_refuses_bad_input():
    ex = cm.models.load("cannon_001")
    Z = cm.Zonotope.from_box(FIG46_BOX)
    with pytest.raises(cm.DimensionError, match="dimension"):
        cm.evolve(ex.model, cm.Zonotope([0.0], [[1.0]]), [0.0])
    with pytest.raises(cm.ModelError, match="u is required"):
        cm.evolve(ex.model, Z)
    with pytest.raises(cm.DimensionError, match="control"):
        cm.evolve(ex.model, Z, [0.0, 1.0])
    with pytest.raises(cm.ModelError, match="no disturbance"):
        cm.evolve(ex.model, Z, [0.0], W=cm.Box([0.0], [1.0]))
    with pytest.raises(TypeError):
        cm.evolve(ex.model, FIG46_BOX, [0.0])


# ----------------------------------------------------------- input, persistence, plot
def test_bad_input_raises_specific_errors():
    with pytest.raises(cm.DimensionError, match="expected 2"):
        cm.Zonotope([0.0, 0.0], np.ones((3, 2)))
    with pytest.raises(cm.DimensionError):
        cm.Zonotope(np.zeros((2, 2)), np.ones((2, 2)))
    with pytest.raises(cm.InvalidBoundsError, match="NaN"):
        cm.Zonotope([0.0, np.nan], np.eye(2))
    with pytest.raises(cm.InvalidBoundsError, match="NaN"):
        cm.Zonotope([0.0, 0.0], [[np.nan, 0.0], [0.0, 1.0]])
    with pytest.raises(cm.UnboundedSetError):
        cm.Zonotope([0.0, np.inf], np.eye(2))
    Z = cm.Zonotope([0.0, 0.0], np.eye(2))
    with pytest.raises(cm.DimensionError):
        Z.contains(np.zeros((3, 3)))
    with pytest.raises(cm.DimensionError):
        Z.support(np.ones(3))
    with pytest.raises(cm.InvalidBoundsError):
        Z.contains([np.nan, 0.0])
    with pytest.raises(cm.DimensionError):
        Z.contained_in(cm.Polytope(np.ones((1, 3)), [1.0]))
    with pytest.raises(ValueError):  # DimensionError is a ValueError
        Z.contains_box(np.zeros((1, 3, 2)))


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_save_load_round_trip(tmp_path, suffix):
    Z = cm.Zonotope(P_E4, H_E4)
    path = Z.save(tmp_path / f"z{suffix}")
    Z2 = cm.Zonotope.load(path)
    assert isinstance(Z2, cm.Zonotope) and Z2 == Z
    np.testing.assert_array_equal(Z2.generators, H_E4)
    pt = cm.Zonotope([1.0], np.zeros((1, 0)))
    assert cm.load_set(pt.save(tmp_path / f"p{suffix}")) == pt


def test_plot_draws_polygon():
    import matplotlib.pyplot as plt

    Z = cm.Zonotope(P_E4, H_E4)
    ax = Z.plot(facecolor="C1")
    assert len(ax.patches) == 1
    np.testing.assert_allclose(_area(ax.patches[0].get_xy()[:-1]), Z.volume(), rtol=1e-12)
    cm.Zonotope(np.zeros(3), np.eye(3)).plot(ax=ax, dims=(0, 2))
    plt.close("all")


def test_docstring_examples():
    result = doctest.testmod(zmod, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0
