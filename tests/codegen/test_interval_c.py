"""The generated C interval evaluation (casadi_cmpc.interval._cgen) encloses the exact
value of every supported operation: a Function using them all is compiled alone with the
interval helpers and compared with mpmath at 60 digits on random points."""

from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import casadi as ca
import mpmath
import numpy as np
import pytest

from casadi_cmpc.interval._cgen import (
    PRELUDE,
    UnsupportedIntervalOp,
    c_double,
    interval_function,
    unsupported_ops,
)

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")

def _trunc(v: mpmath.mpf) -> mpmath.mpf:
    """Rounding toward zero (C's fmod keeps the sign of x; mpmath.fmod is Python's %)."""
    return mpmath.floor(v) if v >= 0 else mpmath.ceil(v)


_MP_UNARY = {
    ca.OP_ASSIGN: lambda a: a, ca.OP_NEG: lambda a: -a, ca.OP_SQ: lambda a: a * a,
    ca.OP_TWICE: lambda a: 2 * a, ca.OP_INV: lambda a: 1 / a, ca.OP_SQRT: mpmath.sqrt,
    ca.OP_EXP: mpmath.exp, ca.OP_LOG: mpmath.log, ca.OP_SIN: mpmath.sin,
    ca.OP_COS: mpmath.cos, ca.OP_TAN: mpmath.tan, ca.OP_ASIN: mpmath.asin,
    ca.OP_ACOS: mpmath.acos, ca.OP_ATAN: mpmath.atan, ca.OP_SINH: mpmath.sinh,
    ca.OP_COSH: mpmath.cosh, ca.OP_TANH: mpmath.tanh, ca.OP_ASINH: mpmath.asinh,
    ca.OP_ACOSH: mpmath.acosh, ca.OP_ATANH: mpmath.atanh, ca.OP_FABS: abs,
    ca.OP_FLOOR: mpmath.floor, ca.OP_CEIL: mpmath.ceil, ca.OP_SIGN: mpmath.sign,
    ca.OP_NOT: lambda a: mpmath.mpf(a == 0), ca.OP_ERF: mpmath.erf,
    ca.OP_LOG1P: mpmath.log1p, ca.OP_EXPM1: mpmath.expm1,
}
_MP_BINARY = {
    ca.OP_ADD: lambda a, b: a + b, ca.OP_SUB: lambda a, b: a - b,
    ca.OP_MUL: lambda a, b: a * b, ca.OP_DIV: lambda a, b: a / b,
    ca.OP_POW: mpmath.power, ca.OP_CONSTPOW: mpmath.power, ca.OP_ATAN2: mpmath.atan2,
    ca.OP_FMIN: min, ca.OP_FMAX: max, ca.OP_LT: lambda a, b: mpmath.mpf(a < b),
    ca.OP_LE: lambda a, b: mpmath.mpf(a <= b), ca.OP_EQ: lambda a, b: mpmath.mpf(a == b),
    ca.OP_NE: lambda a, b: mpmath.mpf(a != b),
    ca.OP_AND: lambda a, b: mpmath.mpf(a != 0 and b != 0),
    ca.OP_OR: lambda a, b: mpmath.mpf(a != 0 or b != 0),
    ca.OP_IF_ELSE_ZERO: lambda c, x: x if c != 0 else mpmath.mpf(0),
    ca.OP_COPYSIGN: lambda a, b: abs(a) if b >= 0 else -abs(a),
    ca.OP_FMOD: lambda a, b: a - b * _trunc(a / b), ca.OP_HYPOT: mpmath.hypot,
    ca.OP_REMAINDER: lambda a, b: a - b * mpmath.nint(a / b),
}


def mp_eval(fun: ca.Function, x: np.ndarray) -> list[mpmath.mpf]:
    """Output 0 of ``fun`` at the doubles x, evaluated by mpmath at 60 digits."""
    work: dict[int, mpmath.mpf] = {}
    out = [mpmath.mpf(0)] * fun.numel_out(0)
    with mpmath.workdps(60):
        for k in range(fun.n_instructions()):
            op = fun.instruction_id(k)
            i = list(fun.instruction_input(k))
            o = list(fun.instruction_output(k))
            if op == ca.OP_CONST:
                work[o[0]] = mpmath.mpf(float(fun.instruction_constant(k)))
            elif op == ca.OP_INPUT:
                work[o[0]] = mpmath.mpf(float(x[i[1]]))
            elif op == ca.OP_OUTPUT:
                out[o[1]] = work[i[0]]
            elif op in _MP_UNARY:
                work[o[0]] = _MP_UNARY[op](work[i[0]])
            else:
                work[o[0]] = _MP_BINARY[op](work[i[0]], work[i[1]])
    return out


