"""One batched branch-and-bound engine for every interval solver.

A *frontier* of boxes (or zonotopes) is classified in one vectorised call per level; the
undecided elements are bisected together. Each solver is a *classifier* plugged into
:func:`branch_and_bound`:

``classify(frontier) -> labels`` with one ``int8`` per element: ``INNER`` (1, proven to have
the property; kept), ``OUTER`` (-1, proven not to have it; discarded) or ``UNDECIDED`` (0).
Undecided elements narrower than ``eps`` become *boundary*; the others are bisected.

A frontier whose elements are grouped (:class:`PairFrontier`: (state box, control cell)
pairs, a state box being the group) has a ``reduce(labels, eps) -> (labels, small)`` hook
that turns the labels of the elements into labels of the groups, marking the elements that
are finished without a record ``DROPPED`` (2).

The frontier is a plain array structure and every classification is a pure function of it,
so a level can be split across processes without touching the algorithms. Limits (``eps``,
``max_boxes``, ``time_limit``) and Ctrl-C stop the loop and return the partial result, which
is still sound: everything not classified is reported as boundary (undecided).
"""

from __future__ import annotations

import ctypes
import enum
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from .._bisect import _COLUMN_MAX, RULES_C, bisect_widest, widest_of
from .._interrupt import InterruptScope
from ..exceptions import UnboundedSetError
from ..interval import _fpu
from ..interval._native import address, c_function
from ._common import positive_eps
from ._parallel import LevelRunner, _two_phase

__all__ = ["INNER", "OUTER", "UNDECIDED", "DROPPED", "Status", "BoxFrontier", "PairFrontier",
           "BnBOutcome", "branch_and_bound"]

INNER = np.int8(1)
OUTER = np.int8(-1)
UNDECIDED = np.int8(0)
DROPPED = np.int8(2)  # finished without a record (grouped frontiers, see PairFrontier)


class Status(enum.IntEnum):
    """Outcome codes shared by the solvers (``success == (status == PROVED)``).

    An :class:`~enum.IntEnum`: a member equals its code (``Status.PROVED == 0``), while
    ``str()`` and formatting give its name, so that printed results read as words.

    Examples
    --------
    >>> from casadi_cmpc.solvers.engine import Status
    >>> str(Status.PROVED), f"{Status.BUDGET}", int(Status.DISPROVED), Status(3)
    ('PROVED', 'BUDGET', 2, <Status.UNDECIDED: 3>)
    """

    PROVED = 0
    BUDGET = 1  # a limit (max_boxes, time_limit) or an interruption stopped the search
    DISPROVED = 2
    UNDECIDED = 3
    NUMERICAL = 4

    def __str__(self) -> str:
        return self.name


class Frontier(Protocol):
    """What the engine needs from a frontier representation.

    A frontier may also have ``split() -> (children, stuck)``; the engine then uses it instead
    of ``bisect`` and reports the ``stuck`` elements (too narrow to be split in floating point)
    as boundary instead of classifying them again and again.
    """

    def __len__(self) -> int: ...

    def take(self, mask: np.ndarray) -> Frontier: ...

    def width(self) -> np.ndarray: ...

    def bisect(self) -> Frontier: ...

    @staticmethod
    def concat(parts: list[Any]) -> Any: ...


def _concat_data(parts: list[Any]) -> dict[str, np.ndarray] | None:
    """The per-element data of frontier parts joined, or None unless all have the same keys."""
    keys = [None if p.data is None else set(p.data) for p in parts]
    if keys[0] is None or any(k != keys[0] for k in keys):
        return None
    return {key: np.concatenate([p.data[key] for p in parts]) for key in keys[0]}


@dataclass
class BoxFrontier:
    """A batch of boxes as ``lo``, ``hi`` arrays of shape (N, n).

    ``bisect`` splits every box at ``split_ratio`` of its widest component (ties: lowest
    index; widths relative to ``scale`` when given), thesis eqs. (4.2)-(4.4), by
    :func:`casadi_cmpc._bisect.bisect_widest`.

    ``data`` holds optional per-box arrays (first axis N) that travel with the boxes: ``take``
    selects their rows, ``concat`` joins them and both halves of a bisected box inherit the
    row of their parent. A classifier may record there what it proved about a box (e.g. which
    constraints hold on all of it), which then holds on every descendant as well. Finished
    boxes (the records of a search) drop their data, except the keys in ``keep`` (e.g. the
    control sequence that proves an inner box).
    """

    lo: np.ndarray
    hi: np.ndarray
    scale: np.ndarray | None = None
    split_ratio: float = 0.5
    data: dict[str, np.ndarray] | None = None
    # widest component of each box, kept from width() for split() (same boxes, same order)
    _split_dim: np.ndarray | None = field(default=None, repr=False, compare=False)
    keep: tuple[str, ...] = ()

    @classmethod
    def from_boxes(cls, boxes: np.ndarray, scale: np.ndarray | None = None,
                   split_ratio: float = 0.5) -> BoxFrontier:
        b = np.asarray(boxes, dtype=float)
        return cls(np.ascontiguousarray(b[..., 0]), np.ascontiguousarray(b[..., 1]), scale,
                   split_ratio)

    def _with(self, lo: np.ndarray, hi: np.ndarray, data: dict[str, np.ndarray] | None,
              split_dim: np.ndarray | None = None) -> BoxFrontier:
        return BoxFrontier(lo, hi, self.scale, self.split_ratio, data, split_dim, self.keep)

    def __len__(self) -> int:
        return self.lo.shape[0]

    @property
    def boxes(self) -> np.ndarray:
        """(N, n, 2) array."""
        return np.stack([self.lo, self.hi], axis=-1)

    def take(self, mask: np.ndarray) -> BoxFrontier:
        """The boxes selected by a boolean mask (N,) or by an array of indices."""
        idx = np.asarray(mask)
        if idx.dtype == bool:
            idx = np.flatnonzero(idx)  # integer take is far faster than boolean row indexing
        k = None if self._split_dim is None else self._split_dim.take(idx)
        data = None if self.data is None else {
            key: v.take(idx, axis=0) for key, v in self.data.items()}
        return self._with(self.lo.take(idx, axis=0), self.hi.take(idx, axis=0), data, k)

    def take_done(self, idx: np.ndarray) -> BoxFrontier:
        """The boxes at the indices ``idx`` without their per-box data, except the keys of
        ``keep`` (for finished parts)."""
        data = None if self.data is None or not self.keep else {
            key: self.data[key].take(idx, axis=0) for key in self.keep}
        return BoxFrontier(self.lo.take(idx, axis=0), self.hi.take(idx, axis=0), self.scale,
                           self.split_ratio, data, None, self.keep)

    def width(self) -> np.ndarray:
        """Largest component width of each box (relative to ``scale`` when given), (N,)."""
        w, self._split_dim = widest_of(self.lo, self.hi, self.scale)
        return w

    def split(self) -> tuple[BoxFrontier, BoxFrontier]:
        """``(children, stuck)``: the two halves of every box that can be split, and the boxes
        whose widest component holds no float strictly between its bounds (not split)."""
        k = self._split_dim
        if k is None or len(k) != len(self):
            k = widest_of(self.lo, self.hi, self.scale)[1]
        new_lo, new_hi, _, ok = bisect_widest(self.lo, self.hi, k=k, ratio=self.split_ratio)
        data = self.data
        if ok.all():
            stuck = self._with(self.lo[:0], self.hi[:0], None if data is None else {
                key: v[:0] for key, v in data.items()})
        else:
            stuck = self.take(~ok)
            keep = np.flatnonzero(ok)
            both = np.concatenate([keep, keep + len(self)])
            new_lo, new_hi = new_lo.take(both, axis=0), new_hi.take(both, axis=0)
            if data is not None:
                data = {key: v.take(keep, axis=0) for key, v in data.items()}
        if data is not None:  # both halves inherit what was proven on their parent
            data = {key: np.concatenate([v, v]) for key, v in data.items()}
        children = self._with(new_lo, new_hi, data)
        return children, stuck

    def bisect(self) -> BoxFrontier:
        """Both halves of every box; a box that cannot be split is kept whole (see ``split``)."""
        children, stuck = self.split()
        return BoxFrontier.concat([children, stuck]) if len(stuck) else children

    @staticmethod
    def concat(parts: list[BoxFrontier]) -> BoxFrontier:
        if not parts:
            raise ValueError("nothing to concatenate")
        return parts[0]._with(np.concatenate([p.lo for p in parts]),
                              np.concatenate([p.hi for p in parts]), _concat_data(parts))


