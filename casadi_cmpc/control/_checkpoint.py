"""Resumable runs of :func:`~casadi_cmpc.controllable_sets`: the checkpoint file.

A checkpoint is the sequence computed so far, written by :meth:`SetSequence.save
<casadi_cmpc.SetSequence.save>` (the one file format of a sequence) with two more entries of
its ``info``: the key of the problem it answers (:data:`KEY`) and the state boxes still to be
searched after its last step (:data:`FRONTIER`). It is rewritten after every completed step
through a partial file in the same directory renamed over it (:func:`save_atomically`), so a
process killed at any moment leaves the previous checkpoint whole.

The problem key is a list of named parts, each a short text (a number as written, or a
hash by :func:`digest`, the hash of the files ``cmpc run`` caches), so that a checkpoint of
another problem is refused with the names of the parts that differ.
"""

from __future__ import annotations

import dataclasses
import glob
import hashlib
import math
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..exceptions import CmpcError

__all__ = ["CheckpointError", "Checkpoint", "digest", "save_atomically", "problem_key",
           "terminal_part", "progress_text"]

# what the parts of the key mean, for the message that names the parts that differ
_PARTS = {
    "model": "the model's map f (hash of its CasADi Function)",
    "X": "the state box X",
    "U": "the input box U",
    "W": "the disturbance box W",
    "T": "the terminal set T",
    "eps": "eps",
    "robust": "robust",
    "polytopic": "polytopic / polytopic_method",
    "obstacles": "the obstacles",
    "u_eps": "u_eps",
    "max_cells": "max_cells",
    "w_points": "the points of W that discard control cells (w_points)",
    "terminal": "the proof of T's invariance (how: proved / assumed, local law, W covered)",
    "version": "the casadi_cmpc version",
    "format": "the checkpoint format",
}
_PLURAL = ("obstacles", "w_points")  # "the obstacles differ"
# parts shown with both values in the message (short, readable texts)
_SHOWN = ("eps", "robust", "polytopic", "u_eps", "max_cells", "terminal", "version", "format",
          "X", "U", "W")

FORMAT = "controllable-sets-checkpoint-1"
KEY = "checkpoint_key"  # info entry of a checkpoint: [[part, text], ...]
FRONTIER = "checkpoint_frontier"  # info entry: (N, n, 2) state boxes still to be searched


class CheckpointError(CmpcError, ValueError):
    """A checkpoint file that cannot be resumed: it answers another problem, or it is not a
    checkpoint of :func:`~casadi_cmpc.controllable_sets`. The file is left as it is."""


def digest(parts: Iterable[Any]) -> str:
    """SHA-256 (hex, 64 characters) of the parts in order: bytes as they are, anything else
    as the UTF-8 of ``str(part)``."""
    h = hashlib.sha256()
    for part in parts:
        h.update(part if isinstance(part, bytes) else str(part).encode())
    return h.hexdigest()


def _array_parts(a: Any) -> list[Any]:
    """What identifies an array bit for bit: dtype, shape and bytes."""
    a = np.ascontiguousarray(a)
    return [a.dtype.str, a.shape, a.tobytes()]


def _state_hash(S: Any) -> str:
    """A hash of a set's stored state (type, arrays bit for bit, other values as text)."""
    parts: list[Any] = [type(S).__name__]

    def walk(v: Any) -> None:
        if isinstance(v, np.ndarray):
            parts.extend(_array_parts(v))
        elif isinstance(v, dict):
            for k in sorted(v):
                parts.append(k)
                walk(v[k])
        elif isinstance(v, (list, tuple)):
            parts.append(len(v))
            for x in v:
                walk(x)
        else:
            parts.append(repr(v))

    walk(S._state())
    return digest(parts)[:20]


def _box_text(B: Any) -> str:
    """A box as the list of its bounds ``[[lo, hi], ...]`` (floats as ``repr`` writes them,
    which reads back to the same numbers)."""
    return repr(np.asarray(B.as_array(), dtype=float).tolist())


