"""The block layout of the forward, adjoint, residual and ADMM projection kernels on a GPU, in one run.

Those kernels give each work item a block of ``TILE_R`` rows of ``TILE_W`` neighbouring pixels and
loop over the block's sub-frames. A CPU device takes 8 × 4 pixels (float32) in explicit vectors, for
its SIMD units; a device that is not a CPU takes ``rsocl.model.operator.GPU_BLOCK``. This benchmark
times whole reconstructions with each layout of ``--layouts`` (``WxR``: pixels per row × rows) set
as ``GPU_BLOCK``, in alternating rounds, and checks that every layout computes the same datacube as
the first.

Cases (``--cases``): ``paper``, one set of the paper configuration (4 cameras, 50×50, t_e = 0.18 ms,
t_r = 35 µs, ``--iterations`` ADMM iterations), one ``rsocl.reconstruct`` call timed NumPy in and
NumPy out; ``batchB``, B such sets per call (sets per second); ``sizeM``, one set of M×M timed per
ADMM iteration (``history["time"]``) over ``--size-iterations`` iterations.

On a CPU device the layouts apply only with ``--as-gpu`` (the device read as one that is not a
CPU, with the rest of a GPU's choices): there the times say how a CPU runs a GPU's layout, not how a
GPU would.

    python benchmarks/blocks.py [--device SPEC] [--layouts 8x4 1x1 2x1 4x1 1x2] [--rounds 3]
        [--out docs/gpu/blocks.md]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from launches import path  # noqa: E402
from paper_config import paper_rig  # noqa: E402
from provenance import DOCS, header_lines, write_page  # noqa: E402

import rsocl  # noqa: E402
from rsocl.model.scenes import builtin_scene  # noqa: E402

LAM, ETA = 0.1, 0.2


def layout(text: str) -> tuple[int, int]:
    """``"WxR"`` → ``(W, R)``: pixels per row of a block (1, 2, 4, 8 or 16) and rows (>= 1)."""
    try:
        width, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"a layout is WxR (e.g. 1x1, 8x4), got {text!r}") from None
    if width not in (1, 2, 4, 8, 16) or rows < 1:
        raise argparse.ArgumentTypeError(f"layout {text!r}: W must be 1, 2, 4, 8 or 16 and R >= 1")
    return width, rows


@contextmanager
def gpu_block(block, as_gpu: bool):
    """Run the block with ``GPU_BLOCK = block`` (and the device read as a GPU where ``as_gpu``: launches.py's
    ``gpu`` path, with the rest of a GPU's choices)."""
    from rsocl.model import operator

    saved = operator.GPU_BLOCK
    operator.GPU_BLOCK = block
    try:
        with path("gpu" if as_gpu else "device"):
            yield
    finally:
        operator.GPU_BLOCK = saved


def case_list(args):
    """``[(name, rig, sets, iterations, per_iteration)]`` in ``--cases``' order."""
    out = {}
    for name in args.cases:
        if name == "paper":
            out[name] = (name, paper_rig(), 1, args.iterations, False)
        elif name.startswith("batch") and name[5:].isdigit() and int(name[5:]) >= 1:
            out[name] = (name, paper_rig(), int(name[5:]), args.iterations, False)
        elif name.startswith("size") and name[4:].isdigit() and int(name[4:]) >= 2:
            m = int(name[4:])
            rig = rsocl.Rig.paper_array(4, (m, m), 0.18e-3, 35e-6)
            out[name] = (name, rig, 1, args.size_iterations, True)
        else:
            raise SystemExit(f"--cases: {name!r} is not paper, batchB (B >= 1) or sizeM (M >= 2)")
    return list(out.values())


def measure(case, layouts, args, device):
    """``({layout: [seconds per round]}, {layout: largest |datacube - first layout's|})``."""
    name, rig, sets, iterations, per_iteration = case
    op = rsocl.RollingShutterOperator(rig, device=device)
    g = np.stack([op.forward(builtin_scene(rig.shape, rig.T, seed=s)) for s in range(sets)])
    g = g[0] if sets == 1 else g
    opts = dict(lam=LAM, eta=ETA, tune=False, device=device)

    def run(block):
        with gpu_block(block, args.as_gpu):
            t0 = time.perf_counter()
            res = rsocl.reconstruct(g, rig, iterations=iterations, **opts)
            seconds = time.perf_counter() - t0
        return res.datacube, (float(res.history["time"][-1]) / iterations if per_iteration else seconds)

    cubes = {}
    for block in layouts:  # kernel builds
        cubes[block] = run(block)[0]
    times = {block: [] for block in layouts}
    for r in range(args.rounds):
        k = r % len(layouts)
        for block in layouts[k:] + layouts[:k]:
            times[block].append(run(block)[1])
        print(f"  {name} round {r + 1}: " + ", ".join(f"{w}x{h} {times[(w, h)][-1] * 1e3:.2f} ms" for w, h in layouts))
    first = cubes[layouts[0]]
    return times, {block: float(np.max(np.abs(cube - first))) for block, cube in cubes.items()}


def describe(case) -> str:
    name, rig, sets, iterations, _ = case
    m, n = rig.shape
    if name.startswith("size"):
        return f"one set {m}×{n} (T = {rig.T}), per ADMM iteration"
    return f"paper configuration ({m}×{n}, T = {rig.T}, {iterations} it), " + (
        "one set" if sets == 1 else f"{sets} sets per call"
    )


def table_head(title: str, columns) -> list:
    """Markdown lines that open a section: its title and a table's head (a case column, then ``columns``)."""
    return ["", title, "", "| case | " + " | ".join(columns) + " |", "|---" * (1 + len(columns)) + "|"]


def page(results, layouts, device, args, argv):
    heads = [f"{w}×{h}" for w, h in layouts]
    lines = header_lines("Block layout of the operator and projection kernels", device, argv)[:-1]
    lines += [
        f"float32, `lam` {LAM}, `eta` {ETA}, fixed settings (`tune=False`), the built-in scene (seed = set); "
        f"{args.rounds} rounds with the layouts in rotating order, medians. A layout W×R gives each work item "
        "R rows of W neighbouring pixels (`rsocl.model.operator.GPU_BLOCK`)."
        + (" The device is read as one that is not a CPU (`--as-gpu`)." if args.as_gpu else "")
    ]
    lines += table_head("## Times", heads)
    for case, (times, _) in results:
        sets, per_iteration = case[2], case[4]
        cells = []
        for block in layouts:
            sec = statistics.median(times[block])
            cells.append(f"{sets / sec:.1f} sets/s" if sets > 1 and not per_iteration else f"{sec * 1e3:.3f} ms")
        lines.append(f"| {describe(case)} | " + " | ".join(cells) + " |")
    lines += table_head(f"## Time over {heads[0]}'s (median and range of the per-round ratios)", heads[1:])
    for case, (times, _) in results:
        base = times[layouts[0]]
        cells = []
        for block in layouts[1:]:
            ratios = [a / b for a, b in zip(times[block], base)]
            cells.append(f"{statistics.median(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f})")
        lines.append(f"| {describe(case)} | " + " | ".join(cells) + " |")
    lines += table_head(f"## Same results: largest |datacube − {heads[0]}'s|", heads[1:])
    for case, (_, diffs) in results:
        lines.append(f"| {describe(case)} | " + " | ".join(f"{diffs[b]:.1e}" for b in layouts[1:]) + " |")
    return lines + [""]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None, help="OpenCL device spec (default: rsocl's choice)")
    p.add_argument(
        "--layouts", type=layout, nargs="+", default=[(8, 4), (1, 1), (2, 1), (4, 1), (1, 2), (2, 2)], help="WxR ..."
    )
    p.add_argument("--cases", nargs="+", default=["paper", "batch64", "size128", "size256"])
    p.add_argument("--iterations", type=int, default=200, help="ADMM iterations of paper and batch cases")
    p.add_argument("--size-iterations", type=int, default=20, help="ADMM iterations of the sizeM cases")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--as-gpu", action="store_true", help="read a CPU device as a GPU (the layouts apply)")
    p.add_argument("--out", type=Path, default=None, help=f"write the page here (e.g. {DOCS / 'gpu' / 'blocks.md'})")
    args = p.parse_args(argv)
    if min(args.iterations, args.size_iterations, args.rounds) < 1:
        p.error("--iterations, --size-iterations and --rounds must be >= 1")
    layouts = list(dict.fromkeys(args.layouts))
    if len(layouts) < 2:
        p.error("--layouts: name at least two different layouts")
    device = rsocl.device.get_device(args.device)
    if device.is_cpu and not args.as_gpu:
        p.error(f"{device.name} is a CPU device, where GPU_BLOCK does not apply: add --as-gpu")
    argv = None if argv is None else [__file__, *argv]
    results = []
    for case in case_list(args):
        print(f"{case[0]}: {describe(case)}", flush=True)
        results.append((case, measure(case, layouts, args, device)))
        if args.out:
            write_page(args.out, page(results, layouts, device, args, argv))
    print("\n".join(page(results, layouts, device, args, argv)))


if __name__ == "__main__":
    main()
