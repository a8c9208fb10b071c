"""Batched box helpers and ``Paving`` (``casadi_cmpc/sets/paving.py``)."""

from __future__ import annotations

import doctest
import itertools

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import casadi_cmpc as cm  # noqa: E402
from casadi_cmpc.sets import paving as pv  # noqa: E402
from casadi_cmpc.sets.paving import (  # noqa: E402
    bisect_boxes,
    box_diam,
    box_mid,
    box_volume,
    box_width,
    boxes_contain_points,
    hull_of_boxes,
)

SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


# --------------------------------------------------------------------- strategies
@st.composite
def bounded_boxes(draw, n=None, min_boxes=1, max_boxes=6, positive=True):
    """A batch (N, n, 2) of bounded boxes with float bounds."""
    n = draw(st.integers(1, 4)) if n is None else n
    N = draw(st.integers(min_boxes, max_boxes))
    lo = np.array(draw(st.lists(st.floats(-1e3, 1e3), min_size=N * n, max_size=N * n)))
    wmin = 1e-3 if positive else 0.0
    w = np.array(draw(st.lists(st.floats(wmin, 1e2), min_size=N * n, max_size=N * n)))
    lo = lo.reshape(N, n)
    return np.stack([lo, lo + w.reshape(N, n)], axis=-1)


@st.composite
def grid_boxes(draw, n, min_boxes=0, max_boxes=5):
    """Boxes with small integer bounds (many shared faces, some degenerate)."""
    N = draw(st.integers(min_boxes, max_boxes))
    lo = np.array(draw(st.lists(st.integers(0, 5), min_size=N * n, max_size=N * n)),
                  dtype=float).reshape(N, n)
    w = np.array(draw(st.lists(st.integers(0, 3), min_size=N * n, max_size=N * n)),
                 dtype=float).reshape(N, n)
    return np.stack([lo, lo + w], axis=-1)


def _covered_reference(q: np.ndarray, U: np.ndarray) -> bool:
    """Exact ``q ⊆ union U`` by the arrangement of all bounds.

    Along each axis the bounds inside ``q`` cut it into points and open intervals; membership
    in the union is constant on each product cell, so one point per cell decides.
    """
    axes = []
    for k in range(q.shape[0]):
        cuts = np.unique(np.concatenate([q[k], U[:, k, :].ravel()]))
        cuts = cuts[(cuts >= q[k, 0]) & (cuts <= q[k, 1])]
        axes.append(np.unique(np.concatenate([cuts, 0.5 * (cuts[1:] + cuts[:-1])])))
    pts = np.array(list(itertools.product(*axes)))
    if U.shape[0] == 0:
        return False
    inside = ((U[:, None, :, 0] <= pts) & (pts <= U[:, None, :, 1])).all(axis=2).any(axis=0)
    return bool(inside.all())


def _regular_paving(domain: np.ndarray, depth: int, rng: np.random.Generator,
                    p_stop: float = 0.3) -> np.ndarray:
    """Boxes of a regular subpaving: bisect, keep some boxes, bisect the others again."""
    frontier = domain[None].copy()
    kept = []
    for level in range(depth):
        stop = (rng.random(frontier.shape[0]) < p_stop) & (level >= 2)
        kept.append(frontier[stop])
        L, R = bisect_boxes(frontier[~stop])
        frontier = np.concatenate([L, R])
    kept.append(frontier)
    return np.concatenate(kept)


