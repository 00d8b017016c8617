"""V4L2 camera backend: webcams and other ``/dev/video*`` capture nodes, through linuxpy.

Install with ``pip install "rsocl[v4l2]"`` (Linux only; linuxpy is imported when a
camera is opened, so listing plugins never needs it).

Rig-file configuration (the camera's TOML table)::

    [[cameras]]
    backend = "v4l2"
    device = "/dev/video0"     # a path, or an index: 0 -> /dev/video0 (default 0)
    pixel_format = "GREY"      # "GREY", "Y16" or "YUYV" (default: the first of these the device offers)
    buffers = 4                # mmap buffers queued in the driver, 1..32 (default 4)
    width = 640                # optional requested frame size; the driver picks the nearest it has
    height = 480

Pixel formats
    ``GREY`` -> uint8; ``Y16`` -> uint16 (the V4L2 layout is little endian, converted to
    native order; ``bit_depth`` 16); ``YUYV`` -> the Y (luma) channel only, uint8 — the
    chroma bytes are dropped. Line padding (``bytesperline > width * bytes_per_pixel``)
    is removed. Compressed formats (MJPG, H264) are not read.

Exposure
    ``set_exposure(seconds)`` sets ``auto_exposure`` to manual (when the device has that
    control), then ``exposure_time_absolute`` in its units of 100 µs: the value is rounded
    to the nearest unit, clamped to the control's minimum/maximum and snapped to its step.
    The value read back from the device is returned, in seconds (so a request outside the
    device's range returns the clamped value, never the request).

ROI
    Coordinates are sensor pixels. When the driver implements the selection API
    (``VIDIOC_S_SELECTION``, target CROP) the crop is done in hardware; if the driver
    adjusts the rectangle to a larger one that still contains the request, the rest is
    cropped in software. Drivers without it (most UVC webcams) get a software crop: the
    full frame is transferred and ``read`` returns the requested region (no frame-rate
    gain). ``frame.meta["roi"]`` says which (``"hardware"`` / ``"software"`` / ``None``).
    Changing the ROI or the pixel format needs acquisition stopped.

Trigger
    V4L2 webcams are free-running: they have no trigger input. ``"free"`` reads the
    oldest frame the driver has completed (up to ``buffers`` frames old). ``"software"``
    emulates a trigger: ``trigger()`` throws away the frames already completed and
    ``read`` returns the next frame that completes after the call (and, when the driver
    timestamps frames on the monotonic clock, whose timestamp is not earlier than the
    call). Latency caveat: that is *not* a synchronised exposure start — the frame
    returned may have started exposing before the call, and the delay between the call
    and the frame varies between 0 and about two frame periods, differently for each
    camera. For synchronised rolling-shutter capture use hardware-triggered cameras;
    ``"line"`` (hardware trigger) raises :class:`~rsocl.hardware.backend.CameraError`.

Timestamps
    ``frame.timestamp`` is the driver's buffer timestamp (seconds; for most drivers
    ``CLOCK_MONOTONIC``, i.e. ``time.monotonic()``; UVC stamps the start of the frame),
    or host ``time.time()`` when the driver gives none. ``frame.meta`` also holds
    ``sequence`` (driver frame counter), ``dropped`` (frames the driver skipped since the
    previous read, from sequence gaps), ``timestamp_clock``, ``timestamp_source``,
    ``host_time``, ``buffer_index``, ``exposure`` (seconds, last set value) and ``roi``.

Errors
    ``read`` waits with ``poll`` and raises :class:`~rsocl.hardware.backend.CameraTimeout` when no
    frame completes in time; a device that vanished (``ENODEV``/``ENXIO``, e.g. unplugged)
    raises :class:`~rsocl.hardware.backend.CameraDisconnected` (``close()`` still works; re-open to
    use it again); everything else is a :class:`~rsocl.hardware.backend.CameraError`. Frames the
    driver flags as corrupt (``V4L2_BUF_FLAG_ERROR``) or that are shorter than the format
    are skipped and counted in ``meta["skipped"]``.
"""

from __future__ import annotations

import errno
import functools
import math
import os
import select
import time

import numpy as np

from rsocl.hardware.backend import CameraBackend, CameraDisconnected, CameraError, CameraTimeout, Frame

__all__ = ["V4L2Camera", "EXPOSURE_UNIT", "PIXEL_FORMATS"]

#: name -> (bytes per pixel in the V4L2 buffer, significant bits of the returned image)
PIXEL_FORMATS = {"GREY": (1, 8), "Y16": (2, 16), "YUYV": (2, 8)}

