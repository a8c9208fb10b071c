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
        ``sets[i]`` is K_i (``sets[0]`` is the target).
    converged_at : int or None
        The first i with K_i = K_{i-1} (the maximal controllable set reached), else None.
    """

    sets: list = field(default_factory=list)
    converged_at: int | None = None
    info: dict = field(default_factory=dict)

    def level(self, x: Any) -> int | None:
        """Smallest i with x in K_i, or None when x lies in no set of the sequence."""
        for i, S in enumerate(self.sets):
            if S.contains(x):
                return i
        return None

    def __len__(self) -> int:
        return len(self.sets)

    def plot(self, ax: Any = None, cmap: str = "viridis", **kw: Any) -> Any:
        """Draw the sets from the largest (back) to the target (front)."""
        import matplotlib.pyplot as plt

        from ..plot import new_axes

        ax = new_axes(ax)
        colors = plt.get_cmap(cmap)(np.linspace(0.1, 0.9, max(len(self.sets), 2)))
        for i in range(len(self.sets) - 1, -1, -1):
            S = self.sets[i]
            members = S.polytopes if isinstance(S, PolytopeUnion) else [S]
            for P in members:
                P.plot(ax=ax, facecolor=colors[i], alpha=kw.get("alpha", 0.6),
                       edgecolor=kw.get("edgecolor", "k"))
        return ax


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
            break
        if pts is not None and np.all(K.contains(pts)):
            break
    return seq
