"""Private normalisers shared by the package: convert, check and name arguments."""

from __future__ import annotations

from typing import Any

import numpy as np

from .exceptions import DimensionError, EmptySetError, InvalidBoundsError

__all__: list[str] = []


def _first_string(data: Any) -> Any:
    """The first str/bytes element of a (nested) sequence or array, else None."""
    if isinstance(data, (str, bytes, np.str_, np.bytes_)):
        return data
    if isinstance(data, np.ndarray):
        if data.dtype.kind in "US":
            return data.ravel()[0] if data.size else None
        if data.dtype.kind != "O":
            return None
        data = data.ravel().tolist()
    if isinstance(data, (list, tuple)):
        for x in data:
            found = _first_string(x)
            if found is not None:
                return found
    return None


def as_float_array(data: Any, name: str) -> np.ndarray:
    """``np.asarray(data, dtype=float)`` that refuses strings (also numeric ones: a string
    is not a number) and names the argument when the conversion fails."""
    try:
        raw = np.asarray(data)
    except (TypeError, ValueError) as exc:  # ragged nesting
        raise InvalidBoundsError(f"{name} must be an array of numbers; {exc}") from exc
    if raw.dtype.kind in "biuf":  # the common case: no element to inspect
        return raw.astype(float, copy=False)
    s = _first_string(data)  # the original elements (numpy turns 1 into "1" beside "a")
    if s is not None:
        raise InvalidBoundsError(
            f"{name} must be numbers; got the string {str(s)!r} (write numbers, e.g. 1.5, "
            "not '1.5')")
    try:
        return np.asarray(data, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidBoundsError(f"{name} must be an array of numbers; {exc}") from exc


def as_boxes(data: Any, d: int | None = None, name: str = "X", *,
             allow_empty: bool = False) -> np.ndarray:
    """Return a float array of shape ``(N, d, 2)`` from boxes given in any accepted form.

    Accepted: a :class:`~casadi_cmpc.Box`, an ``(N, d, 2)`` array, one ``(d, 2)`` array,
    or (when ``d == 1``) an ``(N, 2)`` array is *not* guessed: pass ``(N, 1, 2)``.
    Raises :class:`DimensionError` with the argument name on a wrong shape and
    :class:`InvalidBoundsError` on NaN bounds; :class:`EmptySetError` when some lower bound
    exceeds its upper bound (unless ``allow_empty``).
    """
    if hasattr(data, "as_array") and not isinstance(data, np.ndarray):
        data = data.as_array()
    arr = np.asarray(data, dtype=float)
    if arr.ndim == 2 and arr.shape[-1] == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[-1] != 2:
        raise DimensionError(
            f"{name} must be boxes of shape (N, d, 2) or (d, 2); got shape {arr.shape}")
    if d is not None and arr.shape[1] != d:
        raise DimensionError(
            f"{name} has the wrong dimension; expected {d} instead of {arr.shape[1]}")
    if np.isnan(arr).any():
        raise InvalidBoundsError(f"{name} contains NaN bounds")
    if not allow_empty and (arr[..., 0] > arr[..., 1]).any():
        i = np.argwhere(arr[..., 0] > arr[..., 1])[0]
        raise EmptySetError(
            f"{name} is empty: lower bound {arr[i[0], i[1], 0]} > upper bound "
            f"{arr[i[0], i[1], 1]} (box {i[0]}, component {i[1]})")
    return arr


def as_points(data: Any, d: int | None = None, name: str = "x") -> tuple[np.ndarray, bool]:
    """Return ``(points (N, d), was_batched)`` from a point ``(d,)`` or batch ``(N, d)``."""
    arr = np.asarray(data, dtype=float)
    batched = arr.ndim == 2
    if arr.ndim == 0:
        arr = arr.reshape(1, 1)
    elif arr.ndim == 1:
        arr = arr[None] if (d is None or arr.shape[0] == d) else arr[:, None]
        batched = batched or (d == 1 and arr.shape[0] != 1)
    if arr.ndim != 2:
        raise DimensionError(f"{name} must have shape (N, d) or (d,); got {np.shape(data)}")
    if d is not None and arr.shape[1] != d:
        raise DimensionError(
            f"{name} has the wrong dimension; expected {d} instead of {arr.shape[1]}")
    return arr, batched


def weight_matrix(M: Any, d: int, name: str, definite: bool, default: np.ndarray | None
            ) -> np.ndarray:
    if M is None:
        return np.eye(d) if default is None else default
    W = np.asarray(M, dtype=float)
    if W.ndim == 0 or (W.ndim == 1 and W.size == 1 and d == 1):
        W = W.reshape(1, 1) * np.eye(d) if W.size == 1 else W
        W = np.atleast_2d(W)
    if W.ndim == 1 and W.size == d:
        W = np.diag(W)
    if W.shape == (1, 1) and d > 1:
        W = W[0, 0] * np.eye(d)
    if W.shape != (d, d):
        raise DimensionError(f"{name} must be a ({d}, {d}) matrix (or a scalar or a "
                             f"length-{d} diagonal); got shape {np.shape(M)}")
    if not np.isfinite(W).all():
        raise ValueError(f"{name} must be finite; got {W.tolist()}")
    if not np.allclose(W, W.T, rtol=1e-12, atol=1e-12 * (1 + np.abs(W).max())):
        raise ValueError(f"{name} must be symmetric; got {W.tolist()}")
    ev = np.linalg.eigvalsh(0.5 * (W + W.T))
    tol = 1e-12 * max(1.0, float(np.abs(ev).max()))
    if definite and ev.min() <= tol:
        raise ValueError(f"{name} must be symmetric positive definite; its smallest "
                         f"eigenvalue is {ev.min():.3g}")
    if not definite and ev.min() < -tol:
        raise ValueError(f"{name} must be symmetric positive semidefinite; its smallest "
                         f"eigenvalue is {ev.min():.3g}")
    return 0.5 * (W + W.T)


def float_vector(v: Any, d: int, name: str, default: np.ndarray) -> np.ndarray:
    if v is None:
        return default.copy()
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.size != d:
        raise DimensionError(f"{name} must have {d} elements; got shape {np.shape(v)}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} must be finite; got {a.tolist()}")
    return a
