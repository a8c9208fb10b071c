"""Polytopes in H-representation ``{x : A x <= b}`` and finite unions of them."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any

import numpy as np

from .._validate import as_points
from ..exceptions import DimensionError, InvalidBoundsError

__all__ = ["Polytope", "PolytopeUnion"]


class Polytope:
    """The polyhedron ``{x in R^n : A x <= b}``.

    Parameters
    ----------
    A : array_like, shape (k, n)
        Constraint normals, one row per half-space. ``k = 0`` (no row) gives ``R^n``.
    b : array_like, shape (k,)
        Right-hand sides. ``+inf`` makes a row vacuous; ``-inf`` makes the set empty.

    Raises
    ------
    DimensionError
        ``A`` is not 2-D, ``b`` is not 1-D, or their numbers of rows differ.
    InvalidBoundsError
        ``A`` or ``b`` contains NaN, or ``A`` contains an infinite entry.

    Examples
    --------
    >>> import casadi_cmpc as cm
    >>> P = cm.Polytope([[1, 0], [-1, 0], [0, 1], [0, -1]], [1, 1, 1, 1])
    >>> P.dim
    2
    >>> P.contains([[0.5, 0.5], [2.0, 0.0]])
    array([ True, False])
    """

    __slots__ = ("A", "b")

    def __init__(self, A: Any, b: Any) -> None:
        A_a = np.array(A, dtype=float)
        b_a = np.array(b, dtype=float)
        if A_a.ndim != 2:
            raise DimensionError(f"Polytope A must be a 2-D array (k, n); got shape {A_a.shape}")
        if b_a.ndim != 1:
            raise DimensionError(f"Polytope b must be a 1-D array (k,); got shape {b_a.shape}")
        if A_a.shape[0] != b_a.shape[0]:
            raise DimensionError(
                f"Polytope A has {A_a.shape[0]} rows but b has {b_a.shape[0]} entries")
        if A_a.shape[1] == 0:
            raise DimensionError("Polytope A must have at least one column (n >= 1)")
        if np.isnan(A_a).any() or np.isnan(b_a).any():
            raise InvalidBoundsError("Polytope A or b contains NaN")
        if not np.isfinite(A_a).all():
            raise InvalidBoundsError("Polytope A contains an infinite entry")
        A_a.setflags(write=False)
        b_a.setflags(write=False)
        self.A = A_a
        self.b = b_a

    @property
    def dim(self) -> int:
        """Dimension n of the ambient space."""
        return int(self.A.shape[1])

    @property
    def n_constraints(self) -> int:
        """Number k of half-spaces (rows of A)."""
        return int(self.A.shape[0])

    def contains(self, points: Any, tol: float = 0.0) -> np.ndarray | bool:
        """Membership of points: ``A p <= b + tol`` row by row.

        Parameters
        ----------
        points : array_like, shape (N, n) or (n,)
        tol : float, optional
            Absolute tolerance added to every right-hand side (default 0: exact test in
            floating point).

        Returns
        -------
        bool or ndarray of bool, shape (N,)
            A single bool for one unbatched point.
        """
        p, batched = as_points(points, self.dim, name="points")
        if self.n_constraints == 0:
            inside = np.ones(p.shape[0], dtype=bool)
        else:
            inside = (p @ self.A.T <= self.b + float(tol)).all(axis=1)
        return inside if batched else bool(inside[0])

    def __repr__(self) -> str:
        return f"Polytope(dim={self.dim}, constraints={self.n_constraints})"


class PolytopeUnion:
    """A finite union ``P_1 ∪ ... ∪ P_p`` of polytopes of the same dimension.

    Parameters
    ----------
    polytopes : iterable of Polytope
        At least one polytope; all of the same dimension.

    Raises
    ------
    TypeError
        An element is not a :class:`Polytope`.
    ValueError
        The iterable is empty.
    DimensionError
        The polytopes have different dimensions.
    """

    __slots__ = ("polytopes",)

    def __init__(self, polytopes: Iterable[Polytope]) -> None:
        items = tuple(polytopes)
        if not items:
            raise ValueError("PolytopeUnion needs at least one polytope")
        for i, P in enumerate(items):
            if not isinstance(P, Polytope):
                raise TypeError(
                    f"PolytopeUnion element {i} is a {type(P).__name__}, not a Polytope")
        dims = {P.dim for P in items}
        if len(dims) != 1:
            raise DimensionError(
                f"PolytopeUnion polytopes differ in dimension: {sorted(dims)}")
        self.polytopes: tuple[Polytope, ...] = items

    @property
    def dim(self) -> int:
        """Dimension n of the ambient space."""
        return self.polytopes[0].dim

    def __len__(self) -> int:
        return len(self.polytopes)

    def __iter__(self) -> Iterator[Polytope]:
        return iter(self.polytopes)

    def contains(self, points: Any, tol: float = 0.0) -> np.ndarray | bool:
        """Membership of points in at least one of the polytopes.

        Parameters
        ----------
        points : array_like, shape (N, n) or (n,)
        tol : float, optional
            Absolute tolerance passed to :meth:`Polytope.contains`.

        Returns
        -------
        bool or ndarray of bool, shape (N,)
        """
        p, batched = as_points(points, self.dim, name="points")
        inside = np.zeros(p.shape[0], dtype=bool)
        for P in self.polytopes:
            inside |= P.contains(p, tol=tol)
        return inside if batched else bool(inside[0])

    def __repr__(self) -> str:
        return f"PolytopeUnion(dim={self.dim}, polytopes={len(self.polytopes)})"
