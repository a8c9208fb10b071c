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

from collections.abc import Callable, Sequence
from typing import Any

import casadi as ca
import numpy as np

from .._validate import as_boxes
from ..exceptions import DimensionError, InvalidBoundsError, UnsupportedOperationError
from . import arith
from .compiler import InclusionFunction, _as_sx_function, _discontinuous_ops, inclusion

__all__ = [
    "PROPER", "IMPROPER", "POINT",
    "dual", "prop", "mode", "is_proper", "is_improper", "modal_subset", "meet", "join",
    "no_nan", "round_outer", "round_inner",
    "kaucher_add", "kaucher_sub", "kaucher_neg", "kaucher_mul", "kaucher_div",
    "kaucher_inv", "kaucher_sq", "kaucher_fabs", "kaucher_powi", "kaucher_monotone",
    "MONOTONE_FUNCTIONS",
    "SemanticExtension", "semantic_extension",
]

PROPER = 1
IMPROPER = -1
POINT = 0

_ROUNDINGS = ("outer", "inner")


# =============================================================================== helpers
def _arr(X: Any, name: str = "X") -> np.ndarray:
    a = np.asarray(X, dtype=float)
    if a.ndim == 0 or a.shape[-1] != 2:
        raise DimensionError(f"{name} must be a modal interval array of shape (..., 2); "
                             f"got shape {a.shape}")
    return a


def _check_rounding(rounding: str) -> str:
    r = str(rounding).lower()
    if r not in _ROUNDINGS:
        raise ValueError(f"unknown rounding '{rounding}'; valid roundings: outer, inner")
    return r


def _pack(lo: Any, hi: Any) -> np.ndarray:
    return np.stack(np.broadcast_arrays(lo, hi), axis=-1)


# (round down, round up) per error model of arith
_RND = {
    "add": (arith.dn, arith.up),
    "mul": (arith.dnm, arith.upm),
    "libm": (arith.dnf, arith.upf),
}


def _round(lo: Any, hi: Any, rounding: str, kind: str) -> tuple[Any, Any]:
    """Directed rounding of a computed (lo, hi): Out rounds lo down / hi up, Inn the reverse."""
    down, upw = _RND[kind]
    with np.errstate(all="ignore"):
        if rounding == "outer":
            return down(lo), upw(hi)
        return upw(lo), down(hi)


# ======================================================================= modal structure
def dual(X: Any) -> np.ndarray:
    """Dual of modal intervals: ``Dual([a, b]) = [b, a]`` (changes the modality).

    Parameters
    ----------
    X : array_like, shape (..., 2)

    Returns
    -------
    ndarray, shape (..., 2)
    """
    a = _arr(X)
    return a[..., ::-1].copy()


def prop(X: Any) -> np.ndarray:
    """Proper projection ``Prop([a, b]) = [min(a, b), max(a, b)]`` (thesis eq. (5.1)).

    Parameters
    ----------
    X : array_like, shape (..., 2)

    Returns
    -------
    ndarray, shape (..., 2)
        Classical intervals.
    """
    a = _arr(X)
    return _pack(np.minimum(a[..., 0], a[..., 1]), np.maximum(a[..., 0], a[..., 1]))


def mode(X: Any) -> np.ndarray:
    """Modality of each modal interval: ``PROPER`` (1), ``IMPROPER`` (-1) or ``POINT`` (0).

    Parameters
    ----------
    X : array_like, shape (..., 2)
        NaN bounds are refused.

    Returns
    -------
    ndarray of int8, shape (...)
    """
    a = _arr(X)
    if np.isnan(a).any():
        raise InvalidBoundsError("mode: the modal intervals contain NaN bounds")
    return np.sign(a[..., 1] - a[..., 0]).astype(np.int8)


def is_proper(X: Any) -> np.ndarray:
    """True where ``Lb <= Ub`` (proper intervals and points).

    Parameters
    ----------
    X : array_like, shape (..., 2)

    Returns
    -------
    ndarray of bool, shape (...)
    """
    a = _arr(X)
    return a[..., 0] <= a[..., 1]


def is_improper(X: Any) -> np.ndarray:
    """True where ``Lb >= Ub`` (improper intervals and points).

    Parameters
    ----------
    X : array_like, shape (..., 2)

    Returns
    -------
    ndarray of bool, shape (...)
    """
    a = _arr(X)
    return a[..., 0] >= a[..., 1]


