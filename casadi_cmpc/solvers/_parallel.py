"""Classification of a branch-and-bound level on a ``concurrent.futures`` executor.

A level's frontier is cut into contiguous chunks; each chunk is classified by a worker
(a :class:`~concurrent.futures.ProcessPoolExecutor` process, or a Dask worker through
``distributed.Client.get_executor()``), and the labels (and the per-element data a classifier
writes, such as proving controls) are put back in order. Everything else of the search stays
in the driver: the reduction of grouped labels, bisection, budgets, the record of finished
boxes, and, for a two-phase classifier (``map`` on the workers, ``combine`` in the driver),
the level-wide reduction such as the incumbent bound of :func:`~casadi_cmpc.minimize`. The
outcome is that of the serial search, the same boxes in the same order, provided the
classifier labels each element from that element alone (every classifier of the library
does) and its interval evaluations give the same bits in the worker as in the driver. They
do for the operations every backend evaluates alike (``+ - *``, squares, constants); for
libm functions the numpy, scalar and native backends may differ in the last bits of a bound,
which can change a label at a box within a few ulps of a decision.

A set search (a frontier that splits, a one-phase classifier, no per-level callback) is
also cut into *parts* at its split level (see :func:`~casadi_cmpc.solvers.engine
.branch_and_bound`): :meth:`LevelRunner.subtrees` runs the rest of the search below each
contiguous range of parts as one task, the first range in the driver, and the engine joins
their records level by level. This spreads the whole search below the split (bisection and
bookkeeping included), not only the classification of large levels.

Chunk sizes follow the measured cost: about :data:`TARGET_S` seconds of work per task (a Dask
task costs about 1 ms of overhead, a process-pool task less), from the cost per element of
the previous levels; a search's first levels, and every level with less work than two tasks,
run in the driver.

The classifier is serialised once (pickle, CasADi expressions in one shared context;
closures need ``cloudpickle``, which the ``[dask]`` extra installs), sent with the first
tasks only and rebuilt once per worker process (kept by a hash of its bytes), so that its
compiled evaluators and their native kernels are reused across chunks and levels; a worker
that has not seen it asks for it again. A worker process that dies is replaced
by classifying its chunk in the driver (with a warning); no chunk is lost, and an exception
raised by the classifier itself is raised again.
"""

from __future__ import annotations

import hashlib
import pickle
import time
import warnings
from collections import OrderedDict
from concurrent.futures import Executor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import casadi as ca
import numpy as np

from ..exceptions import CmpcWarning

__all__ = ["LevelRunner", "TARGET_S"]

TARGET_S = 0.1  # seconds of classification per task
MIN_CHUNK = 64  # elements: below this a task is not worth sending
#: seconds of classification at the split level below which a search is not cut into tasks
SUBTREE_MIN_S = 0.002

_WORKER_CACHE: OrderedDict[str, Any] = OrderedDict()  # classifier bytes hash -> classifier
# seconds per element last measured for a type of classifier (in this process): lets a
# search cut its first level into tasks when an earlier search measured the cost
_COST_HINT: dict[type, float] = {}


def _dumps(obj: Any) -> bytes:
    """The classifier's bytes: pickle (CasADi expressions in one shared context, so that
    their symbols stay the same), cloudpickle for closures."""
    try:
        with ca.global_pickle_context():
            return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    except (pickle.PicklingError, AttributeError, TypeError) as exc:
        try:
            import cloudpickle
        except ImportError:
            raise TypeError(
                f"the classifier cannot be sent to worker processes ({exc}); install "
                "cloudpickle (pip install 'casadi_cmpc[dask]') or run without executor") \
                from exc
        with ca.global_pickle_context():
            return cloudpickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)


_MISSING = "missing classifier"  # a worker's answer to a task without the classifier's bytes


def _classifier(blob: bytes | None, key: str) -> Any:
    clf = _WORKER_CACHE.get(key)
    if clf is None:
        if blob is None:
            return None
        with ca.global_unpickle_context():
            clf = _WORKER_CACHE[key] = pickle.loads(blob)
        while len(_WORKER_CACHE) > 8:
            _WORKER_CACHE.popitem(last=False)
    else:
        _WORKER_CACHE.move_to_end(key)
    return clf


def _classify_chunk(blob: bytes | None, key: str, chunk: Any) -> tuple[Any, Any, float]:
    """Worker side: (labels, or the :meth:`map` part of a two-phase classifier; the chunk's
    per-element data; seconds). ``blob`` None: the classifier of ``key`` was sent to this
    process before; :data:`_MISSING` if it was not."""
    t0 = time.perf_counter()
    clf = _classifier(blob, key)
    if clf is None:
        return _MISSING, None, 0.0
    if _two_phase(clf):
        out: Any = clf.map(chunk)
    else:
        out = np.asarray(clf(chunk), dtype=np.int8)
    return out, getattr(chunk, "data", None), time.perf_counter() - t0