@dataclass
class BnBOutcome:
    """Raw result of :func:`branch_and_bound`.

    Attributes
    ----------
    inner, boundary, outer : frontier
        Elements classified INNER; undecided elements narrower than eps (plus everything left
        when a limit stopped the search); elements classified OUTER (empty unless
        ``keep_outer``). The raw outcome keeps the names of the labels; the solvers' results
        (:class:`~casadi_cmpc.SetResult`) call the OUTER elements ``outside``.
    n_discarded : int
        Number of OUTER elements.
    status : Status
        PROVED when the search ran to completion, BUDGET when a limit or an interruption
        stopped it (the leftover frontier is in ``boundary``).
    """

    inner: Any
    boundary: Any
    outer: Any
    n_discarded: int
    status: Status
    message: str
    levels: int
    n_classified: int
    elapsed: float
    history: list[dict] = field(default_factory=list)


@_fpu.default_env  # every rounding of a search holds in the default environment
def branch_and_bound(frontier: Any, classify: Callable[[Any], np.ndarray], eps: float, *,
                     max_boxes: int = 5_000_000, time_limit: float | None = None,
                     keep_outer: bool = True, progress: bool | None = None,
                     desc: str = "branch and bound",
                     on_level: Callable[[int, Any, np.ndarray], None] | None = None,
                     executor: Any = None, _tagged: bool = False, _raw: bool = False
                     ) -> Any:
    """Breadth-first branch and bound over a frontier, one vectorised classification per level.

    Parameters
    ----------
    frontier : BoxFrontier or another frontier type
        The initial elements (usually one box).
    classify : callable
        ``classify(frontier) -> (N,) int8`` labels INNER / OUTER / UNDECIDED.
    eps : float
        Undecided elements whose ``width()`` is at most eps are not bisected (boundary).
    max_boxes : int
        Stop when this many elements have been classified in total.
    time_limit : float, optional
        Stop after this many seconds (checked once per level).
    keep_outer : bool
        Keep the OUTER elements (for drawing); they are always counted.
    progress : bool or None
        Show a tqdm bar (None: only when the search lasts more than 2 s).
    on_level : callable, optional
        ``on_level(level, frontier, labels)`` after each classification (e.g. to update a
        bound from the classified boxes).
    executor : concurrent.futures.Executor, optional
        Classify the large levels in chunks on this executor (a ``ProcessPoolExecutor``, or
        ``distributed.Client(...).get_executor()``); the outcome is that of the serial
        search (see :mod:`casadi_cmpc.solvers._parallel`). The classifier must be picklable
        (closures: with cloudpickle) and label each element from that element alone.

    Returns
    -------
    BnBOutcome

    Notes
    -----
    **Parts.** At the first level with at least :data:`SPLIT_N` elements (a frontier that
    can ``split``, no ``on_level``, a one-phase classifier) every element is tagged with
    one of :data:`N_PARTS` parts (its group, or its index, modulo N_PARTS, bits reversed:
    neighbours go to different ranges of parts); descendants
    keep the tag, and from then on the records of each level are ordered by part (stably:
    within a part, in the order of the search). The searches below different parts are
    independent, so with an ``executor`` the rest of the search (from the first level
    whose cost per element is known: measured by this search, or by an earlier one with a
    classifier of the same type) runs as one task per worker, each on a contiguous range
    of parts, and their records are joined level by level: the same elements in the same
    order as the serial search, which orders its records the same way. Should the joined
    run exceed ``max_boxes``, the search goes on serially from the split level instead
    (the serial result, budget included).
    """
    with warnings.catch_warnings():
        # in a notebook without ipywidgets tqdm.auto warns, then uses the text bar
        warnings.simplefilter("ignore")
        from tqdm.auto import tqdm

    eps = positive_eps(eps)
    if isinstance(frontier, BoxFrontier) and not (
            np.isfinite(frontier.lo).all() and np.isfinite(frontier.hi).all()):
        raise UnboundedSetError("the initial box of a branch and bound must be bounded")
    t0 = time.perf_counter()
    done: list[tuple[Any, ...]] = []  # per level: (inner, outer, boundary parts, n_out, n)
    level = 0
    status = Status.PROVED
    message = "search completed"
    history: list[dict] = []
    splits = callable(getattr(frontier, "split", None))
    bar = tqdm(total=None, desc=desc, unit="box", disable=progress is False,
               delay=0 if progress else 2.0, leave=False)
    n_classified = 0
    runner = LevelRunner(executor)
    scope = InterruptScope()
    tagged = bool(_tagged)
    pending = False  # tagged, and the parts not yet sent to the executor
    partition = (splits and hasattr(frontier, "data") and on_level is None
                 and not _two_phase(classify))
    try:
        while len(frontier):
            if n_classified + len(frontier) > max_boxes:
                status, message = Status.BUDGET, f"max_boxes = {max_boxes} reached"
                break
            if time_limit is not None and time.perf_counter() - t0 > time_limit:
                status, message = Status.BUDGET, f"time_limit = {time_limit} s reached"
                break
            if partition and not tagged and len(frontier) >= SPLIT_N:
                frontier, tagged = _tag(frontier), True
                pending = runner.executor is not None
            # the parts go to the workers at the first level whose cost per element is known
            # (measured by an earlier search with this type of classifier, or by this one)
            if pending and runner.cost_of(classify) is not None:
                pending = False
                left = None if time_limit is None else \
                    time_limit - (time.perf_counter() - t0)
                subs = runner.subtrees(classify, frontier, eps, keep_outer,
                                       max_boxes - n_classified, left)
                joined = None if subs is None else _join_tasks(subs)
                if joined is not None and (joined["status"] != Status.BUDGET or
                                           joined["message"].startswith("time_limit")) \
                        and _within(joined["done"], n_classified, max_boxes):
                    for k, d in enumerate(joined["done"]):
                        history.append({"level": level + k, "classified": d[5],
                                        "inner": 0 if d[0] is None else len(d[0]),
                                        "outer": d[4], "boundary": sum(
                                            len(p) for p in d[2:4] if p is not None)})
                        if not bar.disable:
                            bar.update(d[5])
                    done = done + joined["done"]
                    n_classified += sum(d[5] for d in joined["done"])
                    level += len(joined["done"])
                    status, message = joined["status"], joined["message"]
                    frontier = joined["left"] if joined["left"] is not None else \
                        frontier.take(np.zeros(len(frontier), dtype=bool))
                    break
            labels = runner(classify, frontier)
            reduce = getattr(frontier, "reduce", None)
            small = None
            if reduce is not None:  # grouped elements: labels and sizes of the groups
                labels, small = reduce(labels, eps)
            # finished elements need no per-element data: a frontier may drop it there
            take_done = getattr(frontier, "take_done", frontier.take)
            n = len(frontier)
            if on_level is not None:
                on_level(level, frontier, labels)
            # Everything of this level is computed before anything is recorded, so that an
            # interruption leaves either the whole level or none of it in the result.
            i_in = (labels == INNER).nonzero()[0]
            i_out = (labels == OUTER).nonzero()[0]
            undecided = (labels != INNER) & (labels != OUTER)
            if reduce is not None:
                undecided &= labels != DROPPED
            if small is None:
                # widths of every element (cheaper than gathering the undecided ones first)
                small = frontier.width() <= eps
            i_small = (undecided & small).nonzero()[0]
            i_grow = (undecided & ~small).nonzero()[0]
            if tagged:  # the records of a level in the order of the parts
                tag = frontier.data[_PART]
                i_in, i_out, i_small = (i[np.argsort(tag[i], kind="stable")]
                                        for i in (i_in, i_out, i_small))
            in_part = _untag(take_done(i_in)) if i_in.size else None
            out_part = _untag(take_done(i_out)) if keep_outer and i_out.size else None
            small_part = _untag(take_done(i_small)) if i_small.size else None
            stuck_part = None
            if not i_grow.size:
                nxt = frontier.take(i_grow)
            elif splits:
                # the growing elements split (a frontier may do it without gathering them
                # first: the same children)
                split_selected = getattr(frontier, "split_selected", None)
                nxt, stuck = (split_selected(i_grow) if split_selected is not None
                              else frontier.take(i_grow).split())
                if len(stuck):  # too narrow for floating point: undecided for good
                    if tagged:
                        stuck = stuck.take(np.argsort(stuck.data[_PART], kind="stable"))
                    stuck_part = _untag(stuck)
            else:
                nxt = frontier.take(i_grow).bisect()
            n_bnd = sum(len(p) for p in (small_part, stuck_part) if p is not None)
            # commit the level in one assignment statement
            done, frontier, n_classified = done + [
                (in_part, out_part, small_part, stuck_part, i_out.size, n)], \
                nxt, n_classified + n
            history.append({"level": level, "classified": n, "inner": int(i_in.size),
                            "outer": int(i_out.size), "boundary": n_bnd})
            level += 1
            if not bar.disable:
                bar.update(n)
                bar.set_postfix(level=level - 1, frontier=len(frontier), refresh=False)
    except KeyboardInterrupt:
        scope.reraise_if_nested()  # inside a larger computation: it answers Ctrl-C
        status, message = Status.BUDGET, "interrupted"
    finally:
        scope.close()
        bar.close()
    if _raw:  # a task of a split search: the records level by level
        return {"done": done, "status": status, "message": message,
                "left": frontier if len(frontier) else None}
    level = len(done)
    inner = [d[0] for d in done if d[0] is not None]
    outer = [d[1] for d in done if d[1] is not None]
    boundary = [p for d in done for p in d[2:4] if p is not None]
    n_discarded = int(sum(d[4] for d in done))
    n_classified = int(sum(d[5] for d in done))
    history = history[:level]
    if len(frontier):
        frontier = _untag(frontier)
        boundary.append(frontier)  # unclassified leftovers are undecided: sound
    empty = frontier.take(np.zeros(len(frontier), dtype=bool))
    cat = type(frontier).concat
    return BnBOutcome(
        inner=cat(inner) if inner else empty,
        boundary=cat(boundary) if boundary else empty,
        outer=cat(outer) if outer else empty,
        n_discarded=n_discarded, status=status, message=message, levels=level,
        n_classified=n_classified, elapsed=time.perf_counter() - t0, history=history)


