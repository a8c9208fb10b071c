"""Interval operations on Python floats, as source templates for small batches.

The numpy operations of :mod:`casadi_cmpc.interval.arith` cost 8-20 ufunc calls each, about
3-4 µs per operation whatever the batch size below a few hundred boxes. The same operations
written as straight-line statements on Python floats cost tens of nanoseconds. This module
holds them as *emitters*: functions returning Python source lines that compute the bounds
``lo``, ``hi`` of one operation from the operand bounds (variable names or float literals).
The scalar compiler (:class:`casadi_cmpc.interval.compiler._ScalarCodegen`) pastes them into
one generated function per CasADi Function; :func:`scalar_op` compiles one of them alone
(used by the tests).

Semantics
---------
Every emitter follows the numpy operation of the same name in
:mod:`~casadi_cmpc.interval.arith` line by line: the same outward rounding (``|x| * 2**-52``
after ``+``/``-``; ``|x| * 2**-52 + 2**-1074`` after ``*``, ``/``, ``sqrt``; ``|x| * 2**-44 +
2**-1060`` after a libm function), the same overflow caps (a lower bound computed as ``+inf``
becomes the largest float before it is rounded down, an upper bound ``-inf`` the most negative
one), the same domain convention (``[nan, nan]`` where the operation may be undefined on the
box) and the same NaN rules (a NaN met in any operand bound of a case-based operation gives
``[nan, nan]``; sums and monotone functions compute each bound from the matching operand
bounds). Sums, products, quotients, square roots, ``min``/``max`` and comparisons of Python
floats are the same IEEE double operations as numpy's, so those results are bit for bit those
of the numpy backend (up to the sign of a zero); libm functions (``math.exp`` vs ``np.exp``)
may differ in the last bits, which the 256-ulp margin covers.

Python raises where numpy returns ``inf`` or ``nan``: ``math.exp`` overflows with
``OverflowError``, ``math.log(0)`` and ``math.sin(inf)`` raise ``ValueError``, ``x / 0.0``
raises ``ZeroDivisionError``. The emitters test domains before calling such functions and
catch ``OverflowError`` where a result may overflow, so valid operands never raise; the
evaluators of :class:`~casadi_cmpc.interval.compiler.InclusionFunction` still evaluate a batch
with the numpy backend if one of these exceptions escapes (e.g. for inverted operand bounds
passed to ``evaluate_unchecked``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from scipy import special as _special

from . import arith as _A

__all__: list[str] = []

MAX = _A.MAX_FLOAT
INF = math.inf
NAN = math.nan
# Beyond 2**52 every float is an integer: floor and ceil return their argument.
_INT_EXACT = 4503599627370496.0

# Globals of every generated function (and of the helpers compiled here).
NAMESPACE: dict[str, Any] = {
    "MAX": MAX, "NMAX": -MAX, "U": _A.U, "TINY": _A.TINY, "RL": _A.REL_LIBM,
    "AL": _A.ABS_LIBM, "INF": INF, "NINF": -INF, "NAN": NAN, "C_DN": _A.C_DN,
    "C_UP": _A.C_UP, "TWO_PI": 2.0 * _A.PI_LO, "PI_LO": _A.PI_LO, "PI_HI": float(_A.PI_HI),
    "HALF_PI_HI": float(_A.HALF_PI_HI), "SIN_SAFE": _A._SIN_SAFE, "INT_EXACT": _INT_EXACT,
    "_sqrt": math.sqrt, "_exp": math.exp, "_expm1": math.expm1, "_log": math.log,
    "_log1p": math.log1p, "_sin": math.sin, "_cos": math.cos, "_tan": math.tan,
    "_asin": math.asin, "_acos": math.acos, "_atan": math.atan, "_sinh": math.sinh,
    "_cosh": math.cosh, "_tanh": math.tanh, "_asinh": math.asinh, "_acosh": math.acosh,
    "_atanh": math.atanh, "_erf": math.erf, "_floor": math.floor, "_ceil": math.ceil,
    "_float": float,
}

Lines = list[str]


def is_literal(s: str) -> bool:
    """True for a finite float literal (never NaN, so it needs no NaN test)."""
    return s[:1].isdigit() or s[:2] == "(-"


def is_constant_text(s: str) -> bool:
    """True for the source text of a constant (a literal, ``INF``, ``NINF`` or ``NAN``)."""
    return is_literal(s) or s in ("INF", "NINF", "NAN")


def _nan_test(args: Sequence[str]) -> str | None:
    """Condition that is True when one of the (non-literal) operands is NaN."""
    terms = [f"{a} != {a}" for a in args if not is_literal(a)]
    return " or ".join(terms) if terms else None


def _guarded(args: Sequence[str], lo: str, hi: str, body: Lines) -> Lines:
    """``[nan, nan]`` when an operand bound is NaN, else ``body``."""
    cond = _nan_test(args)
    if cond is None:
        return list(body)
    return [f"if {cond}:", f"    {lo} = {hi} = NAN", "else:"] + [f"    {b}" for b in body]


# ---------------------------------------------------------------------- rounding
# One operation's result v (or an infinite bound): as arith.dn/up/dnm/upm/dnf/upf. The
# margin |v| * e + a is written without abs: for v <= 0, v - ((-v) * e + a) equals
# v + (v * e - a) bit for bit (negation is exact and rounding to nearest is symmetric), and
# a conditional expression is cheaper than a call of abs.
def _dn(v: str, cap: bool = True) -> Lines:
    return ([f"if {v} > MAX: {v} = MAX"] if cap else []) + [
        f"{v} = {v} - {v} * U if {v} > 0.0 else {v} + {v} * U"]


def _up(v: str, cap: bool = True) -> Lines:
    return ([f"if {v} < NMAX: {v} = NMAX"] if cap else []) + [
        f"{v} = {v} + {v} * U if {v} > 0.0 else {v} - {v} * U"]


def _dnm(v: str, cap: bool = True) -> Lines:
    return ([f"if {v} > MAX: {v} = MAX"] if cap else []) + [
        f"{v} = {v} - ({v} * U + TINY) if {v} > 0.0 else {v} + ({v} * U - TINY)"]


def _upm(v: str, cap: bool = True) -> Lines:
    return ([f"if {v} < NMAX: {v} = NMAX"] if cap else []) + [
        f"{v} = {v} + ({v} * U + TINY) if {v} > 0.0 else {v} - ({v} * U - TINY)"]


def _dnf(v: str, cap: bool = True) -> Lines:
    return ([f"if {v} > MAX: {v} = MAX"] if cap else []) + [
        f"{v} = {v} - ({v} * RL + AL) if {v} > 0.0 else {v} + ({v} * RL - AL)"]


def _upf(v: str, cap: bool = True) -> Lines:
    return ([f"if {v} < NMAX: {v} = NMAX"] if cap else []) + [
        f"{v} = {v} + ({v} * RL + AL) if {v} > 0.0 else {v} - ({v} * RL - AL)"]


def _minmax(lo: str, hi: str, ps: Sequence[str]) -> Lines:
    """lo = min(ps), hi = max(ps) for non-NaN values (2 or 4 of them)."""
    p1, p2 = ps[0], ps[1]
    out = [f"if {p1} < {p2}: {lo} = {p1}; {hi} = {p2}",
           f"else: {lo} = {p2}; {hi} = {p1}"]
    if len(ps) == 4:
        p3, p4 = ps[2], ps[3]
        out += [f"if {p3} < {p4}:",
                f"    if {p3} < {lo}: {lo} = {p3}",
                f"    if {p4} > {hi}: {hi} = {p4}",
                "else:",
                f"    if {p4} < {lo}: {lo} = {p4}",
                f"    if {p3} > {hi}: {hi} = {p3}"]
    return out


def _any_nan(ps: Sequence[str]) -> str:
    return " or ".join(f"{p} != {p}" for p in ps)


# -------------------------------------------------------------------- arithmetic
def add(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah, bl, bh = a
    return [f"{lo} = {al} + {bl}", *_dn(lo), f"{hi} = {ah} + {bh}", *_up(hi)]


def sub(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah, bl, bh = a
    return [f"{lo} = {al} - {bh}", *_dn(lo), f"{hi} = {ah} - {bl}", *_up(hi)]


def addc(lo: str, hi: str, a: Sequence[str], t: str, c: float) -> Lines:
    """x + c for a float constant c (arith.addc)."""
    al, ah = a
    if not math.isfinite(c):
        return [f"{lo} = {hi} = NAN"]
    cs = literal(c)
    if c > 0:  # only the lower bound can overflow
        return [f"{lo} = {al} + {cs}", *_dn(lo), f"{hi} = {ah} + {cs}", *_up(hi, cap=False)]
    return [f"{lo} = {al} + {cs}", *_dn(lo, cap=False), f"{hi} = {ah} + {cs}", *_up(hi)]


def csub(lo: str, hi: str, a: Sequence[str], t: str, c: float) -> Lines:
    """c - x for a float constant c (arith.csub)."""
    bl, bh = a
    if not math.isfinite(c):
        return [f"{lo} = {hi} = NAN"]
    cs = literal(c)
    if c > 0:
        return [f"{lo} = {cs} - {bh}", *_dn(lo), f"{hi} = {cs} - {bl}", *_up(hi, cap=False)]
    return [f"{lo} = {cs} - {bh}", *_dn(lo, cap=False), f"{hi} = {cs} - {bl}", *_up(hi)]


def neg(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah = a
    return [f"{lo} = -{ah}", f"{hi} = -{al}"]


def twice(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah = a
    return [f"{lo} = {al} + {al}", f"if {lo} > MAX: {lo} = MAX",
            f"{hi} = {ah} + {ah}", f"if {hi} < NMAX: {hi} = NMAX"]


def assign(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    return [f"{lo} = {a[0]}", f"{hi} = {a[1]}"]


def mul(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah, bl, bh = a
    ps = [f"{t}1", f"{t}2", f"{t}3", f"{t}4"]
    return [f"{ps[0]} = {al} * {bl}; {ps[1]} = {al} * {bh}; {ps[2]} = {ah} * {bl}; "
            f"{ps[3]} = {ah} * {bh}",
            f"if {_any_nan(ps)}:",
            f"    {lo} = {hi} = NAN",
            "else:",
            *[f"    {s}" for s in _minmax(lo, hi, ps)],
            *_dnm(lo), *_upm(hi)]


def mulc(lo: str, hi: str, a: Sequence[str], t: str, c: float) -> Lines:
    """x * c for a float constant c (arith.mulc)."""
    al, ah = a
    if not math.isfinite(c):
        return [f"{lo} = {hi} = NAN"]
    cs = literal(c)
    cap = not (-1.0 <= c <= 1.0)  # |x * c| <= |x|: no overflow
    if c > 0:
        return [f"{lo} = {al} * {cs}", *_dnm(lo, cap), f"{hi} = {ah} * {cs}", *_upm(hi, cap)]
    if c < 0:
        return [f"{lo} = {ah} * {cs}", *_dnm(lo, cap), f"{hi} = {al} * {cs}", *_upm(hi, cap)]
    return _guarded([al, ah], lo, hi, [f"{lo} = {hi} = 0.0"])  # 0 * x = 0 for every real x


def mulci(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    """x * [cl, ch] for a constant interval of one sign given as literals (arith.mulci)."""
    al, ah, cl, ch = a
    vl, vh = _literal_value(cl), _literal_value(ch)
    if not (math.isfinite(vl) and math.isfinite(vh)) or not (vl > 0 or vh < 0):
        return mul(lo, hi, a, t)
    p, q = f"{t}1", f"{t}2"
    if vl > 0:
        x, y = al, ah
    else:
        x, y = ah, al
    return [f"{p} = {x} * {cl}; {q} = {x} * {ch}",
            f"{lo} = {p} if {p} < {q} else {q}", *_dnm(lo),
            f"{p} = {y} * {cl}; {q} = {y} * {ch}",
            f"{hi} = {p} if {p} > {q} else {q}", *_upm(hi)]


def sq(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah = a
    m = f"{t}m"
    return _guarded([al, ah], lo, hi, [
        f"{m} = {al} if {al} > -{ah} else -{ah}",
        f"if {m} < 0.0: {m} = 0.0",
        f"{lo} = {m} * {m} * C_DN - TINY",
        f"if {lo} < 0.0: {lo} = 0.0",
        f"if {lo} > MAX: {lo} = MAX",
        f"{m} = -{al} if -{al} > {ah} else {ah}",
        f"{hi} = {m} * {m} * C_UP + TINY",
    ])


def div(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah, bl, bh = a
    ps = [f"{t}1", f"{t}2", f"{t}3", f"{t}4"]
    return [f"if {bl} > 0.0 or {bh} < 0.0:",
            f"    {ps[0]} = {al} / {bl}; {ps[1]} = {al} / {bh}; {ps[2]} = {ah} / {bl}; "
            f"{ps[3]} = {ah} / {bh}",
            f"    if {_any_nan(ps)}:",
            f"        {lo} = {hi} = NAN",
            "    else:",
            *[f"        {s}" for s in _minmax(lo, hi, ps)],
            *[f"        {s}" for s in _dnm(lo) + _upm(hi)],
            "else:",
            f"    {lo} = {hi} = NAN"]


def divc(lo: str, hi: str, a: Sequence[str], t: str, c: float) -> Lines:
    """x / c for a float constant c (arith.divc)."""
    al, ah = a
    if not math.isfinite(c) or c == 0:
        return [f"{lo} = {hi} = NAN"]
    cs = literal(c)
    cap = -1.0 < c < 1.0  # |x / c| <= |x| when |c| >= 1: no overflow
    if c > 0:
        return [f"{lo} = {al} / {cs}", *_dnm(lo, cap), f"{hi} = {ah} / {cs}", *_upm(hi, cap)]
    return [f"{lo} = {ah} / {cs}", *_dnm(lo, cap), f"{hi} = {al} / {cs}", *_upm(hi, cap)]


def cdiv(lo: str, hi: str, a: Sequence[str], t: str, c: float) -> Lines:
    """c / x for a float constant c (arith.cdiv)."""
    bl, bh = a
    if not math.isfinite(c):
        return [f"{lo} = {hi} = NAN"]
    cs = literal(c)
    ps = [f"{t}1", f"{t}2"]
    return [f"if {bl} > 0.0 or {bh} < 0.0:",
            f"    {ps[0]} = {cs} / {bl}; {ps[1]} = {cs} / {bh}",
            f"    if {_any_nan(ps)}:",
            f"        {lo} = {hi} = NAN",
            "    else:",
            *[f"        {s}" for s in _minmax(lo, hi, ps)],
            *[f"        {s}" for s in _dnm(lo) + _upm(hi)],
            "else:",
            f"    {lo} = {hi} = NAN"]


def inv(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    return cdiv(lo, hi, a, t, 1.0)


def sqrt(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah = a
    return [f"if {al} < 0.0:",
            f"    {lo} = {hi} = NAN",
            "else:",
            f"    {lo} = _sqrt({al})",
            *[f"    {s}" for s in _dnm(lo)],
            f"    if {lo} < 0.0: {lo} = 0.0",
            f"    {hi} = _sqrt({ah})",
            *[f"    {s}" for s in _upm(hi)]]


# ---------------------------------------------------------------- transcendental
def _call(v: str, fn: str, x: str, overflow: str | None) -> Lines:
    """v = fn(x); ``overflow``: the value when fn raises OverflowError (None: cannot)."""
    if overflow is None:
        return [f"{v} = {fn}({x})"]
    return ["try:", f"    {v} = {fn}({x})", "except OverflowError:", f"    {v} = {overflow}"]


def _mono(fn: str, inc: bool = True, rlo: str | None = None, rhi: str | None = None,
          dom: str | None = None, ovf: tuple[str, str] | None = None):
    """Emitter of a monotone libm function (arith._mono_inc / _mono_dec + _domain).

    ``dom``: condition (on ``{al}``, ``{ah}``) under which the box is not inside the
    domain; ``ovf``: values of fn at the lower / upper operand bound when it overflows.
    """

    def emit(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
        al, ah = a
        xl, xh = (al, ah) if inc else (ah, al)
        ol, oh = ovf if ovf is not None else (None, None)
        if ovf is not None and not inc:
            ol, oh = oh, ol
        body = [*_call(lo, fn, xl, ol), *_dnf(lo), *_call(hi, fn, xh, oh), *_upf(hi)]
        if rlo is not None:
            body.append(f"if {lo} < {rlo}: {lo} = {rlo}")
        if rhi is not None:
            body.append(f"if {hi} > {rhi}: {hi} = {rhi}")
        if dom is None:
            return body
        return [f"if {dom.format(al=al, ah=ah)}:", f"    {lo} = {hi} = NAN", "else:",
                *[f"    {s}" for s in body]]

    return emit


exp = _mono("_exp", rlo="0.0", ovf=("INF", "INF"))
expm1 = _mono("_expm1", rlo="-1.0", ovf=("INF", "INF"))
log = _mono("_log", dom="{al} <= 0.0")
log1p = _mono("_log1p", dom="{al} <= -1.0")
asin = _mono("_asin", rlo="-HALF_PI_HI", rhi="HALF_PI_HI", dom="{al} < -1.0 or {ah} > 1.0")
acos = _mono("_acos", inc=False, rlo="0.0", rhi="PI_HI", dom="{al} < -1.0 or {ah} > 1.0")
atan = _mono("_atan", rlo="-HALF_PI_HI", rhi="HALF_PI_HI")
tanh = _mono("_tanh", rlo="-1.0", rhi="1.0")
asinh = _mono("_asinh")
acosh = _mono("_acosh", rlo="0.0", dom="{al} < 1.0")
atanh = _mono("_atanh", dom="{al} <= -1.0 or {ah} >= 1.0")
erf = _mono("_erf", rlo="-1.0", rhi="1.0")


def sinh(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah = a
    return [*_call(lo, "_sinh", al, f"(INF if {al} > 0.0 else NINF)"), *_dnf(lo),
            *_call(hi, "_sinh", ah, f"(INF if {ah} > 0.0 else NINF)"), *_upf(hi)]


def cosh(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah = a
    ml, mh = f"{t}l", f"{t}h"
    return _guarded([al, ah], lo, hi, [
        *_fabs_lines(ml, mh, al, ah),
        *_call(lo, "_cosh", ml, "INF"), *_dnf(lo),
        *_call(hi, "_cosh", mh, "INF"), *_upf(hi),
        f"if {lo} < 1.0: {lo} = 1.0",
    ])


def _contains(x: str, al: str, ah: str, offset: str, period: str, t: str) -> Lines:
    """x = arith._contains_point(al, ah, offset, period) for finite bounds."""
    kl, kh, s = f"{t}kl", f"{t}kh", f"{t}s"
    return [f"{kl} = ({al} - {offset}) / {period}; {kh} = ({ah} - {offset}) / {period}",
            f"{s} = 1e-9 + 1e-15 * (abs({kl}) + abs({kh}))",
            f"{x} = _floor({kh} + {s}) >= _ceil({kl} - {s})"]


def _sincos(fn: str, max_off: str, min_off: str):
    def emit(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
        al, ah = a
        p, q, c = f"{t}p", f"{t}q", f"{t}c"
        body = [
            f"if not ({ah} - {al} < TWO_PI and abs({al}) <= SIN_SAFE "
            f"and abs({ah}) <= SIN_SAFE):",
            f"    {lo} = -1.0; {hi} = 1.0",
            "else:",
            f"    {p} = {fn}({al}); {q} = {fn}({ah})",
            *[f"    {s}" for s in _minmax(lo, hi, [p, q])],
            *[f"    {s}" for s in _dnf(lo, cap=False)],
            f"    if {lo} < -1.0: {lo} = -1.0",
            *[f"    {s}" for s in _upf(hi, cap=False)],
            f"    if {hi} > 1.0: {hi} = 1.0",
            *[f"    {s}" for s in _contains(c, al, ah, max_off, "TWO_PI", t)],
            f"    if {c}: {hi} = 1.0",
            *[f"    {s}" for s in _contains(c, al, ah, min_off, "TWO_PI", t)],
            f"    if {c}: {lo} = -1.0",
        ]
        return _guarded([al, ah], lo, hi, body)

    return emit


sin = _sincos("_sin", repr(0.5 * _A.PI_LO), repr(-0.5 * _A.PI_LO))
cos = _sincos("_cos", "0.0", "PI_LO")


def tan(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah = a
    c = f"{t}c"
    return [
        f"if not ({ah} - {al} < PI_LO and abs({al}) <= SIN_SAFE and abs({ah}) <= SIN_SAFE):",
        f"    {lo} = {hi} = NAN",
        "else:",
        *[f"    {s}" for s in _contains(c, al, ah, repr(0.5 * _A.PI_LO), "PI_LO", t)],
        f"    if {c}:",
        f"        {lo} = {hi} = NAN",
        "    else:",
        f"        {lo} = _tan({al})",
        *[f"        {s}" for s in _dnf(lo)],
        f"        {hi} = _tan({ah})",
        *[f"        {s}" for s in _upf(hi)],
    ]


# --------------------------------------------------------------------- piecewise
def _fabs_lines(lo: str, hi: str, al: str, ah: str) -> Lines:
    """|x| for non-NaN bounds (arith.fabs)."""
    return [f"{lo} = {al} if {al} > -{ah} else -{ah}",
            f"if {lo} < 0.0: {lo} = 0.0",
            f"{hi} = -{al} if -{al} > {ah} else {ah}"]


def fabs(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah = a
    return _guarded([al, ah], lo, hi, _fabs_lines(lo, hi, al, ah))


def _two_sided(lo: str, hi: str) -> Lines:
    return [f"if not {lo} <= {hi}: {lo} = {hi} = NAN"]


def fmin(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah, bl, bh = a
    return _guarded(a, lo, hi, [f"{lo} = {al} if {al} < {bl} else {bl}",
                                f"{hi} = {ah} if {ah} < {bh} else {bh}", *_two_sided(lo, hi)])


def fmax(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah, bl, bh = a
    return _guarded(a, lo, hi, [f"{lo} = {al} if {al} > {bl} else {bl}",
                                f"{hi} = {ah} if {ah} > {bh} else {bh}", *_two_sided(lo, hi)])


def _rounder(fn: str):
    def emit(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
        al, ah = a
        return _guarded(a, lo, hi, [
            f"{lo} = _float({fn}({al})) if -INT_EXACT < {al} < INT_EXACT else {al}",
            f"{hi} = _float({fn}({ah})) if -INT_EXACT < {ah} < INT_EXACT else {ah}",
            *_two_sided(lo, hi)])

    return emit


floor = _rounder("_floor")
ceil = _rounder("_ceil")


def sign(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    al, ah = a
    return _guarded(a, lo, hi, [
        f"{lo} = 1.0 if {al} > 0.0 else (-1.0 if {al} < 0.0 else 0.0)",
        f"{hi} = 1.0 if {ah} > 0.0 else (-1.0 if {ah} < 0.0 else 0.0)",
        *_two_sided(lo, hi)])


# ------------------------------------------------------------------------- logic
def _logic(true_sure: str, false_sure: str):
    """[1, 1] when surely true, [0, 0] when surely false, else [0, 1] (arith._bool_interval)."""

    def emit(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
        names = dict(zip(("al", "ah", "bl", "bh"), a, strict=False))
        ts, fs = true_sure.format(**names), false_sure.format(**names)
        return _guarded(a, lo, hi, [f"{lo} = 1.0 if {ts} else 0.0",
                                    f"{hi} = 0.0 if {fs} else 1.0"])

    return emit


lt = _logic("{ah} < {bl}", "{al} >= {bh}")
le = _logic("{ah} <= {bl}", "{al} > {bh}")
eq = _logic("({al} == {ah} and {bl} == {bh} and {al} == {bl})", "({ah} < {bl} or {al} > {bh})")
ne = _logic("({ah} < {bl} or {al} > {bh})", "({al} == {ah} and {bl} == {bh} and {al} == {bl})")
not_ = _logic("({al} == 0.0 and {ah} == 0.0)", "({al} > 0.0 or {ah} < 0.0)")
and_ = _logic("(({al} > 0.0 or {ah} < 0.0) and ({bl} > 0.0 or {bh} < 0.0))",
              "(({al} == 0.0 and {ah} == 0.0) or ({bl} == 0.0 and {bh} == 0.0))")
or_ = _logic("(({al} > 0.0 or {ah} < 0.0) or ({bl} > 0.0 or {bh} < 0.0))",
             "(({al} == 0.0 and {ah} == 0.0) and ({bl} == 0.0 and {bh} == 0.0))")


def if_else_zero(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
    """``c ? x : 0`` (arith.if_else_zero)."""
    cl, ch, xl, xh = a
    return _guarded(a, lo, hi, [
        f"if {cl} > 0.0 or {ch} < 0.0: {lo} = {xl}; {hi} = {xh}",
        f"elif {cl} == 0.0 and {ch} == 0.0: {lo} = {hi} = 0.0",
        "else:",
        f"    {lo} = {xl} if {xl} < 0.0 else 0.0",
        f"    {hi} = {xh} if {xh} > 0.0 else 0.0"])


# ------------------------------------------------------- helpers called, not inlined
# Longer operations: plain functions of floats returning (lo, hi), mirroring arith.
def _hcall(name: str):
    def emit(lo: str, hi: str, a: Sequence[str], t: str) -> Lines:
        return [f"{lo}, {hi} = _S_{name}({', '.join(a)})"]

    return emit


def _dnf_v(x: float) -> float:
    if x > MAX:
        x = MAX
    return x - (abs(x) * _A.REL_LIBM + _A.ABS_LIBM)


def _upf_v(x: float) -> float:
    if x < -MAX:
        x = -MAX
    return x + (abs(x) * _A.REL_LIBM + _A.ABS_LIBM)


def _isnan(*v: float) -> bool:
    return any(x != x for x in v)


def _fabs_v(al: float, ah: float) -> tuple[float, float]:
    if al != al or ah != ah:
        return NAN, NAN
    lo = al if al > -ah else -ah
    if lo < 0.0:
        lo = 0.0
    return lo, (-al if -al > ah else ah)


def _pow_v(x: float, n: float) -> float:
    """math.pow with numpy's overflow result (+-inf) and NaN for NaN."""
    try:
        return math.pow(x, n)
    except OverflowError:
        odd = float(n).is_integer() and int(n) % 2 == 1
        return -INF if (x < 0 and odd) else INF


