"""Synchronized sets from the cameras of a rig file, written frame by frame (``rsocl capture``).

:func:`capture_sets` opens every camera of a :class:`~rsocl.files.rigfile.RigFile`
through its ``rsocl.cameras`` plugin, sets exposure (``t_e``), ROI, pixel format
and software trigger, then for each set fires all triggers back to back and
reads one frame per camera. Every raw frame is written to the file and flushed
before the next frame is requested, so whatever happens later, everything
already captured is on disk.

Files and atomicity
-------------------
The capture is written incrementally to ``<out>.partial`` and renamed to
``<out>`` when the run ends, successfully **or not**: a failed run still gives
``<out>``, holding the frames captured before the failure and the failure
itself. A ``<out>.partial`` left behind means the process itself died (power
loss, ``kill -9``); it is a readable HDF5 file up to the last flush. An existing
``<out>`` is replaced only at the end of the run.

Layout
------
A capture file of :mod:`rsocl.files.hdf5` (``rsocl_file = "capture"``, format 1, the
rig, attribute ``meta``), readable by :func:`rsocl.files.hdf5.load_capture` once a
first set is complete, plus:

- ``snapshots`` ``(K, m, n)`` float64: set 0 registered on the reference grid,
  in model units (written when set 0 is complete);
- ``snapshot_sets`` ``(S, K, m, n)`` float64: every complete set, registered;
- ``truth`` ``(T, m, n)``: the datacube of set 0, when every camera can tell it
  (the ``simulated`` backend's ``scene_truth``);
- ``raw/<i>`` ``(N_i, h, w)``: camera ``i``'s frames as delivered (its dtype),
  attributes ``backend``, ``name``, ``pixel_format``, ``bit_depth``,
  ``exposure`` (s, as the camera reports it), ``roi`` and ``config`` (JSON);
- ``raw_meta/<i>/set``, ``.../timestamp`` (s), ``.../meta`` (JSON of the
  frame's metadata): one entry per raw frame;
- root attributes ``capture_status`` (``"running"``, ``"complete"``,
  ``"failed"``, ``"interrupted"``), ``sets_complete`` and, after a failure,
  ``failure`` (JSON ``{"camera", "set", "phase", "type", "error"}``; ``set`` is
  null for failures while opening or configuring). The same status, failure and
  per-camera settings are in ``meta``.

Registration and units
----------------------
Frames from the ``simulated`` backend (``frame.meta["registered"]``) are on the
reference grid already. Other frames are warped onto it with the camera's
``homography`` from the rig file (:func:`rsocl.hardware.calibration.warp_to_reference`,
bilinear, 0 outside the sensor; the ROI origin is subtracted) or, without one, taken as registered (their shape
must then equal the rig's). Integer frames are converted to model units as
``image / (2**bit_depth - 1) * full_scale`` with ``full_scale`` from
``frame.meta["full_scale"]`` when the backend reports it, else ``t_e/dt``
(a white scene at unit gain fills the sensor); float frames are taken as they are.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rsocl.common import validation as check
from rsocl.files.atomic import output_path
from rsocl.files.rigfile import RigFile, load_rigfile

__all__ = ["capture_sets", "CaptureFailed", "load_raw", "RawCapture"]

PARTIAL_SUFFIX = ".partial"


class CaptureFailed(RuntimeError):
    """A capture stopped early. The file at :attr:`path` holds what was captured and the failure.

    Attributes
    ----------
    path : Path
        The capture file (complete up to the failure).
    camera : int or None
        Index of the camera that failed (None if not camera-specific).
    set_index : int or None
        The set being captured (None while opening or configuring).
    phase : str
        ``"open"``, ``"configure"``, ``"start"``, ``"trigger"``, ``"read"``, ``"write"`` or ``"register"``.
    sets_complete : int
        Complete sets in the file.
    """

    def __init__(self, message, *, path, camera, set_index, phase, sets_complete):
        super().__init__(message)
        self.path = path
        self.camera = camera
        self.set_index = set_index
        self.phase = phase
        self.sets_complete = sets_complete


def _json(data) -> str:
    from rsocl.files.hdf5_header import json_default

    def default(value):
        try:
            return json_default(value)
        except TypeError:
            return repr(value)

    return json.dumps(data, default=default)


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


# ---------------------------------------------------------------------- the file
class _Writer:
    """The capture file being written (``<out>.partial``), opened once."""

    def __init__(self, partial: Path, rig, rigfile: RigFile, labels, sets: int, timeout: float):
        import h5py

        from rsocl.files.hdf5_header import write_header

        self.partial = partial
        self.rig = rig
        self.rigfile = rigfile
        self.K = rig.n_channels
        self.h5 = h5py.File(partial, "w")
        try:
            self._start(rig, rigfile, labels, sets, timeout, write_header)
        except BaseException:
            self.h5.close()
            with contextlib.suppress(OSError):
                partial.unlink()
            raise

    def _start(self, rig, rigfile, labels, sets, timeout, write_header):
        write_header(self.h5, "capture", rig)
        self.sets_complete = 0
        self.pending = {}
        self.meta = {
            "source": "rsocl capture", "rig_file": None if rigfile.path is None else str(rigfile.path),
            "sets_requested": sets, "sets_complete": 0, "timeout": timeout, "status": "running", "failure": None,
            "started": _now(), "finished": None, "warnings": [],
            "cameras": [{"backend": b, "name": label} for (b, _), label in zip(rigfile.backends(), labels)],
            "units": "snapshots in model units (a scene in [0, 1] gives [0, gain*t_e/dt])",
        }
        self.h5.attrs["capture_status"] = "running"
        self.h5.attrs["sets_complete"] = 0
        self._write_meta()
        self.h5.flush()

    def _write_meta(self):
        self.h5.attrs["meta"] = _json(self.meta)

    def camera_settings(self, index, **settings):
        self.meta["cameras"][index].update(settings)
        self._write_meta()

    def warn(self, text):
        self.meta["warnings"].append(text)
        self._write_meta()

    # ------------------------------------------------------------------ raw frames
    def add_raw(self, index: int, set_index: int, frame, camera) -> None:
        import h5py

        image = np.asarray(frame.image)
        if image.ndim != 2:
            raise ValueError(f"camera {index}: frames must be 2-D images, got shape {image.shape}")
        name = f"raw/{index}"
        if name not in self.h5:
            ds = self.h5.create_dataset(name, shape=(0,) + image.shape, maxshape=(None,) + image.shape,
                                        dtype=image.dtype, chunks=(1,) + image.shape)
            ds.attrs["backend"] = camera.backend
            ds.attrs["name"] = camera.name
            ds.attrs["pixel_format"] = str(frame.pixel_format)
            ds.attrs["bit_depth"] = int(frame.bit_depth)
            ds.attrs["config"] = _json(camera.config)
            info = self.meta["cameras"][index]
            for key in ("exposure", "roi"):
                if info.get(key) is not None:
                    ds.attrs[key] = info[key]
            group = self.h5.require_group(f"raw_meta/{index}")
            group.create_dataset("set", shape=(0,), maxshape=(None,), dtype=np.int64, chunks=(64,))
            group.create_dataset("timestamp", shape=(0,), maxshape=(None,), dtype=np.float64, chunks=(64,))
            group.create_dataset("meta", shape=(0,), maxshape=(None,), dtype=h5py.string_dtype(), chunks=(64,))
        ds = self.h5[name]
        if image.shape != ds.shape[1:] or image.dtype != ds.dtype:
            raise ValueError(f"camera {index}: frame changed from {ds.shape[1:]} {ds.dtype} to "
                             f"{image.shape} {image.dtype} during the capture")
        n = ds.shape[0]
        ds.resize(n + 1, axis=0)
        ds[n] = image
        group = self.h5[f"raw_meta/{index}"]
        meta = dict(frame.meta)
        meta.update(pixel_format=str(frame.pixel_format), bit_depth=int(frame.bit_depth))
        for key, value in (("set", set_index), ("timestamp", float(frame.timestamp)), ("meta", _json(meta))):
            group[key].resize(n + 1, axis=0)
            group[key][n] = value
        self.h5.flush()

    # ------------------------------------------------------------------ registered sets
    def register(self, index: int, frame) -> np.ndarray:
        """Frame of camera ``index`` on the reference grid, model units, float64 ``(m, n)``."""
        cam = self.rigfile.cameras[index]
        image = np.asarray(frame.image)
        if image.dtype.kind in "biu":
            levels = 2 ** int(frame.bit_depth) - 1
            full_scale = frame.meta.get("full_scale")
            if full_scale is None:
                full_scale = cam["t_e"] / self.rig.dt
            value = image.astype(np.float64) * (float(full_scale) / levels)
        else:
            value = image.astype(np.float64)
        H = self.rigfile.homography(index)
        if H is not None and not frame.meta.get("registered", False):
            from rsocl.hardware.calibration import warp_to_reference

            origin = tuple(cam["roi"][:2]) if cam.get("roi") else (0, 0)
            value = warp_to_reference(value, H, self.rig.shape, frame_origin=origin, order=1, cval=0.0)
        if value.shape != self.rig.shape:
            raise ValueError(f"camera {index}: frame shape {value.shape} is not the rig's shape {self.rig.shape} "
                             "and the rig file gives no homography to register it")
        if not np.all(np.isfinite(value)):
            raise ValueError(f"camera {index}: frame has NaN or inf values")
        return value

    def add_registered(self, index: int, value: np.ndarray) -> None:
        self.pending[index] = value

    def complete_set(self, set_index: int, cameras) -> None:
        m, n = self.rig.shape
        stack = np.stack([self.pending[i] for i in range(self.K)])
        self.pending = {}
        if "snapshot_sets" not in self.h5:
            self.h5.create_dataset("snapshot_sets", shape=(0, self.K, m, n), maxshape=(None, self.K, m, n),
                                   dtype=np.float64, chunks=(1, self.K, m, n))
        ds = self.h5["snapshot_sets"]
        ds.resize(set_index + 1, axis=0)
        ds[set_index] = stack
        if set_index == 0:
            self.h5.create_dataset("snapshots", data=stack)
            truth = self._truth(cameras)
            if truth is not None:
                self.h5.create_dataset("truth", data=truth)
            self.meta["truth"] = truth is not None
        self.sets_complete = set_index + 1
        self.h5.attrs["sets_complete"] = self.sets_complete
        self.meta["sets_complete"] = self.sets_complete
        self._write_meta()
        self.h5.flush()

    def _truth(self, cameras):
        if not all(callable(getattr(cam, "scene_truth", None)) for cam in cameras):
            return None
        try:
            truth = np.asarray(cameras[0].scene_truth(0), dtype=np.float64)
        except Exception as exc:  # the truth is a bonus, never a reason to fail a capture
            self.warn(f"no ground truth: {type(exc).__name__}: {exc}")
            return None
        if truth.shape != (self.rig.T,) + self.rig.shape:
            self.warn(f"no ground truth: the scene has shape {truth.shape}, the rig needs "
                      f"{(self.rig.T,) + self.rig.shape}")
            return None
        return truth

    # ------------------------------------------------------------------ end
    def finish(self, status: str, failure: dict | None) -> None:
        self.meta.update(status=status, failure=failure, finished=_now())
        self.h5.attrs["capture_status"] = status
        if failure is not None:
            self.h5.attrs["failure"] = _json(failure)
        self._write_meta()

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.h5.flush()
        self.h5.close()


def _publish(partial: Path, out: Path) -> None:
    """fsync ``partial`` and rename it to ``out`` (atomic on one file system)."""
    from rsocl.files.atomic import _default_mode, _fsync_directory, _fsync_file

    mode = (out.stat().st_mode & 0o7777) if out.exists() else _default_mode()
    os.chmod(partial, mode)
    _fsync_file(partial)
    os.replace(partial, out)
    _fsync_directory(out.parent if str(out.parent) else Path("."))


# ---------------------------------------------------------------------- capture
def _label(index, backend, config):
    address = config.get("address")
    return f"camera {index} ({backend}{' ' + str(address) if address is not None else ''})"


def capture_sets(rigfile, out_path, sets=1, timeout=2.0, progress=False) -> Path:
    """Capture ``sets`` synchronized sets from the cameras of ``rigfile`` into the capture file ``out_path``.

    Parameters
    ----------
    rigfile : RigFile, str or os.PathLike
        The rig (a :class:`~rsocl.files.rigfile.RigFile` or the path of a TOML rig file).
    out_path : str or os.PathLike
        Capture file to write (``.h5``); its directory must exist. Written as
        ``<out_path>.partial`` during the run, renamed at the end (see the module docstring).
    sets : int
        Number of sets (one frame per camera each), >= 1.
    timeout : float
        Seconds to wait for each frame (> 0).
    progress : bool
        Show a progress bar (tqdm).

    Returns
    -------
    pathlib.Path
        ``out_path``, a complete capture file.

    Raises
    ------
    CaptureFailed
        A camera (or the registration of its frame) failed: ``out_path`` holds
        everything captured before and the failure (camera, set, error).
    ValueError, FileNotFoundError
        Bad arguments, rig file, unknown backend or camera config; nothing is written.
    KeyboardInterrupt
        Re-raised after the file is closed with status ``"interrupted"``.
    """
    from rsocl.common.registry import load

    if not isinstance(rigfile, RigFile):
        rigfile = load_rigfile(rigfile)
    sets = check.positive_int("sets", sets)
    timeout = check.positive("timeout", timeout, "seconds")
    rig = rigfile.rig()
    for i, cam in enumerate(rig.cameras):
        if cam.frames != 1:
            raise ValueError(f"camera[{i}].frames = {cam.frames}: rsocl capture reads one frame per trigger")
    out = output_path(out_path, "out")
    partial = out.with_name(out.name + PARTIAL_SUFFIX)

    backends = rigfile.backends()
    labels = [_label(i, b, c) for i, (b, c) in enumerate(backends)]
    cameras = [load("rsocl.cameras", b)(c, name=label) for (b, c), label in zip(backends, labels)]

    writer = _Writer(partial, rig, rigfile, labels, sets, timeout)
    where = {"camera": None, "set": None, "phase": "open"}
    failure = None
    interrupted = None
    try:
        try:
            _run(cameras, rigfile, writer, sets, timeout, progress, where)
        except Exception as exc:
            failure = dict(where, type=type(exc).__name__, error=str(exc))
        except BaseException as exc:  # KeyboardInterrupt, SystemExit: record, then let it through
            failure = dict(where, type=type(exc).__name__, error=str(exc) or type(exc).__name__)
            interrupted = exc
        for i, cam in enumerate(cameras):
            for step in (cam.stop, cam.close):
                try:
                    step()
                except Exception as exc:  # closing must reach every camera
                    writer.warn(f"camera {i}: {step.__name__} failed: {type(exc).__name__}: {exc}")
        status = "complete" if failure is None else ("interrupted" if interrupted is not None else "failed")
        writer.finish(status, failure)
    finally:
        writer.close()
    _publish(partial, out)
    if interrupted is not None:
        raise interrupted
    if failure is not None:
        who = "" if failure["camera"] is None else f"{labels[failure['camera']]}: "
        when = "before the first set" if failure["set"] is None else f"in set {failure['set']}"
        raise CaptureFailed(
            f"{who}{failure['phase']} failed {when}: {failure['type']}: {failure['error']} "
            f"({writer.sets_complete} complete set(s) and the failure are in {out})",
            path=out, camera=failure["camera"], set_index=failure["set"], phase=failure["phase"],
            sets_complete=writer.sets_complete)
    return out


def _run(cameras, rigfile, writer, sets, timeout, progress, where):
    from tqdm import tqdm

    def at(camera, set_index, phase):
        where.update(camera=camera, set=set_index, phase=phase)

    for i, cam in enumerate(cameras):
        at(i, None, "open")
        cam.open()
    for i, cam in enumerate(cameras):
        at(i, None, "configure")
        spec = rigfile.cameras[i]
        exposure = cam.set_exposure(spec["t_e"])
        if abs(exposure - spec["t_e"]) > 1e-3 * spec["t_e"]:
            writer.warn(f"camera {i}: exposure is {exposure!r} s, the rig file says t_e = {spec['t_e']!r} s")
        settings = {"exposure": exposure}
        if spec.get("roi"):
            cam.set_roi(*spec["roi"])
            settings["roi"] = list(spec["roi"])
        if spec.get("pixel_format"):
            cam.set_pixel_format(spec["pixel_format"])
            settings["pixel_format"] = spec["pixel_format"]
        cam.set_trigger("software")
        readout = cam.readout_time
        settings["readout_time"] = readout
        if readout is not None and abs(readout - spec["t_r"]) > 1e-3 * spec["t_r"]:
            writer.warn(f"camera {i}: the device reports t_r = {readout!r} s, the rig file says {spec['t_r']!r} s")
        writer.camera_settings(i, **settings)
    for i, cam in enumerate(cameras):
        at(i, None, "start")
        cam.start()
    with tqdm(total=sets, unit="set", desc="capture", disable=not progress) as bar:
        for j in range(sets):
            for i, cam in enumerate(cameras):   # fire all triggers back to back
                at(i, j, "trigger")
                cam.trigger()
            for i, cam in enumerate(cameras):
                at(i, j, "read")
                frame = cam.read(timeout)
                at(i, j, "write")
                writer.add_raw(i, j, frame, cam)
                at(i, j, "register")
                writer.add_registered(i, writer.register(i, frame))
            at(None, j, "write")
            writer.complete_set(j, cameras)
            bar.update(1)


# ---------------------------------------------------------------------- reading raw frames
@dataclass(frozen=True)
class RawCapture:
    """The raw side of a file written by :func:`capture_sets`.

    Attributes
    ----------
    frames : list of ndarray
        Per camera, ``(N_i, h, w)`` frames as delivered (``N_i`` may differ after a failure).
    sets, timestamps : list of ndarray
        Per camera and frame: set index, timestamp (s).
    frame_meta : list of list of dict
        Per camera and frame: the backend's metadata (plus pixel format and bit depth).
    snapshot_sets : ndarray, shape (S, K, m, n), or None
        The complete sets, registered, model units.
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
        return RawCapture(frames=frames, sets=sets, timestamps=stamps, frame_meta=metas,
                          snapshot_sets=h5["snapshot_sets"][()] if "snapshot_sets" in h5 else None,
                          status=status, sets_complete=int(h5.attrs.get("sets_complete", 0)), failure=failure,
                          meta=json.loads(str_attr(h5, "meta", str(path))))
