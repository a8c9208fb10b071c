"""One-step and controllable sets of nonlinear models (thesis Alg 4.6, 5.2, 6.1; (6.8)).

:func:`one_step_set` computes an inner approximation of

    K(X, T) = {x in X : exists u in U such that f(x, u, w) in T for all w in W}

(``robust=True``; the control is chosen before the disturbance is known) as a union of
boxes, each with a proving control. It is one nested (state box × control cell) search on
the batched branch-and-bound engine (:class:`~casadi_cmpc.solvers.engine.PairFrontier`).
:func:`controllable_sets` iterates it, ``K_{i+1} = K(X, K_i)``, to convergence.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .._interrupt import InterruptScope
from .._validate import as_boxes
from ..exceptions import DimensionError, ModelError
from ..interval._native import Rows
from ..interval.compiler import InclusionFunction, inclusion
from ..model import Model
from ..sets._boxunion import _compact_union
from ..sets.box import Box
from ..sets.paving import Paving
from ..sets.polytope import Polytope, PolytopeUnion
from ..sets.union import SetUnion
from ..sets.zonotope import Zonotope
from ..solvers._common import positive_eps
from ..solvers.engine import INNER, OUTER, PairFrontier, Status, branch_and_bound
from ..solvers.result import SetResult

__all__ = ["one_step_set", "OneStepSet", "controllable_sets"]

ROBUST = "exists u for all w"
MODAL = "for all w exists u (u may depend on w)"
NOMINAL = "exists u, w at its nominal value"
NO_W = "exists u (no disturbance)"


# ----------------------------------------------------------------------------- targets
def _flatten(target: Any) -> list[Any]:
    if isinstance(target, (list, tuple)):
        return [m for t in target for m in _flatten(t)]
    if isinstance(target, SetUnion):
        return [m for t in target.members for m in _flatten(t)]
    if isinstance(target, PolytopeUnion):
        return list(target.polytopes)
    if isinstance(target, Box):
        return [Polytope.from_box(target)]
    if isinstance(target, (Polytope, Paving, Zonotope)):
        return [target]
    raise TypeError(f"the target must be a Polytope, PolytopeUnion, Paving (its inner boxes), "
                    f"Zonotope, Box, SetUnion or a list of them; got {type(target).__name__}")


def _rows_inclusion(model: Model, A: np.ndarray) -> Any:
    """The centered inclusion of the target rows ``A f(x, u, w)``, A read as exact constants
    (a :class:`~casadi_cmpc.interval._derivative.ParamFunction` over ``H f`` with H a
    symbol: CasADi folds nothing of A while composing, the compiler folds it exactly). One
    per model and matrix, kept for the last 64 matrices, so that the targets of every level
    of a sequence (and every call) share its compiled evaluators (numpy, scalar, native)."""
    from collections import OrderedDict

    from ..interval._derivative import ParamFunction

    cache = model.__dict__.setdefault("_rows_inclusions", OrderedDict())
    key = (A.shape, A.tobytes())
    F = cache.get(key)
    if F is None:
        H = ca.SX.sym("H", A.shape[0], model.n)
        if model._exact_f is None:  # f as given: its literals are the model's
            g = ca.Function("target_rows", [model.x, model.u, model._w_sym, H],
                            [ca.mtimes(H, model.f)])
            F = InclusionFunction(ParamFunction(g, 3, A.ravel(order="F")), "centered")
        else:  # closed loop or validated ODE: the exact interval source, with its parameters
            expr, P, Pb = model.interval_expr()
            g = ca.Function("target_rows", [model.x, model.u, model._w_sym,
                                            ca.vertcat(ca.vec(H), P)], [ca.mtimes(H, expr)])
            vals = np.vstack([np.repeat(A.ravel(order="F")[:, None], 2, axis=1), Pb])
            F = InclusionFunction(ParamFunction(g, 3, vals), "centered")
        cache[key] = F
        while len(cache) > 64:
            cache.popitem(last=False)
    else:
        cache.move_to_end(key)
    return F


def _signed_rows(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows of ``A x <= b`` (r, n) up to sign: ``(D, lower, upper)`` with
    ``{A x <= b} = {lower <= D x <= upper}``.

    A row equal to minus an earlier one (exactly) becomes a lower bound of that one,
    ``-a x <= c  <=>  a x >= -c`` (negation is exact); repeated rows keep the tightest bound.
    A box or any centrally symmetric polytope has half as many rows to enclose, and the
    enclosure of ``-a f`` is the negation of that of ``a f``. Missing sides are infinite.
    """
    seen: dict[bytes, int] = {}
    D: list[np.ndarray] = []
    lower: list[float] = []
    upper: list[float] = []
    for a, c in zip(A, b, strict=True):
        a = a + 0.0  # -0.0 -> 0.0: one key per direction
        key, neg = a.tobytes(), (-a + 0.0).tobytes()
        if key in seen:
            upper[seen[key]] = min(upper[seen[key]], float(c))
        elif neg in seen:
            lower[seen[neg]] = max(lower[seen[neg]], -float(c))
        else:
            seen[key] = len(D)
            D.append(a)
            lower.append(-np.inf)
            upper.append(float(c))
    return (np.array(D).reshape(-1, A.shape[1]), np.array(lower, dtype=float),
            np.array(upper, dtype=float))


