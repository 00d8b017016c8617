"""Tiles, Dask and Zarr: seams, the whole sensor, workers, and N devices on paper.

Parts (``--parts``, default all; each part's numbers are kept in ``docs/scale.json`` with the
date, commit and command that measured them, and docs/scale.md is written from all of them):

* ``seams``: the paper's 4-camera array at 256x256 (t_e = 180 µs, t_r = 35 µs), reconstructed
  whole and in 128x128 tiles with a halo of 16: PSNR of each against the truth, their largest
  and mean difference, and a picture (``--picture``; default ``scale_seams.png`` beside ``--results``,
  docs/scale_seams.png for the default results): the middle sub-frame, both reconstructions and
  their difference with the tile borders drawn.
* ``tilings``: the same array at 128x128, whole and in tiles of 64 (2x2) and 32 (4x4) pixels with a
  halo of 16, with TV's fixed defaults and self-tuned (the default): the largest difference from the
  run in one piece, over all sub-frames and over those each tile models, and the PSNRs. In a 2x2 grid
  every tile's exposures span the capture's sub-frames; in a finer one the tiles inside model fewer.
* ``sensor``: the paper camera's whole 1024x1280 sensor, 4 cameras, t_r = 26 µs, t_e = 180 µs,
  dt = t_r (T = 1286 sub-frames). The capture (an analytic scene, simulated row block by row
  block) is written to an HDF5 file, then ``rsocl reconstruct CAPTURE --out rec.zarr --tile 128
  128`` (``--sensor-shape``: another sensor, tiles of at most 128 pixels a side) runs in this process
  on Dask's local scheduler; wall time and this process's peak RSS
  (which includes the OpenCL device's buffers on a CPU device) are reported, and the PSNR of a
  central 256x256 crop over the kept sub-frames. Run it alone (``--parts sensor``) so that the
  peak RSS is the reconstruction's.
* ``cluster``: many small sets (64x64, 4 cameras) on a LocalCluster of 1 and of 2 worker
  processes, alternating rounds; sets per second and the ratio.
* the N-device table is computed from the sensor run's measured per-tile times.

    python benchmarks/scale.py [--parts seams tilings sensor cluster] [--iterations 50] [--sensor-iterations 20]

Parts run one by one (``--parts sensor`` alone for its peak RSS) each add their numbers to the
results file; ``--parts`` with no part writes the page from the numbers kept.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import rsocl
from rsocl.analysis.metrics import psnr

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import DOCS, cpu_model, git_revision, header_lines, usable_cores, write_page  # noqa: E402

RESULTS = DOCS / "scale.json"
#: The sensor part's tile side, pixels (a smaller ``--sensor-shape`` side: that side).
SENSOR_TILE = 128
#: The smallest ``--sensor-shape`` side, pixels.
MIN_SENSOR_SIDE = 16


# ---------------------------------------------------------------------- scenes
def scene_block(rig, rows, subframes, seed=0):
    """An analytic scene over ``rows`` (slice of the grid) and ``subframes`` (slice): three bright
    discs crossing a smooth textured background at different speeds; values in [0, 1]."""
    m, n = rig.shape
    rng = np.random.default_rng(seed)
    y = np.arange(rows.start, rows.stop, dtype=np.float32)[:, None]
    x = np.arange(n, dtype=np.float32)[None, :]
    background = 0.3 + 0.1 * np.sin(x / 37.0 + 0.5) * np.cos(y / 23.0) + 0.08 * np.sin((x + 2 * y) / 61.0)
    discs = [(rng.uniform(0.2, 0.8) * m, rng.uniform(0.08, 0.15) * min(m, n), rng.uniform(0.5, 1.5)) for _ in range(3)]
    out = np.empty((subframes.stop - subframes.start, rows.stop - rows.start, n), dtype=np.float32)
    for i, s in enumerate(range(subframes.start, subframes.stop)):
        frame = background.copy()
        for k, (cy, radius, speed) in enumerate(discs):
            cx = (-radius + (n + 2 * radius) * ((s + 0.5) / rig.T * speed + k / 3.0)) % (n + 2 * radius) - radius
            d = np.sqrt((y - cy) ** 2 + (x - cx) ** 2) - radius
            frame = np.maximum(frame, 0.95 * np.clip(0.5 - d, 0, 1))
        out[i] = frame
    return out


def simulate_blocks(rig, block_rows=64):
    """Snapshots ``(K, m, n)`` of :func:`scene_block`, simulated row block by row block."""

    m, n = rig.shape
    g = np.empty((rig.n_channels, m, n), dtype=np.float32)
    for y0 in range(0, m, block_rows):
        h = min(block_rows, m - y0)
        sub = rig.crop((y0, 0, h, n))
        frames = sub.sampled_range()
        op = rsocl.RollingShutterOperator(sub, subframes=frames)
        g[:, y0 : y0 + h] = op.forward(scene_block(rig, slice(y0, y0 + h), frames))
    return g


# ---------------------------------------------------------------------- parts
def part_seams(args):
    from rsocl.model.scenes import builtin_scene
    from rsocl.scale import reconstruct_tiled, tile_grid

    rig = rsocl.Rig.paper_array(4, (256, 256), t_e=180e-6, t_r=35e-6)
    truth = builtin_scene(rig.shape, rig.T, seed=0)
    g = rsocl.RollingShutterOperator(rig).forward(truth)
    began = time.perf_counter()
    untiled = rsocl.reconstruct(g, rig, iterations=args.iterations, tune=False, progress=True).datacube
    untiled_s = time.perf_counter() - began
    tiled_result = reconstruct_tiled(
        g, rig, tile=(128, 128), halo=16, iterations=args.iterations, tune=False, progress=True
    )
    tiled = tiled_result.datacube
    diff = np.abs(tiled - untiled)
    kept = rig.kept_subframes()
    out = dict(
        shape=list(rig.shape),
        T=rig.T,
        iterations=args.iterations,
        tile=[128, 128],
        halo=16,
        psnr_untiled=psnr(untiled, truth),
        psnr_tiled=psnr(tiled, truth),
        psnr_untiled_kept=psnr(untiled[kept], truth[kept]),
        psnr_tiled_kept=psnr(tiled[kept], truth[kept]),
        max_diff=float(diff.max()),
        mean_diff=float(diff.mean()),
        max_diff_kept=float(diff[kept].max()),
        untiled_seconds=untiled_s,
        tiled_seconds=tiled_result.seconds,
    )
    picture = picture_path(args)
    _seam_picture(truth, untiled, tiled, tile_grid(rig.shape, (128, 128), 16), (kept.start + kept.stop) // 2, picture)
    print(f"seam picture written to {picture}", flush=True)
    return out


def part_tilings(args):
    from rsocl.model.scenes import builtin_scene
    from rsocl.scale import reconstruct_tiled, tile_grid
    from rsocl.scale.tiles import tile_rig

    rig = rsocl.Rig.paper_array(4, (128, 128), t_e=180e-6, t_r=35e-6)
    truth = builtin_scene(rig.shape, rig.T, seed=0)
    g = rsocl.RollingShutterOperator(rig).forward(truth)
    rows = []
    for label, tune in (("fixed (TV defaults)", False), ("self-tuned (the default)", True)):
        whole = rsocl.reconstruct(g, rig, iterations=args.iterations, tune=tune).datacube
        for side in (64, 32):
            grid = tile_grid(rig.shape, (side, side), 16)
            tiled = reconstruct_tiled(g, rig, tile=(side, side), halo=16, iterations=args.iterations, tune=tune)
            diff = np.abs(tiled.datacube - whole)
            modelled = np.zeros(diff.shape, bool)
            for tile in grid:
                modelled[(tile_rig(rig, tile).sampled_range(),) + tile.core_slices] = True
            rows.append(
                dict(
                    settings=label,
                    tile=side,
                    tasks=len(grid),
                    max_diff=float(diff.max()),
                    max_diff_modelled=float(diff[modelled].max()),
                    psnr_untiled=psnr(whole, truth),
                    psnr_tiled=psnr(tiled.datacube, truth),
                )
            )
            print(rows[-1], flush=True)
    return dict(shape=list(rig.shape), T=rig.T, iterations=args.iterations, halo=16, rows=rows)


def picture_path(args) -> Path:
    """Where the seams part draws its picture: ``--picture``, else ``scale_seams.png`` beside ``--results``."""
    return Path(args.picture) if args.picture else Path(args.results).with_name("scale_seams.png")


def _seam_picture(truth, untiled, tiled, grid, s, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rsocl.files.atomic import atomic_path

    diff = np.abs(tiled[s] - untiled[s])
    fig, axes = plt.subplots(1, 4, figsize=(16, 4.4))
    for ax, image, title in zip(
        axes[:3], (truth[s], untiled[s], tiled[s]), ("truth", "untiled", "tiled 128x128, halo 16")
    ):
        ax.imshow(image, cmap="gray", vmin=0, vmax=1)
        ax.set_title(f"{title}, sub-frame {s}")
    shown = axes[3].imshow(diff, cmap="magma", vmin=0, vmax=max(float(diff.max()), 1e-6))
    axes[3].set_title(f"|tiled - untiled| (max {diff.max():.2e})")
    fig.colorbar(shown, ax=axes[3], fraction=0.046)
    for t in grid:
        y0, y1, x0, x1 = t.core
        axes[3].add_patch(plt.Rectangle((x0 - 0.5, y0 - 0.5), x1 - x0, y1 - y0, fill=False, ec="cyan", lw=0.6))
    for ax in axes:
        ax.set_axis_off()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=80)
    plt.close(fig)


def part_sensor(args):
    from rsocl.cli.main import main as rsocl_main
    from rsocl.files.hdf5 import save_capture
    from rsocl.scale.store import load_store

    rig = rsocl.Rig.paper_array(4, tuple(args.sensor_shape), t_e=180e-6, t_r=26e-6)
    tile = [str(min(SENSOR_TILE, side)) for side in rig.shape]
    work = Path(args.workdir or tempfile.mkdtemp(prefix="rsocl-sensor-"))
    capture, store = work / "sensor.h5", work / "sensor.zarr"
    began = time.perf_counter()
    save_capture(capture, simulate_blocks(rig), rig)
    simulate_s = time.perf_counter() - began
    command = [
        "reconstruct",
        str(capture),
        "--out",
        str(store),
        "--tile",
        *tile,
        "--iterations",
        str(args.sensor_iterations),
    ]
    began = time.perf_counter()
    code = rsocl_main(command)
    seconds = time.perf_counter() - began
    if code != 0:
        raise SystemExit(f"rsocl reconstruct exited with {code}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    stored = load_store(store)
    tiles = stored.tiles.reshape(-1, stored.tiles.shape[-1])
    kept = rig.kept_subframes()
    m, n = rig.shape
    rows, cols = (
        slice(m // 2 - min(128, m // 4), m // 2 + min(128, m // 4)),
        slice(n // 2 - min(128, n // 4), n // 2 + min(128, n // 4)),
    )
    crop = np.asarray(stored.datacube[kept, rows, cols])
    truth = scene_block(rig, rows, kept)[:, :, cols]
    return dict(
        shape=list(rig.shape),
        T=rig.T,
        T_se=rig.T_se,
        iterations=args.sensor_iterations,
        command="rsocl " + " ".join(command[:1] + ["CAPTURE", "--out", "rec.zarr"] + command[4:]),
        tasks=int(tiles.shape[0]),
        complete=bool(stored.complete),
        seconds=seconds,
        simulate_seconds=simulate_s,
        tile_seconds=[float(v) for v in tiles[:, 3]],
        modelled_subframes=[int(v) for v in tiles[:, 2] - tiles[:, 1]],
        peak_rss_bytes=int(peak),
        psnr_center_kept=psnr(crop, truth),
        store_bytes=int(sum(p.stat().st_size for p in store.rglob("*") if p.is_file())),
    )


def part_cluster(args):
    from rsocl.model.scenes import builtin_scene
    from rsocl.scale import reconstruct_tiled

    rig = rsocl.Rig.paper_array(4, (64, 64), t_e=180e-6, t_r=35e-6)
    op = rsocl.RollingShutterOperator(rig)
    sets = np.stack([op.forward(builtin_scene(rig.shape, rig.T, seed=s)) for s in range(args.sets)])
    times = {1: [], 2: []}
    reference = None
    for _ in range(args.rounds):
        for workers in (1, 2):
            result = reconstruct_tiled(
                sets, rig, tile=rig.shape, halo=0, iterations=args.iterations, workers=workers, tune=False
            )
            times[workers].append(result.seconds)
            if reference is None:
                reference = result.datacube
            assert np.array_equal(result.datacube, reference), "1 and 2 workers gave different numbers"
    best = {w: min(v) for w, v in times.items()}
    return dict(
        shape=list(rig.shape),
        sets=args.sets,
        iterations=args.iterations,
        rounds=args.rounds,
        seconds={str(w): v for w, v in times.items()},
        sets_per_second={str(w): args.sets / best[w] for w in best},
        ratio=best[1] / best[2],
    )


# ---------------------------------------------------------------------- page
def n_devices_table(sensor):
    """Wall time of the sensor's tasks on N devices from its measured per-tile times (longest first
    onto the least loaded device, the order a cluster's scheduler approaches)."""
    times = sorted(sensor["tile_seconds"], reverse=True)
    rows = []
    for n in (1, 2, 4, 8, 16):
        load = [0.0] * n
        for t in times:
            load[load.index(min(load))] += t
        rows.append((n, max(load)))
    return rows


