"""Where a tiled run chooses its parameters: one tile against the centred block of ``TUNE_SIDE`` pixels.

Runner (docs/model.md protocol) through the paper's 4-camera array (t_e = 180 µs, t_r = dt = 35 µs) at
``SIDE x SIDE`` pixels, reconstructed self-tuned at rsocl's defaults, noiseless, three ways (``--runs``):
``untiled`` (``rsocl.reconstruct``); ``block``, in tiles of ``TILE`` pixels (default halo) choosing on
the centred block of :func:`rsocl.scale.tuning_tile.tuning_crop` (``TUNE_SIDE`` pixels a side, the
rule); ``tile``, in the same tiles choosing on the tile nearest the centre (the rule's fallback,
forced). Per run: PSNR in dB (peak 1), the values chosen, the blend and the wall seconds. Prints a
Markdown table and writes it to docs/scale_tuning.md (``--out``) with the provenance header.

    python benchmarks/tiled_tuning.py [--cases 128/64 256/128] [--runs untiled block tile] [--out docs/scale_tuning.md]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import rsocl
from rsocl.analysis.metrics import psnr
from rsocl.model.scenes import load_scene
from rsocl.scale import tuning_tile
from rsocl.scale.tiled import reconstruct_tiled
from rsocl.scale.tiles import tile_grid

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import DOCS, header_lines, write_page  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
RUNS = ("untiled", "block", "tile")
#: The smallest grid side, pixels (the paper array's rig needs a few rows per camera).
MIN_SIDE = 16


def case(text: str) -> tuple:
    """``"SIDE/TILE"`` as ``(side, tile)``: a grid of SIDE x SIDE pixels in tiles of TILE x TILE."""
    side, sep, tile = text.partition("/")
    try:
        value = int(side), int(tile)
    except ValueError:
        value = None
    if not sep or value is None or value[0] < MIN_SIDE or not 1 <= value[1] <= value[0]:
        raise argparse.ArgumentTypeError(
            f"a case is SIDE/TILE pixels with SIDE >= {MIN_SIDE} and 1 <= TILE <= SIDE (e.g. 128/64), got {text!r}"
        )
    return value


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--cases",
        type=case,
        nargs="+",
        default=[(128, 64), (256, 128)],
        metavar="SIDE/TILE",
        help="grids of SIDE x SIDE pixels in tiles of TILE x TILE (default 128/64 256/128)",
    )
    parser.add_argument("--runs", nargs="+", choices=RUNS, default=list(RUNS), help="runs of every case (default all)")
    parser.add_argument("--device", default=None)
    parser.add_argument("--data", type=Path, default=DATA, help="folder of runner40.npz (default ../shared/data)")
    parser.add_argument("--out", type=Path, default=DOCS / "scale_tuning.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if not (args.data / "runner40.npz").is_file():
        parser.error(f"--data: no runner40.npz in {args.data}")
    if not args.out.parent.is_dir():
        parser.error(f"--out: no folder {args.out.parent}")
    return args


def block_label(side: int, tile: int) -> str:
    """The ``block`` run's label: the side of the block the search runs on (``tuning_crop``)."""
    y0, y1, x0, x1 = tuning_tile.tuning_crop(tile_grid((side, side), (tile, tile))).core
    if (y1 - y0, x1 - x0) == (side, side):
        return "centre block (the whole grid)"
    return f"centre block ({y1 - y0}x{x1 - x0})"


def run_case(side, tile, run, args) -> str:
    """One table row: ``run`` of a SIDE x SIDE grid in tiles of ``tile`` pixels."""
    rig = rsocl.Rig.paper_array(4, (side, side), 180e-6, 35e-6)
    truth = load_scene(args.data / "runner40.npz", (side, side), rig.T)
    g = rsocl.RollingShutterOperator(rig, device=args.device).forward(truth)
    crop_block = tuning_tile._crop_block
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if run == "untiled":
                result = rsocl.reconstruct(g, rig, device=args.device)
            else:
                if run == "tile":
                    tuning_tile._crop_block = lambda *a: None  # force the fallback: the tile nearest the centre
                result = reconstruct_tiled(g, rig, tile=(tile, tile), device=args.device)
    finally:
        tuning_tile._crop_block = crop_block
    seconds = time.perf_counter() - start
    chosen = result.params["tuning"]["chosen"]
    label = {"untiled": "untiled", "block": block_label(side, tile), "tile": "one tile"}[run]
    tiles = "-" if run == "untiled" else f"{tile}x{tile}"
    return (
        f"| {side}x{side} | {tiles} | {label} | {psnr(np.asarray(result.datacube), truth):.2f} | "
        f"{chosen.get('lam', float('nan')):.3g} | {chosen.get('temporal_weight', float('nan')):.3g} | "
        f"{result.params.get('blend') or 1:.2f} | {seconds:.1f} |"
    )


def main(argv=None) -> int:
    args = parse_args(argv)
    op = rsocl.RollingShutterOperator(rsocl.Rig.paper_array(4, (16, 16), 180e-6, 35e-6), device=args.device)
    page = header_lines(
        "Where a tiled run chooses its parameters", op.device, None if argv is None else [__file__, *argv]
    )
    page += [
        "Runner (`runner40.npz`, docs/model.md protocol) through the paper's 4-camera array (t_e = 180 µs, "
        't_r = dt = 35 µs), self-tuned runs at rsocl\'s defaults, noiseless. "untiled": `rsocl.reconstruct`; '
        '"centre block": `reconstruct_tiled` choosing on the block of '
        f"`rsocl.scale.tuning_tile.tuning_crop` (`TUNE_SIDE` = {tuning_tile.TUNE_SIDE} pixels a side, or a "
        'tile with its halo where that is larger, within the grid) centred on the grid; "one tile": the same '
        "tiles choosing on the tile nearest the grid's centre (the rule's fallback when the block's search "
        "does not fit the device). Default halo. PSNR in dB, peak 1; seconds are wall time.",
        "",
        "| grid | tiles | run | PSNR | lam | temporal weight | blend | seconds |",
        "|---|---|---|---|---|---|---|---|",
    ]
    print("\n".join(page), flush=True)
    for side, tile in args.cases:
        for run in args.runs:
            page.append(run_case(side, tile, run, args))
            print(page[-1], flush=True)
    write_page(args.out, page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
