"""Row readout time from a frame of a flickering light (the *temporal* calibration).

A rolling shutter records the flicker as horizontal bands;
:func:`estimate_row_time` measures their period ``P`` (rows) and returns
``t_r = 1 / (f * P)``; :func:`check_row_time` compares it with the value the
rig file states.
"""

from __future__ import annotations

import math

import numpy as np

from rsocl.common import validation as check
from rsocl.hardware.calibration._common import _image

#: Degree of the polynomial fitted beside the bands: a light that rises and falls over the rows
#: (vignetting, a lamp's beam) is no straight trend, and a sinusoid fitted beside a straight one leans
#: towards the curvature (t_r off by 2 % for a 10 % fall-off and a 10 % flicker over four periods).
_TREND_DEGREE = 2
#: A band weaker than this fraction of the profile's level is rounding, not light (a 16-bit level is
#: 1.5e-5 of full scale): a frame whose exposure holds whole flicker periods is flat to rounding.
_FLAT = 1e-9


def _trend(N: int) -> np.ndarray:
    """``(N, _TREND_DEGREE + 1)`` Legendre polynomials over the profile's samples (scaled to [-1, 1])."""
    return np.polynomial.legendre.legvander(np.linspace(-1.0, 1.0, N), _TREND_DEGREE)


def _sinusoid_fit(profile: np.ndarray, frequency: float):
    """Least-squares fit of a quadratic trend + a cos + b sin at ``frequency``; returns (rss, coefficients)."""
    k = np.arange(profile.size, dtype=np.float64)
    phase = 2 * np.pi * frequency * k
    design = np.column_stack([_trend(profile.size), np.cos(phase), np.sin(phase)])
    coefficients, *_ = np.linalg.lstsq(design, profile, rcond=None)
    residual = profile - design @ coefficients
    return float(residual @ residual), coefficients[-2:]


def band_period(profile, *, min_periods=2.0) -> float:
    """Period, in samples, of the dominant sinusoid of a 1-D profile.

    The initial estimate is the peak of the Hann-windowed, zero-padded FFT
    (quadratic trend removed), refined by parabolic interpolation of the log
    magnitude; the final value minimises the residual of a least-squares fit
    of ``quadratic trend + a cos + b sin`` over the frequency, within one FFT
    bin of the peak. The quadratic takes up a light that rises and falls
    smoothly over the profile (vignetting).

    Parameters
    ----------
    profile : array_like, shape (N,)
        E.g. the row means of a frame.
    min_periods : float
        Fewest whole periods the profile must hold (the lowest frequency
        searched is ``min_periods / N``).

    Returns
    -------
    float
        Period in samples (> 2, the Nyquist limit).

    Raises
    ------
    ValueError
        If the profile is too short or no significant periodic band is found
        (one weaker than the residual's noise, or than 1e-9 of the profile's
        level: rounding).
    """
    from scipy.optimize import minimize_scalar

    profile = check.finite_array("profile", profile).astype(np.float64).ravel()
    N = profile.size
    min_periods = check.positive("min_periods", min_periods)
    if N < 8:
        raise ValueError(f"profile must hold at least 8 samples, got {N}")
    trend = _trend(N)
    detrended = profile - trend @ np.linalg.lstsq(trend, profile, rcond=None)[0]
    pad = 16 * (1 << int(math.ceil(math.log2(N))))
    spectrum = np.abs(np.fft.rfft(detrended * np.hanning(N), pad))
    freqs = np.fft.rfftfreq(pad)
    valid = freqs >= min_periods / N
    level = float(np.abs(profile).max())
    if not valid.any() or not np.abs(detrended).max() > _FLAT * level:  # a constant leaves rounding only
        raise ValueError("profile has no periodic component (flat after removing its trend)")
    index = int(np.flatnonzero(valid)[np.argmax(spectrum[valid])])
    f0 = freqs[index]
    if 0 < index < len(spectrum) - 1:
        a, b, c = np.log(spectrum[index - 1 : index + 2] + 1e-300)
        denominator = a - 2 * b + c
        if denominator < 0:
            f0 = freqs[index] + 0.5 * (a - c) / denominator * (freqs[1] - freqs[0])
    low, high = max(f0 - 1.0 / N, 0.5 / N), min(f0 + 1.0 / N, 0.5)
    best = minimize_scalar(
        lambda f: _sinusoid_fit(profile, f)[0], bounds=(low, high), method="bounded", options={"xatol": 1e-9}
    )
    frequency = float(best.x)
    rss, coefficients = _sinusoid_fit(profile, frequency)
    amplitude = float(np.hypot(*coefficients))
    noise = math.sqrt(rss / max(N - _TREND_DEGREE - 4, 1))
    if amplitude < max(5 * noise * math.sqrt(2.0 / N), _FLAT * level):
        raise ValueError(
            f"no significant band found: fitted amplitude {amplitude:.3g} against a residual of {noise:.3g} per sample"
        )
    if frequency < min_periods / N or frequency >= 0.5:
        raise ValueError(
            f"band period {1 / frequency:.3g} samples is outside the measurable range (2 .. {N / min_periods:.3g})"
        )
    return 1.0 / frequency


