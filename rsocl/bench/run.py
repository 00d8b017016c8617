"""``rsocl bench``: what each setting buys in quality (PSNR, SSIM) and costs in time and memory.

A *point* (:class:`BenchPoint`) fixes every knob: scene, number of cameras (the paper's angle
order), ROI, sub-frame duration ``dt``, ADMM and inner denoiser iterations, regularizer, dtype
and device. :func:`run_point` simulates the capture, reconstructs it and measures it; a sweep
varies one knob at a time around a default point; :func:`write_outputs` writes ``bench.csv``,
``iterations.csv``, ``bench.md`` and three PNG plots (:mod:`rsocl.bench.plots`).

The pieces, one module each (all re-exported here):

* :mod:`rsocl.bench.point`: :class:`BenchPoint`, the knobs of one measurement;
* :mod:`rsocl.bench.measure`: :func:`run_point`, how a point is measured;
* :mod:`rsocl.model.interpolation`: :func:`interp3d`, the baseline that needs no solver;
* :mod:`rsocl.bench.memory`: :func:`device_memory_bytes`, the device memory of a run;
* :mod:`rsocl.bench.analysis`: :func:`pareto_front` and :func:`picks`;
* :mod:`rsocl.bench.report`: ``bench.csv``, ``iterations.csv``, ``bench.md``, and the plots of
  :mod:`rsocl.bench.plots`;
* this module: the sweeps (:func:`build_points`, :func:`run_bench`).

The command line, ``rsocl bench``, is :mod:`rsocl.cli.bench`.
"""

from __future__ import annotations

import os
import time
from dataclasses import replace

from rsocl.bench.analysis import SPEED_PICK_DB, pareto_front, picks  # noqa: F401
from rsocl.bench.measure import _device_of, run_point
from rsocl.bench.memory import device_memory_bytes
from rsocl.bench.point import BASELINE, BenchPoint, BenchResult, on_iterations_line
from rsocl.bench.report import (  # noqa: F401
    COLUMNS,
    HEADER,
    markdown,
    tradeoff_lines,
    write_csv,
    write_iterations_csv,
    write_outputs,
)
from rsocl.model.interpolation import interp3d

__all__ = [
    "BenchPoint",
    "BenchResult",
    "SWEEPS",
    "BASELINE",
    "run_point",
    "interp3d",
    "device_memory_bytes",
    "sweep_point",
    "build_points",
    "parse_sweep",
    "run_bench",
    "canonical_device",
    "pareto_front",
    "picks",
    "markdown",
    "write_csv",
    "write_outputs",
]


# ---------------------------------------------------------------------- sweeps
#: Sweep name -> the :class:`BenchPoint` field it varies.
SWEEPS = {
    "cameras": "cameras",
    "iterations": "iterations",
    "tv_iterations": "tv_iterations",
    "regularizer": "regularizer",
    "dtype": "dtype",
    "dt": "dt_factor",
    "roi": "roi",
    "device": "device",
    "tune": "tune",
    "quality": "quality",
}
#: Sweep values of the full run; iterations and roi as fractions of the default point's.
FULL: dict[str, list] = {
    "cameras": [1, 2, 3, 4, 5, 6, 7, 8],
    "iterations": [0.125, 0.25, 0.5, 1.0, 1.5],
    "tv_iterations": [2, 5, 10, 20],
    "dt": [1, 2, 3, 4],
    "roi": [0.5, 0.75, 1.0],
}
#: The ``--quick`` run: fewer values, the sweeps that show the trade.
QUICK: dict[str, list] = {
    "cameras": [1, 2, 4, 8],
    "iterations": [0.1, 0.25, 0.5, 1.0],
    "tv_iterations": [2, 5, 10],
    "dt": [1, 2, 4],
    "roi": [0.5, 0.75, 1.0],
    "regularizer": ["tv", "dct", "wavelet"],
    "tune": [False, True],
}


def canonical_device(spec):
    """``"P:D"`` of the device ``spec`` selects (so one device is one point whatever its spelling)."""
    from rsocl.device.context import list_devices

    dev = _device_of(spec).device
    for pi, di, _, d in list_devices():
        if d == dev:
            return f"{pi}:{di}"
    return spec


