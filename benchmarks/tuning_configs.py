"""The self-tuned default against the fixed defaults and interp3d, over camera counts and grid shapes.

``benchmarks/quality.py`` measures the self-tuning on the paper's 4-camera array at 64x64 and
128x128 over scenes; this script varies the rig instead: the built-in scene (no shared data
needed) on paper arrays of 2, 3, 4, 6 and 8 cameras and grids of 16x16, 24x40 and 48x32 pixels,
noiseless and with Poisson noise (1000 photo-electrons at full scale). PSNR in dB (peak 1) of
``interp3d``, of ``rsocl.reconstruct(..., tune=False)`` (fixed defaults: temporal weight 3,
``lam`` 0.1) and of the default ``rsocl.reconstruct`` (self-tuned), with the values it chose.
Writes ``docs/tuning_configs.md``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from provenance import DOCS, header_lines, write_page  # noqa: E402

CAMERAS = (2, 3, 4, 6, 8)
SHAPES = ((16, 16), (24, 40), (48, 32))
NOISE = ("none", "poisson")


def case(cameras, shape, noise, iterations, device):
    """``(T, interp3d, fixed, tuned, chosen)`` for one rig and noise level (PSNR in dB)."""
    import rsocl
    from rsocl.analysis.metrics import psnr
    from rsocl.model.interpolation import interp3d
    from rsocl.model.scenes import builtin_scene
    from rsocl.model.simulate import simulate

    rig = rsocl.Rig.paper_array(cameras, shape, t_e=0.18e-3, t_r=35e-6)
    truth = builtin_scene(rig.shape, rig.T)
    g = simulate(truth, rig) if noise == "none" else simulate(truth, rig, noise="poisson", photons=1000)
    fixed = rsocl.reconstruct(g, rig, iterations=iterations, tune=False, device=device)
    tuned = rsocl.reconstruct(g, rig, iterations=iterations, device=device)
    return (
        rig.T,
        psnr(interp3d(g, rig), truth),
        psnr(fixed.datacube, truth),
        psnr(tuned.datacube, truth),
        tuned.params["tuning"]["chosen"],
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=100, help="ADMM iterations per run (>= 10)")
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", type=Path, default=DOCS / "tuning_configs.md")
    args = parser.parse_args(argv)
    if args.iterations < 10:
        raise SystemExit("--iterations must be >= 10")
    import rsocl

    device = rsocl.device.get_device(args.device)
    page = header_lines(
        "Self-tuning across camera counts and grid shapes", device, None if argv is None else [__file__, *argv]
    )
    page += [
        __doc__.split("\n\n", 1)[1].strip(),
        "",
        f"{args.iterations} ADMM iterations, float32, t_e = 180 µs, t_r = 35 µs.",
        "",
        "| cameras | grid | T | noise | interp3d | fixed | tuned | tuned - fixed | tuned - interp3d "
        "| chosen weight, lam |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    to_fixed, to_interp = [], []
    for cameras in CAMERAS:
        for shape in SHAPES:
            for noise in NOISE:
                T, base, fixed, tuned, chosen = case(cameras, shape, noise, args.iterations, device)
                to_fixed.append(tuned - fixed)
                to_interp.append(tuned - base)
                line = (
                    f"| {cameras} | {shape[0]}x{shape[1]} | {T} | {noise} | {base:.2f} | {fixed:.2f} | {tuned:.2f} | "
                    f"{tuned - fixed:+.2f} | {tuned - base:+.2f} | "
                    f"{chosen.get('temporal_weight', float('nan')):.3g}, {chosen['lam']:.3g} |"
                )
                page.append(line)
                print(line, flush=True)
    to_fixed, to_interp = np.array(to_fixed), np.array(to_interp)
    page += [
        "",
        f"Over {len(to_fixed)} cases: tuned - fixed from {to_fixed.min():+.2f} to {to_fixed.max():+.2f} dB "
        f"(mean {to_fixed.mean():+.2f} dB; more than 0.3 dB below fixed in {int((to_fixed < -0.3).sum())}); "
        f"tuned - interp3d from {to_interp.min():+.2f} to {to_interp.max():+.2f} dB.",
    ]
    write_page(args.out, page)


if __name__ == "__main__":
    main()
