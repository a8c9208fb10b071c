r"""Outer bounds of reachable sets over a given control sequence (thesis §6.3.2, Def 6.2).

For ``x+ = f(x, u, w)``, an initial set ``X_0`` and controls ``u(0), ..., u(i-1)``, the
reachable sets are ``X(k+1) = f(X(k), u(k), W)`` (Def 6.2). Two sound outer bounds:

* ``method="zonotope"``: every step is the mean-value form bounded by Kühn's zonotope
  inclusion (thesis Thm 4.4, (4.14)-(4.16)), as :func:`casadi_cmpc.evolve`, with less
  wrapping effect;
* ``method="interval"``: every step is the natural interval inclusion of ``f`` over the
  box of the previous step (the "interval evolution" of Fig 6.10).

The batched kernels :func:`zonotope_step`, :func:`support_bounds` and :func:`box_of` act on
whole frontiers of zonotopes ``c_i ⊕ G_i B^p`` (arrays ``C (N, n)``, ``G (N, n, p)``) and are
shared with the quasi multi-step controllable sets (:mod:`casadi_cmpc.control.quasi`).
Every interval operation is rounded outward; a non-finite enclosure (overflow, NaN) gives
non-finite bounds, which no containment test accepts.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import as_boxes
from ..exceptions import DimensionError, InvalidBoundsError, ModelError
from . import _zono_num as zn
from .box import Box
from .zonotope import Zonotope

__all__ = ["reach"]

_METHODS = ("zonotope", "interval")


# ------------------------------------------------------------------ batched kernels
def box_zonotopes(boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes ``(N, n, 2)`` as zonotopes ``mid ⊕ diag(rad) B^n`` containing them.

    Returns
    -------
    C : ndarray (N, n)
    G : ndarray (N, n, n)
        Diagonal; the radius is rounded upward (:func:`_zono_num.midrad`).
    """
    c, r = zn.midrad(boxes[..., 0], boxes[..., 1])
    N, n = c.shape
    G = np.zeros((N, n, n))
    G[:, np.arange(n), np.arange(n)] = r
    return c, G