def _rows_hold(R: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``lower <= [lo, hi] <= upper`` on every row: (N,) from the enclosures R (N, r, 2)."""
    if R.shape[1] > 16:
        return (R[..., 1] <= upper).all(axis=1) & (R[..., 0] >= lower).all(axis=1)
    ok = np.ones(R.shape[0], dtype=bool)  # column by column: reductions along a short
    for k in range(R.shape[1]):           # last axis are slow in numpy
        ok &= R[:, k, 1] <= upper[k]
        ok &= R[:, k, 0] >= lower[k]
    return ok


def _rows_fail(R: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Some row's enclosure lies beyond its bounds: (N,) from R (N, r, 2)."""
    if R.shape[1] > 16:
        return (R[..., 0] > upper).any(axis=1) | (R[..., 1] < lower).any(axis=1)
    out = np.zeros(R.shape[0], dtype=bool)
    for k in range(R.shape[1]):
        out |= R[:, k, 0] > upper[k]
        out |= R[:, k, 1] < lower[k]
    return out


class _Target:
    """Proven tests of ``f(X, U, W) ⊆ T`` and ``f(X, U, W) ∩ T = ∅`` for batches of boxes.

    Polytope members are tested through the rows composed with f, ``H f(x, u, w) <= h``,
    enclosed by the centered form (H enters as exact constants, so nothing is rounded; a
    row and its negation are enclosed once, see :func:`_signed_rows`); box unions and
    zonotopes through the interval hull of the successor.
    """

    def __init__(self, model: Model, target: Any) -> None:
        members = _flatten(target)
        n = model.n
        for S in members:
            if S.dim != n:
                raise DimensionError(f"the target has dimension {S.dim}; the model has n = {n}")
        # per polytope: the inclusion of its rows up to sign, and the bounds on each
        self.polys: list[tuple[Any, np.ndarray, np.ndarray]] = []
        boxes = []
        self.zonos: list[Zonotope] = []
        for S in members:
            if isinstance(S, Polytope):
                if S.is_empty():
                    continue
                A, lower, upper = _signed_rows(np.asarray(S.A, dtype=float),
                                               np.asarray(S.b, dtype=float))
                self.polys.append((_rows_inclusion(model, A), lower, upper))
            elif isinstance(S, Paving):
                if S.inner.shape[0]:
                    boxes.append(S.inner)
            else:
                self.zonos.append(S)
        self.boxes = Paving(inner=np.concatenate(boxes)) if boxes else None
        self.F = (inclusion(model.interval_map("xuw"), "centered") if (boxes or self.zonos)
                  else None)
        self.empty = not (self.polys or boxes or self.zonos)

    def images(self, X: np.ndarray, U: np.ndarray, W: np.ndarray
               ) -> tuple[list[np.ndarray], np.ndarray | None]:
        """One evaluation of every test function on the boxes (N, ., 2) (U, W: N rows or
        one): the enclosures of the rows ``H f`` of each polytope member, (N, r, 2) each,
        and the hull of ``f`` (N, n, 2) when a member is a box union or a zonotope (else
        None)."""
        N = X.shape[0]
        rows = [F.evaluate_unchecked([X, U, W], N)[0] for F, _, _ in self.polys]
        Y = self.F.evaluate_unchecked([X, U, W], N)[0] if self.F is not None else None
        return rows, Y

    def inside_of(self, rows: list[np.ndarray], Y: np.ndarray | None) -> np.ndarray:
        """Proven ``f(x, u, w) in T`` from the :meth:`images` of a batch, (N,)."""
        N = rows[0].shape[0] if rows else (0 if Y is None else Y.shape[0])
        ok = np.zeros(N, dtype=bool)
        if self.empty or N == 0:
            return ok
        for (_, lower, upper), R in zip(self.polys, rows, strict=True):
            ok |= _rows_hold(R, lower, upper)
        if Y is not None:
            und = np.flatnonzero(~ok)
            if und.size:
                Yu = Y[und]
                grid = None if self.boxes is None else self.boxes._grid("inner", und.size)
                if grid is not None and not self.zonos:
                    # the exact grid index answers False for a non-finite enclosure
                    got = grid.contains(Yu)
                else:
                    fin = np.isfinite(Yu).all(axis=(1, 2))
                    got = np.zeros(und.size, dtype=bool)
                    if self.boxes is not None:
                        got |= self.boxes.contains_box(Yu, view="inner") & fin
                    for Z in self.zonos:
                        got |= np.asarray(Z.contains_box(Yu), dtype=bool) & fin
                ok[und[got]] = True
        return ok

    def outside_of(self, rows: list[np.ndarray], Y: np.ndarray | None) -> np.ndarray:
        """Proven ``f(x, u, w) not in T`` from the :meth:`images` of a batch, (N,)."""
        N = rows[0].shape[0] if rows else (0 if Y is None else Y.shape[0])
        out = np.ones(N, dtype=bool)
        if self.empty:
            return out
        for (_, lower, upper), R in zip(self.polys, rows, strict=True):
            out &= _rows_fail(R, lower, upper)
        if Y is not None and out.any():
            idx = np.flatnonzero(out)
            Yi = Y[idx]
            grid = None if self.boxes is None else self.boxes._grid("inner", idx.size)
            if grid is not None and not self.zonos:
                # the exact grid index: True for a NaN enclosure, exact for infinite bounds
                meet = grid.intersects(Yi)
            else:
                meet = ~np.isfinite(Yi).all(axis=(1, 2))
                if self.boxes is not None:
                    meet |= self.boxes.intersects_box(np.nan_to_num(Yi), view="inner")
                for Z in self.zonos:
                    meet |= np.asarray(Z.intersects_box(np.nan_to_num(Yi)), dtype=bool)
            out[idx[meet]] = False
        return out

    def inside(self, X: np.ndarray, U: np.ndarray, W: np.ndarray) -> np.ndarray:
        """Proven ``f(x, u, w) in T`` for all x, u, w of the boxes, (N,)."""
        if self.empty or X.shape[0] == 0:
            return np.zeros(X.shape[0], dtype=bool)
        return self.inside_of(*self.images(X, U, W))

    def outside(self, X: np.ndarray, U: np.ndarray, W: np.ndarray) -> np.ndarray:
        """Proven ``f(x, u, w) not in T`` for all x, u, w of the boxes, (N,)."""
        if self.empty:
            return np.ones(X.shape[0], dtype=bool)
        return self.outside_of(*self.images(X, U, W))


def _as_obstacles(obstacles: Any, n: int) -> list[Any]:
    if obstacles is None:
        return []
    if isinstance(obstacles, (Box, Polytope, PolytopeUnion, Zonotope)):
        obstacles = [obstacles]
    out = []
    for ob in obstacles:
        if isinstance(ob, Box):
            ob = Polytope.from_box(ob)
        if not isinstance(ob, (Polytope, PolytopeUnion, Zonotope)):
            raise TypeError(f"obstacles must be Boxes, Polytopes or Zonotopes; got "
                            f"{type(ob).__name__}")
        if ob.dim != n:
            raise DimensionError(f"an obstacle has dimension {ob.dim}; the model has n = {n}")
        out.append(ob)
    return out


class _OneStepClassifier:
    """Pair classifier of thesis Alg 6.1 (Alg 4.6 without disturbance).

    * cell useless (OUTER) when, for one of the points ``w_c`` of W,
      ``f(X_i, U_j, w_c) ∩ T = ∅``: then every control of the cell fails for every state of
      the box (with that w), so the cell cannot provide the ``exists u`` of ``exists u
      for all w`` (the w may differ from cell to cell: the negation is ``for all u exists w``);
    * pair INNER when ``f(X_i, mid(U_j), W) ⊆ T``: the control ``mid(U_j)`` works for every
      state of the box and every w (it is stored as the witness);
    * a box that may meet an obstacle is never inner; a box inside one is outside.
    """

    def __init__(self, target: _Target, W: np.ndarray, w_points: np.ndarray,
                 obstacles: list[Any]) -> None:
        self.target = target
        self.W = W[None]  # (1, l, 2)
        self.w_points = w_points  # (C, l)
        self.obstacles = obstacles

    def __call__(self, fr: PairFrontier) -> np.ndarray:
        with np.errstate(all="ignore"):
            return self._classify(fr)

    def _classify(self, fr: PairFrontier) -> np.ndarray:
        N = len(fr)
        labels = np.zeros(N, dtype=np.int8)
        if N == 0:
            return labels
        lo, hi, n = fr.lo, fr.hi, fr.n
        blocked = np.zeros(N, dtype=bool)
        buried = np.zeros(N, dtype=bool)
        if self.obstacles:
            X = fr.x_boxes
            for ob in self.obstacles:
                blocked |= np.asarray(ob.intersects_box(X), dtype=bool)
                buried |= np.asarray(ob.contains_box(X), dtype=bool)
        # the target's test functions on the pairs with each point w_c of W (exclusion),
        # then on the boxes of the cells that may still be useful with the cell midpoint
        # over all of W (inclusion)
        T = self.target
        und = np.flatnonzero(~buried)
        cand = np.flatnonzero(~buried & ~blocked)
        if T.empty or und.size == 0:
            labels[:] = OUTER  # nothing reaches an empty target; every box is buried
            return labels
        wp = self.w_points
        nc, K = wp.shape[0], und.size
        # the kernels read the state boxes and cells in place from the frontier's bounds
        # (rows und, nc times over: one copy of the boxes per point of W)
        rows = None if K == N else und
        if nc == 1:
            Ws: Any = np.stack([wp, wp], axis=-1)  # (1, l, 2): broadcast
        else:
            rows = np.tile(np.arange(N) if rows is None else rows, nc)
            Ws = Rows(wp, wp, idx=np.repeat(np.arange(nc), K))  # (nc K, l, 2)
        out = T.outside_of(*T.images(Rows(lo, hi, 0, n, rows), Rows(lo, hi, n, None, rows), Ws))
        useless = buried.copy()
        useless[und] = out.reshape(nc, K).any(axis=0)
        labels[useless] = OUTER
        cand = cand[~useless[cand]]
        if cand.size:
            cl, ch = lo[cand, n:], hi[cand, n:]
            mid = np.clip(0.5 * cl + 0.5 * ch, cl, ch)
            ok = T.inside_of(*T.images(Rows(lo, hi, 0, n, None if cand.size == N else cand),
                                       Rows(mid, mid), self.W))
            labels[cand[ok]] = INNER
            fr.data["witness"][cand[ok]] = mid[ok]
        return labels


# ----------------------------------------------------------------------------- results
@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class OneStepSet(SetResult):
    """Inner approximation of a one-step (robust) controllable set, with proving controls.

    A :class:`~casadi_cmpc.SetResult`: it acts as its paving (``res.inner``,
    ``res.boundary``, ``res.outside``, ...), except for :meth:`contains`, :meth:`area` and
    :meth:`plot` below.

    Attributes
    ----------
    paving : Paving
        ``inner``: state boxes proven in the set; ``boundary``: undecided boxes;
        ``outside``: boxes proven outside it (for drawing).
    witness : ndarray (N_inner, m) or None
        For the ``general`` method, a control proving each inner box: ``f(x, witness, w)``
        lies in the target for every x of the box and every w of W (``None`` for the
        modal method, whose proof gives no control).
    semantics : str
        ``"exists u for all w"`` (robust), ``"exists u, w at its nominal value"``
        (``robust=False`` with a disturbance; w at the centre of W), or ``"for all w
        exists u (u may depend on w)"`` (modal method: a weaker statement).
    status : Status
        PROVED when the search ran to completion and proved some box (the boundary boxes
        are narrower than eps), UNDECIDED when it completed without proving any box (or
        DISPROVED when every box is proven outside), BUDGET when a limit stopped it.
    pieces : PolytopeUnion or None
        For ``method="affine_state"`` (thesis Alg 6.4) the set is this union of polytopes,
        each proven in the set with its control ``witness[k]`` (then ``witness`` has one
        row per piece and the paving holds no box: its domain only).
    details : dict or None
        Method-specific data. Affine-state method: the x_NL grid ``boxes`` (N, p, 2), per
        piece its ``box`` index, the target ``member`` it reaches and the offsets ``c`` of
        its x_L part ``{x_L in D_lin : rows[member] x_L <= c}``, the nonlinear and linear
        state indices ``nl`` and ``lin``.
    """

    witness: np.ndarray | None = None
    semantics: str = ROBUST
    target: Any = None
    pieces: PolytopeUnion | None = None
    details: dict | None = None

    @property
    def verdict(self) -> str:
        """What the result proves, in words (see :attr:`SetResult.verdict`; for the
        affine-state method: the number of proven polytope pieces)."""
        if self.pieces is None:
            return super().verdict
        k = len(self.pieces)
        return (f"{k} polytope piece{'s' if k != 1 else ''} proven ({self.semantics})" if k
                else "no polytope piece proven")

    def _repr_note(self) -> str | None:
        if self.pieces is None:
            return super()._repr_note()
        return None if len(self.pieces) else self.verdict

    def _repr_parts(self) -> list[str]:
        if self.pieces is not None:
            return [f"pieces={len(self.pieces)}", f"semantics={self.semantics!r}"]
        p = self.paving
        return [f"inner={p.n_inner}", f"boundary={p.n_boundary}",
                f"semantics={self.semantics!r}"]

    def area(self, view: str = "inner") -> float:
        """Area (volume) of the inner boxes (``view="outer"``: inner and boundary); of the
        union of the pieces for the affine-state method (``view="inner"`` only)."""
        if self.pieces is not None:
            if view != "inner":
                raise ValueError("the affine-state method gives an inner approximation only; "
                                 "use view='inner'")
            from .affine_state import union_volume

            return union_volume(self.details or {})
        return self.paving.volume(view=view)

    def contains(self, points: Any) -> np.ndarray | bool:
        """Whether points lie in an inner box (proven members of the set), or in a piece
        for the affine-state method."""
        if self.pieces is not None:
            P = np.atleast_2d(np.asarray(points, dtype=float))
            out = self._first_piece(P) >= 0
            return out if np.ndim(points) > 1 else bool(out[0])
        return self.paving.contains(points, view="inner")

    def _first_piece(self, P: np.ndarray) -> np.ndarray:
        """Per point of P (N, n), the index of the first piece holding it (-1: none), by
        the exact membership test of the pieces. With the affine-state details, only the
        pieces of the x_NL cells that hold a point are asked (a piece lies in its cell,
        so the answer is the same)."""
        N = P.shape[0]
        first = np.full(N, -1, dtype=np.intp)
        if not len(self.pieces):
            return first
        polys = self.pieces.polytopes
        d = self.details or {}
        if not {"boxes", "box", "nl"} <= set(d) or len(d["box"]) != len(polys):
            for k, Q in enumerate(polys):
                free = np.flatnonzero(first < 0)
                if not free.size:
                    break
                hit = np.asarray(Q.contains(P[free]), dtype=bool)
                first[free[hit]] = k
            return first
        boxes, bix, nl = d["boxes"], np.asarray(d["box"]), list(d["nl"])
        Pn = P[:, nl]
        order = np.argsort(bix, kind="stable")  # pieces of a cell, in their order
        cells, starts = np.unique(bix[order], return_index=True)
        ends = np.append(starts[1:], order.size)
        for c, a, b in zip(cells, starts, ends, strict=True):
            B = boxes[c]
            sel = np.flatnonzero(((Pn >= B[:, 0]) & (Pn <= B[:, 1])).all(axis=1))
            for k in order[a:b]:
                # a point on a face of two cells may already hold an earlier piece
                sel = sel[(first[sel] < 0) | (first[sel] > k)]
                if not sel.size:
                    break
                hit = np.asarray(polys[k].contains(P[sel]), dtype=bool)
                first[sel[hit]] = k
                sel = sel[~hit]
        return first

    def control(self, x: Any) -> np.ndarray | None:
        """The stored proving control of the first inner box (or piece) containing ``x``
        (n,), or None when ``x`` lies in none or the method stores no control."""
        n = self.paving.dim
        arr = np.asarray(x, dtype=float)
        if arr.shape not in ((n,), (1, n)) and not (n == 1 and arr.size == 1):
            raise DimensionError(f"x must be one state of shape ({n},); got shape "
                                 f"{arr.shape} (for many points use contains(points))")
        if self.witness is None:
            return None
        x = arr.reshape(-1)
        if self.pieces is not None:
            k = int(self._first_piece(x[None])[0])
            return None if k < 0 else self.witness[k].copy()
        I = self.paving.inner
        hit = np.flatnonzero(((I[..., 0] <= x) & (x <= I[..., 1])).all(axis=1))
        return None if hit.size == 0 else self.witness[hit[0]].copy()

    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), model: Any = None,
             **kw: Any) -> Any:
        """Draw the paving (inner green, boundary yellow), or the pieces of the affine-state
        method. The axes are labelled with the model's state names and units when ``model``
        is given, else ``x1, x2``."""
        from ..plot import axis_label, variable_labels

        if self.pieces is not None:
            import matplotlib.pyplot as plt

            if ax is None:
                _, ax = plt.subplots()
            kw.setdefault("facecolor", "tab:green")
            kw.setdefault("alpha", 0.5)
            if len(self.pieces):
                self.pieces.plot(ax=ax, dims=dims, **kw)
            D = self.paving.domain
            if D is not None:
                ax.set_xlim(D.lo[dims[0]], D.hi[dims[0]])
                ax.set_ylim(D.lo[dims[1]], D.hi[dims[1]])
            names, units = variable_labels(model, "x", d=self.paving.dim)
            ax.set_xlabel(axis_label(names[dims[0]], units[dims[0]]))
            ax.set_ylabel(axis_label(names[dims[1]], units[dims[1]]))
            return ax
        ax = self.paving.plot(ax=ax, dims=dims, **kw)
        names, units = variable_labels(model, "x", d=self.paving.dim)
        ax.set_xlabel(axis_label(names[dims[0]], units[dims[0]]))
        ax.set_ylabel(axis_label(names[dims[1]], units[dims[1]]))
        return ax


