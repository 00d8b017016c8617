"""Aravis camera backend: GenICam cameras (GigE Vision, USB3 Vision) through Aravis 0.8.

Install: :mod:`~rsocl_plugins.aravis_discovery` (Aravis from the system, PyGObject from pip).

Rig-file configuration (the camera's ``[camera.config]`` table)::

    [[camera]]
    backend = "aravis"
    address = "192.168.1.20"   # Aravis device id ("Basler-21234567"), IP address, serial number or
                               # "Fake_1"; omitted: the first camera Aravis finds
    [camera.config]
    interfaces = ["GigEVision"]  # optional: enable only these Aravis interfaces ("GigEVision",
                                 # "USB3Vision", "Fake"), disable the others (see aravis_discovery);
                                 # a name this Aravis lacks is refused when the camera is made
    buffers = 8                  # stream buffers queued for the device, 1..256 (default 8)
    packet_size = 8192           # optional GigE Vision stream packet size, bytes (default: Aravis')

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

The rest of the backend, one module each: installing, importing and discovering Aravis
(:mod:`~rsocl_plugins.aravis_discovery`), pixel formats (:mod:`~rsocl_plugins.aravis_formats`),
exposure, ROI, pixel format, trigger and readout time (:mod:`~rsocl_plugins.aravis_settings`).
"""

from __future__ import annotations

import numbers
import time

from rsocl.common.validation import unknown_keys
from rsocl.hardware.backend import CameraBackend, CameraDisconnected, CameraError, CameraTimeout, Frame
from rsocl_plugins.aravis_discovery import aravis_interfaces, check_interfaces, import_aravis, select_interfaces
from rsocl_plugins.aravis_formats import BY_CODE, PIXEL_FORMATS, convert_buffer
from rsocl_plugins.aravis_settings import AravisSettings

__all__ = ["AravisCamera", "PIXEL_FORMATS"]

_CONFIG_KEYS = {"address", "interfaces", "buffers", "packet_size"}
_DEFAULT_BUFFERS = 8
#: Longest single wait for a frame, seconds: a read waits its timeout in slices this long, so that Ctrl-C
#: (which Python raises between them) and a lost camera end it within one slice, not after the whole timeout.
WAIT_SLICE = 0.1
_MAX_BUFFERS = 256


def _int(key, value, minimum, maximum):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not minimum <= value <= maximum:
        raise ValueError(f"{key} must be an integer in [{minimum}, {maximum}], got {value!r}")
    return int(value)


