"""The LP (3.5)-(3.6) of linear contractive MPC (casadi_cmpc/mpc/linear.py).

Every feasible answer is re-simulated here in exact rational arithmetic, independently of
the module's own check; every "infeasible" answer is compared with an independent proof
or with a feasible sequence known by construction.
"""

from __future__ import annotations

import dataclasses
import doctest
import itertools
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.mpc import linear as lin
from casadi_cmpc.mpc.linear import ContractiveLP, LPStep

F = Fraction


# ----------------------------------------------------------------- exact helpers
def fr(a):
    a = np.asarray(a, dtype=float)
    if a.ndim == 1:
        return [F(float(v)) for v in a]
    return [fr(r) for r in a]


def matvec(M, x):
    return [sum((a * v for a, v in zip(row, x, strict=True)), F(0)) for row in M]


def exact_gauge(kind, x, x_ref, P=None, p=None):
    """Exact gauge of ``x - x_ref`` (x, x_ref: lists of Fractions)."""
    d = [a - b for a, b in zip(x, x_ref, strict=True)]
    if kind == "l1":
        return sum((abs(v) for v in d), F(0))
    if kind == "linf":
        return max(abs(v) for v in d)
    Pf, pf = fr(P), fr(p)
    vals = [sum((a * v for a, v in zip(row, d, strict=True)), F(0))
            / (pi - sum((a * r for a, r in zip(row, x_ref, strict=True)), F(0)))
            for row, pi in zip(Pf, pf, strict=True)]
    return max(max(vals), F(0))


def gauge_spec(gauge):
    if isinstance(gauge, cm.Polytope):
        return "poly", np.asarray(gauge.A), np.asarray(gauge.b)
    return ("l1" if gauge == 1 else "linf"), None, None


def exact_trajectory(A, B, x0, u_seq):
    Af, Bf = fr(A), fr(B)
    xs = [fr(x0)]
    for u in np.asarray(u_seq, dtype=float):
        uf = fr(u)
        xs.append([a + b for a, b in zip(matvec(Af, xs[-1]), matvec(Bf, uf), strict=True)])
    return xs


def check_exactly(A, B, X, U, x0, u_seq, alpha, gauge, x_ref=None, terminal=None,
                  path=None):
    """Independent exact check of a returned sequence; returns a list of violations."""
    n = np.asarray(A).shape[0]
    x_ref = np.zeros(n) if x_ref is None else np.asarray(x_ref, dtype=float)
    xs = exact_trajectory(A, B, x0, u_seq)
    bad = []
    for i, u in enumerate(np.asarray(u_seq, dtype=float)):
        for j, v in enumerate(u):
            if not (F(float(U.lo[j])) <= F(float(v)) <= F(float(U.hi[j]))):
                bad.append(f"u({i})[{j}]")
        if path is not None:
            Gx, Gu, g = (np.asarray(t, dtype=float) for t in path)
            lhs = [a + b for a, b in zip(matvec(fr(Gx), xs[i]), matvec(fr(Gu), fr(u)),
                                         strict=True)]
            bad += [f"path {k} at {i}" for k, (a, b) in enumerate(zip(lhs, fr(g),
                                                                      strict=True)) if a > b]
    for i, x in enumerate(xs[1:], start=1):
        for j, v in enumerate(x):
            if not (F(float(X.lo[j])) <= v <= F(float(X.hi[j]))):
                bad.append(f"x({i})[{j}]")
    if terminal is not None:
        lhs = matvec(fr(terminal.A), xs[-1])
        bad += [f"terminal {k}" for k, (a, b) in enumerate(zip(lhs, fr(terminal.b),
                                                               strict=True)) if a > b]
    kind, P, p = gauge_spec(gauge)
    g0 = exact_gauge(kind, xs[0], fr(x_ref), P, p)
    gN = exact_gauge(kind, xs[-1], fr(x_ref), P, p)
    if not gN < F(float(alpha)) * g0:
        bad.append("contraction")
    return bad


def frac_up(v):
    f = float(v)
    return math.nextafter(f, math.inf) if F(f) < v else f


def frac_down(v):
    f = float(v)
    return math.nextafter(f, -math.inf) if F(f) > v else f