# ---------------------------------------------------------------------- bisection
@SETTINGS
@given(bounded_boxes(), st.sampled_from([0.5, 0.49, 0.3]), st.integers(0, 2 ** 31))
def test_bisection_halves_cover_the_box_exactly(boxes, ratio, seed):
    L, R = bisect_boxes(boxes, split_ratio=ratio)
    N, n = boxes.shape[:2]
    diff_l = L != boxes
    diff_r = R != boxes
    # one component changed, the same in both halves, only the inner bound
    assert (diff_l.any(axis=2).sum(axis=1) == 1).all()
    j = diff_l.any(axis=2).argmax(axis=1)
    rows = np.arange(N)
    assert (diff_r.any(axis=2).argmax(axis=1) == j).all()
    np.testing.assert_array_equal(L[..., 0], boxes[..., 0])
    np.testing.assert_array_equal(R[..., 1], boxes[..., 1])
    c = L[rows, j, 1]
    np.testing.assert_array_equal(R[rows, j, 0], c)  # the halves share the face x_j = c
    lo, hi = boxes[rows, j, 0], boxes[rows, j, 1]
    assert ((lo < c) & (c < hi)).all()
    np.testing.assert_allclose(c, lo + ratio * (hi - lo), rtol=1e-12, atol=1e-9)
    # volumes add up; the intersection is the face (zero width along j)
    np.testing.assert_allclose(box_volume(L) + box_volume(R), box_volume(boxes), rtol=1e-9)
    inter_w = np.minimum(L[..., 1], R[..., 1]) - np.maximum(L[..., 0], R[..., 0])
    assert (inter_w[rows, j] == 0).all()
    # union equals the box: sampled points of the box lie in a half, points of a half in the box
    rng = np.random.default_rng(seed)
    pts = boxes[..., 0] + rng.random((40, N, n)) * (boxes[..., 1] - boxes[..., 0])
    pts = np.concatenate([pts, boxes[None, ..., 0], boxes[None, ..., 1]])
    inL = ((L[..., 0] <= pts) & (pts <= L[..., 1])).all(axis=2)
    inR = ((R[..., 0] <= pts) & (pts <= R[..., 1])).all(axis=2)
    assert (inL | inR).all()
    assert ((L[..., 0] >= boxes[..., 0]) & (L[..., 1] <= boxes[..., 1])).all()
    assert ((R[..., 0] >= boxes[..., 0]) & (R[..., 1] <= boxes[..., 1])).all()


@SETTINGS
@given(st.integers(1, 5).flatmap(lambda n: st.tuples(
    st.lists(st.lists(st.integers(1, 4), min_size=n, max_size=n), min_size=1, max_size=6),
    st.lists(st.integers(-5, 5), min_size=n, max_size=n))))
def test_split_component_is_widest_with_lowest_index_on_ties(data):
    widths, lo = data
    w = np.array(widths, dtype=float)
    lo = np.broadcast_to(np.array(lo, dtype=float), w.shape)
    boxes = np.stack([lo, lo + w], axis=-1)
    L, _ = bisect_boxes(boxes)
    j = (L != boxes).any(axis=2).argmax(axis=1)
    for i in range(w.shape[0]):  # eq. (4.3): smallest index attaining the width
        expected = min(k for k in range(w.shape[1]) if w[i, k] == w[i].max())
        assert j[i] == expected
    np.testing.assert_array_equal(box_width(boxes), w.max(axis=1))


@SETTINGS
@given(st.integers(1, 4).flatmap(lambda n: st.tuples(
    st.lists(st.lists(st.integers(1, 8), min_size=n, max_size=n), min_size=1, max_size=5),
    st.lists(st.integers(1, 8), min_size=n, max_size=n))))
def test_relative_scaling_picks_widest_relative_component(data):
    widths, scale = data
    w = np.array(widths, dtype=float)
    s = np.array(scale, dtype=float)
    boxes = np.stack([np.zeros_like(w), w], axis=-1)
    init = cm.Box(np.zeros_like(s), s)
    for sc in (s, init, init.as_array()):
        L, _ = bisect_boxes(boxes, scale=sc)
        j = (L != boxes).any(axis=2).argmax(axis=1)
        rel = w / s
        for i in range(w.shape[0]):
            assert j[i] == np.flatnonzero(rel[i] == rel[i].max())[0]
    np.testing.assert_allclose(box_width(boxes, scale=s), (w / s).max(axis=1))


def test_relative_scaling_example_and_single_box_inputs():
    box = np.array([[0.0, 2.0], [0.0, 1.0]])
    L, R = bisect_boxes(box)  # absolute: component 0
    np.testing.assert_array_equal(L, [[[0, 1], [0, 1]]])
    L, R = bisect_boxes(box, scale=[10.0, 1.0])  # 2/10 < 1/1: component 1
    np.testing.assert_array_equal(L, [[[0, 2], [0, 0.5]]])
    np.testing.assert_array_equal(R, [[[0, 2], [0.5, 1]]])
    L, R = bisect_boxes(cm.Box([0, 0], [1, 1]), split_ratio=0.49)
    np.testing.assert_allclose(L[0, 0], [0, 0.49])
    E = np.zeros((0, 3, 2))
    assert bisect_boxes(E)[0].shape == (0, 3, 2)


