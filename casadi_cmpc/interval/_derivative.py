"""Graph work behind the derivative-based enclosures (mean-value form, interval Jacobians).

Two facts make a CasADi Jacobian unsafe to evaluate naively with intervals:

* **Folded constants.** CasADi folds constant subexpressions in floating point while it
  differentiates (``d(3 (0.1 x))/dx`` becomes the single constant ``0.30000000000000004``)
  and caches numeric constants, so a folded value may be the very node of a literal of f.
  :class:`ParamGraph` therefore rebuilds f from its instruction list with every literal
  constant replaced by a *symbol*: differentiation cannot fold literals any more, and the
  compiler later reads those symbols as thin, exact constants (:class:`ParamFunction`) and
  folds them soundly with interval operations. The only constants left in the derivative
  graph come from CasADi's differentiation rules (``2`` of ``d x^2``, ``1/2`` of ``d sqrt``,
  ``2/sqrt(pi)`` of ``d erf`` ...); all but small integers and halves are widened
  (:func:`rule_constants`).
* **Jumps.** The mean-value theorem needs f continuous on the segment. CasADi
  differentiates floor, sign, comparisons, if_else, fmod ... as if they never jumped, and a
  pole (``1/x`` across 0, ``tan`` across pi/2) or a domain edge (``sqrt`` of a negative
  number) breaks it as well. :class:`ParamGraph` lists every operation of f that may jump
  together with the argument it jumps on (a *guard*) and which output elements depend on
  it; :func:`jumps` decides, per box, from the interval enclosures of the guards whether a
  jump is reachable. A derivative-based enclosure of an output element is only valid on
  boxes where none of its guards fires.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np

__all__ = ["ParamGraph", "ParamFunction", "exact_function", "rule_constants", "jumps",
           "JUMP_OPS"]

# op -> guard kind of its arguments; see ``_guards_of``
JUMP_OPS = {
    ca.OP_FLOOR, ca.OP_CEIL, ca.OP_SIGN, ca.OP_NOT, ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE,
    ca.OP_AND, ca.OP_OR, ca.OP_IF_ELSE_ZERO, ca.OP_COPYSIGN, ca.OP_FMOD, ca.OP_REMAINDER,
    ca.OP_ATAN2,
    # poles and domain edges
    ca.OP_INV, ca.OP_DIV, ca.OP_TAN, ca.OP_LOG, ca.OP_LOG1P, ca.OP_SQRT, ca.OP_ASIN,
    ca.OP_ACOS, ca.OP_ACOSH, ca.OP_ATANH, ca.OP_ERFINV, ca.OP_POW, ca.OP_CONSTPOW,
}

_UNARY_OPS = {
    ca.OP_ASSIGN, ca.OP_NEG, ca.OP_SQ, ca.OP_TWICE, ca.OP_INV, ca.OP_SQRT, ca.OP_EXP,
    ca.OP_LOG, ca.OP_SIN, ca.OP_COS, ca.OP_TAN, ca.OP_ASIN, ca.OP_ACOS, ca.OP_ATAN,
    ca.OP_SINH, ca.OP_COSH, ca.OP_TANH, ca.OP_ASINH, ca.OP_ACOSH, ca.OP_ATANH, ca.OP_FABS,
    ca.OP_FLOOR, ca.OP_CEIL, ca.OP_SIGN, ca.OP_NOT, ca.OP_ERF, ca.OP_ERFINV, ca.OP_LOG1P,
    ca.OP_EXPM1,
}

# Rule constants kept thin: small integers and halves. CasADi's differentiation rules only
# introduce such dyadic numbers (exact, and exactly folded with each other) and a few
# transcendental ones (erf, erfinv), whose folded combinations are not of this form.
_THIN_RULE_LIMIT = 2.0 ** 10


class ParamGraph:
    """An SX Function rebuilt with its literal constants as symbols, plus its jump guards.

    Parameters
    ----------
    fun : casadi.Function or ParamFunction
        An SX Function with dense inputs.

    Attributes
    ----------
    inputs : list of casadi.SX
        Fresh symbols, one per input of ``fun`` (same sparsity).
    params : casadi.SX, shape (p, 1)
        One symbol per literal constant of ``fun`` (an ``OP_CONST`` instruction).
    values : ndarray, shape (p,)
        Their values.
    outputs : list of casadi.SX
        The outputs of ``fun`` as expressions of ``inputs`` and ``params``.
    guards : list of (str, int, float)
        ``(kind, first guard expression, threshold)`` per operation that may jump; see
        :func:`jumps`.
    guard_exprs : casadi.SX, shape (q, 1)
        The guard expressions (arguments of the operations, or ``a - b`` for a comparison,
        ``a / b`` for fmod/remainder, ``cos(a)`` for tan).
    masks : list of list of int
        Per output, per nonzero: bit set of the guards it depends on.
    widen : ndarray of bool, shape (p,)
        True for the constants that are not exact literals but values CasADi may have
        rounded (those a :class:`ParamFunction` ``fun`` lists in ``derived``, other than
        its interval-valued ones): they are enclosed with a margin wherever the graph is
        evaluated, and never decide a guard.
    interval : ndarray of bool, shape (p,)
        True for the interval-valued parameters of a :class:`ParamFunction` ``fun``
        (their interval in ``bounds``); they never decide a guard either.
    bounds : ndarray, shape (p, 2)
        The interval every parameter stands for wherever the graph is evaluated: ``[v, v]``
        for an exact literal, the widened interval around ``v`` for a possibly rounded
        constant, and the given interval of an interval-valued parameter of a
        :class:`ParamFunction` ``fun`` (``values`` then holds its midpoint). Code that
        feeds the parameters to an interval evaluator must feed these bounds.

    ``fun`` may also be a :class:`ParamFunction`: its literals (and its widened constants)
    become parameters like any other constant.
    """

    def __init__(self, fun: Any) -> None:
        self.name = fun.name()
        derived = getattr(fun, "derived", frozenset())
        self.inputs = [ca.SX.sym(f"z{i}", fun.sparsity_in(i)) for i in range(fun.n_in())]
        flat = [ca.vertsplit(ca.vec(s)) if s.numel() else [] for s in self.inputs]
        work: dict[int, Any] = {}
        mask: dict[int, int] = {}
        const_val: dict[int, float] = {}
        params: list[ca.SX] = []
        values: list[float] = []
        widen: list[bool] = []
        bounds: list[tuple[float, float]] = []
        interval: list[bool] = []
        interval_of = getattr(fun, "instruction_bounds", None)
        guard_exprs: list[ca.SX] = []
        self.guards: list[tuple[str, int, float]] = []
        nz_out: list[list[Any]] = [[None] * fun.nnz_out(i) for i in range(fun.n_out())]
        self.masks: list[list[int]] = [[0] * fun.nnz_out(i) for i in range(fun.n_out())]
        for k in range(fun.n_instructions()):
            op = fun.instruction_id(k)
            ins = list(fun.instruction_input(k))
            outs = list(fun.instruction_output(k))
            if op == ca.OP_CONST:
                p = ca.SX.sym(f"c{len(params)}")
                params.append(p)
                v = float(fun.instruction_constant(k))
                iv = interval_of(k) if interval_of is not None else None
                values.append(v)
                interval.append(iv is not None)
                widen.append(k in derived and iv is None)
                if iv is not None:
                    bounds.append(iv)
                else:
                    bounds.append(_widened(v) if k in derived else (v, v))
                work[outs[0]] = p
                mask[outs[0]] = 0
                if k in derived or iv is not None:  # not an exact number: decides no guard
                    const_val.pop(outs[0], None)
                else:
                    const_val[outs[0]] = v
                continue
            if op == ca.OP_INPUT:
                work[outs[0]] = flat[ins[0]][ins[1]]
                mask[outs[0]] = 0
                const_val.pop(outs[0], None)
                continue
            if op == ca.OP_OUTPUT:
                nz_out[outs[0]][outs[1]] = work[ins[0]]
                self.masks[outs[0]][outs[1]] = mask[ins[0]]
                continue
            if op == ca.OP_CALL:
                from ..exceptions import UnsupportedOperationError

                raise UnsupportedOperationError(
                    f"'{self.name}' calls another Function (a call kept by never_inline): "
                    "write f in SX operations (inline the call) to analyse it")
            unary = op in _UNARY_OPS
            args = [work[ins[0]]] if unary else [work[ins[0]], work[ins[1]]]
            m = mask[ins[0]] if unary else mask[ins[0]] | mask[ins[1]]
            if op in JUMP_OPS:
                for kind, expr, t in _guards_of(op, args, const_val.get(ins[-1])):
                    self.guards.append((kind, len(guard_exprs), t))
                    guard_exprs.extend(expr)
                    m |= 1 << (len(self.guards) - 1)
            work[outs[0]] = ca.SX.unary(op, args[0]) if unary else ca.SX.binary(op, *args)
            mask[outs[0]] = m
            const_val.pop(outs[0], None)
        self.params = ca.vertcat(*params) if params else ca.SX(0, 1)
        self.values = np.asarray(values, dtype=float)
        self.widen = np.asarray(widen, dtype=bool)
        self.bounds = (np.asarray(bounds, dtype=float).reshape(-1, 2) if bounds
                       else np.zeros((0, 2)))
        self.interval = np.asarray(interval, dtype=bool)
        self.outputs = [ca.SX(fun.sparsity_out(i), ca.vertcat(*nz_out[i]))
                        if nz_out[i] else ca.SX(fun.sparsity_out(i))
                        for i in range(fun.n_out())]
        self.guard_exprs = ca.vertcat(*guard_exprs) if guard_exprs else ca.SX(0, 1)

    def function(self, name: str, inputs: Sequence[ca.SX], outputs: Sequence[ca.SX]
                 ) -> ParamFunction:
        """``Function(inputs + [params] -> outputs)`` viewed with the params as constants."""
        g = ca.Function(name, list(inputs) + [self.params], list(outputs),
                        {"live_variables": False})
        if self.interval.any():  # interval-valued parameters: pass their bounds
            values = self.bounds.copy()
            values[self.widen] = self.values[self.widen, None]  # widened by ParamFunction
            return ParamFunction(g, len(inputs), values, self.widen)
        return ParamFunction(g, len(inputs), self.values, self.widen)


def _guards_of(op: int, args: list[Any], c: float | None
               ) -> list[tuple[str, list[Any], float]]:
    """Guards ``(kind, expressions, threshold)`` of one operation with arguments ``args``
    (``c``: the value of the last argument when it is a literal constant)."""
    a = args[0]
    if op == ca.OP_FLOOR:
        return [("floor", [a], 0.0)]
    if op == ca.OP_CEIL:
        return [("ceil", [a], 0.0)]
    if op in (ca.OP_SIGN, ca.OP_NOT):
        return [("cross", [a], 0.0)]
    if op in (ca.OP_AND, ca.OP_OR):
        return [("cross", [a], 0.0), ("cross", [args[1]], 0.0)]
    if op in (ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE):
        return [("cross", [a - args[1]], 0.0)]
    if op == ca.OP_IF_ELSE_ZERO:
        return [("cross", [a], 0.0)]
    if op == ca.OP_COPYSIGN:
        return [("cross", [args[1]], 0.0)]
    if op == ca.OP_FMOD:
        return [("trunc", [a / args[1]], 0.0)]
    if op == ca.OP_REMAINDER:
        return [("half", [a / args[1]], 0.0)]
    if op == ca.OP_ATAN2:  # atan2(y, x): branch cut {y = 0, x <= 0}
        return [("atan2", [a, args[1]], 0.0)]
    if op == ca.OP_INV:
        return [("reach", [a], 0.0)]
    if op == ca.OP_DIV:
        return [("reach", [args[1]], 0.0)]
    if op == ca.OP_TAN:
        return [("reach", [ca.cos(a)], 0.0)]
    if op == ca.OP_LOG:
        return [("below_or", [a], 0.0)]
    if op == ca.OP_LOG1P:
        return [("below_or", [a], -1.0)]
    if op == ca.OP_SQRT:
        return [("below", [a], 0.0)]
    if op == ca.OP_ACOSH:
        return [("below", [a], 1.0)]
    if op in (ca.OP_ASIN, ca.OP_ACOS):
        return [("outside", [a], 1.0)]
    if op in (ca.OP_ATANH, ca.OP_ERFINV):
        return [("outside_or", [a], 1.0)]
    if op in (ca.OP_POW, ca.OP_CONSTPOW):
        if c is not None and np.isfinite(c) and c == np.floor(c):
            return [] if c >= 0 else [("reach", [a], 0.0)]
        if c is not None and c > 0:
            return [("below", [a], 0.0)]
        return [("below_or", [a], 0.0)]
    raise AssertionError(f"no guard for op {op}")  # pragma: no cover


def jumps(kind: str, lo: np.ndarray, hi: np.ndarray, t: float,
          lo2: np.ndarray | None = None, hi2: np.ndarray | None = None) -> np.ndarray:
    """Can the guarded operation jump (or leave its domain) for a guard in ``[lo, hi]``?

    ``lo``, ``hi`` (and ``lo2``, ``hi2`` for atan2's second guard) are enclosures of the
    guard expression over a batch of boxes, shape (N,) or scalars. Returns a boolean array:
    True where a jump is reachable or the enclosure carries no information (NaN).

    Kinds: ``floor``/``ceil``: the argument reaches an integer where the function steps
    (floor is continuous on ``[k, k + 1)``, ceil on ``(k - 1, k]``); ``cross``: a non-constant
    argument reaches 0 (sign, comparisons as ``a - b``, if_else's condition, copysign's
    sign, logical operations); ``trunc``: fmod's quotient crosses a non-zero integer
    (trunc is continuous on (-1, 1) and on [k, k + 1), (-k - 1, -k] for k >= 1);
    ``half``: remainder's quotient reaches an odd multiple of 1/2; ``atan2``: y reaches 0
    with x <= 0; ``reach``: a pole at 0; ``below``/``below_or``: below (or at) ``t``;
    ``outside``/``outside_or``: outside ``[-t, t]`` (or on its edge).
    """
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    bad = np.isnan(lo) | np.isnan(hi)
    with np.errstate(invalid="ignore"):
        if kind == "floor":
            j = np.floor(lo) != np.floor(hi)
        elif kind == "ceil":
            j = np.ceil(lo) != np.ceil(hi)
        elif kind == "cross":
            j = (lo <= 0) & (hi >= 0) & (lo < hi)
        elif kind == "trunc":
            j = ~np.isfinite(lo) | ~np.isfinite(hi) | (np.trunc(lo) != np.trunc(hi))
        elif kind == "half":
            a = np.ceil(2.0 * lo)  # odd integers in [2 lo, 2 hi] (doubling is exact)
            b = np.floor(2.0 * hi)
            j = ~np.isfinite(lo) | ~np.isfinite(hi) | (a < b) | ((a == b) & (np.fmod(a, 2.0) != 0))
        elif kind == "atan2":
            assert lo2 is not None and hi2 is not None
            j = (lo <= 0) & (hi >= 0) & ~(np.asarray(lo2) > 0)
            bad = bad | np.isnan(lo2) | np.isnan(hi2)
        elif kind == "reach":
            j = (lo <= 0) & (hi >= 0)
        elif kind == "below":
            j = lo < t
        elif kind == "below_or":
            j = lo <= t
        elif kind == "outside":
            j = (lo < -t) | (hi > t)
        elif kind == "outside_or":
            j = (lo <= -t) | (hi >= t)
        else:  # pragma: no cover
            raise ValueError(f"unknown guard kind {kind}")
    return np.asarray(j | bad)


class ParamFunction:
    """Instruction-list view of ``G(inputs..., p)`` in which every read of ``p`` is a constant.

    Quacks like the ``casadi.Function`` it wraps (for the interval compiler): the last input
    ``p`` is hidden (``n_in``) and its ``OP_INPUT`` instructions read as ``OP_CONST`` with
    the literal values. :attr:`literals` holds those instruction indices.

    Parameters
    ----------
    g : casadi.Function
        SX Function whose last input is the parameter vector ``p`` (dense, shape (q, 1)).
    n_real : int
        Number of inputs before ``p``.
    values : ndarray, shape (q,) or (q, 2)
        The values of ``p``; or, as rows ``[lo, hi]``, the intervals they stand for: a
        parameter with ``lo < hi`` is *interval-valued* (every evaluator reads it as the
        constant interval ``[lo, hi]``: the expression then encloses a family of
        functions, e.g. a remainder term known only to lie in an interval), one with
        ``lo == hi`` is exact.
    widen : ndarray of bool, shape (q,), optional
        True for the parameters whose value may be rounded (enclosed with a margin instead
        of thin); default: all exact.
    widen_own : bool
        Also widen the constants of ``g`` itself (``OP_CONST``): set it when ``g`` was built
        by composing expressions whose literals are all in ``p``, so that any constant left
        in ``g`` was created, and possibly rounded, by CasADi's simplifications.

    Attributes
    ----------
    literals : frozenset of int
        Instructions that read an exact (thin or widened) parameter of ``p``.
    derived : frozenset of int
        Constant instructions that an interval evaluation must not take as exact numbers:
        reads of widened parameters and of interval-valued ones (:meth:`instruction_bounds`
        gives their interval), and the constants of ``g`` with ``widen_own``.
    values : ndarray, shape (q,)
        The values (of an interval-valued parameter: its midpoint, for display only).
    bounds : ndarray, shape (q, 2)
        What an interval evaluator must feed for each parameter: ``[v, v]``, the widened
        interval of a possibly rounded value, or the given interval.
    interval : ndarray of bool, shape (q,)
        True for the interval-valued parameters.
    """

    def __init__(self, g: ca.Function, n_real: int, values: np.ndarray,
                 widen: np.ndarray | None = None, widen_own: bool = False) -> None:
        self._g = g
        self._n = int(n_real)
        q = g.nnz_in(self._n)
        arr = np.asarray(values, dtype=float)
        if arr.ndim == 2 and arr.shape == (q, 2) and q > 0:
            lo, hi = arr[:, 0].copy(), arr[:, 1].copy()
            if not (lo <= hi).all():
                raise ValueError(f"'{g.name()}': interval parameters need lo <= hi (no NaN)")
            with np.errstate(over="ignore", invalid="ignore"):
                mid = np.where(lo == hi, lo, 0.5 * lo + 0.5 * hi)
        else:
            mid = arr.reshape(-1)
            if mid.size != q:
                raise ValueError(f"'{g.name()}' has {q} parameters; got {mid.size} values")
            lo, hi = mid, mid
        wid = (np.zeros(q, dtype=bool) if widen is None
               else np.asarray(widen, dtype=bool).reshape(-1))
        self.interval = np.asarray(lo < hi, dtype=bool)
        self._const: dict[int, float] = {}
        self._bounds: dict[int, tuple[float, float]] = {}
        derived = set()
        for k in range(g.n_instructions()):
            op = g.instruction_id(k)
            if op == ca.OP_INPUT:
                ins = g.instruction_input(k)
                if ins[0] == self._n:
                    j = ins[1]
                    self._const[k] = float(mid[j])
                    if self.interval[j]:  # its interval (widened too if flagged)
                        b_lo, b_hi = float(lo[j]), float(hi[j])
                        if wid[j]:
                            b_lo, b_hi = _widened(b_lo)[0], _widened(b_hi)[1]
                        self._bounds[k] = (b_lo, b_hi)
                    if wid[j] or self.interval[j]:
                        # not an exact number: code that only knows thin or widened
                        # constants (e.g. a contractor) must refuse it
                        derived.add(k)
            elif op == ca.OP_CONST and widen_own:
                derived.add(k)
        self.literals = frozenset(k for k in self._const if k not in self._bounds)
        self.derived = frozenset(derived)
        self.values = np.asarray(mid, dtype=float)
        self.widen = wid
        b = np.stack([lo, hi], axis=1).astype(float) if q else np.zeros((0, 2))
        for j in np.flatnonzero(wid):
            b[j] = _widened(float(b[j, 0]))[0], _widened(float(b[j, 1]))[1]
        self.bounds = b

    def instruction_id(self, k: int) -> int:
        return ca.OP_CONST if k in self._const else self._g.instruction_id(k)

    def instruction_input(self, k: int) -> list[int]:
        return [] if k in self._const else list(self._g.instruction_input(k))

    def instruction_constant(self, k: int) -> float:
        return self._const[k] if k in self._const else self._g.instruction_constant(k)

    def instruction_bounds(self, k: int) -> tuple[float, float] | None:
        """``(lo, hi)`` of the constant instruction ``k`` when it reads an interval-valued
        parameter (to be used as it is, not widened further), else None (an exact or
        widened constant, see :attr:`derived`)."""
        return self._bounds.get(k)

    def n_in(self) -> int:
        return self._n

    @property
    def function(self) -> ca.Function:
        """The wrapped Function ``G(inputs..., p)`` (``p`` its last input)."""
        return self._g

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):  # protocols (copy, pickle) and unset private state
            raise AttributeError(name)
        return getattr(self._g, name)

    def __repr__(self) -> str:
        return (f"ParamFunction('{self._g.name()}', {self._n} inputs, "
                f"{self.values.size} parameters ({int(self.interval.sum())} interval-valued), "
                f"{len(self.derived)} widened constants)")


def exact_function(name: str, inputs: Sequence[ca.SX], outputs: Sequence[ca.SX],
                   params: ca.SX, values: np.ndarray) -> ParamFunction:
    """``(inputs...) -> outputs`` with the symbols ``params`` read as exact constants.

    Parameters
    ----------
    name : str
    inputs : list of casadi.SX
        Dense symbolic inputs.
    outputs : list of casadi.SX
        Expressions of ``inputs`` and ``params``.
    params : casadi.SX, shape (q, 1)
        Symbols standing for exact numbers (e.g. :attr:`ParamGraph.params` of the graphs
        composed into ``outputs``).
    values : ndarray, shape (q,) or (q, 2)
        Their values, or the intervals ``[lo, hi]`` they stand for (see
        :class:`ParamFunction`).

    Returns
    -------
    ParamFunction
        Every constant of the outputs that is not among ``params`` was created by CasADi
        while composing (``a - a`` -> 0, then ``acos(0)`` folded) and is widened.
    """
    g = ca.Function(name, list(inputs) + [params], list(outputs), {"live_variables": False})
    vals = np.asarray(values, dtype=float)
    if not (vals.ndim == 2 and vals.shape[1:] == (2,)):
        vals = vals.reshape(-1)
    return ParamFunction(g, len(inputs), vals, widen_own=True)


def _widened(v: float) -> tuple[float, float]:
    from .compiler import _widen_constant

    return _widen_constant(v)


def rule_constants(g: ParamFunction) -> frozenset[int]:
    """Instructions of ``g`` that load a constant created by differentiation (not a literal of
    f) and not provably exact: everything except 0 and small integers and halves; and the
    constants ``g`` marks as possibly rounded (:attr:`ParamFunction.derived`)."""
    out = set(getattr(g, "derived", ()))
    for k in range(g.n_instructions()):
        if g.instruction_id(k) != ca.OP_CONST or k in g.literals:
            continue
        v = float(g.instruction_constant(k))
        if not (np.isfinite(v) and abs(v) <= _THIN_RULE_LIMIT and 2.0 * v == np.floor(2.0 * v)):
            out.add(k)
    return frozenset(out)


def guard_flags(graph: ParamGraph, lo: np.ndarray, hi: np.ndarray, n: int) -> np.ndarray:
    """(N, q_guards) booleans from guard enclosures ``lo``, ``hi`` (lists of per-expression
    bounds, arrays (N,) or scalars)."""
    flags = np.zeros((n, len(graph.guards)), dtype=bool)
    for gi, (kind, e, t) in enumerate(graph.guards):
        if kind == "atan2":
            j = jumps(kind, lo[e], hi[e], t, lo[e + 1], hi[e + 1])
        else:
            j = jumps(kind, lo[e], hi[e], t)
        flags[:, gi] = j
    return flags


def rows_reaching_jumps(masks: Sequence[int], flags: np.ndarray) -> np.ndarray:
    """(N, len(masks)) booleans: row r reaches a jump when a guard of ``masks[r]`` fires."""
    n = flags.shape[0]
    out = np.zeros((n, len(masks)), dtype=bool)
    for r, m in enumerate(masks):
        if not m:
            continue
        idx = [i for i in range(flags.shape[1]) if (m >> i) & 1]
        out[:, r] = flags[:, idx].any(axis=1)
    return out


def _run(evaluator: Any, boxes: Sequence[np.ndarray], nnz: int) -> list[Any]:
    """Run a generated evaluator on ``(N_i, d_i, 2)`` boxes; one (lo, hi) per nonzero."""
    il = [np.ascontiguousarray(b[..., 0].T) for b in boxes]
    ih = [np.ascontiguousarray(b[..., 1].T) for b in boxes]
    o: list[list[Any]] = [[None] * nnz]
    with np.errstate(all="ignore"):
        evaluator(il, ih, o)
    return o[0]


class JumpGuard:
    """Per box: which output elements of ``graph`` may jump (so that no derivative-based
    enclosure is valid for them)."""

    def __init__(self, graph: ParamGraph, out_rows: Sequence[int]) -> None:
        from .compiler import _compile

        self.graph = graph
        self.masks = list(out_rows)
        self.active = bool(graph.guards) and any(self.masks)
        if self.active:
            g = graph.function(f"{graph.name}_guards", graph.inputs, [graph.guard_exprs])
            self._eval = _compile(g, rule_constants(g))[0]
            self._nnz = g.nnz_out(0)
            self._pos = np.asarray(g.sparsity_out(0).find(), dtype=np.intp)
            self._q = g.numel_out(0)

    def __call__(self, boxes: Sequence[np.ndarray], n: int) -> np.ndarray:
        """(N, rows) booleans, True where the row may jump on the box."""
        if not self.active:
            return np.zeros((n, len(self.masks)), dtype=bool)
        res = _run(self._eval, boxes, self._nnz)
        lo = [np.zeros(n)] * self._q
        hi = [np.zeros(n)] * self._q
        for j, (a, b) in enumerate(res):
            lo[int(self._pos[j])] = np.broadcast_to(np.asarray(a, dtype=float), (n,))
            hi[int(self._pos[j])] = np.broadcast_to(np.asarray(b, dtype=float), (n,))
        return rows_reaching_jumps(self.masks, guard_flags(self.graph, lo, hi, n))


def output_masks(graph: ParamGraph, fun_sparsity: Any, out: int) -> list[int]:
    """Guard masks of the elements of ``vec(output out)`` (structural zeros: 0)."""
    masks = [0] * int(fun_sparsity.numel())
    for j, r in enumerate(fun_sparsity.find()):
        masks[int(r)] = graph.masks[out][j]
    return masks


class JacobianInclusion:
    """Batched interval Jacobian ``d vec(f_out) / d vec(x_wrt)`` valid for the mean-value form.

    For every box, entry ``(r, c)`` encloses ``d f_r / d x_c`` at every point of the box, and
    row ``r`` is ``[-inf, inf]`` wherever ``f_r`` may jump (or leave its domain) on the box:
    then ``f_r(b) - f_r(a)`` lies in ``J_r (b - a)`` for all points ``a``, ``b`` of the box
    (mean-value theorem). Literal constants of ``f`` enter exactly; constants created by
    differentiation are widened (see :class:`ParamGraph`).

    Parameters
    ----------
    fun : casadi.Function or ParamFunction
        SX Function with dense inputs (a ParamFunction: its parameters as constants).
    wrt, out : int
        Input and output indices.

    Call ``J(boxes, n)`` with one ``(N_i, d_i, 2)`` array per input (``N_i`` in {1, n});
    returns ``(n, m, d, 2)`` with ``m`` = numel of the output, ``d`` = numel of the input.
    """

    def __init__(self, fun: Any, wrt: int = 0, out: int = 0) -> None:
        from .compiler import _as_sx_function, _compile

        fun = _as_sx_function(fun, allow_param=True)
        graph = ParamGraph(fun)
        y = ca.vec(graph.outputs[out])
        z = ca.vec(graph.inputs[wrt])
        self.m, self.d = int(y.numel()), int(z.numel())
        jac = ca.densify(ca.jacobian(y, z))
        g = graph.function(f"{fun.name()}_jac", graph.inputs, [jac])
        self.source = _compile(g, rule_constants(g))
        self._eval = self.source[0]
        self._nnz = g.nnz_out(0)
        self._pos = np.asarray(g.sparsity_out(0).find(), dtype=np.intp)
        self.guard = JumpGuard(graph, output_masks(graph, fun.sparsity_out(out), out))
        self.graph = graph

    def __call__(self, boxes: Sequence[np.ndarray], n: int) -> np.ndarray:
        m, d = self.m, self.d
        out = np.zeros((n, m * d, 2))
        for j, (lo, hi) in enumerate(_run(self._eval, boxes, self._nnz)):
            out[:, self._pos[j], 0] = lo
            out[:, self._pos[j], 1] = hi
        nan = np.isnan(out)
        out[..., 0][nan[..., 0]] = -np.inf
        out[..., 1][nan[..., 1]] = np.inf
        J = out.reshape(n, d, m, 2).transpose(0, 2, 1, 3)
        jump = self.guard(boxes, n)  # (n, m)
        if jump.any():
            J = J.copy()
            J[jump, :, 0] = -np.inf
            J[jump, :, 1] = np.inf
        return J
