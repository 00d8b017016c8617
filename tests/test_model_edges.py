"""Extreme settings of the model and the solver's entry points: a TV weight too small for the device's
real type, ``lam / eta`` overflowing, ``binary`` windows that hold no sub-frame start, and ``simulate``
on a rig or a scene it cannot represent."""

import numpy as np
import pytest

import rsocl
from rsocl.model import reference as ref
from rsocl.model.curvature import full_scales
from rsocl.solver.request import make_request
from rsocl_plugins.tv import TV

T_R = 35e-6

#: The smallest positive weights whose ``tau / weight`` overflows each real type.
TINY = {"float32": 1e-41, "float64": 1e-320}

#: The TV's paths: the plain one in two launches per iteration, in one, in one per two, and the fused one.
PATHS = [dict(fused=0, one_launch=0), dict(fused=0, one_launch=1), dict(fused=0, one_launch=2), dict(fused=3)]


# ---------------------------------------------------------------- TV weight too small for tau / weight
@pytest.mark.parametrize("options", PATHS, ids=["plain0", "plain1", "plain2", "fused"])
def test_tv_with_a_tiny_weight_is_nearly_the_identity(device, dtype, rng, options):
    import pyopencl.array as cla

    x = rng.random((6, 5, 7))
    xd = cla.to_device(device.queue, x.astype(dtype))
    tv = TV(iterations=5, **options)
    y = tv.denoise(xd, TINY[dtype]).get()
    assert np.isfinite(y).all()
    np.testing.assert_allclose(y, x.astype(dtype), atol=1e-6)
    assert options.get("fused", 0) == 0 or tv.fused_plan(xd) is not None  # the fused path ran


def test_tv_steps_clip_tau_over_weight_and_keep_ordinary_weights(device, dtype):
    tv = TV(temporal_weight=2.0)
    weights = np.array([0.0, 1e-3, 0.1, 7.5, TINY[dtype]])
    steps = tv._steps(device.queue, weights, dtype).get().reshape(-1, 3)
    tau = tv.step / (2.0 * (2.0 + 2.0**2))
    ordinary = np.stack([np.full(3, tau), tau / weights[1:4], np.full(3, 2.0)], axis=1).astype(dtype)
    np.testing.assert_array_equal(steps[1:4], ordinary)  # bit for bit
    np.testing.assert_array_equal(steps[0], np.array([0.0, 0.0, 2.0], dtype))
    assert steps[4, 1] == np.finfo(dtype).max


@pytest.mark.parametrize("lam, eta", [(1e-44, 0.2), (1e-40, 0.0), (1e-42, 20.0)])
def test_reconstruct_with_a_tiny_denoiser_weight_is_finite(rng, lam, eta):
    rig = rsocl.Rig.paper_array(4, shape=(8, 8), t_e=180e-6, t_r=T_R)
    g = rsocl.simulate(rng.random((rig.T,) + rig.shape), rig)
    for options in ({}, {"fused": 3}):
        result = rsocl.reconstruct(
            g, rig, iterations=3, lam=lam, eta=eta, tune=False, regularizer_options=options, dtype="float32"
        )
        assert np.isfinite(result.datacube).all(), options


# ---------------------------------------------------------------- lam / eta overflowing
def test_lam_over_eta_overflowing_is_refused_naming_lam_and_eta():
    rig = rsocl.Rig.paper_array(4, shape=(8, 8), t_e=180e-6, t_r=T_R)
    with pytest.raises(ValueError, match=r"lam / eta overflows \(lam = 0.1, eta = 1e-310\): eta must be 0 \(GAP\)"):
        make_request(rig, lam=0.1, eta=1e-310, tune=False)
    with pytest.raises(ValueError, match=r"lam / eta of set 1 overflows.*at least lam / 1.8e\+308"):
        make_request(rig, sets=2, lam=[0.1, 0.1], eta=[0.2, 1e-310], tune=False)
    with pytest.raises(ValueError, match=r"lam / eta overflows"):  # the default lam, given eta
        make_request(rig, eta=1e-310)
    # the ends that are fine: GAP (eta = 0), lam = 0, a ratio just inside float64
    make_request(rig, sets=3, lam=[0.1, 0.0, 0.1], eta=[0.0, 1e-310, 1e-300], tune=False)


