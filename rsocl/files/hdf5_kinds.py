"""What a file is, for a write about to replace it: frames from cameras, a capture, a reconstruction.

The commands and the saves of :mod:`rsocl.files.hdf5` and :mod:`rsocl.files.hdf5_reconstruction` ask before
they write: a capture from cameras is never replaced (:func:`refuse_camera_capture`), and a file that is no
simulated capture keeps a second name (:func:`keeping_unless_simulated`). :mod:`rsocl.files.hdf5` gives
these names too.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

__all__ = ["camera_frames", "refuse_camera_capture", "file_kind", "keeping_unless_simulated"]


def camera_frames(path) -> int | None:
    """How many frames from cameras an existing file holds: the ``raw/`` datasets of a capture of
    ``rsocl capture`` (:mod:`rsocl.hardware.capture_file`), however many of its sets are complete.

    Parameters
    ----------
    path : str or os.PathLike
        Any path.

    Returns
    -------
    int or None
        The frames (> 0); None where ``path`` holds none: absent, a folder, not HDF5, or a file
        without camera frames (a simulated capture, a reconstruction).

    Raises
    ------
    OSError
        ``path`` is a file that cannot be read (permissions, another process's lock).

    Examples
    --------
    >>> camera_frames("no-such-file.h5") is None
    True
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        return None
    with open(path, "rb"):  # an unreadable file is an OSError here, not "not HDF5"
        pass
    if not h5py.is_hdf5(path):
        return None
    with h5py.File(path, "r") as h5:
        raw = h5.get("raw")
        datasets = raw.values() if isinstance(raw, h5py.Group) else ()
        frames = sum(int(d.shape[0]) for d in datasets if isinstance(d, h5py.Dataset) and d.ndim)
    return frames or None


def refuse_camera_capture(path, name: str = "--out") -> None:
    """Refuse, naming ``name``, to write ``path`` where it holds frames from cameras (:func:`camera_frames`)
    or cannot be read to tell: a capture from cameras is never replaced by another file. Nothing is written.

    Raises
    ------
    ValueError
        ``path`` holds camera frames, or cannot be read; the message names it and says it is kept.
    """
    try:
        frames = camera_frames(path)
    except OSError as exc:
        why = exc.strerror or " ".join(str(exc).split())
        raise ValueError(
            f"{name} {str(path)!r} cannot be read to tell whether it holds frames from cameras ({why}); "
            f"it is kept: choose another {name}"
        ) from None
    if frames:
        raise ValueError(
            f"{name} {str(path)!r} holds {frames} frame(s) from cameras (rsocl capture); a capture from cameras "
            f"is never replaced: it is kept, move it or choose another {name}"
        )


def file_kind(path) -> str | None:
    """What the file at ``path`` is, for a command about to write there: None (no file, or a folder),
    ``"camera capture"`` (frames from cameras, :func:`camera_frames`), ``"capture"`` (a capture without them:
    a simulated one), ``"reconstruction"``, ``"HDF5"`` (another HDF5 file) or ``"file"`` (anything else);
    an ``OSError`` where the file cannot be read."""
    import h5py

    if camera_frames(path):
        return "camera capture"
    path = Path(path)
    if not path.is_file():
        return None
    if not h5py.is_hdf5(path):
        return "file"
    with h5py.File(path, "r") as h5:
        kind = h5.attrs.get("rsocl_file")
    kind = kind.decode() if isinstance(kind, bytes) else kind
    return kind if kind in ("capture", "reconstruction") else "HDF5"


@contextlib.contextmanager
def keeping_unless_simulated(path):
    """Context manager for a block that writes a capture to ``path``: a file there other than a simulated
    capture (a reconstruction, any other file; :func:`file_kind`) keeps a second name,
    ``<stem>.earlier-<UTC time><suffix>`` (:func:`rsocl.files.atomic.keeping`), yielded (None where nothing
    was kept), which is removed again if the block fails. A simulated capture is replaced."""
    from rsocl.files.atomic import EARLIER, keeping

    try:
        replaceable = file_kind(path) in (None, "capture")
    except OSError:  # it cannot be read to tell: kept
        replaceable = False
    with contextlib.nullcontext() if replaceable else keeping(path, EARLIER) as kept:
        yield kept
