"""The static part of a scene, from the snapshots, kept as the interpolation gives it.

Where every camera sees the same value, the scene did not change during the exposures, and the
``interp3d`` interpolation of the snapshots is already right there; a regularized solution can
fade such a background in the first and last sub-frames. :func:`static_mask` finds those pixels
(:data:`SPREAD` of the snapshots' bright level, shrunk by one pixel so that edges of moving parts
stay out) and :func:`static_fix` moves the result towards the interpolation on them. With noise
in the snapshots the cameras rarely agree that closely, and the mask is empty.

Small bright features that every camera sees alike, points and spots up to
``2 * POINT_HALF + 1`` pixels across on a darker surround, are held only in the few sub-frames a
camera exposes there: in the others TV's spatial term shrinks them towards the surround, and the
held-out pixels of the parameter search cannot see those sub-frames. :func:`point_mask` finds them
with a tolerance scaled to the feature's own contrast and to the snapshots' noise, and
:func:`static_fix` sets them, with their surround, to the interpolation (:data:`POINT_WEIGHT`).

Both masks measure the snapshots as a whole: their bright level, darkest value and noise
(:class:`Levels`). A tile of a larger frame (:mod:`rsocl.scale`) takes the frame's levels
(:func:`frame_levels`), so that it marks the pixels the run in one piece marks.

Measured effect (PSNR and SSIM): ``docs/quality_ladder.md``; on point sources:
``docs/point_sources.md``.
"""

from __future__ import annotations

import contextlib
import contextvars
from typing import NamedTuple

import numpy as np

__all__ = [
    "SPREAD",
    "BRIGHT_PERCENTILE",
    "POINT_HALF",
    "POINT_AGREE",
    "POINT_CONTRAST",
    "POINT_NOISE",
    "POINT_SURROUND",
    "POINT_WEIGHT",
    "Levels",
    "levels",
    "frame_levels",
    "static_mask",
    "noise_level",
    "point_mask",
    "static_weights",
    "static_fix",
]

#: Largest spread of a pixel over the cameras (max - min), as a fraction of the bright level, for
#: the pixel to count as static.
SPREAD = 0.02
#: Percentile of the snapshots that sets their bright level.
BRIGHT_PERCENTILE = 99.9
#: Half the side of the window a point feature fits in, pixels (features up to 5x5 pixels).
POINT_HALF = 2
#: Largest spread of the cameras (max - min) anywhere in a point's window, as a fraction of its contrast.
POINT_AGREE = 0.5
#: Smallest contrast of a point over its surround, as a fraction of the snapshots' range (bright level
#: minus the darkest value).
POINT_CONTRAST = 0.25
#: Smallest contrast of a point, in standard deviations of the snapshots' noise (:func:`noise_level`).
POINT_NOISE = 5.0
#: Brightest value just outside a point's window, over the surround, as a fraction of its contrast.
POINT_SURROUND = 0.25
#: How far a point's window moves to the interpolation in :func:`static_fix` (1: all the way).
POINT_WEIGHT = 1.0
#: Why these values, measured on point sources and on the quality benchmarks' scenes:
#: ``docs/solver-notes.md`` (point sources).


class Levels(NamedTuple):
    """What the masks measure on the snapshots as a whole, in their units: ``bright`` (their
    :data:`BRIGHT_PERCENTILE` th percentile), ``darkest`` (their minimum) and ``noise``
    (:func:`noise_level`)."""

    bright: float
    darkest: float
    noise: float


def levels(g: np.ndarray) -> Levels:
    """The :class:`Levels` of snapshots ``g`` ``(K, m, n)``.

    Examples
    --------
    >>> levels(np.arange(8.0).reshape(2, 2, 2))
    Levels(bright=7.0, darkest=0.0, noise=0.0)
    """
    g = np.asarray(g, dtype=np.float64)
    bright = float(np.percentile(g, BRIGHT_PERCENTILE))
    return Levels(bright, float(g.min()), noise_level(g) if g.shape[0] >= 2 else 0.0)


