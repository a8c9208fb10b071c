"""The pair frontier of nested existential searches: group reduction and splitting."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from casadi_cmpc.solvers.engine import (
    DROPPED,
    INNER,
    OUTER,
    UNDECIDED,
    PairFrontier,
    branch_and_bound,
)


def _frontier(groups, n=1, m=1):
    N = len(groups)
    lo = np.zeros((N, n + m))
    hi = np.ones((N, n + m))
    return PairFrontier(lo, hi, np.asarray(groups, dtype=np.intp), n, np.ones(n), np.ones(m),
                        u_eps=0.1, max_cells=8,
                        data={"witness": np.arange(N, dtype=float).reshape(N, 1)})


def test_reduce_group_inner_if_any_pair_inner_outside_only_if_all():
    fr = _frontier([0, 0, 1, 1, 2, 2])
    labels = np.array([OUTER, INNER, OUTER, OUTER, OUTER, UNDECIDED], dtype=np.int8)
    out, small = fr.reduce(labels, eps=0.01)
    assert out[1] == INNER and out[0] == DROPPED  # one representative, with its data
    assert (out[2:4] == [OUTER, DROPPED]).all() or (out[2:4] == [DROPPED, OUTER]).all()
    assert out[4] == DROPPED and out[5] == UNDECIDED  # a useless cell, a live group
    assert not small.any()
    kept = fr.take_done(np.flatnonzero(out == INNER))
    assert kept.data["witness"][0, 0] == 1.0


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 10 ** 6), k=st.integers(1, 12))
def test_reduce_of_a_subset_of_groups_labels_as_the_whole(seed, k):
    """A frontier holding only some groups (ids with gaps, as a part of a search holds):
    every pair gets the label it gets in the frontier of all groups."""
    rng = np.random.default_rng(seed)
    groups = np.repeat(np.arange(k), rng.integers(1, 4, k))
    labels = rng.choice([INNER, OUTER, UNDECIDED], size=groups.size).astype(np.int8)
    full, _ = _frontier(groups).reduce(labels, eps=0.01)
    keep = np.isin(groups, rng.choice(k, size=max(1, k // 2), replace=False))
    part = _frontier(groups[keep])
    got, _ = part.reduce(labels[keep], eps=0.01)
    assert (got == full[keep]).all()


def test_exhausted_group_becomes_one_boundary_pair():
    fr = _frontier([0, 0, 0])
    fr.lo[:, 1] = [0.0, 0.05, 0.5]
    fr.hi[:, 1] = [0.05, 0.1, 0.55]  # cells narrower than u_eps
    fr.hi[:, 0] = 0.005  # state box narrower than eps
    out, small = fr.reduce(np.zeros(3, dtype=np.int8), eps=0.01)
    assert small.sum() == 1 and (out == UNDECIDED).sum() == 1
    assert out[small][0] == UNDECIDED


def test_split_bisects_cells_first_then_the_state_box_with_the_hull_of_the_cells():
    fr = PairFrontier.from_boxes(np.array([[[0.0, 1.0], [0.0, 2.0]]]),
                                 np.array([[-1.0, 1.0]]), u_eps=0.3, max_cells=16,
                                 data={"witness": np.zeros((1, 1))})
    seen_x_split = False
    for _ in range(6):
        out, small = fr.reduce(np.zeros(len(fr), dtype=np.int8), eps=0.01)
        fr = fr.take(np.flatnonzero(out == UNDECIDED))
        nxt, stuck = fr.split()
        assert len(stuck) == 0
        groups = np.unique(nxt.group)
        for g in groups:  # the cells of every group cover U (no cell was discarded)
            C = nxt.u_cells[nxt.group == g][:, 0, :]
            C = C[np.argsort(C[:, 0])]
            assert C[0, 0] == -1.0 and C[-1, 1] == 1.0
            assert (C[1:, 0] <= C[:-1, 1]).all()
            X = nxt.x_boxes[nxt.group == g]
            assert (X == X[0]).all()  # one state box per group
        if len(groups) > 1:
            seen_x_split = True
        fr = nxt
    assert seen_x_split


def test_discarded_cells_shrink_the_inherited_cell():
    fr = PairFrontier.from_boxes(np.array([[[0.0, 1.0]]]), np.array([[0.0, 1.0]]),
                                 u_eps=0.3, max_cells=16, data={"witness": np.zeros((1, 1))})
    out, _ = fr.reduce(np.zeros(1, dtype=np.int8), eps=0.01)
    fr = fr.take(out == UNDECIDED).split()[0]  # cells [0, .5], [.5, 1]
    out, _ = fr.reduce(np.zeros(2, dtype=np.int8), eps=0.01)
    fr = fr.take(out == UNDECIDED).split()[0]  # four cells of width .25
    lab = np.where(fr.u_cells[:, 0, 0] < 0.5, OUTER, UNDECIDED).astype(np.int8)
    out, _ = fr.reduce(lab, eps=0.01)
    ch = fr.take(out == UNDECIDED).split()[0]  # cells too narrow: the state box splits
    assert len(np.unique(ch.group)) == 2
    assert (ch.u_cells[:, 0, 0] == 0.5).all() and (ch.u_cells[:, 0, 1] == 1.0).all()


@settings(max_examples=40, deadline=None)
@given(a=st.floats(-2, 2), c=st.floats(0.1, 1.0), eps=st.sampled_from([0.05, 0.02]))
def test_search_exists_u_on_a_scalar_problem(a, c, eps):
    """x in [0, 1], u in [-1, 1]: x + c u in [a - .2, a + .2] for some u iff x lies in
    [a - .2 - c, a + .2 + c]; the proven boxes and witnesses are checked against it."""
    def classify(fr):
        X, U = fr.x_boxes[:, 0], fr.u_cells[:, 0]
        lab = np.zeros(len(fr), dtype=np.int8)
        ylo, yhi = X[:, 0] + c * U[:, 0], X[:, 1] + c * U[:, 1]
        lab[(yhi < a - 0.2) | (ylo > a + 0.2)] = OUTER
        mid = 0.5 * (U[:, 0] + U[:, 1])
        ok = (X[:, 0] + c * mid >= a - 0.2) & (X[:, 1] + c * mid <= a + 0.2)
        lab[ok] = INNER
        fr.data["witness"][ok, 0] = mid[ok]
        return lab

    fr = PairFrontier.from_boxes(np.array([[[0.0, 1.0]]]), np.array([[-1.0, 1.0]]),
                                 u_eps=1 / 16, data={"witness": np.full((1, 1), np.nan)})
    out = branch_and_bound(fr, classify, eps, progress=False)
    inner, outer = out.inner.x_boxes[:, 0], out.outer.x_boxes[:, 0]
    lo, hi = a - 0.2 - c, a + 0.2 + c
    assert ((inner[:, 0] >= lo - 1e-12) & (inner[:, 1] <= hi + 1e-12)).all()
    assert ((outer[:, 1] < lo) | (outer[:, 0] > hi)).all()
    w = out.inner.data["witness"][:, 0]
    tol = 1e-12
    assert ((inner[:, 0] + c * w >= a - 0.2 - tol) & (inner[:, 1] + c * w <= a + 0.2 + tol)).all()
    # the pieces cover [0, 1] (inner, outer, boundary together)
    allb = np.concatenate([inner, outer, out.boundary.x_boxes[:, 0]])
    assert np.isclose((allb[:, 1] - allb[:, 0]).sum(), 1.0)


def _shared_frontier(groups, excl):
    N = len(groups)
    fr = _frontier(groups)
    fr.data["excl"] = np.asarray(excl, dtype=bool).reshape(N, -1)
    fr.shared = "excl"
    return fr


def test_shared_exclusion_needs_one_common_column():
    # group 0: cells excluded at different columns only (for all w exists u may hold);
    # group 1: both cells excluded at column 1; group 2: one cell dropped (every column),
    # the other excluded at column 0
    fr = _shared_frontier([0, 0, 1, 1, 2, 2],
                          [[1, 0], [0, 1], [0, 1], [1, 1], [1, 1], [1, 0]])
    labels = np.array([UNDECIDED, UNDECIDED, UNDECIDED, OUTER, OUTER, UNDECIDED],
                      dtype=np.int8)
    out, _ = fr.reduce(labels, eps=0.01)
    assert (out[:2] == UNDECIDED).all()
    assert (out[2:4] == OUTER).sum() == 1 and (out[4:] == OUTER).sum() == 1
    # without the shared key, "all pairs outer" is the rule (exists u for all w)
    out2, _ = _frontier([0, 0, 1, 1, 2, 2]).reduce(labels, eps=0.01)
    assert (out2 != OUTER).all()


def test_restart_gives_new_state_boxes_the_whole_control_box_and_fresh_data():
    fresh = {"excl": np.zeros((1, 2), dtype=bool), "tag": np.zeros(1)}
    fr = PairFrontier.from_boxes(np.array([[[0.0, 1.0]]]), np.array([[-1.0, 1.0]]),
                                 u_eps=0.6, max_cells=16,
                                 data={"excl": np.zeros((1, 2), dtype=bool),
                                       "tag": np.ones(1)},
                                 restart=fresh, shared="excl")
    out, _ = fr.reduce(np.zeros(1, dtype=np.int8), eps=0.01)
    fr = fr.take(out == UNDECIDED).split()[0]  # cells [-1, 0], [0, 1]
    fr.data["excl"][0] = True
    lab = np.array([OUTER, UNDECIDED], dtype=np.int8)  # the first cell is dropped
    out, _ = fr.reduce(lab, eps=0.01)
    ch = fr.take(out == UNDECIDED).split()[0]  # cells narrow: the state box splits
    assert len(np.unique(ch.group)) == 2
    assert (ch.u_cells[:, 0] == [-1.0, 1.0]).all()  # not the hull [0, 1] of the survivor
    assert (ch.data["tag"] == 0).all() and not ch.data["excl"].any()


def test_shared_key_must_be_in_data():
    with pytest.raises(ValueError, match="shared"):
        PairFrontier.from_boxes(np.array([[[0.0, 1.0]]]), np.array([[-1.0, 1.0]]),
                                data={"witness": np.zeros((1, 1))}, shared="excl")


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 10 ** 6), N=st.integers(64, 400), G=st.integers(1, 50),
       d=st.integers(1, 6))
def test_group_loops_in_c_equal_numpy(seed, N, G, d):
    """The per-group first member and hull of the pair frontiers by their C loops equal
    numpy's ufunc.at results (groups without members, NaN-free boxes of every sign)."""
    from casadi_cmpc.interval._native import native_available
    from casadi_cmpc.solvers import engine as E

    if not native_available():
        return
    rng = np.random.default_rng(seed)
    g = rng.integers(0, G, N)
    mask = rng.random(N) < 0.5
    lo = rng.normal(size=(N, d)) * 10.0 ** rng.integers(-3, 3, (N, d))
    hi = lo + rng.random((N, d))
    assert E._group_kernel("cmpc_group_first", wait=True) is not None
    assert E._group_kernel("cmpc_group_hull", wait=True) is not None
    first = E._group_first(g, mask, G)
    glo, ghi = E._group_hull(g, G, lo, hi)
    ref_first = np.full(G, N, dtype=np.intp)
    idx = np.flatnonzero(mask)
    np.minimum.at(ref_first, g[idx], idx)
    ref_lo = np.full((G, d), np.inf)
    ref_hi = np.full((G, d), -np.inf)
    np.minimum.at(ref_lo, g, lo)
    np.maximum.at(ref_hi, g, hi)
    assert (first == ref_first).all()
    assert np.array_equal(glo, ref_lo) and np.array_equal(ghi, ref_hi)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10 ** 6), N=st.integers(64, 300), G=st.integers(1, 40),
       n=st.integers(1, 3), m=st.integers(0, 2), max_cells=st.integers(1, 8),
       eps=st.sampled_from([0.005, 0.05, 0.2]), sorted_groups=st.booleans())
