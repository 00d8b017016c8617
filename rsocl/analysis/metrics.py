"""Image-quality metrics of a reconstructed datacube against the ground truth.

Both metrics use the same ``data_range`` convention: when not given it is
``1.0`` for a ground truth inside [0, 1] (the benchmark protocol's scale: a
uint8 video divided by 255, peak 1, as the snapshot-compressive-imaging
literature reports PSNR), else the truth's peak-to-peak range (``1.0`` when
that is zero).
"""

from __future__ import annotations

import math

import numpy as np

from rsocl.common import validation as check
from rsocl.common.hints import ArrayLike

__all__ = ["psnr", "ssim", "mse", "default_data_range"]

#: Window side skimage's SSIM uses by default, pixels.
SSIM_WINDOW = 7


def _pair(estimate, truth) -> tuple[np.ndarray, np.ndarray]:
    estimate = check.finite_array("estimate", estimate)
    truth = check.finite_array("truth", truth)
    if estimate.shape != truth.shape:
        raise ValueError(
            f"estimate and truth must have the same shape, got estimate {estimate.shape} and truth {truth.shape}"
        )
    if truth.size == 0:
        raise ValueError(f"truth must not be empty, got shape {truth.shape}")
    return estimate, truth


def default_data_range(truth) -> float:
    """``1.0`` for data in [0, 1], else ``max - min`` of ``truth`` (``1.0`` when constant)."""
    truth = np.asarray(truth)
    low, high = float(truth.min()), float(truth.max())
    if low >= 0.0 and high <= 1.0:
        return 1.0
    peak_to_peak = high - low
    return peak_to_peak if peak_to_peak > 0 else 1.0


def _data_range(truth: np.ndarray, data_range) -> float:
    if data_range is not None:
        return check.positive("data_range", data_range, "(intensity units)")
    return default_data_range(truth)


def mse(estimate, truth) -> float:
    """Mean squared error, computed in float64 with pairwise summation.

    Parameters
    ----------
    estimate, truth : array_like
        Arrays of the same shape, intensity units.

    Returns
    -------
    float
        ``mean((estimate - truth)**2)``, intensity units squared.
    """
    estimate, truth = _pair(estimate, truth)
    diff = estimate.astype(np.float64) - truth.astype(np.float64)
    return float(np.mean(np.square(diff)))


def psnr(estimate: ArrayLike, truth: ArrayLike, *, data_range: float | None = None) -> float:
    """Peak signal-to-noise ratio of ``estimate`` against ``truth``, dB.

    ``PSNR = 10 log10(data_range**2 / MSE)`` over all elements (sub-frames,
    rows and columns together).

    Parameters
    ----------
    estimate : array_like
        Reconstruction, any shape (typically ``[T, m, n]``), intensity units.
    truth : array_like
        Ground truth, same shape as ``estimate``.
    data_range : float, optional
        Peak value range, intensity units (> 0). Default: :func:`default_data_range`, ``1.0``
        for a truth inside [0, 1], else ``truth.max() - truth.min()`` (``1.0`` when constant).

    Returns
    -------
    float
        PSNR in dB; ``inf`` when ``estimate`` equals ``truth`` exactly.

    Raises
    ------
    ValueError
        If the shapes differ, an array is empty or not finite, or
        ``data_range`` is not > 0.

    Examples
    --------
    >>> import numpy as np, rsocl
    >>> truth = np.full((2, 8, 8), 0.5)
    >>> round(rsocl.psnr(truth + 0.1, truth), 6)          # data in [0, 1]: peak 1, MSE 0.01
    20.0
    """
    estimate, truth = _pair(estimate, truth)
    peak = _data_range(truth, data_range)
    error = mse(estimate, truth)
    if error == 0.0:
        return math.inf
    return 10.0 * math.log10(peak * peak / error)


def _win_size(m: int, n: int):
    """Largest odd SSIM window ``<= min(m, n)`` and ``<= 7``; ``None`` below 3 px."""
    side = min(m, n, SSIM_WINDOW)
    if side % 2 == 0:
        side -= 1
    return side if side >= 3 else None


def ssim(estimate: ArrayLike, truth: ArrayLike, *, data_range: float | None = None) -> tuple[float, np.ndarray]:
    """Structural similarity, per sub-frame and averaged.

    Each sub-frame is compared as a 2-D image with
    :func:`skimage.metrics.structural_similarity` (uniform 7x7 window,
    skimage's defaults) using one ``data_range`` for the whole datacube.

    Parameters
    ----------
    estimate : array_like
        Reconstruction ``[T, m, n]`` (or one image ``[m, n]``), intensity units.
    truth : array_like
        Ground truth, same shape as ``estimate``.
    data_range : float, optional
        Peak value range, intensity units (> 0), one for the whole datacube. Default:
        :func:`default_data_range`, ``1.0`` for a truth inside [0, 1], else
        ``truth.max() - truth.min()`` (``1.0`` when constant).

    Returns
    -------
    mean : float
        Mean SSIM over the sub-frames (dimensionless, at most 1).
    per_subframe : ndarray of float64, shape (T,)
        SSIM of each sub-frame.

    Notes
    -----
    Frames smaller than 7 pixels along a side use the largest odd window that
    fits (``win_size = 5`` or ``3``). Frames with fewer than 3 rows or columns
    cannot be compared by SSIM: every value, and the mean, is then NaN.

    Raises
    ------
    ValueError
        If the shapes differ, the arrays are not 2-D or 3-D, empty or not
        finite, or ``data_range`` is not > 0.

    Examples
    --------
    >>> import rsocl
    >>> truth = rsocl.builtin_scene((16, 16), 3)
    >>> mean, per_subframe = rsocl.ssim(truth, truth)
    >>> round(mean, 6), per_subframe.shape
    (1.0, (3,))
    """
    from skimage.metrics import structural_similarity

    estimate, truth = _pair(estimate, truth)
    if truth.ndim == 2:
        estimate, truth = estimate[None], truth[None]
    elif truth.ndim != 3:
        raise ValueError(f"truth must be [T, m, n] (or one [m, n] image), got {truth.ndim}-D shape {truth.shape}")
    peak = _data_range(truth, data_range)
    _, m, n = truth.shape
    win = _win_size(m, n)
    per = np.full(truth.shape[0], np.nan, dtype=np.float64)
    if win is not None:
        for s in range(truth.shape[0]):
            per[s] = structural_similarity(
                estimate[s].astype(np.float64), truth[s].astype(np.float64), data_range=peak, win_size=win
            )
    return float(np.mean(per)), per
