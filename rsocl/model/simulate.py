"""Simulated snapshots: the forward model plus an optional sensor model.

Intensities follow docs/model.md: a scene in [0, 1] per sub-frame gives snapshots in
``[0, gain * t_e/dt]`` (the ``binary`` mask: ``gain`` times the sub-frame starts an exposure holds).
The sensor's full scale is that maximum (the largest over channels,
:func:`rsocl.model.curvature.full_scales`), so ``bit_depth`` quantises ``[0, full_scale]`` into
``2**bit_depth`` levels and values above it saturate.
"""

from __future__ import annotations

import numbers
import warnings

import numpy as np

from rsocl.common import validation as check
from rsocl.common.hints import ArrayLike, DTypeLike
from rsocl.device.context import Device, get_device
from rsocl.model.curvature import NO_WEIGHT, full_scales
from rsocl.model.operator import RollingShutterOperator
from rsocl.model.rig import Rig

__all__ = [
    "simulate",
    "full_scale",
    "check_photons",
    "check_seed",
    "check_fits_dtype",
    "MAX_PHOTONS",
    "CLIPPED_SHARE_WARN",
]

#: Most photo-electrons at full scale: NumPy's Poisson sampler draws means below about 9.2e18.
MAX_PHOTONS = 1e18
#: Share of the snapshot samples above full scale over which ``bit_depth`` warns that it saturates them.
CLIPPED_SHARE_WARN = 0.5


def check_photons(name: str, photons) -> float:
    """``photons`` (photo-electrons at full scale) as a float in ``(0, MAX_PHOTONS]``; ValueError naming ``name``."""
    photons = check.positive(name, photons, "photo-electrons")
    if photons > MAX_PHOTONS:
        raise ValueError(
            f"{name} must be in (0, {MAX_PHOTONS:g}] photo-electrons at full scale (the Poisson "
            f"sampler's largest mean), got {photons!r}"
        )
    return photons


def _noise_settings(noise: str, sigma, photons, bit_depth):
    """``(sigma, photons, bit_depth)`` of :func:`simulate`, checked before any work: each in its range, the
    settings of another noise model than ``noise`` refused (``sigma`` 0 counts as none)."""
    if noise != "gaussian" and not (isinstance(sigma, numbers.Number) and sigma == 0):
        raise ValueError(f"sigma applies to noise='gaussian' only, got sigma = {sigma!r} with noise = {noise!r}")
    if noise != "poisson" and photons is not None:
        raise ValueError(f"photons applies to noise='poisson' only, got photons = {photons!r} with noise = {noise!r}")
    if noise == "gaussian":
        sigma = check.non_negative("sigma", sigma, "(fraction of full scale)")
    if noise == "poisson":
        if photons is None:
            raise ValueError("photons (photo-electrons at full scale, > 0) is required for noise='poisson'")
        photons = check_photons("photons", photons)
    bits = None if bit_depth is None else check.positive_int("bit_depth", bit_depth, maximum=32)
    return sigma, photons, bits


def check_seed(name: str, seed):
    """``seed`` of the noise generator: an integer ``>= 0``, or None (fresh entropy); ValueError naming ``name``."""
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {seed!r}")
    return int(seed)


def check_fits_dtype(name: str, array, dtype) -> None:
    """Raise a ValueError naming ``name`` when ``array`` (None: nothing to check) holds values beyond the
    largest finite value of the real type ``dtype`` (float64 data above 3.4e38 run in float32 would turn
    into inf)."""
    dtype = check.real_dtype("dtype", dtype)
    top = float(np.finfo(dtype).max)
    peak = float(np.max(np.abs(array))) if array is not None and np.size(array) else 0.0
    if peak > top:
        raise ValueError(
            f"{name} holds values up to {peak:.3g}, beyond {dtype.name}'s largest {top:.3g}; "
            "scale the data (rsocl works on data in [0, 1] per sub-frame) or use dtype='float64'"
        )


def full_scale(rig: Rig) -> float:
    """Snapshot value of a white (1.0) scene on the brightest channel: ``max gain * t_e/dt`` (the
    ``binary`` mask: ``gain`` times the sub-frame starts an exposure holds; :func:`full_scales`).

    Raises ValueError when it is 0: no window gives any sub-frame a weight (a ``binary`` rig whose
    exposures, shorter than ``dt``, hold no sub-frame start).
    """
    scale = float(np.max(full_scales(rig)))
    if not scale > 0:
        raise ValueError(NO_WEIGHT)
    return scale


