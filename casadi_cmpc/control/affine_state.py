"""One-step controllable sets of models with an affine state part (thesis §6.2, Alg 6.4-6.6).

For ``x+ = A x + g(x_NL, u, w)``, where only the states ``x_NL``
(:attr:`~casadi_cmpc.Model.nonlinear_states`) enter nonlinearly, the one-step set of a
polytope ``T = {y : H y <= h}`` splits into polytopes: for a box ``B`` of ``x_NL`` and a
control ``u``, every ``x`` with ``x_NL in B`` and

    H A x <= h - sup { H g(x_NL, u, w) : x_NL in B, w in W }

reaches T under ``u`` for every w. Only ``x_NL`` and ``U`` are gridded (Alg 6.4): the cost
grows with the number of nonlinear states and controls, not with n. The union of these
pieces is approximated by one polytope with Alg 6.2 or 6.5
(:func:`~casadi_cmpc.inner_polytope`), and the recursion over such polytopes gives the
sequence of controllable sets (Alg 6.6's sets).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ..exceptions import DimensionError, ModelError
from ..model import Model
from ..sets import _lp
from ..sets._poly_lp import RTOL
from ..sets._zono_num import imatmul
from ..sets.box import Box
from ..sets.polytope import Polytope, PolytopeUnion

__all__ = ["affine_state_pieces", "union_volume"]

#: largest number of control candidates per x_NL box
MAX_CONTROLS = 4096
#: pairs (x_NL box, control) evaluated in one batch
CHUNK = 65536


def _structure(model: Model, D: Box) -> tuple[tuple[int, ...], tuple[int, ...], np.ndarray]:
    """(nonlinear states, linear states, interval enclosure (n, n_L, 2) of the constant
    columns of A = df/dx_L). The enclosure is the interval Jacobian over the domain: a
    constant column is enclosed (outward) whatever the box."""
    nl = tuple(model.nonlinear_states)
    lin = tuple(model.linear_states)
    if not lin:
        raise ModelError(
            f"model '{model.name}' has no state that enters f only linearly (nonlinear "
            f"states: {list(nl)}): method='affine_state' needs f = A x + g(x_NL, u, w); "
            "use method='general'")
    Wb = model.W.as_array()[None] if model.W is not None else None
    J = np.asarray(model.jacobian_inclusion("x")(D.as_array()[None], model.U.as_array()[None],
                                                 Wb), dtype=float)[0]  # (n, n, 2)
    A = J[:, list(lin), :]
    if not np.isfinite(A).all():
        raise ModelError("the constant columns of A (df/dx of the linear states) have no "
                         "finite enclosure")
    return nl, lin, A


def _grid_boxes(lo: np.ndarray, hi: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Regular grid of boxes (N, d, 2) on [lo, hi]: per component ``2^k`` cells, the first
    power of two with cells at most ``widths`` wide (the boxes a bisection to that
    tolerance reaches; neighbouring boxes share their edges); one box (1, 0, 2) for d = 0."""
    d = lo.size
    if d == 0:
        return np.zeros((1, 0, 2))
    edges = []
    for j in range(d):
        k = 1  # the cells a bisection reaches: halve while wider than the tolerance
        while (hi[j] - lo[j]) / k > widths[j]:
            k *= 2
        e = lo[j] + (hi[j] - lo[j]) * np.arange(k + 1) / k
        e[0], e[-1] = lo[j], hi[j]
        edges.append(e)
    idx = np.stack(np.meshgrid(*[np.arange(e.size - 1) for e in edges], indexing="ij"),
                   axis=-1).reshape(-1, d)
    out = np.empty((idx.shape[0], d, 2))
    for j, e in enumerate(edges):
        out[:, j, 0] = e[idx[:, j]]
        out[:, j, 1] = e[idx[:, j] + 1]
    return out


def _controls(U: Box, u_eps: float) -> np.ndarray:
    """Candidate controls (C, m): per component the midpoints of the cells of every level of
    the dyadic bisection of U down to cells of width at most ``u_eps`` times U's width
    (the controls a bisection of U would try: 1 + 2 + 4 + ... values), combined."""
    lo, hi = U.lo, U.hi
    levels = max(0, math.ceil(math.log2(1.0 / u_eps) - 1e-9))
    axes = []
    for j in range(lo.size):
        vals = [lo[j] + (hi[j] - lo[j]) * (np.arange(2 ** L) + 0.5) / 2 ** L
                for L in range(levels + 1)]
        axes.append(np.unique(np.concatenate(vals)))
    total = int(np.prod([a.size for a in axes]))
    if total > MAX_CONTROLS:
        raise ValueError(f"u_eps = {u_eps} gives {total} candidate controls per box (more than "
                         f"{MAX_CONTROLS}); choose a larger u_eps")
    if lo.size == 0:
        return np.zeros((1, 0))
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, lo.size)


