"""``rsocl calibrate``: measure homographies, row times and gains, and write them into a rig file.

Wired into :mod:`rsocl.cli` with :func:`add_parser`; the command is
:func:`cmd_calibrate`. Every measurement is optional, but at least one is
needed:

* ``--frames``: one frame per camera of a target with marker dots -> each
  camera's ``homography`` (replacing its ``angle`` or ``row_map_file``), and
  a PNG of the registered markers (``--png``). Markers paired as no camera sees
  them are refused (:mod:`rsocl.hardware.calibration.plausibility`); four markers
  fit exactly and cannot check the fit, five or more give its error over the grid;
* ``--flicker`` + ``--flicker-hz``: frames of a flickering light -> each
  camera's ``t_r`` (the mean over its frames), checked against the rig
  file first (``--tolerance``);
* ``--flat``: flat-field frames -> each camera's ``gain`` relative to camera 0.

Nothing is written unless every requested measurement succeeds; the rig file
(and the PNG) are replaced atomically. An ``--out`` or ``--png`` that is an HDF5 file (a capture, a
reconstruction) is refused before any work, and ``--png`` must end in ``.png``.

The layouts of the frame files (``.npz``, ``.npy``, a folder of images) are in
:mod:`rsocl.cli.calibrate_frames`.
"""

from __future__ import annotations

import math

import numpy as np

from rsocl.cli.calibrate_frames import NEEDS, _dest, check_needs, load_frames, one_frame, parse_points, per_camera
from rsocl.cli.options import load_rig_file, say

__all__ = ["add_parser", "cmd_calibrate", "load_frames", "parse_points"]


# ---------------------------------------------------------------------- parser
def add_parser(subparsers):
    """Add the ``calibrate`` sub-command to an :mod:`argparse` sub-parsers object; returns its parser."""
    p = subparsers.add_parser(
        "calibrate",
        help="measure homographies, t_r and gains and write them into a rig file",
        description="Measure each camera's registration (marker target), row time (flickering light) and "
        "photometric gain (flat field), and write them into the rig file.",
    )
    p.add_argument("--rig", required=True, help="rig file (.toml) to update")
    p.add_argument(
        "--out",
        default=None,
        help="write the updated rig file here instead (default: --rig); the file it replaces is kept beside it "
        "as <stem>.before-calibration-<UTC time>.toml; never an HDF5 file (a capture, a reconstruction)",
    )
    g = p.add_argument_group("registration (marker target)")
    g.add_argument(
        "--frames",
        default=None,
        help="one frame per camera of the marker target: .npz ('frames' or camera0..), .npy, or folder",
    )
    g.add_argument(
        "--markers-ref",
        nargs="+",
        default=None,
        metavar="X,Y",
        help="marker positions on the reference grid, pixels (x = column, y = row); default: every "
        "dot found in camera 0's frame, which must then have the rig's shape. With "
        "--identify largest, list the large marker first. Negative values: "
        "--markers-ref='-3,5 60,5 ...'",
    )
    g.add_argument(
        "--identify",
        choices=["position", "largest"],
        default="position",
        help="how markers are matched across rotated cameras: 'position' (clockwise from top-left, "
        "turned by each camera's nominal angle from the rig file) or 'largest' (the target "
        "has one larger marker; it comes first)",
    )
    g.add_argument(
        "--mirrored",
        type=int,
        nargs="+",
        default=[],
        metavar="C",
        help="cameras (indices) that see the target in a mirror, e.g. through a beam splitter: their "
        "homography mirrors the image (any other camera's may not). With --identify position a mirrored "
        "camera's marker order starts from its rig file angle, the direction in which it sees the "
        "reference x axis; --identify largest needs no angle",
    )
    g.add_argument("--polarity", choices=["bright", "dark"], default="bright", help="bright or dark dots")
    g.add_argument("--threshold", type=float, default=None, help="dot/background threshold (default: automatic)")
    g.add_argument(
        "--png",
        default=None,
        help="overlay picture to write, a .png (default: <rig stem>-calibration.png next to the output); never an "
        "HDF5 file (a capture, a reconstruction)",
    )
    g = p.add_argument_group("row time (flickering light)")
    g.add_argument(
        "--flicker",
        default=None,
        help="frame(s) of an evenly lit scene under a flickering light: one 2-D .npy for all "
        "cameras, or one frame per camera",
    )
    g.add_argument(
        "--flicker-hz",
        type=float,
        default=None,
        help="intensity flicker frequency, Hz (twice the mains frequency for lamps on AC)",
    )
    g.add_argument(
        "--tolerance",
        type=float,
        default=0.01,
        help="largest accepted relative difference from the rig file's t_r (default 0.01)",
    )
    g.add_argument(
        "--force",
        action="store_true",
        help="write the measured values even when they fail a check: a t_r beyond --tolerance, a homography "
        "whose markers fit with an rms error above 1 px (five or more markers); never a pairing no camera has",
    )
    g = p.add_argument_group("photometric gain (flat field)")
    g.add_argument(
        "--flat",
        default=None,
        help="flat-field frame(s) per camera in one unit for all (raw levels of one bit depth), same exposure; "
        "or an rsocl capture file (HDF5: .h5, .hdf5, .hdf, .he5) of the flat field, whose frames are normalised "
        "per camera",
    )
    g.add_argument(
        "--dark",
        type=float,
        default=0.0,
        help="dark level subtracted from flat fields, in their units (a capture file's: a fraction of full "
        "scale) (default 0)",
    )
    p.add_argument("--quiet", action="store_true", help="print only errors")
    needed = {_dest(o): p.get_default(_dest(o)) for options in NEEDS.values() for o in options}
    p.set_defaults(func=cmd_calibrate, option_defaults=needed)
    return p


