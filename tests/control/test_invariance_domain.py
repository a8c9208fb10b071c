"""certify_invariant on ill-conditioned sets: the searched domain provably contains S.

Each test checks its verdict against exact rational arithmetic: the vertices of a
parallelotope ``{lo <= V x <= hi}`` are ``V^-1 z`` for the corners ``z`` of ``[lo, hi]``,
computed with Fractions, and the law ``u = K x`` is linear, so its largest value over S is
attained at one of them.
"""

from __future__ import annotations

import itertools
from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.control.invariance import _domain


def _solve(M: list[list[Fraction]], z: list[Fraction]) -> list[Fraction]:
    """Exact solution of ``M x = z`` (M square, invertible)."""
    n = len(M)
    A = [list(M[i]) + [z[i]] for i in range(n)]
    for c in range(n):
        p = next(i for i in range(c, n) if A[i][c] != 0)
        A[c], A[p] = A[p], A[c]
        for i in range(n):
            if i != c and A[i][c] != 0:
                f = A[i][c] / A[c][c]
                A[i] = [a - f * b for a, b in zip(A[i], A[c], strict=True)]
    return [A[i][n] / A[i][i] for i in range(n)]


def _exact_vertices(V: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> list[list[Fraction]]:
    M = [[Fraction(float(v)) for v in row] for row in V]
    out = []
    for corner in itertools.product(*[(Fraction(float(a)), Fraction(float(b)))
                                      for a, b in zip(lo, hi, strict=True)]):
        out.append(_solve(M, list(corner)))
    return out


def _in_zonotope_exact(Z: cm.Zonotope, v: list[Fraction]) -> bool:
    """v in the parallelotope Z (square generator matrix), decided exactly."""
    G = [[Fraction(float(g)) for g in row] for row in Z.generators]
    d = [vi - Fraction(float(ci)) for vi, ci in zip(v, Z.center, strict=True)]
    xi = _solve(G, d)
    return all(abs(t) <= 1 for t in xi)


def _model(n: int, U_hi: float, U_lo: float | None = None) -> cm.Model:
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u")
    big = 1e12
    return cm.Model(x=x, u=u, f=0.5 * x, X=cm.Box([-big] * n, [big] * n),
                    U=cm.Box([-2 * abs(U_hi) if U_lo is None else U_lo], [U_hi]))


def _check(cert: cm.Certificate, S: cm.Polytope, U_hi: Fraction) -> None:
    """The verdict is not 'proved', and a counterexample is exactly in S with law > U.hi."""
    assert cert.proved is not True, cert.reason
    if cert.proved is False:
        x = [Fraction(float(v)) for v in cert.counterexample]
        for a, b in zip(S.A, S.b, strict=True):
            assert sum(Fraction(float(ai)) * xi for ai, xi in zip(a, x, strict=True)) \
                <= Fraction(float(b))
        assert x[0] > U_hi


def test_near_parallel_parallelogram_reproduction() -> None:
    V = np.array([[-0.022954241955331668, 1.0010549947766059],
                  [-0.02295424474534512, 1.001054994539801]])
    S = cm.Polytope(np.vstack([V, -V]), np.ones(4))
    U_hi = 715450006.9967935
    verts = _exact_vertices(V, -np.ones(2), np.ones(2))
    assert max(v[0] for v in verts) > Fraction(U_hi)  # the claim is false
    cert = cm.certify_invariant(_model(2, U_hi), S, np.array([[1.0, 0.0]]), eps=1e6,
                                progress=False)
    _check(cert, S, Fraction(U_hi))
    Z, _ = _domain(S)
    assert Z is not None and all(_in_zonotope_exact(Z, v) for v in verts)


def test_thin_triangle_far_vertex() -> None:
    A = np.array([[0.0016100957671534466, 0.9941447117587666],
                  [-0.0016099915317663365, -0.9941448206805195], [-1.0, 0.0]])
    S = cm.Polytope(A, np.ones(3))
    for eps in (1e5, 1e3):
        cert = cm.certify_invariant(_model(2, 2.5, -2.5), S, np.array([[1.0, 0.0]]), eps=eps,
                                    progress=False)
        _check(cert, S, Fraction(2.5))


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_input_refutation_names_a_violating_point(side: float) -> None:
    # law 0 (outside U = [1, 2]) on one half of S and 1.5 (inside U) on the other: every
    # violating point has law 0, and the point reported must be one of them
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=0.5 * x, X=cm.Box([-2, -2], [2, 2]), U=cm.Box([1.0], [2.0]))
    S = cm.Polytope.from_box(cm.Box([-1, -1], [1, 1]))
    law = ca.if_else(side * x[0] < 0, 0.0, 1.5)
    cert = cm.certify_invariant(model, S, law, eps=0.1, progress=False)
    assert cert.proved is False
    xc = cert.counterexample
    assert side * xc[0] < 0, (xc, cert.reason)  # law(xc) = 0, outside U


