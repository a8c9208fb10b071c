"""Set inversion via zonotope geometry (thesis Alg 4.3): Fig 4.8, bisection cover, images."""

import doctest
import importlib
import itertools
from fractions import Fraction

import casadi as ca
import matplotlib
import numpy as np
import pytest
from scipy.spatial import ConvexHull

import casadi_cmpc as cm
from casadi_cmpc.solvers.engine import Status
from casadi_cmpc.solvers.zonotope_sivia import (
    ZonotopeFrontier,
    ZonotopePaving,
    inner_zonotopes,
    zonotope_classifier,
    zonotope_sivia,
)

matplotlib.use("Agg")

# A pentagon in the spirit of Fig 4.8 (the thesis gives no numbers for it)
P_FIG48 = cm.Polytope.from_vertices([[0, 0], [2.2, 0.6], [2.9, 1.9], [1.0, 2.3], [-0.6, 0.9]])


def _quadratic():
    x = ca.SX.sym("x", 2)
    return ca.Function("quad", [x], [x + 0.1 * ca.vertcat(x[0] ** 2, x[0] * x[1])])


def _eval(f, pts):
    return np.asarray(f(pts.T)).T.reshape(len(pts), -1)


# ----------------------------------------------------------------------------- Fig 4.8
@pytest.fixture(scope="module")
def fig48():
    return {eps: inner_zonotopes(P_FIG48, eps) for eps in (0.2, 0.1, 0.05, 0.02)}


def test_fig48_inner_zonotopes_inside_polytope(fig48):
    for res in fig48.values():
        assert res.status == Status.PROVED and res.success
        V = res.inner.polygons().reshape(-1, 2)  # every vertex of every inner zonotope
        assert (V @ P_FIG48.A.T - P_FIG48.b).max() <= 1e-12
        # and their exact vertices as Zonotope objects, for a few of them
        for Z in list(res.inner)[:20]:
            assert P_FIG48.contains(Z.vertices(), tol=1e-12).all()
            assert Z.contained_in(P_FIG48)


def test_fig48_area_grows_to_polytope_area(fig48):
    area = P_FIG48.volume()
    inner = [fig48[e].volume() for e in (0.2, 0.1, 0.05, 0.02)]
    assert all(a < b for a, b in zip(inner, inner[1:], strict=False))
    assert inner[-1] <= area
    assert inner[-1] > 0.95 * area
    # inner ∪ boundary covers P (Alg 4.3 loses nothing)
    for res in fig48.values():
        assert res.volume() + res.volume("boundary") >= area


def test_fig48_union_area_by_sampling(fig48):
    """The inner zonotopes do not overlap: the union area equals the sum of the areas."""
    res = fig48[0.05]
    rng = np.random.default_rng(0)
    bb = P_FIG48.bounding_box()
    pts = rng.uniform(bb.lo, bb.hi, (20000, 2))
    hits = np.zeros(len(pts), dtype=int)
    for Z in res.inner:
        # parallelotopes: coordinates in the generator basis
        a = np.linalg.solve(Z.generators[:, :2], (pts - Z.center).T).T
        hits += (np.abs(a) <= 1.0).all(axis=1)
    assert hits.max() <= 1 or (hits > 1).mean() < 1e-3  # shared facets only
    union = (hits > 0).mean() * bb.volume()
    assert abs(union - res.volume()) < 0.05 * bb.volume()
    assert P_FIG48.contains(pts[hits > 0]).all()


def test_fig48_discarded_outside(fig48):
    for res in fig48.values():
        assert res.n_discarded == len(res.outside) > 0
        pts = res.outside.sample(40, rng=1).reshape(-1, 2)
        assert not P_FIG48.contains(pts).any()


def test_fig48_starts_from_bounding_parallelotope(fig48):
    res = fig48[0.1]
    Z0 = res.domain
    assert Z0.is_parallelotope()
    assert Z0.contains(P_FIG48.vertices()).all()
    assert np.allclose(Z0.center, P_FIG48.chebyshev_ball()[0])
    res_box = inner_zonotopes(P_FIG48, 0.1, center="box", method="box")
    assert np.allclose(res_box.domain.generators, np.diag(np.diag(res_box.domain.generators)))


