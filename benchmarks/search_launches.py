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
``gpu`` path), and checks that both searches choose the same values. Wall times are printed too, but
on a CPU device batches do not pay (its kernels' work, not their launches, bounds it): there the
launch counts are the measurement.

    python benchmarks/search_launches.py [--sizes 50 128] [--device SPEC] [--out docs/search_launches.md]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from launches import case, counting, path  # noqa: E402
from provenance import DOCS, header_lines, write_page  # noqa: E402

import rsocl  # noqa: E402
from rsocl.device.context import get_device  # noqa: E402
from rsocl.solver import search_batch  # noqa: E402


def _timed(fn):
    with counting() as counts:
        start = time.perf_counter()
        result = fn()
        seconds = time.perf_counter() - start
    return result, seconds, dict(counts)


def measure(m: int, device) -> dict:
    """Counts and times of the three runs at ``m``×``m`` on the GPU path."""
    rig, g = case(m)
    out = {}
    with path("gpu"):
        rsocl.reconstruct(g, rig, iterations=3, device=device)  # builds
        tuned, out["tuned"], out["tuned_counts"] = _timed(lambda: rsocl.reconstruct(g, rig, device=device))
        saved = search_batch.CANDIDATES
        search_batch.CANDIDATES = 1
        try:
            alone, out["alone"], out["alone_counts"] = _timed(lambda: rsocl.reconstruct(g, rig, device=device))
        finally:
            search_batch.CANDIDATES = saved
        chosen = tuned.params["tuning"]["chosen"]
        options = {k: v for k, v in chosen.items() if k != "lam"}
        _, out["fixed"], out["fixed_counts"] = _timed(
            lambda: rsocl.reconstruct(
                g,
                rig,
                iterations=tuned.params["iterations"],
                tune=False,
                x0="interp3d",
                lam=chosen["lam"],
                regularizer_options=options,
                device=device,
            )
        )
    out.update(
        m=m,
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
        line.append(
            f"| {r['m']}×{r['m']} | {label} | {launches[key]} | {c['enqueue_copy']} | {c['enqueue_fill_buffer']} | "
            f"{launches[key] / launches['fixed']:.2f} | {r[key]:.3f} |"
        )
    return line


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[50, 128], help="ROI sides m (m × m), pixels")
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", type=Path, default=DOCS / "search_launches.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if min(args.sizes) < 8:
        raise SystemExit("--sizes must be >= 8")
    device = get_device(args.device)
    page = header_lines(
        "The self-tuned default's launches against a fixed run", device, None if argv is None else [__file__, *argv]
    )
    page += [
        "Paper array (4 cameras at 0/90/180/270°, t_e = 0.18 ms, t_r = 35 µs), the built-in scene, float32, the "
        "default rung (`balanced`: 200 iterations; frames of 96 pixels or more search a central 48×48 block), "
        "on the paths a GPU takes (the device read as one that is not a CPU). Counts of one call each; "
        "`launches / fixed`: the call's kernel launches over the fixed run's, about its time over the fixed "
        "run's where launches bound a run (a small set on a GPU). Seconds: this device's wall time of the call "
        "(kernel builds excluded).",
        "",
        "| ROI | run | kernel launches | copies | fills | launches / fixed | seconds |",
        "|---|---|---|---|---|---|---|",
    ]
    notes = []
    for m in args.sizes:
        r = measure(m, device)
        page += rows(r)
        print("\n".join(page[-3:]), file=sys.stderr, flush=True)
        notes.append(
            f"- {m}×{m} (T = {r['T']}): {r['candidates']} candidates on {r['folds']} hold-out pattern(s), chosen "
            f"{r['chosen']}; the two searches chose {'the same values' if r['same'] else 'DIFFERENT values'}."
        )
    page += [""] + notes + [""]
    print("\n".join(page))
    write_page(args.out, page)


if __name__ == "__main__":
    main()
