"""Certified answers of the polytope tests do not depend on translation or scale.

Every claim is checked against the stored data in exact rational arithmetic: a box
reported inside has its corners (and samples) inside, a box reported disjoint has no
sampled point inside, ``is_empty()`` is never True for a set with a known point.
"""

from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.sets import _hull


def exact_in(A, b, x):
    """x in {A x <= b}, exactly (stored floats read as rationals)."""
    xf = [Fraction(float(v)) for v in x]
    return all(sum((Fraction(float(a)) * v for a, v in zip(row, xf, strict=True)),
                   Fraction(0)) <= Fraction(float(bi))
               for row, bi in zip(A, b, strict=True) if np.isfinite(bi))


def exact_in_union(U, x):
    return any(exact_in(P.A, P.b, x) for P in U.polytopes)


def corners(box):
    n = box.shape[0]
    out = []
    for k in range(2 ** n):
        out.append([box[j, (k >> j) & 1] for j in range(n)])
    return np.array(out)


def samples(box, rng, k=60):
    pts = rng.uniform(box[:, 0], box[:, 1], (k, box.shape[0]))
    return np.vstack([pts, corners(box)])


# ----------------------------------------------------------------- the review's cases
def test_union_gap_far_from_origin_is_not_covered():
    for x0 in (0.0, 1e6, -1e8, 3e7):
        for g in (1e-4, 1e-7):
            L = cm.Polytope.from_box(cm.Box([x0 - 1, 0], [x0, 1]))
            R = cm.Polytope.from_box(cm.Box([x0 + g, 0], [x0 + 1 + g, 1]))
            U = cm.PolytopeUnion([L, R])
            box = np.array([[[x0 - 0.5, x0 + 0.5], [0.2, 0.8]]])
            assert not U.contains_box(box)[0]
            if g >= 1e-4 * max(1.0, abs(x0)) * 1e-6:
                mid = np.array([x0 + g / 2, 0.5])
                if mid[0] > x0 and mid[0] < x0 + g:
                    assert not exact_in_union(U, mid)
            # closing the gap exactly: covered
            R2 = cm.Polytope.from_box(cm.Box([x0, 0], [x0 + 1, 1]))
            assert cm.PolytopeUnion([L, R2]).contains_box(box)[0]


@pytest.mark.parametrize("y0", [0.0, 1e6, 1e10, -1e10])
def test_small_triangle_far_away_keeps_its_dimension(y0):
    V = np.array([[0.0, y0], [0.5, y0], [0.0, y0 + 0.5]])
    T = cm.Polytope.from_vertices(V)
    assert T.is_full_dimensional()
    assert len(T.vertices()) == 3
    assert {tuple(v) for v in T.vertices()} == {tuple(v) for v in V}
    for v in V:
        assert exact_in(T.A, T.b, v)
    # a point just outside the hypotenuse is outside the H-representation
    assert not T.contains([0.3, y0 + 0.3])
    np.testing.assert_allclose(T.support([1.0, 1.0]), 0.5 + y0, rtol=1e-15)
    fresh = cm.Polytope(T.A, T.b)
    np.testing.assert_allclose(np.sort(fresh.vertices(), axis=0), np.sort(V, axis=0),
                               atol=1e-6 * max(1.0, abs(y0)) * 1e-9 + 1e-9)


def test_sivia_contract_keeps_solutions_of_a_far_triangle():
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [x])
    V = np.array([[0.0, 1e10], [0.5, 1e10], [0.0, 1e10 + 0.5]])
    T = cm.Polytope.from_vertices(V)
    S = cm.sivia(f, cm.Box([-0.1, 1e10 - 0.1], [0.6, 1e10 + 0.6]), T, eps=0.05, contract=True)
    pts = np.array([[0.1, 1e10 + 0.1], [0.2, 1e10 + 0.25], [0.01, 1e10 + 0.01]])
    assert S.contains(pts).all() if hasattr(S, "contains") else True
    assert len(S.inner) > 0
    for box in S.inner:
        for c in corners(np.asarray(box)):
            assert exact_in(T.A, T.b, c)


