"""Linear contractive MPC with a compulsory contractive constraint, as one LP (thesis §3.3).

For ``x(i+1) = A x(i) + B u(i)`` with an equilibrium ``(x_ref, u_ref)``, the problem
(3.5)–(3.6) with the norm replaced by a gauge ``γ`` (1-norm, ∞-norm or the Minkowski
functional of a polytope around ``x_ref``) reads

    min  ξ   over u(0), ..., u(N-1), ξ
    s.t. u(i) ∈ U                  i = 0, ..., N-1
         x(i) ∈ X                  i = 1, ..., N
         H x(N) <= h               (optional terminal polytope S)
         Gx x(i) + Gu u(i) <= g    i = 0, ..., N-1 (optional path constraints)
         γ(x(N) - x_ref) <= ξ <= α γ(x0 - x_ref),        α ∈ (0, 1].

:class:`ContractiveLP` builds the constant matrices of this LP once per (model, horizon)
and solves it for a given ``x0`` with one call of HiGHS
(``scipy.optimize.linprog(method="highs")``); only the bounds and right-hand sides depend
on ``x0``.

Numerics
--------
* **Formulation.** The predicted states are kept as variables linked by the dynamics as
  equality rows (no condensing): the matrix then holds the entries of ``A`` and ``B``
  themselves, stays sparse and well conditioned for long horizons and unstable ``A``,
  and the same rows serve the exact infeasibility proof.
* **Scaling.** The LP runs in the deviation coordinates ``(x - x_ref, u - u_ref, ξ)``
  divided by ``σ = γ(x0 - x_ref)``: the contraction bound becomes ``ξ <= α`` whatever the
  distance to ``x_ref``, so HiGHS's absolute tolerances (``1e-10``) are relative to
  ``σ``. The matrices do not change with ``σ`` (the dynamics are homogeneous in the
  deviations); only bounds and right-hand sides do.
* **Back-off (inward).** In the LP every state bound is moved *inward* by
  ``backoff · max(width of X, σ)``, each terminal and path row by
  ``backoff · max(its range over X (× U), σ ||row||_1)``, and the contraction bound
  ``α σ`` is lowered by ``backoff · σ`` (by at most half of it): the LP's solution lies
  strictly inside the true constraints by more than HiGHS's tolerance (``1e-10`` in the
  scaled units), so the returned sequence (clipped into U exactly) passes an exact
  re-check even where a constraint is active.
  The re-check is done in rational arithmetic and reported as ``LPStep.verified``.
* **Caps.** Scaled bounds are clipped to ``±1e12`` (deviations beyond ``1e12 γ(x0)`` are
  not explored). When the optimal sequence fails the exact re-check (near ``x_ref`` a
  degenerate optimum may swing far from ``x0`` and lose the contraction to rounding), the
  LP is solved once more with deviations capped at ``1e3 γ(x0)``. Both are restrictions
  of the LP: a returned sequence is still checked exactly and a proof of infeasibility
  never uses them (a certificate computed with them simply fails the exact check).
* **Infeasibility is proven, not reported.** When HiGHS finds the (backed-off) LP
  infeasible, a phase-1 LP on the *un*-tightened constraints (every row relaxed by
  ``t >= 0``, minimise ``t``) is solved (a second HiGHS call). Its multipliers ``y >= 0``
  of the inequality rows, read as exact fractions, define the certificate; the
  multipliers ``λ`` of the dynamics are computed from ``y`` exactly (backwards through
  the horizon) so that the combination vanishes on every predicted state, and the
  remaining inequality is checked in :class:`fractions.Fraction` arithmetic on the float
  data. When rounding of ``y`` spoils the check (near ``x_ref``, where the margin is tiny
  beside the width of U), ``y`` is projected exactly onto the null space of the
  coefficients that should vanish and checked again. Only a passing check gives
  ``status == "infeasible"``; see :meth:`ContractiveLP.solve` for what is proven.
* **Limits.** ``γ(x0 - x_ref)`` must be a normal float that can be inverted (above about
  ``1e-308``); a problem that is feasible only with equality in the contraction (or only
  inside the back-off) gives ``"failed"``: the strict (3.6) is then infeasible but the
  certificate proves the non-strict problem only.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from fractions import Fraction
from numbers import Integral, Real
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from .._validate import as_float_array
from ..exceptions import DimensionError, InvalidBoundsError, ModelError
from ..sets._exact import rat_nullspace
from ..sets._lp import HIGHS_OPTIONS, OPTIMAL, block_lp
from ..sets.box import Box
from ..sets.polytope import Polytope

__all__: list[str] = []

#: Relative tolerance of the equilibrium test ``A x_ref + B u_ref == x_ref``.
EQUILIBRIUM_RTOL = 1e-12

#: Largest magnitude of a scaled bound or right-hand side passed to HiGHS: deviations
#: from (x_ref, u_ref) beyond 1e12 gamma(x0) are not explored (a restriction, so sound).
_BOUND_CAP = 1e12
#: Cap of the retry when the first optimal sequence fails the exact re-check.
_RETRY_CAP = 1e3
_HUGE = float(np.finfo(float).max)

_F0 = Fraction(0)


@dataclass(frozen=True)
class LPStep:
    """Result of one contractive LP (thesis (3.5)–(3.6)) for one initial state.

    Attributes
    ----------
    status : str
        ``"optimal"`` (HiGHS solved the backed-off LP), ``"infeasible"`` (proven by an
        exactly checked Farkas certificate, see ``proof``) or ``"failed"`` (no answer:
        solver trouble, or HiGHS said infeasible but no certificate could be checked).
    u_seq : ndarray, shape (N, m), or None
        Optimal controls ``u(0), ..., u(N-1)``, clipped into U (exact). None unless optimal.
    x_pred : ndarray, shape (N + 1, n), or None
        ``x(0) = x0, x(1), ..., x(N)`` simulated in floating point from ``u_seq``.
    xi : float
        LP optimum ``ξ`` (units of the gauge: ``γ(x(N) - x_ref)``); NaN unless optimal.
    xi_bound : float
        The contraction bound ``α γ(x0 - x_ref)`` in floating point.
    verified : bool
        True when ``u_seq`` was re-simulated in exact rational arithmetic from ``x0`` and
        satisfies every constraint exactly: ``u(i) ∈ U``, ``x(i) ∈ X`` (i >= 1), the
        terminal and path rows, and ``γ(x(N) - x_ref) < α γ(x0 - x_ref)`` (strict, as in
        (3.6); ``x(N) = x_ref`` when ``x0 = x_ref``), all on the given float data taken as
        exact numbers. False otherwise (always False unless optimal).
    proof : dict or None
        For ``"infeasible"``: the checked Farkas certificate, else None. Keys:
        ``kind`` (``"farkas"``), ``statement`` (what is proven), ``margin`` (a float
        lower bound of the exact gap ``min_{z ∈ Z} r.z - β > 0``), ``xi_bound`` (the
        contraction bound ``α γ(x0 - x_ref)`` rounded up), ``y_exact`` (dict row index ->
        Fraction: the certificate), ``y`` (its floats, shape ``(R,)``), ``lam`` (the
        dynamics multipliers, floats, shape ``(N n,)``), ``rows`` (labels of the rows with
        ``y > 0``, e.g. ``"x(3)[1] <= X.hi"``, ``"contraction xi <= alpha*gamma(x0)"``).
    elapsed : float
        Wall-clock time of :meth:`ContractiveLP.solve`, seconds.
    message : str
        HiGHS's message, or why the step failed or is not verified.
    """

    status: str
    u_seq: np.ndarray | None
    x_pred: np.ndarray | None
    xi: float
    xi_bound: float
    verified: bool
    proof: dict | None
    elapsed: float
    message: str

    @property
    def success(self) -> bool:
        """True when ``status == "optimal"`` and the sequence is ``verified``."""
        return self.status == "optimal" and self.verified


def _matrix(M: Any, name: str, rows: int | None = None, cols: int | None = None) -> np.ndarray:
    arr = as_float_array(M, name)
    if arr.ndim != 2:
        raise DimensionError(f"{name} must be a 2-D array; got shape {arr.shape}")
    if rows is not None and arr.shape[0] != rows:
        raise DimensionError(
            f"{name} has the wrong number of rows; expected {rows} instead of {arr.shape[0]}")
    if cols is not None and arr.shape[1] != cols:
        raise DimensionError(
            f"{name} has the wrong number of columns; expected {cols} instead of "
            f"{arr.shape[1]}")
    if not np.isfinite(arr).all():
        raise InvalidBoundsError(f"{name} contains NaN or an infinite entry")
    return np.array(arr, dtype=float)


def _vector(v: Any, name: str, size: int) -> np.ndarray:
    arr = as_float_array(v, name)
    if arr.ndim > 1 or arr.size != size:
        raise DimensionError(f"{name} must have shape ({size},); got {arr.shape}")
    arr = np.array(arr, dtype=float).reshape(size)
    if not np.isfinite(arr).all():
        raise InvalidBoundsError(f"{name} contains NaN or an infinite entry")
    return arr


def _box(S: Any, name: str, dim: int) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(S, Box):
        raise TypeError(f"{name} must be a casadi_cmpc.Box; got {type(S).__name__}")
    if S.dim != dim:
        raise DimensionError(f"{name} has the wrong dimension; expected {dim} instead of {S.dim}")
    lo, hi = np.asarray(S.lo, dtype=float), np.asarray(S.hi, dtype=float)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise InvalidBoundsError(
            f"{name} must be bounded (thesis §3.3: X and U are compact); got lo = {lo}, "
            f"hi = {hi}")
    return lo.copy(), hi.copy()


def _halfspaces(P: Polytope, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``P`` that constrain anything (finite b, non-zero a); refuses empty rows."""
    A, b = np.asarray(P.A, dtype=float), np.asarray(P.b, dtype=float)
    zero = ~np.any(A != 0.0, axis=1)
    if np.any(b == -np.inf) or np.any(zero & (b < 0)):
        raise ValueError(f"{name} is empty (a row 0.x <= b < 0 or b = -inf)")
    keep = np.isfinite(b) & ~zero
    return A[keep].copy(), b[keep].copy()


