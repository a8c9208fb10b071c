"""``pre_set`` is a proven inner approximation: every vertex of the returned polytope,
taken exactly, is one-step controllable to the target, checked in rational arithmetic.

The check is independent of the implementation: the exact vertices of the returned float
polytope are recovered from its float vertices (their tight rows solved in Fractions) and,
at each, the input set ``{u in U : H (A v + B u + E w + c) <= h for every vertex w of W}``
is shown non-empty by an exact vertex (a rational solution of m of its rows that satisfies
all of them), found first among the rows tight at an LP solution, else by enumeration of
all m-subsets (complete: a non-empty bounded polyhedron has a vertex).
"""

from __future__ import annotations

import itertools
from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

import casadi_cmpc as cm

F0 = Fraction(0)


# ----------------------------------------------------------------------- exact helpers
def _fr(v: float) -> Fraction:
    return Fraction(float(v))


def _solve(M: list[list[Fraction]], r: list[Fraction]) -> list[Fraction] | None:
    """Unique solution of the square system ``M y = r`` (None when singular)."""
    k = len(M)
    T = [list(M[i]) + [r[i]] for i in range(k)]
    for col in range(k):
        piv = next((i for i in range(col, k) if T[i][col] != 0), None)
        if piv is None:
            return None
        T[col], T[piv] = T[piv], T[col]
        pv = T[col][col]
        T[col] = [x / pv for x in T[col]]
        for i in range(k):
            if i != col and T[i][col] != 0:
                f = T[i][col]
                T[i] = [a - f * b for a, b in zip(T[i], T[col], strict=True)]
    return [T[i][k] for i in range(k)]


def _exact_vertices(K: cm.Polytope, limit: int | None = None
                    ) -> tuple[list[list[Fraction]], int]:
    """Exact vertices of the float polytope ``{x : K.A x <= K.b}`` (rows taken exactly)
    near its float vertices (n of the rows nearest to each solved exactly, the first
    solution inside kept; at most ``limit`` float vertices, evenly spread over the list),
    and how many float vertices gave none."""
    A = [[_fr(v) for v in row] for row in K.A]
    b = [_fr(v) for v in K.b]
    An = np.asarray(K.A) / np.linalg.norm(K.A, axis=1)[:, None]
    bn = np.asarray(K.b) / np.linalg.norm(K.A, axis=1)
    n = K.dim
    out, skipped = [], 0
    V = K.vertices()
    if limit is not None and V.shape[0] > limit:
        V = V[np.linspace(0, V.shape[0] - 1, limit).astype(int)]
    for v in V:
        near = [int(i) for i in np.argsort(np.abs(An @ v - bn))[:n + 4]]
        for rows in itertools.combinations(near, n):
            x = _solve([A[i] for i in rows], [b[i] for i in rows])
            if x is not None and all(
                    sum((a * xi for a, xi in zip(A[i], x, strict=True)), F0) <= b[i]
                    for i in range(len(b))):
                out.append(x)
                break
        else:
            skipped += 1
    return out, skipped


def _input_rows(model: cm.Model, T: cm.Polytope, x: list[Fraction]
                ) -> tuple[list[list[Fraction]], list[Fraction]]:
    """Exact rows ``G u <= g`` of the admissible inputs at the state x: every vertex of W
    (the tightest per target row), and the box U."""
    A, B, E, c = model.linear_matrices()
    n, m = model.n, model.m
    Af = [[_fr(v) for v in row] for row in A]
    Bf = [[_fr(v) for v in row] for row in B.reshape(n, m)]
    cf = [_fr(v) for v in c]
    if model.l:
        W = model.W
        wv = [[_fr(v) for v in w] for w in itertools.product(*zip(W.lo, W.hi, strict=True))]
        Ef = [[_fr(v) for v in row] for row in E.reshape(n, model.l)]
    else:
        wv, Ef = [[]], [[] for _ in range(n)]
    y0 = [sum((Af[i][j] * x[j] for j in range(n)), F0) + cf[i] for i in range(n)]
    G, g = [], []
    for Hrow, hval in zip(T.A, T.b, strict=True):
        H = [_fr(v) for v in Hrow]
        worst = None
        for w in wv:
            y = [y0[i] + sum((Ef[i][j] * w[j] for j in range(len(w))), F0) for i in range(n)]
            val = _fr(hval) - sum((H[i] * y[i] for i in range(n)), F0)
            worst = val if worst is None else min(worst, val)
        G.append([sum((H[i] * Bf[i][j] for i in range(n)), F0) for j in range(m)])
        g.append(worst)
    for j in range(m):
        e = [F0] * m
        e[j] = Fraction(1)
        G.append(e)
        g.append(_fr(model.U.hi[j]))
        G.append([-v for v in e])
        g.append(-_fr(model.U.lo[j]))
    return G, g


