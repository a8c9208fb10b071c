"""Compile a CasADi SX ``Function`` into a batched interval inclusion function.

The compiler walks the Function's instruction list once (``n_instructions``,
``instruction_id/input/output/constant``) and generates straight-line Python/numpy source in
which every CasADi operation is replaced by its interval extension from
:mod:`casadi_cmpc.interval.arith`. Constants are folded at compile time (soundly: folded with
the interval operations themselves) and operations with a thin constant operand are
specialised (e.g. ``x * c`` costs two multiplications instead of four).
"""

from __future__ import annotations

import warnings
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
        f = self.fun
        for k in range(f.n_instructions()):
            if self.only is not None and k not in self.only:
                continue
            op = f.instruction_id(k)
            ins = list(f.instruction_input(k))
            outs = list(f.instruction_output(k))
            if op == ca.OP_CONST:
                v = float(f.instruction_constant(k))
                if k in self.widen:
                    lo, hi = _widen_constant(v)
                    self.consts[outs[0]] = (lo, hi)
                else:
                    self.consts[outs[0]] = (v, v)
            elif op == ca.OP_INPUT:
                self.consts.pop(outs[0], None)
                self.lines.append(
                    f"    l{outs[0]} = IL[{ins[0]}][{ins[1]}]; h{outs[0]} = IH[{ins[0]}][{ins[1]}]")
            elif op == ca.OP_OUTPUT:
                lo, hi = self._operand(ins[0])
                oi = outs[0] if self.out_map is None else self.out_map[outs[0]]
                self.lines.append(f"    O[{oi}][{outs[1]}] = ({lo}, {hi})")
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
                    elif self._signed_const(i1):
                        expr = f"_A.mulci({a[0]}, {a[1]}, {b[0]}, {b[1]})"
                    elif self._signed_const(i0):
                        expr = f"_A.mulci({b[0]}, {b[1]}, {a[0]}, {a[1]})"
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

    Attributes
    ----------
    fun : casadi.Function
        The SX Function (expanded if an MX Function was given).
    kind : str
        ``"natural"`` or ``"centered"``.
    centered_fallback : bool
        True when ``kind == "centered"`` but the Function contains operations through which it
        may be discontinuous (floor, ceil, sign, comparisons, if_else, fmod, remainder,
        copysign): the mean-value form would be unsound there, so the natural inclusion is
        used (a :class:`~casadi_cmpc.CmpcWarning` says so).
    source : str
        The generated numpy source (natural evaluator), for inspection.
    """

    chunk: int = 8192
    chunk_centered: int = 4096

    def __init__(self, fun: ca.Function, kind: str = "natural", *,
                 derived_outputs: Sequence[int] = (), evaluate: Sequence[int] | None = None
                 ) -> None:
        kind = str(kind).lower()
        if kind not in _KINDS:
            raise ValueError(f"unknown inclusion kind '{kind}'; valid kinds: {', '.join(_KINDS)}")
        fun = _as_sx_function(fun)
        if derived_outputs or evaluate is not None:
            if kind != "natural":
                raise ValueError("derived_outputs/evaluate are for natural inclusions only")
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
        self._eval, self.source = _compile(fun, self._widen, self._keep)
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
                and (self.kind == "natural" or self.centered_fallback))

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
        self._g_eval, self._g_source = _compile(g, _dv.rule_constants(g))  # type: ignore[arg-type]
        self._g_nnz = [g.nnz_out(i) for i in range(g.n_out())]
        rows, cols = jac.sparsity().get_triplet()
        # row offsets of each output inside y, and nonzero rows of each output
        self._jac_rows = np.asarray(rows, dtype=np.intp)
        self._jac_cols = np.asarray(cols, dtype=np.intp)
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
        # the thin midpoint boxes [m, m] share one array for both bounds: the evaluator
        # never writes into its inputs
        o: list[list[Any]] = [[None] * k for k in self._g_nnz]
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
        boxes, n = self._inputs(args)
        return self.evaluate_unchecked(boxes, n)

    def evaluate_unchecked(self, boxes: Sequence[np.ndarray], n: int) -> list[np.ndarray]:
        """Evaluate on already validated ``(N_i, d_i, 2)`` float arrays (N_i in {1, n}).

        For solvers that build their own box batches; no shape or NaN checks are made.
        """
        run = self._natural if (self.kind == "natural" or self.centered_fallback) \
            else self._centered
        step = int(self.chunk if run == self._natural else self.chunk_centered)
        if n <= step:
            return run(boxes, n)
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
                f"inputs={self.size_in}, outputs={self.size_out})")


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
