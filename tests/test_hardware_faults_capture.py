"""Capture faults found by QA: simulated ROIs, disagreeing scenes, camera names, option names, scene paths,
singular homographies."""

import h5py
import numpy as np
import pytest

from rsocl.cli.main import main
from rsocl.files.hdf5 import load_capture
from rsocl.files.rigfile import load_rigfile
from rsocl.hardware.capture import CaptureFailed, capture_sets
from rsocl.hardware.capture_file import load_raw
from rsocl.model.operator import RollingShutterOperator

CAMERA = "t_e = 1.0e-04\nt_r = 2.0e-05\n"


def _rig(folder, body, shape=(24, 32), name="rig.toml"):
    path = folder / name
    path.write_text(f"[rig]\nshape = [{shape[0]}, {shape[1]}]\n" + body, encoding="utf-8")
    return path


def test_a_simulated_camera_with_a_homography_and_a_partial_roi_gives_the_model_inside_the_roi(tmp_path):
    # the homography of angle 90; the simulated sensor is the reference grid, the roi a window on it
    rig = _rig(
        tmp_path,
        '[[camera]]\nbackend = "simulated"\nhomography = [[0.0, -1.0, 31.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]\n'
        + CAMERA
        + "roi = [2, 2, 28, 20]\n",
    )
    cap = load_capture(capture_sets(rig, tmp_path / "c.h5"))
    model = RollingShutterOperator(cap.rig, dtype="float64").forward(cap.truth)[0]
    g = cap.snapshots[0]
    np.testing.assert_allclose(g[2:22, 2:30], model[2:22, 2:30], atol=1e-5)
    outside = np.ones(g.shape, bool)
    outside[2:22, 2:30] = False
    assert np.all(g[outside] == 0)
    assert load_raw(tmp_path / "c.h5").frames[0].shape == (1, 20, 28)  # the raw frame is the ROI as read


def test_simulated_cameras_that_see_different_scenes_store_no_truth(tmp_path):
    rig = _rig(
        tmp_path,
        f'[[camera]]\nbackend = "simulated"\nangle = 0.0\n{CAMERA}[camera.config]\nscene_seed = 3\n'
        f'[[camera]]\nbackend = "simulated"\nangle = 90.0\n{CAMERA}[camera.config]\nscene_seed = 4\n',
    )
    with pytest.warns(UserWarning, match=r"no ground truth: camera 1 .*sees another scene than camera 0") as info:
        capture_sets(rig, tmp_path / "c.h5")
    assert len(str(info[0].message).splitlines()) == 1
    assert load_capture(tmp_path / "c.h5").truth is None
    with h5py.File(tmp_path / "c.h5") as h5:
        assert "truth" not in h5


def test_the_camera_name_is_in_messages_and_in_the_capture_file(tmp_path):
    rig = _rig(
        tmp_path, f'[[camera]]\nbackend = "simulated"\nname = "north"\n{CAMERA}[camera.config]\nfail_after = 2\n'
    )
    with pytest.raises(CaptureFailed, match=r'^camera 0 "north" \(simulated\): read failed in set 1'):
        capture_sets(rig, tmp_path / "c.h5", sets=3)
    raw = load_raw(tmp_path / "c.h5")
    assert raw.meta["cameras"][0]["camera_name"] == "north"
    with h5py.File(tmp_path / "c.h5") as h5:
        assert h5["raw/0"].attrs["camera_name"] == "north"


def test_an_earlier_capture_or_partial_at_out_is_named_as_typed(tmp_path, capsys):
    rig = _rig(tmp_path, f'[[camera]]\nbackend = "simulated"\n{CAMERA}', shape=(16, 16))
    out = tmp_path / "cap.h5"
    assert main(["capture", "--rig", str(rig), "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["capture", "--rig", str(rig), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rsocl capture: error: --out {str(out)!r} holds 1 frame(s)"), err
    assert "another --out" in err and "another out" not in err
    (tmp_path / "cap2.h5.partial").write_bytes(out.read_bytes())
    assert main(["capture", "--rig", str(rig), "--out", str(tmp_path / "cap2.h5"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rsocl capture: error: --out: "), err


def test_a_simulated_scene_path_is_relative_to_the_rig_files_folder(tmp_path, monkeypatch):
    folder = tmp_path / "rigs"
    folder.mkdir()
    np.save(folder / "video.npy", np.random.default_rng(0).integers(0, 255, (8, 16, 16), dtype=np.uint8))
    np.save(folder / "rows.npy", np.tile(np.arange(16.0)[:, None], (1, 16)))
    body = f'[[camera]]\nbackend = "simulated"\nrow_map_file = "rows.npy"\n{CAMERA}[camera.config]\nscene = "%s"\n'
    rig = _rig(folder, body % "video.npy", shape=(16, 16), name="sim.toml")
    monkeypatch.chdir(tmp_path)
    assert load_capture(capture_sets("rigs/sim.toml", "cap.h5")).truth is not None
    # a scene that is not there: refused before anything is written, naming the key
    _rig(folder, body % "missing.npy", shape=(16, 16), name="bad.toml")
    with pytest.raises(ValueError, match=r"config\['scene'\].*missing\.npy.*does not exist"):
        capture_sets("rigs/bad.toml", "bad.h5")
    assert not (tmp_path / "bad.h5").exists() and not (tmp_path / "bad.h5.partial").exists()
    assert rig.exists()


def test_a_singular_homography_is_refused_by_the_rig_file_check(tmp_path):
    rig = _rig(
        tmp_path,
        '[[camera]]\nbackend = "simulated"\nhomography = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]\n'
        + CAMERA,
        shape=(8, 8),
    )
    with pytest.raises(ValueError, match=r"camera\[0\]\.homography is singular"):
        load_rigfile(rig)