def test_reduce_in_c_equals_numpy(seed, N, G, n, m, max_cells, eps, sorted_groups):
    """PairFrontier.reduce by its C loop gives the labels, small flags, splittable cells and
    split modes of the numpy reduction: groups with inner, outer and undecided pairs, group
    ids absent from the frontier, boxes at the eps limit and cells at the u_eps limit."""
    from casadi_cmpc.interval._native import native_available
    from casadi_cmpc.solvers import engine as E

    if not native_available():
        return
    assert E._group_kernel("cmpc_pair_reduce", wait=True) is not None
    rng = np.random.default_rng(seed)
    g = rng.integers(0, G, N)
    if sorted_groups:
        g = np.sort(g)
    xlo = rng.uniform(-1, 1, (G, n))
    xw = rng.choice([eps / 2, eps, 2 * eps], (G, n))  # at the limit too
    ulo = rng.uniform(-1, 0, (N, m))
    uw = rng.choice([0.025, 0.05, 0.5], (N, m))
    lo = np.ascontiguousarray(np.concatenate([xlo[g], ulo], axis=1))
    hi = np.ascontiguousarray(np.concatenate([xlo[g] + xw[g], ulo + uw], axis=1))
    labels = rng.choice(np.array([INNER, OUTER, UNDECIDED], dtype=np.int8), N,
                        p=rng.dirichlet([1.0, 1.0, 1.0]))

    def frontier():
        return PairFrontier(lo, hi, g.astype(np.intp), n, np.ones(n), np.ones(m), u_eps=0.05,
                            max_cells=max_cells)

    a, b = frontier(), frontier()
    # group ids and labels of other integer types (converted copies must outlive the call)
    a.group = a.group.astype(np.int32)
    got = a._reduce_native(labels.astype(np.int64), eps, int(g.max()) + 1)
    saved = E._GROUP_MIN
    E._GROUP_MIN = 10 ** 9  # the numpy reduction
    try:
        ref = b.reduce(labels, eps)
    finally:
        E._GROUP_MIN = saved
    assert got is not None
    assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])
    assert np.array_equal(a._u_mode, b._u_mode) and np.array_equal(a._u_can, b._u_can)


