"""The ``cmpc`` command line.

``cmpc run [EXAMPLE] [--out DIR]`` is the main job: it loads a thesis example (default
``cannon_robust``) and builds the controller the library has for it. For the examples with
controllable sets (``example.info["sequence"]``: E8, E9, E10, E14) that is the full pipeline:
certify the terminal set, compute (or load from the cache) the sequence of (robust)
controllable sets, and run the dual-mode one-step MPC along it, every control certified.
The two structured examples of thesis chapter 6 run their own pipelines:
``khalil_affine_state`` (E11, ``info["affine_state"]``: T proven, the affine-state
controllable sets of Alg 6.4-6.6, the one-step MPC along them) and
``khalil_affine_control`` (E12, ``info["quasi"]``: T proven, the quasi 2-step robust
controllable sets of Alg 6.7 and the MPC of Alg 6.8); ``--eps`` changes the resolution of
any set pipeline. For the others (or with ``--controller contractive``) it is the
contractive MPC of thesis §4.3 configured in ``example.info["mpc"]``. It simulates the
closed loop from the thesis' initial states, checks the constraints itself, and prints a
summary. With ``--out DIR`` it writes the figures (PNG), ``summary.json`` and
``report.txt``.

``cmpc list`` prints the examples (name, thesis example or "extra" for the examples not from
the thesis, dimensions, what the system is).
``cmpc cache`` prints the directory of cached set sequences with its files and their sizes;
``cmpc cache --clear`` deletes them. ``cmpc export EXAMPLE --out DIR [--build]`` writes the
controller as C (with ``--build``, make and a C compiler are checked first).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["main"]

DEFAULT_EXAMPLE = "cannon_robust"


def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if np.isfinite(f) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    return v


def _obstacle_distances(traj: Any, run: dict) -> np.ndarray | None:
    obs = run.get("obstacles")
    if obs is None:
        return None
    obs = np.asarray(obs, dtype=float)
    d = np.linalg.norm(traj.x[:, None, :2] - obs[None, :, :], axis=2)
    return d.min(axis=1)


# bumped when what a cached sequence holds changes (2: the proven law of T is stored;
# 3: compressed arrays, K_i stored as a reference to the step boxes, the law's key)
_SEQUENCE_FORMAT = "sequence-format-3"

# the names of the files `cmpc run` writes in the cache (and `cmpc cache --clear` removes)
_CACHE_FILE = r"[A-Za-z0-9_]+-[0-9a-f]{16}\.npz"
_PARTIAL_FILE = r"\.[A-Za-z0-9_]+-[0-9a-f]{16}\.[0-9]+\.partial\.npz"


def _cache_dir(cache: str | None) -> Path:
    """The directory of cached set sequences: ``cache`` when given, else
    ``$XDG_CACHE_HOME/casadi_cmpc`` or ``~/.cache/casadi_cmpc``."""
    import os

    if cache:
        return Path(cache)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "casadi_cmpc"


def _law_key(ex: Any) -> str:
    """A key of the example's local law: the hash of its expression in x (a gain, a law
    object with its equilibrium and an SX expression alike)."""
    from .control.invariance import law_identity

    return law_identity(ex.model, ex.local_law)["law_key"]


def _cache_path(ex: Any, cfg: dict, cache: str | None) -> Path:
    """A file name that changes with the model, T, the law and the settings."""
    from . import __version__
    from .control._checkpoint import digest
    from .control.invariance import model_key

    h = digest((model_key(ex.model), np.asarray(ex.terminal.A).tobytes(),
                np.asarray(ex.terminal.b).tobytes(), _law_key(ex),
                repr(sorted((k, v) for k, v in cfg.items() if k in ("eps", "robust"))),
                __version__, _SEQUENCE_FORMAT))
    return _cache_dir(cache) / f"{ex.name}-{h[:16]}.npz"


def _size(nbytes: int) -> str:
    """``nbytes`` for a reader: ``"512 B"``, ``"1.5 kB"``, ``"892.5 MB"`` (powers of 1000)."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{nbytes} B"


# statuses of a sequence that answers its settings completely (cached and reused)
_COMPLETE = ("converged", "max_steps", "until")


def _cache_mismatch(seq: Any, ex: Any, cfg: dict) -> str | None:
    """Why a cached sequence does not answer this run (None when it does)."""
    from .control.invariance import model_key

    info = seq.info
    if seq.status not in _COMPLETE:
        return f"its computation stopped early: status '{seq.status}'"
    if info.get("model_key") != model_key(ex.model):
        return "it was computed for another model"
    if float(info.get("eps", -1.0)) != float(cfg["eps"]) or \
            bool(info.get("robust")) != bool(cfg["robust"]):
        return "it was computed with other settings"
    if info.get("terminal_certificate") != "proved":
        return "its terminal set is not proven invariant"
    if info.get("terminal_law_key", _law_key(ex)) != _law_key(ex):
        return "its terminal set was proven invariant under another local law"
    return None


def _save_atomically(seq: Any, path: Path) -> None:
    """Write ``seq`` to ``path`` through a partial file renamed when complete (an
    interrupted write leaves no truncated cache file under the final name)."""
    from .control._checkpoint import save_atomically

    save_atomically(seq, path)


