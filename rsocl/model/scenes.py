"""Scenes (ground-truth datacubes ``[T, m, n]`` in [0, 1]) for simulation and benchmarks.

- :func:`builtin_scene`: a synthetic high-speed scene that needs no data file.
- :func:`benchmark_protocol`: turn any video into a datacube (docs/model.md's protocol).
- :func:`load_scene`: either of the two from one specification string.

Video files are read by :func:`rsocl.model.video.load_video` (also importable from here).
"""

from __future__ import annotations

import math
import numbers
import os

import numpy as np

from rsocl.common import validation as check
from rsocl.common.hints import ArrayLike, DTypeLike, PathLike
from rsocl.model.video import VIDEO_SUFFIXES, load_video

__all__ = ["builtin_scene", "load_video", "benchmark_protocol", "load_scene", "VIDEO_SUFFIXES"]


# ---------------------------------------------------------------------- helpers
def _shape(shape) -> tuple:
    try:
        m, n = shape
    except (TypeError, ValueError):
        raise ValueError(f"shape must be (m, n): rows and columns, pixels; got {shape!r}") from None
    return (check.positive_int("shape[0] (rows m)", m), check.positive_int("shape[1] (columns n)", n))


def _coverage(signed_distance: np.ndarray) -> np.ndarray:
    """Fraction of a pixel inside a shape, from the signed distance (pixels, < 0 inside): a linear
    ramp one pixel wide centred on the edge, exact for a straight edge aligned with the pixel grid."""
    return np.clip(0.5 - signed_distance, 0.0, 1.0)


def _background(shape, rng) -> np.ndarray:
    """scikit-image's ``camera`` image (bundled in the wheel), cropped to the aspect of ``shape``."""
    from skimage import data
    from skimage.transform import resize

    image = data.camera().astype(np.float64) / 255.0
    m, n = shape
    rows, cols = image.shape
    if m * cols >= n * rows:  # target is taller: full height, crop columns
        width = max(1, int(round(rows * n / m)))
        start = int(rng.integers(0, cols - width + 1))
        image = image[:, start : start + width]
    else:  # target is wider: full width, crop rows
        height = max(1, int(round(cols * m / n)))
        start = int(rng.integers(0, rows - height + 1))
        image = image[start : start + height, :]
    return resize(image, shape, order=1, anti_aliasing=True, mode="reflect")


