"""V4L2 pixel formats the ``v4l2`` camera backend reads, and their conversion to images.

``GREY`` -> uint8; ``Y16`` -> uint16 (the V4L2 layout is little endian, converted to
native order; ``bit_depth`` 16); ``YUYV`` -> the Y (luma) channel only, uint8 — the
chroma bytes are dropped. Line padding (``bytesperline > width * bytes_per_pixel``)
is removed. Compressed formats (MJPG, H264) are not read.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PIXEL_FORMATS", "convert_frame"]

#: name -> (bytes per pixel in the V4L2 buffer, significant bits of the returned image)
PIXEL_FORMATS = {"GREY": (1, 8), "Y16": (2, 16), "YUYV": (2, 8)}


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
