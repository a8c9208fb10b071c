"""The cart-pole's robust one-step set (4 states: p, v linear; theta, omega nonlinear).

The set is searched by the affine-state method in the bounding box of the certified
terminal set T at a coarse eps (relative 0.05 of that box). Checked here:

* the pieces are proven (status PROVED) and hold points outside T;
* sampled points of the pieces, with their stored control, are sent into T for sampled w,
  decided rigorously: the outward-rounded interval image of the point is inside T (exact
  polytope test), for the extreme and sampled disturbances;
* 200 closed loops (stored control on the first step, then the local law u = K x) under
  uniformly drawn disturbance sequences stay in X, use controls of U, and enter and stay
  in T.
"""

from __future__ import annotations

import numpy as np
import pytest

import casadi_cmpc as cm


@pytest.fixture(scope="module")
def cartpole():
    ex = cm.models.load("cartpole")
    D = ex.terminal.bounding_box()
    res = cm.one_step_set(ex.model, ex.terminal, 0.05, robust=True, X=D, relative=True,
                          progress=False)
    return ex, res


def _points(res, n_pieces: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One point drawn in each of ``n_pieces`` random pieces (rejection from the piece's
    bounding box), and the piece index of each point."""
    pts, idx = [], []
    for j in rng.choice(len(res.pieces), size=n_pieces, replace=False):
        P = res.pieces.polytopes[j]
        bb = P.bounding_box()
        X = bb.lo + rng.random((64, bb.dim)) * (bb.hi - bb.lo)
        ok = np.flatnonzero(P.contains(X))
        if ok.size:
            pts.append(X[ok[0]])
            idx.append(j)
    return np.asarray(pts), np.asarray(idx)


def test_cartpole_robust_one_step_set_is_proven_beyond_the_target(cartpole):
    ex, res = cartpole
    assert res.status == cm.Status.PROVED
    assert res.method.startswith("affine state")  # p and v enter f linearly
    assert ex.model.nonlinear_states == (2, 3) and ex.model.linear_states == (0, 1)
    assert "every w in W" in res.message and "cartpole" in res.message
    assert len(res.pieces) > 100 and res.witness.shape == (len(res.pieces), 1)
    assert np.all(np.abs(res.witness) <= 10.0)
    # states outside T are proven to reach it: points of the pieces outside T
    X, _ = _points(res, 400, np.random.default_rng(3))
    assert (~ex.terminal.contains(X)).sum() > 20


def test_cartpole_pieces_send_sampled_points_into_the_target_rigorously(cartpole):
    ex, res = cartpole
    m, T = ex.model, ex.terminal
    rng = np.random.default_rng(0)
    X, k = _points(res, 300, rng)
    assert X.shape[0] > 250
    U = res.witness[k]
    F = m.inclusion("natural")
    thin = lambda P: np.stack([P, P], axis=-1)  # noqa: E731
    ws = np.concatenate([m.W.lo, m.W.hi, [0.0], rng.uniform(m.W.lo[0], m.W.hi[0], 5)])
    for w in ws:
        Wb = np.full((X.shape[0], 1, 2), w)
        Y = np.asarray(F(thin(X), thin(U), Wb))  # (N, 4, 2): encloses the RK4 successor
        assert np.isfinite(Y).all()
        assert T.contains_box(Y).all(), f"an image leaves T at w = {w}"


def test_cartpole_closed_loops_from_the_one_step_set_have_no_violation(cartpole):
    ex, res = cartpole
    m, T, law = ex.model, ex.terminal, ex.local_law
    rng = np.random.default_rng(1)
    X0, k = _points(res, 260, rng)
    X0, k = X0[:200], k[:200]
    assert X0.shape[0] == 200
    tol = 1e-9 * (1.0 + np.abs(T.b).max())  # float simulation of the exact map
    for i, (x0, j) in enumerate(zip(X0, k, strict=True)):
        u0 = res.witness[j]
        w0 = rng.uniform(m.W.lo, m.W.hi)
        x1 = m.step(x0, u0, w0)
        assert T.contains(x1[None], tol=tol).all(), f"run {i}: the first step misses T"
        traj = cm.simulate(m, law, x1, 30, disturbance="uniform", seed=i, progress=False)
        assert T.contains(traj.x, tol=tol).all(), f"run {i} leaves T"
        assert m.X.contains(traj.x).all() and m.U.contains(traj.u).all()
        assert np.all(np.abs(traj.w) <= m.W.hi)
