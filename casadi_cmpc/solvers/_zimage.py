r"""The image enclosure of zonotope SIVIA: mean-value form with Kühn's inclusion.

:class:`_Image` encloses ``f(Z)`` (or ``f(Z, W)`` for a Model with a disturbance box) for
every zonotope of a batch by a zonotope with an added box (thesis (4.14)-(4.16),
Thm 4.4), with outward rounding, falling back to interval enclosures over the bounding
boxes where the mean-value form does not apply.
"""

from __future__ import annotations

import warnings
from typing import Any

import casadi as ca
import numpy as np

from ..exceptions import CmpcWarning, DimensionError, ModelError, UnboundedSetError
from ..interval._derivative import JacobianInclusion
from ..interval.compiler import InclusionFunction, _discontinuous_ops
from ..model import Model
from ..sets import _zono_num as zn
from ._common import inclusion_of, split_inclusion
from ._zbatch import ZonotopeFrontier

__all__: list[str] = []


class _Image:
    """Enclosure of ``f(Z)`` (or ``f(Z, W)``) for a zonotope batch.

    Mean-value form with Kühn's inclusion (thesis (4.14)-(4.16), Thm 4.4): for ``x`` in
    ``Z = c ⊕ H B^p ⊕ [-r, r]`` and ``w`` in ``W``, row by row
    ``f_k(x, w) = f_k(c, w) + ∇_x f_k(ξ_k, w) (x - c)`` with ``ξ_k`` on the segment
    ``[c, x] ⊆ □Z`` (the bounding box). So ``f(x, w) ∈ [f(c, W)] + [J](H α + ρ)`` with
    ``[J] ⊇ ∇_x f(□Z, W)``, ``α ∈ B^p``, ``|ρ| <= r``. With ``[M] ⊇ [J] H`` (outward
    interval product) and ``Mid/Rad`` rounded so that ``[M] ⊆ Mid ± Rad``, the enclosure
    is the zonotope

    ``Mid[f(c, W)] ⊕ Mid[M] B^p ⊕ [-s, s]``,
    ``s = Rad[f(c, W)] + sum_j Rad[M]_{:j} + |[J]| r`` (sums rounded upward),

    i.e. Kühn's diagonal generator matrix G of (4.15) written as a box. The mean-value form
    of row ``k`` needs ``f_k`` continuous on ``□Z``: where an operation of ``f_k`` may jump
    on ``□Z`` (floor, sign, comparisons, if_else, fmod, a pole ...; decided per zonotope from
    interval enclosures of the operations' arguments) or its Jacobian is unbounded, row
    ``k`` is the interval enclosure of ``f_k(□Z, W)`` instead (zero generator row, its
    radius in ``s``).
    """

    def __init__(self, f: Any, n_x: int | None, W: Any, box_form: str | None) -> None:
        self.identity = f is None
        self.W = None
        if self.identity:
            if n_x is None:
                raise ValueError("the dimension of the identity map is unknown")
            self.n = self.m = n_x
            return
        given = None  # an InclusionFunction passed as f: evaluated as given
        if isinstance(f, InclusionFunction):
            f, given = split_inclusion(f, "f")
        source = None  # the SX Function of f, whose (cached) inclusions are evaluated
        if isinstance(f, ca.Function):
            if f.n_in() != 1 or f.n_out() != 1:
                raise DimensionError(
                    f"zonotope_sivia needs a Function with one input and one output; "
                    f"'{f.name()}' has {f.n_in()} inputs and {f.n_out()} outputs (use "
                    "casadi.vertcat to stack them)")
            if not f.is_a("SXFunction"):
                f = f.expand()
            source = f
            if W is not None:
                raise ModelError("W is only used with a Model that has a disturbance w")
            x = ca.SX.sym("x", f.numel_in(0))
            expr = ca.densify(ca.vec(f(x)))
            syms = [x]
            name = f.name()
        elif isinstance(f, Model):
            if f.m > 0:
                raise ModelError(
                    f"model '{f.name}' has {f.m} inputs; set inversion needs an autonomous "
                    "map: close the loop first (model.closed_loop(K))")
            x = f.x
            expr = f.f
            syms = [x]
            name = f.name
            if f.l > 0:
                Wb = f.W if W is None else W
                from .._validate import as_boxes

                self.W = as_boxes(Wb, f.l, "W")
                if self.W.shape[0] != 1 or not np.isfinite(self.W).all():
                    raise UnboundedSetError("W must be one bounded box")
                syms = [x, f.w]
            elif W is not None:
                raise ModelError(f"model '{f.name}' has no disturbance; do not pass W")
        else:
            raise TypeError(f"f must be None (identity), a casadi.Function, an "
                            f"InclusionFunction or a Model; got {type(f).__name__}")
        self.n = int(x.numel())
        self.m = int(expr.numel())
        if self.W is None:
            syms = [x]
        if isinstance(f, Model):  # exact literals (the f of a closed loop is rounded)
            fun = f.interval_map("xw" if self.W is not None else "x")
        else:
            fun = ca.Function(f"{name}_map", syms, [expr])
        self.fun = fun
        self.discontinuous = _discontinuous_ops(fun)
        if self.discontinuous:
            warnings.warn(
                f"'{name}' contains operations through which it may jump "
                f"({', '.join(self.discontinuous)}); the mean-value form is not valid on "
                "zonotopes whose bounding box reaches a jump: there the natural interval "
                "enclosure over the bounding box is used instead", CmpcWarning, stacklevel=4)
        # interval Jacobian whose rows are [-inf, inf] on boxes where they may jump
        self.jac = JacobianInclusion(fun, wrt=0)
        point = "centered" if self.W is not None and not self.discontinuous else "natural"
        # The inclusions of f itself (its output flattened column-major, structural zeros
        # [0, 0]: the layout of fun's dense vector) come from the cache of inclusion(), or are
        # the one given; a Model's map is compiled here.
        self._source, self._given = source, given
        self.point = self._inclusion(point)
        self.box = self._inclusion(box_form) if box_form else None
        self._hull: InclusionFunction | None = self.box

    def _inclusion(self, kind: str) -> InclusionFunction:
        """The inclusion function of ``f`` of this kind: cached on its Function, the one
        given, or compiled here for a Model's map."""
        if self._source is None:
            return InclusionFunction(self.fun, kind)
        return inclusion_of(self._source, kind, self._given)

    def __call__(self, fr: ZonotopeFrontier
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """(centres, generators, radii, valid, boxes) of the image enclosures."""
        C, H, r = fr.centers, fr.generators, fr.radii
        N = len(fr)
        if self.identity:
            return C, H, r, np.ones(N, dtype=bool), None
        Xb = fr.bounding_boxes()
        extra = [self.W] if self.W is not None else []
        boxes = None
        if self.box is not None:
            boxes = self.box.evaluate_unchecked([Xb] + extra, N)[0]
        P = np.stack([C, C], axis=-1)
        fp = self.point.evaluate_unchecked([P] + extra, N)[0]  # (N, m, 2)
        J = self.jac([Xb] + extra, N)  # (N, m, n, 2); [-inf, inf] rows where f may jump
        rows = np.isfinite(fp).all(axis=2) & np.isfinite(J).all(axis=(2, 3))  # (N, m)
        if not rows.all():
            # rows without a mean-value enclosure: the interval hull of f over the bounding
            # box, as an independent box generator (zero generator row)
            if self._hull is None:
                self._hull = self._inclusion("natural")
            hull = boxes if boxes is not None else \
                self._hull.evaluate_unchecked([Xb] + extra, N)[0]
            fp = np.where(rows[..., None], fp, hull)
            J = np.where(rows[..., None, None], J, 0.0)
        valid = np.isfinite(fp).all(axis=(1, 2))
        if not valid.all():
            fp = np.where(valid[:, None, None], fp, 0.0)
        Jlo, Jhi = J[..., 0], J[..., 1]
        Mlo, Mhi = zn.imatmul(Jlo, Jhi, H, H)  # (N, m, p)
        Mmid, Mrad = zn.midrad(Mlo, Mhi)
        q, qrad = zn.midrad(fp[..., 0], fp[..., 1])
        s = zn.add_up(qrad, zn.sum_up(Mrad, axis=-1))
        if np.any(r):
            mag = np.maximum(np.abs(Jlo), np.abs(Jhi))  # (N, m, n)
            s = zn.add_up(s, zn.sum_up(zn.mul_up(mag, r[:, None, :]), axis=-1))
        ok = np.isfinite(s).all(axis=1) & np.isfinite(Mmid).all(axis=(1, 2))
        valid &= ok
        if not ok.all():
            s = np.where(valid[:, None], s, 0.0)
            Mmid = np.where(valid[:, None, None], Mmid, 0.0)
        return q, Mmid, s, valid, boxes
