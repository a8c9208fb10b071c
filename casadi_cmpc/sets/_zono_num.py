"""Sound floating-point kernels used by :mod:`casadi_cmpc.sets.zonotope`.

* directed sums (``add_up``/``add_dn``): the exact error of a floating-point sum is recovered
  with Knuth's TwoSum and the result is moved by one ulp only when the sum was inexact, so
  exact sums (e.g. ``0.5 - 0.4``) stay exact;
* interval matrix products built from :mod:`casadi_cmpc.interval.arith` (outward rounding);
* a verified linear solve (enclosure of ``A^{-1} B`` with a proof that ``A`` is invertible);
* exact facet normals of a zonotope: for every ``(n-1)``-subset of generators an interval
  vector that contains a non-zero vector orthogonal to the subset (verified solve, with an
  exact rational fallback for ill-conditioned or rank-deficient subsets).
"""

from __future__ import annotations

import itertools
from fractions import Fraction
from math import comb

import numpy as np

from ..interval import arith as ia
from ._exact import rat_nullspace

__all__: list[str] = []

_MAXF = float(np.finfo(float).max)


# ----------------------------------------------------------------- directed sums
def add_up(a, b):
    """Smallest float >= a + b (exact real sum), elementwise."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    with np.errstate(all="ignore"):
        s = a + b
        z = s - a
        e = (a - (s - z)) + (b - z)
        s = np.where(e > 0, np.nextafter(s, np.inf), s)
    # round-to-nearest overflow of finite operands towards -inf is not an upper bound
    return np.where((s == -np.inf) & np.isfinite(a) & np.isfinite(b), -_MAXF, s)


def add_dn(a, b):
    """Largest float <= a + b (exact real sum), elementwise."""
    return -add_up(-np.asarray(a, dtype=float), -np.asarray(b, dtype=float))


def sub_up(a, b):
    """Smallest float >= a - b."""
    return add_up(a, -np.asarray(b, dtype=float))


def sub_dn(a, b):
    """Largest float <= a - b."""
    return add_dn(a, -np.asarray(b, dtype=float))


def sum_up(x, axis=-1):
    """Upper bound of the exact sum along ``axis`` (sequential directed additions)."""
    x = np.moveaxis(np.asarray(x, dtype=float), axis, 0)
    if x.shape[0] == 0:
        return np.zeros(x.shape[1:])
    s = x[0]
    for t in range(1, x.shape[0]):
        s = add_up(s, x[t])
    return np.array(s, dtype=float)


def sum_dn(x, axis=-1):
    """Lower bound of the exact sum along ``axis``."""
    return -sum_up(-np.asarray(x, dtype=float), axis=axis)


def mul_up(a, b):
    """Upper bound of the exact product a * b (any signs)."""
    return ia.upm(np.asarray(a, dtype=float) * np.asarray(b, dtype=float))


def div_up(a, b):
    """Upper bound of a / b for a >= 0, b > 0."""
    with np.errstate(all="ignore"):
        return ia.upm(np.asarray(a, dtype=float) / np.asarray(b, dtype=float))


def two_sum_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact ``(a + b) - fl(a + b)`` (Knuth's TwoSum; finite operands), elementwise."""
    s = a + b
    z = s - a
    return (a - (s - z)) + (b - z)


def halve_generator(C: np.ndarray, H: np.ndarray, k: np.ndarray | None = None
                    ) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], np.ndarray]:
    r"""The two halves (thesis Thm 4.1) of zonotopes ``c_i ⊕ H_i B^p``, one generator each.

    Parameters
    ----------
    C : ndarray, shape (N, n)
        Centres.
    H : ndarray, shape (N, n, p), p >= 1
        Generator matrices (columns are generators).
    k : ndarray of int, shape (N,), optional
        The generator halved in each zonotope. Default: the first generator holding the
        largest ``|h_ij|`` (thesis (4.12)-(4.13)).

    Returns
    -------
    H2 : ndarray, shape (N, n, p)
        ``H`` with column ``k`` halved: the generators of both halves.
    centres : [ndarray, ndarray], shapes (N, n)
        ``fl(c - h_k/2)`` (left halves) and ``fl(c + h_k/2)`` (right halves).
    errors : [ndarray, ndarray], shapes (N, n)
        The exact rounding errors ``(c ∓ h_k/2) - centre`` of the centres (TwoSum).
    extra : ndarray, shape (N, n)
        ``h_k - 2 fl(h_k/2)``: nonzero only where halving a subnormal was inexact.
        The halves with the errors and ``extra`` added as generators (or radii) cover the
        zonotope exactly.
    """
    N = C.shape[0]
    if k is None:
        k = np.argmax(np.abs(H).max(axis=1), axis=1)  # (4.13): first column holding Max(H)
    rows = np.arange(N)
    h = H[rows, :, k]  # (N, n)
    half = 0.5 * h
    H2 = H.copy()
    H2[rows, :, k] = half
    centres, errors = [], []
    for sgn in (-1.0, 1.0):
        step = sgn * half
        centres.append(C + step)
        errors.append(two_sum_error(C, step))
    return H2, centres, errors, h - 2.0 * half


