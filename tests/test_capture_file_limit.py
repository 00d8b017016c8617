"""rsocl capture under a file-size limit (``ulimit -f``, RLIMIT_FSIZE) and on a disk that fills: a set with no room
ends the capture, the complete sets kept in a file HDF5 opens, and one line saying what was kept."""

from __future__ import annotations

import re
import subprocess
import sys

import h5py
import numpy as np
import pytest

from rsocl.files.hdf5 import load_capture
from rsocl.files.rigfile import RigFile, save_rigfile
from rsocl.hardware import capture_room
from rsocl.hardware.capture import CaptureFailed, capture_sets
from rsocl.hardware.capture_file import load_raw
from rsocl.model.rig import Rig

SHAPE = (32, 32)
SETS = 40  # 24 KiB of data each (two float32 frames, the registered float64 set): 960 KiB in all
LIMIT = 600_000

#: The child: the OpenCL kernels are built (PoCL writes files far larger than the limit as it compiles) in a
#: first capture, then the limit is set and the capture under test runs, as `rsocl capture` would.
CHILD = """
import resource, sys
from rsocl.cli.main import main
rig, out, warm, limit, sets = sys.argv[1:]
assert main(["capture", "--rig", rig, "--out", warm, "--quiet"]) == 0
resource.setrlimit(resource.RLIMIT_FSIZE, (int(limit), resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
sys.exit(main(["capture", "--rig", rig, "--out", out, "--sets", sets, "--quiet"]))
"""


def _rig_file(path):
    rf = RigFile.from_rig(Rig.paper_array(2, SHAPE, t_e=180e-6, t_r=35e-6))
    save_rigfile(path, rf)
    return path


@pytest.mark.not_under_oclgrind("host code: the capture file under a file-size limit, in a child process")
def test_a_capture_cut_by_the_file_size_limit_keeps_its_complete_sets_in_a_readable_file(tmp_path):
    rig, out = _rig_file(tmp_path / "rig.toml"), tmp_path / "cap.h5"
    warm = tmp_path / "warm" / "w.h5"
    warm.parent.mkdir()
    run = subprocess.run(
        [sys.executable, "-c", CHILD, str(rig), str(out), str(warm), str(LIMIT), str(SETS)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap.h5", "rig.toml", "warm"], run.stderr
    with h5py.File(out, "r") as h5:  # HDF5 opens it
        sets = int(h5.attrs["sets_complete"])
    assert 1 <= sets < SETS and out.stat().st_size <= LIMIT
    raw = load_raw(out)
    assert raw.status == "failed" and raw.sets_complete == sets
    assert {k: raw.failure[k] for k in ("camera", "set", "phase", "type")} == {
        "camera": None,
        "set": sets,
        "phase": "write",
        "type": "FileSizeLimit",
    }
    assert [f.shape[0] for f in raw.frames] == [sets, sets]  # the set refused was not triggered
    assert raw.snapshot_sets.shape == (sets, 2) + SHAPE
    capture = load_capture(out, set_index=sets - 1)
    np.testing.assert_array_equal(capture.snapshots, raw.snapshot_sets[sets - 1])
    assert capture.truth is None  # no room for it beside the sets asked for, under the limit
    assert run.returncode == 1
    (warning,) = [line for line in run.stderr.splitlines() if "warning" in line]
    assert re.fullmatch(
        r"rsocl capture: warning: no ground truth stored: it takes [\d.]+ MiB and the file-size limit \(ulimit -f\) "
        r"leaves the capture file [\d.]+ MiB, which the sets asked for need",
        warning,
    ), warning
    (error,) = [line for line in run.stderr.splitlines() if "error" in line]
    assert re.fullmatch(
        re.escape(
            f"rsocl capture: error: write failed in set {sets}: FileSizeLimit: set {sets} would take the capture "
            f"file past this process's file-size limit (ulimit -f) of {LIMIT:,} bytes: it holds "
        )
        + r"[\d,]+"
        + re.escape(
            f" bytes, and set {sets} needs room for its {24 * 1024:,} bytes twice over and {capture_room.SLACK:,} "
            f"for HDF5's metadata; raise the limit or capture fewer sets ({sets} complete set(s) and the failure "
            f"are in {out})"
        ),
        error,
    ), error


def test_a_capture_onto_a_disk_that_fills_keeps_its_complete_sets_in_a_readable_file(tmp_path, monkeypatch):
    import collections
    import shutil

    rig, folder = _rig_file(tmp_path / "rig.toml"), tmp_path / "disk"
    folder.mkdir()
    usage, size = collections.namedtuple("usage", "total used free"), 700_000  # a disk of 700 kB for the capture

    def disk_usage(path):
        used = sum(p.stat().st_size for p in folder.iterdir())
        return usage(size, used, max(0, size - used))

    monkeypatch.setattr(shutil, "disk_usage", disk_usage)
    out = folder / "cap.h5"
    with pytest.warns(UserWarning, match="no ground truth stored"):
        with pytest.raises(CaptureFailed, match=r"write failed in set (\d+): DiskFull: set \1 would fill the disk of"):
            capture_sets(rig, out, sets=SETS)
    raw = load_raw(out)
    sets = raw.sets_complete
    assert 1 <= sets < SETS and out.stat().st_size <= size
    assert raw.status == "failed" and raw.failure["type"] == "DiskFull" and raw.failure["set"] == sets
    assert [f.shape[0] for f in raw.frames] == [sets, sets]  # the set refused was not triggered
    capture = load_capture(out, set_index=sets - 1)
    np.testing.assert_array_equal(capture.snapshots, raw.snapshot_sets[sets - 1])


def test_a_frame_larger_than_the_set_was_counted_for_is_refused_before_it_is_written(tmp_path, monkeypatch):
    from rsocl.hardware.capture_file import CaptureWriter

    rig = _rig_file(tmp_path / "rig.toml")
    room = {}

    def check_room(self, set_index):  # record the room the set was given, and let it in
        room["size"] = self.h5.id.get_filesize()

    monkeypatch.setattr(CaptureWriter, "check_room", check_room)
    monkeypatch.setattr(capture_room, "file_size_limit", lambda: room.get("size", 0) + capture_room.SLACK + 1000)
    with pytest.raises(CaptureFailed, match=r"write failed in set 0: FileSizeLimit: camera 0's frame of set 0 would"):
        capture_sets(rig, tmp_path / "c.h5", sets=2)
    raw = load_raw(tmp_path / "c.h5")
    assert raw.sets_complete == 0 and [f.shape[0] for f in raw.frames] == [0, 0]


def test_a_file_size_limit_with_no_room_for_a_capture_file_is_refused_before_any_camera_opens(tmp_path, monkeypatch):
    from rsocl_plugins.simulated import SimulatedCamera

    rig = _rig_file(tmp_path / "rig.toml")
    monkeypatch.setattr(SimulatedCamera, "_open_device", lambda self: pytest.fail("a camera opened"))
    monkeypatch.setattr(capture_room, "file_size_limit", lambda: 4096)
    with pytest.raises(
        ValueError,
        match=r"^this process's file-size limit \(ulimit -f\) of 4,096 bytes leaves no room for a capture file",
    ):
        capture_sets(rig, tmp_path / "c.h5")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]
