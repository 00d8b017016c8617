"""TV's inner iterations per ADMM iteration: PSNR and time of the default run at 10, 5 and 3.

Each ADMM iteration calls the TV denoiser (Chambolle's algorithm from a zero dual), and its
inner iterations are most of an iteration's time. For every case this script runs
``rsocl.reconstruct`` (200 ADMM iterations, float32) with ``tv_iterations`` = each of
``--counts``, self-tuned (the default: ``lam``, the temporal weight and the blend with the
interpolation chosen from the snapshots for that count) and, on the paper array, also with
fixed settings from zeros (``tune=False``: ``lam`` 0.1, temporal weight 3), and reports PSNR
(dB, peak 1) against the first count, runs below ``interp3d``, and the time of each run
against the first count's (wall clock, compile excluded; the same process runs the counts in
turn, so the machine's drift hits them alike).

Cases: the groups of ``benchmarks/tuning_blend.py`` (random rigs of ``benchmarks/tv_step.py``,
one-camera rigs included here, in three groups of seeds and scenes, noiseless and with Poisson
noise plus 1 % read noise; the paper array's scenes of ``benchmarks/quality.py`` at 64x64 and
128x128). ``design`` is the group a default would be chosen on; the others are held out.
Results are cached per case (``--cache``). Writes docs/tv_iterations.md.

    python benchmarks/tv_iterations.py [--groups design check-a check-b paper] [--counts 10 5 3]
        [--out docs/tv_iterations.md]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

import rsocl
from rsocl.analysis.metrics import psnr
from rsocl.model.interpolation import interp3d

sys.path.insert(0, str(Path(__file__).resolve().parent))
from case_cache import Cache  # noqa: E402
from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import available, case_data  # noqa: E402
from tuning_blend import GROUPS  # noqa: E402
from tuning_blend import cases as blend_cases

ITERATIONS = 200
COUNTS = (10, 5, 3)


def cases(group):
    """``(key, rig, scene, photons, modes)`` of a group of ``tuning_blend.py`` (one-camera rigs included);
    ``modes``: "tuned", and "fixed" on the paper array."""
    for key, rig, scene, photons in blend_cases(group, one_camera=True):
        yield key, rig, scene, photons, ("tuned", "fixed") if GROUPS[group][0] is None else ("tuned",)


def run_case(rig, scene, photons, modes, counts, device):
    """PSNR of interp3d; per mode and count: PSNR, seconds and the chosen values."""
    truth, g = case_data(scene, rig, photons)
    out = {"interp3d": float(psnr(interp3d(g, rig), truth, data_range=1.0))}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rsocl.reconstruct(g, rig, iterations=2, device=device, tune=False)  # compile outside the timing
        for mode in modes:
            for k in counts:
                t0 = time.perf_counter()
                result = rsocl.reconstruct(
                    g, rig, iterations=ITERATIONS, tv_iterations=k, device=device, tune=mode == "tuned"
                )
                seconds = time.perf_counter() - t0
                options = result.params.get("regularizer_options", {})
                out[f"{mode}{k}"] = {
                    "psnr": float(psnr(result.datacube, truth, data_range=1.0)),
                    "seconds": seconds,
                    "lam": float(result.params["lam"]),
                    "blend": float(result.params.get("blend", 1.0)),
                    "temporal_weight": float(options.get("temporal_weight", 0.0)),
                }
    return out


def summary_rows(label, results, mode, counts):
    """Rows per other count: PSNR change against counts[0] (mean, worst, best), below interp3d, time ratio."""
    base = f"{mode}{counts[0]}"
    rows = []
    for k in counts[1:]:
        key = f"{mode}{k}"
        level = [r for r in results if key in r and base in r]
        if not level:
            continue
        change = np.array([r[key]["psnr"] - r[base]["psnr"] for r in level])
        ratio = np.array([r[key]["seconds"] / r[base]["seconds"] for r in level])
        below = (
            sum(r[base]["psnr"] < r["interp3d"] for r in level),
            sum(r[key]["psnr"] < r["interp3d"] for r in level),
        )
        rows.append(
            f"| {label} | {mode} | {len(level)} | {k} | {change.mean():+.2f} | {change.min():+.2f} | "
            f"{change.max():+.2f} | {int(np.sum(change < -0.1))} | {below[0]} -> {below[1]} | "
            f"{np.median(ratio):.2f}x |"
        )
    return rows


def plot(path, pooled, counts):
    """``path`` (PNG): each tuned case's PSNR change against its time ratio, per count other than the
    first, noiseless and noisy side by side; returns the file's name."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rsocl.files.atomic import atomic_path

    base = f"tuned{counts[0]}"
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, (level, cases_of_level) in zip(axes, pooled.items()):
        for k, colour in zip(counts[1:], ("tab:blue", "tab:orange", "tab:green", "tab:red")):
            ratio = [r[f"tuned{k}"]["seconds"] / r[base]["seconds"] for r in cases_of_level]
            change = [r[f"tuned{k}"]["psnr"] - r[base]["psnr"] for r in cases_of_level]
            ax.scatter(ratio, change, s=9, alpha=0.5, color=colour, label=f"{k} TV iterations")
        ax.axhline(0.0, color="grey", lw=0.8)
        ax.set_title(f"{'noiseless' if level == 'none' else 'with noise'} ({len(cases_of_level)} cases)")
        ax.set_xlabel(f"time / time at {counts[0]} TV iterations")
    axes[0].set_ylabel(f"PSNR - PSNR at {counts[0]} TV iterations (dB)")
    axes[0].legend(loc="lower right")
    fig.suptitle("Self-tuned default, every group: fewer inner TV iterations")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=80)
    plt.close(fig)
    return Path(path).name


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--groups", nargs="+", choices=list(GROUPS), default=list(GROUPS))
    parser.add_argument(
        "--counts",
        type=int,
        nargs="+",
        default=list(COUNTS),
        help="TV iterations per ADMM iteration (>= 1); the first is the reference",
    )
    parser.add_argument("--device", default=None)
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "rsocl-tv-iterations-cache.json")
    parser.add_argument("--out", type=Path, default=DOCS / "tv_iterations.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if any(k < 1 for k in args.counts) or len(set(args.counts)) != len(args.counts):
        parser.error(f"--counts must be distinct integers >= 1, got {args.counts}")
    counts = tuple(args.counts)
    cache = Cache(args.cache)
    op = rsocl.RollingShutterOperator(rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6), device=args.device)
    page = header_lines(
        "TV iterations per ADMM iteration: quality and time", op.device, None if argv is None else [__file__, *argv]
    )
    page += [
        f"`rsocl.reconstruct` ({ITERATIONS} ADMM iterations, float32) with `tv_iterations` = "
        f"{', '.join(map(str, counts))}: self-tuned (`tuned`, the default) and, on the paper array, fixed "
        "settings from zeros (`fixed`, `tune=False`). PSNR in dB with peak 1; change: PSNR at the count minus "
        f"PSNR at {counts[0]}; time: the run's wall time (search included) over the run's at {counts[0]}, "
        "median over the cases. Noise: Poisson at the given photo-electrons at full scale plus 1 % read "
        "noise. Groups (see `benchmarks/tuning_blend.py`): `design` (random rigs of seeds 100-139 x built-in "
        "scene and Runner at 1 frame per sub-frame), `check-a` (seeds 160-199 x Traffic at 1 and the slow "
        "built-in scene), `check-b` (seeds 140-159 x Runner at 2 and Traffic at 0.5), `paper` (the paper "
        "array's scenes of `benchmarks/quality.py`, 64x64 and 128x128). A case found in the cache (`--cache`) "
        "is not run again: its numbers are those of the run that measured it.",
        "",
        "| group | mode | cases | TV iterations | change mean | worst | best | cases below -0.1 dB | "
        f"runs below interp3d: {counts[0]} -> this | time vs {counts[0]} |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    detail, skipped = [], set()
    pooled = {"none": [], "noisy": []}  # tuned cases of every group
    for group in args.groups:
        results = {"tuned": {}, "fixed": {}}
        for key, rig, scene, photons, modes in cases(group):
            if not available(scene):
                skipped.add(scene)
                continue
            name = f"{key}|{scene}|{photons}|{ITERATIONS}|{','.join(map(str, counts))}"
            r = cache.get(
                name,
                lambda rig=rig, scene=scene, photons=photons, modes=modes: run_case(
                    rig, scene, photons, modes, counts, args.device
                ),
            )
            noise = "none" if photons is None else f"{photons:g}"
            for mode in modes:
                results[mode].setdefault(noise, []).append(r)
                if mode == "tuned":
                    pooled["none" if photons is None else "noisy"].append(r)
                what = "paper array" if GROUPS[group][0] is None else f"{key}, {rig.n_channels} cameras"
                cells = " | ".join(f"{r[f'{mode}{k}']['psnr']:.2f}" for k in counts)
                detail.append(
                    f"| {group} | {what}, {rig.shape[0]}x{rig.shape[1]} | {scene} | {noise} | {mode} | "
                    f"{r['interp3d']:.2f} | {cells} |"
                )
                print(detail[-1], flush=True)
        for mode in ("tuned", "fixed"):
            for noise, level in results[mode].items():
                page += summary_rows(f"{group}, noise {noise}", level, mode, counts)
    for level, pooled_cases in pooled.items():
        page += summary_rows(
            f"every group, {'noiseless' if level == 'none' else 'noisy'}", pooled_cases, "tuned", counts
        )
    if pooled["none"] or pooled["noisy"]:
        picture = plot(args.out.with_suffix(".png"), pooled, counts)
        page += ["", f"![PSNR change against time, per case]({picture})"]
    if skipped:
        page += ["", f"Skipped (no ../shared/data): {', '.join(sorted(skipped))}."]
    page += [
        "",
        "## Per case (PSNR, dB)",
        "",
        "| group | rig | scene | photo-electrons | mode | interp3d | " + " | ".join(f"TV {k}" for k in counts) + " |",
        "|---|---|---|---|---|---|" + "---|" * len(counts),
    ] + detail
    write_page(args.out, page)


if __name__ == "__main__":
    main()
