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
import platform
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

_FLAGS = ("-O3", "-fno-fast-math", "-fno-trapping-math", "-ffp-contract=off", "-fopenmp-simd",
          "-fPIC", "-shared")
_ARCH = "-march=native"  # the SIMD width of this machine; dropped where the compiler refuses
_lock = threading.Lock()
_state: dict[str, Any] = {"cc": None, "checked": False, "warned": False}
_loaded: dict[tuple[str, str], Any] = {}  # (source hash, symbol) -> loaded C function


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


def _cpu_id() -> str:
    """The processor's model and feature flags (a kernel built for one machine's SIMD width is
    not loaded on another that shares the cache directory)."""
    with _lock:
        if "cpu" not in _state:
            ident = [platform.machine(), platform.processor()]
            try:
                with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
                    seen: set[str] = set()
                    for line in fh:
                        key = line.split(":", 1)[0].strip()
                        if key in ("model name", "flags", "Features", "CPU part") \
                                and key not in seen:
                            seen.add(key)
                            ident.append(line.strip())
            except OSError:
                pass
            _state["cpu"] = "\n".join(ident)
        return _state["cpu"]


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
            self.zeros: set[int] = set()  # slots holding 0 (or NaN): a product by 0

        def _lit(self, v: float) -> str:
            return c_double(v)

        def _civ(self, slot: int) -> str:
            if slot in self.consts:
                lo, hi = self.consts[slot]
                return f"CIV({c_double(lo)}, {c_double(hi)})"
            return f"v{slot}"

        def _assign(self, out: int, expr: str) -> None:
            self.consts.pop(out, None)
            self.slots.add(out)
            self.lines.append(f"        v{out} = {expr};")

        def _input(self, k: int, out: int, i: int, j: int) -> None:
            self.used_inputs.add(i)
            self._set(out, f"CIV(B{i}[{2 * j}][l], B{i}[{2 * j + 1}][l])")

        def _output(self, k: int, slot: int, oi: int, j: int) -> None:
            self.lines.append(f"        CIV_PUT(Q{oi}, {2 * self.out_pos[oi][j]}, "
                              f"{self._civ(slot)});")

        def _unary(self, k: int, op: int, name: str, out: int, i0: int) -> None:
            if op not in _C_UNARY:
                raise _NoRule(name)
            fn = _C_UNARY[op]
            a = self._civ(i0)
            self._set(out, a if fn is None else f"{fn}({a})")

        def _set(self, out: int, expr: str) -> None:
            self.zeros.discard(out)
            self._assign(out, expr)

        def _binary(self, k: int, op: int, name: str, out: int, i0: int, i1: int) -> None:
            if op not in _C_BINARY:
                raise _NoRule(name)
            c0, c1 = self._thin(i0), self._thin(i1)
            # exact operations with 0 and 1 (a product by constant weights, e.g. the rows
            # H f of a target): x 1 = x and x + 0 = x exactly; x 0 is 0, or "possibly
            # undefined" (NaN) where x is, which a sum passes on
            if op == ca.OP_MUL and (c0 is None) != (c1 is None):
                var, c = (i1, c0) if c0 is not None else (i0, c1)
                if c == 1.0:
                    self._set(out, self._civ(var))
                    if var in self.zeros:
                        self.zeros.add(out)
                    return
                if c == 0.0:
                    self._set(out, f"civ_zero_of({self._civ(var)})")
                    self.zeros.add(out)
                    return
                if np.isfinite(c):
                    self._set(out, f"civ_mulc({self._civ(var)}, {c_double(c)})")
                    return
            if op == ca.OP_ADD and (c0 == 0.0 or c1 == 0.0) and (c0 is None) != (c1 is None):
                var = i1 if c0 is not None else i0
                self._set(out, self._civ(var))
                if var in self.zeros:
                    self.zeros.add(out)
                return
            if op in (ca.OP_ADD, ca.OP_SUB) and (i0 in self.zeros or i1 in self.zeros):
                both = i0 in self.zeros and i1 in self.zeros
                if i1 in self.zeros:
                    self._set(out, f"civ_nan_of({self._civ(i0)}, {self._civ(i1)})")
                elif op == ca.OP_ADD:
                    self._set(out, f"civ_nan_of({self._civ(i1)}, {self._civ(i0)})")
                else:
                    self._set(out, f"civ_nan_of(civ_neg({self._civ(i1)}), {self._civ(i0)})")
                if both:
                    self.zeros.add(out)
                return
            if op == ca.OP_DIV and c1 is not None and c1 != 0.0 and np.isfinite(c1) \
                    and c0 is None:
                self._set(out, f"civ_divc({self._civ(i0)}, {c_double(c1)})")
                return
            if op == ca.OP_DIV and c0 is not None and not np.isnan(c0) and c1 is None:
                self._set(out, f"civ_cdiv({c_double(c0)}, {self._civ(i1)})")
                return
            self._set(out, f"{_C_BINARY[op]}({self._civ(i0)}, {self._civ(i1)})")

        def _finish(self) -> str:
            slots = sorted(self.slots)
            decl = [f"        civ {', '.join(f'v{s}' for s in slots[i:i + 12])};"
                    for i in range(0, len(slots), 12)]
            n_in = self.fun.n_in()
            size_in = [int(self.fun.numel_in(i)) if i in self.used_inputs else 0
                       for i in range(n_in)]
            return _block_loop(size_in, self.size_out, decl + self.lines)

    return _CCodegen


