"""Launches per ADMM-TV iteration and host time per launch, beside a trivial kernel's, in one run.

A small reconstruction on a fast device is bound by the host: every kernel launch costs the
time Python and the OpenCL runtime take to enqueue it. This benchmark counts what one ADMM
iteration enqueues and how long the host spends per enqueue, against the floor of the same
device: a kernel with one work item and one buffer argument, enqueued in a loop.

- **Launches per iteration**: every ``enqueue_nd_range_kernel``, ``enqueue_copy`` and
  ``enqueue_fill_buffer`` that pyopencl is asked for, counted during fixed-setting runs
  (``tune=False``, start ``x0="interp3d"``) of two lengths; the difference over the difference
  of iterations is what one iteration costs (set-up and read-back cancel out).
- **Host µs per launch**: the wall time of an iteration of the tiny case (so small that the
  kernels' own work is negligible) over its launches, and the same for the trivial kernel's
  loop. Their ratio says how far the solver's host path is from the floor.
- **Against a bare replay** (:func:`replay_us`, the smallest ROI): the same launches that rsocl's
  loop makes, recorded during a run and enqueued again with nothing between them: rsocl's host
  path over the cost of these very kernels' enqueues on this device.

Five paths are measured (``--paths``, :data:`PATHS`): ``device``, what the device chooses; ``gpu``, what
rsocl chooses on a device that is not a CPU (the dual update and ``u = f - b`` folded into the TV's and the
projection's launches, the TV's last primal step made by the next projection, the plain TV in one launch per
Chambolle iteration); ``gpu-two``, that with the
plain TV in two launches per iteration; ``gpu-pairs``, that with one launch per two iterations;
``lean``, that with the TV's fused path. On a CPU device the last four run by reading the device as a
GPU for the run.

Rounds alternate the trivial loop and the ADMM runs of each path, and the median of the rounds is reported.
Then the passes that the GPU paths fold are timed against the separate ones they replace, in
alternating rounds (:func:`passes`): what a device's choice of path rests on.

    python benchmarks/launches.py [--shapes 8 50 64] [--paths device gpu gpu-two gpu-pairs lean] [--rounds 5]
        [--out docs/launches.md]
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

from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import make_scene  # noqa: E402

import rsocl  # noqa: E402
from rsocl.device.context import get_device  # noqa: E402
from rsocl.model import reference as ref  # noqa: E402

#: The paper's array: exposure and row readout time, seconds.
T_E, T_R = 0.18e-3, 35e-6
#: The enqueue calls that are counted (pyopencl module-level names).
COUNTED = ("enqueue_nd_range_kernel", "enqueue_copy", "enqueue_fill_buffer")

TRIVIAL = "__kernel void trivial(__global float *x) { x[get_global_id(0)] += 1.0f; }"


@contextmanager
def counting():
    """Count the enqueues of :data:`COUNTED` while the block runs; yields a dict ``{name: count}``. Kernel
    launches made by ``pyopencl.array`` arithmetic (its generated invokers call ``pyopencl._cl`` directly)
    count too."""
    import pyopencl as cl
    import pyopencl._cl as _cl

    counts = dict.fromkeys(COUNTED, 0)
    saved = {name: getattr(cl, name) for name in COUNTED}
    raw = _cl.enqueue_nd_range_kernel

    def wrap(name, fn):
        def counted(*args, **kwargs):
            counts[name] += 1
            return fn(*args, **kwargs)

        return counted

    for name, fn in saved.items():
        setattr(cl, name, wrap(name, fn))
    _cl.enqueue_nd_range_kernel = wrap("enqueue_nd_range_kernel", raw)
    try:
        yield counts
    finally:
        for name, fn in saved.items():
            setattr(cl, name, fn)
        _cl.enqueue_nd_range_kernel = raw


def trivial_launch_us(device, launches: int = 2000) -> float:
    """Host µs per enqueue of a one-work-item kernel with one buffer argument, after a finish."""
    import pyopencl as cl

    buf = cl.Buffer(device.context, cl.mem_flags.READ_WRITE, 4)
    kernel = cl.Program(device.context, TRIVIAL).build().trivial
    kernel.set_arg(0, buf)
    queue = device.queue
    for _ in range(50):
        cl.enqueue_nd_range_kernel(queue, kernel, (1,), None)
    queue.finish()
    t0 = time.perf_counter()
    for _ in range(launches):
        cl.enqueue_nd_range_kernel(queue, kernel, (1,), None)
    queue.finish()
    return (time.perf_counter() - t0) / launches * 1e6


def small_calls(as_gpu: bool) -> str:
    """The sentence a page of small fixed-setting calls on :func:`case`'s frames opens with, naming the path
    (``as_gpu``: launches.py's ``gpu`` path, a GPU's choices run by this device)."""
    where = "the device read as a GPU (its choices run by this CPU)" if as_gpu else "the device's own choices"
    return (
        "Paper array (4 cameras at 0/90/180/270°, t_e = 0.18 ms, t_r = 35 µs), the built-in scene, float32, "
        f"fixed settings from the interpolation, on {where}"
    )


def case(m: int, scene: str = "builtin"):
    """The paper's 4-camera array on an ``m × m`` grid of ``scene`` (``benchmarks/quality_scenes.py``; the
    built-in scene by default): ``(rig, snapshots)``."""
    rig = rsocl.Rig.paper_array(4, (m, m), T_E, T_R)
    return rig, ref.forward(rig, make_scene(scene, rig.shape, rig.T)).astype(np.float32)


#: ``fused`` of the lean path: as many Chambolle iterations per launch as the TV's tile plan allows.
LEAN_FUSED = 16

#: The paths: (read the device as one that is not a CPU, ``GPU_FUSED``, ``GPU_ONE_LAUNCH``); None: as it is.
PATHS = {
    "device": (False, None, None),
    "gpu": (True, None, None),
    "gpu-two": (True, 0, 0),
    "gpu-pairs": (True, 0, 2),
    "lean": (True, LEAN_FUSED, None),
}


@contextmanager
def path(name: str):
    """Run the block on path ``name`` of :data:`PATHS`: ``device``, the device's own choice; ``gpu``, the
    device read as one that is not a CPU, with the choices rsocl makes for such a device (the ADMM's passes
    folded, the plain TV in one launch per Chambolle iteration); ``gpu-two``, that with the plain TV in two
    launches per iteration; ``gpu-pairs``, that with one launch per two iterations (``tv_step2``); ``lean``,
    that with the fused TV (:data:`LEAN_FUSED`)."""
    import rsocl_plugins.tv as tv
    from rsocl.device.context import Device

    as_gpu, fused, one_launch = PATHS[name]
    saved = Device.is_cpu, tv.GPU_FUSED, tv.GPU_ONE_LAUNCH
    if as_gpu:
        Device.is_cpu = property(lambda self: False)
    tv.GPU_FUSED = tv.GPU_FUSED if fused is None else fused
    tv.GPU_ONE_LAUNCH = tv.GPU_ONE_LAUNCH if one_launch is None else one_launch
    try:
        yield
    finally:
        Device.is_cpu, tv.GPU_FUSED, tv.GPU_ONE_LAUNCH = saved


def run(rig, g, iterations: int, device, name: str = "device"):
    """One fixed-setting reconstruction on path ``name``; returns ``(seconds, enqueue counts)``."""
    with path(name), counting() as counts:
        t0 = time.perf_counter()
        rsocl.reconstruct(g, rig, iterations=iterations, tune=False, x0="interp3d", device=device)
        seconds = time.perf_counter() - t0
    return seconds, dict(counts)


def per_iteration(rig, g, device, short: int, long: int, name: str = "device"):
    """``(launches per iteration by kind, seconds per iteration)`` from runs of ``short`` and ``long``."""
    t_short, c_short = run(rig, g, short, device, name)
    t_long, c_long = run(rig, g, long, device, name)
    span = long - short
    return {k: (c_long[k] - c_short[k]) / span for k in COUNTED}, (t_long - t_short) / span


#: Iterations of launches the replay repeats, and how many times (:func:`replay_us`).
REPLAY_ITERATIONS, REPLAY_REPEATS = 8, 25


def replay_us(rig, g, device, name: str, per_iteration: int) -> float:
    """Host µs per launch of the kernel launches rsocl's loop makes on path ``name``, replayed in a bare loop.

    During a fixed-setting run, once 4 iterations have passed, the last :data:`REPLAY_ITERATIONS`
    iterations' launches (``per_iteration`` each: every kernel enqueued through
    :class:`rsocl.device.kernel.Kernel`, the same kernel objects and grids, arguments as they are set) are
    enqueued :data:`REPLAY_REPEATS` times with plain ``pyopencl.enqueue_nd_range_kernel`` calls and no
    Python in between, then waited for: what the same launches cost without rsocl's host path.
    """
    import pyopencl as cl

    from rsocl.device import kernel as kernel_module

    log, result = [], []
    body_size = per_iteration * REPLAY_ITERATIONS
    target = [0]  # set once the set-up's launches are known: no replay before
    enqueue, call = kernel_module.Kernel.enqueue, kernel_module.Kernel.__call__

    def replay(queue):
        body = log[-body_size:]
        queue.finish()
        t0 = time.perf_counter()
        for _ in range(REPLAY_REPEATS):
            for q, k, gsize, lsize, offset in body:
                cl.enqueue_nd_range_kernel(q, k, gsize, lsize, global_work_offset=offset)
        queue.finish()
        result.append((time.perf_counter() - t0) / (REPLAY_REPEATS * body_size) * 1e6)

    def logged(self, queue, gsize, lsize, offset):
        log.append((queue, self.kernel, gsize, lsize, offset))
        if len(log) == target[0] and not result:
            replay(queue)  # inside the run: every buffer the launches name is alive

    def hooked_enqueue(self, queue, gsize, lsize, global_offset=None):
        logged(self, queue, gsize, lsize, global_offset)
        return enqueue(self, queue, gsize, lsize, global_offset)

    def hooked_call(self, queue, gsize, lsize, *args, global_offset=None, wait_for=None):
        event = call(self, queue, gsize, lsize, *args, global_offset=global_offset, wait_for=wait_for)
        logged(self, queue, gsize, lsize, global_offset)
        return event

    kernel_module.Kernel.enqueue, kernel_module.Kernel.__call__ = hooked_enqueue, hooked_call
    try:
        with path(name):
            rsocl.reconstruct(g, rig, iterations=1, tune=False, x0="interp3d", device=device)
            setup = len(log) - per_iteration  # a call's launches before its first iteration
            log.clear()
            target[0] = setup + per_iteration * (REPLAY_ITERATIONS + 4)
            rsocl.reconstruct(g, rig, iterations=REPLAY_ITERATIONS + 8, tune=False, x0="interp3d", device=device)
    finally:
        kernel_module.Kernel.enqueue, kernel_module.Kernel.__call__ = enqueue, call
    return result[0] if result else float("nan")


def measure(shapes, rounds: int, short: int, long: int, device, paths=tuple(PATHS)):
    """Alternating rounds of the trivial loop and each shape's runs on each path (their order reversed
    every other round); per-shape and path medians."""
    cases = {m: case(m) for m in shapes}
    for rig, g in cases.values():  # warm-up: kernel builds, the interpolation's set-up
        for name in paths:
            run(rig, g, 2, device, name)
    trivial = []
    replays = {name: [] for name in paths}  # at the smallest ROI, which isolates the host path
    rows = {(m, name): [] for m in shapes for name in paths}
    calls = {(m, name): [] for m in shapes for name in paths}
    launches = {}
    for r in range(rounds):
        trivial.append(trivial_launch_us(device))
        for m, (rig, g) in cases.items():
            for name in paths if r % 2 == 0 else paths[::-1]:
                kinds, seconds = per_iteration(rig, g, device, short, long, name)
                launches[m, name] = kinds
                rows[m, name].append(seconds)
                calls[m, name].append(statistics.median(run(rig, g, 1, device, name)[0] for _ in range(5)))
                if m == min(shapes):
                    kernels = int(round(kinds["enqueue_nd_range_kernel"]))
                    replays[name].append(
                        (seconds / sum(kinds.values()) * 1e6, replay_us(rig, g, device, name, kernels))
                    )
    floor = statistics.median(trivial)
    out = []
    for m in shapes:
        for name in paths:
            total = sum(launches[m, name].values())
            seconds = statistics.median(rows[m, name])
            us = seconds / total * 1e6 if total else float("nan")
            out.append(
                {
                    "m": m,
                    "T": cases[m][0].T,
                    "path": name,
                    "launches": launches[m, name],
                    "total": total,
                    "ms_per_iteration": seconds * 1e3,
                    "rounds_ms": [v * 1e3 for v in rows[m, name]],
                    "us_per_launch": us,
                    "ratio": us / floor,
                    "call_ms": statistics.median(calls[m, name]) * 1e3,
                    "call_rounds_ms": [v * 1e3 for v in calls[m, name]],
                }
            )
    return floor, trivial, out, replays


def passes(m: int, device, rounds: int, reps: int = 100):
    """The folded passes against the separate ones on the ``m × m`` case, in alternating rounds of ``reps``
    enqueues each (a finish around each round): ``[(name, separate µs, folded µs, folded / separate per round)]``.

    - the residual: ``forward`` + ``sum_sq_diff`` against ``residual_partials`` (one launch);
    - the residual in the projection: ``admm_project`` + ``residual_partials`` against ``admm_project``
      adding the residual of the estimate to its own launch;
    - ``u = f - b``: ``admm_project`` + ``admm_difference`` against ``admm_project`` writing u itself;
    - the ADMM's dual update: ``tv_primal`` + ``admm_dual`` against ``tv_primal_update``;
    - one Chambolle iteration: ``tv_primal`` + ``tv_dual`` against ``tv_step`` (two copies of p);
    - two Chambolle iterations: two ``tv_step`` against one ``tv_step2``;
    - the first two Chambolle iterations (from ``p = 0``): ``tv_dual_first`` + ``tv_step`` against ``tv_first2``;
    - on a device where the projection makes the TV's last primal step (``Regularizer.deferred_primal_on``):
      ``tv_primal_update`` + ``admm_project`` (with the residual) against ``admm_project`` making it first.
    """
    import pyopencl.array as cla

    from rsocl.device.reduction import sum_sq_diff_async
    from rsocl.model.operator import RollingShutterOperator
    from rsocl.solver.admm import ADMM, PROJECT_DEFERRED
    from rsocl_plugins.tv import TV
    from rsocl_plugins.tv import launches as tv_launches

    rig, g = case(m)
    op = RollingShutterOperator(rig, device=device, subframes=rig.sampled_range())
    tv = TV(fused=0)
    s = ADMM(op, cla.to_device(op.queue, g), tv, lam=0.1, eta=0.2)
    s.step()
    q, prog, T = op.queue, s.program, op.T
    tv_prog = tv._program(s.u, "tv.cl")
    grids = tv_launches(tv_prog, device, T, m, m)
    (p, p2), xnext = tv._buffers(s.u, 2)
    steps = tv._steps(q, [0.5], s.u.dtype)
    sizes = (np.int32(T), np.int32(m), np.int32(m), np.int32(1))

    def project(difference, slot=-1):  # the solver's own projection, with u = f - b and the residual or not
        s._project.set_arg(11, np.int32(difference))
        s._project.enqueue(q, *s.project_grid, (0, 0, slot + 1))  # the residual's slot is the offset along the sets

    def project_then_difference():
        project(0)
        for gs, ls, off in s.elements:
            prog.admm_difference(q, gs, ls, s.f.data, s.b.data, s.u.data, global_offset=off)

    def primal_then_dual():
        for gs, ls, off in grids:
            tv_prog.tv_primal(q, gs, ls, s.u.data, p.data, s.theta.data, steps.data, *sizes, global_offset=off)
        for gs, ls, off in s.voxels:
            prog.admm_dual(
                q,
                gs,
                ls,
                s.theta.data,
                s.b.data,
                s.f.data,
                s.dual_on.data,
                np.int32(1),
                np.int32(s.per_set),
                global_offset=off,
            )

    def primal_update():
        for gs, ls, off in grids:
            tv_prog.tv_primal_update(
                q,
                gs,
                ls,
                s.u.data,
                p.data,
                s.theta.data,
                steps.data,
                *sizes,
                s.b.data,
                s.f.data,
                s.dual_on.data,
                global_offset=off,
            )

    def primal_dual():
        for gs, ls, off in grids:
            tv_prog.tv_primal(q, gs, ls, s.u.data, p.data, s.theta.data, steps.data, *sizes, global_offset=off)
        for gs, ls, off in grids:
            tv_prog.tv_dual(q, gs, ls, s.theta.data, p.data, xnext.data, steps.data, *sizes, global_offset=off)

    def one_step():
        for gs, ls, off in grids:
            tv_prog.tv_step(q, gs, ls, s.u.data, p.data, p2.data, xnext.data, steps.data, *sizes, global_offset=off)

    def two_steps():
        one_step()
        for gs, ls, off in grids:
            tv_prog.tv_step(q, gs, ls, s.u.data, p2.data, p.data, xnext.data, steps.data, *sizes, global_offset=off)

    def step_pair():
        for gs, ls, off in grids:
            tv_prog.tv_step2(q, gs, ls, s.u.data, p.data, p2.data, xnext.data, steps.data, *sizes, global_offset=off)

    def first_then_step():
        for gs, ls, off in grids:
            tv_prog.tv_dual_first(q, gs, ls, s.u.data, p.data, xnext.data, steps.data, *sizes, global_offset=off)
        one_step()

    def first_two():
        for gs, ls, off in grids:
            tv_prog.tv_first2(q, gs, ls, s.u.data, p2.data, xnext.data, steps.data, *sizes, global_offset=off)

    def forward_then_sum():
        op.forward_into(s.theta, s.hx)
        sum_sq_diff_async(s.g, s.hx)

    def project_then_residual():
        project(1)
        s.residual_into(0)

    pairs = [
        ("residual: forward + sum_sq_diff | residual_partials", forward_then_sum, lambda: s.residual_into(0)),
        (
            "residual in the projection: admm_project + residual_partials | admm_project with the residual",
            project_then_residual,
            lambda: project(1, 0),
        ),
        (
            "u = f - b: admm_project + admm_difference | admm_project writing u",
            project_then_difference,
            lambda: project(1),
        ),
        ("dual update: tv_primal + admm_dual | tv_primal_update", primal_then_dual, primal_update),
        ("Chambolle iteration: tv_primal + tv_dual | tv_step", primal_dual, one_step),
        ("two Chambolle iterations: tv_step + tv_step | tv_step2", two_steps, step_pair),
        ("first two Chambolle iterations: tv_dual_first + tv_step | tv_first2", first_then_step, first_two),
    ]

    def project_deferred(on):  # the projection with the residual, making the TV's last primal step first or not
        s._project.set_arg(PROJECT_DEFERRED, np.int32(on))
        project(1, 0)

    def primal_update_then_project():
        primal_update()
        project_deferred(0)

    if s._defines is not None:  # the solver's projection takes the TV's final dual and steps (bound at its step)
        pairs.append(
            (
                "last primal step in the projection: tv_primal_update + admm_project | admm_project making it",
                primal_update_then_project,
                lambda: project_deferred(1),
            )
        )

    def timed(fn):
        q.finish()
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        q.finish()
        return (time.perf_counter() - t0) / reps * 1e6

    out = []
    for name, separate, folded in pairs:
        timed(separate), timed(folded)
        a, b = [], []
        for r in range(rounds):
            if r % 2:
                b.append(timed(folded)), a.append(timed(separate))
            else:
                a.append(timed(separate)), b.append(timed(folded))
        out.append((name, statistics.median(a), statistics.median(b), [y / x for x, y in zip(a, b)]))
    return out


def command_buffers(device) -> list:
    """Lines on record-once-replay (``cl_khr_command_buffer``): whether the device lists the extension
    and whether pyopencl binds its API (any name with "command_buffer" or "CommandBuffer")."""
    import pyopencl as cl
    import pyopencl._cl as _cl

    listed = "cl_khr_command_buffer" in device.device.extensions.split()
    names = sorted({n for mod in (cl, _cl) for n in dir(mod) if "command_buffer" in n.lower() or "CommandBuffer" in n})
    return [
        f"`cl_khr_command_buffer` in this device's extension list: **{'yes' if listed else 'no'}**; "
        f"command-buffer names in pyopencl {cl.VERSION_TEXT}: **{', '.join(names) if names else 'none'}**."
    ]


def page(floor, trivial, rows, device, args, passes_rows=None, replays=None) -> list:
    lines = header_lines("Launches per ADMM-TV iteration and host time per launch", device)
    lines += [
        "",
        "Paper array (4 cameras at 0/90/180/270°, t_e = 0.18 ms, t_r = 35 µs), built-in scene,",
        f"fixed settings from the interpolation, float32; {args.rounds} alternating rounds, medians.",
        f"Launches per iteration: counts of runs of {args.long} and {args.short} iterations, differenced.",
        "",
        f"Trivial kernel (one work item, one buffer argument): **{floor:.1f} µs** per enqueue "
        f"(rounds: {', '.join(f'{t:.1f}' for t in trivial)}).",
        "",
        "| ROI | T | path | kernels | copies | fills | launches / iteration | ms / iteration (rounds) "
        "| µs / launch | × trivial | ms / call of 1 iteration (rounds) | call in trivial launches |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        k = r["launches"]
        each = ", ".join(f"{v:.2f}" for v in r["rounds_ms"])
        lines.append(
            f"| {r['m']}×{r['m']} | {r['T']} | {r['path']} | {k['enqueue_nd_range_kernel']:.1f} | "
            f"{k['enqueue_copy']:.3f} | {k['enqueue_fill_buffer']:.1f} | {r['total']:.2f} | "
            f"{r['ms_per_iteration']:.2f} ({each}) | {r['us_per_launch']:.1f} | {r['ratio']:.2f} | "
            f"{r['call_ms']:.1f} ({', '.join(f'{v:.1f}' for v in r['call_rounds_ms'])}) | "
            f"{r['call_ms'] * 1e3 / floor:.0f} |"
        )
    if replays:
        m = min(r["m"] for r in rows)
        lines += [
            "",
            f"The host path against a bare replay of its own launches ({m}×{m}, `replay_us`: the launches of "
            f"{REPLAY_ITERATIONS} iterations, same kernels, grids and arguments, enqueued {REPLAY_REPEATS} times "
            "with nothing between them; µs per launch, one measurement per round):",
            "",
            "| path | rsocl µs / launch | replay µs / launch | rsocl / replay (rounds) |",
            "|---|---|---|---|",
        ]
        for name, pairs in replays.items():
            ratios = [a / b for a, b in pairs]
            lines.append(
                f"| {name} | {statistics.median(a for a, _ in pairs):.1f} | "
                f"{statistics.median(b for _, b in pairs):.1f} | "
                f"{statistics.median(ratios):.2f} ({', '.join(f'{r:.2f}' for r in ratios)}) |"
            )
    if passes_rows:
        lines += [
            "",
            "The folded passes against the separate ones (µs per enqueue of the pair or of the one, "
            f"{args.rounds} alternating rounds of 100, medians):",
            "",
            "| ROI | separate \\| folded | separate µs | folded µs | folded / separate (rounds) |",
            "|---|---|---|---|---|",
        ]
        for m, rows_m in passes_rows.items():
            for name, a, b, ratios in rows_m:
                lines.append(
                    f"| {m}×{m} | {name.replace('|', chr(92) + '|')} | {a:.0f} | {b:.0f} | "
                    f"{', '.join(f'{r:.2f}' for r in ratios)} |"
                )
    lines += [""] + command_buffers(device)
    lines += [
        "",
        "Paths: `device` is the device's own choice. `gpu` is what rsocl chooses on a device that is not a",
        "CPU: the ADMM's dual update and u = f - b folded into the TV's and the projection's launches, the",
        "TV's last primal step made by the next projection, the",
        "plain TV in one launch per Chambolle iteration (`tv_step` on two copies of the dual); `gpu-two` is",
        "that with the plain TV in two launches per iteration (`tv_primal`, `tv_dual`); `gpu-pairs` that with",
        "one launch per two iterations (`tv_step2`, each work item also stepping the dual of the twelve voxels",
        "around it); `lean` that with the fused TV (tiles in local memory). On a CPU device these four run by",
        "reading the device as a GPU, and their times are those of a GPU's choices run by a CPU (the fused",
        "TV's tiles of hundreds of work items with barriers, the recomputed neighbours of tv_step and",
        "tv_step2): there the launch counts are the",
        "measurement, the times say nothing about a GPU. Every path reads the residuals",
        "of 8 iterations (`rsocl.solver.admm.RESIDUAL_SLOTS`) in one copy.",
        "",
        "µs / launch is the iteration's wall time over its launches: on a CPU device the kernels'",
        "own work shares the cores with the host, so only the smallest ROI isolates the host path.",
        "A call of 1 iteration is a whole `reconstruct` call (median of 5 per round): its fixed cost (the",
        "problem's set-up, the interpolation's start, the solver's set-up and the read-back), also",
        "counted in trivial launches of the same run.",
    ]
    return lines


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--shapes", type=int, nargs="+", default=[8, 50, 64], help="ROI sizes m (m × m)")
    p.add_argument(
        "--paths",
        nargs="+",
        choices=tuple(PATHS),
        default=list(PATHS),
        help="launch paths (default: all)",
    )
    p.add_argument("--rounds", type=int, default=5, help="alternating rounds (default 5)")
    p.add_argument(
        "--no-passes", dest="passes", action="store_false", help="leave out the folded passes against the separate ones"
    )
    p.add_argument("--short", type=int, default=20, help="iterations of the short run (default 20)")
    p.add_argument("--long", type=int, default=100, help="iterations of the long run (default 100)")
    p.add_argument("--device", default=None, help="OpenCL device spec (default: rsocl's choice)")
    p.add_argument("--out", type=Path, default=None, help=f"write the page here (e.g. {DOCS / 'launches.md'})")
    args = p.parse_args(argv)
    if args.long <= args.short or args.short < 1:
        p.error(f"--long ({args.long}) must exceed --short ({args.short}) >= 1")
    device = get_device(args.device)
    floor, trivial, rows, replays = measure(args.shapes, args.rounds, args.short, args.long, device, tuple(args.paths))
    passes_rows = {m: passes(m, device, args.rounds) for m in args.shapes if m >= 8} if args.passes else None
    lines = page(floor, trivial, rows, device, args, passes_rows, replays)
    print("\n".join(lines))
    if args.out:
        write_page(args.out, lines)


if __name__ == "__main__":
    main()
