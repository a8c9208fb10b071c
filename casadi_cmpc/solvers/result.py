"""The base class of the results returned by the solvers.

Every solver returns a frozen dataclass built on :class:`Result`, which holds what all of
them report: the outcome code ``status`` (a :class:`~casadi_cmpc.solvers.engine.Status`),
``success == (status == PROVED)``, a ``message`` in words, the ``method`` used, and the
effort spent (``nit``, ``n_boxes``, ``elapsed``). Subclasses add the solver's answer; the
set-valued solvers (SIVIA, quantified and zonotope set inversion, one-step sets) return a
:class:`SetResult`, which holds the paving.
"""

from __future__ import annotations

import operator
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..exceptions import DimensionError
from .engine import Status

__all__ = ["Certificate", "Result", "SetResult"]


@dataclass(frozen=True, eq=False, kw_only=True)
class Result:
    """Outcome of a solver: status code, message and effort spent.

    All fields are keyword-only. The instance is frozen: assigning a field raises
    :class:`dataclasses.FrozenInstanceError`.

    Attributes
    ----------
    success : bool
        ``status == Status.PROVED``. Derived from ``status`` when omitted; a value that
        disagrees with ``status`` is refused.
    status : Status
        Outcome code (an :class:`~enum.IntEnum`; an int 0 to 4 is converted):
        ``PROVED`` (0) the solver's claim is proven; ``BUDGET`` (1) a limit
        (``max_boxes``, ``time_limit``) or an interruption stopped the search;
        ``DISPROVED`` (2) the claim is proven false; ``UNDECIDED`` (3) the search completed
        without deciding; ``NUMERICAL`` (4) an enclosure was unbounded or undefined. What
        each code proves for a given solver is stated by its subclass.
    message : str
        What was proven, in words.
    method : str
        The algorithm (and variant) that produced the result.
    nit : int
        Iterations (branch-and-bound levels), at least 0.
    n_boxes : int
        Boxes classified, at least 0.
    elapsed : float
        Wall-clock time in s, at least 0.

    Raises
    ------
    ValueError
        ``status`` is not a valid code, ``success`` disagrees with ``status``, ``nit`` or
        ``n_boxes`` is negative, or ``elapsed`` is negative or not finite.
    TypeError
        ``message`` or ``method`` is not a str, or ``nit`` or ``n_boxes`` is not an integer.

    Notes
    -----
    A subclass is declared with ``@dataclass(frozen=True, eq=False, kw_only=True,
    repr=False)`` (``repr=False`` keeps the shared ``__repr__``), chains
    ``__post_init__`` to ``super().__post_init__()``, and lists its own numbers in the
    repr by overriding ``_repr_parts``.

    Examples
    --------
    >>> from casadi_cmpc.solvers.engine import Status
    >>> from casadi_cmpc.solvers.result import Result
    >>> r = Result(status=Status.BUDGET, message="max_boxes reached", method="demo",
    ...            nit=3, n_boxes=12, elapsed=0.25)
    >>> r.success, r.status.name
    (False, 'BUDGET')
    >>> r
    Result(status=BUDGET, nit=3, n_boxes=12, elapsed=0.25)
    >>> Result(status=0, success=False, message="", method="demo", nit=0, n_boxes=0,
    ...        elapsed=0.0)
    Traceback (most recent call last):
    ...
    ValueError: success=False disagrees with status=PROVED (success must equal status == PROVED)
    """

    success: bool | None = None
    status: Status
    message: str
    method: str
    nit: int
    n_boxes: int
    elapsed: float

    def __post_init__(self) -> None:
        try:
            status = Status(self.status)
        except ValueError:
            codes = ", ".join(f"{s.value} {s.name}" for s in Status)
            raise ValueError(f"status must be one of {codes}; got {self.status!r}") from None
        proved = status == Status.PROVED
        if self.success is not None and bool(self.success) != proved:
            raise ValueError(f"success={self.success} disagrees with status={status.name} "
                             "(success must equal status == PROVED)")
        for name in ("message", "method"):
            if not isinstance(getattr(self, name), str):
                raise TypeError(f"{name} must be a str; got "
                                f"{type(getattr(self, name)).__name__}")
        counts = {}
        for name in ("nit", "n_boxes"):
            try:
                counts[name] = operator.index(getattr(self, name))
            except TypeError:
                raise TypeError(f"{name} must be an integer; got "
                                f"{getattr(self, name)!r}") from None
            if counts[name] < 0:
                raise ValueError(f"{name} must be >= 0; got {counts[name]}")
        elapsed = float(self.elapsed)
        if not (np.isfinite(elapsed) and elapsed >= 0):
            raise ValueError(f"elapsed must be a finite number of seconds >= 0; got {elapsed}")
        self._set(status=status, success=proved, elapsed=elapsed, **counts)

    def _set(self, **values: Any) -> None:
        """Store normalised field values (in ``__post_init__`` of a frozen instance)."""
        for name, value in values.items():
            object.__setattr__(self, name, value)

    def _repr_parts(self) -> list[str]:
        """``name=value`` items a subclass shows between ``status`` and ``nit``."""
        return []

    def _repr_note(self) -> str | None:
        """A short statement shown as ``verdict='...'`` right after the status, for the
        cases in which the status alone would be misread (None: no note)."""
        return None

    def __repr__(self) -> str:
        note = self._repr_note()
        parts = [f"status={self.status.name}", *([f"verdict={note!r}"] if note else []),
                 *self._repr_parts(), f"nit={self.nit}", f"n_boxes={self.n_boxes}",
                 f"elapsed={self.elapsed:.3g}"]
        return f"{type(self).__name__}({', '.join(parts)})"


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class _BracketResult(Result):
    """A :class:`Result` with a certified bracket ``lower <= value <= upper``.

    Attributes
    ----------
    lower, upper : float
        Certified bounds of the optimal value (``lower <= upper``; either may be infinite).
    candidates : ndarray, shape (N, n, 2)
        Boxes that may hold optimal points: every optimal point lies in their union.
    fun : float
        Same as ``upper`` (scipy's name for the optimal value).
    width : float
        ``upper - lower``.
    """

    lower: float
    upper: float
    candidates: np.ndarray

    def __post_init__(self) -> None:
        super().__post_init__()
        lower, upper = float(self.lower), float(self.upper)
        if lower > upper:
            raise ValueError(f"the bracket is inverted: lower {lower:.17g} > upper {upper:.17g}")
        cand = np.asarray(self.candidates, dtype=float)
        if cand.ndim != 3 or cand.shape[-1] != 2:
            raise DimensionError(
                f"candidates must be boxes of shape (N, n, 2); got shape {cand.shape}")
        self._set(lower=lower, upper=upper, candidates=cand)

    @property
    def fun(self) -> float:
        """Same as ``upper`` (scipy's name for the optimal value)."""
        return self.upper

    @property
    def width(self) -> float:
        """Width ``upper - lower`` of the certified bracket."""
        return float(self.upper - self.lower)

    def _repr_solution(self) -> list[str]:
        """``name=value`` items of the returned point, shown after the bracket."""
        return []

    def _repr_parts(self) -> list[str]:
        return [f"lower={self.lower:.10g}", f"upper={self.upper:.10g}", *self._repr_solution(),
                f"candidates={self.candidates.shape[0]}"]


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class SetResult(Result):
    """Outcome of a set-valued solver: a :class:`Result` holding the paving it computed.

    Returned by :func:`~casadi_cmpc.sivia`, :func:`~casadi_cmpc.quantified_sivia`,
    :func:`~casadi_cmpc.solvers.zonotope_sivia.zonotope_sivia`,
    :func:`~casadi_cmpc.solvers.zonotope_sivia.inner_zonotopes` and (as its subclass
    :class:`~casadi_cmpc.OneStepSet`) :func:`~casadi_cmpc.one_step_set`.

    Attributes
    ----------
    paving : Paving or ZonotopePaving
        The answer: boxes (or zonotopes) ``inner`` (every point proven to be a solution),
        ``boundary`` (undecided) and ``outside`` (every point proven not to be one; empty
        unless the solver kept them), with ``domain`` and ``n_discarded``. What "solution"
        means is stated by each solver.
    n_pairs : int
        (state box, input cell) pairs examined by a nested search over the inputs
        (quantified set inversion, one-step sets); 0 for the others.
    history : list of dict
        Per bisection level: boxes classified, and how many became inner, outside
        (key ``"outer"``, the engine's label) and boundary.
    status : Status
        ``PROVED``: the search ran to completion (every box is decided or narrower than
        eps); ``BUDGET``: a limit (``max_boxes``, ``time_limit``) or an interruption
        stopped it, and the unexplored boxes are reported as boundary (still sound).
        The proof is in the paving, whatever the status: a complete search that proved
        no box inside is ``PROVED`` too, and its repr then says so (see ``verdict``).
    verdict : str
        What the paving proves, in words: how many boxes are proven inside, or that the set
        is proven empty in the domain, or that no box is proven inside (undecided ones
        remain). The repr shows it whenever no box is proven inside.
    nit, n_boxes : int
        Bisection levels and boxes classified (also available under their older names
        ``levels`` and ``n_classified``). Not to be confused with ``paving.n_boxes``, the
        number of inner and boundary boxes (``len(result)``).

    Notes
    -----
    **Acts as its paving.** Attributes that are not fields of the result are looked up on
    the paving: ``res.inner``, ``res.boundary``, ``res.outside``, ``res.domain``,
    ``res.n_discarded``, ``res.volume(...)``, ``res.contains(...)``, ``res.plot(...)``,
    ``res.view_boxes(...)``, ``res.n_inner``, ``res.save(path)`` (saves the paving) and
    so on; ``len(res)``, ``bool(res)`` and ``res | other`` (union) are those of the paving,
    and ``isinstance(res, cm.Paving)`` is True when it holds a Paving. So code written for
    the Paving these solvers returned before keeps working. ``res.outer`` is the deprecated
    name of ``res.outside``.

    Examples
    --------
    >>> import casadi as ca, casadi_cmpc as cm
    >>> p = ca.SX.sym("p", 2)
    >>> disk = ca.Function("disk", [p], [p[0]**2 + p[1]**2])
    >>> res = cm.sivia(disk, cm.Box([-2, -2], [2, 2]), cm.Box([0], [1]), eps=0.5)
    >>> res.success, isinstance(res.paving, cm.Paving), isinstance(res, cm.Paving)
    (True, True, True)
    >>> res.n_inner == len(res.paving.inner) == len(res.inner)
    True
    >>> far = cm.sivia(disk, cm.Box([5, 5], [6, 6]), cm.Box([0], [1]), eps=0.5)
    >>> str(far.status), far.n_inner, far.verdict
    ('PROVED', 0, 'proved: the set is empty in the domain (every box is proven outside)')
    """

    #: the attribute holding the set (see :class:`~casadi_cmpc.sets.base.HoldsSetMeta`)
    _held_set = "paving"

    paving: Any
    n_pairs: int = 0
    history: list = field(default_factory=list)

    def __post_init__(self) -> None:
        super().__post_init__()
        pav = self.paving
        if isinstance(pav, SetResult):  # a result given as the paving: hold its paving
            pav = pav.paving
        missing = [a for a in ("inner", "boundary", "outside", "domain", "n_discarded")
                   if not hasattr(pav, a)]
        if missing:
            raise TypeError(f"paving must be a Paving or ZonotopePaving; got "
                            f"{type(pav).__name__} (without {', '.join(missing)})")
        try:
            n_pairs = operator.index(self.n_pairs)
        except TypeError:
            raise TypeError(f"n_pairs must be an integer; got {self.n_pairs!r}") from None
        if n_pairs < 0:
            raise ValueError(f"n_pairs must be >= 0; got {n_pairs}")
        self._set(paving=pav, n_pairs=n_pairs, history=list(self.history))

    # ------------------------------------------------------------- older names
    @property
    def levels(self) -> int:
        """Bisection levels, same as ``nit``."""
        return self.nit

    @property
    def n_classified(self) -> int:
        """Boxes classified, same as ``n_boxes``."""
        return self.n_boxes

    @property
    def outer(self) -> Any:
        """Deprecated alias of ``outside`` (the proven-outside boxes of the paving)."""
        warnings.warn(
            "SetResult.outer is deprecated: the proven-outside boxes are now called "
            "'outside' (the view 'outer' is inner ∪ boundary, the outer approximation); use "
            "'outside'", DeprecationWarning, stacklevel=2)
        return self.paving.outside

    # ------------------------------------------------------ acts as its paving
    def __getattr__(self, name: str) -> Any:
        # only called when the normal lookup fails: fields and methods of the result win
        if name.startswith("__") and name.endswith("__"):
            raise AttributeError(name)  # protocols (copy, pickle, numpy) are not forwarded
        try:
            pav = object.__getattribute__(self, "paving")
        except AttributeError:  # not initialised yet (unpickling)
            raise AttributeError(name) from None
        try:
            return getattr(pav, name)
        except AttributeError:
            raise AttributeError(
                f"'{type(self).__name__}' object has no attribute '{name}' (nor has its "
                f"paving, a {type(pav).__name__})") from None

    def __dir__(self) -> list[str]:
        return sorted(set(super().__dir__()) | set(dir(self.paving)))

    def __len__(self) -> int:
        return len(self.paving)

    def __bool__(self) -> bool:
        return bool(self.paving)

    def __or__(self, other: Any) -> Any:
        if isinstance(other, SetResult):
            other = other.paving
        return self.paving | other

    def __ror__(self, other: Any) -> Any:
        return other | self.paving

    @property
    def verdict(self) -> str:
        """What the paving proves, in words (it does not depend on ``status`` alone).

        * some inner box: ``"<k> boxes proven inside, <b> undecided"``;
        * no inner and no boundary box: every box of the domain was proven outside, so
          ``"proved: the set is empty in the domain"``;
        * no inner box but undecided ones: ``"no box proven inside: <b> undecided boxes"``
          (after a complete search they are narrower than eps; after a stopped one some
          were not explored).
        """
        p = self.paving
        n_in, n_bd = len(p.inner), len(p.boundary)
        if n_in:
            return (f"{n_in} box{'es' if n_in != 1 else ''} proven inside, {n_bd} "
                    "undecided")
        if not n_bd:
            return "proved: the set is empty in the domain (every box is proven outside)"
        # a completed search (PROVED, or UNDECIDED when nothing was proven) leaves its
        # undecided boxes at eps; a budget or an interruption leaves unexplored ones
        why = ("the search was stopped" if self.status == Status.BUDGET
               else "narrower than eps")
        return (f"no box proven inside: {n_bd} undecided box{'es' if n_bd != 1 else ''} "
                f"({why})")

    def _repr_note(self) -> str | None:
        # a PROVED status with no inner box reads as a proven set: say what it is
        return None if len(self.paving.inner) else self.verdict

    def _repr_parts(self) -> list[str]:
        p = self.paving
        return [f"inner={len(p.inner)}", f"boundary={len(p.boundary)}",
                f"outside={len(p.outside)}"]


