"""Closed-form, rounding-safe bounds of ``a_k . x`` over batches of boxes.

For rows ``a_k`` (k = 1..m) and boxes ``[lo, hi]`` (N of them, in R^n),

    max_{x in box} a.x = sum_j a_j^+ hi_j - a_j^- lo_j,
    min_{x in box} a.x = sum_j a_j^+ lo_j - a_j^- hi_j,

with ``a^+ = max(a, 0)`` and ``a^- = max(-a, 0)``.  A batch ``(N, n, 2)`` of boxes is
read as an ``(N, 2n)`` matrix ``[lo_1, hi_1, lo_2, hi_2, ...]`` (a view), extended by two
columns ``s = sum_j |lo_j| + |hi_j|`` and ``1``; one matrix product with a
``(2n + 2, m)`` weight matrix then gives, for the upper test,

    S_k = fl( sum_j w_kj x_j + c alpha_k s - b'_k ),   alpha_k = max_j |a_kj|,

with ``c = 4 (n + 4) 2^-52`` and ``b'_k = b_k - 1e-300`` rounded down (underflow guard).
The batch tests (:meth:`BoxKernel.all_le`, :meth:`BoxKernel.separates`) avoid the two
extra columns: they bound ``s`` by ``2n max |x|`` over the batch and move the
(rounded-outward) shift into the right-hand side, then ``S_k = fl(sum_j w_kj x_j) - b''_k``
with the same guarantee (``gamma_2n alpha_k s`` is below the shift).

Rounding: a dot product of length ``L = 2n + 2`` computed in binary64 (any summation
order, with or without FMA) is within ``gamma_L * sum |terms|`` of the exact value,
``gamma_L = L u / (1 - L u)``, ``u = 2^-53``; ``sum_j |w_kj x_j| <= alpha_k s``. If
``|b'_k| <= 3 alpha_k s`` the shift ``c alpha_k s`` exceeds ``gamma_L (4 + c) alpha_k s``,
so ``S_k <= 0`` implies ``max a_k.x <= b_k``; if ``|b'_k| > 3 alpha_k s`` the sign of
``S_k`` cannot be wrong (the exact value has magnitude ``>= 2|b'_k|/3`` and the error is
below that).  Hence ``S_k <= 0`` proves ``box ⊆ {a_k.x <= b_k}``; the lower test
(``> 0`` proves ``box ∩ {a_k.x <= b_k} = ∅``) is symmetric.  The products are done in
chunks small enough for OpenBLAS to run them on one thread (cache friendly, and immune
to thread contention on busy machines).

Points are tested against rows by :func:`points_le` (plain floating point) and
:func:`exact_points_le` (exact), and a box against an implied inequality ``y^T A x <= y^T b``
(LP multipliers ``y >= 0``) by :func:`_certify_separation` (rigorous, exact near the
bound).
"""

import math
from fractions import Fraction

import numpy as np

__all__: list[str] = []

_TINY = 1e-300
_SPLIT = 134217729.0  # 2^27 + 1 (Veltkamp)
_U = 2.0 ** -53  # unit roundoff of binary64


def _gamma(k: int) -> float:
    """``gamma_k = k u / (1 - k u)``: relative error bound of a sum or dot product of length
    ``k`` in binary64 (``u = 2^-53``)."""
    return k * _U / (1.0 - k * _U)


