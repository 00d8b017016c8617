"""Exposure, ROI, pixel format, trigger and readout time of an ``aravis`` camera, as GenICam features.

Exposure
    ``ExposureTime`` (SFNC), else ``ExposureTimeAbs`` (older GigE cameras), both in µs;
    ``ExposureAuto`` is switched ``Off`` first when the device has it. A request outside the
    feature's bounds raises :class:`~rsocl.hardware.backend.CameraError` (with the bounds in seconds);
    the value read back is returned, in seconds (devices round to their own increments).

ROI
    ``OffsetX``/``OffsetY`` are zeroed, ``Width``/``Height`` set, then the offsets (so a
    shrink-and-move never exceeds the sensor on the way). Bounds and increments are checked
    first, and the region is read back: any difference raises
    :class:`~rsocl.hardware.backend.CameraError`. Change the ROI or the pixel format with acquisition
    stopped (the stream's buffers are sized at :meth:`start`). ``sensor_size``, once the camera is
    open: ``WidthMax``/``HeightMax``, else ``SensorWidth``/``SensorHeight``, else None.

Trigger
    ``"free"``: ``TriggerMode = Off`` for every ``TriggerSelector``. ``"software"`` and
    ``"line"``: every other selector off, then ``TriggerSelector = FrameStart``,
    ``TriggerMode = On``, ``TriggerSource = Software`` or the line given (``"Line1"``...,
    checked against the device's sources). ``trigger()`` executes ``TriggerSoftware``.

Readout time
    GenICam has no standard per-row readout feature. When the device has
    ``SensorReadoutTime`` (µs to read the current ROI, e.g. Basler), ``readout_time`` is that
    divided by ``Height``, in seconds per row; otherwise None.
"""

from __future__ import annotations

import contextlib
import math

from rsocl.hardware.backend import CameraError
from rsocl_plugins.aravis_formats import PIXEL_FORMATS

__all__ = ["AravisSettings"]


