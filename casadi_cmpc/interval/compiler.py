"""Compile a CasADi SX ``Function`` into a batched interval inclusion function.

The compiler walks the Function's instruction list once (``n_instructions``,
``instruction_id/input/output/constant``) and generates straight-line Python/numpy source in
which every CasADi operation is replaced by its interval extension from
:mod:`casadi_cmpc.interval.arith`. Constants are folded at compile time (soundly: folded with
the interval operations themselves) and operations with a thin constant operand are
specialised (e.g. ``x * c`` costs two multiplications instead of four).

The same walk generates a second evaluator for small batches (:class:`_ScalarCodegen`):
straight-line Python code on floats, one box after the other, with the operations of
:mod:`casadi_cmpc.interval._scalar` inlined. :class:`InclusionFunction` picks one of the two
by batch size (``backend="auto"``) or as told. :func:`inclusion` caches the compiled
functions per Function object.
"""

from __future__ import annotations

import hashlib
import math
import pickle
import sys
import threading
import warnings
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import Any

import casadi as ca
import numpy as np

from .._validate import as_boxes
from ..exceptions import (
    CmpcWarning,
    DimensionError,
    FreeSymbolError,
    UnsupportedOperationError,
)
from . import _derivative as _dv
from . import _fpu, arith
from . import _scalar as _S
from ._native import Rows as _Rows
from ._native import as_arrays as _native_as_arrays

__all__ = ["inclusion", "InclusionFunction", "inclusion_cache_clear"]

_KINDS = ("natural", "centered")

# op code -> (arith function name, arity)
_UNARY = {
    ca.OP_ASSIGN: "assign", ca.OP_NEG: "neg", ca.OP_SQ: "sq", ca.OP_TWICE: "twice",
    ca.OP_INV: "inv", ca.OP_SQRT: "sqrt", ca.OP_EXP: "exp", ca.OP_LOG: "log",
    ca.OP_SIN: "sin", ca.OP_COS: "cos", ca.OP_TAN: "tan", ca.OP_ASIN: "asin",
    ca.OP_ACOS: "acos", ca.OP_ATAN: "atan", ca.OP_SINH: "sinh", ca.OP_COSH: "cosh",
    ca.OP_TANH: "tanh", ca.OP_ASINH: "asinh", ca.OP_ACOSH: "acosh", ca.OP_ATANH: "atanh",
    ca.OP_FABS: "fabs", ca.OP_FLOOR: "floor", ca.OP_CEIL: "ceil", ca.OP_SIGN: "sign",
    ca.OP_NOT: "not_", ca.OP_ERF: "erf", ca.OP_ERFINV: "erfinv", ca.OP_LOG1P: "log1p",
    ca.OP_EXPM1: "expm1",
}
_BINARY = {
    ca.OP_ADD: "add", ca.OP_SUB: "sub", ca.OP_MUL: "mul", ca.OP_DIV: "div",
    ca.OP_POW: "pow", ca.OP_CONSTPOW: "pow", ca.OP_ATAN2: "atan2", ca.OP_FMIN: "fmin",
    ca.OP_FMAX: "fmax", ca.OP_LT: "lt", ca.OP_LE: "le", ca.OP_EQ: "eq", ca.OP_NE: "ne",
    ca.OP_AND: "and_", ca.OP_OR: "or_", ca.OP_IF_ELSE_ZERO: "if_else_zero",
    ca.OP_COPYSIGN: "copysign", ca.OP_FMOD: "fmod", ca.OP_REMAINDER: "remainder",
    ca.OP_HYPOT: "hypot",
}

# Operations through which f may jump: the mean-value (centered) form is not valid for them.
_DISCONTINUOUS = {
    ca.OP_FLOOR, ca.OP_CEIL, ca.OP_SIGN, ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE, ca.OP_NOT,
    ca.OP_AND, ca.OP_OR, ca.OP_IF_ELSE_ZERO, ca.OP_FMOD, ca.OP_REMAINDER, ca.OP_COPYSIGN,
    ca.OP_ATAN2,  # jumps by 2 pi across the negative x axis
}


def _discontinuous_ops(fun: ca.Function) -> list[str]:
    ops = {fun.instruction_id(k) for k in range(fun.n_instructions())}
    return sorted(_op_name(op) for op in ops & _DISCONTINUOUS)


def _op_name(op: int) -> str:
    for name in dir(ca):
        if name.startswith("OP_") and getattr(ca, name) == op:
            return name
    return f"op {op}"


def _as_sx_function(fun: Any, allow_param: bool = False) -> ca.Function:
    """``fun`` checked (SX, no free symbols, dense inputs), an MX Function expanded.

    With ``allow_param`` a :class:`~._derivative.ParamFunction` (an SX Function whose
    parameter reads are exact constants) is accepted as it is."""
    if allow_param and isinstance(fun, _dv.ParamFunction):
        if not fun.function.is_a("SXFunction") or fun.function.has_free():
            raise TypeError(f"ParamFunction '{fun.name()}' must wrap an SX Function without "
                            "free symbols")
        return fun  # type: ignore[return-value]
    if not isinstance(fun, ca.Function):
        raise TypeError(f"expected a casadi.Function, got {type(fun).__name__}")
    if not fun.is_a("SXFunction"):
        try:
            fun = fun.expand()
        except Exception as exc:  # pragma: no cover - depends on CasADi internals
            raise UnsupportedOperationError(
                f"Function '{fun.name()}' is not an SX Function and cannot be expanded to one "
                f"({exc}); build it from casadi.SX symbols") from exc
    if fun.has_free():
        free = ", ".join(str(v) for v in fun.get_free())
        raise FreeSymbolError(
            f"Function '{fun.name()}' depends on symbols that are not among its inputs: "
            f"{free}; add them as inputs (or substitute numbers for them with "
            "casadi.substitute) before building an interval inclusion")
    for i in range(fun.n_in()):
        if not fun.sparsity_in(i).is_dense():
            raise DimensionError(
                f"input {i} ('{fun.name_in(i)}') of '{fun.name()}' is sparse; "
                "interval inclusion functions need dense inputs")
    return fun