def problem_key(model: Any, T: Any, D: Any, *, eps: float, robust: bool, polytopic: bool,
                polytopic_method: str, obstacles: Sequence[Any], u_eps: float,
                max_cells: int, w_points: np.ndarray) -> list[list[str]]:
    """The parts of the problem that determine every step of a sequence, except the proof
    of T's invariance (:func:`terminal_part`, added once it is known).

    Parameters
    ----------
    model : Model
        Its map f (:func:`~casadi_cmpc.control.invariance.model_key`) and boxes U, W.
    T : Polytope
        The terminal set (its rows A, b bit for bit).
    D : Box
        The state box searched (X).
    eps, robust, polytopic, polytopic_method, obstacles, u_eps, max_cells
        As given to :func:`~casadi_cmpc.controllable_sets` (after validation).
    w_points : ndarray (C, l)
        The points of W the search uses to discard control cells (given or default).

    Returns
    -------
    list of [name, text]
        In a fixed order. Limits (``max_steps``, ``until``, ``max_boxes``, ``time_limit``)
        and ``progress`` are not parts: they decide where a run stops, not what a completed
        step holds.
    """
    from .. import __version__
    from .invariance import model_key

    return [
        ["model", model_key(model)],
        ["X", _box_text(D)],
        ["U", _box_text(model.U)],
        ["W", _box_text(model.W) if model.l else "none"],
        ["T", digest(_array_parts(T.A) + _array_parts(T.b))[:20]],
        ["eps", repr(float(eps))],
        ["robust", repr(bool(robust))],
        ["polytopic", repr((bool(polytopic), polytopic_method if polytopic else None))],
        ["obstacles", digest([_state_hash(ob) for ob in obstacles])[:20]],
        ["u_eps", repr(float(u_eps))],
        ["max_cells", repr(int(max_cells))],
        ["w_points", digest(_array_parts(np.asarray(w_points, dtype=float)))[:20]],
        ["version", str(__version__)],
        ["format", FORMAT],
    ]


def terminal_part(info: dict[str, Any]) -> list[str]:
    """The key part of the proof of T's invariance, from the entries of a sequence's info:
    ``terminal_certificate`` (``"proved"``, ``"assumed"``), ``terminal_law_key`` (the law
    proven) and ``terminal_W`` (the disturbance box it covers)."""
    return ["terminal", repr((info.get("terminal_certificate"), info.get("terminal_law_key"),
                              info.get("terminal_W")))]


def save_atomically(seq: Any, path: Path, **save_options: Any) -> None:
    """Write ``seq`` to ``path`` (``seq.save(..., **save_options)``) through a partial file
    in the same directory, ``.<stem>.<pid>.partial<suffix>``, renamed over ``path`` when
    complete: an interrupted or killed write leaves no truncated file under the final name
    (the previous file stays whole). A failed write removes its partial file and raises."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.partial{path.suffix}")
    try:
        seq.save(tmp, **save_options)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _alive(pid: int) -> bool:
    """Whether a process with this id runs (on this machine)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