def h_powi(al: float, ah: float, n: int) -> tuple[float, float]:
    """x**n for an integer n (arith.powi)."""
    n = int(n)
    if n == 0:
        return (NAN, NAN) if _isnan(al, ah) else (1.0, 1.0)
    if n == 1:
        return al, ah
    if n == 2:
        return _OPS["sq"](al, ah)
    if n < 0:
        pl, ph = h_powi(al, ah, -n)
        return _OPS["inv"](pl, ph)
    if n % 2 == 1:
        return _dnf_v(_pow_v(al, n)), _upf_v(_pow_v(ah, n))
    ml, mh = _fabs_v(al, ah)
    lo = _dnf_v(_pow_v(ml, n))
    if lo < 0.0:
        lo = 0.0
    return lo, _upf_v(_pow_v(mh, n))


def h_powc(al: float, ah: float, c: float) -> tuple[float, float]:
    """x**c for a real constant c (arith.powc)."""
    c = float(c)
    if not math.isfinite(c):
        return NAN, NAN
    if c.is_integer() and abs(c) < 2 ** 31:
        return h_powi(al, ah, int(c))
    if c > 0:
        if al < 0.0:
            return NAN, NAN
        lo = _dnf_v(_pow_v(al, c))
        if lo < 0.0:
            lo = 0.0
        return lo, _upf_v(_pow_v(ah, c))
    if al <= 0.0:
        return NAN, NAN
    lo = _dnf_v(_pow_v(ah, c))
    if lo < 0.0:
        lo = 0.0
    return lo, _upf_v(_pow_v(al, c))


