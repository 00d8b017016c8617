"""The paper's configuration, batches, fewer iterations, and float32 against float64, measured in one run.

1. Paper array (4 cameras, 50x50, t_e = 180 µs, t_r = 35 µs), 200 ADMM-TV iterations:
   seconds per reconstructed set (compile excluded; the operator and solver set-up included)
   and how many sets per second that is against the paper cameras' 67 fps; then sets per second
   as one batch of ``--batch`` sets, in the batches ``batch_size`` chooses, and one set at a time,
   in alternating rounds;
   then batches at fewer ADMM and TV iterations, from zeros or from the interpolation of the
   snapshots: sets per second and PSNR against the default.
2. float32 against float64 at equal settings on the shared videos (64x64, default settings):
   PSNR of both, their difference (target: within 0.05 dB), time per iteration and device
   memory of each.

Writes docs/paper_config.md (``--out``) with the machine, commit and date it was measured on.

    python benchmarks/paper_config.py [--sets 3] [--batch 16] [--rounds 3] [--device SPEC]
        [--out docs/paper_config.md]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import rsocl
from rsocl.bench.memory import device_memory_bytes
from rsocl.model.scenes import builtin_scene, load_scene

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import DOCS, header_lines, write_page  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
PAPER_FPS = 67.0


def paper_rig():
    """The paper's configuration: 4 cameras, 50x50, t_e = 180 µs, t_r = 35 µs."""
    return rsocl.Rig.paper_array(4, (50, 50), t_e=0.18e-3, t_r=35e-6)


def paper_configuration(device, sets, iterations):
    """Markdown lines: seconds per reconstructed set of the paper's configuration (compile excluded)."""
    rig = paper_rig()
    snapshots = [
        rsocl.RollingShutterOperator(rig, device=device).forward(builtin_scene(rig.shape, rig.T, seed=s))
        for s in range(sets + 1)
    ]
    rsocl.reconstruct(snapshots[0], rig, iterations=2, device=device, tune=False)  # compile once
    seconds = []
    for g in snapshots[1:]:
        t0 = time.perf_counter()
        rsocl.reconstruct(g, rig, iterations=iterations, device=device, tune=False)
        seconds.append(time.perf_counter() - t0)
    per_set = float(np.median(seconds))
    spread = f", {min(seconds):.2f}-{max(seconds):.2f} s over the {sets} sets" if sets > 1 else ""
    return [
        f"## Paper configuration: 4 cameras, 50x50, T = {rig.T}, {iterations} iterations, float32",
        "",
        "Snapshots of the built-in scene (a different seed per set); each set is one `rsocl.reconstruct` call "
        "(operator and solver set-up included, kernel compilation excluded).",
        "",
        f"- {per_set:.2f} s per reconstructed set (median of {sets}{spread}); {1 / per_set:.2f} sets/s, "
        f"i.e. {1 / per_set / PAPER_FPS:.4f} of the cameras' {PAPER_FPS:g} fps "
        f"({PAPER_FPS * per_set:.0f}x slower than real time)",
        f"- each set is {rig.T} sub-frames: {rig.T / per_set:.0f} reconstructed sub-frames/s",
        "",
    ]


def batches(device, batch, rounds, iterations):
    """Markdown lines: sets per second of ``batch`` sets as one batch, in the batches
    :func:`rsocl.solver.sets.batch_size` chooses for the device (``reconstruct_sets``, the CLI's
    path), and one set at a time.

    Each round reconstructs the same sets every way (the order reverses every other round); the
    ratios are taken within each round.
    """
    from rsocl.solver.sets import CACHE_FRACTION, GPU_BATCH_VOXELS, batch_size, reconstruct_sets

    rig = paper_rig()
    op = rsocl.RollingShutterOperator(rig, device=device)
    g = np.stack([op.forward(builtin_scene(rig.shape, rig.T, seed=100 + s)) for s in range(batch)])
    chosen = batch_size(rig, sets=batch, device=device)
    for b in {batch, chosen, 1}:
        rsocl.reconstruct(g[:b] if b > 1 else g[0], rig, iterations=2, device=device, tune=False)  # compile once
    ways = {
        f"one batch of {batch}": lambda: (
            rsocl.reconstruct(g, rig, iterations=iterations, device=device, tune=False).datacube
        ),
        f"batches of {chosen} (batch_size)": lambda: (
            reconstruct_sets(g, rig, iterations=iterations, device=device, tune=False).datacube
        ),
        "one at a time": lambda: np.stack(
            [rsocl.reconstruct(one, rig, iterations=iterations, device=device, tune=False).datacube for one in g]
        ),
    }
    names = list(ways)
    rates = {k: [] for k in names}
    worst = 0.0
    for r in range(rounds):
        results = {}
        for name in names if r % 2 == 0 else names[::-1]:
            t0 = time.perf_counter()
            results[name] = ways[name]()
            rates[name].append(batch / (time.perf_counter() - t0))
        loop = results["one at a time"]
        worst = max(worst, *(float(np.abs(results[k] - loop).max() / np.abs(loop).max()) for k in names))
    if device.is_cpu:
        why = (
            f"on this CPU device a batch stays within {CACHE_FRACTION:.0%} of its "
            f"{device.cache_bytes / 2**20:.0f} MiB cache"
        )
    else:
        why = f"on this device up to {GPU_BATCH_VOXELS / 2**20:.0f} Mi voxels, within its memory"
    lines = [
        f"## Batches: {batch} sets per call against one set per call",
        "",
        f"The same {batch} sets of the paper configuration ({iterations} iterations, float32) reconstructed "
        f"as one batch `(B, K, m, n)`, in the batches `rsocl.solver.sets.batch_size` chooses for this device "
        f"({chosen} sets: {why}), and one set at a time, in {rounds} rounds with the "
        "order reversed every other round (set-up included, compilation excluded).",
        "",
        "| | sets/s (median) | range over rounds | s per set | against one at a time |",
        "|---|---|---|---|---|",
    ]
    for name in names:
        med = float(np.median(rates[name]))
        ratio = [a / b for a, b in zip(rates[name], rates["one at a time"])]
        lines.append(
            f"| {name} | {med:.2f} | {min(rates[name]):.2f}-{max(rates[name]):.2f} | {1 / med:.3f} | "
            f"{np.median(ratio):.2f}× ({min(ratio):.2f}-{max(ratio):.2f}×) |"
        )
    return lines + [
        "",
        f"- largest difference between a set's batched and single-set result: {worst:.1e} of the largest value",
        "",
    ]


