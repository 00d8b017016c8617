"""GenICam pixel formats the ``aravis`` camera backend reads, and the conversion of a buffer's bytes.

``Mono8`` -> uint8 (``bit_depth`` 8); ``Mono12`` (unpacked, 12 bits in 16) and ``Mono16`` ->
uint16 (``bit_depth`` 12 / 16; the GenICam layout is little endian, converted to native
order). Row padding reported by the buffer is removed. Packed formats (``Mono12p``,
``Mono12Packed``) and colour formats are not read. ``set_pixel_format`` raises
:class:`~rsocl.hardware.backend.CameraError` listing the device's formats when it lacks the one asked.
"""

from __future__ import annotations

import numpy as np

from rsocl.hardware.backend import CameraError

__all__ = ["PIXEL_FORMATS", "BY_CODE", "convert_buffer"]

#: name -> (GenICam PFNC code, numpy dtype of the buffer, significant bits)
PIXEL_FORMATS = {"Mono8": (0x01080001, "u1", 8), "Mono12": (0x01100005, "<u2", 12), "Mono16": (0x01100007, "<u2", 16)}
#: GenICam PFNC code -> name
BY_CODE = {code: name for name, (code, _, _) in PIXEL_FORMATS.items()}


def convert_buffer(data, pixel_format: str, width: int, height: int, x_padding: int = 0) -> np.ndarray:
    """Image bytes of a GenICam buffer -> 2-D array (``Mono8`` uint8, ``Mono12``/``Mono16`` native uint16).

    ``x_padding`` is the number of bytes after each row. Always returns a new, writable array.
    """
    if pixel_format not in PIXEL_FORMATS:
        raise CameraError(f"pixel format {pixel_format!r} is not supported; use one of {list(PIXEL_FORMATS)}")
    dtype = np.dtype(PIXEL_FORMATS[pixel_format][1])
    width, height, x_padding = int(width), int(height), int(x_padding)
    row = width * dtype.itemsize
    stride = row + max(x_padding, 0)
    need = stride * (height - 1) + row if height > 0 else 0
    raw = np.frombuffer(data, dtype=np.uint8)
    if width < 1 or height < 1 or raw.size < need:
        raise CameraError(
            f"{pixel_format} buffer of {raw.size} bytes is too small for {width}x{height} pixels "
            f"(row padding {x_padding} bytes; needs {need})"
        )
    rows = np.lib.stride_tricks.as_strided(raw, shape=(height, row), strides=(stride, 1))
    return np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("="), copy=True).reshape(height, width)
