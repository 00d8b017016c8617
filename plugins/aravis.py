"""Aravis camera backend: GenICam cameras (GigE Vision, USB3 Vision) through Aravis 0.8.

Install
    Aravis and its GObject introspection data from the system, PyGObject from pip::

        apt-get install gir1.2-aravis-0.8                # Debian/Ubuntu; aravis-tools has the fake GigE camera
        apt-get install libgirepository1.0-dev libcairo2-dev pkg-config gcc python3-dev   # to build PyGObject
        pip install "rsocl[aravis]"                      # PyGObject<3.51 (built from source: no wheels)

    ``gi`` is imported when a camera is opened, so listing plugins never needs it.

Rig-file configuration (the camera's ``[camera.config]`` table)::

    [[camera]]
    backend = "aravis"
    address = "192.168.1.20"   # Aravis device id ("Basler-21234567"), IP address, serial number or
                               # "Fake_1"; omitted: the first camera Aravis finds
    [camera.config]
    interfaces = ["GigEVision"]  # optional: enable only these Aravis interfaces ("GigEVision",
                                 # "USB3Vision", "Fake"), disable the others (see Discovery)
    buffers = 8                  # stream buffers queued for the device, 1..256 (default 8)
    packet_size = 8192           # optional GigE Vision stream packet size, bytes (default: Aravis')

Pixel formats
    ``Mono8`` -> uint8 (``bit_depth`` 8); ``Mono12`` (unpacked, 12 bits in 16) and ``Mono16`` ->
    uint16 (``bit_depth`` 12 / 16; the GenICam layout is little endian, converted to native
    order). Row padding reported by the buffer is removed. Packed formats (``Mono12p``,
    ``Mono12Packed``) and colour formats are not read. ``set_pixel_format`` raises
    :class:`~rsocl.hardware.backend.CameraError` listing the device's formats when it lacks the one asked.

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
    stopped (the stream's buffers are sized at :meth:`start`).

Trigger
    ``"free"``: ``TriggerMode = Off`` for every ``TriggerSelector``. ``"software"`` and
    ``"line"``: every other selector off, then ``TriggerSelector = FrameStart``,
    ``TriggerMode = On``, ``TriggerSource = Software`` or the line given (``"Line1"``...,
    checked against the device's sources). ``trigger()`` executes ``TriggerSoftware``.

Readout time
    GenICam has no standard per-row readout feature. When the device has
    ``SensorReadoutTime`` (µs to read the current ROI, e.g. Basler), ``readout_time`` is that
    divided by ``Height``, in seconds per row; otherwise None.

Frames and timestamps
    :meth:`start` creates the stream, queues ``buffers`` buffers of the device's payload size
    and starts acquisition (``AcquisitionMode = Continuous``). :meth:`read` pops the next
    buffer with ``timeout_pop_buffer``, copies the image out and gives the buffer back to
    the stream. ``frame.timestamp`` is the buffer's device timestamp (Aravis gives it in ns;
    seconds here), or the host's reception time when the device gives none.
    ``frame.meta``: ``frame_id``, ``device_timestamp_ns``, ``system_timestamp`` (host
    reception time, s since the epoch), ``exposure`` (s, as last set or read), ``roi``
    (``[x, y, width, height]`` of the buffer), ``device_id``.

Errors
    No buffer in time -> :class:`~rsocl.hardware.backend.CameraTimeout`. A buffer whose status is not
    ``SUCCESS`` (``missing-packets``, ``timeout``, ``size-mismatch``...) is given back to
    the stream and raises :class:`~rsocl.hardware.backend.CameraError` naming the status. The device's
    ``control-lost`` signal (GigE heartbeat failed: cable, power, process gone), and Aravis
    errors ``NOT_CONNECTED``/``TIMEOUT``/``TRANSFER_ERROR`` on register access, raise
    :class:`~rsocl.hardware.backend.CameraDisconnected` (then and for every later call; ``close()``
    still works). Other Aravis errors are :class:`~rsocl.hardware.backend.CameraError` with Aravis'
    message.

Discovery
    Opening a camera makes Aravis discover devices on every enabled interface: the GigE
    Vision interface *broadcasts* discovery packets on every network interface of the host.
    ``interfaces`` restricts that (Aravis' interface switches are process-wide: cameras of
    one process should agree). :func:`discover` lists the devices Aravis sees.
"""