#: ``(ADMM iterations, TV iterations, start)`` of the settings trade, the default (``tune=False``: from
#: zeros) first; ``"interp3d"`` starts from the interpolation of the snapshots, as the self-tuned default does.
SETTINGS = (
    (200, 10, "zeros"),
    (100, 10, "zeros"),
    (100, 5, "zeros"),
    (50, 5, "zeros"),
    (50, 3, "zeros"),
    (25, 3, "zeros"),
    (100, 10, "interp3d"),
    (50, 10, "interp3d"),
    (25, 10, "interp3d"),
)


def _named(key) -> str:
    """A setting of :data:`SETTINGS` in words."""
    return f"{key[0]} ADMM x {key[1]} TV iterations from {key[2]}"


def _run(one, g, rig, key, device):
    """The datacube of ``g`` at the setting ``key`` (:data:`SETTINGS`): one set, or sets in batches."""
    from rsocl.solver.sets import reconstruct_sets

    kwargs = dict(
        iterations=key[0], tv_iterations=key[1], x0=None if key[2] == "zeros" else key[2], device=device, tune=False
    )
    return (rsocl.reconstruct(g, rig, **kwargs) if one else reconstruct_sets(g, rig, **kwargs)).datacube


def settings_trade(device, batch, rounds):
    """Markdown lines: sets per second and PSNR of ``batch`` sets of the paper configuration (in the
    batches :func:`rsocl.solver.sets.reconstruct_sets` chooses) at fewer ADMM and TV iterations, from
    zeros or from the interpolation (:data:`SETTINGS`), each against the default in the same rounds
    (settings in turn, the order reversed every other round)."""
    from rsocl.analysis.metrics import psnr
    from rsocl.solver.sets import batch_size

    rig = paper_rig()
    op = rsocl.RollingShutterOperator(rig, device=device)
    truth = np.stack([builtin_scene(rig.shape, rig.T, seed=200 + s) for s in range(batch)])
    g = np.stack([op.forward(t) for t in truth])
    rsocl.reconstruct(g, rig, iterations=2, tv_iterations=3, device=device, tune=False)  # compile once
    rates = {k: [] for k in SETTINGS}
    quality = {}
    for r in range(rounds):
        for key in SETTINGS if r % 2 == 0 else SETTINGS[::-1]:
            t0 = time.perf_counter()
            cube = _run(False, g, rig, key, device)
            rates[key].append(batch / (time.perf_counter() - t0))
            quality[key] = float(np.mean([psnr(c, t) for c, t in zip(cube, truth)]))
    videos = {}
    for video in ("runner40", "traffic48"):
        path = DATA / f"{video}.npz"
        if path.exists():
            t = load_scene(path, rig.shape, rig.T)
            one = op.forward(t)
            videos[video] = {key: psnr(_run(True, one, rig, key, device), t) for key in SETTINGS}
    base = SETTINGS[0]
    lines = [
        f"## Fewer iterations: the speed and what it costs ({batch} sets)",
        "",
        f"The paper configuration, {batch} sets of the built-in scene (other seeds than above) in the batches "
        f"`batch_size` chooses ({batch_size(rig, sets=batch, device=device)} sets), "
        f"{rounds} rounds with the settings in turn; PSNR is the mean over the sets (dB, peak 1). Ratios "
        "are taken within each round against the default (200 ADMM iterations, 10 TV iterations). "
        "Fixed settings (temporal weight 3, lam 0.1), from zeros (`tune=False`'s start) or from the "
        'interpolation of the snapshots (`x0="interp3d"`, the self-tuned default\'s start, its time '
        "included). The last columns: the change of PSNR against the default on the shared videos at the "
        "same 50x50 configuration (one set each).",
        "",
        "| ADMM iterations | TV iterations | start | sets/s (median) | s per set | speed vs default | PSNR (dB) | "
        "PSNR vs default (dB) |" + "".join(f" {v}: PSNR vs default (dB) |" for v in videos),
        "|---|---|---|---|---|---|---|---|" + "---|" * len(videos),
    ]
    for key in SETTINGS:
        rate = float(np.median(rates[key]))
        ratio = float(np.median([a / b for a, b in zip(rates[key], rates[base])]))
        lines.append(
            f"| {key[0]} | {key[1]} | {key[2]} | {rate:.2f} | {1 / rate:.3f} | {ratio:.2f}× | {quality[key]:.2f} | "
            f"{quality[key] - quality[base]:+.2f} |" + "".join(f" {v[key] - v[base]:+.2f} |" for v in videos.values())
        )
    fast = [k for k in SETTINGS if np.median(rates[k]) >= 10]
    lines += [
        "",
        ("- 10 sets/s or more: " + ", ".join(map(_named, fast)))
        if fast
        else "- no setting of the table reaches 10 sets/s",
        "",
    ]
    within = [k for k in fast if all(abs(q[k] - q[base]) <= 0.1 for q in (quality, *videos.values()))]
    lines += [
        ("- of those, PSNR within 0.1 dB of the default on every scene of the table: " + ", ".join(map(_named, within)))
        if within
        else "- none of those keeps the PSNR within 0.1 dB of the default on every scene of the table",
        "",
    ]
    return lines


