"""PolytopeUnion: membership, exact box-in-union test (thesis §6.1.4), protocol members."""

import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.exceptions import DimensionError, EmptySetError


def box_poly(lo, hi):
    return cm.Polytope.from_box(cm.Box(lo, hi))


def corners(box):
    bits = np.array(list(itertools.product((0, 1), repeat=box.shape[0])), dtype=bool)
    return np.where(bits, box[:, 1], box[:, 0])


def test_construction_and_membership():
    L = box_poly([0, 0], [1, 1])
    T = cm.Polytope.from_vertices([[1, 0], [2, 0], [1, 1]])
    U = cm.PolytopeUnion([L, T])
    assert U.dim == 2 and len(U) == 2 and list(U) == [L, T]
    assert isinstance(U, cm.SetBase)
    np.testing.assert_array_equal(U.contains([[0.5, 0.5], [1.5, 0.2], [1.5, 0.8]]),
                                  [True, True, False])
    assert U.contains([1.5, 0.5 + 1e-10], tol=1e-9) is True
    assert repr(U) == "PolytopeUnion(dim=2, polytopes=2)"
    with pytest.raises(TypeError, match="not a Polytope"):
        cm.PolytopeUnion([L, cm.Box([0, 0], [1, 1])])
    with pytest.raises(ValueError, match="at least one"):
        cm.PolytopeUnion([])
    with pytest.raises(DimensionError, match="differ in dimension"):
        cm.PolytopeUnion([L, box_poly([0], [1])])
    with pytest.raises(DimensionError):
        cm.PolytopeUnion([L], dim=3)


def test_box_covered_by_two_members_together_but_by_neither_alone():
    L = box_poly([0, 0], [1, 1])
    R = cm.Polytope.from_vertices([[1, -0.5], [2.5, -0.5], [2.5, 1.5], [1, 1.5]])
    U = cm.PolytopeUnion([L, R])
    box = np.array([[[0.5, 1.5], [0.2, 0.8]]])
    assert not L.contains_box(box)[0] and not R.contains_box(box)[0]  # closed form fails
    res, wit = U.contains_box(box, return_witness=True)
    assert res[0] and np.isnan(wit).all()
    # the same with a diagonal seam: two triangles tile the square exactly
    T1 = cm.Polytope.from_vertices([[0, 0], [1, 0], [1, 1]])
    T2 = cm.Polytope.from_vertices([[0, 0], [0, 1], [1, 1]])
    np.testing.assert_array_equal(
        cm.PolytopeUnion([T1, T2]).contains_box([[[0, 1], [0, 1]], [[0.2, 0.9], [0.1, 0.3]],
                                                 [[0, 1.01], [0, 1]]]),
        [True, True, False])
    # three members meeting at one point
    th = np.array([0, 2 * np.pi / 3, 4 * np.pi / 3, 2 * np.pi])
    fans = [cm.Polytope.from_vertices([[0, 0], 3 * np.array([np.cos(a), np.sin(a)]),
                                       3 * np.array([np.cos(b), np.sin(b)]),
                                       3 * np.array([np.cos((a + b) / 2),
                                                     np.sin((a + b) / 2)]) / np.cos(np.pi / 3)])
            for a, b in zip(th[:-1], th[1:], strict=True)]
    # 3 (cos 2pi, sin 2pi) != (3, 0): the stored fans leave a sliver of angle ~2e-16
    # uncovered at the origin, and the certified answer must be False
    F = cm.PolytopeUnion(fans)
    gap = np.array([1.0, -1e-16])
    assert not F.contains(gap)
    assert not F.contains_box([[-1, 1], [-1, 1]])[0]
    # the same fans closing exactly (shared edges): covered
    th[-1] = 0.0
    fans = [cm.Polytope.from_vertices([[0, 0], 3 * np.array([np.cos(a), np.sin(a)]),
                                       3 * np.array([np.cos(b), np.sin(b)]),
                                       3 * np.array([np.cos((a + b) / 2),
                                                     np.sin((a + b) / 2)]) / np.cos(np.pi / 3)])
            for a, b in zip(th[:-1], th[1:], strict=True)]
    assert cm.PolytopeUnion(fans).contains_box([[-1, 1], [-1, 1]])[0]


