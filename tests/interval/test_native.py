"""The native backend (a fused C loop over the boxes): sound against a 300-bit reference,
independent of the FPU rounding mode, cached on disk, and replaced by numpy with one
warning where no C compiler is found."""

from __future__ import annotations

import ctypes
import ctypes.util
import warnings

import casadi as ca
import mpmath
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mp_reference import Undefined, eval_function, inside

import casadi_cmpc as cm
from casadi_cmpc.interval import InclusionFunction
from casadi_cmpc.interval import _native as nat

pytestmark = pytest.mark.skipif(not nat.native_available(), reason="needs a C compiler")

_UNARY = [ca.sin, ca.cos, ca.exp, ca.tanh, ca.atan, lambda v: ca.log(1 + v * v), ca.fabs,
          lambda v: ca.sqrt(1 + v * v), ca.sinh, lambda v: v ** 3, ca.floor]


def _model_like(n: int, ops: list[int], seed: int) -> ca.Function:
    """A random n-state map with unary operations, products, constants and a division."""
    rng = np.random.default_rng(seed)
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u")
    out = []
    for i in range(n):
        g = _UNARY[ops[i % len(ops)]]
        c = float(rng.normal())
        out.append(x[i] + 0.1 * g(c * x[(i + 1) % n] + u) - x[i] * x[(i + 2) % n] / 3
                   + 0.1 * u / (2 + x[i] ** 2))
    return ca.Function("f", [x, u], [ca.vertcat(*out)])


def _boxes(rng: np.random.Generator, N: int, d: int, scale: float) -> np.ndarray:
    c = rng.uniform(-2, 2, (N, d))
    r = rng.uniform(0, scale, (N, d))
    return np.stack([c - r, c + r], -1)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 4), ops=st.lists(st.integers(0, len(_UNARY) - 1), min_size=1,
                                          max_size=4), seed=st.integers(0, 10**6))
def test_native_encloses_the_exact_value_and_agrees_with_numpy(n, ops, seed):
    f = _model_like(n, ops, seed)
    rng = np.random.default_rng(seed)
    X, U = _boxes(rng, 40, n, 0.3), _boxes(rng, 40, 1, 0.3)
    Fn = InclusionFunction(f, backend="native")
    assert Fn._native_kernel() is not None
    a = Fn(X, U)[0]
    b = InclusionFunction(f, backend="numpy")(X, U)[0]
    assert np.all(a[..., 0] <= a[..., 1])
    for k in range(0, 40, 4):  # the exact value at points of the boxes (300 bits)
        for t in (0.0, 0.37, 1.0):
            px = X[k, :, 0] + t * (X[k, :, 1] - X[k, :, 0])
            pu = U[k, :, 0] + (1 - t) * (U[k, :, 1] - U[k, :, 0])
            try:
                ref = eval_function(f, [list(px), list(pu)])[0]
            except Undefined:
                continue
            for j in range(n):
                assert inside(a[k, j, 0], a[k, j, 1], ref[j]), (k, j)
    # the same rules as numpy: a few ulps of the operands apart, or both uninformative
    fin = np.isfinite(a) & np.isfinite(b)
    assert np.allclose(a[fin], b[fin], rtol=1e-10, atol=1e-12)
    assert np.array_equal(np.isfinite(a), np.isfinite(b))


def _fesetround(libm: ctypes.CDLL, mode: int) -> int:
    return libm.fesetround(ctypes.c_int(mode))


def test_native_is_sound_in_every_rounding_mode():
    """codac switches the FPU to upward rounding in the same process: the kernel's bounds
    move outward by an ulp in every mode, so they still hold the exact values."""
    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    modes = {"upward": 0x800, "downward": 0x400, "toward zero": 0xC00}  # x86-64 values
    if ctypes.util.find_library("m") is None or libm.fegetround() != 0:
        pytest.skip("fesetround not available as expected")
    f = _model_like(3, [0, 2, 6], 7)
    rng = np.random.default_rng(3)
    X, U = _boxes(rng, 30, 3, 1e-9), _boxes(rng, 30, 1, 1e-9)  # thin: rounding matters
    Fn = InclusionFunction(f, backend="native")
    Fn._native_kernel()
    for name, mode in modes.items():
        assert _fesetround(libm, mode) == 0
        try:
            a = Fn(X, U)[0]
        finally:
            _fesetround(libm, 0)
        for k in range(30):
            ref = eval_function(f, [list(X[k, :, 0]), list(U[k, :, 0])])[0]
            for j in range(3):
                assert inside(a[k, j, 0], a[k, j, 1], ref[j]), (name, k, j)


