"""The C successor check is a proof: wherever the exported set-sequence controller returns a
level without CMPC_FLAG_UNVERIFIED, the exact successor lies in the claimed set.

The models cancel large offsets, ``x2+ = x2 + 0.1 (fmax(c + s u, 0) - c) / s + w``: in floating
point ``c + s u`` is rounded to a multiple of ulp(c), an error far above any relative margin
of the images, while the real value of the expression is ``0.1 u``. The successors are
evaluated exactly, in rational arithmetic, from the CasADi instruction list of the model (the
same graph the controller was exported from; every constant is the double it holds), and
tested exactly against the claimed set: the rows of a polytope, or the closed boxes of the
steps ``1..i-1`` of a box sequence.
"""

from __future__ import annotations

import math
import shutil
import sys
from fractions import Fraction
from typing import Any

import casadi as ca
import control
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.codegen import load
from casadi_cmpc.codegen.export import _model_fun
from casadi_cmpc.mpc.sequence import SetSequenceMPC, _members

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None or shutil.which("make") is None,
                                reason="building the export needs gcc and make")


# ------------------------------------------------------------------ exact evaluation
_BINARY = {ca.OP_ADD: lambda a, b: a + b, ca.OP_SUB: lambda a, b: a - b,
           ca.OP_MUL: lambda a, b: a * b, ca.OP_DIV: lambda a, b: a / b,
           ca.OP_FMAX: max, ca.OP_FMIN: min}
_UNARY = {ca.OP_NEG: lambda a: -a, ca.OP_SQ: lambda a: a * a, ca.OP_TWICE: lambda a: a + a,
          ca.OP_ASSIGN: lambda a: a, ca.OP_FABS: abs}


def exact_eval(fun: ca.Function, *args: Any) -> list[list[Fraction]]:
    """The outputs of the SX Function ``fun`` in exact rational arithmetic (dense column
    outputs), from its instruction list; the inputs are taken as the doubles they hold."""
    ins = [[Fraction(float(v)) for v in np.asarray(a, dtype=float).reshape(-1)] for a in args]
    out = [[Fraction(0)] * fun.numel_out(o) for o in range(fun.n_out())]
    pos = [list(fun.sparsity_out(o).find()) for o in range(fun.n_out())]
    work: dict[int, Fraction] = {}
    for k in range(fun.n_instructions()):
        op = fun.instruction_id(k)
        i = list(fun.instruction_input(k))
        o = list(fun.instruction_output(k))
        if op == ca.OP_CONST:
            work[o[0]] = Fraction(float(fun.instruction_constant(k)))
        elif op == ca.OP_INPUT:
            work[o[0]] = ins[i[0]][i[1]]
        elif op == ca.OP_OUTPUT:
            out[o[0]][pos[o[0]][o[1]]] = work[i[0]]
        elif op in _BINARY:
            work[o[0]] = _BINARY[op](work[i[0]], work[i[1]])
        elif op in _UNARY:
            work[o[0]] = _UNARY[op](work[i[0]])
        else:
            raise NotImplementedError(f"operation {op} in the exact evaluator")
    return out


def in_polytope_exact(A: np.ndarray, b: np.ndarray, y: list[Fraction]) -> bool:
    """``A y <= b`` in rational arithmetic (A, b: doubles)."""
    return all(sum((Fraction(float(a)) * v for a, v in zip(A[r], y, strict=True)),
                   Fraction(0)) <= Fraction(float(b[r])) for r in range(len(b)))


