"""Validated sampled-data models of ODEs (``Model.from_ode(method="taylor")``).

The interval evaluators of such a model must enclose the TRUE flow of the ODE. The
reference flows are integrated by the Taylor series method on numpy ``longdouble`` jets
(64-bit mantissa), with steps of at most 0.05 and degree 24, for right-hand sides drawn
as small expression trees (constants, x, u, w, +, *, sin, exp, sqrt on a positive
argument); the reference itself is checked against ``mpmath.odefun`` with 30 digits.
A reference value may lie up to ``1e-17 (1 + |x|)`` outside a bound (its own error);
every enclosure is rounded outward by at least one double ulp (about 1e-16 relative).
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.exceptions import ModelError
from casadi_cmpc.interval._native import native_available

LD = np.longdouble
REF_TOL = 1e-17

# ----------------------------------------------------------------- reference flow


def to_casadi(e: tuple, x: ca.SX, u: ca.SX, w: ca.SX) -> ca.SX:
    op = e[0]
    if op == "c":
        return ca.SX(float(e[1]))
    if op in ("x", "u", "w"):
        return {"x": x, "u": u, "w": w}[op][e[1]]
    if op == "add":
        return to_casadi(e[1], x, u, w) + to_casadi(e[2], x, u, w)
    if op == "mul":
        return to_casadi(e[1], x, u, w) * to_casadi(e[2], x, u, w)
    return getattr(ca, op)(to_casadi(e[1], x, u, w))


def to_mpmath(e: tuple, y: list, uu: list, ww: list) -> Any:
    import mpmath

    op = e[0]
    if op == "c":
        return mpmath.mpf(float(e[1]))
    if op == "x":
        return y[e[1]]
    if op == "u":
        return mpmath.mpf(float(uu[e[1]]))
    if op == "w":
        return mpmath.mpf(float(ww[e[1]]))
    if op == "add":
        return to_mpmath(e[1], y, uu, ww) + to_mpmath(e[2], y, uu, ww)
    if op == "mul":
        return to_mpmath(e[1], y, uu, ww) * to_mpmath(e[2], y, uu, ww)
    return getattr(mpmath, op)(to_mpmath(e[1], y, uu, ww))


class _Jets:
    """Coefficient-by-coefficient evaluation of the rhs trees on Taylor jets (K + 1, N)."""

    def __init__(self, trees: list[tuple], K: int, N: int, u: np.ndarray, w: np.ndarray) -> None:
        self.trees, self.K, self.N = trees, K, N
        self.u, self.w = u, w

    def run(self, y0: np.ndarray, h: Any) -> np.ndarray:
        """One Taylor step of size h from y0 (n, N): the state at h, (n, N)."""
        K, N = self.K, self.N
        n = y0.shape[0]
        self.y = np.zeros((n, K + 1, N), dtype=LD)
        self.y[:, 0] = y0
        self.cache: dict[int, Any] = {}
        for k in range(K):
            for i, t in enumerate(self.trees):
                fk = self.coef(t, k)
                self.y[i, k + 1] = fk / LD(k + 1)
        # Horner in h
        out = self.y[:, K].copy()
        for k in range(K - 1, -1, -1):
            out = out * h + self.y[:, k]
        return out

    def coef(self, e: tuple, k: int) -> np.ndarray:
        """Coefficient k of the jet of node e (all lower ones already computed)."""
        key = id(e)
        node = self.cache.get(key)
        if node is None:
            node = self.cache[key] = {"jet": np.zeros((self.K + 1, self.N), dtype=LD), "n": 0}
            if e[0] in ("sin",):
                node["cos"] = np.zeros((self.K + 1, self.N), dtype=LD)
        while node["n"] <= k:
            j = node["n"]
            node["jet"][j] = self._compute(e, node, j)
            node["n"] += 1
        return node["jet"][k]

    def _compute(self, e: tuple, node: dict, k: int) -> np.ndarray:
        op = e[0]
        N = self.N
        if op == "c":
            return np.full(N, LD(e[1]) if k == 0 else LD(0))
        if op == "x":
            return self.y[e[1], k]
        if op in ("u", "w"):
            v = (self.u if op == "u" else self.w)[:, e[1]]
            return v.copy() if k == 0 else np.zeros(N, dtype=LD)
        if op == "add":
            return self.coef(e[1], k) + self.coef(e[2], k)
        if op == "mul":
            for j in range(k + 1):
                self.coef(e[1], j)
                self.coef(e[2], j)
            a = self.cache[id(e[1])]["jet"][:k + 1]
            b = self.cache[id(e[2])]["jet"][:k + 1]
            return (a * b[::-1]).sum(axis=0)
        a_k = self.coef(e[1], k)
        a = self.cache[id(e[1])]["jet"]
        jet = node["jet"]
        if op == "exp":
            if k == 0:
                return np.exp(a_k)
            i = np.arange(1, k + 1, dtype=LD)[:, None]
            return (i * a[1:k + 1] * jet[k - 1::-1][:k]).sum(axis=0) / LD(k)
        if op == "sin":
            c = node["cos"]
            if k == 0:
                c[0] = np.cos(a_k)
                return np.sin(a_k)
            i = np.arange(1, k + 1, dtype=LD)[:, None]
            s_k = (i * a[1:k + 1] * c[k - 1::-1][:k]).sum(axis=0) / LD(k)
            c[k] = -(i * a[1:k + 1] * jet[k - 1::-1][:k]).sum(axis=0) / LD(k)
            return s_k
        if op == "sqrt":
            if k == 0:
                return np.sqrt(a_k)
            s = (jet[1:k] * jet[k - 1:0:-1]).sum(axis=0) if k > 1 else LD(0)
            return (a_k - s) / (LD(2) * jet[0])
        raise ValueError(op)


def flow(trees: list[tuple], x0: np.ndarray, u: np.ndarray, w: np.ndarray, dt: float,
         K: int = 24, hmax: float = 0.05) -> np.ndarray:
    """States at time dt from the initial states x0 (N, n) with u (N, m), w (N, l) constant
    over the sample; (N, n) longdouble."""
    x0 = np.asarray(x0, dtype=LD)
    N = x0.shape[0]
    u = np.asarray(u, dtype=LD).reshape(N, -1)
    w = np.asarray(w, dtype=LD).reshape(N, -1)
    steps = max(1, int(np.ceil(dt / hmax)))
    h = LD(dt) / LD(steps)
    J = _Jets(trees, K, N, u, w)
    y = x0.T.copy()
    for _ in range(steps):
        y = J.run(y, h)
    return y.T


# ------------------------------------------------------------------- helpers
def _build(trees: list[tuple], n: int, m: int, l: int, X: Any, U: Any, W: Any, dt: float,
           order: int) -> cm.Model:
    """The validated model; a draw whose ODE cannot be validated (finite escape, too fast
    for dt) is discarded (the refusals have their own tests)."""
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u", m)
    w = ca.SX.sym("w", l) if l else None
    ws = w if w is not None else ca.SX.sym("w", 0)
    rhs = ca.vertcat(*[to_casadi(t, x, u, ws) for t in trees])
    try:
        return cm.Model.from_ode(x, u, rhs, dt, method="taylor", order=order, w=w, X=X,
                                 U=U if m else None, W=W if l else None)
    except ModelError as exc:
        assert "cannot be validated" in str(exc)
        assume(False)
        raise


def _inside(enc: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(N, n) booleans: the reference values lie in the enclosures (N, n, 2)."""
    lo = enc[..., 0].astype(LD)
    hi = enc[..., 1].astype(LD)
    tol = LD(REF_TOL) * (1 + np.abs(ref))
    return (lo - tol <= ref) & (ref <= hi + tol)


