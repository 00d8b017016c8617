"""Sets per second against the batch size, and where a single set's time goes, on one device.

1. The paper's configuration (4 cameras, 50x50, t_e = 180 µs, t_r = 35 µs, 200 ADMM-TV
   iterations, float32, fixed settings): ``--batches`` sets reconstructed as one batch
   ``(B, K, m, n)`` by one ``rsocl.reconstruct`` call, each size in turn over ``--rounds``
   rounds (the order reversed every other round, kernel builds excluded): sets per second,
   milliseconds per ADMM iteration, and what :func:`rsocl.solver.sets.batch_size` would choose
   with its default limit and with none.
2. One set with the host's work profiled (``cProfile``): kernel launches per ADMM iteration,
   the host's time per launch inside rsocl and pyopencl, and the time spent waiting for the
   device, so the page says whether a run is bound by the device or by launching.

Writes docs/batch_scaling.md (``--out``) with the machine, commit and date it was measured on.

    python benchmarks/batch_scaling.py [--batches 1 4 16 32 64 128] [--rounds 2] [--device SPEC]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

import numpy as np

import rsocl
from rsocl.model.scenes import builtin_scene

sys.path.insert(0, str(Path(__file__).resolve().parent))
from paper_config import paper_rig  # noqa: E402
from provenance import DOCS, header_lines, write_page  # noqa: E402


def snapshots(rig, device, count):
    """``count`` snapshot sets of the built-in scene (seeds 0, 1, ...), ``(count, K, m, n)``."""
    op = rsocl.RollingShutterOperator(rig, device=device)
    return np.stack([op.forward(builtin_scene(rig.shape, rig.T, seed=s)) for s in range(count)])


def scaling(device, batches, rounds, iterations):
    """Markdown lines: sets per second and ms per iteration for each batch size."""
    from rsocl.solver.sets import batch_size

    rig = paper_rig()
    g = snapshots(rig, device, max(batches))
    for b in batches:  # kernel builds: not timed
        rsocl.reconstruct(g[:b] if b > 1 else g[0], rig, iterations=2, device=device, tune=False)
    rates = {b: [] for b in batches}
    for r in range(rounds):
        for b in batches if r % 2 == 0 else batches[::-1]:
            t0 = time.perf_counter()
            rsocl.reconstruct(g[:b] if b > 1 else g[0], rig, iterations=iterations, device=device, tune=False)
            rates[b].append(b / (time.perf_counter() - t0))
            print(f"  round {r + 1}: batch {b}: {rates[b][-1]:.2f} sets/s", file=sys.stderr, flush=True)
    chosen = batch_size(rig, device=device, sets=max(batches))
    unlimited = batch_size(rig, device=device, sets=max(batches), limit=max(batches), cache_fraction=None)
    lines = [
        f"## Sets per second against the batch size ({iterations} iterations, float32)",
        "",
        f"The paper's configuration: 4 cameras, 50x50, T = {rig.T}, fixed settings (TV temporal weight 3, "
        f"lam 0.1, start from zeros); each batch is one `rsocl.reconstruct` call (set-up included, kernel "
        f"builds excluded), median over {rounds} rounds with the sizes in turn.",
        "",
        "| batch (sets) | sets/s (median) | range | ms per ADMM iteration | against one set |",
        "|---|---|---|---|---|",
    ]
    one = float(np.median(rates[batches[0]]))
    for b in batches:
        med = float(np.median(rates[b]))
        lines.append(
            f"| {b} | {med:.2f} | {min(rates[b]):.2f}-{max(rates[b]):.2f} | "
            f"{b / med / iterations * 1e3:.2f} | {med / one:.2f}× |"
        )
    best = max(batches, key=lambda b: np.median(rates[b]))
    lines += [
        "",
        f"- fastest batch: {best} sets, {np.median(rates[best]):.1f} sets/s",
        f"- `batch_size` for {max(batches)} sets: {chosen} with its default limit, {unlimited} within the "
        "device's memory alone",
        "",
    ]
    return lines


def host_profile(device, iterations):
    """Markdown lines: launches per iteration and the host's share of one set's run."""
    rig = paper_rig()
    g = snapshots(rig, device, 1)[0]
    rsocl.reconstruct(g, rig, iterations=2, device=device, tune=False)
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    result = rsocl.reconstruct(g, rig, iterations=iterations, device=device, tune=False)
    prof.disable()
    wall = time.perf_counter() - t0
    stats = pstats.Stats(prof).stats
    launches = waited = launch_time = 0.0
    for (filename, _, name), (_, calls, _, cumulative, _) in stats.items():
        if filename.endswith(("rsocl/device/kernel.py", "rsocl\\device\\kernel.py")) and name == "__call__":
            launches, launch_time = calls, cumulative
        if filename.endswith(("rsocl/device/reduction.py", "rsocl\\device\\reduction.py")) and name == "result":
            waited = cumulative
    loop = float(result.history["time"][-1])
    return [
        "## Where one set's time goes (profiled)",
        "",
        f"One set of the paper's configuration, {iterations} iterations, under `cProfile` (which slows the "
        "host's Python down, so the host's shares are upper bounds):",
        "",
        f"- {wall:.3f} s for the call, {loop:.3f} s in the iterations: {loop / iterations * 1e3:.2f} ms per "
        "ADMM iteration",
        f"- {launches / iterations:.1f} kernel launches per iteration through `rsocl.device.kernel.Kernel`, "
        f"{launch_time / max(launches, 1) * 1e6:.1f} µs of host time each (arguments and enqueue)",
        f"- {waited:.3f} s ({waited / loop:.0%} of the iterations) waiting for a residual, i.e. for the device",
        "",
    ]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--batches", type=int, nargs="+", default=[1, 4, 16, 32, 64, 128], help="batch sizes, sets (ascending)"
    )
    parser.add_argument("--iterations", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", type=Path, default=DOCS / "batch_scaling.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    batches = sorted(set(args.batches))
    if min(batches + [args.iterations, args.rounds]) < 1:
        raise SystemExit("--batches, --iterations and --rounds must be >= 1")
    device = rsocl.device.get_device(args.device)
    page = header_lines("Sets per second against the batch size", device, None if argv is None else [__file__, *argv])
    page += scaling(device, batches, args.rounds, args.iterations)
    page += host_profile(device, args.iterations)
    print("\n".join(page))
    write_page(args.out, page)


if __name__ == "__main__":
    main()
