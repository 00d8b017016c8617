"""What a small reconstruction call costs beside its iterations, with device buffers pooled or made each
call, in one run.

A live camera calls ``rsocl.reconstruct`` once per set of snapshots, on a small frame. Beside the
ADMM's iterations a call stages the snapshots and the operator's geometry, makes the ADMM's and the
regularizer's arrays, the inverse blocks and the interpolation start, and frees them all on return.
rsocl takes these buffers from a pool (:mod:`rsocl.device.pool`) on a device that is not a CPU
(``pooled`` sets ``rsocl.device.pool.ON_CPU``, so that a CPU device pools too); ``made each call`` sets
``rsocl.device.pool.LARGEST_BYTES = 0``, so that every buffer is created and released by the driver,
as a plain :class:`pyopencl.array.Array` is.

First, one buffer's own cost (:func:`buffer_us`): a buffer of a paper set's datacube made, written (a
4-byte fill, so that a lazy driver allocates it) and released, against the same from the pool. Then, for
each ROI, in alternating rounds: the median wall time of ``--calls`` whole calls of 1 iteration and
of the default 200 (fixed settings, ``x0="interp3d"``, the built-in scene on the paper array), with the
pool and without, their ratio per round, the device buffers one warm call makes, and whether both
give the same datacube.

    python benchmarks/call_cost.py [--device SPEC] [--sizes 8 50] [--rounds 5] [--calls 9] [--as-gpu]
        [--out docs/call_cost.md]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from launches import case, path, small_calls  # noqa: E402
from provenance import DOCS, emit, header_lines  # noqa: E402

import rsocl  # noqa: E402
from rsocl.device import pool  # noqa: E402
from rsocl.device.context import get_device  # noqa: E402

#: The two ways device buffers are had: the pool's largest pooled buffer in each (None: the default).
VARIANTS = {"pooled": None, "made each call": 0}
#: Iterations of the two calls timed.
ITERATIONS = (1, 200)


@contextmanager
def variant(name: str):
    """Run the block with device buffers had as :data:`VARIANTS` ``name`` says (a CPU device pools too)."""
    saved = pool.LARGEST_BYTES, pool.ON_CPU
    largest = VARIANTS[name]
    pool.LARGEST_BYTES = saved[0] if largest is None else largest
    pool.ON_CPU = True
    try:
        yield
    finally:
        pool.LARGEST_BYTES, pool.ON_CPU = saved


def buffer_us(device, nbytes: int, count: int, rounds: int) -> dict:
    """``{"made": [µs per buffer, per round], "pooled": [...]}``: ``count`` buffers of ``nbytes`` bytes, each
    made (plainly, or from a pool of its own), filled over 4 bytes and released, in alternating rounds."""
    import pyopencl as cl

    queue = device.queue
    own = pool.BufferPool(queue)
    zero = np.zeros(1, np.float32)

    def plain():
        return cl.Buffer(device.context, cl.mem_flags.READ_WRITE, nbytes)

    out: dict = {"made": [], "pooled": []}
    for r in range(rounds + 1):  # round 0 warms up
        order = [("made", plain), ("pooled", lambda: own(nbytes))]
        for name, make in order if r % 2 else order[::-1]:
            queue.finish()
            t0 = time.perf_counter()
            for _ in range(count):
                buf = make()
                cl.enqueue_fill_buffer(queue, buf, zero, 0, 4)
                del buf
            queue.finish()
            if r:
                out[name].append((time.perf_counter() - t0) / count * 1e6)
    own.release()
    return out


def one_call(rig, g, iterations: int, device):
    """``(seconds, datacube)`` of one fixed-setting call."""
    t0 = time.perf_counter()
    result = rsocl.reconstruct(g, rig, iterations=iterations, tune=False, x0="interp3d", device=device)
    return time.perf_counter() - t0, result.datacube


def buffers_made(rig, g, device) -> dict:
    """``{variant: device buffers a warm call of 1 iteration makes}``."""
    own = pool.pool_for(device.queue)
    out = {}
    for name in VARIANTS:
        with variant(name):
            one_call(rig, g, 1, device)
            before = own.made
            one_call(rig, g, 1, device)
            out[name] = own.made - before
    return out


def measure(m: int, device, rounds: int, calls: int) -> dict:
    """``{"ms": {(variant, iterations): [median ms per round]}, "made": ..., "same": bool}`` for ROI ``m``."""
    rig, g = case(m)
    made = buffers_made(rig, g, device)
    ms: dict = {(name, it): [] for name in VARIANTS for it in ITERATIONS}
    cubes: dict = {}
    for r in range(rounds):
        order = list(VARIANTS) if r % 2 == 0 else list(VARIANTS)[::-1]
        for name in order:
            with variant(name):
                for it in ITERATIONS:
                    times = []
                    for _ in range(calls):
                        seconds, cube = one_call(rig, g, it, device)
                        times.append(seconds)
                    ms[name, it].append(1e3 * statistics.median(times))
                    cubes[name, it] = cube
    same = all(np.array_equal(cubes["pooled", it], cubes["made each call", it]) for it in ITERATIONS)
    return {"ms": ms, "made": made, "same": same, "T": rig.T}


def buffer_lines(times: dict, nbytes: int, count: int) -> list:
    """Markdown lines of :func:`buffer_us`'s times."""
    ratios = [a / b for a, b in zip(times["made"], times["pooled"])]
    made, pooled = (", ".join(f"{v:.2f}" for v in times[k]) for k in ("made", "pooled"))
    return [
        f"One buffer of {nbytes} bytes (a paper set's datacube) made, filled over 4 bytes and released, {count} "
        f"per round: **{statistics.median(times['made']):.2f} µs** ({made}); from the pool "
        f"**{statistics.median(times['pooled']):.2f} µs** ({pooled}); made / pooled {statistics.median(ratios):.2f} "
        f"({', '.join(f'{v:.2f}' for v in ratios)}).",
        "",
    ]


