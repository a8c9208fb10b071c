"""Ctrl-C during a compiled solver call (IPOPT) stops the run: CasADi clears the
KeyboardInterrupt it polls during a solve, ``solver_call`` raises it again afterwards, and
``cmpc run`` ends with one line and exit code 130."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.skipif(os.name != "posix", reason="POSIX signals")

_SCRIPT = textwrap.dedent("""
    import os, signal, sys, threading, time
    import casadi as ca
    from casadi_cmpc._interrupt import solver_call
    n = 3000
    x = ca.SX.sym("x", n)
    f = ca.sum1((x[1:] - x[:-1]**2)**2) + 1e-3 * ca.sum1((1 - x)**2)
    S = ca.nlpsol("S", "ipopt", {"x": x, "f": f}, {
        "ipopt.print_level": 0, "print_time": False, "ipopt.max_iter": 400,
        "ipopt.tol": 1e-300, "ipopt.acceptable_iter": 0,
        "ipopt.hessian_approximation": "limited-memory"})
    guarded = sys.argv[1] == "guarded"
    threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT)).start()
    t = time.perf_counter()
    try:
        if guarded:
            with solver_call():
                S(x0=[-1.2] * n)
        else:
            S(x0=[-1.2] * n)
    except KeyboardInterrupt:
        print("interrupted", S.stats()["return_status"])
        sys.exit(0)
    print("went on", S.stats()["return_status"])
""")


def _run(mode: str) -> str:
    out = subprocess.run([sys.executable, "-c", _SCRIPT, mode], capture_output=True,
                         text=True, timeout=300)
    return out.stdout.strip().splitlines()[-1]


def test_a_sigint_during_ipopt_raises_keyboard_interrupt():
    assert _run("guarded").startswith("interrupted")
    # without the guard CasADi stops the solve but the interrupt is lost: the run goes on
    assert _run("plain").startswith("went on")


def test_cmpc_run_interrupted_during_the_solver_exits_130_with_one_line():
    """SIGINT while `cmpc run` simulates a contractive MPC (IPOPT at every step)."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    p = subprocess.Popen([sys.executable, "-m", "casadi_cmpc", "run", "mirosot", "--steps",
                          "100000", "--no-progress"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.monotonic() + 120
    line = ""
    while "run 1" not in line and time.monotonic() < deadline:  # the simulation started
        line = p.stdout.readline()
    time.sleep(2.0)
    p.send_signal(signal.SIGINT)
    try:
        _, err = p.communicate(timeout=60)
    finally:
        p.kill()
    assert p.returncode == 130
    lines = [x for x in err.strip().splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("cmpc: interrupted"), err


def test_cmpc_run_interrupted_during_the_set_computation_then_run_again(tmp_path):
    """SIGINT while the controllable sets are computed: exit 130 with one line and no cache
    file; the next run computes the sequence, caches it and succeeds."""
    cache = tmp_path / "cache"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "casadi_cmpc", "run", "cstr", "--steps", "3",
           "--no-progress", "--cache", str(cache)]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=env)
    deadline = time.monotonic() + 120
    line = ""
    while "model" not in line.lower() and time.monotonic() < deadline:  # summary printed
        line = p.stdout.readline()
    time.sleep(1.5)  # the CSTR sequence takes several seconds: this lands inside it
    p.send_signal(signal.SIGINT)
    try:
        out, err = p.communicate(timeout=60)
    finally:
        p.kill()
    assert "sequence computed" not in out  # interrupted before the sequence was complete
    assert p.returncode == 130
    lines = [x for x in err.strip().splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("cmpc: interrupted"), err
    assert not cache.exists() or not any(cache.iterdir())
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert again.returncode == 0, again.stderr
    assert "sequence computed" in again.stdout and "violations: state 0, input 0" in again.stdout
    assert any(cache.iterdir())


def _interrupting_classify(after: int):
    """A classifier that labels everything undecided and is interrupted at call ``after``."""
    import numpy as np

    calls = []

    def classify(frontier):
        calls.append(len(frontier))
        if len(calls) == after:
            raise KeyboardInterrupt
        return np.zeros(len(frontier), dtype=np.int8)

    return classify, calls


def _frontier():
    import numpy as np

    from casadi_cmpc.solvers.engine import BoxFrontier

    return BoxFrontier(np.zeros((1, 2)), np.ones((1, 2)))


def test_an_outermost_search_returns_its_partial_result_on_ctrl_c():
    from casadi_cmpc.solvers.engine import Status, branch_and_bound

    classify, calls = _interrupting_classify(3)
    out = branch_and_bound(_frontier(), classify, 1e-6, progress=False)
    assert out.status == Status.BUDGET and out.message == "interrupted"
    assert len(calls) == 3 and out.levels == 2  # the two completed levels are kept


def test_a_nested_search_passes_ctrl_c_to_the_outermost_call():
    """A search inside a simulation (e.g. a controller's set inversion) must not turn Ctrl-C
    into its own "budget" answer that the controller would act on: the simulation stops."""
    import casadi as ca
    import numpy as np

    import casadi_cmpc as cm
    from casadi_cmpc.solvers.engine import branch_and_bound

    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=0.5 * x + ca.vertcat(u, 0), X=cm.Box([-1, -1], [1, 1]),
                     U=cm.Box([-1], [1]))
    answers = []

    def ctrl(xk):
        classify, _ = _interrupting_classify(2 if len(answers) == 3 else 10**9)
        out = branch_and_bound(_frontier(), classify, 0.25, progress=False)
        answers.append(out.message)
        return np.zeros(1)

    traj = cm.simulate(model, ctrl, [0.5, 0.5], 10, progress=False)
    assert traj.stop_reason == "interrupted" and traj.steps == 3
    assert "interrupted" not in answers  # no search answered "interrupted" to the controller
