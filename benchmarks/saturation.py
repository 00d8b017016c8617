"""Clipped snapshots: the self-tuned default with ``saturation=`` against the same run that ignores the clipping.

A sensor clips at its full well or ADC range: a clipped sample only says that the true value is at
least the level. ``rsocl.reconstruct(..., saturation=level)`` takes those samples one-sided in the
data step (``docs/model.md``, saturated pixels). For every case this script simulates the snapshots,
clips them at a percentile of their values (the level), and reconstructs with the self-tuned default
(200 iterations, float32) three times: the unclipped snapshots (what the clipping costs at best), the
clipped ones as if they were exact, and the clipped ones with ``saturation=level``. PSNR (dB, peak 1)
against the truth.

Cases: the paper array (4 cameras, t_e = 0.18 ms, t_r = 35 µs) at 32x32 and 48x48 on every scene of
``benchmarks/quality_scenes.py`` found here, and random multi-camera rigs of ``benchmarks/tv_step.py``
on the built-in scene; noiseless and with 1000 photo-electrons at full scale plus 1 % read noise
(``quality_scenes.noisy``, seed 1); clipped at the 90th and the 75th percentile. Writes
docs/saturation.md.

    python benchmarks/saturation.py [--sizes 32 48] [--seeds 1 2 3 4 5 6] [--levels 90 75] [--out docs/saturation.md]
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

import rsocl
from rsocl.analysis.metrics import psnr

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import available, case_data, scene_names  # noqa: E402
from tv_step import random_rig  # noqa: E402

#: Noise levels: None (noiseless) or photo-electrons at full scale.
NOISES = (None, 1000.0)
ITERATIONS = 200


def cases(sizes, seeds):
    """``(key, rig, scene, photons)``: the paper array's scenes at each size, then the random rigs of ``seeds``
    (more than one camera) on the built-in scene."""
    for size in sizes:
        rig = rsocl.Rig.paper_array(4, (size, size), t_e=0.18e-3, t_r=35e-6)
        for scene in (s for s in scene_names() if available(s)):
            for photons in NOISES:
                yield f"paper {size}x{size}", rig, scene, photons
    for seed in seeds:
        rig = random_rig(seed)
        if rig.n_channels > 1:
            for photons in NOISES:
                yield f"seed {seed}", rig, "builtin", photons


def run_case(rig, scene, photons, levels, device):
    """PSNR of the unclipped run and, per clip level (a percentile), of the clipped run ignoring the clipping
    and with ``saturation=``; the share of clipped samples."""
    truth, g = case_data(scene, rig, photons)

    def score(snapshots, **kw):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = rsocl.reconstruct(snapshots, rig, iterations=ITERATIONS, device=device, **kw)
        return float(psnr(result.datacube, truth, data_range=1.0))

    out = {"unclipped": score(g)}
    for level in levels:
        cut = float(np.percentile(g, level))
        clipped = np.minimum(g, cut)
        out[level] = {
            "clipped": float(np.mean(g >= cut)),
            "ignored": score(clipped),
            "saturation": score(clipped, saturation=cut),
        }
    return out


def table(results, levels):
    lines = [
        "| case | scene | noise | unclipped | "
        + " | ".join(f"p{v:g}: ignored | p{v:g}: `saturation=` | p{v:g}: gain" for v in levels)
        + " |",
        "|---|---|---|---|" + "---|---|---|" * len(levels),
    ]
    for r in results:
        cells = [f"{r['unclipped']:.2f}"]
        for v in levels:
            c = r[v]
            cells += [f"{c['ignored']:.2f}", f"{c['saturation']:.2f}", f"{c['saturation'] - c['ignored']:+.2f}"]
        noise = "none" if r["photons"] is None else f"{r['photons']:g}"
        lines.append(f"| {r['key']} | {r['scene']} | {noise} | " + " | ".join(cells) + " |")
    return lines


def summary(results, levels):
    lines = [
        "| clip level | cases | gain of `saturation=`: mean | worst | best | cases it loses |",
        "|---|---|---|---|---|---|",
    ]
    for v in levels:
        gain = np.array([r[v]["saturation"] - r[v]["ignored"] for r in results])
        share = np.mean([r[v]["clipped"] for r in results])
        lines.append(
            f"| {v:g}th percentile (on average {100 * share:.0f} % of the samples clipped) | {len(gain)} | "
            f"{gain.mean():+.2f} | {gain.min():+.2f} | {gain.max():+.2f} | {int(np.sum(gain < -0.005))} |"
        )
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 48], help="paper array grids (pixels a side)")
    parser.add_argument("--seeds", type=int, nargs="*", default=[1, 2, 3, 4, 5, 6], help="random rigs (tv_step.py)")
    parser.add_argument("--levels", type=float, nargs="+", default=[90.0, 75.0], help="clip levels, percentiles")
    parser.add_argument("--device", default=None, help="rsocl device spec (default: rsocl's choice)")
    parser.add_argument("--out", default=str(DOCS / "saturation.md"), help="the page to write")
    args = parser.parse_args(argv)
    for v in args.levels:
        if not 0 < v < 100:
            parser.error(f"--levels must lie in (0, 100), got {v:g}")
    device = rsocl.get_device(args.device)
    results = []
    for key, rig, scene, photons in cases(args.sizes, args.seeds):
        r = run_case(rig, scene, photons, args.levels, device)
        results.append({"key": key, "scene": scene, "photons": photons, **r})
        gains = ", ".join(f"p{v:g} {r[v]['saturation'] - r[v]['ignored']:+.2f} dB" for v in args.levels)
        print(f"{key} {scene} noise={photons}: unclipped {r['unclipped']:.2f} dB; {gains}", flush=True)
    title = "Clipped snapshots: `saturation=` against ignoring the clipping"
    lines = header_lines(title, device, None if argv is None else [__file__, *argv])
    lines += [
        "",
        __doc__.split("\n\n")[1].replace("\n", " "),
        "",
        "## Summary",
        "",
        *summary(results, args.levels),
        "",
        "## Every case (PSNR, dB)",
        "",
        *table(results, args.levels),
        "",
    ]
    write_page(args.out, lines)


if __name__ == "__main__":
    main()
