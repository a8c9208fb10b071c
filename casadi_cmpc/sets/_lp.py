"""Batched linear programs solved by HiGHS (``scipy.optimize.linprog(method="highs")``).

Many small independent LPs that share the number of variables are stacked into one
block-diagonal LP: one solver call instead of one per problem (the call overhead of
``linprog`` dominates small problems).  Blocks are solved in chunks to keep each LP small.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from ..exceptions import SolverError

__all__: list[str] = []

#: HiGHS feasibility tolerances used by every LP of the set library.
HIGHS_OPTIONS = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}
#: Largest number of constraint rows in one stacked LP.
_CHUNK_ROWS = 4000

OPTIMAL, INFEASIBLE, UNBOUNDED, NUMERICAL = 0, 2, 3, 4


@dataclass
class BlockLPResult:
    """Solutions of ``K`` independent LPs ``min c_k.x_k`` s.t. ``A_k x_k <= b_k``, bounds.

    Attributes
    ----------
    status : ndarray of int, shape (K,)
        0 optimal, 2 infeasible, 3 unbounded, 4 numerical trouble (scipy's codes).
    x : ndarray, shape (K, p)
        Minimisers (NaN rows where ``status != 0``).
    fun : ndarray, shape (K,)
        Optimal values (``+inf`` infeasible, ``-inf`` unbounded, NaN numerical trouble).
    y : ndarray, shape (R,)
        Lagrange multipliers ``>= 0`` of the rows (``c + A^T y`` is then the reduced cost);
        NaN where ``status != 0``.
    """

    status: np.ndarray
    x: np.ndarray
    fun: np.ndarray
    y: np.ndarray


def _solve_one(c: np.ndarray, A: sp.spmatrix | np.ndarray | None, b: np.ndarray | None,
               bounds: np.ndarray) -> tuple[int, np.ndarray | None, float, np.ndarray | None]:
    res = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs", options=HIGHS_OPTIONS)
    if res.status == 0:
        y = None if A is None else -np.asarray(res.ineqlin.marginals, dtype=float)
        return 0, np.asarray(res.x, dtype=float), float(res.fun), y
    if res.status == 2:
        return INFEASIBLE, None, np.inf, None
    if res.status == 3:
        return UNBOUNDED, None, -np.inf, None
    return NUMERICAL, None, np.nan, None


def block_lp(C: np.ndarray, rows_A: np.ndarray, rows_b: np.ndarray, row_block: np.ndarray,
             lb: np.ndarray | float = -np.inf, ub: np.ndarray | float = np.inf
             ) -> BlockLPResult:
    """Solve ``K`` independent LPs with ``p`` variables each.

    Parameters
    ----------
    C : ndarray, shape (K, p)
        Objective of each block (minimised).
    rows_A : ndarray, shape (R, p)
        All constraint rows ``a.x_k <= b``, grouped by block (``row_block`` non-decreasing).
    rows_b : ndarray, shape (R,)
        Right-hand sides, finite or ``+inf`` (a row that constrains nothing: left out, its
        multiplier 0).
    row_block : ndarray of int, shape (R,)
        Block index of each row, non-decreasing.
    lb, ub : float or ndarray broadcastable to (K, p)
        Variable bounds (may be infinite).

    Returns
    -------
    BlockLPResult
    """
    C = np.atleast_2d(np.asarray(C, dtype=float))
    K, p = C.shape
    rows_A = np.asarray(rows_A, dtype=float).reshape(-1, p)
    rows_b = np.asarray(rows_b, dtype=float).ravel()
    row_block = np.asarray(row_block, dtype=np.int64).ravel()
    if np.isnan(rows_b).any() or (rows_b == -np.inf).any():
        raise ValueError("a linear program got a row a.x <= b with b = -inf or NaN (for a "
                         "polytope: a row with b / |a| below -1.8e308, which no point of "
                         "the floating-point range satisfies); rescale the data")
    LB = np.broadcast_to(np.asarray(lb, dtype=float), (K, p))
    UB = np.broadcast_to(np.asarray(ub, dtype=float), (K, p))
    if row_block.size and np.any(np.diff(row_block) < 0):
        raise ValueError("block_lp: rows must be grouped by block (row_block non-decreasing)")
    status = np.full(K, NUMERICAL, dtype=int)
    X = np.full((K, p), np.nan)
    fun = np.full(K, np.nan)
    Y = np.full(rows_b.size, np.nan)
    if K == 0:
        return BlockLPResult(status, X, fun, Y)
    # first row of each block (blocks without rows have start == end)
    starts = np.searchsorted(row_block, np.arange(K + 1))
    k0 = 0
    while k0 < K:
        # grow the chunk until it has _CHUNK_ROWS rows (at least one block)
        k1 = int(np.searchsorted(starts, starts[k0] + _CHUNK_ROWS, side="right")) - 1
        k1 = min(max(k1, k0 + 1), K)
        _solve_chunk(C, rows_A, rows_b, row_block, LB, UB, starts, k0, k1, status, X, fun, Y)
        k0 = k1
    return BlockLPResult(status, X, fun, Y)


def _solve_chunk(C, rows_A, rows_b, row_block, LB, UB, starts, k0, k1, status, X, fun, Y):
    p = C.shape[1]
    r0, r1 = int(starts[k0]), int(starts[k1])
    nb = k1 - k0
    c = C[k0:k1].ravel()
    bounds = np.stack([LB[k0:k1].ravel(), UB[k0:k1].ravel()], axis=1)
    if r1 > r0:
        # a row with b = +inf constrains nothing: left out (multiplier 0)
        live = np.flatnonzero(rows_b[r0:r1] < np.inf)
        A_rows = rows_A[r0:r1][live]
        rr = np.repeat(np.arange(live.size), p)
        cc = ((row_block[r0:r1][live] - k0)[:, None] * p + np.arange(p)).ravel()
        data = A_rows.ravel()
        keep = data != 0.0
        A = sp.csr_matrix((data[keep], (rr[keep], cc[keep])), shape=(live.size, nb * p))
        b = rows_b[r0:r1][live]
        if not live.size:
            A, b = None, None
    else:
        A, b, live = None, None, np.zeros(0, dtype=np.intp)
    st, x, f, y = _solve_one(c, A, b, bounds)
    if st == OPTIMAL:
        X[k0:k1] = x.reshape(nb, p)
        blk_fun = (C[k0:k1] * X[k0:k1]).sum(axis=1)
        fun[k0:k1] = blk_fun
        status[k0:k1] = OPTIMAL
        Y[r0:r1] = 0.0
        if y is not None:
            Y[r0 + live] = np.maximum(y, 0.0)
        return
    if nb == 1:
        status[k0] = st
        fun[k0] = f
        return
    # one block infeasible or unbounded spoils the stacked LP: solve the blocks one by one
    for k in range(k0, k1):
        _solve_chunk(C, rows_A, rows_b, row_block, LB, UB, starts, k, k + 1, status, X, fun, Y)


def lp(c: np.ndarray, A: np.ndarray, b: np.ndarray, lb: np.ndarray | float = -np.inf,
       ub: np.ndarray | float = np.inf) -> tuple[int, np.ndarray, float, np.ndarray]:
    """Solve one LP ``min c.x  s.t.  A x <= b, lb <= x <= ub``.

    Returns
    -------
    status : int
    x : ndarray, shape (p,)
    fun : float
    y : ndarray, shape (m,)
        Multipliers ``>= 0`` of the rows.
    """
    c = np.asarray(c, dtype=float).ravel()
    A = np.asarray(A, dtype=float).reshape(-1, c.size)
    res = block_lp(c[None], A, b, np.zeros(A.shape[0], dtype=np.int64), lb, ub)
    return int(res.status[0]), res.x[0], float(res.fun[0]), res.y


def check_status(status: np.ndarray | int, what: str) -> None:
    """Raise :class:`SolverError` when some LP reported numerical trouble."""
    if np.any(np.asarray(status) == NUMERICAL):
        raise SolverError(f"HiGHS could not solve the linear program for {what} "
                          "(numerical difficulties); rescale the polytope data")