# ----------------------------------------------------------------------------- search
def _w_setup(model: Model, robust: bool, w_points: Any) -> tuple[np.ndarray, np.ndarray, str]:
    """(W box for the inclusion test (l, 2), exclusion points (C, l), semantics)."""
    l = model.l
    if l == 0:
        return np.zeros((0, 2)), np.zeros((1, 0)), NO_W
    Wb = model.W.as_array()
    centre = np.clip(0.5 * Wb[:, 0] + 0.5 * Wb[:, 1], Wb[:, 0], Wb[:, 1])
    if not robust:
        return np.stack([centre, centre], axis=-1), centre[None], NOMINAL
    if w_points is not None:
        P = np.atleast_2d(np.asarray(w_points, dtype=float))
        if P.shape[1] != l or not model.W.contains(P).all():
            raise ValueError(f"w_points must be points of W, shape (C, {l})")
        return Wb, P, ROBUST
    pts = [centre]
    if l <= 3:
        pts += list(np.asarray(model.W.vertices()))
    else:
        for j in range(l):
            for side in (0, 1):
                p = centre.copy()
                p[j] = Wb[j, side]
                pts.append(p)
    return Wb, np.unique(np.asarray(pts), axis=0), ROBUST


def _search(model: Model, target: _Target, X0: np.ndarray, eps: float, *, robust: bool,
            obstacles: list[Any], u_eps: float, max_cells: int, w_points: Any,
            x_scale: np.ndarray | None, max_boxes: int, time_limit: float | None,
            progress: bool | None, desc: str, executor: Any = None) -> dict[str, Any]:
    """One pair search from the state boxes X0 (N, n, 2); raw arrays of the outcome."""
    Wb, wpts, semantics = _w_setup(model, robust, w_points)
    clf = _OneStepClassifier(target, Wb, wpts, obstacles)
    N0 = X0.shape[0]
    fr = PairFrontier.from_boxes(X0, model.U.as_array(), x_scale=x_scale, u_eps=u_eps,
                                 max_cells=max_cells,
                                 data={"witness": np.full((N0, model.m), np.nan)})
    out = branch_and_bound(fr, clf, eps, max_boxes=max_boxes, time_limit=time_limit,
                           keep_outer=True, progress=progress, desc=desc, executor=executor)
    bnd = out.boundary.x_boxes
    if bnd.shape[0]:  # leftovers of a stopped search hold several cells per box
        bnd = np.unique(bnd, axis=0)
    return {"inner": out.inner.x_boxes, "witness": out.inner.data["witness"],
            "boundary": bnd, "outer": out.outer.x_boxes, "status": out.status,
            "message": out.message, "levels": out.levels, "n_classified": out.n_classified,
            "n_discarded": out.n_discarded, "elapsed": out.elapsed, "n_pairs": out.n_classified,
            "semantics": semantics}


