"""Ctrl-C around compiled solver calls.

CasADi polls Python's pending signals from inside a solve and clears the
``KeyboardInterrupt`` it receives, so a Ctrl-C during IPOPT (or sqpmethod) would be lost and
the run would go on. :func:`solver_call` records the signal while the solver runs and raises
``KeyboardInterrupt`` as soon as the call returns. CasADi's warning about the interruption
(written to ``sys.stderr`` during the call) is dropped; other messages of the call are
passed on to ``sys.stderr`` when it returns.
"""

from __future__ import annotations

import io
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["InterruptScope", "solver_call"]


@contextmanager
def solver_call() -> Iterator[None]:
    """Run the body (a compiled solver call); a SIGINT received meanwhile raises
    ``KeyboardInterrupt`` when the body returns (outside the main thread: no effect)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    seen: list[int] = []

    def handler(signum: int, frame: object) -> None:
        seen.append(signum)
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGINT, handler)
    except (ValueError, OSError):  # no signal support here: run the body as it is
        yield
        return
    err, buf = sys.stderr, io.StringIO()
    sys.stderr = buf
    try:
        yield
    finally:
        sys.stderr = err
        signal.signal(signal.SIGINT, previous)
        pass_on_stderr(err, buf.getvalue(), seen or sys.exc_info()[0] is KeyboardInterrupt)
    if seen:
        raise KeyboardInterrupt


def pass_on_stderr(err: Any, text: str, interrupted: bool) -> None:
    """Write what a compiled call printed to ``err``, without CasADi's line about the
    interruption when it was interrupted (the caller raises KeyboardInterrupt instead)."""
    if interrupted:
        text = "".join(line for line in text.splitlines(keepends=True)
                       if "KeyboardInterrupt" not in line)
    if text:
        err.write(text)


_scope = threading.local()


class InterruptScope:
    """Who answers Ctrl-C: the outermost library call that returns a partial result on
    ``KeyboardInterrupt`` (a search, a set sequence, a simulation). Calls nested in it
    re-raise the interruption, so that it reaches the outermost one instead of being
    turned into an inner "budget" answer that the caller would take for a result.

    Use: ``scope = InterruptScope()`` before the ``try``; in ``except KeyboardInterrupt``
    call ``scope.reraise_if_nested()``; in ``finally`` call ``scope.close()``.
    """

    __slots__ = ("outermost",)

    def __init__(self) -> None:
        self.outermost = not getattr(_scope, "active", False)
        _scope.active = True

    def reraise_if_nested(self) -> None:
        """Raise ``KeyboardInterrupt`` again unless this is the outermost scope."""
        if not self.outermost:
            raise KeyboardInterrupt

    def close(self) -> None:
        if self.outermost:
            _scope.active = False
