"""LP queries of a polytope: Chebyshev ball, emptiness, boundedness, support, bounding box,
redundancy.

Each function takes the :class:`~casadi_cmpc.sets.polytope.Polytope` ``P`` whose method
calls it and caches its answer in ``P._cache``. The LPs run in the scaled coordinates of
``P._rows()`` (HiGHS, :mod:`casadi_cmpc.sets._lp`) and decide with the tolerance
:data:`RTOL` times the scale of the polytope (a distance in the units of ``x``); the
certificates (Farkas multipliers, upper bounds of the support function) are checked in
exact rational arithmetic.
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import EmptySetError, SolverError
from . import _lp
from ._exact import rat_nullspace
from .box import Box

if TYPE_CHECKING:
    from .polytope import Polytope

__all__: list[str] = []

#: Relative LP decision tolerance (multiplied by the scale of the data).
RTOL = 1e-9


def chebyshev(P: Polytope) -> tuple[np.ndarray, float]:
    """Chebyshev centre and signed radius (negative: empty; inf: unbounded radius)."""
    c = P._cache.get("cheb")
    if c is not None:
        return c
    R = P._rows()
    n = P.dim
    if R.empty:
        c = (np.full(n, np.nan), -np.inf)
    elif R.An.shape[0] == 0:
        c = (np.zeros(n), np.inf)
    else:
        cap = 1e6  # in the scaled coordinates z
        rows = np.hstack([R.An, np.ones((R.An.shape[0], 1))])
        cost = np.zeros(n + 1)
        cost[-1] = -1.0
        ub = np.full(n + 1, np.inf)
        ub[-1] = cap
        st, x, f, y = _lp.lp(cost, rows, R.bz, -np.inf, ub)
        if st == _lp.INFEASIBLE:  # HiGHS proved r <= cap infeasible: cannot happen
            st = _lp.NUMERICAL  # pragma: no cover
        if st != _lp.OPTIMAL:
            # numerical trouble: nothing is claimed (not proven empty)
            c = (R.c0.copy(), 0.0)
            P._cache["cheb"] = c
            P._cache["cheb_y"] = None
            return c
        r = float(x[-1])
        c = (R.c0 + R.s * x[:n], np.inf if r >= cap * (1 - 1e-9) else r * R.s)
        P._cache["cheb_y"] = y
    P._cache["cheb"] = c
    return c


def is_empty(P: Polytope) -> bool:
    """Whether P is proven empty (:meth:`Polytope.is_empty`; cached)."""
    e = P._cache.get("empty")
    if e is None:
        R = P._rows()
        if R.empty:
            e = True
        elif R.An.shape[0] == 0:
            e = False
        else:
            r = P._chebyshev()[1]
            y = P._cache.get("cheb_y")
            e = bool(r < 0.0 and y is not None
                     and _farkas_empty(R.A, R.b, R.raw_multipliers(y)))
        P._cache["empty"] = e
    return e


def is_bounded(P: Polytope) -> bool:
    """Whether P is bounded (:meth:`Polytope.is_bounded`: one LP on the recession cone;
    cached)."""
    bnd = P._cache.get("bounded")
    if bnd is not None:
        return bnd
    R = P._rows()
    n = P.dim
    if P.is_empty():
        bnd = True
    elif R.An.shape[0] < n + 1 or np.linalg.matrix_rank(R.An) < n:
        bnd = False
    else:
        cost = R.An.sum(axis=0)  # minimise 1^T A d  <=>  maximise -1^T A d
        st, _, f, _ = _lp.lp(cost, R.An, np.zeros(R.An.shape[0]), -1.0, 1.0)
        _lp.check_status(st, "the boundedness test")
        bnd = bool(-f <= 1e-9 * R.An.shape[0])
    P._cache["bounded"] = bnd
    return bnd


def max_lp(P: Polytope, D: np.ndarray, multipliers_only: bool = False
           ) -> tuple[np.ndarray, np.ndarray]:
    """``max d.x`` over the polytope for each row of D (K, n): values (K,) and maximisers
    (K, n).

    Solved in the scaled coordinates ``z`` of :class:`~casadi_cmpc.sets.polytope._Rows`
    (translation and scale invariant); the LP multipliers of the unit rows are kept in
    ``P._last_y`` (K, m).
    An LP that HiGHS cannot solve is solved again on the rows relaxed by the decision
    tolerance (values up to ``tol`` too large). With ``multipliers_only`` (the
    multipliers serve as certificates that are checked exactly, so any ``y >= 0``
    is admissible) larger relaxations are tried too, and LPs that still fail get
    NaN values and multipliers instead of an error.
    """
    R = P._rows()
    K, n = D.shape
    m = R.An.shape[0]
    res = _lp.block_lp(-D, np.tile(R.An, (K, 1)), np.tile(R.bz0, K),
                       np.repeat(np.arange(K), m))
    status, fun = res.status.copy(), res.fun.copy()
    Xz = res.x.copy()
    Y = res.y.reshape(K, m).copy() if m else np.zeros((K, 0))
    bounded = P._cache.get("bounded") is True
    relax = (0.0, RTOL, 1e-6, 1e-3) if multipliers_only else (0.0, RTOL)
    for k, eps in enumerate(relax):
        # first retry: the rows rounded outward (a thin set that rounding made
        # infeasible); then relaxed by a tolerance
        bad = (status == _lp.NUMERICAL) | (bounded & (status == _lp.UNBOUNDED))
        if k == 0:
            bad |= status == _lp.INFEASIBLE
        redo = np.flatnonzero(bad)
        if redo.size == 0:
            break
        r2 = _lp.block_lp(-D[redo], np.tile(R.An, (redo.size, 1)),
                          np.tile(R.bz + eps, redo.size), np.repeat(np.arange(redo.size), m))
        ok = r2.status == _lp.OPTIMAL
        if k == 0:
            keep = r2.status == _lp.INFEASIBLE
            status[redo[keep]] = _lp.INFEASIBLE
            fun[redo[keep]] = np.inf
        status[redo[ok]] = _lp.OPTIMAL
        fun[redo[ok]] = r2.fun[ok]
        Xz[redo[ok]] = r2.x[ok]
        if m:
            Y[redo[ok]] = r2.y.reshape(redo.size, m)[ok]
    failed = (status == _lp.NUMERICAL) | (bounded & (status == _lp.UNBOUNDED))
    if not multipliers_only:
        _lp.check_status(np.where(failed, _lp.NUMERICAL, status), "a support function")
    vals = -fun * R.s + D @ R.c0
    vals[status == _lp.UNBOUNDED] = np.inf
    vals[status == _lp.INFEASIBLE] = -np.inf
    vals[failed] = np.nan
    X = R.c0 + R.s * Xz
    Y[failed] = np.nan
    P._last_y = Y
    return vals, X


def support_upper(P: Polytope, D: np.ndarray) -> np.ndarray:
    """Rigorous upper bounds of ``h(d) = max_{x in P} d.x`` for a bounded non-empty P.

    From LP multipliers ``y >= 0`` of the raw rows: ``d.x = y^T A x + rho.x <=
    y.b + rho.x`` with ``rho = d - A^T y``; ``rho.x`` is bounded on the box
    ``|x - c0| <= W`` around the reference point, and W itself comes from the same
    bound in the axis directions (``W <= B + |R| W`` solved with ``||R|| < 1``).
    All sums are evaluated in exact rational arithmetic and rounded upward.

    Parameters
    ----------
    D : ndarray, shape (K, n)

    Returns
    -------
    ndarray, shape (K,)
        ``+inf`` where no bound could be established.
    """
    R = P._rows()
    K, n = D.shape
    E = np.vstack([np.eye(n), -np.eye(n)])
    P._max_lp(np.vstack([E, D]), multipliers_only=True)
    Y = np.asarray(P._last_y, dtype=float)
    Y = R.raw_multipliers(np.where(np.isfinite(Y), Y, 0.0))
    A = [[Fraction(float(v)) for v in row] for row in R.A]
    b = [Fraction(float(v)) for v in R.b]
    c0 = [Fraction(float(v)) for v in R.c0]
    DD = np.vstack([E, D])
    beta: list[Fraction] = []
    rho: list[list[Fraction]] = []
    for k in range(DD.shape[0]):
        y = [Fraction(float(v)) for v in Y[k]]
        idx = [i for i, v in enumerate(y) if v != 0]
        g = [sum((y[i] * A[i][j] for i in idx), Fraction(0)) for j in range(n)]
        r_k = [Fraction(float(DD[k, j])) - g[j] for j in range(n)]
        beta.append(sum((y[i] * b[i] for i in idx), Fraction(0))
                    + sum((r_k[j] * c0[j] for j in range(n)), Fraction(0)))
        rho.append([abs(v) for v in r_k])
    # W_j >= max |x_j - c0_j|:  W <= B + Rm W
    B = [max(beta[j] - c0[j], beta[n + j] + c0[j]) for j in range(n)]
    q = max(sum(max(rho[j][i], rho[n + j][i]) for i in range(n)) for j in range(n))
    out = np.full(K, np.inf)
    if q >= Fraction(1, 2):
        return out
    Bmax = max(max(B), Fraction(0))
    W = [max(Bj, Fraction(0)) + q * Bmax / (1 - q) for Bj in B]
    for k in range(K):
        kk = 2 * n + k
        val = beta[kk] + sum((rho[kk][j] * W[j] for j in range(n)), Fraction(0))
        out[k] = _frac_up(val)
    return out


def bounding_box(P: Polytope) -> Box:
    """The rigorous bounding box of P (:meth:`Polytope.bounding_box`), a Box of
    dimension n with infinite bounds where P is unbounded."""
    if P.is_empty():
        raise EmptySetError("an empty polytope has no bounding box")
    n = P.dim
    E = np.vstack([np.eye(n), -np.eye(n)])
    try:
        bounded = P.is_bounded()
    except SolverError:
        bounded = None  # undecided: the LP values below tell
    if bounded is not False and P._rows().An.shape[0]:
        h = P._support_upper(E)
        if not np.isfinite(h).all() and "vertices" in P._cache:
            # from_vertices: the rows describe the hull of the points up to rounding
            hv = np.asarray(P.support(E))
            with np.errstate(invalid="ignore"):
                hv = hv + (1e-12 * np.abs(hv) + 4 * np.abs(np.spacing(hv)))
            h = np.where(np.isfinite(h), h, hv)
        if not np.isfinite(h).all():
            h = np.where(np.isfinite(h), h, support_lp_outward(P, E))
    else:
        h = support_lp_outward(P, E)
    hi, lo = h[:n], -h[n:]
    hi = np.where(np.isnan(hi), np.inf, hi)
    lo = np.where(np.isnan(lo), -np.inf, lo)
    return Box(np.minimum(lo, hi), hi)


def support_lp_outward(P: Polytope, E: np.ndarray) -> np.ndarray:
    """LP values of the support function in the directions E, widened outward by
    ``1e-12`` relative (``+inf`` where unbounded or where no LP could be solved)."""
    vals, _ = P._max_lp(E, multipliers_only=True)
    h = np.where(np.isnan(vals), np.inf, vals)
    with np.errstate(invalid="ignore"):
        h = h + (1e-12 * np.abs(h) + 4 * np.abs(np.spacing(h)))
    return np.where(np.isnan(h), np.inf, h)


def minimal(P: Polytope) -> Polytope:
    """P without redundant rows (:meth:`Polytope.minimal`; cached on P)."""
    from .polytope import Polytope

    if P._cache.get("minimal") is True:
        return P
    m_cached = P._cache.get("minimal_poly")
    if m_cached is not None:
        return m_cached
    n = P.dim
    if P.is_empty():
        return Polytope.empty(n)
    R = P._rows()
    A, b, An, bn, tol = R.A, R.b, R.An, R.bz0, RTOL
    m = An.shape[0]
    # exact duplicate normals: keep the smallest right-hand side
    order = np.lexsort((bn, *An.T[::-1]))
    keep = np.ones(m, dtype=bool)
    same = np.all(An[order][1:] == An[order][:-1], axis=1)
    keep[order[1:][same]] = False
    idx = np.flatnonzero(keep)
    vals = row_maxima(An, bn, idx, idx)
    essential = idx[vals > bn[idx] + tol]
    cand = idx[vals <= bn[idx] + tol]
    if cand.size:
        vals2 = row_maxima(An, bn, cand, essential)
        cand = cand[vals2 > bn[cand] + tol]
        alive = set(cand.tolist())
        for i in cand.tolist():
            others = np.array(sorted(set(essential.tolist()) | (alive - {i})), dtype=int)
            v = row_maxima(An, bn, np.array([i]), others)[0]
            if v <= bn[i] + tol:
                alive.discard(i)
        essential = np.array(sorted(set(essential.tolist()) | alive), dtype=int)
    out = Polytope(A[essential], b[essential])
    for key in ("empty", "bounded", "cheb", "vertices"):
        if key in P._cache:
            out._cache[key] = P._cache[key]
    out._cache["minimal"] = True
    P._cache["minimal_poly"] = out
    return out


def row_maxima(An: np.ndarray, bn: np.ndarray, test: np.ndarray,
               against: np.ndarray) -> np.ndarray:
    """``max a_i.x`` s.t. rows ``against`` (row i itself relaxed by 1), i in ``test``.

    ``An`` (m, n) and ``bn`` (m,) are the scaled rows, ``test`` and ``against`` index
    arrays into them; one stacked LP, values of shape ``(len(test),)`` (``inf`` where
    unbounded).
    """
    K = test.size
    if K == 0:
        return np.zeros(0)
    blocks_A, blocks_b, blk = [], [], []
    for k, i in enumerate(test.tolist()):
        rows = against[against != i]
        blocks_A.append(An[rows])
        blocks_b.append(bn[rows])
        blocks_A.append(An[[i]])
        blocks_b.append(bn[[i]] + max(1.0, abs(bn[i])))
        blk.append(np.full(rows.size + 1, k))
    res = _lp.block_lp(-An[test], np.vstack(blocks_A), np.concatenate(blocks_b),
                       np.concatenate(blk))
    _lp.check_status(res.status, "the redundancy test")
    vals = -res.fun
    vals[res.status == _lp.UNBOUNDED] = np.inf
    return vals


def _frac_up(v: Fraction) -> float:
    """The smallest float ``>= v`` (up to one ulp)."""
    f = float(v)
    if Fraction(f) < v:
        f = math.nextafter(f, math.inf)
    return f


def _farkas_empty(A: np.ndarray, b: np.ndarray, y: np.ndarray) -> bool:
    """Exact proof that ``{x : A x <= b}`` is empty, guided by approximate multipliers.

    On the support of ``y`` (dropping its smallest entries one at a time), the exact
    null space of ``A_S^T`` is computed; a one-dimensional null space spanned by
    ``v >= 0`` with ``b_S.v < 0`` is a Farkas certificate: ``0 = v^T A x <= v.b < 0``.
    """
    y = np.where(np.isfinite(y), y, 0.0)
    if y.size == 0 or y.max(initial=0.0) <= 0.0:
        return False
    order = np.argsort(-y)
    S = [int(i) for i in order if y[i] > 1e-12 * y.max()]
    n = A.shape[1]
    while len(S) >= 1:
        k = len(S)
        M = [[Fraction(float(A[i, j])) for i in S] for j in range(n)]
        basis = rat_nullspace(M, k)
        if len(basis) == 1:
            v = basis[0]
            if sum(v) < 0:
                v = [-x for x in v]
            if all(x >= 0 for x in v) and \
                    sum((x * Fraction(float(b[i])) for x, i in zip(v, S, strict=True)),
                        Fraction(0)) < 0:
                return True
            return False
        if not basis:
            return False
        S = S[:-1]
    return False