# ----------------------------------------------------------------------- E1
@pytest.fixture(scope="module")
def e1():
    ex = cm.models.load("linear_sliding")
    A, B = ex.info["A"], ex.info["B"]
    A2, B2, _, c = ex.model.linear_matrices()
    assert np.array_equal(A, A2) and np.array_equal(B, B2) and not c.any()
    return ex


def _gauges(ex):
    return {"hull": ex.info["terminal_hull"], "inf": np.inf, "l1": 1}


# smallest horizons: every shorter one is *proven* infeasible by the test below
E1_HORIZONS = {("hull", 0.9): (1, 1), ("hull", 0.2): (2, 2), ("inf", 0.9): (2, 2),
               ("inf", 0.2): (7, 7), ("l1", 0.9): (1, 1), ("l1", 0.2): (6, 6)}


@pytest.mark.parametrize("name,alpha", sorted(E1_HORIZONS))
def test_e1_horizon_search_and_exact_recheck(e1, name, alpha):
    A, B = e1.info["A"], e1.info["B"]
    X, U = e1.model.X, e1.model.U
    gauge = _gauges(e1)[name]
    found = []
    for x0 in e1.x0s:
        for N in range(1, 21):
            lp = ContractiveLP(A, B, X, U, N, alpha, gauge)
            step = lp.solve(x0)
            if step.status == "optimal":
                break
            assert step.status == "infeasible", step.message
            assert lp.check_proof(x0, step.proof)
        assert step.success and step.verified, step.message
        assert step.u_seq.shape == (N, 1) and step.x_pred.shape == (N + 1, 2)
        assert check_exactly(A, B, X, U, x0, step.u_seq, alpha, gauge) == []
        found.append(N)
    assert tuple(found) == E1_HORIZONS[(name, alpha)]


def test_e1_closed_loop_reaches_hull_then_origin(e1):
    """Receding horizon, alpha = 0.9, hull gauge; first control of each LP applied."""
    A, B = e1.info["A"], e1.info["B"]
    X, U = e1.model.X, e1.model.U
    hull = e1.info["terminal_hull"]
    lps = {}
    for x0 in e1.x0s:
        x = np.array(x0, dtype=float)
        entered = None
        gam = []
        for k in range(60):
            for N in range(1, 11):
                lp = lps.setdefault(N, ContractiveLP(A, B, X, U, N, 0.9, hull))
                step = lp.solve(x)
                if step.success:
                    break
            assert step.success, step.message
            u = step.u_seq[0]
            assert U.lo[0] <= u[0] <= U.hi[0]
            x = A @ x + B @ u
            assert np.all(np.abs(x) <= 8.0)
            gam.append(lp.gauge_value(x))
            if entered is None and hull.contains(x):
                entered = k + 1
        assert entered is not None and entered <= 10
        after = np.array(gam[entered - 1:])
        assert np.all(after <= 1.0)  # stays in the hull
        assert np.all(np.diff(after) < 0)  # and its gauge keeps contracting
        assert np.abs(x).max() < 1e-3


def test_e1_dual_mode_sliding_law(e1):
    """LP until x is in the sliding domain S, then the linear law equal to u_eq on S."""
    A, B = e1.info["A"], e1.info["B"]
    X, U = e1.model.X, e1.model.U
    S, K = e1.terminal, e1.info["local_gain"]
    lps = {}
    for x0 in e1.x0s:
        x = np.array(x0, dtype=float)
        switched = None
        for k in range(80):
            if switched is None and S.contains(x):
                switched = k
            if switched is None:
                for N in range(1, 11):
                    lp = lps.setdefault(N, ContractiveLP(A, B, X, U, N, 0.5, np.inf))
                    step = lp.solve(x)
                    if step.success:
                        break
                assert step.success, step.message
                u = step.u_seq[0]
            else:
                u = K @ x
                assert S.contains(x, tol=1e-12)
            assert U.lo[0] <= u[0] <= U.hi[0]
            x = A @ x + B @ u
        assert switched is not None and switched <= 12
        assert np.abs(x).max() < 1e-6


