"""Soundness classes of SIVIA's certified views.

* inner boxes hold only points where f is *defined* and in Y, also for target components
  without a finite bound;
* outer boxes (including the slabs cut off by the contractor) are closed: no point of them,
  faces included, is a solution;
* any number of constrained output elements;
* overflow inside the graph never turns into a proof (outside or inside).

Exact checks use Fractions (affine functions) or mpmath at high precision.
"""

from __future__ import annotations

from fractions import Fraction

import casadi as ca
import mpmath
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm


def _corners(box: np.ndarray) -> np.ndarray:
    n = box.shape[0]
    idx = np.array(np.meshgrid(*[[0, 1]] * n, indexing="ij")).reshape(n, -1).T
    return box[np.arange(n), idx]  # (2^n, n)


def _points(box: np.ndarray, rng: np.random.Generator, k: int = 4) -> np.ndarray:
    """Corners, centre and random points of a closed box (all floats inside it)."""
    lo, hi = box[:, 0], box[:, 1]
    mid = np.clip(0.5 * lo + 0.5 * hi, lo, hi)
    rand = np.clip(lo + (hi - lo) * rng.random((k, lo.size)), lo, hi)
    return np.vstack([_corners(box), mid[None], rand])


# ------------------------------------------------------ class 3: undefined points in inner
_DOMAIN_OPS = {
    "log": (ca.log, lambda v: v > 0),
    "sqrt": (ca.sqrt, lambda v: v >= 0),
    "inv": (lambda e: 1 / e, lambda v: v != 0),
    "asin": (ca.asin, lambda v: -1 <= v <= 1),
    "log1p": (ca.log1p, lambda v: v > -1),
}


@settings(max_examples=30)
@given(n=st.integers(1, 4), op=st.sampled_from(sorted(_DOMAIN_OPS)),
       shift=st.sampled_from([0.0, 0.5, -3.0, 1e6, -1e8]),
       scale=st.sampled_from([1.0, 1e-3, 1e4]), seed=st.integers(0, 2**31 - 1),
       bounded_first=st.booleans())
def test_inner_boxes_hold_only_points_where_f_is_defined(n, op, shift, scale, seed,
                                                         bounded_first):
    """f = (x0 (bounded target), op(arg)) with Y unbounded on the second element: an inner
    box must not contain points where op is undefined."""
    fn, ok = _DOMAIN_OPS[op]
    x = ca.SX.sym("x", n)
    arg = (x[n - 1] - shift) / scale
    outs = [x[0], fn(arg)] if bounded_first else [fn(arg), x[0]]
    f = ca.Function("f", [x], [ca.vertcat(*outs)])
    half = 2.0 * scale
    X0 = cm.Box([-1.0] * (n - 1) + [shift - half], [1.0] * (n - 1) + [shift + half])
    if bounded_first:
        Y = cm.Box([-0.5, -np.inf], [0.5, np.inf])
    else:
        Y = cm.Box([-np.inf, -0.5], [np.inf, 0.5])
    P = cm.sivia(f, X0, Y, eps=0.05 if n <= 2 else 0.2, relative=True)
    rng = np.random.default_rng(seed)
    for box in P.inner:
        for p in _points(box, rng, 2):
            v = (Fraction(float(p[n - 1])) - Fraction(shift)) / Fraction(scale)
            assert ok(v), f"inner box {box.tolist()} holds {p} where {op} is undefined"


def test_log_component_with_unbounded_target_reproduction():
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [ca.vertcat(x[0], ca.log(x[1]))])
    P = cm.sivia(f, cm.Box([-1, -1], [1, 1]), cm.Box([0, -np.inf], [1, np.inf]), eps=0.05)
    assert P.inner.shape[0] > 0
    assert (P.inner[:, 1, 0] > 0).all()  # x1 > 0 on every inner box, faces included
    # one element only (the joint classifier): the same rule
    g = ca.Function("g", [x], [ca.sqrt(x[1])])
    P = cm.sivia(g, cm.Box([-1, -1], [1, 1]), cm.Box([-np.inf], [np.inf]), eps=0.05)
    assert P.inner.shape[0] > 0 and (P.inner[:, 1, 0] >= 0).all()


# ------------------------------------------------------ class 4: closed faces of outer boxes
def test_contractor_slabs_do_not_claim_the_face_of_the_solution_set():
    y = ca.SX.sym("y")
    f = ca.Function("f", [y], [y])
    for contract in (False, True):
        P = cm.sivia(f, cm.Box([0], [1]), cm.Box([0.5], [1]), eps=0.01, contract=contract)
        on = (P.outside[:, 0, 0] <= 0.5) & (P.outside[:, 0, 1] >= 0.5)
        assert not on.any(), f"x = 0.5 is a solution but lies in the outer view ({contract=})"
        assert P.contains(np.array([[0.5]])).all()  # the views still cover the domain


@settings(max_examples=40)
@given(n=st.integers(1, 4), seed=st.integers(0, 2**31 - 1),
       shift=st.sampled_from([0.0, 1.0, -7.5, 1e5, -1e9]),
       scale=st.sampled_from([1.0, 1e-4, 1e3]), contract=st.booleans(),
       open_target=st.booleans(), exact=st.booleans())
