"""Natural and centered enclosures of one Euler step of the CSTR.

Scaled coordinates: x = [C_A - 0.5, (T - 350) / 100], u = (T_c - 300) / 100, dt = 0.03 min.
The true successors are computed exactly (mpmath, 300 bits) from the instruction list of
``model.function``; the true range over a box is estimated from the inside by a dense grid
including the corners.
"""

from __future__ import annotations

import casadi as ca
import mp_reference as R
import mpmath
import numpy as np
import pytest

import casadi_cmpc as cm

Q, V, CAF, TF, RHO, CP, DH, E_R, K0, UA = (
    100.0, 100.0, 1.0, 350.0, 1000.0, 0.239, -5e4, 8750.0, 7.2e10, 5e4)

CENTERS = np.array([[0.0, 0.0, 0.0], [0.2, -0.1, 0.1], [-0.3, 0.2, -0.2], [0.4, 0.4, 0.3],
                    [-0.4, -0.4, -0.4], [0.1, -0.05, 0.05]])


@pytest.fixture(scope="module")
def model():
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    ca_ = x[0] + 0.5
    t = 350.0 + 100.0 * x[1]
    tc = 300.0 + 100.0 * u
    rate = K0 * ca.exp(-E_R / t) * ca_
    dca = Q / V * (CAF - ca_) - rate
    dt_ = Q / V * (TF - t) + (-DH) / (RHO * CP) * rate + UA / (V * RHO * CP) * (tc - t)
    return cm.Model.from_ode(x=x, u=u, rhs=ca.vertcat(dca, dt_ / 100.0), dt=0.03,
                             X=cm.Box([-0.5, -0.5], [0.5, 0.5]), U=cm.Box([-0.5], [0.5]),
                             name="cstr")


def _boxes(centers, width):
    """(N, 3) centers -> X (N, 2, 2), U (N, 1, 2) boxes of the given width."""
    c = np.atleast_2d(centers)
    b = np.stack([c - width / 2, c + width / 2], axis=-1)
    return b[:, :2], b[:, 2:]


def _grid(center, width, k=9):
    g = np.linspace(-0.5, 0.5, k)
    G = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    return np.asarray(center) + width * G  # includes the 8 corners


def _exact_successor(model, pt):
    """Exact successor of the model's graph at a float point (x0, x1, u)."""
    return R.eval_function(model.function, [[pt[0], pt[1]], [pt[2]], []])[0]


def _formula_successor(pt):
    """The Euler step of the CSTR equations, evaluated directly in mpmath."""
    x0, x1, u = (R.F(v) for v in pt)
    c_a, t, tc = x0 + 0.5, 350 + 100 * x1, 300 + 100 * u
    rate = R.F(K0) * mpmath.exp(-R.F(E_R) / t) * c_a
    dca = R.F(Q) / R.F(V) * (R.F(CAF) - c_a) - rate
    dt_ = (R.F(Q) / R.F(V) * (R.F(TF) - t) + (-R.F(DH)) / (R.F(RHO) * R.F(CP)) * rate
           + R.F(UA) / (R.F(V) * R.F(RHO) * R.F(CP)) * (tc - t))
    return [x0 + R.F(0.03) * dca, x1 + R.F(0.03) * dt_ / 100]


def _width(b):
    return b[..., 1] - b[..., 0]


def test_centered_is_tighter_on_small_boxes(model):
    X, U = _boxes(CENTERS, 0.01)
    nat = model.inclusion("natural")(X, U)
    cen = model.inclusion("centered")(X, U)
    assert nat.shape == cen.shape == (len(CENTERS), 2, 2)
    assert np.all(np.isfinite(nat)) and np.all(np.isfinite(cen))
    assert np.all(cen[..., 0] >= nat[..., 0]) and np.all(cen[..., 1] <= nat[..., 1])
    wn, wc = _width(nat).sum(axis=1), _width(cen).sum(axis=1)
    assert np.all(wc < 0.97 * wn), (wc, wn)
    assert wc.sum() < 0.9 * wn.sum()


def _slope(r, excess):
    return float(np.polyfit(np.log(r), np.log(excess), 1)[0])