def _frac_up(v: Fraction) -> float:
    f = float(v)
    if Fraction(f) < v:
        f = math.nextafter(f, math.inf)
    return f


def _frac_down(v: Fraction) -> float:
    f = float(v)
    if Fraction(f) > v:
        f = math.nextafter(f, -math.inf)
    return f


def _fr(a: np.ndarray) -> list:
    """Nested lists of exact Fractions of a float array."""
    if a.ndim == 1:
        return [Fraction(float(v)) for v in a]
    return [_fr(r) for r in a]


def _dot(row: list[Fraction], x: list[Fraction]) -> Fraction:
    return sum((a * v for a, v in zip(row, x, strict=True) if a), _F0)


class ContractiveLP:
    """The LP (3.5)–(3.6) of linear contractive MPC for one horizon, built once.

    Parameters
    ----------
    A : array_like, shape (n, n)
        State matrix of ``x(i+1) = A x(i) + B u(i)``.
    B : array_like, shape (n, m)
        Input matrix.
    X : Box, dimension n
        State constraints ``x(i) ∈ X`` for i = 1..N (bounded).
    U : Box, dimension m
        Input constraints ``u(i) ∈ U`` for i = 0..N-1 (bounded).
    horizon : int
        ``N >= 1`` (the thesis' ``M_f``).
    alpha : float
        Contraction parameter ``α ∈ (0, 1]``.
    gauge : {1, numpy.inf} or Polytope
        The distance to ``x_ref``: the 1-norm, the ∞-norm, or the gauge (Minkowski
        functional) of a bounded polytope ``P = {x : P x <= p}`` holding ``x_ref`` strictly
        inside, ``γ(x) = max(0, max_i P_i (x - x_ref) / (p_i - P_i x_ref))`` (the 0 only
        matters for unbounded sets, which are refused); its unit level set
        ``{γ <= 1}`` is ``P`` itself (for ``x_ref = 0``: ``max_i P_i x / p_i``, and for
        ``p = 1`` the ``P x(N) <= ξ`` of (3.6)).
    x_ref : array_like, shape (n,), optional
        Equilibrium state (default the origin), inside X.
    u_ref : array_like, shape (m,), optional
        Equilibrium input (default the origin), inside U;
        ``A x_ref + B u_ref = x_ref`` must hold up to a relative ``1e-12``.
    terminal : Polytope, optional
        Terminal constraint ``x(N) ∈ S = {H x <= h}``.
    path : tuple (Gx, Gu, g), optional
        Path constraints ``Gx x(i) + Gu u(i) <= g`` for i = 0..N-1; shapes (k, n), (k, m),
        (k,).
    backoff : float
        Relative inward tightening of the LP's constraints (default ``1e-9``; see the
        module notes), in ``[0, 0.01]``.

    Raises
    ------
    ValueError
        ``alpha`` outside (0, 1]; ``horizon < 1``; ``x_ref`` not an equilibrium (the
        message gives the residual); ``x_ref``/``u_ref`` outside X/U; a gauge polytope that
        does not hold ``x_ref`` strictly inside or is unbounded; an empty terminal set.
    DimensionError
        A matrix, vector, box or polytope of the wrong shape (a ``ValueError``).
    TypeError
        X or U not a Box, terminal or gauge of the wrong type.

    Notes
    -----
    Thesis §3.3, problem (3.5)–(3.6); the horizon search of §3.3.2 calls :meth:`solve`
    for increasing N. The strict contraction ``<`` of (3.6) is obtained through the
    back-off; the infeasibility proof is for the non-strict (larger) problem, hence
    also for the strict one.

    Examples
    --------
    >>> import numpy as np
    >>> import casadi_cmpc as cm
    >>> from casadi_cmpc.mpc.linear import ContractiveLP
    >>> lp = ContractiveLP([[0.9, 0.1], [-0.5, 0.2]], [[0.0], [1.0]],
    ...                    cm.Box([-8, -8], [8, 8]), cm.Box([-2], [2]), horizon=3,
    ...                    alpha=0.9, gauge=np.inf)
    >>> step = lp.solve([3.0, 3.0])
    >>> step.status, step.verified, step.u_seq.shape
    ('optimal', True, (3, 1))
    """

    def __init__(self, A: Any, B: Any, X: Box, U: Box, horizon: int, alpha: float,
                 gauge: Any, x_ref: Any = None, u_ref: Any = None,
                 terminal: Polytope | None = None,
                 path: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                 backoff: float = 1e-9) -> None:
        A = _matrix(A, "A")
        n = A.shape[0]
        if A.shape != (n, n) or n == 0:
            raise DimensionError(f"A must be square (n, n) with n >= 1; got shape {A.shape}")
        B = _matrix(B, "B", rows=n)
        m = B.shape[1]
        if m == 0:
            raise DimensionError("B must have at least one column (m >= 1)")
        if isinstance(horizon, bool) or not isinstance(horizon, Integral):
            raise TypeError(f"horizon must be an integer; got {horizon!r}")
        N = int(horizon)
        if N < 1:
            raise ValueError(f"horizon must be >= 1; got {N}")
        if isinstance(alpha, bool) or not isinstance(alpha, Real):
            raise TypeError(f"alpha must be a real number; got {alpha!r}")
        alpha = float(alpha)
        if not (0.0 < alpha <= 1.0):
            raise ValueError(f"alpha must lie in (0, 1] (thesis (3.6)); got {alpha}")
        if isinstance(backoff, bool) or not isinstance(backoff, Real) or \
                not (0.0 <= float(backoff) <= 0.01):
            raise ValueError(f"backoff must be a number in [0, 0.01]; got {backoff!r}")
        backoff = float(backoff)
        xlo, xhi = _box(X, "X", n)
        ulo, uhi = _box(U, "U", m)
        x_ref = np.zeros(n) if x_ref is None else _vector(x_ref, "x_ref", n)
        u_ref = np.zeros(m) if u_ref is None else _vector(u_ref, "u_ref", m)
        res = A @ x_ref + B @ u_ref - x_ref
        scale = float(np.max(np.abs(A) @ np.abs(x_ref) + np.abs(B) @ np.abs(u_ref)
                             + np.abs(x_ref)))
        if float(np.max(np.abs(res))) > EQUILIBRIUM_RTOL * scale:
            raise ValueError(
                f"(x_ref, u_ref) is not an equilibrium: A x_ref + B u_ref - x_ref = {res} "
                f"(max {float(np.max(np.abs(res))):.3g} > {EQUILIBRIUM_RTOL:g} x "
                f"{scale:.3g}); give u_ref with A x_ref + B u_ref = x_ref")
        if np.any(x_ref < xlo) or np.any(x_ref > xhi):
            raise ValueError(f"x_ref = {x_ref} lies outside X = [{xlo}, {xhi}]")
        if np.any(u_ref < ulo) or np.any(u_ref > uhi):
            raise ValueError(f"u_ref = {u_ref} lies outside U = [{ulo}, {uhi}]")

        # gauge
        if isinstance(gauge, Polytope):
            if gauge.dim != n:
                raise DimensionError(
                    f"gauge polytope has the wrong dimension; expected {n} instead of "
                    f"{gauge.dim}")
            P, p = _halfspaces(gauge, "gauge polytope")
            Pf, pf, xr = _fr(P), _fr(p), _fr(x_ref)
            q_ex = [pi - _dot(row, xr) for row, pi in zip(Pf, pf, strict=True)]
            bad = [i for i, q in enumerate(q_ex) if q <= 0]
            if bad:
                i = bad[0]
                raise ValueError(
                    f"the gauge polytope must hold x_ref = {x_ref} strictly inside; row {i} "
                    f"gives P_i x_ref - p_i = {float(-q_ex[i]):.6g} >= 0. Translate the "
                    "polytope or choose x_ref inside it")
            if P.shape[0] < n + 1 or not gauge.is_bounded():
                raise ValueError("the gauge polytope must be bounded (a gauge that vanishes "
                                 "on a direction does not measure the distance to x_ref)")
            kind = "poly"
            Pn_ex = [[a / q for a in row] for row, q in zip(Pf, q_ex, strict=True)]
            Pn = np.array([[float(v) for v in row] for row in Pn_ex])
        elif not isinstance(gauge, (bool, str)) and isinstance(gauge, Real) and gauge == 1:
            kind, Pn, Pn_ex = "l1", None, None
        elif not isinstance(gauge, (bool, str)) and isinstance(gauge, Real) and \
                gauge == math.inf:
            kind, Pn, Pn_ex = "linf", None, None
        else:
            raise ValueError(
                f"gauge must be 1 (1-norm), numpy.inf (inf-norm) or a Polytope; got {gauge!r}")

        # terminal and path rows
        if terminal is not None:
            if not isinstance(terminal, Polytope):
                raise TypeError(f"terminal must be a Polytope; got {type(terminal).__name__}")
            if terminal.dim != n:
                raise DimensionError(
                    f"terminal has the wrong dimension; expected {n} instead of {terminal.dim}")
            H, h = _halfspaces(terminal, "terminal set")
        else:
            H, h = np.zeros((0, n)), np.zeros(0)
        if path is not None:
            if not isinstance(path, (tuple, list)) or len(path) != 3:
                raise TypeError("path must be a tuple (Gx, Gu, g)")
            Gx = _matrix(path[0], "path Gx", cols=n)
            k = Gx.shape[0]
            Gu = _matrix(path[1], "path Gu", rows=k, cols=m)
            g = as_float_array(path[2], "path g")
            if g.ndim != 1 or g.size != k:
                raise DimensionError(f"path g must have shape ({k},); got {g.shape}")
            if np.isnan(g).any() or np.any(g == -np.inf):
                raise InvalidBoundsError("path g contains NaN or -inf")
            keep = np.isfinite(g)
            Gx, Gu, g = Gx[keep], Gu[keep], np.array(g[keep], dtype=float)
        else:
            Gx, Gu, g = np.zeros((0, n)), np.zeros((0, m)), np.zeros(0)

        self.A, self.B, self.n, self.m, self.horizon = A, B, n, m, N
        self.alpha, self.backoff, self.kind = alpha, backoff, kind
        self.x_ref, self.u_ref = x_ref, u_ref
        self.xlo, self.xhi, self.ulo, self.uhi = xlo, xhi, ulo, uhi
        self.H, self.h, self.Gx, self.Gu, self.g = H, h, Gx, Gu, g
        self._Pn, self._Pn_ex = Pn, Pn_ex
        self._exact: dict[str, Any] | None = None
        self._build()

    # ------------------------------------------------------------------ building
    def _build(self) -> None:
        A, B, n, m, N = self.A, self.B, self.n, self.m, self.horizon
        nx = (N + 1) * n
        iu = nx
        ixi = iu + N * m
        ns = n if self.kind == "l1" else 0
        nv = ixi + 1 + ns
        self._iu, self._ixi, self._nv = iu, ixi, nv

        # dynamics: x(i+1) - A x(i) - B u(i) = 0 (i = 0..N-1)
        ar, ac = np.nonzero(A)
        br, bc = np.nonzero(B)
        steps = np.arange(N)
        rows = [np.arange(N * n),
                (steps[:, None] * n + ar[None]).ravel(),
                (steps[:, None] * n + br[None]).ravel()]
        cols = [n + np.arange(N * n),
                (steps[:, None] * n + ac[None]).ravel(),
                (iu + steps[:, None] * m + bc[None]).ravel()]
        data = [np.ones(N * n), np.tile(-A[ar, ac], N), np.tile(-B[br, bc], N)]
        self._E = sp.csr_matrix((np.concatenate(data), (np.concatenate(rows),
                                                         np.concatenate(cols))),
                                shape=(N * n, nv))

        # inequality rows shared by the LP and the phase-1 LP: terminal, path, gauge
        blocks: list[sp.spmatrix] = []
        off: list[np.ndarray] = []  # g - G z_ref (right-hand side in deviation coordinates)
        rng: list[np.ndarray] = []  # range of each row over X (x U): scale of its back-off
        labels: list[str] = []
        xN = N * n
        H, h = self.H, self.h
        if H.shape[0]:
            blocks.append(_place(H, xN, nv))
            off.append(h - H @ self.x_ref)
            rng.append(h - _box_min(H, self.xlo, self.xhi))
            labels += [f"terminal row {k}" for k in range(H.shape[0])]
        Gx, Gu, g = self.Gx, self.Gu, self.g
        kP = Gx.shape[0]
        if kP:
            for i in range(N):
                blocks.append(_place(Gx, i * n, nv) + _place(Gu, iu + i * m, nv))
                off.append(g - Gx @ self.x_ref - Gu @ self.u_ref)
                rng.append(g - _box_min(Gx, self.xlo, self.xhi)
                           - _box_min(Gu, self.ulo, self.uhi))
                labels += [f"path row {k} at i={i}" for k in range(kP)]
        eye = np.eye(n)
        if self.kind == "linf":  # ±(x_j(N) - x_ref_j) - ξ <= 0
            D = np.vstack([eye, -eye])
            blk = _place(D, xN, nv) + _place(-np.ones((2 * n, 1)), ixi, nv)
            labels += [f"inf-norm row {s}{j}" for s in "+-" for j in range(n)]
        elif self.kind == "l1":  # ±(x_j(N) - x_ref_j) - s_j <= 0 ; sum s - ξ <= 0
            D = np.vstack([eye, -eye])
            blk = sp.vstack([_place(D, xN, nv) + _place(-np.vstack([eye, eye]), ixi + 1, nv),
                             _place(np.hstack([[-1.0], np.ones(n)])[None], ixi, nv)])
            labels += [f"1-norm row {s}{j}" for s in "+-" for j in range(n)] + ["1-norm sum"]
        else:  # (P_i / q_i)(x(N) - x_ref) - ξ <= 0
            kG = self._Pn.shape[0]
            blk = _place(self._Pn, xN, nv) + _place(-np.ones((kG, 1)), ixi, nv)
            labels += [f"gauge row {k}" for k in range(kG)]
        blocks.append(blk)
        off.append(np.zeros(blk.shape[0]))
        rng.append(np.zeros(blk.shape[0]))
        n_gen = sum(b.shape[0] for b in blocks)
        self._G = sp.vstack(blocks, format="csr")
        self._off = np.concatenate(off)
        self._rng = np.maximum(np.concatenate(rng), 0.0)
        # row scale of the back-off; none on the gauge rows (the bound on ξ carries it)
        self._rownorm = np.asarray(abs(self._G).sum(axis=1)).ravel()
        self._rownorm[n_gen - blk.shape[0]:] = 0.0
        self._labels_gen = labels
        self._n_gen = n_gen

        # bounds (deviation coordinates, before division by σ)
        self._xlo_d = self.xlo - self.x_ref
        self._xhi_d = self.xhi - self.x_ref
        self._xw = self.xhi - self.xlo
        self._ulo_d = self.ulo - self.u_ref
        self._uhi_d = self.uhi - self.u_ref
        self._c = np.zeros(nv)
        self._c[ixi] = 1.0

        # phase-1 LP: X rows + general rows + ξ row, each relaxed by t * weight
        ix = n + np.arange(N * n)  # x(1..N)
        GX = sp.csr_matrix((np.ones(N * n), (np.arange(N * n), ix)), shape=(N * n, nv))
        xi_row = sp.csr_matrix(([1.0], ([0], [ixi])), shape=(1, nv))
        G1 = sp.vstack([GX, -GX, self._G, xi_row], format="csr")
        weights = np.sqrt(np.asarray(G1.multiply(G1).sum(axis=1)).ravel())
        self._G1 = sp.hstack([G1, sp.csr_matrix(-weights[:, None])], format="csr")
        self._E1 = sp.hstack([self._E, sp.csr_matrix((N * n, 1))], format="csr")
        self._off1_x = (np.tile(self.xhi - self.x_ref, N), np.tile(self.x_ref - self.xlo, N))
        self._labels1 = ([f"x({i})[{j}] <= X.hi" for i in range(1, N + 1) for j in range(n)]
                         + [f"x({i})[{j}] >= X.lo" for i in range(1, N + 1) for j in range(n)]
                         + labels + ["contraction xi <= alpha*gamma(x0)"])

    # ------------------------------------------------------------------- gauge
    def gauge_value(self, x: Any) -> float:
        """The gauge ``γ(x - x_ref)`` in floating point.

        Parameters
        ----------
        x : array_like, shape (n,)

        Returns
        -------
        float
        """
        d = np.asarray(x, dtype=float).reshape(self.n) - self.x_ref
        if self.kind == "l1":
            return float(np.abs(d).sum())
        if self.kind == "linf":
            return float(np.abs(d).max())
        return float(max(np.max(self._Pn @ d), 0.0))

    def _gauge_exact(self, x: list[Fraction]) -> Fraction:
        d = [a - Fraction(float(r)) for a, r in zip(x, self.x_ref, strict=True)]
        if self.kind == "l1":
            return sum((abs(v) for v in d), _F0)
        if self.kind == "linf":
            return max(abs(v) for v in d)
        return max(max(_dot(row, d) for row in self._Pn_ex), _F0)

    # ------------------------------------------------------------------- solve
    def solve(self, x0: Any) -> LPStep:
        """Solve the contractive LP from ``x0``.

        Parameters
        ----------
        x0 : array_like, shape (n,)
            Current state ``x(k)``.

        Returns
        -------
        LPStep
            ``"optimal"``: ``u_seq`` minimises ``ξ`` over the backed-off constraints;
            ``verified`` tells whether it satisfies the true ones exactly.
            ``"infeasible"``: proven. ``proof["statement"]`` says what: no
            ``u(0..N-1) ∈ U`` gives ``x(1..N) ∈ X``, ``x(N) ∈ S``, the path rows and
            ``γ(x(N) - x_ref) <= α γ(x0 - x_ref)`` (non-strict, the exact real value of the
            bound), for the given float data ``A, B, X, U, S, path, x0, x_ref, α`` read as
            exact rational numbers. With ``z = (x(0..N), u(0..N-1), ξ, s)`` (``s``: the
            1-norm's slacks), ``G z <= g`` the rows for X (i = 1..N), S, the path, the
            gauge epigraph ``γ(x(N) - x_ref) <= ξ`` and ``ξ <= α γ(x0 - x_ref)`` (exact
            rational data), and ``E z = 0`` the dynamics, the certificate is ``y >= 0``
            (exact fractions, from the phase-1 LP's multipliers) with ``λ`` computed
            exactly so that ``r = G^T y + E^T λ`` vanishes on ``x(1..N)``; then
            ``min_{z ∈ Z} r.z - y.g > 0`` is verified exactly over the box Z implied by
            the constraints (``x(0) = x0``, ``u(i) ∈ U``, ``0 <= ξ, s_j <= α γ(x0 -
            x_ref)``), whereas every feasible z gives ``r.z <= y.g``.
            ``"failed"``: neither (see ``message``).

        Raises
        ------
        DimensionError
            ``x0`` has the wrong shape.
        InvalidBoundsError
            ``x0`` contains NaN or an infinite entry.
        """
        t0 = time.perf_counter()
        x0 = _vector(x0, "x0", self.n)
        sigma = self.gauge_value(x0)
        xi_bound = self.alpha * sigma
        if not (math.isfinite(sigma) and (sigma == 0.0 or math.isfinite(1.0 / sigma))):
            return LPStep("failed", None, None, math.nan, xi_bound, False, None,
                          time.perf_counter() - t0,
                          f"the gauge of x0 - x_ref ({sigma:.3g}) cannot be scaled to 1")
        if sigma == 0.0:
            u_seq = np.tile(self.u_ref, (self.horizon, 1))
            x_pred = self._simulate(x0, u_seq)
            ok, why = self._verify(x0, u_seq)
            return LPStep("optimal", u_seq, x_pred, 0.0, 0.0, ok, None,
                          time.perf_counter() - t0,
                          "x0 = x_ref: u_ref kept" + ("" if ok else f"; not verified: {why}"))
        res = self._main_lp(x0, sigma, _BOUND_CAP)
        if res.status == 0:
            step = self._optimal(x0, sigma, xi_bound, res, "")
            if not step.verified:
                # a degenerate optimal face far from x0 (e.g. near x_ref): retry with the
                # deviations capped, which keeps the sequence at the scale of gamma(x0)
                res2 = self._main_lp(x0, sigma, _RETRY_CAP)
                if res2.status == 0:
                    step2 = self._optimal(x0, sigma, xi_bound, res2,
                                          f" (deviations capped at {_RETRY_CAP:g} gamma(x0))")
                    if step2.verified:
                        step = step2
            return replace(step, elapsed=time.perf_counter() - t0)
        if res.status != 2:
            return LPStep("failed", None, None, math.nan, xi_bound, False, None,
                          time.perf_counter() - t0,
                          f"HiGHS could not solve the contractive LP: {res.message}")
        status, proof, msg = self._certify(x0, sigma)
        return LPStep(status, None, None, math.nan, xi_bound, False, proof,
                      time.perf_counter() - t0, msg)

    def _main_lp(self, x0: np.ndarray, sigma: float, cap: float) -> Any:
        """The backed-off LP in scaled deviation coordinates (bounds clipped to ``±cap``)."""
        n, N = self.n, self.horizon
        inv = 1.0 / sigma
        nv, iu, ixi = self._nv, self._iu, self._ixi
        lb = np.empty(nv)
        ub = np.empty(nv)
        bo = self.backoff
        with np.errstate(over="ignore", invalid="ignore"):
            lb[:n] = ub[:n] = (x0 - self.x_ref) * inv
            shrink = bo * np.maximum(self._xw * inv, 1.0)
            lb[n:iu] = np.tile(np.maximum(self._xlo_d * inv + shrink, -cap), N)
            ub[n:iu] = np.tile(np.minimum(self._xhi_d * inv - shrink, cap), N)
            lb[iu:ixi] = np.tile(np.maximum(self._ulo_d * inv, -cap), N)
            ub[iu:ixi] = np.tile(np.minimum(self._uhi_d * inv, cap), N)
            b_ub = self._off * inv - bo * np.maximum(self._rng * inv, self._rownorm)
            b_ub = np.clip(np.nan_to_num(b_ub, nan=-_HUGE), -_HUGE, cap)
        lb[ixi] = 0.0
        ub[ixi] = self.alpha - min(bo, 0.5 * self.alpha)
        lb[ixi + 1:] = 0.0
        ub[ixi + 1:] = np.inf
        return linprog(self._c, A_ub=self._G, b_ub=b_ub,
                       A_eq=self._E, b_eq=np.zeros(N * n), bounds=np.column_stack([lb, ub]),
                       method="highs", options=HIGHS_OPTIONS)

    def _optimal(self, x0: np.ndarray, sigma: float, xi_bound: float, res: Any,
                 note: str) -> LPStep:
        N, m, iu, ixi = self.horizon, self.m, self._iu, self._ixi
        z = np.asarray(res.x, dtype=float)
        u_seq = self.u_ref + sigma * z[iu:ixi].reshape(N, m)
        u_seq = np.minimum(np.maximum(u_seq, self.ulo), self.uhi)
        x_pred = self._simulate(x0, u_seq)
        ok, why = self._verify(x0, u_seq)
        msg = str(res.message) + note + ("" if ok else f"; not verified: {why}")
        return LPStep("optimal", u_seq, x_pred, float(sigma * z[ixi]), xi_bound, ok, None,
                      0.0, msg)

    # --------------------------------------------------------------- simulation
    def _simulate(self, x0: np.ndarray, u_seq: np.ndarray) -> np.ndarray:
        x = np.empty((self.horizon + 1, self.n))
        x[0] = x0
        for i in range(self.horizon):
            x[i + 1] = self.A @ x[i] + self.B @ u_seq[i]
        return x

    def _exact_data(self) -> dict[str, Any]:
        if self._exact is None:
            self._exact = {
                "A": _fr(self.A), "B": _fr(self.B), "H": _fr(self.H), "h": _fr(self.h),
                "Gx": _fr(self.Gx), "Gu": _fr(self.Gu), "g": _fr(self.g),
                "alpha": Fraction(self.alpha),
            }
        return self._exact

    def _verify(self, x0: np.ndarray, u_seq: np.ndarray) -> tuple[bool, str]:
        """Exact re-simulation of ``u_seq`` from ``x0`` and check of every constraint.

        Floats are dyadic rationals: the states are integers times a power of two
        (:func:`_dyadic`), so the simulation is exact and needs no fraction reductions.
        """
        ex = self._exact_data()
        if "dyA" not in ex:
            ex["dyA"], ex["dyB"] = _dyadic(self.A), _dyadic(self.B)
            ex["dyGx"], ex["dyGu"] = _dyadic(self.Gx), _dyadic(self.Gu)
            ex["dyxlo"] = [_dyadic1(v) for v in self.xlo]
            ex["dyxhi"] = [_dyadic1(v) for v in self.xhi]
            ex["dyg"] = [_dyadic1(v) for v in self.g]
        (Ai, EA), (Bi, EB) = ex["dyA"], ex["dyB"]
        (Gxi, EGx), (Gui, EGu) = ex["dyGx"], ex["dyGu"]
        dlo, dhi, dg = ex["dyxlo"], ex["dyxhi"], ex["dyg"]
        if np.any(u_seq < self.ulo) or np.any(u_seq > self.uhi):  # float comparisons: exact
            return False, "u outside U"
        x, Ex = _dyadic(x0)
        for i in range(self.horizon):
            u, Eu = _dyadic(u_seq[i])
            for k, gk in enumerate(dg):
                s = _add(_dot_int(Gxi[k], x), EGx + Ex, _dot_int(Gui[k], u), EGu + Eu)
                if _cmp(*s, *gk) > 0:
                    return False, f"path row {k} violated at i={i}"
            ax = [_dot_int(row, x) for row in Ai]
            bu = [_dot_int(row, u) for row in Bi]
            E1, E2 = EA + Ex, EB + Eu
            Ex = min(E1, E2)
            x = [(a << (E1 - Ex)) + (b << (E2 - Ex)) for a, b in zip(ax, bu, strict=True)]
            for j in range(self.n):
                if _cmp(x[j], Ex, *dlo[j]) < 0 or _cmp(x[j], Ex, *dhi[j]) > 0:
                    return False, f"x({i + 1}) outside X"
        xN = [Fraction(v, 1 << -Ex) if Ex < 0 else Fraction(v << Ex) for v in x]
        for k, (hk, bk) in enumerate(zip(ex["H"], ex["h"], strict=True)):
            if _dot(hk, xN) > bk:
                return False, f"terminal row {k} violated"
        g0 = self._gauge_exact(_fr(x0))
        gN = self._gauge_exact(xN)
        bound = ex["alpha"] * g0
        if not (gN < bound or (g0 == 0 and gN == 0)):
            return False, (f"contraction gamma(x(N)) = {float(gN):.17g} not below "
                           f"alpha*gamma(x0) = {float(bound):.17g}")
        return True, ""

    # ------------------------------------------------------------- certificate
    def _exact_rows(self) -> dict[str, Any]:
        """Exact sparse rows of the phase-1 system in original coordinates (cached)."""
        ex = self._exact_data()
        if "rows1" in ex:
            return ex
        n, N, ixi = self.n, self.horizon, self._ixi
        G = self._G1.tocsr()
        rows: list[list[tuple[int, Fraction]]] = []
        rhs: list[Fraction | None] = []
        nX = N * n
        xr = _fr(self.x_ref)
        for k in range(G.shape[0]):
            cols = G.indices[G.indptr[k]:G.indptr[k + 1]]
            vals = G.data[G.indptr[k]:G.indptr[k + 1]]
            rows.append([(int(c), Fraction(float(v))) for c, v in zip(cols, vals, strict=True)
                         if c < self._nv])
        # right-hand sides in original coordinates
        rhs += [Fraction(float(v)) for v in self.xhi] * N
        rhs += [-Fraction(float(v)) for v in self.xlo] * N
        rhs += list(ex["h"])
        for _ in range(N):
            rhs += list(ex["g"])
        base = len(rhs)
        if self.kind in ("linf", "l1"):
            rhs += xr + [-v for v in xr]
            if self.kind == "l1":
                rhs.append(_F0)
        else:
            kG = len(self._Pn_ex)
            xN = N * n
            for k in range(kG):
                rows[base + k] = ([(xN + j, a) for j, a in enumerate(self._Pn_ex[k]) if a]
                                  + [(ixi, Fraction(-1))])
                rhs.append(_dot(self._Pn_ex[k], xr))
        rhs.append(None)  # ξ <= α γ(x0): depends on x0
        assert len(rhs) == len(rows) == 2 * nX + self._n_gen + 1
        ex["rows1"], ex["rhs1"] = rows, rhs
        return ex

    def _certify(self, x0: np.ndarray, sigma: float) -> tuple[str, dict | None, str]:
        n, N = self.n, self.horizon
        nv, iu, ixi = self._nv, self._iu, self._ixi
        x0f = _fr(x0)
        ex = self._exact_data()
        xi_max = ex["alpha"] * self._gauge_exact(x0f)  # exact α γ(x0 - x_ref)
        xi_up = _frac_up(xi_max)
        inv = 1.0 / sigma
        cap = _BOUND_CAP
        lb = np.full(nv + 1, -np.inf)
        ub = np.full(nv + 1, np.inf)
        with np.errstate(over="ignore"):
            b1 = np.concatenate([self._off1_x[0] * inv, self._off1_x[1] * inv,
                                 self._off * inv, [xi_up * inv]])
            b1 = np.clip(b1, -_HUGE, cap)
            lb[:n] = ub[:n] = (x0 - self.x_ref) * inv
            lb[iu:ixi] = np.tile(np.maximum(self._ulo_d * inv, -cap), N)
            ub[iu:ixi] = np.tile(np.minimum(self._uhi_d * inv, cap), N)
        lb[ixi:] = 0.0
        c = np.zeros(nv + 1)
        c[-1] = 1.0
        res = linprog(c, A_ub=self._G1, b_ub=b1, A_eq=self._E1, b_eq=np.zeros(N * n),
                      bounds=np.column_stack([lb, ub]), method="highs", options=HIGHS_OPTIONS)
        if res.status != 0:
            return "failed", None, ("HiGHS reported the contractive LP infeasible; the "
                                    f"phase-1 LP for its certificate failed: {res.message}")
        if not res.fun > 0.0:
            return "failed", None, ("HiGHS reported the backed-off contractive LP infeasible, "
                                    "but the un-tightened problem is feasible within the LP "
                                    "tolerance (phase-1 optimum 0): no proof of infeasibility")
        y = np.maximum(-np.asarray(res.ineqlin.marginals, dtype=float), 0.0)
        yd = {int(k): Fraction(float(y[k])) for k in np.flatnonzero(y > 0)}
        r, beta, lam_ex = self._combination(yd, xi_max)
        margin = self._margin(r, beta, x0f, xi_max)
        if margin <= 0:
            polished = self._polish(x0f, xi_max, y)
            if polished is not None and polished[0] > 0:
                margin, yd, lam_ex = polished
        if margin <= 0:
            return "failed", None, (
                "HiGHS reported the contractive LP infeasible (phase-1 violation "
                f"{res.fun * sigma:.3g}), but its multipliers do not form an exact Farkas "
                "certificate; infeasibility is not proven")
        y = np.zeros(self._G1.shape[0])
        for k, v in yd.items():
            y[k] = float(v)
        lam = np.array([float(v) for row in lam_ex for v in row])
        labels = [self._labels1[k] for k in np.flatnonzero(y > 0)]
        proof = {
            "kind": "farkas",
            "statement": (
                f"no u(0..{N - 1}) in U gives x(1..{N}) in X"
                + (", x(N) in the terminal set" if self.H.shape[0] else "")
                + (", the path constraints" if self.g.size else "")
                + " and gauge(x(N) - x_ref) <= alpha*gauge(x0 - x_ref) (non-strict) for "
                "this x0; proven by an exactly checked Farkas combination on the float data "
                "read as exact rationals"),
            "margin": _frac_down(margin),
            "xi_bound": xi_up,
            "y_exact": yd,
            "y": y,
            "lam": lam,
            "rows": labels,
        }
        return "infeasible", proof, (f"infeasible (exact Farkas certificate, margin "
                                     f"{_frac_down(margin):.3g})")

    def check_proof(self, x0: Any, proof: dict) -> bool:
        """Re-check an infeasibility certificate of :meth:`solve` exactly.

        Parameters
        ----------
        x0 : array_like, shape (n,)
            The state the certificate was computed for.
        proof : dict
            ``LPStep.proof`` of an ``"infeasible"`` step; only ``proof["y_exact"]`` is used
            (a dict row index -> Fraction ``>= 0``, rows numbered as in ``proof["y"]``;
            see :meth:`solve`).

        Returns
        -------
        bool
            True when ``y >= 0`` and the exact check of :meth:`solve` passes, i.e. the
            problem from ``x0`` is infeasible.

        Raises
        ------
        DimensionError
            ``x0`` or ``proof["y"]`` has the wrong shape.
        """
        x0 = _vector(x0, "x0", self.n)
        R = self._G1.shape[0]
        yd = proof["y_exact"]
        if not isinstance(yd, dict) or any(
                not isinstance(k, Integral) or not 0 <= k < R for k in yd):
            raise DimensionError(f"proof['y_exact'] must map row indices in [0, {R}) to "
                                 "Fractions")
        yd = {int(k): Fraction(v) for k, v in yd.items()}
        if any(v < 0 for v in yd.values()):
            return False
        x0f = _fr(x0)
        xi_max = self._exact_data()["alpha"] * self._gauge_exact(x0f)
        r, beta, _ = self._combination(yd, xi_max)
        return self._margin(r, beta, x0f, xi_max) > 0

    def _combination(self, yd: dict[int, Fraction], xi_max: Fraction
                     ) -> tuple[dict[int, Fraction], Fraction, list[list[Fraction]]]:
        """``r = G^T y + E^T λ``, ``β = y.g`` and ``λ``, exactly, for ``y`` (row -> value).

        ``λ`` (dynamics multipliers, one ``(n,)`` vector per step) is computed exactly from
        ``y`` so that ``r`` vanishes on the predicted states ``x(1..N)``:
        ``λ_{N-1} = -c_{x(N)}``, ``λ_{i-1} = A^T λ_i - c_{x(i)}`` with ``c = G^T y``.
        """
        ex = self._exact_rows()
        rows, rhs = ex["rows1"], ex["rhs1"]
        Af, Bf = ex["A"], ex["B"]
        n, m, N, iu, ixi = self.n, self.m, self.horizon, self._iu, self._ixi
        c: dict[int, Fraction] = {}
        beta = _F0
        for k, yk in yd.items():
            if not yk:
                continue
            for col, a in rows[k]:
                c[col] = c.get(col, _F0) + yk * a
            beta += yk * (xi_max if rhs[k] is None else rhs[k])

        def cx(i: int) -> list[Fraction]:
            return [c.get(i * n + j, _F0) for j in range(n)]

        def at_times(lam: list[Fraction]) -> list[Fraction]:  # A^T lam
            return [sum((Af[q][j] * lam[q] for q in range(n) if Af[q][j] and lam[q]), _F0)
                    for j in range(n)]

        lam: list[list[Fraction]] = [[]] * N
        lam[N - 1] = [-v for v in cx(N)]
        for i in range(N - 1, 0, -1):
            lam[i - 1] = [a - b for a, b in zip(at_times(lam[i]), cx(i), strict=True)]
        r: dict[int, Fraction] = {}
        for j, v in enumerate(at_times(lam[0])):
            r[j] = c.get(j, _F0) - v
        for i in range(N):
            for k in range(m):
                col = iu + i * m + k
                r[col] = c.get(col, _F0) - sum(
                    (Bf[q][k] * lam[i][q] for q in range(n) if Bf[q][k] and lam[i][q]), _F0)
        for col in range(ixi, self._nv):
            r[col] = c.get(col, _F0)
        return r, beta, lam

    def _margin(self, r: dict[int, Fraction], beta: Fraction, x0f: list[Fraction],
                xi_max: Fraction) -> Fraction:
        """``min_{z ∈ Z} r.z - β`` exactly (r vanishes on x(1..N))."""
        n, m, iu, ixi = self.n, self.m, self._iu, self._ixi
        ex = self._exact_data()
        if "ulo" not in ex:
            ex["ulo"], ex["uhi"] = _fr(self.ulo), _fr(self.uhi)
        ulo, uhi = ex["ulo"], ex["uhi"]
        total = -beta
        for col, v in r.items():
            if v == 0:
                continue
            if col < n:
                lo = hi = x0f[col]
            elif col < iu:  # cannot happen: r vanishes on x(1..N)
                raise AssertionError("combination does not vanish on the predicted states")
            elif col < ixi:
                j = (col - iu) % m
                lo, hi = ulo[j], uhi[j]
            else:
                lo, hi = _F0, xi_max
            total += v * (lo if v > 0 else hi)
        return total

    def _polish(self, x0f: list[Fraction], xi_max: Fraction, y: np.ndarray
                ) -> tuple[Fraction, dict[int, Fraction], list[list[Fraction]]] | None:
        """Exact multipliers near ``y`` whose combination vanishes where it nearly does.

        The rounding of HiGHS's multipliers leaves tiny coefficients on controls whose
        bounds are not binding; over the width of U they can outweigh the margin (near
        ``x_ref``). On the support S of ``y``, the exact null space of the map
        ``y_S -> r`` restricted to those columns is computed; ``y`` is replaced by the
        null-space vector closest to it (least-squares weights of an exact basis, combined
        exactly). None when that vector has a negative entry or the null space is
        trivial.
        """
        ymax = float(y.max(initial=0.0))
        if ymax <= 0.0:
            return None
        S = [int(k) for k in np.argsort(-y) if y[k] > 1e-12 * ymax]
        yd = {k: Fraction(float(y[k])) for k in S}
        r, _, _ = self._combination(yd, xi_max)
        cols = [col for col in r if col >= self.n]
        scale = max([abs(float(r[col])) for col in cols] + [ymax])
        Z = [col for col in cols if r[col] != 0 and abs(float(r[col])) <= 1e-8 * scale]
        if not Z:
            return None
        unit = [self._combination({k: Fraction(1)}, xi_max)[0] for k in S]
        M = [[u.get(col, _F0) for u in unit] for col in Z]
        basis = rat_nullspace(M, len(S))
        if not basis:
            return None
        # an exact null-space vector close to y (least-squares weights, exact combination)
        Bm = np.array([[float(v) for v in b] for b in basis])
        w = np.linalg.lstsq(Bm.T, np.array([float(yd[k]) for k in S]), rcond=None)[0]
        ys = [_F0] * len(S)
        for b, wb in zip(basis, w, strict=True):
            if not np.isfinite(wb) or wb == 0.0:
                continue
            fw = Fraction(float(wb))
            ys = [a + fw * v for a, v in zip(ys, b, strict=True)]
        if any(v < 0 for v in ys):
            return None
        yd2 = {k: v for k, v in zip(S, ys, strict=True) if v}
        r2, beta2, lam2 = self._combination(yd2, xi_max)
        return self._margin(r2, beta2, x0f, xi_max), yd2, lam2


