"""TV's Chambolle step: scikit-image's step against smaller fractions of it, over random rigs and the paper array.

rsocl's TV takes the dual step ``tau = step / (2 (2 + w²))`` (``w``: temporal weight); ``step = 1``
is scikit-image's ``denoise_tv_chambolle``, at the edge of stability of the dual iteration.
Three parts, each run at every ``--steps`` value:

- **random rigs**: ``--rigs`` rigs drawn from seeds 100, 101, ...: 1-8 cameras, at the paper's
  even angles or at random ones, 6-48 pixels a side, ``t_r`` 5-60 µs and ``t_e`` 0.5-12 ``t_r``,
  trigger offsets, gains and the binary mask now and then; scenes: the built-in scene and
  Runner at 1 frame per sub-frame (``../shared/data``; skipped without it); the self-tuned
  default (200 ADMM iterations), its PSNR against ``interp3d``'s;
- **paper array**: 4 cameras, ``t_e`` = 180 µs, ``t_r`` = 35 µs, every scene of
  ``benchmarks/quality_scenes.py`` at 64x64 and three at 128x128, self-tuned default (which starts
  from ``interp3d``);
- **fixed settings from zeros**: the same array, three scenes at each size, ``tune=False``
  (``rsocl reconstruct --fixed``: temporal weight 3, ``lam`` 0.1, start from zeros), where the
  step sets how far 200 iterations get;
- **large denoising weight**: a 7-camera rig of 41x11 pixels with exposures as short as a row
  (``lam`` 3, so ``lam / eta`` = 112), fixed settings, 200 iterations, four temporal weights.

Noiseless, float32. Writes ``docs/tv_step.md``; ``docs/regularizer_defaults.md`` quotes its figures
(why TV's ``step`` defaults to 0.9).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import available, make_scene, scene_names  # noqa: E402

STEPS = (1.0, 0.9, 0.75, 0.5)
PAPER_128 = ("builtin", "runner40@1", "traffic48@1")
LARGE_WEIGHT_ANGLES = (215, 284, 328, 248, 68, 353, 103)


def random_rig(seed):
    """The rig of ``seed``: see the module doc."""
    import rsocl

    rng = np.random.default_rng(seed)
    K = int(rng.integers(1, 9))
    m, n = (int(v) for v in rng.integers(6, 49, 2))
    t_r = float(rng.uniform(5e-6, 60e-6))
    t_e = float(rng.uniform(0.5, 12) * t_r)
    angles = [360.0 * k / K for k in range(K)] if rng.random() < 0.5 else list(rng.uniform(0, 360, K))
    cameras = [
        rsocl.Camera(
            angle=a,
            t_e=t_e,
            t_r=t_r,
            t_a=float(rng.uniform(0, 3) * t_r) if rng.random() < 0.3 else 0.0,
            gain=float(rng.uniform(0.5, 2)) if rng.random() < 0.2 else 1.0,
        )
        for a in angles
    ]
    return rsocl.Rig(cameras, shape=(m, n), mask="binary" if rng.random() < 0.2 else "exact")


def run(g, rig, truth, step, device, **kw):
    """PSNR (dB) and the record of one reconstruction with TV's ``step``."""
    import rsocl
    from rsocl.analysis.metrics import psnr

    options = {**kw.pop("regularizer_options", {}), "step": step}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = rsocl.reconstruct(g, rig, regularizer_options=options, device=device, **kw)
    return psnr(result.datacube, truth, data_range=1.0), result


def chosen(result):
    tuning = result.params.get("tuning")
    if not tuning:
        return ""
    return f"{tuning['chosen']['temporal_weight']:.3g} / {tuning['chosen']['lam']:.2g}"


def tuned_cases(cases, steps, device, **kw):
    """Self-tuned runs (or as ``kw`` says, e.g. ``tune=False``): one row per case,
    ``(name, interp3d, [(psnr, choice) per step])``."""
    import rsocl
    from rsocl.analysis.metrics import psnr
    from rsocl.model.interpolation import interp3d

    rows = []
    for name, rig, scene in cases:
        truth = make_scene(scene, rig.shape, rig.T)
        g = rsocl.RollingShutterOperator(rig).forward(truth)
        base = psnr(interp3d(g, rig), truth, data_range=1.0)
        per = []
        for step in steps:
            value, result = run(g, rig, truth, step, device, **kw)
            per.append((value, chosen(result)))
        rows.append((name, base, per))
        print(
            f"{name}: interp3d {base:.2f} " + " ".join(f"{s:g}: {v:.2f}" for s, (v, _) in zip(steps, per)), flush=True
        )
    return rows


def summary(rows, steps):
    """Markdown rows: per step, its PSNR minus the first step's and minus interp3d's."""
    psnrs = np.array([[v for v, _ in per] for _, _, per in rows])
    interp = np.array([base for _, base, _ in rows])
    out = [
        "| step | mean vs step " + f"{steps[0]:g}" + " | worst | best | mean vs interp3d | worst vs interp3d | "
        "cases below interp3d |",
        "|---|---|---|---|---|---|---|",
    ]
    for j, step in enumerate(steps):
        d = psnrs[:, j] - psnrs[:, 0]
        e = psnrs[:, j] - interp
        out.append(
            f"| {step:g} | {d.mean():+.2f} | {d.min():+.2f} | {d.max():+.2f} | {e.mean():+.2f} | {e.min():+.2f} | "
            f"{int((e < 0).sum())} of {len(e)} |"
        )
    return out


