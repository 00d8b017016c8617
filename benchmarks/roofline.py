"""Bandwidth of rsocl's kernels against a plain copy kernel, measured in one run on one device.

For each kernel: the bytes it must move (each value read or written once, neighbours
from cache), the time per launch (median of repeats), the bandwidth that makes, and
its ratio to the copy kernel's bandwidth. Paper array, 128x128 by default, float32.

    python benchmarks/roofline.py [--size 128] [--repeats 30] [--device SPEC]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import rsocl
from rsocl.device import get_device, voxel_grid


def timed(queue, launch, repeats):
    launch()
    queue.finish()
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        launch()
        queue.finish()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)


def main():
    import pyopencl as cl
    import pyopencl.array as cla

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--device", default=None)
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
    copy = dev.program(["reduce.cl"], REAL="float", ACC="double" if dev.has_fp64 else "float").copy
    tv = dev.program(["tv.cl"], REAL="float", TEMPORAL=1)
    gsize, lsize = voxel_grid(T, m, n)
    sizes = (np.int32(T), np.int32(m), np.int32(n))
    # sampled voxels per channel and pixel: the window loop reads only those
    first, last = rig.sampled_window()
    samples = int(np.sum(last - first + 1))
    rows = [
        ("copy (reference)", 2 * N * f32,
         lambda: copy(q, (N,), None, x.data, y.data, np.int32(N))),
        ("tv_primal (3-D)", (1 + 3 + 1) * N * f32,
         lambda: tv.tv_primal(q, gsize, lsize, x.data, p.data, y.data, np.float32(1), *sizes)),
        ("tv_dual (3-D)", (1 + 3 + 3) * N * f32,
         lambda: tv.tv_dual(q, gsize, lsize, y.data, p.data, np.float32(1 / 6), np.float32(0.5), np.float32(1),
                            *sizes)),
        ("forward H", (samples + K * mn * 3) * f32,
         lambda: op.forward_into(x, g)),
        ("adjoint Hᵀ", (N + 2 * samples + K * mn * 3) * f32,
         lambda: op.adjoint_into(g, y)),
    ]
    print(f"device: {dev.name}; paper array {m}x{n}, T = {T}, {K} cameras, float32; "
          f"median of {args.repeats} launches\n")
    print("| kernel | bytes it must move | per voxel of the datacube | time (ms) | GB/s | vs copy |")
    print("|---|---|---|---|---|---|")
    copy_bw = None
    for name, nbytes, launch in rows:
        seconds = timed(q, launch, args.repeats)
        bw = nbytes / seconds / 1e9
        copy_bw = copy_bw or bw
        print(f"| {name} | {nbytes / 2**20:.1f} MiB | {nbytes / N:.1f} B | {seconds * 1e3:.3f} | {bw:.2f} | "
              f"{bw / copy_bw:.0%} |", flush=True)
    print("\nBytes: each array element read or written once (neighbours counted once, as from cache); "
          "forward/adjoint: the sampled window of every channel and pixel plus the per-pixel maps.")


if __name__ == "__main__":
    main()
