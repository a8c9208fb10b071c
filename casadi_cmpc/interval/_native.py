"""Native batch backend of the inclusion functions: one fused C loop over the boxes.

The C source comes from the compiler's own instruction walk (:class:`~.compiler._Codegen`:
the same constant folding, exact and widened constants and output selection as the numpy
and scalar evaluators) with the outward-rounded interval rules of :mod:`._cgen` (the rules
of the exported controllers). Every operation of one box runs in registers; one loop runs
over the batch. The rules move each rounded bound outward by at least one ulp in every
rounding mode, so the enclosures do not depend on the FPU rounding mode of the process.

The kernel is compiled once by the system C compiler (``$CC``, else ``cc``, ``gcc`` or
``clang``) with IEEE semantics (``-O2 -fno-fast-math -ffp-contract=off``) and cached on disk
by a hash of its source and of the compiler command (``$XDG_CACHE_HOME/casadi_cmpc/kernels``,
default ``~/.cache/casadi_cmpc/kernels``). Without a compiler, or for a Function with an
operation the C rules lack, :func:`native_kernel` returns None and the caller evaluates with
numpy (one :class:`~casadi_cmpc.CmpcWarning` per process says that no compiler was found).
``CMPC_NATIVE=0`` in the environment turns the backend off (every evaluation then is that of
numpy or of the scalar evaluator, bit for bit reproducible from run to run).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from ..exceptions import CmpcWarning
from ._cgen import _BINARY as _C_BINARY
from ._cgen import _UNARY as _C_UNARY
from ._cgen import PRELUDE, c_double

__all__ = ["native_kernel", "native_available", "kernel_dir"]

_FLAGS = ("-O2", "-fno-fast-math", "-ffp-contract=off", "-fPIC", "-shared")
_lock = threading.Lock()
_state: dict[str, Any] = {"cc": None, "checked": False, "warned": False}
_loaded: dict[str, Any] = {}  # source hash -> the loaded kernel function


def kernel_dir() -> Path:
    """Where compiled kernels are cached."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "casadi_cmpc" / "kernels"


def _compiler() -> str | None:
    """The C compiler command, or None (checked once per process)."""
    with _lock:
        if not _state["checked"]:
            _state["checked"] = True
            cands = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
            for c in cands:
                if shutil.which(c.split()[0]):
                    _state["cc"] = c
                    break
        return _state["cc"]


def native_disabled() -> bool:
    """Whether ``CMPC_NATIVE=0`` turns the native backend off."""
    return os.environ.get("CMPC_NATIVE", "1").strip() == "0"


def native_available() -> bool:
    """Whether the native backend can run: a C compiler was found and ``CMPC_NATIVE`` is
    not ``0``."""
    return not native_disabled() and sys.platform != "win32" and _compiler() is not None


def _warn_once(msg: str) -> None:
    with _lock:
        if _state["warned"]:
            return
        _state["warned"] = True
    warnings.warn(msg, CmpcWarning, stacklevel=4)


