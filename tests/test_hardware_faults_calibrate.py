"""Calibration faults found by QA: mirrored cameras, flat fields of mixed bit depths, options named as typed,
all the dots of a target."""

import h5py
import numpy as np
import pytest

from rsocl.cli.main import main
from rsocl.files.rigfile import load_rigfile
from rsocl.hardware import calibration as cal
from rsocl.hardware.capture import capture_sets

SHAPE, SENSOR = (48, 64), (80, 96)
REF5 = np.array([[10, 8], [54, 7], [55, 40], [9, 41], [30, 16]], float)
REF6 = np.array([[10, 8], [54, 7], [55, 40], [9, 41], [30, 16], [22, 33]], float)
TWO = '[[camera]]\nbackend = "simulated"\n%s\nt_e = 1.0e-04\nt_r = 2.0e-05\n'


def _dots(shape, points, rng=None):
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    image = 0.1 + sum(np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / 4.0) for x, y in points)
    return image + (0.0 if rng is None else 0.03 * rng.standard_normal(shape))


def _write_rig(folder, geometry0, geometry1):
    text = f"[rig]\nshape = [{SHAPE[0]}, {SHAPE[1]}]\n" + TWO % geometry0 + TWO % geometry1
    (folder / "rig.toml").write_text(text, encoding="utf-8")
    return folder / "rig.toml"


def _calibrate(folder, *extra):
    return main(["calibrate", "--rig", str(folder / "rig.toml"), *[str(e) for e in extra]])


@pytest.fixture
def mirrored(tmp_path):
    """Camera 1 sees the 5-marker target in a mirror (x -> -x after a 2° turn)."""
    H = np.array([[-1, 0, SENSOR[1] - 1], [0, 1, 0], [0, 0, 1.0]]) @ cal.rotation_homography(
        2.0, SHAPE, sensor_shape=SENSOR
    )
    np.savez(tmp_path / "markers.npz", camera0=_dots(SHAPE, REF5), camera1=_dots(SENSOR, cal.project_points(H, REF5)))
    refs = ["--markers-ref"] + [f"{x:g},{y:g}" for x, y in REF5]
    return tmp_path, H, ["--frames", tmp_path / "markers.npz", *refs]


def test_a_mirrored_camera_without_mirrored_is_refused_naming_mirrored(mirrored, capsys):
    folder, H, frames = mirrored
    rig = _write_rig(folder, "angle = 0.0", "angle = 0.0")
    before = rig.read_bytes()
    assert _calibrate(folder, *frames) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("rsocl calibrate: error: camera 1: the markers fit a homography with rms reprojection")
    assert "more than 1 px" in err[0] and "give --mirrored 1" in err[0], err
    assert rig.read_bytes() == before and not list(folder.glob("*.png"))
    # --force writes the measured homography anyway, saying so
    assert _calibrate(folder, *frames, "--force", "--out", folder / "forced.toml") == 0
    assert "written as --force asks" in capsys.readouterr().out
    assert (folder / "forced.toml").exists()


def test_a_mirrored_camera_with_its_angle_and_mirrored_calibrates_by_position(mirrored, capsys):
    folder, H, frames = mirrored
    angle = cal.homography_angle(H, SHAPE)
    _write_rig(folder, "angle = 0.0", "angle = 0.0")  # a mirrored camera's angle starts its order: wrong here
    assert _calibrate(folder, *frames, "--mirrored", "1") == 2
    err = capsys.readouterr().err
    assert "they fit in an order that starts at another marker" in err and "camera[1].angle = 178" in err, err
    _write_rig(folder, "angle = 0.0", f"angle = {angle:.1f}")
    assert _calibrate(folder, *frames, "--mirrored", "1") == 0, capsys.readouterr().err
    assert cal.homography_difference(load_rigfile(folder / "rig.toml").homography(1), H, SHAPE) < 0.1


def test_four_corners_and_a_centre_still_calibrate(tmp_path, capsys):
    five = np.array([[8.0, 7.0], [55.0, 7.0], [55.0, 40.0], [8.0, 40.0], [31.5, 23.5]])
    H = cal.rotation_homography(90, SHAPE, sensor_shape=SENSOR, scale=1.1)
    rng = np.random.default_rng(1)
    markers = np.stack([five, cal.project_points(H, five) + rng.normal(0, 0.1, (5, 2))])
    np.savez(tmp_path / "m.npz", camera0=np.zeros(SHAPE), camera1=np.zeros(SENSOR), markers=markers)
    _write_rig(tmp_path, "angle = 0.0", "angle = 90.0")
    refs = ";".join(f"{x:g},{y:g}" for x, y in markers[0])
    assert _calibrate(tmp_path, "--frames", tmp_path / "m.npz", "--markers-ref", refs) == 0, capsys.readouterr().err
    assert "not checked" in capsys.readouterr().out