def midrad(lo, hi):
    """Midpoint (float) and radius (rounded up) with ``[lo, hi] ⊆ [mid - rad, mid + rad]``."""
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    with np.errstate(all="ignore"):
        mid = 0.5 * lo + 0.5 * hi  # no overflow; halving is exact except for subnormals
    mid = np.where(lo == hi, lo, mid)
    rad = np.maximum(sub_up(hi, mid), sub_up(mid, lo))
    return mid, np.maximum(rad, 0.0)


def iabs(lo, hi):
    """Interval absolute value (exact)."""
    return ia.fabs(lo, hi)


# ------------------------------------------------------------ interval matrices
def imatmul(Alo, Ahi, Blo, Bhi):
    """Interval product of ``(..., m, k)`` and ``(..., k, r)`` interval matrices (outward)."""
    Alo = np.asarray(Alo, dtype=float)
    Ahi = np.asarray(Ahi, dtype=float)
    Blo = np.asarray(Blo, dtype=float)
    Bhi = np.asarray(Bhi, dtype=float)
    k = Alo.shape[-1]
    shape = np.broadcast_shapes(Alo.shape[:-1] + (1,), Blo.shape[:-2] + (1, Blo.shape[-1]))
    if k == 0:
        return np.zeros(shape), np.zeros(shape)
    lo = hi = None
    for t in range(k):
        pl, ph = ia.mul(Alo[..., :, t, None], Ahi[..., :, t, None],
                        Blo[..., None, t, :], Bhi[..., None, t, :])
        if lo is None:
            lo, hi = pl, ph
        else:
            lo, hi = ia.add(lo, hi, pl, ph)
    return np.broadcast_to(lo, shape).copy(), np.broadcast_to(hi, shape).copy()


def isum(lo, hi, axis=-1):
    """Interval sum along ``axis`` (outward)."""
    lo = np.moveaxis(np.asarray(lo, dtype=float), axis, 0)
    hi = np.moveaxis(np.asarray(hi, dtype=float), axis, 0)
    if lo.shape[0] == 0:
        return np.zeros(lo.shape[1:]), np.zeros(lo.shape[1:])
    sl, sh = lo[0], hi[0]
    for t in range(1, lo.shape[0]):
        sl, sh = ia.add(sl, sh, lo[t], hi[t])
    return np.array(sl, dtype=float), np.array(sh, dtype=float)