@SETTINGS
@given(st.floats(-1e300, 1e300, allow_nan=False), st.integers(2, 6),
       st.floats(0.01, 0.99))
def test_bisection_splits_every_box_that_holds_a_float_between_its_bounds(x, k, ratio):
    """A box only a few ulps wide is split at any ratio: the cut falls back to
    (1 - r) lo + r hi where lo + r (hi - lo) lands on a bound."""
    hi = x
    for _ in range(k):
        hi = np.nextafter(hi, np.inf)
    box = np.array([[[x, hi], [0.0, 0.0]]])
    L, R = bisect_boxes(box, split_ratio=ratio)
    c = L[0, 0, 1]
    assert x < c < hi and R[0, 0, 0] == c and L[0, 0, 0] == x and R[0, 0, 1] == hi


def test_bisection_refuses_bad_boxes_and_arguments():
    with pytest.raises(cm.UnboundedSetError, match="box 1 has component 0"):
        bisect_boxes(np.array([[[0.0, 1.0]], [[0.0, np.inf]]]))
    with pytest.raises(cm.InvalidBoundsError, match="all its widths are zero"):
        bisect_boxes(np.array([[[1.0, 1.0], [2.0, 2.0]]]))
    tiny = np.array([[[1.0, np.nextafter(1.0, 2.0)]]])
    with pytest.raises(cm.InvalidBoundsError, match="no float strictly between"):
        bisect_boxes(tiny)
    with pytest.raises(ValueError, match="Unknown bisection rule"):
        bisect_boxes(np.array([[[0.0, 1.0]]]), rule="random")
    with pytest.raises(ValueError, match="split_ratio"):
        bisect_boxes(np.array([[[0.0, 1.0]]]), split_ratio=1.0)
    with pytest.raises(cm.DimensionError, match="scale"):
        bisect_boxes(np.array([[[0.0, 1.0]]]), scale=[1.0, 2.0])
    with pytest.raises(cm.InvalidBoundsError, match="scale"):
        bisect_boxes(np.array([[[0.0, 1.0]]]), scale=[-1.0])
    with pytest.raises(cm.EmptySetError):
        bisect_boxes(np.array([[[1.0, 0.0]]]))


def test_bisection_of_huge_boxes_does_not_overflow():
    L, R = bisect_boxes(np.array([[[-1e308, 1.7e308]]]))
    assert np.isfinite(L).all() and np.isfinite(R).all()
    assert L[0, 0, 1] == R[0, 0, 0]


# ------------------------------------------------------------------ other helpers
@SETTINGS
@given(bounded_boxes(positive=False), st.integers(0, 2 ** 31))
def test_box_helpers_agree_with_per_box_loops(boxes, seed):
    n = boxes.shape[1]
    np.testing.assert_array_equal(box_diam(boxes), boxes[..., 1] - boxes[..., 0])
    np.testing.assert_array_equal(box_mid(boxes), (boxes[..., 0] + boxes[..., 1]) / 2)
    np.testing.assert_allclose(box_volume(boxes),
                               [np.prod(b[:, 1] - b[:, 0]) for b in boxes], rtol=1e-12)
    hull = hull_of_boxes(boxes)
    for k in range(n):
        assert hull[k, 0] == min(b[k, 0] for b in boxes)
        assert hull[k, 1] == max(b[k, 1] for b in boxes)
    rng = np.random.default_rng(seed)
    pts = np.concatenate([boxes[..., 0], boxes[..., 1],
                          rng.uniform(hull[:, 0] - 1, hull[:, 1] + 1, (30, n))])
    M = boxes_contain_points(boxes, pts)
    assert M.shape == (boxes.shape[0], pts.shape[0])
    for i, b in enumerate(boxes):
        for k, p in enumerate(pts):
            assert M[i, k] == (all(b[:, 0] <= p) and all(p <= b[:, 1]))
    np.testing.assert_array_equal(boxes_contain_points(boxes, pts[0]), M[:, 0])