#: Unit of ``exposure_time_absolute`` (V4L2_CID_EXPOSURE_ABSOLUTE), seconds.
EXPOSURE_UNIT = 100e-6

_CID_EXPOSURE_AUTO = 0x009A0901  # V4L2_CID_EXPOSURE_AUTO, menu
_CID_EXPOSURE_ABSOLUTE = 0x009A0902  # V4L2_CID_EXPOSURE_ABSOLUTE, integer, 100 us units
_EXPOSURE_MANUAL = 1  # V4L2_EXPOSURE_MANUAL

_BUF_FLAG_ERROR = 0x40
_BUF_TIMESTAMP_MASK = 0xE000
_BUF_TIMESTAMP_CLOCKS = {0x0: "unknown", 0x2000: "monotonic", 0x4000: "copy"}
_BUF_TSTAMP_SRC_MASK = 0x70000
_BUF_TSTAMP_SOURCES = {0x0: "end-of-frame", 0x10000: "start-of-exposure"}

_GONE = {errno.ENODEV, errno.ENXIO}
_UNSUPPORTED = {errno.ENOTTY, errno.EINVAL, errno.ENODATA, errno.EOPNOTSUPP, errno.ENOSYS}
_MAX_BUFFERS = 32


def _device_path(device) -> str:
    """``0`` / ``"0"`` -> ``/dev/video0``; a path is kept as given."""
    if isinstance(device, bool) or device is None:
        raise ValueError(f"device must be a path like /dev/video0 or an index, got {device!r}")
    if isinstance(device, int):
        if device < 0:
            raise ValueError(f"device index must be >= 0, got {device}")
        return f"/dev/video{device}"
    text = os.fspath(device).strip() if not isinstance(device, str) else device.strip()
    if not text:
        raise ValueError("device must be a path like /dev/video0 or an index, got an empty string")
    if text.isdigit():
        return f"/dev/video{int(text)}"
    return text


def _os_errors(fn):
    """Translate OSError / linuxpy errors of a hook: ENODEV -> CameraDisconnected, rest -> CameraError."""

    @functools.wraps(fn)
    def hook(self, *args):
        try:
            return fn(self, *args)
        except CameraError:
            raise
        except OSError as exc:
            raise self._os_error(exc) from exc
        except Exception as exc:
            lvd = self._lvd
            if lvd is not None and isinstance(exc, lvd.V4L2Error):
                raise CameraError(f"{self.name}: {exc}") from exc
            raise

    return hook


def convert_frame(data, pixel_format: str, width: int, height: int, bytes_per_line: int = 0) -> np.ndarray:
    """Raw V4L2 buffer bytes -> 2-D image (``GREY``/``YUYV`` -> uint8, ``Y16`` -> uint16).

    ``YUYV`` gives the Y channel; ``Y16`` is read little endian; line padding is removed.
    ``data`` shorter than ``bytes_per_line * height`` is accepted as long as it holds the
    last line's pixels (drivers may omit the last line's padding).
    """
    bpp = PIXEL_FORMATS[pixel_format][0]
    bpl = int(bytes_per_line) or width * bpp
    if bpl < width * bpp:
        raise ValueError(f"bytes per line {bpl} < width {width} x {bpp} bytes")
    need = bpl * (height - 1) + width * bpp
    data = memoryview(data).cast("B")
    if len(data) < need:
        raise ValueError(f"{pixel_format} {width}x{height} frame needs {need} bytes, got {len(data)}")
    if len(data) < bpl * height:
        buf = np.zeros(bpl * height, np.uint8)
        buf[: len(data)] = np.frombuffer(data, np.uint8)
    else:
        buf = np.frombuffer(data, np.uint8, count=bpl * height)
    rows = buf.reshape(height, bpl)
    if pixel_format == "GREY":
        image = rows[:, :width]
    elif pixel_format == "YUYV":  # Y0 U0 Y1 V0 | Y2 U2 Y3 V2 ...: Y is every other byte
        image = rows[:, 0 : 2 * width : 2]
    else:  # Y16: two bytes per pixel, least significant first
        image = np.ascontiguousarray(rows[:, : 2 * width]).view("<u2").astype(np.uint16, copy=False)
    return np.array(image, dtype=image.dtype, order="C", copy=True)  # writeable, owns its memory


