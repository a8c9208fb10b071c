"""Exact rational linear algebra for the certificates of the set library.

Besides null spaces (Farkas certificates), this module holds the exact polyhedral tools
of :func:`casadi_cmpc.pre_set`: half-space rows with integer normals and rational offsets
(:data:`ExactRow`), Fourier–Motzkin elimination, an exact simplex method, redundancy
removal in which floating-point LPs only *guide* exactly checked certificates
(:func:`reduce_rows`), and the inward rounding of exact rows to floats
(:func:`round_rows_inward`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction

import numpy as np
from scipy.optimize import nnls

from . import _lp

__all__ = ["rat_nullspace", "ExactRow", "exact_row", "fm_eliminate", "rat_solve",
           "rat_lp_eq", "implied_by", "prune_rows", "reduce_rows", "exact_max",
           "round_rows_inward", "lp_feasible", "frac_down", "frac_up"]

_FMAX = float(np.finfo(float).max)


def _gauss_jordan(rows: list[list[Fraction]], k: int) -> list[int]:
    """Reduce ``rows`` in place to reduced row echelon form on their first ``k`` columns
    (exact); returns the pivot columns (one per leading row)."""
    pivots: list[int] = []
    r = 0
    for col in range(k):
        piv = next((i for i in range(r, len(rows)) if rows[i][col] != 0), None)
        if piv is None:
            continue
        rows[r], rows[piv] = rows[piv], rows[r]
        pv = rows[r][col]
        rows[r] = [x / pv for x in rows[r]]
        for i in range(len(rows)):
            if i != r and rows[i][col] != 0:
                f = rows[i][col]
                rows[i] = [x - f * y for x, y in zip(rows[i], rows[r], strict=True)]
        pivots.append(col)
        r += 1
        if r == len(rows):
            break
    return pivots


def rat_nullspace(M: list[list[Fraction]], k: int) -> list[list[Fraction]]:
    """Basis of ``{v in Q^k : M v = 0}`` by exact Gauss–Jordan elimination."""
    rows = [list(r) for r in M]
    pivots = _gauss_jordan(rows, k)
    free = [c for c in range(k) if c not in pivots]
    basis = []
    for fc in free:
        v = [Fraction(0)] * k
        v[fc] = Fraction(1)
        for i, pc in enumerate(pivots):
            v[pc] = -rows[i][fc]
        basis.append(v)
    return basis


# ---------------------------------------------------------------------------------------
# Exact half-space rows, Fourier–Motzkin elimination, certified redundancy removal
# ---------------------------------------------------------------------------------------

#: An exact half-space ``a.x <= beta``: ``a`` integers with gcd 1 (or all zero), ``beta``
#: rational. The normalisation makes two rows with the same direction have equal ``a``.
ExactRow = tuple[tuple[int, ...], Fraction]


def frac_down(q: Fraction) -> float:
    """The largest float ``<= q`` (``-inf`` below the float range)."""
    try:
        f = float(q)
    except OverflowError:
        return -math.inf if q < 0 else _FMAX
    if math.isinf(f):
        return -math.inf if f < 0 else _FMAX
    if Fraction(f) > q:
        f = math.nextafter(f, -math.inf)
    return f


def frac_up(q: Fraction) -> float:
    """The smallest float ``>= q`` (``+inf`` above the float range)."""
    return -frac_down(-q)


def exact_row(coeffs: Sequence[Fraction | int], beta: Fraction | int) -> ExactRow:
    """The row ``coeffs.x <= beta`` scaled by a positive rational to integer, coprime
    coefficients (the set it describes is unchanged)."""
    fr = [Fraction(c) for c in coeffs]
    den = 1
    for c in fr:
        den = den * c.denominator // math.gcd(den, c.denominator)
    ints = [int(c * den) for c in fr]
    g = 0
    for v in ints:
        g = math.gcd(g, v)
    if g == 0:
        return tuple(0 for _ in ints), Fraction(beta)
    return tuple(v // g for v in ints), Fraction(beta) * den / g


def fm_eliminate(rows: Sequence[ExactRow], k: int) -> list[ExactRow]:
    """Fourier–Motzkin elimination of coordinate ``k``: exact rows of the projection of
    ``{z : a.z <= beta for every row}`` along ``z_k`` (coordinate k dropped).

    Rows without ``z_k`` are kept; every pair of a row with a positive and a row with a
    negative coefficient of ``z_k`` gives their non-negative combination free of it. The
    result is the exact projection (with many redundant rows: prune them with
    :func:`prune_rows`).
    """
    pos = [r for r in rows if r[0][k] > 0]
    neg = [r for r in rows if r[0][k] < 0]
    # a zero entry does not change the gcd: rows free of z_k stay normalised
    out = [(a[:k] + a[k + 1:], b) for a, b in rows if a[k] == 0]
    for ap, bp in pos:
        for an, bn in neg:
            lp_, ln = -an[k], ap[k]
            a = [lp_ * x + ln * y for x, y in zip(ap, an, strict=True)]
            del a[k]
            g = 0
            for v in a:
                g = math.gcd(g, v)
            if g == 0:
                out.append((tuple(a), lp_ * bp + ln * bn))
            else:
                out.append((tuple(v // g for v in a), (lp_ * bp + ln * bn) / g))
    return out


def rat_solve(M: list[list[Fraction]], r: list[Fraction]) -> list[Fraction] | None:
    """A solution ``y`` of ``M y = r`` (M of shape (p, k)) by exact Gauss–Jordan
    elimination, free unknowns set to 0; None when the system is inconsistent."""
    k = len(M[0]) if M else 0
    rows = [list(M[i]) + [r[i]] for i in range(len(M))]
    pivots = _gauss_jordan(rows, k)
    rr = len(pivots)
    if any(rows[i][k] != 0 for i in range(rr, len(rows))):
        return None
    y = [Fraction(0)] * k
    for i, pc in enumerate(pivots):
        y[pc] = rows[i][k]
    return y


def _dot(y: Sequence[int], b: Sequence[Fraction]) -> Fraction:
    """Exact ``sum y_i b_i`` (integers y) with one reduction at the end."""
    num, den = 0, 1
    for yi, bi in zip(y, b, strict=True):
        d_ = bi.denominator
        if d_ == den:
            num += yi * bi.numerator
        else:
            num, den = num * d_ + yi * bi.numerator * den, den * d_
    return Fraction(num, den)


def rat_lp_eq(M: list[list[Fraction]], r: list[Fraction], c: list[Fraction]
              ) -> tuple[list[Fraction], Fraction] | None:
    """``min c.y  s.t.  M y = r, y >= 0`` (M of shape (p, k)) by the two-phase simplex
    method in exact rational arithmetic with Bland's rule (no cycling).

    Returns
    -------
    (y, value) or None
        None when the problem is infeasible or unbounded below.
    """
    p = len(M)
    k = len(c)
    # rows with r >= 0, artificial variables k .. k + p - 1
    T = []
    for i in range(p):
        sgn = -1 if r[i] < 0 else 1
        T.append([sgn * v for v in M[i]] + [Fraction(int(j == i)) for j in range(p)]
                 + [sgn * r[i]])
    basis = list(range(k, k + p))

    def pivot(row: int, col: int) -> None:
        pv = T[row][col]
        T[row] = [v / pv for v in T[row]]
        for i in range(p):
            if i != row and T[i][col] != 0:
                f = T[i][col]
                T[i] = [a - f * b for a, b in zip(T[i], T[row], strict=True)]
        basis[row] = col

    def run(cost: list[Fraction], cols: list[int]) -> bool:
        """Simplex iterations on the columns ``cols``; False when unbounded."""
        while True:
            cb = [cost[b] for b in basis]
            enter = None
            for j in cols:
                red = cost[j] - sum((cb[i] * T[i][j] for i in range(p)), Fraction(0))
                if red < 0:
                    enter = j
                    break
            if enter is None:
                return True
            best, leave = None, None
            for i in range(p):
                if T[i][enter] > 0:
                    ratio = T[i][-1] / T[i][enter]
                    if best is None or ratio < best or (ratio == best and
                                                        basis[i] < basis[leave]):
                        best, leave = ratio, i
            if leave is None:
                return False
            pivot(leave, enter)

    zero, one = Fraction(0), Fraction(1)
    cost1 = [zero] * k + [one] * p
    run(cost1, list(range(k + p)))
    if any(basis[i] >= k and T[i][-1] != 0 for i in range(p)):
        return None
    # drive zero-level artificials out of the basis (or drop their redundant rows)
    for i in range(p - 1, -1, -1):
        if basis[i] >= k:
            j = next((j for j in range(k) if T[i][j] != 0), None)
            if j is None:
                del T[i]
                del basis[i]
                p -= 1
            else:
                pivot(i, j)
    cost2 = list(c) + [zero] * len(r)
    if not run(cost2, list(range(k))):
        return None
    y = [zero] * k
    for i, b in enumerate(basis):
        y[b] = T[i][-1]
    return y, sum((cv * yv for cv, yv in zip(c, y, strict=True)), zero)


def implied_by(rows: Sequence[ExactRow], S: Sequence[int], a: Sequence[int | Fraction],
               ) -> Fraction | None:
    """Exact bound of ``a.z`` over ``{z : rows[s] for s in S}`` by a certificate on S.

    Solves ``sum_s y_s a_s = a`` exactly on the rows ``S``; when the solution has
    ``y >= 0``, every z satisfying those rows has ``a.z <= sum_s y_s beta_s``, which is
    returned. None when no non-negative solution was found (nothing is claimed).
    """
    S = list(S)
    if not S:
        return None
    d = len(a)
    M = [[Fraction(rows[s][0][j]) for s in S] for j in range(d)]
    y = rat_solve(M, [Fraction(v) for v in a])
    if y is None or any(v < 0 for v in y):
        return None
    return sum((v * rows[s][1] for v, s in zip(y, S, strict=True)), Fraction(0))


class _FloatView:
    """Approximate unit rows of exact rows in the coordinates ``t`` of ``z = mid + hw t``
    (the box [lo, hi] becomes [-1, 1]), only to guide LPs: ``An[i] = f_i (a_i ∘ hw)``
    with ``f_i = 1 / (M_i nrm_i)``, ``M_i = max_j |a_ij|``."""

    def __init__(self, rows: Sequence[ExactRow], lo: np.ndarray, hi: np.ndarray) -> None:
        lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        mid, hw = (lo + hi) / 2.0, (hi - lo) / 2.0
        hw = np.where(hw > 0, hw, 1.0)
        A = np.empty((len(rows), lo.size))
        b = np.empty(len(rows))
        self.M: list[int] = []
        for i, (a, beta) in enumerate(rows):
            M = max(abs(v) for v in a) or 1
            self.M.append(M)
            A[i] = [v / M for v in a]
            q = beta / M
            b[i] = float(q) if abs(q) < 1e300 else (1e300 if q > 0 else -1e300)
        b = b - A @ mid
        A = A * hw
        nrm = np.linalg.norm(A, axis=1)
        self.nrm = np.where(nrm > 0, nrm, 1.0)
        self.An = A / self.nrm[:, None]
        self.bn = b / self.nrm


def _support(y: np.ndarray, idx: Sequence[int]) -> tuple[list[int], np.ndarray]:
    """Entries of ``idx`` with significant multipliers (relative to the largest), and
    those multipliers."""
    y = np.where(np.isfinite(y), y, 0.0)
    top = float(y.max(initial=0.0))
    if top <= 0.0:
        return [], np.zeros(0)
    sel = np.flatnonzero(y > 1e-12 * top)
    return [int(idx[i]) for i in sel], y[sel]


def _active(A: np.ndarray, b: np.ndarray, x: np.ndarray, idx: Sequence[int], cap: int
            ) -> list[int]:
    """Up to ``cap`` entries of ``idx`` whose rows are tight at x (within 1e-9), tightest
    first."""
    gap = b - A @ x
    tight = np.flatnonzero(gap <= 1e-9 * np.maximum(1.0, np.abs(b)))
    tight = tight[np.argsort(gap[tight])][:cap]
    return [int(idx[i]) for i in tight]


def _vertices(A: np.ndarray, b: np.ndarray, z0: np.ndarray
              ) -> tuple[np.ndarray, list[list[int]]] | None:
    """Vertices of ``{z : A z <= b}`` (interior point z0) and the rows tight at each,
    by Qhull's half-space intersection; None in dimension 1 or when Qhull fails (e.g. an
    unbounded set). Floating point: a guide for the certificates only."""
    if A.shape[1] < 2 or A.shape[0] <= A.shape[1]:
        return None
    from scipy.spatial import HalfspaceIntersection, QhullError

    try:
        with np.errstate(all="ignore"):
            hs = HalfspaceIntersection(np.hstack([A, -b[:, None]]), z0)
    except (QhullError, ValueError):
        return None
    V = hs.intersections
    if not np.all(np.isfinite(V)) or V.shape[0] == 0:
        return None
    return V, [list(map(int, f)) for f in hs.dual_facets]


def _trivial_keep(rows: Sequence[ExactRow], allowed: set[int]) -> list[int] | None:
    """Exact first pass of :func:`prune_rows`: vacuous rows and parallel rows with a
    larger offset dropped; None when a row ``0.z <= beta < 0`` proves emptiness."""
    keep: list[int] = []
    groups: dict[tuple[int, ...], list[int]] = {}
    for i, (a, beta) in enumerate(rows):
        if any(a):
            groups.setdefault(a, []).append(i)
        elif beta < 0:
            return None
        elif i not in allowed:
            keep.append(i)
    for members in groups.values():
        j = min(members, key=lambda q: rows[q][1])
        keep += [q for q in members if q == j or q not in allowed]
    return sorted(keep)


def _first_hits(An: np.ndarray, slack: np.ndarray, D: np.ndarray) -> np.ndarray:
    """For rays ``z0 + t d`` (rows of D) from an interior point with row slacks
    ``slack > 0``: the index of the row each ray leaves the polytope through (-1: none)."""
    out = np.full(D.shape[0], -1, dtype=int)
    for s in range(0, D.shape[0], 256):
        S = An @ D[s:s + 256].T
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(S > 0, slack[:, None] / S, np.inf)
        j = np.argmin(t, axis=0)
        ok = np.isfinite(t[j, np.arange(t.shape[1])])
        out[s:s + 256] = np.where(ok, j, -1)
    return out


def _unit_rows(rows: Sequence[ExactRow], idx: Sequence[int]) -> dict[tuple[int, int], int]:
    """``{(j, ±1): i}`` for the rows ``±z_j <= beta`` among ``idx``."""
    out: dict[tuple[int, int], int] = {}
    for i in idx:
        a = rows[i][0]
        nz = [j for j, v in enumerate(a) if v]
        if len(nz) == 1 and abs(a[nz[0]]) == 1:
            out[(nz[0], a[nz[0]])] = i
    return out


class _Pruner:
    """State of one redundancy removal: the rows, their current offsets (rows may be
    moved inward within a budget, see :func:`reduce_rows`) and the float view."""

    def __init__(self, rows: Sequence[ExactRow], keep: list[int], lo: np.ndarray,
                 hi: np.ndarray, shrink: float) -> None:
        self.rows = rows
        self.keep = keep
        self.beta = {i: rows[i][1] for i in keep}
        self.view = _FloatView([rows[i] for i in keep], lo, hi)
        self.pos = {i: p for p, i in enumerate(keep)}
        self.M = {i: self.view.M[p] for i, p in self.pos.items()}
        self.nrm = {i: float(self.view.nrm[p]) for i, p in self.pos.items()}
        hw = (np.asarray(hi, float) - np.asarray(lo, float)) / 2.0
        scale = float(np.max(np.abs(np.concatenate([hw, np.asarray(lo, float),
                                                     np.asarray(hi, float)]))))
        # largest total inward move of a row, in the units of the row scaled to
        # max |a_j| = 1
        self.budget = Fraction(float(shrink) * scale) if shrink > 0 else Fraction(0)
        self.moved = {i: Fraction(0) for i in keep}

    def _candidates(self, p: int, S: list[int], yS: np.ndarray, units: dict,
                    active: Sequence[int]):
        """Certificates ``(used rows, (numerators, denominator) of the multipliers
        y >= 0, bound on a_p.z)`` with ``sum y_s a_s = a_p`` exactly, cheapest first."""
        rows, beta = self.rows, self.beta
        a_p = rows[p][0]
        d = len(a_p)
        # (1) the LP multipliers as fractions, residual covered by the unit rows
        cert = self._cover(p, S, yS, units) if S else None
        if cert is not None:
            used, k, D, bound = cert
            yield used, (k, D), bound
        # (2) exact solve on the LP support
        if S:
            M = [[Fraction(rows[s][0][j]) for s in S] for j in range(d)]
            y = rat_solve(M, [Fraction(v) for v in a_p])
            if y is not None and all(v >= 0 for v in y):
                yield S, (y, 1), sum((v * beta[s] for v, s in zip(y, S, strict=True)),
                                     Fraction(0))
        # (3) exact LP over the support and the rows tight at the LP maximiser
        cols = list(dict.fromkeys(list(S) + list(active)))
        if len(cols) > len(S):
            sol = rat_lp_eq([[Fraction(rows[s][0][j]) for s in cols] for j in range(d)],
                            [Fraction(v) for v in a_p], [beta[s] for s in cols])
            if sol is not None:
                yield cols, (sol[0], 1), sol[1]

    def _cover(self, p: int, S: list[int], yS: np.ndarray, units: dict):
        """Certificate (1) of :meth:`_candidates` in integer arithmetic: multipliers
        ``y_s = k_s / D`` (the LP's, rescaled to the exact rows), residual
        ``r = a_p - sum y_s a_s`` covered by the unit rows."""
        rows = self.rows
        try:
            scale = [float(v) * (self.M[p] / self.M[s]) * float(self.nrm[p] / self.nrm[s])
                     for v, s in zip(yS, S, strict=True)]
        except OverflowError:
            return None
        if not all(math.isfinite(v) and v >= 0 for v in scale):
            return None
        ratios = [v.as_integer_ratio() for v in scale]
        D = max(den for _, den in ratios)
        k = [num * (D // den) for num, den in ratios]
        a_p = rows[p][0]
        used, mult = list(S), list(k)
        for j, aj in enumerate(a_p):
            R = D * aj - sum(kv * rows[s][0][j] for kv, s in zip(k, S, strict=True))
            if R == 0:
                continue
            u = units.get((j, 1 if R > 0 else -1))
            if u is None:
                return None
            used.append(u)
            mult.append(abs(R))
        return used, mult, D, _dot(mult, [self.beta[s] for s in used]) / D

    def certify(self, p: int, S: list[int], yS: np.ndarray, units: dict,
                active: Sequence[int]) -> bool:
        """Prove that row p is implied by the rows of a certificate (which the caller
        keeps), moving those rows inward by at most the budget when the bound misses
        ``beta_p`` by a margin (then the set shrinks, never grows)."""
        beta_p = self.beta[p]
        best = None
        for used, mult, bound in self._candidates(p, S, yS, units, active):
            if bound <= beta_p:
                return True
            if best is None or bound < best[2]:
                best = (used, mult, bound)
        if best is None or self.budget == 0:
            return False
        used, (num, den), bound = best
        # move every row of the certificate by the same amount theta (rows scaled to
        # max |a_j| = 1): sum_s y_s theta M_s = gap
        # (a row used twice is moved once; the bound drops by theta * total)
        pairs = list({s: max(abs(c) for c in self.rows[s][0])
                      for s, v in zip(used, num, strict=True) if v > 0}.items())
        total = sum((Fraction(v) * max(abs(c) for c in self.rows[s][0])
                     for s, v in zip(used, num, strict=True) if v > 0), Fraction(0)) / den
        if total == 0:
            return False
        # rounded up to a float: offsets keep short denominators
        theta = Fraction(frac_up((bound - beta_p) / total))
        if any(self.moved[s] + theta > self.budget for s, _ in pairs):
            return False
        for s, M in pairs:
            self.beta[s] -= theta * M
            self.moved[s] += theta
        return True


def _prune(rows: Sequence[ExactRow], lo: np.ndarray, hi: np.ndarray,
           removable: Sequence[int] | None, shrink: float
           ) -> tuple[list[int], dict[int, Fraction]] | None:
    """Kept indices and their (possibly lowered) offsets; see :func:`reduce_rows`."""
    allowed = set(range(len(rows))) if removable is None else {int(i) for i in removable}
    keep = _trivial_keep(rows, allowed)
    if keep is None:
        return None
    test = [i for i in keep if i in allowed]
    if len(keep) <= 1 or not test:
        return keep, {i: rows[i][1] for i in keep}
    P = _Pruner(rows, keep, lo, hi, shrink)
    An, bn = P.view.An, P.view.bn
    pos = P.pos
    K, d = An.shape
    # Chebyshev centre (radius capped): max r  s.t.  An z + r <= bn
    st, zr, _, _ = _lp.lp(np.r_[np.zeros(d), -1.0], np.hstack([An, np.ones((K, 1))]), bn,
                          np.r_[np.full(d, -np.inf), 0.0], np.r_[np.full(d, np.inf), 1e3])
    z0 = zr[:d] if st == _lp.OPTIMAL else None
    slack = None if z0 is None else bn - An @ z0
    if z0 is None or not zr[-1] > 1e-9 or not np.all(slack > 0):
        return _prune_pairwise(P, allowed)
    R = {pos[i] for i in keep if i not in allowed}
    rng = np.random.default_rng(0)
    some = An[np.linspace(0, K - 1, min(K, 256)).astype(int)]
    D = np.vstack([np.eye(d), -np.eye(d), some, rng.standard_normal((8 * d, d))])
    R.update(int(j) for j in _first_hits(An, slack, D) if j >= 0)
    und = [pos[i] for i in test if pos[i] not in R]
    tol = 1e-6 * np.maximum(1.0, np.abs(bn))
    while und:
        Rl = sorted(R)
        glob = [keep[q] for q in Rl]
        units = _unit_rows(rows, glob)
        Ar, br = An[Rl], bn[Rl]
        grow: set[int] = set()
        # rows that cut the polytope of R at a point z: the ray from z0 towards z names
        # a row of the full set to add to R (batched below)
        cut_rows: list[int] = []
        cut_pts: list[np.ndarray] = []
        # screening by the vertices of the polytope of R (Qhull): max a_p.z is taken
        # at a vertex, whose tight rows give the multipliers of the certificate
        verts = _vertices(Ar, br, z0)
        lp_rows = und
        if verts is not None:
            V, facets = verts
            vals = An[und] @ V.T
            arg = np.argmax(vals, axis=1)
            lp_rows = []
            for t, p in enumerate(und):
                if vals[t, arg[t]] <= bn[p] + tol[p]:
                    Sq = facets[arg[t]]
                    yS = nnls(Ar[Sq].T, An[p])[0]
                    S = [glob[q] for q, yq in zip(Sq, yS, strict=True) if yq > 0]
                    if not (S and P.certify(keep[p], S, yS[yS > 0], units,
                                            [glob[q] for q in Sq])):
                        lp_rows.append(p)
                    continue
                cut_rows.append(p)
                cut_pts.append(V[arg[t]])
        if lp_rows:
            blocks_A, blocks_b, blk = [], [], []
            for t, p in enumerate(lp_rows):
                blocks_A += [Ar, An[[p]]]
                blocks_b += [br, bn[[p]] + max(1.0, abs(bn[p]))]
                blk.append(np.full(len(Rl) + 1, t))
            res = _lp.block_lp(-An[lp_rows], np.vstack(blocks_A), np.concatenate(blocks_b),
                               np.concatenate(blk))
            w = len(Rl) + 1
            for t, p in enumerate(lp_rows):
                if res.status[t] != _lp.OPTIMAL:
                    grow.add(p)
                    continue
                val = -float(res.fun[t])
                y = res.y[t * w:(t + 1) * w]
                if val <= bn[p] + tol[p]:
                    S, yS = _support(y[:-1], glob)
                    act = _active(Ar, br, res.x[t], glob, 3 * d)
                    if y[-1] > 0 or not S or not P.certify(keep[p], S, yS, units, act):
                        grow.add(p)
                    continue
                cut_rows.append(p)
                cut_pts.append(res.x[t])
        nxt: list[int] = []
        if cut_rows:
            # at most 256 rays per round (each costs a pass over all rows); the other
            # cutting rows wait for the next round, against a larger R
            shoot = np.zeros(len(cut_rows), dtype=bool)
            shoot[np.linspace(0, len(cut_rows) - 1, min(len(cut_rows), 256)).astype(int)] = True
            nxt += [p for p, f in zip(cut_rows, shoot, strict=True) if not f]
            idx = np.flatnonzero(shoot)
            hits = _first_hits(An, slack, np.array(cut_pts)[idx] - z0)
            for i, j in zip(idx.tolist(), hits.tolist(), strict=True):
                p = cut_rows[i]
                if j < 0 or j in R:
                    grow.add(p)  # no progress from the ray: keep the row
                else:
                    grow.add(j)
                    nxt.append(p)
        R |= grow
        und = [p for p in dict.fromkeys(nxt) if p not in R]
    kept = sorted(keep[p] for p in R)
    return kept, {i: P.beta[i] for i in kept}


def _prune_pairwise(P: _Pruner, allowed: set[int]
                    ) -> tuple[list[int], dict[int, Fraction]]:
    """:func:`_prune` for a set without interior: each removable row tested by an LP
    against all other rows, dropped one at a time with a certificate on rows not
    dropped."""
    An, bn, keep = P.view.An, P.view.bn, P.keep
    alive = set(range(len(keep)))
    for p in [q for q in range(len(keep)) if keep[q] in allowed]:
        rest = sorted(alive - {p})
        if not rest:
            break
        A_ = np.vstack([An[rest], An[[p]]])
        b_ = np.concatenate([bn[rest], bn[[p]] + max(1.0, abs(bn[p]))])
        st, x, f, y = _lp.lp(-An[p], A_, b_)
        if st != _lp.OPTIMAL or -f > bn[p] + 1e-6 * max(1.0, abs(bn[p])) or y[-1] > 0:
            continue
        glob = [keep[q] for q in rest]
        S, yS = _support(np.asarray(y[:-1]), glob)
        act = _active(An[rest], bn[rest], x, glob, 3 * An.shape[1])
        if S and P.certify(keep[p], S, yS, _unit_rows(P.rows, glob), act):
            alive.discard(p)
    kept = sorted(keep[p] for p in alive)
    return kept, {i: P.beta[i] for i in kept}


def prune_rows(rows: Sequence[ExactRow], lo: np.ndarray, hi: np.ndarray,
               removable: Sequence[int] | None = None) -> list[int] | None:
    """Indices of rows to keep so that the kept rows describe exactly the same set
    (:func:`reduce_rows` without moving rows); None when a row ``0.z <= beta < 0``
    proves the set empty."""
    out = _prune(rows, lo, hi, removable, 0.0)
    return None if out is None else out[0]


def reduce_rows(rows: Sequence[ExactRow], lo: np.ndarray, hi: np.ndarray,
                removable: Sequence[int] | None = None, shrink: float = 0.0
                ) -> list[ExactRow] | None:
    """Rows describing a subset of ``{z : rows}``, equal to it when ``shrink = 0``,
    without the rows proven redundant.

    Parameters
    ----------
    rows : sequence of ExactRow
        Half-spaces in ``d`` coordinates.
    lo, hi : ndarray, shape (d,)
        Finite box giving the scale of the coordinates (conditions the LPs, and sets the
        unit of ``shrink``).
    removable : sequence of int, optional
        Only these rows may be dropped (default: all).
    shrink : float
        A row whose certificate misses by a margin may still be dropped after the rows
        of the certificate are moved inward to close the margin, each row by at most
        ``shrink * max(|lo|, |hi|, (hi - lo) / 2)`` in total (the row scaled to
        ``max_j |a_j| = 1``). The result is then a subset of the set, never a superset.

    Returns
    -------
    list of ExactRow or None
        The kept rows in their order (offsets possibly lowered); None when a row ``0.z <= beta < 0``
        proves the set empty.

    Notes
    -----
    Vacuous rows (zero normal, ``beta >= 0``) and rows with the normal of another row and
    a larger or equal ``beta`` are dropped exactly. The other rows are sorted by a
    Clarkson-type scheme: a set R of kept rows starts with the rows that cannot be
    dropped and the rows hit first by rays from an interior point (Chebyshev centre, LP);
    each undecided row i is tested by an LP (HiGHS, stacked) maximising ``a_i.z`` over R.
    When the maximum is not above ``beta_i``, row i is dropped if the LP multipliers lead
    to an exact certificate ``y >= 0``, ``sum y_s a_s = a_i``, ``sum y_s beta_s <=
    beta_i`` on rows of R (solved on the LP support, or with the residual covered by
    unit rows ``±z_j <= c``, or by an exact simplex over the rows tight at the LP
    maximiser), else kept; otherwise the ray towards the maximiser names a row to add to
    R, and the test is repeated. Rows of R are never dropped and offsets only decrease,
    so every certificate holds for the returned rows whatever the LPs' accuracy (which
    only decides how many redundant rows remain). For a set without interior each row is
    tested against all other rows, dropped one at a time. An LP failure only keeps rows.
    """
    out = _prune(rows, lo, hi, removable, shrink)
    if out is None:
        return None
    kept, beta = out
    return [(rows[i][0], beta[i]) for i in kept]


def exact_max(rows: Sequence[ExactRow], c: Sequence[int | Fraction], lo: np.ndarray,
              hi: np.ndarray) -> Fraction | None:
    """A proven upper bound of ``max c.z`` over the rows, or None (unbounded, or no
    certificate found). An LP (HiGHS) guides an exact certificate ``y >= 0``,
    ``sum y_s a_s = c``: solved on the LP support (:func:`implied_by`), else by the exact
    simplex over the support and the rows tight at the LP maximiser; the bound is then
    ``sum y_s beta_s``."""
    view = _FloatView(rows, lo, hi)
    hw = (np.asarray(hi, float) - np.asarray(lo, float)) / 2.0
    hw = np.where(hw > 0, hw, 1.0)
    cf = np.array([float(v) for v in c]) * hw
    st, x, _, y = _lp.lp(-cf, view.An, view.bn)
    if st != _lp.OPTIMAL or y is None:
        return None
    S = _support(np.asarray(y), range(len(rows)))[0]
    bound = implied_by(rows, S, c)
    if bound is not None:
        return bound
    cols = list(dict.fromkeys(S + _active(view.An, view.bn, x, range(len(rows)),
                                          3 * len(c))))
    sol = rat_lp_eq([[Fraction(rows[s][0][j]) for s in cols] for j in range(len(c))],
                    [Fraction(v) for v in c], [rows[s][1] for s in cols])
    return None if sol is None else sol[1]


def round_rows_inward(rows: Sequence[ExactRow], lo: Sequence[Fraction | None],
                      hi: Sequence[Fraction | None]) -> tuple[np.ndarray, np.ndarray]:
    """Float rows ``(A_f, b_f)`` with ``{x in B : A_f x <= b_f} ⊆ {x : a.x <= beta}``.

    Each row is divided by its largest ``|a_j|``, its normal rounded to the nearest floats
    ``a_f``, and its offset lowered by ``max_{x in B} (a - a_f).x`` (exact, over the box
    ``B = [lo, hi]``) and rounded down: for x in B (floats taken exactly),
    ``a.x = a_f.x + (a - a_f).x <= b_f + max_B (a - a_f).x <= beta``. The caller must keep
    B's rows with the result. Coordinates where every normal is exact may have infinite
    bounds (``lo``/``hi`` entries None).

    Returns
    -------
    A_f : ndarray, shape (k, d)
    b_f : ndarray, shape (k,)
    """
    d = len(lo)
    A_f = np.zeros((len(rows), d))
    b_f = np.zeros(len(rows))
    for i, (a, beta) in enumerate(rows):
        M = max(abs(v) for v in a)
        if M == 0:
            A_f[i] = 0.0
            b_f[i] = frac_down(beta)
            continue
        corr = Fraction(0)
        for j, v in enumerate(a):
            fj = v / M
            A_f[i, j] = fj
            err = Fraction(v, M) - Fraction(fj)
            if err == 0:
                continue
            lj, hj = lo[j], hi[j]
            if lj is None or hj is None:
                raise ValueError(f"coordinate {j} needs finite bounds for the rounding")
            corr += max(err * lj, err * hj)
        b_f[i] = frac_down(beta / M - corr)
    return A_f, b_f


def lp_feasible(rows: Sequence[ExactRow], lo: np.ndarray, hi: np.ndarray) -> bool:
    """False when HiGHS finds ``{z : rows}`` infeasible (up to its tolerance, about
    ``1e-10`` in the coordinates scaled to the box [lo, hi]); True otherwise."""
    if not rows:
        return True
    view = _FloatView(rows, lo, hi)
    st, _, _, _ = _lp.lp(np.zeros(view.An.shape[1]), view.An, view.bn)
    return st != _lp.INFEASIBLE
