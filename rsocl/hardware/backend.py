"""The camera plugin contract (entry-point group ``rsocl.cameras``).

A backend opens one physical (or simulated) camera from a plain ``config`` dict
(the camera's table of the TOML rig file), and offers the few operations a
synchronised rolling-shutter capture needs. Every wait has a timeout; every
failure is one of the exceptions below, with the camera named.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

__all__ = ["CameraError", "CameraTimeout", "CameraDisconnected", "Frame", "CameraBackend", "TRIGGER_MODES"]

TRIGGER_MODES = ("free", "software", "line")


class CameraError(RuntimeError):
    """A camera could not do what was asked (bad setting, lost buffer, ...)."""


class CameraTimeout(CameraError):
    """No frame arrived within the timeout."""


class CameraDisconnected(CameraError):
    """The camera went away (unplugged, network lost, process died)."""


@dataclass
class Frame:
    """One raw frame.

    Attributes
    ----------
    image : ndarray, 2-D
        Pixel values as delivered (uint8 / uint16), sensor orientation, after the ROI.
    timestamp : float
        Device timestamp in seconds when the backend has one, else host time.
    pixel_format : str
        ``"Mono8"``, ``"Mono12"``, ``"Mono16"``, ``"GREY"``, ``"Y16"``, ``"YUYV"``...
    bit_depth : int
        Significant bits per pixel.
    meta : dict
        Anything else the backend reports (frame id, exposure actually used, ...).
    """

    image: np.ndarray
    timestamp: float
    pixel_format: str
    bit_depth: int
    meta: dict = field(default_factory=dict)


class CameraBackend:
    """Base class of camera backends; a backend overrides the ``_`` hooks.

    Parameters
    ----------
    config : dict
        Backend-specific settings (address, ROI, ...), from the rig file.
    name : str
        Human-readable name used in errors (``"camera 2 (aravis 127.0.0.1)"``).

    Raises
    ------
    rsocl.common.registry.PluginError
        A ValueError, when a subclass's constructor raises anything but a CameraError or ValueError (a
        config key it lacks, ...): naming the camera, the backend's class and its distribution, with the cause.
    """

    backend = "base"

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        own = cls.__dict__.get("__init__")
        if own is not None:
            cls.__init__ = _guarded(cls, own)

    def __init__(self, config: dict | None = None, name: str | None = None):
        self.config = dict(config or {})
        self.name = name or f"{self.backend} camera"
        self._open = False
        self._trigger_mode = "software"

    # -------------------------------------------------------------- lifecycle
    @classmethod
    def check_dependencies(cls) -> None:
        """Import what opening a camera of this backend needs (a library, a driver binding).

        ``rsocl plugins`` calls it to tell a backend that can open cameras from one that cannot.
        The base class needs nothing.

        Raises
        ------
        CameraError
            Saying what is missing and how to install it.
        """

    def open(self):
        """Connect to the device. Idempotent."""
        if not self._open:
            self._wrap(self._open_device)
            self._open = True
        return self

    def close(self):
        """Release the device. Idempotent; never raises for an already closed camera."""
        if self._open:
            self._open = False
            self._wrap(self._close_device)

    def __enter__(self):
        return self.open()

    def __exit__(self, *exc):
        self.close()
        return False

    def _need_open(self):
        if not self._open:
            raise CameraError(f"{self.name}: not open (use 'with camera:' or camera.open())")

    def _wrap(self, fn, *args):
        try:
            return fn(*args)
        except CameraError:
            raise
        except (OSError, RuntimeError) as exc:
            raise CameraError(f"{self.name}: {type(exc).__name__}: {exc}") from exc

    # -------------------------------------------------------------- settings
    def set_exposure(self, seconds: float) -> float:
        """Set the exposure time (s); returns the value the device actually uses."""
        self._need_open()
        if not (np.isfinite(seconds) and seconds > 0):
            raise ValueError(f"{self.name}: exposure must be > 0 seconds, got {seconds!r}")
        return float(self._wrap(self._set_exposure, float(seconds)))

    def set_roi(self, x: int, y: int, width: int, height: int):
        """Set the sensor region of interest, pixels."""
        self._need_open()
        for key, value in (("x", x), ("y", y)):
            if int(value) < 0:
                raise ValueError(f"{self.name}: ROI {key} must be >= 0, got {value!r}")
        for key, value in (("width", width), ("height", height)):
            if int(value) < 1:
                raise ValueError(f"{self.name}: ROI {key} must be >= 1, got {value!r}")
        self._wrap(self._set_roi, int(x), int(y), int(width), int(height))

    def set_pixel_format(self, pixel_format: str):
        """Select the pixel format (one of :attr:`pixel_formats`)."""
        self._need_open()
        if pixel_format not in self.pixel_formats:
            raise ValueError(
                f"{self.name}: pixel_format must be one of {list(self.pixel_formats)}, got {pixel_format!r}"
            )
        self._wrap(self._set_pixel_format, pixel_format)

    def set_trigger(self, mode: str = "software", source: str | None = None):
        """``"free"`` running, ``"software"`` trigger, or hardware ``"line"`` (``source`` e.g. ``"Line1"``)."""
        self._need_open()
        if mode not in TRIGGER_MODES:
            raise ValueError(f"{self.name}: trigger mode must be one of {list(TRIGGER_MODES)}, got {mode!r}")
        if mode == "line" and not source:
            raise ValueError(f"{self.name}: trigger mode 'line' needs a source such as 'Line1'")
        self._wrap(self._set_trigger, mode, source)
        self._trigger_mode = mode

    @property
    def sensor_size(self) -> tuple[int, int] | None:
        """``(width, height)``, pixels, of the area a ROI is cut from (the whole sensor), or None where the
        backend cannot tell: some know it only once the camera is open, some never."""
        return self._wrap(self._sensor_size)

    @property
    def readout_time(self) -> float | None:
        """Row readout time reported by the device (seconds per row), or None if it does not say."""
        self._need_open()
        return self._wrap(self._readout_time)

    # -------------------------------------------------------------- capture
    def start(self):
        """Start acquisition (buffers queued, waiting for triggers)."""
        self._need_open()
        self._wrap(self._start)

    def stop(self):
        """Stop acquisition."""
        if self._open:
            self._wrap(self._stop)

    def trigger(self):
        """Fire a software trigger."""
        self._need_open()
        self._wrap(self._trigger)

    def read(self, timeout: float = 2.0) -> Frame:
        """Wait at most ``timeout`` seconds for the next frame."""
        self._need_open()
        if not (np.isfinite(timeout) and timeout > 0):
            raise ValueError(f"{self.name}: timeout must be > 0 seconds, got {timeout!r}")
        return self._wrap(self._read, float(timeout))

    def capture(self, timeout: float = 2.0) -> Frame:
        """One frame: software trigger (when in software mode) and read."""
        if self._trigger_mode == "software":
            self.trigger()
        return self.read(timeout)

    def __repr__(self):
        return f"<{type(self).__name__} {self.name!r} {'open' if self._open else 'closed'}>"

    # -------------------------------------------------------------- hooks
    #: The pixel formats the camera delivers; a camera may narrow its backend's from its config.
    pixel_formats: tuple = ()

    def _sensor_size(self):
        return None

    def _open_device(self):
        raise NotImplementedError(f"{type(self).__name__} does not implement _open_device")

    def _close_device(self):
        raise NotImplementedError(f"{type(self).__name__} does not implement _close_device")

    def _set_exposure(self, seconds):
        raise NotImplementedError(f"{type(self).__name__} does not implement _set_exposure")

    def _set_roi(self, x, y, width, height):
        raise NotImplementedError(f"{type(self).__name__} does not implement _set_roi")

    def _set_pixel_format(self, pixel_format):
        raise NotImplementedError(f"{type(self).__name__} does not implement _set_pixel_format")

    def _set_trigger(self, mode, source):
        raise NotImplementedError(f"{type(self).__name__} does not implement _set_trigger")

    def _readout_time(self):
        return None

    def _start(self):
        raise NotImplementedError(f"{type(self).__name__} does not implement _start")

    def _stop(self):
        raise NotImplementedError(f"{type(self).__name__} does not implement _stop")

    def _trigger(self):
        raise NotImplementedError(f"{type(self).__name__} does not implement _trigger")

    def _read(self, timeout):
        raise NotImplementedError(f"{type(self).__name__} does not implement _read")


def _guarded(cls: type, init):
    """``cls``'s own ``__init__`` made to raise a PluginError (a ValueError) naming the camera, the class and
    its distribution for anything but a CameraError or ValueError (a config key the rig file lacks, ...)."""

    @functools.wraps(init)
    def __init__(self, config=None, name=None, *args, **kwargs):
        try:
            init(self, config, name, *args, **kwargs)
        except (CameraError, ValueError):  # the backend's own words (a config value it refuses, ...)
            raise
        except Exception as exc:
            from rsocl.common.registry import PluginError, origin

            where = origin("rsocl.cameras", cls)
            what = f"{cls.__module__}.{cls.__qualname__}{' from ' + where if where else ''}"
            raise PluginError(
                f"{name or cls.backend + ' camera'}: backend {cls.backend!r} ({what}) could not be set up: "
                f"{type(exc).__name__}: {exc}"
            ) from exc

    return __init__
