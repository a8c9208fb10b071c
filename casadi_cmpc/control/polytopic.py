"""One polytope proven inside a union of boxes or polytopes (thesis §6.1.3, §6.2.3).

A controllable set computed by set inversion is a union of boxes (or, with an affine state
part, a union of polytopes). :func:`inner_polytope` replaces it by **one** polytope
``P ⊆ ∪ S_i`` by either of the thesis' algorithms:

``"separating"`` (Alg 6.2, the revised polytopic approximation, eqs (6.4)-(6.6))
    The convex hull ``H`` of the union is cut by one ``α``-support hyperplane per piece of
    the complement ``C = H \\ ∪ S_i = ∪ C_m`` that still meets the current polytope.
``"scaling"`` (Alg 6.5, hull scaling by bisection)
    The largest ``α`` in ``[0, 1]`` (to ``eps``) with ``x0 + α (H - x0) ⊆ ∪ S_i``.

Whatever the method, the polytope returned is accepted only after the exact covering test
:meth:`Polytope.is_subset` against the :class:`PolytopeUnion` succeeded on its stored rows.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np

from .._validate import as_boxes
from ..exceptions import DimensionError, EmptySetError, UnboundedSetError
from ..sets import _lp
from ..sets._poly_ops import subset_of_union
from ..sets.box import Box
from ..sets.paving import Paving
from ..sets.polytope import Polytope, PolytopeUnion, hull
from ..solvers.result import Certificate

__all__ = ["inner_polytope", "InnerPolytope"]

_METHODS = ("separating", "scaling")
_ORDERS = ("gamma", "given")


class InnerPolytope(NamedTuple):
    """Result of :func:`inner_polytope`: unpacks as ``P, cert = inner_polytope(...)``.

    Attributes
    ----------
    polytope : Polytope
        Proven inside the union when ``certificate.proved`` is True; the empty polytope
        otherwise.
    certificate : Certificate
        ``label="proved"`` (``proved=True``) or ``label="undecided"`` (``proved=None``);
        ``details`` holds the numbers of the run (see :func:`inner_polytope`).
    """

    polytope: Polytope
    certificate: Certificate


# ------------------------------------------------------------------ inputs
def _members_of(boxes: Any) -> tuple[list[Polytope], np.ndarray | None, str]:
    """The full-dimensional members of the union, the box array (None for polytopes) and
    a word for the kind of input."""
    if isinstance(boxes, Paving):
        arr, kind = np.asarray(boxes.inner, dtype=float), "Paving (inner boxes)"
        if arr.shape[0] == 0:
            raise EmptySetError("the Paving has no inner box: there is no union to approximate")
    elif isinstance(boxes, (PolytopeUnion, Polytope)) or (
            isinstance(boxes, (list, tuple)) and len(boxes)
            and all(isinstance(P, Polytope) for P in boxes)):
        if isinstance(boxes, PolytopeUnion):
            U = boxes
        else:  # checks the dimensions
            U = PolytopeUnion([boxes] if isinstance(boxes, Polytope) else list(boxes))
        members = []
        for i, P in enumerate(U.polytopes):
            if P.is_empty():
                continue
            if not P.is_bounded():
                raise UnboundedSetError(
                    f"member {i} of the union is unbounded; intersect it with a Box first")
            if P.is_full_dimensional():  # a flat member covers no open set: it cannot help
                members.append(P)
        if not members:
            raise EmptySetError(
                "the union has no member with an interior point (all members are empty or "
                "flat): there is no polytope with interior inside it")
        return members, None, "union of polytopes"
    else:
        if isinstance(boxes, (list, tuple)) and len(boxes) and all(
                isinstance(B, Box) for B in boxes):
            boxes = np.stack([B.as_array() for B in boxes])
        if isinstance(boxes, (list, tuple)) and len(boxes) == 0:
            raise EmptySetError("the union is empty: give at least one box")
        arr = as_boxes(boxes, None, "boxes")
        kind = "union of boxes"
    if arr.shape[0] == 0:
        raise EmptySetError("the union is empty: give at least one box (shape (N, n, 2), N >= 1)")
    if not np.isfinite(arr).all():
        raise UnboundedSetError("boxes must have finite bounds; a box has an infinite bound")
    full = (arr[..., 1] > arr[..., 0]).all(axis=1)
    if not full.any():
        raise EmptySetError(
            "no box of the union has positive widths in every coordinate: the union has no "
            "interior, so no polytope with interior lies inside it")
    arr = _merge_boxes(arr[full])
    kind = f"{kind} ({int(full.sum())} with interior, {arr.shape[0]} after merging)"
    return [Polytope.from_box(B) for B in arr], arr, kind


def _merge_boxes(arr: np.ndarray) -> np.ndarray:
    """The same union with fewer boxes: two boxes with equal bounds in all coordinates but
    one, whose intervals in that one overlap or touch, become one box (their union,
    exactly: bounds are copied, never computed). Repeated over the axes until stable."""
    n = arr.shape[1]
    changed = True
    while changed and arr.shape[0] > 1:
        changed = False
        for k in range(n):
            others = np.delete(arr, k, axis=1).reshape(arr.shape[0], -1)
            order = np.lexsort((arr[:, k, 0],) + tuple(others.T[::-1]))
            arr, others = arr[order], others[order]
            out = [arr[0].copy()]
            for i in range(1, arr.shape[0]):
                cur = out[-1]
                if np.array_equal(others[i], others[i - 1]) and arr[i, k, 0] <= cur[k, 1]:
                    cur[k, 1] = max(cur[k, 1], arr[i, k, 1])
                    changed = True
                else:
                    out.append(arr[i].copy())
            arr = np.stack(out)
    return arr


def _interior_proven(U: PolytopeUnion, x: np.ndarray, scale: float) -> bool:
    """``x`` is proven interior to the union: a small box around it is covered (exact)."""
    if not np.isfinite(x).all():
        return False
    h = 1e-7 * scale + 4 * np.spacing(np.abs(x).max(initial=1.0))
    box = np.stack([x - h, x + h], axis=-1)[None]
    return bool(U.contains_box(box)[0])


def _default_centers(members: list[Polytope], arr: np.ndarray | None, H: Polytope,
                     U: PolytopeUnion, scale: float) -> list[tuple[np.ndarray, str]]:
    """The candidate interior points: the Chebyshev centre of the hull when it is proven
    interior to the union, and the centre of the largest member."""
    out = []
    c = H.chebyshev_ball()[0]
    if _interior_proven(U, c, scale):
        out.append((c, "Chebyshev centre of the convex hull (proven interior to the union)"))
    if arr is not None:
        vol = np.prod(arr[..., 1] - arr[..., 0], axis=1)
        k = int(np.argmax(vol))
        c = 0.5 * arr[k, :, 0] + 0.5 * arr[k, :, 1]
        what = f"centre of the largest box (box {k})"
    else:
        radii = [P.chebyshev_ball()[1] for P in members]
        k = int(np.argmax(radii))
        c = members[k].chebyshev_ball()[0]
        what = f"Chebyshev centre of the member with the largest inscribed ball ({k})"
    if not out or np.abs(out[0][0] - c).max() > 1e-6 * scale:
        out.append((c, what))
    return out


# ------------------------------------------------------------------ proofs
class _Prover:
    """The exact covering test ``P ⊆ U`` on full-dimensional P, after cheap refutations.

    1. Probe points of P (its float vertices pulled toward its Chebyshev centre by
       ``1e-9`` relative, and seeded random points of its bounding box that P contains):
       one outside every member rejects P (not proven; a failed covering test can cost
       much more than a passed one, as the pieces outside the union keep splitting).
    2. Members whose bounding boxes miss the bounding box of P (both rigorous, outward)
       cannot cover a point of P and are left out of the proof.
    3. :meth:`Polytope.is_subset` against the union of the remaining members.

    For a union of boxes, step 3 is first tried on the grid of the boxes' bounds
    (:meth:`casadi_cmpc.sets._boxunion._BoxGrid.polytope_inside`: every uncovered cell meeting
    P's rigorous bounding box is proven disjoint from P), whose answer is final there.

    Only step 3 can answer True; steps 1-2 err toward "not proven" only.
    """

    def __init__(self, members: list[Polytope], mboxes: np.ndarray, n_probe: int = 256,
                 boxes: np.ndarray | None = None) -> None:
        from ..sets._boxunion import _BoxGrid

        # a union of boxes: the exact grid of their bounds decides most candidates fast
        self.grid = _BoxGrid.build(boxes) if boxes is not None and boxes.shape[0] else None
        self.members = members
        self.mboxes = mboxes
        self.U = PolytopeUnion(members)
        self.n_probe = int(n_probe)
        self.calls = 0  # candidates tested
        self.proofs = 0  # exact covering tests run
        self.exhausted = 0  # covering tests stopped by their budget ("not proven")

    def _probes(self, P: Polytope) -> np.ndarray:
        n = P.dim
        c = P.chebyshev_ball()[0]
        pts = [c[None]]
        try:
            V = P.vertices()
            pts.append(c + (1.0 - 1e-9) * (V - c))
        except Exception:  # noqa: BLE001 - no vertex list: random probes only
            pass
        bb = P.bounding_box()
        rng = np.random.default_rng(self.calls)
        X = rng.uniform(bb.lo, bb.hi, size=(self.n_probe, n))
        pts.append(X[P.contains(X)])
        return np.vstack(pts)

    def __call__(self, P: Polytope) -> bool:
        self.calls += 1
        if P.is_empty() or not P.is_bounded() or not P.is_full_dimensional():
            return False  # only the full-dimensional branch of is_subset is a proof
        if not np.all(self.U.contains(self._probes(P))):
            return False
        if self.grid is not None:
            self.proofs += 1
            # the grid answer is final: a P it cannot prove touches an uncovered cell, which
            # the exact covering would mostly refute at a much higher cost
            return bool(self.grid.polytope_inside(P))
        bb = P.bounding_box().as_array()
        keep = ~((self.mboxes[:, :, 0] > bb[:, 1]) | (self.mboxes[:, :, 1] < bb[:, 0])
                 ).any(axis=1)
        if not keep.any():
            return False
        sub = PolytopeUnion([self.members[i] for i in np.flatnonzero(keep)])
        self.proofs += 1
        status = subset_of_union(P, sub)
        self.exhausted += status == "budget exhausted"
        return status == "proved"


def _scaled(A: np.ndarray, b: np.ndarray, x0: np.ndarray, alpha: float) -> Polytope:
    """``x0 + alpha (P - x0)`` for ``P = {A x <= b}`` (rounded: the proof is on the result)."""
    Ax0 = A @ x0
    return Polytope(A, Ax0 + alpha * (b - Ax0))


def _scale_search(A: np.ndarray, b: np.ndarray, x0: np.ndarray, prove: _Prover, eps: float,
                  one_failed: bool = False) -> tuple[Polytope | None, float]:
    """Largest proven ``alpha`` (to ``eps``) with ``x0 + alpha (P - x0) ⊆ U`` (Alg 6.5).

    ``alpha -> x0 + alpha (P - x0)`` is nested for ``x0 in P``, so the proven values of
    ``alpha`` form an interval ``[0, a*]`` up to the numerics of the test; bisection keeps
    the last proven polytope. ``alpha = 1`` is tried first, then ``1 - 2^-40`` and
    ``1 - 2^-20`` (a candidate that sticks out by rounding only, e.g. a hull whose
    right-hand sides were rounded outward), then bisection on ``[0, 1 - 2^-20]``. When
    nothing is proven down to ``eps``, ``alpha`` keeps halving down to ``1e-9``.
    """
    tries = ([] if one_failed else [1.0]) + [1.0 - 2.0 ** -40, 1.0 - 2.0 ** -20]
    for a in tries:
        P = _scaled(A, b, x0, a)
        if prove(P):
            return P, a
    lo, hi, best = 0.0, tries[-1], None
    while hi - lo > eps:
        mid = 0.5 * (lo + hi)
        P = _scaled(A, b, x0, mid)
        if prove(P):
            lo, best = mid, P
        else:
            hi = mid
    while best is None and hi > 1e-9:
        hi *= 0.5
        P = _scaled(A, b, x0, hi)
        if prove(P):
            lo, best = hi, P
    return best, lo


# --------------------------------------------------------- Alg 6.2 pieces
def _complement(H: Polytope, members: list[Polytope], boxes: np.ndarray,
                max_pieces: int) -> list[Polytope] | None:
    """``C = H \\ ∪ members`` as closed pieces (None beyond ``max_pieces``).

    Member by member, every piece is split by :meth:`Polytope.difference`, except where the
    bounding box of the piece (from its floating-point vertices) and the box of the member
    have disjoint interiors (the piece is kept whole) or the box of the piece lies in a box
    member (the piece is dropped). These shortcuts are heuristic, like the whole
    construction of the candidate: the final covering test decides.
    """
    pieces = [H]
    for M, mb in zip(members, boxes, strict=True):
        is_box = M.n_constraints == 2 * M.dim and bool(
            np.array_equal(M.A, np.vstack([np.eye(M.dim), -np.eye(M.dim)])))
        new: list[Polytope] = []
        for P in pieces:
            try:
                V = P.vertices()
                lo, hi = V.min(axis=0), V.max(axis=0)
            except Exception:  # noqa: BLE001 - no vertex list: split by LPs
                lo, hi = np.full(M.dim, -np.inf), np.full(M.dim, np.inf)
            if np.any(hi <= mb[:, 0]) or np.any(lo >= mb[:, 1]):
                new.append(P)
            elif is_box and np.all(lo >= mb[:, 0]) and np.all(hi <= mb[:, 1]):
                continue
            else:
                new.extend(P.difference(M).polytopes)
        pieces = new
        if len(pieces) > max_pieces:
            return None
        if not pieces:
            break
    return pieces


def _grid_complement(H: Polytope, grid: Any, max_pieces: int) -> list[Polytope] | None:
    """``H`` minus the union for a union of boxes, from the grid of their bounds: the uncovered
    cells meeting the (rigorous) bounding box of H, merged into runs along the first
    coordinate, each intersected with H (None beyond ``max_pieces``). Heuristic like the
    whole candidate construction: the final covering test decides."""
    n = len(grid.edges)
    D = np.vstack([np.eye(n), -np.eye(n)])
    up = H._support_upper(D)
    i0, i1 = [], []
    for j in range(n):
        e = grid.edges[j]
        a = max(int(np.searchsorted(e, -up[n + j], side="left")) - 1, 0)
        b = min(int(np.searchsorted(e, up[j], side="right")), e.size - 1)
        i0.append(a)
        i1.append(max(b, a + 1))
    unc = ~grid.covered[tuple(slice(a, b) for a, b in zip(i0, i1, strict=True))]
    # runs of uncovered cells along axis 0 (for fixed other indices)
    runs = []
    moved = np.moveaxis(unc, 0, -1)
    for idx in np.ndindex(moved.shape[:-1]):
        line = moved[idx]
        k = 0
        L = line.size
        while k < L:
            if line[k]:
                k2 = k
                while k2 + 1 < L and line[k2 + 1]:
                    k2 += 1
                runs.append((k, k2, idx))
                k = k2 + 1
            else:
                k += 1
        if len(runs) > 4 * max_pieces:
            return None
    pieces = []
    for k, k2, idx in runs:
        lo = np.empty(n)
        hi = np.empty(n)
        lo[0], hi[0] = grid.edges[0][i0[0] + k], grid.edges[0][i0[0] + k2 + 1]
        for j in range(1, n):
            c = idx[j - 1] + i0[j]
            lo[j], hi[j] = grid.edges[j][c], grid.edges[j][c + 1]
        P = Polytope(np.vstack([H.A, np.eye(n), -np.eye(n)]), np.concatenate([H.b, hi, -lo]))
        if not P.is_empty() and P.is_full_dimensional():
            pieces.append(P)
        if len(pieces) > max_pieces:
            return None
    return pieces


def _alpha_support(pieces: list[np.ndarray], VH: np.ndarray, margin: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """LP (6.4)-(6.5) for every piece, in coordinates centred at the interior point.

    ``min γ`` over ``(c, γ)`` s.t. ``c.w_j >= 1 + margin`` (the thesis' strict ``> 1``)
    for the vertices ``w_j`` of the piece, ``c.v_k <= γ`` for the vertices ``v_k`` of the
    hull, ``γ >= 1``. Returns ``c`` (K, n), ``γ`` (K,) and the LP status (K,).
    """
    K = len(pieces)
    n = VH.shape[1]
    rows, rhs, blk = [], [], []
    for k, W in enumerate(pieces):
        rows.append(np.hstack([-W, np.zeros((W.shape[0], 1))]))
        rhs.append(np.full(W.shape[0], -(1.0 + margin)))
        rows.append(np.hstack([VH, -np.ones((VH.shape[0], 1))]))
        rhs.append(np.zeros(VH.shape[0]))
        blk.append(np.full(W.shape[0] + VH.shape[0], k))
    C = np.zeros((K, n + 1))
    C[:, -1] = 1.0
    lb = np.full((K, n + 1), -np.inf)
    lb[:, -1] = 1.0
    res = _lp.block_lp(C, np.vstack(rows), np.concatenate(rhs), np.concatenate(blk), lb,
                       np.inf)
    return res.x[:, :n], res.x[:, -1], res.status


def _separating(H: Polytope, pieces: list[Polytope], x0: np.ndarray, s: float,
                margin: float, order: str, details: dict) -> Polytope:
    """Alg 6.2: the hull cut by the α-support hyperplanes of the complement pieces
    (the candidate, not yet proven)."""
    if not pieces:  # the union is convex (up to slivers): the hull itself
        details["n_cuts"] = 0
        return H
    # translated and scaled coordinates y = (x - x0) / s: the origin is interior
    VH = (H.vertices() - x0) / s
    Ws, has_v = [], np.ones(len(pieces), dtype=bool)
    for i, P in enumerate(pieces):
        try:
            Ws.append((P.vertices() - x0) / s)
        except Exception:  # noqa: BLE001 - a piece without a vertex list gets no cut
            Ws.append(np.ones((1, H.dim)))
            has_v[i] = False
    c, gam, st = _alpha_support(Ws, VH, margin)
    ok = (st == _lp.OPTIMAL) & has_v
    details["lp_failures"] = int((~ok).sum())
    idx = np.flatnonzero(ok)
    if order == "gamma":  # the deepest pieces (largest γ) first: their cuts are forced
        idx = idx[np.argsort(-gam[idx], kind="stable")]
    # cuts c.(x - x0)/s <= 1 in the original coordinates: (c/s).x <= 1 + (c/s).x0
    A_cut = c / s
    b_cut = 1.0 + A_cut @ x0
    chosen: list[int] = []
    A_cur, b_cur = np.array(H.A), np.array(H.b)
    nh = H.n_constraints
    for k in idx.tolist():
        Pk = pieces[k]
        Wk = Ws[k] * s + x0
        if chosen and np.any(np.all(Wk @ A_cur[nh:].T > b_cur[nh:], axis=0)):
            continue  # an earlier hyperplane already separates this piece (thesis' test)
        meet = Polytope(np.vstack([Pk.A, A_cur]), np.concatenate([Pk.b, b_cur]))
        if not meet.is_full_dimensional():
            continue  # C_m ∩ P^a has no interior point (Step 5)
        chosen.append(k)
        A_cur = np.vstack([A_cur, A_cut[k:k + 1]])
        b_cur = np.append(b_cur, b_cut[k])
    details["n_cuts"] = len(chosen)
    details["gamma"] = gam[chosen].tolist()
    P = Polytope(A_cur, b_cur)
    try:
        return P.minimal()
    except Exception:  # noqa: BLE001 - redundancy removal is cosmetic; prove P itself
        return P


# ------------------------------------------------------------------ public
def inner_polytope(boxes: Any, method: str = "separating", *, eps: float = 1e-3,
                   center: Any = None, margin: float = 1e-6, order: str = "gamma",
                   max_pieces: int = 5000) -> InnerPolytope:
    """One polytope proven inside a union of boxes or polytopes (thesis Alg 6.2 / 6.5).

    Parameters
    ----------
    boxes : array_like (N, n, 2), Box, list of Box, Paving, PolytopeUnion, list of Polytope
        The union ``S = ∪ S_i``. For a :class:`Paving` its ``inner`` boxes (the part proven
        inside the target set). Members without interior (flat boxes, flat or empty
        polytopes) are dropped: they cannot cover an open set. Boxes with equal bounds in
        all coordinates but one, overlapping or touching in that one, are merged first
        (exactly: bounds are copied; the union is unchanged, with fewer members).
    method : {"separating", "scaling"}
        ``"separating"``: Alg 6.2, the revised polytopic approximation. ``H = hull(S)``
        (Qhull); the complement ``C = H \\ S`` as closed pieces ``C_m``
        (:meth:`PolytopeUnion.difference`); per piece the LP (6.4)-(6.5) in the
        coordinates ``y = (x - x0) / s`` (the form ``c.y <= 1`` needs the origin inside,
        hence the translation to the interior point ``x0``; ``s`` is the extent of the
        hull): ``min γ`` s.t. ``c.w_j >= 1 + margin`` on the vertices of ``C_m`` (the
        thesis' strict ``c.w > 1``) and ``c.v_k <= γ`` on the vertices of ``H``; then
        (Steps 4-9, eq (6.6)) ``P = H ∩ {c_m.y <= 1}`` over the pieces that still meet P
        (with interior) when their turn comes. ``"scaling"``: Alg 6.5, the largest
        ``α in [0, 1]`` found by bisection (to ``eps``) with
        ``x0 + α (H - x0) ⊆ S`` proven (``α = 1`` is tried first).
    eps : float
        Bisection tolerance on ``α`` (``0 < eps < 1``): for ``"scaling"``, and for the
        shrinking fallback of ``"separating"``.
    center : array_like (n,), optional
        The interior point ``x0`` (the thesis uses the origin). It must be proven interior
        to ``S`` (a box of half-width ``1e-7`` of the extent of ``H`` around it is proven
        covered), else ``ValueError``. Default: two candidates, the Chebyshev centre of
        ``H`` when it is proven interior to ``S`` and the centre of the largest box (for
        polytopes: the Chebyshev centre of the member with the largest inscribed ball);
        the method runs from each and the proven polytope of larger volume is returned
        (both are listed in ``details["candidates"]``).
    margin : float
        The strict inequality ``c.w > 1`` of (6.5) as ``c.w >= 1 + margin`` (scaled
        coordinates; ``> 0``).
    order : {"gamma", "given"}
        Processing order of the pieces in Alg 6.2: by decreasing optimal ``γ`` (the
        pieces nearest ``x0`` first, whose cuts are forced; later pieces are then often
        already separated) or as :meth:`~Polytope.difference` produced them (the thesis).
    max_pieces : int
        Budget on the number of complement pieces (which can grow exponentially with the
        number of members, thesis §6.2.3); beyond it ``"separating"`` answers undecided.

    Returns
    -------
    InnerPolytope
        ``(polytope, certificate)``, unpackable. ``certificate.details``: ``method``,
        ``center``, ``center_rule``, ``alpha`` (the proven scale factor: ``α`` of Alg 6.5,
        or the shrink factor applied to the cut polytope of Alg 6.2, 1 when none was
        needed), ``n_members``, ``n_pieces``/``n_cuts``/``gamma`` (Alg 6.2), ``n_tests``
        (candidates tested), ``n_proofs`` (exact covering tests run on them),
        ``n_budget_exhausted`` (covering tests stopped by their budget: those candidates
        count as not proven, never as refuted), ``candidates`` (default centre), ``seconds``.

    Raises
    ------
    ValueError
        Unknown ``method``/``order``, ``eps`` or ``margin`` out of range, or ``center``
        not proven interior to the union.
    DimensionError
        Boxes not of shape (N, n, 2) or (n, 2), members or ``center`` of other dimensions.
    EmptySetError
        No box/member (with interior) in the union, or a box with ``lo > hi``.
    UnboundedSetError, InvalidBoundsError
        An infinite bound or an unbounded member; NaN bounds.

    Notes
    -----
    **Claim.** When ``certificate.proved`` is True: ``P ⊆ S_1 ∪ ... ∪ S_N`` for the
    returned ``P = {x : A x <= b}`` with its stored floating-point rows, and the stored
    rows of the members (boxes become the exact rows ``±e_i.x <= hi_i, -lo_i``).

    **Proof.** :meth:`Polytope.is_subset` with a :class:`PolytopeUnion`, on the final
    ``P`` only, and only when ``P`` is full-dimensional (its flat branch is not a
    proof). It runs the covering engine of :meth:`PolytopeUnion.contains_box`: the
    region ``bounding_box(P) ∩ {A x <= b}`` (the box from exact rational upper bounds of
    the support function) minus the members is split into pieces, and a piece is dropped
    only when LP multipliers give a Farkas-type certificate that it has no interior point,
    checked on the stored rows with a rigorous floating-point error bound or in exact
    rational arithmetic. No piece left proves the inclusion (a non-empty
    ``P \\ S`` would be relatively open in the full-dimensional ``P``). Before it, two
    cheap steps that can only refuse: probe points of ``P`` (its vertices pulled inward
    by ``1e-9``, seeded random points) outside every member reject the candidate, and
    members whose bounding box misses the (outward, rigorous) bounding box of ``P`` are
    left out of the proof (they cannot cover a point of ``P``).

    **Tolerances and the direction they err.** Only the final test is a proof, and it
    errs toward "not proven" (a rounding-level gap or touching contact between ``P``
    and the members may be refused). Everything that builds the candidate is floating
    point and heuristic, and can only cost size, never soundness: the hull (its
    right-hand sides are rounded *outward* by :func:`hull`, so it may stick out of ``S``
    by an ulp), the complement pieces (pieces without interior, Chebyshev radius below
    ``1e-9`` of the scale, are dropped; a piece whose bounding box, from its float
    vertices, has an interior disjoint from a member box is not split by it), the
    ``margin`` of (6.5), the Step-5 test "``C_m ∩ P^a`` has interior" (first the
    thesis' discard test on the vertices of ``C_m``, then a Chebyshev LP with tolerance
    ``1e-9`` relative) and the rounding of the cut rows ``c/s . x <= 1 + c/s . x0``. A
    candidate that is not proven is shrunk about ``x0`` (factors ``1 - 2^-40``,
    ``1 - 2^-20``, then bisection to ``eps``: Alg 6.5 applied to it) until a proof
    succeeds; ``details["alpha"]`` is the factor used. For ``"scaling"`` every step of
    the bisection is such a proof: the returned ``α`` is proven, and, as
    ``α -> x0 + α (H - x0)`` is nested, the thesis' optimal ``α`` lies below ``α + eps``
    unless the test refused a true inclusion (then the answer is only smaller). (The
    loop of Alg 6.5 is printed ``while (b - a) < ε``; it is read as ``> ε``.) When no
    factor down to ``1e-9`` is proven, the empty polytope is returned with
    ``label="undecided"`` (``proved=None``); so is it when the complement has more than
    ``max_pieces`` pieces.

    **Dimension.** Nothing depends on ``n``: the hull (Qhull; the spanned interval for
    ``n = 1``), the differences, the vertex enumeration (cddlib, else Qhull) and the LPs
    work in any dimension (tested for ``n = 1, 2, 3``); the cost grows with ``n``
    through the number of hull facets and complement pieces.

    Examples
    --------
    >>> import numpy as np
    >>> import casadi_cmpc as cm
    >>> L = np.array([[[0, 2], [0, 1]], [[0, 1], [1, 2]]], dtype=float)  # an L
    >>> P, cert = cm.inner_polytope(L, "separating")
    >>> cert.proved, round(P.volume(), 3)
    (True, 2.0)
    >>> P, cert = cm.inner_polytope(L, "scaling")  # the hull scaled about (1, 0.5)
    >>> cert.proved, cert.details["center"].tolist(), round(cert.details["alpha"], 3)
    (True, [1.0, 0.5], 0.333)
    """
    t0 = time.perf_counter()
    if method not in _METHODS:
        raise ValueError(f"method must be one of {_METHODS}; got {method!r}")
    if order not in _ORDERS:
        raise ValueError(f"order must be one of {_ORDERS}; got {order!r}")
    eps = float(eps)
    if not (0.0 < eps < 1.0):
        raise ValueError(f"eps must lie in (0, 1) (a tolerance on the scale factor); got {eps}")
    margin = float(margin)
    if not (0.0 < margin < 1.0):
        raise ValueError(f"margin must lie in (0, 1); got {margin}")
    if int(max_pieces) < 1:
        raise ValueError(f"max_pieces must be a positive integer; got {max_pieces}")
    members, arr, kind = _members_of(boxes)
    n = members[0].dim
    U = PolytopeUnion(members)
    mboxes = arr if arr is not None else np.stack([M.bounding_box().as_array()
                                                    for M in members])
    if n == 1:  # Qhull needs n >= 2; in 1-D the hull is the interval spanned
        H = Polytope.from_box(Box(mboxes[:, 0, 0].min(), mboxes[:, 0, 1].max()))
    else:
        H = hull(*members)
    VH = H.vertices()
    lo_h, hi_h = VH.min(axis=0), VH.max(axis=0)
    scale = float(np.max(hi_h - lo_h))
    if center is None:
        centers = _default_centers(members, arr, H, U, scale)
    else:
        x0 = np.asarray(center, dtype=float).ravel()
        if x0.shape != (n,):
            raise DimensionError(f"center must have shape ({n},); got {np.shape(center)}")
        if not _interior_proven(U, x0, scale):
            raise ValueError(
                f"center {x0.tolist()} is not proven interior to the union (a small box "
                "around it is not covered): give a point well inside one of the members")
        centers = [(x0, "given")]
    prove = _Prover(members, mboxes, boxes=arr)
    details: dict[str, Any] = {"method": method, "input": kind, "n_members": len(members),
                               "dim": n}
    claim = f"P ⊆ the union of the {len(members)} given sets (n = {n})"
    pieces: list[Polytope] = []
    if method == "separating":
        C = (_grid_complement(H, prove.grid, int(max_pieces)) if prove.grid is not None
             else _complement(H, members, mboxes, int(max_pieces)))
        if C is None:
            details.update(n_pieces=f"> {max_pieces}", n_tests=0, n_proofs=0, alpha=0.0,
                           center=centers[0][0].copy(), center_rule=centers[0][1],
                           seconds=time.perf_counter() - t0)
            cert = Certificate(
                "undecided", None, claim,
                f"the complement H \\ S has more than {max_pieces} pieces (Alg 6.2 grows "
                "exponentially with the number of members): raise max_pieces or use "
                "method='scaling'", details)
            return InnerPolytope(Polytope.empty(n), cert)
        pieces = C
        details["n_pieces"] = len(pieces)
    best: tuple[float, Polytope, float, dict, str] | None = None
    tried = []
    for x0, rule in centers:
        x0 = np.asarray(x0, dtype=float)
        run: dict[str, Any] = {"center": x0.copy(), "center_rule": rule}
        if method == "scaling":
            P, alpha = _scale_search(np.array(H.A), np.array(H.b), x0, prove, eps)
            how = "hull scaled about the centre by bisection (Alg 6.5)"
        else:
            s_ = float(np.abs(VH - x0).max())
            cand = _separating(H, pieces, x0, s_, margin, order, run)
            if prove(cand):
                P, alpha = cand, 1.0
            else:
                P, alpha = _scale_search(np.array(cand.A), np.array(cand.b), x0, prove, eps,
                                         one_failed=True)
            how = ("hull cut by α-support hyperplanes of the complement pieces (Alg 6.2)"
                   + ("" if alpha == 1.0 else f", shrunk about the centre by {alpha!r}"))
        run["alpha"] = alpha
        vol = 0.0
        if P is not None and len(centers) > 1:
            try:
                vol = float(P.volume())
            except Exception:  # noqa: BLE001 - no volume: rank it last, it stays proven
                vol = 0.0
        tried.append({"center": x0.tolist(), "alpha": alpha,
                      "volume": vol if P is not None else None})
        if P is not None and (best is None or vol > best[0]):
            best = (vol, P, alpha, run, how)
        if P is not None and alpha == 1.0 and (method == "scaling" or not pieces):
            break  # the hull itself is proven: no other centre can do better
    if len(centers) > 1:
        details["candidates"] = tried
    details.update(n_tests=prove.calls, n_proofs=prove.proofs,
                   n_budget_exhausted=prove.exhausted)
    if best is None:
        details.update(center=np.asarray(centers[0][0], dtype=float).copy(),
                       center_rule=centers[0][1], alpha=0.0, seconds=time.perf_counter() - t0)
        cert = Certificate(
            "undecided", None, claim,
            "no candidate could be proven inside the union, down to the scale factor "
            "1e-9 about the centre"
            + (f" ({prove.exhausted} covering proofs stopped by their budget: not proven, "
               "not refuted)" if prove.exhausted else "")
            + "; the empty polytope is returned", details)
        return InnerPolytope(Polytope.empty(n), cert)
    _, P, alpha, run, how = best
    details.update(run)
    details["seconds"] = time.perf_counter() - t0
    cert = Certificate(
        "proved", True, claim,
        f"{how}; proven by the exact covering test Polytope.is_subset(PolytopeUnion) "
        "(pieces of P minus the members dropped only with certificates checked with "
        "rigorous rounding bounds or exact rationals)", details)
    return InnerPolytope(P, cert)
