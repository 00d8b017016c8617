"""The hold-out design of the self-tuning: block size and patterns, measured over rigs and scenes.

:func:`rsocl.solver.crossval.tune_parameters` holds one camera out of each square block of the
grid, fits the candidates on the rest and scores them on the held-out pixels. Which camera a
block holds out decides which scene content tests which camera. The designs compared: blocks of
half (``1/2``) or a quarter (``1/4``) of the grid's smaller side, in one pattern or two (``x2``:
the second with the held-out cameras shifted), both sizes pooled (``1/2 + 1/4 x2``), and
rsocl's ``default`` (:func:`~rsocl.solver.holdout.default_patterns`). More patterns are added
where one leaves a camera never held out. All at equal cost: 50 ADMM iterations per candidate,
shared among the patterns (what the default search runs for a run of 200 iterations).

For each rig and scene: the PSNR of full runs (``--iterations`` ADMM iterations, start from
interp3d, as the tuned default runs) on the grid of temporal weights 1, 1.73, 3, 5.48, 10, 17.3,
30 x ``lam`` factors 0.3, 1, 3 (every point the search can choose), then, per design, the search
itself (:func:`~rsocl.solver.crossval.tune_parameters`, no ground truth) and the PSNR of its choice.
"best" is the best point of the grid of the quality benchmark (weights 1, 3, 10, 30 x the three
``lam``), chosen with the ground truth. Rigs: the paper array of 2, 3, 4, 7 and 8 cameras and
rotations other than the paper's (0/30/60/90, 0/90/45/135, 0/45 degrees). Scenes:
``benchmarks/quality_scenes.py`` (the video scenes need ``../shared/data`` and are skipped
without it). Writes ``docs/tuning_design.md``.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from case_cache import Cache  # noqa: E402
from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import available, make_scene  # noqa: E402

WEIGHTS = (1.0, math.sqrt(3.0), 3.0, math.sqrt(30.0), 10.0, math.sqrt(300.0), 30.0)
COARSE = (1.0, 3.0, 10.0, 30.0)
LAM_FACTORS = (0.3, 1.0, 3.0)
RIGS = ("paper4", "0/30/60/90", "0/90/45/135", "paper7", "paper3", "paper2", "paper8", "0/45")
SCENES = (
    "builtin",
    "builtin-fast",
    "builtin-slow",
    "runner40@1",
    "runner40@0.5",
    "traffic48@1",
    "traffic48@2",
    "runner40-crop@1",
)
#: name -> scales of :func:`rsocl.solver.holdout.default_patterns`: (block side as a fraction of the grid's
#: smaller side, patterns at least; more when a camera would never be held out); None: rsocl's default
DESIGNS = {
    "1/2": ((0.5, 1),),
    "1/2 x2": ((0.5, 2),),
    "1/4": ((0.25, 1),),
    "1/4 x2": ((0.25, 2),),
    "1/2 + 1/4 x2": ((0.5, 1), (0.25, 2)),
    "default": None,
}
#: ADMM iterations per candidate, shared among the patterns (at least 10 each): what the default
#: search runs for a run of 200 iterations
BUDGET = 50


def make_rig(name, size):
    """``paperN``: the paper array of N cameras; ``a/b/...``: cameras at those angles, degrees."""
    import rsocl

    if name.startswith("paper"):
        return rsocl.Rig.paper_array(int(name[len("paper") :]), (size, size), t_e=0.18e-3, t_r=35e-6)
    cameras = [rsocl.Camera(float(a), t_e=0.18e-3, t_r=35e-6) for a in name.split("/")]
    return rsocl.Rig(cameras, (size, size))


def key(weight, factor) -> str:
    return f"{weight:.4g},{factor:g}"


def run_case(rig_name, scene, size, iterations, device, done=None):
    """PSNR (dB) of interp3d, of full runs on the grid, and each design's choice (``done``: what an
    earlier run computed of them)."""
    from rsocl.analysis.metrics import psnr
    from rsocl.model.curvature import default_scale
    from rsocl.model.interpolation import interp3d
    from rsocl.model.interpolation_device import interp3d_device
    from rsocl.model.simulate import simulate
    from rsocl.solver.admm import ADMM
    from rsocl.solver.crossval import SearchSpace, tune_parameters
    from rsocl.solver.holdout import default_patterns
    from rsocl.solver.problem import check_problem, check_settings, stage_on_device
    from rsocl.solver.request import make_regularizer

    rig = make_rig(rig_name, size)
    truth = make_scene(scene, rig.shape, rig.T)
    g = simulate(truth, rig)
    tv = make_regularizer("tv")
    problem = check_problem(g, rig)
    settings = check_settings(iterations=iterations).settled_for(tv, "float32", scale=default_scale(rig))
    staged = stage_on_device(problem, tv, settings, device=device, start=True)
    op, solved = staged.op, rig.sampled_range()
    start = interp3d_device(op, problem.g, None, solved)

    def make(options):
        return make_regularizer("tv", options)

    def full(weight, lam):
        solver = ADMM(op, staged.g, make({"temporal_weight": weight}), lam=lam, eta=settings.eta, x0=start)
        for _ in range(iterations):
            solver.step()
        x = np.zeros_like(truth)
        x[solved] = solver.theta.get()
        return float(psnr(x, truth, data_range=1.0))

    if done is None:
        done = {
            "interp3d": float(psnr(interp3d(g, rig), truth, data_range=1.0)),
            "grid": {key(w, f): full(w, settings.lam * f) for w in WEIGHTS for f in LAM_FACTORS},
            "designs": {},
        }
    out = done
    for name, scales in DESIGNS.items():
        if name in out["designs"]:
            continue
        patterns = default_patterns(rig.shape, rig.n_channels, scales)
        begin = time.perf_counter()
        space = SearchSpace({"temporal_weight": COARSE}, [settings.lam * f for f in LAM_FACTORS])
        tuning = tune_parameters(
            op,
            staged.g,
            problem.g,
            make,
            space,
            eta=settings.eta,
            patterns=patterns,
            iterations=max(10, round(BUDGET / len(patterns))),
        )
        weight, lam = tuning.chosen["temporal_weight"], tuning.chosen["lam"]
        out["designs"][name] = {
            "weight": weight,
            "factor": lam / settings.lam,
            "psnr": out["grid"][key(weight, lam / settings.lam)],
            "seconds": time.perf_counter() - begin,
            "patterns": len(patterns),
        }
    return out


def best_of_grid(grid):
    """``(psnr, weight, factor)`` of the best point of the quality benchmark's grid."""
    return max((grid[key(w, f)], w, f) for w in COARSE for f in LAM_FACTORS)


