"""One batched branch-and-bound engine for every interval solver.

A *frontier* of boxes (or zonotopes) is classified in one vectorised call per level; the
undecided elements are bisected together. Each solver is a *classifier* plugged into
:func:`branch_and_bound`:

``classify(frontier) -> labels`` with one ``int8`` per element: ``INNER`` (1, proven to have
the property; kept), ``OUTER`` (-1, proven not to have it; discarded) or ``UNDECIDED`` (0).
Undecided elements narrower than ``eps`` become *boundary*; the others are bisected.

The frontier is a plain array structure and every classification is a pure function of it,
so a level can be split across processes without touching the algorithms. Limits (``eps``,
``max_boxes``, ``time_limit``) and Ctrl-C stop the loop and return the partial result, which
is still sound: everything not classified is reported as boundary (undecided).
"""

from __future__ import annotations

import enum
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from ..exceptions import UnboundedSetError

__all__ = ["INNER", "OUTER", "UNDECIDED", "Status", "BoxFrontier", "BnBOutcome",
           "branch_and_bound"]

INNER = np.int8(1)
OUTER = np.int8(-1)
UNDECIDED = np.int8(0)


class Status(enum.IntEnum):
    """Outcome codes shared by the solvers (``success == (status == PROVED)``)."""

    PROVED = 0
    BUDGET = 1  # a limit (max_boxes, time_limit) or an interruption stopped the search
    DISPROVED = 2
    UNDECIDED = 3
    NUMERICAL = 4


class Frontier(Protocol):
    """What the engine needs from a frontier representation."""

    def __len__(self) -> int: ...

    def take(self, mask: np.ndarray) -> Frontier: ...

    def width(self) -> np.ndarray: ...

    def bisect(self) -> Frontier: ...

    @staticmethod
    def concat(parts: list[Any]) -> Any: ...


@dataclass
class BoxFrontier:
    """A batch of boxes as ``lo``, ``hi`` arrays of shape (N, n).

    ``bisect`` splits every box at ``split_ratio`` of its widest component (ties: lowest
    index; widths relative to ``scale`` when given), thesis eqs. (4.2)-(4.4).
    """

    lo: np.ndarray
    hi: np.ndarray
    scale: np.ndarray | None = None
    split_ratio: float = 0.5

    @classmethod
    def from_boxes(cls, boxes: np.ndarray, scale: np.ndarray | None = None,
                   split_ratio: float = 0.5) -> BoxFrontier:
        b = np.asarray(boxes, dtype=float)
        return cls(np.ascontiguousarray(b[..., 0]), np.ascontiguousarray(b[..., 1]), scale,
                   split_ratio)

    def __len__(self) -> int:
        return self.lo.shape[0]

    @property
    def boxes(self) -> np.ndarray:
        """(N, n, 2) array."""
        return np.stack([self.lo, self.hi], axis=-1)

    def take(self, mask: np.ndarray) -> BoxFrontier:
        return BoxFrontier(self.lo[mask], self.hi[mask], self.scale, self.split_ratio)

    def width(self) -> np.ndarray:
        """Largest component width of each box (relative to ``scale`` when given), (N,)."""
        w = self.hi - self.lo
        if self.scale is not None:
            w = w / self.scale
        return w.max(axis=1) if w.shape[1] else np.zeros(w.shape[0])

    def bisect(self) -> BoxFrontier:
        lo, hi = self.lo, self.hi
        w = hi - lo
        if self.scale is not None:
            w = w / self.scale
        k = np.argmax(w, axis=1)
        rows = np.arange(lo.shape[0])
        a = lo[rows, k]
        b = hi[rows, k]
        r = self.split_ratio
        c = a + r * (b - a) if r != 0.5 else 0.5 * a + 0.5 * b
        c = np.minimum(np.maximum(c, a), b)
        left_hi = hi.copy()
        left_hi[rows, k] = c
        right_lo = lo.copy()
        right_lo[rows, k] = c
        return BoxFrontier(np.concatenate([lo, right_lo]), np.concatenate([left_hi, hi]),
                           self.scale, self.split_ratio)

    @staticmethod
    def concat(parts: list[BoxFrontier]) -> BoxFrontier:
        if not parts:
            raise ValueError("nothing to concatenate")
        return BoxFrontier(np.concatenate([p.lo for p in parts]),
                           np.concatenate([p.hi for p in parts]), parts[0].scale,
                           parts[0].split_ratio)


