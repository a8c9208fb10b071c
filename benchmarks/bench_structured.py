"""The structured set algorithms of thesis chapter 6 against the general ones, same eps.

Prints ONE JSON line:

* ``e11``: E11's robust one-step set of T (``khalil_affine_state``) by the affine-state
  method (Alg 6.4, ``method="affine_state"``) and by the general algorithm (Alg 4.6/6.1,
  ``method="general"``): seconds (median of ``--reps`` runs after a warm-up run, whose
  time, with the compilation of the interval functions, is ``first_call_seconds``), area of
  the proven set, the speed ratio ``general / structured`` next to the target (>= 5) and
  the area ratio ``structured / general`` (target >= 1);
* ``e12``: E12's (``khalil_affine_control``) quasi 2-step robust controllable set of T
  (Alg 6.7) against two recursive quasi one-step sets (thesis Fig 6.13: the quasi one-step
  set of T, its inner polytope P_1, the quasi one-step set of P_1), and against two steps
  of the general robust controllable sets (``cm.controllable_sets(..., max_steps=2)``, K_2:
  a control chosen afresh at each step, a weaker requirement than one open-loop sequence):
  seconds, areas, ratios and targets as for E11;
* with ``--sequences``, also the recursions to convergence: E12's polytopic quasi 2-step
  sets against the quasi one-step sets (seconds, index of convergence, final area, whether
  the initial states of Fig 6.15 lie in a set), and E11's affine-state sequence.

Areas: ``area()`` of the results (the union of the proven boxes or pieces), and for the
sets of different kinds (K_2, the polytopes) the fraction of a 401 x 401 grid of X inside
the set times the area of X (``grid_area``, the same estimate for every set compared).
The claims of every set (model, W, robust) are those of the functions called; this script
only times them.

Usage: ``python benchmarks/bench_structured.py [--eps11 0.05] [--eps12 0.05] [--reps 3]
[--sequences]``.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np

import casadi_cmpc as cm
from casadi_cmpc.control.quasi import (
    quasi_controllable_set,
    quasi_controllable_sets,
    quasi_step_comparison,
)

TARGET_SPEEDUP = 5.0


def timed(fn: Any, reps: int) -> tuple[Any, float, float]:
    """(result of the last call, median seconds of ``reps`` calls after a warm-up call,
    seconds of the warm-up call: with the compilation of the interval functions)."""
    t0 = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t0
    ts = []
    for _ in range(max(int(reps), 1)):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return out, float(np.median(ts)), first


def grid_area(model: cm.Model, inside: Any, k: int = 401) -> float:
    """Area of ``{x in X : inside(x)}`` estimated on a k x k grid of X (2-D)."""
    X = model.X
    g = [np.linspace(X.lo[j], X.hi[j], k) for j in range(2)]
    P = np.stack(np.meshgrid(*g, indexing="ij"), axis=-1).reshape(-1, 2)
    hit = np.asarray(inside(P), dtype=bool)
    return float(hit.mean() * np.prod(X.diam))


def ratio(a: float, b: float) -> float | None:
    return float(a / b) if b > 0 and np.isfinite(a) and np.isfinite(b) else None


def bench_e11(eps: float, reps: int) -> dict[str, Any]:
    ex = cm.models.load("khalil_affine_state")
    out: dict[str, Any] = {"example": "E11 khalil_affine_state", "eps": eps, "robust": True,
                           "W": [ex.model.W.lo.tolist(), ex.model.W.hi.tolist()]}
    for meth in ("affine_state", "general"):
        r, t, t1 = timed(lambda m=meth: cm.one_step_set(ex.model, ex.terminal, eps,
                                                        robust=True, method=m,
                                                        progress=False), reps)
        out[meth] = {"method": r.method, "status": str(r.status), "seconds": t,
                     "first_call_seconds": t1,
                     "area": float(r.area()),
                     "grid_area": grid_area(ex.model, r.contains)}
    s, g = out["affine_state"], out["general"]
    out["speedup"] = ratio(g["seconds"], s["seconds"])
    out["speedup_target"] = TARGET_SPEEDUP
    out["area_ratio"] = ratio(s["area"], g["area"])
    out["area_ratio_target"] = 1.0
    out["meets_target"] = bool(out["speedup"] is not None and out["speedup"] >= TARGET_SPEEDUP
                               and out["area_ratio"] is not None and out["area_ratio"] >= 1.0)
    return out


def bench_e12(eps: float, reps: int) -> dict[str, Any]:
    ex = cm.models.load("khalil_affine_control")
    model, T = ex.model, ex.terminal
    out: dict[str, Any] = {"example": "E12 khalil_affine_control", "eps": eps, "robust": True,
                           "W": [model.W.lo.tolist(), model.W.hi.tolist()]}
    q2, t2, t21 = timed(lambda: quasi_controllable_set(model, T, 2, eps), reps)
    out["quasi_2_step"] = {"seconds": t2, "first_call_seconds": t21, "area": float(q2.area()),
                           "grid_area": grid_area(model, q2.contains),
                           "status": str(q2.status)}
    ts = []
    for _ in range(max(int(reps), 1)):  # warm: the functions were compiled above
        cmp_ = quasi_step_comparison(model, T, eps, steps=2)
        ts.append(cmp_["seconds_one_step"])
    one = cmp_["one_step"]
    last = one[-1][0]
    out["two_quasi_1_step"] = {"seconds": float(np.median(ts)), "area": float(last.area()),
                               "grid_area": grid_area(model, last.contains),
                               "complete": bool(cmp_["complete_one_step"])}
    out["fig_6_13_polytope_areas"] = {"two_quasi_1_step": cmp_["poly_area_one_step"],
                                      "quasi_2_step": cmp_["poly_area_multi_step"]}
    # T's proof once, outside the timing (the quasi sets do not prove T either)
    cert = cm.certify_invariant(model, T, ex.local_law, 0.05, progress=False)
    seq, tg, tg1 = timed(lambda: cm.controllable_sets(model, T, eps, robust=True,
                                                      certificate=cert, max_steps=2,
                                                      progress=False), reps)

    def in_k2(P: np.ndarray) -> np.ndarray:
        lv = seq.level(P)
        return (lv >= 0) & (lv <= 2)

    out["general_K2"] = {"seconds": tg, "first_call_seconds": tg1,
                         "grid_area": grid_area(model, in_k2),
                         "status": seq.status, "steps": len(seq) - 1}
    q, o, g = out["quasi_2_step"], out["two_quasi_1_step"], out["general_K2"]
    out["speedup_vs_two_quasi_1_step"] = ratio(o["seconds"], q["seconds"])
    out["area_ratio_vs_two_quasi_1_step"] = ratio(q["grid_area"], o["grid_area"])
    out["speedup_vs_general_K2"] = ratio(g["seconds"], q["seconds"])
    out["area_ratio_vs_general_K2"] = ratio(q["grid_area"], g["grid_area"])
    out["speedup_target"] = TARGET_SPEEDUP
    out["area_ratio_target"] = 1.0
    out["meets_target_vs_two_quasi_1_step"] = bool(
        (out["speedup_vs_two_quasi_1_step"] or 0) >= TARGET_SPEEDUP
        and (out["area_ratio_vs_two_quasi_1_step"] or 0) >= 1.0)
    out["meets_target_vs_general_K2"] = bool(
        (out["speedup_vs_general_K2"] or 0) >= TARGET_SPEEDUP
        and (out["area_ratio_vs_general_K2"] or 0) >= 1.0)
    return out


def bench_sequences(eps11: float, eps12: float) -> dict[str, Any]:
    out: dict[str, Any] = {}
    ex = cm.models.load("khalil_affine_control")
    for steps in (2, 1):
        t0 = time.perf_counter()
        s = quasi_controllable_sets(ex.model, ex.terminal, steps, eps12, max_sets=60)
        out[f"e12_quasi_{steps}_step_sequence"] = {
            "eps": eps12, "seconds": time.perf_counter() - t0, "sets": len(s) - 1,
            "converged_at": s.converged_at, "status": s.status,
            "final_area": float(s.areas[-1]),
            "levels_x0": {str(x.tolist()): s.level(x) for x in ex.x0s},
            "thesis": "P20 = P21 (quasi 2-step)"}
    ex = cm.models.load("khalil_affine_state")
    meth = ex.info["affine_state"]["polytopic_method"]  # as `cmpc run` computes them
    t0 = time.perf_counter()
    seq = cm.controllable_sets(ex.model, ex.terminal, eps11, robust=True,
                               method="affine_state", law=ex.local_law, max_steps=80,
                               polytopic_method=meth, progress=False)
    out["e11_affine_state_sequence"] = {
        "eps": eps11, "polytopic_method": meth, "seconds": time.perf_counter() - t0,
        "sets": len(seq) - 1,
        "converged_at": seq.converged_at, "status": seq.status,
        "final_area": float(seq.sets[-1].volume()),
        "level_x0": seq.level(ex.x0s[0]), "thesis": "P39 = P40"}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--eps11", type=float, default=0.05)
    ap.add_argument("--eps12", type=float, default=0.05)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--sequences", action="store_true")
    a = ap.parse_args()
    res: dict[str, Any] = {"bench": "structured", "e11": bench_e11(a.eps11, a.reps),
                           "e12": bench_e12(a.eps12, a.reps)}
    if a.sequences:
        res["sequences"] = bench_sequences(a.eps11, a.eps12)
    print(json.dumps(res))


if __name__ == "__main__":
    main()