def _feasible_at(G, g, u: list[Fraction]) -> bool:
    return all(sum((a * b for a, b in zip(row, u, strict=True)), F0) <= gi
               for row, gi in zip(G, g, strict=True))


def _controllable_exact(model: cm.Model, T: cm.Polytope, x: list[Fraction]) -> bool:
    """Exact: is there u in U with the successor in T for every w in W?"""
    G, g = _input_rows(model, T, x)
    m = model.m
    if m == 0:
        return all(gi >= 0 for gi in g)
    Gf = np.array([[float(v) for v in row] for row in G])
    gf = np.array([float(v) for v in g])
    subsets: list[tuple[int, ...]] = []
    for cost in (np.zeros(m), np.ones(m), -np.ones(m)):
        res = linprog(cost, A_ub=Gf, b_ub=gf, bounds=[(None, None)] * m, method="highs")
        if res.status != 0:
            continue
        u = [_fr(v) for v in res.x]
        if _feasible_at(G, g, u):
            return True
        scale = np.abs(Gf) @ np.abs(res.x) + np.abs(gf) + 1e-300
        near = np.argsort(np.abs(Gf @ res.x - gf) / scale)[:8]
        subsets += list(itertools.combinations(sorted(int(i) for i in near), m))
    seen = set()
    for S in itertools.chain(subsets, itertools.combinations(range(len(G)), m)):
        if S in seen:
            continue
        seen.add(S)
        u = _solve([G[i] for i in S], [g[i] for i in S])
        if u is not None and _feasible_at(G, g, u):
            return True
    return False


# ------------------------------------------------------------------------- models
def _model(A, B, c, X, U, E=None, W=None) -> cm.Model:
    n, m = np.shape(B)
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u", m)
    f = ca.mtimes(ca.DM(A), x) + ca.mtimes(ca.DM(B), u) + ca.DM(c)
    kw = {}
    if E is not None:
        w = ca.SX.sym("w", np.shape(E)[1])
        f = f + ca.mtimes(ca.DM(E), w)
        kw = {"w": w, "W": W}
    return cm.Model(x=x, u=u, f=f, X=X, U=U, **kw)


@st.composite
def _cases(draw):
    n = draw(st.integers(2, 4))
    m = draw(st.integers(1, min(n, 3)))
    nl = draw(st.integers(0, 2))
    s = 10.0 ** draw(st.integers(-3, 3))      # state magnitude
    su = 10.0 ** draw(st.integers(-3, 3))     # input magnitude
    sw = 10.0 ** draw(st.integers(-3, 3))     # disturbance magnitude
    kind = draw(st.sampled_from(["box", "hull"]))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    A = 0.9 * np.eye(n) + 0.4 * rng.standard_normal((n, n))
    B = rng.standard_normal((n, m)) * (s / su)
    c = 0.2 * s * rng.standard_normal(n)
    X = cm.Box(-4 * s * np.ones(n), 4 * s * np.ones(n))
    U = cm.Box(-su * np.ones(m), su * np.ones(m))
    centre = s * rng.uniform(-1, 1, n)
    if kind == "box":
        half = s * rng.uniform(0.5, 1.5, n)
        T = cm.Polytope.from_box(cm.Box(centre - half, centre + half))
    else:
        T = cm.Polytope.from_vertices(centre + s * rng.uniform(-1.5, 1.5, (2 * n + 2, n)))
    if nl:
        E = 0.05 * (s / sw) * rng.standard_normal((n, nl))
        W = cm.Box(-sw * np.ones(nl), sw * rng.uniform(0.5, 1.0, nl))
        return _model(A, B, c, X, U, E, W), T
    return _model(A, B, c, X, U), T


def _check_inner(model: cm.Model, T: cm.Polytope, K: cm.Polytope,
                 limit: int | None = None) -> int:
    """Assert every exact vertex of K (at most ``limit`` of them) is controllable into T;
    the number checked."""
    if K.is_empty():
        return 0
    verts, _ = _exact_vertices(K, limit)
    for v in verts:
        assert _controllable_exact(model, T, v), [float(t) for t in v]
    return len(verts)


@settings(max_examples=30)
@given(_cases())
def test_vertices_of_the_pre_set_are_exactly_controllable(case):
    """Up to 24 vertices per case, spread over the vertex list."""
    model, T = case
    K = cm.pre_set(model, T)
    assert isinstance(K, cm.Polytope)
    _check_inner(model, T, K, limit=24)


