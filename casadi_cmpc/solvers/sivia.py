"""Set inversion via interval analysis (SIVIA, thesis Alg 4.1)."""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .._validate import as_boxes
from ..exceptions import DimensionError, ModelError
from ..interval import arith as _ar
from ..interval._derivative import ParamFunction
from ..interval._native import Rows, address, c_function
from ..interval.compiler import InclusionFunction, inclusion
from ..model import Model
from ..sets.base import SetBase
from ..sets.box import Box
from ..sets.paving import Paving
from ._common import single_box
from .engine import INNER, OUTER, BoxFrontier, branch_and_bound
from .result import SetResult

__all__ = ["sivia", "image_classifier"]


def _as_inclusion(f: Any, kind: str) -> InclusionFunction:
    if isinstance(f, (ca.Function, ParamFunction)):
        if f.n_in() != 1 or f.n_out() != 1:
            raise DimensionError(
                f"sivia needs a Function with one input and one output; '{f.name()}' has "
                f"{f.n_in()} inputs and {f.n_out()} outputs (use casadi.vertcat to stack them)")
        return inclusion(f, kind)
    if isinstance(f, InclusionFunction):
        if f.n_in != 1 or f.n_out != 1:
            raise DimensionError(
                f"sivia needs an inclusion function with one input and one output; "
                f"'{f.fun.name()}' has {f.n_in} inputs and {f.n_out} outputs")
        return f
    raise TypeError(f"f must be a casadi.Function or an InclusionFunction; got {type(f).__name__}")


def _image_rows(F: InclusionFunction, lo: np.ndarray, hi: np.ndarray) -> list[tuple[Any, Any]]:
    """Enclosures of the output components of F over the boxes ``lo``, ``hi`` (N, n).

    One ``(lower, upper)`` pair per component, arrays of shape (N,) or scalars; a NaN bound
    means "no information" (every comparison with it is False, so the box stays undecided).
    The natural form runs the compiled evaluator on views of ``lo``, ``hi`` (its operations
    never write into their operands), without packing the result into an (N, m, 2) array.
    """
    ev = getattr(F, "_eval", None)
    pos = getattr(F, "_out_pos", None)
    if ev is not None and pos is not None and (F.kind == "natural" or F.centered_fallback):
        o: list[list[Any]] = [[None] * len(p) for p in pos]
        with np.errstate(all="ignore"):
            ev([lo.T], [hi.T], o)
        rows: list[tuple[Any, Any]] = [(0.0, 0.0)] * F.size_out[0]  # structural zeros
        for j, b in zip(pos[0], o[0], strict=True):
            rows[int(j)] = b
        return rows
    img = F.evaluate_unchecked([np.stack([lo, hi], axis=-1)], lo.shape[0])[0]
    return [(img[:, j, 0], img[:, j, 1]) for j in range(img.shape[1])]


@dataclass(frozen=True)
class Thresholds:
    """Bounds ``[y_lo, y_hi]`` on one output element, as thresholds on an expression ``g``
    with ``f_j = steps(g)``: ``in_*`` for proofs of ``f_j`` inside, ``out_*`` for proofs of
    ``f_j`` outside (None: no bound on that side). E.g. ``f_j = g + c`` and ``f_j > y`` is
    proven by ``g > in_lo = up(y - c)``, ``f_j <= y`` by ``g <= out_lo = dn(y - c)``."""

    in_lo: float | None
    out_lo: float | None
    in_hi: float | None
    out_hi: float | None

    @classmethod
    def through(cls, y_lo: float, y_hi: float, steps: list[tuple[str, float]]) -> Thresholds:
        """Move the bounds back through ``steps`` (outermost first), rounding each threshold
        so that the proofs stay valid for the exact real values."""
        in_lo = out_lo = y_lo if np.isfinite(y_lo) else None
        in_hi = out_hi = y_hi if np.isfinite(y_hi) else None

        def back(t: float, kind: str, c: float, upward: bool) -> float:
            """y - c (for f = g + c) or y / c (for f = g c, c > 0), rounded up or down."""
            if kind == "add":
                return _ar.up(t - c) if upward else _ar.dn(t - c)
            return _ar.upm(t / c) if upward else _ar.dnm(t / c)

        with np.errstate(all="ignore"):
            for kind, c in steps:  # f > y <=> g > back(y); inner proofs need the larger one
                if in_lo is not None:
                    in_lo, out_lo = back(in_lo, kind, c, True), back(out_lo, kind, c, False)
                if in_hi is not None:
                    in_hi, out_hi = back(in_hi, kind, c, False), back(out_hi, kind, c, True)
        # NaN (an overflow turned into inf - inf) makes every comparison False: no proof
        return cls(*(None if v is None else float(v) for v in (in_lo, out_lo, in_hi, out_hi)))


