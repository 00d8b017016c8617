"""rsocl calibrate is honest about its fit: four markers cannot check it, wrong pairings are refused."""

import numpy as np
import pytest

from rsocl.cli.main import main
from rsocl.hardware import calibration as cal
from rsocl.hardware.calibration.plausibility import (
    check_registration,
    check_rotation,
    fit_summary,
    leave_one_out_errors,
)

import test_calibration
from test_calibration import MARKERS, SHAPE, camera_homography

calibration_files = test_calibration.calibration_files  # the fixture, shared with test_calibration.py

ANGLES = (0, 90, 180, 270)
ORIGINS = [np.zeros(2), np.array([6.0, 4.0]), np.zeros(2), np.zeros(2)]  # camera 1 has a sensor ROI


def _given(folder, markers, per_camera=None, name="given.npz"):
    """A --frames file with the markers' sensor positions given (frame coordinates, in ``markers`` order)."""
    truth = [camera_homography(a) for a in ANGLES]
    given = [cal.project_points(H, markers) - o for H, o in zip(truth, ORIGINS)]
    for c, change in (per_camera or {}).items():
        given[c] = change(given[c])
    with np.load(folder / "markers.npz") as data:
        np.savez(folder / name, frames=data["frames"], markers=np.stack(given))
    return folder / name


def _run(folder, frames, markers, *extra):
    refs = ";".join(f"{x:g},{y:g}" for x, y in markers)
    return main(
        ["calibrate", "--rig", str(folder / "rig.toml"), "--frames", str(frames), "--markers-ref", refs, *extra]
    )


def _unchanged(folder, before):
    assert (folder / "rig.toml").read_bytes() == before
    assert not list(folder.glob("*calibration.png"))


def test_four_markers_say_they_cannot_check_the_fit(calibration_files, capsys):
    folder, *_ = calibration_files
    assert _run(folder, _given(folder, MARKERS), MARKERS) == 0
    out = capsys.readouterr().out
    assert "rms reprojection 0.000" not in out
    assert out.count("4 markers fit a homography exactly, so they cannot check it") == 4, out


def test_five_markers_report_a_leave_one_out_error(calibration_files, capsys):
    folder, *_ = calibration_files
    five = np.vstack([MARKERS, [[30.0, 25.0]]])
    noisy = {c: (lambda p, c=c: p + np.random.default_rng(c).normal(0, 0.2, p.shape)) for c in range(4)}
    assert _run(folder, _given(folder, five, noisy), five) == 0
    out = capsys.readouterr().out
    assert out.count("5 markers: rms reprojection") == 4 and "leave-one-out largest" in out, out


def test_swapped_markers_are_refused_naming_the_camera_and_the_markers(calibration_files, capsys):
    folder, *_ = calibration_files
    before = (folder / "rig.toml").read_bytes()
    frames = _given(folder, MARKERS, {1: lambda p: p[[0, 2, 1, 3]]})
    assert _run(folder, frames, MARKERS) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("rsocl calibrate: error: camera 1: markers 1 (55,9) and 2 (54,40) look swapped"), err
    _unchanged(folder, before)


def test_markers_shifted_a_turn_are_refused_naming_the_angle(calibration_files, capsys):
    folder, *_ = calibration_files
    before = (folder / "rig.toml").read_bytes()
    frames = _given(folder, MARKERS, {2: lambda p: p[[1, 2, 3, 0]]})  # a 90° turn: fits exactly
    assert _run(folder, frames, MARKERS) == 2
    err = capsys.readouterr().err
    assert "camera 2: the markers give a rotation of" in err and "camera[2].angle = 180" in err, err
    _unchanged(folder, before)


