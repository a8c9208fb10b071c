"""Interval global minimisation with a certified bracket on the minimum (thesis Alg 4.2).

The search is a classifier plugged into the batched branch-and-bound engine
(:func:`~casadi_cmpc.solvers.engine.branch_and_bound`): each level, the whole frontier is
enclosed at once, the certified upper bound of the minimum is improved from points of the
frontier, and boxes that provably cannot hold a global minimiser are discarded (OUTER).
Nothing is ever INNER: the undecided boxes narrower than ``eps`` are the candidates.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .._interrupt import solver_call
from ..exceptions import DimensionError
from ..interval.compiler import InclusionFunction
from ._common import (
    inclusion_of,
    one_output_function,
    positive_eps,
    single_box,
    split_inclusion,
    thin,
)
from .engine import OUTER, UNDECIDED, BoxFrontier, Status, branch_and_bound
from .result import _BracketResult, _format_point

__all__ = ["minimize", "MinimizeResult"]

_KINDS = ("centered", "natural")
_LOCAL_SOLVERS = ("ipopt", None)

# Local solver schedule: one solve at level 0, then one every _LOCAL_EVERY levels, at most
# _LOCAL_MAX solves in total. Starting points closer than this fraction of the diameter of
# X0 to an earlier start are skipped.
_LOCAL_EVERY = 3
_LOCAL_MAX = 6
_LOCAL_SAME_START = 1e-3
# IPOPT solves with the constraints tightened to g(x) <= -margin, margin relative to the
# scale of g at the start, so that its solution is strictly feasible and can be certified.
_LOCAL_MARGIN = 1e-8
# When IPOPT's point cannot be certified, points x + 2^-k (x_best - x), k = 1.._SEGMENT_STEPS
# towards the best certified point are tried.
_SEGMENT_STEPS = 40
# Vertices of the boxes with the best midpoint values are tried as well (thesis Fig 4.2),
# for the _VERTEX_BOXES best boxes of each level when 2**n <= _VERTEX_MAX.
_VERTEX_BOXES = 4
_VERTEX_MAX = 64


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class MinimizeResult(_BracketResult):
    """Result of :func:`minimize`: a certified bracket ``lower <= min f <= upper``.

    A frozen :class:`~casadi_cmpc.solvers.result.Result` (keyword-only fields): ``success``,
    ``message``, ``nit`` (branch-and-bound levels), ``n_boxes`` (boxes classified) and
    ``elapsed`` (s) are described there. ``fun`` and ``width`` are read-only properties.

    Attributes
    ----------
    status : Status
        ``PROVED``: the search ran to completion and both bounds are finite.
        ``BUDGET``: ``max_boxes``, ``time_limit`` or an interruption stopped the search; the
        bracket is still certified (the leftover boxes are among the candidates).
        ``DISPROVED``: every box was proven to violate a constraint: the problem is
        infeasible (``lower = upper = inf``, ``x is None``).
        ``UNDECIDED``: the search completed but no feasible point could be certified
        (``upper = inf``), e.g. constraints whose feasible set has an empty interior.
        ``NUMERICAL``: the enclosure of ``f`` is unbounded below on a candidate box (``f``
        undefined or unbounded there), so ``lower = -inf``.
    method : str
        ``"<kind>"`` or ``"<kind>+ipopt"``: the inclusion form and the local solver used.
    lower : float
        Certified lower bound: every feasible ``x`` in ``X0`` has ``f(x) >= lower``.
    upper : float
        Certified upper bound: ``f(x) <= upper`` at the proven-feasible point ``x``, hence
        ``min f <= upper`` (``inf`` when no feasible point was certified).
    x : ndarray, shape (n,), or None
        The best point found. When ``x_feasible`` it is proven feasible and
        ``f(x) <= upper``; otherwise it is only a guess (no certified point was found).
    x_feasible : bool
        True when ``x`` is proven to lie in ``X0`` and to satisfy every constraint.
    fun : float
        Same as ``upper`` (scipy's name for the optimal value).
    width : float
        Width ``upper - lower`` of the bracket.
    candidates : ndarray, shape (N, n, 2)
        Boxes that may contain global minimisers: every global minimiser lies in their
        union. Boxes whose lower bound exceeds the final ``upper`` are removed.
    n_local : int
        Local (IPOPT) solves made (a solve whose tightened problem fails is repeated once
        with the original constraints; both count).
    """

    x: np.ndarray | None
    x_feasible: bool
    n_local: int

    def _repr_solution(self) -> list[str]:
        return [f"x={_format_point(self.x)}", f"x_feasible={self.x_feasible}"]


# --------------------------------------------------------------------------- validation
def _check_function(fun: Any, name: str, n: int | None) -> ca.Function:
    fun = one_output_function(fun, name, ("x",))
    if n is not None and fun.numel_in(0) != n:
        raise DimensionError(
            f"{name} takes an input of {fun.numel_in(0)} elements but X0 has dimension {n}")
    return fun


class _Search:
    """The state of one minimisation: inclusion functions and the certified upper bound."""

    def __init__(self, f: ca.Function, g: ca.Function | None, x0: np.ndarray, kind: str,
                 local_solver: str | None, F: InclusionFunction | None = None,
                 G: InclusionFunction | None = None) -> None:
        self.F = inclusion_of(f, kind, F)
        self.F_point = inclusion_of(f, "natural", F)
        self.G = None if g is None else inclusion_of(g, kind, G)
        self.G_point = None
        if g is not None:
            self.G_point = inclusion_of(g, "natural", G)
        self.n = x0.shape[0]
        self.lo0, self.hi0 = x0[:, 0].copy(), x0[:, 1].copy()
        self.diam0 = float(np.max(self.hi0 - self.lo0)) if self.n else 0.0
        self.upper = np.inf
        self.x: np.ndarray | None = None
        self.guess: tuple[float, np.ndarray] | None = None  # best unverified point
        self.local_solver = local_solver
        self._nlp: Any = None
        self.n_local = 0
        self._starts: list[np.ndarray] = []
        self._last = None  # (midpoints, midpoint values, flb) of the last level's kept boxes

    # ------------------------------------------------------------ point certification
    def _point_values(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Upper bounds of f at the points (inside X0), and whether each is proven
        feasible and finite, (m,) each."""
        pts_thin = thin(pts)
        m = pts.shape[0]
        fu = self.F_point.evaluate_unchecked([pts_thin], m)[0][:, 0, 1]
        ok = np.isfinite(fu)
        if self.G_point is not None:
            gu = self.G_point.evaluate_unchecked([pts_thin], m)[0][..., 1]
            ok &= (gu <= 0).all(axis=1)
        return fu, ok

    def _lower_upper(self, pts: np.ndarray, fcert: np.ndarray) -> None:
        """Keep the best certified value ``fcert`` (+inf: not certified) of the points."""
        if pts.shape[0] == 0 or not np.isfinite(fcert).any():
            return
        k = int(np.argmin(fcert))
        if fcert[k] < self.upper:
            self.upper = float(fcert[k])
            self.x = pts[k].copy()

    def certify_points(self, pts: np.ndarray) -> None:
        """Certify ``f <= value`` and feasibility at the points; keep the best bound."""
        if pts.shape[0] == 0:
            return
        pts = np.clip(pts, self.lo0, self.hi0)
        fu, ok = self._point_values(pts)
        self._lower_upper(pts, np.where(ok, fu, np.inf))

    def _note_guess(self, value: float, x: np.ndarray) -> None:
        if np.isfinite(value) and (self.guess is None or value < self.guess[0]):
            self.guess = (float(value), x.copy())

    # --------------------------------------------------------------------- classifier
    def map(self, fr: BoxFrontier) -> dict[str, np.ndarray]:
        """The per-box part of a classification (a pure function of the boxes, run on the
        workers of an executor): lower bounds of f, proven infeasibility, and the
        certified value of f at the midpoint (+inf where the midpoint is not proven
        feasible)."""
        n_box = len(fr)
        boxes = fr.boxes
        flb = self.F.evaluate_unchecked([boxes], n_box)[0][:, 0, 0]
        infeasible = np.zeros(n_box, dtype=bool)
        if self.G is not None:
            g = self.G.evaluate_unchecked([boxes], n_box)[0]
            infeasible = (g[..., 0] > 0).any(axis=1)
        mid = np.clip(0.5 * fr.lo + 0.5 * fr.hi, fr.lo, fr.hi)
        fmid = np.full(n_box, np.inf)
        fcert = np.full(n_box, np.inf)
        live = np.flatnonzero(~infeasible)
        if live.size:
            fm, ok = self._point_values(mid[live])
            fmid[live] = fm
            fcert[live] = np.where(ok, fm, np.inf)
        return {"flb": flb, "infeasible": infeasible, "fmid": fmid, "fcert": fcert}

    def combine(self, fr: BoxFrontier, parts: list[dict[str, np.ndarray]]) -> np.ndarray:
        """Labels of a level from the :meth:`map` parts of its boxes (in order): the best
        certified midpoint and the vertices of the best boxes lower the upper bound, then
        boxes whose lower bound exceeds it are discarded."""
        r = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if len(parts) > 1 \
            else parts[0]
        flb, infeasible, fmid, fcert = r["flb"], r["infeasible"], r["fmid"], r["fcert"]
        labels = np.full(len(fr), UNDECIDED, dtype=np.int8)
        live = ~infeasible
        if live.any():
            lo, hi = fr.lo[live], fr.hi[live]
            mid = np.clip(0.5 * lo + 0.5 * hi, lo, hi)
            fml = fmid[live]
            self._lower_upper(mid, fcert[live])
            order = np.argsort(np.where(np.isfinite(fml), fml, np.inf), kind="stable")
            best = order[:_VERTEX_BOXES]
            if 0 < self.n and 2 ** self.n <= _VERTEX_MAX and best.size:
                bits = np.array(np.meshgrid(*[[0.0, 1.0]] * self.n, indexing="ij"))
                bits = bits.reshape(self.n, -1).T  # (2^n, n)
                verts = np.where(bits[None] == 1.0, hi[best][:, None, :], lo[best][:, None, :])
                self.certify_points(verts.reshape(-1, self.n))
            keep = flb[live] <= self.upper
            self._last = (mid[keep], fml[keep], flb[live][keep])
        else:
            self._last = None
        labels[infeasible | (flb > self.upper)] = OUTER
        return labels

    def classify(self, fr: BoxFrontier) -> np.ndarray:
        """Labels of a level (:meth:`map` then :meth:`combine`)."""
        return self.combine(fr, [self.map(fr)])

    __call__ = classify

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_nlp"] = None  # the local solver stays in the driver
        return state

    # -------------------------------------------------------------------- local solver
    def on_level(self, level: int, fr: BoxFrontier, labels: np.ndarray) -> None:
        if (self.local_solver is None or self.n_local >= _LOCAL_MAX or self._last is None
                or level % _LOCAL_EVERY):
            return
        mid, fmid, flb = self._last
        if mid.shape[0] == 0:
            return
        starts = []
        if np.isfinite(fmid).any():
            starts.append(mid[int(np.argmin(np.where(np.isfinite(fmid), fmid, np.inf)))])
        starts.append(mid[int(np.argmin(flb))])
        for s in starts:
            if self.n_local >= _LOCAL_MAX:
                break
            tol = _LOCAL_SAME_START * max(self.diam0, 1e-300)
            if any(np.max(np.abs(s - t)) <= tol for t in self._starts):
                continue
            self._starts.append(s)
            self.local_solve(s)

    def _build_nlp(self) -> Any:
        x = ca.SX.sym("x", self.n)
        nlp = {"x": x, "f": self.F.fun(x)}
        if self.G is not None:
            nlp["g"] = ca.vec(self.G.fun(x))
        opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False,
                "ipopt.max_iter": 200, "ipopt.tol": 1e-10, "ipopt.constr_viol_tol": 1e-10,
                "error_on_fail": False,
                # IPOPT backs off from points where f is undefined (NaN) by itself; CasADi
                # would print one warning per such evaluation
                "show_eval_warnings": False}
        return ca.nlpsol("minimize_local", "ipopt", nlp, opts)

    def _run_nlp(self, args: dict[str, Any]) -> dict[str, Any] | None:
        self.n_local += 1
        try:
            with solver_call():
                return self._nlp(**args)
        except RuntimeError:  # an evaluation error: the local solver is only a heuristic
            return None

    def local_solve(self, start: np.ndarray) -> None:
        """One IPOPT solve from ``start``; its solution is certified like any other point."""
        if self._nlp is None:
            self._nlp = self._build_nlp()
        args: dict[str, Any] = {"x0": start, "lbx": self.lo0, "ubx": self.hi0}
        if self.G is not None:
            g0 = np.asarray(self.G.fun(start), dtype=float).reshape(-1)
            scale = np.maximum(1.0, np.abs(np.where(np.isfinite(g0), g0, 1.0)))
            args["lbg"] = -np.inf
            args["ubg"] = -_LOCAL_MARGIN * scale
        sol = self._run_nlp(args)
        if sol is not None and not self._nlp.stats().get("success", False) and "ubg" in args:
            # The tightened problem may be infeasible (e.g. equality-like constraints): solve
            # the original one for a best guess.
            args["ubg"] = 0.0
            sol = self._run_nlp(args)
        if sol is None:
            return
        x = np.asarray(sol["x"], dtype=float).reshape(-1)
        if not np.isfinite(x).all():
            return
        x = np.clip(x, self.lo0, self.hi0)
        if self._nlp.stats().get("success", False):
            self._note_guess(float(sol["f"]), x)
        before = self.upper
        self.certify_points(x[None])
        if self.upper == before and self.x is not None and self.G is not None:
            # Not certified (a constraint is active up to IPOPT's tolerance): try points on
            # the segment towards the best certified point, closest to x first.
            t = 2.0 ** -np.arange(_SEGMENT_STEPS, 0, -1)
            self.certify_points(x[None] + t[:, None] * (self.x - x)[None])