class AravisSettings:
    """Typed access to GenICam features and the camera hooks built on them (a mixin of the camera).

    The hooks ``_set_exposure``, ``_sensor_size``, ``_set_roi``, ``_set_pixel_format``, ``_set_trigger`` and
    ``_readout_time``. Uses the camera's open device (``_device``), its error translation
    (``_call``) and ``_stream`` (settings change only with acquisition stopped); sets
    ``_exposure`` (seconds).
    """

    # ------------------------------------------------------------------ features
    def _has(self, feature):
        return bool(self._call(f"looking up {feature}", self._device.is_feature_available, feature))

    def _enum_values(self, feature):
        return list(
            self._call(
                f"reading the values of {feature}",
                self._device.dup_available_enumeration_feature_values_as_strings,
                feature,
            )
            or []
        )

    def _set_enum(self, feature, value):
        values = self._enum_values(feature)
        if value not in values:
            raise CameraError(f"{self.name}: {feature} cannot be {value!r}; the device offers {values}")
        self._call(f"setting {feature} = {value}", self._device.set_string_feature_value, feature, value)

    def _get_int(self, feature):
        return int(self._call(f"reading {feature}", self._device.get_integer_feature_value, feature))

    def _set_int(self, feature, value):
        self._call(f"setting {feature} = {value}", self._device.set_integer_feature_value, feature, int(value))

    # ------------------------------------------------------------------ settings
    def _exposure_feature(self):
        for feature in ("ExposureTime", "ExposureTimeAbs"):
            if self._has(feature):
                return feature
        raise CameraError(f"{self.name}: the device has neither ExposureTime nor ExposureTimeAbs")

    def _set_exposure(self, seconds):
        feature = self._exposure_feature()
        if self._has("ExposureAuto") and "Off" in self._enum_values("ExposureAuto"):
            self._call("setting ExposureAuto = Off", self._device.set_string_feature_value, "ExposureAuto", "Off")
        lo, hi = self._call(f"reading the bounds of {feature}", self._device.get_float_feature_bounds, feature)
        us = seconds * 1e6
        if not (lo * (1 - 1e-9) <= us <= hi * (1 + 1e-9)):
            raise CameraError(
                f"{self.name}: exposure {seconds!r} s is outside the device's range "
                f"[{lo * 1e-6:.6g}, {hi * 1e-6:.6g}] s ({feature})"
            )
        us = min(max(us, lo), hi)
        self._call(f"setting {feature} = {us} us", self._device.set_float_feature_value, feature, us)
        actual = float(self._call(f"reading {feature}", self._device.get_float_feature_value, feature)) * 1e-6
        self._exposure = actual
        return actual

    def _sensor_size(self):
        if self._device is None:  # known once open
            return None
        for features in (("WidthMax", "HeightMax"), ("SensorWidth", "SensorHeight")):
            if all(self._has(f) for f in features):
                return tuple(self._get_int(f) for f in features)
        return None

    def _set_roi(self, x, y, width, height):
        if self._stream is not None:
            raise CameraError(f"{self.name}: stop acquisition before changing the ROI")
        for feature in ("Width", "Height"):
            if not self._has(feature):
                raise CameraError(f"{self.name}: the device has no {feature} feature")
        offsets = self._has("OffsetX") and self._has("OffsetY")
        if (x or y) and not offsets:
            raise CameraError(f"{self.name}: the device has no OffsetX/OffsetY, the ROI must start at (0, 0)")
        sizes = [(f, self._get_int(f)) for f in ("Width", "Height")]
        origin = [(f, self._get_int(f)) for f in ("OffsetX", "OffsetY")] if offsets else []
        try:
            self._write_roi(x, y, width, height, offsets)
        except CameraError:  # the ROI refused: the device back at its earlier one (offsets 0 first: they bound it)
            with contextlib.suppress(CameraError):
                for feature, value in [(f, 0) for f, _ in origin] + sizes + origin:
                    self._set_int(feature, value)
            raise

    def _write_roi(self, x, y, width, height, offsets):
        if offsets:
            self._set_int("OffsetX", 0)
            self._set_int("OffsetY", 0)
        for feature, value in (("Width", width), ("Height", height)) + (
            (("OffsetX", x), ("OffsetY", y)) if offsets else ()
        ):
            lo, hi = self._call(f"reading the bounds of {feature}", self._device.get_integer_feature_bounds, feature)
            step = (
                self._call(f"reading the increment of {feature}", self._device.get_integer_feature_increment, feature)
                or 1
            )
            if not lo <= value <= hi:
                raise CameraError(
                    f"{self.name}: ROI {feature} = {value} is outside the device's range [{lo}, {hi}] "
                    f"(ROI {x}, {y}, {width}, {height})"
                )
            if (value - lo) % step:
                raise CameraError(
                    f"{self.name}: ROI {feature} = {value} is not a multiple of the device's "
                    f"increment {step} (from {lo})"
                )
            self._set_int(feature, value)
        got = tuple(
            self._get_int(f) if (f in ("Width", "Height") or offsets) else 0
            for f in ("OffsetX", "OffsetY", "Width", "Height")
        )
        if got != (x, y, width, height):
            raise CameraError(f"{self.name}: the device set the ROI to {list(got)} instead of {[x, y, width, height]}")

    def _set_pixel_format(self, pixel_format):
        if self._stream is not None:
            raise CameraError(f"{self.name}: stop acquisition before changing the pixel format")
        values = self._enum_values("PixelFormat")
        if pixel_format not in values:
            raise CameraError(
                f"{self.name}: the device has no pixel format {pixel_format!r}; it offers {values} "
                f"(rsocl reads {list(PIXEL_FORMATS)})"
            )
        self._call(
            f"setting PixelFormat = {pixel_format}", self._device.set_string_feature_value, "PixelFormat", pixel_format
        )

    def _set_trigger(self, mode, source):
        for feature in ("TriggerMode",) + (("TriggerSource",) if mode != "free" else ()):
            if not self._has(feature):
                raise CameraError(f"{self.name}: the device has no {feature} feature (trigger mode {mode!r})")
        selectors = self._enum_values("TriggerSelector") if self._has("TriggerSelector") else []
        if mode != "free" and selectors and "FrameStart" not in selectors:
            raise CameraError(f"{self.name}: the device has no TriggerSelector FrameStart (it has {selectors})")
        if mode == "software" and not self._has("TriggerSoftware"):
            raise CameraError(f"{self.name}: the device has no TriggerSoftware command")
        wanted = {"software": "Software", "line": source}.get(mode)
        sources = self._enum_values("TriggerSource") if wanted is not None else []
        if wanted is not None and wanted not in sources:  # before any setting changes
            raise CameraError(f"{self.name}: TriggerSource cannot be {wanted!r}; the device offers {sources}")
        if not selectors:  # the one trigger off
            self._set_enum("TriggerMode", "Off")
        for selector in selectors:  # every trigger off first (AcquisitionStart, FrameBurstStart, ...)
            self._call(
                f"setting TriggerSelector = {selector}",
                self._device.set_string_feature_value,
                "TriggerSelector",
                selector,
            )
            self._call(
                f"setting TriggerMode = Off ({selector})", self._device.set_string_feature_value, "TriggerMode", "Off"
            )
        if mode == "free":
            if "FrameStart" in selectors:
                self._set_enum("TriggerSelector", "FrameStart")
            return
        if selectors:
            self._set_enum("TriggerSelector", "FrameStart")
        self._set_enum("TriggerMode", "On")
        self._set_enum("TriggerSource", "Software" if mode == "software" else source)

    def _readout_time(self):
        if not self._has("SensorReadoutTime"):
            return None
        us = float(self._call("reading SensorReadoutTime", self._device.get_float_feature_value, "SensorReadoutTime"))
        rows = self._get_int("Height")
        if not (math.isfinite(us) and us > 0 and rows > 0):
            return None
        return us * 1e-6 / rows
