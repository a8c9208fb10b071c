"""Derivative-based enclosures across jumps, with derived constants, and zonotope bisection.

Facts checked: exact values (mpmath, 300 bits, from the instruction list of the very
Function evaluated) of sampled points - including both sides of jumps (integers and their
float neighbours) - lie in every derivative-based enclosure: the mean-value bound
``f(b) - f(a) in J(box) (b - a)``, the centered form, ``evolve``'s zonotope and the Kühn
image of zonotope SIVIA; Jacobian enclosures contain exact derivatives computed in
rational arithmetic from the literal values of f; zonotope halves cover the parent exactly.
"""

from __future__ import annotations

import itertools
import math
from fractions import Fraction

import casadi as ca
import mp_reference as R
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.interval.compiler import InclusionFunction
from casadi_cmpc.solvers.zonotope_sivia import ZonotopeFrontier, _Image

# ------------------------------------------------------------------- expressions
_UN = {
    "floor": ca.floor, "ceil": ca.ceil, "sign": ca.sign, "fabs": ca.fabs, "sin": ca.sin,
    "sq": lambda a: a * a, "neg": lambda a: -a, "round": lambda a: ca.floor(a + 0.5),
    "inv": lambda a: 1 / a, "tan": ca.tan,
}
_BIN = {
    "add": lambda a, b: a + b, "mul": lambda a, b: a * b, "sub": lambda a, b: a - b,
    "fmod": ca.fmod, "rem": ca.remainder, "copysign": ca.copysign, "atan2": ca.atan2,
    "lt": lambda a, b: a < b, "le": lambda a, b: a <= b, "fmin": ca.fmin,
    "ifelse": lambda a, b: ca.if_else(a < b, a * b, b - 1.5),
    "and": ca.logic_and, "eq": lambda a, b: a == b,
}
CONSTS = [0.5, 1.0, 2.0, 3.0, 0.1, 0.7, -1.25]


def trees(n: int):
    leaf = st.one_of(st.integers(0, n - 1).map(lambda i: ("x", i)),
                     st.sampled_from(CONSTS).map(lambda c: ("c", c)))

    def extend(ch):
        return st.one_of(st.tuples(st.just("u"), st.sampled_from(sorted(_UN)), ch),
                         st.tuples(st.just("b"), st.sampled_from(sorted(_BIN)), ch, ch))

    return st.recursive(leaf, extend, max_leaves=6)


def build(t, x):
    if t[0] == "x":
        return x[t[1]]
    if t[0] == "c":
        return ca.SX(t[1])
    if t[0] == "u":
        return _UN[t[1]](build(t[2], x))
    return _BIN[t[1]](build(t[2], x), build(t[3], x))


@st.composite
def problems(draw):
    """(n, Function R^n -> R^n, box (n, 2), sample points (k, n))."""
    n = draw(st.integers(1, 4))
    ts = [draw(trees(n)) for _ in range(n)]
    x = ca.SX.sym("x", n)
    f = ca.vertcat(*[build(t, x) + 0 * x[i] for i, t in enumerate(ts)])
    fun = ca.Function("f", [x], [f])
    lo = np.array([draw(st.sampled_from([-1.5, -1.0, -0.5, 0.0, 0.25, 1.0])) for _ in range(n)])
    w = np.array([draw(st.sampled_from([0.0, 0.5, 1.0, 2.0, 2.5])) for _ in range(n)])
    box = np.stack([lo, lo + w], axis=-1)
    seed = draw(st.integers(0, 2**31))
    return n, fun, box, _samples(box, seed)


