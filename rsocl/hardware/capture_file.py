"""The file :func:`rsocl.hardware.capture.capture_sets` writes: raw frames as they arrive, registered sets.

:class:`CaptureWriter` writes it (to ``<out>.partial``, flushed after every frame);
:func:`publish` renames it to ``<out>``; :func:`load_raw` (from :mod:`rsocl.hardware.capture_raw`) reads the
raw side back.

Layout
------
A capture file of :mod:`rsocl.files.hdf5` (``rsocl_file = "capture"``, format 1, the
rig with each camera's exposure as its device applied it, attribute ``meta``), readable by
:func:`rsocl.files.hdf5.load_capture` once a first set is complete, plus:

- ``snapshots`` ``(K, m, n)`` float64: set 0 registered on the reference grid,
  in model units (written when set 0 is complete);
- ``snapshot_sets`` ``(S, K, m, n)`` float64: every complete set, registered;
- ``truth`` ``(T, m, n)``: the datacube of set 0, when every camera can tell it
  (the ``simulated`` backend's ``scene_truth``) and all tell the same one (else a warning says why
  there is none);
- ``raw/<i>`` ``(N_i, h, w)``: camera ``i``'s frames as delivered (its dtype),
  attributes ``backend``, ``name`` (the label messages use), ``camera_name`` (the rig file's
  ``name``, when it gives one), ``pixel_format``, ``bit_depth``,
  ``exposure`` (s, as the camera reports it), ``roi`` and ``config`` (JSON);
- ``raw_meta/<i>/set``, ``.../timestamp`` (s), ``.../meta`` (JSON of the
  frame's metadata): one entry per raw frame;
- ``raw_changed/<i>/<set>``: a frame of camera ``i`` whose shape or dtype changed during the capture (it
  ends the capture), kept as delivered, attributes ``timestamp`` and ``meta``;
- root attributes ``capture_status`` (``"running"``, ``"complete"``,
  ``"failed"``, ``"interrupted"``), ``sets_complete`` and, after a failure,
  ``failure`` (JSON ``{"camera", "set", "phase", "type", "error"}``; ``set`` is
  null for failures while opening or configuring, and for an interrupt while the cameras stop
  or close, phase ``"stop"`` or ``"close"``). The same status, failure and
  per-camera settings are in ``meta`` (``meta["cameras"][i]``: ``backend``, ``name`` the label,
  ``camera_name`` the rig file's ``name`` or null, and the settings applied).
"""

from __future__ import annotations

import contextlib
import json
import os
import time
import warnings
from pathlib import Path

import numpy as np

from rsocl.files.rigfile import RigFile
from rsocl.hardware.capture_raw import RawCapture, load_raw
from rsocl.hardware.capture_room import check_room, set_bytes
from rsocl.hardware.capture_truth import room_for, set_truth

__all__ = ["CaptureWriter", "check_partial", "readable", "publish", "RawCapture", "load_raw", "PARTIAL_SUFFIX"]

#: Suffix of the file being written; renamed to the capture file's name at the end of the run.
PARTIAL_SUFFIX = ".partial"


# ---------------------------------------------------------------------- writing
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


def check_partial(partial: Path, name: str = "out") -> None:
    """Refuse, naming ``name``, to capture while ``partial`` (``<out>.partial``) exists: the capture
    file another run is writing (it holds a lock on it), or one a killed run left, whose complete sets
    the message counts. The file is kept as it is (a capture never truncates or appends to it)."""
    if not (partial.exists() or partial.is_symlink()):
        return
    import h5py

    try:
        with h5py.File(partial, "r") as h5:
            if "sets_complete" in h5.attrs:  # written by rsocl capture after each set
                sets = int(h5.attrs["sets_complete"])
            else:  # another writer's capture file
                sets = h5["snapshot_sets"].shape[0] if "snapshot_sets" in h5 else int("snapshots" in h5)
    except BlockingIOError:
        raise ValueError(
            f"{name}: {str(partial)!r} is being written by another capture (it holds the file's "
            "lock); wait for it or choose another --out"
        ) from None
    except OSError as exc:
        why = " ".join(str(exc).split())
        raise ValueError(
            f"{name}: {str(partial)!r} is left from an earlier capture and is not readable "
            f"({why}); it is kept: move or remove it, or choose another --out"
        ) from None
    raise ValueError(
        f"{name}: {str(partial)!r} holds {sets} complete set(s) of an earlier capture that did not "
        "end; it is kept: rename it (it is a readable capture file) or remove it, or choose "
        "another --out"
    )


