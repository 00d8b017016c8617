"""rsocl's TV kernels against the same loops compiled as C with OpenMP: the plain path against this CPU's ceiling.

Each ADMM-TV iteration of rsocl is mostly its inner Chambolle iterations: one ``tv_primal`` and one
``tv_dual`` launch each (``kernels/tv.cl``, one work item per voxel). ``tv_ceiling.c`` holds the
same arithmetic (the same square root, the same edge rules) as plain C loops, a row per call,
parallel over rows with OpenMP; this script compiles it with the system's C compiler
(``cc -O3 -march=native -fopenmp``: vector code for this very CPU) and times, in interleaved rounds,
calls of ``--chain`` TV iterations (primal, dual) on one set of the paper array's datacube at each
``--sizes``:

- rsocl's kernels on the OpenCL device, enqueued back to back and waited for once (launches
  included: what a denoising call pays);
- the C loops with 1 thread and with as many threads as the CPU offers to this process.

Before timing, one iteration from the same input and dual is run both ways and compared (largest
difference, float32). Bytes per voxel and iteration: 48 (primal 20: input, three dual planes,
output; dual 28: output, three dual planes read and written), neighbours counted once. Writes
docs/tv_ceiling.md (``--out``). Needs a C compiler with OpenMP (``cc``, or ``--cc``).

    python benchmarks/tv_ceiling.py [--sizes 50 64 128] [--rounds 20] [--chain 10] [--device SPEC] [--cc cc]
"""

from __future__ import annotations

import argparse
import ctypes
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rsocl_plugins.tv import STEP as TV_STEP

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import DOCS, header_lines, usable_cores, write_page  # noqa: E402

SOURCE = Path(__file__).resolve().parent / "tv_ceiling.c"
#: bytes per voxel each kernel must move (float32; see the module doc)
BYTES = {"tv_primal": 20, "tv_dual": 28}
WEIGHT = 3.0  # TV's default temporal weight
#: Chambolle's step tau at TV's default fraction of scikit-image's, and tau over the denoising weight 0.05
STEP = TV_STEP / (2.0 * (2.0 + WEIGHT**2))
STEP_OVER_WEIGHT = STEP / 0.05


def compile_library(cc: str, folder: Path):
    """The C loops as a shared library (``ctypes``); flags as used, or a RuntimeError saying what failed."""
    if shutil.which(cc) is None:
        raise RuntimeError(f"no C compiler {cc!r} on PATH (give one with --cc)")
    out = folder / "tv_ceiling.so"
    base = ["-O3", "-fopenmp", "-shared", "-fPIC", "-std=c99", str(SOURCE), "-o", str(out), "-lm"]
    for flags in (["-march=native"], []):
        done = subprocess.run([cc, *flags, *base], capture_output=True, text=True)
        if done.returncode == 0:
            lib = ctypes.CDLL(str(out))
            f, i, ptr = ctypes.c_float, ctypes.c_int, ctypes.c_void_p
            lib.tv_primal.argtypes = [ptr, ptr, ptr, f, i, i, i]
            lib.tv_dual.argtypes = [ptr, ptr, ptr, f, f, f, i, i, i]
            lib.set_threads.argtypes = [i]
            return lib, " ".join([cc, *flags, *base[:5]])
    raise RuntimeError(f"{cc} could not build {SOURCE.name}: {done.stderr.strip()[:400]}")