@pytest.mark.parametrize("center", [CENTERS[5], CENTERS[2]])
def test_excess_width_orders(model, center):
    """Excess width over the true range: O(r^2) for centered, O(r) for natural."""
    Fn, Fc = model.inclusion("natural"), model.inclusion("centered")
    rs = 0.1 * 2.0 ** -np.arange(7)
    ex_n, ex_c = [], []
    for r in rs:
        X, U = _boxes(center, r)
        pts = _grid(center, r)
        y = model.step(pts[:, :2], pts[:, 2:])
        inner = y.max(axis=0) - y.min(axis=0)  # inside the true range
        wn, wc = _width(Fn(X, U)[0]), _width(Fc(X, U)[0])
        assert np.all(wn >= inner) and np.all(wc >= inner)
        ex_n.append(wn - inner)
        ex_c.append(wc - inner)
    ex_n, ex_c = np.array(ex_n), np.array(ex_c)
    assert np.all(ex_n > 0) and np.all(ex_c > 0)
    for i in range(2):
        sn, sc = _slope(rs, ex_n[:, i]), _slope(rs, ex_c[:, i])
        assert 0.8 < sn < 1.3, (i, sn)
        assert sc > 1.7, (i, sc)
        # and at the smallest box the centered excess is far below the natural one
        assert ex_c[-1, i] < 0.05 * ex_n[-1, i]


@pytest.mark.parametrize("width", [0.3, 0.01, 1e-4])
def test_true_successors_inside_both_enclosures(model, width):
    rng = np.random.default_rng(int(width * 1e4))
    X, U = _boxes(CENTERS, width)
    encs = [model.inclusion("natural")(X, U), model.inclusion("centered")(X, U)]
    for b, c in enumerate(CENTERS):
        pts = np.vstack([_grid(c, width, k=2), c + width * (rng.random((12, 3)) - 0.5)])
        pts = np.clip(pts, np.hstack([X[b, :, 0], U[b, :, 0]]),
                      np.hstack([X[b, :, 1], U[b, :, 1]]))
        for pt in pts:
            y = _exact_successor(model, pt)
            for yi, zi in zip(y, _formula_successor(pt), strict=True):  # it is the CSTR
                assert abs(yi - zi) <= 1e-12 * (1 + abs(zi))
            for enc in encs:
                for i in range(2):
                    assert R.inside(enc[b, i, 0], enc[b, i, 1], y[i]), (width, pt, i, enc[b])


def test_model_boxes_are_the_defaults(model):
    X = model.X.as_array()[None]
    U = model.U.as_array()[None]
    for kind in ("natural", "centered"):
        F = model.inclusion(kind)
        np.testing.assert_array_equal(F(X), F(X, U))
        assert F(X).shape == (1, 2, 2)


@pytest.mark.parametrize("wrt", ["x", "u"])
@pytest.mark.parametrize("width", [0.2, 0.01])
def test_jacobian_inclusion_contains_the_jacobian(model, wrt, width):
    d = 2 if wrt == "x" else 1
    J = model.jacobian_inclusion(wrt)
    jf = model.jacobian_function(wrt)
    X, U = _boxes(CENTERS, width)
    enc = J(X, U)
    assert enc.shape == (len(CENTERS), 2, d, 2)
    assert np.all(np.isfinite(enc))
    rng = np.random.default_rng(3)
    for b, c in enumerate(CENTERS):
        for pt in np.vstack([_grid(c, width, k=2), c + width * (rng.random((6, 3)) - 0.5)]):
            exact = R.eval_function(jf, [[pt[0], pt[1]], [pt[2]], []])[0]  # column-major
            num = np.array(jf(pt[:2], pt[2], np.zeros(0)))
            for i in range(2):
                for j in range(d):
                    lo, hi = enc[b, i, j]
                    assert R.inside(lo, hi, exact[j * 2 + i]), (wrt, pt, i, j)
                    tol = 1e-12 * max(1.0, abs(num[i, j]))
                    assert lo - tol <= num[i, j] <= hi + tol, (wrt, pt, i, j)
    # the enclosure is not trivially wide on small boxes
    if width == 0.01:
        assert np.all(_width(enc) < 0.1 * (1.0 + np.abs(enc[..., 0])))


@pytest.mark.parametrize("kind", ["natural", "centered"])
def test_model_inclusion_encloses_the_user_expression(kind):
    x = ca.SX.sym("x")
    f = ca.fmax(x, ca.atan(0.5 + (ca.exp(ca.sin(x)) - ca.exp(ca.sin(x)))))  # = atan(0.5)
    m = cm.Model(x=x, u=None, f=f, X=cm.Box([0.0], [0.1]))
    direct = cm.interval.inclusion(ca.Function("f", [x], [f]), kind)(np.array([[[0.0, 0.1]]]))
    exact = R.atan(R.F(0.5))
    assert R.inside(direct[0][0, 0, 0], direct[0][0, 0, 1], exact)  # the compiler is sound
    enc = m.inclusion(kind)(np.array([[[0.0, 0.1]]]))
    assert R.inside(enc[0, 0, 0], enc[0, 0, 1], exact)
