"""One-step MPC along a sequence of controllable sets (thesis Alg 4.7, 5.4, 6.3; (5.20)).

In ``K_i \\ K_{i-1}`` the controller solves the one-step problem (4.26)-(4.27)

    min_u max_{w in W}  f(x,u,w)' Q f(x,u,w) + u' R u   s.t.  f(x, u, w) in K_{i-1} for all w,

and applies the local law inside the terminal set ``K_0 = T``. The worst case over w is
taken at the vertices of W (exact for models affine in w) or, for models not affine in w, by
the interval minimax of Alg 5.3 (:func:`casadi_cmpc.minimax`). Every applied control is
certified by interval arithmetic: ``f(x, u, W) ⊆ K_{i-1}``; when the optimiser's control
cannot be certified, the proving control stored with the sequence is applied instead.
"""

from __future__ import annotations

import bisect
import itertools
import math
import time
import warnings
from typing import Any

import casadi as ca
import numpy as np

from .._interrupt import solver_call
from .._validate import float_vector, weight_matrix
from ..exceptions import CmpcWarning, DimensionError, ModelError, NotControllableError
from ..interval.compiler import InclusionFunction
from ..interval.modal import SemanticExtension
from ..model import Model
from ..sets.polytope import Polytope
from ..solvers.engine import Status
from ..solvers.minimax import MinimaxResult
from ..solvers.minimax import minimax as _minimax
from ..solvers.result import Certificate
from ._fastcall import BufferedCall
from ._stepcheck import NativeAfter
from .contractive import MPCResult, _solver_options
from .linear import OneStepLP
from .spec import SetSequenceSpec

__all__ = ["SetSequenceMPC"]

_MINIMAX_MODES = ("auto", "vertices", "interval")
#: The blends u_w + t (u* - u_w) of the stored and the solver's control tried (one per row).
_BLEND_STEPS = np.array([[0.75], [0.5], [0.25]])
_BLEND_STEPS.flags.writeable = False
_MINIMAX_KEYS = ("eps", "time_limit", "max_boxes", "w_depth", "w_depth_final", "mean_value")


def _members(S: Any) -> list[Any]:
    return list(getattr(S, "members", None) or getattr(S, "polytopes", None) or [S])


def _model_key(model: Model) -> str:
    from ..control.invariance import model_key

    return model_key(model)


def _first_max(c: Any) -> int:
    """Index of the first largest finite entry of c (0 when none is finite); the C export
    picks the same."""
    k, best = 0, -math.inf
    for i, v in enumerate(c):
        if math.isfinite(v) and v > best:
            k, best = i, v
    return k


def _minimax_options(opts: Any, U: Any, l: int) -> dict[str, Any]:
    """Checked options of the interval minimax with their defaults (see SetSequenceMPC)."""
    if opts is None:
        opts = {}
    if not isinstance(opts, dict):
        raise TypeError(f"minimax_options must be a dict; got {type(opts).__name__}")
    unknown = sorted(set(opts) - set(_MINIMAX_KEYS))
    if unknown:
        raise ValueError(f"unknown minimax_options {unknown}; valid keys: "
                         f"{', '.join(_MINIMAX_KEYS)}")
    width = float(np.max(np.asarray(U.hi, dtype=float) - np.asarray(U.lo, dtype=float)))
    out: dict[str, Any] = {"eps": width / 32 if width > 0 else 1e-3, "time_limit": 0.03,
                           "max_boxes": 2000, "w_depth": min(l, 2), "mean_value": True}

    def number(key: str, v: Any, allow_none: bool) -> float | None:
        if v is None and allow_none:
            return None
        if isinstance(v, (bool, np.bool_, str, bytes)) or not isinstance(
                v, (int, float, np.integer, np.floating)) or not math.isfinite(v) or v <= 0:
            raise ValueError(f"minimax_options['{key}'] must be a finite positive number"
                             f"{' or None' if allow_none else ''}; got {v!r}")
        return float(v)

    for key, v in opts.items():
        if key in ("eps", "time_limit"):
            out[key] = number(key, v, key == "time_limit")
        elif key in ("max_boxes", "w_depth", "w_depth_final"):
            low = 1 if key == "max_boxes" else 0
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) \
                    or v < low:
                raise ValueError(f"minimax_options['{key}'] must be an integer >= {low}; "
                                 f"got {v!r}")
            out[key] = int(v)
        else:  # mean_value
            if not isinstance(v, (bool, np.bool_)):
                raise ValueError(f"minimax_options['mean_value'] must be True or False; "
                                 f"got {v!r}")
            out[key] = bool(v)
    out.setdefault("w_depth_final", out["w_depth"] + 1)
    if out["w_depth_final"] < out["w_depth"]:
        raise ValueError(f"minimax_options['w_depth_final'] = {out['w_depth_final']} must be "
                         f">= w_depth = {out['w_depth']}")
    return out


class _PointLocator:
    """``seq.locate(x)`` for one point, on the sequence's grid of step boxes held as Python
    lists (the same cells, faces and ties as the batched look-up
    ``SetSequence._box_levels``, without its numpy calls on one point)."""

    def __init__(self, seq: Any, grid: tuple[Any, Any, Any]) -> None:
        edges, lev, box = grid
        self.seq = seq
        self.edges = [e.tolist() for e in edges]
        self.lev = lev
        self.box = box
        self.n = len(edges)
        self.witness = [np.asarray(st["witness"], dtype=float) for st in seq.steps]
        self.bits = list(itertools.product((0, 1), repeat=self.n))

    def box_level(self, x: np.ndarray) -> tuple[int, int]:
        """``(level, box)`` of the point x from the step boxes (-1: in no box); on a cell
        face the smallest level of the cells meeting there."""
        cand = []
        for j, v in enumerate(x.tolist()):
            e = self.edges[j]
            if not e[0] <= v <= e[-1]:
                return -1, -1
            k = len(e)
            i = bisect.bisect_right(e, v) - 1
            hi_i = min(max(i, 0), k - 2)
            lo_i = min(max(i - 1, 0), k - 2) if i >= 0 and e[i] == v else hi_i
            cand.append((lo_i, hi_i))
        best, which = -1, -1
        lev, box = self.lev, self.box
        for bits in self.bits:
            ix = tuple(cand[j][b] for j, b in enumerate(bits))
            lv = int(lev[ix])
            if lv > 0 and (best < 0 or lv < best):
                best, which = lv, int(box[ix])
        return best, which

    def locate(self, x: np.ndarray) -> tuple[int | None, tuple[int, np.ndarray] | None]:
        """``seq.locate(x)``: the level of x and the stored proving control of its box."""
        lv, bx = self.box_level(x)
        wit = (lv, self.witness[lv - 1][bx].copy()) if lv >= 1 else None
        if bool(np.asarray(self.seq.sets[0].contains(x))):
            return 0, wit
        return (None if lv < 0 else lv), wit