def _dyadic1(v: float) -> tuple[int, int]:
    """``(p, e)`` with ``v = p * 2**e`` exactly."""
    p, q = float(v).as_integer_ratio()
    return p, -(q.bit_length() - 1)


def _dyadic(a: np.ndarray) -> tuple[list, int]:
    """Integers ``v`` (nested like ``a``, 1-D or 2-D) and one exponent ``E``, ``a = v 2^E``."""
    arr = np.asarray(a, dtype=float)
    pairs = [_dyadic1(t) for t in arr.ravel()]
    E = min((e for _, e in pairs), default=0)
    ints = [p << (e - E) for p, e in pairs]
    if arr.ndim == 2:
        c = arr.shape[1]
        return [ints[r * c:(r + 1) * c] for r in range(arr.shape[0])], E
    return ints, E


def _dot_int(row: list[int], x: list[int]) -> int:
    return sum(a * v for a, v in zip(row, x, strict=True) if a)


def _add(a: int, ea: int, b: int, eb: int) -> tuple[int, int]:
    """``a 2^ea + b 2^eb`` as ``(v, e)``."""
    e = min(ea, eb)
    return (a << (ea - e)) + (b << (eb - e)), e


def _cmp(a: int, ea: int, b: int, eb: int) -> int:
    """Sign of ``a 2^ea - b 2^eb``."""
    if ea >= eb:
        a <<= ea - eb
    else:
        b <<= eb - ea
    return (a > b) - (a < b)