def _member_rows(members: list[Polytope], A: np.ndarray, D_lin: Box
                 ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Per target member ``H y <= h``: ``(H, h, M, s)`` with ``M`` (t, n_L) the midpoint of
    the interval product ``H A`` and ``s`` (t,) an upper bound of
    ``sup_{x_L in D_L} |(H A - M) x_L|`` (radius of the product times the largest |x_L|):
    for every x_L of D_L, ``(H A) x_L <= M x_L + s`` in exact arithmetic."""
    xmax = np.maximum(np.abs(D_lin.lo), np.abs(D_lin.hi))
    out = []
    for P in members:
        H = np.asarray(P.A, dtype=float)
        h = np.asarray(P.b, dtype=float)
        lo, hi = imatmul(H, H, A[..., 0], A[..., 1])  # (t, n_L), outward
        M = 0.5 * lo + 0.5 * hi
        rad = np.nextafter(np.maximum(hi - M, M - lo), np.inf)
        s = (rad * xmax).sum(axis=1)
        # nonnegative terms: a relative margin covers the rounding of products and sum
        s = np.nextafter(s * (1.0 + 4.0 * (xmax.size + 2) * np.finfo(float).eps)
                         + np.finfo(float).tiny, np.inf)
        out.append((H, h, M, s))
    return out


def _undominated(C: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Per cell, the candidates (rows of C (nb, k, t)) with ``ok`` (nb, k) not dominated
    by another ok one of the same cell (``C[j] >= C[i]`` everywhere, strictly somewhere,
    or equal with a smaller index): with equal normals, the piece of a dominated offset
    lies inside the piece of the dominating one. Returns a bool mask (nb, k)."""
    k = C.shape[1]
    Cj = np.where(ok[..., None], C, -np.inf)  # a candidate not kept dominates nothing
    ge = (Cj[:, None, :, :] >= C[:, :, None, :]).all(axis=3)  # ge[c, i, j]: C[j] >= C[i]
    gt = (Cj[:, None, :, :] > C[:, :, None, :]).any(axis=3)
    earlier = np.tril(np.ones((k, k), dtype=bool), -1)  # earlier[i, j]: j < i
    dom = ge & (gt | earlier[None]) & ok[:, None, :]
    dom &= ~np.eye(k, dtype=bool)[None]
    return ok & ~dom.any(axis=2)


def _polytope(A: np.ndarray, b: np.ndarray) -> Polytope:
    """A Polytope of rows built here (finite, shapes checked by construction), without the
    validation of the public constructor; A and b are read-only and used as they are (A
    is shared by the pieces, b is a row of a read-only array)."""
    P = object.__new__(Polytope)
    P.A, P.b, P._cache = A, b, {}
    return P


def _useful_intervals(a: np.ndarray, C: np.ndarray, D_lin: Box) -> list[tuple[int, int]]:
    """:func:`_useful` with one linear state for every cell at once: C (nb, k, t) offsets,
    a (t,) the rows' coefficients of x_L. Returns (cell, candidate) pairs whose interval
    ``{x in D_L : a x <= C[cell, k]}`` is not empty and not inside another kept one of the
    same cell."""
    nb, k, _ = C.shape
    ok = np.isfinite(C).all(axis=2) & ~np.any((a == 0) & (C < 0), axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = C / np.where(a == 0, 1.0, a)
    hi = np.minimum(float(D_lin.hi[0]), np.where(a > 0, q, np.inf).min(axis=2))
    lo = np.maximum(float(D_lin.lo[0]), np.where(a < 0, q, -np.inf).max(axis=2))
    ok &= hi > lo
    lo = np.where(ok, lo, np.inf)
    hi = np.where(ok, hi, -np.inf)
    # inside[c, i, j]: candidate i's interval inside j's (equal ones: keep the first)
    inside = (lo[:, None, :] <= lo[:, :, None]) & (hi[:, :, None] <= hi[:, None, :])
    same = (lo[:, None, :] == lo[:, :, None]) & (hi[:, None, :] == hi[:, :, None])
    earlier = np.tril(np.ones((k, k), dtype=bool), -1)
    inside &= ~same | earlier[None]
    inside &= ~np.eye(k, dtype=bool)[None]
    inside &= ok[:, None, :]  # only kept intervals absorb others
    keep = ok & ~inside.any(axis=2)
    cells, cands = np.nonzero(keep)
    return list(zip(cells.tolist(), cands.tolist(), strict=True))


def _useful(M: np.ndarray, C: np.ndarray, D_lin: Box) -> list[tuple[int, int]]:
    """(cell, candidate) pairs worth keeping among the x_L slices
    ``{x_L in D_L : M x_L <= C[cell, k]}`` (C: (nb, k, t)), with several linear states:
    a slice is kept when its offsets are finite and not below the rows' minimum over D_L,
    it is not dominated by another of its cell (:func:`_undominated`) and it has an
    interior (a point found by projections, else a Chebyshev LP; all cells at once).
    Only the size of the approximation depends on this choice (a dropped slice is never
    needed for soundness). One linear state: :func:`_useful_intervals`."""
    # a row whose offset is below its minimum over D_L leaves nothing (exact necessary test)
    low = (np.minimum(M * D_lin.lo, M * D_lin.hi)).sum(axis=1)
    ok = np.isfinite(C).all(axis=2) & (C >= low).all(axis=2)
    if ok.any():
        ok = _undominated(C, ok)
    cells, cands = np.nonzero(ok)
    if cells.size:
        Ck = C[cells, cands]
        inside = _interior_point(M, Ck, D_lin)
        if not inside.all():
            inside[~inside] = _chebyshev_positive(M, Ck[~inside], D_lin)
        cells, cands = cells[inside], cands[inside]
    return list(zip(cells.tolist(), cands.tolist(), strict=True))


def _chebyshev_positive(M: np.ndarray, C: np.ndarray, D_lin: Box) -> np.ndarray:
    """Whether ``{x in D_L : M x <= C[k]}`` has a Chebyshev ball of radius above
    ``RTOL`` times D_L's largest half-width, per row of C (K, t): all K Chebyshev LPs in
    one batched HiGHS call. Only sizes the list of pieces (nothing is claimed from it)."""
    K, t = C.shape
    n_l = M.shape[1]
    nrm = np.linalg.norm(M, axis=1)
    live = nrm > 0  # zero rows passed the offset test: satisfied on all of D_L
    Mn = M[live] / nrm[live, None]
    I = np.eye(n_l)
    # rows (a, ||a||) . (x, r) <= b: the scaled rows, then x + r <= hi and -x + r <= -lo
    A1 = np.vstack([np.hstack([Mn, np.ones((Mn.shape[0], 1))]),
                    np.hstack([I, np.ones((n_l, 1))]), np.hstack([-I, np.ones((n_l, 1))])])
    R = A1.shape[0]
    b = np.concatenate([C[:, live] / nrm[live],
                        np.broadcast_to(D_lin.hi, (K, n_l)),
                        np.broadcast_to(-D_lin.lo, (K, n_l))], axis=1)
    half = float(np.max(0.5 * (D_lin.hi - D_lin.lo), initial=0.0))
    obj = np.zeros((K, n_l + 1))
    obj[:, -1] = -1.0  # maximise r
    ub = np.full((K, n_l + 1), np.inf)
    ub[:, -1] = max(half, 1.0)
    lb = np.full((K, n_l + 1), -np.inf)
    # r may go negative (an empty slice): every LP of the batch is feasible, so that the
    # stacked LP is solved in one piece (one infeasible block would make it infeasible)
    xm = float(np.linalg.norm(np.maximum(np.abs(D_lin.lo), np.abs(D_lin.hi))))
    lb[:, -1] = -(np.abs(b).max(axis=1) + xm + 1.0)
    res = _lp.block_lp(obj, np.tile(A1, (K, 1)), b.ravel(),
                       np.repeat(np.arange(K), R), lb, ub)
    return (res.status == _lp.OPTIMAL) & (-res.fun > RTOL * max(half, np.finfo(float).tiny))


def _interior_point(M: np.ndarray, C: np.ndarray, D_lin: Box, sweeps: int = 30) -> np.ndarray:
    """Whether a point strictly inside ``{x in D_L : M x <= C[k]}`` is found, per row of C
    (K, t): cyclic projections onto the (slightly tightened) half-spaces and the box, from
    the box's centre, all candidates at once; a point with every inequality strict proves
    an interior (in floating point: the choice only sizes the list of pieces, no claim
    rests on it). False only means "not found" (an LP decides those)."""
    lo, hi = D_lin.lo, D_lin.hi
    K = C.shape[0]
    X = np.broadcast_to(0.5 * (lo + hi), (K, lo.size)).copy()
    nrm = (M * M).sum(axis=1)
    scale = np.maximum(1.0, np.abs(C).max(axis=1))
    Ct = C - 1e-9 * scale[:, None]  # aim slightly inside
    for _ in range(sweeps):
        for i in range(M.shape[0]):
            if nrm[i] == 0:
                continue
            viol = X @ M[i] - Ct[:, i]
            X -= np.maximum(viol, 0.0)[:, None] * M[i][None, :] / nrm[i]
        X = np.clip(X, lo, hi)
    strict = ((X @ M.T) < C).all(axis=1) & ((X > lo) & (X < hi)).all(axis=1)
    return strict


def affine_state_pieces(model: Model, members: list[Polytope], D: Box, eps: float, *,
                        robust: bool, u_eps: float, relative: bool, max_pairs: int,
                        time_limit: float | None) -> dict[str, Any]:
    """The pieces of Alg 6.4 for a target union of polytopes ``members``.

    Parameters
    ----------
    model : Model
        With at least one linear state.
    members : list of Polytope
        Target ``T = ∪ {y : H_j y <= h_j}`` in the state space (n).
    D : Box
        State domain (n): the pieces lie in it.
    eps : float
        Width of the grid cells of ``x_NL`` (relative to D's widths when ``relative``).
    robust : bool
        All w of W (True) or w at the centre of W.
    u_eps : float
        Candidate controls: the centres of a grid of U with cells of width ``u_eps`` times
        U's width.
    max_pairs, time_limit
        Budget: (x_NL box, control) pairs evaluated, seconds; a stopped run keeps the
        pieces found so far (all proven).

    Returns
    -------
    dict
        ``pieces`` list of Polytope (n), ``witness`` (K, m), ``member`` (K,) index of the
        member each piece reaches, ``box`` (K,) index of its x_NL box in ``boxes``
        (N, p, 2), ``slices`` list of Polytope (n_L) (the piece's x_L part), ``nl``,
        ``lin``, ``n_pairs``, ``complete`` (bool), ``seconds``.

    Notes
    -----
    **Claim of a piece.** Its stored rows are ``M x_L <= c`` (``M`` the midpoint of
    ``H A``), ``x_NL`` in its box and ``x`` in D. For every x satisfying them in exact
    arithmetic and every w (of W, or the centre of W), ``H f(x, u, w) <= h`` with u its
    witness: ``H f = (H A) x_L + H g(x_NL, u, w)``; ``(H A) x_L <= M x_L + s`` on D;
    ``H g <= b`` where ``b`` is the upper bound of the outward-rounded centered inclusion
    of the rows ``H f`` over the x_NL box × {u} × W with ``x_L = 0`` (f = A x + g, so
    f at x_L = 0 is g); and ``c = h - b - s`` is rounded downward.
    """
    t0 = time.perf_counter()
    from .controllable import _rows_inclusion

    n = model.n
    nl, lin, A = _structure(model, D)
    nl_l, lin_l = list(nl), list(lin)
    D_lin = Box(D.lo[lin_l], D.hi[lin_l])
    rows = _member_rows(members, A, D_lin)
    width = eps * np.where(D.diam > 0, D.diam, 1.0) if relative else np.full(n, eps)
    boxes = _grid_boxes(D.lo[nl_l], D.hi[nl_l], width[nl_l])
    ctrl = _controls(model.U, u_eps)
    C = ctrl.shape[0]
    Wb = _semantics(model, robust)[0][None]  # W, or the thin box at its centre, (1, l, 2)
    Ub = np.stack([ctrl, ctrl], axis=-1)  # (C, m, 2)
    pieces: list[Polytope] = []
    offs: list[np.ndarray] = []
    wit: list[np.ndarray] = []
    mem: list[int] = []
    bix: list[int] = []
    n_pairs = 0
    complete = True
    per_chunk = max(1, CHUNK // C)
    fulls = []
    for _, _, M, _ in rows:
        t = M.shape[0]
        Af = np.zeros((t + 2 * n, n))
        Af[:t, lin_l] = M
        Af[t:t + n] = np.eye(n)
        Af[t + n:] = -np.eye(n)
        fulls.append(Af)
    for start in range(0, boxes.shape[0], per_chunk):
        if n_pairs >= max_pairs or (time_limit is not None
                                    and time.perf_counter() - t0 > time_limit):
            complete = False
            break
        B = boxes[start:start + per_chunk]
        nb = B.shape[0]
        X = np.zeros((nb, C, n, 2))
        X[:, :, nl_l, :] = B[:, None, :, :]
        X = X.reshape(nb * C, n, 2)
        U = np.broadcast_to(Ub[None], (nb, C) + Ub.shape[1:]).reshape(nb * C, -1, 2)
        N = nb * C
        n_pairs += N
        for j, (H, h, M, s) in enumerate(rows):
            Afull = fulls[j]
            F = _rows_inclusion(model, H)
            R = np.asarray(F.evaluate_unchecked([X, np.ascontiguousarray(U), Wb], N)[0])
            ub = R[..., 1]  # (N, t)
            with np.errstate(invalid="ignore", over="ignore"):
                cc = np.nextafter(np.nextafter(h - ub, -np.inf) - s, -np.inf)
            cc = np.where(np.isnan(cc), -np.inf, cc).reshape(nb, C, -1)
            if M.shape[1] == 1:  # intervals: all cells at once
                kept = _useful_intervals(M[:, 0], cc, D_lin)
            else:
                kept = _useful(M, cc, D_lin)
            if not kept:
                continue
            ci, ck = np.asarray(kept, dtype=int).T
            K = ci.size
            off = cc[ci, ck]  # (K, t), a fresh array: the pieces' offsets are its rows
            lo_b = np.broadcast_to(D.lo, (K, n)).copy()
            hi_b = np.broadcast_to(D.hi, (K, n)).copy()
            lo_b[:, nl_l], hi_b[:, nl_l] = B[ci, :, 0], B[ci, :, 1]
            bvec = np.concatenate([off, hi_b, -lo_b], axis=1)
            bvec.setflags(write=False)  # rows are read-only views, shared by nothing else
            off.setflags(write=False)
            if Afull.flags.writeable:
                Afull.setflags(write=False)
            pieces.extend(_polytope(Afull, b) for b in bvec)
            offs.extend(off)
            wit.append(ctrl[ck])
            mem.extend([j] * K)
            bix.extend((start + ci).tolist())
    return {"pieces": pieces, "offsets": offs, "rows": [r[2] for r in rows],
            "D_lin": D_lin,
            "witness": (np.concatenate(wit, axis=0) if wit
                        else np.zeros((0, model.m))).reshape(-1, model.m),
            "member": np.asarray(mem, dtype=int), "box": np.asarray(bix, dtype=int),
            "boxes": boxes, "nl": nl, "lin": lin, "n_pairs": n_pairs,
            "complete": complete, "seconds": time.perf_counter() - t0}


def _cell_intervals(details: dict[str, Any]) -> dict[int, list[tuple[float, float]]]:
    """With one linear state: per x_NL cell (index into ``details["boxes"]``), the x_L
    intervals of its pieces, each rounded inward (every x with x_NL in the cell and x_L in
    the interval lies in the piece), sorted, not merged."""
    D_lin = details["D_lin"]
    out: dict[int, list[tuple[float, float]]] = {}
    for k, b in enumerate(details["box"]):
        a = details["rows"][details["member"][k]][:, 0]
        c = details["offsets"][k]
        with np.errstate(divide="ignore", invalid="ignore"):
            q = c / np.where(a == 0, 1.0, a)
        # {x : a x <= c}: x <= c/a for a > 0, x >= c/a for a < 0, rounded inward
        hi = min(float(D_lin.hi[0]), float(np.min(np.nextafter(q[a > 0], -np.inf),
                                                  initial=np.inf)))
        lo = max(float(D_lin.lo[0]), float(np.max(np.nextafter(q[a < 0], np.inf),
                                                  initial=-np.inf)))
        if hi > lo:
            out.setdefault(int(b), []).append((lo, hi))
    return out


def _merge(iv: list[tuple[float, float]]) -> list[list[float]]:
    """Union of closed intervals as disjoint ones (touching ones joined; exact)."""
    merged: list[list[float]] = []
    for lo, hi in sorted(iv):
        if merged and lo <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    return merged


def inner_boxes(details: dict[str, Any], D: Box) -> np.ndarray | None:
    """With one linear state: the union of the pieces as boxes (N, n, 2), each inside it
    (per x_NL box, the union of its x_L intervals, each interval rounded inward, merged
    where they overlap or touch). None with several linear states (the pieces are then
    not boxes)."""
    if details["D_lin"].dim != 1:
        return None
    boxes = details["boxes"]
    nl, lin = list(details["nl"]), list(details["lin"])
    out = []
    for b, iv in sorted(_cell_intervals(details).items()):
        for lo, hi in _merge(iv):
            B = D.as_array().copy()
            B[nl] = boxes[b]
            B[lin[0]] = (lo, hi)
            out.append(B)
    return np.asarray(out).reshape(len(out), D.dim, 2)


def _inside_on_cell(P: Polytope, cell: np.ndarray, nl: list[int], j: int
                    ) -> tuple[float, float] | None:
    """The x_j interval ``{t : x in P for every x with x_NL in cell, x_j = t}`` (other
    linear states absent: one linear state), rounded inward; None when empty."""
    A, b = np.asarray(P.A), np.asarray(P.b)
    aN = A[:, nl]
    m = np.maximum(aN * cell[:, 0], aN * cell[:, 1]).sum(axis=1)  # max over the cell
    m = np.nextafter(m + np.abs(m) * 4 * (len(nl) + 1) * np.finfo(float).eps
                     + np.finfo(float).tiny, np.inf)
    r = np.nextafter(b - m, -np.inf)
    a = A[:, j]
    if np.any((a == 0) & (r < 0)):
        return None
    with np.errstate(divide="ignore", invalid="ignore"):
        q = r / np.where(a == 0, 1.0, a)
    hi = float(np.min(np.nextafter(q[a > 0], -np.inf), initial=np.inf))
    lo = float(np.max(np.nextafter(q[a < 0], np.inf), initial=-np.inf))
    return (lo, hi) if hi > lo else None


def _slice_range(A: np.ndarray, b: np.ndarray, cells: np.ndarray, nl: list[int], j: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Outer bounds ``(lo, hi)`` (B,) of ``x_j`` over ``{x : A x <= b, x_nl in cell}`` for
    each cell (B, p, 2) of the x_NL grid, ``j`` the one remaining coordinate, in closed
    form: a row with ``a_j > 0`` gives ``x_j <= (b - min_cell a_nl.x_nl) / a_j``, one with
    ``a_j < 0`` a lower bound, and a row with ``a_j = 0`` that no point of the cell meets
    proves the slice empty (``lo = +inf``). The sums are rounded outward by an a-priori
    bound of their error, the quotients by one ulp; a NaN (an overflow) decides nothing.
    The bounds contain the exact range, which an LP may make tighter."""
    B, p = cells.shape[0], len(nl)
    k = A.shape[0]
    if k == 0:
        return np.full(B, -np.inf), np.full(B, np.inf)
    An = A[:, nl]  # (k, p)
    lo, hi = cells[:, None, :, 0], cells[:, None, :, 1]  # (B, 1, p)
    with np.errstate(over="ignore", invalid="ignore"):
        t = np.minimum(An[None] * lo, An[None] * hi)  # (B, k, p)
        m = b[None, :] - t.sum(axis=2)  # (B, k)
        mag = np.abs(b)[None, :] + (np.abs(An)[None] * np.maximum(np.abs(lo), np.abs(hi))
                                    ).sum(axis=2)
        g = (p + 3) * 2.0 ** -53 / (1 - (p + 3) * 2.0 ** -53)
        m_up = m + (g * mag + (p + 2) * 2.0 ** -1074) * (1 + 2.0 ** -52)
        a = A[:, j]
        q = m_up / np.where(a == 0, 1.0, a)[None, :]
        up = np.where(a[None, :] > 0, np.nextafter(q, np.inf), np.inf)
        dn = np.where(a[None, :] < 0, np.nextafter(q, -np.inf), -np.inf)
        hi_j = np.where(np.isnan(up), np.inf, up).min(axis=1)
        lo_j = np.where(np.isnan(dn), -np.inf, dn).max(axis=1)
        void = ((a[None, :] == 0) & (m_up < 0)).any(axis=1)
    lo_j[void] = np.inf
    return lo_j, hi_j


def scaled_polytope(details: dict[str, Any], prev: Polytope, D: Box, eps: float = 1e-3
                    ) -> Polytope | None:
    """Alg 6.5 for one linear state, with a proof that scales: the largest ``x0 + α (H -
    x0)`` (H the convex hull of the pieces and ``prev``, x0 the Chebyshev centre of
    ``prev``, α to ``eps`` by bisection, α = 1 tried first) proven inside the union of the
    pieces and ``prev``; None when no α > 0 is proven.

    **Proof.** Column by column of the x_NL grid: the x_L range of ``candidate ∩ D`` over
    the cell (rigorous support bounds, :meth:`Polytope._support_upper`) must lie in one
    interval of the union, on that cell, of the pieces' x_L intervals and of the x_L
    interval on which ``prev`` holds the whole cell (all rounded inward). Cells the
    candidate's rigorous bounding box misses are skipped. The proof is local to each cell,
    so its cost grows with the number of cells, not with the number of pieces.
    """
    nl, lin = list(details["nl"]), list(details["lin"])
    j = lin[0]
    boxes = details["boxes"]
    cover: dict[int, list[list[float]]] = {}
    per = _cell_intervals(details)
    for b in range(boxes.shape[0]):
        iv = list(per.get(b, []))
        got = _inside_on_cell(prev, boxes[b], nl, j)
        if got is not None:
            iv.append(got)
        if iv:
            cover[b] = _merge(iv)
    if not cover:
        return None
    pts = []
    for b, iv in cover.items():
        corners = np.stack(np.meshgrid(*[boxes[b, i] for i in range(len(nl))],
                                       indexing="ij"), axis=-1).reshape(-1, len(nl))
        for lo, hi in iv:
            for t in (lo, hi):
                X = np.empty((corners.shape[0], D.dim))
                X[:, nl] = corners
                X[:, j] = t
                pts.append(X)
    pts.append(prev.vertices())
    H = Polytope.convex_hull(np.concatenate(pts))
    x0 = prev.chebyshev_ball()[0]
    Dp = Polytope.from_box(D)
    e = np.zeros((2, D.dim))
    e[0, j], e[1, j] = 1.0, -1.0

    def prove(P: Polytope) -> bool:
        PD = P.intersect(Dp)
        if PD.is_empty():
            return False
        bb = PD.bounding_box().as_array()
        # first, per cell, the x_L range in closed form (no LP): sound outer bounds, so a
        # range inside a cover interval, or proven empty, settles the cell
        lo_c, hi_c = _slice_range(np.asarray(PD.A), np.asarray(PD.b), boxes, nl, j)
        for b in range(boxes.shape[0]):
            cell = boxes[b]
            if np.any(cell[:, 1] < bb[nl, 0]) or np.any(cell[:, 0] > bb[nl, 1]):
                continue  # the candidate does not reach this cell
            if lo_c[b] > hi_c[b]:
                continue  # proven: no point of the candidate over this cell
            iv = cover.get(b)
            if not iv:
                return False
            if any(a <= lo_c[b] and hi_c[b] <= c for a, c in iv):
                continue
            S = Polytope(np.vstack([PD.A, np.eye(D.dim)[nl], -np.eye(D.dim)[nl]]),
                         np.concatenate([PD.b, cell[:, 1], -cell[:, 0]]))
            if S.is_empty():  # numerically: bound its x_L by the candidate's (rigorous) box
                lo, hi = float(bb[j, 0]), float(bb[j, 1])
            else:
                up = S._support_upper(e)
                hi, lo = float(up[0]), -float(up[1])
            if not (np.isfinite(hi) and np.isfinite(lo)):
                return False
            if not any(a <= lo and hi <= c for a, c in iv):
                return False
        return True

    A, bH = np.asarray(H.A), np.asarray(H.b)

    def scaled(alpha: float) -> Polytope:
        Ax0 = A @ x0
        return Polytope(A, Ax0 + alpha * (bH - Ax0)).intersect(Dp)

    best = None
    if prove(scaled(1.0)):
        return scaled(1.0)
    lo_a, hi_a = 0.0, 1.0
    while hi_a - lo_a > eps:
        mid = 0.5 * (lo_a + hi_a)
        cand = scaled(mid)
        if prove(cand):
            lo_a, best = mid, cand
        else:
            hi_a = mid
    return best


def union_volume(details: dict[str, Any]) -> float:
    """Volume of the union of the pieces of :func:`affine_state_pieces` (its output, or a
    result's ``details``): per x_NL box, the volume of the union of its x_L slices (an exact
    union of intervals with one linear state, else a disjoint decomposition: each slice
    minus the earlier ones) times the box's volume. Pieces of different boxes overlap at
    most on faces."""
    boxes, box_index, D_lin = details["boxes"], details["box"], details["D_lin"]
    n_l = D_lin.dim
    I = np.eye(n_l)
    total = 0.0
    if n_l == 2:  # slabs between the crossings of the rows' lines (fast, same measure)
        for b in np.unique(box_index):
            ks = np.flatnonzero(box_index == b)
            rows = [details["rows"][details["member"][k]] for k in ks]
            vb = float(np.prod(boxes[b, :, 1] - boxes[b, :, 0])) if boxes.shape[1] else 1.0
            total += vb * _union_area_2d(rows, [details["offsets"][k] for k in ks], D_lin)
        return total
    for b in np.unique(box_index):
        sel = []
        for k in np.flatnonzero(box_index == b):
            M = details["rows"][details["member"][k]]
            sel.append(Polytope(np.vstack([M, I, -I]),
                                np.concatenate([details["offsets"][k], D_lin.hi, -D_lin.lo])))
        vb = float(np.prod(boxes[b, :, 1] - boxes[b, :, 0])) if boxes.shape[1] else 1.0
        total += vb * _union_of(sel)
    return total


def _union_area_2d(rows: list[np.ndarray], offsets: list[np.ndarray], D: Box) -> float:
    """Area of the union of the polygons ``{y in D : M_k y <= c_k}`` (D a 2-D box, M_k
    (t_k, 2), c_k (t_k,)), by vertical slabs: between consecutive x where two of the
    polygons' lines cross (or a vertical line stands), each polygon's section is an
    interval whose ends move linearly, and so does the length of their union; the area
    is the sum over the slabs of width times that length at the slab's middle. In floating
    point (a measure, not a claim: the pieces themselves are proven)."""
    K = len(rows)
    if K == 0:
        return 0.0
    t = max(r.shape[0] for r in rows)
    M = np.zeros((K, t, 2))
    C = np.full((K, t), np.inf)  # padding rows: 0 . y <= inf
    for k, (r, c) in enumerate(zip(rows, offsets, strict=True)):
        M[k, : r.shape[0]] = r
        C[k, : r.shape[0]] = c
    (x0, y0), (x1, y1) = D.lo, D.hi
    if not (x1 > x0 and y1 > y0):
        return 0.0
    # every line a . y = b of the polygons and of D
    A = np.concatenate([M.reshape(-1, 2), [[0.0, 1.0], [0.0, 1.0]]])
    B = np.concatenate([C.reshape(-1), [y0, y1]])
    keep = np.isfinite(B) & (np.abs(A).sum(axis=1) > 0)
    A, B = A[keep], B[keep]
    ev = [np.array([x0, x1])]
    vert = (A[:, 1] == 0) & (A[:, 0] != 0)
    ev.append(B[vert] / A[vert, 0])
    i, j = np.triu_indices(A.shape[0], 1)
    det = A[i, 0] * A[j, 1] - A[i, 1] * A[j, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = (B[i] * A[j, 1] - B[j] * A[i, 1]) / det
    ev.append(xc[(det != 0) & np.isfinite(xc)])
    xs = np.concatenate(ev)
    xs = np.unique(xs[(xs >= x0) & (xs <= x1)])
    if xs.size < 2:
        return 0.0
    width = np.diff(xs)
    mid = 0.5 * (xs[1:] + xs[:-1])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        rhs = C[None] - M[None, :, :, 0] * mid[:, None, None]  # (S, K, t): My y <= rhs
        My = M[None, :, :, 1]
        up = np.where(My > 0, rhs / np.where(My > 0, My, 1.0), np.inf).min(axis=2)
        lo = np.where(My < 0, rhs / np.where(My < 0, My, 1.0), -np.inf).max(axis=2)
    ok = np.where(My == 0, rhs >= 0, True).all(axis=2)
    up, lo = np.minimum(up, y1), np.maximum(lo, y0)
    ok &= up > lo
    lo = np.where(ok, lo, np.inf)
    up = np.where(ok, up, -np.inf)
    order = np.argsort(lo, axis=1)
    lo = np.take_along_axis(lo, order, axis=1)
    up = np.take_along_axis(up, order, axis=1)
    prev = np.concatenate([np.full((lo.shape[0], 1), -np.inf),
                           np.maximum.accumulate(up, axis=1)[:, :-1]], axis=1)
    with np.errstate(invalid="ignore"):
        add = np.maximum(0.0, up - np.maximum(lo, prev))
    length = np.where(np.isfinite(add), add, 0.0).sum(axis=1)
    return float((width * length).sum())


def _union_of(polys: list[Polytope]) -> float:
    """Lebesgue measure of a union of bounded polytopes of one dimension."""
    if not polys:
        return 0.0
    if polys[0].dim == 1:
        iv = sorted((float(P.vertices().min()), float(P.vertices().max())) for P in polys
                    if P.is_full_dimensional())
        tot, cur_lo, cur_hi = 0.0, None, None
        for lo, hi in iv:
            if cur_hi is None or lo > cur_hi:
                if cur_hi is not None:
                    tot += cur_hi - cur_lo
                cur_lo, cur_hi = lo, hi
            else:
                cur_hi = max(cur_hi, hi)
        if cur_hi is not None:
            tot += cur_hi - cur_lo
        return tot
    tot = 0.0
    for k, P in enumerate(polys):
        rest = PolytopeUnion([P], dim=P.dim)
        for Q in polys[:k]:
            rest = rest.difference(Q)
            if not len(rest):
                break
        tot += sum(R.volume() for R in rest if R.is_full_dimensional())
    return tot


def check_members(target: Any, n: int) -> list[Polytope]:
    """The target of the affine-state method as polytopes (a Polytope, a Box, a
    PolytopeUnion, or a SetUnion/list of these); anything else is refused."""
    from .controllable import _flatten

    items = _flatten(target)
    bad = sorted({type(S).__name__ for S in items if not isinstance(S, Polytope)})
    if bad:
        raise TypeError(f"method='affine_state' needs a polytopic target (Polytope, Box or "
                        f"unions of them); got {', '.join(bad)}")
    for S in items:
        if S.dim != n:
            raise DimensionError(f"the target has dimension {S.dim}; the model has n = {n}")
    return [S for S in items if not S.is_empty()]


def is_polytopic(target: Any) -> bool:
    """Whether every member of the target is a polytope (or a box)."""
    from .controllable import _flatten

    try:
        return all(isinstance(S, Polytope) for S in _flatten(target))
    except TypeError:
        return False


def affine_state_sequence(model: Model, T: Polytope, eps: float, *, robust: bool,
                          polytopic_method: str, max_steps: int, terminal_info: dict[str, Any],
                          D: Box, u_eps: float, relative: bool, until: np.ndarray | None,
                          max_pairs: int, time_limit: float | None, progress: bool | None,
                          rtol: float = 1e-3) -> Any:
    """The polytopic sequence of Alg 6.4-6.6: ``P_0 = T``, ``P_i`` a polytope proven inside
    the union of the pieces of the one-step set of ``P_{i-1}`` (Alg 6.4) and ``P_{i-1}``
    itself (Alg 6.2 or 6.5, :func:`~casadi_cmpc.inner_polytope`).

    Claim: a state of ``P_i`` outside ``P_{i-1}`` lies in a piece, so a stored control
    sends it into ``P_{i-1}`` for all w; hence ``level(x) = min {i : x in P_i}`` decreases
    at every step and x reaches T in at most ``level(x)`` steps. The sets need not be nested.
    The recursion stops when a polytope grows by less than ``rtol`` (relative volume) over
    its predecessor (``converged_at``; a stopping rule, not a proof that the maximal set is
    reached).
    """
    from tqdm.auto import tqdm

    from .controllable import about_model, proof_w_box
    from .linear_sets import SetSequence
    from .polytopic import inner_polytope

    t0 = time.perf_counter()
    _, _, semantics = _semantics(model, robust)
    seq = SetSequence(sets=[T], info={
        "model": model.name, "eps": eps, "robust": bool(robust), "semantics": semantics,
        "about": about_model(model, robust), "proof_W": proof_w_box(model, robust),
        "method": "affine state (Alg 6.4) with polytopic approximation "
                  f"({'Alg 6.5' if polytopic_method == 'scaling' else 'Alg 6.2'})",
        "polytopic": True, "state_names": list(model.state_names), **terminal_info})
    seq.status = "max_steps"
    prev = T
    vol_prev = T.volume()
    bar = tqdm(total=None, desc="controllable sets (affine state)", unit="step",
               disable=progress is False, delay=0 if progress else 2.0, leave=False)
    try:
        for i in range(1, max_steps + 1):
            ts = time.perf_counter()
            r = affine_state_pieces(model, [prev], D, eps, robust=robust, u_eps=u_eps,
                                    relative=relative, max_pairs=max_pairs,
                                    time_limit=time_limit)
            step: dict[str, Any] = {
                "boxes": np.zeros((0, model.n, 2)), "witness": r["witness"],
                "pieces": PolytopeUnion(r["pieces"], dim=model.n), "polytope": None,
                "boundary": 0, "n_pairs": r["n_pairs"]}
            if not r["pieces"]:
                P = None
            elif polytopic_method == "scaling" and len(r["lin"]) == 1:
                P = scaled_polytope(r, prev, D)
            else:
                B = inner_boxes(r, D)
                members = ([Polytope.from_box(Box(b[:, 0], b[:, 1])) for b in B]
                           if B is not None else list(r["pieces"]))
                got = inner_polytope(members + [prev], method=polytopic_method)
                P = got[0] if got[1].proved else None
            step["polytope"] = P
            step["seconds"] = time.perf_counter() - ts
            seq.steps.append(step)
            if P is None:  # nothing proven beyond P_{i-1}: the sequence stays
                seq.sets.append(prev)
                seq.converged_at = i
                seq.status = "converged" if r["complete"] else "budget"
                break
            seq.sets.append(P)
            vol = P.volume()
            bar.set_postfix_str(f"P_{i}: volume {vol:.4g}", refresh=False)
            bar.update(1)
            if not r["complete"]:
                seq.status = "budget"
                break
            if vol <= vol_prev * (1.0 + rtol):
                seq.converged_at = i
                seq.status = "converged"
                break
            if until is not None and np.all(P.contains(until)):
                seq.status = "until"
                break
            prev, vol_prev = P, vol
    except KeyboardInterrupt:
        seq.status = "interrupted"
    finally:
        bar.close()
    seq.info["seconds"] = time.perf_counter() - t0
    return seq


def _semantics(model: Model, robust: bool) -> tuple[Any, Any, str]:
    from .controllable import _w_setup

    return _w_setup(model, robust, None)