# ------------------------------------------------------------------ infeasible
def _independent_proof(A, B, umax, x0, N, alpha, kind, cs):
    """Exact: some c gives c.x(N) > alpha gamma(x0) * dual_norm(c) for every admissible u."""
    Af, Bf = fr(A), fr(B)
    x = fr(x0)
    g0 = exact_gauge(kind, x, [F(0)] * len(x))
    for c in cs:
        cf = fr(c)
        dual = sum((abs(v) for v in cf), F(0)) if kind == "linf" else max(abs(v) for v in cf)
        xN = x
        for _ in range(N):
            xN = matvec(Af, xN)
        lower = sum((a * v for a, v in zip(cf, xN, strict=True)), F(0))
        # subtract the largest effect of the controls: sum_k |c A^k B| umax
        row = cf
        for _ in range(N):
            cB = [sum((row[q] * Bf[q][j] for q in range(len(row))), F(0))
                  for j in range(len(Bf[0]))]
            lower -= sum((abs(v) * F(float(w)) for v, w in zip(cB, umax, strict=True)), F(0))
            row = [sum((row[q] * Af[q][j] for q in range(len(row))), F(0))
                   for j in range(len(row))]
        if lower > F(float(alpha)) * g0 * dual:
            return True
    return False


def _sign_vectors(n):
    return [np.array(s, dtype=float) for s in itertools.product([-1.0, 1.0], repeat=n)]


def _units(n):
    return [s * np.eye(n)[j] for j in range(n) for s in (1.0, -1.0)]


@pytest.mark.parametrize("case", ["e1_small_U", "unstable_3", "unstable_4"])
def test_infeasible_with_exact_certificate(e1, case):
    if case == "e1_small_U":
        A, B = e1.info["A"], e1.info["B"]
        X, U, umax = e1.model.X, cm.Box([-0.05], [0.05]), [0.05]
        x0, alpha, gauge, kind, Ns = np.array([6.8, 7.2]), 0.5, np.inf, "linf", range(1, 5)
    elif case == "unstable_3":
        A = np.array([[1.2, 0.1, 0.0], [0.0, 1.1, 0.2], [0.0, 0.0, 0.9]])
        B = np.array([[0.0], [0.0], [1.0]])
        X, U, umax = cm.Box([-50] * 3, [50] * 3), cm.Box([-0.1], [0.1]), [0.1]
        x0, alpha, gauge, kind, Ns = np.array([1.0, 1.0, 0.0]), 0.9, np.inf, "linf", \
            range(1, 9)
    else:
        A = np.array([[1.1, 0.2, 0, 0], [0, 1.05, 0.1, 0], [0, 0, 0.8, 0.3], [0, 0, 0, 0.7]])
        B = np.array([[0, 0], [0.05, 0], [0, 1.0], [0, 0.5]])
        X, U, umax = cm.Box([-50] * 4, [50] * 4), cm.Box([-0.2, -0.2], [0.2, 0.2]), [0.2, 0.2]
        x0, alpha, gauge, kind, Ns = np.array([1.0, 1.0, 0.0, 0.0]), 0.9, 1, "l1", range(1, 9)
    n = A.shape[0]
    cs = _units(n) if kind == "linf" else _sign_vectors(n)
    for N in Ns:
        assert _independent_proof(A, B, umax, x0, N, alpha, kind, cs)  # truly infeasible
        lp = ContractiveLP(A, B, X, U, N, alpha, gauge)
        step = lp.solve(x0)
        assert step.status == "infeasible", step.message
        assert not step.success and step.u_seq is None and step.x_pred is None
        pr = step.proof
        assert pr["kind"] == "farkas" and pr["margin"] > 0
        assert "contraction xi <= alpha*gamma(x0)" in pr["rows"]
        assert pr["xi_bound"] >= alpha * lp.gauge_value(x0)
        assert "non-strict" in pr["statement"]
        assert lp.check_proof(x0, pr)
        assert pr["y"].shape == (2 * N * n + lp._n_gen + 1,)
        assert pr["lam"].shape == (N * n,)


