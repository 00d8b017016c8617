"""Calibration: markers and homographies, row maps, warping, row time, flat-field gain, overlay PNG.

Synthetic frames are rendered through known homographies: every sensor pixel
is mapped back to the reference grid and the target (Gaussian dots) is
evaluated there, so the true marker images and the true homography are known.
"""

import numpy as np
import pytest

from rsocl import Camera
from rsocl.hardware import calibration as cal

SHAPE = (48, 64)  # reference ROI (m, n)
SENSOR = (100, 110)  # camera frames (rows, columns)
MARKERS = np.array([[8.0, 7.0], [55.0, 9.0], [54.0, 40.0], [9.0, 41.0]])  # (x, y), clockwise from top-left
SIGMAS = (3.0, 2.0, 2.0, 2.0)  # marker 0 is the large one


def render(H, markers=MARKERS, sigmas=SIGMAS, *, sensor=SENSOR, rng=None, noise=0.02, background=0.1, amplitude=0.8):
    """Frame of a target with Gaussian dots (sigma in reference pixels) seen through H (reference -> sensor)."""
    rows, cols = sensor
    y, x = np.mgrid[0:rows, 0:cols]
    reference = cal.project_points(np.linalg.inv(H), np.column_stack([x.ravel(), y.ravel()]))
    frame = np.full(rows * cols, background)
    for (mx, my), sigma in zip(markers, sigmas):
        frame += amplitude * np.exp(-((reference[:, 0] - mx) ** 2 + (reference[:, 1] - my) ** 2) / (2 * sigma**2))
    frame = frame.reshape(rows, cols)
    if rng is not None:
        frame = frame + noise * rng.standard_normal(frame.shape)
    return frame


def camera_homography(angle, perspective=(1.5e-3, -1.0e-3), scale=1.3, shift=(3.0, -2.0)):
    """A camera rotated by ``angle`` (docs/model.md convention), scaled, shifted, with a small perspective."""
    H = cal.rotation_homography(angle, SHAPE, sensor_shape=SENSOR, scale=scale, shift=shift)
    cx, cy = (SENSOR[1] - 1) / 2, (SENSOR[0] - 1) / 2
    centre = np.array([[1, 0, -cx], [0, 1, -cy], [0, 0, 1.0]])
    tilt = np.array([[1, 0, 0], [0, 1, 0], [perspective[0], perspective[1], 1.0]])
    H = np.linalg.inv(centre) @ tilt @ centre @ H
    return H / H[2, 2]


# ---------------------------------------------------------------------- markers and homography
@pytest.mark.parametrize("angle", [0, 90, 180, 270])
@pytest.mark.parametrize("reference", ["largest", None])
def test_detected_markers_recover_known_homography(angle, reference, rng):
    H_true = camera_homography(angle)
    frame = render(H_true, rng=rng)
    registration = cal.register_camera(frame, MARKERS, reference=reference, angle=angle)
    # The markers are matched to the right physical markers...
    np.testing.assert_allclose(registration.reference_points, MARKERS)
    np.testing.assert_allclose(registration.sensor_points, cal.project_points(H_true, MARKERS), atol=0.15)
    # ...and the homography maps every reference pixel within 0.5 px of the truth.
    assert cal.homography_difference(registration.homography, H_true, SHAPE) < 0.5
    assert registration.rms_error < 1e-6  # four markers: exact fit
    assert registration.homography[2, 2] == pytest.approx(1.0)


def test_largest_marker_identifies_order_whatever_the_rotation(rng):
    frame = render(camera_homography(90), rng=rng)
    # Without the rotation hint the geometric order starts at another marker: a wrong match.
    geometric = cal.detect_markers(frame)
    identified, areas = cal.detect_markers(frame, reference="largest", return_areas=True)
    assert areas[0] > 1.5 * areas[1:].max()
    truth = cal.project_points(camera_homography(90), MARKERS)
    np.testing.assert_allclose(identified, truth, atol=0.15)
    assert np.abs(geometric - truth).max() > 10
    np.testing.assert_allclose(cal.detect_markers(frame, angle=90), truth, atol=0.15)


