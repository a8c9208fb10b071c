r"""Quasi multi-step robust controllable sets (thesis §6.3, Def 6.1, Alg 6.7).

For a model with an affine control part ``x+ = g(x, w) + B u`` (thesis (6.18), ``B``
constant) and a target polytope ``T = {x : A x <= b}``, the quasi i-step robust
controllable set is the set of states of X for which **one** control sequence
``u(0), ..., u(i-1)`` in U keeps the state in X and brings it into T within i steps for
every disturbance sequence in W (Def 6.1). :func:`quasi_controllable_set` computes an
inner approximation by Alg 6.7: the state space is bisected; for each box the controls are
chosen step by step by the LP (6.20)-(6.21) on the bounding box of the zonotope enclosure
of ``g(X(k), W)``, and the box is accepted only when the sound evolution of the whole box
under that sequence is proven inside X at every intermediate step and inside T at the
end. :func:`quasi_controllable_sets` repeats it on polytopic inner approximations (§6.3.4,
``P_0 = T``, ``P_m`` one polytope inside the m-th quasi set computed towards ``P_{m-1}``)
and :func:`quasi_step_comparison` computes the data of Fig 6.13 (two recursive quasi
one-step sets against one quasi two-step set).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validate import as_boxes
from ..exceptions import CmpcWarning, DimensionError, ModelError
from ..model import Model
from ..sets import _lp
from ..sets._reach import (
    box_of,
    box_zonotopes,
    hybrid_step,
    jacobian_bounds,
    support_bounds,
    zonotope_step,
)
from ..sets.box import Box
from ..sets.paving import Paving
from ..sets.polytope import Polytope
from ..solvers._common import positive_eps
from ..solvers.engine import INNER, OUTER, BoxFrontier, Status, branch_and_bound
from ..solvers.result import SetResult

__all__ = ["QuasiSet", "QuasiSequence", "quasi_controllable_set", "quasi_controllable_sets",
           "quasi_step_comparison", "quasi_invariance"]


# ----------------------------------------------------------------------------- checks
def _check_model(model: Any) -> np.ndarray:
    """The constant input matrix B (n, m); clear errors for other models."""
    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    if model.m == 0:
        raise ModelError(f"model '{model.name}' has no input: quasi controllable sets need "
                         "a control")
    if not model.has_affine_control_part:
        raise ModelError(
            f"model '{model.name}' has no affine control part: Alg 6.7 chooses the controls "
            "by the LP (6.20)-(6.21), which needs x+ = g(x, w) + B u with a constant B "
            "(thesis (6.18)); use cm.controllable_sets for general models")
    if not (np.isfinite(model.U.lo).all() and np.isfinite(model.U.hi).all()):
        raise ValueError(f"U must be bounded; got {model.U}")
    return model.input_matrix


def _check_steps(steps: Any) -> int:
    if isinstance(steps, (bool, np.bool_)) or not isinstance(steps, (int, np.integer)):
        raise TypeError(f"steps must be an integer >= 1; got {steps!r}")
    if steps < 1:
        raise ValueError(f"steps must be >= 1; got {steps}")
    return int(steps)


def _check_target(target: Any, n: int) -> Polytope:
    if isinstance(target, Box):
        target = Polytope.from_box(target)
    if not isinstance(target, Polytope):
        raise TypeError(f"target must be a Polytope (or Box); got {type(target).__name__} "
                        "(the LP (6.21) needs the rows of one polytope)")
    if target.dim != n:
        raise DimensionError(f"target has dimension {target.dim}; the model has n = {n}")
    if target.A.shape[0] == 0 or not target.is_bounded() or target.is_empty():
        raise ValueError("target must be a non-empty bounded polytope")
    return target


def _w_box(model: Model, W: Any) -> tuple[np.ndarray, str]:
    """(W as (1, l, 2), words for the claim)."""
    if model.l == 0:
        if W is not None:
            raise ModelError(f"model '{model.name}' has no disturbance; do not pass W")
        return np.zeros((1, 0, 2)), "no disturbance"
    Wb = as_boxes(model.W_box if W is None else W, model.l, "W")
    if Wb.shape[0] != 1 or not np.isfinite(Wb).all():
        raise ValueError("W must be one bounded box")
    return Wb, (f"robust: for all disturbance sequences in W = [{Wb[0, :, 0].tolist()}, "
                f"{Wb[0, :, 1].tolist()}]")


# ----------------------------------------------------------------------------- LP (6.20)
def _lp_rows(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of (6.19) ``T x <= 1`` (A / b) when every b > 0, else rows of unit norm."""
    if np.all(b > 0):
        return A / b[:, None], np.ones_like(b)
    s = np.linalg.norm(A, axis=1)
    s = np.where(s > 0, s, 1.0)
    return A / s[:, None], b / s


