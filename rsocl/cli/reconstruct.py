"""``rsocl reconstruct``: a capture file -> a reconstruction file and a GIF (one file per set of a
multi-set capture, the sets in batches sized to the device), or tiles (and sets) on Dask into a
Zarr store (:mod:`rsocl.cli.tiling`)."""

from __future__ import annotations

from pathlib import Path

from rsocl.cli.options import (
    add_device_args,
    add_solver_args,
    run_reconstruction,
    say,
    solver_options,
    tuning_plot_files,
)
from rsocl.cli.outputs import interrupted, kept_clause, kept_note, nothing_written, save_result, written
from rsocl.cli.result_lines import quality_line
from rsocl.cli.tiling import add_reconstruct_tiling_args, check_outputs, reconstruct_tiled_if_needed

__all__ = ["add_parser", "cmd_reconstruct", "set_path", "check_set_outputs"]


def add_parser(subparsers):
    """Add ``reconstruct`` to the ``rsocl`` sub-parsers; returns its parser."""
    p = subparsers.add_parser("reconstruct", help="capture file -> reconstruction file and GIF")
    p.add_argument("capture", help="capture file (.h5) from 'rsocl simulate' or 'rsocl capture'")
    p.add_argument(
        "--out",
        required=True,
        help="reconstruction file to write (.h5; a capture of several sets writes one per set, "
        "OUT with '-setNNN' before the suffix; a file already there is kept as STEM.earlier-<UTC time>.h5), "
        "or a Zarr store (.zarr)",
    )
    p.add_argument("--gif", default=None, help="GIF to write (default: next to an .h5 --out; of set 0)")
    p.add_argument(
        "--no-truth",
        action="store_true",
        help="ignore a ground truth stored in the capture: no PSNR/SSIM, none in the output",
    )
    p.add_argument("--first-set-only", action="store_true", help="of a capture of several sets, set 0 only")
    p.add_argument(
        "--batch",
        type=int,
        default=None,
        help="sets of a capture of several sets, reconstructed in one piece, run together in one batch "
        "(default: as many as fit the device: up to 32 on a CPU, up to 2**24 voxels on a GPU)",
    )
    add_solver_args(p)
    add_device_args(p)
    add_reconstruct_tiling_args(p)
    p.set_defaults(func=cmd_reconstruct)
    return p


def set_path(out: Path, index: int) -> Path:
    """The reconstruction file of set ``index`` of a multi-set capture: ``out`` with ``-setNNN`` before the suffix."""
    return out.with_name(f"{out.stem}-set{index:03d}{out.suffix}")


def check_set_outputs(args) -> None:
    """Refuse, naming ``--out``, an HDF5 ``--out`` whose files (``--out`` itself and, for a capture of
    several sets, every :func:`set_path`) would replace the capture the run reads (the same path, a
    link or a hard link to it) or any other capture file, before anything is computed."""
    from rsocl.files.atomic import output_path
    from rsocl.files.hdf5 import snapshot_set_count

    capture = Path(args.capture)
    if str(args.out).rstrip("/").lower().endswith(".zarr") or not capture.is_file():
        return  # a store is a folder; a missing capture is named on loading
    out = Path(args.out)
    paths = [("--out", out)]
    if not (args.first_set_only or args.window is not None):
        count = snapshot_set_count(capture)
        if count > 1:
            paths += [(f"--out's set {i} file (of {count} sets)", set_path(out, i)) for i in range(count)]
    for name, path in paths:
        output_path(path, name, inputs=(("capture", capture),))
        if _is_capture(path):
            raise ValueError(
                f"{name} {str(path)!r} is a capture file; a reconstruction never replaces a capture: "
                "choose another --out"
            )


def _is_capture(path: Path) -> bool:
    """Whether ``path`` is an existing rsocl capture file (HDF5, ``rsocl_file = "capture"``)."""
    if not path.is_file():
        return False
    import h5py

    try:
        if not h5py.is_hdf5(path):
            return False
        with h5py.File(path, "r") as h5:
            kind = h5.attrs.get("rsocl_file")
    except OSError:
        return False
    return (kind.decode() if isinstance(kind, bytes) else kind) == "capture"


