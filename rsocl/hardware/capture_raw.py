"""Reading back the raw side of a capture file that :func:`rsocl.hardware.capture.capture_sets` wrote.

The layout is in :mod:`rsocl.hardware.capture_file` (which re-exports :func:`load_raw` and
:class:`RawCapture`). Times are seconds.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

__all__ = ["RawCapture", "load_raw"]


# ---------------------------------------------------------------------- reading
@dataclass(frozen=True)
class RawCapture:
    """The raw side of a file written by :func:`~rsocl.hardware.capture.capture_sets`.

    Attributes
    ----------
    frames : list of ndarray
        Per camera, ``(N_i, h, w)`` frames as delivered (``N_i`` may differ after a failure).
    sets, timestamps : list of ndarray
        Per camera and frame: set index, timestamp (s).
    frame_meta : list of list of dict
        Per camera and frame: the backend's metadata (plus pixel format and bit depth).
    snapshot_sets : ndarray, shape (S, K, m, n), or None
        The complete sets (the first ``sets_complete`` rows), registered, model units.
    status : str
        ``"complete"``, ``"failed"``, ``"interrupted"`` (or ``"running"`` in a ``.partial`` file).
    sets_complete : int
    failure : dict or None
        ``camera``, ``set``, ``phase``, ``type``, ``error``.
    meta : dict
        The capture's ``meta`` attribute.
    """

    frames: list
    sets: list
    timestamps: list
    frame_meta: list
    snapshot_sets: np.ndarray | None
    status: str
    sets_complete: int
    failure: dict | None
    meta: dict


def load_raw(path) -> RawCapture:
    """Read the raw frames, their metadata and the capture status of a capture file (or its ``.partial``)."""
    from rsocl.files.hdf5_header import open_checked, str_attr

    with open_checked(path, "capture") as h5:
        n_cameras = int(h5.attrs["n_cameras"])
        frames, sets, stamps, metas = [], [], [], []
        for i in range(n_cameras):
            if f"raw/{i}" in h5:
                frames.append(h5[f"raw/{i}"][()])
                group = h5[f"raw_meta/{i}"]
                sets.append(group["set"][()])
                stamps.append(group["timestamp"][()])
                metas.append([json.loads(s.decode() if isinstance(s, bytes) else s) for s in group["meta"][()]])
            else:
                frames.append(np.zeros((0, 0, 0)))
                sets.append(np.zeros(0, dtype=np.int64))
                stamps.append(np.zeros(0))
                metas.append([])
        failure = json.loads(str_attr(h5, "failure", str(path))) if "failure" in h5.attrs else None
        status = str_attr(h5, "capture_status", str(path)) if "capture_status" in h5.attrs else "unknown"
        complete = h5.attrs.get("sets_complete")  # rows of snapshot_sets past it: a set never completed
        return RawCapture(
            frames=frames,
            sets=sets,
            timestamps=stamps,
            frame_meta=metas,
            snapshot_sets=h5["snapshot_sets"][:complete] if "snapshot_sets" in h5 else None,
            status=status,
            sets_complete=int(complete or 0),
            failure=failure,
            meta=json.loads(str_attr(h5, "meta", str(path))),
        )
