"""Batched box geometry: widths, volumes, midpoints, hulls, membership, support, bisection.

A batch of boxes is a float array of shape ``(N, n, 2)``: ``[..., 0]`` lower bounds,
``[..., 1]`` upper bounds (``(n, 2)`` arrays and :class:`~casadi_cmpc.Box` are accepted as
one box). Every helper works on a whole batch at once. The public helpers are importable
from :mod:`casadi_cmpc.sets.paving`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._bisect import bisect_widest, midpoint
from .._validate import as_boxes, as_points
from ..exceptions import DimensionError, EmptySetError, InvalidBoundsError, UnboundedSetError
from .box import Box

__all__ = [
    "bisect_boxes",
    "box_volume",
    "box_width",
    "box_diam",
    "box_mid",
    "boxes_contain_points",
    "hull_of_boxes",
]

_BISECTION_RULES = ("widest",)
# largest number of (box, box) pairs examined in one vectorised step
_PAIR_BUDGET = 1 << 18


def _scale_widths(scale: Any, n: int) -> np.ndarray:
    """Normalise ``scale`` (widths (n,), a Box or an (n, 2) box) to non-negative widths."""
    if isinstance(scale, Box):
        s = scale.diam
    else:
        s = np.asarray(scale, dtype=float)
        if s.ndim == 3 and s.shape[0] == 1:
            s = s[0]
        if s.ndim == 2 and s.shape == (n, 2):
            s = s[:, 1] - s[:, 0]
    if s.shape != (n,):
        raise DimensionError(
            f"scale must be widths of shape ({n},) or an initial box of shape ({n}, 2); "
            f"got shape {np.shape(scale)}")
    if not np.isfinite(s).all() or (s < 0).any():
        raise InvalidBoundsError(
            f"scale must hold finite non-negative widths; got {s.tolist()}")
    return s


def _rel_widths(b: np.ndarray, scale: Any) -> np.ndarray:
    """Component widths of boxes ``b`` (N, n, 2), divided by ``scale`` when given: (N, n).

    A zero width counts 0 (also against a zero scale); a positive width against a zero
    scale is infinite.
    """
    with np.errstate(over="ignore"):
        w = b[..., 1] - b[..., 0]
    if scale is None:
        return w
    s = _scale_widths(scale, b.shape[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        r = w / s
    return np.where(w == 0, 0.0, r)


def box_diam(boxes: Any) -> np.ndarray:
    """Widths of every component.

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box

    Returns
    -------
    ndarray, shape (N, n)
        ``hi - lo`` per component (``inf`` for an infinite bound).
    """
    b = as_boxes(boxes, name="boxes")
    return b[..., 1] - b[..., 0]


def box_width(boxes: Any, scale: Any = None) -> np.ndarray:
    """Width of each box: its largest component width, thesis eq. (4.2).

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box
    scale : array_like, shape (n,), or Box, optional
        Widths of a reference (initial) box; when given the widths are measured relative to
        it, ``max_i (hi_i - lo_i) / scale_i``.

    Returns
    -------
    ndarray, shape (N,)

    See Also
    --------
    box_diam : the widths of all components, shape (N, n).
    """
    b = as_boxes(boxes, name="boxes")
    if b.shape[0] == 0:
        return np.zeros(0)
    return _rel_widths(b, scale).max(axis=1)


def box_volume(boxes: Any) -> np.ndarray:
    """Volume (product of the widths) of each box.

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box

    Returns
    -------
    ndarray, shape (N,)
        ``0`` for a box with a zero width (even when another width is infinite).
    """
    b = as_boxes(boxes, name="boxes")
    w = b[..., 1] - b[..., 0]
    flat = (w == 0).any(axis=1)
    with np.errstate(invalid="ignore"):
        v = np.prod(w, axis=1)
    return np.where(flat, 0.0, v)


def box_mid(boxes: Any) -> np.ndarray:
    """Midpoint of each box.

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box

    Returns
    -------
    ndarray, shape (N, n)
        ``(lo + hi) / 2``, inside the box even for huge or subnormal bounds; NaN for
        ``(-inf, inf)``.
    """
    b = as_boxes(boxes, name="boxes")
    with np.errstate(invalid="ignore"):
        return midpoint(b[..., 0], b[..., 1])


def hull_of_boxes(boxes: Any) -> np.ndarray:
    """Interval hull (smallest enclosing box) of a batch of boxes.

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box
        At least one box.

    Returns
    -------
    ndarray, shape (n, 2)

    Raises
    ------
    EmptySetError
        The batch holds no box.
    """
    b = as_boxes(boxes, name="boxes")
    if b.shape[0] == 0:
        raise EmptySetError("hull_of_boxes needs at least one box; got an empty batch")
    return np.stack([b[..., 0].min(axis=0), b[..., 1].max(axis=0)], axis=-1)


def boxes_contain_points(boxes: Any, points: Any) -> np.ndarray:
    """Membership matrix of points in boxes (closed boxes, bounds included).

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box
    points : array_like, shape (P, n) or (n,)

    Returns
    -------
    ndarray of bool, shape (N, P), or (N,) for a single point ``(n,)``
        Entry ``[i, k]`` is True when point ``k`` lies in box ``i``.
    """
    b = as_boxes(boxes, name="boxes")
    p, batched = as_points(points, b.shape[1], name="points")
    out = np.empty((b.shape[0], p.shape[0]), dtype=bool)
    step = max(1, _PAIR_BUDGET // max(1, b.shape[0] * b.shape[1]))
    for k0 in range(0, p.shape[0], step):
        q = p[None, k0:k0 + step, :]
        out[:, k0:k0 + step] = ((b[:, None, :, 0] <= q) & (q <= b[:, None, :, 1])).all(axis=2)
    return out if batched else out[:, 0]


def bisect_boxes(boxes: Any, rule: str = "widest", scale: Any = None,
                 split_ratio: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Bisect every box of a batch along its widest component (thesis eqs. (4.2)-(4.4)).

    Parameters
    ----------
    boxes : array_like, shape (N, n, 2) or (n, 2), or Box
        Bounded boxes that are not single points.
    rule : {"widest"}
        Choice of the split component: the widest one, ties going to the lowest index
        (eq. (4.3)).
    scale : array_like, shape (n,), or Box, or array_like, shape (n, 2), optional
        Widths of the initial box (or the initial box itself). When given, the widest
        component is the one with the largest ``width_i / scale_i`` (widths relative to the
        initial box). A zero scale makes a positive width infinitely wide.
    split_ratio : float
        Position of the cut in ``(0, 1)``: ``lo_j + split_ratio * (hi_j - lo_j)``, or
        ``(1 - split_ratio) lo_j + split_ratio hi_j`` where the first lands on a bound or
        overflows. ``0.5`` is the midpoint of eq. (4.4), ``(lo_j + hi_j) / 2`` correctly
        rounded; a value such as ``0.49`` (codac's default) avoids cutting at points of
        symmetry. The rule is that of every bisection of the library
        (:func:`casadi_cmpc._bisect.bisect_widest`).

    Returns
    -------
    left, right : ndarray, shape (N, n, 2)
        ``left`` keeps ``[lo_j, c]`` and ``right`` keeps ``[c, hi_j]`` in the split
        component ``j``; the other components are copied. Both share the face ``x_j = c``.

    Raises
    ------
    UnboundedSetError
        A box has an infinite bound.
    InvalidBoundsError
        A box is a single point, or its split component is too narrow to hold a float
        strictly between its bounds.
    ValueError
        Unknown ``rule`` or ``split_ratio`` outside ``(0, 1)``.

    Examples
    --------
    >>> import numpy as np
    >>> from casadi_cmpc.sets.paving import bisect_boxes
    >>> L, R = bisect_boxes(np.array([[[0.0, 1.0], [0.0, 1.0]]]))
    >>> L[0, 0].tolist(), R[0, 0].tolist()
    ([0.0, 0.5], [0.5, 1.0])
    >>> L, R = bisect_boxes(np.array([[[0.0, 1.0], [0.0, 1.0]]]), scale=[4.0, 1.0])
    >>> L[0, 1].tolist()
    [0.0, 0.5]
    """
    meth = str(rule).lower()
    if meth not in _BISECTION_RULES:
        raise ValueError(f"Unknown bisection rule {rule!r}; valid rules: {_BISECTION_RULES}")
    r = float(split_ratio)
    if not 0.0 < r < 1.0:
        raise ValueError(f"split_ratio must lie strictly between 0 and 1; got {split_ratio}")
    b = as_boxes(boxes, name="boxes")
    N = b.shape[0]
    if N == 0:
        return b.copy(), b.copy()
    bad = ~np.isfinite(b).all(axis=2)
    if bad.any():
        i, k = np.argwhere(bad)[0]
        raise UnboundedSetError(
            f"cannot bisect an unbounded box: box {i} has component {k} = "
            f"[{b[i, k, 0]}, {b[i, k, 1]}]; bisect bounded boxes only")
    rel = _rel_widths(b, scale)
    lo2, hi2, j, ok = bisect_widest(b[..., 0], b[..., 1], rel, ratio=r, exact_mid=True)
    rows = np.arange(N)
    lo, hi = b[rows, j, 0], b[rows, j, 1]
    point = lo == hi
    if point.any():
        i = int(np.flatnonzero(point)[0])
        raise InvalidBoundsError(
            f"cannot bisect box {i}: all its widths are zero (it is the point "
            f"{b[i, :, 0].tolist()})")
    if not ok.all():
        i = int(np.flatnonzero(~ok)[0])
        raise InvalidBoundsError(
            f"cannot bisect box {i}: component {int(j[i])} = [{lo[i]!r}, {hi[i]!r}] holds no "
            "float strictly between its bounds")
    left = np.stack([lo2[:N], hi2[:N]], axis=-1)
    right = np.stack([lo2[N:], hi2[N:]], axis=-1)
    return left, right