@pytest.mark.parametrize("radius", [1e-6, 1e-9])
@pytest.mark.parametrize("dist", [100.0, 1e6])
def test_tiny_sets_far_away_do_not_raise(radius, dist):
    th = np.arange(6) * np.pi / 3
    V = np.c_[dist + radius * np.cos(th), radius * np.sin(th)]
    Pv = cm.Polytope.from_vertices(V)
    for P in (Pv, cm.Polytope(Pv.A, Pv.b)):
        assert not P.is_empty()
        B = P.bounding_box()
        for v in V:
            assert B.contains(v)
        assert B.hi[0] - B.lo[0] < 3 * radius + 64 * np.spacing(dist)
        M = P.minimal()
        assert M.n_constraints == 6
        assert len(P.vertices()) == 6
        x = ca.SX.sym("x", 2)
        S = cm.sivia(ca.Function("f", [x], [x]), cm.Box(V.min(0) - radius, V.max(0) + radius),
                     P, eps=radius / 4)
        assert len(S.inner) > 0
        for box in S.inner:
            for c in corners(np.asarray(box)):
                assert exact_in(P.A, P.b, c)


# ------------------------------------------------------------------- flat sets
@pytest.mark.parametrize("n", [2, 3, 4])
@pytest.mark.parametrize("shift", [0.0, 1e6, -1e8])
def test_flat_hulls_are_described_by_equality_pairs(n, shift):
    rng = np.random.default_rng(n)
    # a triangle (a segment for n = 2) in the coordinate plane x_{n-1} = shift + 0.5
    k = min(3, n)
    pts = np.zeros((k, n))
    pts[:, : k - 1] = np.round(rng.uniform(-1, 1, (k, k - 1)), 3) + shift
    pts[:, -1] = shift + 0.5
    extra = pts.mean(axis=0)  # not extreme
    P = cm.Polytope.from_vertices(np.vstack([pts, extra]))
    assert not P.is_full_dimensional()
    V = P.vertices()
    assert {tuple(v) for v in V} == {tuple(v) for v in pts}
    e = np.zeros(n)
    e[-1] = 1.0
    # the equality pair x_{n-1} = shift + 0.5 is stored exactly
    assert any(np.array_equal(a, e) and b == shift + 0.5 for a, b in zip(P.A, P.b, strict=True))
    assert any(np.array_equal(a, -e) and b == -(shift + 0.5)
               for a, b in zip(P.A, P.b, strict=True))
    D = rng.normal(size=(10, n))
    np.testing.assert_allclose(P.support(D), (pts @ D.T).max(axis=0),
                               rtol=1e-12, atol=1e-9 * max(1, abs(shift)))
    off = extra.copy()
    off[-1] += 1e-3
    assert not P.contains(off)
    for p in pts:
        assert exact_in(P.A, P.b, p)


# ---------------------------------------------------------- property tests
def _base_polytope(rng, n):
    """Integer vertices: an exact reference in rational arithmetic."""
    V = rng.integers(-5, 6, size=(n + 4, n)).astype(float)
    while np.linalg.matrix_rank(V[1:] - V[0]) < n:
        V = rng.integers(-5, 6, size=(n + 4, n)).astype(float)
    return cm.Polytope.from_vertices(V)


settings.register_profile("robust", max_examples=25, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(2, 4), seed=st.integers(0, 2 ** 31),
       shift=st.floats(-1e8, 1e8), log_s=st.floats(-6, 6))