def proof_w_box(model: Model, robust: bool) -> list[list[float]] | None:
    """The disturbances the sets of a computation are proven for, as ``[lo, hi]`` lists
    (W when robust, the thin box at its centre when nominal; None without disturbance):
    what a controller driving along them may claim (stored in a sequence's info)."""
    if not model.l:
        return None
    Wb, _, _ = _w_setup(model, robust, None)
    return [Wb[:, 0].tolist(), Wb[:, 1].tolist()]


def _domain(model: Model, X: Any) -> Box:
    if X is None:
        D = model.X
    else:
        b = as_boxes(X, model.n, "X")
        if b.shape[0] != 1:
            raise DimensionError("X must be one box (give obstacles= for holes)")
        D = Box(b[0, :, 0], b[0, :, 1])
    if not (np.isfinite(D.lo).all() and np.isfinite(D.hi).all()):
        raise ValueError(f"the state box must be bounded; got {D}")
    return D


def one_step_set(model: Model, target: Any, eps: float, *, robust: bool = False,
                 method: str = "auto", X: Any = None, obstacles: Any = None,
                 u_eps: float = 1 / 16, max_cells: int = 64, w_points: Any = None,
                 relative: bool = False, max_boxes: int = 2_000_000,
                 time_limit: float | None = None, progress: bool | None = None,
                 options: dict[str, Any] | None = None, executor: Any = None) -> OneStepSet:
    """Inner approximation of the one-step controllable set ``K(X, T)`` (Alg 4.6, 6.1, 5.2).

    Parameters
    ----------
    model : Model
        ``x+ = f(x, u, w)``; U (bounded) and W are the model's boxes.
    target : Polytope, PolytopeUnion, Paving, Zonotope, Box, SetUnion or list of them
        The set T to reach in one step (of a Paving, its inner boxes).
    eps : float
        State boxes narrower than eps (relative to X when ``relative``) are not bisected.
    robust : bool
        ``True``: ``exists u in U, for all w in W: f(x, u, w) in T`` (the control may depend
        on the state, never on w). ``False``: w fixed at the centre of W (no effect for a
        model without disturbance).
    method : {"auto", "general", "modal", "affine_state"}
        ``"auto"``: ``"affine_state"`` for a model with an affine state part (some states
        enter f only linearly, :attr:`Model.nonlinear_states`), a polytopic target and no
        obstacles; ``"general"`` otherwise (the result's ``method`` says which ran).
        ``"general"``: the nested state × control search of
        Alg 4.6/6.1, with a proving control per inner box. ``"affine_state"`` (thesis
        §6.2, Alg 6.4): only the nonlinear states and U are gridded (cells of the width a
        bisection to eps reaches; controls: the midpoints of the dyadic cells of U down to
        ``u_eps``), and the set is a union of polytope pieces (``res.pieces``), each with
        its proving control (``res.witness``); it runs in this process (``executor`` is
        not used) and ``max_boxes`` bounds its (cell, control) pairs. ``"modal"``: quantified set
        inversion with modal intervals (Alg 5.2, :func:`casadi_cmpc.quantified_sivia`),
        which proves the **weaker** ``for all w exists u`` (u may depend on w) and gives no
        control; only for one Polytope or Box target.
    X : Box, optional
        State constraint box (default: the model's X); the set is searched inside it.
    obstacles : Box, Polytope or list, optional
        Forbidden state regions (X with holes): an inner box is proven disjoint from every
        obstacle.
    u_eps : float
        Control cells narrower than this fraction of U (per component) are not split.
    max_cells : int
        Largest number of control cells examined at once per state box.
    w_points : array_like (C, l), optional
        Points of W used to discard control cells (default: centre and vertices of W for
        ``l <= 3``, centre and the centres of the faces otherwise). Any points of W are
        sound; more points discard more.
    relative : bool
        Measure state widths relative to X.
    max_boxes, time_limit, progress
        Budget (pairs classified, seconds) and tqdm bar; a stopped search is still sound
        (the rest is boundary) and has status BUDGET.
    options : dict, optional
        For ``method="modal"``: passed to :func:`casadi_cmpc.quantified_sivia`.
    executor : concurrent.futures.Executor, optional
        Classify the large levels of the search on this executor: a
        ``ProcessPoolExecutor(n)`` on this machine, or ``distributed.Client(address)
        .get_executor()`` on a Dask cluster (workers with casadi_cmpc installed). The result
        is that of the serial run (the same boxes in the same order; see
        :mod:`casadi_cmpc.solvers._parallel` for the one caveat, libm functions).

    Returns
    -------
    OneStepSet
        ``paving`` (inner, boundary, outer boxes), ``witness`` (a proving control per inner
        box), ``semantics``, ``status``.

    Notes
    -----
    **Proof of an inner box.** For a polytope ``T = {y : H y <= h}`` the composed rows
    ``H f(x, u, w)`` are enclosed by the centered form over the box × {u} × W (outward
    rounding; H is a thin input of the graph, so CasADi folds no constant): every upper
    bound ``<= h`` proves ``f(x, u, w) in T`` for all x of the box and all w. For a union,
    one member must contain the image; for box unions and zonotopes, the interval hull of
    the image must be inside (exact box-union cover; zonotope facet test).

    **Discarded cells and boxes.** A control cell is discarded for a state box when, for a
    point ``w_c`` of W, the image ``f(box, cell, w_c)`` is proven disjoint from T. A box is
    outside when all its cells are discarded: then for every control some w fails, which is
    the negation of ``exists u for all w``. The cells of a state box always cover U apart
    from cells discarded before, for the box or a box containing it.

    Examples
    --------
    >>> import casadi_cmpc as cm
    >>> ex = cm.models.load("cannon")                                  # doctest: +SKIP
    >>> K1 = cm.one_step_set(ex.model, ex.terminal, eps=0.05)          # doctest: +SKIP
    """
    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    if model.m == 0:
        raise ModelError(f"model '{model.name}' has no input: a one-step controllable set "
                         "needs a control")
    if not (np.isfinite(model.U.lo).all() and np.isfinite(model.U.hi).all()):
        raise ValueError(f"U must be bounded; got {model.U}")
    meth = str(method).lower()
    if meth not in ("auto", "general", "modal", "affine_state"):
        raise ValueError(f"unknown method '{method}'; valid methods: auto, general, modal, "
                         "affine_state")
    eps = positive_eps(eps)
    D = _domain(model, X)
    obs = _as_obstacles(obstacles, model.n)
    if meth == "auto":
        from .affine_state import is_polytopic

        meth = ("affine_state" if model.has_affine_state_part and not obs
                and options is None and is_polytopic(target) else "general")
    if meth == "affine_state":
        if obs:
            raise ValueError("method='affine_state' does not take obstacles; use "
                             "method='general'")
        if options:
            raise ValueError("options are for method='modal'")
        return _affine(model, target, eps, D, robust=robust, u_eps=u_eps, relative=relative,
                       max_boxes=max_boxes, time_limit=time_limit)
    if meth == "modal":
        return _modal(model, target, eps, D, robust, relative, max_boxes, time_limit,
                      progress, options, obs, executor=executor)
    if options:
        raise ValueError("options are for method='modal'")
    T = _Target(model, target)
    scale = np.where(D.diam > 0, D.diam, 1.0) if relative else None
    r = _search(model, T, D.as_array()[None], eps, robust=robust, obstacles=obs,
                u_eps=float(u_eps), max_cells=int(max_cells), w_points=w_points,
                x_scale=scale, max_boxes=max_boxes, time_limit=time_limit,
                progress=progress, desc="one-step set", executor=executor)
    pav = Paving(inner=r["inner"], boundary=r["boundary"], outside=r["outer"], domain=D,
                 n_discarded=r["n_discarded"])
    status, msg = _what_was_proven(r["status"], r["message"], pav, r["semantics"])
    msg += f"; {about_model(model, robust)}"
    return OneStepSet(status=status, message=msg, method="general (Alg 4.6/6.1)",
                      nit=r["levels"], n_boxes=r["n_classified"], elapsed=r["elapsed"],
                      paving=pav, witness=r["witness"], semantics=r["semantics"],
                      target=target, n_pairs=r["n_pairs"])


