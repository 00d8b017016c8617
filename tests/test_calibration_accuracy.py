"""Calibration measured against known answers, on inputs built independently of the code under test.

The rolling-shutter frames here integrate a flickering light over each row's exposure (a row starts at
``r * t_r`` and integrates for ``t_e``); the flat fields are raw levels of known gains, clipped at the
sensor's top level; the marker frames are flat discs, area-sampled through a known homography.
"""

import numpy as np
import pytest

from rsocl.hardware import calibration as cal

T_R = 20e-6  # row time, seconds


def rolling_shutter_frame(flicker_hz, t_e, *, rows=480, cols=64, depth=0.8, falloff=0.0, noise=0.0, seed=0):
    """A frame of an evenly lit scene under ``1 + depth * sin(2 pi f t)``: row ``r`` integrates the light
    over ``[r t_r, r t_r + t_e]`` (exactly: the sine's antiderivative), times an illumination falling off
    by ``falloff`` towards the top and bottom rows."""
    start = 1.234e-3 + np.arange(rows) * T_R
    w = 2 * np.pi * flicker_hz
    light = 1 + depth * (np.cos(w * start) - np.cos(w * (start + t_e))) / (w * t_e)
    x = np.linspace(-1.0, 1.0, rows)
    profile = 0.5 * light * (1 - falloff * x**2)
    frame = np.repeat(profile[:, None], cols, axis=1)
    return frame + noise * np.random.default_rng(seed).standard_normal(frame.shape)


@pytest.mark.parametrize(
    "depth, periods, falloff, within",
    [(0.1, 3.84, 0.1, 0.003), (0.05, 3.84, 0.3, 0.003), (0.02, 12.0, 0.3, 0.003), (0.8, 3.84, 0.3, 0.003)]
    + [(0.1, 2.06, 0.1, 0.01)],  # two periods, the fewest measured: within the 1 % of --tolerance
)
def test_row_time_is_not_biased_by_an_illumination_falling_off_along_the_rows(depth, periods, falloff, within):
    # a light that rises and falls over the rows (vignetting, a lamp's beam) is not a straight trend
    hz = periods / (480 * T_R)
    frame = rolling_shutter_frame(hz, 20e-6, depth=depth, falloff=falloff, noise=0.01)
    assert cal.estimate_row_time(frame, hz) == pytest.approx(T_R, rel=within)


@pytest.mark.parametrize("bits", [None, 8, 12])
@pytest.mark.parametrize("periods_exposed", [1, 2, 3])
def test_an_exposure_of_whole_flicker_periods_has_no_band_and_is_refused(periods_exposed, bits):
    # every row integrates whole periods: the rows are alike (to rounding), and no t_r may come out
    hz = 1250.0
    frame = rolling_shutter_frame(hz, periods_exposed / hz)
    if bits is not None:
        frame = np.round(frame * (2**bits - 1) * 0.98)  # raw levels: every row the same
    with pytest.raises(ValueError, match="no periodic component|no significant band"):
        cal.estimate_row_time(frame, hz)