#: elements of the level at which a search is cut into parts (see branch_and_bound)
SPLIT_N = 256
#: number of parts
N_PARTS = 64
_PART = "_part"  # the data key of an element's part


# part of the index k (mod N_PARTS): its 6 bits reversed, so that consecutive elements
# fall in different contiguous ranges of parts (each range a balanced, interleaved share)
_BITS = N_PARTS.bit_length() - 1  # N_PARTS is a power of two
_SPREAD = np.array([int(f"{k:0{_BITS}b}"[::-1], 2) for k in range(N_PARTS)], dtype=np.int16)


def _tag(frontier: Any) -> Any:
    """The frontier with its part tags: the group (or the index) modulo N_PARTS, spread by
    bit reversal."""
    g = getattr(frontier, "group", None)
    ids = g if g is not None else np.arange(len(frontier))
    data = dict(frontier.data) if frontier.data is not None else {}
    data[_PART] = _SPREAD[ids % N_PARTS]
    fr = frontier.take(np.arange(len(frontier)))
    fr.data = data
    return fr


def _untag(part: Any) -> Any:
    """The part without its tags (records carry only the classifier's data)."""
    if part is not None and getattr(part, "data", None) is not None and _PART in part.data:
        data = {k: v for k, v in part.data.items() if k != _PART}
        part.data = data or None
    return part


