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
  the RK4 map; the validated one about the ODE itself.
"""

from __future__ import annotations

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


def main() -> None:
    res: dict = {"benchmark": "validated_ode", "python": platform.python_version(),
                 "numpy": np.__version__}
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
