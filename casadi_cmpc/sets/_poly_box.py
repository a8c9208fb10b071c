"""Box tests of a polytope beyond the closed-form kernel: ``intersects_box`` in stages.

Stage 1 and the complete set of separating directions of a bounded 2-D or 3-D polytope
(:func:`sat_kernel`) run in closed form on :class:`~casadi_cmpc.sets._boxkernel.BoxKernel`
rows; the remaining boxes are tried with interior points and then with one LP each, whose
multipliers give separating inequalities checked with a rigorous rounding bound
(:func:`~casadi_cmpc.sets._boxkernel._certify_separation`). ``False`` is always a proof.
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING, Any

import numpy as np

from .._validate import as_boxes
from ..exceptions import SolverError
from . import _lp, _poly_project
from ._boxkernel import BoxKernel, _certify_separation, points_le

if TYPE_CHECKING:
    from .polytope import Polytope

__all__: list[str] = []


def intersects_box(P: Polytope, boxes: Any) -> np.ndarray:
    """Whether the boxes (array_like (N, n, 2) or (n, 2), or Box) meet P: (N,) bool,
    ``False`` only when proven (the stages of :meth:`Polytope.intersects_box`)."""
    bx = as_boxes(boxes, P.dim, "boxes")
    N = bx.shape[0]
    R = P._rows()
    if R.empty:
        return np.zeros(N, dtype=bool)
    out = np.ones(N, dtype=bool)
    if R.A.shape[0] == 0 or N == 0:
        return out
    if P.dim in (2, 3):
        sat = sat_kernel(P)
        if sat is not None:  # stages 1 and 2 in one closed-form pass
            return ~sat.separates(bx)
    sep = P._kernel().separates(bx)
    out[sep] = False
    und = np.flatnonzero(~sep)
    if und.size == 0 or P.dim == 1:  # stage 1 is complete on the line
        return out
    if P.is_empty():
        out[und] = False
        return out
    sub = bx[und]
    lo, hi = sub[..., 0], sub[..., 1]
    with np.errstate(invalid="ignore"):
        mid = 0.5 * (lo + hi)
    mid = np.where(np.isfinite(mid), mid, np.clip(0.0, lo, hi))
    near = np.clip(P._chebyshev()[0], lo, hi)
    hit = points_le(mid, R.A, R.b) | points_le(near, R.A, R.b)
    und = und[~hit]
    if und.size:
        out[und] = ~lp_separated(P, bx[und])
    return out


def sat_kernel(P: Polytope) -> BoxKernel | None:
    """Rows of P and separating directions of its projections (n = 2, 3), or None.

    For a bounded full-dimensional P the facet normals of ``P ⊕ box`` are facet
    normals of P or (lifted) facet normals of the projections of P on proper subsets
    of the coordinates, whatever the box; so a box misses P iff one of these rows
    separates it. The offsets of the lifted rows are rigorous upper bounds of the
    support function (:meth:`Polytope._support_upper`), so a separation is a proof.
    """
    if "sat" in P._cache:
        return P._cache["sat"]
    n = P.dim
    sat = None
    try:
        if n in (2, 3) and not P.is_empty() and P.is_bounded() \
                and P.is_full_dimensional():
            R = P._rows()
            rows, rhs = [R.A], [R.b]
            for k in range(1, n):
                for T in itertools.combinations(range(n), k):
                    # a bounded effort: an ill-conditioned P whose projection does
                    # not settle falls back to the general stages (conservative)
                    Q = _poly_project.project_support(P, list(T), max_rounds=60)
                    QR = Q._rows()
                    lifted = np.zeros((QR.A.shape[0], n))
                    lifted[:, list(T)] = QR.A
                    h = P._support_upper(lifted)
                    ok = np.isfinite(h)
                    if not ok.all():
                        # a missing direction would make "not separated" no proof of
                        # intersection: use the general stages instead
                        raise SolverError("no rigorous offset for a projection facet")
                    rows.append(lifted)
                    rhs.append(h)
            sat = BoxKernel(np.vstack(rows), np.concatenate(rhs))
    except SolverError:
        sat = None  # the general stages of intersects_box decide (conservatively)
    P._cache["sat"] = sat
    return sat


def lp_separated(P: Polytope, bx: np.ndarray) -> np.ndarray:
    """Stage 4 of :meth:`Polytope.intersects_box`: proven separation of the boxes ``bx``
    (K, n, 2) from P by LP multipliers, (K,) bool."""
    R = P._rows()
    K, n = bx.shape[0], P.dim
    m = R.An.shape[0]
    rows = np.hstack([R.An, np.ones((m, 1))])
    C = np.zeros((K, n + 1))
    C[:, -1] = -1.0
    with np.errstate(invalid="ignore", over="ignore"):
        zlo = (bx[..., 0] - R.c0) / R.s
        zhi = (bx[..., 1] - R.c0) / R.s
    lb = np.hstack([zlo, np.full((K, 1), -np.inf)])
    ub = np.hstack([zhi, np.zeros((K, 1))])
    res = _lp.block_lp(C, np.tile(rows, (K, 1)), np.tile(R.bz, K),
                       np.repeat(np.arange(K), m), lb, ub)
    r = res.x[:, -1]
    cand = (res.status == _lp.OPTIMAL) & (r < 0.0)
    proven = np.zeros(K, dtype=bool)
    idx = np.flatnonzero(cand)
    if idx.size == 0:
        return proven
    Y = R.raw_multipliers(res.y.reshape(K, m)[idx])  # multipliers of the raw rows
    proven[idx] = _certify_separation(Y, R.A, R.b, bx[idx])
    return proven
