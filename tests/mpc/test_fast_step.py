"""The per-step path of the controllers (CasADi Functions evaluated on preallocated arrays,
the interval checks on the native backend, the point look-up of a set sequence) gives the
same steps as the plain path: the same controls, costs and certificate labels."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.interval._native import native_available
from casadi_cmpc.interval.compiler import InclusionFunction
from casadi_cmpc.mpc._fastcall import BufferedCall
from casadi_cmpc.mpc._stepcheck import NativeAfter
from casadi_cmpc.mpc.contractive import ContractiveMPC
from casadi_cmpc.mpc.sequence import SetSequenceMPC


class _Plain:
    """An NLP solver called with keywords (the plain path): each call converts its arguments
    and results as ``solver(x0=..., p=...)`` does."""

    def __init__(self, fun: ca.Function) -> None:
        self.fun = fun

    def __call__(self, **kw):
        return self.fun(**kw)

    def stats(self) -> dict:
        return self.fun.stats()


@pytest.fixture(scope="module")
def cannon():
    return cm.models.load("cannon").model


def _closed_loop(model, ctrl, x0, steps):
    """(controls, labels, costs) of a closed loop on the nominal model."""
    x = np.asarray(x0, dtype=float)
    us, labels, costs = [], [], []
    for _ in range(steps):
        u = ctrl(x)
        r = ctrl.last_result
        us.append(u.copy())
        labels.append(r.certificate.label)
        costs.append(r.cost)
        x = model.step(x, u)
    return np.array(us), labels, np.array(costs)


# ------------------------------------------------------------------ BufferedCall
def test_buffered_call_gives_the_plain_call_values():
    x, u = ca.SX.sym("x", 3), ca.SX.sym("u", 2)
    f = ca.Function("f", [x, u], [ca.sin(x) * ca.sumsqr(u) + x[::-1], ca.exp(u) / x[0]])
    call = BufferedCall(f)
    rng = np.random.default_rng(0)
    for _ in range(5):
        xv, uv = rng.normal(size=3), rng.normal(size=2)
        call.args[0][:] = xv
        call.args[1][:] = uv
        call()
        for got, want in zip(call.res, f(xv, uv), strict=True):
            np.testing.assert_array_equal(got, np.asarray(want).ravel())


def test_buffered_call_binds_views_and_refuses_bad_arrays():
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [2 * x])
    z = np.zeros(4)
    call = BufferedCall(f, args={0: z[:2]}, res={0: z[2:]})
    z[:2] = [1.5, -2.0]
    call()
    np.testing.assert_array_equal(z, [1.5, -2.0, 3.0, -4.0])
    with pytest.raises(ValueError, match="contiguous float64 vector of 2"):
        BufferedCall(f, args={0: np.zeros(4)[::2]})
    with pytest.raises(ValueError, match="output 0"):
        BufferedCall(f, res={0: np.zeros(3)})


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
@pytest.mark.parametrize("plugin", ["ipopt", "sqpmethod"])
def test_a_sigint_during_a_buffered_solve_raises_keyboard_interrupt(plugin):
    """The interruption is raised (not lost, as in a plain call without ``solver_call``),
    and CasADi's warning about it is dropped.

    The SIGINT must land inside the solve (else the script prints "went on" and the test
    fails): with IPOPT n = 3000 (400 iterations); with sqpmethod n = 800, whose solve runs
    for seconds without the signal (about 10 s) while the interruption is seen within about
    a second (with n = 3000 it took about 30 s to be seen).
    """
    script = textwrap.dedent("""
        import os, signal, sys, threading
        import casadi as ca
        from casadi_cmpc._interrupt import solver_call
        from casadi_cmpc.mpc._fastcall import BufferedCall
        n = 3000 if sys.argv[1] == "ipopt" else 800
        x = ca.SX.sym("x", n)
        f = ca.sum1((x[1:] - x[:-1]**2)**2) + 1e-3 * ca.sum1((1 - x)**2)
        if sys.argv[1] == "ipopt":
            opts = {"ipopt.print_level": 0, "ipopt.max_iter": 400, "ipopt.tol": 1e-300,
                    "ipopt.acceptable_iter": 0,
                    "ipopt.hessian_approximation": "limited-memory"}
        else:
            opts = {"qpsol": "qrqp", "max_iter": 100000, "print_iteration": False,
                    "print_header": False, "print_status": False,
                    "hessian_approximation": "limited-memory",
                    "qpsol_options": {"print_iter": False, "print_header": False}}
        S = ca.nlpsol("S", sys.argv[1], {"x": x, "f": f}, {"print_time": False, **opts})
        call = BufferedCall(S, interruptible=True)
        call.args[S.index_in("x0")][:] = -1.2
        call.args[S.index_in("lbx")][:] = -float("inf")
        call.args[S.index_in("ubx")][:] = float("inf")
        threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT)).start()
        try:
            if sys.argv[2] == "guarded":
                with solver_call():
                    call()
            else:
                call()
        except KeyboardInterrupt:
            print("interrupted")
            sys.exit(0)
        print("went on")
    """)
    for mode in ("guarded", "plain"):
        out = subprocess.run([sys.executable, "-c", script, plugin, mode],
                             capture_output=True, text=True, timeout=300)
        assert out.stdout.strip().splitlines()[-1] == "interrupted", out.stderr[-2000:]
        assert "KeyboardInterrupt" not in out.stderr, out.stderr[-2000:]


def test_native_after_moves_to_its_own_native_copy():
    x = ca.SX.sym("x", 2)
    F = InclusionFunction(ca.Function("g", [x], [ca.vertcat(x[0] * x[1], ca.sin(x[0]))]))
    step = NativeAfter(F, after=3)
    box = np.array([[[0.3, 0.3], [-1.7, -1.7]]])
    want = np.array([0.3 * -1.7, np.sin(0.3)])
    for k in range(6):
        Y = step.evaluate_unchecked([box], 1)[0][0]
        assert ((Y[:, 0] <= want) & (want <= Y[:, 1])).all()
        assert (step._native is None) == (k < 3)
    assert step.calls == 3 and F.backend == "auto"  # the shared function is left alone
    if native_available():  # its copy wants the native kernel (compiled in the background)
        assert step._native._wants_native(1) and step._native is not F


# ------------------------------------------------------------------ ContractiveMPC
@pytest.mark.parametrize("kw", [
    {"solver": "sqp"}, {"solver": "ipopt"}, {"solver": "sqp", "norm": 1},
    {"solver": "sqp", "norm": np.inf, "shooting": "single"}])
def test_contractive_step_is_the_plain_step(cannon, kw):
    """Against a controller whose NLP solver is called with keywords and whose check runs
    on the shared (automatic) backend: identical controls, labels and costs."""
    fast = ContractiveMPC(cannon, 6, 0.8, mode="receding", **kw)
    ref = ContractiveMPC(cannon, 6, 0.8, mode="receding", **kw)
    h = ref._get(6)
    h.solver = _Plain(h.solver)
    h._step_check = NativeAfter(h.check_inclusion, after=10 ** 9)  # the shared evaluator
    got = _closed_loop(cannon, fast, [1.9, -1.5], 10)
    want = _closed_loop(cannon, ref, [1.9, -1.5], 10)
    np.testing.assert_array_equal(got[0], want[0])
    assert got[1] == want[1] and set(got[1]) == {"verified"}
    np.testing.assert_array_equal(got[2], want[2])
    # the cost is the float graph's value at the applied sequence
    r = fast.solve([0.7, -0.4])
    c, _ = fast._get(6).cost_pred(r.u_seq.ravel(), r.x)
    assert r.cost == float(c)


# reference values (casadi 3.8.2) of the plain per-step path: the first moves and costs of
# the closed loop of ContractiveMPC(cannon, 10, 0.9, solver="sqp", mode="receding") from
# (1.9, -1.5)
_E8_U = ["-0x1.39f7938e5ec83p-2", "-0x1.24ff5bc980d3ep-2", "-0x1.10314fe7a62bep-2",
         "-0x1.f7d4d4f089d4fp-3", "-0x1.d0d27a8c29c60p-3", "-0x1.abac8d768006ap-3",
         "-0x1.8893cc1e2f350p-3", "-0x1.67a15b6a8811bp-3", "-0x1.48dd23a81d570p-3",
         "-0x1.2c428db6e8bd1p-3", "-0x1.11c412f21de5bp-3", "-0x1.f29bde41b35e6p-4"]
_E8_COST = ["0x1.6f3ed5d2e291ep+4", "0x1.2b986ae97efddp+4", "0x1.e88b45ef1fbf9p+3",
            "0x1.8e1f1ddead661p+3", "0x1.4446a8cab9175p+3", "0x1.0801b84bfee26p+3",
            "0x1.adb1cb118debap+2", "0x1.5d8b6acbfc783p+2", "0x1.1c3d9b0ba1dfap+2",
            "0x1.ce1e30bf2ea7ap+1", "0x1.7789c9c20242cp+1", "0x1.31179e79fc28ep+1"]


@pytest.mark.skipif(ca.__version__ != "3.8.2", reason="values recorded with casadi 3.8.2")
def test_e8_closed_loop_matches_the_reference_values(cannon):
    ctrl = ContractiveMPC(cannon, 10, 0.9, solver="sqp", mode="receding")
    us, labels, costs = _closed_loop(cannon, ctrl, [1.9, -1.5], len(_E8_U))
    assert [float(u[0]).hex() for u in us] == _E8_U
    assert [float(c).hex() for c in costs] == _E8_COST
    assert labels == ["verified"] * len(_E8_U)


def test_replacing_the_solver_rebuilds_the_step_calls(cannon):
    ctrl = ContractiveMPC(cannon, 4, 0.9, solver="sqp", mode="receding")
    ctrl.solve([0.5, -0.3])
    h = ctrl._get(4)
    first = h.calls()
    h.solver = _Plain(h.solver)
    assert h.calls() is not first and h.calls().solve is None
    assert ctrl.solve([0.5, -0.3]).certificate.label == "verified"


def test_export_spec_problem_is_the_solved_problem(cannon):
    ctrl = ContractiveMPC(cannon, 5, 0.9, solver="sqp", mode="receding")
    spec = ctrl.export_spec()
    P = spec.problem
    assert spec.kind == "contractive" and spec.horizon == 5 and P.horizon == 5
    assert P.nlp is ctrl._get(5).nlp and P.check_fun is ctrl._get(5).check_fun
    assert P.plugin == "sqpmethod" and P.options["qpsol"] == "qrqp"
    u = np.linspace(-0.5, 0.5, 5)
    x = np.array([0.4, -0.2])
    xs = np.asarray(P.predict_states(u, x)).ravel()
    want = np.asarray(ctrl._get(5).pred_fun(u, x))[:, 1:].ravel(order="F")
    np.testing.assert_array_equal(xs, want)
    assert ContractiveMPC(cannon, None, 0.9).export_spec().problem is None


# ------------------------------------------------------------------ SetSequenceMPC
@pytest.fixture(scope="module")
def e9_short():
    """E9 with the first six robust controllable sets (a short sequence)."""
    ex = cm.models.load("cannon_robust")
    cfg = ex.info["sequence"]
    seq = cm.controllable_sets(ex.model, ex.terminal, cfg["eps"], robust=True,
                               law=ex.local_law, progress=False, max_steps=6)
    return ex, seq


def _e9_controller(e9_short, solver: str = "sqp") -> SetSequenceMPC:
    ex, seq = e9_short
    cfg = ex.info["sequence"]
    return SetSequenceMPC(ex.model, seq, Q=cfg["Q"], R=cfg["R"], local_law=ex.local_law,
                          solver=solver, robust=True)


def _reference(ctrl: SetSequenceMPC) -> SetSequenceMPC:
    """The plain path: ``seq.locate``, the shared inclusion functions, keyword calls of
    the NLP solver."""
    ctrl._locator = False
    ctrl._native_form = lambda F: F
    ctrl._nlp = _Plain(ctrl._nlp)
    return ctrl


@pytest.mark.parametrize("solver", ["sqp", "ipopt"])
def test_set_sequence_step_is_the_plain_step(e9_short, solver):
    ex, seq = e9_short
    fast, ref = _e9_controller(e9_short, solver), _reference(_e9_controller(e9_short, solver))
    B = np.concatenate([st["boxes"] for st in seq.steps])
    rng = np.random.default_rng(2)
    states = rng.uniform(B[:, :, 0], B[:, :, 1])[rng.choice(len(B), 40)]
    x0 = 0.5 * (seq.steps[-1]["boxes"][0, :, 0] + seq.steps[-1]["boxes"][0, :, 1])
    traj = cm.simulate(ex.model, fast, x0, steps=10, disturbance="uniform", seed=3,
                       progress=False)
    states = np.concatenate([states, traj.x])
    sources = set()
    for x in states:
        a, b = fast.solve(x), ref.solve(x)
        np.testing.assert_array_equal(a.u, b.u)
        assert a.certificate.label == b.certificate.label
        assert a.certificate.details == b.certificate.details
        assert a.horizon == b.horizon and a.stats["level"] == b.stats["level"]
        assert a.stats.get("return_status") == b.stats.get("return_status")
        np.testing.assert_array_equal(a.x_pred, b.x_pred)
        assert a.cost == b.cost
        sources.add(a.certificate.details.get("source"))
    assert "solver" in sources and {"verified", "local_law"} <= set(traj.certificate)


def test_point_look_up_is_seq_locate(e9_short):
    seq = e9_short[1]
    loc = _e9_controller(e9_short)._point_locator()
    assert loc is not False
    edges = seq._grid()[0]
    rng = np.random.default_rng(5)
    pts = [rng.uniform(-2.2, 2.2, 2) for _ in range(300)]
    # cell corners and faces (ties between levels), and the ends of the grid
    pts += [np.array([a, b]) for a in rng.choice(edges[0], 40) for b in rng.choice(edges[1], 3)]
    pts += [np.array([a, rng.uniform(edges[1][0], edges[1][-1])])
            for a in rng.choice(edges[0], 40)]
    pts += [np.array([edges[0][0], edges[1][-1]]), np.array([edges[0][-1], edges[1][0]]),
            np.array([np.nextafter(edges[0][0], -9), 0.0])]
    levels = set()
    for p in pts:
        lv, wit = loc.locate(p)
        want_lv, want_wit = seq.locate(p)
        assert lv == want_lv
        assert (wit is None) == (want_wit is None)
        if wit is not None:
            assert wit[0] == want_wit[0]
            np.testing.assert_array_equal(wit[1], want_wit[1])
        levels.add(lv)
    assert None in levels and 0 in levels and len(levels) >= 5


def test_export_spec_of_a_set_sequence(e9_short):
    seq = e9_short[1]
    spec = _e9_controller(e9_short).export_spec()
    assert spec.kind == "set_sequence" and spec.seq is seq and spec.robust
    assert spec.grid is seq._grid() and len(spec.members) == len(seq.sets)
    assert spec.plugin == "sqpmethod" and spec.rows == 0 and spec.nlp_rows == []
    u0, c = spec.start([1.0, -0.2], [0.3])
    assert np.asarray(c).size == spec.w_vertices.shape[0]
