"""The inclusion functions of the per-step certificates of the controllers.

A controller evaluates the same inclusion function on one box at every step. The native
backend (one fused C loop per call) is then the cheapest evaluator, but it is compiled (or
loaded from the disk cache) at its first use: 10 ms to 1 s, too much for a controller that
solves once. :class:`NativeAfter` evaluates with the given (shared) inclusion function for
the first calls and moves to its own copy on the native backend after
``InclusionFunction.native_after`` calls, as ``backend="auto"`` does for large functions:
the choice depends on the calls made, not on timings. Both evaluators are sound enclosures
of the same Function; their bounds may differ in the last bits.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from ..exceptions import CmpcWarning
from ..interval.compiler import InclusionFunction

__all__ = ["NativeAfter"]


class NativeAfter:
    """``F.evaluate_unchecked`` for per-step checks, on the native backend once used often.

    Parameters
    ----------
    F : InclusionFunction
        The inclusion function (possibly shared with other users, whose backend is left
        alone).
    after : int, optional
        Calls evaluated by ``F`` before the move (default
        ``InclusionFunction.native_after``).

    Attributes
    ----------
    F : InclusionFunction
    calls : int
        Calls evaluated by ``F`` so far.
    """

    def __init__(self, F: InclusionFunction, after: int | None = None) -> None:
        self.F = F
        self.after = InclusionFunction.native_after if after is None else int(after)
        self.calls = 0
        self._native: InclusionFunction | None = None

    def evaluate_unchecked(self, boxes: Sequence[np.ndarray], n: int) -> list[np.ndarray]:
        """Evaluate on validated ``(N_i, d_i, 2)`` float arrays (see
        :meth:`InclusionFunction.evaluate_unchecked`)."""
        if self.calls < self.after:
            self.calls += 1
            return self.F.evaluate_unchecked(boxes, n)
        native = self._native
        if native is None:
            native = self._native = self._native_copy()
        return native.evaluate_unchecked(boxes, n)

    def _native_copy(self) -> InclusionFunction:
        """A copy of ``F`` past the threshold of the automatic backend: the native kernel
        from its next call (``F``'s own calls started compiling it in the background);
        ``F`` itself without a C compiler."""
        from ..interval._native import native_available

        F = self.F
        if F.backend == "native" or not native_available():
            return F
        with warnings.catch_warnings():  # F has given its warnings already
            warnings.simplefilter("ignore", CmpcWarning)
            G = InclusionFunction(F.fun, F.kind, backend="auto")
        G._native_batches = G.native_after
        return G