def h_pow(al: float, ah: float, bl: float, bh: float) -> tuple[float, float]:
    """x**y for an interval y (arith.pow): exp(y log x) on x > 0, thin integer y by powi."""
    if _isnan(al, ah, bl, bh):
        return NAN, NAN
    if bl == bh and -2.0 ** 31 < bl < 2.0 ** 31 and float(math.floor(bl)) == bl:
        return h_powi(al, ah, int(bl))
    if (al < 0.0 and ah >= 0.0) or (al <= 0.0 and ah >= 0.0 and bl < 0.0):
        return NAN, NAN
    ll, lh = _OPS["log"](al, ah)
    pl, ph = _OPS["mul"](ll, lh, bl, bh)
    lo, hi = _OPS["exp"](pl, ph)
    if _isnan(lo, hi):
        return NAN, NAN
    return lo, hi


def h_atan2(yl: float, yh: float, xl: float, xh: float) -> tuple[float, float]:
    """atan2(y, x) in [-pi, pi] (arith.atan2)."""
    y0 = yl + 0.0
    y1 = yh + 0.0
    c = (math.atan2(y0, xl), math.atan2(y0, xh), math.atan2(y1, xl), math.atan2(y1, xh))
    if _isnan(*c):
        lo = hi = NAN
    else:
        lo = _dnf_v(min(c))
        if lo < -_A.PI_HI:
            lo = float(-_A.PI_HI)
        hi = _upf_v(max(c))
        if hi > _A.PI_HI:
            hi = float(_A.PI_HI)
    cut = xl <= 0 and yl < 0 and yh >= 0
    origin = xl <= 0 and xh >= 0 and yl <= 0 and yh >= 0
    if (cut or origin) and lo == lo:
        lo, hi = float(-_A.PI_HI), float(_A.PI_HI)
    return lo, hi


