"""rsocl against the same ADMM-TV written plainly in PyTorch, on one machine and in one run.

The peer is ``torch_admm_tv.Peer`` (dense mask ``W[C, T, m, n]``, the exact per-pixel ``C×C``
projection, 3-D Chambolle TV with rsocl's TV defaults: temporal weight and step read from
``rsocl_plugins.tv.TV``), float32, fixed ``lam`` 0.1 and ``eta`` 0.2, 10 TV iterations, started
from zeros like ``rsocl.reconstruct(..., tune=False)``. It runs in three modes:

- ``eager``: the iteration as PyTorch expressions, one kernel per operation;
- ``CUDA graph`` (CUDA only): one ADMM iteration captured with ``torch.cuda.graph`` and replayed;
- ``torch.compile``: the iteration through ``torch.compile(mode="reduce-overhead")`` (CUDA graphs
  of fused kernels on CUDA; fused C++ on a CPU).

Cases (``--cases``, all by default): ``paper``, the paper configuration (4 cameras, 50x50,
t_e = 0.18 ms, t_r = 35 µs, ``--iterations`` ADMM iterations), one set per call; ``batchB``, the
same with B sets per call (``--batches``); ``sizeM``, one set of M x M (``--sizes``) timed per
ADMM iteration over ``--size-iterations`` iterations. A whole call is timed from the NumPy
snapshots to the NumPy datacube on both sides (rsocl's set-up, the peer's upload and
read-back included; the peer's mask and inverse blocks, built once per rig, are not); a
per-iteration case times the loops only (rsocl: ``history["time"]``, which also pays its
per-iteration residual). Warm-ups (kernel builds, graph capture, compilation) are not timed;
the rounds alternate rsocl and the modes and the page gives medians. Every result is checked
against rsocl's: PSNR against the truth and the largest difference.

Without torch the peer is skipped; without CUDA the modes run on the CPU (no CUDA graph).

    python benchmarks/peer.py [--device SPEC] [--torch-device cuda] [--rounds 3] [--out docs/gpu/peer.md]
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import importlib
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import rsocl
from rsocl.model.scenes import builtin_scene
from rsocl_plugins.tv import TV

sys.path.insert(0, str(Path(__file__).resolve().parent))
from numpy_admm_tv import psnr  # noqa: E402
from paper_config import paper_rig  # noqa: E402
from provenance import DOCS, header_lines, power_of_two, write_page  # noqa: E402

try:
    import torch
    from torch_admm_tv import Peer, synchronize
except ImportError:  # the peer is optional
    torch = None

LAM, ETA = 0.1, 0.2
MODES = ("eager", "graph", "compile")
LABELS = {
    "eager": "PyTorch eager",
    "graph": "PyTorch, CUDA graph",
    "compile": '`torch.compile(mode="reduce-overhead")`',
}


class Eager:
    """The peer's iterations as plain PyTorch calls."""

    def __init__(self, peer):
        self.peer = peer

    def run(self, iterations):
        theta, b = self.peer.zeros(), self.peer.zeros()
        for _ in range(iterations):
            theta, b = self.peer.step(theta, b)
        return theta


class Graph:
    """One ADMM iteration captured in a CUDA graph (after warm-up runs on a side stream), replayed."""

    def __init__(self, peer):
        self.theta, self.b = peer.zeros(), peer.zeros()
        stream = torch.cuda.Stream()
        stream.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(stream):
            for _ in range(3):
                peer.step(self.theta, self.b)
        torch.cuda.current_stream().wait_stream(stream)
        self.graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self.graph):
            theta, b = peer.step(self.theta, self.b)
            self.theta.copy_(theta)
            self.b.copy_(b)

    def run(self, iterations):
        self.theta.zero_()
        self.b.zero_()
        for _ in range(iterations):
            self.graph.replay()
        return self.theta


class Compiled:
    """The iteration through ``torch.compile(mode="reduce-overhead")``, its outputs cloned before they
    are fed back (a replay overwrites its previous outputs)."""

    def __init__(self, peer):
        self.peer = peer
        mark = getattr(importlib.import_module("torch._dynamo"), "mark_static_address", None)
        if mark is not None:  # the CUDA graphs read these in place instead of copying them in
            for tensor in (peer.W, peer.Minv, peer.g):
                mark(tensor)
        self.step = torch.compile(peer.step, mode="reduce-overhead", dynamic=False)

    def run(self, iterations):
        theta, b = self.peer.zeros(), self.peer.zeros()
        for _ in range(iterations):
            torch.compiler.cudagraph_mark_step_begin()
            theta, b = self.step(theta, b)
            theta, b = theta.clone(), b.clone()
        return theta