class CaptureWriter:
    """The capture file being written (``<out>.partial``), opened once."""

    def __init__(self, partial: Path, rig, rigfile: RigFile, labels, sets: int, timeout: float):
        import h5py

        from rsocl.files.hdf5_header import write_header

        self.partial = partial
        self.rig = rig
        self.K = rig.n_channels
        try:
            # "x": never truncates a partial capture (another run's). No chunk cache: each frame reaches the
            # file as it is written, and a write the disk refuses fails there, not later at close (whose
            # failure would leave HDF5 a file it cannot close, and the process a crash at exit)
            self.h5 = h5py.File(partial, "x", rdcc_nbytes=0)
        except FileExistsError:
            check_partial(partial)
            raise
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
        self.interrupt: BaseException | None = None
        self.pending = {}
        self.meta = {
            "source": "rsocl capture",
            "rig_file": None if rigfile.path is None else str(rigfile.path),
            "sets_requested": sets,
            "sets_complete": 0,
            "timeout": timeout,
            "status": "running",
            "failure": None,
            "started": _now(),
            "finished": None,
            "warnings": [],
            "cameras": [
                {"backend": cam["backend"], "name": label, "camera_name": cam.get("name")}
                for cam, label in zip(rigfile.cameras, labels)
            ],
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
        """Record ``text`` in ``meta["warnings"]`` and issue it as a :class:`UserWarning` (the CLI prints it)."""
        self.meta["warnings"].append(text)
        self._write_meta()
        warnings.warn(text, stacklevel=2)

    def use_exposures(self, exposures, tolerance: float = 1e-3) -> None:
        """Store the exposures (s, one per camera) the devices applied in the file's rig, where one differs
        from the rig's ``t_e`` (the rig file's) by more than ``tolerance`` of it, and warn for each.

        Devices round a requested exposure to their units and clamp it to their range (V4L2 in
        units of 100 µs; 10 s asked of a webcam can give 0.2047 s). The frames were exposed for the
        applied time, so the rig that reconstructs them must say so. Called before the first frame.
        """
        from rsocl.files.hdf5_header import write_rig
        from rsocl.model.rig import Rig

        data = self.rig.to_dict()
        changed = []
        for i, (camera, applied) in enumerate(zip(data["cameras"], exposures)):
            asked = camera["t_e"]
            if abs(applied - asked) > tolerance * asked:
                camera["t_e"] = float(applied)
                changed.append((i, applied, asked))
        if not changed:
            return
        rig = Rig.from_dict(data)
        write_rig(self.h5, rig)
        self.rig = rig
        self.h5.flush()
        for i, applied, asked in changed:
            self.warn(
                f"camera {i}: the device applied an exposure of {applied!r} s where the rig file says "
                f"t_e = {asked!r} s; the capture's rig uses {applied!r} s (T = {rig.T} sub-frames)"
            )

    def check_room(self, set_index: int) -> None:
        """Raise :class:`~rsocl.hardware.capture_room.NoRoom` where set ``set_index`` would take the file
        past the process's file-size limit or fill its disk (:mod:`rsocl.hardware.capture_room`)."""
        data = set_bytes(self.h5, self.rig, self.meta["cameras"], set_index == 0)
        check_room(self.h5.id.get_filesize(), data, f"set {set_index}", self.h5.filename)

    # ------------------------------------------------------------------ raw frames
    def add_raw(self, index: int, set_index: int, frame, camera) -> None:
        """Append ``frame`` to ``raw/<index>`` and its set, timestamp and metadata to ``raw_meta/<index>``, then
        flush. All or nothing: on any exception (a write the disk refuses, Ctrl-C, SIGTERM) the datasets are
        resized back to the frames written whole (or removed, on the camera's first frame) and it is
        re-raised, so that frames and their metadata never differ in number. A frame with no room (on the
        file's disk or under the file-size limit) is refused before anything is written
        (:class:`~rsocl.hardware.capture_room.NoRoom`)."""
        image = np.asarray(frame.image)
        if image.ndim != 2:
            raise ValueError(f"camera {index}: frames must be 2-D images, got shape {image.shape}")
        meta = dict(frame.meta)
        meta.update(pixel_format=str(frame.pixel_format), bit_depth=int(frame.bit_depth))
        entries = (("set", int(set_index)), ("timestamp", float(frame.timestamp)), ("meta", _json(meta)))
        name = f"raw/{index}"
        first = name not in self.h5
        if not first:
            ds = self.h5[name]
            if image.shape != ds.shape[1:] or image.dtype != ds.dtype:
                kept = self._keep_changed(index, set_index, image, frame, meta)
                raise ValueError(
                    f"camera {index}: frame changed from {ds.shape[1:]} {ds.dtype} to "
                    f"{image.shape} {image.dtype} during the capture{kept}"
                )
        check_room(
            self.h5.id.get_filesize(), image.nbytes, f"camera {index}'s frame of set {set_index}", self.h5.filename
        )
        n = 0 if first else self.h5[name].shape[0]
        try:
            if first:
                self._create_raw(index, image, frame, camera)
            ds, group = self.h5[name], self.h5[f"raw_meta/{index}"]
            ds.resize(n + 1, axis=0)
            ds[n] = image
            for key, value in entries:
                group[key].resize(n + 1, axis=0)
                group[key][n] = value
        except BaseException:
            self._roll_back(index, n, first)
            raise
        self.h5.flush()

    def _keep_changed(self, index: int, set_index: int, image, frame, meta) -> str:
        """Keep a frame that does not fit ``raw/<index>`` as ``raw_changed/<index>/<set_index>``: the clause
        that says so, or ``""`` where the file does not take it."""
        name = f"raw_changed/{index}/{set_index}"
        try:
            check_room(self.h5.id.get_filesize(), image.nbytes, "the changed frame", self.h5.filename)
            ds = self.h5.create_dataset(name, data=image)
            ds.attrs["timestamp"] = float(frame.timestamp)
            ds.attrs["meta"] = _json(meta)
            self.h5.flush()
        except Exception:  # noqa: BLE001 - the failure is said either way, the frame only where kept
            with contextlib.suppress(Exception):
                del self.h5[name]
            return ""
        return f" (the frame is kept as {name})"

    def _create_raw(self, index: int, image: np.ndarray, frame, camera) -> None:
        import h5py

        ds = self.h5.create_dataset(
            f"raw/{index}",
            shape=(0,) + image.shape,
            maxshape=(None,) + image.shape,
            dtype=image.dtype,
            chunks=(1,) + image.shape,
        )
        ds.attrs["backend"] = camera.backend
        ds.attrs["name"] = camera.name
        if self.meta["cameras"][index].get("camera_name") is not None:
            ds.attrs["camera_name"] = self.meta["cameras"][index]["camera_name"]
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

    def _roll_back(self, index: int, n: int, first: bool) -> None:
        """Undo a frame that :meth:`add_raw` wrote in part: back to ``n`` frames, or, for the camera's first,
        no ``raw/<index>`` nor ``raw_meta/<index>``. Best effort: the fault being raised is the one reported."""
        names = [f"raw/{index}"] + [f"raw_meta/{index}/{key}" for key in ("set", "timestamp", "meta")]
        if first:
            names = [f"raw_meta/{index}", f"raw/{index}"]
        for name in names:
            with contextlib.suppress(Exception):
                if name in self.h5 and first:
                    del self.h5[name]
                elif name in self.h5 and self.h5[name].shape[0] > n:
                    self.h5[name].resize(n, axis=0)

    # ------------------------------------------------------------------ registered sets
    def add_registered(self, index: int, value: np.ndarray) -> None:
        self.pending[index] = value

    def complete_set(self, set_index: int, cameras) -> None:
        m, n = self.rig.shape
        stack = np.stack([self.pending[i] for i in range(self.K)])
        self.pending = {}
        if "snapshot_sets" not in self.h5:
            self.h5.create_dataset(
                "snapshot_sets",
                shape=(0, self.K, m, n),
                maxshape=(None, self.K, m, n),
                dtype=np.float64,
                chunks=(1, self.K, m, n),
            )
        ds = self.h5["snapshot_sets"]
        ds.resize(set_index + 1, axis=0)
        ds[set_index] = stack
        if set_index == 0:  # under temporary names until all are written whole; then the count says so
            truth = set_truth(cameras, self.rig, self.warn)
            sets_bytes = stack.nbytes * int(self.meta["sets_requested"])
            truth = room_for(truth, self.partial.parent, sets_bytes, self.warn, self.h5.id.get_filesize())
            names = ["snapshots"] + (["truth"] if truth is not None else [])
            for name, data in zip(names, (stack, truth)):
                self.h5.create_dataset(f"{name}.writing", data=data)
            for name in names:
                self.h5.move(f"{name}.writing", name)
            self.meta["truth"] = truth is not None
        self.h5.flush()
        self.sets_complete = set_index + 1
        self.h5.attrs["sets_complete"] = self.sets_complete
        self.meta["sets_complete"] = self.sets_complete
        self._write_meta()
        self.h5.flush()

    # ------------------------------------------------------------------ end
    def finish(self, status: str, failure: dict | None) -> None:
        self.meta.update(status=status, failure=failure, finished=_now())
        self.h5.attrs["capture_status"] = status
        if failure is not None:
            self.h5.attrs["failure"] = _json(failure)
        self._write_meta()

    def close(self) -> bool:
        """Flush and close the file; False when HDF5 could not (a write the disk refused). Never raises:
        the caller decides from the file (:func:`readable`) whether it can be published. An interrupt
        (Ctrl-C, SIGTERM) while it closes does not stop it; it is kept in :attr:`interrupt` (else None)
        for the caller to raise."""
        closed = True
        self.interrupt = None
        for step in (self.h5.flush, self.h5.close):
            try:
                step()
            except Exception:  # HDF5's RuntimeError/OSError: the data it holds cannot reach the disk
                closed = False
            except BaseException as exc:
                self.interrupt = self.interrupt or exc
        return closed


def readable(path: Path) -> bool:
    """Whether ``path`` opens as an HDF5 file and its ``sets_complete`` can be read."""
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            int(h5.attrs.get("sets_complete", 0))
    except Exception:
        return False
    return True


def publish(partial: Path, out: Path) -> None:
    """fsync ``partial`` and rename it to ``out`` (atomic on one file system), the mode of a file there kept.

    The rename is the last step, so that a block keeping the file there under a second name
    (:func:`rsocl.files.atomic.keeping`) fails only while ``out`` is still that file; the caller then
    persists the rename with :func:`rsocl.files.atomic.fsync_directory` on ``out``'s folder."""
    from rsocl.files.atomic import default_mode, fsync_file

    mode = (out.stat().st_mode & 0o7777) if out.exists() else default_mode()
    os.chmod(partial, mode)
    fsync_file(partial)
    os.replace(partial, out)