def _sequence_controller(ex: Any, cache: str | None, progress: bool | None,
                         solver: str | None = None, checkpoint: str | None = None,
                         executor: Any = None, eps: float | None = None) -> Any:
    """The SetSequenceMPC of an example and its sequence, from the cache or computed (and
    then cached); ``solver`` overrides the example's (default ipopt); ``checkpoint``: the
    file that makes the computation resumable (see :func:`controllable_sets`); ``executor``:
    where the large levels of the set computation run; ``eps`` replaces the example's."""
    from .control.controllable import controllable_sets
    from .control.linear_sets import SetSequence
    from .mpc.sequence import SetSequenceMPC

    cfg = dict(ex.info["sequence"])
    if eps is not None:
        cfg["eps"] = float(eps)
    path = _cache_path(ex, cfg, cache)
    seq = None
    if path.is_file():
        try:
            seq = SetSequence.load(path)
            why = _cache_mismatch(seq, ex, cfg)
            if why:
                print(f"cache {path} does not answer this run ({why}); computing the "
                      "sequence again")
                seq = None
            else:
                print(f"sequence loaded from the cache {path} "
                      f"({_size(path.stat().st_size)})")
        except (ValueError, TypeError, KeyError, OSError) as exc:
            print(f"cache {path} unreadable ({exc}); computing the sequence again")
            seq = None
    if seq is None:
        t0 = time.perf_counter()
        seq = controllable_sets(ex.model, ex.terminal, cfg["eps"], robust=cfg["robust"],
                                law=ex.local_law, progress=progress, checkpoint=checkpoint,
                                executor=executor)
        if checkpoint is not None:
            print(f"checkpoint {checkpoint}: {seq.info.get('resumed_steps', 0)} of the "
                  f"{len(seq.steps)} steps read from it")
        if seq.status == "interrupted":  # a partial sequence is neither used nor cached
            if checkpoint is not None:
                print(f"the completed steps are kept in {checkpoint}: run again with "
                      f"--checkpoint {checkpoint} to resume", file=sys.stderr)
            raise KeyboardInterrupt
        print(f"sequence computed in {time.perf_counter() - t0:.1f} s ({seq.status})")
        if seq.status in _COMPLETE:
            try:
                _save_atomically(seq, path)
                print(f"  cached in {path} ({_size(path.stat().st_size)}; 'cmpc cache' lists "
                      "the cache, 'cmpc cache --clear' empties it)")
            except OSError as exc:
                print(f"  not cached ({exc})")
        else:
            print(f"  not cached: the computation stopped early ({seq.status})")
    print(f"terminal set: {seq.info.get('terminal_certificate')} invariant under the local "
          f"law; sequence: {seq!r}, {len(seq) - 1} steps, eps = {seq.info.get('eps')}, "
          f"{seq.info.get('semantics')}")
    ctrl = SetSequenceMPC(ex.model, seq, Q=cfg.get("Q"), R=cfg.get("R"),
                          local_law=ex.local_law, solver=solver or cfg.get("solver", "ipopt"),
                          robust=cfg["robust"])
    return ctrl, seq


def _set_pipeline(ex: Any) -> str | None:
    """The set pipeline ``cmpc run`` builds for an example: ``"quasi"`` (quasi i-step sets
    and their MPC, Alg 6.7-6.8: E12), ``"affine_state"`` (the controllable sets of the
    affine-state method, Alg 6.4-6.6, and the one-step MPC: E11), ``"sequence"`` (the
    general controllable sets: E8, E9, E10, E14) or None (contractive MPC only)."""
    for key in ("quasi", "affine_state", "sequence"):
        if key in ex.info:
            return key
    return None


def _pipeline_config(ex: Any, eps: float | None) -> dict:
    """The example's set configuration, with ``eps`` (``--eps``) replacing its own."""
    cfg = dict(ex.info[_set_pipeline(ex)])
    if eps is not None:
        cfg["eps"] = float(eps)
    return cfg


# the set sequences of the structured pipelines computed in this process (they are not
# written to the disk cache), by a digest of the model, T, the law and the settings
_SETS_OF_THIS_PROCESS: dict[str, Any] = {}


def _structured_key(ex: Any, cfg: dict) -> str:
    from .control._checkpoint import digest

    items = sorted((k, np.asarray(v).tolist() if isinstance(v, np.ndarray) else v)
                   for k, v in cfg.items() if k != "note")
    from .control.invariance import model_key

    return digest((ex.name, model_key(ex.model), np.asarray(ex.terminal.A).tobytes(),
                   np.asarray(ex.terminal.b).tobytes(), _law_key(ex), repr(items)))


def _until(ex: Any, cfg: dict) -> np.ndarray | None:
    """The run's initial states when the configuration stops the recursion as soon as they
    all lie in a set (``cfg["until_x0s"]``; the sets are then not the maximal ones)."""
    if not cfg.get("until_x0s"):
        return None
    x0s = ex.info.get("run", {}).get("x0s", ex.x0s)
    return np.asarray(x0s, dtype=float).reshape(-1, ex.model.n)


def _affine_state_controller(ex: Any, progress: bool | None, eps: float | None = None,
                             solver: str | None = None, executor: Any = None
                             ) -> tuple[Any, Any]:
    """E11's pipeline (thesis §6.2): T proven robustly invariant under the local law
    (:func:`certify_invariant`, inside :func:`controllable_sets`, on ``executor`` when
    given), the polytopic robust controllable sets of the affine-state method (Alg
    6.4-6.6) to convergence, and the robust one-step MPC along them
    (:class:`SetSequenceMPC`)."""
    from .control.controllable import controllable_sets
    from .mpc.sequence import SetSequenceMPC

    cfg = _pipeline_config(ex, eps)
    key = _structured_key(ex, cfg)
    seq = _SETS_OF_THIS_PROCESS.get(key)
    if seq is None:
        t0 = time.perf_counter()
        seq = controllable_sets(ex.model, ex.terminal, cfg["eps"], robust=cfg["robust"],
                                method="affine_state", law=ex.local_law,
                                polytopic_method=cfg.get("polytopic_method", "separating"),
                                max_steps=int(cfg.get("max_steps", 100)),
                                until=_until(ex, cfg), progress=progress,
                                executor=executor)
        print(f"affine-state controllable sets (Alg 6.4-6.6) computed in "
              f"{time.perf_counter() - t0:.1f} s ({seq.status})")
        if seq.status in _COMPLETE:
            _SETS_OF_THIS_PROCESS[key] = seq
    else:
        print("affine-state controllable sets reused (computed earlier in this process)")
    if len(seq) < 2:
        raise ValueError(f"no controllable set proven at eps = {cfg['eps']} "
                         f"({seq.status}); try a smaller --eps")
    print(f"terminal set: {seq.info.get('terminal_certificate')} invariant under the local "
          f"law; sequence: {len(seq) - 1} steps, eps = {seq.info.get('eps')}, "
          f"{seq.info.get('semantics')}")
    ctrl = SetSequenceMPC(ex.model, seq, Q=cfg.get("Q"), R=cfg.get("R"),
                          local_law=ex.local_law, solver=solver or cfg.get("solver", "ipopt"),
                          robust=cfg["robust"])
    return ctrl, seq


