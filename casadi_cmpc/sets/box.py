"""Axis-aligned boxes (interval vectors)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import _first_string, as_boxes, as_float_array, as_points
from ..exceptions import DimensionError, EmptySetError, InvalidBoundsError
from .base import SetBase

__all__ = ["Box"]


class Box(SetBase):
    """An axis-aligned box ``[lo_1, hi_1] x ... x [lo_d, hi_d]``.

    Parameters
    ----------
    lo, hi : array_like, shape (d,)
        Lower and upper bounds. Infinite bounds are allowed (e.g. a target set
        ``[0, inf)``); NaN bounds and ``lo > hi`` are refused.

    Examples
    --------
    >>> import casadi_cmpc as cm
    >>> B = cm.Box([-1, 0], [1, 2])
    >>> B.as_array().shape
    (2, 2)
    >>> B.mid
    array([0., 1.])
    """


    def __init__(self, lo: Any, hi: Any = None) -> None:
        if hi is None:
            shape = np.shape(lo) if _first_string(lo) is None else "?"
            raise TypeError(
                "Box(lo, hi) takes the lower and the upper bounds as two arguments; got one "
                f"argument of shape {shape}. For an array of [lo, hi] rows (shape (d, 2), "
                "as returned by as_array()) use cm.Box.from_array(arr) or cm.Box(*arr.T); "
                "for an array [lo, hi] of shape (2, d) use cm.Box(*arr)")
        lo_a = np.atleast_1d(as_float_array(lo, "Box lo")).copy()
        hi_a = np.atleast_1d(as_float_array(hi, "Box hi")).copy()
        if lo_a.ndim != 1 or hi_a.ndim != 1:
            raise DimensionError(
                f"Box bounds must be 1-D; got lo shape {lo_a.shape}, hi shape {hi_a.shape}")
        if lo_a.shape != hi_a.shape:
            raise DimensionError(
                f"Box bounds differ in length: lo has {lo_a.size}, hi has {hi_a.size}")
        if np.isnan(lo_a).any() or np.isnan(hi_a).any():
            raise InvalidBoundsError("Box bounds contain NaN")
        bad = np.flatnonzero(lo_a > hi_a)
        if bad.size:
            i = int(bad[0])
            raise EmptySetError(
                f"Box is empty: lo[{i}] = {lo_a[i]} > hi[{i}] = {hi_a[i]}; "
                "give bounds with lo <= hi")
        lo_a.setflags(write=False)
        hi_a.setflags(write=False)
        self.lo = lo_a
        self.hi = hi_a

    @classmethod
    def from_array(cls, arr: Any) -> Box:
        """Build a box from a ``(d, 2)`` array of ``[lo, hi]`` rows (as :meth:`as_array`)."""
        a = as_float_array(arr, "Box.from_array arr")
        if a.ndim != 2 or a.shape[1] != 2:
            raise DimensionError(f"expected an array of shape (d, 2); got {a.shape}")
        return cls(a[:, 0], a[:, 1])

    @property
    def dim(self) -> int:
        """Dimension d."""
        return int(self.lo.size)

    def __len__(self) -> int:
        return self.dim

    def as_array(self) -> np.ndarray:
        """Bounds as an array of shape ``(d, 2)``."""
        return np.stack([self.lo, self.hi], axis=-1)

    @property
    def mid(self) -> np.ndarray:
        """Midpoint, shape (d,)."""
        return 0.5 * (self.lo + self.hi)

    @property
    def rad(self) -> np.ndarray:
        """Radius (half width), shape (d,)."""
        return 0.5 * (self.hi - self.lo)

    @property
    def diam(self) -> np.ndarray:
        """Width, shape (d,)."""
        return self.hi - self.lo

    def volume(self) -> float:
        """Product of the widths."""
        return float(np.prod(self.hi - self.lo))

    def is_bounded(self) -> bool:
        """True when every bound is finite."""
        return bool(np.isfinite(self.lo).all() and np.isfinite(self.hi).all())

    def contains(self, points: Any) -> np.ndarray | bool:
        """Membership of points.

        Parameters
        ----------
        points : array_like, shape (N, d) or (d,)

        Returns
        -------
        bool or ndarray of bool, shape (N,)
        """
        p, batched = as_points(points, self.dim, name="points")
        inside = ((p >= self.lo) & (p <= self.hi)).all(axis=1)
        return inside if batched else bool(inside[0])

    def sample(self, n: int, seed: int | np.random.Generator | None = None) -> np.ndarray:
        """Uniform random points of the box, shape (n, d). The box must be bounded."""
        if not self.is_bounded():
            raise ValueError("cannot sample an unbounded box")
        rng = np.random.default_rng(seed)
        return self.lo + (self.hi - self.lo) * rng.random((n, self.dim))

    def vertices(self) -> np.ndarray:
        """The 2**d corners, shape (2**d, d)."""
        d = self.dim
        bits = (np.arange(2 ** d)[:, None] >> np.arange(d)) & 1
        return np.where(bits.astype(bool), self.hi, self.lo)

    # ------------------------------------------------------------- protocol
    def is_empty(self) -> bool:
        """Always False: an empty box cannot be constructed."""
        return False

    def contains_box(self, boxes: Any) -> np.ndarray:
        """(N, d, 2) boxes -> (N,) bool: each box lies inside this box (exact test)."""
        b = as_boxes(boxes, self.dim, "boxes")
        return ((b[..., 0] >= self.lo) & (b[..., 1] <= self.hi)).all(axis=1)

    def intersects_box(self, boxes: Any) -> np.ndarray:
        """(N, d, 2) boxes -> (N,) bool: each box meets this box (exact test)."""
        b = as_boxes(boxes, self.dim, "boxes")
        return ((b[..., 0] <= self.hi) & (b[..., 1] >= self.lo)).all(axis=1)

    def support(self, directions: Any) -> np.ndarray | float:
        """Support function ``sum_i max(d_i lo_i, d_i hi_i)``; (k, d) -> (k,), (d,) -> float."""
        D = np.asarray(directions, dtype=float)
        single = D.ndim == 1
        D = np.atleast_2d(D)
        if D.shape[1] != self.dim:
            raise DimensionError(f"directions must have {self.dim} columns; got {D.shape[1]}")
        with np.errstate(invalid="ignore"):
            a = D * self.lo
            b = D * self.hi
        val = np.where(D == 0, 0.0, np.maximum(a, b)).sum(axis=1)
        return float(val[0]) if single else val

    def bounding_box(self) -> Box:
        """The box itself."""
        return self

    def is_subset(self, other: Box) -> bool:
        """True when this box lies inside ``other``."""
        return bool(np.all(self.lo >= other.lo) and np.all(self.hi <= other.hi))

    def __and__(self, other: Box) -> Box | None:
        """Intersection, or None when empty."""
        if not isinstance(other, Box):
            return NotImplemented
        lo = np.maximum(self.lo, other.lo)
        hi = np.minimum(self.hi, other.hi)
        return None if np.any(lo > hi) else Box(lo, hi)

    def __or__(self, other: Box) -> Box:
        """Interval hull of the two boxes."""
        if not isinstance(other, Box):
            return NotImplemented
        return Box(np.minimum(self.lo, other.lo), np.maximum(self.hi, other.hi))

    def _state(self) -> dict:
        return {"lo": np.array(self.lo), "hi": np.array(self.hi)}

    @classmethod
    def _from_state(cls, state: dict) -> Box:
        return cls(state["lo"], state["hi"])

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Box):
            return NotImplemented
        return bool(np.array_equal(self.lo, other.lo) and np.array_equal(self.hi, other.hi))

    def __hash__(self) -> int:
        return hash((self.lo.tobytes(), self.hi.tobytes()))

    def __repr__(self) -> str:
        lo = ", ".join(f"{a:.6g}" for a in self.lo)
        hi = ", ".join(f"{b:.6g}" for b in self.hi)
        return f"Box([{lo}], [{hi}])"
