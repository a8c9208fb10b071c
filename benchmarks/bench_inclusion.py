"""Throughput of the CSTR inclusion functions vs CasADi's own batched point evaluation, and
the per-call cost of small batches (the scalar backend) on the 2-state cannon model.

Prints one JSON line with, measured in the same run:

* box evaluations per second for the natural and centered inclusion functions of the CSTR
  at batch sizes 1, 1e3, 1e5, CasADi ``Function.map`` point evaluations per second at the
  same sizes (the three called in turn), and the cost ratios the foundation issue sets
  targets for: natural >= 2e6 boxes/s at 1e5; natural/CasADi-point cost <= 5;
  centered/natural cost <= 4;
* ``small_batch``: per-call times in µs (medians of 20 consecutive calls, the functions
  interleaved) of the natural
  inclusion of the cannon model (thesis E8, 2 states, 1 input) at N = 1 and N = 10 boxes,
  through ``model.inclusion("natural")`` (argument checks, default U) and through the raw
  :class:`~casadi_cmpc.interval.InclusionFunction` of ``model.function``, each with the
  numpy backend and with the default ``"auto"`` backend (the scalar evaluator at these
  sizes); the centered form the same way at N = 1; the numpy/auto cost ratios; and CasADi's
  own point call ``model.function(x, u, w)`` as an anchor. Target: at N = 1 the auto
  backend is at least 20 times cheaper than numpy (both including the argument checks and
  the output array).
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


def _interleaved(fns: dict, min_time: float = 0.6, min_reps: int = 9, inner: int = 1) -> dict:
    """Median time of one call of each function, calling them in turn so that a change of
    machine load during the measurement affects all of them alike; each measurement times
    ``inner`` consecutive calls (for calls of a few µs, as a controller loop makes them)."""
    for fn in fns.values():
        fn()  # warm up
    times: dict = {k: [] for k in fns}
    calls = range(inner)
    t_start = time.perf_counter()
    while len(times[next(iter(fns))]) < min_reps or time.perf_counter() - t_start < min_time:
        for k, fn in fns.items():
            t0 = time.perf_counter()
            for _ in calls:
                fn()
            times[k].append((time.perf_counter() - t0) / inner)
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
    small = small_batch()
    out["small_batch"] = small
    out["targets"] = {"natural_boxes_per_s@1e5": ">= 2e6",
                      "natural_over_casadi_cost@1e5": "<= 5",
                      "centered_over_natural_cost@1e5": "<= 4",
                      "small_batch.model_numpy_over_auto@1": ">= 20"}
    out["met"] = {
        "natural_throughput": out["natural_boxes_per_s@1e5"] >= 2e6,
        "natural_vs_casadi": out["natural_over_casadi_cost@1e5"] <= 5,
        "centered_vs_natural": out["centered_over_natural_cost@1e5"] <= 4,
        "small_batch_scalar": small["model_numpy_over_auto@1"] >= 20,
    }
    return out


def small_batch() -> dict:
    """Per-call µs of the cannon model's inclusions at N = 1 and 10, numpy vs auto."""
    model = cm.models.load("cannon").model
    fun = model.function
    rng = np.random.default_rng(1)
    res: dict = {"model": "cannon", "n_instructions": int(fun.n_instructions()),
                 "scalar_max_batch": cm.interval.InclusionFunction.scalar_max_batch}
    X = model.X.as_array()
    U1 = model.U.as_array()[None]
    W1 = np.zeros((1, 0, 2))
    x_pt, u_pt, w_pt = np.array([0.5, -0.3]), np.array([0.1]), np.zeros(0)
    fns: dict = {"casadi_point": lambda: fun(x_pt, u_pt, w_pt)}
    for n in (1, 10):
        c = rng.uniform(0.8 * X[:, 0], 0.8 * X[:, 1], (n, model.n))
        Xb = np.stack([c - 0.05, c + 0.05], axis=-1)
        Xarg = Xb[0] if n == 1 else Xb  # one (n, 2) box, as a controller passes it
        for backend in ("numpy", "auto"):
            Fm = model.inclusion("natural", backend=backend)
            Fr = cm.interval.inclusion(fun, "natural", backend=backend)
            fns[f"model_{backend}@{n}"] = lambda Fm=Fm, Xarg=Xarg: Fm(Xarg)
            fns[f"raw_{backend}@{n}"] = lambda Fr=Fr, Xb=Xb: Fr(Xb, U1, W1)
            if n == 1:
                Fc = model.inclusion("centered", backend=backend)
                fns[f"model_centered_{backend}@{n}"] = lambda Fc=Fc, Xarg=Xarg: Fc(Xarg)
    t = _interleaved(fns, min_time=2.0, min_reps=100, inner=20)
    for k, v in t.items():
        res[f"{k}_us"] = v * 1e6
    for n in (1, 10):
        for what in ("model", "raw"):
            res[f"{what}_numpy_over_auto@{n}"] = t[f"{what}_numpy@{n}"] / t[f"{what}_auto@{n}"]
    res["model_centered_numpy_over_auto@1"] = (t["model_centered_numpy@1"]
                                               / t["model_centered_auto@1"])
    res["model_auto_over_casadi_point@1"] = t["model_auto@1"] / t["casadi_point"]
    return res


if __name__ == "__main__":
    res = main()

    def _round(v):
        if isinstance(v, dict):
            return {k: _round(x) for k, x in v.items()}
        return float(f"{v:.4g}") if isinstance(v, float) else v

    json.dump(_round(res), sys.stdout)
    sys.stdout.write("\n")
