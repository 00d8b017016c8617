"""Picture of a calibration, to check it by eye.

:func:`marker_overlay_png` draws the registered markers over each camera's
frame.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from rsocl.common import validation as check
from rsocl.files.atomic import atomic_path
from rsocl.hardware.calibration._common import _image, _points


def marker_overlay_png(
    path, frames, detected, reprojected=None, *, outlines=None, titles=None, cmap="gray", dpi=100
) -> Path:
    """Write a PNG of each camera's frame with its markers drawn over it.

    Detected markers are circles, numbered in marker order; markers
    reprojected from the reference grid through the fitted homography are
    crosses. Each panel has its own display range (1st to 99.9th
    percentile), since cameras differ in exposure.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ``.png`` (written atomically).
    frames : sequence of array_like
        One 2-D frame per camera (sizes may differ).
    detected : sequence of array_like, shape (N, 2)
        Detected ``(x, y)`` per camera.
    reprojected : sequence of array_like, shape (N, 2), optional
        Reprojected ``(x, y)`` per camera (None entries are skipped).
    outlines : sequence of array_like, shape (K, 2), optional
        A closed polygon per camera (None entries are skipped), drawn as a
        cyan line: e.g. the reference ROI's border mapped onto the frame
        (:func:`reference_outline`).
    titles : sequence of str, optional
        Panel titles; default ``"camera c"``.
    cmap : str
        Matplotlib colormap name.
    dpi : int
        Resolution, dots per inch (>= 10).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    frames = [_image(f"frames[{c}]", f) for c, f in enumerate(frames)]
    C = len(frames)
    if C == 0:
        raise ValueError("frames must hold at least one frame")
    if len(detected) != C:
        raise ValueError(f"detected must hold one point set per frame ({C}), got {len(detected)}")
    detected = [_points(f"detected[{c}]", d) for c, d in enumerate(detected)]
    if reprojected is None:
        reprojected = [None] * C
    if len(reprojected) != C:
        raise ValueError(f"reprojected must hold one point set per frame ({C}), got {len(reprojected)}")
    reprojected = [None if r is None else _points(f"reprojected[{c}]", r) for c, r in enumerate(reprojected)]
    if outlines is None:
        outlines = [None] * C
    if len(outlines) != C:
        raise ValueError(f"outlines must hold one polygon per frame ({C}), got {len(outlines)}")
    outlines = [None if o is None else _points(f"outlines[{c}]", o) for c, o in enumerate(outlines)]
    if titles is None:
        titles = [f"camera {c}" for c in range(C)]
    if isinstance(titles, str) or len(titles) != C:
        raise ValueError(f"titles must be a sequence of one str per frame ({C})")
    dpi = check.positive_int("dpi", dpi)
    if dpi < 10:
        raise ValueError(f"dpi must be >= 10, got {dpi}")

    ncols = min(C, 4)
    nrows = math.ceil(C / ncols)
    aspect = max(f.shape[0] / f.shape[1] for f in frames)
    panel = 3.0
    figure = Figure(figsize=(ncols * panel, nrows * panel * aspect + 0.6), layout="constrained")
    axes = figure.subplots(nrows, ncols, squeeze=False)
    for index, ax in enumerate(axes.ravel()):
        ax.set_xticks([])
        ax.set_yticks([])
        if index >= C:
            ax.set_axis_off()
            continue
        frame = frames[index]
        low, high = np.percentile(frame, [1.0, 99.9])
        if high <= low:
            high = low + 1.0
        ax.imshow(frame, cmap=cmap, vmin=low, vmax=high, interpolation="nearest")
        if outlines[index] is not None:
            closed = np.vstack([outlines[index], outlines[index][:1]])
            ax.plot(closed[:, 0], closed[:, 1], color="cyan", linewidth=1.0)
        points = detected[index]
        ax.scatter(points[:, 0], points[:, 1], s=90, facecolors="none", edgecolors="lime", linewidths=1.2)
        for k, (x, y) in enumerate(points):
            ax.annotate(str(k), (x, y), xytext=(6, 6), textcoords="offset points", color="yellow", fontsize=8)
        if reprojected[index] is not None:
            ax.scatter(reprojected[index][:, 0], reprojected[index][:, 1], s=50, marker="x", c="red", linewidths=1.2)
        ax.set_xlim(-0.5, frame.shape[1] - 0.5)
        ax.set_ylim(frame.shape[0] - 0.5, -0.5)
        ax.set_title(str(titles[index]), fontsize=9)
    handles = [
        Line2D([], [], marker="o", linestyle="", markerfacecolor="none", markeredgecolor="lime", label="detected"),
        Line2D([], [], marker="x", linestyle="", color="red", label="reprojected from reference"),
    ]
    if any(o is not None for o in outlines):
        handles.append(Line2D([], [], color="cyan", label="reference ROI"))
    try:
        figure.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8)
    except ValueError:  # matplotlib < 3.7 has no "outside" legend placement
        figure.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8)
    path = Path(os.fspath(path))
    FigureCanvasAgg(figure)
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png", dpi=dpi, facecolor="white")
    return path