class Case:
    """One datacube of ``(T, m, n)``: its arrays on the host and on the device, both kernels each way."""

    def __init__(self, device, lib, T, m, n, seed=0):
        import pyopencl.array as cla

        from rsocl_plugins.tv import edge_weights, launches

        self.lib, self.queue, self.shape = lib, device.queue, (T, m, n)
        rng = np.random.default_rng(seed)
        self.img = rng.random((T, m, n), dtype=np.float32)
        p = (rng.random((3, T, m, n), dtype=np.float32) - 0.5) * 0.2
        # tv.cl's invariants: no difference across the last column, row and sub-frame (p stays 0 there)
        p[0, :, -1, :] = p[1, :, :, -1] = p[2, -1] = 0.0
        self.p0 = p
        self.host_p, self.host_out = p.copy(), np.empty_like(self.img)
        self.prog = device.program(["tv.cl"], REAL="float", TEMPORAL=1)
        self.grids = launches(self.prog, device, T, m, n)
        self.d_img, self.d_p = cla.to_device(self.queue, self.img), cla.to_device(self.queue, p)
        self.d_out = cla.empty(self.queue, self.img.shape, np.float32)
        self.xnext = edge_weights(n, np.float32)
        self.d_xnext = cla.to_device(self.queue, self.xnext)
        self.d_steps = cla.to_device(self.queue, np.array([STEP, STEP_OVER_WEIGHT, WEIGHT], np.float32))
        self.sizes = (np.int32(T), np.int32(m), np.int32(n), np.int32(1))

    def device_primal(self):
        for gsize, lsize, offset in self.grids:
            self.prog.tv_primal(
                self.queue,
                gsize,
                lsize,
                self.d_img.data,
                self.d_p.data,
                self.d_out.data,
                self.d_steps.data,
                *self.sizes,
                global_offset=offset,
            )

    def device_dual(self):
        for gsize, lsize, offset in self.grids:
            self.prog.tv_dual(
                self.queue,
                gsize,
                lsize,
                self.d_out.data,
                self.d_p.data,
                self.d_xnext.data,
                self.d_steps.data,
                *self.sizes,
                global_offset=offset,
            )

    def device_iterations(self, count):
        """``count`` TV iterations (primal, dual) enqueued back to back, as a denoising call issues them."""
        for _ in range(count):
            self.device_primal()
            self.device_dual()
        self.queue.finish()

    def c_iterations(self, count):
        for _ in range(count):
            self.c_primal()
            self.c_dual()

    def c_primal(self):
        T, m, n = self.shape
        self.lib.tv_primal(self.img.ctypes.data, self.host_p.ctypes.data, self.host_out.ctypes.data, WEIGHT, T, m, n)

    def c_dual(self):
        T, m, n = self.shape
        self.lib.tv_dual(
            self.host_out.ctypes.data,
            self.host_p.ctypes.data,
            self.xnext.ctypes.data,
            STEP,
            STEP_OVER_WEIGHT,
            WEIGHT,
            T,
            m,
            n,
        )

    def difference(self) -> float:
        """Largest difference between the two ways after one primal and one dual step from ``p0``."""
        import pyopencl as cl

        cl.enqueue_copy(self.queue, self.d_p.data, self.p0)
        self.host_p[...] = self.p0
        self.device_iterations(1)
        self.lib.set_threads(1)
        self.c_iterations(1)
        return float(max(np.abs(self.d_out.get() - self.host_out).max(), np.abs(self.d_p.get() - self.host_p).max()))


