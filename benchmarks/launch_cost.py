"""What one kernel launch costs the host on a device, by the kernel's arguments and grid, in one run.

An ADMM-TV iteration of a small set is bound by launches, and a launch of ``tv_step`` can cost more
than the trivial kernel's: this benchmark times enqueues of kernels that do no work (one work item
writes one value) and differ in one thing at a time, in alternating rounds of ``--launches``
enqueues each (a finish around each round):

- ``one buffer, 1 item``: the trivial kernel (one buffer argument, one work item);
- ``9 arguments, 1 item``: ``tv_step``'s signature (5 buffers, 4 ints), one work item;
- ``9 arguments, tv_step's grid``: the same on ``tv_step``'s grid and work groups for ``--shape``
  (m × m × T of the paper array);
- ``9 arguments, 4 ints set per launch``: the previous, with its 4 ints set before every enqueue
  (what pyopencl's ``kernel(queue, grid, local, *args)`` does);
- ``9 arguments, global offset``: the third with a global offset along the last dimension;
- ``..., no event (ctypes)``: the first and the third enqueued by ``clEnqueueNDRangeKernel`` itself through
  :mod:`ctypes` (pyopencl's own OpenCL library, sizes prepared once), with no event asked for: what
  pyopencl's call adds (its argument conversion, the event it always makes and releases).

    python benchmarks/launch_cost.py [--device SPEC] [--rounds 5] [--launches 2000] [--shape 50]
        [--out docs/launch_cost.md]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from provenance import DOCS, header_lines, write_page  # noqa: E402

import rsocl  # noqa: E402

SOURCE = """
__kernel void one_buffer(__global float *x) { if (get_global_id(0) == 0) x[0] += 1.0f; }
__kernel void nine_args(__global float *a, __global const float *b, __global float *c, __global const float *d,
                        __global const float *e, int T, int m, int n, int sets)
{
    if (get_global_id(0) == 0 && get_global_id(1) == 0 && get_global_id(2) == get_global_offset(2))
        a[0] += (float)(T + m + n + sets);
}
"""

VARIANTS = (
    "one buffer, 1 item",
    "9 arguments, 1 item",
    "9 arguments, tv_step's grid",
    "9 arguments, 4 ints set per launch",
    "9 arguments, global offset",
    "one buffer, 1 item, no event (ctypes)",
    "9 arguments, tv_step's grid, no event (ctypes)",
)


def bare_enqueue():
    """``clEnqueueNDRangeKernel`` of the OpenCL library pyopencl loads, through :mod:`ctypes` (its argument
    types set), or None where that library is not found."""
    import ctypes
    import ctypes.util
    import glob
    import os

    import pyopencl as cl

    found = sorted(glob.glob(os.path.join(os.path.dirname(cl.__file__), ".libs", "libOpenCL*")))
    name = found[0] if found else ctypes.util.find_library("OpenCL")
    if not name:
        return None
    fn = ctypes.CDLL(name).clEnqueueNDRangeKernel
    pointer = ctypes.c_void_p
    fn.argtypes = [pointer, pointer, ctypes.c_uint32, pointer, pointer, pointer, ctypes.c_uint32, pointer, pointer]
    fn.restype = ctypes.c_int32
    return fn


def ctypes_sizes(*sizes) -> list:
    """Each of ``sizes`` (tuples of ints) as a ctypes array of ``size_t``."""
    import ctypes

    return [(ctypes.c_size_t * len(size))(*size) for size in sizes]


def launchers(device, m: int):
    """``({variant: enqueue()}, (global, local), buffer)``: a function per variant of :data:`VARIANTS` that
    makes one enqueue, tv_step's grid, and the buffer the kernels name (kernel objects do not keep it alive:
    hold it while enqueueing)."""
    import pyopencl as cl

    from rsocl.device.launch import voxel_launches
    from rsocl_plugins.tv import GROUP

    T = rsocl.Rig.paper_array(4, (m, m), 0.18e-3, 35e-6).T
    prog = cl.Program(device.context, SOURCE).build()
    queue = device.queue
    buf = cl.Buffer(device.context, cl.mem_flags.READ_WRITE, 64)
    one = cl.Kernel(prog, "one_buffer")
    one.set_arg(0, buf)
    kernels = {}
    for name in VARIANTS[1:]:
        k = cl.Kernel(prog, "nine_args")
        for i in range(5):
            k.set_arg(i, buf)
        for i, v in enumerate((T, m, m, 1), 5):
            k.set_arg(i, np.int32(v))
        kernels[name] = k
    group = min(GROUP, device.max_work_group_size)
    (gsize, lsize, _), *_ = voxel_launches(T, m, m, group=group, max_x=device.max_work_item_sizes[0])
    ints = [np.int32(v) for v in (T, m, m, 1)]
    enqueue = cl.enqueue_nd_range_kernel

    def set_ints_and_enqueue():
        k = kernels[VARIANTS[3]]
        for i, v in enumerate(ints, 5):
            k.set_arg(i, v)
        enqueue(queue, k, gsize, lsize)

    bare, sizes = bare_enqueue(), ctypes_sizes((1,), gsize, lsize or ())
    qp, onep, ninep = queue.int_ptr, one.int_ptr, kernels[VARIANTS[2]].int_ptr

    def bare_one():
        if bare(qp, onep, 1, None, sizes[0], None, 0, None, None):
            raise RuntimeError("clEnqueueNDRangeKernel failed")

    def bare_grid():
        if bare(qp, ninep, len(gsize), None, sizes[1], sizes[2] if lsize else None, 0, None, None):
            raise RuntimeError("clEnqueueNDRangeKernel failed")

    return (
        {
            VARIANTS[0]: lambda: enqueue(queue, one, (1,), None),
            VARIANTS[1]: lambda: enqueue(queue, kernels[VARIANTS[1]], (1, 1, 1), None),
            VARIANTS[2]: lambda: enqueue(queue, kernels[VARIANTS[2]], gsize, lsize),
            VARIANTS[3]: set_ints_and_enqueue,
            VARIANTS[4]: lambda: enqueue(queue, kernels[VARIANTS[4]], gsize, lsize, global_work_offset=(0, 0, 3)),
            **({} if bare is None else {VARIANTS[5]: bare_one, VARIANTS[6]: bare_grid}),
        },
        (gsize, lsize),
        buf,
    )


def measure(device, rounds: int, launches: int, m: int):
    """``({variant: [µs per enqueue, per round]}, (global, local))`` in alternating rounds."""
    calls, grid, buf = launchers(device, m)
    queue = device.queue
    for call in calls.values():  # warm-up
        for _ in range(50):
            call()
    queue.finish()
    times: dict = {name: [] for name in calls}
    for r in range(rounds):
        order = list(calls) if r % 2 == 0 else list(calls)[::-1]
        for name in order:
            call = calls[name]
            queue.finish()
            t0 = time.perf_counter()
            for _ in range(launches):
                call()
            queue.finish()
            times[name].append((time.perf_counter() - t0) / launches * 1e6)
    del buf  # alive until every enqueue is done
    return times, grid


def lines(times, grid, m: int, launches: int) -> list:
    """Markdown lines: µs per enqueue of each variant and its ratio to the trivial kernel's."""
    base = times[VARIANTS[0]]
    out = [
        f"µs of host time per enqueue of a kernel that does no work ({launches} enqueues per round, "
        f"alternating rounds, medians; tv_step's grid at {m}×{m}: global {grid[0]}, local {grid[1]}):",
        "",
        "| kernel | µs per enqueue (rounds) | × one buffer, 1 item (rounds) |",
        "|---|---|---|",
    ]
    for name in VARIANTS:
        if name not in times:
            out.append(f"| {name} | not measured: no OpenCL library found through ctypes | |")
            continue
        ratios = [a / b for a, b in zip(times[name], base)]
        out.append(
            f"| {name} | {statistics.median(times[name]):.2f} ({', '.join(f'{t:.2f}' for t in times[name])}) | "
            f"{statistics.median(ratios):.2f} ({', '.join(f'{r:.2f}' for r in ratios)}) |"
        )
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None, help="OpenCL device spec (default: rsocl's choice)")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--launches", type=int, default=2000, help="enqueues per variant and round")
    p.add_argument("--shape", type=int, default=50, help="m of the m × m frame whose tv_step grid is used")
    p.add_argument("--out", type=Path, default=None, help=f"write the page here (e.g. {DOCS / 'launch_cost.md'})")
    args = p.parse_args(argv)
    if min(args.rounds, args.launches) < 1 or args.shape < 2:
        p.error("--rounds and --launches must be >= 1, --shape >= 2")
    device = rsocl.device.get_device(args.device)
    times, grid = measure(device, args.rounds, args.launches, args.shape)
    page = header_lines("What a kernel launch costs the host", device, None if argv is None else [__file__, *argv])
    page += lines(times, grid, args.shape, args.launches) + [""]
    print("\n".join(page))
    if args.out:
        write_page(args.out, page)


if __name__ == "__main__":
    main()
