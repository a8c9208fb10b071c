"""High-precision reference semantics for the interval tests.

Every function takes mpmath numbers (floats are converted exactly with ``mpmath.mpf``) and
returns the exact real value rounded to ``PREC`` bits, or raises :class:`Undefined` where the
real function is undefined (``log`` of a non-positive number, division by zero, ...).

``eval_function`` evaluates a CasADi SX Function instruction by instruction with these
semantics, which gives the exact value of the very graph an inclusion function is compiled
from (CasADi simplifies and folds expressions while building them).
"""

from __future__ import annotations

import math

import casadi as ca
import mpmath
from mpmath import mpf

PREC = 300
mpmath.mp.prec = PREC

ZERO = mpf(0)
ONE = mpf(1)
INF = mpf("inf")


class Undefined(ArithmeticError):
    """The real function is undefined at this point."""


def F(x) -> mpf:
    """Exact conversion of a float (or mpf) to mpf."""
    if isinstance(x, mpf):
        return x
    return mpf(float(x))


def _is_float(x: mpf) -> bool:
    return mpmath.isfinite(x) and mpf(float(x)) == x


# ---------------------------------------------------------------------- arithmetic
# Sums and products of two floats are exact (whatever their exponents); results of earlier
# operations (up to PREC bits, any exponent) are combined with rounding to PREC bits.
def add(a, b):
    return mpmath.fadd(a, b, exact=_is_float(a) and _is_float(b))


def sub(a, b):
    return mpmath.fsub(a, b, exact=_is_float(a) and _is_float(b))


def mul(a, b):
    return mpmath.fmul(a, b, exact=_is_float(a) and _is_float(b))


def neg(a):
    return -a


def twice(a):
    return mpmath.fmul(a, 2, exact=True)


def sq(a):
    return mul(a, a)


def div(a, b):
    if b == 0:
        raise Undefined("division by zero")
    return mpmath.fdiv(a, b)


def inv(a):
    return div(ONE, a)


def sqrt(a):
    if a < 0:
        raise Undefined("sqrt of a negative number")
    return mpmath.sqrt(a)


def exp(a):
    return mpmath.exp(a)


def expm1(a):
    return mpmath.expm1(a)


def log(a):
    if a <= 0:
        raise Undefined("log of a non-positive number")
    return mpmath.log(a)


def log1p(a):
    if a <= -1:
        raise Undefined("log1p of a number <= -1")
    return mpmath.log1p(a)


def sin(a):
    return mpmath.sin(a)


def cos(a):
    return mpmath.cos(a)


def tan(a):
    return mpmath.tan(a)  # a real number is never a pole of tan exactly


def asin(a):
    if not -1 <= a <= 1:
        raise Undefined("asin outside [-1, 1]")
    return mpmath.asin(a)


def acos(a):
    if not -1 <= a <= 1:
        raise Undefined("acos outside [-1, 1]")
    return mpmath.acos(a)


def atan(a):
    return mpmath.atan(a)


def sinh(a):
    return mpmath.sinh(a)


def cosh(a):
    return mpmath.cosh(a)


def tanh(a):
    return mpmath.tanh(a)


def asinh(a):
    return mpmath.asinh(a)


def acosh(a):
    if a < 1:
        raise Undefined("acosh below 1")
    return mpmath.acosh(a)


def atanh(a):
    if not -1 < a < 1:
        raise Undefined("atanh outside (-1, 1)")
    return mpmath.atanh(a)


def erf(a):
    return mpmath.erf(a)


def erfinv(a):
    if not -1 < a < 1:
        raise Undefined("erfinv outside (-1, 1)")
    return mpmath.erfinv(a)


# ----------------------------------------------------------------------- piecewise
def fabs(a):
    return abs(a)


def fmin(a, b):
    return min(a, b)


def fmax(a, b):
    return max(a, b)


def floor(a):
    return mpmath.floor(a)


