"""Compile a CasADi SX ``Function`` into a batched interval inclusion function.

The compiler walks the Function's instruction list once (``n_instructions``,
``instruction_id/input/output/constant``) and generates straight-line Python/numpy source in
which every CasADi operation is replaced by its interval extension from
:mod:`casadi_cmpc.interval.arith`. Constants are folded at compile time (soundly: folded with
the interval operations themselves) and operations with a thin constant operand are
specialised (e.g. ``x * c`` costs two multiplications instead of four).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import casadi as ca
import numpy as np

from .._validate import as_boxes
from ..exceptions import DimensionError, UnsupportedOperationError
from . import arith

__all__ = ["inclusion", "InclusionFunction"]

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


def _op_name(op: int) -> str:
    for name in dir(ca):
        if name.startswith("OP_") and getattr(ca, name) == op:
            return name
    return f"op {op}"


def _as_sx_function(fun: Any) -> ca.Function:
    if not isinstance(fun, ca.Function):
        raise TypeError(f"expected a casadi.Function, got {type(fun).__name__}")
    if not fun.is_a("SXFunction"):
        try:
            fun = fun.expand()
        except Exception as exc:  # pragma: no cover - depends on CasADi internals
            raise UnsupportedOperationError(
                f"Function '{fun.name()}' is not an SX Function and cannot be expanded to one "
                f"({exc}); build it from casadi.SX symbols") from exc
    for i in range(fun.n_in()):
        if not fun.sparsity_in(i).is_dense():
            raise DimensionError(
                f"input {i} ('{fun.name_in(i)}') of '{fun.name()}' is sparse; "
                "interval inclusion functions need dense inputs")
    return fun


class _Codegen:
    """Generate the straight-line numpy source for one SX Function."""

    def __init__(self, fun: ca.Function) -> None:
        self.fun = fun
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

    def _emit(self, out: int, expr: str) -> None:
        self.consts.pop(out, None)
        self.lines.append(f"    l{out}, h{out} = {expr}")

    def _fold(self, name: str, out: int, ins: Sequence[int]) -> None:
        fn = getattr(arith, name)
        args = []
        for s in ins:
            args.extend(np.array([v]) for v in self.consts[s])
        lo, hi = fn(*args)
        lo = float(np.asarray(lo).reshape(-1)[0])
        hi = float(np.asarray(hi).reshape(-1)[0])
        if np.isnan(lo):
            lo = -np.inf
        if np.isnan(hi):
            hi = np.inf
        self.consts[out] = (lo, hi)

    def _exact_const(self, out: int, ins: Sequence[int], op: int) -> bool:
        """Fold exactly-representable constant results (neg, twice, assign) without widening."""
        if op in (ca.OP_NEG, ca.OP_ASSIGN, ca.OP_TWICE):
            lo, hi = self.consts[ins[0]]
            if op == ca.OP_NEG:
                lo, hi = -hi, -lo
            elif op == ca.OP_TWICE:
                lo, hi = 2.0 * lo, 2.0 * hi
            self.consts[out] = (lo, hi)
            return True
        return False

    def build(self) -> str:
        f = self.fun
        for k in range(f.n_instructions()):
            op = f.instruction_id(k)
            ins = list(f.instruction_input(k))
            outs = list(f.instruction_output(k))
            if op == ca.OP_CONST:
                v = float(f.instruction_constant(k))
                self.consts[outs[0]] = (v, v)
            elif op == ca.OP_INPUT:
                self.consts.pop(outs[0], None)
                self.lines.append(
                    f"    l{outs[0]} = IL[{ins[0]}][{ins[1]}]; h{outs[0]} = IH[{ins[0]}][{ins[1]}]")
            elif op == ca.OP_OUTPUT:
                lo, hi = self._operand(ins[0])
                self.lines.append(f"    O[{outs[0]}][{outs[1]}] = ({lo}, {hi})")
            elif op in _UNARY:
                name = _UNARY[op]
                if ins[0] in self.consts:
                    if not self._exact_const(outs[0], ins, op):
                        self._fold(name, outs[0], ins[:1])
                    continue
                a = self._operand(ins[0])
                self._emit(outs[0], f"_A.{name}({a[0]}, {a[1]})")
            elif op in _BINARY:
                name = _BINARY[op]
                i0, i1 = ins[0], ins[1]
                if i0 in self.consts and i1 in self.consts:
                    self._fold(name, outs[0], (i0, i1))
                    continue
                c0, c1 = self._thin(i0), self._thin(i1)
                a, b = self._operand(i0), self._operand(i1)
                expr = None
                if op == ca.OP_ADD:
                    if c1 is not None:
                        expr = f"_A.addc({a[0]}, {a[1]}, {self._lit(c1)})"
                    elif c0 is not None:
                        expr = f"_A.addc({b[0]}, {b[1]}, {self._lit(c0)})"
                elif op == ca.OP_SUB:
                    if c1 is not None:
                        expr = f"_A.addc({a[0]}, {a[1]}, {self._lit(-c1)})"
                    elif c0 is not None:
                        expr = f"_A.csub({self._lit(c0)}, {b[0]}, {b[1]})"
                elif op == ca.OP_MUL:
                    if c1 is not None:
                        expr = f"_A.mulc({a[0]}, {a[1]}, {self._lit(c1)})"
                    elif c0 is not None:
                        expr = f"_A.mulc({b[0]}, {b[1]}, {self._lit(c0)})"
                elif op == ca.OP_DIV:
                    if c1 is not None:
                        expr = f"_A.divc({a[0]}, {a[1]}, {self._lit(c1)})"
                    elif c0 is not None:
                        expr = f"_A.cdiv({self._lit(c0)}, {b[0]}, {b[1]})"
                elif op in (ca.OP_POW, ca.OP_CONSTPOW) and c1 is not None:
                    expr = f"_A.powc({a[0]}, {a[1]}, {self._lit(c1)})"
                if expr is None:
                    expr = f"_A.{name}({a[0]}, {a[1]}, {b[0]}, {b[1]})"
                self._emit(outs[0], expr)
            else:
                raise UnsupportedOperationError(
                    f"CasADi operation {_op_name(op)} (instruction {k} of '{f.name()}') has no "
                    "interval extension; rewrite the model with elementary operations")
        src = ["def _eval(IL, IH, O):"] + (self.lines or ["    pass"])
        return "\n".join(src) + "\n"


class InclusionFunction:
    """A batched interval inclusion function compiled from a CasADi SX Function.

    Call it with one box array per input of the Function: ``(N, d_i, 2)`` (or one ``(d_i, 2)``
    box, or a :class:`~casadi_cmpc.Box`). Inputs with ``N = 1`` broadcast against the others.
    Returns a list with one ``(N, d_o, 2)`` array per output, where ``d_i``/``d_o`` are the
    numbers of elements of the (dense, column-major flattened) inputs/outputs.

    Guarantee: for every point inside the input boxes, the exact real value of each output
    lies inside the returned bounds (floating-point rounding included). Where the Function is
    undefined on part of a box (e.g. ``log`` of a box reaching 0), the result is
    ``[-inf, inf]``. Outputs never contain NaN.

    Attributes
    ----------
    fun : casadi.Function
        The SX Function (expanded if an MX Function was given).
    kind : str
        ``"natural"`` or ``"centered"``.
    source : str
        The generated numpy source (natural evaluator), for inspection.
    """

    def __init__(self, fun: ca.Function, kind: str = "natural") -> None:
        kind = str(kind).lower()
        if kind not in _KINDS:
            raise ValueError(f"unknown inclusion kind '{kind}'; valid kinds: {', '.join(_KINDS)}")
        fun = _as_sx_function(fun)
        self.fun = fun
        self.kind = kind
        self.n_in = fun.n_in()
        self.n_out = fun.n_out()
        self.size_in = [fun.numel_in(i) for i in range(self.n_in)]
        self.size_out = [fun.numel_out(i) for i in range(self.n_out)]
        self._out_pos = [np.asarray(fun.sparsity_out(i).find(), dtype=np.intp)
                         for i in range(self.n_out)]
        self._eval, self.source = _compile(fun)
        self._jac: InclusionFunction | None = None
        if kind == "centered":
            self._build_centered()

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

    def _natural(self, boxes: Sequence[np.ndarray], n: int) -> list[np.ndarray]:
        il = [np.ascontiguousarray(b[..., 0].T) for b in boxes]
        ih = [np.ascontiguousarray(b[..., 1].T) for b in boxes]
        o: list[list[Any]] = [[None] * len(p) for p in self._out_pos]
        self._eval(il, ih, o)
        outs = []
        for i, pos in enumerate(self._out_pos):
            out = np.zeros((n, self.size_out[i], 2))
            for j, (lo, hi) in enumerate(o[i]):
                out[:, pos[j], 0] = lo
                out[:, pos[j], 1] = hi
            _sanitize(out)
            outs.append(out)
        return outs

    # --------------------------------------------------------------- centered
    def _build_centered(self) -> None:
        f = self.fun
        syms = [ca.SX.sym(f"z{i}", f.sparsity_in(i)) for i in range(self.n_in)]
        z = ca.vertcat(*[ca.vec(s) for s in syms])
        outs = f(*syms)
        if not isinstance(outs, (list, tuple)):
            outs = [outs]
        y = ca.vertcat(*[ca.vec(ca.densify(o)) for o in outs])
        jac = ca.Function(f"{f.name()}_jac", syms, [ca.jacobian(y, z)])
        self._jac = InclusionFunction(jac, "natural")
        self._nz = int(z.numel())
        self._ny = int(y.numel())

    def _centered(self, boxes: Sequence[np.ndarray], n: int) -> list[np.ndarray]:
        assert self._jac is not None
        mids = []
        for b in boxes:
            m = np.clip(0.5 * b[..., 0] + 0.5 * b[..., 1], b[..., 0], b[..., 1])
            mids.append(np.stack([m, m], axis=-1))
        fm = self._natural(mids, n)
        nat = self._natural(boxes, n)
        jac = self._jac._natural(boxes, n)[0]  # (N, ny*nz, 2), column-major
        jl = jac[..., 0].reshape(n, self._nz, self._ny).transpose(0, 2, 1)
        jh = jac[..., 1].reshape(n, self._nz, self._ny).transpose(0, 2, 1)
        dzl = np.concatenate(
            [np.broadcast_to(b[..., 0] - m[..., 0], (n, b.shape[1]))
             for b, m in zip(boxes, mids, strict=True)], axis=1)
        dzh = np.concatenate(
            [np.broadcast_to(b[..., 1] - m[..., 0], (n, b.shape[1]))
             for b, m in zip(boxes, mids, strict=True)], axis=1)
        dzl, dzh = arith.dn(dzl), arith.up(dzh)
        pl, ph = arith.mul(jl, jh, dzl[:, None, :], dzh[:, None, :])  # (N, ny, nz)
        sl, sh = _sum_interval(pl, ph, axis=2)
        results = []
        start = 0
        for i in range(self.n_out):
            d = self.size_out[i]
            cl, ch = arith.add(fm[i][..., 0], fm[i][..., 1],
                               sl[:, start:start + d], sh[:, start:start + d])
            start += d
            lo = np.maximum(cl, nat[i][..., 0])
            hi = np.minimum(ch, nat[i][..., 1])
            out = np.stack([lo, hi], axis=-1)
            _sanitize(out)
            results.append(out)
        return results

    def __call__(self, *args: Any) -> list[np.ndarray]:
        boxes, n = self._inputs(args)
        if self.kind == "natural":
            return self._natural(boxes, n)
        return self._centered(boxes, n)

    def __repr__(self) -> str:
        return (f"InclusionFunction('{self.fun.name()}', kind='{self.kind}', "
                f"inputs={self.size_in}, outputs={self.size_out})")


def _sanitize(out: np.ndarray) -> None:
    """Replace NaN bounds ("no information") by -inf / +inf in place."""
    nan = np.isnan(out)
    if nan.any():
        out[..., 0][nan[..., 0]] = -np.inf
        out[..., 1][nan[..., 1]] = np.inf


def _sum_interval(lo: np.ndarray, hi: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Outward-rounded sum of interval terms along ``axis``.

    Uses the floating-point summation error bound |fl(sum) - sum| <= (k-1) u sum|x_i|,
    widened to k * 2**-52 * sum|x_i| (k terms).
    """
    k = lo.shape[axis]
    with np.errstate(all="ignore"):
        sl = np.sum(lo, axis=axis)
        sh = np.sum(hi, axis=axis)
        el = np.sum(np.abs(lo), axis=axis) * (k * arith.U)
        eh = np.sum(np.abs(hi), axis=axis) * (k * arith.U)
        return arith.dn(sl - el), arith.up(sh + eh)


