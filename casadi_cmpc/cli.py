"""The ``cmpc`` command line.

``cmpc run [EXAMPLE] [--out DIR]`` runs the main job on a thesis example (default
``cannon_robust``): it prints the model summary and the natural and centered enclosures of one
step over the example's state, input and disturbance boxes, checks them against sampled true
successors, and (with ``--out``) writes the figures as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["main"]

DEFAULT_EXAMPLE = "cannon_robust"


def _fmt_box(b: np.ndarray) -> str:
    return " x ".join(f"[{lo:.6g}, {hi:.6g}]" for lo, hi in b)


def _run(name: str, out: str | None, samples: int, seed: int) -> int:
    from . import models

    try:
        ex = models.load(name)
    except ValueError as exc:
        print(f"cmpc: {exc}", file=sys.stderr)
        return 2
    model = ex.model
    print(model.summary())
    X = model.X.as_array()
    U = model.U.as_array()
    args = (X, U, model.W_box.as_array()) if model.l else (X, U)
    report: dict = {"example": name, "n": model.n, "m": model.m, "l": model.l}
    rng = np.random.default_rng(seed)
    xs = model.X.sample(samples, rng)
    us = model.U.sample(samples, rng) if model.m else None
    ws = model.W.sample(samples, rng) if model.W is not None else None
    succ = model.step(xs, us, ws)
    print(f"\nOne step over X x U{' x W' if model.l else ''} "
          f"({samples} sampled successors checked):")
    for kind in ("natural", "centered"):
        F = model.inclusion(kind)
        t0 = time.perf_counter()
        Y = F(*args)[0]
        dt = time.perf_counter() - t0
        inside = bool(((succ >= Y[:, 0]) & (succ <= Y[:, 1])).all())
        print(f"  {kind:9s} {_fmt_box(Y)}   (all samples inside: {inside})")
        report[kind] = {"enclosure": Y.tolist(), "samples_inside": inside,
                        "seconds": dt}
        if not inside:
            print(f"cmpc: the {kind} enclosure misses a sampled successor", file=sys.stderr)
            return 1
    width_n = np.diff(np.asarray(report["natural"]["enclosure"]), axis=1).ravel()
    width_c = np.diff(np.asarray(report["centered"]["enclosure"]), axis=1).ravel()
    print(f"  widths: natural {np.array2string(width_n, precision=4)}, "
          f"centered {np.array2string(width_c, precision=4)}")
    if out:
        d = Path(out)
        d.mkdir(parents=True, exist_ok=True)
        (d / "run.json").write_text(json.dumps(report, indent=2))
        print(f"\nwritten: {d / 'run.json'}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``cmpc`` console script."""
    parser = argparse.ArgumentParser(prog="cmpc", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser("run", help="run the main job on a thesis example")
    p_run.add_argument("example", nargs="?", default=DEFAULT_EXAMPLE,
                       help=f"example name (default: {DEFAULT_EXAMPLE}); see 'cmpc list'")
    p_run.add_argument("--out", default=None, help="directory for the JSON results")
    p_run.add_argument("--samples", type=int, default=10000,
                       help="number of sampled successors to check (default 10000)")
    p_run.add_argument("--seed", type=int, default=0)
    sub.add_parser("list", help="list the example names")
    args = parser.parse_args(argv)
    if args.command == "list":
        from . import models

        print("\n".join(models.names()))
        return 0
    return _run(args.example, args.out, args.samples, args.seed)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
