"""Where a tiled run chooses its parameters: one tile against the centred block of ``TUNE_SIDE`` pixels.

Runner (docs/model.md protocol) through the paper's 4-camera array (t_e = 180 µs, t_r = dt = 35 µs) at
``SIDE x SIDE`` pixels, reconstructed self-tuned (200 iterations) three ways: untiled
(``rsocl.reconstruct``), in tiles of ``TILE`` pixels choosing on the centred block
(``rsocl.scale.tuning_tile.TUNE_SIDE``, the rule), and in the same tiles choosing on the tile nearest
the centre (the rule's fallback, forced). Prints one line per run: PSNR in dB (peak 1), the values
chosen, the blend and the seconds.

    python benchmarks/tiled_tuning.py SIDE TILE [untiled] [block] [tile]
"""

from __future__ import annotations

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

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    side, tile, runs = int(argv[0]), int(argv[1]), argv[2:] or ["untiled", "block", "tile"]
    rig = rsocl.Rig.paper_array(4, (side, side), 180e-6, 35e-6)
    truth = load_scene(DATA / "runner40.npz", (side, side), rig.T)
    g = rsocl.RollingShutterOperator(rig).forward(truth)
    crop_block = tuning_tile._crop_block
    for run in runs:
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if run == "untiled":
                result = rsocl.reconstruct(g, rig)
            else:
                tuning_tile._crop_block = crop_block if run == "block" else (lambda *args: None)
                result = reconstruct_tiled(g, rig, tile=(tile, tile))
        chosen = {k: round(v, 3) for k, v in result.params["tuning"]["chosen"].items()}
        print(
            f"{run} {side}x{side} tile {tile}: PSNR {psnr(np.asarray(result.datacube), truth):.2f} dB, chosen "
            f"{chosen}, blend {result.params.get('blend') or 1:.3f}, {time.perf_counter() - start:.1f} s",
            flush=True,
        )
    tuning_tile._crop_block = crop_block
    return 0


if __name__ == "__main__":
    sys.exit(main())
