"""Search for a certified terminal set: scaled Lyapunov sublevel sets tested by
:func:`~casadi_cmpc.certify_invariant`.

:func:`terminal_set` builds, around an equilibrium ``(x_eq, u_eq)`` of the closed loop
``x+ = f(x, law(x), w)``, a one-parameter family of polytopes

    S(s) = {x : A_unit (x - x_eq) <= s},   s > 0,

shaped by a Lyapunov function of the linearised closed loop, and searches the scale ``s``:
a descent from the largest scale the boxes X and U allow, then a bisection (geometric
mean) between the largest proven and the smallest failed scale. Every candidate
is checked by :func:`~casadi_cmpc.certify_invariant` (``f(x, law(x), w) in S`` and
``law(x) in U`` for all ``x in S``, ``w in W``) and by a rigorous bounding box for
``S ⊆ X`` (which ``certify_invariant`` does not claim). Only a candidate for which both are
proven is ever returned. Nothing here is specific to two states.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from .._interrupt import InterruptScope
from .._validate import float_vector as _vector
from .._validate import weight_matrix as _weight
from ..exceptions import ModelError
from ..model import Model, _as_model_box
from ..sets.box import Box
from ..sets.polytope import Polytope
from ..solvers._common import positive_eps
from ..solvers.engine import Status
from ..solvers.result import Certificate, Result
from .invariance import _certify, _check_target, _closed, local_lqr
from .law import LinearLaw, as_law, law_expr

__all__ = ["terminal_set", "TerminalSetResult"]

SHAPES = ("ellipsoid", "parallelotope", "modal")

# n >= 3: ±e_i and (±e_i ± e_j)/sqrt(2) (2 n^2 facets); n = 2: a regular 16-gon
_POLYGON_FACETS = 16
# the descent of a shape stops after this many candidates in a row left undecided with
# the budget of their set inversion (max_boxes) spent: smaller scales rarely help then
_MAX_OVER_BUDGET = 3


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class TerminalSetResult(Result):
    """Result of :func:`terminal_set`.

    Attributes
    ----------
    terminal : Polytope or None
        The largest candidate ``S(scale)`` proven invariant: its ``certificate`` (of
        :func:`~casadi_cmpc.certify_invariant`) has ``proved is True`` and ``S ⊆ X`` is
        proven by a rigorous bounding box. ``None`` when no candidate was proven.
    scale : float
        Its scale ``s`` (0.0 when ``terminal`` is None). ``S(s) = {x : A_unit (x - x_eq)
        <= s}`` with ``A_unit = unit.A``.
    certificate : Certificate or None
        The proof for ``terminal`` (what it claims: ``certificate.claim``; what it is about,
        model, set, law and W: ``certificate.about``).
    law : LinearLaw or casadi.SX
        The law the set is proven invariant under (the LQR law of the linearisation at
        the equilibrium when none was given).
    x_eq : ndarray (n,)
        The equilibrium the candidates are centred at (state units).
    u_eq : ndarray (m,)
        ``law(x_eq)`` (input units).
    W : Box or None
        The disturbance box the proof covers (None for a model without w).
    robust : bool
        True when ``W`` is a box of more than one point (every w in W is covered); False
        for a nominal proof (one w only, or no w).
    shape : str
        ``"ellipsoid"``, ``"parallelotope"`` or ``"modal"`` (see :func:`terminal_set`).
    unit : Polytope
        The unit candidate about the origin, ``{dx : A_unit dx <= 1}``; ``S(s)`` is
        ``x_eq + s * unit``.
    P : ndarray (n, n)
        The quadratic Lyapunov matrix of the linearised closed loop
        (``Acl' P Acl - P = -(Q + K' R K)``; for the LQR law, the Riccati solution).
        ``unit`` contains ``{dx : dx' P dx <= 1}`` for the shapes "ellipsoid" and
        "parallelotope".
    contraction : dict of str to float
        Per shape, the one-step factor of the linearised closed loop on the unit candidate,
        ``max_i max_{dx in unit} a_i Acl dx`` (below 1: the linearisation maps every
        ``S(s)`` into ``S(contraction * s)``; 1 or more: the shape is not invariant even
        for the linearisation). Floating point; a guide, not a proof.
    scale_limit : float
        The largest scale searched: the smallest of ``max_scale`` and the largest ``s``
        with ``S(s) ⊆ X`` and ``K_lin S(s) ⊆ U - u_eq`` (floating point).
    candidates : list of dict
        Every candidate tried, in order: ``shape``, ``scale``, ``verdict`` (``"proved"``,
        ``"refuted"``, ``"undecided"`` or ``"outside X"``), ``reason`` and ``seconds``.
    stop_reason : str
        Why the search stopped: ``"resolution"`` (the largest proven and the smallest
        failed scale are within ``rtol``), ``"scale_limit"`` (the largest scale allowed was
        proven), ``"min_scale"`` (no candidate proven down to the smallest scale),
        ``"max_boxes"`` (the descent gave up after 3 candidates in a row left undecided
        with the budget of their set inversion spent; try a larger ``max_boxes`` or
        another shape), ``"time_limit"``, ``"max_candidates"`` or ``"interrupted"``.
    stats : dict
        ``proved``, ``refuted``, ``undecided``, ``outside_X`` (counts over all shapes),
        ``seconds``, ``certify_seconds``, ``min_scale`` and ``disturbance_floor`` of the
        returned shape (the floor: the smallest scale at which the linearisation absorbs
        W, 0 for a nominal search), and ``searches``: per shape searched, its ``scale``
        (0.0: none proven), ``stop``, ``eps``, ``scale_limit``, ``min_scale``,
        ``disturbance_floor``, ``unit_volume`` and ``over_budget`` (candidates in a row
        left undecided with max_boxes spent).
    status, success, message, method, nit, n_boxes, elapsed
        See :class:`~casadi_cmpc.solvers.result.Result`: ``PROVED`` (0) the search ran to
        its end (``stop_reason`` "resolution" or "scale_limit") with a proven set;
        ``BUDGET`` (1) ``time_limit``, ``max_candidates`` or an interruption stopped it
        (``terminal``, if any, is proven, but a larger scale may be); ``UNDECIDED`` (3) no
        candidate was proven. ``nit`` and ``n_boxes`` both count the candidates tried.
    """

    terminal: Polytope | None
    scale: float
    certificate: Certificate | None
    law: Any
    x_eq: np.ndarray
    u_eq: np.ndarray
    W: Box | None
    robust: bool
    shape: str
    unit: Polytope
    P: np.ndarray
    contraction: dict = field(default_factory=dict)
    scale_limit: float = 0.0
    candidates: list = field(default_factory=list)
    stop_reason: str = ""
    stats: dict = field(default_factory=dict)

    @property
    def claim(self) -> str:
        """What was proven about ``terminal``, in words ("" when nothing was)."""
        if self.terminal is None or self.certificate is None:
            return ""
        return (self.certificate.claim + "; and S ⊆ X, the model's state box (rigorous "
                "bounding box)")

    def _repr_parts(self) -> list[str]:
        return [f"shape={self.shape!r}", f"scale={self.scale:.6g}",
                f"robust={self.robust}", f"stop={self.stop_reason!r}"]


# ------------------------------------------------------------------ helpers
def _law_function(model: Model, law: Any) -> ca.Function:
    return ca.Function("law", [model.x], [law_expr(model, law)])


def _linear_gain(model: Model, law: Any, x_eq: np.ndarray) -> np.ndarray:
    """The gain (m, n) of the law's linearisation at x_eq."""
    if isinstance(law, LinearLaw):
        return np.array(law.K, dtype=float)
    J = ca.Function("dlaw", [model.x], [ca.jacobian(law_expr(model, law), model.x)])
    return np.asarray(J(x_eq), dtype=float).reshape(model.m, model.n)


def _margins(box: Box, c: np.ndarray, what: str) -> np.ndarray:
    """Distances (d,) from c to the bounds of box on the nearer side; c must be inside."""
    lo, hi = c - box.lo, box.hi - c
    if (lo <= 0).any() or (hi <= 0).any():
        raise ValueError(f"{what} = {c.tolist()} is not inside the interior of "
                         f"[{box.lo.tolist()}, {box.hi.tolist()}]: no set around it fits")
    return np.minimum(lo, hi)


def _unit_directions(n: int) -> np.ndarray:
    """Unit vectors whose polytope ``{z : d.z <= 1}`` circumscribes the unit ball."""
    if n == 1:
        return np.array([[1.0], [-1.0]])
    if n == 2:
        th = 2 * np.pi * np.arange(_POLYGON_FACETS) / _POLYGON_FACETS
        return np.stack([np.cos(th), np.sin(th)], axis=1)
    rows = [s * e for e in np.eye(n) for s in (1.0, -1.0)]
    for i in range(n):
        for j in range(i + 1, n):
            for si in (1.0, -1.0):
                for sj in (1.0, -1.0):
                    d = np.zeros(n)
                    d[i], d[j] = si, sj
                    rows.append(d / np.sqrt(2.0))
    return np.array(rows)


def _whitening(P: np.ndarray) -> np.ndarray:
    """V with ``V' V = P`` and rows along the eigenvectors of P (scaled by sqrt(lambda))."""
    lam, Qv = np.linalg.eigh(0.5 * (P + P.T))
    return np.sqrt(lam)[:, None] * Qv.T


def _real_modal(Acl: np.ndarray) -> tuple[np.ndarray, list[list[int]]] | None:
    """Real modal coordinates ``z = T dx`` of Acl (rows of T) and the blocks (one index
    for a real eigenvalue, two for a complex pair); None when Acl is not (well)
    diagonalisable."""
    ev, Wv = np.linalg.eig(Acl)
    n = Acl.shape[0]
    cols, blocks, used = [], [], set()
    for i in range(n):
        if i in used:
            continue
        if abs(ev[i].imag) <= 1e-12 * max(1.0, abs(ev[i])):
            blocks.append([len(cols)])
            cols.append(Wv[:, i].real)
            used.add(i)
            continue
        j = next((k for k in range(n) if k not in used and k != i
                  and abs(ev[k] - np.conj(ev[i])) <= 1e-9 * max(1.0, abs(ev[i]))), None)
        if j is None:
            return None
        used.update((i, j))
        blocks.append([len(cols), len(cols) + 1])
        cols += [Wv[:, i].real, Wv[:, i].imag]
    Tinv = np.array(cols).T
    if not np.isfinite(Tinv).all() or np.linalg.cond(Tinv) > 1e8:
        return None
    return np.linalg.inv(Tinv), blocks


def _modal_scaling(T: np.ndarray, blocks: list[list[int]], limits: np.ndarray,
                   rows: np.ndarray) -> np.ndarray:
    """Per-coordinate scales e (n,) of the modal box ``{|diag(1/e) T dx|_inf <= 1}``
    maximising its volume under ``|rows T^-1| e <= limits`` (the box inside X and the
    linear law inside U); one scale per block, so that a complex pair keeps its
    rotation-scaling form."""
    from scipy.optimize import minimize

    M = np.abs(rows @ np.linalg.inv(T))
    nb = len(blocks)
    E = np.zeros((nb, T.shape[0]))
    for k, b in enumerate(blocks):
        E[k, b] = 1.0
    Mb = M @ E.T  # (rows, blocks)
    size = np.array([len(b) for b in blocks], dtype=float)

    # log-scales y: maximise sum(size * y) (the log-volume) under Mb exp(y) <= limits
    y0 = np.full(nb, np.log(np.min(limits / np.maximum(Mb.sum(axis=1), 1e-300))))
    cons = {"type": "ineq", "fun": lambda y: 1.0 - (Mb @ np.exp(y)) / limits}
    res = minimize(lambda y: -float(size @ y), y0, constraints=[cons], method="SLSQP",
                   options={"maxiter": 200, "ftol": 1e-10})
    y = res.x if res.success and np.isfinite(res.x).all() else y0
    e = np.exp(y)
    worst = float(((Mb @ e) / limits).max())
    if worst > 1.0:  # keep it feasible
        e = e / worst
    return E.T @ e


def _lp_max(A: np.ndarray, C: np.ndarray) -> np.ndarray:
    """``max c.x s.t. A x <= 1`` for every row c of C (floating point, HiGHS, all rows of
    C in one stacked LP); ``+inf`` where unbounded or not solved.

    The variables are scaled by exact powers of two, ``x = D z`` with the largest entry of
    every column of ``A D`` in [0.5, 1), so that the LP does not depend on the units of the
    states (a set a thousand times smaller gives HiGHS the same problem)."""
    from ..sets import _lp

    A = np.asarray(A, dtype=float)
    C = np.atleast_2d(np.asarray(C, dtype=float))
    K, n = C.shape
    _, e = np.frexp(np.abs(A).max(axis=0, initial=0.0))
    e = np.where(np.abs(A).max(axis=0, initial=0.0) > 0, e, 0).astype(np.int64)
    AD, CD = np.ldexp(A, -e[None, :]), np.ldexp(C, -e[None, :])
    m = A.shape[0]
    res = _lp.block_lp(-CD, np.tile(AD, (K, 1)), np.ones(K * m), np.repeat(np.arange(K), m))
    return np.where(res.status == _lp.OPTIMAL, -res.fun, np.inf)


def _unit_shapes(P: np.ndarray, Acl: np.ndarray, limits: np.ndarray, rows: np.ndarray
                 ) -> dict[str, tuple[np.ndarray | None, str]]:
    """The unit candidates ``A_unit`` of every shape (None with a reason when a shape is
    not available)."""
    n = P.shape[0]
    lam = np.linalg.eigvalsh(P)
    if not lam.min() > 1e-12 * lam.max():
        why = (f"the Lyapunov matrix P is not positive definite (eigenvalues "
               f"{lam.tolist()}); give a positive definite Q")
        out: dict[str, tuple[np.ndarray | None, str]] = {"ellipsoid": (None, why),
                                                          "parallelotope": (None, why)}
    else:
        V = _whitening(P)
        out = {"ellipsoid": (_unit_directions(n) @ V, "outer polytope of {dx' P dx <= 1}"),
               "parallelotope": (np.vstack([V, -V]), "box along the eigenvectors of P "
                                 "circumscribing {dx' P dx <= 1}")}
    modal = _real_modal(Acl)
    if modal is None:
        out["modal"] = (None, "the linearised closed loop is not diagonalisable (or its "
                              "modal matrix is ill-conditioned)")
    else:
        T, blocks = modal
        e = _modal_scaling(T, blocks, limits, rows)
        R = T / e[:, None]
        out["modal"] = (np.vstack([R, -R]), "box in the real modal coordinates of the "
                        "linearised closed loop")
    return out


def _contraction(Au: np.ndarray, Acl: np.ndarray) -> float:
    """``max_i max_{Au x <= 1} a_i Acl x``: the one-step factor of the linearisation."""
    return float(_lp_max(Au, Au @ Acl).max())


def _scale_limit(Au: np.ndarray, limits: np.ndarray, rows: np.ndarray) -> float:
    """The largest s with ``rows dx`` inside ``±limits`` on ``s * unit`` (each row
    symmetric: ``limits`` are the nearer margins)."""
    h = np.maximum(_lp_max(Au, rows), _lp_max(Au, -rows))
    with np.errstate(divide="ignore"):
        return float(np.min(np.where(h > 0, limits / h, np.inf)))


def _disturbance_floor(model: Model, Au: np.ndarray, Acl: np.ndarray, Wb: Box | None,
                       x_eq: np.ndarray, u_eq: np.ndarray, w_mid: np.ndarray) -> float:
    """The smallest s at which the linearisation absorbs the disturbances of W: every facet
    ``a_i`` needs ``gamma_i s + push_i <= s``, with ``gamma_i = max_{Au x <= 1} a_i Acl x``
    and ``push_i = max_w a_i E (w - w_mid)`` (both maxima are attained together: x and w
    vary independently), so the floor is ``max_i push_i / (1 - gamma_i)`` (0 for a nominal
    search; inf when a facet that W pushes out does not contract)."""
    if not model.l or Wb is None or np.array_equal(Wb.lo, Wb.hi):
        return 0.0
    gamma = _lp_max(Au, Au @ Acl)
    E = np.asarray(model.jacobian_function("w")(x_eq, u_eq, w_mid), dtype=float)
    dw = np.asarray(Wb.vertices(), dtype=float) - w_mid
    push = np.maximum((Au @ E @ dw.T).max(axis=1), 0.0)
    need = push > 0.0
    if (gamma[need] >= 1.0).any():
        return np.inf
    return float(np.max(push[need] / (1.0 - gamma[need]), initial=0.0))


# ------------------------------------------------------------------ the search
def terminal_set(model: Model, law: Any = None, *, W: Any = None, x_eq: Any = None,
                 u_eq: Any = None, shape: str = "auto", Q: Any = None, R: Any = None,
                 eps: float | None = None, max_scale: float | None = None, rtol: float = 0.05,
                 min_scale: float = 1e-3, max_candidates: int = 40,
                 max_boxes: int = 20_000, time_limit: float | None = None,
                 samples: int = 64, seed: int = 0,
                 progress: bool | None = None) -> TerminalSetResult:
    """The largest scaled Lyapunov sublevel polytope proven invariant under a local law.

    Candidates are ``S(s) = {x : A_unit (x - x_eq) <= s}``, polytopes shaped by a Lyapunov
    function of the closed loop linearised at the equilibrium, ``Acl = A + B K_lin``:

    * ``"ellipsoid"``: an outer polytope of the ellipsoid ``{dx' P dx <= s^2}``, P the
      quadratic Lyapunov matrix (``Acl' P Acl - P = -(Q + K_lin' R K_lin)``, the Riccati
      solution for the LQR law): in the coordinates ``z = V dx`` (``V' V = P``) its facets
      are ``d.z <= s`` for the unit vectors ``d`` = ±e_i and (±e_i ± e_j)/sqrt(2)
      (2 n^2 facets; a regular 16-gon for n = 2);
    * ``"parallelotope"``: the box ``|V dx|_inf <= s`` along the eigenvectors of P
      (2 n facets), circumscribing the same ellipsoid;
    * ``"modal"``: the box ``|D T dx|_inf <= s`` in the real modal coordinates ``T dx`` of
      ``Acl`` (2 n facets), the sublevel set of the polyhedral Lyapunov function
      ``|D T dx|_inf``; D (one scale per real mode or complex pair) maximises its volume
      inside X and U. For a real eigenvalue lambda the coordinate contracts by |lambda|,
      for a complex pair ``a ± ib`` by ``|a| + |b|``;
    * ``"auto"`` (default): every shape whose linearisation contracts (``contraction``
      below 1, see :class:`TerminalSetResult`) is searched, fewer facets first, and the
      proven set of largest volume is returned (when none contracts, the one that comes
      closest is searched).

    With small sampling times the quadratic shapes often do not contract in the polytope's
    facets even for the linearisation (their outer points leave the ellipsoid by more than
    one step shrinks it); ``result.contraction`` gives the factor of each shape.

    The scale is searched from the largest value X and U allow (``scale_limit``) down,
    halving its distance to the disturbance floor (0 for a nominal search; see ``stats``),
    until a candidate is proven, then by bisection (geometric mean) between the
    largest proven and the smallest failed scale until they are within ``rtol``. Each
    candidate must be proven by :func:`~casadi_cmpc.certify_invariant` (for every x in S
    and w in W: ``f(x, law(x), w) in S`` and ``law(x) in U``) and ``S ⊆ X`` by a rigorous
    bounding box; nothing else counts. Invariance need not be monotone in s (a robust
    search fails below the scale that absorbs W, and every search fails above the scale
    where the nonlinearity or U bites); the bisection assumes one proven interval of
    scales, and the answer is the largest scale *proven* on the way.

    Parameters
    ----------
    model : Model
        With at least one input; any number of states (n = 1, 2, 3, 4, ...).
    law : LinearLaw, array_like (m, n) or casadi.SX (m, 1), optional
        The local law (convention of :mod:`casadi_cmpc.control.law`). Default: the LQR law
        of the linearisation at ``(x_eq, u_eq)`` with the weights Q, R
        (:func:`~casadi_cmpc.local_lqr`).
    W : Box (l,), optional
        Disturbance box of the proof (default: the model's W, i.e. robust for a model with
        w). Pass a one-point box ``Box(w0, w0)`` for a nominal proof at ``w0``.
    x_eq : array_like (n,), optional
        Equilibrium state (state units). Default: the law's ``x_eq`` for a
        :class:`LinearLaw`, else the origin. Must lie inside X and be a fixed point of
        the closed loop at the centre of W.
    u_eq : array_like (m,), optional
        Equilibrium input (input units). Default: ``law(x_eq)`` (zeros when no law is
        given); when given with a law it must equal ``law(x_eq)``. Must lie inside U.
    shape : {"auto", "ellipsoid", "parallelotope", "modal"}
        See above.
    Q : array_like (n, n), optional
        State weight of the LQR law and of the Lyapunov equation. Default (Bryson's rule):
        ``diag(1 / d_x^2)``, ``d_x`` the distance from x_eq to the nearer bound of X per
        state.
    R : array_like (m, m), optional
        Input weight; default ``diag(1 / d_u^2)``, ``d_u`` the distance from u_eq to the
        nearer bound of U.
    eps : float, optional
        Resolution of each certification, relative to the candidate: pieces whose largest
        generator entry is at most ``eps`` times the largest half-width of the candidate's
        bounding box are not split. Default: 0.02 for the parallelotopes (the pieces are
        then sub-parallelotopes of S, split only to tighten the nonlinear terms) and
        ``(1 - contraction) / 4`` (within [0.002, 0.02]) for the ellipsoid's polytope (the
        pieces straddling its boundary must map inside it). ``max_boxes`` bounds the work
        per candidate either way.
    max_scale : float, optional
        Largest scale tried (default: the largest with ``S ⊆ X`` and ``K_lin S ⊆ U - u_eq``).
    rtol : float
        The bisection stops when ``failed / proven <= 1 + rtol``.
    min_scale : float
        Smallest scale tried, relative to ``scale_limit`` (the descent stops below it;
        also below the disturbance floor, see ``stats``).
    max_candidates : int
        Limit on the candidates certified.
    max_boxes : int
        Budget of each set inversion (pieces classified); a candidate over budget is
        undecided (not proven).
    time_limit : float, optional
        Wall-clock limit of the whole search in s; the best proven set so far is returned
        with status BUDGET.
    samples, seed
        Random points tried as counterexamples by each certification.
    progress : bool or None
        tqdm progress bar over the candidates (None: only for searches longer than 2 s).

    Returns
    -------
    TerminalSetResult
        ``terminal`` (the largest proven set, or None), ``scale``, ``certificate``,
        ``law``, ``x_eq``, ``u_eq``, ``W``, ``robust``, ``shape``, ``unit``, ``P``,
        ``contraction``, ``scale_limit``, ``candidates``, ``stop_reason``, ``status``.

    Raises
    ------
    TypeError
        ``model`` is not a Model.
    ModelError
        The model has no input.
    DimensionError
        The law, x_eq, u_eq, Q, R or W has the wrong shape.
    ValueError
        ``(x_eq, law(x_eq))`` is not an equilibrium at the centre of W; ``u_eq`` differs
        from ``law(x_eq)``; the given ``x_eq`` differs from the LinearLaw's; x_eq or u_eq
        is not inside the interior of X or U; the linearised closed loop is not stable
        (spectral radius >= 1); an unknown shape or a bad tolerance.

    Examples
    --------
    >>> import casadi as ca, numpy as np, casadi_cmpc as cm
    >>> x = ca.SX.sym("x", 2); u = ca.SX.sym("u")
    >>> f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * (u + ca.sin(x[0])))
    >>> model = cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-2], [2]))
    >>> res = cm.terminal_set(model, progress=False)
    >>> res.status.name, res.certificate.proved, res.shape, sorted(res.stats["searches"])
    ('PROVED', True, 'ellipsoid', ['ellipsoid', 'modal', 'parallelotope'])
    >>> round(res.scale, 4), res.stop_reason
    (1.8458, 'resolution')
    >>> cm.certify_invariant(model, res.terminal, res.law, eps=0.005).proved
    True
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from tqdm.auto import tqdm
    import scipy.linalg as sl

    t0 = time.perf_counter()
    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    if model.m == 0:
        raise ModelError(f"model '{model.name}' has no input to close the loop on")
    n, m = model.n, model.m
    shape = str(shape).lower()
    if shape not in ("auto",) + SHAPES:
        raise ValueError(f"shape must be one of auto, {', '.join(SHAPES)}; got {shape!r}")
    eps = None if eps is None else positive_eps(eps, "eps")
    if not (np.isfinite(rtol) and rtol > 0):
        raise ValueError(f"rtol must be a positive number; got {rtol}")
    if not (np.isfinite(min_scale) and 0 < min_scale < 1):
        raise ValueError(f"min_scale must be in (0, 1) (relative to the scale limit); got "
                         f"{min_scale}")
    if int(max_candidates) < 1:
        raise ValueError(f"max_candidates must be at least 1; got {max_candidates}")
    if max_scale is not None and not (np.isfinite(max_scale) and max_scale > 0):
        raise ValueError(f"max_scale must be a positive number; got {max_scale}")

    # ------------------------------------------------------- disturbance box
    if W is not None and not model.l:
        raise ModelError(f"model '{model.name}' has no disturbance w; W must be None")
    Wb = (_as_model_box(W, model.l, "W") if W is not None else model.W) if model.l else None
    w_mid = Wb.mid if Wb is not None else np.zeros(0)

    # ------------------------------------------------------- equilibrium and law
    bare = law is not None and not isinstance(law, (LinearLaw, ca.SX))
    if law is not None:
        law = as_law(law, m, n)  # DimensionError for a gain of the wrong shape
    if isinstance(law, LinearLaw):
        xe = _vector(x_eq, n, "x_eq", law.x_eq)
        if x_eq is not None and not np.allclose(xe, law.x_eq, rtol=1e-12, atol=1e-12):
            raise ValueError(
                f"x_eq = {xe.tolist()} differs from the law's x_eq = {law.x_eq.tolist()}; "
                + ("a bare gain K is the law u = K x about the origin: pass "
                   "cm.LinearLaw(K, x_eq, u_eq)" if bare else
                   "give one equilibrium (the law's)"))
    else:
        xe = _vector(x_eq, n, "x_eq", np.zeros(n))
    ue_given = None if u_eq is None else _vector(u_eq, m, "u_eq", np.zeros(m))
    dx = _margins(model.X, xe, "x_eq")
    if law is None:
        ue = ue_given if ue_given is not None else np.zeros(m)
        du = _margins(model.U, ue, "u_eq")
        Qm = _weight(Q, n, "Q", definite=False, default=np.diag(1.0 / dx ** 2))
        Rm = _weight(R, m, "R", definite=True, default=np.diag(1.0 / du ** 2))
        model.check_equilibrium(xe, ue, w_mid if model.l else None)
        law = local_lqr(model, Qm, Rm, x_eq=xe, u_eq=ue, w=w_mid if model.l else None)
    else:
        ue = np.asarray(_law_function(model, law)(xe), dtype=float).reshape(m)
        if ue_given is not None and not np.allclose(ue, ue_given, rtol=1e-9, atol=1e-12):
            raise ValueError(f"the law gives u = {ue.tolist()} at x_eq = {xe.tolist()}, not "
                             f"u_eq = {ue_given.tolist()}: pass the law designed at this "
                             "equilibrium (e.g. cm.LinearLaw(K, x_eq, u_eq)) or leave u_eq out")
        du = _margins(model.U, ue, "law(x_eq)")
        Qm = _weight(Q, n, "Q", definite=False, default=np.diag(1.0 / dx ** 2))
        Rm = _weight(R, m, "R", definite=True, default=np.diag(1.0 / du ** 2))
        model.check_equilibrium(xe, ue, w_mid if model.l else None, names="x_eq, law(x_eq)")

    # ------------------------------------------------------- linearisation
    A = np.asarray(model.jacobian_function("x")(xe, ue, w_mid), dtype=float)
    B = np.asarray(model.jacobian_function("u")(xe, ue, w_mid), dtype=float)
    K = _linear_gain(model, law, xe)
    Acl = A + B @ K
    radius = float(np.abs(np.linalg.eigvals(Acl)).max())
    if not radius < 1.0:
        raise ValueError(f"the law does not stabilise the linearisation of '{model.name}' at "
                         f"x_eq = {xe.tolist()}: spectral radius of A + B K is {radius:.6g} "
                         ">= 1, so no sublevel set around x_eq is invariant; give a "
                         "stabilising law (e.g. cm.local_lqr)")
    P = sl.solve_discrete_lyapunov(Acl.T, Qm + K.T @ Rm @ K)
    P = 0.5 * (P + P.T)
    rows = np.vstack([np.eye(n), K])  # x inside X, K_lin dx inside U - u_eq
    limits = np.concatenate([dx, du])
    shapes = _unit_shapes(P, Acl, limits, rows)
    contraction = {k: (_contraction(Au, Acl) if Au is not None else np.inf)
                   for k, (Au, _) in shapes.items()}
    if shape == "auto":
        order = sorted((k for k in SHAPES if shapes[k][0] is not None),
                       key=lambda k: (shapes[k][0].shape[0], contraction[k]))
        if not order:
            raise ValueError("no candidate shape is available: " + "; ".join(
                f"{k}: {why}" for k, (_, why) in shapes.items()))
        todo = [k for k in order if contraction[k] < 1.0] or [
            min(order, key=lambda k: contraction[k])]
    else:
        if shapes[shape][0] is None:
            raise ValueError(f"shape '{shape}' is not available here: {shapes[shape][1]}")
        todo = [shape]
    robust = bool(model.l) and Wb is not None and not np.array_equal(Wb.lo, Wb.hi)
    what = (f"robustly for every w in [{Wb.lo.tolist()}, {Wb.hi.tolist()}]" if robust else
            f"nominally at w = {Wb.lo.tolist()} only" if Wb is not None
            else "(no disturbance)")

    # ------------------------------------------------------- the searches
    closed = _closed(model, law)
    budget = {"candidates": int(max_candidates), "t0": t0, "time_limit": time_limit}
    bar = tqdm(total=None, desc="terminal set", unit="candidate",
               disable=progress is False, delay=0 if progress else 2.0, leave=False)
    scope = InterruptScope()
    runs: dict[str, dict] = {}
    cands: list[dict] = []
    interrupted = False
    try:
        for k in todo:
            Au = shapes[k][0]
            gamma = contraction[k]
            if eps is None:
                e_rel = 0.02 if _is_parallelotope(Au) else float(
                    np.clip((1.0 - gamma) / 4.0, 2e-3, 0.02))
            else:
                e_rel = eps
            limit = _scale_limit(Au, limits, rows) * (1.0 - 1e-9)
            if max_scale is not None:
                limit = min(limit, float(max_scale))
            floor = _disturbance_floor(model, Au, Acl, Wb, xe, ue, w_mid)
            run = runs[k] = {"best": None, "stop": "", "eps": e_rel, "scale_limit": limit,
                             "min_scale": max(limit * float(min_scale), floor),
                             "disturbance_floor": floor, "unit_volume": _unit_volume(Au)}
            _search(model, closed, law, Au, xe, Wb, run, rtol, max_boxes, samples, seed,
                    budget, cands, bar, k)
            if run["stop"] in ("time_limit", "max_candidates"):
                break
    except KeyboardInterrupt:
        scope.reraise_if_nested()
        # the proven sets found so far are kept (each was proven before the interruption)
        for r in runs.values():
            r["stop"] = r["stop"] or "interrupted"
        interrupted = True
    finally:
        scope.close()
        bar.close()

    # ------------------------------------------------------- the answer
    done = runs
    proven = {k: r for k, r in done.items() if r["best"] is not None}
    if proven:
        chosen = max(proven, key=lambda k: proven[k]["unit_volume"]
                     * proven[k]["best"][0] ** n)
    else:
        chosen = next(iter(done), todo[0])
    run = done.get(chosen, {"stop": "interrupted", "best": None, "scale_limit": 0.0})
    stops = [r["stop"] for r in runs.values()]
    if interrupted:
        stop = "interrupted"
    elif any(s_ in ("time_limit", "max_candidates") for s_ in stops):
        stop = next(s_ for s_ in stops if s_ in ("time_limit", "max_candidates"))
    else:
        stop = run["stop"]
    if stop in ("interrupted", "time_limit", "max_candidates"):
        status = Status.BUDGET
    elif proven:
        status = Status.PROVED
    else:
        status = Status.UNDECIDED
    elapsed = time.perf_counter() - t0
    counts = {v: sum(c["verdict"] == v for c in cands)
              for v in ("proved", "refuted", "undecided", "outside X")}
    stats = {"proved": counts["proved"], "refuted": counts["refuted"],
             "undecided": counts["undecided"], "outside_X": counts["outside X"],
             "seconds": elapsed,
             "certify_seconds": float(sum(c["seconds"] for c in cands)),
             "searches": {k: {kk: vv for kk, vv in r.items() if kk != "best"}
                          | {"scale": 0.0 if r["best"] is None else r["best"][0]}
                          for k, r in done.items()}}
    if chosen in done:
        stats["min_scale"] = done[chosen]["min_scale"]
        stats["disturbance_floor"] = done[chosen]["disturbance_floor"]
    why = {"resolution": f"the proven and the failed scale are within rtol = {rtol}",
           "scale_limit": "the largest scale X, U and max_scale allow is proven",
           "min_scale": "no candidate proven down to the smallest scale "
                        f"{run.get('min_scale', 0.0):.6g}" + (
                            f" (the linearisation absorbs W only from "
                            f"{run['disturbance_floor']:.6g})"
                            if run.get("disturbance_floor", 0.0) > 0 else ""),
           "max_boxes": (f"{_MAX_OVER_BUDGET} candidates in a row undecided with "
                         f"max_boxes = {max_boxes} spent (try a larger max_boxes or "
                         "another shape)"),
           "time_limit": f"time_limit = {time_limit} s reached",
           "max_candidates": f"max_candidates = {max_candidates} reached",
           "interrupted": "interrupted"}[stop]
    tried = ", ".join(f"{k} (contraction {contraction[k]:.4g})" for k in done) or "none"
    if run["best"] is None:
        message = (f"no candidate proven invariant {what} ({len(cands)} tried: "
                   f"{counts['refuted']} refuted, {counts['undecided']} undecided, "
                   f"{counts['outside X']} not inside X; shapes searched: {tried}); "
                   f"stopped: {why}")
        terminal, scale, cert = None, 0.0, None
    else:
        scale, terminal, cert = run["best"]
        message = (f"{chosen} set of scale {scale:.6g} proven invariant {what} under the "
                   f"law, inside X, with the law inside U ({len(cands)} candidates; shapes "
                   f"searched: {tried}; scale limit {run['scale_limit']:.6g}); stopped: "
                   f"{why}")
    Au = shapes[chosen][0]
    return TerminalSetResult(
        status=status, message=message, method=f"scaled {chosen} sublevel sets, "
        "certify_invariant (Alg 4.3) per candidate", nit=len(cands), n_boxes=len(cands),
        elapsed=elapsed, terminal=terminal, scale=float(scale), certificate=cert,
        law=law, x_eq=xe, u_eq=ue, W=Wb, robust=robust, shape=chosen,
        unit=Polytope(Au, np.ones(Au.shape[0])), P=P,
        contraction={k: float(v) for k, v in contraction.items()},
        scale_limit=float(run.get("scale_limit", 0.0)), candidates=cands,
        stop_reason=stop, stats=stats)


def _is_parallelotope(Au: np.ndarray) -> bool:
    """2 n rows in opposite pairs (the certification's domain is then S itself)."""
    n = Au.shape[1]
    return Au.shape[0] == 2 * n and np.array_equal(Au[n:], -Au[:n])


def _unit_volume(Au: np.ndarray) -> float:
    """Volume of ``{dx : Au dx <= 1}`` (floating point)."""
    if _is_parallelotope(Au):
        n = Au.shape[1]
        return float(2.0 ** n / abs(np.linalg.det(Au[:n])))
    return Polytope(Au, np.ones(Au.shape[0])).volume()


def _search(model: Model, closed: Any, law: Any, Au: np.ndarray, xe: np.ndarray,
            Wb: Box | None, run: dict, rtol: float, max_boxes: int, samples: int,
            seed: int, budget: dict, cands: list, bar: Any, shape: str) -> None:
    """Descent by halving from ``run["scale_limit"]`` to the first proven scale, then
    bisection (down to ``run["min_scale"]``, at the relative resolution ``run["eps"]``);
    the candidates are appended to ``cands``, ``run["best"]`` ((scale, S, certificate) or
    None) and ``run["stop"]`` are kept up to date (an interruption leaves them valid)."""
    n = model.n
    t0, time_limit = budget["t0"], budget["time_limit"]
    limit, lowest, eps = run["scale_limit"], run["min_scale"], run["eps"]
    failed: float | None = None

    def test(s: float) -> bool:
        t1 = time.perf_counter()
        S = Polytope(Au, s * np.ones(Au.shape[0]) + Au @ xe)
        _check_target(S, n)
        bb = S.bounding_box()  # rigorous
        if not (np.all(bb.lo >= model.X.lo) and np.all(bb.hi <= model.X.hi)):
            cands.append({"shape": shape, "scale": s, "verdict": "outside X", "reason": (
                f"S is not proven inside X: its bounding box is [{bb.lo.tolist()}, "
                f"{bb.hi.tolist()}]"), "seconds": time.perf_counter() - t1})
            return False
        left = None if time_limit is None else max(time_limit - (t1 - t0), 1e-3)
        e_abs = eps * float(np.max(0.5 * (bb.hi - bb.lo)))
        cert = _certify(model, closed, S, e_abs, Wb, max_boxes, left, samples, seed, False,
                        law=law)
        verdict = {True: "proved", False: "refuted", None: "undecided"}[cert.proved]
        cands.append({"shape": shape, "scale": s, "verdict": verdict, "reason": cert.reason,
                      "seconds": time.perf_counter() - t1})
        over = cert.proved is None and any(
            isinstance(v, dict) and v.get("status") == "BUDGET"
            for v in cert.details.values())
        run["over_budget"] = run.get("over_budget", 0) + 1 if over else 0
        if cert.proved is True and (run["best"] is None or s > run["best"][0]):
            run["best"] = (s, S, cert)
        if not bar.disable:
            best = run["best"]
            bar.update(1)
            bar.set_postfix(shape=shape, scale=f"{s:.4g}",
                            best=0.0 if best is None else f"{best[0]:.4g}", refresh=False)
        return cert.proved is True

    def out_of_budget() -> str:
        if len(cands) >= budget["candidates"]:
            return "max_candidates"
        if time_limit is not None and time.perf_counter() - t0 > time_limit:
            return "time_limit"
        return ""

    floor = run["disturbance_floor"]
    stop = "" if lowest < limit else "min_scale"
    s = limit
    while not stop:  # descent: the distance to the disturbance floor (or 0) halved
        stop = out_of_budget()
        if stop:
            break
        if test(s):
            if failed is None:
                stop = "scale_limit"
            break
        failed = s
        s = floor + 0.5 * (s - floor)
        if s < lowest or (floor > 0 and s <= floor * (1.0 + rtol)):
            stop = "min_scale"
        elif run.get("over_budget", 0) >= _MAX_OVER_BUDGET:
            stop = "max_boxes"
    while not stop and run["best"] is not None and failed is not None:  # bisection
        if failed / run["best"][0] <= 1.0 + rtol:
            stop = "resolution"
            break
        stop = out_of_budget()
        if stop:
            break
        s = float(np.sqrt(run["best"][0] * failed))
        if not test(s):
            failed = s
    run["stop"] = stop
