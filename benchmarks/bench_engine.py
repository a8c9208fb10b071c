"""The interval engine per core: the native backend against numpy, measured in one run.

Prints one JSON line:

* ``inclusion_1e5``: the CSTR natural inclusion at 1e5 boxes, boxes per second with the
  native backend (fused C loop) and with numpy, their ratio, and CasADi's own batched point
  evaluation (``Function.map``, no intervals) as the hardware anchor; the native kernel's
  C loop with the outward rounding taken out (``c_unrounded``: not sound, what a fused C
  loop of this function does here); immrax (JAX, float64, one core, rounding to nearest:
  not sound) where installed.
* ``batch_300``: the CSTR natural and centered inclusions at 300 boxes (the mean batch of the
  set searches), µs per call, native against numpy.
* ``call_n1``: one natural call at N = 1 on the 2-state cannon model (E8), µs, with the
  default backend (the scalar evaluator at this size) and with the native one.
* ``one_step_3state``: ``one_step_set`` (the state × control branch and bound,
  ``method="general"``) on a 3-state model at eps 0.05 against the naive grid (one cell per
  eps-box, one transition per cell and control value on 17 values, the same centered
  inclusion, cells certified once skipped): pairs per second and certified volume of each;
  the grid refined (4 more cells per axis at a time) until it certifies the search's
  volume, and its time there (time to equal volume); beside them the default method for
  this model (affine-state: x_1 and x_2 enter f linearly), its seconds and volume. The
  grid is the benchmark's reference, not a library feature.
* ``e9_sequence``: the E9 robust controllable sequence at eps 0.05, seconds with numpy forced
  against the default backend (native once a function is called repeatedly), and whether
  the sets are identical.
* ``before_issue``: the CSTR numpy inclusion at 1e5 boxes and the E9 sequence of the code
  before the native backend (commit ``BASELINE``, checked out in a temporary git worktree
  and run in a child process of this run), and the ratios of today's default against them.

Ratios are what counts: the machine is shared.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")
# immrax (JAX) on one core as well, in float64
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false "
                      "intra_op_parallelism_threads=1")

from _timing import median_time  # noqa: E402

import casadi_cmpc as cm  # noqa: E402
from casadi_cmpc.interval import InclusionFunction  # noqa: E402
from casadi_cmpc.interval._native import native_available  # noqa: E402


def _cstr_boxes(model: cm.Model, N: int, seed: int = 0) -> tuple:
    rng = np.random.default_rng(seed)
    c = rng.uniform(model.X.lo, model.X.hi, (N, 2))
    X = np.stack([c - 0.01, c + 0.01], -1)
    U = np.stack([np.full((N, 1), -0.1), np.full((N, 1), 0.1)], -1)
    return X, U, np.zeros((1, 0, 2))


def inclusion_1e5() -> dict:
    m = cm.models.load("cstr").model
    f = m.function
    args = _cstr_boxes(m, 100_000)
    nat = InclusionFunction(f, backend="native")
    num = InclusionFunction(f, backend="numpy")
    pts = f.map(100_000)
    xm = 0.5 * (args[0][..., 0] + args[0][..., 1])
    um = 0.5 * (args[1][..., 0] + args[1][..., 1])
    t_nat = median_time(lambda: nat(*args), 7)
    t_num = median_time(lambda: num(*args), 7)
    t_c = _unsound_c_time(f, args)
    t_pt = median_time(lambda: pts(xm.T, um.T, np.zeros((0, 100_000))), 7)
    out = {"native_boxes_per_s": 1e5 / t_nat, "numpy_boxes_per_s": 1e5 / t_num,
           "casadi_points_per_s": 1e5 / t_pt, "native_over_numpy": t_num / t_nat,
           "native_cost_over_casadi_point": t_nat / t_pt}
    if t_c is not None:  # the hardware's figure for this loop without outward rounding
        out.update({"c_unrounded_boxes_per_s": 1e5 / t_c,
                    "c_unrounded_over_numpy": t_num / t_c,
                    "native_cost_over_c_unrounded": t_nat / t_c})
    try:
        t_imm = _immrax_time(f, *args[:2])
    except ImportError:
        out["immrax"] = "not installed"
    else:
        out["immrax_boxes_per_s"] = 1e5 / t_imm
        out["native_over_immrax"] = t_imm / t_nat
    return out


def _unsound_c_time(f, args: tuple) -> float | None:
    """Median time of the native kernel's own C loop with the outward rounding taken out
    (every bound moved by nothing, no NaN bookkeeping; the same exp polynomial): what a
    fused C loop of this function does on this machine, the anchor of the issue's 8x. Not
    sound: a benchmark figure only."""
    import re

    from casadi_cmpc.interval import _native

    srcs: list[tuple] = []
    orig = _native.load_kernel

    def spy(src, size_in, size_out, wait=True):
        srcs.append((src, size_in, size_out))
        return orig(src, size_in, size_out, wait=wait)

    _native.load_kernel = spy
    try:
        InclusionFunction(f, backend="native")(*[a[:2] for a in args])
    finally:
        _native.load_kernel = orig
    if not srcs:
        return None
    src, size_in, size_out = srcs[-1]
    for name in ("civ_dn", "civ_up", "civ_dns", "civ_ups", "civ_dnf", "civ_upf"):
        src = re.sub(r"CIV_INLINE double " + name + r"\(double v\) \{.*?\n\}",
                     "CIV_INLINE double " + name + "(double v) { return v; }", src,
                     flags=re.S)
    src = re.sub(r"CIV_INLINE civ civ_make\(double lo, double hi\) \{.*?\n\}",
                 "CIV_INLINE civ civ_make(double lo, double hi) { civ r; r.lo = lo; "
                 "r.hi = hi; return r; }", src, flags=re.S)
    run = _native.load_kernel(src, size_in, size_out)
    if not run:
        return None
    boxes = list(args)
    return median_time(lambda: run(boxes, boxes[0].shape[0]), 7)


def _immrax_time(f, X: np.ndarray, U: np.ndarray) -> float:
    """Median time of immrax's natural inclusion (float64, jit-compiled, vmapped over the
    boxes) of the SX Function ``f(x, u)``, written as JAX operations by a walk of its
    instructions. immrax rounds to nearest: its enclosures are not sound."""
    import casadi as ca
    import immrax as irx
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    binary = {ca.OP_ADD: lambda a, b: a + b, ca.OP_SUB: lambda a, b: a - b,
              ca.OP_MUL: lambda a, b: a * b, ca.OP_DIV: lambda a, b: a / b}
    unary = {ca.OP_EXP: jnp.exp, ca.OP_NEG: lambda a: -a, ca.OP_SQ: lambda a: a * a,
             ca.OP_SIN: jnp.sin, ca.OP_COS: jnp.cos, ca.OP_ASSIGN: lambda a: a}
    prog = [(f.instruction_id(k), list(f.instruction_input(k)),
             list(f.instruction_output(k)), float(f.instruction_constant(k))
             if f.instruction_id(k) == ca.OP_CONST else 0.0)
            for k in range(f.n_instructions())]

    def g(x, u):
        ins, w, out = [x, u], {}, [None] * f.nnz_out(0)
        for op, i, o, c in prog:
            if op == ca.OP_CONST:
                w[o[0]] = c
            elif op == ca.OP_INPUT:
                w[o[0]] = ins[i[0]][i[1]]
            elif op == ca.OP_OUTPUT:
                out[o[1]] = w[i[0]]
            elif op in binary:
                w[o[0]] = binary[op](w[i[0]], w[i[1]])
            else:
                w[o[0]] = unary[op](w[i[0]])
        return out

    G = irx.natif(g)

    def one(xl, xh, ul, uh):
        return [(q.lower, q.upper) for q in G(irx.interval(xl, xh), irx.interval(ul, uh))]

    run = jax.jit(jax.vmap(one))
    a = [jnp.asarray(X[..., 0]), jnp.asarray(X[..., 1]), jnp.asarray(U[..., 0]),
         jnp.asarray(U[..., 1])]
    return median_time(lambda: jax.block_until_ready(run(*a)), 7)


def batch_300() -> dict:
    m = cm.models.load("cstr").model
    args = _cstr_boxes(m, 300, 1)
    res = {}
    for kind in ("natural", "centered"):
        nat = InclusionFunction(m.function, kind, backend="native")
        num = InclusionFunction(m.function, kind, backend="numpy")
        a, b = median_time(lambda f=nat: f(*args), 40), median_time(lambda f=num: f(*args), 40)
        res[kind] = {"native_us": a * 1e6, "numpy_us": b * 1e6, "numpy_over_native": b / a}
    return res


def call_n1() -> dict:
    m = cm.models.load("cannon").model
    X = np.array([[[0.1, 0.11], [0.2, 0.21]]])
    U = np.array([[[0.0, 0.1]]])
    auto = m.inclusion("natural")
    nat = InclusionFunction(m.function, backend="native")
    W = np.zeros((1, m.l, 2)) if m.l else np.zeros((1, 0, 2))
    n_in = m.function.n_in()
    args = (X, U, W)[:n_in]
    reps = 2000

    def per_call(fn) -> float:
        fn()
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        return (time.perf_counter() - t0) / reps

    return {"auto_us": per_call(lambda: auto(X, U)) * 1e6,
            "native_us": per_call(lambda: nat(*args)) * 1e6}


def one_step_3state() -> dict:
    import casadi as ca

    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * (u + 0.5 * ca.sin(x[0]) + 0.2 * x[2]),
                   0.7 * x[2] + 0.1 * x[0] ** 2 + 0.1 * x[1])
    m = cm.Model(x=x, u=u, f=f, X=cm.Box([-1] * 3, [1] * 3), U=cm.Box([-2], [2]))
    T = cm.Polytope.from_box(cm.Box([-0.4] * 3, [0.4] * 3))
    eps = 0.05
    # the state x control branch and bound (the default picks the affine-state method for
    # this model: x_1 and x_2 enter f linearly; it is reported beside)
    cm.one_step_set(m, T, eps, method="general", progress=False)  # kernels compiled
    t0 = time.perf_counter()
    K = cm.one_step_set(m, T, eps, method="general", progress=False)
    t_ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    Ka = cm.one_step_set(m, T, eps, progress=False)
    t_aff = time.perf_counter() - t0
    # the grid's kernel warmed like ours: the native backend from the first call (the
    # default backend would evaluate the first calls with numpy while the kernel compiles)
    F = InclusionFunction(m.function, "centered", backend="native")
    F(np.array([[[0.0, 0.1]] * 3]), np.array([[[0.0, 0.0]]]), np.zeros((1, 0, 2)))

    def grid(k: int) -> tuple[float, int, float]:
        """(seconds, transitions, certified volume) of the grid of k cells per axis."""
        edges = np.linspace(-1, 1, k + 1)
        lo = np.stack(np.meshgrid(edges[:-1], edges[:-1], edges[:-1], indexing="ij"),
                      -1).reshape(-1, 3)
        cells = np.stack([lo, lo + 2 / k], -1)
        t0 = time.perf_counter()
        ok = np.zeros(len(cells), dtype=bool)
        pairs = 0
        for uv in np.linspace(-2, 2, 17):
            todo = np.flatnonzero(~ok)
            Y = F(cells[todo], np.array([[[uv, uv]]]), np.zeros((1, 0, 2)))[0]
            pairs += todo.size
            ok[todo] |= ((Y[:, :, 0] >= -0.4) & (Y[:, :, 1] <= 0.4)).all(axis=1)
        return time.perf_counter() - t0, pairs, float(ok.sum() * (2 / k) ** 3)

    k = int(round(2 / eps))
    t_grid, pairs, v_grid = grid(k)
    # the grid refined until it certifies the search's volume (time to equal volume)
    k_eq = k
    t_eq, v_eq = t_grid, v_grid
    while v_eq < float(K.area()) and k_eq < 4 * k:
        k_eq += 4
        t_eq, _, v_eq = grid(k_eq)
    return {"ours_s": t_ours, "ours_pairs_per_s": K.n_pairs / t_ours,
            "ours_volume": float(K.area()), "affine_state_s": t_aff,
            "affine_state_volume": float(Ka.area()),
            "affine_state_method": Ka.pieces is not None, "grid_s": t_grid,
            "grid_pairs_per_s": pairs / t_grid, "grid_volume": v_grid,
            "pairs_per_s_ours_over_grid": (K.n_pairs / t_ours) / (pairs / t_grid),
            "ours_volume_over_grid": float(K.area()) / max(v_grid, 1e-300),
            "time_to_volume_grid_over_ours": t_grid / t_ours,
            "grid_eps_for_ours_volume": 2 / k_eq, "grid_volume_there": v_eq,
            "grid_s_for_ours_volume": t_eq,
            "time_to_equal_volume_grid_over_ours": t_eq / t_ours}


def e9_sequence() -> dict:
    ex = cm.models.load("cannon_robust")

    def run() -> tuple[float, object]:
        t0 = time.perf_counter()
        seq = cm.controllable_sets(ex.model, ex.terminal, 0.05, robust=True,
                                   law=ex.local_law, progress=False)
        return time.perf_counter() - t0, seq

    saved = InclusionFunction.native_after
    InclusionFunction.native_after = 10**12  # numpy (and scalar) only
    try:
        t_num, s_num = run()
    finally:
        InclusionFunction.native_after = saved
    t_auto, s_auto = run()
    same = len(s_num.steps) == len(s_auto.steps) and all(
        np.array_equal(a["boxes"], b["boxes"]) for a, b in zip(s_num.steps, s_auto.steps,
                                                                strict=True))
    return {"numpy_s": t_num, "default_s": t_auto, "speedup": t_num / t_auto,
            "identical_sets": bool(same), "steps": len(s_auto.steps)}


BASELINE = "bf2c92b"  # the last commit before the native backend and the fused classifier

_BASELINE_SCRIPT = r"""
import json, os, sys, time
import numpy as np
os.environ.setdefault("OMP_NUM_THREADS", "1")
# immrax (JAX) on one core as well, in float64
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false "
                      "intra_op_parallelism_threads=1")