def test_the_pre_set_is_checked_at_vertices_and_is_tight():
    """Regression for the float pre-set (its vertices lay outside the exact set by
    ~1e-15), plus: the inner set is not much smaller than the exact one (points that
    are controllable with a margin of 1e-7 of the scale are inside)."""
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(6):
        A = 0.9 * np.eye(2) + 0.4 * rng.standard_normal((2, 2))
        B = rng.standard_normal((2, 1))
        c = 0.2 * rng.standard_normal(2)
        model = _model(A, B, c, cm.Box([-4, -4], [4, 4]), cm.Box([-1], [1]))
        T = cm.Polytope.from_vertices(rng.uniform(-1.5, 1.5, (7, 2)))
        K = cm.pre_set(model, T)
        checked += _check_inner(model, T, K)
        H, h = np.asarray(T.A), np.asarray(T.b)
        for x in model.X.sample(200, rng):
            res = linprog(np.zeros(1), A_ub=H @ B, b_ub=h - H @ (A @ x + c) - 1e-7,
                          bounds=[(-1 + 1e-7, 1 - 1e-7)], method="highs")
            if res.status == 0 and np.all(np.abs(x) <= 4 - 1e-7):
                assert K.contains(x, tol=1e-9), x
    assert checked > 0


def test_union_targets_and_within_X_false_are_inner():
    ex = cm.models.load("linear_sliding")
    K = cm.pre_set(ex.model, ex.terminal)
    assert isinstance(K, cm.PolytopeUnion) and len(K.polytopes) == 2
    for P, member in zip(K.polytopes, ex.terminal.polytopes, strict=True):
        assert _check_inner(ex.model, member, P) > 0
    # without X: x+ = 0.5 x + u is bounded by the target alone
    model = _model(0.5 * np.eye(2), np.eye(2)[:, :1], [0.1, -0.2], cm.Box([-1, -1], [1, 1]),
                   cm.Box([-0.3], [0.3]))
    T = cm.Polytope.from_vertices(np.array([[0.0, 0.0], [1.0, 0.3], [0.2, 1.1]]))
    K = cm.pre_set(model, T, within_X=False)
    assert K.bounding_box().hi.max() > 1.0  # reaches outside X
    assert _check_inner(model, T, K) > 0


def test_robust_pre_set_with_offsets_is_inner():
    rng = np.random.default_rng(11)
    A = np.array([[1.0, 0.1], [0.0, 1.0]]) + 0.01 * rng.standard_normal((2, 2))
    B = np.array([[0.005], [0.1]])
    E = np.array([[0.01, 0.0], [0.0, 0.02]])
    model = _model(A, B, [1e-3, -2e-3], cm.Box([-5, -5], [5, 5]), cm.Box([-1], [1]),
                   E, cm.Box([-1, -0.5], [1, 1.0]))
    T = cm.Polytope.from_box(cm.Box([-1.2, -0.8], [0.9, 1.1]))
    K = T
    for _ in range(3):  # a short controllable-set sequence: each set inner to the next
        K_next = cm.pre_set(model, K)
        assert _check_inner(model, K, K_next) > 0
        K = K_next


def test_autonomous_and_single_state_models():
    x = ca.SX.sym("x", 2)
    f = ca.mtimes(ca.DM([[0.9, 0.2], [-0.1, 0.8]]), x) + ca.DM([0.01, 0.02])
    auto = cm.Model(x=x, u=ca.SX.sym("u", 0), f=f, X=cm.Box([-3, -3], [3, 3]))
    T = cm.Polytope.from_box(cm.Box([-1, -1], [1, 1]))
    assert _check_inner(auto, T, cm.pre_set(auto, T)) > 0
    x1 = ca.SX.sym("x", 1)
    u2 = ca.SX.sym("u", 2)
    model = cm.Model(x=x1, u=u2, f=1.1 * x1 + u2[0] - 0.3 * u2[1] + 0.1,
                     X=cm.Box([-3], [3]), U=cm.Box([-1, -1], [1, 1]))
    T1 = cm.Polytope.from_box(cm.Box([-1], [1]))
    assert _check_inner(model, T1, cm.pre_set(model, T1)) == 2


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_scalar_pre_set_is_inside_the_exact_interval(scale):
    # x+ = 3 x + u, |u| <= scale / 10, T = [-scale, scale]: Pre = [-11/30, 11/30] scale
    x = ca.SX.sym("x", 1)
    u = ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=3 * x + u, X=cm.Box([-10 * scale], [10 * scale]),
                     U=cm.Box([-scale / 10], [scale / 10]))
    K = cm.pre_set(model, cm.Polytope.from_box(cm.Box([-scale], [scale])))
    B = K.bounding_box()
    exact = (Fraction(scale) + Fraction(scale / 10)) / 3
    assert Fraction(B.hi[0]) <= exact and Fraction(-B.lo[0]) <= exact
    assert float(exact) - B.hi[0] <= 1e-12 * scale
    verts = _exact_vertices(K)[0]
    assert len(verts) == 2