def test_inner_zonotopes_3d_and_1d():
    rng = np.random.default_rng(3)
    P3 = cm.Polytope.from_vertices(rng.normal(size=(10, 3)))
    res = inner_zonotopes(P3, 0.2)
    assert len(res.inner) > 0
    assert P3.contains(res.inner.sample(20, rng=0).reshape(-1, 3)).all()
    assert not P3.contains(res.outside.sample(20, rng=0).reshape(-1, 3)).any()
    P1 = cm.Polytope([[1.0], [-1.0]], [1.0, 2.0])
    res1 = inner_zonotopes(P1, 0.01)
    assert 2.95 < res1.volume() <= 3.0


@pytest.mark.parametrize("tiny", [1e-200, 1e-160, 1e-3])
def test_inner_zonotopes_respect_a_row_whose_norm_underflows(tiny):
    """``tiny x <= 0`` is ``x <= 0`` whatever the magnitude: the inner zonotopes (proven
    inside the rows) stay in x <= 0, and the polytope's volume sees the row."""
    A = np.array([[tiny, 0], [1, 0], [0, 1.0], [-1, 0], [0, -1]])
    P = cm.Polytope(A, np.array([0, 1, 1, 1, 1.0]))
    res = inner_zonotopes(P, 0.1)
    assert len(res.inner) > 0
    pts = res.inner.sample(20, rng=0).reshape(-1, 2)
    assert (pts[:, 0] <= 0).all()
    # the same rows up to a positive factor: the same search
    ref = inner_zonotopes(cm.Polytope(np.array([[1.0, 0], [1, 0], [0, 1], [-1, 0], [0, -1]]),
                                      np.array([0, 1, 1, 1, 1.0])), 0.1)
    assert res.volume() == pytest.approx(ref.volume()) and 1.0 < res.volume() <= 2.0


# ----------------------------------------------------------------------------- frontier
def _awkward_frontier(rng, N=30, n=2, p=3):
    C = rng.normal(size=(N, n)) * 1e3 + np.pi
    G = rng.normal(size=(N, n, p)) * np.exp(rng.uniform(-8, 2, (N, 1, p)))
    return ZonotopeFrontier(C, G)


def test_bisect_covers_parent_exactly():
    """Exact rational check: every parent point lies in a half, centre error included."""
    rng = np.random.default_rng(0)
    fr = _awkward_frontier(rng)
    halves = fr.bisect()
    N = len(fr)
    assert np.any(halves.radii > 0)  # the rounding case is exercised
    assert halves.n_generators == fr.n_generators
    k = np.argmax(np.abs(fr.generators).max(axis=1), axis=1)
    for i in range(N):
        for _ in range(6):
            alpha = list(rng.uniform(-1, 1, fr.n_generators))
            alpha[k[i]] = float(rng.choice([-1.0, 0.0, 1.0, rng.uniform(-1, 1)]))
            a = [Fraction(t) for t in alpha]
            x = [Fraction(fr.centers[i, r]) + sum(Fraction(fr.generators[i, r, j]) * a[j]
                                                  for j in range(fr.n_generators))
                 for r in range(fr.dim)]
            child = i if a[k[i]] <= 0 else N + i
            b = list(a)
            b[k[i]] = 2 * a[k[i]] + (1 if a[k[i]] <= 0 else -1)
            assert abs(b[k[i]]) <= 1
            for r in range(fr.dim):
                y = Fraction(halves.centers[child, r]) + sum(
                    Fraction(halves.generators[child, r, j]) * b[j]
                    for j in range(fr.n_generators))
                assert abs(x[r] - y) <= Fraction(halves.radii[child, r])


def test_bisect_covers_parent_sampled():
    rng = np.random.default_rng(1)
    C = rng.normal(size=(20, 2))
    G = rng.normal(size=(20, 2, 2))
    fr = ZonotopeFrontier(C, G)
    halves = fr.bisect()
    pts = fr.sample(200, rng=2)  # (20, 200, 2)
    for i in range(len(fr)):
        inside = np.zeros(200, dtype=bool)
        for child in (i, len(fr) + i):
            a = np.linalg.solve(halves.generators[child], (pts[i] - halves.centers[child]).T).T
            inside |= (np.abs(a) <= 1 + 1e-9).all(axis=1)
        assert inside.all()
    # the halves are Thm 4.1's: half the split generator, centres c ∓ h_k / 2
    Z = fr[0]
    L, R = Z.bisect(cover=False)
    assert np.allclose(halves[0].center, L.center) and np.allclose(halves[20].center, R.center)
    assert np.allclose(halves[0].generators[:, :2], L.generators)