def test_more_markers_are_fitted_in_the_least_squares_sense(rng):
    markers = np.vstack([MARKERS, [[32.0, 24.0], [30.0, 8.0]]])
    H_true = camera_homography(180)
    frame = render(H_true, markers, SIGMAS + (2.0, 2.0), rng=rng)
    sensor = cal.detect_markers(frame, n=6, reference="largest")
    # Order the reference the same way: the large marker first, then clockwise.
    reference = cal.order_markers(markers, first=0)
    H = cal.estimate_homography(reference, sensor)
    assert cal.homography_difference(H, H_true, SHAPE) < 0.5
    errors = cal.reprojection_error(H, reference, sensor)
    assert errors.shape == (6,) and 0 < errors.max() < 0.3


def test_dark_markers_and_explicit_threshold(rng):
    H_true = camera_homography(0)
    frame = 1.0 - render(H_true, rng=rng)
    truth = cal.project_points(H_true, MARKERS)
    np.testing.assert_allclose(cal.detect_markers(frame, polarity="dark"), truth, atol=0.15)
    np.testing.assert_allclose(cal.detect_markers(frame, polarity="dark", threshold=0.6), truth, atol=0.15)
    with pytest.raises(ValueError, match="found 0 marker blob"):
        cal.detect_markers(frame)  # bright dots asked, none there


def test_given_sensor_points_skip_detection():
    H_true = camera_homography(270)
    registration = cal.register_camera(None, MARKERS, sensor_points=cal.project_points(H_true, MARKERS))
    np.testing.assert_allclose(registration.homography, H_true, atol=1e-9)
    with pytest.raises(ValueError, match="frame or sensor_points"):
        cal.register_camera(None, MARKERS)


def test_marker_errors_are_explained(rng):
    equal = render(camera_homography(0), sigmas=(2.0,) * 4, rng=rng)
    with pytest.raises(ValueError, match="cannot tell which"):
        cal.detect_markers(equal, reference="largest")
    with pytest.raises(ValueError, match="need 5"):
        cal.detect_markers(equal, n=5)
    edge = render(np.array([[1, 0, -8.0], [0, 1, 0], [0, 0, 1]]), rng=rng)  # marker 0 cut by the left edge
    with pytest.raises(ValueError, match="touches the frame edge"):
        cal.detect_markers(edge)
    with pytest.raises(ValueError, match="collinear"):
        cal.estimate_homography([[0, 0], [1, 1], [2, 2], [0, 5]], MARKERS)
    with pytest.raises(ValueError, match="same markers"):
        cal.estimate_homography(np.vstack([MARKERS, [[30.0, 20.0]]]), MARKERS)


def test_order_markers_is_clockwise_from_top_left():
    shuffled = MARKERS[[2, 0, 3, 1]]
    np.testing.assert_array_equal(cal.order_markers(shuffled), MARKERS)
    np.testing.assert_array_equal(cal.order_markers(shuffled, first=0), MARKERS[[2, 3, 0, 1]])
    np.testing.assert_array_equal(cal.order_markers(shuffled, first=0, mirrored=True), MARKERS[[2, 1, 0, 3]])


# ---------------------------------------------------------------------- row maps
def test_row_map_of_identity_is_angle_0():
    rows = cal.row_map_from_homography(np.eye(3), SHAPE)
    np.testing.assert_array_equal(rows, Camera(0, t_e=1e-4, t_r=1e-5).rows(SHAPE))