class _Codegen:
    """Generate the straight-line numpy source for one SX Function."""

    def __init__(self, fun: ca.Function, widen: frozenset[int] = frozenset()) -> None:
        self.fun = fun
        self.widen = widen  # instruction indices of constants to widen (derived constants)
        self.only: set[int] | None = None  # instructions to emit (None: all)
        self.out_map: dict[int, int] | None = None  # Function output -> evaluator output
        self.lines: list[str] = []
        self.consts: dict[int, tuple[float, float]] = {}  # slot -> folded constant interval
        self.const_table: list[float] = []

    def _lit(self, v: float) -> str:
        if np.isfinite(v):
            return repr(float(v))
        self.const_table.append(float(v))
        return f"_K[{len(self.const_table) - 1}]"

    def _operand(self, slot: int) -> tuple[str, str]:
        if slot in self.consts:
            lo, hi = self.consts[slot]
            return self._lit(lo), self._lit(hi)
        return f"l{slot}", f"h{slot}"

    def _thin(self, slot: int) -> float | None:
        c = self.consts.get(slot)
        if c is not None and c[0] == c[1]:
            return c[0]
        return None

    def _signed_const(self, slot: int) -> bool:
        c = self.consts.get(slot)
        return c is not None and (c[0] > 0 or c[1] < 0) and bool(np.isfinite(c).all())

    def _emit(self, out: int, expr: str) -> None:
        self.consts.pop(out, None)
        self.lines.append(f"    l{out}, h{out} = {expr}")

    def _fold(self, name: str, out: int, ins: Sequence[int]) -> None:
        fn = getattr(arith, name)
        args = []
        for s in ins:
            args.extend(np.array([v]) for v in self.consts[s])
        with np.errstate(all="ignore"):
            lo, hi = fn(*args)
        lo = float(np.asarray(lo).reshape(-1)[0])
        hi = float(np.asarray(hi).reshape(-1)[0])
        if np.isnan(lo) or np.isnan(hi):
            # possibly undefined: stays NaN on both sides (as the operations' own results),
            # never "any real", which a later bounded operation (sin, atan) would narrow
            lo = hi = np.nan
        self.consts[out] = (lo, hi)

    def _exact_const(self, out: int, ins: Sequence[int], op: int) -> bool:
        """Fold exactly-representable constant results (neg, twice, assign) without widening."""
        if op in (ca.OP_NEG, ca.OP_ASSIGN, ca.OP_TWICE):
            lo, hi = self.consts[ins[0]]
            if op == ca.OP_NEG:
                lo, hi = -hi, -lo
            elif op == ca.OP_TWICE:  # exact, but an overflow is only known to be huge
                lo, hi = arith.twice(np.float64(lo), np.float64(hi))
                lo, hi = float(lo), float(hi)
            self.consts[out] = (lo, hi)
            return True
        return False

    def build(self) -> str:
        """Walk the instruction list: fold constants, emit the other instructions through
        :meth:`_input`, :meth:`_output`, :meth:`_unary` and :meth:`_binary`."""
        f = self.fun
        interval_of = getattr(f, "instruction_bounds", None)  # interval-valued parameters
        for k in range(f.n_instructions()):
            if self.only is not None and k not in self.only:
                continue
            op = f.instruction_id(k)
            ins = list(f.instruction_input(k))
            outs = list(f.instruction_output(k))
            if op == ca.OP_CONST:
                v = float(f.instruction_constant(k))
                iv = interval_of(k) if interval_of is not None else None
                if iv is not None:  # an interval-valued parameter, as it is
                    self.consts[outs[0]] = (float(iv[0]), float(iv[1]))
                elif k in self.widen:
                    lo, hi = _widen_constant(v)
                    self.consts[outs[0]] = (lo, hi)
                else:
                    self.consts[outs[0]] = (v, v)
            elif op == ca.OP_INPUT:
                self.consts.pop(outs[0], None)
                self._input(k, outs[0], ins[0], ins[1])
            elif op == ca.OP_OUTPUT:
                oi = outs[0] if self.out_map is None else self.out_map[outs[0]]
                self._output(k, ins[0], oi, outs[1])
            elif op in _UNARY:
                name = _UNARY[op]
                if ins[0] in self.consts:
                    if not self._exact_const(outs[0], ins, op):
                        self._fold(name, outs[0], ins[:1])
                    continue
                self._unary(k, op, name, outs[0], ins[0])
            elif op in _BINARY:
                name = _BINARY[op]
                if ins[0] in self.consts and ins[1] in self.consts:
                    self._fold(name, outs[0], (ins[0], ins[1]))
                    continue
                self._binary(k, op, name, outs[0], ins[0], ins[1])
            else:
                raise UnsupportedOperationError(
                    f"CasADi operation {_op_name(op)} (instruction {k} of '{f.name()}') has no "
                    "interval extension; rewrite the model with elementary operations")
        return self._finish()

    # ------------------------------------------------------------- numpy emitters
    def _input(self, k: int, out: int, i: int, j: int) -> None:
        self.lines.append(f"    l{out} = IL[{i}][{j}]; h{out} = IH[{i}][{j}]")

    def _output(self, k: int, slot: int, oi: int, j: int) -> None:
        lo, hi = self._operand(slot)
        self.lines.append(f"    O[{oi}][{j}] = ({lo}, {hi})")

    def _unary(self, k: int, op: int, name: str, out: int, i0: int) -> None:
        a = self._operand(i0)
        self._emit(out, f"_A.{name}({a[0]}, {a[1]})")

    def _specialised(self, op: int, i0: int, i1: int) -> tuple[str, tuple[Any, ...]] | None:
        """``(name, args)`` of the constant-operand variant of a binary operation (``args``:
        operand slots and float constants), or None for the generic one."""
        c0, c1 = self._thin(i0), self._thin(i1)
        if op == ca.OP_ADD:
            if c1 is not None:
                return "addc", (i0, c1)
            if c0 is not None:
                return "addc", (i1, c0)
        elif op == ca.OP_SUB:
            if c1 is not None:
                return "addc", (i0, -c1)
            if c0 is not None:
                return "csub", (c0, i1)
        elif op == ca.OP_MUL:
            if c1 is not None:
                return "mulc", (i0, c1)
            if c0 is not None:
                return "mulc", (i1, c0)
            if self._signed_const(i1):
                return "mulci", (i0, i1)
            if self._signed_const(i0):
                return "mulci", (i1, i0)
        elif op == ca.OP_DIV:
            if c1 is not None:
                return "divc", (i0, c1)
            if c0 is not None:
                return "cdiv", (c0, i1)
        elif op in (ca.OP_POW, ca.OP_CONSTPOW) and c1 is not None:
            return "powc", (i0, c1)
        return None

    def _binary(self, k: int, op: int, name: str, out: int, i0: int, i1: int) -> None:
        spec = self._specialised(op, i0, i1)
        if spec is None:
            spec = (name, (i0, i1))
        fname, args = spec
        parts: list[str] = []
        for v in args:
            if isinstance(v, int):
                parts.extend(self._operand(v))
            else:
                parts.append(self._lit(v))
        self._emit(out, f"_A.{fname}({', '.join(parts)})")

    def _finish(self) -> str:
        src = ["def _eval(IL, IH, O):"] + (self.lines or ["    pass"])
        return "\n".join(src) + "\n"


class _ScalarCodegen(_Codegen):
    """Generate a straight-line evaluator on Python floats for small batches.

    The instruction walk and the constant folding are those of :class:`_Codegen`; every
    other instruction becomes the source lines of :mod:`._scalar` (static single assignment:
    instruction ``k`` writes ``l{k}``, ``h{k}``). The generated ``_eval_s(B, n)`` takes, per
    input, a list of ``n`` boxes (each a list of ``[lo, hi]`` float pairs, as
    ``ndarray.tolist()`` gives) and returns, per output, the flat list of the ``n * d_o * 2``
    bounds in the order of an ``(n, d_o, 2)`` array, with structural zeros ``[0.0, 0.0]``,
    sanitised like :func:`_sanitize`.
    """

    def __init__(self, fun: ca.Function, widen: frozenset[int], out_pos: Sequence[np.ndarray],
                 size_out: Sequence[int], sanitize: bool = True) -> None:
        super().__init__(fun, widen)
        self.sanitize = sanitize
        self.out_pos = [[int(p) for p in pos] for pos in out_pos]
        self.size_out = list(size_out)
        self.names: dict[int, tuple[str, str]] = {}  # slot -> current (lo, hi) variables
        self.used_inputs: set[int] = set()
        self.results: dict[tuple[int, int], tuple[str, str]] = {}

    def _lit(self, v: float) -> str:
        return _S.literal(v)

    def _operand(self, slot: int) -> tuple[str, str]:
        if slot in self.consts:
            lo, hi = self.consts[slot]
            return self._lit(lo), self._lit(hi)
        return self.names[slot]

    def _set(self, out: int, names: tuple[str, str]) -> None:
        self.consts.pop(out, None)
        self.names[out] = names

    def _add(self, lines: Sequence[str]) -> None:
        self.lines.extend(f"        {s}" for s in lines)

    def _input(self, k: int, out: int, i: int, j: int) -> None:
        self.used_inputs.add(i)
        self._add([f"l{k}, h{k} = x{i}[{j}]"])
        self._set(out, (f"l{k}", f"h{k}"))

    def _output(self, k: int, slot: int, oi: int, j: int) -> None:
        self.results[(oi, j)] = self._operand(slot)

    def _unary(self, k: int, op: int, name: str, out: int, i0: int) -> None:
        a = self._operand(i0)
        if name == "assign":
            self._set(out, a)
            return
        lo, hi = f"l{k}", f"h{k}"
        self._add(_S.emit(name, lo, hi, a, f"t{k}_"))
        self._set(out, (lo, hi))

    def _binary(self, k: int, op: int, name: str, out: int, i0: int, i1: int) -> None:
        lo, hi = f"l{k}", f"h{k}"
        t = f"t{k}_"
        spec = self._specialised(op, i0, i1)
        if spec is None:
            lines = _S.emit(name, lo, hi, [*self._operand(i0), *self._operand(i1)], t)
        else:
            fname, args = spec
            if fname == "mulci":
                lines = _S.emit("mulci", lo, hi, [*self._operand(args[0]),
                                                  *self._operand(args[1])], t)
            elif fname == "powc":
                a = self._operand(args[0])
                lines = [f"{lo}, {hi} = _S_powc({a[0]}, {a[1]}, {self._lit(args[1])})"]
            elif fname in ("csub", "cdiv"):
                lines = _S.CONST_EMITTERS[fname](lo, hi, self._operand(args[1]), t, args[0])
            else:
                lines = _S.CONST_EMITTERS[fname](lo, hi, self._operand(args[0]), t, args[1])
        self._add(lines)
        self._set(out, (lo, hi))

    def _finish(self) -> str:
        n_in = self.fun.n_in()
        # the constants and ``abs`` as default arguments: local variables are read faster
        src = ["def _eval_s(B, n, U=U, TINY=TINY, MAX=MAX, NMAX=NMAX, RL=RL, AL=AL, NAN=NAN, "
               "INF=INF, NINF=NINF, abs=abs):"]
        if n_in:
            src.append(f"    {', '.join(f'B{i}' for i in range(n_in))}, = B")
        outs = range(len(self.size_out))
        src.append("    " + "; ".join(f"R{i} = []" for i in outs) if self.size_out else "    pass")
        src.append("    for _k in range(n):")
        body = [f"        x{i} = B{i}[_k]" for i in sorted(self.used_inputs)]
        body += self.lines
        for oi in outs:
            if not self.size_out[oi]:
                continue
            cells = ["0.0, 0.0"] * self.size_out[oi]
            for j, pos in enumerate(self.out_pos[oi]):
                lo, hi = self.results[(oi, j)]
                if not self.sanitize:
                    pass
                elif _S.is_constant_text(lo) and _S.is_constant_text(hi):
                    vl, vh = _S._literal_value(lo), _S._literal_value(hi)
                    if not vl <= vh:  # as _sanitize
                        lo, hi = "NINF", "INF"
                else:
                    body.append(f"        if not {lo} <= {hi}: {lo} = NINF; {hi} = INF")
                cells[pos] = f"{lo}, {hi}"
            body.append(f"        R{oi} += ({', '.join(cells)})")
        src += body or ["        pass"]
        src.append(f"    return [{', '.join(f'R{i}' for i in outs)}]")
        return "\n".join(src) + "\n"


_REBUILT: OrderedDict[str, Any] = OrderedDict()  # pickled spec hash -> InclusionFunction


