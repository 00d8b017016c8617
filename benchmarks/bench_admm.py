"""Time rsocl's ADMM-TV against the plain NumPy + scikit-image baseline and a PyTorch peer, in one run.

For each ROI size the paper's 4-camera array (angles 0, 90, 180, 270; t_e = 0.18 ms,
t_r = 35 us) films a benchmark video (docs/model.md's protocol: resized, resampled to T
sub-frames, [0, 1]); the snapshots are simulated in float64 with rsocl's operator.
Four reconstructions then run with the same parameters and iteration count:

    baseline float64  (numpy_admm_tv.py, a user's default dtype)
    baseline float32
    torch    float32  (torch_admm_tv.py: the same algorithm in plain PyTorch, CPU, once per thread count
                       of --torch-threads; when torch is installed)
    rsocl    float32  (OpenCL; one warm-up run first, excluded from the timing)
    rsocl    float64

and a Markdown table gives seconds per iteration, PSNR (peak 1), the speed-up over
both baselines and the PSNR difference to the baseline of the same dtype. rsocl is compared
with PyTorch at its faster thread count, round by round.

    python benchmarks/bench_admm.py --sizes 64 128 --iterations 20 --repeat 3 [--out docs/bench_admm.md]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from numpy_admm_tv import admm_tv  # noqa: E402

import rsocl  # noqa: E402
from rsocl.analysis.metrics import psnr  # noqa: E402
from rsocl.device.context import get_device  # noqa: E402
from rsocl.model.scenes import builtin_scene, load_scene  # noqa: E402

try:
    import torch
    from torch_admm_tv import admm_tv as torch_admm_tv
except ImportError:  # the PyTorch peer is optional
    torch = None
from provenance import DOCS, header_lines, usable_cores, write_page  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"

#: Paper's simulated array: exposure and row readout time, seconds.
T_E, T_R = 0.18e-3, 35e-6
#: PSNR agreement required to call two runs "equal PSNR", dB.
PSNR_TOLERANCE = 0.1
#: Speed-up per iteration that the issue targets.
TARGET = 10.0


def parse_args(argv=None):
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter
    )
    p.add_argument("--sizes", type=int, nargs="+", default=[64, 128], help="square ROI sides, pixels")
    p.add_argument("--iterations", type=int, default=30, help="ADMM iterations of every run")
    p.add_argument(
        "--video", default="runner40", help="video name in ../shared/data (runner40, traffic48) or a video file path"
    )
    p.add_argument("--tv-iterations", type=int, default=10, help="Chambolle iterations per TV call")
    p.add_argument("--lam", type=float, default=0.1, help="regularization strength (data in [0, 1])")
    p.add_argument("--eta", type=float, default=0.2, help="ADMM penalty")
    p.add_argument("--device", default=None, help="OpenCL device spec for rsocl (default: rsocl's choice)")
    p.add_argument(
        "--repeat",
        type=int,
        default=1,
        help="rounds: each runs every implementation once, in turn; the table keeps each one's "
        "fastest, the summary also gives the ratio round by round",
    )
    p.add_argument(
        "--torch-threads",
        type=int,
        nargs="+",
        default=None,
        help="thread counts of the PyTorch peer, one run each per round (default: 1 and the "
        "cores this process may use)",
    )
    p.add_argument("--out", type=Path, default=DOCS / "bench_admm.md", help="the Markdown page to write")
    return p.parse_args(argv)


def scene_source(video: str):
    """The file to read for ``--video``, or None (built-in scene) when the data is absent."""
    candidates = [Path(video)] if Path(video).suffix else []
    candidates.append(DATA / f"{video}.npz")
    for path in candidates:
        if path.is_file():
            return path
    print(
        f"note: video {video!r} not found (looked in {DATA}); using rsocl.model.scenes.builtin_scene instead",
        file=sys.stderr,
    )
    return None


def signed(x: float) -> str:
    """``x`` with a sign and 4 decimals; a difference that rounds to zero prints as ``+0.0000``."""
    text = f"{x:+.4f}"
    return "+0.0000" if text == "-0.0000" else text


def run_baseline(g, rig, truth, dtype, params):
    """One baseline run: (seconds per iteration, PSNR in dB)."""
    theta, _, seconds = admm_tv(g, rig, dtype=dtype, **params)
    return seconds, psnr(theta, truth, data_range=1.0)


def rsocl_params(params):
    # the baseline's TV is scikit-image's 3-D TV: the same algorithm is temporal_weight 1 at scikit-image's step
    return dict(params, regularizer_options={"temporal_weight": 1.0, "step": 1.0}, tune=False)


def run_rsocl(g, rig, truth, dtype, params, device):
    """One rsocl run (kernels already built): (seconds per iteration, PSNR in dB)."""
    result = rsocl.reconstruct(g, rig, device=device, dtype=dtype, **rsocl_params(params))
    return result.history["time"][-1] / params["iterations"], psnr(result.datacube, truth, data_range=1.0)


def run_torch(g, rig, truth, params, threads):
    """One run of the PyTorch peer in float32 on ``threads`` threads: (seconds per iteration, PSNR in dB)."""
    theta, _, seconds = torch_admm_tv(g, rig, dtype=torch.float32, threads=threads, **params)
    return seconds, psnr(theta, truth, data_range=1.0)


def torch_peers(torch_threads) -> dict:
    """The PyTorch runs of a round, ``{"torch Nt": N}`` (N threads); none without torch."""
    return {f"torch {n}t": n for n in torch_threads} if torch is not None else {}


def implementations(torch_threads):
    """The (implementation, dtype) pairs of a round; PyTorch once per thread count (:func:`torch_peers`)."""
    peers = [(label, "float32") for label in torch_peers(torch_threads)]
    return [("baseline", "float64"), ("baseline", "float32"), ("rsocl", "float32"), ("rsocl", "float64")] + peers


def timed_rounds(g, rig, truth, params, device, repeat, torch_threads=()):
    """``repeat`` rounds, each running every implementation once, in turn.

    Interleaving exposes the four to the same machine drift (this VM's speed changes by up
    to 2x over minutes), so the ratio of one round is a fair comparison. Returns
    ``{(impl, dtype): [(seconds per iteration, PSNR), ...]}``, one entry per round.
    """
    for dtype in ("float32", "float64"):  # kernel builds: not timed
        rsocl.reconstruct(g, rig, device=device, dtype=dtype, **dict(rsocl_params(params), iterations=2))
    runs = {key: [] for key in implementations(torch_threads)}
    peers = torch_peers(torch_threads)
    for r in range(repeat):
        for impl, dtype in runs:
            t0 = time.perf_counter()
            if impl == "baseline":
                out = run_baseline(g, rig, truth, np.dtype(dtype).type, params)
            elif impl in peers:
                out = run_torch(g, rig, truth, params, peers[impl])
            else:
                out = run_rsocl(g, rig, truth, dtype, params, device)
            runs[impl, dtype].append(out)
            print(
                f"  round {r + 1}: {impl} {dtype}: {out[0]:.4g} s/iteration, {out[1]:.3f} dB "
                f"({time.perf_counter() - t0:.1f} s)",
                file=sys.stderr,
                flush=True,
            )
    return runs


def round_ratios(runs, fast, slow):
    """Per-round speed-ups of ``fast`` over ``slow``, as a text 'median (min-max)'.

    ``slow`` is one key or a list of keys: then each round takes the fastest of them.
    """
    slows = [slow] if isinstance(slow, tuple) else slow
    ratios = sorted(min(runs[key][r][0] for key in slows) / b[0] for r, b in enumerate(runs[fast]))
    median = statistics.median(ratios)
    if len(ratios) == 1:
        return f"{median:.1f}×"
    return f"{median:.1f}× ({ratios[0]:.1f}-{ratios[-1]:.1f}× over {len(ratios)} rounds)"


def main(argv=None):
    args = parse_args(argv)
    if args.iterations < 1 or args.repeat < 1 or args.tv_iterations < 1:
        raise SystemExit("--iterations, --tv-iterations and --repeat must be >= 1")
    if not (args.lam > 0 and args.eta > 0):
        raise SystemExit("--lam and --eta must be > 0 (the baseline is ADMM, not GAP)")
    torch_threads = sorted(set(args.torch_threads or (1, usable_cores())))
    if torch_threads[0] < 1:
        raise SystemExit(f"--torch-threads must be >= 1, got {args.torch_threads}")
    device = get_device(args.device)
    source = scene_source(args.video)
    params = {"iterations": args.iterations, "lam": args.lam, "eta": args.eta, "tv_iterations": args.tv_iterations}

    import skimage

    header = header_lines(
        "ADMM-TV: rsocl against plain NumPy + scikit-image", device, None if argv is None else [__file__, *argv]
    )
    if source is None:
        scene = "rsocl.model.scenes.builtin_scene"
    elif source.parent == DATA:
        scene = f"../shared/data/{source.name}"
    else:
        scene = source.name
    header[-1:] = [
        f"- scikit-image {skimage.__version__} (the baseline's TV)",
        f"- scene: {scene}; paper array, 4 cameras, t_e = {T_E * 1e3:g} ms, t_r = {T_R * 1e6:g} us; "
        f"lam = {args.lam:g}, eta = {args.eta:g}, {args.tv_iterations} TV iterations (rsocl's TV with "
        f"temporal weight 1, scikit-image's 3-D TV), {args.iterations} ADMM iterations"
        + (f", best of {args.repeat} interleaved rounds" if args.repeat > 1 else ""),
        "- s/iteration: baseline = its loop; rsocl = history['time'][-1] / iterations (device-synced, "
        "includes the per-iteration residual); PSNR with peak 1 on the [0, 1] scale",
        "",
    ]
    print("\n".join(header), flush=True)

    columns = [
        "size",
        "T",
        "implementation",
        "dtype",
        "s/iteration",
        "PSNR (dB)",
        "speed-up vs baseline f64",
        "speed-up vs baseline f32",
        "ΔPSNR vs baseline same dtype (dB)",
    ]
    rows, summary = [], []
    for side in args.sizes:
        rig = rsocl.Rig.paper_array(4, (side, side), T_E, T_R)
        if source is None:
            truth = builtin_scene(rig.shape, rig.T, dtype=np.float32)
        else:
            truth = load_scene(source, rig.shape, rig.T)
        g = rsocl.RollingShutterOperator(rig, device=args.device, dtype="float64").forward(truth)
        print(f"{side}x{side}: T = {rig.T} sub-frames ...", file=sys.stderr, flush=True)

        rounds = timed_rounds(g, rig, truth, params, args.device, args.repeat, torch_threads)
        runs = {key: (min(sec for sec, _ in values), values[-1][1]) for key, values in rounds.items()}

        base64, base32 = runs["baseline", "float64"], runs["baseline", "float32"]
        for (impl, dtype), (sec, db) in runs.items():
            same = runs["baseline", dtype]
            rows.append(
                [
                    f"{side}×{side}",
                    str(rig.T),
                    impl,
                    dtype,
                    f"{sec:.4g}",
                    f"{db:.3f}",
                    f"{base64[0] / sec:.1f}×",
                    f"{base32[0] / sec:.1f}×",
                    signed(db - same[1]),
                ]
            )

        checks = []
        for dtype in ("float32", "float64"):
            sec, db = runs["rsocl", dtype]
            diff = db - runs["baseline", dtype][1]
            ok = abs(diff) <= PSNR_TOLERANCE
            checks.append(
                f"rsocl {dtype} vs baseline {dtype}: {runs['baseline', dtype][0] / sec:.1f}× best to best, "
                f"{round_ratios(rounds, ('rsocl', dtype), ('baseline', dtype))} round by round "
                f"(ΔPSNR {signed(diff)} dB, {'equal' if ok else 'NOT equal'} within {PSNR_TOLERANCE} dB)"
            )
        sec, db = runs["rsocl", "float32"]
        diff = db - base64[1]
        checks.append(
            f"rsocl float32 vs baseline float64 (a user's default): {base64[0] / sec:.1f}× (ΔPSNR {signed(diff)} dB)"
        )
        peers = [(label, "float32") for label in torch_peers(torch_threads)]
        if peers:
            fastest = min(peers, key=lambda key: runs[key][0])
            checks.append(
                f"rsocl float32 vs PyTorch float32 at its faster thread count each round "
                f"({', '.join(f'{n}t' for n in torch_threads)} tried): "
                f"{round_ratios(rounds, ('rsocl', 'float32'), peers)} round by round "
                f"(ΔPSNR {signed(db - runs[fastest][1])} dB)"
            )
        summary.append(f"- {side}×{side}: " + "; ".join(checks))

    widths = [max(len(c), *(len(r[i]) for r in rows)) for i, c in enumerate(columns)]
    fmt = lambda cells: "| " + " | ".join(c.ljust(w) for c, w in zip(cells, widths)) + " |"  # noqa: E731
    table = [fmt(columns), "|" + "|".join("-" * (w + 2) for w in widths) + "|"] + [fmt(r) for r in rows]
    body = table + ["", f"Speed-up per iteration (target: at least {TARGET:g}× at equal PSNR, ±{PSNR_TOLERANCE} dB):"]
    body += summary
    print("\n".join(body))
    write_page(args.out, header + body)


if __name__ == "__main__":
    main()