def test_polytope_box_answers_survive_translation_and_scaling(n, seed, shift, log_s):
    rng = np.random.default_rng(seed)
    P0 = _base_polytope(rng, n)
    s = 10.0 ** log_s
    t = shift * rng.uniform(-1, 1, n)
    P = cm.Polytope(P0.A, P0.b * s + P0.A @ t)  # the stored (A, b) is the reference
    P = cm.Polytope(P.A, P.b)
    c = t + s * rng.uniform(-6, 6, (40, n))
    r = s * rng.uniform(0.01, 3, (40, n))
    boxes = np.stack([c - r, c + r], axis=-1)
    # include boxes touching a vertex / a facet
    inside = P.contains_box(boxes)
    meets = P.intersects_box(boxes)
    assert not np.any(inside & ~meets)
    assert not P.is_empty()
    for k in range(boxes.shape[0]):
        pts = samples(boxes[k], rng, 30)
        if inside[k]:
            for p in corners(boxes[k]):
                assert exact_in(P.A, P.b, p)
        if not meets[k]:
            for p in pts:
                assert not exact_in(P.A, P.b, p)
    B = P.bounding_box().as_array()
    V = P.vertices()  # floating-point vertices: inside B up to rounding
    slack = 1e-9 * s + 64 * np.spacing(np.abs(V).max())
    assert np.all(V >= B[:, 0] - slack) and np.all(V <= B[:, 1] + slack)
    # every point of the stored set is inside the bounding box (exactly)
    for p in samples(np.stack([B[:, 0] - s, B[:, 1] + s], axis=-1), rng, 200):
        if exact_in(P.A, P.b, p):
            assert np.all(p >= B[:, 0]) and np.all(p <= B[:, 1])


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(2, 4), seed=st.integers(0, 2 ** 31),
       k=st.lists(st.integers(-900, 900), min_size=1, max_size=12))
def test_rows_scaled_by_powers_of_two_give_the_same_answers(n, seed, k):
    """Scaling a row ``a x <= b`` by 2**k (exact) leaves the set unchanged: every answer,
    including those decided by LPs on the unit rows, is the same bit for bit, whatever the
    magnitudes (a row norm computed in floating point underflows below about 1e-154 and
    overflows above 1e154)."""
    rng = np.random.default_rng(seed)
    P0 = _base_polytope(rng, n)
    P = cm.Polytope(P0.A, P0.b)  # as stored, nothing cached (Q has nothing either)
    e = np.resize(np.asarray(k), P.A.shape[0])
    Q = cm.Polytope(np.ldexp(P.A, e[:, None]), np.ldexp(P.b, e))
    assert np.array_equal(np.ldexp(Q.A, -e[:, None]), P.A)  # the scaling was exact
    c = rng.uniform(-6, 6, (30, n))
    r = rng.uniform(0.01, 3, (30, n))
    boxes = np.stack([c - r, c + r], axis=-1)
    assert np.array_equal(P.contains_box(boxes), Q.contains_box(boxes))
    assert np.array_equal(P.intersects_box(boxes), Q.intersects_box(boxes))
    assert P.is_empty() == Q.is_empty() and P.is_bounded() == Q.is_bounded()
    assert np.array_equal(P.bounding_box().as_array(), Q.bounding_box().as_array())
    assert P.volume() == Q.volume()
    pts = rng.uniform(-6, 6, (50, n))
    assert np.array_equal(P.contains(pts), Q.contains(pts))


def test_a_row_whose_norm_underflows_still_constrains():
    """``1e-200 x <= 0`` is ``x <= 0``: no box with x > 0 is inside, the bounding box and
    the volume see the row."""
    A = np.array([[1e-200, 0], [1, 0], [0, 1.0], [-1, 0], [0, -1]])
    P = cm.Polytope(A, np.array([0, 1, 1, 1, 1.0]))
    assert not P.contains_box(np.array([[[0.25, 0.5], [0, 0.5]]]))[0]
    assert not P.intersects_box(np.array([[[0.25, 0.5], [0, 0.5]]]))[0]
    assert P.bounding_box().as_array()[0, 1] < 1e-12
    assert P.volume() == pytest.approx(2.0)


def test_a_row_beyond_the_double_range_answers_without_scipy_errors():
    """``1e-10 x <= 1e300`` bounds x only beyond the largest double: the LPs leave it
    out (their claims hold for a superset), and what cannot be represented is refused
    with a clear error."""
    A = np.array([[1e-10, 0], [0, 1.0], [-1, 0], [0, -1]])
    P = cm.Polytope(A, np.array([1e300, 1, 1, 1]))
    assert not P.is_empty() and P.is_bounded()
    assert P.intersects_box(np.array([[[0, 1], [0, 1]]]))[0]
    assert P.contains_box(np.array([[[0, 1e300], [0, 1]]]))[0]
    assert P.bounding_box().as_array()[0, 1] == np.inf
    with pytest.raises(cm.SolverError, match="floating-point range"):
        P.volume()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(2, 4), seed=st.integers(0, 2 ** 31),
       shift=st.floats(-1e8, 1e8), log_s=st.floats(-6, 6), log_gap=st.floats(-12, 0))
