"""Per-step cost of the contractive MPC on E8 (Cannon system) vs a bare CasADi ``nlpsol`` loop
and do-mpc 5.x.

Problem (the anchor of the MPC issue): ``cm.models.load("cannon").model`` (2 states, 1 input,
|x|_inf <= 2, |u| <= 2, dt = 0.1), horizon N = 10, cost
``sum_{k=0}^{N-1} |x_{k+1}|^2 + u_k^2`` (Q = P = I, R = 1), terminal contraction
``|x_N|_2 <= 0.9 |x_0|_2``; closed loop of ``STEPS`` receding-horizon steps from
x0 = (0.3, -0.2), warm-started, repeated; per-step figures are medians over the steps of a
run, then over the runs. All variants are run in turn inside every repeat (interleaved), so
that a change of machine load affects them alike; compare ratios from the same run only.

Prints one JSON line with:

* ``ours_ipopt`` / ``ours_sqp``: ``ContractiveMPC(model, 10, 0.9, solver=...)``; per step
  the whole ``ctrl(x)`` call (interval verification included), the local solve
  (``stats["solve_time"]``) and the verification (``stats["verify_time"]``);
  ``*_noverify``: the same with ``verify=False, search="never"`` (``verify=False`` alone
  sends every step to the set inversion over U^N, since an unverified answer triggers the
  search);
* ``direct_ipopt`` / ``direct_sqp``: the same NLP written with ``casadi.nlpsol`` by hand
  (single shooting over u, x_1..x_N in X tightened by the same 1e-6 backoff, contraction as
  ``s^2 |x_N|^2 <= (0.9 (1 - 1e-6))^2`` with ``s = 1 / |x_0|`` a parameter, the solver
  options of ``contractive._solver_options``), warm-started with the shifted previous solution
  and the previous multipliers, called in a plain Python loop;
* ``raw_sqp_same_nlp``: the NLP that ``ours_sqp`` solves (``ctrl.export_spec().problem``:
  multiple shooting, same options) given to a fresh ``casadi.nlpsol``, called in a plain
  Python loop with the controller's start (the shifted previous sequence, the states
  predicted from it, the previous multipliers); only the ``nlpsol`` call is timed
  (``solve_s``). The target of the issue: ``ours_sqp`` step median <= 1.3 x this median,
  from the same run (``ratios["ours_sqp_step_over_raw_sqp_solve"]``);
* ``e9_set_sequence``: ``SetSequenceMPC(solver="sqp")`` on E9 (``cannon_robust``, the robust
  sequence of ``ex.info["sequence"]``): the median ``ctrl(x)`` over 1000 random states of the
  proven boxes (seed 1), and over the steps outside T of the closed loop from (1.75, -1.6)
  with mu drawn uniformly (seed 0); target <= 1 ms;
* ``do_mpc``: do-mpc 5.x ``make_step`` on the same problem, run in a child process (importing
  do-mpc prints warnings) together with ``ours_ipopt`` and ``direct_ipopt`` interleaved, so
  that the ratio do-mpc / ours comes from one process. Set-up (FACTS.md): ``Model("discrete",
  "SX")``, ``n_horizon=10``, ``t_step=0.1``, ``set_rterm(u=0)``, lterm ``|x|^2 + u^2`` and
  mterm ``|x|^2`` (= our cost + |x_0|^2, the same minimiser), bounds |x| <= 2, |u| <= 2,
  ``prepare_nlp()``, the x0-dependent constraint ``|x_N|^2 - 0.81 |x_0|^2 <= 0`` appended to
  ``nlp_cons`` with ``opt_x["_x", -1, 0, -1]`` and ``opt_p["_x0"]``, then ``create_nlp()``;
  ``nlpsol_opts={"ipopt.print_level": 0, "print_time": 0}``. ``do_mpc_our_opts`` adds our
  IPOPT options (warm-start init point, mu_init 1e-4, ...) to separate option effects from
  Python overhead. ``solver_call_s`` is the time spent inside do-mpc's ``nlpsol`` call;
* ``verify_one_step``: ``ctrl._check(x0, 10, u_seq)`` alone, and its ratio to the IPOPT
  solve time;
* ``inclusion_n1``: one call of ``model.inclusion("natural")`` on one box, against the 85 us
  of FACTS.md and CasADi's own point call ``model.function(x, u, w)``; also the call of the
  ``InclusionFunction`` behind the model's wrapper (``F.F(X, U, W)``, without the model's
  argument handling);
* closed-loop sanity: final |x|, verified steps, largest input difference to the direct loop
  and to do-mpc along the trajectory.

do-mpc is a benchmark-only dependency (not in pyproject): ``pip install "do-mpc>=5,<6"``.
Without it the do-mpc figures read "do-mpc not installed".

Usage: ``python benchmarks/bench_mpc.py [--quick] [--profile] [--no-dompc] [--no-e9]``
(``--profile`` prints the cProfile top costs of the ``ctrl(x)`` path to stderr; ``--no-dompc``
and ``--no-e9`` leave those parts out).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import platform
import subprocess
import sys
import time

import casadi as ca
import numpy as np

import casadi_cmpc as cm
from casadi_cmpc.mpc.contractive import ContractiveMPC
from casadi_cmpc.mpc.sequence import SetSequenceMPC

N = 10
ALPHA = 0.9
BACKOFF = 1e-6  # ContractiveMPC's default tightening of the constraints given to the solver
X0 = np.array([0.3, -0.2])
STEPS = 40
FACTS_INCLUSION_N1_S = 85e-6  # FACTS.md: natural inclusion, 2-state model, N = 1
TARGETS = {"ipopt_solve_s": 1e-3, "sqp_solve_s": 0.15e-3, "ours_over_direct": 1.2,
           "verify_over_ipopt_solve": 0.10, "inclusion_n1_s": FACTS_INCLUSION_N1_S / 20,
           "ours_sqp_over_raw_sqp": 1.3, "e9_step_s": 1e-3}

# the options of contractive._solver_options, written out so that the direct loop is a
# plain CasADi program (the JSON reports whether they still agree with the library's)
IPOPT_OPTS = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
              "ipopt.max_iter": 300, "ipopt.warm_start_init_point": "yes",
              "ipopt.mu_init": 1e-4}
SQP_OPTS = {"qpsol": "qrqp", "print_header": False, "print_iteration": False,
            "print_status": False, "print_time": False, "error_on_fail": False,
            "max_iter": 100,
            "qpsol_options": {"print_iter": False, "print_header": False,
                              "error_on_fail": False}}


def cannon():
    return cm.models.load("cannon").model


# ------------------------------------------------------------------ the direct nlpsol loop
class DirectNLP:
    """The NLP of ContractiveMPC (N = 10, 2-norm contraction) written with nlpsol by hand."""

    def __init__(self, model, solver: str) -> None:
        n, m = model.n, model.m
        us = ca.SX.sym("u", N * m)
        x0 = ca.SX.sym("x0", n)
        s = ca.SX.sym("s")
        w = ca.DM.zeros(0, 1)
        xs = [x0]
        cost = 0
        for i in range(N):
            u = us[i * m:(i + 1) * m]
            xs.append(model.function(xs[-1], u, w))
            cost = cost + ca.sumsqr(u) + ca.sumsqr(xs[-1])
        g = ca.vertcat(*xs[1:], s * s * ca.sumsqr(xs[N]))
        tight = BACKOFF * np.maximum(model.X.hi - model.X.lo, 1.0)
        a_eff = ALPHA * (1.0 - BACKOFF)
        self.lbg = np.concatenate([np.tile(model.X.lo + tight, N), [-np.inf]])
        self.ubg = np.concatenate([np.tile(model.X.hi - tight, N), [a_eff ** 2]])
        self.lbx = np.tile(model.U.lo, N)
        self.ubx = np.tile(model.U.hi, N)
        plugin, opts = ("ipopt", IPOPT_OPTS) if solver == "ipopt" else ("sqpmethod", SQP_OPTS)
        self.S = ca.nlpsol(f"direct_{solver}", plugin,
                           {"x": us, "p": ca.vertcat(x0, s), "f": cost, "g": g}, opts)
        self.m = m
        self.reset()

    def reset(self) -> None:
        self.u = None
        self.lam = None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        z0 = (np.zeros(N * self.m) if self.u is None
              else np.concatenate([self.u[self.m:], self.u[-self.m:]]))
        p = np.concatenate([x, [1.0 / np.linalg.norm(x)]])
        if self.lam is None:
            sol = self.S(x0=z0, p=p, lbx=self.lbx, ubx=self.ubx, lbg=self.lbg, ubg=self.ubg)
        else:
            sol = self.S(x0=z0, p=p, lbx=self.lbx, ubx=self.ubx, lbg=self.lbg, ubg=self.ubg,
                         lam_x0=self.lam[0], lam_g0=self.lam[1])
        self.lam = (sol["lam_x"], sol["lam_g"])
        self.u = np.clip(sol["x"].full().ravel(), self.lbx, self.ubx)
        return self.u[:self.m]


class RawSameNLP:
    """The controller's own NLP solved by a fresh ``nlpsol`` in a plain loop.

    The problem, options and bounds come from ``ctrl.export_spec().problem``; each call starts
    as the controller does (the previous sequence shifted by one move, the states predicted
    from it, the previous multipliers). ``last_solve_s`` is the time of the ``nlpsol`` call
    alone.
    """

    def __init__(self, ctrl: ContractiveMPC) -> None:
        P = ctrl.export_spec().problem
        self.P = P
        self.S = ca.nlpsol("raw_same_nlp", P.plugin, P.nlp, P.options)
        self.m = ctrl.model.m
        self.nm = P.horizon * self.m
        self.lo, self.hi = ctrl.model.U.lo, ctrl.model.U.hi
        self.last_solve_s = math.nan
        self.reset()

    def reset(self) -> None:
        self.u = None
        self.lam = None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        P, m, nm = self.P, self.m, self.nm
        u0 = (np.zeros(nm) if self.u is None
              else np.concatenate([self.u[m:], self.u[-m:]]))
        z0 = np.concatenate([u0, np.asarray(P.predict_states(u0, x), dtype=float).ravel()])
        p = np.concatenate([x, [1.0 / np.linalg.norm(x)]])
        warm = {} if self.lam is None else {"lam_x0": self.lam[0], "lam_g0": self.lam[1]}
        t0 = time.perf_counter()
        sol = self.S(x0=z0, p=p, lbx=P.lbz, ubx=P.ubz, lbg=P.lbg, ubg=P.ubg, **warm)
        self.last_solve_s = time.perf_counter() - t0
        self.lam = (sol["lam_x"], sol["lam_g"])
        self.u = np.clip(sol["x"].full().ravel()[:nm], np.tile(self.lo, P.horizon),
                         np.tile(self.hi, P.horizon))
        return self.u[:m]


# ------------------------------------------------------------------ closed-loop runner
class Loop:
    """One controller variant: run STEPS closed-loop steps, keep per-step figures."""

    def __init__(self, name: str, ctrl, model, ours: bool) -> None:
        self.name, self.ctrl, self.ours = name, ctrl, ours
        self.sim = model.function
        self.w = np.zeros(model.l)
        self.runs: list[dict] = []

    def run(self, steps: int, keep: bool = True) -> dict:
        ctrl = self.ctrl
        ctrl.reset()
        x = X0.copy()
        t_step, t_solve, t_verify, iters, us = [], [], [], [], []
        verified = 0
        for _ in range(steps):
            t0 = time.perf_counter()
            u = ctrl(x)
            t_step.append(time.perf_counter() - t0)
            if self.ours:
                r = ctrl.last_result
                st = r.stats
                t_solve.append(st.get("solve_time", math.nan))
                t_verify.append(st.get("verify_time", math.nan))
                iters.append(st.get("iter_count", 0))
                verified += r.certificate.label == "verified"
            else:
                iters.append(ctrl.S.stats().get("iter_count", 0))
                t_solve.append(getattr(ctrl, "last_solve_s", math.nan))
            us.append(float(u[0]))
            x = self.sim(x, u, self.w).full().ravel()
        res = {"step_s": float(np.median(t_step)), "iters": float(np.median(iters)),
               "iters_mean": float(np.mean(iters)),
               "final_norm_x": float(np.linalg.norm(x)), "verified_steps": verified,
               "u": us}
        if self.ours:
            res["solve_s"] = float(np.median(t_solve))
            res["verify_s"] = float(np.nanmedian(t_verify)) if verified else math.nan
            # the per-step path without the verification (same warm start as with it)
            res["step_minus_verify_s"] = float(np.median(
                np.asarray(t_step) - np.nan_to_num(np.asarray(t_verify))))
        elif not np.isnan(t_solve).all():
            res["solve_s"] = float(np.median(t_solve))
        if keep:
            self.runs.append(res)
        return res

    def summary(self) -> dict:
        keys = [k for k in self.runs[0] if k != "u"]
        out = {k: float(np.median([r[k] for r in self.runs])) for k in keys}
        out["verified_steps"] = int(min(r["verified_steps"] for r in self.runs))
        if not self.ours:
            del out["verified_steps"]  # nothing is verified outside ContractiveMPC
        out["final_norm_x"] = self.runs[-1]["final_norm_x"]
        return out


def run_interleaved(loops: list[Loop], repeats: int, steps: int) -> None:
    for lp in loops:
        lp.run(steps, keep=False)  # warm-up: builds the NLPs and the interval evaluators
    for _ in range(repeats):
        for lp in loops:
            lp.run(steps)


def _max_du(a: Loop, b: Loop) -> float:
    return float(np.max(np.abs(np.asarray(a.runs[-1]["u"]) - np.asarray(b.runs[-1]["u"]))))


def _interleaved_calls(fns: dict, min_time: float = 0.5, min_reps: int = 200) -> dict:
    """Median time of each function, called in turn (same-run comparison)."""
    for fn in fns.values():
        fn()
    times: dict = {k: [] for k in fns}
    t_start = time.perf_counter()
    first = next(iter(fns))
    while len(times[first]) < min_reps or time.perf_counter() - t_start < min_time:
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t0)
        if len(times[first]) > 20000:
            break
    return {k: float(np.median(v)) for k, v in times.items()}


# ------------------------------------------------------------------ do-mpc (child process)
def dompc_build(opts: dict):
    import do_mpc

    dt, mu = 0.1, 0.9  # E8: thesis (4.28)
    model = do_mpc.model.Model("discrete", "SX")
    x = model.set_variable("_x", "x", (2, 1))
    u = model.set_variable("_u", "u", (1, 1))
    model.set_rhs("x", ca.vertcat(x[0] + dt * x[1] + dt * (mu + (1 - mu) * x[0]) * u,
                                  dt * x[0] + x[1] + dt * (mu - 4 * (1 - mu) * x[1]) * u))
    model.setup()
    mpc = do_mpc.controller.MPC(model)
    mpc.settings.n_horizon = N
    mpc.settings.t_step = 0.1
    mpc.settings.store_full_solution = False
    mpc.settings.nlpsol_opts = dict(opts)
    # lterm(x_k, u_k), k = 0..N-1, + mterm(x_N) = our cost + |x_0|^2
    mpc.set_objective(lterm=ca.sumsqr(x) + ca.sumsqr(u), mterm=ca.sumsqr(x))
    mpc.set_rterm(u=0)
    mpc.bounds["lower", "_u", "u"] = -2.0
    mpc.bounds["upper", "_u", "u"] = 2.0
    mpc.bounds["lower", "_x", "x"] = -2.0
    mpc.bounds["upper", "_x", "x"] = 2.0
    mpc.prepare_nlp()
    xN = mpc.opt_x["_x", -1, 0, -1]
    x0 = mpc.opt_p["_x0"]
    mpc.nlp_cons.append(ca.sumsqr(xN) - ALPHA ** 2 * ca.sumsqr(x0))
    mpc.nlp_cons_lb.append(-np.inf)
    mpc.nlp_cons_ub.append(0.0)
    mpc.create_nlp()
    return mpc


class _TimedSolver:
    """Wraps do-mpc's nlpsol to time the solver call inside make_step."""

    def __init__(self, S, calls: list) -> None:
        self.S = S
        self.calls = calls

    def __call__(self, **kw):
        t0 = time.perf_counter()
        r = self.S(**kw)
        self.calls.append(time.perf_counter() - t0)
        return r

    def stats(self):
        return self.S.stats()