# ------------------------------------------------------ the exact helpers of pre_set
@settings(max_examples=40)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(3, 14),
       shrink=st.sampled_from([0.0, 1e-12]))
def test_reduce_rows_never_enlarges_the_set(seed, k, shrink):
    """Every vertex of the reduced set (exact, all pairs of its rows) satisfies every
    original row exactly; with shrink = 0 the kept rows are among the original ones."""
    from casadi_cmpc.sets._exact import exact_row, reduce_rows

    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(k):  # random rows, some nearly parallel to others
        a = rng.standard_normal(2)
        if rows and rng.random() < 0.4:
            a = np.array([float(v) for v in rows[-1][0]]) + 1e-13 * rng.standard_normal(2)
        rows.append(exact_row([_fr(v) for v in a], _fr(rng.uniform(0.1, 2.0))))
    box = [exact_row([1, 0], 3), exact_row([-1, 0], 3), exact_row([0, 1], 3),
           exact_row([0, -1], 3)]
    allr = rows + box
    out = reduce_rows(allr, np.array([-3.0, -3.0]), np.array([3.0, 3.0]),
                      removable=range(len(rows)), shrink=shrink)
    assert out is not None  # the origin is inside
    verts = []
    for (a1, b1), (a2, b2) in itertools.combinations(out, 2):
        v = _solve([[Fraction(t) for t in a1], [Fraction(t) for t in a2]], [b1, b2])
        if v is not None and all(a[0] * v[0] + a[1] * v[1] <= b for a, b in out):
            verts.append(v)
    assert len(verts) >= 3
    for v in verts:
        for a, b in allr:
            assert a[0] * v[0] + a[1] * v[1] <= b
    if shrink == 0.0:
        assert all(r in allr for r in out)


@settings(max_examples=60)
@given(seed=st.integers(0, 2**32 - 1))
def test_exact_simplex_agrees_with_highs(seed):
    from casadi_cmpc.sets._exact import rat_lp_eq

    rng = np.random.default_rng(seed)
    p, k = int(rng.integers(1, 4)), int(rng.integers(1, 7))
    M = rng.integers(-3, 4, (p, k))
    r = rng.integers(-3, 4, p)
    c = rng.integers(-2, 5, k)
    res = rat_lp_eq([[Fraction(int(v)) for v in row] for row in M],
                    [Fraction(int(v)) for v in r], [Fraction(int(v)) for v in c])
    ref = linprog(c, A_eq=M, b_eq=r, bounds=[(0, None)] * k, method="highs")
    if res is None:
        assert ref.status in (2, 3)
    else:
        y, val = res
        assert all(v >= 0 for v in y)
        assert all(sum(int(M[i, j]) * y[j] for j in range(k)) == r[i] for i in range(p))
        assert ref.status == 0 and abs(float(val) - ref.fun) <= 1e-9 * (1 + abs(ref.fun))


def test_pre_set_uses_the_exact_model_not_a_folded_one() -> None:
    """A closed loop whose gain CasADi would fold (exactly -7.65, folded 0.5) is refused, and
    an open-loop constant term that rounds to 0 (exactly 0.555) empties the pre-set."""
    import casadi as ca

    from casadi_cmpc.exceptions import ModelError

    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(x[0] * (0.5 + 1e17 * (ca.exp(u + 0.1) - float(np.exp(0.1)))), 0.5 * x[1])
    m = cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))
    cl = m.closed_loop(np.zeros((1, 2)))
    A = cl.linear_enclosures()[0]
    assert A[0, 0, 0] <= -7.6495 <= A[0, 0, 1]  # the exact gain, not the folded 0.5
    with pytest.raises(ModelError, match="not known exactly"):
        cm.pre_set(cl, cm.Polytope.from_box(cm.Box([-1, -1], [1, 1])))
    y = ca.SX.sym("y")
    v = ca.SX.sym("v")
    mo = cm.Model(x=y, u=v, f=0.1 * (y + 1e17) - 1e16 + v, X=cm.Box([-1], [1]),
                  U=cm.Box([-0.5], [0.5]))
    c = mo.linear_enclosures()[3]
    exact_c = Fraction(0.1) * Fraction(10**17) - Fraction(10**16)
    assert Fraction(c[0, 0]) <= exact_c <= Fraction(c[0, 1])
    assert cm.pre_set(mo, cm.Polytope.from_box(cm.Box([-0.1], [0.1]))).is_empty()
