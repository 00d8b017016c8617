"""The header every rsocl HDF5 file starts with: its kind, format version and the rig.

Root attributes (format version 1):

- ``rsocl_file``: ``"capture"`` or ``"reconstruction"``;
- ``format_version``: ``1``;
- ``rig``: JSON of :meth:`rsocl.model.rig.Rig.to_dict` in which each camera's
  ``row_map`` array is replaced by ``{"dataset": "rig_row_maps/<camera index>"}``
  (or ``null``); the row maps are float64 datasets at those paths;
- human-readable copies (not read back): ``T``, ``T_se``, ``dt`` (seconds),
  ``mask``, ``n_cameras``, ``n_channels``, ``shape``.

:func:`write_header` writes them, :func:`open_checked` opens a file and checks its kind and
version, :func:`read_rig` reads the rig back; JSON attributes go through :func:`dumps_json`.
:func:`new_file` creates a file whose failed close (a full disk) is an ``OSError``. The checks the
writers and readers of both kinds share: :func:`check_rig`, :func:`check_cube`, :func:`optional_array`;
the sets of a capture its readers may read: :func:`complete_set_count`.
"""

from __future__ import annotations

import contextlib
import errno
import json
import numbers
import os
import re
import warnings
from pathlib import Path

import numpy as np

from rsocl.common import validation as check
from rsocl.common.memory import check_host_memory
from rsocl.model.rig import Rig

#: The suffixes of HDF5 files (``rsocl reconstruct --out`` takes these for a reconstruction file).
HDF5_SUFFIXES = (".h5", ".hdf5", ".hdf", ".he5")
__all__ = [
    "FORMAT_VERSION",
    "HDF5_SUFFIXES",
    "json_default",
    "dumps_json",
    "write_rig",
    "read_rig",
    "str_attr",
    "write_header",
    "open_checked",
    "json_attr",
    "read_array",
    "real_dataset",
    "optional_array",
    "check_rig",
    "check_cube",
    "complete_set_count",
    "new_file",
    "close_error",
]

#: Version written to the ``format_version`` attribute; files with a larger
#: version are refused.
FORMAT_VERSION = 1

_ROW_MAPS = "rig_row_maps"


# ---------------------------------------------------------------------- JSON
def json_default(value):
    """``default`` for :func:`json.dumps`: NumPy scalars and arrays as numbers and lists, paths as str."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def dumps_json(name: str, data) -> str:
    """JSON text of the dict ``data`` (None: ``{}``); a ValueError naming ``name`` when it cannot be written."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ValueError(f"{name} must be a dict of str -> JSON-serialisable values, got {type(data).__name__}")
    for key in data:
        if not isinstance(key, str):
            raise ValueError(f"{name} keys must be str, got {key!r}")
    try:
        return json.dumps(data, default=json_default)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"{name} must be JSON-serialisable (numbers, str, bool, None, lists, dicts, NumPy scalars/arrays): {exc}"
        ) from None


# ---------------------------------------------------------------------- rig
def write_rig(h5, rig: Rig) -> None:
    """Store ``rig`` in the root of the open file ``h5`` (attributes + row-map datasets), replacing a rig
    stored there before."""
    data = rig.to_dict()
    for index, camera in enumerate(data["cameras"]):
        row_map = camera.get("row_map")
        name = f"{_ROW_MAPS}/{index}"
        if name in h5:
            del h5[name]
        if row_map is not None:
            h5.create_dataset(name, data=np.asarray(row_map, dtype=np.float64))
            camera["row_map"] = {"dataset": name}
    h5.attrs["rig"] = json.dumps(data, allow_nan=False)
    h5.attrs["T"] = rig.T
    h5.attrs["T_se"] = rig.T_se
    h5.attrs["dt"] = rig.dt
    h5.attrs["mask"] = rig.mask
    h5.attrs["n_cameras"] = rig.C
    h5.attrs["n_channels"] = rig.n_channels
    h5.attrs["shape"] = np.asarray(rig.shape, dtype=np.int64)


