"""V4L2 camera backend: webcams and other ``/dev/video*`` capture nodes, through linuxpy.

Install with ``pip install "rsocl[v4l2]"`` (Linux only; linuxpy is imported when a
camera is opened, so listing plugins never needs it).

Configuration (the ``[camera.config]`` table of a ``backend = "v4l2"`` camera in a rig file)::

    [camera.config]
    device = "/dev/video0"     # a path, or an index: 0 -> /dev/video0 (default 0)
    address = "/dev/video0"    # the same forms; also the [[camera]] table's own ``address`` key.
                               # Give address or device, or both naming the same node
    pixel_format = "GREY"      # "GREY", "Y16", "Y12", "Y10" or "YUYV" (default: the first of these the
                               # device offers); Y10/Y12: 10/12-bit levels, one pixel per 16-bit word
    buffers = 4                # mmap buffers queued in the driver, 1..32 (default 4)
    width = 640                # optional requested frame size; the driver picks the nearest it has
    height = 480

A value out of range is refused with a ``ValueError`` that names the camera and its key as
``config['buffers']``, the aravis backend's form, and says what the key may be. Any other key
(a typo such as ``adress``) is refused with a ``ValueError`` that names it, suggests the closest
accepted key and lists them all.

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

The rest of the backend, one module each: pixel formats and their conversion
(:mod:`~rsocl_plugins.v4l2_formats`), exposure and ROI (:mod:`~rsocl_plugins.v4l2_controls`),
streaming, frames, timestamps and read errors (:mod:`~rsocl_plugins.v4l2_stream`), the device
node and its errors (:mod:`~rsocl_plugins.v4l2_device`).
"""

from __future__ import annotations

import time

from rsocl.common.validation import unknown_keys
from rsocl.hardware.backend import CameraBackend, CameraError
from rsocl_plugins.v4l2_controls import EXPOSURE_UNIT, V4L2Controls
from rsocl_plugins.v4l2_device import device_path, import_linuxpy, os_errors
from rsocl_plugins.v4l2_formats import PIXEL_FORMATS, packed_note
from rsocl_plugins.v4l2_stream import V4L2Stream

__all__ = ["V4L2Camera", "EXPOSURE_UNIT", "PIXEL_FORMATS"]

_MAX_BUFFERS = 32
#: The keys of a camera's config this backend reads; any other is refused.
_CONFIG_KEYS = ("device", "address", "pixel_format", "buffers", "width", "height")