def _rebuild_inclusion(spec: bytes) -> InclusionFunction:
    """The InclusionFunction of a pickled spec, built once per process (last 64 kept)."""
    key = hashlib.sha1(spec).hexdigest()
    F = _REBUILT.get(key)
    if F is None:
        fun, kind, backend, derived, evaluate = pickle.loads(spec)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CmpcWarning)  # said once where it was built
            F = InclusionFunction(fun, kind, backend=backend, derived_outputs=derived,
                                  evaluate=evaluate)
        _REBUILT[key] = F
        while len(_REBUILT) > 64:
            _REBUILT.popitem(last=False)
    else:
        _REBUILT.move_to_end(key)
    return F


class InclusionFunction:
    """A batched interval inclusion function compiled from a CasADi SX Function.

    Large batches are evaluated in chunks of :attr:`chunk` boxes (default 8192 for the natural
    form, 4096 for the centered one, which has more temporaries), which keeps the numpy
    temporaries in cache.

    Call it with one box array per input of the Function: ``(N, d_i, 2)`` (or one ``(d_i, 2)``
    box, or a :class:`~casadi_cmpc.Box`). Inputs with ``N = 1`` broadcast against the others.
    Returns a list with one ``(N, d_o, 2)`` array per output, where ``d_i``/``d_o`` are the
    numbers of elements of the (dense, column-major flattened) inputs/outputs.

    Guarantee: for every point inside the input boxes, the exact real value of each output
    lies inside the returned bounds (floating-point rounding included). Where the Function is
    undefined on part of a box (e.g. ``log`` of a box reaching 0), the result is
    ``[-inf, inf]``. Outputs never contain NaN.

    Parameters
    ----------
    fun : casadi.Function or ParamFunction
        SX Function (an MX Function is expanded) with dense inputs; or a
        :class:`~._derivative.ParamFunction`, whose parameters enter as exact constants (and
        its possibly rounded constants, :attr:`~._derivative.ParamFunction.derived`, with a
        margin).
    kind : {"natural", "centered"}
        See :func:`inclusion`.
    backend : {"auto", "numpy", "scalar", "native"}
        Evaluator of the boxes (see Notes).
    derived_outputs, evaluate : internal
        Restricted forms for derivative graphs: outputs whose constants were folded by
        CasADi (widened), and the outputs to evaluate.

    Attributes
    ----------
    fun : casadi.Function or ParamFunction
        The SX Function (expanded if an MX Function was given), or the ParamFunction given.
    kind : str
        ``"natural"`` or ``"centered"``.
    centered_fallback : bool
        True when ``kind == "centered"`` but the Function contains operations through which it
        may be discontinuous (floor, ceil, sign, comparisons, if_else, fmod, remainder,
        copysign): the mean-value form would be unsound there, so the natural inclusion is
        used (a :class:`~casadi_cmpc.CmpcWarning` says so).
    source : str
        The generated numpy source (natural evaluator), for inspection.
    backend : str
        ``"auto"``, ``"numpy"``, ``"scalar"`` or ``"native"``: how batches are evaluated (see
        Notes). May be reassigned.
    scalar_unsupported : list of str
        CasADi operations of the Function (or of its centered graph) without a scalar
        evaluation; when not empty, every batch is evaluated with numpy.
    scalar_source : str or None
        The generated Python float source of the natural evaluator, once it has been used.
    scalar_max_batch, scalar_max_batch_centered : int
        Class attributes: the largest batch that ``backend="auto"`` evaluates with the scalar
        evaluator, for the natural form (32) and the centered form (16). Measured on 2- to
        3-state models: the scalar evaluator is 25-40 times faster for one box and breaks
        even with numpy at about 50 boxes (natural) and 30 boxes (centered).

    Notes
    -----
    Three evaluators compute enclosures with the same rounding, domain and NaN rules
    (:mod:`casadi_cmpc.interval.arith`), all generated from one walk of the instruction list
    (the same constant folding and constants):

    * **numpy**: one numpy interval operation per CasADi instruction over the whole batch
      (8-20 ufunc calls each): a fixed cost of a few µs per instruction, then tens of
      nanoseconds per box and instruction. For large batches.
    * **scalar**: straight-line Python code on floats (:mod:`casadi_cmpc.interval._scalar`),
      one box after the other: no fixed cost per instruction, about 0.1 µs per box and
      instruction. For batches of a few boxes, as model predictive control and nested
      searches evaluate. Its sums, products, quotients and square roots are bit for bit those
      of numpy; libm functions may differ in the last bits (both are covered by the same
      256-ulp margin). It is generated when first used.

    * **native** (natural form): a fused C loop, every operation of one box in registers, the
      outward-rounded rules of :mod:`._cgen` (those of the exported controllers; they hold
      in every FPU rounding mode), compiled once by the system C compiler and cached on
      disk (:mod:`._native`). About 5 µs per call plus 0.1 µs per box and instruction: 3-5
      times cheaper than numpy for batches of 30 to 1000 boxes, as nested searches make
      them; on par with numpy's vectorised libm for 1e5 boxes. Without a C compiler numpy
      evaluates instead (one warning per process). Its enclosures may differ from numpy's
      in the last bits (libm functions, a subnormal in the widening); both are sound, but a
      function that has moved to it answers a repeated call with those bits.

    ``backend="auto"`` (default) evaluates batches of ``1 <= N <= scalar_max_batch`` boxes
    (``scalar_max_batch_centered`` for the centered form) with the scalar evaluator and
    larger ones with numpy, the natural form with the native kernel once the function has
    evaluated :attr:`native_after` batches (its compilation starts in the background after
    :attr:`native_prefetch` batches, and the switch waits for it: the batch at which the
    backend changes does not depend on timings); ``"numpy"``, ``"scalar"`` and ``"native"``
    force one (an empty batch always goes to numpy). Small batches count toward the move as
    one batch each for a function of :attr:`native_large` instructions or more, and as one
    batch per :attr:`native_small_quantum` box instructions (boxes × instructions) for a
    smaller one (a compilation pays for itself only after thousands of small calls of a
    small function); once a function is on its native kernel, a small batch goes there too
    when it holds at least :attr:`native_small_work` box instructions (the scalar code
    would then take longer than the kernel's call). The centered form's scalar evaluation runs
    its Jacobian graph on floats and combines the mean-value terms in Python exactly as
    :meth:`_centered_impl` does (its jump guard encloses the guard expressions with scalar code
    too). A Function with an operation the scalar evaluator lacks is evaluated with numpy
    whatever the backend (:attr:`scalar_unsupported` names them), as is a batch on which Python
    raises an arithmetic exception (e.g. inverted bounds passed to :meth:`evaluate_unchecked`).
    """

    chunk: int = 8192
    chunk_centered: int = 4096
    scalar_max_batch: int = 32
    scalar_max_batch_centered: int = 16
    native_after: int = 16
    native_prefetch: int = 4
    native_large: int = 200
    native_small_work: int = 64
    native_small_quantum: int = 65536

    def __init__(self, fun: ca.Function | _dv.ParamFunction, kind: str = "natural", *,
                 backend: str = "auto", derived_outputs: Sequence[int] = (),
                 evaluate: Sequence[int] | None = None) -> None:
        kind = str(kind).lower()
        if kind not in _KINDS:
            raise ValueError(f"unknown inclusion kind '{kind}'; valid kinds: {', '.join(_KINDS)}")
        backend = _check_backend(backend)
        fun = _as_sx_function(fun, allow_param=True)
        # what rebuilds it in another process (pickle): the graph and the options
        self._spec = (fun, kind, backend, tuple(int(i) for i in derived_outputs),
                      None if evaluate is None else tuple(int(i) for i in evaluate))
        self._param = isinstance(fun, _dv.ParamFunction)
        if derived_outputs or evaluate is not None:
            if kind != "natural":
                raise ValueError("derived_outputs/evaluate are for natural inclusions only")
            if self._param:
                raise TypeError("derived_outputs/evaluate need a casadi.Function, not a "
                                "ParamFunction")
            fun = _restrict(fun, derived_outputs, evaluate)
            self._widen = _derived_constants(
                fun.fun, [i for i in range(fun.fun.n_out()) if i not in derived_outputs])
            self._keep = fun.keep
            fun = fun.fun
        else:
            self._widen = frozenset()
            self._keep = None
        self.fun = fun
        self.kind = kind
        outs = list(range(fun.n_out())) if self._keep is None else list(self._keep)
        self.n_in = fun.n_in()
        self.n_out = len(outs)
        self.size_in = [fun.numel_in(i) for i in range(self.n_in)]
        self.size_out = [fun.numel_out(i) for i in outs]
        self._out_pos = [np.asarray(fun.sparsity_out(i).find(), dtype=np.intp) for i in outs]
        # constants to widen: derived ones of a restricted form, and those a ParamFunction
        # marks as possibly rounded
        self._cwiden = self._widen | frozenset(getattr(fun, "derived", ()))
        self._eval, self.source = _compile(fun, self._cwiden, self._keep)
        self.backend = backend
        self.scalar_unsupported = _scalar_unsupported(fun)
        self._scalar_fn: Callable[..., list[list[Any]]] | None = None
        self._fast: Any = None  # generated checked call for small batches
        self._scalar_strict = False  # tests: raise instead of falling back to numpy
        self.scalar_source: str | None = None
        self.centered_fallback = False
        if kind == "centered":
            bad = _discontinuous_ops(fun)
            if bad:
                self.centered_fallback = True
                warnings.warn(
                    f"'{fun.name()}' contains operations through which it may jump "
                    f"({', '.join(bad)}); the centered (mean-value) form is not valid for it, "
                    "so its natural inclusion is used instead", CmpcWarning, stacklevel=3)
            else:
                self._build_centered()
        if not self._natural_form():
            # the scalar centered form needs the scalar operations of the Jacobian graph
            self.scalar_unsupported = sorted(set(self.scalar_unsupported)
                                             | set(_scalar_unsupported(self._g)))
        self._scalar_capable = not self.scalar_unsupported
        self._is_natural = self._natural_form()
        self._native: Any = None  # the native kernel; False: not available
        self._native_batches = 0  # batches evaluated so far by numpy (auto: when to compile)
        self._small_work = 0  # box instructions of small batches not yet counted
        self._n_instr = self.fun.n_instructions() + (
            self._g.n_instructions() if not self._is_natural else 0)
        self._large = self._n_instr >= self.native_large  # small batches count toward native

    def __reduce__(self) -> tuple[Any, tuple[bytes]]:
        """Pickled as its CasADi graph and options; rebuilt once per process (the compiled
        evaluators and the native kernel are then reused by every later copy)."""
        fun, kind, backend, derived, evaluate = self._spec
        return _rebuild_inclusion, (pickle.dumps((fun, kind, backend, derived, evaluate)),)

    # ---------------------------------------------------------------- natural
    def _inputs(self, args: Sequence[Any]) -> tuple[list[np.ndarray], int]:
        if len(args) != self.n_in:
            raise TypeError(
                f"'{self.fun.name()}' takes {self.n_in} box arguments, got {len(args)}")
        boxes = [as_boxes(a, self.size_in[i], name=self.fun.name_in(i))
                 for i, a in enumerate(args)]
        ns = {b.shape[0] for b in boxes}
        n = max(ns) if ns else 1
        if len(ns - {1, n}) > 0:
            raise DimensionError(
                f"batch sizes of the inputs of '{self.fun.name()}' do not broadcast: "
                f"{[b.shape[0] for b in boxes]}")
        return boxes, n

    def _raw(self, evaluator: Callable[..., None], boxes: Sequence[np.ndarray],
             n_outs: Sequence[int]) -> list[list[Any]]:
        """Run a generated evaluator; per output, a list of (lo, hi) per nonzero."""
        il = [np.ascontiguousarray(b[..., 0].T) for b in boxes]
        ih = [np.ascontiguousarray(b[..., 1].T) for b in boxes]
        o: list[list[Any]] = [[None] * k for k in n_outs]
        with np.errstate(all="ignore"):
            evaluator(il, ih, o)
        return o

    def _pack(self, o: list[list[Any]], n: int) -> list[np.ndarray]:
        outs = []
        for i, pos in enumerate(self._out_pos):
            out = np.zeros((n, self.size_out[i], 2))
            for j, (lo, hi) in enumerate(o[i]):
                out[:, pos[j], 0] = lo
                out[:, pos[j], 1] = hi
            _sanitize(out)
            outs.append(out)
        return outs

    def _natural(self, boxes: Sequence[np.ndarray], n: int) -> list[np.ndarray]:
        return self._pack(self._raw(self._eval, boxes, [len(p) for p in self._out_pos]), n)

    def _single_natural(self) -> bool:
        """One input, one output, plain natural evaluation (what the element evaluators need)."""
        return (self.n_in == 1 and self.n_out == 1 and self._keep is None and not self._widen
                and not self._param and (self.kind == "natural" or self.centered_fallback))

    def _traced(self) -> tuple[ca.Function, list[ca.SX], list[ca.SX]]:
        """``(g, inputs, outputs)``: the Function rebuilt with one work slot per node (to trace
        what each output element depends on) and its symbolic inputs and output expressions.
        Built once."""
        if "_traced_fun" not in self.__dict__:
            syms = self.fun.sx_in()
            outs = self.fun.call(syms)
            g = ca.Function(self.fun.name(), syms, outs, {"live_variables": False})
            self._traced_fun = (g, syms, outs)
        return self._traced_fun

    def component_evaluator(self, j: int) -> Callable[[np.ndarray, np.ndarray], Any] | None:
        """Natural enclosure of one element of the (single) output, for solvers.

        Returns ``ev(lo, hi) -> (lower, upper)`` where ``lo``, ``hi`` have shape (N, n) (the
        boxes of the single input) and the bounds have shape (N,) (or are scalars when the
        element is constant); NaN bounds mean "no information". Only the instructions that
        element depends on are evaluated. ``None`` when this is not available (several
        inputs or outputs, a centered form, a restricted function); a structural zero gives
        ``(0.0, 0.0)``. Cached per element. ``ev.unchecked`` is the same without its own
        ``np.errstate`` (for callers that set it once around many calls).
        """
        if not self._single_natural():
            return None
        cache = self.__dict__.setdefault("_components", {})
        if j in cache:
            return cache[j]
        if not 0 <= j < self.size_out[0]:
            raise IndexError(f"output element {j} out of range ({self.size_out[0]} elements)")
        nz = np.flatnonzero(self._out_pos[0] == j)
        if nz.size == 0:
            def zero(lo: np.ndarray, hi: np.ndarray) -> tuple[float, float]:
                return 0.0, 0.0
            zero.unchecked = zero  # type: ignore[attr-defined]
            cache[j] = zero
            return zero
        k = int(nz[0])
        g = self._traced()[0]
        raw = _compile(g, keep_outputs=[0], nonzeros={k})[0]
        size = g.nnz_out(0)

        def unchecked(lo: np.ndarray, hi: np.ndarray) -> tuple[Any, Any]:
            o: list[list[Any]] = [[None] * size]
            raw([lo.T], [hi.T], o)
            return o[0][k]

        def ev(lo: np.ndarray, hi: np.ndarray) -> tuple[Any, Any]:
            with np.errstate(all="ignore"):
                return unchecked(lo, hi)

        ev.unchecked = unchecked  # type: ignore[attr-defined]  # caller sets np.errstate
        cache[j] = ev
        return ev

    def component_core(self, j: int) -> tuple[Callable[..., Any], list[tuple[str, float]]] | None:
        """Element ``j`` of the output as ``core(x)`` followed by affine steps, for solvers.

        When element ``j`` is ``core(x) + c`` (also ``c + core``, ``core - c``) or
        ``core(x) * c`` with ``c > 0``, possibly nested, returns ``(ev, steps)``: ``ev`` is the
        natural enclosure of ``core`` (same conventions as :meth:`component_evaluator`) and
        ``steps`` lists ``("add", c)`` / ``("mul", c)``, outermost first. A test such as
        ``f_j > y`` then becomes ``core > y'`` with the threshold moved back through the
        steps (rounded in the safe direction by the caller), which spares the interval
        operations of the steps. ``None`` when element ``j`` has no such step or when
        :meth:`component_evaluator` is not available.
        """
        if not self._single_natural():
            return None
        cache = self.__dict__.setdefault("_cores", {})
        if j in cache:
            return cache[j]
        if not 0 <= j < self.size_out[0]:
            raise IndexError(f"output element {j} out of range ({self.size_out[0]} elements)")
        nz = np.flatnonzero(self._out_pos[0] == j)
        result = None
        if nz.size:
            f = self.fun
            _, syms, outs = self._traced()
            e = outs[0].nz[int(nz[0])]
            steps: list[tuple[str, float]] = []
            while not e.is_constant() and not e.is_symbolic() and e.n_dep() == 2:
                a, b = e.dep(0), e.dep(1)
                if e.is_op(ca.OP_ADD) and b.is_constant():
                    steps.append(("add", float(b)))
                    e = a
                elif e.is_op(ca.OP_ADD) and a.is_constant():
                    steps.append(("add", float(a)))
                    e = b
                elif e.is_op(ca.OP_SUB) and b.is_constant():
                    steps.append(("add", -float(b)))
                    e = a
                elif e.is_op(ca.OP_MUL) and b.is_constant() and float(b) > 0:
                    steps.append(("mul", float(b)))
                    e = a
                elif e.is_op(ca.OP_MUL) and a.is_constant() and float(a) > 0:
                    steps.append(("mul", float(a)))
                    e = b
                else:
                    break
            finite = all(np.isfinite(c) for _, c in steps)
            if steps and finite and not e.is_constant():
                core = InclusionFunction(ca.Function(f"{f.name()}_core{j}", syms, [e]))
                result = (core.component_evaluator(0), steps)
        cache[j] = result
        return result

    # --------------------------------------------------------------- centered
    def _build_centered(self) -> None:
        """One SX Function G(z_mid..., z_box...) -> [f(z_mid)..., J(z_box), f(z_box)...].

        The Jacobian's expressions share the nodes of f(z_box), so their common
        subexpressions are evaluated once. G is built from f with its literal constants as
        symbols (:class:`~._derivative.ParamGraph`), which the compiler reads back as exact
        thin constants: CasADi cannot fold literals while differentiating, and only the
        constants its differentiation rules create are widened. A jump guard marks the
        outputs that may jump (or leave their domain) on a box: there the natural
        enclosure is used.
        """
        f = self.fun
        graph = _dv.ParamGraph(f)
        zb = graph.inputs
        zm = [ca.SX.sym(f"m{i}", f.sparsity_in(i)) for i in range(self.n_in)]
        fp = ca.Function(f"{f.name()}_p", zb + [graph.params], graph.outputs)
        outs_m = fp.call(zm + [graph.params])
        outs_b = graph.outputs
        z = ca.vertcat(*[ca.vec(s) for s in zb])
        y = ca.vertcat(*[ca.vec(o) for o in outs_b])
        jac = ca.jacobian(y, z)
        g = graph.function(f"{f.name()}_centered", zm + zb, list(outs_m) + [jac] + list(outs_b))
        self._g = g
        self._g_widen = _dv.rule_constants(g)
        self._g_eval, self._g_source = _compile(g, self._g_widen)  # type: ignore[arg-type]
        self._g_nnz = [g.nnz_out(i) for i in range(g.n_out())]
        self._g_scalar_fn: Callable[..., list[list[Any]]] | None = None
        self._guard_fn: Callable[..., list[list[Any]]] | None = None
        rows, cols = jac.sparsity().get_triplet()
        # row offsets of each output inside y, and nonzero rows of each output
        self._jac_rows = np.asarray(rows, dtype=np.intp)
        self._jac_cols = np.asarray(cols, dtype=np.intp)
        self._jac_rows_list = [int(r) for r in rows]
        self._jac_cols_list = [int(c) for c in cols]
        self._out_pos_list = [[int(p) for p in pos] for pos in self._out_pos]
        self._y_nz: list[list[int]] = []  # per output: the row of y of each of its nonzeros
        masks: list[int] = []
        off = 0
        for i in range(self.n_out):
            sp = f.sparsity_out(i)
            self._y_nz.append([off + int(k) for k in sp.find()])
            masks.extend(_dv.output_masks(graph, sp, i))
            off += sp.numel()
        self._guard = _dv.JumpGuard(graph, masks)

    def _centered(self, boxes: Sequence[np.ndarray], n: int) -> list[np.ndarray]:
        with np.errstate(all="ignore"):
            return self._centered_impl(boxes, n)

    def _centered_impl(self, boxes: Sequence[np.ndarray], n: int) -> list[np.ndarray]:
        native = self._centered_native() if self._native_ready() else None
        if native is not None and native[0] == "fused":
            return native[1](boxes, n)
        if native is not None and native[0] == "fused_guarded":
            outs = native[1](boxes, n)
            res, nat = outs[:self.n_out], outs[self.n_out:]
            jump = self._guard(boxes, n)  # the natural enclosure where a row may jump
            for i in range(self.n_out):
                for j, row in enumerate(self._y_nz[i]):
                    rows = jump[:, row]
                    if rows.any():
                        p = self._out_pos_list[i][j]
                        res[i][rows, p] = nat[i][rows, p]
            return res
        il: list[np.ndarray] = []
        ih: list[np.ndarray] = []
        mids: list[np.ndarray] = []
        rad: list[np.ndarray] = []  # one (N_i,) array per joint coordinate
        for b in boxes:
            lo = np.ascontiguousarray(b[..., 0].T)  # (d_i, N_i)
            hi = np.ascontiguousarray(b[..., 1].T)
            m = 0.5 * lo
            m += 0.5 * hi
            np.maximum(m, lo, out=m)  # the midpoint must lie in the box
            np.minimum(m, hi, out=m)
            r = np.maximum(m - lo, hi - m)
            rad.extend(arith._up_(r))
            il.append(lo)
            ih.append(hi)
            mids.append(m)
        o = self._g_native_eval(mids, il, ih, n) if native is not None else None
        if o is None:
            # the thin midpoint boxes [m, m] share one array for both bounds: the evaluator
            # never writes into its inputs
            o = [[None] * k for k in self._g_nnz]
            self._g_eval(mids + il, mids + ih, o)
        k = self.n_out
        fm, jac, fb = o[:k], o[k], o[k + 1:]
        # S_r >= sum_j mag(J_rj) * rad_j, so that J (Z - m) lies in [-S, S]. The terms are
        # non-negative: sum them in floating point and bound all roundings at once,
        # S = fl(sum fl(t_j)) * (1 + (k + 4) 2^-52) + (k + 1) 2^-1074 for k terms.
        sums: dict[int, Any] = {}
        counts: dict[int, int] = {}
        for t, (jl, jh) in enumerate(jac):
            r_j = rad[self._jac_cols[t]]
            term = np.maximum(-jl, jh)
            term = term * r_j
            if np.isnan(term).any():
                # a coordinate that does not vary contributes nothing (even where J is
                # unbounded); elsewhere a NaN slope means no information
                term = np.where(r_j == 0, 0.0, np.where(np.isnan(term), np.inf, term))
            r = int(self._jac_rows[t])
            if r in sums:
                sums[r] = sums[r] + term  # shapes may differ (broadcast inputs)
                counts[r] += 1
            else:
                sums[r] = term
                counts[r] = 1
        jump = self._guard(boxes, n) if self._guard.active else None  # (N, rows of y)
        res: list[list[Any]] = []
        for i in range(k):
            col = []
            for j, (ml, mh) in enumerate(fm[i]):
                bl, bh = fb[i][j]
                row = self._y_nz[i][j]
                if row not in sums:
                    col.append((bl, bh))
                    continue
                kk = counts[row]
                S = sums[row] * (1.0 + (kk + 4) * arith.U) + (kk + 1) * arith.TINY
                lo = arith._dn_(ml - S)
                hi = arith._up_(mh + S)
                lo, hi = np.maximum(lo, bl), np.minimum(hi, bh)
                if jump is not None and jump[:, row].any():
                    # the mean-value form is not valid where f may jump on the box
                    lo = np.where(jump[:, row], bl, lo)
                    hi = np.where(jump[:, row], bh, hi)
                col.append((lo, hi))
            res.append(col)
        return self._pack(res, n)

    def __call__(self, *args: Any) -> list[np.ndarray]:
        """Enclosures over the boxes ``args`` (one ``(N, d_i, 2)`` or ``(d_i, 2)`` array, or
        Box, per input); a list of ``(N, d_o, 2)`` arrays, one per output."""
        limit = self._scalar_limit()
        if limit:
            fast = self._fast
            if fast is None:
                fast = self._fast = self._make_fast()
            out = fast(args, limit)
            if out is not None:
                return out
        boxes, n = self._inputs(args)
        return self.evaluate_unchecked(boxes, n)

    def _call_small(self, args: Sequence[Any]) -> list[np.ndarray] | None:
        """The outputs for ``args`` when the scalar evaluator takes them (float64 arrays of
        valid boxes, a batch of at most the backend's limit), else None; for wrappers that
        validate their arguments themselves on the other path (see :meth:`_make_fast`)."""
        limit = self._scalar_limit()
        if not limit:
            return None
        fast = self._fast
        if fast is None:
            fast = self._fast = self._make_fast()
        return fast(args, limit)

    # ----------------------------------------------------------------- scalar
    def _natural_form(self) -> bool:
        return self.kind == "natural" or self.centered_fallback

    def _scalar_limit(self) -> int:
        """Largest batch evaluated by the scalar evaluator (0: never)."""
        b = self.backend
        if b == "auto" and self._scalar_capable:
            return self.scalar_max_batch if self._is_natural else self.scalar_max_batch_centered
        if b == "scalar" and self._scalar_capable:
            return sys.maxsize
        return 0

    def _make_fast(self) -> Callable[..., list[np.ndarray] | None]:
        """The checked scalar call for small batches, generated for the input sizes.

        ``fast(args, limit)`` evaluates float64 arrays of valid boxes (``(N, d_i, 2)`` or
        ``(d_i, 2)``, batch sizes in {1, N}, ``1 <= N <= limit``) with the scalar evaluator
        and returns the outputs; anything else (other types, shapes or dtypes, NaN or empty
        boxes, larger batches) returns None, and the checked path then evaluates it or raises
        the errors of :func:`~casadi_cmpc._validate.as_boxes`.
        """
        ev = self._scalar() if self._natural_form() else self._centered_scalar
        k = self.n_in
        a = [f"a{i}" for i in range(k)]
        # the floating-point environment check of _fpu inline, its operands as local
        # defaults (about 0.1 us)
        lines = [f"def _fast(args, limit, {_fpu.CHECK_PARAMS}):"]
        if k == 0:
            lines.append("    return None")
        else:
            lines += [f"    if len(args) != {k}: return None",
                      f"    {', '.join(a)}, = args",
                      "    if " + " or ".join(f"type({x}) is not ndarray" for x in a)
                      + ": return None",
                      "    if " + " or ".join(f"{x}.dtype is not F64" for x in a) + ": return None",
                      "    n = 1"]
            for i, d in enumerate(self.size_in):
                lines += [f"    s = a{i}.shape",
                          f"    if len(s) == 3 and s[1] == {d} and s[2] == 2:",
                          f"        k{i} = s[0]",
                          f"        if k{i} != 1 and k{i} != n:",
                          "            if n != 1: return None",
                          f"            n = k{i}",
                          f"    elif s == ({d}, 2): k{i} = 0",
                          "    else: return None"]
            lines.append("    if n > limit or n == 0: return None")
            # not in the default floating-point environment: the checked path switches
            lines.append(f"    if {_fpu.NOT_DEFAULT}: return None")
            for i, d in enumerate(self.size_in):
                if d == 0:
                    lines.append(f"    L{i} = [[]] * n")
                    continue
                lines.append(f"    L{i} = a{i}.tolist() if k{i} else [a{i}.tolist()]")
                if d <= 8:  # unpack the pairs of each box at once
                    pairs = ", ".join(f"(p{j}, q{j})" for j in range(d))
                    test = " and ".join(f"p{j} <= q{j}" for j in range(d))
                    lines += [f"    for {pairs}{',' if d == 1 else ''} in L{i}:",
                              f"        if not ({test}): return None"]
                else:
                    lines += [f"    for b in L{i}:",
                              "        for lo, hi in b:",
                              "            if not lo <= hi: return None"]
                lines.append(f"    if len(L{i}) != n: L{i} = L{i} * n")
            args = f"[{', '.join(f'L{i}' for i in range(k))}]"
            if self._natural_form():
                lines += ["    try:",
                          f"        R = ev({args}, n)",
                          "    except (ArithmeticError, ValueError):",
                          "        return None"]
                outs = [f"fromiter(R[{j}], F64, {2 * d} * n).reshape(n, {d}, 2)"
                        for j, d in enumerate(self.size_out)]
                lines.append(f"    return [{', '.join(outs)}]")
            else:
                lines.append(f"    return ev({args}, n)")
        ns: dict[str, Any] = {"ndarray": np.ndarray, "F64": _F64, "ev": ev,
                              "fromiter": np.fromiter}
        exec(compile("\n".join(lines) + "\n", f"<interval-call:{self.fun.name()}>", "exec"),
             ns)  # noqa: S102
        return ns["_fast"]

    def _scalar(self) -> Callable[..., list[list[Any]]]:
        if self._scalar_fn is None:
            self._scalar_fn, self.scalar_source = _compile_scalar(
                self.fun, self._cwiden, self._keep, self._out_pos, self.size_out)
        return self._scalar_fn

    def _run_scalar(self, lists: list[list[Any]], n: int,
                    boxes: Sequence[np.ndarray] | None = None) -> list[np.ndarray]:
        """Evaluate boxes given as nested lists (``ndarray.tolist()`` of ``(N_i, d_i, 2)``,
        N_i in {1, n}) with the scalar evaluator; numpy if Python raises."""
        if not _fpu.is_default():  # the rules hold in the default environment
            return _fpu.call_in_default(self._run_scalar, lists, n, boxes)
        args = [b if len(b) == n else b * n for b in lists]
        out: list[np.ndarray] | None = None
        try:
            if self._natural_form():
                res = self._scalar()(args, n)
                out = [np.fromiter(r, _F64, 2 * d * n).reshape(n, d, 2)
                       for r, d in zip(res, self.size_out, strict=True)]
            else:
                out = self._centered_scalar(args, n)
        except (ArithmeticError, ValueError):
            if self._scalar_strict:
                raise
        if out is None:
            if self._scalar_strict:
                raise ArithmeticError("the scalar evaluation raised")
            if boxes is None:
                boxes = [np.array(b, dtype=float).reshape(len(b), d, 2)
                         for b, d in zip(lists, self.size_in, strict=True)]
            return self._numpy(boxes, n)
        return out

    def _g_scalar(self) -> Callable[..., list[list[Any]]]:
        """Scalar evaluator of the centered graph G: per output, its nonzeros (unsanitised:
        NaN stays NaN, as the numpy evaluator gives them)."""
        if self._g_scalar_fn is None:
            pos = [np.arange(k) for k in self._g_nnz]
            self._g_scalar_fn = _compile_scalar(self._g, self._g_widen, None, pos,
                                                self._g_nnz, sanitize=False)[0]
        return self._g_scalar_fn

    def _guard_scalar(self, lists: list[list[Any]], n: int) -> list[list[bool]]:
        """The jump guard of the centered form (:class:`~._derivative.JumpGuard`), its guard
        expressions enclosed by a scalar evaluator: per box, per row of y, may it jump."""
        gd = self._guard
        if self._guard_fn is None:
            g = gd.graph.function(f"{gd.graph.name}_guards", gd.graph.inputs,
                                  [gd.graph.guard_exprs])
            self._guard_fn = _compile_scalar(g, _dv.rule_constants(g), None,
                                             [np.arange(gd._nnz)], [gd._nnz],
                                             sanitize=False)[0]
        res = np.fromiter(self._guard_fn([b if len(b) == n else b * n for b in lists], n)[0],
                          _F64, 2 * gd._nnz * n).reshape(n, gd._nnz, 2)
        lo = [np.zeros(n)] * gd._q
        hi = [np.zeros(n)] * gd._q
        for j, p in enumerate(gd._pos):
            lo[int(p)] = res[:, j, 0]
            hi[int(p)] = res[:, j, 1]
        with np.errstate(all="ignore"):
            flags = _dv.guard_flags(gd.graph, lo, hi, n)
        return _dv.rows_reaching_jumps(gd.masks, flags).tolist()

    def _centered_scalar(self, lists: list[list[Any]], n: int) -> list[np.ndarray] | None:
        """The centered form of :meth:`_centered_impl` on Python floats, box by box, for
        boxes as nested lists (each input a list of ``n`` boxes). Every step is that of the
        numpy version, with its NaN propagation (``np.maximum`` / ``np.minimum`` keep NaN).
        None when Python raises (the caller then uses numpy)."""
        ev = self._g_scalar()
        jump = self._guard_scalar(lists, n) if self._guard.active else None
        u, tiny, big, nan, inf = arith.U, arith.TINY, arith.MAX_FLOAT, math.nan, math.inf
        mids: list[list[Any]] = []
        rads: list[list[float]] = [[] for _ in range(n)]
        for box_list in lists:
            if len(box_list) != n:
                box_list = box_list * n
            mid_list = []
            for rb, box in zip(rads, box_list, strict=True):
                row = []
                for lo, hi in box:
                    m = 0.5 * lo + 0.5 * hi
                    if m < lo:  # the midpoint must lie in the box (NaN stays NaN)
                        m = lo
                    if m > hi:
                        m = hi
                    a = m - lo
                    c = hi - m
                    r = nan if (a != a or c != c) else (a if a > c else c)
                    if r < -big:
                        r = -big
                    rb.append(r + r * u if r > 0.0 else r - r * u)
                    row.append([m, m])
                mid_list.append(row)
            mids.append(mid_list)
        try:
            res = ev(mids + [b if len(b) == n else b * n for b in lists], n)
        except (ArithmeticError, ValueError):
            return None
        k = self.n_out
        jac = res[k]
        n_jac = len(self._jac_rows)
        rows = self._jac_rows_list
        cols = self._jac_cols_list
        outs: list[list[float]] = [[] for _ in range(k)]
        for b in range(n):
            rb = rads[b]
            base = 2 * n_jac * b
            sums: dict[int, float] = {}
            counts: dict[int, int] = {}
            for t in range(n_jac):
                jl = jac[base + 2 * t]
                jh = jac[base + 2 * t + 1]
                mag = nan if (jl != jl or jh != jh) else (-jl if -jl > jh else jh)
                rj = rb[cols[t]]
                term = mag * rj
                if term != term:
                    # a coordinate that does not vary contributes nothing (even where J is
                    # unbounded); elsewhere a NaN slope means no information
                    term = 0.0 if rj == 0 else inf
                r = rows[t]
                if r in sums:
                    sums[r] = sums[r] + term
                    counts[r] += 1
                else:
                    sums[r] = term
                    counts[r] = 1
            for i in range(k):
                fm, fb = res[i], res[k + 1 + i]
                y_nz = self._y_nz[i]
                pos = self._out_pos_list[i]
                nz = len(y_nz)
                base = 2 * nz * b
                dense = [0.0] * (2 * self.size_out[i])
                for j in range(nz):
                    bl = fb[base + 2 * j]
                    bh = fb[base + 2 * j + 1]
                    row = y_nz[j]
                    if row in sums:
                        kk = counts[row]
                        S = sums[row] * (1.0 + (kk + 4) * u) + (kk + 1) * tiny
                        lo = fm[base + 2 * j] - S
                        if lo > big:
                            lo = big
                        lo = lo - lo * u if lo > 0.0 else lo + lo * u
                        hi = fm[base + 2 * j + 1] + S
                        if hi < -big:
                            hi = -big
                        hi = hi + hi * u if hi > 0.0 else hi - hi * u
                        if lo != lo or bl != bl:
                            lo = nan
                        elif bl > lo:
                            lo = bl
                        if hi != hi or bh != bh:
                            hi = nan
                        elif bh < hi:
                            hi = bh
                    else:
                        lo, hi = bl, bh
                    if jump is not None and jump[b][row]:
                        # the mean-value form is not valid where f may jump on the box
                        lo, hi = bl, bh
                    if not lo <= hi:  # as _sanitize
                        lo, hi = -inf, inf
                    p = pos[j]
                    dense[2 * p] = lo
                    dense[2 * p + 1] = hi
                outs[i] += dense
        return [np.fromiter(o, _F64, 2 * d * n).reshape(n, d, 2)
                for o, d in zip(outs, self.size_out, strict=True)]

    def evaluate_unchecked(self, boxes: Sequence[np.ndarray], n: int) -> list[np.ndarray]:
        """Evaluate on already validated ``(N_i, d_i, 2)`` float arrays (N_i in {1, n}).

        For solvers that build their own box batches; no shape or NaN checks are made. The
        backend is chosen as for a call (see the class Notes). An input may also be a
        :class:`~._native.Rows` (rows of bound arrays): the native kernels read it in place,
        the other evaluators after gathering it.
        """
        small = 0 < n <= self._scalar_limit()
        if small:
            # to the native kernel: a large function after native_after batches (counted
            # here too); another once it has moved there and the work is worth the kernel's
            # call (about 8 µs; the scalar evaluator: about 0.1 µs per box and instruction)
            work = n * self._n_instr
            if self._large:
                go = self._wants_native(n)
            elif work < self.native_small_work:
                go = False
            elif self._native_ready():
                go = True
            else:
                # small batches of a smaller function count toward the move by their work:
                # one batch per native_small_quantum box instructions (the scalar code
                # spends 0.1-0.5 µs on each), so that the move comes once the scalar
                # evaluations have cost about what the kernel's compilation does (0.1-1 s)
                self._small_work += work
                go = False
                if self._small_work >= self.native_small_quantum:
                    self._small_work -= self.native_small_quantum
                    go = self._wants_native(n)
        else:
            go = bool(n) and self._wants_native(n)
        if go:
            if not self._is_natural:
                native = self._centered_native()
                if native is not None and native[0] == "fused":
                    return native[1](boxes, n)  # the whole centered form in one C loop
                return self._numpy(_as_arrays(boxes), n)
            run = self._native_kernel()
            if run is not None:
                return run(boxes, n)
        boxes = _as_arrays(boxes)
        if small:
            return self._run_scalar([b.tolist() for b in boxes], n, boxes)
        return self._numpy(boxes, n)

    def _wants_native(self, n: int) -> bool:
        """Whether a batch of ``n`` boxes goes to the native kernel: always with
        ``backend="native"``; with ``"auto"`` once this function has evaluated
        :attr:`native_after` batches with numpy (a search or a controller that calls it
        again and again: the compilation, about 0.1 s, or its load from the disk cache,
        about 10 ms, then pays for itself). Deterministic: the choice depends on the calls
        made, not on timings."""
        if self.backend == "native":
            return True
        if self.backend != "auto" or self._native is False:
            return False
        self._native_batches += 1
        if self._native_batches == self.native_prefetch and self._native is None:
            self._prefetch_native()
        return self._native_batches > self.native_after

    def _prefetch_native(self) -> None:
        """Start compiling this function's native kernel in the background (when it is not
        in the disk cache), so that the switch after :attr:`native_after` batches, which
        waits for it, rarely waits long. The switch itself stays at that batch: the
        results do not depend on how long a compilation took."""
        try:
            if self._natural_form():
                self._native_kernel(wait=False)
            else:
                self._centered_native(wait=False)
        except Exception:  # noqa: BLE001 - the switch compiles again and reports errors
            self._native = None

    def _centered_native(self, wait: bool = True) -> tuple[str, Any] | None:
        """The native centered form: ``("fused", run)``, one C loop doing all of
        :meth:`_centered_impl`; ``("fused_guarded", run)``, the same with the natural
        enclosures as extra outputs, used where the jump guard (evaluated as before) fires;
        or ``("g", (run, pos))``, the graph G alone; None: numpy."""
        if self._native is None:
            from ._native import PENDING, centered_source, load_kernel, native_kernel

            g = self._g
            guarded = self._guard.active
            src = centered_source(g, self._g_widen, self.size_in, self._out_pos,
                                  self.size_out, self._jac_rows_list, self._jac_cols_list,
                                  self._y_nz, with_natural=guarded)
            sizes = list(self.size_out) * (2 if guarded else 1)
            run = load_kernel(src, self.size_in, sizes, wait=wait) if src else None
            if run is PENDING:
                return None
            if run is not None:
                self._native = ("fused_guarded" if guarded else "fused", run)
            else:
                pos = [np.asarray(g.sparsity_out(i).find(), dtype=np.intp)
                       for i in range(g.n_out())]
                k = native_kernel(g, self._g_widen, pos,
                                  [g.numel_out(i) for i in range(g.n_out())], wait=wait)
                if k is PENDING:
                    return None
                self._native = ("g", (k, pos)) if k is not None else False
        return self._native or None

    def _native_ready(self) -> bool:
        """The native kernel is (to be) used: forced, or past the auto threshold."""
        if self.backend == "native":
            return True
        return (self.backend == "auto" and self._native is not False
                and self._native_batches > self.native_after)

    def _g_native_eval(self, mids: list[np.ndarray], il: list[np.ndarray],
                       ih: list[np.ndarray], n: int) -> list[list[Any]] | None:
        """The centered graph G(mids, boxes) by the native kernel, in the layout of the
        numpy evaluator (per output, a (lo, hi) pair of (N,) arrays per nonzero); None when
        no kernel is available. A possibly undefined value comes out as [-inf, inf] instead
        of NaN, which the mean-value combination treats alike (no information)."""
        native = self._centered_native()
        if native is None or native[0] != "g":
            return None
        run, pos = native[1]
        ins = [np.stack([m.T, m.T], axis=-1) for m in mids]
        ins += [np.stack([lo.T, hi.T], axis=-1) for lo, hi in zip(il, ih, strict=True)]
        outs = run(ins, n)
        return [[(a[:, p, 0], a[:, p, 1]) for p in ps] for a, ps in zip(outs, pos, strict=True)]

    def _native_kernel(self, wait: bool = True
                       ) -> Callable[[Sequence[np.ndarray], int], list[np.ndarray]] | None:
        """The natural form's kernel; ``wait=False``: start its compilation in the
        background and answer None until it is built."""
        if self._native is None:
            from ._native import PENDING, native_kernel

            k = native_kernel(self.fun, self._cwiden, self._out_pos, self.size_out,
                              self._keep, wait=wait)
            if k is PENDING:
                return None
            self._native = k if k is not None else False
        return self._native or None

    def _numpy(self, boxes: Sequence[np.ndarray], n: int) -> list[np.ndarray]:
        """Evaluate with the numpy evaluators (in chunks for large batches)."""
        if not _fpu.is_default():  # the rules hold in the default environment
            return _fpu.call_in_default(self._numpy, boxes, n)
        run = self._natural if self._natural_form() else self._centered
        step = int(self.chunk if run == self._natural else self.chunk_centered)
        if n <= step:
            return run(boxes, n)
        if run != self._natural and self._native_ready():
            native = self._centered_native()
            if native is not None and native[0] in ("fused", "fused_guarded"):
                return run(boxes, n)  # one C loop, in cache-sized blocks of its own
        # Evaluate in chunks: the temporaries of a chunk stay in cache, which is several
        # times faster than whole-batch numpy operations on large arrays.
        outs = [np.empty((n, d, 2)) for d in self.size_out]
        for i in range(0, n, step):
            j = min(i + step, n)
            part = [b if b.shape[0] == 1 else b[i:j] for b in boxes]
            for o, r in zip(outs, run(part, j - i), strict=True):
                o[i:j] = r
        return outs

    def __repr__(self) -> str:
        return (f"InclusionFunction('{self.fun.name()}', kind='{self.kind}', "
                f"inputs={self.size_in}, outputs={self.size_out}, backend='{self.backend}')")


