"""The plots of ``rsocl bench``: Pareto front, cameras (the paper's Fig. 8), PSNR per iteration.

Off-screen matplotlib (explicit :class:`~matplotlib.figure.Figure` on the Agg canvas, never
pyplot), small PNGs, written atomically through :func:`rsocl.files.atomic.atomic_path`.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from rsocl.bench.point import seconds_text
from rsocl.files.atomic import atomic_path

__all__ = ["pareto_plot", "cameras_plot", "iterations_plot"]

SIZE = (6.0, 3.8)
DPI = 90
#: Marker colour per sweep (the first sweep label of a row).
COLOURS = {
    "default": "black",
    "baseline": "tab:red",
    "cameras": "tab:blue",
    "iterations": "tab:orange",
    "tv_iterations": "tab:green",
    "regularizer": "tab:purple",
    "dtype": "tab:brown",
    "dt": "tab:pink",
    "roi": "tab:olive",
    "device": "tab:cyan",
    "tune": "tab:gray",
    "quality": "darkgoldenrod",
}


def _figure(size=SIZE):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=size, dpi=DPI)
    FigureCanvasAgg(figure)
    return figure


def _save(figure, path) -> Path:
    path = Path(os.fspath(path))
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png", dpi=DPI, facecolor="white")
    return path


def _empty(path, text, title) -> Path:
    figure = _figure()
    ax = figure.add_subplot()
    ax.set_axis_off()
    ax.text(0.5, 0.5, text, ha="center", va="center", fontsize=10)
    ax.set_title(title, fontsize=10)
    return _save(figure, path)


def _psnr(value):
    """PSNR for plotting: inf (exact) drawn at 99 dB."""
    return 99.0 if math.isinf(value) else value


def pareto_plot(path, rows, comparable, front, *, title="") -> Path:
    """PSNR against seconds (log) of every row; the Pareto front (the rows ``front``) joined and labelled.

    ``comparable`` are the rows of the default's capture (its cameras and ROI); the others
    are drawn hollow: they are not a choice for the same cameras and scene region. Baseline
    rows are crosses, labelled.
    """
    rows = [r for r in rows if r.get("seconds") is not None and r.get("psnr") is not None]
    if not rows:
        return _empty(path, "no measured points", title)
    figure = _figure((7.2, 3.8))
    ax = figure.add_subplot()
    same = {id(r) for r in comparable}
    seen = set()
    for row in rows:
        sweep = row.get("sweep", "").split("|")[0] or "default"
        colour = COLOURS.get(sweep, "gray")
        hollow = id(row) not in same
        label = None if (sweep, hollow) in seen else sweep + (" (other capture)" if hollow else "")
        seen.add((sweep, hollow))
        x, y = max(row["seconds"], 1e-5), _psnr(row["psnr"])
        if sweep == "baseline":
            ax.scatter(
                [x],
                [y],
                s=30 if not hollow else 18,
                marker="x" if not hollow else "+",
                color=colour,
                label=label,
                zorder=3,
            )
            if not hollow:
                ax.annotate(
                    row.get("label", ""), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7, color=colour
                )
        else:
            ax.scatter(
                [x],
                [y],
                s=26,
                marker="o",
                facecolors="none" if hollow else colour,
                edgecolors=colour,
                label=label,
                zorder=3,
            )
    if front:
        xs = [max(r["seconds"], 1e-5) for r in front]
        ys = [_psnr(r["psnr"]) for r in front]
        ax.step(xs, ys, where="post", color="black", lw=1, alpha=0.6, zorder=2, label="Pareto front")
        for r, x, y in zip(front, xs, ys):
            ax.annotate(r.get("label", ""), (x, y), textcoords="offset points", xytext=(4, -9), fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("seconds (whole reconstruction, log scale)")
    ax.set_ylabel("PSNR (dB)")
    ax.set_title(f"Quality against time: {title}", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    return _save(figure, path)


def cameras_plot(path, rows, baseline_rows, *, title="") -> Path:
    """PSNR and SSIM against the number of cameras (two panels), reconstruction and ``interp3d``."""
    if not rows and not baseline_rows:
        return _empty(path, "no cameras sweep in this run", title)
    figure = _figure((7.0, 3.2))
    left, right = figure.add_subplot(1, 2, 1), figure.add_subplot(1, 2, 2)
    for data, name, style in ((rows, None, "o-"), (baseline_rows, "interp3d", "x--")):
        if not data:
            continue
        label = name or data[0].get("regularizer", "reconstruction")
        cams = [r["cameras"] for r in data]
        left.plot(cams, [_psnr(r["psnr"]) for r in data], style, label=label)
        right.plot(cams, [r["ssim_mean"] for r in data], style, label=label)
    for ax, what in ((left, "PSNR (dB)"), (right, "SSIM")):
        ax.set_xlabel("cameras (paper's angle order)")
        ax.set_ylabel(what)
        ax.grid(True, alpha=0.3)
        ax.set_xticks(range(1, 9))
        ax.legend(fontsize=7)
    left.set_title(f"{title}", fontsize=9)
    right.set_title("mean over sub-frames", fontsize=9)
    return _save(figure, path)


def iterations_plot(path, history, rows, baseline_psnr=None, *, title="") -> Path:
    """PSNR after each ADMM iteration (the history of the longest default run); sweep points as markers."""
    if history is None or "psnr" not in history or len(history["psnr"]) == 0:
        return _empty(path, "no iterations history in this run", title)
    figure = _figure()
    ax = figure.add_subplot()
    psnr = [_psnr(float(v)) for v in history["psnr"]]
    ax.plot(range(1, len(psnr) + 1), psnr, lw=1.2, label="PSNR per iteration (longest run)")
    if rows:
        ax.plot([r["iterations"] for r in rows], [_psnr(r["psnr"]) for r in rows], "o", ms=4, label="measured runs")
        for r in rows:
            ax.annotate(
                f"{seconds_text(r['seconds'])} s",
                (r["iterations"], _psnr(r["psnr"])),
                textcoords="offset points",
                xytext=(3, -10),
                fontsize=7,
            )
    if baseline_psnr is not None:
        ax.axhline(_psnr(baseline_psnr), color="tab:red", ls="--", lw=1, label="interp3d baseline")
    ax.set_xlabel("ADMM iteration")
    ax.set_ylabel("PSNR (dB)")
    ax.set_title(f"Convergence: {title}", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    return _save(figure, path)
