"""rsocl capture refuses settings a camera cannot take before it makes the capture file, naming the rig file's
key and what it may be: a pixel format the sensor cannot fill, a roi beyond the sensor, an Aravis interface
this Aravis does not have. (A roi beyond an Aravis or V4L2 sensor, known once the camera is open: in
tests/test_aravis.py and tests/test_v4l2.py.)"""

from __future__ import annotations

import pytest

from rsocl.cli.main import main
from rsocl.files.rigfile import RigFile, save_rigfile
from rsocl.hardware.capture import capture_sets
from rsocl.model.rig import Rig
from rsocl_plugins.simulated import SimulatedCamera

SHAPE = (16, 16)


def _rig_file(path, configs=None, **camera_extra):
    rf = RigFile.from_rig(Rig.paper_array(2, SHAPE, t_e=180e-6, t_r=35e-6), configs=configs)
    for i, extra in camera_extra.items():
        rf.cameras[int(i[1:])].update(extra)
    save_rigfile(path, RigFile(shape=rf.shape, cameras=rf.cameras, dt=rf.dt, mask=rf.mask))
    return path


@pytest.fixture
def no_camera_opens(monkeypatch):
    monkeypatch.setattr(SimulatedCamera, "_open_device", lambda self: pytest.fail(f"{self.name} opened"))


def test_mono8_on_a_12_bit_simulated_sensor_is_refused_before_any_camera_opens(tmp_path, no_camera_opens):
    rig = _rig_file(tmp_path / "rig.toml", configs=[{}, {"sensor": {"bit_depth": 12}}], c1={"pixel_format": "Mono8"})
    with pytest.raises(
        ValueError, match=r"rig\.toml: camera\[1\]\.pixel_format must be one of \['Mono16', 'Float32'\], got 'Mono8'$"
    ):
        capture_sets(rig, tmp_path / "c.h5")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]
    assert SimulatedCamera({"t_e": 1e-3, "t_r": 1e-4, "shape": [4, 4]}).pixel_formats == ("Mono8", "Mono16", "Float32")


def test_a_roi_beyond_a_simulated_sensor_is_refused_before_any_camera_opens(tmp_path, no_camera_opens, capsys):
    rig = _rig_file(tmp_path / "rig.toml", c0={"roi": [8, 0, 16, 16]})
    assert main(["capture", "--rig", str(rig), "--out", str(tmp_path / "c.h5")]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"rsocl capture: error: {rig}: camera[0].roi = [8, 0, 16, 16] ([x, y, width, height]) must lie on the "
        "16x16 (width x height) sensor of camera 0 (simulated): x + width <= 16 and y + height <= 16\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]


def test_an_aravis_interface_this_aravis_lacks_is_refused_before_any_camera_opens(tmp_path, monkeypatch):
    pytest.importorskip("gi")
    from rsocl_plugins.aravis import AravisCamera
    from rsocl_plugins.aravis_discovery import aravis_interfaces

    known = aravis_interfaces()
    if known is None:
        pytest.skip("Aravis 0.8 does not import through PyGObject here")
    monkeypatch.setattr(AravisCamera, "_open_device", lambda self: pytest.fail(f"{self.name} opened"))
    rig = tmp_path / "rig.toml"
    rig.write_text(
        '[rig]\nshape = [16, 16]\n\n[[camera]]\nbackend = "aravis"\nangle = 0.0\nt_e = 2e-3\nt_r = 4e-5\n\n'
        '[camera.config]\ninterfaces = ["GigEVision", "Bogus"]\n'
    )
    with pytest.raises(ValueError) as info:
        capture_sets(rig, tmp_path / "c.h5")
    assert str(info.value) == (
        f"camera 0 (aravis): config['interfaces'] must list interfaces this Aravis has, any of {known}; "
        "got ['GigEVision', 'Bogus'] (no 'Bogus')"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]
    assert AravisCamera({"interfaces": known[:1]}).interfaces == known[:1]
