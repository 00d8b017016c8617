"""The quality ladder measured: time, PSNR and SSIM of every rung against interp3d and a fixed run.

For each case of :data:`quality.CASES` picked by ``--sizes`` and ``--scenes`` (scenes of
:mod:`quality_scenes`; Runner and Traffic only where ``../shared/data`` holds them), with the paper's
4-camera array (t_e = 180 µs, t_r = 35 µs, dt = t_r): ``interp3d`` (no solver), the fixed run
(``tune=False``: temporal weight 3, lam 0.1, zero start, the ``balanced`` rung's iterations) and
``rsocl.reconstruct(quality=...)`` for every rung of :mod:`rsocl.solver.ladder` at its own
iterations, then ``balanced`` with ``iterations="auto"``. Per run: PSNR (dB, peak 1), mean SSIM,
wall seconds, the search's seconds (``Result.search_seconds``) and the iterations that ran. After a
kernel build, a case's runs are timed in ``--rounds`` rounds, the order reversed every other round
(the machine's speed drifts): seconds are medians over the rounds, and a run's time against the
fixed run's is the median (and range) of its ratios within a round. PSNR, SSIM and iterations are
the first round's; every round must give the same PSNR. Results are cached per case and number of
rounds (``--cache``). Writes docs/quality_ladder.md (``--out``) with the provenance header, and
``--plot`` a Pareto plot (time against PSNR and SSIM).

    python benchmarks/ladder.py [--sizes 64 128] [--scenes builtin] [--rounds 5] [--out docs/quality_ladder.md]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import rsocl
from rsocl.analysis.metrics import psnr, ssim
from rsocl.model.interpolation import interp3d
from rsocl.solver.ladder import QUALITIES, RUNGS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from case_cache import Cache  # noqa: E402
from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality import CASES, add_sizes, check_sizes  # noqa: E402
from quality_scenes import available, case_data  # noqa: E402

#: The runs of a case, in the table's order: (label, keyword arguments of rsocl.reconstruct).
RUNS = [("fixed", {"tune": False, "iterations": RUNGS["balanced"].iterations})] + [
    (q, {"quality": q}) for q in QUALITIES
]
RUNS.append(("balanced, auto", {"quality": "balanced", "iterations": "auto"}))


def measure(g, rig, truth, device, **kwargs) -> dict:
    """One reconstruction's PSNR, SSIM, seconds, search seconds and iterations."""
    start = time.perf_counter()
    res = rsocl.reconstruct(g, rig, device=device, **kwargs)
    seconds = time.perf_counter() - start
    mean_ssim, _ = ssim(res.datacube, truth, data_range=1.0)
    return {
        "psnr": float(psnr(res.datacube, truth, data_range=1.0)),
        "ssim": float(mean_ssim),
        "seconds": seconds,
        "search": float(res.search_seconds or 0.0),
        "iterations": int(res.iterations),
    }


def timed_rounds(run, rounds: int) -> dict:
    """Every run of :data:`RUNS` measured ``rounds`` times, the order reversed every other round (``run(label,
    kwargs)`` -> :func:`measure`'s dict): per label, the first round's measures with ``seconds`` and ``search``
    the medians over the rounds and ``ratio`` / ``ratio_range`` the median and range of ``seconds`` over the
    fixed run's in the same round. Raises RuntimeError where a round's PSNR differs from the first's."""
    per: dict = {label: [] for label, _ in RUNS}
    for k in range(rounds):
        for label, kwargs in RUNS if k % 2 == 0 else RUNS[::-1]:
            per[label].append(run(label, kwargs))
    out = {}
    for label, ms in per.items():
        if any(abs(m["psnr"] - ms[0]["psnr"]) > 1e-9 for m in ms):
            raise RuntimeError(f"{label}: PSNR differs between rounds: {[m['psnr'] for m in ms]}")
        ratios = [m["seconds"] / f["seconds"] for m, f in zip(ms, per["fixed"])]
        out[label] = {
            **ms[0],
            "seconds": statistics.median(m["seconds"] for m in ms),
            "search": statistics.median(m["search"] for m in ms),
            "ratio": statistics.median(ratios),
            "ratio_range": [min(ratios), max(ratios)],
        }
    return out


def run_case(scene, size, noise, device, cache, rounds: int) -> dict:
    """Every run of one case (a dict of label -> measures, :func:`timed_rounds`), computed or from the cache."""
    rig = rsocl.Rig.paper_array(4, (size, size), t_e=0.18e-3, t_r=35e-6)
    truth, g = case_data(scene, rig, 1000.0 if noise == "poisson" else None)
    g = np.asarray(g, np.float32)
    prefix = f"{scene}|{size}|{noise}|"
    rsocl.reconstruct(g, rig, iterations=2, tune=False, device=device)  # kernel builds, not timed
    ip = interp3d(g, rig)
    out = {
        "interp3d": cache.get(
            prefix + "interp3d",
            lambda: {"psnr": float(psnr(ip, truth, data_range=1.0)), "ssim": float(ssim(ip, truth, data_range=1.0)[0])},
        )
    }
    runs = cache.get(
        prefix + f"runs x{rounds}",
        lambda: timed_rounds(lambda label, kw: measure(g, rig, truth, device, **kw), rounds),
    )
    return {**out, **runs}


