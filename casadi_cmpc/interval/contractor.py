"""Forward-backward (HC4Revise) contractors generated from a CasADi SX graph.

A contractor for the constraint ``f(x) in Y`` maps a box ``X`` to a smaller box
``C(X) ⊆ X`` that still contains every solution ``x ∈ X`` with ``f(x) ∈ Y``. The
forward-backward contractor (HC4Revise, Benhamou et al. 1999) works on the expression graph
of ``f``:

1. *Forward sweep.* Every node of the graph gets an interval enclosure of its value over
   ``X`` (the natural inclusion of :mod:`casadi_cmpc.interval.compiler`, with the same
   outward-rounded operations of :mod:`casadi_cmpc.interval.arith`).
2. The enclosures of the output nodes are intersected with ``Y``.
3. *Backward sweep.* In reverse topological order, each node ``z = op(a, b)`` narrows its
   operands with the projections of the constraint ``z = op(a, b)``, e.g.
   ``a ← a ∩ (z - b)`` for ``z = a + b``. A node used by several parents receives the
   intersection of all their projections before its own projection is applied, and the
   input nodes finally narrow the box.

An empty intersection anywhere proves that the box holds no solution. In a set inversion
such as SIVIA (thesis §4.1.2, Algorithm 4.1, after Jaulin et al. 2001) the contractor
removes parts of a box that can be discarded without bisecting, and can discard whole boxes
that the inclusion test alone leaves undecided.

Soundness
---------
* Every projection is an interval operation of :mod:`~casadi_cmpc.interval.arith`, or is
  rounded outward in the same way (``sqrt`` by ``dnm``/``upm`` as IEEE ``sqrt`` is correctly
  rounded, ``exp``, ``log`` and the other libm functions by ``dnf``/``upf``): the contracted
  set is never smaller than the exact projection.
* A NaN forward value means *possibly undefined, no information*. It takes part in the
  forward sweep under the NaN convention of :mod:`~casadi_cmpc.interval.arith`, and wherever
  an enclosure is used to narrow something it counts as the whole line. Projections that
  come out NaN (``0 * inf``, division by an interval containing 0, ...) do not narrow.
* *Solutions* are the points ``x`` at which every element of ``f(x)``, evaluated along the
  graph in exact real arithmetic, is defined and lies in ``Y``. Undefined values propagate as
  IEEE NaN does: through arithmetic and the elementary functions, but not through ``fmin``,
  ``fmax``, comparisons, ``if_else``, ``pow`` (``pow(nan, 0) = 1``), ``hypot`` or the sign
  argument of ``copysign``. Nodes from which an undefined value reaches an output (*strict*
  nodes) are defined at every solution; only they are narrowed, and only for them does the
  contractor use the domain of an operation (``sqrt`` needs ``a >= 0``, ``log`` needs
  ``a > 0``, ...). A box on which a strict node is undefined everywhere, e.g. ``x < 0``
  under ``sqrt(x)``, is therefore declared empty.
* Operations without a projection rule (``sin``, ``fmin``, comparisons, ``pow``, ...) pass no
  information backward: their operands keep their forward enclosures, which is sound.

References
----------
F. Benhamou, F. Goualard, L. Granvilliers, J.-F. Puget, "Revising hull and box consistency",
Proc. ICLP 1999, pp. 230-244.
L. Jaulin, M. Kieffer, O. Didrit, E. Walter, *Applied Interval Analysis*, Springer, 2001.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import casadi as ca
import numpy as np
from scipy import special as _special

from ..exceptions import (
    DimensionError,
    EmptySetError,
    InvalidBoundsError,
    UnsupportedOperationError,
)
from . import arith as A
from .compiler import _BINARY, _UNARY, _as_sx_function

__all__ = ["Contractor", "contractor"]

_INF = np.inf
_NAN = np.nan
_fmax = np.fmax  # ignores NaN: a NaN projection bound leaves the enclosure as it is
_fmin = np.fmin

# Operations whose result is NaN whenever one of their operands is NaN (IEEE semantics, as
# CasADi evaluates them): an undefined operand makes the result undefined.
_STRICT = frozenset({
    ca.OP_ASSIGN, ca.OP_ADD, ca.OP_SUB, ca.OP_MUL, ca.OP_DIV, ca.OP_NEG, ca.OP_TWICE,
    ca.OP_SQ, ca.OP_SQRT, ca.OP_EXP, ca.OP_LOG, ca.OP_INV, ca.OP_FABS, ca.OP_SIN, ca.OP_COS,
    ca.OP_TAN, ca.OP_ASIN, ca.OP_ACOS, ca.OP_ATAN, ca.OP_SINH, ca.OP_COSH, ca.OP_TANH,
    ca.OP_ASINH, ca.OP_ACOSH, ca.OP_ATANH, ca.OP_ERF, ca.OP_ERFINV, ca.OP_LOG1P,
    ca.OP_EXPM1, ca.OP_FLOOR, ca.OP_CEIL, ca.OP_SIGN, ca.OP_ATAN2, ca.OP_FMOD,
    ca.OP_REMAINDER,
})

# Strict unary functions with a closed domain [lo, hi]: the forward value of a strict node
# is taken over the part of its operand inside the domain.
_CLOSED_DOMAIN: dict[int, tuple[float, float, Callable[..., Any]]] = {
    ca.OP_SQRT: (0.0, _INF, A.sqrt),
    ca.OP_ASIN: (-1.0, 1.0, A.asin),
    ca.OP_ACOS: (-1.0, 1.0, A.acos),
    ca.OP_ACOSH: (1.0, _INF, A.acosh),
}
# Increasing functions with an open domain (lo, hi), infinite at the open ends.
_OPEN_DOMAIN: dict[int, tuple[float, float, Callable[..., Any]]] = {
    ca.OP_LOG: (0.0, _INF, np.log),
    ca.OP_LOG1P: (-1.0, _INF, np.log1p),
    ca.OP_ATANH: (-1.0, 1.0, np.arctanh),
    ca.OP_ERFINV: (-1.0, 1.0, _special.erfinv),
}
# z = fn(a) increasing: a = inv(z) on the clipped range [clip_lo, clip_hi] of fn; the
# projection is intersected with [dom_lo, inf) (the lower end of the domain of fn).
_MONO_INVERSE: dict[int, tuple[Callable[..., Any], float, float, float]] = {
    ca.OP_EXP: (np.log, 0.0, _INF, -_INF),
    ca.OP_LOG: (np.exp, -_INF, _INF, 0.0),
    ca.OP_EXPM1: (np.log1p, -1.0, _INF, -_INF),
    ca.OP_LOG1P: (np.expm1, -_INF, _INF, -1.0),
    ca.OP_SINH: (np.arcsinh, -_INF, _INF, -_INF),
    ca.OP_ASINH: (np.sinh, -_INF, _INF, -_INF),
    ca.OP_TANH: (np.arctanh, -1.0, 1.0, -_INF),
}

_Step = Callable[["_State"], None]


class _State:
    """Per-call work arrays: node enclosures ``L``/``H`` (one per work slot), the input box
    ``XL``/``XH`` (one ``(N,)`` array per input element) and the emptiness flags."""

    __slots__ = ("L", "H", "XL", "XH", "emp")

    def __init__(self, L: list[Any], H: list[Any], XL: list[np.ndarray],
                 XH: list[np.ndarray], emp: np.ndarray) -> None:
        self.L = L
        self.H = H
        self.XL = XL
        self.XH = XH
        self.emp = emp


def _real(lo: Any, hi: Any) -> tuple[Any, Any]:
    """An enclosure with a NaN bound (no information) becomes the whole line, on both sides:
    a NaN on one side also says nothing about the other."""
    bad = np.isnan(lo) | np.isnan(hi)
    if np.any(bad):
        return np.where(bad, -_INF, lo), np.where(bad, _INF, hi)
    return lo, hi


def _flag(s: _State, mask: Any) -> None:
    np.logical_or(s.emp, mask, out=s.emp)


def _meet(s: _State, i: int, lo: Any, hi: Any) -> None:
    """Narrow node ``i`` to its intersection with the projection [lo, hi]. A projection with
    a NaN bound (an overflow or an undefined operation met on the way) narrows nothing, on
    either side."""
    bad = np.isnan(lo) | np.isnan(hi)
    if np.any(bad):
        lo = np.where(bad, -_INF, lo)
        hi = np.where(bad, _INF, hi)
    s.L[i] = _fmax(s.L[i], lo)
    s.H[i] = _fmin(s.H[i], hi)


def _two_branch(s: _State, i: int, rl: Any, rh: Any) -> None:
    """Narrow node ``i`` to the hull of its intersections with [rl, rh] and [-rh, -rl]."""
    al, ah = s.L[i], s.H[i]
    pl, ph = _fmax(al, rl), _fmin(ah, rh)
    nl, nh = _fmax(al, -rh), _fmin(ah, -rl)
    p_empty = pl > ph
    n_empty = nl > nh
    # both non-empty: the negative branch lies below the positive one
    s.L[i] = np.where(n_empty, pl, nl)
    s.H[i] = np.where(p_empty, nh, ph)


def _factor(s: _State, i: int, pl: Any, ph: Any, ql: Any, qh: Any) -> None:
    """Narrow node ``u`` (slot ``i``) by the constraint ``u * q = p``, ``q ∈ [ql, qh]``,
    ``p ∈ [pl, ph]``: ``u ∈ p / q``, with the extended (two-ray) quotient where ``q``
    contains 0 and ``p`` does not; no narrowing where both contain 0."""
    lo, hi = A.div(pl, ph, ql, qh)  # NaN where q contains 0
    ray = (ql <= 0) & (qh >= 0) & ((pl > 0) | (ph < 0))
    if np.any(ray):
        ul, uh = s.L[i], s.H[i]
        pos = pl > 0
        # u <= nu (reached with q < 0 when p > 0, with q > 0 when p < 0) or u >= pu; a
        # ray bound that comes out NaN (an overflowed quotient) keeps the whole ray
        nu = A.upm(np.where(pos, pl / ql, ph / qh))
        pu = A.dnm(np.where(pos, pl / qh, ph / ql))
        nu = np.where(np.isnan(nu), _INF, nu)
        pu = np.where(np.isnan(pu), -_INF, pu)
        n_ok = np.where(pos, ql < 0, qh > 0) & (ul <= nu)
        p_ok = np.where(pos, qh > 0, ql < 0) & (pu <= uh)
        lo = np.where(ray, np.where(n_ok, ul, np.where(p_ok, pu, _INF)), lo)
        hi = np.where(ray, np.where(p_ok, uh, np.where(n_ok, nu, -_INF)), hi)
    _meet(s, i, lo, hi)


# ------------------------------------------------------------------------ forward steps
def _forward_value(op: int, ins: Sequence[int], cv: dict[int, float]
                   ) -> Callable[[_State], tuple[Any, Any]] | None:
    """The natural interval extension of one instruction (None: no extension known)."""
    if op in _UNARY:
        fn = getattr(A, _UNARY[op])
        i = ins[0]
        return lambda s: fn(s.L[i], s.H[i])
    if op not in _BINARY:
        return None
    i, j = ins[0], ins[1]
    c0, c1 = cv.get(i), cv.get(j)
    if op == ca.OP_ADD and c1 is not None:
        return lambda s: A.addc(s.L[i], s.H[i], c1)
    if op == ca.OP_ADD and c0 is not None:
        return lambda s: A.addc(s.L[j], s.H[j], c0)
    if op == ca.OP_SUB and c1 is not None:
        return lambda s: A.addc(s.L[i], s.H[i], -c1)
    if op == ca.OP_SUB and c0 is not None:
        return lambda s: A.csub(c0, s.L[j], s.H[j])
    if op == ca.OP_MUL and c1 is not None:
        return lambda s: A.mulc(s.L[i], s.H[i], c1)
    if op == ca.OP_MUL and c0 is not None:
        return lambda s: A.mulc(s.L[j], s.H[j], c0)
    if op == ca.OP_DIV and c1 is not None:
        return lambda s: A.divc(s.L[i], s.H[i], c1)
    if op == ca.OP_DIV and c0 is not None:
        return lambda s: A.cdiv(c0, s.L[j], s.H[j])
    if op in (ca.OP_POW, ca.OP_CONSTPOW) and c1 is not None:
        return lambda s: A.powc(s.L[i], s.H[i], c1)
    fn = getattr(A, _BINARY[op])
    return lambda s: fn(s.L[i], s.H[i], s.L[j], s.H[j])


def _strict_domain_value(op: int, ins: Sequence[int], cv: dict[int, float]
                         ) -> Callable[[_State], tuple[Any, Any]] | None:
    """Forward value of a strict node over the part of its operand inside the domain of
    the operation; flags the rows where that part is empty (None: no domain to use)."""
    i = ins[0]
    if op in _CLOSED_DOMAIN:
        dlo, dhi, fn = _CLOSED_DOMAIN[op]

        def closed(s: _State) -> tuple[Any, Any]:
            al, ah = s.L[i], s.H[i]
            _flag(s, (ah < dlo) | (al > dhi))
            return fn(np.clip(al, dlo, dhi), np.clip(ah, dlo, dhi))
        return closed
    if op in _OPEN_DOMAIN:
        dlo, dhi, f = _OPEN_DOMAIN[op]

        def open_(s: _State) -> tuple[Any, Any]:
            al, ah = s.L[i], s.H[i]
            _flag(s, (ah <= dlo) | (al >= dhi))
            return A.dnf(f(np.clip(al, dlo, dhi))), A.upf(f(np.clip(ah, dlo, dhi)))
        return open_
    if op in (ca.OP_POW, ca.OP_CONSTPOW) and ins[1] in cv:
        c = cv[ins[1]]
        if not np.isfinite(c) or float(c).is_integer():
            return None  # integer powers are defined everywhere (or handled by powi)
        if c > 0:
            def pos_pow(s: _State) -> tuple[Any, Any]:
                al, ah = s.L[i], s.H[i]
                _flag(s, ah < 0)
                return A.powc(_fmax(al, 0.0), _fmax(ah, 0.0), c)
            return pos_pow

        def neg_pow(s: _State) -> tuple[Any, Any]:  # decreasing on (0, inf), inf at 0
            al, ah = s.L[i], s.H[i]
            _flag(s, ah <= 0)
            lo = _fmax(A.dnf(np.power(_fmax(ah, 0.0), c)), 0.0)
            return lo, A.upf(np.power(_fmax(al, 0.0), c))
        return neg_pow
    return None


# ----------------------------------------------------------------------- backward steps
def _backward_rule(op: int, o: int, ins: Sequence[int], cv: dict[int, float],
                   is_const: set[int]) -> _Step | None:
    """Projection of the constraint ``z = op(a, b)`` (z in slot ``o``) onto its operands.

    Constant operands are used but not narrowed. Returns None for operations without a
    projection rule.
    """
    if not ins:
        return None
    a = ins[0]
    b = ins[1] if len(ins) > 1 else -1
    na = a not in is_const  # narrow a?
    nb = b >= 0 and b not in is_const
    ca_, cb = cv.get(a), cv.get(b)

    if op == ca.OP_ASSIGN and na:
        return lambda s: _meet(s, a, s.L[o], s.H[o])
    if op == ca.OP_NEG and na:
        return lambda s: _meet(s, a, -s.H[o], -s.L[o])
    if op == ca.OP_TWICE and na:
        return lambda s: _meet(s, a, *A.mulc(s.L[o], s.H[o], 0.5))
    if op == ca.OP_INV and na:
        return lambda s: _factor(s, a, 1.0, 1.0, s.L[o], s.H[o])
    if op == ca.OP_ADD:  # a = z - b, b = z - a
        if na and nb:
            def add(s: _State) -> None:
                zl, zh = s.L[o], s.H[o]
                _meet(s, a, *A.sub(zl, zh, s.L[b], s.H[b]))
                _meet(s, b, *A.sub(zl, zh, s.L[a], s.H[a]))
            return add
        if na:
            if cb is not None:
                return lambda s: _meet(s, a, *A.addc(s.L[o], s.H[o], -cb))
            return lambda s: _meet(s, a, *A.sub(s.L[o], s.H[o], s.L[b], s.H[b]))
        if nb:
            if ca_ is not None:
                return lambda s: _meet(s, b, *A.addc(s.L[o], s.H[o], -ca_))
            return lambda s: _meet(s, b, *A.sub(s.L[o], s.H[o], s.L[a], s.H[a]))
        return None
    if op == ca.OP_SUB:  # a = z + b, b = a - z
        if na and nb:
            def sub(s: _State) -> None:
                zl, zh = s.L[o], s.H[o]
                _meet(s, a, *A.add(zl, zh, s.L[b], s.H[b]))
                _meet(s, b, *A.sub(s.L[a], s.H[a], zl, zh))
            return sub
        if na:
            if cb is not None:
                return lambda s: _meet(s, a, *A.addc(s.L[o], s.H[o], cb))
            return lambda s: _meet(s, a, *A.add(s.L[o], s.H[o], s.L[b], s.H[b]))
        if nb:
            if ca_ is not None:
                return lambda s: _meet(s, b, *A.csub(ca_, s.L[o], s.H[o]))
            return lambda s: _meet(s, b, *A.sub(s.L[a], s.H[a], s.L[o], s.H[o]))
        return None
    if op == ca.OP_MUL:  # a = z / b where b excludes 0 (arith.div is NaN otherwise)
        if na and nb:
            def mul(s: _State) -> None:
                zl, zh = s.L[o], s.H[o]
                _factor(s, a, zl, zh, s.L[b], s.H[b])
                _factor(s, b, zl, zh, s.L[a], s.H[a])
            return mul
        if na:
            if cb is not None:
                return lambda s: _meet(s, a, *A.divc(s.L[o], s.H[o], cb))
            return lambda s: _factor(s, a, s.L[o], s.H[o], s.L[b], s.H[b])
        if nb:
            if ca_ is not None:
                return lambda s: _meet(s, b, *A.divc(s.L[o], s.H[o], ca_))
            return lambda s: _factor(s, b, s.L[o], s.H[o], s.L[a], s.H[a])
        return None
    if op == ca.OP_DIV:  # a = z * b; b = a / z where z excludes 0 (b != 0 at solutions)
        if na and nb:
            def div(s: _State) -> None:
                zl, zh = s.L[o], s.H[o]
                _meet(s, a, *A.mul(zl, zh, s.L[b], s.H[b]))
                _factor(s, b, s.L[a], s.H[a], zl, zh)
            return div
        if na:
            if cb is not None:
                return lambda s: _meet(s, a, *A.mulc(s.L[o], s.H[o], cb))
            return lambda s: _meet(s, a, *A.mul(s.L[o], s.H[o], s.L[b], s.H[b]))
        if nb:
            if ca_ is not None:
                return lambda s: _factor(s, b, ca_, ca_, s.L[o], s.H[o])
            return lambda s: _factor(s, b, s.L[a], s.H[a], s.L[o], s.H[o])
        return None
    if op == ca.OP_SQ and na:  # a in ±sqrt(z ∩ [0, inf))
        def sq(s: _State) -> None:
            rl = _fmax(A.dnm(np.sqrt(_fmax(s.L[o], 0.0))), 0.0)
            rh = A.upm(np.sqrt(_fmax(s.H[o], 0.0)))
            _two_branch(s, a, rl, rh)
        return sq
    if op == ca.OP_FABS and na:  # a in ±(z ∩ [0, inf)), exact
        return lambda s: _two_branch(s, a, _fmax(s.L[o], 0.0), _fmax(s.H[o], 0.0))
    if op == ca.OP_SQRT and na:  # a = z^2, a >= 0
        def sqrt(s: _State) -> None:
            lo, hi = A.sq(_fmax(s.L[o], 0.0), _fmax(s.H[o], 0.0))
            _meet(s, a, _fmax(lo, 0.0), hi)
        return sqrt
    if op in _MONO_INVERSE and na:
        inv, clo, chi, dlo = _MONO_INVERSE[op]

        def mono(s: _State) -> None:
            lo = A.dnf(inv(np.clip(s.L[o], clo, chi)))
            hi = A.upf(inv(np.clip(s.H[o], clo, chi)))
            if dlo != -_INF:
                lo = _fmax(lo, dlo)
            _meet(s, a, lo, hi)
        return mono
    return None


# ---------------------------------------------------------------------------- contractor
class Contractor:
    """Batched forward-backward (HC4Revise) contractor for ``f(x) in Y``.

    Built by :func:`contractor`. Calling it contracts a batch of boxes.

    Attributes
    ----------
    fun : casadi.Function
        The SX Function, rebuilt with one work slot per graph node.
    n : int
        Number of elements of the input ``x``.
    m : int
        Number of elements of the output (column-major flattening).
    Y : ndarray, shape (m, 2)
        The target box.
    n_iter : int
        Default maximum number of forward-backward passes per call.
    rtol : float
        Default relative width reduction below which a box is considered stable.
    chunk : int
        Batches larger than this are processed in chunks of this many boxes (keeps the numpy
        temporaries in cache).
    """

    chunk: int = 8192

    def __init__(self, fun: ca.Function, Y: Any, *, n_iter: int = 1,
                 rtol: float = 0.01) -> None:
        fun = _as_sx_function(fun)
        if fun.n_in() != 1 or fun.n_out() != 1:
            raise DimensionError(
                f"contractor needs a Function with one input and one output; "
                f"'{fun.name()}' has {fun.n_in()} inputs and {fun.n_out()} outputs")
        syms = fun.sx_in()
        self.fun = ca.Function(fun.name(), syms, fun.call(syms), fun.name_in(),
                               fun.name_out(), {"live_variables": False})
        self.n = int(self.fun.numel_in(0))
        self.m = int(self.fun.numel_out(0))
        self.Y = _as_target(Y, self.m)
        self.n_iter, self.rtol = _check_iter(n_iter, rtol)
        self._build()

    # ------------------------------------------------------------------ construction
    def _build(self) -> None:
        g = self.fun
        nk = g.n_instructions()
        ids = [g.instruction_id(k) for k in range(nk)]
        ins = [[int(v) for v in g.instruction_input(k)] for k in range(nk)]
        outs = [[int(v) for v in g.instruction_output(k)] for k in range(nk)]
        sz = g.sz_w()

        cv: dict[int, float] = {}  # slot -> value of a CONST instruction
        is_const: set[int] = set()  # slots whose value does not depend on x
        for k in range(nk):
            op = ids[k]
            if op == ca.OP_CONST:
                cv[outs[k][0]] = float(g.instruction_constant(k))
                is_const.add(outs[k][0])
            elif op not in (ca.OP_INPUT, ca.OP_OUTPUT) and ins[k] \
                    and all(i in is_const for i in ins[k] if i >= 0):
                is_const.update(outs[k])

        # strict slots: an undefined value there makes some output undefined
        strict: set[int] = set()
        for k in range(nk - 1, -1, -1):
            op = ids[k]
            if op == ca.OP_OUTPUT:
                strict.add(ins[k][0])
                continue
            if op in (ca.OP_CONST, ca.OP_INPUT) or not outs[k] or outs[k][0] not in strict:
                continue
            if op in _STRICT:
                strict.update(i for i in ins[k] if i >= 0)
            elif op in (ca.OP_COPYSIGN,):
                strict.add(ins[k][0])
            elif op in (ca.OP_POW, ca.OP_CONSTPOW) and cv.get(ins[k][1], 0.0) != 0.0:
                strict.add(ins[k][0])

        L0: list[Any] = [_NAN] * sz
        H0: list[Any] = [_NAN] * sz
        fwd: list[_Step] = []
        bwd: list[_Step] = []
        self._outputs: list[tuple[int, int]] = []  # (slot, output element)
        pos = np.asarray(g.sparsity_out(0).find(), dtype=np.intp)
        for k in range(nk):
            op, i_k, o_k = ids[k], ins[k], outs[k]
            if op == ca.OP_CONST:
                L0[o_k[0]] = H0[o_k[0]] = cv[o_k[0]]
            elif op == ca.OP_INPUT:
                fwd.append(_input_step(o_k[0], i_k[1]))
                if o_k[0] in strict:
                    bwd.append(_input_back(o_k[0], i_k[1]))
            elif op == ca.OP_OUTPUT:
                self._outputs.append((i_k[0], int(pos[o_k[1]])))
            else:
                o = o_k[0] if o_k else -1
                fwd.append(self._forward_step(op, i_k, o_k, cv, strict))
                if o in strict and o not in is_const:
                    bwd.append(_check_then(o, _backward_rule(op, o, i_k, cv, is_const)))
        self._L0, self._H0 = L0, H0
        self._fwd = fwd
        self._bwd = bwd[::-1]
        # output elements that are structural zeros: f_e(x) = 0 for every x
        zeros = np.setdiff1d(np.arange(self.m), pos)
        self._always_empty = bool(np.any((self.Y[zeros, 0] > 0) | (self.Y[zeros, 1] < 0)))

    @staticmethod
    def _forward_step(op: int, i_k: Sequence[int], o_k: Sequence[int],
                      cv: dict[int, float], strict: set[int]) -> _Step:
        value = _forward_value(op, i_k, cv)
        if value is None:  # unknown operation: no information on its results
            res = [(o, (-_INF, _INF) if o in strict else (_NAN, _NAN)) for o in o_k]

            def unknown(s: _State) -> None:
                for o, (lo, hi) in res:
                    s.L[o], s.H[o] = lo, hi
            return unknown
        o = o_k[0]
        if o not in strict:
            def plain(s: _State) -> None:
                s.L[o], s.H[o] = value(s)
            return plain
        value = _strict_domain_value(op, i_k, cv) or value

        def real(s: _State) -> None:
            s.L[o], s.H[o] = _real(*value(s))
        return real

    # -------------------------------------------------------------------------- call
    def __call__(self, lo: Any, hi: Any, *, n_iter: int | None = None,
                 rtol: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Contract a batch of boxes.

        Parameters
        ----------
        lo, hi : array_like, shape (N, n)
            Lower and upper bounds of ``N`` boxes. Infinite bounds are allowed; NaN bounds
            are refused. A row with some ``lo > hi`` (or no real point) is reported empty.
        n_iter : int, optional
            Maximum number of forward-backward passes (default :attr:`n_iter`). After the
            first pass, only boxes whose width shrank by more than ``rtol`` (relative, in
            some coordinate) or that lost an infinite bound are contracted again.
        rtol : float, optional
            Relative width reduction that triggers another pass (default :attr:`rtol`).

        Returns
        -------
        lo2, hi2 : ndarray, shape (N, n)
            Contracted boxes, ``lo <= lo2 <= hi2 <= hi`` on every non-empty row. Every
            solution ``x ∈ [lo, hi]`` (``f(x)`` defined and in ``Y``) lies in
            ``[lo2, hi2]``. Rows flagged empty hold unspecified values.
        empty : ndarray of bool, shape (N,)
            True where the box provably holds no solution.
        """
        n_iter, rtol = _check_iter(self.n_iter if n_iter is None else n_iter,
                                   self.rtol if rtol is None else rtol)
        lo_a, hi_a = self._check_boxes(lo, hi)
        n_rows = lo_a.shape[0]
        empty = ((lo_a > hi_a) | (lo_a == _INF) | (hi_a == -_INF)).any(axis=1)
        if self._always_empty:
            empty[:] = True
        active = np.flatnonzero(~empty)
        if active.size == n_rows and n_rows:  # first pass on the whole batch: no gathering
            lo2, hi2, e1 = self._contract(lo_a, hi_a)
            l0, h0, l1, h1 = lo_a, hi_a, lo2, hi2
        else:
            lo2, hi2 = lo_a.copy(), hi_a.copy()
            if not active.size:
                return lo2, hi2, empty
            l0, h0 = lo2[active], hi2[active]
            l1, h1, e1 = self._contract(l0, h0)
            lo2[active], hi2[active] = l1, h1
        empty[active[e1]] = True
        for _ in range(n_iter - 1):
            w0, w1 = h0 - l0, h1 - l1
            shrunk = ((w1 < w0 * (1.0 - rtol)) | (np.isfinite(l1) & ~np.isfinite(l0))
                      | (np.isfinite(h1) & ~np.isfinite(h0))).any(axis=1)
            active = active[shrunk & ~e1]
            if not active.size:
                break
            l0, h0 = lo2[active], hi2[active]
            l1, h1, e1 = self._contract(l0, h0)
            lo2[active], hi2[active] = l1, h1
            empty[active[e1]] = True
        return lo2, hi2, empty

    def _check_boxes(self, lo: Any, hi: Any) -> tuple[np.ndarray, np.ndarray]:
        lo_a = np.asarray(lo, dtype=float)
        hi_a = np.asarray(hi, dtype=float)
        if lo_a.shape != hi_a.shape:
            raise DimensionError(
                f"lo and hi must have the same shape; got {lo_a.shape} and {hi_a.shape}")
        if lo_a.ndim != 2 or lo_a.shape[1] != self.n:
            raise DimensionError(
                f"boxes must have shape (N, {self.n}) for '{self.fun.name()}'; "
                f"got {lo_a.shape}")
        if np.isnan(lo_a).any() or np.isnan(hi_a).any():
            raise InvalidBoundsError("box bounds contain NaN")
        return lo_a, hi_a

    def _contract(self, lo: np.ndarray, hi: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One forward-backward pass on (N, n) boxes, in chunks of :attr:`chunk` rows."""
        n_rows = lo.shape[0]
        step = max(int(self.chunk), 1)
        if n_rows <= step:
            return self._pass(lo, hi)
        lo2, hi2 = np.empty_like(lo), np.empty_like(hi)
        emp = np.empty(n_rows, dtype=bool)
        for i in range(0, n_rows, step):
            j = min(i + step, n_rows)
            lo2[i:j], hi2[i:j], emp[i:j] = self._pass(lo[i:j], hi[i:j])
        return lo2, hi2, emp

    def _pass(self, lo: np.ndarray, hi: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n_rows = lo.shape[0]
        XL = list(np.ascontiguousarray(lo.T))
        XH = list(np.ascontiguousarray(hi.T))
        s = _State(list(self._L0), list(self._H0), XL, XH, np.zeros(n_rows, dtype=bool))
        ylo, yhi = self.Y[:, 0], self.Y[:, 1]
        with np.errstate(all="ignore"):
            for f in self._fwd:
                f(s)
            for slot, e in self._outputs:  # intersect the outputs with Y
                zl, zh = _fmax(s.L[slot], ylo[e]), _fmin(s.H[slot], yhi[e])
                _flag(s, zl > zh)
                if isinstance(zl, np.ndarray) and zl.ndim:  # constants are not narrowed
                    s.L[slot], s.H[slot] = zl, zh
            for b in self._bwd:
                b(s)
            for i in range(self.n):
                _flag(s, s.XL[i] > s.XH[i])
        if not self.n:
            return lo.copy(), hi.copy(), s.emp
        return np.stack(s.XL, axis=1), np.stack(s.XH, axis=1), s.emp

    def __repr__(self) -> str:
        return (f"Contractor('{self.fun.name()}', n={self.n}, m={self.m}, "
                f"n_iter={self.n_iter}, rtol={self.rtol})")


def _input_step(o: int, j: int) -> _Step:
    def inp(s: _State) -> None:
        s.L[o], s.H[o] = s.XL[j], s.XH[j]
    return inp


def _input_back(o: int, j: int) -> _Step:
    def inp(s: _State) -> None:
        s.XL[j] = _fmax(s.XL[j], s.L[o])
        s.XH[j] = _fmin(s.XH[j], s.H[o])
    return inp


def _check_then(o: int, rule: _Step | None) -> _Step:
    """Flag the rows where node ``o`` is empty, then project it onto its operands."""
    if rule is None:
        return lambda s: _flag(s, s.L[o] > s.H[o])

    def step(s: _State) -> None:
        _flag(s, s.L[o] > s.H[o])
        rule(s)
    return step


def _check_iter(n_iter: Any, rtol: Any) -> tuple[int, float]:
    if int(n_iter) != n_iter or int(n_iter) < 1:
        raise ValueError(f"n_iter must be a positive integer; got {n_iter!r}")
    rtol = float(rtol)
    if not 0.0 <= rtol < 1.0:
        raise ValueError(f"rtol must lie in [0, 1); got {rtol!r}")
    return int(n_iter), rtol


def _as_target(Y: Any, m: int) -> np.ndarray:
    """The target box as an (m, 2) float array."""
    if hasattr(Y, "lo") and hasattr(Y, "hi") and not isinstance(Y, np.ndarray):
        ylo = np.asarray(Y.lo, dtype=float).reshape(-1)
        yhi = np.asarray(Y.hi, dtype=float).reshape(-1)
        if ylo.shape != yhi.shape:
            raise DimensionError(
                f"Y.lo and Y.hi differ in length: {ylo.size} and {yhi.size}")
        arr = np.stack([ylo, yhi], axis=1)
    else:
        arr = np.asarray(Y, dtype=float)
    if arr.shape != (m, 2):
        raise DimensionError(
            f"Y has the wrong shape; expected ({m}, 2) (one [lo, hi] row per output element) "
            f"instead of {arr.shape}")
    if np.isnan(arr).any():
        raise InvalidBoundsError("Y contains NaN bounds")
    if (arr[:, 0] > arr[:, 1]).any():
        raise EmptySetError("Y is empty: some lower bound exceeds its upper bound")
    if (arr[:, 0] == _INF).any() or (arr[:, 1] == -_INF).any():
        raise InvalidBoundsError("Y has a row with no real point ([inf, inf] or [-inf, -inf])")
    return arr


def contractor(fun: ca.Function, Y: Any, *, n_iter: int = 1,
               rtol: float = 0.01) -> Contractor:
    """Build a forward-backward (HC4Revise) contractor for the constraint ``f(x) in Y``.

    Parameters
    ----------
    fun : casadi.Function
        SX Function (an MX Function is expanded) with one dense input ``x`` of ``n``
        elements and one output of ``m`` elements (column-major flattening; structural
        zeros count as the constant 0).
    Y : array_like, shape (m, 2), or Box
        Target box, ``Y[e] = [lo_e, hi_e]``; an object with ``.lo``/``.hi`` arrays (such as
        :class:`~casadi_cmpc.Box`) is accepted. Infinite bounds are allowed; the bounds are
        closed.
    n_iter : int, optional
        Default maximum number of forward-backward passes per call (default 1).
    rtol : float, optional
        Default relative width reduction that triggers another pass (default 0.01).

    Returns
    -------
    Contractor
        ``C(lo, hi) -> (lo2, hi2, empty)`` for boxes ``lo``, ``hi`` of shape ``(N, n)``.

    Raises
    ------
    DimensionError
        When ``fun`` has not exactly one input and one output, the input is sparse, or ``Y``
        does not have ``m`` rows of ``[lo, hi]``.
    InvalidBoundsError, EmptySetError
        When ``Y`` has NaN bounds, a row with ``lo > hi`` or no real point.

    Notes
    -----
    HC4Revise (Benhamou et al. 1999): a forward sweep of the natural interval extension over
    the box, intersection of the outputs with ``Y``, then a backward sweep of projections in
    reverse order. Projection rules exist for ``+``, ``-``, negation, doubling, ``*``, ``/``,
    ``1/x``, ``x^2``, ``|x|``, ``sqrt``, ``exp``, ``log``, ``expm1``, ``log1p``, ``sinh``,
    ``asinh``, ``tanh`` and assignment; other operations keep the forward enclosures of
    their operands. Quotients by an interval containing 0 (in the projections of ``*``, ``/``
    and ``1/x``) use the extended division, the two rays ``p / q`` for ``q < 0`` and
    ``q > 0``, whose hull is taken after intersecting each ray with the current enclosure;
    when the dividend contains 0 as well, nothing is narrowed. A variable occurring several
    times is narrowed by each occurrence separately and the results are intersected, so the
    result is not the hull of the solution set in general; further passes (``n_iter``) may
    narrow it more.
    See the module docstring for the treatment of undefined values.

    Examples
    --------
    >>> import casadi as ca, numpy as np
    >>> from casadi_cmpc.interval.contractor import contractor
    >>> x = ca.SX.sym("x", 2)
    >>> C = contractor(ca.Function("f", [x], [x[0] + x[1]]), [[3.0, 4.0]])
    >>> lo2, hi2, empty = C(np.array([[0.0, 0.0], [0.0, 0.0]]),
    ...                     np.array([[2.0, 2.0], [1.0, 1.0]]))
    >>> np.round(lo2[0], 12), np.round(hi2[0], 12)
    (array([1., 1.]), array([2., 2.]))
    >>> empty
    array([False,  True])
    """
    from ._derivative import ParamFunction

    if isinstance(fun, ParamFunction):
        return _ParamContractor(fun, Y, n_iter=n_iter, rtol=rtol)
    return Contractor(fun, Y, n_iter=n_iter, rtol=rtol)


class _ParamContractor:
    """Contractor of a :class:`~._derivative.ParamFunction` ``G(x, p)`` with exact literals.

    The parameters ``p`` become extra input columns, held at their (thin) values, or at an
    interval around a value that may be rounded (``ParamFunction.widen``); the contractor
    of ``[x; p] -> G(x, p)`` then never folds a literal, and only the ``x`` columns are
    returned. A ParamFunction whose own constants must be widened is refused.
    """

    def __init__(self, pf: Any, Y: Any, *, n_iter: int = 1, rtol: float = 0.01) -> None:
        from .compiler import _widen_constant

        g = pf.function
        if pf.n_in() != 1 or g.n_out() != 1:
            raise DimensionError(
                f"contractor needs a Function with one input and one output; "
                f"'{g.name()}' has {pf.n_in()} inputs and {g.n_out()} outputs")
        if pf.interval.any():
            # a validated ODE model's enclosure: the backward pass would also read the
            # guard of its validated domain as a constraint and drop states outside it,
            # about which the enclosure says nothing (they must stay undecided)
            raise UnsupportedOperationError(
                f"'{g.name()}' has interval-valued parameters (an enclosure such as a "
                "validated ODE model's remainder, valid on its domain only): the contractor "
                "cannot use it; use sivia without contract=True")
        own = [k for k in pf.derived if k not in pf.literals]
        if own:
            raise UnsupportedOperationError(
                f"'{g.name()}' holds constants created by CasADi's simplifications, which "
                "the contractor cannot widen; use sivia without contract=True")
        x = ca.SX.sym("x", g.sparsity_in(0).nnz())
        p = ca.SX.sym("p", g.nnz_in(1))
        out = g(ca.reshape(x, g.sparsity_in(0)) if g.sparsity_in(0).is_dense() else x, p)
        self._C = Contractor(ca.Function(g.name(), [ca.vertcat(x, p)], [out]), Y,
                             n_iter=n_iter, rtol=rtol)
        v = np.asarray(pf.values, dtype=float)
        lo, hi = v.copy(), v.copy()
        for i in np.flatnonzero(pf.widen):
            lo[i], hi[i] = _widen_constant(float(v[i]))
        self._plo, self._phi = lo, hi
        self.n = int(x.numel())
        self.m = self._C.m
        self.Y = self._C.Y

    def __call__(self, lo: Any, hi: Any, **kw: Any
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        lo = np.atleast_2d(np.asarray(lo, dtype=float))
        hi = np.atleast_2d(np.asarray(hi, dtype=float))
        N = lo.shape[0]
        L = np.hstack([lo, np.broadcast_to(self._plo, (N, self._plo.size))])
        H = np.hstack([hi, np.broadcast_to(self._phi, (N, self._phi.size))])
        l2, h2, empty = self._C(L, H, **kw)
        return l2[:, :self.n], h2[:, :self.n], empty