def _quasi_controller(ex: Any, progress: bool | None, eps: float | None = None,
                      solver: str | None = None, executor: Any = None) -> tuple[Any, Any]:
    """E12's pipeline (thesis §6.3): T proven robustly invariant under the local law
    (:func:`certify_invariant` and ``T ⊆ X`` by rigorous support bounds), the recursion of
    polytopic quasi i-step robust controllable sets (Alg 6.7, §6.3.4) to convergence, and
    :class:`QuasiMultiStepMPC` (Alg 6.8) along them; the searches on ``executor`` when
    given."""
    from .control.controllable import _check_terminal, _terminal_info
    from .control.quasi import quasi_controllable_sets
    from .mpc.quasi import QuasiMultiStepMPC

    cfg = _pipeline_config(ex, eps)
    model = ex.model
    key = _structured_key(ex, cfg)
    seqs = _SETS_OF_THIS_PROCESS.get(key)
    if seqs is None:
        t0 = time.perf_counter()
        # T in X (rigorous support bounds) and robustly invariant under the local law
        # (certify_invariant at resolutions relative to T); a clean exit when not proven
        cert = _check_terminal(model, ex.terminal, ex.local_law, None, False, True,
                               cfg["eps"], model.X, executor)
        t_cert = time.perf_counter() - t0
        print(f"terminal set proven robustly invariant under the local law in {t_cert:.1f} s"
              f": {cert.claim}")
        t0 = time.perf_counter()
        seqs = quasi_controllable_sets(
            model, ex.terminal, int(cfg["steps"]), cfg["eps"],
            max_sets=int(cfg.get("max_sets", 30)),
            polytopic_method=cfg.get("polytopic_method", "separating"),
            until=_until(ex, cfg), progress=progress, executor=executor)
        seqs.info.update({"terminal_certificate": cert.label, "robust": model.l > 0,
                          "terminal_seconds": t_cert, **_terminal_info(model, cert)})
        print(f"quasi {seqs.steps}-step robust controllable sets (Alg 6.7) computed in "
              f"{time.perf_counter() - t0:.1f} s ({seqs.status})")
        if seqs.status in ("converged", "until", "max_sets"):
            _SETS_OF_THIS_PROCESS[key] = seqs
    else:
        print(f"quasi {seqs.steps}-step sets reused (computed earlier in this process)")
    if len(seqs) < 2:
        raise ValueError(f"no quasi {seqs.steps}-step set proven at eps = {cfg['eps']} "
                         f"({seqs.status}); try a smaller --eps")
    print(f"terminal set: {seqs.info.get('terminal_certificate')} invariant under the local "
          f"law; sets P_0..P_{len(seqs) - 1}, eps = {seqs.info.get('eps')}, "
          f"{seqs.info.get('semantics')}")
    ctrl = QuasiMultiStepMPC(model, seqs, P0=cfg.get("P0"), Q=cfg.get("Q"), R=cfg.get("R"),
                             local_law=ex.local_law,
                             solver=solver or cfg.get("solver", "ipopt"))
    return ctrl, seqs


def _controller(ex: Any, kind: str = "auto", cache: str | None = None,
                progress: bool | None = None, checkpoint: str | None = None,
                executor: Any = None, eps: float | None = None) -> tuple[Any, Any]:
    """The controller of an example and its set sequence (None for the contractive MPC)."""
    from .mpc.contractive import ContractiveMPC

    pipeline = _set_pipeline(ex)
    if kind == "sequence" and pipeline is None:
        raise ValueError(f"example '{ex.name}' has no controllable-set configuration; use "
                         "--controller contractive")
    if kind in ("auto", "sequence") and pipeline is not None:
        if pipeline != "sequence" and checkpoint is not None:
            raise ValueError(f"--checkpoint is for the general controllable sets; "
                             f"'{ex.name}' runs the {pipeline} pipeline")
        if pipeline == "quasi":
            return _quasi_controller(ex, progress, eps, executor=executor)
        if pipeline == "affine_state":
            return _affine_state_controller(ex, progress, eps, executor=executor)
        return _sequence_controller(ex, cache, progress, checkpoint=checkpoint,
                                    executor=executor, eps=eps)
    if eps is not None:
        raise ValueError("--eps sets the resolution of the controllable sets; the "
                         "contractive MPC has none")
    return ContractiveMPC(ex.model, **ex.info["mpc"]), None


def _sequence_summary(ex: Any, seq: Any, runs: list) -> dict:
    """What ``summary.json`` records of a set sequence (general, affine-state or quasi)."""
    from .control.quasi import QuasiSequence

    out = {"pipeline": _set_pipeline(ex), "steps": len(seq) - 1,
           "converged_at": seq.converged_at, "status": seq.status,
           "eps": seq.info.get("eps"), "semantics": seq.info.get("semantics"),
           "terminal_certificate": seq.info.get("terminal_certificate"),
           "terminal_claim": seq.info.get("terminal_claim"),
           "levels_x0": [seq.level(r["x0"]) for r in runs]}
    if isinstance(seq, QuasiSequence):
        out.update(method=f"quasi {seq.steps}-step robust controllable sets (Alg 6.7), "
                          "polytopic recursion (§6.3.4)",
                   quasi_steps=seq.steps, areas=list(seq.areas),
                   seconds=seq.info.get("total_seconds"),
                   seconds_per_set=list(seq.info.get("seconds", [])),
                   terminal_seconds=seq.info.get("terminal_seconds"),
                   W=np.asarray(seq.info.get("W")).tolist())
    else:
        out.update(method=seq.info.get("method", "general (Alg 4.6/6.1)"),
                   seconds=seq.info.get("seconds"))
        if _set_pipeline(ex) == "affine_state":
            out["areas"] = [float(S.volume()) for S in seq.sets]
    return out


def _quasi_figure(ex: Any, seq: Any, trajs: list, out: Path) -> str:
    """``sets.png`` of the quasi pipeline: the polytopes P_m coloured by index, T, X and
    the closed loops (thesis Fig 6.14-6.15)."""
    import matplotlib.pyplot as plt

    from .plot import plot_runs

    fig, ax = plt.subplots(figsize=(8.0, 7.4), layout="constrained")
    plot_runs(trajs, ax=ax, model=ex.model, show_X=False, legend=False)
    seq.plot(ax=ax, model=ex.model, boxes=True)
    M = len(seq) - 1
    done = (f"recursion stopped: P_{seq.converged_at} no larger than "
            f"P_{seq.converged_at - 1}" if seq.converged_at is not None
            else f"P_0..P_{M} ({seq.status})")
    ax.set_title(f"{ex.name} ({ex.info.get('example', '')}): quasi {seq.steps}-step robust "
                 f"controllable sets P_m and closed loops\neps = {seq.info.get('eps')}; "
                 f"{done}", fontsize="medium")
    path = out / "sets.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path.name


