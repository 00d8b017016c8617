"""The v4l2 camera backend, against a fake V4L2 device at the ioctl layer.

There is no ``/dev/video*`` here and no way to load vivid or v4l2loopback, so, as
linuxpy's own test suite does, the kernel is replaced where linuxpy meets it:

* ``open()`` of the device node (``linuxpy.io.open``) returns a file whose descriptor is
  the read end of a real pipe, so ``poll`` in the backend is the real system call: one
  byte in the pipe per completed buffer; unplugging closes the write end (``POLLHUP``,
  as the kernel reports ``POLLERR`` for a vanished device);
* ``fcntl.ioctl`` as linuxpy calls it (``linuxpy.ioctl.fcntl``) is answered by
  :class:`FakeV4L2Device`, which keeps the driver state (format, crop, controls, the
  mmap buffer queue, streaming) and answers every V4L2 ioctl the backend and linuxpy
  issue with the kernel's semantics and errnos (EINVAL past the last enumerated item,
  ENOTTY for an ioctl the driver does not implement, EBUSY while buffers are allocated,
  EAGAIN from DQBUF on a non-blocking fd with no frame, ENODEV once unplugged); it checks
  that each argument's size is the one the ioctl number encodes (the ABI);
* ``mmap.mmap`` as linuxpy calls it (``linuxpy.video.device.mmap``) returns a real
  anonymous mapping that the fake "DMA"s frame bytes into, at the offset QUERYBUF gave.

What the fake cannot show: real driver timing, a real sensor, the exact errno a given
driver uses for an inactive control, and the kernel's own copy/caching of buffers. The
``v4l2_device`` test at the end runs the backend on a real ``/dev/video*`` where one exists.
"""

from __future__ import annotations

import ctypes
import errno
import glob
import mmap as mmap_module
import os
import re
import sys
import threading
import time
import warnings
from contextlib import ExitStack
from types import SimpleNamespace
from unittest import mock

import numpy as np
import pytest

from rsocl.hardware.backend import CameraBackend, CameraDisconnected, CameraError, CameraTimeout, Frame
from rsocl_plugins.v4l2 import EXPOSURE_UNIT, V4L2Camera
from rsocl_plugins.v4l2_formats import convert_frame

_real_mmap = mmap_module.mmap
PAGE = mmap_module.PAGESIZE

CID_USER_CLASS = 0x00980001
CID_BRIGHTNESS = 0x00980900
CID_CAMERA_CLASS = 0x009A0001
CID_EXPOSURE_AUTO = 0x009A0901
CID_EXPOSURE_ABSOLUTE = 0x009A0902
EXPOSURE_MANUAL, EXPOSURE_APERTURE_PRIORITY = 1, 3
BYTES_PER_PIXEL = {"GREY": 1, "Y16": 2, "Y12": 2, "Y10": 2, "YUYV": 2}
PAD = 0xEE  # line padding bytes the fake writes: must never reach an image


def _err(code):
    return OSError(code, os.strerror(code))


@pytest.fixture
def lvd():
    return pytest.importorskip("linuxpy.video.device", reason='linuxpy not installed (pip install "rsocl[v4l2]")')


class FakeFile:
    """The open device node: its descriptor is a real pipe's read end."""

    def __init__(self, path, mode):
        self.name, self.mode = path, mode
        self.r, self.w = os.pipe()
        os.set_blocking(self.r, False)  # linuxpy opens with O_NONBLOCK
        self.closed = False

    def fileno(self):
        if self.closed:
            raise ValueError("I/O operation on closed file")
        return self.r

    def close_write_end(self):
        if self.w is not None:
            os.close(self.w)
            self.w = None

    def close(self):
        if not self.closed:
            self.closed = True
            os.close(self.r)
            self.close_write_end()


