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