RUNNERS = {"eager": Eager, "graph": Graph, "compile": Compiled}
#: Name prefix of an rsocl run with the TV's ``one_launch`` option set (``--tv-one-launch``).
VARIANT = "rsocl one_launch="
#: Name of the rsocl run with the TV's first two iterations in two launches (``--no-first-two``:
#: ``rsocl_plugins.tv.GPU_FIRST_TWO`` off).
NO_FIRST_TWO = "rsocl first2=off"
#: Name prefix of an rsocl run with that many projection lanes (``--project-lanes``:
#: ``rsocl.solver.admm.GPU_PROJECT_LANES``).
LANES = "rsocl lanes="


def is_variant(impl) -> bool:
    """Whether ``impl`` names one of rsocl's runs beside its defaults."""
    return impl.startswith((VARIANT, LANES)) or impl == NO_FIRST_TWO


def variant_names(args, name):
    """rsocl's runs beside its defaults in case ``name``: one per ``--tv-one-launch`` value,
    :data:`NO_FIRST_TWO` with ``--no-first-two`` and one per ``--project-lanes`` value, in the cases of
    ``--variant-cases``."""
    if "all" not in args.variant_cases and name not in args.variant_cases:
        return []
    return (
        [f"{VARIANT}{n}" for n in dict.fromkeys(args.tv_one_launch)]
        + ([NO_FIRST_TWO] if args.no_first_two else [])
        + [f"{LANES}{n}" for n in dict.fromkeys(args.project_lanes)]
    )


def variant_options(impl):
    """``regularizer_options`` of rsocl run ``impl`` (None: the defaults)."""
    return {"one_launch": int(impl[len(VARIANT) :])} if impl.startswith(VARIANT) else None


@contextlib.contextmanager
def variant_context(impl):
    """Module settings of rsocl run ``impl`` while it runs: ``GPU_FIRST_TWO`` off for :data:`NO_FIRST_TWO`,
    ``GPU_PROJECT_LANES`` set for a :data:`LANES` run."""
    import rsocl.solver.admm as admm_module
    import rsocl_plugins.tv as tv_module

    saved, lanes = tv_module.GPU_FIRST_TWO, admm_module.GPU_PROJECT_LANES
    tv_module.GPU_FIRST_TWO = saved and impl != NO_FIRST_TWO
    if impl.startswith(LANES):
        admm_module.GPU_PROJECT_LANES = int(impl[len(LANES) :])
    try:
        yield
    finally:
        tv_module.GPU_FIRST_TWO, admm_module.GPU_PROJECT_LANES = saved, lanes


def cases(args):
    """``[(name, rig, sets, iterations, per_iteration)]`` of the chosen cases, in ``--cases``' order."""
    out = [("paper", paper_rig(), 1, args.iterations, False)]
    out += [(f"batch{b}", paper_rig(), b, args.iterations, False) for b in args.batches]
    out += [
        (f"size{m}", rsocl.Rig.paper_array(4, (m, m), 0.18e-3, 35e-6), 1, args.size_iterations, True)
        for m in args.sizes
    ]
    if not args.cases:
        return out
    named = {c[0]: c for c in out}
    unknown = [name for name in args.cases if name not in named]
    if unknown:
        raise SystemExit(f"--cases: unknown {unknown}; choose from {list(named)} (see --batches, --sizes)")
    return [named[name] for name in dict.fromkeys(args.cases)]


def describe(name, rig, sets, iterations):
    m, n = rig.shape
    if name.startswith("size"):
        return f"one set {m}×{n} (T = {rig.T}), per ADMM iteration"
    what = "one set" if sets == 1 else f"{sets} sets per call"
    return f"paper configuration (4 cameras, {m}×{n}, T = {rig.T}, {iterations} it), {what}"


def modes_for(name, args, torch_device):
    """The peer's modes that run in case ``name`` on ``torch_device``."""
    if torch is None:
        return []
    modes = [m for m in args.modes if m != "graph" or torch_device.type == "cuda"]
    if "all" not in args.compile_cases and name not in args.compile_cases:
        modes = [m for m in modes if m != "compile"]
    return modes