def part_ranges(n_tasks: int) -> list[tuple[int, int]]:
    """The contiguous part ranges ``[a, b)`` of ``n_tasks`` tasks (balanced)."""
    k = max(1, min(int(n_tasks), N_PARTS))
    return [(i * N_PARTS // k, (i + 1) * N_PARTS // k) for i in range(k)]


def task_frontier(frontier: Any, a: int, b: int) -> Any:
    """The elements of parts ``a <= part < b`` (in their order), group ids made dense."""
    tag = frontier.data[_PART]
    sub = frontier.take(np.flatnonzero((tag >= a) & (tag < b)))
    if getattr(sub, "group", None) is not None and len(sub):
        sub.group = _dense_ids(sub.group)[1]
    return sub


def _join_tasks(results: list[dict]) -> dict:
    """The records of tasks on consecutive part ranges, joined level by level."""
    depth = max(len(r["done"]) for r in results)
    done = []

    def cat(items: list[Any]) -> Any:
        items = [p for p in items if p is not None]
        if not items:
            return None
        return items[0] if len(items) == 1 else type(items[0]).concat(items)

    for k in range(depth):
        rows = [r["done"][k] for r in results if k < len(r["done"])]
        done.append(tuple(cat([d[j] for d in rows]) for j in range(4))
                    + (sum(d[4] for d in rows), sum(d[5] for d in rows)))
    budget = [r for r in results if r["status"] == Status.BUDGET]
    left = cat([_untag(r["left"]) for r in results if r["left"] is not None])
    status, message = ((Status.BUDGET, budget[0]["message"]) if budget
                       else (Status.PROVED, "search completed"))
    return {"done": done, "status": status, "message": message, "left": left}


def _within(done: list[tuple], n0: int, max_boxes: int) -> bool:
    """Whether the serial search would have classified every level of ``done`` within
    ``max_boxes`` (it stops before a level whose elements would exceed it)."""
    n = n0
    for d in done:
        if n + d[5] > max_boxes:
            return False
        n += d[5]
    return True


def _dense_ids(group: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(group, return_inverse=True)`` for non-negative int ids, in linear time
    (ids are dense up to a small factor: those of a frontier)."""
    present = np.bincount(group) > 0
    rank = np.cumsum(present) - 1
    return np.flatnonzero(present), rank[group].astype(np.intp)


# Per-group reductions of the pair frontiers as C loops (numpy's ufunc.at is slow); the
# numpy code gives the same answers where no compiler is found and while these compile.
# Widths and cuts follow the one bisection rule of casadi_cmpc._bisect (its RULES_C).
_GROUP_C = RULES_C + r"""
#include <stdint.h>
#include <math.h>
void cmpc_group_first(int64_t N, const int64_t *g, const unsigned char *mask, int64_t *first)
{
    for (int64_t i = N - 1; i >= 0; --i)
        if (mask[i]) first[g[i]] = i;
}
/* [a, b] := hull of [a, b] and [l, h] (d coordinates; numpy.minimum / maximum: a NaN
 * propagates) */
static inline void cmpc_hull_add(double *a, double *b, const double *l, const double *h,
                                 int64_t d)
{
    for (int64_t j = 0; j < d; ++j) {
        a[j] = (l[j] < a[j] || l[j] != l[j]) ? l[j] : a[j];
        b[j] = (h[j] > b[j] || h[j] != h[j]) ? h[j] : b[j];
    }
}
void cmpc_group_hull(int64_t N, int64_t d, const int64_t *g, const double *lo,
                     const double *hi, double *glo, double *ghi)
{
    for (int64_t i = 0; i < N; ++i)
        cmpc_hull_add(glo + g[i] * d, ghi + g[i] * d, lo + i * d, hi + i * d, d);
}
/* PairFrontier.reduce: group labels from pair labels (1 inner, -1 outer, 0 undecided,
 * 2 dropped), in three passes, and per pair whether its cell can be split (u_can: widest
 * relative control width above u_eps); cnt, n_in, n_out, n_live, n_split, first_in,
 * first_any, first_und: G int64 each, zeroed (first_*: N) by the caller */
void cmpc_pair_reduce(int64_t N, int64_t G, const int64_t *g, const signed char *lab,
                      int64_t d, int64_t n, const double *lo, const double *hi,
                      const double *x_scale, const double *u_scale, double eps,
                      double u_eps, unsigned char *u_can,
                      int64_t max_cells, int64_t *cnt, int64_t *n_in, int64_t *n_out,
                      int64_t *n_live, int64_t *n_split, int64_t *first_in,
                      int64_t *first_any, int64_t *first_und, unsigned char *gflag,
                      signed char *out, unsigned char *small, unsigned char *u_mode)
{
    /* gflag bits: 1 inner, 2 outer, 4 u_ok, 8 x_small, 16 exhausted */
    for (int64_t i = 0; i < N; ++i) {
        int64_t k = g[i];
        double wx, wu = 0.0;
        (void)cmpc_widest_row(lo + i * d, hi + i * d, x_scale, n, &wx);
        if (d > n) (void)cmpc_widest_row(lo + i * d + n, hi + i * d + n, u_scale, d - n, &wu);
        u_can[i] = (unsigned char)(d > n && wu > u_eps);
        cnt[k] += 1;
        if (lab[i] == 1) { n_in[k] += 1; if (first_in[k] == N) first_in[k] = i; }
        if (lab[i] == -1) n_out[k] += 1;
        if (first_any[k] == N) first_any[k] = i;
        gflag[k] = (unsigned char)((gflag[k] & ~8) | (wx <= eps ? 8 : 0)); /* last wins */
    }
    for (int64_t k = 0; k < G; ++k) {
        if (n_in[k] > 0) gflag[k] |= 1;
        else if (cnt[k] > 0 && n_out[k] == cnt[k]) gflag[k] |= 2;
    }
    for (int64_t i = 0; i < N; ++i) {
        int64_t k = g[i];
        if (!(gflag[k] & 3) && lab[i] != 1 && lab[i] != -1) {
            n_live[k] += 1;
            if (u_can[i]) n_split[k] += 1;
            if (first_und[k] == N) first_und[k] = i;
        }
    }
    for (int64_t k = 0; k < G; ++k) {
        if (n_split[k] > 0 && n_live[k] + n_split[k] <= max_cells) gflag[k] |= 4;
        if (!(gflag[k] & 3) && !(gflag[k] & 4) && (gflag[k] & 8)) gflag[k] |= 16;
    }
    for (int64_t i = 0; i < N; ++i) {
        int64_t k = g[i];
        unsigned char f = gflag[k];
        signed char o = 2;
        if ((f & 1) && first_in[k] == i) o = 1;
        else if ((f & 2) && first_any[k] == i) o = -1;
        else if (!(f & 3) && lab[i] != 1 && lab[i] != -1)
            o = (f & 16) ? (first_und[k] == i ? 0 : 2) : 0;
        out[i] = o;
        small[i] = (unsigned char)((f & 16) && first_und[k] == i);
        u_mode[i] = (unsigned char)((f & 4) != 0);
    }
}

/* PairFrontier.split of the pairs sel (M indices, increasing) of a frontier (N pairs of d
 * coordinates, n of them the state): children (at most 2 M rows) and stuck state boxes (at
 * most M rows), with the source pair of each row (its data) and its group. Scratch: G
 * groups (ids < G): first (int64, set to -1), glo/ghi (G d, set to +inf / -inf), gk (int64),
 * gc (double), gok (uint8, zeroed), rank (int64, zeroed); per selected pair: pk (int64),
 * pc (double), pok (uint8). counts: n_uok, n_keep1, n_keep2, G2_ok, n_stuck, n_present_u. */
void cmpc_pair_split(int64_t M, const int64_t *sel, int64_t d, int64_t n,
                     const double *lo, const double *hi, const int64_t *g,
                     const unsigned char *mode, const unsigned char *can,
                     const double *u_scale, const double *x_scale, double x_ratio,
                     int64_t G, int64_t *first, double *glo, double *ghi, int64_t *gk,
                     double *gc, unsigned char *gok, int64_t *rank,
                     int64_t *pk, double *pc, unsigned char *pok,
                     double *clo, double *chi, int64_t *csrc, int64_t *cgrp,
                     double *slo, double *shi, int64_t *ssrc, int64_t *sgrp, int64_t *counts)
{
    const int64_t m = d - n;
    int64_t n_uok = 0, n_keep1 = 0, n_keep2 = 0, g2 = 0, n_stuck = 0;
    for (int64_t t = 0; t < M; ++t) {
        const int64_t i = sel[t], k = g[i];
        const double *l = lo + i * d, *h = hi + i * d;
        if (mode[i]) {
            if (can[i]) {
                double wu;
                const int64_t j = n + cmpc_widest_row(l + n, h + n, u_scale, m, &wu);
                pk[t] = j;
                pok[t] = (unsigned char)cmpc_cut(l[j], h[j], 0.5, 1, pc + t);
                if (pok[t]) n_uok++; else n_keep2++;
            } else {
                n_keep1++;
            }
        } else {
            if (first[k] < 0) first[k] = i;
            cmpc_hull_add(glo + k * d, ghi + k * d, l, h, d);
        }
    }
    for (int64_t k = 0; k < G; ++k) {
        if (first[k] < 0) continue;
        double wx;
        gk[k] = cmpc_widest_row(glo + k * d, ghi + k * d, x_scale, n, &wx);
        gok[k] = (unsigned char)cmpc_cut(glo[k * d + gk[k]], ghi[k * d + gk[k]], x_ratio,
                                         x_ratio == 0.5, gc + k);
        if (gok[k]) g2++; else n_stuck++;
    }
    /* rows: u left halves, u right halves, keep (cells not split), keep (cut failed), state
     * left halves, state right halves */
    int64_t r_left = 0, r_right = n_uok, r_k1 = 2 * n_uok, r_k2 = 2 * n_uok + n_keep1;
    for (int64_t t = 0; t < M; ++t) {
        const int64_t i = sel[t];
        if (!mode[i]) continue;
        const double *l = lo + i * d, *h = hi + i * d;
        rank[g[i]] = 1;
        if (can[i] && pok[t]) {
            double *l1 = clo + r_left * d, *h1 = chi + r_left * d;
            double *l2 = clo + r_right * d, *h2 = chi + r_right * d;
            for (int64_t j = 0; j < d; ++j) { l1[j] = l2[j] = l[j]; h1[j] = h2[j] = h[j]; }
            h1[pk[t]] = pc[t];
            l2[pk[t]] = pc[t];
            csrc[r_left] = csrc[r_right] = i;
            cgrp[r_left++] = cgrp[r_right++] = g[i];
        } else {
            int64_t r = can[i] ? r_k2++ : r_k1++;
            for (int64_t j = 0; j < d; ++j) { clo[r * d + j] = l[j]; chi[r * d + j] = h[j]; }
            csrc[r] = i;
            cgrp[r] = g[i];
        }
    }
    int64_t n_u = 2 * n_uok + n_keep1 + n_keep2, n_pu = 0;
    for (int64_t k = 0; k < G; ++k) {  /* dense ids: the cell-splitting groups first */
        int64_t present = rank[k];
        rank[k] = n_pu;
        n_pu += present;
    }
    for (int64_t r = 0; r < n_u; ++r) cgrp[r] = rank[cgrp[r]];
    int64_t xl = n_u, xr = n_u + g2, q = 0, s = 0;
    for (int64_t k = 0; k < G; ++k) {
        if (first[k] < 0) continue;
        const double *a = glo + k * d, *b = ghi + k * d;
        if (gok[k]) {
            double *l1 = clo + xl * d, *h1 = chi + xl * d;
            double *l2 = clo + xr * d, *h2 = chi + xr * d;
            for (int64_t j = 0; j < d; ++j) { l1[j] = l2[j] = a[j]; h1[j] = h2[j] = b[j]; }
            h1[gk[k]] = gc[k];
            l2[gk[k]] = gc[k];
            csrc[xl] = csrc[xr] = first[k];
            cgrp[xl++] = n_pu + q;
            cgrp[xr++] = n_pu + g2 + q;
            q++;
        } else {
            for (int64_t j = 0; j < d; ++j) { slo[s * d + j] = a[j]; shi[s * d + j] = b[j]; }
            ssrc[s] = first[k];
            sgrp[s++] = k;
        }
    }
    counts[0] = n_uok; counts[1] = n_keep1; counts[2] = n_keep2; counts[3] = g2;
    counts[4] = n_stuck; counts[5] = n_pu;
}
"""
_GROUP_MIN = 64  # smaller batches stay in numpy (the C call's fixed cost)


_I64, _PTR = ctypes.c_int64, ctypes.c_void_p
_GROUP_ARGS = {"cmpc_group_first": [_I64, _PTR, _PTR, _PTR],
               "cmpc_group_hull": [_I64, _I64, _PTR, _PTR, _PTR, _PTR, _PTR],
               "cmpc_pair_reduce": [_I64, _I64, _PTR, _PTR, _I64, _I64, _PTR, _PTR, _PTR,
                                    _PTR, ctypes.c_double, ctypes.c_double, _PTR, _I64]
               + [_PTR] * 12,
               "cmpc_pair_split": [_I64, _PTR, _I64, _I64, _PTR, _PTR, _PTR, _PTR, _PTR,
                                   _PTR, _PTR, ctypes.c_double, _I64] + [_PTR] * 19}


def _group_kernel(name: str, wait: bool = False) -> Any:
    """The C loop ``name`` of :data:`_GROUP_C`, or None (not available, or still compiling
    with ``wait=False``)."""
    return c_function(_GROUP_C, name, _GROUP_ARGS[name], wait)


def _group_first(group: np.ndarray, mask: np.ndarray, G: int) -> np.ndarray:
    """Per group, the lowest element index with ``mask`` (``len(mask)`` where none), (G,)."""
    N = group.shape[0]
    first = np.full(G, N, dtype=np.intp)
    fn = _group_kernel("cmpc_group_first") if N >= _GROUP_MIN else None
    if fn is not None:
        # converted arrays held by names until the call returns (an address alone does not
        # keep a temporary copy alive)
        g64 = np.ascontiguousarray(group, dtype=np.int64)
        m8 = np.ascontiguousarray(mask, dtype=bool)
        fn(N, address(g64), address(m8), address(first))
        return first
    idx = np.flatnonzero(mask)
    np.minimum.at(first, group[idx], idx)
    return first


def _group_hull(inv: np.ndarray, G: int, lo: np.ndarray, hi: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per group ``inv`` (dense ids < G), the hull of the boxes ``lo``, ``hi`` (N, d)."""
    d = lo.shape[1]
    glo = np.full((G, d), np.inf)
    ghi = np.full((G, d), -np.inf)
    fn = _group_kernel("cmpc_group_hull") if lo.shape[0] >= _GROUP_MIN else None
    if fn is not None:
        inv64 = np.ascontiguousarray(inv, dtype=np.int64)
        lo = np.ascontiguousarray(lo, dtype=float)
        hi = np.ascontiguousarray(hi, dtype=float)
        fn(lo.shape[0], d, address(inv64), address(lo), address(hi), address(glo),
           address(ghi))
        return glo, ghi
    np.minimum.at(glo, inv, lo)
    np.maximum.at(ghi, inv, hi)
    return glo, ghi


@dataclass
class PairFrontier:
    """(state box, control cell) pairs of a nested existential search, grouped by state box.

    The element ``k`` is the joint box ``[lo[k], hi[k]]`` of shape ``(n + m,)``: a state box
    (the first ``n`` components) and a cell of the control box (the last ``m``). Pairs with
    the same ``group`` share their state box; the cells of a group, together with the cells
    already proven useless for that box (or for a box containing it), cover the control box.
    This is the frontier of thesis Alg 4.6 and Alg 6.1, with the two nested loops run
    breadth-first, batched over all pairs.

    A classifier labels **pairs**: ``INNER`` (the pair proves its state box: some control of
    the cell works for every state of the box; it writes the proving control into
    ``data``), ``OUTER`` (the cell is proven useless for the box) or ``UNDECIDED``.
    :meth:`reduce` turns them into labels of the **groups**:

    * a group is inner when one of its pairs is (one representative pair is kept, with its
      data: the proving control);
    * a group is outside when all its pairs are outer (its cells cover every control not
      proven useless before, so no control works);
    * an undecided group whose state box is at most ``eps`` wide (relative to ``x_scale``)
      and whose cells cannot be split (narrower than ``u_eps`` relative to ``u_scale``, or
      ``max_cells`` reached) is boundary (one representative);
    * every other pair of a finished group, and every useless cell of a live group, is
      ``DROPPED``.

    :meth:`split` bisects, per group, the control cells while one of them can be split
    (widest component relative to ``u_scale``: a per-dimension split mask), and otherwise
    the state box (widest component relative to ``x_scale``); both halves of a state box
    inherit the hull of the surviving cells of their group (one cell each), or, with
    ``restart`` set, the whole control box with the per-pair data of ``restart`` (the
    nested search starts again for each state box, as in thesis Alg 5.2).

    **Shared exclusion.** With ``shared`` naming a data key of shape (N, C), a pair label
    ``OUTER`` only drops the cell, and a group is outside when there is a column ``c`` at
    which every pair of the group is excluded (``data[shared][k, c]`` or labelled
    ``OUTER``; the classifier labels a pair ``OUTER`` only when its cell is excluded at
    every column). This is the exclusion of ``for all w exists u``: the columns are points
    of W shared by all cells of a state box, and a cell may be dropped only when it fails at
    all of them, so that the dropped cells and the live ones still cover the control box
    at each column.

    Attributes
    ----------
    lo, hi : ndarray (N, n + m)
    group : ndarray (N,) of int
    n : int
        Number of state components.
    x_scale, u_scale : ndarray (n,), (m,)
        Widths against which state and control widths are measured.
    u_eps : float
        Cells narrower than this (relative) are not split.
    max_cells : int
        Largest number of cells per state box.
    data : dict of ndarray, optional
        Per-pair arrays (first axis N) kept by :meth:`take_done`, so proven pairs keep what
        the classifier wrote (e.g. ``"witness"``, the proving control, ``(N, m)``).
    u_box : ndarray (m, 2)
        The control box.
    restart : dict of ndarray, optional
        Per-pair data (first axis 1) given to the pairs of newly split state boxes, whose
        cell is then the whole control box (see the class notes); None: inherit the hull.
    shared : str, optional
        Data key of the shared exclusion columns (see the class notes).
    """

    lo: np.ndarray
    hi: np.ndarray
    group: np.ndarray
    n: int
    x_scale: np.ndarray
    u_scale: np.ndarray
    u_eps: float = 0.05
    max_cells: int = 64
    split_ratio: float = 0.5
    data: dict[str, np.ndarray] | None = None
    u_box: np.ndarray | None = None
    restart: dict[str, np.ndarray] | None = None
    shared: str | None = None
    _u_mode: np.ndarray | None = field(default=None, repr=False, compare=False)
    # per pair: its cell can still be split (set by reduce, kept by take, read by split)
    _u_can: np.ndarray | None = field(default=None, repr=False, compare=False)

    @classmethod
    def from_boxes(cls, X: np.ndarray, U: np.ndarray, *, x_scale: np.ndarray | None = None,
                   u_eps: float = 0.05, max_cells: int = 64,
                   data: dict[str, np.ndarray] | None = None,
                   restart: dict[str, np.ndarray] | None = None,
                   shared: str | None = None, split_ratio: float = 0.5) -> PairFrontier:
        """One pair per state box ``X`` (N, n, 2), each with the whole control box ``U``
        (m, 2); ``data`` arrays (first axis N) are attached; ``restart`` and ``shared``:
        see the class notes."""
        X = np.asarray(X, dtype=float)
        U = np.asarray(U, dtype=float).reshape(-1, 2)
        N, n = X.shape[0], X.shape[1]
        m = U.shape[0]
        lo = np.concatenate([X[..., 0], np.broadcast_to(U[:, 0], (N, m))], axis=1)
        hi = np.concatenate([X[..., 1], np.broadcast_to(U[:, 1], (N, m))], axis=1)
        du = U[:, 1] - U[:, 0]
        u_scale = np.where(du > 0, du, 1.0)
        if x_scale is None:
            x_scale = np.ones(n)
        if restart is not None:
            restart = {k: np.asarray(v)[:1] for k, v in restart.items()}
        if shared is not None and (data is None or shared not in data):
            raise ValueError(f"the shared exclusion key {shared!r} is not in data")
        return cls(np.ascontiguousarray(lo), np.ascontiguousarray(hi),
                   np.arange(N, dtype=np.intp), n, np.asarray(x_scale, dtype=float), u_scale,
                   float(u_eps), int(max_cells), float(split_ratio), data=data,
                   u_box=U.copy(), restart=restart, shared=shared)

    def __len__(self) -> int:
        return self.lo.shape[0]

    @property
    def m(self) -> int:
        return self.lo.shape[1] - self.n

    @property
    def x_boxes(self) -> np.ndarray:
        """State boxes, (N, n, 2)."""
        return np.stack([self.lo[:, : self.n], self.hi[:, : self.n]], axis=-1)

    @property
    def u_cells(self) -> np.ndarray:
        """Control cells, (N, m, 2)."""
        return np.stack([self.lo[:, self.n:], self.hi[:, self.n:]], axis=-1)

    @property
    def boxes(self) -> np.ndarray:
        """Joint boxes, (N, n + m, 2)."""
        return np.stack([self.lo, self.hi], axis=-1)

    def _with(self, lo: np.ndarray, hi: np.ndarray, group: np.ndarray,
              data: dict[str, np.ndarray] | None, u_mode: np.ndarray | None = None,
              u_can: np.ndarray | None = None) -> PairFrontier:
        return PairFrontier(lo, hi, group, self.n, self.x_scale, self.u_scale, self.u_eps,
                            self.max_cells, self.split_ratio, data, self.u_box, self.restart,
                            self.shared, u_mode, u_can)

    def take(self, mask: np.ndarray) -> PairFrontier:
        idx = np.asarray(mask)
        if idx.dtype == bool:
            idx = np.flatnonzero(idx)
        data = None if self.data is None else {
            k: v.take(idx, axis=0) for k, v in self.data.items()}
        mode = None if self._u_mode is None else self._u_mode.take(idx)
        can = None if self._u_can is None else self._u_can.take(idx)
        return self._with(self.lo.take(idx, axis=0), self.hi.take(idx, axis=0),
                          self.group.take(idx), data, mode, can)

    take_done = take  # proven pairs keep their data (the proving control)

    def width(self) -> np.ndarray:
        """Largest relative width of each state box, (N,)."""
        return widest_of(self.lo, self.hi, self.x_scale, 0, self.n)[0]

    def _u_splittable(self) -> np.ndarray:
        if self.m == 0:
            return np.zeros(len(self), dtype=bool)
        return widest_of(self.lo, self.hi, self.u_scale, self.n)[0] > self.u_eps

    def reduce(self, labels: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
        """Group labels from pair labels (see the class notes): ``(labels, small)``."""
        N = len(self)
        out = np.full(N, DROPPED, dtype=np.int8)
        small = np.zeros(N, dtype=bool)
        if N == 0:
            return out, small
        g = self.group
        G = int(g.max()) + 1
        if self.shared is None and N >= _GROUP_MIN and max(self.n, self.m) <= _COLUMN_MAX:
            got = self._reduce_native(labels, eps, G)
            if got is not None:
                return got
        inner = labels == INNER
        outer = labels == OUTER
        g_in = np.bincount(g, weights=inner, minlength=G) > 0
        cnt = np.bincount(g, minlength=G)
        if self.shared is None:
            g_out = (np.bincount(g, weights=outer, minlength=G) == cnt) & ~g_in
        else:  # a column at which every cell of the group is excluded
            E = np.asarray(self.data[self.shared], dtype=bool) | outer[:, None]
            miss = np.zeros((G, E.shape[1]), dtype=np.int64)
            np.add.at(miss, g, ~E)
            g_out = (miss == 0).any(axis=1) & ~g_in
        g_out &= cnt > 0  # ids of groups absent from this frontier label nothing
        rep_in = _group_first(g, inner, G)[g_in]
        out[rep_in] = INNER
        out[_group_first(g, np.ones(N, dtype=bool), G)[g_out]] = OUTER
        live = ~(g_in | g_out)
        und = live[g] & ~outer & ~inner
        out[und] = UNDECIDED
        # groups that can neither split a cell nor their state box are boundary
        self._u_can = self._u_splittable()
        split_u = und & self._u_can
        n_live = np.bincount(g, weights=und, minlength=G)
        n_split = np.bincount(g, weights=split_u, minlength=G)
        u_ok = (n_split > 0) & (n_live + n_split <= self.max_cells)
        x_small = np.zeros(G, dtype=bool)
        x_small[g] = self.width() <= eps
        exhausted = live & ~u_ok & x_small
        rep = _group_first(g, und, G)[exhausted]
        small[rep] = True
        out[und & exhausted[g]] = DROPPED
        out[rep] = UNDECIDED
        self._u_mode = u_ok[g]
        return out, small

    def _reduce_native(self, labels: np.ndarray, eps: float, G: int
                       ) -> tuple[np.ndarray, np.ndarray] | None:
        """:meth:`reduce` (without shared exclusion) as one C loop: the same labels, small
        flags and split modes; None where the loop is not available."""
        fn = _group_kernel("cmpc_pair_reduce")
        if fn is None:
            return None
        N, n, d = len(self), self.n, self.lo.shape[1]
        u_can = np.empty(N, dtype=bool)
        cnt = np.zeros((5, G), dtype=np.int64)  # cnt, n_in, n_out, n_live, n_split
        first = np.full((3, G), N, dtype=np.int64)  # first inner, first pair, first undecided
        gflag = np.zeros(G, dtype=np.uint8)
        out = np.empty(N, dtype=np.int8)
        small = np.empty(N, dtype=bool)
        mode = np.empty(N, dtype=bool)
        a = address
        c0 = a(cnt)
        f0 = a(first)
        lo = np.ascontiguousarray(self.lo, dtype=np.float64)
        hi = np.ascontiguousarray(self.hi, dtype=np.float64)
        xs = np.ascontiguousarray(np.broadcast_to(self.x_scale, (n,)), dtype=np.float64)
        us = np.ascontiguousarray(self.u_scale, dtype=np.float64) if d > n else xs
        g64 = np.ascontiguousarray(self.group, dtype=np.int64)  # held until the call returns
        lab = np.ascontiguousarray(labels, dtype=np.int8)
        fn(N, G, a(g64), a(lab), d, n, a(lo), a(hi), a(xs), a(us),
           float(eps), float(self.u_eps), a(u_can), self.max_cells, c0, c0 + 8 * G,
           c0 + 16 * G, c0 + 24 * G, c0 + 32 * G, f0, f0 + 8 * G, f0 + 16 * G, a(gflag),
           a(out), a(small), a(mode))
        self._u_mode, self._u_can = mode, u_can
        return out, small

    def split(self) -> tuple[PairFrontier, PairFrontier]:
        """``(children, stuck)``: cells bisected in groups that can still split a cell, state
        boxes bisected in the others (see the class notes); ``stuck``: state boxes that
        cannot be split in floating point (one pair per group)."""
        N, n = len(self), self.n
        mode = self._u_mode
        if mode is None:
            mode = np.zeros(N, dtype=bool)
            mode_g = np.zeros(int(self.group.max()) + 1 if N else 0, dtype=bool)
            mode_g[self.group[self._u_splittable()]] = True
            mode = mode_g[self.group] if N else mode
        parts: list[PairFrontier] = []
        # --- groups splitting their cells ---------------------------------------------
        iu = np.flatnonzero(mode)
        if iu.size:
            P = self if iu.size == N else self.take(iu)
            can = P._u_can if P._u_can is not None else P._u_splittable()
            keep = P.take(~can)
            S = P if can.all() else P.take(can)
            if len(S):
                lo2, hi2, ok = S._halves(widest_of(S.lo, S.hi, S.u_scale, n)[1] + n, 0.5)
                if not ok.all():
                    keep = PairFrontier._join([keep, S.take(~ok)])
                    S = S.take(ok)
                data = None if S.data is None else {
                    key: np.concatenate([v, v]) for key, v in S.data.items()}
                parts.append(self._with(lo2, hi2, np.concatenate([S.group, S.group]), data))
            if len(keep):
                parts.append(keep)
        # --- groups splitting their state box -----------------------------------------
        ix = np.flatnonzero(~mode)
        stuck = self.take(ix[:0])
        if ix.size:
            P = self if ix.size == N else self.take(ix)
            ug, inv = _dense_ids(P.group)
            G = ug.size
            lo, hi = _group_hull(inv, G, P.lo, P.hi)
            first = _group_first(inv, np.ones(len(P), dtype=bool), G)
            data = None if P.data is None else {
                key: v.take(first, axis=0) for key, v in P.data.items()}
            if self.restart is not None:  # the nested search starts again from U
                lo[:, n:] = self.u_box[:, 0]
                hi[:, n:] = self.u_box[:, 1]
                data = dict(data or {})
                data.update({key: np.repeat(v, G, axis=0) for key, v in self.restart.items()})
            H = self._with(lo, hi, ug, data)
            lo2, hi2, ok = H._halves(widest_of(H.lo, H.hi, H.x_scale, 0, n)[1],
                                     self.split_ratio)
            if not ok.all():
                stuck = H.take(~ok)
                H = H.take(ok)
            G2 = len(H)
            data = None if H.data is None else {
                key: np.concatenate([v, v]) for key, v in H.data.items()}
            # fresh group ids, beyond those of the cell-splitting groups
            base = int(self.group.max()) + 1
            gid = base + np.arange(2 * G2, dtype=np.intp)
            parts.append(self._with(lo2, hi2, gid, data))
        children = PairFrontier._join(parts) if parts else self.take(ix[:0])
        # dense group ids keep the per-group arrays of reduce small
        if len(children):
            children.group = _dense_ids(children.group)[1]
        return children, stuck

    def split_selected(self, idx: np.ndarray) -> tuple[PairFrontier, PairFrontier]:
        """``self.take(idx).split()`` for increasing indices ``idx`` (the pairs that grow):
        the same children and stuck boxes, in the same order, by one C pass over the
        selected pairs where it is available (numpy otherwise)."""
        idx = np.asarray(idx)
        if idx.dtype == bool:  # a mask, as take() reads it
            idx = np.flatnonzero(idx)
        idx = np.ascontiguousarray(idx, dtype=np.int64)  # held until the call returns
        fn = _group_kernel("cmpc_pair_split") if idx.size >= _GROUP_MIN else None
        # (more than _COLUMN_MAX coordinates: widest_of's numpy rule picks a NaN width, the
        # C loop's does not; the numpy split keeps that rule there)
        if fn is None or self.n > _COLUMN_MAX or self.m > _COLUMN_MAX or (
                self.restart is not None and (
                    self.data is None or not set(self.restart) <= set(self.data))):
            return self.take(idx).split()
        n, d = self.n, self.lo.shape[1]
        mode, can = self._u_mode, self._u_can
        if can is None:
            can = self._u_splittable()
        if mode is None:
            mode_g = np.zeros(int(self.group.max()) + 1, dtype=bool)
            sg = self.group.take(idx)
            mode_g[sg[can.take(idx)]] = True  # (a group splits its cells if one of the
            mode = mode_g[self.group]          # selected pairs can)
        M = idx.size
        g = np.ascontiguousarray(self.group, dtype=np.int64)
        G = int(g.take(idx).max()) + 1
        first = np.full(G, -1, dtype=np.int64)
        glo = np.full((G, d), np.inf)
        ghi = np.full((G, d), -np.inf)
        gk = np.empty(G, dtype=np.int64)
        gc = np.empty(G)
        gok = np.zeros(G, dtype=np.uint8)
        rank = np.zeros(G, dtype=np.int64)
        pk = np.empty(M, dtype=np.int64)
        pc = np.empty(M)
        pok = np.zeros(M, dtype=np.uint8)
        clo = np.empty((2 * M, d))
        chi = np.empty((2 * M, d))
        csrc = np.empty(2 * M, dtype=np.int64)
        cgrp = np.empty(2 * M, dtype=np.int64)
        slo = np.empty((M, d))
        shi = np.empty((M, d))
        ssrc = np.empty(M, dtype=np.int64)
        sgrp = np.empty(M, dtype=np.int64)
        counts = np.zeros(6, dtype=np.int64)
        us = np.ascontiguousarray(self.u_scale, dtype=np.float64) if self.m else np.ones(1)
        xs = np.ascontiguousarray(np.broadcast_to(self.x_scale, (n,)), dtype=np.float64)
        a = address
        lo = np.ascontiguousarray(self.lo, dtype=np.float64)
        hi = np.ascontiguousarray(self.hi, dtype=np.float64)
        mode8 = np.ascontiguousarray(mode, dtype=bool)
        can8 = np.ascontiguousarray(can, dtype=bool)
        fn(M, a(idx), d, n, a(lo), a(hi), a(g), a(mode8), a(can8),
           a(us), a(xs), float(self.split_ratio), G, a(first), a(glo), a(ghi), a(gk), a(gc),
           a(gok), a(rank), a(pk), a(pc), a(pok), a(clo), a(chi), a(csrc), a(cgrp), a(slo),
           a(shi), a(ssrc), a(sgrp), a(counts))
        n_uok, n_keep1, n_keep2, g2, n_stuck, _ = (int(v) for v in counts)
        n_u = 2 * n_uok + n_keep1 + n_keep2
        nc = n_u + 2 * g2
        src = csrc[:nc]
        data = None if self.data is None else {
            key: v.take(src, axis=0) for key, v in self.data.items()}
        c_lo, c_hi = clo[:nc], chi[:nc]
        s_lo, s_hi, s_src = slo[:n_stuck], shi[:n_stuck], ssrc[:n_stuck]
        s_data = None if self.data is None else {
            key: v.take(s_src, axis=0) for key, v in self.data.items()}
        if self.restart is not None:  # the nested search starts again from U
            for L, H_, rows in ((c_lo, c_hi, slice(n_u, nc)), (s_lo, s_hi, slice(0, n_stuck))):
                L[rows, n:] = self.u_box[:, 0]
                H_[rows, n:] = self.u_box[:, 1]
            for key, v in self.restart.items():  # (data holds every restart key)
                v = np.asarray(v)
                data[key] = np.concatenate([data[key][:n_u], np.repeat(v, 2 * g2, axis=0)])
                s_data[key] = np.repeat(v, n_stuck, axis=0)
        children = self._with(c_lo, c_hi, cgrp[:nc].astype(np.intp, copy=False), data)
        stuck = self._with(s_lo, s_hi, sgrp[:n_stuck].astype(np.intp, copy=False), s_data)
        return children, stuck

    def _halves(self, k: np.ndarray, ratio: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Both halves of every pair cut in the joint coordinate ``k`` (N,) at ``ratio``.

        Returns ``(lo2, hi2, ok)``: the left halves then the right halves, shape
        (2 M, n + m), of the ``M`` pairs where the cut lies strictly inside coordinate ``k``
        (``ok``, shape (N,)); the other pairs are not split.
        """
        lo2, hi2, _, ok = bisect_widest(self.lo, self.hi, k=k, ratio=ratio)
        if not ok.all():
            keep = np.flatnonzero(ok)
            both = np.concatenate([keep, keep + len(self)])
            lo2, hi2 = lo2.take(both, axis=0), hi2.take(both, axis=0)
        return lo2, hi2, ok

    def bisect(self) -> PairFrontier:
        children, stuck = self.split()
        return PairFrontier.concat([children, stuck]) if len(stuck) else children

    @staticmethod
    def _join(parts: list[PairFrontier]) -> PairFrontier:
        """Join parts of one frontier (group ids kept as they are)."""
        return parts[0]._with(np.concatenate([p.lo for p in parts]),
                              np.concatenate([p.hi for p in parts]),
                              np.concatenate([p.group for p in parts]), _concat_data(parts))

    @staticmethod
    def concat(parts: list[PairFrontier]) -> PairFrontier:
        """Join frontiers; group ids are offset so that groups of different parts stay
        distinct."""
        if not parts:
            raise ValueError("nothing to concatenate")
        shifted, off = [], 0
        for p in parts:
            shifted.append(p._with(p.lo, p.hi, p.group + off, p.data))
            if len(p):
                off += int(p.group.max()) + 1
        return PairFrontier._join(shifted)