def test_box_helper_edge_cases():
    unbounded_flat = np.array([[[0.0, 0.0], [0.0, np.inf]]])
    assert box_volume(unbounded_flat)[0] == 0.0
    assert box_volume(np.array([[[0.0, 1.0], [0.0, np.inf]]]))[0] == np.inf
    assert box_width(np.zeros((0, 2, 2))).shape == (0,)
    with pytest.raises(cm.EmptySetError, match="at least one box"):
        hull_of_boxes(np.zeros((0, 2, 2)))


# -------------------------------------------------------------------- construction
def test_paving_construction_views_and_counts():
    D = cm.Box([0, 0], [4, 2])
    inner = np.array([[[0, 1], [0, 1]], [[1, 2], [0, 1]]], dtype=float)
    boundary = [cm.Box([2, 0], [3, 1])]
    outer = np.array([[[3, 4], [0, 2]]], dtype=float)
    P = cm.Paving(inner, boundary, outer, domain=D)
    assert (P.dim, P.n_inner, P.n_boundary, P.n_outside) == (2, 2, 1, 1)
    assert P.n_boxes == len(P) == 3 and P.n_discarded == 1
    assert P.domain == D and not P.is_empty()
    np.testing.assert_array_equal(P.boxes, np.concatenate([inner, boundary[0].as_array()[None]]))
    np.testing.assert_array_equal(P.view_boxes("outside"), outer)
    # the default measure is the proven part; the outer approximation is asked for by name
    assert P.volume() == 2.0 and P.volume("inner") == 2.0 and P.volume("outer") == 3.0
    assert P.volume("boundary") == 1.0 and P.volume("outside") == 2.0
    assert P.area() == 2.0 and P.area("outer") == 3.0
    with pytest.raises(ValueError, match="Unknown view"):
        P.volume("all")
    with pytest.raises(ValueError):
        P.boxes[0, 0, 0] = 5.0  # read-only
    I, O = P.inner_set(), P.outer_set()
    assert (I.n_inner, I.n_boundary, I.n_outside) == (2, 0, 0)
    assert (O.n_inner, O.n_boundary, O.n_outside) == (2, 1, 0)
    assert I.volume() == 2.0 and O.volume("outer") == 3.0 and O.volume() == 2.0
    assert P.contains([2.5, 0.5]) is True
    assert P.contains([2.5, 0.5], view="inner") is False
    assert I.contains([2.5, 0.5]) is False
    assert P.contains([3.5, 0.5], view="outside") is True
    assert cm.Paving(np.zeros((0, 3, 2))).is_empty()
    assert cm.Paving(boundary=[], domain=cm.Box([0], [1])).is_empty()
    assert "inner=2" in repr(P)
    assert P.n_discarded == 1 and cm.Paving(outside=outer, n_discarded=7).n_discarded == 7


def test_paving_refuses_bad_input():
    with pytest.raises(cm.DimensionError, match="dimension"):
        cm.Paving()
    with pytest.raises(cm.DimensionError, match="expected 2 instead of 3"):
        cm.Paving(np.zeros((1, 2, 2)), np.zeros((1, 3, 2)))
    with pytest.raises(cm.InvalidBoundsError, match="not inside the domain"):
        cm.Paving(np.array([[[0.0, 5.0]]]), domain=cm.Box([0], [1]))
    with pytest.raises(cm.EmptySetError):
        cm.Paving(np.array([[[1.0, 0.0]]]))
    with pytest.raises(cm.InvalidBoundsError, match="NaN"):
        cm.Paving(np.array([[[np.nan, 0.0]]]))
    with pytest.raises(ValueError, match="n_discarded"):
        cm.Paving(np.zeros((0, 1, 2)), n_discarded=-1)
    with pytest.raises(cm.DimensionError, match="area requires"):
        cm.Paving(np.zeros((1, 3, 2))).area()


# ---------------------------------------------------------------------- measures
def test_volume_of_regular_paving_adds_up_to_domain():
    rng = np.random.default_rng(1)
    D = np.array([[-1.0, 3.0], [0.0, 2.0], [1.0, 1.5]])
    boxes = _regular_paving(D, 9, rng)
    lab = rng.integers(0, 3, boxes.shape[0])
    P = cm.Paving(boxes[lab == 0], boxes[lab == 1], boxes[lab == 2], domain=cm.Box.from_array(D))
    dom_vol = 4.0 * 2.0 * 0.5
    assert P.volume("inner") + P.volume("boundary") + P.volume("outside") == pytest.approx(
        dom_vol, rel=1e-12)
    assert P.volume("outer") == pytest.approx(box_volume(P.boxes).sum(), rel=1e-12)
    everything = cm.Paving(boxes)
    assert everything.volume() == pytest.approx(dom_vol, rel=1e-12)
    assert everything.contains_box(D)[0]