class _OneStepCalls:
    """The evaluations of one step on arrays kept between steps: the solver's start, the
    NLP solver (parameter ``p = [x, vec(H), h, cs]``) and the cost. A solver that is not a
    ``casadi.Function`` is called as such."""

    def __init__(self, ctrl: SetSequenceMPC) -> None:
        S = ctrl._nlp
        self.solver = S
        self.solve: BufferedCall | None = None
        n, m, r = ctrl._n, ctrl._m, ctrl._rmax
        self.z0 = np.zeros(m + 1)  # [v, t]
        self.p = np.zeros(n + r * n + r + 1)  # [x, vec(H), h, cs]
        self.lam_g0 = np.zeros(ctrl._ng)
        self.lbx = np.concatenate([ctrl._v_lo, [-np.inf]])
        self.ubx = np.concatenate([ctrl._v_hi, [np.inf]])
        if isinstance(S, ca.Function):
            idx = {name: S.index_in(name) for name in S.name_in()}
            self.solve = BufferedCall(S, args={idx["x0"]: self.z0, idx["p"]: self.p,
                                               idx["lam_g0"]: self.lam_g0},
                                      interruptible=True)
            for name, v in (("lbx", self.lbx), ("ubx", self.ubx), ("lbg", -np.inf),
                            ("ubg", 0.0)):
                self.solve.args[idx[name]][:] = v
            self.x_out = self.solve.res[S.index_out("x")]
        self.start = BufferedCall(ctrl._start)
        self.cost = BufferedCall(ctrl._costfun)

    def run(self) -> tuple[np.ndarray, Any]:
        """Solve from :attr:`z0`, :attr:`p`, :attr:`lam_g0`: ``(x, stats source)``; Ctrl-C
        raises ``KeyboardInterrupt``."""
        if self.solve is not None:
            try:
                self.solve()
                return self.x_out, self.solve
            except RuntimeError:
                pass  # the plain call below raises the solver's own error
        with solver_call():
            sol = self.solver(x0=self.z0, p=self.p, lbx=self.lbx, ubx=self.ubx,
                              lbg=-np.inf, ubg=0.0, lam_g0=self.lam_g0)
        return np.asarray(sol["x"], dtype=float).reshape(-1), self.solver


