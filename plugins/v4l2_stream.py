"""mmap streaming I/O of a ``v4l2`` camera: :class:`V4L2Stream`, a mixin of :class:`~rsocl_plugins.v4l2.V4L2Camera`.

``start`` queues ``buffers`` mmap buffers in the driver and turns streaming on (a start that fails unmaps
and frees them, so the pixel format and ROI can be changed again; a driver that refuses to stream with
``ENOSPC``, uvcvideo's answer when the USB bus lacks the bandwidth, is a CameraError that says so); ``read`` waits
with ``poll``, dequeues a completed buffer, copies the image out and queues the buffer again.

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
    raises :class:`~rsocl.hardware.backend.CameraDisconnected` (``stop()`` and ``close()`` still work
    and raise nothing for it; re-open to use it again); everything else is a
    :class:`~rsocl.hardware.backend.CameraError`. Frames the driver flags as corrupt
    (``V4L2_BUF_FLAG_ERROR``) or that are shorter than the format are skipped and counted in
    ``meta["skipped"]``. A timeout after skipped frames says how many and why (corrupt, short, or
    timestamped before the software trigger), with the largest bytesused or lag (seconds) among them.
"""

from __future__ import annotations

import errno
import math
import select
import time

import numpy as np

from rsocl.hardware.backend import CameraError, CameraTimeout, Frame
from rsocl_plugins.v4l2_device import GONE, os_errors
from rsocl_plugins.v4l2_formats import PIXEL_FORMATS, convert_frame

__all__ = ["V4L2Stream"]

_BUF_FLAG_ERROR = 0x40
_BUF_TIMESTAMP_MASK = 0xE000
_BUF_TIMESTAMP_CLOCKS = {0x0: "unknown", 0x2000: "monotonic", 0x4000: "copy"}
_BUF_TSTAMP_SRC_MASK = 0x70000
_BUF_TSTAMP_SOURCES = {0x0: "end-of-frame", 0x10000: "start-of-exposure"}