def _samples(box, seed, k=14):
    """Corners, integers and their float neighbours, random points of the box."""
    rng = np.random.default_rng(seed)
    lo, hi = box[:, 0], box[:, 1]
    pts = [lo, hi, 0.5 * (lo + hi)]
    for _ in range(k):
        p = rng.uniform(lo, hi)
        j = rng.integers(len(lo))
        cand = [c for c in range(math.ceil(lo[j]) - 1, math.floor(hi[j]) + 2)
                if lo[j] <= c <= hi[j]]
        if cand:
            c = float(rng.choice(cand))
            # float neighbours (2^-40 around 0: the 300-bit reference cannot resolve
            # subnormal steps next to O(1) terms)
            eps = abs(c) * 2.0**-52 if c else 2.0**-40
            p[j] = np.clip(rng.choice([c, c - eps, c + eps]), lo[j], hi[j])
        pts.append(p)
    return np.array(pts)


def exact(fun, p):
    """Exact outputs of fun at the point p (list of mpf or R.UNDEF)."""
    return R.eval_function(fun, [list(map(float, p))])[0]


def _defined(v):
    return all(e is not R.UNDEF for e in v)


# ------------------------------------------------------------------- A: jumps
def _mvt_bound(J, d):
    """Exact [lo, hi] of J d for an interval matrix row J (k, 2) and a vector d (mpf)."""
    lo = hi = R.ZERO
    for (a, b), dj in zip(J, d, strict=True):
        if dj == 0:
            continue
        if not (math.isfinite(a) and math.isfinite(b)):
            return None
        p, q = R.F(a) * dj, R.F(b) * dj
        lo += min(p, q)
        hi += max(p, q)
    return lo, hi


@settings(max_examples=120)
@given(prob=problems())
def test_mean_value_theorem_holds_across_jumps(prob):
    n, fun, box, pts = prob
    model = cm.Model(x=fun.sx_in(0), u=None, f=fun(fun.sx_in(0)), X=cm.Box(box[:, 0], box[:, 1]))
    J = model.jacobian_inclusion("x")(box)[0]  # (n, n, 2)
    vals = [exact(model.function, p) for p in pts]
    for (a, fa), (b, fb) in itertools.combinations(zip(pts, vals, strict=True), 2):
        if not (_defined(fa) and _defined(fb)):
            continue
        d = [R.F(bj) - R.F(aj) for aj, bj in zip(a, b, strict=True)]
        for i in range(n):
            bound = _mvt_bound(J[i], d)
            if bound is not None:
                assert bound[0] <= fb[i] - fa[i] <= bound[1], (i, a, b, J[i], str(fun))


@settings(max_examples=80)
@given(prob=problems())
def test_evolve_kuhn_image_and_centered_contain_sampled_images(prob):
    n, fun, box, pts = prob
    x = fun.sx_in(0)
    model = cm.Model(x=x, u=None, f=fun(x), X=cm.Box(box[:, 0], box[:, 1]))
    Z = cm.Zonotope.from_box(cm.Box(box[:, 0], box[:, 1]))
    try:
        Zf = cm.evolve(model, Z)
        zb = Zf.bounding_box().as_array()
    except cm.UnboundedSetError:
        zb = None
    with _no_check():
        img = _Image(fun, n, None, None)
    q, G, s, valid, _ = img(ZonotopeFrontier.from_zonotopes(Z))
    with _no_check():
        Fc = InclusionFunction(fun, "centered")
    cen = Fc(box[None])[0][0]
    for p in pts:
        v = exact(model.function, p)
        for i, e in enumerate(v):
            if e is R.UNDEF:
                continue
            if zb is not None:
                assert R.inside(zb[i, 0], zb[i, 1], e), ("evolve", i, p)
            if valid[0]:
                r_i = sum((R.F(abs(g)) for g in G[0, i]), R.F(s[0, i]))  # exact at 300 bits
                assert R.F(q[0, i]) - r_i <= e <= R.F(q[0, i]) + r_i, ("kuhn", i, p)
            assert R.inside(cen[i, 0], cen[i, 1], e), ("centered", i, p)


class _no_check:
    """Silence the CmpcWarnings about jumps inside a block."""

    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", cm.CmpcWarning)

    def __exit__(self, *a):
        self._w.__exit__(*a)


