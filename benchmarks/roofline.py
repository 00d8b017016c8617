"""Bandwidth of rsocl's kernels against a plain copy kernel, measured in one run on one device.

For each kernel: the bytes it must move (each value read or written once, neighbours
from cache), the time per launch (median of round-robin repeats, each from cold caches), the bandwidth that makes, and
its ratio to the copy kernel's bandwidth. Paper array, 128x128 by default, float32.

    python benchmarks/roofline.py [--size 128] [--repeats 60] [--caches cold|warm] [--device SPEC]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import rsocl
from rsocl.device.context import get_device
from rsocl.device.launch import element_launches
from rsocl_plugins import tv as tv_plugin


FLUSH_SOURCE = """
__kernel void flush(__global const float *big, __global float *out, int per_item)
{
    size_t i = get_global_id(0), n = get_global_size(0);
    float acc = 0.0f;
    for (int j = 0; j < per_item; ++j) acc += big[j * n + i];
    out[i] = acc;
}
"""

# Reads the 64-byte lines whose indices are listed (8 per work item) and writes one sum per
# work item: the least a kernel that needs exactly those lines can do, in the list's order.
LINES_SOURCE = """
__kernel void read_lines(__global const float16 *f, __global const int *line, __global float *out, int count)
{
    size_t i = get_global_id(0);
    float16 acc = (float16)(0.0f);
    for (int j = 0; j < 8; ++j) {
        size_t t = i * 8 + j;
        if (t < (size_t)count) acc += f[line[t]];
    }
    float8 h = acc.lo + acc.hi;
    float4 v = h.lo + h.hi;
    out[i] = v.x + v.y + v.z + v.w;
}

/* every line of f in memory order, 8 per work item: the stream that the sorted list above thins out */
__kernel void read_all(__global const float16 *f, __global float *out)
{
    size_t i = get_global_id(0);
    float16 acc = (float16)(0.0f);
    for (int j = 0; j < 8; ++j) acc += f[i * 8 + j];
    float8 h = acc.lo + acc.hi;
    float4 v = h.lo + h.hi;
    out[i] = v.x + v.y + v.z + v.w;
}

