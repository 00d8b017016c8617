"""The command line's interrupts (Ctrl-C's SIGINT, SIGTERM), never lost to a weakref callback.

Python raises a signal handler's exception in the main thread wherever it runs; where that is a weakref
callback or a ``__del__`` method, the exception is printed ("Exception ignored in ...") and dropped, and the
command goes on as if no signal had come. :func:`handle`, the command line's handler of both signals, notes
each signal before it raises; a long loop calls :func:`raise_dropped` at its safe points (``rsocl capture``:
after each set), which raises again a noted signal whose exception never reached the command, and
:func:`forget` clears the notes once the command has caught the interrupt.

>>> forget(); raise_dropped()  # nothing noted: nothing happens
"""

from __future__ import annotations

import signal

__all__ = ["Terminated", "handle", "raise_dropped", "forget"]

_NOTED: list = []


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command runs, so that the command ends as on Ctrl-C: closing its files and
    saying in one line what was kept (exit status 143)."""


def _exception(signum) -> KeyboardInterrupt:
    return Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def handle(signum, frame):
    """Note ``signum`` (SIGINT or SIGTERM) and raise its exception: :class:`KeyboardInterrupt`, or
    :class:`Terminated` for SIGTERM."""
    _NOTED.append(signum)
    raise _exception(signum)


def raise_dropped() -> None:
    """Raise the exception of a noted signal that the command has not caught yet (:func:`forget`): one Python
    dropped where it came (a weakref callback, a ``__del__``)."""
    if _NOTED:
        signum = _NOTED[-1]
        _NOTED.clear()
        raise _exception(signum)


def forget() -> None:
    """Clear the notes: the command caught the interrupt (or starts afresh)."""
    _NOTED.clear()