def page(results, argv):
    from rsocl.device.context import get_device

    lines = header_lines("Tiles, Dask and Zarr: seams, the whole sensor, workers", get_device(None), argv)
    lines += [
        "Written by `benchmarks/scale.py`; each part below names when, on which CPU and at which commit it was "
        "measured (the header above names the latest part's machine).",
        "",
    ]
    seams = results.get("seams")
    if seams:
        lines += [
            "## Tiled against untiled (256x256, paper array)",
            "",
            _stamp(seams),
            f"4 cameras at 0/90/180/270°, t_e = 180 µs, t_r = 35 µs, T = {seams['T']}, "
            f"{seams['iterations']} iterations, TV defaults; tiles of 128x128 with a halo of 16 (4 tasks).",
            "",
            "| | untiled | tiled | difference |",
            "|---|---|---|---|",
            f"| PSNR against the truth, all sub-frames | {seams['psnr_untiled']:.2f} dB | {seams['psnr_tiled']:.2f} dB "
            f"| {seams['psnr_tiled'] - seams['psnr_untiled']:+.3f} dB |",
            f"| PSNR, kept sub-frames (T_se) | {seams['psnr_untiled_kept']:.2f} dB | {seams['psnr_tiled_kept']:.2f} dB "
            f"| {seams['psnr_tiled_kept'] - seams['psnr_untiled_kept']:+.3f} dB |",
            f"| largest abs. difference (all / kept) | | | {seams['max_diff']:.2e} / {seams['max_diff_kept']:.2e} |",
            f"| mean abs. difference | | | {seams['mean_diff']:.2e} |",
            f"| wall time | {seams['untiled_seconds']:.1f} s | {seams['tiled_seconds']:.1f} s | |",
            "",
            "![seams](scale_seams.png)",
            "",
        ]
    tilings = results.get("tilings")
    if tilings:
        lines += [
            f"## Tilings ({tilings['shape'][0]}x{tilings['shape'][1]}, paper array)",
            "",
            _stamp(tilings),
            f"4 cameras at 0/90/180/270°, t_e = 180 µs, t_r = 35 µs, T = {tilings['T']}, "
            f"{tilings['iterations']} iterations, a halo of {tilings['halo']}. A tile models the sub-frames its "
            "own exposures touch (with its halo) and holds its first and last over the others; in a 2x2 grid "
            "those are all of the capture's, in a finer grid the inner tiles model fewer, and there the first "
            "and last they model lack the coupling in time to the others that the run in one piece has.",
            "",
            "| settings | tiles | largest difference, all sub-frames | the sub-frames each tile models | "
            "PSNR untiled | PSNR tiled |",
            "|---|---|---|---|---|---|",
        ]
        for row in tilings["rows"]:
            side = row["tile"]
            lines.append(
                f"| {row['settings']} | {row['tasks']} of {side}x{side} | {row['max_diff']:.2e} | "
                f"{row['max_diff_modelled']:.2e} | {row['psnr_untiled']:.2f} dB | {row['psnr_tiled']:.2f} dB |"
            )
        lines.append("")
    sensor = results.get("sensor")
    if sensor:
        gib = sensor["peak_rss_bytes"] / 2**30
        lines += [
            "## The whole sensor into a Zarr store",
            "",
            _stamp(sensor),
            f"{sensor['shape'][0]}x{sensor['shape'][1]}, 4 cameras, t_e = 180 µs, t_r = 26 µs, dt = t_r: "
            f"T = {sensor['T']} sub-frames (T_se = {sensor['T_se']}); one datacube is "
            f"{sensor['T'] * sensor['shape'][0] * sensor['shape'][1] * 4 / 2**30:.1f} GiB in float32.",
            "",
            f"- command: `{sensor['command']}` ({sensor['iterations']} iterations, so that the whole run "
            f"fits in under an hour on this 2-core CPU; the PSNR below is that of {sensor['iterations']} "
            "iterations, not of a "
            "converged reconstruction)",
            f"- {sensor['tasks']} tasks, store complete: {sensor['complete']}, "
            f"store on disk {sensor['store_bytes'] / 2**30:.2f} GiB",
            f"- wall time {sensor['seconds']:.0f} s ({sensor['seconds'] / 60:.1f} min); per tile "
            f"{np.median(sensor['tile_seconds']):.1f} s median, {max(sensor['tile_seconds']):.1f} s at most; "
            f"modelled sub-frames per tile {min(sensor['modelled_subframes'])}..{max(sensor['modelled_subframes'])}",
            f"- peak RSS of the process (the OpenCL CPU device's buffers included): {gib:.2f} GiB",
            f"- PSNR of the central 256x256 crop over the kept sub-frames: {sensor['psnr_center_kept']:.2f} dB",
            "",
            "### On paper: N devices",
            "",
            "From the per-tile times measured above, the tasks placed longest first onto the least loaded "
            "device (a lower bound on what a cluster's scheduler achieves, transfers left out). "
            "A device k times faster than this CPU divides every entry by k.",
            "",
            "| devices | wall time | speed-up |",
            "|---|---|---|",
        ]
        table = n_devices_table(sensor)
        lines += [f"| {n} | {t:.0f} s | {table[0][1] / t:.2f}x |" for n, t in table] + [""]
    cluster = results.get("cluster")
    if cluster:
        lines += [
            "## LocalCluster: 1 against 2 worker processes",
            "",
            _stamp(cluster),
            f"{cluster['sets']} sets of 64x64 (4 cameras), one task per set, {cluster['iterations']} iterations, "
            f"{cluster['rounds']} alternating rounds (best of each; cluster start-up not counted).",
            "",
            "| workers | seconds per round | sets/s |",
            "|---|---|---|",
        ]
        for w in ("1", "2"):
            lines.append(
                f"| {w} | {', '.join(f'{s:.1f}' for s in cluster['seconds'][w])} | "
                f"{cluster['sets_per_second'][w]:.2f} |"
            )
        lines += [
            "",
            f"Ratio (1 worker's time / 2 workers'): **{cluster['ratio']:.2f}x**. Both workers' OpenCL "
            "devices are the same 2 CPU cores (PoCL; each worker's device spans both), so the ratio measures "
            "how much of them one worker running one 64x64 set at a time leaves idle.",
            "",
        ]
    return lines