def test_floor_jacobian_and_evolve_reach_the_jumps():
    x = ca.SX.sym("x")
    model = cm.Model(x=x, u=None, f=ca.floor(x), X=cm.Box([-2], [2]))
    J = model.jacobian_inclusion("x")(np.array([[-0.5, 1.5]]))[0, 0, 0]
    assert J[0] == -np.inf and J[1] == np.inf
    # away from the jumps the derivative 0 is valid
    assert list(model.jacobian_inclusion("x")(np.array([[0.0, 0.75]]))[0, 0, 0]) == [0, 0]
    bb = cm.evolve(model, cm.Zonotope([0.5], [[1.0]])).bounding_box().as_array()
    assert bb[0, 0] <= -1 and bb[0, 1] >= 1
    # the left-open jump of floor: [0.5, 1] reaches 1
    assert model.jacobian_inclusion("x")(np.array([[0.5, 1.0]]))[0, 0, 0, 1] == np.inf


@pytest.mark.parametrize("expr, box, jumps", [
    (lambda x: ca.ceil(x), [0.5, 1.0], False), (lambda x: ca.ceil(x), [0.0, 0.5], True),
    (lambda x: ca.sign(x), [0.0, 0.0], False), (lambda x: ca.sign(x), [-1e-300, 0.0], True),
    (lambda x: ca.fmod(x, 2.0), [2.5, 3.9], False),
    (lambda x: ca.fmod(x, 2.0), [1.0, 2.0], True),
    (lambda x: ca.fmod(x, 2.0), [-1.9, 1.9], False),
    (lambda x: ca.fmod(x, 2.0), [-2.0, -1.0], True),  # fmod(-2, 2) = 0, fmod(-1.99, 2) = -1.99
    (lambda x: ca.remainder(x, 2.0), [-0.9, 0.9], False),
    (lambda x: ca.remainder(x, 2.0), [0.5, 1.0], True),
    (lambda x: ca.atan2(x, -1.0), [-0.1, 0.1], True), (lambda x: ca.atan2(x, 1.0), [-1, 1], False),
    (lambda x: ca.copysign(2.0, x), [-1.0, 1.0], True), (lambda x: 1 / x, [-1.0, 1.0], True),
    (lambda x: ca.atan(1 / x), [-1.0, 1.0], True), (lambda x: ca.tan(x), [1.5, 1.7], True),
    (lambda x: ca.fabs(x), [-1.0, 1.0], False),
])
def test_jump_detection_per_box(expr, box, jumps):
    x = ca.SX.sym("x")
    model = cm.Model(x=x, u=None, f=expr(x), X=cm.Box([-5], [5]))
    J = model.jacobian_inclusion("x")(np.array([box], dtype=float))[0, 0, 0]
    assert (J[0] == -np.inf and J[1] == np.inf) == jumps


def test_fabs_jacobian_encloses_both_slopes():
    x = ca.SX.sym("x")
    model = cm.Model(x=x, u=None, f=ca.fabs(x), X=cm.Box([-5], [5]))
    J = model.jacobian_inclusion("x")(np.array([[-1.0, 1.0]]))[0, 0, 0]
    assert J[0] <= -1 and J[1] >= 1


# ------------------------------------------------------------- B: derived constants
LITERALS = [0.1, 0.3, 1 / 3, 1e-17, 3e16, 3.0, 10.0, 0.30000000000000004, 3 * (1 / 3),
            0.1 * 3, 2.0, 1e-200]


def polys(n: int):
    var = st.integers(0, n - 1).map(lambda i: ("x", i))

    def extend(ch):
        return st.one_of(
            st.tuples(st.just("cmul"), st.sampled_from(LITERALS), ch),
            st.tuples(st.just("cadd"), st.sampled_from(LITERALS), ch),
            st.tuples(st.just("add"), ch, ch), st.tuples(st.just("mul"), ch, ch))

    return st.recursive(var, extend, max_leaves=6)