class DoMPCController:
    """``ctrl(x)`` interface around a fresh do-mpc MPC per closed-loop run."""

    def __init__(self, opts: dict) -> None:
        self.opts = opts
        self.mpc = None
        self.calls: list[float] = []

    def reset(self) -> None:
        # a fresh object per run: do-mpc keeps its history and warm start in the object
        self.mpc = dompc_build(self.opts)
        self.mpc.x0 = X0.reshape(2, 1)
        self.mpc.set_initial_guess()
        self.calls = []
        self.mpc.S = self.S = _TimedSolver(self.mpc.S, self.calls)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.mpc.make_step(x.reshape(2, 1)).ravel()


def dompc_child(repeats: int, steps: int) -> None:
    """Entry of the child process: do-mpc, ours and direct interleaved; one JSON line."""
    model = cannon()
    ours = Loop("ours_ipopt", ContractiveMPC(model, N, ALPHA, solver="ipopt", mode="receding"),
                model, True)
    direct = Loop("direct_ipopt", DirectNLP(model, "ipopt"), model, False)
    import do_mpc  # after our set-up; its import warnings go to the child's stderr

    variants = {"do_mpc": {"ipopt.print_level": 0, "print_time": 0},
                "do_mpc_our_opts": {**IPOPT_OPTS, "print_time": 0}}
    dm = {}
    for key, opts in variants.items():
        dm[key] = Loop(key, DoMPCController(opts), model, False)
    solver_calls: dict = {k: [] for k in dm}
    for lp in [ours, direct, *dm.values()]:
        lp.run(steps, keep=False)
    for _ in range(repeats):
        for lp in [ours, direct, *dm.values()]:
            lp.run(steps)
            if lp.name in dm:
                solver_calls[lp.name].append(float(np.median(lp.ctrl.calls)))
    out = {"version": do_mpc.__version__, "ours_ipopt": ours.summary(),
           "direct_ipopt": direct.summary()}
    for key, lp in dm.items():
        out[key] = lp.summary()
        out[key]["solver_call_s"] = float(np.median(solver_calls[key]))
        out[key]["max_abs_du_vs_ours"] = _max_du(lp, ours)
        out[key]["nlpsol_opts"] = {k: v for k, v in variants[key].items()}
    print(json.dumps(out))