def modal_subset(X: Any, Y: Any) -> np.ndarray:
    """Modal inclusion ``X ⊆ Y`` componentwise, thesis eq. (5.7): ``Lb X >= Lb Y`` and
    ``Ub X <= Ub Y``.

    Parameters
    ----------
    X, Y : array_like, shape (..., 2)
        Broadcast against each other.

    Returns
    -------
    ndarray of bool, shape (...)
        False where a bound is NaN.
    """
    a, b = _arr(X, "X"), _arr(Y, "Y")
    return (a[..., 0] >= b[..., 0]) & (a[..., 1] <= b[..., 1])


def meet(X: Any, Y: Any) -> np.ndarray:
    """Largest modal interval included in both: ``[max(Lb), min(Ub)]``.

    Parameters
    ----------
    X, Y : array_like, shape (..., 2)

    Returns
    -------
    ndarray, shape (..., 2)
        Never empty (improper when ``Prop X`` and ``Prop Y`` are disjoint). The meet of two
        outer approximations of one modal interval is an outer approximation.
    """
    a, b = _arr(X, "X"), _arr(Y, "Y")
    return _pack(np.maximum(a[..., 0], b[..., 0]), np.minimum(a[..., 1], b[..., 1]))


def join(X: Any, Y: Any) -> np.ndarray:
    """Smallest modal interval including both: ``[min(Lb), max(Ub)]``.

    Parameters
    ----------
    X, Y : array_like, shape (..., 2)

    Returns
    -------
    ndarray, shape (..., 2)
        The join of two inner approximations of one modal interval is an inner approximation.
    """
    a, b = _arr(X, "X"), _arr(Y, "Y")
    return _pack(np.minimum(a[..., 0], b[..., 0]), np.maximum(a[..., 1], b[..., 1]))


def no_nan(X: Any, rounding: str = "outer") -> np.ndarray:
    """Replace NaN bounds ("no information") by the information-free bound of the direction.

    Parameters
    ----------
    X : array_like, shape (..., 2)
    rounding : {"outer", "inner"}
        ``"outer"``: NaN lower bounds become ``-inf`` and NaN upper bounds ``+inf`` (an outer
        approximation contains ``f*``, so it may only grow); ``"inner"``: ``+inf`` and
        ``-inf`` (``[inf, -inf]`` is included in every modal interval).

    Returns
    -------
    ndarray, shape (..., 2)
    """
    r = _check_rounding(rounding)
    a = np.array(_arr(X), dtype=float)
    s = -1.0 if r == "outer" else 1.0
    lo, hi = a[..., 0], a[..., 1]
    lo[np.isnan(lo)] = s * np.inf
    hi[np.isnan(hi)] = -s * np.inf
    return a


# ------------------------------------------------------------------------------ roundings
def _left(x: np.ndarray, digits: int | None) -> np.ndarray:
    """A float ``<= x`` (exactly): one ulp below, or x rounded down to ``digits`` decimals."""
    with np.errstate(all="ignore"):
        if digits is None:
            return np.where(np.isfinite(x), np.nextafter(x, -np.inf), x)
        s = 10.0 ** int(digits)
        y = np.floor(x * s) / s
        y = np.where(np.isfinite(x) & np.isfinite(y), y, x)
        for _ in range(4):  # the scaling rounds: step down until y <= x holds exactly
            bad = y > x
            if not bad.any():
                break
            y = np.where(bad, np.nextafter(y, -np.inf), y)
        return y


def round_outer(X: Any, digits: int | None = None) -> np.ndarray:
    """Outer rounding ``Out([a, b]) = [Left(a), Right(b)]``, thesis eq. (5.8).

    Parameters
    ----------
    X : array_like, shape (..., 2)
        Modal intervals (proper or improper).
    digits : int, optional
        Scale of the rounding: ``None`` moves each bound by one ulp; an integer rounds to that
        many decimal digits (``Left(x) <= x <= Right(x)`` holds exactly, the result is on the
        decimal grid up to the float nearest to it).

    Returns
    -------
    ndarray, shape (..., 2)
        ``X ⊆ round_outer(X)`` (modal inclusion, (5.10)). Infinite and NaN bounds are kept.
    """
    a = _arr(X)
    lo = _left(a[..., 0], digits)
    hi = -_left(-a[..., 1], digits)
    return _pack(lo, hi)


