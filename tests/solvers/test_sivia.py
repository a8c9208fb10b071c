"""SIVIA (thesis Alg 4.1) on the Routh example E2 (Fig 4.1), set targets, limits, bad input."""

import itertools
from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.exceptions import DimensionError, UnboundedSetError
from casadi_cmpc.sets.paving import box_volume, boxes_contain_points
from casadi_cmpc.solvers.engine import (
    INNER,
    OUTER,
    UNDECIDED,
    BoxFrontier,
    Status,
    branch_and_bound,
)
from casadi_cmpc.solvers.sivia import (
    Thresholds,
    _box_difference,
    _image_rows,
    image_classifier,
)

X0_ROUTH = cm.Box([-3, -3], [9, 9])
Y_POS = cm.Box([0, 0, 0], [np.inf, np.inf, np.inf])
AREA_ROUTH = 144.0


def _routh_function():
    p = ca.SX.sym("p", 2)
    r = ca.vertcat(p[0] + p[1] + 2,
                   (p[0] - 1) ** 2 + (p[1] - 1) ** 2 - 1,
                   2 * (p[0] + 3) * (p[1] + 3) - 15)
    return ca.Function("routh", [p], [r])


def routh(P):
    """r(p) at points (..., 2) -> (..., 3), in floating point."""
    p1, p2 = P[..., 0], P[..., 1]
    return np.stack([p1 + p2 + 2, (p1 - 1) ** 2 + (p2 - 1) ** 2 - 1,
                     2 * (p1 + 3) * (p2 + 3) - 15], axis=-1)


def routh_exact(p1, p2):
    """r(p) with rational arithmetic (exact for float inputs)."""
    a, b = Fraction(p1), Fraction(p2)
    return (a + b + 2, (a - 1) ** 2 + (b - 1) ** 2 - 1, 2 * (a + 3) * (b + 3) - 15)


def samples(boxes, k=7):
    """A k x k grid in every box, corners included: (N, k*k, 2)."""
    t = np.linspace(0.0, 1.0, k)
    lo, hi = boxes[:, None, :, 0], boxes[:, None, :, 1]
    g = np.array(list(itertools.product(t, t)))[None]  # (1, k*k, 2)
    pts = lo + g * (hi - lo)
    # the corners exactly (lo + 1 * (hi - lo) may round away from hi)
    pts[:, 0] = boxes[:, :, 0]
    pts[:, -1] = boxes[:, :, 1]
    pts[:, k - 1] = np.stack([boxes[:, 0, 0], boxes[:, 1, 1]], axis=-1)
    pts[:, k * (k - 1)] = np.stack([boxes[:, 0, 1], boxes[:, 1, 0]], axis=-1)
    return pts


def corners(boxes):
    return [[(b[0, i], b[1, j]) for i in (0, 1) for j in (0, 1)] for b in boxes]


def assert_covers(paving, domain_volume):
    """inner, boundary and outside boxes tile the domain: volumes add up, no overlap."""
    parts = [paving.inner, paving.boundary, paving.outside]
    each = sum(float(box_volume(b).sum()) for b in parts if len(b))
    union = paving.volume("inner") + paving.volume("boundary") + paving.volume("outside")
    assert each == pytest.approx(domain_volume, rel=1e-12)
    assert union == pytest.approx(domain_volume, rel=1e-12)
    assert paving.n_discarded == len(paving.outside)


@pytest.fixture(scope="module")
def F_routh():
    return cm.interval.inclusion(_routh_function())


@pytest.fixture(scope="module")
def routh_pavings(F_routh):
    return {eps: cm.sivia(F_routh, X0_ROUTH, Y_POS, eps, open_target=True, progress=False)
            for eps in (0.5, 0.1, 0.05)}


# ----------------------------------------------------------------- E2, Fig 4.1
@pytest.mark.parametrize("eps", [0.5, 0.1, 0.05])
def test_routh_inner_boxes_are_stable(routh_pavings, eps):
    P = routh_pavings[eps]
    assert P.status == Status.PROVED and len(P.inner) > 0
    assert (routh(samples(P.inner)) > 0).all()
    if eps >= 0.1:  # exact rational check of every corner
        for cs in corners(P.inner):
            for c in cs:
                assert all(v > 0 for v in routh_exact(*c))


@pytest.mark.parametrize("eps", [0.5, 0.1, 0.05])
def test_routh_outside_boxes_are_unstable(routh_pavings, eps):
    P = routh_pavings[eps]
    assert len(P.outside) > 0
    r = routh(samples(P.outside))  # (N, k*k, 3)
    # one component of r is <= 0 on the whole box
    assert (r <= 0).all(axis=1).any(axis=1).all()
    if eps >= 0.1:
        for cs in corners(P.outside):
            vals = [routh_exact(*c) for c in cs]
            assert any(all(v[j] <= 0 for v in vals) for j in range(3))


@pytest.mark.parametrize("eps", [0.5, 0.1, 0.05])
def test_routh_paving_tiles_the_domain(routh_pavings, eps):
    P = routh_pavings[eps]
    assert_covers(P, AREA_ROUTH)
    assert P.domain == X0_ROUTH
    # boundary boxes are narrower than eps, the others came from bisection of X0
    assert (np.diff(P.boundary, axis=-1).max(axis=(1, 2)) <= eps).all()