def test_volume_default_counts_proven_boxes_only():
    """By hand: inner [0, 2] x [0, 1] (area 2) and [2, 3] x [0, 0.5] (0.5); undecided
    [0, 3] x [1, 2] (3) and [3, 4] x [0, 2] (2), overlapping the inner box by nothing."""
    P = cm.Paving(inner=[cm.Box([0, 0], [2, 1]), cm.Box([2, 0], [3, 0.5])],
                  boundary=[cm.Box([0, 1], [3, 2]), cm.Box([3, 0], [4, 2])],
                  outside=[cm.Box([2, 0.5], [3, 1])], domain=cm.Box([0, 0], [4, 2]))
    assert P.volume() == P.area() == 2.5  # undecided boxes are not counted
    assert P.volume(view="outer") == P.area("outer") == 7.5  # counted only when asked for
    assert P.volume("boundary") == 5.0 and P.volume(view="outside") == 0.5
    assert P.volume("INNER") == 2.5  # view names are not case-sensitive
    # a paving with undecided boxes only has a proven volume of 0
    assert cm.Paving(boundary=[cm.Box([0, 0], [1, 1])]).volume() == 0.0


def test_volume_counts_overlaps_once():
    P = cm.Paving([cm.Box([0, 0], [2, 2]), cm.Box([1, 1], [3, 3]), cm.Box([0.5, 0.5], [1, 1])])
    assert P.volume() == pytest.approx(7.0)
    Q = P | P
    assert Q.n_boxes == 6 and Q.volume() == pytest.approx(7.0)


@SETTINGS
@given(st.integers(1, 3).flatmap(lambda n: grid_boxes(n, 0, 5)), st.integers(0, 2 ** 31))
def test_union_volume_matches_cell_count(boxes, seed):
    """Exact volume on integer boxes: count the unit cells covered."""
    P = cm.Paving(boxes)
    n = boxes.shape[1]
    cells = np.array(list(itertools.product(range(9), repeat=n)), dtype=float) + 0.5
    covered = boxes_contain_points(boxes, cells).any(axis=0).sum() if len(boxes) else 0
    assert P.volume() == pytest.approx(float(covered))


# -------------------------------------------------------------------- membership
@SETTINGS
@given(bounded_boxes(max_boxes=8), st.integers(0, 2 ** 31))
def test_membership_agrees_with_brute_force(boxes, seed):
    rng = np.random.default_rng(seed)
    split = rng.integers(0, 3, boxes.shape[0])
    P = cm.Paving(boxes[split == 0], boxes[split == 1], boxes[split == 2])
    n = boxes.shape[1]
    hull = hull_of_boxes(boxes)
    pts = np.concatenate([boxes[..., 0], boxes[..., 1],
                          rng.uniform(hull[:, 0] - 1, hull[:, 1] + 1, (200, n))])
    for view, sel in (("outer", split < 2), ("inner", split == 0),
                      ("boundary", split == 1), ("outside", split == 2)):
        expect = [any(np.all(b[:, 0] <= p) and np.all(p <= b[:, 1]) for b in boxes[sel])
                  for p in pts]
        np.testing.assert_array_equal(P.contains(pts, view=view), expect)
        q = np.stack([pts, pts + rng.uniform(0, 5, pts.shape)], axis=-1)
        expect = [any(np.all(b[:, 0] <= x[:, 1]) and np.all(x[:, 0] <= b[:, 1])
                      for b in boxes[sel]) for x in q]
        np.testing.assert_array_equal(P.intersects_box(q, view=view), expect)


