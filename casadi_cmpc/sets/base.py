"""The set protocol shared by Box, Paving, Polytope, PolytopeUnion and Zonotope.

Every set type implements eight members::

    dim                      ambient dimension n
    is_empty()               True only when the set is proven empty
    contains(points)         (N, n) or (n,) points -> (N,) bool or bool
    contains_box(boxes)      (N, n, 2) boxes -> (N,) bool: True only when box ⊆ set is proven
    intersects_box(boxes)    (N, n, 2) boxes -> (N,) bool: False only when box ∩ set = ∅ is proven
    support(directions)      (k, n) or (n,) -> (k,) or float: h(d) = sup_{x in S} d.x
    bounding_box()           smallest enclosing Box (outer approximation)
    vertices()               (k, n) points whose convex hull is the convex hull of the set

and inherits ``plot(ax=None, **kw)`` (2-D drawing; ``dims=(i, j)`` projects higher dimensions),
``save(path)`` and ``load(path)`` (``.npz`` or ``.json``; exact round trip).
"""

from __future__ import annotations

import json
import zipfile
import zlib
from abc import ABCMeta, abstractmethod
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

__all__ = ["SetBase", "load_set"]

_TYPES: dict[str, type[SetBase]] = {}
_FORMAT_VERSION = 1


class HoldsSetMeta(ABCMeta):
    """Metaclass of the set types: an object that *holds* a set counts as an instance of it.

    A class whose attribute ``_held_set`` names one of its instance attributes (e.g. a
    solver's :class:`~casadi_cmpc.SetResult`, ``_held_set = "paving"``) wraps a set and
    forwards its members to it. ``isinstance(obj, T)`` is then True when the held object is
    an instance of ``T``, so code written for the set a solver used to return (``if
    isinstance(x, cm.Paving)``) keeps accepting the result. ``issubclass`` is unchanged.
    """

    def __instancecheck__(cls, instance: Any) -> bool:
        if ABCMeta.__instancecheck__(cls, instance):
            return True
        attr = getattr(type(instance), "_held_set", None)
        if not isinstance(attr, str):
            return False
        try:
            held = object.__getattribute__(instance, attr)
        except AttributeError:
            return False
        return held is not instance and isinstance(held, cls)


def held_set(obj: Any) -> Any:
    """The set an object holds (see :class:`HoldsSetMeta`, e.g. a solver result's paving), or
    the object itself."""
    attr = getattr(type(obj), "_held_set", None)
    if isinstance(attr, str):
        try:
            return object.__getattribute__(obj, attr)
        except AttributeError:
            pass
    return obj


class SetBase(metaclass=HoldsSetMeta):
    """Abstract base of the set types (see the module docstring for the protocol)."""

    _type_name: ClassVar[str] = ""

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        cls._type_name = cls.__name__
        _TYPES[cls.__name__] = cls

    # ------------------------------------------------------------- protocol
    @property
    @abstractmethod
    def dim(self) -> int:
        """Ambient dimension n."""

    @abstractmethod
    def is_empty(self) -> bool:
        """True when the set is empty."""

    @abstractmethod
    def contains(self, points: Any) -> np.ndarray | bool:
        """Membership of points (N, n) -> (N,) bool, or (n,) -> bool."""

    @abstractmethod
    def contains_box(self, boxes: Any) -> np.ndarray:
        """(N, n, 2) boxes -> (N,) bool; True only when box ⊆ set is proven."""

    @abstractmethod
    def intersects_box(self, boxes: Any) -> np.ndarray:
        """(N, n, 2) boxes -> (N,) bool; False only when box ∩ set = ∅ is proven."""

    @abstractmethod
    def support(self, directions: Any) -> np.ndarray | float:
        """Support function h(d) = sup over the set of d.x; (k, n) -> (k,), (n,) -> float."""

    @abstractmethod
    def bounding_box(self) -> Any:
        """Smallest axis-aligned Box containing the set."""

    @abstractmethod
    def vertices(self) -> np.ndarray:
        """(k, n) points whose convex hull equals the convex hull of the set."""

    # ------------------------------------------------------------- plotting
    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), **kw: Any) -> Any:
        """Draw the set in 2-D (the projection on ``dims`` for n > 2).

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Created when omitted.
        dims : (int, int)
            Coordinates drawn on the horizontal and vertical axes.
        **kw
            Passed to matplotlib (``facecolor``, ``edgecolor``, ``alpha``, ``label``, ...).

        Returns
        -------
        matplotlib Axes
        """
        from ..plot import plot_polygon_hull

        return plot_polygon_hull(self._plot_points(dims), ax=ax, **kw)

    def _plot_points(self, dims: tuple[int, int]) -> np.ndarray:
        if self.dim == 1:
            v = self.vertices()[:, [0]]
            return np.hstack([v, np.zeros_like(v)])
        return self.vertices()[:, list(dims)]

    # ---------------------------------------------------------- persistence
    def _state(self) -> dict[str, Any]:
        """Arrays and scalars that determine the set exactly (override)."""
        raise NotImplementedError(f"{type(self).__name__} does not define _state()")

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> SetBase:
        """Rebuild a set from :meth:`_state` output (override)."""
        raise NotImplementedError(f"{cls.__name__} does not define _from_state()")

    def save(self, path: str | Path) -> Path:
        """Save the set exactly to ``path`` (``.npz`` binary or ``.json`` text).

        Parameters
        ----------
        path : str or Path
            The file written, exactly this name; it must end in ``.npz`` or ``.json``.

        Returns
        -------
        pathlib.Path
            The written file (``path`` itself).

        Raises
        ------
        ValueError
            ``path`` does not end in ``.npz`` or ``.json``.
        """
        return _save_state(self._type_name, self._state(), Path(path))

    @classmethod
    def load(cls, path: str | Path) -> SetBase:
        """Load a set saved with :meth:`save`; the file must hold this type (or a subclass).

        Raises
        ------
        ValueError
            Wrong suffix, or the file is not a set file written by :meth:`save`.
        FileNotFoundError
            No file at ``path``.
        TypeError
            The file holds another set type.
        """
        obj = load_set(path)
        if not isinstance(obj, cls):
            raise TypeError(f"{path} holds a {type(obj).__name__}, not a {cls.__name__}")
        return obj