def _default_values(name, default: BenchPoint, quick: bool, notes: list):
    from rsocl.common.registry import available
    from rsocl.device.context import list_devices

    table = QUICK if quick else FULL
    if name in table:
        values = table[name]
        if name == "iterations":
            return sorted({max(1, round(f * default.iterations)) for f in values})
        if name == "roi":
            return sorted({max(4, round(f * default.shape)) for f in values})
        return list(values)
    if name == "regularizer":
        return list(available("rsocl.regularizers"))
    if name == "dtype":
        if _device_of(default.device).has_fp64:
            return ["float32", "float64"]
        notes.append(f"dtype: device {_device_of(default.device).name} has no fp64; float32 only")
        return ["float32"]
    if name == "device":
        return [f"{pi}:{di}" for pi, di, _, _ in list_devices()]
    if name == "tv_iterations":
        return list(FULL["tv_iterations"])
    if name == "tune":
        return [False, True]
    if name == "quality":
        from rsocl.solver.ladder import QUALITIES

        return list(QUALITIES)
    raise ValueError(f"unknown sweep {name!r}; known: {sorted(SWEEPS)}")


def parse_sweep(text: str):
    """``"NAME"`` or ``"NAME=v1,v2,..."`` -> (name, values or None)."""
    name, _, values = str(text).partition("=")
    name = name.strip().replace("-", "_")
    if name not in SWEEPS:
        raise ValueError(f"--sweep must be one of {sorted(SWEEPS)} (optionally NAME=v1,v2,...), got {text!r}")
    if not values.strip():
        return name, None
    if name == "tune":
        flags = {"0": False, "false": False, "no": False, "1": True, "true": True, "yes": True}
        words = [v.strip().lower() for v in values.split(",") if v.strip()]
        if any(v not in flags for v in words):
            raise ValueError(f"--sweep tune: values must be true/false (or 1/0), got {words!r}")
        return name, [flags[v] for v in words]
    kind = {"cameras": int, "iterations": int, "tv_iterations": int, "roi": int, "dt": float}.get(name, str)
    try:
        return name, [kind(v.strip()) for v in values.split(",") if v.strip()]
    except ValueError:
        raise ValueError(
            f"--sweep {name}: values must be {kind.__name__}s separated by commas, got {values!r}"
        ) from None


def _regularizer_point(default: BenchPoint, name: str):
    """The default point with regularizer ``name`` (inner iterations only where it has them)."""
    from rsocl.common.registry import load

    cls = load("rsocl.regularizers", name)
    iterative = "iterations" in getattr(cls, "options", {})
    return replace(default, regularizer=name, tv_iterations=default.tv_iterations if iterative else None)


def sweep_point(default: BenchPoint, name: str, value) -> BenchPoint:
    """The point of sweep ``name`` (a key of :data:`SWEEPS`) at ``value`` around ``default``.

    Raises
    ------
    Exception
        What the knob's check raises: a ValueError for an out-of-range value (``roi`` above
        ``shape``, ``dt`` below 1, ``cameras`` above 8, ...), the registry's error for an unknown
        or broken regularizer, the device lookup's for an unknown device.
    """
    knob = SWEEPS[name]
    if knob == "regularizer":
        return _regularizer_point(default, value)
    if knob == "device":
        return replace(default, device=canonical_device(value))
    return replace(default, **{knob: value})


def build_points(default: BenchPoint, sweeps=None, *, quick=False, baseline=True):
    """Points of the requested sweeps around ``default``, deduplicated, default first.

    Parameters
    ----------
    sweeps : iterable of str or (name, values) or None
        Sweep names (``"cameras"``) or ``"NAME=v1,v2"`` strings or ``(name, values)`` pairs;
        None: every sweep (``--quick``: the quick set).
    baseline : bool
        Add an ``interp3d`` point for every capture (cameras, ROI) of the run.

    Returns
    -------
    points : list of (BenchPoint, sweep labels)
    notes : list of str
        Values left out (a broken regularizer, a ROI larger than the grid, no fp64, ...).
    """
    notes: list[str] = []
    if sweeps is None:
        sweeps = list(QUICK) if quick else list(SWEEPS)
    requested = []
    for item in sweeps:
        name, values = parse_sweep(item) if isinstance(item, str) else (item[0], item[1])
        requested.append((name, values if values is not None else _default_values(name, default, quick, notes)))
    order, labels = [default], {default: ["default"]}

    def add(point, label):
        if point not in labels:
            order.append(point)
            labels[point] = []
        if label not in labels[point]:
            labels[point].append(label)

    for name, values in requested:
        for value in values:
            try:
                point = sweep_point(default, name, value)
            except Exception as exc:  # a broken plugin, an out-of-range value
                notes.append(f"{name}={value}: skipped ({type(exc).__name__}: {exc})")
                continue
            add(point, name)
    if baseline:
        for point in list(order):
            base = replace(
                default,
                cameras=point.cameras,
                roi=point.roi,
                regularizer=BASELINE,
                iterations=0,
                tv_iterations=None,
                dtype="float64",
                dt_factor=1.0,
                device=default.device,
            )
            add(base, "baseline")
    order.sort(key=lambda p: p.roi is not None)  # full-ROI runs first: the crops compare with them
    return [(p, labels[p]) for p in order], notes


