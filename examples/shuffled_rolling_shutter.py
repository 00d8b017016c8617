"""Reconstruct the real shuffled rolling-shutter capture (wine) with an explicit exposure map.

The capture (../shared/data/wine_shuffled_rs_real.npz) is ONE 256x256 measurement in which
each pixel was exposed in exactly one of 256 time steps (``*_time_index``). rsocl models it
as a single camera whose per-pixel exposure-start map, in units of its row time t_r, is the
time index, with t_e = t_r; ``dt = bin * t_r`` groups the 256 steps into 256/bin sub-frames.
There is no ground truth, so the script writes a montage and a GIF to look at.

    python examples/shuffled_rolling_shutter.py [--pattern opt|rnd] [--bin 16] [--out wine]
"""

import argparse
import sys
from pathlib import Path

import numpy as np

import rsocl
from rsocl.analysis.visual import comparison_gif, datacube_montage

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "wine_shuffled_rs_real.npz"


def load_capture(path, pattern):
    """``(measurement, time index)`` of ``pattern`` in the capture at ``path``, float64; a missing or
    unreadable file ends the script with one line saying where the capture is expected."""
    path = Path(path)
    if not path.is_file():
        sys.exit(
            f"shuffled_rolling_shutter: error: --data: no capture at {path}; it is expected at {DATA} (the "
            "shared data folder beside the repository): pass its path with --data PATH"
        )
    keys = (f"meas_{pattern}", f"{pattern}_time_index")
    try:
        with np.load(path) as data:
            return tuple(data[key].astype(np.float64) for key in keys)
    except (OSError, ValueError, KeyError) as exc:
        sys.exit(
            f"shuffled_rolling_shutter: error: --data: {path} is not the shuffled rolling-shutter capture "
            f"(an .npz with arrays {list(keys)}): {type(exc).__name__}: {exc}"
        )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pattern", choices=["opt", "rnd"], default="opt")
    parser.add_argument("--bin", type=int, default=16, help="time steps per sub-frame")
    parser.add_argument("--iterations", type=int, default=200)
    # psi = (t_e/dt)^2 = 1/256 here, far below the [0, 1]-scene defaults' scale: eta and lam follow it
    parser.add_argument("--lam", type=float, default=1e-4)
    parser.add_argument("--eta", type=float, default=1e-3)
    parser.add_argument(
        "--temporal-weight",
        type=float,
        default=1.0,
        help="TV temporal weight (1: fast events such as this pour; rsocl's default is 3)",
    )
    parser.add_argument("--out", default="wine")
    parser.add_argument(
        "--data", default=str(DATA), help=f"the capture (default {DATA}: the shared data folder beside the repository)"
    )
    args = parser.parse_args()

    meas, index = load_capture(args.data, args.pattern)
    t_r = 1e-4  # arbitrary: only ratios matter for the reconstruction
    camera = rsocl.Camera(t_e=t_r, t_r=t_r, row_map=index)
    rig = rsocl.Rig([camera], meas.shape, dt=args.bin * t_r)
    # a scene in [0, 1] gives snapshots in [0, t_e/dt]: scale the 16-bit measurement to that
    g = (meas / meas.max() * rig.exposure_subframes)[None]
    print(f"{rig!r}: {rig.T} sub-frames of {args.bin} time steps from one measurement")
    result = rsocl.reconstruct(
        g,
        rig,
        iterations=args.iterations,
        lam=args.lam,
        eta=args.eta,
        progress=True,
        regularizer_options={"temporal_weight": args.temporal_weight},
    )
    print(
        f"residual {result.history['residual'][-1]:.4f} after {result.iterations} iterations, "
        f"{result.history['time'][-1]:.1f} s"
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    # left: what a global-shutter camera would see (the measurement spread evenly in time)
    still = np.broadcast_to(g[0] / rig.exposure_subframes, result.datacube.shape)
    comparison_gif(out / f"wine_{args.pattern}.gif", still, result.datacube, fps=4, scale=1)
    datacube_montage(out / f"wine_{args.pattern}.png", result.datacube, max_columns=8)
    print(f"wrote {out}/wine_{args.pattern}.gif and .png")


if __name__ == "__main__":
    main()