def test_routh_refinement_shrinks_the_boundary(routh_pavings):
    inner = [routh_pavings[e].volume("inner") for e in (0.5, 0.1, 0.05)]
    bnd = [routh_pavings[e].volume("boundary") for e in (0.5, 0.1, 0.05)]
    assert inner[0] < inner[1] < inner[2]
    assert bnd[0] > bnd[1] > bnd[2]
    assert bnd[2] < 2.0


def test_routh_random_points_agree_with_the_labels(routh_pavings):
    rng = np.random.default_rng(0)
    pts = rng.uniform(-3, 9, size=(4000, 2))
    stable = (routh(pts) > 0).all(axis=1)
    for P in routh_pavings.values():
        in_inner = boxes_contain_points(P.inner, pts).any(axis=0)
        in_outer = boxes_contain_points(P.outside, pts).any(axis=0)
        in_bnd = boxes_contain_points(P.boundary, pts).any(axis=0)
        assert (in_inner | in_outer | in_bnd).all()
        assert stable[in_inner].all()
        assert not stable[in_outer].any()


def test_routh_fig41_box_counts(routh_pavings):
    # Fig 4.1 (eps = 0.5) with midpoint bisection and the natural inclusion; regression
    # figures of this deterministic run
    P = routh_pavings[0.5]
    assert (len(P.inner), len(P.boundary), len(P.outside)) == (55, 83, 46)
    assert P.volume("inner") == pytest.approx(105.890625)
    assert P.volume("boundary") == pytest.approx(11.671875)


def test_routh_from_casadi_function_equals_precompiled(F_routh, routh_pavings):
    P = cm.sivia(_routh_function(), X0_ROUTH, Y_POS, 0.5, open_target=True, progress=False)
    Q = routh_pavings[0.5]
    for a, b in ((P.inner, Q.inner), (P.boundary, Q.boundary), (P.outside, Q.outside)):
        np.testing.assert_array_equal(a, b)


def test_routh_centered_is_at_least_as_tight(routh_pavings):
    P = cm.sivia(_routh_function(), X0_ROUTH, Y_POS, 0.1, kind="centered",
                 open_target=True, progress=False)
    Q = routh_pavings[0.1]
    assert (routh(samples(P.inner)) > 0).all()
    assert P.volume("inner") >= Q.volume("inner")
    assert P.volume("boundary") <= Q.volume("boundary")
    assert_covers(P, AREA_ROUTH)


def test_split_ratio_049(F_routh, routh_pavings):
    P = cm.sivia(F_routh, X0_ROUTH, Y_POS, 0.1, open_target=True, split_ratio=0.49,
                 progress=False)
    assert P.status == Status.PROVED
    assert (routh(samples(P.inner)) > 0).all()
    assert (routh(samples(P.outside)) <= 0).all(axis=1).any(axis=1).all()
    assert_covers(P, AREA_ROUTH)
    Q = routh_pavings[0.1]
    assert len(P.inner) != len(Q.inner)  # a different (off-centre) subpaving
    assert P.volume("boundary") == pytest.approx(Q.volume("boundary"), rel=0.1)
    # the first cut is at 49 % of the first component
    assert np.isin(-3 + 0.49 * 12, np.concatenate([P.inner, P.boundary, P.outside])[:, 0, :])


def test_relative_eps_matches_a_rescaled_problem(routh_pavings):
    # p2 = q2 / 10: the same problem on [-3, 9] x [-30, 90]; eps relative to the widths
    q = ca.SX.sym("q", 2)
    p = ca.vertcat(q[0], q[1] / 10)
    r = ca.vertcat(p[0] + p[1] + 2, (p[0] - 1) ** 2 + (p[1] - 1) ** 2 - 1,
                   2 * (p[0] + 3) * (p[1] + 3) - 15)
    f = ca.Function("routh_scaled", [q], [r])
    X0 = cm.Box([-3, -30], [9, 90])
    P = cm.sivia(f, X0, Y_POS, 0.5 / 12, relative=True, open_target=True, progress=False)
    Q = routh_pavings[0.5]
    assert (len(P.inner), len(P.boundary), len(P.outside)) == (
        len(Q.inner), len(Q.boundary), len(Q.outside))
    assert P.volume("inner") == pytest.approx(10 * Q.volume("inner"))
    back = P.inner * np.array([1.0, 0.1])[None, :, None]
    assert (routh(samples(back)) > 0).all()
    assert_covers(P, 12 * 120)
    # without relative=True the same eps bisects the long side much further
    R = cm.sivia(f, X0, Y_POS, 0.5 / 12, open_target=True, progress=False)
    assert len(R.boundary) > len(P.boundary)


def test_closed_and_open_targets():
    x = ca.SX.sym("x")
    f = ca.Function("id", [x], [x])
    X0 = cm.Box([0.0], [2.0])
    closed = cm.sivia(f, X0, cm.Box([1.0], [np.inf]), 0.1, progress=False)
    opened = cm.sivia(f, X0, cm.Box([1.0], [np.inf]), 0.1, open_target=True, progress=False)
    # [1, 2] is inside the closed target, [0, 1) outside it; x = 1 decides nothing for the
    # box below 1 (closed) or above 1 (open)
    assert closed.volume("inner") == pytest.approx(1.0)
    assert closed.boundary[:, 0, 1].tolist() == [1.0]
    assert opened.volume("outside") == pytest.approx(1.0)
    assert opened.boundary[:, 0, 0].tolist() == [1.0]
    assert opened.outside[:, 0, 1].max() == 1.0 and closed.inner[:, 0, 0].min() == 1.0


