"""C source of outward-rounded interval evaluations of CasADi SX Functions.

:func:`interval_function` walks the instruction list of a Function (``n_instructions``,
``instruction_id``/``input``/``output``/``constant``) and writes one straight-line C
function that evaluates its natural interval inclusion: every work slot holds an interval
``civ {lo, hi}`` and every operation calls the helper of :data:`PRELUDE` of the same name.

Rounding rules (those of :mod:`casadi_cmpc.interval.arith`):

* ``+ - * /`` and ``sqrt`` (correctly rounded by IEEE 754): a lower bound ``v`` becomes
  ``v - (|v| 2**-52 + 2**-1074)`` and an upper bound ``v + (|v| 2**-52 + 2**-1074)``
  (``civ_dn``, ``civ_up``; the rule of the Python backend for products). That is at least
  the next float toward -inf (+inf), at most two ulps further, in every rounding mode; the
  exact result of a rounded operation lies within one ulp of it, so the moved bound holds
  it. The step is that of ``nextafter`` or larger, and cheaper (two floating-point
  operations, no moves through the integer registers). A product by a constant of the
  instruction list takes two products instead of four (``civ_mulc``). A lower bound that
  overflowed to +inf becomes the largest float first (an upper bound -inf the most
  negative one). An overflow must round to an infinity, as it does in the default
  floating-point environment: every entry point that evaluates these rules (a batch
  kernel, an exported controller's step) sets that environment (round to nearest,
  subnormals kept) and gives the caller's back (``CIV_ENV_ENTER``/``CIV_ENV_LEAVE``).
* libm functions (exp, log, sin, ...): a margin of ``2**-44`` relative (256 ulps) plus
  ``2**-1060`` absolute, then one ulp; results are intersected with the range of the
  function. ``exp``, ``sin`` and ``cos`` are computed here, without libm, in straight-line
  arithmetic that a compiler runs in SIMD lanes: ``exp`` within ``2**-48`` relative;
  ``sin``/``cos`` after a reduction by ``k pi/2`` in five exact pieces, within ``2**-47``
  relative plus ``|k| 2**-141``, with the margin plus ``|k| 2**-135`` (both in every
  rounding mode). ``sin``/``cos``: the values at the ends, and ``1`` (``-1``) where the box
  (conservatively) holds a maximum (minimum), ``[-1, 1]`` for a box of width ``2 pi`` or
  beyond ``|t| = 1e8``; ``tan``: increasing between poles, possibly undefined where a pole
  may lie in the box (the rules of the Python backend).
* Exact operations (negation, ``fabs``, ``fmin``/``fmax``, ``floor``/``ceil``, ``sign``,
  comparisons, ``if_else``) are not widened.
* A NaN bound means "possibly undefined": it is two-sided, it propagates through every
  operation (``fmin``/``fmax``/comparisons included), and an operation on an operand that
  leaves its domain (``log`` of a non-positive bound, division by an interval holding 0,
  ...) gives it. The callers map NaN to ``[-inf, inf]``.

Constants of the instruction list are exact doubles (written as C99 hexadecimal literals).
Operations without a rule here (``erfinv``, calls of other Functions, ...) raise
:class:`UnsupportedIntervalOp`.
"""

from __future__ import annotations

import math
from typing import Any

import casadi as ca

from ..exceptions import DimensionError, FreeSymbolError, UnsupportedOperationError

__all__ = ["PRELUDE", "UnsupportedIntervalOp", "interval_function", "unsupported_ops",
           "c_double"]


class UnsupportedIntervalOp(ValueError):
    """The Function holds an operation without an interval rule in C."""


# op code -> C helper (civ -> civ, or (civ, civ) -> civ)
_UNARY = {
    ca.OP_ASSIGN: None, ca.OP_NEG: "civ_neg", ca.OP_SQ: "civ_sq", ca.OP_TWICE: "civ_twice",
    ca.OP_INV: "civ_inv", ca.OP_SQRT: "civ_sqrt", ca.OP_EXP: "civ_exp", ca.OP_LOG: "civ_log",
    ca.OP_SIN: "civ_sin", ca.OP_COS: "civ_cos", ca.OP_TAN: "civ_tan", ca.OP_ASIN: "civ_asin",
    ca.OP_ACOS: "civ_acos", ca.OP_ATAN: "civ_atan", ca.OP_SINH: "civ_sinh",
    ca.OP_COSH: "civ_cosh", ca.OP_TANH: "civ_tanh", ca.OP_ASINH: "civ_asinh",
    ca.OP_ACOSH: "civ_acosh", ca.OP_ATANH: "civ_atanh", ca.OP_FABS: "civ_fabs",
    ca.OP_FLOOR: "civ_floor", ca.OP_CEIL: "civ_ceil", ca.OP_SIGN: "civ_sign",
    ca.OP_NOT: "civ_not", ca.OP_ERF: "civ_erf", ca.OP_LOG1P: "civ_log1p",
    ca.OP_EXPM1: "civ_expm1",
}
_BINARY = {
    ca.OP_ADD: "civ_add", ca.OP_SUB: "civ_sub", ca.OP_MUL: "civ_mul", ca.OP_DIV: "civ_div",
    ca.OP_POW: "civ_pow", ca.OP_CONSTPOW: "civ_pow", ca.OP_ATAN2: "civ_atan2",
    ca.OP_FMIN: "civ_fmin", ca.OP_FMAX: "civ_fmax", ca.OP_LT: "civ_lt", ca.OP_LE: "civ_le",
    ca.OP_EQ: "civ_eq", ca.OP_NE: "civ_ne", ca.OP_AND: "civ_and", ca.OP_OR: "civ_or",
    ca.OP_IF_ELSE_ZERO: "civ_if_else_zero", ca.OP_COPYSIGN: "civ_copysign",
    ca.OP_FMOD: "civ_fmod", ca.OP_REMAINDER: "civ_remainder", ca.OP_HYPOT: "civ_hypot",
}
_STRUCTURAL = {ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT}