def _chunk(m: int, q: int) -> int:
    """Rows per matrix product: ``m q chunk`` stays below OpenBLAS's threading threshold."""
    return int(max(256, min(8192, 200_000 // max(1, m * q))))


def points_le(X: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``all(A x <= b)`` for each row x of X (N, n) -> (N,) bool, in chunks.

    Plain floating-point evaluation (no rounding guard), as ``(X @ A.T <= b).all(1)``.
    """
    N = X.shape[0]
    out = np.empty(N, dtype=bool)
    if A.shape[0] == 0:
        out[:] = True
        return out
    bc = b[:, None]
    step = _chunk(A.shape[0], A.shape[1])
    for i in range(0, N, step):
        S = A @ X[i:i + step].T
        out[i:i + S.shape[1]] = (S <= bc).all(axis=0)
    return out


def _two_prod(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Error-free products ``a * b = p + e`` (Dekker); ``ok`` marks where it is exact."""
    p = a * b
    ca = _SPLIT * a
    ah = ca - (ca - a)
    al = a - ah
    cb = _SPLIT * b
    bh = cb - (cb - b)
    bl = b - bh
    e = ((ah * bh - p) + ah * bl + al * bh) + al * bl
    big = 2.0 ** 995
    ok = ((np.abs(a) < big) & (np.abs(b) < big) & (np.abs(p) < 2.0 ** 1000)
          & ((p == 0) & ((a == 0) | (b == 0)) | (np.abs(p) >= 2.0 ** -960)))
    return p, e, ok


def exact_dot_le(X: np.ndarray, W: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact decision of ``sum_j W[i, j] X[i, j] <= b[i]`` for finite float data.

    Parameters
    ----------
    X, W : ndarray, shape (p, q)
    b : ndarray, shape (p,)

    Returns
    -------
    ndarray of bool, shape (p,)
    """
    P, E, ok = _two_prod(W, X)
    out = np.empty(X.shape[0], dtype=bool)
    for i in range(X.shape[0]):
        if ok[i].all() and abs(float(b[i])) < 2.0 ** 1000 and X.shape[1] < 2 ** 20:
            # math.fsum is correctly rounded, so its sign is the sign of the exact sum
            s = math.fsum([*P[i].tolist(), *E[i].tolist(), -float(b[i])])
            out[i] = s <= 0.0
        else:
            acc = sum((Fraction(float(w)) * Fraction(float(x))
                       for w, x in zip(W[i], X[i], strict=True)), Fraction(0))
            out[i] = acc <= Fraction(float(b[i]))
    return out


class BoxKernel:
    """Rigorous box tests against the half-spaces ``a_k.x <= b_k`` of fixed rows.

    Parameters
    ----------
    A : ndarray, shape (m, n)
        Finite rows.
    b : ndarray, shape (m,)
        Finite right-hand sides.
    """

    def __init__(self, A: np.ndarray, b: np.ndarray) -> None:
        A = np.asarray(A, dtype=float)
        b = np.asarray(b, dtype=float)
        m, n = A.shape
        self.A, self.b, self.n, self.m = A, b, n, m
        self.c = 4.0 * (n + 4) * 2.0 ** -52
        Ap = np.maximum(A, 0.0).T
        Am = np.maximum(-A, 0.0).T
        alpha = np.abs(A).max(axis=1, initial=0.0)
        # rounded up, and never 0 for a nonzero row (c alpha underflows for subnormal rows)
        self.calpha = np.where(alpha > 0, np.nextafter(self.c * alpha, np.inf), 0.0)
        # the float paths assume no sum overflows: |a| |x| sums stay below 2**1000 when
        # every |x| <= self._xmax (boxes beyond it are decided exactly)
        self._xmax = 2.0 ** 1000 / ((2 * n + 2) * max(float(alpha.max(initial=0.0)), 1e-300))
        if not np.all(np.abs(b) < 2.0 ** 1000):
            self._xmax = 0.0
        self.b_up = np.nextafter(b - _TINY, -np.inf)
        self.b_lo = np.nextafter(b + _TINY, np.inf)
        W_up = np.empty((2 * n + 2, m))
        W_up[0:2 * n:2] = -Am
        W_up[1:2 * n:2] = Ap
        W_up[2 * n] = self.calpha
        W_up[2 * n + 1] = -self.b_up
        W_lo = np.empty((2 * n + 2, m))
        W_lo[0:2 * n:2] = Ap
        W_lo[1:2 * n:2] = -Am
        W_lo[2 * n] = -self.calpha
        W_lo[2 * n + 1] = -self.b_lo
        self.WT_up = np.ascontiguousarray(W_up.T)
        self.WT_lo = np.ascontiguousarray(W_lo.T)
        self.chunk = _chunk(m, 2 * n)
        self._ones = np.ones(2 * n)

    def _aug(self, flat: np.ndarray) -> np.ndarray:
        aug = np.empty((flat.shape[0], 2 * self.n + 2))
        aug[:, :-2] = flat
        aug[:, -2] = np.abs(flat) @ self._ones
        aug[:, -1] = 1.0
        return aug

    def _scores(self, flat: np.ndarray, up: bool) -> np.ndarray:
        """(N, m) scores: ``<= 0`` proves the row holds the box (up); ``> 0`` proves the
        row excludes the box (not up). Finite boxes only."""
        WT = self.WT_up if up else self.WT_lo
        return (WT @ self._aug(flat).T).T

    def _slow(self, boxes: np.ndarray, up: bool) -> np.ndarray:
        """Decisions (N, m) for boxes with infinite bounds (``0 * inf`` counts as 0).

        ``up``: the row surely holds the box (exact: undecided rows are decided with
        :func:`exact_dot_le`); otherwise: the row surely excludes the box.
        """
        lo = boxes[..., 0][:, None, :]
        hi = boxes[..., 1][:, None, :]
        A = self.A[None]
        with np.errstate(invalid="ignore", over="ignore"):
            if up:
                t = np.where(A > 0, A * hi, np.where(A < 0, A * lo, 0.0))
            else:
                t = np.where(A > 0, A * lo, np.where(A < 0, A * hi, 0.0))
            val = t.sum(axis=2)
            absum = np.where(np.isfinite(t), np.abs(t), 0.0).sum(axis=2)
            E = absum * self.c
            # every term finite but the sum (or its magnitude) not: an overflow, which
            # decides nothing; such rows are decided exactly
            ovf = np.isfinite(t).all(axis=2) & ~(np.isfinite(val) & (absum < 2.0 ** 1000))
            if not up:
                res = ((val - E) > self.b_lo) & ~ovf  # NaN compares False
            else:
                res = ((val + E) <= self.b_up) & ~ovf
            # decided exactly: overflowed rows, and (up) rows the rounding bound leaves open
            amb = ovf | (~res & np.isfinite(val) & (val - E <= self.b) if up else ovf)
        bi, kr = np.nonzero(amb)
        if bi.size:
            # with a finite value, infinite bounds only meet zero weights: drop them
            flat = boxes.reshape(boxes.shape[0], 2 * self.n)
            X = np.where(np.isfinite(flat[bi]), flat[bi], 0.0)
            W = (self.WT_up if up else self.WT_lo)[kr, :-2]
            le = exact_dot_le(X, W, self.b[kr])
            res[bi, kr] = le if up else ~le
        return res

    def _flat(self, boxes: np.ndarray) -> tuple[np.ndarray, float]:
        """The (N, 2n) view and ``max |x|`` (not finite when some bound is infinite, and
        reported as infinite when a sum of the float paths could overflow: the exact
        path of :meth:`_slow` then decides)."""
        flat = boxes.reshape(boxes.shape[0], 2 * self.n)
        amax = float(np.abs(flat).max(initial=0.0))
        return flat, (amax if amax <= self._xmax else np.inf)

    def holds(self, boxes: np.ndarray) -> np.ndarray:
        """(N, m) bool: the half-space of row k surely contains the box."""
        flat, amax = self._flat(boxes)
        if not np.isfinite(amax):
            return self._slow(boxes, True)
        return self._scores(flat, True) <= 0.0

    def _shift(self, amax: float) -> np.ndarray:
        """Per-row shift ``>= c alpha_k s_i`` for boxes with coordinates ``|x| <= amax``."""
        s_max = amax * (2 * self.n) * (1 + 8 * 2.0 ** -53)
        return self.calpha * s_max * (1 + 4 * 2.0 ** -53)

    def separates(self, boxes: np.ndarray) -> np.ndarray:
        """(N,) bool: some row surely excludes the whole box (``min a_k.x > b_k``)."""
        flat, amax = self._flat(boxes)
        if not np.isfinite(amax):
            return self._slow(boxes, False).any(axis=1)
        N = flat.shape[0]
        out = np.empty(N, dtype=bool)
        WT = self.WT_lo[:, :-2]
        thr = np.nextafter(self.b_lo + self._shift(amax), np.inf)[:, None]
        for i in range(0, N, self.chunk):
            f = flat[i:i + self.chunk]
            ST = WT @ f.T
            ST -= thr
            out[i:i + f.shape[0]] = ST.max(axis=0, initial=-np.inf) > 0.0
        return out

    def all_le(self, boxes: np.ndarray) -> np.ndarray:
        """Exact test ``max_{x in box} a_k.x <= b_k`` for every row k; (N, n, 2) -> (N,).

        Rows that the rounding bound cannot decide (the box touches the hyperplane up to
        rounding) are decided exactly (error-free products and a correctly rounded sum).
        """
        flat, amax = self._flat(boxes)
        if not np.isfinite(amax):
            return self._slow(boxes, True).all(axis=1)
        N = flat.shape[0]
        res = np.empty(N, dtype=bool)
        amb = np.zeros(N, dtype=bool)
        WT = self.WT_up[:, :-2]
        shift = self._shift(amax)
        thr = np.nextafter(self.b_up - shift, -np.inf)[:, None]
        for i in range(0, N, self.chunk):
            f = flat[i:i + self.chunk]
            ST = WT @ f.T
            ST -= thr
            mx = ST.max(axis=0, initial=-np.inf)
            ok = mx <= 0.0
            res[i:i + f.shape[0]] = ok
            # a score above twice the largest shift is a certain failure
            amb[i:i + f.shape[0]] = ~ok & (mx <= 2.0 * float(shift.max(initial=0.0))
                                           + 4 * _TINY)
        idx = np.flatnonzero(amb)
        if idx.size == 0:
            return res
        S = self._scores(flat[idx], True)
        E = np.outer(flat[idx].__abs__() @ self._ones, self.calpha)
        sure_fail = (S > 4.0 * E + 4 * _TINY).any(axis=1)
        idx = idx[~sure_fail]
        S = S[~sure_fail]
        bi, kr = np.nonzero(S > 0.0)  # undecided (box, row) pairs
        ok = exact_dot_le(flat[idx[bi]], self.WT_up[kr, :-2], self.b[kr])
        fail = np.zeros(idx.size, dtype=bool)
        np.logical_or.at(fail, bi, ~ok)
        res[idx[~fail]] = True
        return res


def exact_points_le(X: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``all(A x <= b)`` decided exactly for each row x of X (N, n) -> (N,) bool.

    The floating-point residuals ``A x - b`` with the bound ``gamma_{n+2} (|A| |x| + |b|)``
    of their rounding error decide every row they can; a point with a row inside that
    bound is decided in exact rational arithmetic (the float data taken as exact). Rows
    with ``b = +inf`` hold everywhere, ``b = -inf`` nowhere; a non-finite point is decided
    in plain floating point.
    """
    N, n = X.shape
    if A.shape[0] == 0 or N == 0:
        return np.ones(N, dtype=bool)
    with np.errstate(over="ignore", invalid="ignore"):
        S = X @ A.T - b[None, :]
        mag = np.abs(X) @ np.abs(A).T + np.abs(b)[None, :]
        err = _gamma(n + 2) * mag + 1e-300
    # a float decision needs a finite magnitude: with |A| |x| + |b| finite no partial sum
    # overflowed (an overflow gives S = -inf <= -err = -inf, not a proof)
    fin = np.isfinite(mag) & np.isfinite(S)
    sure_in = (fin & (S <= -err)) | (b[None, :] == np.inf)
    sure_out = (fin & (S > err)) | (b[None, :] == -np.inf)
    inside = sure_in.all(axis=1)
    out = sure_out.any(axis=1)
    undecided = np.flatnonzero(~inside & ~out)
    if undecided.size:
        finite = np.isfinite(X[undecided]).all(axis=1)
        plain = undecided[~finite]
        inside[plain] = ((X[plain] @ A.T) <= b[None, :]).all(axis=1)
        rows: dict[int, tuple[list[Fraction], Fraction]] = {}
        for k in undecided[finite]:
            xk = [Fraction(float(v)) for v in X[k]]
            ok = True
            for i in np.flatnonzero(~sure_in[k]).tolist():
                if i not in rows:
                    rows[i] = ([Fraction(float(a)) for a in A[i]], Fraction(float(b[i])))
                ai, bi = rows[i]
                if sum((a * x for a, x in zip(ai, xk, strict=True)), Fraction(0)) > bi:
                    ok = False
                    break
            inside[k] = ok
    return inside


def _exact_box_slack(y: np.ndarray, A: np.ndarray, b: np.ndarray, lo: np.ndarray,
                     hi: np.ndarray) -> Fraction | None:
    """Exact ``min_{x in [lo, hi]} (A^T y).x - y.b`` (None when it is ``-inf``)."""
    idx = np.flatnonzero(y != 0.0)
    yf = [Fraction(float(y[i])) for i in idx]
    beta = sum((v * Fraction(float(b[i])) for v, i in zip(yf, idx, strict=True)),
               Fraction(0))
    total = -beta
    for j in range(A.shape[1]):
        g = sum((v * Fraction(float(A[i, j])) for v, i in zip(yf, idx, strict=True)),
                Fraction(0))
        if g == 0:
            continue
        bound = lo[j] if g > 0 else hi[j]
        if not np.isfinite(bound):
            return None
        total += g * Fraction(float(bound))
    return total


def _certify_separation(Y: np.ndarray, A: np.ndarray, b: np.ndarray,
                        bx: np.ndarray, strict: bool = True) -> np.ndarray:
    """Rigorous check that ``y^T A x <= y^T b`` excludes each box.

    Parameters
    ----------
    Y : ndarray, shape (K, m), >= 0
    A, b : raw finite rows, shapes (m, n), (m,); or one set per box, (K, m, n), (K, m)
    bx : ndarray, shape (K, n, 2)

    Returns
    -------
    ndarray of bool, shape (K,)
        True where ``min_{x in box} (A^T y).x - y^T b > 0`` (``>= 0`` when not
        ``strict``) is proven: by a floating-point evaluation with a rigorous bound on its
        rounding error, or, when the value lies within that bound, in exact rational
        arithmetic.
    """
    K, m = Y.shape
    n = A.shape[-1]
    if A.ndim == 3:  # one row set per box: A (K, m, n), b (K, m)
        G = np.einsum("km,kmn->kn", Y, A)
        beta = (Y * b).sum(axis=1)
        Ge = _gamma(m + 2) * np.einsum("km,kmn->kn", Y, np.abs(A))
        be = _gamma(m + 2) * (Y * np.abs(b)).sum(axis=1)
    else:
        G = Y @ A
        beta = Y @ b
        Ge = _gamma(m + 2) * (Y @ np.abs(A))  # |G - exact| <= Ge
        be = _gamma(m + 2) * (Y @ np.abs(b))
    lo, hi = bx[..., 0], bx[..., 1]
    with np.errstate(invalid="ignore", over="ignore"):
        t = np.where(G > 0, G * lo, np.where(G < 0, G * hi, 0.0))
        M = np.maximum(np.abs(lo), np.abs(hi))
        L = t.sum(axis=1)
        err = (_gamma(n + 2) * np.where(np.isfinite(t), np.abs(t), 0.0).sum(axis=1)
               + np.where(Ge > 0, Ge * M, 0.0).sum(axis=1) + be)
        slack = L - beta
        err = (err + _gamma(4) * (np.abs(L) + np.abs(beta))) * (1 + 8 * _U) + 1e-300
        ok = slack > err if strict else slack >= err
        fin = np.isfinite(slack) & np.isfinite(err)
        amb = fin & ~ok & (slack >= -err)
    ok = np.where(fin, ok, False)
    for k in np.flatnonzero(amb).tolist():
        Ak, bk = (A[k], b[k]) if A.ndim == 3 else (A, b)
        v = _exact_box_slack(Y[k], Ak, bk, lo[k], hi[k])
        ok[k] = v is not None and (v > 0 if strict else v >= 0)
    return ok