def in_polytope(A: np.ndarray, b: np.ndarray, y: list[Fraction]) -> bool:
    """``A y <= b`` decided exactly: rows settled by floating point with a margin far above
    its rounding error, the others (near their boundary) by :func:`in_polytope_exact`.

    With y in the box [lo, hi] of doubles next to it (:func:`float_bracket`), the row a
    lies between the real sums L = sum min(a lo, a hi) and U = sum max(a lo, a hi). Their
    floating-point values differ from them by at most gamma_n S (S = sum |a| max(|lo|,
    |hi|), gamma_n = n u / (1 - n u), u = 2^-53, plus underflow terms of 2^-1074 each);
    the margin ``M = 1e-12 (S + |b| + 1)`` exceeds that and the rounding of ``b -+ M`` for
    n <= 1000. So ``U_float <= b - M`` proves the row, ``L_float > b + M`` refutes it."""
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    n = A.shape[1]
    if n > 1000 or not (np.isfinite(A).all() and np.isfinite(b).all()):
        return in_polytope_exact(A, b, y)
    lo, hi = np.array([float_bracket(v) for v in y]).T
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        return in_polytope_exact(A, b, y)
    with np.errstate(over="ignore", invalid="ignore"):
        p, q = A * lo, A * hi
        U = np.maximum(p, q).sum(axis=1)
        L = np.minimum(p, q).sum(axis=1)
        S = (np.abs(A) * np.maximum(np.abs(lo), np.abs(hi))).sum(axis=1)
        M = 1e-12 * (S + np.abs(b) + 1.0)
        proved = U <= b - M
        refuted = L > b + M
    if not (np.isfinite(S).all() and np.isfinite(M).all()):
        return in_polytope_exact(A, b, y)
    if refuted.any():
        return False
    rest = np.flatnonzero(~proved)
    return in_polytope_exact(A[rest], b[rest], y)


def float_bracket(v: Fraction) -> tuple[float, float]:
    """The doubles ``lo <= v <= hi`` next to v: ``lo == hi == v`` when v is a double, else
    two adjacent doubles with ``lo < v < hi`` (beyond the largest double: it and inf)."""
    try:
        f = float(v)  # int / int: correctly rounded
    except OverflowError:
        big = float(np.finfo(float).max)
        return (big, np.inf) if v > 0 else (-np.inf, -big)
    exact = Fraction(f)
    if exact == v:
        return f, f
    return (f, float(np.nextafter(f, np.inf))) if exact < v else \
        (float(np.nextafter(f, -np.inf)), f)


def in_boxes(B: np.ndarray, y: list[Fraction]) -> bool:
    """Exact membership of y in the union of the closed boxes B (N, n, 2) of doubles.

    With y_d bracketed by adjacent doubles lo_d < y_d < hi_d, a double bound a satisfies
    ``a <= y_d`` exactly when ``a <= lo_d`` and ``y_d <= a`` exactly when ``hi_d <= a`` (no
    double lies strictly between lo_d and hi_d); when y_d is a double, lo_d = hi_d = y_d. So
    the comparisons of doubles below decide the exact inclusion."""
    if B.shape[0] == 0:
        return False
    lo, hi = np.array([float_bracket(v) for v in y]).T
    return bool(np.any(np.all((B[:, :, 0] <= lo) & (hi <= B[:, :, 1]), axis=1)))


def in_level(seq: Any, j: int, y: list[Fraction]) -> bool:
    """Exact membership of y in K_j: T, or a polytope of a set K_1..K_j (polytopic
    sequences), or a closed box of steps 1..j (box sequences)."""
    T = seq.sets[0]
    if in_polytope(T.A, T.b, y):
        return True
    for i in range(1, j + 1):
        for M in _members(seq.sets[i]):
            if isinstance(M, cm.Polytope) and in_polytope(M.A, M.b, y):
                return True
        if in_boxes(seq.steps[i - 1]["boxes"], y):
            return True
    return False


def w_points(W: cm.Box, robust: bool) -> list[np.ndarray]:
    """The disturbances whose successors are tested: the vertices of W and interior points
    on a grid (the centre alone for a nominal controller)."""
    lo, hi = np.asarray(W.lo, dtype=float), np.asarray(W.hi, dtype=float)
    if not robust:
        return [0.5 * lo + 0.5 * hi]
    return [lo + t * (hi - lo) for t in np.linspace(0.0, 1.0, 9)]


def false_verified(C: Any, ctrl: SetSequenceMPC, seq: Any, states: np.ndarray
                   ) -> tuple[int, int, list[tuple[Any, ...]]]:
    """(claims, false claims, points): the steps that C reports as proved, those whose exact
    successor leaves K_{level-1} (or whose control leaves U) for some tested w, and the
    tested points ``(x, u, w, exact f(x, u, w))``."""
    fun = _model_fun(ctrl.model)
    ws = w_points(ctrl.model.W, ctrl.robust)
    claims = bad = 0
    points = []
    for x in states:
        u, code = C.step(x)
        d = C.decode(code)
        if d["level"] in (None, 0) or d["unverified"]:
            continue
        claims += 1
        ok = bool(np.all((u >= ctrl.model.U.lo) & (u <= ctrl.model.U.hi)))
        for w in ws:
            y = exact_eval(fun, x, u, w)[0]
            ok = ok and in_level(seq, d["level"] - 1, y)
            points.append((x, u, w, y))
        bad += not ok
    return claims, bad, points