_F64 = np.dtype(np.float64)
_BACKENDS = ("auto", "numpy", "scalar", "native")


def _check_backend(backend: Any) -> str:
    b = str(backend).lower()
    if b not in _BACKENDS:
        raise ValueError(f"unknown backend '{backend}'; valid backends: {', '.join(_BACKENDS)}")
    return b


# CasADi operations with a scalar (Python float) evaluation
_SCALAR_OPS = frozenset([ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT]) | frozenset(
    op for op, name in {**_UNARY, **_BINARY}.items() if name in _S.EMITTERS)


def _scalar_unsupported(fun: ca.Function) -> list[str]:
    """Names of the operations of ``fun`` that the scalar evaluator lacks."""
    ops = {fun.instruction_id(k) for k in range(fun.n_instructions())}
    return sorted(_op_name(op) for op in ops - _SCALAR_OPS)


def _sanitize(out: np.ndarray) -> None:
    """Replace results with a NaN in either bound ("possibly undefined, no information") by
    the whole line ``[-inf, inf]`` (both bounds), in place; also ``lo > hi``, which no sound
    enclosure gives. (A constant infinite output, e.g. ``casadi.inf``, stays ``[inf, inf]``.)"""
    bad = ~(out[..., 0] <= out[..., 1])  # True where either bound is NaN
    if bad.any():
        out[bad] = (-np.inf, np.inf)


