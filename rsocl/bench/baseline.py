"""The ``interp3d`` baseline of ``rsocl bench``.

The baseline ``interp3d`` (:func:`interp3d`) needs no solver: each snapshot pixel divided by
its exposure length estimates the scene at the middle of its exposure window, and each
pixel is interpolated linearly in time between its ``C`` samples.
"""

from __future__ import annotations

import numpy as np

__all__ = ["interp3d"]


def interp3d(g, rig) -> np.ndarray:
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

    Returns
    -------
    ndarray of float64, shape (T, m, n)
    """
    g = np.asarray(g, dtype=np.float64)
    K = rig.n_channels
    if g.shape != (K,) + rig.shape:
        raise ValueError(f"g must have shape (K, m, n) = {(K,) + rig.shape}, got {g.shape}")
    win = rig.windows
    length = win.length[:, None, None]
    centre = win.index + win.fraction + length / 2.0
    values = g / (win.gain[:, None, None] * length)
    T = rig.T
    if K == 1:
        return np.repeat(values, T, axis=0)
    order = np.argsort(centre, axis=0, kind="stable")
    times = np.take_along_axis(centre, order, axis=0)
    values = np.take_along_axis(values, order, axis=0)
    query = np.arange(T, dtype=np.float64) + 0.5
    hi = np.zeros((T,) + rig.shape, dtype=np.int64)
    for k in range(K):                                   # samples at or before each query time
        hi += times[k][None] <= query[:, None, None]
    hi = np.clip(hi, 1, K - 1)
    lo = hi - 1
    t_lo, t_hi = np.take_along_axis(times, lo, axis=0), np.take_along_axis(times, hi, axis=0)
    v_lo, v_hi = np.take_along_axis(values, lo, axis=0), np.take_along_axis(values, hi, axis=0)
    span = t_hi - t_lo
    w = np.where(span > 0, (query[:, None, None] - t_lo) / np.where(span > 0, span, 1.0), 0.5)
    w = np.clip(w, 0.0, 1.0)
    return v_lo + w * (v_hi - v_lo)