_FRAME: contextvars.ContextVar[Levels | None] = contextvars.ContextVar("rsocl_static_levels", default=None)


@contextlib.contextmanager
def frame_levels(measured: Levels | None):
    """Within the block, the static-part fix of this thread's runs measures nothing on their own snapshots and
    takes ``measured`` (None: their own, as outside the block): a tile's run takes its frame's."""
    token = _FRAME.set(measured)
    try:
        yield
    finally:
        _FRAME.reset(token)


def _levels(g, given: Levels | None) -> Levels:
    """``given``, else the levels of :func:`frame_levels`, else ``g``'s own."""
    if given is None:
        given = _FRAME.get()
    return levels(g) if given is None else given


def _erode(mask: np.ndarray) -> np.ndarray:
    """``mask`` ``(m, n)`` shrunk by one pixel (4-neighbourhood; pixels on the border are dropped)."""
    out = mask.copy()
    out[0, :] = out[-1, :] = False
    out[:, 0] = out[:, -1] = False
    out[1:-1, 1:-1] &= mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:]
    return out


def static_mask(g: np.ndarray, measured: Levels | None = None) -> np.ndarray:
    """The static pixels of snapshots ``g`` ``(K, m, n)``: bool ``(m, n)`` (module doc).

    Parameters
    ----------
    g : ndarray, shape (K, m, n)
        Snapshots of every camera on the reference grid.
    measured : Levels or None
        The levels to hold the spread against (None: :func:`frame_levels`' or ``g``'s own).

    Returns
    -------
    ndarray of bool, shape (m, n)

    Examples
    --------
    >>> g = np.ones((4, 6, 6)); g[0, 0, 0] = 2.0
    >>> int(static_mask(g).sum())
    16
    """
    g = np.asarray(g, dtype=np.float64)
    measured = measured if measured is not None else _FRAME.get()  # else its own bright level alone
    bright = float(np.percentile(g, BRIGHT_PERCENTILE)) if measured is None else measured.bright
    if g.shape[0] < 2 or bright <= 0 or min(g.shape[1:]) < 3:
        return np.zeros(g.shape[1:], bool)
    return _erode((g.max(axis=0) - g.min(axis=0)) < SPREAD * bright)


def noise_level(g: np.ndarray) -> float:
    """Standard deviation of the noise of snapshots ``g`` ``(K, m, n)``, ``K >= 2``, in their units: the
    median absolute deviation of the differences of consecutive cameras at each pixel, scaled to a
    Gaussian's standard deviation and divided by sqrt(2). Moving parts only raise it; on a scene that
    is mostly black with shot noise only it is 0.

    Examples
    --------
    >>> g = np.random.default_rng(0).normal(1.0, 0.1, (4, 64, 64))
    >>> round(noise_level(g), 2)
    0.1
    """
    g = np.asarray(g, dtype=np.float64)
    d = (g[1:] - g[:-1]).ravel()
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))