def h_hypot(al: float, ah: float, bl: float, bh: float) -> tuple[float, float]:
    """hypot (arith.hypot)."""
    xl, xh = _fabs_v(al, ah)
    yl, yh = _fabs_v(bl, bh)
    lo = _dnf_v(math.hypot(xl, yl))
    if lo < 0.0:
        lo = 0.0
    hi = _upf_v(math.hypot(xh, yh))
    if not lo <= hi:
        return NAN, NAN
    return lo, hi


def h_copysign(al: float, ah: float, bl: float, bh: float) -> tuple[float, float]:
    """copysign (arith.copysign)."""
    if _isnan(al, ah, bl, bh):
        return NAN, NAN
    ml, mh = _fabs_v(al, ah)
    if bl >= 0:
        return ml, mh
    if bh < 0:
        return -mh, -ml
    return -mh, mh


def h_fmod(al: float, ah: float, bl: float, bh: float) -> tuple[float, float]:
    """fmod(x, y): the sign of x, magnitude below |y| (arith.fmod)."""
    if _isnan(al, ah, bl, bh) or (bl <= 0 and bh >= 0):
        return NAN, NAN
    ml, mh = _fabs_v(bl, bh)
    if (al >= 0 and ah < ml) or (ah <= 0 and -al < ml):
        return al, ah
    lo = 0.0 if al >= 0 else (al if al > -mh else -mh)
    hi = 0.0 if ah <= 0 else (ah if ah < mh else mh)
    return lo, hi


