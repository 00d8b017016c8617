"""Running ``rsocl reconstruct`` in tiles or as a stream of windows, and writing what it made.

:mod:`rsocl.cli.tiling` decides whether a run goes in tiles (:func:`run_tiles`), as a stream of frame
windows (:func:`run_stream`) or in one piece, and checks the options first; the functions here run
the reconstruction through :mod:`rsocl.scale` and write the result (an HDF5 file or a Zarr store),
the comparison GIF and the tuning plots.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from rsocl.cli.outputs import interrupted, kept_note, nothing_written, save_result, written

__all__ = ["is_zarr", "zarr_gif", "run_tiles", "run_stream"]


def is_zarr(path) -> bool:
    """Whether ``path`` names a Zarr store (ends in ``.zarr``)."""
    return str(path).rstrip("/").lower().endswith(".zarr")


def zarr_gif(args) -> Path:
    """The GIF of a Zarr run: ``--gif``, else ``NAME.gif`` next to ``--out NAME.zarr`` (written when the
    capture holds a ground truth, or ``--gif`` asks)."""
    return Path(args.gif) if args.gif else Path(args.out).with_suffix(".gif")


def _retries(args) -> int:
    """``--retries``, or :data:`rsocl.scale.runner.RETRIES` when not given."""
    from rsocl.scale.runner import RETRIES

    return RETRIES if args.retries is None else args.retries


def _error(text: str) -> int:
    """Print ``text`` as ``rsocl reconstruct``'s error; the exit code of a run whose tasks failed (1)."""
    print(f"rsocl reconstruct: error: {text}", file=sys.stderr, flush=True)
    return 1


def _discarded(exc, out, what: str, why: str) -> str:
    """The error of a run into an HDF5 ``out`` whose tasks failed (``exc``, a TilesFailed): what was
    solved and discarded (``what`` adds to it), that nothing was written and ``why``, then the
    failures, one line each."""
    solved = len(exc.result.pieces) + exc.result.skipped
    return (
        f"{len(exc.result.failures)} task(s) failed, {solved} solved and discarded{what}; nothing was written "
        f"to {out} ({why}):\n  " + "\n  ".join(exc.lines)
    )


def run_tiles(args, capture):
    """Reconstruct ``capture`` (a :class:`rsocl.scale.inputs.CaptureSets`) in tiles of ``--tile``, or of
    the tile :func:`rsocl.scale.proposal.propose_tiling` proposes for the device, into ``--out`` (an
    HDF5 file, or a Zarr store of every set with ``--sets``); the exit code (1 when tiles failed). An
    interrupt ends in one line saying what was kept: the tiles in the store, or whether ``--out`` is written."""
    from rsocl.cli.options import regularizer_from, say, solver_options
    from rsocl.scale.proposal import propose_tiling
    from rsocl.scale.tiled import TilesFailed, reconstruct_tiled

    tile = args.tile
    if tile is None:
        tile = propose_tiling(
            capture.rig,
            halo=args.halo,
            regularizer=regularizer_from(args),
            dtype=args.dtype,
            projection=args.projection,
            device=args.device,
            measure=False,
        ).tile
        say(args, f"tiles of {tile[0]} x {tile[1]} pixels (proposed for this device; --tile H W to choose)")
    zarr_out = is_zarr(args.out)
    try:  # Ctrl-C: the store keeps the tiles done; an HDF5 --out is not written
        with interrupted(lambda: _interrupted_tiles(args.out, zarr_out)):
            result = reconstruct_tiled(
                capture,
                capture.rig,
                tile=tile,
                halo=args.halo,
                out=args.out if zarr_out else None,
                scheduler=args.scheduler,
                workers=args.workers,
                retries=_retries(args),
                **solver_options(args),
            )
    except TilesFailed as exc:
        if zarr_out:
            return _error(str(exc))
        store = Path(args.out).with_suffix(".zarr").name
        why = f"an HDF5 --out is written once every task is solved; a Zarr --out, e.g. {store}, keeps solved tiles"
        return _error(_discarded(exc, args.out, "", why + " and a re-run redoes only the failed ones"))
    from rsocl.analysis.visual import comparison_gif
    from rsocl.cli.options import tuning_plot_files

    if zarr_out:  # the store is complete: an interrupt from here on says so
        with written(args.out, []):
            truth, first = _tiles_line(args, capture, result)
            gif = [comparison_gif(zarr_gif(args), truth, first)] if first is not None else []
            plots = tuning_plot_files(args, result.params, Path(args.out).with_suffix(".gif"))
        say(args, "wrote " + ", ".join(map(str, [args.out, *gif, *plots])))
        return 0
    history = {
        "tile_seconds": np.array([p.seconds for p in result.pieces]),
        "tile_residual": np.array([p.residual for p in result.pieces]),
    }
    with interrupted(nothing_written(args.out)):  # until the file is renamed into place, the last step of the save
        truth, _ = _tiles_line(args, capture, result)
        kept = save_result(args.out, result.datacube, capture.rig, params=result.params, history=history, truth=truth)
    gif = Path(args.gif) if args.gif else Path(args.out).with_suffix(".gif")
    with written(args.out, [kept]):
        comparison_gif(gif, truth, result.datacube)
        files = [args.out, gif, *tuning_plot_files(args, result.params, gif)]
    say(args, "wrote " + ", ".join(map(str, files)) + kept_note([kept]))
    return 0