def _support_of_boxes(U: np.ndarray, D: np.ndarray) -> np.ndarray:
    """``max_j sum_l max(D_il lo_jl, D_il hi_jl)`` for each direction ``i``: shape (k,)."""
    if U.shape[0] == 0:
        return np.full(D.shape[0], -np.inf)
    if np.isfinite(U).all():
        return (np.maximum(D, 0.0) @ U[..., 1].T + np.minimum(D, 0.0) @ U[..., 0].T).max(axis=1)
    out = np.full(D.shape[0], -np.inf)
    step = max(1, _PAIR_BUDGET // max(1, U.shape[0] * U.shape[1]))
    for k0 in range(0, D.shape[0], step):
        d = D[k0:k0 + step, None, :]
        with np.errstate(invalid="ignore"):
            s = np.where(d == 0, 0.0, np.maximum(d * U[None, :, :, 0], d * U[None, :, :, 1]))
        out[k0:k0 + step] = s.sum(axis=2).max(axis=1)
    return out


def _corners(U: np.ndarray) -> np.ndarray:
    """The ``2**n`` corners of every box of ``U`` (N, n, 2), box by box: shape (N 2**n, n)."""
    n = U.shape[1]
    bits = ((np.arange(2 ** n)[:, None] >> np.arange(n)) & 1).astype(np.intp)
    return U[:, np.arange(n)[None, :], bits].reshape(-1, n)