def test_certificate_check_is_not_vacuous(e1):
    A, B = e1.info["A"], e1.info["B"]
    X, U = e1.model.X, cm.Box([-0.05], [0.05])
    x0 = np.array([6.8, 7.2])
    lp = ContractiveLP(A, B, X, U, 2, 0.5, np.inf)
    step = lp.solve(x0)
    assert step.status == "infeasible"
    y = step.proof["y_exact"]
    assert lp.check_proof(x0, {"y_exact": {k: 3 * v for k, v in y.items()}})  # scaling
    assert not lp.check_proof(x0, {"y_exact": {}})
    assert not lp.check_proof(x0, {"y_exact": {k: -v for k, v in y.items()}})
    dropped = dict(y)
    del dropped[max(dropped, key=dropped.get)]
    assert not lp.check_proof(x0, {"y_exact": dropped})
    assert not lp.check_proof(x0, {"y_exact": {0: F(1)}})  # one X row alone proves nothing
    # the same multipliers do not prove anything for a state that is feasible
    x_ok = np.array([0.0, 0.01])
    assert lp.solve(x_ok).status == "optimal"
    assert not lp.check_proof(x_ok, step.proof)
    with pytest.raises(cm.DimensionError):
        lp.check_proof(x0, {"y_exact": {10**6: F(1)}})


def test_terminal_and_path_constraints(e1):
    A, B = e1.info["A"], e1.info["B"]
    X, U = e1.model.X, e1.model.U
    hull = e1.info["terminal_hull"]
    path = (np.array([[0.0, 0.3], [0.0, -0.3]]), np.array([[1.0], [-1.0]]),
            np.array([2.5, 2.5]))  # |0.3 x2 + u| <= 2.5
    for x0 in e1.x0s:
        for N in range(1, 15):
            lp = ContractiveLP(A, B, X, U, N, 1.0, np.inf, terminal=hull, path=path)
            step = lp.solve(x0)
            if step.status == "optimal":
                break
            assert step.status == "infeasible", step.message
            assert any(r.startswith("terminal") or r.startswith("path")
                       or r.startswith("x(") for r in step.proof["rows"])
        assert step.verified and N == 4
        assert hull.contains(step.x_pred[-1])
        assert check_exactly(A, B, X, U, x0, step.u_seq, 1.0, np.inf, terminal=hull,
                             path=path) == []


def test_backoff_moves_active_constraints_inward():
    # integrator, terminal x >= 1 active at the optimum of min |x(2)|
    A, B = np.array([[1.0]]), np.array([[1.0]])
    X, U = cm.Box([-5.0], [5.0]), cm.Box([-1.0], [1.0])
    T = cm.Polytope([[-1.0]], [-1.0])
    step = ContractiveLP(A, B, X, U, 2, 1.0, np.inf, terminal=T, backoff=1e-6).solve([3.0])
    assert step.success
    xN = exact_trajectory(A, B, [3.0], step.u_seq)[-1][0]
    # the LP keeps x(N) at least backoff * (range of the row over X) = 4e-6 inside
    assert F(1) + F(39, 10**7) < xN < F(1) + F(1, 10**4)
    assert step.xi == pytest.approx(1.0 + 4e-6, abs=1e-9)


def test_nonzero_equilibrium_converges(e1):
    A, B = e1.info["A"], e1.info["B"]
    X, U = e1.model.X, e1.model.U
    u_ref = np.array([0.5])
    x_ref = np.linalg.solve(np.eye(2) - A, B @ u_ref)
    lps = {}
    for x0 in e1.x0s:
        x = np.array(x0, dtype=float)
        for _ in range(40):
            if np.array_equal(x, x_ref):
                break  # reached in floating point (then u_ref is kept, see below)
            for N in range(1, 11):
                lp = lps.setdefault(N, ContractiveLP(A, B, X, U, N, 0.8, np.inf,
                                                     x_ref=x_ref, u_ref=u_ref))
                step = lp.solve(x)
                if step.success:
                    break
            assert step.success, step.message
            assert check_exactly(A, B, X, U, x, step.u_seq, 0.8, np.inf, x_ref=x_ref) == []
            x = A @ x + B @ step.u_seq[0]
        assert np.abs(x - x_ref).max() < 1e-6
        assert np.abs(x).max() > 0.3  # not the origin
    # at x_ref itself u_ref is returned; it is verified only for an exact equilibrium
    step = lps[1].solve(x_ref)
    assert step.status == "optimal" and np.array_equal(step.u_seq, [u_ref])
    residual = exact_trajectory(A, B, x_ref, [u_ref])[1]
    assert step.verified == (residual == fr(x_ref))