def builtin_scene(
    shape: tuple[int, int] = (64, 64), T: int = 55, *, dtype: DTypeLike = np.float32, seed: int = 0
) -> np.ndarray:
    """A synthetic high-speed scene: a bright disc crossing the frame and a rotating bar.

    The background is scikit-image's ``camera`` photograph (shipped inside the scikit-image wheel,
    no download), dimmed to [0.05, 0.55]. Over the ``T`` sub-frames a bright disc (value 1.0, radius
    12% of the smaller side) crosses the frame from left to right on a slightly tilted path, about
    ``(n + radius) / T`` pixels per sub-frame, and a bar (value 0.8, length 44% of the smaller side)
    turns half a revolution about a fixed centre. Edges are antialiased (coverage from the exact
    signed distance, one pixel wide ramp). Sub-frame ``s`` is rendered at time ``(s + 0.5) / T`` of
    the sequence.

    Parameters
    ----------
    shape : (int, int)
        ``(m, n)``: rows and columns, pixels (>= 1 each).
    T : int
        Number of sub-frames (>= 1).
    dtype : floating dtype
        Output dtype, e.g. ``np.float32`` (default) or ``np.float64``.
    seed : int
        Seed (>= 0) of the path, the bar's centre, phase and direction and
        the background crop. The same seed always gives the same scene.

    Returns
    -------
    ndarray, shape (T, m, n)
        Intensities in [0, 1].

    Raises
    ------
    ValueError
        If ``shape``, ``T``, ``dtype`` or ``seed`` are out of range.

    Examples
    --------
    >>> import rsocl
    >>> truth = rsocl.builtin_scene((32, 48), 40)
    >>> truth.shape, truth.dtype.name, float(truth.max())
    ((40, 32, 48), 'float32', 1.0)
    """
    m, n = _shape(shape)
    T = check.positive_int("T (sub-frames)", T)
    try:
        dtype = np.dtype(dtype)
    except TypeError:
        raise ValueError(f"dtype must be a floating NumPy dtype, got {dtype!r}") from None
    if dtype.kind != "f":
        raise ValueError(f"dtype must be a floating NumPy dtype (float32, float64), got {dtype}")
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    rng = np.random.default_rng(int(seed))

    background = 0.05 + 0.5 * _background((m, n), rng)
    size = min(m, n)
    yy = np.arange(m, dtype=np.float64)[:, None]
    xx = np.arange(n, dtype=np.float64)[None, :]

    # Disc: enters at the left edge, leaves at the right edge, slightly tilted path.
    radius = max(1.0, 0.12 * size)
    disc_y0 = rng.uniform(0.2, 0.4) * (m - 1)
    disc_y1 = rng.uniform(0.3, 0.5) * (m - 1)
    disc_x0, disc_x1 = -0.5 * radius, (n - 1) + 0.5 * radius
    # Bar: rotates half a turn about a centre in the lower half.
    half_length = max(1.0, 0.22 * size)
    half_width = max(0.75, 0.045 * size)
    bar_cy = rng.uniform(0.62, 0.72) * (m - 1)
    bar_cx = rng.uniform(0.35, 0.65) * (n - 1)
    phase = rng.uniform(0.0, math.pi)
    turn = math.pi if rng.random() < 0.5 else -math.pi

    out = np.empty((T, m, n), dtype=dtype)
    chunk = max(1, _CHUNK_VALUES // (m * n))
    for s0 in range(0, T, chunk):  # sub-frames s0 .. s0 + chunk at once; per sub-frame, the scalars first
        taus = [(s + 0.5) / T for s in range(s0, min(s0 + chunk, T))]
        angles = [phase + turn * tau for tau in taus]
        cos_a, sin_a = _column([math.cos(a) for a in angles]), _column([math.sin(a) for a in angles])
        cy = _column([disc_y0 + (disc_y1 - disc_y0) * tau for tau in taus])
        cx = _column([disc_x0 + (disc_x1 - disc_x0) * tau for tau in taus])
        frame = np.broadcast_to(background, (len(taus), m, n))
        # bar (drawn first, the disc passes over it)
        dy, dx = yy - bar_cy, xx - bar_cx
        along = dx * cos_a + dy * sin_a
        across = -dx * sin_a + dy * cos_a
        qa = np.abs(along) - half_length
        qc = np.abs(across) - half_width
        outside = np.hypot(np.maximum(qa, 0.0), np.maximum(qc, 0.0))
        inside = np.minimum(np.maximum(qa, qc), 0.0)
        cover = _coverage(outside + inside)
        frame = frame * (1.0 - cover) + 0.8 * cover
        # disc
        cover = _coverage(np.hypot(yy - cy, xx - cx) - radius)
        frame = frame * (1.0 - cover) + 1.0 * cover
        out[s0 : s0 + len(taus)] = np.clip(frame, 0.0, 1.0)
    return out


#: Values (sub-frames x pixels) :func:`builtin_scene` renders at once: a few MiB per float64 array.
_CHUNK_VALUES = 1 << 18


def _column(values) -> np.ndarray:
    """Per-sub-frame scalars as a ``(k, 1, 1)`` float64 array, to broadcast over a chunk's frames."""
    return np.asarray(values, dtype=np.float64)[:, None, None]


# ---------------------------------------------------------------------- protocol
def _unit_scaler(video: np.ndarray):
    """A function mapping frame index -> that frame scaled to [0, 1], float64: integers (and booleans)
    divided by their dtype maximum, floats min-max scaled over the whole video (constant -> 0)."""
    kind = video.dtype.kind
    if kind == "b":
        return lambda i: video[i].astype(np.float64)
    if kind in "ui":
        top = float(np.iinfo(video.dtype).max)
        return lambda i: video[i].astype(np.float64) / top
    low, high = float(video.min()), float(video.max())
    if high == low:
        return lambda i: np.zeros(video.shape[1:], dtype=np.float64)
    return lambda i: (video[i].astype(np.float64) - low) / (high - low)


def benchmark_protocol(video: ArrayLike, shape: tuple[int, int], T: int) -> np.ndarray:
    """Turn a video into a benchmark datacube (the protocol of docs/model.md).

    1. Scale to [0, 1]: integer dtypes are divided by their dtype maximum (uint8 by 255, uint16 by
       65535, ...); float input is min-max scaled over the whole video (a constant one becomes zeros).
    2. Resize every frame to ``shape`` with :func:`skimage.transform.resize` (bilinear, anti-aliased).
    3. Resample linearly in time to ``T`` sub-frames: sub-frame ``s`` sits at source frame position
       ``s*(F-1)/(T-1)`` (``T = 1``: the first frame), so the first and last sub-frames are the
       resized first and last frames.
    4. Clip to [0, 1].

    Only the source frames that the ``T`` positions touch are resized.

    Parameters
    ----------
    video : array_like, shape (F, h, w)
        Source frames, integer or float intensities.
    shape : (int, int)
        ``(m, n)``: rows and columns of the datacube, pixels.
    T : int
        Number of sub-frames (>= 1).

    Returns
    -------
    ndarray of float32, shape (T, m, n)
        Intensities in [0, 1].

    Raises
    ------
    ValueError
        If ``video`` is not a finite real 3-D array with at least one frame,
        or ``shape`` or ``T`` are out of range.

    Examples
    --------
    >>> import numpy as np, rsocl
    >>> video = np.random.default_rng(0).integers(0, 256, (10, 120, 160), dtype=np.uint8)  # 8-bit frames
    >>> cube = rsocl.benchmark_protocol(video, (32, 32), 55)
    >>> cube.shape, cube.dtype.name, bool(0 <= cube.min() and cube.max() <= 1)
    ((55, 32, 32), 'float32', True)
    """
    from skimage.transform import resize

    video = check.finite_array("video", video)
    if video.ndim != 3 or 0 in video.shape:
        raise ValueError(f"video must be a non-empty 3-D array [frames, h, w], got shape {video.shape}")
    shape = _shape(shape)
    T = check.positive_int("T (sub-frames)", T)
    F = video.shape[0]
    if T == 1 or F == 1:
        position = np.zeros(T)
    else:
        position = np.arange(T, dtype=np.float64) * (F - 1) / (T - 1)
    lower = np.minimum(np.floor(position).astype(np.int64), max(F - 2, 0))
    fraction = position - lower
    needed = sorted(set(lower.tolist()) | {i + 1 for i, f in zip(lower.tolist(), fraction) if f > 0})

    unit = _unit_scaler(video)
    resized = {}
    for i in needed:
        resized[i] = resize(unit(i), shape, order=1, anti_aliasing=True, mode="reflect", preserve_range=True)

    out = np.empty((T,) + shape, dtype=np.float32)
    for s in range(T):
        i, f = int(lower[s]), float(fraction[s])
        value = resized[i] if f == 0.0 else (1.0 - f) * resized[i] + f * resized[i + 1]
        out[s] = np.clip(value, 0.0, 1.0)
    return out


def load_scene(spec: PathLike, shape: tuple[int, int], T: int, *, key: str = "video") -> np.ndarray:
    """A benchmark datacube from a specification: ``"builtin"`` or a video file.

    Parameters
    ----------
    spec : str or os.PathLike
        ``"builtin"`` for :func:`builtin_scene` (default seed), otherwise the
        path of a video file read by :func:`load_video`.
    shape : (int, int)
        ``(m, n)``: rows and columns, pixels.
    T : int
        Number of sub-frames (>= 1).
    key : str
        Array name inside a ``.npz`` file.

    Returns
    -------
    ndarray of float32, shape (T, m, n)
        Intensities in [0, 1].
    """
    if isinstance(spec, str) and spec == "builtin":
        return builtin_scene(shape, T, dtype=np.float32)
    if not isinstance(spec, (str, os.PathLike)):
        raise ValueError(f"spec must be 'builtin' or a video file path, got {spec!r}")
    return benchmark_protocol(load_video(spec, key=key), shape, T)