def enclosure_misses(C: Any, points: list[tuple[Any, ...]]) -> list[tuple[Any, ...]]:
    """The points where the bounds of cmpc_model_iv miss the exact value."""
    out = []
    for x, u, w, y in points:
        lo, hi = C.model_iv(x, u, w)
        if not all(Fraction(float(a)) <= v <= Fraction(float(b))
                   for a, v, b in zip(lo, y, hi, strict=True)):
            out.append((x, u, w))
    return out


# ------------------------------------------------------------------ the models
def cancelling_model(offset: float, n: int = 2, scale: float = 1.0, state_term: bool = False
                     ) -> tuple[cm.Model, ca.SX]:
    """x1+ = 0.8 x1 + 0.1 x2, x2+ = x2 + 0.1 (fmax(c + s u, 0) - c) / s + w (and, for
    n = 3, x3+ = 0.7 x3 + 0.1 (fmax(c + s x1, 0) - c) / s when ``state_term``, else
    0.7 x3 + 0.1 x1), with its LQR law. ``s`` is a power of two (exact division)."""
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    inv = 1.0 / scale

    def cancel(v: ca.SX) -> ca.SX:
        g = ca.fmax(offset + scale * v, 0) - offset
        return g if scale == 1.0 else g * inv

    rows = [0.8 * x[0] + 0.1 * x[1], x[1] + 0.1 * cancel(u) + w]
    A = np.eye(n)
    A[0, 0], A[0, 1] = 0.8, 0.1
    if n == 3:
        rows.append(0.7 * x[2] + 0.1 * (cancel(x[0]) if state_term else x[0]))
        A[2, 2], A[2, 0] = 0.7, 0.1
    Bm = np.zeros((n, 1))
    Bm[1, 0] = 0.1
    K, _, _ = control.dlqr(A, Bm, np.eye(n), np.eye(1))
    law = -ca.mtimes(ca.DM(np.asarray(K)), x)
    model = cm.Model(x=x, u=u, w=w, f=ca.vertcat(*rows), X=cm.Box([-2.0] * n, [2.0] * n),
                     U=cm.Box([-4.0], [4.0]), W=cm.Box([-0.02], [0.02]), name="cancelling")
    return model, law


def exported(model: cm.Model, law: ca.SX, directory: Any, *, robust: bool, polytopic: bool,
             eps: float, steps: int) -> tuple[Any, SetSequenceMPC, Any]:
    T = cm.Polytope.from_box(cm.Box([-0.4] * model.n, [0.4] * model.n))
    seq = cm.controllable_sets(model, T, eps, robust=robust, polytopic=polytopic, law=law,
                               assume_invariant=True, max_steps=steps, progress=False)
    ctrl = SetSequenceMPC(model, seq, local_law=law, solver="sqp", robust=robust)
    info = ctrl.export_c(directory)
    return seq, ctrl, load(info.directory)


def states_of(seq: Any, rng: np.random.Generator, k: int) -> np.ndarray:
    B = np.concatenate([s["boxes"] for s in seq.steps])
    return rng.uniform(B[:, :, 0], B[:, :, 1])[rng.choice(len(B), k)]


# ------------------------------------------------------------------ the tests
@pytest.mark.parametrize("robust, polytopic", [(True, True), (True, False), (False, True)],
                         ids=["robust-polytopic", "robust-boxes", "nominal-polytopic"])
def test_no_false_verified_flag_on_a_cancelling_offset(robust, polytopic, tmp_path):
    """x2+ = x2 + 0.1 (fmax(1e14 + u, 0) - 1e14) + w: 1e14 + u is rounded to a multiple of
    1/64, so a floating-point image is off by up to 8e-4; 600 random states of the proven
    boxes: no step reported as proved has its exact successor outside K_{level-1}."""
    model, law = cancelling_model(1e14)
    seq, ctrl, C = exported(model, law, tmp_path / "c", robust=robust, polytopic=polytopic,
                            eps=0.1, steps=4)
    states = states_of(seq, np.random.default_rng(0), 600)
    claims, bad, points = false_verified(C, ctrl, seq, states)
    assert bad == 0, f"{bad} of {claims} steps reported as proved leave K_(level-1)"
    assert claims >= 300, claims  # the check still proves most steps
    assert enclosure_misses(C, points) == []


