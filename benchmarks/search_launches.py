"""What the self-tuned default launches beside a fixed run, with the search's candidates batched or not.

On a GPU a small reconstruction is bound by its kernel launches (``docs/launches.md``), so the
self-tuned default's cost over a fixed run is about the ratio of their launches. This script counts
every kernel launch (``enqueue_nd_range_kernel``), copy and fill of:

- **fixed**: ``rsocl.reconstruct(g, rig, tune=False, x0="interp3d")`` with the values the search chose
  and the same iterations (the run the self-tuned default ends with, without its search);
- **tuned, rounds batched**: the default ``rsocl.reconstruct(g, rig)``, its search running each round's
  candidates on all hold-out patterns as one batch (``rsocl.solver.search_batch``);
- **tuned, one candidate per batch**: the same with ``search_batch.CANDIDATES = 1`` (each candidate's
  folds as one batch, the candidates one after the other);

on the paths a GPU takes (the device read as one that is not a CPU, as ``benchmarks/launches.py``'s
``gpu`` path), and checks that both searches choose the same values. Then ``--rounds`` rounds time the
three calls again in rotating order: the median wall time of each, and each tuned call's time over the
fixed run's of its round (median and range). On a CPU device batches do not pay (its kernels' work, not
their launches, bounds it): there the launch counts are the measurement.

The scenes (``benchmarks/quality_scenes.py``) differ in what the search chooses, and so in its batches:
where the coarse temporal weight chosen first lies inside the range (``builtin-slow``), the second round
holds two midpoints and the ``lam`` values of three weights, 8 candidates, against 5 where it lies at an
edge (``builtin``). The launches are the same; the time of a batch grows with its sets where the kernels'
work, not their launches, bounds it. The page is written again after each scene and size.

    python benchmarks/search_launches.py [--sizes 50 128] [--scenes builtin builtin-slow] [--rounds 3]
                                         [--device SPEC] [--out docs/search_launches.md]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from contextlib import contextmanager
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from launches import case, counting, path  # noqa: E402
from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import available  # noqa: E402

import rsocl  # noqa: E402
from rsocl.device.context import get_device  # noqa: E402
from rsocl.solver import search_batch  # noqa: E402

#: Scenes of :func:`quality_scenes.make_scene` measured by default: the search's second round of 5 and of 8
#: candidates on the paper array at 50×50.
SCENES = ("builtin", "builtin-slow")


@contextmanager
def batch_sets():
    """Record the sets (candidates x folds) of each batch the search runs while the block runs; yields the list."""
    sizes, run = [], search_batch.BatchedFolds._run

    def recorded(self, op, g_device, folds, reg, lams, *args):
        sizes.append(len(lams) * len(folds))
        return run(self, op, g_device, folds, reg, lams, *args)

    search_batch.BatchedFolds._run = recorded
    try:
        yield sizes
    finally:
        search_batch.BatchedFolds._run = run


def _timed(fn):
    with counting() as counts:
        start = time.perf_counter()
        result = fn()
        seconds = time.perf_counter() - start
    return result, seconds, dict(counts)


def _alone(call):
    """``call()`` with the search's candidates one per batch (``search_batch.CANDIDATES = 1``)."""
    saved = search_batch.CANDIDATES
    search_batch.CANDIDATES = 1
    try:
        return call()
    finally:
        search_batch.CANDIDATES = saved


def measure(m: int, device, rounds: int = 3, scene: str = "builtin") -> dict:
    """Counts of the three runs at ``m``×``m`` of ``scene`` on the GPU path (one call each), then ``rounds``
    rounds of the three in rotating order: ``out[key]`` the median seconds, ``out[key + "_rounds"]`` each
    round's; ``out["batches"]`` the sets of each batch of the tuned call's search."""
    rig, g = case(m, scene)
    out = {}
    with path("gpu"):
        rsocl.reconstruct(g, rig, iterations=3, device=device)  # builds
        with batch_sets() as out["batches"]:
            tuned, _, out["tuned_counts"] = _timed(lambda: rsocl.reconstruct(g, rig, device=device))
        alone, _, out["alone_counts"] = _alone(lambda: _timed(lambda: rsocl.reconstruct(g, rig, device=device)))
        chosen = tuned.params["tuning"]["chosen"]
        options = {k: v for k, v in chosen.items() if k != "lam"}
        fixed_kw = dict(
            iterations=tuned.params["iterations"],
            tune=False,
            x0="interp3d",
            lam=chosen["lam"],
            regularizer_options=options,
            device=device,
        )
        _, _, out["fixed_counts"] = _timed(lambda: rsocl.reconstruct(g, rig, **fixed_kw))
        calls = {
            "fixed": lambda: rsocl.reconstruct(g, rig, **fixed_kw),
            "tuned": lambda: rsocl.reconstruct(g, rig, device=device),
            "alone": lambda: _alone(lambda: rsocl.reconstruct(g, rig, device=device)),
        }
        keys = list(calls)
        for key in keys:
            out[f"{key}_rounds"] = []
        for r in range(rounds):
            for key in keys[r % 3 :] + keys[: r % 3]:
                start = time.perf_counter()
                calls[key]()
                out[f"{key}_rounds"].append(time.perf_counter() - start)
    for key in keys:
        out[key] = statistics.median(out[f"{key}_rounds"])
    out.update(
        m=m,
        scene=scene,
        T=rig.T,
        same=chosen == alone.params["tuning"]["chosen"],
        chosen=chosen,
        candidates=len(tuned.params["tuning"]["candidates"]),
        folds=tuned.params["tuning"]["folds"],
    )
    return out