def point_mask(g: np.ndarray, measured: Levels | None = None) -> np.ndarray:
    """The windows of small static bright features of snapshots ``g`` ``(K, m, n)``: bool ``(m, n)``.

    A feature is a pixel whose camera mean is the largest in its window of ``2 * POINT_HALF + 1``
    pixels a side, with a contrast ``c`` over the darkest camera mean in the window grown by one
    pixel that is above :data:`POINT_CONTRAST` of the snapshots' range and :data:`POINT_NOISE` times
    their :func:`noise_level`; the camera means on the ring just outside the window stay within
    :data:`POINT_SURROUND` ``c`` of that darkest value, and at every pixel of the window the cameras
    spread by less than :data:`POINT_AGREE` ``c``. Its whole window is marked. One camera, or a grid
    smaller than the window grown by one pixel, has none.

    Parameters
    ----------
    g : ndarray, shape (K, m, n)
        Snapshots of every camera on the reference grid.
    measured : Levels or None
        The snapshots' range and noise (None: :func:`frame_levels`' or ``g``'s own).

    Returns
    -------
    ndarray of bool, shape (m, n)

    Examples
    --------
    >>> g = np.zeros((4, 12, 12)); g[:, 6, 6] = 5.0
    >>> int(point_mask(g).sum())
    25
    """
    from scipy.ndimage import binary_dilation, maximum_filter, minimum_filter

    g = np.asarray(g, dtype=np.float64)
    K, m, n = g.shape
    side = 2 * POINT_HALF + 1
    if K < 2 or min(m, n) < side + 2:
        return np.zeros((m, n), bool)
    mean = g.mean(axis=0)
    surround = minimum_filter(mean, size=side + 2, mode="nearest")
    contrast = mean - surround
    ring = np.ones((side + 2, side + 2), bool)
    ring[1:-1, 1:-1] = False
    outside = maximum_filter(mean, footprint=ring, mode="nearest") - surround
    spread = maximum_filter(g.max(axis=0) - g.min(axis=0), size=side, mode="nearest")
    measured = _levels(g, measured)
    span = measured.bright - measured.darkest
    points = (
        (mean >= maximum_filter(mean, size=side, mode="nearest"))
        & (contrast > POINT_CONTRAST * span)
        & (contrast > POINT_NOISE * measured.noise)
        & (outside <= POINT_SURROUND * contrast)
        & (spread < POINT_AGREE * contrast)
    )
    if not points.any():
        return points
    return binary_dilation(points, structure=np.ones((side, side), bool))


def _parts(g: np.ndarray) -> tuple:
    """``(still, points)``: the pixels of :func:`static_mask` of ``g`` outside :func:`point_mask`, and
    :func:`point_mask`."""
    measured = _levels(np.asarray(g, dtype=np.float64), None)  # once for both masks
    points = point_mask(g, measured)
    return static_mask(g, measured) & ~points, points


def static_weights(g: np.ndarray, weight: float) -> np.ndarray:
    """How far :func:`static_fix` moves each pixel of snapshots ``g`` ``(K, m, n)`` to the interpolation:
    ``(m, n)`` floats, :data:`POINT_WEIGHT` on :func:`point_mask` (where ``weight > 0``), ``weight`` on the
    rest of :func:`static_mask`, 0 elsewhere.

    Examples
    --------
    >>> g = np.zeros((4, 12, 12)); g[:, 6, 6] = 5.0; g[0, 0, 0] = 1.0
    >>> w = static_weights(g, 0.75)
    >>> float(w[6, 6]), float(w[2, 6]), float(w[0, 0])
    (1.0, 0.75, 0.0)
    """
    still, points = _parts(g)
    return weight * still + (POINT_WEIGHT if weight > 0 else 0.0) * points


def static_fix(solver, start, g: np.ndarray, weight: float):
    """Move ``solver``'s estimate towards ``start`` by :func:`static_weights` (``weight`` on the static
    pixels of ``g``, :data:`POINT_WEIGHT` on the point windows), on the device; how many pixels move (or
    would, at ``weight`` 0; one count per set for a batch).

    Parameters
    ----------
    solver : rsocl.solver.admm.ADMM
        The run, its estimate ``theta`` ``(T, m, n)`` or ``(B, T, m, n)`` on the device.
    start : pyopencl.array.Array
        The interpolation the run started from, ``theta``'s shape.
    g : ndarray, shape (K, m, n) or (B, K, m, n)
        The snapshots.
    weight : float
        In [0, 1]; 0 leaves the estimate as it is.
    """
    g = np.asarray(g)
    parts = [_parts(one) for one in (g if g.ndim == 4 else g[None])]
    counts = [int(still.sum() + points.sum()) for still, points in parts]
    if weight > 0 and any(counts):
        solver.pull_towards(start, np.stack([weight * still + POINT_WEIGHT * points for still, points in parts]))
    return counts if g.ndim == 4 else counts[0]
