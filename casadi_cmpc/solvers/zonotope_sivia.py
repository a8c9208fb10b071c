r"""Set inversion via zonotope geometry (SIVZG, thesis §4.2.5, Alg 4.3).

The paving elements are zonotopes instead of boxes. A batch of zonotopes with a common
number of generators is a :class:`ZonotopeFrontier`; it implements the frontier protocol of
:func:`~casadi_cmpc.solvers.engine.branch_and_bound` (``take``, ``width``, ``bisect`` by
Thm 4.1, ``concat``), so Alg 4.3 is the engine with a zonotope classifier
(:func:`zonotope_classifier`):

* the image ``f(Z)`` of every zonotope ``Z = c ⊕ H B^p`` of the frontier is enclosed by the
  mean-value form with an interval Jacobian over the bounding box of ``Z``, bounded by Kühn's
  zonotope inclusion (thesis (4.14)-(4.16), Thm 4.4);
* ``Z`` is INNER when the enclosure is proven inside the target ``Y`` (support functions of
  the enclosure against the rows of a polytope, or against lower bounds of the supports of
  a zonotope target in its exact facet normals), OUTER when it is proven disjoint from ``Y``
  (a separating inequality implied by the rows of ``Y``, or a separating direction of two
  zonotopes), else UNDECIDED; undecided
  zonotopes whose largest ``|h_ij|`` (4.12) is at most ``eps`` are kept as boundary, the
  others bisected along the generator holding it (4.13).

:func:`inner_zonotopes` is the special case ``f = identity`` of Fig 4.8: a polytope is
approximated from inside by a union of zonotopes, starting from a parallelotope bounding it.

Rounding
--------
Each element of a frontier is ``c ⊕ H B^p ⊕ [-r, r]``: besides its generators it carries a
box of radii ``r`` (usually zero or a few ulps) that absorbs the rounding errors of the
bisection, so that the two halves provably cover their parent, and every enclosure below
is computed with outward rounding. INNER is therefore a proof for every point of the
zonotope (box included); OUTER is a proof that no point of it is in the solution set.

Layout
------
The batched zonotope type is defined in :mod:`casadi_cmpc.solvers._zbatch`, the target
tests in :mod:`casadi_cmpc.solvers._ztargets` and the image enclosure in
:mod:`casadi_cmpc.solvers._zimage`; this module holds the classifier, the result type and
the solvers, and exports :class:`ZonotopeFrontier`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..exceptions import DimensionError, EmptySetError, InvalidBoundsError, UnboundedSetError
from ..sets.base import HoldsSetMeta
from ..sets.box import Box
from ..sets.paving import _outside_keyword, _warn_outer
from ..sets.polytope import Polytope
from ..sets.zonotope import Zonotope
from ._zbatch import ZonotopeFrontier
from ._zimage import _Image
from ._ztargets import MAX_NORMAL_SUBSETS, _Target  # noqa: F401
from .engine import INNER, OUTER, branch_and_bound
from .result import SetResult

__all__ = ["ZonotopeFrontier", "ZonotopePaving", "zonotope_classifier", "zonotope_sivia",
           "inner_zonotopes"]


def zonotope_classifier(f: Any, Y: Any, *, n: int | None = None, X: Any = None, W: Any = None,
                        box_form: str | None = "natural"):
    """Classifier of zonotopes ``Z`` by their image enclosure against a target ``Y``.

    Parameters
    ----------
    f : None, casadi.Function, InclusionFunction or Model
        ``None`` for the identity; a Function ``R^n -> R^m`` (one input, one output), or its
        compiled :class:`~casadi_cmpc.interval.InclusionFunction` (evaluated as given where
        its kind is used; its Function gives the Jacobian); or a Model without inputs (e.g.
        ``model.closed_loop(K)``), robust over its disturbance box ``W``.
    Y : Box, Polytope, PolytopeUnion, Zonotope or another set of dimension m
        The target.
    n : int, optional
        Dimension of ``Z`` (needed for the identity only).
    X : Polytope or Box, optional
        A constraint on ``x`` itself: INNER also needs ``Z ⊆ X`` proven, and ``Z ∩ X = ∅``
        proven makes ``Z`` OUTER.
    W : Box, optional
        Disturbance box of a Model (default: ``model.W``).
    box_form : {"natural", "centered", None}
        Also enclose ``f(□Z)`` by this interval inclusion over the bounding box; a proof by
        either enclosure counts (ignored for the identity).

    Returns
    -------
    callable
        ``classify(frontier) -> (N,) int8`` labels INNER / OUTER / UNDECIDED, for
        :func:`~casadi_cmpc.solvers.engine.branch_and_bound`.
    """
    if box_form is not None:
        box_form = str(box_form).lower()
        if box_form not in ("natural", "centered"):
            raise ValueError(f"Unknown box_form '{box_form}'; valid: natural, centered, None")
    img = _Image(f, n, W, box_form if f is not None else None)
    target = _Target(Y, img.m, "Y")
    dom = _Target(X, img.n, "X") if X is not None else None

    def classify(fr: ZonotopeFrontier) -> np.ndarray:
        N = len(fr)
        labels = np.zeros(N, dtype=np.int8)
        if N == 0:
            return labels
        c, G, R, valid, boxes = img(fr)
        ins = np.zeros(N, dtype=bool)
        dis = np.zeros(N, dtype=bool)
        if valid.any():
            v = np.flatnonzero(valid)
            ins[v], dis[v] = target.classify(c[v], G[v], R[v],
                                             None if boxes is None else boxes[v])
        if boxes is not None and not valid.all():
            # no zonotope enclosure (e.g. an unbounded Jacobian): the box may still decide
            b = np.flatnonzero(~valid)
            ins[b], dis[b] = target.classify_boxes(boxes[b])
        if dom is not None:
            din, ddis = dom.classify(fr.centers, fr.generators, fr.radii)
            ins &= din
            dis |= ddis
        labels[ins] = INNER
        labels[dis & ~ins] = OUTER
        return labels

    classify.n = img.n  # type: ignore[attr-defined]
    classify.m = img.m  # type: ignore[attr-defined]
    return classify


# ----------------------------------------------------------------------------- result
class ZonotopePaving(metaclass=HoldsSetMeta):
    """The zonotopes of :func:`zonotope_sivia` / :func:`inner_zonotopes`, by label.

    Held by their :class:`~casadi_cmpc.SetResult` as ``result.paving`` (the result acts as
    it: ``result.inner``, ``result.volume()``, ``result.plot()``, and
    ``isinstance(result, ZonotopePaving)`` is True).

    Parameters
    ----------
    inner, boundary, outside : ZonotopeFrontier
        See the attributes.
    domain : Zonotope
        The initial zonotope.
    n_discarded : int, optional
        Number of zonotopes proven outside (default ``len(outside)``).
    outer : deprecated
        Old name of ``outside`` (keyword only; emits a DeprecationWarning).

    Attributes
    ----------
    inner : ZonotopeFrontier
        Zonotopes proven inside the solution set (every point, rounding included); Alg
        4.3's Σ_x. Iterate to get :class:`~casadi_cmpc.Zonotope` objects.
    boundary : ZonotopeFrontier
        Undecided zonotopes with ``Max(H) <= eps`` (Σ_x^b), plus any leftovers of a search
        stopped by a limit.
    outside : ZonotopeFrontier
        Zonotopes proven outside (discarded); empty unless ``keep_outer``. ``outer`` is its
        deprecated alias.
    domain : Zonotope
    n_discarded : int
    """

    def __init__(self, inner: ZonotopeFrontier, boundary: ZonotopeFrontier,
                 outside: ZonotopeFrontier | None = None, domain: Zonotope | None = None,
                 n_discarded: int | None = None, *, outer: ZonotopeFrontier | None = None
                 ) -> None:
        outside = _outside_keyword(outside, outer, "ZonotopePaving()")
        if outside is None or domain is None:
            raise TypeError("ZonotopePaving needs inner, boundary, outside and domain")
        self.inner = inner
        self.boundary = boundary
        self.outside = outside
        self.domain = domain
        self.n_discarded = len(outside) if n_discarded is None else int(n_discarded)

    @property
    def outer(self) -> ZonotopeFrontier:
        """Deprecated alias of :attr:`outside` (the discarded zonotopes)."""
        _warn_outer("ZonotopePaving.outer")
        return self.outside

    def __repr__(self) -> str:
        return (f"ZonotopePaving(dim={self.domain.dim}, inner={len(self.inner)}, "
                f"boundary={len(self.boundary)}, outside={len(self.outside)}, "
                f"n_discarded={self.n_discarded})")

    def volume(self, view: str = "inner") -> float:
        """Sum of the volumes of the ``"inner"``, ``"boundary"`` or ``"outside"`` zonotopes.

        The halves of a parallelotope share only a facet (Thm 4.2), so for a parallelotope
        domain this is the volume of the union; with redundant generators the halves
        overlap and the sum counts overlaps more than once. The view ``"outer"`` is a
        deprecated name of ``"outside"`` here (for a :class:`~casadi_cmpc.Paving` the view
        ``"outer"`` is inner ∪ boundary).
        """
        v = str(view).lower()
        if v == "outer":
            _warn_outer("the view 'outer' of ZonotopePaving.volume")
            v = "outside"
        fr = {"inner": self.inner, "boundary": self.boundary, "outside": self.outside}.get(v)
        if fr is None:
            raise ValueError(f"Unknown view '{view}'; valid: inner, boundary, outside")
        return float(fr.volumes().sum()) if len(fr) else 0.0

    def plot(self, ax: Any = None, dims: tuple[int, int] = (0, 1), domain: bool = True,
             outer: bool = True) -> Any:
        """Draw the paving: inner (green), boundary (yellow), outside (light blue), domain.

        Parameters
        ----------
        ax : matplotlib Axes, optional
        dims : (int, int)
            Coordinates drawn.
        domain : bool
            Outline the initial zonotope.
        outer : bool
            Draw the discarded (outside) zonotopes, when kept.

        Returns
        -------
        matplotlib Axes
        """
        from ..plot import new_axes

        ax = new_axes(ax)
        if outer and len(self.outside):
            self.outside.plot(ax, dims, facecolor="lightsteelblue", edgecolor="0.5",
                              linewidth=0.2, label=f"outside ({len(self.outside)})")
        if len(self.boundary):
            self.boundary.plot(ax, dims, facecolor="gold", edgecolor="0.3", linewidth=0.2,
                               label=f"boundary ({len(self.boundary)})")
        if len(self.inner):
            self.inner.plot(ax, dims, facecolor="tab:green", edgecolor="k", linewidth=0.3,
                            label=f"inner ({len(self.inner)})")
        if domain:
            self.domain.plot(ax=ax, dims=dims, facecolor="none", edgecolor="k",
                             linewidth=1.2, alpha=1.0, linestyle="--", label="domain")
        return ax


def _zonotope_result(out: Any, Z0: Zonotope, method: str) -> SetResult:
    """The SetResult of a zonotope search from the engine's outcome."""
    paving = ZonotopePaving(out.inner, out.boundary, out.outer, Z0, out.n_discarded)
    return SetResult(status=out.status, message=out.message, method=method, nit=out.levels,
                     n_boxes=out.n_classified, elapsed=out.elapsed, paving=paving,
                     history=out.history)


