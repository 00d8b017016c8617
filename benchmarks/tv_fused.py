"""The TV's fused path against its plain path: time per denoising call and bytes moved, in one run.

For each ROI size, a datacube of the paper array's T sub-frames (float32, random values) is
denoised with 10 Chambolle iterations (3-D, temporal weight 3) by ``TV(fused=0, one_launch=0)``
(the plain path, two launches per iteration) and by ``TV(fused=k)`` for each ``--fused`` k, in
``--rounds`` rounds that run every variant in turn; each round times ``--calls`` calls per variant
(device-synced). The page gives the median time per call, the ratio to the plain path within each
round (median and range), the tile the planner picked and the bytes per voxel-iteration counted by
``rsocl_plugins.tv_fused``, and the largest difference between fused and plain results.

Then the same comparison inside whole reconstructions: the paper configuration (4 cameras, 50x50,
T = 55, 200 ADMM iterations of 10 TV iterations, fixed settings, float32) in batches of
``--admm-batches`` sets per ``rsocl.reconstruct`` call, plain against each fused value, in
alternating rounds; seconds per set (set-up included, compilation excluded), the ratio to the
plain path within each round, and the largest difference between the datacubes. Writes
``docs/tv_fused.md``; ``docs/regularizer_defaults.md`` quotes its figures (why TV's ``fused``
defaults to 0).

    python benchmarks/tv_fused.py [--sizes 64 128] [--fused 3 5 9] [--rounds 3] [--calls 5]
        [--admm-batches 1 4] [--device SPEC] [--out docs/tv_fused.md]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import rsocl
from rsocl.device.context import get_device
from rsocl_plugins.tv import TV
from rsocl_plugins.tv_fused import plain_values

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import DOCS, header_lines, write_page  # noqa: E402

ITERATIONS = 10
#: ADMM iterations of the whole reconstructions (the paper's)
ADMM_ITERATIONS = 200


def measure(dev, side, fused, rounds, calls):
    """Markdown table rows for one ROI size."""
    import pyopencl.array as cla

    T = rsocl.Rig.paper_array(4, (side, side), t_e=0.18e-3, t_r=35e-6).T
    x = cla.to_device(dev.queue, np.random.default_rng(0).random((T, side, side)).astype(np.float32))
    out = cla.empty_like(x)
    variants = {k: TV(iterations=ITERATIONS, fused=k, one_launch=0) for k in (0, *fused)}
    plain = variants[0].denoise(x, 0.1).get()
    worst = {k: float(np.abs(reg.denoise(x, 0.1).get() - plain).max()) for k, reg in variants.items()}
    seconds = {k: [] for k in variants}
    for _ in range(rounds):
        for k, reg in variants.items():
            dev.queue.finish()
            t0 = time.perf_counter()
            for _ in range(calls):
                reg.denoise(x, 0.1, out=out)
            dev.queue.finish()
            seconds[k].append((time.perf_counter() - t0) / calls)
    rows = []
    for k, reg in variants.items():
        plan = reg.fused_plan(x) if k else None
        values = plan.values() if plan is not None else plain_values(ITERATIONS, True)
        ratio = [s / p for s, p in zip(seconds[k], seconds[0])]
        rows.append(
            f"| {side}×{side}×{T} | {'plain' if k == 0 else f'fused = {k}'} | "
            f"{plan.tile if plan is not None else '-'} | {np.median(seconds[k]) * 1e3:.2f} | "
            f"{np.median(ratio):.2f}× ({min(ratio):.2f}-{max(ratio):.2f}×) | "
            f"{values * 4 / ITERATIONS:.1f} | {worst[k]:.1e} |"
        )
    return rows


def measure_admm(dev, batch, fused, rounds):
    """Markdown table rows for whole reconstructions of ``batch`` paper-configuration sets per call."""
    from rsocl.model.scenes import builtin_scene

    rig = rsocl.Rig.paper_array(4, (50, 50), t_e=0.18e-3, t_r=35e-6)
    op = rsocl.RollingShutterOperator(rig, device=dev)
    g = np.stack([op.forward(builtin_scene(rig.shape, rig.T, seed=seed)) for seed in range(batch)])
    g = g[0] if batch == 1 else g

    def run(k):
        options = {"fused": k, "one_launch": 0}
        kw = dict(tune=False, device=dev, regularizer_options=options)
        return rsocl.reconstruct(g, rig, iterations=ADMM_ITERATIONS, **kw)

    results = {k: run(k).datacube for k in (0, *fused)}  # compiles every variant once
    worst = {k: float(np.abs(cube - results[0]).max()) for k, cube in results.items()}
    seconds = {k: [] for k in results}
    for r in range(rounds):
        for k in list(results) if r % 2 == 0 else list(results)[::-1]:
            t0 = time.perf_counter()
            run(k)
            seconds[k].append((time.perf_counter() - t0) / batch)
    rows = []
    for k in results:
        ratio = [s / p for s, p in zip(seconds[k], seconds[0])]
        rows.append(
            f"| {batch} | {'plain' if k == 0 else f'fused = {k}'} | {np.median(seconds[k]) * 1e3:.1f} | "
            f"{1 / np.median(seconds[k]):.1f} | {np.median(ratio):.2f}× ({min(ratio):.2f}-{max(ratio):.2f}×) | "
            f"{worst[k]:.1e} |"
        )
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--fused", type=int, nargs="+", default=[3, 5, 9], help="values of the fused option")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--calls", type=int, default=5, help="denoising calls timed per variant and round")
    parser.add_argument(
        "--admm-batches",
        type=int,
        nargs="*",
        default=[1, 4],
        help="sets per reconstruct call in the whole-reconstruction comparison (none: skip it)",
    )
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", type=Path, default=DOCS / "tv_fused.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if (
        min(args.sizes) < 8
        or min(args.fused) < 1
        or args.rounds < 1
        or args.calls < 1
        or min(args.admm_batches, default=1) < 1
    ):
        raise SystemExit("--sizes must be >= 8, --fused, --rounds, --calls and --admm-batches >= 1")
    dev = get_device(args.device)
    page = header_lines("TV: fused path against plain path", dev, None if argv is None else [__file__, *argv])
    page += [
        f"One TV call of {ITERATIONS} Chambolle iterations (3-D, temporal weight 3, float32) on random "
        f"values; median of {args.rounds} rounds of {args.calls} calls per variant, variants in turn. "
        "Bytes per voxel-iteration are counted (global memory, halos included), not measured.",
        "",
        "| datacube | path | tile (x, y, t) | ms per call | time vs plain (range) | B/voxel-iteration | "
        "largest difference to plain |",
        "|---|---|---|---|---|---|---|",
    ]
    for side in args.sizes:
        page += measure(dev, side, args.fused, args.rounds, args.calls)
        print(page[-1], file=sys.stderr, flush=True)
    if args.admm_batches:
        page += [
            "",
            f"Whole reconstructions: the paper configuration (4 cameras, 50x50, T = 55, {ADMM_ITERATIONS} "
            f"ADMM iterations of {ITERATIONS} TV iterations, temporal weight 3, lam 0.1, float32, `tune=False`), "
            f"the built-in scene; {args.rounds} rounds, variants in turn (order reversed every other round); "
            "seconds per set include the call's set-up, not compilation.",
            "",
            "| sets per call | path | ms per set | sets/s | time vs plain (range) | largest difference to plain |",
            "|---|---|---|---|---|---|",
        ]
        for batch in args.admm_batches:
            page += measure_admm(dev, batch, args.fused, args.rounds)
            print(page[-1], file=sys.stderr, flush=True)
    page.append("")
    print("\n".join(page))
    write_page(args.out, page)


if __name__ == "__main__":
    main()
