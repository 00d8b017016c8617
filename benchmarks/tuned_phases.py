"""Where a self-tuned call's time goes beside a fixed run's, phase by phase.

``benchmarks/search_launches.py`` gives the self-tuned default's time over a fixed run's; this script says
where the difference lies. It runs both calls of that page (the default ``rsocl.reconstruct(g, rig)``, and
the fixed run with the values it chose, ``tune=False, x0="interp3d"``) on the paths a GPU takes, with the
queue finished before and after each phase, so a phase's time holds its device work:

- ``prepare``: the request checked, the snapshots staged, the operator made;
- ``search: folds``: the hold-out folds (their masks, starts and predictions);
- ``search: batch``: each batch of candidates of the search (its ADMM set up or restarted, its iterations,
  its two held-out sums read);
- ``search: rest``: the rest of the search (scores, the next round's candidates);
- ``interpolation``: the ``interp3d`` start;
- ``run: set-up``: the final run's ADMM made (inverse blocks included);
- ``run: iterations``: its iterations (the static fix not included), ``run: static fix``, ``run: collect``
  (the datacube read back);
- ``other``: the call's time outside those phases.

Each phase's time excludes the phases inside it. Beside each: its kernel launches, and the host's time in
``ADMM.step`` (enqueueing iterations) within it. Then a bound: the tuned call with its search's batches
taking only their host time in ``ADMM.step``, the least the search's launches allow however fast the device
ran them; and the calls' wall times without the phase boundaries' waits (median of ``--rounds`` rounds in
alternating order) and their ratio.

    python benchmarks/tuned_phases.py [--size 50] [--scenes builtin builtin-slow] [--rounds 5] [--device SPEC]
                                      [--out docs/tuned_phases.md]
"""

from __future__ import annotations

import argparse
import collections
import statistics
import sys
import time
from contextlib import contextmanager
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from launches import case, path  # noqa: E402
from provenance import DOCS, header_lines, write_page  # noqa: E402
from quality_scenes import available  # noqa: E402

import rsocl  # noqa: E402
from rsocl.device.context import get_device  # noqa: E402

#: (module, attribute, phase) of each function timed as a phase, in the page's order; ``search: rest`` is the
#: search's own time (``pipeline.tune`` less the folds and batches inside it).
PHASES = (
    ("rsocl.solver.reconstruct", "prepare", "prepare"),
    ("rsocl.solver.crossval", "make_fold", "search: folds"),
    ("rsocl.solver.search_batch", "BatchedFolds._run", "search: batch"),
    ("rsocl.solver.pipeline", "tune", "search: rest"),
    ("rsocl.solver.pipeline", "interpolation_start", "interpolation"),
    ("rsocl.solver.pipeline", "ADMM", "run: set-up"),
    ("rsocl.solver.pipeline", "run_iterations", "run: iterations"),
    ("rsocl.solver.pipeline", "static_fix", "run: static fix"),
    ("rsocl.solver.pipeline", "collect", "run: collect"),
)
ORDER = [label for *_, label in PHASES] + ["other"]


class Recorder:
    """Per phase: calls, seconds (exclusive of the phases inside), launches, host seconds in ``ADMM.step``."""

    def __init__(self, queue):
        self.queue, self.stack = queue, ["other"]
        self.seconds = collections.Counter()
        self.calls, self.launches, self.step_host = collections.Counter(), collections.Counter(), collections.Counter()
        self.inner = [0.0]

    def timed(self, label, fn):
        def wrapper(*args, **kwargs):
            self.queue.finish()
            self.stack.append(label)
            self.inner.append(0.0)
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.queue.finish()
                total = time.perf_counter() - start
                self.seconds[label] += total - self.inner.pop()
                self.inner[-1] += total
                self.calls[label] += 1
                self.stack.pop()

        return wrapper


@contextmanager
def recording(queue):
    """Patch :data:`PHASES`, ``ADMM.step`` and the kernel enqueue to record into a :class:`Recorder`. Kernel
    launches made by ``pyopencl.array`` arithmetic (through ``pyopencl._cl``) count too, as in
    ``launches.counting``."""
    import importlib

    import pyopencl as cl
    import pyopencl._cl as _cl

    from rsocl.solver.admm import ADMM

    rec, saved = Recorder(queue), []
    for module, attribute, label in PHASES:
        owner = importlib.import_module(module)
        *outer, name = attribute.split(".")
        for part in outer:
            owner = getattr(owner, part)
        saved.append((owner, name, getattr(owner, name)))
        setattr(owner, name, rec.timed(label, getattr(owner, name)))
    step, enqueue = ADMM.step, cl.enqueue_nd_range_kernel  # pyopencl's and _cl's: one function

    def timed_step(self, *args, **kwargs):
        start = time.perf_counter()
        try:
            return step(self, *args, **kwargs)
        finally:
            rec.step_host[rec.stack[-1]] += time.perf_counter() - start

    def counted(*args, **kwargs):
        rec.launches[rec.stack[-1]] += 1
        return enqueue(*args, **kwargs)

    ADMM.step, cl.enqueue_nd_range_kernel, _cl.enqueue_nd_range_kernel = timed_step, counted, counted
    start = time.perf_counter()
    try:
        yield rec
    finally:
        rec.seconds["other"] += time.perf_counter() - start - rec.inner[0]
        ADMM.step, cl.enqueue_nd_range_kernel, _cl.enqueue_nd_range_kernel = step, enqueue, enqueue
        for owner, name, value in reversed(saved):
            setattr(owner, name, value)


