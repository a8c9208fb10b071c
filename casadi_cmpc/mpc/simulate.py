"""Closed-loop simulation: :func:`simulate` runs a model under a controller and returns a
:class:`Trajectory` (states, inputs, disturbances, what the controller reported, violations).
"""

from __future__ import annotations

import json
import math
import operator
import time
import warnings
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import casadi as ca
import numpy as np

from .._interrupt import InterruptScope
from .._validate import as_float_array
from ..exceptions import (
    CmpcWarning,
    DimensionError,
    InvalidBoundsError,
    ModelError,
    NotControllableError,
)
from ..model import Model

__all__ = ["simulate", "Trajectory"]

_FORMAT = "casadi_cmpc.Trajectory"
_FORMAT_VERSION = 3  # 2: per-step levels of set-sequence controllers; 3: proof_covers_w
_STOP_REASONS = ("steps", "stop_when", "interrupted", "diverged", "not_controllable")
_LIST_FIELDS = ("status", "certificate", "horizon", "mode", "level", "proof_covers_w")
# the kind of a step, from the mode the controller reported
_SOLVER_MODES = frozenset({"mpc"})
_LAW_MODES = frozenset({"local_law"})
_STEP_KINDS = ("solver", "local_law", "other")


# --------------------------------------------------------------------------- Trajectory
@dataclass(frozen=True, eq=False)
class Trajectory:
    """A simulated closed-loop run of ``K`` steps (``K <= steps`` asked for).

    Returned by :func:`simulate`. The instance is frozen and its arrays are read-only.

    Attributes
    ----------
    x : ndarray, shape (K + 1, n)
        States ``x(0), ..., x(K)`` (``x(0)`` is the initial state).
    u : ndarray, shape (K, m)
        Inputs ``u(k)`` as returned by the controller and applied (never clipped).
    w : ndarray, shape (K, l)
        Disturbances ``w(k)`` applied at step k (``l = 0`` without disturbance).
    status : tuple of (str or None), length K
        The controller's ``last_info["status"]`` per step; ``"ok"`` for a plain callable
        or a gain.
    certificate : tuple of (str or None), length K
        ``last_info["certificate"]`` per step (e.g. ``"verified"``, ``"unverified"``,
        ``"proved_infeasible"``, ``"undecided"``, ``"local_law"``); None when not reported.
    horizon : tuple of (int or None), length K
        ``last_info["horizon"]`` per step; None when not reported. For a controller along
        a set sequence (:class:`~casadi_cmpc.SetSequenceMPC`) these numbers are the levels
        of the sequence, not prediction horizons: see ``level``.
    solve_time : ndarray, shape (K,)
        Seconds per step reported as ``last_info["solve_time"]``; where the controller does
        not report one, the wall-clock time of the call measured by the simulator.
    call_time : ndarray, shape (K,)
        Wall-clock seconds of each controller call, always measured by the simulator.
    mode : tuple of (str or None), length K
        ``last_info["mode"]`` per step (e.g. ``"mpc"``, ``"sequence"``, ``"local_law"``,
        ``"fallback"``); ``"feedback"`` for a plain callable or gain, ``"autonomous"`` for
        a model without input.
    level : tuple of (int or None), length K
        For a controller along a set sequence ``K_0 = T, K_1, ...``: the level ``i(k)``,
        the index of the set ``K_i`` that held ``x(k)`` (``last_info["level"]``, or the
        ``"horizon"`` a :class:`~casadi_cmpc.SetSequenceMPC` reports); None for other
        controllers. Given empty, it is None at every step.
    proof_covers_w : tuple of (bool or None), length K
        Whether the disturbances the controller's proofs are about (its ``proof_w`` box: W
        for a robust controller, the nominal w for a nominal one) hold the w applied at
        step k; None where the controller names none (or the model has no w). A step
        proven for the nominal w only and run with another w does not count as proven
        (see :meth:`summary`). Given empty, it is None at every step.
    guarantee : str
        The controller's ``guarantee`` (what its closed loop is proven to do, for which
        disturbances); empty when it states none.
    x_ref : ndarray (n,) or None
        The state the controller regulates to (its ``x_ref``); None when it has none.
    violations : mapping
        ``"state"``: number of states ``x(k)``, ``k >= 1``, outside the model's X;
        ``"input"``: number of inputs ``u(k)`` outside U; ``"state_steps"``,
        ``"input_steps"``: the step indices k of those (tuples of int). Computed by the
        simulator with no tolerance (a point on the boundary is inside).
    model : Model or None
        The simulated model (None for a trajectory loaded from a file).
    stop_reason : str
        Why the run ended: ``"steps"`` (all steps run), ``"stop_when"`` (the ``stop_when``
        test held), ``"interrupted"`` (KeyboardInterrupt), ``"diverged"`` (a non-finite
        successor state; it is the last row of ``x``), ``"not_controllable"`` (a set-sequence
        controller found the state in no set of its sequence: it raised
        :class:`~casadi_cmpc.NotControllableError`; the state is the last row of ``x``).
    disturbance : str
        How w was chosen: ``"none"``, ``"centre"``, ``"uniform"``, ``"vertices"``,
        ``"array"`` or ``"callable"``.
    seed : int or None
        The seed of the random disturbances (None when a Generator or None was given).
    model_name : str
        Name of the model (kept when the model itself is not).

    See Also
    --------
    step_kind : which steps used the solver, the local law, or neither.

    Examples
    --------
    >>> import casadi as ca, numpy as np, casadi_cmpc as cm
    >>> x = ca.SX.sym("x"); u = ca.SX.sym("u")
    >>> model = cm.Model(x=x, u=u, f=x + u, X=cm.Box([-1], [1]), U=cm.Box([-1], [1]))
    >>> traj = cm.simulate(model, [[-0.5]], x0=[0.8], steps=3)
    >>> traj.x.ravel().tolist()
    [0.8, 0.4, 0.2, 0.1]
    >>> traj.steps, traj.violations["state"], traj.summary()["final_norm_inf"]
    (3, 0, 0.1)
    """

    x: np.ndarray
    u: np.ndarray
    w: np.ndarray
    status: tuple = ()
    certificate: tuple = ()
    horizon: tuple = ()
    solve_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    call_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mode: tuple = ()
    violations: Mapping[str, Any] = field(default_factory=dict)
    model: Model | None = field(default=None, repr=False)
    stop_reason: str = "steps"
    disturbance: str = "none"
    seed: int | None = None
    model_name: str = ""
    level: tuple = ()
    proof_covers_w: tuple = ()
    guarantee: str = ""
    x_ref: Any = None

    def __post_init__(self) -> None:
        x = np.array(self.x, dtype=float)
        if x.ndim != 2 or x.shape[0] < 1:
            raise DimensionError(f"x must have shape (K + 1, n); got {x.shape}")
        K = x.shape[0] - 1
        u = np.array(self.u, dtype=float)
        w = np.array(self.w, dtype=float)
        for arr, nm in ((u, "u"), (w, "w")):
            if arr.ndim != 2 or arr.shape[0] != K:
                raise DimensionError(f"{nm} must have shape (K, d) with K = {K} steps; "
                                     f"got {arr.shape}")
        if self.model is not None:
            for arr, d, nm in ((x, self.model.n, "x"), (u, self.model.m, "u"),
                               (w, self.model.l, "w")):
                if arr.shape[1] != d:
                    raise DimensionError(f"{nm} has {arr.shape[1]} columns; the model has {d}")
        solve_time = np.array(self.solve_time, dtype=float).reshape(-1)
        call_time = np.array(self.call_time, dtype=float).reshape(-1)
        values: dict[str, Any] = {}
        for name in _LIST_FIELDS:
            seq = tuple(getattr(self, name))
            if name == "level":
                seq = tuple(None if v is None else int(v) for v in seq) or (None,) * K
            elif name == "proof_covers_w":
                seq = tuple(None if v is None else bool(v) for v in seq) or (None,) * K
            if len(seq) != K:
                raise DimensionError(f"{name} must have one entry per step ({K}); got {len(seq)}")
            values[name] = seq
        for name, arr in (("solve_time", solve_time), ("call_time", call_time)):
            if arr.shape != (K,):
                raise DimensionError(f"{name} must have shape ({K},); got {arr.shape}")
        if self.stop_reason not in _STOP_REASONS:
            raise ValueError(f"stop_reason must be one of {', '.join(_STOP_REASONS)}; "
                             f"got {self.stop_reason!r}")
        viol = dict(self.violations) if self.violations else None
        if viol is None:
            viol = _count_violations(self.model, x, u) if self.model is not None else {
                "state": 0, "input": 0, "state_steps": (), "input_steps": ()}
        viol = {"state": int(viol["state"]), "input": int(viol["input"]),
                "state_steps": tuple(int(k) for k in viol["state_steps"]),
                "input_steps": tuple(int(k) for k in viol["input_steps"])}
        for arr in (x, u, w, solve_time, call_time):
            arr.setflags(write=False)
        name = self.model_name or (self.model.name if self.model is not None else "")
        for key, val in dict(x=x, u=u, w=w, solve_time=solve_time, call_time=call_time,
                             violations=MappingProxyType(viol), model_name=name,
                             **values).items():
            object.__setattr__(self, key, val)

    # ------------------------------------------------------------------ views
    @property
    def steps(self) -> int:
        """Number K of steps run."""
        return int(self.x.shape[0] - 1)

    @property
    def t(self) -> np.ndarray:
        """Step indices ``0, ..., K`` of the states, shape (K + 1,) (``u[k]`` acts at ``t[k]``)."""
        return np.arange(self.steps + 1)

    @property
    def interrupted(self) -> bool:
        """True when the run was stopped by KeyboardInterrupt."""
        return self.stop_reason == "interrupted"

    @property
    def x_final(self) -> np.ndarray:
        """The last state ``x(K)``, shape (n,)."""
        return self.x[-1]

    @property
    def step_kind(self) -> tuple[str, ...]:
        """What computed ``u(k)``, per step (length K), from the reported ``mode``.

        ``"solver"``: the controller solved its optimisation problem (mode ``"mpc"``);
        ``"local_law"``: the local law was applied, no solver (mode ``"local_law"``);
        ``"other"``: anything else (a gain or plain callable, a move of a stored sequence,
        the reference input, a step without a reported mode).
        """
        return tuple("solver" if m in _SOLVER_MODES else "local_law" if m in _LAW_MODES
                     else "other" for m in self.mode)

    def __len__(self) -> int:
        return self.steps

    def __repr__(self) -> str:
        return (f"Trajectory(model='{self.model_name}', steps={self.steps}, "
                f"stop_reason='{self.stop_reason}', state_violations={self.violations['state']}, "
                f"input_violations={self.violations['input']})")

    # ---------------------------------------------------------------- summary
    def summary(self) -> dict[str, Any]:
        """Figures of the run as a JSON-serialisable dict.

        Keys: ``model``, ``n``, ``m``, ``l``, ``steps``, ``stop_reason``, ``interrupted``,
        ``disturbance``, ``seed``, ``x0``, ``final_state``, ``final_norm_inf`` (max-norm of
        ``x(K)`` itself), ``final_error_inf`` (max-norm of ``x(K) - x_ref``, the state the
        controller regulates to; None for a controller without ``x_ref``), ``violations``
        (counts and step indices), ``certificates``, ``statuses``,
        ``modes`` (counts per value, ``"none"`` for None), ``proven_steps`` (steps whose
        certificate's claim holds for the w applied: status PROVED, or ``"ok"`` with a
        certificate, as the set-sequence controllers report it, and a w inside the
        disturbances the proof is about), ``proven_for_another_w`` (steps proven for the
        controller's disturbances only, e.g. the nominal w, while another w was applied:
        not counted as proven), ``not_proven`` (the steps without a proof, counted by
        certificate label, ``"none"`` for a step without one: e.g. a local-law step in a
        set whose invariance is not proven keeps the label ``"local_law"`` and counts here),
        ``guarantee`` (the controller's, None when it states none),
        ``step_kinds`` (steps per
        :attr:`step_kind`: ``"solver"``, ``"local_law"``, ``"other"``; they add up to
        ``steps``), ``horizons`` (histogram of the prediction horizons, keys as strings,
        over the steps that report no level), ``levels`` (histogram of the set-sequence
        levels ``i(k)``; empty for other controllers), ``solve_time`` (``min``,
        ``median``, ``max``, ``mean``, ``total`` in s over the steps that used the solver
        only, and ``steps``, how many those are; the figures are None when no step used
        it) and ``call_time`` (the same figures over all steps of the run, as measured by
        the simulator; None for a run of 0 steps). Non-finite numbers (a diverged run)
        are written as None.
        """
        def counts(values: tuple) -> dict[str, int]:
            c = Counter("none" if v is None else str(v) for v in values)
            return dict(sorted(c.items()))

        def histogram(values: list) -> dict[str, int]:
            hist = Counter(values)
            return {("none" if h is None else str(h)): int(c) for h, c in
                    sorted(hist.items(), key=lambda kv: (kv[0] is None, kv[0] or 0))}

        kinds = self.step_kind
        # a proven step: status PROVED (contractive MPC), or "ok" with a certificate (the
        # set-sequence controllers report a proven step as "ok", the others by the name of
        # their status); "ok" without a certificate is a controller that reports none
        claimed = [st == "PROVED" or (st == "ok" and c is not None)
                   for st, c in zip(self.status, self.certificate, strict=True)]
        # a proof about other disturbances than the one applied does not prove the step
        other_w = [ok and cov is False for ok, cov in zip(claimed, self.proof_covers_w,
                                                           strict=True)]
        proven = [ok and not o for ok, o in zip(claimed, other_w, strict=True)]
        solver = np.array([k == "solver" for k in kinds], dtype=bool)
        solve_time = _time_stats(self.solve_time[solver])
        solve_time["steps"] = int(solver.sum())
        return {
            "model": self.model_name,
            "n": int(self.x.shape[1]),
            "m": int(self.u.shape[1]),
            "l": int(self.w.shape[1]),
            "steps": self.steps,
            "stop_reason": self.stop_reason,
            "interrupted": self.interrupted,
            "disturbance": self.disturbance,
            "seed": self.seed,
            "x0": _json_floats(self.x[0]),
            "final_state": _json_floats(self.x[-1]),
            "final_norm_inf": _json_float(np.max(np.abs(self.x[-1]))),
            "final_error_inf": (None if self.x_ref is None else _json_float(
                np.max(np.abs(self.x[-1] - np.asarray(self.x_ref, dtype=float))))),
            "violations": {"state": self.violations["state"], "input": self.violations["input"],
                           "state_steps": list(self.violations["state_steps"]),
                           "input_steps": list(self.violations["input_steps"])},
            "certificates": counts(self.certificate),
            "statuses": counts(self.status),
            "proven_steps": sum(proven),
            "proven_for_another_w": sum(other_w),
            "not_proven": counts(tuple(c for c, ok in zip(self.certificate, claimed,
                                                          strict=True) if not ok)),
            "guarantee": self.guarantee or None,
            "modes": counts(self.mode),
            "step_kinds": {k: kinds.count(k) for k in _STEP_KINDS},
            "horizons": histogram([h for h, lv in zip(self.horizon, self.level, strict=True)
                                   if lv is None]),
            "levels": histogram([lv for lv in self.level if lv is not None]),
            "solve_time": solve_time,
            "call_time": _time_stats(self.call_time),
        }

    def to_json(self, indent: int | None = 2) -> str:
        """:meth:`summary` as a JSON string."""
        return json.dumps(self.summary(), indent=indent)

    # ------------------------------------------------------------ persistence
    def _payload(self) -> dict[str, Any]:
        return {
            "format": _FORMAT, "version": _FORMAT_VERSION,
            "model_name": self.model_name, "stop_reason": self.stop_reason,
            "disturbance": self.disturbance, "seed": self.seed,
            "status": list(self.status), "certificate": list(self.certificate),
            "horizon": list(self.horizon), "mode": list(self.mode),
            "level": list(self.level), "proof_covers_w": list(self.proof_covers_w),
            "guarantee": self.guarantee,
            "x_ref": None if self.x_ref is None else _json_floats(self.x_ref),
            "violations": {k: (list(v) if isinstance(v, tuple) else v)
                           for k, v in self.violations.items()},
        }

    def save(self, path: str | Path) -> Path:
        """Write the whole trajectory (not the model) to ``path``.

        Parameters
        ----------
        path : str or Path
            Ends in ``.json`` (text: arrays as nested lists, exact floats) or ``.npz``.

        Returns
        -------
        pathlib.Path
            The written file. :meth:`load` reads it back exactly.
        """
        path = Path(path)
        arrays = {"x": self.x, "u": self.u, "w": self.w, "solve_time": self.solve_time,
                  "call_time": self.call_time}
        if path.suffix == ".json":
            data = self._payload()
            data["summary"] = self.summary()
            for k, a in arrays.items():
                data[k] = {"shape": list(a.shape), "data": a.ravel().tolist()}
            path.write_text(json.dumps(data, indent=1))
        elif path.suffix == ".npz":
            np.savez(path, meta=np.array(json.dumps(self._payload())), **arrays)
        else:
            raise ValueError(f"the file name must end in .json or .npz; got '{path.name}'")
        return path

    @classmethod
    def load(cls, path: str | Path, model: Model | None = None) -> Trajectory:
        """Read a trajectory written by :meth:`save`.

        Parameters
        ----------
        path : str or Path
            A ``.json`` or ``.npz`` file.
        model : Model, optional
            Attach this model (its n, m, l must match) so that :meth:`plot` can draw X and U.
        """
        path = Path(path)
        if path.suffix == ".json":
            data = json.loads(path.read_text())
            arrays = {k: np.array(data[k]["data"], dtype=float).reshape(data[k]["shape"])
                      for k in ("x", "u", "w", "solve_time", "call_time")}
        elif path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as z:
                data = json.loads(str(z["meta"]))
                arrays = {k: np.array(z[k]) for k in ("x", "u", "w", "solve_time", "call_time")}
        else:
            raise ValueError(f"the file name must end in .json or .npz; got '{path.name}'")
        if data.get("format") != _FORMAT:
            raise ValueError(f"'{path}' does not hold a saved Trajectory")
        return cls(**arrays, status=tuple(data["status"]),
                   certificate=tuple(data["certificate"]), horizon=tuple(data["horizon"]),
                   mode=tuple(data["mode"]), level=tuple(data.get("level", ())),
                   proof_covers_w=tuple(data.get("proof_covers_w", ())),
                   guarantee=str(data.get("guarantee", "")), x_ref=data.get("x_ref"),
                   violations=data["violations"], model=model,
                   stop_reason=data["stop_reason"], disturbance=data["disturbance"],
                   seed=data["seed"], model_name=data["model_name"])

    # ------------------------------------------------------------------- plot
    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), **kw: Any) -> Any:
        """Draw the phase plane and the time series of states, inputs and disturbances.

        Axis labels are the model's names and units (``"name [unit]"``), time is in
        seconds when the model has a sampling time ``dt`` (else the step k).

        Parameters
        ----------
        ax : matplotlib Axes, sequence of Axes, or None
            Where to draw (see :func:`casadi_cmpc.plot.plot_trajectory`).
        dims : (int, int)
            States on the axes of the phase plane.
        **kw
            Keywords of :func:`casadi_cmpc.plot.plot_trajectory`: ``sets``, ``obstacles``,
            ``obstacle_label``, ``state_names``, ``input_names``, ``disturbance_names``,
            ``states``, ``disturbance``, ``horizon`` (default ``"auto"``: a panel of the
            level i(k) of a run along a set sequence, when :attr:`level` records one;
            ``"horizon"``: the horizon N(k) of a contractive MPC), ``equal_aspect``,
            ``title``.

        Returns
        -------
        matplotlib Figure
        """
        from ..plot import plot_trajectory

        return plot_trajectory(self, ax=ax, dims=dims, **kw)