def test_frontier_protocol_and_conversions():
    Zs = [cm.Zonotope([0, 0], [[1, 0], [0, 1]]), cm.Zonotope([1, 1], [[1, 0.5, 0.1], [0, 1, 0]])]
    fr = ZonotopeFrontier.from_zonotopes(Zs)
    assert fr.generators.shape == (2, 2, 3) and fr.dim == 2 and len(fr) == 2
    assert fr[1] == Zs[1] and fr[-1] == Zs[1]
    assert np.allclose(fr.width(), [1.0, 1.0])
    assert len(fr.take(np.array([False, True]))) == 1
    both = ZonotopeFrontier.concat([fr, fr.bisect()])
    assert len(both) == 6
    assert np.allclose(fr.volumes(), [Z.volume() for Z in Zs])
    assert np.allclose(fr.bounding_boxes()[1], Zs[1].bounding_box().as_array())
    lo, hi = fr.support_bounds(np.array([[1.0, 2.0], [-1.0, 0.5]]))
    exact = np.array([Z.support(np.array([[1.0, 2.0], [-1.0, 0.5]])) for Z in Zs])
    assert np.all(lo <= exact) and np.all(exact <= hi) and np.allclose(lo, hi)
    poly = fr.polygons()
    assert poly.shape == (2, 6, 2)
    hull = poly[1][ConvexHull(poly[1]).vertices]  # parallel generators: collinear points
    assert np.allclose(np.sort(hull, axis=0), np.sort(Zs[1].vertices(), axis=0))
    with pytest.raises(cm.DimensionError):
        ZonotopeFrontier.concat([fr, ZonotopeFrontier(np.zeros((1, 2)), np.zeros((1, 2, 1)))])
    with pytest.raises(cm.DimensionError):
        ZonotopeFrontier.from_zonotopes([Zs[0], cm.Zonotope([0.0], [[1.0]])])


# ----------------------------------------------------------------------------- images
def test_nonlinear_inner_and_outer_are_sound():
    f = _quadratic()
    Z0 = cm.Zonotope([0.0, 0.0], [[1.5, 0.5], [0.0, 1.5]])
    Y = cm.Polytope.from_vertices([[-1, -1], [1, -0.8], [1.2, 1], [-0.5, 1.1]])
    areas = []
    for eps in (0.1, 0.05):
        res = zonotope_sivia(f, Z0, Y, eps)
        assert res.success and len(res.inner) and res.n_discarded
        pin = res.inner.sample(30, rng=0).reshape(-1, 2)
        assert Y.contains(_eval(f, pin)).all()
        pout = res.outside.sample(30, rng=0).reshape(-1, 2)
        assert not Y.contains(_eval(f, pout)).any()
        # points of the domain outside inner ∪ boundary are not solutions, and vice versa
        areas.append(res.volume())
    assert areas[0] < areas[1]


def test_image_enclosure_contains_sampled_images():
    """The Kühn/mean-value image zonotope contains f of sampled points (and vertices)."""
    f = _quadratic()
    rng = np.random.default_rng(4)
    fr = ZonotopeFrontier(rng.normal(size=(25, 2)), 0.3 * rng.normal(size=(25, 2, 3)))
    from casadi_cmpc.solvers.zonotope_sivia import _Image

    C, G, R, valid, _ = _Image(f, 2, None, None)(fr)
    assert valid.all()
    img = ZonotopeFrontier(C, G, R)
    pts = fr.sample(200, rng=5)
    for i in range(len(fr)):
        y = _eval(f, pts[i])
        Zi = img[i]
        assert Zi.contains(y).all()


