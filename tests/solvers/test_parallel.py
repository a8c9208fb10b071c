"""A branch-and-bound level classified on an executor, or a search cut into parts, gives
the serial outcome: the same boxes in the same order, for the set searches of the library,
with a process pool and with a Dask cluster; a dying worker loses no box, a failing
classifier fails the run."""

from __future__ import annotations

import os
import pickle
import warnings
from concurrent.futures import Executor, ProcessPoolExecutor

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.interval import InclusionFunction
from casadi_cmpc.solvers import _parallel, engine
from casadi_cmpc.solvers.engine import (
    INNER,
    OUTER,
    UNDECIDED,
    BoxFrontier,
    branch_and_bound,
)


class _Counting(Executor):
    """An executor that counts the tasks it passes on (the levels did go to the pool)."""

    def __init__(self, inner: Executor) -> None:
        self.inner, self.n, self.parts, self.proofs = inner, 0, 0, 0
        self._max_workers = 2

    def submit(self, fn, /, *args, **kwargs):
        from casadi_cmpc.control.controllable import _prove_terminal_task

        self.n += 1
        self.parts += fn is _parallel._subtree  # a part of a search cut at its split level
        self.proofs += fn is _prove_terminal_task  # T's proof beside the first steps
        return self.inner.submit(fn, *args, **kwargs)


@pytest.fixture(scope="module")
def process_pool():
    with ProcessPoolExecutor(2) as ex:
        yield ex


@pytest.fixture()
def pool(process_pool):
    ex = _Counting(process_pool)
    yield ex
    assert ex.n > 0  # some level of every search was cut into tasks


@pytest.fixture(autouse=True)
def small_tasks(monkeypatch):
    """Tiny tasks: the small searches of these tests are cut in chunks."""
    monkeypatch.setattr(_parallel, "TARGET_S", 1e-6)
    monkeypatch.setattr(_parallel, "MIN_CHUNK", 16)


def _same_paving(a, b) -> bool:
    return all(np.array_equal(getattr(a, k), getattr(b, k))
               for k in ("inner", "boundary", "outside"))


def _three_state() -> tuple[cm.Model, cm.Polytope]:
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * (u + 0.5 * x[0] * x[0] + 0.2 * x[2]),
                   0.7 * x[2] + 0.1 * x[0] ** 2 + 0.1 * x[1])
    m = cm.Model(x=x, u=u, f=f, X=cm.Box([-1] * 3, [1] * 3), U=cm.Box([-2], [2]))
    return m, cm.Polytope.from_box(cm.Box([-0.4] * 3, [0.4] * 3))


def test_one_step_set_on_a_process_pool_equals_the_serial_run(pool):
    m, T = _three_state()
    A = cm.one_step_set(m, T, 0.1, method="general", progress=False)
    B = cm.one_step_set(m, T, 0.1, method="general", progress=False, executor=pool)
    assert A.paving.n_inner > 0 and _same_paving(A.paving, B.paving)
    assert np.array_equal(A.witness, B.witness)  # the proving controls came back in order
    assert A.n_pairs == B.n_pairs


def test_sivia_and_its_component_classifier_on_a_pool(pool):
    p = ca.SX.sym("p", 2)
    f = ca.Function("routh", [p], [ca.vertcat(p[0] + p[1] + 2, (p[0] - 1) ** 2
                                              + (p[1] - 1) ** 2 - 1,
                                              2 * (p[0] + 3) * (p[1] + 3) - 15)])
    X0, Y = cm.Box([-3, -3], [9, 9]), cm.Box([0, 0, 0], [np.inf] * 3)
    A = cm.sivia(f, X0, Y, eps=0.02, open_target=True, progress=False)
    B = cm.sivia(f, X0, Y, eps=0.02, open_target=True, progress=False, executor=pool)
    assert A.paving.n_inner > 100 and _same_paving(A.paving, B.paving)
    with pytest.raises(ValueError, match="contract"):
        cm.sivia(f, X0, Y, eps=0.1, contract=True, executor=pool)