def test_union_answers_survive_translation_and_scaling(n, seed, shift, log_s, log_gap):
    rng = np.random.default_rng(seed)
    s = 10.0 ** log_s
    t = shift * rng.uniform(-1, 1, n)
    g = s * 10.0 ** log_gap * rng.choice([0.0, 1.0, -1.0])  # gap, touch or overlap
    lo1 = t.copy()
    hi1 = t + s
    lo2 = t.copy()
    lo2[0] = hi1[0] + g
    hi2 = lo2 + s
    L = cm.Polytope.from_box(cm.Box(lo1, hi1))
    R = cm.Polytope.from_box(cm.Box(lo2, np.maximum(hi2, lo2 + s / 2)))
    tilt = rng.normal(size=n)
    tilt /= np.linalg.norm(tilt)
    cut = cm.Polytope(np.vstack([R.A, tilt]), np.concatenate([R.b, [tilt @ hi2 + s]]))
    U = cm.PolytopeUnion([L, cut])
    c = hi1[0] + s * rng.uniform(-0.5, 0.5, (30, 1)) * np.eye(n)[0] + \
        (t + s * rng.uniform(0.05, 0.95, (30, n))) * (1 - np.eye(n)[0])
    r = s * rng.uniform(1e-3, 0.4, (30, n))
    boxes = np.stack([c - r, c + r], axis=-1)
    inside = U.contains_box(boxes)
    meets = U.intersects_box(boxes)
    assert not np.any(inside & ~meets)
    for k in range(boxes.shape[0]):
        if inside[k]:
            pts = samples(boxes[k], rng, 30)
            if g > 0 and boxes[k][0, 0] < hi1[0] < boxes[k][0, 1]:
                mid = pts[0].copy()
                mid[0] = hi1[0] + g / 2
                if hi1[0] < mid[0] < lo2[0]:
                    pts = np.vstack([pts, mid])
            for p in pts:
                assert exact_in_union(U, p)
        if not meets[k]:
            for p in samples(boxes[k], rng, 30):
                assert not exact_in_union(U, p)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(2, 4), shift=st.floats(-1e8, 1e8), log_s=st.floats(-6, 6),
       log_w=st.floats(-14, 0), seed=st.integers(0, 2 ** 31))
def test_emptiness_is_only_claimed_when_true(n, shift, log_s, log_w, seed):
    rng = np.random.default_rng(seed)
    s = 10.0 ** log_s
    t = shift * rng.uniform(-1, 1, n)
    w = s * 10.0 ** log_w * rng.choice([-1.0, 1.0])  # slab width: negative = empty
    a = rng.normal(size=n)
    A = np.vstack([np.eye(n), -np.eye(n), a, -a])
    b = np.concatenate([t + s, -(t - s), [a @ t + w, -(a @ t)]])
    P = cm.Polytope(A, b)
    # a point of the stored set, found in exact arithmetic on a grid near t
    if P.is_empty():
        for p in samples(np.stack([t - s, t + s], axis=-1), rng, 200):
            assert not exact_in(A, b, p)
        assert w < 0
    # "clearly" empty or not: |w| beyond the scale tolerance and far beyond the rounding of
    # the stored right-hand sides (a.t is about |a| |t|, rounded to ~1e-16 of that)
    clear = 1e-6 * s + 1e-12 * (np.abs(a) @ np.abs(t) + np.abs(t).max())
    if w < 0 and abs(w) > clear:
        assert P.is_empty()  # clearly empty after rounding: the certificate finds it
    if w > 0 and abs(w) > clear:
        assert not P.is_empty()


