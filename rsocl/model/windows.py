"""Exposure windows on the sub-frame grid: when each channel and pixel is exposed, in units of ``dt``.

Conventions follow ``docs/model.md``: sub-frame ``s`` covers ``[s*dt, (s+1)*dt)``. A window starts
at the exposure start divided by ``dt`` and lasts ``t_e/dt`` sub-frames. :class:`ExposureWindows`
holds them; :func:`exposure_windows` builds them from start times in seconds, and
:func:`weighted_bounds` gives the first and last sub-frame each window gives a non-zero weight under
a shutter mask. :class:`~rsocl.model.rig.Rig` keeps its windows in one of these.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rsocl.model.camera import _snap

__all__ = ["ExposureWindows", "exposure_windows", "weighted_bounds"]


@dataclass(frozen=True)
class ExposureWindows:
    """Per-channel, per-pixel exposure windows in units of ``dt``.

    Attributes
    ----------
    index : ndarray of int32, shape (K, m, n)
        ``floor(start/dt)``: the first sub-frame the window can touch.
    fraction : ndarray of float64, shape (K, m, n)
        ``start/dt - index``, in [0, 1).
    length : ndarray of float64, shape (K,)
        Exposure ``t_e/dt`` of each channel, in sub-frames.
    gain : ndarray of float64, shape (K,)
        Gain of each channel.
    """

    index: np.ndarray
    fraction: np.ndarray
    length: np.ndarray
    gain: np.ndarray

    @property
    def end(self) -> np.ndarray:
        """Window end in sub-frames, ``(K, m, n)`` float64."""
        return self.index + self.fraction + self.length[:, None, None]


def exposure_windows(start_times: np.ndarray, t_e: np.ndarray, gain: np.ndarray, dt: float) -> ExposureWindows:
    """The windows of exposures starting at ``start_times`` (seconds, ``(K, m, n)``) and lasting
    ``t_e`` (seconds, ``(K,)``), with per-channel ``gain`` (``(K,)``), on sub-frames of ``dt`` seconds.

    Raises ``ValueError`` if an exposure starts 2**31 - 1 sub-frames or more after t = 0.
    """
    start = _snap(start_times / dt)
    index = np.floor(start)
    fraction = start - index
    if index.max() >= 2**31 - 1:
        raise ValueError(f"exposure starts {index.max():.3g} sub-frames after t=0; reduce t_a/t_d or raise dt")
    return ExposureWindows(index.astype(np.int32), fraction, _snap(np.asarray(t_e) / dt), np.asarray(gain))


def weighted_bounds(windows: ExposureWindows, mask: str) -> tuple[np.ndarray, np.ndarray]:
    """``(first, last)``: the first and the last sub-frame (inclusive, float64, ``(K, m, n)``, not
    clipped to the rig's sub-frames) to which each window gives a non-zero weight under ``mask``
    (``"exact"``: any overlap; ``"binary"``: the paper's Eq. 4, see ``docs/model.md``)."""
    start, end = windows.index + windows.fraction, windows.end
    if mask == "exact":
        return np.floor(start), np.ceil(end) - 1
    return np.ceil(start), np.floor(end)