def test_membership_uses_the_sweep_on_large_pavings():
    rng = np.random.default_rng(3)
    boxes = _regular_paving(np.array([[0.0, 1.0], [0.0, 1.0]]), 14, rng, p_stop=0.15)
    keep = rng.random(boxes.shape[0]) < 0.5
    U = boxes[keep]
    assert U.shape[0] * 600 > pv._PAIR_BUDGET
    P = cm.Paving(U)
    pts = np.concatenate([rng.random((500, 2)), U[:100, :, 0]])
    np.testing.assert_array_equal(P.contains(pts), boxes_contain_points(U, pts).any(axis=0))
    q = np.sort(rng.random((300, 2, 2)), axis=-1) * 0.3
    expect = [_covered_reference(x, U) for x in q[:40]]
    np.testing.assert_array_equal(P.contains_box(q[:40]), expect)
    ia, ib = pv._pairs(q, U)
    ja, jb = pv._filter_pairs(q, U, np.repeat(np.arange(300), U.shape[0]),
                              np.tile(np.arange(U.shape[0]), 300), False)
    assert set(zip(ia.tolist(), ib.tolist(), strict=True)) == set(
        zip(ja.tolist(), jb.tolist(), strict=True))


# ------------------------------------------------------------------- contains_box
def test_contains_box_needs_two_boxes_together():
    P = cm.Paving([cm.Box([0, 0], [1, 1]), cm.Box([1, 0], [2, 1])])
    q = np.array([[[0.5, 1.5], [0.2, 0.8]]])
    assert P.contains_box(q)[0]
    for b in P.boxes:  # neither box alone covers it
        assert not cm.Paving(b).contains_box(q)[0]
    gap = cm.Paving([cm.Box([0, 0], [1, 1]), cm.Box([1.01, 0], [2, 1])])
    assert not gap.contains_box(q)[0]
    # touching only at a corner / along a face that the query crosses
    corner = cm.Paving([cm.Box([0, 0], [1, 1]), cm.Box([1, 1], [2, 2])])
    assert not corner.contains_box(np.array([[[0.5, 1.5], [0.5, 1.5]]]))[0]
    # a degenerate query lying on the shared face
    assert P.contains_box(np.array([[[1.0, 1.0], [0.0, 1.0]]]))[0]
    L = cm.Paving([cm.Box([0, 0], [2, 1]), cm.Box([0, 1], [1, 2])])  # an L-shape
    assert L.contains_box(np.array([[[0, 1], [0, 2]], [[0, 2], [0, 1]]])).all()
    assert not L.contains_box(np.array([[[0, 2], [0, 2]]]))[0]
    np.testing.assert_array_equal(
        P.contains_box(np.array([[[0.5, 1.5], [0.2, 0.8]]]), view="inner"), [True])
    assert not P.contains_box(q, view="boundary")[0]


def test_contains_box_with_many_boxes_together():
    # a 4x4 grid of unit squares covers [0, 4]^2 only together; a hole makes a gap
    g = np.array([[[i, i + 1], [j, j + 1]] for i in range(4) for j in range(4)], dtype=float)
    P = cm.Paving(g)
    assert P.contains_box(np.array([[[0, 4], [0, 4]], [[0.5, 3.5], [0.5, 3.5]]])).all()
    H = cm.Paving(np.delete(g, 5, axis=0))
    np.testing.assert_array_equal(
        H.contains_box(np.array([[[0, 4], [0, 4]], [[0, 1], [0, 4]], [[1, 2], [1.5, 2]]])),
        [False, True, False])


@SETTINGS
@given(st.integers(1, 3).flatmap(lambda n: st.tuples(grid_boxes(n, 0, 6), grid_boxes(n, 1, 4))))
def test_contains_box_is_exact(data):
    U, Q = data
    P = cm.Paving(U) if len(U) else cm.Paving(np.zeros((0, Q.shape[1], 2)))
    if len(U) >= 2:  # hulls of several boxes: often covered only by boxes together
        Q = np.concatenate([Q, [hull_of_boxes(U[:2]), hull_of_boxes(U)]])
    got = P.contains_box(Q)
    for x, g in zip(Q, got, strict=True):
        assert g == _covered_reference(x, U)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2 ** 31))
def test_contains_box_on_random_regular_pavings(seed):
    rng = np.random.default_rng(seed)
    boxes = _regular_paving(np.array([[0.0, 1.0], [0.0, 1.0]]), 7, rng)
    U = boxes[rng.random(boxes.shape[0]) < 0.8]
    q = np.sort(rng.random((30, 2, 2)), axis=-1)
    q[:10] = np.sort(rng.random((10, 2, 2)) * 0.3 + rng.random((10, 2, 1)) * 0.7, axis=-1)
    got = cm.Paving(U).contains_box(q)
    np.testing.assert_array_equal(got, [_covered_reference(x, U) for x in q])


