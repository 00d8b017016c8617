"""The static part of a scene, from the snapshots, kept as the interpolation gives it.

Where every camera sees the same value, the scene did not change during the exposures, and the
``interp3d`` interpolation of the snapshots is already right there; a regularized solution can
fade such a background in the first and last sub-frames. :func:`static_mask` finds those pixels
(:data:`SPREAD` of the snapshots' bright level, shrunk by one pixel so that edges of moving parts
stay out) and :func:`static_fix` moves the result towards the interpolation on them. With noise
in the snapshots the cameras rarely agree that closely, and the mask is empty.

Measured effect (PSNR and SSIM): ``docs/quality_ladder.md``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SPREAD", "BRIGHT_PERCENTILE", "static_mask", "static_fix"]

#: Largest spread of a pixel over the cameras (max - min), as a fraction of the bright level, for
#: the pixel to count as static.
SPREAD = 0.02
#: Percentile of the snapshots that sets their bright level.
BRIGHT_PERCENTILE = 99.9


def _erode(mask: np.ndarray) -> np.ndarray:
    """``mask`` ``(m, n)`` shrunk by one pixel (4-neighbourhood; pixels on the border are dropped)."""
    out = mask.copy()
    out[0, :] = out[-1, :] = False
    out[:, 0] = out[:, -1] = False
    out[1:-1, 1:-1] &= mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:]
    return out


def static_mask(g: np.ndarray) -> np.ndarray:
    """The static pixels of snapshots ``g`` ``(K, m, n)``: bool ``(m, n)`` (module doc).

    Parameters
    ----------
    g : ndarray, shape (K, m, n)
        Snapshots of every camera on the reference grid.

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
    bright = float(np.percentile(g, BRIGHT_PERCENTILE))
    if g.shape[0] < 2 or bright <= 0 or min(g.shape[1:]) < 3:
        return np.zeros(g.shape[1:], bool)
    return _erode((g.max(axis=0) - g.min(axis=0)) < SPREAD * bright)


def static_fix(solver, start, g: np.ndarray, weight: float):
    """Move ``solver``'s estimate by ``weight`` towards ``start`` on the static pixels of ``g``
    (:func:`static_mask`), on the device; how many pixels those are (one count per set for a batch).

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
    masks = np.stack([static_mask(one) for one in g]) if g.ndim == 4 else static_mask(g)[None]
    counts = [int(m.sum()) for m in masks]
    if weight > 0 and any(counts):
        solver.pull_towards(start, weight * masks)
    return counts if g.ndim == 4 else counts[0]
