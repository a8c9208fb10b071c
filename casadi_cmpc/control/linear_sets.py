"""Exact one-step (pre-)sets and controllable-set sequences of linear models (thesis §3.4).

For ``x+ = A x + B u + E w + c`` with ``u`` in the box U and ``w`` in the box W,

    Pre(T) = {x : exists u in U such that A x + B u + E w + c in T for all w in W}

is computed exactly for a polytope ``T = {y : H y <= h}`` as the projection onto x of the
lifted polytope ``{(x, u) : H (A x + B u + c) <= h - max_{w in W} H E w, u in U}``
(Pontryagin difference for the disturbance). For a union of polytopes without disturbance,
``Pre(T_1 ∪ ... ∪ T_p) = Pre(T_1) ∪ ... ∪ Pre(T_p)`` exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..exceptions import ModelError
from ..model import Model
from ..sets.polytope import Polytope, PolytopeUnion

__all__ = ["pre_set", "linear_controllable_sets", "SetSequence"]


def _check_linear(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    if not isinstance(model, Model):
        raise TypeError(f"model must be a casadi_cmpc.Model; got {type(model).__name__}")
    if not model.is_linear:
        raise ModelError(
            f"pre_set computes exact pre-sets of linear models only; model '{model.name}' is "
            "nonlinear (use the interval-based one-step sets for nonlinear models)")
    return model.linear_matrices()


def _pre_polytope(model: Model, T: Polytope, within_X: bool) -> Polytope:
    A, B, E, c = _check_linear(model)
    n, m = model.n, model.m
    if T.dim != n:
        raise ValueError(f"target has dimension {T.dim}; the model has n = {n}")
    H, h = np.asarray(T.A), np.asarray(T.b)
    if model.l:
        # tighten by the support of E W in each row direction (exact for boxes)
        HE = H @ E
        W = model.W
        h = h - np.maximum(HE * W.lo, HE * W.hi).sum(axis=1)
    rows = [np.hstack([H @ A, H @ B])]
    rhs = [h - H @ c]
    if m:
        eye = np.eye(m)
        rows += [np.hstack([np.zeros((m, n)), eye]), np.hstack([np.zeros((m, n)), -eye])]
        rhs += [model.U.hi, -model.U.lo]
    if within_X:
        eye = np.eye(n)
        rows += [np.hstack([eye, np.zeros((n, m))]), np.hstack([-eye, np.zeros((n, m))])]
        rhs += [model.X.hi, -model.X.lo]
    lifted = Polytope(np.vstack(rows), np.concatenate(rhs))
    if m == 0:
        return lifted.minimal()
    return lifted.project(list(range(n))).minimal()


def pre_set(model: Model, target: Any, within_X: bool = True) -> Polytope | PolytopeUnion:
    """Exact one-step controllable set of a linear model to a target polytope or union.

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
        ``{x in X : exists u in U, A x + B u + E w + c in T for all w in W}``; for a union
        target, the union of the members' pre-sets (empty members dropped).

    Raises
    ------
    ModelError
        The model is not linear, or a union target is given for a model with disturbance.
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


@dataclass
class SetSequence:
    """A nested sequence of sets K_0 = T, K_1, K_2, ... (K_i: states controllable in i steps).

    Attributes
    ----------
    sets : list
        ``sets[i]`` is K_i (``sets[0]`` is the target); also ``seq[i]``.
    converged_at : int or None
        The first i with K_i = K_{i-1} (the maximal controllable set reached), else None.
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
             colorbar: bool = True, **kw: Any) -> Any:
        """Draw the sets from the largest (back) to the target (front), coloured by step,
        with a colour bar as the key (step i = K_i)."""
        import matplotlib as mpl
        import matplotlib.pyplot as plt

        from ..plot import new_axes, plot_boxes

        ax = new_axes(ax)
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
            members = S.polytopes if isinstance(S, PolytopeUnion) else (
                S.members if hasattr(S, "members") else [S])
            for P in members:
                if isinstance(P, Polytope) and not P.is_empty():
                    P.plot(ax=ax, dims=dims, facecolor=col, alpha=alpha,
                           edgecolor="k", **kw)
        if colorbar:
            sm = mpl.cm.ScalarMappable(norm=norm, cmap=cm_)
            ax.figure.colorbar(sm, ax=ax, label="step i (set K_i)")
        names = self.info.get("state_names")
        ax.set_xlabel(names[dims[0]] if names else f"x{dims[0] + 1}")
        ax.set_ylabel(names[dims[1]] if names else f"x{dims[1] + 1}")
        return ax

    # -------------------------------------------------------------- persistence
    def save(self, path: Any) -> Any:
        """Save the sequence exactly (sets, steps, status) to ``.npz`` or ``.json``."""
        from pathlib import Path

        from ..sets.base import _save_state

        state = {
            "sets": [{"type": S._type_name, "state": S._state()} for S in self.sets],
            "converged_at": -1 if self.converged_at is None else int(self.converged_at),
            "status": self.status,
            "steps": [{k: ({"type": v._type_name, "state": v._state()}
                           if hasattr(v, "_state") else v)
                       for k, v in st.items() if v is not None} for st in self.steps],
            "info": {k: v for k, v in self.info.items()
                     if isinstance(v, (str, int, float, bool, list, np.ndarray))},
        }
        return _save_state("SetSequence", state, Path(path))

    @classmethod
    def load(cls, path: Any) -> SetSequence:
        """Load a sequence written by :meth:`save`."""
        from ..sets.base import load_set

        obj = load_set(path)
        if not isinstance(obj, SetSequence):
            raise TypeError(f"{path} holds a {type(obj).__name__}, not a SetSequence")
        return obj

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> SetSequence:
        from ..sets.base import _TYPES

        def build(d: Any) -> Any:
            if isinstance(d, dict) and set(d) == {"type", "state"}:
                return _TYPES[d["type"]]._from_state(d["state"])
            return d

        sets = [build(d) for d in state["sets"]]
        steps = [{k: build(v) for k, v in st.items()} for st in state["steps"]]
        conv = int(state["converged_at"])
        return cls(sets=sets, converged_at=None if conv < 0 else conv,
                   info=dict(state.get("info", {})), status=str(state["status"]), steps=steps)


def _register() -> None:
    from ..sets.base import _TYPES

    _TYPES["SetSequence"] = SetSequence  # type: ignore[assignment]


_register()


def _same_set(S1: Any, S2: Any) -> bool:
    """Exact equality test of two polytopes or unions of polytopes."""
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
        ``converged_at`` is set when K_i equals K_{i-1} (exact comparison member by member).
    """
    seq = SetSequence(sets=[target])
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