sys.path.insert(0, sys.argv[1])
import importlib.util
import casadi_cmpc as cm
# the example models of the baseline tree (an editable install maps casadi_cmpc.models to
# the current tree's models/ otherwise)
_root = os.path.join(os.path.dirname(cm.__file__), os.pardir, "models")
_spec = importlib.util.spec_from_file_location(
    "casadi_cmpc.models", os.path.join(_root, "__init__.py"),
    submodule_search_locations=[_root])
cm.models = sys.modules["casadi_cmpc.models"] = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(cm.models)
from casadi_cmpc.interval import InclusionFunction
from _timing import median_time
m = cm.models.load("cstr").model
rng = np.random.default_rng(0)
c = rng.uniform(m.X.lo, m.X.hi, (100000, 2))
X = np.stack([c - 0.01, c + 0.01], -1)
U = np.stack([np.full((100000, 1), -0.1), np.full((100000, 1), 0.1)], -1)
num = InclusionFunction(m.function, backend="numpy")
t_num = median_time(lambda: num(X, U, np.zeros((1, 0, 2))), 7)
ex = cm.models.load("cannon_robust")
t0 = time.perf_counter()
cm.controllable_sets(ex.model, ex.terminal, 0.05, robust=True, law=ex.local_law,
                     progress=False)