def _sequence_figure(ex: Any, seq: Any, trajs: list, out: Path) -> str:
    """``sets.png``: the sets K_i coloured by step, T, X and the closed loops."""
    import matplotlib.pyplot as plt

    from .plot import plot_runs

    fig, ax = plt.subplots(figsize=(8.0, 7.4), layout="constrained")
    # runs first (drawn above the sets by their zorder), then the sets and one legend
    plot_runs(trajs, ax=ax, model=ex.model, show_X=False, legend=False)
    seq.plot(ax=ax, model=ex.model)
    if seq.converged_at is None:
        done = f"{len(seq) - 1} steps ({seq.status})"
    elif seq.info.get("polytopic"):  # a volume test on polytopes: a stopping rule
        done = (f"recursion stopped: K_{seq.converged_at} no larger than "
                f"K_{seq.converged_at - 1}")
    else:
        done = (f"recursion stopped: K_{seq.converged_at} = K_{seq.converged_at - 1} "
                "(no new box at this eps)")
    ax.set_title(f"{ex.name} ({ex.info.get('example', '')}): controllable sets K_i and "
                 f"closed loops\neps = {seq.info.get('eps')}, "
                 f"{seq.info.get('semantics', '')}; {done}", fontsize="medium")
    path = out / "sets.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path.name


