"""Synchronized sets from the cameras of a rig file, written frame by frame (``rsocl capture``).

:func:`capture_sets` opens every camera of a :class:`~rsocl.files.rigfile.RigFile`
through its ``rsocl.cameras`` plugin, sets exposure (``t_e``), ROI, pixel format
and software trigger, then for each set fires all triggers back to back and
reads one frame per camera. Every raw frame is written to the file and flushed
before the next frame is requested, so whatever happens later, everything
already captured is on disk.

Settings a camera cannot take are refused (a ValueError naming the rig file's key and what it may be)
before the capture file is made (:mod:`rsocl.hardware.capture_checks`): a ``pixel_format`` the
camera does not deliver and a ``roi`` beyond a sensor whose size the backend tells before the
cameras open; a ``roi`` beyond a sensor whose size is known once the camera is open, right after
the cameras open (they are closed again). A camera that fails to open is recorded in the file,
as a camera that fails later is.

A device may apply another exposure than ``t_e`` (rounded to its units, clamped to its range).
The capture file's rig then holds, for that camera, the exposure the device applied (the
frames' true exposure, which the reconstruction needs), and a warning names both values
(``meta["warnings"]``, and a :class:`UserWarning` that ``rsocl capture`` prints). A readout
time the device reports differently from ``t_r`` is only warned about: devices define it in
different ways.

Files and atomicity
-------------------
The capture is written incrementally to ``<out>.partial`` and renamed to
``<out>`` when the run ends, successfully **or not**: a failed run still gives
``<out>``, holding the frames captured before the failure and the failure
itself. So does a run whose next set (or frame) its disk or the process's file-size limit
(``ulimit -f``) has no room for: it ends before that set is triggered (:mod:`rsocl.hardware.capture_room`), and
a limit that leaves no room for a capture file at all is refused before any camera opens. A
``<out>.partial`` left behind means the process itself died (power loss, ``kill -9``), or the rename
failed (the run's error names the file and its complete sets); it is a readable capture file up to
the last flush. It is
never truncated nor appended to: a capture to the same ``<out>`` is refused
(:func:`~rsocl.hardware.capture_file.check_partial`, naming the file and its complete sets) until the
user renames it (to keep it as a capture) or removes it; so is a capture
whose ``<out>.partial`` another process is writing, and one whose ``<out>``
holds frames from cameras, an earlier capture
(:func:`~rsocl.files.hdf5.refuse_camera_capture`). A simulated capture at ``<out>`` is replaced only
at the end of the run; any other file there (a reconstruction, say) then keeps a second name,
``<stem>.earlier-<UTC time><suffix>`` (:func:`~rsocl.files.hdf5.keeping_unless_simulated`), which a
warning names (or the error of a failed run). The file's layout and its reader,
:func:`~rsocl.hardware.capture_file.load_raw`, are in :mod:`rsocl.hardware.capture_file`.

Registration and units
----------------------
Frames from the ``simulated`` backend (``frame.meta["registered"]``) are on the
reference grid already (a simulated sensor *is* the reference grid); one of a partial ROI,
``frame.meta["roi"] = [x, y, width, height]`` on that grid, is put back in its place, 0 outside.
Other frames are warped onto it with the camera's
``homography`` from the rig file (:func:`rsocl.hardware.calibration.warp_to_reference`,
bilinear, 0 outside the sensor; the ROI origin is subtracted) or, without one, taken as registered (their shape
must then equal the rig's). Integer frames are converted to model units as
``image / (2**bit_depth - 1) * full_scale`` with ``full_scale`` from
``frame.meta["full_scale"]`` when the backend reports it, else a white scene's value at unit gain (which
fills the sensor): ``t_e/dt``, the applied exposure, or with the binary mask the most sub-frame starts one
exposure holds (:func:`rsocl.model.curvature.white_levels`); float frames are taken as they are.
"""

from __future__ import annotations

import contextlib
import json
import os
import warnings
from pathlib import Path

