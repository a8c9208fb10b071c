"""Local laws: one convention for every function that takes a law.

A law is one of

* a :class:`LinearLaw` ``u = u_eq + K (x - x_eq)``, which carries its gain and the
  equilibrium it was designed at (:func:`casadi_cmpc.local_lqr` returns one);
* a bare gain matrix ``K`` of shape (m, n): the same as ``LinearLaw(K)``, i.e. ``u = K x``
  about the origin, everywhere (a bare gain never means a deviation from some other point);
* a ``casadi.SX`` expression of the model's ``x`` with m elements.

:func:`law_expr` turns each into the one expression every certificate, set sequence and
controller uses; two laws are the same when they are the same expression of ``x``.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from ..exceptions import DimensionError

__all__ = ["LinearLaw"]


class LinearLaw:
    """The affine law ``u = u_eq + K (x - x_eq)``.

    Parameters
    ----------
    K : array_like (m, n)
        The gain [input units per state unit].
    x_eq : array_like (n,), optional
        The state the law regulates to (default: the origin).
    u_eq : array_like (m,), optional
        The input at ``x_eq`` (default: zero).

    Notes
    -----
    ``np.asarray(law)`` is the gain ``K`` alone; pass the law object itself to the
    library's functions so that the equilibrium goes with it.

    Examples
    --------
    >>> law = LinearLaw([[-0.5, -1.0]], x_eq=[1.0, 0.0], u_eq=[0.3])
    >>> law([1.0, 0.0]).tolist()
    [0.3]
    """

    __slots__ = ("K", "x_eq", "u_eq")

    def __init__(self, K: Any, x_eq: Any = None, u_eq: Any = None) -> None:
        Km = np.atleast_2d(np.array(K, dtype=float))
        if Km.ndim != 2:
            raise DimensionError(f"K must be a matrix (m, n); got shape {Km.shape}")
        m, n = Km.shape
        xe = np.zeros(n) if x_eq is None else np.array(x_eq, dtype=float).reshape(-1)
        ue = np.zeros(m) if u_eq is None else np.array(u_eq, dtype=float).reshape(-1)
        if xe.shape != (n,):
            raise DimensionError(f"x_eq must have n = {n} elements (K is {m} x {n}); "
                                 f"got {xe.size}")
        if ue.shape != (m,):
            raise DimensionError(f"u_eq must have m = {m} elements (K is {m} x {n}); "
                                 f"got {ue.size}")
        for name, a in (("K", Km), ("x_eq", xe), ("u_eq", ue)):
            if not np.isfinite(a).all():
                raise ValueError(f"{name} contains NaN or infinite entries")
            a.setflags(write=False)
        self.K, self.x_eq, self.u_eq = Km, xe, ue

    @property
    def shape(self) -> tuple[int, int]:
        """``(m, n)``, the shape of ``K``."""
        return self.K.shape  # type: ignore[return-value]

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        return np.array(self.K, dtype=dtype)

    def __call__(self, x: Any) -> np.ndarray:
        """``u = u_eq + K (x - x_eq)`` at a state ``x`` (n,); returns (m,)."""
        return self.u_eq + self.K @ (np.asarray(x, dtype=float).reshape(-1) - self.x_eq)

    def expr(self, x: ca.SX) -> ca.SX:
        """The law as an (m, 1) expression of the state symbol ``x`` (n, 1). The origin's
        zeros are left out, so ``LinearLaw(K).expr(x)`` is the expression ``K x``."""
        dx = x - ca.DM(self.x_eq) if np.any(self.x_eq) else x
        u = ca.mtimes(ca.DM(self.K), dx)
        return ca.DM(self.u_eq) + u if np.any(self.u_eq) else u

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, LinearLaw):
            return NotImplemented
        return (np.array_equal(self.K, other.K) and np.array_equal(self.x_eq, other.x_eq)
                and np.array_equal(self.u_eq, other.u_eq))

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return (f"LinearLaw(K={self.K.tolist()}, x_eq={self.x_eq.tolist()}, "
                f"u_eq={self.u_eq.tolist()})")

    def __str__(self) -> str:
        dx = "(x - x_eq)" if np.any(self.x_eq) else "x"
        head = "u_eq + " if np.any(self.u_eq) else ""
        return f"u = {head}K {dx}, K = {np.round(self.K, 6).tolist()}" + (
            f", x_eq = {self.x_eq.tolist()}" if np.any(self.x_eq) else "") + (
            f", u_eq = {self.u_eq.tolist()}" if np.any(self.u_eq) else "")


def as_law(law: Any, m: int, n: int) -> LinearLaw | ca.SX:
    """A law given by the user as a :class:`LinearLaw` or an SX expression (a bare gain
    (m, n), or (n,) for one input, becomes ``LinearLaw(K)``: ``u = K x``)."""
    if isinstance(law, (LinearLaw, ca.SX)):
        out = law
    elif isinstance(law, (ca.MX, ca.DM)) and not isinstance(law, ca.SX):
        if isinstance(law, ca.MX):
            raise TypeError("give a law as casadi.SX in the model's x, a LinearLaw or a "
                            "gain matrix K (m, n)")
        out = LinearLaw(np.asarray(law, dtype=float).reshape(m, -1))
    else:
        try:
            K = np.asarray(law, dtype=float)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"a law must be a LinearLaw, a gain matrix K ({m}, {n}) or a "
                            f"casadi.SX expression of x; got {type(law).__name__}") from exc
        if K.ndim == 1 and m == 1 and K.size == n:
            K = K.reshape(1, n)
        out = LinearLaw(np.atleast_2d(K))
    if isinstance(out, LinearLaw) and out.shape != (m, n):
        raise DimensionError(f"gain K must have shape (m, n) = ({m}, {n}) (u = K x); got "
                             f"{out.shape}")
    if isinstance(out, ca.SX) and out.numel() != m:
        raise DimensionError(f"the law must have {m} elements (one per input); got "
                             f"{out.numel()}")
    return out


def law_expr(model: Any, law: Any) -> ca.SX:
    """The law as an (m, 1) SX expression of ``model.x`` (see the module's convention)."""
    lw = as_law(law, model.m, model.n)
    if isinstance(lw, LinearLaw):
        return lw.expr(model.x)
    allowed = {model.x[i].__hash__() for i in range(model.n)}
    free = [s for s in ca.symvar(lw) if s.__hash__() not in allowed]
    if free:
        from ..exceptions import FreeSymbolError

        raise FreeSymbolError("the law may depend on the model's x only; it depends on "
                         + ", ".join(str(s) for s in free))
    return ca.reshape(lw, model.m, 1)