def read_rig(h5, source: str) -> Rig:
    """The rig :func:`write_rig` stored in the open file ``h5``; ``source`` names the file in errors."""
    try:
        data = json.loads(str_attr(h5, "rig", source))
        for camera in data["cameras"]:
            ref = camera.get("row_map")
            if isinstance(ref, dict):
                stored = h5[ref["dataset"]]
                check_host_memory(
                    8 * stored.size,
                    f"row map {ref['dataset']!r}",
                    f"its {stored.shape} float64 array",
                    "the stored rig is damaged or too large for this machine",
                )
                camera["row_map"] = np.asarray(stored[()], dtype=np.float64)
        rig = Rig.from_dict(data)
    except (KeyError, TypeError, AttributeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{source}: the stored rig description is damaged ({exc!r})") from None
    except ValueError as exc:
        raise ValueError(f"{source}: the stored rig is not valid: {exc}") from None
    return rig


def json_attr(h5, name: str, source: str):
    """Root attribute ``name`` of ``h5`` decoded from JSON; a ValueError naming ``source`` and the
    attribute when it is missing or not JSON."""
    try:
        return json.loads(str_attr(h5, name, source))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{source}: attribute {name!r} is not valid JSON ({exc})") from None


def read_array(h5, name: str, source: str, tail=None):
    """Dataset ``name`` of ``h5`` as a real-valued array, checked by :func:`real_dataset`."""
    return real_dataset(h5, name, source, tail)[()]


def optional_array(h5, name: str, source: str, tail=None):
    """Dataset ``name`` of ``h5`` read by :func:`read_array`, or None when the file has no ``name``."""
    return read_array(h5, name, source, tail) if name in h5 else None


def check_rig(rig) -> Rig:
    """``rig`` when it is a :class:`~rsocl.model.rig.Rig`; a ValueError naming ``rig`` otherwise."""
    if not isinstance(rig, Rig):
        raise ValueError(f"rig must be an rsocl.model.rig.Rig, got {type(rig).__name__}")
    return rig


def check_cube(name: str, array, expected_shape=None, what="") -> np.ndarray:
    """``array`` as a finite 3-D array (of ``expected_shape`` when given); a ValueError naming ``name``
    and the shape it must have (``what`` says it in words) otherwise."""
    array = check.finite_array(name, array)
    if array.ndim != 3:
        raise ValueError(f"{name} must be 3-D {what}, got shape {array.shape}")
    if expected_shape is not None and array.shape != tuple(expected_shape):
        raise ValueError(f"{name} must have shape {tuple(expected_shape)} {what}, got {array.shape}")
    return array


def real_dataset(h5, name: str, source: str, tail=None):
    """Dataset ``name`` of ``h5`` (not read); a ValueError naming ``source`` when it is missing, not a
    dataset, not real numbers or (``tail``: the expected trailing axes) of another shape."""
    import h5py

    if name not in h5:
        raise ValueError(f"{source}: dataset {name!r} is missing")
    item = h5[name]
    if not isinstance(item, h5py.Dataset):
        raise ValueError(f"{source}: {name!r} must be a dataset, it is a {type(item).__name__}")
    if item.dtype.kind not in "biuf":
        raise ValueError(f"{source}: dataset {name!r} must hold real numbers, it holds {item.dtype}")
    if tail is not None and tuple(item.shape[-len(tail) :]) != tuple(tail):
        raise ValueError(
            f"{source}: dataset {name!r} has shape {item.shape}, the rig needs (..., {', '.join(map(str, tail))})"
        )
    return item


def complete_set_count(h5, source: str) -> int:
    """How many sets of the open capture ``h5`` (named ``source``) are complete: ``sets_complete`` where
    ``rsocl capture`` wrote it (rows of ``snapshot_sets`` past it, never completed, are warned about), else the
    rows of ``snapshot_sets`` (1 without it).

    Raises
    ------
    ValueError
        No set is complete: the message names the file, its ``capture_status`` and failure.
    """
    rows = int(h5["snapshot_sets"].shape[0]) if "snapshot_sets" in h5 else 1
    if "sets_complete" not in h5.attrs:
        return rows
    complete = min(int(h5.attrs["sets_complete"]), rows)
    status = str_attr(h5, "capture_status", source) if "capture_status" in h5.attrs else "unknown"
    if complete < 1:
        try:  # rsocl capture's failure: {"camera", "set", "phase", "type", "error"}
            found = json_attr(h5, "failure", source)
            failure = f": {found['phase']} failed: {found['type']}: {found['error']}"
        except (ValueError, KeyError, TypeError, OSError):  # none, not rsocl capture's, or damaged
            failure = ""
        raise ValueError(
            f"{source}: no set of this capture is complete (capture_status {status!r}{failure}); "
            "it holds no snapshots to read"
        )
    if rows > complete:
        warnings.warn(
            f"{source}: {complete} of the {rows} sets in 'snapshot_sets' are complete (capture_status "
            f"{status!r}); the {rows - complete} incomplete set(s) are not read",
            stacklevel=1,  # here, so that the loaders of one command say it once
        )
    return complete


# ---------------------------------------------------------------------- header
def str_attr(h5, name: str, source: str) -> str:
    """Root attribute ``name`` of ``h5`` as str; a ValueError naming ``source`` when it is missing."""
    if name not in h5.attrs:
        raise ValueError(f"{source}: attribute {name!r} is missing")
    value = h5.attrs[name]
    if isinstance(value, bytes):
        value = value.decode("utf-8")
    return str(value)


def write_header(h5, kind: str, rig: Rig) -> None:
    """Write the header (``rsocl_file = kind``, ``format_version``, the rig) to the open file ``h5``."""
    h5.attrs["rsocl_file"] = kind
    h5.attrs["format_version"] = FORMAT_VERSION
    write_rig(h5, rig)


def open_checked(path, kind: str, name: str = "path"):
    """Open ``path`` read-only and check that it is an rsocl file of ``kind``; errors name the parameter
    ``name``."""
    import h5py

    path = check.existing_file(name, path, f"{kind} file")
    try:
        h5 = h5py.File(path, "r")
    except OSError as exc:
        if "unable to lock file" in str(exc):
            raise ValueError(
                f"{name}: {str(path)!r} is being written by another process (it holds the file's "
                "lock); read it once that process has finished"
            ) from None
        raise ValueError(f"{name}: {str(path)!r} is not a readable HDF5 file ({check.cause(exc)})") from None
    try:
        found = h5.attrs.get("rsocl_file")
        if isinstance(found, bytes):
            found = found.decode("utf-8")
        if found != kind:
            what = "not an rsocl file" if found is None else f"an rsocl {found!r} file"
            raise ValueError(f"{name}: {str(path)!r} is {what}, expected an rsocl {kind!r} file")
        version = h5.attrs.get("format_version")
        if version is None or not isinstance(version, numbers.Integral) or not 1 <= int(version) <= FORMAT_VERSION:
            raise ValueError(
                f"{name}: {str(path)!r} has format_version {version!r}; this rsocl reads 1..{FORMAT_VERSION}"
            )
    except BaseException:
        h5.close()
        raise
    return h5


def close_error(exc: Exception) -> OSError:
    """An ``OSError`` for HDF5's failure ``exc`` (h5py raises ``RuntimeError`` when a close cannot write
    what it holds), with the error number HDF5 names (``errno = N``) and the system's words for it."""
    if isinstance(exc, OSError) and exc.errno:
        return OSError(exc.errno, os.strerror(exc.errno))
    found = re.search(r"errno = (\d+)", str(exc))
    code = int(found.group(1)) if found else errno.EIO
    return OSError(code, os.strerror(code))


@contextlib.contextmanager
def new_file(path):
    """``h5py.File(path, "w")``, closed at the end of the block; when the close fails (HDF5 cannot write
    the data it still holds: a full disk), an ``OSError`` (:func:`close_error`), and when the block
    fails, its own error after the file is closed as far as HDF5 can.

    Examples
    --------
    >>> with new_file(tmp) as h5:                 # doctest: +SKIP
    ...     h5.create_dataset("x", data=array)
    """
    import h5py

    h5 = h5py.File(path, "w")
    try:
        yield h5
    except BaseException:
        with contextlib.suppress(Exception):
            h5.close()
        raise
    try:
        h5.close()
    except Exception as exc:  # h5py's RuntimeError "Can't decrement id ref count (... errno = 28 ...)"
        raise close_error(exc) from exc