def test_x0_at_equilibrium_keeps_u_ref():
    A, B = np.array([[0.5, 1.0], [0.0, 2.0]]), np.array([[0.0], [1.0]])
    lp = ContractiveLP(A, B, cm.Box([-1, -1], [1, 1]), cm.Box([-1], [1]), 3, 0.5, np.inf)
    step = lp.solve([0.0, 0.0])
    assert step.success and step.xi == 0.0
    assert np.array_equal(step.u_seq, np.zeros((3, 1)))
    assert np.array_equal(step.x_pred, np.zeros((4, 2)))


def test_step_fields(e1):
    A, B = e1.info["A"], e1.info["B"]
    hull = e1.info["terminal_hull"]
    lp = ContractiveLP(A, B, e1.model.X, e1.model.U, 3, 0.5, hull)
    step = lp.solve(e1.x0s[0])
    assert isinstance(step, LPStep) and step.status == "optimal" and step.verified
    assert step.elapsed > 0 and step.xi <= step.xi_bound
    assert step.xi_bound == pytest.approx(0.5 * lp.gauge_value(e1.x0s[0]))
    assert step.xi == pytest.approx(lp.gauge_value(step.x_pred[-1]), abs=1e-8)
    sim = lp._simulate(np.asarray(e1.x0s[0]), step.u_seq)
    assert np.array_equal(sim, step.x_pred)
    with pytest.raises(dataclasses.FrozenInstanceError):
        step.status = "failed"


def test_exact_recheck_rejects_a_violating_sequence(e1):
    A, B = e1.info["A"], e1.info["B"]
    lp = ContractiveLP(A, B, e1.model.X, e1.model.U, 2, 0.5, np.inf)
    x0 = np.array([6.8, 7.2])
    ok, why = lp._verify(x0, np.array([[2.0], [2.0]]))  # |x1(2)| = 6.16 > 0.5 * 7.2
    assert not ok and "contraction" in why
    small = ContractiveLP(A, B, cm.Box([-1, -1], [1, 1]), e1.model.U, 2, 0.5, np.inf)
    ok, why = small._verify(np.array([0.5, 0.5]), np.array([[2.0], [0.0]]))
    assert not ok and "x(1) outside X" in why  # x2(1) = 1.85
    ok, why = lp._verify(x0, np.array([[2.5], [0.0]]))
    assert not ok and "U" in why


# ------------------------------------------------------------------ hypothesis
def _draw_matrix(data, rows, cols, lim):
    vals = data.draw(st.lists(st.floats(-lim, lim, allow_nan=False, width=32),
                              min_size=rows * cols, max_size=rows * cols))
    return np.array(vals, dtype=float).reshape(rows, cols)


def _draw_gauge(data, n):
    kind = data.draw(st.sampled_from(["l1", "linf", "poly"]))
    if kind == "l1":
        return 1
    if kind == "linf":
        return np.inf
    w = np.array(data.draw(st.lists(st.floats(0.25, 4.0), min_size=2 * n, max_size=2 * n)))
    extra = _draw_matrix(data, data.draw(st.integers(0, 3)), n, 2.0)
    P = np.vstack([np.eye(n), -np.eye(n), extra])
    p = np.concatenate([w, np.full(extra.shape[0], 1.0)])
    return cm.Polytope(P, p)