def lp_controls(An: np.ndarray, bn: np.ndarray, TB: np.ndarray, Y: np.ndarray,
                U: Box) -> np.ndarray:
    """The controls of the LP (6.20)-(6.21) for a batch of boxes.

    ``min_{u in U, xi} xi`` s.t. ``max_{y in Y} T_r y + (T B u)_r - 1 <= xi`` for every row
    ``r`` (``T = An``, right-hand side ``bn``): the control that brings the box ``Y`` of
    ``g(X(k), W)`` deepest into the target polytope (a heuristic choice; nothing is
    claimed about it, the evolution under it is checked afterwards).

    Parameters
    ----------
    An : ndarray (r, n)
    bn : ndarray (r,)
    TB : ndarray (r, m)
        ``An B``.
    Y : ndarray (N, n, 2)
        Boxes bounding ``g(X(k), W)`` (finite).
    U : Box

    Returns
    -------
    ndarray (N, m)
        Controls in U.
    """
    N = Y.shape[0]
    m = TB.shape[1]
    mid = 0.5 * (Y[..., 0] + Y[..., 1])
    rad = 0.5 * (Y[..., 1] - Y[..., 0])
    c = mid @ An.T + rad @ np.abs(An).T - bn  # (N, r)
    lo, hi = np.asarray(U.lo, dtype=float), np.asarray(U.hi, dtype=float)
    if N == 0:
        return np.zeros((0, m))
    if m == 1:
        # convex piecewise-linear max_r (c_r + s_r u) on [lo, hi]: its minimum is at an end
        # or at the crossing of two lines
        s = TB[:, 0]
        r = s.size
        cand = [np.full((N, 1), lo[0]), np.full((N, 1), hi[0])]
        if r > 1:
            i, j = np.triu_indices(r, 1)
            ds = s[i] - s[j]
            ok = ds != 0
            i, j, ds = i[ok], j[ok], ds[ok]
            if i.size:
                cand.append(np.clip((c[:, j] - c[:, i]) / ds, lo[0], hi[0]))
        cand.append(np.clip(np.zeros((N, 1)), lo[0], hi[0]))
        Uc = np.concatenate(cand, axis=1)  # (N, K)
        val = (c[:, :, None] + s[None, :, None] * Uc[:, None, :]).max(axis=1)  # (N, K)
        best = val.min(axis=1, keepdims=True)
        # among the minimisers (up to rounding), the smallest |u|
        tie = val <= best + 1e-12 * np.maximum(1.0, np.abs(best))
        score = np.where(tie, np.abs(Uc), np.inf)
        k = np.argmin(score, axis=1)
        return Uc[np.arange(N), k][:, None]
    # general m: one LP per box in the variables (u, xi)
    r = An.shape[0]
    rows_A = np.tile(np.hstack([TB, -np.ones((r, 1))]), (N, 1))
    rows_b = (-c).reshape(-1)
    block = np.repeat(np.arange(N), r)
    C = np.zeros((N, m + 1))
    C[:, m] = 1.0
    lb = np.concatenate([lo, [-np.inf]])
    ub = np.concatenate([hi, [np.inf]])
    res = _lp.block_lp(C, rows_A, rows_b, block, lb, ub)
    u = res.x[:, :m]
    u = np.where(np.isfinite(u), u, 0.5 * (lo + hi))
    return np.clip(u, lo, hi)


# ----------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class QuasiSet(SetResult):
    """Inner approximation of a quasi i-step robust controllable set, with its controls.

    A :class:`~casadi_cmpc.SetResult` (it acts as its paving: ``res.inner``,
    ``res.boundary``, ``res.outside``, ...).

    Attributes
    ----------
    paving : Paving
        ``inner``: state boxes proven in the set (each with its control sequence);
        ``boundary``: undecided boxes narrower than eps (or unexplored after a budget
        stop); ``outside``: boxes proven to reach the target at no step ``1..steps`` for
        any control sequence in U and any disturbance sequence in W.
    controls : ndarray (N_inner, steps, m)
        The control sequence of every inner box; entries after ``arrival`` are NaN.
    arrival : ndarray of int (N_inner,)
        The step ``k <= steps`` at which the whole box is proven inside the target.
    steps : int
        i of the quasi i-step set.
    target : Polytope
        The target T.
    semantics : str
        The claim of an inner box, in words (model, W, robust, quasi i-step).
    W : ndarray (l, 2)
        The disturbance box of the claim.
    model_name : str
    """

    controls: np.ndarray = field(default_factory=lambda: np.zeros((0, 1, 1)))
    arrival: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    steps: int = 1
    target: Any = None
    semantics: str = ""
    W: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    model_name: str = ""

    def _repr_parts(self) -> list[str]:
        p = self.paving
        return [f"steps={self.steps}", f"inner={p.n_inner}", f"boundary={p.n_boundary}",
                f"outside={p.n_outside}"]

    def area(self, view: str = "inner") -> float:
        """Area (volume) of the inner boxes (``view="outer"``: inner and boundary)."""
        return self.paving.volume(view=view)

    def contains(self, points: Any) -> np.ndarray | bool:
        """Whether points lie in an inner box (floating-point test on the box bounds)."""
        return self.paving.contains(points, view="inner")

    def box_index(self, x: Any) -> int | None:
        """Index of the first inner box containing the point ``x`` (n,), or None."""
        x = np.asarray(x, dtype=float).reshape(-1)
        inner = self.paving.inner
        hit = np.flatnonzero(((inner[..., 0] <= x) & (x <= inner[..., 1])).all(axis=1))
        return None if hit.size == 0 else int(hit[0])

    def control_sequence(self, x: Any) -> np.ndarray | None:
        """The stored control sequence ``(arrival, m)`` of the first inner box containing
        ``x``, or None when ``x`` lies in no inner box."""
        k = self.box_index(x)
        if k is None:
            return None
        return self.controls[k, :int(self.arrival[k])].copy()


