"""Pictures of captures and reconstructions: an animated GIF and PNG montages.

Everything renders off-screen with matplotlib's Agg canvas on explicit
:class:`matplotlib.figure.Figure` objects (never pyplot, so no global state
and no display is touched), and every file is written atomically through
:func:`rsocl.files.atomic.atomic_path`.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from rsocl.common import validation as check
from rsocl.files.atomic import atomic_path

__all__ = ["GIF_PANEL", "comparison_gif", "snapshot_montage", "datacube_montage", "channel_titles"]

#: Gray level (0..255) of the separators between GIF panels.
_SEPARATOR = 128
#: Height of a GIF text strip, pixels, and the font size used in it (1 pt = 1 px).
_STRIP = 14
_FONT = 10
_MIN_FONT = 6


# ---------------------------------------------------------------------- helpers
def _stack(name: str, array) -> np.ndarray:
    array = check.finite_array(name, array)
    if array.ndim == 2:
        array = array[None]
    if array.ndim != 3 or 0 in array.shape:
        raise ValueError(f"{name} must be a non-empty [T, m, n] stack (or one [m, n] image), got shape {array.shape}")
    return array


def _display_range(*arrays):
    """Common (low, high) of the arrays given (None entries skipped)."""
    present = [a for a in arrays if a is not None]
    low = min(float(a.min()) for a in present)
    high = max(float(a.max()) for a in present)
    return low, high


def _to_unit(array: np.ndarray, low: float, high: float) -> np.ndarray:
    if high <= low:
        return np.zeros(array.shape, dtype=np.float64)
    return np.clip((array.astype(np.float64) - low) / (high - low), 0.0, 1.0)


class _TextStrip:
    """Renders one line of white-on-black text into a ``(height, width)`` uint8 strip."""

    def __init__(self, width: int, height: int = _STRIP, fontsize: float = _FONT):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.shape = (height, width)
        self.figure = Figure(figsize=(width / 72.0, height / 72.0), dpi=72, facecolor="black")
        self.canvas = FigureCanvasAgg(self.figure)
        self.text = self.figure.text(
            0.5, 0.5, "", color="white", ha="center", va="center", fontsize=fontsize, family="DejaVu Sans"
        )

    def render(self, label: str) -> np.ndarray:
        self.text.set_text(label)
        self.canvas.draw()
        rgba = np.asarray(self.canvas.buffer_rgba())
        strip = rgba[..., :3].mean(axis=-1).round().astype(np.uint8)
        out = np.zeros(self.shape, dtype=np.uint8)  # guard against off-by-one canvas sizes
        h, w = min(self.shape[0], strip.shape[0]), min(self.shape[1], strip.shape[1])
        out[:h, :w] = strip[:h, :w]
        return out


def _fitting_font(width: int, label: str):
    """Font size (px) that fits ``label`` in ``width`` pixels, or None when too small to read."""
    size = min(_FONT, width / (0.62 * max(len(label), 1)))
    return size if size >= _MIN_FONT else None


def _save_figure(path, figure, dpi) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    path = Path(os.fspath(path))
    FigureCanvasAgg(figure)
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png", dpi=dpi, facecolor="white")
    return path


def channel_titles(rig) -> list:
    """Titles such as ``"camera 0 (0°)"`` for each channel of ``rig``.

    Multi-frame cameras add the frame (``"camera 1 (90°) frame 2"``); a camera
    defined by a row map says ``"row map"`` instead of an angle.
    """
    titles = []
    for c, k in rig.channels:
        camera = rig.cameras[c]
        where = "row map" if camera.row_map is not None else f"{camera.angle:g}°"
        titles.append(f"camera {c} ({where})" + (f" frame {k}" if camera.frames > 1 else ""))
    return titles


# ---------------------------------------------------------------------- GIF
#: Largest side of a GIF panel the automatic ``scale`` of :func:`comparison_gif` upscales to, pixels.
GIF_PANEL = 512


def comparison_gif(path, truth, estimate, *, fps=10, scale=None) -> Path:
    """Write an animated GIF: ground truth and reconstruction side by side.

    Both panels share one display range (the joint minimum and maximum of
    ``truth`` and ``estimate``, mapped to black and white), are upscaled by
    ``scale`` with nearest-neighbour so that small ROIs stay visible, and
    are labelled in a title strip ("ground truth", "reconstruction"); a strip
    below shows the sub-frame index. Labels are left out when the panels are
    too narrow to hold readable text. The GIF loops forever.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ``.gif`` (written atomically).
    truth : array_like, shape (T, m, n), or None
        Ground truth; ``None`` shows the reconstruction alone.
    estimate : array_like, shape (T, m, n)
        Reconstructed sub-frames, one GIF frame each.
    fps : float
        Playback rate, frames per second (> 0; GIF stores delays in 10 ms
        steps, so rates above 100 fps play at most at 100).
    scale : int or None
        Integer upscaling factor (>= 1, <= 64); None (default): 4, less for frames whose larger
        side passes ``GIF_PANEL / 4`` pixels, so that a panel's side stays within
        :data:`GIF_PANEL` (512) pixels (1 from 257 pixels up): memory about ``T`` times one frame
        of at most 512 x 1026 pixels (a 256 x 256 capture of 300 sub-frames takes 0.5 GB at 2, 2 GB at 4).

    Returns
    -------
    pathlib.Path
        ``path``.

    Notes
    -----
    GIF encoders merge consecutive identical frames into one longer frame, so
    a reader may count fewer frames than ``T`` when sub-frames repeat exactly;
    playback timing is unchanged.

    Raises
    ------
    ValueError
        If the arrays are not finite ``[T, m, n]`` stacks of equal shape, or
        ``fps`` or ``scale`` are out of range.
    """
    import imageio.v3 as iio

    estimate = _stack("estimate", estimate)
    if truth is not None:
        truth = _stack("truth", truth)
        if truth.shape != estimate.shape:
            raise ValueError(
                f"truth and estimate must have the same shape, got truth {truth.shape} and estimate {estimate.shape}"
            )
    fps = check.positive("fps", fps, "frames per second")
    T, m, n = estimate.shape
    scale = max(1, min(4, GIF_PANEL // max(m, n))) if scale is None else check.positive_int("scale", scale, maximum=64)
    low, high = _display_range(truth, estimate)

    height, width = m * scale, n * scale
    panels = (
        [("ground truth", truth), ("reconstruction", estimate)] if truth is not None else [("reconstruction", estimate)]
    )
    gap = max(1, scale // 2)
    total_width = len(panels) * width + (len(panels) - 1) * gap

    labels = [label for label, _ in panels]
    title_font = min((_fitting_font(width, label) or 0) for label in labels)
    titles = None
    if title_font:
        strip = _TextStrip(width, fontsize=title_font)
        titles = [strip.render(label) for label in labels]
    counter_label = f"sub-frame {T - 1} / {T - 1}"
    counter_font = _fitting_font(total_width, counter_label)
    counter = _TextStrip(total_width, fontsize=counter_font) if counter_font else None

    frames = []
    for s in range(T):
        row = []
        for i, (_, cube) in enumerate(panels):
            if i:
                row.append(np.full((height, gap), _SEPARATOR, dtype=np.uint8))
            image = np.rint(_to_unit(cube[s], low, high) * 255).astype(np.uint8)
            row.append(np.repeat(np.repeat(image, scale, axis=0), scale, axis=1))
        body = np.concatenate(row, axis=1)
        parts = []
        if titles is not None:
            head = []
            for i, title in enumerate(titles):
                if i:
                    head.append(np.full((title.shape[0], gap), _SEPARATOR, dtype=np.uint8))
                head.append(title)
            parts.append(np.concatenate(head, axis=1))
        parts.append(body)
        if counter is not None:
            parts.append(counter.render(f"sub-frame {s} / {T - 1}"))
        frames.append(np.concatenate(parts, axis=0))

    path = Path(os.fspath(path))
    duration = 1000.0 / fps
    # encoded in memory first: a write that fails (a full disk) then fails once, in the write below, and
    # not again when the encoder is collected with frames still buffered
    data = iio.imwrite("<bytes>", frames, extension=".gif", is_batch=True, duration=duration, loop=0)
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(data)
    return path


# ---------------------------------------------------------------------- PNG
def snapshot_montage(path, snapshots, *, titles=None, rig=None, cmap="gray", dpi=100) -> Path:
    """Write a PNG montage of the ``K`` snapshots with a shared colorbar.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ``.png`` (written atomically).
    snapshots : array_like, shape (K, m, n)
        The snapshots (one ``[m, n]`` image is accepted as ``K = 1``).
    titles : sequence of str, optional
        One title per snapshot. Defaults to :func:`channel_titles` of ``rig``
        when given (``"camera 0 (0°)"``, ...), else ``"snapshot k"``.
    rig : Rig, optional
        The rig that took the snapshots, for the default titles.
    cmap : str
        Matplotlib colormap name.
    dpi : int
        Resolution, dots per inch (>= 10).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        If ``snapshots`` is not a finite stack, or ``titles`` / ``rig`` do
        not have one entry per snapshot.
    """
    from matplotlib.figure import Figure

    snapshots = _stack("snapshots", snapshots)
    K = snapshots.shape[0]
    if titles is None:
        if rig is not None:
            titles = channel_titles(rig)
            if len(titles) != K:
                raise ValueError(f"rig has {len(titles)} channels but snapshots holds {K} images")
        else:
            titles = [f"snapshot {k}" for k in range(K)]
    if isinstance(titles, str):
        raise ValueError(f"titles must be a sequence of str (one per snapshot), got the string {titles!r}")
    titles = [str(t) for t in titles]
    if len(titles) != K:
        raise ValueError(f"titles must hold one title per snapshot ({K}), got {len(titles)}")
    dpi = check.positive_int("dpi", dpi)
    if dpi < 10:
        raise ValueError(f"dpi must be >= 10, got {dpi}")
    low, high = _display_range(snapshots)
    if high <= low:
        high = low + 1.0

    ncols = min(K, 4)
    nrows = math.ceil(K / ncols)
    m, n = snapshots.shape[1:]
    aspect = m / n
    panel = 2.4
    figure = Figure(figsize=(ncols * panel + 1.2, nrows * panel * aspect + 0.5), layout="constrained")
    axes = figure.subplots(nrows, ncols, squeeze=False)
    image = None
    for index, ax in enumerate(axes.ravel()):
        if index >= K:
            ax.set_axis_off()
            continue
        image = ax.imshow(snapshots[index], cmap=cmap, vmin=low, vmax=high, interpolation="nearest")
        ax.set_title(titles[index], fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    assert image is not None  # at least one panel (K >= 1, checked above) draws an image
    figure.colorbar(image, ax=axes.ravel().tolist(), shrink=0.85, label="intensity")
    return _save_figure(path, figure, dpi)


def datacube_montage(path, datacube, *, every=None, truth=None, max_columns=8, cmap="gray", dpi=100) -> Path:
    """Write a PNG grid of selected sub-frames, optionally with the truth above each row.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ``.png`` (written atomically).
    datacube : array_like, shape (T, m, n)
        Sub-frames to show (e.g. a reconstruction).
    every : int, optional
        Show sub-frames ``0, every, 2*every, ...`` (>= 1). Defaults to
        ``ceil(T / max_columns)``, one row of at most ``max_columns`` panels.
    truth : array_like, shape (T, m, n), optional
        Ground truth; its selected sub-frames form a row ("truth") above each
        row of ``datacube`` ("reconstruction").
    max_columns : int
        Panels per row (>= 1); longer selections wrap onto more rows.
    cmap : str
        Matplotlib colormap name.
    dpi : int
        Resolution, dots per inch (>= 10).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        If the arrays are not finite ``[T, m, n]`` stacks of equal shape, or
        ``every``, ``max_columns`` or ``dpi`` are out of range.
    """
    from matplotlib.figure import Figure

    datacube = _stack("datacube", datacube)
    T, m, n = datacube.shape
    if truth is not None:
        truth = _stack("truth", truth)
        if truth.shape != datacube.shape:
            raise ValueError(f"truth must have the datacube's shape {datacube.shape}, got {truth.shape}")
    max_columns = check.positive_int("max_columns", max_columns)
    every = math.ceil(T / max_columns) if every is None else check.positive_int("every", every)
    dpi = check.positive_int("dpi", dpi)
    if dpi < 10:
        raise ValueError(f"dpi must be >= 10, got {dpi}")
    selected = list(range(0, T, every))
    low, high = _display_range(truth, datacube)
    if high <= low:
        high = low + 1.0

    ncols = min(len(selected), max_columns)
    chunks = [selected[i : i + ncols] for i in range(0, len(selected), ncols)]
    cubes = [("truth", truth), ("reconstruction", datacube)] if truth is not None else [(None, datacube)]
    nrows = len(chunks) * len(cubes)
    panel = 1.6
    figure = Figure(figsize=(ncols * panel + 1.4, nrows * panel * m / n + 0.4), layout="constrained")
    axes = figure.subplots(nrows, ncols, squeeze=False)
    image = None
    for c, chunk in enumerate(chunks):
        for r, (label, cube) in enumerate(cubes):
            row = axes[c * len(cubes) + r]
            for j, ax in enumerate(row):
                ax.set_xticks([])
                ax.set_yticks([])
                if j >= len(chunk):
                    ax.set_axis_off()
                    continue
                image = ax.imshow(cube[chunk[j]], cmap=cmap, vmin=low, vmax=high, interpolation="nearest")
                if r == 0:
                    ax.set_title(f"s = {chunk[j]}", fontsize=9)
                if j == 0 and label is not None:
                    ax.set_ylabel(label, fontsize=9)
    assert image is not None  # at least one panel (K >= 1, checked above) draws an image
    figure.colorbar(image, ax=axes.ravel().tolist(), shrink=0.85, label="intensity")
    return _save_figure(path, figure, dpi)