def test_kernels_are_cached_on_disk_by_their_source(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setattr(nat, "_loaded", {})
    x = ca.SX.sym("x", 2)
    f = ca.Function("g", [x], [ca.vertcat(ca.exp(x[0]) * x[1], x[0] - 0.3 * x[1])])
    assert InclusionFunction(f, backend="native")._native_kernel() is not None
    files = sorted((tmp_path / "casadi_cmpc" / "kernels").glob("k*.so"))
    assert len(files) == 1
    stamp = files[0].stat().st_mtime_ns
    monkeypatch.setattr(nat, "_loaded", {})  # a new process: loaded from the disk cache
    G = InclusionFunction(ca.Function("g2", [x], [f(x)]), backend="native")
    assert G._native_kernel() is not None
    assert sorted((tmp_path / "casadi_cmpc" / "kernels").glob("k*.so")) == files
    assert files[0].stat().st_mtime_ns == stamp
    X = np.array([[[0.1, 0.2], [1.0, 1.5]]])
    np.testing.assert_array_equal(G(X)[0], InclusionFunction(f, backend="native")(X)[0])


def test_without_a_compiler_numpy_evaluates_after_one_warning(monkeypatch):
    monkeypatch.setattr(nat, "_state", {"cc": None, "checked": True, "warned": False})
    x = ca.SX.sym("x", 2)
    f = ca.Function("h", [x], [ca.sin(x[0]) * x[1]])
    X = np.array([[[0.1, 0.2], [1.0, 1.5]]] * 50)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        a = InclusionFunction(f, backend="native")(X)[0]
        InclusionFunction(f, backend="native")(X)
    assert sum(issubclass(w.category, cm.CmpcWarning) for w in rec) == 1
    assert "no C compiler" in str(rec[0].message)
    np.testing.assert_array_equal(a, InclusionFunction(f, backend="numpy")(X)[0])


def test_auto_moves_to_native_after_repeated_batches():
    x = ca.SX.sym("x", 2)
    f = ca.Function("k", [x], [ca.vertcat(x[0] * x[1], ca.cos(x[0]))])
    F = InclusionFunction(f)  # auto
    X = np.tile(np.array([[[0.1, 0.2], [1.0, 1.5]]]), (100, 1, 1))
    ref = InclusionFunction(f, backend="numpy")(X)[0]
    for _ in range(F.native_after):
        # numpy so far (the kernel may already be built in the background or on disk)
        assert not F._native_ready()
        np.testing.assert_array_equal(F(X)[0], ref)
    out = F(X)[0]
    assert F._native_ready() and callable(F._native)
    assert np.all(out[..., 0] <= ref[..., 0] + 1e-15) and np.all(out[..., 1] >= ref[..., 1] - 1e-15)


def test_overflow_and_undefined_widen_never_narrow():
    x = ca.SX.sym("x", 2)
    f = ca.Function("o", [x], [ca.vertcat(ca.exp(x[0]), ca.log(x[1]), x[0] / x[1],
                                          ca.sqrt(x[1]))])
    X = np.array([[[709.0, 710.0], [-1.0, 1.0]], [[1.0, 2.0], [0.5, 1.0]]])
    a = InclusionFunction(f, backend="native")(X)[0]
    assert a[0, 0, 1] == np.inf and a[0, 0, 0] <= np.exp(709.0)
    assert (a[0, 1] == (-np.inf, np.inf)).all()  # log of a box reaching below 0
    assert (a[0, 2] == (-np.inf, np.inf)).all()  # division by a box holding 0
    assert (a[0, 3] == (-np.inf, np.inf)).all()
    assert a[1, 1, 0] <= np.log(0.5) <= a[1, 1, 1] and a[1, 1, 1] >= 0.0


@settings(max_examples=20, deadline=None)
@given(n=st.integers(1, 4), ops=st.lists(st.sampled_from([0, 1, 2, 3, 4, 7, 8, 9]),
                                          min_size=1, max_size=3),
       seed=st.integers(0, 10**6))
def test_native_centered_form_encloses_the_exact_value_and_matches_numpy(n, ops, seed):
    """The fused mean-value kernel (midpoints, radii, G, combination in one C loop) and the
    numpy form: both enclose the exact values, and they are the same to a few ulps."""
    f = _model_like(n, ops, seed)
    rng = np.random.default_rng(seed)
    X, U = _boxes(rng, 30, n, 0.05), _boxes(rng, 30, 1, 0.05)
    Fn = InclusionFunction(f, "centered", backend="native")
    a = Fn(X, U)[0]
    assert Fn._native and Fn._native[0] in ("fused", "fused_guarded", "g")
    b = InclusionFunction(f, "centered", backend="numpy")(X, U)[0]
    for k in range(0, 30, 3):
        for t in (0.0, 0.61, 1.0):
            px = X[k, :, 0] + t * (X[k, :, 1] - X[k, :, 0])
            pu = U[k, :, 1] - t * (U[k, :, 1] - U[k, :, 0])
            ref = eval_function(f, [list(px), list(pu)])[0]
            for j in range(n):
                assert inside(a[k, j, 0], a[k, j, 1], ref[j]), (k, j)
    fin = np.isfinite(a) & np.isfinite(b)
    assert np.array_equal(np.isfinite(a), np.isfinite(b))
    assert np.allclose(a[fin], b[fin], rtol=1e-10, atol=1e-12)


def test_fused_centered_kernel_is_bit_identical_on_a_polynomial_model():
    """Without libm calls both forms round the same operations the same way."""
    ex = cm.models.load("cannon_robust")
    m = ex.model
    rng = np.random.default_rng(5)
    c = rng.uniform(m.X.lo, m.X.hi, (500, 2))
    X = np.stack([c - 0.03, c + 0.03], -1)
    U = np.tile(np.array([[[-0.2, 0.3]]]), (500, 1, 1))
    W = np.tile(m.W.as_array()[None], (500, 1, 1))
    Fn = InclusionFunction(m.function, "centered", backend="native")
    a = Fn(X, U, W)[0]
    assert Fn._native[0] == "fused"
    np.testing.assert_array_equal(a, InclusionFunction(m.function, "centered",
                                                       backend="numpy")(X, U, W)[0])


def test_fused_centered_kernel_with_a_jump_guard_uses_the_natural_enclosure_there():
    """x / y and log(y) leave their domain on boxes that reach y = 0: there the guard makes
    the row natural ([-inf, inf]); elsewhere the mean-value form holds the exact values."""
    x = ca.SX.sym("x", 2)
    f = ca.Function("q", [x], [ca.vertcat(x[0] / x[1] + x[0] ** 2, ca.log(x[1]) * x[0])])
    rng = np.random.default_rng(11)
    c = np.column_stack([rng.uniform(-1, 1, 200), rng.uniform(-0.3, 2, 200)])
    X = np.stack([c - 0.05, c + 0.05], -1)
    Fn = InclusionFunction(f, "centered", backend="native")
    a = Fn(X)[0]
    assert Fn._native[0] == "fused_guarded"
    b = InclusionFunction(f, "centered", backend="numpy")(X)[0]
    assert np.array_equal(np.isfinite(a), np.isfinite(b))
    holds0 = (X[:, 1, 0] <= 0) & (X[:, 1, 1] >= 0)  # x / y undefined somewhere on the box
    reach = X[:, 1, 0] <= 0  # log y undefined somewhere on the box
    assert holds0.any() and np.isinf(a[holds0, 0]).all() and np.isinf(a[reach, 1]).all()
    for k in np.flatnonzero(~reach)[:40]:
        for t in (0.0, 0.5, 1.0):
            p = X[k, :, 0] + t * (X[k, :, 1] - X[k, :, 0])
            ref = eval_function(f, [list(p)])[0]
            for j in range(2):
                assert inside(a[k, j, 0], a[k, j, 1], ref[j])


def test_a_large_function_called_box_by_box_moves_to_native():
    """A controller's check evaluates one box per call: for a large function (hundreds of
    instructions) the native kernel takes over after native_after calls; a small function
    stays on the scalar evaluator, cheaper at that size (its small batches do not count)."""
    x = ca.SX.sym("x", 2)
    e = x
    for k in range(40):  # 40 steps of a nonlinear map: a few hundred instructions
        e = ca.vertcat(e[0] + 0.05 * e[1], e[1] + 0.05 * (ca.sin(e[0]) - 0.1 * e[1] + 0.01 * k))
    big = InclusionFunction(ca.Function("big", [x], [e]))
    small = InclusionFunction(ca.Function("small", [x], [ca.sin(x[0]) * x[1]]))
    assert big._large and not small._large
    box = np.array([[[0.1, 0.1 + 1e-9], [0.2, 0.2 + 1e-9]]])
    for _ in range(big.native_after + 1):
        a = big.evaluate_unchecked([box], 1)[0]
        small.evaluate_unchecked([box], 1)
    assert callable(big._native) and small._native is None
    ref = InclusionFunction(ca.Function("big", [x], [e]), backend="numpy")(box)[0]
    assert np.all(a[..., 0] <= ref[..., 1]) and np.all(ref[..., 0] <= a[..., 1])
    pt = eval_function(ca.Function("big", [x], [e]), [list(box[0, :, 0])])[0]
    for j in range(2):
        assert inside(a[0, j, 0], a[0, j, 1], pt[j])


def test_the_switch_to_native_is_at_a_fixed_batch_whatever_the_compilation_time(
        tmp_path, monkeypatch):
    """With the automatic backend the kernel starts compiling in the background after
    native_prefetch batches and the switch after native_after batches waits for it: the
    backend of every batch, so every result, is the same from run to run."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))  # an empty kernel cache
    x = ca.SX.sym("x", 2)
    f = ca.Function("bg", [x], [ca.vertcat(x[0] * x[1] + 0.25, ca.exp(x[0]) - x[1])])
    F = InclusionFunction(f)
    X = np.tile(np.array([[[0.1, 0.2], [1.0, 1.5]]]), (100, 1, 1))
    for _ in range(F.native_prefetch):
        F(X)
    assert F._native is None and nat._building  # compiling in the background
    for _ in range(F.native_prefetch, F.native_after):
        first = F(X)[0]
    assert F._native is None  # numpy up to the threshold
    out = F(X)[0]  # waits for the kernel
    assert callable(F._native) and any(tmp_path.rglob("k*.so"))
    lo, hi = np.maximum(out[..., 0], first[..., 0]), np.minimum(out[..., 1], first[..., 1])
    assert np.all(lo <= hi)  # both enclose the same values


def test_cmpc_native_0_turns_the_backend_off_without_a_warning(monkeypatch):
    monkeypatch.setenv("CMPC_NATIVE", "0")
    x = ca.SX.sym("x", 2)
    f = ca.Function("off", [x], [ca.exp(x[0]) * x[1]])
    X = np.tile(np.array([[[0.1, 0.2], [1.0, 1.5]]]), (64, 1, 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        F = InclusionFunction(f, backend="native")
        a = F(X)[0]
    assert F._native is False
    np.testing.assert_array_equal(a, InclusionFunction(f, backend="numpy")(X)[0])


_CSR_SRC = r"""
#include <xmmintrin.h>
unsigned int get_csr(void) { return _mm_getcsr(); }
void set_csr(unsigned int v) { _mm_setcsr(v); }
"""


def test_flush_to_zero_of_the_caller_neither_narrows_nor_leaks(tmp_path):
    """A library compiled with fast-math sets flush-to-zero and denormals-are-zero for the
    whole process: a subnormal product then becomes 0 and an upper bound 0 + 1 ulp would
    miss it. The kernel runs in the default environment and gives the caller's back."""
    import platform
    import shutil
    import subprocess

    if platform.machine() not in ("x86_64", "AMD64") or shutil.which("gcc") is None:
        pytest.skip("needs x86-64 and gcc")
    (tmp_path / "csr.c").write_text(_CSR_SRC)
    subprocess.run(["gcc", "-O2", "-shared", "-fPIC", "-o", str(tmp_path / "csr.so"),
                    str(tmp_path / "csr.c")], check=True, capture_output=True)
    lib = ctypes.CDLL(str(tmp_path / "csr.so"))
    lib.get_csr.restype = ctypes.c_uint
    lib.set_csr.argtypes = [ctypes.c_uint]
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    F = InclusionFunction(ca.Function("p", [x, y], [ca.vertcat(x * y, x * y + x)]),
                          backend="native")
    X = np.array([[[1e-300, 1e-300]], [[3e-160, 3e-160]], [[-1e-300, -1e-300]]])
    Y = np.array([[[1e-10, 1e-10]], [[3e-160, 3e-160]], [[1e-10, 1e-10]]])
    import mpmath

    exact = [mpmath.mpf(float(a)) * mpmath.mpf(float(b))
             for a, b in zip(X[:, 0, 0], Y[:, 0, 0], strict=True)]  # subnormal products
    saved = lib.get_csr()
    ftz = (saved | 0x8040)  # flush-to-zero, denormals-are-zero
    lib.set_csr(ftz)
    try:
        out = F(X, Y)[0]
        after = lib.get_csr()
    finally:
        lib.set_csr(saved)
    assert after & 0xFFC0 == ftz & 0xFFC0  # the caller's mode and masks come back
    for k, e in enumerate(exact):
        lo, hi = out[k, 0]
        assert mpmath.mpf(float(lo)) <= e <= mpmath.mpf(float(hi)), (k, lo, hi)


_POLY_OPS = [lambda a, b: a + b, lambda a, b: a - b, lambda a, b: a * b,
             lambda a, b: a * a, lambda a, b: 2 * a, lambda a, b: -a + 0.1 * b,
             lambda a, b: a / (b * b + 2.0), lambda a, b: 3.0 / (a * a + 1.5),
             lambda a, b: ca.sqrt(a * a + 1e-3), lambda a, b: ca.fabs(a) - ca.fmin(a, b),
             lambda a, b: a ** 3]


@settings(max_examples=40, deadline=None)
@given(ops=st.lists(st.integers(0, len(_POLY_OPS) - 1), min_size=1, max_size=8),
       seed=st.integers(0, 10**6), tiny=st.booleans())
def test_native_equals_numpy_bit_for_bit_without_libm(ops, seed, tiny):
    """Without libm functions the native kernel and numpy apply the same rules to the same
    operations: their enclosures are equal bit for bit (so a search gives the same boxes
    whichever backend evaluated which batch, on workers or in the driver), also for
    thin boxes, boxes around 0 and tiny (subnormal) values."""
    x = ca.SX.sym("x", 3)
    e = [x[0], x[1], x[2]]
    for k, o in enumerate(ops):
        e[k % 3] = _POLY_OPS[o](e[k % 3], e[(k + 1) % 3])
    f = ca.Function("p", [x], [ca.vertcat(*e)])
    rng = np.random.default_rng(seed)
    scale = 1e-310 if tiny else 2.0
    c = rng.uniform(-scale, scale, (64, 3))
    r = rng.uniform(0, scale / 4, (64, 3)) * (rng.random((64, 1)) < 0.7)
    X = np.stack([c - r, c + r], -1)
    X[:4] = np.array([[[0.0, 0.0]] * 3, [[-1.0, 1.0]] * 3, [[-0.0, 0.5]] * 3,
                      [[2.5, 2.5]] * 3])
    a = InclusionFunction(f, backend="native")(X)[0]
    b = InclusionFunction(f, backend="numpy")(X)[0]
    assert np.array_equal(a, b, equal_nan=True), np.argwhere(a != b)[:3]


def test_small_batches_follow_a_function_that_moved_to_native():
    """A function of a few dozen instructions moves to its native kernel through large
    batches (a search's levels); afterwards its small batches worth the kernel's call go
    there too (the same enclosure as the kernel's), tiny ones stay scalar, and small
    batches alone never move it."""
    from casadi_cmpc.interval._native import native_available

    if not native_available():
        pytest.skip("no C compiler")
    x = ca.SX.sym("x", 2)
    e = ca.vertcat(x[0] * x[1] + ca.sin(x[0]), x[1] ** 2 - 0.3 * x[0] * x[1] + 1)
    fun = ca.Function("mid", [x], [e])
    rng = np.random.default_rng(5)
    c = rng.random((400, 2))
    big = np.stack([c, c + 0.01], -1)
    few = big[:8]
    only_small = InclusionFunction(fun)
    for _ in range(3 * only_small.native_after):
        only_small.evaluate_unchecked([few], 8)
    assert only_small._native is None  # never compiled for small batches alone
    F = InclusionFunction(fun)
    assert 8 * F._n_instr >= F.native_small_work > F._n_instr
    for _ in range(F.native_after + 1):
        F.evaluate_unchecked([big], 400)
    assert callable(F._native)
    calls = []
    run = F._native

    def counted(boxes, n):
        calls.append(n)
        return run(boxes, n)

    F._native = counted
    got = F.evaluate_unchecked([few], 8)[0]
    assert calls == [8]
    assert np.array_equal(got, run([few], 8)[0])
    F.evaluate_unchecked([few[:1]], 1)  # one box: below the work worth the call
    assert calls == [8]


def test_address_is_the_data_pointer_of_every_kind_of_array():
    """The cheap address of an array's data is its data pointer, also for read-only,
    empty and broadcast arrays (which take the slower path)."""
    from casadi_cmpc.interval._native import address

    a = np.arange(12.0).reshape(3, 4)
    ro = a.copy()
    ro.flags.writeable = False
    for x in (a, a[1:], ro, np.empty(0), np.broadcast_to(np.ones(3), (3,)), np.zeros(5, bool)):
        assert address(x) == x.ctypes.data


@settings(max_examples=12, deadline=None)  # each example compiles its own kernel
@given(seed=st.integers(0, 10 ** 6), kind=st.sampled_from(["natural", "centered"]))
def test_weights_0_and_1_are_exact_and_keep_undefined_parts(seed, kind):
    """Rows ``H f`` with exact weights (0, 1, -1 and others, as the targets' row functions):
    the native kernel folds x 1 = x, x + 0 = x and x 0 = 0 exactly. Its enclosures hold the
    exact values (60 digits), a row of weights 0 and 1 on exactly representable parts is
    exact (no widening), and a part that is possibly undefined (log of a box reaching 0)
    keeps its row possibly undefined even with weight 0, as numpy says."""
    from casadi_cmpc.interval._derivative import ParamFunction

    if not nat.native_available():
        pytest.skip("no C compiler")
    rng = np.random.default_rng(seed)
    x = ca.SX.sym("x", 2)
    parts = ca.vertcat(ca.log(x[0]), ca.sin(x[1]) * x[0], x[0], x[1])
    H = ca.SX.sym("H", 3, 4)
    g = ca.Function("rows", [x, H], [ca.mtimes(H, parts)])
    w = rng.choice([0.0, 1.0, -1.0, 0.5, 2.0, 0.0, 1.0], (3, 4))
    w[2] = [0.0, 0.0, 1.0, 0.0]  # the last row is x0: exact
    pf = ParamFunction(g, 1, w.ravel(order="F"))
    lo = rng.uniform(-1.0, 2.0, (40, 2))
    B = np.stack([lo, lo + rng.uniform(0.0, 0.5, (40, 2))], axis=-1)
    a = InclusionFunction(pf, kind, backend="native")(B)[0]
    b = InclusionFunction(pf, kind, backend="numpy")(B)[0]
    whole = (a[..., 0] == -np.inf) & (a[..., 1] == np.inf)
    assert (whole == ((b[..., 0] == -np.inf) & (b[..., 1] == np.inf))).all()
    undefined = (B[:, 0, 0] <= 0.0)[:, None] & (w[:, 0] != 0.0)[None, :]
    assert whole[undefined].all()
    if kind == "natural":  # (0 log x0 is possibly undefined where x0 may be <= 0)
        pos = B[:, 0, 0] > 0.0
        assert (a[pos, 2, 0] == B[pos, 0, 0]).all() and (a[pos, 2, 1] == B[pos, 0, 1]).all()
    f = ca.Function("exact", [x], [ca.mtimes(ca.DM(w), parts)])
    for k in range(0, 40, 4):
        for t in (0.0, 0.37, 1.0):
            p = B[k, :, 0] + t * (B[k, :, 1] - B[k, :, 0])
            p = np.clip(p, B[k, :, 0], B[k, :, 1])
            ref = eval_function(f, [list(p)])[0]
            for j in range(3):
                if isinstance(ref[j], mpmath.mpf):  # (else undefined at p)
                    assert inside(a[k, j, 0], a[k, j, 1], ref[j]), (kind, k, j)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10**6), kind=st.sampled_from(["natural", "centered"]),
       gather=st.booleans(), one_u=st.booleans())
