"""Exact rational linear algebra for the certificates of the set library."""

from __future__ import annotations

from fractions import Fraction

__all__ = ["rat_nullspace"]


def rat_nullspace(M: list[list[Fraction]], k: int) -> list[list[Fraction]]:
    """Basis of ``{v in Q^k : M v = 0}`` by exact Gauss–Jordan elimination."""
    rows = [list(r) for r in M]
    pivots: list[int] = []
    r = 0
    for col in range(k):
        piv = next((i for i in range(r, len(rows)) if rows[i][col] != 0), None)
        if piv is None:
            continue
        rows[r], rows[piv] = rows[piv], rows[r]
        pv = rows[r][col]
        rows[r] = [x / pv for x in rows[r]]
        for i in range(len(rows)):
            if i != r and rows[i][col] != 0:
                f = rows[i][col]
                rows[i] = [x - f * y for x, y in zip(rows[i], rows[r], strict=True)]
        pivots.append(col)
        r += 1
        if r == len(rows):
            break
    free = [c for c in range(k) if c not in pivots]
    basis = []
    for fc in free:
        v = [Fraction(0)] * k
        v[fc] = Fraction(1)
        for i, pc in enumerate(pivots):
            v[pc] = -rows[i][fc]
        basis.append(v)
    return basis
