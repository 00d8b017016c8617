"""Where an ADMM iteration's device time goes, kernel by kernel, beside its wall time, in one run.

A small reconstruction on a GPU is bound either by the host (the device waits between launches) or
by a kernel that runs longer than a launch takes to enqueue. This benchmark runs fixed-setting
reconstructions (``tune=False``, ``x0="interp3d"``, the built-in scene on the paper array) on a
queue with OpenCL profiling, keeps the event of every kernel enqueued through
:class:`rsocl.device.kernel.Kernel` by ``--iterations`` ADMM steps of the run (from one step's start
to the next one's), and reports per kernel: launches per iteration and device µs per launch
(``CL_PROFILING_COMMAND_START`` to ``END``, median); per iteration: the device's busy time (the
kernels' sum), the span from the first kernel's start to the last one's end, and the device's idle
time between them (span less busy). Busy close to span: the device bounds the loop; idle close to span: the host does.
``--sets`` also runs batches of that many copies of the snapshots in one call, as the self-tuned search's
batches of candidates run (rows ``50×50, 5 sets``); ``--lanes`` sets the projection's lanes on a device that is
not a CPU (``rsocl.solver.admm.GPU_PROJECT_LANES``).

    python benchmarks/kernel_times.py [--device SPEC] [--sizes 8 50 128] [--sets 1 5] [--lanes 4] [--iterations 40]
        [--as-gpu] [--out docs/kernel_times.md]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from launches import case, path, small_calls  # noqa: E402
from provenance import DOCS, emit, header_lines, power_of_two  # noqa: E402

import rsocl  # noqa: E402
import rsocl.solver.admm as admm_module  # noqa: E402
from rsocl.device import kernel as kernel_module  # noqa: E402
from rsocl.device.context import Device, device_for_queue, get_device  # noqa: E402

#: Iterations run before the recorded ones (kernel builds, the first iterations' own launches).
SKIP = 4


def profiling_device(device) -> Device:
    """``device`` with a queue of its own that records kernel times (``CL_QUEUE_PROFILING_ENABLE``), as rsocl
    wraps a queue made outside it (:func:`rsocl.device.context.device_for_queue`)."""
    import pyopencl as cl

    queue = cl.CommandQueue(device.context, device.device, properties=cl.command_queue_properties.PROFILING_ENABLE)
    return device_for_queue(queue)


def record(rig, g, device, iterations: int, sets: int = 1) -> list:
    """``[(kernel name, event), ...]`` of the kernels enqueued by ADMM steps ``SKIP`` to ``SKIP + iterations - 1``
    of a run of ``SKIP + iterations + 1`` iterations (each step's start marked in the log), on ``sets`` copies of
    the snapshots ``g`` in one batch (one set: ``g`` itself)."""
    from rsocl.solver.admm import ADMM

    if sets > 1:
        g = np.stack([g] * sets)

    log: list = []
    marks: list = []
    enqueue, call, step = kernel_module.Kernel.enqueue, kernel_module.Kernel.__call__, ADMM.step

    def hooked_enqueue(self, queue, gsize, lsize, global_offset=None):
        event = enqueue(self, queue, gsize, lsize, global_offset)
        log.append((self.kernel.function_name, event))
        return event

    def hooked_call(self, queue, gsize, lsize, *args, global_offset=None, wait_for=None):
        event = call(self, queue, gsize, lsize, *args, global_offset=global_offset, wait_for=wait_for)
        log.append((self.kernel.function_name, event))
        return event

    def hooked_step(self, *args, **kwargs):
        marks.append(len(log))
        return step(self, *args, **kwargs)

    kernel_module.Kernel.enqueue, kernel_module.Kernel.__call__, ADMM.step = hooked_enqueue, hooked_call, hooked_step
    try:
        rsocl.reconstruct(g, rig, iterations=SKIP + iterations + 1, tune=False, x0="interp3d", device=device)
    finally:
        kernel_module.Kernel.enqueue, kernel_module.Kernel.__call__, ADMM.step = enqueue, call, step
    return log[marks[SKIP] : marks[SKIP + iterations]]


def summarise(events: list, iterations: int) -> dict:
    """Per kernel ``(launches per iteration, median µs)`` and per iteration busy, span and idle µs."""
    times = defaultdict(list)
    starts, ends = [], []
    for name, event in events:
        start, end = event.profile.start, event.profile.end
        times[name].append((end - start) / 1e3)
        starts.append(start)
        ends.append(end)
    busy = sum(sum(v) for v in times.values()) / iterations
    span = (max(ends) - min(starts)) / 1e3 / iterations
    kernels = {name: (len(v) / iterations, statistics.median(v)) for name, v in times.items()}
    return {"kernels": kernels, "busy": busy, "span": span, "idle": span - busy}


def lines(m: int, sets: int, T: int, s: dict) -> list:
    """Markdown rows of one ROI and batch of ``sets`` sets."""
    out = []
    roi = f"{m}×{m}" if sets == 1 else f"{m}×{m}, {sets} sets"
    total = sum(count * us for count, us in s["kernels"].values())
    for name, (count, us) in sorted(s["kernels"].items(), key=lambda kv: -kv[1][0] * kv[1][1]):
        out.append(f"| {roi} | {T} | `{name}` | {count:g} | {us:.1f} | {100 * count * us / total:.0f} % |")
    out.append(
        f"| {roi} | {T} | **an iteration** | {sum(c for c, _ in s['kernels'].values()):g} | busy {s['busy']:.1f}, "
        f"span {s['span']:.1f}, idle {s['idle']:.1f} | busy / span {s['busy'] / s['span']:.2f} |"
    )
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None, help="OpenCL device spec (default: rsocl's choice)")
    p.add_argument("--sizes", type=int, nargs="+", default=[8, 50, 128], help="ROI sides m (m × m), pixels")
    p.add_argument("--sets", type=int, nargs="+", default=[1], help="sets per call: batches of copies (>= 1)")
    p.add_argument("--lanes", type=int, default=None, help="projection lanes (GPU_PROJECT_LANES; default: rsocl's)")
    p.add_argument("--iterations", type=int, default=40, help="iterations recorded per ROI (>= 1)")
    p.add_argument("--as-gpu", action="store_true", help="read the device as a GPU (its choices run on a CPU)")
    p.add_argument("--out", type=Path, default=None, help=f"write the page here (e.g. {DOCS / 'kernel_times.md'})")
    args = p.parse_args(argv)
    if args.iterations < 1:
        p.error(f"--iterations must be >= 1, got {args.iterations}")
    if any(m < 2 for m in args.sizes):
        p.error(f"--sizes must be >= 2 pixels each, got {args.sizes}")
    if any(b < 1 for b in args.sets):
        p.error(f"--sets must be >= 1 each, got {args.sets}")
    if args.lanes is not None and not power_of_two(args.lanes):
        p.error(f"--lanes must be >= 1 and a power of two, got {args.lanes}")
    device = profiling_device(get_device(args.device))
    rows = []
    saved = admm_module.GPU_PROJECT_LANES
    lanes = saved if args.lanes is None else args.lanes
    admm_module.GPU_PROJECT_LANES = lanes
    try:
        with path("gpu" if args.as_gpu else "device"):
            for m in args.sizes:
                rig, g = case(m)
                for sets in args.sets:
                    events = record(rig, g, device, args.iterations, sets)
                    rows += lines(m, sets, rig.T, summarise(events, args.iterations))
    finally:
        admm_module.GPU_PROJECT_LANES = saved
    page = header_lines(
        "An ADMM iteration's device time, kernel by kernel", device, None if argv is None else [__file__, *argv]
    )
    page += [
        f"{small_calls(args.as_gpu)}; a queue with profiling; the {args.iterations} iterations "
        f"after the first {SKIP} of one run. Device µs per launch: the median of the kernel's launches "
        "(`CL_PROFILING_COMMAND_START` to `END`). An iteration: busy, the kernels' device time; span, the first "
        "kernel's start to the last one's end; idle, span less busy (µs per iteration). Busy / span near 1: "
        "the device bounds the loop; near 0: the host does."
        + (" Rows `m×m, B sets`: B copies of the snapshots in one call, one batch." if max(args.sets) > 1 else "")
        + f" Projection lanes where the device is not a CPU: {lanes}.",
        "",
        "| ROI | T | kernel | launches per iteration | device µs per launch | share of busy |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
    ]
    emit(page, args.out)
    return rows


if __name__ == "__main__":
    main()