def _op_name(op: int) -> str:
    for name in dir(ca):
        if name.startswith("OP_") and getattr(ca, name) == op:
            return name
    return f"op {op}"


def c_double(v: float) -> str:
    """C99 text of a double, exact: a hexadecimal literal, ``INFINITY``/``-INFINITY`` or
    ``NAN``."""
    v = float(v)
    if math.isnan(v):
        return "NAN"
    if math.isinf(v):
        return "INFINITY" if v > 0 else "-INFINITY"
    return v.hex()


def _as_sx(fun: ca.Function) -> ca.Function:
    """``fun`` checked as for the Python interval compiler (SX or expandable, no free
    symbols, dense inputs; a :class:`~._derivative.ParamFunction` as it is), its refusals
    raised as :class:`UnsupportedIntervalOp`."""
    from .compiler import _as_sx_function

    try:
        return _as_sx_function(fun, allow_param=True)
    except (UnsupportedOperationError, FreeSymbolError, DimensionError) as exc:
        raise UnsupportedIntervalOp(str(exc)) from exc


def unsupported_ops(fun: ca.Function) -> list[str]:
    """Names of the operations of ``fun`` without an interval rule in C (empty: all have
    one)."""
    fun = _as_sx(fun)
    bad = {fun.instruction_id(k) for k in range(fun.n_instructions())}
    bad -= set(_UNARY) | set(_BINARY) | _STRUCTURAL
    return sorted(_op_name(op) for op in bad)


def interval_function(fun: Any, name: str) -> str:
    """C text of ``static void name(il, ih, ol, oh)``: the natural interval inclusion of the
    SX Function ``fun``, outward rounded (see the module notes).

    ``fun`` may be a :class:`~casadi_cmpc.interval._derivative.ParamFunction` (e.g.
    :meth:`casadi_cmpc.Model.interval_map` of a closed loop or of a validated ODE model):
    its parameters are written as constants, a possibly rounded one (``derived``) widened
    as by the Python compiler, an interval-valued one as its interval.

    ``il[i]``/``ih[i]`` point to the lower/upper bounds of input ``i`` (dense, its
    ``numel`` entries); ``ol[o]``/``oh[o]`` receive the bounds of output ``o`` (dense,
    column-major; structural zeros are written as ``[0, 0]``). A bound may come out NaN
    ("possibly undefined", both sides); the caller decides what that means.

    Raises
    ------
    UnsupportedIntervalOp
        ``fun`` holds an operation without a rule (listed in the message), or free
        symbols, or a sparse input.
    """
    fun = _as_sx(fun)
    bad = unsupported_ops(fun)
    if bad:
        raise UnsupportedIntervalOp(
            f"'{fun.name()}' holds operations without an outward-rounded interval rule in the "
            f"C export: {', '.join(bad)}")
    body: list[str] = []
    used: set[int] = set()
    for o in range(fun.n_out()):  # structural zeros of a sparse output
        sp = fun.sparsity_out(o)
        if not sp.is_dense():
            body.append(f"    for (k = 0; k < {sp.numel()}; ++k) ol[{o}][k] = oh[{o}][k] = "
                        "0.0;")
    nz_pos = [list(fun.sparsity_out(o).find()) for o in range(fun.n_out())]
    consts: dict[int, float] = {}  # slot -> the finite constant it holds
    interval_of = getattr(fun, "instruction_bounds", None)
    widen = frozenset(getattr(fun, "derived", ()))
    for k in range(fun.n_instructions()):
        op = fun.instruction_id(k)
        ins = list(fun.instruction_input(k))
        outs = list(fun.instruction_output(k))
        held = dict(consts)  # the constants of the operands
        if op != ca.OP_OUTPUT:
            consts.pop(outs[0], None)
        if op == ca.OP_CONST:
            v = float(fun.instruction_constant(k))
            used.add(outs[0])
            iv = interval_of(k) if interval_of is not None else None
            if iv is not None or k in widen:
                from .compiler import _widen_constant

                lo, hi = iv if iv is not None else _widen_constant(v)
                body.append(f"    v{outs[0]}.lo = {c_double(lo)}; v{outs[0]}.hi = "
                            f"{c_double(hi)}; /* [{lo!r}, {hi!r}] */")
                continue
            c = c_double(v)
            note = f" /* {v!r} */" if math.isfinite(v) else ""
            body.append(f"    v{outs[0]}.lo = v{outs[0]}.hi = {c};{note}")
            if math.isfinite(v):
                consts[outs[0]] = v
        elif op == ca.OP_MUL and (ins[0] in held) != (ins[1] in held):
            used.add(outs[0])
            var, c = (ins[1], held[ins[0]]) if ins[0] in held else (ins[0], held[ins[1]])
            body.append(f"    v{outs[0]} = civ_mulc(v{var}, {c_double(c)});")
        elif op == ca.OP_INPUT:
            used.add(outs[0])
            body.append(f"    v{outs[0]}.lo = il[{ins[0]}][{ins[1]}]; "
                        f"v{outs[0]}.hi = ih[{ins[0]}][{ins[1]}];")
        elif op == ca.OP_OUTPUT:
            oi, j = outs[0], nz_pos[outs[0]][outs[1]]
            body.append(f"    ol[{oi}][{j}] = v{ins[0]}.lo; oh[{oi}][{j}] = v{ins[0]}.hi;")
        elif op in _UNARY:
            used.add(outs[0])
            fn = _UNARY[op]
            expr = f"v{ins[0]}" if fn is None else f"{fn}(v{ins[0]})"
            body.append(f"    v{outs[0]} = {expr};")
        else:
            used.add(outs[0])
            body.append(f"    v{outs[0]} = {_BINARY[op]}(v{ins[0]}, v{ins[1]});")
    slots = sorted(used)
    decl = []
    if slots:
        names = [f"v{s}" for s in slots]
        for i in range(0, len(names), 12):
            decl.append("    civ " + ", ".join(names[i:i + 12]) + ";")
    if any("for (k = 0;" in b for b in body):
        decl.append("    int k;")
    tail = ["    " + " ".join(f"(void)v{s};" for s in slots[i:i + 12])
            for i in range(0, len(slots), 12)]
    return "\n".join([
        f"/* natural interval inclusion of '{fun.name()}', outward rounded "
        f"({fun.n_instructions()} instructions) */",
        f"static void {name}(const double *const *il, const double *const *ih, "
        "double *const *ol, double *const *oh) {",
        *decl, *body,
        "    (void)il; (void)ih; (void)ol; (void)oh;", *tail, "}", ""])


