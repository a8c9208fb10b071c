"""What a controller hands to an exporter: the data its C export is generated from.

:meth:`ContractiveMPC.export_spec <casadi_cmpc.ContractiveMPC.export_spec>`,
:meth:`SetSequenceMPC.export_spec <casadi_cmpc.SetSequenceMPC.export_spec>` and
:meth:`QuasiMultiStepMPC.export_spec <casadi_cmpc.mpc.quasi.QuasiMultiStepMPC.export_spec>`
return these frozen records. They are the interface between the controllers and
:mod:`casadi_cmpc.codegen` (which reads nothing else of a controller), so that an exporter
needs neither the controllers' internals nor an import of their modules. The CasADi
Functions in them are the ones the Python controller evaluates, so that the generated code
computes what the controller computes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

__all__ = ["ContractiveSpec", "HorizonProblem", "QuasiSpec", "SetSequenceSpec"]


@dataclass(frozen=True, eq=False)
class HorizonProblem:
    """The local problem of a contractive MPC at one horizon N, and its interval check.

    Attributes
    ----------
    horizon : int
        N.
    nlp : dict
        The NLP given to ``casadi.nlpsol``: ``x`` (the controls ``N m``, then ``n_t`` slack
        variables of the 1-norm, then ``n_zx`` predicted states), ``p`` (``[x, s]`` with
        ``s = 1 / ||C (x - x_ref)||``), ``f``, ``g``.
    plugin : str
        ``"ipopt"`` or ``"sqpmethod"``.
    options : dict
        The solver options of the controller.
    n_z, n_t, n_zx : int
        Number of variables, of 1-norm slacks and of predicted states among them.
    lbz, ubz, lbg, ubg : ndarray
        Bounds of the variables and of the constraint rows.
    predict_states : casadi.Function
        ``(u (N m), x0 (n)) -> x (n N)``: the states ``x(1..N)`` predicted from a control
        sequence (column after column), the start of the multiple-shooting states.
    check_fun : casadi.Function
        The exact check graph ``z -> rows``, ``z = [u_seq, x, constants]``: a sequence is
        verified when an interval evaluation of every row lies in ``[check_lo, check_hi]``
        with the constants in ``[param_lo, param_hi]``.
    check_lo, check_hi, param_lo, param_hi : ndarray
    """

    horizon: int
    nlp: dict
    plugin: str
    options: dict
    n_z: int
    n_t: int
    n_zx: int
    lbz: np.ndarray
    ubz: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    predict_states: ca.Function
    check_fun: ca.Function
    check_lo: np.ndarray
    check_hi: np.ndarray
    param_lo: np.ndarray
    param_hi: np.ndarray


@dataclass(frozen=True, eq=False)
class ContractiveSpec:
    """The export data of a :class:`~casadi_cmpc.ContractiveMPC`.

    Attributes
    ----------
    kind : str
        ``"contractive"``.
    model : Model
    solver : str
        ``"ipopt"``, ``"sqp"`` or ``"lp"``.
    horizon : int or None
        The fixed horizon (None: the controller searches for one).
    mode : str
        ``"receding"`` or ``"sequence"``.
    gauge : Polytope or None
        The polytope gauge of the contraction (LP form only).
    norm : float
        The p-norm of the contraction (1, 2 or inf; NaN with a gauge).
    contract, x_ref, u_ref, w_nominal : ndarray
        ``C``, the reference, the nominal disturbance (empty without w).
    local_law : casadi.Function or None
        ``x -> u`` applied inside ``local_set``.
    local_set : Polytope, PolytopeUnion, Box or None
    problem : HorizonProblem or None
        The local problem at ``horizon`` (None without a fixed horizon or for the LP form).
    """

    model: Any
    solver: str
    horizon: int | None
    mode: str
    gauge: Any
    norm: float
    contract: np.ndarray
    x_ref: np.ndarray
    u_ref: np.ndarray
    w_nominal: np.ndarray
    local_law: ca.Function | None
    local_set: Any
    problem: HorizonProblem | None
    kind: str = "contractive"


@dataclass(frozen=True, eq=False)
class SetSequenceSpec:
    """The export data of a :class:`~casadi_cmpc.SetSequenceMPC`.

    Attributes
    ----------
    kind : str
        ``"set_sequence"``.
    model : Model
    seq : SetSequence
        The sequence ``K_0 = T, K_1, ...``.
    members : list of list
        The sets each ``K_i`` is the union of (polytopes, pavings, ...).
    grid : tuple or None
        ``(edges, level, box)``: per cell of the grid of all step boxes' bounds, the
        smallest step whose boxes cover it and one such box (None: the sequence stores no
        boxes).
    robust : bool
        Certified for all w in W (else for the centre of W).
    minimax : str
        ``"vertices"`` or ``"interval"``.
    local_law : casadi.Function or None
        ``x -> u`` applied in T.
    polytopic : bool
        Every ``K_i``, i >= 1, is held by polytopes.
    rows : int
        Rows ``r`` of the polytope parameter ``(H, h)`` of the NLP (0: none).
    nlp_rows : list of tuple
        Per target level ``j = 0 .. L-2``, the parameter ``(H (r, n), h (r,))`` of the NLP
        for a step into ``K_j`` (zero rows with ``h = 1`` where ``K_j`` is not held by
        polytopes); empty when ``rows == 0``.
    nlp : dict
        The NLP: ``x = [v, t]`` (the scaled control ``u = u_mid + u_half v`` and the
        epigraph variable), ``p = [x, vec(H), h, cs]``, ``f``, ``g`` (``g <= 0``).
    plugin : str
        ``"ipopt"`` or ``"sqpmethod"``.
    options : dict
        The solver options of the controller.
    start : casadi.Function
        ``(x, u_guess) -> (u0, costs)``: the solver's starting control and the cost at each
        vertex of W there.
    w_vertices : ndarray (V, l)
        The points of W the costs and the NLP's rows are taken at.
    u_mid, u_half, v_lo, v_hi : ndarray (m,)
        The scaling of the control and the bounds of ``v``.
    """

    model: Any
    seq: Any
    members: list = field(default_factory=list)
    grid: Any = None
    robust: bool = False
    minimax: str = "vertices"
    local_law: ca.Function | None = None
    polytopic: bool = False
    rows: int = 0
    nlp_rows: list = field(default_factory=list)
    nlp: dict = field(default_factory=dict)
    plugin: str = "sqpmethod"
    options: dict = field(default_factory=dict)
    start: ca.Function | None = None
    w_vertices: np.ndarray = field(default_factory=lambda: np.zeros((1, 0)))
    u_mid: np.ndarray = field(default_factory=lambda: np.zeros(0))
    u_half: np.ndarray = field(default_factory=lambda: np.zeros(0))
    v_lo: np.ndarray = field(default_factory=lambda: np.zeros(0))
    v_hi: np.ndarray = field(default_factory=lambda: np.zeros(0))
    kind: str = "set_sequence"


@dataclass(frozen=True, eq=False)
class QuasiSpec:
    """The export data of a :class:`~casadi_cmpc.mpc.quasi.QuasiMultiStepMPC` (Alg 6.8).

    Attributes
    ----------
    kind : str
        ``"quasi"``.
    model : Model
    steps : int
        i of the quasi i-step sets (length of every planned sequence).
    polytopes : list of Polytope
        ``P_0 = T, P_1, ..., P_M``.
    boxes : list of tuple
        Per level ``m = 1..M``: ``(inner (N_m, n, 2), controls (N_m, steps, m),
        arrival (N_m,))``, the inner boxes of the m-th quasi set (towards ``P_{m-1}``) with
        their stored sequences (NaN after arrival).
    local_law : casadi.Function or None
        ``x -> u`` applied in T.
    nlp : dict
        The NLP (6.22)-(6.23): ``x`` the controls (``steps m``), ``p = [x, vec(H), h]``
        (the rows of the target polytope padded to ``rows``), ``f``, ``g``.
    plugin, options
        Solver plugin and options of the controller.
    rows : int
        r of the polytope parameter.
    nlp_rows : list of tuple
        Per target level ``j = 0..M-1``: ``(H (r, n), h (r,))``.
    lbx, ubx, lbg, ubg : ndarray
        Bounds of the NLP.
    W : ndarray (l, 2)
        The disturbance box the sets and every proof are about.
    """

    model: Any
    steps: int
    polytopes: list
    boxes: list
    local_law: ca.Function | None
    nlp: dict
    plugin: str
    options: dict
    rows: int
    nlp_rows: list
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    W: np.ndarray
    kind: str = "quasi"