def _points(Z: np.ndarray, rng: np.random.Generator, k: int = 3) -> np.ndarray:
    """Corners, face centres and interior points of the box Z (d, 2); (N, d)."""
    d = Z.shape[0]
    lo, hi = Z[:, 0], Z[:, 1]
    pts = [lo, hi]
    for _ in range(k):
        pts.append(np.where(rng.random(d) < 0.5, lo, hi))  # corners
    mid = 0.5 * (lo + hi)
    for j in range(min(d, 2)):  # face centres
        p = mid.copy()
        p[j] = lo[j] if rng.random() < 0.5 else hi[j]
        pts.append(p)
    pts.append(mid)
    pts.append(lo + rng.random(d) * (hi - lo))
    return np.array(pts)


def _check_model(model: cm.Model, trees: list[tuple], Z: np.ndarray, dt: float,
                 backends: tuple[str, ...], rng: np.random.Generator,
                 jacobian: bool = True) -> None:
    """Flows from sample points of the box Z over (x, u, w) lie in every enclosure."""
    n, m, l = model.n, model.m, model.l
    P = _points(Z, rng)
    ref = flow(trees, P[:, :n], P[:, n:n + m], P[:, n + m:], dt)
    Xb, Ub, Wb = Z[None, :n], Z[None, n:n + m], Z[None, n + m:]
    thin = np.stack([P, P], axis=-1)
    for backend in backends:
        for kind in ("natural", "centered") if backend != "scalar" else ("natural",):
            F = model.inclusion(kind, backend=backend)
            box = F(Xb, Ub if m else None, Wb if l else None)[0]
            assert np.isfinite(box).all()
            ok = _inside(np.broadcast_to(box, (P.shape[0], n, 2)), ref)
            assert ok.all(), (backend, kind, box, ref[~ok.all(axis=1)])
            pts = F(thin[:, :n], thin[:, n:n + m] if m else None, thin[:, n + m:] if l else None)
            ok = _inside(pts, ref)
            assert ok.all(), (backend, kind, pts[~ok.all(axis=1)], ref[~ok.all(axis=1)])
    if not jacobian:
        return
    # the Jacobian at the centre of Z (thin box) against central differences of the flow
    # (step 1e-6 in longdouble: truncation about 1e-12, rounding about 1e-13)
    c = 0.5 * (Z[:, 0] + Z[:, 1])
    d = c.size
    h = 1e-6
    E = np.eye(d) * h
    pts = np.concatenate([c + E, c - E])
    r = flow(trees, pts[:, :n], pts[:, n:n + m], pts[:, n + m:], dt)
    fd = (r[:d] - r[d:]) / LD(2 * h)  # (d, n): column j of the Jacobian in row j
    cth = np.stack([c, c], axis=-1)[None]
    for wrt, sl in (("x", slice(0, n)), ("u", slice(n, n + m)), ("w", slice(n + m, n + m + l))):
        if sl.stop == sl.start:
            continue
        Jc = model.jacobian_inclusion(wrt)(cth[:, :n], cth[:, n:n + m] if m else None,
                                           cth[:, n + m:] if l else None)[0]
        ref = fd[sl].T  # (n, d_wrt)
        tol = 1e-9 * (1 + np.abs(ref))
        ok = (Jc[..., 0] - tol <= ref) & (ref <= Jc[..., 1] + tol)
        assert ok.all(), (wrt, Jc, ref)
    # mean-value theorem for the true flow: phi(b) - phi(a) in J(Z) (b - a) per variable
    a, b = P[0], P[1]  # the two opposite corners
    for wrt, sl in (("x", slice(0, n)), ("u", slice(n, n + m)), ("w", slice(n + m, None))):
        if sl.stop is not None and sl.start == sl.stop or (wrt == "w" and l == 0):
            continue
        c = a.copy()
        c[sl] = b[sl]  # a and c differ only in this variable
        r = flow(trees, np.stack([a[:n], c[:n]]), np.stack([a[n:n + m], c[n:n + m]]),
                 np.stack([a[n + m:], c[n + m:]]), dt)
        J = model.jacobian_inclusion(wrt)(Xb, Ub if m else None, Wb if l else None)[0]
        assert np.isfinite(J).all()
        d = (c[sl] - a[sl]).astype(LD)
        prod = np.stack([J[..., 0].astype(LD) * d, J[..., 1].astype(LD) * d], axis=-1)
        lo = prod.min(axis=-1).sum(axis=1)
        hi = prod.max(axis=-1).sum(axis=1)
        diff = r[1] - r[0]
        tol = LD(1e-15) * (1 + np.abs(prod).max(axis=-1).sum(axis=1)) + LD(REF_TOL) * (
            1 + np.abs(r).max(axis=0))
        assert ((lo - tol <= diff) & (diff <= hi + tol)).all(), (wrt, lo, hi, diff)


