"""The files of ``rsocl bench``: ``bench.csv``, ``iterations.csv``, ``bench.md`` and the plots.

``bench.md`` holds the table, what coarser ``dt`` and a tighter ROI buy, and the picks
(:mod:`rsocl.bench.analysis`); the plots are drawn by :mod:`rsocl.bench.plots`.
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

import numpy as np

from rsocl.bench.analysis import (
    SPEED_PICK_DB,
    _comparable,
    _default_row,
    _reconstructions,
    _varied,
    pareto_front,
    picks,
)
from rsocl.bench.point import US, BenchResult, _scene_name, seconds_text
from rsocl.files.atomic import EARLIER, atomic_path, keeping

__all__ = ["COLUMNS", "HEADER", "write_csv", "write_iterations_csv", "tradeoff_lines", "markdown", "write_outputs"]

#: Columns of ``bench.csv``, in order.
COLUMNS = (
    "scene",
    "sweep",
    "label",
    "regularizer",
    "cameras",
    "shape",
    "roi",
    "dt_factor",
    "dt_us",
    "iterations",
    "tv_iterations",
    "dtype",
    "device",
    "lam",
    "eta",
    "T",
    "T_se",
    "subframes_evaluated",
    "psnr",
    "ssim_mean",
    "seconds",
    "seconds_per_iteration",
    "peak_device_memory_bytes",
    "psnr_full_roi",
    "ssim_per_subframe",
)
#: Units the header of ``bench.csv`` adds to the columns whose names do not say them (``psnr_db``);
#: the others are counts, ratios, text or named with their unit (``dt_us``, ``seconds``).
UNITS = {"shape": "px", "roi": "px", "psnr": "db", "psnr_full_roi": "db"}
#: The header of ``bench.csv``: :data:`COLUMNS` with :data:`UNITS`.
HEADER = tuple(f"{name}_{UNITS[name]}" if name in UNITS else name for name in COLUMNS)


def _fmt(value, digits=6):
    if value is None:
        return ""
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return f"{value:.{digits}g}"
    if isinstance(value, np.ndarray):
        return " ".join(f"{v:.4f}" for v in value)
    return str(value)


def write_csv(path, rows) -> Path:
    """``bench.csv``: one line per row, :data:`COLUMNS` under :data:`HEADER` (PSNR in dB, sides in pixels,
    ``dt_us`` in µs, times in seconds, memory in bytes; SSIM per sub-frame space-separated)."""
    path = Path(os.fspath(path))
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(HEADER)
    for row in rows:
        writer.writerow([_fmt(row.get(k)) for k in COLUMNS])
    with atomic_path(path) as tmp:
        tmp.write_text(buffer.getvalue(), encoding="utf-8")
    return path


def write_iterations_csv(path, history) -> Path:
    """``iterations.csv``: iteration, PSNR (dB), relative residual, seconds since the start."""
    path = Path(os.fspath(path))
    buffer = io.StringIO()
    buffer.write("iteration,psnr_db,residual,seconds\n")
    if history is not None:
        psnr_values = history.get("psnr", [math.nan] * len(history["residual"]))
        for i, (p, r, t) in enumerate(zip(psnr_values, history["residual"], history["time"]), start=1):
            buffer.write(f"{i},{_fmt(float(p))},{_fmt(float(r))},{_fmt(float(t))}\n")
    with atomic_path(path) as tmp:
        tmp.write_text(buffer.getvalue(), encoding="utf-8")
    return path


def _num(value, spec):
    if value is None:
        return "–"
    if isinstance(value, float) and math.isinf(value):
        return "∞"
    return format(value, spec)


def _ssim(value) -> str:
    """SSIM as text: ``n/a`` where it is undefined (frames under 3 pixels a side, the smallest window)."""
    return f"{value:.3f}" if value is not None and math.isfinite(value) else "n/a"


def _ratio(a, b):
    return a / b if b else math.nan


def tradeoff_lines(result: BenchResult):
    """Sentences on what coarser ``dt`` and a tighter ROI buy in time and cost in PSNR."""
    base = _default_row(result)
    lines = []
    if base is None:
        return ["(the default point did not run)"]
    if result.timing_check:  # the reference time: the mean of the default's two timings
        base = dict(base, seconds=sum(result.timing_check) / 2)
        lines.append(f"Times against the default point's mean of its two timings, {seconds_text(base['seconds'])} s.")
        lines.append("")
    for row in _varied(result, "dt_factor"):
        p = row["_point"]
        if p == result.default:
            continue
        lines.append(
            f"- **dt = {p.dt_factor:g}·t_r = {row['dt_us']:.0f} µs** (T {base['T']} → {row['T']}): "
            f"{seconds_text(row['seconds'])} s instead of {seconds_text(base['seconds'])} s "
            f"(×{_ratio(row['seconds'], base['seconds']):.2f}), "
            f"memory ×{_ratio(row['peak_device_memory_bytes'], base['peak_device_memory_bytes']):.2f}; "
            f"PSNR {_num(row['psnr'], '.2f')} dB vs {_num(base['psnr'], '.2f')} dB "
            f"({row['psnr'] - base['psnr']:+.2f} dB against the same dt = t_r ground truth), "
            f"SSIM {_ssim(row['ssim_mean'])} vs {_ssim(base['ssim_mean'])}."
        )
    for row in _varied(result, "roi"):
        p = row["_point"]
        if p == result.default:
            continue
        full = row["psnr_full_roi"]
        diff = "" if full is None else f" ({row['psnr'] - full:+.2f} dB)"
        lines.append(
            f"- **ROI {p.roi_size}×{p.roi_size}** (centred crop of {p.shape}×{p.shape}, "
            f"{row['subframes_evaluated']} sub-frames sampled instead of {base['subframes_evaluated']}): "
            f"{seconds_text(row['seconds'])} s instead of {seconds_text(base['seconds'])} s "
            f"(×{_ratio(row['seconds'], base['seconds']):.2f}), "
            f"memory ×{_ratio(row['peak_device_memory_bytes'], base['peak_device_memory_bytes']):.2f}; "
            f"PSNR in the crop {_num(row['psnr'], '.2f')} dB vs {_num(full, '.2f')} dB for the full-ROI "
            f"reconstruction over the same pixels and sub-frames{diff}."
        )
    return lines if any(line.startswith("- ") for line in lines) else ["(no dt or roi sweep in this run)"]


def _weights(point) -> str:
    """How the default point is run, self-tuned or fixed, and its ``lam`` and ``eta``, as the report states them."""
    if point.tune or point.quality is not None:
        rung = "" if point.quality is None else f", quality {point.quality}"
        eta = "" if point.eta is None else f", eta = {point.eta:g}"
        return (
            f"self-tuned as rsocl's default (lam chosen from each point's snapshots, started from interp3d{rung}){eta}"
        )
    said = [f"{name} = {value:g}" for name, value in (("lam", point.lam), ("eta", point.eta)) if value is not None]
    fixed = "fixed settings from zeros, as `rsocl reconstruct --fixed` (rsocl's default self-tunes: sweep `tune`)"
    if len(said) == 2:
        return ", ".join([fixed] + said)
    own = (
        "the fixed defaults for each point's rig (0.1 and 0.2 at the paper's configuration, scaled by the data "
        "term's curvature; the csv has each point's)"
    )
    left = " and ".join(name for name, value in (("lam", point.lam), ("eta", point.eta)) if value is None)
    return ", ".join([fixed] + said + [f"{left}: {own}"])


def markdown(result: BenchResult) -> str:
    """``bench.md``: the table, what coarser dt and a tighter ROI buy, and the picks."""
    d = result.default
    devices = {r["device"] for r in result.rows if not r["_point"].is_baseline}
    show_device = len(devices) > 1
    lines = [
        f"# rsocl bench: {_scene_name(d.scene)}",
        "",
        f"Paper array (angles 0, 90, 180, 270, 45, 135, 225, 315 in that order), t_e = {d.t_e / US:g} µs, "
        f"t_r = {d.t_r / US:g} µs, scene resized to {d.shape}×{d.shape} (benchmark protocol). "
        f"Default point: {d.cameras} cameras, dt = {d.dt_factor:g}·t_r, {d.regularizer} "
        f"({d.iterations} iterations, {d.tv_iterations} inner), {d.dtype}, {_weights(d)}. "
        f"Device: {result.device}; {os.cpu_count()} CPU cores; whole run {result.seconds:.0f} s.",
        "",
    ]
    if result.load and None not in result.load:
        timing = (
            f"Load average {result.load[0]:.1f} at the start and {result.load[1]:.1f} at the end of the run "
            f"on {os.cpu_count()} cores"
        )
        if result.timing_check:
            a, b = result.timing_check
            timing += (
                f"; the default point took {seconds_text(a)} s at the start and {seconds_text(b)} s when timed "
                "again at the end "
                f"({abs(b - a) / min(a, b) * 100:.0f}% apart): read time differences smaller than that as noise"
            )
        lines += [timing + ".", ""]
    lines += [
        "PSNR (dB, peak 1) and SSIM (mean over sub-frames) against the dt = t_r ground truth, over the "
        "sub-frames some camera samples; seconds: the whole `reconstruct` call as a user makes it (no "
        "ground truth on the device), compile excluded; "
        "ms/it: the ADMM loop alone; memory: the exact sum of the device buffers rsocl allocates "
        "(PoCL has no allocation counter). `interp3d`: per-pixel linear interpolation in time of the "
        "snapshots (no solver). T follows the capture (the 45° cameras, 5 to 8, read longer diagonals) "
        "and the scene is resampled to it by the protocol.",
        "",
    ]
    head = ["point", "regularizer", "cameras", "ROI (px)", "dt (µs)", "iterations", "inner", "dtype"]
    head += ["device"] if show_device else []
    head += ["T", "PSNR (dB)", "SSIM", "seconds", "ms/it", "memory (MiB)"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in result.rows:
        base = row["_point"].is_baseline
        cells = [
            row["label"],
            row["regularizer"],
            str(row["cameras"]),
            f"{row['roi']}",
            f"{row['dt_us']:.0f}",
            "–" if base else str(row["iterations"]),
            "–" if row["tv_iterations"] is None else str(row["tv_iterations"]),
            "–" if base else row["dtype"],
        ]
        cells += [row["device"]] if show_device else []
        spi = row["seconds_per_iteration"]
        cells += [
            str(row["T"]),
            _num(row["psnr"], ".2f"),
            _ssim(row["ssim_mean"]),
            seconds_text(row["seconds"]),
            "–" if spi is None else f"{spi * 1e3:.1f}",
            f"{row['peak_device_memory_bytes'] / 2**20:.2f}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    if any(_ssim(row["ssim_mean"]) == "n/a" for row in result.rows):
        lines += ["", "SSIM n/a: the ROI's frames are under 3 pixels a side, SSIM's smallest window."]
    lines += ["", "## What coarser dt and a tighter ROI buy", ""] + tradeoff_lines(result)
    speed, quality = picks(result)
    lines += ["", "## Which settings to pick", ""]
    if quality is None:
        lines.append("(no reconstruction of the default capture ran)")
    else:
        lines.append(
            f"- **pick for quality:** {quality['label']} — {_num(quality['psnr'], '.2f')} dB, "
            f"SSIM {_ssim(quality['ssim_mean'])}, {seconds_text(quality['seconds'])} s."
        )
        lines.append(
            f"- **pick for speed:** {speed['label']} — the fastest point of the Pareto front within "
            f"{SPEED_PICK_DB:g} dB of the best: {_num(speed['psnr'], '.2f')} dB, "
            f"SSIM {_ssim(speed['ssim_mean'])}, "
            f"{seconds_text(speed['seconds'])} s."
        )
        coarse = [r for r in (quality, speed) if r["_point"].dt_factor > 1]
        if coarse:
            k = coarse[0]["_point"].dt_factor
            lines.append(
                f"- a pick with dt = {k:g}·t_r delivers {1e-3 / (k * d.t_r):.1f} k sub-frames/s instead of "
                f"{1e-3 / d.t_r:.1f} k; its PSNR, against the dt = t_r ground truth, says this scene has "
                "little detail faster than that (a video with fewer frames than T is smooth in time)."
            )
        interp = [r for r in result.rows if r["_point"].is_baseline and _comparable(r, d)]
        if interp:
            b = interp[0]
            lines.append(
                f"- the baseline `interp3d` gives {_num(b['psnr'], '.2f')} dB "
                f"(SSIM {_ssim(b['ssim_mean'])}) in "
                f"{b['seconds'] * 1e3:.1f} ms: the reconstruction buys "
                f"{quality['psnr'] - b['psnr']:+.2f} dB at best, {speed['psnr'] - b['psnr']:+.2f} dB "
                "with the speed pick."
            )
        recs = _reconstructions(result)
        front = [recs[i] for i in pareto_front(recs)]
        lines.append(
            "- Pareto front of the reconstructions (PSNR against seconds, default capture), fastest first: "
            + ", ".join(f"{r['label']} ({_num(r['psnr'], '.1f')} dB, {seconds_text(r['seconds'])} s)" for r in front)
            + "."
        )
    if result.notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in result.notes]
    return "\n".join(lines) + "\n"


def _write_text(path: Path, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def write_outputs(result: BenchResult, out, kept: list | None = None) -> list:
    """Write ``bench.csv``, ``iterations.csv``, ``bench.md``, ``pareto.png``, ``cameras.png``, ``iterations.png``
    into the folder ``out``; returns their paths.

    The tables an earlier run left there keep a second name, ``<stem>.earlier-<UTC time><suffix>``
    (:func:`rsocl.files.atomic.keeping`), appended to ``kept`` where given; the pictures are drawn anew.
    """
    from rsocl.bench import plots as bench_plots

    out = Path(os.fspath(out))
    out.mkdir(parents=True, exist_ok=True)
    md = out / "bench.md"
    tables = (
        (out / "bench.csv", lambda path: write_csv(path, result.rows)),
        (out / "iterations.csv", lambda path: write_iterations_csv(path, result.history())),
        (md, lambda path: _write_text(path, markdown(result))),
    )
    files = []
    for path, write in tables:
        with keeping(path, EARLIER) as earlier:
            files.append(write(path))
        if kept is not None and earlier is not None:
            kept.append(earlier)
    d = result.default
    comparable = [r for r in result.rows if _comparable(r, d)]
    recs = _reconstructions(result)
    title = f"{_scene_name(d.scene)}, {d.shape}×{d.shape}"
    files.append(
        bench_plots.pareto_plot(
            out / "pareto.png", result.rows, comparable, [recs[i] for i in pareto_front(recs)], title=title
        )
    )
    files.append(
        bench_plots.cameras_plot(
            out / "cameras.png", _varied(result, "cameras"), _varied(result, "cameras", baseline=True), title=title
        )
    )
    baseline = [r for r in comparable if r["_point"].is_baseline]
    files.append(
        bench_plots.iterations_plot(
            out / "iterations.png",
            result.history(),
            _varied(result, "iterations"),
            baseline[0]["psnr"] if baseline else None,
            title=title,
        )
    )
    return files