# ----------------------------------------------------------------------------- solvers
def _as_domain(X0: Any) -> tuple[Zonotope, Polytope | None]:
    if isinstance(X0, Zonotope):
        return X0, None
    if isinstance(X0, Box):
        if not X0.is_bounded():
            raise UnboundedSetError(f"X0 must be bounded; got {X0!r}")
        return Zonotope.from_box(X0), None
    if isinstance(X0, Polytope):
        return _bounding_parallelotope(X0), X0
    raise TypeError(f"X0 must be a Zonotope, Box or Polytope; got {type(X0).__name__}")


def _bounding_parallelotope(P: Polytope, method: str = "svd",
                            center: str | Any = "chebyshev") -> Zonotope:
    """A parallelotope containing the vertices of P (§4.2.5, Fig 4.7(b)), widened by 1e-9."""
    if P.is_empty():
        raise EmptySetError("the polytope is empty")
    if not P.is_bounded():
        raise UnboundedSetError("the polytope is unbounded; intersect it with a Box")
    V = P.vertices()
    if isinstance(center, str):
        key = center.lower()
        if key == "chebyshev":
            c = P.chebyshev_ball()[0]
        elif key == "box":
            c = None
        else:
            raise ValueError(f"Unknown center '{center}'; valid: chebyshev, box, or a point")
    else:
        c = np.asarray(center, dtype=float)
    Z = Zonotope.outer_parallelotope(V, center=c, method=method)
    # the float vertices may miss the exact ones by a few ulps: widen slightly
    return Zonotope(Z.center, Z.generators * (1.0 + 1e-9))


