"""Quantified set inversion via modal intervals (thesis §5.1.5, Alg 5.1 and Alg 5.2).

Paves the set

    Σ = { x ∈ X0 : ∀ w ∈ W  ∃ u ∈ U :  f(x, u, w) ∈ Y }

with one pair classifier plugged into the batched branch-and-bound engine
(:func:`~casadi_cmpc.solvers.engine.branch_and_bound` over a
:class:`~casadi_cmpc.solvers.engine.PairFrontier` of (x-box, U-cell) pairs, the frontier of
the one-step sets too). The classifier uses the inner and outer approximations of the
semantic extension ``f*`` computed by :class:`~casadi_cmpc.interval.modal.SemanticExtension`,
with ``x`` and ``w`` proper (universally quantified) and ``u`` improper (existentially
quantified). For Alg 5.2 the U-cells of each x-box are bisected breadth-first, batched over
the whole frontier; each new x-box starts again from the whole U, and its shared exclusion
columns (points of W) make the frontier's group reduction sound for ``∀w ∃u``.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import casadi as ca
import numpy as np

from .._validate import as_boxes
from ..exceptions import (
    CmpcWarning,
    DimensionError,
    ModelError,
    UnboundedSetError,
    UnsupportedOperationError,
)
from ..interval.modal import SemanticExtension
from ..model import Model
from ..sets.box import Box
from ..sets.paving import Paving
from ._common import positive_eps, split_inclusion
from .engine import INNER, OUTER, PairFrontier, branch_and_bound
from .result import SetResult

__all__ = ["quantified_sivia"]

_METHODS = ("auto", "alg5.1", "alg5.2")
_DEFAULT_OPTIONS: dict[str, Any] = {
    "u_depth": 8,
    "max_pairs": 200_000,
    "witnesses": True,
    "mean_value": True,
}


def _check_options(options: dict[str, Any] | None, method: str) -> dict[str, Any]:
    opts = dict(_DEFAULT_OPTIONS)
    if options is None:
        options = {}
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict; got {type(options).__name__}")
    unknown = sorted(set(options) - set(_DEFAULT_OPTIONS))
    if unknown:
        warnings.warn(f"quantified_sivia ignores the unknown options {unknown}; valid options: "
                      f"{', '.join(_DEFAULT_OPTIONS)}", CmpcWarning, stacklevel=3)
    for k in _DEFAULT_OPTIONS:
        if k in options:
            opts[k] = options[k]
    if method == "alg5.1":
        if "u_depth" in options and int(options["u_depth"]) != 0:
            warnings.warn("method 'alg5.1' does not bisect U; option u_depth is ignored",
                          CmpcWarning, stacklevel=3)
        opts["u_depth"] = 0
        opts["witnesses"] = False
    u_depth = int(opts["u_depth"])
    if u_depth < 0:
        raise ValueError(f"option u_depth must be >= 0; got {opts['u_depth']}")
    opts["u_depth"] = u_depth
    opts["max_pairs"] = int(opts["max_pairs"])
    if opts["max_pairs"] < 1:
        raise ValueError(f"option max_pairs must be >= 1; got {options.get('max_pairs')}")
    opts["witnesses"] = bool(opts["witnesses"])
    opts["mean_value"] = bool(opts["mean_value"])
    return opts


def _bounded_box(data: Any, d: int, name: str) -> np.ndarray:
    b = as_boxes(data, d, name)
    if b.shape[0] != 1:
        raise DimensionError(f"{name} must be a single box; got {b.shape[0]} boxes")
    if not np.isfinite(b).all():
        raise UnboundedSetError(f"{name} must be bounded; got {b[0].tolist()}")
    return b[0]


class _QuantifiedClassifier:
    """Pair classifier of ``∀w ∈ W ∃u ∈ U : f(x, u, w) ∈ Y`` on a
    :class:`~casadi_cmpc.solvers.engine.PairFrontier` (x-box, U-cell).

    Columns of the joint boxes: x (0..n-1), u (n..n+m-1), w (n+m..d-1). Per-pair data:
    ``"wc"`` (N, C, l), the points of W shared by the cells of a state box (NaN until the
    box is first classified, with the whole U as its cell); ``"excl"`` (N, C'), the cell is
    proven excluded at column c (C' = max(C, 1); with no w, column 0 is the exclusion
    itself; without witnesses it only records a whole-U exclusion); ``"useless"`` (N,),
    the cell is excluded at some w of its own and cannot prove the box.
    """

    def __init__(self, ext: SemanticExtension, n: int, m: int, l: int, U: np.ndarray,
                 W: np.ndarray, Y: Box, opts: dict[str, Any]) -> None:
        self.ext = ext
        self.n, self.m, self.l = n, m, l
        self.d = n + m + l
        self.p = ext.p
        self.U = U
        self.W = W
        self.ylo = Y.lo
        self.yhi = Y.hi
        # a point W (a nominal problem): "exists w" and "for all w" coincide
        self.point_w = l > 0 and bool((W[:, 0] == W[:, 1]).all())
        self.witnesses = opts["witnesses"] and l > 0 and not self.point_w
        self.C = 2 * self.p if self.witnesses else 0
        self.us = slice(n, n + m)
        self.ws = slice(n + m, self.d)
        self.imp_u = np.zeros(self.d, dtype=bool)
        self.imp_u[self.us] = True
        self.imp_xu = np.zeros(self.d, dtype=bool)
        self.imp_xu[: n + m] = True
        self.imp_none = np.zeros(self.d, dtype=bool)

    def fresh_data(self, N: int) -> dict[str, np.ndarray]:
        """Per-pair data of N state boxes whose cell is the whole U."""
        return {"wc": np.full((N, self.C, self.l), np.nan),
                "excl": np.zeros((N, max(self.C, 1)), dtype=bool),
                "useless": np.zeros(N, dtype=bool)}

    # ------------------------------------------------------------------ helpers
    def _inside(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Outer approximation ``[lo, hi]`` (modal) included in Y, per output: (P, p).

        An infinite or NaN bound of the outer approximation may stand for "f possibly
        undefined" (also where Y is unbounded on that side), so it proves nothing."""
        return (lo >= self.ylo) & (hi <= self.yhi) & np.isfinite(lo) & np.isfinite(hi)

    def _excluded(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Inner approximation ``[lo, hi]`` not included in Y for some output: (P,)."""
        return ((lo < self.ylo) | (hi > self.yhi)).any(axis=-1)

    def _witness_points(self, J0: np.ndarray) -> np.ndarray:
        """Candidate points of W per x-box from its Jacobian over X x U x W: (N, C, l).

        For each output j, the corner of W minimising f_j and the one maximising it (by the
        sign of the interval derivative over X x U x W; the midpoint where it is unknown).
        """
        Jw = J0[:, :, self.ws, :]
        inc = Jw[..., 0] >= 0
        dec = (Jw[..., 1] <= 0) & ~inc
        wlo, whi = self.W[:, 0], self.W[:, 1]
        wm = np.clip(0.5 * wlo + 0.5 * whi, wlo, whi)
        low = np.where(inc, wlo, np.where(dec, whi, wm))
        high = np.where(inc, whi, np.where(dec, wlo, wm))
        return np.concatenate([low, high], axis=1)

    # --------------------------------------------------------------------- classify
    def __call__(self, fr: PairFrontier) -> np.ndarray:
        with np.errstate(all="ignore"):
            return self._classify(fr)

    def _classify(self, fr: PairFrontier) -> np.ndarray:
        ext, n = self.ext, self.n
        P = len(fr)
        labels = np.zeros(P, dtype=np.int8)
        if P == 0:
            return labels
        data = fr.data
        Z = np.concatenate([fr.boxes, np.broadcast_to(self.W, (P, self.l, 2))], axis=1)
        J = ext.jacobian_unchecked(Z)
        whole = ((fr.lo[:, n:] == self.U[:, 0]) & (fr.hi[:, n:] == self.U[:, 1])).all(axis=1)
        if self.C:
            new = np.isnan(data["wc"][:, 0, 0])  # a state box classified for the first time
            if new.any():  # its cell is the whole U: J is over X x U x W
                data["wc"][new] = self._witness_points(J[new])
        # --- exclusion (inner approximations, x and u improper) -------------------------
        # own: w proper (thesis Alg 5.2 step 12; Alg 5.1 step 5 for the whole U);
        # columns: w fixed to a point shared by all cells of the state box
        Zs = [Z]
        for c in range(self.C):
            Zc = Z.copy()
            wc = data["wc"][:, c]
            Zc[:, self.ws, 0] = wc
            Zc[:, self.ws, 1] = wc
            Zs.append(Zc)
        r = ext.bounds_unchecked(np.concatenate(Zs), self.imp_xu,
                                 np.concatenate([J] * len(Zs)), outer=False, inner=True)
        ex = self._excluded(r["inner_lo"], r["inner_hi"]).reshape(len(Zs), P)
        own = ex[0]
        excl = data["excl"]
        if self.C:
            excl |= ex[1:].T
        elif self.l == 0 or self.point_w:
            excl[:, 0] |= own  # no w, or a single w: the exclusion holds for every w
        # the cell is all of U: ∃w ∀x ∀u f ∉ Y, so no x of the box is in the set
        excl[whole & own] = True
        useless = data["useless"]
        useless |= own | excl.any(axis=1)
        # --- inclusion (outer approximations, u improper) -------------------------------
        sel = np.flatnonzero(~useless)
        if sel.size:
            ok = self._included(Z[sel], J[sel])
            labels[sel[ok]] = INNER
        # a cell excluded at every column is dropped; the others stay to be refined
        labels[excl.all(axis=1) & (labels != INNER)] = OUTER
        return labels

    def _included(self, Z: np.ndarray, J: np.ndarray) -> np.ndarray:
        """Cells proving ``∀x ∀w ∃u ∈ cell : f ∈ Y`` (thesis Alg 5.1 step 7, Alg 5.2 steps
        16 and 20): output j* with u improper, the other outputs with u proper."""
        ext, p = self.ext, self.p
        P = Z.shape[0]
        if p == 1:
            r = ext.bounds_unchecked(Z, self.imp_u, J, outer=True, inner=False)
            return self._inside(r["outer_lo"], r["outer_hi"])[:, 0]
        imp = np.concatenate([np.broadcast_to(self.imp_u, (P, self.d)),
                              np.broadcast_to(self.imp_none, (P, self.d))])
        r = ext.bounds_unchecked(np.concatenate([Z, Z]), imp, np.concatenate([J, J]),
                                 outer=True, inner=False)
        ins = self._inside(r["outer_lo"], r["outer_hi"])
        in_a, in_b = ins[:P], ins[P:]
        others = in_b.sum(axis=1)[:, None] - in_b  # outputs other than j* inside (∀u)
        return (in_a & (others == p - 1)).any(axis=1)


def _model_function(model: Model, X0: Any, U: Any, W: Any
                    ) -> tuple[ca.Function, Any, Any, Any]:
    """(Function ``(x, u[, w])`` of the successor, X0, U, W) of a Model, boxes defaulted."""
    if model.m == 0:
        raise ModelError(
            f"model '{model.name}' has no input: there is no u to quantify; invert its "
            "successor with cm.sivia(model, Y=..., eps=...) (for every w in W)")
    if model.is_validated:
        raise ModelError(_ENCLOSURE_REFUSED.format(
            f"model '{model.name}' is {model.discretisation}: its successor"))
    if model.l == 0:
        if W is not None:
            raise ModelError(f"model '{model.name}' has no disturbance w; do not pass W")
    else:
        W = model.W if W is None else W
    # the model's interval source (never model.f, which of some models is only a rounded
    # or approximate map)
    fun = model.interval_map("xu" if model.l == 0 else "xuw")
    if not isinstance(fun, ca.Function):
        raise ModelError(f"model '{model.name}' has no plain CasADi graph for the semantic "
                         f"extension (its interval source is {fun!r})")
    return fun, model.X if X0 is None else X0, model.U if U is None else U, W


_ENCLOSURE_REFUSED = (
    "{} is enclosed by a Taylor polynomial plus interval-valued remainder parameters, not "
    "given by one graph. The semantic extension proves 'for every w there is a u' about "
    "one continuous function; for an enclosure it would prove it for every member of the "
    "family separately, with a u that may depend on the remainder, which is not a proof "
    "about the flow. Use an interval method instead (cm.one_step_set(..., "
    "method='boxes') or the zonotope methods)")


def quantified_sivia(f: Any, X0: Any = None, U: Any = None, W: Any = None, Y: Any = None,
                     eps: float | None = None, *, method: str = "auto",
                     options: dict[str, Any] | None = None, split_ratio: float = 0.5,
                     relative: bool = False, max_boxes: int = 2_000_000,
                     time_limit: float | None = None, keep_outer: bool = True,
                     progress: bool | None = None, executor: Any = None) -> SetResult:
    """Quantified set inversion: pave ``{x ∈ X0 : ∀w ∈ W ∃u ∈ U : f(x, u, w) ∈ Y}``.

    Thesis §5.1.5, Alg 5.1 (one output) and Alg 5.2 (several outputs, nested bisection of U).

    Parameters
    ----------
    f : casadi.Function, InclusionFunction or Model
        Continuous SX Function with inputs ``(x, u, w)`` (or ``(x, u)`` when ``W`` is None) and
        one output of ``p = Y.dim`` elements. Of an InclusionFunction its Function is used
        (the semantic extension needs the graph; its natural form is shared through the
        cache of :func:`casadi_cmpc.interval.inclusion`). A :class:`~casadi_cmpc.Model` with
        inputs stands for its successor ``f(x, u, w)`` (``p = n``; Y is then a box of
        successor states): ``X0``, ``U`` and ``W`` default to ``model.X``, ``model.U`` and
        ``model.W``, so ``quantified_sivia(model, Y=T, eps=0.05)`` paves the states from
        which, for every disturbance, some admissible input reaches ``T`` in one step
        (a model without input is refused: use :func:`~casadi_cmpc.sivia`).
    X0 : Box or array_like, shape (n, 2)
        The initial (bounded) box of states. Required for a Function.
    U : Box or array_like, shape (m, 2)
        Admissible inputs (existentially quantified, bounded). Required for a Function.
    W : Box or array_like, shape (l, 2), or None
        Disturbances (universally quantified, bounded); None when ``f`` has no ``w`` (for a
        Model: ``model.W``, refused when the model has no ``w``).
    Y : Box
        The target, of dimension ``p``; its bounds may be infinite. Required (by keyword
        when the boxes before it are left to their defaults).
    eps : float
        Undecided x-boxes whose widest component is at most ``eps`` (relative to the widths
        of ``X0`` when ``relative=True``) are not bisected further.
    method : {"auto", "alg5.1", "alg5.2"}
        ``"alg5.1"``: thesis Alg 5.1, scalar ``f`` only, no bisection of ``U``.
        ``"alg5.2"``: Alg 5.2 with the nested bisection of ``U``, any ``p``. ``"auto"``:
        ``"alg5.2"`` (for a scalar ``f`` it contains Alg 5.1 as its first step).
    options : dict, optional
        ``u_depth`` (int, default 8): bisection rounds of U per x-box (Alg 5.2): cells are
        bisected down to ``2**-ceil(u_depth / m)`` of U per component, at most
        ``2**u_depth`` cells per x-box;
        ``max_pairs`` (int, default 200000): a lower cap on the number of U-cells per x-box
        (beyond it the cells are not bisected further: sound, less sharp);
        ``witnesses`` (bool, default True): exclude x-boxes through points of W shared by
        all U-cells (see Notes); ``mean_value`` (bool, default True): combine the
        monotonicity bounds with the modal mean-value extension. Unknown keys warn.
    split_ratio : float
        Position of the cut when an x-box is bisected.
    relative : bool
        Measure widths relative to ``X0``.
    max_boxes, time_limit : optional
        Limits (``max_boxes`` counts classified (x-box, U-cell) pairs); a stopped search
        reports its leftovers as boundary boxes (still sound).
    keep_outer : bool
        Keep the excluded boxes (``result.outside``) for drawing.
    progress : bool or None
        tqdm progress bar (None: only for searches longer than 2 s).

    executor : concurrent.futures.Executor, optional
        Classify the large levels on this executor (``ProcessPoolExecutor``, or
        ``distributed.Client(address).get_executor()``); the result is that of the serial
        run.

    Returns
    -------
    SetResult
        ``paving`` (a :class:`~casadi_cmpc.Paving`; the result acts as it): ``inner``: boxes
        in which the quantified statement is proven for **every** x; ``outside``: boxes in
        which it is proven **false** for every x (for every x there is a w for which no u in
        U works); ``boundary``: undecided boxes. ``method`` is ``"alg5.1"`` or
        ``"alg5.2"``, ``n_pairs`` the (x-box, U-cell) pairs examined; ``status`` is
        ``PROVED`` when the search ran to completion, ``BUDGET`` when a limit stopped it.

    Raises
    ------
    DimensionError
        Sizes of ``f``'s inputs or output disagree with ``X0``, ``U``, ``W``, ``Y``.
    UnsupportedOperationError
        ``f`` contains operations through which it may jump (the semantics needs continuity).

    Notes
    -----
    Write ``f*(X, W, U*)`` for the semantic extension with x, w proper and u improper
    (``U* = Dual U``). By the semantic theorem (5.13), ``f_j*(X, W, U*) ⊆ [a_j, b_j]`` iff
    ``∀x ∀w ∃u ∈ U: f_j(x, u, w) ∈ [a_j, b_j]`` (for continuous ``f``).

    **Inclusion (INNER).** A box is inner when, for some U-cell ``Uc`` (the whole U for Alg
    5.1; the cells of the nested bisection for Alg 5.2) and some output ``k``,
    ``Outer(f_k*(X, W, Uc*)) ⊆ Y_k`` (u existential) and, for every other output ``j``,
    ``Outer(f_j*(X, W, Uc)) ⊆ Y_j`` with ``Uc`` proper (``∀u ∈ Uc``): the u found for ``k``
    then satisfies the others too (thesis Alg 5.2 steps 16 and 20). Proven:
    ``∀x ∈ box ∀w ∈ W ∃u ∈ Uc ⊆ U : f(x, u, w) ∈ Y``.

    **Exclusion (OUTER).** With x made existential too,
    ``Inner(f_j*(Dual X, W, Uc*)) ⊄ Y_j`` proves ``∃w ∀x ∈ box ∀u ∈ Uc : f_j ∉ Y_j``
    (Alg 5.1 step 5, Alg 5.2 steps 5 and 12). For ``Uc = U`` this excludes the box. For a
    smaller cell it only shows that the cell cannot provide the ``∃u`` (the w may differ
    from cell to cell), and the cell is dropped from the inclusion search. In addition,
    with ``witnesses`` on, a few points ``w_c`` of W are fixed per x-box (for each output,
    the corners of W that minimise and maximise it by the sign of the interval derivative).
    A box is excluded when, for one ``w_c``, **every** cell of a partition of U has some
    output proven outside Y for all x of the box and u of the cell (inner approximations
    with ``w = w_c``). This proves ``∀x ∈ box ∀u ∈ U ∃j : f_j(x, u, w_c) ∉ Y_j``, which
    catches infeasibility that comes from the coupling of the outputs through a common u;
    Alg 5.2 alone never excludes those boxes.

    The semantics is ``∀w ∃u``: u may depend on w. A control input that must be chosen
    before w is known (``∃u ∀w``) is a stronger requirement that this solver does not
    certify.

    Examples
    --------
    >>> import casadi as ca, numpy as np, casadi_cmpc as cm
    >>> from casadi_cmpc.solvers.quantified import quantified_sivia
    >>> x, u, w = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("w")
    >>> f = ca.Function("f", [x, u, w], [x + u + w])
    >>> P = quantified_sivia(f, cm.Box([-4], [4]), cm.Box([-1], [1]), cm.Box([-0.5], [0.5]),
    ...                      cm.Box([-1], [1]), eps=0.01)
    >>> bool(P.inner[:, 0, 0].min() >= -1.5 and P.inner[:, 0, 1].max() <= 1.5)  # Σ = [-1.5, 1.5]
    True

    A Model (X0, U, W default to its boxes):

    >>> model = cm.Model(x=x, u=u, w=w, f=x + u + w, X=cm.Box([-4], [4]), U=cm.Box([-1], [1]),
    ...                  W=cm.Box([-0.5], [0.5]))
    >>> Q = quantified_sivia(model, Y=cm.Box([-1], [1]), eps=0.01)
    >>> bool((Q.inner == P.inner).all())
    True
    """
    meth = str(method).lower()
    if meth not in _METHODS:
        raise ValueError(f"Unknown method '{method}'; valid methods: {', '.join(_METHODS)}")
    if Y is None:  # (a missing eps is refused below: "eps must be a positive number")
        raise TypeError("quantified_sivia needs the target Y, e.g. "
                        "quantified_sivia(f, X0, U, W, Y, eps) or "
                        "quantified_sivia(model, Y=Y, eps=0.05)")
    if isinstance(f, Model):
        f, X0, U, W = _model_function(f, X0, U, W)
    elif X0 is None or U is None:
        raise TypeError("quantified_sivia needs the boxes X0 and U for a Function f (they "
                        "default to the model's boxes only for a Model)")
    f = split_inclusion(f, "f")[0]
    from ..interval._derivative import ParamFunction

    if isinstance(f, ParamFunction):
        if f.interval.any():
            raise UnsupportedOperationError(_ENCLOSURE_REFUSED.format(
                f"'{f.function.name()}' has interval-valued parameters: it"))
        raise TypeError(f"f must be a casadi.Function; got the ParamFunction "
                        f"'{f.function.name()}' (pass the Model itself)")
    if not isinstance(f, ca.Function):
        raise TypeError(f"f must be a casadi.Function or an InclusionFunction; got "
                        f"{type(f).__name__}")
    n_in = 2 if W is None else 3
    if f.n_in() != n_in:
        raise DimensionError(
            f"f must take {'(x, u)' if W is None else '(x, u, w)'} ({n_in} inputs) "
            f"{'since W is None' if W is None else ''}; '{f.name()}' has {f.n_in()} inputs")
    if f.n_out() != 1:
        raise DimensionError(f"f must have one output; '{f.name()}' has {f.n_out()} "
                             "(stack them with casadi.vertcat)")
    if not isinstance(Y, Box):
        raise TypeError(f"Y must be a Box; got {type(Y).__name__}")
    n = f.numel_in(0)
    m = f.numel_in(1)
    l = 0 if W is None else f.numel_in(2)
    x0 = _bounded_box(X0, n, "X0")
    ub = _bounded_box(U, m, "U")
    wb = np.zeros((0, 2)) if W is None else _bounded_box(W, l, "W")
    p = f.numel_out(0)
    if Y.dim != p:
        raise DimensionError(f"target Y has dimension {Y.dim}; f has {p} outputs")
    if meth == "auto":
        meth = "alg5.2"
    if meth == "alg5.1" and p != 1:
        raise ValueError(f"method 'alg5.1' is the 1-dimensional algorithm; f has {p} "
                         "outputs (use 'alg5.2')")
    opts = _check_options(options, meth)
    eps = positive_eps(eps)
    ext = SemanticExtension(f, mean_value=opts["mean_value"])
    classify = _QuantifiedClassifier(ext, n, m, l, ub, wb, Y, opts)
    domain = Box(x0[:, 0], x0[:, 1])
    scale = None
    if relative:
        scale = np.where(domain.diam > 0, domain.diam, 1.0)
    u_depth = opts["u_depth"] if m > 0 else 0
    # u_depth bisection rounds of U: cells down to 2^-ceil(u_depth / m) of U per component,
    # at most 2^u_depth (and max_pairs) cells per state box
    u_eps = 2.0 ** -math.ceil(u_depth / max(m, 1))
    fr = PairFrontier.from_boxes(x0[None], ub, x_scale=scale, u_eps=u_eps,
                                 max_cells=max(1, min(2 ** min(u_depth, 62), opts["max_pairs"])),
                                 data=classify.fresh_data(1), restart=classify.fresh_data(1),
                                 shared="excl", split_ratio=split_ratio)
    out = branch_and_bound(fr, classify, eps, max_boxes=max_boxes, time_limit=time_limit,
                           keep_outer=keep_outer, progress=progress, desc="quantified sivia",
                           executor=executor)
    bnd = out.boundary.x_boxes
    if bnd.shape[0]:  # leftovers of a stopped search hold several cells per state box
        bnd = np.unique(bnd, axis=0)
    paving = Paving._from_solver(out.inner.x_boxes, bnd, out.outer.x_boxes, domain,
                                 out.n_discarded)
    return SetResult(status=out.status, message=out.message, method=meth, nit=out.levels,
                     n_boxes=out.n_classified, elapsed=out.elapsed, paving=paving,
                     n_pairs=out.n_classified, history=out.history)
