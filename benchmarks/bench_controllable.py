"""Controllable-set sequences of E8 and E9 (eps 0.05) and the robust one-step MPC along them.

Prints one JSON line with, for E8 (nominal, ``cm.models.load("cannon")``) and E9 (robust,
``"cannon_robust"``, mu in [0.85, 0.95]):

* ``seconds``: ``cm.controllable_sets(model, T, 0.05, robust=..., law=K)`` to convergence
  (terminal certificate included), one process (one core), with ``converged_at`` next to
  the thesis' step (E8: 41, E9: K48 = K49);
* ``area_ratio``: area of the maximal set (T and the proven boxes) against a dense-grid
  estimate of the true maximal controllable set, both counted on the same grid of nodes;
  the estimate is grid dynamic programming: a node is in K_i when, for one of 401 sampled
  controls, the successors at the vertices of W (affine in mu: the vertices decide) fall in
  cells of K_{i-1} (K_0: nodes of T, exact membership), iterated to a fixed point. It is an
  estimate (cells, sampled controls), not a bound;
* ``modal_k1``: for E9, K_1 by the modal route (Alg 5.2, "for all w exists u") and by the
  general route ("exists u for all w"), areas against the grid estimates of both
  statements;
* ``mpc``: ``cm.SetSequenceMPC`` (IPOPT and SQP) from (1.75, -1.6) under ``RUNS`` random mu
  sequences: median time of the one-step MPC steps (mode "mpc"), violations of X and U,
  steps whose control was not certified.

Targets of the issue: E8 <= 20 s, E9 <= 60 s, area ratio >= 0.9, median robust step <= 1 ms.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

import casadi_cmpc as cm

EPS = 0.05
RUNS = int(sys.argv[1]) if len(sys.argv) > 1 else 200
GRID = 201
N_U = 401


def _grid(model):
    X = model.X
    axes = [np.linspace(X.lo[j], X.hi[j], GRID) for j in range(model.n)]
    mesh = np.meshgrid(*axes, indexing="ij")
    return axes, np.stack([m.ravel() for m in mesh], axis=1)


def _grid_dp(model, T, robust, semantics="exists_forall"):
    """Boolean membership of the grid nodes in the maximal set, and in K_1."""
    axes, P = _grid(model)
    M = P.shape[0]
    us = np.linspace(model.U.lo[0], model.U.hi[0], N_U)
    W = (np.asarray(model.W.vertices()) if robust else model.W.mid[None]) if model.l else \
        np.zeros((1, 0))
    F = model.function.map(M * N_U)
    Xr = np.repeat(P, N_U, axis=0).T
    Ur = np.tile(us, M)[None]
    cells = []
    for wv in W:
        Y = np.asarray(F(Xr, Ur, np.repeat(wv[:, None], M * N_U, axis=1)), dtype=float).T
        idx = np.zeros(M * N_U, dtype=np.int64)
        inside = np.ones(M * N_U, dtype=bool)
        for j in range(model.n):
            h = axes[j][1] - axes[j][0]
            k = np.rint((Y[:, j] - axes[j][0]) / h).astype(np.int64)
            inside &= (k >= 0) & (k < GRID)
            idx = idx * GRID + np.clip(k, 0, GRID - 1)
        cells.append((idx, inside))
    member = np.asarray(T.contains(P), dtype=bool)
    k1 = None
    for _ in range(200):
        oks = [member[idx] & inside for idx, inside in cells]
        if semantics == "exists_forall":
            ok = np.logical_and.reduce(oks).reshape(M, N_U).any(axis=1)
        else:  # for all w exists u: each vertex with its own u
            ok = np.logical_and.reduce([o.reshape(M, N_U).any(axis=1) for o in oks])
        new = member | ok
        if k1 is None:
            k1 = new.copy()
        if (new == member).all():
            break
        member = new
    return P, member, k1


def _sequence(name, robust):
    ex = cm.models.load(name)
    t0 = time.perf_counter()
    seq = cm.controllable_sets(ex.model, ex.terminal, EPS, robust=robust, law=ex.local_law,
                               progress=False)
    sec = time.perf_counter() - t0
    P, est, _ = _grid_dp(ex.model, ex.terminal, robust)
    ours = seq.level(P) >= 0
    return ex, seq, {
        "seconds": round(sec, 2), "converged_at": seq.converged_at, "status": seq.status,
        "thesis_converged_at": ex.info.get("expected_converged_at", 49 if robust else 41),
        "area_ratio": round(float(ours.sum() / max(est.sum(), 1)), 4),
        "nodes_ours": int(ours.sum()), "nodes_grid_estimate": int(est.sum()),
        "ours_outside_estimate": int((ours & ~est).sum())}


def _modal(ex):
    out = {}
    P, _, k1_ef = _grid_dp(ex.model, ex.terminal, True, "exists_forall")
    _, _, k1_fe = _grid_dp(ex.model, ex.terminal, True, "forall_exists")
    for meth, est in (("general", k1_ef), ("modal", k1_fe)):
        t0 = time.perf_counter()
        r = cm.one_step_set(ex.model, ex.terminal, EPS, robust=True, method=meth,
                            time_limit=120, progress=False)
        ours = (r.paving.contains(P, view="inner")
                | np.asarray(ex.terminal.contains(P), dtype=bool))
        out[meth] = {"seconds": round(time.perf_counter() - t0, 2),
                     "semantics": r.semantics, "status": r.status.name,
                     "area_ratio": round(float(ours.sum() / max(est.sum(), 1)), 4)}
    return out


def _mpc(ex, seq):
    out = {}
    rng = np.random.default_rng(1)
    mus = rng.uniform(ex.model.W.lo[0], ex.model.W.hi[0], (RUNS, 40))
    for solver in ("ipopt", "sqp"):
        ctrl = cm.SetSequenceMPC(ex.model, seq, Q=np.eye(2), R=np.eye(1),
                                 local_law=ex.local_law, solver=solver)
        times, viol, uncert = [], 0, 0
        for run in range(RUNS):
            x = np.array([1.75, -1.6])
            for k in range(40):
                r = ctrl.solve(x)
                if r.mode == "mpc":
                    times.append(r.elapsed)
                if r.certificate.label not in ("verified", "local_law"):
                    uncert += 1
                viol += int(not ex.model.U.contains(r.u))
                x = ex.model.step(x, r.u, mus[run, k:k + 1]).reshape(-1)
                viol += int(not ex.model.X.contains(x))
        out[solver] = {"median_step_ms": round(1e3 * float(np.median(times)), 3),
                       "p90_step_ms": round(1e3 * float(np.percentile(times, 90)), 3),
                       "mpc_steps": len(times), "violations": viol,
                       "uncertified_steps": uncert}
    return out


def main() -> None:
    res = {"eps": EPS, "runs": RUNS}
    _, _, res["E8"] = _sequence("cannon", False)
    ex9, seq9, res["E9"] = _sequence("cannon_robust", True)
    res["E9_modal_k1"] = _modal(ex9)
    res["E9_mpc"] = _mpc(ex9, seq9)
    res["targets"] = {"E8_s": 20, "E9_s": 60, "area_ratio": 0.9, "median_step_ms": 1.0}
    print(json.dumps(res))


if __name__ == "__main__":
    main()
