"""``rsocl bench``: sweep settings around a default point; PSNR/SSIM against seconds and memory, as files."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_parser", "default_point", "check_sweeps", "cmd_bench"]


def add_parser(subparsers):
    """Add ``bench`` to the ``rsocl`` sub-parsers; returns its parser."""
    from rsocl.bench.run import QUICK, SWEEPS

    p = subparsers.add_parser(
        "bench",
        help="sweep settings on a scene: PSNR/SSIM against seconds and memory; CSV, Markdown, plots",
        description="Measure what each setting buys: sweeps one knob at a time around a default point "
        "(4 cameras, 64x64, 200 ADMM-TV iterations with 10 inner, float32, dt = t_r, fixed settings as "
        "rsocl reconstruct --fixed; the sweep tune adds the self-tuned default), with a "
        "3-D interpolation baseline; writes bench.csv, iterations.csv, bench.md, pareto.png, "
        "cameras.png and iterations.png.",
    )
    p.add_argument(
        "--scene",
        default="builtin",
        help="'builtin' or a video file of 2 frames or more (.npz key 'video', .tif, .gif)",
    )
    p.add_argument(
        "--sweep",
        action="append",
        default=None,
        metavar="NAME[=V1,V2,...]",
        help=f"sweep to run, repeatable: {', '.join(SWEEPS)} (default: all; --quick: {', '.join(QUICK)})",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="32x32, 100 iterations, fewer values: 4-15 s on 2 CPU cores (15 s with the kernels to build)",
    )
    p.add_argument("--out", default="rsocl-bench", help="output folder (default ./rsocl-bench)")
    p.add_argument("--device", default=None, help="OpenCL device for every point but the device sweep")
    p.add_argument("--t-e-us", type=float, default=180.0, help="exposure time, µs, > 0 (default 180)")
    p.add_argument("--t-r-us", type=float, default=35.0, help="row readout time, µs, > 0 (default 35)")
    p.add_argument("--lam", type=float, default=None, help="regularization weight, >= 0 (default rsocl's)")
    p.add_argument("--eta", type=float, default=None, help="ADMM penalty, >= 0; 0 runs GAP (default rsocl's)")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no table, only the result line")
    # testing and tuning knobs: the default point's grid side, cameras and iterations
    p.add_argument("--shape", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--cameras", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--iterations", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--tv-iterations", type=int, default=None, help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_bench)
    return p


def default_point(args):
    """The default :class:`~rsocl.bench.point.BenchPoint` of a ``rsocl bench`` command line.

    Raises
    ------
    ValueError
        Naming the option (``--lam``, ``--t-r-us``, ...) and its allowed range, before anything runs.
    FileNotFoundError
        When ``--scene`` names no file (a ValueError names a file that is no readable video, one of
        a single frame, a still image, and one holding NaN or inf).
    """
    from rsocl.bench.point import US, BenchPoint
    from rsocl.bench.run import canonical_device
    from rsocl.cli.options import check_datacube_memory, check_rig_memory
    from rsocl.common import validation as check
    from rsocl.model.plausible import check_window_us
    from rsocl.solver.problem import DEFAULTS, MAX_ITERATIONS

    scene = args.scene
    if scene != "builtin":
        if not Path(scene).exists():
            raise FileNotFoundError(f"--scene: video file {scene!r} does not exist")
        from rsocl.model.video import load_video

        video = load_video(scene)  # an unreadable file is named here, before any point runs
        if video.shape[0] < 2:  # a still image: every sub-frame the same, PSNRs infinite
            raise ValueError(
                f"--scene {scene!r} holds {video.shape[0]} frame; rsocl bench needs a video of at least 2 frames"
            )
        check.finite_array(f"--scene {scene!r}", video)
    quick = bool(args.quick)
    for option, value, maximum in (
        ("--cameras", args.cameras, 8),
        ("--shape", args.shape, None),
        ("--iterations", args.iterations, MAX_ITERATIONS),
        ("--tv-iterations", args.tv_iterations, None),
    ):
        if value is not None:
            check.positive_int(option, value, maximum=maximum)
    if args.lam is not None:
        check.non_negative("--lam", args.lam)
    if args.eta is not None:
        check.non_negative("--eta", args.eta, "(0 runs GAP)")
    check_window_us(check.positive("--t-e-us", args.t_e_us, "µs"), check.positive("--t-r-us", args.t_r_us, "µs"))

    def pick(value, fallback):
        return fallback if value is None else value

    point = BenchPoint(
        scene=scene,
        cameras=pick(args.cameras, 4),
        shape=pick(args.shape, 32 if quick else 64),
        iterations=pick(args.iterations, 100 if quick else DEFAULTS["iterations"]),
        tv_iterations=pick(args.tv_iterations, DEFAULTS["tv_iterations"]),
        device=canonical_device(args.device),
        lam=args.lam,
        eta=args.eta,
        t_e=args.t_e_us * US,
        t_r=args.t_r_us * US,
    )
    side = point.shape  # the default point's rig and datacube must fit this machine first
    check_rig_memory(point.cameras, (side, side), f"--shape {side}", "choose a smaller --shape")
    check_datacube_memory(point.rig(), f"--shape {side}", "choose a smaller --shape")
    return point


def check_sweeps(default, sweeps) -> None:
    """Refuse a ``--sweep NAME=V1,V2`` value that makes no point around ``default`` (a ROI above
    ``--shape``, ``cameras`` outside 1..8, an unknown regularizer or device, ...), naming it, before
    anything runs. Sweeps without values take the built-in ones, which :func:`run_bench` may skip."""
    from rsocl.bench.run import sweep_point

    for name, values in sweeps or ():
        for value in values or ():
            try:
                sweep_point(default, name, value)
            except Exception as exc:  # noqa: BLE001 - a range check, the registry or the device lookup
                raise ValueError(f"--sweep {name}={value}: {exc}") from None


def cmd_bench(args) -> int:
    """Run the sweeps and write the files; returns 0, or 1 when no reconstruction point could be
    measured (the reasons on stderr, no file written).

    The options, the ``--out`` folder and the sweep values given are checked first (a ValueError
    naming the option). An interrupt (Ctrl-C, SIGTERM) ends the sweeps: the files are written with
    the points measured before it (none where no reconstruction point was), and the interrupt is
    raised again with a message saying what was written.
    """
    from rsocl.bench.point import seconds_text
    from rsocl.bench.report import _num
    from rsocl.bench.run import markdown, parse_sweep, picks, run_bench, write_outputs
    from rsocl.cli.outputs import kept_clause, kept_note, nothing_written
    from rsocl.files.atomic import output_folder

    output_folder(args.out, "--out")
    default = default_point(args)
    sweeps = None if not args.sweep else [parse_sweep(s) for s in args.sweep]
    check_sweeps(default, sweeps)
    result = run_bench(default, sweeps, quick=args.quick, progress=not args.quiet, keep_on_interrupt=True)
    measured = any(not row["_point"].is_baseline for row in result.rows)
    kept: list = []
    if result.interrupted is not None:
        stop = type(result.interrupted)
        if not measured:
            raise stop(f"no reconstruction point measured, {nothing_written(args.out)}")
        files = write_outputs(result, args.out, kept)
        raise stop(
            f"written with the points measured before it ({len(result.rows)}): "
            + ", ".join(str(f) for f in files)
            + kept_clause(kept)
        )
    if not measured:
        print("rsocl bench: error: no reconstruction point could be measured, nothing written:", file=sys.stderr)
        for note in result.notes:
            print(f"  {note}", file=sys.stderr)
        return 1
    files = write_outputs(result, args.out, kept)
    if not args.quiet:
        print(markdown(result))
        print("wrote " + ", ".join(str(f) for f in files) + kept_note(kept))
    else:
        speed, quality = picks(result)
        text = (
            f"{len(result.rows)} points in {result.seconds:.0f} s; wrote {Path(args.out) / 'bench.md'}{kept_note(kept)}"
        )
        if quality is not None:
            text += (
                f"; quality: {quality['label']} {_num(quality['psnr'], '.2f')} dB; "
                f"speed: {speed['label']} {_num(speed['psnr'], '.2f')} dB in {seconds_text(speed['seconds'])} s"
            )
        print(text)
        for note in result.notes:  # the table, which lists them, is not printed
            print(f"rsocl bench: note: {note}", file=sys.stderr)
    return 0
