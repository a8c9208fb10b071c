"""A search cut into parts at its split level (one part per worker for the rest of the
search, the first in the driver) gives the serial outcome: the same boxes in the same
order, the same proving controls, the same budget stop; a worker dying in its part loses
no box."""

from __future__ import annotations

import os
import warnings
from concurrent.futures import Executor, ProcessPoolExecutor

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.solvers import _parallel, engine
from casadi_cmpc.solvers.engine import (
    INNER,
    OUTER,
    UNDECIDED,
    BoxFrontier,
    branch_and_bound,
)


class _Tasks(Executor):
    """Counts the part tasks (``_subtree``) it passes on."""

    def __init__(self, inner: Executor) -> None:
        self.inner, self.parts = inner, 0
        self._max_workers = 2

    def submit(self, fn, /, *args, **kwargs):
        self.parts += fn is _parallel._subtree
        return self.inner.submit(fn, *args, **kwargs)


@pytest.fixture(scope="module")
def process_pool():
    with ProcessPoolExecutor(2) as ex:
        yield ex


@pytest.fixture()
def pool(process_pool):
    ex = _Tasks(process_pool)
    yield ex
    assert ex.parts > 0  # the search was cut into part tasks


@pytest.fixture(autouse=True)
def always_cut(monkeypatch):
    """Every search of these tests is cut at its split level, whatever its work."""
    monkeypatch.setattr(_parallel, "SUBTREE_MIN_S", 0.0)
    monkeypatch.setattr(engine, "SPLIT_N", 32)


def _same(a, b) -> None:
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
    ref = branch_and_bound(fr, _Ring(), eps, progress=False)
    with ProcessPoolExecutor(2) as pe:
        ex = _Tasks(pe)
        got = branch_and_bound(fr, _Ring(), eps, progress=False, executor=ex)
    assert ex.parts == 1  # two parts: one runs in the driver, one on the pool
    _same(ref, got)


def test_serial_records_after_the_split_are_ordered_by_part():
    """The serial run orders each level's records by part (the order the joined tasks
    give): within a level, the inner boxes' parts never decrease."""
    fr = BoxFrontier.from_boxes(np.array([[[-1.0, 1.0]] * 2]))
    out = branch_and_bound(fr, _Ring(), 0.05, progress=False)
    assert out.inner.data is None  # the part tags do not leak into the records
    assert len(out.inner) > 100


def test_one_step_set_cut_into_parts_equals_the_serial_run(pool):
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
    assert A.n_pairs == B.n_pairs


def test_a_budget_that_binds_after_the_split_gives_the_serial_stop(pool):
    """max_boxes reached below the split level: the serial result (the same partial
    records and leftovers), not a per-task stop."""
    fr = BoxFrontier.from_boxes(np.array([[[-1.0, 1.0]] * 2]))
    full = branch_and_bound(fr, _Ring(), 0.01, progress=False)
    cap = full.n_classified // 2
    ref = branch_and_bound(fr, _Ring(), 0.01, progress=False, max_boxes=cap)
    got = branch_and_bound(fr, _Ring(), 0.01, progress=False, max_boxes=cap, executor=pool)
    assert ref.status == cm.Status.BUDGET
    _same(ref, got)


class _DiesInPart(_Ring):
    """The ring classifier, exiting its process when it runs a part task (a crash)."""

    def __call__(self, fr: BoxFrontier) -> np.ndarray:
        import multiprocessing

        if multiprocessing.parent_process() is not None:
            os._exit(3)
        return super().__call__(fr)


def test_a_worker_dying_in_its_part_loses_no_box():
    fr = BoxFrontier.from_boxes(np.array([[[-1.0, 1.0]] * 2]))
    ref = branch_and_bound(fr, _DiesInPart(), 0.02, progress=False)
    with ProcessPoolExecutor(2) as ex, warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        got = branch_and_bound(fr, _DiesInPart(), 0.02, progress=False, executor=ex)
    assert any("worker process died" in str(r.message) for r in rec)
    _same(ref, got)