def build_poly(t, x):
    if t[0] == "x":
        return x[t[1]]
    if t[0] == "cmul":
        return t[1] * build_poly(t[2], x)
    if t[0] == "cadd":
        return t[1] + build_poly(t[2], x)
    a, b = build_poly(t[1], x), build_poly(t[2], x)
    return a + b if t[0] == "add" else a * b


def dual(fun, p, j):
    """Exact (values, d/dx_j) of the outputs at the rational point p, from the instruction
    list of fun (its literal constants as written in the graph; CasADi may have merged
    ``0.1 * (0.1 * x)`` into one literal while building f)."""
    w: dict = {}
    vals, ders = [None] * fun.nnz_out(0), [None] * fun.nnz_out(0)
    for k in range(fun.n_instructions()):
        op, ins, o = (fun.instruction_id(k), list(fun.instruction_input(k)),
                      list(fun.instruction_output(k)))
        if op == ca.OP_CONST:
            w[o[0]] = (Fraction(fun.instruction_constant(k)), Fraction(0))
        elif op == ca.OP_INPUT:
            w[o[0]] = (p[ins[1]], Fraction(int(ins[1] == j)))
        elif op == ca.OP_OUTPUT:
            vals[o[1]], ders[o[1]] = w[ins[0]]
        else:
            a, da = w[ins[0]]
            b, db = w[ins[1]] if op in (ca.OP_ADD, ca.OP_SUB, ca.OP_MUL) else (None, None)
            if op == ca.OP_ADD:
                w[o[0]] = (a + b, da + db)
            elif op == ca.OP_SUB:
                w[o[0]] = (a - b, da - db)
            elif op == ca.OP_MUL:
                w[o[0]] = (a * b, da * b + a * db)
            elif op == ca.OP_NEG:
                w[o[0]] = (-a, -da)
            elif op == ca.OP_TWICE:
                w[o[0]] = (2 * a, 2 * da)
            elif op == ca.OP_SQ:
                w[o[0]] = (a * a, 2 * a * da)
            else:
                assert op == ca.OP_ASSIGN, op
                w[o[0]] = (a, da)
    return vals, ders


@settings(max_examples=150)
@given(n=st.integers(1, 4), data=st.data())
def test_jacobian_and_centered_contain_exact_derivatives_with_folded_literals(n, data):
    ts = [data.draw(polys(n)) for _ in range(n)]
    x = ca.SX.sym("x", n)
    f = ca.vertcat(*[build_poly(t, x) for t in ts])
    model = cm.Model(x=x, u=None, f=f, X=cm.Box(-np.ones(n), np.ones(n)))
    fun = ca.Function("f", [x], [f])
    with _no_check():
        Fc = InclusionFunction(fun, "centered")
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    p = rng.uniform(-1, 1, n)
    thin = np.stack([p, p], axis=-1)
    J = model.jacobian_inclusion("x")(thin)[0]
    P = [Fraction(v) for v in p]
    box = np.stack([p - 0.25, p + 0.25], axis=-1)
    cen = Fc(box[None])[0][0]
    for j in range(n):
        vals, ders = dual(model.function, P, j)
        for i in range(n):
            assert Fraction(J[i, j, 0]) <= ders[i] <= Fraction(J[i, j, 1]), (i, j, ts[i])
            # the centered form over a box around p contains the exact value at p
            assert Fraction(cen[i, 0]) <= vals[i] <= Fraction(cen[i, 1]), (i, ts[i])


