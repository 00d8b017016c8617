"""The cameras' side of a capture (:func:`rsocl.hardware.capture.capture_sets`): opening them, closing them
where the capture ends before its file is made, stopping and closing them at its end; and how a fault is
said on one line (:func:`one_line`), as the capture file records it."""

from __future__ import annotations

import contextlib
import os

__all__ = ["open_cameras", "closing_on_error", "stop_cameras", "one_line"]


def open_cameras(cameras, where):
    """Open the cameras in turn, up to the first that fails: ``(failure, interrupt)``, the failure (``where``
    it happened, its type and error) and the interrupt (Ctrl-C, SIGTERM) or None each, for the file to record."""
    for i, cam in enumerate(cameras):
        where.update(camera=i, set=None, phase="open")
        try:
            cam.open()
        except Exception as exc:
            return dict(where, type=type(exc).__name__, error=one_line(exc)), None
        except BaseException as exc:  # KeyboardInterrupt, SystemExit: recorded, then let through
            return dict(where, type=type(exc).__name__, error=one_line(exc)), exc
    return None, None


def closing_on_error(cameras, step, *args):
    """``step(*args)``; where it raises (a refused setting, a capture file that cannot be made), the cameras
    are closed first (best effort: the error raised is the one reported)."""
    try:
        return step(*args)
    except BaseException:
        for cam in cameras:
            with contextlib.suppress(Exception):
                cam.close()
        raise


def stop_cameras(cameras, writer, failure, interrupted):
    """Stop and close every camera: an error is a warning; an interrupt (Ctrl-C, SIGTERM) is recorded (the
    first, with the failure, where none is) and closing goes on. Returns ``(failure, interrupted)``."""
    for i, cam in enumerate(cameras):
        for step in (cam.stop, cam.close):
            try:
                try:
                    step()
                except Exception as exc:  # closing must reach every camera
                    writer.warn(f"camera {i}: {step.__name__} failed: {type(exc).__name__}: {exc}")
            except BaseException as exc:  # an interrupt (or a warning the file does not take): on to the next
                if interrupted is None and not isinstance(exc, Exception):
                    interrupted = exc
                    error = one_line(exc)
                    failure = failure or dict(
                        camera=i, set=None, phase=step.__name__, type=type(exc).__name__, error=error
                    )
    return failure, interrupted


def one_line(exc: BaseException) -> str:
    """``str(exc)`` on one line (HDF5's messages hold line breaks), or the exception's type name; an
    ``OSError`` with an error number as the system's words for it (HDF5 adds buffers and offsets)."""
    if isinstance(exc, OSError) and exc.errno:
        return f"[Errno {exc.errno}] {os.strerror(exc.errno)}"
    return " ".join(str(exc).split()) or type(exc).__name__
