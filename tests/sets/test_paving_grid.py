"""The exact grid index of box unions agrees with the pairwise exact routines."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.sets.paving import _BoxGrid, _covered, _pairs


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 10 ** 6), n=st.integers(1, 3), k=st.integers(1, 30),
       scale=st.sampled_from([1.0, 0.1, 1e-3, 37.0]), shift=st.sampled_from([0.0, -5.0, 1e3]))
def test_grid_equals_pairwise_tests(seed, n, k, scale, shift):
    rng = np.random.default_rng(seed)
    U = np.sort(rng.integers(0, 6, (k, n, 2)).astype(float), axis=-1) * scale + shift
    Q = rng.integers(-1, 7, (120, n, 2)).astype(float)
    Q += (rng.random(Q.shape) < 0.3) * rng.random(Q.shape)
    Q = np.sort(Q, axis=-1) * scale + shift
    G = _BoxGrid.build(U)
    if G is None:
        return
    assert (G.contains(Q) == _covered(Q, U)).all()
    ref = np.zeros(Q.shape[0], dtype=bool)
    ia, _ = _pairs(Q, U)
    ref[ia] = True
    assert (G.intersects(Q) == ref).all()


def test_paving_uses_the_grid_for_large_unions_and_stays_exact():
    rng = np.random.default_rng(3)
    lo = rng.integers(0, 40, (300, 2)) * 0.05
    inner = np.stack([lo, lo + 0.05], axis=-1)
    P = cm.Paving(inner=inner)
    Q = np.sort(rng.random((500, 2, 2)) * 2.1, axis=-1)
    assert (P.contains_box(Q, view="inner") == _covered(Q, inner)).all()
    assert P._cache.get(("grid", "inner")) is not None
    pts = rng.random((2000, 2)) * 2.0
    inside = P.contains(pts, view="inner")
    thin = np.stack([pts, pts], axis=-1)
    assert (P.contains_box(thin, view="inner") == inside).all()


def _grid_c_loaded() -> bool:
    """Load the C grid query (waiting for its compilation); False without a compiler."""
    from casadi_cmpc.sets import _boxunion as bu

    return bu._grid_kernel(wait=True) is not None


@settings(max_examples=120, deadline=None)
@given(seed=st.integers(0, 10 ** 6), n=st.integers(1, 6), k=st.integers(1, 300),
       scale=st.sampled_from([1.0, 1e-3, 37.0, 0.1, 1e-300, 2.0 ** -1070, 1e150, 1e300]),
       shift=st.sampled_from([0.0, -5.0, 1e3, 1e-310]))
def test_c_grid_query_equals_the_numpy_code(seed, n, k, scale, shift):
    """The C loop and the numpy code answer every query alike: faces, flat unions, queries
    sticking out of the grid, infinite and NaN bounds (intersects: True; contains: False),
    with the binary searches (unions of up to 128 boxes) and with the search hints of
    bounds on a uniform grid (larger unions; scale 0.1: not exactly on one)."""
    import pytest

    from casadi_cmpc.sets import _boxunion as bu

    if not _grid_c_loaded():
        pytest.skip("no C compiler")
    rng = np.random.default_rng(seed)
    U = np.sort(rng.integers(0, 6, (k, n, 2)).astype(float), axis=-1) * scale + shift
    if rng.random() < 0.2:  # every box flat in one coordinate
        U[:, 0, 1] = U[:, 0, 0] = U[0, 0, 0]
        U[0, 1 % n, 1] = U[0, 1 % n, 0] + scale
    Q = rng.integers(-2, 8, (200, n, 2)).astype(float)
    Q += (rng.random(Q.shape) < 0.3) * rng.random(Q.shape)
    Q = np.sort(Q, axis=-1) * scale + shift
    odd = rng.random(Q.shape) < 0.02
    Q[odd] = rng.choice([np.inf, -np.inf, np.nan], size=int(odd.sum()))
    G = _BoxGrid.build(U)
    if G is None:
        return
    fat = ~(Q[..., 1] <= Q[..., 0]).any(axis=1)  # contains sends thin queries elsewhere
    got_c = G._native(Q[fat], True)
    assert got_c is not None
    got_i = G.intersects(Q)
    from casadi_cmpc.interval import _native

    key = (bu._GRID_C, "cmpc_grid_query")
    saved = _native._functions[key]
    _native._functions[key] = None  # as without a compiler: the numpy code
    try:
        ref_c = G.contains(Q[fat])
        ref_i = G.intersects(Q)
    finally:
        _native._functions[key] = saved
    assert (got_c == ref_c).all()
    assert (got_i == ref_i).all()
    nan = np.isnan(Q).any(axis=(1, 2))
    assert got_i[nan].all()  # an enclosure with a NaN bound may be anything
    # otherwise exact, infinite bounds included: against all pairs of closed boxes
    Qk = Q[~nan]
    brute = ((Qk[:, None, :, 0] <= U[None, :, :, 1])
             & (U[None, :, :, 0] <= Qk[:, None, :, 1])).all(axis=2).any(axis=1)
    assert (got_i[~nan] == brute).all()
    # a copy of a used index (as sent to a worker process) queries its own arrays: the
    # original freed and its memory reused must not change the copy's answers
    import pickle

    G2 = pickle.loads(pickle.dumps(G))
    del G
    junk = [np.full(a.shape, -7, dtype=a.dtype) for a in (G2.table, G2._edges_cat)]
    assert (G2._native(Q[fat], True) == ref_c).all()
    assert (G2.intersects(Q) == ref_i).all()
    del junk


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 10 ** 6), n=st.integers(129, 600), span=st.integers(1, 3000),
       h=st.sampled_from([0.1, 1 / 3, 2.0 ** -7, 1e-9, 37.0]),
       lo=st.sampled_from([0.0, -1.0, 0.3, -1e3, 1e6]), jitter=st.booleans())
def test_linear_time_unique_equals_numpy(seed, n, span, h, lo, jitter):
    """The grid fast path of the bound index gives np.unique's answer exactly, on grids
    that floating point reproduces and on those it does not (then: by sorting)."""
    from casadi_cmpc.sets._boxunion import _unique_inverse

    rng = np.random.default_rng(seed)
    B = lo + np.sort(rng.integers(0, span + 1, (n, 2)), axis=-1) * h
    if jitter:  # one bound off the grid
        B[rng.integers(n), rng.integers(2)] += 0.37 * h
        B = np.sort(B, axis=-1)
    e, inv, grid = _unique_inverse(B)
    if grid is not None:  # the codes of the distinct bounds give them back
        assert np.array_equal(grid[0] + grid[2] * grid[1], e)
    e2, inv2 = np.unique(B.ravel(), return_inverse=True)
    assert np.array_equal(e, e2) and np.array_equal(inv, inv2.reshape(-1))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10 ** 6), n=st.integers(1, 3), k=st.integers(1, 63),
       q=st.sampled_from([1, 31, 32, 200]))
def test_small_unions_answer_exactly_by_either_path(seed, n, k, q):
    """A union of fewer than 64 boxes is indexed by the grid at the first batch of 32
    queries or more (pairwise routines below): the same exact answers either way."""
    rng = np.random.default_rng(seed)
    U = np.sort(rng.integers(0, 6, (k, n, 2)).astype(float), axis=-1) * 0.3 - 1.0
    Q = np.sort(rng.integers(-1, 7, (q, n, 2)).astype(float) * 0.3 - 1.0
                + (rng.random((q, n, 2)) < 0.3) * 0.1, axis=-1)
    P = cm.Paving(inner=U)
    assert (P.contains_box(Q, view="inner") == _covered(Q, U)).all()
    ref = np.zeros(q, dtype=bool)
    ia, _ = _pairs(Q, U)
    ref[ia] = True
    assert (P.intersects_box(Q, view="inner") == ref).all()


@settings(max_examples=120, deadline=None)
@given(seed=st.integers(0, 10 ** 6), n=st.integers(1, 3), k=st.integers(1, 200),
       flat=st.booleans())
def test_compacted_union_is_the_same_closed_set(seed, n, k, flat):
    """The runs of covered grid cells cover exactly the union: each box of either list lies
    in the union of the other (exact tests), flat boxes are kept, and the runs never
    outnumber the boxes (the boxes themselves are kept then)."""
    from casadi_cmpc.sets._boxunion import _compact_union

    rng = np.random.default_rng(seed)
    U = np.sort(rng.integers(0, 8, (k, n, 2)).astype(float), axis=-1) * 0.25 - 1.0
    U = U[(U[..., 1] > U[..., 0]).all(axis=1)]
    if flat:
        F = np.sort(rng.integers(0, 8, (3, n, 2)).astype(float), axis=-1) * 0.25 - 1.0
        F[:, 0, 1] = F[:, 0, 0]
        U = np.concatenate([U, F])
    if U.shape[0] == 0:
        return
    C = _compact_union(U)
    assert _covered(C, U).all() and _covered(U, C).all()
    assert (C[..., 0] <= C[..., 1]).all()
    assert C.shape[0] <= U.shape[0]
    n_flat = int((U[..., 1] <= U[..., 0]).any(axis=1).sum())
    assert int((C[..., 1] <= C[..., 0]).any(axis=1).sum()) == n_flat


def test_compacting_tall_thin_boxes_keeps_them():
    """64 boxes spanning every row of the grid, side by side with gaps: runs along the last
    coordinate would be 64 per row; the boxes are kept as they are."""
    from casadi_cmpc.sets._boxunion import _compact_union

    lo = np.arange(64) * 2.0
    U = np.stack([np.stack([np.zeros(64), np.full(64, 10.0)], -1),
                  np.stack([lo, lo + 1.0], -1)], axis=1)
    U = np.concatenate([U, np.array([[[0.0, 5.0], [0.0, 0.5]]])])  # one more edge per axis
    C = _compact_union(U)
    assert C.shape[0] <= U.shape[0]
    assert _covered(C, U).all() and _covered(U, C).all()


def test_a_symbol_loaded_with_another_signature_is_refused():
    """One C function object per symbol: asking for it with other argument types (which
    would pass arguments of the wrong width) is a TypeError, not memory corruption."""
    import ctypes

    import pytest

    from casadi_cmpc.interval._native import load_symbol
    from casadi_cmpc.sets import _boxunion as bu

    if not _grid_c_loaded():
        pytest.skip("no C compiler")
    i64, ptr = ctypes.c_int64, ctypes.c_void_p
    with pytest.raises(TypeError, match="already loaded"):
        load_symbol(bu._GRID_C, "cmpc_grid_query", [i64, i64, ptr, ptr, ptr, ptr, ptr, i64, ptr])
