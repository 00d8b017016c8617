"""``rsocl demo``: simulate the paper's array on the built-in scene, reconstruct it, write files and pictures."""

from __future__ import annotations

from rsocl.cli.options import (
    add_device_args,
    add_rig_args,
    add_solver_args,
    check_datacube_memory,
    quality_line,
    rig_from,
    run_reconstruction,
    say,
    tuning_plot_files,
)

__all__ = ["add_parser", "cmd_demo"]


def add_parser(subparsers):
    """Add ``demo`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("demo", help="simulate the paper's array on the built-in scene and reconstruct it")
    add_rig_args(p)
    add_solver_args(p)
    add_device_args(p)
    p.add_argument("--out", default="rsocl-demo", help="output folder (default ./rsocl-demo)")
    p.set_defaults(func=cmd_demo)
    return p


def cmd_demo(args) -> int:
    """Write ``demo.h5``, ``demo.gif``, ``snapshots.png``, ``subframes.png`` and (unless ``--fixed``)
    ``demo-tuning.png``, the parameter search, to ``--out``; returns 0."""
    from rsocl.analysis.visual import comparison_gif, datacube_montage, snapshot_montage
    from rsocl.files.atomic import output_folder
    from rsocl.files.hdf5 import save_reconstruction
    from rsocl.model.operator import RollingShutterOperator
    from rsocl.model.scenes import builtin_scene

    out = output_folder(args.out, "--out")
    rig = rig_from(args)
    check_datacube_memory(rig)
    out.mkdir(parents=True, exist_ok=True)
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
    files = [
        save_reconstruction(
            out / "demo.h5", result.datacube, rig, params=result.params, history=result.history, truth=truth
        ),
        comparison_gif(out / "demo.gif", truth, result.datacube),
        snapshot_montage(out / "snapshots.png", g, rig=rig),
        datacube_montage(out / "subframes.png", result.datacube, truth=truth),
    ]
    files += tuning_plot_files(args, result.params, out / "demo.gif")  # demo-tuning.png, after a search
    say(args, "wrote " + ", ".join(str(f) for f in files))
    return 0