def round_inner(X: Any, digits: int | None = None) -> np.ndarray:
    """Inner rounding ``Inn([a, b]) = [Right(a), Left(b)] = Dual(Out(Dual([a, b])))``,
    thesis eqs. (5.8), (5.9).

    Parameters
    ----------
    X : array_like, shape (..., 2)
    digits : int, optional
        As in :func:`round_outer`.

    Returns
    -------
    ndarray, shape (..., 2)
        ``round_inner(X) ⊆ X``; a proper interval narrower than the scale becomes improper
        (``Inn([1.346, 1.347]) = [1.35, 1.34]`` at two digits), which is still a modal
        interval, as (5.10) requires.

    Examples
    --------
    >>> import numpy as np
    >>> from casadi_cmpc.interval.modal import round_inner, round_outer
    >>> round_outer(np.array([1.346, 1.347]), digits=2).tolist()
    [1.34, 1.35]
    """
    return dual(round_outer(dual(X), digits))


# ===================================================================== Kaucher arithmetic
def _kadd(al, ah, bl, bh, r):
    with np.errstate(all="ignore"):
        return _round(al + bl, ah + bh, r, "add")


def _ksub(al, ah, bl, bh, r):
    with np.errstate(all="ignore"):
        return _round(al - bh, ah - bl, r, "add")


def _classes(a, b):
    """Kaucher sign class codes: 0 = P (both >= 0), 1 = Z (a < 0 < b, proper with 0 inside),
    2 = N (both <= 0, not P), 3 = D (a > 0 > b, improper with 0 inside Prop), 4 = NaN."""
    P = (a >= 0) & (b >= 0)
    Z = (a < 0) & (b > 0)
    N = (a <= 0) & (b <= 0) & ~P
    D = (a > 0) & (b < 0)
    none = ~(P | Z | N | D)
    return Z.astype(np.intp) + 2 * N + 3 * D + 4 * none


# candidates: 0 ac, 1 ad, 2 bc, 3 bd, 4 min(ad, bc), 5 max(ac, bd), 6 zero, 7 NaN;
# rows: class of X (P, Z, N, D, NaN), columns: class of Y
_MUL_LO = np.array([[0, 2, 2, 0, 7],
                    [1, 4, 2, 6, 7],
                    [1, 1, 3, 3, 7],
                    [0, 6, 3, 5, 7],
                    [7, 7, 7, 7, 7]], dtype=np.intp).ravel()
_MUL_HI = np.array([[3, 3, 1, 1, 7],
                    [3, 5, 0, 6, 7],
                    [2, 0, 0, 2, 7],
                    [2, 6, 1, 4, 7],
                    [7, 7, 7, 7, 7]], dtype=np.intp).ravel()


def _kmul_exact(al, ah, bl, bh):
    """Kaucher product in floating point (each entry one rounded product), no directed rounding.

    The table (Kaucher 1980) for X = [a, b], Y = [c, d]:

    ====== ================ ============ ================ =================
    X \\ Y  P                Z            N                D
    ====== ================ ============ ================ =================
    P      [ac, bd]         [bc, bd]     [bc, ad]         [ac, ad]
    Z      [ad, bd]         [min(ad,bc), [bc, ac]         [0, 0]
                            max(ac,bd)]
    N      [ad, bc]         [ad, ac]     [bd, ac]         [bd, bc]
    D      [ac, bc]         [0, 0]       [bd, ad]         [max(ac,bd),
                                                          min(ad,bc)]
    ====== ================ ============ ================ =================
    """
    with np.errstate(all="ignore"):
        al, ah, bl, bh = np.broadcast_arrays(al, ah, bl, bh)
        ac, ad, bc, bd = al * bl, al * bh, ah * bl, ah * bh
        cand = np.stack([ac, ad, bc, bd, np.minimum(ad, bc), np.maximum(ac, bd),
                         np.zeros(ac.shape), np.full(ac.shape, np.nan)])
        code = _classes(al, ah) * 5 + _classes(bl, bh)
        lo = np.take_along_axis(cand, _MUL_LO[code][None], axis=0)[0]
        hi = np.take_along_axis(cand, _MUL_HI[code][None], axis=0)[0]
    return lo, hi


