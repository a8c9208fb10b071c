"""Reachable-set bounds (thesis Def 6.2, Fig 6.10) and quasi multi-step robust controllable
sets (Def 6.1, Alg 6.7, §6.3.4) on E12 and on a 3-state model with two inputs."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.control.quasi import (
    QuasiSet,
    quasi_controllable_set,
    quasi_controllable_sets,
    quasi_step_comparison,
)
from casadi_cmpc.exceptions import DimensionError, ModelError
from casadi_cmpc.sets._reach import reach


@pytest.fixture(scope="module")
def e12(e12_example):
    return e12_example  # loaded once per session (tests/conftest.py)


@pytest.fixture(scope="module")
def k2(e12):
    return quasi_controllable_set(e12.model, e12.terminal, steps=2, eps=0.1)


def _three_state():
    """x+ = g(x, w) + B u with n = 3, m = 2, l = 1 (not from the thesis)."""
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u", 2)
    w = ca.SX.sym("w")
    f = ca.vertcat(x[0] + 0.1 * x[1] + 0.02 * ca.sin(x[2]),
                   x[1] + 0.1 * (x[0] ** 2 + u[0]),
                   x[2] + 0.1 * (u[1] - x[1] * x[2]) + w)
    return cm.Model(x=x, u=u, w=w, f=f, X=cm.Box([-1, -1, -1], [1, 1, 1]),
                    U=cm.Box([-2, -2], [2, 2]), W=cm.Box([-0.01], [0.01]), name="three_state")


def _w_sequences(model, steps, k, rng):
    """k disturbance sequences (k, steps, l): vertex sequences and uniform draws."""
    lo, hi = model.W.lo, model.W.hi
    out = []
    for s in range(k):
        if s % 2 == 0:
            pick = rng.integers(0, 2, size=(steps, model.l))
            out.append(np.where(pick == 1, hi, lo))
        else:
            out.append(rng.uniform(lo, hi, size=(steps, model.l)))
    return np.asarray(out)


def _sample_boxes(boxes, per_box, rng):
    """Corners and random points of every box: (N, c, n)."""
    N, n, _ = boxes.shape
    corners = np.array(np.meshgrid(*[[0, 1]] * n, indexing="ij")).reshape(n, -1).T
    pts = [boxes[:, np.arange(n), c] for c in corners]  # each (N, n)
    for _ in range(per_box):
        pts.append(rng.uniform(boxes[..., 0], boxes[..., 1]))
    return np.stack(pts, axis=1)


def _check_inner_by_simulation(model, res: QuasiSet, rng, per_box=4, n_w=4):
    """Every sampled start of every inner box, under sampled disturbance sequences, stays in
    X before its arrival and lies in the target at arrival (stored sequences only)."""
    I = np.asarray(res.inner)
    assert I.shape[0] > 0
    X, T = model.X, res.target
    pts = _sample_boxes(I, per_box, rng)  # (N, c, n)
    N, c, n = pts.shape
    for wseq in _w_sequences(model, res.steps, n_w, rng):
        x = pts.reshape(-1, n)
        arr = np.repeat(res.arrival, c)
        u_all = np.repeat(res.controls, c, axis=0)  # (N c, steps, m)
        for k in range(res.steps):
            active = arr > k
            if not active.any():
                break
            if k > 0:
                assert np.all(X.contains(x[active])), "a state left X before arrival"
            xn = model.step(x[active], u_all[active, k], wseq[k])
            x = x.copy()
            x[active] = xn
            arrived = arr == k + 1
            assert np.all(T.contains(x[arrived])), "a state missed the target at arrival"
        assert np.all(np.isfinite(res.controls[np.arange(N), res.arrival - 1]))


# ----------------------------------------------------------------------------- reach
def test_reach_zonotope_boxes_inside_interval_boxes_and_contain_trajectories(e12):
    """Fig 6.10 setting: a subbox of X under a fixed 4-step control sequence."""
    model = e12.model
    X0 = cm.Box([-0.45, 0.05], [-0.3, 0.2])
    useq = np.array([[-1.0], [0.5], [1.5], [-2.0]])
    Z = reach(model, X0, useq)
    Zp = reach(model, X0, useq, refine=False)
    I = reach(model, X0, useq, method="interval")
    assert len(Z) == len(I) == len(Zp) == 5
    rng = np.random.default_rng(3)
    x = X0.sample(300, seed=4)
    x = np.vstack([x, X0.vertices()])
    for k in range(4):
        w = np.column_stack([rng.uniform(-0.01, 0.01, x.shape[0]),
                             rng.choice([0.9, 1.0, 0.95], x.shape[0])])
        x = model.step(x, useq[k], w)
        bz, bi = Z[k + 1].bounding_box(), I[k + 1]
        # never larger, up to the outward rounding of the zonotope's own mid/radius
        tol = 4 * np.spacing(np.maximum(np.abs(bi.lo), np.abs(bi.hi)))
        assert np.all(bz.lo >= bi.lo - tol) and np.all(bz.hi <= bi.hi + tol)
        assert np.all(bi.contains(x))
        assert np.all(Z[k + 1].contains(x)) and np.all(Zp[k + 1].contains(x))


def test_reach_three_states_and_control_boxes():
    model = _three_state()
    X0 = cm.Box([0.1, -0.2, 0.3], [0.2, -0.1, 0.4])
    Ub = [model.U] * 3
    Z = reach(model, X0, Ub, max_order=3)
    assert all(z.n_generators <= 9 for z in Z[1:])
    rng = np.random.default_rng(0)
    x = X0.sample(200, seed=1)
    for k in range(3):
        u = rng.uniform(-2, 2, (x.shape[0], 2))
        x = model.step(x, u, rng.uniform(-0.01, 0.01, (x.shape[0], 1)))
        assert np.all(Z[k + 1].contains(x))


def test_reach_refuses_bad_input(e12):
    model = e12.model
    with pytest.raises(ValueError):
        reach(model, cm.Box([0, 0], [0.1, 0.1]), [[0.0]], method="taylor")
    with pytest.raises(DimensionError):
        reach(model, cm.Box([0, 0], [0.1, 0.1]), np.zeros((2, 3)))
    with pytest.raises(DimensionError):
        reach(model, cm.Box([0, 0, 0], [0.1, 0.1, 0.1]), [[0.0]])
    with pytest.raises(ValueError):
        reach(model, cm.Box([0, 0], [0.1, 0.1]), np.zeros((0, 1)))


# ----------------------------------------------------------------------------- Alg 6.7
def test_e12_quasi_two_step_inner_boxes_verified_by_simulation(e12, k2):
    assert isinstance(k2, QuasiSet) and k2.success
    assert k2.controls.shape == (k2.n_inner, 2, 1)
    assert set(np.unique(k2.arrival)) <= {1, 2} and 2 in k2.arrival
    # early exit: a sequence that arrives at step 1 stores no second control
    assert np.all(np.isnan(k2.controls[k2.arrival == 1, 1]))
    assert np.all(np.abs(k2.controls[~np.isnan(k2.controls)]) <= 3.0)
    assert "robust" in k2.semantics and "khalil_affine_control" in k2.semantics
    assert "quasi 2-step" in k2.message
    _check_inner_by_simulation(e12.model, k2, np.random.default_rng(0))


def test_e12_outside_boxes_reach_no_target(e12, k2):
    """A box proven outside is missed at steps 1 and 2 by every control sequence."""
    model, T = e12.model, e12.terminal
    O = np.asarray(k2.outside)
    assert O.shape[0] > 0
    rng = np.random.default_rng(1)
    x0 = _sample_boxes(O, 2, rng).reshape(-1, 2)
    for _ in range(6):
        u = rng.choice([-3.0, 3.0, 0.0, rng.uniform(-3, 3)], size=(2, 1))
        x = x0
        for k in range(2):
            x = model.step(x, u[k], [rng.uniform(-0.01, 0.01), rng.uniform(0.9, 1.0)])
            assert not np.any(T.contains(x))


def test_quasi_two_step_larger_than_one_step_and_control_lookup(e12, k2):
    k1 = quasi_controllable_set(e12.model, e12.terminal, steps=1, eps=0.1)
    assert k2.area() > k1.area() > 0
    x = k2.inner[0].mean(axis=1)
    seq = k2.control_sequence(x)
    assert seq is not None and seq.shape[1] == 1 and 1 <= seq.shape[0] <= 2
    assert k2.control_sequence([5.0, 5.0]) is None


def test_three_state_model_two_inputs():
    model = _three_state()
    T = cm.Polytope.from_box(cm.Box([-0.5] * 3, [0.5] * 3))
    res = quasi_controllable_set(model, T, steps=2, eps=0.25)
    assert res.n_inner > 0 and res.controls.shape[1:] == (2, 2)
    _check_inner_by_simulation(model, res, np.random.default_rng(2), per_box=2, n_w=2)


def test_refused_bad_input(e12):
    model, T = e12.model, e12.terminal
    with pytest.raises(ValueError):
        quasi_controllable_set(model, T, steps=0, eps=0.1)
    with pytest.raises(TypeError):
        quasi_controllable_set(model, T, steps=1.5, eps=0.1)
    with pytest.raises(ValueError):
        quasi_controllable_set(model, T, steps=2, eps=0.0)
    with pytest.raises(DimensionError):
        quasi_controllable_set(model, cm.Polytope.from_box(cm.Box([-1] * 3, [1] * 3)),
                               steps=2, eps=0.1)
    with pytest.raises(TypeError):
        quasi_controllable_set(model, [T], steps=2, eps=0.1)
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    bilinear = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * x[0] * u),
                        X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))
    with pytest.raises(ModelError, match="affine control part"):
        quasi_controllable_set(bilinear, T, steps=2, eps=0.1)
    auto = cm.Model(x=x, u=ca.SX.sym("u", 0), f=0.5 * x, X=cm.Box([-1, -1], [1, 1]),
                    U=None)
    with pytest.raises(ModelError):
        quasi_controllable_set(auto, T, steps=2, eps=0.1)


def test_budget_stop_is_sound(e12):
    res = quasi_controllable_set(e12.model, e12.terminal, steps=2, eps=0.01, max_boxes=200)
    assert res.status == cm.Status.BUDGET and not res.success
    if res.n_inner:
        _check_inner_by_simulation(e12.model, res, np.random.default_rng(5), per_box=1, n_w=2)


# ----------------------------------------------------------------------------- §6.3.4
def test_recursion_polytopes_lie_in_their_quasi_sets(e12):
    seq = quasi_controllable_sets(e12.model, e12.terminal, steps=2, eps=0.1, max_sets=3)
    assert len(seq.polytopes) >= 2 and seq.polytopes[0] is not None
    rng = np.random.default_rng(6)
    for m in range(1, len(seq.polytopes)):
        P, res = seq.polytopes[m], seq.results[m - 1]
        bb = P.bounding_box()
        pts = rng.uniform(bb.lo, bb.hi, (4000, 2))
        pts = pts[P.contains(pts)]
        assert pts.shape[0] > 0 and np.all(res.contains(pts))
        assert res.target is seq.polytopes[m - 1]
    assert seq.level(np.zeros(2)) == 0
    assert seq.level([5.0, 5.0]) is None


def test_fig_6_13_comparison_data(e12):
    data = quasi_step_comparison(e12.model, e12.terminal, eps=0.1, steps=2)
    assert data["complete_one_step"]
    assert len(data["one_step"]) == 2
    r2, P2 = data["multi_step"]
    assert r2.steps == 2 and P2 is not None
    assert data["area_multi_step"] > 0 and data["poly_area_multi_step"] > 0
    assert data["seconds_multi_step"] > 0


def test_terminal_set_proven_invariant_by_its_quasi_one_step_set(e12):
    from casadi_cmpc.control.quasi import quasi_invariance

    cert = quasi_invariance(e12.model, e12.terminal, eps=0.02)
    assert cert.proved is True and cert.label == "proved"
    cover = cert.details["cover"]
    # every sampled state of T lies in a cover box whose control keeps it in T for all w
    T = e12.terminal
    bb = T.bounding_box()
    rng = np.random.default_rng(8)
    pts = rng.uniform(bb.lo, bb.hi, (3000, 2))
    pts = pts[T.contains(pts)]
    for x in pts[:300]:
        k = cover.box_index(x)
        assert k is not None
        for w in ([0.01, 1.0], [-0.01, 0.9], [0.0, 0.95]):
            assert T.contains(e12.model.step(x, cover.controls[k, 0], w))
    # too coarse: not proven, and said so
    coarse = quasi_invariance(e12.model, e12.terminal, eps=0.2)
    assert coarse.proved is None and coarse.label == "undecided"


# ----------------------------------------------------------------------------- engine
class _CountingPool:
    """A process pool that counts the tasks it was given."""

    def __init__(self, n: int) -> None:
        from concurrent.futures import ProcessPoolExecutor

        self.pool = ProcessPoolExecutor(n)
        self._max_workers = n
        self.tasks = 0

    def submit(self, *a, **k):
        self.tasks += 1
        return self.pool.submit(*a, **k)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.pool.shutdown()


def test_quasi_set_on_a_process_pool_is_the_serial_one(e12, monkeypatch):
    """The search runs on the engine: with an executor, the same boxes in the same order,
    the same control sequences and arrival steps, statuses and counts as serially; and
    work really went to the workers."""
    from casadi_cmpc.solvers import _parallel

    monkeypatch.setattr(_parallel, "SUBTREE_MIN_S", 0.0)
    a = quasi_controllable_set(e12.model, e12.terminal, steps=2, eps=0.05, progress=False)
    with _CountingPool(2) as pool:
        b = quasi_controllable_set(e12.model, e12.terminal, steps=2, eps=0.05,
                                   progress=False, executor=pool)
        assert pool.tasks > 0
    for v in ("inner", "boundary", "outside"):
        assert np.array_equal(getattr(a.paving, v), getattr(b.paving, v))
    assert np.array_equal(a.controls, b.controls, equal_nan=True)
    assert np.array_equal(a.arrival, b.arrival) and a.arrival.shape[0] == a.n_inner > 0
    assert (a.status, a.nit, a.n_boxes, a.history) == (b.status, b.nit, b.n_boxes, b.history)
    assert sum(h["boxes"] for h in a.history) == a.n_boxes
    _check_inner_by_simulation(e12.model, b, np.random.default_rng(7), per_box=1, n_w=2)


def test_quasi_several_inputs_on_workers_warns_and_stays_sound():
    """With two inputs the LP may break ties differently per batch: a warning, and every
    inner box still proven (checked by simulation)."""
    from concurrent.futures import ProcessPoolExecutor

    model = _three_state()
    T = cm.Polytope.from_box(cm.Box([-0.5] * 3, [0.5] * 3))
    with ProcessPoolExecutor(2) as pool, pytest.warns(cm.CmpcWarning, match="several inputs"):
        res = quasi_controllable_set(model, T, steps=2, eps=0.25, executor=pool,
                                     progress=False)
    _check_inner_by_simulation(model, res, np.random.default_rng(4), per_box=2, n_w=2)


def test_quasi_status_says_what_was_proven(e12):
    """A completed search that proves no box is not PROVED: UNDECIDED while boxes are
    undecided (eps too coarse to bisect), DISPROVED when every box is outside."""
    res = quasi_controllable_set(e12.model, e12.terminal, steps=1, eps=100.0, progress=False)
    assert res.n_inner == 0 and res.paving.n_boundary == 1
    assert res.status == cm.Status.UNDECIDED and not res.success
    far = cm.Polytope.from_box(cm.Box([50.0, 50.0], [51.0, 51.0]))
    X = cm.Box([-0.1, -0.1], [0.1, 0.1])
    res = quasi_controllable_set(e12.model, far, steps=1, eps=0.05, X=X, progress=False)
    assert res.n_inner == 0 and res.paving.n_boundary == 0
    assert res.status == cm.Status.DISPROVED