def _codegen_class() -> type:
    from .compiler import _Codegen

    class _CCodegen(_Codegen):
        """Emit the body of the fused batch loop: one ``civ`` per work slot."""

        def __init__(self, fun: Any, widen: frozenset[int], out_pos: Sequence[np.ndarray],
                     size_out: Sequence[int]) -> None:
            super().__init__(fun, widen)
            self.out_pos = [[int(p) for p in pos] for pos in out_pos]
            self.size_out = list(size_out)
            self.slots: set[int] = set()
            self.used_inputs: set[int] = set()

        def _lit(self, v: float) -> str:
            return c_double(v)

        def _civ(self, slot: int) -> str:
            if slot in self.consts:
                lo, hi = self.consts[slot]
                return f"CIV({c_double(lo)}, {c_double(hi)})"
            return f"v{slot}"

        def _set(self, out: int, expr: str) -> None:
            self.consts.pop(out, None)
            self.slots.add(out)
            self.lines.append(f"        v{out} = {expr};")

        def _input(self, k: int, out: int, i: int, j: int) -> None:
            self.used_inputs.add(i)
            self._set(out, f"CIV(P{i}[{2 * j}], P{i}[{2 * j + 1}])")

        def _output(self, k: int, slot: int, oi: int, j: int) -> None:
            self.lines.append(f"        civ_store(O{oi} + {2 * self.out_pos[oi][j]}, "
                              f"{self._civ(slot)});")

        def _unary(self, k: int, op: int, name: str, out: int, i0: int) -> None:
            if op not in _C_UNARY:
                raise _NoRule(name)
            fn = _C_UNARY[op]
            a = self._civ(i0)
            self._set(out, a if fn is None else f"{fn}({a})")

        def _binary(self, k: int, op: int, name: str, out: int, i0: int, i1: int) -> None:
            if op not in _C_BINARY:
                raise _NoRule(name)
            c0, c1 = self._thin(i0), self._thin(i1)
            if op == ca.OP_MUL and (c0 is None) != (c1 is None):
                var, c = (i1, c0) if c0 is not None else (i0, c1)
                if np.isfinite(c):
                    self._set(out, f"civ_mulc({self._civ(var)}, {c_double(c)})")
                    return
            self._set(out, f"{_C_BINARY[op]}({self._civ(i0)}, {self._civ(i1)})")

        def _finish(self) -> str:
            n_in = self.fun.n_in()
            slots = sorted(self.slots)
            decl = [f"        civ {', '.join(f'v{s}' for s in slots[i:i + 12])};"
                    for i in range(0, len(slots), 12)]
            head = [f"        const double *P{i} = in[{i}] + b * st[{i}];"
                    for i in range(n_in) if i in self.used_inputs]
            head += [f"        double *O{o} = out[{o}] + b * {2 * d};"
                     for o, d in enumerate(self.size_out)]
            return "\n".join([
                "void cmpc_batch(long n, const double *const *in, const long *st, "
                "double *const *out) {",
                "    long b;",
                "    for (b = 0; b < n; ++b) {",
                *decl, *head, *self.lines,
                "    }",
                "    (void)in; (void)st; (void)out;",
                "}", ""])

    return _CCodegen


class _NoRule(Exception):
    """An operation without a C interval rule."""


_HEADER = r"""#include <math.h>
#include <float.h>
""" + PRELUDE + r"""
#define CIV(a, b) ((civ){(a), (b)})

/* an output bound pair, [-inf, inf] where it is possibly undefined (as the numpy backend) */
static inline void civ_store(double *o, civ a) {
    if (!(a.lo <= a.hi)) { o[0] = -INFINITY; o[1] = INFINITY; return; }
    o[0] = a.lo;
    o[1] = a.hi;
}
"""


def kernel_source(fun: Any, widen: frozenset[int], out_pos: Sequence[np.ndarray],
                  size_out: Sequence[int], keep_outputs: Sequence[int] | None = None) -> str | None:
    """C source of the fused batch loop ``cmpc_batch`` (None: an operation has no C rule)."""
    from .compiler import _needed_instructions

    gen = _codegen_class()(fun, widen, out_pos, size_out)
    if keep_outputs is not None:
        gen.only = _needed_instructions(fun, keep_outputs)
        gen.out_map = {int(o): i for i, o in enumerate(keep_outputs)}
    try:
        body = gen.build()
    except _NoRule:
        return None
    return _HEADER + body