class V4L2Camera(V4L2Controls, V4L2Stream, CameraBackend):
    """A V4L2 capture device (webcam) read with mmap streaming I/O through linuxpy.

    Parameters
    ----------
    config : dict
        ``device`` or ``address`` (path or index, default 0; a rig file camera's
        ``address`` arrives here as ``address``; both may be given only when they name
        the same node), ``pixel_format`` (``GREY``/``Y16``/``Y12``/``Y10``/``YUYV``, default
        the first the device offers in that order), ``buffers`` (default 4), optional ``width`` /
        ``height`` (pixels). See the module documentation for behaviour. Other keys are refused
        (``ValueError`` naming them).
    name : str
        Name used in errors (default ``"v4l2 /dev/videoN"``).

    Raises
    ------
    ValueError
        A config value out of range, or ``address`` and ``device`` naming different nodes: the message
        names the key as ``config['buffers']``.
    """

    backend = "v4l2"
    pixel_formats = tuple(PIXEL_FORMATS)

    @classmethod
    def check_dependencies(cls) -> None:
        """Import linuxpy's V4L2 module; a CameraError saying what to install."""
        import_linuxpy("v4l2")

    def __init__(self, config: dict | None = None, name: str | None = None):
        super().__init__(config, name)
        self.path = self._device_node()
        if name is None:
            self.name = f"v4l2 {self.path}"
        unknown_keys(self.name, self.config, _CONFIG_KEYS)
        k = self._key
        buffers = self.config.get("buffers", 4)
        if isinstance(buffers, bool) or not isinstance(buffers, int) or not 1 <= buffers <= _MAX_BUFFERS:
            raise ValueError(f"{k('buffers')} must be an integer in 1..{_MAX_BUFFERS}, got {buffers!r}")
        self.n_buffers = buffers
        pixel_format = self.config.get("pixel_format")
        if pixel_format is not None and (not isinstance(pixel_format, str) or pixel_format not in PIXEL_FORMATS):
            raise ValueError(
                f"{k('pixel_format')} must be one of {list(PIXEL_FORMATS)}, got {pixel_format!r}"
                + packed_note([pixel_format] if isinstance(pixel_format, str) else [])
            )
        self._requested_format = pixel_format
        self._requested_size = []
        for key in ("width", "height"):
            value = self.config.get(key)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                raise ValueError(f"{k(key)} must be a positive integer (pixels), got {value!r}")
            self._requested_size.append(value)
        self._lvd = None
        self._dev = None
        self._reset_state()

    def _key(self, key: str) -> str:
        """How messages name config key ``key``: ``"camera 0 (v4l2 /dev/video0): config['buffers']"``."""
        return f"{self.name}: config[{key!r}]"

    def _device_node(self) -> str:
        """The node ``address`` or ``device`` names (``/dev/video0`` when neither is given)."""
        given = {key: self.config[key] for key in ("address", "device") if key in self.config}
        paths = {key: device_path(value, self._key(key)) for key, value in given.items()}
        if len(set(paths.values())) > 1:
            raise ValueError(
                f"{self._key('address')} = {given['address']!r} ({paths['address']}) and "
                f"config['device'] = {given['device']!r} ({paths['device']}) name different devices; "
                "give one of them (a path like /dev/video0 or an index)"
            )
        return next(iter(paths.values()), device_path(0))

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
        self._skipped = self._dropped = 0

    # ---------------------------------------------------------------- state
    @property
    def pixel_format(self) -> str | None:
        """The pixel format in use (None before open)."""
        return self._fmt["name"] if self._fmt else None

    @property
    def frame_size(self) -> tuple | None:
        """``(width, height)`` the driver delivers (before a software ROI)."""
        return (self._fmt["width"], self._fmt["height"]) if self._fmt else None

    # ---------------------------------------------------------------- lifecycle
    @os_errors
    def _open_device(self):
        lvd = import_linuxpy(self.name)
        self._lvd = lvd
        self._reset_state()
        dev = lvd.Device(self.path)
        try:
            dev.open()
        except FileNotFoundError as exc:
            raise CameraError(
                f"{self.name}: no such device {self.path} (is the camera plugged in? "
                "`ls /dev/video*` or `v4l2-ctl --list-devices` lists them)"
            ) from exc
        except PermissionError as exc:
            raise CameraError(
                f"{self.name}: permission denied on {self.path} (add the user to the 'video' group)"
            ) from exc
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
            raise CameraError(
                f"{self.name}: {self.path} is not a video capture node (capabilities: {caps!r}); "
                "webcams often also have a metadata node, try another /dev/video*"
            )
        if lvd.Capability.STREAMING not in caps:
            raise CameraError(f"{self.name}: the device does not support streaming (mmap) I/O")
        offered = []
        for fmt in lvd.iter_read_formats(dev, lvd.BufferType.VIDEO_CAPTURE):
            name = getattr(fmt.pixel_format, "name", str(fmt.pixel_format))
            if name not in offered:
                offered.append(name)
        self.device_formats = tuple(offered)
        wanted = self._requested_format
        if wanted is not None and wanted not in offered:
            raise CameraError(
                f"{self._key('pixel_format')} = {wanted!r}: the device does not offer {wanted}; it offers {offered}"
            )
        if wanted is None:
            usable = [name for name in PIXEL_FORMATS if name in offered]
            if not usable:
                raise CameraError(
                    f"{self.name}: the device offers {offered or 'no formats'}, none of which this "
                    f"backend reads ({list(PIXEL_FORMATS)}){packed_note(offered)}"
                )
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
            raise CameraError(
                f"{self.name}: asked the driver for {name}, it chose {got} "
                f"(the device offers {list(self.device_formats)})"
            )
        if got not in PIXEL_FORMATS:
            raise CameraError(f"{self.name}: the driver delivers {got}, which this backend does not read")
        width, height = int(pix.width), int(pix.height)
        bpp = PIXEL_FORMATS[got][0]
        bpl = int(pix.bytesperline) or width * bpp
        if bpl < width * bpp or width < 1 or height < 1:
            raise CameraError(
                f"{self.name}: the driver reports an inconsistent {got} format {width}x{height}, {bpl} bytes per line"
            )
        self._fmt = {
            "name": got,
            "width": width,
            "height": height,
            "bpl": bpl,
            "sizeimage": int(pix.sizeimage) or bpl * height,
        }
        if self._soft_roi is not None:
            x, y, w, h = self._soft_roi
            if x + w > width or y + h > height:
                self._soft_roi, self._roi_kind = None, None
                raise CameraError(
                    f"{self.name}: the ROI {[x, y, w, h]} does not fit the {got} frames of {width}x{height}; "
                    "it is cleared: set the ROI after the pixel format"
                )
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

    @os_errors
    def _set_pixel_format(self, pixel_format):
        self._apply_format(pixel_format)

    # ---------------------------------------------------------------- trigger
    def _set_trigger(self, mode, source):
        if mode == "line":
            raise CameraError(
                f"{self.name}: V4L2 webcams are free-running and have no hardware trigger input "
                f"(asked for line trigger on {source!r}); use 'software' (next frame after the call) "
                "or 'free'"
            )
        self._trigger_time = None

    @os_errors
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
