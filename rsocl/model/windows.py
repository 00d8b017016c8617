"""Exposure windows on the sub-frame grid: when each channel and pixel is exposed, in units of ``dt``.

Conventions follow ``docs/model.md``: sub-frame ``s`` covers ``[s*dt, (s+1)*dt)``. A window starts
at the exposure start divided by ``dt`` and lasts ``t_e/dt`` sub-frames. :class:`ExposureWindows`
holds them; :func:`exposure_windows` builds them from start times in seconds,
:func:`weighted_bounds` gives the first and last sub-frame each window gives a non-zero weight under
a shutter mask, and :func:`kernel_windows` the windows as the OpenCL kernels take them.
:class:`~rsocl.model.rig.Rig` keeps its windows in one of these.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rsocl.model.camera import _snap

__all__ = ["ExposureWindows", "exposure_windows", "weighted_bounds", "kernel_windows"]


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
        """Window end in sub-frames, ``(K, m, n)`` float64, snapped to a sub-frame start as the start
        is (an end that the sum's rounding leaves 1e-16 off a whole sub-frame lies on it)."""
        return _snap(self.index + self.fraction + self.length[:, None, None])


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


def kernel_windows(windows: ExposureWindows, mask: str, dtype) -> tuple[np.ndarray, np.ndarray]:
    """``(frac, length)``: the windows as ``kernels/common.cl``'s ``shutter_weight`` takes them, in
    ``dtype`` (the kernels' real type).

    ``length`` is ``(K, 2)``: each channel's whole sub-frames and the rest, in [0, 1), so that the
    kernels form a weight near a window's end from small numbers (a window of 2000.3 sub-frames keeps
    its last weight of 0.3 in float32). ``frac`` is ``(K, m, n)``: the start's fraction
    (:attr:`ExposureWindows.fraction`) under the ``exact`` mask; under ``binary`` (a weight of 1 or 0)
    a value that makes the kernels' test give exactly :func:`weighted_bounds`' first and last
    sub-frame whatever the rounding in ``dtype``: 0 where the window starts on a sub-frame start, the
    smallest positive normal number where its last sub-frame is ``floor(length)`` after its first
    index, else 1.
    """
    dtype = np.dtype(dtype)
    whole = np.floor(windows.length)
    # the rest, below 1 in dtype, so that 1 + rest stays below 2 there (binary's test below)
    rest = np.minimum(windows.length - whole, 1.0 - float(np.finfo(dtype).eps))
    length = np.stack([whole, rest], axis=1).astype(dtype)
    if mask != "binary":
        return windows.fraction.astype(dtype), length
    first, last = weighted_bounds(windows, mask)
    # the last sub-frame after the window's index, less its whole sub-frames: 0 or 1 (its rest passes
    # a sub-frame start or not); only 0 where the window starts on one or the rest is 0
    beyond = (last - windows.index) - whole[:, None, None]
    on_start = first == windows.index
    beyond = np.where(on_start | (rest[:, None, None] == 0), 0.0, np.clip(beyond, 0.0, 1.0))
    frac = np.where(on_start, 0.0, np.where(beyond > 0, 1.0, float(np.finfo(dtype).tiny)))
    return frac.astype(dtype), length