def h_remainder(al: float, ah: float, bl: float, bh: float) -> tuple[float, float]:
    """IEEE remainder (arith.remainder)."""
    if _isnan(al, ah, bl, bh) or (bl <= 0 and bh >= 0):
        return NAN, NAN
    ml, mh = _fabs_v(bl, bh)
    if -2.0 * al <= ml and 2.0 * ah <= ml:
        return al, ah
    half = mh * 0.5 + _A.TINY
    xm = -al if -al > ah else ah
    bound = half if half < xm else xm
    return -bound, bound


def h_erfinv(al: float, ah: float) -> tuple[float, float]:
    """erfinv (arith.erfinv), by scipy's erfinv of each bound."""
    if al <= -1.0 or ah >= 1.0:
        return NAN, NAN
    return _dnf_v(float(_special.erfinv(al))), _upf_v(float(_special.erfinv(ah)))


# ------------------------------------------------------------------------ tables
def literal(v: float) -> str:
    """Source text of a float constant: finite literals (negative ones in parentheses),
    ``INF``, ``NINF`` or ``NAN`` (names of :data:`NAMESPACE`)."""
    v = float(v)
    if v != v:
        return "NAN"
    if v == INF:
        return "INF"
    if v == -INF:
        return "NINF"
    s = repr(v)
    return f"({s})" if s.startswith("-") else s