def precision(device, iterations):
    """Markdown lines: float32 against float64 on the shared videos (64x64, default settings)."""
    lines = [
        "## float32 against float64 (64x64 paper array, default settings)",
        "",
        "| video | PSNR float32 | PSNR float64 | difference | ms/iteration f32 | f64 | device MiB f32 | f64 |",
        "|---|---|---|---|---|---|---|---|",
    ]
    big = rsocl.Rig.paper_array(4, (64, 64), t_e=0.18e-3, t_r=35e-6)
    for video in ("runner40", "traffic48"):
        path = DATA / f"{video}.npz"
        if not path.exists():
            lines.append(f"| {video} | missing ../shared/data/{path.name} | | | | | | |")
            continue
        truth = load_scene(path, big.shape, big.T)
        g = rsocl.RollingShutterOperator(big, device=device, dtype="float64").forward(truth)
        row = {}
        for dtype in ("float32", "float64"):
            if dtype == "float64" and not device.has_fp64:
                continue
            rsocl.reconstruct(g, big, iterations=1, device=device, dtype=dtype, tune=False)
            res = rsocl.reconstruct(g, big, iterations=iterations, truth=truth, device=device, dtype=dtype, tune=False)
            mem = device_memory_bytes(big, "tv", dtype, device=device, with_truth=True)
            row[dtype] = (res.history["psnr"][-1], res.history["time"][-1] / res.iterations * 1e3, mem / 2**20)
        if len(row) == 2:
            a, b = row["float32"], row["float64"]
            lines.append(
                f"| {video} | {a[0]:.3f} | {b[0]:.3f} | {a[0] - b[0]:+.3f} dB | {a[1]:.1f} | {b[1]:.1f} | "
                f"{a[2]:.1f} | {b[2]:.1f} |"
            )
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", type=int, default=3, help="sets timed in the paper configuration")
    parser.add_argument("--iterations", type=int, default=200)
    parser.add_argument("--batch", type=int, default=16, help="sets per batch in the batch comparison")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds of the batch comparison")
    parser.add_argument("--skip-precision", action="store_true", help="leave out the float32/float64 section")
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", type=Path, default=DOCS / "paper_config.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if min(args.sets, args.iterations, args.batch, args.rounds) < 1:
        raise SystemExit("--sets, --iterations, --batch and --rounds must be >= 1")
    device = rsocl.device.get_device(args.device)
    page = header_lines(
        "The paper's configuration, and float32 against float64", device, None if argv is None else [__file__, *argv]
    )
    page += paper_configuration(device, args.sets, args.iterations)
    page += batches(device, args.batch, args.rounds, args.iterations)
    page += settings_trade(device, args.batch, args.rounds)
    if not args.skip_precision:
        page += precision(device, args.iterations)
    print("\n".join(page))
    write_page(args.out, page)


if __name__ == "__main__":
    main()
