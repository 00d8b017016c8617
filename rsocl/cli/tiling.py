"""Tiles, sets, Dask and Zarr for ``rsocl reconstruct`` and ``rsocl plan``: the options and the choice of run.

``rsocl reconstruct`` runs tiled when asked (``--tile``, ``--sets``, ``--scheduler``/``RSOCL_SCHEDULER``,
``--workers``, an ``--out`` ending in ``.zarr``) or when the capture does not fit the device in
one piece (then with the tile ``rsocl plan`` would propose). A tiled run (and a stream of
windows) chooses the unset parameters once for every tile, as ``rsocl.scale.reconstruct_tiled``
does; ``--fixed`` keeps the fixed defaults. ``rsocl plan`` prints a tiling
proposal when the problem does not fit one device, or for ``--tile``.

:mod:`rsocl.cli.tiled_run` runs the reconstruction in tiles or windows and writes its outputs.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from rsocl.cli.tiled_run import is_zarr, run_stream, run_tiles, zarr_gif
from rsocl.files.hdf5_header import HDF5_SUFFIXES

__all__ = [
    "add_reconstruct_tiling_args",
    "check_outputs",
    "reconstruct_tiled_if_needed",
    "add_plan_tiling_args",
    "check_plan_tiling_args",
    "print_plan_tiling",
]


# ---------------------------------------------------------------------- reconstruct
def add_reconstruct_tiling_args(p):
    from rsocl.scale.runner import RETRIES
    from rsocl.scale.tiles import DEFAULT_HALO

    g = p.add_argument_group("tiles, sets and Dask (pip install 'rsocl[dask]' for clusters and Zarr stores)")
    g.add_argument(
        "--tile",
        type=int,
        nargs=2,
        metavar=("H", "W"),
        default=None,
        help="reconstruct in tiles of H x W reference pixels (default: one piece when it fits the "
        "device, else the tile 'rsocl plan' proposes)",
    )
    g.add_argument(
        "--halo",
        type=int,
        default=None,
        help=f"pixels added on every side of a tile, cropped off after, in a run in tiles (or windows in "
        f"tiles) (default {DEFAULT_HALO}, or the grid's larger side where that is smaller)",
    )
    g.add_argument(
        "--sets",
        action="store_true",
        help="reconstruct every set of the capture (snapshot_sets) into a [S, T, m, n] Zarr array",
    )
    g.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run the tiles on a running dask.distributed scheduler (default: RSOCL_SCHEDULER, else "
        "Dask's local scheduler); its workers must see the capture and --out paths",
    )
    g.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="start a local cluster of N worker processes (each its own OpenCL context), 1 to 4 per CPU core",
    )
    g.add_argument(
        "--retries",
        type=int,
        default=None,
        help=f"extra attempts of a failing tile, in a run in tiles or windows (default {RETRIES})",
    )
    g.add_argument(
        "--window",
        type=int,
        default=None,
        metavar="F",
        help="multi-frame capture (frames, t_d): reconstruct it as a stream of windows of F frames",
    )
    g.add_argument(
        "--overlap",
        type=int,
        default=None,
        metavar="V",
        help="with --window: frames shared by consecutive windows (default 1, or 0 with --window 1; 0 "
        "when the readout has gaps)",
    )


def check_outputs(args) -> None:
    """Check ``--out`` (and ``--gif``) before anything is computed; errors name the option. No picture (the
    GIF, the tuning plot beside it) is written over ``--out``, an input or any HDF5 file (a capture)."""
    from rsocl.cli.options import tuning_plot_path
    from rsocl.cli.outputs import HDF5_FILES, refuse_kinds, refuse_same_file
    from rsocl.files.atomic import output_path, same_file

    suffix = Path(str(args.out).rstrip("/")).suffix.lower()
    if suffix not in HDF5_SUFFIXES + (".zarr",) and not Path(args.out).is_dir():  # a folder: said as such below
        raise ValueError(
            f"--out must name an HDF5 file ({', '.join(HDF5_SUFFIXES)}) or a Zarr store (.zarr), got {str(args.out)!r}"
        )
    if args.window is not None and (is_zarr(args.out) or args.sets):
        raise ValueError(
            "--window: a stream of frame windows is written to an HDF5 file (--out NAME.h5), one set at a time"
        )
    if args.window is not None and args.workers is not None:
        raise ValueError(
            "--workers: the windows of --window run one after another in this process (their tiles "
            "on Dask's local scheduler or --scheduler); leave out --workers"
        )
    if args.sets and getattr(args, "first_set_only", False):
        raise ValueError(
            "--sets and --first-set-only contradict each other: --sets reconstructs every set into a "
            "Zarr store, --first-set-only set 0 only; give one of them"
        )
    if is_zarr(args.out) and not args.sets:
        _note_first_set(args, "the store gets set 0 (--sets: every set; --first-set-only says set 0 and silences this)")
    reads = (("capture", args.capture),)
    tuned = not getattr(args, "fast", False)  # the search's plot: NAME-tuning.png
    if is_zarr(args.out):
        from rsocl.scale.store import require_zarr

        require_zarr("--out")
        _check_store(args)
        gif_name = "--gif" if args.gif else "--out's NAME.gif"  # the GIF beside the store, unless --gif names one
        gif = output_path(zarr_gif(args), gif_name, inputs=reads)
        _gif_suffix(gif, args)
        pictures = [(gif_name, gif)]
        if tuned:
            plot_name = "--out's NAME-tuning.png"
            pictures.append((plot_name, output_path(tuning_plot_path(Path(args.out).with_suffix(".gif")), plot_name)))
        refuse_kinds(pictures, HDF5_FILES)  # a picture never replaces a capture, a result or any HDF5 file
        return
    if args.sets:
        raise ValueError(f"--out: every set (--sets) goes to a Zarr store (--out NAME.zarr), got {args.out!r}")
    out = output_path(args.out, "--out", inputs=reads)
    gif = output_path(Path(args.gif) if args.gif else out.with_suffix(".gif"), "--gif", inputs=reads)
    if same_file(gif, out):
        raise ValueError(f"--gif {str(gif)!r} is the --out file; give the GIF another name")
    _gif_suffix(gif, args)
    pictures = [("--gif" if args.gif else "--out's NAME.gif", gif)]
    if tuned:  # next to the GIF
        plot = output_path(tuning_plot_path(gif), "--gif's NAME-tuning.png", inputs=reads)
        if not getattr(args, "fixed", False):  # --fixed: no search, no plot
            words = "the tuning plot of --gif (NAME-tuning.png beside NAME.gif)"
            refuse_same_file("--out", out, [(words, plot)], "choose another --out or --gif")
            pictures.append(("--gif's NAME-tuning.png", plot))
    refuse_kinds(pictures, HDF5_FILES)  # a picture never replaces a capture, a result or any HDF5 file


def _check_store(args) -> None:
    """Refuse an existing ``--out`` that is not an rsocl store, or a store of another rig (row maps
    included), dtype, sets or (with ``--tile``) tiling, naming ``--out``; the capture's rig is read only
    where such a store exists."""
    import numpy as np

    from rsocl.scale.inputs import CaptureSets
    from rsocl.scale.store import KNOWN_FIRST, StoreSpec, check_store, check_store_path
    from rsocl.scale.tiles import TileGrid, check_halo, check_tile

    path = check_store_path(args.out, "--out")
    if not (path.is_dir() and any(path.iterdir())):
        return
    capture = CaptureSets(args.capture, all_sets=args.sets)
    rig = capture.rig
    tiled = args.tile is not None  # else the tile is proposed later, and compared then
    tile = check_tile(args.tile, rig.shape, "--tile") if tiled else rig.shape
    grid = TileGrid(rig.shape, tile, check_halo(args.halo, rig.shape, "--halo"))
    spec = StoreSpec(rig, grid.tile, grid.halo, grid.grid, capture.n_sets, str(np.dtype(args.dtype)), {}, "")
    keys = KNOWN_FIRST if tiled else tuple(k for k in KNOWN_FIRST if k != "tiling")
    check_store(path, spec, "--out", keys)


def _gif_suffix(gif, args) -> None:
    if gif.suffix.lower() != ".gif":
        raise ValueError(f"--gif must name a .gif file (the animation is written as a GIF), got {args.gif!r}")


def _note_first_set(args, what: str) -> None:
    """Say on stderr that a capture of several sets gets only set 0 (``what``), unless ``--first-set-only``."""
    if getattr(args, "first_set_only", False):
        return
    from rsocl.files.hdf5 import snapshot_set_count

    count = snapshot_set_count(args.capture)
    if count > 1:
        print(f"rsocl reconstruct: note: the capture holds {count} sets; {what}", file=sys.stderr, flush=True)


def _wants_tiles(args, capture) -> bool:
    from rsocl.cli.options import regularizer_from
    from rsocl.device.context import get_device
    from rsocl.scale.runner import SCHEDULER_ENV
    from rsocl.solver.memory import device_limit, memory_need

    if (
        args.tile
        or args.sets
        or args.workers is not None
        or args.scheduler
        or os.environ.get(SCHEDULER_ENV)
        or is_zarr(args.out)
    ):
        return True
    largest, total = memory_need(capture.rig, regularizer_from(args), dtype=args.dtype, projection=args.projection)
    return device_limit(get_device(args.device), largest, total) is not None


def _check_applies(args, run: str) -> None:
    """ValueError naming ``--overlap``, ``--halo`` or ``--batch`` when the run (``"window"``: a stream of
    windows, ``"tiles"``, ``"whole"``: in one piece) would ignore it."""
    if args.overlap is not None and run != "window":
        raise ValueError(
            "--overlap applies to --window (the frames consecutive windows share); without --window it would be ignored"
        )
    if args.retries is not None and run == "whole":
        raise ValueError(
            "--retries applies to a run in tiles (--tile H W; also --sets, --workers, --scheduler, a "
            "Zarr --out or a capture too large for the device) or windows (--window), whose tiles run "
            "as tasks; this capture runs in one piece, where --retries would be ignored"
        )
    if args.halo is not None and (run == "whole" or (run == "window" and args.tile is None)):
        where = "this capture runs" if run == "whole" else "without --tile each window of --window runs"
        raise ValueError(
            "--halo applies to a run in tiles (--tile H W; also --sets, --workers, --scheduler, a Zarr "
            "--out or a capture too large for the device) or windows in tiles (--window with --tile); "
            f"{where} in one piece, where --halo would be ignored"
        )
    if args.batch is None:
        return
    if run != "whole":
        how = (
            "--window reconstructs set 0, window by window"
            if run == "window"
            else "a run in tiles runs every tile of every set as a task of its own"
        )
        raise ValueError(
            f"--batch applies to the sets of a capture reconstructed in one piece; {how}, where "
            "--batch would be ignored"
        )
    from rsocl.files.hdf5 import snapshot_set_count

    if args.first_set_only or snapshot_set_count(args.capture) == 1:
        which = "--first-set-only reconstructs set 0 only" if args.first_set_only else "the capture holds one set"
        raise ValueError(
            f"--batch applies to a capture of several sets reconstructed together; {which}, where "
            "--batch would be ignored"
        )


def reconstruct_tiled_if_needed(args):
    """Run ``rsocl reconstruct`` tiled when it should be (see the module); the exit code, or None.

    ``--overlap``, ``--halo`` and ``--batch`` are refused, naming the option, where the run would
    ignore them (:func:`_check_applies`)."""
    from rsocl.scale.inputs import CaptureSets

    capture = CaptureSets(args.capture, all_sets=args.sets)
    if args.window is not None:
        _check_applies(args, "window")
        _note_first_set(args, "--window reconstructs set 0 (--first-set-only says set 0 and silences this)")
        return run_stream(args)
    if not _wants_tiles(args, capture):
        _check_applies(args, "whole")
        return None
    _check_applies(args, "tiles")
    if not is_zarr(args.out):
        _note_first_set(
            args,
            "a tiled run into an HDF5 file reconstructs set 0 (--out NAME.zarr --sets: every "
            "set, in tiles; --first-set-only says set 0 and silences this)",
        )
    return run_tiles(args, capture)


# ---------------------------------------------------------------------- plan
def add_plan_tiling_args(p):
    from rsocl.scale.tiles import DEFAULT_HALO

    g = p.add_argument_group("tiling (proposed when the problem does not fit one device)")
    g.add_argument("--tile", type=int, nargs=2, metavar=("H", "W"), default=None, help="cost this tile instead")
    g.add_argument(
        "--halo",
        type=int,
        default=None,
        help=f"halo, pixels (default {DEFAULT_HALO}, or the grid's larger side where that is smaller)",
    )
    g.add_argument("--sets", type=int, default=1, help="sets to reconstruct (default 1)")
    g.add_argument(
        "--memory-mib",
        type=float,
        default=None,
        help="device memory one task may use, MiB (default: half the device's)",
    )


def check_plan_tiling_args(args, shape) -> None:
    """Check ``rsocl plan``'s ``--tile``, ``--halo``, ``--sets`` and ``--memory-mib`` before anything is
    computed; errors name the option and its allowed range.

    Parameters
    ----------
    args : argparse.Namespace
        The ``plan`` arguments of :func:`add_plan_tiling_args`.
    shape : (int, int)
        Rows and columns of the grid the tiles cover (the ``--roi`` when given), pixels.
    """
    from rsocl.common import validation as check
    from rsocl.scale.tiles import check_halo, check_tile

    if args.tile is not None:
        check_tile(args.tile, shape, "--tile")
    check_halo(args.halo, shape, "--halo")
    check.positive_int("--sets", args.sets)
    if args.memory_mib is not None:
        check.positive("--memory-mib", args.memory_mib, "MiB")


def print_plan_tiling(args, p) -> None:
    """After ``rsocl plan``'s table: the tiling, when the proposal does not fit or ``--tile``, ``--sets``
    or ``--memory-mib`` asks (the arguments checked first by :func:`check_plan_tiling_args`)."""
    from rsocl.cli.options import regularizer_from
    from rsocl.scale.proposal import format_tiling, propose_tiling

    if args.tile is None and p.proposed.fits and args.sets == 1 and args.memory_mib is None:
        return
    budget = None if args.memory_mib is None else int(args.memory_mib * 2**20)
    tiling = propose_tiling(
        p.proposed.rig,
        tile=args.tile,
        halo=args.halo,
        sets=args.sets,
        iterations=args.iterations,
        regularizer=regularizer_from(args),
        dtype=args.dtype,
        device=args.device,
        budget_bytes=budget,
        measure=not args.no_measure,
    )
    print(format_tiling(tiling))
