"""The interpolation baseline ``interp3d``: a datacube from the snapshots with no solver.

Each snapshot pixel divided by its exposure length estimates the scene at the middle of its
exposure window, and each pixel is interpolated linearly in time between its samples. It is
the baseline of ``rsocl bench`` and the warm start of :func:`rsocl.solver.reconstruct`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from rsocl.common import validation as check
from rsocl.common.hints import ArrayLike
from rsocl.model.curvature import binary_span

if TYPE_CHECKING:
    from rsocl.model.rig import Rig

__all__ = ["interp3d", "samples", "evaluate", "Samples"]


def interp3d(g: ArrayLike, rig: Rig, valid: ArrayLike | None = None) -> np.ndarray:
    """The 3-D interpolation baseline: a ``(T, m, n)`` datacube from the snapshots alone.

    Snapshot pixel ``g[k, y, x]`` divided by its gain and exposure length (``t_e/dt``
    sub-frames) is the mean of the scene over its exposure window, taken as the scene's
    value at the window's middle, ``(start + end) / 2``. Each pixel then has ``K``
    samples scattered in time (one per camera, at its own row time); the estimate of
    sub-frame ``s`` is the linear interpolation of those samples at the sub-frame's centre
    ``s + 1/2``, constant before the first and after the last sample. Samples at equal
    times count with equal weight. This is the natural 3-D interpolation of the
    scattered space-time samples, done per pixel; it is exact for a scene constant in time.

    Parameters
    ----------
    g : array_like, shape (K, m, n)
        Snapshots of ``rig``.
    rig : Rig
    valid : array_like of bool, shape (K, m, n), or None
        Samples to use (None: all). A pixel with one valid sample is constant in time; a
        pixel with none takes the mean of every valid sample of the snapshots.

    Returns
    -------
    ndarray of float64, shape (T, m, n)

    Raises
    ------
    ValueError
        If ``rig`` is not a Rig, ``g`` is not ``(K, m, n)`` and finite, or ``valid`` has another
        shape or keeps no sample.

    Examples
    --------
    >>> import rsocl
    >>> rig = rsocl.Rig.paper_array(4, shape=(16, 16), t_e=180e-6, t_r=35e-6)
    >>> truth = rsocl.builtin_scene(rig.shape, rig.T)
    >>> cube = rsocl.interp3d(rsocl.simulate(truth, rig), rig)
    >>> cube.shape == truth.shape
    True
    """
    from rsocl.model.rig import Rig

    if not isinstance(rig, Rig):
        raise ValueError(f"rig must be an rsocl.Rig, got {type(rig).__name__}")
    g = check.finite_array("g", g).astype(np.float64, copy=False)
    K = rig.n_channels
    if g.shape != (K,) + rig.shape:
        raise ValueError(f"g must have shape (K, m, n) = {(K,) + rig.shape}, got {g.shape}")
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != g.shape:
            raise ValueError(f"valid must have the shape of g {g.shape}, got {valid.shape}")
        if not valid.any():
            raise ValueError("valid must keep at least one snapshot pixel")
        if valid.all():
            valid = None
    return _interpolated(g, rig, valid)


def _sampled(rig):
    """Per snapshot pixel, ``(K, m, n)`` each: the sum of its shutter weights (sub-frames) and the
    centre of the sub-frames it averages (in sub-frames, a sub-frame's centre at ``s + 1/2``).

    ``exact`` mask: the window's length ``t_e/dt`` and its middle. ``binary`` mask (``w = 1`` for
    the sub-frames ``s`` with ``start <= s <= end``, docs/model.md): the count of those ``s`` within
    ``0 .. T-1`` and the middle of the first and the last one's centres.
    """
    win = rig.windows
    if rig.mask == "exact":
        start = win.index + win.fraction
        length = np.broadcast_to(win.length[:, None, None], start.shape)
        return length, start + length / 2.0
    first, last = binary_span(rig)
    return np.maximum(last - first + 1.0, 0.0), (first + last) / 2.0 + 0.5


@dataclass
class Samples:
    """Each pixel's samples in time, sorted: what :func:`interp3d` interpolates between.

    ``times`` and ``values`` are ``(K, m, n)`` float64: per pixel, the distinct centres of its samples'
    windows (sub-frames, a sub-frame's centre at ``s + 1/2``) in ascending order, the rest at
    ``+inf``, and the scene values there (snapshot over gain and window length; the mean of the
    samples that share a centre) in the same order. ``count`` ``(m, n)``: the distinct times a pixel
    keeps; ``fallback``: the value of a pixel
    that keeps none (the mean of every kept sample); ``empty``: no sample is kept anywhere (the
    snapshots say nothing and the interpolation is zero).
    """

    times: np.ndarray
    values: np.ndarray
    count: np.ndarray
    fallback: float
    empty: bool = False


def samples(g, rig, valid=None) -> Samples:
    """The sorted :class:`Samples` of checked snapshots ``g`` (float64 ``(K, m, n)``) and ``valid``
    (bool of that shape, or None: every sample)."""
    K = rig.n_channels
    length, centre = _sampled(rig)
    seen = length > 0  # a binary window may hold no sub-frame start
    if not seen.all():
        valid = seen if valid is None else valid & seen
        if not valid.any():  # H is zero: the snapshots say nothing
            nothing = np.zeros((K,) + rig.shape)
            return Samples(nothing, nothing, np.zeros(rig.shape, dtype=np.int64), 0.0, empty=True)
    scaled = g / (rig.windows.gain[:, None, None] * np.where(seen, length, 1.0))
    if valid is not None:
        centre = np.where(valid, centre, np.inf)  # left-out samples sort last
        count = valid.sum(axis=0)
    else:
        count = np.full(rig.shape, K)
    order = np.argsort(centre, axis=0, kind="stable")
    fallback = float(np.mean(scaled[valid])) if valid is not None and np.any(count == 0) else 0.0
    times, values, count = _merged(
        np.take_along_axis(centre, order, axis=0), np.take_along_axis(scaled, order, axis=0), count
    )
    return Samples(times, values, count, fallback)


def _merged(times, values, count):
    """Sorted ``times`` and ``values`` ``(K, m, n)`` of ``count`` kept samples per pixel, with the samples
    of each pixel at one time merged into one at their mean: ``(times, values, count)`` of the distinct
    times, first in each pixel, the rest at ``+inf`` with value 0."""
    K = times.shape[0]
    kept = np.arange(K)[:, None, None] < count[None]
    group = np.cumsum(np.concatenate([np.ones_like(times[:1], bool), times[1:] != times[:-1]]), axis=0) - 1
    sums, num = np.zeros_like(values), np.zeros_like(values)
    first = np.full_like(times, np.inf)
    for k in range(K):  # sample k adds to its time's group, a position at or before k
        at = group[k][None]
        np.put_along_axis(sums, at, np.take_along_axis(sums, at, 0) + np.where(kept[k], values[k], 0.0), 0)
        np.put_along_axis(num, at, np.take_along_axis(num, at, 0) + kept[k], 0)
        np.put_along_axis(first, at, np.where(kept[k], times[k], np.take_along_axis(first, at, 0)), 0)
    merged = num > 0
    return first, np.where(merged, sums / np.where(merged, num, 1.0), 0.0), merged.sum(axis=0)


def _interpolated(g, rig, valid):
    """:func:`interp3d` of checked ``g`` (float64) and ``valid`` (bool or None: every sample)."""
    found = samples(g, rig, valid)
    if found.empty:
        return np.zeros((rig.T,) + rig.shape)
    return evaluate(found, np.arange(rig.T))


def evaluate(found: Samples, subframes) -> np.ndarray:
    """The interpolation of ``found`` at the centres of ``subframes`` (indices): ``(len, m, n)`` float64.

    Per pixel and sub-frame ``s``: the two kept samples around ``s + 1/2`` (the first two before
    the first sample, the last two after the last), linearly interpolated and held constant
    beyond them; samples at equal times give their mean; one kept sample is constant in time,
    none gives ``found.fallback``. ``rsocl.model.interpolation_device`` computes the same on a
    device.
    """
    times, values, count = found.times, found.values, found.count
    K = times.shape[0]
    query = np.asarray(subframes, dtype=np.float64) + 0.5
    hi = np.zeros((len(query),) + count.shape, dtype=np.int64)
    for k in range(K):  # samples at or before each query time
        hi += times[k][None] <= query[:, None, None]
    hi = np.clip(hi, 1, np.maximum(count - 1, 1)[None])
    lo = hi - 1
    top = max(K - 1, 0)
    hi, lo = np.minimum(hi, top), np.minimum(lo, top)
    t_lo, t_hi = np.take_along_axis(times, lo, axis=0), np.take_along_axis(times, hi, axis=0)
    v_lo, v_hi = np.take_along_axis(values, lo, axis=0), np.take_along_axis(values, hi, axis=0)
    with np.errstate(invalid="ignore"):  # inf - inf where a pixel lacks samples
        span = t_hi - t_lo
    ok = np.isfinite(span) & (span > 0)
    w = np.where(ok, (query[:, None, None] - t_lo) / np.where(ok, span, 1.0), 0.0)
    w = np.clip(w, 0.0, 1.0)
    equal = np.isfinite(span) & (span == 0)  # samples at equal times: their mean
    w = np.where(equal, 0.5, w)
    out = v_lo + w * (v_hi - v_lo)
    out = np.where((count == 1)[None], values[0][None], out)
    if np.any(count == 0):
        out = np.where((count == 0)[None], found.fallback, out)
    return out