def all_ops_function() -> ca.Function:
    """Every operation with a rule, on x in [-2, 2] x [0.5, 2] (inside all domains)."""
    v = ca.SX.sym("v", 2)
    x, y = v[0], v[1]
    e = [
        ca.exp(x) * y, ca.log(1 + x ** 2), ca.sqrt(x ** 2 + y ** 2 + 0.1),
        ca.sin(3 * x) + ca.cos(y), ca.tan(0.5 * x), ca.atan(x / y), ca.atan2(x, y),
        ca.atan2(y, -x), ca.tanh(x), ca.sinh(x), ca.cosh(x), ca.asinh(x),
        ca.acosh(1.5 + x ** 2), ca.atanh(0.5 * ca.tanh(x)), ca.asin(0.5 * ca.sin(x)),
        ca.acos(0.5 * ca.cos(x)), ca.erf(x), x ** 3, 1 / (x ** 2 + 0.01), y ** 2.5,
        y ** -1.5, y ** x, ca.power(y, 3), ca.hypot(x, y), ca.fmin(x, y), ca.fmax(x, -y),
        ca.fabs(x), ca.floor(3 * x), ca.ceil(3 * x), ca.sign(x), ca.fmod(x, y),
        ca.remainder(x, y), ca.copysign(y, x), ca.if_else(x < y, x * y, x - y),
        ca.if_else(ca.logic_and(x > 0, y > 1), 1.0, 2.0),
        ca.if_else(ca.logic_or(x <= 0, y != 1), x, y), ca.if_else(x == y, 1.0, 0.0),
        ca.log1p(x ** 2), ca.expm1(x), (x + 1e15) - 1e15, 2 * x, -x, x * 0.0,
        ca.sin(x * 1e9), ca.cos(x + 1e9),
    ]
    return ca.Function("allops", [v], [ca.vertcat(*e)])


def compile_interval(fun: ca.Function, directory: Path) -> ctypes.CDLL:
    """A shared library with ``void eval(const double *lo, const double *hi, double *olo,
    double *ohi)``: the generated evaluation of the one-input, one-output ``fun``."""
    src = ("#include <float.h>\n#include <math.h>\n" + PRELUDE
           + interval_function(fun, "gen_iv") + """
void eval(const double *lo, const double *hi, double *olo, double *ohi) {
    const double *il[1], *ih[1];
    double *ol[1], *oh[1];
    il[0] = lo; ih[0] = hi; ol[0] = olo; oh[0] = ohi;
    gen_iv(il, ih, ol, oh);
}
""")
    (directory / "iv.c").write_text(src)
    subprocess.run(["gcc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-O2", "-shared",
                    "-fPIC", str(directory / "iv.c"), "-o", str(directory / "iv.so"), "-lm"],
                   check=True, capture_output=True, text=True)
    lib = ctypes.CDLL(str(directory / "iv.so"))
    dp = ctypes.POINTER(ctypes.c_double)
    lib.eval.argtypes = [dp, dp, dp, dp]
    lib.eval.restype = None
    return lib


def call(lib: ctypes.CDLL, lo: np.ndarray, hi: np.ndarray, k: int
         ) -> tuple[np.ndarray, np.ndarray]:
    lo = np.ascontiguousarray(lo, dtype=float)
    hi = np.ascontiguousarray(hi, dtype=float)
    olo, ohi = np.empty(k), np.empty(k)
    dp = ctypes.POINTER(ctypes.c_double)
    lib.eval(lo.ctypes.data_as(dp), hi.ctypes.data_as(dp), olo.ctypes.data_as(dp),
             ohi.ctypes.data_as(dp))
    return olo, ohi


def test_every_operation_encloses_the_60_digit_value(tmp_path):
    fun = all_ops_function()
    assert unsupported_ops(fun) == []
    lib = compile_interval(fun, tmp_path)
    rng = np.random.default_rng(5)
    pts = np.column_stack([rng.uniform(-2, 2, 300), rng.uniform(0.5, 2, 300)])
    pts[:4] = [[0.0, 1.0], [1.0, 1.0], [-2.0, 0.5], [2.0, 2.0]]  # ties, domain edges
    k = fun.numel_out(0)
    widths = []
    for p in pts:
        lo, hi = call(lib, p, p, k)
        exact = mp_eval(fun, p)
        for j in range(k):
            assert not (np.isnan(lo[j]) or np.isnan(hi[j])), (j, p)
            assert mpmath.mpf(float(lo[j])) <= exact[j] <= mpmath.mpf(float(hi[j])), \
                (j, p, lo[j], hi[j], exact[j])
            widths.append((hi[j] - lo[j]) / max(1.0, abs(float(exact[j]))))
    # outward rounding, not a loose bound (the offset cancellation and sin(1e9 x) aside)
    assert np.median(widths) < 1e-12