def _affine(model: Model, target: Any, eps: float, D: Box, *, robust: bool, u_eps: float,
            relative: bool, max_boxes: int, time_limit: float | None) -> OneStepSet:
    """The one-step set by the affine-state method (Alg 6.4) as a :class:`OneStepSet`."""
    from .affine_state import affine_state_pieces, check_members

    members = check_members(target, model.n)
    _, _, semantics = _w_setup(model, robust, None)
    if not (0 < u_eps <= 1):
        raise ValueError(f"u_eps must be in (0, 1]; got {u_eps}")
    r = affine_state_pieces(model, members, D, eps, robust=robust, u_eps=float(u_eps),
                            relative=relative, max_pairs=int(max_boxes),
                            time_limit=time_limit)
    K = len(r["pieces"])
    nl = list(r["nl"])
    about = f"{about_model(model, robust)}; target of {len(members)} polytope(s)"
    msg = (f"{K} polytope pieces proven ({semantics}); {about}; x_NL = states {nl} gridded "
           f"into {r['boxes'].shape[0]} boxes")
    if r["complete"]:
        status = Status.PROVED if K else Status.UNDECIDED
        if not K:
            msg = f"no polytope piece proven ({semantics}); {about}"
    else:
        status = Status.BUDGET
        msg += "; stopped by the budget (the pieces found are proven)"
    pav = Paving(inner=np.zeros((0, model.n, 2)), domain=D)
    return OneStepSet(status=status, message=msg, method="affine state (Alg 6.4)",
                      nit=1, n_boxes=int(r["boxes"].shape[0]), elapsed=r["seconds"],
                      paving=pav, witness=r["witness"], semantics=semantics, target=target,
                      n_pairs=int(r["n_pairs"]), pieces=PolytopeUnion(r["pieces"],
                                                                      dim=model.n),
                      details={k: r[k] for k in ("boxes", "box", "member", "rows", "offsets",
                                                 "D_lin", "nl", "lin")})


def about_model(model: Model, robust: bool) -> str:
    """What a set of this module is a claim about: the model (and what its map is: a
    discrete model, the Euler/RK4 map of an ODE, or the validated sampled-data ODE) and the
    disturbances it covers."""
    if model.W is None:
        dist = "no disturbance"
    elif robust:
        dist = f"every w in W = {model.W}"
    else:
        dist = f"w at the centre of W = {model.W} only (nominal)"
    return f"about model '{model.name}' ({model.discretisation}), {dist}"


def _what_was_proven(status: Status, message: str, pav: Paving, semantics: str
                     ) -> tuple[Status, str]:
    """The status and message of a one-step set, read from what its paving proves: a
    completed search with no inner box is not PROVED (UNDECIDED while boxes are undecided,
    DISPROVED when every box is proven outside: no state of X can reach the target)."""
    msg = (f"{pav.n_inner} state boxes proven ({semantics}), {pav.n_boundary} undecided; "
           f"{message}")
    if status == Status.PROVED and pav.n_inner == 0:
        if pav.n_boundary:
            return Status.UNDECIDED, (f"no state box proven ({pav.n_boundary} undecided): "
                                      "try a smaller eps, more control cells (u_eps, "
                                      "max_cells) or relative=True; " + message)
        return Status.DISPROVED, (f"every state box is proven outside ({semantics}): no "
                                  "state of X reaches the target; " + message)
    return status, msg


def _modal_rows(model: Model, A: np.ndarray, robust: bool) -> tuple[ca.Function, Box | None]:
    """The rows ``A f(x, u, w)`` as a Function for :func:`quantified_sivia`, and its W.

    Nothing is replaced by a number: CasADi would fold the constant subexpressions of the
    result in floating point (``exp(w + 0.1)`` with ``w = 0`` would become
    ``fl(exp(0.1))``, ``3 * f_j`` with a constant ``f_j = 0.7`` would become
    ``fl(3 * 0.7)``), and the proof would be about a rounded model. So w stays a symbol:
    over W (``robust``) or over the thin box ``[c, c]`` at the centre ``c`` of W
    (nominal); and a constant element ``f_j`` of f enters as one more thin component of w
    (universal quantification over one point), so that ``A_ij f_j`` is an interval product.
    With neither w nor a constant element, the Function takes ``(x, u)`` and W is None.

    Parameters
    ----------
    model : Model
    A : ndarray, shape (r, n)
        The rows of the target polytope.
    robust : bool
        Quantify w over W (else: at the centre of W).

    Returns
    -------
    (casadi.Function, Box or None)
        ``(x, u[, w'])`` -> ``A f`` of shape (r, 1), with ``w'`` = ``(w, constants of f)``;
        the box of ``w'`` (None without ``w'``).
    """
    if model._exact_f is not None:
        raise ModelError(
            f"method='modal' works on the expressions of f, and model '{model.name}' is "
            f"{model.discretisation}: its proofs need the exact interval source (use "
            "method='general')")
    f = model.f
    const = [j for j in range(model.n) if f[j].is_constant()]
    s = ca.SX.sym("s", len(const))
    fs = ca.vertcat(*[s[const.index(j)] if j in const else f[j] for j in range(model.n)])
    rows = ca.mtimes(ca.DM(A), fs)  # A_ij f_j folds only for a constant f_j, a symbol here
    lo, hi, syms = [], [], []
    if model.l:
        Wa = _w_setup(model, robust, None)[0]  # W, or [c, c] at its centre as for "general"
        lo.append(Wa[:, 0])
        hi.append(Wa[:, 1])
        syms.append(model.w)
    if const:
        v = np.array([float(ca.DM(f[j])) for j in const])
        lo.append(v)
        hi.append(v)
        syms.append(s)
    if not syms:
        return ca.Function("target_rows", [model.x, model.u], [rows]), None
    w = ca.vertcat(*syms)
    g = ca.Function("target_rows", [model.x, model.u, w], [rows])
    return g, Box(np.concatenate(lo), np.concatenate(hi))