def _literal_value(s: str) -> float:
    if s in ("NAN", "INF", "NINF"):
        return {"NAN": NAN, "INF": INF, "NINF": -INF}[s]
    return float(s.strip("()"))


# name -> emitter(lo, hi, operands, temp prefix) of the operations of arith with that name
EMITTERS: dict[str, Callable[..., Lines]] = {
    "add": add, "sub": sub, "neg": neg, "twice": twice, "assign": assign, "mul": mul,
    "mulci": mulci, "sq": sq, "div": div, "inv": inv, "sqrt": sqrt, "exp": exp,
    "expm1": expm1, "log": log, "log1p": log1p, "sin": sin, "cos": cos, "tan": tan,
    "asin": asin, "acos": acos, "atan": atan, "sinh": sinh, "cosh": cosh, "tanh": tanh,
    "asinh": asinh, "acosh": acosh, "atanh": atanh, "erf": erf, "fabs": fabs,
    "fmin": fmin, "fmax": fmax, "floor": floor, "ceil": ceil, "sign": sign, "lt": lt,
    "le": le, "eq": eq, "ne": ne, "not_": not_, "and_": and_, "or_": or_,
    "if_else_zero": if_else_zero,
    "pow": _hcall("pow"), "atan2": _hcall("atan2"), "hypot": _hcall("hypot"),
    "copysign": _hcall("copysign"), "fmod": _hcall("fmod"), "remainder": _hcall("remainder"),
    "erfinv": _hcall("erfinv"),
}
# operations with a float constant known when the source is generated
CONST_EMITTERS: dict[str, Callable[..., Lines]] = {
    "addc": addc, "csub": csub, "mulc": mulc, "divc": divc, "cdiv": cdiv,
}
HELPERS: dict[str, Callable[..., tuple[float, float]]] = {
    "pow": h_pow, "atan2": h_atan2, "hypot": h_hypot, "copysign": h_copysign,
    "fmod": h_fmod, "remainder": h_remainder, "erfinv": h_erfinv, "powi": h_powi,
    "powc": h_powc,
}
# Emitted as calls of a function compiled from the emitter (long, rarely hot operations).
CALLED = frozenset({"tan", "asin", "acos", "sinh", "cosh", "asinh", "acosh", "atanh",
                    "erf", "expm1", "log1p", "tanh", "atan", "floor", "ceil", "sign", "eq",
                    "ne", "and_", "or_"})