def ceil(a):
    return mpmath.ceil(a)


def sign(a):
    return mpf(mpmath.sign(a))


def copysign(a, b):
    """|a| with the sign of the real number b (b = 0 counts as positive)."""
    return abs(a) if b >= 0 else -abs(a)


def _trunc(q):
    return mpmath.floor(q) if q >= 0 else mpmath.ceil(q)


def fmod(a, b):
    """C fmod: a - trunc(a / b) * b."""
    if b == 0:
        raise Undefined("fmod by zero")
    if _is_float(a) and _is_float(b):
        return mpf(math.fmod(float(a), float(b)))  # exact for floats
    return sub(a, mul(_trunc(a / b), b))


def remainder(a, b):
    """IEEE remainder: a - n * b, n = a / b rounded to the nearest integer, ties to even."""
    if b == 0:
        raise Undefined("remainder by zero")
    if _is_float(a) and _is_float(b):
        return mpf(math.remainder(float(a), float(b)))  # exact for floats
    q = a / b
    n = mpmath.nint(q)
    return sub(a, mul(n, b))


def hypot(a, b):
    return mpmath.sqrt(add(sq(a), sq(b)))


def atan2(y, x):
    if x == 0 and y == 0:
        return ZERO  # C/CasADi value at the origin
    return mpmath.atan2(y, x)


# -------------------------------------------------------------------------- powers
def powi(a, n: int):
    n = int(n)
    if n < 0 and a == 0:
        raise Undefined("negative power of zero")
    if n == 0:
        return ONE
    return mpmath.power(a, n)


def pow(a, b):
    """Real power: a**b for a > 0; 0**b for b >= 0; integer b for a < 0."""
    if b == mpmath.floor(b) and abs(b) < 2 ** 62:
        return powi(a, int(b))
    if a > 0:
        return mpmath.power(a, b)
    if a == 0:
        if b > 0:
            return ZERO
        raise Undefined("non-positive power of zero")
    raise Undefined("non-integer power of a negative number")


# ------------------------------------------------------------------------- logic
def _b(v: bool):
    return ONE if v else ZERO


def lt(a, b):
    return _b(a < b)


def le(a, b):
    return _b(a <= b)


def eq(a, b):
    return _b(a == b)


def ne(a, b):
    return _b(a != b)


def not_(a):
    return _b(a == 0)


def and_(a, b):
    return _b(a != 0 and b != 0)


def or_(a, b):
    return _b(a != 0 or b != 0)


def if_else_zero(c, x):
    return x if c != 0 else ZERO


# --------------------------------------------------------- CasADi instruction list
_OPS = {
    ca.OP_ASSIGN: lambda a: a, ca.OP_NEG: neg, ca.OP_SQ: sq, ca.OP_TWICE: twice,
    ca.OP_INV: inv, ca.OP_SQRT: sqrt, ca.OP_EXP: exp, ca.OP_LOG: log, ca.OP_SIN: sin,
    ca.OP_COS: cos, ca.OP_TAN: tan, ca.OP_ASIN: asin, ca.OP_ACOS: acos, ca.OP_ATAN: atan,
    ca.OP_SINH: sinh, ca.OP_COSH: cosh, ca.OP_TANH: tanh, ca.OP_ASINH: asinh,
    ca.OP_ACOSH: acosh, ca.OP_ATANH: atanh, ca.OP_FABS: fabs, ca.OP_FLOOR: floor,
    ca.OP_CEIL: ceil, ca.OP_SIGN: sign, ca.OP_NOT: not_, ca.OP_ERF: erf,
    ca.OP_ERFINV: erfinv, ca.OP_LOG1P: log1p, ca.OP_EXPM1: expm1,
    ca.OP_ADD: add, ca.OP_SUB: sub, ca.OP_MUL: mul, ca.OP_DIV: div, ca.OP_POW: pow,
    ca.OP_CONSTPOW: pow, ca.OP_ATAN2: atan2, ca.OP_FMIN: fmin, ca.OP_FMAX: fmax,
    ca.OP_LT: lt, ca.OP_LE: le, ca.OP_EQ: eq, ca.OP_NE: ne, ca.OP_AND: and_, ca.OP_OR: or_,
    ca.OP_IF_ELSE_ZERO: if_else_zero, ca.OP_COPYSIGN: copysign, ca.OP_FMOD: fmod,
    ca.OP_REMAINDER: remainder, ca.OP_HYPOT: hypot,
}