class V4L2Camera(CameraBackend):
    """A V4L2 capture device (webcam) read with mmap streaming I/O through linuxpy.

    Parameters
    ----------
    config : dict
        ``device`` (path or index, default 0), ``pixel_format`` (``GREY``/``Y16``/``YUYV``,
        default the first the device offers in that order), ``buffers`` (default 4),
        optional ``width`` / ``height``. See the module documentation for behaviour.
    name : str
        Name used in errors (default ``"v4l2 /dev/videoN"``).
    """

    backend = "v4l2"
    pixel_formats = tuple(PIXEL_FORMATS)

    def __init__(self, config: dict | None = None, name: str | None = None):
        super().__init__(config, name)
        self.path = _device_path(self.config.get("device", 0))
        if name is None:
            self.name = f"v4l2 {self.path}"
        buffers = self.config.get("buffers", 4)
        if isinstance(buffers, bool) or not isinstance(buffers, int) or not 1 <= buffers <= _MAX_BUFFERS:
            raise ValueError(f"{self.name}: buffers must be an integer in 1..{_MAX_BUFFERS}, got {buffers!r}")
        self.n_buffers = buffers
        pixel_format = self.config.get("pixel_format")
        if pixel_format is not None and pixel_format not in PIXEL_FORMATS:
            raise ValueError(f"{self.name}: pixel_format must be one of {list(PIXEL_FORMATS)}, got {pixel_format!r}")
        self._requested_format = pixel_format
        self._requested_size = []
        for key in ("width", "height"):
            value = self.config.get(key)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                raise ValueError(f"{self.name}: {key} must be a positive integer, got {value!r}")
            self._requested_size.append(value)
        self._lvd = None
        self._dev = None
        self._reset_state()

    def _reset_state(self):
        self.device_formats = ()  # pixel formats the device offers (names)
        self.driver = None
        self.card = None
        self._fmt = None  # dict: name, width, height, bpl, sizeimage
        self._maps = []
        self._streaming = False
        self._soft_roi = None  # (x, y, w, h) in the delivered image
        self._roi_kind = None
        self._exposure = None
        self._trigger_time = None
        self._last_sequence = None
        self._skipped = 0

    # ---------------------------------------------------------------- helpers
    def _os_error(self, exc: OSError) -> CameraError:
        if exc.errno in _GONE:
            return CameraDisconnected(f"{self.name}: the device went away ({os.strerror(exc.errno)}); "
                                      "check the cable, then close and open the camera again")
        reason = f"{os.strerror(exc.errno)} (errno {exc.errno})" if exc.errno else str(exc)
        if exc.errno == errno.EBUSY:
            reason += "; another program may be using the camera"
        return CameraError(f"{self.name}: {reason}")

    @property
    def pixel_format(self) -> str | None:
        """The pixel format in use (None before open)."""
        return self._fmt["name"] if self._fmt else None

    @property
    def frame_size(self) -> tuple | None:
        """``(width, height)`` the driver delivers (before a software ROI)."""
        return (self._fmt["width"], self._fmt["height"]) if self._fmt else None

    def _import_linuxpy(self):
        try:
            from linuxpy.video import device as lvd
        except (ImportError, OSError) as exc:
            raise CameraError(f"{self.name}: the v4l2 camera backend needs linuxpy (Linux only), which could not "
                              f"be imported ({type(exc).__name__}: {exc}); install it with: "
                              'pip install "rsocl[v4l2]"') from exc
        return lvd

    # ---------------------------------------------------------------- lifecycle
    @_os_errors
    def _open_device(self):
        lvd = self._import_linuxpy()
        self._lvd = lvd
        self._reset_state()
        dev = lvd.Device(self.path)
        try:
            dev.open()
        except FileNotFoundError as exc:
            raise CameraError(f"{self.name}: no such device {self.path} (is the camera plugged in? "
                              "`ls /dev/video*` or `v4l2-ctl --list-devices` lists them)") from exc
        except PermissionError as exc:
            raise CameraError(f"{self.name}: permission denied on {self.path} (add the user to the "
                              "'video' group)") from exc
        self._dev = dev
        try:
            self._probe()
        except BaseException:
            self._dev = None
            try:
                dev.close()
            except Exception:
                pass
            raise

    def _probe(self):
        lvd, dev = self._lvd, self._dev
        caps = lvd.Capability(dev.info.device_capabilities)
        self.driver, self.card = dev.info.driver, dev.info.card
        if lvd.Capability.VIDEO_CAPTURE not in caps:
            if lvd.Capability.VIDEO_CAPTURE_MPLANE in caps:
                raise CameraError(f"{self.name}: multi-planar capture devices are not supported")
            raise CameraError(f"{self.name}: {self.path} is not a video capture node (capabilities: {caps!r}); "
                              "webcams often also have a metadata node, try another /dev/video*")
        if lvd.Capability.STREAMING not in caps:
            raise CameraError(f"{self.name}: the device does not support streaming (mmap) I/O")
        offered = []
        for fmt in lvd.iter_read_formats(dev, lvd.BufferType.VIDEO_CAPTURE):
            name = getattr(fmt.pixel_format, "name", str(fmt.pixel_format))
            if name not in offered:
                offered.append(name)
        self.device_formats = tuple(offered)
        wanted = self._requested_format
        if wanted is None:
            usable = [name for name in PIXEL_FORMATS if name in offered]
            if not usable:
                raise CameraError(f"{self.name}: the device offers {offered or 'no formats'}, none of which this "
                                  f"backend reads ({list(PIXEL_FORMATS)})")
            wanted = usable[0]
        self._apply_format(wanted, *self._requested_size)

    def _close_device(self):
        dev = self._dev
        try:
            if self._streaming:
                try:
                    self._stop()
                except CameraError:  # a vanished device cannot stop; closing must still work
                    pass
        finally:
            self._release_buffers(None, free=False)
            self._streaming = False
            self._dev = None
            if dev is not None:
                try:
                    dev.close()
                except OSError:
                    pass

    # ---------------------------------------------------------------- format
    def _read_format(self, name=None):
        lvd = self._lvd
        fmt = lvd.get_raw_format(self._dev, lvd.BufferType.VIDEO_CAPTURE)
        pix = fmt.fmt.pix
        try:
            got = lvd.PixelFormat(pix.pixelformat).name
        except ValueError:
            got = f"0x{pix.pixelformat:08x}"
        if name is not None and got != name:
            raise CameraError(f"{self.name}: asked the driver for {name}, it chose {got} "
                              f"(the device offers {list(self.device_formats)})")
        if got not in PIXEL_FORMATS:
            raise CameraError(f"{self.name}: the driver delivers {got}, which this backend does not read")
        width, height = int(pix.width), int(pix.height)
        bpp = PIXEL_FORMATS[got][0]
        bpl = int(pix.bytesperline) or width * bpp
        if bpl < width * bpp or width < 1 or height < 1:
            raise CameraError(f"{self.name}: the driver reports an inconsistent {got} format "
                              f"{width}x{height}, {bpl} bytes per line")
        self._fmt = {"name": got, "width": width, "height": height, "bpl": bpl,
                     "sizeimage": int(pix.sizeimage) or bpl * height}
        if self._soft_roi is not None:
            x, y, w, h = self._soft_roi
            if x + w > width or y + h > height:
                self._soft_roi, self._roi_kind = None, None
        return self._fmt

    def _apply_format(self, name, width=None, height=None):
        lvd = self._lvd
        if self._streaming:
            raise CameraError(f"{self.name}: stop() acquisition before changing the pixel format")
        if name not in self.device_formats:
            raise CameraError(f"{self.name}: the device does not offer {name}; it offers {list(self.device_formats)}")
        current = lvd.get_raw_format(self._dev, lvd.BufferType.VIDEO_CAPTURE).fmt.pix
        width = width or int(current.width)
        height = height or int(current.height)
        lvd.set_format(self._dev, lvd.BufferType.VIDEO_CAPTURE, width, height, int(lvd.PixelFormat[name]))
        return self._read_format(name)

    @_os_errors
    def _set_pixel_format(self, pixel_format):
        self._apply_format(pixel_format)

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

    @_os_errors
    def _set_exposure(self, seconds):
        auto = self._control(_CID_EXPOSURE_AUTO, ("auto_exposure", "exposure_auto"))
        absolute = self._control(_CID_EXPOSURE_ABSOLUTE, ("exposure_time_absolute", "exposure_absolute"))
        if absolute is None:
            raise CameraError(f"{self.name}: the device has no exposure_time_absolute control, so its exposure "
                              "cannot be set in seconds")
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
        self._exposure = actual * EXPOSURE_UNIT
        return self._exposure

    # ---------------------------------------------------------------- ROI
    @_os_errors
    def _set_roi(self, x, y, width, height):
        if self._streaming:
            raise CameraError(f"{self.name}: stop() acquisition before changing the ROI")
        lvd = self._lvd
        capture = lvd.BufferType.VIDEO_CAPTURE
        try:
            bounds = lvd.get_selection(self._dev, capture, lvd.SelectionTarget.CROP_BOUNDS)
        except OSError as exc:
            if exc.errno not in _UNSUPPORTED:
                raise
            bounds = None
        if bounds is None:  # no selection API: crop in software
            self._software_roi(x, y, width, height)
            return
        if x + width > bounds.width or y + height > bounds.height:
            raise ValueError(f"{self.name}: ROI {width}x{height}+{x}+{y} exceeds the sensor "
                             f"{bounds.width}x{bounds.height}")
        want = lvd.Rect(bounds.left + x, bounds.top + y, width, height)
        try:
            lvd.set_selection(self._dev, capture, lvd.SelectionTarget.CROP, want)
        except OSError as exc:
            if exc.errno not in _UNSUPPORTED:
                raise
            self._software_roi(x, y, width, height)
            return
        got = lvd.get_selection(self._dev, capture, lvd.SelectionTarget.CROP)
        self._soft_roi = None
        fmt = self._read_format(self._fmt["name"])
        scaled = (fmt["width"], fmt["height"]) != (got.width, got.height)
        contains = (got.left <= want.left and got.top <= want.top
                    and got.left + got.width >= want.left + width and got.top + got.height >= want.top + height)
        if tuple(got) == tuple(want) and not scaled:
            whole = tuple(got) == tuple(bounds)
            self._soft_roi, self._roi_kind = None, (None if whole else "hardware")
        elif contains and not scaled:  # the driver rounded the crop outwards: finish in software
            self._soft_roi = (want.left - got.left, want.top - got.top, width, height)
            self._roi_kind = "hardware"
        else:  # adjusted inwards or scaled: back to the full frame, crop in software
            default = lvd.get_selection(self._dev, capture, lvd.SelectionTarget.CROP_DEFAULT)
            lvd.set_selection(self._dev, capture, lvd.SelectionTarget.CROP, default)
            self._read_format(self._fmt["name"])
            self._software_roi(x + bounds.left - default.left, y + bounds.top - default.top, width, height)

    def _software_roi(self, x, y, width, height):
        fmt = self._fmt
        if x < 0 or y < 0 or x + width > fmt["width"] or y + height > fmt["height"]:
            raise ValueError(f"{self.name}: ROI {width}x{height}+{x}+{y} exceeds the frame "
                             f"{fmt['width']}x{fmt['height']}")
        full = (x, y, width, height) == (0, 0, fmt["width"], fmt["height"])
        self._soft_roi = None if full else (x, y, width, height)
        self._roi_kind = None if full else "software"

    # ---------------------------------------------------------------- trigger
    def _set_trigger(self, mode, source):
        if mode == "line":
            raise CameraError(f"{self.name}: V4L2 webcams are free-running and have no hardware trigger input "
                              f"(asked for line trigger on {source!r}); use 'software' (next frame after the call) "
                              "or 'free'")
        self._trigger_time = None

    @_os_errors
    def _trigger(self):
        if not self._streaming:
            raise CameraError(f"{self.name}: start() acquisition before trigger()")
        self._trigger_time = time.monotonic()
        while True:  # throw away what the driver completed before the call
            buff = self._dequeue()
            if buff is None:
                break
            self._note_sequence(buff)
            self._requeue(buff.index)

    # ---------------------------------------------------------------- capture
    @_os_errors
    def _start(self):
        if self._streaming:
            return
        lvd, dev = self._lvd, self._dev
        capture, mmap_memory = lvd.BufferType.VIDEO_CAPTURE, lvd.Memory.MMAP
        self._read_format(self._fmt["name"])
        try:
            req = lvd.request_buffers(dev, capture, mmap_memory, self.n_buffers)
            fd = dev.fileno()
            for index in range(req.count):
                buff = lvd.query_buffer(dev, capture, mmap_memory, index)
                self._maps.append(lvd.mem_map(fd, buff.length, buff.m.offset))
            for index in range(req.count):
                lvd.enqueue_buffer(dev, capture, mmap_memory, 0, index)
            lvd.stream_on(dev, capture)
        except BaseException:
            self._release_buffers(dev, free=True)
            raise
        self._streaming = True
        self._last_sequence = None
        self._trigger_time = None

    @_os_errors
    def _stop(self):
        if not self._streaming and not self._maps:
            return
        lvd, dev = self._lvd, self._dev
        try:
            if self._streaming:
                lvd.stream_off(dev, lvd.BufferType.VIDEO_CAPTURE)
        finally:
            self._streaming = False
            self._release_buffers(dev, free=True)

    def _release_buffers(self, dev, free):
        maps, self._maps = self._maps, []
        for mm in maps:
            try:
                mm.close()
            except Exception:
                pass
        if free and maps and dev is not None:
            lvd = self._lvd
            lvd.free_buffers(dev, lvd.BufferType.VIDEO_CAPTURE, lvd.Memory.MMAP)

    def _dequeue(self):
        """DQBUF without blocking: the buffer, or None when no frame is ready (EAGAIN)."""
        lvd = self._lvd
        try:
            return lvd.dequeue_buffer(self._dev, lvd.BufferType.VIDEO_CAPTURE, lvd.Memory.MMAP)
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                return None
            raise

    def _requeue(self, index):
        lvd = self._lvd
        lvd.enqueue_buffer(self._dev, lvd.BufferType.VIDEO_CAPTURE, lvd.Memory.MMAP, 0, index)

    def _note_sequence(self, buff):
        seq = int(buff.sequence)
        dropped = 0 if self._last_sequence is None else max(0, seq - self._last_sequence - 1)
        self._last_sequence = seq
        return seq, dropped

    @_os_errors
    def _read(self, timeout):
        if not self._streaming:
            raise CameraError(f"{self.name}: not acquiring; call start() first")
        deadline = time.monotonic() + timeout
        poller = select.poll()
        poller.register(self._dev.fileno(), select.POLLIN)
        while True:
            buff = self._dequeue()
            if buff is not None:
                frame = self._frame_from(buff)
                if frame is not None:
                    return frame
                continue
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise CameraTimeout(f"{self.name}: no frame within {timeout:g} s (is the device streaming? "
                                    "a long exposure or a low frame rate needs a longer timeout)")
            events = poller.poll(max(1, int(math.ceil(remaining * 1000))))
            if events and not any(ev & select.POLLIN for _, ev in events):
                # POLLERR / POLLHUP: DQBUF tells why (ENODEV when the device vanished)
                buff = self._dequeue()
                if buff is None:
                    mask = events[0][1]
                    raise CameraError(f"{self.name}: poll reported an error (events 0x{mask:x}) and no frame")
                frame = self._frame_from(buff)
                if frame is not None:
                    return frame

    def _frame_from(self, buff):
        """Copy a dequeued buffer out, requeue it; None for a frame to skip."""
        host_time = time.time()
        index = int(buff.index)
        try:
            seq, dropped = self._note_sequence(buff)
            flags = int(buff.flags)
            stamp = int(buff.timestamp.secs) + int(buff.timestamp.usecs) * 1e-6
            clock = _BUF_TIMESTAMP_CLOCKS.get(flags & _BUF_TIMESTAMP_MASK, "unknown")
            if (self._trigger_mode == "software" and self._trigger_time is not None and clock == "monotonic"
                    and stamp > 0 and stamp < self._trigger_time):
                return None  # completed after trigger() but started before it
            fmt = self._fmt
            bpp = PIXEL_FORMATS[fmt["name"]][0]
            need = fmt["bpl"] * (fmt["height"] - 1) + fmt["width"] * bpp
            used = int(buff.bytesused)
            if flags & _BUF_FLAG_ERROR or used < need:
                self._skipped += 1
                return None
            data = self._maps[index][: min(used, fmt["bpl"] * fmt["height"])]
        finally:
            self._requeue(index)
        image = convert_frame(data, fmt["name"], fmt["width"], fmt["height"], fmt["bpl"])
        if self._soft_roi is not None:
            x, y, w, h = self._soft_roi
            image = np.ascontiguousarray(image[y : y + h, x : x + w])
        if stamp <= 0:
            stamp, clock = host_time, "host"
        if self._trigger_mode == "software":
            self._trigger_time = None  # one frame per trigger
        meta = {
            "sequence": seq,
            "dropped": dropped,
            "skipped": self._skipped,
            "buffer_index": index,
            "timestamp_clock": clock,
            "timestamp_source": _BUF_TSTAMP_SOURCES.get(flags & _BUF_TSTAMP_SRC_MASK, "unknown"),
            "host_time": host_time,
            "exposure": self._exposure,
            "roi": self._roi_kind,
            "device": self.path,
        }
        self._skipped = 0
        return Frame(image=image, timestamp=stamp, pixel_format=fmt["name"],
                     bit_depth=PIXEL_FORMATS[fmt["name"]][1], meta=meta)