def simulate(
    truth: ArrayLike,
    rig: Rig,
    *,
    noise: str = "none",
    sigma: float = 0.0,
    photons: float | None = None,
    bit_depth: int | None = None,
    seed: int | None = 0,
    device: str | Device | None = None,
    dtype: DTypeLike | None = None,
) -> np.ndarray:
    """Snapshots ``(K, m, n)`` of the datacube ``truth`` ``(T, m, n)`` seen by ``rig``.

    Parameters
    ----------
    truth : array_like, shape (T, m, n)
        The scene, linear intensities (in [0, 1] under the benchmark protocol), ``T = rig.T``.
    rig : Rig
        The camera array.
    noise : {"none", "gaussian", "poisson"}
        ``gaussian`` adds ``N(0, sigma**2)`` in snapshot units (``sigma`` as a
        fraction of the full scale); ``poisson`` draws shot noise with ``photons``
        photo-electrons at full scale.
    sigma : float
        Gaussian standard deviation, fraction of full scale (>= 0); with another ``noise``, 0 only.
    photons : float or None
        Photo-electrons at full scale for Poisson noise, ``0 < photons <=`` :data:`MAX_PHOTONS` (and the
        brightest snapshot's mean within it); with another ``noise``, None only.
    bit_depth : int or None
        Quantise to ``2**bit_depth`` levels over ``[0, full_scale]`` (1..32), with saturation (a warning when
        it saturates more than :data:`CLIPPED_SHARE_WARN` of the samples).
    seed : int or None
        Seed of the noise generator, ``>= 0`` (None: fresh entropy).
    device : str, Device or None
        OpenCL device of the forward model (see :func:`rsocl.get_device`).
    dtype : {"float64", "float32"} or None
        Arithmetic of the forward model on the device; None: float64 where the device has fp64, else
        float32 (the forward model's sums to about 1e-7 of the full scale).

    Returns
    -------
    ndarray of float64, shape (K, m, n)
        Snapshots in the units of ``truth`` times the exposure in sub-frames (``gain * t_e/dt``
        for a white scene).

    Raises
    ------
    ValueError
        If ``truth`` is not ``(T, m, n)`` and finite or holds values beyond ``dtype``'s largest, a noise
        parameter is out of range or belongs to another noise model (the message names it),
        ``noise="poisson"`` lacks ``photons`` or sees a negative scene, or no window of the rig gives any
        sub-frame a weight (:func:`full_scale`).

    Examples
    --------
    >>> import rsocl
    >>> rig = rsocl.Rig.paper_array(4, shape=(16, 16), t_e=180e-6, t_r=35e-6)
    >>> truth = rsocl.builtin_scene(rig.shape, rig.T)
    >>> g = rsocl.simulate(truth, rig, noise="poisson", photons=1e4, bit_depth=12, seed=1)
    >>> g.shape, bool(0 <= g.min() and g.max() <= rsocl.model.simulate.full_scale(rig))
    ((4, 16, 16), True)
    """
    if not isinstance(rig, Rig):
        raise ValueError(f"rig must be an rsocl.Rig, got {type(rig).__name__}")
    truth = check.finite_array("truth", truth)
    expected = (rig.T,) + rig.shape
    if truth.shape != expected:
        raise ValueError(f"truth must have shape (T, m, n) = {expected} for this rig, got {truth.shape}")
    noise = check.choice("noise", noise, {"none", "gaussian", "poisson"})
    sigma, photons, bits = _noise_settings(noise, sigma, photons, bit_depth)
    seed = check_seed("seed", seed)
    scale = full_scale(rig)
    if dtype is None:
        dtype = "float64" if get_device(device).has_fp64 else "float32"
    check_fits_dtype("truth", truth, dtype)
    g = RollingShutterOperator(rig, device=device, dtype=dtype).forward(truth).astype(np.float64)
    rng = np.random.default_rng(seed)
    if noise == "gaussian":
        g = g + rng.normal(0.0, sigma * scale, g.shape)
    elif noise == "poisson":
        if np.any(g < 0):
            raise ValueError("poisson noise needs a non-negative scene")
        peak = float(g.max()) / scale
        if peak * photons > MAX_PHOTONS:
            raise ValueError(
                f"photons must be at most {MAX_PHOTONS / peak:.3g} for this scene, whose brightest snapshot is "
                f"{peak:.3g}x full scale (the Poisson sampler's largest mean is {MAX_PHOTONS:g}), got {photons!r}"
            )
        g = rng.poisson(g * (photons / scale)) * (scale / photons)
    if bits is not None:
        over = float(np.mean(g > scale))
        if over > CLIPPED_SHARE_WARN:
            warnings.warn(
                f"bit_depth = {bits} saturates {100 * over:.0f} % of the snapshot samples: full scale is a white scene "
                f"(1.0), and truth peaks at {float(np.max(truth)):.4g}; a scene in raw counts needs dividing by its "
                "white level first",
                UserWarning,
                stacklevel=2,
            )
        levels = 2**bits - 1
        g = np.round(np.clip(g, 0.0, scale) / scale * levels) * (scale / levels)
    return g
