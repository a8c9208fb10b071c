"""Wall-clock time of the main job, ``cmpc run``, with a cold and a warm cache.

Prints one JSON line. Every figure is the wall-clock time of a fresh process
(``python3 -m casadi_cmpc run EXAMPLE --no-progress --cache DIR``, the same as ``cmpc run``),
so it includes the interpreter start and the imports:

* ``cold_s``: the first run in an empty temporary cache directory (it certifies the terminal
  set, computes the sequence of controllable sets, writes the cache, simulates);
* ``warm_s``: median of the following runs, which load the sequence from that cache;
* ``sequence_s``: the time the cold run reports for computing the sequence;
* ``cache_bytes``: the size of the cache file the cold run wrote;
* ``import_s`` (the anchor, measured in the same run): median time of
  ``python3 -c "import casadi_cmpc"``; ``cold_over_import`` and ``warm_over_import`` are the
  ratios, which transfer between machines better than the seconds.

``machine`` records the CPU count and the load average before and after, since a loaded
machine stretches every figure.

Usage: ``python3 benchmarks/bench_cli.py [--example NAME ...] [--warm N] [--steps K]``
(default: the default example ``cannon_robust``, 3 warm runs, the example's own steps).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _timed(cmd: list[str]) -> tuple[float, str]:
    """Wall-clock seconds of ``cmd`` run to completion, and its standard output; raises
    RuntimeError when it fails."""
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with {res.returncode}:\n{res.stderr}")
    return dt, res.stdout


def bench_example(name: str, warm: int, steps: int | None) -> dict:
    """Cold and warm ``cmpc run`` of one example in a temporary cache directory."""
    with tempfile.TemporaryDirectory(prefix="cmpc_bench_cache_") as cache:
        cmd = [sys.executable, "-m", "casadi_cmpc", "run", name, "--no-progress", "--cache",
               cache] + (["--steps", str(steps)] if steps is not None else [])
        cold, out = _timed(cmd)
        m = re.search(r"sequence computed in ([0-9.]+) s", out)
        files = list(Path(cache).glob("*.npz"))
        cache_bytes = sum(f.stat().st_size for f in files) if files else None
        warm_times = []
        for _ in range(warm):
            dt, out_w = _timed(cmd)
            if files and "loaded from the cache" not in out_w:
                raise RuntimeError(f"the warm run of {name} did not load the cache")
            warm_times.append(dt)
    return {"cold_s": round(cold, 2),
            "warm_s": round(statistics.median(warm_times), 2) if warm_times else None,
            "warm_runs_s": [round(t, 2) for t in warm_times],
            "sequence_s": float(m.group(1)) if m else None,
            "cache_bytes": cache_bytes}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--example", nargs="+", default=["cannon_robust"])
    parser.add_argument("--warm", type=int, default=3, help="number of warm runs")
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--imports", type=int, default=5, help="runs of the import anchor")
    args = parser.parse_args()
    load_before = os.getloadavg()
    imports = [_timed([sys.executable, "-c", "import casadi_cmpc"])[0]
               for _ in range(args.imports)]
    imp = statistics.median(imports)
    runs = {}
    for name in args.example:
        r = bench_example(name, args.warm, args.steps)
        r["cold_over_import"] = round(r["cold_s"] / imp, 1)
        if r["warm_s"] is not None:
            r["warm_over_import"] = round(r["warm_s"] / imp, 1)
        runs[name] = r
    print(json.dumps({
        "benchmark": "bench_cli", "command": "python3 -m casadi_cmpc run EXAMPLE --no-progress "
        "--cache TMP" + (f" --steps {args.steps}" if args.steps is not None else ""),
        "import_s": round(imp, 2), "runs": runs,
        "machine": {"cpus": os.cpu_count(), "loadavg_before": [round(v, 2) for v in load_before],
                    "loadavg_after": [round(v, 2) for v in os.getloadavg()]}}))


if __name__ == "__main__":
    main()