class Checkpoint:
    """The checkpoint file of one :func:`~casadi_cmpc.controllable_sets` run.

    Parameters
    ----------
    path : str or Path
        The file; it must end in ``.npz`` (compressed binary) or ``.json`` (text), the
        formats of :meth:`SetSequence.save <casadi_cmpc.SetSequence.save>`.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        from ..sets.base import _check_suffix

        self.path = Path(path)
        _check_suffix(self.path, "write a checkpoint to")
        if self.path.is_dir():
            raise CheckpointError(f"checkpoint '{self.path}' is a directory; give a file path "
                                  "ending in .npz")

    def _remove_stale_partials(self) -> None:
        """Delete partial files of this checkpoint left by killed processes."""
        p = self.path
        pattern = f".{glob.escape(p.stem)}.*.partial{glob.escape(p.suffix)}"
        for f in p.parent.glob(pattern):
            pid = f.name[len(p.stem) + 2:-len(".partial" + p.suffix)]
            if pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)):
                try:
                    f.unlink()
                except OSError:
                    pass

    def load(self, key: list[list[str]]) -> Any:
        """The checkpointed sequence (a SetSequence), or None when there is no file yet.

        Raises
        ------
        CheckpointError
            The file is not a checkpoint of ``controllable_sets``, or one of another
            problem (a part of ``key`` differs; see :meth:`check`).
        """
        from .linear_sets import SetSequence

        self._remove_stale_partials()
        if not self.path.exists():
            return None
        try:
            seq = SetSequence.load(self.path)
        except Exception as exc:  # any reason (a truncated archive, another format)
            raise CheckpointError(
                f"'{self.path}' exists but cannot be read as a checkpoint ({exc}); it is left "
                "as it is: delete it or give another checkpoint path") from exc
        if not isinstance(seq.info.get(KEY), list) or FRONTIER not in seq.info:
            raise CheckpointError(
                f"'{self.path}' holds a set sequence that is not a checkpoint of "
                "controllable_sets (written by save() or cmpc's cache?); it is left as it is: "
                "give another checkpoint path")
        self.check(seq, key)
        return seq

    def check(self, seq: Any, key: list[list[str]]) -> None:
        """Raise :class:`CheckpointError` naming the parts of ``key`` that the checkpoint
        ``seq`` was computed with otherwise (parts absent from ``key`` are not compared)."""
        stored = {str(k): str(v) for k, v in seq.info.get(KEY, [])}
        diffs = []
        for name, text in key:
            if stored.get(name) == text:
                continue
            what = _PARTS.get(name, name)
            if name in _SHOWN:
                diffs.append(f"{what}: {stored.get(name, 'missing')} in the checkpoint, "
                             f"{text} here")
            else:
                diffs.append(f"{what} {'differ' if name in _PLURAL else 'differs'}")
        if diffs:
            raise CheckpointError(
                f"checkpoint '{self.path}' was computed for another problem (" +
                "; ".join(diffs) + "). It is left as it is: call with the settings it was "
                "computed with to resume it, or give another checkpoint path (or delete the "
                "file) to start afresh")

    @staticmethod
    def resume_state(seq: Any, n: int) -> tuple[list[dict[str, Any]], np.ndarray]:
        """The completed steps of a checkpoint (as :func:`controllable_sets` builds them:
        ``"polytope"`` None where none was stored) and the state boxes (N, n, 2) still to be
        searched after the last of them."""
        steps = []
        for st in seq.steps:
            st = dict(st)
            st.setdefault("polytope", None)
            steps.append(st)
        frontier = np.asarray(seq.info[FRONTIER], dtype=float).reshape(-1, n, 2)
        return steps, frontier

    def write(self, seq: Any, key: list[list[str]], frontier: np.ndarray, status: str) -> None:
        """Write the sequence so far with its key and frontier, atomically.

        Parameters
        ----------
        seq : SetSequence
            The sequence after its last completed step (not modified).
        key : list of [name, text]
            :func:`problem_key` with :func:`terminal_part`.
        frontier : ndarray (N, n, 2)
            The state boxes the next step searches.
        status : str
            The status stored: the final one when the run stops at this step, else
            ``"interrupted"`` (a partial sequence). A final file is compressed; the others,
            rewritten after every step, are not (writing them is several times faster).
        """
        info = {**seq.info, KEY: [list(p) for p in key], FRONTIER: frontier}
        options = {"compress": status != "interrupted"} if self.path.suffix == ".npz" else {}
        save_atomically(dataclasses.replace(seq, info=info, status=status), self.path,
                        **options)


def _clock(seconds: float) -> str:
    """A duration for the progress bar: ``"0:42"``, ``"12:05"``, ``"1:02:03"``."""
    from tqdm import tqdm

    return tqdm.format_interval(max(0.0, seconds))


def progress_text(i: int, n_boxes: int, new: Sequence[int], seconds: Sequence[float],
                  max_steps: int) -> str:
    """The postfix of the progress bar of :func:`~casadi_cmpc.controllable_sets` after step i.

    Parameters
    ----------
    i : int
        Steps done.
    n_boxes : int
        Boxes proven so far (all steps).
    new : sequence of int
        Boxes first proven at each step 1..i.
    seconds : sequence of float
        Duration of each step 1..i, in seconds.
    max_steps : int
        Largest number of steps.

    Returns
    -------
    str
        ``K_i``, its boxes (+ the new ones), the mean time of the last steps and, once the
        number of new boxes per step has declined for three steps from its largest value,
        an estimate of the time left: the steps left if the decline per step since that
        largest value goes on geometrically until no new box is proven (at most
        ``max_steps - i``), times the mean time of the last steps.
    """
    recent = [float(s) for s in seconds[-3:]]
    per_step = sum(recent) / len(recent) if recent else 0.0
    text = f"K_{i}: {n_boxes} boxes (+{new[-1] if len(new) else 0}), {per_step:.2g} s/step"
    left = max_steps - i
    if left <= 0:
        return text
    top = int(np.argmax(new)) if len(new) else 0
    since = len(new) - 1 - top
    if since < 3 or not 0 < new[-1] < new[top]:
        return f"{text}; time left not estimated while the new boxes per step do not decline"
    rate = (new[-1] / new[top]) ** (1.0 / since)  # decline per step since the largest value
    steps_left = min(left, math.ceil(math.log(new[-1] + 1) / -math.log(rate)) + 1)
    return (f"{text}; about {_clock(steps_left * per_step)} left (estimate: {steps_left} "
            f"more step{'s' * (steps_left != 1)})")
