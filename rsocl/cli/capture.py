"""``rsocl capture``: a rig file (TOML) -> a capture file (HDF5) of synchronized sets from the cameras."""

from __future__ import annotations

import sys

__all__ = ["add_parser", "cmd_capture"]


def add_parser(subparsers):
    """Add ``capture`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser(
        "capture",
        help="rig file (TOML) -> capture file (HDF5): synchronized sets from the cameras",
        description="Capture synchronized sets from the cameras of a rig file. Each raw frame is written "
        "before the next is requested, to OUT.partial, renamed to OUT at the end; if a camera "
        "fails, or the next set would fill the disk or take the file past the file-size limit (ulimit -f), OUT "
        "keeps everything captured and records the failure, and the exit status is 1. "
        "Settings a camera cannot take (a pixel_format it does not deliver, a roi beyond its sensor, an Aravis "
        "interface this Aravis lacks) are refused before OUT.partial is made (exit status 2). "
        "An OUT.partial left by a killed capture is never overwritten: the capture is refused "
        "(naming its complete sets) until it is renamed or removed.",
    )
    p.add_argument("--rig", required=True, help="TOML rig file (seconds, degrees)")
    p.add_argument(
        "--out",
        required=True,
        help="capture file to write (.h5); never one that holds frames from cameras; a file there other than a "
        "simulated capture is kept as STEM.earlier-<UTC time>.h5",
    )
    p.add_argument("--sets", type=int, default=1, help="number of synchronized sets (default 1)")
    p.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for each frame (default 2)")
    p.add_argument("--quiet", action="store_true", help="no progress bar (drawn on a terminal only), only errors")
    p.set_defaults(func=cmd_capture)
    return p


def cmd_capture(args) -> int:
    """Run :func:`~rsocl.hardware.capture.capture_sets`: 0 on success, 1 when a camera failed (the file records it)
    or the capture file could not be completed or renamed to ``--out`` (the line names the file holding the sets).

    Bad arguments or rig files raise ValueError / FileNotFoundError (the CLI's exit status 2).
    """
    from rsocl.cli.options import load_rig_file, progress_bar
    from rsocl.cli.outputs import require_hdf5_name
    from rsocl.common import validation as check
    from rsocl.files.atomic import output_path
    from rsocl.files.hdf5 import refuse_camera_capture
    from rsocl.hardware.capture import CaptureFailed, capture_sets
    from rsocl.hardware.capture_file import PARTIAL_SUFFIX, check_partial

    quiet = bool(getattr(args, "quiet", False))
    check.positive_int("--sets", args.sets)  # named as typed, before the rig file is read (capture_sets checks again)
    check.positive("--timeout", args.timeout, "seconds")
    out = output_path(args.out, "--out", inputs=(("--rig", args.rig),))  # an input at --out: said as such
    require_hdf5_name(args.out)
    check_partial(out.with_name(out.name + PARTIAL_SUFFIX), "--out")  # as typed (capture_sets checks again)
    refuse_camera_capture(out, "--out")
    rigfile = load_rig_file(args.rig)  # a shape beyond the host's memory: refused here
    try:
        path = capture_sets(
            rigfile, args.out, sets=args.sets, timeout=args.timeout, progress=progress_bar(args), name="--out"
        )
    except CaptureFailed as exc:
        print(f"rsocl capture: error: {exc}", file=sys.stderr)
        return 1
    if not quiet:
        from rsocl.files.hdf5 import load_capture_rig

        rig = load_capture_rig(path)
        print(
            f"wrote {path}: {args.sets} set(s) from {rig.C} camera(s), {rig.shape[0]}x{rig.shape[1]}, "
            f"T = {rig.T} sub-frames",
            flush=True,
        )
    return 0