def test_small_gap_is_found():
    L = box_poly([0, 0], [1, 1])
    R = box_poly([1.001, 0], [2, 1])
    U = cm.PolytopeUnion([L, R])
    boxes = np.array([[[0.5, 1.5], [0.2, 0.8]], [[0.2, 0.4], [0.2, 0.4]],
                      [[0.999, 1.0015], [0.5, 0.6]]])
    res, wit = U.contains_box(boxes, return_witness=True)
    np.testing.assert_array_equal(res, [False, True, False])
    for k in (0, 2):
        assert cm.Box.from_array(boxes[k]).contains(wit[k])
        assert not U.contains(wit[k])
    # a gap too thin for the sample points: found by the exact stage (LP pieces)
    R2 = cm.Polytope([[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-1.0, 1e-3]],
                     [-1.0, 2.0, 1.0, 0.0, -0.9995])
    U2 = cm.PolytopeUnion([L, R2])
    box = np.array([[0.5, 1.5], [0.2, 0.8]])
    assert U2.contains(corners(box)).all() and U2.contains(box.mean(axis=1))
    res, wit = U2.contains_box(box, return_witness=True)
    assert not res[0]
    assert cm.Box.from_array(box).contains(wit[0]) and not U2.contains(wit[0])


def _random_union(rng, k, n=2):
    members = []
    for _ in range(k):
        c = rng.uniform(-1, 1, n)
        members.append(cm.Polytope.from_vertices(c + 0.7 * rng.normal(size=(3 * n + 3, n))))
    return cm.PolytopeUnion(members)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), width=st.floats(0.02, 0.8))
def test_random_box_tests_against_sampling(seed, width):
    rng = np.random.default_rng(seed)
    U = _random_union(rng, 4)
    c = rng.uniform(-1.5, 1.5, (40, 2))
    r = width * rng.random((40, 2))
    boxes = np.stack([c - r, c + r], axis=-1)
    res, wit = U.contains_box(boxes, return_witness=True)
    meets = U.intersects_box(boxes)
    for k, box in enumerate(boxes):
        pts = np.vstack([corners(box), box[:, 0] + (box[:, 1] - box[:, 0])
                         * rng.random((300, 2))])
        inside = U.contains(pts)
        if res[k]:
            assert U.contains(pts, tol=1e-9).all()
            assert meets[k]
        else:
            assert cm.Box.from_array(box).contains(wit[k]) and not U.contains(wit[k])
        if inside.any():
            assert meets[k]
        np.testing.assert_equal(meets[k], any(P.intersects_box(box)[0] for P in U))


def test_exact_stage_on_a_three_dimensional_union():
    rng = np.random.default_rng(2)
    # a cube cut into slabs by random planes: every box inside the cube is covered
    cube = box_poly([-1, -1, -1], [1, 1, 1])
    a = rng.normal(size=3)
    cuts = [-0.4, 0.1, 0.5]
    pieces = []
    lo = -np.inf
    for hi in [*cuts, np.inf]:
        rows = [a, -a]
        rhs = [hi, -lo]
        P = cube & cm.Polytope(np.array(rows), np.array(rhs))
        pieces.append(P)
        lo = hi
    U = cm.PolytopeUnion(pieces)
    c = rng.uniform(-0.8, 0.8, (30, 3))
    r = rng.uniform(0.01, 0.2, (30, 3))
    boxes = np.stack([c - r, c + r], axis=-1)
    assert U.contains_box(boxes).all()
    # without the middle piece, boxes that cross its slab are not covered
    V = cm.PolytopeUnion([pieces[0], pieces[2], pieces[3]])
    res, wit = V.contains_box(boxes, return_witness=True)
    crosses = np.array([pieces[1].intersects_box(b)[0] and
                        (pieces[1] & cm.Polytope.from_box(cm.Box.from_array(b)))
                        .is_full_dimensional() for b in boxes])
    np.testing.assert_array_equal(res, ~crosses)
    for k in np.flatnonzero(~res):
        assert not V.contains(wit[k]) and cm.Box.from_array(boxes[k]).contains(wit[k])