@settings(max_examples=2, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(exponent=st.floats(8.0, 16.0), extra=st.integers(6, 14), n=st.sampled_from([2, 3]),
       polytopic=st.booleans(), seed=st.integers(0, 2 ** 16))
@example(exponent=14.0, extra=0, n=2, polytopic=True, seed=1)
@example(exponent=12.5, extra=9, n=3, polytopic=False, seed=2)
def test_random_cancelling_offsets_give_no_false_verified_flag(exponent, extra, n, polytopic,
                                                                seed, tmp_path_factory):
    """Offsets c = 10^e, e in [8, 16], scaled by s = 2^k ulp(c) (k = 0 keeps s = 1): the
    rounding of c + s u is then 2^-k-1 of the control's unit, far above the margin of a
    floating-point check and far below the sets' resolution. For 2 or 3 states (3: a second
    cancellation in the state part), box or polytopic sequences: cmpc_model_iv encloses the
    exact successor at every tested point, and no step reported as proved is false."""
    offset = float(10.0 ** exponent)
    scale = 1.0 if extra == 0 else 2.0 ** (math.frexp(float(np.spacing(offset)))[1] - 1
                                           + extra)
    model, law = cancelling_model(offset, n, scale, state_term=n == 3)
    polytopic = polytopic and n == 2  # 3-state polytopic sets cost too much here
    d = tmp_path_factory.mktemp("hyp")
    seq, ctrl, C = exported(model, law, d / "c", robust=True, polytopic=polytopic,
                            eps=0.1 if n == 2 else 0.2, steps=2 if n == 3 else 3)
    rng = np.random.default_rng(seed)
    states = states_of(seq, rng, 250)
    claims, bad, points = false_verified(C, ctrl, seq, states)
    assert bad == 0, f"{bad} of {claims} steps reported as proved leave K_(level-1)"
    assert claims >= 50, claims
    # and random points of X x U x W: the enclosure holds at all of them
    fun = _model_fun(model)
    for _ in range(100):
        x = rng.uniform(model.X.lo, model.X.hi)
        u = rng.uniform(model.U.lo, model.U.hi)
        w = rng.uniform(model.W.lo, model.W.hi)
        points.append((x, u, w, exact_eval(fun, x, u, w)[0]))
    assert enclosure_misses(C, points) == []


def test_contractive_check_claims_only_what_the_python_certificate_proves(tmp_path):
    """Contractive MPC of the cancelling model (horizon 4): the C check of the solver's
    sequence is the interval evaluation of the Python certificate's graph, so wherever C
    applies a move as checked (no CMPC_FLAG_UNVERIFIED), the Python controller, from the
    same cold start, proved the same move with its local solver alone. (A floating-point
    check accepts sequences whose interval enclosure leaves the constraints.)"""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(0.8 * x[0] + 0.1 * x[1], x[1] + 0.1 * (ca.fmax(1e14 + u, 0) - 1e14))
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-2.0, -2.0], [2.0, 2.0]),
                     U=cm.Box([-4.0], [4.0]), name="cancelling_contractive")
    ctrl = cm.ContractiveMPC(model, horizon=4, alpha=0.9, solver="sqp", mode="receding")
    C = load(ctrl.export_c(tmp_path / "c").directory)
    claims = 0
    for p in np.random.default_rng(0).uniform(-1.5, 1.5, (300, 2)):
        ctrl.reset()
        C.reset()
        r = ctrl.solve(p)
        uc, code = C.step(p)
        d = C.decode(code)
        if d["level"] != 1 or d["unverified"]:
            continue
        claims += 1
        assert r.certificate.label == "verified" and "search_time" not in r.stats, p
        assert abs(uc[0] - r.u[0]) <= 1e-12, (p, uc, r.u)
    assert claims >= 150, claims


