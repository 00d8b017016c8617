"""``rsocl info``: the numbers of a rig (T, N_s, T_se, compression ratio, effective frame rate, memory).

The rig is the paper's array of the rig options, or, with ``--capture``, the rig stored in a capture
file: the one ``rsocl reconstruct`` uses, as it is. The rig options cannot change a capture's rig
(its snapshots were taken with it), so they are refused with ``--capture`` rather than ignored.
"""

from __future__ import annotations

from rsocl.cli.options import US, add_rig_args, refuse_rig_args, rig_from
from rsocl.common import validation as check

__all__ = ["add_parser", "check_info_args", "cmd_info"]


def add_parser(subparsers):
    """Add ``info`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("info", help="T, N_s, T_se, compression ratio and effective fps of a rig")
    add_rig_args(p, shape=(50, 50))
    p.add_argument(
        "--capture",
        default=None,
        help="read the rig from this capture file instead (the rig options cannot be given with it)",
    )
    p.add_argument("--camera-fps", type=float, default=67.0, help="camera frame rate, Hz (default 67)")
    p.set_defaults(func=cmd_info, check_options=check_info_args)
    return p


def check_info_args(args) -> None:
    """Refuse rig options given with ``--capture`` (``rsocl.cli.main`` calls it before :func:`cmd_info`)."""
    if args.capture:
        refuse_rig_args(
            args,
            "--capture",
            "the capture file holds the rig its snapshots were taken with, which rsocl reconstruct uses as it is",
        )


def cmd_info(args) -> int:
    """Print one ``key  value`` line per quantity of the rig; returns 0."""
    from rsocl.files.hdf5 import load_capture_rig

    fps = check.positive("--camera-fps", args.camera_fps, "Hz")
    rig = load_capture_rig(args.capture, "--capture") if args.capture else rig_from(args)
    m, n = rig.shape
    rows = [
        ("cameras", f"{rig.C} ({rig.n_channels} snapshots)"),
        ("ROI", f"{m} x {n} pixels"),
        ("sub-frame dt", f"{rig.dt / US:g} µs ({rig.subframe_rate:,.0f} sub-frames/s)"),
        ("mask", rig.mask),
        ("T (sub-frames)", f"{rig.T}"),
        ("N_s = ceil(t_e/t_r)", f"{rig.N_s}"),
        ("t_e/dt (exact rule)", f"{rig.exposure_subframes:.2f}"),
        ("T_se (trimmed)", _kept_line(rig)),
        ("compression ratio", f"{rig.compression_ratio:.2f}x (T_se / snapshots)"),
        (f"effective fps at {fps:g} fps", f"{rig.effective_fps(fps):,.0f}"),
        ("datacube", f"{rig.datacube_bytes(4) / 2**20:.2f} MiB in float32"),
    ]
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key:<{width}}  {value}")
    return 0


def _kept_line(rig) -> str:
    """``T_se`` and its sub-frames: the first and last seen by ``min_cameras`` cameras or more, and how many
    between them fewer see (the trimming keeps them: ``docs/model.md``)."""
    import numpy as np

    kept = rig.kept_subframes()
    if kept.stop == kept.start:
        return f"0 (no sub-frame is seen by >= {rig.min_cameras} cameras)"
    fewer = int(np.count_nonzero(rig.cameras_per_subframe()[kept] < rig.min_cameras))
    between = "" if not fewer else f"; {fewer} between them by fewer"
    ends = "each" if not fewer else "the first and last"
    return (
        f"{rig.T_se} (sub-frames {kept.start}..{kept.stop - 1}, {ends} seen by >= {rig.min_cameras} cameras{between})"
    )