def rows(scene, size, noise, r) -> list:
    """The Markdown rows of one case: one per run."""
    base = r["interp3d"]
    lines = [f"| {scene} | {size} | {noise} | interp3d | {base['psnr']:.2f} | {base['ssim']:.3f} | | | | |"]
    for label, _ in RUNS:
        m = r[label]
        lines.append(
            f"| {scene} | {size} | {noise} | {label} | {m['psnr']:.2f} | {m['ssim']:.3f} | "
            f"{m['psnr'] - base['psnr']:+.2f} | {m['iterations']} | {m['seconds']:.2f} ({m['search']:.2f}) | "
            f"{m['ratio']:.2f}x ({m['ratio_range'][0]:.2f}-{m['ratio_range'][1]:.2f}) |"
        )
    return lines


def pareto_plot(path, results) -> None:
    """Seconds against PSNR and SSIM, one line per case through its rungs (the fixed run and interp3d marked)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for (scene, size, noise), r in results:
        times = [r[q]["seconds"] for q in QUALITIES]
        for ax, key in zip(axes, ("psnr", "ssim")):
            (line,) = ax.plot(times, [r[q][key] for q in QUALITIES], "o-", label=f"{scene} {size} {noise}")
            ax.plot([r["fixed"]["seconds"]], [r["fixed"][key]], "x", color=line.get_color())
            ax.axhline(r["interp3d"][key], color=line.get_color(), lw=0.6, ls=":")
    for ax, name in zip(axes, ("PSNR, dB", "SSIM")):
        ax.set_xlabel("seconds (search included)")
        ax.set_ylabel(name)
    axes[0].legend(fontsize=7)
    fig.suptitle("rungs fast, balanced, best (o-); fixed run (x); interp3d (dotted)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def selected(args) -> list:
    """The cases of :data:`quality.CASES` that ``--sizes`` and ``--scenes`` pick."""
    return [
        (scene, size, noise)
        for scene, size, noise in CASES
        if size in args.sizes and (args.scenes is None or scene in args.scenes)
    ]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_sizes(parser)
    parser.add_argument("--scenes", nargs="+", default=None, help="scenes of quality.CASES to run (default: all)")
    parser.add_argument("--device", default=None)
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "rsocl-ladder-cache.json")
    parser.add_argument("--out", type=Path, default=DOCS / "quality_ladder.md", help="the Markdown page to write")
    parser.add_argument("--plot", type=Path, default=None, help="a PNG of the Pareto front")
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds of a case's runs (>= 1)")
    args = parser.parse_args(argv)
    check_sizes(parser, args.sizes)
    if args.rounds < 1:
        parser.error(f"--rounds must be >= 1, got {args.rounds}")
    scenes = sorted({scene for scene, _, _ in CASES})
    unknown = sorted(set(args.scenes or ()) - set(scenes))
    if unknown:
        parser.error(f"--scenes: no case has {', '.join(unknown)}; the cases' scenes are {', '.join(scenes)}")
    if not selected(args):
        parser.error(
            f"--sizes {' '.join(map(str, args.sizes))} and --scenes {' '.join(args.scenes)} select no case; "
            f"the cases: {', '.join(f'{scene} at {size}' for scene, size, _ in CASES if scene in args.scenes)}"
        )
    cache = Cache(args.cache)
    op = rsocl.RollingShutterOperator(rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6), device=args.device)
    page = header_lines("The quality ladder", op.device, None if argv is None else [__file__, *argv])
    page += [
        "Paper array (4 cameras, t_e = 180 µs, t_r = 35 µs, dt = t_r), TV, float32. PSNR in dB with peak 1, "
        "mean SSIM. Runs: `interp3d` (no solver); `fixed` = `tune=False` (temporal weight 3, lam 0.1, zero "
        "start, 200 iterations); `fast`, `balanced`, `best` = `rsocl.reconstruct(quality=...)` at the "
        'rung\'s own iterations (rsocl/solver/ladder.py); `balanced, auto` with `iterations="auto"`. '
        f"Seconds: the whole call, the search's share in brackets, medians of {args.rounds} rounds whose order "
        "reverses every other round; `/ fixed`: the median (and range) over the rounds of the call's time over "
        "the fixed run's of the same case and round. Noise `poisson`: 1000 photo-electrons at full scale and "
        "1 % read noise.",
        "",
        "| scene | size | noise | run | PSNR | SSIM | - interp3d dB | iterations | seconds (search) | / fixed |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    print("\n".join(page), flush=True)
    results, skipped = [], []
    for scene, size, noise in selected(args):
        if not available(scene):
            skipped.append(scene)
            continue
        r = run_case(scene, size, noise, args.device, cache, args.rounds)
        results.append(((scene, size, noise), r))
        for line in rows(scene, size, noise, r):
            page.append(line)
            print(line, flush=True)
    if skipped:
        page += ["", f"Skipped (no ../shared/data): {', '.join(sorted(set(skipped)))}."]
    if results:
        page += [
            "",
            "Worst and mean PSNR of each rung against interp3d over these cases, and the range of its cases' "
            "median time over the fixed run's:",
            "",
        ]
        sizes = sorted({size for (_, size, _), _ in results})
        for label, _ in RUNS:
            diff = [r[label]["psnr"] - r["interp3d"]["psnr"] for _, r in results]
            spans = []
            for size in sizes:
                ratios = [r[label]["ratio"] for (_, s, _), r in results if s == size]
                spans.append(f"time over the fixed run at {size}: {min(ratios):.2f}-{max(ratios):.2f}x")
            psnr_line = f"worst {min(diff):+.2f} dB, mean {float(np.mean(diff)):+.2f} dB"
            page.append(f"- {label}: {psnr_line}; {'; '.join(spans)}")
    if args.plot is not None and results:
        pareto_plot(args.plot, results)
        page += ["", f"![time against PSNR and SSIM]({args.plot.name})"]
    write_page(args.out, page)


if __name__ == "__main__":
    main()