# Relative widening of constants that CasADi may have folded while differentiating (it folds
# constant subexpressions such as 3 * 0.1 or 0.1 - 1 in floating point): covers a few
# thousand roundings; the absolute part covers underflow (1e-200 * 1e-200 folds to 0).
DERIVED_CONST_REL = 2.0 ** -40


def _widen_constant(v: float) -> tuple[float, float]:
    """Interval around a constant that may be the rounded result of folding."""
    m = abs(v) * DERIVED_CONST_REL + arith.ABS_LIBM
    return v - m, v + m


def _derived_constants(g: ca.Function, exact_outputs: Sequence[int]) -> frozenset[int]:
    """Instructions of ``g`` (built with live_variables=False) that load a constant used by a
    derived output (an output not in ``exact_outputs``).

    All of them are widened, also those shared with ``exact_outputs``: CasADi caches numeric
    constants, so a value folded while differentiating (``3 * 0.1`` gives
    ``0.30000000000000004``) may be the very node of a literal of f, and no exact value (not
    even 0 or 1: ``10 * 0.1`` folds to 1.0) proves that it was not folded. Exact outputs that
    share such a constant see it widened too (sound, slightly loose); derivative paths that
    need f exact build their graph with :class:`~._derivative.ParamGraph` instead.
    """
    needed: set[int] = set()
    n = g.n_instructions()
    ids = [g.instruction_id(k) for k in range(n)]
    exact = set(exact_outputs)
    for k in range(n - 1, -1, -1):
        op = ids[k]
        if op == ca.OP_OUTPUT:
            if g.instruction_output(k)[0] not in exact:
                needed.add(g.instruction_input(k)[0])
            continue
        outs = g.instruction_output(k)
        if op in (ca.OP_CONST, ca.OP_INPUT):
            continue
        if outs and outs[0] in needed:
            needed.update(g.instruction_input(k))
    return frozenset(k for k in range(n) if ids[k] == ca.OP_CONST
                     and g.instruction_output(k)[0] in needed)


