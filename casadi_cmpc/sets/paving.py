"""Pavings (finite unions of boxes labelled inner / boundary / outside) and box helpers.

A batch of boxes is a float array of shape ``(N, n, 2)``: ``[..., 0]`` lower bounds,
``[..., 1]`` upper bounds. The batched box helpers exported here (``bisect_boxes``,
``box_width``, ...) work on whole batches at once; they are defined in
:mod:`casadi_cmpc.sets._boxes`, and the exact tests on unions of boxes behind
:class:`Paving` in :mod:`casadi_cmpc.sets._boxunion`.

A :class:`Paving` is what set inversion (SIVIA, thesis §4.1.2, Alg. 4.1) returns: the boxes of
the initial domain sorted into ``inner`` (proven inside the target set), ``boundary``
(undecided at the resolution ``eps``) and ``outside`` (proven outside, discarded).

Examples
--------
>>> import numpy as np
>>> import casadi_cmpc as cm
>>> from casadi_cmpc.sets.paving import bisect_boxes
>>> left, right = bisect_boxes(np.array([[[0.0, 4.0], [0.0, 2.0]]]))
>>> left[0].tolist(), right[0].tolist()
([[0.0, 2.0], [0.0, 2.0]], [[2.0, 4.0], [0.0, 2.0]])
>>> P = cm.Paving(inner=left, boundary=right, domain=cm.Box([0, 0], [4, 2]))
>>> P.volume(), P.volume(view="outer")
(4.0, 8.0)
>>> P.contains([[1.0, 1.0], [5.0, 1.0]])
array([ True, False])
>>> bool(P.contains_box(np.array([[[1.0, 3.0], [0.5, 1.5]]]))[0])
True
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._validate import as_boxes, as_points
from ..exceptions import DimensionError, EmptySetError, InvalidBoundsError
from ._boxes import *  # noqa: F403
from ._boxes import _PAIR_BUDGET, _corners, _support_of_boxes, hull_of_boxes  # noqa: F401
from ._boxes import __all__ as _boxes_all
from ._boxunion import _BoxGrid, _covered, _filter_pairs, _pairs, _union_volume  # noqa: F401
from .base import SetBase, held_set
from .box import Box

__all__ = ["Paving", *_boxes_all]

_VIEWS = ("outer", "inner", "boundary", "outside")
_DEFAULT_COLORS = {"inner": "#6abf69", "boundary": "#ffe066", "outside": "#c9d6e3"}
_DEFAULT_LABELS = {"inner": "inner", "boundary": "boundary", "outside": "outside"}


def _warn_outer(what: str, stacklevel: int = 3) -> None:
    """The DeprecationWarning of the old name ``outer`` of the proven-outside boxes."""
    warnings.warn(
        f"{what} is deprecated: the proven-outside boxes are now called 'outside' (the "
        "view 'outer' is inner ∪ boundary, the outer approximation); use 'outside'",
        DeprecationWarning, stacklevel=stacklevel)


def _outside_keyword(outside: Any, outer: Any, what: str) -> Any:
    """``outside``, or the deprecated keyword ``outer`` (with a warning); not both."""
    if outer is None:
        return outside
    _warn_outer(f"the keyword outer= of {what}", stacklevel=4)
    if outside is not None:
        raise TypeError(f"{what} got both outside= and its deprecated alias outer=; "
                        "pass outside= only")
    return outer


def _box_array(data: Any, n: int | None, name: str) -> np.ndarray:
    if isinstance(data, Sequence) and not isinstance(data, str):
        if len(data) == 0 and n is not None:
            data = np.zeros((0, n, 2))
        elif len(data) and all(isinstance(x, Box) for x in data):
            data = np.stack([x.as_array() for x in data])
    arr = np.array(as_boxes(data, n, name), dtype=float)
    arr.setflags(write=False)
    return arr


# ======================================================================== Paving
class Paving(SetBase):
    """A finite union of boxes, labelled with the three views of set inversion.

    Parameters
    ----------
    inner : array_like, shape (N_i, n, 2), or Box, or list of Box, optional
        Boxes proven inside the target set (SIVIA's Σ).
    boundary : array_like, shape (N_b, n, 2), or Box, or list of Box, optional
        Undecided boxes, narrower than the resolution ``eps`` (SIVIA's Σ^b).
    outside : array_like, shape (N_o, n, 2), or Box, or list of Box, optional
        Boxes proven outside the target set (discarded). A solver may keep them to draw the
        complement, or drop them and only count them in ``n_discarded``.
    domain : Box or array_like, shape (n, 2), optional
        The initial box the paving was built from; every box must lie in it.
    n_discarded : int, optional
        Number of boxes discarded as proven outside; defaults to ``len(outside)``.
    outer : deprecated
        Old name of ``outside`` (keyword only; emits a DeprecationWarning).

    Attributes
    ----------
    inner, boundary, outside : ndarray, shape (N, n, 2)
        Read-only arrays (possibly with ``N = 0``). ``outer`` is a deprecated alias of
        ``outside`` (it emits a DeprecationWarning).
    domain : Box or None
    n_discarded : int

    Raises
    ------
    DimensionError
        The arrays disagree in dimension, or no argument fixes the dimension.
    InvalidBoundsError, EmptySetError
        NaN bounds, a box with ``lo > hi``, or a box outside ``domain``.

    Notes
    -----
    **Which set is represented.** A paving stands for the *outer approximation* of the
    target set, ``inner ∪ boundary``: the protocol members ``contains``, ``contains_box``,
    ``intersects_box``, ``support``, ``bounding_box``, ``vertices`` and ``is_empty`` use it
    by default. The measures :meth:`volume` and :meth:`area` are the exception: by default
    they count the proven part only (view ``"inner"``), never undecided boxes. Each of them
    takes ``view=`` to choose another union:

    ``"outer"`` (default, except for ``volume`` and ``area``)
        ``inner ∪ boundary``: every point of the target set in the domain is in it.
    ``"inner"`` (default of ``volume`` and ``area``)
        ``inner``: every point of it is proven inside the target set.
    ``"boundary"``
        ``boundary`` only.
    ``"outside"``
        the ``outside`` boxes: every point of them is proven outside the target set.

    The *view* ``"outer"`` is the outer approximation; the discarded boxes are the attribute
    and view ``outside`` (the attribute was called ``outer`` before, a name kept as a
    deprecated alias).
    :meth:`inner_set` and :meth:`outer_set` return the two approximations as pavings of
    their own.

    A subpaving from bisection (thesis §4.1.1) has boxes with disjoint interiors; the
    paving does not require it (after :meth:`union` boxes may overlap) and its volume
    counts overlaps once.

    Examples
    --------
    >>> import numpy as np
    >>> import casadi_cmpc as cm
    >>> P = cm.Paving(inner=cm.Box([0, 0], [1, 1]), boundary=[cm.Box([1, 0], [2, 1])])
    >>> P.n_boxes, P.volume(), P.volume(view="outer")
    (2, 1.0, 2.0)
    >>> P.contains([1.5, 0.5]), P.contains([1.5, 0.5], view="inner")
    (True, False)
    """

    def __init__(self, inner: Any = None, boundary: Any = None, outside: Any = None,
                 domain: Any = None, *, n_discarded: int | None = None,
                 outer: Any = None) -> None:
        outside = _outside_keyword(outside, outer, "Paving()")
        if domain is not None:
            if not isinstance(domain, Box):
                d = np.asarray(domain, dtype=float)
                if d.ndim == 3 and d.shape[0] == 1:
                    d = d[0]
                domain = Box.from_array(d)
        n = domain.dim if domain is not None else None
        arrays = {}
        for name, data in (("inner", inner), ("boundary", boundary), ("outside", outside)):
            if data is not None:
                arrays[name] = _box_array(data, n, name)
                n = arrays[name].shape[1]
        if n is None:
            raise DimensionError(
                "Paving needs its dimension: give a domain Box or at least one box array "
                "(an empty array of shape (0, n, 2) is fine)")
        for name in ("inner", "boundary", "outside"):
            if name not in arrays:
                arrays[name] = _box_array(np.zeros((0, n, 2)), n, name)
        if domain is not None:
            for name, arr in arrays.items():
                out = ~domain.contains_box(arr) if arr.shape[0] else np.zeros(0, dtype=bool)
                if out.any():
                    i = int(np.flatnonzero(out)[0])
                    raise InvalidBoundsError(
                        f"{name} box {i} = {arr[i].tolist()} is not inside the domain {domain}")
        if n_discarded is None:
            n_discarded = arrays["outside"].shape[0]
        if int(n_discarded) != n_discarded or n_discarded < 0:
            raise ValueError(f"n_discarded must be a non-negative integer; got {n_discarded!r}")
        self._n = int(n)
        self.inner: np.ndarray = arrays["inner"]
        self.boundary: np.ndarray = arrays["boundary"]
        self.outside: np.ndarray = arrays["outside"]
        self.domain: Box | None = domain
        self.n_discarded = int(n_discarded)
        self._cache: dict[str, Any] = {}

    @classmethod
    def _from_solver(cls, inner: np.ndarray, boundary: np.ndarray, outside: np.ndarray,
                     domain: Box, n_discarded: int) -> Paving:
        """A paving from boxes a solver produced by bisecting ``domain``: float arrays of
        shape (N, n, 2) with lo <= hi, each box inside the domain, so no checks are made."""
        self = cls.__new__(cls)
        for arr in (inner, boundary, outside):
            arr.setflags(write=False)
        self._n = domain.dim
        self.inner, self.boundary, self.outside = inner, boundary, outside
        self.domain = domain
        self.n_discarded = int(n_discarded)
        self._cache = {}
        return self

    @property
    def outer(self) -> np.ndarray:
        """Deprecated alias of :attr:`outside` (the proven-outside boxes).

        Not to be confused with the *view* ``"outer"`` (``inner ∪ boundary``).
        """
        _warn_outer("Paving.outer")
        return self.outside

    # ---------------------------------------------------------------- views
    @property
    def boxes(self) -> np.ndarray:
        """The boxes of the represented set, ``inner`` then ``boundary``; shape (N, n, 2)."""
        if "boxes" not in self._cache:
            b = np.concatenate([self.inner, self.boundary])
            b.setflags(write=False)
            self._cache["boxes"] = b
        return self._cache["boxes"]

    def view_boxes(self, view: str = "outer") -> np.ndarray:
        """The boxes of one view.

        Parameters
        ----------
        view : {"outer", "inner", "boundary", "outside"}
            ``"outer"``: ``inner ∪ boundary`` (the default, the represented set);
            ``"outside"``: the discarded boxes of the attribute ``outside``.

        Returns
        -------
        ndarray, shape (N, n, 2)
        """
        v = str(view).lower()
        if v == "outer":
            return self.boxes
        if v == "inner":
            return self.inner
        if v == "boundary":
            return self.boundary
        if v == "outside":
            return self.outside
        raise ValueError(f"Unknown view {view!r}; valid views: {_VIEWS} ('outer' is "
                         "inner ∪ boundary, 'outside' the discarded boxes)")

    def inner_set(self) -> Paving:
        """The inner approximation as a paving: only the ``inner`` boxes (all proven inside)."""
        return Paving(inner=self.inner, domain=self.domain, n_discarded=0)

    def outer_set(self) -> Paving:
        """The outer approximation as a paving: ``inner`` and ``boundary``, no outside boxes."""
        return Paving(inner=self.inner, boundary=self.boundary, domain=self.domain,
                      n_discarded=0)

    @property
    def n_inner(self) -> int:
        """Number of inner boxes."""
        return int(self.inner.shape[0])

    @property
    def n_boundary(self) -> int:
        """Number of boundary boxes."""
        return int(self.boundary.shape[0])

    @property
    def n_outside(self) -> int:
        """Number of stored outside (discarded) boxes."""
        return int(self.outside.shape[0])

    @property
    def n_outer(self) -> int:
        """Deprecated alias of :attr:`n_outside`."""
        _warn_outer("Paving.n_outer")
        return self.n_outside

    @property
    def n_boxes(self) -> int:
        """Number of boxes of the represented set, ``n_inner + n_boundary``."""
        return self.n_inner + self.n_boundary

    def __len__(self) -> int:
        return self.n_boxes

    # ------------------------------------------------------------- protocol
    @property
    def dim(self) -> int:
        """Dimension n."""
        return self._n

    def is_empty(self, view: str = "outer") -> bool:
        """True when the view holds no box (then it is empty; boxes are never empty)."""
        return self.view_boxes(view).shape[0] == 0

    def contains(self, points: Any, view: str = "outer") -> np.ndarray | bool:
        """Membership of points in the union of the boxes of a view (bounds included).

        Parameters
        ----------
        points : array_like, shape (P, n) or (n,)
        view : {"outer", "inner", "boundary", "outside"}

        Returns
        -------
        bool or ndarray of bool, shape (P,)
        """
        p, batched = as_points(points, self._n, name="points")
        U = self.view_boxes(view)
        pb = np.stack([p, p], axis=-1)
        res = np.zeros(p.shape[0], dtype=bool)
        ia, _ = _pairs(pb, U)
        res[ia] = True
        return res if batched else bool(res[0])

    def contains_box(self, boxes: Any, view: str = "outer") -> np.ndarray:
        """Exact test ``box ⊆ union of the boxes of a view``, for a batch of boxes.

        Parameters
        ----------
        boxes : array_like, shape (N, n, 2) or (n, 2), or Box
        view : {"outer", "inner", "boundary", "outside"}

        Returns
        -------
        ndarray of bool, shape (N,)

        Notes
        -----
        A box covered by one box of the union is found by one vectorised comparison. The
        others are covered by several boxes together or not at all: the boxes meeting them
        are subtracted one after another (a box minus a box is at most ``2 n`` boxes) until
        nothing or a part outside every box is left. The test is exact on closed boxes.
        """
        q = as_boxes(boxes, self._n, "boxes")
        grid = self._grid(view, q.shape[0])
        if grid is not None:
            return grid.contains(q)
        return _covered(q, self.view_boxes(view))

    def _grid(self, view: str, n_queries: int) -> _BoxGrid | None:
        """The exact grid index of a view (built once, for unions of 64 boxes or more, or
        at the first batch of 32 queries or more)."""
        key = ("grid", str(view).lower())
        if key in self._cache:
            return self._cache[key]
        U = self.view_boxes(view)
        if U.shape[0] < 64 and (n_queries < 32 or U.shape[0] < 2):
            return None
        if key not in self._cache:
            self._cache[key] = _BoxGrid.build(U)
        return self._cache[key]

    def intersects_box(self, boxes: Any, view: str = "outer") -> np.ndarray:
        """Exact test ``box ∩ union ≠ ∅`` (closed boxes: a shared face counts).

        Parameters
        ----------
        boxes : array_like, shape (N, n, 2) or (n, 2), or Box
        view : {"outer", "inner", "boundary", "outside"}

        Returns
        -------
        ndarray of bool, shape (N,)
        """
        q = as_boxes(boxes, self._n, "boxes")
        grid = self._grid(view, q.shape[0])
        if grid is not None:
            return grid.intersects(q)
        res = np.zeros(q.shape[0], dtype=bool)
        ia, _ = _pairs(q, self.view_boxes(view))
        res[ia] = True
        return res

    def support(self, directions: Any, view: str = "outer") -> np.ndarray | float:
        """Support function ``h(d) = max over the boxes of the box support``.

        Parameters
        ----------
        directions : array_like, shape (k, n) or (n,)
        view : {"outer", "inner", "boundary", "outside"}

        Returns
        -------
        float or ndarray, shape (k,)
            ``-inf`` for an empty view.
        """
        D = np.asarray(directions, dtype=float)
        single = D.ndim == 1
        D = np.atleast_2d(D)
        if D.ndim != 2 or D.shape[1] != self._n:
            raise DimensionError(f"directions must have shape (k, {self._n}) or "
                                 f"({self._n},); got {np.shape(directions)}")
        val = _support_of_boxes(self.view_boxes(view), D)
        return float(val[0]) if single else val

    def bounding_box(self, view: str = "outer") -> Box:
        """Interval hull of the boxes of a view.

        Raises
        ------
        EmptySetError
            The view holds no box.
        """
        U = self.view_boxes(view)
        if U.shape[0] == 0:
            raise EmptySetError(f"the {view!r} view of this paving is empty; it has no "
                                "bounding box")
        return Box.from_array(hull_of_boxes(U))

    def vertices(self, view: str = "outer") -> np.ndarray:
        """Points whose convex hull is the convex hull of the union, shape (k, n).

        For ``n <= 3`` the vertices of the convex hull of all box corners (all distinct
        corners when the hull is flat or unbounded); for ``n > 3`` all distinct corners.
        ``(0, n)`` for an empty view.
        """
        U = self.view_boxes(view)
        n = self._n
        if U.shape[0] == 0:
            return np.zeros((0, n))
        if n == 1:
            h = hull_of_boxes(U)
            return np.unique(h.reshape(2, 1), axis=0)
        pts = np.unique(_corners(U), axis=0)
        if n <= 3 and len(pts) > n + 1 and np.isfinite(pts).all():
            from scipy.spatial import ConvexHull, QhullError

            try:
                return pts[np.sort(ConvexHull(pts).vertices)]
            except (QhullError, ValueError):
                return pts
        return pts

    # ------------------------------------------------------------- measures
    def volume(self, view: str = "inner") -> float:
        """Volume of the union of the boxes of a view (overlaps counted once).

        Parameters
        ----------
        view : {"inner", "outer", "boundary", "outside"}
            ``"inner"`` (default): the proven part only, a lower bound of the volume of the
            target set in the domain; ``"outer"``: inner and undecided boxes, an upper bound
            of it; ``"boundary"``: the undecided boxes; ``"outside"``: the boxes proven
            outside.

        Returns
        -------
        float
            In the units of the state product (e.g. an area in 2-D); 0.0 for an empty view.
        """
        v = str(view).lower()
        key = "volume:" + v
        if key not in self._cache:
            self._cache[key] = _union_volume(self.view_boxes(v))
        return self._cache[key]

    def area(self, view: str = "inner") -> float:
        """Area of a 2-D paving (alias of :meth:`volume`; by default of the proven part).

        Raises
        ------
        DimensionError
            The paving is not 2-dimensional.
        """
        if self._n != 2:
            raise DimensionError(
                f"area requires a paving of dimension 2 but received a {self._n}-dimensional "
                "one; use volume()")
        return self.volume(view)

    # ----------------------------------------------------------- operations
    def union(self, other: Paving | Box) -> Paving:
        """Union of two pavings (or a paving and a Box, taken as proven inside).

        ``inner`` and ``boundary`` boxes are concatenated; the outside boxes of the result
        are the intersections of the outside boxes of both (outside both sets); the domain
        is the hull of both domains (None when one is unknown).

        Parameters
        ----------
        other : Paving or Box

        Returns
        -------
        Paving
        """
        other = held_set(other)  # a solver's result: its paving
        if isinstance(other, Box):
            other = Paving(inner=other)
        if not isinstance(other, Paving):
            raise TypeError(f"cannot unite a Paving with a {type(other).__name__}")
        if other.dim != self._n:
            raise DimensionError(
                f"cannot unite pavings of dimensions {self._n} and {other.dim}")
        A, B = self.outside, other.outside
        ia, ib = _pairs(A, B)
        lo = np.maximum(A[ia, :, 0], B[ib, :, 0])
        hi = np.minimum(A[ia, :, 1], B[ib, :, 1])
        flat_a = A[ia, :, 0] == A[ia, :, 1]
        flat_b = B[ib, :, 0] == B[ib, :, 1]
        keep = ((lo < hi) | flat_a | flat_b).all(axis=1)  # drop mere face contacts
        outside = np.stack([lo[keep], hi[keep]], axis=-1).reshape(-1, self._n, 2)
        domain = None
        if self.domain is not None and other.domain is not None:
            domain = self.domain | other.domain
        return Paving(inner=np.concatenate([self.inner, other.inner]),
                      boundary=np.concatenate([self.boundary, other.boundary]),
                      outside=outside, domain=domain)

    def __or__(self, other: Any) -> Paving:
        if not isinstance(other, (Paving, Box)):
            return NotImplemented
        return self.union(other)

    def __ror__(self, other: Any) -> Paving:
        if not isinstance(other, (Paving, Box)):
            return NotImplemented
        return self.union(other)

    # ------------------------------------------------------------- plotting
    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), *,
             show_outer: bool = False, legend: bool = True,
             colors: dict[str, Any] | None = None, labels: dict[str, str] | None = None,
             **kw: Any) -> Any:
        """Draw the paving: inner (green), boundary (yellow), optionally outside (grey-blue).

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Created when omitted.
        dims : (int, int)
            Coordinates drawn for ``n >= 2``; for ``n > 2`` the boxes are projected on them
            (identical projections drawn once). A 1-D paving is drawn as intervals on a line.
        show_outer : bool
            Also draw the outside (discarded) boxes.
        legend : bool
            Add a legend with one entry per drawn category, outside the axes (right).
        colors, labels : dict, optional
            Face colour and legend label per category ``"inner"``, ``"boundary"``,
            ``"outside"`` (the old key ``"outer"`` is a deprecated alias of ``"outside"``).
        **kw
            Passed to every ``PatchCollection`` (``edgecolor``, ``linewidth``, ``alpha``,
            ...); a ``facecolor`` here overrides ``colors``.

        Returns
        -------
        matplotlib Axes
            One collection per non-empty category drawn (outside, boundary, inner, in
            that order), one rectangle per box.
        """
        from ..plot import legend_outside, new_axes, plot_boxes

        n = self._n
        if n >= 2:
            i, j = (int(dims[0]), int(dims[1]))
            if i == j or not (0 <= i < n and 0 <= j < n):
                raise DimensionError(
                    f"dims must be two distinct coordinates in 0..{n - 1}; got {tuple(dims)}")
            sel = [i, j]
        else:
            sel = [0]
        col = {**_DEFAULT_COLORS, **_outside_key(colors, "colors")}
        lab = {**_DEFAULT_LABELS, **_outside_key(labels, "labels")}
        cats = [("outside", self.outside)] if show_outer else []
        cats += [("boundary", self.boundary), ("inner", self.inner)]
        drawn = {name: arr[:, sel, :] for name, arr in cats if arr.shape[0]}
        if n > 2:
            drawn = {k: np.unique(v, axis=0) for k, v in drawn.items()}
        drawn = _clip_infinite(drawn, None if self.domain is None else
                               self.domain.as_array()[sel])
        ax = new_axes(ax)
        for name, arr in drawn.items():
            style = {k: v for k, v in kw.items() if k != "label"}
            style.setdefault("facecolor", col[name])
            plot_boxes(arr, ax=ax, dims=(0, 1), label=lab[name], **style)
        if legend and drawn:
            legend_outside(ax)
        return ax

    # ---------------------------------------------------------- persistence
    def _state(self) -> dict[str, Any]:
        return {
            "dim": self._n,
            "inner": np.array(self.inner),
            "boundary": np.array(self.boundary),
            "outside": np.array(self.outside),
            "domain": None if self.domain is None else self.domain.as_array(),
            "n_discarded": self.n_discarded,
        }

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> Paving:
        n = int(state["dim"])
        state = dict(state)
        if "outside" not in state and "outer" in state:  # files written before the rename
            state["outside"] = state["outer"]
        arrs = {k: np.asarray(state[k], dtype=float).reshape(-1, n, 2)
                for k in ("inner", "boundary", "outside")}
        dom = state.get("domain")
        domain = None if dom is None else Box.from_array(np.asarray(dom, dtype=float))
        return cls(**arrs, domain=domain, n_discarded=int(state["n_discarded"]))

    def __repr__(self) -> str:
        return (f"Paving(dim={self._n}, inner={self.n_inner}, boundary={self.n_boundary}, "
                f"outside={self.n_outside}, n_discarded={self.n_discarded}, "
                f"domain={self.domain!r})")


def _outside_key(d: dict[str, Any] | None, what: str) -> dict[str, Any]:
    """A copy of a per-category dict with the deprecated key ``"outer"`` renamed."""
    d = dict(d or {})
    if "outer" in d:
        _warn_outer(f"the key 'outer' of {what}=", stacklevel=4)
        d.setdefault("outside", d.pop("outer"))
    return d


def _clip_infinite(drawn: dict[str, np.ndarray], domain: np.ndarray | None
                   ) -> dict[str, np.ndarray]:
    """Replace infinite bounds by finite ones just beyond the finite data (for drawing)."""
    if all(np.isfinite(v).all() for v in drawn.values()):
        return drawn
    parts = list(drawn.values()) + ([] if domain is None else [domain[None]])
    allv = np.concatenate(parts)
    fin = np.isfinite(allv)
    lo = np.where(fin, allv, np.inf).min(axis=(0, 2))
    hi = np.where(fin, allv, -np.inf).max(axis=(0, 2))
    lo = np.where(np.isfinite(lo), lo, np.where(np.isfinite(hi), hi - 1.0, -1.0))
    hi = np.where(np.isfinite(hi), hi, lo + 2.0)
    pad = np.maximum(0.1 * (hi - lo), 1.0)
    return {k: np.clip(v, (lo - pad)[None, :, None], (hi + pad)[None, :, None])
            for k, v in drawn.items()}