def run_dompc(repeats: int, steps: int) -> dict:
    if importlib.util.find_spec("do_mpc") is None:  # looks the package up, no import
        return {"error": "do-mpc not installed (pip install 'do-mpc>=5,<6')"}
    try:
        proc = subprocess.run([sys.executable, os.path.abspath(__file__), "--dompc-child",
                               str(repeats), str(steps)], capture_output=True, text=True,
                              timeout=900)
    except subprocess.TimeoutExpired:
        return {"error": "do-mpc run did not finish in 900 s"}
    try:
        return json.loads(proc.stdout.strip().splitlines()[-1])
    except (json.JSONDecodeError, IndexError):
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        return {"error": f"do-mpc run failed (exit {proc.returncode}): {tail}"}


# ------------------------------------------------------------------ main
def profile_ctrl(model, steps: int) -> None:
    """cProfile of the ctrl(x) path (both solvers), top costs to stderr."""
    import cProfile
    import pstats

    for solver in ("ipopt", "sqp"):
        lp = Loop(solver, ContractiveMPC(model, N, ALPHA, solver=solver, mode="receding"),
                  model, True)
        lp.run(steps, keep=False)
        pr = cProfile.Profile()
        pr.enable()
        for _ in range(10):
            lp.run(steps, keep=False)
        pr.disable()
        print(f"==== cProfile, ctrl(x) with solver={solver!r}, {10 * steps} steps",
              file=sys.stderr)
        pstats.Stats(pr, stream=sys.stderr).sort_stats("tottime").print_stats(20)


