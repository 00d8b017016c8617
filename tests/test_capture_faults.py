"""rsocl capture when a fault or an interrupt (Ctrl-C, SIGTERM) comes at the end of a run or inside a frame's write:
every camera is closed, nothing captured is lost, the raw frames and their metadata stay in step, and one line
says where the captured sets are."""

import errno
import os
import signal
import stat

import h5py
import numpy as np
import pytest

from rsocl.cli.main import Terminated, main
from rsocl.files.hdf5 import save_reconstruction
from rsocl.files.rigfile import RigFile, save_rigfile
from rsocl.hardware.capture import CaptureFailed, capture_sets
from rsocl.hardware.capture_file import CaptureWriter, load_raw
from rsocl.model.rig import Rig
from rsocl_plugins.simulated import SimulatedCamera

SHAPE = (16, 16)
T_E, T_R = 180e-6, 35e-6


def _rig_path(folder, configs=None):
    rig = Rig.paper_array(2, SHAPE, t_e=T_E, t_r=T_R)
    rf = RigFile.from_rig(rig, configs=configs)
    path = folder / "rig.toml"
    save_rigfile(path, RigFile(shape=rf.shape, cameras=rf.cameras, dt=rf.dt, mask=rf.mask))
    return path


def _capture(rig_path, out, sets=3):
    return main(["capture", "--rig", str(rig_path), "--out", str(out), "--sets", str(sets), "--quiet"])


def _in_step(raw):
    """Per camera: as many set, timestamp and meta entries as frames, and no frame that no camera delivered."""
    for i, frames in enumerate(raw.frames):
        assert len(frames) == len(raw.sets[i]) == len(raw.timestamps[i]) == len(raw.frame_meta[i]), i
        assert list(raw.sets[i]) == list(range(len(frames))), i
        assert all(frame.max() > 0 for frame in frames), i


# ---------------------------------------------------------------------- bug 1: interrupts while the run ends
@pytest.fixture
def closed(monkeypatch):
    """The indices of the cameras whose device was closed."""
    indices = []
    real_close = SimulatedCamera._close_device

    def close_device(self):
        indices.append(self.index)
        return real_close(self)

    monkeypatch.setattr(SimulatedCamera, "_close_device", close_device)
    return indices


def _interrupt_on_stop(monkeypatch, kind=KeyboardInterrupt):
    real_stop = SimulatedCamera._stop

    def stop(self):
        if self.index == 0:
            raise kind()
        return real_stop(self)

    monkeypatch.setattr(SimulatedCamera, "_stop", stop)