# One pass over a level's joint image (N, k, 2): per box, every element's proof inside
# (clearing its bit of the open mask) or outside, and the box's label. flags[c]: bit 0 a
# lower bound, bit 1 an upper bound, bit 2 neither (inside = defined: no NaN bound and not
# the whole line). Comparisons as in _ComponentClassifier._decide (NaN: no proof).
_DECIDE_C = r"""
#include <stdint.h>
#include <math.h>
void cmpc_sivia_decide(int64_t n, int64_t k, const double *img, const double *t,
                       const unsigned char *flags, int64_t open, uint64_t *mask,
                       signed char *labels)
{
    int64_t i, c;
    for (i = 0; i < n; ++i) labels[i] = 0;  /* first: 1 where an element is proven outside */
    for (c = 0; c < k; ++c) {  /* element by element: loops over the boxes without branches */
        const double *b = img + 2 * c;
        const double t0 = t[4 * c], t1 = t[4 * c + 1], t2 = t[4 * c + 2], t3 = t[4 * c + 3];
        const int f = flags[c], has_lo = f & 1, has_hi = (f >> 1) & 1;
        const uint64_t bit = (uint64_t)1 << c;
        if (f & 4) {
            for (i = 0; i < n; ++i) {
                const double l = b[2 * k * i], h = b[2 * k * i + 1];
                const int ins = !(isnan(l) | isnan(h) | ((l == -INFINITY) & (h == INFINITY)));
                mask[i] &= ~(ins ? bit : 0);
            }
        } else if (open) {
            for (i = 0; i < n; ++i) {
                const double l = b[2 * k * i], h = b[2 * k * i + 1];
                const int ins = (!has_lo | (l > t0)) & (!has_hi | (h < t2));
                labels[i] |= (has_lo & (h <= t1)) | (has_hi & (l >= t3));
                mask[i] &= ~(ins ? bit : 0);
            }
        } else {
            for (i = 0; i < n; ++i) {
                const double l = b[2 * k * i], h = b[2 * k * i + 1];
                const int ins = (!has_lo | (l >= t0)) & (!has_hi | (h <= t2));
                labels[i] |= (has_lo & (h < t1)) | (has_hi & (l > t3));
                mask[i] &= ~(ins ? bit : 0);
            }
        }
    }
    for (i = 0; i < n; ++i)
        labels[i] = (signed char)(labels[i] ? -1 : (mask[i] == 0));
}
"""


_DECIDE_ARGS = [ctypes.c_int64, ctypes.c_int64] + [ctypes.c_void_p] * 3 + [ctypes.c_int64] \
    + [ctypes.c_void_p] * 2


def _decide_kernel(wait: bool = False) -> Any:
    """The C decision of a joint image, or None (no compiler, ``CMPC_NATIVE=0``, or, with
    ``wait=False``, still compiling in the background: numpy decides meanwhile, with the
    same answers)."""
    return c_function(_DECIDE_C, "cmpc_sivia_decide", _DECIDE_ARGS, wait)


def _defined(l: Any, h: Any) -> Any:
    """Where an output enclosure ``[l, h]`` proves the element defined at every point of its
    box: no NaN bound ("possibly undefined") and not the whole line (which is what a
    possibly undefined result becomes once NaN bounds are replaced by infinities)."""
    return ~(np.isnan(l) | np.isnan(h) | ((l == -np.inf) & (h == np.inf)))


