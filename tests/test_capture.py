"""rsocl capture with simulated cameras: the capture file, the round trip, failures and the command."""

import argparse

import h5py
import numpy as np
import pytest

from rsocl import reconstruct
from rsocl.analysis.metrics import psnr
from rsocl.cli.capture import add_parser as add_capture_parser
from rsocl.cli.capture import cmd_capture
from rsocl.files.hdf5 import load_capture
from rsocl.files.rigfile import RigFile, save_rigfile
from rsocl.hardware.capture import CaptureFailed, capture_sets
from rsocl.hardware.capture_file import load_raw
from rsocl.model import reference
from rsocl.model.rig import Rig
from rsocl.model.scenes import builtin_scene
from rsocl_plugins.simulated import SimulatedCamera

SHAPE = (16, 16)
T_E, T_R = 180e-6, 35e-6


def _rigfile(configs=None, **camera_extra):
    rig = Rig.paper_array(4, SHAPE, t_e=T_E, t_r=T_R)
    rf = RigFile.from_rig(rig, configs=configs)
    for i, extra in camera_extra.items():
        rf.cameras[int(i[1:])].update(extra)
    return RigFile(shape=rf.shape, cameras=rf.cameras, dt=rf.dt, mask=rf.mask)


def test_capture_round_trip(tmp_path):
    path = tmp_path / "rig.toml"
    save_rigfile(path, _rigfile(configs=[{}, {"sensor": {"bit_depth": 12}}, {}, {}]))
    out = tmp_path / "capture.h5"
    assert capture_sets(path, out, sets=3) == out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture.h5", "rig.toml"]  # no .partial left

    capture = load_capture(out, set_index=0)
    rig = capture.rig
    assert rig == Rig.paper_array(4, SHAPE, t_e=T_E, t_r=T_R)
    assert capture.snapshots.shape == (4,) + SHAPE and capture.truth.shape == (rig.T,) + SHAPE
    assert capture.meta["status"] == "complete" and capture.meta["sets_complete"] == 3
    assert capture.meta["rig_file"] == str(path) and capture.meta["cameras"][1]["exposure"] == T_E
    assert capture.meta["cameras"][1]["readout_time"] == T_R
    # the four simulated cameras together are the rig's forward model of the scene
    np.testing.assert_array_equal(capture.truth, builtin_scene(SHAPE, rig.T, dtype=np.float64, seed=0))
    expected = reference.forward(rig, capture.truth)
    np.testing.assert_allclose(capture.snapshots[[0, 2, 3]], expected[[0, 2, 3]], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(capture.snapshots[1], expected[1], atol=T_E / T_R / 4095 / 2 + 1e-5)  # 12 bits

    raw = load_raw(out)
    assert raw.status == "complete" and raw.failure is None and raw.sets_complete == 3
    assert [f.shape for f in raw.frames] == [(3,) + SHAPE] * 4
    assert [f.dtype for f in raw.frames] == [np.float32, np.uint16, np.float32, np.float32]
    assert all(list(s) == [0, 1, 2] for s in raw.sets)
    assert raw.frame_meta[1][2]["bit_depth"] == 12 and raw.frame_meta[1][2]["pixel_format"] == "Mono16"
    assert raw.snapshot_sets.shape == (3, 4) + SHAPE
    np.testing.assert_array_equal(raw.snapshot_sets[0], capture.snapshots)
    later = reference.forward(rig, builtin_scene(SHAPE, rig.T, dtype=np.float64, seed=2))  # set 2: seed 2
    np.testing.assert_allclose(raw.snapshot_sets[2][[0, 2, 3]], later[[0, 2, 3]], rtol=1e-5, atol=1e-5)
    with h5py.File(out, "r") as h5:
        assert h5.attrs["capture_status"] == "complete" and "failure" not in h5.attrs
        assert h5["raw/1"].attrs["backend"] == "simulated" and h5["raw/1"].attrs["bit_depth"] == 12
        assert h5["raw/0"].maxshape == (None,) + SHAPE

    result = reconstruct(capture.snapshots, rig, iterations=60, truth=capture.truth)
    assert psnr(result.datacube, capture.truth) > 18.0


def test_each_frame_is_written_before_the_next_is_requested(tmp_path, monkeypatch):
    from rsocl.hardware import capture_file

    log = []
    real_read, real_add = SimulatedCamera._read, capture_file.CaptureWriter.add_raw
    monkeypatch.setattr(
        SimulatedCamera, "_read", lambda self, t: log.append(("read", self.index)) or real_read(self, t)
    )
    monkeypatch.setattr(
        SimulatedCamera,
        "_trigger",
        (lambda trig: lambda self: log.append(("trigger", self.index)) or trig(self))(SimulatedCamera._trigger),
    )
    monkeypatch.setattr(
        capture_file.CaptureWriter,
        "add_raw",
        lambda self, i, j, frame, cam: log.append(("write", i)) or real_add(self, i, j, frame, cam),
    )
    capture_sets(_rigfile(), tmp_path / "c.h5", sets=2)
    one_set = [("trigger", i) for i in range(4)] + [x for i in range(4) for x in (("read", i), ("write", i))]
    assert log == one_set * 2


def test_camera_failure_keeps_what_was_captured(tmp_path):
    out = tmp_path / "capture.h5"
    rf = _rigfile(configs=[{}, {}, {"fail_after": 2}, {}])
    with pytest.raises(
        CaptureFailed, match=r"camera 2 \(simulated\): read failed in set 1: CameraDisconnected"
    ) as info:
        capture_sets(rf, out, sets=3)
    exc = info.value
    assert (exc.path, exc.camera, exc.set_index, exc.phase, exc.sets_complete) == (out, 2, 1, "read", 1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture.h5"]

    raw = load_raw(out)
    assert raw.status == "failed" and raw.sets_complete == 1
    assert raw.failure == {
        "camera": 2,
        "set": 1,
        "phase": "read",
        "type": "CameraDisconnected",
        "error": raw.failure["error"],
    }
    assert "fail_after=2" in raw.failure["error"]
    # set 1: cameras 0, 1 read before camera 2 failed, and camera 3's frame, triggered with them, kept after
    assert [f.shape[0] for f in raw.frames] == [2, 2, 1, 2] and list(raw.sets[3]) == [0, 1]
    assert raw.snapshot_sets.shape == (1, 4) + SHAPE
    capture = load_capture(out)  # set 0 is complete: a valid capture file
    assert capture.meta["status"] == "failed" and capture.meta["failure"]["camera"] == 2
    np.testing.assert_array_equal(capture.snapshots, raw.snapshot_sets[0])

    # failure in the first set: raw frames and the failure are kept, but there are no snapshots yet
    first = tmp_path / "first.h5"
    with pytest.raises(CaptureFailed, match="in set 0"):
        capture_sets(_rigfile(configs=[{}, {"fail_after": 1}, {}, {}]), first, sets=2)
    raw = load_raw(first)
    assert [f.shape[0] for f in raw.frames] == [1, 0, 1, 1] and raw.failure["camera"] == 1  # 2, 3: triggered
    with pytest.raises(ValueError, match="snapshots"):
        load_capture(first)


def test_open_and_registration_failures(tmp_path, monkeypatch):
    out = tmp_path / "c.h5"
    (tmp_path / "bad.npz").write_text("not a video", encoding="utf-8")  # there, but no video: fails at open
    with pytest.raises(CaptureFailed, match="open failed before the first set") as info:
        capture_sets(_rigfile(configs=[{}, {}, {}, {"scene": str(tmp_path / "bad.npz")}]), out)
    assert (info.value.camera, info.value.set_index) == (3, None)
    assert load_raw(out).failure["phase"] == "open"
    # a frame that cannot be registered (NaN values): the raw frame is still kept
    read = SimulatedCamera._read

    def nan_in_camera_1(camera, timeout):
        frame = read(camera, timeout)
        if camera.index == 1:
            frame.image[0, 0] = np.nan
        return frame

    with monkeypatch.context() as patch:
        patch.setattr(SimulatedCamera, "_read", nan_in_camera_1)
        with pytest.raises(CaptureFailed, match="register failed in set 0.*NaN"):
            capture_sets(_rigfile(c1={"roi": [2, 3, 12, 10]}), out)
    raw = load_raw(out)
    assert raw.frames[1].shape == (1, 10, 12) and raw.failure["phase"] == "register"
    # errors in the arguments or the rig write nothing
    for bad in ({"sets": 0}, {"timeout": -1.0}):
        with pytest.raises(ValueError):
            capture_sets(_rigfile(), tmp_path / "none.h5", **bad)
    with pytest.raises(ValueError, match="unknown config key"):
        capture_sets(_rigfile(configs=[{"exposure": 1}, {}, {}, {}]), tmp_path / "none.h5")
    with pytest.raises(ValueError, match="unknown camera 'nope'"):
        capture_sets(_rigfile(c0={"backend": "nope"}), tmp_path / "none.h5")
    assert not (tmp_path / "none.h5").exists() and not (tmp_path / "none.h5.partial").exists()


def test_homography_registers_a_cropped_roi(tmp_path):
    rf = _rigfile(c0={"roi": [2, 3, 12, 10], "homography": np.eye(3).tolist(), "angle": None})
    capture = load_capture(capture_sets(rf, tmp_path / "c.h5"))
    raw = load_raw(tmp_path / "c.h5")
    registered = capture.snapshots[0]
    np.testing.assert_allclose(registered[3:13, 2:14], raw.frames[0][0], rtol=1e-6)
    assert np.all(registered[:3] == 0) and np.all(registered[:, :2] == 0)
    # docs/model.md: the sensor row of each pixel, counted from the roi's top row, the first the camera reads
    # (the rows above it are not read: 0)
    np.testing.assert_array_equal(capture.rig.row_map(0), np.maximum(Rig.paper_array(1, SHAPE).row_map(0) - 3, 0))


def test_interrupt_is_recorded_and_re_raised(tmp_path, monkeypatch):
    real_read = SimulatedCamera._read

    def read(self, timeout):
        if self.index == 1 and self._reads == 1:
            raise KeyboardInterrupt
        return real_read(self, timeout)

    monkeypatch.setattr(SimulatedCamera, "_read", read)
    with pytest.raises(KeyboardInterrupt):
        capture_sets(_rigfile(), tmp_path / "c.h5", sets=3)
    raw = load_raw(tmp_path / "c.h5")
    assert raw.status == "interrupted" and raw.failure["type"] == "KeyboardInterrupt" and raw.sets_complete == 1


def test_an_interrupted_capture_says_in_one_line_what_the_file_holds(tmp_path, monkeypatch, capsys):
    from rsocl.cli.main import main

    real_read = SimulatedCamera._read

    def read(self, timeout):
        if self.index == 1 and self._reads == 2:
            raise KeyboardInterrupt
        return real_read(self, timeout)

    monkeypatch.setattr(SimulatedCamera, "_read", read)
    rig_path, out = tmp_path / "rig.toml", tmp_path / "c.h5"
    save_rigfile(rig_path, _rigfile())
    assert main(["capture", "--rig", str(rig_path), "--out", str(out), "--sets", "5", "--quiet"]) == 130
    err = capsys.readouterr().err
    assert err == f"rsocl capture: interrupted: {out} holds the 2 complete set(s) (capture_status 'interrupted')\n"
    assert load_raw(out).sets_complete == 2


def test_cmd_capture(tmp_path, capsys):
    rig_path = tmp_path / "rig.toml"
    save_rigfile(rig_path, _rigfile())
    parser = argparse.ArgumentParser(prog="rsocl")
    add_capture_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["capture", "--rig", str(rig_path), "--out", str(tmp_path / "c.h5"), "--sets", "2"])
    assert args.func is cmd_capture and args.timeout == 2.0 and not args.quiet
    assert args.func(args) == 0
    assert "wrote" in capsys.readouterr().out and load_raw(tmp_path / "c.h5").sets_complete == 2
    # and the capture file feeds 'rsocl reconstruct' as it is
    from rsocl.cli.main import main

    assert (
        main(["reconstruct", str(tmp_path / "c.h5"), "--out", str(tmp_path / "r.h5"), "--iterations", "10", "--quiet"])
        == 0
    )
    assert "PSNR" in capsys.readouterr().out

    save_rigfile(rig_path, _rigfile(configs=[{"fail_after": 2}, {}, {}, {}]))
    args = argparse.Namespace(rig=str(rig_path), out=str(tmp_path / "f.h5"), sets=3, timeout=1.0, quiet=True)
    assert cmd_capture(args) == 1
    captured = capsys.readouterr()
    assert captured.out == "" and "rsocl capture: error: camera 0 (simulated): read failed in set 1" in captured.err
    assert load_raw(tmp_path / "f.h5").status == "failed"


def test_an_output_that_is_an_input_is_refused_before_any_camera_opens(tmp_path):
    from rsocl.cli.main import main

    rig_path = tmp_path / "rig.toml"
    save_rigfile(rig_path, _rigfile())
    before = rig_path.read_bytes()
    with pytest.raises(ValueError, match=r"out .*rig.toml' is the rig file it reads"):
        capture_sets(rig_path, rig_path, sets=1)
    assert main(["capture", "--rig", str(rig_path), "--out", str(rig_path), "--quiet"]) == 2
    assert rig_path.read_bytes() == before
    (tmp_path / "c.h5.partial").mkdir()  # the partial file's name taken by a folder
    with pytest.raises(ValueError, match=r"out must name a file, .*c.h5.partial' is a directory"):
        capture_sets(rig_path, tmp_path / "c.h5", sets=1)


def test_the_capture_rig_holds_the_exposure_the_device_applied(tmp_path, capsys):
    # camera 0 clamps the rig file's 180 µs to its longest exposure, 150 µs, and renders with it
    rf = _rigfile(configs=[{"exposure_range": [1e-5, 150e-6]}, {}, {}, {}])
    out = tmp_path / "c.h5"
    with pytest.warns(
        UserWarning,
        match=r"camera 0: the device applied an exposure of 0\.00015 s where the rig "
        r"file says t_e = 0\.00018 s; the capture's rig uses 0\.00015 s",
    ):
        capture_sets(rf, out, sets=2)
    capture = load_capture(out, set_index=0)
    assert [cam.t_e for cam in capture.rig.cameras] == [150e-6, T_E, T_E, T_E]
    assert capture.meta["cameras"][0]["exposure"] == 150e-6 and len(capture.meta["warnings"]) == 1
    # the snapshots are the stored rig's forward model of the scene: the rig reconstructs them
    np.testing.assert_allclose(capture.snapshots, reference.forward(capture.rig, capture.truth), rtol=1e-5, atol=1e-5)
    with h5py.File(out, "r") as h5:
        assert h5["raw/0"].attrs["exposure"] == 150e-6

    # a camera clamped to a shorter rig (T smaller than the rig file's): the scene's first T sub-frames are the truth
    short = tmp_path / "short.h5"
    rf = _rigfile(configs=[{"exposure_range": [1e-5, 100e-6]} for _ in range(4)])
    with pytest.warns(UserWarning, match="applied an exposure of 0.0001 s"):
        capture_sets(rf, short, sets=1)
    capture = load_capture(short)
    assert capture.rig.T < rf.rig().T and capture.truth.shape == (capture.rig.T,) + SHAPE
    np.testing.assert_allclose(capture.snapshots, reference.forward(capture.rig, capture.truth), rtol=1e-5, atol=1e-5)

    # rsocl capture prints the warning
    from rsocl.cli.main import main

    rig_path = tmp_path / "rig.toml"
    save_rigfile(rig_path, _rigfile(configs=[{}, {"exposure_range": [200e-6, 1e-3]}, {}, {}]))
    assert main(["capture", "--rig", str(rig_path), "--out", str(tmp_path / "cli.h5"), "--quiet"]) == 0
    assert (
        "rsocl capture: warning: camera 1: the device applied an exposure of 0.0002 s where the rig file says "
        "t_e = 0.00018 s"
    ) in capsys.readouterr().err


@pytest.mark.parametrize("value", [[1e-3], [2e-3, 1e-3], [0, 1e-3], "1e-3", [1e-3, float("inf")]])
def test_simulated_exposure_range_is_checked(value):
    with pytest.raises(ValueError, match=r"config\['exposure_range'\]"):
        SimulatedCamera({"shape": [4, 4], "t_e": T_E, "t_r": T_R, "exposure_range": value})


def test_a_rig_file_shape_beyond_the_host_memory_is_refused_before_the_rig_is_built(tmp_path, capsys, monkeypatch):
    from rsocl.cli.main import main
    from rsocl.common import memory

    monkeypatch.setattr(memory, "host_memory_bytes", lambda: 2**30)  # a 1 GiB machine
    rig_path = tmp_path / "rig.toml"
    rig_path.write_text(
        "[rig]\nshape = [100000, 100000]\n\n"
        '[[camera]]\nbackend = "simulated"\nt_e = 1.8e-4\nt_r = 3.5e-5\n\n'
        '[[camera]]\nbackend = "simulated"\nrow_map_file = "rows.npy"\nt_e = 1.8e-4\nt_r = 3.5e-5\n'
    )
    for argv in (
        ["capture", "--rig", str(rig_path), "--out", str(tmp_path / "c.h5")],
        ["calibrate", "--rig", str(rig_path), "--flat", str(tmp_path / "flat.png")],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "rig.toml: shape = [100000, 100000]: a rig of 2 camera(s) on 100000 x 100000 pixels" in err, err
        assert "at least 372.5 GiB of host memory, more than this machine's 1.0 GiB" in err
        assert len(err.strip().splitlines()) == 1
    assert [p.name for p in tmp_path.iterdir()] == ["rig.toml"]


@pytest.mark.parametrize(
    "extra, said",
    [
        (["--sets", "0"], "--sets must be an integer >= 1, got 0"),
        (["--timeout", "0"], "--timeout must be > 0 seconds, got 0.0"),
    ],
)
def test_capture_options_are_named_as_typed(tmp_path, capsys, extra, said):
    from rsocl.cli.main import main

    rig_path = tmp_path / "rig.toml"
    save_rigfile(rig_path, _rigfile())
    assert main(["capture", "--rig", str(rig_path), "--out", str(tmp_path / "c.h5"), *extra]) == 2
    assert capsys.readouterr().err == f"rsocl capture: error: {said}\n" and not (tmp_path / "c.h5").exists()
    assert main(["capture", "--rig", str(rig_path), "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err.startswith("rsocl capture: error: --out must name a file")


@pytest.mark.parametrize("mask, white", [("exact", T_E / T_R), ("binary", 6.0)])
def test_integer_frames_without_a_full_scale_map_the_sensors_top_to_a_white_scene(mask, white):
    # the paper's Eq. 4 (binary) counts the 6 sub-frame starts of a 5.14-sub-frame exposure
    from types import SimpleNamespace

    from rsocl.hardware.registration import register

    rig = Rig.paper_array(2, SHAPE, t_e=T_E, t_r=T_R, mask=mask)
    frame = SimpleNamespace(image=np.full(SHAPE, 4095, np.uint16), bit_depth=12, meta={"registered": True})
    assert register(RigFile.from_rig(rig), rig, 1, frame) == pytest.approx(np.full(SHAPE, white))


def test_a_rig_file_with_a_multi_frame_camera_is_refused_naming_the_file_and_camera(tmp_path):
    path = tmp_path / "rig.toml"
    save_rigfile(path, _rigfile(c1={"frames": 2, "t_d": 1e-3}))
    with pytest.raises(ValueError, match=r"rig\.toml: camera\[1\]\.frames = 2: rsocl capture reads one frame per "):
        capture_sets(path, tmp_path / "c.h5")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]


def test_a_pixel_format_the_backend_does_not_deliver_is_refused_before_any_camera_opens(tmp_path, monkeypatch):
    path = tmp_path / "rig.toml"
    save_rigfile(path, _rigfile(c2={"pixel_format": "Mono12"}))
    monkeypatch.setattr(SimulatedCamera, "_open_device", lambda self: pytest.fail("a camera opened"))
    with pytest.raises(ValueError, match=r"rig\.toml: camera\[2\]\.pixel_format must be one of \['Mono8', 'Mono16',"):
        capture_sets(path, tmp_path / "c.h5")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]


def test_a_disk_without_room_for_the_truth_and_the_sets_gets_the_sets_only(tmp_path, monkeypatch):
    import collections
    import shutil

    from rsocl.hardware import capture_room

    path = tmp_path / "rig.toml"
    save_rigfile(path, _rigfile())
    with_truth = capture_sets(path, tmp_path / "a.h5", sets=2)
    assert load_capture(with_truth, set_index=0).truth is not None
    usage = collections.namedtuple("usage", "total used free")
    free = capture_room.SLACK + 2**16  # room for each set (2 x 20 KiB at most), not for the truth (42 KiB) too
    monkeypatch.setattr(shutil, "disk_usage", lambda folder: usage(2**30, 2**30 - free, free))
    said = r"no ground truth stored: it takes 0\.0 MiB and the disk has 0\.1 MiB free beside"
    with pytest.warns(UserWarning, match=said):
        out = capture_sets(path, tmp_path / "b.h5", sets=2)
    capture = load_capture(out, set_index=1)
    assert capture.truth is None and load_raw(out).sets_complete == 2
    assert capture_room.shutil.disk_usage is shutil.disk_usage  # the module that reads the disk's room


def test_a_frame_whose_shape_changed_is_kept_beside_the_raw_frames(tmp_path, monkeypatch):
    import h5py

    from rsocl.hardware.capture import CaptureFailed
    from rsocl_plugins.simulated import SimulatedCamera

    real = SimulatedCamera._read

    def read(self, timeout):  # camera 1 delivers a frame 5 rows short in set 1
        frame = real(self, timeout)
        if self.index == 1 and frame.meta["set"] == 1:
            frame.image = frame.image[:-5]
        return frame

    monkeypatch.setattr(SimulatedCamera, "_read", read)
    path = tmp_path / "rig.toml"
    save_rigfile(path, _rigfile())
    with pytest.raises(CaptureFailed, match=r"frame changed from .* \(the frame is kept as raw_changed/1/1\)"):
        capture_sets(path, tmp_path / "c.h5", sets=3)
    with h5py.File(tmp_path / "c.h5") as h5:
        assert h5["raw_changed/1/1"].shape == (SHAPE[0] - 5, SHAPE[1]) and "meta" in h5["raw_changed/1/1"].attrs
    assert load_raw(tmp_path / "c.h5").sets_complete == 1
