"""``rsocl plan``: propose dt, ROI and T_se for a scene, with the memory and time they need, before running."""

from __future__ import annotations

from rsocl.cli.options import add_device_args, add_rig_args, rig_from

__all__ = ["add_parser", "cmd_plan"]


def add_parser(subparsers):
    """Add ``plan`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("plan", help="propose dt, ROI and T_se for a scene, with memory and time, before running")
    add_rig_args(p, shape=(256, 256))
    p.add_argument("--roi", type=int, nargs=4, metavar=("Y", "X", "H", "W"), default=None,
                   help="where the motion is, reference pixels (default: whole grid)")
    p.add_argument("--speed", type=float, default=None, help="largest image speed, pixels/s")
    p.add_argument("--fps", type=float, default=None, help="sub-frame rate wanted, Hz")
    p.add_argument("--blur", type=float, default=1.0, help="motion allowed within a sub-frame, pixels (default 1)")
    p.add_argument("--iterations", type=int, default=200)
    p.add_argument("--regularizer", default="tv")
    p.add_argument("--no-measure", action="store_true", help="memory only; do not time 3 iterations")
    add_device_args(p)
    p.set_defaults(func=cmd_plan)
    return p


def cmd_plan(args) -> int:
    """Print the plan of :func:`rsocl.solver.plan.plan`; returns 0."""
    from rsocl.solver.plan import format_plan, plan

    rig = rig_from(args)
    p = plan(rig, roi=args.roi, speed=args.speed, fps=args.fps, blur_pixels=args.blur, iterations=args.iterations,
             regularizer=args.regularizer, dtype=args.dtype, device=args.device, measure=not args.no_measure)
    print(format_plan(p))
    return 0