_ARITY = {"add": 2, "sub": 2, "mul": 2, "mulci": 2, "div": 2, "fmin": 2, "fmax": 2,
          "lt": 2, "le": 2, "eq": 2, "ne": 2, "and_": 2, "or_": 2, "if_else_zero": 2,
          "pow": 2, "atan2": 2, "hypot": 2, "copysign": 2, "fmod": 2, "remainder": 2}


def _compile_emitter(name: str, emit: Callable[..., Lines], arity: int,
                     const: float | None = None) -> Callable[..., tuple[float, float]]:
    args = ["al", "ah", "bl", "bh"][: 2 * arity]
    extra = () if const is None else (const,)
    body = emit("lo", "hi", args, "t", *extra)
    src = "\n".join([f"def _op({', '.join(args)}):", *[f"    {s}" for s in body],
                     "    return lo, hi"]) + "\n"
    ns = dict(NAMESPACE)
    ns.update({f"_S_{k}": v for k, v in HELPERS.items()})
    exec(compile(src, f"<scalar:{name}>", "exec"), ns)  # noqa: S102
    return ns["_op"]


# The operations as functions of floats (compiled from their emitters when first needed):
# the helpers call some of them, the generated code calls those of CALLED.
_OPS: dict[str, Callable[..., tuple[float, float]]] = {}