def e9_set_sequence(repeats: int) -> dict:
    """Median ``ctrl(x)`` of ``SetSequenceMPC(solver="sqp")`` on E9 (see the module notes)."""
    ex = cm.models.load("cannon_robust")
    cfg = ex.info["sequence"]
    t0 = time.perf_counter()
    seq = cm.controllable_sets(ex.model, ex.terminal, cfg["eps"], robust=True,
                               law=ex.local_law, progress=False)
    t_seq = time.perf_counter() - t0
    ctrl = SetSequenceMPC(ex.model, seq, Q=cfg["Q"], R=cfg["R"], local_law=ex.local_law,
                          solver="sqp", robust=True)
    B = np.concatenate([st["boxes"] for st in seq.steps])
    rng = np.random.default_rng(1)
    states = rng.uniform(B[:, :, 0], B[:, :, 1])[rng.choice(len(B), 1000)]
    traj = cm.simulate(ex.model, ctrl, ex.x0s[0], steps=60, disturbance="uniform", seed=0,
                       progress=False)
    outside = np.array([x for x in traj.x[:-1] if seq.level(x) not in (0, None)])
    labels: dict = {}
    for x in states:  # warm-up: the target evaluators of every level
        label = ctrl.solve(x).certificate.label
        labels[label] = labels.get(label, 0) + 1
    t_rand: list[float] = []
    t_loop: list[float] = []
    for _ in range(repeats):
        for x in states:
            t = time.perf_counter()
            ctrl(x)
            t_rand.append(time.perf_counter() - t)
        for _ in range(20):
            for x in outside:
                t = time.perf_counter()
                ctrl(x)
                t_loop.append(time.perf_counter() - t)
    return {"step_s": float(np.median(t_rand)), "step_p90_s": float(np.percentile(t_rand, 90)),
            "closed_loop_outside_T_step_s": float(np.median(t_loop)),
            "closed_loop_steps_outside_T": int(len(outside)),
            "closed_loop_final_norm_x": float(np.linalg.norm(traj.x[-1])),
            "closed_loop_labels": sorted(set(traj.certificate)),
            "labels_random_states": labels, "levels": len(seq.sets),
            "sequence_build_s": t_seq, "target_s": TARGETS["e9_step_s"]}