def _summary_lines(s: Mapping[str, Any]) -> list[str]:
    """Lines that say what a run's :meth:`Trajectory.summary` ``s`` counts: which steps used
    the solver, the solve time over those only, and the levels of a set sequence or the
    prediction horizons (never one for the other)."""
    kinds = s.get("step_kinds") or {}
    n_solver, n_law, n_other = (int(kinds.get(k, 0)) for k in _STEP_KINDS)
    total = n_solver + n_law + n_other

    def plural(k: int, word: str) -> str:
        return f"{k} {word}{'' if k == 1 else 's'}"

    parts = [f"{n_solver} used the solver", f"{n_law} the local law (no solver)"]
    if n_other:
        modes = {m: c for m, c in (s.get("modes") or {}).items()
                 if m not in _SOLVER_MODES | _LAW_MODES}
        parts.append(f"{n_other} neither" + (" (mode " + ", ".join(
            f"{m}: {c}" for m, c in modes.items()) + ")" if modes else ""))
    lines = [f"steps: {total}, of which " + ", ".join(parts)]
    st = s.get("solve_time") or {}
    if st.get("median") is not None:
        lines.append(f"solve time per solver step ({plural(n_solver, 'step')}): median "
                     f"{st['median'] * 1e3:.3g} ms, max {st['max'] * 1e3:.3g} ms")
    else:
        lines.append("solve time: no step used the solver")
    levels = sorted(((int(k), int(c)) for k, c in (s.get("levels") or {}).items()),
                    reverse=True)
    if levels:
        # consecutive levels with the same count as one group: "i = 13..1: 1 step each"
        groups: list[list[int]] = []
        for i, c in levels:
            if groups and groups[-1][1] == i + 1 and groups[-1][2] == c:
                groups[-1][1] = i
            else:
                groups.append([i, i, c])
        lines.append("level i(k) of the set sequence (x(k) in K_i, K_0 = T): " + ", ".join(
            f"i = {a}: {plural(c, 'step')}" if a == b else
            f"i = {a}..{b}: {plural(c, 'step')} each" for a, b, c in groups))
    horizons = {k: c for k, c in (s.get("horizons") or {}).items() if k != "none"}
    if horizons:
        lines.append("prediction horizons used: " + ", ".join(
            f"N = {k}: {plural(c, 'step')}" for k, c in horizons.items()))
    if "proven_steps" in s and total:  # what the certificates of the steps proved
        unproven = s.get("not_proven") or {}
        other = int(s.get("proven_for_another_w") or 0)
        lines.append(f"proven steps: {int(s['proven_steps'])} of {total}" + (
            f"; {plural(other, 'step')} proven for other disturbances than the w applied "
            "(not counted)" if other else "") + (
            "; not proven: " + ", ".join(f"{'no certificate' if k == 'none' else k}: {c}"
                                         for k, c in unproven.items()) if unproven else ""))
    return lines


