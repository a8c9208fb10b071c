"""Modal (Kaucher) interval arithmetic and the semantic extension of CasADi functions.

Modal intervals (thesis §5.1)
-----------------------------
A modal interval is a pair of bounds ``[a, b]`` in which ``a > b`` is allowed. Batches are
float arrays of shape ``(..., 2)`` (``[..., 0]`` = ``Lb``, ``[..., 1]`` = ``Ub``), like the
classical interval arrays of :mod:`casadi_cmpc.interval.ops`, except that the lower bound may
exceed the upper one:

* ``a < b``: *proper*, ``Prop = [a, b]``, modality ∃ (thesis eq. (5.1));
* ``a > b``: *improper*, ``Prop = [b, a]``, modality ∀;
* ``a == b``: a *point*, both at once.

``dual([a, b]) = [b, a]`` changes the modality, ``prop`` returns the classical interval
``[min(a, b), max(a, b)]``. Inclusion (5.7) is ``[a, b] ⊆ [c, d] <=> a >= c and b <= d``
(:func:`modal_subset`); it makes the modal intervals a lattice with :func:`meet` (largest
common sub-interval) and :func:`join`.

Arithmetic and rounding
-----------------------
``kaucher_add``, ``kaucher_sub``, ``kaucher_mul``, ``kaucher_div`` and ``kaucher_neg`` implement
Kaucher's complete arithmetic, which coincides with the semantic extensions (5.11)/(5.12) of
``+ - * /`` (thesis §5.1.4). Every operation takes ``rounding="outer"`` (default) or
``"inner"``:

* ``"outer"``: the lower bound is rounded down and the upper bound up, ``Out`` of (5.8), so the
  exact Kaucher result ``R`` satisfies ``R ⊆ result`` (modal inclusion);
* ``"inner"``: the lower bound is rounded up and the upper bound down, ``Inn`` of (5.8), so
  ``result ⊆ R``. For a proper result this shrinks the interval (rounds its endpoints inward),
  for an improper one it widens ``Prop`` — in both cases the result stays an inner
  approximation in the modal sense, as (5.10) requires.

The margins are those of :mod:`casadi_cmpc.interval.arith` (at least one ulp; ``2**-1074``
more for products and quotients; 256 ulps for libm functions). Kaucher operations are
inclusion-isotone, so composing operations rounded the same way keeps the direction: an
expression evaluated with outer (inner) rounding everywhere contains (is contained in) the exact
Kaucher value.

A NaN bound means *no information*, as in :mod:`~casadi_cmpc.interval.arith` (division by an
interval whose ``Prop`` contains 0, a function outside its domain, ``0 * inf``). An outer
result without information is ``[-inf, inf]``, an inner one ``[inf, -inf]``; :func:`no_nan`
converts.

:func:`round_outer` / :func:`round_inner` are the roundings ``Out`` / ``Inn`` of (5.8) of given
bounds to a coarser scale (one ulp, or a number of decimal digits); ``round_inner = dual ∘
round_outer ∘ dual`` (5.9).

The modal structure, the roundings and the arithmetic are defined in
:mod:`casadi_cmpc.interval._kaucher` and exported from this module, which adds the semantic
extension below.

Semantic extension (thesis §5.1.3, §5.1.4)
------------------------------------------
For ``f : R^d -> R^p`` and a modal box ``X*`` with proper components ``x_p`` and improper
components ``x_i``, the semantic extension (5.11) of each output is

    f*(X*) = [ min_{x_p} max_{x_i} f(x_p, x_i),  max_{x_p} min_{x_i} f(x_p, x_i) ]

and, for a modal interval ``Z`` (5.13),

    f*(X*) ⊆ Z  <=>  ∀ x_p ∈ Prop(X_p)  Q(Z) z ∈ Prop(Z)  ∃ x_i ∈ Prop(X_i) : z = f(x_p, x_i).

So **proper components are universally and improper components existentially quantified**
when an outer approximation is included in a target: for ``Z = [a, b]`` proper,
``Outer(f*) ⊆ [a, b]`` proves ``∀x_p ∃x_i : f(x_p, x_i) ∈ [a, b]`` (for continuous ``f``).

:class:`SemanticExtension` computes, from a CasADi Function, an outer approximation
``Outer ⊇ f*(X*)`` and an inner approximation ``Inner ⊆ f*(X*)`` (both modal, possibly
improper) by the theorems stated in its Notes: monotonicity from the sign of the interval
Jacobian (sharp when ``f`` is monotone in every variable over the box, which includes the
totally monotone case of Gardeñes et al.), the modal mean-value extension, and the partition
bounds (5.15)/(5.16).

Examples
--------
>>> import numpy as np
>>> from casadi_cmpc.interval import modal
>>> X = np.array([1.0, 2.0]); Y = np.array([3.0, -1.0])          # Y improper
>>> modal.kaucher_add(X, modal.dual(modal.kaucher_neg(X))).tolist()   # X + Dual(-X)
[0.0, 0.0]
>>> np.round(modal.kaucher_mul(X, Y), 12).tolist()   # [min_x max_y xy, max_x min_y xy]
[3.0, -1.0]
>>> modal.mode(np.array([[1.0, 2.0], [3.0, -1.0], [2.0, 2.0]])).tolist()
[1, -1, 0]
>>> modal.round_inner(np.array([1.346, 1.347]), digits=2).tolist()
[1.35, 1.34]
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np

from .._bisect import bisect_widest
from .._validate import as_boxes
from ..exceptions import DimensionError, InvalidBoundsError, UnsupportedOperationError
from . import arith
from ._kaucher import *  # noqa: F403
from ._kaucher import __all__ as _kaucher_all
from ._kaucher import _kmul_centered, _pack
from .compiler import InclusionFunction, _as_sx_function, _discontinuous_ops, inclusion

__all__ = [*_kaucher_all, "SemanticExtension", "semantic_extension"]


# ===================================================================== semantic extension
def _mid(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        return np.clip(0.5 * lo + 0.5 * hi, lo, hi)


def _bisect_masked(Z: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """Bisect every box of Z (N, d, 2) along its widest allowed component -> (N, 2, d, 2).

    ``allowed`` (N, d) or (1, d) bool. A box without an allowed component of positive width
    is repeated (both halves equal).
    """
    lo, hi = Z[..., 0], Z[..., 1]
    w = np.where(allowed, hi - lo, -1.0)
    lo2, hi2, k, _ = bisect_widest(lo, hi, w)
    N = Z.shape[0]
    keep = np.flatnonzero(~(w[np.arange(N), k] > 0))
    hi2[keep] = hi[keep]
    lo2[keep + N] = lo[keep]
    left = np.stack([lo2[:N], hi2[:N]], axis=-1)
    right = np.stack([lo2[N:], hi2[N:]], axis=-1)
    return np.stack([left, right], axis=1)


def _partition(Z: np.ndarray, allowed: np.ndarray, depth: int) -> np.ndarray:
    """Cells of ``depth`` rounds of bisection of each box: (N, 2**depth, d, 2)."""
    N, d = Z.shape[0], Z.shape[1]
    cells = Z[:, None]
    for _ in range(int(depth)):
        k = cells.shape[1]
        flat = cells.reshape(N * k, d, 2)
        al = np.repeat(allowed, k, axis=0) if allowed.shape[0] == N else allowed
        cells = _bisect_masked(flat, al).reshape(N, 2 * k, d, 2)
    return cells


class SemanticExtension:
    """Inner and outer approximations of the semantic extension ``f*`` of a CasADi Function.

    Parameters
    ----------
    fun : casadi.Function
        An SX Function (an MX Function is expanded) with dense inputs and one output of ``p``
        elements (stack several outputs with ``casadi.vertcat``). It must be continuous: a
        Function with an operation through which it may jump (``floor``, comparisons,
        ``if_else``, ...) is refused.
    mean_value : bool
        Also use the modal mean-value extension and keep the sharper bound (default True).

    Attributes
    ----------
    F : InclusionFunction
        Natural inclusion of ``fun``.
    J : InclusionFunction
        Natural inclusion of CasADi's symbolic Jacobian of the output with respect to all
        inputs (stacked), constants created by differentiation widened.
    size_in : list of int
        Number of elements of each input.
    p : int
        Number of output elements.

    Notes
    -----
    Inputs are modal interval arrays, one per Function input, of shape ``(N, d_i, 2)``; a
    component with ``Lb > Ub`` is improper (existentially quantified in ``f* ⊆ Z``, see the
    module docstring), the others proper. Write ``X*`` for the joint modal box and ``Z`` for
    ``Prop X*``; ``J`` encloses the derivatives of ``f_j`` over ``Z``. For output ``j``,
    ``f_j*(X*) = [L, U]`` with ``L = min_{x_p} max_{x_i} f_j`` and
    ``U = max_{x_p} min_{x_i} f_j``. All functions below bound ``L`` and ``U`` with sound
    floating-point enclosures (outward rounding):

    **Theorem 1 (monotonicity; thesis (5.14) with χ* from the monotonicity of f).** Call a
    component ``k`` *increasing* if ``Lb J_jk >= 0`` and *decreasing* if ``Ub J_jk <= 0``; the
    others are *free*. Put a monotone component at the corner ``c_L = Lb(X*_k)`` (increasing)
    or ``Ub(X*_k)`` (decreasing) for the lower bound and at the opposite corner for the upper
    bound — the same rule for proper and improper components, which is what makes modal
    intervals convenient. Then

    * outer: ``L >= lb F_j(B_L)`` where ``B_L`` has the monotone components at ``c_L``, the
      free proper components equal to ``Prop`` and the free improper components at a point
      (the midpoint); ``U <= ub F_j(B_U)`` likewise;
    * inner: ``L <= ub F_j(B'_L)`` where ``B'_L`` has the monotone components at ``c_L``, the
      free proper components at a point and the free improper components equal to ``Prop``;
      ``U >= lb F_j(B'_U)`` likewise.

    Proof: ``max_{x_i} f >= f(x_p, e)`` for any point ``e``, and ``f`` increasing in a
    component over ``Z`` attains its minimum over that component at its lower end for any
    fixed other components (similarly for the other cases); ``min_{x_p}`` is at most the value
    at any point. When ``f_j`` is monotone in every component (in particular when it is
    totally monotone in each occurrence of each variable and the interval derivative shows
    it), ``B_L = B'_L`` is a point and the bounds are sharp up to rounding: inner and outer
    approximations coincide with ``f*``.

    **Theorem 2 (modal mean-value extension).** With ``x~`` the midpoint of ``Z`` and Kaucher
    arithmetic,

        K(X*) = f_j(x~) + sum_k J_jk * (X*_k - x~_k)

    satisfies ``f*(X*) ⊆ K(X*)`` and hence ``Dual(K(Dual X*)) ⊆ f*(X*)``. Proof: by the mean
    value theorem ``f(x) >= f(x~) + sum_k phi_k(x_k)`` with
    ``phi_k(t) = min_{g in J_jk} g (t - x~_k)``, a separable bound, so
    ``min_{x_p} max_{x_i} f >= f(x~) + sum_{proper} min phi_k + sum_{improper} max phi_k``,
    and ``min phi_k`` over a proper component (``max phi_k`` over an improper one) is the lower
    bound of the Kaucher product ``J_jk * (X*_k - x~_k)`` (checked entry by entry of the
    multiplication table: e.g. for ``J`` proper containing 0 and an improper component the
    product is ``[0, 0]`` and ``max phi_k = phi_k(x~_k) = 0``). The upper bound is symmetric.
    The same separable bound gives ``f**(X*) ⊆ K(X*)`` (5.12); since
    ``f*(X*) = Dual(f**(Dual X*))`` and ``Dual`` reverses inclusion, the inner statement
    follows. The bounds of Theorems 1 and 2 are combined with :func:`meet` (outer) and
    :func:`join` (inner).

    **Theorem 3 (partitions, thesis (5.15)/(5.16)).** Let ``{A_j}`` partition the proper part
    and ``{E_k}`` the improper part. Then ``L >= min_j max_k L'_jk`` for any outer lower bounds
    ``L'_jk`` of ``f*(A_j, E_k)``, and ``L <= min_j max_k L''_jk`` for inner bounds
    ``L''_jk >= max_{E_k} f(a_j, .)`` computed with a point ``a_j`` of ``A_j`` *shared by all
    k*; symmetrically for ``U``. :meth:`bounds` with ``splits`` implements this, choosing
    ``a_j`` by the monotonicity rule of Theorem 1 over ``A_j x E``.

    Continuity of ``f`` (assumed) makes ``f*`` well defined and gives (5.13); the Jacobian
    hypothesis is that of the centered form (``J`` encloses the derivatives, or the Clarke
    gradients of a piecewise smooth ``f``, over ``Z``).

    Examples
    --------
    >>> import casadi as ca, numpy as np
    >>> from casadi_cmpc.interval.modal import SemanticExtension, dual
    >>> x = ca.SX.sym("x"); u = ca.SX.sym("u")
    >>> ext = SemanticExtension(ca.Function("f", [x, u], [x + u]))
    >>> X = np.array([[[0.0, 1.0]]]); U = dual(np.array([[[0.0, 2.0]]]))   # ∀x ∃u
    >>> outer = ext.outer(X, U)[0, 0]; inner = ext.inner(X, U)[0, 0]
    >>> bool(outer[0] <= 2.0 <= inner[0] and inner[1] <= 1.0 <= outer[1])   # f* = [2, 1]
    True
    """

    def __init__(self, fun: ca.Function, *, mean_value: bool = True) -> None:
        fun = _as_sx_function(fun)
        if fun.n_out() != 1:
            raise DimensionError(
                f"SemanticExtension needs a Function with one output; '{fun.name()}' has "
                f"{fun.n_out()} (stack them with casadi.vertcat)")
        bad = _discontinuous_ops(fun)
        if bad:
            raise UnsupportedOperationError(
                f"'{fun.name()}' contains operations through which it may jump "
                f"({', '.join(bad)}); the semantic extension f* and its approximations assume "
                "a continuous function")
        self.fun = fun
        self.mean_value = bool(mean_value)
        self.F = inclusion(fun, "natural")
        self.size_in = list(self.F.size_in)
        self.d = int(sum(self.size_in))
        self.p = int(self.F.size_out[0])
        self._cuts = np.cumsum([0] + self.size_in)
        syms = [ca.SX.sym(f"z{i}", fun.sparsity_in(i)) for i in range(fun.n_in())]
        y = ca.vec(fun.call(syms)[0])
        z = ca.vertcat(*[ca.vec(s) for s in syms]) if syms else ca.SX(0, 1)
        jac = ca.densify(ca.jacobian(y, z))
        g = ca.Function(f"{fun.name()}_jac", syms, [jac, y], {"live_variables": False})
        self.J = InclusionFunction(g, "natural", derived_outputs=(0,), evaluate=(0,))

    # ------------------------------------------------------------------ raw (for solvers)
    def _split(self, Z: np.ndarray) -> list[np.ndarray]:
        c = self._cuts
        return [Z[:, c[i]:c[i + 1]] for i in range(len(self.size_in))]

    def evaluate_unchecked(self, Z: np.ndarray) -> np.ndarray:
        """Classical natural enclosure of ``f`` over joint proper boxes (no checks).

        Parameters
        ----------
        Z : ndarray, shape (N, d, 2)
            All inputs stacked (column-major within each input).

        Returns
        -------
        ndarray, shape (N, p, 2)
        """
        n = Z.shape[0]
        if n == 0:
            return np.zeros((0, self.p, 2))
        return self.F.evaluate_unchecked(self._split(Z), n)[0]

    def jacobian_unchecked(self, Z: np.ndarray) -> np.ndarray:
        """Interval Jacobian of the output over joint proper boxes (no checks).

        Parameters
        ----------
        Z : ndarray, shape (N, d, 2)

        Returns
        -------
        ndarray, shape (N, p, d, 2)
            ``[i, j, k]`` encloses ``d f_j / d z_k`` over box ``i``.
        """
        n = Z.shape[0]
        if n == 0:
            return np.zeros((0, self.p, self.d, 2))
        out = self.J.evaluate_unchecked(self._split(Z), n)[0]  # (N, p*d, 2), column-major
        return out.reshape(n, self.d, self.p, 2).transpose(0, 2, 1, 3)

    def bounds_unchecked(self, Z: np.ndarray, improper: np.ndarray,
                         J: np.ndarray | None = None, *, outer: bool = True,
                         inner: bool = True) -> dict[str, np.ndarray]:
        """Theorems 1 and 2 on joint boxes, without checks (for solvers).

        Parameters
        ----------
        Z : ndarray, shape (N, d, 2)
            ``Prop`` of the modal boxes (``lo <= hi``).
        improper : ndarray of bool, shape (N, d) or (d,)
            True for the improper (existentially quantified) components.
        J : ndarray, shape (N, p, d, 2), optional
            An enclosure of the Jacobian over a box containing Z (computed when omitted).
        outer, inner : bool
            Which approximations to compute.

        Returns
        -------
        dict
            ``"outer_lo"``, ``"outer_hi"`` (outer ``[L', U']``: ``L' <= L``, ``U' >= U``) and
            ``"inner_lo"``, ``"inner_hi"`` (inner ``[L'', U'']``: ``L'' >= L``,
            ``U'' <= U``), each of shape (N, p). Bounds without information are
            ``-inf``/``+inf`` (outer) and ``+inf``/``-inf`` (inner).
        """
        N, d, p = Z.shape[0], self.d, self.p
        res: dict[str, np.ndarray] = {}
        if N == 0:
            for k in ("outer_lo", "outer_hi", "inner_lo", "inner_hi"):
                res[k] = np.zeros((0, p))
            return res
        if J is None:
            J = self.jacobian_unchecked(Z)
        imp = np.broadcast_to(np.asarray(improper, dtype=bool), (N, d))[:, None, :]
        lo = Z[:, None, :, 0]
        hi = Z[:, None, :, 1]
        mid = _mid(lo, hi)
        inc = J[..., 0] >= 0  # (N, p, d)
        dec = (J[..., 1] <= 0) & ~inc
        mono = inc | dec
        lb = np.where(imp, hi, lo)  # modal lower bound Lb(X*_k)
        ub = np.where(imp, lo, hi)
        c_lo = np.where(inc, lb, ub)  # corner of the lower end of f*
        c_hi = np.where(inc, ub, lb)
        kinds = []
        boxes = []
        if outer:
            # free proper components: the whole Prop; free improper components: a point
            flo = np.where(imp, mid, lo)
            fhi = np.where(imp, mid, hi)
            for corner in (c_lo, c_hi):
                boxes.append(np.stack([np.where(mono, corner, flo),
                                       np.where(mono, corner, fhi)], axis=-1))
            kinds += ["outer_lo", "outer_hi"]
        if inner:
            # free proper components: a point; free improper components: the whole Prop
            flo = np.where(imp, lo, mid)
            fhi = np.where(imp, hi, mid)
            for corner in (c_lo, c_hi):
                boxes.append(np.stack([np.where(mono, corner, flo),
                                       np.where(mono, corner, fhi)], axis=-1))
            kinds += ["inner_lo", "inner_hi"]
        T = len(boxes)
        B = np.stack(boxes).reshape(T * N * p, d, 2)  # (T, N, p, d, 2) flattened
        R = self.evaluate_unchecked(B).reshape(T, N, p, p, 2)
        idx = np.arange(p)
        R = R[:, :, idx, idx, :]  # (T, N, p, 2): output j of the box built for output j
        # outer lower bound: lower end; outer upper: upper end; inner lower: upper end of the
        # enclosure of max over the free improper part; inner upper: lower end
        end = {"outer_lo": 0, "outer_hi": 1, "inner_lo": 1, "inner_hi": 0}
        for t, k in enumerate(kinds):
            res[k] = R[t, ..., end[k]]
        if self.mean_value:
            # where f is monotone in every component the corner bounds are already sharp
            rows = np.flatnonzero(~mono.all(axis=(1, 2)))
            if rows.size:
                sub = {k: v[rows] for k, v in res.items()}
                self._mean_value(Z[rows], np.broadcast_to(imp[:, 0, :], (N, d))[rows],
                                 J[rows], mid[rows, 0, :], sub, outer, inner)
                for k, v in sub.items():
                    res[k] = res[k].copy()
                    res[k][rows] = v
        return res

    def _mean_value(self, Z: np.ndarray, imp: np.ndarray, J: np.ndarray, xm: np.ndarray,
                    res: dict[str, np.ndarray], outer: bool, inner: bool) -> None:
        """Theorem 2, combined into ``res`` (meet for outer, join for inner)."""
        fm = self.evaluate_unchecked(np.stack([xm, xm], axis=-1))  # (N, p, 2)
        lo, hi = Z[..., 0], Z[..., 1]
        lb = np.where(imp, hi, lo)
        ub = np.where(imp, lo, hi)
        point = (lo == hi)[:, None, :]  # (N, 1, d): contributes exactly 0
        Jl, Jh = J[..., 0], J[..., 1]

        def K(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            # X*_k - x~_k with outward rounding, then the Kaucher products and the sum
            with np.errstate(all="ignore"):
                dl = arith.dn(a - xm)[:, None, :]
                dh = arith.up(b - xm)[:, None, :]
                tl, th = _kmul_centered(Jl, Jh, dl, dh)
                tl = np.where(point, 0.0, tl)
                th = np.where(point, 0.0, th)
                kl, kh = fm[..., 0], fm[..., 1]
                for k in range(self.d):
                    kl = arith.dn(kl + tl[..., k])
                    kh = arith.up(kh + th[..., k])
            return kl, kh

        if outer:
            kl, kh = K(lb, ub)
            kl = np.where(np.isnan(kl), -np.inf, kl)
            kh = np.where(np.isnan(kh), np.inf, kh)
            res["outer_lo"] = np.maximum(res["outer_lo"], kl)
            res["outer_hi"] = np.minimum(res["outer_hi"], kh)
        if inner:
            kl, kh = K(ub, lb)  # K(Dual X*); Inner = Dual(K(Dual X*))
            il = np.where(np.isnan(kh), np.inf, kh)
            ih = np.where(np.isnan(kl), -np.inf, kl)
            res["inner_lo"] = np.minimum(res["inner_lo"], il)
            res["inner_hi"] = np.maximum(res["inner_hi"], ih)

    # ------------------------------------------------------------------------- public
    def _modal_inputs(self, args: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
        if len(args) != len(self.size_in):
            raise TypeError(f"'{self.fun.name()}' takes {len(self.size_in)} modal box "
                            f"arguments, got {len(args)}")
        arrs = [as_boxes(a, self.size_in[i], name=self.fun.name_in(i), allow_empty=True)
                for i, a in enumerate(args)]
        ns = {a.shape[0] for a in arrs}
        n = max(ns) if ns else 1
        if len(ns - {1, n}) > 0:
            raise DimensionError(f"batch sizes of the inputs do not broadcast: "
                                 f"{[a.shape[0] for a in arrs]}")
        arrs = [np.broadcast_to(a, (n,) + a.shape[1:]) for a in arrs]
        M = np.concatenate(arrs, axis=1) if arrs else np.zeros((n, 0, 2))
        imp = M[..., 0] > M[..., 1]
        Z = np.stack([np.minimum(M[..., 0], M[..., 1]), np.maximum(M[..., 0], M[..., 1])],
                     axis=-1)
        if not np.isfinite(Z).all():
            raise InvalidBoundsError("the modal boxes must have finite bounds")
        return Z, imp

    def bounds(self, *args: Any, splits: tuple[int, int] = (0, 0)
               ) -> tuple[np.ndarray, np.ndarray]:
        """Inner and outer approximations of ``f*(X*)``.

        Parameters
        ----------
        *args : array_like, shape (N, d_i, 2) or (d_i, 2)
            One modal box per input of the Function (``Lb > Ub``: improper component).
        splits : (int, int)
            Rounds of bisection of the proper part and of the improper part of each modal box
            (``2**splits[0]`` times ``2**splits[1]`` cells), Theorem 3 = thesis (5.15)/(5.16).

        Returns
        -------
        inner, outer : ndarray, shape (N, p, 2)
            Modal intervals with ``inner ⊆ f*(X*) ⊆ outer`` for every output.
        """
        Z, imp = self._modal_inputs(args)
        kp, ki = (int(s) for s in splits)
        if kp < 0 or ki < 0:
            raise ValueError(f"splits must be non-negative; got {splits}")
        with np.errstate(all="ignore"):
            if kp == 0 and ki == 0:
                r = self.bounds_unchecked(Z, imp)
                return (_pack(r["inner_lo"], r["inner_hi"]),
                        _pack(r["outer_lo"], r["outer_hi"]))
            return self._partitioned(Z, imp, kp, ki)

    def _partitioned(self, Z: np.ndarray, imp: np.ndarray, kp: int, ki: int
                     ) -> tuple[np.ndarray, np.ndarray]:
        N, d, p = Z.shape[0], self.d, self.p
        A = _partition(Z, ~imp, kp)  # (N, cp, d, 2): cells of the proper part
        cp = A.shape[1]
        Af = A.reshape(N * cp, d, 2)
        imp_a = np.repeat(imp, cp, axis=0)
        E = _partition(Af, imp_a, ki)  # (N*cp, ci, d, 2)
        ci = E.shape[1]
        Ef = E.reshape(N * cp * ci, d, 2)
        imp_e = np.repeat(imp_a, ci, axis=0)
        r = self.bounds_unchecked(Ef, imp_e, inner=False)
        olo = r["outer_lo"].reshape(N, cp, ci, p).max(axis=2).min(axis=1)
        ohi = r["outer_hi"].reshape(N, cp, ci, p).min(axis=2).max(axis=1)
        # inner: one point of each proper cell, shared by all improper cells (Theorem 3)
        JA = self.jacobian_unchecked(Af)  # over A_j x (whole improper part)
        lo, hi = Af[..., 0], Af[..., 1]
        mid = _mid(lo, hi)
        ilo = np.empty((N, p))
        ihi = np.empty((N, p))
        for j in range(p):
            inc = JA[:, j, :, 0] >= 0
            dec = (JA[:, j, :, 1] <= 0) & ~inc
            for key, pt in (("inner_lo", np.where(inc, lo, np.where(dec, hi, mid))),
                            ("inner_hi", np.where(inc, hi, np.where(dec, lo, mid)))):
                pt_e = np.repeat(pt, ci, axis=0)  # (N*cp*ci, d)
                Zp = Ef.copy()
                Zp[..., 0] = np.where(imp_e, Ef[..., 0], pt_e)
                Zp[..., 1] = np.where(imp_e, Ef[..., 1], pt_e)
                b = self.bounds_unchecked(Zp, imp_e, outer=False)[key][:, j]
                b = b.reshape(N, cp, ci)
                if key == "inner_lo":
                    ilo[:, j] = b.max(axis=2).min(axis=1)
                else:
                    ihi[:, j] = b.min(axis=2).max(axis=1)
        return _pack(ilo, ihi), _pack(olo, ohi)

    def outer(self, *args: Any, splits: tuple[int, int] = (0, 0)) -> np.ndarray:
        """Outer approximation ``Outer ⊇ f*(X*)`` (thesis (5.16)); see :meth:`bounds`.

        Parameters
        ----------
        *args : array_like, shape (N, d_i, 2) or (d_i, 2)
            One modal box per input.
        splits : (int, int)
            Bisection rounds of the proper and the improper part.

        Returns
        -------
        ndarray, shape (N, p, 2)
        """
        return self.bounds(*args, splits=splits)[1]

    def inner(self, *args: Any, splits: tuple[int, int] = (0, 0)) -> np.ndarray:
        """Inner approximation ``Inner ⊆ f*(X*)`` (thesis (5.15)); see :meth:`bounds`.

        Parameters
        ----------
        *args : array_like, shape (N, d_i, 2) or (d_i, 2)
            One modal box per input.
        splits : (int, int)
            Bisection rounds of the proper and the improper part.

        Returns
        -------
        ndarray, shape (N, p, 2)
        """
        return self.bounds(*args, splits=splits)[0]

    def __repr__(self) -> str:
        return (f"SemanticExtension('{self.fun.name()}', inputs={self.size_in}, "
                f"outputs={self.p}, mean_value={self.mean_value})")


def semantic_extension(fun: ca.Function, *, mean_value: bool = True) -> SemanticExtension:
    """Build the :class:`SemanticExtension` of a CasADi Function.

    Parameters
    ----------
    fun : casadi.Function
        Continuous SX Function with one (dense) output.
    mean_value : bool
        Combine the monotonicity bounds with the modal mean-value extension.

    Returns
    -------
    SemanticExtension
    """
    return SemanticExtension(fun, mean_value=mean_value)