@st.composite
def _near_parallel(draw: st.DrawFn) -> tuple[np.ndarray, float]:
    n = draw(st.integers(2, 4))
    base = np.array(draw(st.lists(st.floats(-1, 1, allow_nan=False), min_size=n,
                                  max_size=n)))
    base[-1] = 1.0 + abs(base[-1])
    rows = [base]
    for _ in range(n - 1):
        scale = 10.0 ** draw(st.integers(-9, -3))
        pert = np.array(draw(st.lists(st.floats(-1, 1, allow_nan=False), min_size=n,
                                      max_size=n)))
        rows.append(base + scale * pert)
    V = np.array(rows)
    delta = draw(st.floats(1e-6, 1e-2))
    return V, delta


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_near_parallel())
def test_never_proved_when_the_law_leaves_U_at_a_vertex(data: tuple[np.ndarray, float]
                                                      ) -> None:
    V, delta = data
    n = V.shape[0]
    if abs(np.linalg.det(V)) < 1e-300 or np.linalg.cond(V) > 1e13:
        return
    S = cm.Polytope(np.vstack([V, -V]), np.ones(2 * n))
    verts = _exact_vertices(V, -np.ones(n), np.ones(n))
    top = max(v[0] for v in verts)
    U_hi = float(top) * (1.0 - delta)  # strictly below the exact maximum of u = x1
    if not Fraction(U_hi) < top or not np.isfinite(U_hi) or U_hi <= 0:
        return
    K = np.zeros((1, n))
    K[0, 0] = 1.0
    cert = cm.certify_invariant(_model(n, U_hi), S, K, eps=float(top) / 4, max_boxes=4000,
                                progress=False)
    _check(cert, S, Fraction(U_hi))
    Z, _ = _domain(S)
    if Z is not None:  # a domain is only ever used when it provably covers S
        assert all(_in_zonotope_exact(Z, v) for v in verts)


@pytest.mark.parametrize("n", [2, 3, 4])
def test_well_conditioned_sets_still_proved(n: int) -> None:
    S = cm.Polytope.from_box(cm.Box([-1.0] * n, [1.0] * n))
    K = np.zeros((1, n))
    K[0, 0] = 0.5
    cert = cm.certify_invariant(_model(n, 1.0, -1.0), S, K, eps=0.5, progress=False)
    assert cert.proved is True
    assert "proven" in cert.details["domain"]


def test_translated_three_dimensional_sliver_is_not_proved() -> None:
    # nearly parallel rows, translated far from the origin; the law exceeds U.hi at a vertex
    V = np.array([[0.9009273926518706, -0.7116807745607325, 1.8972988942744877],
                  [0.9009270163147747, -0.7116809279078345, 1.8972995496796754],
                  [0.9009273936437444, -0.7116807840095503, 1.89729889934475]])
    c = np.array([76.28662643855644, -340.5365670018157, 576.8574068568087])
    S = cm.Polytope(np.vstack([V, -V]), np.concatenate([V @ c + 1, -(V @ c - 1)]))
    lo = [Fraction(float(v)) - 1 for v in V @ c]
    hi = [Fraction(float(v)) + 1 for v in V @ c]
    M = [[Fraction(float(a)) for a in row] for row in V]
    verts = [_solve(M, [h if s else low for s, low, h in zip(bits, lo, hi, strict=True)])
             for bits in itertools.product((0, 1), repeat=3)]
    top = max(v[0] for v in verts)
    U_hi = 37610034.41448195
    assert top > Fraction(U_hi)
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=0.5 * x + 0.5 * c, X=cm.Box([-1e12] * 3, [1e12] * 3),
                     U=cm.Box([-1e9], [U_hi]))
    cert = cm.certify_invariant(model, S, np.array([[1.0, 0.0, 0.0]]), eps=1e7,
                                max_boxes=3000, time_limit=10, progress=False)
    _check(cert, S, Fraction(U_hi))
