"""``rsocl plan``: propose dt, ROI and T_se for a scene, with the memory and time they need, before running."""

from __future__ import annotations

from rsocl.cli.options import add_device_args, add_rig_args, reg_options, regularizer_from, rig_from
from rsocl.cli.tiling import add_plan_tiling_args, check_plan_tiling_args, print_plan_tiling
from rsocl.solver.ladder import DEFAULT_QUALITY, QUALITIES

__all__ = ["add_parser", "roi_from", "cmd_plan"]


def add_parser(subparsers):
    """Add ``plan`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("plan", help="propose dt, ROI and T_se for a scene, with memory and time, before running")
    add_rig_args(p, shape=(256, 256))
    p.add_argument(
        "--roi",
        type=int,
        nargs=4,
        metavar=("X", "Y", "WIDTH", "HEIGHT"),
        default=None,
        help="where the motion is: column and row of its top-left pixel, then width and height, reference "
        "pixels, the order of a rig file's roi = [x, y, width, height] (default: whole grid)",
    )
    p.add_argument("--speed", type=float, default=None, help="largest image speed, pixels/s")
    p.add_argument("--fps", type=float, default=None, help="sub-frame rate wanted, Hz")
    p.add_argument("--blur", type=float, default=1.0, help="motion allowed within a sub-frame, pixels (default 1)")
    p.add_argument("--iterations", type=int, default=200, help="ADMM iterations to cost, >= 1 (default 200)")
    p.add_argument("--regularizer", default="tv", help="regularizer name (see 'rsocl plugins')")
    p.add_argument(
        "--reg-opt",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="regularizer option, repeatable (its workspace is counted: TV's fused=N keeps a second dual buffer)",
    )
    p.add_argument(
        "--quality",
        choices=QUALITIES,
        default=DEFAULT_QUALITY,
        help="rung of the self-tuned run costed (default balanced; docs/quality_ladder.md)",
    )
    p.add_argument(
        "--no-measure", action="store_true", help="memory only; do not time 3 iterations and the parameter search"
    )
    add_device_args(p)
    add_plan_tiling_args(p)
    p.set_defaults(func=cmd_plan)
    return p


def roi_from(roi, shape):
    """``--roi X Y WIDTH HEIGHT`` as the ``(y, x, height, width)`` block of the solver's API, checked inside
    the ``shape`` (rows, columns) grid: a ValueError saying the order, the grid and the values; None stays None."""
    if roi is None:
        return None
    x, y, width, height = (int(v) for v in roi)
    m, n = shape
    if not (0 <= x and 0 <= y and width >= 1 and height >= 1 and x + width <= n and y + height <= m):
        raise ValueError(
            f"--roi is X Y WIDTH HEIGHT (top-left column and row, then width and height, pixels), inside "
            f"the grid of {n} columns x {m} rows: x + width <= {n}, y + height <= {m}; got {x} {y} "
            f"{width} {height}"
        )
    return (y, x, height, width)


def cmd_plan(args) -> int:
    """Print the plan of :func:`rsocl.solver.plan.plan` (and a tiling when it does not fit); returns 0.

    Every option is checked before the table is printed or anything is measured.
    """
    from rsocl.common import validation as check
    from rsocl.solver.plan import format_plan, plan
    from rsocl.solver.problem import MAX_ITERATIONS

    check.positive_int("--iterations", args.iterations, MAX_ITERATIONS)
    check.positive("--blur", args.blur, "pixels")
    regularizer_from(args)  # its options checked now; the plan takes them as rsocl reconstruct does
    rig = rig_from(args)
    roi = roi_from(args.roi, rig.shape)
    check_plan_tiling_args(args, rig.shape if roi is None else rig.crop(roi).shape)
    p = plan(
        rig,
        roi=roi,
        speed=args.speed,
        fps=args.fps,
        blur_pixels=args.blur,
        iterations=args.iterations,
        regularizer=args.regularizer,
        regularizer_options=reg_options(args.reg_opt),
        dtype=args.dtype,
        device=args.device,
        measure=not args.no_measure,
        quality=args.quality,
    )
    print(format_plan(p))
    print_plan_tiling(args, p)
    return 0