def test_interval_inputs_and_domain_edges(tmp_path):
    """Wide input intervals still enclose (random points of the box); an operand leaving
    the domain gives NaN on both sides."""
    v = ca.SX.sym("v", 2)
    fun = ca.Function("dom", [v], [ca.vertcat(ca.log(v[0]), ca.sqrt(v[0]), v[1] / v[0],
                                              ca.sin(v[1]) * v[0], ca.exp(v[1]) - v[0])])
    lib = compile_interval(fun, tmp_path)
    lo, hi = call(lib, np.array([0.5, -1.0]), np.array([2.0, 3.0]), 5)
    rng = np.random.default_rng(1)
    for p in np.column_stack([rng.uniform(0.5, 2.0, 200), rng.uniform(-1.0, 3.0, 200)]):
        ex = mp_eval(fun, p)
        assert all(mpmath.mpf(float(a)) <= e <= mpmath.mpf(float(b))
                   for a, e, b in zip(lo, ex, hi, strict=True))
    lo, hi = call(lib, np.array([-0.5, 0.0]), np.array([2.0, 1.0]), 5)
    assert np.isnan(lo[:3]).all() and np.isnan(hi[:3]).all()  # log, sqrt, division by 0
    assert np.isfinite(lo[3:]).all() and np.isfinite(hi[3:]).all()


def test_rounding_at_overflow_and_subnormals(tmp_path):
    """x * y overflowing, a product underflowing to 0, a sum of opposite large values: the
    bounds hold the exact result (never a finite bound on the wrong side)."""
    v = ca.SX.sym("v", 2)
    fun = ca.Function("edge", [v], [ca.vertcat(v[0] * v[1], v[0] + v[1], v[0] - v[1])])
    lib = compile_interval(fun, tmp_path)
    cases = [(1e300, 1e10), (-1e300, 1e10), (1e-300, 1e-300), (-1e-300, 1e-300),
             (5e-324, 0.5), (1.7976931348623157e308, 1.7976931348623157e308),
             (0.1, -0.1), (0.0, -0.0)]
    for a, b in cases:
        p = np.array([a, b])
        lo, hi = call(lib, p, p, 3)
        ex = mp_eval(fun, p)
        for j in range(3):
            assert mpmath.mpf(float(lo[j])) <= ex[j] <= mpmath.mpf(float(hi[j])), (a, b, j)
            # thin only where the result is exact (a sum that is zero or subnormal)
            assert lo[j] < hi[j] or mpmath.mpf(float(lo[j])) == ex[j], (a, b, j)


def test_unsupported_operations_are_named():
    v = ca.SX.sym("v")
    fun = ca.Function("f", [v], [ca.erfinv(v) + v])
    assert unsupported_ops(fun) == ["OP_ERFINV"]
    with pytest.raises(UnsupportedIntervalOp, match="OP_ERFINV"):
        interval_function(fun, "f_iv")


def test_constants_are_exact_hexadecimal_literals():
    assert c_double(0.1) == "0x1.999999999999ap-4"
    assert c_double(float("inf")) == "INFINITY" and c_double(float("-inf")) == "-INFINITY"
    assert c_double(float("nan")) == "NAN"
    assert float.fromhex(c_double(5e-324)) == 5e-324


@pytest.mark.parametrize("mode", ["nearest", "upward", "downward", "toward_zero"])
def test_exp_polynomial_encloses_in_every_rounding_mode(tmp_path, mode):
    """The C exp (range reduction, Taylor polynomial, the bits of 2^k) encloses e^x at
    60 digits on thin and wide boxes from below the subnormal range to overflow, in every
    FPU rounding mode, and stays within 2^-40 relative where e^x is a normal float."""
    import ctypes.util

    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    codes = {"nearest": 0, "downward": 0x400, "upward": 0x800, "toward_zero": 0xC00}
    if libm.fegetround() != 0:
        pytest.skip("fesetround not available as expected")
    v = ca.SX.sym("v", 1)
    lib = compile_interval(ca.Function("e", [v], [ca.exp(v)]), tmp_path)
    rng = np.random.default_rng(11)
    edges = [-760.0, -745.2, -708.4, -700.0000001, -700.0, -699.9999999, -1e-300, 0.0,
             5e-324, 1e-16, 0.34657359, 0.6931471805599453, 1.0, 88.7, 708.0, 709.0,
             709.0000001, 709.78, 709.79, 800.0]
    xs = np.concatenate([edges, rng.uniform(-40, 40, 600), rng.uniform(-745, 710, 600)])
    mpmath.mp.prec = 200
    assert libm.fesetround(ctypes.c_int(codes[mode])) == 0
    try:
        res = [call(lib, np.array([x]), np.array([x]), 1) for x in xs]
        wide = [call(lib, np.array([x]), np.array([x + 0.5]), 1) for x in xs[:200]]
    finally:
        libm.fesetround(ctypes.c_int(0))
    for x, (lo, hi) in zip(xs, res, strict=True):
        e = mpmath.exp(mpmath.mpf(float(x)))
        assert mpmath.mpf(float(lo[0])) <= e <= mpmath.mpf(float(hi[0])), (mode, x, lo, hi)
        if -700 <= x <= 709:
            assert (hi[0] - lo[0]) <= 2.0 ** -40 * float(e), (mode, x, lo, hi)
    for x, (lo, hi) in zip(xs[:200], wide, strict=True):
        assert mpmath.mpf(float(lo[0])) <= mpmath.exp(mpmath.mpf(float(x)))
        assert mpmath.exp(mpmath.mpf(float(x + 0.5))) <= mpmath.mpf(float(hi[0]))
    lo, hi = call(lib, np.array([np.nan]), np.array([np.nan]), 1)
    assert np.isnan(lo[0]) and np.isnan(hi[0])
    lo, hi = call(lib, np.array([-np.inf]), np.array([np.inf]), 1)
    assert lo[0] == 0.0 and hi[0] == np.inf


