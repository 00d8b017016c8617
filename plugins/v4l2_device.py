"""The device node behind a ``v4l2`` camera: its path, the linuxpy import, OS errors as camera errors."""

from __future__ import annotations

import errno
import functools
import numbers
import os

from rsocl.hardware.backend import CameraDisconnected, CameraError

__all__ = ["GONE", "UNSUPPORTED", "device_path", "import_linuxpy", "os_error", "os_errors"]

#: errno of a device that went away (unplugged): CameraDisconnected.
GONE = {errno.ENODEV, errno.ENXIO}
#: errno of a request the driver does not implement.
UNSUPPORTED = {errno.ENOTTY, errno.EINVAL, errno.ENODATA, errno.EOPNOTSUPP, errno.ENOSYS}


def device_path(device, key: str = "device") -> str:
    """The device node of a ``device`` (or ``address``) config value.

    Parameters
    ----------
    device : int, str or os.PathLike
        An index (``0`` or ``"0"`` -> ``/dev/video0``) or a path, kept as given
        (``/dev/video2``, ``/dev/v4l/by-id/...``).
    key : str
        How errors name the config key ``device`` came from (``"camera 0 (v4l2): config['device']"``).

    Returns
    -------
    str
        The path of the device node.

    Raises
    ------
    ValueError
        If ``device`` is not a non-negative index or a non-empty path.
    """
    if isinstance(device, bool) or not isinstance(device, (numbers.Integral, str, os.PathLike)):
        raise ValueError(f"{key} must be a path like /dev/video0 or an index >= 0, got {device!r}")
    if isinstance(device, numbers.Integral):
        if device < 0:
            raise ValueError(f"{key} must be an index >= 0 or a path like /dev/video0, got {device!r}")
        return f"/dev/video{int(device)}"
    text = os.fsdecode(device).strip()
    if not text:
        raise ValueError(f"{key} must be a path like /dev/video0 or an index >= 0, got an empty string")
    if text.isdigit():
        return f"/dev/video{int(text)}"
    return text


def import_linuxpy(name: str):
    """``linuxpy.video.device``; a CameraError naming camera ``name`` and the extra to install when missing."""
    try:
        from linuxpy.video import device as lvd
    except (ImportError, OSError) as exc:
        raise CameraError(
            f"{name}: the v4l2 camera backend needs linuxpy (Linux only), which could not "
            f"be imported ({type(exc).__name__}: {exc}); install it with: "
            'pip install "rsocl[v4l2]"'
        ) from exc
    return lvd


def os_error(name: str, exc: OSError) -> CameraError:
    """The camera error of ``exc``: CameraDisconnected when the device went away, else CameraError."""
    if exc.errno in GONE:
        return CameraDisconnected(
            f"{name}: the device went away ({os.strerror(exc.errno)}); "
            "check the cable, then close and open the camera again"
        )
    reason = f"{os.strerror(exc.errno)} (errno {exc.errno})" if exc.errno else str(exc)
    if exc.errno == errno.EBUSY:
        reason += "; another program may be using the camera"
    return CameraError(f"{name}: {reason}")


def os_errors(fn):
    """Decorate a camera hook (a method; the camera has ``name`` and ``_lvd``): errors as camera errors.

    OSError -> :func:`os_error` (ENODEV -> CameraDisconnected), linuxpy's V4L2Error -> CameraError.
    """

    @functools.wraps(fn)
    def hook(self, *args):
        try:
            return fn(self, *args)
        except CameraError:
            raise
        except OSError as exc:
            raise os_error(self.name, exc) from exc
        except Exception as exc:
            lvd = self._lvd
            if lvd is not None and isinstance(exc, lvd.V4L2Error):
                raise CameraError(f"{self.name}: {exc}") from exc
            raise

    return hook
