"""Photometric gain from flat-field frames (the *photometric* calibration).

:func:`flat_field_gain` gives each camera's gain relative to camera 0.
"""

from __future__ import annotations

import numpy as np

from rsocl.common import validation as check


def flat_field_gain(frames, *, relative_to=0, dark=0.0, region=0.5, trim=0.1, saturation=None) -> np.ndarray:
    """Photometric gain of each camera from flat-field frames.

    Parameters
    ----------
    frames : sequence of array_like, or array_like
        One entry per camera: a flat-field frame ``(rows, columns)`` or a
        stack of them ``(K, rows, columns)`` (frames may differ in size
        between cameras). An array ``(C, rows, columns)`` or
        ``(C, K, rows, columns)`` is accepted too. All cameras must see the
        same uniform light with the same exposure time.
    relative_to : int or "mean"
        Camera whose gain is 1 (default camera 0), or ``"mean"`` for gains
        whose mean is 1.
    dark : float or sequence of float
        Dark level (black offset) subtracted from each camera's frames, in
        intensity units; one value, or one per camera.
    region : float
        Fraction (0, 1] of each axis, centred, over which the level is
        measured (vignetting grows towards the edges).
    trim : float
        Fraction [0, 0.5) cut from each tail before averaging (robust
        against hot pixels and dust).
    saturation : float or sequence of float or None, optional
        Level, in the frames' units, at or above which a camera's sensor
        clips a pixel (e.g. ``2**bit_depth - 1`` for raw levels); one value,
        or one per camera (None for a camera whose level is unknown).
        Default None: not checked.

    Returns
    -------
    ndarray of float64, shape (C,)
        Gains, dimensionless (``Camera.gain``).

    Raises
    ------
    ValueError
        If a camera's dark-subtracted level is not positive, or more than
        ``trim`` of its measured pixels are saturated (the trimmed mean would
        hold clipped levels, and the gain would come out low).
    """
    from scipy.stats import trim_mean

    if isinstance(frames, np.ndarray):
        frames = list(frames)
    frames = [check.finite_array(f"frames[{c}]", f) for c, f in enumerate(frames)]
    if not frames:
        raise ValueError("frames must hold at least one camera's flat field")
    C = len(frames)
    region = check.in_range("region", region, 1e-6, 1.0)
    trim = check.finite("trim", trim)
    if not 0 <= trim < 0.5:
        raise ValueError(f"trim must be in [0, 0.5), got {trim!r}")
    darks = (
        np.full(C, check.finite("dark", dark))
        if np.ndim(dark) == 0
        else check.finite_array("dark", dark).astype(np.float64)
    )
    if darks.shape != (C,):
        raise ValueError(f"dark must be one value or one per camera ({C}), got shape {darks.shape}")
    tops = list(saturation) if np.ndim(saturation) == 1 else [saturation] * C
    if len(tops) != C:
        raise ValueError(f"saturation must be one value or one per camera ({C}), got {len(tops)}")
    tops = [None if t is None else check.finite(f"saturation[{c}]", t) for c, t in enumerate(tops)]
    levels = np.empty(C)
    for c, flat in enumerate(frames):
        if flat.ndim not in (2, 3) or 0 in flat.shape:
            raise ValueError(
                f"frames[{c}] must be a (rows, columns) frame or a (K, rows, columns) stack, got shape {flat.shape}"
            )
        rows, cols = flat.shape[-2:]
        dr, dc = (rows - max(1, round(rows * region))) // 2, (cols - max(1, round(cols * region))) // 2
        centre = flat[..., dr : rows - dr, dc : cols - dc].astype(np.float64)
        clipped = 0.0 if tops[c] is None else float(np.mean(centre >= tops[c]))
        if clipped > trim:
            raise ValueError(
                f"camera {c}: {100 * clipped:.3g} % of its flat field's measured pixels are saturated (at or "
                f"above {tops[c]:.6g}), more than the {100 * trim:g} % (trim) that the mean leaves out: its gain "
                "would come out low; lower the light or the exposure"
            )
        scale = float(np.max(np.abs(centre))) or 1.0  # the mean of values near the float range's top
        levels[c] = float(trim_mean(centre.ravel() / scale, trim)) * scale - darks[c]  # does not overflow
        if not levels[c] > 0:
            raise ValueError(
                f"camera {c}: flat-field level minus dark is {levels[c]:.6g}, must be > 0 "
                f"(is the dark level right, is the light on?)"
            )
    if relative_to == "mean":
        levels = levels / levels.max()
        return levels / levels.mean()
    if isinstance(relative_to, bool) or not isinstance(relative_to, (int, np.integer)) or not 0 <= relative_to < C:
        raise ValueError(f"relative_to must be a camera index in [0, {C - 1}] or 'mean', got {relative_to!r}")
    return levels / levels[int(relative_to)]
