"""One-step (pre-)sets and controllable-set sequences of linear models (thesis §3.4).

For ``x+ = A x + B u + E w + c`` with ``u`` in the box U and ``w`` in the box W,

    Pre(T) = {x : exists u in U such that A x + B u + E w + c in T for all w in W}

is, for a polytope ``T = {y : H y <= h}``, ``{x : A x ∈ S}`` with
``S = (T ⊖ E W) - c ⊕ (-B U)`` (the Pontryagin difference for the disturbance is exact
row by row for a box W; the Minkowski sum with the box image ``-B U`` is one segment per
input). :func:`pre_set` computes it in rational arithmetic (Fourier–Motzkin elimination
of each segment parameter, redundant rows dropped only with an exactly checked
certificate) and stores it as a float polytope rounded *inward*: every point of the
returned set is proven one-step controllable. For a union of polytopes
without disturbance, ``Pre(T_1 ∪ ... ∪ T_p) = Pre(T_1) ∪ ... ∪ Pre(T_p)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from ..exceptions import ModelError, SolverError, UnboundedSetError
from ..model import Model
from ..sets._exact import (
    ExactRow,
    exact_max,
    exact_row,
    fm_eliminate,
    frac_down,
    frac_up,
    lp_feasible,
    prune_rows,
    reduce_rows,
    round_rows_inward,
)
from ..sets.polytope import Polytope, PolytopeUnion

__all__ = ["pre_set", "linear_controllable_sets", "SetSequence"]

#: Largest inward move of a row while dropping rows that are redundant only up to a
#: margin (tiny facets that exact arithmetic finds where floating point sees one vertex),
#: relative to the scale of the coordinates (see ``reduce_rows``).
_SHRINK = 1e-12


def _check_linear(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    if not model.is_linear:
        raise ModelError(
            f"pre_set computes pre-sets of linear models only; model '{model.name}' is "
            "nonlinear (use the interval-based one-step sets for nonlinear models)")
    return model.linear_matrices()


def _exact_coefficients(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                               np.ndarray]:
    """``(A, B, E, c_mid, c_rad)`` of a linear model for an exact pre-set: A, B, E must be
    known exactly (thin enclosures, e.g. literal coefficients); c may be an interval
    (``|c - c_mid| <= c_rad``, entrywise), which the target rows absorb."""
    _check_linear(model)
    A, B, E, c = model.linear_enclosures()
    for name, M in (("A", A), ("B", B), ("E", E)):
        if not (np.isfinite(M).all() and (M[..., 0] == M[..., 1]).all()):
            raise ModelError(
                f"the coefficient matrix {name} of model '{model.name}' is not known exactly "
                "in floating point (a coefficient computed from constants, e.g. "
                "0.1 * 0.3 * x, or folded by a closed loop): an exact pre-set needs exact "
                "coefficients; write f with literal coefficients")
    if not np.isfinite(c).all():
        raise ModelError(f"the constant term of model '{model.name}' has no finite enclosure")
    cm_ = 0.5 * c[:, 0] + 0.5 * c[:, 1]
    cm_ = np.where(c[:, 0] == c[:, 1], c[:, 0], cm_)
    rad = np.maximum(c[:, 1] - cm_, cm_ - c[:, 0])
    rad = np.nextafter(rad, np.inf) * (rad > 0)
    return A[..., 0], B[..., 0], E[..., 0], cm_, rad


def _fr(M: np.ndarray) -> list:
    """Floats (any shape) as nested lists of exact Fractions."""
    return np.vectorize(lambda v: Fraction(float(v)), otypes=[object])(
        np.asarray(M, dtype=float)).tolist()


def _box_rows(lo: list[Fraction], hi: list[Fraction]) -> list[ExactRow]:
    """Exact rows ``z_j <= hi_j``, ``-z_j <= -lo_j`` of a box."""
    out = []
    for j, (bl, bh) in enumerate(zip(lo, hi, strict=True)):
        e = [0] * len(lo)
        e[j] = 1
        out.append(exact_row(e, bh))
        e[j] = -1
        out.append(exact_row(e, -bl))
    return out


def _image_box(M: list[list[Fraction]], lo: list[Fraction], hi: list[Fraction]
               ) -> tuple[list[Fraction], list[Fraction]]:
    """Exact interval hull ``[lo', hi']`` of ``{M z : z in [lo, hi]}``."""
    zero = Fraction(0)
    blo = [sum((min(v * a, v * b) for v, a, b in zip(row, lo, hi, strict=True)), zero)
           for row in M]
    bhi = [sum((max(v * a, v * b) for v, a, b in zip(row, lo, hi, strict=True)), zero)
           for row in M]
    return blo, bhi


def _pre_rows(model: Model, H: np.ndarray, h: np.ndarray, within_X: bool
              ) -> list[ExactRow] | None:
    """Exact rows in x of ``{x (in X) : A x ∈ S}``, ``S = (T ⊖ E W) - c ⊕ (-B U)``
    (None: empty; the rows of X are not included).

    ``T ⊖ E W`` is exact row by row for the box W; ``S`` is built by one Minkowski sum
    with a segment per input, ``S_j = S_{j-1} ⊕ G_j``, ``G_j = -b_j [lo_j, hi_j]``, i.e.
    ``{y : exists t in [lo_j, hi_j], y + b_j t in S_{j-1}}``, each an exact
    Fourier–Motzkin elimination of t in n + 1 coordinates with the redundant rows pruned
    (certified). Then ``Pre(T) = {x : A x ∈ S}`` (rows ``a A``), for any A. With
    ``within_X``, each ``S_j`` is intersected with a box ``Y_j`` (exact) without changing
    the result: ``Y_m ⊇ A X`` and ``Y_{j-1} = Y_j ⊕ (-G_j)``, so that a point of
    ``S_m ∩ Y_m`` is ``s + g`` with ``s = y - g`` in ``S_{m-1} ∩ Y_{m-1}``; the box rows
    keep every stage bounded and let nearly parallel rows be proven redundant.
    """
    A, B, E, c, c_rad = _exact_coefficients(model)
    n, m, nl = model.n, model.m, model.l
    Af, Bf, Ef, cf = _fr(A), _fr(B.reshape(n, m)), _fr(E.reshape(n, nl)), _fr(c)
    cr = _fr(c_rad)
    zero = Fraction(0)
    rows: list[ExactRow] = []
    for Hi_f, hi_f in zip(_fr(H), _fr(h), strict=True):
        # the constant term is only known within c_rad: the row holds for all of it
        beta = hi_f - sum((Hi_f[k] * cf[k] + abs(Hi_f[k]) * cr[k] for k in range(n)), zero)
        if nl:
            W = model.W
            for j, (wl, wh) in enumerate(zip(_fr(W.lo), _fr(W.hi), strict=True)):
                he = sum((Hi_f[k] * Ef[k][j] for k in range(n)), zero)
                beta -= max(he * wl, he * wh)
        rows.append(exact_row(Hi_f, beta))
    Ulo, Uhi = _fr(model.U.lo), _fr(model.U.hi)
    # stage boxes Y_m ⊇ A X, Y_{j-1} = Y_j ⊕ b_j [lo_j, hi_j]
    Ylo, Yhi = _image_box(Af, _fr(model.X.lo), _fr(model.X.hi))
    boxes = [(Ylo, Yhi)]
    for j in range(m - 1, -1, -1):
        glo, ghi = _image_box([[Bf[k][j]] for k in range(n)], [Ulo[j]], [Uhi[j]])
        Ylo = [a + b for a, b in zip(Ylo, glo, strict=True)]
        Yhi = [a + b for a, b in zip(Yhi, ghi, strict=True)]
        boxes.insert(0, (Ylo, Yhi))
    # the LPs are conditioned by the scale of y over X x U
    slo = np.array([float(v) for v in boxes[0][0]])
    shi = np.array([float(v) for v in boxes[0][1]])

    def stage(rows: list[ExactRow], j: int) -> list[ExactRow] | None:
        """Rows of (an inner approximation of) S_j ∩ Y_j, pruned; with the box Y_j the
        normals are rounded to floats (offsets moved inward to pay for it) so that the
        integers of the next stages stay short."""
        if not within_X:
            return reduce_rows(rows, slo, shi, shrink=_SHRINK)
        pinned = _box_rows(*boxes[j])
        out = reduce_rows(rows + pinned, slo, shi, removable=range(len(rows)),
                          shrink=_SHRINK)
        if out is None:
            return None
        box = set(pinned)
        free = [r for r in out if r not in box]
        A_f, b_f = round_rows_inward(free, *boxes[j])
        if np.any(b_f == -np.inf):
            return None
        return [exact_row(_fr(a), Fraction(float(b))) for a, b in zip(A_f, b_f, strict=True)
                if np.isfinite(b)] + [r for r in out if r in box]

    if not lp_feasible(rows + (_box_rows(*boxes[0]) if within_X else []), slo, shi):
        return None
    cur = stage(rows, 0)
    for j in range(m):
        if cur is None:
            return None
        bj = [Bf[k][j] for k in range(n)]
        if not any(bj):
            continue
        lifted = [exact_row(list(a) + [sum((ak * bk for ak, bk in zip(a, bj, strict=True)),
                                           zero)], beta) for a, beta in cur]
        lifted += [exact_row([0] * n + [1], Uhi[j]), exact_row([0] * n + [-1], -Ulo[j])]
        cur = stage(fm_eliminate(lifted, n), j + 1)
    if cur is None:
        return None
    if within_X:  # the rows of Y_m are implied by x in X
        drop = set(_box_rows(*boxes[m]))
        cur = [r for r in cur if r not in drop]
    return [exact_row([sum((Fraction(a[k]) * Af[k][j] for k in range(n)), zero)
                       for j in range(n)], beta) for a, beta in cur]


def _pre_polytope(model: Model, T: Polytope, within_X: bool) -> Polytope:
    """Inner float polytope of the exact Pre(T) (∩ X) of one target polytope."""
    _check_linear(model)
    n = model.n
    if T.dim != n:
        raise ValueError(f"target has dimension {T.dim}; the model has n = {n}")
    H, h = np.asarray(T.A, dtype=float), np.asarray(T.b, dtype=float)
    if np.any(h == -np.inf):
        return Polytope.empty(n)
    fin = np.isfinite(h)
    rows = _pre_rows(model, H[fin], h[fin], within_X)
    if rows is None:
        # empty (up to HiGHS's tolerance): the empty set is an inner approximation
        return Polytope.empty(n)
    if within_X:
        for j, (bl, bh) in enumerate(zip(_fr(model.X.lo), _fr(model.X.hi), strict=True)):
            e = [0] * n
            e[j] = 1
            rows.append(exact_row(e, bh))
            e[j] = -1
            rows.append(exact_row(e, -bl))
    if not lp_feasible(rows, model.X.lo, model.X.hi):
        return Polytope.empty(n)
    rows = reduce_rows(rows, model.X.lo, model.X.hi, shrink=_SHRINK)
    if rows is None:
        return Polytope.empty(n)
    if not rows:  # no constraint left (only without X): all of R^n
        return Polytope(np.zeros((0, n)), np.zeros(0))
    return _round_inward(rows, model, within_X)


def _round_inward(rows: list[ExactRow], model: Model, within_X: bool) -> Polytope:
    """The float polytope ``{x in B : A_f x <= b_f}`` inside the exact rows' set, with B
    the box X (``within_X``) or a proven bounding box of the exact set in the coordinates
    where some normal is not a float vector."""
    n = model.n
    inexact = set()
    for a, _ in rows:
        M = max(abs(v) for v in a)
        if M:
            inexact.update(j for j, v in enumerate(a) if Fraction(v, M) != Fraction(v / M))
    if within_X:
        blo, bhi = list(model.X.lo), list(model.X.hi)
    else:
        blo, bhi = [-np.inf] * n, [np.inf] * n
        for j in sorted(inexact):
            e = [0] * n
            e[j] = 1
            up = exact_max(rows, e, model.X.lo, model.X.hi)
            e[j] = -1
            dn = exact_max(rows, e, model.X.lo, model.X.hi)
            if up is None or dn is None:
                raise UnboundedSetError(
                    f"the pre-set without X has no proven bound in x{j + 1} and its rows "
                    "cannot be stored exactly in floating point; use within_X=True")
            blo[j], bhi[j] = frac_down(-dn), frac_up(up)
    Lo = [Fraction(float(v)) if np.isfinite(v) else None for v in blo]
    Hi = [Fraction(float(v)) if np.isfinite(v) else None for v in bhi]
    A_f, b_f = round_rows_inward(rows, Lo, Hi)
    box_A, box_b = [], []
    for j in range(n):
        if Lo[j] is not None and Hi[j] is not None:
            e = np.zeros(n)
            e[j] = 1.0
            box_A += [e, -e]
            box_b += [float(Hi[j]), -float(Lo[j])]
    if box_A:
        A_f = np.vstack([A_f, np.array(box_A)])
        b_f = np.concatenate([b_f, np.array(box_b)])
    if np.any(b_f == -np.inf):
        return Polytope.empty(n)
    # drop box rows implied by the others (exactly: the set does not change)
    frows = [exact_row(_fr(a), Fraction(float(b))) for a, b in zip(A_f, b_f, strict=True)]
    k0 = len(rows)
    keep = prune_rows(frows, model.X.lo, model.X.hi, removable=range(k0, len(frows)))
    if keep is None:  # pragma: no cover - the rounded rows prove emptiness
        return Polytope.empty(n)
    if not keep:
        raise SolverError("the pre-set lost every row in the rounding")  # pragma: no cover
    return Polytope(A_f[keep], b_f[keep])


def pre_set(model: Model, target: Any, within_X: bool = True) -> Polytope | PolytopeUnion:
    """Proven inner approximation, tight up to rounding, of the one-step controllable set
    of a linear model to a target polytope or union.

    Parameters
    ----------
    model : Model
        Linear in (x, u, w) (``model.is_linear``); U and W are the model's boxes.
    target : Polytope or PolytopeUnion
        The target set T (dimension n). A union requires a model without disturbance.
    within_X : bool
        Intersect with the state box X (default True): ``Pre(T) ∩ X``.

    Returns
    -------
    Polytope or PolytopeUnion
        A float polytope ``K = {x : K.A x <= K.b}`` (for a union target, the union of the
        members' sets, members proven empty dropped). What is proven, with K's stored
        rows, T's rows, the boxes and ``(A, B, E, c) = model.linear_matrices()`` all
        taken as exact numbers: every x in K (and in X) has a u in U with
        ``A x + B u + E w + c`` in T for every w in W. So ``K ⊆ Pre(T) (∩ X)``; K is
        empty when HiGHS finds the problem infeasible.

    Raises
    ------
    ModelError
        The model is not linear, or a union target is given for a model with disturbance.
    UnboundedSetError
        ``within_X=False`` and the pre-set has no proven bound in a coordinate where one
        of its facet normals is not a float vector (then it cannot be stored as an inner
        float polytope).

    Notes
    -----
    The computation is exact except where it moves rows inward. ``Pre(T) = {x : A x ∈
    S}`` with ``S = (T ⊖ E W) - c ⊕ (-B U)``: the disturbance tightening
    ``max_{w in W} (H E w)_i`` is exact row by row; the Minkowski sum adds one segment
    ``-b_j [lo_j, hi_j]`` per input by exact Fourier–Motzkin elimination in n + 1
    coordinates (rational rows). After each step, rows are dropped as redundant only with
    an exactly checked certificate (LP multipliers from HiGHS, see
    :func:`casadi_cmpc.sets._exact.reduce_rows`). Rows are moved inward (never outward)
    in three places, each time by about 1e-12 of the scale of X and ``A X + B U`` or
    less (rows scaled to largest coefficient 1): (1) a row that is redundant only up to
    a margin (tiny facets that exact arithmetic finds where floating point sees one
    vertex) is dropped after the rows of its certificate are moved inward to close the
    margin, each row by at most ``1e-12`` of the scale in total; (2) with ``within_X``,
    after each segment the normals are rounded to floats and the offsets lowered by the
    rounding error over a box that holds the intermediate set (the coefficients stay
    short); (3) the result's normals are rounded to floats and the offsets lowered by
    ``max_{x in B} (a - a_f).x`` and rounded down, over ``B = X`` (or a proven bounding
    box without X), whose rows are kept unless proven redundant. A set thinner than
    these moves may come out empty. ``K.contains`` is a floating-point test of the
    rows: a point it accepts on the boundary may lie outside K by a rounding error.
    """
    if isinstance(target, PolytopeUnion):
        if model.l:
            raise ModelError("the robust pre-set of a union is not the union of the members' "
                             "pre-sets; give a single polytope for a model with disturbance")
        pieces = [_pre_polytope(model, P, within_X) for P in target.polytopes]
        pieces = [P for P in pieces if not P.is_empty()]
        return PolytopeUnion(pieces, dim=model.n)
    if not isinstance(target, Polytope):
        raise TypeError(f"target must be a Polytope or PolytopeUnion; got "
                        f"{type(target).__name__}")
    return _pre_polytope(model, target, within_X)


def _members(S: Any) -> list:
    """The polytopes of a set: the members of a union, or the set itself."""
    if isinstance(S, PolytopeUnion):
        return list(S.polytopes)
    return list(S.members) if hasattr(S, "members") else [S]


@dataclass
class SetSequence:
    """A nested sequence of sets K_0 = T, K_1, K_2, ... (K_i: states controllable in i steps).

    Attributes
    ----------
    sets : list
        ``sets[i]`` is K_i (``sets[0]`` is the target); also ``seq[i]``.
    converged_at : int or None
        The first i with K_i = K_{i-1}, else None. For :func:`linear_controllable_sets`
        (exact polytopes of a linear model) the maximal controllable set is reached, up to
        the tolerance of the LP inclusion tests. For :func:`controllable_sets` (boxes at a
        resolution eps) it is where the recursion stopped because no new box was proven:
        the inner approximation stopped growing at this eps, which does not prove that the
        maximal controllable set is reached (a finer eps may prove more).
    status : str
        ``"converged"``, ``"max_steps"`` (the recursion stopped at ``max_steps``),
        ``"until"`` (the given states were reached), ``"budget"`` (a step ran out of budget:
        its set is still a proven inner approximation) or ``"interrupted"``.
    steps : list of dict
        Per step i >= 1 (``steps[i - 1]``), for sequences computed by set inversion:
        ``"boxes"`` (N_i, n, 2) the state boxes first proven at step i, ``"witness"``
        (N_i, m) a proving control per box, ``"polytope"`` (polytopic sequences), and
        ``"seconds"``.
    info : dict
        How the sequence was computed (model, eps, robust, semantics, certificate of T).
    """

    sets: list = field(default_factory=list)
    converged_at: int | None = None
    info: dict = field(default_factory=dict)
    status: str = "max_steps"
    steps: list = field(default_factory=list)

    # ------------------------------------------------------------------ queries
    def _index(self) -> Any:
        """The grid of :meth:`_grid` when the sets are the step boxes (with T), else None
        (polytopic steps: the level is read from the polytopes)."""
        if any(st.get("polytope") is not None for st in self.steps):
            return None
        return self._grid()

    def _grid(self) -> Any:
        """Per cell of the grid of all step boxes' bounds: the smallest step whose boxes
        cover the cell, and one such box (built once; None without boxes):
        ``(edges, level, box)``."""
        idx = getattr(self, "_idx", None)
        if idx is not None:
            return idx if idx else None
        boxes = [st.get("boxes") for st in self.steps]
        if not boxes or any(b is None for b in boxes):
            self._idx = False
            return None
        allb = np.concatenate(boxes)
        if allb.shape[0] == 0 or not np.isfinite(allb).all():
            self._idx = False
            return None
        n = allb.shape[1]
        edges = [np.unique(allb[:, j, :]) for j in range(n)]
        shape = tuple(max(e.size - 1, 1) for e in edges)
        if float(np.prod(shape, dtype=float)) > 4e6:
            self._idx = False
            return None
        lev = np.full(shape, -1, dtype=np.int32)
        box = np.full(shape, -1, dtype=np.int64)
        for i in range(len(boxes), 0, -1):  # lower steps overwrite higher ones
            B = boxes[i - 1]
            a = [np.searchsorted(edges[j], B[:, j, 0]) for j in range(n)]
            b = [np.searchsorted(edges[j], B[:, j, 1]) for j in range(n)]
            for k in range(B.shape[0]):
                sl = tuple(slice(a[j][k], b[j][k]) for j in range(n))
                lev[sl] = i
                box[sl] = k
        self._idx = (edges, lev, box)
        return self._idx

    def _box_levels(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(level, box)`` per point from the step boxes (-1: in no box); a point on a
        cell face takes the smallest level of the cells meeting there."""
        edges, lev, box = self._idx
        n = P.shape[1]
        cand = []
        for j in range(n):
            e = edges[j]
            i = np.searchsorted(e, P[:, j], side="right") - 1
            inside = (P[:, j] >= e[0]) & (P[:, j] <= e[-1])
            hi_i = np.clip(i, 0, e.size - 2)
            lo_i = np.where((i >= 0) & (i < e.size) & (e[np.clip(i, 0, e.size - 1)] == P[:, j]),
                            np.clip(i - 1, 0, e.size - 2), hi_i)
            cand.append((lo_i, hi_i, inside))
        best = np.full(P.shape[0], np.iinfo(np.int32).max, dtype=np.int64)
        which = np.full(P.shape[0], -1, dtype=np.int64)
        ok = np.ones(P.shape[0], dtype=bool)
        for _, _, inside in cand:
            ok &= inside
        import itertools

        for bits in itertools.product((0, 1), repeat=n):
            ix = tuple(cand[j][bits[j]] for j in range(n))
            lv = lev[ix].astype(np.int64)
            bx = box[ix]
            better = ok & (lv > 0) & (lv < best)
            best = np.where(better, lv, best)
            which = np.where(better, bx, which)
        best = np.where(best == np.iinfo(np.int32).max, -1, best)
        return best, which

    def level(self, x: Any) -> Any:
        """Smallest i with x in K_i, or None when x lies in no set of the sequence.

        For a batch ``(P, n)`` of points, an int array ``(P,)`` with -1 outside every set.
        """
        p = np.asarray(x, dtype=float)
        batched = p.ndim == 2
        P = np.atleast_2d(p)
        out = np.full(P.shape[0], -1, dtype=int)
        if self.sets and self._index() is not None:
            inT = np.atleast_1d(np.asarray(self.sets[0].contains(P), dtype=bool))
            lv, _ = self._box_levels(P)
            out = np.where(inT, 0, lv).astype(int)
            if batched:
                return out
            return None if out[0] < 0 else int(out[0])
        for i, S in enumerate(self.sets):
            und = np.flatnonzero(out < 0)
            if und.size == 0:
                break
            hit = np.atleast_1d(np.asarray(S.contains(P[und]), dtype=bool))
            out[und[hit]] = i
        if batched:
            return out
        return None if out[0] < 0 else int(out[0])

    def locate(self, x: Any) -> tuple[int | None, tuple[int, np.ndarray] | None]:
        """``(level(x), witness(x))`` of one point, sharing the look-up."""
        p = np.asarray(x, dtype=float).reshape(1, -1)
        if self._index() is None:
            return self.level(p[0]), self.witness(p[0])
        lv, bx = self._box_levels(p)
        wit = None
        if lv[0] >= 1:
            wit = int(lv[0]), np.asarray(self.steps[lv[0] - 1]["witness"][bx[0]],
                                         dtype=float).copy()
        if bool(np.asarray(self.sets[0].contains(p[0]))):
            return 0, wit
        return (None if lv[0] < 0 else int(lv[0])), wit

    def witness(self, x: Any) -> tuple[int, np.ndarray] | None:
        """``(i, u)``: a stored proving control of a box first proven at step i that holds
        ``x`` (smallest i), or None (x in T or in no box, or no controls stored)."""
        p = np.asarray(x, dtype=float).reshape(-1)
        if self._grid() is not None and all(st.get("witness") is not None
                                            for st in self.steps):
            lv, bx = self._box_levels(p[None])
            if lv[0] < 1:
                return None
            return int(lv[0]), np.asarray(self.steps[lv[0] - 1]["witness"][bx[0]],
                                          dtype=float).copy()
        for i, st in enumerate(self.steps, start=1):
            B = st.get("boxes")
            if B is None or B.shape[0] == 0:
                continue
            hit = np.flatnonzero(((B[..., 0] <= p) & (p <= B[..., 1])).all(axis=1))
            if hit.size:
                return i, np.asarray(st["witness"][hit[0]], dtype=float).copy()
        return None

    def __len__(self) -> int:
        return len(self.sets)

    def __getitem__(self, i: int) -> Any:
        return self.sets[i]

    def __iter__(self):
        return iter(self.sets)

    def __repr__(self) -> str:
        conv = "" if self.converged_at is None else f", converged_at={self.converged_at}"
        return f"SetSequence(len={len(self.sets)}, status={self.status!r}{conv})"

    # ------------------------------------------------------------------ drawing
    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), cmap: str = "viridis",
             colorbar: bool = True, *, model: Model | None = None, legend: bool = True,
             **kw: Any) -> Any:
        """Draw the sets from the largest (back) to the target (front), coloured by step.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Created when omitted (equal aspect).
        dims : (int, int)
            States on the horizontal and vertical axes.
        cmap : str
            Sequential colour map of the steps i (K_0 = T at its low end).
        colorbar : bool
            Add a colour bar as the key of the steps (step i = K_i).
        model : Model, optional
            The model of the sequence: X is drawn as a dashed rectangle and the axes are
            labelled with its state names and units (``"name [unit]"``); without it the
            labels are ``info["state_names"]`` (or ``x1, x2``).
        legend : bool
            Add a legend outside the axes (below): X, the terminal set T and the meaning
            of white (unfilled) space, where nothing is proven.
        **kw
            Passed to matplotlib for every set (``alpha``, ``edgecolor``, ...).

        Returns
        -------
        matplotlib Axes
            The sets K_i (boxes or polytopes) filled in the colour of step i, T outlined
            in magenta, X dashed.
        """
        import matplotlib as mpl
        import matplotlib.pyplot as plt
        from matplotlib.patches import Patch

        from ..plot import (
            axis_label,
            draw_state_box,
            legend_outside,
            new_axes,
            plot_boxes,
            variable_labels,
        )

        ax = new_axes(ax)
        i_d, j_d = int(dims[0]), int(dims[1])
        k = max(len(self.sets), 2)
        cm_ = plt.get_cmap(cmap)
        norm = mpl.colors.Normalize(vmin=0, vmax=k - 1)
        alpha = kw.pop("alpha", 0.8)
        edge = kw.pop("edgecolor", "none" if self.steps else "k")
        for i in range(len(self.sets) - 1, -1, -1):
            col = cm_(norm(i))
            st = self.steps[i - 1] if 1 <= i <= len(self.steps) else None
            if st is not None and st.get("polytope") is None and "boxes" in st:
                if st["boxes"].shape[0]:
                    plot_boxes(st["boxes"], ax=ax, dims=dims, facecolor=col, alpha=alpha,
                               edgecolor=edge, **kw)
                continue
            S = self.sets[i] if st is None or st.get("polytope") is None else st["polytope"]
            for P in _members(S):
                if isinstance(P, Polytope) and not P.is_empty():
                    P.plot(ax=ax, dims=dims, facecolor=col, alpha=alpha,
                           edgecolor="k", **kw)
        # T on top, outlined (its fill is the colour of step 0)
        if self.sets:
            first = True
            for P in _members(self.sets[0]):
                if isinstance(P, Polytope) and not P.is_empty():
                    P.plot(ax=ax, dims=dims, facecolor="none", edgecolor="magenta", alpha=1.0,
                           linewidth=1.8, label="T = K_0 (terminal set)" if first else None)
                    first = False
        if model is not None:
            draw_state_box(ax, model, i_d, j_d, label="X (state box)")
            ax.autoscale_view()
        if colorbar:
            sm = mpl.cm.ScalarMappable(norm=norm, cmap=cm_)
            ax.figure.colorbar(sm, ax=ax, label="step i (set K_i)")
        if model is not None:
            names, units = variable_labels(model, "x")
        else:
            names = list(self.info.get("state_names") or [])
            units = [None] * len(names)
        ax.set_xlabel(axis_label(names[i_d], units[i_d]) if len(names) > i_d
                      else f"x{i_d + 1}")
        ax.set_ylabel(axis_label(names[j_d], units[j_d]) if len(names) > j_d
                      else f"x{j_d + 1}")
        if legend:  # the key of white space is in the legend only
            legend_outside(ax, where="below", ncol=2, extra=[Patch(
                facecolor="white", edgecolor="0.4", linewidth=0.8,
                label="white (unfilled): not proven controllable")])
        return ax

    # -------------------------------------------------------------- persistence
    def save(self, path: Any, *, compress: bool = True) -> Any:
        """Save the sequence exactly (sets, steps, status, info) to ``.npz`` or ``.json``.

        Parameters
        ----------
        path : str or Path
            The file written; it must end in ``.npz`` (compressed binary) or ``.json``
            (text).
        compress : bool
            Compress the arrays of an ``.npz`` file (default). ``False`` writes the same
            archive with its arrays stored as they are: larger, several times faster to
            write (checkpoints rewritten after every step use it).

        Returns
        -------
        pathlib.Path
            The written file.

        Notes
        -----
        A set ``K_i`` that is ``T`` together with the boxes of steps 1..i (as
        :func:`~casadi_cmpc.controllable_sets` builds it) is stored as that reference, not
        as a copy of the boxes (the copies grow with the square of the number of steps).
        In ``.npz`` files every array is a binary entry of a compressed archive; the
        structure is a JSON entry. :meth:`load` (and :func:`casadi_cmpc.load_set`)
        rebuild an equal sequence: the same arrays bit for bit.
        """
        import json
        from pathlib import Path

        from ..sets.base import _FORMAT_VERSION, _check_suffix, _encode, _save_state

        cum = _StepBoxes(self.steps)
        state = {
            "sets": [self._set_state(i, S, cum) for i, S in enumerate(self.sets)],
            "converged_at": -1 if self.converged_at is None else int(self.converged_at),
            "status": self.status,
            "steps": [{k: ({"type": v._type_name, "state": v._state()}
                           if hasattr(v, "_state") else v)
                       for k, v in st.items() if v is not None} for st in self.steps],
            "info": {k: v for k, v in self.info.items()
                     if isinstance(v, (str, int, float, bool, list, np.ndarray))},
        }
        path = Path(path)
        _check_suffix(path, "save a set to")
        if path.suffix.lower() == ".json":
            return _save_state("SetSequence", state, path)
        arrays: dict[str, np.ndarray] = {}
        meta = {"type": "SetSequence", "format": _FORMAT_VERSION,
                "state": {k: _encode(_to_refs(v, arrays)) for k, v in state.items()}}
        path.parent.mkdir(parents=True, exist_ok=True)
        # through a file object: numpy would append '.npz' to a name without it
        with open(path, "wb") as fh:
            (np.savez_compressed if compress else np.savez)(
                fh, __meta__=np.array(json.dumps(meta)),
                **{f"a_{k}": v for k, v in arrays.items()})
        return path

    def _set_state(self, i: int, S: Any, cum: _StepBoxes | None = None) -> dict[str, Any]:
        """The stored form of ``K_i``: a reference to T and the boxes of steps 1..i when
        ``K_i`` is exactly their union (bit for bit), else the set's own state. ``cum``:
        the step boxes of this sequence, shared by the sets of one :meth:`save`."""
        from ..sets.paving import Paving
        from ..sets.union import SetUnion

        def plain() -> dict[str, Any]:
            return {"type": S._type_name, "state": S._state()}

        if i == 0 or i > len(self.steps) or not isinstance(S, SetUnion) \
                or len(S.members) != 2:
            return plain()
        T, P = S.members
        if not isinstance(P, Paving) or P.boundary.shape[0] or P.outside.shape[0] \
                or not (T is self.sets[0] or _same_state(T, self.sets[0])):
            return plain()
        if not (cum or _StepBoxes(self.steps)).is_prefix(i, P.inner, P.dim):
            return plain()
        return {"type": _STEPS_UNION, "state": {
            "dim": P.dim, "n_discarded": P.n_discarded,
            "domain": None if P.domain is None else P.domain.as_array()}}

    @classmethod
    def load(cls, path: Any) -> SetSequence:
        """Load a sequence written by :meth:`save`.

        Parameters
        ----------
        path : str or Path
            A ``.npz`` or ``.json`` file written by :meth:`save`.

        Returns
        -------
        SetSequence
            Equal to the saved one: the same sets, steps (arrays bit for bit), status,
            ``converged_at`` and info.

        Raises
        ------
        ValueError
            The file is not a set file written by ``save``.
        TypeError
            The file holds another kind of set.
        FileNotFoundError
            No file at ``path``.
        """
        from ..sets.base import load_set

        obj = load_set(path)
        if not isinstance(obj, SetSequence):
            raise TypeError(f"{path} holds a {type(obj).__name__}, not a SetSequence")
        return obj

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> SetSequence:
        from ..sets.base import _TYPES
        from ..sets.paving import Paving
        from ..sets.union import SetUnion

        arrays = {k: v for k, v in state.items() if isinstance(v, np.ndarray)}
        state = {k: _from_refs(v, arrays) for k, v in state.items() if k not in arrays}

        def build(d: Any) -> Any:
            if isinstance(d, dict) and set(d) == {"type", "state"}:
                return _TYPES[d["type"]]._from_state(d["state"])
            return d

        steps = [{k: build(v) for k, v in st.items()} for st in state["steps"]]
        sets: list[Any] = []
        for i, d in enumerate(state["sets"]):
            if isinstance(d, dict) and d.get("type") == _STEPS_UNION:
                st = d["state"]
                n = int(st["dim"])
                inner = np.concatenate([np.asarray(s["boxes"], dtype=float).reshape(-1, n, 2)
                                        for s in steps[:i]])
                sets.append(SetUnion([sets[0], Paving(
                    inner=inner, domain=st["domain"], n_discarded=int(st["n_discarded"]))],
                    dim=n))
            else:
                sets.append(build(d))
        conv = int(state["converged_at"])
        return cls(sets=sets, converged_at=None if conv < 0 else conv,
                   info=dict(state.get("info", {})), status=str(state["status"]), steps=steps)