def _modal(model: Model, target: Any, eps: float, D: Box, robust: bool, relative: bool,
           max_boxes: int, time_limit: float | None, progress: bool | None,
           options: dict[str, Any] | None, obstacles: list[Any],
           executor: Any = None) -> OneStepSet:
    from ..solvers.quantified import quantified_sivia

    members = _flatten(target)
    if len(members) != 1 or not isinstance(members[0], Polytope):
        raise ValueError("method='modal' needs one Polytope or Box target")
    P = members[0]
    A, b = np.asarray(P.A, dtype=float), np.asarray(P.b, dtype=float)
    g, Wb = _modal_rows(model, A, robust)
    sem = (MODAL if robust else NOMINAL) if model.l else NO_W
    Y = Box(np.full(A.shape[0], -np.inf), b)
    t0 = time.perf_counter()
    pav = quantified_sivia(g, D, model.U, Wb, Y, eps, options=options, relative=relative,
                           max_boxes=max_boxes, time_limit=time_limit, progress=progress,
                           executor=executor)
    if obstacles:
        # inner boxes that may meet an obstacle are not proven members: undecided; boxes
        # inside an obstacle are outside
        I = pav.inner
        meet = np.zeros(I.shape[0], dtype=bool)
        buried = np.zeros(I.shape[0], dtype=bool)
        for ob in obstacles:
            meet |= np.asarray(ob.intersects_box(I), dtype=bool)
            buried |= np.asarray(ob.contains_box(I), dtype=bool)
        status, message, levels, ncl, npairs = (pav.status, pav.message, pav.levels,
                                                pav.n_classified, pav.n_pairs)
        pav = Paving(inner=I[~meet], boundary=np.concatenate([pav.boundary, I[meet & ~buried]]),
                     outside=np.concatenate([pav.outside, I[buried]]), domain=D,
                     n_discarded=pav.n_discarded + int(buried.sum()))
        pav.status, pav.message, pav.levels, pav.n_classified, pav.n_pairs = (
            status, message, levels, ncl, npairs)
    status, msg = _what_was_proven(pav.status, pav.message, pav, sem)
    msg += f"; {about_model(model, robust)}"
    return OneStepSet(status=status, message=msg, method="modal (Alg 5.2)",
                      nit=pav.levels, n_boxes=pav.n_classified,
                      elapsed=time.perf_counter() - t0, paving=pav, witness=None,
                      semantics=sem, target=target, n_pairs=pav.n_pairs)


def _check_terminal(model: Model, T: Any, law: Any, certificate: Any,
                    assume_invariant: bool, robust: bool, eps: float, X: Box,
                    executor: Any = None, prove: bool = True) -> Any:
    """The certificate of T's invariance (certified on ``executor`` when given), or a clear
    error. ``prove=False``: the checks only (None where T is to be certified under
    ``law``: :func:`_prove_terminal` does it)."""
    from ..solvers.result import Certificate

    n = model.n
    D = np.vstack([np.eye(n), -np.eye(n)])
    up = T._support_upper(D) if not T.is_empty() and T.is_bounded() else np.full(2 * n,
                                                                                 np.inf)
    if not ((up[:n] <= X.hi).all() and (up[n:] <= -X.lo).all()):
        raise ValueError("the terminal set must lie inside the state box X (proven with "
                         "rigorous support bounds); intersect it with X and certify the "
                         "intersection")
    if assume_invariant:
        return Certificate("assumed", None, "T is control invariant",
                           "assume_invariant=True: not proven; the sets are then inner "
                           "approximations of the i-step sets only if T is invariant")
    W_need = _terminal_W(model, robust)
    if certificate is not None:
        from .invariance import check_about

        why = check_about(certificate, model, T, W_need, law)
        if why is not None:
            raise ValueError(
                f"certificate does not prove T invariant for this problem: {why}. Give the "
                "proved Certificate of cm.certify_invariant(model, T, law, ...) for this "
                "model, this T and " + ("W" if robust else "the centre of W") + ", or law= "
                "to certify T here")
        return certificate
    if law is None:
        raise ValueError(
            "the terminal set must be proven (robustly) control invariant: pass law= (the "
            "local law, e.g. a gain K with u = K x) to certify it with cm.certify_invariant, "
            "or certificate= a proved Certificate, or assume_invariant=True to proceed "
            "without a proof")
    if not isinstance(T, Polytope):
        raise ValueError("certifying T with law= needs T as a Polytope")
    if not prove:
        return None
    return _proven_or_raise(_prove_terminal(model, T, law, W_need, executor))


def _prove_terminal(model: Model, T: Polytope, law: Any, W: Box | None,
                    executor: Any = None) -> Any:
    """certify_invariant of T under ``law`` for W at finer pieces (relative to T) while
    undecided: its certificate, proven or not."""
    from .invariance import certify_invariant

    size = float(np.max(T.bounding_box().diam))
    for e in (0.02, 0.005, 0.0015, 0.0005):
        cert = certify_invariant(model, T, law, eps=e * size, W=W, time_limit=60,
                                 executor=executor)
        if cert.proved is not None:
            break
    return cert


def _prove_terminal_task(blob: bytes) -> Any:
    """Worker side of :func:`_prove_terminal` (model, T, law and W pickled together, so
    that the law's symbols are the model's)."""
    import pickle

    with ca.global_unpickle_context():
        model, T, law, W = pickle.loads(blob)
    return _prove_terminal(model, T, law, W)


def _proven_or_raise(cert: Any) -> Any:
    if cert.proved is not True:
        raise ValueError(f"the terminal set is not proven invariant under the law "
                         f"({cert.label}: {cert.reason}); pass assume_invariant=True to "
                         "proceed without a proof")
    return cert


def _terminal_beside(model: Model, T: Polytope, law: Any, robust: bool, executor: Any
                     ) -> Any:
    """T's proof submitted to ``executor`` as one task, to run beside the first steps (a
    future), or None when it cannot be sent (the caller proves T here)."""
    from ..solvers._parallel import _dumps

    try:
        blob = _dumps((model, T, law, _terminal_W(model, robust)))
        return executor.submit(_prove_terminal_task, blob)
    except Exception:  # noqa: BLE001 - not picklable, or a pool that takes no task
        return None


def _terminal_W(model: Model, robust: bool) -> Box | None:
    """The disturbance box T is proven invariant for: W (robust), the thin box at the centre
    of W that the one-step sets use (nominal, see :func:`_w_setup`), None without w."""
    if not model.l:
        return None
    if robust:
        return model.W
    Wc = _w_setup(model, False, None)[0]
    return Box(Wc[:, 0], Wc[:, 1])


def _stored_terminal(model: Model, saved: Any, law: Any, certificate: Any,
                     assume_invariant: bool, robust: bool) -> dict[str, Any] | None:
    """The entries of T's proof in a checkpoint's info (``terminal_*``, ``model_key``) when
    they are what certifying T under ``law`` gives (T proven, for this law and W): then T
    is not certified again. None otherwise (no checkpoint, or T is to be certified,
    assumed invariant or backed by a given certificate)."""
    if saved is None or law is None or certificate is not None or assume_invariant:
        return None
    from .invariance import law_identity

    try:
        law_key = law_identity(model, law)["law_key"]
    except Exception:  # a bad law: certifying reports it
        return None
    W = _terminal_W(model, robust)
    expected = {"terminal_certificate": "proved", "terminal_law_key": law_key,
                "terminal_W": None if W is None else [np.asarray(W.lo).tolist(),
                                                      np.asarray(W.hi).tolist()]}
    info = saved.info
    if any(info.get(k) != v for k, v in expected.items()):
        return None
    return {k: v for k, v in info.items() if k == "model_key" or k.startswith("terminal_")}


def _terminal_info(model: Model, cert: Any) -> dict[str, Any]:
    """What the sequence stores of T's certificate: the law it proves (text, key,
    serialized Function), the disturbance box it covers and the claim."""
    from .invariance import model_key

    ab = getattr(cert, "about", None) or {}
    out: dict[str, Any] = {"terminal_claim": cert.claim, "model_key": model_key(model)}
    if cert.proved is True and ab.get("law_key"):
        out.update(terminal_law=ab["law"], terminal_law_key=ab["law_key"],
                   terminal_law_function=ab["law_function"])
        if ab.get("W") is not None:
            out["terminal_W"] = [np.asarray(ab["W"].lo).tolist(),
                                 np.asarray(ab["W"].hi).tolist()]
    return out