def zonotope_sivia(f: Any, X0: Any, Y: Any, eps: float, *, W: Any = None,
                   box_form: str | None = "natural", max_boxes: int = 2_000_000,
                   time_limit: float | None = None, keep_outer: bool = True,
                   progress: bool | None = None, executor: Any = None) -> SetResult:
    r"""Set inversion via zonotope geometry: pave ``{x in X0 : f(x) in Y}`` (thesis Alg 4.3).

    Parameters
    ----------
    f : None, casadi.Function, InclusionFunction or Model
        The map: ``None`` for the identity (then the result approximates ``X0 ∩ Y``); a
        Function ``R^n -> R^m`` with one input and one output (stack several conditions
        with ``casadi.vertcat``), or its compiled InclusionFunction (see
        :func:`zonotope_classifier`); or a Model without inputs (a closed loop,
        ``model.closed_loop(K)``), whose successor must lie in Y for every disturbance in
        ``W``.
    X0 : Zonotope, Box or Polytope
        The initial admissible domain. A Polytope is bounded by a parallelotope (its
        Chebyshev centre as centre, SVD directions, §4.2.5) and ``x in X0`` is added as a
        condition.
    Y : Box, Polytope, PolytopeUnion, Zonotope or another set of dimension m
        The target (a Box may have infinite bounds).
    eps : float
        Undecided zonotopes with ``Max(H) = max |h_ij| <= eps`` (4.12) are not bisected
        (boundary).
    W : Box, optional
        Disturbance box for a Model with ``w`` (default: the model's W).
    box_form : {"natural", "centered", None}
        Additional interval enclosure of ``f`` over the bounding box of each zonotope; a
        proof by either enclosure counts.
    max_boxes, time_limit : optional
        Limits; a stopped search reports its leftovers as boundary (still sound).
    keep_outer : bool
        Keep the discarded zonotopes for drawing (always counted).
    progress : bool or None
        tqdm progress bar (None: only for searches longer than 2 s).

    executor : concurrent.futures.Executor, optional
        Classify the large levels on this executor (see
        :func:`casadi_cmpc.solvers.engine.branch_and_bound`); the result is that of the
        serial run.

    Returns
    -------
    SetResult
        ``paving``: a :class:`ZonotopePaving` (the result acts as it) with ``inner`` (every
        point proven: ``f(x) in Y``, for every w in W for a Model with a disturbance, and
        ``x in X0`` for a Polytope ``X0``), ``boundary``, ``outside``, ``n_discarded``,
        ``volume()``, ``plot(ax)``; ``status`` is ``PROVED`` when the search ran to
        completion, ``BUDGET`` when a limit stopped it.

    Notes
    -----
    **Image enclosure** (thesis (4.16), Thm 4.4). For ``Z = c ⊕ H B^p`` the mean-value
    theorem gives ``f(Z) ⊆ f(c) + ∇f(□Z)(Z - c)`` with the interval Jacobian over the
    bounding box ``□Z``; the interval matrix ``[M] = ∇f(□Z) H`` is bounded by Kühn's
    zonotope inclusion ``◇([M] B^p) = Mid[M] B^p ⊕ diag(Σ_j Rad[M]_ij) B^m`` (4.14)-(4.15).
    Everything is evaluated with outward rounding, so the enclosure contains the exact
    image. Compared with the interval enclosure of ``J H`` times ``B^p`` this keeps the
    correlation between the outputs (only the Jacobian's *width* is wrapped into a box),
    and its overestimation shrinks quadratically with the size of ``Z``.

    **Tests.** INNER: the enclosure is inside every row of a polytope target,
    ``h(a_i) <= b_i`` with support functions rounded upward (for a union: inside one
    member). OUTER: a row of the target, or a combination of the rows active at the vertex
    of the target that maximises a facet normal of the enclosure, separates them (see the
    separating axis theorem: complete in 2-D up to rounding). A Zonotope target is tested
    against its exact facet normals (interval enclosures): INNER needs an upper bound of
    the enclosure's support below a *lower* bound of the target's support in every facet
    normal; OUTER a facet normal of either zonotope (or an axis) along which the
    enclosure's minimum, rounded down, exceeds the target's support, rounded up. Its
    outward-rounded H-representation is never used for INNER (it contains the target).

    **Bisection** (Thm 4.1) along the first generator holding ``Max(H)``. The halves of a
    parallelotope share only a facet (Thm 4.2); for a zonotope with redundant generators
    they overlap (Fig 4.4) - bound it first with ``Z.reduce_to_parallelotope()`` (§4.2.5)
    when a non-overlapping paving is wanted (this enlarges the domain).

    Examples
    --------
    >>> import casadi as ca, numpy as np, casadi_cmpc as cm
    >>> from casadi_cmpc.solvers.zonotope_sivia import zonotope_sivia
    >>> x = ca.SX.sym("x", 2)
    >>> f = ca.Function("f", [x], [x + 0.1 * ca.vertcat(x[0] ** 2, x[0] * x[1])])
    >>> Z0 = cm.Zonotope([0.0, 0.0], [[1.0, 0.5], [0.0, 1.0]])
    >>> res = zonotope_sivia(f, Z0, cm.Box([-1, -1], [1, 1]), eps=0.1)
    >>> bool(res.success and len(res.inner) > 0)
    True
    """
    Z0, Xc = _as_domain(X0)
    classify = zonotope_classifier(f, Y, n=Z0.dim, X=Xc, W=W, box_form=box_form)
    if classify.n != Z0.dim:
        raise DimensionError(f"X0 has dimension {Z0.dim}; f takes {classify.n} inputs")
    if Z0.n_generators == 0:
        raise InvalidBoundsError("X0 is a single point (a zonotope without generators)")
    fr = ZonotopeFrontier.from_zonotopes(Z0)
    out = branch_and_bound(fr, classify, eps, max_boxes=max_boxes, time_limit=time_limit,
                           keep_outer=keep_outer, progress=progress, desc="zonotope sivia",
                           executor=executor)
    return _zonotope_result(out, Z0, "zonotope sivia (Alg 4.3)")