# ---------------------------------------------------------------------- command
def _nominal_angle(camera: dict, shape) -> float:
    """The rotation the rig file states for a camera (angle, or implied by its homography), degrees."""
    from rsocl.hardware.calibration import homography_angle

    if camera.get("angle") is not None:
        return float(camera["angle"])
    if camera.get("homography") is not None:
        return homography_angle(np.asarray(camera["homography"], dtype=np.float64), shape)
    return 0.0


def _nominal_key(camera: dict) -> str:
    return "angle" if camera.get("angle") is not None else "homography"


def _has_nominal(camera: dict) -> bool:
    """Whether the rig file states the camera's rotation (an ``angle`` or a ``homography``)."""
    return camera.get("angle") is not None or camera.get("homography") is not None


def _origin(camera: dict):
    roi = camera.get("roi")
    return (float(roi[0]), float(roi[1])) if roi is not None else (0.0, 0.0)


def _register(args, rigfile, updates):
    """Registration of every camera; returns the overlay inputs."""
    from rsocl.hardware.calibration import detect_markers, homography_angle, reference_outline, register_camera
    from rsocl.hardware.calibration.plausibility import (
        check_fit,
        check_registration,
        check_rotation,
        fit_refusal,
        fit_summary,
    )

    C = len(rigfile.cameras)
    bad = [c for c in args.mirrored if not 0 <= c < C]
    if bad:
        raise ValueError(f"--mirrored must list camera indices in [0, {C - 1}], got {bad}")
    frames, extras = load_frames(args.frames, "--frames")
    frames = [one_frame(f) for f in per_camera(frames, C, "--frames")]
    given = extras.get("markers")
    if given is not None and (given.ndim != 3 or given.shape[0] != C or given.shape[2] != 2):
        raise ValueError(f"--frames: 'markers' must have shape ({C}, N, 2), got {given.shape}")
    reference = "largest" if args.identify == "largest" else None
    options = {"polarity": args.polarity, "threshold": args.threshold}
    if args.markers_ref is not None:
        reference_points = parse_points(args.markers_ref)
    else:
        if tuple(frames[0].shape) != tuple(rigfile.shape):
            raise ValueError(
                f"without --markers-ref, camera 0's frame is the reference grid and must have the "
                f"rig's shape {tuple(rigfile.shape)}, got {frames[0].shape}"
            )
        reference_points = (  # every dot camera 0 shows
            given[0] if given is not None else detect_markers(frames[0], None, reference=reference, **options)
        )
        say(
            args,
            f"reference markers (camera 0, {len(reference_points)} dots): "
            + " ".join(f"{x:.2f},{y:.2f}" for x, y in reference_points),
        )
    if len(reference_points) < 4:
        raise ValueError(f"a homography needs at least 4 markers, got {len(reference_points)}")
    detected, reprojected, outlines, titles = [], [], [], []
    for c, camera in enumerate(rigfile.cameras):
        origin = np.asarray(_origin(camera))
        angle = _nominal_angle(camera, rigfile.shape)
        try:
            registration = register_camera(
                frames[c],
                reference_points,
                reference=reference,
                angle=angle,
                frame_origin=origin,
                sensor_points=None if given is None else given[c] + origin,
                mirrored=c in args.mirrored,
                **options,
            )
            H = registration.homography
            check_registration(
                registration.reference_points, registration.sensor_points, H, rigfile.shape, mirrored=c in args.mirrored
            )
            rms = check_fit(registration)
            if rms is not None:
                why = fit_refusal(
                    registration, rms, rigfile.shape, camera=c, key=_nominal_key(camera), mirrored=c in args.mirrored
                )
                if not args.force:
                    raise ValueError(f"{why}; --force writes it anyway")
                say(args, f"camera {c}: {why}; written as --force asks")
            measured = (
                homography_angle(H, rigfile.shape)
                if not _has_nominal(camera)
                else check_rotation(H, rigfile.shape, angle, key=f"camera[{c}].{_nominal_key(camera)}")
            )
        except ValueError as exc:
            hint = None
            if given is None and "--force" not in str(exc):  # detected markers refused: does another order fit?
                hint = _detected_hint(
                    frames[c], reference_points, reference, angle, origin, options, c, rigfile, c in args.mirrored
                )
            raise ValueError(f"camera {c}: {exc}{hint or ''}") from None
        rows = registration.row_map(rigfile.shape)
        updates[c]["homography"] = H
        detected.append(registration.sensor_points - origin)
        reprojected.append(registration.reprojected - origin)
        outlines.append(reference_outline(H, rigfile.shape, frame_origin=origin))
        name = camera.get("name")
        fit = f"rms {registration.rms_error:.2f} px" if len(reference_points) > 4 else "4 markers: exact fit"
        titles.append(f"camera {c}" + (f" ({name})" if name else "") + f": {measured:.1f}°, {fit}")
        say(
            args,
            f"camera {c}: homography from {fit_summary(registration, rigfile.shape)}; rotation {measured:.2f}° "
            f"(rig file: {angle:g}°), sensor rows 0..{rows.max():.2f} over the ROI",
        )
    return frames, detected, reprojected, outlines, titles