class _Restricted:
    def __init__(self, fun: ca.Function, keep: tuple[int, ...] | None) -> None:
        self.fun = fun
        self.keep = keep


def _restrict(fun: ca.Function, derived: Sequence[int],
              evaluate: Sequence[int] | None) -> _Restricted:
    """Rebuild ``fun`` with one work slot per node (needed to trace constants to outputs)."""
    syms = fun.sx_in()
    g = ca.Function(fun.name(), syms, fun.call(syms), fun.name_in(), fun.name_out(),
                    {"live_variables": False})
    keep = None if evaluate is None else tuple(int(i) for i in evaluate)
    for i in list(derived) + list(keep or ()):
        if not 0 <= int(i) < g.n_out():
            raise ValueError(f"output index {i} out of range for '{fun.name()}'")
    return _Restricted(g, keep)


def _needed_instructions(g: ca.Function, outputs: Sequence[int],
                         nonzeros: set[int] | None = None) -> set[int]:
    """Instructions of ``g`` (one slot per node) that the given outputs depend on (only their
    nonzeros in ``nonzeros`` when given)."""
    needed_slots: set[int] = set()
    keep: set[int] = set()
    outs = set(outputs)
    for k in range(g.n_instructions() - 1, -1, -1):
        op = g.instruction_id(k)
        if op == ca.OP_OUTPUT:
            o = g.instruction_output(k)
            if o[0] in outs and (nonzeros is None or o[1] in nonzeros):
                keep.add(k)
                needed_slots.add(g.instruction_input(k)[0])
            continue
        o = g.instruction_output(k)
        if o and o[0] in needed_slots:
            keep.add(k)
            if op not in (ca.OP_CONST, ca.OP_INPUT):
                needed_slots.update(g.instruction_input(k))
    return keep