def test_certify_invariant_on_a_pool_gives_the_serial_certificate(pool):
    ex = cm.models.load("cannon")
    S = ex.terminal
    law = ex.local_law
    a = cm.certify_invariant(ex.model, S, law, 0.02, progress=False)
    b = cm.certify_invariant(ex.model, S, law, 0.02, progress=False, executor=pool)
    assert a.label == b.label and a.proved == b.proved
    for k in ("state set", "input bound"):
        if k in a.details:
            assert a.details[k]["inner"] == b.details[k]["inner"]
            assert a.details[k]["boundary"] == b.details[k]["boundary"]


class _Halves:
    """Labels boxes by their lower bound; exits its process when run in a worker the first
    time (a crashed worker)."""

    def __init__(self, die: bool) -> None:
        self.die = die

    def __call__(self, fr: BoxFrontier) -> np.ndarray:
        import multiprocessing

        if self.die and multiprocessing.parent_process() is not None:
            os._exit(3)
        lab = np.full(len(fr), UNDECIDED, dtype=np.int8)
        lab[fr.hi[:, 0] < 0.3] = OUTER
        lab[fr.lo[:, 0] > 0.7] = INNER
        return lab


def test_a_dying_worker_loses_no_box():
    fr = BoxFrontier.from_boxes(np.array([[[0.0, 1.0], [0.0, 1.0]]]))
    ref = branch_and_bound(fr, _Halves(False), 0.01, progress=False)
    with ProcessPoolExecutor(2) as ex, warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        got = branch_and_bound(fr, _Halves(True), 0.01, progress=False, executor=ex)
    assert any("worker process died" in str(r.message) for r in rec)
    for k in ("inner", "boundary", "outer"):
        assert np.array_equal(getattr(ref, k).boxes, getattr(got, k).boxes)


def _fails(fr: BoxFrontier) -> np.ndarray:
    import multiprocessing

    if multiprocessing.parent_process() is not None:  # in a worker
        raise ValueError("classifier failure")
    return np.zeros(len(fr), dtype=np.int8)


def test_a_failing_classifier_fails_the_run(pool):
    fr = BoxFrontier.from_boxes(np.array([[[0.0, 1.0], [0.0, 1.0]]]))
    with pytest.raises(ValueError, match="classifier failure"):
        branch_and_bound(fr, _fails, 0.01, progress=False, executor=pool)
    with pytest.raises(TypeError, match="executor"):
        branch_and_bound(fr, _fails, 0.1, progress=False, executor=object())


def test_inclusion_functions_travel_as_their_graph():
    m = cm.models.load("cstr").model
    rng = np.random.default_rng(3)
    c = rng.uniform(m.X.lo, m.X.hi, (50, 2))
    X = np.stack([c - 0.01, c + 0.01], -1)
    U, W = np.array([[[-0.1, 0.1]]]), np.zeros((1, 0, 2))
    for kind in ("natural", "centered"):
        F = InclusionFunction(m.function, kind)
        G = pickle.loads(pickle.dumps(F))
        assert G.kind == kind and np.array_equal(F(X, U, W)[0], G(X, U, W)[0])
        assert pickle.loads(pickle.dumps(F)) is G  # rebuilt once per process


