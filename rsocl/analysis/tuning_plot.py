"""The plot of a parameter search: the criterion of every candidate against its parameters.

Reads the record :func:`rsocl.solver.crossval.Tuning.as_params` writes (``Result.params["tuning"]``,
also in the reconstruction file), so it draws a search from a file as well as from a run.
"""

from __future__ import annotations

import os
import textwrap
from pathlib import Path

from rsocl.files.atomic import atomic_path

__all__ = ["tuning_plot", "search_summary"]


def search_summary(record) -> str:
    """One line on how the search held pixels out and ran: block side (pixels), hold-out folds,
    held-out pixels, ADMM iterations per candidate and per fold, candidates, the chosen blend with the
    interpolation and seconds (what the record has of them)."""
    parts = []
    block = record.get("block")
    if block:
        sides = [block] if isinstance(block, (int, float)) else list(block)
        parts.append(f"blocks of {' and '.join(str(b) for b in sides)} px")
    folds = int(record.get("folds", 1) or 1)
    parts.append(f"{folds} hold-out fold" + ("s" if folds > 1 else ""))
    if record.get("held_out_pixels"):
        parts.append(f"{record['held_out_pixels']} held-out pixels")
    if record.get("iterations_per_candidate"):
        per = " and fold" if folds > 1 else ""
        parts.append(f"{record['iterations_per_candidate']} iterations per candidate{per}")
    parts.append(f"{len(record.get('candidates', []))} candidates")
    if record.get("preset"):
        preset = ", ".join(f"{k} = {v:.3g}" for k, v in record["preset"].items())
        parts.append(f"{preset} set, not searched (one camera)")
    if record.get("blend") is not None:
        parts.append(f"blend with the interpolation {record['blend']:.2f}")
    if record.get("seconds"):
        parts.append(f"{record['seconds']:.2f} s")
    return ", ".join(parts)


def tuning_plot(path, record, *, dpi=100) -> Path:
    """Write a PNG of the cross-validation criterion against each searched parameter.

    Parameters
    ----------
    path : str or os.PathLike
        PNG to write (atomically).
    record : dict
        ``Result.params["tuning"]``: ``candidates`` (dicts with ``lam``, the tuned options and
        ``score``), ``chosen`` and ``fixed``; the title's second line is :func:`search_summary`.

    Returns
    -------
    pathlib.Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not isinstance(record, dict) or not record.get("candidates"):
        raise ValueError("record must be a tuning record with at least one candidate (Result.params['tuning'])")
    candidates = [c for c in record["candidates"] if c.get("score") is not None]
    chosen = record["chosen"]
    names = [k for k in chosen if len({c.get(k) for c in candidates}) > 1] or list(chosen)
    figure = Figure(figsize=(4.0 * len(names), 3.2))
    FigureCanvasAgg(figure)
    from matplotlib.ticker import NullFormatter

    best = min(candidates, key=lambda c: c["score"])
    for i, name in enumerate(names, 1):
        ax = figure.add_subplot(1, len(names), i)
        groups: dict = {}  # one line per setting of the other parameters
        for c in candidates:
            key = tuple((k, c[k]) for k in chosen if k != name and k in c)
            groups.setdefault(key, []).append((c[name], c["score"]))
        for j, (key, points) in enumerate(sorted(groups.items(), key=lambda item: -len(item[1]))):
            label = ", ".join(f"{k} = {v:.3g}" for k, v in key) or "candidates"
            ax.plot(*zip(*sorted(points)), "o-" if len(points) > 1 else "o", color=f"C{j % 10}", label=label)
        ax.plot(
            [best[name]], [best["score"]], "*", color="C3", markersize=14, label=f"chosen {name} = {best[name]:.3g}"
        )
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(name)
        ax.set_ylabel("held-out relative error")
        ax.legend(fontsize=7)
    fixed = ", ".join(f"{k} = {v:g}" for k, v in record.get("fixed", {}).items() if isinstance(v, (int, float)))
    width = int(figure.get_figwidth() * 17)  # characters of 8-point text per line
    figure.suptitle(
        textwrap.fill("cross-validation on held-out snapshot pixels" + (f" (fixed: {fixed})" if fixed else ""), width)
        + "\n"
        + textwrap.fill(search_summary(record), width),
        fontsize=8,
    )
    figure.tight_layout()
    path = Path(os.fspath(path))
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png", dpi=dpi, facecolor="white")
    return path