def _compile(fun: ca.Function, widen: frozenset[int] = frozenset(),
             keep_outputs: Sequence[int] | None = None, nonzeros: set[int] | None = None
             ) -> tuple[Callable[..., None], str]:
    gen = _Codegen(fun, widen)
    if keep_outputs is not None:
        gen.only = _needed_instructions(fun, keep_outputs, nonzeros)
        gen.out_map = {int(o): i for i, o in enumerate(keep_outputs)}
    src = gen.build()
    namespace: dict[str, Any] = {"_A": arith, "_K": gen.const_table, "np": np}
    exec(compile(src, f"<interval:{fun.name()}>", "exec"), namespace)  # noqa: S102
    return namespace["_eval"], src


def _compile_scalar(fun: ca.Function, widen: frozenset[int], keep_outputs: Sequence[int] | None,
                    out_pos: Sequence[np.ndarray], size_out: Sequence[int],
                    sanitize: bool = True) -> tuple[Callable[..., list[list[Any]]], str]:
    """The scalar evaluator ``_eval_s(B, n)`` of :class:`_ScalarCodegen` and its source."""
    gen = _ScalarCodegen(fun, widen, out_pos, size_out, sanitize)
    if keep_outputs is not None:
        gen.only = _needed_instructions(fun, keep_outputs)
        gen.out_map = {int(o): i for i, o in enumerate(keep_outputs)}
    src = gen.build()
    namespace: dict[str, Any] = dict(_S.ready())
    exec(compile(src, f"<interval-scalar:{fun.name()}>", "exec"), namespace)  # noqa: S102
    return namespace["_eval_s"], src