def _same_frontier(A, B) -> bool:
    if A.lo.shape != B.lo.shape or A.group.dtype != B.group.dtype:
        return False
    if not (np.array_equal(A.lo, B.lo) and np.array_equal(A.hi, B.hi)
            and np.array_equal(A.group, B.group)):
        return False
    if (A.data is None) != (B.data is None):
        return False
    return A.data is None or (set(A.data) == set(B.data) and all(
        np.array_equal(A.data[k], B.data[k]) and A.data[k].dtype == B.data[k].dtype
        for k in A.data))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10 ** 6), N=st.integers(64, 300), G=st.integers(1, 40),
       n=st.integers(1, 3), m=st.integers(0, 2), max_cells=st.integers(1, 8),
       ratio=st.sampled_from([0.5, float(np.float32(0.49))]), reduced=st.booleans(),
       restart=st.booleans(), with_data=st.booleans(),
       mag=st.sampled_from([1.0, 1e-3, 1e3, 1e-310, 1e307]))
def test_split_of_selected_pairs_in_c_equals_take_then_split(seed, N, G, n, m, max_cells,
                                                              ratio, reduced, restart,
                                                              with_data, mag):
    """``split_selected(idx)`` (one C pass) gives ``take(idx).split()``: the same children
    and stuck boxes in the same order, group ids and data (also with a restarted nested
    search, zero-width and subnormal-width coordinates, subnormal and huge bounds where
    halving rounds or sums overflow, and split modes computed by reduce or not)."""
    from casadi_cmpc.interval._native import native_available
    from casadi_cmpc.solvers import engine as E

    if not native_available():
        return
    assert E._group_kernel("cmpc_pair_split", wait=True) is not None
    rng = np.random.default_rng(seed)
    g = rng.integers(0, G, N)
    xlo = rng.uniform(-1, 1, (G, n)) * 10.0 ** rng.integers(-3, 3)
    xw = rng.choice([0.0, 1e-300, 0.01, 0.1, 0.5], (G, n))
    ulo = rng.uniform(-1, 0, (N, m))
    uw = rng.choice([0.0, 5e-324, 0.025, 0.05, 0.5], (N, m))
    with np.errstate(over="ignore"):  # bounds beyond the largest float become infinite
        lo = np.ascontiguousarray(np.concatenate([xlo[g], ulo], axis=1)) * mag
        hi = np.ascontiguousarray(np.concatenate([xlo[g] + xw[g], ulo + uw], axis=1)) * mag
    data = {"witness": rng.normal(size=(N, max(m, 1))),
            "tag": rng.integers(0, 5, N).astype(np.int16)} if with_data else None
    rs = {"tag": np.array([7], dtype=np.int16)} if restart and with_data else None
    x_scale = rng.uniform(0.5, 2.0, n)

    def frontier():
        return PairFrontier(lo, hi, g.astype(np.intp), n, x_scale, np.ones(m), 0.05,
                            max_cells, ratio, data, np.tile([-1.0, 1.0], (m, 1)), rs)

    A, B = frontier(), frontier()
    if reduced:
        labels = rng.choice(np.array([INNER, OUTER, UNDECIDED], dtype=np.int8), N)
        A.reduce(labels, 0.05)
        B._u_mode, B._u_can = A._u_mode.copy(), A._u_can.copy()
    mask = rng.random(N) < rng.uniform(0.3, 1.0)
    sel = np.flatnonzero(mask)
    c1, s1 = A.split_selected(sel)
    c2, s2 = B.take(sel).split()
    assert _same_frontier(c1, c2) and _same_frontier(s1, s2)
    # a boolean mask, and indices as a strided int32 view (converted copies)
    c3, s3 = A.split_selected(mask)
    assert _same_frontier(c3, c2) and _same_frontier(s3, s2)
    wide = np.zeros(2 * sel.size, dtype=np.int32)
    wide[::2] = sel
    c4, s4 = A.split_selected(wide[::2])
    assert _same_frontier(c4, c2) and _same_frontier(s4, s2)