def test_kernels_read_rows_and_strided_views_in_place(seed, kind, gather, one_u):
    """The native kernels read boxes given as rows of bound arrays (a column range, optional
    row indices, a broadcast row) and as non-contiguous (N, d, 2) views: the enclosures are
    those of the same boxes as contiguous arrays, bit for bit; the numpy evaluator gets
    them gathered (the same enclosures as its own arrays)."""
    from casadi_cmpc.interval._native import Rows

    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u", 2)
    f = ca.Function("f", [x, u], [ca.vertcat(x[0] * u[1] + ca.sin(x[2]), x[1] ** 2 - u[0],
                                             x[0] / (2.0 + x[1] ** 2) + u[0] * u[1])])
    rng = np.random.default_rng(seed)
    R = 300
    lo = rng.uniform(-2, 2, (R, 6))  # columns: x (3), u (2), one more
    hi = lo + rng.uniform(0, 0.3, (R, 6)) * (rng.random((R, 6)) < 0.8)
    idx = rng.integers(0, R, 257) if gather else None
    rows_x = Rows(lo, hi, 0, 3, idx)
    rows_u = Rows(lo[:1], hi[:1], 3, 5) if one_u else Rows(lo, hi, 3, 5, idx)
    X, Uu = rows_x.boxes(), rows_u.boxes()
    n = X.shape[0]
    F = InclusionFunction(f, kind, backend="native")
    ref = F.evaluate_unchecked([np.ascontiguousarray(X), np.ascontiguousarray(Uu)], n)[0]
    got = F.evaluate_unchecked([rows_x, rows_u], n)[0]
    assert np.array_equal(got, ref, equal_nan=True)
    # a non-contiguous view: every other box of a larger array
    big = np.zeros((2 * n, 3, 2))
    big[::2] = X
    view = big[::2]
    assert not view.flags.c_contiguous
    assert np.array_equal(F.evaluate_unchecked([view, Uu], n)[0], ref, equal_nan=True)
    # numpy gathers them
    Fn = InclusionFunction(f, kind, backend="numpy")
    assert np.array_equal(Fn.evaluate_unchecked([rows_x, rows_u], n)[0],
                          Fn.evaluate_unchecked([X, Uu], n)[0], equal_nan=True)