def _subtree_run(clf: Any, frontier: Any, eps: float, keep_outer: bool, max_boxes: int,
                 time_limit: float | None) -> dict:
    from .engine import branch_and_bound

    return branch_and_bound(frontier, clf, eps, max_boxes=max_boxes, time_limit=time_limit,
                            keep_outer=keep_outer, progress=False, _tagged=True, _raw=True)


def _subtree(blob: bytes | None, key: str, frontier: Any, eps: float, keep_outer: bool,
             max_boxes: int, time_limit: float | None) -> Any:
    """Worker side: the rest of a tagged search on ``frontier`` (its records level by
    level); :data:`_MISSING` if the classifier was not sent to this process before."""
    clf = _classifier(blob, key)
    if clf is None:
        return _MISSING
    return _subtree_run(clf, frontier, eps, keep_outer, max_boxes, time_limit)


def _two_phase(clf: Any) -> bool:
    """A classifier whose labels need the whole level (e.g. a bound shared by all boxes):
    ``map(chunk) -> part`` per chunk on the workers, ``combine(frontier, parts) -> labels``
    in the driver, with ``combine(fr, [map(fr)])`` the serial classification."""
    return callable(getattr(clf, "map", None)) and callable(getattr(clf, "combine", None))


def _workers(executor: Executor) -> int:
    n = getattr(executor, "_max_workers", None)  # ProcessPoolExecutor, ThreadPoolExecutor
    if n is None:
        client = getattr(executor, "_client", None)  # distributed.client.ClientExecutor
        try:
            n = sum(client.nthreads().values()) if client is not None else None
        except Exception:  # noqa: BLE001 - a client that cannot say: assume two
            n = None
    return max(int(n or 2), 1)


class _Failed:
    """A task that could not be submitted: its ``result()`` raises the submission's error."""

    def __init__(self, exc: BaseException) -> None:
        self.exc = exc

    def result(self) -> Any:
        raise self.exc

    def cancel(self) -> bool:
        return False