def measure_case(case, args, device, torch_device, tv):
    """One case: ``{"seconds": {impl: [per round]}, "x": {impl: datacube}, "psnr": ..., "errors": ...}``."""
    name, rig, sets, iterations, per_iteration = case
    op = rsocl.RollingShutterOperator(rig, device=device)
    truth = [builtin_scene(rig.shape, rig.T, seed=s) for s in range(sets)]
    g = np.stack([op.forward(t) for t in truth])
    g = g[0] if sets == 1 else g
    opts = dict(lam=LAM, eta=ETA, tune=False, device=device)

    def run_rsocl(impl="rsocl"):
        with variant_context(impl):
            t0 = time.perf_counter()
            res = rsocl.reconstruct(g, rig, iterations=iterations, regularizer_options=variant_options(impl), **opts)
            seconds = time.perf_counter() - t0
        return res.datacube, (float(np.max(res.history["time"][-1])) / iterations if per_iteration else seconds)

    variants = variant_names(args, name)
    for impl in ["rsocl", *variants]:  # kernel builds
        with variant_context(impl):
            rsocl.reconstruct(g, rig, iterations=2, regularizer_options=variant_options(impl), **opts)
    record = {"seconds": {impl: [] for impl in ["rsocl", *variants]}, "x": {}, "first": {}, "errors": {}}
    runners, peer = {}, None
    modes = modes_for(name, args, torch_device)
    if modes:
        peer = Peer(
            g,
            rig,
            lam=LAM,
            eta=ETA,
            tv_iterations=tv.iterations,
            dtype=torch.float32,
            device=torch_device,
            temporal_weight=tv.temporal_weight,
            step=tv.step,
        )

    def run_peer(mode):
        synchronize(torch_device)
        t0 = time.perf_counter()
        peer.load(g)
        if per_iteration:  # the loop alone
            synchronize(torch_device)
            t0 = time.perf_counter()
            theta = runners[mode].run(iterations)
            synchronize(torch_device)
            return theta.cpu().numpy(), (time.perf_counter() - t0) / iterations
        x = runners[mode].run(iterations).cpu().numpy()  # NumPy in, NumPy out
        return x, time.perf_counter() - t0

    with torch.no_grad() if torch is not None else contextlib.nullcontext():
        for mode in modes:  # capture, compile: not timed
            t0 = time.perf_counter()
            try:
                runners[mode] = RUNNERS[mode](peer)
                run_peer(mode)
                record["first"][mode] = time.perf_counter() - t0
                record["seconds"][mode] = []
            except Exception as exc:  # noqa: BLE001 (reported, not hidden)
                record["errors"][mode] = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"[:200]
                runners.pop(mode, None)
                print(f"  {name}: {mode} failed: {record['errors'][mode]}", file=sys.stderr, flush=True)
        impls = ["rsocl", *variants, *runners]
        for r in range(args.rounds):
            k = r % len(impls)
            for impl in impls[k:] + impls[:k]:
                x, sec = run_rsocl(impl) if impl.startswith("rsocl") else run_peer(impl)
                record["seconds"][impl].append(sec)
                record["x"][impl] = x
            print(
                f"  {name} round {r + 1}: " + ", ".join(f"{i} {record['seconds'][i][-1] * 1e3:.2f} ms" for i in impls),
                file=sys.stderr,
                flush=True,
            )
    cubes = [t.astype(np.float64) for t in truth]
    record["psnr"] = {
        impl: [psnr(x if sets == 1 else x[s], cubes[s]) for s in range(sets)] for impl, x in record["x"].items()
    }
    record["diff"] = {impl: float(np.max(np.abs(x - record["x"]["rsocl"]))) for impl, x in record["x"].items()}
    compiled = "compile" in runners
    runners.clear()
    peer = None
    if compiled:  # drop the case's compiled graphs and their memory
        importlib.import_module("torch._dynamo").reset()
    gc.collect()
    if torch is not None and torch_device.type == "cuda":
        torch.cuda.empty_cache()
    return record


def unit(name, sets, seconds):
    """The case's figure of one time: ms per set or per iteration, or sets per second for a batch."""
    return f"{sets / seconds:.1f} sets/s" if sets > 1 else f"{seconds * 1e3:.2f} ms"