from __future__ import annotations

import math
import numbers
import time

import numpy as np

from rsocl.hardware.backend import CameraBackend, CameraDisconnected, CameraError, CameraTimeout, Frame

__all__ = ["AravisCamera", "PIXEL_FORMATS", "convert_buffer", "discover", "import_aravis"]

#: name -> (GenICam PFNC code, numpy dtype of the buffer, significant bits)
PIXEL_FORMATS = {
    "Mono8": (0x01080001, "u1", 8),
    "Mono12": (0x01100005, "<u2", 12),
    "Mono16": (0x01100007, "<u2", 16),
}
_BY_CODE = {code: name for name, (code, _, _) in PIXEL_FORMATS.items()}

_CONFIG_KEYS = {"address", "interfaces", "buffers", "packet_size"}
_DEFAULT_BUFFERS = 8
_MAX_BUFFERS = 256

INSTALL_HINT = ("install Aravis' introspection data with 'apt-get install gir1.2-aravis-0.8' and PyGObject with "
                "'pip install \"rsocl[aravis]\"' (PyGObject<3.51, built from source: it needs "
                "'apt-get install libgirepository1.0-dev libcairo2-dev pkg-config gcc python3-dev')")


def import_aravis():
    """``(Aravis, GLib)`` from ``gi.repository``; :class:`CameraError` saying what to install when missing."""
    try:
        import gi
    except ImportError as exc:
        raise CameraError(f"the aravis camera backend needs PyGObject (module 'gi'): {INSTALL_HINT}") from exc
    try:
        gi.require_version("Aravis", "0.8")
        from gi.repository import Aravis, GLib
    except (ImportError, ValueError) as exc:
        raise CameraError(f"the aravis camera backend needs Aravis 0.8 for GObject introspection ({exc}): "
                          f"{INSTALL_HINT}") from exc
    return Aravis, GLib


def _select_interfaces(Aravis, interfaces, who="aravis"):
    """Enable exactly ``interfaces`` (a list of Aravis interface ids), disable the others."""
    if interfaces is None:
        return
    known = [Aravis.get_interface_id(i) for i in range(Aravis.get_n_interfaces())]
    unknown = sorted(set(interfaces) - set(known))
    if unknown:
        raise CameraError(f"{who}: unknown Aravis interface(s) {unknown}; this Aravis has {known}")
    for name in known:
        if name in interfaces:
            Aravis.enable_interface(name)
        else:
            Aravis.disable_interface(name)


def discover(interfaces=None) -> list:
    """Devices Aravis finds: ``[{"id", "address", "protocol", "serial", "vendor", "model", "physical_id"}]``.

    This runs Aravis' discovery: on the GigE Vision interface that is a **broadcast on every
    network interface of the host**. ``interfaces`` (e.g. ``["Fake"]``) enables only those
    Aravis interfaces first (process-wide).
    """
    Aravis, _ = import_aravis()
    _select_interfaces(Aravis, _check_interfaces("interfaces", interfaces))
    Aravis.update_device_list()
    out = []
    for i in range(Aravis.get_n_devices()):
        out.append({"id": Aravis.get_device_id(i), "address": Aravis.get_device_address(i),
                    "protocol": Aravis.get_device_protocol(i), "serial": Aravis.get_device_serial_nbr(i),
                    "vendor": Aravis.get_device_vendor(i), "model": Aravis.get_device_model(i),
                    "physical_id": Aravis.get_device_physical_id(i)})
    return out