def _detected_hint(frame, reference_points, reference, angle, origin, options, c, rigfile, mirrored):
    """:func:`~rsocl.hardware.calibration.plausibility.pairing_hint` for camera ``c``'s detected markers."""
    from rsocl.hardware.calibration import detect_markers, order_markers
    from rsocl.hardware.calibration.plausibility import pairing_hint

    try:
        sensor = detect_markers(
            frame, len(reference_points), reference=reference, angle=angle, mirrored=mirrored, **options
        )
        ordered = order_markers(reference_points, first=0 if reference == "largest" else None)
        key = _nominal_key(rigfile.cameras[c])
        return pairing_hint(ordered, sensor + origin, rigfile.shape, camera=c, key=key, mirrored=mirrored)
    except ValueError:  # detection itself failed: the error says why
        return None


def _row_times(args, rigfile, updates):
    from rsocl.hardware.calibration import check_row_time, estimate_row_time
    from rsocl.hardware.calibration.timing import flicker_limits

    frames, _ = load_frames(args.flicker, "--flicker")
    C = len(rigfile.cameras)
    if len(frames) == 1 and C > 1 and frames[0].ndim == 2:
        frames = frames * C
    frames = per_camera(frames, C, "--flicker")
    problems = []
    for c, camera in enumerate(rigfile.cameras):
        stack = frames[c] if frames[c].ndim == 3 else frames[c][None]
        why = "".join(f"; {r}" for r in flicker_limits(args.flicker_hz, camera["t_r"], camera["t_e"], len(stack[0])))
        try:
            t_r = float(np.mean([estimate_row_time(frame, args.flicker_hz) for frame in stack]))
        except ValueError as exc:
            raise ValueError(f"camera {c}: {exc}{why}") from None
        message = check_row_time(t_r, camera["t_r"], args.tolerance, raise_error=False)
        message += why if message.startswith("t_r mismatch") else ""
        say(args, f"camera {c}: {message}")
        if message.startswith("t_r mismatch"):
            problems.append(f"camera {c}: {message}")
        updates[c]["t_r"] = t_r
    if problems and not args.force:
        raise ValueError("; ".join(problems) + " (nothing written; --force writes the measured values)")


