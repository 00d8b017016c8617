"""HDF5 files of captures: the snapshots and the rig that took them.

One file per capture, written atomically (see :mod:`rsocl.files.atomic`): a crash or error never
leaves a partial file and never clobbers an existing one. Reconstruction files are
:mod:`rsocl.files.hdf5_reconstruction`; its names are importable from here too, so this module
gives the whole file format.

Layout (format version 1)
-------------------------
Root attributes: the header of :mod:`rsocl.files.hdf5_header` (kind ``"capture"``, format
version, the rig).

Dataset ``snapshots`` ``[K, m, n]``, optional ``truth`` ``[T, m, n]``, attribute ``meta`` (JSON
object); a capture of several sets (``rsocl capture --sets S``) adds ``snapshot_sets``
``[S, K, m, n]``. Of a file with the attribute ``sets_complete`` (``rsocl capture``'s, updated after each
set) only that many sets are read: a set never completed (set 0's ``snapshots``, ``truth``) is not data.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rsocl.common.hints import ArrayLike, PathLike
from rsocl.files.atomic import atomic_path
from rsocl.files.hdf5_header import (
    FORMAT_VERSION,
    check_cube,
    check_rig,
    complete_set_count,
    dumps_json,
    json_attr,
    new_file,
    open_checked,
    optional_array,
    read_array,
    read_rig,
    real_dataset,
    write_header,
)
from rsocl.files.hdf5_kinds import camera_frames, file_kind, keeping_unless_simulated, refuse_camera_capture
from rsocl.files.hdf5_reconstruction import Reconstruction, load_reconstruction, save_reconstruction
from rsocl.model.rig import Rig

__all__ = [
    "Capture",
    "Reconstruction",
    "save_capture",
    "load_capture",
    "load_capture_rig",
    "load_snapshot_sets",
    "snapshot_set_count",
    "complete_set_count",
    "camera_frames",
    "file_kind",
    "refuse_camera_capture",
    "keeping_unless_simulated",
    "save_reconstruction",
    "load_reconstruction",
    "FORMAT_VERSION",
]


@dataclass(frozen=True)
class Capture:
    """A loaded capture file.

    Attributes
    ----------
    snapshots : ndarray, shape (K, m, n)
        One snapshot per channel, registered on the reference grid.
    rig : Rig
        The camera array that took them.
    truth : ndarray, shape (T, m, n), or None
        Ground-truth datacube (simulations only).
    meta : dict
        Free-form metadata stored with the capture.
    """

    snapshots: np.ndarray
    rig: Rig
    truth: np.ndarray | None
    meta: dict


# ---------------------------------------------------------------------- capture
def save_capture(
    path: PathLike, snapshots: ArrayLike, rig: Rig, *, truth: ArrayLike | None = None, attrs: dict | None = None
) -> Path:
    """Write a capture (snapshots and the rig that took them) to one HDF5 file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination file (conventionally ``.h5``); its directory must exist. A simulated capture already
        there (snapshots only) is replaced once the new file is complete; any other file is kept as
        ``<stem>.earlier-<UTC time><suffix>``; a capture with frames from cameras is never replaced: a
        ValueError, nothing written.
    snapshots : array_like, shape (K, m, n)
        One registered snapshot per channel, ``K = rig.n_channels`` and
        ``(m, n) = rig.shape``; stored in its own dtype.
    rig : Rig
        The camera array.
    truth : array_like, shape (T, m, n), optional
        Ground-truth datacube, ``T = rig.T`` (simulations).
    attrs : dict of str -> JSON-serialisable, optional
        Free-form metadata (e.g. noise level, scene name), stored as the JSON
        attribute ``meta``. NumPy scalars and arrays become numbers and lists.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        If a shape does not match the rig, an array is not finite, or
        ``attrs`` is not a JSON-serialisable dict with str keys; where ``path`` holds frames from cameras,
        or a file that cannot be read to tell.

    Examples
    --------
    >>> import os, tempfile, numpy as np, rsocl
    >>> folder = tempfile.TemporaryDirectory()
    >>> rig = rsocl.Rig.paper_array(2, shape=(8, 8), t_e=180e-6, t_r=35e-6)
    >>> snapshots = np.zeros((rig.n_channels,) + rig.shape, np.float32)
    >>> path = rsocl.save_capture(os.path.join(folder.name, "cap.h5"), snapshots, rig, attrs={"scene": "dark"})
    >>> capture = rsocl.load_capture(path)
    >>> capture.rig == rig, capture.snapshots.shape, capture.meta
    (True, (2, 8, 8), {'scene': 'dark'})
    >>> folder.cleanup()
    """
    rig = check_rig(rig)
    m, n = rig.shape
    snapshots = check_cube(
        "snapshots", snapshots, (rig.n_channels, m, n), "[K = rig.n_channels, m, n] = rig's channels and shape"
    )
    if truth is not None:
        truth = check_cube("truth", truth, (rig.T, m, n), "[T = rig.T, m, n]")
    meta = dumps_json("attrs", attrs)
    path = Path(os.fspath(path))
    refuse_camera_capture(path, "path")
    with keeping_unless_simulated(path), atomic_path(path) as tmp:
        with new_file(tmp) as h5:
            write_header(h5, "capture", rig)
            h5.attrs["meta"] = meta
            h5.create_dataset("snapshots", data=snapshots)
            if truth is not None:
                h5.create_dataset("truth", data=truth)
    return path


def load_capture(path: PathLike, set_index: int | None = None) -> Capture:
    """Read a file written by :func:`save_capture` or ``rsocl capture``: one set of snapshots.

    Parameters
    ----------
    path : str or os.PathLike
        The capture file.
    set_index : int, optional
        Which set of a capture of several sets (``rsocl capture --sets S``: ``0 <= set_index < S``).
        None, the default, reads the only set of a one-set capture; of a capture of several sets it
        reads set 0 and warns, naming the set count (give ``set_index=0`` to say so).
        :func:`load_snapshot_sets` reads every set.

    Returns
    -------
    Capture
        ``snapshots`` (of the set asked for), ``rig`` (equal to the saved one), ``truth``
        (set 0's datacube, so None for another set, or None when not stored) and ``meta``.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not an rsocl capture file (another kind, not HDF5, or
        a newer format version) or its content is damaged, or ``set_index`` is not
        one of its sets.

    Warns
    -----
    UserWarning
        ``set_index`` not given for a capture of several sets.

    Examples
    --------
    >>> capture = load_capture("capture.h5", set_index=2)      # doctest: +SKIP
    >>> capture.snapshots.shape                                 # doctest: +SKIP
    (4, 64, 64)
    """
    source = str(path)
    if set_index is not None:
        set_index = _set_index(set_index)
    with open_checked(path, "capture") as h5:
        rig = read_rig(h5, source)
        count = complete_set_count(h5, source)
        if set_index is not None and set_index >= count:
            raise ValueError(f"set_index must be in [0, {count - 1}] ({source} holds {count} set(s)), got {set_index}")
        if set_index is None and count > 1:
            warnings.warn(
                f"{source} holds {count} sets; load_capture reads set 0 (set_index=0 says so, "
                f"set_index=k reads set k, load_snapshot_sets reads every set)",
                stacklevel=2,
            )
        if set_index:
            snapshots = real_dataset(h5, "snapshot_sets", source, (rig.n_channels,) + rig.shape)[set_index]
            if not np.all(np.isfinite(snapshots)):
                raise ValueError(f"{source}: set {set_index} of dataset 'snapshot_sets' holds NaN or inf values")
            truth = None  # the stored truth is set 0's datacube
        else:
            snapshots = read_array(h5, "snapshots", source, (rig.n_channels,) + rig.shape)
            if not np.all(np.isfinite(snapshots)):
                bad = int(np.count_nonzero(~np.isfinite(snapshots)))
                raise ValueError(f"{source}: dataset 'snapshots' holds {bad} NaN or inf value(s); all must be finite")
            truth = optional_array(h5, "truth", source, rig.shape)
            if truth is not None:  # as save_capture takes it
                try:
                    truth = check_cube("truth", truth, (rig.T,) + rig.shape, "[T = rig.T, m, n]")
                except ValueError as exc:
                    raise ValueError(f"{source}: damaged: {exc}") from None
        return Capture(snapshots=snapshots, rig=rig, truth=truth, meta=_meta(h5, source))


def _meta(h5, source: str) -> dict:
    """The ``meta`` attribute of the open capture ``h5``; ``{}`` with a one-line warning where HDF5 cannot read
    it (a capture cut off by a full disk): no snapshot depends on it."""
    try:
        return json_attr(h5, "meta", source)
    except OSError as exc:  # the attribute's data is damaged; missing or not JSON: the ValueError of json_attr
        why = exc.strerror or " ".join(str(exc).split())
        warnings.warn(f"{source}: attribute 'meta' cannot be read ({why}); read without it", stacklevel=3)
    return {}


def _set_index(value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"set_index must be an integer >= 0 (a set of the capture), got {value!r}")
    return int(value)


def load_capture_rig(path, name: str = "path") -> Rig:
    """The rig of a capture file (as :func:`load_capture` returns it), reading no snapshots.

    Raises the errors of :func:`load_capture` for a missing file, another kind of file or a
    damaged rig description; they name the parameter ``name`` (a command line's option, say).
    """
    with open_checked(path, "capture", name) as h5:
        return read_rig(h5, str(path))


def snapshot_set_count(path) -> int:
    """How many complete sets a capture holds (:func:`complete_set_count`), reading no data."""
    with open_checked(path, "capture") as h5:
        return complete_set_count(h5, str(path))


def load_snapshot_sets(path) -> np.ndarray | None:
    """Every registered set ``(S, K, m, n)`` of a multi-set capture (dataset ``snapshot_sets``), or None.

    Captures of ``rsocl capture`` hold one set per trigger; :func:`load_capture` reads one of them. Only the
    complete sets are read (:func:`complete_set_count`).
    """
    source = str(path)
    with open_checked(path, "capture") as h5:
        count = complete_set_count(h5, source)
        if "snapshot_sets" not in h5:
            return None
        sets = h5["snapshot_sets"][:count]
    if sets.ndim != 4 or sets.shape[0] < 1 or not np.all(np.isfinite(sets)):
        raise ValueError(f"{source}: dataset 'snapshot_sets' must be finite (S >= 1, K, m, n), got {sets.shape}")
    return sets