# ---------------------------------------------------------------- set targets
HEXAGON = cm.Polytope.from_vertices([[1, 0], [0.5, 0.9], [-0.5, 0.9], [-1, 0], [-0.5, -0.9],
                                     [0.5, -0.9]])


def _in_polytope_exact(P, pts):
    A = [[Fraction(a) for a in row] for row in P.A]
    b = [Fraction(v) for v in P.b]
    out = []
    for x in pts:
        xs = [Fraction(v) for v in x]
        out.append(all(sum(a * v for a, v in zip(row, xs, strict=True)) <= bi
                       for row, bi in zip(A, b, strict=True)))
    return np.array(out)


def _shoelace(V):
    c = V.mean(axis=0)
    V = V[np.argsort(np.arctan2(V[:, 1] - c[1], V[:, 0] - c[0]))]
    x, y = V[:, 0], V[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def test_polytope_target_identity():
    x = ca.SX.sym("x", 2)
    f = ca.Function("id2", [x], [x])
    X0 = cm.Box([-1.5, -1.5], [1.5, 1.5])
    P = cm.sivia(f, X0, HEXAGON, 0.05, progress=False)
    assert P.status == Status.PROVED
    # inner boxes: their four vertices are in the (convex) hexagon, exactly
    V = np.array([c for cs in corners(P.inner) for c in cs])
    assert _in_polytope_exact(HEXAGON, V).all()
    # outside boxes: no sample lies in the hexagon
    S = samples(P.outside, k=5).reshape(-1, 2)
    assert not HEXAGON.contains(S).any()
    assert_covers(P, 9.0)
    area = _shoelace(HEXAGON.vertices())
    assert P.volume("inner") <= area <= P.volume("inner") + P.volume("boundary")
    assert P.volume("inner") > 0.85 * area


def test_polytope_target_nonlinear_image():
    # {x : (x1 + x2^2, x2) in hexagon}
    x = ca.SX.sym("x", 2)
    f = ca.Function("bend", [x], [ca.vertcat(x[0] + x[1] ** 2, x[1])])
    P = cm.sivia(f, cm.Box([-2, -1], [2, 1]), HEXAGON, 0.05, progress=False)
    img = samples(P.inner, k=5)
    img = np.stack([img[..., 0] + img[..., 1] ** 2, img[..., 1]], axis=-1).reshape(-1, 2)
    assert HEXAGON.contains(img, tol=1e-12).all()
    out = samples(P.outside, k=5)
    out = np.stack([out[..., 0] + out[..., 1] ** 2, out[..., 1]], axis=-1).reshape(-1, 2)
    assert not HEXAGON.contains(out).any()
    assert_covers(P, 8.0)


def test_polytope_union_target():
    A = cm.Polytope.from_box(cm.Box([-1, -1], [0.2, 1]))
    B = cm.Polytope.from_vertices([[0, -1], [1.2, 0], [0, 1]])
    U = cm.PolytopeUnion([A, B])
    x = ca.SX.sym("x", 2)
    f = ca.Function("id2", [x], [x])
    P = cm.sivia(f, cm.Box([-1.5, -1.5], [1.5, 1.5]), U, 0.05, progress=False)
    assert P.status == Status.PROVED and len(P.inner) > 0
    S = samples(P.inner, k=5).reshape(-1, 2)
    assert (A.contains(S, tol=1e-9) | B.contains(S, tol=1e-9)).all()
    # boxes straddling x1 = 0.2 are inside the union without being inside one member
    straddle = (P.inner[:, 0, 0] < 0.2) & (P.inner[:, 0, 1] > 0.2)
    assert straddle.any()
    S = samples(P.outside, k=5).reshape(-1, 2)
    assert not (A.contains(S) | B.contains(S)).any()
    assert_covers(P, 9.0)
    area = 1.2 * 2 + 0.5 * 2 * 1.2 - 0.5 * 2 * 0.2 * (1 - 0.2 / 1.2)  # |A| + |B| - |A ∩ B|
    assert P.volume("inner") <= area <= P.volume("inner") + P.volume("boundary")


def test_structural_zero_and_constant_outputs():
    x = ca.SX.sym("x", 2)
    f = ca.Function("zc", [x], [ca.vertcat(x[0], ca.SX(1, 1), 2.0)])
    X0 = cm.Box([-1, -1], [1, 1])
    P = cm.sivia(f, X0, cm.Box([0, -1, 1], [2, 1, 3]), 0.1, progress=False)
    assert P.volume("inner") == pytest.approx(2.0)  # x0 in [0, 1]
    assert P.volume("outside") + P.volume("boundary") == pytest.approx(2.0)
    assert (P.boundary[:, 0, 1] == 0.0).all()
    Q = cm.sivia(f, X0, cm.Box([0, 0.5, 1], [2, 1, 3]), 0.1, progress=False)  # 0 not in Y
    assert Q.volume("outside") == pytest.approx(4.0) and Q.levels == 1


def test_undefined_function_parts_stay_undecided():
    x = ca.SX.sym("x")
    f = ca.Function("root", [x], [ca.sqrt(x) - 1])
    P = cm.sivia(f, cm.Box([-1.0], [4.0]), cm.Box([0.0], [np.inf]), 0.01, progress=False)
    assert (P.inner[:, 0, 0] >= 1.0).all()
    assert (P.outside[:, 0, 0] >= 0.0).all() and (P.outside[:, 0, 1] <= 1.0).all()
    assert P.volume("boundary") > 1.0  # [-1, 0] is never decided
    assert_covers(P, 5.0)


def test_fast_image_path_matches_evaluate(F_routh):
    rng = np.random.default_rng(3)
    lo = rng.uniform(-3, 9, (500, 2))
    hi = lo + rng.uniform(0, 2, (500, 2))
    rows = _image_rows(F_routh, lo, hi)
    img = F_routh.evaluate_unchecked([np.stack([lo, hi], axis=-1)], 500)[0]
    for j, (l, h) in enumerate(rows):
        np.testing.assert_array_equal(l, img[:, j, 0])
        np.testing.assert_array_equal(h, img[:, j, 1])
    # the frontier itself is left untouched
    assert (hi >= lo).all() and lo.min() >= -3


# -------------------------------------------------------- limits, interruption
def test_max_boxes_stops_with_sound_leftovers(F_routh):
    P = cm.sivia(F_routh, X0_ROUTH, Y_POS, 0.05, open_target=True, max_boxes=200,
                 progress=False)
    assert P.status == Status.BUDGET and "max_boxes" in P.message
    assert P.n_classified <= 200
    assert (routh(samples(P.inner)) > 0).all()
    assert (routh(samples(P.outside)) <= 0).all(axis=1).any(axis=1).all()
    assert_covers(P, AREA_ROUTH)
    # leftovers are reported as boundary although wider than eps
    assert np.diff(P.boundary, axis=-1).max() > 0.05


def test_time_limit_stops_with_sound_leftovers(F_routh):
    P = cm.sivia(F_routh, X0_ROUTH, Y_POS, 0.005, open_target=True, time_limit=0.0,
                 progress=False)
    assert P.status == Status.BUDGET and "time_limit" in P.message
    assert len(P.inner) == 0
    assert_covers(P, AREA_ROUTH)
    np.testing.assert_array_equal(P.boundary, X0_ROUTH.as_array()[None])


def test_keyboard_interrupt_in_classifier_returns_partial_result(F_routh):
    inner = image_classifier(F_routh, Y_POS, open_target=True)
    calls = []

    def classify(fr):
        calls.append(len(fr))
        if len(calls) == 4:  # level 3
            raise KeyboardInterrupt
        return inner(fr)

    fr = BoxFrontier.from_boxes(X0_ROUTH.as_array()[None])
    out = branch_and_bound(fr, classify, 0.05, progress=False)
    assert out.status == Status.BUDGET and out.message == "interrupted"
    assert out.levels == 3 and len(out.history) == 3
    assert len(out.boundary) == calls[3]  # the unclassified frontier of level 3
    P = cm.Paving(inner=out.inner.boxes, boundary=out.boundary.boxes,
                  outside=out.outer.boxes, domain=X0_ROUTH, n_discarded=out.n_discarded)
    assert_covers(P, AREA_ROUTH)
    assert (routh(samples(P.inner)) > 0).all()


def test_keyboard_interrupt_after_contraction_keeps_a_tiling(F_routh, monkeypatch):
    import importlib

    sivia_mod = importlib.import_module("casadi_cmpc.solvers.sivia")
    calls = []
    real = sivia_mod._ComponentClassifier.__call__

    def interrupted(self, fr):
        calls.append(len(fr))
        if len(calls) == 5:  # after the contraction of level 4
            raise KeyboardInterrupt
        return real(self, fr)

    monkeypatch.setattr(sivia_mod._ComponentClassifier, "__call__", interrupted)
    P = cm.sivia(F_routh, X0_ROUTH, Y_POS, 0.05, open_target=True, contract=True,
                 progress=False)
    assert P.status == Status.BUDGET and P.message == "interrupted"
    assert len(P.outside) == P.n_discarded > 0  # slabs removed by the contractor included
    assert_covers(P, AREA_ROUTH)
    assert (routh(samples(P.inner)) > 0).all()


def test_keyboard_interrupt_while_splitting_keeps_a_tiling(F_routh):
    class Fragile(BoxFrontier):
        splits = 0

        def take(self, mask):
            b = super().take(mask)
            return Fragile(b.lo, b.hi, b.scale, b.split_ratio)

        def split(self):
            Fragile.splits += 1
            if Fragile.splits == 3:
                raise KeyboardInterrupt
            c, s = super().split()
            return Fragile(c.lo, c.hi, c.scale, c.split_ratio), s

    fr = Fragile(np.array([[-3.0, -3.0]]), np.array([[9.0, 9.0]]))
    out = branch_and_bound(fr, image_classifier(F_routh, Y_POS, True), 0.05, progress=False)
    assert out.status == Status.BUDGET and out.levels == 2
    P = cm.Paving(inner=out.inner.boxes, boundary=out.boundary.boxes,
                  outside=out.outer.boxes, n_discarded=out.n_discarded)
    assert_covers(P, AREA_ROUTH)  # no box of the interrupted level counted twice


def test_engine_labels_and_history():
    fr = BoxFrontier.from_boxes(np.array([[[0.0, 1.0]]]))

    def classify(f):
        lab = np.full(len(f), UNDECIDED)
        lab[f.lo[:, 0] >= 0.5] = INNER
        lab[f.hi[:, 0] <= 0.25] = OUTER
        return lab

    out = branch_and_bound(fr, classify, 0.1, progress=False)
    assert out.status == Status.PROVED
    assert [h["classified"] for h in out.history] == [1, 2, 2, 2, 4]
    assert out.inner.boxes.tolist() == [[[0.5, 1.0]]]
    assert out.outer.boxes.tolist() == [[[0.0, 0.25]]]
    # [0.25, 0.5] is never decided: bisected down to widths <= eps
    assert sorted(out.boundary.boxes[:, 0].tolist()) == [[0.25, 0.3125], [0.3125, 0.375],
                                                 [0.375, 0.4375], [0.4375, 0.5]]
    assert out.n_discarded == 1
    none_kept = branch_and_bound(fr, classify, 0.1, keep_outer=False, progress=False)
    assert len(none_kept.outer) == 0 and none_kept.n_discarded == 1


def test_boxes_too_narrow_to_split_become_boundary():
    # eps below the float resolution: the boxes at the threshold cannot be split further
    x = ca.SX.sym("x")
    f = ca.Function("id", [x], [x])
    a = 1.0
    b = a
    for _ in range(8):
        b = np.nextafter(b, 2.0)
    c = (a + b) / 2 + 1e-17
    P = cm.sivia(f, cm.Box([a], [b]), cm.Box([c], [np.inf]), 1e-300, open_target=True,
                 max_boxes=10_000, progress=False)
    assert P.status == Status.PROVED and P.n_classified < 100
    assert len(P.boundary) >= 1 and (P.boundary[:, 0, 0] <= c).all()
    assert_covers(P, b - a)


def test_frontier_split_and_bisect():
    fr = BoxFrontier(np.array([[0.0, 0.0], [0.0, 0.0]]), np.array([[1.0, 2.0], [2.0, 2.0]]))
    assert fr.width().tolist() == [2.0, 2.0]
    ch, stuck = fr.split()
    assert len(stuck) == 0
    # widest component, ties to the lowest index
    assert ch.boxes.tolist() == [[[0, 1], [0, 1]], [[0, 1], [0, 2]],
                                 [[0, 1], [1, 2]], [[1, 2], [0, 2]]]
    point = BoxFrontier(np.array([[1.0]]), np.array([[1.0]]))
    ch, stuck = point.split()
    assert len(ch) == 0 and len(stuck) == 1
    assert point.bisect().boxes.tolist() == [[[1.0, 1.0]]]
    huge = BoxFrontier(np.array([[-1e308]]), np.array([[1.7e308]]), split_ratio=0.49)
    ch, stuck = huge.split()
    assert len(stuck) == 0 and np.isfinite(ch.lo).all() and np.isfinite(ch.hi).all()
    sel = fr.take(np.array([False, True]))
    assert sel.boxes.tolist() == fr.take(np.array([1])).boxes.tolist()


def test_frontier_data_follows_the_boxes():
    lo = np.array([[0.0, 0.0], [0.0, 0.0], [5.0, 5.0]])
    hi = np.array([[1.0, 2.0], [2.0, 2.0], [5.0, 5.0]])  # the last box cannot be split
    tag = np.array([10, 11, 12])
    fr = BoxFrontier(lo, hi, data={"tag": tag})
    assert fr.take(np.array([False, True, True])).data["tag"].tolist() == [11, 12]
    ch, stuck = fr.split()
    # left halves first, then right halves; each half keeps its parent's row
    assert ch.data["tag"].tolist() == [10, 11, 10, 11]
    assert ch.boxes.tolist() == [[[0, 1], [0, 1]], [[0, 1], [0, 2]],
                                 [[0, 1], [1, 2]], [[1, 2], [0, 2]]]
    assert stuck.data["tag"].tolist() == [12]
    both = BoxFrontier.concat([ch, stuck])
    assert both.data["tag"].tolist() == [10, 11, 10, 11, 12]
    # parts without the same data keys lose it rather than misalign rows
    assert BoxFrontier.concat([ch, BoxFrontier(lo, hi)]).data is None


def test_component_classifier_records_the_proven_constraints(F_routh):
    rng = np.random.default_rng(5)
    lo = rng.uniform(-3, 9, (400, 2))
    hi = lo + rng.uniform(0, 1.5, (400, 2))
    fr = BoxFrontier(lo.copy(), hi.copy())
    classify = image_classifier(F_routh, Y_POS, open_target=True)
    labels = classify(fr)
    rows = _image_rows(F_routh, lo, hi)
    proven = np.stack([r[0] > 0 for r in rows], axis=1)  # (N, 3)
    refuted = np.stack([r[1] <= 0 for r in rows], axis=1)
    mask = fr.data["open"]
    for c in range(3):
        assert ((mask >> c) & 1 == 0).tolist() == proven[:, c].tolist()
    assert (labels == INNER).tolist() == proven.all(axis=1).tolist()
    assert (labels == OUTER).tolist() == refuted.any(axis=1).tolist()
    # the children of an undecided box are not re-tested on what holds on their parent
    und = fr.take(labels == UNDECIDED)
    und.width()
    children, _ = und.split()
    half = len(children) // 2
    assert (children.data["open"][:half] == und.data["open"]).all()
    assert (children.data["open"][half:] == und.data["open"]).all()
    inherited = classify(children)
    child_rows = _image_rows(F_routh, children.lo, children.hi)
    child_refuted = np.stack([r[1] <= 0 for r in child_rows], axis=1)
    child_inner = np.stack([r[0] > 0 for r in child_rows], axis=1).all(axis=1)
    # a proof kept from the parent can only decide more boxes
    assert ((inherited == INNER) >= child_inner).all()
    assert (inherited == OUTER).tolist() == child_refuted.any(axis=1).tolist()


def test_component_and_joint_evaluation_give_the_same_paving(F_routh, routh_pavings):
    joint = cm.interval.inclusion(_routh_function())
    joint.component_evaluator = lambda j: None  # forces one evaluation of all outputs
    P = cm.sivia(joint, X0_ROUTH, Y_POS, 0.1, open_target=True, progress=False)
    Q = routh_pavings[0.1]
    for view in ("inner", "boundary", "outside"):
        a, b = getattr(P, view), getattr(Q, view)
        assert sorted(map(tuple, a.reshape(len(a), -1).tolist())) == \
            sorted(map(tuple, b.reshape(len(b), -1).tolist()))


def test_native_joint_levels_are_sound_and_give_the_routh_paving(monkeypatch):
    """Large levels of a function that has moved to its native kernel are evaluated in one
    call (every element at once, against its own bounds): the labels hold exactly at sampled
    points (rational arithmetic), and the Routh paving is that of the component path."""
    from casadi_cmpc.interval._native import native_available

    if not native_available():
        pytest.skip("no C compiler")
    mod = __import__("casadi_cmpc.solvers.sivia", fromlist=["_ComponentClassifier"])
    calls = []
    orig = mod._ComponentClassifier._joint_image

    def counted(self, fr):
        img = orig(self, fr)
        calls.append(img is not None)
        return img

    F = cm.interval.inclusion(_routh_function())
    F.native_after = 0  # on the native kernel from the first large level
    monkeypatch.setattr(mod._ComponentClassifier, "JOINT_MIN", 16)
    monkeypatch.setattr(mod._ComponentClassifier, "_joint_image", counted)
    P = cm.sivia(F, X0_ROUTH, Y_POS, 0.05, open_target=True, progress=False)
    assert any(calls)
    for b in P.inner[::37]:
        for c in corners(b[None])[0]:
            assert all(v > 0 for v in routh_exact(*c))
    for b in P.outside[::37]:
        for c in corners(b[None])[0]:
            assert any(v <= 0 for v in routh_exact(*c))
    monkeypatch.setattr(mod._ComponentClassifier, "JOINT_MIN", 10 ** 9)
    Q = cm.sivia(cm.interval.inclusion(_routh_function()), X0_ROUTH, Y_POS, 0.05,
                 open_target=True, progress=False)
    for view in ("inner", "boundary", "outside"):
        a, b = getattr(P, view), getattr(Q, view)
        assert sorted(map(tuple, a.reshape(len(a), -1).tolist())) == \
            sorted(map(tuple, b.reshape(len(b), -1).tolist()))


def test_two_sided_targets_per_component():
    x = ca.SX.sym("x", 2)
    f = ca.Function("ring", [x], [ca.vertcat(x[0] ** 2 + x[1] ** 2, x[0] - x[1])])
    Y = cm.Box([1.0, -0.5], [4.0, 0.5])  # 1 <= |x|^2 <= 4 and |x0 - x1| <= 1/2
    P = cm.sivia(f, cm.Box([-3, -3], [3, 3]), Y, 0.05, progress=False)
    pts = samples(P.inner, 5).reshape(-1, 2)
    r2 = (pts ** 2).sum(axis=1)
    assert ((r2 >= 1) & (r2 <= 4) & (np.abs(pts[:, 0] - pts[:, 1]) <= 0.5)).all()
    out = samples(P.outside, 5).reshape(-1, 2)
    r2 = (out ** 2).sum(axis=1)
    assert ((r2 < 1) | (r2 > 4) | (np.abs(out[:, 0] - out[:, 1]) > 0.5)).all()
    assert P.volume("inner") > 0.75 * 1.41  # two pieces of a band: area about 1.41


def test_box_difference_tiles_the_removed_part():
    rng = np.random.default_rng(11)
    lo = rng.uniform(-1, 0, (50, 3))
    hi = rng.uniform(1, 2, (50, 3))
    t = rng.uniform(0, 1, (2, 50, 3))
    keep = rng.uniform(size=(50, 3)) < 0.3  # some sides untouched
    lo2 = np.where(keep, lo, lo + t[0] * (hi - lo) * 0.5)
    hi2 = np.where(keep[:, ::-1], hi, hi - t[1] * (hi - lo) * 0.5)
    slabs = _box_difference(lo, hi, lo2, hi2)
    vol = np.prod(hi - lo, axis=1).sum() - np.prod(hi2 - lo2, axis=1).sum()
    assert float(box_volume(slabs).sum()) == pytest.approx(vol, rel=1e-12)
    pts = lo[:, None] + rng.uniform(size=(50, 200, 3)) * (hi - lo)[:, None]
    for i in range(50):
        inside_kept = ((pts[i] > lo2[i]) & (pts[i] < hi2[i])).all(axis=1)
        in_slabs = boxes_contain_points(slabs, pts[i]).any(axis=0)
        # every point is in the contracted box or in a slab (up to the shared faces)
        assert (inside_kept | in_slabs).all()
    assert _box_difference(lo, hi, lo, hi).shape == (0, 3, 2)


def test_contraction_keeps_the_routh_paving_sound(F_routh):
    P = cm.sivia(F_routh, X0_ROUTH, Y_POS, 0.1, open_target=True, contract=True,
                 progress=False)
    assert P.status == Status.PROVED
    assert (routh(samples(P.inner)) > 0).all()
    # the removed slabs hold no solution: some component is <= 0 at every point
    assert (routh(samples(P.outside)) <= 0).any(axis=2).all()
    assert_covers(P, AREA_ROUTH)
    plain = cm.sivia(F_routh, X0_ROUTH, Y_POS, 0.1, open_target=True, progress=False)
    assert P.volume("boundary") < plain.volume("boundary")


def test_contraction_on_a_thin_constraint():
    x = ca.SX.sym("x", 2)
    f = ca.Function("line", [x], [x[0] + 2 * x[1]])
    X0, Y = cm.Box([0, 0], [1, 1]), cm.Box([1.0], [1.0])  # the segment x0 + 2 x1 = 1
    plain = cm.sivia(f, X0, Y, 0.01, progress=False)
    P = cm.sivia(f, X0, Y, 0.01, contract=True, progress=False)
    assert P.volume("inner") == plain.volume("inner") == 0.0
    assert P.volume("boundary") < 0.5 * plain.volume("boundary")
    t = np.linspace(0, 1, 101)
    on_line = np.stack([t, (1 - t) / 2], axis=1)
    assert P.contains(on_line).all()  # the solution set stays inside inner + boundary
    assert_covers(P, 1.0)


finite = st.floats(min_value=-1e300, max_value=1e300, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(y=finite, c=finite, pos=st.floats(min_value=1e-300, max_value=1e300),
       g=st.lists(finite, min_size=1, max_size=8), ulps=st.integers(-3, 3))
def test_moved_thresholds_prove_only_true_facts(y, c, pos, g, ulps):
    """g > in_lo must imply g + c > y (resp. g * pos > y) exactly, and so on."""
    for kind, k in (("add", c), ("mul", pos)):
        t = Thresholds.through(y, y, [(kind, k)])
        # values at and around the thresholds, where rounding matters
        near = [v for v in (t.in_lo, t.out_lo, t.in_hi, t.out_hi) if v is not None]
        cand = list(g) + [float(np.nextafter(v, np.inf if ulps > 0 else -np.inf) * 1.0)
                          for v in near if np.isfinite(v)] + near
        for v in cand:
            if not np.isfinite(v):
                continue
            exact = Fraction(v) + Fraction(k) if kind == "add" else Fraction(v) * Fraction(k)
            if t.in_lo is not None and v > t.in_lo:
                assert exact > Fraction(y)
            if t.out_lo is not None and v <= t.out_lo:
                assert exact <= Fraction(y)
            if t.in_hi is not None and v < t.in_hi:
                assert exact < Fraction(y)
            if t.out_hi is not None and v >= t.out_hi:
                assert exact >= Fraction(y)


def test_thresholds_of_one_sided_and_nested_bounds():
    t = Thresholds.through(0.0, np.inf, [("add", -1.0), ("mul", 2.0)])  # 2 g - 1 >= 0
    assert t.in_hi is None and t.out_hi is None
    assert 0.5 <= t.in_lo <= 0.5 + 1e-15 and 0.5 - 1e-15 <= t.out_lo <= 0.5
    assert Thresholds.through(-np.inf, np.inf, [("add", 1.0)]) == Thresholds(None, None,
                                                                             None, None)


# ------------------------------------------------------------------ bad input
def test_bad_inputs(F_routh):
    f = _routh_function()
    with pytest.raises(UnboundedSetError):
        cm.sivia(f, cm.Box([-3, -3], [9, np.inf]), Y_POS, 0.5)
    for eps in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="eps"):
            cm.sivia(f, X0_ROUTH, Y_POS, eps)
    x, y = ca.SX.sym("x", 2), ca.SX.sym("y")
    with pytest.raises(DimensionError, match="one input"):
        cm.sivia(ca.Function("two", [x, y], [x[0] + y]), X0_ROUTH, cm.Box([0], [1]), 0.5)
    with pytest.raises(DimensionError, match="one input"):
        cm.sivia(ca.Function("two_out", [x], [x[0], x[1]]), X0_ROUTH, cm.Box([0], [1]), 0.5)
    with pytest.raises(DimensionError, match="one input"):
        cm.sivia(cm.interval.inclusion(ca.Function("two", [x, y], [x[0] + y])), X0_ROUTH,
                 cm.Box([0], [1]), 0.5)
    with pytest.raises(DimensionError, match="target Y has dimension 2"):
        cm.sivia(F_routh, X0_ROUTH, cm.Box([0, 0], [1, 1]), 0.5)
    with pytest.raises(DimensionError, match="target Y has dimension 2"):
        cm.sivia(F_routh, X0_ROUTH, HEXAGON, 0.5)
    with pytest.raises(DimensionError, match="X0"):
        cm.sivia(F_routh, cm.Box([-3, -3, -3], [9, 9, 9]), Y_POS, 0.5)
    with pytest.raises(TypeError, match="Y must be"):
        cm.sivia(F_routh, X0_ROUTH, [[0, 1]] * 3, 0.5)
    with pytest.raises(TypeError, match="f must be"):
        cm.sivia(lambda p: p, X0_ROUTH, Y_POS, 0.5)
    for r in (0.0, 1.0, 1.5, np.nan):
        with pytest.raises(ValueError, match="split_ratio"):
            cm.sivia(F_routh, X0_ROUTH, Y_POS, 0.5, split_ratio=r)


def test_plot_draws_three_categories(routh_pavings):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ax = routh_pavings[0.5].plot(show_outer=True)
    assert len(ax.collections) == 3
    plt.close(ax.figure)


_EDGE = [0.0, -0.0, 1.0, -1.0, 2.5, -2.5, np.inf, -np.inf, np.nan, 5e-324, 1e308]


@settings(max_examples=150, deadline=None)
@given(k=st.integers(1, 6), N=st.integers(1, 40), open_target=st.booleans(),
       seed=st.integers(0, 2 ** 32 - 1))
def test_joint_decision_c_numpy_and_per_element_agree(k, N, open_target, seed):
    """The decision of a level's joint image (every element against its bounds, the open
    mask, the label) is the same by the C loop, by numpy and element by element, for
    one- and two-sided and free elements, NaN and infinite enclosures and both kinds of
    target."""
    import importlib

    mod = importlib.import_module("casadi_cmpc.solvers.sivia")

    rng = np.random.default_rng(seed)
    pick = lambda: float(rng.choice(_EDGE)) if rng.random() < 0.3 else float(  # noqa: E731
        rng.integers(-3, 4))
    ts = []
    for _ in range(k):
        lo = pick() if rng.random() < 0.6 else -np.inf
        hi = pick() if rng.random() < 0.6 else np.inf
        if np.isnan(lo) or np.isnan(hi):
            lo, hi = -np.inf, np.inf
        lo, hi = min(lo, hi), max(lo, hi)
        ts.append(Thresholds.through(lo, hi, []))
    cls = mod._ComponentClassifier([(None, t) for t in ts], open_target, 8192,
                                   (None, ts))
    img = np.array([[sorted([pick(), pick()]) for _ in range(k)] for _ in range(N)])
    nan = rng.random((N, k, 2)) < 0.1
    img[nan] = np.nan
    mask = rng.integers(0, 2 ** k, N).astype(np.uint64)
    # element by element
    ref_mask = mask.copy()
    ref_out = np.zeros(N, dtype=bool)
    for c in range(k):
        ins, out = cls._decide(img[:, c, 0], img[:, c, 1], ts[c], N)
        ref_mask[np.asarray(ins)] &= ~np.uint64(1 << c)
        ref_out |= np.asarray(out)
    ref_labels = np.where(ref_out, OUTER, np.where(ref_mask == 0, INNER, 0)).astype(np.int8)
    # numpy, all elements at once
    with np.errstate(all="ignore"):
        ins, out = cls._decide_all(img)
    np_mask = mask & ~(ins.view(np.uint8) * cls.bit_values).sum(axis=1, dtype=np.uint64)
    assert (np_mask == ref_mask).all()
    assert (out.any(axis=1) == ref_out).all()
    # the C loop
    fn = mod._decide_kernel(wait=True)
    if fn is None:
        return  # no compiler (or still compiling): numpy decides
    c_mask = mask.copy()
    labels = np.empty(N, dtype=np.int8)
    img = np.ascontiguousarray(img)
    a = mod.address
    fn(N, k, a(img), a(cls.t_all), a(cls.flags), int(open_target), a(c_mask), a(labels))
    assert (c_mask == ref_mask).all()
    assert (labels == ref_labels).all()


def test_a_search_of_small_levels_does_not_compile_a_kernel():
    """Levels under JOINT_COUNT_MIN boxes do not count toward the move to the native
    kernel: a small SIVIA repeated many times stays on the numpy element evaluators (no
    compilation for it), and its paving is the same every time."""
    from casadi_cmpc.solvers.sivia import _ComponentClassifier

    x = ca.SX.sym("x", 2)
    F = cm.interval.inclusion(ca.Function("disk_band", [x], [ca.vertcat(
        x[0] ** 2 + x[1] ** 2, x[0] - x[1])]))
    Y = cm.Box([0.0, -1.0], [1.0, 1.0])
    first = cm.sivia(F, cm.Box([-2, -2], [2, 2]), Y, 0.5, progress=False)
    assert max(h["classified"] for h in first.history) < _ComponentClassifier.JOINT_COUNT_MIN
    for _ in range(40):
        P = cm.sivia(F, cm.Box([-2, -2], [2, 2]), Y, 0.5, progress=False)
        assert np.array_equal(P.inner, first.inner)
    assert F._native is None and F._native_batches == 0