# ------------------------------------------------------------ both backends
@pytest.fixture(params=["cdd", "scipy"])
def backend(request, monkeypatch):
    if request.param == "scipy":
        monkeypatch.setattr(_hull, "_cdd", lambda: None)
    elif _hull._cdd() is None:
        pytest.skip("pycddlib is not installed")
    return request.param


@pytest.mark.parametrize("n", [2, 3, 4])
def test_vertices_projection_minimal_on_both_backends(backend, n):
    rng = np.random.default_rng(10 + n)
    V = rng.normal(size=(12, n))
    P0 = cm.Polytope.from_vertices(V)
    P = cm.Polytope(np.vstack([P0.A, P0.A[:2]]), np.concatenate([P0.b, P0.b[:2] + 1.0]))
    W = P.vertices()
    assert {tuple(np.round(v, 9)) for v in W} == {tuple(np.round(v, 9))
                                                  for v in P0.vertices()}
    M = P.minimal()
    assert M.n_constraints == P0.n_constraints
    for method in ("support", "vertices"):
        Q = P.project([0, 1], method=method)
        np.testing.assert_allclose(Q.support(np.eye(2)), V[:, :2].max(axis=0), atol=1e-9)
    # an unbounded polyhedron: elimination (cddlib or Fourier-Motzkin)
    H = cm.Polytope(np.vstack([P0.A[:, :2] @ np.eye(2), [[0.0, -1.0]]]) if n == 2 else
                    np.vstack([np.eye(n)[:1], -np.eye(n)[:1], [[1.0] * n]]),
                    np.concatenate([P0.b, [5.0]]) if n == 2 else np.array([1.0, 1.0, 2.0]))
    E = H.project([0], method="elimination")
    np.testing.assert_allclose(E.bounding_box().as_array()[0, 1], H.support(np.eye(n)[0]),
                               atol=1e-9)
    # a flat polytope in H-representation (no interior)
    F = cm.Polytope(np.vstack([np.eye(n), -np.eye(n)]),
                    np.concatenate([[1.0] * (n - 1) + [0.5], [1.0] * (n - 1) + [-0.5]]))
    FV = F.vertices()
    assert len(FV) == 2 ** (n - 1)
    np.testing.assert_allclose(FV[:, -1], 0.5, atol=1e-12)


def test_no_module_imports_cdd_at_import_time():
    import subprocess
    import sys

    code = ("import sys; sys.modules['cdd'] = None\n"
            "import casadi_cmpc as cm, numpy as np\n"
            "import casadi_cmpc.sets.polytope, casadi_cmpc.control.linear_sets\n"
            "P = cm.Polytope(np.vstack([np.eye(2), -np.eye(2)]), np.ones(4))\n"
            "assert len(P.vertices()) == 4\n"
            "assert len(P.project([0], method='elimination').minimal().A) == 2\n")
    subprocess.run([sys.executable, "-c", code], check=True)


# ------------------------------------------------------ nearly flat point clouds
def _check_flat_cloud(V):
    """The protocol never raises on the hull of V and its certified answers hold."""
    n = V.shape[1]
    P = cm.Polytope.from_vertices(V)
    for v in V:  # every input point is in the stored rows, exactly
        assert exact_in(P.A, P.b, v)
    for Q in (P, cm.Polytope(P.A, P.b)):
        assert not Q.is_empty()
        B = Q.bounding_box()
        for v in V:  # the bounding box contains every input point, exactly
            assert np.all(B.lo <= v) and np.all(v <= B.hi)
        w = np.maximum(np.abs(V) * 1e-15, 1e-300)
        tiny = np.stack([V - w, V + w], axis=-1)
        assert Q.intersects_box(tiny).all()
        inside = Q.contains_box(tiny)
        for k in np.flatnonzero(inside):
            for c in corners(tiny[k]):
                assert exact_in(Q.A, Q.b, c)
        lo, hi = V.min(axis=0), V.max(axis=0)
        far = np.stack([hi + (hi - lo) + 1.0, hi + 2 * (hi - lo) + 2.0], axis=-1)
        Q.intersects_box(np.stack([np.stack([lo, hi], -1), far]))
        Q.support(np.vstack([np.eye(n), -np.eye(n)]))
    assert len(P.vertices()) >= 1