def test_image_enclosure_overestimation_shrinks():
    """Mean-value + Kühn: area ratio enclosure / hull of the image tends to 1 (quadratic)."""
    f = _quadratic()
    from casadi_cmpc.solvers.zonotope_sivia import _Image

    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    ratios = []
    for scale in (0.3, 0.1, 0.03):
        rng = np.random.default_rng(4)
        fr = ZonotopeFrontier(rng.normal(size=(25, 2)), scale * rng.normal(size=(25, 2, 3)))
        img = ZonotopeFrontier(*_Image(f, 2, None, None)(fr)[:3])
        vol = img.volumes()
        pts = fr.sample(300, rng=5)
        r = []
        for i in range(len(fr)):
            x = np.vstack([pts[i], fr.centers[i] + signs @ fr.generators[i].T])
            r.append(vol[i] / ConvexHull(_eval(f, x)).volume)
        ratios.append(np.median(r))
        assert min(r) >= 1.0 - 1e-9
    assert ratios[0] > ratios[1] > ratios[2] and ratios[2] < 1.2


def test_box_target_with_infinite_bound_matches_disk():
    x = ca.SX.sym("x", 2)
    f = ca.Function("r2", [x], [x[0] ** 2 + x[1] ** 2])
    res = zonotope_sivia(f, cm.Box([-2, -2], [2, 2]), cm.Box([-np.inf], [1.0]), 0.05)
    assert 2.5 < res.volume() <= np.pi <= res.volume() + res.volume("boundary")
    pts = res.inner.sample(20, rng=0).reshape(-1, 2)
    assert (np.sum(pts ** 2, axis=1) <= 1).all()


def test_polytope_domain_is_a_condition():
    """X0 = Polytope: inner zonotopes are inside X0 too (identity: X0 ∩ Y)."""
    Y = cm.Polytope.from_box(cm.Box([0.5, -5], [5, 5]))
    res = zonotope_sivia(None, P_FIG48, Y, 0.05)
    V = res.inner.polygons().reshape(-1, 2)
    assert (V @ P_FIG48.A.T - P_FIG48.b).max() <= 1e-12 and V[:, 0].min() >= 0.5 - 1e-12
    assert res.volume() > 0.8 * (P_FIG48 & Y).volume()


def test_union_target():
    U = cm.PolytopeUnion([cm.Polytope.from_box(cm.Box([-1, -1], [0, 1])),
                          cm.Polytope.from_box(cm.Box([0, -1], [1, 0]))])
    res = zonotope_sivia(None, cm.Zonotope([0, 0], [[1.5, 0.3], [0.2, 1.5]]), U, 0.05)
    pts = res.inner.sample(20, rng=0).reshape(-1, 2)
    assert U.contains(pts).all() and res.volume() > 2.0
    assert not U.contains(res.outside.sample(20, rng=0).reshape(-1, 2)).any()


# ----------------------------------------------------------------------------- E5, Fig 4.9
def _cannon_invariance(level):
    ex = cm.models.load("cannon_001")
    cl = ex.model.closed_loop(ex.local_law)
    P = cm.Polytope(np.vstack([ex.info["V"], -ex.info["V"]]), np.full(4, level))
    # P = {|V x|_inf <= level} is the parallelogram level V^-1 B^2 (up to rounding)
    Z0 = cm.Zonotope([0.0, 0.0], level * np.linalg.inv(ex.info["V"]))
    # successor in P and input u = K x in U, stacked in one map R^2 -> R^3
    g = ca.Function("cl_and_u", [cl.x], [ca.vertcat(cl.f, cl.law)])
    A3 = np.zeros((6, 3))
    A3[:4, :2] = P.A
    A3[4, 2], A3[5, 2] = 1.0, -1.0
    Y3 = cm.Polytope(A3, np.r_[P.b, 2.0, 2.0])
    return ex, cl, P, Z0, g, Y3


def test_cannon_001_closed_loop_invariance_fig49():
    ex, cl, P, Z0, g, Y3 = _cannon_invariance(0.9)
    assert P.contains(Z0.vertices(), tol=1e-12).all() and Z0.contains(P.vertices()).all()
    res = zonotope_sivia(g, Z0, Y3, 0.1)
    assert res.success and len(res.boundary) == 0 and res.n_discarded == 0
    assert abs(res.volume() - res.domain.volume()) < 1e-9 * res.domain.volume()
    pts = res.inner.sample(50, rng=0).reshape(-1, 2)
    pts = pts[P.contains(pts)]
    nxt = cl.step(pts)
    assert P.contains(nxt).all()
    assert (np.abs(pts @ ex.local_law.T) <= 2).all()
    # the closed-loop Model directly (successor only)
    res_m = zonotope_sivia(cl, Z0, P, 0.1)
    assert res_m.success and len(res_m.boundary) == 0


