"""``rsocl reconstruct``: a capture file -> a reconstruction file and a GIF."""

from __future__ import annotations

from pathlib import Path

from rsocl.cli.options import add_device_args, add_solver_args, quality_line, run_reconstruction, say

__all__ = ["add_parser", "cmd_reconstruct"]


def add_parser(subparsers):
    """Add ``reconstruct`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("reconstruct", help="capture file -> reconstruction file and GIF")
    p.add_argument("capture", help="capture file (.h5) from 'rsocl simulate' or 'rsocl capture'")
    p.add_argument("--out", required=True, help="reconstruction file to write (.h5)")
    p.add_argument("--gif", default=None, help="GIF to write (default: next to --out)")
    p.add_argument("--no-truth", action="store_true", help="ignore a ground truth stored in the capture")
    add_solver_args(p)
    add_device_args(p)
    p.set_defaults(func=cmd_reconstruct)
    return p


def cmd_reconstruct(args) -> int:
    """Reconstruct the capture, print the quality line, write ``--out`` and the GIF; returns 0."""
    from rsocl.analysis.visual import comparison_gif
    from rsocl.files.hdf5 import load_capture, save_reconstruction

    capture = load_capture(args.capture)
    truth = capture.truth if not args.no_truth else None
    result = run_reconstruction(args, capture.snapshots, capture.rig, truth)
    print(quality_line(result, truth))
    out = Path(args.out)
    save_reconstruction(out, result.datacube, capture.rig, params=result.params, history=result.history,
                        truth=capture.truth)
    gif = Path(args.gif) if args.gif else out.with_suffix(".gif")
    comparison_gif(gif, truth, result.datacube)
    written = [out, gif]
    if result.params.get("tuning"):
        from rsocl.analysis.tuning_plot import tuning_plot

        chosen = ", ".join(f"{k} = {v:.3g}" for k, v in result.params["tuning"]["chosen"].items())
        say(args, f"chosen from the snapshots: {chosen}")
        written.append(tuning_plot(gif.with_name(gif.stem + "-tuning.png"), result.params["tuning"]))
    say(args, "wrote " + ", ".join(str(p) for p in written))
    return 0