def test_sivia_on_a_dask_cluster_equals_the_serial_run():
    distributed = pytest.importorskip("distributed")
    p = ca.SX.sym("p", 2)
    g = ca.Function("disk", [p], [p[0] ** 2 + p[1] ** 2])
    A = cm.sivia(g, cm.Box([-2, -2], [2, 2]), cm.Box([0], [1]), eps=0.01, progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        B = cm.sivia(g, cm.Box([-2, -2], [2, 2]), cm.Box([0], [1]), eps=0.01,
                     progress=False, executor=client.get_executor())
    assert _same_paving(A.paving, B.paving)


def test_minimize_on_a_pool_equals_the_serial_run(pool):
    """The incumbent bound is a reduction over the whole level: with the bounds evaluated on
    the workers and the bound lowered in the driver, the result is the serial one."""
    x = ca.SX.sym("x", 2)
    f = ca.Function("six_hump", [x], [(4 - 2.1 * x[0] ** 2 + x[0] ** 4 / 3) * x[0] ** 2
                                      + x[0] * x[1] + (-4 + 4 * x[1] ** 2) * x[1] ** 2])
    g = ca.Function("disk", [x], [x[0] ** 2 + x[1] ** 2 - 2.5])
    X0 = cm.Box([-3, -2], [3, 2])
    a = cm.minimize(f, X0, 1e-4, constraints=g, local_solver=None, progress=False)
    b = cm.minimize(f, X0, 1e-4, constraints=g, local_solver=None, progress=False,
                    executor=pool)
    assert a.lower == b.lower and a.upper == b.upper and np.array_equal(a.x, b.x)
    assert a.upper - a.lower < 1e-3 and abs(a.upper + 1.0316284534898774) < 1e-3
    assert a.n_boxes == b.n_boxes


def test_minimax_on_a_pool_equals_the_serial_run(pool):
    u = ca.SX.sym("u", 2)
    w = ca.SX.sym("w")
    f = ca.Function("f", [u, w], [(u[0] - 0.3) * w + 0.5 * u[0] + (u[1] - w) ** 2])
    g = ca.Function("g", [u, w], [u[0] + u[1] * w - 1.2])
    U, W = cm.Box([-1, -1], [1, 1]), cm.Box([-1], [1])
    a = cm.minimax(f, U, W, 1e-3, constraints=g, progress=False)
    b = cm.minimax(f, U, W, 1e-3, constraints=g, progress=False, executor=pool)
    assert a.lower == b.lower and a.upper == b.upper and np.array_equal(a.u, b.u)
    assert np.array_equal(a.candidates, b.candidates) and a.width < 1e-2


def test_quantified_sivia_through_the_modal_one_step_set_on_a_pool(pool):
    ex = cm.models.load("cannon")
    a = cm.one_step_set(ex.model, ex.terminal, 0.1, method="modal", progress=False)
    b = cm.one_step_set(ex.model, ex.terminal, 0.1, method="modal", progress=False,
                        executor=pool)
    assert a.paving.n_inner > 0 and _same_paving(a.paving, b.paving)


def test_e9_robust_sequence_is_the_same_serial_on_a_pool_and_on_dask(pool, monkeypatch):
    """The acceptance case: the E9 robust controllable sequence at eps 0.025 (the levels
    with more than 20 ms of work cut into tasks of 10 ms)."""
    monkeypatch.setattr(_parallel, "TARGET_S", 0.01)
    ex = cm.models.load("cannon_robust")

    def run(executor=None):
        seq = cm.controllable_sets(ex.model, ex.terminal, 0.025, robust=True,
                                   law=ex.local_law, progress=False, executor=executor)
        info = {k: v for k, v in seq.info.items() if k != "seconds"}
        return [s["boxes"] for s in seq.steps], [s["witness"] for s in seq.steps], info

    ref = run()
    runs = [run(pool)]
    assert pool.proofs == 1  # T was proven by a worker while the first steps ran
    assert repr(runs[0][2]) == repr(ref[2]) and ref[2]["terminal_certificate"] == "proved"
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        runs.append(run(client.get_executor()))
    for boxes, wit, _ in runs:
        assert len(boxes) == len(ref[0]) > 10
        assert all(np.array_equal(a, b) for a, b in zip(boxes, ref[0], strict=True))
        assert all(np.array_equal(a, b, equal_nan=True)
                   for a, b in zip(wit, ref[1], strict=True))


class _BreaksAtSubmit(Executor):
    """A pool that breaks after its first task: later submissions raise BrokenProcessPool
    (as a ProcessPoolExecutor does once a worker has died)."""

    def __init__(self, inner: Executor) -> None:
        self.inner, self.n, self._max_workers = inner, 0, 2

    def submit(self, fn, /, *args, **kwargs):
        from concurrent.futures.process import BrokenProcessPool

        self.n += 1
        if self.n > 1:
            raise BrokenProcessPool("a worker died")
        return self.inner.submit(fn, *args, **kwargs)


def test_a_pool_broken_between_submissions_loses_no_box(process_pool):
    fr = BoxFrontier.from_boxes(np.array([[[0.0, 1.0], [0.0, 1.0]]]))
    ref = branch_and_bound(fr, _Halves(False), 0.01, progress=False)
    ex = _BreaksAtSubmit(process_pool)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        got = branch_and_bound(fr, _Halves(False), 0.01, progress=False, executor=ex)
    assert ex.n > 1 and any("worker process died" in str(r.message) for r in rec)
    for k in ("inner", "boundary", "outer"):
        assert np.array_equal(getattr(ref, k).boxes, getattr(got, k).boxes)


# ---------------------------------------------------------------- parts of a search
# A search cut into parts at its split level (one part per worker for the rest of the
# search, the first in the driver) gives the serial outcome: the same boxes in the same
# order, the same proving controls, the same budget stop; a worker dying in its part loses
# no box.


@pytest.fixture()
def always_cut(monkeypatch):
    """Every search of the test is cut at its split level, whatever its work."""
    monkeypatch.setattr(_parallel, "SUBTREE_MIN_S", 0.0)
    monkeypatch.setattr(engine, "SPLIT_N", 32)


def _same_outcome(a, b) -> None:
    for k in ("inner", "boundary", "outer"):
        A, B = getattr(a, k), getattr(b, k)
        assert np.array_equal(A.lo, B.lo) and np.array_equal(A.hi, B.hi), k
    assert a.n_classified == b.n_classified and a.levels == b.levels
    assert a.status == b.status


class _Ring:
    """Labels boxes against the ring 0.3 <= |x| <= 0.8 (exact for these tests: bounds of
    |x|^2 on a box by its nearest and farthest points)."""

    def __call__(self, fr: BoxFrontier) -> np.ndarray:
        near = np.clip(0.0, fr.lo, fr.hi)
        far = np.maximum(np.abs(fr.lo), np.abs(fr.hi))
        lo2, hi2 = (near ** 2).sum(axis=1), (far ** 2).sum(axis=1)
        lab = np.full(len(fr), UNDECIDED, dtype=np.int8)
        lab[(lo2 >= 0.09) & (hi2 <= 0.64)] = INNER
        lab[(hi2 < 0.09) | (lo2 > 0.64)] = OUTER
        return lab


@settings(max_examples=6, deadline=None)
@given(st.sampled_from([2, 3]), st.sampled_from([0.02, 0.05, 0.1]))
def test_parts_give_the_serial_records_in_the_serial_order(n, eps):
    """Property over dimensions and eps: the executor run equals the serial run."""
    fr = BoxFrontier.from_boxes(np.array([[[-1.0, 1.0]] * n]))
    with ProcessPoolExecutor(2) as pe, pytest.MonkeyPatch.context() as mp:
        mp.setattr(_parallel, "SUBTREE_MIN_S", 0.0)
        mp.setattr(engine, "SPLIT_N", 32)
        ref = branch_and_bound(fr, _Ring(), eps, progress=False)
        ex = _Counting(pe)
        got = branch_and_bound(fr, _Ring(), eps, progress=False, executor=ex)
    assert ex.parts == 1  # two parts: one runs in the driver, one on the pool
    _same_outcome(ref, got)


def test_serial_records_after_the_split_are_ordered_by_part(always_cut):
    """The serial run orders each level's records by part (the order the joined tasks
    give): within a level, the inner boxes' parts never decrease."""
    fr = BoxFrontier.from_boxes(np.array([[[-1.0, 1.0]] * 2]))
    out = branch_and_bound(fr, _Ring(), 0.05, progress=False)
    assert out.inner.data is None  # the part tags do not leak into the records
    assert len(out.inner) > 100


def test_one_step_set_cut_into_parts_equals_the_serial_run(pool, always_cut):
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * (u + 0.5 * x[0] * x[0] + 0.2 * x[2]),
                   0.7 * x[2] + 0.1 * x[0] ** 2 + 0.1 * x[1])
    m = cm.Model(x=x, u=u, f=f, X=cm.Box([-1] * 3, [1] * 3), U=cm.Box([-2], [2]))
    T = cm.Polytope.from_box(cm.Box([-0.4] * 3, [0.4] * 3))
    A = cm.one_step_set(m, T, 0.1, method="general", progress=False)
    B = cm.one_step_set(m, T, 0.1, method="general", progress=False, executor=pool)
    assert A.paving.n_inner > 0
    for k in ("inner", "boundary", "outside"):
        assert np.array_equal(getattr(A.paving, k), getattr(B.paving, k))
    assert np.array_equal(A.witness, B.witness)  # proving controls in the same order
    assert A.n_pairs == B.n_pairs and pool.parts > 0