def test_four_points_in_r4_near_a_point_are_flat():
    V = np.array([[-37.49999994, -37.50000003, -37.49999995, -37.49999998],
                  [-37.50000017, -37.49999991, -37.50000016, -37.50000004],
                  [-37.49999979, -37.50000002, -37.49999987, -37.4999999],
                  [-37.4999998, -37.4999998, -37.50000005, -37.4999998]])
    P = cm.Polytope.from_vertices(V)
    assert len(P.vertices()) == 4
    assert any(np.array_equal(-a, c) for a in P.A for c in P.A)  # a slab pair
    _check_flat_cloud(V)


def test_affine_hull_rank_is_at_most_n_points_minus_one():
    rng = np.random.default_rng(1)
    for shift in (0.0, -37.5, 1e8, 1e12):
        for N in range(1, 5):
            V = shift + 1e-7 * max(1.0, abs(shift)) * rng.standard_normal((N, 4))
            _, U, Nc = _hull.affine_hull(V)
            assert U.shape[1] <= N - 1 or (N == 1 and U.shape[1] == 0)
            assert U.shape[1] + Nc.shape[1] == 4


def test_segment_far_from_origin_answers_without_error():
    V = np.array([[1e12 + 1000 * a, 1e12 + 1000 * 0.3 * a] for a in (-1.3, 0.2, 0.9)])
    P = cm.Polytope.from_vertices(V)
    box = np.array([[[1e12, 1e12 + 1000.0]] * 2])
    assert P.intersects_box(box)[0]  # the segment passes through the box
    B = P.bounding_box()
    slack = 64 * np.spacing(1e12)
    assert B.hi[0] - B.lo[0] < 2200 + slack and B.hi[1] - B.lo[1] < 660 + slack
    # a box beside the segment is separated (the LP stage gives a certificate)
    assert not P.intersects_box(np.array([[[1e12 - 1300, 1e12 - 1200],
                                           [1e12 + 100, 1e12 + 200]]]))[0]
    _check_flat_cloud(V)


def test_sliver_near_a_point_answers_without_error():
    # six points on a segment of length 6e-3, flat up to the rounding of coordinates
    rng = np.random.default_rng(14)
    t = rng.uniform(-1, 1, 6)
    V = np.c_[-38.6712 + 3e-3 * t, -50.2942 + 4.1e-4 * t]
    _check_flat_cloud(V)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(2, 4), seed=st.integers(0, 2 ** 31),
       shift=st.sampled_from([0.0, -37.5, 1e6, -1e8, 3.3e11, 1e12, -1e12]),
       log_rel=st.floats(-9, 0), few=st.booleans())
def test_flat_clouds_never_raise_and_contain_their_points(n, seed, shift, log_rel, few):
    rng = np.random.default_rng(seed)
    if few:  # N <= n points: at most N - 1 dimensions
        N = int(rng.integers(1, n + 1))
        r = max(N - 1, 1)
    else:  # more points on an r-flat
        r = int(rng.integers(1, n))
        N = int(rng.integers(r + 1, 2 * n + 3))
    spread = max(abs(shift), 1.0) * 10.0 ** log_rel
    V = (rng.standard_normal((N, r)) @ rng.standard_normal((r, n))) * spread \
        + shift * rng.uniform(0.5, 1.5, n)
    _check_flat_cloud(V)


def test_hull_of_many_points_needs_no_n_by_n_matrix():
    """The affine hull of N points takes the n right singular vectors only: 60 000 points
    (a full N x N factor would need 29 GB) give their hull, which holds them."""
    rng = np.random.default_rng(5)
    pts = rng.normal(size=(60_000, 3))
    P = cm.Polytope.from_vertices(pts)
    assert P.contains(pts[::97]).all() and P.is_full_dimensional()


