"""The covering engine ends: a proof that runs out of its budget answers "not proven"."""

import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.sets._poly_ops import subset_of_union
from casadi_cmpc.sets._poly_union import CoverBudget, _uncovered


def _grid_union(k: int, jitter: float = 0.0, seed: int = 0) -> cm.PolytopeUnion:
    """k x k overlapping boxes covering [0, 1]^2 (each widened by 1/(4k)), rotated a little
    so that the members cut each other's pieces (many pieces for the engine)."""
    rng = np.random.default_rng(seed)
    h = 1.0 / k
    members = []
    for i in range(k):
        for j in range(k):
            lo = np.array([i * h, j * h]) - h / 4
            hi = np.array([(i + 1) * h, (j + 1) * h]) + h / 4
            P = cm.Polytope.from_box(cm.Box(lo, hi))
            th = jitter * rng.uniform(-1, 1)
            R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
            c = 0.5 * (lo + hi)
            members.append(cm.Polytope(P.A @ R.T, P.b + (P.A @ R.T) @ c - P.A @ c))
    return cm.PolytopeUnion(members)


def test_covered_polytope_proved_with_default_budget_and_not_refuted_with_tiny_one():
    U = _grid_union(4, jitter=0.05)
    P = cm.Polytope.from_box(cm.Box([0.05, 0.05], [0.95, 0.95]))
    st: dict = {}
    assert subset_of_union(P, U, stats=st) == "proved"
    assert st["exhausted"] is False and st["lp_pieces"] > 10
    assert P.is_subset(U) is True
    # the same (true) inclusion with a budget far too small: stopped, and said so
    for budget in (CoverBudget(max_lps=5), CoverBudget(max_pieces=3), CoverBudget(max_seconds=0.0)):
        st = {}
        status = subset_of_union(P, U, budget=budget, stats=st)
        assert status == "budget exhausted", (budget, status)
        assert st["exhausted"] is True
    # sampled points of P are all in U: a "not a subset" claim would have been false
    X = cm.Box([0.05, 0.05], [0.95, 0.95]).sample(2000, seed=1)
    assert np.asarray(U.contains(X), dtype=bool).all()


def test_budget_never_turns_into_a_proof():
    """A polytope sticking out of the union is never "proved", whatever the budget."""
    U = _grid_union(3, jitter=0.05)
    P = cm.Polytope.from_box(cm.Box([0.1, 0.1], [1.3, 0.9]))  # x1 up to 1.3 > 1 + 1/12
    for budget in (None, CoverBudget(max_lps=5), CoverBudget(max_pieces=2),
                   CoverBudget(max_lps=10**6)):
        assert subset_of_union(P, U, budget=budget) in ("not proven", "budget exhausted")
    assert P.is_subset(U) is False


def test_engine_returns_a_point_for_every_open_region_when_stopped():
    U = _grid_union(4, jitter=0.05)
    boxes = np.array([[[0.05, 0.95], [0.05, 0.95]], [[0.2, 0.3], [0.2, 0.3]],
                      [[0.0, 1.5], [0.0, 1.0]]])
    centres = boxes.mean(axis=2)
    full = _uncovered(U._members(), boxes, centres)
    assert full[0] is None and full[1] is None and full[2] is not None
    st: dict = {}
    tiny = _uncovered(U._members(), boxes, centres, budget=CoverBudget(max_lps=4), stats=st)
    assert st["exhausted"] is True
    # nothing is proven by a stopped run that a full run would not prove
    for a, b in zip(full, tiny, strict=True):
        assert not (b is None and a is not None)
    assert tiny[0] is not None  # stopped before its proof: answered "not proven"


@pytest.mark.parametrize("method", ["separating", "scaling"])
def test_inner_polytope_under_budget_stays_inside(method):
    """inner_polytope with exhausted proofs still returns only proven polytopes."""
    U = _grid_union(3, jitter=0.08, seed=3)
    P, cert = cm.inner_polytope(list(U), method=method)
    assert "n_budget_exhausted" in cert.details
    if cert.proved:
        Y = P.bounding_box().sample(4000, seed=2)
        Y = Y[np.asarray(P.contains(Y), dtype=bool)]
        assert len(Y) > 100 and np.asarray(U.contains(Y), dtype=bool).all()


def test_rounding_level_tilt_that_doubled_the_pieces_now_ends_not_proven():
    """A square cut into 40 vertical strips, against the square with its left facet tilted
    by one rounding unit: every strip doubles the undecidable slivers along that facet
    (2^(k-1) pieces after k strips: without a budget the proof would never end). The
    answer must come, be "budget exhausted", and nothing may claim either way."""
    k = 40
    e = np.linspace(-1.0, 1.0, k + 1)
    U = cm.PolytopeUnion([cm.Polytope.from_box(cm.Box([e[i], -1.0], [e[i + 1], 1.0]))
                          for i in range(k)])
    P = cm.Polytope(np.array([[-1.0, 2.0**-53], [1.0, 0.0], [0.0, 1.0], [0.0, -1.0]]),
                    np.ones(4))
    st: dict = {}
    assert subset_of_union(P, U, stats=st) == "budget exhausted"
    assert st["exhausted"] is True and st["max_alive"] <= CoverBudget().max_pieces
    assert P.is_subset(U) is False  # "not proven"
    # the box inside (no tilt) is proven at once: the budget is not what decides
    Q = cm.Polytope.from_box(cm.Box([-0.999, -0.999], [0.999, 0.999]))
    assert subset_of_union(Q, U) == "proved"