def summary(cases, name):
    """One Markdown row: a design's loss to the grid's best and gain over interp3d over the cases."""
    loss = np.array([c["designs"][name]["psnr"] - best_of_grid(c["grid"])[0] for c in cases])
    gain = np.array([c["designs"][name]["psnr"] - c["interp3d"] for c in cases])
    seconds = np.median([c["designs"][name]["seconds"] for c in cases])
    return (
        f"| {name} | {loss.mean():+.2f} | {np.median(loss):+.2f} | {loss.min():+.2f} | "
        f"{int((loss < -0.3).sum())} | {int((gain < 1.0).sum())} | {seconds:.2f} |"
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=48, help="grid side, pixels (>= 16)")
    parser.add_argument("--iterations", type=int, default=100, help="ADMM iterations of a full run (>= 10)")
    parser.add_argument("--rigs", nargs="+", default=list(RIGS))
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--device", default=None)
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "rsocl-tuning-design.json")
    parser.add_argument("--out", type=Path, default=DOCS / "tuning_design.md")
    args = parser.parse_args(argv)
    if args.size < 16 or args.iterations < 10:
        raise SystemExit("--size must be >= 16 and --iterations >= 10")
    import rsocl

    device = rsocl.device.get_device(args.device)
    cache = Cache(args.cache)
    cases, skipped = [], set()
    for rig_name in args.rigs:
        for scene in args.scenes:
            if not available(scene):
                skipped.add(scene)
                continue
            case_key = f"{rig_name}|{scene}|{args.size}|{args.iterations}"
            earlier = cache[case_key] if case_key in cache else None
            if set((earlier or {}).get("designs", {})) != set(DESIGNS):
                cache.put(case_key, run_case(rig_name, scene, args.size, args.iterations, args.device, earlier))
            cases.append({"rig": rig_name, "scene": scene, **cache[case_key]})
            print(rig_name, scene, {n: round(d["psnr"], 2) for n, d in cache[case_key]["designs"].items()}, flush=True)
    page = header_lines("The hold-out design of the self-tuning", device, None if argv is None else [__file__, *argv])
    page += [
        __doc__.split("\n\n", 1)[1].strip(),
        "",
        f"{args.size}x{args.size} pixels, {args.iterations} ADMM iterations per full run, float32, noiseless, "
        "t_e = 180 µs, t_r = 35 µs; lam factors of the rig's default lam.",
        "",
        f"## Over {len(cases)} cases ({len(args.rigs)} rigs x {len(cases) // max(len(args.rigs), 1)} scenes)",
        "",
        "Loss: the design's choice minus the grid's best (dB); below interp3d + 1 dB: cases whose choice is "
        "less than 1 dB above interp3d (for some scenes no grid point is).",
        "",
        "| design | mean loss | median loss | worst loss | cases more than 0.3 dB below | "
        "below interp3d + 1 dB | search s (median) |",
        "|---|---|---|---|---|---|---|",
    ]
    page += [summary(cases, name) for name in DESIGNS]
    page += [
        "",
        "## Per case",
        "",
        "PSNR in dB; each design's choice as temporal weight, lam factor.",
        "",
        "| rig | scene | interp3d | best (weight, factor) | " + " | ".join(DESIGNS) + " |",
        "|---|---|---|---|" + "---|" * len(DESIGNS),
    ]
    for c in cases:
        best, w, f = best_of_grid(c["grid"])
        cells = [f"{d['psnr']:.2f} ({d['weight']:.3g}, {d['factor']:g})" for d in c["designs"].values()]
        page.append(
            f"| {c['rig']} | {c['scene']} | {c['interp3d']:.2f} | {best:.2f} ({w:g}, {f:g}) | "
            + " | ".join(cells)
            + " |"
        )
    if skipped:
        page += ["", f"Skipped (no ../shared/data): {', '.join(sorted(skipped))}."]
    write_page(args.out, page)


if __name__ == "__main__":
    main()
