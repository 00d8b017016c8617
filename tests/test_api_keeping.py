"""The Python API's saves lose nothing, as the commands do: a capture from cameras is never replaced, a
reconstruction never replaces a capture, and an earlier file is kept under a second name."""

import hashlib
import shutil

import numpy as np
import pytest

import rsocl
from rsocl.files.rigfile import RigFile, save_rigfile
from rsocl.hardware.capture import capture_sets

SHAPE = (8, 8)


def _md5(path):
    return hashlib.md5(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def camera_capture(tmp_path_factory):
    """A capture of 2 sets from (simulated) cameras, made once; tests copy it."""
    folder = tmp_path_factory.mktemp("cameras")
    save_rigfile(folder / "rig.toml", RigFile.from_rig(rsocl.Rig.paper_array(4, SHAPE, t_e=180e-6, t_r=35e-6)))
    return capture_sets(folder / "rig.toml", folder / "cam.h5", sets=2)


def _cube(rig):
    return np.zeros((rig.T,) + rig.shape, np.float32)


def test_neither_save_replaces_a_capture_from_cameras(camera_capture, tmp_path):
    path = shutil.copy(camera_capture, tmp_path / "cam.h5")
    before = _md5(path)
    rig = rsocl.load_capture(path, set_index=0).rig
    with pytest.raises(ValueError, match=r"^path '.*cam\.h5' holds \d+ frame\(s\) from cameras .* never replaced"):
        rsocl.save_reconstruction(path, _cube(rig), rig)
    with pytest.raises(ValueError, match=r"^path '.*cam\.h5' holds \d+ frame\(s\) from cameras"):
        rsocl.save_capture(path, np.zeros((rig.n_channels,) + rig.shape), rig)
    assert _md5(path) == before and sorted(p.name for p in tmp_path.iterdir()) == ["cam.h5"]


def test_a_reconstruction_never_replaces_a_simulated_capture(tmp_path):
    rig = rsocl.Rig.paper_array(2, SHAPE, t_e=180e-6, t_r=35e-6)
    path = rsocl.save_capture(tmp_path / "sim.h5", np.ones((rig.n_channels,) + rig.shape), rig)
    before = _md5(path)
    with pytest.raises(ValueError, match=r"^path '.*sim\.h5' is an rsocl capture file; a reconstruction never"):
        rsocl.save_reconstruction(path, _cube(rig), rig)
    assert _md5(path) == before


def test_a_second_save_to_one_path_keeps_the_earlier_file(tmp_path):
    rig = rsocl.Rig.paper_array(2, SHAPE, t_e=180e-6, t_r=35e-6)
    rec = tmp_path / "rec.h5"
    rsocl.save_reconstruction(rec, _cube(rig), rig, params={"run": 1})
    rsocl.save_reconstruction(rec, _cube(rig) + 1, rig, params={"run": 2})
    [earlier] = tmp_path.glob("rec.earlier-*.h5")
    assert rsocl.load_reconstruction(earlier).params == {"run": 1} and rsocl.load_reconstruction(rec).params == {
        "run": 2
    }
    cap = tmp_path / "cap.h5"  # a simulated capture is replaced (the scene gives it again); another file is kept
    rsocl.save_capture(cap, np.zeros((rig.n_channels,) + rig.shape), rig)
    rsocl.save_capture(cap, np.ones((rig.n_channels,) + rig.shape), rig)
    assert not list(tmp_path.glob("cap.earlier-*")) and rsocl.load_capture(cap).snapshots.max() == 1
    rsocl.save_capture(rec, np.ones((rig.n_channels,) + rig.shape), rig)
    assert len(list(tmp_path.glob("rec.earlier-*.h5"))) == 2  # the second reconstruction, kept too
