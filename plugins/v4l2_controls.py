"""Exposure and ROI of a ``v4l2`` camera: :class:`V4L2Controls`, a mixin of :class:`~rsocl_plugins.v4l2.V4L2Camera`.

Exposure
    ``set_exposure(seconds)`` sets ``auto_exposure`` to manual (when the device has that
    control), then ``exposure_time_absolute`` in its units of 100 µs: the value is rounded
    to the nearest unit, clamped to the control's minimum/maximum and snapped to its step.
    The value read back from the device is returned, in seconds: its units / 10000, the double nearest
    the decimal value (123 -> 0.0123 s); so a request outside the device's range returns the clamped
    value, never the request.

ROI
    Coordinates are sensor pixels. When the driver implements the selection API
    (``VIDIOC_S_SELECTION``, target CROP) the crop is done in hardware; if the driver
    adjusts the rectangle to a larger one that still contains the request, the rest is
    cropped in software. Drivers without it (most UVC webcams) get a software crop: the
    full frame is transferred and ``read`` returns the requested region (no frame-rate
    gain). ``frame.meta["roi"]`` says which (``"hardware"`` / ``"software"`` / ``None``).
    A driver that scales its crop (binning) cannot be cropped in sensor pixels: a CameraError.
    Changing the ROI or the pixel format needs acquisition stopped; a pixel format whose frames the
    ROI no longer fits clears it with a CameraError (set the pixel format first). ``sensor_size``, once
    the camera is open: the selection API's crop bounds; None without that API (the software crop is
    bounded by the frame, whose size the pixel format sets).
"""

from __future__ import annotations

import math

from rsocl.hardware.backend import CameraError
from rsocl_plugins.v4l2_device import UNSUPPORTED, os_errors

__all__ = ["V4L2Controls", "EXPOSURE_UNIT"]

#: Unit of ``exposure_time_absolute`` (V4L2_CID_EXPOSURE_ABSOLUTE), seconds.
EXPOSURE_UNIT = 100e-6
_UNITS_PER_SECOND = round(1 / EXPOSURE_UNIT)  # 10000: an exposure in seconds is its units divided by this

_CID_EXPOSURE_AUTO = 0x009A0901  # V4L2_CID_EXPOSURE_AUTO, menu
_CID_EXPOSURE_ABSOLUTE = 0x009A0902  # V4L2_CID_EXPOSURE_ABSOLUTE, integer, 100 us units
_EXPOSURE_MANUAL = 1  # V4L2_EXPOSURE_MANUAL


