"""Validated ODE models (``Model.from_ode(method="taylor")``) against the RK4 map.

Prints one JSON line with, measured in the same run:

* ``inclusion``: cost per box (µs) of the natural and centered inclusions (numpy backend,
  batches of 10 000 boxes of 1 % of X, U and W whole) of the validated Moore-Greitzer model
  and of the RK4 map of the same ODE (same boxes, dt, order-4 Runge-Kutta, one step), and
  the ratios validated / RK4;
* ``sets``: area of the certified one-step set (inner boxes of ``cm.one_step_set``,
  method "general") towards a target, at the same eps, for the RK4 and the validated
  variant of each of ``cstr_validated`` (target: the terminal polytope (7.10), eps 0.002,
  nominal: no disturbance) and ``moore_greitzer`` (target: the goal box, eps 0.0005,
  robust: for all w in W), with the build and search times. The RK4 certificate is about
  the RK4 map; the validated one about the ODE itself;
* ``controllable``: the certified robust controllable sets of ``moore_greitzer`` towards
  its stored terminal set (proven robustly invariant for the ODE, inside the goal box)
  with the obstacle removed (``cm.controllable_sets(..., robust=True, obstacles=[...])``,
  eps 2.5e-4 on the goal box +- 0.006), and the controllable sets of ``cstr_validated``
  towards a terminal set certified here by ``cm.terminal_set`` (eps 0.01): areas per
  level (grid estimates, 601 x 601 points), steps and times;
* ``closed_loop``: ``cm.SetSequenceMPC`` along those sets, run on the true ODE
  (``solve_ivp`` DOP853, rtol 1e-10, u and w held over each sample): for moore_greitzer
  ``--sequences`` (default 200) runs from random states of K_1 \\ K_0 under uniform random
  disturbance sequences, for cstr_validated as many runs from random states of the
  proven boxes (no disturbance); the violations counted: state outside X, inside the
  obstacle, input outside U (0 expected).

``--quick`` skips the inclusion costs and the one-step sets.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import casadi as ca
import numpy as np
from casadi_cmpc.models import cstr as C
from casadi_cmpc.models import moore_greitzer as MG

import casadi_cmpc as cm

os.environ.setdefault("OMP_NUM_THREADS", "1")


def _median(fn, reps: int = 7) -> float:
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from _timing import median_time

    return median_time(fn, reps)


def _mg(method: str) -> tuple[cm.Model, float]:
    x, u, w = ca.SX.sym("x", 2), ca.SX.sym("u", 2), ca.SX.sym("w", 2)
    X = cm.Box([r[0] for r in MG.X_RANGE], [r[1] for r in MG.X_RANGE])
    U = cm.Box([r[0] for r in MG.U_RANGE], [r[1] for r in MG.U_RANGE])
    W = cm.Box([-MG.W_MAX] * 2, [MG.W_MAX] * 2)
    t0 = time.perf_counter()
    kw = {"order": MG.ORDER} if method == "taylor" else {}
    m = cm.Model.from_ode(x, u, MG.rhs(x, u, w), MG.TAU, method=method, w=w, X=X, U=U, W=W,
                          name=f"mg_{method}", **kw)
    return m, time.perf_counter() - t0


def _cstr(method: str) -> tuple[cm.Model, float]:
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    U = cm.Box([(C.T_C_RANGE[0] - C.T_C_EQ) / 100], [(C.T_C_RANGE[1] - C.T_C_EQ) / 100])
    t0 = time.perf_counter()
    kw = {"order": C.VALIDATED_ORDER} if method == "taylor" else {}
    m = cm.Model.from_ode(x, u, C.rhs(x, u), C.VALIDATED_DT, method=method,
                          X=cm.Box(*C.VALIDATED_X), U=U, name=f"cstr_{method}", **kw)
    return m, time.perf_counter() - t0


def _inclusion_costs(mv: cm.Model, mr: cm.Model, N: int = 10_000) -> dict:
    rng = np.random.default_rng(0)
    X = mv.X.as_array()
    lo = X[:, 0] + rng.uniform(0, 0.99, (N, 2)) * (X[:, 1] - X[:, 0])
    boxes = np.stack([lo, lo + 0.01 * (X[:, 1] - X[:, 0])], axis=-1)
    out: dict = {}
    for kind in ("natural", "centered"):
        Fv = mv.inclusion(kind, backend="numpy")
        Fr = mr.inclusion(kind, backend="numpy")
        tv = _median(lambda Fv=Fv: Fv(boxes))
        tr = _median(lambda Fr=Fr: Fr(boxes))
        wv = Fv(boxes)
        wr = Fr(boxes)
        out[kind] = {"validated_us_per_box": 1e6 * tv / N, "rk4_us_per_box": 1e6 * tr / N,
                     "cost_ratio": tv / tr,
                     "mean_width_ratio": float(np.mean((wv[..., 1] - wv[..., 0])
                                                       / (wr[..., 1] - wr[..., 0])))}
    return out


def _set_area(model: cm.Model, target, eps: float, robust: bool) -> dict:
    t0 = time.perf_counter()
    res = cm.one_step_set(model, target, eps, robust=robust, method="general", progress=False)
    return {"area": float(res.area()), "inner_boxes": int(res.inner.shape[0]),
            "status": str(res.status), "seconds": time.perf_counter() - t0}


def _grid_areas(seq, box: cm.Box, k: int = 601) -> list[float]:
    g = [np.linspace(box.lo[j], box.hi[j], k) for j in range(2)]
    P = np.stack(np.meshgrid(*g, indexing="ij"), axis=-1).reshape(-1, 2)
    return [float(np.asarray(K.contains(P)).mean() * np.prod(box.diam)) for K in seq.sets]


def _ivp_plant(rhs, dt: float):
    from scipy.integrate import solve_ivp

    def plant(x, u, w):
        sol = solve_ivp(lambda t, y: rhs(y, u, w), (0.0, dt), x, method="DOP853",
                        rtol=1e-10, atol=1e-13)
        return sol.y[:, -1]

    return plant


def _cstr_rhs(x, u, w):
    c_a = x[0] + C.C_A_EQ
    temp = 100 * x[1] + C.T_EQ
    rate = C.K0 * np.exp(-C.E_OVER_R / temp) * c_a
    dc = C.Q_FLOW / C.VOLUME * (C.C_AF - c_a) - rate
    dT = (C.Q_FLOW / C.VOLUME * (C.T_F - temp) + (-C.DELTA_H) / (C.RHO * C.C_P) * rate
          + C.UA / (C.VOLUME * C.RHO * C.C_P) * (100 * u[0] + C.T_C_EQ - temp))
    return np.array([dc, dT / 100])


def _closed_loops(model, seq, ctrl, plant, runs: int, steps: int, obstacle=None,
                  disturbance=None) -> dict:
    rng = np.random.default_rng(0)
    B = np.concatenate([np.asarray(st["boxes"]) for st in seq.steps])
    T = seq.sets[0]
    out = {"runs": runs, "steps": steps, "state": 0, "input": 0, "obstacle": 0,
           "reached_terminal": 0}
    t0 = time.perf_counter()
    for i in range(runs):
        b = B[rng.integers(len(B))]
        x0 = rng.uniform(b[:, 0], b[:, 1])
        ctrl.reset()
        tr = cm.simulate(model, ctrl, x0, steps, disturbance=disturbance, seed=i,
                         plant=plant, progress=False)
        out["state"] += int(tr.violations["state"])
        out["input"] += int(tr.violations["input"])
        if obstacle is not None:
            out["obstacle"] += int(np.asarray(obstacle.contains(tr.x)).sum())
        out["reached_terminal"] += int(np.asarray(T.contains(tr.x)).any())
    out["seconds"] = time.perf_counter() - t0
    out["violations"] = out["state"] + out["input"] + out["obstacle"]
    return out


def _controllable(runs: int) -> tuple[dict, dict]:
    sets: dict = {}
    loops: dict = {}
    # Moore-Greitzer: robust, obstacle removed, stored terminal set (re-proven here)
    ex = cm.models.load("moore_greitzer")
    m = ex.model
    t0 = time.perf_counter()
    cert = cm.certify_invariant(m, ex.terminal, ex.local_law, 0.5)
    t_cert = time.perf_counter() - t0
    c = ex.info["x_ref"]
    near = cm.Box(c - 0.006, c + 0.006)
    t0 = time.perf_counter()
    seq = cm.controllable_sets(m, ex.terminal, 2.5e-4, robust=True, certificate=cert,
                               X=near, obstacles=[ex.info["obstacle"]], max_steps=30,
                               progress=False)
    sets["moore_greitzer"] = {
        "eps": 2.5e-4, "robust": True, "domain": near.as_array().tolist(),
        "terminal_proved": cert.proved, "terminal_seconds": t_cert,
        "terminal_area": float(ex.terminal.volume()), "status": seq.status,
        "converged_at": seq.converged_at, "levels": len(seq) - 1,
        "areas": _grid_areas(seq, near), "seconds": time.perf_counter() - t0,
        "about": m.discretisation}
    ctrl = cm.SetSequenceMPC(m, seq, Q=np.eye(2), R=1e-3 * np.eye(2), robust=True, x_ref=c,
                             minimax="vertices")
    loops["moore_greitzer"] = _closed_loops(
        m, seq, ctrl, _ivp_plant(MG.rhs_numpy, MG.TAU), runs, 10,
        obstacle=ex.info["obstacle"], disturbance="uniform")
    # CSTR: nominal (no disturbance), terminal set certified here
    ex = cm.models.load("cstr_validated")
    m = ex.model
    x_eq, u_eq = ex.info["mpc"]["x_ref"], ex.info["mpc"]["u_ref"]
    t0 = time.perf_counter()
    ts = cm.terminal_set(m, x_eq=x_eq, u_eq=u_eq, progress=False)
    t_term = time.perf_counter() - t0
    t0 = time.perf_counter()
    seq = cm.controllable_sets(m, ts.terminal, 0.01, certificate=ts.certificate,
                               max_steps=40, progress=False)
    sets["cstr_validated"] = {
        "eps": 0.01, "robust": False, "terminal_shape": ts.shape,
        "terminal_proved": ts.certificate.proved, "terminal_seconds": t_term,
        "terminal_area": float(ts.terminal.volume()), "status": seq.status,
        "converged_at": seq.converged_at, "levels": len(seq) - 1,
        "areas": _grid_areas(seq, m.X), "seconds": time.perf_counter() - t0,
        "about": m.discretisation}
    ctrl = cm.SetSequenceMPC(m, seq, Q=np.eye(2), R=np.eye(1), x_ref=x_eq)
    loops["cstr_validated"] = _closed_loops(m, seq, ctrl,
                                            _ivp_plant(_cstr_rhs, C.VALIDATED_DT), runs, 12)
    return sets, loops


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", type=int, default=200,
                    help="closed-loop runs per example (default 200)")
    ap.add_argument("--quick", action="store_true",
                    help="skip the inclusion costs and the one-step sets")
    args = ap.parse_args()
    res: dict = {"benchmark": "validated_ode", "python": platform.python_version(),
                 "numpy": np.__version__}
    res["controllable"], res["closed_loop"] = _controllable(args.sequences)
    if args.quick:
        json.dump(res, sys.stdout, default=float)
        sys.stdout.write("\n")
        return
    mv, tv = _mg("taylor")
    mr, tr = _mg("rk4")
    res["inclusion"] = {"model": "moore_greitzer", "boxes": 10_000,
                        **_inclusion_costs(mv, mr)}
    goal = cm.Polytope.from_box(cm.Box(MG.GOAL_CENTRE - MG.GOAL_RADIUS,
                                       MG.GOAL_CENTRE + MG.GOAL_RADIUS))
    cv, tcv = _cstr("taylor")
    cr, tcr = _cstr("rk4")
    terminal = cm.Polytope(C.H_TERMINAL, C.B_TERMINAL)
    res["sets"] = {
        "moore_greitzer": {"eps": 0.0005, "robust": True,
                           "rk4": {"build_s": tr, **_set_area(mr, goal, 0.0005, True)},
                           "validated": {"build_s": tv, **_set_area(mv, goal, 0.0005, True),
                                         "remainder_width": mv.validation["remainder_width"]}},
        "cstr_validated": {"eps": 0.002, "robust": False,
                           "rk4": {"build_s": tcr, **_set_area(cr, terminal, 0.002, False)},
                           "validated": {"build_s": tcv,
                                         **_set_area(cv, terminal, 0.002, False),
                                         "remainder_width": cv.validation["remainder_width"]}},
    }
    for v in res["sets"].values():
        v["area_ratio_validated_over_rk4"] = v["validated"]["area"] / max(v["rk4"]["area"],
                                                                           1e-300)
    json.dump(res, sys.stdout, default=float)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