def test_a_budget_that_binds_after_the_split_gives_the_serial_stop(pool, always_cut):
    """max_boxes reached below the split level: the serial result (the same partial
    records and leftovers), not a per-task stop."""
    fr = BoxFrontier.from_boxes(np.array([[[-1.0, 1.0]] * 2]))
    full = branch_and_bound(fr, _Ring(), 0.01, progress=False)
    cap = full.n_classified // 2
    ref = branch_and_bound(fr, _Ring(), 0.01, progress=False, max_boxes=cap)
    got = branch_and_bound(fr, _Ring(), 0.01, progress=False, max_boxes=cap, executor=pool)
    assert ref.status == cm.Status.BUDGET and pool.parts > 0
    _same_outcome(ref, got)


class _DiesInPart(_Ring):
    """The ring classifier, exiting its process when it runs a part task (a crash)."""

    def __call__(self, fr: BoxFrontier) -> np.ndarray:
        import multiprocessing

        if multiprocessing.parent_process() is not None:
            os._exit(3)
        return super().__call__(fr)


def test_a_worker_dying_in_its_part_loses_no_box(always_cut):
    fr = BoxFrontier.from_boxes(np.array([[[-1.0, 1.0]] * 2]))
    ref = branch_and_bound(fr, _DiesInPart(), 0.02, progress=False)
    with ProcessPoolExecutor(2) as ex, warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        got = branch_and_bound(fr, _DiesInPart(), 0.02, progress=False, executor=ex)
    assert any("worker process died" in str(r.message) for r in rec)
    _same_outcome(ref, got)


def test_a_terminal_set_whose_proof_fails_on_a_worker_fails_the_run(process_pool):
    """T's proof runs beside the first steps on the executor; when it does not prove T,
    the run raises the serial run's error (and returns no sequence)."""
    ex = cm.models.load("cannon_robust")
    big = cm.Polytope(ex.terminal.A, 3.0 * ex.terminal.b)  # not invariant under the law
    with pytest.raises(ValueError, match="not proven invariant") as serial:
        cm.controllable_sets(ex.model, big, 0.1, robust=True, law=ex.local_law,
                             progress=False, max_steps=3)
    with pytest.raises(ValueError, match="not proven invariant") as pooled:
        cm.controllable_sets(ex.model, big, 0.1, robust=True, law=ex.local_law,
                             progress=False, max_steps=3, executor=_Counting(process_pool))
    assert str(pooled.value) == str(serial.value)