def test_lam_over_eta_is_checked_before_any_device_work(monkeypatch):
    import rsocl.solver.pipeline as pipeline

    def staged(*args, **kwargs):
        raise AssertionError("staged before the check")

    monkeypatch.setattr(pipeline, "stage_on_device", staged)
    rig = rsocl.Rig.paper_array(4, shape=(8, 8), t_e=180e-6, t_r=T_R)
    g = np.zeros((2, rig.n_channels) + rig.shape)
    with pytest.raises(ValueError, match="lam / eta of set 1 overflows"):
        rsocl.reconstruct(g, rig, lam=0.1, eta=[0.2, 1e-310], tune=False, iterations=2)


def test_the_searchs_largest_lam_candidate_over_eta_is_checked_before_any_device_work(monkeypatch):
    # the default lam passes the check, 3 times it (the search's largest candidate) overflows
    import rsocl.solver.pipeline as pipeline

    def staged(*args, **kwargs):
        raise AssertionError("staged before the check")

    monkeypatch.setattr(pipeline, "stage_on_device", staged)
    rig = rsocl.Rig.paper_array(4, shape=(8, 8), t_e=180e-6, t_r=T_R)
    lam = make_request(rig, eta=1.0, tune=False).settled(None)[1].lam
    top = float(np.finfo(np.float64).max)
    eta = 2 * lam / top  # lam / eta = top / 2
    make_request(rig, eta=eta, tune=False)
    g = np.zeros((rig.n_channels,) + rig.shape)
    with pytest.raises(ValueError, match=r"lam / eta overflows \(lam \(the search's largest candidate\) = "):
        rsocl.reconstruct(g, rig, eta=eta, iterations=2)


# ---------------------------------------------------------------- binary windows holding no sub-frame start
def _two_camera_rig():
    """Rows 0..1 of a long exposure (weights on 0..4), and a camera whose windows [8.2, 8.7], [9.2, 9.7]
    hold no sub-frame start."""
    cams = [rsocl.Camera(0, t_e=3 * T_R, t_r=T_R), rsocl.Camera(0, t_e=0.5 * T_R, t_r=T_R, t_a=8.2 * T_R)]
    return rsocl.Rig(cams, (2, 1), mask="binary")


def _from_weights(rig):
    """``(cameras per sub-frame, T_se, sampled range)`` counted from the model's weights."""
    W = ref.weights(rig)
    channel_camera = np.array([c for c, _ in rig.channels])
    counts = sum((W[channel_camera == c] > 0).any(axis=(0, 2, 3)).astype(int) for c in range(rig.C))
    ok = np.nonzero(counts >= rig.min_cameras)[0]
    used = np.nonzero(W.sum(axis=(0, 2, 3)) > 0)[0]
    return counts, ok[-1] - ok[0] + 1, slice(int(used[0]), int(used[-1]) + 1)


RIGS = {
    "two-cameras": _two_camera_rig,
    "paper8-binary-te-half-dt": lambda: rsocl.Rig.paper_array(8, (8, 8), 0.5 * T_R, T_R, dt=1.5 * T_R, mask="binary"),
    "paper4-binary": lambda: rsocl.Rig.paper_array(4, (6, 5), 180e-6, T_R, mask="binary"),
    "paper4-exact-te-half-dt": lambda: rsocl.Rig.paper_array(4, (6, 5), 0.5 * T_R, T_R, dt=1.5 * T_R),
}


@pytest.mark.parametrize("name", sorted(RIGS))
def test_counts_follow_the_weights(name):
    rig = RIGS[name]()
    counts, T_se, used = _from_weights(rig)
    np.testing.assert_array_equal(rig.cameras_per_subframe(), counts)
    assert rig.T_se == T_se and rig.compression_ratio == T_se / rig.n_channels
    assert rig.sampled_range() == used
    first, last = rig.sampled_window()
    assert first.min() >= 0 and first.max() <= rig.T - 1
    np.testing.assert_array_equal(last - first + 1, (ref.weights(rig) > 0).sum(axis=1))


