"""The exact projection's inverse blocks on the device against the host, and what a call saves.

``rsocl.solver.inverse.inverse_blocks`` makes ``(eta I + M)⁻¹`` per pixel with a Jacobi
eigen-decomposition on the device (``kernels/inverse.cl``, float64) where the device has fp64, and
with NumPy's ``eigh`` on the host otherwise. This script times both in the same run, alternating,
on the paper array (4 cameras, float32): the blocks alone (from the gram on the device to the
blocks on the device, waited for), and a whole ``rsocl.reconstruct`` call of 1 ADMM iteration
(the fixed cost of a call: set-up, one iteration, read-back). It checks that both give the same
blocks (largest difference over the largest entry).

    python benchmarks/inverse.py [--sizes 8 50 128 256] [--rounds 5] [--calls 7] [--device SPEC]
        [--out docs/inverse.md]
"""

from __future__ import annotations

import argparse
import functools
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import rsocl
from rsocl.device.context import get_device
from rsocl.model import reference as ref
from rsocl.model.operator import RollingShutterOperator
from rsocl.model.scenes import builtin_scene
from rsocl.solver import inverse

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import DOCS, header_lines, write_page  # noqa: E402

ETA = 0.2


def _timed(fn, calls):
    fn()  # warm: builds, first allocations
    times = []
    for _ in range(calls):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def measure(dev, side, rounds, calls):
    """``(blocks: {where: [s per round]}, call: {where: [s per round]}, difference)`` at ``side``×``side``."""
    rig = rsocl.Rig.paper_array(4, (side, side), 0.18e-3, 35e-6)
    op = RollingShutterOperator(rig, device=dev, dtype=np.float32)
    etas = np.array([ETA])
    g = ref.forward(rig, builtin_scene(rig.shape, rig.T)).astype(np.float32)

    def blocks(on_device):
        return inverse.inverse_blocks(op, "exact", etas, None, 1, on_device=on_device)[1].get()

    host, device = blocks(False), blocks(True)
    difference = float(np.abs(host - device).max() / np.abs(host).max())
    chooses = inverse.inverts_on_device

    def call(on_device):
        inverse.inverts_on_device = lambda device, K: on_device
        try:
            rsocl.reconstruct(g, rig, iterations=1, lam=0.1, eta=ETA, tune=False, device=dev)
        finally:
            inverse.inverts_on_device = chooses

    times = {"blocks": {True: [], False: []}, "call": {True: [], False: []}}
    for r in range(rounds):
        order = (True, False) if r % 2 == 0 else (False, True)
        for where in order:
            times["blocks"][where].append(_timed(functools.partial(blocks, where), calls))
            times["call"][where].append(_timed(functools.partial(call, where), calls))
    return times, difference


def _ms(values):
    return f"{statistics.median(values) * 1e3:.2f}"


def rows(side, times, difference):
    out = []
    for what, label in (("blocks", "inverse blocks"), ("call", "a call of 1 ADMM iteration")):
        dev_t, host_t = times[what][True], times[what][False]
        ratios = [d / h for d, h in zip(dev_t, host_t)]
        out.append(
            f"| {side}×{side} | {label} | {_ms(host_t)} | {_ms(dev_t)} | "
            f"{statistics.median(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f}) | "
            + (f"{difference:.1e} |" if what == "blocks" else "|")
        )
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[8, 50, 128, 256], help="ROI sides, pixels")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--calls", type=int, default=7, help="timed calls per variant and round (median)")
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", type=Path, default=DOCS / "inverse.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if min(args.sizes) < 2 or args.rounds < 1 or args.calls < 1:
        raise SystemExit("--sizes must be >= 2, --rounds and --calls >= 1")
    dev = get_device(args.device)
    if not inverse.inverts_on_device(dev, 4):
        raise SystemExit(f"{dev.name!r} has no cl_khr_fp64: rsocl inverts on the host there, nothing to compare")
    page = header_lines(
        "Inverse blocks: on the device against the host", dev, None if argv is None else [__file__, *argv]
    )
    page += [
        f"Paper array (4 cameras at 0/90/180/270°, t_e = 0.18 ms, t_r = 35 µs), float32, eta {ETA}; "
        f"{args.rounds} rounds, the two variants in turn (order reversed every other round), each the "
        f"median of {args.calls} timed calls. *Inverse blocks*: `inverse_blocks` from the operator to the "
        "blocks read back (the gram on the device, then NumPy's `eigh` on the host and an upload, or the "
        "Jacobi kernel of `kernels/inverse.cl`). *A call of 1 ADMM iteration*: `rsocl.reconstruct(..., "
        "iterations=1, tune=False)`, the fixed cost of a call, with the blocks made either way. "
        "Difference: the largest over the blocks, relative to the largest entry.",
        "",
        "| ROI | what | host ms | device ms | device / host (range over rounds) | difference |",
        "|---|---|---|---|---|---|",
    ]
    for side in args.sizes:
        times, difference = measure(dev, side, args.rounds, args.calls)
        page += rows(side, times, difference)
        print("\n".join(page[-2:]), file=sys.stderr, flush=True)
    page.append("")
    print("\n".join(page))
    write_page(args.out, page)


if __name__ == "__main__":
    main()