@pytest.mark.parametrize("mode", ["nearest", "upward", "downward", "toward_zero"])
def test_sin_cos_polynomial_encloses_in_every_rounding_mode(tmp_path, mode):
    """The C sin and cos (reduction by pi/2 in five exact pieces, Taylor polynomials, no
    libm) enclose the exact values at 60 digits in every FPU rounding mode: at the doubles
    nearest to k pi/2 and their neighbours (where the reduction cancels) up to the limit
    |x| = 1e8, at random points of every magnitude, on wide boxes holding extrema, and they
    stay within 2^-40 relative where the value is not tiny."""
    import ctypes.util

    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    codes = {"nearest": 0, "downward": 0x400, "upward": 0x800, "toward_zero": 0xC00}
    if libm.fegetround() != 0:
        pytest.skip("fesetround not available as expected")
    v = ca.SX.sym("v", 1)
    lib = compile_interval(ca.Function("sc", [v], [ca.vertcat(ca.sin(v), ca.cos(v))]),
                           tmp_path)
    rng = np.random.default_rng(5)
    mpmath.mp.prec = 200
    ks = np.concatenate([np.arange(1, 200), rng.integers(1, 63_000_000, 200)])
    near = np.array([float(mpmath.mpf(int(k)) * mpmath.pi / 2) for k in ks])
    near = np.concatenate([near, -near])
    xs = np.concatenate([near, np.nextafter(near, np.inf), np.nextafter(near, -np.inf),
                         [0.0, -0.0, 5e-324, -5e-324, 1e-300, 0.7853981633974483,
                          0.7853981633974484, 1e8, -1e8, 99999999.99999999],
                         rng.uniform(-10, 10, 300), rng.uniform(-1e8, 1e8, 300),
                         10.0 ** rng.uniform(-300, 8, 300) * rng.choice([-1, 1], 300)])
    a = rng.uniform(-30, 30, 200)
    b = a + 10.0 ** rng.uniform(-6, 0.8, 200)  # (in the default rounding mode)
    assert libm.fesetround(ctypes.c_int(codes[mode])) == 0
    try:
        res = [call(lib, np.array([x]), np.array([x]), 2) for x in xs]
        wide = [call(lib, np.array([x]), np.array([y]), 2) for x, y in zip(a, b, strict=True)]
    finally:
        libm.fesetround(ctypes.c_int(0))
    for x, (lo, hi) in zip(xs, res, strict=True):
        xm = mpmath.mpf(float(x))
        for j, e in enumerate((mpmath.sin(xm), mpmath.cos(xm))):
            assert mpmath.mpf(float(lo[j])) <= e <= mpmath.mpf(float(hi[j])), \
                (mode, float(x).hex(), j, lo[j], hi[j])
            if abs(e) > 1e-290:
                assert hi[j] - lo[j] <= 2.0 ** -40 * float(abs(e)), (mode, x, j, lo, hi)
    for x, y, (lo, hi) in zip(a, b, wide, strict=True):
        for t in np.clip(np.linspace(x, y, 9), x, y):
            tm = mpmath.mpf(float(t))
            for j, e in enumerate((mpmath.sin(tm), mpmath.cos(tm))):
                assert mpmath.mpf(float(lo[j])) <= e <= mpmath.mpf(float(hi[j])), (mode, x, y)
    lo, hi = call(lib, np.array([np.nan]), np.array([np.nan]), 2)
    assert np.isnan(lo).all() and np.isnan(hi).all()
    lo, hi = call(lib, np.array([1e8]), np.array([1.5e8]), 2)  # beyond the limit: [-1, 1]
    assert (lo == -1.0).all() and (hi == 1.0).all()
