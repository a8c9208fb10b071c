"""Throughput of the CSTR inclusion functions vs CasADi's own batched point evaluation.

Prints one JSON line: box evaluations per second for the natural and centered inclusion
functions at batch sizes 1, 1e3, 1e5, CasADi ``Function.map`` point evaluations per second at
the same sizes (same run, the three called in turn), and the cost ratios the foundation issue
sets targets for: natural >= 2e6 boxes/s at 1e5; natural/CasADi-point cost <= 5;
centered/natural cost <= 4.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time

import numpy as np

import casadi_cmpc as cm

os.environ.setdefault("OMP_NUM_THREADS", "1")


def _interleaved(fns: dict, min_time: float = 0.6, min_reps: int = 9) -> dict:
    """Median time of each function, calling them in turn so that a change of machine load
    during the measurement affects all of them alike."""
    for fn in fns.values():
        fn()  # warm up
    times: dict = {k: [] for k in fns}
    t_start = time.perf_counter()
    while len(times[next(iter(fns))]) < min_reps or time.perf_counter() - t_start < min_time:
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t0)
        if len(times[next(iter(fns))]) > 2000:
            break
    return {k: float(np.median(v)) for k, v in times.items()}


def main() -> dict:
    ex = cm.models.load("cstr")
    model = ex.model
    F = model.inclusion("natural")
    Fc = model.inclusion("centered")
    rng = np.random.default_rng(0)
    out: dict = {"benchmark": "bench_inclusion", "model": "cstr",
                 "python": platform.python_version(), "numpy": np.__version__}
    for key, n in (("1", 1), ("1e3", 1000), ("1e5", 100000)):
        c = rng.uniform(-0.05, 0.05, (n, model.n))
        X = np.stack([c - 0.005, c + 0.005], axis=-1)
        U = np.stack([np.full((n, 1), 0.1), np.full((n, 1), 0.12)], axis=-1)
        fmap = model.function.map(n)
        xs = np.ascontiguousarray(c.T)
        us = np.full((1, n), 0.11)
        ws = np.zeros((0, n))
        t = _interleaved({"nat": lambda: F(X, U), "cen": lambda: Fc(X, U),  # noqa: B023
                          "pt": lambda: fmap(xs, us, ws)})  # noqa: B023
        t_nat, t_cen, t_pt = t["nat"], t["cen"], t["pt"]
        out[f"natural_boxes_per_s@{key}"] = n / t_nat
        out[f"centered_boxes_per_s@{key}"] = n / t_cen
        out[f"casadi_points_per_s@{key}"] = n / t_pt
        out[f"natural_over_casadi_cost@{key}"] = t_nat / t_pt
        out[f"centered_over_natural_cost@{key}"] = t_cen / t_nat
    out["targets"] = {"natural_boxes_per_s@1e5": ">= 2e6",
                      "natural_over_casadi_cost@1e5": "<= 5",
                      "centered_over_natural_cost@1e5": "<= 4"}
    out["met"] = {
        "natural_throughput": out["natural_boxes_per_s@1e5"] >= 2e6,
        "natural_vs_casadi": out["natural_over_casadi_cost@1e5"] <= 5,
        "centered_vs_natural": out["centered_over_natural_cost@1e5"] <= 4,
    }
    return out


if __name__ == "__main__":
    res = main()
    json.dump({k: (float(f'{v:.4g}') if isinstance(v, float) else v) for k, v in res.items()},
              sys.stdout)
    sys.stdout.write("\n")
