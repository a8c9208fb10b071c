"""A union of sets of any kinds (polytopes, box unions, zonotopes, boxes)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import as_boxes, as_points
from ..exceptions import DimensionError
from .base import _TYPES, SetBase, held_set
from .box import Box

__all__ = ["SetUnion"]


class SetUnion(SetBase):
    """The union ``S_1 ∪ ... ∪ S_p`` of sets of any kinds, of one dimension.

    Members are any sets of this library (Polytope, PolytopeUnion, Paving, Zonotope, Box,
    another SetUnion). Of a :class:`~casadi_cmpc.Paving` member the **inner** boxes count:
    the union is meant for proven (inner) sets, such as controllable sets.

    ``contains`` is exact per member. ``contains_box`` answers True only when one member
    contains the box (sufficient, not necessary: a box straddling two members answers
    False, "not proven"); ``intersects_box`` answers False only when every member is proven
    disjoint from the box.

    Parameters
    ----------
    members : iterable of sets
    dim : int, optional
        Needed when ``members`` is empty.
    """

    def __init__(self, members: Any, dim: int | None = None) -> None:
        flat: list[Any] = []
        for S in members:
            S = held_set(S)  # a solver's result: its paving
            if isinstance(S, SetUnion):
                flat.extend(S.members)
            else:
                if not isinstance(S, SetBase):
                    raise TypeError(f"members must be sets of casadi_cmpc; got "
                                    f"{type(S).__name__}")
                flat.append(S)
        dims = {S.dim for S in flat}
        if dim is not None:
            dims.add(int(dim))
        if len(dims) != 1:
            raise DimensionError(f"members of a SetUnion must share one dimension; got "
                                 f"{sorted(dims) or 'none (pass dim=)'}")
        self.members: list[Any] = flat
        self._n = dims.pop()

    @property
    def dim(self) -> int:
        return self._n

    def __len__(self) -> int:
        return len(self.members)

    def __iter__(self):
        return iter(self.members)

    @staticmethod
    def _kw(S: Any) -> dict[str, Any]:
        from .paving import Paving

        return {"view": "inner"} if isinstance(S, Paving) else {}

    def _any(self, test: str, a: np.ndarray) -> np.ndarray:
        """Per row of ``a``: some member answers True to ``S.<test>`` (members asked only
        for the rows still False)."""
        out = np.zeros(a.shape[0], dtype=bool)
        for S in self.members:
            und = np.flatnonzero(~out)
            if und.size == 0:
                break
            out[und[np.asarray(getattr(S, test)(a[und], **self._kw(S)), dtype=bool)]] = True
        return out

    def is_empty(self) -> bool:
        return all(S.is_empty(**self._kw(S)) for S in self.members)

    def contains(self, points: Any) -> np.ndarray | bool:
        p, batched = as_points(points, self._n, name="points")
        out = self._any("contains", p)
        return out if batched else bool(out[0])

    def contains_box(self, boxes: Any) -> np.ndarray:
        return self._any("contains_box", as_boxes(boxes, self._n, "boxes"))

    def intersects_box(self, boxes: Any) -> np.ndarray:
        return self._any("intersects_box", as_boxes(boxes, self._n, "boxes"))

    def support(self, directions: Any) -> np.ndarray | float:
        vals = [np.asarray(S.support(directions, **self._kw(S)), dtype=float)
                for S in self.members if not S.is_empty(**self._kw(S))]
        if not vals:
            d = np.atleast_2d(np.asarray(directions, dtype=float))
            return np.full(d.shape[0], -np.inf)
        return np.max(np.stack(vals), axis=0)

    def bounding_box(self) -> Box:
        bbs = [S.bounding_box(**self._kw(S)) for S in self.members
               if not S.is_empty(**self._kw(S))]
        if not bbs:
            return Box(np.full(self._n, np.inf), np.full(self._n, -np.inf))
        lo = np.min([b.lo for b in bbs], axis=0)
        hi = np.max([b.hi for b in bbs], axis=0)
        return Box(lo, hi)

    def vertices(self) -> np.ndarray:
        vs = [np.asarray(S.vertices(**self._kw(S))) for S in self.members
              if not S.is_empty(**self._kw(S))]
        return np.concatenate(vs) if vs else np.zeros((0, self._n))

    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), **kw: Any) -> Any:
        from ..plot import new_axes

        ax = new_axes(ax)
        for S in self.members:
            if isinstance(S, Box):
                from .polytope import Polytope

                Polytope.from_box(S).plot(ax=ax, dims=dims, **kw)
            elif hasattr(S, "inner") and hasattr(S, "view_boxes"):
                from ..plot import plot_boxes

                if S.inner.shape[0]:
                    plot_boxes(S.inner, ax=ax, dims=dims, **kw)
            else:
                S.plot(ax=ax, dims=dims, **kw)
        return ax

    def _state(self) -> dict[str, Any]:
        return {"dim": self._n,
                "members": [{"type": S._type_name, "state": S._state()} for S in self.members]}

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> SetUnion:
        members = [_TYPES[m["type"]]._from_state(m["state"]) for m in state["members"]]
        return cls(members, dim=int(state["dim"]))

    def __repr__(self) -> str:
        kinds = ", ".join(type(S).__name__ for S in self.members)
        return f"SetUnion(dim={self._n}, members=[{kinds}])"