class _InclusionCache:
    """Bounded least-recently-used cache of the inclusion functions of :func:`inclusion`.

    Keyed by ``(id(fun), kind, backend)``; each entry keeps the Function object itself and
    is returned only when the stored Function *is* the one asked for. Holding the Function
    keeps it alive while its entry exists, so its ``id`` cannot be reused by another object
    meanwhile; an evicted entry is simply compiled again. A CasADi Function is immutable, so
    an entry never goes stale.
    """

    def __init__(self, maxsize: int = 256) -> None:
        self.maxsize = maxsize
        self._data: OrderedDict[tuple[int, str, str], tuple[ca.Function, InclusionFunction]] \
            = OrderedDict()
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def get(self, fun: Any, kind: str, backend: str) -> InclusionFunction | None:
        key = (id(fun), kind, backend)
        with self._lock:
            entry = self._data.get(key)
            if entry is None or entry[0] is not fun:
                self.misses += 1
                return None
            self._data.move_to_end(key)
            self.hits += 1
            return entry[1]

    def put(self, fun: Any, kind: str, backend: str, F: InclusionFunction) -> None:
        with self._lock:
            self._data[(id(fun), kind, backend)] = (fun, F)
            self._data.move_to_end((id(fun), kind, backend))
            while len(self._data) > self.maxsize:
                self._data.popitem(last=False)

    def clear(self) -> None:
        with self._lock:
            self._data.clear()
            self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._data)


_CACHE = _InclusionCache()


def _as_arrays(boxes: Sequence[Any]) -> Sequence[np.ndarray]:
    """Kernel inputs as ``(N_i, d_i, 2)`` arrays (rows of bound arrays gathered; nothing
    to look for before the first :class:`~._native.Rows` of the process)."""
    if _Rows.in_use and any(type(b) is _Rows for b in boxes):
        return _native_as_arrays(boxes)
    return boxes


def inclusion(fun: ca.Function | _dv.ParamFunction, kind: str = "natural", *,
              backend: str = "auto") -> InclusionFunction:
    """Compile a CasADi Function into a batched interval inclusion function (cached).

    Parameters
    ----------
    fun : casadi.Function or ParamFunction
        An SX Function (an MX Function is expanded to SX when possible). Inputs must be dense.
        A :class:`~._derivative.ParamFunction` (e.g. :attr:`casadi_cmpc.Model.interval_function`
        of a closed loop) reads its parameters as exact constants.
    kind : {"natural", "centered"}
        ``"natural"``: every operation replaced by its interval extension.
        ``"centered"``: the mean-value form ``f(m) + J(Z)(Z - m)`` over the joint box ``Z`` of
        all inputs (``m`` its midpoint, ``J`` the interval Jacobian of CasADi's symbolic
        Jacobian), intersected with the natural enclosure. Its overestimation shrinks
        quadratically with the box width.
    backend : {"auto", "numpy", "scalar"}
        Evaluator of the boxes: ``"auto"`` evaluates batches of at most
        :attr:`InclusionFunction.scalar_max_batch` (32; 16 for the centered form) boxes with
        straight-line Python float code and larger ones with numpy; ``"numpy"`` /
        ``"scalar"`` force one. Same enclosures either way (see :class:`InclusionFunction`).

    Returns
    -------
    InclusionFunction
        Callable taking one ``(N, d_i, 2)`` array per input and returning a list with one
        ``(N, d_o, 2)`` array per output.

    Notes
    -----
    Compiling costs 0.1-2.4 ms, so the result is cached: the same Function object with the
    same ``kind`` and ``backend`` gives the same :class:`InclusionFunction` object (shared:
    attributes set on it, e.g. ``chunk``, are seen by every caller). The cache holds the 256
    most recently used and keeps their Functions alive; :func:`inclusion_cache_clear`
    empties it. Build an :class:`InclusionFunction` directly for a private, uncached one.

    Examples
    --------
    >>> import casadi as ca, numpy as np
    >>> import casadi_cmpc as cm
    >>> x = ca.SX.sym("x")
    >>> f = ca.Function("f", [x], [x * (1 - x)])
    >>> F = cm.interval.inclusion(f)
    >>> lo, hi = F(np.array([[[0.0, 1.0]]]))[0][0, 0]
    >>> bool(lo <= 0.0 and hi >= 1.0)
    True
    >>> cm.interval.inclusion(f) is F
    True
    """
    kind = str(kind).lower()
    backend = _check_backend(backend)
    F = _CACHE.get(fun, kind, backend)
    if F is None:
        F = InclusionFunction(fun, kind, backend=backend)
        _CACHE.put(fun, kind, backend, F)
    elif F.centered_fallback:
        warnings.warn(
            f"'{F.fun.name()}' contains operations through which it may jump "
            f"({', '.join(_discontinuous_ops(F.fun))}); the centered (mean-value) form is not "
            "valid for it, so its natural inclusion is used instead", CmpcWarning,
            stacklevel=2)
    return F


def inclusion_cache_clear() -> None:
    """Empty the cache of :func:`inclusion` (and release the Functions it keeps alive)."""
    _CACHE.clear()
