"""V4L2 pixel formats the ``v4l2`` camera backend reads, and their conversion to images.

``GREY`` -> uint8 (``bit_depth`` 8); ``Y16`` -> uint16 (``bit_depth`` 16); ``Y10`` and ``Y12``
-> uint16 of levels 0..1023 (``bit_depth`` 10) and 0..4095 (``bit_depth`` 12): one pixel per
16-bit word, its value in the low bits, as industrial and embedded greyscale sensors deliver them.
The 16-bit formats are little endian in the V4L2 buffer, converted to native order; their values
are kept as the driver wrote them. ``YUYV`` -> the Y (luma) channel only, uint8 — the chroma bytes
are dropped. Line padding (``bytesperline > width * bytes_per_pixel``, bytes) is removed.
Compressed formats (MJPG, H264) and packed greyscale formats (``Y10P``, ``Y12P``, ``Y14P``,
``Y10BPACK``, ``IPU3_Y10``: several pixels in fewer bytes than 16 bits each) are not read.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PIXEL_FORMATS", "PACKED_FORMATS", "convert_frame", "packed_note"]

#: name -> (bytes per pixel in the V4L2 buffer, significant bits of the returned image), in the order the
#: backend picks a default from those a device offers: GREY, the 16-bit greyscale words deepest first, YUYV.
PIXEL_FORMATS = {"GREY": (1, 8), "Y16": (2, 16), "Y12": (2, 12), "Y10": (2, 10), "YUYV": (2, 8)}

#: Packed greyscale formats (not read) -> how they pack their pixels.
PACKED_FORMATS = {
    "Y10P": "MIPI CSI-2 packed, 4 pixels in 5 bytes",
    "Y12P": "MIPI CSI-2 packed, 2 pixels in 3 bytes",
    "Y14P": "MIPI CSI-2 packed, 4 pixels in 7 bytes",
    "Y10BPACK": "bit-packed big endian, 4 pixels in 5 bytes",
    "IPU3_Y10": "IPU3 packed, 25 pixels in 32 bytes",
}


_WORD = "one pixel per 16-bit word"


def packed_note(names) -> str:
    """What a message about formats the backend does not read adds for the packed ones among ``names``:
    ``"; Y10P is packed (MIPI CSI-2 packed, 4 pixels in 5 bytes), which this backend does not unpack (it reads
    Y10 and Y12, one pixel per 16-bit word)"``, or ``""`` when none is packed."""
    packed = [f"{name} is packed ({PACKED_FORMATS[name]})" for name in names if name in PACKED_FORMATS]
    if not packed:
        return ""
    return f"; {', '.join(packed)}, which this backend does not unpack (it reads Y10 and Y12, {_WORD})"


def convert_frame(data, pixel_format: str, width: int, height: int, bytes_per_line: int = 0) -> np.ndarray:
    """Raw V4L2 buffer bytes -> 2-D image (``GREY``/``YUYV`` -> uint8, ``Y16``/``Y12``/``Y10`` -> uint16).

    ``YUYV`` gives the Y channel; ``Y16``, ``Y12`` and ``Y10`` are read little endian, one pixel per
    16-bit word; line padding is removed. ``width`` and ``height`` are pixels, ``bytes_per_line``
    bytes (0: no padding). ``data`` shorter than ``bytes_per_line * height`` is accepted as long as
    it holds the last line's pixels (drivers may omit the last line's padding).
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
    else:  # Y16, Y12, Y10: two bytes per pixel, least significant first
        image = np.ascontiguousarray(rows[:, : 2 * width]).view("<u2").astype(np.uint16, copy=False)
    return np.array(image, dtype=image.dtype, order="C", copy=True)  # writeable, owns its memory
