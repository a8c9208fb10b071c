"""The forward-backward contractor at extreme magnitudes: overflow, underflow, subnormals.

Rule: an overflow or NaN met in any projection widens (keeps the solutions), never narrows.
Checked by sampling against mpmath at 300 bits: every sampled point whose exact value lies
in the target must stay in the contracted box, and a box declared empty must hold none.
The targets are built around the exact value at a sampled point, so solutions exist.
"""

from __future__ import annotations

import casadi as ca
import mpmath
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from casadi_cmpc.interval.contractor import contractor


class _MP:
    """The functions of the expressions below, evaluated by mpmath."""

    exp = staticmethod(mpmath.exp)
    log = staticmethod(mpmath.log)
    sqrt = staticmethod(mpmath.sqrt)
    sinh = staticmethod(mpmath.sinh)
    tanh = staticmethod(mpmath.tanh)
    expm1 = staticmethod(mpmath.expm1)
    log1p = staticmethod(mpmath.log1p)


# name -> (expression in (m, x, y), box families ((x lo, x hi), (y lo, y hi)))
EXPRS = {
    "inv_exp": lambda m, x, y: 1 / m.exp(x),
    "exp_times": lambda m, x, y: m.exp(x) * y,
    "product": lambda m, x, y: x * y,
    "quotient": lambda m, x, y: x / y,
    "exp_diff": lambda m, x, y: m.exp(x) - m.exp(y),
    "log_product": lambda m, x, y: m.log(x * y),
    "sqrt_sum": lambda m, x, y: m.sqrt(x * x + y),
    "scaled": lambda m, x, y: x * 1e300 + y / 1e-300,
    "sinh_ratio": lambda m, x, y: m.sinh(x) / y,
    "tanh_big": lambda m, x, y: m.tanh(x * 1e300) + m.expm1(y),
    "log1p_inv": lambda m, x, y: m.log1p(1 / x) * y,
}
REGIONS = [
    (700.0, 760.0), (-760.0, -700.0), (1e150, 1e160), (1e300, 1.7e308), (-1.7e308, -1e300),
    (1e-320, 1e-300), (-1e-300, 1e-300), (5e-324, 1e-310), (0.5, 2.0), (-3.0, 3.0),
]


def _float_in(lo: float, hi: float, u: float) -> float:
    if lo > 0 and hi / lo > 1e3:  # log-uniform over wide positive ranges
        return float(np.clip(np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo))), lo, hi))
    if hi < 0 and lo / hi > 1e3:
        return -_float_in(-hi, -lo, u)
    return float(np.clip(lo + u * (hi - lo), lo, hi))


def _exact(name: str, x: float, y: float):
    with mpmath.workprec(300):
        try:
            v = EXPRS[name](_MP, mpmath.mpf(x), mpmath.mpf(y))
        except (ValueError, ZeroDivisionError):
            return None
        if not isinstance(v, mpmath.mpf) or not mpmath.isfinite(v):
            return None  # undefined (complex or infinite) here: no solution
        return v


@pytest.mark.parametrize("rx", REGIONS)
@pytest.mark.parametrize("name", sorted(EXPRS))
@settings(max_examples=8)
@given(ry=st.sampled_from(REGIONS), seed=st.integers(0, 2**31 - 1),
       width=st.sampled_from([1e-6, 1e-2, 0.3, 1.0]), rel=st.sampled_from([0.0, 2**-20, 0.5]),
       reach=st.sampled_from(["around", "to_zero", "across_zero"]))
def test_contractor_keeps_every_exact_solution(name, rx, ry, seed, width, rel, reach):
    """``reach``: the target is an interval around an exact value, or stretched to 0 or
    across 0 (where the projections of products and quotients divide by intervals holding
    0 and use the extended division)."""
    rng = np.random.default_rng(seed)
    X = ca.SX.sym("x", 2)
    C = contractor(ca.Function("f", [X], [EXPRS[name](ca, X[0], X[1])]), [[-np.inf, np.inf]])
    # a sub-box of the region pair
    box = []
    for lo, hi in (rx, ry):
        a = _float_in(lo, hi, rng.random())
        b = _float_in(lo, hi, min(1.0, rng.random() * width + (rng.random() * 0.0)))
        box.append((min(a, b), max(a, b)))
    lo = np.array([[box[0][0], box[1][0]]])
    hi = np.array([[box[0][1], box[1][1]]])
    pts = [(_float_in(*box[0], rng.random()), _float_in(*box[1], rng.random()))
           for _ in range(12)]
    pts += [(box[0][i], box[1][j]) for i in (0, 1) for j in (0, 1)]
    vals = [_exact(name, px, py) for px, py in pts]
    known = [v for v in vals if v is not None]
    if not known:
        return
    centre = known[int(rng.integers(len(known)))]
    # target around an exact value, as floats rounded outward
    with mpmath.workprec(300):
        t_lo = float(mpmath.mpf(centre) - abs(centre) * rel)
        t_hi = float(mpmath.mpf(centre) + abs(centre) * rel)
    t_lo = float(np.nextafter(t_lo, -np.inf))
    t_hi = float(np.nextafter(t_hi, np.inf))
    if reach == "to_zero":
        t_lo, t_hi = min(t_lo, 0.0), max(t_hi, 0.0)
    elif reach == "across_zero":
        t_lo, t_hi = min(t_lo, -1e-300), max(t_hi, 1e-300)
    C.Y[0] = (t_lo, t_hi)
    lo2, hi2, empty = C(lo, hi, n_iter=3)
    for (px, py), v in zip(pts, vals, strict=True):
        if v is None or not (mpmath.mpf(t_lo) <= v <= mpmath.mpf(t_hi)):
            continue
        ctx = f"{name} on {box}, Y = [{t_lo!r}, {t_hi!r}], solution ({px!r}, {py!r})"
        assert not empty[0], f"{ctx}: box declared empty"
        assert lo2[0, 0] <= px <= hi2[0, 0] and lo2[0, 1] <= py <= hi2[0, 1], (
            f"{ctx}: contracted to {lo2[0].tolist()} .. {hi2[0].tolist()}")