# the stored form of a K_i that is T plus the boxes of steps 1..i (see SetSequence.save)
_STEPS_UNION = "SetSequence.steps_union"


class _StepBoxes:
    """The boxes of a sequence's steps 1, 2, ... joined once (per dimension), to test which
    sets ``K_i`` are exactly the boxes of steps 1..i without joining them again for every
    i."""

    def __init__(self, steps: list) -> None:
        self.steps = steps
        self._by_dim: dict[int, tuple[np.ndarray, list[int]]] = {}

    def _joined(self, dim: int) -> tuple[np.ndarray, list[int]]:
        """The boxes (N, dim, 2) of the steps up to the first without a box array, and the
        number of boxes after each of those steps."""
        if dim not in self._by_dim:
            parts = []
            for st in self.steps:
                b = st.get("boxes")
                if not isinstance(b, np.ndarray):
                    break
                parts.append(np.asarray(b, dtype=float).reshape(-1, dim, 2))
            ends = list(np.cumsum([p.shape[0] for p in parts], dtype=int))
            joined = np.concatenate(parts) if parts else np.zeros((0, dim, 2))
            self._by_dim[dim] = (np.ascontiguousarray(joined), ends)
        return self._by_dim[dim]

    def is_prefix(self, i: int, inner: np.ndarray, dim: int) -> bool:
        """Whether ``inner`` is, bit for bit, the boxes of steps 1..i (in order)."""
        joined, ends = self._joined(dim)
        if i > len(ends):
            return False
        head = joined[:ends[i - 1]]
        inner = np.asarray(inner)
        if inner.dtype != head.dtype or inner.shape != head.shape:
            return False
        a = np.ascontiguousarray(inner).view(np.uint64)
        return bool(np.array_equal(a, head.view(np.uint64)))


