"""PSNR of rsocl's ADMM on the shared videos with the paper's 4-camera array (MODEL.md protocol).

Reports, for Runner and Traffic at 64x64 (t_e = 180 µs, t_r = 35 µs, dt = t_r):
the default settings (exact projection), the paper's diagonal projection (Eq. 15) at the
paper's lam = 20, eta = 30 and at the best of a small sweep, and a lam/eta/tv_iterations
sweep around the defaults, so the defaults in rsocl.solver.reconstruct.DEFAULTS can be checked.
PSNR in dB with peak 1 (videos scaled to [0, 1]). Prints a Markdown table.

    python benchmarks/quality.py [--size 64] [--iterations 300] [--quick]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import rsocl
from rsocl.solver.reconstruct import DEFAULTS
from rsocl.model.scenes import load_scene

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def runs(quick):
    yield "default (exact)", dict(projection="exact")
    yield "paper Eq. 15, lam=20 eta=30", dict(projection="paper", lam=20.0, eta=30.0)
    yield "paper Eq. 15, lam=1 eta=5", dict(projection="paper", lam=1.0, eta=5.0)
    if quick:
        return
    for lam in (0.05, 0.2):
        yield f"exact, lam={lam}", dict(lam=lam)
    yield "exact, eta=0.05", dict(eta=0.05)
    yield "exact, eta=1", dict(eta=1.0)
    yield "exact, tv_iterations=5", dict(tv_iterations=5)
    yield "exact, 2-D TV (temporal_weight=0)", dict(regularizer_options={"temporal_weight": 0.0})
    yield "GAP (eta=0)", dict(eta=0.0, lam=0.05)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--iterations", type=int, default=300)
    parser.add_argument("--videos", nargs="+", default=["runner40", "traffic48"])
    parser.add_argument("--quick", action="store_true", help="only the default and the paper's projection")
    parser.add_argument("--device", default=None)
    args = parser.parse_args()
    rig = rsocl.Rig.paper_array(4, (args.size, args.size), t_e=0.18e-3, t_r=35e-6)
    op = rsocl.RollingShutterOperator(rig, device=args.device, dtype="float64")
    print(f"paper array, {args.size}x{args.size}, T = {rig.T}, defaults {DEFAULTS}, device {op.device.name}\n")
    print("| video | settings | PSNR @200 | PSNR @last | best (iteration) | ms/iteration |")
    print("|---|---|---|---|---|---|")
    for video in args.videos:
        path = DATA / f"{video}.npz"
        if not path.exists():
            print(f"| {video} | missing: {path} | | | | |")
            continue
        truth = load_scene(path, rig.shape, rig.T)
        g = op.forward(truth)
        for label, kwargs in runs(args.quick):
            t0 = time.perf_counter()
            try:
                res = rsocl.reconstruct(g, rig, iterations=args.iterations, truth=truth, device=args.device, **kwargs)
            except FloatingPointError as exc:
                print(f"| {video} | {label} | diverged: {str(exc).splitlines()[0][:60]} | | | |")
                continue
            p = res.history["psnr"]
            at200 = p[min(199, len(p) - 1)]
            per_it = (time.perf_counter() - t0) / len(p) * 1e3
            print(f"| {video} | {label} | {at200:.2f} | {p[-1]:.2f} | {p.max():.2f} ({p.argmax() + 1}) | "
                  f"{per_it:.1f} |", flush=True)


if __name__ == "__main__":
    main()