class V4L2Controls:
    """The camera hooks ``_set_exposure``, ``_sensor_size`` and ``_set_roi``.

    Uses the camera's open device (``_lvd``, ``_dev``), its format (``_fmt``, ``_read_format``)
    and ``_streaming``; sets ``_exposure`` (seconds) and the ROI state ``_soft_roi`` (the crop
    done in software, ``(x, y, w, h)`` or None) and ``_roi_kind``.
    """

    # ---------------------------------------------------------------- exposure
    def _control(self, cid, names):
        controls = self._dev.controls
        try:
            return controls[cid]
        except KeyError:
            pass
        for key in names:
            try:
                return controls[key]
            except KeyError:
                continue
        return None

    @os_errors
    def _set_exposure(self, seconds):
        auto = self._control(_CID_EXPOSURE_AUTO, ("auto_exposure", "exposure_auto"))
        absolute = self._control(_CID_EXPOSURE_ABSOLUTE, ("exposure_time_absolute", "exposure_absolute"))
        if absolute is None:
            raise CameraError(
                f"{self.name}: the device has no exposure_time_absolute control, so its exposure "
                "cannot be set in seconds"
            )
        try:
            if auto is not None and auto.value != _EXPOSURE_MANUAL:
                menu = getattr(auto, "data", None)
                if menu and _EXPOSURE_MANUAL not in menu:
                    raise CameraError(f"{self.name}: auto_exposure has no manual mode (menu: {dict(menu)})")
                auto.value = _EXPOSURE_MANUAL
            lo, hi = int(absolute.minimum), int(absolute.maximum)
            step = max(1, int(absolute.step or 1))
            units = int(math.floor(seconds / EXPOSURE_UNIT + 0.5))
            units = min(max(units, lo), hi)
            units = lo + int(math.floor((units - lo) / step + 0.5)) * step
            if units > hi:
                units -= step
            absolute.value = units
            actual = int(absolute.value)
        except AttributeError as exc:  # linuxpy: control not writeable (read-only, disabled, grabbed)
            raise CameraError(f"{self.name}: {exc}") from exc
        self._exposure = actual / _UNITS_PER_SECOND  # 123 -> 0.0123 (123 * 1e-4 is 0.012300000000000002)
        return self._exposure

    # ---------------------------------------------------------------- ROI
    def _crop_bounds(self):
        """The selection API's CROP_BOUNDS (the sensor), or None for a driver without that API."""
        lvd = self._lvd
        try:
            return lvd.get_selection(self._dev, lvd.BufferType.VIDEO_CAPTURE, lvd.SelectionTarget.CROP_BOUNDS)
        except OSError as exc:
            if exc.errno not in UNSUPPORTED:
                raise
            return None

    @os_errors
    def _sensor_size(self):
        bounds = None if self._dev is None else self._crop_bounds()  # None: the frame's size, set by its format
        return None if bounds is None else (bounds.width, bounds.height)

    @os_errors
    def _set_roi(self, x, y, width, height):
        if self._streaming:
            raise CameraError(f"{self.name}: stop() acquisition before changing the ROI")
        lvd = self._lvd
        capture = lvd.BufferType.VIDEO_CAPTURE
        bounds = self._crop_bounds()
        if bounds is None:  # no selection API: crop in software
            self._software_roi(x, y, width, height)
            return
        if x + width > bounds.width or y + height > bounds.height:
            raise ValueError(f"{self.name}: {_off('sensor', (x, y, width, height), bounds.width, bounds.height)}")
        want = lvd.Rect(bounds.left + x, bounds.top + y, width, height)
        try:
            lvd.set_selection(self._dev, capture, lvd.SelectionTarget.CROP, want)
        except OSError as exc:
            if exc.errno not in UNSUPPORTED:
                raise
            self._software_roi(x, y, width, height)
            return
        got = lvd.get_selection(self._dev, capture, lvd.SelectionTarget.CROP)
        self._soft_roi = None
        fmt = self._read_format(self._fmt["name"])
        scaled = (fmt["width"], fmt["height"]) != (got.width, got.height)
        contains = (
            got.left <= want.left
            and got.top <= want.top
            and got.left + got.width >= want.left + width
            and got.top + got.height >= want.top + height
        )
        if tuple(got) == tuple(want) and not scaled:
            whole = tuple(got) == tuple(bounds)
            self._soft_roi, self._roi_kind = None, (None if whole else "hardware")
        elif contains and not scaled:  # the driver rounded the crop outwards: finish in software
            self._soft_roi = (want.left - got.left, want.top - got.top, width, height)
            self._roi_kind = "hardware"
        else:  # adjusted inwards or scaled: back to the full frame, crop in software
            default = lvd.get_selection(self._dev, capture, lvd.SelectionTarget.CROP_DEFAULT)
            lvd.set_selection(self._dev, capture, lvd.SelectionTarget.CROP, default)
            full = self._read_format(self._fmt["name"])
            if (full["width"], full["height"]) != (default.width, default.height):
                raise CameraError(
                    f"{self.name}: the driver scales its {default.width}x{default.height} sensor area to "
                    f"{full['width']}x{full['height']} frames, so a ROI in sensor pixels cannot be cut from them; "
                    "choose a frame size the driver delivers unscaled, or no ROI"
                )
            self._software_roi(x + bounds.left - default.left, y + bounds.top - default.top, width, height)

    def _software_roi(self, x, y, width, height):
        fmt = self._fmt
        if x < 0 or y < 0 or x + width > fmt["width"] or y + height > fmt["height"]:
            raise ValueError(f"{self.name}: {_off('frame', (x, y, width, height), fmt['width'], fmt['height'])}")
        full = (x, y, width, height) == (0, 0, fmt["width"], fmt["height"])
        self._soft_roi = None if full else (x, y, width, height)
        self._roi_kind = None if full else "software"


def _off(what, roi, width, height):
    """Why ``roi`` (x, y, width, height; pixels) is refused: it does not lie on the ``what`` of width x height
    pixels; in the rig file's order, as :func:`rsocl.hardware.capture_checks.check_rois` says it."""
    return (
        f"roi = {list(roi)} ([x, y, width, height]) must lie on the {width}x{height} (width x height) {what}: "
        f"x, y >= 0, x + width <= {width} and y + height <= {height}"
    )