class LevelRunner:
    """``runner(classify, frontier) -> labels``: one level classified serially or on an
    executor (see the module notes).

    Parameters
    ----------
    executor : concurrent.futures.Executor or None
        None: every level in the driver.
    target_s : float, optional
        Seconds of work per task (default :data:`TARGET_S`).
    """

    def __init__(self, executor: Executor | None, target_s: float | None = None) -> None:
        if executor is not None and not callable(getattr(executor, "submit", None)):
            raise TypeError("executor must be a concurrent.futures.Executor (e.g. "
                            "ProcessPoolExecutor(2), or distributed.Client(...)"
                            ".get_executor()); got " + type(executor).__name__)
        self.executor = executor
        self.target_s = float(TARGET_S if target_s is None else target_s)
        self.cost: float | None = None  # seconds per element, measured
        self.n_workers = _workers(executor) if executor is not None else 1
        self.n_tasks = 0
        self._blob: tuple[int, bytes, str] | None = None
        self._shipped: dict[str, int] = {}  # classifier key -> tasks that carried its bytes

    def __call__(self, classify: Any, frontier: Any) -> np.ndarray:
        N = len(frontier)
        # a level runs here until the cost per element is known (measured on this level)
        # and predicts at least two tasks' worth of work
        if self.executor is None or N < 2 * MIN_CHUNK or self.cost is None \
                or N * self.cost < 2 * self.target_s:
            t0 = time.perf_counter()
            if _two_phase(classify):
                labels = classify.combine(frontier, [classify.map(frontier)])
            else:
                labels = classify(frontier)
            labels = np.asarray(labels, dtype=np.int8)
            if N:
                self._measure((time.perf_counter() - t0) / N, classify)
            return labels
        return self._parallel(classify, frontier, N)

    def subtrees(self, classify: Any, frontier: Any, eps: float, keep_outer: bool,
                 max_boxes: int, time_limit: float | None) -> list[dict] | None:
        """The rest of a tagged search (see :func:`~casadi_cmpc.solvers.engine
        .branch_and_bound`) cut into one contiguous range of parts per worker: the first
        range runs here while the others run as tasks (the driver would otherwise only
        wait, and its compiled functions are warm). Returns the records of the ranges in
        their order, or None when the work left looks too small to be worth the tasks
        (the driver goes on alone). A task whose worker died runs here (with a warning)."""
        from .engine import part_ranges, task_frontier

        cost = self.cost_of(classify)
        if self.executor is None or cost is None or len(frontier) * cost < SUBTREE_MIN_S:
            return None
        blob, key = self._serialised(classify)
        ranges = part_ranges(self.n_workers)
        parts = [task_frontier(frontier, a, b) for a, b in ranges]
        args = (eps, keep_outer, max_boxes, time_limit)
        futures: list[Any] = [None]  # the first part runs here meanwhile
        for p in parts[1:]:
            if not len(p):
                futures.append(None)
                continue
            try:
                futures.append(self.executor.submit(_subtree, blob, key, p, *args))
            except BrokenProcessPool as exc:
                futures.append(_Failed(exc))
        self.n_tasks += sum(f is not None for f in futures)
        out: list[dict] = []
        try:
            for p, fut in zip(parts, futures, strict=True):
                if fut is None:
                    out.append(_subtree_run(classify, p, *args))
                    continue
                try:
                    r = fut.result()
                    if isinstance(r, str) and r == _MISSING:
                        r = self.executor.submit(_subtree, blob, key, p, *args).result()
                except BrokenProcessPool as exc:
                    warnings.warn(f"a worker process died ({exc}); its part of the search "
                                  f"({len(p)} elements) runs in the driver", CmpcWarning,
                                  stacklevel=4)
                    self.executor = None
                    r = _subtree_run(classify, p, *args)
                out.append(r)
        except BaseException:
            for fut in futures:
                if fut is not None:
                    fut.cancel()
            raise
        return out

    def _measure(self, c: float, classify: Any) -> None:
        self.cost = c if self.cost is None else 0.5 * self.cost + 0.5 * c
        _COST_HINT[type(classify)] = self.cost

    def cost_of(self, classify: Any) -> float | None:
        """Seconds per element: measured in this search, else the last measure of a
        classifier of the same type in this process, else None."""
        return self.cost if self.cost is not None else _COST_HINT.get(type(classify))

    def _serialised(self, classify: Any) -> tuple[bytes, str]:
        if self._blob is None or self._blob[0] != id(classify):
            blob = _dumps(classify)
            self._blob = (id(classify), blob, hashlib.sha1(blob).hexdigest())
        return self._blob[1], self._blob[2]

    def _parallel(self, classify: Any, frontier: Any, N: int) -> np.ndarray:
        blob, key = self._serialised(classify)
        size = int(self.target_s / max(float(self.cost or 0.0), 1e-9))
        size = min(size, -(-N // self.n_workers))  # every worker gets a share
        size = max(size, MIN_CHUNK)
        bounds = [(a, min(a + size, N)) for a in range(0, N, size)]
        chunks = [frontier.take(np.arange(a, b)) for a, b in bounds]
        futures: list[Any] = []
        for c in chunks:
            # the classifier's bytes go with the first tasks only (each worker keeps it);
            # a worker that never got them answers _MISSING and the chunk goes again
            shipped = self._shipped.get(key, 0)
            ship = shipped < 2 * self.n_workers
            self._shipped[key] = shipped + ship
            try:
                futures.append(self.executor.submit(_classify_chunk, blob if ship else None,
                                                    key, c))
            except BrokenProcessPool as exc:  # a worker died since: the rest runs here
                futures.append(_Failed(exc))
        self.n_tasks += len(futures)
        two = _two_phase(classify)
        labels = np.empty(N, dtype=np.int8)
        parts: list[Any] = []
        spent = 0.0
        try:
            for (a, b), chunk, fut in zip(bounds, chunks, futures, strict=True):
                try:
                    lab, data, dt = fut.result()
                    if isinstance(lab, str) and lab == _MISSING and self.executor is not None:
                        lab, data, dt = self.executor.submit(_classify_chunk, blob, key,
                                                             chunk).result()
                except BrokenProcessPool as exc:
                    warnings.warn(f"a worker process died ({exc}); its chunk of {b - a} "
                                  "elements is classified in the driver", CmpcWarning,
                                  stacklevel=4)
                    t0 = time.perf_counter()
                    lab = classify.map(chunk) if two else np.asarray(classify(chunk),
                                                                     dtype=np.int8)
                    data, dt = getattr(chunk, "data", None), time.perf_counter() - t0
                    self.executor = None  # a broken pool takes no more tasks
                if two:
                    parts.append(lab)
                else:
                    labels[a:b] = lab
                if data:
                    for name, v in data.items():
                        frontier.data[name][a:b] = v
                spent += dt
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise
        self._measure(spent / N, classify)
        if two:
            labels = np.asarray(classify.combine(frontier, parts), dtype=np.int8)
        return labels
