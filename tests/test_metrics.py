import math

import numpy as np
import pytest
from skimage.metrics import structural_similarity

from rsocl.analysis.metrics import default_data_range, mse, psnr, ssim


def _checker_noise(shape, sigma):
    """+-sigma in a checkerboard: MSE is exactly sigma**2."""
    sign = np.indices(shape).sum(axis=0) % 2 * 2 - 1
    return sigma * sign


@pytest.fixture
def truth():
    return np.random.default_rng(1).uniform(0.0, 1.0, size=(4, 16, 20))


# ---------------------------------------------------------------------- PSNR
def test_psnr_closed_form_with_given_range(truth):
    sigma = 0.1
    estimate = truth + _checker_noise(truth.shape, sigma)
    assert mse(estimate, truth) == pytest.approx(sigma**2, rel=1e-12)
    assert psnr(estimate, truth, data_range=1.0) == pytest.approx(-20 * math.log10(sigma), rel=1e-12)
    assert psnr(estimate, truth, data_range=2.0) == pytest.approx(10 * math.log10(4 / sigma**2), rel=1e-12)


def test_psnr_default_range_is_one_inside_unit_interval():
    truth = np.linspace(0.2, 0.7, 3 * 8 * 8).reshape(3, 8, 8)
    sigma = 0.01
    estimate = truth + _checker_noise(truth.shape, sigma)
    expected = 10 * math.log10(1.0 / sigma**2)
    assert psnr(estimate, truth) == pytest.approx(expected, rel=1e-9)


def test_psnr_default_range_is_truth_peak_to_peak_outside_unit_interval():
    truth = np.linspace(10.0, 60.0, 3 * 8 * 8).reshape(3, 8, 8)
    sigma = 0.5
    estimate = truth + _checker_noise(truth.shape, sigma)
    expected = 10 * math.log10(50.0**2 / sigma**2)
    assert psnr(estimate, truth) == pytest.approx(expected, rel=1e-9)


def test_psnr_constant_truth_uses_unit_range():
    truth = np.full((2, 5, 5), 0.3)
    estimate = truth + 0.05
    assert psnr(estimate, truth) == pytest.approx(10 * math.log10(1 / 0.05**2), rel=1e-9)


def test_psnr_identical_is_inf(truth):
    assert psnr(truth, truth) == math.inf


def test_psnr_float32_accumulates_in_float64():
    n = 4_000_000
    truth = np.zeros(n, dtype=np.float32)
    truth[0] = 1.0
    estimate = np.full(n, 1e-3, dtype=np.float32)
    estimate[0] = 1.0 + np.float32(1e-3)
    exact_mse = float(np.float32(1e-3)) ** 2
    assert mse(estimate, truth) == pytest.approx(exact_mse, rel=1e-9)  # float32 sums are off by ~1e-7
    assert psnr(estimate, truth, data_range=1.0) == pytest.approx(-10 * math.log10(exact_mse), rel=1e-9)


def test_psnr_rejects_bad_input(truth):
    with pytest.raises(ValueError, match="shape"):
        psnr(truth[:, :-1], truth)
    with pytest.raises(ValueError, match="data_range"):
        psnr(truth, truth, data_range=0.0)
    with pytest.raises(ValueError, match="data_range"):
        psnr(truth, truth, data_range=-1)
    bad = truth.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="estimate"):
        psnr(bad, truth)
    with pytest.raises(ValueError, match="empty"):
        psnr(np.zeros((0, 3)), np.zeros((0, 3)))


# ---------------------------------------------------------------------- SSIM
def test_ssim_identical_is_one(truth):
    mean, per = ssim(truth, truth)
    assert per.shape == (truth.shape[0],)
    assert per.dtype == np.float64
    np.testing.assert_allclose(per, 1.0)
    assert mean == pytest.approx(1.0)


def test_ssim_matches_skimage_per_subframe_with_global_range(truth):
    rng = np.random.default_rng(2)
    estimate = truth + rng.normal(0, 0.1, truth.shape)
    peak = default_data_range(truth)
    mean, per = ssim(estimate, truth)
    for s in range(truth.shape[0]):
        expected = structural_similarity(estimate[s], truth[s], data_range=peak)
        assert per[s] == pytest.approx(expected, rel=1e-12)
    assert mean == pytest.approx(per.mean(), rel=1e-12)
    # an explicit range is honoured and changes the value
    _, per2 = ssim(estimate, truth, data_range=10.0)
    assert per2[0] == pytest.approx(structural_similarity(estimate[0], truth[0], data_range=10.0))
    assert per2[0] != pytest.approx(per[0])


def test_ssim_decreases_with_noise(truth):
    rng = np.random.default_rng(3)
    noise = rng.normal(0, 1, truth.shape)
    low, _ = ssim(truth + 0.02 * noise, truth)
    high, _ = ssim(truth + 0.2 * noise, truth)
    assert 1.0 > low > high


@pytest.mark.parametrize("shape, win", [((5, 9), 5), ((6, 6), 5), ((4, 30), 3), ((3, 3), 3)])
def test_ssim_small_frames_shrink_window(shape, win):
    rng = np.random.default_rng(4)
    truth = rng.uniform(size=(2,) + shape)
    estimate = truth + rng.normal(0, 0.05, truth.shape)
    _, per = ssim(estimate, truth, data_range=1.0)
    expected = structural_similarity(estimate[1], truth[1], data_range=1.0, win_size=win)
    assert per[1] == pytest.approx(expected, rel=1e-12)


def test_ssim_tiny_frames_give_nan():
    truth = np.ones((3, 2, 8))
    mean, per = ssim(truth, truth)
    assert math.isnan(mean)
    assert per.shape == (3,) and np.all(np.isnan(per))


def test_ssim_accepts_one_image_and_rejects_mismatch(truth):
    mean, per = ssim(truth[0], truth[0])
    assert per.shape == (1,) and mean == pytest.approx(1.0)
    with pytest.raises(ValueError, match="shape"):
        ssim(truth, truth[:2])
    with pytest.raises(ValueError, match="truth"):
        ssim(np.zeros((2, 2, 8, 8)), np.zeros((2, 2, 8, 8)))