@dataclass
class BnBOutcome:
    """Raw result of :func:`branch_and_bound`.

    Attributes
    ----------
    inner, boundary, outer : frontier
        Elements classified INNER; undecided elements narrower than eps (plus everything left
        when a limit stopped the search); elements classified OUTER (empty unless
        ``keep_outer``).
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


def branch_and_bound(frontier: Any, classify: Callable[[Any], np.ndarray], eps: float, *,
                     max_boxes: int = 5_000_000, time_limit: float | None = None,
                     keep_outer: bool = True, progress: bool | None = None,
                     desc: str = "branch and bound",
                     on_level: Callable[[int, Any, np.ndarray], None] | None = None
                     ) -> BnBOutcome:
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

    Returns
    -------
    BnBOutcome
    """
    from tqdm.auto import tqdm

    if not np.isfinite(eps) or eps <= 0:
        raise ValueError(f"eps must be a positive number; got {eps}")
    if isinstance(frontier, BoxFrontier) and not (
            np.isfinite(frontier.lo).all() and np.isfinite(frontier.hi).all()):
        raise UnboundedSetError("the initial box of a branch and bound must be bounded")
    t0 = time.perf_counter()
    inner: list[Any] = []
    boundary: list[Any] = []
    outer: list[Any] = []
    n_discarded = 0
    n_classified = 0
    level = 0
    status = Status.PROVED
    message = "search completed"
    history: list[dict] = []
    bar = tqdm(total=None, desc=desc, unit="box", disable=progress is False,
               delay=0 if progress else 2.0, leave=False)
    try:
        while len(frontier):
            if n_classified + len(frontier) > max_boxes:
                status, message = Status.BUDGET, f"max_boxes = {max_boxes} reached"
                break
            if time_limit is not None and time.perf_counter() - t0 > time_limit:
                status, message = Status.BUDGET, f"time_limit = {time_limit} s reached"
                break
            labels = np.asarray(classify(frontier), dtype=np.int8)
            n = len(frontier)
            n_classified += n
            if on_level is not None:
                on_level(level, frontier, labels)
            is_in = labels == INNER
            is_out = labels == OUTER
            und = ~(is_in | is_out)
            if is_in.any():
                inner.append(frontier.take(is_in))
            n_out = int(is_out.sum())
            n_discarded += n_out
            if keep_outer and n_out:
                outer.append(frontier.take(is_out))
            undecided = frontier.take(und)
            small = undecided.width() <= eps
            if small.any():
                boundary.append(undecided.take(small))
            frontier = undecided.take(~small).bisect() if (~small).any() else undecided.take(
                ~small)
            history.append({"level": level, "classified": n, "inner": int(is_in.sum()),
                            "outer": n_out, "boundary": int(small.sum())})
            bar.update(n)
            bar.set_postfix(level=level, frontier=len(frontier), refresh=False)
            level += 1
    except KeyboardInterrupt:
        status, message = Status.BUDGET, "interrupted"
    finally:
        bar.close()
    if len(frontier):
        boundary.append(frontier)  # unclassified leftovers are undecided: sound
    empty = frontier.take(np.zeros(len(frontier), dtype=bool))
    cat = type(frontier).concat
    return BnBOutcome(
        inner=cat(inner) if inner else empty,
        boundary=cat(boundary) if boundary else empty,
        outer=cat(outer) if outer else empty,
        n_discarded=n_discarded, status=status, message=message, levels=level,
        n_classified=n_classified, elapsed=time.perf_counter() - t0, history=history)