def _tiles_line(args, capture, result) -> tuple:
    """Print the line of :func:`run_tiles`' ``result`` (its tasks, seconds and, with a truth, set 0's
    quality); ``(truth, first)``: set 0's truth (None with ``--no-truth`` or none stored) and set 0's
    datacube in memory, read only where the truth or the store's ``--gif`` needs it (else None)."""
    from rsocl.cli.result_lines import truth_quality

    kept = f", {result.skipped} already in the store" if result.skipped else ""
    text = f"{len(result.pieces)} tile task(s) in {result.seconds:.2f} s{kept}"
    truth = None if args.no_truth else capture.truth()  # set 0's
    # set 0 in memory (from a Zarr store, GiBs) only for what reads it: the truth's PSNR, the store's GIF
    compared = truth is not None or args.gif
    first = np.asarray(result.datacube[0] if args.sets else result.datacube) if compared else None
    if truth is not None:
        text = ("set 0: " if args.sets else "") + f"{truth_quality(first, truth)}, " + text
    print(text, flush=True)
    return truth, first


def _interrupted_tiles(out, zarr_out: bool) -> str:
    """What an interrupted tiled run into ``out`` kept: one clause (an interrupt before the run checked the
    store at ``out`` already says that nothing was computed: :func:`rsocl.scale.reconstruct_tiled`)."""
    if not zarr_out:
        return f"nothing written to {out} (an HDF5 --out is written once every task is solved)"
    from rsocl.scale.store import tiles_done

    counts = tiles_done(out)
    if counts is None:
        return f"no store made at {out}"
    return f"{counts[0]} of {counts[1]} tile task(s) kept in {out}; the same command again redoes only the others"


def _window(rig, failed, args) -> tuple:
    """``(label, before)`` of the window of the stream of ``rig`` whose rig is ``failed``: ``window W/N
    (frames k0..k1-1)`` and the number of windows done before it (None where none matches)."""
    from rsocl.scale.stream import frame_windows

    windows = frame_windows(rig.cameras[0].frames, args.window, args.overlap)
    for w, (k0, k1) in enumerate(windows):
        if rig.frames_window(k0, k1) == failed:
            return f"window {w + 1}/{len(windows)} (frames {k0}..{k1 - 1})", w
    return f"a window of {args.window} frame(s)", None


def run_stream(args):
    """``--window``: set 0 of the capture as a stream of overlapping frame windows, into an HDF5 file;
    the exit code. An interrupt ends in one line saying whether ``--out`` is written and what was kept."""
    from rsocl.analysis.visual import comparison_gif
    from rsocl.cli.options import say, solver_options, tuning_plot_files
    from rsocl.cli.result_lines import truth_quality
    from rsocl.files.hdf5 import load_capture
    from rsocl.scale.stream import default_overlap, reconstruct_stream
    from rsocl.scale.tiled import TilesFailed

    loaded = load_capture(args.capture, set_index=0)
    try:
        with interrupted(nothing_written(args.out)):  # a stream's --out is written once every window is solved
            stream = reconstruct_stream(
                loaded.snapshots,
                loaded.rig,
                window=args.window,
                overlap=args.overlap,
                tile=args.tile,
                halo=args.halo,
                scheduler=args.scheduler,
                retries=_retries(args),
                **solver_options(args),
            )
            truth = None if args.no_truth else loaded.truth
            text = f"{len(stream.windows)} window(s) of {args.window} frame(s)"
            if truth is not None:
                text = f"{truth_quality(stream.datacube, truth)}, " + text
            print(text, flush=True)
    except TilesFailed as exc:
        label, before = _window(loaded.rig, exc.result.rig, args)
        done = f", with the {before} window(s) done before it" if before else ""
        why = "a stream's --out is written once every window is solved"
        return _error(f"{label} failed: " + _discarded(exc, args.out, done, why))
    overlap = default_overlap(args.window) if args.overlap is None else args.overlap
    params = dict(stream.params, window=args.window, overlap=overlap, windows=[list(w) for w in stream.windows])
    with interrupted(nothing_written(args.out)):  # until the file is renamed into place
        kept = save_result(args.out, stream.datacube, loaded.rig, params=params, truth=truth)
    gif = Path(args.gif) if args.gif else Path(args.out).with_suffix(".gif")
    with written(args.out, [kept]):
        comparison_gif(gif, truth, stream.datacube)
        files = [args.out, gif, *tuning_plot_files(args, params, gif)]
    say(args, "wrote " + ", ".join(map(str, files)) + kept_note([kept]))
    return 0
