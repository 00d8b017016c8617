"""``rsocl demo``: simulate the paper's array on the built-in scene, reconstruct it, write files and pictures."""

from __future__ import annotations

from rsocl.cli.options import (
    add_device_args,
    add_rig_args,
    add_solver_args,
    check_datacube_memory,
    rig_from,
    run_reconstruction,
    say,
    tuning_plot_files,
)
from rsocl.cli.result_lines import quality_line

__all__ = ["add_parser", "cmd_demo", "FILES"]


def add_parser(subparsers):
    """Add ``demo`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("demo", help="simulate the paper's array on the built-in scene and reconstruct it")
    add_rig_args(p)
    add_solver_args(p)
    add_device_args(p)
    p.add_argument(
        "--out",
        default="rsocl-demo",
        help="output folder (default ./rsocl-demo); an earlier demo.h5 there is kept as demo.earlier-<UTC time>.h5, "
        "a capture at one of the names written is refused",
    )
    p.set_defaults(func=cmd_demo)
    return p


#: The files ``rsocl demo`` writes into ``--out`` (``demo-tuning.png`` after a parameter search).
FILES = ("demo.h5", "demo.gif", "snapshots.png", "subframes.png", "demo-tuning.png")


def cmd_demo(args) -> int:
    """Write ``demo.h5``, ``demo.gif``, ``snapshots.png``, ``subframes.png`` and (unless ``--fixed``)
    ``demo-tuning.png``, the parameter search, to ``--out``; returns 0.

    A capture at one of these names is refused before any work; an earlier ``demo.h5`` is kept as
    ``demo.earlier-<UTC time>.h5`` (:func:`rsocl.cli.outputs.save_result`). An interrupt (Ctrl-C, SIGTERM)
    ends in one line saying whether ``demo.h5`` was written and what was kept."""
    from rsocl.analysis.visual import comparison_gif, datacube_montage, snapshot_montage
    from rsocl.cli.outputs import interrupted, kept_note, nothing_written, refuse_kinds, save_result, written
    from rsocl.files.atomic import output_folder
    from rsocl.model.operator import RollingShutterOperator
    from rsocl.model.scenes import builtin_scene

    out = output_folder(args.out, "--out")
    refuse_kinds(("--out", out / name) for name in FILES)
    rig = rig_from(args)
    check_datacube_memory(rig)
    out.mkdir(parents=True, exist_ok=True)
    result_file = out / "demo.h5"
    with interrupted(nothing_written(result_file)):
        truth = builtin_scene(rig.shape, rig.T)
        op = RollingShutterOperator(rig, device=args.device, dtype=args.dtype)
        g = op.forward(truth)
        say(
            args,
            f"rig: {rig!r}\ndevice: {op.device.name}\ncompression: {rig.T} sub-frames from "
            f"{rig.n_channels} snapshots (CR {rig.compression_ratio:.1f}x)",
        )
        result = run_reconstruction(args, g, rig, truth)
        print(quality_line(result, truth))
    kept = save_result(result_file, result.datacube, rig, params=result.params, history=result.history, truth=truth)
    with written(result_file, [kept]):
        files = [
            result_file,
            comparison_gif(out / "demo.gif", truth, result.datacube),
            snapshot_montage(out / "snapshots.png", g, rig=rig),
            datacube_montage(out / "subframes.png", result.datacube, truth=truth),
        ]
        files += tuning_plot_files(args, result.params, out / "demo.gif")  # demo-tuning.png, after a search
    say(args, "wrote " + ", ".join(str(f) for f in files) + kept_note([kept]))
    return 0
