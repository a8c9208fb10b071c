"""Interval results do not depend on the caller's floating-point environment.

Another library may leave a directed rounding mode (codac rounds upward) or flush-to-zero /
denormals-are-zero (a library built with -ffast-math) behind. The rules are proven for the
default environment: there an overflow is +-inf and subnormal bounds are kept. Every
backend (numpy, scalar, native, auto), the interval operations and the branch and bound
must give in any environment the bits they give in the default one, and leave the caller's
environment as it was."""

from __future__ import annotations

import ctypes
import platform
import struct
import sys

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.interval import InclusionFunction, _fpu

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="switches the environment through glibc's libm")

_LIBM = ctypes.CDLL("libm.so.6") if sys.platform.startswith("linux") else None
_X86 = platform.machine() in ("x86_64", "AMD64")
MODES = {"downward": 0x400, "upward": 0x800, "toward zero": 0xC00}


def _mxcsr_bits(bits: int, on: bool) -> None:
    """Set or clear MXCSR bits (x86-64 glibc: fenv_t holds MXCSR at byte 28)."""
    buf = ctypes.create_string_buffer(512)
    _LIBM.fegetenv(buf)
    mx = struct.unpack_from("<I", buf, 28)[0]
    struct.pack_into("<I", buf, 28, (mx | bits) if on else (mx & ~bits))
    _LIBM.fesetenv(buf)


ENVS = list(MODES) + (["flush to zero", "denormals are zero"] if _X86 else [])


def _enter(env: str) -> None:
    if env in MODES:
        _LIBM.fesetround(MODES[env])
    else:
        _mxcsr_bits(0x8000 if env == "flush to zero" else 0x0040, True)


def _leave() -> None:
    _LIBM.fesetround(0)
    if _X86:
        _mxcsr_bits(0x8040, False)
    assert _fpu.is_default()


x, y = ca.SX.sym("x"), ca.SX.sym("y")
EXPRS = [x * x * 1e-300, ca.exp(x) * 1e-300, 1 / (x * x), x * 1e-10 * y, ca.sqrt(ca.fabs(x)) * y,
         ca.sin(x) * y + x / (1 + y * y), (x + y) ** 3 * 1e-250, ca.log(ca.fabs(x) + 1e-310) * y]


@settings(max_examples=60, deadline=None)
@given(k=st.integers(0, len(EXPRS) - 1), env=st.sampled_from(ENVS),
       backend=st.sampled_from(["numpy", "scalar", "native", "auto"]),
       n=st.sampled_from([1, 3, 200]), seed=st.integers(0, 2 ** 16),
       mag=st.sampled_from([1e-310, 1e-300, 1e-8, 1.0, 1e100, 1e200, 1e307]))
def test_backends_give_the_default_environment_bits(k, env, backend, n, seed, mag):
    f = ca.Function("f", [x, y], [EXPRS[k]])
    F = InclusionFunction(f, backend=backend)
    rng = np.random.default_rng(seed)
    c = rng.uniform(-2, 2, (n, 2)) * mag
    r = np.abs(rng.uniform(0, 0.1, (n, 2))) * mag * (rng.random((n, 2)) < 0.5)
    X, Y = np.stack([c[:, :1] - r[:, :1], c[:, :1] + r[:, :1]], -1), \
        np.stack([c[:, 1:] - r[:, 1:], c[:, 1:] + r[:, 1:]], -1)
    ref = F(X, Y)[0]
    _enter(env)
    try:
        got = F(X, Y)[0]
        still = not _fpu.is_default()  # the caller's environment is given back
    finally:
        _leave()
    assert still
    assert np.array_equal(got, ref, equal_nan=True), (env, backend)


@pytest.mark.parametrize("env", ENVS)
def test_interval_ops_and_a_search_in_another_environment(env):
    """The overflow of a directed mode (the largest float instead of inf) would make sivia
    prove a box inner where f >= 1e100 > 1e9; in the default environment nothing is inner."""
    h = ca.Function("h", [x], [x * x * 1e-300])
    a = np.array([1e200, 2e200])
    ref_ops = (cm.interval.mul(a, a), cm.interval.exp(np.array([700.0, 800.0])))
    ref = cm.sivia(h, cm.Box([1e200], [2e200]), cm.Box([-np.inf], [1e9]), eps=1e199)
    _enter(env)
    try:
        ops = (cm.interval.mul(a, a), cm.interval.exp(np.array([700.0, 800.0])))
        res = cm.sivia(h, cm.Box([1e200], [2e200]), cm.Box([-np.inf], [1e9]), eps=1e199)
    finally:
        _leave()
    assert all(np.array_equal(u, v) for u, v in zip(ops, ref_ops, strict=True))
    assert res.paving.n_inner == 0 == ref.paving.n_inner
    assert np.array_equal(res.paving.outside, ref.paving.outside)


def test_no_switch_possible_is_an_error(monkeypatch):
    """Where the environment cannot be switched, evaluating raises instead of computing
    unsoundly."""
    F = InclusionFunction(ca.Function("f", [x], [x * x]), backend="numpy")
    monkeypatch.setattr(_fpu, "_load", lambda: (_ for _ in ()).throw(OSError("no libm")))
    _enter("downward")
    try:
        with pytest.raises(_fpu.FPUStateError, match="not the default"):
            F(np.array([[[1.0, 2.0]]]))
    finally:
        _leave()
