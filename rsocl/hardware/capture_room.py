"""Room for the capture file: on its disk, and under the process's file-size limit (``ulimit -f``,
``RLIMIT_FSIZE``).

A write past the limit (EFBIG: Python ignores SIGXFSZ) or onto a full disk (ENOSPC) fails part way
through HDF5's own bookkeeping and leaves a file HDF5 cannot read, though the sets written before it
were whole. So the capture asks first: before each set (:func:`set_bytes`: a frame per camera, the
registered set and, for set 0, its copy in ``snapshots``) and before each frame it writes,
:func:`check_room` raises :class:`FileSizeLimit` where the file would have less room left under the
limit than twice the data and :data:`SLACK` for HDF5's metadata, and :class:`DiskFull` where its disk
has less free. The capture then ends as it does when a write fails: the complete sets are kept,
readable, and the failure is recorded. (Another process filling the same disk between two checks
can still make a write fail.) :func:`room_under_limit` bounds the ground truth's room as well
(:func:`rsocl.hardware.capture_truth.room_for`), and :func:`check_limit` refuses, before any camera opens,
a limit that leaves no room for a capture file at all.
"""

from __future__ import annotations

import os
import shutil

import numpy as np

try:
    import resource
except ImportError:  # no resource limits on this system (Windows)
    resource = None  # type: ignore[assignment]

__all__ = [
    "SLACK",
    "NoRoom",
    "FileSizeLimit",
    "DiskFull",
    "file_size_limit",
    "room_on_disk",
    "room_under_limit",
    "check_limit",
    "check_room",
    "set_bytes",
]

#: Bytes kept free under the limit beside twice the data: HDF5's metadata (chunk indexes, heaps, the
#: status and ``meta`` attributes the capture writes after its last set).
SLACK = 2**18

#: Bytes per pixel taken for a camera's frame before its first arrives (the widest a backend delivers).
UNKNOWN_PIXEL_BYTES = 8


class NoRoom(RuntimeError):
    """What comes next has no room in the capture file (:class:`FileSizeLimit`, :class:`DiskFull`)."""


class FileSizeLimit(NoRoom):
    """What comes next would take the capture file past the process's file-size limit."""


class DiskFull(NoRoom):
    """What comes next would leave the capture file's disk with less free than it needs."""


def file_size_limit() -> int | None:
    """The process's file-size limit (``RLIMIT_FSIZE``'s soft limit), bytes, or None where there is none."""
    if resource is None:
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    return None if soft == resource.RLIM_INFINITY else int(soft)


def room_on_disk(folder) -> int:
    """Bytes free on the disk of ``folder`` beyond :data:`SLACK` kept for HDF5's metadata (negative where
    the disk has less than that)."""
    return shutil.disk_usage(folder).free - SLACK


def room_under_limit(size: int) -> int | None:
    """Bytes a file of ``size`` bytes may still grow by under the file-size limit, :data:`SLACK` kept for
    HDF5's metadata (0 at least), or None where there is no limit."""
    limit = file_size_limit()
    return None if limit is None else max(0, limit - int(size) - SLACK)


def check_limit() -> None:
    """Refuse (a ValueError) a file-size limit that leaves no room for a capture file: at most :data:`SLACK`."""
    limit = file_size_limit()
    if limit is not None and limit <= SLACK:
        raise ValueError(
            f"this process's file-size limit (ulimit -f) of {limit:,} bytes leaves no room for a capture "
            f"file, which takes more than {SLACK:,} bytes beside its sets (HDF5's metadata); raise the limit"
        )


def check_room(size: int, data_bytes: int, what: str, path=None) -> None:
    """Raise :class:`FileSizeLimit` where ``what`` (``data_bytes`` of data) does not fit, twice over, in the
    room a file of ``size`` bytes has left under the process's file-size limit (:func:`room_under_limit`), and
    :class:`DiskFull` where the disk of the file ``path`` (None: not asked) has less free than twice the data and
    :data:`SLACK`."""
    if path is not None:
        folder = os.path.dirname(os.path.abspath(os.fspath(path)))
        on_disk = room_on_disk(folder)
        if on_disk < 2 * int(data_bytes):
            raise DiskFull(
                f"{what} would fill the disk of {folder}: it has {on_disk + SLACK:,} bytes free, and {what} needs room "
                f"for its {int(data_bytes):,} bytes twice over and {SLACK:,} for HDF5's metadata; free space on it "
                "or capture fewer sets"
            )
    room = room_under_limit(size)
    if room is not None and 2 * int(data_bytes) > room:
        raise FileSizeLimit(
            f"{what} would take the capture file past this process's file-size limit (ulimit -f) of "
            f"{file_size_limit():,} bytes: it holds {int(size):,} bytes, and {what} needs room for its "
            f"{int(data_bytes):,} bytes twice over and {SLACK:,} for HDF5's metadata; raise the limit or "
            "capture fewer sets"
        )


def set_bytes(h5, rig, cameras: list, first: bool) -> int:
    """Bytes of data a set adds to the capture file ``h5``: a frame per camera (the size of its frames in
    ``raw/<i>``; before its first, its ``roi``'s pixels (``cameras[i]``, the settings ``meta`` records) or
    the rig's, at :data:`UNKNOWN_PIXEL_BYTES` each), the registered set (float64) and, where ``first``, its
    copy in ``snapshots``."""
    m, n = rig.shape
    total = (2 if first else 1) * rig.n_channels * m * n * 8
    for i, settings in enumerate(cameras):
        raw = h5.get(f"raw/{i}")
        if raw is not None:
            total += int(np.prod(raw.shape[1:])) * raw.dtype.itemsize
        else:
            roi = settings.get("roi")
            total += (roi[2] * roi[3] if roi else m * n) * UNKNOWN_PIXEL_BYTES
    return total