def measure(m: int, scene: str, device, rounds: int) -> dict:
    """Both calls at ``m``×``m`` of ``scene`` on the GPU path: their phases (the median of ``rounds`` recorded
    calls, phase by phase) and their wall times without the phases' waits."""
    rig, g = case(m, scene)
    with path("gpu"):
        tuned = rsocl.reconstruct(g, rig, device=device)  # builds
        chosen = tuned.params["tuning"]["chosen"]
        fixed_kw = dict(
            iterations=tuned.params["iterations"],
            tune=False,
            x0="interp3d",
            lam=chosen["lam"],
            regularizer_options={k: v for k, v in chosen.items() if k != "lam"},
            device=device,
        )
        calls = {
            "fixed": lambda: rsocl.reconstruct(g, rig, **fixed_kw),
            "tuned": lambda: rsocl.reconstruct(g, rig, device=device),
        }
        calls["fixed"]()
        out: dict = {key: {"recorded": [], "walls": []} for key in calls}
        for r in range(rounds):
            for key in list(calls)[r % 2 :] + list(calls)[: r % 2]:
                start = time.perf_counter()
                calls[key]()
                out[key]["walls"].append(time.perf_counter() - start)
                with recording(device.queue) as rec:
                    calls[key]()
                out[key]["recorded"].append(rec)
    out["ratios"] = [t / f for t, f in zip(out["tuned"]["walls"], out["fixed"]["walls"])]
    out.update(m=m, scene=scene, T=rig.T, chosen=chosen)
    return out


def _median(recs, field, label):
    return statistics.median(getattr(rec, field)[label] for rec in recs)


def rows(r) -> list:
    lines = []
    for label in ORDER:
        cells = []
        for key in ("fixed", "tuned"):
            recs = r[key]["recorded"]
            if not any(rec.calls[label] or rec.seconds[label] for rec in recs):
                cells.append("| – | – | – ")
                continue
            cells.append(
                f"| {1e3 * _median(recs, 'seconds', label):.2f} | {_median(recs, 'launches', label):.0f} | "
                f"{1e3 * _median(recs, 'step_host', label):.2f} "
            )
        calls = statistics.median(rec.calls[label] for rec in r["tuned"]["recorded"])
        lines.append(f"| {r['scene']} | {r['m']}×{r['m']} | {label} | {calls:.0f} " + "".join(cells) + "|")
    total = {
        key: statistics.median(sum(rec.seconds.values()) for rec in r[key]["recorded"]) for key in ("fixed", "tuned")
    }
    walls = {key: statistics.median(r[key]["walls"]) for key in ("fixed", "tuned")}
    lines.append(
        f"| {r['scene']} | {r['m']}×{r['m']} | **the call, phases waited for** | | "
        f"**{1e3 * total['fixed']:.2f}** | | | **{1e3 * total['tuned']:.2f}** | | |"
    )
    batch = {f: _median(r["tuned"]["recorded"], f, "search: batch") for f in ("seconds", "step_host")}
    bound = total["tuned"] - batch["seconds"] + batch["step_host"]
    lines.append(
        f"| {r['scene']} | {r['m']}×{r['m']} | **bound: the search's batches at their host time** | | | | | "
        f"**{1e3 * bound:.2f}** (×{bound / total['fixed']:.2f}) | | |"
    )
    ratios = r["ratios"]
    lines.append(
        f"| {r['scene']} | {r['m']}×{r['m']} | **the call, no waits** | | **{1e3 * walls['fixed']:.2f}** | | | "
        f"**{1e3 * walls['tuned']:.2f}** (×{statistics.median(ratios):.2f}, {min(ratios):.2f}-{max(ratios):.2f}) | | |"
    )
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=50, help="ROI side m (m × m), pixels")
    parser.add_argument("--scenes", nargs="+", default=["builtin", "builtin-slow"], help="scenes of quality_scenes.py")
    parser.add_argument("--rounds", type=int, default=5, help="rounds of the two calls, recorded and not (>= 1)")
    parser.add_argument("--device", default=None)
    parser.add_argument("--out", type=Path, default=DOCS / "tuned_phases.md", help="the Markdown page to write")
    args = parser.parse_args(argv)
    if args.size < 8 or args.rounds < 1:
        raise SystemExit("--size must be >= 8 and --rounds >= 1")
    missing = [name for name in args.scenes if not available(name)]
    if missing:
        raise SystemExit(f"--scenes: {missing} need their videos in ../shared/data; the built-in ones need none")
    device = get_device(args.device)
    page = header_lines("Where a self-tuned call's time goes", device, None if argv is None else [__file__, *argv])
    page += [
        "Paper array (4 cameras at 0/90/180/270°, t_e = 0.18 ms, t_r = 35 µs), float32, the default rung, on the "
        "paths a GPU takes. The self-tuned default (`tuned`) and the fixed run with the values it chose "
        "(`fixed`), each phase waited for before and after (`benchmarks/tuned_phases.py` names them): ms "
        "(exclusive of the phases inside), kernel launches, and ms of host time in `ADMM.step`, medians of "
        f"{args.rounds} recorded calls; then the calls without those waits (median of {args.rounds} rounds in "
        "alternating order; the tuned call's time over the fixed run's in the same round, median and range). "
        "The bound: the tuned call with its search's batches taking only the host's time enqueueing their "
        "iterations (in `step`), i.e. however fast the device ran them; beside it, its ratio to the fixed call, "
        "both with the phases waited for.",
        "",
        "| scene | ROI | phase | calls (tuned) | fixed ms | launches | in `step` ms | tuned ms | launches | "
        "in `step` ms |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for scene in args.scenes:
        r = measure(args.size, scene, device, args.rounds)
        page += rows(r)
        print("\n".join(page[-len(ORDER) - 3 :]), file=sys.stderr, flush=True)
        write_page(args.out, page)


if __name__ == "__main__":
    main()