def _same_state(S1: Any, S2: Any) -> bool:
    """Same type and the same stored state (arrays bit for bit)."""
    return type(S1) is type(S2) and _same_value(S1._state(), S2._state())


def _same_value(a: Any, b: Any) -> bool:
    """Equality of nested dicts, lists and arrays, arrays bit for bit (dtype and shape)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same_value(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same_value(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def _to_refs(v: Any, arrays: dict[str, np.ndarray]) -> Any:
    """``v`` with every array replaced by ``{"__ref__": key}`` (the array in ``arrays``)."""
    if isinstance(v, np.ndarray):
        key = f"ref{len(arrays)}"
        arrays[key] = v
        return {"__ref__": key}
    if isinstance(v, dict):
        return {k: _to_refs(x, arrays) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_to_refs(x, arrays) for x in v]
    return v


def _from_refs(v: Any, arrays: dict[str, np.ndarray]) -> Any:
    """The inverse of :func:`_to_refs`."""
    if isinstance(v, dict):
        if set(v) == {"__ref__"} and v["__ref__"] in arrays:
            return arrays[v["__ref__"]]
        return {k: _from_refs(x, arrays) for k, x in v.items()}
    if isinstance(v, list):
        return [_from_refs(x, arrays) for x in v]
    return v


def _register() -> None:
    from ..sets.base import _TYPES

    _TYPES["SetSequence"] = SetSequence  # type: ignore[assignment]


_register()


def _same_set(S1: Any, S2: Any) -> bool:
    """Equality of two polytopes or unions of polytopes, member by member, by LP
    inclusion tests (:meth:`Polytope.is_subset`, which errs toward True by its
    tolerance): a convergence test, not a proof."""
    if isinstance(S1, Polytope) and isinstance(S2, Polytope):
        return S1.is_subset(S2) and S2.is_subset(S1)
    m1 = S1.polytopes if isinstance(S1, PolytopeUnion) else (S1,)
    m2 = S2.polytopes if isinstance(S2, PolytopeUnion) else (S2,)
    if len(m1) != len(m2):
        return False
    return all(_same_set(a, b) for a, b in zip(m1, m2, strict=True))


def linear_controllable_sets(model: Model, target: Any, max_steps: int = 50,
                             until: Any = None) -> SetSequence:
    """The recursion K_{i+1} = Pre(K_i) ∩ X of a linear model (thesis §3.4).

    Each K_{i+1} is :func:`pre_set` of the computed K_i, a proven inner approximation:
    every state of K_{i+1} has an input in U that brings it into K_i for every w in W,
    exactly (so into T in i + 1 steps); the sets are the exact ones up to the inward moves
    described in :func:`pre_set`.

    Parameters
    ----------
    model : Model
        Linear model.
    target : Polytope or PolytopeUnion
        K_0 (a control-invariant terminal set for the sequence to be nested).
    max_steps : int
        Upper bound on the number of pre-sets computed.
    until : array_like (k, n), optional
        Stop as soon as every one of these states lies in the last set.

    Returns
    -------
    SetSequence
        ``info`` records the model, ``robust`` (the model has a disturbance: every w in
        W), ``semantics`` and ``method``. ``converged_at`` is set when K_i equals
        K_{i-1} up to the tolerance of the LP inclusion tests, member by member (a
        stopping rule: it does not prove that K_{i-1} is control invariant).
    """
    from .controllable import NO_W, ROBUST, proof_w_box
    from .invariance import model_key

    _check_linear(model)
    seq = SetSequence(sets=[target], info={
        "model": model.name, "robust": bool(model.l), "model_key": model_key(model),
        "proof_W": proof_w_box(model, True),
        "semantics": ROBUST if model.l else NO_W,
        "method": "pre_set: exact rational pre-sets, rows rounded inward (inner sets)",
        "state_names": [f"x{i + 1}" for i in range(model.n)]})
    pts = None if until is None else np.atleast_2d(np.asarray(until, dtype=float))
    for i in range(1, int(max_steps) + 1):
        K = pre_set(model, seq.sets[-1])
        seq.sets.append(K)
        if _same_set(K, seq.sets[-2]):
            seq.converged_at = i
            seq.status = "converged"
            break
        if pts is not None and np.all(K.contains(pts)):
            seq.status = "until"
            break
    return seq
