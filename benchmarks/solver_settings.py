"""PSNR of rsocl's ADMM on the shared videos with the paper's 4-camera array (docs/model.md protocol).

Reports, for Runner and Traffic at 64x64 (t_e = 180 µs, t_r = 35 µs, dt = t_r):
the default settings (exact projection), the paper's diagonal projection (Eq. 15) at the
paper's lam = 20, eta = 30 and at the best of a small sweep, and a lam/eta/tv_iterations
sweep around the defaults, so the defaults in rsocl.solver.problem.DEFAULTS can be checked.
PSNR in dB with peak 1 (videos scaled to [0, 1]). Prints a Markdown table and writes it to
docs/solver_settings.md (``--out``) with the machine, commit and date it was measured on.

    python benchmarks/solver_settings.py [--size 64] [--iterations 300] [--quick] [--out docs/solver_settings.md]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import rsocl
from rsocl.analysis.metrics import psnr
from rsocl.model.interpolation import interp3d
from rsocl.model.scenes import load_scene
from rsocl.solver.problem import DEFAULTS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import DOCS, header_lines, write_page  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def runs(quick):
    """(label, keyword arguments of rsocl.reconstruct) of every row; ``quick``: the first three."""
    yield "default (exact)", dict(projection="exact")
    yield "paper Eq. 15, lam=20 eta=30", dict(projection="paper", lam=20.0, eta=30.0)
    yield "paper Eq. 15, lam=1 eta=5", dict(projection="paper", lam=1.0, eta=5.0)
    if quick:
        return
    yield "paper Eq. 15 at the defaults (lam=0.1, eta=0.2)", dict(projection="paper")
    yield (
        "paper Eq. 15, lam=20 eta=30, TV temporal_weight=1",
        dict(projection="paper", lam=20.0, eta=30.0, regularizer_options={"temporal_weight": 1.0}),
    )
    for lam in (0.05, 0.2):
        yield f"exact, lam={lam}", dict(lam=lam)
    yield "exact, eta=0.05", dict(eta=0.05)
    yield "exact, eta=1", dict(eta=1.0)
    yield "exact, tv_iterations=5", dict(tv_iterations=5)
    for weight in (1.0, 5.0):
        note = " (scikit-image's 3-D TV)" if weight == 1 else ""
        yield f"exact, TV temporal_weight={weight:g}{note}", dict(regularizer_options={"temporal_weight": weight})
    yield "exact, 2-D TV (temporal_weight=0)", dict(regularizer_options={"temporal_weight": 0.0})
    yield "GAP (eta=0, lam=0.05)", dict(eta=0.0, lam=0.05)
    yield "DCT (3-D, whole frame; its lam=0.3, eta=0.2)", dict(regularizer="dct")
    yield "wavelet (Haar, 3-D), lam=0.06", dict(regularizer="wavelet", lam=0.06)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--iterations", type=int, default=300)
    parser.add_argument("--videos", nargs="+", default=["runner40", "traffic48"])
    parser.add_argument("--quick", action="store_true", help="only the default and the paper's projection")
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", type=Path, default=DOCS / "solver_settings.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if args.size < 8 or args.iterations < 1:
        raise SystemExit("--size must be >= 8 and --iterations >= 1")
    rig = rsocl.Rig.paper_array(4, (args.size, args.size), t_e=0.18e-3, t_r=35e-6)
    op = rsocl.RollingShutterOperator(rig, device=args.device, dtype="float64")
    page = header_lines(
        "Reconstruction quality on the shared videos", op.device, None if argv is None else [__file__, *argv]
    )
    page += [
        f"Paper array, {args.size}x{args.size}, T = {rig.T}, t_e = 180 µs, t_r = 35 µs, dt = t_r; "
        f"videos by the benchmark protocol of docs/model.md; {args.iterations} iterations; rsocl's defaults "
        f"{DEFAULTS} unless the row says otherwise; TV with temporal weight 3 (the `tv` plugin's default). "
        "PSNR in dB with peak 1; 'best (iteration)' is the highest PSNR over the iterations and where it "
        "was reached; ms/iteration is the whole call's wall time per iteration (kernel builds excluded, "
        "PSNR tracking included).",
        "",
        "| video | settings | PSNR @200 | PSNR @last | best (iteration) | ms/iteration |",
        "|---|---|---|---|---|---|",
    ]
    print("\n".join(page), flush=True)
    for video in args.videos:
        path = DATA / f"{video}.npz"
        if not path.exists():
            page.append(f"| {video} | missing: ../shared/data/{path.name} | | | | |")
            print(page[-1], flush=True)
            continue
        truth = load_scene(path, rig.shape, rig.T)
        g = op.forward(truth)
        for label, kwargs in runs(args.quick):
            try:
                # kernel builds are not timed
                rsocl.reconstruct(g, rig, iterations=2, device=args.device, tune=False, **kwargs)
                t0 = time.perf_counter()
                res = rsocl.reconstruct(
                    g, rig, iterations=args.iterations, truth=truth, device=args.device, tune=False, **kwargs
                )
            except FloatingPointError as exc:
                page.append(f"| {video} | {label} | diverged: {str(exc).splitlines()[0][:60]} | | | |")
                print(page[-1], flush=True)
                continue
            p = res.history["psnr"]
            at200 = p[min(199, len(p) - 1)]
            per_it = (time.perf_counter() - t0) / len(p) * 1e3
            page.append(
                f"| {video} | {label} | {at200:.2f} | {p[-1]:.2f} | {p.max():.2f} ({p.argmax() + 1}) | {per_it:.1f} |"
            )
            print(page[-1], flush=True)
        if not args.quick:
            t0 = time.perf_counter()
            estimate = interp3d(g, rig)
            seconds = time.perf_counter() - t0
            db = psnr(estimate, truth, data_range=1.0)
            page.append(
                f"| {video} | interp3d: per-pixel linear interpolation in time (no solver) | {db:.2f} | "
                f"{db:.2f} | | {seconds * 1e3:.1f} (whole) |"
            )
            print(page[-1], flush=True)
    write_page(args.out, page)


if __name__ == "__main__":
    main()
