"""The ``cmpc`` command line.

``cmpc run [EXAMPLE] [--out DIR]`` is the main job: it loads a thesis example (default
``cannon_robust``) and builds the controller the library has for it. For the examples with
controllable sets (``example.info["sequence"]``: E8, E9, E10, E14) that is the full pipeline:
certify the terminal set, compute (or load from the cache) the sequence of (robust)
controllable sets, and run the dual-mode one-step MPC along it, every control certified. For
the others (or with ``--controller contractive``) it is the contractive MPC of thesis §4.3
configured in ``example.info["mpc"]``. It simulates the closed loop from the thesis' initial
states, checks the constraints itself, and prints a summary. With ``--out DIR`` it writes the
figures (PNG), ``summary.json`` and ``report.txt``.

``cmpc list`` prints the example names.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
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


# bumped when what a cached sequence holds changes (2: the proven law of T is stored)
_SEQUENCE_FORMAT = "sequence-format-2"


def _cache_path(ex: Any, cfg: dict, cache: str | None) -> Path:
    """A file name that changes with the model, T, the law and the settings."""
    import hashlib
    import os

    from . import __version__

    h = hashlib.sha256()
    for part in (ex.model.function.serialize(), np.asarray(ex.terminal.A).tobytes(),
                 np.asarray(ex.terminal.b).tobytes(), np.asarray(ex.local_law).tobytes(),
                 repr(sorted((k, v) for k, v in cfg.items() if k in ("eps", "robust"))),
                 __version__, _SEQUENCE_FORMAT):
        h.update(part if isinstance(part, bytes) else str(part).encode())
    base = Path(cache) if cache else Path(os.environ.get(
        "XDG_CACHE_HOME", Path.home() / ".cache")) / "casadi_cmpc"
    return base / f"{ex.name}-{h.hexdigest()[:16]}.npz"


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
    return None


def _sequence_controller(ex: Any, cache: str | None, progress: bool | None) -> Any:
    from .control.controllable import controllable_sets
    from .control.linear_sets import SetSequence
    from .mpc.sequence import SetSequenceMPC

    cfg = ex.info["sequence"]
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
                print(f"sequence loaded from the cache {path}")
        except (ValueError, TypeError, KeyError, OSError) as exc:
            print(f"cache {path} unreadable ({exc}); computing the sequence again")
            seq = None
    if seq is None:
        t0 = time.perf_counter()
        seq = controllable_sets(ex.model, ex.terminal, cfg["eps"], robust=cfg["robust"],
                                law=ex.local_law, progress=progress)
        if seq.status == "interrupted":  # a partial sequence is neither used nor cached
            raise KeyboardInterrupt
        print(f"sequence computed in {time.perf_counter() - t0:.1f} s ({seq.status})")
        if seq.status in _COMPLETE:
            try:
                seq.save(path)
                print(f"  cached in {path}")
            except OSError as exc:
                print(f"  not cached ({exc})")
        else:
            print(f"  not cached: the computation stopped early ({seq.status})")
    print(f"terminal set: {seq.info.get('terminal_certificate')} invariant under the local "
          f"law; sequence: {seq!r}, {len(seq) - 1} steps, eps = {seq.info.get('eps')}, "
          f"{seq.info.get('semantics')}")
    ctrl = SetSequenceMPC(ex.model, seq, Q=cfg.get("Q"), R=cfg.get("R"),
                          local_law=ex.local_law, solver=cfg.get("solver", "ipopt"),
                          robust=cfg["robust"])
    return ctrl, seq


def _controller(ex: Any, kind: str = "auto", cache: str | None = None,
                progress: bool | None = None) -> tuple[Any, Any]:
    """The controller of an example and its set sequence (None for the contractive MPC)."""
    from .mpc.contractive import ContractiveMPC

    if kind == "sequence" and "sequence" not in ex.info:
        raise ValueError(f"example '{ex.name}' has no controllable-set configuration; use "
                         "--controller contractive")
    if kind in ("auto", "sequence") and "sequence" in ex.info:
        return _sequence_controller(ex, cache, progress)
    return ContractiveMPC(ex.model, **ex.info["mpc"]), None


def _sequence_figure(ex: Any, seq: Any, trajs: list, out: Path) -> str:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 5.6))
    seq.plot(ax=ax)
    for i, traj in enumerate(trajs, start=1):
        ax.plot(traj.x[:, 0], traj.x[:, 1], "o-", color="r" if i == 1 else f"C{i}", ms=3,
                lw=1.2, label=f"closed loop from {np.round(traj.x[0], 3).tolist()}")
    names = ex.info.get("state_names")
    if names:
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
    ax.legend(fontsize=8, loc="best")
    ax.set_title(f"{ex.name}: controllable sets K_i and closed loops "
                 f"({ex.info.get('example', '')})")
    path = out / "sets.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path.name


def _figures(ex: Any, trajs: list, run: dict, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .plot import plot_trajectory

    names = ex.info.get("state_names") or ex.info.get("state_layout")
    sets: dict[str, Any] = {}
    if ex.terminal is not None:
        sets["terminal set"] = ex.terminal
    obstacles = None
    if run.get("obstacles") is not None:
        obstacles = [(o[0], o[1], run["D"]) for o in np.asarray(run["obstacles"])]
    written = []
    fig, ax = plt.subplots(figsize=(6.4, 5.2))
    for i, traj in enumerate(trajs, start=1):
        before = set(ax.lines)
        plot_trajectory(traj, ax=ax, sets=sets or None, obstacles=obstacles,
                        state_names=names)
        sets, obstacles = {}, None  # draw them once
        for line in set(ax.lines) - before:
            if line.get_label() == "trajectory":
                line.set_label(f"run {i}" if len(trajs) > 1 else "trajectory")
                line.set_color(f"C{i - 1}")
    handles, labels = ax.get_legend_handles_labels()
    keep = {lab: h for h, lab in zip(handles, labels, strict=True)}
    ax.legend(list(keep.values()), list(keep.keys()), fontsize=8, loc="best")
    ax.set_title(f"{ex.name}: closed loop ({ex.info.get('example', '')})")
    path = out / "phase_plane.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    written.append(path.name)
    for i, traj in enumerate(trajs, start=1):
        fig = plot_trajectory(
            traj, sets={"terminal set": ex.terminal} if ex.terminal is not None else None,
            obstacles=[(o[0], o[1], run["D"]) for o in np.asarray(run["obstacles"])]
            if run.get("obstacles") is not None else None,
            state_names=names,
            title=f"{ex.name}: run {i} from x0 = {np.round(traj.x[0], 4).tolist()}")
        for a in fig.axes:
            handles, labels = a.get_legend_handles_labels()
            if a.get_legend() is not None and len(set(labels)) < len(labels):
                keep = {lab: h for h, lab in zip(handles, labels, strict=True)}
                a.legend(list(keep.values()), list(keep.keys()), fontsize=8)
        path = out / f"run{i}.png"
        fig.savefig(path, dpi=110, bbox_inches="tight")
        plt.close(fig)
        written.append(path.name)
    return written


def _run(name: str, out: str | None, steps: int | None, seed: int,
         progress: bool | None, controller: str = "auto", cache: str | None = None) -> int:
    from . import models
    from .mpc.simulate import simulate

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
        ctrl, seq = _controller(ex, controller, cache, progress)
    except ValueError as exc:
        print(f"cmpc: {exc}", file=sys.stderr)
        return 2
    t_build = time.perf_counter() - t_build
    if seq is not None:
        run["note"] = ex.info["sequence"].get("note", run.get("note", ""))
    print(f"\ncontroller: {ctrl!r}")
    if run.get("note"):
        print(f"  {run['note']}")
    n_steps = int(steps if steps is not None else run.get("steps", 50))
    x0s = np.asarray(run.get("x0s", ex.x0s), dtype=float).reshape(-1, model.n)
    disturbance = run.get("disturbance")
    trajs, runs = [], []
    x_ref = ctrl.x_ref
    for i, x0 in enumerate(x0s, start=1):
        ctrl.reset()
        print(f"\nrun {i}: x0 = {x0.tolist()}, {n_steps} steps"
              + (f", disturbance {disturbance}" if disturbance else ""))
        traj = simulate(model, ctrl, x0, n_steps, disturbance=disturbance, seed=seed + i - 1,
                        progress=progress)
        trajs.append(traj)
        s = traj.summary()
        dist = float(np.abs(ctrl.contract @ (traj.x[-1] - x_ref)).max())
        certs = s.get("certificates", {})
        info = {"x0": x0, "final_state": traj.x[-1], "final_distance_to_reference": dist,
                "steps": traj.steps, "stop_reason": traj.stop_reason,
                "violations": {"state": int(traj.violations["state"]),
                               "input": int(traj.violations["input"])},
                "certificates": certs, "horizon_per_step": list(traj.horizon),
                "solve_time": s.get("solve_time"), "disturbance": traj.disturbance}
        dmin = _obstacle_distances(traj, run)
        if dmin is not None:
            info["min_obstacle_distance"] = float(dmin.min())
            info["obstacle_violations"] = int((dmin < run["D"]).sum())
        runs.append(info)
        st = s.get("solve_time") or {}
        med = st.get("median")
        print(f"  final state {np.round(traj.x[-1], 6).tolist()} "
              f"(|C (x - x_ref)|_inf = {dist:.3g})")
        print(f"  certificates: {certs}")
        print(f"  violations: state {info['violations']['state']}, input "
              f"{info['violations']['input']}"
              + (f", obstacle {info['obstacle_violations']} (min distance "
                 f"{info['min_obstacle_distance']:.3g}, D = {run['D']})" if dmin is not None
                 else ""))
        if med is not None:
            print(f"  solve time per step: median {med * 1e3:.3g} ms, max "
                  f"{st.get('max', 0) * 1e3:.3g} ms")
    total_viol = sum(r["violations"]["state"] + r["violations"]["input"]
                     + r.get("obstacle_violations", 0) for r in runs)
    summary = {"example": name, "thesis_example": ex.info.get("example"),
               "controller": repr(ctrl), "note": run.get("note", ""),
               "controller_build_time": t_build, "steps": n_steps, "seed": seed,
               "runs": runs, "total_violations": total_viol}
    if seq is not None:
        summary["sequence"] = {"steps": len(seq) - 1, "converged_at": seq.converged_at,
                               "status": seq.status, "eps": seq.info.get("eps"),
                               "semantics": seq.info.get("semantics"),
                               "terminal_certificate": seq.info.get("terminal_certificate"),
                               "seconds": seq.info.get("seconds"),
                               "levels_x0": [seq.level(r["x0"]) for r in runs]}
    if out:
        d = Path(out)
        d.mkdir(parents=True, exist_ok=True)
        figs = _figures(ex, trajs, run, d)
        if seq is not None and ex.model.n >= 2:
            figs.append(_sequence_figure(ex, seq, trajs, d))
        summary["figures"] = figs
        (d / "summary.json").write_text(json.dumps(_jsonable(summary), indent=2))
        (d / "report.txt").write_text(_report(ex, ctrl, summary))
        print(f"\nwritten to {d}: {', '.join(figs + ['summary.json', 'report.txt'])}")
    if total_viol:
        print(f"cmpc: {total_viol} constraint violations in the closed loop", file=sys.stderr)
        return 1
    return 0


def _report(ex: Any, ctrl: Any, summary: dict) -> str:
    lines = [f"cmpc run {ex.name} ({ex.info.get('example', '')}, thesis §"
             f"{ex.info.get('section', '')})", "", ex.model.summary(), "",
             f"controller: {summary['controller']}"]
    if summary["note"]:
        lines.append(f"  {summary['note']}")
    for i, r in enumerate(summary["runs"], start=1):
        lines += ["", f"run {i}: x0 = {np.asarray(r['x0']).tolist()}, {r['steps']} steps "
                      f"({r['stop_reason']}), disturbance {r['disturbance']}",
                  f"  final state {np.round(np.asarray(r['final_state']), 6).tolist()}, "
                  f"|C (x - x_ref)|_inf = {r['final_distance_to_reference']:.3g} (C: the "
                  "contracted components)",
                  f"  certificates per step: {r['certificates']}",
                  f"  violations counted by the simulator: {r['violations']}"]
        if "min_obstacle_distance" in r:
            lines.append(f"  smallest obstacle distance {r['min_obstacle_distance']:.4g} "
                         f"(required >= {ex.info['run']['D']})")
        hs = [h for h in r["horizon_per_step"] if h is not None]
        if hs:
            vals, cnt = np.unique(hs, return_counts=True)
            lines.append("  horizons used: " + ", ".join(
                f"N = {v}: {c} steps" for v, c in zip(vals, cnt, strict=True)))
        st = r.get("solve_time") or {}
        if st.get("median") is not None:
            lines.append(f"  solve time: median {st['median'] * 1e3:.3g} ms, max "
                         f"{st['max'] * 1e3:.3g} ms")
    lines += ["", "'verified': the applied sequence was re-evaluated in interval arithmetic "
              "from the exact state and satisfies X, U, the contraction and the extra "
              "constraints (for the nominal disturbance when the model has one); "
              "'local_law': the state was inside the local set and the local law was applied; "
              "other labels claim nothing.", ""]
    return "\n".join(lines)


def export_controller(ex: Any, controller: str = "auto", cache: Any = None,
                      progress: bool | None = None) -> Any:
    """The controller ``cmpc export`` writes for an example (solver ``"sqp"``): the
    example's SetSequenceMPC (sets from the cache) or its ContractiveMPC at a fixed horizon
    (``horizon_max`` when the example searches the horizon). Raises ValueError for the LP
    form, which has no C export."""
    from .mpc.contractive import ContractiveMPC
    from .mpc.sequence import SetSequenceMPC

    ctrl, seq = _controller(ex, controller, cache, progress)
    if isinstance(ctrl, SetSequenceMPC):
        cfg = ex.info["sequence"]
        return SetSequenceMPC(ex.model, seq, Q=cfg.get("Q"), R=cfg.get("R"),
                              local_law=ex.local_law, solver="sqp", robust=cfg["robust"])
    kw = dict(ex.info["mpc"])
    if kw.get("solver") == "lp":
        raise ValueError(f"example '{ex.name}' uses the LP form of the contractive MPC "
                         "(solver='lp'), which has no C export; the sqp and ipopt forms "
                         "have one")
    kw["solver"] = "sqp"
    if kw.get("horizon") is None:
        kw["horizon"] = kw.get("horizon_max", 10)
    return ContractiveMPC(ex.model, **kw)


def _export(args: Any) -> int:
    """``cmpc export``: the example's controller (solver sqp) written as C."""
    from . import models
    from .codegen import build, export_c
    from .codegen.export import ExportError

    try:
        ex = models.load(args.example)
    except (KeyError, ValueError) as exc:
        print(f"cmpc export: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    if out.exists() and (not out.is_dir() or (any(out.iterdir()) and not args.overwrite)):
        print(f"cmpc export: {out} exists and is not an empty directory (use --overwrite)",
              file=sys.stderr)
        return 2
    try:
        ctrl = export_controller(ex, args.controller, args.cache,
                                 False if args.no_progress else None)
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
            build(out)
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
        print(f"build with: make -C {out} && {out / 'example'}")
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
                       help="'sequence': one-step MPC along controllable sets (default for "
                            "the examples that have them), 'contractive': contractive MPC")
    p_run.add_argument("--cache", default=None,
                       help="directory of cached set sequences (default: "
                            "$XDG_CACHE_HOME/casadi_cmpc or ~/.cache/casadi_cmpc)")
    p_exp = sub.add_parser("export", help="export the controller of an example to C")
    p_exp.add_argument("example", help="example name; see 'cmpc list'")
    p_exp.add_argument("--out", required=True, help="directory of the C sources (created)")
    p_exp.add_argument("--solver", choices=("sqp", "ipopt"), default="sqp",
                       help="'sqp' (default): standalone C; 'ipopt': links casadi's IPOPT")
    p_exp.add_argument("--controller", choices=("auto", "sequence", "contractive"),
                       default="auto", help="as for 'cmpc run'")
    p_exp.add_argument("--overwrite", action="store_true",
                       help="replace the contents of a non-empty --out directory")
    p_exp.add_argument("--build", action="store_true",
                       help="run make afterwards and the example program (needs gcc)")
    p_exp.add_argument("--cache", default=None, help="as for 'cmpc run'")
    p_exp.add_argument("--no-progress", action="store_true", help="no progress bar")
    sub.add_parser("list", help="list the example names")
    args = parser.parse_args(argv)
    try:
        return _command(parser, args)
    except KeyboardInterrupt:
        print("cmpc: interrupted (nothing partial was cached)", file=sys.stderr)
        return 130


def _command(parser: Any, args: Any) -> int:
    """Run the parsed command."""
    if args.command == "export":
        return _export(args)
    if args.command == "list":
        from . import models

        for n in models.names():
            ex_doc = models.load(n).info.get("example", "")
            print(f"{n:24s} {ex_doc}")
        return 0
    if args.steps is not None and args.steps < 1:
        parser.error("--steps must be at least 1")
    return _run(args.example, args.out, args.steps, args.seed,
                False if args.no_progress else None, args.controller, args.cache)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
