"""The ground truth a capture of simulated cameras stores beside set 0: a bonus, never a reason to fail a capture.

:func:`set_truth` is the datacube every camera tells (the ``simulated`` backend's ``scene_truth``) where all tell
the same one of the rig's shape; :func:`room_for` keeps it only where the disk and the process's file-size limit
leave room for it beside the sets.
Each says why there is none through ``warn`` (:meth:`rsocl.hardware.capture_file.CaptureWriter.warn`).
"""

from __future__ import annotations

import numpy as np

from rsocl.hardware.capture_room import room_on_disk, room_under_limit

__all__ = ["set_truth", "room_for"]


def set_truth(cameras, rig, warn):
    """Set 0's datacube ``(T, m, n)`` float64 as every camera of ``cameras`` tells it, or None (with ``warn``'s
    reason where a camera could tell one)."""
    if not all(callable(getattr(cam, "scene_truth", None)) for cam in cameras):
        return None
    try:
        truths = [np.asarray(cam.scene_truth(0), dtype=np.float64) for cam in cameras]
    except Exception as exc:  # the truth is a bonus, never a reason to fail a capture
        warn(f"no ground truth: {type(exc).__name__}: {exc}")
        return None
    truth = truths[0]
    for i, other in enumerate(truths[1:], start=1):
        if other.shape != truth.shape or not np.array_equal(other, truth):
            warn(
                f"no ground truth: camera {i} sees another scene than camera 0 (their [camera.config] "
                "scene, scene_seed or scene_sets differ), so no one datacube is the truth of this capture"
            )
            return None
    if truth.ndim == 3 and truth.shape[0] > rig.T:  # the scene outlasts the exposures: its first T
        truth = truth[: rig.T]
    if truth.shape != (rig.T,) + rig.shape:
        warn(f"no ground truth: the scene has shape {truth.shape}, the rig needs {(rig.T,) + rig.shape}")
        return None
    return truth


def room_for(truth, folder, sets_bytes: int, warn, file_size: int = 0):
    """``truth``, or None (with a warning) where the disk of ``folder``
    (:func:`~rsocl.hardware.capture_room.room_on_disk`) or the process's file-size limit for a capture file
    of ``file_size`` bytes (:func:`~rsocl.hardware.capture_room.room_under_limit`) has no room for it and,
    twice over, for the ``sets_bytes`` of every set asked for: the sets come first."""
    if truth is None:
        return None
    free = room_on_disk(folder)
    limit = room_under_limit(file_size)
    if free >= truth.nbytes + 2 * sets_bytes and (limit is None or limit >= truth.nbytes + 2 * sets_bytes):
        return truth
    room = (
        f"the disk has {free / 2**20:.1f} MiB free beside HDF5's metadata"
        if limit is None or free <= limit
        else f"the file-size limit (ulimit -f) leaves the capture file {limit / 2**20:.1f} MiB"
    )
    warn(f"no ground truth stored: it takes {truth.nbytes / 2**20:.1f} MiB and {room}, which the sets asked for need")
    return None