class _NoRule(Exception):
    """An operation without a C interval rule."""


_HEADER = r"""#include <math.h>
#include <float.h>
""" + PRELUDE + r"""
#define CIV(a, b) ((civ){(a), (b)})

/* an output bound pair, [-inf, inf] where it is possibly undefined (as the numpy backend) */
CIV_INLINE civ civ_out(civ a) {
    int ok = a.lo <= a.hi;
    a.lo = ok ? a.lo : -INFINITY;
    a.hi = ok ? a.hi : INFINITY;
    return a;
}
#define CIV_PUT(Q, k, v) do { civ t_ = civ_out(v); Q[k][l] = t_.lo; Q[(k) + 1][l] = t_.hi; } \
    while (0)

/* The kernel sets the default floating-point environment (CIV_ENV_ENTER of the prelude)
 * and gives the caller's back on return. */
#define CMPC_L 16 /* boxes per block: whole SIMD registers of 2, 4 or 8 doubles */
"""


def _block_loop(size_in: Sequence[int], size_out: Sequence[int], body: Sequence[str],
                n_extra_out: int = 0) -> str:
    """The batch loop around a per-box ``body``: blocks of ``CMPC_L`` boxes (the last one
    shorter), each input copied into lane-major arrays ``B<i>[2 d_i][CMPC_L]``, the body run
    for every lane ``l`` of the block in one loop a compiler can vectorise (it writes
    ``Q<o>[2 d_o][CMPC_L]``), the outputs copied back for the boxes of the block.
    ``size_in[i] == 0``: input ``i`` is not read. ``n_extra_out`` outputs follow, of the
    sizes of ``size_out`` again."""
    sizes = list(size_out) * (1 + n_extra_out)
    L = ["/* input i: lower bounds in[2 i], upper bounds in[2 i + 1], row stride st[2 i] and",
         " * coordinate stride st[2 i + 1] (doubles), box b on row ix[i][b] (b where ix[i] is",
         " * NULL): interleaved (N, d, 2) arrays, separate bound arrays and gathered rows */",
         "void cmpc_batch(long n, const double *const *in, const long *st, "
         "const long *const *ix, double *const *out) {",
         "    long b0, l, k;",
         "    CIV_ENV_ENTER;",
         "    for (b0 = 0; b0 < n; b0 += CMPC_L) {",
         "        long m = n - b0 < CMPC_L ? n - b0 : CMPC_L;"]
    for i, d in enumerate(size_in):
        if d:
            L.append(f"        double B{i}[{2 * d}][CMPC_L];")
    for o, d in enumerate(sizes):
        L.append(f"        double Q{o}[{max(2 * d, 1)}][CMPC_L] = {{{{0.0}}}};")
    L.append("        for (l = 0; l < m; ++l) {")
    L.append("            long bb = b0 + l;")
    for i, d in enumerate(size_in):
        if d:
            L += [f"            const long r{i} = (ix[{i}] ? ix[{i}][bb] : bb) * st[{2 * i}];",
                  f"            const double *L{i} = in[{2 * i}] + r{i}, "
                  f"*H{i} = in[{2 * i + 1}] + r{i};",
                  f"            for (k = 0; k < {d}; ++k) {{",
                  f"                B{i}[2 * k][l] = L{i}[k * st[{2 * i + 1}]];",
                  f"                B{i}[2 * k + 1][l] = H{i}[k * st[{2 * i + 1}]];",
                  "            }"]
    L += ["        }",
          "        #pragma omp simd",
          "        for (l = 0; l < m; ++l) {",
          *body,
          "        }",
          "        for (l = 0; l < m; ++l) {"]
    for o, d in enumerate(sizes):
        if d:
            L += [f"            double *O{o} = out[{o}] + (b0 + l) * {2 * d};",
                  f"            for (k = 0; k < {2 * d}; ++k) O{o}[k] = Q{o}[k][l];"]
    L += ["        }", "    }", "    CIV_ENV_LEAVE;",
          "    (void)in; (void)st; (void)ix; (void)out; (void)k;", "}", ""]
    return "\n".join(L)



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
                self._set(out, f"CIV(B{i - n_in}[{2 * j}][l], B{i - n_in}[{2 * j + 1}][l])")

        def _output(self, kk: int, slot: int, oi: int, j: int) -> None:
            self.results.add((oi, j))
            self.lines.append(f"        R{oi}_{j} = {self._civ(slot)};")

    gen = _Centered(g, widen, [np.zeros(0, dtype=np.intp)] * g.n_out(), [0] * g.n_out())
    gen.results = set()
    try:
        gen.build()
    except _NoRule:
        return None
    lines: list[str] = []
    slots = sorted(gen.slots)
    lines += [f"        civ {', '.join(f'v{s}' for s in slots[i:i + 12])};"
              for i in range(0, len(slots), 12)]
    res = sorted(gen.results)
    lines += [f"        civ {', '.join(f'R{o}_{j}' for o, j in res[i:i + 12])};"
              for i in range(0, len(res), 12)]
    # midpoints (inside the box) and radii rounded up, one per joint coordinate
    c = 0
    rad: list[str] = []
    for i, d in enumerate(size_in):
        for j in range(d):
            lines += [f"        double M{i}_{j}, D{c};",
                      f"        {{ double lo = B{i}[{2 * j}][l], hi = B{i}[{2 * j + 1}][l], r;",
                      f"          M{i}_{j} = 0.5 * lo + 0.5 * hi;",
                      f"          M{i}_{j} = M{i}_{j} < lo ? lo : M{i}_{j};",
                      f"          M{i}_{j} = M{i}_{j} > hi ? hi : M{i}_{j};",
                      f"          r = civ_max(M{i}_{j} - lo, hi - M{i}_{j});",
                      f"          D{c} = civ_ups(r); }}"]
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
                lines.append(f"        CIV_PUT(Q{k + i}, {2 * pos}, {fb});")
            terms = rows.get(int(row))
            if not terms:
                lines.append(f"        CIV_PUT(Q{i}, {2 * pos}, {fb});")
                continue
            kk = len(terms)
            scale = c_double(1.0 + (kk + 4) * arith.U)
            tiny = c_double((kk + 1) * arith.TINY)
            lines.append("        { double S = 0.0, lo, hi;")
            for t in terms:
                lines.append(f"          S += civ_term(R{k}_{t}, {rad[int(jac_cols[t])]});")
            lines += [f"          S = S * {scale} + {tiny};",
                      f"          lo = civ_dns({fm}.lo - S); hi = civ_ups({fm}.hi + S);",
                      f"          CIV_PUT(Q{i}, {2 * pos}, civ_mv(lo, hi, {fm}, {fb})); }}"]
    return _HEADER + _CENTERED_HELPERS + _block_loop(
        [int(d) for d in size_in], size_out, lines, 1 if with_natural else 0)