def _kmul_centered(gl, gh, dl, dh):
    """Outer-rounded Kaucher product ``[gl, gh] * [dl, dh]`` for a proper ``[gl, gh]`` and a
    ``[dl, dh]`` whose Prop contains 0 (a centered difference ``X*_k - x~_k``).

    For these classes the table reduces to: ``D`` proper, the classical product; ``D``
    improper, ``[max(gl dl, gh dh, 0), min(gh dl, gl dh, 0)]``. Fewer operations than
    :func:`_kmul_exact`, same values.
    """
    with np.errstate(all="ignore"):
        p1, p2, p3, p4 = gl * dl, gl * dh, gh * dl, gh * dh
        imp = dl > dh
        lo = np.where(imp, np.maximum(np.maximum(p1, p4), 0.0),
                      np.minimum(np.minimum(p1, p2), np.minimum(p3, p4)))
        hi = np.where(imp, np.minimum(np.minimum(p3, p2), 0.0),
                      np.maximum(np.maximum(p1, p2), np.maximum(p3, p4)))
        return arith.dnm(lo), arith.upm(hi)


def _kmul(al, ah, bl, bh, r):
    lo, hi = _kmul_exact(al, ah, bl, bh)
    return _round(lo, hi, r, "mul")


def _kinv(al, ah, r):
    """1 / [a, b] = [1/b, 1/a] where 0 is not in Prop; NaN otherwise."""
    with np.errstate(all="ignore"):
        lo, hi = _round(1.0 / ah, 1.0 / al, r, "mul")
        bad = ~((np.minimum(al, ah) > 0) | (np.maximum(al, ah) < 0))
    return np.where(bad, np.nan, lo), np.where(bad, np.nan, hi)


def _kdiv(al, ah, bl, bh, r):
    il, ih = _kinv(bl, bh, r)
    return _kmul(al, ah, il, ih, r)


def _binary(core: Callable, X: Any, Y: Any, rounding: str) -> np.ndarray:
    r = _check_rounding(rounding)
    a, b = _arr(X, "X"), _arr(Y, "Y")
    return _pack(*core(a[..., 0], a[..., 1], b[..., 0], b[..., 1], r))


def kaucher_add(X: Any, Y: Any, rounding: str = "outer") -> np.ndarray:
    """Kaucher sum ``[a, b] + [c, d] = [a + c, b + d]``.

    Parameters
    ----------
    X, Y : array_like, shape (..., 2)
        Modal intervals (broadcast).
    rounding : {"outer", "inner"}
        Direction of the rounding (module docstring).

    Returns
    -------
    ndarray, shape (..., 2)

    Notes
    -----
    Modal intervals form a group under ``+``: ``X + Dual(-X) = [0, 0]``.
    """
    return _binary(_kadd, X, Y, rounding)


def kaucher_sub(X: Any, Y: Any, rounding: str = "outer") -> np.ndarray:
    """Kaucher difference ``[a, b] - [c, d] = [a - d, b - c]`` (``X - Dual(X) = [0, 0]``).

    Parameters
    ----------
    X, Y : array_like, shape (..., 2)
    rounding : {"outer", "inner"}

    Returns
    -------
    ndarray, shape (..., 2)
    """
    return _binary(_ksub, X, Y, rounding)


def kaucher_neg(X: Any) -> np.ndarray:
    """``-[a, b] = [-b, -a]`` (exact).

    Parameters
    ----------
    X : array_like, shape (..., 2)

    Returns
    -------
    ndarray, shape (..., 2)
    """
    a = _arr(X)
    return _pack(-a[..., 1], -a[..., 0])


def kaucher_mul(X: Any, Y: Any, rounding: str = "outer") -> np.ndarray:
    """Kaucher product (Kaucher's multiplication table over the sign classes P, N, Z, D).

    Parameters
    ----------
    X, Y : array_like, shape (..., 2)
    rounding : {"outer", "inner"}

    Returns
    -------
    ndarray, shape (..., 2)

    Notes
    -----
    It equals the semantic extension (5.11) of ``x * y`` (thesis §5.1.4). On proper
    operands it is the classical interval product. With ``X`` proper and ``0`` in the interior
    of ``Prop Y``, ``Y`` improper (class D), the product is ``[0, 0]``.
    """
    return _binary(_kmul, X, Y, rounding)


def kaucher_inv(X: Any, rounding: str = "outer") -> np.ndarray:
    """``1 / [a, b] = [1/b, 1/a]`` where ``0 ∉ Prop``; NaN (no information) elsewhere.

    Parameters
    ----------
    X : array_like, shape (..., 2)
    rounding : {"outer", "inner"}

    Returns
    -------
    ndarray, shape (..., 2)
    """
    r = _check_rounding(rounding)
    a = _arr(X)
    return _pack(*_kinv(a[..., 0], a[..., 1], r))


