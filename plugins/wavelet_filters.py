"""Orthonormal wavelet filters (PyWavelets' decomposition filters) and the plan of a transform."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["WAVELETS", "MODES", "filters", "axis_levels", "Plan"]

# Decomposition filters of PyWavelets (pywt.Wavelet(name).dec_lo / dec_hi, PyWavelets 1.8),
# written as the shortest decimals that round-trip to the same doubles. The
# reconstruction filters are their reverses (rec_lo = dec_lo[::-1], rec_hi = dec_hi[::-1]).
WAVELETS: dict[str, dict[str, tuple[float, ...]]] = {
    "haar": {"dec_lo": (0.7071067811865476, 0.7071067811865476), "dec_hi": (-0.7071067811865476, 0.7071067811865476)},
    "db2": {
        "dec_lo": (-0.12940952255126037, 0.2241438680420134, 0.8365163037378079, 0.48296291314453416),
        "dec_hi": (-0.48296291314453416, 0.8365163037378079, -0.2241438680420134, -0.12940952255126037),
    },
    "db4": {
        "dec_lo": (
            -0.010597401785069032,
            0.0328830116668852,
            0.030841381835560764,
            -0.18703481171909309,
            -0.027983769416859854,
            0.6308807679298589,
            0.7148465705529157,
            0.2303778133088965,
        ),
        "dec_hi": (
            -0.2303778133088965,
            0.7148465705529157,
            -0.6308807679298589,
            -0.027983769416859854,
            0.18703481171909309,
            0.030841381835560764,
            -0.0328830116668852,
            -0.010597401785069032,
        ),
    },
}
MODES = {"2d": (1, 2), "3d": (0, 1, 2)}


def filters(name: str) -> dict:
    """``dec_lo``, ``dec_hi``, ``rec_lo``, ``rec_hi`` of wavelet ``name`` as float64 arrays."""
    if name not in WAVELETS:
        raise ValueError(f"unknown wavelet {name!r}; known: {sorted(WAVELETS)}")
    lo = np.array(WAVELETS[name]["dec_lo"], dtype=np.float64)
    hi = np.array(WAVELETS[name]["dec_hi"], dtype=np.float64)
    return {"dec_lo": lo, "dec_hi": hi, "rec_lo": lo[::-1].copy(), "rec_hi": hi[::-1].copy()}


def axis_levels(length: int, filter_length: int) -> int:
    """Most levels an axis of ``length`` takes: ``length`` divisible by ``2**L`` and the
    signal entering the coarsest level, ``length / 2**(L-1)``, at least ``filter_length`` long."""
    levels = 0
    while length % (2 ** (levels + 1)) == 0 and length // 2**levels >= filter_length:
        levels += 1
    return levels


class Plan(NamedTuple):
    """How a ``(T, m, n)`` array is transformed.

    levels : int
        Decomposition levels, the same for every transformed axis (0: identity).
    axes : tuple of int
        Axes transformed in the first block (0: t, 1: y, 2: x).
    blocks : tuple of (t0, frames, axes)
        Blocks of consecutive sub-frames ``[t0, t0 + frames)``, each transformed
        on its own along its axes (a single block unless the time axis is split).
    """

    levels: int
    axes: tuple
    blocks: tuple
