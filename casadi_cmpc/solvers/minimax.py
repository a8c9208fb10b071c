"""Constrained minimax optimisation via modal intervals (thesis §5.1.6, Alg 5.3).

Solves

    V* = min { max_{w ∈ W} f(u, w)  :  u ∈ U,  g(u, w) <= 0 for all w ∈ W }

by interval branch and bound over ``u``: one classifier plugged into
:func:`~casadi_cmpc.solvers.engine.branch_and_bound` bounds ``max_w f`` from below on whole
u-boxes with the outer approximation of the semantic extension ``f*(U, Dual W)`` (thesis
Alg 5.3 step 14) and from above at points with its inner approximation (step 15), and
classifies the constraints with outer approximations of ``g*`` (steps 4-7).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import CmpcWarning, DimensionError
from ..interval.modal import SemanticExtension, _partition
from ._common import (
    one_output_function,
    positive_eps,
    single_box,
    split_inclusion,
    thin,
)
from .engine import OUTER, UNDECIDED, BoxFrontier, Status, branch_and_bound
from .result import _BracketResult, _format_point

__all__ = ["minimax", "MinimaxResult"]

_METHODS = ("auto", "alg5.3")
_OPTION_KEYS = ("w_depth", "w_depth_final", "mean_value")
_VERTEX_MAX = 16  # vertices of W used as extra points of the lower bound when 2**l <= this


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class MinimaxResult(_BracketResult):
    """Result of :func:`minimax`: a certified bracket ``lower <= V* <= upper``.

    Fields shared by all solvers (``success``, ``message``, ``elapsed`` in s, ``nit``: levels,
    ``n_boxes``: u-boxes classified) are those of the frozen, keyword-only base
    :class:`~casadi_cmpc.solvers.result.Result`.

    Attributes
    ----------
    status : Status
        ``PROVED``: the search ran to completion and both bounds are finite.
        ``BUDGET``: a limit or an interruption stopped the search; the bracket is still
        certified (the leftover boxes are among the candidates).
        ``DISPROVED``: every u-box was proven to violate a constraint for some w: no u in U
        satisfies ``g(u, w) <= 0`` for all w (``lower = upper = inf``, ``u is None``).
        ``UNDECIDED``: no feasible u could be certified (``upper = inf``).
        ``NUMERICAL``: the enclosure of ``f`` is unbounded below on a candidate box
        (``lower = -inf``).
    method : str
        ``"alg5.3"``.
    lower : float
        Certified: every ``u ∈ U`` with ``g(u, w) <= 0`` for all ``w ∈ W`` has
        ``max_{w ∈ W} f(u, w) >= lower``.
    upper : float
        Certified: ``max_{w ∈ W} f(u, w) <= upper`` at the returned ``u``, which is proven
        feasible; hence ``V* <= upper`` (``inf`` when no feasible u was certified).
    u : ndarray, shape (m,), or None
        The best certified point (``u_feasible``), or None.
    u_feasible : bool
        True when ``u`` is proven to satisfy ``g(u, w) <= 0`` for every ``w ∈ W``.
    w : ndarray, shape (l,), or None
        A worst-case disturbance for ``u`` found by sampling (a guess, not certified).
    fun, width : float
        Read-only: ``upper`` and ``upper - lower``.
    candidates : ndarray, shape (N, m, 2)
        u-boxes that may contain minimax solutions: every solution lies in their union.
    """

    u: np.ndarray | None
    u_feasible: bool
    w: np.ndarray | None

    def _repr_solution(self) -> list[str]:
        return [f"u={_format_point(self.u)}"]


def _check_fun(fun: Any, name: str, m: int, l: int, k: int | None, scalar: bool,
               mean_value: bool | None) -> SemanticExtension:
    """The semantic extension of ``fun`` (a Function of (u, w) or, with ``k`` parameters,
    of (u, w, p)), after checking its inputs and outputs; a SemanticExtension is reused."""
    inputs = ("u", "w") if k is None else ("u", "w", "p")
    raw = fun.fun if isinstance(fun, SemanticExtension) else split_inclusion(fun, name)[0]
    if k is None and getattr(raw, "n_in", lambda: 0)() == 3:
        raise DimensionError(f"{name} takes three inputs (u, w, p): give params, the values "
                             "of p")
    if isinstance(fun, SemanticExtension):
        ext = fun
        if mean_value is not None and bool(mean_value) != ext.mean_value:
            raise ValueError(
                f"{name} is a SemanticExtension built with mean_value={ext.mean_value}; the "
                f"option mean_value={bool(mean_value)} cannot change it (build the extension "
                "with the value wanted, or drop the option)")
        fn = one_output_function(raw, name, inputs)
    else:
        fn = one_output_function(raw, name, inputs)
        ext = None
    if fn.numel_in(0) != m or fn.numel_in(1) != l:
        raise DimensionError(
            f"{name} takes inputs of {fn.numel_in(0)} and {fn.numel_in(1)} elements but U "
            f"has dimension {m} and W dimension {l}")
    if k is not None and fn.numel_in(2) != k:
        raise DimensionError(f"{name} takes a parameter input of {fn.numel_in(2)} elements "
                             f"but params has {k}")
    if scalar and fn.numel_out(0) != 1:
        raise DimensionError(f"{name} must be scalar; '{fn.name()}' has "
                             f"{fn.numel_out(0)} outputs")
    if ext is None:
        ext = SemanticExtension(fn, mean_value=True if mean_value is None else
                                bool(mean_value))
    return ext


class _Minimax:
    """State of one minimax search: the extensions, the W partitions, the certified bound."""

    def __init__(self, fext: SemanticExtension, gext: SemanticExtension | None,
                 U: np.ndarray, W: np.ndarray, params: np.ndarray | None, w_depth: int,
                 w_depth_final: int) -> None:
        self.fext, self.gext = fext, gext
        self.U, self.W = U, W
        self.m, self.l = U.shape[0], W.shape[0]
        # parameters: thin proper components appended to every joint box
        self.P = np.zeros((0, 2)) if params is None else thin(params)
        self.imp_w = np.zeros(self.m + self.l + self.P.shape[0], dtype=bool)
        self.imp_w[self.m:self.m + self.l] = True
        self.cells = self._cells(w_depth)
        self.cells_final = self._cells(w_depth_final)
        pts = [np.clip(0.5 * W[:, 0] + 0.5 * W[:, 1], W[:, 0], W[:, 1])]
        if 2 ** self.l <= _VERTEX_MAX:
            bits = np.array(np.meshgrid(*[[0, 1]] * self.l, indexing="ij")).reshape(self.l, -1).T
            pts.extend(np.where(bits == 1, W[:, 1], W[:, 0]))
        self.points = thin(np.array(pts))  # thin cells: extra points for the lower bound
        self.upper = np.inf
        self.u: np.ndarray | None = None

    def _cells(self, depth: int) -> np.ndarray:
        allowed = np.ones((1, self.l), dtype=bool)
        return _partition(self.W[None], allowed, depth)[0]  # (K, l, 2)

    def _pairs(self, ub: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """Joint boxes (u-box, w-cell, params) for every u-box and cell: (N*K, m+l+k, 2)."""
        N, K = ub.shape[0], cells.shape[0]
        uu = np.repeat(ub, K, axis=0)
        ww = np.tile(cells, (N, 1, 1))
        pp = np.broadcast_to(self.P, (N * K,) + self.P.shape)
        return np.concatenate([uu, ww, pp], axis=1)

    def lower_bounds(self, ub: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lb of min_{u ∈ box} max_w f, proven infeasible) for u-boxes (N, m, 2)."""
        N = ub.shape[0]
        allc = np.concatenate([cells, self.points])
        Z = self._pairs(ub, allc)
        K = allc.shape[0]
        r = self.fext.bounds_unchecked(Z, self.imp_w, outer=True, inner=False)
        lb = r["outer_lo"][:, 0].reshape(N, K).max(axis=1)
        infeasible = np.zeros(N, dtype=bool)
        if self.gext is not None:
            rg = self.gext.bounds_unchecked(Z, self.imp_w, outer=True, inner=False)
            # outer lower bound of g_j*(box, Dual W_k) > 0: ∀u ∈ box ∃w ∈ W_k: g_j(u, w) > 0
            infeasible = (rg["outer_lo"] > 0).any(axis=1).reshape(N, K).any(axis=1)
        return lb, infeasible

    def point_bounds(self, pts: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(ub of max_w f(u, w), proven feasible) at points u (N, m); cells cover W."""
        N, K = pts.shape[0], cells.shape[0]
        Z = self._pairs(thin(pts), cells)
        r = self.fext.bounds_unchecked(Z, self.imp_w, outer=False, inner=True)
        # inner lower bound of f*(u, Dual W_k) is >= max_{w ∈ W_k} f(u, w)
        ub = r["inner_lo"][:, 0].reshape(N, K).max(axis=1)
        ub = np.where(np.isnan(ub), np.inf, ub)
        feasible = np.isfinite(ub)
        if self.gext is not None:
            rg = self.gext.bounds_unchecked(Z, self.imp_w, outer=False, inner=True)
            feasible &= (rg["inner_lo"] <= 0).all(axis=1).reshape(N, K).all(axis=1)
        return ub, feasible

    def certify(self, pts: np.ndarray, cells: np.ndarray) -> None:
        if pts.shape[0] == 0:
            return
        pts = np.clip(pts, self.U[:, 0], self.U[:, 1])
        ub, ok = self.point_bounds(pts, cells)
        if not ok.any():
            return
        k = int(np.argmin(np.where(ok, ub, np.inf)))
        if ub[k] < self.upper:
            self.upper = float(ub[k])
            self.u = pts[k].copy()

    def map(self, fr: BoxFrontier) -> dict[str, np.ndarray]:
        """The per-box part of a classification (pure; run on the workers of an executor):
        lower bounds, proven infeasibility, and the certified value at the midpoint (+inf
        where it is not proven feasible)."""
        with np.errstate(all="ignore"):
            lb, infeasible = self.lower_bounds(fr.boxes, self.cells)
            cert = np.full(len(fr), np.inf)
            live = np.flatnonzero(~infeasible)
            if live.size:
                lo, hi = fr.lo[live], fr.hi[live]
                mid = np.clip(np.clip(0.5 * lo + 0.5 * hi, lo, hi), self.U[:, 0], self.U[:, 1])
                ub, ok = self.point_bounds(mid, self.cells)
                cert[live] = np.where(ok, ub, np.inf)
            return {"lb": lb, "infeasible": infeasible, "cert": cert}

    def combine(self, fr: BoxFrontier, parts: list[dict[str, np.ndarray]]) -> np.ndarray:
        """Labels of a level from its :meth:`map` parts (in order): the best certified
        midpoint lowers the bound, then boxes whose lower bound exceeds it are discarded."""
        r = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if len(parts) > 1 \
            else parts[0]
        lb, infeasible, cert = r["lb"], r["infeasible"], r["cert"]
        live = ~infeasible
        if live.any() and np.isfinite(cert[live]).any():
            lo, hi = fr.lo[live], fr.hi[live]
            mid = np.clip(np.clip(0.5 * lo + 0.5 * hi, lo, hi), self.U[:, 0], self.U[:, 1])
            k = int(np.argmin(cert[live]))
            if cert[live][k] < self.upper:
                self.upper = float(cert[live][k])
                self.u = mid[k].copy()
        labels = np.full(len(fr), UNDECIDED, dtype=np.int8)
        labels[infeasible | (lb > self.upper)] = OUTER
        return labels

    def classify(self, fr: BoxFrontier) -> np.ndarray:
        """Labels of a level (:meth:`map` then :meth:`combine`)."""
        return self.combine(fr, [self.map(fr)])

    __call__ = classify

    def worst_w(self, u: np.ndarray) -> np.ndarray:
        """A maximiser of f(u, .) over a grid of W (a guess)."""
        k = max(2, int(round(4096 ** (1.0 / max(self.l, 1)))))
        k = min(k, 65)
        axes = [np.linspace(lo, hi, k) for lo, hi in self.W]
        grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(self.l, -1).T
        Z = self._pairs(thin(u[None]), thin(grid))
        vals = self.fext.evaluate_unchecked(Z)[:, 0]
        mid = 0.5 * vals[:, 0] + 0.5 * vals[:, 1]
        return grid[int(np.argmax(np.where(np.isfinite(mid), mid, -np.inf)))]


def minimax(f: Any, U: Any, W: Any, eps: float,
            constraints: Any = None, *, params: Any = None, points: Any = None,
            method: str = "auto",
            options: dict[str, Any] | None = None, max_boxes: int = 1_000_000,
            time_limit: float | None = None, progress: bool | None = None,
            executor: Any = None) -> MinimaxResult:
    """Certified constrained minimax: ``min_u max_w f(u, w)`` s.t. ``g(u, w) <= 0`` for all w.

    Thesis §5.1.6, Alg 5.3, as one interval branch and bound over u (see Notes).

    Parameters
    ----------
    f : casadi.Function, InclusionFunction or SemanticExtension
        Continuous scalar SX Function of ``(u, w)``, or of ``(u, w, p)`` with ``params``
        (of an InclusionFunction: its Function, from which the semantic extension is built;
        its natural form is shared through the cache of
        :func:`casadi_cmpc.interval.inclusion`). A
        :class:`~casadi_cmpc.interval.modal.SemanticExtension` of such a Function is used as
        it is: a caller that solves many problems with the same ``f`` and other ``params``
        builds it once (about 1 ms saved per call).
    U : Box or array_like, shape (m, 2)
        Decision box (bounded).
    W : Box or array_like, shape (l, 2)
        Disturbance box (bounded).
    eps : float
        u-boxes whose widest component is at most ``eps`` are not bisected (candidates).
    constraints : casadi.Function, InclusionFunction or SemanticExtension, optional
        Continuous SX Function of ``(u, w)`` (``(u, w, p)`` with ``params``) with a vector
        output ``g``; ``u`` is feasible when ``g(u, w) <= 0`` for **every** ``w ∈ W``.
    params : array_like, shape (k,), optional
        Values of the third input ``p`` of ``f`` and ``constraints``, held fixed (thin
        intervals: exact, nothing is folded into constants). Without it, ``f`` and
        ``constraints`` take ``(u, w)`` only.
    points : array_like, shape (k, m), optional
        Guesses of a minimiser (e.g. from a local solver), clipped to U and tried first:
        the best one proven feasible gives the first ``upper``, which prunes the search from
        its start. The returned ``upper`` is never above the bound certified at the best of
        them (when one is proven feasible).
    method : {"auto", "alg5.3"}
        Only ``"alg5.3"`` (the branch and bound of the Notes).
    options : dict, optional
        ``w_depth`` (int, default ``min(3 l, 9)``): rounds of bisection of W into the cells
        used during the search; ``w_depth_final`` (int, default ``w_depth + 3``): finer cells
        for the final bounds; ``mean_value`` (bool, default True; a SemanticExtension keeps
        its own, and a different value is refused). Unknown keys warn.
    max_boxes, time_limit : optional
        Limits; a stopped search keeps its bracket certified.
    progress : bool or None
        tqdm progress bar (None: only for searches longer than 2 s).

    executor : concurrent.futures.Executor, optional
        Evaluate the bounds of the large levels on this executor (``ProcessPoolExecutor``,
        or ``distributed.Client(address).get_executor()``); the incumbent bound is updated
        once per level in this process, so the result is that of the serial run.

    Returns
    -------
    MinimaxResult
        ``lower``, ``upper`` (certified bracket on ``V*``), ``u`` (proven feasible, with
        ``max_w f(u, w) <= upper``), ``w`` (a worst case for ``u``, not certified),
        ``candidates``, ``status``, ``message``.

    Notes
    -----
    Let ``φ(u) = max_{w ∈ W} f(u, w)`` and ``S = {u ∈ U : g(u, w) <= 0 ∀w ∈ W}``. For a
    partition ``{W_k}`` of W (plus a few points of W: its centre and vertices), the semantic
    extension with u proper and w improper gives, on every u-box ``B``,

    * ``φ(u) >= max_k Lb Outer(f*(B, Dual W_k))`` for all ``u ∈ B`` (thesis (5.16), Alg 5.3
      step 14): the lower bound;
    * ``Lb Outer(g_j*(B, Dual W_k)) > 0`` proves ``∀u ∈ B ∃w: g_j(u, w) > 0``: B holds no
      feasible point and is discarded (steps 4-5);

    and, at the midpoint ``u`` of each box,

    * ``φ(u) <= max_k Lb Inner(f*(u, Dual W_k))`` (thesis (5.15), step 15) and
      ``max_k Lb Inner(g_j*(u, Dual W_k)) <= 0`` proves ``u ∈ S``: the best such bound is the
      certified ``upper``.

    Boxes whose lower bound exceeds ``upper`` are discarded; the others, once narrower than
    ``eps``, are the candidates and ``lower`` is the least lower bound over them (recomputed
    with the finer cells). Both bounds are rigorous (outward rounding throughout).

    Differences from the thesis: Alg 5.3 first computes an inner approximation ``Σ⁻`` of
    ``S`` and then a bracket from one point per box of ``Σ⁻``; it calls the result an
    approximation, since the bracket is only valid over ``Σ⁻``, is not refined, and boxes of
    the boundary of ``S`` are dropped. Here the feasibility test and the bounds are one
    branch and bound over all of ``U``, so the bracket is certified for the exact problem
    over ``S``, and the returned ``u`` is proven to be in ``S``. Its width is limited by
    ``eps`` and by the W-cells where ``f`` is not monotone in ``w`` (a larger ``w_depth``
    tightens it).

    Examples
    --------
    >>> import casadi as ca, casadi_cmpc as cm
    >>> from casadi_cmpc.solvers.minimax import minimax
    >>> u, w = ca.SX.sym("u"), ca.SX.sym("w")
    >>> r = minimax(ca.Function("f", [u, w], [(u - w) ** 2]), cm.Box([-1], [1]),
    ...             cm.Box([-0.5], [0.5]), eps=1e-3)
    >>> bool(r.lower <= 0.25 <= r.upper and r.width < 1e-2)
    True
    """
    t0 = time.perf_counter()
    meth = str(method).lower()
    if meth not in _METHODS:
        raise ValueError(f"Unknown method '{method}'; valid methods: {', '.join(_METHODS)}")
    meth = "alg5.3"
    ub0 = single_box(U, "U")
    wb0 = single_box(W, "W")
    m, l = ub0.shape[0], wb0.shape[0]
    pv = None
    if params is not None:
        pv = np.asarray(params, dtype=float).reshape(-1)
        if not np.isfinite(pv).all():
            raise ValueError(f"params must be finite; got {pv.tolist()}")
    npar = None if pv is None else pv.size
    opts: dict[str, Any] = {"w_depth": min(3 * l, 9)}
    options = {} if options is None else options
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict; got {type(options).__name__}")
    unknown = sorted(set(options) - set(_OPTION_KEYS))
    if unknown:
        warnings.warn(f"minimax ignores the unknown options {unknown}; valid options: "
                      f"{', '.join(_OPTION_KEYS)}", CmpcWarning, stacklevel=2)
    opts.update({k: v for k, v in options.items() if k in _OPTION_KEYS})
    mv = opts.get("mean_value")
    fext = _check_fun(f, "f", m, l, npar, True, mv)
    gext = None if constraints is None else _check_fun(constraints, "constraints", m, l,
                                                       npar, False, mv)
    opts.setdefault("w_depth_final", int(opts["w_depth"]) + 3)
    w_depth, w_final = int(opts["w_depth"]), int(opts["w_depth_final"])
    if w_depth < 0 or w_final < 0:
        raise ValueError(f"options w_depth and w_depth_final must be >= 0; got {w_depth}, "
                         f"{w_final}")
    eps = positive_eps(eps)

    S = _Minimax(fext, gext, ub0, wb0, pv, w_depth, w_final)
    if points is not None:
        P0 = np.asarray(points, dtype=float)
        if P0.ndim == 1 and P0.size == m:
            P0 = P0[None]
        if P0.ndim != 2 or P0.shape[1] != m:
            raise DimensionError(f"points must have shape (k, {m}); got {np.shape(points)}")
        if not np.isfinite(P0).all():
            raise ValueError("points must be finite")
        with np.errstate(all="ignore"):
            S.certify(P0, S.cells)
    fr = BoxFrontier.from_boxes(ub0[None])
    out = branch_and_bound(fr, S, eps, max_boxes=max_boxes, time_limit=time_limit,
                           keep_outer=False, progress=progress, desc="minimax",
                           executor=executor)
    cand = out.boundary.boxes
    with np.errstate(all="ignore"):
        # final bounds with the finer cells
        if S.u is not None:
            S.certify(S.u[None], S.cells_final)
        if cand.shape[0]:
            lb, infeasible = S.lower_bounds(cand, S.cells_final)
            mid = np.clip(0.5 * cand[..., 0] + 0.5 * cand[..., 1], cand[..., 0], cand[..., 1])
            order = np.argsort(lb)[:64]
            S.certify(mid[order], S.cells_final)
            keep = ~infeasible & ~(lb > S.upper)
            cand, lb = cand[keep], lb[keep]
    upper = S.upper
    if cand.shape[0]:
        lower = float(lb.min())
    else:
        lower = upper  # nothing may hold a feasible point below upper (or nothing feasible)
    lower = min(lower, upper)
    status = out.status
    if upper == np.inf and cand.shape[0] == 0:
        status = Status.DISPROVED
        lower = upper = np.inf
        msg = ("proven infeasible: for every u in U some w in W gives g(u, w) > 0"
               if gext is not None else "no finite bound could be certified")
    elif upper == np.inf:
        if status == Status.PROVED:
            status = Status.UNDECIDED
        msg = (f"no feasible u certified; certified: max_w f(u, w) >= {lower:.10g} for every "
               "feasible u")
    elif lower == -np.inf:
        if status == Status.PROVED:
            status = Status.NUMERICAL
        msg = "f is unbounded below on a candidate box (or undefined there): lower = -inf"
    else:
        over = " over the u with g(u, w) <= 0 for all w" if gext is not None else ""
        msg = (f"certified: {lower:.10g} <= min_u max_w f(u, w) <= {upper:.10g}{over}; the "
               f"returned u is proven feasible and max_w f(u, w) <= {upper:.10g} at it")
        if status == Status.BUDGET:
            msg = f"{out.message}; {msg}"
    w_best = None if S.u is None else S.worst_w(S.u)
    return MinimaxResult(
        status=status, message=msg, method=meth, lower=float(lower), upper=float(upper),
        u=S.u, u_feasible=S.u is not None, w=w_best, candidates=cand, nit=out.levels,
        n_boxes=out.n_classified, elapsed=time.perf_counter() - t0)