class _ComponentClassifier:
    """Box-target classifier that evaluates each output element separately and only on the
    boxes where it is still open.

    An element proven inside its bounds on a box holds on every sub-box, so the proof is kept
    in the frontier's per-box data (``data["open"]``: bit ``c`` set while element ``c`` is not
    proven; for more than 64 elements a boolean ``(N, k)`` array) and inherited by both halves
    of a bisected box: later levels evaluate only the constraints that are still open, which
    is where SIVIA spends its time (thin boundary regions usually involve one or two
    constraints). An element without a finite bound in Y must still be proven *defined*
    (inner means "f is defined and in Y at every point").
    """

    #: levels of at least this many boxes are evaluated in one call of the function's
    #: native kernel (every element at once) once the function has moved to it: one call
    #: of a few microseconds, against one numpy evaluation per open element
    JOINT_MIN = 1
    #: levels of at least this many boxes count toward the function's move to its native
    #: kernel (a search of small levels only does not compile one)
    JOINT_COUNT_MIN = 64

    def __init__(self, comps: list[tuple[Any, Thresholds]], open_target: bool,
                 step: int, joint: tuple[InclusionFunction, list[Thresholds]] | None = None
                 ) -> None:
        self.comps = [getattr(ev, "unchecked", ev) for ev, _ in comps]
        self.thresholds = [t for _, t in comps]
        self.joint = joint
        self.open_target = open_target
        self.step = step
        k = len(comps)
        self.k = k
        self.wide = k > 64
        if self.wide:
            self.dtype = np.dtype(bool)
            return
        self.dtype = np.uint64  # (the layout of the C decision)
        self.bits = [(self.dtype(1 << c), ~self.dtype(1 << c)) for c in range(k)]
        self.all_open = self.dtype((1 << k) - 1) if k < 64 else self.dtype(2**64 - 1)
        if joint is not None:
            self._joint_thresholds(joint[1])

    def _joint_thresholds(self, ts: list[Thresholds]) -> None:
        """The thresholds of every element as (k,) arrays, for :meth:`_decide_all`."""
        def arr(name: str) -> tuple[np.ndarray, np.ndarray]:
            v = [getattr(t, name) for t in ts]
            return (np.array([np.nan if x is None else x for x in v]),
                    np.array([x is not None for x in v]))

        (self.t_in_lo, self.has_lo), (self.t_out_lo, _) = arr("in_lo"), arr("out_lo")
        (self.t_in_hi, self.has_hi), (self.t_out_hi, _) = arr("in_hi"), arr("out_hi")
        self.free = np.flatnonzero(~(self.has_lo | self.has_hi))
        self.bit_values = np.array([b for b, _ in self.bits], dtype=self.dtype)
        self.t_all = np.ascontiguousarray(np.stack(
            [self.t_in_lo, self.t_out_lo, self.t_in_hi, self.t_out_hi], axis=1))
        self.flags = (self.has_lo.astype(np.uint8) | (self.has_hi.astype(np.uint8) << 1)
                      | ((~(self.has_lo | self.has_hi)).astype(np.uint8) << 2))

    def _test(self, c: int, lo: np.ndarray, hi: np.ndarray) -> tuple[Any, Any]:
        """(inside, outside) proven for element ``c`` over the boxes ``lo``, ``hi`` (N, n)."""
        l, h = self.comps[c](lo, hi)
        return self._decide(l, h, self.thresholds[c], lo.shape[0])

    def _decide(self, l: Any, h: Any, t: Thresholds, N: int) -> tuple[Any, Any]:
        """(inside, outside) proven from the enclosure ``[l, h]`` of an element and its
        thresholds ``t``."""
        ins = out = None
        if t.in_lo is not None:
            if self.open_target:
                ins, out = l > t.in_lo, h <= t.out_lo
            else:
                ins, out = l >= t.in_lo, h < t.out_lo
        if t.in_hi is not None:
            if self.open_target:
                i2, o2 = h < t.in_hi, l >= t.out_hi
            else:
                i2, o2 = h <= t.in_hi, l > t.out_hi
            ins = i2 if ins is None else ins & i2
            out = o2 if out is None else out | o2
        if ins is None:  # no finite bound: inside Y wherever the element is defined
            ins, out = _defined(l, h), False
        if np.ndim(ins) == 0 or np.ndim(out) == 0:  # a constant element
            return np.broadcast_to(ins, (N,)), np.broadcast_to(out, (N,))
        return ins, out

    def _joint_image(self, fr: BoxFrontier) -> np.ndarray | None:
        """Every element's enclosure (N, k, 2) by one call of the native kernel, for a
        level of a function that has moved to it (levels of :attr:`JOINT_COUNT_MIN` boxes
        or more count toward the move, see :meth:`InclusionFunction.evaluate_unchecked`:
        it depends on the calls made, not on timings); None: the elements are evaluated
        one by one."""
        if self.joint is None or len(fr) < self.JOINT_MIN:
            return None
        F = self.joint[0]
        N = len(fr)
        if not (F._wants_native(N) if N >= self.JOINT_COUNT_MIN else F._native_ready()):
            return None
        run = F._native_kernel()
        if run is None:
            return None
        return run([Rows(fr.lo, fr.hi)], N)[0]  # read in place from the frontier's bounds

    def _decide_all(self, img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_decide` for every element at once: ``(inside, outside)``, (N, k) booleans
        from the enclosures ``img`` (N, k, 2) and the thresholds of the raw elements."""
        l, h = img[:, :, 0], img[:, :, 1]
        N, k = l.shape
        if self.open_target:
            ins_lo, out_lo = l > self.t_in_lo, h <= self.t_out_lo
            ins_hi, out_hi = h < self.t_in_hi, l >= self.t_out_hi
        else:
            ins_lo, out_lo = l >= self.t_in_lo, h < self.t_out_lo
            ins_hi, out_hi = h <= self.t_in_hi, l > self.t_out_hi
        # a side without a bound proves nothing outside and does not stop a proof inside
        # (its threshold is NaN: every comparison above is False there)
        ins = (ins_lo | ~self.has_lo) & (ins_hi | ~self.has_hi)
        out = out_lo | out_hi
        if self.free.size:  # no finite bound: inside Y wherever the element is defined
            ins[:, self.free] = _defined(l[:, self.free], h[:, self.free])
        return ins, out

    def _bounds(self, c: int, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        N = lo.shape[0]
        if N <= self.step:
            return self._test(c, lo, hi)
        inside = np.empty(N, dtype=bool)
        outside = np.empty(N, dtype=bool)
        for i0 in range(0, N, self.step):
            i1 = min(i0 + self.step, N)
            inside[i0:i1], outside[i0:i1] = self._test(c, lo[i0:i1], hi[i0:i1])
        return inside, outside

    def __call__(self, fr: BoxFrontier) -> np.ndarray:
        with np.errstate(all="ignore"):
            if self.wide:
                return self._classify_wide(fr)
            return self._classify(fr)

    def _classify(self, fr: BoxFrontier) -> np.ndarray:
        N = len(fr)
        data = fr.data if fr.data is not None else {}
        mask = data.get("open")
        if mask is None or mask.shape != (N,) or mask.dtype != self.dtype:
            mask = np.full(N, self.all_open, dtype=self.dtype)
        img = self._joint_image(fr)
        if img is not None:
            # every element at once; an element proven on the parent box is proven again
            # (clearing its bit again), and no sound enclosure proves it outside
            fn = _decide_kernel()
            if fn is not None:
                mask = np.ascontiguousarray(mask)
                labels = np.empty(N, dtype=np.int8)
                fn(N, self.k, address(img), address(self.t_all), address(self.flags),
                   int(self.open_target), address(mask), address(labels))
                data["open"] = mask
                fr.data = data
                return labels
            ins, out = self._decide_all(img)
            mask &= ~(ins.view(np.uint8) * self.bit_values).sum(axis=1, dtype=self.dtype)
            data["open"] = mask
            fr.data = data
            labels = (mask == 0).view(np.int8)
            labels[out.any(axis=1)] = OUTER
            return labels
        outer = np.zeros(N, dtype=bool)
        for c, (bit, clear) in enumerate(self.bits):
            idx = (mask & bit).nonzero()[0]
            if idx.size == 0:
                continue
            if idx.size > 0.9 * N:  # nearly all open: no gathers
                ins, out = self._bounds(c, fr.lo, fr.hi)
                outer |= out  # a proven element cannot be violated anywhere on its box
                mask[ins] &= clear
            else:
                ins, out = self._bounds(c, fr.lo.take(idx, 0), fr.hi.take(idx, 0))
                outer[idx[out]] = True
                sel = idx[ins]
                mask[sel] = mask.take(sel) & clear
        data["open"] = mask
        fr.data = data
        labels = (mask == 0).view(np.int8)  # INNER = 1 where every element is proven
        labels[outer] = OUTER
        return labels

    def _classify_wide(self, fr: BoxFrontier) -> np.ndarray:
        """The same with a boolean ``(N, k)`` mask (more than 64 elements)."""
        N = len(fr)
        data = fr.data if fr.data is not None else {}
        mask = data.get("open")
        if mask is None or mask.shape != (N, self.k) or mask.dtype != self.dtype:
            mask = np.ones((N, self.k), dtype=bool)
        outer = np.zeros(N, dtype=bool)
        for c in range(self.k):
            idx = mask[:, c].nonzero()[0]
            if idx.size == 0:
                continue
            ins, out = self._bounds(c, fr.lo.take(idx, 0), fr.hi.take(idx, 0))
            outer[idx[out]] = True
            mask[idx[ins], c] = False
        data["open"] = mask
        fr.data = data
        labels = (~mask.any(axis=1)).view(np.int8)
        labels[outer] = OUTER
        return labels


def _box_difference(lo: np.ndarray, hi: np.ndarray, lo2: np.ndarray, hi2: np.ndarray
                    ) -> np.ndarray:
    """Boxes tiling ``[lo, hi] minus [lo2, hi2]`` for rows with ``[lo2, hi2] ⊆ [lo, hi]``.

    For each dimension ``d``, the slabs below ``lo2_d`` and above ``hi2_d`` with dimensions
    ``< d`` already cut to ``[lo2, hi2]`` and dimensions ``> d`` whole; empty slabs are left
    out. Returns an (M, n, 2) array.
    """
    n = lo.shape[1]
    out = []
    for d in range(n):
        for side in (0, 1):
            rows = np.flatnonzero(lo2[:, d] > lo[:, d]) if side == 0 else \
                np.flatnonzero(hi2[:, d] < hi[:, d])
            if rows.size == 0:
                continue
            b_lo = np.concatenate([lo2[rows, :d], lo[rows, d:]], axis=1)
            b_hi = np.concatenate([hi2[rows, :d], hi[rows, d:]], axis=1)
            if side == 0:
                b_hi[:, d] = lo2[rows, d]
            else:
                b_lo[:, d] = hi2[rows, d]
            out.append(np.stack([b_lo, b_hi], axis=-1))
    return np.concatenate(out) if out else np.zeros((0, n, 2))


class _Contracting:
    """Wraps a classifier: each box is first narrowed by a forward-backward contractor.

    The contracted box replaces the box in the frontier (it holds every solution of the box),
    the removed parts are recorded as outside boxes (so that the three views still tile the
    domain), and a box the contractor proves to hold no solution is labelled OUTER whole.
    The contracted box is widened by one float on each side that was cut, so that the
    removed (closed) slabs do not share a face with it: every point of a slab, faces
    included, lies outside the contracted box and is therefore proven to be no solution.
    """

    def __init__(self, C: Any, classify: Any, keep_outer: bool) -> None:
        self.C = C
        self.classify = classify
        self.keep_outer = keep_outer
        self.removed: list[np.ndarray] = []
        self.n_removed = 0

    def __call__(self, fr: BoxFrontier) -> np.ndarray:
        lo2, hi2, empty = self.C(fr.lo, fr.hi)
        keep = ~empty
        # Solutions may lie on the faces of the contracted box, which the removed slabs
        # would share: keep one float more on each cut side, so that every point of a
        # (closed) removed slab lies strictly outside [lo2, hi2] and is proven no solution.
        with np.errstate(all="ignore"):
            lo2 = np.where(lo2 > fr.lo, np.maximum(np.nextafter(lo2, -np.inf), fr.lo), fr.lo)
            hi2 = np.where(hi2 < fr.hi, np.minimum(np.nextafter(hi2, np.inf), fr.hi), fr.hi)
        shrunk = keep & ((lo2 > fr.lo) | (hi2 < fr.hi)).any(axis=1)
        if shrunk.any():
            i = np.flatnonzero(shrunk)
            slabs = _box_difference(fr.lo[i], fr.hi[i], lo2[i], hi2[i])
            e = keep[:, None]
            lo_c, hi_c = np.where(e, lo2, fr.lo), np.where(e, hi2, fr.hi)
            # the removed slabs and the contracted boxes replace the boxes together, so that
            # an interruption of the classification below still leaves a tiling
            self.n_removed += slabs.shape[0]
            if self.keep_outer:
                self.removed.append(slabs)
            fr.lo, fr.hi, fr._split_dim = lo_c, hi_c, None
        labels = np.asarray(self.classify(fr), dtype=np.int8)
        labels[empty] = OUTER
        return labels


def image_classifier(F: InclusionFunction, Y: Any, open_target: bool = False):
    """Classifier of boxes X by their image enclosure F(X) against a target set Y.

    INNER when F(X) ⊆ Y is proven, OUTER when F(X) ∩ Y = ∅ is proven, else UNDECIDED.
    Y is a Box (closed; ``open_target=True`` for its interior), or any set with
    ``contains_box`` / ``intersects_box`` (Polytope, PolytopeUnion, Zonotope, Paving).
    """
    m = F.size_out[0]
    if isinstance(Y, Box):
        if Y.dim != m:
            raise DimensionError(f"target Y has dimension {Y.dim}; f has {m} outputs")
        ylo, yhi = Y.lo, Y.hi
        rows_lo = [(j, float(ylo[j])) for j in range(m) if np.isfinite(ylo[j])]
        rows_hi = [(j, float(yhi[j])) for j in range(m) if np.isfinite(yhi[j])]
        step = int(getattr(F, "chunk", 8192))
        bounded = {j for j, _ in rows_lo} | {j for j, _ in rows_hi}
        # elements without a finite bound are tested for definedness only
        free = [j for j in range(m) if j not in bounded]
        evs = [F.component_evaluator(j) for j in range(m)] if m > 1 else []
        if evs and all(ev is not None for ev in evs):
            comps = []
            for j, ev in enumerate(evs):
                core = F.component_core(j) if j in bounded else None
                steps: list[tuple[str, float]] = []
                if core is not None:  # f_j = affine steps of a core expression
                    ev, steps = core
                comps.append((ev, Thresholds.through(float(ylo[j]), float(yhi[j]), steps)))
            raw = [Thresholds.through(float(ylo[j]), float(yhi[j]), []) for j in range(m)]
            joint = (F, raw) if F.kind == "natural" and F._keep is None else None
            return _ComponentClassifier(comps, open_target, step, joint)

        def classify(fr: BoxFrontier) -> np.ndarray:
            N = len(fr)
            labels = np.zeros(N, dtype=np.int8)
            for i0 in range(0, N, step):
                i1 = min(i0 + step, N)
                rows = _image_rows(F, fr.lo[i0:i1], fr.hi[i0:i1])
                inner = np.ones(i1 - i0, dtype=bool)
                outer = np.zeros(i1 - i0, dtype=bool)
                for j, y in rows_lo:
                    lo_j, hi_j = rows[j]
                    if open_target:
                        inner &= lo_j > y
                        outer |= hi_j <= y
                    else:
                        inner &= lo_j >= y
                        outer |= hi_j < y
                for j, y in rows_hi:
                    lo_j, hi_j = rows[j]
                    if open_target:
                        inner &= hi_j < y
                        outer |= lo_j >= y
                    else:
                        inner &= hi_j <= y
                        outer |= lo_j > y
                for j in free:  # inner also means "f_j defined at every point"
                    inner &= _defined(*rows[j])
                lab = labels[i0:i1]
                np.putmask(lab, inner, INNER)
                np.putmask(lab, outer & ~inner, OUTER)
            return labels

        return classify
    if not isinstance(Y, SetBase):
        raise TypeError(f"Y must be a Box, Polytope, PolytopeUnion or another set; got "
                        f"{type(Y).__name__}")
    if Y.dim != m:
        raise DimensionError(f"target Y has dimension {Y.dim}; f has {m} outputs")

    def classify_set(fr: BoxFrontier) -> np.ndarray:
        img = F.evaluate_unchecked([fr.boxes], len(fr))[0]
        finite = np.isfinite(img).all(axis=(1, 2))
        labels = np.zeros(img.shape[0], dtype=np.int8)
        if finite.any():
            sub = img[finite]
            inside = np.asarray(Y.contains_box(sub), dtype=bool)
            meets = np.asarray(Y.intersects_box(sub), dtype=bool)
            lab = np.zeros(sub.shape[0], dtype=np.int8)
            lab[inside] = INNER
            lab[~meets & ~inside] = OUTER
            labels[finite] = lab
        return labels

    return classify_set


def _model_map(model: Model, X0: Any, W: Any) -> tuple[ca.Function, Any, np.ndarray | None]:
    """(Function of the successor, X0, W box or None) of a Model given to :func:`sivia`.

    Without a disturbance the Function is ``x -> f(x)``; with one it is ``[x; w] -> f(x, w)``
    (one stacked input), W being kept whole in every box. Both are cached on the model.
    """
    if model.m > 0:
        raise ModelError(
            f"sivia inverts a map of the state alone, but model '{model.name}' has "
            f"{model.m} input(s): whether some u in U or every u must bring f(x, u, w) into "
            "Y is not something sivia guesses. For a given law u = K x (or an expression "
            "in x) invert the closed loop, cm.sivia(model.closed_loop(K), Y=..., eps=...); "
            "for 'some u in U works' use cm.one_step_set(model, target, eps) or "
            "cm.quantified_sivia(model, Y=..., eps=...)")
    X0 = model.X if X0 is None else X0
    if model.l == 0:
        if W is not None:
            raise ModelError(f"model '{model.name}' has no disturbance w; do not pass W")
        # exact literals: the f of a closed loop is rounded (see Model.interval_map)
        return model.interval_map("x"), X0, None
    Wb = single_box(model.W if W is None else W, "W", model.l)
    return model.interval_map("xw", joined=True), X0, Wb


def sivia(f: Any, X0: Any = None, Y: Any = None, eps: float | None = None, *,
          W: Any = None, kind: str = "natural", open_target: bool = False,
          split_ratio: float = 0.5, relative: bool = False, max_boxes: int = 5_000_000,
          time_limit: float | None = None, keep_outer: bool = True, contract: bool = False,
          progress: bool | None = None, executor: Any = None) -> SetResult:
    """Set inversion via interval analysis: pave ``{x in X0 : f(x) in Y}`` (thesis Alg 4.1).

    Parameters
    ----------
    f : casadi.Function, InclusionFunction or Model
        ``R^n -> R^m``, one input and one output (an SX Function; MX is expanded). A
        casadi.Function is compiled with :func:`casadi_cmpc.interval.inclusion` (cached per
        Function object); an InclusionFunction is used as given (its own kind and backend;
        ``kind`` is then ignored).

        A :class:`~casadi_cmpc.Model` **without inputs** (``m = 0``, e.g. a closed loop
        ``model.closed_loop(K)``) stands for its successor map ``x -> f(x, w)``: the
        result paves ``{x in X0 : f(x, w) in Y for every w in W}`` (``X0`` defaults to
        ``model.X``, ``W`` to ``model.W``; W is an interval parameter, never bisected).
        Only the successor is inverted: a closed loop's input bound ``law(x) in U`` is not
        part of it. A model with inputs is refused (:class:`~casadi_cmpc.ModelError`):
        whether *some* or *every* u must work is ambiguous; close the loop, or use
        :func:`~casadi_cmpc.one_step_set` / :func:`~casadi_cmpc.quantified_sivia` for
        "some u in U".
    X0 : Box or array_like, shape (n, 2)
        The initial (bounded) box. Required, except for a Model (default ``model.X``).
    Y : Box, Polytope, PolytopeUnion or another set of dimension m
        The target set. A Box may have infinite bounds (e.g. ``[0, inf)``). Required
        (pass it by keyword when X0 is left to its default: ``sivia(model, Y=T, eps=0.1)``).
    eps : float
        Boxes whose widest component is at most ``eps`` are not bisected further (relative
        to the widths of ``X0`` when ``relative=True``); neither are boxes whose widest
        component holds no float strictly inside (both become boundary boxes). Required.
    W : Box, optional
        Disturbance box of a Model with ``w`` (default: ``model.W``); refused otherwise.
    kind : {"natural", "centered"}
        Inclusion function used to enclose the images.
    open_target : bool
        For a Box target: prove ``f(x)`` in the *interior* of Y (e.g. ``r(p) > 0``).
    split_ratio : float
        Position of the cut in the widest component (0.5: midpoint; codac uses 0.49).
    max_boxes, time_limit : optional limits; a stopped search reports its leftovers as
        boundary boxes (still sound).
    keep_outer : bool
        Keep the discarded boxes (``result.outside``) for drawing; they are always counted.
    contract : bool
        Narrow every box with a forward-backward (HC4) contractor generated from the same
        CasADi graph before testing it (:func:`casadi_cmpc.interval.contractor`, target Y or,
        for a set target, its bounding box). The parts removed are outside boxes. Needs a
        casadi.Function or a natural InclusionFunction (or a Model without disturbance:
        contracting W would prove less than "for every w"). Pays off when constraints are
        thin or tight (equalities, narrow bands); on wide inequality regions the inclusion
        test alone is usually cheaper.
    progress : bool or None
        tqdm progress bar (None: only for searches longer than 2 s).
    executor : concurrent.futures.Executor, optional
        Classify the large levels on this executor (``ProcessPoolExecutor(n)``, or
        ``distributed.Client(address).get_executor()``); the result is that of the serial
        run (:mod:`casadi_cmpc.solvers._parallel`). Not with ``contract=True`` (the
        contractor keeps the slabs it removes).

    Returns
    -------
    SetResult
        ``paving``: a :class:`~casadi_cmpc.Paving` whose three views of closed boxes together
        cover X0 (neighbouring boxes share faces):

        * ``inner``: at every point of each box, faces included, ``f`` is defined and
          ``f(x) ∈ Y`` (the interior of Y with ``open_target=True``; for every w in W for a
          Model with a disturbance);
        * ``outside``: at no point of each box, faces included, is ``f`` defined with
          ``f(x) ∈ Y`` (points where f is undefined are not solutions; for a Model with a
          disturbance: for no w in W);
        * ``boundary``: undecided boxes (narrower than eps, or left over when a limit
          stopped the search); nothing is claimed about them.

        A point on a face shared by an inner and a boundary box is a solution; on a face
        shared by an outside and a boundary box it is not. ``n_discarded`` counts the
        outside boxes. The result acts as its paving (``res.inner``, ``res.volume()``,
        ``res.plot()``, ... see :class:`~casadi_cmpc.SetResult`); ``status`` is ``PROVED``
        when the search ran to completion, ``BUDGET`` when a limit stopped it.

    Examples
    --------
    >>> import casadi as ca, numpy as np, casadi_cmpc as cm
    >>> p = ca.SX.sym("p", 2)
    >>> f = ca.Function("disk", [p], [p[0]**2 + p[1]**2])
    >>> P = cm.sivia(f, cm.Box([-2, -2], [2, 2]), cm.Box([0], [1]), eps=0.1)
    >>> 2.5 < P.volume(view="inner") <= np.pi <= P.volume(view="outer")
    True

    A closed loop as a Model (X0 = model.X):

    >>> x = ca.SX.sym("x", 2)
    >>> model = cm.Model(x=x, u=None, f=0.5 * x, X=cm.Box([-2, -2], [2, 2]))
    >>> res = cm.sivia(model, Y=cm.Box([-0.5, -0.5], [0.5, 0.5]), eps=0.1)
    >>> res.contains([[0.9, -0.9], [1.1, 0.0]], view="inner")
    array([ True, False])
    >>> bool(res.contains([1.1, 0.0], view="outside"))
    True
    """
    if Y is None:  # (a missing eps is refused by the engine: "eps must be a positive number")
        raise TypeError("sivia needs the target Y, e.g. cm.sivia(f, X0, Y, eps=0.1) or "
                        "cm.sivia(model, Y=Y, eps=0.1)")
    Wb = None
    if isinstance(f, Model):
        f, X0, Wb = _model_map(f, X0, W)
    else:
        if W is not None:
            raise ModelError("W is only used with a Model that has a disturbance w; put the "
                             "parameters of a Function into its input")
        if X0 is None:
            raise TypeError("sivia needs the initial box X0 (it defaults to model.X only "
                            "for a Model)")
    F = _as_inclusion(f, kind)
    n = F.size_in[0]
    l = 0 if Wb is None else Wb.shape[0]
    r = float(split_ratio)
    if not 0.0 < r < 1.0:
        raise ValueError(f"split_ratio must lie strictly between 0 and 1; got {split_ratio!r}")
    x0 = as_boxes(X0, n - l, "X0")
    if x0.shape[0] != 1:
        raise DimensionError(f"X0 must be a single box; got {x0.shape[0]} boxes")
    domain = Box(x0[0, :, 0], x0[0, :, 1])
    if not domain.is_bounded():
        from ..exceptions import UnboundedSetError

        raise UnboundedSetError(f"X0 must be bounded; got {domain!r}")
    scale = None
    if relative:
        scale = np.where(domain.diam > 0, domain.diam, 1.0)
    if l:
        if contract:
            raise ValueError("contract=True is not available for a Model with a disturbance: "
                             "contracting W would prove f(x, w) in Y for part of W only")
        # W rides along whole in every box: an infinite scale makes its widths count as 0
        x0 = np.concatenate([x0, Wb[None]], axis=1)
        scale = np.concatenate([np.ones(n - l) if scale is None else scale, np.full(l, np.inf)])
    classify = image_classifier(F, Y, open_target)
    if contract and executor is not None:
        raise ValueError("contract=True runs in this process: leave executor unset")
    if contract:
        from ..interval.contractor import contractor

        target = Y if isinstance(Y, Box) else Y.bounding_box()
        classify = _Contracting(contractor(F.fun, target), classify, keep_outer)
    fr = BoxFrontier.from_boxes(x0, scale=scale, split_ratio=r)
    out = branch_and_bound(fr, classify, eps, max_boxes=max_boxes, time_limit=time_limit,
                           keep_outer=keep_outer, progress=progress, desc="sivia",
                           executor=executor)
    parts = [out.inner.boxes, out.boundary.boxes, out.outer.boxes]
    n_discarded = out.n_discarded
    if contract:
        if classify.removed:
            parts[2] = np.concatenate([parts[2]] + classify.removed)
        n_discarded += classify.n_removed
    if l:  # the state part of the (x, w) boxes, whose w part is all of W
        parts = [np.ascontiguousarray(b[:, :n - l]) for b in parts]
    # Every box comes from bisecting X0 and lies in it: no checks needed.
    paving = Paving._from_solver(*parts, domain, n_discarded)
    method = f"sivia (Alg 4.1, {F.kind} inclusion{', contractor' if contract else ''})"
    return SetResult(status=out.status, message=out.message, method=method, nit=out.levels,
                     n_boxes=out.n_classified, elapsed=out.elapsed, paving=paving,
                     history=out.history)