# ---------------------------------------------------- support, vertices, hull, union
@SETTINGS
@given(bounded_boxes(max_boxes=6), st.integers(0, 2 ** 31))
def test_support_vertices_and_bounding_box(boxes, seed):
    P = cm.Paving(boxes)
    n = boxes.shape[1]
    rng = np.random.default_rng(seed)
    D = rng.normal(size=(20, n))
    D[0] = 0.0
    corners = np.concatenate([cm.Box(b[:, 0], b[:, 1]).vertices() for b in boxes])
    np.testing.assert_allclose(P.support(D), (D @ corners.T).max(axis=1), rtol=1e-9, atol=1e-9)
    assert P.support(D[1]) == pytest.approx(float((corners @ D[1]).max()), rel=1e-9, abs=1e-9)
    V = P.vertices()
    assert V.shape[1] == n
    # V is made of corners and has the same support as all corners (same convex hull)
    assert boxes_contain_points(corners[:, :, None].repeat(2, axis=2), V).any(axis=0).all()
    np.testing.assert_allclose((D @ V.T).max(axis=1), (D @ corners.T).max(axis=1),
                               rtol=1e-9, atol=1e-6)
    B = P.bounding_box()
    np.testing.assert_array_equal(B.as_array(), hull_of_boxes(boxes))


def test_support_and_vertices_edge_cases():
    P = cm.Paving(np.zeros((0, 2, 2)))
    assert P.support([1.0, 0.0]) == -np.inf
    assert P.vertices().shape == (0, 2)
    with pytest.raises(cm.EmptySetError, match="empty"):
        P.bounding_box()
    U = cm.Paving(np.array([[[0.0, np.inf], [0.0, 1.0]]]))
    assert U.support([1.0, 0.0]) == np.inf
    assert U.support([-1.0, 0.0]) == 0.0
    assert U.support([0.0, 1.0]) == 1.0
    sq = cm.Paving([cm.Box([0, 0], [1, 1]), cm.Box([1, 0], [2, 1])])
    assert {tuple(v) for v in sq.vertices()} == {(0, 0), (2, 0), (0, 1), (2, 1)}
    with pytest.raises(cm.DimensionError, match="directions"):
        sq.support([1.0, 0.0, 0.0])


def test_union_keeps_views_and_intersects_outside_boxes():
    A = cm.Paving(inner=[cm.Box([0, 0], [1, 1])], boundary=[cm.Box([1, 0], [2, 1])],
                  outside=[cm.Box([2, 0], [4, 1])], domain=cm.Box([0, 0], [4, 1]))
    B = cm.Paving(inner=[cm.Box([3, 0], [4, 1])], outside=[cm.Box([0, 0], [3, 1])],
                  domain=cm.Box([0, 0], [4, 1]))
    U = A | B
    assert (U.n_inner, U.n_boundary) == (2, 1)
    np.testing.assert_array_equal(U.outside, [[[2, 3], [0, 1]]])  # outside both
    assert U.n_discarded == 1 and U.domain == cm.Box([0, 0], [4, 1])
    assert U.volume() == 2.0 and U.volume("outer") == 3.0
    assert (A | cm.Box([5, 5], [6, 6])).domain is None
    assert (A | cm.Box([5, 5], [6, 6])).n_inner == 2
    with pytest.raises(cm.DimensionError):
        A.union(cm.Paving(np.zeros((0, 3, 2))))
    with pytest.raises(TypeError):
        A.union(np.zeros((1, 2, 2)))