def row(cells):
    """One Markdown table row."""
    return "| " + " | ".join(cells) + " |"


def ratio_cell(numerator, denominator):
    """``median (min-max)`` of the per-round ratios of two lists of times; "–" where one is empty."""
    if not numerator or not denominator:
        return "–"
    ratios = [a / b for a, b in zip(numerator, denominator)]
    return f"{statistics.median(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f})"


def tables(done, modes):
    """Markdown lines: times, ratios (rsocl time / peer time; an rsocl variant's time / rsocl's) and the
    equality check."""
    variants = list(dict.fromkeys(i for _, rec in done for i in rec["seconds"] if is_variant(i)))
    others = variants + list(modes)
    heads = [LABELS.get(m, m) for m in others]
    lines = ["## Times (median of the rounds)", "", row(["case", "rsocl"] + heads), row(["---"] * (2 + len(heads)))]
    for case, rec in done:
        name, _, sets, _, _ = case
        cells = [describe(*case[:4])]
        for impl in ["rsocl"] + others:
            if impl in rec["errors"]:
                cells.append("failed")
            elif rec["seconds"].get(impl):
                cells.append(unit(name, sets, statistics.median(rec["seconds"][impl])))
            else:
                cells.append("–")
        lines.append(row(cells))
    if not others:
        return lines + ["", "No PyTorch peer ran (torch is not installed).", ""]
    lines += [
        "",
        "## rsocl's time over the peer's (below 1: rsocl is faster)",
        "",
        "Median over the rounds of the ratio within each round, and its range"
        + ("; for an rsocl variant, its time over rsocl's defaults'." if variants else "."),
        "",
        row(["case"] + [f"{h} / rsocl" for h in variants] + [LABELS[m] for m in modes]),
        row(["---"] * (1 + len(heads))),
    ]
    for case, rec in done:
        sec = rec["seconds"]
        cells = [describe(*case[:4])]
        cells += [ratio_cell(sec.get(v), sec["rsocl"]) for v in variants]
        cells += ["failed" if m in rec["errors"] else ratio_cell(sec["rsocl"], sec.get(m)) for m in modes]
        lines.append(row(cells))
    lines += [
        "",
        "## Same results",
        "",
        "PSNR (dB, peak 1) against the built-in scene's truth; for a batch the mean over the sets, and the "
        "largest PSNR difference over them. Largest |other − rsocl| over the datacube(s).",
        "",
        row(["case", "rsocl PSNR"] + [f"{h}: PSNR − rsocl's, largest difference" for h in heads]),
        row(["---"] * (2 + len(heads))),
    ]
    for case, rec in done:
        base = rec["psnr"]["rsocl"]
        cells = [describe(*case[:4]), f"{np.mean(base):.4f}"]
        for m in others:
            if m not in rec["psnr"]:
                cells.append("failed" if m in rec["errors"] else "–")
                continue
            delta = max((a - b for a, b in zip(rec["psnr"][m], base)), key=abs)
            cells.append(f"{delta:+.1e} dB, {rec['diff'][m]:.1e}")
        lines.append(row(cells))
    errors = [f"- {case[0]}, {m}: {msg}" for case, rec in done for m, msg in rec["errors"].items()]
    firsts = [f"{case[0]} {m} {sec:.1f} s" for case, rec in done for m, sec in rec["first"].items()]
    if errors:
        lines += ["", "Modes that failed:", ""] + errors
    if firsts:
        lines += ["", "First call of each mode (capture or compilation, not in the times): " + ", ".join(firsts) + "."]
    return lines + [""]


