"""HDF5 files of reconstructions: the datacube, the rig, solver parameters and traces.

One file per reconstruction, written atomically (see :mod:`rsocl.files.atomic`): a crash or error
never leaves a partial file and never clobbers an existing one. Captures are
:mod:`rsocl.files.hdf5`, which also gives the names of this module.

Layout (format version 1): the header of :mod:`rsocl.files.hdf5_header` (kind
``"reconstruction"``, format version, the rig); dataset ``datacube`` ``[T, m, n]``, optional
``truth`` (same shape), attribute ``params`` (JSON object), group ``history`` of 1-D datasets
(insertion order kept).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rsocl.common.hints import ArrayLike, PathLike
from rsocl.files.atomic import atomic_path
from rsocl.files.hdf5_header import (
    check_cube,
    check_rig,
    dumps_json,
    json_attr,
    new_file,
    open_checked,
    optional_array,
    read_array,
    read_rig,
    write_header,
)
from rsocl.model.rig import Rig

__all__ = ["Reconstruction", "save_reconstruction", "load_reconstruction"]


@dataclass(frozen=True)
class Reconstruction:
    """A loaded reconstruction file.

    Attributes
    ----------
    datacube : ndarray, shape (T, m, n)
        The reconstructed sub-frames.
    rig : Rig
        The camera array of the capture.
    params : dict
        Solver parameters (JSON data).
    history : dict of str -> ndarray
        Per-iteration traces (1-D arrays), e.g. residual or PSNR.
    truth : ndarray, shape (T, m, n), or None
        Ground truth, when known.
    """

    datacube: np.ndarray
    rig: Rig
    params: dict
    history: dict
    truth: np.ndarray | None


def save_reconstruction(
    path: PathLike,
    datacube: ArrayLike,
    rig: Rig,
    *,
    params: dict | None = None,
    history: dict | None = None,
    truth: ArrayLike | None = None,
) -> Path:
    """Write a reconstruction (datacube, rig, solver parameters, traces) to one HDF5 file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination file (conventionally ``.h5``); its directory must exist. A file already there is
        kept as ``<stem>.earlier-<UTC time><suffix>`` (a hard link where the file system has them); a
        capture there (snapshots, frames from cameras) is never replaced: a ValueError, nothing written.
    datacube : array_like, shape (T, m, n)
        Reconstructed sub-frames: ``(m, n) = rig.shape`` and
        ``1 <= T <= rig.T`` (all sub-frames, or a trimmed range such as the
        ``rig.T_se`` kept ones).
    rig : Rig
        The camera array of the capture.
    params : dict of str -> JSON-serialisable, optional
        Solver parameters (e.g. ``lam``, ``eta``, iterations), JSON attribute.
    history : dict of str -> 1-D array_like, optional
        Per-iteration traces, stored as datasets ``history/<name>`` in the
        given order. Names must be non-empty and contain no ``/``.
    truth : array_like, optional
        Ground truth with the same shape as ``datacube``.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        On shape mismatches, non-finite datacube/truth, bad history names or
        non-1-D traces, or non-JSON ``params``; where ``path`` holds a capture, or a file that cannot be
        read to tell.

    Examples
    --------
    >>> import os, tempfile, numpy as np, rsocl
    >>> folder = tempfile.TemporaryDirectory()
    >>> rig = rsocl.Rig.paper_array(2, shape=(8, 8), t_e=180e-6, t_r=35e-6)
    >>> cube = np.zeros((rig.T,) + rig.shape)
    >>> path = rsocl.save_reconstruction(os.path.join(folder.name, "rec.h5"), cube, rig,
    ...                                  params={"lam": 0.1}, history={"residual": [1.0, 0.5]})
    >>> result = rsocl.load_reconstruction(path)
    >>> result.params, list(result.history), result.datacube.shape == cube.shape
    ({'lam': 0.1}, ['residual'], True)
    >>> folder.cleanup()
    """
    from rsocl.files.atomic import EARLIER, keeping
    from rsocl.files.hdf5_kinds import file_kind, refuse_camera_capture

    rig = check_rig(rig)
    datacube, truth, traces = _checked(rig, datacube, truth, history)
    params_json = dumps_json("params", params)
    path = Path(os.fspath(path))
    refuse_camera_capture(path, "path")
    if file_kind(path) == "capture":
        raise ValueError(
            f"path {str(path)!r} is an rsocl capture file; a reconstruction never replaces a capture: it is kept, "
            "choose another path"
        )
    with keeping(path, EARLIER), atomic_path(path) as tmp:
        with new_file(tmp) as h5:
            write_header(h5, "reconstruction", rig)
            h5.attrs["params"] = params_json
            h5.create_dataset("datacube", data=datacube)
            if truth is not None:
                h5.create_dataset("truth", data=truth)
            group = h5.create_group("history", track_order=True)
            for name, trace in traces.items():
                group.create_dataset(name, data=trace)
    return path


def load_reconstruction(path: PathLike) -> Reconstruction:
    """Read a file written by :func:`save_reconstruction`.

    Parameters
    ----------
    path : str or os.PathLike
        The reconstruction file.

    Returns
    -------
    Reconstruction
        ``datacube``, ``rig``, ``params``, ``history`` (in saved order) and
        ``truth`` (or None).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not an rsocl reconstruction file or is damaged.
    """
    source = str(path)
    with open_checked(path, "reconstruction") as h5:
        rig = read_rig(h5, source)
        datacube = read_array(h5, "datacube", source, rig.shape)
        history = {}
        if "history" in h5:
            if not hasattr(h5["history"], "items"):
                raise ValueError(f"{source}: 'history' must be a group of datasets")
            for name in h5["history"]:
                history[name] = read_array(h5, f"history/{name}", source)
        params = json_attr(h5, "params", source)
        truth = optional_array(h5, "truth", source, rig.shape)
    if not isinstance(params, dict):
        raise ValueError(f"{source}: damaged: params must be a JSON object, got {type(params).__name__}")
    try:
        datacube, truth, history = _checked(rig, datacube, truth, history)
    except ValueError as exc:
        raise ValueError(f"{source}: damaged: {exc}") from None
    return Reconstruction(datacube=datacube, rig=rig, params=params, history=history, truth=truth)


def _checked(rig: Rig, datacube, truth, history) -> tuple:
    """``(datacube, truth, history)`` of a reconstruction of ``rig`` as :func:`save_reconstruction` takes
    them and :func:`load_reconstruction` returns them: a finite ``[T, m, n]`` datacube with ``(m, n) =
    rig.shape`` and ``1 <= T <= rig.T``, a truth of its shape or None, and 1-D real traces under names
    without ``/``; a ValueError naming what is wrong otherwise."""
    if np.ndim(datacube) == 4:
        raise ValueError(
            f"datacube must be 3-D [T, m, n], got a batch of {np.shape(datacube)[0]} sets {np.shape(datacube)}: save "
            "each set on its own (a batch Result's set(i), or sets())"
        )
    datacube = check_cube("datacube", datacube, None, "[T, m, n]")
    if datacube.shape[1:] != rig.shape or not 1 <= datacube.shape[0] <= rig.T:
        raise ValueError(
            f"datacube must have shape [T, m, n] with (m, n) = rig.shape = {rig.shape} and "
            f"1 <= T <= rig.T = {rig.T}, got {datacube.shape}"
        )
    if truth is not None:
        truth = check_cube("truth", truth, datacube.shape, "(the datacube's shape)")
    traces = {}
    if history is not None:
        if not isinstance(history, dict):
            raise ValueError(f"history must be a dict of name -> 1-D array, got {type(history).__name__}")
        for name, trace in history.items():
            if not isinstance(name, str) or not name or "/" in name or name in (".", ".."):
                raise ValueError(f"history names must be non-empty str without '/', got {name!r}")
            trace = np.asarray(trace)
            if trace.ndim != 1 or trace.dtype.kind not in "biuf":
                raise ValueError(
                    f"history[{name!r}] must be a 1-D real array, got shape {trace.shape} dtype {trace.dtype}"
                )
            traces[name] = trace
    return datacube, truth, traces
