"""How close ``rsocl plan``'s time of the self-tuned default comes to the run's own.

``rsocl plan`` (:func:`rsocl.solver.plan.estimate` with ``search=True``) costs the self-tuned default as
the parameter search timed on the built-in scene (:func:`rsocl.solver.search_cost.search_seconds`)
plus a fixed run's iterations timed over 3 of them. This script sets that beside what
``rsocl.reconstruct`` (the self-tuned default, 200 iterations, float32) reports for other scenes:
``Result.search_seconds`` and the whole ``Result.seconds``. Rigs: the paper array (``t_e`` =
0.18 ms, ``t_r`` = 35 µs) with 4 cameras at 32x32, 64x64, 128x128 (the search then runs on a
48x48 block) and a 40x160 strip, with 2 and 8 cameras at 48x48, and with 4 at ``dt = 2 t_r``,
64x64. Scenes: the built-in one slowed and sped up, Runner and Traffic at one source frame per
sub-frame (``../shared/data``; left out without it), and Runner with Poisson noise of 1000
photo-electrons and 1 % read noise. Every case is timed in ``--rounds`` rounds, the plan's estimate
and the scenes' runs alternating, after one untimed round that builds the programs. Ratios are
plan / run per round: median and range. Writes docs/plan_search.md.

    python benchmarks/plan_search.py [--rounds 3] [--out docs/plan_search.md]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import rsocl
from rsocl.solver.plan import estimate

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import available, make_scene, noisy  # noqa: E402

T_E, T_R = 0.18e-3, 35e-6
#: (label, cameras, shape, dt as a multiple of t_r)
RIGS = (
    ("4 cameras, 32x32", 4, (32, 32), 1),
    ("4 cameras, 64x64", 4, (64, 64), 1),
    ("4 cameras, 128x128", 4, (128, 128), 1),
    ("4 cameras, 40x160", 4, (40, 160), 1),
    ("2 cameras, 48x48", 2, (48, 48), 1),
    ("8 cameras, 48x48", 8, (48, 48), 1),
    ("4 cameras, 64x64, dt = 2 t_r", 4, (64, 64), 2),
)
#: (label, scene name of quality_scenes, photo-electrons or None)
SCENES = (
    ("builtin-slow", "builtin-slow", None),
    ("builtin-fast", "builtin-fast", None),
    ("runner40@1", "runner40@1", None),
    ("traffic48@1", "traffic48@1", None),
    ("runner40@1, 1000 e-", "runner40@1", 1000.0),
)
ITERATIONS = 200


def make_rig(cameras, shape, dt):
    return rsocl.Rig.paper_array(cameras, shape, t_e=T_E, t_r=T_R, dt=dt * T_R)


def case(rig, device, rounds):
    """``(plan, runs)``: per round, the plan's ``(search, total)`` seconds, and per scene label its runs'."""
    data = {}
    for label, name, photons in SCENES:
        if available(name):
            g = rsocl.simulate(make_scene(name, rig.shape, rig.T), rig, device=device)
            data[label] = g if photons is None else noisy(g, rig, photons=photons)
    plan, runs = [], {label: [] for label in data}
    for r in range(rounds + 1):  # round 0 builds the programs and is not kept
        e = estimate(rig, iterations=ITERATIONS, device=device, search=True)
        timed = {}
        for label, g in data.items():
            params = rsocl.reconstruct(g, rig, iterations=ITERATIONS, device=device).params
            timed[label] = (params["search_seconds"], params["seconds"])
        if r:
            plan.append((e.search_seconds, e.tuned_seconds))
            for label, t in timed.items():
                runs[label].append(t)
    return plan, runs


def ratio_text(plan, run):
    r = np.asarray(plan) / np.asarray(run)
    return f"{np.median(r):.2f} ({r.min():.2f}-{r.max():.2f})"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="timed rounds per case, >= 1 (default 3)")
    parser.add_argument("--device", default=None, help="rsocl device spec (default: rsocl's choice)")
    parser.add_argument("--out", type=Path, default=DOCS / "plan_search.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds must be >= 1, got {args.rounds}")
    device = rsocl.get_device(args.device)
    page = header_lines(
        "rsocl plan's time of the self-tuned default", device, None if argv is None else [__file__, *argv]
    )
    page += [
        __doc__.split("\n\n")[1].replace("\n", " "),
        "",
        "| rig | scene | plan: search | run: search | search, plan / run | plan: whole | run: whole | "
        "whole, plan / run |",
        "|---|---|---|---|---|---|---|---|",
    ]
    searches, wholes = [], []
    for label, cameras, shape, dt in RIGS:
        rig = make_rig(cameras, shape, dt)
        plan, runs = case(rig, device, args.rounds)
        p_search, p_whole = (np.array(v) for v in zip(*plan))
        for scene, timed in runs.items():
            r_search, r_whole = (np.array(v) for v in zip(*timed))
            searches.append(np.median(p_search / r_search))
            wholes.append(np.median(p_whole / r_whole))
            row = (
                f"| {label} | {scene} | {np.median(p_search):.2f} s | {np.median(r_search):.2f} s | "
                f"{ratio_text(p_search, r_search)} | {np.median(p_whole):.2f} s | {np.median(r_whole):.2f} s | "
                f"{ratio_text(p_whole, r_whole)} |"
            )
            page.append(row)
            print(row, flush=True)
    page += [
        "",
        f"Over the {len(searches)} cases, the median ratio plan / run of each case: search "
        f"{np.min(searches):.2f}-{np.max(searches):.2f} (median {np.median(searches):.2f}); whole run "
        f"{np.min(wholes):.2f}-{np.max(wholes):.2f} (median {np.median(wholes):.2f}).",
    ]
    write_page(args.out, page)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
