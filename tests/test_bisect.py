"""The one bisection (casadi_cmpc._bisect): its C loop gives the bits of its numpy rules."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from casadi_cmpc import _bisect as B
from casadi_cmpc.interval._native import native_available

# magnitudes where the cut rules take their fallbacks: huge bounds (b - a overflows),
# subnormals, intervals a few ulps wide, signed zeros
_VALUES = [0.0, -0.0, 1.0, -1.0, 3.0, 1e-300, -1e-300, 5e-324, -5e-324, 1e308, -1e308,
           1.7976931348623157e308, -1.7976931348623157e308, 2.0 ** -1021, 0.1]


def _boxes(rng: np.random.Generator, N: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    a = np.where(rng.random((N, n)) < 0.4, rng.choice(_VALUES, (N, n)),
                 rng.uniform(-10, 10, (N, n)) * 10.0 ** rng.integers(-5, 5, (N, n)))
    kind = rng.integers(0, 4, (N, n))
    with np.errstate(over="ignore"):  # the float after the largest one is inf
        b = _others(rng, a, kind)
    tiny = rng.random((N, n)) < 0.15  # a few subnormal steps: halving them rounds
    ticks = rng.integers(-20, 20, (N, n))
    a = np.where(tiny, ticks * 5e-324, a)
    b = np.where(tiny, (ticks + rng.integers(0, 20, (N, n))) * 5e-324, b)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return np.ascontiguousarray(lo), np.ascontiguousarray(hi)


def _others(rng: np.random.Generator, a: np.ndarray, kind: np.ndarray) -> np.ndarray:
    """The second bounds: equal, the next float, two floats on, or anything."""
    N, n = a.shape
    return np.where(kind == 0, a, np.where(kind == 1, np.nextafter(a, np.inf),
                 np.where(kind == 2, np.nextafter(np.nextafter(a, np.inf), np.inf),
                          np.where(rng.random((N, n)) < 0.3, rng.choice(_VALUES, (N, n)),
                                   a + rng.uniform(0, 5, (N, n))))))


def _numpy_widest(lo, hi, scale=None):
    with np.errstate(all="ignore"):
        w = hi - lo
        if scale is not None:
            w = w / scale
    return B.widest(w)


def _numpy_bisect(lo, hi, k, ratio):
    """bisect_widest with the C loop switched off."""
    saved = B.NATIVE_MIN
    B.NATIVE_MIN = 1 << 62
    try:
        return B.bisect_widest(lo, hi, k=k, ratio=ratio)
    finally:
        B.NATIVE_MIN = saved


@pytest.fixture(scope="module")
def kernels():
    if not native_available():
        pytest.skip("no C compiler")
    assert B._kernel("cmpc_widest", wait=True) is not None
    assert B._kernel("cmpc_bisect", wait=True) is not None


@settings(max_examples=200, deadline=None)
@given(N=st.integers(16, 80), n=st.integers(1, 8), seed=st.integers(0, 2 ** 32 - 1),
       ratio=st.sampled_from([0.5, 0.49000000953674316, 0.25, 0.9]),
       scaled=st.booleans(), before=st.integers(0, 2), after=st.integers(0, 2))
def test_c_loop_gives_the_numpy_bits(kernels, N, n, seed, ratio, scaled, before, after):
    """Split coordinates, widths (of a range of coordinates, as the pair frontiers measure
    states and controls), cut points, halves and the 'splits' flags of the C loop equal
    those of the numpy rules bit for bit, at every magnitude."""
    rng = np.random.default_rng(seed)
    lo_all, hi_all = _boxes(rng, N, before + n + after)
    scale = None
    if scaled:
        scale = rng.choice([1.0, 0.5, 3.0, 1e-300, 1e300, np.inf], n)
    best, k = B.widest_of(lo_all, hi_all, scale, before, before + n)
    best_np, k_np = _numpy_widest(lo_all[:, before:before + n], hi_all[:, before:before + n],
                                  scale)
    assert (k == k_np).all()
    assert np.array_equal(best, best_np, equal_nan=True)
    lo = np.ascontiguousarray(lo_all[:, before:before + n])
    hi = np.ascontiguousarray(hi_all[:, before:before + n])
    got = B.bisect_widest(lo, hi, k=k, ratio=ratio)
    ref = _numpy_bisect(lo, hi, k_np, ratio)
    for g, r in zip(got, ref, strict=True):
        assert g.shape == r.shape
        assert np.array_equal(g.view(np.uint8), r.view(np.uint8))  # bits, signed zeros too
    # a cut that splits lies strictly inside its coordinate
    lo2, hi2, _, ok = got
    rows = np.flatnonzero(ok)
    c = hi2[rows, k[rows]]
    assert ((lo[rows, k[rows]] < c) & (c < hi[rows, k[rows]])).all()
    assert (lo2[N + rows, k[rows]] == c).all()


def test_an_interval_without_a_float_inside_is_not_split(kernels):
    a = np.full((32, 2), 1.0)
    b = a.copy()
    b[:, 0] = np.nextafter(1.0, 2.0)
    _, _, k, ok = B.bisect_widest(a, b)
    assert (k == 0).all() and not ok.any()
    b[:, 0] = np.nextafter(np.nextafter(1.0, 2.0), 2.0)  # one float inside: the cut
    lo2, hi2, _, ok = B.bisect_widest(a, b)
    assert ok.all() and (hi2[:32, 0] == np.nextafter(1.0, 2.0)).all()