def test_an_interrupt_while_a_camera_stops_closes_every_camera_and_publishes_the_capture(tmp_path, monkeypatch, closed):
    _interrupt_on_stop(monkeypatch)
    out = tmp_path / "c.h5"
    with pytest.raises(KeyboardInterrupt) as caught:
        capture_sets(_rig_path(tmp_path), out, sets=3)
    assert str(caught.value) == f"{out} holds the 3 complete set(s) (capture_status 'interrupted')"
    assert sorted(closed) == [0, 1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.h5", "rig.toml"]
    raw = load_raw(out)
    assert raw.status == "interrupted" and raw.sets_complete == 3 and raw.snapshot_sets.shape[0] == 3
    assert raw.failure == {
        "camera": 0,
        "set": None,
        "phase": "stop",
        "type": "KeyboardInterrupt",
        "error": "KeyboardInterrupt",
    }
    _in_step(raw)


@pytest.mark.parametrize("kind, how, code", [(KeyboardInterrupt, "interrupted", 130), (Terminated, "terminated", 143)])
def test_ctrl_c_or_sigterm_while_a_camera_stops_ends_in_one_line_naming_the_capture(
    tmp_path, monkeypatch, capsys, closed, kind, how, code
):
    _interrupt_on_stop(monkeypatch, kind)
    out = tmp_path / "c.h5"
    assert _capture(_rig_path(tmp_path), out) == code
    err = capsys.readouterr().err
    assert err == f"rsocl capture: {how}: {out} holds the 3 complete set(s) (capture_status 'interrupted')\n"
    assert sorted(closed) == [0, 1] and load_raw(out).sets_complete == 3


@pytest.mark.parametrize(
    "signum, how, code", [(signal.SIGINT, "interrupted", 130), (signal.SIGTERM, "terminated", 143)]
)
def test_a_signal_whose_exception_python_dropped_still_ends_the_capture_after_its_set(
    tmp_path, monkeypatch, capsys, signum, how, code
):
    from rsocl.common import interrupts

    real = CaptureWriter.complete_set

    def complete_set(self, j, cameras):  # the signal came in a weakref callback: noted, its exception dropped
        real(self, j, cameras)
        if j == 1:
            interrupts._NOTED.append(signum)

    monkeypatch.setattr(CaptureWriter, "complete_set", complete_set)
    out = tmp_path / "c.h5"
    assert _capture(_rig_path(tmp_path), out, sets=6) == code
    assert capsys.readouterr().err == (
        f"rsocl capture: {how}: {out} holds the 2 complete set(s) (capture_status 'interrupted')\n"
    )
    assert load_raw(out).sets_complete == 2 and not interrupts._NOTED


def test_an_interrupt_while_the_status_is_written_still_publishes_the_capture(tmp_path, monkeypatch, closed):
    real_finish = CaptureWriter.finish
    calls = []

    def finish(self, status, failure):
        calls.append(status)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return real_finish(self, status, failure)

    monkeypatch.setattr(CaptureWriter, "finish", finish)
    out = tmp_path / "c.h5"
    with pytest.raises(
        KeyboardInterrupt, match=r"c\.h5 holds the 3 complete set\(s\) \(capture_status 'interrupted'\)"
    ):
        capture_sets(_rig_path(tmp_path), out, sets=3)
    assert sorted(closed) == [0, 1] and not (tmp_path / "c.h5.partial").exists()
    raw = load_raw(out)
    assert raw.status == "interrupted" and raw.sets_complete == 3 and raw.failure["type"] == "KeyboardInterrupt"


def test_an_interrupt_while_the_file_closes_still_closes_and_publishes_it(tmp_path, monkeypatch):
    real_finish = CaptureWriter.finish

    def finish(self, status, failure):
        real_finish(self, status, failure)
        real_flush = self.h5.flush

        def flush():  # Ctrl-C as the last flush returns
            real_flush()
            raise KeyboardInterrupt

        self.h5.flush = flush

    monkeypatch.setattr(CaptureWriter, "finish", finish)
    out = tmp_path / "c.h5"
    with pytest.raises(KeyboardInterrupt, match=r"c\.h5 holds the 2 complete set\(s\) \(capture_status 'complete'\)"):
        capture_sets(_rig_path(tmp_path), out, sets=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.h5", "rig.toml"] and load_raw(out).status == "complete"


# ---------------------------------------------------------------------- bug 2: a raw frame written in part
def _fault_on_write(monkeypatch, dataset, count, fault, after):
    """The ``count``-th write to ``dataset`` raises ``fault``, before or ``after`` the real write."""
    real_setitem = h5py.Dataset.__setitem__
    writes = []

    def setitem(self, key, value):
        if self.name == dataset:
            writes.append(key)
            if len(writes) == count and not after:
                raise fault
        real_setitem(self, key, value)
        if self.name == dataset and len(writes) == count and after:
            raise fault

    monkeypatch.setattr(h5py.Dataset, "__setitem__", setitem)


@pytest.mark.parametrize(
    "dataset, count, after",
    [
        ("/raw/1", 2, True),  # Ctrl-C as the image write returns: its set, timestamp and meta not written yet
        ("/raw/1", 1, True),  # the same on the camera's first frame
        ("/raw_meta/1/timestamp", 2, False),  # between the metadata writes
    ],
)
def test_an_interrupt_inside_a_raw_frames_write_rolls_the_frame_back(tmp_path, monkeypatch, dataset, count, after):
    _fault_on_write(monkeypatch, dataset, count, KeyboardInterrupt(), after)
    out = tmp_path / "c.h5"
    with pytest.raises(KeyboardInterrupt, match=f"holds the {count - 1} complete set"):
        capture_sets(_rig_path(tmp_path), out, sets=3)
    monkeypatch.undo()
    raw = load_raw(out)
    assert raw.status == "interrupted" and raw.sets_complete == count - 1
    assert [len(f) for f in raw.frames] == [count, count - 1]
    _in_step(raw)


def test_a_write_error_on_a_raw_frame_leaves_no_frame_of_zeros(tmp_path, monkeypatch, capsys):
    _fault_on_write(monkeypatch, "/raw/1", 2, OSError(errno.EIO, "Can't write data (file write failed)"), False)
    out = tmp_path / "c.h5"
    assert _capture(_rig_path(tmp_path), out) == 1
    assert (
        "camera 1 (simulated): write failed in set 1: OSError: [Errno 5] Input/output error" in capsys.readouterr().err
    )
    monkeypatch.undo()
    raw = load_raw(out)
    assert raw.status == "failed" and raw.sets_complete == 1 and [len(f) for f in raw.frames] == [2, 1]
    _in_step(raw)


# ---------------------------------------------------------------------- bug 3: the rename to --out fails
def _refuse_chmod_of_partial(monkeypatch, fault):
    real_chmod = os.chmod

    def chmod(path, mode, *args, **kwargs):
        if str(path).endswith(".partial"):
            raise fault
        return real_chmod(path, mode, *args, **kwargs)

    monkeypatch.setattr(os, "chmod", chmod)


def test_a_failed_rename_says_in_one_line_that_the_partial_file_holds_the_capture(tmp_path, monkeypatch, capsys):
    _refuse_chmod_of_partial(monkeypatch, PermissionError(errno.EPERM, os.strerror(errno.EPERM)))
    out, partial = tmp_path / "c.h5", tmp_path / "c.h5.partial"
    assert _capture(_rig_path(tmp_path), out) == 1
    assert capsys.readouterr().err == (
        f"rsocl capture: error: {str(partial)!r} holds the 3 complete set(s) (capture_status 'complete') and is "
        f"kept as it is: renaming it to {str(out)!r} failed ([Errno 1] Operation not permitted), so {str(out)!r} "
        "was not made\n"
    )
    monkeypatch.undo()
    raw = load_raw(partial)
    assert raw.status == "complete" and raw.sets_complete == 3 and not out.exists()

    # through the API: CaptureFailed names the partial file; a camera failure is still said
    rig_path = _rig_path(tmp_path, configs=[{"fail_after": 2}, {}])
    _refuse_chmod_of_partial(monkeypatch, PermissionError(errno.EPERM, os.strerror(errno.EPERM)))
    with pytest.raises(CaptureFailed) as caught:
        capture_sets(rig_path, tmp_path / "f.h5", sets=3)
    assert caught.value.path == tmp_path / "f.h5.partial" and caught.value.sets_complete == 1
    assert "holds the 1 complete set(s) (capture_status 'failed'; read failed: " in str(caught.value)

    # an interrupt while renaming: the interrupt's line says the same
    _refuse_chmod_of_partial(monkeypatch, KeyboardInterrupt())
    with pytest.raises(KeyboardInterrupt, match=r"i\.h5\.partial' holds the 1 complete set\(s\) .*was interrupted"):
        capture_sets(rig_path, tmp_path / "i.h5", sets=1)


def test_a_failed_copy_of_the_earlier_file_keeps_it_and_names_the_captured_sets(tmp_path, monkeypatch, capsys):
    import rsocl.files.atomic as atomic

    out = tmp_path / "c.h5"
    rig = Rig.paper_array(2, SHAPE, t_e=T_E, t_r=T_R)
    save_reconstruction(out, np.zeros((rig.T,) + SHAPE), rig)  # an earlier result at --out
    before = out.read_bytes()

    def no_link(src, dst, *args, **kwargs):
        raise PermissionError(errno.EPERM, os.strerror(errno.EPERM), str(src), None, str(dst))

    def full_copy(src, dst, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(dst))

    monkeypatch.setattr(atomic.os, "link", no_link)
    monkeypatch.setattr(atomic.shutil, "copy2", full_copy)
    assert _capture(_rig_path(tmp_path), out) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "No space left on device" in err
    assert f"{str(out) + '.partial'!r} holds the 3 complete set(s) (capture_status 'complete')" in err
    assert err.endswith(f"so {str(out)!r} is unchanged\n") and out.read_bytes() == before


def test_an_interrupt_after_the_rename_keeps_the_earlier_file(tmp_path, monkeypatch):
    out = tmp_path / "c.h5"
    rig = Rig.paper_array(2, SHAPE, t_e=T_E, t_r=T_R)
    save_reconstruction(out, np.zeros((rig.T,) + SHAPE), rig)
    before, rig_path = out.read_bytes(), _rig_path(tmp_path)
    real_fsync = os.fsync

    def fsync(fd):  # Ctrl-C while the folder's rename is persisted
        real_fsync(fd)
        if stat.S_ISDIR(os.fstat(fd).st_mode):
            raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", fsync)
    with pytest.raises(KeyboardInterrupt) as caught:
        capture_sets(rig_path, out, sets=1)
    monkeypatch.undo()
    (earlier,) = tmp_path.glob("c.earlier-*.h5")
    assert earlier.read_bytes() == before and load_raw(out).sets_complete == 1
    assert str(caught.value) == (
        f"{out} holds the 1 complete set(s) (capture_status 'complete'); the earlier file there is kept as {earlier}"
    )


# ---------------------------------------------------------------------- bug 4: --out that is an input
def test_an_out_that_is_a_row_map_is_refused_naming_the_option_and_the_camera(tmp_path, capsys):
    rows = tmp_path / "rows.npy"
    np.save(rows, np.tile(np.arange(16.0)[:, None], (1, 16)))
    cameras = [
        {"backend": "simulated", "angle": 0.0, "t_e": T_E, "t_r": T_R, "config": {}},
        {"backend": "simulated", "row_map_file": "rows.npy", "t_e": T_E, "t_r": T_R, "config": {}},
    ]
    rig_path = tmp_path / "rig.toml"
    save_rigfile(rig_path, RigFile(shape=SHAPE, cameras=cameras, path=rig_path))
    before = rows.read_bytes()
    assert main(["capture", "--rig", str(rig_path), "--out", str(rows), "--quiet"]) == 2  # no HDF5 name, first
    assert capsys.readouterr().err == (
        f"rsocl capture: error: --out must name an HDF5 file (.h5, .hdf5, .hdf, .he5), got {str(rows)!r}\n"
    )
    with pytest.raises(ValueError, match=r"^out '.*rows\.npy' is the camera\[1\]\.row_map_file it reads"):
        capture_sets(rig_path, rows)
    assert rows.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml", "rows.npy"]
