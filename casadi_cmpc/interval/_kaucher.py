"""Kaucher (modal) interval arithmetic on batches of bounds ``(..., 2)``.

The modal structure (``dual``, ``prop``, ``mode``, inclusion, ``meet`` / ``join``), the
roundings ``Out`` / ``Inn`` of thesis (5.8) (``round_outer``, ``round_inner``) and Kaucher's
complete arithmetic (``kaucher_*``), each operation with ``rounding="outer"`` (the exact
Kaucher result is included in the result) or ``"inner"`` (the result is included in it).
The conventions, error models and examples are in :mod:`casadi_cmpc.interval.modal`, which
exports every public name of this module.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..exceptions import DimensionError, InvalidBoundsError
from . import arith

__all__ = [
    "PROPER", "IMPROPER", "POINT",
    "dual", "prop", "mode", "is_proper", "is_improper", "modal_subset", "meet", "join",
    "no_nan", "round_outer", "round_inner",
    "kaucher_add", "kaucher_sub", "kaucher_neg", "kaucher_mul", "kaucher_div",
    "kaucher_inv", "kaucher_sq", "kaucher_fabs", "kaucher_powi", "kaucher_monotone",
    "MONOTONE_FUNCTIONS",
]

PROPER = 1
IMPROPER = -1
POINT = 0

_ROUNDINGS = ("outer", "inner")


# =============================================================================== helpers
def _arr(X: Any, name: str = "X") -> np.ndarray:
    """``X`` as a float array of modal intervals, shape (..., 2) (DimensionError otherwise)."""
    a = np.asarray(X, dtype=float)
    if a.ndim == 0 or a.shape[-1] != 2:
        raise DimensionError(f"{name} must be a modal interval array of shape (..., 2); "
                             f"got shape {a.shape}")
    return a


def _check_rounding(rounding: str) -> str:
    """The rounding mode ``"outer"`` or ``"inner"`` (lower case; ValueError otherwise)."""
    r = str(rounding).lower()
    if r not in _ROUNDINGS:
        raise ValueError(f"unknown rounding '{rounding}'; valid roundings: outer, inner")
    return r


def _pack(lo: Any, hi: Any) -> np.ndarray:
    """Bounds ``lo``, ``hi`` (broadcast to one shape S) stacked into intervals, (*S, 2)."""
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
def _kadd(al: np.ndarray, ah: np.ndarray, bl: np.ndarray, bh: np.ndarray, r: str
          ) -> tuple[np.ndarray, np.ndarray]:
    """Kaucher sum ``[al, ah] + [bl, bh]`` (bounds of one shape), rounded by ``r``."""
    with np.errstate(all="ignore"):
        return _round(al + bl, ah + bh, r, "add")


def _ksub(al: np.ndarray, ah: np.ndarray, bl: np.ndarray, bh: np.ndarray, r: str
          ) -> tuple[np.ndarray, np.ndarray]:
    """Kaucher difference ``[al, ah] - [bl, bh]`` (bounds of one shape), rounded by ``r``."""
    with np.errstate(all="ignore"):
        return _round(al - bh, ah - bl, r, "add")


def _classes(a: np.ndarray, b: np.ndarray) -> np.ndarray:
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


def _kmul_exact(al: np.ndarray, ah: np.ndarray, bl: np.ndarray, bh: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
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


def _kmul_centered(gl: np.ndarray, gh: np.ndarray, dl: np.ndarray, dh: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
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


def _kmul(al: np.ndarray, ah: np.ndarray, bl: np.ndarray, bh: np.ndarray, r: str
          ) -> tuple[np.ndarray, np.ndarray]:
    """Kaucher product ``[al, ah] * [bl, bh]`` (bounds of one shape), rounded by ``r``."""
    lo, hi = _kmul_exact(al, ah, bl, bh)
    return _round(lo, hi, r, "mul")


def _kinv(al: np.ndarray, ah: np.ndarray, r: str) -> tuple[np.ndarray, np.ndarray]:
    """1 / [a, b] = [1/b, 1/a] where 0 is not in Prop; NaN otherwise."""
    with np.errstate(all="ignore"):
        lo, hi = _round(1.0 / ah, 1.0 / al, r, "mul")
        bad = ~((np.minimum(al, ah) > 0) | (np.maximum(al, ah) < 0))
    return np.where(bad, np.nan, lo), np.where(bad, np.nan, hi)


def _kdiv(al: np.ndarray, ah: np.ndarray, bl: np.ndarray, bh: np.ndarray, r: str
          ) -> tuple[np.ndarray, np.ndarray]:
    """Kaucher quotient ``[al, ah] / [bl, bh]`` (bounds of one shape), rounded by ``r``."""
    il, ih = _kinv(bl, bh, r)
    return _kmul(al, ah, il, ih, r)


def _binary(core: Callable, X: Any, Y: Any, rounding: str) -> np.ndarray:
    """A binary operation ``core(al, ah, bl, bh, r) -> (lo, hi)`` on modal interval arrays
    ``X``, ``Y`` (..., 2): result (..., 2)."""
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
def _migmag(al: np.ndarray, ah: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mignitude and magnitude of ``Prop [al, ah]`` (NaN where a bound is NaN)."""
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