def _label(point: BenchPoint, default: BenchPoint) -> str:
    parts = [] if not point.is_baseline else [BASELINE]
    if point.cameras != default.cameras:
        parts.append(f"C={point.cameras}")
    if point.roi_size != default.roi_size:
        parts.append(f"ROI {point.roi_size}")
    if point.is_baseline:
        return " ".join(parts)
    if point.regularizer != default.regularizer:
        parts.append(point.regularizer)
    if point.iterations != default.iterations:
        parts.append(f"it={point.iterations}")
    if point.tv_iterations != default.tv_iterations and point.regularizer == default.regularizer:
        parts.append(f"inner={point.tv_iterations}")
    if point.dtype != default.dtype:
        parts.append(point.dtype)
    if point.dt_factor != default.dt_factor:
        parts.append(f"dt={point.dt_factor:g}t_r")
    if point.device != default.device:
        parts.append(f"dev {point.device}")
    if point.tune != default.tune:
        parts.append("self-tuned" if point.tune else "fixed")
    if point.quality != default.quality:
        parts.append(f"quality {point.quality}")
    return " ".join(parts) or "default"


def run_bench(
    default: BenchPoint,
    sweeps=None,
    *,
    quick=False,
    baseline=True,
    progress=True,
    cache=None,
    repeat_default=True,
    keep_on_interrupt=False,
) -> BenchResult:
    """Build the points (:func:`build_points`) and measure each (:func:`run_point`).

    With ``repeat_default`` the default point is timed once more at the end
    (:attr:`BenchResult.timing_check`), which shows how much the times drift with the
    machine's other load.

    A point that fails (a broken plugin, a dtype the regularizer lacks, a problem too large
    for the device) is left out with a note; the others are measured.

    An interrupt (Ctrl-C's KeyboardInterrupt, or its subclass for SIGTERM) propagates; with
    ``keep_on_interrupt`` it ends the run instead, and the result holds the rows measured before
    it, a note saying how many of the points were measured, and the exception
    (:attr:`BenchResult.interrupted`).
    """
    from tqdm.auto import tqdm

    start = time.perf_counter()
    load_start = _load()
    default = replace(default, device=canonical_device(default.device))
    points, notes = build_points(default, sweeps, quick=quick, baseline=baseline)
    cache = {} if cache is None else cache
    rows: list = []
    interrupted, timing_check, measuring = None, None, True
    bar = tqdm(points, desc="rsocl bench", unit="point", disable=None if progress else True, leave=False)
    try:
        for point, labels in bar:
            bar.set_postfix_str(_label(point, default))
            try:
                row = run_point(point, cache, with_history=on_iterations_line(point, default))
            except (KeyboardInterrupt, MemoryError):
                raise
            except Exception as exc:
                notes.append(f"{_label(point, default)}: failed ({type(exc).__name__}: {exc})")
                continue
            row["sweep"] = "|".join(labels)
            row["label"] = _label(point, default)
            rows.append(row)
        measuring = False
        first = next((r for r in rows if r["_point"] == default), None)
        if repeat_default and first is not None and len(rows) > 1:
            timing_check = (first["seconds"], run_point(default, cache)["seconds"])
    except KeyboardInterrupt as exc:
        if not keep_on_interrupt:
            raise
        interrupted = exc
        if measuring:
            notes.append(f"interrupted: {len(rows)} of the {len(points)} points measured, the others not")
        else:
            notes.append("interrupted while the default point was timed again: no second timing")
    finally:
        bar.close()
    device = _device_of(default.device).name
    return BenchResult(
        rows, default, notes, time.perf_counter() - start, device, timing_check, (load_start, _load()), interrupted
    )


def _load():
    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return None