def centered_source(g: Any, widen: frozenset[int], size_in: Sequence[int],
                    out_pos: Sequence[np.ndarray], size_out: Sequence[int],
                    jac_rows: Sequence[int], jac_cols: Sequence[int],
                    y_nz: Sequence[Sequence[int]], with_natural: bool = False) -> str | None:
    """C source of the fused mean-value (centered) form: per box, the midpoint and the
    radii, the graph ``G(mid, box) -> [f(mid), J(box), f(box)]``, and the combination of
    :meth:`~.compiler.InclusionFunction._centered_impl` (the same operations in the same
    order), in one loop over the batch. ``with_natural``: the natural enclosures ``f(box)``
    follow as extra outputs (for a jump guard applied afterwards). None: an operation has no
    C rule."""
    from . import arith

    base = _codegen_class()
    n_in = len(size_in)
    k = len(size_out)

    class _Centered(base):  # type: ignore[misc, valid-type]
        def _input(self, kk: int, out: int, i: int, j: int) -> None:
            if i < n_in:
                self._set(out, f"CIV(M{i}_{j}, M{i}_{j})")
            else:
                self.used_inputs.add(i - n_in)
                self._set(out, f"CIV(P{i - n_in}[{2 * j}], P{i - n_in}[{2 * j + 1}])")

        def _output(self, kk: int, slot: int, oi: int, j: int) -> None:
            self.results.add((oi, j))
            self.lines.append(f"        R{oi}_{j} = {self._civ(slot)};")

    gen = _Centered(g, widen, [np.zeros(0, dtype=np.intp)] * g.n_out(), [0] * g.n_out())
    gen.results = set()
    try:
        gen.build()
    except _NoRule:
        return None
    lines = ["void cmpc_batch(long n, const double *const *in, const long *st, "
             "double *const *out) {", "    long b;", "    for (b = 0; b < n; ++b) {"]
    slots = sorted(gen.slots)
    lines += [f"        civ {', '.join(f'v{s}' for s in slots[i:i + 12])};"
              for i in range(0, len(slots), 12)]
    res = sorted(gen.results)
    lines += [f"        civ {', '.join(f'R{o}_{j}' for o, j in res[i:i + 12])};"
              for i in range(0, len(res), 12)]
    lines += [f"        const double *P{i} = in[{i}] + b * st[{i}];" for i in range(n_in)]
    lines += [f"        double *O{o} = out[{o}] + b * {2 * d};" for o, d in enumerate(size_out)]
    if with_natural:
        lines += [f"        double *N{o} = out[{k + o}] + b * {2 * d};"
                  for o, d in enumerate(size_out)]
    # midpoints (inside the box) and radii rounded up, one per joint coordinate
    c = 0
    rad: list[str] = []
    for i, d in enumerate(size_in):
        for j in range(d):
            lines += [f"        double M{i}_{j}, D{c};",
                      f"        {{ double lo = P{i}[{2 * j}], hi = P{i}[{2 * j + 1}], r;",
                      f"          M{i}_{j} = 0.5 * lo + 0.5 * hi;",
                      f"          if (M{i}_{j} < lo) M{i}_{j} = lo;",
                      f"          if (M{i}_{j} > hi) M{i}_{j} = hi;",
                      f"          r = civ_max(M{i}_{j} - lo, hi - M{i}_{j});",
                      f"          D{c} = civ_up_(r); }}"]
            rad.append(f"D{c}")
            c += 1
    lines += gen.lines
    rows: dict[int, list[int]] = {}
    for t, r in enumerate(jac_rows):
        rows.setdefault(int(r), []).append(t)
    for i in range(k):
        for j, row in enumerate(y_nz[i]):
            pos = int(out_pos[i][j])
            fm, fb = f"R{i}_{j}", f"R{k + 1 + i}_{j}"
            if with_natural:
                lines.append(f"        civ_store(N{i} + {2 * pos}, {fb});")
            terms = rows.get(int(row))
            if not terms:
                lines.append(f"        civ_store(O{i} + {2 * pos}, {fb});")
                continue
            kk = len(terms)
            scale = c_double(1.0 + (kk + 4) * arith.U)
            tiny = c_double((kk + 1) * arith.TINY)
            lines.append("        { double S = 0.0, lo, hi;")
            for t in terms:
                lines.append(f"          S += civ_term(R{k}_{t}, {rad[int(jac_cols[t])]});")
            lines += [f"          S = S * {scale} + {tiny};",
                      f"          lo = civ_dn_({fm}.lo - S); hi = civ_up_({fm}.hi + S);",
                      f"          civ_store_mv(O{i} + {2 * pos}, lo, hi, {fm}, {fb}); }}"]
    lines += ["    }", "    (void)in; (void)st; (void)out;", "}", ""]
    return _HEADER + _CENTERED_HELPERS + "\n".join(lines)


_CENTERED_HELPERS = r"""
/* the array rules of the numpy mean-value combination, element by element */
static inline double civ_dn_(double x) {
    if (x > DBL_MAX) x = DBL_MAX;
    return x - fabs(x) * 0x1p-52;
}
static inline double civ_up_(double x) {
    if (x < -DBL_MAX) x = -DBL_MAX;
    return x + fabs(x) * 0x1p-52;
}

/* mag(J) * rad: a coordinate that does not vary contributes nothing, a NaN slope is +inf */
static inline double civ_term(civ J, double r) {
    double a = -J.lo, t;
    if (a != a || J.hi != J.hi) t = NAN;
    else t = (a > J.hi ? a : J.hi) * r;
    if (t != t) t = (r == 0.0) ? 0.0 : INFINITY;
    return t;
}

/* [lo, hi] intersected with the natural enclosure fb; NaN anywhere: possibly undefined */
static inline void civ_store_mv(double *o, double lo, double hi, civ fm, civ fb) {
    if (lo != lo || hi != hi || civ_isnan(fm) || civ_isnan(fb)) {
        o[0] = -INFINITY; o[1] = INFINITY; return;
    }
    civ_store(o, civ_make(civ_max(lo, fb.lo), civ_min(hi, fb.hi)));
}

"""


