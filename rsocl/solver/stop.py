"""Stopping a run from another thread: a tile task that the command line's Ctrl-C should end.

A run checks the event of :func:`stopping` (of its own thread) where it books its residuals, every
iteration or every group of iterations read together (:mod:`rsocl.solver.iterate`), and raises
:class:`Stopped` once the event is set. Nothing else about the run changes: the check costs no launch
and no wait.

>>> import threading
>>> event = threading.Event()
>>> with stopping(event):
...     check_stop()  # not set: nothing happens
...     event.set()
...     check_stop()
Traceback (most recent call last):
...
rsocl.solver.stop.Stopped: the run was stopped from outside (its stop event is set)
"""

from __future__ import annotations

import contextlib
import contextvars
import threading

__all__ = ["Stopped", "stopping", "check_stop"]

_EVENT: contextvars.ContextVar[threading.Event | None] = contextvars.ContextVar("rsocl_stop_event", default=None)


class Stopped(Exception):
    """A run ended because the event of :func:`stopping` was set (by another thread)."""


@contextlib.contextmanager
def stopping(event: threading.Event | None):
    """Within the block, runs of this thread raise :class:`Stopped` at their next booking once ``event`` is
    set (None: no stop, as outside the block)."""
    token = _EVENT.set(event)
    try:
        yield
    finally:
        _EVENT.reset(token)


def check_stop() -> None:
    """Raise :class:`Stopped` where this thread's stop event (:func:`stopping`) is set."""
    event = _EVENT.get()
    if event is not None and event.is_set():
        raise Stopped("the run was stopped from outside (its stop event is set)")