def test_cannon_001_level_one_is_refused():
    """|V x| <= 1 is not admissible (max |K x| = 2.0002 > 2): never all inner."""
    ex, cl, P, Z0, g, Y3 = _cannon_invariance(1.0)
    res = zonotope_sivia(g, Z0, Y3, 0.05)
    assert len(res.boundary) + res.n_discarded > 0
    assert res.volume() < res.domain.volume()
    V = P.vertices()
    assert (np.abs(V @ ex.local_law.T) > 2).any()  # the witness: a vertex of P


def test_robust_closed_loop_model():
    ex = cm.models.load("cannon_robust")
    cl = ex.model.closed_loop(ex.local_law)
    T = ex.terminal
    res = zonotope_sivia(cl, T, T, 0.05)
    pts = res.inner.sample(20, rng=0).reshape(-1, 2)
    for w in (0.85, 0.9, 0.95):
        assert T.contains(cl.step(pts, w=np.full((len(pts), 1), w))).all()
        assert T.contains(pts).all()


# ----------------------------------------------------------------------------- API
def test_classifier_labels_and_result_plot():
    f = _quadratic()
    cls = zonotope_classifier(f, cm.Box([-1, -1], [1, 1]))
    fr = ZonotopeFrontier(np.array([[0.0, 0.0], [5.0, 5.0], [0.9, 0.0]]),
                          np.array([np.eye(2) * 0.1, np.eye(2) * 0.1, np.eye(2) * 0.3]))
    assert list(cls(fr)) == [1, -1, 0]
    res = inner_zonotopes(P_FIG48, 0.1)
    assert isinstance(res, ZonotopePaving)
    ax = res.plot()
    P_FIG48.plot(ax=ax, facecolor="none", edgecolor="r")
    assert len(ax.collections) >= 3
    import matplotlib.pyplot as plt

    plt.close("all")


def test_bad_input():
    f = _quadratic()
    Z0 = cm.Zonotope([0.0, 0.0], np.eye(2))
    with pytest.raises(cm.DimensionError):
        zonotope_sivia(f, Z0, cm.Box([-1], [1]), 0.1)
    with pytest.raises(cm.DimensionError):
        zonotope_sivia(f, cm.Zonotope([0.0], [[1.0]]), cm.Box([-1, -1], [1, 1]), 0.1)
    with pytest.raises(ValueError, match="eps"):
        zonotope_sivia(f, Z0, cm.Box([-1, -1], [1, 1]), 0.0)
    with pytest.raises(TypeError):
        zonotope_sivia("x**2", Z0, cm.Box([-1, -1], [1, 1]), 0.1)
    with pytest.raises(TypeError):
        zonotope_sivia(f, Z0, [[-1, 1], [-1, 1]], 0.1)
    with pytest.raises(cm.ModelError, match="closed_loop"):
        zonotope_sivia(cm.models.load("cannon_001").model, Z0, cm.Box([-1, -1], [1, 1]), 0.1)
    with pytest.raises(ValueError, match="box_form"):
        zonotope_sivia(f, Z0, cm.Box([-1, -1], [1, 1]), 0.1, box_form="taylor")
    with pytest.raises(cm.UnboundedSetError):
        inner_zonotopes(cm.Polytope([[1.0, 0.0]], [1.0]), 0.1)


def test_discontinuous_map_falls_back_to_box_enclosure():
    x = ca.SX.sym("x", 2)
    f = ca.Function("step", [x], [ca.if_else(x[0] > 0, x[0], 0.5 * x[0]) + x[1]])
    with pytest.warns(cm.CmpcWarning, match="mean-value"):
        res = zonotope_sivia(f, cm.Box([-1, -1], [1, 1]), cm.Box([-0.5], [0.5]), 0.1)
    pts = res.inner.sample(20, rng=0).reshape(-1, 2)
    assert (np.abs(_eval(f, pts)) <= 0.5).all()


def test_budget_leftovers_are_boundary():
    res = inner_zonotopes(P_FIG48, 0.001, max_boxes=200)
    assert res.status == Status.BUDGET and not res.success
    assert len(res.boundary) > 0


def test_docstring_examples():
    # by module path: a package star-import would shadow the module with the function
    mod = importlib.import_module("casadi_cmpc.solvers.zonotope_sivia")
    result = doctest.testmod(mod, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0