def _figures(ex: Any, trajs: list, run: dict, out: Path) -> list[str]:
    """``phase_plane.png`` (all runs) and ``run<i>.png`` (one run with its signals)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .plot import legend_outside, plot_runs, plot_trajectory, variable_labels

    model = ex.model
    sets = {"T (terminal set)": ex.terminal} if ex.terminal is not None else None
    obstacles, obstacle_label = None, "obstacle"
    if run.get("obstacles") is not None:
        obstacles = [(o[0], o[1], run["D"]) for o in np.asarray(run["obstacles"])]
        unit = variable_labels(model, "x")[1][0]
        obstacle_label = f"keep-out zone (radius D = {run['D']:g}{' ' + unit if unit else ''})"
    # the reference of a run without terminal set (e.g. the target pose of MiroSot)
    x_ref = ex.info.get("mpc", {}).get("x_ref")
    target = np.asarray(x_ref, dtype=float) if ex.terminal is None and x_ref is not None \
        else None
    written = []
    fig, ax = plt.subplots(figsize=(8.0, 5.6), layout="constrained")
    if model.n >= 2:
        plot_runs(trajs, ax=ax, sets=sets, obstacles=obstacles, obstacle_label=obstacle_label,
                  model=model, legend=False)
        if target is not None:
            ax.plot(target[0], target[1], "*", ms=16, color="gold", mec="k", zorder=5,
                    label="target x_ref")
        legend_outside(ax)
    else:
        for traj in trajs:
            plot_trajectory(traj, ax=ax, sets=sets)
    ax.set_title(f"{ex.name}: closed loop ({ex.info.get('example', '')})")
    path = out / "phase_plane.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    written.append(path.name)
    for i, traj in enumerate(trajs, start=1):
        levels = getattr(traj, "level", ())
        hs = {h for h in traj.horizon if h is not None}
        horizon = "auto" if any(v is not None for v in levels) else (
            "horizon" if len(hs) > 1 else None)
        fig = plot_trajectory(
            traj, sets=sets, obstacles=obstacles, obstacle_label=obstacle_label,
            states=ex.info.get("plot_states"), horizon=horizon,
            title=f"{ex.name}: run {i} from x0 = {np.round(traj.x[0], 4).tolist()}")
        if target is not None:
            pa = fig.axes[0]
            pa.plot(target[0], target[1], "*", ms=16, color="gold", mec="k", zorder=5,
                    label="target x_ref")
            legend_outside(pa, where="below", ncol=2)  # as plot_trajectory places it
        path = out / f"run{i}.png"
        fig.savefig(path, dpi=110, bbox_inches="tight")
        plt.close(fig)
        written.append(path.name)
    return written


def _executor(workers: int | None, scheduler: str | None) -> Any:
    """A context manager giving the executor of ``--workers`` / ``--scheduler`` (None for
    neither)."""
    import contextlib

    if scheduler:
        try:
            import distributed
        except ImportError:
            raise ValueError("--scheduler needs dask's distributed: pip install "
                             "'casadi_cmpc[dask]'") from None

        @contextlib.contextmanager
        def client() -> Any:
            try:
                c = distributed.Client(scheduler, timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise ValueError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") \
                    from None
            with c:
                print(f"set computations on the Dask cluster at {scheduler} "
                      f"({len(c.scheduler_info().get('workers', {}))} workers)")
                yield c.get_executor()

        return client()
    if workers:
        from concurrent.futures import ProcessPoolExecutor

        return ProcessPoolExecutor(workers)
    return contextlib.nullcontext()


def _run(name: str, out: str | None, steps: int | None, seed: int,
         progress: bool | None, controller: str = "auto", cache: str | None = None,
         checkpoint: str | None = None, workers: int | None = None,
         scheduler: str | None = None, eps: float | None = None) -> int:
    from . import models
    from .exceptions import CmpcWarning
    from .mpc.simulate import _summary_lines, simulate

    try:
        ex = models.load(name)
    except ValueError as exc:
        print(f"cmpc: {exc}", file=sys.stderr)
        return 2
    model = ex.model
    run = dict(ex.info.get("run", {}))
    if out:
        try:
            Path(out).mkdir(parents=True, exist_ok=True)
            probe = Path(out) / ".cmpc_write_test"
            probe.write_text("")
            probe.unlink()
        except OSError as exc:
            print(f"cmpc: cannot write to --out {out}: {exc}", file=sys.stderr)
            return 2
    print(model.summary())
    t_build = time.perf_counter()
    try:
        with _executor(workers, scheduler) as executor:
            ctrl, seq = _controller(ex, controller, cache, progress, checkpoint, executor,
                                    eps)
    except ValueError as exc:
        print(f"cmpc: {exc}", file=sys.stderr)
        return 2
    t_build = time.perf_counter() - t_build
    if seq is not None:
        run["note"] = ex.info[_set_pipeline(ex)].get("note", run.get("note", ""))
    print(f"\ncontroller: {ctrl!r}")
    guarantee = getattr(ctrl, "guarantee", None)
    if guarantee:
        print(f"  guarantee: {guarantee}")
    if run.get("note"):
        print(f"  {run['note']}")
    print(f"  certificates are about {model.discretisation}; closed loops run on "
          f"{_plant_text(model, run)}")
    n_steps = int(steps if steps is not None else run.get("steps", 50))
    x0s = np.asarray(run.get("x0s", ex.x0s), dtype=float).reshape(-1, model.n)
    disturbance = run.get("disturbance")
    trajs, runs = [], []
    x_ref = ctrl.x_ref
    for i, x0 in enumerate(x0s, start=1):
        ctrl.reset()
        print(f"\nrun {i}: x0 = {x0.tolist()}, {n_steps} steps"
              + (f", disturbance {disturbance}" if disturbance else ""))
        with warnings.catch_warnings():  # said below, in the run's own words
            warnings.filterwarnings("ignore", "the state lies in no set", CmpcWarning)
            traj = simulate(model, ctrl, x0, n_steps, disturbance=disturbance,
                            seed=seed + i - 1, progress=progress, plant=run.get("plant"))
        if traj.interrupted:  # Ctrl-C: the run ends (exit code 130), nothing is written
            raise KeyboardInterrupt
        trajs.append(traj)
        if traj.stop_reason == "not_controllable":
            print(f"  stopped at step {traj.steps}: x = {traj.x[-1].tolist()} lies in no set "
                  "of the sequence (not controllable as far as the sets at this eps prove; "
                  "a finer --eps proves more)")
        s = traj.summary()
        dist = float(np.abs(ctrl.contract @ (traj.x[-1] - x_ref)).max())
        certs = s.get("certificates", {})
        # a set-sequence controller reports levels, not horizons: each under its own name
        info = {"x0": x0, "final_state": traj.x[-1], "final_distance_to_reference": dist,
                "steps": traj.steps, "stop_reason": traj.stop_reason,
                "violations": {"state": int(traj.violations["state"]),
                               "input": int(traj.violations["input"])},
                "certificates": certs,
                "horizon_per_step": [h if lv is None else None
                                     for h, lv in zip(traj.horizon, traj.level, strict=True)],
                "horizons": s["horizons"], "levels": s["levels"],
                "step_kinds": s["step_kinds"], "modes": s["modes"],
                "solve_time": s["solve_time"],
                "call_time": s["call_time"], "disturbance": traj.disturbance}
        if s["levels"]:
            info["level_per_step"] = list(traj.level)
        dmin = _obstacle_distances(traj, run)
        if dmin is not None:
            info["min_obstacle_distance"] = float(dmin.min())
            info["obstacle_violations"] = int((dmin < run["D"]).sum())
        runs.append(info)
        print(f"  final state {np.round(traj.x[-1], 6).tolist()} "
              f"(|C (x - x_ref)|_inf = {dist:.3g})")
        print(f"  certificates: {certs}")
        print(f"  violations: state {info['violations']['state']}, input "
              f"{info['violations']['input']}"
              + (f", obstacle {info['obstacle_violations']} (min distance "
                 f"{info['min_obstacle_distance']:.3g}, D = {run['D']})" if dmin is not None
                 else ""))
        for line in _summary_lines(s):
            print(f"  {line}")
    total_viol = sum(r["violations"]["state"] + r["violations"]["input"]
                     + r.get("obstacle_violations", 0) for r in runs)
    summary = {"example": name, "thesis_example": ex.info.get("example"),
               "model_map": model.discretisation,
               "simulated_on": _plant_text(model, run),
               "controller": repr(ctrl), "guarantee": guarantee,
               "robust": bool(getattr(ctrl, "robust", False)) and model.l > 0,
               "note": run.get("note", ""),
               "controller_build_time": t_build, "steps": n_steps, "seed": seed,
               "runs": runs, "total_violations": total_viol}
    if seq is not None:
        summary["sequence"] = _sequence_summary(ex, seq, runs)
    if out:
        d = Path(out)
        d.mkdir(parents=True, exist_ok=True)
        figs = _figures(ex, trajs, run, d)
        if seq is not None and ex.model.n >= 2:
            figs.append(_quasi_figure(ex, seq, trajs, d) if _set_pipeline(ex) == "quasi"
                        else _sequence_figure(ex, seq, trajs, d))
        summary["figures"] = figs
        (d / "summary.json").write_text(json.dumps(_jsonable(summary), indent=2))
        (d / "report.txt").write_text(_report(ex, ctrl, summary))
        print(f"\nwritten to {d}: {', '.join(figs + ['summary.json', 'report.txt'])}")
    if total_viol:
        print(f"cmpc: {total_viol} constraint violations in the closed loop", file=sys.stderr)
        return 1
    return 0


def _plant_text(model: Any, run: dict) -> str:
    """What the closed loops were simulated on: the example's plant (e.g. the ODE
    integrated accurately) or the model's own map."""
    plant = run.get("plant")
    if plant is None:
        if getattr(model, "is_validated", False):
            # simulate() evaluates model.function: the Taylor polynomial, not the flow
            return ("the model's Taylor polynomial without its remainder (a point map "
                    "inside the certified enclosure, not the ODE itself; pass a plant to "
                    "cm.simulate to run on the ODE)")
        return f"the model's own map ({model.discretisation})"
    doc = (getattr(plant, "__doc__", None) or "").strip().splitlines()
    return f"the plant {getattr(plant, '__name__', 'given')}()" + (
        f" ({doc[0].rstrip('.')})" if doc else "")