def test_views_are_exact_on_affine_functions(n, seed, shift, scale, contract, open_target,
                                             exact):
    """For affine f (exactly evaluable with Fractions) every point of every inner box, faces
    included, is a solution and no point of any outer box is. With ``exact``, coefficients
    and bounds are binary fractions, so that the contractor's cuts land exactly on the
    boundary of the solution set (where a closed face must not be claimed outside)."""
    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, 3))
    if exact:
        shift, scale = 0.0, 1.0
        C = rng.choice([-2.0, -1.0, -0.5, 0.5, 1.0, 2.0], size=(m, n))
        C[:, rng.random(n) < 0.5] = 0.0
        C[np.arange(m), np.arange(m) % n] = 1.0
        ylo = rng.integers(-10, 0, m) / 8
        yhi = ylo + rng.integers(2, 12, m) / 8
    else:
        C = np.round(rng.normal(size=(m, n)) * 4) / 4  # binary fractions: exact coefficients
        C[C == 0] = 0.5
        ylo = np.round(rng.uniform(-1.5, 0.0, m), 3)
        yhi = ylo + np.round(rng.uniform(0.25, 2.0, m), 3)
    x = ca.SX.sym("x", n)
    z = (x - shift) / scale
    f = ca.Function("f", [x], [ca.mtimes(ca.DM(C), z)])
    X0 = cm.Box(shift - 1.5 * scale * np.ones(n), shift + 1.5 * scale * np.ones(n))
    P = cm.sivia(f, X0, cm.Box(ylo, yhi), eps=0.2 * scale, contract=contract,
                 open_target=open_target)

    def image(p):
        zz = [(Fraction(float(v)) - Fraction(shift)) / Fraction(scale) for v in p]
        return [sum(Fraction(float(C[i, j])) * zz[j] for j in range(n)) for i in range(m)]

    def solution(p, strict):
        y = image(p)
        lo = [Fraction(float(v)) for v in ylo]
        hi = [Fraction(float(v)) for v in yhi]
        if strict:
            return all(a < v < b for v, a, b in zip(y, lo, hi, strict=True))
        return all(a <= v <= b for v, a, b in zip(y, lo, hi, strict=True))

    for box in P.inner[:20]:
        for p in _points(box, rng, 2):
            assert solution(p, open_target), f"inner point {p} is no solution"
    for box in P.outside[:60]:
        for p in _points(box, rng, 2):
            assert not solution(p, open_target), f"outer point {p} of {box.tolist()} is a solution"


# ------------------------------------------------ many constrained elements, overflow classes
def test_more_than_64_constrained_elements():
    z = ca.SX.sym("z", 3)
    k = 100
    h = ca.Function("h", [z], [ca.vertcat(*[z[i % 3] * (1 + 0.01 * i) for i in range(k)])])
    P = cm.sivia(h, cm.Box([-1] * 3, [1] * 3), cm.Box([-0.5] * k, [0.5] * k), eps=0.1)
    assert P.inner.shape[0] > 0
    bound = 0.5 / (1 + 0.01 * 99)  # the tightest constraint on each coordinate
    assert (np.abs(P.inner) <= bound).all()
    # the origin is a solution and must not be outer
    assert not ((P.outside[:, :, 0] <= 0) & (P.outside[:, :, 1] >= 0)).all(axis=1).any()


def test_overflowing_quotient_in_the_contractor_keeps_solutions():
    """1/exp(x) on [740, 741] is about 1e-322 > 0 and below 1e-320 at every point: no part of
    the box may be discarded."""
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [1 / ca.exp(x)])
    with mpmath.workprec(200):
        for v in (740, 740.5, 741):
            assert 0 <= 1 / mpmath.exp(v) <= mpmath.mpf(1e-320)
    P = cm.sivia(f, cm.Box([740], [741]), cm.Box([0], [1e-320]), eps=0.1, contract=True)
    assert P.outside.shape[0] == 0
    from casadi_cmpc.interval.contractor import contractor

    lo2, hi2, empty = contractor(f, [[0, 1e-320]])(np.array([[740.0]]), np.array([[741.0]]))
    assert not empty[0] and lo2[0, 0] == 740.0 and hi2[0, 0] == 741.0


@pytest.mark.parametrize("eps", ["0.1", b"0.1", True, None, -1.0, float("nan")])
def test_eps_must_be_a_positive_number(eps):
    y = ca.SX.sym("y")
    f = ca.Function("f", [y], [y])
    with pytest.raises(ValueError, match="eps must be a positive number"):
        cm.sivia(f, cm.Box([0], [1]), cm.Box([0], [1]), eps=eps)


def test_quantified_inner_boxes_hold_only_points_where_f_is_defined():
    """The same rule for quantified set inversion (∀w ∃u): log(x1 + w) must be defined for
    every w at every point of an inner box."""
    from casadi_cmpc.solvers.quantified import quantified_sivia

    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    f = ca.Function("f", [x, u, w], [ca.vertcat(x[0] + u, ca.log(x[1] + w))])
    P = quantified_sivia(f, cm.Box([-1, -1], [1, 1]), cm.Box([-0.5], [0.5]),
                         cm.Box([-0.1], [0.1]), cm.Box([-0.5, -np.inf], [0.5, np.inf]),
                         eps=0.25, progress=False)
    assert P.inner.shape[0] > 0
    assert (P.inner[:, 1, 0] > 0.1).all()  # x1 + w > 0 for all w in [-0.1, 0.1]