def kaucher_div(X: Any, Y: Any, rounding: str = "outer") -> np.ndarray:
    """Kaucher quotient ``X / Y = X * [1/Ub Y, 1/Lb Y]`` where ``0 ∉ Prop Y``; NaN elsewhere.

    Parameters
    ----------
    X, Y : array_like, shape (..., 2)
    rounding : {"outer", "inner"}

    Returns
    -------
    ndarray, shape (..., 2)
    """
    return _binary(_kdiv, X, Y, rounding)


# ------------------------------------------------------------------------ unary functions
def _migmag(al, ah):
    pl, ph = np.minimum(al, ah), np.maximum(al, ah)
    with np.errstate(invalid="ignore"):
        mig = np.maximum(np.maximum(pl, -ph), 0.0)
        mag = np.maximum(-pl, ph)
    nan = np.isnan(al) | np.isnan(ah)
    return np.where(nan, np.nan, mig), np.where(nan, np.nan, mag)


def _even(X: Any, rounding: str, fn: Callable, kind: str) -> np.ndarray:
    """``g*`` for an even function increasing in |x|: ``[g(mig), g(mag)]`` on proper intervals,
    ``[g(mag), g(mig)]`` on improper ones."""
    r = _check_rounding(rounding)
    a = _arr(X)
    al, ah = a[..., 0], a[..., 1]
    mig, mag = _migmag(al, ah)
    with np.errstate(all="ignore"):
        gmig, gmag = fn(mig), fn(mag)
    imp = al > ah
    lo = np.where(imp, gmag, gmig)
    hi = np.where(imp, gmig, gmag)
    lo, hi = _round(lo, hi, r, kind)
    return _pack(lo, hi)


def kaucher_sq(X: Any, rounding: str = "outer") -> np.ndarray:
    """Semantic extension of ``x**2``: ``[mig², mag²]`` (proper), ``[mag², mig²]`` (improper).

    Parameters
    ----------
    X : array_like, shape (..., 2)
    rounding : {"outer", "inner"}

    Returns
    -------
    ndarray, shape (..., 2)

    Notes
    -----
    For a function of one variable ``f*(X) = range`` when ``X`` is proper and
    ``Dual(range)`` when it is improper, by (5.11); ``mig``/``mag`` are the smallest/largest
    ``|x|`` over ``Prop X``.
    """
    return _even(X, rounding, np.square, "mul")


def kaucher_fabs(X: Any, rounding: str = "outer") -> np.ndarray:
    """Semantic extension of ``|x|``: ``[mig, mag]`` (proper), ``[mag, mig]`` (improper).

    Parameters
    ----------
    X : array_like, shape (..., 2)
    rounding : {"outer", "inner"}
        Exact operation; the argument is accepted for symmetry.

    Returns
    -------
    ndarray, shape (..., 2)
    """
    _check_rounding(rounding)
    a = _arr(X)
    al, ah = a[..., 0], a[..., 1]
    mig, mag = _migmag(al, ah)
    imp = al > ah
    return _pack(np.where(imp, mag, mig), np.where(imp, mig, mag))


def kaucher_powi(X: Any, n: int, rounding: str = "outer") -> np.ndarray:
    """Semantic extension of ``x**n`` for an integer ``n >= 0``.

    Parameters
    ----------
    X : array_like, shape (..., 2)
    n : int
        Odd ``n``: increasing, ``[Lb**n, Ub**n]``; even ``n``: as :func:`kaucher_sq`.
    rounding : {"outer", "inner"}

    Returns
    -------
    ndarray, shape (..., 2)
    """
    n = int(n)
    if n < 0:
        raise ValueError(f"kaucher_powi needs n >= 0; got {n} (use kaucher_inv for 1/x)")
    a = _arr(X)
    if n == 0:
        one = np.ones(a.shape[:-1])
        return _pack(one, one)
    if n == 1:
        return a.copy()
    if n == 2:
        return kaucher_sq(a, rounding)
    if n % 2 == 0:
        return _even(a, rounding, lambda v: np.power(v, n), "libm")
    return kaucher_monotone(a, lambda v: np.power(v, n), increasing=True, rounding=rounding)