def estimate_row_time(frame, flicker_hz, *, axis=0, min_periods=2.0) -> float:
    """Row readout time from a frame of a flickering light, seconds.

    A rolling shutter starts row ``r`` at ``r * t_r``, so a light whose
    intensity oscillates at ``flicker_hz`` paints bands with a period of
    ``P = 1 / (flicker_hz * t_r)`` rows; hence ``t_r = 1 / (flicker_hz * P)``.

    Parameters
    ----------
    frame : array_like, shape (rows, columns)
        A raw sensor frame (not registered: its rows are the sensor's rows)
        of an evenly lit scene under the flickering light.
    flicker_hz : float
        Frequency of the intensity oscillation, Hz. Lamps on AC mains flicker
        at twice the mains frequency (100 Hz on 50 Hz mains, 120 Hz on 60 Hz).
    axis : int
        Axis of ``frame`` along which the sensor rows run (0 for a frame
        stored as rows x columns, 1 for a transposed one).
    min_periods : float
        Fewest band periods the frame must show (see :func:`band_period`).

    Returns
    -------
    float
        ``t_r``, seconds.

    Notes
    -----
    The period is measured on the profile of row means
    (:func:`band_period`), so it must span more than 2 rows
    (``flicker_hz * t_r < 0.5``) and the frame at least ``min_periods``
    periods. An exposure time that is a whole number of flicker periods
    averages the bands away. :func:`flicker_limits` says which of these a
    camera's stated ``t_r`` and ``t_e`` break.
    """
    frame = _image("frame", frame)
    flicker_hz = check.positive("flicker_hz", flicker_hz, "Hz")
    if axis not in (0, 1, -1, -2):
        raise ValueError(f"axis must be 0 or 1, got {axis!r}")
    profile = frame.mean(axis=1 if axis in (0, -2) else 0)
    return 1.0 / (flicker_hz * band_period(profile, min_periods=min_periods))


def flicker_limits(flicker_hz, t_r, t_e, rows, *, min_periods=2.0) -> list:
    """Why a flicker cannot show a camera's row time, from its stated ``t_r`` and ``t_e``: one line each.

    Parameters
    ----------
    flicker_hz : float
        Frequency of the light's intensity oscillation, Hz.
    t_r, t_e : float
        The camera's row time and exposure time as the rig file states them, seconds.
    rows : int
        Rows of the camera's frame.
    min_periods : float
        Fewest band periods :func:`estimate_row_time` measures.

    Returns
    -------
    list of str
        Empty when the flicker can show ``t_r``; else the reasons: the bands alias (``flicker_hz * t_r >= 0.5``,
        so every measurable ``t_r`` is below ``1 / (2 flicker_hz)``), the frame holds fewer than
        ``min_periods`` periods, or the exposure spans so many periods (or so nearly a whole number of them)
        that it averages the bands to under 10 % of the flicker (``|sinc(flicker_hz * t_e)| < 0.1``).
    """
    f = check.positive("flicker_hz", flicker_hz, "Hz")
    t_r, t_e = check.positive("t_r", t_r, "seconds"), check.positive("t_e", t_e, "seconds")
    rows = check.positive_int("rows", rows)
    reasons = []
    if f * t_r >= 0.5:
        reasons.append(
            f"at the rig file's t_r = {t_r * 1e6:.4g} µs the flicker advances {f * t_r:.3g} periods per row, "
            f"0.5 or more: its bands alias, and no t_r above 1 / (2 x {f:.6g} Hz) = {0.5e6 / f:.4g} µs can be "
            f"measured; use a light flickering below 1 / (2 t_r) = {0.5 / t_r:.6g} Hz"
        )
    elif rows * f * t_r < min_periods:
        reasons.append(
            f"at the rig file's t_r = {t_r * 1e6:.4g} µs the frame's {rows} rows hold {rows * f * t_r:.3g} "
            f"flicker periods, fewer than {min_periods:g}; use a light flickering at "
            f"{min_periods / (rows * t_r):.6g} Hz or more, or frames of more rows"
        )
    kept = abs(float(np.sinc(f * t_e)))  # the share of the flicker's fundamental an exposure keeps
    if f * t_e >= 0.5 and kept < 0.1:
        averaged = "away" if kept < 1e-3 else f"down to {100 * kept:.2g} % of the flicker"
        reasons.append(
            f"t_e = {t_e * 1e6:.4g} µs spans {f * t_e:.3g} times the flicker's period, which averages its bands "
            f"{averaged} (a whole number of periods leaves none); an exposure of half a period, "
            f"{0.5e6 / f:.4g} µs, keeps 64 %"
        )
    return reasons


def check_row_time(estimated, expected, tolerance=0.01, *, raise_error=True) -> str:
    """Compare a measured row time with the stated one.

    Parameters
    ----------
    estimated, expected : float
        Measured and stated ``t_r``, seconds.
    tolerance : float
        Largest accepted relative difference ``|estimated/expected - 1|``.
    raise_error : bool
        Raise on a mismatch (default); otherwise return the message.

    Returns
    -------
    str
        A one-line report, starting with ``"t_r ok"`` or ``"t_r mismatch"``.

    Raises
    ------
    ValueError
        On a mismatch, when ``raise_error``.
    """
    estimated = check.positive("estimated", estimated, "seconds")
    expected = check.positive("expected", expected, "seconds")
    tolerance = check.non_negative("tolerance", tolerance)
    relative = estimated / expected - 1.0
    detail = (
        f"measured {estimated * 1e6:.4g} µs, rig file {expected * 1e6:.4g} µs "
        f"({relative * 100:+.2f} %, tolerance {tolerance * 100:g} %)"
    )
    if abs(relative) <= tolerance:
        return "t_r ok: " + detail
    message = (
        "t_r mismatch: " + detail + "; check the flicker frequency (lamps flicker at twice the mains "
        "frequency) and the camera's readout settings"
    )
    if raise_error:
        raise ValueError(message)
    return message