def test_empty_binary_windows_count_for_nothing():
    rig = _two_camera_rig()
    assert rig.cameras_per_subframe().tolist() == [1, 1, 1, 1, 1, 0, 0, 0, 0, 0]
    assert rig.T_se == 5 and rig.kept_subframes() == slice(0, 5) and rig.compression_ratio == 2.5
    assert rig.effective_fps(67) == pytest.approx(335.0)
    assert rig.sampled_range() == slice(0, 5)
    first, last = rig.sampled_window()
    assert (last[1] == first[1] - 1).all()  # the empty camera's windows
    paper = RIGS["paper8-binary-te-half-dt"]()
    assert paper.T == 7 and paper.T_se == 6 and paper.cameras_per_subframe()[-1] == 0


def test_a_blocks_sampled_range_leaves_out_its_empty_windows():
    # rows y: [y, y + 2] (sub-frames y .. y + 2); [5.2 + 1.5 y, 5.6 + 1.5 y]: empty for rows 0 and 2
    cams = [
        rsocl.Camera(0, t_e=2 * T_R, t_r=T_R),
        rsocl.Camera(0, t_e=0.4 * T_R, t_r=1.5 * T_R, t_a=5.2 * T_R),
    ]
    rig = rsocl.Rig(cams, (4, 3), dt=T_R, mask="binary")
    expected = {
        (0, 0, 4, 3): slice(0, 11),
        (0, 0, 3, 3): slice(0, 8),
        (2, 1, 1, 2): slice(2, 5),
        (0, 0, 1, 1): slice(0, 3),
    }
    for roi, span in expected.items():
        sub = rig.crop(roi)
        assert rig.sampled_range(roi) == sub.sampled_range() == _from_weights(sub)[2] == span, roi


def test_a_binary_full_scale_counts_only_the_rigs_sub_frames():
    # one pixel exposed over [0, 3]: T = 3, weights on 0, 1, 2 (sub-frame 3 is not in the rig)
    rig = rsocl.Rig([rsocl.Camera(0, t_e=3 * T_R, t_r=T_R)], (1, 1), mask="binary")
    assert rig.T == 3 and ref.weights(rig).sum() == 3
    assert full_scales(rig).tolist() == [3.0]


# ---------------------------------------------------------------- simulate on a rig or scene it cannot represent
@pytest.mark.parametrize("noise", [dict(noise="poisson", photons=100), dict(bit_depth=8), {}])
def test_simulate_refuses_a_rig_without_weights(noise):
    rig = rsocl.Rig([rsocl.Camera(0, t_e=0.3 * T_R, t_r=T_R, t_a=0.2 * T_R)], (2, 2), mask="binary")
    with pytest.raises(ValueError, match="the rig's exposure windows hold no sub-frame"):
        rsocl.simulate(np.ones((rig.T,) + rig.shape), rig, **noise)


def test_simulate_refuses_a_truth_beyond_the_dtype(has_fp64):
    rig = rsocl.Rig.paper_array(4, (2, 2), t_e=180e-6, t_r=T_R)
    truth = np.full((rig.T, 2, 2), 1e39)
    with pytest.raises(ValueError, match=r"truth holds values up to 1e\+39, beyond float32's largest.*float64"):
        rsocl.simulate(truth, rig, dtype="float32")
    if has_fp64:
        assert np.isfinite(rsocl.simulate(truth, rig, dtype="float64")).all()


def test_simulate_refuses_the_settings_of_another_noise_model_and_a_too_bright_poisson_mean():
    rig = rsocl.Rig.paper_array(2, shape=(4, 4), t_e=180e-6, t_r=T_R)
    truth = np.ones((rig.T,) + rig.shape)
    with pytest.raises(ValueError, match=r"sigma applies to noise='gaussian' only, got sigma = 0.5 with noise = 'n"):
        rsocl.simulate(truth, rig, sigma=0.5)
    with pytest.raises(ValueError, match=r"photons applies to noise='poisson' only"):
        rsocl.simulate(truth, rig, noise="gaussian", sigma=0.1, photons=10)
    with pytest.raises(ValueError, match=r"photons must be at most 5e\+16 for this scene.*20x full scale"):
        rsocl.simulate(20 * truth, rig, noise="poisson", photons=1e17)
    assert rsocl.simulate(truth, rig, sigma=0.0).shape == (2, 4, 4)  # sigma 0 is no setting