def convert_buffer(data, pixel_format: str, width: int, height: int, x_padding: int = 0) -> np.ndarray:
    """Image bytes of a GenICam buffer -> 2-D array (``Mono8`` uint8, ``Mono12``/``Mono16`` native uint16).

    ``x_padding`` is the number of bytes after each row. Always returns a new, writable array.
    """
    if pixel_format not in PIXEL_FORMATS:
        raise CameraError(f"pixel format {pixel_format!r} is not supported; use one of {list(PIXEL_FORMATS)}")
    _, dtype, _ = PIXEL_FORMATS[pixel_format]
    dtype = np.dtype(dtype)
    width, height, x_padding = int(width), int(height), int(x_padding)
    row = width * dtype.itemsize
    stride = row + max(x_padding, 0)
    need = stride * (height - 1) + row if height > 0 else 0
    raw = np.frombuffer(data, dtype=np.uint8)
    if width < 1 or height < 1 or raw.size < need:
        raise CameraError(f"{pixel_format} buffer of {raw.size} bytes is too small for {width}x{height} pixels "
                          f"(row padding {x_padding} bytes; needs {need})")
    rows = np.lib.stride_tricks.as_strided(raw, shape=(height, row), strides=(stride, 1))
    return np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("="), copy=True).reshape(height, width)


def _check_interfaces(key, value):
    if value is None:
        return None
    if isinstance(value, str) or not isinstance(value, (list, tuple)) or not value \
            or not all(isinstance(v, str) and v for v in value):
        raise ValueError(f"{key} must be a non-empty list of Aravis interface names such as ['GigEVision'], "
                         f"got {value!r}")
    return list(value)


def _int(key, value, minimum, maximum):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not minimum <= value <= maximum:
        raise ValueError(f"{key} must be an integer in [{minimum}, {maximum}], got {value!r}")
    return int(value)