def test_rows_are_checked():
    from casadi_cmpc.interval._native import Rows

    a = np.zeros((4, 3))
    with pytest.raises(ValueError, match="2-D"):
        Rows(a, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="column range"):
        Rows(a, a, 2, 5)
    r = Rows(a, a, 1, 3, np.array([3, 0]))
    assert r.shape == (2, 2, 2) and r.boxes().shape == (2, 2, 2)
    for bad in ([-1], [4], [0, 10**6]):  # rows the kernels would read out of bounds
        with pytest.raises(IndexError, match="row indices"):
            Rows(a, a, 0, 3, np.array(bad))


def test_small_batches_of_a_medium_function_move_it_to_native_by_their_work():
    """A function below native_large instructions called only with small batches (a
    nested search's small levels, a controller's checks) moves to its native kernel once
    those batches add up to native_after quanta of work (boxes x instructions): about what
    a compilation costs; the answers stay sound and the move comes at a fixed call."""
    from casadi_cmpc.interval._native import native_available

    if not native_available():
        pytest.skip("no C compiler")
    x = ca.SX.sym("x", 3)
    e = x
    for _ in range(2):
        e = ca.vertcat(e[0] + 0.1 * e[1] * e[2], e[1] - 0.1 * ca.sin(e[0]), 0.9 * e[2] + e[0] ** 2)
    fun = ca.Function("medium", [x], [e])
    F = InclusionFunction(fun, "centered")
    assert not F._large and F._n_instr * 16 >= F.native_small_work
    rng = np.random.default_rng(2)
    c = rng.random((16, 3))
    boxes = np.stack([c, c + 1e-3], -1)
    per_call = 16 * F._n_instr
    calls = -(-F.native_small_quantum * (F.native_after + 1) // per_call)
    for k in range(calls + 1):
        got = F.evaluate_unchecked([boxes], 16)[0]
        if k == 0:
            first = got
        if k == calls // 2:
            assert not F._native_ready()  # not before the work adds up
    assert F._native_ready() and F._native not in (None, False)  # moved, small batches alone
    assert np.all(got[..., 0] <= first[..., 1]) and np.all(first[..., 0] <= got[..., 1])
    ref = InclusionFunction(fun, "centered", backend="numpy")(boxes)[0]
    assert np.all(got[..., 0] <= ref[..., 1]) and np.all(ref[..., 0] <= got[..., 1])