class SetSequenceMPC:
    """Dual-mode one-step MPC along a controllable-set sequence (Alg 4.7, 5.4, 6.3).

    Parameters
    ----------
    model : Model
    seq : SetSequence
        From :func:`casadi_cmpc.controllable_sets` (box unions with proving controls, or
        polytopes) or :func:`casadi_cmpc.linear_controllable_sets` (polytopes).
    Q : array_like (n, n), optional
        Weight of the successor state (default identity).
    R : array_like (m, m), optional
        Weight of the control (default identity).
    local_law : LinearLaw, array_like (m, n) or casadi.SX, optional
        The law applied inside ``T = seq[0]``: a :class:`~casadi_cmpc.LinearLaw`
        ``u = u_eq + K (x - x_eq)`` (as :func:`~casadi_cmpc.local_lqr` returns), a bare gain
        ``K`` (``u = K x``) or an expression of ``model.x``. Default: the law T was proven
        invariant under (stored with the sequence by :func:`casadi_cmpc.controllable_sets`).
        A law other than that one is refused (ValueError): T's invariance was proven for its
        law only. With a sequence that holds no proven law (``assume_invariant=True``) the
        given law is applied and its answers say "not proven".
    solver : {"ipopt", "sqp", "lp"}
        Local solver of the one-step problem (built once, the state as parameter), or
        ``"lp"``: the one-step LP (3.9)-(3.10) of a linear model along polytopic sets
        (see the Notes; Q and R are then not used: the objective is the gauge of
        ``gauge``). ``"lp"`` refuses a nonlinear model (ModelError) and a sequence held
        as box unions (ValueError).
    robust : bool, optional
        Certify and optimise for all w in W (default: ``seq.info["robust"]``, else True
        when the model has a disturbance); False uses the centre of W.
    x_ref : array_like (n,), optional
        The cost penalises ``f - x_ref`` (default: the equilibrium ``x_eq`` of a
        :class:`~casadi_cmpc.LinearLaw` given as ``local_law``, else 0).
    solver_options : dict, optional
        Passed to ``casadi.nlpsol``.
    minimax : {"auto", "vertices", "interval"}
        How the worst case over W of (5.20) is taken. ``"vertices"``: the cost's maximum
        over the vertices of W through an epigraph variable of the local solver.
        ``"interval"``: in addition, the certified interval minimax of Alg 5.3
        (:func:`casadi_cmpc.minimax`) over U and the whole W box, whose control is tried
        first (see the Notes). ``"auto"`` (default):
        ``"interval"`` for a robust controller of a model not affine in w
        (:attr:`Model.is_affine_in_w`), else ``"vertices"``. The choice made is the attribute
        ``minimax``.
    minimax_options : dict, optional
        For ``"interval"``: ``eps`` (u-boxes narrower than this are not bisected; default
        the widest side of U / 32, in the units of u), ``time_limit`` (s, default 0.03, or
        None; checked between levels of the search, and the final bounds come after it),
        ``max_boxes`` (u-boxes classified, default 2000), ``w_depth`` (bisection rounds of W
        during the search, default ``min(l, 2)``), ``w_depth_final`` (for the final bounds,
        default ``w_depth + 1``), ``mean_value`` (default True). With the defaults one step
        takes about 10 ms for one control and one disturbance, and about 60 ms for two
        controls, two disturbances and a target of 7 rows (against 2-3 ms for
        ``"vertices"``); a stopped search keeps a certified bracket. Other keys or values
        are refused.
    gauge : Polytope, optional
        Only with ``solver="lp"``: the polytope ``{y : a_k y <= b_k}`` whose gauge around
        ``x_ref``, ``max_k a_k (y - x_ref) / (b_k - a_k x_ref)``, the LP minimises at the
        successor (the ``T x <= 1`` of (3.9)). Default: the terminal set ``K_0``, or the
        convex hull of its polytopes when it is a union; ``x_ref`` must lie strictly
        inside it (ValueError otherwise).

    Attributes
    ----------
    minimax : str
        ``"vertices"`` or ``"interval"``: the resolved choice of the ``minimax`` argument.

    Notes
    -----
    **Robust minimax (5.20), vertices.** The cost's maximum over the vertices of W is taken
    through an epigraph variable, and for polytopic sets the constraint is imposed at every
    vertex. For a model affine in w this is exact (a convex set holds the image of W iff it
    holds the images of its vertices; the cost is convex in the successor). For other models
    the vertex maximum is a lower estimate of the worst-case cost; feasibility is not
    affected, since every applied control is certified by intervals over the whole W.

    **Robust minimax (5.20), interval (Alg 5.4 step 6 with Alg 5.3).** At ``x`` in
    ``K_i \\ K_{i-1}``, :func:`casadi_cmpc.minimax` brackets
    ``V* = min_{u in U} max_{w in W} J(u, w)``, ``J = e' Q e + u' R u``,
    ``e = f(x, u, w) - x_ref``, with ``x`` held as a thin parameter, under
    ``H f(x, u, w) <= h`` for all w when ``K_{i-1}`` is held by polytopes (the latest
    polytope of ``K_{i-1}``, tightened as in the local solver; for a box union only the
    terminal set ``K_0 = T`` gives rows, and the search is over U without constraint at
    the other levels). The vertex-epigraph solver runs first and its candidates (next
    paragraph) seed the search, so the minimax's point is never worse, in its certified
    bound, than the best of them that meets the rows. Its certified point
    (``max_w J <= upper`` there) is the first candidate, then those of the next paragraph;
    the interval test ``f(x, u, W) ⊆ K_{i-1}`` decides as always. When the minimax's point
    fails it, the blends ``u + t (u_mm - u)`` (t = 3/4, 1/2, 1/4) of the certified control
    ``u`` toward it are tried, and the first certified one replaces ``u`` when its
    certified worst-case cost is smaller (a box union cannot be a constraint of the search,
    so its point may leave the target). ``stats["minimax"]`` holds the
    search's status, bracket and size, and ``stats["cost_upper"]`` a certified upper bound
    of ``max_{w in W} J`` at the control applied (its ``upper`` when the control is the
    minimax's; otherwise from a minimax over the single point ``u``), with
    ``stats["cost_lower"]`` the certified lower bound of that problem's ``V*`` when the
    control is the minimax's. ``cost`` of the result stays the maximum over the vertices of W
    (a lower estimate here).

    **Linear models, solver="lp" (thesis (3.9)-(3.10)).** At ``x`` in
    ``K_i \\ K_{i-1}`` one LP per polytope of ``K_{i-1}`` (scipy's HiGHS, all in one call)
    minimises the gauge ξ of the successor over ``u`` in U, with the target rows, and the
    gauge rows, holding for every w in W (the support of ``E W`` taken row by row) and
    moved inward by 1e-9 of each row's scale, ten times HiGHS's feasibility tolerance:
    a solver tolerance cannot then turn an optimum on a facet into a control that misses
    the target. Where the room left at ``x`` is thinner than that margin, the control with
    the largest smallest slack is proposed, and the LP again with half of that slack as
    margin (:class:`~casadi_cmpc.mpc.linear.OneStepLP`). Every answer is a candidate
    only: the first, by gauge value, that passes the interval test
    ``f(x, u, W) ⊆ K_{i-1}`` is applied (label "verified"); when none passes the step
    says "unverified". ``cost`` of the result is the gauge value (worst case over W),
    ``stats["lp"]`` lists the candidates.

    **Linear models along polytopes, NLP solvers.** The NLP's target rows are moved
    inward by 1e-6 of their scale; when the room at ``x`` is thinner, the tightened NLP
    is infeasible and its answer misses the target. When no candidate passes the interval
    test, the most interior control (an LP, as above) is proposed and tested too.

    **Sets held as box unions.** The solver minimises the cost over U; the control applied is
    the first of ``u*``, ``u_w + t (u* - u_w)`` (t = 3/4, 1/2, 1/4) and the stored proving
    control ``u_w`` that is certified to map ``x`` into ``K_{i-1}`` for all w.
    """

    def __init__(self, model: Model, seq: Any, Q: Any = None, R: Any = None,
                 local_law: Any = None, solver: str = "ipopt", *, robust: bool | None = None,
                 x_ref: Any = None, solver_options: dict | None = None,
                 minimax: str = "auto", minimax_options: dict | None = None,
                 gauge: Polytope | None = None) -> None:
        from ..control.controllable import _Target, _w_setup

        if not isinstance(model, Model):
            raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
        if model.m == 0:
            raise ModelError(f"model '{model.name}' has no input")
        sets = getattr(seq, "sets", None)
        if not sets:
            raise TypeError("seq must be a SetSequence (from cm.controllable_sets)")
        if sets[0].dim != model.n:
            raise DimensionError(f"the sequence has dimension {sets[0].dim}; the model has "
                                 f"n = {model.n}")
        solver = str(solver).lower()
        if solver not in ("ipopt", "sqp", "lp"):
            raise ValueError(f"solver must be 'ipopt', 'sqp' or 'lp'; got {solver!r}")
        if solver == "lp":
            if not model.is_linear:
                raise ModelError(
                    f"solver='lp' solves the one-step LP (3.9)-(3.10) of a linear model; "
                    f"model '{model.name}' is nonlinear (use solver='ipopt' or 'sqp')")
            if not all(isinstance(M, Polytope) for S in sets for M in _members(S)):
                raise ValueError("solver='lp' needs every set of the sequence held as "
                                 "polytopes (e.g. from cm.linear_controllable_sets); this "
                                 "sequence holds box unions (use solver='ipopt' or 'sqp')")
            if solver_options:
                raise ValueError("solver_options are options of casadi.nlpsol; solver='lp' "
                                 "takes none")
        n, m = model.n, model.m
        self.model, self.seq, self.solver = model, seq, solver
        self.Q = weight_matrix(Q, n, "Q", definite=False, default=np.eye(n))
        self.R = weight_matrix(R, m, "R", definite=False, default=np.eye(m))
        if x_ref is None:  # the equilibrium of the local law, when it names one
            x_ref = getattr(local_law, "x_eq", None)
        self.x_ref = float_vector(x_ref, n, "x_ref", np.zeros(n))
        if robust is None:
            robust = bool(seq.info.get("robust", model.l > 0))
        self.robust = bool(robust) and model.l > 0
        self._Wbox, _, _ = _w_setup(model, self.robust, None)
        self._law, self._law_proved = self._local_law(local_law)
        # a sequence computed for another map f: its sets are not proven controllable for
        # this model (each step is still certified on this model, one by one)
        self._other_model = seq.info.get("model_key") not in (None, _model_key(model))
        if self._other_model:
            warnings.warn(f"the sequence was computed for model '{seq.info.get('model')}' "
                          f"(another map f than '{model.name}'): its sets are not proven "
                          "controllable for this model, so no bound on the steps to T is "
                          "claimed; each applied control is still certified on this model",
                          CmpcWarning, stacklevel=2)
        # the sets must be proven for every w this controller claims: a sequence computed
        # for a smaller W (or nominally) bounds no steps to T for this W
        self._other_w = not self._other_model and not self._sets_cover_w()
        if self._other_w:
            warnings.warn("the sequence's sets are proven for the disturbances "
                          f"{seq.info.get('proof_W')} (robust={seq.info.get('robust')}), "
                          f"not for every w this controller claims ({self._Wbox.tolist()}): "
                          "no bound on the steps to T is claimed; each applied control is "
                          "still certified for the controller's W", CmpcWarning, stacklevel=2)
        self._w_vertices = (np.asarray(model.W.vertices()) if self.robust else
                            self._Wbox[:, 0][None]) if model.l else np.zeros((1, 0))
        self._targets: dict[int, Any] = {}
        self._target_cls = _Target
        self._polytopic = all(isinstance(M, Polytope) for S in sets[1:] for M in _members(S))
        self._rmax = 0
        if self._polytopic:
            self._rmax = max(M.A.shape[0] for S in sets for M in _members(S)
                             if isinstance(M, Polytope))
        self.minimax = self._resolve_minimax(minimax)
        if self.minimax == "interval" and solver == "lp":
            raise ValueError("minimax='interval' is for models not affine in w; solver='lp' "
                             "takes the worst case over W exactly (use minimax='auto')")
        if self.minimax == "interval":
            self._mm_opts = _minimax_options(minimax_options, model.U, model.l)
        else:
            if minimax_options is not None:
                _minimax_options(minimax_options, model.U, model.l)  # still checked
                warnings.warn("minimax_options are not used: the minimax is 'vertices'",
                              CmpcWarning, stacklevel=2)
            self._mm_opts = {}
        # the one-step LP (3.9)-(3.10) (solver='lp'), and for a linear model along polytopes
        # the most interior control, proposed when no other candidate is certified
        self._lp: OneStepLP | None = None
        self._lp_fallback: OneStepLP | None = None
        if solver == "lp":
            self._lp = OneStepLP(model, self._gauge(gauge), self.x_ref, self._Wbox)
            self._nlp = None
            self._costfun = None
        else:
            if gauge is not None:
                raise ValueError("gauge is the objective of solver='lp'; the NLP solvers "
                                 "minimise the quadratic cost")
            self._nlp = self._build(solver_options or {})
            if model.is_linear and self._polytopic:
                self._lp_fallback = OneStepLP(model, None, self.x_ref, self._Wbox)
        if self.minimax == "interval":
            self._build_minimax()
        self.contract = np.eye(n)  # the whole state is driven to x_ref (for reports)
        self.last_info: dict[str, Any] = {}
        self._xnext: np.ndarray | None = None
        self._n, self._m = n, m
        self._calls: _OneStepCalls | None = None
        self._locator: _PointLocator | bool | None = None
        self._rows_cache: dict[tuple[int, int], Any] = {}
        self._native: dict[int, tuple[Any, Any]] = {}
        self._w_text: str | None = None
        self._W1 = self._Wbox[None]  # (1, l, 2): W for every candidate

    def _local_law(self, local_law: Any) -> tuple[ca.Function | None, bool]:
        """The law applied in T and whether T is proven invariant under it (for the W this
        controller claims). A law other than the one T was proven with is refused."""
        from ..control.invariance import _law_expr, law_from_function, law_identity

        model, info = self.model, self.seq.info
        key = info.get("terminal_law_key")
        same_model = info.get("model_key") == _model_key(model)
        if local_law is not None:
            given = law_identity(model, local_law)
            if key and given["law_key"] != key:
                raise ValueError(
                    f"local_law (u = {given['law']}) is not the law the terminal set was "
                    f"proven invariant under (u = {info.get('terminal_law')}); omit local_law "
                    "to apply the proven law, or certify T under your law and compute the "
                    "sequence with it")
            expr = _law_expr(model, local_law)
        elif key:
            expr = law_from_function(model, info["terminal_law_function"])
        elif info.get("law") is not None:
            expr = _law_expr(model, info["law"])
        else:
            return None, False
        # T's certificate is about the model of the sequence: for another model (another
        # map f) the law's answers say "not proven"
        proved = bool(key) and same_model and info.get("terminal_certificate") == "proved"
        if proved and model.l:  # T's certificate must cover the w this controller claims
            Wc = info.get("terminal_W")
            need = self._Wbox
            proved = Wc is not None and bool(
                np.all(np.asarray(Wc[0]) <= need[:, 0])
                and np.all(need[:, 1] <= np.asarray(Wc[1])))
        return ca.Function("law", [model.x], [expr]), proved

    def _sets_cover_w(self) -> bool:
        """Whether the sequence's sets are proven for every w of this controller's box
        (its info's ``proof_W``; a sequence saved without it: its robust flag and the
        model's W)."""
        if not self.model.l:
            return True
        info = self.seq.info
        pw = info.get("proof_W")
        if pw is None:  # an older file: robust sets are about the model's W, nominal
            return bool(info.get("robust", False)) or not self.robust  # ones its centre
        lo, hi = np.asarray(pw[0], dtype=float), np.asarray(pw[1], dtype=float)
        need = self._Wbox
        return lo.shape == need[:, 0].shape and bool(
            np.all(lo <= need[:, 0]) and np.all(need[:, 1] <= hi))

    def _gauge(self, gauge: Polytope | None) -> Polytope:
        """The gauge polytope of (3.9): the given one, else the terminal set T = K_0 (a
        union: its convex hull)."""
        if gauge is not None:
            if not isinstance(gauge, Polytope):
                raise TypeError(f"gauge must be a Polytope; got {type(gauge).__name__}")
            if gauge.dim != self.model.n:
                raise DimensionError(f"gauge has dimension {gauge.dim}; the model has "
                                     f"n = {self.model.n}")
            return gauge
        members = [M for M in _members(self.seq.sets[0]) if not M.is_empty()]
        if not members:
            raise ValueError("the terminal set K_0 is empty: pass gauge= a polytope around "
                             "x_ref for the objective (3.9)")
        return members[0] if len(members) == 1 else members[0].hull(*members[1:])

    def _resolve_minimax(self, minimax: Any) -> str:
        if not isinstance(minimax, str) or minimax.lower() not in _MINIMAX_MODES:
            raise ValueError(f"minimax must be one of {', '.join(map(repr, _MINIMAX_MODES))}; "
                             f"got {minimax!r}")
        mode = minimax.lower()
        validated = self.model._exact_f is not None
        if mode == "auto":
            return ("interval" if self.robust and not self.model.is_affine_in_w
                    and not validated else "vertices")
        if mode == "interval" and validated:
            raise ModelError(
                f"minimax='interval' brackets the cost of f's expressions, and model "
                f"'{self.model.name}' is {self.model.discretisation}: its bracket would not be "
                "about the interval source of the proofs; use minimax='vertices'")
        if mode == "interval" and self.model.l == 0:
            raise ValueError(f"minimax='interval' needs a disturbance; model "
                             f"'{self.model.name}' has none (use 'vertices' or 'auto')")
        return mode

    # ---------------------------------------------------------------- solver
    def _build_minimax(self) -> None:
        """Semantic extensions of the cost and of the polytope rows, x as a parameter."""
        model = self.model
        n, m, l = model.n, model.m, model.l
        u, w, x = ca.SX.sym("u", m), ca.SX.sym("w", l), ca.SX.sym("x", n)
        # rows of the largest polytope that may be a target (T, the polytopes of K_j)
        r = max(M.A.shape[0] for S in self.seq.sets for M in _members(S)
                if isinstance(M, Polytope))
        Hs, hs = ca.SX.sym("H", r, n), ca.SX.sym("h", r)
        xn = model.function(x, u, w)
        e = xn - ca.DM(self.x_ref)
        J = ca.mtimes([e.T, ca.DM(self.Q), e]) + ca.mtimes([u.T, ca.DM(self.R), u])
        p = ca.vertcat(x, ca.vec(Hs), hs)
        mv = self._mm_opts["mean_value"]
        # one cost for the unconstrained search (parameter x) and one with the rows' inputs
        # (the parameters of the cost and of the constraints of one search are shared)
        self._mm_cost = SemanticExtension(ca.Function("one_step_cost", [u, w, x], [J]),
                                          mean_value=mv)
        self._mm_cost_p = SemanticExtension(ca.Function("one_step_cost_p", [u, w, p], [J]),
                                            mean_value=mv)
        self._mm_rows = SemanticExtension(
            ca.Function("one_step_rows", [u, w, p], [ca.mtimes(Hs, xn) - hs]), mean_value=mv)
        self._mm_r = r

    def _rows(self, j: int, r: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The rows of the target ``K_j`` padded to r rows (see :meth:`_target_rows`),
        computed once per level."""
        key = (j, r)
        if key not in self._rows_cache:
            self._rows_cache[key] = self._target_rows(j, r)
        return self._rows_cache[key]

    def _target_rows(self, j: int, r: int) -> tuple[np.ndarray, np.ndarray] | None:
        """``(H, h)`` padded to r rows: the latest polytope of ``K_j`` (P_j, or T) when K_j
        is held by polytopes only, its offsets tightened by 1e-6 of each row's scale so that
        a control on a facet passes the interval check (the tightening claims nothing); None
        for a box union."""
        members = _members(self.seq.sets[j])
        if not all(isinstance(M, Polytope) for M in members):
            return None
        P = members[-1]
        n = self.model.n
        H = np.zeros((r, n))
        h = np.ones(r)
        H[: P.A.shape[0]] = P.A
        scale = np.abs(P.A) @ np.maximum(np.abs(self.model.X.lo), np.abs(self.model.X.hi))
        h[: P.b.shape[0]] = P.b - 1e-6 * np.maximum(scale, np.abs(P.b))
        return H, h

    def _build(self, opts: dict) -> Any:
        model = self.model
        n, m = model.n, model.m
        u = ca.SX.sym("u", m)
        t = ca.SX.sym("t")
        x = ca.SX.sym("x", n)
        r = self._rmax
        Hs = ca.SX.sym("H", r, n)
        hs = ca.SX.sym("h", r)
        f = model.function
        # the solver sees scaled unknowns: u = mid(U) + half(U) v with v in [-1, 1], and the
        # epigraph of the costs divided by their largest value at the start (parameter cs),
        # so that its absolute tolerances mean the same at every magnitude of U and cost
        U = model.U
        half = 0.5 * (U.hi - U.lo)
        self._u_mid = np.asarray(U.mid, dtype=float)
        self._u_half = np.where(half > 0, half, 1.0)
        self._v_lo = (U.lo - self._u_mid) / self._u_half
        self._v_hi = (U.hi - self._u_mid) / self._u_half
        v = ca.SX.sym("v", m)
        cs = ca.SX.sym("cs")
        uv = ca.DM(self._u_mid) + ca.DM(self._u_half) * v
        g, costs = [], []
        Q, R = ca.DM(self.Q), ca.DM(self.R)
        for wv in self._w_vertices:
            xn = f(x, u, ca.DM(wv)) if model.l else f(x, u, ca.DM.zeros(0))
            e = xn - ca.DM(self.x_ref)
            cost = ca.mtimes([e.T, Q, e]) + ca.mtimes([u.T, R, u])
            costs.append(cost)
            g.append(cs * ca.substitute(cost, u, uv) - t)
            if r:
                g.append(ca.substitute(ca.mtimes(Hs, xn) - hs, u, uv))
        p = ca.vertcat(x, ca.vec(Hs), hs, cs)
        nlp = {"x": ca.vertcat(v, t), "f": t, "g": ca.vertcat(*g), "p": p}
        # one control, a few constraints: a short iteration budget (the applied control is
        # certified whatever the solver returns)
        short = {"ipopt.max_iter": 50} if self.solver == "ipopt" else {
            "max_iter": 10, "tol_du": 1e-6}
        plugin, base = _solver_options(self.solver, {**short, **opts})
        if plugin == "sqpmethod" and "qpsol_options" not in opts:
            # a bound on the active-set changes of one QP (default 1000): a degenerate QP
            # then costs microseconds, not a millisecond, in Python and in the exported C
            base["qpsol_options"] = {**base["qpsol_options"], "max_iter": 50}
        self._ng = int(nlp["g"].numel())
        self._stride = 1 + r
        self._start = self._start_function(x, u, ca.vertcat(*costs))
        wn = ca.DM(self._Wbox[:, 0] * 0.5 + self._Wbox[:, 1] * 0.5) if model.l else \
            ca.DM.zeros(0)
        self._costfun = ca.Function("cost", [x, u], [ca.mmax(ca.vertcat(*costs)),
                                                      f(x, u, wn)])
        self._nlp_spec = (nlp, plugin, base)  # kept for the C export
        return ca.nlpsol("set_sequence_mpc", plugin, nlp, base)

    def _start_function(self, x: Any, u: Any, cvec: Any) -> ca.Function:
        """``start(x, u_g) -> (u_0, c)``: the solver's starting control and the cost at each
        vertex of W there (shape (V,)).

        ``u_0`` is one Newton step from the guess ``u_g`` on the mean of the vertex costs,
        clipped to U; it is kept only when it is finite and lowers that mean, else ``u_g``
        is. For a model affine in u the step lands on the minimiser of the mean cost, a few
        hundredths from the minimax point, which saves the solver about one iteration. The
        exported C calls the same generated function, so both start alike."""
        U = self.model.U
        Jm = ca.sum1(cvec) / cvec.numel()
        un = u - ca.solve(ca.hessian(Jm, u)[0], ca.gradient(Jm, u))
        uc = ca.fmin(ca.fmax(un, ca.DM(U.lo)), ca.DM(U.hi))
        finite = ca.logic_and(ca.mmax(ca.fabs(un)) < ca.inf,
                              ca.substitute(Jm, u, uc) <= Jm)
        u0 = ca.if_else(finite, uc, u)
        return ca.Function("start", [x, u], [u0, ca.substitute(cvec, u, u0)],
                           ["x", "u_guess"], ["u0", "costs"])

    def _initial(self, x: np.ndarray, ug: np.ndarray) -> float:
        """The solver's start, written into its input arrays: ``u_0`` from
        :meth:`_start_function` (as the scaled ``v_0``), the epigraph variable at the largest
        vertex cost ``c_k`` and multiplier 1 on that row, 0 elsewhere; returns ``cs = 1 /
        c_k`` (1 when ``c_k`` is 0 or not finite), which scales the costs. Such a start
        satisfies complementarity: ``sqpmethod``, whose convergence test does not check it,
        would otherwise stop at once where the mean cost is stationary. The exported C does
        the same."""
        calls = self._step_calls()
        st = calls.start
        st.args[0][:] = x
        st.args[1][:] = ug
        st()
        u0, c = st.res
        k = _first_max(c.tolist())
        ck = float(c[k])
        cs = 1.0 / ck if math.isfinite(ck) and ck > 0 else 1.0
        m = self._m
        z0 = calls.z0
        np.subtract(u0, self._u_mid, out=z0[:m])
        z0[:m] /= self._u_half
        z0[m] = cs * ck
        lam = calls.lam_g0
        lam.fill(0.0)
        lam[k * self._stride] = 1.0
        return cs

    def _step_calls(self) -> _OneStepCalls:
        """The per-step evaluations (built at the first use, and again when the solver has
        been replaced)."""
        c = self._calls
        if c is None or c.solver is not self._nlp:
            c = self._calls = _OneStepCalls(self)
        return c

    def _target(self, i: int) -> Any:
        """The proven test ``f(X, U, W) ⊆ K_i`` (built once per level), its inclusion
        functions moving to the native backend after a few steps (:class:`NativeAfter`)."""
        t = self._targets.get(i)
        if t is None:
            t = self._target_cls(self.model, self.seq.sets[i])
            t.polys = [(self._native_form(F), c, b) for F, c, b in t.polys]
            if t.F is not None:
                t.F = self._native_form(t.F)
            self._targets[i] = t
        return t

    def _native_form(self, F: InclusionFunction) -> Any:
        """``F`` (an inclusion function shared with the model's other users) for the checks
        of this controller: one :class:`NativeAfter` per function, shared by the levels, on
        the native backend once it has evaluated a few steps."""
        got = self._native.get(id(F))
        if got is None:
            got = self._native[id(F)] = (F, NativeAfter(F))
        return got[1]

    def _certify(self, x: np.ndarray, U: np.ndarray, i: int) -> np.ndarray:
        """Proven ``f(x, u, W) ⊆ K_i`` and ``u in U`` per candidate row of ``U``."""
        U = np.atleast_2d(U)
        box = self.model.U
        inU = ((U >= box.lo) & (U <= box.hi)).all(axis=1) & np.isfinite(U).all(axis=1)
        if not inU.all():
            ok = np.zeros(U.shape[0], dtype=bool)
            idx = np.flatnonzero(inU)
            if idx.size:
                ok[idx] = self._certify(x, U[idx], i)
            return ok
        k = U.shape[0]
        X = np.empty((k, x.size, 2))
        X[...] = x[:, None]
        Ub = np.empty((k, U.shape[1], 2))
        Ub[...] = U[:, :, None]
        return self._target(i).inside(X, Ub, self._W1)

    def _cost(self, x: np.ndarray, u: np.ndarray) -> float:
        """The cost's maximum over the vertices of W (the nominal w when not robust); for
        solver='lp' the gauge value of (3.9), worst case over W."""
        lp = self._lp
        if lp is not None:
            wc = 0.5 * self._Wbox[:, 0] + 0.5 * self._Wbox[:, 1]
            self._xnext = lp.A @ x + lp.B @ u + lp.E @ wc + lp.c
            return lp.xi(x, u)
        call = self._step_calls().cost
        call.args[0][:] = x
        call.args[1][:] = u
        call()
        c, xn = call.res
        self._xnext = xn.copy()
        return float(c[0])

    def __repr__(self) -> str:
        return (f"SetSequenceMPC(model='{self.model.name}', sets={len(self.seq)}, "
                f"solver='{self.solver}', robust={self.robust}, minimax='{self.minimax}')")

    def export_spec(self) -> SetSequenceSpec:
        """The data the C export is generated from (see :mod:`casadi_cmpc.mpc.spec`).

        Internal API shared with :mod:`casadi_cmpc.codegen`: the sequence and its grid of
        step boxes, the local law, the one-step NLP with its parameters per target level,
        the solver's start and the scaling of the control.

        Returns
        -------
        SetSequenceSpec
        """
        if self._lp is not None:
            raise NotImplementedError("the C export covers the NLP one-step solvers; build "
                                      "the controller with solver='sqp' to export it")
        seq, n, r = self.seq, self._n, self._rmax
        rows = []
        for j in range(len(seq.sets) - 1 if r else 0):
            got = self._rows(j, r)
            rows.append(got if got is not None else (np.zeros((r, n)), np.ones(r)))
        grid = seq._grid() if hasattr(seq, "_grid") else None
        nlp, plugin, options = self._nlp_spec
        return SetSequenceSpec(
            model=self.model, seq=seq, members=[_members(S) for S in seq.sets], grid=grid,
            robust=self.robust, minimax=self.minimax, local_law=self._law,
            polytopic=self._polytopic, rows=r, nlp_rows=rows, nlp=nlp, plugin=plugin,
            options=dict(options), start=self._start, w_vertices=self._w_vertices,
            u_mid=self._u_mid, u_half=self._u_half, v_lo=self._v_lo, v_hi=self._v_hi)

    def export_c(self, directory: Any, solver: str = "sqp", **kw: Any) -> Any:
        """Write this controller as standalone C: the one-step solver, the model, the local
        law and the set tables (level look-up, stored proving controls); see
        :func:`casadi_cmpc.codegen.export_c` for the files, the ``cmpc_step`` API and the
        options. Returns an :class:`~casadi_cmpc.codegen.ExportInfo`."""
        from ..codegen import export_c

        return export_c(self, directory, solver=solver, **kw)

    def reset(self) -> None:
        """Forget the previous call (the controller keeps no state between calls)."""
        self.last_info = {}

    @property
    def guarantee(self) -> str:
        """What the closed loop under this controller is guaranteed (one sentence).

        From ``x`` in ``K_i`` (``i >= 1``) each applied control is certified (interval
        arithmetic) to bring the next state into ``K_{i-1}``; in ``T = K_0`` the local law
        keeps it in T when T's invariance under that law is proven. Together: T is reached
        in at most ``i`` steps and never left, for the disturbances named."""
        w = self._w_claim() or " (no disturbance)"
        law = ("the local law keeps it in T (T proven invariant under that law)"
               if self._law_proved else
               "inside T the local law is applied, but T's invariance under it is NOT "
               "proven, so staying in T is not guaranteed")
        if self._other_w:
            return (f"the sets K_i are proven for w in {self.seq.info.get('proof_W')} only, "
                    f"not for every w this controller claims: a control certified to bring "
                    f"the state into K_(i-1){w} is applied where one is found (the step says "
                    "so in its label), but that one exists at every step is not proven, so "
                    f"reaching T is not guaranteed; {law}")
        if self._other_model:
            return (f"the sets K_i were computed for another model "
                    f"('{self.seq.info.get('model')}'): a control certified on this model to "
                    f"bring the state into K_(i-1){w} is applied where one is found (the step "
                    "says so in its label), but that one exists at every step is not proven "
                    f"for this model, so reaching T is not guaranteed; {law}")
        return (f"from x in K_i every applied control is certified to bring the state into "
                f"K_(i-1), so T = K_0 is reached in at most i steps{w}; {law}. A step that "
                "is not certified (e.g. x outside every K_i) says so in its label")

    @property
    def proof_w(self) -> np.ndarray:
        """The disturbances its certified steps are proven for, as a box (l, 2): W when
        robust, else the thin box at the nominal w (the centre of W)."""
        return np.array(self._Wbox, dtype=float).reshape(self.model.l, 2)

    def _w_claim(self) -> str:
        """Which disturbances a claim of this controller covers (built once)."""
        text = self._w_text
        if text is None:
            text = self._w_text = self._w_claim_text()
        return text

    def _w_claim_text(self) -> str:
        if not self.model.l:
            return ""
        if self.robust:
            return (f" for all w in W = [{self.model.W.lo.tolist()}, "
                    f"{self.model.W.hi.tolist()}] (robust)")
        return (f" for w = {self._Wbox[:, 0].tolist()} only (nominal: the centre of W; "
                "other w are not checked)")

    # ---------------------------------------------------------------- calls
    def __call__(self, x: Any) -> np.ndarray:
        """The control to apply at ``x`` (m,); raises ValueError when x is not controllable
        as far as the sequence proves."""
        res = self.solve(x)
        if res.u is None or not np.isfinite(res.u).all():
            if res.certificate.label == "not_controllable":
                raise NotControllableError(res.certificate.reason)
            raise ValueError(res.certificate.reason)
        return res.u

    def solve(self, x: Any) -> MPCResult:
        """Solve the one-step problem at ``x``; see the class notes."""
        t0 = time.perf_counter()
        n, m = self._n, self._m
        x = float_vector(x, n, "x", None)
        lvl, wit = self._locate(x)
        nan_u = np.full(m, np.nan)
        stats: dict[str, Any] = {"solver": self.solver, "level": lvl}
        if lvl is None:
            cert = Certificate("not_controllable", None,
                               "x lies in a set of the sequence",
                               f"x = {x.tolist()} lies in no set K_0..K_{len(self.seq) - 1} "
                               "of the sequence: not controllable from here as far as the "
                               "sequence proves (the maximal set may be larger than its "
                               "inner approximation)")
            return self._done(x, nan_u, np.nan, None, cert, stats, "not_controllable",
                              Status.UNDECIDED, t0)
        if lvl == 0:
            if self._law is None:
                raise ValueError("x lies in the terminal set but no local_law was given")
            u = np.asarray(self._law(x), dtype=float).reshape(m)
            cert = Certificate(
                "local_law", True if self._law_proved else None,
                "x in T: the local law keeps the state in T" + self._w_claim()
                if self._law_proved else
                "x in T: the local law is applied (that it keeps the state in T"
                + self._w_claim() + " is NOT proven)",
                f"T is proven invariant under this law ({self.seq.info.get('terminal_claim')})"
                if self._law_proved else
                "the invariance of T under this law was not proven "
                + ("for this model (the sequence was computed for "
                   f"'{self.seq.info.get('model')}', another map f)"
                   if self.seq.info.get("model_key") not in (None, _model_key(self.model))
                   else "for all w in W (the certificate of T covers "
                   f"{self.seq.info.get('terminal_W')})" if self.seq.info.get(
                       "terminal_law_key") else "(the sequence holds no proven law)"))
            return self._done(x, u, self._cost(x, u), 0, cert, stats, "local_law",
                              Status.PROVED if self._law_proved else Status.UNDECIDED, t0)
        # ---------------- one-step problem into K_{lvl - 1}
        j = lvl - 1
        u_w = None if wit is None else np.asarray(wit[1], dtype=float).reshape(m)
        if self._lp is not None:
            return self._solve_lp(x, lvl, u_w, stats, t0)
        ts = time.perf_counter()
        u_opt = self._solve_nlp(x, j, stats, u_w)
        stats["solve_time"] = time.perf_counter() - ts
        cands: list[tuple[np.ndarray, str]] = []
        if u_opt is not None:
            cands.append((u_opt, "solver"))
        if u_w is not None:
            if u_opt is not None:  # u_w + t (u_opt - u_w), t = 3/4, 1/2, 1/4
                blends = u_w + _BLEND_STEPS * (u_opt - u_w)
                cands += [(b, "blend of solver and stored control") for b in blends]
            cands.append((u_w, "stored control"))
        mm: MinimaxResult | None = None
        if self.minimax == "interval":
            tm = time.perf_counter()
            seeds = np.asarray([c for c, _ in cands], dtype=float).reshape(-1, m)
            mm = self._solve_minimax(x, j, stats, seeds)
            stats["minimax_time"] = time.perf_counter() - tm
            if mm.u_feasible and mm.u is not None:
                cands.insert(0, (np.asarray(mm.u, dtype=float).reshape(m), "interval minimax"))
        if not cands:
            cert = Certificate("undecided", None, f"f(x, u, w) in K_{j}" + self._w_claim(),
                               "the solver failed and no proving control is stored")
            return self._done(x, nan_u, np.nan, lvl, cert, stats, "mpc", Status.NUMERICAL,
                              t0)
        C = np.asarray([c for c, _ in cands], dtype=float).reshape(-1, m)
        tv = time.perf_counter()
        ok = np.zeros(C.shape[0], dtype=bool)
        ok[0] = self._certify(x, C[:1], j)[0]  # the optimiser's control first
        if not ok[0] and C.shape[0] > 1:
            ok[1:] = self._certify(x, C[1:], j)
        # the witness proves x's box into the target of its own step (a subset of K_{lvl-1});
        # needed only when no candidate before it is certified
        if u_w is not None and not ok.any() and wit[0] <= lvl:
            ok[-1] = self._certify(x, C[-1:], wit[0] - 1)[0]
        k = np.flatnonzero(ok)
        if k.size == 0 and self._lp_fallback is not None:
            # the solver's answers are candidates only; along polytopes of a linear model
            # the most interior control (an LP) is proposed when none of them passes
            more = self._interior(x, j, stats)
            if more:
                cands += [(c.u, f"most interior control ({c.how}, LP)") for c in more]
                C = np.vstack([C] + [c.u[None] for c in more])
                ok = np.concatenate([ok, self._certify(x, C[-len(more):], j)])
                k = np.flatnonzero(ok)
        stats["verify_time"] = time.perf_counter() - tv
        if k.size == 0:
            u = C[-1] if u_w is not None else C[0]
            self._cost_bounds(x, u, mm, False, stats)
            cert = Certificate("unverified", None, f"f(x, u, w) in K_{j}" + self._w_claim(),
                               "no candidate control could be certified")
            return self._done(x, u, self._cost(x, u), lvl, cert, stats, "mpc",
                              Status.UNDECIDED, t0)
        u, src = C[k[0]], cands[k[0]][1]
        if mm is not None and mm.u_feasible and src != "interval minimax":
            u, src = self._toward_minimax(x, j, u, src, np.asarray(mm.u, dtype=float), stats)
        self._cost_bounds(x, u, mm, src == "interval minimax", stats)
        cert = Certificate("verified", True, f"f(x, u, w) in K_{j}" + self._w_claim(),
                           f"interval evaluation at x with u from the {src}",
                           {"candidates": int(C.shape[0]), "chosen": int(k[0]),
                            "source": src})
        return self._done(x, u, self._cost(x, u), lvl, cert, stats, "mpc", Status.PROVED, t0)

    def _interior(self, x: np.ndarray, j: int, stats: dict) -> list[Any]:
        """Candidates of the fallback LP toward ``K_j`` (none unless K_j is polytopes)."""
        members = _members(self.seq.sets[j])
        if self._lp_fallback is None or not all(isinstance(M, Polytope) for M in members):
            return []
        got = self._lp_fallback.candidates(x, members)
        stats["interior_lp"] = [{"how": c.how, "member": c.member, "slack": c.slack}
                                for c in got]
        return got

    def _solve_lp(self, x: np.ndarray, lvl: int, u_w: np.ndarray | None, stats: dict,
                  t0: float) -> MPCResult:
        """The one-step LP (3.9)-(3.10) at ``x`` in ``K_lvl \\ K_(lvl-1)``: candidates
        from :class:`OneStepLP`, the first (smallest gauge value) that passes the interval
        test ``f(x, u, W) ⊆ K_(lvl-1)`` is applied."""
        j = lvl - 1
        m = self._m
        ts = time.perf_counter()
        got = self._lp.candidates(x, _members(self.seq.sets[j]))
        stats["solve_time"] = time.perf_counter() - ts
        stats["lp"] = [{"how": c.how, "member": c.member, "xi": c.xi, "slack": c.slack}
                       for c in got]
        cands = [(c.u, f"one-step LP (3.9)-(3.10), {c.how}") for c in got]
        if u_w is not None:
            cands.append((u_w, "stored control"))
        claim = f"f(x, u, w) in K_{j}" + self._w_claim()
        if not cands:
            cert = Certificate("undecided", None, claim,
                               "every one-step LP was infeasible for HiGHS (no room at x)")
            return self._done(x, np.full(m, np.nan), np.nan, lvl, cert, stats, "mpc",
                              Status.NUMERICAL, t0)
        C = np.asarray([c for c, _ in cands], dtype=float).reshape(-1, m)
        tv = time.perf_counter()
        ok = self._certify(x, C, j)
        stats["verify_time"] = time.perf_counter() - tv
        k = np.flatnonzero(ok)
        if k.size == 0:
            u = C[0]
            cert = Certificate("unverified", None, claim,
                               "no candidate control could be certified")
            return self._done(x, u, self._cost(x, u), lvl, cert, stats, "mpc",
                              Status.UNDECIDED, t0)
        u, src = C[k[0]], cands[k[0]][1]
        cert = Certificate("verified", True, claim,
                           f"interval evaluation at x with u from the {src}",
                           {"candidates": int(C.shape[0]), "chosen": int(k[0]),
                            "source": src})
        return self._done(x, u, self._cost(x, u), lvl, cert, stats, "mpc", Status.PROVED, t0)

    def _locate(self, x: np.ndarray) -> tuple[int | None, tuple[int, np.ndarray] | None]:
        """``(level, witness)`` of x: :meth:`SetSequence.locate`, by a point look-up on the
        grid of the step boxes (built once) when the sequence has one."""
        loc = self._locator
        if loc is None:
            loc = self._locator = self._point_locator()
        if loc is not False:
            return loc.locate(x)
        if hasattr(self.seq, "locate"):
            return self.seq.locate(x)
        return self.seq.level(x), None

    def _point_locator(self) -> _PointLocator | bool:
        """The point look-up, or False when ``seq.locate`` does not read a grid of step
        boxes with their proving controls."""
        seq = self.seq
        index = getattr(seq, "_index", None)
        if not hasattr(seq, "locate") or index is None:
            return False
        grid = index()
        if grid is None or any(st.get("witness") is None for st in seq.steps):
            return False
        return _PointLocator(seq, grid)

    # ---------------------------------------------------------------- interval minimax
    def _minimax_kw(self) -> dict[str, Any]:
        o = self._mm_opts
        return {"options": {"w_depth": o["w_depth"], "w_depth_final": o["w_depth_final"]},
                "max_boxes": o["max_boxes"], "time_limit": o["time_limit"],
                "progress": False}

    def _solve_minimax(self, x: np.ndarray, j: int, stats: dict,
                       seeds: np.ndarray) -> MinimaxResult:
        """Alg 5.3 at ``x``: min over U of max over W of the cost, into ``K_j``'s rows;
        ``seeds`` (k, m): the other candidates, tried first (their bound prunes the search)."""
        rows = self._rows(j, self._mm_r)
        if rows is None:
            f, g, par = self._mm_cost, None, x
        else:
            H, h = rows
            f, g = self._mm_cost_p, self._mm_rows
            par = np.concatenate([x, H.ravel(order="F"), h])
        res = _minimax(f, self.model.U, self._Wbox, self._mm_opts["eps"], g, params=par,
                       points=seeds if seeds.size else None, **self._minimax_kw())
        stats["minimax"] = {
            "status": res.status.name, "lower": res.lower, "upper": res.upper,
            "u": None if res.u is None else np.asarray(res.u, dtype=float).copy(),
            "u_feasible": res.u_feasible, "constrained": rows is not None,
            "n_boxes": res.n_boxes, "levels": res.nit, "elapsed": res.elapsed,
            "message": res.message}
        return res

    def _point_bound(self, x: np.ndarray, u: np.ndarray) -> float:
        """A certified upper bound of ``max_{w in W} J(u, w)`` at the single point u."""
        ub = np.stack([u, u], axis=-1)
        r = _minimax(self._mm_cost, ub, self._Wbox, self._mm_opts["eps"], params=x,
                     **{**self._minimax_kw(), "max_boxes": 4})
        return float(r.upper)

    def _toward_minimax(self, x: np.ndarray, j: int, u: np.ndarray, src: str,
                        u_mm: np.ndarray, stats: dict) -> tuple[np.ndarray, str]:
        """The certified control ``u`` or, when one is certified too and has a smaller
        certified worst-case cost, the blend ``u + t (u_mm - u)`` with the largest t of
        3/4, 1/2, 1/4 (the minimax's own point could not be certified)."""
        B = np.asarray([u + t * (u_mm - u) for t in (0.75, 0.5, 0.25)])
        ok = self._certify(x, B, j)
        bound = self._point_bound(x, u)
        stats["cost_upper"] = bound
        if ok.any():
            ub = B[int(np.flatnonzero(ok)[0])]
            b2 = self._point_bound(x, ub)
            if b2 < bound:
                stats["cost_upper"] = b2
                return ub, f"blend of interval minimax and {src}"
        return u, src

    def _cost_bounds(self, x: np.ndarray, u: np.ndarray, mm: MinimaxResult | None,
                     from_minimax: bool, stats: dict) -> None:
        """``stats["cost_upper"]`` (and ``"cost_lower"``) for the interval minimax."""
        if mm is None or not np.isfinite(u).all():
            return
        if from_minimax:
            stats["cost_lower"], stats["cost_upper"] = mm.lower, mm.upper
        elif "cost_upper" not in stats:
            stats["cost_upper"] = self._point_bound(x, u)

    def _solve_nlp(self, x: np.ndarray, j: int, stats: dict,
                   u0: np.ndarray | None) -> np.ndarray | None:
        n, r = self._n, self._rmax
        calls = self._step_calls()
        p = calls.p
        p[:n] = x
        if r:
            rows = self._rows(j, r)
            H, h = rows if rows is not None else (np.zeros((r, n)), np.ones(r))
            p[n:n + r * n] = H.ravel(order="F")
            p[n + r * n:n + r * n + r] = h
        try:
            p[-1] = self._initial(x, self.model.U.mid if u0 is None else u0)
            z, src = calls.run()
        except RuntimeError as exc:
            stats["return_status"] = str(exc)
            return None
        stats["return_status"] = src.stats().get("return_status")
        v = z[:self._m]
        u = np.minimum(np.maximum(self._u_mid + self._u_half * v, self.model.U.lo),
                       self.model.U.hi)
        return u if np.isfinite(v).all() else None

    def _done(self, x: np.ndarray, u: np.ndarray, cost: float, lvl: int | None,
              cert: Certificate, stats: dict, mode: str, status: Status,
              t0: float) -> MPCResult:
        el = time.perf_counter() - t0
        xp = np.full((2, self._n), np.nan)
        xp[0] = x
        if np.isfinite(u).all():
            if self._xnext is None:
                self._cost(x, u)
            xp[1] = self._xnext
        self._xnext = None
        self.last_info = {"status": "ok" if status == Status.PROVED else status.name.lower(),
                          "certificate": cert.label, "horizon": lvl, "level": lvl,
                          "mode": mode,
                          "solve_time": el, "minimax": self.minimax}
        return MPCResult(status=status, message=cert.reason, method="set sequence one-step",
                         nit=0, n_boxes=0, elapsed=el, x=x, u=u, u_seq=u[None],
                         x_pred=xp, cost=float(cost), horizon=lvl, certificate=cert,
                         stats=stats, mode=mode)