class V4L2Stream:
    """The camera hooks ``_start``, ``_stop`` and ``_read``, and the buffer queue under them.

    Uses the camera's open device (``_lvd``, ``_dev``), ``n_buffers``, its format (``_fmt``,
    ``_read_format``), trigger state (``_trigger_mode``, ``_trigger_time``) and ROI state
    (``_soft_roi``, ``_roi_kind``); keeps the mappings (``_maps``), ``_streaming``, the last
    driver sequence number and the count of skipped frames.
    """

    # ---------------------------------------------------------------- capture
    @os_errors
    def _start(self):
        if self._streaming:
            return
        lvd, dev = self._lvd, self._dev
        capture, mmap_memory = lvd.BufferType.VIDEO_CAPTURE, lvd.Memory.MMAP
        self._read_format(self._fmt["name"])
        requested = False  # the driver holds buffers: freed on failure, else S_FMT and S_SELECTION get EBUSY
        try:
            req = lvd.request_buffers(dev, capture, mmap_memory, self.n_buffers)
            requested = True
            fd = dev.fileno()
            for index in range(req.count):
                buff = lvd.query_buffer(dev, capture, mmap_memory, index)
                self._maps.append(lvd.mem_map(fd, buff.length, buff.m.offset))
            for index in range(req.count):
                lvd.enqueue_buffer(dev, capture, mmap_memory, 0, index)
            try:
                lvd.stream_on(dev, capture)
            except OSError as exc:
                if exc.errno != errno.ENOSPC:
                    raise
                raise CameraError(self._no_bandwidth()) from exc
        except BaseException:
            self._release_buffers(dev, free=requested)
            raise
        self._streaming = True
        self._last_sequence, self._dropped = None, 0
        self._trigger_time = None

    def _no_bandwidth(self):
        """What STREAMON's ENOSPC ("No space left on device") says: uvcvideo's answer when the USB bus lacks
        the bandwidth for the frames asked for, not a full disk."""
        fmt = self._fmt
        return (
            f"{self.name}: the driver refused to start streaming {fmt['name']} {fmt['width']}x{fmt['height']} "
            "frames (ENOSPC: for a USB camera, the bus lacks the bandwidth for them, the disk is not full): "
            "put the camera on another USB controller or stream fewer cameras from this one, or ask for smaller "
            "frames (config width and height)"
        )

    @os_errors
    def _stop(self):
        if not self._streaming and not self._maps:
            return
        lvd, dev = self._lvd, self._dev
        try:
            try:
                if self._streaming:
                    lvd.stream_off(dev, lvd.BufferType.VIDEO_CAPTURE)
            finally:
                self._streaming = False
                self._release_buffers(dev, free=True)
        except OSError as exc:
            if exc.errno not in GONE:
                raise
            # unplugged: nothing streams; the kernel frees the buffers when the descriptor closes

    def _release_buffers(self, dev, free):
        maps, self._maps = self._maps, []
        for mm in maps:
            try:
                mm.close()
            except Exception:
                pass
        if free and dev is not None:
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
        """``(sequence, dropped)`` of a dequeued buffer: the driver's gaps since the last frame returned, the
        gaps before buffers skipped since (corrupt, early, drained by ``trigger()``) included."""
        seq = int(buff.sequence)
        gap = 0 if self._last_sequence is None else max(0, seq - self._last_sequence - 1)
        self._last_sequence = seq
        self._dropped += gap
        return seq, self._dropped

    @os_errors
    def _read(self, timeout):
        if not self._streaming:
            raise CameraError(f"{self.name}: not acquiring; call start() first")
        deadline = time.monotonic() + timeout
        self._passed_over = {}  # frames this read skips, for its timeout's message: see _pass_over
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
                raise self._timeout(timeout)
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

    def _frame_bytes(self):
        """Bytes a frame of the format needs: every line but the last padded to ``bytesperline``."""
        fmt = self._fmt
        return fmt["bpl"] * (fmt["height"] - 1) + fmt["width"] * PIXEL_FORMATS[fmt["name"]][0]

    def _pass_over(self, why, detail):
        """Count a frame ``read`` skips: ``why`` is ``"corrupt"``, ``"short"`` (``detail``: its bytesused) or
        ``"early"`` (``detail``: seconds its timestamp is before the trigger); the largest ``detail`` is kept."""
        count, most = self._passed_over.get(why, (0, detail))
        self._passed_over[why] = (count + 1, max(most, detail))

    def _timeout(self, timeout):
        """The CameraTimeout of a ``read`` that got no frame in ``timeout`` seconds, naming the frames it skipped."""
        if not self._passed_over:
            return CameraTimeout(
                f"{self.name}: no frame within {timeout:g} s (is the device streaming? "
                "a long exposure or a low frame rate needs a longer timeout)"
            )
        fmt = self._fmt
        words = {
            "corrupt": "flagged corrupt by the driver (V4L2_BUF_FLAG_ERROR: a USB bus short of bandwidth, a "
            "loose cable?)",
            "short": "shorter than a {name} {width}x{height} frame (bytesused up to {detail} of {need})",
            "early": "timestamped before the software trigger, by up to {detail:.3g} s (a driver clock behind "
            "time.monotonic() makes every frame look early)",
        }
        parts = [
            f"{count} {words[why].format(detail=detail, need=self._frame_bytes(), **fmt)}"
            for why, (count, detail) in self._passed_over.items()
        ]
        total = sum(count for count, _ in self._passed_over.values())
        return CameraTimeout(
            f"{self.name}: no usable frame within {timeout:g} s: {total} came and were skipped, {'; '.join(parts)}"
        )

    def _frame_from(self, buff):
        """Copy a dequeued buffer out, requeue it; None for a frame to skip."""
        host_time = time.time()
        index = int(buff.index)
        try:
            seq, dropped = self._note_sequence(buff)
            flags = int(buff.flags)
            stamp = int(buff.timestamp.secs) + int(buff.timestamp.usecs) * 1e-6
            clock = _BUF_TIMESTAMP_CLOCKS.get(flags & _BUF_TIMESTAMP_MASK, "unknown")
            if (
                self._trigger_mode == "software"
                and self._trigger_time is not None
                and clock == "monotonic"
                and stamp > 0
                and stamp < self._trigger_time
            ):
                self._pass_over("early", self._trigger_time - stamp)
                return None  # completed after trigger() but started before it
            fmt = self._fmt
            used = int(buff.bytesused)
            if flags & _BUF_FLAG_ERROR or used < self._frame_bytes():
                self._pass_over("corrupt" if flags & _BUF_FLAG_ERROR else "short", used)
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
        self._skipped = self._dropped = 0
        return Frame(
            image=image, timestamp=stamp, pixel_format=fmt["name"], bit_depth=PIXEL_FORMATS[fmt["name"]][1], meta=meta
        )