def test_split_and_reduce_of_many_coordinates_keep_the_numpy_rule():
    """Beyond the C loops' 8 coordinates (where numpy's widest picks a NaN width first) the
    pair frontier splits and reduces as numpy does: same children and labels."""
    from casadi_cmpc.solvers import engine as E

    rng = np.random.default_rng(0)
    N, n, m = 128, 9, 1
    lo = rng.uniform(-1, 0, (N, n + m))
    hi = lo + rng.uniform(0.01, 0.5, (N, n + m))
    lo[:, 4], hi[:, 4] = np.inf, np.inf  # a NaN width (inf - inf) in one coordinate
    g = np.arange(N)

    def fr():
        return PairFrontier(lo.copy(), hi.copy(), g.copy(), n, np.ones(n), np.ones(m), 0.05,
                            4)

    A, B = fr(), fr()
    labels = rng.choice(np.array([INNER, OUTER, UNDECIDED], dtype=np.int8), N)
    ra = A.reduce(labels, 0.05)
    saved = E._GROUP_MIN
    E._GROUP_MIN = 10 ** 9
    try:
        rb = B.reduce(labels, 0.05)
        c2, s2 = B.take(np.arange(0, N, 2)).split()
    finally:
        E._GROUP_MIN = saved
    assert np.array_equal(ra[0], rb[0]) and np.array_equal(ra[1], rb[1])
    c1, s1 = A.split_selected(np.arange(0, N, 2))
    assert _same_frontier(c1, c2) and _same_frontier(s1, s2)
