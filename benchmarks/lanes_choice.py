"""The projection's lanes per block, timed on this device, and the count the timings choose.

``admm_project`` (``kernels/admm.cl``) may give each block of pixels ``PROJECT_LANES`` work items, which share
the passes over the block's whole column (``rsocl.solver.admm.GPU_PROJECT_LANES``, on a device that is not a
CPU). More lanes shorten the longest work item of a small frame and add work items that wait at the barriers
of a large one. This benchmark runs fixed-setting reconstructions (``tune=False``, ``x0="interp3d"``, the
built-in scene on the paper array) of each case, ``m×m`` pixels in batches of ``B`` sets (``--cases 50x1
50x5``: the paper set, and a batch of five as the self-tuned search's), with each lane count of ``--lanes``
on a queue with profiling, and reports the device's busy time per ADMM iteration (the kernels' sum of
``CL_PROFILING_COMMAND_START`` to ``END``, :mod:`kernel_times`), the median of ``--rounds`` rounds, each
round taking the lane counts in a rotated order.

The choice (:func:`choose`): among the lane counts that make no case busier than one lane's by more than
:data:`TOLERANCE`, the one whose busy time over one lane's has the smallest geometric mean over the cases,
where that mean is below ``1 - MIN_GAIN``; else one lane. Busy time, not wall time, because lanes change no
launch: where the host bounds a loop (one small set) they cannot change its wall time, and where the device
does, its busy time is the loop's. With ``--budget``, no case but the first starts after that many seconds:
the choice is made on the cases timed, and the page names the others. ``--choice FILE`` writes the chosen
count (``benchmarks/gpu_check.sh`` runs the later benchmarks with it through ``RSOCL_BENCH_PROJECT_LANES``,
:mod:`provenance`).

    python benchmarks/lanes_choice.py [--device SPEC] [--cases 50x1 256x1 50x5 128x1 50x64 50x9]
        [--lanes 1 2 4 8] [--iterations 10] [--rounds 2] [--budget SECONDS] [--as-gpu] [--choice FILE]
        [--out docs/lanes_choice.md]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from kernel_times import SKIP, profiling_device, record, summarise  # noqa: E402
from launches import case, path, small_calls  # noqa: E402
from provenance import DOCS, emit, header_lines, power_of_two, write_page  # noqa: E402

import rsocl.solver.admm as admm_module  # noqa: E402
from rsocl.device.context import get_device  # noqa: E402

#: The most a chosen lane count may raise any case's busy time over one lane's (a fraction).
TOLERANCE = 0.03
#: The least a chosen lane count must lower the geometric mean of the cases' busy times over one lane's.
MIN_GAIN = 0.03
#: The cases by default, the most telling first (``--budget`` may leave the last ones out): the paper set, a
#: frame where the device bounds the loop, a batch of the self-tuned search's size, 128×128, 64 sets per call,
#: and the search's larger batches.
CASES = ("50x1", "256x1", "50x5", "128x1", "50x64", "50x9")


def parse_case(text: str) -> tuple:
    """``"MxB"`` as ``(m, sets)``: ``m × m`` pixels (>= 2), ``B`` sets (>= 1)."""
    try:
        m, sets = (int(part) for part in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"a case is MxB (pixels x sets, e.g. 50x5), got {text!r}") from None
    if m < 2 or sets < 1:
        raise argparse.ArgumentTypeError(f"a case needs m >= 2 pixels and B >= 1 sets, got {text!r}")
    return m, sets


def choose(busy: dict, tolerance: float = TOLERANCE, min_gain: float = MIN_GAIN) -> tuple:
    """The lane count the timings choose (see the module doc) and each count's geometric-mean ratio.

    Parameters
    ----------
    busy : dict
        ``{case: {lanes: busy µs per iteration}}``; every case holds one lane (the baseline).
    tolerance, min_gain : float
        :data:`TOLERANCE`, :data:`MIN_GAIN`.

    Returns
    -------
    (int, dict)
        The chosen count and ``{lanes: (geometric mean, largest ratio)}`` of every count timed in every case.
    """
    counts = sorted(set.intersection(*(set(times) for times in busy.values())))
    if 1 not in counts:
        raise ValueError("every case needs one lane's time, the baseline")
    scores = {}
    for lanes in counts:
        ratios = [times[lanes] / times[1] for times in busy.values()]
        scores[lanes] = (math.exp(statistics.fmean(math.log(r) for r in ratios)), max(ratios))
    fit = [lanes for lanes in counts if scores[lanes][1] <= 1 + tolerance and scores[lanes][0] < 1 - min_gain]
    return (min(fit, key=lambda lanes: (scores[lanes][0], lanes)) if fit else 1), scores


def time_case(m: int, sets: int, lanes_list: list, device, iterations: int, rounds: int) -> tuple:
    """``(T, {lanes: median busy µs per iteration}, {lanes: lanes the solver used})`` of ``m×m`` in batches of
    ``sets``, rounds rotating the order of ``lanes_list``; a solver uses fewer lanes where its work groups would
    not fit (:func:`rsocl.solver.admm.lanes_that_fit`)."""
    rig, g = case(m)
    samples: dict = {lanes: [] for lanes in lanes_list}
    used: dict = {}
    saved, init = admm_module.GPU_PROJECT_LANES, admm_module.ADMM.__init__

    def recording(self, *args, **kwargs):
        init(self, *args, **kwargs)
        used[admm_module.GPU_PROJECT_LANES] = self.lanes

    admm_module.ADMM.__init__ = recording
    try:
        for r in range(rounds):
            shift = r % len(lanes_list)
            for lanes in lanes_list[shift:] + lanes_list[:shift]:
                admm_module.GPU_PROJECT_LANES = lanes
                samples[lanes].append(summarise(record(rig, g, device, iterations, sets), iterations)["busy"])
    finally:
        admm_module.GPU_PROJECT_LANES, admm_module.ADMM.__init__ = saved, init
    return rig.T, {lanes: statistics.median(v) for lanes, v in samples.items()}, used


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None, help="OpenCL device spec (default: rsocl's choice)")
    p.add_argument("--cases", type=parse_case, nargs="+", default=[parse_case(c) for c in CASES], help="MxB each")
    p.add_argument("--lanes", type=int, nargs="+", default=[1, 2, 4, 8], help="lane counts (powers of two, with 1)")
    p.add_argument("--iterations", type=int, default=10, help="iterations recorded per run (>= 1)")
    p.add_argument("--rounds", type=int, default=2, help="rounds of every lane count per case (>= 1)")
    p.add_argument("--budget", type=float, default=None, help="seconds after which no case but the first starts (> 0)")
    p.add_argument("--as-gpu", action="store_true", help="read the device as a GPU (its choices run on a CPU)")
    p.add_argument("--choice", type=Path, default=None, help="write the chosen lane count to this file")
    p.add_argument("--out", type=Path, default=None, help=f"write the page here (e.g. {DOCS / 'lanes_choice.md'})")
    args = p.parse_args(argv)
    if args.iterations < 1 or args.rounds < 1:
        p.error(f"--iterations and --rounds must be >= 1, got {args.iterations} and {args.rounds}")
    if args.budget is not None and not args.budget > 0:
        p.error(f"--budget must be > 0 seconds, got {args.budget}")
    if 1 not in args.lanes or not all(map(power_of_two, args.lanes)):
        p.error(f"--lanes must be powers of two (1, 2, 4, ...) and hold 1, the baseline, got {args.lanes}")
    lanes_list = list(dict.fromkeys(args.lanes))
    device = profiling_device(get_device(args.device))
    busy, rows, left = {}, [], []
    start = time.perf_counter()
    with path("gpu" if args.as_gpu else "device"):
        for m, sets in args.cases:
            label = f"{m}×{m}" + ("" if sets == 1 else f", {sets} sets")
            if busy and args.budget is not None and time.perf_counter() - start > args.budget:
                left.append(label)
                continue
            T, times, used = time_case(m, sets, lanes_list, device, args.iterations, args.rounds)
            busy[label] = times
            cells = " | ".join(
                f"{times[n]:.1f} ({times[n] / times[1]:.2f})" + ("" if used[n] == n else f" [{used[n]} taken]")
                for n in lanes_list
            )
            rows.append(f"| {label} | {T} | {cells} |")
            print(rows[-1], flush=True)
    chosen, scores = choose(busy)
    title = "The projection's lanes: device time per iteration, and the choice"
    page = header_lines(title, device, None if argv is None else [__file__, *argv])
    page += [
        f"{small_calls(args.as_gpu)}; a queue with profiling; the {args.iterations} iterations after the first "
        f"{SKIP} of a run; the device's busy time per ADMM iteration (µs, the kernels' sum), the median of "
        f"{args.rounds} rounds in rotated order, and in brackets over one lane's; `[k taken]`: the solver took k lanes "
        "(one on a CPU device, or where the regularizer does not fuse the dual update; fewer where the work groups "
        "would not fit).",
        "",
        "| case | T | " + " | ".join(f"{n} lane{'s' if n > 1 else ''}" for n in lanes_list) + " |",
        "|---|---|" + "---|" * len(lanes_list),
        *rows,
        "| **geometric mean over one lane's (largest)** | | "
        + " | ".join(f"{scores[n][0]:.3f} ({scores[n][1]:.2f})" for n in lanes_list)
        + " |",
        "",
        f"Chosen: **{chosen}** (the smallest geometric mean below {1 - MIN_GAIN:g} among the counts that raise no "
        f"case above {1 + TOLERANCE:g}× one lane's; else 1)"
        + (f"; not timed, past the budget of {args.budget:g} s: {'; '.join(left)}." if left else "."),
        "",
    ]
    emit(page, args.out)
    if args.choice is not None:
        write_page(args.choice, [str(chosen)])
    return chosen


if __name__ == "__main__":
    main()