print(json.dumps({"numpy_boxes_per_s": 1e5 / t_num, "e9_s": time.perf_counter() - t0}))
"""


def before_issue(res: dict) -> dict:
    """The baseline commit's figures, measured now in a child process (see the notes)."""
    root = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory() as tmp:
        wt = Path(tmp) / "baseline"
        r = subprocess.run(["git", "-C", str(root), "worktree", "add", "--detach", str(wt),
                            BASELINE], capture_output=True, text=True)
        if r.returncode != 0:
            return {"error": f"git worktree of {BASELINE}: {r.stderr.strip()[:200]}"}
        try:
            env = dict(os.environ, PYTHONPATH=str(wt), XDG_CACHE_HOME=str(Path(tmp) / "c"))
            p = subprocess.run([sys.executable, "-c", _BASELINE_SCRIPT,
                                str(Path(__file__).resolve().parent)], capture_output=True,
                               text=True, env=env, cwd=tmp, timeout=1800)
            if p.returncode != 0:
                return {"error": p.stderr.strip()[-400:]}
            base = json.loads(p.stdout.strip().splitlines()[-1])
        finally:
            subprocess.run(["git", "-C", str(root), "worktree", "remove", "--force", str(wt)],
                           capture_output=True)
    return {"commit": BASELINE, **base,
            "native_over_baseline_numpy": res["inclusion_1e5"]["native_boxes_per_s"]
            / base["numpy_boxes_per_s"],
            "e9_baseline_over_default": base["e9_s"] / res["e9_sequence"]["default_s"]}


def main() -> dict:
    if not native_available():
        return {"error": "no C compiler: the native backend is not available"}
    res = {"machine": platform.machine(), "cpus": os.cpu_count(),
           "inclusion_1e5": inclusion_1e5(), "batch_300": batch_300(), "call_n1": call_n1(),
           "one_step_3state": one_step_3state(), "e9_sequence": e9_sequence()}
    res["before_issue"] = before_issue(res)
    return res


if __name__ == "__main__":
    print(json.dumps(main()))