# ----------------------------------------------------------------------------- search
def _take(C: np.ndarray, G: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return C[idx], G[idx]


def _finite(C: np.ndarray, G: np.ndarray) -> np.ndarray:
    return np.isfinite(C).all(axis=1) & np.isfinite(G).all(axis=(1, 2))


def _step(model: Model, C: np.ndarray, G: np.ndarray, U: np.ndarray, W: np.ndarray,
          J: np.ndarray | None, refine: bool, max_order: float | None, inclusion: str
          ) -> tuple[np.ndarray, np.ndarray]:
    """One sound step for the finite zonotopes of the batch (the others stay NaN)."""
    ok = _finite(C, G)
    if not ok.all():
        Cn = np.full(C.shape, np.nan)
        if not ok.any():
            return Cn, np.full((C.shape[0], C.shape[1], 1), np.nan)
        Uo = U[ok] if U.shape[0] == C.shape[0] else U
        c2, g2 = _step(model, C[ok], G[ok], Uo, W, None if J is None else J[ok], refine,
                       max_order, inclusion)
        Gn = np.full((C.shape[0], C.shape[1], g2.shape[2]), np.nan)
        Cn[ok] = c2
        Gn[ok] = g2
        return Cn, Gn
    fn = hybrid_step if refine else zonotope_step
    return fn(model, C, G, U, W, J=J, inclusion=inclusion, max_order=max_order)


def _inside_rows(C: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Proven ``Z ⊆ {A x <= b}`` per zonotope (False for non-finite ones)."""
    up = support_bounds(C, G, A)[1]
    with np.errstate(invalid="ignore"):
        return np.all(up <= b, axis=1) & np.isfinite(up).all(axis=1)


def _disjoint_rows(C: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Proven ``Z ∩ {A x <= b} = ∅`` per zonotope (one row separates; False if non-finite)."""
    lo = support_bounds(C, G, A)[0]
    with np.errstate(invalid="ignore"):
        return np.any(lo > b, axis=1)


def _in_box(C: np.ndarray, G: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Proven inclusion of each zonotope in the box D (n, 2)."""
    bx = box_of(C, G)
    with np.errstate(invalid="ignore"):
        return np.all((bx[..., 0] >= D[:, 0]) & (bx[..., 1] <= D[:, 1]), axis=1)


class _Quasi:
    """The pieces of Alg 6.7 for one model, target, W and number of steps."""

    def __init__(self, model: Model, target: Polytope, steps: int, Wb: np.ndarray,
                 D: np.ndarray, refine: bool, max_order: float | None, inclusion: str) -> None:
        self.model, self.steps, self.W, self.D = model, steps, Wb, D
        self.A = np.asarray(target.A, dtype=float)
        self.b = np.asarray(target.b, dtype=float)
        B = model.input_matrix
        self.An, self.bn = _lp_rows(self.A, self.b)
        self.TB = self.An @ B
        self.Ubox = model.U.as_array()[None]
        self.U0 = np.zeros((1, model.m, 2))
        self.refine, self.max_order, self.inclusion = refine, max_order, inclusion

    def step(self, C: np.ndarray, G: np.ndarray, U: np.ndarray, J: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
        return _step(self.model, C, G, U, self.W, J, self.refine, self.max_order,
                     self.inclusion)

    def reachable(self, boxes: np.ndarray) -> np.ndarray:
        """Step 5: False where the target is proven missed at every step 1..i for all
        controls in U (then the box is outside the quasi set)."""
        C, G = box_zonotopes(boxes)
        possible = np.zeros(boxes.shape[0], dtype=bool)
        for _ in range(self.steps):
            C, G = self.step(C, G, self.Ubox)
            possible |= ~_disjoint_rows(C, G, self.A, self.b)
        return possible

    def jac(self, C: np.ndarray, G: np.ndarray) -> np.ndarray | None:
        ok = _finite(C, G)
        if not ok.all():
            return None
        return jacobian_bounds(self.model, C, G, self.Ubox, self.W)

    def controls_and_check(self, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                               np.ndarray]:
        """Steps 6-16 for a batch: the control sequences (N, i, m) (NaN after arrival), the
        arrival step (N,) (0: not proven) and whether the box is proven (N,)."""
        N, m, i = boxes.shape[0], self.model.m, self.steps
        ctrl = np.full((N, i, m), np.nan)
        arrival = np.zeros(N, dtype=int)
        alive = np.arange(N)
        C, G = box_zonotopes(boxes)
        for k in range(i):
            if alive.size == 0:
                break
            if k > 0:  # Step 7: X(k) inside X
                keep = _in_box(C, G, self.D)
                alive, C, G = alive[keep], C[keep], G[keep]
                if alive.size == 0:
                    break
            J = self.jac(C, G)
            Cg, Gg = self.step(C, G, self.U0, J)  # g(X(k), W)
            Y = box_of(Cg, Gg)
            fin = np.isfinite(Y).all(axis=(1, 2))
            u = np.full((alive.size, m), np.nan)
            if fin.any():
                u[fin] = lp_controls(self.An, self.bn, self.TB, Y[fin], self.model.U)
            keep = fin
            alive, C, G, u = alive[keep], C[keep], G[keep], u[keep]
            J = None if J is None else J[keep]
            if alive.size == 0:
                break
            ctrl[alive, k] = u
            Ut = np.stack([u, u], axis=-1)
            C, G = self.step(C, G, Ut, J)  # Step 9: X(k+1) under the chosen u(k)
            done = _inside_rows(C, G, self.A, self.b)  # Step 10
            arrival[alive[done]] = k + 1
            alive, C, G = alive[~done], C[~done], G[~done]
        ok = arrival > 0
        ctrl[~ok] = np.nan
        return ctrl, arrival, ok


class _QuasiClassifier:
    """Alg 6.7 as a classifier of the branch and bound: a box is OUTER when the target is
    proven missed at every step for all controls (Step 5), INNER when the control sequence
    of the LPs is proven to bring the whole box into the target (Steps 6-16; the sequence
    and the arrival step are stored in the frontier's data ``controls`` (N, i, m) and
    ``arrival`` (N,)), else undecided. Each box is labelled from itself alone (the LP of a
    box does not depend on the others of its batch with one input: a closed form; with
    several inputs a tie between optimal LP vertices may be broken differently in another
    batch, which a proof then checks like any other choice)."""

    def __init__(self, Q: _Quasi) -> None:
        self.Q = Q

    def __call__(self, fr: BoxFrontier) -> np.ndarray:
        boxes = fr.boxes
        labels = np.zeros(len(fr), dtype=np.int8)
        possible = self.Q.reachable(boxes)
        labels[~possible] = OUTER
        cand = np.flatnonzero(possible)
        if cand.size:
            ctrl, arrival, ok = self.Q.controls_and_check(boxes[cand])
            won = cand[ok]
            labels[won] = INNER
            fr.data["controls"][won] = ctrl[ok]
            fr.data["arrival"][won] = arrival[ok]
        return labels


def quasi_controllable_set(model: Model, target: Any, steps: int, eps: float, *,
                           X: Any = None, W: Any = None, refine: bool = True,
                           max_order: float | None = None, inclusion: str = "natural",
                           max_boxes: int = 1_000_000, time_limit: float | None = None,
                           progress: bool | None = None, executor: Any = None) -> QuasiSet:
    r"""Inner approximation of the quasi i-step robust controllable set (Alg 6.7).

    Parameters
    ----------
    model : Model
        ``x+ = g(x, w) + B u`` with a constant B (:attr:`Model.has_affine_control_part`);
        any number of states, inputs and disturbances. U must be bounded.
    target : Polytope or Box
        The target T (the thesis' terminal set Omega, (6.19)).
    steps : int
        i >= 1.
    eps : float
        State boxes whose widest side is at most eps are not bisected (units of x).
    X : Box, optional
        State constraint box (default: the model's X); the set is searched inside it.
    W : Box, optional
        Disturbance box of the claim (default: the model's W).
    refine : bool
        Intersect every zonotope step with an interval step (see
        :func:`casadi_cmpc.sets._reach.reach`); False: the plain zonotope evolution.
    max_order : float, optional
        Girard reduction of the zonotopes to at most ``floor(max_order n)`` generators.
    inclusion : {"natural", "centered"}
        Inclusion of f at the zonotope centres.
    max_boxes, time_limit : int, float
        Budget (boxes classified; seconds). A stopped search is sound: the unexplored
        boxes are boundary and the status is BUDGET.
    progress : bool or None
        tqdm bar over the boxes classified.
    executor : concurrent.futures.Executor, optional
        Run the search below its first levels on worker processes (a
        ``ProcessPoolExecutor``, or ``distributed.Client(...).get_executor()``); the same
        boxes, controls and arrival steps as the serial search (see
        :func:`casadi_cmpc.solvers.engine.branch_and_bound`). With several inputs (a
        :class:`~casadi_cmpc.CmpcWarning` says so) the LP may pick another of a box's
        equally good controls in another batch, so the sets may then differ from the
        serial run's (each is proven).

    Returns
    -------
    QuasiSet
        ``paving``, ``controls`` (N_inner, steps, m), ``arrival``, ``semantics``, status
        (PROVED: the search ran to completion and proved some box; UNDECIDED: it ran to
        completion without proving a box; DISPROVED: every box is proven outside; BUDGET:
        a limit stopped it).

    Notes
    -----
    **Claim of an inner box** (Def 6.1, robust). For every ``x(0)`` in the box and every
    disturbance sequence in W, the stored sequence ``u(0..a-1)`` (``a`` = its arrival,
    ``a <= steps``) gives ``x(k) in X`` for ``k < a`` and ``x(a) in T``. It is proven by
    the evolution of the whole box: zonotopes (mean-value form with Kühn's inclusion,
    Thm 4.4) refined by interval steps, outward rounding throughout; ``X(k)`` inside the
    box X by its rounded bounding box, ``X(a)`` inside T by rounded-up support values
    ``h_Z(A_r) <= b_r`` on the stored rows of T. An overflow or NaN fails the test.

    **Controls.** At step k the control minimises the LP (6.20)-(6.21) over the bounding
    box of the zonotope enclosure of ``g(X(k), W)`` (rows ``T = A / b`` of (6.19) when
    ``b > 0``); for ``m = 1`` it is solved exactly by enumerating the breakpoints, else
    by HiGHS. The evolution stops as soon as the whole box is proven in T (early exit,
    Step 10).

    **Outside boxes** (Step 5): the evolution with the whole of U at every step is proven
    disjoint from T (one row of T separates) at every step ``1..steps``; then no control
    sequence in U brings any state of the box into T within ``steps`` steps, whatever
    the disturbances.

    Examples
    --------
    >>> import casadi_cmpc as cm
    >>> from casadi_cmpc.control.quasi import quasi_controllable_set
    >>> ex = cm.models.load("khalil_affine_control")
    >>> K2 = quasi_controllable_set(ex.model, ex.terminal, steps=2, eps=0.1)
    >>> K2.controls.shape[1:], bool(K2.n_inner > 0)
    ((2, 1), True)
    """
    t0 = time.perf_counter()
    _check_model(model)
    i = _check_steps(steps)
    T = _check_target(target, model.n)
    eps = positive_eps(eps)
    Wb, wtext = _w_box(model, W)
    D = model.X if X is None else X
    if not isinstance(D, Box):
        D = Box.from_array(as_boxes(D, model.n, "X")[0])
    if D.dim != model.n or not D.is_bounded():
        raise ValueError(f"X must be a bounded box of dimension {model.n}")
    if str(inclusion).lower() not in ("natural", "centered"):
        raise ValueError(f"inclusion must be 'natural' or 'centered'; got {inclusion!r}")
    if max_order is not None and not float(max_order) >= 1.0:
        raise ValueError(f"max_order must be >= 1; got {max_order}")
    Dar = D.as_array()
    Q = _Quasi(model, T, i, Wb, Dar, bool(refine), max_order, str(inclusion).lower())
    m = model.m
    if executor is not None and m > 1:
        warnings.warn(
            "with several inputs, the LP (6.20)-(6.21) of a box may return another of its "
            "equally good controls when the box is solved in another batch (on a worker), "
            "so the sets may differ from the serial run's in such boxes; every box is "
            "proven either way", CmpcWarning, stacklevel=2)
    fr = BoxFrontier.from_boxes(Dar[None])
    fr.data = {"controls": np.full((1, i, m), np.nan), "arrival": np.zeros(1, dtype=np.int64)}
    fr.keep = ("controls", "arrival")
    out = branch_and_bound(fr, _QuasiClassifier(Q), eps, max_boxes=max_boxes,
                           time_limit=None if time_limit is None
                           else max(0.0, time_limit - (time.perf_counter() - t0)),
                           progress=progress, desc=f"quasi {i}-step set", executor=executor)
    status, why = out.status, out.message
    pav = Paving(inner=out.inner.boxes, boundary=out.boundary.boxes, outside=out.outer.boxes,
                 domain=D)
    data = out.inner.data if len(out.inner) else None
    controls = np.zeros((0, i, m)) if data is None else data["controls"]
    arrival = np.zeros(0, dtype=int) if data is None else data["arrival"]
    history = [{"boxes": h["classified"], "inner": h["inner"], "outer": h["outer"],
                "boundary": h["boundary"]} for h in out.history]
    semantics = (f"quasi {i}-step robust controllable set (Def 6.1, Alg 6.7) of model "
                 f"'{model.name}': from every state of an inner box its stored control "
                 f"sequence keeps x(k) in X = {D} before arrival and puts x(arrival) in the "
                 f"target (arrival <= {i}), {wtext}")
    msg = (f"{pav.n_inner} boxes proven ({semantics}); {pav.n_boundary} undecided, "
           f"{pav.n_outside} proven outside; {why}")
    if status == Status.PROVED and pav.n_inner == 0:
        # nothing proven in the set: empty (every box proven outside) or not known
        status = Status.UNDECIDED if pav.n_boundary else Status.DISPROVED
    return QuasiSet(status=status, message=msg, method="quasi i-step (Alg 6.7, zonotope "
                    "evolution + LP (6.20)-(6.21))", nit=out.levels, n_boxes=out.n_classified,
                    elapsed=time.perf_counter() - t0, paving=pav, history=history,
                    controls=controls, arrival=arrival.astype(int), steps=i, target=T,
                    semantics=semantics, W=Wb[0].copy(), model_name=model.name)


# ----------------------------------------------------------------------------- recursion
@dataclass
class QuasiSequence:
    """Polytopic quasi i-step robust controllable sets ``P_0 = T, P_1, ..., P_M`` (§6.3.4).

    Attributes
    ----------
    polytopes : list of Polytope
        ``polytopes[0]`` is the target T; ``polytopes[m]`` (m >= 1) is proven inside the
        inner boxes of ``results[m - 1]``, the quasi i-step set computed towards
        ``polytopes[m - 1]``. So every x in ``P_m`` has a stored control sequence that
        brings it into ``P_{m-1}`` within ``steps`` steps, staying in X, for all
        disturbance sequences in W.
    results : list of QuasiSet
    steps : int
    converged_at : int or None
        The first m whose polytope is no larger than ``P_{m-1}`` (volume grew by less
        than ``rtol``; the thesis' ``P_M = P_{M+1}``), else None.
    areas : list of float
        Volumes of ``P_0 .. P_M``.
    info : dict
        Model, W, eps, semantics, seconds per set.
    """

    polytopes: list = field(default_factory=list)
    results: list = field(default_factory=list)
    steps: int = 1
    converged_at: int | None = None
    areas: list = field(default_factory=list)
    info: dict = field(default_factory=dict)

    @property
    def sets(self) -> list:
        """Same as ``polytopes``."""
        return self.polytopes

    @property
    def status(self) -> str:
        """Why the recursion stopped: ``"converged"``, ``"until"``, ``"max_sets"`` or ``"no
        polytope"`` (no box proven, or no polytope proven inside the boxes)."""
        return str(self.info.get("status", "max_sets"))

    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), cmap: str = "viridis",
             colorbar: bool = True, *, model: Model | None = None, legend: bool = True,
             boxes: bool = False, **kw: Any) -> Any:
        """Draw ``P_M`` (back) to ``P_0 = T`` (front), coloured by index (cf. Fig 6.14).

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Created when omitted.
        dims : (int, int)
            States on the horizontal and vertical axes (projections for n > 2).
        cmap : str
            Sequential colour map of the index m (``P_0 = T`` at its low end).
        colorbar : bool
            Add a colour bar as the key of the index (m = set ``P_m``).
        model : Model, optional
            Draw X dashed and label the axes with the state names and units.
        legend : bool
            Legend below the axes: X, T and the meaning of unfilled space.
        boxes : bool
            Also draw the inner boxes of the last quasi set (light grey, under the sets).
        **kw
            Passed to :meth:`Polytope.plot` for every set.

        Returns
        -------
        matplotlib Axes
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
        k = max(len(self.polytopes), 2)
        cmap_ = plt.get_cmap(cmap)
        norm = mpl.colors.Normalize(vmin=0, vmax=k - 1)
        alpha = kw.pop("alpha", 0.8)
        if boxes and self.results and self.results[-1].n_inner:
            plot_boxes(np.asarray(self.results[-1].inner), ax=ax, dims=dims,
                       facecolor="0.85", edgecolor="none",
                       label=f"inner boxes of the last quasi {self.steps}-step set")
        for m in range(len(self.polytopes) - 1, 0, -1):
            self.polytopes[m].plot(ax=ax, dims=dims, facecolor=cmap_(norm(m)), alpha=alpha,
                                   edgecolor="k", linewidth=0.5, **kw)
        self.polytopes[0].plot(ax=ax, dims=dims, facecolor=cmap_(norm(0)), alpha=1.0,
                               edgecolor="magenta", linewidth=1.8,
                               label="T = P_0 (terminal set)")
        if model is not None:
            draw_state_box(ax, model, i_d, j_d, label="X (state box)")
            ax.autoscale_view()
            names, units = variable_labels(model, "x")
        else:
            names = [f"x{q + 1}" for q in range(self.polytopes[0].dim)]
            units = [None] * len(names)
        if colorbar:
            sm = mpl.cm.ScalarMappable(norm=norm, cmap=cmap_)
            ax.figure.colorbar(sm, ax=ax, label=f"index m (set P_m: into P_(m-1) within "
                                                f"{self.steps} steps)")
        ax.set_xlabel(axis_label(names[i_d], units[i_d]))
        ax.set_ylabel(axis_label(names[j_d], units[j_d]))
        if legend:
            legend_outside(ax, where="below", ncol=2, extra=[Patch(
                facecolor="white", edgecolor="0.4", linewidth=0.8,
                label="white (unfilled): not proven controllable")])
        return ax

    def __len__(self) -> int:
        return len(self.polytopes)

    def level(self, x: Any, boxes: bool = True) -> int | None:
        """The smallest m with x in ``P_m``, or (``boxes=True``, m >= 1) in an inner box of
        ``results[m - 1]`` (floating-point tests), or None.

        Either way x has a stored control sequence into ``P_{m-1}``: the inner boxes of the
        m-th quasi set hold it, and ``P_m`` lies inside them; with ``boxes=True`` the
        corners that the convex ``P_m`` leaves out count too.
        """
        x = np.asarray(x, dtype=float).reshape(-1)
        for m, P in enumerate(self.polytopes):
            if bool(P.contains(x)):
                return m
            if boxes and m >= 1 and bool(self.results[m - 1].contains(x)):
                return m
        return None


def _polytope_of(res: QuasiSet, method: str) -> Polytope | None:
    from .controllable import _as_polytope
    from .polytopic import inner_polytope

    if res.paving.n_inner == 0:
        return None
    try:
        got = inner_polytope(np.asarray(res.paving.inner), method=method)
    except Exception:  # noqa: BLE001 - no polytope is a sound answer (the set stays as is)
        return None
    P = _as_polytope(got)
    cert = got[1] if isinstance(got, tuple) else None
    if P is None or P.is_empty() or (cert is not None and cert.proved is not True):
        return None
    return P


def quasi_controllable_sets(model: Model, target: Any, steps: int, eps: float, *,
                            max_sets: int = 30, polytopic_method: str = "separating",
                            rtol: float = 1e-3, W: Any = None, X: Any = None,
                            until: Any = None, progress: bool | None = None,
                            **kw: Any) -> QuasiSequence:
    """Recursion of polytopic quasi i-step robust controllable sets (§6.3.4, Fig 6.14).

    ``P_0 = T``; ``K_m`` = :func:`quasi_controllable_set` towards ``P_{m-1}``; ``P_m`` = one
    polytope proven inside the inner boxes of ``K_m`` (:func:`casadi_cmpc.inner_polytope`,
    Alg 6.2 ``"separating"`` or Alg 6.5 ``"scaling"``). Stops when ``vol(P_m) <= (1 +
    rtol) vol(P_{m-1})`` (converged: the thesis' stopping rule ``P_M = P_{M+1}``; at a
    resolution eps this is where the polytopes stopped growing, not a proof that the
    maximal quasi set is reached), when no box is proven, or after ``max_sets`` sets.

    Parameters
    ----------
    model, target, steps, eps, W, X
        As in :func:`quasi_controllable_set`; ``target`` must be a Polytope.
    max_sets : int
        Largest M.
    polytopic_method : {"separating", "scaling"}
    rtol : float
        Relative volume growth below which the sequence counts as converged.
    until : array_like (k, n), optional
        Stop as soon as every one of these states has a level (:meth:`QuasiSequence.level`).
    progress : bool or None
    **kw
        Passed to :func:`quasi_controllable_set` (refine, max_order, inclusion, budgets).

    Returns
    -------
    QuasiSequence
    """
    t0 = time.perf_counter()
    _check_model(model)
    i = _check_steps(steps)
    T = _check_target(target, model.n)
    if polytopic_method not in ("separating", "scaling"):
        raise ValueError("polytopic_method must be 'separating' (Alg 6.2) or 'scaling' "
                         "(Alg 6.5)")
    if int(max_sets) < 1:
        raise ValueError(f"max_sets must be >= 1; got {max_sets}")
    Wb, wtext = _w_box(model, W)
    pts = None if until is None else np.atleast_2d(np.asarray(until, dtype=float))
    if pts is not None and pts.shape[1] != model.n:
        raise DimensionError(f"until must hold states of dimension {model.n}")
    seq = QuasiSequence(polytopes=[T], steps=i, areas=[float(T.volume())],
                        info={"model": model.name, "eps": float(eps), "steps": i,
                              "W": Wb[0].copy(), "claim": wtext, "seconds": [],
                              "status": "max_sets",
                              "semantics": "x in P_m: a stored control sequence brings x "
                                           f"into P_(m-1) within {i} steps, staying in X, "
                                           f"{wtext}"})
    for _ in range(int(max_sets)):
        ts = time.perf_counter()
        res = quasi_controllable_set(model, seq.polytopes[-1], i, eps, W=W, X=X,
                                     progress=progress, **kw)
        P = _polytope_of(res, polytopic_method)
        seq.info["seconds"].append(time.perf_counter() - ts)
        if P is None:
            seq.info["status"] = "no polytope"
            break
        seq.results.append(res)
        seq.polytopes.append(P)
        seq.areas.append(float(P.volume()))
        if seq.areas[-1] <= (1.0 + rtol) * seq.areas[-2]:
            seq.converged_at = len(seq.polytopes) - 1
            seq.info["status"] = "converged"
            break
        if pts is not None and all(seq.level(p) is not None for p in pts):
            seq.info["status"] = "until"
            break
    seq.info["total_seconds"] = time.perf_counter() - t0
    return seq


def quasi_step_comparison(model: Model, target: Any, eps: float, steps: int = 2, *,
                          polytopic_method: str = "separating", **kw: Any) -> dict[str, Any]:
    """Fig 6.13: ``steps`` recursive quasi one-step sets against one quasi ``steps``-step set.

    Both start from ``target`` at the same eps. The recursion computes the quasi one-step
    set towards the target, its inner polytope ``P_1``, the quasi one-step set towards
    ``P_1``, ... (``steps`` times); the direct way computes the quasi ``steps``-step set
    towards the target and its inner polytope.

    Returns
    -------
    dict
        ``"one_step"``: list of (QuasiSet, Polytope or None) per recursion step;
        ``"multi_step"``: (QuasiSet, Polytope or None); ``"seconds_one_step"``,
        ``"seconds_multi_step"``; ``"area_one_step"`` / ``"area_multi_step"``: areas of the
        last box unions (inner) and ``"poly_area_one_step"`` / ``"poly_area_multi_step"``
        of the polytopes (NaN without one).
    """
    _check_model(model)
    T = _check_target(target, model.n)
    i = _check_steps(steps)
    t0 = time.perf_counter()
    one: list[tuple[QuasiSet, Polytope | None]] = []
    tgt = T
    for _ in range(i):
        r = quasi_controllable_set(model, tgt, 1, eps, **kw)
        P = _polytope_of(r, polytopic_method)
        one.append((r, P))
        if P is None:
            break
        tgt = P
    t1 = time.perf_counter()
    r2 = quasi_controllable_set(model, T, i, eps, **kw)
    P2 = _polytope_of(r2, polytopic_method)
    t2 = time.perf_counter()

    def vol(P: Polytope | None) -> float:
        return float(P.volume()) if P is not None else float("nan")

    return {"one_step": one, "multi_step": (r2, P2), "seconds_one_step": t1 - t0,
            "seconds_multi_step": t2 - t1, "area_one_step": one[-1][0].area(),
            "area_multi_step": r2.area(), "poly_area_one_step": vol(one[-1][1]),
            "poly_area_multi_step": vol(P2), "complete_one_step": len(one) == i}


def quasi_invariance(model: Model, target: Any, eps: float, *, W: Any = None,
                     **kw: Any) -> Any:
    """Prove a polytope robustly control invariant by its quasi one-step set (§6.3.5).

    The thesis shows its terminal set Omega robust control invariant by
    ``Omega ⊆ K_1^q(X, Omega)``. Here the quasi one-step set towards ``target`` is computed
    over the bounding box of the target (within X) and the inclusion of the target in the
    union of its inner boxes is proven (:meth:`Polytope.is_subset` with a
    :class:`~casadi_cmpc.PolytopeUnion`: an exact covering proof).

    Parameters
    ----------
    model : Model
        With an affine control part.
    target : Polytope
    eps : float
        Resolution of the quasi one-step set.
    W : Box, optional
        Disturbance box of the claim (default: the model's W).
    **kw
        Passed to :func:`quasi_controllable_set`.

    Returns
    -------
    Certificate
        ``label="proved"`` (``proved=True``): for every x of the target one stored control
        (that of an inner box holding x, ``details["cover"]``) maps x into the target for
        every w in W, and keeps it in X; ``"undecided"`` (``proved=None``) otherwise (a
        smaller eps may succeed). ``about`` names the model, the set and W.
    """
    from ..sets.polytope import PolytopeUnion
    from ..solvers.result import Certificate

    t0 = time.perf_counter()
    _check_model(model)
    T = _check_target(target, model.n)
    Wb, wtext = _w_box(model, W)
    bb = T.bounding_box()
    lo = np.maximum(bb.lo, model.X.lo)
    hi = np.minimum(bb.hi, model.X.hi)
    claim = (f"the polytope is robustly control invariant for model '{model.name}' "
             f"({wtext}): every state of it has a control in U mapping it into it")
    about = {"kind": "quasi_invariance", "model": model.name, "set": T,
             "W": Wb[0].copy() if model.l else None}
    if np.any(lo > hi) or not T.is_subset(Polytope.from_box(Box(lo, hi)), tol=0.0):
        return Certificate("undecided", None, claim, "the polytope does not lie in X",
                           about=about)
    res = quasi_controllable_set(model, T, 1, eps, X=Box(lo, hi), W=W, **kw)
    details = {"cover": res, "eps": float(eps)}
    if res.n_inner == 0:
        details["seconds"] = time.perf_counter() - t0
        return Certificate("undecided", None, claim, "no box of the quasi one-step set "
                           "was proven", details, about=about)
    U = PolytopeUnion([Polytope.from_box(Box.from_array(b)) for b in np.asarray(res.inner)])
    ok = bool(T.is_subset(U))
    details["seconds"] = time.perf_counter() - t0
    if ok:
        return Certificate("proved", True, claim,
                           f"the polytope is covered (exact covering proof) by the "
                           f"{res.n_inner} inner boxes of its quasi one-step set, each with a "
                           "control proven by zonotope evolution", details, about=about)
    return Certificate("undecided", None, claim, "the inner boxes of the quasi one-step set "
                       "do not cover the polytope (as far as proven); try a smaller eps",
                       details, about=about)