# ---------------------------------------------------------------------- save/load
def _assert_same(P, Q):
    assert type(Q) is cm.Paving and Q.dim == P.dim
    for k in ("inner", "boundary", "outside"):
        a, b = getattr(P, k), getattr(Q, k)
        assert a.shape == b.shape and a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    assert Q.domain == P.domain and Q.n_discarded == P.n_discarded


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_save_load_round_trip(tmp_path, suffix):
    rng = np.random.default_rng(5)
    D = np.array([[-1.0, 2.0], [0.1, 0.7]])
    boxes = _regular_paving(D, 8, rng) * (1 + 1e-16)  # awkward floats
    boxes = np.clip(boxes, D[:, 0][None, :, None], D[:, 1][None, :, None])
    lab = rng.integers(0, 3, boxes.shape[0])
    P = cm.Paving(boxes[lab == 0], boxes[lab == 1], boxes[lab == 2],
                  domain=cm.Box.from_array(D), n_discarded=int((lab == 2).sum()) + 11)
    Q = cm.Paving.load(P.save(tmp_path / f"p{suffix}"))
    _assert_same(P, Q)
    assert cm.load_set(tmp_path / f"p{suffix}").volume() == P.volume()
    # empty views, no domain, infinite bounds
    E = cm.Paving(inner=np.zeros((0, 3, 2)), boundary=np.array([[[0, np.inf]] * 3]))
    _assert_same(E, cm.Paving.load(E.save(tmp_path / f"e{suffix}")))
    with pytest.raises(TypeError, match="not a Box"):
        cm.Box.load(tmp_path / f"e{suffix}")


# ------------------------------------------------------------------------ plotting
def _paving_2d():
    inner = np.array([[[0, 1], [0, 1]], [[1, 2], [0, 1]], [[0, 1], [1, 2]]], dtype=float)
    boundary = np.array([[[1, 2], [1, 2]], [[2, 3], [0, 1]]], dtype=float)
    outer = np.array([[[2, 3], [1, 2]], [[3, 4], [0, 1]], [[3, 4], [1, 2]], [[0, 4], [2, 3]]],
                     dtype=float)
    return cm.Paving(inner, boundary, outer, domain=cm.Box([0, 0], [4, 3]))


def test_plot_draws_one_rectangle_per_box():
    P = _paving_2d()
    ax = P.plot()
    assert [len(c.get_paths()) for c in ax.collections] == [2, 3]
    assert [c.get_label() for c in ax.collections] == ["boundary", "inner"]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["boundary", "inner"]
    ax = P.plot(show_outer=True, legend=False, edgecolor="k")
    assert [len(c.get_paths()) for c in ax.collections] == [4, 2, 3]
    assert ax.get_legend() is None
    _, ax2 = plt.subplots()
    assert P.plot(ax=ax2, dims=(1, 0)) is ax2
    # the rectangles of the inner boxes sit where the boxes are (dims swapped)
    ext = np.array([p.get_extents().get_points() for p in ax2.collections[1].get_paths()])
    np.testing.assert_allclose(np.sort(ext[:, :, 0].ravel()), np.sort(P.inner[:, 1].ravel()))
    assert P.inner_set().plot().collections[0].get_label() == "inner"
    ax = P.plot(colors={"inner": "red"}, labels={"inner": "certified"})
    assert ax.collections[1].get_label() == "certified"
    np.testing.assert_allclose(ax.collections[1].get_facecolor()[0][:3], [1, 0, 0])
    with pytest.raises(cm.DimensionError, match="dims"):
        P.plot(dims=(0, 0))


def test_plot_projects_higher_dimensions_and_draws_1d_intervals():
    B3 = np.array([[[0, 1], [0, 1], [0, 1]], [[0, 1], [0, 1], [1, 2]],
                   [[1, 2], [0, 1], [0, 2]]], dtype=float)
    P = cm.Paving(B3, np.zeros((0, 3, 2)))
    ax = P.plot(dims=(0, 1))
    assert [len(c.get_paths()) for c in ax.collections] == [2]  # equal projections drawn once
    ax = P.plot(dims=(0, 2))
    assert [len(c.get_paths()) for c in ax.collections] == [3]
    P1 = cm.Paving(np.array([[[0, 1]], [[2, 3]]], dtype=float), np.array([[[1, 2]]], dtype=float))
    ax = P1.plot()
    assert [len(c.get_paths()) for c in ax.collections] == [1, 2]
    Pu = cm.Paving(np.array([[[0, np.inf], [0, 1]]]))  # unbounded boxes are clipped
    assert len(Pu.plot().collections) == 1
    assert len(cm.Paving(np.zeros((0, 2, 2))).plot().collections) == 0


def test_docstring_examples():
    result = doctest.testmod(pv, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0