@settings(max_examples=80)
@given(st.data())
def test_never_infeasible_when_a_feasible_sequence_is_known(data):
    n = data.draw(st.integers(1, 4))
    m = data.draw(st.integers(1, 2))
    N = data.draw(st.integers(1, 5))
    A = _draw_matrix(data, n, n, 1.5)
    rho = max(abs(np.linalg.eigvals(A)).max(), 1e-3)
    A = A * (data.draw(st.floats(0.1, 1.3)) / rho)
    B = _draw_matrix(data, n, m, 1.0)
    ulo = np.array(data.draw(st.lists(st.floats(-2.0, 0.0), min_size=m, max_size=m)))
    uhi = np.array(data.draw(st.lists(st.floats(0.0, 2.0), min_size=m, max_size=m)))
    U = cm.Box(ulo, uhi)
    u_seq = np.array([[data.draw(st.floats(ulo[j], uhi[j])) for j in range(m)]
                      for _ in range(N)])
    x0 = _draw_matrix(data, 1, n, 5.0)[0]
    gauge = _draw_gauge(data, n)
    kind, P, p = gauge_spec(gauge)
    xs = exact_trajectory(A, B, x0, u_seq)
    zero = [F(0)] * n
    g0, gN = exact_gauge(kind, xs[0], zero, P, p), exact_gauge(kind, xs[-1], zero, P, p)
    assume(g0 > 0 and gN <= g0)
    slack = data.draw(st.sampled_from([0.0, 1e-3, 0.3]))
    alpha = max(min(frac_up(gN / g0 * F(1 + slack)), 1.0), 1e-3)
    lo = [frac_down(min([F(0)] + [x[j] for x in xs[1:]])) for j in range(n)]
    hi = [frac_up(max([F(0)] + [x[j] for x in xs[1:]])) for j in range(n)]
    wid = np.array(hi) - np.array(lo)
    X = cm.Box(np.array(lo) - slack * (wid + 1), np.array(hi) + slack * (wid + 1))
    terminal = path = None
    if data.draw(st.booleans()):
        t_lo = np.array([frac_down(v) for v in xs[-1]]) - slack
        t_hi = np.array([frac_up(v) for v in xs[-1]]) + slack
        terminal = cm.Polytope.from_box(cm.Box(t_lo, t_hi))
    if data.draw(st.booleans()):
        Gx, Gu = _draw_matrix(data, 1, n, 1.0), _draw_matrix(data, 1, m, 1.0)
        vals = [sum((a * v for a, v in zip(fr(Gx[0]), xs[i], strict=True)), F(0))
                + sum((a * v for a, v in zip(fr(Gu[0]), fr(u_seq[i]), strict=True)), F(0))
                for i in range(N)]
        path = (Gx, Gu, np.array([frac_up(max(vals)) + slack]))
    lp = ContractiveLP(A, B, X, U, N, alpha, gauge, terminal=terminal, path=path)
    step = lp.solve(x0)
    assert step.status != "infeasible", step.proof
    generous = slack == 0.3 and gN / g0 * F(13, 10) <= 1
    if generous:
        assert step.success, step.message
    if step.status == "optimal" and step.verified:
        assert check_exactly(A, B, X, U, x0, step.u_seq, alpha, gauge, terminal=terminal,
                             path=path) == []


def _pieces(kind, a, b, P):
    """gamma(a + b u) = max_k (c_k + d_k u): the affine pieces (l1: all sign vectors)."""
    if kind == "linf":
        return [(s * a[j], s * b[j]) for j in range(a.size) for s in (1.0, -1.0)]
    if kind == "l1":
        return [(float(np.dot(s, a)), float(np.dot(s, b)))
                for s in itertools.product([-1.0, 1.0], repeat=a.size)]
    return [(float(P[k] @ a), float(P[k] @ b)) for k in range(P.shape[0])]


@settings(max_examples=80)
@given(st.data())
def test_lp_optimum_matches_brute_force_for_one_step(data):
    n = data.draw(st.integers(2, 3))
    A = _draw_matrix(data, n, n, 1.5)
    B = _draw_matrix(data, n, 1, 1.5)
    assume(np.abs(B).max() > 1e-3)
    x0 = _draw_matrix(data, 1, n, 3.0)[0]
    assume(np.abs(x0).max() > 1e-3)
    lo, hi = -data.draw(st.floats(0.05, 2.0)), data.draw(st.floats(0.05, 2.0))
    alpha = data.draw(st.floats(0.05, 1.0))
    gauge = _draw_gauge(data, n)
    kind, P, p = gauge_spec(gauge)
    Pn = None if P is None else P / p[:, None]
    lp = ContractiveLP(A, B, cm.Box([-1e3] * n, [1e3] * n), cm.Box([lo], [hi]), 1, alpha,
                       gauge)
    step = lp.solve(x0)
    a, b = A @ x0, B[:, 0]
    pieces = _pieces(kind, a, b, Pn)
    cand = [lo, hi] + list(np.linspace(lo, hi, 2001))
    for (c1, d1), (c2, d2) in itertools.combinations(pieces, 2):
        if d1 != d2:
            u = (c2 - c1) / (d1 - d2)
            if lo <= u <= hi:
                cand.append(u)
    best = min(max(c + d * u for c, d in pieces) for u in cand)
    best = max(best, 0.0)
    bound = alpha * lp.gauge_value(x0)
    scale = 1.0 + bound
    if best < bound - 1e-7 * scale:
        assert step.status == "optimal", step.message
    if best > bound + 1e-7 * scale:
        assert step.status != "optimal"
    if step.status == "optimal":
        assert step.xi == pytest.approx(best, abs=1e-7 * scale)
        if step.verified:
            assert check_exactly(A, B, cm.Box([-1e3] * n, [1e3] * n), cm.Box([lo], [hi]),
                                 x0, step.u_seq, alpha, gauge) == []
    if step.status == "infeasible":
        assert best > bound - 1e-9 * scale