def _stamp(part):
    load = f" (load average at start {part['_load']})" if part.get("_load") else ""
    cpu = f" on {part['_cpu']}" if part.get("_cpu") else ""
    return f"_measured {part['_measured']}{load}{cpu} at commit {part['_commit']}: `{part['_command']}`_\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--parts",
        nargs="*",
        choices=["seams", "tilings", "sensor", "cluster"],
        default=["seams", "tilings", "sensor", "cluster"],
    )
    parser.add_argument("--iterations", type=int, default=50, help="seams, tilings and cluster parts (default 50)")
    parser.add_argument("--sensor-iterations", type=int, default=20, help="whole-sensor part (default 20)")
    parser.add_argument("--sets", type=int, default=16, help="sets of the cluster part (default 16)")
    parser.add_argument("--rounds", type=int, default=2, help="alternating rounds of the cluster part (default 2)")
    parser.add_argument(
        "--sensor-shape",
        type=int,
        nargs=2,
        default=[1024, 1280],
        metavar=("ROWS", "COLUMNS"),
        help=f"the sensor part's grid, each side >= {MIN_SENSOR_SIDE}; tiles of at most {SENSOR_TILE} pixels "
        "a side (default 1024 1280)",
    )
    parser.add_argument(
        "--results",
        default=str(RESULTS),
        help="JSON file the parts' numbers are kept in (default docs/scale.json, which also writes docs/scale.md)",
    )
    parser.add_argument(
        "--picture",
        default=None,
        help="the seams part's PNG (default: scale_seams.png beside --results; docs/scale_seams.png by default)",
    )
    parser.add_argument("--merge", nargs="*", default=[], help="results files of other runs to add first")
    parser.add_argument("--workdir", default=None, help="where the sensor's capture and store go (default: a temp dir)")
    args = parser.parse_args(argv)
    if min(args.sensor_shape) < MIN_SENSOR_SIDE:
        parser.error(
            f"--sensor-shape: each side must be >= {MIN_SENSOR_SIDE} pixels, "
            f"got {' '.join(map(str, args.sensor_shape))}"
        )
    for name in ("iterations", "sensor_iterations", "sets", "rounds"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    checked = [(Path(args.results), "--results")] + [(picture_path(args), "--picture")] * ("seams" in args.parts)
    for path, option in checked:
        if not path.parent.is_dir():
            parser.error(f"{option}: no folder {path.parent}")
    argv = sys.argv if argv is None else [sys.argv[0]] + list(argv)
    results_path = Path(args.results)
    for name in args.parts:
        print(f"--- {name}", flush=True)
        stamp = dict(
            _measured=datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            _load=", ".join(f"{x:.2f}" for x in os.getloadavg()),
            _commit=git_revision(),
            _cpu=f"{cpu_model()}, {usable_cores()} usable cores",
            _command=" ".join(["python", "benchmarks/scale.py"] + argv[1:]),
        )
        part = {**globals()[f"part_{name}"](args), **stamp}
        print(
            json.dumps({k: v for k, v in part.items() if k not in ("tile_seconds", "modelled_subframes")}, indent=1),
            flush=True,
        )
        results = json.loads(results_path.read_text()) if results_path.exists() else {}
        results[name] = part
        results_path.write_text(json.dumps(results, indent=1) + "\n")
    for extra in args.merge:
        results = json.loads(results_path.read_text()) if results_path.exists() else {}
        results.update(json.loads(Path(extra).read_text()))
        results_path.write_text(json.dumps(results, indent=1) + "\n")
    if args.results == str(RESULTS):
        results = json.loads(results_path.read_text()) if results_path.exists() else {}
        write_page(DOCS / "scale.md", page(results, argv))


if __name__ == "__main__":
    main()