class _Undef:
    """Value of an undefined sub-expression (propagates like NaN)."""


UNDEF = _Undef()


def eval_function(fun: ca.Function, inputs: list[list], ops: dict | None = None) -> list[list]:
    """Exact values of the outputs of an SX Function at one point.

    ``inputs[i]`` lists the (dense, column-major) entries of input ``i`` (floats or mpf).
    Returns, per output, the list of its non-zeros as mpf, or ``UNDEF`` where the graph
    evaluates an operation outside its domain (``if_else_zero(0, undefined)`` is 0, as in
    CasADi). A NaN constant is CasADi's folded value of an operation outside its domain
    (``log(-2.5)``), so it is ``UNDEF`` too. ``ops`` replaces the semantics of some
    operation codes (default: this module's).
    """
    table = _OPS if ops is None else {**_OPS, **ops}
    work: dict[int, object] = {}
    outs = [[None] * fun.nnz_out(i) for i in range(fun.n_out())]
    for k in range(fun.n_instructions()):
        op = fun.instruction_id(k)
        ins = list(fun.instruction_input(k))
        o = list(fun.instruction_output(k))
        if op == ca.OP_CONST:
            v = float(fun.instruction_constant(k))
            work[o[0]] = UNDEF if math.isnan(v) else F(v)
        elif op == ca.OP_INPUT:
            work[o[0]] = F(inputs[ins[0]][ins[1]])
        elif op == ca.OP_OUTPUT:
            outs[o[0]][o[1]] = work[ins[0]]
        else:
            fn = table[op]
            args = [work[i] for i in ins[: (1 if op in _UNARY_OPS else 2)]]
            if op == ca.OP_IF_ELSE_ZERO and args[0] is not UNDEF and args[0] == 0:
                work[o[0]] = ZERO
            elif any(a is UNDEF for a in args):
                work[o[0]] = UNDEF
            else:
                try:
                    work[o[0]] = fn(*args)
                except Undefined:
                    work[o[0]] = UNDEF
    return outs


_UNARY_OPS = {
    ca.OP_ASSIGN, ca.OP_NEG, ca.OP_SQ, ca.OP_TWICE, ca.OP_INV, ca.OP_SQRT, ca.OP_EXP,
    ca.OP_LOG, ca.OP_SIN, ca.OP_COS, ca.OP_TAN, ca.OP_ASIN, ca.OP_ACOS, ca.OP_ATAN,
    ca.OP_SINH, ca.OP_COSH, ca.OP_TANH, ca.OP_ASINH, ca.OP_ACOSH, ca.OP_ATANH, ca.OP_FABS,
    ca.OP_FLOOR, ca.OP_CEIL, ca.OP_SIGN, ca.OP_NOT, ca.OP_ERF, ca.OP_ERFINV, ca.OP_LOG1P,
    ca.OP_EXPM1,
}


def inside(lo: float, hi: float, v) -> bool:
    """Is the exact value v inside [lo, hi]? A NaN bound carries no information."""
    if not math.isnan(lo) and F(lo) > v:
        return False
    return math.isnan(hi) or v <= F(hi)


def uninformative(lo: float, hi: float) -> bool:
    """The whole real line or NaN (no information) on both sides."""
    return (math.isnan(lo) or lo == -math.inf) and (math.isnan(hi) or hi == math.inf)