class AravisCamera(AravisSettings, CameraBackend):
    """One GenICam camera through Aravis (see the module docstring)."""

    backend = "aravis"
    pixel_formats = tuple(PIXEL_FORMATS)

    @classmethod
    def check_dependencies(cls) -> None:
        """Import PyGObject and Aravis 0.8's introspection data; a CameraError saying what to install."""
        import_aravis()

    def __init__(self, config=None, name=None):
        super().__init__(config, name)
        cfg = self.config
        unknown_keys(self.name, cfg, _CONFIG_KEYS)
        k = lambda key: f"{self.name}: config[{key!r}]"  # noqa: E731
        address = cfg.get("address")
        if address is not None and (not isinstance(address, str) or not address.strip()):
            raise ValueError(f"{k('address')} must be a device id, IP address or serial number string, got {address!r}")
        self.address = None if address is None else address.strip()
        known = None if cfg.get("interfaces") is None else aravis_interfaces()  # before any file: a wrong name
        self.interfaces = check_interfaces(k("interfaces"), cfg.get("interfaces"), known)
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
        return CameraDisconnected(
            f"{self.name}: the device is gone (Aravis lost control of it: cable, power or "
            "network; close and re-open it)"
        )

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
            lost_codes = {
                int(Aravis.DeviceError.NOT_CONNECTED),
                int(Aravis.DeviceError.TIMEOUT),
                int(Aravis.DeviceError.TRANSFER_ERROR),
            }
            if self._lost or (exc.domain == "arv-device-error-quark" and exc.code in lost_codes):
                self._lost = True  # Aravis already retried: the device is not answering any more
                raise CameraDisconnected(f"{self.name}: {what}: {exc.message} (device not answering)") from exc
            raise CameraError(f"{self.name}: {what}: {exc.message}") from exc

    # ------------------------------------------------------------------ lifecycle
    def _open_device(self):
        Aravis, GLib = import_aravis()
        self._aravis, self._glib = Aravis, GLib
        self._lost = False
        select_interfaces(Aravis, self.interfaces, self.name)
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
        for key, getter in (
            ("device_id", camera.get_device_id),
            ("vendor", camera.get_vendor_name),
            ("model", camera.get_model_name),
            ("serial", camera.get_device_serial_number),
        ):
            try:
                info[key] = getter()
            except GLib.Error:
                info[key] = None
        info["protocol"] = (
            "GigEVision" if camera.is_gv_device() else ("USB3Vision" if camera.is_uv_device() else "other")
        )
        self.device_info = info
        if self.packet_size is not None and not camera.is_gv_device():
            self._close_device()
            raise CameraError(
                f"{self.name}: config 'packet_size' applies to GigE Vision cameras only, "
                f"{info['device_id']} is {info['protocol']}"
            )

    def _target(self):
        return "the first camera found" if self.address is None else f"camera {self.address!r}"

    def _seen(self):
        try:
            Aravis = self._aravis
            Aravis.update_device_list()
            ids = [f"{Aravis.get_device_id(i)} ({Aravis.get_device_address(i)})" for i in range(Aravis.get_n_devices())]
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

    # ------------------------------------------------------------------ capture
    def _start(self):
        if self._stream is not None:
            return
        Aravis, camera = self._aravis, self._camera
        if self._has("AcquisitionMode") and "Continuous" in self._enum_values("AcquisitionMode"):
            self._call(
                "setting AcquisitionMode = Continuous",
                self._device.set_string_feature_value,
                "AcquisitionMode",
                "Continuous",
            )
        if self.packet_size is not None:
            self._call(f"setting the packet size to {self.packet_size}", camera.gv_set_packet_size, self.packet_size)
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
                self._exposure = (
                    float(
                        self._call(
                            "reading the exposure", self._device.get_float_feature_value, self._exposure_feature()
                        )
                    )
                    * 1e-6
                )
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
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            buffer = stream.timeout_pop_buffer(max(1, int(round(min(left, WAIT_SLICE) * 1e6))))
            if buffer is not None or left <= WAIT_SLICE or self._lost:
                break
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
            raise CameraError(
                f"{self.name}: frame {frame_id} failed: buffer status {status.value_nick} ({status.value_name})"
            )
        payload_type = buffer.get_payload_type()
        if payload_type not in (Aravis.BufferPayloadType.IMAGE, Aravis.BufferPayloadType.EXTENDED_CHUNK_DATA):
            raise CameraError(f"{self.name}: frame {frame_id} is not an image (payload type {payload_type.value_nick})")
        code = int(buffer.get_image_pixel_format())
        pixel_format = BY_CODE.get(code)
        if pixel_format is None:
            raise CameraError(
                f"{self.name}: frame {frame_id} has pixel format 0x{code:08x}, rsocl reads {list(PIXEL_FORMATS)}"
            )
        width, height = int(buffer.get_image_width()), int(buffer.get_image_height())
        x_padding, _ = buffer.get_image_padding()
        image = convert_buffer(buffer.get_image_data(), pixel_format, width, height, x_padding)
        device_ns = int(buffer.get_timestamp())
        system_ns = int(buffer.get_system_timestamp())
        host = system_ns * 1e-9 if system_ns > 0 else time.time()
        meta = {
            "frame_id": frame_id,
            "device_timestamp_ns": device_ns,
            "system_timestamp": host,
            "exposure": self._exposure,
            "roi": [int(buffer.get_image_x()), int(buffer.get_image_y()), width, height],
            "device_id": self.device_info.get("device_id"),
        }
        return Frame(
            image=image,
            timestamp=device_ns * 1e-9 if device_ns > 0 else host,
            pixel_format=pixel_format,
            bit_depth=PIXEL_FORMATS[pixel_format][2],
            meta=meta,
        )