def test_all_the_dots_of_camera_0_are_the_markers_without_markers_ref(tmp_path, capsys):
    H1 = cal.rotation_homography(3.0, SHAPE, sensor_shape=SENSOR, scale=0.95)
    rng = np.random.default_rng(2)
    np.savez(
        tmp_path / "markers.npz",
        camera0=_dots(SHAPE, REF6, rng),
        camera1=_dots(SENSOR, cal.project_points(H1, REF6), rng),
    )
    _write_rig(tmp_path, "", "")
    assert _calibrate(tmp_path, "--frames", tmp_path / "markers.npz") == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "reference markers (camera 0, 6 dots):" in out and "6 markers: rms reprojection" in out, out
    assert cal.homography_difference(load_rigfile(tmp_path / "rig.toml").homography(1), H1, SHAPE) < 0.5


@pytest.fixture
def flat_capture(tmp_path):
    """A capture of a flat scene by two identical simulated cameras of 8 and 12 bits."""
    np.save(tmp_path / "flat_scene.npy", np.full((4, 16, 16), 128, np.uint8))
    scene = (tmp_path / "flat_scene.npy").as_posix()
    cameras = ""
    for bits in (8, 12):
        cameras += TWO % "" + f'[camera.config]\nscene = "{scene}"\n[camera.config.sensor]\nbit_depth = {bits}\n'
    (tmp_path / "rig.toml").write_text("[rig]\nshape = [16, 16]\n" + cameras, encoding="utf-8")
    capture_sets(tmp_path / "rig.toml", tmp_path / "flat.h5")
    return tmp_path


def test_flat_fields_of_a_capture_file_are_normalised_by_each_cameras_bit_depth(flat_capture, capsys):
    folder = flat_capture
    assert _calibrate(folder, "--flat", folder / "flat.h5") == 0, capsys.readouterr().err
    assert load_rigfile(folder / "rig.toml").cameras[1]["gain"] == pytest.approx(1.0, rel=2e-3)


@pytest.mark.parametrize("name", ["flat.hdf", "flat.he5", "flat-capture"])
def test_a_flat_capture_file_is_recognised_by_any_hdf5_suffix_or_its_signature(flat_capture, capsys, name):
    folder = flat_capture
    (folder / "flat.h5").rename(folder / name)
    assert _calibrate(folder, "--flat", folder / name) == 0, capsys.readouterr().err
    assert load_rigfile(folder / "rig.toml").cameras[1]["gain"] == pytest.approx(1.0, rel=2e-3)


def test_a_flat_capture_with_no_complete_set_is_refused_and_the_rig_file_kept(flat_capture, capsys):
    folder = flat_capture
    with h5py.File(folder / "flat.h5", "r+") as h5:  # a capture that failed in its first set
        h5.attrs["sets_complete"] = 0
        h5.attrs["capture_status"] = "failed"
    before = (folder / "rig.toml").read_bytes()
    assert _calibrate(folder, "--flat", folder / "flat.h5") == 2
    err = capsys.readouterr().err
    assert "holds no complete set (capture status 'failed')" in err and len(err.strip().splitlines()) == 1, err
    assert (folder / "rig.toml").read_bytes() == before


def test_raw_flat_fields_of_cameras_of_different_bit_depths_are_refused(flat_capture, capsys):
    folder = flat_capture
    with h5py.File(folder / "flat.h5") as h5:
        np.savez(folder / "flat.npz", camera0=h5["raw/0"][0], camera1=h5["raw/1"][0])
    before = (folder / "rig.toml").read_bytes()
    assert _calibrate(folder, "--flat", folder / "flat.npz") == 2
    err = capsys.readouterr().err
    assert "--flat: the cameras deliver different bit depths (camera 0: 8, camera 1: 12)" in err, err
    assert len(err.strip().splitlines()) == 1 and (folder / "rig.toml").read_bytes() == before


@pytest.mark.parametrize(
    "extra, said",
    [
        (["--flicker", "f.npy", "--flicker-hz", "0"], "--flicker-hz must be > 0 Hz, got 0.0"),
        (["--flicker", "f.npy", "--flicker-hz", "2500", "--tolerance", "-1"], "--tolerance must be >= 0, got -1.0"),
        (["--flat", "f.npy", "--dark", "nan"], "--dark must be finite, got nan"),
        (
            ["--frames", "f.npy", "--flicker", "f.npy"],
            "--flicker needs --flicker-hz (the light's intensity frequency, Hz)",
        ),
    ],
)
def test_calibrate_options_are_checked_as_typed_before_any_frame_is_read(tmp_path, capsys, extra, said):
    (tmp_path / "rig.toml").write_text(
        "[rig]\nshape = [16, 16]\n" + TWO % "", encoding="utf-8"
    )  # f.npy is not there: the option is checked first
    assert (
        main(
            [
                "calibrate",
                "--rig",
                str(tmp_path / "rig.toml"),
                *[str(tmp_path / e) if e == "f.npy" else e for e in extra],
            ]
        )
        == 2
    )
    assert capsys.readouterr().err == f"rsocl calibrate: error: {said}\n"


