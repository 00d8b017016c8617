"""The self-tuned blend with the interpolation: PSNR with it, without it and of interp3d alone.

``rsocl.reconstruct``'s search also chooses ``blend`` in [0, 1] (``rsocl.solver.crossval``): the run
returns ``x0 + blend (theta - x0)``, ``x0`` its interp3d start. For every case this script runs the
self-tuned default (200 iterations, float32), the same choice with ``blend=1`` (the solver's own
result, no search: the recorded Tuning again) and ``interp3d``, and reports PSNR (dB, peak 1).

Cases: multi-camera rigs from ``benchmarks/tv_step.py``'s random generator (1-8 cameras at any
angle, 6-48 pixels a side, ``t_e`` 0.5-12 ``t_r``, trigger offsets, gains; one-camera rigs are
left out: no search of the temporal weight runs there), in three groups of seeds and scenes, and
the paper array's scenes of ``benchmarks/quality.py`` at 64x64 and 128x128; noiseless and with
Poisson noise of N photo-electrons at full scale plus Gaussian read noise of 1 % of full scale
(``quality_scenes.noisy``, seed 1). The rule was designed on the first group; the others are
held out. Results are cached per case (``--cache``). Writes docs/tuning_blend.md.

    python benchmarks/tuning_blend.py [--groups design check-a check-b paper] [--out docs/tuning_blend.md]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

import rsocl
from rsocl.analysis.metrics import psnr
from rsocl.model.interpolation import interp3d
from rsocl.solver.crossval import Tuning

sys.path.insert(0, str(Path(__file__).resolve().parent))
from case_cache import Cache  # noqa: E402
from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import available, case_data  # noqa: E402
from tv_step import random_rig  # noqa: E402

#: name -> (rig seeds, scenes, noise levels: None or photo-electrons at full scale), the paper array as seeds None
GROUPS = {
    "design": (range(100, 140), ("builtin", "runner40@1"), (None, 1000.0)),
    "check-a": (range(160, 200), ("traffic48@1", "builtin-slow"), (None, 300.0)),
    "check-b": (range(140, 160), ("runner40@2", "traffic48@0.5"), (None, 1000.0, 30.0)),
    "paper": (
        None,
        (
            "builtin",
            "builtin-slow",
            "builtin-fast",
            "runner40@0.5",
            "runner40@1",
            "runner40@2",
            "runner40-crop@1",
            "traffic48@0.5",
            "traffic48@1",
            "traffic48@2",
        ),
        (None, 1000.0),
    ),
}
ITERATIONS = 200


def cases(group, one_camera=False):
    """``(key, rig, scene, photons)`` of a group (the paper array: every scene at 64x64, two at 128x128);
    random rigs of one camera only with ``one_camera``."""
    seeds, scenes, noises = GROUPS[group]
    if seeds is None:
        sizes = [(64, scenes), (128, ("builtin", "runner40@1"))]
        for size, names in sizes:
            rig = rsocl.Rig.paper_array(4, (size, size), t_e=0.18e-3, t_r=35e-6)
            for scene in names:
                for photons in noises:
                    yield f"paper {size}x{size}", rig, scene, photons
        return
    for seed in seeds:
        rig = random_rig(seed)
        if rig.n_channels == 1 and not one_camera:
            continue
        for scene in scenes:
            for photons in noises:
                yield f"seed {seed}", rig, scene, photons


def run_case(rig, scene, photons, device):
    """PSNR of interp3d, the tuned default and the same choice unblended; the chosen blend."""
    truth, g = case_data(scene, rig, photons)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tuned = rsocl.reconstruct(g, rig, iterations=ITERATIONS, device=device)
        own = rsocl.reconstruct(
            g, rig, iterations=ITERATIONS, device=device, blend=1.0, tune=Tuning.from_params(tuned.params["tuning"])
        )
    return {
        "interp3d": float(psnr(interp3d(g, rig), truth, data_range=1.0)),
        "tuned": float(psnr(tuned.datacube, truth, data_range=1.0)),
        "unblended": float(psnr(own.datacube, truth, data_range=1.0)),
        "blend": float(tuned.params["blend"]),
    }


def summary_rows(group, results):
    """One table row per noise level of a group: cases, blend's change (mean, worst, best), runs below interp3d."""
    rows = []
    for photons in GROUPS[group][2]:
        level = [r for r in results if r["photons"] == photons]
        if not level:
            continue
        change = np.array([r["tuned"] - r["unblended"] for r in level])
        below = (sum(r["unblended"] < r["interp3d"] for r in level), sum(r["tuned"] < r["interp3d"] for r in level))
        blends = np.array([r["blend"] for r in level])
        rows.append(
            f"| {group} | {'none' if photons is None else f'{photons:g}'} | {len(level)} | "
            f"{change.mean():+.2f} | {change.min():+.2f} | {change.max():+.2f} | "
            f"{below[0]} -> {below[1]} | {np.median(blends):.2f} ({blends.min():.2f}-{blends.max():.2f}) |"
        )
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--groups", nargs="+", choices=list(GROUPS), default=list(GROUPS))
    parser.add_argument("--device", default=None)
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "rsocl-tuning-blend-cache.json")
    parser.add_argument("--out", type=Path, default=DOCS / "tuning_blend.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    cache = Cache(args.cache)
    op = rsocl.RollingShutterOperator(rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6), device=args.device)
    page = header_lines(
        "The self-tuned blend with the interpolation", op.device, None if argv is None else [__file__, *argv]
    )
    page += [
        f"Self-tuned `rsocl.reconstruct` ({ITERATIONS} iterations, float32) against the same choice with "
        "`blend=1` (the solver's own result) and `interp3d`; PSNR in dB with peak 1. Noise: Poisson at the "
        "given photo-electrons at full scale plus 1 % read noise. Groups (see the script): `design`, the "
        "cases the rule was designed on (random rigs of seeds 100-139 x built-in scene and Runner at 1 "
        "frame per sub-frame); `check-a` (seeds 160-199 x Traffic at 1 and the slow built-in scene) and "
        "`check-b` (seeds 140-159 x Runner at 2 and Traffic at 0.5), held out; `paper`, the paper array's "
        "scenes of `benchmarks/quality.py`. Change: tuned minus unblended PSNR.",
        "",
        "| group | photo-electrons | cases | change mean | worst | best | runs below interp3d: unblended -> tuned | "
        "blend: median (range) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    detail, skipped = [], set()
    for group in args.groups:
        results = []
        for key, rig, scene, photons in cases(group):
            if not available(scene):
                skipped.add(scene)
                continue
            name = f"{key}|{scene}|{photons}|{ITERATIONS}"
            r = dict(
                cache.get(
                    name, lambda rig=rig, scene=scene, photons=photons: run_case(rig, scene, photons, args.device)
                ),
                photons=photons,
            )
            results.append(r)
            what = "paper array" if GROUPS[group][0] is None else f"{key}, {rig.n_channels} cameras"
            detail.append(
                f"| {group} | {what}, {rig.shape[0]}x{rig.shape[1]} | {scene} | "
                f"{'none' if photons is None else f'{photons:g}'} | {r['interp3d']:.2f} | "
                f"{r['unblended']:.2f} | {r['tuned']:.2f} | {r['blend']:.2f} |"
            )
            print(detail[-1], flush=True)
        page += summary_rows(group, results)
    if skipped:
        page += ["", f"Skipped (no ../shared/data): {', '.join(sorted(skipped))}."]
    page += [
        "",
        "## Per case",
        "",
        "| group | rig | scene | photo-electrons | interp3d | unblended | tuned | blend |",
        "|---|---|---|---|---|---|---|---|",
    ] + detail
    write_page(args.out, page)


if __name__ == "__main__":
    main()