def _encode(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return {"__array__": [float(x) if v.dtype.kind == "f" else int(x)
                              for x in v.ravel()],
                "shape": list(v.shape), "dtype": v.dtype.str}
    if isinstance(v, (list, tuple)):
        return {"__list__": [_encode(x) for x in v]}
    if isinstance(v, dict):
        return {"__dict__": {k: _encode(x) for k, x in v.items()}}
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return v.item()
    return v


def _decode(v: Any) -> Any:
    if isinstance(v, dict):
        if "__array__" in v:
            return np.array(v["__array__"], dtype=np.dtype(v["dtype"])).reshape(v["shape"])
        if "__list__" in v:
            return [_decode(x) for x in v["__list__"]]
        if "__dict__" in v:
            return {k: _decode(x) for k, x in v["__dict__"].items()}
    return v


_SUFFIXES = (".npz", ".json")


def _check_suffix(path: Path, action: str) -> None:
    if path.suffix.lower() not in _SUFFIXES:
        raise ValueError(
            f"cannot {action} '{path}': the file name must end in '.npz' (binary) or "
            f"'.json' (text); got the suffix {path.suffix or '(none)'!r}. Rename it, "
            f"e.g. '{path.with_suffix('.npz')}'")


def _save_state(type_name: str, state: dict[str, Any], path: Path) -> Path:
    _check_suffix(path, "save a set to")
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".json":
        doc = {"type": type_name, "format": _FORMAT_VERSION,
               "state": {k: _encode(v) for k, v in state.items()}}
        path.write_text(json.dumps(doc))  # float repr round-trips exactly; inf -> Infinity
        return path
    meta = {"type": type_name, "format": _FORMAT_VERSION,
            "state": {k: _encode(v) for k, v in state.items()
                      if not isinstance(v, np.ndarray)}}
    arrays = {f"a_{k}": v for k, v in state.items() if isinstance(v, np.ndarray)}
    # write through a file object: np.savez would append '.npz' to a name without it
    with open(path, "wb") as fh:
        np.savez(fh, __meta__=np.array(json.dumps(meta)), **arrays)
    return path


def load_set(path: str | Path) -> SetBase:
    """Load any set saved with ``.save(path)``.

    Parameters
    ----------
    path : str or Path
        A ``.npz`` or ``.json`` file written by :meth:`SetBase.save`.

    Returns
    -------
    The set, of the type that was saved.

    Raises
    ------
    ValueError
        ``path`` does not end in ``.npz`` or ``.json``, or is not a set file written by
        ``save`` (the message names the file and the expected format).
    FileNotFoundError
        No file at ``path``.
    """
    path = Path(path)
    _check_suffix(path, "load a set from")
    if not path.is_file():
        raise FileNotFoundError(f"no set file at '{path}'")
    bad = (f"'{path}' is not a set file written by save(): expected "
           + ("a JSON document with the keys 'type' and 'state'"
              if path.suffix.lower() == ".json" else
              "an .npz archive (numpy.savez) with a '__meta__' entry"))
    if path.suffix.lower() == ".npz":
        with open(path, "rb") as fh:
            head = fh.read(4)
        if head[:2] != b"PK":  # every zip archive (numpy.savez) starts with 'PK'
            what = "an empty file" if not head else f"a file starting with {head!r}"
            raise ValueError(f"{bad}; found {what}, not a zip archive")
    try:
        if path.suffix.lower() == ".json":
            doc = json.loads(path.read_text())
            state = {k: _decode(v) for k, v in doc["state"].items()}
        else:
            with np.load(path, allow_pickle=False) as data:
                if not hasattr(data, "files") or "__meta__" not in data.files:
                    raise ValueError("no '__meta__' entry")
                doc = json.loads(str(data["__meta__"]))
                state = {k: _decode(v) for k, v in doc["state"].items()}
                for key in data.files:
                    if key.startswith("a_"):
                        state[key[2:]] = np.array(data[key])
    except (ValueError, KeyError, TypeError, AttributeError, OSError, EOFError,
            UnicodeDecodeError, zipfile.BadZipFile, zlib.error) as exc:
        # (a truncated or damaged archive: BadZipFile, a zlib error, an EOF)
        detail = str(exc)
        if "pickle" in detail:  # numpy's hint to unpickle would mislead: never unpickle
            detail = "the archive holds an entry that is not a plain numeric or text array"
        raise ValueError(f"{bad} ({type(exc).__name__}: {detail})") from exc
    if not isinstance(doc, dict):
        raise ValueError(bad)
    cls = _TYPES.get(doc.get("type", ""))
    if cls is None:
        raise ValueError(f"{path} does not hold a known set type (found {doc.get('type')!r})")
    return cls._from_state(state)