def _report(ex: Any, ctrl: Any, summary: dict) -> str:
    """The text of ``report.txt``: the runs, and what their certificates prove, stated
    from the controller itself (robust or nominal, its disturbance set, its sequence)."""
    from .mpc.simulate import _summary_lines

    model = ex.model
    lines = [f"cmpc run {ex.name} ({ex.info.get('example', '')}, thesis §"
             f"{ex.info.get('section', '')})", "", model.summary(), "",
             f"controller: {summary['controller']}"]
    guarantee = getattr(ctrl, "guarantee", None)
    if guarantee:
        lines.append(f"  guarantee: {guarantee}")
    if summary["note"]:
        lines.append(f"  {summary['note']}")
    labels: list[str] = []
    for i, r in enumerate(summary["runs"], start=1):
        lines += ["", f"run {i}: x0 = {np.asarray(r['x0']).tolist()}, {r['steps']} steps "
                      f"({r['stop_reason']}), disturbance {r['disturbance']}",
                  f"  final state {np.round(np.asarray(r['final_state']), 6).tolist()}, "
                  f"|C (x - x_ref)|_inf = {r['final_distance_to_reference']:.3g} (C: the "
                  "contracted components)",
                  f"  certificates per step: {r['certificates']}",
                  f"  violations counted by the simulator: {r['violations']}"]
        labels += [c for c in r["certificates"] if c not in labels]
        if "min_obstacle_distance" in r:
            lines.append(f"  smallest obstacle distance {r['min_obstacle_distance']:.4g} "
                         f"(required >= {ex.info['run']['D']})")
        lines += [f"  {line}" for line in _summary_lines(r)]

    # ------------------------------------------- what the certificates prove
    seq = getattr(ctrl, "seq", None)
    sinfo = summary.get("sequence") or {}
    robust = bool(getattr(ctrl, "robust", False)) and model.l > 0
    if not model.l:
        w_claim, w_line = "", "the model has no disturbance."
    elif robust:
        W = f"[{model.W.lo.tolist()}, {model.W.hi.tolist()}]"
        w_claim = f", for all w in W = {W}"
        w_line = f"robust controller: its certificates hold for all w in W = {W}."
    else:
        w_nom = getattr(ctrl, "w_nominal", None)
        w_nom = np.asarray(model.W.mid if w_nom is None else w_nom, dtype=float).tolist()
        w_claim = f", for the nominal w = {w_nom} only"
        w_line = (f"nominal controller: its certificates hold for the nominal disturbance "
                  f"w = {w_nom} only; the other w of W = [{model.W.lo.tolist()}, "
                  f"{model.W.hi.tolist()}] are not covered.")
    notes = ["What the certificates prove:",
             f"  model: they are about {model.discretisation} of '{model.name}'; the closed "
             f"loops above ran on {summary.get('simulated_on', 'the model map')}.",
             f"  disturbance: {w_line}"]
    quasi = sinfo.get("pipeline") == "quasi"
    if quasi:
        notes.append(f"  terminal set T = P_0: {sinfo.get('terminal_certificate')} robustly "
                     f"invariant under the local law ({sinfo.get('terminal_claim')}), and "
                     "proven inside X by rigorous support bounds.")
        notes.append(f"  sets P_m (m >= 1): {sinfo.get('semantics')}; each P_m is a polytope "
                     "proven inside the inner boxes of the quasi set computed towards "
                     "P_(m-1) (model "
                     f"'{model.name}', eps = {sinfo.get('eps')}).")
    elif sinfo.get("pipeline") == "affine_state":
        notes.append(f"  sets K_i of the sequence ({sinfo.get('method')}, model "
                     f"'{model.name}', eps = {sinfo.get('eps')}): every state of K_i outside "
                     f"K_(i-1) lies in a polytope piece whose stored control is proven to "
                     f"bring it into K_(i-1) in one step ({sinfo.get('semantics')}); K_0 = T "
                     f"is {sinfo.get('terminal_certificate')} invariant under the local law "
                     "and proven inside X.")
    elif sinfo:
        notes.append(f"  sets K_i of the sequence: every state of K_i is proven to reach "
                     f"K_(i-1) in one step ({sinfo.get('semantics')}); K_0 = T is "
                     f"{sinfo.get('terminal_certificate')} invariant under the local law.")
    for label in labels:
        if quasi and label == "verified":
            text = ("outside T, the applied control starts a control sequence proven from the "
                    "exact state x(k), by zonotope evolution with outward rounding, to keep "
                    f"the state in X and bring it into P_(j-1) within {sinfo.get('quasi_steps')}"
                    " steps (one level down); inside T, the applied control is proven to map "
                    "x(k) into T" + w_claim)
        elif quasi and label == "local_law":
            text = ("x(k) was in T = P_0 and the local law was applied: its step from x(k) was "
                    "proven into T by zonotope evolution when the certificate says proved; T "
                    "is proven robustly invariant under the law either way")
        elif label == "verified" and seq is not None:
            text = ("the applied control was re-evaluated in interval arithmetic from the "
                    f"exact state x(k): f(x(k), u(k){', w' if model.l else ''}) lies in "
                    "K_(i-1), one level down" + w_claim)
        elif label == "verified":
            text = ("the applied sequence was re-evaluated in interval arithmetic from the "
                    "exact state and satisfies X, U, the contraction and the extra "
                    "constraints" + w_claim)
        elif label == "local_law" and seq is not None:
            claim = seq.info.get("terminal_claim") if hasattr(seq, "info") else None
            text = ("x(k) was in T = K_0 and the local law was applied; "
                    + (f"T is proven invariant under it: {claim}"
                       if sinfo.get("terminal_certificate") == "proved" and claim
                       else "the invariance of T under it is not proven"))
        elif label == "local_law":
            text = ("x(k) was proven inside the local set and the local law was applied; "
                    "nothing more is claimed for the step")
        elif label == "at_reference":
            text = "x(k) was the reference and u_ref was applied; nothing more is claimed"
        else:
            text = "nothing is claimed for these steps"
        notes.append(f"  '{label}': {text}.")
    lines += ["", *notes, ""]
    return "\n".join(lines)


def export_controller(ex: Any, controller: str = "auto", cache: Any = None,
                      progress: bool | None = None, eps: float | None = None) -> Any:
    """The controller ``cmpc export`` writes for an example (solver ``"sqp"``): the
    example's SetSequenceMPC (sets from the cache), its QuasiMultiStepMPC
    (``khalil_affine_control``: T proven, the quasi sets computed) or its ContractiveMPC at
    a fixed horizon (``horizon_max`` when the example searches the horizon) in receding
    mode (also for ``khalil_affine_state``, whose affine-state sets have no C form);
    ``eps`` replaces the resolution of the example's sets. Raises ValueError for the LP
    form, which has no C export."""
    from .mpc.contractive import ContractiveMPC

    pipeline = _set_pipeline(ex)
    if controller == "sequence" and pipeline is None:
        raise ValueError(f"example '{ex.name}' has no controllable-set configuration; use "
                         "--controller contractive")
    if controller in ("auto", "sequence") and pipeline == "quasi":
        return _quasi_controller(ex, progress, eps, solver="sqp")[0]
    if controller == "sequence" and pipeline == "affine_state":
        raise ValueError(f"the affine-state controllable sets of '{ex.name}' are polytope "
                         "pieces, which the C export of the one-step MPC does not read (it "
                         "reads proving boxes); use --controller contractive")
    if controller == "auto" and pipeline == "affine_state":
        print(f"{ex.name}: the C export has no form for its affine-state sets (polytope "
              "pieces); exporting its contractive MPC")
    if controller in ("auto", "sequence") and pipeline == "sequence":
        return _sequence_controller(ex, cache, progress, solver="sqp", eps=eps)[0]
    if eps is not None:
        raise ValueError("--eps sets the resolution of the controllable sets; the "
                         "contractive MPC has none")
    kw = dict(ex.info["mpc"])
    if kw.get("solver") == "lp":
        raise ValueError(f"example '{ex.name}' uses the LP form of the contractive MPC "
                         "(solver='lp'), which has no C export; the sqp and ipopt forms "
                         "have one")
    kw["solver"] = "sqp"
    kw["mode"] = "receding"  # the C controller solves at every step
    if kw.get("horizon") is None:
        kw["horizon"] = kw.get("horizon_max", 10)
    return ContractiveMPC(ex.model, **kw)