def box_of(C: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Outward-rounded bounding boxes ``(N, n, 2)`` of zonotopes ``C (N, n)``, ``G (N, n, p)``."""
    s = zn.sum_up(np.abs(G), axis=-1) if G.shape[-1] else np.zeros_like(C)
    return np.stack([zn.sub_dn(C, s), zn.add_up(C, s)], axis=-1)


def support_bounds(C: np.ndarray, G: np.ndarray, A: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Rigorous bounds of ``min`` and ``max`` of ``A x`` over each zonotope.

    Parameters
    ----------
    C : ndarray (N, n)
    G : ndarray (N, n, p)
    A : ndarray (r, n)
        Exact float rows.

    Returns
    -------
    lower, upper : ndarray (N, r)
        ``lower <= min_{x in Z} a.x`` and ``upper >= max_{x in Z} a.x`` per row (NaN where
        the zonotope is not finite).
    """
    A = np.asarray(A, dtype=float)
    c = C[:, :, None]
    dlo, dhi = zn.imatmul(A, A, c, c)  # (N, r, 1)
    if G.shape[-1]:
        glo, ghi = zn.imatmul(A, A, G, G)  # (N, r, p)
        s = zn.sum_up(np.maximum(np.abs(glo), np.abs(ghi)), axis=-1)
    else:
        s = np.zeros(dlo.shape[:-1])
    return zn.sub_dn(dlo[..., 0], s), zn.add_up(dhi[..., 0], s)


def _diag_stack(d: np.ndarray) -> np.ndarray:
    N, n = d.shape
    D = np.zeros((N, n, n))
    D[:, np.arange(n), np.arange(n)] = d
    return D


def reduce_order(G: np.ndarray, max_order: float | None) -> np.ndarray:
    """Girard's reduction of a batch ``G (N, n, p)`` to at most ``floor(max_order n)``
    generators (the smallest by ``||g||_1 - ||g||_inf`` are boxed, sums rounded upward)."""
    if max_order is None:
        return G
    N, n, p = G.shape
    cap = int(np.floor(float(max_order) * n))
    if p <= cap:
        return G
    keep_n = cap - n
    a = np.abs(G)
    score = a.sum(axis=1) - a.max(axis=1)  # (N, p)
    idx = np.argsort(-score, axis=1, kind="stable")
    keep = np.take_along_axis(G, idx[:, None, :keep_n], axis=2)
    rest = np.take_along_axis(a, idx[:, None, keep_n:], axis=2)
    return np.concatenate([keep, _diag_stack(zn.sum_up(rest, axis=-1))], axis=2)


def jacobian_bounds(model: Any, C: np.ndarray, G: np.ndarray, U: np.ndarray,
                    W: np.ndarray) -> np.ndarray:
    """Interval Jacobian ``∇_x f`` over the bounding boxes of the zonotopes: (N, n, n, 2)."""
    return model.jacobian_inclusion("x")(box_of(C, G), U, W)


def zonotope_step(model: Any, C: np.ndarray, G: np.ndarray, U: np.ndarray, W: np.ndarray,
                  J: np.ndarray | None = None, inclusion: str = "natural",
                  max_order: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    r"""One step of uncertain evolution of a batch of zonotopes (Thm 4.4, batched).

    Parameters
    ----------
    model : Model
    C : ndarray (N, n)
        Centres.
    G : ndarray (N, n, p)
        Generators.
    U : ndarray (N or 1, m, 2)
        Control boxes (thin for a fixed control).
    W : ndarray (1, l, 2)
        Disturbance box.
    J : ndarray (N, n, n, 2), optional
        An interval Jacobian ``∇_x f`` valid over the bounding boxes of the zonotopes, the
        controls ``U`` and ``W`` (computed when omitted). One computed over a larger control
        box may be passed.
    inclusion : {"natural", "centered"}
        Inclusion of ``f(c, U, W)``.
    max_order : float, optional
        Reduce the results to at most ``floor(max_order n)`` generators.

    Returns
    -------
    C2 : ndarray (N, n)
    G2 : ndarray (N, n, p + n)
        ``Mid[f(c, U, W)] ⊕ Mid[J G] B^p ⊕ diag(Rad[f(c, U, W)] + sum_j Rad[J G]_{:j}) B^n``,
        which contains ``f(x, u, w)`` for every ``x`` of the zonotope, ``u`` of ``U`` and
        ``w`` of ``W``. Rows where the mean-value form is not available (``f_i`` may jump
        on the bounding box, or its Jacobian is unbounded) are the natural interval
        enclosure over the bounding box. A non-finite enclosure leaves non-finite
        entries (never accepted by :func:`support_bounds` comparisons).
    """
    N, n = C.shape
    P = np.stack([C, C], axis=-1)
    fp = model.inclusion(inclusion)(P, U, W)  # (N, n, 2)
    if J is None:
        J = jacobian_bounds(model, C, G, U, W)
    mvt = np.isfinite(fp).all(axis=-1) & np.isfinite(J).all(axis=(-1, -2))  # (N, n)
    if not mvt.all():
        hull = model.inclusion("natural")(box_of(C, G), U, W)
        fp = np.where(mvt[..., None], fp, hull)
        J = np.where(mvt[..., None, None], J, 0.0)
    Mlo, Mhi = zn.imatmul(J[..., 0], J[..., 1], G, G)  # (N, n, p)
    q, qrad = zn.midrad(fp[..., 0], fp[..., 1])
    Mmid, Mrad = zn.midrad(Mlo, Mhi)
    with np.errstate(invalid="ignore", over="ignore"):
        diag = zn.add_up(qrad, zn.sum_up(Mrad, axis=-1)) if G.shape[-1] else qrad
    bad = ~(np.isfinite(q).all(axis=1) & np.isfinite(diag).all(axis=1)
            & np.isfinite(Mmid).all(axis=(1, 2)))
    if bad.any():  # an overflow or NaN: the whole zonotope becomes non-finite
        q = q.copy()
        q[bad] = np.nan
    G2 = np.concatenate([Mmid, _diag_stack(diag)], axis=2)
    return q, reduce_order(G2, max_order)


def refine(C: np.ndarray, G: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Intersect zonotopes with boxes known to hold the same states, row by row.

    Where the box ``B_i`` (N, n, 2) is tighter than the zonotope's extent in coordinate
    ``i``, row ``i`` of the zonotope is replaced by the interval ``box(Z)_i ∩ B_i`` as an
    independent generator (its other generator entries set to 0). Every state in both the
    zonotope and the box stays inside (the other rows keep their generators; row ``i`` is
    free in the intersection), and the bounding box of the result is ``box(Z) ∩ B``.

    Returns
    -------
    C2 : ndarray (N, n)
    G2 : ndarray (N, n, p + n)
    """
    bz = box_of(C, G)
    lo = np.maximum(bz[..., 0], B[..., 0])
    hi = np.minimum(bz[..., 1], B[..., 1])
    with np.errstate(invalid="ignore"):
        tighter = (lo > bz[..., 0]) | (hi < bz[..., 1])
        tighter &= lo <= hi  # (an empty intersection cannot occur for sound bounds)
        tighter &= np.isfinite(lo) & np.isfinite(hi)
    N, n = C.shape
    extra = np.zeros((N, n))
    if not tighter.any():
        return C, np.concatenate([G, _diag_stack(extra)], axis=2)
    mid, rad = zn.midrad(lo, hi)
    C2 = np.where(tighter, mid, C)
    G2 = np.where(tighter[..., None], 0.0, G)
    extra = np.where(tighter, rad, 0.0)
    return C2, np.concatenate([G2, _diag_stack(extra)], axis=2)


def hybrid_step(model: Any, C: np.ndarray, G: np.ndarray, U: np.ndarray, W: np.ndarray,
                J: np.ndarray | None = None, inclusion: str = "natural",
                max_order: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`zonotope_step` refined (:func:`refine`) by the natural interval enclosure
    ``f(box(Z), U, W)``: the bounding box of the result is inside that of one interval
    step from the bounding box of ``Z``, and inside that of the plain zonotope step."""
    Cn, Gn = zonotope_step(model, C, G, U, W, J=J, inclusion=inclusion)
    B = interval_step(model, box_of(C, G), U, W)
    Cn, Gn = refine(Cn, Gn, B)
    Gn = Gn[:, :, np.any(Gn != 0, axis=(0, 1))] if Gn.shape[0] else Gn
    return Cn, reduce_order(Gn, max_order)


def interval_step(model: Any, X: np.ndarray, U: np.ndarray, W: np.ndarray) -> np.ndarray:
    """One step of interval evolution: the natural inclusion ``f(X, U, W)`` (N, n, 2)."""
    return model.inclusion("natural")(X, U, W)


# ------------------------------------------------------------------ public function
def _controls(u_seq: Any, m: int) -> np.ndarray:
    """Control sequence as boxes (steps, m, 2)."""
    if isinstance(u_seq, Box):
        u_seq = [u_seq]
    if isinstance(u_seq, (list, tuple)) and any(isinstance(v, Box) for v in u_seq):
        arr = np.stack([as_boxes(v, m, "u_seq[k]")[0] for v in u_seq])
    else:
        a = np.asarray(u_seq, dtype=float)
        if a.ndim == 3 and a.shape[1:] == (m, 2):
            arr = a.copy()
        else:
            if a.ndim == 1 and m == 1:
                a = a[:, None]
            if a.ndim != 2 or a.shape[1] != m:
                raise DimensionError(
                    f"u_seq must have shape (steps, {m}) (controls) or (steps, {m}, 2) "
                    f"(control boxes); got shape {a.shape}")
            arr = np.stack([a, a], axis=-1)
    if arr.shape[0] < 1:
        raise ValueError("u_seq must hold at least one step")
    if not np.isfinite(arr).all():
        raise InvalidBoundsError("u_seq must be finite (no NaN or inf)")
    if np.any(arr[..., 0] > arr[..., 1]):
        raise InvalidBoundsError("a control box of u_seq has lo > hi")
    return arr


def reach(model: Any, X0: Any, u_seq: Any, method: str = "zonotope", W: Any = None,
          max_order: float | None = None, inclusion: str = "natural",
          refine: bool = True) -> list[Any]:
    r"""Outer bounds of the reachable sets ``X(0), X(1), ..., X(i)`` over a given control
    sequence.

    Thesis Def 6.2 and §6.3.2: ``X(k+1) = f(X(k), u(k), W)``; the zonotope bounds are the
    evolution of Fig 6.10 with reduced wrapping effect, the interval bounds the natural
    interval evolution it is compared with. Works for any state dimension.

    Parameters
    ----------
    model : Model
        ``x+ = f(x, u, w)``.
    X0 : Box, Zonotope or array_like (n, 2)
        Initial set (a Zonotope only with ``method="zonotope"``; with ``"interval"`` its
        bounding box is used).
    u_seq : array_like (i, m) or (i, m, 2), or list of Box
        The controls ``u(0), ..., u(i-1)`` (points), or boxes of controls (then the bounds
        hold for every control sequence in the boxes, e.g. ``U`` at every step). For
        ``m = 1`` a flat array of length i is accepted.
    method : {"zonotope", "interval"}
    W : Box or array_like (l, 2), optional
        Disturbance box (default: the model's W). Ignored for a model without w.
    max_order : float, optional
        Zonotope method: reduce each step to at most ``floor(max_order n)`` generators
        (Girard); none by default (each step adds n generators).
    inclusion : {"natural", "centered"}
        Zonotope method: the inclusion of ``f`` at the centre (the Jacobian part is always
        the natural interval Jacobian over the bounding box).
    refine : bool
        Zonotope method: intersect every step with one natural interval step from the
        previous bounding box (:func:`hybrid_step`): a coordinate where the interval bound
        is tighter becomes that (independent) interval. Then the bounding box of every
        step lies inside that of the interval evolution (the natural inclusion is
        inclusion-isotone) and inside that of the plain zonotope step. ``False``: the
        plain zonotope evolution of the thesis (Kühn's inclusion only), whose boxes may be
        larger than the interval ones where the mean-value form overestimates a
        nonlinearity (e.g. ``x1^2`` on a box away from 0).

    Returns
    -------
    list of Zonotope or Box, length i + 1
        ``[X(0), X(1), ..., X(i)]``. Every state ``x(k)`` of a trajectory from ``x(0)`` in
        ``X0`` under the given controls and any disturbances in W lies in the k-th set
        (outward rounding throughout). A step whose enclosure overflowed is a Box with
        infinite bounds.

    Raises
    ------
    DimensionError, ValueError
        Wrong shapes, an unknown method, or a model without input.

    Examples
    --------
    >>> import casadi_cmpc as cm
    >>> from casadi_cmpc.sets._reach import reach
    >>> ex = cm.models.load("khalil_affine_control")
    >>> Z = reach(ex.model, cm.Box([0.1, 0.1], [0.2, 0.2]), [[-1.0], [-1.0]])
    >>> len(Z), type(Z[-1]).__name__
    (3, 'Zonotope')
    """
    meth = str(method).lower()
    if meth not in _METHODS:
        raise ValueError(f"method must be one of {_METHODS}; got {method!r}")
    n, m = model.n, model.m
    if m == 0:
        raise ModelError(f"model '{model.name}' has no input: reach() follows a control "
                         "sequence")
    useq = _controls(u_seq, m)
    Wb = (as_boxes(model.W_box if W is None else W, model.l, "W")
          if model.l else np.zeros((1, 0, 2)))
    if isinstance(X0, Zonotope):
        if X0.dim != n:
            raise DimensionError(f"X0 has dimension {X0.dim}; the model has n = {n}")
        if meth == "interval":
            X0 = X0.bounding_box()
    if isinstance(X0, Zonotope):
        C, G = X0.center[None].copy(), X0.generators[None].copy()
        first: Any = X0
    else:
        box = as_boxes(X0, n, "X0")
        if box.shape[0] != 1:
            raise DimensionError(f"X0 must be one box; got a batch of {box.shape[0]}")
        if not np.isfinite(box).all():
            raise InvalidBoundsError("X0 must be bounded")
        first = Box.from_array(box[0])
        C, G = box_zonotopes(box)
    out: list[Any] = [first if meth == "interval" or isinstance(first, Zonotope)
                      else Zonotope(C[0], G[0][:, np.any(G[0] != 0, axis=0)])]
    X = box.copy() if meth == "interval" else None
    unbounded = Box(np.full(n, -np.inf), np.full(n, np.inf))
    for k in range(useq.shape[0]):
        Uk = useq[k][None]
        if isinstance(out[-1], Box) and not out[-1].is_bounded():
            out.append(unbounded)  # an overflow stays an overflow
            continue
        if meth == "zonotope":
            step = hybrid_step if refine else zonotope_step
            C, G = step(model, C, G, Uk, Wb, inclusion=inclusion, max_order=max_order)
            if not (np.isfinite(C).all() and np.isfinite(G).all()):
                out.append(unbounded)
                continue
            Gk = G[0][:, np.any(G[0] != 0, axis=0)]
            out.append(Zonotope(C[0], Gk))
        else:
            X = interval_step(model, X, Uk, Wb)
            if not np.isfinite(X).all() or np.any(X[..., 0] > X[..., 1]):
                out.append(unbounded)
                continue
            out.append(Box.from_array(X[0]))
    return out