def per_case(rows, steps):
    out = ["| case | interp3d | " + " | ".join(f"step {s:g}" for s in steps) + " |", "|---|---|" + "---|" * len(steps)]
    for name, base, per in rows:
        out.append(f"| {name} | {base:.2f} | " + " | ".join(f"{v:.2f} ({c})" for v, c in per) + " |")
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--steps",
        type=float,
        nargs="+",
        default=list(STEPS),
        help="fractions of scikit-image's step, in (0, 1]; the first is the reference of the differences",
    )
    parser.add_argument("--rigs", type=int, default=60, help="random rigs (>= 0)")
    parser.add_argument("--sizes", type=int, nargs="*", default=[64, 128], help="paper-array grid sides (>= 16)")
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", type=Path, default=DOCS / "tv_step.md")
    args = parser.parse_args(argv)
    if not all(0 < s <= 1 for s in args.steps):
        raise SystemExit(f"--steps must be in (0, 1], got {args.steps}")
    if args.rigs < 0 or any(s < 16 for s in args.sizes):
        raise SystemExit("--rigs must be >= 0 and --sizes >= 16")
    import rsocl
    from rsocl.analysis.metrics import psnr
    from rsocl.model.interpolation import interp3d

    device = rsocl.device.get_device(args.device)
    start = time.perf_counter()
    rig_scenes = [s for s in ("builtin", "runner40@1") if available(s)]
    random_cases = []
    for seed in range(100, 100 + args.rigs):
        rig = random_rig(seed)
        for scene in rig_scenes:
            random_cases.append(
                (f"seed {seed}: {rig.n_channels} cam, {rig.shape[0]}x{rig.shape[1]}, {scene}", rig, scene)
            )
    paper_cases, fixed_cases = [], []
    for size in args.sizes:
        rig = rsocl.Rig.paper_array(4, shape=(size, size), t_e=180e-6, t_r=35e-6)
        for scene in scene_names() if size <= 64 else PAPER_128:
            if available(scene):
                paper_cases.append((f"paper {size}x{size}, {scene}", rig, scene))
        fixed_cases += [(f"paper {size}x{size}, {scene}", rig, scene) for scene in PAPER_128 if available(scene)]
    random_rows = tuned_cases(random_cases, args.steps, device)
    paper_rows = tuned_cases(paper_cases, args.steps, device)
    fixed_rows = tuned_cases(fixed_cases, args.steps, device, tune=False)

    rig = rsocl.Rig([rsocl.Camera(angle=a, t_e=21e-6, t_r=21e-6) for a in LARGE_WEIGHT_ANGLES], shape=(41, 11))
    truth = make_scene("builtin", rig.shape, rig.T)
    g = rsocl.RollingShutterOperator(rig).forward(truth)
    large = [
        f"interp3d: {psnr(interp3d(g, rig), truth, data_range=1.0):.2f} dB; T = {rig.T}.",
        "",
        "| temporal weight | " + " | ".join(f"step {s:g}: PSNR (min, max)" for s in args.steps) + " |",
        "|---|" + "---|" * len(args.steps),
    ]
    for weight in (0.0, 1.0, 3.0, 30.0):
        cells = []
        for step in args.steps:
            value, result = run(
                g, rig, truth, step, device, lam=3.0, tune=False, regularizer_options={"temporal_weight": weight}
            )
            cube = result.datacube
            cells.append(f"{value:.2f} ({cube.min():.2f}, {cube.max():.2f})")
        large.append(f"| {weight:g} | " + " | ".join(cells) + " |")
    eta = result.params["eta"]

    page = header_lines("TV's Chambolle step", device, None if argv is None else [__file__, *argv])
    page += [
        __doc__.split("\n\n", 1)[1].strip(),
        "",
        f"Total time {time.perf_counter() - start:.0f} s. PSNR in dB (peak 1); in brackets the self-tuned "
        "choice, temporal weight / lam.",
        "",
    ]
    if random_rows:
        page += [f"## Random rigs ({len(random_rows)} cases)", ""] + summary(random_rows, args.steps) + [""]
    if paper_rows:
        page += [f"## Paper array ({len(paper_rows)} cases)", ""] + summary(paper_rows, args.steps) + [""]
    if fixed_rows:
        page += [f"## Fixed settings from zeros ({len(fixed_rows)} cases)", ""] + summary(fixed_rows, args.steps)
        page += [""] + per_case(fixed_rows, args.steps) + [""]
    page += [f"## Large denoising weight (lam 3, eta {eta:.3g}, lam / eta = {3.0 / eta:.0f})", ""] + large + [""]
    if random_rows:
        page += ["## Random rigs, per case", ""] + per_case(random_rows, args.steps) + [""]
    if paper_rows:
        page += ["## Paper array, per case", ""] + per_case(paper_rows, args.steps) + [""]
    if not available("runner40@1"):
        page += ["Video scenes skipped: ../shared/data not found."]
    write_page(args.out, page)


if __name__ == "__main__":
    main()