def inner_zonotopes(P: Polytope, eps: float, *, method: str = "svd",
                    center: str | Any = "chebyshev", max_boxes: int = 2_000_000,
                    time_limit: float | None = None, keep_outer: bool = True,
                    progress: bool | None = None) -> SetResult:
    """Inner approximation of a polytope by a union of zonotopes (thesis Fig 4.8).

    Alg 4.3 with ``f = identity``, started from a parallelotope bounding P (§4.2.5, Fig
    4.7(b)): INNER means ``Z ⊆ P`` proven, OUTER means ``Z ∩ P = ∅`` proven.

    Parameters
    ----------
    P : Polytope
        Bounded, non-empty.
    eps : float
        Zonotopes with ``Max(H) <= eps`` are not bisected further.
    method : {"svd", "pca", "box"}
        Directions of the bounding parallelotope (see
        :meth:`~casadi_cmpc.Zonotope.outer_parallelotope`).
    center : {"chebyshev", "box"} or array_like, shape (n,)
        Its centre: the centre of the largest inscribed ball (the thesis' choice), the
        midpoint of the bounding box, or a given point.
    max_boxes, time_limit, keep_outer, progress
        As in :func:`zonotope_sivia`.

    Returns
    -------
    SetResult
        ``paving``: a :class:`ZonotopePaving`; ``inner``: zonotopes proven inside P; as eps
        decreases their total volume tends to the volume of P (they are halves of halves of
        one parallelotope, so they do not overlap).

    Examples
    --------
    >>> import numpy as np, casadi_cmpc as cm
    >>> from casadi_cmpc.solvers.zonotope_sivia import inner_zonotopes
    >>> P = cm.Polytope.from_vertices([[0, 0], [2, 0], [2.5, 1], [1, 2], [-0.5, 1]])
    >>> res = inner_zonotopes(P, eps=0.05)
    >>> bool(0.9 * P.volume() < res.volume() <= P.volume())
    True
    """
    if not isinstance(P, Polytope):
        raise TypeError(f"P must be a Polytope; got {type(P).__name__}")
    Z0 = _bounding_parallelotope(P, method, center)
    classify = zonotope_classifier(None, P, n=P.dim)
    fr = ZonotopeFrontier.from_zonotopes(Z0)
    out = branch_and_bound(fr, classify, eps, max_boxes=max_boxes, time_limit=time_limit,
                           keep_outer=keep_outer, progress=progress, desc="inner zonotopes")
    return _zonotope_result(out, Z0, "inner zonotopes (Alg 4.3, f = identity)")