# -------------------------------------------------------------- verified solve
def verified_solve(A, B):
    """Enclose ``X = A^{-1} B`` for a batch of point systems.

    Parameters
    ----------
    A : ndarray, shape (K, m, m)
    B : ndarray, shape (K, m, r)

    Returns
    -------
    X : ndarray, shape (K, m, r)
        Floating-point approximation.
    err : ndarray, shape (K, m, r)
        Upper bounds with ``|A^{-1} B - X| <= err`` (exact reals), valid where ``ok``.
    ok : ndarray of bool, shape (K,)
        True where the enclosure is proven; this also proves that ``A`` is invertible.

    Notes
    -----
    With an approximate inverse ``R`` and ``C = I - R A`` enclosed in interval arithmetic,
    ``||C||_inf <= beta < 1`` proves ``A`` invertible; the error ``E = A^{-1}(B - A X)``
    satisfies ``E = R res + C E``, hence ``||E_col||_inf <= ||R res_col||_inf / (1 - beta)``
    and ``|E_ij| <= |R res|_ij + (|C| 1)_i ||E_col||_inf``.
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    K, m = A.shape[0], A.shape[1]
    r = B.shape[2]
    if m == 0:
        z = np.zeros((K, 0, r))
        return z, z.copy(), np.ones(K, dtype=bool)
    ok = np.isfinite(A).all(axis=(1, 2)) & np.isfinite(B).all(axis=(1, 2))
    R = np.full_like(A, np.nan)
    with np.errstate(all="ignore"):
        try:
            R[ok] = np.linalg.inv(A[ok])
        except np.linalg.LinAlgError:
            for i in np.flatnonzero(ok):
                try:
                    R[i] = np.linalg.inv(A[i])
                except np.linalg.LinAlgError:
                    ok[i] = False
        ok &= np.isfinite(R).all(axis=(1, 2))
        R[~ok] = 0.0
        X = R @ B
        X = X + R @ (B - A @ X)  # one step of refinement
        X[~np.isfinite(X)] = 0.0
    AXlo, AXhi = imatmul(A, A, X, X)
    rlo, rhi = ia.sub(B, B, AXlo, AXhi)
    RAlo, RAhi = imatmul(R, R, A, A)
    eye = np.broadcast_to(np.eye(m), A.shape)
    Clo, Chi = ia.sub(eye, eye, RAlo, RAhi)
    Cabs = np.maximum(np.abs(Clo), np.abs(Chi))
    Crow = sum_up(Cabs, axis=-1)  # (K, m)
    beta = Crow.max(axis=1)
    ok &= beta < 1.0
    Rrlo, Rrhi = imatmul(R, R, rlo, rhi)
    Rrabs = np.maximum(np.abs(Rrlo), np.abs(Rrhi))  # (K, m, r)
    num = Rrabs.max(axis=1)  # (K, r)
    den = np.where(ok, sub_dn(1.0, np.where(ok, beta, 0.0)), 1.0)
    bound = div_up(num, den[:, None])  # (K, r)
    err = add_up(Rrabs, mul_up(Crow[:, :, None], bound[:, None, :]))
    ok &= np.isfinite(err).all(axis=(1, 2))
    err[~ok] = np.inf
    return X, err, ok


# ----------------------------------------------------------- exact facet normals
def _exact_null_vector(rows):
    """Exact normalised null vector of an (n-1) x n rational matrix of rank n-1, else None."""
    M = [[Fraction(float(v)) for v in row] for row in rows]
    n = len(M[0]) if M else 1
    basis = rat_nullspace(M, n)
    if len(basis) != 1:
        return None
    v = basis[0]
    big = max(abs(x) for x in v)
    return [x / big for x in v]


def _fraction_interval(q):
    f = float(q)
    lo = f if Fraction(f) <= q else float(np.nextafter(f, -np.inf))
    hi = f if Fraction(f) >= q else float(np.nextafter(f, np.inf))
    return lo, hi


def facet_normals(G, max_facets):
    """Interval enclosures of the facet normals of the zonotope with generators ``G``.

    Parameters
    ----------
    G : ndarray, shape (n, p)
        Generators without zero columns; ``rank(G) = n`` must be proven by the caller.
    max_facets : int
        Largest number of ``(n-1)``-subsets to enumerate.

    Returns
    -------
    (Nlo, Nhi) : ndarray, shape (F, n), or None when ``C(p, n-1) > max_facets``
        Row ``i`` encloses an exact non-zero normal of the span of one ``(n-1)``-subset of
        generators; subsets of rank < n-1 (no normal) are left out, so every facet normal
        of the zonotope is enclosed by some row.
    """
    n, p = G.shape
    if n == 1:
        one = np.ones((1, 1))
        return one, one.copy()
    if n == 2:  # the rotated generator is an exact normal
        N = np.stack([-G[1], G[0]], axis=1)
        return N, N.copy()
    if comb(p, n - 1) > max_facets:
        return None
    subsets = np.array(list(itertools.combinations(range(p), n - 1)), dtype=int)
    if subsets.size == 0:
        return np.zeros((0, n)), np.zeros((0, n))
    F = subsets.shape[0]
    Af = G.T[subsets]  # (F, n-1, n): rows are the generators of the subset
    with np.errstate(all="ignore"):
        v = np.linalg.svd(Af)[2][:, -1, :]
    k = np.argmax(np.abs(v), axis=1)
    others = np.array([np.delete(np.arange(n), kk) for kk in k])  # (F, n-1)
    Ak = np.take_along_axis(Af, others[:, None, :], axis=2)
    bk = -np.take_along_axis(Af, k[:, None, None], axis=2)
    Y, E, ok = verified_solve(Ak, bk)
    Nlo = np.ones((F, n))
    Nhi = np.ones((F, n))
    rows = np.arange(F)[:, None]
    np.put_along_axis(Nlo, others, sub_dn(Y[:, :, 0], E[:, :, 0]), axis=1)
    np.put_along_axis(Nhi, others, add_up(Y[:, :, 0], E[:, :, 0]), axis=1)
    del rows
    keep = ok.copy()
    for i in np.flatnonzero(~ok):  # exact rational fallback
        vec = _exact_null_vector(Af[i])
        if vec is None:
            continue  # rank < n-1: this subset defines no facet
        iv = np.array([_fraction_interval(q) for q in vec])
        Nlo[i], Nhi[i] = iv[:, 0], iv[:, 1]
        keep[i] = True
    return Nlo[keep], Nhi[keep]


def proven_full_rank(G):
    """True when ``rank(G) = n`` is proven (an n-subset of columns is verified invertible)."""
    n, p = G.shape
    if p < n:
        return False
    if n == 0:
        return True
    # greedy column choice by pivoted QR on the float data
    try:
        from scipy.linalg import qr

        piv = qr(G, pivoting=True, mode="r")[1][:n]
    except Exception:  # pragma: no cover - scipy always available
        piv = np.argsort(-np.linalg.norm(G, axis=0))[:n]
    T = G[:, np.sort(piv)]
    ok = verified_solve(T[None], np.eye(n)[None])[2][0]
    if ok:
        return True
    # exact fallback for small problems
    if n * p <= 64:
        M = [[Fraction(float(v)) for v in row] for row in G]
        return _rank_fraction(M) == n
    return False


def _rank_fraction(M):
    M = [row[:] for row in M]
    rows, cols = len(M), len(M[0]) if M else 0
    r = 0
    for c in range(cols):
        piv = next((i for i in range(r, rows) if M[i][c] != 0), None)
        if piv is None:
            continue
        M[r], M[piv] = M[piv], M[r]
        for i in range(r + 1, rows):
            if M[i][c] != 0:
                f = M[i][c] / M[r][c]
                M[i] = [a - f * b for a, b in zip(M[i], M[r], strict=True)]
        r += 1
        if r == rows:
            break
    return r