class FakeV4L2Device:
    """A V4L2 single-planar capture driver, answering at the ioctl layer.

    ``sensor`` is (width, height); the driver has no scaler, so the format size is the
    crop size. ``pad`` extra bytes end each line (bytesperline > width * bpp).
    ``selection`` gives it the selection (crop) API; ``crop_align`` rounds a crop
    outwards to multiples of that many pixels. ``substitute`` maps a listed format to
    the one S_FMT really picks (a driver that lists more than it delivers).
    """

    def __init__(
        self,
        path="/dev/video7",
        formats=("GREY", "Y16", "YUYV"),
        sensor=(12, 6),
        pad=4,
        selection=False,
        crop_align=1,
        capabilities=None,
        exposure=(3, 2047, 1, 156),
        auto_exposure=True,
        substitute=None,
        min_buffers=2,
    ):
        from linuxpy.video import raw

        self.raw = raw
        self.path = path
        self.formats = [int(raw.PixelFormat[name]) for name in formats]
        self.sensor_w, self.sensor_h = sensor
        self.pad = pad
        self.selection = selection
        self.crop_align = crop_align
        self.caps = (
            capabilities if capabilities is not None else int(raw.Capability.VIDEO_CAPTURE | raw.Capability.STREAMING)
        )
        self.substitute = {int(raw.PixelFormat[k]): int(raw.PixelFormat[v]) for k, v in (substitute or {}).items()}
        self.min_buffers = min_buffers
        self.crop = [0, 0, self.sensor_w, self.sensor_h]
        self.fmt = {"pixelformat": self.formats[0]}
        self._update_format()
        CT = raw.CtrlType
        self.controls = {
            CID_USER_CLASS: dict(
                name=b"User Controls", type=CT.CTRL_CLASS, minimum=0, maximum=0, step=0, default=0, flags=0x44, value=0
            ),
            CID_BRIGHTNESS: dict(
                name=b"Brightness", type=CT.INTEGER, minimum=-64, maximum=64, step=1, default=0, flags=0x20, value=0
            ),
            CID_CAMERA_CLASS: dict(
                name=b"Camera Controls",
                type=CT.CTRL_CLASS,
                minimum=0,
                maximum=0,
                step=0,
                default=0,
                flags=0x44,
                value=0,
            ),
        }
        self.menus = {}
        if auto_exposure:
            self.controls[CID_EXPOSURE_AUTO] = dict(
                name=b"Auto Exposure",
                type=CT.MENU,
                minimum=0,
                maximum=3,
                step=1,
                default=3,
                flags=0x8,
                value=EXPOSURE_APERTURE_PRIORITY,
            )
            self.menus[CID_EXPOSURE_AUTO] = {1: b"Manual Mode", 3: b"Aperture Priority Mode"}
        if exposure is not None:
            lo, hi, step, default = exposure
            self.controls[CID_EXPOSURE_ABSOLUTE] = dict(
                name=b"Exposure Time, Absolute",
                type=CT.INTEGER,
                minimum=lo,
                maximum=hi,
                step=step,
                default=default,
                flags=0x10,
                value=default,
            )
        self.buffers = []
        self.queued, self.done = [], []
        self.streaming = False
        self.sequence = 0
        self.dropped = 0
        self.gone = False
        self.file = None
        self.log = []  # ioctl names, in order
        self.control_writes = []  # (id, value) as the driver stored them
        self.requested_size = None
        self.lock = threading.RLock()

    # ------------------------------------------------------------ patching
    def __enter__(self):
        self._stack = ExitStack()
        self._stack.enter_context(mock.patch("linuxpy.io.open", self._open))
        self._stack.enter_context(mock.patch("linuxpy.ioctl.fcntl", SimpleNamespace(ioctl=self._ioctl)))
        self._stack.enter_context(mock.patch("linuxpy.video.device.mmap", SimpleNamespace(mmap=self._mmap)))
        return self

    def __exit__(self, *exc):
        self._stack.close()
        if self.file is not None:
            self.file.close()
        for buf in self.buffers:
            buf["mm"].close()
        return False

    def _open(self, path, mode="r", buffering=-1, opener=None, **kwargs):
        if str(path) != self.path or self.gone:
            raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), str(path))
        assert "+" in mode, "V4L2 streaming needs the node opened read/write"
        self.file = FakeFile(str(path), mode)
        return self.file

    def _mmap(self, fd, length, offset=0, **kwargs):
        assert isinstance(fd, int) and self.file is not None and fd == self.file.r, "mmap of another fd"
        for buf in self.buffers:
            if buf["offset"] == offset:
                assert length == buf["length"], f"mmap length {length} != buffer length {buf['length']}"
                buf["mapped"] = True
                return buf["mm"]
        raise _err(errno.EINVAL)

    # ------------------------------------------------------------ ioctl dispatch
    def _ioctl(self, fd, request, arg=None, *rest):
        raw = self.raw
        code = int(request)
        try:
            name = raw.IOC(code).name
        except ValueError:
            raise _err(errno.ENOTTY) from None
        size = (code >> 16) & 0x3FFF
        assert ctypes.sizeof(arg) == size, f"VIDIOC_{name}: argument of {ctypes.sizeof(arg)} bytes, ioctl says {size}"
        fd = fd if isinstance(fd, int) else fd.fileno()
        with self.lock:
            if self.file is None or self.file.closed or fd != self.file.r:
                raise _err(errno.EBADF)
            self.log.append(name)
            if self.gone:
                raise _err(errno.ENODEV)
            handler = getattr(self, f"_ioc_{name}", None)
            if handler is None:
                raise _err(errno.ENOTTY)
            handler(arg)
        return 0

    def _check_type(self, arg):
        if arg.type != self.raw.BufType.VIDEO_CAPTURE:
            raise _err(errno.EINVAL)

    # ------------------------------------------------------------ capabilities, formats
    def _ioc_QUERYCAP(self, arg):
        arg.driver, arg.card, arg.bus_info = b"fakecam", b"Fake Webcam", b"usb-fake-1"
        arg.version = (6 << 16) | (1 << 8)
        arg.capabilities = self.caps | 0x80000000  # V4L2_CAP_DEVICE_CAPS
        arg.device_caps = self.caps

    def _ioc_ENUM_FMT(self, arg):
        self._check_type(arg)
        if arg.index >= len(self.formats):
            raise _err(errno.EINVAL)
        arg.pixelformat = self.formats[arg.index]
        arg.description = self.raw.PixelFormat(self.formats[arg.index]).name.encode()
        arg.flags = 0

    def _bpp(self, fourcc):
        return BYTES_PER_PIXEL.get(self.raw.PixelFormat(fourcc).name, 1)

    def _update_format(self):
        width, height = self.crop[2], self.crop[3]
        bpl = width * self._bpp(self.fmt["pixelformat"]) + self.pad
        self.fmt.update(width=width, height=height, bytesperline=bpl, sizeimage=bpl * height)

    def _fill_format(self, pix, fmt):
        pix.width, pix.height = fmt["width"], fmt["height"]
        pix.pixelformat = fmt["pixelformat"]
        pix.field = 1  # V4L2_FIELD_NONE
        pix.bytesperline, pix.sizeimage = fmt["bytesperline"], fmt["sizeimage"]
        pix.colorspace = 8  # SRGB

    def _ioc_G_FMT(self, arg):
        self._check_type(arg)
        self._fill_format(arg.fmt.pix, self.fmt)

    def _negotiate(self, arg, commit):
        self._check_type(arg)
        pix = arg.fmt.pix
        fourcc = pix.pixelformat if pix.pixelformat in self.formats else self.formats[0]
        fourcc = self.substitute.get(fourcc, fourcc)
        saved = dict(self.fmt)
        self.fmt["pixelformat"] = fourcc
        self._update_format()  # no scaler: the size is the crop's, whatever was asked
        result = dict(self.fmt)
        if not commit:
            self.fmt = saved
        self._fill_format(pix, result)

    def _ioc_TRY_FMT(self, arg):
        self._negotiate(arg, commit=False)

    def _ioc_S_FMT(self, arg):
        if self.buffers:
            raise _err(errno.EBUSY)
        self.requested_size = (arg.fmt.pix.width, arg.fmt.pix.height)
        self._negotiate(arg, commit=True)

    # ------------------------------------------------------------ selection
    def _ioc_G_SELECTION(self, arg):
        if not self.selection:
            raise _err(errno.ENOTTY)
        self._check_type(arg)
        T = self.raw.SelectionTarget
        if arg.target == T.CROP:
            rect = self.crop
        elif arg.target in (T.CROP_DEFAULT, T.CROP_BOUNDS):
            rect = [0, 0, self.sensor_w, self.sensor_h]
        else:
            raise _err(errno.EINVAL)
        arg.r.left, arg.r.top, arg.r.width, arg.r.height = rect

    def _ioc_S_SELECTION(self, arg):
        if not self.selection:
            raise _err(errno.ENOTTY)
        self._check_type(arg)
        if arg.target != self.raw.SelectionTarget.CROP:
            raise _err(errno.EINVAL)
        if self.buffers:
            raise _err(errno.EBUSY)
        a = self.crop_align
        left, top = max(0, arg.r.left) // a * a, max(0, arg.r.top) // a * a
        right = min(self.sensor_w, -(-(arg.r.left + arg.r.width) // a) * a)
        bottom = min(self.sensor_h, -(-(arg.r.top + arg.r.height) // a) * a)
        self.crop = [left, top, right - left, bottom - top]
        self._update_format()
        arg.r.left, arg.r.top, arg.r.width, arg.r.height = self.crop

    def _ioc_CROPCAP(self, arg):
        raise _err(errno.ENOTTY)

    # ------------------------------------------------------------ controls
    def _ioc_QUERY_EXT_CTRL(self, arg):
        raw = self.raw
        nxt = int(raw.ControlFlag.NEXT_CTRL | raw.ControlFlag.NEXT_COMPOUND)
        if arg.id & nxt:
            later = sorted(cid for cid in self.controls if cid > arg.id & ~nxt)
            if not later:
                raise _err(errno.EINVAL)
            cid = later[0]
        elif arg.id in self.controls:
            cid = arg.id
        else:
            raise _err(errno.EINVAL)
        c = self.controls[cid]
        flags = c["flags"]
        if cid == CID_EXPOSURE_ABSOLUTE and self.controls.get(CID_EXPOSURE_AUTO, {}).get("value") == EXPOSURE_MANUAL:
            flags &= ~0x10  # active in manual mode
        arg.id, arg.type, arg.name = cid, c["type"], c["name"]
        arg.minimum, arg.maximum, arg.step, arg.default_value = c["minimum"], c["maximum"], c["step"], c["default"]
        arg.flags = flags
        arg.elem_size, arg.elems, arg.nr_of_dims = 4, 1, 0

    def _ioc_QUERYMENU(self, arg):
        name = self.menus.get(arg.id, {}).get(arg.index)
        if name is None:
            raise _err(errno.EINVAL)
        arg.name = name

    def _validate(self, cid, value):
        c = self.controls.get(cid)
        if c is None or c["type"] == self.raw.CtrlType.CTRL_CLASS:
            raise _err(errno.EINVAL)
        if c["flags"] & 0x4:
            raise _err(errno.EACCES)
        if c["type"] == self.raw.CtrlType.MENU:
            if value not in self.menus[cid]:
                raise _err(errno.EINVAL)
            return value
        # kernel semantics for integer controls: clamp to the range, round to the step
        value = min(max(value, c["minimum"]), c["maximum"])
        step = c["step"] or 1
        return c["minimum"] + (value - c["minimum"] + step // 2) // step * step

    def _write_control(self, cid, value):
        if cid == CID_EXPOSURE_ABSOLUTE and self.controls.get(CID_EXPOSURE_AUTO, {}).get("value", EXPOSURE_MANUAL) != 1:
            raise _err(errno.EACCES)  # inactive in an auto mode; a real UVC camera refuses too
        self.controls[cid]["value"] = value
        self.control_writes.append((cid, value))

    def _ioc_G_EXT_CTRLS(self, arg):
        default = arg.which == self.raw.ControlWhichValue.DEF_VAL
        for i in range(arg.count):
            ctrl = arg.controls[i]
            c = self.controls.get(ctrl.id)
            if c is None:
                arg.error_idx = i
                raise _err(errno.EINVAL)
            ctrl.value = c["default"] if default else c["value"]

    def _ioc_S_EXT_CTRLS(self, arg):
        values = []
        for i in range(arg.count):
            try:
                values.append((arg.controls[i].id, self._validate(arg.controls[i].id, arg.controls[i].value)))
            except OSError:
                arg.error_idx = i
                raise
        for cid, value in values:
            self._write_control(cid, value)

    def _ioc_G_CTRL(self, arg):
        if arg.id not in self.controls:
            raise _err(errno.EINVAL)
        arg.value = self.controls[arg.id]["value"]

    def _ioc_S_CTRL(self, arg):
        arg.value = self._validate(arg.id, arg.value)
        self._write_control(arg.id, arg.value)

    # ------------------------------------------------------------ buffers, streaming
    def _ioc_REQBUFS(self, arg):
        self._check_type(arg)
        if arg.memory != self.raw.Memory.MMAP:
            raise _err(errno.EINVAL)
        if self.streaming or any(buf["mapped"] and not buf["mm"].closed for buf in self.buffers):
            raise _err(errno.EBUSY)
        for buf in self.buffers:
            buf["mm"].close()
        self.buffers, self.queued, self.done = [], [], []
        if arg.count == 0:
            return
        self.requested_buffers = arg.count
        count = max(self.min_buffers, min(arg.count, 32))
        length = self.fmt["sizeimage"]
        span = -(-length // PAGE) * PAGE
        for index in range(count):
            self.buffers.append(
                dict(
                    index=index,
                    length=length,
                    offset=index * span,
                    mm=_real_mmap(-1, span),
                    mapped=False,
                    state="dequeued",
                    bytesused=0,
                    timestamp=0.0,
                    sequence=0,
                    error=False,
                )
            )
        arg.count = count

    def _fill_buffer(self, arg, buf):
        arg.index, arg.type, arg.memory = buf["index"], self.raw.BufType.VIDEO_CAPTURE, self.raw.Memory.MMAP
        arg.length, arg.m.offset = buf["length"], buf["offset"]
        flags = 0x2000 | 0x10000  # TIMESTAMP_MONOTONIC | TSTAMP_SRC_SOE, as uvcvideo
        flags |= 0x1 if buf["mapped"] else 0
        flags |= {"queued": 0x2, "done": 0x4}.get(buf["state"], 0)
        flags |= 0x40 if buf["error"] else 0
        arg.flags = flags
        arg.bytesused, arg.field, arg.sequence = buf["bytesused"], 1, buf["sequence"]
        usecs = round(buf["timestamp"] * 1e6)
        arg.timestamp.secs, arg.timestamp.usecs = usecs // 1_000_000, usecs % 1_000_000

    def _buffer(self, arg):
        self._check_type(arg)
        if arg.memory != self.raw.Memory.MMAP or arg.index >= len(self.buffers):
            raise _err(errno.EINVAL)
        return self.buffers[arg.index]

    def _ioc_QUERYBUF(self, arg):
        self._fill_buffer(arg, self._buffer(arg))

    def _ioc_QBUF(self, arg):
        buf = self._buffer(arg)
        if buf["state"] != "dequeued":
            raise _err(errno.EINVAL)
        buf["state"] = "queued"
        self.queued.append(buf["index"])
        self._fill_buffer(arg, buf)

    def _ioc_DQBUF(self, arg):
        self._check_type(arg)
        if arg.memory != self.raw.Memory.MMAP or not self.streaming:
            raise _err(errno.EINVAL)
        if not self.done:
            raise _err(errno.EAGAIN)
        buf = self.buffers[self.done.pop(0)]
        os.read(self.file.r, 1)
        buf["state"] = "dequeued"
        self._fill_buffer(arg, buf)

    def _ioc_STREAMON(self, arg):
        if arg.value != self.raw.BufType.VIDEO_CAPTURE or not self.buffers:
            raise _err(errno.EINVAL)
        self.streaming = True

    def _ioc_STREAMOFF(self, arg):
        if arg.value != self.raw.BufType.VIDEO_CAPTURE:
            raise _err(errno.EINVAL)
        self.streaming = False
        for buf in self.buffers:
            buf["state"] = "dequeued"
        for _ in self.done:
            os.read(self.file.r, 1)
        self.queued, self.done = [], []

    # ------------------------------------------------------------ the "sensor"
    @property
    def pixel_format(self):
        return self.raw.PixelFormat(self.fmt["pixelformat"]).name

    def encode(self, sensor_image):
        """Pack the crop of a full-sensor image the way the driver delivers it (with line padding)."""
        left, top, width, height = self.crop
        image = np.asarray(sensor_image)[top : top + height, left : left + width]
        name = self.pixel_format
        if name == "GREY":
            rows = image.astype(np.uint8)
        elif name in ("Y16", "Y12", "Y10"):  # one pixel per 16-bit little-endian word, the value in the low bits
            rows = image.astype("<u2").view(np.uint8)
        elif name == "YUYV":
            rows = np.empty((height, 2 * width), np.uint8)
            rows[:, 0::2] = image.astype(np.uint8)  # Y0 U Y1 V ...
            rows[:, 1::4] = 0x5A  # U: chroma that must not leak into the image
            rows[:, 3::4] = 0xA5  # V
        else:
            raise AssertionError(name)
        pad = np.full((height, self.pad), PAD, np.uint8)
        return np.concatenate([rows.reshape(height, -1), pad], axis=1).tobytes()

    def emit(self, sensor_image=None, raw_bytes=None, timestamp=None, error=False, bytesused=None, skip=0):
        """One frame from the sensor: DMA'd into the first queued buffer (dropped when none is queued)."""
        with self.lock:
            self.sequence += skip  # frames the driver lost on the way
            if not self.streaming or not self.queued:
                self.sequence += 1
                self.dropped += 1
                return False
            data = raw_bytes if raw_bytes is not None else self.encode(sensor_image)
            buf = self.buffers[self.queued.pop(0)]
            assert len(data) <= buf["length"]
            buf["mm"][: len(data)] = data
            buf.update(
                state="done",
                bytesused=len(data) if bytesused is None else bytesused,
                error=error,
                timestamp=time.monotonic() if timestamp is None else timestamp,
                sequence=self.sequence,
            )
            self.sequence += 1
            self.done.append(buf["index"])
            os.write(self.file.w, b"\0")
            return True

    def emit_later(self, delay, *args, **kwargs):
        timer = threading.Timer(delay, self.emit, args, kwargs)
        timer.start()
        return timer

    def unplug(self):
        with self.lock:
            self.gone = True
            if self.file is not None:
                self.file.close_write_end()  # the reader sees POLLHUP


@pytest.fixture
def make_fake(lvd):
    with ExitStack() as stack:
        yield lambda **kw: stack.enter_context(FakeV4L2Device(**kw))


@pytest.fixture
def fake(make_fake):
    return make_fake()


def sensor_image(fake, high=256, seed=0):
    rng = np.random.default_rng(seed)
    return rng.integers(0, high, size=(fake.sensor_h, fake.sensor_w), dtype=np.int64)


# ====================================================================== without linuxpy
def test_missing_linuxpy_names_the_extra(monkeypatch):
    for mod in ("linuxpy", "linuxpy.video", "linuxpy.video.device"):
        monkeypatch.setitem(sys.modules, mod, None)  # import fails as if not installed
    cam = V4L2Camera({"device": 3})
    with pytest.raises(CameraError, match=r'pip install "rsocl\[v4l2\]"') as info:
        cam.open()
    assert "v4l2 /dev/video3" in str(info.value)
    assert not cam._open


@pytest.mark.parametrize(
    "device, path",
    [
        (0, "/dev/video0"),
        (2, "/dev/video2"),
        ("5", "/dev/video5"),
        ("/dev/v4l/by-id/usb-cam", "/dev/v4l/by-id/usb-cam"),
    ],
)
def test_device_config(device, path):
    cam = V4L2Camera({"device": device})
    assert cam.path == path and cam.name == f"v4l2 {path}"
    assert isinstance(cam, CameraBackend) and cam.backend == "v4l2"
    assert V4L2Camera().path == "/dev/video0"
    assert V4L2Camera({"device": 1}, name="left").name == "left"


@pytest.mark.parametrize(
    "config",
    [
        {"device": -1},
        {"device": True},
        {"device": ""},
        {"buffers": 0},
        {"buffers": 33},
        {"buffers": 2.5},
        {"pixel_format": "MJPEG"},
        {"width": 0},
        {"height": "480"},
        {"device": None},
        {"device": 1.0},
    ],
)
def test_bad_config(config):
    with pytest.raises(ValueError):
        V4L2Camera(config)


def test_unknown_config_key_is_refused_with_the_closest_key_and_the_known_ones():
    with pytest.raises(
        ValueError,
        match=r"^v4l2 /dev/video0: unknown config key 'adress' \(did you mean "
        r"'address'\?\); known: \[",
    ) as info:
        V4L2Camera({"adress": "/dev/video2", "buffers": 2})
    for key in ("address", "buffers", "device", "height", "pixel_format", "width"):
        assert repr(key) in str(info.value).split("known:")[1]
    with pytest.raises(
        ValueError,
        match=r"^left: unknown config keys 'bufers' \(did you mean 'buffers'\?\), "
        r"'zzz'; known",
    ):
        V4L2Camera({"zzz": 1, "bufers": 3}, name="left")


def test_known_config_keys_are_accepted(recwarn):
    V4L2Camera({"device": 1, "address": 1, "pixel_format": "GREY", "buffers": 2, "width": 640, "height": 480})
    assert not [w for w in recwarn if issubclass(w.category, UserWarning)]


@pytest.mark.parametrize(
    "address, path",
    [
        (2, "/dev/video2"),
        ("3", "/dev/video3"),
        ("/dev/video2", "/dev/video2"),
        ("/dev/v4l/by-id/usb-cam", "/dev/v4l/by-id/usb-cam"),
    ],
)
def test_address_selects_the_device(address, path):
    cam = V4L2Camera({"address": address})
    assert cam.path == path and cam.name == f"v4l2 {path}"
    # the same node given both ways, in any of the accepted forms, is not a conflict
    assert V4L2Camera({"address": address, "device": path}).path == path


@pytest.mark.parametrize(
    "config",
    [
        {"address": "/dev/video2", "device": "/dev/video3"},
        {"address": 2, "device": 0},
        {"address": "/dev/video1", "device": "2"},
    ],
)
def test_address_and_device_must_agree(config):
    with pytest.raises(ValueError, match="address") as info:
        V4L2Camera(config)
    message = str(info.value)
    assert "device" in message and repr(config["address"]) in message and repr(config["device"]) in message


@pytest.mark.parametrize("address", [-1, True, "", "  ", 2.5, None])
def test_bad_address_names_the_key(address):
    with pytest.raises(
        ValueError,
        match=r"^v4l2 camera: config\['address'\] must be (a path like /dev/video0 or an index >= 0|an index >= 0 or "
        r"a path like /dev/video0), got ",
    ) as info:
        V4L2Camera({"address": address})
    assert repr(address) in str(info.value) or "empty string" in str(info.value)


def test_address_opens_the_named_node(fake):
    assert fake.path != "/dev/video0"
    with V4L2Camera({"address": fake.path}) as cam:
        assert cam.path == fake.path and fake.file is not None and fake.file.name == fake.path
        assert cam.frame_size == (12, 6)


def _capture_from_webcam(fake, tmp_path, t_e, sets=2):
    """capture_sets on a one-camera rig file of ``fake`` (6x12, t_r = 1 ms), which runs free with a frame every
    5 ms; returns the capture file and the image the fake sends."""
    rig_path = tmp_path / "rig.toml"
    rig_path.write_text(f"""
[rig]
shape = [6, 12]

[[camera]]
backend = "v4l2"
address = "{fake.path}"
angle = 0.0
t_e = {t_e!r}
t_r = 0.001
""")
    image = sensor_image(fake)
    return capture_while_sending(fake, image, rig_path, tmp_path / "capture.h5", sets), image


def capture_while_sending(fake, image, rig_path, out, sets):
    """capture_sets of ``sets`` sets from the rig file ``rig_path`` into ``out`` while ``fake`` sends ``image``
    every 5 ms (it runs free); returns the capture file."""
    from rsocl.hardware.capture import capture_sets

    stop = threading.Event()

    def sensor():
        while not stop.wait(0.005):
            fake.emit(image)

    thread = threading.Thread(target=sensor, daemon=True)
    thread.start()
    try:
        return capture_sets(rig_path, out, sets=sets, timeout=2.0)
    finally:
        stop.set()
        thread.join()


def test_a_roi_beyond_the_sensor_is_refused_once_the_camera_opens_before_any_file(make_fake, tmp_path):
    from rsocl.hardware.capture import capture_sets

    fake = make_fake(selection=True)  # its crop bounds, the 12x6 sensor, are known once it is open
    rig = tmp_path / "rig.toml"
    rig.write_text(
        f'[rig]\nshape = [6, 12]\n\n[[camera]]\nbackend = "v4l2"\naddress = "{fake.path}"\nangle = 0.0\n'
        "t_e = 0.01\nt_r = 0.001\nroi = [4, 0, 12, 6]\n"
    )
    with pytest.raises(
        ValueError,
        match=rf"rig\.toml: camera\[0\]\.roi = \[4, 0, 12, 6\] \(\[x, y, width, height\]\) must lie on the 12x6 "
        rf"\(width x height\) sensor of camera 0 \(v4l2 {fake.path}\): x \+ width <= 12 and y \+ height <= 6$",
    ):
        capture_sets(rig, tmp_path / "c.h5")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]
    assert fake.file.closed and "S_SELECTION" not in fake.log and "STREAMON" not in fake.log  # closed, untouched


def test_rig_file_address_reaches_the_camera(fake, tmp_path):
    from rsocl.hardware.capture_file import load_raw

    out, image = _capture_from_webcam(fake, tmp_path, 0.01)
    raw = load_raw(out)
    assert raw.status == "complete" and raw.sets_complete == 2
    assert raw.meta["cameras"][0]["name"] == f"camera 0 (v4l2 {fake.path})"
    assert raw.frames[0].shape == (2, 6, 12)
    np.testing.assert_array_equal(raw.frames[0][1], image)


@pytest.mark.filterwarnings("ignore:camera t_e = 10 s is longer than 1 s:UserWarning")  # the clamp, on purpose
@pytest.mark.parametrize("t_e, applied", [(10.0, 0.2047), (0.01234, 0.0123)])
def test_the_capture_rig_holds_the_exposure_the_webcam_applied(fake, tmp_path, t_e, applied):
    from rsocl.files.hdf5 import load_capture

    with pytest.warns(
        UserWarning,
        match=rf"camera 0: the device applied an exposure of {applied!r} s where the rig "
        rf"file says t_e = {t_e!r} s",
    ):
        out, image = _capture_from_webcam(fake, tmp_path, t_e, sets=1)
    capture = load_capture(out)
    assert capture.rig.cameras[0].t_e == pytest.approx(applied)
    assert capture.rig.T == int(np.ceil(round((5 * 1e-3 + applied) / 1e-3, 6)))
    # 8-bit frames in model units: full scale is the applied exposure over dt
    np.testing.assert_allclose(capture.snapshots[0], image / 255 * (applied / 1e-3))


def test_entry_point():
    from rsocl.common import registry as plugins

    names = plugins.available("rsocl.cameras")
    if "v4l2" not in names:
        pytest.skip("rsocl not re-installed since the v4l2 entry point was added (pip install -e .)")
    assert names["v4l2"].value == "rsocl_plugins.v4l2:V4L2Camera"
    assert plugins.load("rsocl.cameras", "v4l2") is V4L2Camera


def test_convert_frame_reference():
    # 2x2 pixels, 2 bytes of padding per line
    grey = bytes([1, 2, 0xEE, 0xEE, 3, 4, 0xEE, 0xEE])
    assert convert_frame(grey, "GREY", 2, 2, 4).tolist() == [[1, 2], [3, 4]]
    y16 = bytes([0x34, 0x12, 0xFF, 0x00, 0xEE, 0xEE, 0x01, 0x00, 0x00, 0x01, 0xEE, 0xEE])
    out = convert_frame(y16, "Y16", 2, 2, 6)
    assert out.dtype == np.uint16 and out.tolist() == [[0x1234, 0x00FF], [0x0001, 0x0100]]
    yuyv = bytes([10, 128, 20, 129, 30, 130, 40, 131])
    out = convert_frame(yuyv, "YUYV", 4, 1, 8)
    assert out.dtype == np.uint8 and out.tolist() == [[10, 20, 30, 40]]
    # the last line's padding may be missing
    assert convert_frame(grey[:-2], "GREY", 2, 2, 4).tolist() == [[1, 2], [3, 4]]
    with pytest.raises(ValueError):
        convert_frame(grey[:-3], "GREY", 2, 2, 4)
    assert convert_frame(grey, "GREY", 2, 2, 4).flags.writeable


# ====================================================================== open, formats
def test_open_probes_and_picks_a_format(fake):
    cam = V4L2Camera({"device": fake.path})
    with cam:
        assert cam.driver == "fakecam" and cam.card == "Fake Webcam"
        assert cam.device_formats == ("GREY", "Y16", "YUYV")
        assert cam.pixel_format == "GREY" and fake.pixel_format == "GREY"
        assert cam.frame_size == (12, 6)
        assert cam.readout_time is None
        assert fake.log[:2] == ["QUERYCAP", "ENUM_FMT"] and "S_FMT" in fake.log
        assert cam.open() is cam  # idempotent
    assert fake.file.closed and not cam._open
    cam.close()  # idempotent


def test_open_missing_node(fake):
    cam = V4L2Camera({"device": "/dev/video99"})
    with pytest.raises(CameraError, match="no such device /dev/video99"):
        cam.open()


def test_open_rejects_a_metadata_node(make_fake, lvd):
    fake = make_fake(capabilities=int(lvd.Capability.META_CAPTURE | lvd.Capability.STREAMING))
    with pytest.raises(CameraError, match="not a video capture node"):
        V4L2Camera({"device": fake.path}).open()
    assert fake.file.closed  # nothing leaked


def test_open_needs_streaming(make_fake, lvd):
    fake = make_fake(capabilities=int(lvd.Capability.VIDEO_CAPTURE | lvd.Capability.READWRITE))
    with pytest.raises(CameraError, match="streaming"):
        V4L2Camera({"device": fake.path}).open()


@pytest.mark.parametrize("name", ["GREY", "Y16", "YUYV"])
def test_format_negotiation(fake, name):
    with V4L2Camera({"device": fake.path, "pixel_format": name}) as cam:
        assert cam.pixel_format == name and fake.pixel_format == name
        bpp = BYTES_PER_PIXEL[name]
        assert cam._fmt["bpl"] == 12 * bpp + fake.pad and cam._fmt["sizeimage"] == (12 * bpp + fake.pad) * 6
        for other in ("GREY", "Y16", "YUYV"):
            cam.set_pixel_format(other)
            assert cam.pixel_format == other and fake.pixel_format == other
        with pytest.raises(ValueError, match="pixel_format must be one of"):
            cam.set_pixel_format("MJPEG")


def test_default_format_is_the_first_readable_one_offered(make_fake):
    fake = make_fake(formats=("MJPEG", "YUYV"))
    with V4L2Camera({"device": fake.path}) as cam:
        assert cam.device_formats == ("MJPEG", "YUYV") and cam.pixel_format == "YUYV"
        with pytest.raises(CameraError, match=r"does not offer GREY; it offers \['MJPEG', 'YUYV'\]"):
            cam.set_pixel_format("GREY")
    with pytest.raises(CameraError, match="does not offer Y16"):
        V4L2Camera({"device": fake.path, "pixel_format": "Y16"}).open()


def test_device_without_a_readable_format(make_fake):
    fake = make_fake(formats=("MJPEG",))
    with pytest.raises(CameraError, match="none of which"):
        V4L2Camera({"device": fake.path}).open()


def test_driver_substituting_a_format_is_an_error(make_fake):
    fake = make_fake(substitute={"GREY": "YUYV"})
    with pytest.raises(CameraError, match="asked the driver for GREY, it chose YUYV"):
        V4L2Camera({"device": fake.path, "pixel_format": "GREY"}).open()


def test_requested_size_goes_to_the_driver(fake):
    with V4L2Camera({"device": fake.path, "width": 640, "height": 480}) as cam:
        assert fake.requested_size == (640, 480)
        assert cam.frame_size == (12, 6)  # the driver's answer is what counts


# ====================================================================== exposure
def test_exposure_goes_manual_then_sets_100us_units(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        assert cam.set_exposure(0.01) == pytest.approx(0.01)
        assert fake.controls[CID_EXPOSURE_AUTO]["value"] == EXPOSURE_MANUAL
        assert fake.controls[CID_EXPOSURE_ABSOLUTE]["value"] == 100
        # auto exposure was switched off before the exposure was written (else the fake refuses)
        assert fake.control_writes[:2] == [(CID_EXPOSURE_AUTO, 1), (CID_EXPOSURE_ABSOLUTE, 100)]
        assert cam.set_exposure(0.012345) == pytest.approx(123 * EXPOSURE_UNIT)  # rounded to 123.45 -> 123
        assert cam.set_exposure(0.01236) == pytest.approx(124 * EXPOSURE_UNIT)  # 123.6 -> 124
        assert fake.controls[CID_EXPOSURE_ABSOLUTE]["value"] == 124
        # the seconds are the decimal value of the units, as a rig file's t_e would be written
        assert [cam.set_exposure(t) for t in (0.0003, 0.0123, 0.2047, 0.0007)] == [0.0003, 0.0123, 0.2047, 0.0007]
        assert fake.control_writes.count((CID_EXPOSURE_AUTO, 1)) == 1  # already manual: not rewritten


def test_exposure_is_clamped_and_the_actual_value_reported(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        assert cam.set_exposure(10.0) == pytest.approx(2047 * EXPOSURE_UNIT)  # max 2047 units
        assert fake.controls[CID_EXPOSURE_ABSOLUTE]["value"] == 2047
        assert cam.set_exposure(1e-6) == pytest.approx(3 * EXPOSURE_UNIT)  # min 3 units
        assert fake.controls[CID_EXPOSURE_ABSOLUTE]["value"] == 3
        with pytest.raises(ValueError):
            cam.set_exposure(0)


def test_exposure_snaps_to_the_control_step(make_fake):
    fake = make_fake(exposure=(5, 1000, 10, 155))  # 5, 15, 25, ...
    with V4L2Camera({"device": fake.path}) as cam:
        assert cam.set_exposure(0.0021) == pytest.approx(25 * EXPOSURE_UNIT)  # 21 units -> 25
        assert cam.set_exposure(0.0019) == pytest.approx(15 * EXPOSURE_UNIT)  # 19 units -> 15
        assert cam.set_exposure(1.0) == pytest.approx(995 * EXPOSURE_UNIT)  # not past the maximum


def test_exposure_without_auto_control(make_fake):
    fake = make_fake(auto_exposure=False)
    with V4L2Camera({"device": fake.path}) as cam:
        assert cam.set_exposure(0.02) == pytest.approx(0.02)
        assert fake.control_writes == [(CID_EXPOSURE_ABSOLUTE, 200)]


def test_exposure_needs_the_absolute_control(make_fake):
    fake = make_fake(exposure=None)
    with V4L2Camera({"device": fake.path}) as cam:
        with pytest.raises(CameraError, match="no exposure_time_absolute control"):
            cam.set_exposure(0.01)


# ====================================================================== capture
@pytest.mark.parametrize(
    "name, high, dtype, depth", [("GREY", 256, np.uint8, 8), ("Y16", 65536, np.uint16, 16), ("YUYV", 256, np.uint8, 8)]
)
def test_capture_converts_exactly(fake, name, high, dtype, depth):
    image = sensor_image(fake, high)
    with V4L2Camera({"device": fake.path, "pixel_format": name, "buffers": 3}) as cam:
        exposure = cam.set_exposure(0.005)
        cam.set_trigger("free")
        cam.start()
        assert fake.streaming and fake.requested_buffers == 3 and len(fake.buffers) == 3
        assert fake.emit(image, timestamp=1234.567891)
        frame = cam.read(timeout=1.0)
        assert isinstance(frame, Frame)
        assert frame.image.dtype == dtype and frame.image.shape == (6, 12)
        np.testing.assert_array_equal(frame.image, image.astype(dtype))
        assert frame.image.flags.writeable and frame.image.flags.c_contiguous
        assert frame.pixel_format == name and frame.bit_depth == depth
        assert frame.timestamp == pytest.approx(1234.567891, abs=1e-6)
        assert frame.meta["timestamp_clock"] == "monotonic"
        assert frame.meta["timestamp_source"] == "start-of-exposure"
        assert frame.meta["sequence"] == 0 and frame.meta["exposure"] == exposure and frame.meta["roi"] is None
        cam.stop()
        assert not fake.streaming and fake.buffers == []  # unmapped and freed


def test_y16_is_little_endian(make_fake):
    fake = make_fake(formats=("Y16",), sensor=(2, 1), pad=0)
    with V4L2Camera({"device": fake.path}) as cam:
        cam.start()
        fake.emit(raw_bytes=bytes([0x34, 0x12, 0x01, 0xFF]))
        frame = cam.read(1.0)
        assert frame.image.tolist() == [[0x1234, 0xFF01]] and frame.image.dtype == np.uint16


def test_yuyv_gives_the_y_channel(make_fake):
    fake = make_fake(formats=("YUYV",), sensor=(4, 1), pad=0)
    with V4L2Camera({"device": fake.path}) as cam:
        cam.start()
        fake.emit(raw_bytes=bytes([10, 200, 11, 201, 12, 202, 13, 203]))  # Y0 U0 Y1 V0 Y2 U2 Y3 V2
        assert cam.read(1.0).image.tolist() == [[10, 11, 12, 13]]


def test_frames_come_in_order_and_buffers_are_requeued(fake):
    with V4L2Camera({"device": fake.path, "buffers": 2}) as cam:
        cam.set_trigger("free")
        cam.start()
        images = [np.full((6, 12), k) for k in range(7)]
        for k in range(7):  # more frames than buffers: each read must give its buffer back
            assert fake.emit(images[k])
            frame = cam.read(1.0)
            assert frame.meta["sequence"] == k and frame.meta["dropped"] == 0
            assert frame.image[0, 0] == k
        assert len(fake.queued) == 2


def test_dropped_frames_are_counted_and_bad_frames_skipped(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        cam.set_trigger("free")
        cam.start()
        fake.emit(np.full((6, 12), 1))
        assert cam.read(1.0).meta["dropped"] == 0
        fake.emit(np.full((6, 12), 2), error=True)  # V4L2_BUF_FLAG_ERROR: corrupt
        fake.emit(np.full((6, 12), 3), bytesused=10)  # short frame
        fake.emit(np.full((6, 12), 4), skip=2)  # the driver lost two frames
        frame = cam.read(1.0)
        assert frame.image[0, 0] == 4
        assert frame.meta["skipped"] == 2  # corrupt + short, thrown away by the backend
        assert frame.meta["dropped"] == 2  # sequence gap: frames the driver lost


def test_read_timeout(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        cam.start()
        t0 = time.monotonic()
        with pytest.raises(CameraTimeout, match="no frame within 0.2 s"):
            cam.read(timeout=0.2)
        assert 0.19 <= time.monotonic() - t0 < 1.5
        with pytest.raises(ValueError):
            cam.read(timeout=0)


def test_a_timeout_after_skipped_frames_says_which_and_why(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        cam.set_trigger("free")
        cam.start()
        fake.emit(np.full((6, 12), 1), error=True)  # a USB bus short of bandwidth: every frame flagged
        fake.emit(np.full((6, 12), 2), error=True)
        fake.emit(np.full((6, 12), 3), bytesused=10)
        with pytest.raises(CameraTimeout) as info:
            cam.read(timeout=0.2)
        assert str(info.value) == (
            f"v4l2 {fake.path}: no usable frame within 0.2 s: 3 came and were skipped, 2 flagged corrupt by the "
            "driver (V4L2_BUF_FLAG_ERROR: a USB bus short of bandwidth, a loose cable?); 1 shorter than a GREY "
            "12x6 frame (bytesused up to 10 of 92)"
        )
        cam.stop()
        cam.set_trigger("software")
        cam.start()
        cam.trigger()
        for k in range(2):  # a driver whose monotonic timestamps lag the host's by 50 s: every frame looks early
            fake.emit(np.full((6, 12), k), timestamp=time.monotonic() - 50)
        with pytest.raises(CameraTimeout, match=r"no usable frame within 0\.2 s: 2 came and were skipped, 2 ") as info:
            cam.read(timeout=0.2)
        assert re.search(
            r"2 timestamped before the software trigger, by up to (50|49\.\d) s \(a driver clock", str(info.value)
        )
        with pytest.raises(CameraTimeout, match=r"no frame within 0\.2 s \(is the device streaming"):
            cam.read(timeout=0.2)  # nothing came: the message of a device that sends nothing


def test_read_waits_in_poll_for_a_late_frame(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        cam.set_trigger("free")
        cam.start()
        timer = fake.emit_later(0.15, np.full((6, 12), 9))
        t0 = time.monotonic()
        frame = cam.read(timeout=2.0)
        timer.join()
        assert 0.1 < time.monotonic() - t0 < 1.5 and frame.image[0, 0] == 9


def test_read_before_start(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        with pytest.raises(CameraError, match="start"):
            cam.read(0.1)
        with pytest.raises(CameraError, match="start"):
            cam.trigger()


def test_settings_need_acquisition_stopped(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        cam.start()
        with pytest.raises(CameraError, match="stop"):
            cam.set_pixel_format("Y16")
        with pytest.raises(CameraError, match="stop"):
            cam.set_roi(0, 0, 4, 4)
        cam.stop()
        cam.set_pixel_format("Y16")
        cam.start()  # restart with new buffers
        fake.emit(sensor_image(fake, 65536))
        assert cam.read(1.0).image.dtype == np.uint16


def test_closed_camera(fake):
    cam = V4L2Camera({"device": fake.path})
    with pytest.raises(CameraError, match="not open"):
        cam.read(0.1)


def test_a_usb_bus_short_of_bandwidth_is_named_not_a_full_disk(fake):
    def no_bandwidth(arg):  # uvcvideo: no alternate setting of the interface has the bandwidth the format needs
        raise _err(errno.ENOSPC)

    with V4L2Camera({"device": fake.path, "pixel_format": "YUYV"}) as cam:
        with mock.patch.object(fake, "_ioc_STREAMON", no_bandwidth):
            with pytest.raises(CameraError) as info:
                cam.start()
        assert str(info.value) == (
            f"v4l2 {fake.path}: the driver refused to start streaming YUYV 12x6 frames (ENOSPC: for a USB camera, "
            "the bus lacks the bandwidth for them, the disk is not full): put the camera on another USB controller "
            "or stream fewer cameras from this one, or ask for smaller frames (config width and height)"
        )
        assert fake.buffers == [] and not cam._maps  # unmapped and freed
        cam.start()  # bandwidth back (another camera stopped): it streams
        fake.emit(sensor_image(fake))
        assert cam.read(1.0).image.shape == (6, 12)


@pytest.mark.parametrize("step", ["QUERYBUF", "mmap"])
def test_a_start_that_fails_before_any_mapping_frees_the_driver_buffers(fake, step):
    def refuse(*args, **kwargs):
        raise _err(errno.ENOMEM)

    with V4L2Camera({"device": fake.path}) as cam:
        where = ("linuxpy.video.device.mmap", SimpleNamespace(mmap=refuse))
        with mock.patch.object(fake, "_ioc_QUERYBUF", refuse) if step == "QUERYBUF" else mock.patch(*where):
            with pytest.raises(CameraError, match=r"Cannot allocate memory"):
                cam.start()
        assert fake.buffers == [] and fake.log[-1] == "REQBUFS"  # REQBUFS(0): the driver holds no buffers
        cam.set_pixel_format("Y16")  # S_FMT, which a driver holding buffers refuses with EBUSY
        cam.start()
        fake.emit(sensor_image(fake, 65536))
        assert cam.read(1.0).image.dtype == np.uint16


# ====================================================================== disconnect
def test_unplugged_while_idle(fake):
    cam = V4L2Camera({"device": fake.path}).open()
    cam.start()
    fake.unplug()
    t0 = time.monotonic()
    with pytest.raises(CameraDisconnected, match="went away"):
        cam.read(timeout=5.0)
    assert time.monotonic() - t0 < 1.0  # poll woke at once, not at the timeout
    with pytest.raises(CameraDisconnected):
        cam.set_exposure(0.01)
    cam.close()  # never raises
    assert fake.file.closed
    with pytest.raises(CameraError, match="no such device"):  # the node is gone
        cam.open()


def test_unplugged_while_waiting(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        cam.start()
        timer = threading.Timer(0.1, fake.unplug)
        timer.start()
        t0 = time.monotonic()
        with pytest.raises(CameraDisconnected):
            cam.read(timeout=5.0)
        timer.join()
        assert time.monotonic() - t0 < 2.0


def test_unplugged_mid_capture_ends_in_one_line_that_says_what_was_kept(fake, tmp_path):
    from rsocl.hardware.capture import CaptureFailed, capture_sets
    from rsocl.hardware.capture_file import load_raw

    rig = tmp_path / "rig.toml"
    rig.write_text(
        f'[rig]\nshape = [6, 12]\n\n[[camera]]\nbackend = "v4l2"\naddress = "{fake.path}"\nangle = 0.0\n'
        "t_e = 0.001\nt_r = 0.001\n"
    )
    fds = sorted(os.listdir("/proc/self/fd"))
    dequeued = []  # frames the backend took: a set takes at most 5 (4 thrown away by the trigger, 1 read)
    take = fake._ioc_DQBUF
    fake._ioc_DQBUF = lambda arg: (take(arg), dequeued.append(arg.index))

    def sensor():  # a frame every 2 ms; the cable is pulled once the backend has taken 12: after set 0 at least
        for k in range(5000):
            if len(dequeued) >= 12:
                break
            time.sleep(0.002)
            fake.emit(sensor_image(fake, seed=k))
        fake.unplug()

    thread = threading.Thread(target=sensor, daemon=True)
    thread.start()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(
            CaptureFailed, match=r"(trigger|read) failed in set \d+: CameraDisconnected: .*went away"
        ) as info:
            capture_sets(rig, tmp_path / "c.h5", sets=100, timeout=5.0)
    thread.join()
    raw = load_raw(tmp_path / "c.h5")
    kept = raw.sets_complete
    assert kept >= 1 and raw.frames[0].shape == (kept, 6, 12) and raw.status == "failed"
    assert f"({kept} complete set(s) and the failure are in {tmp_path / 'c.h5'})" in str(info.value)
    assert [str(w.message) for w in caught] == [] and raw.meta["warnings"] == []  # no 'stop failed' besides
    assert sorted(os.listdir("/proc/self/fd")) == fds and fake.file.closed  # the device closed, nothing leaked


# ====================================================================== trigger
def test_line_trigger_is_not_supported(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        with pytest.raises(CameraError, match="free-running"):
            cam.set_trigger("line", "Line1")


def test_software_trigger_takes_the_next_frame(fake):
    with V4L2Camera({"device": fake.path, "buffers": 4}) as cam:
        cam.set_trigger("software")
        cam.start()
        fake.emit(np.full((6, 12), 1))  # completed before the trigger: stale
        fake.emit(np.full((6, 12), 2))
        cam.trigger()
        assert fake.done == [] and len(fake.queued) == 4  # thrown away and requeued
        fake.emit(np.full((6, 12), 3), timestamp=time.monotonic() - 5)  # completed after, started before
        fake.emit(np.full((6, 12), 4))
        frame = cam.read(1.0)
        assert frame.image[0, 0] == 4 and frame.meta["sequence"] == 3


def test_capture_is_trigger_then_read(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        cam.start()  # default trigger mode: software
        fake.emit(np.full((6, 12), 7))  # stale
        timer = fake.emit_later(0.05, np.full((6, 12), 8))
        frame = cam.capture(timeout=2.0)
        timer.join()
        assert frame.image[0, 0] == 8


def test_free_running_reads_the_oldest_completed_frame(fake):
    with V4L2Camera({"device": fake.path}) as cam:
        cam.set_trigger("free")
        cam.start()
        fake.emit(np.full((6, 12), 1), timestamp=1.0)
        fake.emit(np.full((6, 12), 2), timestamp=2.0)
        assert cam.capture(1.0).image[0, 0] == 1  # no trigger in free mode
        assert cam.read(1.0).image[0, 0] == 2


# ====================================================================== ROI
def test_software_roi_without_selection_api(fake):
    image = sensor_image(fake)
    with V4L2Camera({"device": fake.path}) as cam:
        cam.set_roi(2, 1, 5, 3)
        assert "S_SELECTION" not in fake.log and fake.crop == [0, 0, 12, 6]
        cam.start()
        fake.emit(image)
        frame = cam.read(1.0)
        np.testing.assert_array_equal(frame.image, image[1:4, 2:7])
        assert frame.meta["roi"] == "software" and frame.image.flags.c_contiguous
        cam.stop()
        with pytest.raises(ValueError) as info:  # in the rig file's order, with the bounds
            cam.set_roi(8, 0, 5, 2)
        assert str(info.value) == (
            f"v4l2 {fake.path}: roi = [8, 0, 5, 2] ([x, y, width, height]) must lie on the 12x6 (width x height) "
            "frame: x, y >= 0, x + width <= 12 and y + height <= 6"
        )
        cam.set_roi(0, 0, 12, 6)  # the full frame: no crop
        cam.start()
        fake.emit(image)
        frame = cam.read(1.0)
        np.testing.assert_array_equal(frame.image, image.astype(np.uint8))
        assert frame.meta["roi"] is None


@pytest.mark.parametrize("name", ["GREY", "Y16", "YUYV"])
def test_hardware_roi_with_selection_api(make_fake, name):
    fake = make_fake(selection=True)
    image = sensor_image(fake, 256)
    with V4L2Camera({"device": fake.path, "pixel_format": name}) as cam:
        cam.set_roi(2, 1, 6, 4)
        assert fake.crop == [2, 1, 6, 4] and cam.frame_size == (6, 4)  # the driver delivers 6x4
        cam.start()
        fake.emit(image)
        frame = cam.read(1.0)
        np.testing.assert_array_equal(frame.image, image[1:5, 2:8])
        assert frame.meta["roi"] == "hardware"


def test_hardware_roi_rounded_outwards_is_finished_in_software(make_fake):
    fake = make_fake(selection=True, crop_align=4)
    image = sensor_image(fake)
    with V4L2Camera({"device": fake.path}) as cam:
        cam.set_roi(3, 1, 5, 2)  # the driver crops (0, 0, 8, 4)
        assert fake.crop == [0, 0, 8, 4]
        cam.start()
        fake.emit(image)
        frame = cam.read(1.0)
        np.testing.assert_array_equal(frame.image, image[1:3, 3:8])
        assert frame.meta["roi"] == "hardware"
        cam.stop()
        with pytest.raises(
            ValueError, match=r"roi = \[10, 0, 4, 2\] \(\[x, y, width, height\]\) must lie on the 12x6 "
        ):
            cam.set_roi(10, 0, 4, 2)


# ====================================================================== a real device
def _capture_nodes():
    return sorted(glob.glob("/dev/video*"))


@pytest.mark.v4l2_device
@pytest.mark.skipif(
    not _capture_nodes(),
    reason="no /dev/video* device on this machine: the backend is covered by "
    "the fake-device tests above; run on a machine with a webcam (or `modprobe vivid`); "
    "RSOCL_V4L2_DEVICE picks the node",
)
def test_real_device():
    pytest.importorskip("linuxpy.video.device", reason='linuxpy not installed (pip install "rsocl[v4l2]")')
    wanted = os.environ.get("RSOCL_V4L2_DEVICE")
    nodes = [wanted] if wanted else _capture_nodes()
    errors = []
    for node in nodes:
        cam = V4L2Camera({"device": node})
        try:
            cam.open()
        except CameraError as exc:  # metadata nodes, MJPG-only cameras, busy devices...
            errors.append(str(exc))
            continue
        with cam:
            try:
                exposure = cam.set_exposure(0.01)
                assert exposure > 0
            except CameraError as exc:
                if "no exposure_time_absolute" not in str(exc):
                    raise
            cam.set_trigger("software")
            cam.start()
            try:
                frame = cam.capture(timeout=5.0)
                frame2 = cam.capture(timeout=5.0)
            finally:
                cam.stop()
            width, height = cam.frame_size
            assert frame.image.shape == (height, width)
            assert frame.image.dtype == (np.uint8 if cam.pixel_format in ("GREY", "YUYV") else np.uint16)
            assert frame2.timestamp > frame.timestamp and frame2.meta["sequence"] > frame.meta["sequence"]
            with pytest.raises(CameraError):
                cam.set_trigger("line", "Line1")
        return
    pytest.skip(f"no /dev/video* node this backend can read: {errors}")