# ---------------------------------------------------------------- random ODEs
_COEF = st.sampled_from([-1.5, -1.0, -0.5, -0.25, 0.25, 0.5, 1.0, 1.5])


@st.composite
def _term(draw: Any, n: int, m: int, l: int) -> tuple:
    a = ("c", draw(_COEF))
    j = draw(st.integers(0, n - 1))
    kinds = ["lin", "quad", "sin", "exp", "sqrt"] + (["u", "ux"] if m else []) + (
        ["w"] if l else [])
    kind = draw(st.sampled_from(kinds))
    xj = ("x", j)
    if kind == "lin":
        return ("mul", a, xj)
    if kind == "quad":
        return ("mul", a, ("mul", xj, ("x", draw(st.integers(0, n - 1)))))
    if kind == "sin":
        return ("mul", a, ("sin", xj))
    if kind == "exp":
        return ("mul", a, ("exp", ("mul", ("c", draw(_COEF)), xj)))
    if kind == "sqrt":  # x in [-1, 1]: the argument stays >= 0.9 on the domain
        return ("mul", a, ("sqrt", ("add", ("c", 2.0), xj)))
    if kind == "u":
        return ("mul", a, ("u", draw(st.integers(0, m - 1))))
    if kind == "ux":
        return ("mul", a, ("mul", ("u", draw(st.integers(0, m - 1))), xj))
    return ("mul", a, ("w", draw(st.integers(0, l - 1))))