# ------------------------------------------------------------------------------ solver
def minimize(f: Any, X0: Any, eps: float, constraints: Any = None, *,
             kind: str | None = None, local_solver: str | None = "ipopt",
             max_boxes: int = 2_000_000, time_limit: float | None = None,
             progress: bool | None = None, executor: Any = None) -> MinimizeResult:
    """Certified global minimisation over a box, with inequality constraints (thesis Alg 4.2).

    Finds ``lower <= min {f(x) : x in X0, g(x) <= 0} <= upper`` by interval branch and
    bound, together with the boxes that may contain the global minimisers.

    Parameters
    ----------
    f : casadi.Function or InclusionFunction
        The objective ``R^n -> R``: one input of ``n`` elements and one scalar output (an SX
        Function; an MX Function is expanded). An already compiled
        :class:`~casadi_cmpc.interval.InclusionFunction` is evaluated as given when it is of
        the ``kind`` used (its Function serves for the local solver and the other forms).
    X0 : Box or array_like, shape (n, 2)
        The (bounded) search box.
    eps : float
        Undecided boxes whose widest component is at most ``eps`` are not bisected: they
        become candidates. Smaller ``eps`` narrows the bracket and the candidate boxes.
    constraints : casadi.Function or InclusionFunction, optional
        ``g : R^n -> R^p``; the feasible set is ``{x in X0 : g(x) <= 0}`` (componentwise).
    kind : {"centered", "natural"} or None
        Inclusion function used to bound ``f`` and ``g`` on boxes. The centered
        (mean-value) form, intersected with the natural one, shrinks quadratically with the
        box width and prunes far better near minimisers. None (default): the kind of ``f``
        when it is an InclusionFunction, else ``"centered"``.
    local_solver : {"ipopt", None}
        ``"ipopt"``: a few local solves (CasADi ``nlpsol``) started from the most promising
        midpoints supply candidate points; their value and feasibility are then certified by
        interval evaluation like any other point, so the bracket stays certified. ``None``:
        only midpoints and vertices of boxes are tried.
    max_boxes : int
        Stop after classifying this many boxes (``status = BUDGET``).
    time_limit : float, optional
        Stop after this many seconds (checked once per level; ``status = BUDGET``).
    progress : bool or None
        tqdm progress bar (None: only for searches longer than 2 s).

    executor : concurrent.futures.Executor, optional
        Evaluate the bounds of the large levels on this executor (``ProcessPoolExecutor``,
        or ``distributed.Client(address).get_executor()``); the incumbent bound is updated
        once per level in this process, so the result is that of the serial run.

    Returns
    -------
    MinimizeResult
        ``lower``, ``upper`` (certified bracket), ``x`` (best certified point), ``fun``
        (``= upper``), ``candidates`` (N, n, 2), ``success``, ``status``, ``message``,
        ``nit``, ``n_boxes``, ``n_local``, ``elapsed``, ``x_feasible``.

    Raises
    ------
    TypeError
        ``f`` or ``constraints`` is neither a casadi.Function nor an InclusionFunction.
    DimensionError
        ``f`` is not scalar or has several inputs/outputs; the input size of ``f`` or
        ``constraints`` differs from the dimension of ``X0``; ``X0`` is not a single box.
    UnboundedSetError
        ``X0`` has an infinite bound.
    ValueError
        ``eps <= 0``, unknown ``kind`` or ``local_solver``, ``max_boxes < 1``.

    Notes
    -----
    Each level of the breadth-first search (thesis §4.1.3, Alg 4.2; Jaulin et al., 2001):

    1. enclose ``f`` (and ``g``) on every box of the frontier with ``kind``;
    2. evaluate ``f`` and ``g`` at the thin midpoint of every box not proven infeasible, and
       at the vertices of the boxes with the best midpoint values: at a point ``p`` with
       ``sup G(p) <= 0`` (feasibility proven), ``sup F(p)`` is a certified upper bound
       ``f̄`` of the minimum;
    3. discard (OUTER) the boxes with ``inf F(X) > f̄`` (no minimiser inside) and those with
       ``inf G_i(X) > 0`` for some ``i`` (no feasible point inside).

    Every few levels a local solve (IPOPT, constraints tightened slightly so that its
    solution is strictly feasible) proposes another point, certified as in step 2. At the
    end the candidate boxes with ``inf F(X) > f̄`` are removed, and
    ``lower = min inf F(X)`` over the remaining candidates: every global minimiser lies in
    one of them, so ``min f >= lower``. With ``upper = f̄`` the bracket is certified,
    including floating-point rounding. The frontier need not reach ``eps`` for the bracket to
    be sound: a search stopped by a limit keeps its leftover boxes as candidates.

    Examples
    --------
    >>> import casadi as ca, numpy as np
    >>> from casadi_cmpc.solvers.minimize import minimize
    >>> x = ca.SX.sym("x", 2)
    >>> f = ca.Function("f", [x], [(x[0] - 0.5)**2 + (x[1] + 0.25)**2 + 1])
    >>> res = minimize(f, np.array([[-2, 2], [-2, 2]]), eps=1e-3)
    >>> bool(res.success and res.lower <= 1.0 <= res.upper and res.upper - res.lower < 1e-6)
    True
    >>> g = ca.Function("g", [x], [x[0] + x[1] - 1])     # x0 + x1 <= 1
    >>> res = minimize(ca.Function("l", [x], [-x[0] - x[1]]), np.array([[0, 1], [0, 1]]),
    ...                eps=1e-3, constraints=g)
    >>> bool(res.lower <= -1.0 <= res.upper < -1.0 + 1e-6 and res.x_feasible)
    True
    """
    t0 = time.perf_counter()
    f, F_given = split_inclusion(f, "f")
    f = _check_function(f, "f", None)
    if f.numel_out(0) != 1:
        raise DimensionError(
            f"f must be scalar (R^n -> R); '{f.name()}' has an output of shape "
            f"{f.size_out(0)}")
    n = f.numel_in(0)
    if n == 0:
        raise DimensionError(f"f must take at least one variable; '{f.name()}' takes none")
    x0 = single_box(X0, "X0", n)
    eps = positive_eps(eps)
    if kind is None:
        kind = F_given.kind if F_given is not None else "centered"
    kind_l = str(kind).lower()
    if kind_l not in _KINDS:
        raise ValueError(f"unknown kind '{kind}'; valid kinds: {', '.join(_KINDS)}")
    local = None if local_solver is None else str(local_solver).lower()
    if local not in _LOCAL_SOLVERS:
        raise ValueError(f"unknown local_solver '{local_solver}'; valid: 'ipopt', None")
    if int(max_boxes) < 1:
        raise ValueError(f"max_boxes must be at least 1; got {max_boxes}")
    g = None
    G_given = None
    if constraints is not None:
        constraints, G_given = split_inclusion(constraints, "constraints")
        g = _check_function(constraints, "constraints", n)
        if g.numel_out(0) == 0:
            g = None

    search = _Search(f, g, x0, kind_l, local, F_given, G_given)
    out = branch_and_bound(BoxFrontier.from_boxes(x0[None]), search, eps,
                           max_boxes=int(max_boxes), time_limit=time_limit, keep_outer=False,
                           progress=progress, desc="minimize", on_level=search.on_level,
                           executor=executor)
    cand = out.boundary
    boxes = cand.boxes
    upper = search.upper
    if len(cand):
        # The candidates were set aside with the bound of their level: prune them against
        # the final one (and drop unclassified leftovers proven infeasible).
        m = len(cand)
        flb = search.F.evaluate_unchecked([boxes], m)[0][:, 0, 0]
        keep = ~(flb > upper)
        if search.G is not None:
            gl = search.G.evaluate_unchecked([boxes], m)[0][..., 0]
            keep &= ~(gl > 0).any(axis=1)
        boxes, flb = boxes[keep], flb[keep]
    else:
        flb = np.zeros(0)
    lower = float(np.min(flb)) if flb.size else np.inf
    if flb.size == 0 and np.isfinite(upper):  # not reachable with sound enclosures
        lower = upper
    lower = min(lower, upper)

    x = search.x
    x_feasible = x is not None
    if x is None and boxes.shape[0]:
        # No certified point: report IPOPT's best solution, else the midpoint of the most
        # promising candidate, as an unproven guess.
        if search.guess is not None:
            x = search.guess[1]
        else:
            b = boxes[int(np.argmin(flb))]
            x = np.clip(0.5 * b[:, 0] + 0.5 * b[:, 1], b[:, 0], b[:, 1])
    method = kind_l + ("+ipopt" if local else "")
    bracket = f"[{lower:.10g}, {upper:.10g}]"
    ncand = boxes.shape[0]
    if out.status != Status.PROVED:
        status = Status.BUDGET
        message = (f"{out.message}: the search stopped early; the bracket {bracket} is "
                   f"certified ({ncand} candidate boxes, some wider than eps)")
        if not np.isfinite(upper):
            message += "; no feasible point could be certified (upper = inf)"
    elif ncand == 0 and not np.isfinite(upper):
        status = Status.DISPROVED
        lower = np.inf
        x = None
        message = ("the problem is infeasible: every box of X0 is proven to violate a "
                   "constraint")
    elif not np.isfinite(upper):
        status = Status.UNDECIDED
        message = (f"search completed, but no feasible point could be certified (upper = "
                   f"inf); the minimum, if the problem is feasible, is >= {lower:.10g} "
                   f"({ncand} candidate boxes)")
    elif not np.isfinite(lower):
        status = Status.NUMERICAL
        message = (f"the enclosure of f is unbounded below on some candidate box (f "
                   f"undefined or unbounded there): lower = -inf, upper = {upper:.10g}")
    else:
        status = Status.PROVED
        message = (f"global minimum certified in {bracket} (width {upper - lower:.3g}); "
                   f"{ncand} candidate boxes")
    return MinimizeResult(
        status=status, message=message, method=method, lower=float(lower),
        upper=float(upper), x=None if x is None else np.array(x),
        x_feasible=bool(x_feasible and x is not None), candidates=boxes, nit=out.levels,
        n_boxes=out.n_classified, n_local=search.n_local, elapsed=time.perf_counter() - t0)