def cmd_reconstruct(args) -> int:
    """Reconstruct the capture (every set of a multi-set capture, in batches sized to the device), print the
    quality line of each set, write the reconstruction file(s) and the GIF; returns 0.

    The capture's ground truth (set 0's datacube), unless ``--no-truth``, gives the PSNR/SSIM and
    is copied into the reconstruction file (of set 0); with ``--no-truth`` it is neither.

    The output paths are checked first (:func:`check_set_outputs`: no file written replaces the capture,
    or another capture); tiles (and sets) run on Dask when asked or needed.
    """
    from rsocl.analysis.visual import comparison_gif
    from rsocl.files.hdf5 import load_capture, load_snapshot_sets

    if args.batch is not None and args.batch < 1:  # before anything runs, whatever the capture holds
        raise ValueError(f"--batch must be >= 1 (sets per batch), got {args.batch}")
    out = Path(args.out)
    with interrupted(nothing_written(out)):
        check_outputs(args)
        check_set_outputs(args)
    code = reconstruct_tiled_if_needed(args)  # says itself what an interrupt kept
    if code is not None:
        return code

    with interrupted(nothing_written(out)):
        capture = load_capture(args.capture, set_index=0)  # every set: load_snapshot_sets
        sets = None if args.first_set_only else load_snapshot_sets(args.capture)
    truth = capture.truth if not args.no_truth else None
    gif = Path(args.gif) if args.gif else out.with_suffix(".gif")
    if sets is None or sets.shape[0] == 1:
        with interrupted(nothing_written(out)):  # until the file is renamed into place, the last step of the save
            result = run_reconstruction(args, capture.snapshots, capture.rig, truth)
            print(quality_line(result, truth))
            kept = save_result(
                out, result.datacube, capture.rig, params=result.params, history=result.history, truth=truth
            )
        with written(out, [kept]):
            comparison_gif(gif, truth, result.datacube)
            files = [out, gif, *tuning_plot_files(args, result.params, gif)]
        say(args, "wrote " + ", ".join(str(p) for p in files) + kept_note([kept]))
        return 0
    with interrupted("nothing written, the files already there are unchanged"):
        batch = _reconstruct_sets(args, sets, capture.rig)
    say(args, f"{sets.shape[0]} sets in batches of {batch.params['batch']}")
    earlier: list = []
    with interrupted(lambda: _sets_written(out, len(earlier), batch.batch) + kept_clause(earlier)):
        _write_sets(args, batch, capture.rig, truth, out, earlier)
    with written(f"{set_path(out, 0)} .. {set_path(out, batch.batch - 1)}", earlier):
        comparison_gif(gif, truth, batch.set(0).datacube)
        plots = tuning_plot_files(args, batch.set(0).params, gif)
    pictures = ", ".join(map(str, [gif, *plots]))
    say(args, f"wrote {set_path(out, 0)} .. {set_path(out, batch.batch - 1)}, {pictures}" + kept_note(earlier))
    return 0


def _write_sets(args, batch, rig, truth, out, earlier):
    """Write each set's reconstruction file, printing its quality line; ``earlier`` collects the kept files."""
    from rsocl.files.atomic import OutputError

    for i in range(batch.batch):
        one = batch.set(i)
        known = truth if i == 0 else None  # the capture's truth is set 0's datacube
        print(f"set {i}: " + quality_line(one, known))
        try:
            earlier.append(
                save_result(set_path(out, i), one.datacube, rig, params=one.params, history=one.history, truth=known)
            )
        except OutputError as exc:  # a full disk: say which sets are on it
            if i:
                exc.strerror = f"{exc.strerror}; sets 0 to {i - 1} are written ({set_path(out, 0)} ..)"
                exc.strerror += kept_clause(earlier)
            raise


def _sets_written(out, written: int, sets: int) -> str:
    """What an interrupted write of ``sets`` set files kept, ``written`` of them done: one clause."""
    rest = [set_path(out, i) for i in range(written, sets)]
    older = [p for p in rest if p.exists()]
    done = f"sets 0 to {written - 1} written ({set_path(out, 0)} ..)" if written else "no set written"
    if not older:
        return done
    return f"{done}; {len(older)} of the files of sets {written} to {sets - 1} are an earlier run's ({older[0]} ..)"


def _reconstruct_sets(args, sets, rig):
    """:func:`rsocl.solver.sets.reconstruct_sets` of every set with the solver and device arguments."""
    from rsocl.solver.sets import reconstruct_sets

    return reconstruct_sets(sets, rig, batch=args.batch, **solver_options(args))