def _compile(fun: ca.Function) -> tuple[Callable[..., None], str]:
    gen = _Codegen(fun)
    src = gen.build()
    namespace: dict[str, Any] = {"_A": arith, "_K": gen.const_table, "np": np}
    exec(compile(src, f"<interval:{fun.name()}>", "exec"), namespace)  # noqa: S102
    return namespace["_eval"], src


def inclusion(fun: ca.Function, kind: str = "natural") -> InclusionFunction:
    """Compile a CasADi Function into a batched interval inclusion function.

    Parameters
    ----------
    fun : casadi.Function
        An SX Function (an MX Function is expanded to SX when possible). Inputs must be dense.
    kind : {"natural", "centered"}
        ``"natural"``: every operation replaced by its interval extension.
        ``"centered"``: the mean-value form ``f(m) + J(Z)(Z - m)`` over the joint box ``Z`` of
        all inputs (``m`` its midpoint, ``J`` the interval Jacobian of CasADi's symbolic
        Jacobian), intersected with the natural enclosure. Its overestimation shrinks
        quadratically with the box width.

    Returns
    -------
    InclusionFunction
        Callable taking one ``(N, d_i, 2)`` array per input and returning a list with one
        ``(N, d_o, 2)`` array per output.

    Examples
    --------
    >>> import casadi as ca, numpy as np
    >>> import casadi_cmpc as cm
    >>> x = ca.SX.sym("x")
    >>> F = cm.interval.inclusion(ca.Function("f", [x], [x * (1 - x)]))
    >>> lo, hi = F(np.array([[[0.0, 1.0]]]))[0][0, 0]
    >>> bool(lo <= 0.0 and hi >= 1.0)
    True
    """
    return InclusionFunction(fun, kind)