def measure(case, rounds, threads, chain):
    """Seconds per TV iteration of each way (rsocl, then C at each thread count), one per round of
    ``rounds``: calls of ``chain`` iterations, the ways interleaved call by call (a first call of each
    warms it up)."""
    ways = {"rsocl": case.device_iterations, **{f"C {t}t": case.c_iterations for t in threads}}
    times = {way: [] for way in ways}
    for r in range(rounds + 1):
        for way in ways if r % 2 == 0 else list(reversed(list(ways))):
            if way.startswith("C "):
                case.lib.set_threads(int(way[2:-1]))
            t0 = time.perf_counter()
            ways[way](chain)
            if r:
                times[way].append((time.perf_counter() - t0) / chain)
    return {way: np.array(v) for way, v in times.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[50, 64, 128], help="grid sides (>= 8), pixels")
    parser.add_argument("--rounds", type=int, default=20, help="timed calls each way (>= 3)")
    parser.add_argument("--chain", type=int, default=10, help="TV iterations per call (>= 1), as a denoising call")
    parser.add_argument("--device", default=None)
    parser.add_argument("--cc", default="cc", help="C compiler (with OpenMP)")
    parser.add_argument("--out", type=Path, default=DOCS / "tv_ceiling.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if args.rounds < 3 or args.chain < 1 or min(args.sizes) < 8:
        parser.error("--rounds must be >= 3, --chain >= 1 and every --sizes >= 8")
    os.environ.setdefault("OMP_WAIT_POLICY", "passive")  # idle OpenMP threads must not spin beside the device's
    import rsocl

    device = rsocl.device.get_device(args.device)
    cores = usable_cores()
    threads = sorted({1, cores})
    per_voxel = sum(BYTES.values())
    with tempfile.TemporaryDirectory() as folder:
        lib, command = compile_library(args.cc, Path(folder))
        version = subprocess.run([args.cc, "--version"], capture_output=True, text=True).stdout.splitlines()[0]
        page = header_lines(
            "rsocl's TV kernels against the same loops compiled as C",
            device,
            None if argv is None else [__file__, *argv],
        )
        page += [
            f"C: `{command}` ({version}), OpenMP over the rows (OMP_WAIT_POLICY="
            f"{os.environ['OMP_WAIT_POLICY']}). One set of the paper array's datacube per size (T of "
            f"`Rig.paper_array(4, (m, m), t_e=0.18e-3, t_r=35e-6)`), temporal weight {WEIGHT:g}, float32. A call "
            f"is {args.chain} TV iterations (primal, dual) back to back, as a denoising call issues them (rsocl: "
            "enqueued, then one wait); time per iteration: the median over "
            f"{args.rounds} calls, the ways interleaved call by call. GB/s from the {per_voxel} bytes per voxel an "
            f"iteration must move (primal {BYTES['tv_primal']}, dual {BYTES['tv_dual']}). Largest difference: "
            "output and dual after one iteration "
            "from the same input, rsocl against C.",
            "",
            "| datacube | rsocl (ms/iteration) | "
            + " | ".join(f"C, {t} thread{'s' if t > 1 else ''}" for t in threads)
            + " | rsocl / best C, round by round: median (range) | rsocl GB/s | best C GB/s | largest difference |",
            "|---|---|" + "---|" * len(threads) + "---|---|---|---|",
        ]
        ratios = []
        for size in args.sizes:
            T = rsocl.Rig.paper_array(4, (size, size), t_e=0.18e-3, t_r=35e-6).T
            case = Case(device, lib, T, size, size)
            diff = case.difference()
            rounds = measure(case, args.rounds, threads, args.chain)
            times = {way: float(np.median(v)) for way, v in rounds.items()}
            voxels = T * size * size
            best = min((f"C {t}t" for t in threads), key=times.get)
            paired = rounds["rsocl"] / np.min([rounds[f"C {t}t"] for t in threads], axis=0)
            ratio = f"{np.median(paired):.2f}x ({paired.min():.2f}-{paired.max():.2f}x)"
            ratios.append(f"{size}x{size}x{T}: {ratio}")
            cells = " | ".join(f"{times[f'C {t}t'] * 1e3:.3f}" for t in threads)
            page.append(
                f"| {size}x{size}x{T} | {times['rsocl'] * 1e3:.3f} | {cells} | {ratio} | "
                f"{per_voxel * voxels / times['rsocl'] / 1e9:.1f} | {per_voxel * voxels / times[best] / 1e9:.1f} | "
                f"{diff:.1e} |"
            )
            print(page[-1], flush=True)
    page += [
        "",
        "rsocl's time per TV iteration over the faster compiled C's of the same round (1 or all threads): "
        + ", ".join(ratios)
        + ".",
    ]
    write_page(args.out, page)


if __name__ == "__main__":
    main()
