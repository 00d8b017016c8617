"""Analysis of a ``rsocl bench`` run: the Pareto front (PSNR against seconds) and the picks."""

from __future__ import annotations

import math
from dataclasses import replace

from rsocl.bench.point import BASELINE, BenchPoint, BenchResult

__all__ = ["SPEED_PICK_DB", "pareto_front", "picks"]

#: Drop from the best PSNR accepted by the "pick for speed" line, dB.
SPEED_PICK_DB = 1.0


def _finite(value) -> bool:
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def pareto_front(rows, x="seconds", y="psnr"):
    """Indices of the rows no other row beats: less or equal ``x`` and more or equal ``y``, one strictly.

    Rows whose ``x`` or ``y`` is missing or NaN are ignored. Returned in increasing ``x``.
    """
    candidates = [i for i, r in enumerate(rows) if _finite(r.get(x)) and _finite(r.get(y))]
    candidates.sort(key=lambda i: (float(rows[i][x]), -float(rows[i][y])))
    front, best = [], -math.inf
    for i in candidates:
        if float(rows[i][y]) > best:
            front.append(i)
            best = float(rows[i][y])
    return front


def _comparable(row, default: BenchPoint) -> bool:
    """Rows of the same capture as the default (same cameras and ROI): the user's choices."""
    point = row["_point"] if "_point" in row else None
    if point is not None:
        return point.cameras == default.cameras and point.roi_size == default.roi_size and point.shape == default.shape
    return int(row["cameras"]) == default.cameras and int(row["roi"]) == default.roi_size


def _default_row(result: BenchResult):
    for row in result.rows:
        if row["_point"] == result.default:
            return row
    return None


def _varied(result: BenchResult, knob: str, *, baseline=False):
    """Rows that differ from the default (or its baseline) in ``knob`` only, sorted by that knob."""
    default = result.default
    if baseline:
        default = replace(
            default, regularizer=BASELINE, iterations=0, tv_iterations=None, dtype="float64", dt_factor=1.0
        )
    out = []
    for row in result.rows:
        point = row["_point"]
        if replace(point, **{knob: getattr(default, knob)}) == default:
            out.append(row)
    key = (lambda r: r["_point"].roi_size) if knob == "roi" else (lambda r: getattr(r["_point"], knob))
    return sorted(out, key=key)


def _reconstructions(result: BenchResult):
    """Reconstruction rows (no baseline) of the default's capture: what a user chooses between."""
    return [r for r in result.rows if not r["_point"].is_baseline and _comparable(r, result.default)]


def picks(result: BenchResult):
    """``(speed row, quality row)`` among the reconstructions of the default's capture (None when empty).

    Quality: the highest PSNR. Speed: the fastest point of the Pareto front (PSNR against
    seconds) within :data:`SPEED_PICK_DB` of that PSNR.
    """
    rows = _reconstructions(result)
    if not rows:
        return None, None
    front = [rows[i] for i in pareto_front(rows)]
    quality = max(rows, key=lambda r: r["psnr"])
    speed = next((r for r in front if r["psnr"] >= quality["psnr"] - SPEED_PICK_DB), quality)
    return speed, quality