def ready() -> dict[str, Any]:
    """Compile the operations called by generated code (once) and return :data:`NAMESPACE`,
    the globals of a generated evaluator."""
    if not _OPS:
        ops = {}
        for name, emitter in EMITTERS.items():
            if name == "mulci":  # needs its constant operand as literals: see scalar_op
                continue
            ops[name] = HELPERS.get(name) or _compile_emitter(name, emitter,
                                                              _ARITY.get(name, 1))
        NAMESPACE.update({f"_S_{k}": v for k, v in HELPERS.items()})
        NAMESPACE.update({f"_S_{k}": v for k, v in ops.items() if k in CALLED})
        _OPS.update(ops)
    return NAMESPACE


def emit(name: str, lo: str, hi: str, args: Sequence[str], t: str) -> Lines:
    """Source lines of operation ``name`` (inlined, or a call for :data:`CALLED` ones)."""
    if name in CALLED:
        return [f"{lo}, {hi} = _S_{name}({', '.join(args)})"]
    return EMITTERS[name](lo, hi, args, t)


def scalar_op(name: str, *consts: float) -> Callable[..., tuple[float, float]]:
    """The scalar operation ``name`` of :mod:`~casadi_cmpc.interval.arith` as a function of
    floats ``(al, ah[, bl, bh]) -> (lo, hi)``, compiled from the very source lines that the
    scalar compiler inlines. Operations with a constant (``addc``, ``csub``, ``mulc``,
    ``divc``, ``cdiv``, ``powi``, ``powc``) take it here: ``scalar_op("addc", 2.5)``;
    ``mulci`` takes the bounds of its constant interval: ``scalar_op("mulci", 2.0, 3.0)``
    returns ``(al, ah) -> (lo, hi)``."""
    ready()
    if name in CONST_EMITTERS:
        (c,) = consts
        return _compile_emitter(name, CONST_EMITTERS[name], 1, float(c))
    if name == "mulci":
        cl, ch = (literal(c) for c in consts)
        body = mulci("lo", "hi", ["al", "ah", cl, ch], "t")
        src = "\n".join(["def _op(al, ah):", *[f"    {s}" for s in body],
                         "    return lo, hi"]) + "\n"
        ns = dict(NAMESPACE)
        exec(compile(src, "<scalar:mulci>", "exec"), ns)  # noqa: S102
        return ns["_op"]
    if name in ("powi", "powc"):
        (c,) = consts
        fn = HELPERS[name]
        return lambda al, ah: fn(al, ah, c)
    if name in HELPERS:
        return HELPERS[name]
    return _compile_emitter(name, EMITTERS[name], _ARITY.get(name, 1))