def test_row_map_of_quarter_turn_is_angle_90():
    m, n = SHAPE
    # A camera turned by 90°: sensor X = m-1-y, Y = x (it reads the reference left to right).
    H = np.array([[0.0, -1.0, m - 1], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(
        cal.row_map_from_homography(H, SHAPE), Camera(90, t_e=1e-4, t_r=1e-5).rows(SHAPE), atol=1e-12
    )


@pytest.mark.parametrize("angle", [0, 90, 180, 270, 45, 135, 225, 315, 30])
def test_row_map_of_rotation_is_the_angles_plus_the_sensor_row_of_the_roi(angle):
    """docs/model.md: r is the sensor row of the mapped point, so the ROI's first row read is read
    that many rows after the trigger: the angle's row map (first row 0) plus that row."""
    H = cal.rotation_homography(angle, SHAPE, sensor_shape=SENSOR, shift=(2.0, 5.0))
    rows = cal.row_map_from_homography(H, SHAPE)
    y, x = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    first = cal.project_points(H, np.column_stack([x.ravel(), y.ravel()]))[:, 1].min()
    assert 5 < first < SENSOR[0] / 2
    np.testing.assert_allclose(rows, Camera(angle, t_e=1e-4, t_r=1e-5).rows(SHAPE) + first, atol=1e-9)
    # a sensor roi whose top row is that row: the camera reads it first
    np.testing.assert_allclose(
        cal.row_map_from_homography(H, SHAPE, first_row=first), Camera(angle, t_e=1e-4, t_r=1e-5).rows(SHAPE), atol=1e-9
    )


def test_row_map_with_perspective_is_the_sensor_row():
    H = camera_homography(90)
    rows = cal.row_map_from_homography(H, SHAPE)
    y, x = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    mapped = cal.project_points(H, np.column_stack([x.ravel(), y.ravel()]))[:, 1].reshape(SHAPE)
    np.testing.assert_allclose(rows, mapped, atol=1e-9)
    assert rows.min() > 0
    camera = Camera(t_e=2e-4, t_r=26e-6, row_map=rows)  # accepted as a calibrated camera
    np.testing.assert_array_equal(camera.rows(SHAPE), rows)
    horizon = np.array([[1, 0, 0], [0, 1, 0], [-1 / 30, 0, 1.0]])  # w = 0 at x = 30, inside the ROI
    with pytest.raises(ValueError, match="infinity"):
        cal.row_map_from_homography(horizon, SHAPE)


# ---------------------------------------------------------------------- warping
def test_warp_to_reference_undoes_the_camera():
    H = camera_homography(270)
    y, x = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]

    def pattern(x, y):
        return np.sin(x / 7.0) * np.cos(y / 5.0) + 0.01 * x

    rows, cols = SENSOR
    sy, sx = np.mgrid[0:rows, 0:cols]
    ref = cal.project_points(np.linalg.inv(H), np.column_stack([sx.ravel(), sy.ravel()]))
    frame = pattern(ref[:, 0], ref[:, 1]).reshape(SENSOR)
    warped = cal.warp_to_reference(frame, H, SHAPE)
    assert warped.shape == SHAPE and warped.dtype == np.float64
    np.testing.assert_allclose(warped, pattern(x, y), atol=0.02)
    stack = cal.warp_to_reference(np.stack([frame, 2 * frame]), H, SHAPE)
    assert stack.shape == (2,) + SHAPE
    np.testing.assert_allclose(stack[1], 2 * warped)
    shift = np.array([[1, 0, 5.0], [0, 1, 3.0], [0, 0, 1]])  # integer shift: exact crop
    np.testing.assert_allclose(
        cal.warp_to_reference(frame, shift, SHAPE), frame[3 : 3 + SHAPE[0], 5 : 5 + SHAPE[1]], atol=1e-12
    )


# ---------------------------------------------------------------------- row time
T_R = 26e-6
FLICKER_HZ = 1040.0  # band period 1 / (1040 * 26 µs) = 36.98 rows


def flicker_frame(rng, t_r=T_R, hz=FLICKER_HZ, rows=300, cols=64, noise=0.05, phase=0.7):
    r = np.arange(rows, dtype=np.float64)[:, None]
    vignetting = 1.0 - 0.2 * ((np.arange(cols) - cols / 2) / cols) ** 2
    frame = (0.5 + 0.4 * np.sin(2 * np.pi * hz * r * t_r + phase)) * vignetting
    return frame + noise * rng.standard_normal((rows, cols))


def test_row_time_from_flicker_within_one_percent(rng):
    period = 1 / (FLICKER_HZ * T_R)
    assert 30 < period < 45
    frame = flicker_frame(rng)
    estimated = cal.estimate_row_time(frame, FLICKER_HZ)
    assert estimated == pytest.approx(T_R, rel=0.01)
    assert cal.estimate_row_time(frame.T, FLICKER_HZ, axis=1) == pytest.approx(estimated, rel=1e-12)
    assert cal.band_period(frame.mean(axis=1)) == pytest.approx(period, rel=0.01)
    assert cal.check_row_time(estimated, T_R).startswith("t_r ok")


@pytest.mark.parametrize("t_r", [15e-6, 40e-6])
def test_row_time_other_band_periods(t_r, rng):
    assert cal.estimate_row_time(flicker_frame(rng, t_r=t_r, phase=2.0), FLICKER_HZ) == pytest.approx(t_r, rel=0.01)


def test_check_row_time_reports_a_mismatch(rng):
    estimated = cal.estimate_row_time(flicker_frame(rng, hz=1.05 * FLICKER_HZ), FLICKER_HZ)  # wrong frequency
    with pytest.raises(ValueError, match="t_r mismatch"):
        cal.check_row_time(estimated, T_R)
    assert cal.check_row_time(estimated, T_R, raise_error=False).startswith("t_r mismatch")
    assert cal.check_row_time(estimated, T_R, tolerance=0.1).startswith("t_r ok")


def test_flat_frame_has_no_band(rng):
    with pytest.raises(ValueError, match="no significant band"):
        cal.estimate_row_time(0.5 + 0.05 * rng.standard_normal((300, 64)), FLICKER_HZ)


# ---------------------------------------------------------------------- photometric gain
def test_flat_field_gains_within_one_percent(rng):
    gains = np.array([1.0, 0.8, 1.25, 0.93])
    dark = 0.02
    flats = []
    for c, gain in enumerate(gains):
        rows, cols = (60, 80) if c != 2 else (70, 90)  # cameras may differ in size
        y, x = np.mgrid[0:rows, 0:cols]
        vignetting = 1.0 - 0.3 * (((x - cols / 2) / cols) ** 2 + ((y - rows / 2) / rows) ** 2)
        frames = dark + gain * 0.5 * vignetting + 0.01 * rng.standard_normal((3, rows, cols))
        frames[:, rows // 2, cols // 2] = 50.0  # a hot pixel
        flats.append(frames)
    estimated = cal.flat_field_gain(flats, dark=dark, region=0.3)
    np.testing.assert_allclose(estimated, gains, rtol=0.01)
    assert estimated[0] == 1.0
    relative_to_mean = cal.flat_field_gain(flats, dark=dark, region=0.3, relative_to="mean")
    np.testing.assert_allclose(relative_to_mean, gains / gains.mean(), rtol=0.01)
    with pytest.raises(ValueError, match="must be > 0"):
        cal.flat_field_gain(flats, dark=10.0)
    # flat fields near the top of the float range: the same gains, no overflow
    huge = [f * 1e306 for f in flats]
    np.testing.assert_allclose(cal.flat_field_gain(huge, dark=dark * 1e306, region=0.3), gains, rtol=0.01)
    np.testing.assert_allclose(
        cal.flat_field_gain(huge, dark=dark * 1e306, region=0.3, relative_to="mean"), gains / gains.mean(), rtol=0.01
    )


# ---------------------------------------------------------------------- picture
def test_marker_overlay_png_is_written_and_readable(tmp_path, rng):
    import imageio.v3 as iio

    frames, detected, reprojected, outlines = [], [], [], []
    for angle in (0, 90, 180):
        frame = render(camera_homography(angle), rng=rng)
        registration = cal.register_camera(frame, MARKERS, reference="largest")
        frames.append(frame)
        detected.append(registration.sensor_points)
        reprojected.append(registration.reprojected)
        outlines.append(cal.reference_outline(registration.homography, SHAPE))
    corner = cal.project_points(camera_homography(180), [[-0.5, -0.5]])[0]
    np.testing.assert_allclose(outlines[2][0], corner, atol=0.5)
    path = cal.marker_overlay_png(
        tmp_path / "calibration.png", frames, detected, reprojected, outlines=outlines, titles=["a", "b", "c"]
    )
    image = iio.imread(path)
    assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 300
    assert image[..., :3].std() > 10  # not blank
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calibration.png"]  # no temporary left
    with pytest.raises(ValueError, match="one point set per frame"):
        cal.marker_overlay_png(tmp_path / "bad.png", frames, detected[:2], reprojected)
    assert not (tmp_path / "bad.png").exists()


# ---------------------------------------------------------------------- rig file helpers
def test_frame_origin_of_a_camera_roi(rng):
    H_true = camera_homography(90)
    x0, y0 = 6.0, 4.0
    to_frame = np.array([[1, 0, -x0], [0, 1, -y0], [0, 0, 1.0]])
    frame = render(to_frame @ H_true, rng=rng)  # the camera delivers its ROI only
    registration = cal.register_camera(frame, MARKERS, reference="largest", frame_origin=(x0, y0))
    assert cal.homography_difference(registration.homography, H_true, SHAPE) < 0.5  # full-sensor coordinates
    np.testing.assert_allclose(
        cal.warp_to_reference(frame, H_true, SHAPE, frame_origin=(x0, y0)),
        cal.warp_to_reference(frame, to_frame @ H_true, SHAPE),
    )


@pytest.mark.parametrize("angle", [0, 90, 180, 270, -45, 30])
def test_homography_angle(angle):
    def turn(a, b):  # signed difference, degrees in (-180, 180]
        return (a - b + 180.0) % 360.0 - 180.0

    assert -180 < cal.homography_angle(camera_homography(angle), SHAPE) <= 180
    assert abs(turn(cal.homography_angle(camera_homography(angle), SHAPE), angle)) < 2.0  # small perspective
    H = cal.rotation_homography(angle, SHAPE, scale=0.7, shift=(5.0, -3.0))
    assert abs(turn(cal.homography_angle(H, SHAPE), angle)) < 1e-9


# ---------------------------------------------------------------------- rsocl calibrate
ANGLES = (0, 90, 180, 270)


def _calibrate(argv):
    import argparse

    from rsocl.cli.calibrate import add_parser, cmd_calibrate

    parser = argparse.ArgumentParser(prog="rsocl")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["calibrate"] + [str(a) for a in argv])
    args.quiet = True
    return cmd_calibrate(args)


@pytest.fixture
def calibration_files(tmp_path, rng):
    """A 4-camera rig file (angles, t_r = 26 µs) and synthetic marker, flicker and flat-field files."""
    from rsocl import Rig
    from rsocl.files.rigfile import RigFile, save_rigfile

    rigfile = RigFile.from_rig(Rig.paper_array(4, shape=SHAPE, t_e=200e-6, t_r=T_R))
    rigfile.cameras[1]["roi"] = [6, 4, SENSOR[1], SENSOR[0]]  # camera 1 delivers a sensor ROI
    save_rigfile(tmp_path / "rig.toml", rigfile)
    truth = [camera_homography(angle) for angle in ANGLES]
    frames = []
    for c, H in enumerate(truth):
        to_frame = np.array([[1, 0, -6.0], [0, 1, -4.0], [0, 0, 1]]) if c == 1 else np.eye(3)
        frames.append(render(to_frame @ H, rng=rng))
    np.savez(tmp_path / "markers.npz", frames=np.stack(frames))
    t_r = [26.1e-6, 25.9e-6, 26.0e-6, 26.2e-6]  # within 1 % of the rig file
    np.savez(tmp_path / "flicker.npz", frames=np.stack([flicker_frame(rng, t_r=t) for t in t_r]))
    gains = [1.0, 0.9, 1.1, 1.2]
    np.savez(
        tmp_path / "flats.npz",
        **{f"camera{c}": 0.4 * g + 0.01 * rng.standard_normal((2, 60, 80)) for c, g in enumerate(gains)},
    )
    return tmp_path, truth, t_r, gains


def test_calibrate_writes_homographies_row_times_gains_and_png(calibration_files):
    import imageio.v3 as iio

    from rsocl.files.rigfile import load_rigfile

    folder, truth, t_r, gains = calibration_files
    refs = [f"{x:g},{y:g}" for x, y in MARKERS]
    assert (
        _calibrate(
            [
                "--rig",
                folder / "rig.toml",
                "--frames",
                folder / "markers.npz",
                "--identify",
                "largest",
                "--markers-ref",
                *refs,
                "--flicker",
                folder / "flicker.npz",
                "--flicker-hz",
                FLICKER_HZ,
                "--flat",
                folder / "flats.npz",
                "--png",
                folder / "calibration.png",
            ]
        )
        == 0
    )
    calibrated = load_rigfile(folder / "rig.toml")
    rig = calibrated.rig()
    for c, H in enumerate(truth):
        assert "angle" not in calibrated.cameras[c]
        assert cal.homography_difference(calibrated.homography(c), H, SHAPE) < 0.5
        assert calibrated.cameras[c]["t_r"] == pytest.approx(t_r[c], rel=0.01)
        assert calibrated.cameras[c]["gain"] == pytest.approx(gains[c], rel=0.01)
        first_row = 4 if c == 1 else 0  # camera 1 reads from the top row of its roi, sensor row 4
        np.testing.assert_allclose(rig.row_map(c), cal.row_map_from_homography(H, SHAPE, first_row), atol=0.5)
    assert calibrated.cameras[1]["roi"] == [6, 4, SENSOR[1], SENSOR[0]]
    assert rig.dt == pytest.approx(min(cam["t_r"] for cam in calibrated.cameras))  # dt followed t_r
    assert iio.imread(folder / "calibration.png").ndim == 3


def test_calibrate_positions_with_nominal_angles_and_default_png(calibration_files):
    from rsocl.files.rigfile import load_rigfile

    folder, truth, _, _ = calibration_files
    out = folder / "calibrated.toml"
    assert (
        _calibrate(
            [
                "--rig",
                folder / "rig.toml",
                "--frames",
                folder / "markers.npz",
                "--out",
                out,
                "--markers-ref",
                "55,9;9,41",
                "8,7 54,40",
            ]
        )
        == 0
    )  # any order, any separator
    calibrated = load_rigfile(out)
    for c, H in enumerate(truth):
        assert cal.homography_difference(calibrated.homography(c), H, SHAPE) < 0.5
    assert (folder / "calibrated-calibration.png").is_file()
    assert "angle" in load_rigfile(folder / "rig.toml").cameras[0]  # --rig left alone


def test_calibrate_refuses_a_row_time_mismatch_and_writes_nothing(calibration_files):
    folder, *_ = calibration_files
    before = (folder / "rig.toml").read_bytes()
    wrong_hz = ["--flicker", folder / "flicker.npz", "--flicker-hz", 1.1 * FLICKER_HZ]
    with pytest.raises(ValueError, match="t_r mismatch"):
        _calibrate(["--rig", folder / "rig.toml", *wrong_hz])
    assert (folder / "rig.toml").read_bytes() == before
    with pytest.raises(ValueError, match="nothing to calibrate"):
        _calibrate(["--rig", folder / "rig.toml"])
    with pytest.raises(ValueError, match="4 cameras but 2"):
        np.savez(folder / "two.npz", frames=np.zeros((2, 40, 40)))
        _calibrate(["--rig", folder / "rig.toml", "--flat", folder / "two.npz"])
    assert _calibrate(["--rig", folder / "rig.toml", *wrong_hz, "--force"]) == 0
    assert (folder / "rig.toml").read_bytes() != before


def test_calibrate_reads_folders_and_given_marker_coordinates(calibration_files):
    from rsocl.files.rigfile import load_rigfile

    folder, truth, _, gains = calibration_files
    flats = folder / "flats"
    flats.mkdir()
    with np.load(folder / "flats.npz") as data:
        for c in range(4):
            np.save(flats / f"cam{c}.npy", data[f"camera{c}"])
    # Marker coordinates measured elsewhere (frame coordinates, in --markers-ref order): no detection.
    origins = [np.zeros(2), np.array([6.0, 4.0]), np.zeros(2), np.zeros(2)]
    given = np.stack([cal.project_points(H, MARKERS) - o for H, o in zip(truth, origins)])
    with np.load(folder / "markers.npz") as data:
        np.savez(folder / "given.npz", frames=data["frames"], markers=given)
    refs = ";".join(f"{x:g},{y:g}" for x, y in MARKERS)
    assert (
        _calibrate(
            ["--rig", folder / "rig.toml", "--frames", folder / "given.npz", "--markers-ref", refs, "--flat", flats]
        )
        == 0
    )
    calibrated = load_rigfile(folder / "rig.toml")
    for c, H in enumerate(truth):
        assert cal.homography_difference(calibrated.homography(c), H, SHAPE) < 1e-6
        assert calibrated.cameras[c]["gain"] == pytest.approx(gains[c], rel=0.01)
    with pytest.raises(ValueError, match="must have the rig's shape"):
        _calibrate(["--rig", folder / "rig.toml", "--frames", folder / "markers.npz"])


def test_calibrate_refuses_an_output_that_is_an_input_before_any_work(calibration_files, monkeypatch):
    import rsocl.cli.calibrate as calibrate_cli

    folder, *_ = calibration_files
    flats = (folder / "flats.npz").read_bytes()
    monkeypatch.setattr(calibrate_cli, "_gains", lambda *a: pytest.fail("calibrated before checking --out"))
    with pytest.raises(ValueError, match=r"--out .*flats.npz' is the --flat it reads"):
        _calibrate(["--rig", folder / "rig.toml", "--flat", folder / "flats.npz", "--out", folder / "flats.npz"])
    with pytest.raises(FileNotFoundError, match="--out: directory .*missing"):
        _calibrate(
            ["--rig", folder / "rig.toml", "--flat", folder / "flats.npz", "--out", folder / "missing" / "r.toml"]
        )
    with pytest.raises(ValueError, match=r"--png .*markers.npz' is the --frames it reads"):
        _calibrate(["--rig", folder / "rig.toml", "--frames", folder / "markers.npz", "--png", folder / "markers.npz"])
    assert (folder / "flats.npz").read_bytes() == flats


@pytest.mark.parametrize(
    "given, match",
    [
        (["--flat", "flats.npz", "--polarity", "dark", "--png", "o.png"], r"^--polarity, --png need --frames "),
        (["--flat", "flats.npz", "--tolerance", "0.5"], r"^--tolerance needs --flicker \(frames of the flickering"),
        (
            ["--flat", "flats.npz", "--force"],
            r"^--force needs --frames or --flicker \(frames of the marker target or ",
        ),
        (["--frames", "markers.npz", "--dark", "5"], r"^--dark needs --flat \(flat-field frames\)"),
        (["--flat", "flats.npz", "--flicker-hz", "100"], r"^--flicker-hz needs --flicker "),
    ],
)
def test_an_option_of_a_measurement_not_asked_for_is_refused_not_ignored(calibration_files, monkeypatch, given, match):
    import rsocl.cli.calibrate as calibrate_cli

    folder, *_ = calibration_files
    monkeypatch.setattr(calibrate_cli, "_gains", lambda *a: pytest.fail("calibrated before checking the options"))
    with pytest.raises(ValueError, match=match):
        _calibrate(["--rig", folder / "rig.toml", *[folder / v if v.endswith(".npz") else v for v in given]])


def test_calibrate_keeps_the_rig_file_it_replaces(calibration_files, capsys):
    import re

    from rsocl.cli.main import main
    from rsocl.files.rigfile import load_rigfile

    folder, *_ = calibration_files
    rig = folder / "rig.toml"
    before = rig.read_bytes()
    for _ in range(2):  # twice within a second: the second copy takes another name
        assert main(["calibrate", "--rig", str(rig), "--flat", str(folder / "flats.npz")]) == 0
    kept = sorted(folder.glob("rig.before-calibration-*.toml"))
    assert len(kept) == 2 and all(
        re.fullmatch(r"rig\.before-calibration-\d{8}T\d{6}Z(-1)?\.toml", p.name) for p in kept
    )
    [original] = [p for p in kept if p.read_bytes() == before]  # the file before any calibration, byte for byte
    assert load_rigfile(original).cameras[1].get("gain", 1.0) == 1.0
    assert load_rigfile(rig).cameras[1]["gain"] == pytest.approx(0.9, rel=0.01)  # the flat field's
    out = capsys.readouterr().out
    named = re.findall(r"\(the earlier file there is kept as (.+)\)$", out, re.MULTILINE)
    assert sorted(named) == sorted(map(str, kept))
    assert (
        main(["calibrate", "--rig", str(rig), "--flat", str(folder / "flats.npz"), "--out", str(folder / "new.toml")])
        == 0
    )
    assert len(list(folder.glob("*.before-calibration-*"))) == 2  # a new file replaces nothing


def test_keep_copy_names_and_refusals(tmp_path):
    from rsocl.files.atomic import keep_copy

    assert keep_copy(tmp_path / "absent.toml", "before") is None
    (tmp_path / "a.toml").write_text("x")
    copies = [keep_copy(tmp_path / "a.toml", "before") for _ in range(3)]
    assert len(set(copies)) == 3 and all(c.read_text() == "x" and c.parent == tmp_path for c in copies)
    with pytest.raises(ValueError, match="tag must be"):
        keep_copy(tmp_path / "a.toml", "../x")


def test_api_parameters_out_of_range_are_named():
    frame, H = np.ones((8, 8)), np.eye(3)
    for order in (2.7, -1, 6, "x", None, True):
        with pytest.raises(ValueError, match=r"order must be an integer in \[0, 5\]"):
            cal.warp_to_reference(frame, H, (8, 8), order=order)
    with pytest.raises(ValueError, match=r"shift must be \(dx, dy\) in pixels, got \(1,\)"):
        cal.rotation_homography(0.0, (8, 8), shift=(1,))
    for dark in (-np.inf, np.nan):
        with pytest.raises(ValueError, match="dark must be finite"):
            cal.flat_field_gain([frame, frame], dark=dark)