def test_the_threshold_hint_names_the_option():
    with pytest.raises(ValueError, match=r"--threshold"):
        cal.detect_markers(np.zeros((16, 16)) + np.eye(16), 4)


def test_flat_fields_of_binary_mask_cameras_of_other_exposures_give_their_gains(tmp_path, capsys):
    # the binary mask's white level is the sub-frame starts an exposure holds (6 and 4 here), not t_e / dt
    np.save(tmp_path / "flat_scene.npy", np.full((12, 16, 16), 128, np.uint8))
    scene = (tmp_path / "flat_scene.npy").as_posix()
    cameras = ""
    for t_e in ("1.1e-04", "0.7e-04"):
        cameras += (
            f'[[camera]]\nbackend = "simulated"\nt_e = {t_e}\nt_r = 2.0e-05\n[camera.config]\nscene = "{scene}"\n'
        )
    rig = '[rig]\nshape = [16, 16]\nmask = "binary"\n'
    (tmp_path / "rig.toml").write_text(rig + cameras, encoding="utf-8")
    capture_sets(tmp_path / "rig.toml", tmp_path / "flat.h5")
    assert _calibrate(tmp_path, "--flat", tmp_path / "flat.h5") == 0, capsys.readouterr().err
    assert load_rigfile(tmp_path / "rig.toml").cameras[1]["gain"] == pytest.approx(1.0, rel=1e-6)


def test_an_overlay_in_the_frames_folder_is_refused_before_any_work(tmp_path, capsys):
    # a picture there would replace a frame, or be read as one by the next run
    shots = tmp_path / "shots"
    shots.mkdir()
    for c, shape in enumerate((SHAPE, SENSOR)):
        np.save(shots / f"cam{c}.npy", _dots(shape, REF5))
    _write_rig(tmp_path, "angle = 0.0", "angle = 0.0")
    before = {p.name: p.read_bytes() for p in shots.iterdir()}
    refs = ["--markers-ref", ";".join(f"{x:g},{y:g}" for x, y in REF5)]
    for png in (["--png", shots / "cam0.png"], ["--png", shots / "overlay.png"]):
        assert _calibrate(tmp_path, "--frames", shots, *refs, *png) == 2
        err = capsys.readouterr().err
        assert f"--png {str(png[1])!r} lies in the --frames folder {str(shots)!r}" in err, err
    assert {p.name: p.read_bytes() for p in shots.iterdir()} == before


def test_an_interrupt_says_what_calibrate_wrote_and_kept(mirrored, capsys, monkeypatch):
    import rsocl.files.rigfile as rigfile

    folder, H, frames = mirrored
    angle = cal.homography_angle(H, SHAPE)
    rig = _write_rig(folder, "angle = 0.0", f"angle = {angle:.1f}")
    before = rig.read_bytes()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(rigfile, "save_rigfile", interrupted)  # after the overlay, before the rig file
    assert _calibrate(folder, *frames, "--mirrored", "1") == 130
    png = folder / "rig-calibration.png"
    said = f"rsocl calibrate: interrupted: {png} written, {rig} unchanged\n"
    assert capsys.readouterr().err == said and png.is_file() and rig.read_bytes() == before
    monkeypatch.setattr(cal, "register_camera", interrupted)  # while measuring
    assert _calibrate(folder, *frames, "--mirrored", "1") == 130
    assert capsys.readouterr().err == f"rsocl calibrate: interrupted: nothing written, {rig} unchanged\n"


def test_a_simulated_capture_as_flat_field_says_it_holds_no_raw_frames(tmp_path, capsys):
    (tmp_path / "rig.toml").write_text("[rig]\nshape = [16, 16]\n" + TWO % "" + TWO % "", encoding="utf-8")
    assert main(["simulate", "builtin", "--out", str(tmp_path / "sim.h5"), "--shape", "16", "16", "--quiet"]) == 0
    before = (tmp_path / "rig.toml").read_bytes()
    capsys.readouterr()
    assert _calibrate(tmp_path, "--flat", tmp_path / "sim.h5") == 2
    err = capsys.readouterr().err
    assert f"--flat: {tmp_path / 'sim.h5'} holds no raw frames (a capture from rsocl simulate" in err, err
    assert len(err.strip().splitlines()) == 1 and (tmp_path / "rig.toml").read_bytes() == before
