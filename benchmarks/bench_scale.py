"""How set computations scale: with workers, with the state dimension and with 1/eps.

Prints one JSON line, measured in one run:

* ``workers``: the E9 robust controllable sequence at eps 0.025, serial against a
  ``ProcessPoolExecutor(2)`` (target: speedup >= 1.7 on a 2-core machine) and against a Dask
  ``LocalCluster`` of 2 worker processes (its overhead against the pool); the sets must be
  identical. Beside them: the ceiling of two processes on this machine (two serial runs at
  once), and the searches, levels and pairs of the sequence.
* ``growth``: ``one_step_set`` (nominal and robust) on a chain model of n = 2, 3, 4 states
  (``x_i+ = x_i + 0.1 x_{i+1}``, the last state driven by ``u - 0.5 sin(x_0)`` and an
  additive w), at several eps: seconds, pairs classified, peak traced memory (MB) and the
  certified volume fraction of X; next to the naive grid at the same resolution (one cell per
  eps-box of X, one transition per cell and control value on 17 values, the same centered
  inclusion: what a SCOTS-style abstraction computes), its time, transitions and volume.
  The grid runs while it is predicted to finish within ``GRID_LIMIT_S``.

* ``cartpole``: the cart-pole's robust one-step set of its terminal set (4 states) by the
  affine-state method and by the general search, in T's bounding box at eps 0.05.

* ``finest``: the acceptance case of the growth, at n = 4 (robust): the finest eps at which
  the grid is predicted to finish within ``GRID_LIMIT_S``, the grid there against
  ``one_step_set`` (default method, and the general search with a time limit).

Options: ``--quick`` (coarser eps, n <= 3), ``--no-dask``,
``--only workers|growth|cartpole|finest``,
``--plot PNG`` (the growth as a log-log figure: seconds and certified volume against 1/eps,
ours and the grid, one colour per n).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
import tracemalloc
from concurrent.futures import ProcessPoolExecutor

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")

import casadi as ca  # noqa: E402

import casadi_cmpc as cm  # noqa: E402
from casadi_cmpc.interval import InclusionFunction  # noqa: E402

GRID_LIMIT_S = 600.0
N_U = 17  # control values of the grid


def chain(n: int) -> cm.Model:
    """The n-state chain: x_i+ = x_i + 0.1 x_{i+1}, x_{n-1}+ = x_{n-1} + 0.1 (u - 0.5 sin x_0)
    + w, X = [-1, 1]^n, U = [-2, 2], W = [-0.005, 0.005]."""
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    f = [x[i] + 0.1 * x[i + 1] for i in range(n - 1)]
    f.append(x[n - 1] + 0.1 * (u - 0.5 * ca.sin(x[0])) + w)
    return cm.Model(x=x, u=u, w=w, f=ca.vertcat(*f), X=cm.Box([-1] * n, [1] * n),
                    U=cm.Box([-2], [2]), W=cm.Box([-0.005], [0.005]), name=f"chain{n}")


def target(n: int) -> cm.Polytope:
    return cm.Polytope.from_box(cm.Box([-0.4] * n, [0.4] * n))


def ours(m: cm.Model, eps: float, robust: bool, method: str = "general") -> dict:
    """Time (a second run: kernels compiled) and, in a third run, the peak memory traced by
    tracemalloc (which slows Python down, so it is not timed). ``method="general"``: the
    state × control branch and bound; ``"affine_state"``: Alg 6.4, which grids only the
    nonlinear state x_0 of the chain (the others enter linearly)."""
    run = lambda: cm.one_step_set(m, target(m.n), eps, robust=robust,  # noqa: E731
                                  method=method, progress=False)
    run()
    t0 = time.perf_counter()
    K = run()
    dt = time.perf_counter() - t0
    tracemalloc.start()
    run()
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return {"s": dt, "pairs": int(K.n_pairs), "peak_mb": peak,
            "volume_fraction": float(K.area()) / 2.0 ** m.n,
            "status": str(K.status)}


def grid(m: cm.Model, eps: float, robust: bool, budget_s: float) -> dict:
    """The naive abstraction: a cell is proven when one of the N_U control values maps all
    of it (and all of W, robust) into the target."""
    n = m.n
    k = int(round(2 / eps))
    cells_n = k ** n
    from casadi_cmpc.interval._native import native_available

    F = InclusionFunction(m.function, "centered",
                          backend="native" if native_available() else "auto")
    W = (m.W.as_array()[None] if robust else np.zeros((1, 1, 2)))
    T = target(n)
    # time one batch first and predict
    edges = np.linspace(-1, 1, k + 1)
    idx = np.indices((k,) * n).reshape(n, -1).T
    t0 = time.perf_counter()
    probe = min(cells_n, 20000)
    lo = edges[idx[:probe]]
    F(np.stack([lo, lo + 2 / k], -1), np.array([[[0.0, 0.0]]]), W)
    per = (time.perf_counter() - t0) / probe
    predicted = per * cells_n * N_U * 0.6  # proven cells are skipped: about 60 % remain
    if predicted > budget_s:
        return {"skipped": f"predicted {predicted:.0f} s > {budget_s:.0f} s", "cells": cells_n}
    t0 = time.perf_counter()
    ok = np.zeros(cells_n, dtype=bool)
    transitions = 0
    for uv in np.linspace(-2, 2, N_U):
        todo = np.flatnonzero(~ok)
        for a in range(0, todo.size, 200_000):
            part = todo[a:a + 200_000]
            lo = edges[idx[part]]
            Y = F(np.stack([lo, lo + 2 / k], -1), np.array([[[uv, uv]]]), W)[0]
            transitions += part.size
            ok[part] |= np.asarray(T.contains_box(Y), dtype=bool)
    dt = time.perf_counter() - t0
    return {"s": dt, "transitions": transitions, "cells": cells_n,
            "volume_fraction": float(ok.sum()) / cells_n}


def growth(quick: bool) -> list[dict]:
    rows = []
    dims = (2, 3) if quick else (2, 3, 4)
    for n in dims:
        m = chain(n)
        eps_list = {2: (0.1, 0.05, 0.025), 3: (0.2, 0.1, 0.05), 4: (0.25, 0.2, 0.1)}[n]
        if quick:
            eps_list = eps_list[:2]
        for eps in eps_list:
            for robust in (False, True):
                row = {"n": n, "eps": eps, "robust": robust, "ours": ours(m, eps, robust),
                       "affine_state": ours(m, eps, robust, "affine_state")}
                row["grid"] = grid(m, eps, robust, GRID_LIMIT_S)
                g = row["grid"]
                if "s" in g:
                    row["grid_s_over_ours"] = g["s"] / row["ours"]["s"]
                    row["grid_s_over_affine_state"] = g["s"] / row["affine_state"]["s"]
                rows.append(row)
    return rows


def finest(n: int = 4, robust: bool = True, general_limit_s: float = 300.0) -> dict:
    """The acceptance case of the growth: at n states, the finest eps of 0.1, 0.05, 0.025,
    0.0125 at which the grid is predicted to finish within ``GRID_LIMIT_S``; there the grid,
    ``one_step_set`` with the default method (affine-state for the chain) and the general
    search (stopped after ``general_limit_s``): seconds and certified volume fraction."""
    m = chain(n)
    pick = None
    for eps in (0.1, 0.05, 0.025, 0.0125):
        k = int(round(2 / eps))
        if k ** n * (n + 2) * 8 > 4 * 2**30:  # the grid's index arrays alone exceed 4 GB
            break
        g = grid(m, eps, robust, 0.0)  # the prediction only
        pred = float(g["skipped"].split()[1])
        if pred > GRID_LIMIT_S:
            break
        pick = eps
    if pick is None:
        return {"skipped": "the grid does not finish at eps 0.1"}
    out: dict = {"n": n, "eps": pick, "robust": robust, "grid_limit_s": GRID_LIMIT_S}
    out["grid"] = grid(m, pick, robust, 10 * GRID_LIMIT_S)
    out["ours_auto"] = ours(m, pick, robust, "auto")
    t0 = time.perf_counter()
    K = cm.one_step_set(m, target(n), pick, robust=robust, method="general", progress=False,
                        time_limit=general_limit_s)
    out["ours_general"] = {"s": time.perf_counter() - t0, "status": str(K.status),
                           "volume_fraction": float(K.area()) / 2.0 ** n}
    g = out["grid"]
    if "s" in g:
        out["grid_s_over_ours_auto"] = g["s"] / out["ours_auto"]["s"]
        out["ours_auto_volume_over_grid"] = (out["ours_auto"]["volume_fraction"]
                                             / max(g["volume_fraction"], 1e-300))
        out["target"] = ">= 10x faster, same or larger volume"
    return out


def _e9(executor=None) -> tuple[float, list]:
    ex = cm.models.load("cannon_robust")
    t0 = time.perf_counter()
    seq = cm.controllable_sets(ex.model, ex.terminal, 0.025, robust=True, law=ex.local_law,
                               progress=False, executor=executor)
    return time.perf_counter() - t0, [s["boxes"] for s in seq.steps]


def _e9_seconds(_: int = 0) -> float:
    """One serial E9 sequence in a pool process: its seconds."""
    return _e9()[0]


def _e9_levels() -> dict:
    """The serial E9 sequence level by level: searches, levels and pairs, and the fit
    ``level seconds = a + b pairs`` (least squares over the levels; the last level of each
    search, whose end is not seen, left out): ``a`` is what a level costs whatever its size
    (classification calls, reduction, bisection, bookkeeping), which every process of a
    split search pays for each of its levels."""
    from casadi_cmpc.control import controllable as C
    from casadi_cmpc.solvers import _parallel as P

    marks: list[tuple[int, float]] = []  # (pairs, start) per level; (-1, end) per search
    searches: list = []
    orig_bnb, orig_call = C.branch_and_bound, P.LevelRunner.__call__

    def counting(*a, **k):
        out = orig_bnb(*a, **k)
        marks.append((-1, time.perf_counter()))
        searches.append(out)
        return out

    def timed(self, classify, frontier):
        marks.append((len(frontier), time.perf_counter()))
        return orig_call(self, classify, frontier)

    C.branch_and_bound, P.LevelRunner.__call__ = counting, timed
    try:
        _e9()
    finally:
        C.branch_and_bound, P.LevelRunner.__call__ = orig_bnb, orig_call
    N, dt = [], []
    for (n0, t0), (n1, t1) in zip(marks[:-1], marks[1:], strict=True):
        if n0 >= 0 and n1 >= 0:
            N.append(n0)
            dt.append(t1 - t0)
    A = np.column_stack([np.ones(len(N)), N])
    a, b = np.linalg.lstsq(A, np.asarray(dt), rcond=None)[0]
    levels = sum(o.levels for o in searches)
    return {"searches": len(searches), "levels": levels,
            "pairs": sum(o.n_classified for o in searches),
            "per_level_fixed_ms": 1e3 * a, "per_pair_us": 1e6 * b,
            "fixed_s": a * levels}


def _same(a: list, b: list) -> bool:
    return len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


def _mid(v: list[float]) -> float:
    return float(np.median(v))


def workers(dask: bool, rounds: int = 3) -> dict:
    """Serial against 2 pool processes on the E9 sequence, ``rounds`` times interleaved
    (medians and ranges: the machine is shared). Beside them the machine's own ceiling for
    two processes: two serial runs at once, one per pool process; ``2 serial / their wall
    time`` is what a split of perfectly divisible work with no overhead could reach."""
    _e9()  # compile and load every kernel once
    ser, par, two = [], [], []
    same = True
    with ProcessPoolExecutor(2) as pool:
        _e9(pool)  # the workers' kernels
        list(pool.map(_e9_seconds, range(2)))
        for _ in range(rounds):
            t, ref = _e9()
            ser.append(t)
            t, got = _e9(pool)
            par.append(t)
            same &= _same(ref, got)
            t0 = time.perf_counter()
            list(pool.map(_e9_seconds, range(2)))
            two.append(time.perf_counter() - t0)
    lv = _e9_levels()
    ratio = [s / p for s, p in zip(ser, par, strict=True)]
    ceiling = [2 * s / w for s, w in zip(ser, two, strict=True)]
    out = {"serial_s": _mid(ser), "pool2_s": _mid(par), "speedup_pool2": _mid(ratio),
           "speedup_range": [min(ratio), max(ratio)],
           "ceiling_two_processes": _mid(ceiling),
           "ceiling_range": [min(ceiling), max(ceiling)],
           **lv, "fixed_share_of_serial": lv["fixed_s"] / _mid(ser),
           "identical_pool": bool(same), "target_speedup": ">= 1.7"}
    if dask:
        try:
            import distributed
        except ImportError:
            out["dask"] = "not installed"
            return out
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster, \
                distributed.Client(cluster) as client:
            ex = client.get_executor()
            _e9(ex)
            t_dask, got = _e9(ex)
        out.update({"dask2_s": t_dask, "dask_over_pool": t_dask / out["pool2_s"],
                    "identical_dask": _same(ref, got)})
    return out


def cartpole(eps: float = 0.05, general_limit_s: float = 120.0) -> dict:
    """The cart-pole's robust one-step set of its certified terminal set T, searched in T's
    bounding box D at eps relative to D: the affine-state method (p and v enter f
    linearly, theta and omega are gridded) against the general 4-D search (time-limited);
    seconds of a second run, pieces or inner boxes, status, the volume of the proven set
    (``area()``) and the fraction of 20 000 uniform points of D inside it (and inside T,
    for scale)."""
    ex = cm.models.load("cartpole")
    m, T = ex.model, ex.terminal
    D = T.bounding_box()
    pts = D.lo + np.random.default_rng(0).random((20_000, 4)) * (D.hi - D.lo)
    out: dict = {"eps_relative_to_bbox_of_T": eps, "robust": True,
                 "T_fraction": float(np.mean(T.contains(pts)))}
    for meth in ("affine_state", "general"):
        kw = {"time_limit": general_limit_s} if meth == "general" else {}
        run = lambda meth=meth, kw=kw: cm.one_step_set(  # noqa: E731
            m, T, eps, robust=True, X=D, relative=True, method=meth, progress=False, **kw)
        run()
        t0 = time.perf_counter()
        K = run()
        out[meth] = {"s": time.perf_counter() - t0, "status": str(K.status),
                     "pieces_or_inner_boxes": int(len(K.pieces) if K.pieces is not None
                                                  else K.paving.n_inner),
                     "fraction_of_bbox": float(np.mean(K.contains(pts))),
                     "volume": float(K.area())}
    out["T_volume"] = float(T.volume())
    return out


def plot(rows: list[dict], path: str) -> None:
    """Log-log figure of the growth rows (robust runs): time and certified volume fraction
    against 1/eps, ours (solid, circles) and the grid (dashed, squares), one colour per n."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for n, colour in zip((2, 3, 4), ("tab:blue", "tab:orange", "tab:green"), strict=True):
        rs = [r for r in rows if r["n"] == n and r["robust"]]
        if not rs:
            continue
        inv = [1 / r["eps"] for r in rs]
        a1.loglog(inv, [r["ours"]["s"] for r in rs], "o-", color=colour,
                  label=f"n = {n}, branch and bound")
        a2.semilogx(inv, [100 * r["ours"]["volume_fraction"] for r in rs], "o-", color=colour,
                    label=f"n = {n}, branch and bound")
        g = [(1 / r["eps"], r["grid"]) for r in rs if "s" in r["grid"]]
        a1.loglog([x for x, _ in g], [y["s"] for _, y in g], "s--", color=colour,
                  label=f"n = {n}, grid abstraction")
        a2.semilogx([x for x, _ in g], [100 * y["volume_fraction"] for _, y in g], "s--",
                    color=colour, label=f"n = {n}, grid abstraction")
    a1.set_xlabel("1 / eps")
    a1.set_ylabel("time of the robust one-step set (s)")
    a2.set_xlabel("1 / eps")
    a2.set_ylabel("certified volume (% of X)")
    a2.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize=8)
    fig.savefig(path, dpi=110)


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-dask", action="store_true")
    ap.add_argument("--only", choices=["workers", "growth", "cartpole", "finest"])
    ap.add_argument("--plot", default=None, metavar="PNG")
    a = ap.parse_args()
    res: dict = {"machine": platform.machine(), "cpus": os.cpu_count()}
    if a.only in (None, "workers"):
        res["workers"] = workers(not a.no_dask)
    if a.only in (None, "growth"):
        res["growth"] = growth(a.quick)
        if a.plot:
            plot(res["growth"], a.plot)
    if a.only in (None, "cartpole"):
        res["cartpole"] = cartpole()
    if a.only in (None, "finest"):
        res["finest"] = finest()
    return res


if __name__ == "__main__":
    print(json.dumps(main()))