def test_a_model_without_interval_rules_in_c_is_refused(tmp_path):
    """erfinv has an interval extension in Python but no rule in the C export: the check
    could not prove a successor, so the export is refused, naming the operation, before
    anything is written."""
    from casadi_cmpc.codegen.export import ExportError

    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(0.8 * x[0] + 0.1 * x[1], x[1] + 0.1 * u + 0.01 * ca.erfinv(0.1 * x[0]))
    model = cm.Model(x=x, u=u, f=f, X=cm.Box([-2.0, -2.0], [2.0, 2.0]),
                     U=cm.Box([-4.0], [4.0]), name="erfinv_model")
    T = cm.Polytope.from_box(cm.Box([-0.4, -0.4], [0.4, 0.4]))
    law = -ca.mtimes(ca.DM([[1.0, 2.0]]), x)
    seq = cm.controllable_sets(model, T, 0.2, law=law, assume_invariant=True, max_steps=1,
                               progress=False)
    ctrl = SetSequenceMPC(model, seq, local_law=law, solver="sqp")
    with pytest.raises(ExportError, match="OP_ERFINV"):
        ctrl.export_c(tmp_path / "c")
    assert not (tmp_path / "c").exists()


def test_exact_box_membership_at_and_between_doubles():
    """in_boxes against the plain exact comparison, at the bounds, one ulp off them and at
    values strictly between two doubles."""
    a, b = 0.1, 0.30000000000000004
    B = np.array([[[a, b], [-1.0, 1.0]]])
    up = float(np.nextafter(b, np.inf))
    eps = Fraction(1, 10 ** 30)
    for y0 in (Fraction(a), Fraction(b), Fraction(a) - eps, Fraction(b) + eps,
               Fraction(a) + eps, Fraction(b) - eps, Fraction(up),
               (Fraction(b) + Fraction(up)) / 2, Fraction(1, 3), Fraction(10) ** 400,
               -Fraction(10) ** 400):
        y = [y0, Fraction(1)]
        want = Fraction(a) <= y0 <= Fraction(b)
        assert in_boxes(B, y) is want, y0
    assert not in_boxes(np.zeros((0, 2, 2)), [Fraction(0), Fraction(0)])
    assert in_boxes(np.array([[[0.0, np.inf], [-np.inf, 0.0]]]),
                    [Fraction(10) ** 400, -Fraction(10) ** 400])


def test_polytope_membership_agrees_with_rational_arithmetic():
    """in_polytope (floating point with a margin, rational near the boundary) against
    in_polytope_exact: random rows and points, points on a facet and a hair off it."""
    rng = np.random.default_rng(7)
    hair = Fraction(1, 2 ** 80)
    for n in (1, 2, 3):
        A = rng.normal(size=(6, n))
        b = rng.uniform(0.1, 2.0, 6)
        for _ in range(300):
            y = [Fraction(float(v)) for v in rng.uniform(-2, 2, n)]
            assert in_polytope(A, b, y) == in_polytope_exact(A, b, y)
        for r in range(6):  # on facet r: a_r y = b_r exactly, then a hair outside/inside
            y = [Fraction(0)] * n
            y[0] = Fraction(float(b[r])) / Fraction(float(A[r, 0]))
            for z in (y, [y[0] + hair * (1 if A[r, 0] > 0 else -1)] + y[1:],
                      [y[0] - hair * (1 if A[r, 0] > 0 else -1)] + y[1:]):
                assert in_polytope(A, b, z) == in_polytope_exact(A, b, z)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fesetround through glibc")
def test_exported_step_answers_alike_in_every_rounding_mode(tmp_path):
    """cmpc_step sets the default floating-point environment for its interval checks (an
    overflow must round to inf there) and gives the caller's back: an application running
    in a directed rounding mode gets the controls and codes of the default mode."""
    import ctypes

    libm = ctypes.CDLL("libm.so.6")
    model, law = cancelling_model(1e14)
    seq, ctrl, C = exported(model, law, tmp_path / "c", robust=True, polytopic=True,
                            eps=0.1, steps=4)
    states = states_of(seq, np.random.default_rng(3), 60)
    ref = [C.step(x) for x in states]
    for mode in (0x400, 0x800, 0xC00):  # downward, upward, toward zero
        C.reset()
        libm.fesetround(mode)
        try:
            got = [C.step(x) for x in states]
            kept = libm.fegetround()
        finally:
            libm.fesetround(0)
        assert kept == mode  # the caller's mode given back
        assert all(np.array_equal(u, v, equal_nan=True) and a == b
                   for (u, a), (v, b) in zip(got, ref, strict=True))