@st.composite
def _ode(draw: Any, max_n: int = 4, max_order: int = 6) -> dict[str, Any]:
    n = draw(st.integers(1, max_n))
    m = draw(st.integers(0, 1))
    l = draw(st.integers(0, 1))
    trees = []
    for _ in range(n):
        t = draw(_term(n, m, l))
        for _ in range(draw(st.integers(0, 2))):
            t = ("add", t, draw(_term(n, m, l)))
        trees.append(t)
    lo = np.array([draw(st.floats(-1.0, 0.0)) for _ in range(n)])
    hi = lo + np.array([draw(st.floats(0.05, 1.0)) for _ in range(n)])
    X = cm.Box(lo, hi)
    U = cm.Box([-0.5] * m, [0.5] * m)
    W = cm.Box([-0.1] * l, [0.1] * l)
    dt = float(10 ** draw(st.floats(-3.0, np.log10(0.5))))
    # the graph of an order-k model grows fast with k and n: high orders in few states
    order = draw(st.integers(2, max(2, min(max_order, 7 - n))))
    # a random sub-box of X x U x W, down to 1e-4 of its width
    D = np.concatenate([X.as_array(), U.as_array(), W.as_array()])
    frac = 10 ** draw(st.floats(-4.0, 0.0))
    start = draw(st.floats(0.0, 1.0)) * (1 - frac)
    w = D[:, 1] - D[:, 0]
    Z = np.stack([D[:, 0] + start * w, D[:, 0] + (start + frac) * w], axis=1)
    Z[:, 1] = np.minimum(Z[:, 1], D[:, 1])
    return dict(trees=trees, n=n, m=m, l=l, X=X, U=U, W=W, dt=dt, order=order, Z=Z,
                seed=draw(st.integers(0, 2 ** 16)))


def test_reference_flow_matches_mpmath() -> None:
    import mpmath

    trees = [("add", ("mul", ("c", 1.0), ("x", 1)), ("mul", ("c", 0.5), ("u", 0))),
             ("add", ("mul", ("c", -1.0), ("sin", ("x", 0))),
              ("mul", ("c", 0.25), ("exp", ("mul", ("c", -0.5), ("x", 1)))))]
    x0 = np.array([0.3, -0.2])
    uu = np.array([0.4])
    mpmath.mp.dps = 30
    sol = mpmath.odefun(lambda t, y: [to_mpmath(e, y, uu, []) for e in trees], 0,
                        [mpmath.mpf(float(v)) for v in x0])
    exact = np.array([LD(mpmath.nstr(v, 25)) for v in sol(mpmath.mpf(0.3))])
    ours = flow(trees, x0[None], uu[None], np.zeros((1, 0)), 0.3)[0]
    assert np.abs(ours - exact).max() < 1e-18


@settings(max_examples=25)
@given(_ode())
def test_enclosures_hold_the_true_flow(case: dict[str, Any]) -> None:
    model = _build(case["trees"], case["n"], case["m"], case["l"], case["X"], case["U"],
                   case["W"], case["dt"], case["order"])
    assert model.is_validated
    _check_model(model, case["trees"], case["Z"], case["dt"], ("numpy", "scalar"),
                 np.random.default_rng(case["seed"]))


@pytest.mark.skipif(not native_available(), reason="no C compiler")
@settings(max_examples=2)
@given(_ode(max_n=2, max_order=3))
def test_native_enclosures_hold_the_true_flow(case: dict[str, Any]) -> None:
    model = _build(case["trees"], case["n"], case["m"], case["l"], case["X"], case["U"],
                   case["W"], case["dt"], case["order"])
    F = model.inclusion("natural", backend="native")
    assert F.F._native_kernel() is not None, "the native kernel was not built"
    _check_model(model, case["trees"], case["Z"], case["dt"], ("native",),
                 np.random.default_rng(case["seed"]), jacobian=False)
