"""Evaluation of CasADi Functions on preallocated arrays, for the per-step calls of the
controllers.

A call ``fun(*args)`` from Python converts every numpy argument to a ``DM`` and every result
back (15-30 µs per call for the small functions of a controller step, more than the
evaluation itself). :class:`BufferedCall` binds numpy arrays to the inputs and outputs of
the Function once (``casadi.Function.buffer``) and evaluates in place: a call costs a few
hundred nanoseconds plus the evaluation, and gives the same numbers as ``fun(*args)`` (the
same Function evaluated on the same values).
"""

from __future__ import annotations

import io
import sys
import threading
from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np

from .._interrupt import pass_on_stderr

__all__ = ["BufferedCall"]


class BufferedCall:
    """A CasADi Function evaluated in place on arrays bound to its inputs and outputs.

    Parameters
    ----------
    fun : casadi.Function
        A Function with dense inputs and outputs.
    args, res : dict of int to ndarray, optional
        Arrays to bind to inputs / outputs (by index) instead of fresh zero arrays: 1-D,
        C-contiguous float64 views of ``fun.nnz_in(i)`` / ``fun.nnz_out(i)`` elements (e.g. a
        slice of another call's array, so that one call reads what another one wrote).

    Attributes
    ----------
    fun : casadi.Function
    args, res : list of ndarray
        The arrays bound to the inputs and outputs (nonzeros in column-major order). Write
        the inputs in place (``call.args[0][:] = x``), call, read the outputs; the output
        arrays are overwritten by the next call.

    Notes
    -----
    A failing evaluation raises ``RuntimeError`` as a plain call does (its message may be
    worded differently). :meth:`stats` reads the statistics of the evaluations made through
    this object (``fun.stats()`` describes the plain calls only).

    **Ctrl-C.** CasADi polls Python's signals during a solve and stops the solver on a
    ``KeyboardInterrupt``. A plain call then returns as if nothing had happened (hence
    :func:`casadi_cmpc._interrupt.solver_call` around plain solver calls); here the
    interruption comes out of the evaluation (as ``SystemError`` from IPOPT, as
    ``RuntimeError`` from ``sqpmethod``) and is raised as ``KeyboardInterrupt``. With
    ``interruptible=True``, CasADi's warning about the interruption (written to
    ``sys.stderr`` during the call) is dropped and its other messages are passed on when the
    call returns, as ``solver_call`` does.
    """

    def __init__(self, fun: ca.Function, args: dict[int, np.ndarray] | None = None,
                 res: dict[int, np.ndarray] | None = None, *,
                 interruptible: bool = False) -> None:
        self.fun = fun
        self.interruptible = bool(interruptible)
        self.args = self._arrays([fun.nnz_in(i) for i in range(fun.n_in())], args or {},
                                 "input")
        self.res = self._arrays([fun.nnz_out(i) for i in range(fun.n_out())], res or {},
                                "output")
        self._buf, self._eval = fun.buffer()
        for i, a in enumerate(self.args):
            if a.size:
                self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self.res):
            if r.size:
                self._buf.set_res(i, memoryview(r))

    def _arrays(self, sizes: Sequence[int], given: dict[int, np.ndarray],
                what: str) -> list[np.ndarray]:
        out = []
        for i, k in enumerate(sizes):
            a = given.get(i)
            if a is None:
                a = np.zeros(k)
            elif (a.dtype != np.float64 or a.ndim != 1 or a.size != k
                  or not a.flags.c_contiguous):
                raise ValueError(f"{what} {i} of '{self.fun.name()}' needs a contiguous float64 "
                                 f"vector of {k} elements; got {a.dtype} {a.shape}")
            out.append(a)
        return out

    def __call__(self) -> None:
        """Evaluate the Function on the bound input arrays into the output arrays (a
        Ctrl-C during the evaluation raises ``KeyboardInterrupt``)."""
        if not self.interruptible or threading.current_thread() is not threading.main_thread():
            if self._run():
                raise KeyboardInterrupt
            return
        err, buf = sys.stderr, io.StringIO()
        sys.stderr = buf
        try:
            interrupted = self._run()
        finally:
            sys.stderr = err
        pass_on_stderr(err, buf.getvalue(), interrupted)
        if interrupted:
            raise KeyboardInterrupt

    def _run(self) -> bool:
        """Evaluate; whether a ``KeyboardInterrupt`` stopped the evaluation."""
        try:
            self._eval()
        except SystemError as exc:  # IPOPT returns with the interrupt set
            if not isinstance(exc.__cause__, KeyboardInterrupt):
                raise
            return True
        except RuntimeError as exc:  # sqpmethod passes it on as its error
            if str(exc).strip() != "KeyboardInterrupt":
                raise
            return True
        return False

    def stats(self) -> dict[str, Any]:
        """Statistics of the last evaluation through this object (as ``fun.stats()``)."""
        return self._buf.stats()