def test_a_row_below_the_double_range_is_refused_not_read_as_vacuous():
    """``1e-300 x1 <= -1e10`` (x1 <= -1e310) holds at no double point: with the unit
    box the set is empty over the reals. Exact tests answer exactly; the LP-based ones
    refuse with a clear error instead of dropping the row (they gave the unit box's
    vertices and volume)."""
    A = np.array([[1.0, 0], [-1.0, 0], [0, 1.0], [0, -1.0], [1e-300, 0.0]])
    P = cm.Polytope(A, np.array([1.0, 0.0, 1.0, 0.0, -1e10]))
    assert not P.contains_box(np.array([[[0.2, 0.4], [0.2, 0.4]]]))[0]
    assert not P.contains(np.array([[0.5, 0.5]]))[0]
    for op in (P.volume, P.bounding_box, P.minimal, P.chebyshev_ball):
        with pytest.raises(ValueError, match="floating-point range"):
            op()


def test_an_unbounded_set_is_not_inside_a_far_row():
    """{x1 >= 0} is not inside {1e-300 x1 <= 1e10} = {x1 <= 1e310} (over the reals)."""
    P = cm.Polytope(np.array([[-1.0, 0.0]]), np.array([0.0]))
    Q = cm.Polytope(np.array([[1e-300, 0.0]]), np.array([1e10]))
    assert not P.is_subset(Q)


def _exact_le(row, bi, x):
    return sum((Fraction(float(a)) * Fraction(float(v)) for a, v in zip(row, x, strict=True)),
               Fraction(0)) <= Fraction(float(bi))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(2, 4), seed=st.integers(0, 2 ** 31), k=st.integers(1, 5))
def test_box_and_point_tests_hold_at_extreme_magnitudes(n, seed, k):
    """Rows with entries from 1e-300 to 1e300 (mixed within a row), right-hand sides and
    points whose products overflow or underflow part-way: ``contains`` is exact,
    ``contains_box`` True has every corner inside, ``intersects_box`` False has no corner
    inside (all checked in rational arithmetic); an overflowed float sum proves nothing."""
    rng = np.random.default_rng(seed)
    A = rng.choice([-1.0, 1.0], (k, n)) * 10.0 ** rng.uniform(-300, 300, (k, n))
    A[rng.random((k, n)) < 0.2] = 0.0
    X = rng.choice([-1.0, 1.0], (6, n)) * 10.0 ** rng.uniform(-10, 10, (6, n))
    X = np.vstack([X, 10.0 ** rng.uniform(5, 9) * rng.uniform(-1, 1, (4, n))])
    # right-hand sides at the values of the rows at some points (touching, overflowing)
    vals = np.array([float(np.clip(np.dot(A[i], X[i % X.shape[0]]), -1e308, 1e308))
                     for i in range(k)])
    b = np.where(np.isfinite(vals), vals * rng.choice([0.5, 1.0, 2.0], k), 1e300)
    P = cm.Polytope(A, b)
    inside = P.contains(X)
    for x, got in zip(X, inside, strict=True):
        assert got == all(_exact_le(A[i], b[i], x) for i in range(k))
    boxes = np.stack([X, X * (1 + 1e-12) + 1e-300], axis=-1)
    boxes = np.sort(boxes, axis=-1)
    cin = P.contains_box(boxes)
    meet = P.intersects_box(boxes)
    for q in range(boxes.shape[0]):
        corners_ = corners(boxes[q])
        if cin[q]:
            assert all(_exact_le(A[i], b[i], c) for c in corners_ for i in range(k))
        if not meet[q]:
            assert not any(all(_exact_le(A[i], b[i], c) for i in range(k)) for c in corners_)


def test_overflowing_sums_are_no_proof():
    """The review's cases: exact a.x = -5e307 > b = -6e307 (outside), and the point with
    the signs flipped (inside)."""
    A = np.array([[-1e300, -1e300, 1e300]])
    x = np.array([1e8, 1e8, 1.5e8])
    P = cm.Polytope(A, np.array([-6e307]))
    assert not P.contains(x[None])[0] and not P.contains_box(np.stack([x, x], -1)[None])[0]
    Q = cm.Polytope(-A, np.array([6e307]))
    assert Q.contains(x[None])[0] and Q.intersects_box(np.stack([x, x], -1)[None])[0]
