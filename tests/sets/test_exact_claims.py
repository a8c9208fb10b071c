"""Set operations whose results feed proofs are never larger than the truth (exact checks)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm

F = Fraction


def _exact_box_support(a: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> Fraction:
    return sum((max(F(float(ai)) * F(float(l)), F(float(ai)) * F(float(h)))
                for ai, l, h in zip(a, lo, hi, strict=True)), F(0))


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 4), st.integers(0, 10_000), st.sampled_from([1e-3, 1.0, 1e3]),
       st.booleans())
def test_pontryagin_difference_is_inner(n: int, seed: int, scale: float, as_poly: bool
                                        ) -> None:
    rng = np.random.default_rng(seed)
    A = np.vstack([rng.normal(size=(n + 2, n)), np.eye(n), -np.eye(n)])
    b = (np.abs(rng.normal(size=A.shape[0])) + 1.0) * scale + A @ (rng.normal(size=n) * scale)
    P = cm.Polytope(A, b)
    c = rng.normal(size=n) * scale * 0.1
    r = np.abs(rng.normal(size=n)) * scale * 0.1 + 1e-3 * scale
    Q = cm.Box(c - r, c + r)
    D = P.pontryagin_difference(cm.Polytope.from_box(Q) if as_poly else Q)
    Db = np.asarray(D.b)
    for row, bi in zip(np.asarray(D.A), Db, strict=True):
        if not np.isfinite(bi):
            continue
        # the row is a row of P: its offset is at most b_i - h_Q(a_i), exactly
        k = int(np.flatnonzero((A == row).all(axis=1))[0])
        assert F(float(bi)) <= F(float(b[k])) - _exact_box_support(row, Q.lo, Q.hi)


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 4), st.integers(0, 10_000), st.integers(-3, 3),
       st.sampled_from([1e-8, 1.0, 1e8]))
def test_polytope_contains_is_exact_near_facets(n: int, seed: int, steps: int,
                                                 scale: float) -> None:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n + 3, n))
    b = rng.normal(size=n + 3) * scale
    P = cm.Polytope(A, b)
    a = A[0]
    x = (b[0] / (a @ a)) * a + rng.normal(size=n) * 0.0
    for _ in range(abs(steps)):
        x = np.array([math.nextafter(v, math.inf if (s > 0) == (steps > 0) else -math.inf)
                      if s != 0 else v for v, s in zip(x, np.sign(a), strict=True)])
    pts = np.vstack([x, rng.normal(size=(5, n)) * scale])
    exact = [all(sum((F(float(ai)) * F(float(v)) for ai, v in zip(row, p, strict=True)), F(0))
                 <= F(float(bi)) for row, bi in zip(A, b, strict=True)) for p in pts]
    assert P.contains(pts).tolist() == exact