_CENTERED_HELPERS = r"""
/* the array rules of the numpy mean-value combination, element by element (sums and
 * differences rounded by civ_dns / civ_ups of the prelude) */

/* mag(J) * rad: a coordinate that does not vary contributes nothing, a NaN slope is +inf */
CIV_INLINE double civ_term(civ J, double r) {
    double a = -J.lo;
    double t = civ_maxn(a, J.hi) * r; /* NaN for a NaN slope */
    return t != t ? (r == 0.0 ? 0.0 : INFINITY) : t;
}

/* [lo, hi] intersected with the natural enclosure fb; NaN anywhere: possibly undefined
 * (NaN on both sides, stored as [-inf, inf]) */
CIV_INLINE civ civ_mv(double lo, double hi, civ fm, civ fb) {
    (void)fm; /* a NaN fm made lo and hi NaN */
    return civ_make(civ_maxn(lo, fb.lo), civ_minn(hi, fb.hi));
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
            cmd = [*cc.split(), *_FLAGS, "-o", str(so), str(c), "-lm"]
            r = subprocess.run([*cmd[:1], _ARCH, *cmd[1:]], capture_output=True, text=True,
                               timeout=300)
            if r.returncode != 0:
                r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
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


class _Pending:
    """The answer of :func:`load_kernel` while the kernel compiles in the background."""

    def __bool__(self) -> bool:
        return False

    def __repr__(self) -> str:
        return "PENDING"


PENDING: Any = _Pending()
_building: dict[str, threading.Thread] = {}  # key -> background compilation
_failed: set[str] = set()  # keys whose compilation failed in the background


def _build_in_background(src: str, key: str) -> None:
    """Compile ``src`` in a daemon thread (once per key); the next :func:`load_kernel`
    finds the library in the disk cache."""
    with _lock:
        t = _building.get(key)
        if t is not None and (t.is_alive() or (kernel_dir() / f"k{key}.so").is_file()):
            return

        def work() -> None:
            if _build(src, key) is None:
                with _lock:
                    _failed.add(key)

        t = _building[key] = threading.Thread(target=work, name=f"cmpc-cc-{key[:8]}",
                                              daemon=True)
    t.start()


def native_kernel(fun: Any, widen: frozenset[int], out_pos: Sequence[np.ndarray],
                  size_out: Sequence[int], keep_outputs: Sequence[int] | None = None,
                  wait: bool = True
                  ) -> Callable[[Sequence[np.ndarray], int], list[np.ndarray]] | None:
    """``run(boxes, n) -> outputs``: the natural inclusion of ``fun`` by the fused C loop,
    on validated ``(N_i, d_i, 2)`` float64 inputs (N_i in {1, n}); None when no compiler is
    found (one warning per process) or an operation has no C rule; :data:`PENDING` (falsy)
    while it compiles in the background (``wait=False``, see :func:`load_kernel`)."""
    if not native_available():
        if not native_disabled():
            _warn_once("no C compiler found (set $CC, or install cc/gcc/clang): the "
                       "inclusion functions evaluate large batches with numpy, several "
                       "times slower")
        return None
    src = kernel_source(fun, widen, out_pos, size_out, keep_outputs)
    if src is None:
        return None
    return load_kernel(src, [int(fun.numel_in(i)) for i in range(fun.n_in())], size_out,
                       wait=wait)


def address(a: np.ndarray) -> int:
    """The address of the data of a C-contiguous array, to pass to a loaded C function
    (about four times cheaper than ``a.ctypes.data`` for a writable array)."""
    try:
        return ctypes.addressof(ctypes.c_char.from_buffer(a))
    except (TypeError, ValueError, BufferError):  # read-only, empty or not contiguous
        return a.__array_interface__["data"][0]


_functions: dict[tuple[str, str], Any] = {}  # c_function: loaded (or None for good)


def c_function(src: str, name: str, argtypes: Sequence[Any], wait: bool = False) -> Any:
    """:func:`load_symbol`, remembered per source and name: the C function, or None (no
    compiler, ``CMPC_NATIVE=0``, or, with ``wait=False``, still compiling in the
    background: the caller's numpy code answers meanwhile). For the small helper loops of
    the solvers and sets, each with a numpy twin giving the same answers."""
    fn = _functions.get((src, name), False)
    if fn is not False:
        return fn
    fn = load_symbol(src, name, argtypes, wait=wait)
    if fn or fn is None:  # loaded, or unavailable for good; PENDING: ask again next time
        _functions[(src, name)] = fn
    return fn or None


def load_symbol(src: str, name: str, argtypes: Sequence[Any], wait: bool = True) -> Any:
    """The C function ``name`` (returning void, arguments ``argtypes`` of ctypes) of the
    source ``src``, loaded from the disk cache or compiled (the flags of every kernel);
    None without a compiler, with ``CMPC_NATIVE=0`` or when it does not compile.

    ``wait=False``: a source that is not in the disk cache is compiled in a background
    thread and :data:`PENDING` (falsy) is returned until it is there."""
    if not native_available():
        return None
    key = hashlib.sha256("\0".join([src, str(_compiler()), " ".join(_FLAGS), _ARCH,
                                     _cpu_id()]).encode()).hexdigest()[:24]
    with _lock:
        fn = _loaded.get((key, name))
        failed = key in _failed
        building = _building.get(key)
    if fn is not None and list(fn.argtypes) != list(argtypes):
        # one loaded function object per symbol: a second signature would pass arguments
        # the C code does not expect (a wrong pointer width: memory corruption)
        raise TypeError(f"{name} is already loaded with the argument types {fn.argtypes}; "
                        f"asked for {list(argtypes)}")
    if fn is None:
        if failed:
            return None
        lib = kernel_dir() / f"k{key}.so"
        if not lib.is_file():
            if not wait:
                _build_in_background(src, key)
                return PENDING
            if building is not None:
                building.join()
            lib = _build(src, key)
        if lib is None:
            return None
        fn = getattr(ctypes.CDLL(str(lib)), name)
        fn.restype = None
        fn.argtypes = list(argtypes)
        with _lock:
            _loaded[(key, name)] = fn
    return fn


def load_kernel(src: str, size_in: Sequence[int], size_out: Sequence[int],
                wait: bool = True
                ) -> Callable[[Sequence[np.ndarray], int], list[np.ndarray]] | None:
    """``run(boxes, n)`` of a kernel source ``cmpc_batch`` (inputs ``(N_i, d_i, 2)``,
    outputs ``(n, d_o, 2)``), loaded from the disk cache or compiled; None on failure.

    ``wait=False``: a kernel that is not in the disk cache is compiled in a background
    thread (a large function takes seconds to tens of seconds) and :data:`PENDING` is
    returned until it is there; the caller evaluates with numpy meanwhile."""
    fn = load_symbol(src, "cmpc_batch",
                     [ctypes.c_long, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                      ctypes.c_void_p], wait=wait)
    if not fn:
        return fn
    n_in = len(size_in)
    sizes = list(size_out)
    ptr_in = ctypes.c_void_p * max(2 * n_in, 1)
    ptr_ix = ctypes.c_void_p * max(n_in, 1)
    ptr_out = ctypes.c_void_p * max(len(sizes), 1)
    strides: dict[tuple[int, ...], Any] = {}  # stride values -> C longs
    f64 = np.dtype(np.float64)

    def run(boxes: Sequence[Any], n: int) -> list[np.ndarray]:
        ptrs: list[int | None] = []
        st_vals: list[int] = []
        ixs: list[int | None] = []
        keep: list[Any] = []  # arrays whose addresses are passed, alive until the call
        for b in boxes:
            if isinstance(b, Rows):
                lo, hi, idx = b.lo, b.hi, b.idx
                one = b.shape[0] == 1
                row = 0 if not one or idx is None else int(idx[0])
                off = 8 * (b.start + row * lo.shape[1])
                ptrs += [address(lo) + off, address(hi) + off]
                st_vals += [0 if one else lo.shape[1], 1]
                ixs.append(None if one or idx is None else address(idx))
                continue
            if b.dtype != f64 or b.ndim != 3 or any(v % 8 for v in b.strides):
                b = np.ascontiguousarray(b, dtype=np.float64)
            keep.append(b)
            a = address(b)
            ptrs += [a, a + b.strides[2]]
            st_vals += [0 if b.shape[0] == 1 else b.strides[0] // 8, b.strides[1] // 8]
            ixs.append(None)
        key = tuple(st_vals)
        st = strides.get(key)
        if st is None:
            st = strides[key] = (ctypes.c_long * max(2 * n_in, 1))(*st_vals)
        outs = [np.zeros((n, d, 2)) for d in sizes]
        pout = ptr_out(*[address(o) for o in outs])
        fn(n, ptr_in(*ptrs), st, ptr_ix(*ixs), pout)
        return outs

    return run


class Rows:
    """A batch of boxes read in place from bound arrays by the native kernels (no copy into
    an ``(N, d, 2)`` array): box ``b`` is ``[lo[r, start:stop], hi[r, start:stop]]`` with
    ``r = idx[b]`` (``r = b`` without ``idx``). ``lo``, ``hi``: C-contiguous float64 arrays
    of shape (R, D) (the same array for thin boxes); ``idx``: int64 row indices. A batch of
    one row (``shape[0] == 1``) is broadcast like an ``(1, d, 2)`` array. Other evaluators
    take :meth:`boxes`."""

    __slots__ = ("lo", "hi", "start", "stop", "idx")
    in_use = False  # set by the first instance: until then no caller has to look for them

    def __init__(self, lo: np.ndarray, hi: np.ndarray, start: int = 0,
                 stop: int | None = None, idx: np.ndarray | None = None) -> None:
        Rows.in_use = True
        self.lo = np.ascontiguousarray(lo, dtype=np.float64)
        self.hi = self.lo if hi is lo else np.ascontiguousarray(hi, dtype=np.float64)
        if self.lo.ndim != 2 or self.lo.shape != self.hi.shape:
            raise ValueError("Rows: lo and hi must be 2-D arrays of one shape")
        self.start = int(start)
        self.stop = self.lo.shape[1] if stop is None else int(stop)
        if not 0 <= self.start <= self.stop <= self.lo.shape[1]:
            raise ValueError("Rows: the column range lies outside the arrays")
        self.idx = None if idx is None else np.ascontiguousarray(idx, dtype=np.int64)
        if self.idx is not None and self.idx.size and (
                self.idx.min() < 0 or self.idx.max() >= self.lo.shape[0]):
            raise IndexError(f"Rows: row indices must lie in [0, {self.lo.shape[0]})")

    @property
    def shape(self) -> tuple[int, int, int]:
        n = self.lo.shape[0] if self.idx is None else self.idx.shape[0]
        return (n, self.stop - self.start, 2)

    def boxes(self) -> np.ndarray:
        """The boxes as an ``(N, d, 2)`` array."""
        lo = self.lo[:, self.start:self.stop]
        hi = self.hi[:, self.start:self.stop]
        if self.idx is not None:
            lo, hi = lo.take(self.idx, axis=0), hi.take(self.idx, axis=0)
        return np.stack([lo, hi], axis=-1)


def as_arrays(boxes: Sequence[Any]) -> list[np.ndarray]:
    """The inputs of a kernel call as ``(N_i, d_i, 2)`` arrays (:class:`Rows` gathered)."""
    return [b.boxes() if isinstance(b, Rows) else b for b in boxes]
