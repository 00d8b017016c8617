"""The scale of the data term: how strongly the snapshots pin the datacube down.

The diagonal of ``H Hᵀ`` at a snapshot pixel, ``psi = gain² · Σ_s w_s²`` (docs/model.md's shutter
weights ``w_s`` over the sub-frames ``s`` of its window), is the curvature of the data term
``½‖g - H x‖²`` along that pixel's own window. Multiplying every gain by ``c`` multiplies it by
``c²``, and so does shortening an exposure below one sub-frame by ``c`` (one weight of ``t_e/dt``);
above a sub-frame it grows like ``t_e/dt`` (about that many weights of 1). :func:`default_scale`
compares a rig with the paper's configuration, for which the fixed defaults were measured.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "binary_span",
    "psi_values",
    "psi_mean",
    "full_scales",
    "white_levels",
    "REFERENCE_PSI",
    "NO_WEIGHT",
    "default_scale",
]

#: The ValueError's message for a rig whose windows give no sub-frame a weight (:func:`default_scale`,
#: :func:`rsocl.model.simulate.full_scale`).
NO_WEIGHT = (
    "the rig's exposure windows hold no sub-frame: every snapshot pixel has zero weight (check t_e, dt and the mask)"
)


def binary_span(rig):
    """First and last sub-frame a ``binary`` window holds (``w = 1`` for the ``s`` in ``0 .. T-1``
    with ``start <= s <= end``, docs/model.md), ``(K, m, n)`` float64 each; ``last < first`` where the
    window holds no sub-frame start (``t_e < dt``), whose ``first`` may be ``T``
    (:meth:`Rig.sampled_window <rsocl.model.rig.Rig.sampled_window>`: integer indices in ``0 .. T-1``, and
    ``last = first - 1`` for an empty window)."""
    win = rig.windows
    first = np.maximum(np.ceil(win.index + win.fraction), 0.0)
    last = np.minimum(np.floor(win.end), rig.T - 1.0)
    return first, last


def psi_values(rig) -> np.ndarray:
    """``psi`` of every snapshot pixel, ``(K, m, n)`` float64, from the rig's exposure windows alone
    (no device): ``exact`` mask ``Σ_s |[s, s+1) ∩ [start, end]|²`` over ``s = 0 .. T-1``,
    ``binary`` mask the count of ``s`` in ``[start, end]``, each times the channel's gain squared."""
    win = rig.windows
    gain2 = (win.gain**2)[:, None, None]
    if rig.mask == "binary":
        first, last = binary_span(rig)
        return np.maximum(last - first + 1.0, 0.0) * gain2
    T = float(rig.T)
    start = np.clip(win.index + win.fraction, 0.0, T)
    end = np.clip(win.end, 0.0, T)
    a, e = np.floor(start), np.floor(end)
    within = a == e  # the window lies in one sub-frame
    head = np.where(within, end - start, a + 1.0 - start)
    tail = np.where(within, 0.0, end - e)
    full = np.where(within, 0.0, e - a - 1.0)
    return (head**2 + full + tail**2) * gain2


def psi_mean(rig) -> float:
    """The mean of :func:`psi_values` over snapshot pixels (dimensionless, sub-frames)."""
    return float(np.mean(psi_values(rig)))


def full_scales(rig) -> np.ndarray:
    """Each channel's full scale, ``(K,)`` float64: its snapshot of a white (1.0) scene, ``gain · Σ_s w_s``,
    at its brightest pixel. ``exact`` mask: ``gain · t_e/dt``; ``binary``: ``gain`` times the most
    sub-frame starts one of its exposures holds (6 for the paper's ``t_e/dt = 5.14``, docs/model.md)."""
    win = rig.windows
    if rig.mask != "binary":
        return win.gain * win.length
    first, last = binary_span(rig)  # the sub-frame starts of 0 .. T-1 that a window holds
    starts = np.maximum(last - first + 1.0, 0.0).reshape(len(win.gain), -1).max(axis=1)
    return win.gain * starts


def white_levels(rig) -> np.ndarray:
    """Each camera's value of a white (1.0) scene at unit gain, ``(len(rig.cameras),)`` float64: the level a
    sensor's full scale stands for. ``t_e/dt`` (its exposure in sub-frames); with the ``binary`` mask the most
    sub-frame starts one of its exposures holds (:func:`full_scales` over its gain, its frames' largest).

    >>> from rsocl import Rig
    >>> white_levels(Rig.paper_array(1, (4, 4), t_e=180e-6, t_r=35e-6, mask="binary"))
    array([6.])
    """
    white = np.array([camera.t_e / rig.dt for camera in rig.cameras])
    if rig.mask == "binary":
        white[:] = 0.0
        for scale, (c, _) in zip(full_scales(rig), rig.channels):
            white[c] = max(white[c], scale / rig.cameras[c].gain)
    return white


def _reference() -> float:
    from rsocl.model.rig import Rig

    return psi_mean(Rig.paper_array(1, (1, 1), t_e=180e-6, t_r=35e-6))


#: ``psi`` of the paper's configuration (t_e = 180 µs, t_r = dt = 35 µs, gain 1): 5 + (1/7)² = 5.0204.
REFERENCE_PSI = _reference()


def default_scale(rig) -> float:
    """``psi_mean(rig) / REFERENCE_PSI``: the factor the default ``lam`` and ``eta`` take for ``rig``
    (1 for the paper's configuration, which the rig matches to rounding when the ratio is within 1e-9 of 1).

    Raises ValueError when no snapshot pixel has any weight (every window misses every sub-frame).
    """
    scale = psi_mean(rig) / REFERENCE_PSI
    if not scale > 0:
        raise ValueError(NO_WEIGHT)
    return 1.0 if abs(scale - 1.0) < 1e-9 else scale