__kernel void nothing(__global float *out) { }
"""
LINE_READ = "read of the windows' lines, in memory order"
EVERY_LINE = "read of every line of the datacube, in order"
LAUNCH_ONLY = "launch only (empty kernel)"


def cache_flusher(context, queue, nbytes=64 << 20, per_item=64):
    """A launch that reads ``nbytes`` (more than any CPU cache), writing 1/per_item of that.

    Run untimed before every timed launch, it leaves the caches cold and clean, so no
    kernel pays for the write-back of the one before or profits from its data.
    """
    import pyopencl as cl
    import pyopencl.array as cla

    items = nbytes // 4 // per_item
    big = cla.zeros(queue, items * per_item, np.float32)
    out = cla.empty(queue, items, np.float32)
    kernel = cl.Kernel(cl.Program(context, FLUSH_SOURCE).build(), "flush")
    kernel.set_args(big.data, out.data, np.int32(per_item))

    def flush(buffers=(big, out)):          # the default keeps the buffers alive
        return cl.enqueue_nd_range_kernel(queue, kernel, (items,), None)
    return flush


def timed(queue, launches, repeats, prepare):
    """Median seconds per launch of each callable, measured round-robin.

    Interleaving the kernels (copy, tv, ..., copy, tv, ...) exposes them to the same
    machine noise. ``prepare(launch)`` runs untimed before each timed launch: a cache
    flush (cold: data from memory) or the launch itself (warm: its data in cache, as when
    a reconstruction's working set fits in the last-level cache).
    """
    for launch in launches:
        launch()
    queue.finish()
    samples = [[] for _ in launches]
    for _ in range(repeats):
        for i, launch in enumerate(launches):
            prepare(launch)
            queue.finish()
            t0 = time.perf_counter()
            launch()
            queue.finish()
            samples[i].append(time.perf_counter() - t0)
    return [statistics.median(s) for s in samples]


def touched_lines(rig, itemsize, line=64):
    """Sorted indices of the ``line``-byte lines of ``f[T, m, n]`` that the sampled windows touch.

    A rotated camera's window runs across the planes of ``f``, so each plane it visits
    gives it a few neighbouring pixels of a row: memory moves whole lines, so the traffic
    the layout implies is larger than the sampled values.
    """
    first, last = rig.sampled_window()
    mn = first.shape[1] * first.shape[2]
    pix = np.arange(mn)
    lines = []
    for k in range(first.shape[0]):
        lo, hi = first[k].ravel(), last[k].ravel()
        for j in range(int((hi - lo).max()) + 1):
            keep = lo + j <= hi
            lines.append(((lo[keep] + j) * mn + pix[keep]) * itemsize // line)
    return np.unique(np.concatenate(lines))


def line_reader(context, queue, f, lines):
    """A launch that reads the listed 64-byte lines of ``f`` in the list's order (sorted: memory order)."""
    import pyopencl as cl
    import pyopencl.array as cla

    index = cla.to_device(queue, lines.astype(np.int32))
    items = -(-lines.size // (8 * 64)) * 64                 # work items: 8 lines each, whole groups of 64
    out = cla.empty(queue, items, np.float32)
    program = cl.Program(context, LINES_SOURCE).build()
    kernel = cl.Kernel(program, "read_lines")
    kernel.set_args(f.data, index.data, out.data, np.int32(lines.size))
    nothing = cl.Kernel(program, "nothing")
    nothing.set_args(out.data)
    whole = f.nbytes // (64 * 8)                            # work items of read_all (the tail is left out)
    total = cla.empty(queue, max(whole, 1), np.float32)
    everything = cl.Kernel(program, "read_all")
    everything.set_args(f.data, total.data)

    def read(buffers=(index, out)):
        return cl.enqueue_nd_range_kernel(queue, kernel, (items,), (64,))

    def read_every_line(buffers=(total,)):
        return cl.enqueue_nd_range_kernel(queue, everything, (whole,), None)

    def launch_only(buffers=(out,)):
        return cl.enqueue_nd_range_kernel(queue, nothing, (1,), (1,))
    return read, read_every_line, launch_only

def main():
    import pyopencl as cl
    import pyopencl.array as cla

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--repeats", type=int, default=60)
    parser.add_argument("--device", default=None)
    parser.add_argument("--caches", choices=("cold", "warm"), default="cold",
                        help="cold: flush the caches before each launch; warm: run the kernel once first")
    args = parser.parse_args()
    dev = get_device(args.device)
    q = dev.queue
    rig = rsocl.Rig.paper_array(4, (args.size, args.size), t_e=0.18e-3, t_r=35e-6)
    op = rsocl.RollingShutterOperator(rig, device=dev)
    T, (m, n), K = rig.T, rig.shape, rig.n_channels
    N, mn = T * m * n, m * n
    f32 = 4
    rng = np.random.default_rng(0)
    x = cla.to_device(q, rng.random((T, m, n)).astype(np.float32))
    y = cla.empty_like(x)
    g = op.forward(x)
    p = cla.zeros(q, (3, T, m, n), np.float32)
    xnext = cla.to_device(q, tv_plugin.edge_weights(n, np.float32))
    copy = dev.program(["reduce.cl"], REAL="float", ACC="double" if dev.has_fp64 else "float").copy
    tv = dev.program(["tv.cl"], REAL="float", TEMPORAL=1)
    voxels = tv_plugin.launches(tv, dev.device, T, m, n)        # as the TV plugin launches them
    sizes = (np.int32(T), np.int32(m), np.int32(n))
    # sampled voxels per channel and pixel: the window loop reads only those
    first, last = rig.sampled_window()
    samples = int(np.sum(last - first + 1))
    touched = touched_lines(rig, f32)
    lines = touched.size * 64
    maps = K * mn * 3 * f32              # first, frac and the snapshot of every channel and pixel
    read_lines, read_every_line, launch_only = line_reader(dev.context, q, x, touched)
    rows = [
        ("copy (reference)", 2 * N * f32, None,
         lambda: [copy(q, gs, ls, x.data, y.data, global_offset=off) for gs, ls, off in element_launches(N)]),
        ("tv_primal (3-D)", (1 + 3 + 1) * N * f32, None,
         lambda: [tv.tv_primal(q, gs, ls, x.data, p.data, y.data, np.float32(1), *sizes, global_offset=off)
                  for gs, ls, off in voxels]),
        ("tv_dual (3-D)", (1 + 3 + 3) * N * f32 + n * f32, None,
         lambda: [tv.tv_dual(q, gs, ls, y.data, p.data, xnext.data, np.float32(1 / 6), np.float32(0.5), np.float32(1),
                             *sizes, global_offset=off) for gs, ls, off in voxels]),
        ("forward H", samples * f32 + maps, lines + maps,
         lambda: op.forward_into(x, g)),
        ("adjoint Hᵀ", N * f32 + 2 * samples * f32 + maps, N * f32 + 2 * lines + maps,
         lambda: op.adjoint_into(g, y)),
        (LINE_READ, lines + touched.size * 4, lines, read_lines),
        (EVERY_LINE, N // 128 * 128 * f32, None, read_every_line),
        (LAUNCH_ONLY, 0, None, launch_only),
    ]
    print(f"device: {dev.name}; paper array {m}x{n}, T = {T}, {K} cameras, float32, "
          f"blocks of {op.block_rows} rows x {op.vector_width} pixels per work item in the operator; "
          f"median of {args.repeats} round-robin launches, {args.caches} caches\n")
    print("| kernel | bytes it must move | per voxel of the datacube | time (ms) | GB/s | vs copy "
          "| in 64-B lines | GB/s in lines | vs copy, in lines |")
    print("|---|---|---|---|---|---|---|---|---|")
    if args.caches == "cold":
        flush = cache_flusher(dev.context, q)
        prepare = lambda launch: flush()            # noqa: E731
    else:
        prepare = lambda launch: launch()           # noqa: E731
    seconds = timed(q, [row[3] for row in rows], args.repeats, prepare)
    copy_bw = rows[0][1] / seconds[0] / 1e9
    for (name, nbytes, line_bytes, _), sec in zip(rows, seconds):
        if not nbytes:
            print(f"| {name} | 0 | | {sec * 1e3:.3f} | | | | | |", flush=True)
            continue
        bw = nbytes / sec / 1e9
        lines_cols = "| | |"
        if line_bytes is not None:
            lbw = line_bytes / sec / 1e9
            lines_cols = f"{line_bytes / 2**20:.1f} MiB | {lbw:.2f} | {lbw / copy_bw:.0%} |"
        print(f"| {name} | {nbytes / 2**20:.1f} MiB | {nbytes / N:.1f} B | {sec * 1e3:.3f} | {bw:.2f} | "
              f"{bw / copy_bw:.0%} | {lines_cols}", flush=True)
    second = {row[0]: sec for row, sec in zip(rows, seconds)}
    forward_s, lines_s = second["forward H"], second[LINE_READ]
    launch_s, every_s = second[LAUNCH_ONLY], second[EVERY_LINE]
    print(f"\nThe forward takes {forward_s / lines_s:.2f}x the time of a plain read of the same lines in memory "
          f"order ({forward_s * 1e3:.3f} against {lines_s * 1e3:.3f} ms). That read, with no arithmetic, reaches "
          f"{(lines + touched.size * 4) / lines_s / 1e9 / copy_bw:.0%} of the copy's bandwidth: scattered lines cost more "
          f"per byte than a stream, so the windows' pattern, not the arithmetic, bounds the forward "
          f"(reading every line of the datacube in order took {every_s * 1e3:.3f} ms). A launch alone costs "
          f"{launch_s * 1e3:.3f} ms, included in every row.")
    print("\nBytes: each array element read or written once (neighbours counted once, as from cache); "
          "forward/adjoint: the sampled window of every channel and pixel plus the per-pixel maps "
          "(first, frac, snapshot). 'In 64-B lines': the distinct cache lines of the datacube those "
          "windows touch, which is what memory moves for the rotated cameras. The line read moves those "
          "lines and their 4-byte indices.")

if __name__ == "__main__":
    main()