def _gains(args, rigfile, updates):
    from rsocl.cli.calibrate_frames import load_flats
    from rsocl.hardware.calibration import flat_field_gain

    frames, darks, saturation = load_flats(args.flat, rigfile, args.dark)
    gains = flat_field_gain(frames, dark=darks, saturation=saturation)
    for c, gain in enumerate(gains):
        updates[c]["gain"] = float(gain)
    say(args, "gains relative to camera 0: " + ", ".join(f"{g:.4f}" for g in gains))


def _updated(rigfile, updates):
    """A new RigFile with the measured values in place (checked as a whole)."""
    from rsocl.files.rigfile import RigFile

    cameras = []
    old_t_r = min(camera["t_r"] for camera in rigfile.cameras)
    for camera, update in zip(rigfile.cameras, updates):
        camera = dict(camera)
        if "homography" in update:
            for key in ("angle", "row_map_file", "row_map"):
                camera.pop(key, None)
            camera["homography"] = np.asarray(update["homography"], dtype=np.float64).tolist()
        for key in ("t_r", "gain"):
            if key in update:
                camera[key] = float(update[key])
        cameras.append(camera)
    dt = rigfile.dt
    new_t_r = min(camera["t_r"] for camera in cameras)
    if dt is not None and math.isclose(dt, old_t_r, rel_tol=1e-9):
        dt = new_t_r  # a dt equal to the row time follows the measured one
    try:
        return RigFile(shape=rigfile.shape, cameras=cameras, dt=dt, mask=rigfile.mask, path=rigfile.path)
    except ValueError as exc:
        raise ValueError(f"the calibrated rig is not valid: {exc}") from None


def cmd_calibrate(args) -> int:
    """Run ``rsocl calibrate`` with parsed ``args`` (see :func:`add_parser`); returns 0.

    Raises ``ValueError`` / ``FileNotFoundError`` with a message naming the
    option and camera at fault; nothing is written then. An interrupt (Ctrl-C, SIGTERM) ends in one line
    saying what was written and kept (:func:`rsocl.cli.calibrate_outputs.interrupt_line`).
    """
    from rsocl.cli.calibrate_outputs import REPLACED, calibration_outputs, interrupt_line
    from rsocl.cli.outputs import interrupted, kept_note
    from rsocl.common import validation as check
    from rsocl.files.atomic import keeping
    from rsocl.files.rigfile import save_rigfile
    from rsocl.hardware.calibration import marker_overlay_png

    if args.frames is None and args.flicker is None and args.flat is None:
        raise ValueError("nothing to calibrate: give --frames, --flicker (with --flicker-hz) and/or --flat")
    check_needs(args, args.option_defaults)
    if args.flicker is not None:  # as typed, before any frame is read
        if args.flicker_hz is None:
            raise ValueError("--flicker needs --flicker-hz (the light's intensity frequency, Hz)")
        check.positive("--flicker-hz", args.flicker_hz, "Hz")
    check.non_negative("--tolerance", args.tolerance)
    check.finite("--dark", args.dark)
    if args.threshold is not None:
        check.finite("--threshold", args.threshold)
    out, png = calibration_outputs(args)  # before any work
    done: dict = {}
    with interrupted(lambda: interrupt_line(out, png, done)):
        rigfile = load_rig_file(args.rig)
        updates: list[dict] = [{} for _ in rigfile.cameras]
        overlay = _register(args, rigfile, updates) if args.frames is not None else None
        if args.flicker is not None:
            _row_times(args, rigfile, updates)
        if args.flat is not None:
            _gains(args, rigfile, updates)
        calibrated = _updated(rigfile, updates)
        written = []
        if overlay is not None:
            frames, detected, reprojected, outlines, titles = overlay
            written.append(marker_overlay_png(png, frames, detected, reprojected, outlines=outlines, titles=titles))
            done["png"] = True
        with keeping(out, REPLACED) as kept:  # the rig file it replaces, --rig or another
            done["kept"] = kept
            written.insert(0, save_rigfile(out, calibrated))
            done["rig"] = True
    rig = calibrated.rig()
    say(args, f"rig: {rig!r}\nwrote " + ", ".join(str(p) for p in written) + kept_note([kept]))
    return 0