def lines(results: dict, rounds: int, calls: int) -> list:
    """Markdown table of :func:`measure`'s results by ROI."""
    out = [
        f"Median wall time of {calls} whole calls per round, {rounds} alternating rounds (medians of the rounds); "
        "`made / pooled`: a round's time with every buffer made over its time with the pool.",
        "",
        "| ROI | T | iterations | pooled ms (rounds) | made each call ms (rounds) | made / pooled (rounds) "
        "| buffers made by a warm call: pooled, made each call | same datacube |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for m, res in results.items():
        for it in ITERATIONS:
            a, b = res["ms"]["pooled", it], res["ms"]["made each call", it]
            ratios = [y / x for x, y in zip(a, b)]
            out.append(
                f"| {m}×{m} | {res['T']} | {it} | {statistics.median(a):.2f} ({', '.join(f'{v:.2f}' for v in a)}) | "
                f"{statistics.median(b):.2f} ({', '.join(f'{v:.2f}' for v in b)}) | "
                f"{statistics.median(ratios):.2f} ({', '.join(f'{v:.2f}' for v in ratios)}) | "
                f"{res['made']['pooled']}, {res['made']['made each call']} | {'yes' if res['same'] else 'NO'} |"
            )
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None, help="OpenCL device spec (default: rsocl's choice)")
    p.add_argument("--sizes", type=int, nargs="+", default=[8, 50], help="ROI sides m (m × m), pixels")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--calls", type=int, default=9, help="calls per variant, size and round")
    p.add_argument("--as-gpu", action="store_true", help="read the device as a GPU (its choices run on a CPU)")
    p.add_argument("--out", type=Path, default=None, help=f"write the page here (e.g. {DOCS / 'call_cost.md'})")
    args = p.parse_args(argv)
    for name in ("rounds", "calls"):
        if getattr(args, name) < 1:
            p.error(f"--{name} must be >= 1, got {getattr(args, name)}")
    if any(m < 2 for m in args.sizes):
        p.error(f"--sizes must be >= 2 pixels each, got {args.sizes}")
    device = get_device(args.device)
    nbytes = 4 * 50 * 50 * case(50)[0].T
    buffers = buffer_us(device, nbytes, 500, args.rounds)
    with path("gpu" if args.as_gpu else "device"):
        for m in args.sizes:  # kernel builds before any timing
            one_call(*case(m), 2, device)
        results = {m: measure(m, device, args.rounds, args.calls) for m in args.sizes}
    title = "A small call's cost beside its iterations: device buffers pooled or made each call"
    body = [
        *header_lines(title, device, None if argv is None else [__file__, *argv]),
        f"{small_calls(args.as_gpu)}. `pooled`: rsocl's default on a device that is not a CPU "
        f"(here with `rsocl.device.pool.ON_CPU` set), buffers up to {pool.LARGEST_BYTES // 2**20} MiB reused from "
        "`rsocl.device.pool`; `made each call`: every buffer created and released by the driver in each call, "
        "rsocl's default on a CPU device.",
        "",
        *buffer_lines(buffers, nbytes, 500),
        *lines(results, args.rounds, args.calls),
    ]
    emit(body, args.out)
    return results


if __name__ == "__main__":
    main()