def rows(r) -> list:
    launches = {k: r[f"{k}_counts"]["enqueue_nd_range_kernel"] for k in ("fixed", "tuned", "alone")}
    line = []
    for key, label in (
        ("fixed", "fixed"),
        ("tuned", "tuned, rounds batched"),
        ("alone", "tuned, one candidate per batch"),
    ):
        c = r[f"{key}_counts"]
        ratios = [a / b for a, b in zip(r[f"{key}_rounds"], r["fixed_rounds"])]
        batches = ", ".join(map(str, r["batches"])) if key == "tuned" else ""
        line.append(
            f"| {r['scene']} | {r['m']}×{r['m']} | {label} | {batches} | {launches[key]} | {c['enqueue_copy']} | "
            f"{c['enqueue_fill_buffer']} | "
            f"{launches[key] / launches['fixed']:.2f} | {r[key]:.3f} | "
            f"{statistics.median(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f}) |"
        )
    return line


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[50, 128], help="ROI sides m (m × m), pixels")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), help="scenes of benchmarks/quality_scenes.py")
    parser.add_argument("--rounds", type=int, default=3, help="timed rounds of the three calls (>= 1)")
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", type=Path, default=DOCS / "search_launches.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if min(args.sizes) < 8 or args.rounds < 1:
        raise SystemExit("--sizes must be >= 8 and --rounds >= 1")
    missing = [name for name in args.scenes if not available(name)]
    if missing:
        raise SystemExit(f"--scenes: {missing} need their videos in ../shared/data; the built-in ones need none")
    device = get_device(args.device)
    page = header_lines(
        "The self-tuned default's launches against a fixed run", device, None if argv is None else [__file__, *argv]
    )
    page += [
        "Paper array (4 cameras at 0/90/180/270°, t_e = 0.18 ms, t_r = 35 µs), scenes of "
        "`benchmarks/quality_scenes.py`, float32, the "
        "default rung (`balanced`: 200 iterations; frames of 96 pixels or more search a central 48×48 block), "
        "on the paths a GPU takes (the device read as one that is not a CPU). Counts of one call each; "
        "`launches / fixed`: the call's kernel launches over the fixed run's, about its time over the fixed "
        "run's where launches bound a run (a small set on a GPU). Seconds: this device's wall time of the call "
        f"(kernel builds excluded), the median of {args.rounds} rounds of the three calls in rotating order; "
        "`time / fixed`: the call's time over the fixed run's in the same round (median and range). "
        "`search batches`: the sets (candidates × hold-out patterns) of each batch the tuned call's search ran.",
        "",
        "| scene | ROI | run | search batches | kernel launches | copies | fills | launches / fixed | seconds | "
        "time / fixed |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    for scene in args.scenes:
        for m in args.sizes:
            r = measure(m, device, args.rounds, scene)
            page += rows(r)
            print("\n".join(page[-3:]), file=sys.stderr, flush=True)
            notes.append(
                f"- {scene}, {m}×{m} (T = {r['T']}): {r['candidates']} candidates on {r['folds']} hold-out "
                f"pattern(s), chosen {r['chosen']}; the two searches chose "
                f"{'the same values' if r['same'] else 'DIFFERENT values'}."
            )
            write_page(args.out, page + [""] + notes + [""])  # what is measured so far, if a cap stops the rest
    print("\n".join(page + [""] + notes))


if __name__ == "__main__":
    main()