def _format_point(p: np.ndarray | None) -> str:
    """A point for a repr: ``None`` or its entries to 6 digits."""
    return "None" if p is None else np.array2string(np.asarray(p), precision=6)


@dataclass(frozen=True, eq=False)
class Certificate:
    """What was proven about one answer, in words and numbers.

    Attributes
    ----------
    label : str
        ``"verified"`` (the returned sequence satisfies every constraint, proven by interval
        arithmetic), ``"unverified"`` (the check failed or was switched off: nothing is
        claimed), ``"proved_infeasible"`` (no admissible sequence exists for any horizon
        tried, proven by set inversion or an exact LP certificate), ``"undecided"`` (a search
        budget ran out before a proof either way), ``"at_reference"`` (the state is the
        reference: ``u_ref`` is applied), ``"local_law"`` (the state is in the set of the
        local law, which is applied).
    proved : bool or None
        True when the claim is proven, False when its negation is proven, None otherwise.
    claim : str
        The statement the label refers to.
    reason : str
        How it was decided, or why it was not.
    details : dict
        Numbers: margins of the verified constraints, proofs per horizon (boxes, seconds),
        the optimality bracket when requested.
    counterexample : ndarray or None
        A point that disproves the claim, when one was found.
    about : dict
        What the claim is about, for consumers that rely on it (empty when the claim
        is about one answer only). An invariance certificate
        (:func:`~casadi_cmpc.certify_invariant`) holds ``kind`` (``"invariance"``),
        ``model`` (name), ``model_key`` (a hash of the model's map), ``set`` (the set S),
        ``law`` (the law as text), ``law_key`` (a hash of the law's expression in the
        model's x), ``law_function`` (the law as a serialized CasADi Function), ``W``
        (the disturbance Box the proof covers, None without w) and ``robust`` (True when
        that box is not a single point).
    """

    label: str
    proved: bool | None
    claim: str
    reason: str
    details: dict = field(default_factory=dict)
    counterexample: np.ndarray | None = None
    about: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        return f"Certificate({self.label!r}, proved={self.proved}, reason={self.reason!r})"