def test_subset_of_union_and_difference():
    L = box_poly([0, 0], [1, 1])
    R = box_poly([1, 0], [2, 1])
    U = cm.PolytopeUnion([L, R])
    assert box_poly([0.5, 0.1], [1.5, 0.9]).is_subset(U)
    assert not box_poly([0.5, 0.1], [2.5, 0.9]).is_subset(U)
    seg = cm.Polytope.from_vertices([[0.5, 0.5], [1.5, 0.5]])  # no interior
    assert seg.is_subset(U)
    assert not cm.Polytope.from_vertices([[0.5, 0.5], [2.5, 0.5]]).is_subset(U)
    D = U.difference(box_poly([0.5, -1], [1.5, 2]))
    X = np.random.default_rng(0).uniform(-0.5, 2.5, (2000, 2))
    expected = U.contains(X) & ~((X[:, 0] >= 0.5) & (X[:, 0] <= 1.5))
    got = D.contains(X)
    assert (got[expected]).all()
    assert not (got & (X[:, 0] > 0.5 + 1e-9) & (X[:, 0] < 1.5 - 1e-9)).any()


def test_protocol_members():
    L = box_poly([0, 0], [1, 1])
    T = cm.Polytope.from_vertices([[1, 0], [3, 0], [1, 2]])
    U = cm.PolytopeUnion([L, T, cm.Polytope.empty(2)])
    assert not U.is_empty()
    np.testing.assert_allclose(U.support([[1, 0], [0, 1], [-1, -1]]), [3, 2, 0])
    assert isinstance(U.support([1.0, 1.0]), float)
    B = U.bounding_box()
    np.testing.assert_allclose(B.lo, [0, 0], atol=1e-9)
    np.testing.assert_allclose(B.hi, [3, 2], atol=1e-9)
    H = U.convex_hull()
    assert H == cm.Polytope.from_vertices([[0, 0], [3, 0], [1, 2], [0, 1]])
    V = U.vertices()
    assert {tuple(np.round(v, 9)) for v in V} == {(0, 0), (3, 0), (1, 2), (0, 1)}
    np.testing.assert_array_equal(U.intersects_box([[[2.5, 3], [1.5, 2]], [[1.5, 2], [0, 1]]]),
                                  [False, True])


def test_empty_union():
    E = cm.PolytopeUnion([], dim=2)
    assert E.is_empty() and len(E) == 0
    boxes = np.array([[[0, 1], [0, 1]]])
    assert not E.contains_box(boxes)[0] and not E.intersects_box(boxes)[0]
    assert not E.contains([0.5, 0.5])
    assert E.support([1.0, 0.0]) == -np.inf
    with pytest.raises(EmptySetError):
        E.bounding_box()
    with pytest.raises(EmptySetError):
        E.vertices()
    assert cm.PolytopeUnion([cm.Polytope.empty(2)]).is_empty()


def test_save_load_round_trip(tmp_path):
    A1 = np.array([[1.0, 0.1], [-1.0 / 3.0, 1.0], [0.0, -1.0]])
    b1 = np.array([0.7, np.inf, 1.0 / 9.0])
    U = cm.PolytopeUnion([cm.Polytope(A1, b1), box_poly([0.1, 0.2], [0.3, 0.4])])
    for suffix in (".npz", ".json"):
        W = cm.PolytopeUnion.load(U.save(tmp_path / f"u{suffix}"))
        assert isinstance(W, cm.PolytopeUnion) and len(W) == 2
        for P, Q in zip(U, W, strict=True):
            np.testing.assert_array_equal(P.A, Q.A)
            np.testing.assert_array_equal(P.b, Q.b)
    E = cm.PolytopeUnion.load(cm.PolytopeUnion([], dim=3).save(tmp_path / "e.json"))
    assert E.dim == 3 and len(E) == 0


def test_plot_draws_every_member():
    mpl = pytest.importorskip("matplotlib")
    mpl.use("Agg")
    import matplotlib.pyplot as plt

    U = cm.PolytopeUnion([box_poly([0, 0], [1, 1]), box_poly([2, 0], [3, 1]),
                          cm.Polytope.empty(2)])
    ax = U.plot(facecolor="C2")
    assert len(ax.patches) == 2
    U3 = cm.PolytopeUnion([box_poly([0, 0, 0], [1, 1, 1])])
    assert len(U3.plot(dims=(0, 2)).patches) == 1
    plt.close("all")


def test_linear_sliding_terminal_union():
    ex = cm.models.load("linear_sliding")
    S = ex.terminal
    hull = ex.info["terminal_hull"]
    assert S.convex_hull() == hull
    # a small box around a point of one triangle is inside; one straddling the gap is not
    assert S.contains_box([[2.9, 3.0], [-3.9, -3.8]])[0]
    assert not S.contains_box([[0.9, 1.1], [-0.1, 0.1]])[0]
    assert S.intersects_box([[0.9, 1.1], [-1.5, -0.5]])[0]