# name -> (function, increasing, closed domain lo, closed domain hi, open lo, error model)
MONOTONE_FUNCTIONS: dict[str, tuple[Callable, bool, float, float, bool, str]] = {
    "sqrt": (np.sqrt, True, 0.0, np.inf, False, "mul"),
    "exp": (np.exp, True, -np.inf, np.inf, False, "libm"),
    "expm1": (np.expm1, True, -np.inf, np.inf, False, "libm"),
    "log": (np.log, True, 0.0, np.inf, True, "libm"),
    "log1p": (np.log1p, True, -1.0, np.inf, True, "libm"),
    "atan": (np.arctan, True, -np.inf, np.inf, False, "libm"),
    "tanh": (np.tanh, True, -np.inf, np.inf, False, "libm"),
    "sinh": (np.sinh, True, -np.inf, np.inf, False, "libm"),
    "asinh": (np.arcsinh, True, -np.inf, np.inf, False, "libm"),
    "asin": (np.arcsin, True, -1.0, 1.0, False, "libm"),
    "acos": (np.arccos, False, -1.0, 1.0, False, "libm"),
}
"""Continuous monotone functions known to :func:`kaucher_monotone` by name."""


def kaucher_monotone(X: Any, fn: str | Callable, increasing: bool = True,
                     rounding: str = "outer", *, domain: tuple[float, float] | None = None,
                     error: str = "libm") -> np.ndarray:
    """Semantic extension of a continuous monotone function of one variable.

    Parameters
    ----------
    X : array_like, shape (..., 2)
    fn : str or callable
        A name of :data:`MONOTONE_FUNCTIONS` (then ``increasing``, ``domain`` and ``error`` are
        taken from the table), or a vectorised function whose float results are within the
        ``error`` model of the exact value.
    increasing : bool
        Direction of monotonicity of a callable ``fn``.
    rounding : {"outer", "inner"}
    domain : (float, float), optional
        Closed domain of a callable ``fn``; where ``Prop X`` is not inside, the result is NaN.
    error : {"libm", "mul", "add"}
        Error model of ``fn`` (module docstring of :mod:`~casadi_cmpc.interval.arith`).

    Returns
    -------
    ndarray, shape (..., 2)
        ``[g(Lb), g(Ub)]`` for increasing ``g``, ``[g(Ub), g(Lb)]`` for decreasing ``g``.

    Notes
    -----
    For ``g`` increasing and ``X`` improper, (5.11) gives ``[max g, min g]`` over
    ``Prop X = [Ub, Lb]``, i.e. ``[g(Lb), g(Ub)]`` again: the formula does not depend on the
    modality.
    """
    r = _check_rounding(rounding)
    open_lo = False
    if isinstance(fn, str):
        if fn not in MONOTONE_FUNCTIONS:
            raise ValueError(f"unknown monotone function '{fn}'; known: "
                             f"{', '.join(MONOTONE_FUNCTIONS)}")
        fn, increasing, dlo, dhi, open_lo, error = MONOTONE_FUNCTIONS[fn]
        domain = (dlo, dhi)
    if error not in _RND:
        raise ValueError(f"unknown error model '{error}'; valid: {', '.join(_RND)}")
    a = _arr(X)
    al, ah = a[..., 0], a[..., 1]
    with np.errstate(all="ignore"):
        gl, gh = fn(al), fn(ah)
    lo, hi = (gl, gh) if increasing else (gh, gl)
    lo, hi = _round(lo, hi, r, error)
    if domain is not None:
        pl, ph = np.minimum(al, ah), np.maximum(al, ah)
        bad = ((pl <= domain[0]) if open_lo else (pl < domain[0])) | (ph > domain[1])
        bad |= np.isnan(al) | np.isnan(ah)
        lo = np.where(bad, np.nan, lo)
        hi = np.where(bad, np.nan, hi)
    return _pack(lo, hi)


# ===================================================================== semantic extension
def _mid(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        return np.clip(0.5 * lo + 0.5 * hi, lo, hi)


def _bisect_masked(Z: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """Bisect every box of Z (N, d, 2) along its widest allowed component -> (N, 2, d, 2).

    A box without an allowed component of positive width is repeated (both halves equal).
    """
    lo, hi = Z[..., 0], Z[..., 1]
    w = np.where(allowed, hi - lo, -1.0)
    k = np.argmax(w, axis=1)
    rows = np.arange(Z.shape[0])
    a, b = lo[rows, k], hi[rows, k]
    c = _mid(a, b)
    split = w[rows, k] > 0
    left = Z.copy()
    right = Z.copy()
    left[rows, k, 1] = np.where(split, c, b)
    right[rows, k, 0] = np.where(split, c, a)
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