def controllable_sets(model: Model, T: Any, eps: float, *, robust: bool = False,
                      polytopic: bool = False, polytopic_method: str | None = None,
                      max_steps: int = 100, law: Any = None, certificate: Any = None,
                      assume_invariant: bool = False, X: Any = None, obstacles: Any = None,
                      u_eps: float = 1 / 16, max_cells: int = 64, w_points: Any = None,
                      until: Any = None, max_boxes: int = 2_000_000,
                      time_limit: float | None = None, progress: bool | None = None,
                      checkpoint: str | os.PathLike[str] | None = None,
                      executor: Any = None, method: str = "general") -> Any:
    """The sequence ``K_0 = T, K_{i+1} = K(X, K_i)`` of (robust) controllable sets (Alg 4.6,
    6.1, (6.8)), each a proven inner approximation, to convergence.

    Parameters
    ----------
    model : Model
    T : Polytope
        Terminal set, (robustly) control invariant. It must be proven so: give ``law`` (the
        local law: a :class:`~casadi_cmpc.LinearLaw` ``u = u_eq + K (x - x_eq)`` as
        :func:`~casadi_cmpc.local_lqr` returns, a bare gain ``K`` (m, n), ``u = K x``, or
        an SX expression of ``model.x``),
        or ``certificate`` (a proved :class:`~casadi_cmpc.Certificate` of
        :func:`~casadi_cmpc.certify_invariant` about this model, this very T and W, or the
        centre of W when ``robust=False``: checked, with a clear error otherwise), or
        ``assume_invariant=True`` to proceed without a proof (then nothing is claimed about
        the nesting of the sets).
    eps : float
        State resolution of every step (see :func:`one_step_set`).
    robust : bool
        ``exists u for all w`` (True) or w at the centre of W (False).
    polytopic : bool
        After each step, replace the union of proven boxes by one polytope proven inside it
        (:func:`casadi_cmpc.inner_polytope`, ``polytopic_method`` = ``"separating"``, Alg
        6.2, the default, or ``"scaling"``, Alg 6.5); the next target is the union ``T ∪
        P_1 ∪ ... ∪ P_i`` (6.8).
    max_steps : int
        Largest number of steps.
    X, obstacles, u_eps, max_cells, w_points
        As in :func:`one_step_set`.
    until : array_like (k, n), optional
        Stop as soon as all these states lie in the last set.
    max_boxes, time_limit
        Budget of each step (pairs; seconds).
    progress : bool or None
        tqdm bar over the steps: the steps done, the boxes proven (and the new ones), the
        mean time of the last steps and, once the number of new boxes per step declines,
        an estimate of the time left (assuming the decline goes on geometrically until no
        new box is proven). ``False``: silent.
    checkpoint : str or Path, optional
        A file (``.npz``; ``.json`` also works) that makes the run resumable. After each
        completed step the sequence so far is written there (by :meth:`SetSequence.save`,
        with the state boxes the next step searches and the key of the problem) through a
        partial file in the same directory renamed over it: Ctrl-C, ``time_limit`` or a
        killed process lose at most the step in progress, and a write cut short leaves the
        previous checkpoint whole. When the file exists, the run resumes after its last
        completed step, and the result equals that of an uninterrupted run (the same boxes
        and controls bit for bit, statuses, ``converged_at`` and number of steps). When the
        run completes the file holds the complete sequence, so a second call returns it
        without searching (nor certifying T again, when T was proven under the same
        ``law``). A step stopped by ``max_boxes`` or ``time_limit`` is not written: the next
        run computes it again. ``max_steps``, ``until``, ``max_boxes``, ``time_limit`` and
        ``progress`` may differ from run to run (the stored steps are replayed under the new
        stopping rules).

        The file must be a checkpoint of the same problem: the model's map f, X, U, W, T,
        eps, robust, polytopic (and its method), obstacles, u_eps, max_cells, the points of
        W that discard control cells, how T's invariance is established (proved under which
        law for which W, or assumed) and the casadi_cmpc version. A checkpoint of another
        problem, or a file that is no checkpoint, is **refused**: a
        :class:`~casadi_cmpc.control._checkpoint.CheckpointError` (a ``ValueError``) names
        the parts that differ, and the file is left untouched. It is not ignored, since
        ignoring it would either overwrite work that may have taken hours (after a typo in
        eps, say) or run without the checkpoint the caller asked for.

    executor : concurrent.futures.Executor, optional
        Classify the large levels of each step's search on this executor
        (``ProcessPoolExecutor(n)``, or ``distributed.Client(address).get_executor()``);
        the sequence is that of the serial run (the same boxes in the same order). Levels
        with less than about 0.2 s of work run in this process, so small sequences gain
        nothing. Not part of a checkpoint's key: a run may resume with other workers.

    method : {"general", "affine_state"}
        ``"general"``: the nested state × control search of :func:`one_step_set` at every
        step. ``"affine_state"`` (thesis §6.2, Alg 6.4-6.6; models with an affine state
        part, :attr:`Model.nonlinear_states` a strict subset): every step grids only the
        nonlinear states and U, its one-step set is a union of polytopes, and ``P_i`` is
        one polytope proven inside that union and ``P_{i-1}`` (``polytopic_method``,
        default ``"scaling"``, Alg 6.5: with one linear state its proof runs column by
        column of the grid, so its cost does not grow with the number of pieces;
        ``polytopic`` is implied). A state of ``P_i`` outside ``P_{i-1}`` reaches
        ``P_{i-1}`` in one step for all w; the sets need not be nested (``level(x)`` is the
        smallest i with x in ``P_i``). The recursion stops when a polytope grows by less
        than 0.1 % in volume (``converged_at``). ``obstacles`` and ``checkpoint`` are for
        ``"general"``; ``executor`` serves the proof of T here (the grid of each step runs
        in this process: it takes milliseconds to seconds); ``max_boxes`` bounds the (x_NL
        box, control) pairs of a step.

    Returns
    -------
    SetSequence
        ``sets[i]`` = K_i (a :class:`~casadi_cmpc.SetUnion` of T and the proven boxes, or
        the polytopes), ``steps`` (boxes first proven at each step, with proving controls),
        ``converged_at`` (the first i with K_i = K_{i-1}: no new box proven), ``status``,
        ``level(x)``, ``save``/``load``, ``plot``. With ``checkpoint``, ``info["resumed_steps"]``
        is the number of steps read from the checkpoint instead of searched.

    Raises
    ------
    CheckpointError
        ``checkpoint`` is a file of another problem, or no checkpoint (see above).

    Notes
    -----
    Step i+1 starts from what step i left: its inner boxes stay inner (they reach
    K_{i-1} ⊆ K_i), and only its outside and undecided boxes are searched again, against the
    larger target. Every box of K_i is proven to reach K_{i-1} in one step for all w, with
    its stored control; so ``x in K_i`` is steered into T in at most i steps.
    """
    from tqdm.auto import tqdm

    from ._checkpoint import Checkpoint, problem_key, progress_text, terminal_part
    from .linear_sets import SetSequence

    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    if not isinstance(T, Polytope):
        raise TypeError(f"T must be a Polytope; got {type(T).__name__}")
    if T.dim != model.n:
        raise DimensionError(f"T has dimension {T.dim}; the model has n = {model.n}")
    if model.m == 0:
        raise ModelError(f"model '{model.name}' has no input")
    eps = positive_eps(eps)
    max_steps = int(max_steps)
    if max_steps < 1:
        raise ValueError(f"max_steps must be >= 1; got {max_steps}")
    if polytopic_method is None:  # Alg 6.2 for boxes, Alg 6.5 for the affine-state pieces
        polytopic_method = "scaling" if str(method).lower() == "affine_state" else "separating"
    if polytopic_method not in ("separating", "scaling"):
        raise ValueError("polytopic_method must be 'separating' (Alg 6.2) or 'scaling' "
                         "(Alg 6.5)")
    D = _domain(model, X)
    obs = _as_obstacles(obstacles, model.n)
    pts = None if until is None else np.atleast_2d(np.asarray(until, dtype=float))
    meth = str(method).lower()
    if meth not in ("general", "affine_state"):
        raise ValueError(f"unknown method '{method}'; valid methods: general, affine_state")
    if meth == "affine_state":
        from .affine_state import affine_state_sequence

        if obs or checkpoint is not None:
            raise ValueError("obstacles and checkpoint are for method='general'")
        if not 0 < u_eps <= 1:
            raise ValueError(f"u_eps must be in (0, 1]; got {u_eps}")
        cert = _check_terminal(model, T, law, certificate, assume_invariant, robust, eps, D,
                               executor)
        return affine_state_sequence(
            model, T, eps, robust=robust, polytopic_method=polytopic_method,
            max_steps=max_steps,
            terminal_info={"terminal_certificate": cert.label, **_terminal_info(model, cert)},
            D=D, u_eps=float(u_eps), relative=False, until=pts, max_pairs=int(max_boxes),
            time_limit=time_limit, progress=progress)
    t0 = time.perf_counter()
    _, wpts, semantics = _w_setup(model, robust, w_points)
    ck = None if checkpoint is None else Checkpoint(checkpoint)
    key = problem_key(model, T, D, eps=eps, robust=robust, polytopic=polytopic,
                      polytopic_method=polytopic_method, obstacles=obs, u_eps=u_eps,
                      max_cells=max_cells, w_points=wpts)
    saved = None if ck is None else ck.load(key)
    tinfo = _stored_terminal(model, saved, law, certificate, assume_invariant, robust)
    proof = None  # T's proof running beside the first steps (a future)
    if tinfo is None:
        cert = _check_terminal(model, T, law, certificate, assume_invariant, robust, eps, D,
                               prove=False)
        if cert is None:  # T to be certified under law: beside the steps on the executor
            if executor is not None and ck is None:  # (a checkpoint's key holds the proof)
                proof = _terminal_beside(model, T, law, robust, executor)
            if proof is None:
                cert = _proven_or_raise(_prove_terminal(model, T, law,
                                                        _terminal_W(model, robust), executor))
        if cert is not None:
            tinfo = {"terminal_certificate": cert.label, **_terminal_info(model, cert)}
    if tinfo is not None:
        key.append(terminal_part(tinfo))
    done: list[dict[str, Any]] = []  # steps completed in the checkpoint (replayed)
    if saved is not None:
        ck.check(saved, key)
        done, saved_frontier = ck.resume_state(saved, model.n)

    def info_of(tinfo: dict[str, Any]) -> dict[str, Any]:
        return {"model": model.name, "eps": eps, "robust": bool(robust),
                "semantics": semantics, "about": about_model(model, robust),
                "proof_W": proof_w_box(model, robust),
                "polytopic": bool(polytopic),
                "terminal_certificate": tinfo["terminal_certificate"],
                "state_names": [f"x{i + 1}" for i in range(model.n)], **tinfo}

    def terminal_proven() -> dict[str, Any]:
        """The info of T's proof run beside the steps (waiting for it; its worker died:
        here), or the error of a proof that failed."""
        from concurrent.futures.process import BrokenProcessPool

        try:
            cert = proof.result()
        except BrokenProcessPool:
            cert = _prove_terminal(model, T, law, _terminal_W(model, robust))
        cert = _proven_or_raise(cert)
        return {"terminal_certificate": cert.label, **_terminal_info(model, cert)}

    seq = SetSequence(sets=[T], info=info_of(tinfo if tinfo is not None else
                                             {"terminal_certificate": "pending"}))
    frontier = D.as_array()[None]
    inner = np.zeros((0, model.n, 2))
    compact = inner  # the same union as inner, in fewer boxes: what the searches test
    target: Any = T
    polys: list[Polytope] = []
    seq.status = "max_steps"
    # no total: the sequence usually stops at convergence, long before max_steps
    bar = tqdm(total=None, desc="controllable sets", unit="step",
               disable=progress is False, delay=0 if progress else 2.0, leave=False)
    scope = InterruptScope()
    try:
        for i in range(1, max_steps + 1):
            if proof is not None and proof.done():  # a failed proof ends the run now
                tinfo, proof = terminal_proven(), None
            ts = time.perf_counter()
            searched = i > len(done)
            if not searched:  # completed in the checkpoint: its step, as computed then
                step, proved = done[i - 1], True
                if i == len(done):
                    frontier = saved_frontier
            else:
                r = _search(model, _Target(model, target), frontier, eps, robust=robust,
                            obstacles=obs, u_eps=u_eps, max_cells=max_cells,
                            w_points=w_points, x_scale=None, max_boxes=max_boxes,
                            time_limit=time_limit, progress=False, desc=f"K_{i}",
                            executor=executor)
                frontier = np.concatenate([r["outer"], r["boundary"]])
                step = {"boxes": r["inner"], "witness": r["witness"], "polytope": None,
                        "boundary": r["boundary"].shape[0], "seconds": 0.0}
                proved = r["status"] == Status.PROVED
            new = step["boxes"]
            inner = np.concatenate([inner, new])
            if polytopic and new.shape[0]:
                if searched:
                    from .polytopic import inner_polytope

                    step["polytope"] = _as_polytope(inner_polytope(inner,
                                                                   method=polytopic_method))
                P = step["polytope"]
                if P is not None and not P.is_empty():
                    # members proven inside others may be dropped: a smaller target is sound
                    polys = [Q for Q in polys if not Q.is_subset(P)] + [P]
                members = [T] + polys
                K = SetUnion(members, dim=model.n)
            elif polytopic:
                # no new box: K_i = K_{i-1}, held by the same polytopes (a box union here
                # would turn a converged polytopic sequence into a box sequence)
                K = seq.sets[-1]
            else:
                K = SetUnion([T, Paving(inner=inner, domain=D)], dim=model.n)
                # the next search asks only "in K?" and "meets K?" of boxes, exact tests
                # on the union: the same answers from the same union in far fewer boxes
                compact = _compact_union(np.concatenate([compact, new]))
            if searched:
                step["seconds"] = time.perf_counter() - ts
            seq.steps.append(step)
            seq.sets.append(K)
            stop = None
            if not proved:
                stop = "budget"
            elif new.shape[0] == 0:
                stop = "converged"
                seq.converged_at = i
            elif pts is not None and np.all(K.contains(pts)):
                stop = "until"
            if ck is not None and searched and proved:
                ck.write(seq, key, frontier,
                         stop or ("max_steps" if i == max_steps else "interrupted"))
            bar.set_postfix_str(progress_text(
                i, int(inner.shape[0]), [st["boxes"].shape[0] for st in seq.steps],
                [st["seconds"] for st in seq.steps], max_steps), refresh=False)
            bar.update(1)
            if stop is not None:
                seq.status = stop
                break
            target = K if polytopic else SetUnion(
                [T, Paving(inner=compact, domain=D)], dim=model.n)
        if proof is not None:
            tinfo, proof = terminal_proven(), None
    except KeyboardInterrupt:
        scope.reraise_if_nested()
        seq.status = "interrupted"
    finally:
        scope.close()
        bar.close()
        if proof is not None:  # interrupted before T's proof ended: T is not proven
            proof.cancel()
            seq.info = info_of({"terminal_certificate": "not proven (interrupted)"})
    if tinfo is not None and seq.info["terminal_certificate"] == "pending":
        seq.info = info_of(tinfo)
    seq.info["seconds"] = time.perf_counter() - t0
    if ck is not None:
        seq.info["resumed_steps"] = min(len(done), len(seq.steps))
    return seq


def _as_polytope(res: Any) -> Polytope | None:
    """The polytope of an ``inner_polytope`` answer (a Polytope, a pair or a result)."""
    if isinstance(res, Polytope):
        return res
    if isinstance(res, tuple):
        return _as_polytope(res[0])
    P = getattr(res, "polytope", None)
    return P if isinstance(P, Polytope) else None