def _build(src: str, key: str) -> Path | None:
    """The shared library of ``src`` in the kernel cache (compiled if absent)."""
    cc = _compiler()
    if cc is None:
        return None
    d = kernel_dir()
    lib = d / f"k{key}.so"
    if lib.is_file():
        return lib
    try:
        d.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=d) as tmp:
            c = Path(tmp) / "k.c"
            c.write_text(src)
            so = Path(tmp) / "k.so"
            r = subprocess.run([*cc.split(), *_FLAGS, "-o", str(so), str(c), "-lm"],
                               capture_output=True, text=True, timeout=300)
            if r.returncode != 0:
                warnings.warn(f"the native interval kernel did not compile ({cc}): "
                              f"{r.stderr.strip()[:400]}; numpy evaluates instead",
                              CmpcWarning, stacklevel=3)
                return None
            os.replace(so, lib)  # atomic: a concurrent process sees all of it or nothing
    except OSError as exc:
        warnings.warn(f"the native interval kernel could not be cached in {d} ({exc}); "
                      "numpy evaluates instead", CmpcWarning, stacklevel=3)
        return None
    return lib


def native_kernel(fun: Any, widen: frozenset[int], out_pos: Sequence[np.ndarray],
                  size_out: Sequence[int], keep_outputs: Sequence[int] | None = None
                  ) -> Callable[[Sequence[np.ndarray], int], list[np.ndarray]] | None:
    """``run(boxes, n) -> outputs``: the natural inclusion of ``fun`` by the fused C loop,
    on validated ``(N_i, d_i, 2)`` float64 inputs (N_i in {1, n}); None when no compiler is
    found (one warning per process) or an operation has no C rule."""
    if not native_available():
        if not native_disabled():
            _warn_once("no C compiler found (set $CC, or install cc/gcc/clang): the "
                       "inclusion functions evaluate large batches with numpy, several "
                       "times slower")
        return None
    src = kernel_source(fun, widen, out_pos, size_out, keep_outputs)
    if src is None:
        return None
    return load_kernel(src, [int(fun.numel_in(i)) for i in range(fun.n_in())], size_out)


def load_kernel(src: str, size_in: Sequence[int], size_out: Sequence[int]
                ) -> Callable[[Sequence[np.ndarray], int], list[np.ndarray]] | None:
    """``run(boxes, n)`` of a kernel source ``cmpc_batch`` (inputs ``(N_i, d_i, 2)``,
    outputs ``(n, d_o, 2)``), compiled or loaded from the disk cache; None on failure."""
    if not native_available():
        return None
    key = hashlib.sha256((src + "\0" + str(_compiler()) + "\0" + " ".join(_FLAGS)).encode()
                         ).hexdigest()[:24]
    with _lock:
        fn = _loaded.get(key)
    if fn is None:
        lib = _build(src, key)
        if lib is None:
            return None
        fn = ctypes.CDLL(str(lib)).cmpc_batch
        fn.restype = None
        fn.argtypes = [ctypes.c_long, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        with _lock:
            _loaded[key] = fn
    n_in = len(size_in)
    sizes = list(size_out)
    widths = [2 * int(d) for d in size_in]
    ptr_in = ctypes.c_void_p * max(n_in, 1)
    ptr_out = ctypes.c_void_p * max(len(sizes), 1)
    strides: dict[tuple[bool, ...], Any] = {}  # broadcast pattern -> strides (C longs)
    f64 = np.dtype(np.float64)

    def run(boxes: Sequence[np.ndarray], n: int) -> list[np.ndarray]:
        ins = [b if b.dtype == f64 and b.flags.c_contiguous else
               np.ascontiguousarray(b, dtype=np.float64) for b in boxes]
        pattern = tuple(b.shape[0] == 1 for b in ins)
        st = strides.get(pattern)
        if st is None:
            st = strides[pattern] = (ctypes.c_long * max(n_in, 1))(
                *[0 if one else w for one, w in zip(pattern, widths, strict=True)])
        outs = [np.zeros((n, d, 2)) for d in sizes]
        pin = ptr_in(*[b.__array_interface__["data"][0] for b in ins])
        pout = ptr_out(*[o.__array_interface__["data"][0] for o in outs])
        fn(n, pin, st, pout)
        return outs

    return run