def page(done, pending, modes, device, torch_device, tv, args, argv):
    lines = header_lines("rsocl against ADMM-TV in plain PyTorch, in one run", device, argv)[:-1]
    if torch is None:
        lines += ["- PyTorch: not installed; the peer is skipped", ""]
    else:
        name = torch.cuda.get_device_name(torch_device) if torch_device.type == "cuda" else "CPU"
        cuda = f", CUDA {torch.version.cuda}" if torch_device.type == "cuda" else f", {torch.get_num_threads()} threads"
        lines += [f"- PyTorch {torch.__version__} on `{torch_device}` ({name}{cuda})", ""]
    lines += [
        f"float32, `lam` {LAM}, `eta` {ETA}, {tv.iterations} TV iterations at temporal weight "
        f"{tv.temporal_weight:g} and step {tv.step:g} (rsocl's TV defaults), start from zeros "
        "(`rsocl.reconstruct(..., tune=False)`); snapshots of the built-in scene (seed = set). "
        "Whole calls are timed NumPy in, NumPy out; per-iteration cases time the loops only. "
        f"{args.rounds} rounds, rsocl and the modes in rotating order. `benchmarks/peer.py` says what each "
        "mode is.",
        "",
    ]
    lines += tables(done, modes)
    if pending:
        lines += ["Not measured (the run stopped first): " + ", ".join(pending) + ".", ""]
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None, help="rsocl's OpenCL device spec (default: rsocl's choice)")
    parser.add_argument("--torch-device", default=None, help="the peer's torch device (default: cuda if available)")
    parser.add_argument("--iterations", type=int, default=200, help="ADMM iterations of the whole-call cases")
    parser.add_argument("--batches", type=int, nargs="*", default=[64, 256], help="sets per call of the batch cases")
    parser.add_argument("--sizes", type=int, nargs="*", default=[64, 128, 256, 512], help="m of the m x m cases")
    parser.add_argument("--size-iterations", type=int, default=20, help="ADMM iterations of the m x m cases")
    parser.add_argument(
        "--cases", nargs="+", default=None, help="cases to run, in this order (default: paper, batchB..., sizeM...)"
    )
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    parser.add_argument(
        "--compile-cases",
        nargs="+",
        default=["paper", "batch64"],
        help="cases where torch.compile runs ('all': every case)",
    )
    parser.add_argument(
        "--tv-one-launch",
        type=int,
        nargs="*",
        default=[],
        help="rsocl runs beside its defaults with the TV's one_launch option at these values (0, 1, 2)",
    )
    parser.add_argument(
        "--no-first-two",
        action="store_true",
        help="an rsocl run beside its defaults with the TV's first two iterations in two launches (GPU_FIRST_TWO off)",
    )
    parser.add_argument(
        "--project-lanes",
        type=int,
        nargs="*",
        default=[],
        help="rsocl runs beside its defaults with this many projection lanes (GPU_PROJECT_LANES: 1, 2, 4, 8, ...)",
    )
    parser.add_argument(
        "--variant-cases",
        nargs="+",
        default=["all"],
        help="cases of the --tv-one-launch, --no-first-two and --project-lanes runs ('all': every case)",
    )
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=None, help=f"write the page here (e.g. {DOCS / 'gpu' / 'peer.md'})")
    args = parser.parse_args(argv)
    if min([args.iterations, args.size_iterations, args.rounds] + args.batches + args.sizes) < 1:
        raise SystemExit("--iterations, --size-iterations, --rounds, --batches and --sizes must be >= 1")
    if any(n not in (0, 1, 2) for n in args.tv_one_launch):
        raise SystemExit(f"--tv-one-launch: values 0, 1 or 2, got {args.tv_one_launch}")
    if not all(map(power_of_two, args.project_lanes)):
        raise SystemExit(f"--project-lanes: powers of two (1, 2, 4, ...), got {args.project_lanes}")
    argv = None if argv is None else [__file__, *argv]
    device = rsocl.device.get_device(args.device)
    torch_device = None
    if torch is not None:
        torch_device = torch.device(args.torch_device or ("cuda" if torch.cuda.is_available() else "cpu"))
        dynamo = importlib.import_module("torch._dynamo")
        for knob in ("cache_size_limit", "recompile_limit"):  # one compilation per case
            if hasattr(dynamo.config, knob):
                setattr(dynamo.config, knob, 64)
    else:
        print("torch is not installed: the PyTorch peer is skipped", file=sys.stderr)
    tv = TV()
    todo = cases(args)
    modes = [m for m in args.modes if torch is not None and (m != "graph" or torch_device.type == "cuda")]
    done = []
    for i, case in enumerate(todo):
        print(f"{case[0]}: {describe(*case[:4])}", file=sys.stderr, flush=True)
        done.append((case, measure_case(case, args, device, torch_device, tv)))
        if args.out:
            write_page(args.out, page(done, [c[0] for c in todo[i + 1 :]], modes, device, torch_device, tv, args, argv))
    print("\n".join(page(done, [], modes, device, torch_device, tv, args, argv)))


if __name__ == "__main__":
    main()