# ------------------------------------------------------------------ bad input
def test_bad_inputs_are_refused(e1):
    A, B = e1.info["A"], e1.info["B"]
    X, U = e1.model.X, e1.model.U
    hull = e1.info["terminal_hull"]

    def make(**kw):
        args = {"A": A, "B": B, "X": X, "U": U, "horizon": 3, "alpha": 0.9, "gauge": np.inf}
        args.update(kw)
        return ContractiveLP(**args)

    for alpha in (0.0, -0.1, 1.5, math.nan, math.inf):
        with pytest.raises(ValueError, match="alpha"):
            make(alpha=alpha)
    with pytest.raises(TypeError, match="alpha"):
        make(alpha="0.5")
    for N in (0, -2):
        with pytest.raises(ValueError, match="horizon"):
            make(horizon=N)
    for N in (1.5, True, "3"):
        with pytest.raises(TypeError, match="horizon"):
            make(horizon=N)
    with pytest.raises(ValueError, match="square"):
        make(A=np.ones((2, 3)))
    with pytest.raises(ValueError, match="B has the wrong number of rows"):
        make(B=np.ones((3, 1)))
    with pytest.raises(ValueError, match="B must be a 2-D"):
        make(B=np.ones(2))
    with pytest.raises(ValueError, match="X has the wrong dimension"):
        make(X=cm.Box([-1, -1, -1], [1, 1, 1]))
    with pytest.raises(ValueError, match="U has the wrong dimension"):
        make(U=cm.Box([-1, -1], [1, 1]))
    with pytest.raises(TypeError, match="Box"):
        make(X=[[-8, 8], [-8, 8]])
    with pytest.raises(ValueError, match="bounded"):
        make(X=cm.Box([-np.inf, -8], [8, 8]))
    with pytest.raises(ValueError, match="NaN"):
        make(A=np.array([[np.nan, 0], [0, 1]]))
    with pytest.raises(ValueError, match="not an equilibrium") as exc:
        make(x_ref=[1.0, 1.0], u_ref=[0.0])
    assert "A x_ref + B u_ref - x_ref" in str(exc.value)
    with pytest.raises(ValueError, match="x_ref must have shape"):
        make(x_ref=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="strictly inside"):
        make(gauge=cm.Polytope([[1, 0], [-1, 0], [0, 1], [0, -1]], [1, 0, 1, 1]))
    with pytest.raises(ValueError, match="strictly inside"):
        make(gauge=hull.translate([5.0, 5.0]))
    with pytest.raises(ValueError, match="bounded"):
        make(gauge=cm.Polytope([[1, 0], [-1, 0], [0, 1]], [1, 1, 1]))
    with pytest.raises(ValueError, match="dimension"):
        make(gauge=cm.Polytope([[1.0], [-1.0]], [1, 1]))
    for g in (2, 0, "inf", True, None):
        with pytest.raises(ValueError, match="gauge"):
            make(gauge=g)
    with pytest.raises(ValueError, match="terminal set is empty"):
        make(terminal=cm.Polytope([[0.0, 0.0]], [-1.0]))
    with pytest.raises(ValueError, match="path Gu"):
        make(path=(np.ones((2, 2)), np.ones((3, 1)), np.ones(2)))
    with pytest.raises(ValueError, match="backoff"):
        make(backoff=-1e-9)
    lp = make()
    with pytest.raises(ValueError, match="x0 must have shape"):
        lp.solve([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="x0 contains NaN"):
        lp.solve([np.nan, 0.0])


def test_docstring_examples():
    result = doctest.testmod(lin, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0