PRELUDE = r"""
#include <string.h>
/* ------------------------------------------------ interval arithmetic, outward rounded */
/* An interval civ {lo, hi} holds every real its operation can take on its operands; NaN
 * (both bounds) means "possibly undefined". +,-,*,/,sqrt move each rounded bound outward by
 * at least one ulp; libm functions add 2^-44 relative + 2^-1060 absolute (256 ulps), then
 * at least one ulp. */
#if defined(__FAST_MATH__)
#error "the interval check needs IEEE arithmetic: do not compile with -ffast-math"
#endif
#if defined(FLT_EVAL_METHOD) && FLT_EVAL_METHOD == 2
#error "the interval check needs double evaluation in double precision (e.g. -mfpmath=sse)"
#endif

typedef struct { double lo, hi; } civ;

/* The rules are proven for the default floating-point environment: round to nearest,
 * subnormals kept (no flush-to-zero, no denormals-are-zero). In a directed rounding mode
 * an overflow gives the largest float instead of an infinity, and with flush-to-zero a
 * subnormal bound becomes 0: a bound could then miss the exact value. So every entry point
 * that evaluates them (a batch kernel, an exported controller's step) sets the default
 * environment (exceptions masked) and gives the caller's back on return. */
#if defined(__SSE2__) || defined(__x86_64__)
#include <xmmintrin.h>
#define CIV_ENV_ENTER unsigned int civ_csr_ = _mm_getcsr(); _mm_setcsr(0x1F80u)
#define CIV_ENV_LEAVE _mm_setcsr(civ_csr_)
#else
#include <fenv.h>
#define CIV_ENV_ENTER fenv_t civ_env_; feholdexcept(&civ_env_); fesetenv(FE_DFL_ENV)
#define CIV_ENV_LEAVE fesetenv(&civ_env_)
#endif

/* every rule inlined where it is used (a compiler then runs a batch loop in SIMD lanes) */
#ifndef CIV_INLINE
#if defined(__GNUC__) || defined(__clang__)
#define CIV_INLINE static inline __attribute__((always_inline))
#else
#define CIV_INLINE static inline
#endif
#endif

#define CIV_RL 0x1p-44
#define CIV_AL 0x1p-1060
#define CIV_TINY 0x1p-1074
#define CIV_PI_HI 0x1.921fb54442d19p+1      /* above pi */
#define CIV_PI_LO 0x1.921fb54442d18p+1      /* below pi */
#define CIV_HALF_PI_HI 0x1.921fb54442d19p+0 /* above pi / 2 */
#define CIV_SIN_SAFE 1e8                    /* beyond: sin, cos in [-1, 1] */

/* A rounded bound v moved outward by |v| 2^-52 + 2^-1074: at least to the next float toward
 * -inf (civ_dn) or +inf (civ_up), in every rounding mode (|v| 2^-52 >= ulp(v) for a normal v,
 * 2^-1074 is the spacing of the subnormals). The exact result of one rounded operation lies
 * within one ulp of v, so the moved bound holds it. An overflowed lower bound (+inf) is a
 * finite real above the largest float: it becomes DBL_MAX first (-inf as an upper bound
 * -DBL_MAX). NaN stays NaN, -inf (+inf) stays as a lower (upper) bound.
 * The rules of + - * / sqrt fabs sq exp fmin fmax are written without branches (selects),
 * so that a compiler can run one rule on several boxes at once (SIMD). */
CIV_INLINE double civ_dn(double v) {
    v = v > DBL_MAX ? DBL_MAX : v;
    return v - (fabs(v) * 0x1p-52 + CIV_TINY);
}

CIV_INLINE double civ_up(double v) {
    v = v < -DBL_MAX ? -DBL_MAX : v;
    return v + (fabs(v) * 0x1p-52 + CIV_TINY);
}

/* a libm result as a lower / upper bound (an overflowed lower bound is a huge finite value) */
CIV_INLINE double civ_dnf(double v) {
    v = v > DBL_MAX ? DBL_MAX : v;
    return civ_dn(v - (fabs(v) * CIV_RL + CIV_AL));
}

CIV_INLINE double civ_upf(double v) {
    v = v < -DBL_MAX ? -DBL_MAX : v;
    return civ_up(v + (fabs(v) * CIV_RL + CIV_AL));
}

CIV_INLINE civ civ_make(double lo, double hi) {
    civ r;
    r.lo = lo <= hi ? lo : NAN; /* false also for a NaN bound: both sides NaN */
    r.hi = lo <= hi ? hi : NAN;
    return r;
}

CIV_INLINE civ civ_nan(void) { return civ_make(NAN, NAN); }
CIV_INLINE int civ_isnan(civ a) { return a.lo != a.lo || a.hi != a.hi; }
CIV_INLINE double civ_min(double a, double b) { return a < b ? a : b; }
CIV_INLINE double civ_max(double a, double b) { return a > b ? a : b; }
/* min, max that are NaN when an operand is */
CIV_INLINE double civ_minn(double a, double b) {
    double m = a < b ? a : b; /* b where unordered */
    return a != a ? a : m;
}
CIV_INLINE double civ_maxn(double a, double b) {
    double m = a > b ? a : b;
    return a != a ? a : m;
}
/* v, or NaN where the interval b holds 0 (a divisor) */
CIV_INLINE double civ_nz(civ b, double v) {
    return civ_max(b.lo, -b.hi) > 0.0 ? v : NAN; /* b.lo > 0 or b.hi < 0 */
}

/* A rounded sum or difference v moved outward by |v| 2^-52 (civ_dns, civ_ups): a sum whose
 * exact value is subnormal or zero is exact (no absolute step needed); otherwise as civ_dn.
 * These are the rules of the Python backends, bit for bit. */
CIV_INLINE double civ_dns(double v) {
    v = v > DBL_MAX ? DBL_MAX : v;
    return v - fabs(v) * 0x1p-52;
}

CIV_INLINE double civ_ups(double v) {
    v = v < -DBL_MAX ? -DBL_MAX : v;
    return v + fabs(v) * 0x1p-52;
}

/* ---- arithmetic */
CIV_INLINE civ civ_add(civ a, civ b) {
    return civ_make(civ_dns(a.lo + b.lo), civ_ups(a.hi + b.hi));
}

CIV_INLINE civ civ_sub(civ a, civ b) {
    return civ_make(civ_dns(a.lo - b.hi), civ_ups(a.hi - b.lo));
}

CIV_INLINE civ civ_neg(civ a) { return civ_make(-a.hi, -a.lo); }

/* 2 a: exact, except an overflowed lower bound (a real above the largest float) */
CIV_INLINE civ civ_twice(civ a) {
    double lo = a.lo + a.lo, hi = a.hi + a.hi;
    return civ_make(lo > DBL_MAX ? DBL_MAX : lo, hi < -DBL_MAX ? -DBL_MAX : hi);
}

/* a * b: NaN when a product is NaN (0 times an infinite bound) */
CIV_INLINE civ civ_mul(civ a, civ b) {
    double p1 = a.lo * b.lo, p2 = a.lo * b.hi, p3 = a.hi * b.lo, p4 = a.hi * b.hi;
    return civ_make(civ_dn(civ_min(civ_min(p1, p2), civ_min(p3, p4))),
                    civ_up(civ_maxn(civ_maxn(p1, p2), civ_maxn(p3, p4))));
}

/* a * c for a finite constant c: civ_mul with two products (the sign tests are resolved
 * when compiled; 0 x = 0 for every real x) */
CIV_INLINE civ civ_mulc(civ a, double c) {
    civ p = civ_make(civ_dn(a.lo * c), civ_up(a.hi * c));
    civ n = civ_make(civ_dn(a.hi * c), civ_up(a.lo * c));
    civ z = civ_make(a.lo != a.lo ? NAN : 0.0, a.hi != a.hi ? NAN : 0.0);
    return c > 0.0 ? p : (c < 0.0 ? n : z);
}

/* a 0: exactly 0, NaN where a is NaN (possibly undefined) */
CIV_INLINE civ civ_zero_of(civ a) {
    civ r;
    r.lo = a.lo != a.lo ? NAN : 0.0;
    r.hi = a.hi != a.hi ? NAN : 0.0;
    return r;
}

/* a, or NaN where z is NaN: a + z and a - z for z = 0 (or NaN), exactly */
CIV_INLINE civ civ_nan_of(civ a, civ z) {
    civ r;
    r.lo = z.lo != z.lo ? NAN : a.lo;
    r.hi = z.hi != z.hi ? NAN : a.hi;
    return r;
}

/* a / b: NaN where b holds 0 or a quotient is NaN */
CIV_INLINE civ civ_div(civ a, civ b) {
    double p1 = a.lo / b.lo, p2 = a.lo / b.hi, p3 = a.hi / b.lo, p4 = a.hi / b.hi;
    return civ_make(civ_dn(civ_min(civ_min(p1, p2), civ_min(p3, p4))),
                    civ_nz(b, civ_up(civ_maxn(civ_maxn(p1, p2), civ_maxn(p3, p4)))));
}

/* a / c for a finite non-zero constant c: civ_div with two quotients (the same bounds) */
CIV_INLINE civ civ_divc(civ a, double c) {
    double p1 = a.lo / c, p3 = a.hi / c;
    return civ_make(civ_dn(civ_min(p1, p3)), civ_up(civ_maxn(p1, p3)));
}

/* c / b for a constant c (not NaN): civ_div with two quotients (the same bounds) */
CIV_INLINE civ civ_cdiv(double c, civ b) {
    double p1 = c / b.lo, p2 = c / b.hi;
    return civ_make(civ_dn(civ_min(p1, p2)), civ_nz(b, civ_up(civ_maxn(p1, p2))));
}

CIV_INLINE civ civ_inv(civ a) { return civ_cdiv(1.0, a); }

/* |a| as [mignitude, magnitude] */
CIV_INLINE civ civ_fabs(civ a) {
    return civ_make(civ_max(civ_max(a.lo, -a.hi), 0.0), civ_maxn(-a.lo, a.hi));
}

/* a^2 from the distances of a from 0: both products are of non-negative numbers, so
 * p (1 - 2^-51) - 2^-1074 rounded is below the exact p and p (1 + 2^-51) + 2^-1074 above
 * it (one rounding of a normal result, and underflow); an overflowed lower bound is only
 * known to be huge (the largest float) */
CIV_INLINE civ civ_sq(civ a) {
    double mig = civ_maxn(civ_maxn(a.lo, -a.hi), 0.0), mag = civ_maxn(-a.lo, a.hi);
    double lo = civ_minn(civ_maxn(mig * mig * (1.0 - 0x1p-51) - CIV_TINY, 0.0), DBL_MAX);
    return civ_make(lo, mag * mag * (1.0 + 0x1p-51) + CIV_TINY);
}

CIV_INLINE civ civ_sqrt(civ a) {
    return civ_make(a.lo >= 0.0 ? civ_max(civ_dn(sqrt(a.lo)), 0.0) : NAN, civ_up(sqrt(a.hi)));
}

CIV_INLINE civ civ_fmin(civ a, civ b) {
    return civ_make(civ_minn(a.lo, b.lo), civ_minn(a.hi, b.hi));
}

CIV_INLINE civ civ_fmax(civ a, civ b) {
    return civ_make(civ_maxn(a.lo, b.lo), civ_maxn(a.hi, b.hi));
}

/* ---- monotone libm functions: f(lo), f(hi) with the libm margin, clipped to [rlo, rhi] */
CIV_INLINE civ civ_inc(double flo, double fhi, double rlo, double rhi) {
    return civ_make(flo != flo ? NAN : civ_max(civ_dnf(flo), rlo),
                    fhi != fhi ? NAN : civ_min(civ_upf(fhi), rhi));
}

/* e^x for -700 <= x <= 709 (NaN for NaN), within 2^-48 relative in every rounding mode, in
 * straight-line arithmetic (no table, no branch). x = k ln 2 + r with an integer k near
 * x / ln 2 (|r| <= 0.7 whatever the rounding of the shift), ln 2 split in two parts of
 * which the first times k is exact; e^r by its Taylor polynomial of degree 17 (remainder
 * below 2^-61 for |r| <= 0.7), evaluated as 1 + (r + r^2 q(r)); 2^k from the bits of
 * the shifted product. The callers add the libm margin (2^-44 relative), which covers
 * these errors with room to spare. */
CIV_INLINE double civ_exp_core(double x) {
    double t = x * 0x1.71547652b82fep+0 + 0x1.8p52, k = t - 0x1.8p52;
    double r = (x - k * 0x1.62e42fee00000p-1) - k * 0x1.a39ef35793c76p-33;
    double q = 0x1.952c77030ad4ap-49;  /* 1 / 17! */
    unsigned long long ki, bits;
    double s;
    q = q * r + 0x1.ae7f3e733b81fp-45;  /* 1 / 16! */
    q = q * r + 0x1.ae7f3e733b81fp-41;  /* 1 / 15! */
    q = q * r + 0x1.93974a8c07c9dp-37;  /* 1 / 14! */
    q = q * r + 0x1.6124613a86d09p-33;  /* 1 / 13! */
    q = q * r + 0x1.1eed8eff8d898p-29;  /* 1 / 12! */
    q = q * r + 0x1.ae64567f544e4p-26;  /* 1 / 11! */
    q = q * r + 0x1.27e4fb7789f5cp-22;  /* 1 / 10! */
    q = q * r + 0x1.71de3a556c734p-19;  /* 1 / 9! */
    q = q * r + 0x1.a01a01a01a01ap-16;  /* 1 / 8! */
    q = q * r + 0x1.a01a01a01a01ap-13;  /* 1 / 7! */
    q = q * r + 0x1.6c16c16c16c17p-10;  /* 1 / 6! */
    q = q * r + 0x1.1111111111111p-7;  /* 1 / 5! */
    q = q * r + 0x1.5555555555555p-5;  /* 1 / 4! */
    q = q * r + 0x1.5555555555555p-3;  /* 1 / 3! */
    q = q * r + 0x1.0000000000000p-1;  /* 1 / 2! */
    q = 1.0 + (r + (r * r) * q);
    memcpy(&bits, &t, sizeof bits);
    ki = bits - 0x4338000000000000ULL;              /* k as an integer, |k| <= 1025 */
    bits = (ki + 1022) << 52;                       /* 2^(k - 1), a normal float */
    memcpy(&s, &bits, sizeof s);
    return (q * s) * 2.0;
}

/* e^[lo, hi]: below -700 the lower bound is 0 and e^-700 bounds above; above 709 the upper
 * bound is +inf and e^709 bounds below */
CIV_INLINE civ civ_exp(civ a) {
    double xl = a.lo > 709.0 ? 709.0 : a.lo, xh = a.hi < -700.0 ? -700.0 : a.hi;
    double el = civ_exp_core(xl < -700.0 ? -700.0 : xl);
    double eh = civ_exp_core(xh > 709.0 ? 709.0 : xh);
    el = xl < -700.0 ? 0.0 : el;
    eh = xh > 709.0 ? INFINITY : eh;
    return civ_inc(el, eh, 0.0, INFINITY);
}
CIV_INLINE civ civ_expm1(civ a) {
    return civ_inc(expm1(a.lo), expm1(a.hi), -1.0, INFINITY);
}
CIV_INLINE civ civ_log(civ a) {
    if (!(a.lo > 0.0)) return civ_nan();
    return civ_inc(log(a.lo), log(a.hi), -INFINITY, INFINITY);
}
CIV_INLINE civ civ_log1p(civ a) {
    if (!(a.lo > -1.0)) return civ_nan();
    return civ_inc(log1p(a.lo), log1p(a.hi), -INFINITY, INFINITY);
}
CIV_INLINE civ civ_atan(civ a) {
    return civ_inc(atan(a.lo), atan(a.hi), -CIV_HALF_PI_HI, CIV_HALF_PI_HI);
}
CIV_INLINE civ civ_tanh(civ a) { return civ_inc(tanh(a.lo), tanh(a.hi), -1.0, 1.0); }
CIV_INLINE civ civ_erf(civ a) { return civ_inc(erf(a.lo), erf(a.hi), -1.0, 1.0); }
CIV_INLINE civ civ_sinh(civ a) {
    return civ_inc(sinh(a.lo), sinh(a.hi), -INFINITY, INFINITY);
}
CIV_INLINE civ civ_asinh(civ a) {
    return civ_inc(asinh(a.lo), asinh(a.hi), -INFINITY, INFINITY);
}
CIV_INLINE civ civ_asin(civ a) {
    if (!(a.lo >= -1.0 && a.hi <= 1.0)) return civ_nan();
    return civ_inc(asin(a.lo), asin(a.hi), -CIV_HALF_PI_HI, CIV_HALF_PI_HI);
}
CIV_INLINE civ civ_acos(civ a) { /* decreasing */
    if (!(a.lo >= -1.0 && a.hi <= 1.0)) return civ_nan();
    return civ_inc(acos(a.hi), acos(a.lo), 0.0, CIV_PI_HI);
}
CIV_INLINE civ civ_acosh(civ a) {
    if (!(a.lo >= 1.0) || a.hi != a.hi) return civ_nan();
    return civ_inc(acosh(a.lo), acosh(a.hi), 0.0, INFINITY);
}
CIV_INLINE civ civ_atanh(civ a) {
    if (!(a.lo > -1.0 && a.hi < 1.0)) return civ_nan();
    return civ_inc(atanh(a.lo), atanh(a.hi), -INFINITY, INFINITY);
}
CIV_INLINE civ civ_cosh(civ a) { /* even: cosh of [mignitude, magnitude] */
    civ m = civ_fabs(a);
    if (civ_isnan(m)) return m;
    return civ_inc(cosh(m.lo), cosh(m.hi), 1.0, INFINITY);
}

/* Does [lo, hi] contain off + k period for an integer k? Conservative: may answer yes when it
 * does not (which only widens), never no when it does (the slack dwarfs the rounding of the
 * quotients, in every rounding mode). */
CIV_INLINE int civ_contains_point(double lo, double hi, double off, double period) {
    double kl = (lo - off) / period, kh = (hi - off) / period;
    double slack = 1e-9 + 1e-15 * (fabs(kl) + fabs(kh));
    return floor(kh + slack) >= ceil(kl - slack);
}

/* pi/2 in five pieces of at most 26 significant bits (k P_i is exact for |k| < 2^27; the
 * pieces sum to pi/2 within 2^-141) */
#define CIV_PIO2_1 0x1.921fb58p+0
#define CIV_PIO2_2 -0x1.dde974p-27
#define CIV_PIO2_3 0x1.1a6263p-54
#define CIV_PIO2_4 0x1.8a2e038p-81
#define CIV_PIO2_5 -0x1.f1976b8p-110
#define CIV_PIO4 0x1.921fb54442d18p-1 /* below pi / 4 */

/* x - k pi/2 for an integer k, |k| < 2^27, with |x - k pi/2| <= 0.79: every product is
 * exact. Each difference s_i = s_(i-1) - k P_i is exact by Sterbenz's lemma when its
 * operands are within a factor 2 of each other; otherwise |s_i| exceeds |k P_i| / 2, so
 * |r| >= |k| 2^-28 (i = 2) resp. |k| 2^-55 ... and the tail k (P_(i+1) + ...) is below
 * 2^-25 |r|: the rounding error (one ulp in any rounding mode) is at most 2^-51 |r|.
 * Hence the result is within 2^-49 |r| + |k| 2^-141 (the pieces' error) of the exact
 * r = x - k pi/2, in every rounding mode. */
CIV_INLINE double civ_rem_pio2(double x, double k) {
    return ((((x - k * CIV_PIO2_1) - k * CIV_PIO2_2) - k * CIV_PIO2_3) - k * CIV_PIO2_4)
        - k * CIV_PIO2_5;
}

/* sin x (cosine = 0) or cos x (cosine = 1) for |x| <= 1e8, in straight-line arithmetic (no
 * table, no branch, no libm call: SIMD lanes). x = k pi/2 + r with an integer k: the shift
 * gives k within one of x 2/pi in any rounding mode, and one correction brings |r| to at
 * most pi/4 (plus the reduction error); sin r by its Taylor polynomial to r^17 (remainder
 * below 2^-63 |r| for |r| <= 0.786), cos r to r^18 (below 2^-68), chosen and signed by
 * k + cosine mod 4. Within 2^-47 relative plus |k| 2^-141 of the exact value in every
 * rounding mode (|sin r| >= 0.9 |r| and cos r >= 0.7 there, so the error of r is relative);
 * the callers add 2^-44 relative plus |k| 2^-135 (|k| is returned in *kabs). */
CIV_INLINE double civ_sincos_core(double x, int cosine, double *kabs) {
    double t = x * 0x1.45f306dc9c883p-1 + 0x1.8p52, k = t - 0x1.8p52;
    double r = civ_rem_pio2(x, k), z, sn, cs, q;
    k = k + (r > CIV_PIO4 ? 1.0 : 0.0) - (r < -CIV_PIO4 ? 1.0 : 0.0);
    r = civ_rem_pio2(x, k);
    z = r * r;
    sn = 0x1.952c77030ad4ap-49;                    /* 1 / 17! */
    sn = sn * z - 0x1.ae7f3e733b81fp-41;           /* 1 / 15! */
    sn = sn * z + 0x1.6124613a86d09p-33;           /* 1 / 13! */
    sn = sn * z - 0x1.ae64567f544e4p-26;           /* 1 / 11! */
    sn = sn * z + 0x1.71de3a556c734p-19;           /* 1 / 9! */
    sn = sn * z - 0x1.a01a01a01a01ap-13;           /* 1 / 7! */
    sn = sn * z + 0x1.1111111111111p-7;            /* 1 / 5! */
    sn = sn * z - 0x1.5555555555555p-3;            /* 1 / 3! */
    sn = r + (r * z) * sn;
    cs = 0x1.6827863b97d97p-53;                    /* 1 / 18! */
    cs = cs * z - 0x1.ae7f3e733b81fp-45;           /* 1 / 16! */
    cs = cs * z + 0x1.93974a8c07c9dp-37;           /* 1 / 14! */
    cs = cs * z - 0x1.1eed8eff8d898p-29;           /* 1 / 12! */
    cs = cs * z + 0x1.27e4fb7789f5cp-22;           /* 1 / 10! */
    cs = cs * z - 0x1.a01a01a01a01ap-16;           /* 1 / 8! */
    cs = cs * z + 0x1.6c16c16c16c17p-10;           /* 1 / 6! */
    cs = cs * z - 0x1.5555555555555p-5;            /* 1 / 4! */
    cs = 1.0 + z * (-0.5 - z * cs);
    q = k + (cosine ? 1.0 : 0.0);
    q = q - 4.0 * floor(q * 0.25);                 /* exact: 0, 1, 2 or 3 */
    *kabs = fabs(k);
    return q == 0.0 ? sn : (q == 1.0 ? cs : (q == 2.0 ? -sn : -cs));
}

/* a bound of sin or cos from the core: the libm margin plus |k| 2^-135 */
CIV_INLINE double civ_dnt(double v, double kabs) {
    return civ_dn(v - (fabs(v) * CIV_RL + (kabs * 0x1p-135 + CIV_AL)));
}

CIV_INLINE double civ_upt(double v, double kabs) {
    return civ_up(v + (fabs(v) * CIV_RL + (kabs * 0x1p-135 + CIV_AL)));
}

/* sin, cos: f at the ends, and 1 (-1) where the box holds a maximum (minimum) of f; the
 * whole [-1, 1] for a box of width 2 pi or more or beyond |t| = 1e8. Without branches. */
CIV_INLINE civ civ_sincos(civ a, int cosine, double max_off, double min_off) {
    double two_pi = 2.0 * CIV_PI_LO, kl, kh, fl, fh, ka, lo, hi;
    int whole = !(a.hi - a.lo < two_pi && fabs(a.lo) <= CIV_SIN_SAFE
                  && fabs(a.hi) <= CIV_SIN_SAFE);
    double xl = whole ? 0.0 : a.lo, xh = whole ? 0.0 : a.hi;
    fl = civ_sincos_core(xl, cosine, &kl);
    fh = civ_sincos_core(xh, cosine, &kh);
    ka = kl > kh ? kl : kh;
    lo = civ_max(civ_dnt(civ_min(fl, fh), ka), -1.0);
    hi = civ_min(civ_upt(civ_max(fl, fh), ka), 1.0);
    hi = civ_contains_point(xl, xh, max_off, two_pi) ? 1.0 : hi;
    lo = civ_contains_point(xl, xh, min_off, two_pi) ? -1.0 : lo;
    lo = whole ? -1.0 : lo;
    hi = whole ? 1.0 : hi;
    lo = civ_isnan(a) ? NAN : lo;
    hi = civ_isnan(a) ? NAN : hi;
    return civ_make(lo, hi);
}

CIV_INLINE civ civ_sin(civ a) {
    return civ_sincos(a, 0, 0.5 * CIV_PI_LO, -0.5 * CIV_PI_LO);
}
CIV_INLINE civ civ_cos(civ a) { return civ_sincos(a, 1, 0.0, CIV_PI_LO); }

/* tan: increasing between its poles; possibly undefined where the box may hold a pole */
CIV_INLINE civ civ_tan(civ a) {
    if (civ_isnan(a)) return a;
    if (!(a.hi - a.lo < CIV_PI_LO && fabs(a.lo) <= CIV_SIN_SAFE && fabs(a.hi) <= CIV_SIN_SAFE)
        || civ_contains_point(a.lo, a.hi, 0.5 * CIV_PI_LO, CIV_PI_LO))
        return civ_nan();
    return civ_inc(tan(a.lo), tan(a.hi), -INFINITY, INFINITY);
}

/* ---- powers */
/* a^n for an integer n >= 0 */
CIV_INLINE civ civ_pow_nat(civ a, double n) {
    civ m;
    if (civ_isnan(a)) return a;
    if (n == 0.0) return civ_make(1.0, 1.0);
    if (n == 1.0) return a;
    if (n == 2.0) return civ_sq(a);
    if (fmod(n, 2.0) == 1.0) return civ_inc(pow(a.lo, n), pow(a.hi, n), -INFINITY, INFINITY);
    m = civ_fabs(a);
    return civ_inc(pow(m.lo, n), pow(m.hi, n), 0.0, INFINITY);
}

CIV_INLINE civ civ_pow_int(civ a, double n) { /* n integer, |n| < 2^31 */
    if (n < 0.0) return civ_inv(civ_pow_nat(a, -n));
    return civ_pow_nat(a, n);
}

CIV_INLINE civ civ_pow(civ a, civ b) {
    double c = b.lo;
    if (civ_isnan(a) || civ_isnan(b)) return civ_nan();
    if (b.lo == b.hi && fabs(c) < 2147483648.0 && floor(c) == c) return civ_pow_int(a, c);
    if (b.lo == b.hi && c > 0.0 && c < INFINITY) { /* increasing on [0, inf) */
        if (!(a.lo >= 0.0)) return civ_nan();
        return civ_inc(pow(a.lo, c), pow(a.hi, c), 0.0, INFINITY);
    }
    if (b.lo == b.hi && c < 0.0 && c > -INFINITY) { /* decreasing on (0, inf) */
        if (!(a.lo > 0.0)) return civ_nan();
        return civ_inc(pow(a.hi, c), pow(a.lo, c), 0.0, INFINITY);
    }
    if (!(a.lo > 0.0)) return civ_nan();
    return civ_exp(civ_mul(b, civ_log(a)));
}

CIV_INLINE civ civ_hypot(civ a, civ b) {
    civ x = civ_fabs(a), y = civ_fabs(b);
    if (civ_isnan(x) || civ_isnan(y)) return civ_nan();
    return civ_inc(hypot(x.lo, y.lo), hypot(x.hi, y.hi), 0.0, INFINITY);
}

/* atan2(y, x) in [-pi, pi]: corners, or the whole range where the box meets the branch
 * cut (the negative x axis) or the origin */
CIV_INLINE civ civ_atan2(civ y, civ x) {
    double y0, y1, c1, c2, c3, c4;
    civ r;
    if (civ_isnan(y) || civ_isnan(x)) return civ_nan();
    y0 = y.lo + 0.0;
    y1 = y.hi + 0.0;
    c1 = atan2(y0, x.lo); c2 = atan2(y0, x.hi); c3 = atan2(y1, x.lo); c4 = atan2(y1, x.hi);
    r = civ_inc(civ_min(civ_min(c1, c2), civ_min(c3, c4)),
                civ_max(civ_max(c1, c2), civ_max(c3, c4)), -CIV_PI_HI, CIV_PI_HI);
    if (!civ_isnan(r) && ((x.lo <= 0.0 && y.lo < 0.0 && y.hi >= 0.0) ||
                          (x.lo <= 0.0 && x.hi >= 0.0 && y.lo <= 0.0 && y.hi >= 0.0)))
        r = civ_make(-CIV_PI_HI, CIV_PI_HI);
    return r;
}

/* ---- piecewise operations (exact) */
CIV_INLINE civ civ_floor(civ a) {
    if (civ_isnan(a)) return a;
    return civ_make(floor(a.lo), floor(a.hi));
}

CIV_INLINE civ civ_ceil(civ a) {
    if (civ_isnan(a)) return a;
    return civ_make(ceil(a.lo), ceil(a.hi));
}

CIV_INLINE double civ_sgn(double v) { return v > 0.0 ? 1.0 : (v < 0.0 ? -1.0 : 0.0); }

CIV_INLINE civ civ_sign(civ a) {
    if (civ_isnan(a)) return a;
    return civ_make(civ_sgn(a.lo), civ_sgn(a.hi));
}

CIV_INLINE civ civ_copysign(civ a, civ b) {
    civ m = civ_fabs(a);
    if (civ_isnan(m) || civ_isnan(b)) return civ_nan();
    if (b.lo >= 0.0) return m;
    if (b.hi < 0.0) return civ_make(-m.hi, -m.lo);
    return civ_make(-m.hi, m.hi);
}

/* fmod(x, y): the sign of x, magnitude below |y| */
CIV_INLINE civ civ_fmod(civ a, civ b) {
    civ m;
    if (civ_isnan(a) || civ_isnan(b) || (b.lo <= 0.0 && b.hi >= 0.0)) return civ_nan();
    m = civ_fabs(b);
    if ((a.lo >= 0.0 && a.hi < m.lo) || (a.hi <= 0.0 && -a.lo < m.lo)) return a;
    return civ_make(a.lo >= 0.0 ? 0.0 : civ_max(a.lo, -m.hi),
                    a.hi <= 0.0 ? 0.0 : civ_min(a.hi, m.hi));
}

/* IEEE remainder(x, y): x itself when |x| <= |y| / 2, else magnitude below min(|x|, |y|/2) */
CIV_INLINE civ civ_remainder(civ a, civ b) {
    civ m;
    double half, xm, bound;
    if (civ_isnan(a) || civ_isnan(b) || (b.lo <= 0.0 && b.hi >= 0.0)) return civ_nan();
    m = civ_fabs(b);
    if (-2.0 * a.lo <= m.lo && 2.0 * a.hi <= m.lo) return a;
    half = m.hi * 0.5 + CIV_TINY;
    xm = civ_max(-a.lo, a.hi);
    bound = civ_min(half, xm);
    return civ_make(-bound, bound);
}

/* ---- comparisons and logic: [1, 1] surely true, [0, 0] surely false, else [0, 1] */
CIV_INLINE civ civ_bool(civ a, civ b, int sure_true, int sure_false) {
    if (civ_isnan(a) || civ_isnan(b)) return civ_nan();
    return civ_make(sure_true ? 1.0 : 0.0, sure_false ? 0.0 : 1.0);
}

CIV_INLINE int civ_thin_equal(civ a, civ b) {
    return a.lo == a.hi && b.lo == b.hi && a.lo == b.lo;
}

CIV_INLINE int civ_nonzero(civ a) { return a.lo > 0.0 || a.hi < 0.0; }
CIV_INLINE int civ_zero(civ a) { return a.lo == 0.0 && a.hi == 0.0; }

CIV_INLINE civ civ_lt(civ a, civ b) { return civ_bool(a, b, a.hi < b.lo, a.lo >= b.hi); }
CIV_INLINE civ civ_le(civ a, civ b) { return civ_bool(a, b, a.hi <= b.lo, a.lo > b.hi); }
CIV_INLINE civ civ_eq(civ a, civ b) {
    return civ_bool(a, b, civ_thin_equal(a, b), a.hi < b.lo || a.lo > b.hi);
}
CIV_INLINE civ civ_ne(civ a, civ b) {
    return civ_bool(a, b, a.hi < b.lo || a.lo > b.hi, civ_thin_equal(a, b));
}
CIV_INLINE civ civ_not(civ a) { return civ_bool(a, a, civ_zero(a), civ_nonzero(a)); }
CIV_INLINE civ civ_and(civ a, civ b) {
    return civ_bool(a, b, civ_nonzero(a) && civ_nonzero(b), civ_zero(a) || civ_zero(b));
}
CIV_INLINE civ civ_or(civ a, civ b) {
    return civ_bool(a, b, civ_nonzero(a) || civ_nonzero(b), civ_zero(a) && civ_zero(b));
}

/* c ? x : 0 */
CIV_INLINE civ civ_if_else_zero(civ c, civ x) {
    if (civ_isnan(c) || civ_isnan(x)) return civ_nan();
    if (civ_nonzero(c)) return x;
    if (civ_zero(c)) return civ_make(0.0, 0.0);
    return civ_make(civ_min(x.lo, 0.0), civ_max(x.hi, 0.0));
}
"""