def _json_float(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _json_floats(a: np.ndarray) -> list[float | None]:
    return [_json_float(v) for v in np.asarray(a).ravel()]


def _time_stats(t: np.ndarray) -> dict[str, float | None]:
    keys = ("min", "median", "max", "mean", "total")
    if t.size == 0:
        return dict.fromkeys(keys)
    vals = (np.min(t), np.median(t), np.max(t), np.mean(t), np.sum(t))
    return {k: _json_float(v) for k, v in zip(keys, vals, strict=True)}


def _count_violations(model: Model, x: np.ndarray, u: np.ndarray) -> dict[str, Any]:
    """Steps k >= 1 with x(k) outside X and steps k with u(k) outside U (no tolerance)."""
    X, U = model.X, model.U
    with np.errstate(invalid="ignore"):
        xs = x[1:]
        x_out = ~((xs >= X.lo) & (xs <= X.hi)).all(axis=1)
        u_out = ~((u >= U.lo) & (u <= U.hi)).all(axis=1)
    s_steps = tuple(int(k) + 1 for k in np.flatnonzero(x_out))
    i_steps = tuple(int(k) for k in np.flatnonzero(u_out))
    return {"state": len(s_steps), "input": len(i_steps), "state_steps": s_steps,
            "input_steps": i_steps}


# ------------------------------------------------------------------------ controllers
class _Controller:
    """Uniform call ``u = c(x)`` around a callable, a gain matrix or a CasADi law."""

    def __init__(self, model: Model, ctrl: Any) -> None:
        n, m = model.n, model.m
        self.source = ctrl
        self.reports = False
        self.mode = "feedback"
        # the "horizon" a set-sequence controller reports is the level of the state
        from .sequence import SetSequenceMPC

        self.levels = isinstance(ctrl, SetSequenceMPC)
        # the disturbances the controller's proofs are about (l, 2), and what it guarantees
        scope = getattr(ctrl, "proof_w", None) if model.l else None
        self.w_scope = None if scope is None else np.asarray(scope, dtype=float).reshape(
            model.l, 2)
        text = getattr(ctrl, "guarantee", None)
        self.guarantee = text if isinstance(text, str) else ""
        if ctrl is None:
            if m > 0:
                raise TypeError(f"ctrl is None but model '{model.name}' has m = {m} input(s); "
                                "pass a callable x -> u or a gain matrix K of shape "
                                f"({m}, {n}) (u = K x)")
            self.mode = "autonomous"
            self.fun: Callable[[np.ndarray], Any] = lambda x: np.zeros(0)
        elif isinstance(ctrl, (ca.SX, ca.MX)):
            self.fun = _casadi_law(model, ctrl)
        elif isinstance(ctrl, ca.Function) or callable(ctrl):
            self.fun = ctrl
            self.reports = True
        else:
            try:
                K = as_float_array(ctrl, "the gain K")
            except InvalidBoundsError as exc:
                raise TypeError(
                    "ctrl must be a callable x -> u, a gain matrix K of shape (m, n) = "
                    f"({m}, {n}) or a casadi.SX law in the model's x; got "
                    f"{type(ctrl).__name__} ({exc})") from None
            if K.ndim == 0 and n == 1 and m == 1:
                K = K.reshape(1, 1)
            elif K.ndim == 1 and m == 1 and K.size == n:
                K = K.reshape(1, n)
            if K.shape != (m, n):
                raise DimensionError(
                    f"a gain K must have shape (m, n) = ({m}, {n}) (u = K x); got {K.shape}")
            if not np.isfinite(K).all():
                raise ValueError("the gain K contains NaN or infinite entries")
            K = K.copy()
            self.fun = lambda x: K @ x

    def covers(self, w: np.ndarray) -> bool | None:
        """Whether the w applied lies in the disturbances the proofs are about (None: the
        controller names none)."""
        if self.w_scope is None:
            return None
        return bool(np.all((self.w_scope[:, 0] <= w) & (w <= self.w_scope[:, 1])))

    def info(self) -> Mapping[str, Any] | None:
        """The controller's ``last_info`` dict after a call, or None."""
        if not self.reports:
            return None
        info = getattr(self.source, "last_info", None)
        return info if isinstance(info, Mapping) else None


def _casadi_law(model: Model, law: Any) -> Callable[[np.ndarray], Any]:
    if isinstance(law, ca.MX):
        raise TypeError("give a CasADi law as casadi.SX in the model's x, a casadi.Function "
                        "or a callable x -> u")
    if law.numel() != model.m:
        raise DimensionError(f"the law must have {model.m} element(s) (one per input); "
                             f"got shape {law.shape}")
    allowed = {model.x[i].__hash__() for i in range(model.n)}
    free = [s for s in ca.symvar(law) if s.__hash__() not in allowed]
    if free:
        raise ModelError("the law may depend on the model's x only; it depends on "
                         + ", ".join(str(s) for s in free))
    fun = ca.Function("law", [model.x], [ca.reshape(law, model.m, 1)])
    return lambda x: fun(x)


def _check_vector(value: Any, d: int, what: str, k: int) -> np.ndarray:
    """A controller's or disturbance's value at step k as a finite float array (d,)."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{what} at step {k} is not numeric: {value!r}") from exc
    if arr.shape in ((d,), (d, 1)) or (arr.ndim == 0 and d == 1):
        arr = arr.reshape(d)
    else:
        raise DimensionError(f"{what} at step {k} has shape {arr.shape}; expected ({d},)"
                             + (" or a scalar" if d == 1 else ""))
    if not np.isfinite(arr).all():
        raise ValueError(f"{what} at step {k} is not finite: {arr.tolist()}")
    return arr


# ----------------------------------------------------------------------- disturbances
def _disturbance(model: Model, disturbance: Any, steps: int, seed: Any
                 ) -> tuple[str, Callable[[int, np.ndarray], np.ndarray]]:
    """``(label, w_at)`` with ``w_at(k, x) -> (l,)`` a point of W."""
    l = model.l
    if l == 0:
        if disturbance is not None:
            raise ModelError(f"model '{model.name}' has no disturbance w (l = 0); "
                             "leave disturbance=None")
        zero = np.zeros(0)
        return "none", lambda k, x: zero
    W = model.W_box
    if isinstance(disturbance, str):
        key = disturbance.lower()
        if key in ("centre", "center"):
            disturbance = None
        elif key in ("uniform", "vertices"):
            rng = np.random.default_rng(seed)
            if key == "uniform":
                draws = np.clip(W.lo + (W.hi - W.lo) * rng.random((steps, l)), W.lo, W.hi)
            else:
                draws = np.where(rng.integers(0, 2, size=(steps, l)).astype(bool), W.hi, W.lo)
            return key, lambda k, x: draws[k]
        else:
            raise ValueError(f"unknown disturbance '{disturbance}'; use None (centre of W), "
                             "'uniform', 'vertices', an array (steps, l) or (l,), or a "
                             "callable (k, x) -> w")
    if disturbance is None:
        centre = W.mid.copy()
        return "centre", lambda k, x: centre
    if callable(disturbance):
        def w_at(k: int, x: np.ndarray) -> np.ndarray:
            w = _check_vector(disturbance(k, x.copy()), l, "the disturbance", k)
            _check_in_W(W, w[None], k)
            return w
        return "callable", w_at
    arr = as_float_array(disturbance, "disturbance")
    if arr.ndim == 0 and l == 1:
        arr = arr.reshape(1)
    if arr.ndim == 1 and arr.size == l:
        const = arr.copy()
        rows = np.broadcast_to(const, (steps, l))
    elif arr.ndim == 1 and l == 1 and arr.size == steps:
        rows = arr.reshape(steps, 1).copy()
    elif arr.ndim == 2 and arr.shape == (steps, l):
        rows = arr.copy()
    else:
        raise DimensionError(f"a disturbance array must have shape (steps, l) = ({steps}, {l}) "
                             f"or ({l},) for a constant w; got {arr.shape}")
    if not np.isfinite(rows).all():
        k = int(np.flatnonzero(~np.isfinite(rows).all(axis=1))[0])
        raise ValueError(f"the disturbance at step {k} is not finite: {rows[k].tolist()}")
    _check_in_W(W, rows, 0)
    return "array", lambda k, x: rows[k]


def _check_in_W(W: Any, rows: np.ndarray, k0: int) -> None:
    """Raise naming the first step whose w lies outside W (no tolerance)."""
    out = ~((rows >= W.lo) & (rows <= W.hi)).all(axis=1)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        j = int(np.flatnonzero((rows[i] < W.lo) | (rows[i] > W.hi))[0])
        raise ValueError(f"the disturbance at step {k0 + i} lies outside W: w[{j}] = "
                         f"{rows[i, j]:.17g} not in [{W.lo[j]:.17g}, {W.hi[j]:.17g}]")


# --------------------------------------------------------------------------- simulate
def simulate(model: Model, ctrl: Any, x0: Any, steps: int, disturbance: Any = None,
             seed: int | np.random.Generator | None = 0, *,
             stop_when: Callable[[np.ndarray], bool] | None = None, check_x0: bool = True,
             progress: bool | None = None,
             plant: Callable[[np.ndarray, np.ndarray, np.ndarray], Any] | None = None
             ) -> Trajectory:
    """Run ``x(k+1) = f(x(k), u(k), w(k))`` with ``u(k) = ctrl(x(k))`` for ``steps`` steps.

    Parameters
    ----------
    model : Model
        The system (units of its states and inputs are those of the model).
    ctrl : callable, array_like or casadi.SX
        The controller: a callable ``x (n,) -> u (m,)`` (a scalar when ``m = 1``; a
        ``casadi.Function`` works too), a gain matrix ``K`` of shape ``(m, n)`` (``u = K x``;
        a 1-D gain of length n when ``m = 1``), or a ``casadi.SX`` law in ``model.x``.
        None only for a model without input (``m = 0``). A controller of this library sets
        ``ctrl.last_info`` (a dict with ``"status"``, ``"certificate"``, ``"horizon"``,
        ``"solve_time"``, ``"mode"``) after each call; those are recorded per step (absent
        keys as None, an absent ``solve_time`` as the measured call time).
    x0 : array_like, shape (n,)
        Initial state; finite and inside X unless ``check_x0=False``.
    steps : int
        Number of steps, at least 0.
    disturbance : None, str, array_like or callable
        How w is chosen at each step (a model without w accepts only None):

        - None: the centre of W at every step (nominal run; also ``"centre"``);
        - ``"uniform"``: uniform in W, independently per step;
        - ``"vertices"``: a random vertex of W per step (each component at its lower or
          upper bound with probability 1/2);
        - an array of shape ``(steps, l)`` (row k is w(k)) or ``(l,)`` (constant);
        - a callable ``(k, x (n,)) -> w (l,)``.

        Arrays and callable values must be finite and lie in W.
    seed : int, numpy Generator or None
        Seed of the random disturbances (the same seed gives the same draws).
    stop_when : callable, optional
        ``stop_when(x (n,)) -> bool`` is tested on every state ``x(k)``, ``k < steps``,
        before the control is computed; the run ends at the first state where it holds
        (``stop_reason == "stop_when"``, K = k steps).
    check_x0 : bool
        Refuse an ``x0`` outside X (default). With False the run starts anyway; ``x(0)`` is
        never counted as a violation.
    progress : bool or None
        tqdm progress bar; None: shown only when the run lasts more than 2 s. Its total is
        ``steps`` only when the run has no other end; with ``stop_when`` the bar counts
        the steps done (at most ``steps``), and a run that ends normally closes it with its
        total equal to the steps done.
    plant : callable, optional
        ``plant(x (n,), u (m,), w (l,)) -> x_next (n,)``: the system actually run, e.g. an
        accurate ODE integration over one sample of a model built by
        :meth:`~casadi_cmpc.Model.from_ode` (u and w held over the sample). Default: the
        model's map :attr:`~casadi_cmpc.Model.function` (of a validated ODE model its
        Taylor polynomial, of an Euler/RK4 model that map).

    Returns
    -------
    Trajectory
        With ``K = steps`` rows of inputs, or fewer when stopped by ``stop_when``, by a
        KeyboardInterrupt (the steps completed so far are returned, ``stop_reason ==
        "interrupted"``) or by a non-finite successor state (``"diverged"``; that state is
        the last row of ``x``).

    Notes
    -----
    Inputs outside U are applied as returned, not clipped: the model is evaluated at the
    given value and the step is counted in ``violations["input"]``. States ``x(k)``,
    ``k >= 1``, outside X are counted in ``violations["state"]``. Both tests are the
    simulator's own (not the controller's) and have no tolerance.

    Raises
    ------
    TypeError
        ``model`` is not a Model, ``steps`` is not an integer, ``ctrl`` is None for a model
        with inputs, or a controller returns something that is not numeric.
    DimensionError
        ``x0``, the gain, a disturbance array or a value returned at some step has the
        wrong shape (the message names the step).
    ModelError
        A disturbance is given for a model without w.
    ValueError
        ``steps < 0``; ``x0`` not finite or outside X (the message lists the components);
        an unknown disturbance name; a disturbance outside W or a NaN input (naming the step).

    Examples
    --------
    >>> import casadi as ca, numpy as np, casadi_cmpc as cm
    >>> x = ca.SX.sym("x", 2); u = ca.SX.sym("u"); w = ca.SX.sym("w")
    >>> f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * u + w)
    >>> model = cm.Model(x=x, u=u, w=w, f=f, X=cm.Box([-5, -5], [5, 5]),
    ...                  U=cm.Box([-3], [3]), W=cm.Box([-0.01], [0.01]))
    >>> traj = cm.simulate(model, [[-3.0, -4.0]], x0=[1.0, 0.0], steps=50,
    ...                    disturbance="uniform", seed=1)
    >>> traj.x.shape, traj.u.shape, traj.w.shape
    ((51, 2), (50, 1), (50, 1))
    >>> bool(np.abs(traj.x[-1]).max() < 0.2), traj.violations["state"]
    (True, 0)
    """
    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    steps = _check_steps(steps)
    n, m, l = model.n, model.m, model.l
    x_init = _check_x0(model, x0, check_x0)
    controller = _Controller(model, ctrl)
    label, w_at = _disturbance(model, disturbance, steps, seed)
    if stop_when is not None and not callable(stop_when):
        raise TypeError("stop_when must be a callable x -> bool or None")
    if plant is not None and not callable(plant):
        raise TypeError("plant must be a callable (x, u, w) -> x_next or None")
    F = model.function if plant is None else plant

    xs = np.empty((steps + 1, n))
    us = np.empty((steps, m))
    ws = np.empty((steps, l))
    xs[0] = x_init
    status: list[Any] = []
    certificate: list[Any] = []
    horizon: list[Any] = []
    mode: list[Any] = []
    level: list[Any] = []
    covers: list[Any] = []
    solve_time: list[float] = []
    call_time: list[float] = []
    done = 0
    reason = "steps"

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # tqdm.auto without ipywidgets warns, then uses text
        from tqdm.auto import tqdm
    bar = tqdm(total=_bar_total(steps, stop_when), desc=f"simulate {model.name}",
               unit="step", disable=progress is False or steps == 0,
               delay=0 if progress else 2.0, leave=False)
    if stop_when is not None and not bar.disable:
        bar.set_postfix_str(f"stops when stop_when holds, at most {steps} steps",
                            refresh=False)
    scope = InterruptScope()
    try:
        for k in range(steps):
            x = xs[k]
            if stop_when is not None and bool(stop_when(x.copy())):
                reason = "stop_when"
                break
            t0 = time.perf_counter()
            try:
                u_raw = controller.fun(x.copy())
            except NotControllableError as exc:
                reason = "not_controllable"
                warnings.warn(f"the state lies in no set of the controller's sequence at step "
                              f"{k} ({x.tolist()}): not controllable as far as the sequence "
                              f"proves; the simulation stops there ({exc})", CmpcWarning,
                              stacklevel=2)
                break
            except Exception as exc:
                if hasattr(exc, "add_note"):  # Python >= 3.11
                    exc.add_note(f"raised by the controller at step {k}, x = {x.tolist()}")
                raise
            elapsed = time.perf_counter() - t0
            u = _check_vector(u_raw, m, "the controller's input", k)
            info = controller.info()
            w = w_at(k, x)
            x_next = np.asarray(F(x, u, w), dtype=float)
            if x_next.size != n:
                raise DimensionError(f"the plant returned {x_next.size} numbers at step {k}; "
                                     f"expected the {n} of the next state")
            x_next = x_next.reshape(n)
            rec = _record(info, controller.mode, elapsed, controller.levels)
            # commit the step only when all of it is computed
            us[k], ws[k], xs[k + 1] = u, w, x_next
            for lst, v in zip((status, certificate, horizon, mode, solve_time, level),
                              rec, strict=True):
                lst.append(v)
            covers.append(controller.covers(w))
            call_time.append(elapsed)
            done = k + 1
            if not bar.disable:
                bar.update(1)
            if not np.isfinite(x_next).all():
                reason = "diverged"
                warnings.warn(f"the state became non-finite at step {k + 1} "
                              f"({x_next.tolist()}); the simulation stops there",
                              RuntimeWarning, stacklevel=2)
                break
    except KeyboardInterrupt:
        scope.reraise_if_nested()
        reason = "interrupted"
    finally:
        scope.close()
        _close_bar(bar, done, reason)

    x_arr, u_arr = xs[:done + 1], us[:done]
    return Trajectory(
        x=x_arr, u=u_arr, w=ws[:done], status=tuple(status), certificate=tuple(certificate),
        horizon=tuple(horizon), solve_time=np.array(solve_time), call_time=np.array(call_time),
        mode=tuple(mode), violations=_count_violations(model, x_arr, u_arr), model=model,
        stop_reason=reason, disturbance=label,
        seed=int(seed) if isinstance(seed, (int, np.integer)) else None,
        model_name=model.name, level=tuple(level), proof_covers_w=tuple(covers),
        guarantee=controller.guarantee, x_ref=_x_ref_of(ctrl, model.n))


def _x_ref_of(controller: Any, n: int) -> np.ndarray | None:
    """The state the controller regulates to (its ``x_ref``, (n,)), or None."""
    ref = getattr(controller, "x_ref", None)
    if ref is None:
        return None
    ref = np.asarray(ref, dtype=float).reshape(-1)
    return ref if ref.shape == (n,) else None


def _record(info: Mapping[str, Any] | None, mode: str, elapsed: float, levels: bool = False
            ) -> tuple[Any, Any, Any, Any, float, Any]:
    """(status, certificate, horizon, mode, solve_time, level) of one step; ``levels``: the
    controller's ``"horizon"`` is a set-sequence level (used when it reports no ``"level"``)."""
    if info is None:
        return "ok", None, None, mode, elapsed, None

    def text(key: str) -> str | None:
        v = info.get(key)
        return None if v is None else str(v)

    h = info.get("horizon")
    st = info.get("solve_time")
    lv = info["level"] if "level" in info else (h if levels else None)
    return (text("status"), text("certificate"), None if h is None else int(h),
            text("mode"), elapsed if st is None else float(st), None if lv is None else int(lv))