class AravisCamera(CameraBackend):
    """One GenICam camera through Aravis (see the module docstring)."""

    backend = "aravis"
    pixel_formats = tuple(PIXEL_FORMATS)

    def __init__(self, config=None, name=None):
        super().__init__(config, name)
        cfg = self.config
        unknown = sorted(set(cfg) - _CONFIG_KEYS)
        if unknown:
            raise ValueError(f"{self.name}: unknown config key(s) {unknown}; known: {sorted(_CONFIG_KEYS)}")
        k = lambda key: f"{self.name}: config[{key!r}]"  # noqa: E731
        address = cfg.get("address")
        if address is not None and (not isinstance(address, str) or not address.strip()):
            raise ValueError(f"{k('address')} must be a device id, IP address or serial number string, "
                             f"got {address!r}")
        self.address = None if address is None else address.strip()
        self.interfaces = _check_interfaces(k("interfaces"), cfg.get("interfaces"))
        self.buffers = _int(k("buffers"), cfg.get("buffers", _DEFAULT_BUFFERS), 1, _MAX_BUFFERS)
        packet = cfg.get("packet_size")
        self.packet_size = None if packet is None else _int(k("packet_size"), packet, 576, 65535)
        self._aravis = self._glib = None
        self._camera = self._device = self._stream = None
        self._lost_handler = None
        self._lost = False
        self._exposure = None
        self.device_info = {}

    # ------------------------------------------------------------------ errors
    def _gone(self):
        return CameraDisconnected(f"{self.name}: the device is gone (Aravis lost control of it: cable, power or "
                                  "network; close and re-open it)")

    def _call(self, what, fn, *args):
        """``fn(*args)``; Aravis errors become CameraError / CameraDisconnected naming ``what``."""
        if self._lost:
            raise self._gone()
        try:
            return fn(*args)
        except CameraError:
            raise
        except Exception as exc:
            GLib = self._glib
            if GLib is None or not isinstance(exc, GLib.Error):
                raise
            Aravis = self._aravis
            lost_codes = {int(Aravis.DeviceError.NOT_CONNECTED), int(Aravis.DeviceError.TIMEOUT),
                          int(Aravis.DeviceError.TRANSFER_ERROR)}
            if self._lost or (exc.domain == "arv-device-error-quark" and exc.code in lost_codes):
                self._lost = True  # Aravis already retried: the device is not answering any more
                raise CameraDisconnected(f"{self.name}: {what}: {exc.message} (device not answering)") from exc
            raise CameraError(f"{self.name}: {what}: {exc.message}") from exc

    def _has(self, feature):
        return bool(self._call(f"looking up {feature}", self._device.is_feature_available, feature))

    def _enum_values(self, feature):
        return list(self._call(f"reading the values of {feature}",
                               self._device.dup_available_enumeration_feature_values_as_strings, feature) or [])

    def _set_enum(self, feature, value):
        values = self._enum_values(feature)
        if value not in values:
            raise CameraError(f"{self.name}: {feature} cannot be {value!r}; the device offers {values}")
        self._call(f"setting {feature} = {value}", self._device.set_string_feature_value, feature, value)

    def _get_int(self, feature):
        return int(self._call(f"reading {feature}", self._device.get_integer_feature_value, feature))

    def _set_int(self, feature, value):
        self._call(f"setting {feature} = {value}", self._device.set_integer_feature_value, feature, int(value))

    # ------------------------------------------------------------------ lifecycle
    def _open_device(self):
        Aravis, GLib = import_aravis()
        self._aravis, self._glib = Aravis, GLib
        self._lost = False
        _select_interfaces(Aravis, self.interfaces, self.name)
        try:
            camera = Aravis.Camera.new(self.address)
        except GLib.Error as exc:
            raise CameraError(f"{self.name}: cannot open {self._target()}: {exc.message}{self._seen()}") from exc
        if camera is None:
            raise CameraError(f"{self.name}: cannot open {self._target()}{self._seen()}")
        self._camera = camera
        self._device = camera.get_device()
        self._lost_handler = self._device.connect("control-lost", self._on_control_lost)
        info = {}
        for key, getter in (("device_id", camera.get_device_id), ("vendor", camera.get_vendor_name),
                            ("model", camera.get_model_name), ("serial", camera.get_device_serial_number)):
            try:
                info[key] = getter()
            except GLib.Error:
                info[key] = None
        info["protocol"] = "GigEVision" if camera.is_gv_device() else ("USB3Vision" if camera.is_uv_device()
                                                                       else "other")
        self.device_info = info
        if self.packet_size is not None and not camera.is_gv_device():
            self._close_device()
            raise CameraError(f"{self.name}: config 'packet_size' applies to GigE Vision cameras only, "
                              f"{info['device_id']} is {info['protocol']}")

    def _target(self):
        return "the first camera found" if self.address is None else f"camera {self.address!r}"

    def _seen(self):
        try:
            Aravis = self._aravis
            Aravis.update_device_list()
            ids = [f"{Aravis.get_device_id(i)} ({Aravis.get_device_address(i)})"
                   for i in range(Aravis.get_n_devices())]
        except Exception:  # only a hint
            return ""
        enabled = "" if self.interfaces is None else f" on interfaces {self.interfaces}"
        return f"; Aravis sees {ids or 'no camera'}{enabled}"

    def _on_control_lost(self, *_):
        # Called from Aravis' heartbeat thread: only set a flag.
        self._lost = True

    def _close_device(self):
        try:
            if self._stream is not None:
                try:
                    self._stop()
                except CameraError:
                    pass
        finally:
            if self._device is not None and self._lost_handler is not None:
                try:
                    self._device.disconnect(self._lost_handler)
                except Exception:  # already gone
                    pass
            self._stream = None
            self._lost_handler = None
            self._device = None
            self._camera = None

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
            raise CameraError(f"{self.name}: exposure {seconds!r} s is outside the device's range "
                              f"[{lo * 1e-6:.6g}, {hi * 1e-6:.6g}] s ({feature})")
        us = min(max(us, lo), hi)
        self._call(f"setting {feature} = {us} us", self._device.set_float_feature_value, feature, us)
        actual = float(self._call(f"reading {feature}", self._device.get_float_feature_value, feature)) * 1e-6
        self._exposure = actual
        return actual

    def _set_roi(self, x, y, width, height):
        if self._stream is not None:
            raise CameraError(f"{self.name}: stop acquisition before changing the ROI")
        for feature in ("Width", "Height"):
            if not self._has(feature):
                raise CameraError(f"{self.name}: the device has no {feature} feature")
        offsets = self._has("OffsetX") and self._has("OffsetY")
        if (x or y) and not offsets:
            raise CameraError(f"{self.name}: the device has no OffsetX/OffsetY, the ROI must start at (0, 0)")
        if offsets:
            self._set_int("OffsetX", 0)
            self._set_int("OffsetY", 0)
        for feature, value in (("Width", width), ("Height", height)) + ((("OffsetX", x), ("OffsetY", y))
                                                                        if offsets else ()):
            lo, hi = self._call(f"reading the bounds of {feature}", self._device.get_integer_feature_bounds,
                                feature)
            step = self._call(f"reading the increment of {feature}", self._device.get_integer_feature_increment,
                              feature) or 1
            if not lo <= value <= hi:
                raise CameraError(f"{self.name}: ROI {feature} = {value} is outside the device's range [{lo}, {hi}] "
                                  f"(ROI {x}, {y}, {width}, {height})")
            if (value - lo) % step:
                raise CameraError(f"{self.name}: ROI {feature} = {value} is not a multiple of the device's "
                                  f"increment {step} (from {lo})")
            self._set_int(feature, value)
        got = tuple(self._get_int(f) if (f in ("Width", "Height") or offsets) else 0
                    for f in ("OffsetX", "OffsetY", "Width", "Height"))
        if got != (x, y, width, height):
            raise CameraError(f"{self.name}: the device set the ROI to {list(got)} instead of "
                              f"{[x, y, width, height]}")

    def _set_pixel_format(self, pixel_format):
        if self._stream is not None:
            raise CameraError(f"{self.name}: stop acquisition before changing the pixel format")
        values = self._enum_values("PixelFormat")
        if pixel_format not in values:
            raise CameraError(f"{self.name}: the device has no pixel format {pixel_format!r}; it offers {values} "
                              f"(rsocl reads {list(PIXEL_FORMATS)})")
        self._call(f"setting PixelFormat = {pixel_format}", self._device.set_string_feature_value, "PixelFormat",
                   pixel_format)

    def _set_trigger(self, mode, source):
        for feature in ("TriggerMode",) + (("TriggerSource",) if mode != "free" else ()):
            if not self._has(feature):
                raise CameraError(f"{self.name}: the device has no {feature} feature (trigger mode {mode!r})")
        selectors = self._enum_values("TriggerSelector") if self._has("TriggerSelector") else []
        if mode != "free" and selectors and "FrameStart" not in selectors:
            raise CameraError(f"{self.name}: the device has no TriggerSelector FrameStart (it has {selectors})")
        for selector in selectors:  # every trigger off first (AcquisitionStart, FrameBurstStart, ...)
            self._call(f"setting TriggerSelector = {selector}", self._device.set_string_feature_value,
                       "TriggerSelector", selector)
            self._call(f"setting TriggerMode = Off ({selector})", self._device.set_string_feature_value,
                       "TriggerMode", "Off")
        if mode == "free":
            if "FrameStart" in selectors:
                self._set_enum("TriggerSelector", "FrameStart")
            return
        if mode == "software" and not self._has("TriggerSoftware"):
            raise CameraError(f"{self.name}: the device has no TriggerSoftware command")
        if selectors:
            self._set_enum("TriggerSelector", "FrameStart")
        self._set_enum("TriggerMode", "On")
        self._set_enum("TriggerSource", "Software" if mode == "software" else source)

    def _readout_time(self):
        if not self._has("SensorReadoutTime"):
            return None
        us = float(self._call("reading SensorReadoutTime", self._device.get_float_feature_value,
                              "SensorReadoutTime"))
        rows = self._get_int("Height")
        if not (math.isfinite(us) and us > 0 and rows > 0):
            return None
        return us * 1e-6 / rows

    # ------------------------------------------------------------------ capture
    def _start(self):
        if self._stream is not None:
            return
        Aravis, camera = self._aravis, self._camera
        if self._has("AcquisitionMode") and "Continuous" in self._enum_values("AcquisitionMode"):
            self._call("setting AcquisitionMode = Continuous", self._device.set_string_feature_value,
                       "AcquisitionMode", "Continuous")
        if self.packet_size is not None:
            self._call(f"setting the packet size to {self.packet_size}", camera.gv_set_packet_size,
                       self.packet_size)
        payload = int(self._call("reading the payload size", camera.get_payload))
        if payload <= 0:
            raise CameraError(f"{self.name}: the device reports a payload of {payload} bytes")
        stream = self._call("creating the stream", camera.create_stream, None, None)
        if stream is None:
            raise CameraError(f"{self.name}: Aravis could not create a stream")
        for _ in range(self.buffers):
            stream.push_buffer(Aravis.Buffer.new_allocate(payload))
        self._stream = stream
        try:
            self._call("starting acquisition", camera.start_acquisition)
        except CameraError:
            self._stream = None
            raise
        if self._exposure is None:
            try:
                self._exposure = float(self._call("reading the exposure", self._device.get_float_feature_value,
                                                  self._exposure_feature())) * 1e-6
            except CameraError:
                pass

    def _stop(self):
        if self._stream is None:
            return
        try:
            if not self._lost:
                self._call("stopping acquisition", self._camera.stop_acquisition)
        finally:
            self._stream = None  # dropping the last reference stops the stream thread

    def _trigger(self):
        self._call("TriggerSoftware", self._device.execute_command, "TriggerSoftware")

    def _read(self, timeout):
        if self._lost:
            raise self._gone()
        if self._stream is None:
            raise CameraError(f"{self.name}: acquisition not started (call start() first)")
        stream = self._stream
        buffer = stream.timeout_pop_buffer(max(1, int(round(timeout * 1e6))))
        if buffer is None:
            if self._lost:
                raise self._gone()
            raise CameraTimeout(f"{self.name}: no frame within {timeout:g} s")
        try:
            return self._frame(buffer)
        finally:
            stream.push_buffer(buffer)

    def _frame(self, buffer):
        Aravis = self._aravis
        status = buffer.get_status()
        frame_id = int(buffer.get_frame_id())
        if status != Aravis.BufferStatus.SUCCESS:
            raise CameraError(f"{self.name}: frame {frame_id} failed: buffer status {status.value_nick} "
                              f"({status.value_name})")
        payload_type = buffer.get_payload_type()
        if payload_type not in (Aravis.BufferPayloadType.IMAGE, Aravis.BufferPayloadType.EXTENDED_CHUNK_DATA):
            raise CameraError(f"{self.name}: frame {frame_id} is not an image (payload type "
                              f"{payload_type.value_nick})")
        code = int(buffer.get_image_pixel_format())
        pixel_format = _BY_CODE.get(code)
        if pixel_format is None:
            raise CameraError(f"{self.name}: frame {frame_id} has pixel format 0x{code:08x}, rsocl reads "
                              f"{list(PIXEL_FORMATS)}")
        width, height = int(buffer.get_image_width()), int(buffer.get_image_height())
        x_padding, _ = buffer.get_image_padding()
        image = convert_buffer(buffer.get_image_data(), pixel_format, width, height, x_padding)
        device_ns = int(buffer.get_timestamp())
        system_ns = int(buffer.get_system_timestamp())
        host = system_ns * 1e-9 if system_ns > 0 else time.time()
        meta = {"frame_id": frame_id, "device_timestamp_ns": device_ns, "system_timestamp": host,
                "exposure": self._exposure,
                "roi": [int(buffer.get_image_x()), int(buffer.get_image_y()), width, height],
                "device_id": self.device_info.get("device_id")}
        return Frame(image=image, timestamp=device_ns * 1e-9 if device_ns > 0 else host,
                     pixel_format=pixel_format, bit_depth=PIXEL_FORMATS[pixel_format][2], meta=meta)
