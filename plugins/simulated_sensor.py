"""The simulated camera's sensor model: noise, saturation and quantisation of a rendered frame.

The ``sensor`` table of a simulated camera's config (:mod:`rsocl_plugins.simulated`) names the
effects; each is off by default.

Applied in this order to the model value ``g`` (scene in [0, 1] gives
``g`` in ``[0, gain * white]``). The *full scale* is ``saturation`` when given,
else ``white``, the value of a white scene at unit gain: ``t_e/dt``, or with the
binary mask the most sub-frame starts one exposure holds
(:func:`rsocl.model.curvature.white_levels`; a camera with ``gain > 1`` saturates
on scenes brighter than ``1/gain``).

1. ``trigger_jitter`` (s): each trigger offsets ``t_a`` by a normal draw with
   this standard deviation (the offset start is clipped at 0: nothing exists
   before the scene starts).
2. ``shot_noise_photons``: photo-electrons at full scale; ``g`` is replaced by
   ``Poisson(g * photons / full_scale) * full_scale / photons``. None = off.
3. ``read_noise``: standard deviation of additive Gaussian noise, as a
   fraction of full scale. 0 = off.
4. ``saturation`` (model units): values above it are clipped to it.
5. ``bit_depth`` (1..16): quantisation to ``2**bit_depth`` levels over
   ``[0, full_scale]`` (values clipped to that range first). Frames are then
   integers ``0..2**bit_depth - 1`` (``Mono8`` up to 8 bits, else ``Mono16``);
   ``pixel_format = "Float32"`` keeps the quantised values in model units.
   None = float output (``Float32``), model units.
6. ``seed``: seed of the noise and jitter generator (with ``index``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["SENSOR_KEYS", "apply_sensor", "sensor_bits"]

#: The keys of the ``sensor`` table.
SENSOR_KEYS = {"shot_noise_photons", "read_noise", "bit_depth", "saturation", "trigger_jitter", "seed"}


def sensor_bits(bit_depth, pixel_format: str) -> int:
    """Bits per pixel of a frame: ``bit_depth`` where given (at most 8 for ``Mono8``), else the
    pixel format's own (8, 16; 32 for ``Float32``)."""
    if pixel_format == "Mono8":
        return min(bit_depth or 8, 8)
    if pixel_format == "Mono16":
        return bit_depth or 16
    return bit_depth or 32


def apply_sensor(g, sensor: dict, full_scale: float, pixel_format: str, rng) -> np.ndarray:
    """Effects 2-5 of the sensor model on the model values ``g`` (the jitter acts on the trigger).

    Parameters
    ----------
    g : numpy.ndarray
        Model values of one frame (float64; ``[0, gain * white]`` for a scene in [0, 1]).
    sensor : dict
        The parsed ``sensor`` table (every key of :data:`SENSOR_KEYS`; None or 0 where off).
    full_scale : float
        Model value of full scale (``saturation`` when given, else ``white``).
    pixel_format : str
        ``"Mono8"``, ``"Mono16"`` or ``"Float32"``.
    rng : numpy.random.Generator
        The camera's noise generator.

    Returns
    -------
    numpy.ndarray
        ``uint8``/``uint16`` levels ``0 .. 2**bits - 1``, or ``float32`` model units.
    """
    fs = full_scale
    if sensor["shot_noise_photons"] is not None:
        photons = sensor["shot_noise_photons"]
        g = rng.poisson(np.clip(g, 0.0, None) * (photons / fs)) * (fs / photons)
    if sensor["read_noise"] > 0:
        g = g + rng.normal(0.0, sensor["read_noise"] * fs, g.shape)
    if sensor["saturation"] is not None:
        g = np.minimum(g, sensor["saturation"])
    if pixel_format != "Float32" or sensor["bit_depth"] is not None:
        levels = 2 ** sensor_bits(sensor["bit_depth"], pixel_format) - 1
        dn = np.rint(np.clip(g, 0.0, fs) / fs * levels)
        if pixel_format == "Float32":
            return (dn * (fs / levels)).astype(np.float32)
        return dn.astype(np.uint8 if pixel_format == "Mono8" else np.uint16)
    return g.astype(np.float32)