def test_a_mirrored_camera_needs_mirrored(calibration_files, capsys):
    folder, *_ = calibration_files
    before = (folder / "rig.toml").read_bytes()
    # camera 3 sees the target through a mirror: x -> -x about the reference centre before its homography
    flip = np.array([[-1.0, 0, SHAPE[1] - 1], [0, 1, 0], [0, 0, 1]])
    H3 = camera_homography(90) @ flip  # a mirror image turned 90°
    frames = _given(folder, MARKERS, {3: lambda p: cal.project_points(H3, MARKERS)})
    assert _run(folder, frames, MARKERS) == 2
    err = capsys.readouterr().err
    assert "camera 3: every triangle of the 4 markers turns the other way" in err and "--mirrored" in err, err
    _unchanged(folder, before)
    # its reference x axis runs along sensor -y: 270°, the rig file's angle
    assert _run(folder, frames, MARKERS, "--mirrored", "3", "--out", str(folder / "m.toml")) == 0, (
        capsys.readouterr().err
    )
    from rsocl.files.rigfile import load_rigfile

    assert cal.homography_difference(load_rigfile(folder / "m.toml").homography(3), H3, SHAPE) < 1e-6
    assert main(["calibrate", "--rig", str(folder / "rig.toml"), "--frames", str(frames), "--mirrored", "4"]) == 2
    assert "--mirrored must list camera indices in [0, 3], got [4]" in capsys.readouterr().err


def test_check_registration_refuses_extreme_distortion_and_accepts_cameras():
    ref = np.array([[0, 0], [10, 0], [10, 10], [0, 10.0]])
    for angle in ANGLES:  # real cameras, perspective included
        H = camera_homography(angle)
        check_registration(MARKERS, cal.project_points(H, MARKERS), H, SHAPE)
    squeezed = np.array([[0, 0], [10, 0], [5, 5.5], [0, 10.0]])  # convex, same turning sense, folded corner
    with pytest.raises(ValueError, match=r"magnifies one corner of the grid .*x as much as another \(at most 3"):
        check_registration(ref, squeezed, cal.estimate_homography(ref, squeezed), (11, 11))
    stretched = ref * [5.0, 1.0]
    with pytest.raises(ValueError, match=r"stretches the grid 5.0x more along one direction"):
        check_registration(ref, stretched, cal.estimate_homography(ref, stretched), (11, 11))
    with pytest.raises(ValueError, match=r"rotation of 90.0°, 90° from the rig file's angle = 0°"):
        check_rotation(cal.rotation_homography(90, (11, 11)), (11, 11), 0.0)


def test_leave_one_out_finds_the_misplaced_marker():
    five = np.vstack([MARKERS, [[30.0, 25.0]]])
    H = camera_homography(0)
    sensor = cal.project_points(H, five)
    assert leave_one_out_errors(MARKERS, sensor[:4]) is None
    assert leave_one_out_errors(five, sensor).max() < 1e-6
    sensor[4] += [3.0, 0.0]
    loo = leave_one_out_errors(five, sensor)
    assert loo[4] == pytest.approx(3.0, rel=1e-6) and loo.max() > 3.0  # it, and the fits that include it
    registration = cal.register_camera(None, five, sensor_points=sensor)
    assert registration.rms_error < 3.0 / 2  # the fit spreads the error: rms hides it
    assert f"leave-one-out largest {loo.max():.3f} px" in fit_summary(registration)


def test_a_centre_marker_among_four_corners_is_a_fit_with_markers_left_unchecked():
    # left out with a corner, the centre's others hold three on a diagonal: that marker cannot be checked,
    # and the calibration still fits (five markers determine the homography)
    corners = np.array([[2.0, 2.0], [13.0, 2.0], [13.0, 13.0], [2.0, 13.0]])
    five = np.vstack([corners, [[7.5, 7.5]]])
    sensor = cal.project_points(camera_homography(0), five)
    loo = leave_one_out_errors(five, sensor)
    assert np.isnan(loo[:4]).all() and loo[4] < 1e-6
    registration = cal.register_camera(None, five, sensor_points=sensor)
    summary = fit_summary(registration)
    assert "leave-one-out largest 0.000 px (markers [0, 1, 2, 3] not checked" in summary, summary