from rsocl.common import validation as check
from rsocl.common.interrupts import raise_dropped
from rsocl.files.atomic import fsync_directory, output_path
from rsocl.files.hdf5 import keeping_unless_simulated, refuse_camera_capture
from rsocl.files.rigfile import RigFile, load_rigfile
from rsocl.hardware.capture_cameras import closing_on_error, one_line, open_cameras, stop_cameras
from rsocl.hardware.capture_checks import check_pixel_formats, check_rois, in_file
from rsocl.hardware.capture_file import PARTIAL_SUFFIX, CaptureWriter, check_partial, publish, readable
from rsocl.hardware.capture_room import check_limit
from rsocl.hardware.registration import register

__all__ = ["capture_sets", "CaptureFailed"]


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


# ---------------------------------------------------------------------- capture
def _label(index, backend, config, name=None):
    """How messages name camera ``index``: ``camera 1 "north" (aravis 192.168.10.21)``."""
    address = config.get("address")
    called = "" if name is None else f" {json.dumps(name)}"
    return f"camera {index}{called} ({backend}{' ' + str(address) if address is not None else ''})"


def capture_sets(rigfile, out_path, sets=1, timeout=2.0, progress=False, name="out") -> Path:
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
    name : str
        How messages name ``out_path`` (``"--out"`` for ``rsocl capture``).

    Returns
    -------
    pathlib.Path
        ``out_path``, a complete capture file.

    Raises
    ------
    CaptureFailed
        A camera (or the registration of its frame) failed, or the next set would fill the file's disk or take
        the file past the process's file-size limit: ``out_path`` holds everything captured before and the
        failure (camera, set, error). Or the file could not be closed or renamed to ``out_path``:
        :attr:`CaptureFailed.path` (``<out_path>.partial``) holds the complete sets, and the message says so.
    ValueError, FileNotFoundError
        Bad arguments, rig file, unknown backend or camera config, a setting a camera cannot take
        (:mod:`rsocl.hardware.capture_checks`), a file-size limit with no room for a capture file, or an
        ``out_path`` that holds frames from cameras (an earlier capture); nothing is written.
    KeyboardInterrupt
        Re-raised (also when it comes while the cameras stop or close, which goes on for every camera)
        after the file is closed, with status ``"interrupted"``; its message names the file, its complete
        sets and its status.

    Warns
    -----
    UserWarning
        A file at ``out_path`` other than a simulated capture was kept as ``<stem>.earlier-<UTC time><suffix>``.
    """
    from rsocl.common.registry import load

    if not isinstance(rigfile, RigFile):
        rigfile = load_rigfile(rigfile)
    sets = check.positive_int("sets", sets)
    timeout = check.positive("timeout", timeout, "seconds")
    rig = rigfile.rig()
    for i, cam in enumerate(rig.cameras):
        if cam.frames != 1:
            raise ValueError(
                f"{in_file(rigfile)}camera[{i}].frames = {cam.frames}: rsocl capture reads one frame per trigger; "
                "set frames = 1 (multi-frame captures: rsocl simulate --frames N)"
            )
    folder = Path(rigfile.path).parent if rigfile.path is not None else Path(".")
    reads = [("rig file", rigfile.path)] + [
        (f"camera[{i}].row_map_file", folder / cam["row_map_file"])
        for i, cam in enumerate(rigfile.cameras)
        if isinstance(cam.get("row_map_file"), (str, os.PathLike))
    ]
    reads += [(f"camera[{i}].config.scene", rigfile.scene_path(i)) for i in range(len(rigfile.cameras))]
    reads = [(what, path) for what, path in reads if path is not None]
    out = output_path(out_path, name, inputs=reads)
    partial = output_path(out.with_name(out.name + PARTIAL_SUFFIX), name, inputs=reads)
    check_partial(partial, name)
    refuse_camera_capture(out, name)
    check_limit()

    backends = rigfile.backends()
    labels = [_label(i, b, c, cam.get("name")) for i, ((b, c), cam) in enumerate(zip(backends, rigfile.cameras))]
    cameras = [load("rsocl.cameras", b)(c, name=label) for (b, c), label in zip(backends, labels)]
    check_pixel_formats(rigfile, cameras)
    check_rois(rigfile, cameras)  # the sensors known before the cameras open

    where = {"camera": None, "set": None, "phase": "open"}
    failure, interrupted = open_cameras(cameras, where)
    if failure is None:
        closing_on_error(cameras, check_rois, rigfile, cameras)  # the sensors known once open
    writer = closing_on_error(cameras, CaptureWriter, partial, rig, rigfile, labels, sets, timeout)
    try:
        try:
            if failure is None:
                _run(cameras, rigfile, writer, sets, timeout, progress, where)
        except Exception as exc:
            failure = dict(where, type=type(exc).__name__, error=one_line(exc))
        except BaseException as exc:  # KeyboardInterrupt, SystemExit: record, then let it through
            failure = dict(where, type=type(exc).__name__, error=one_line(exc))
            interrupted = exc
        failure, interrupted = stop_cameras(cameras, writer, failure, interrupted)
        status = "complete" if failure is None else ("interrupted" if interrupted is not None else "failed")
        try:
            writer.finish(status, failure)
        except BaseException as exc:  # the file takes no more (disk full): whether it is readable decides below
            failure = failure or dict(where, phase="write", type=type(exc).__name__, error=one_line(exc))
            if not isinstance(exc, Exception):  # Ctrl-C while the status is written: written again
                interrupted = interrupted or exc
                with contextlib.suppress(Exception):
                    writer.finish("interrupted", failure)
    finally:
        closed = writer.close()
    interrupted = interrupted or writer.interrupt
    status = writer.meta["status"]
    if not (closed and readable(partial)):
        state = "is unchanged" if out.exists() else "was not made"
        why = "" if failure is None else f"{failure['type']}: {failure['error']}; "
        message = (
            f"the capture file could not be completed ({why}HDF5 could not close it): {str(partial)!r} is kept as "
            f"written, {writer.sets_complete} set(s) complete before the failure; {str(out)!r} {state}"
        )
        _raise_kept(message, partial, writer, failure, interrupted)
    kept: Path | None = None
    fault = None
    try:
        with keeping_unless_simulated(out) as kept:  # a file there that is not a simulated capture keeps a name
            publish(partial, out)
        fsync_directory(out.parent if str(out.parent) else Path("."))
    except BaseException as exc:  # the rename failed (its kept copy is then removed again), or an interrupt
        kept, fault = (kept if kept is not None and kept.exists() else None), exc
        interrupted = interrupted or (None if isinstance(exc, Exception) else exc)
    if partial.exists():  # not renamed: it holds the capture; out is as it was
        how = "was interrupted" if not isinstance(fault, Exception) else f"failed ({_fault_words(fault)})"
        what = "" if failure is None else f"; {failure['phase']} failed: {failure['type']}: {failure['error']}"
        message = (
            f"{str(partial)!r} holds the {writer.sets_complete} complete set(s) (capture_status {status!r}{what}) "
            f"and is kept as it is: renaming it to {str(out)!r} {how}, so {str(out)!r} "
            f"{'is unchanged' if out.exists() else 'was not made'}"
        )
        _raise_kept(message, partial, writer, failure, interrupted)
    note = "" if kept is None else f"; the earlier file there is kept as {kept}"
    if kept is not None and failure is None and interrupted is None:  # the error or interrupt line says it
        warnings.warn(f"{out}: the earlier file there is kept as {kept}", stacklevel=2)
    if isinstance(interrupted, KeyboardInterrupt):
        raise type(interrupted)(
            f"{out} holds the {writer.sets_complete} complete set(s) (capture_status {status!r}){note}"
        ) from None
    if interrupted is not None:
        raise interrupted
    if failure is not None:
        who = "" if failure["camera"] is None else f"{labels[failure['camera']]}: "
        when = "before the first set" if failure["set"] is None else f"in set {failure['set']}"
        raise CaptureFailed(
            f"{who}{failure['phase']} failed {when}: {failure['type']}: {failure['error']} "
            f"({writer.sets_complete} complete set(s) and the failure are in {out}{note})",
            path=out,
            camera=failure["camera"],
            set_index=failure["set"],
            phase=failure["phase"],
            sets_complete=writer.sets_complete,
        )
    return out


def _raise_kept(message, partial, writer, failure, interrupted):
    """Raise the end of a capture whose file stays at ``partial``: a :class:`CaptureFailed` with ``message``,
    or the interrupt with it as its message (Ctrl-C, SIGTERM: the line says what was kept)."""
    error = CaptureFailed(
        message,
        path=partial,
        camera=None if failure is None else failure["camera"],
        set_index=None if failure is None else failure["set"],
        phase="write",
        sets_complete=writer.sets_complete,
    )
    if isinstance(interrupted, KeyboardInterrupt):
        raise type(interrupted)(message) from None
    if interrupted is not None:
        raise interrupted from error
    raise error


def _fault_words(exc: Exception) -> str:
    """An :class:`~rsocl.files.atomic.OutputError` as it is (it names its file), another fault on one line."""
    from rsocl.files.atomic import OutputError

    return str(exc) if isinstance(exc, OutputError) else one_line(exc)


#: Longest wait, seconds, for each frame a failed set had triggered: it should be there already.
FIRED_WAIT = 1.0


def _keep_fired(cameras, fired, set_index, writer, timeout) -> None:
    """After a failure in set ``set_index``, read and keep the raw frames of the cameras ``fired`` (triggered,
    not read yet): captured frames are saved, though the set is not complete. A camera that fails too is left."""
    for i in fired:
        with contextlib.suppress(Exception):
            writer.add_raw(i, set_index, cameras[i].read(min(timeout, FIRED_WAIT)), cameras[i])


def _run(cameras, rigfile, writer, sets, timeout, progress, where):
    from tqdm import tqdm

    def at(camera, set_index, phase):
        where.update(camera=camera, set=set_index, phase=phase)

    exposures = []
    for i, cam in enumerate(cameras):
        at(i, None, "configure")
        spec = rigfile.cameras[i]
        exposure = cam.set_exposure(spec["t_e"])
        exposures.append(exposure)
        settings = {"exposure": exposure}
        if spec.get("pixel_format"):  # first: the frame size and the ROI's bounds may depend on it
            cam.set_pixel_format(spec["pixel_format"])
            settings["pixel_format"] = spec["pixel_format"]
        if spec.get("roi"):
            cam.set_roi(*spec["roi"])
            settings["roi"] = list(spec["roi"])
        cam.set_trigger("software")
        readout = cam.readout_time
        settings["readout_time"] = readout
        if readout is not None and abs(readout - spec["t_r"]) > 1e-3 * spec["t_r"]:
            writer.warn(f"camera {i}: the device reports t_r = {readout!r} s, the rig file says {spec['t_r']!r} s")
        writer.camera_settings(i, **settings)
    at(None, None, "configure")
    writer.use_exposures(exposures)
    for i, cam in enumerate(cameras):
        at(i, None, "start")
        cam.start()
    with tqdm(total=sets, unit="set", desc="capture", disable=not progress) as bar:
        for j in range(sets):
            fired: list = []  # cameras triggered in this set whose frame is not read yet
            try:
                at(None, j, "write")
                writer.check_room(j)  # a set the disk or the file-size limit has no room for ends the capture first
                for i, cam in enumerate(cameras):  # fire all triggers back to back
                    at(i, j, "trigger")
                    cam.trigger()
                    fired.append(i)
                for i, cam in enumerate(cameras):
                    at(i, j, "read")
                    fired.remove(i)  # this camera's frame comes now, or its failure
                    frame = cam.read(timeout)
                    at(i, j, "write")
                    writer.add_raw(i, j, frame, cam)
                    at(i, j, "register")
                    writer.add_registered(i, register(rigfile, writer.rig, i, frame))
            except Exception:
                _keep_fired(cameras, fired, j, writer, timeout)
                raise
            at(None, j, "write")
            writer.complete_set(j, cameras)
            bar.update(1)
            raise_dropped()  # a Ctrl-C or SIGTERM whose exception Python dropped (rsocl.common.interrupts)