def _place(M: np.ndarray, col0: int, nv: int) -> sp.csr_matrix:
    """``M`` (k, c) placed at columns ``col0 .. col0 + c - 1`` of a (k, nv) sparse matrix."""
    M = np.asarray(M, dtype=float)
    k, c = M.shape
    r, cc = np.nonzero(M)
    return sp.csr_matrix((M[r, cc], (r, col0 + cc)), shape=(k, nv))


def _box_min(M: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``min_{lo <= x <= hi} M x`` row by row (floating point)."""
    return np.minimum(M * lo, M * hi).sum(axis=1)


# ----------------------------------------------------------------------------- one step
#: Inward margin of every target row handed to HiGHS, in units of the row's scale
#: (``max(|H_k| . max|X|, |h_k|)``): ten times HiGHS's feasibility tolerance (1e-10), so
#: that a solution HiGHS calls feasible has a true slack of at least 9e-10 of the scale,
#: far above the rounding of the interval check that decides the step.
ONE_STEP_MARGIN = 1e-9
#: Slack (same units) below which the most interior control is not refined by a second LP.
_SLACK_FLOOR = 2e-10


@dataclass(frozen=True)
class OneStepCandidate:
    """One control proposed by :class:`OneStepLP` (a candidate: nothing is proven).

    Attributes
    ----------
    u : ndarray, shape (m,)
        The control, inside U (clipped exactly).
    xi : float
        Gauge value ``max_k G_k (x+ - x_ref)`` at u, worst case over W (floating point;
        NaN without a gauge).
    member : int
        Index of the target polytope of ``K_{i-1}`` the LP aimed at.
    how : str
        ``"lp"`` (the LP (3.9)-(3.10) with every row moved inward by the margin),
        ``"lp, smaller margin"`` (the same with half the largest available slack) or
        ``"most interior"`` (the control that maximises the smallest scaled slack).
    slack : float
        The LP's smallest scaled slack of the target rows at u (estimate, floating point).
    """

    u: np.ndarray
    xi: float
    member: int
    how: str
    slack: float


class OneStepLP:
    """Candidate controls of the one-step LP (3.9)–(3.10) of a linear model.

    For ``x+ = A x + B u + E w + c``, a state ``x`` and the target ``K_{i-1}`` held as a
    union of polytopes ``P_j = {y : H_j y <= h_j}``, each member gives the LP

        min ξ  over u in U, ξ >= 0
        s.t.  G (A x + B u + E w + c - x_ref) <= ξ 1          for all w in W
              H_j (A x + B u + E w + c) <= h_j - δ σ          for all w in W

    with ``G y <= 1`` the gauge polytope (the terminal set T of (3.9), or its convex hull,
    written around ``x_ref``), the worst case over the box W taken row by row exactly as
    the support ``max_{w in W} M E w``, and ``σ`` the scale of each row
    (``max(|H_k| . max|X|, |h_k|)``). The inward margin ``δ`` (:data:`ONE_STEP_MARGIN`)
    exceeds HiGHS's feasibility tolerance tenfold, so that a solver tolerance cannot turn
    an answer into a control that misses the target. When that LP is infeasible (the room
    left by ``K_{i-1}`` at ``x`` is thinner than the margin), the control maximising the
    smallest scaled slack is proposed, and, when that slack is positive, the LP again
    with half of it as margin.

    Every answer is only a candidate: the caller decides a step with a rigorous test of
    ``f(x, u, W) ⊆ K_{i-1}`` (:class:`~casadi_cmpc.SetSequenceMPC` uses interval
    arithmetic with outward rounding).

    Parameters
    ----------
    model : Model
        A linear model (``model.is_linear``).
    gauge : Polytope or None
        ``{y : G y <= g}`` with ``x_ref`` strictly inside (the objective (3.9)); None: no
        objective (only the most interior control is proposed).
    x_ref : ndarray, shape (n,)
        Reference state of the gauge.
    W : ndarray, shape (l, 2)
        The disturbance box the rows must hold for (thin for a nominal controller).
    """

    def __init__(self, model: Any, gauge: Polytope | None, x_ref: np.ndarray,
                 W: np.ndarray) -> None:
        if not model.is_linear:
            raise ModelError(f"the one-step LP (3.9)-(3.10) needs a linear model; model "
                             f"'{model.name}' is nonlinear (use solver='ipopt' or 'sqp')")
        A, B, E, c = model.linear_matrices()
        n, m = model.n, model.m
        self.A, self.B = A, B.reshape(n, m)
        self.E = E.reshape(n, model.l)
        self.c = np.asarray(c, dtype=float).reshape(n)
        W = np.asarray(W, dtype=float).reshape(model.l, 2)
        self._wc = 0.5 * W[:, 0] + 0.5 * W[:, 1]
        self._wr = np.maximum(W[:, 1] - self._wc, self._wc - W[:, 0])
        self.U_lo = np.asarray(model.U.lo, dtype=float)
        self.U_hi = np.asarray(model.U.hi, dtype=float)
        self.xmax = np.maximum(np.abs(model.X.lo), np.abs(model.X.hi))
        self.x_ref = np.asarray(x_ref, dtype=float).reshape(n)
        self.n, self.m = n, m
        self.G: np.ndarray | None = None
        if gauge is not None:
            Gb = np.asarray(gauge.b, dtype=float) - np.asarray(gauge.A, dtype=float) @ self.x_ref
            if Gb.size == 0 or not np.all(Gb > 0):
                raise ValueError(
                    "the gauge of (3.9) needs x_ref strictly inside its polytope (every "
                    f"row b_k - a_k x_ref > 0; smallest {float(np.min(Gb, initial=0.0)):.3g}); "
                    "pass gauge= a polytope around x_ref")
            self.G = np.asarray(gauge.A, dtype=float) / Gb[:, None]

    def _support(self, M: np.ndarray) -> np.ndarray:
        """``max_{w in W} M E w`` per row (floating point; 0 without w)."""
        if self.E.shape[1] == 0:
            return np.zeros(M.shape[0])
        ME = M @ self.E
        return ME @ self._wc + np.abs(ME) @ self._wr

    def xi(self, x: np.ndarray, u: np.ndarray) -> float:
        """Gauge value of the successor, worst case over W (floating point)."""
        if self.G is None:
            return math.nan
        y = self.A @ x + self.B @ u + self.c - self.x_ref
        return float(np.max(self.G @ y + self._support(self.G)))

    def _rows(self, x: np.ndarray, P: Polytope) -> tuple[np.ndarray, np.ndarray]:
        """Scaled rows ``(H B / σ, (h - H (A x + c) - support) / σ)`` of one member."""
        H = np.asarray(P.A, dtype=float)
        h = np.asarray(P.b, dtype=float)
        sig = np.maximum(np.abs(H) @ self.xmax, np.abs(h))
        sig = np.where(sig > 0, sig, 1.0)
        rhs = h - H @ (self.A @ x + self.c) - self._support(H)
        return (H @ self.B) / sig[:, None], rhs / sig

    def candidates(self, x: Any, members: list[Polytope]) -> list[OneStepCandidate]:
        """Candidate controls toward the union of ``members``, best gauge value first.

        Parameters
        ----------
        x : array_like, shape (n,)
        members : list of Polytope
            The polytopes of ``K_{i-1}`` (empty ones are skipped).

        Returns
        -------
        list of OneStepCandidate
            Possibly empty (every LP infeasible with no slack to spare).
        """
        x = np.asarray(x, dtype=float).reshape(self.n)
        m = self.m
        rows = [self._rows(x, P) for P in members
                if isinstance(P, Polytope) and not P.is_empty()]
        if not rows:
            return []
        out: list[OneStepCandidate] = []
        lo = np.concatenate([self.U_lo, [0.0]])
        hi = np.concatenate([self.U_hi, [np.inf]])

        def lp_blocks(idx: list[int], margins: np.ndarray) -> Any:
            """The LP (3.9)-(3.10) of each member in idx with its margin, one HiGHS call."""
            RA, Rb, blk = [], [], []
            gA = gb = None
            if self.G is not None:
                gA = np.hstack([self.G @ self.B, -np.ones((self.G.shape[0], 1))])
                gb = -(self.G @ (self.A @ x + self.c - self.x_ref) + self._support(self.G))
            for k, (j, d) in enumerate(zip(idx, margins, strict=True)):
                HB, r = rows[j]
                RA.append(np.hstack([HB, np.zeros((HB.shape[0], 1))]))
                Rb.append(r - d)
                blk.append(np.full(HB.shape[0], k))
                if gA is not None:
                    RA.append(gA)
                    Rb.append(gb)
                    blk.append(np.full(gA.shape[0], k))
            C = np.zeros((len(idx), m + 1))
            C[:, m] = 1.0
            return block_lp(C, np.vstack(RA), np.concatenate(Rb), np.concatenate(blk), lo, hi)

        def add(z: np.ndarray, j: int, how: str) -> None:
            u = np.minimum(np.maximum(z[:m], self.U_lo), self.U_hi)
            HB, r = rows[j]
            out.append(OneStepCandidate(u=u, xi=self.xi(x, u), member=j, how=how,
                                        slack=float(np.min(r - HB @ u, initial=1.0))))

        idx = list(range(len(rows)))
        failed = idx
        if self.G is not None:
            res = lp_blocks(idx, np.full(len(idx), ONE_STEP_MARGIN))
            failed = []
            for k, j in enumerate(idx):
                if res.status[k] == OPTIMAL and np.isfinite(res.x[k]).all():
                    add(res.x[k], j, "lp")
                else:
                    failed.append(j)
        if failed:
            # the most interior control: max t s.t. HB u + t <= r, t <= 1
            RA, Rb, blk = [], [], []
            for k, j in enumerate(failed):
                HB, r = rows[j]
                RA.append(np.hstack([HB, np.ones((HB.shape[0], 1))]))
                Rb.append(r)
                blk.append(np.full(HB.shape[0], k))
            C = np.zeros((len(failed), m + 1))
            C[:, m] = -1.0
            res = block_lp(C, np.vstack(RA), np.concatenate(Rb), np.concatenate(blk),
                           np.concatenate([self.U_lo, [-np.inf]]),
                           np.concatenate([self.U_hi, [1.0]]))
            again, margins = [], []
            for k, j in enumerate(failed):
                if res.status[k] != OPTIMAL or not np.isfinite(res.x[k]).all():
                    continue
                t = float(res.x[k, m])
                if t < -ONE_STEP_MARGIN:  # this member is out of reach from x
                    continue
                add(res.x[k], j, "most interior")
                if self.G is not None and t > _SLACK_FLOOR:
                    again.append(j)
                    margins.append(0.5 * min(t, 2 * ONE_STEP_MARGIN))
            if again:
                res = lp_blocks(again, np.asarray(margins))
                for k, j in enumerate(again):
                    if res.status[k] == OPTIMAL and np.isfinite(res.x[k]).all():
                        add(res.x[k], j, "lp, smaller margin")
        key = [(c.xi if np.isfinite(c.xi) else -c.slack) for c in out]
        order = np.argsort(np.asarray(key, dtype=float), kind="stable")
        return [out[i] for i in order]