def main(quick: bool, dompc: bool = True, e9: bool = True) -> dict:
    repeats = 5 if quick else 41
    model = cannon()
    from casadi_cmpc.mpc import contractive

    same_opts = (contractive._solver_options("ipopt", None)[1] == IPOPT_OPTS
                 and contractive._solver_options("sqp", None)[1] == SQP_OPTS)

    loops = {}
    for solver in ("ipopt", "sqp"):
        loops[f"ours_{solver}"] = Loop(
            f"ours_{solver}", ContractiveMPC(model, N, ALPHA, solver=solver, mode="receding"),
            model, True)
        loops[f"ours_{solver}_noverify"] = Loop(
            f"ours_{solver}_noverify",
            ContractiveMPC(model, N, ALPHA, solver=solver, verify=False, search="never",
                           mode="receding"),
            model, True)
        loops[f"direct_{solver}"] = Loop(f"direct_{solver}", DirectNLP(model, solver), model,
                                         False)
    loops["raw_sqp"] = Loop("raw_sqp", RawSameNLP(loops["ours_sqp"].ctrl), model, False)
    run_interleaved(list(loops.values()), repeats, STEPS)
    S = {k: lp.summary() for k, lp in loops.items()}
    for k in ("ours_ipopt_noverify", "ours_sqp_noverify"):
        for key in ("verify_s", "verified_steps"):
            S[k].pop(key, None)

    # 4. one verification at N = 10 alone
    ctrl = loops["ours_ipopt"].ctrl
    ctrl.reset()
    useq = ctrl.solve(X0).u_seq
    t_check = _interleaved_calls({"check": lambda: ctrl._check(X0, N, useq)})["check"]

    # 5. small-batch interval evaluation (N = 1) vs CasADi's point call
    F = model.inclusion("natural")
    Xb = np.stack([X0 - 0.01, X0 + 0.01], axis=-1)[None]
    Ub = np.array([[[0.1, 0.1]]])
    xp, up, wp = X0.copy(), np.array([0.1]), np.zeros(model.l)
    fun = model.function
    calls = {"incl": lambda: F(Xb, Ub), "point": lambda: fun(xp, up, wp)}
    raw = getattr(F, "F", None)  # the InclusionFunction behind the model's wrapper
    if callable(raw):
        Wb = np.zeros((1, model.l, 2))
        calls["raw"] = lambda: raw(Xb, Ub, Wb)
    t_incl = _interleaved_calls(calls)

    dm = run_dompc(repeats, STEPS) if dompc else {"error": "left out (--no-dompc)"}
    e9res = e9_set_sequence(1 if quick else 3) if e9 else {"error": "left out (--no-e9)"}

    oi, os_, di, ds = S["ours_ipopt"], S["ours_sqp"], S["direct_ipopt"], S["direct_sqp"]
    oin, osn = S["ours_ipopt_noverify"], S["ours_sqp_noverify"]
    raw = S["raw_sqp"]
    ratios = {
        "ours_sqp_step_over_raw_sqp_solve": os_["step_s"] / raw["solve_s"],
        "ours_sqp_noverify_step_over_raw_sqp_solve": osn["step_s"] / raw["solve_s"],
        "ours_over_direct_ipopt_noverify": oin["step_s"] / di["step_s"],
        "ours_over_direct_ipopt_verify": oi["step_s"] / di["step_s"],
        "ours_over_direct_ipopt_verified_path_minus_verify":
            oi["step_minus_verify_s"] / di["step_s"],
        "ours_over_direct_sqp_noverify": osn["step_s"] / ds["step_s"],
        "ours_over_direct_sqp_verify": os_["step_s"] / ds["step_s"],
        "ours_over_direct_sqp_verified_path_minus_verify":
            os_["step_minus_verify_s"] / ds["step_s"],
        "verify_one_step_over_ipopt_solve": t_check / oi["solve_s"],
        "verify_in_loop_over_ipopt_solve": oi["verify_s"] / oi["solve_s"],
        "verify_one_step_over_sqp_solve": t_check / os_["solve_s"],
        "inclusion_n1_speedup_vs_facts_85us": FACTS_INCLUSION_N1_S / t_incl["incl"],
        "inclusion_n1_over_casadi_point": t_incl["incl"] / t_incl["point"],
    }
    if "error" not in dm:
        ratios["do_mpc_over_ours_ipopt_verify"] = (dm["do_mpc"]["step_s"]
                                                   / dm["ours_ipopt"]["step_s"])
        ratios["do_mpc_over_direct_ipopt"] = dm["do_mpc"]["step_s"] / dm["direct_ipopt"]["step_s"]
        ratios["do_mpc_our_opts_over_ours_ipopt_verify"] = (
            dm["do_mpc_our_opts"]["step_s"] / dm["ours_ipopt"]["step_s"])
    res: dict = {
        "benchmark": "bench_mpc",
        "problem": "E8 cannon, N=10, Q=P=I, R=1, |u|<=2, |x|<=2, |x_N|<=0.9|x_0|, "
                   f"x0=(0.3,-0.2), {STEPS} closed-loop steps x {repeats} repeats",
        "python": platform.python_version(), "numpy": np.__version__,
        "casadi": ca.__version__, "same_solver_options_as_library": same_opts,
        "ipopt": {"solve_s": oi["solve_s"], "solve_target_s": TARGETS["ipopt_solve_s"],
                  "ctrl_call_s": oi["step_s"], "ctrl_call_noverify_s": oin["step_s"],
                  "verify_in_loop_s": oi["verify_s"], "iters": oi["iters"],
                  "iters_mean": oi["iters_mean"], "iters_mean_noverify": oin["iters_mean"],
                  "noverify_solve_s": oin["solve_s"]},
        "sqp": {"solve_s": os_["solve_s"], "solve_target_s": TARGETS["sqp_solve_s"],
                "ctrl_call_s": os_["step_s"], "ctrl_call_noverify_s": osn["step_s"],
                "verify_in_loop_s": os_["verify_s"], "iters": os_["iters"],
                "iters_mean": os_["iters_mean"], "iters_mean_noverify": osn["iters_mean"],
                "noverify_solve_s": osn["solve_s"]},
        "direct_nlpsol": {"ipopt_step_s": di["step_s"], "ipopt_iters_mean": di["iters_mean"],
                          "sqp_step_s": ds["step_s"], "sqp_iters_mean": ds["iters_mean"]},
        "raw_sqp_same_nlp": {"solve_s": raw["solve_s"], "loop_step_s": raw["step_s"],
                             "iters_mean": raw["iters_mean"],
                             "ours_sqp_iters_mean": os_["iters_mean"]},
        "e9_set_sequence": e9res,
        "verify_one_step_s": t_check,
        "inclusion_n1": {"natural_call_s": t_incl["incl"],
                         "target_s": TARGETS["inclusion_n1_s"],
                         "facts_reference_s": FACTS_INCLUSION_N1_S,
                         "casadi_point_call_s": t_incl["point"],
                         "inclusion_function_call_s": t_incl.get("raw", math.nan)},
        "closed_loop": {
            "final_norm_x": {k: v["final_norm_x"] for k, v in S.items()},
            "verified_steps": {k: S[k]["verified_steps"] for k in ("ours_ipopt", "ours_sqp")},
            "steps": STEPS,
            "max_abs_du_ours_vs_direct_ipopt": _max_du(loops["ours_ipopt"],
                                                       loops["direct_ipopt"]),
            "max_abs_du_ours_vs_direct_sqp": _max_du(loops["ours_sqp"], loops["direct_sqp"]),
            "max_abs_du_ours_sqp_vs_raw_same_nlp": _max_du(loops["ours_sqp"], loops["raw_sqp"]),
            "max_abs_du_ours_ipopt_vs_sqp": _max_du(loops["ours_ipopt"], loops["ours_sqp"])},
        "do_mpc": dm,
        "ratios": ratios,
    }
    res["targets"] = {"ours_sqp_step_over_raw_sqp_solve": "<= 1.3", "e9_step_s": "<= 1e-3",
                      "ipopt_solve_s": "<= 1e-3", "sqp_solve_s": "<= 1.5e-4",
                      "ours_over_direct": "<= 1.2", "verify_over_ipopt_solve": "<= 0.10",
                      "inclusion_n1_s": "<= 4.25e-6 (>= 20x faster than 85 us)"}
    res["met"] = {
        "ours_sqp_over_raw_sqp": (ratios["ours_sqp_step_over_raw_sqp_solve"]
                                  <= TARGETS["ours_sqp_over_raw_sqp"]),
        "e9_step": bool(e9res.get("step_s", math.inf) <= TARGETS["e9_step_s"]),
        "ipopt_solve": oi["solve_s"] <= TARGETS["ipopt_solve_s"],
        "sqp_solve": os_["solve_s"] <= TARGETS["sqp_solve_s"],
        "ours_over_direct_ipopt_noverify":
            ratios["ours_over_direct_ipopt_noverify"] <= TARGETS["ours_over_direct"],
        "ours_over_direct_ipopt_verify":
            ratios["ours_over_direct_ipopt_verify"] <= TARGETS["ours_over_direct"],
        "verify_over_ipopt_solve":
            ratios["verify_one_step_over_ipopt_solve"] <= TARGETS["verify_over_ipopt_solve"],
        "inclusion_n1": t_incl["incl"] <= TARGETS["inclusion_n1_s"],
    }
    load = os.getloadavg() if hasattr(os, "getloadavg") else (math.nan,) * 3
    res["note"] = (f"wall-clock medians ({os.cpu_count()} cores, load average {load[0]:.2f} "
                   "at the end); variants interleaved per repeat, do-mpc in a child process "
                   "interleaved with its own ours_ipopt/direct_ipopt; compare ratios only")
    return res


def _round(v):
    if isinstance(v, float):
        return float(f"{v:.4g}")
    if isinstance(v, dict):
        return {k: _round(x) for k, x in v.items()}
    return v


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    ap.add_argument("--profile", action="store_true",
                    help="cProfile of the ctrl(x) path to stderr (no benchmark)")
    ap.add_argument("--no-dompc", action="store_true", help="leave the do-mpc comparison out")
    ap.add_argument("--no-e9", action="store_true", help="leave the E9 SetSequenceMPC part out")
    ap.add_argument("--dompc-child", nargs=2, type=int, metavar=("REPEATS", "STEPS"),
                    help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.dompc_child:
        dompc_child(*args.dompc_child)
    elif args.profile:
        profile_ctrl(cannon(), STEPS)
    else:
        json.dump(_round(main(args.quick, not args.no_dompc, not args.no_e9)), sys.stdout)
        sys.stdout.write("\n")