def _bar_total(steps: int, stop_when: Any) -> int | None:
    """The total of the progress bar: ``steps`` when the run ends only there, else None (a
    run that stops early at ``stop_when`` is not an aborted one)."""
    return steps if stop_when is None else None


def _close_bar(bar: Any, done: int, reason: str) -> None:
    """Close the progress bar; a run that ended normally (all steps or ``stop_when``) shows
    ``done / done``, an interrupted or diverged one keeps its total."""
    if reason in ("steps", "stop_when") and bar.total != done:
        bar.total = done
        bar.refresh()
    bar.close()


def _check_steps(steps: Any) -> int:
    if isinstance(steps, bool):
        raise TypeError("steps must be an integer >= 0; got a bool")
    try:
        k = operator.index(steps)
    except TypeError:
        raise TypeError(f"steps must be an integer >= 0; got {steps!r}") from None
    if k < 0:
        raise ValueError(f"steps must be >= 0; got {k}")
    return int(k)


def _check_x0(model: Model, x0: Any, check: bool) -> np.ndarray:
    n = model.n
    x = as_float_array(x0, "x0")
    if x.ndim == 0 and n == 1:
        x = x.reshape(1)
    if x.shape != (n,):
        raise DimensionError(f"x0 must have shape ({n},); got {x.shape}")
    if not np.isfinite(x).all():
        bad = np.flatnonzero(~np.isfinite(x)).tolist()
        raise ValueError(f"x0 must be finite; components {bad} are {x[bad].tolist()}")
    if check:
        X = model.X
        parts = [f"x0[{i}] = {x[i]:.17g} < {X.lo[i]:.17g} (lower bound)" if x[i] < X.lo[i]
                 else f"x0[{i}] = {x[i]:.17g} > {X.hi[i]:.17g} (upper bound)"
                 for i in range(n) if not X.lo[i] <= x[i] <= X.hi[i]]
        if parts:
            raise ValueError("x0 lies outside the state box X: " + "; ".join(parts)
                             + "; pass check_x0=False to simulate from outside X anyway")
    return x.copy()