def _export(args: Any) -> int:
    """``cmpc export``: the example's controller (solver sqp) written as C; with
    ``--build`` the tools are checked before anything is computed."""
    from . import models
    from .codegen import export_c
    from .codegen.export import ExportError, build, check_build_tools

    if args.eps is not None and not (np.isfinite(args.eps) and args.eps > 0):
        print("cmpc export: --eps must be a positive number", file=sys.stderr)
        return 2
    compiler = None
    if args.build:
        try:
            compiler = check_build_tools()
        except ExportError as exc:
            print(f"cmpc export: cannot --build: {exc}. Nothing was computed; without "
                  "--build the C sources are written all the same", file=sys.stderr)
            return 2
    try:
        ex = models.load(args.example)
    except (KeyError, ValueError) as exc:
        print(f"cmpc export: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    bad = _unwritable_file(out / "x") if not out.is_dir() else None
    if out.exists() and not out.is_dir():
        bad = "is a file; --out names a directory for the C sources"
    if bad:
        print(f"cmpc export: --out {out}: {bad}", file=sys.stderr)
        return 2
    if out.is_dir() and any(out.iterdir()) and not args.overwrite:
        print(f"cmpc export: {out} exists and is not an empty directory (use --overwrite)",
              file=sys.stderr)
        return 2
    try:
        ctrl = export_controller(ex, args.controller, args.cache,
                                 False if args.no_progress else None, args.eps)
    except ValueError as exc:
        print(f"cmpc export: {exc}", file=sys.stderr)
        return 2
    x0s = np.asarray(ex.info.get("run", {}).get("x0s", ex.x0s), dtype=float)
    x0 = x0s.reshape(-1, ex.model.n)[0] if x0s.size else None
    try:
        info = export_c(ctrl, out, solver=args.solver, overwrite=args.overwrite, x0=x0)
    except (ExportError, ValueError, TypeError) as exc:
        print(f"cmpc export: {exc}", file=sys.stderr)
        return 2
    print(f"exported {ex.name} ({info.kind}, solver {info.solver}) to {out}: "
          f"{', '.join(info.files)}")
    if info.tables:
        print("tables: " + ", ".join(f"{k} {v}" for k, v in info.tables.items()))
    if args.build:
        try:
            build(out, cc=compiler)
        except ExportError as exc:
            print(f"cmpc export: {exc}", file=sys.stderr)
            return 1
        res = subprocess.run([str(out / "example")], capture_output=True, text=True)
        print(res.stdout, end="")
        if res.returncode != 0:
            print(f"cmpc export: the example program exited with {res.returncode}",
                  file=sys.stderr)
            return 1
    else:
        print(f"build with: make -C {out} && {out / 'example'}  (needs make and a C "
              "compiler: $(CC), by default cc)")
    return 0


def _example_line(name: str) -> str:
    """One line of ``cmpc list``: name, thesis example, dimensions, what the system is."""
    from . import models

    ex = models.load(name)
    info = ex.info
    n, m, nw = ex.model.n, ex.model.m, ex.model.l
    dims = f"{n} state{'s' * (n != 1)}, {m} input{'s' * (m != 1)}"
    if nw:
        dims += f", {nw} disturbance{'s' * (nw != 1)}"
    desc = info.get("description") or _module_summary(name) or (
        f"thesis {info['equation']}" if info.get("equation") else "")
    section = str(info.get("section", "") or "")
    if section:
        desc += " (" + ", ".join("§" + p.strip().lstrip("§")
                                 for p in section.split(",") if p.strip()) + ")"
    pipeline = _set_pipeline(ex)
    if pipeline == "sequence":
        desc += "; controllable sets"
    elif pipeline == "quasi":
        desc += f"; quasi {info['quasi'].get('steps', 2)}-step controllable sets"
    elif pipeline == "affine_state":
        desc += "; affine-state controllable sets"
    return f"{name:22s} {str(info.get('example', '')):8s} {dims:34s} {desc}".rstrip()


def _module_summary(name: str) -> str:
    """What an example is, from the first line of its module's docstring without the
    example number and the thesis reference ("E8 — Cannon et al. (2003) system with dt =
    0.1, mu = 0.9 (thesis §4.4.4, (4.28))." gives "Cannon et al. (2003) system with dt =
    0.1, mu = 0.9"); "" when there is none."""
    import importlib

    from . import models

    try:
        doc = importlib.import_module(f"{models.__name__}.{name}").__doc__ or ""
    except ImportError:
        return ""
    line = doc.strip().splitlines()[0].strip() if doc.strip() else ""
    if " — " in line:
        line = line.split(" — ", 1)[1]
    if " (thesis" in line:
        line = line[:line.index(" (thesis")]
    return line.rstrip(" .")


def _cache_command(cache: str | None, clear: bool) -> int:
    """``cmpc cache``: the cache directory and its files with their sizes;
    ``--clear`` deletes the files ``cmpc run`` wrote there (nothing else)."""
    import re

    d = _cache_dir(cache)
    print(f"cache directory: {d}")
    if not d.is_dir():
        print("  (does not exist: nothing cached)")
        return 0
    ours = re.compile(f"(?:{_CACHE_FILE})|(?:{_PARTIAL_FILE})")
    files = sorted(f for f in d.iterdir() if f.is_file() and ours.fullmatch(f.name))
    others = sorted(f.name for f in d.iterdir() if f not in files)
    total = 0
    for f in files:
        size = f.stat().st_size
        total += size
        print(f"  {f.name:44s} {_size(size):>10s}")
        if clear:
            f.unlink()
    what = f"{len(files)} cached sequence file{'s' * (len(files) != 1)}, {_size(total)}"
    print(f"removed {what}" if clear else what)
    from .interval._native import kernel_dir

    kd = kernel_dir()
    if kd.parent == d:  # the compiled interval kernels (the native backend) live here too
        others = [o for o in others if o != kd.name]
        kernels = sorted(kd.glob("k*.so")) if kd.is_dir() else []
        size = sum(k.stat().st_size for k in kernels)
        if clear:
            for k in kernels:
                k.unlink()
        print(f"{'removed ' if clear else ''}{len(kernels)} compiled interval kernel"
              f"{'s' * (len(kernels) != 1)} in {kd}, {_size(size)}")
    if others:
        print(f"  not written by cmpc (left alone): {', '.join(others)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``cmpc`` console script."""
    parser = argparse.ArgumentParser(prog="cmpc", description=__doc__.split("\n\n")[1])
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser("run", help="simulate the closed loop of a thesis example")
    p_run.add_argument("example", nargs="?", default=DEFAULT_EXAMPLE,
                       help=f"example name (default: {DEFAULT_EXAMPLE}); see 'cmpc list'")
    p_run.add_argument("--out", default=None,
                       help="directory for the figures, summary.json and report.txt")
    p_run.add_argument("--steps", type=int, default=None,
                       help="closed-loop steps per initial state (default: the example's)")
    p_run.add_argument("--seed", type=int, default=0, help="seed of the disturbances")
    p_run.add_argument("--no-progress", action="store_true", help="no progress bar")
    p_run.add_argument("--controller", choices=("auto", "sequence", "contractive"),
                       default="auto",
                       help="'sequence': the MPC along the example's controllable sets "
                            "(default for the examples that have them; the quasi i-step MPC "
                            "for khalil_affine_control), 'contractive': contractive MPC")
    p_run.add_argument("--eps", type=float, default=None,
                       help="resolution of the controllable sets (default: the example's; a "
                            "larger eps is faster and gives smaller sets)")
    p_run.add_argument("--cache", default=None,
                       help="directory of cached set sequences (default: "
                            "$XDG_CACHE_HOME/casadi_cmpc or ~/.cache/casadi_cmpc)")
    p_run.add_argument("--checkpoint", default=None, metavar="PATH",
                       help="file (.npz) that makes computing the sets resumable: written "
                            "after each completed step; an interrupted or killed run given "
                            "the same PATH again resumes there (the cache, when it holds "
                            "the sets, still answers first)")
    par = p_run.add_mutually_exclusive_group()
    par.add_argument("--workers", type=int, default=None, metavar="N",
                     help="compute the sets with N worker processes on this machine (the "
                          "sets are those of a serial run; small levels stay in this "
                          "process)")
    par.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="compute the sets on a Dask cluster, e.g. tcp://host:8786 "
                          "(workers with casadi_cmpc installed; pip install "
                          "'casadi_cmpc[dask]')")
    p_exp = sub.add_parser("export", help="export the controller of an example to C")
    p_exp.add_argument("example", help="example name; see 'cmpc list'")
    p_exp.add_argument("--out", required=True, help="directory of the C sources (created)")
    p_exp.add_argument("--solver", choices=("sqp", "ipopt"), default="sqp",
                       help="'sqp' (default): standalone C; 'ipopt': links casadi's IPOPT")
    p_exp.add_argument("--controller", choices=("auto", "sequence", "contractive"),
                       default="auto",
                       help="as for 'cmpc run', except that khalil_affine_state exports its "
                            "contractive MPC (its affine-state sets, polytope pieces, have no "
                            "C form; 'sequence' is refused there)")
    p_exp.add_argument("--overwrite", action="store_true",
                       help="replace the contents of a non-empty --out directory")
    p_exp.add_argument("--build", action="store_true",
                       help="run make afterwards and the example program (needs make and a "
                            "C compiler, $CC or cc; checked before anything is computed)")
    p_exp.add_argument("--cache", default=None, help="as for 'cmpc run'")
    p_exp.add_argument("--eps", type=float, default=None, help="as for 'cmpc run'")
    p_exp.add_argument("--no-progress", action="store_true", help="no progress bar")
    sub.add_parser("list", help="list the examples: name, thesis example, dimensions, what "
                                "the system is")
    p_cache = sub.add_parser("cache", help="show the cache of set sequences (directory, "
                                           "files, sizes)")
    p_cache.add_argument("--cache", default=None, help="as for 'cmpc run'")
    p_cache.add_argument("--clear", action="store_true",
                         help="delete the cached sequences")
    args = parser.parse_args(argv)
    try:
        return _command(parser, args)
    except KeyboardInterrupt:
        print("cmpc: interrupted (nothing partial was cached)", file=sys.stderr)
        return 130


def _unwritable_file(path: Path) -> str | None:
    """Why a file cannot be written at ``path`` (a directory there, or a path component
    that is a file), or None."""
    if path.is_dir():
        return "is a directory; give a file name (e.g. run.npz)"
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                return f"{parent} is a file, not a directory"
            break
    return None


def _command(parser: Any, args: Any) -> int:
    """Run the parsed command."""
    if args.command == "export":
        return _export(args)
    if args.command == "cache":
        return _cache_command(args.cache, args.clear)
    if args.command == "list":
        from . import models

        for n in models.names(validated=True):  # the validated variants last
            print(_example_line(n))
        return 0
    if args.steps is not None and args.steps < 1:
        parser.error("--steps must be at least 1")
    if args.workers is not None and args.workers < 1:
        parser.error("--workers must be at least 1")
    if args.eps is not None and not (np.isfinite(args.eps) and args.eps > 0):
        parser.error("--eps must be a positive number")
    if args.seed < 0:
        parser.error("--seed must be a non-negative integer")
    if args.checkpoint is not None:
        bad = _unwritable_file(Path(args.checkpoint))
        if bad:
            parser.error(f"--checkpoint {args.checkpoint}: {bad}")
    return _run(args.example, args.out, args.steps, args.seed,
                False if args.no_progress else None, args.controller, args.cache,
                args.checkpoint, args.workers, args.scheduler, args.eps)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