def test_issue_example_folded_constant_shared_with_f():
    x = ca.SX.sym("x", 2)
    f = ca.vertcat(3 * (0.1 * x[0] + x[1]), 0.30000000000000004 * x[1])
    model = cm.Model(x=x, u=None, f=f, X=cm.Box([-1, -1], [1, 1]))
    J = model.jacobian_inclusion("x")(np.zeros((2, 2)))[0]
    exact_d = 3 * Fraction(0.1)
    assert Fraction(J[0, 0, 0]) <= exact_d <= Fraction(J[0, 0, 1])
    # f's own literal stays exact in the centered form's f part
    Fc = model.inclusion("centered")
    y = Fc(np.array([[1.0, 1.0], [1.0, 1.0]]))[0, 1]
    assert Fraction(y[0]) <= Fraction(0.30000000000000004) <= Fraction(y[1])


# ------------------------------------------------------------------ C: bisection
def _solve_small(E, r):
    """Exact beta with E beta = r (E: n x e, e <= 2), or None."""
    n, e = len(E), len(E[0]) if E else 0
    if e == 0:
        return [] if all(v == 0 for v in r) else None
    for rows in itertools.combinations(range(n), e):
        A = [[E[i][c] for c in range(e)] for i in rows]
        if e == 1:
            if A[0][0] == 0:
                continue
            beta = [r[rows[0]] / A[0][0]]
        else:
            det = A[0][0] * A[1][1] - A[0][1] * A[1][0]
            if det == 0:
                continue
            b0, b1 = r[rows[0]], r[rows[1]]
            beta = [(b0 * A[1][1] - A[0][1] * b1) / det, (A[0][0] * b1 - b0 * A[1][0]) / det]
        if all(sum(E[i][c] * beta[c] for c in range(e)) == r[i] for i in range(n)):
            return beta
    return None


@settings(max_examples=200)
@given(n=st.integers(1, 4), m=st.integers(1, 4), data=st.data())
def test_bisect_halves_cover_every_point_exactly(n, m, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    scale_c = 10.0 ** data.draw(st.integers(-2, 16))
    c = rng.uniform(-1, 1, n) * scale_c
    G = rng.uniform(-1, 1, (n, m)) * 10.0 ** rng.uniform(-8, 8, (n, m))
    Z = cm.Zonotope(c, G)
    k = int(np.argmax(np.abs(G).max(axis=0)))
    L, Rz = Z.bisect()
    ts = [[Fraction(0)] * m] + [[Fraction(int(v)) for v in sg]
                                for sg in itertools.product([-1, 1], repeat=m)]
    ts += [[Fraction(v) for v in rng.uniform(-1, 1, m)] for _ in range(5)]
    ts += [[Fraction(0) if j == k else Fraction(v) for j, v in enumerate(rng.uniform(-1, 1, m))]]
    for t in ts:
        xp = [Fraction(c[i]) + sum(Fraction(G[i, j]) * t[j] for j in range(m)) for i in range(n)]
        half, a_k = (L, 2 * t[k] + 1) if t[k] <= 0 else (Rz, 2 * t[k] - 1)
        H = half.generators
        alpha = [t[j] if j != k else a_k for j in range(m)]
        r = [xp[i] - Fraction(half.center[i])
             - sum(Fraction(H[i, j]) * alpha[j] for j in range(m)) for i in range(n)]
        E = [[Fraction(H[i, j]) for j in range(m, H.shape[1])] for i in range(n)]
        beta = _solve_small(E, r)
        assert beta is not None and all(abs(b) <= 1 for b in beta), (t, c, G)


def test_bisect_large_centre_keeps_the_centre():
    Z = cm.Zonotope([1e16], [[3.0]])
    L, Rz = Z.bisect()
    lo = min(Fraction(L.center[0]) - sum(abs(Fraction(g)) for g in L.generators[0]),
             Fraction(Rz.center[0]) - sum(abs(Fraction(g)) for g in Rz.generators[0]))
    mid_cover = any(abs(Fraction(1e16) - Fraction(h.center[0]))
                    <= sum(abs(Fraction(g)) for g in h.generators[0]) for h in (L, Rz))
    assert mid_cover and lo <= Fraction(1e16) - 3
