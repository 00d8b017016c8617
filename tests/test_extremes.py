"""Numerical soundness at extreme settings: every result is checked, not only computed."""

import warnings

import numpy as np
import pytest

import rsocl
from rsocl.model import reference as ref
from rsocl.model.interpolation import interp3d
from rsocl.model.operator import RollingShutterOperator
from rsocl.model.scenes import builtin_scene
from rsocl.solver.crossval import Tuning


def _scene(rig, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.random(rig.shape)
    ramp = np.linspace(0, 1, rig.T)[:, None, None]
    return np.clip(0.6 * base + 0.4 * ramp * base[::-1], 0, 1)


def _solve(rig, scene, dtype="float32", **kw):
    g = ref.forward(rig, scene)
    kw.setdefault("iterations", 40)
    kw.setdefault("lam", 0.01)  # random test scenes are rough: regularize lightly
    kw.setdefault("tune", False)  # the solver at the extremes; tests/test_tuning.py runs the search
    res = rsocl.reconstruct(g, rig, dtype=dtype, **kw)
    assert np.all(np.isfinite(res.datacube))
    assert np.all(np.isfinite(res.history["residual"]))
    return res, g


def test_exposure_far_shorter_than_a_row(dtype):
    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=0.1 * 30e-6, t_r=30e-6)
    truth = _scene(rig)
    # psi = 0.01 here (weights of 0.1): lam and eta scale with it
    res, g = _solve(rig, truth, dtype=dtype, lam=1e-4, eta=1e-3)
    # each snapshot pixel integrates a tenth of one sub-frame: the data are still fitted
    assert res.history["residual"][-1] < 0.1


def test_exposure_longer_than_the_whole_readout_tends_to_the_pixel_mean(dtype):
    m = 10
    rig = rsocl.Rig.paper_array(4, (m, m), t_e=5 * m * 30e-6, t_r=30e-6)
    truth = np.random.default_rng(3).random((rig.T, m, m))  # flickers strongly in time
    res, g = _solve(rig, truth, dtype=dtype, iterations=60)
    # each pixel integrates 50 of the 60 sub-frames: little more than its mean is determined, and TV
    # keeps it flat in time while the data stay fitted
    assert res.history["residual"][-1] < 0.02
    core = res.datacube[m:-m]
    assert core.std(axis=0).mean() < 0.2 * truth[m:-m].std(axis=0).mean()


@pytest.mark.parametrize("dt_factor", [1.0, 1.0 + 1e-12, 25.0])
def test_very_fine_and_very_coarse_dt(dt_factor):
    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6, dt=35e-6 * dt_factor)
    truth = _scene(rig)
    # psi scales with (t_e/dt)^2: lam and eta follow it
    scale = (rig.exposure_subframes / 5.14) ** 2
    res, _ = _solve(rig, truth, lam=0.01 * scale, eta=0.2 * scale)
    assert res.datacube.shape == (rig.T, 16, 16)
    assert res.history["residual"][-1] < 0.05


@pytest.mark.parametrize("n_cameras, shape", [(1, (12, 12)), (8, (12, 12)), (4, (1, 16)), (4, (16, 1)), (2, (1, 1))])
def test_camera_count_and_degenerate_rois(n_cameras, shape, dtype):
    rig = rsocl.Rig.paper_array(n_cameras, shape, t_e=1e-4, t_r=3e-5)
    truth = _scene(rig)
    res, _ = _solve(rig, truth, dtype=dtype)
    assert res.history["residual"][-1] < 0.05


def test_single_subframe():
    rig = rsocl.Rig([rsocl.Camera(0, t_e=3e-5, t_r=3e-5)], (1, 1))
    assert rig.T == 1
    truth = np.full((1, 1, 1), 0.7)
    res, _ = _solve(rig, truth, lam=0.0, eta=0.0, iterations=3, dtype="float64")
    assert res.datacube[0, 0, 0] == pytest.approx(0.7, rel=1e-9)


@pytest.mark.slow
def test_512_roi_is_solved_or_refused_with_numbers(device):
    """A 512x512 ROI fits the device or is refused naming the sizes (the run only: no parameter search)."""
    rig = rsocl.Rig.paper_array(4, (512, 512), t_e=0.18e-3, t_r=35e-6)
    g = np.zeros((4, 512, 512), np.float32)
    try:
        res = rsocl.reconstruct(g, rig, iterations=1, tv_iterations=1, device=device, tune=False)
    except ValueError as exc:
        assert "MiB" in str(exc) and "device" in str(exc)
    else:
        assert res.datacube.shape == (rig.T, 512, 512) and not res.datacube.any()


def test_lam_to_zero_fits_the_data(dtype):
    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=1e-4, t_r=3e-5)
    res, _ = _solve(rig, _scene(rig), dtype=dtype, lam=1e-12, eta=1e-3, iterations=60)
    assert res.history["residual"][-1] < (1e-4 if dtype == "float64" else 1e-3)


def test_lam_to_infinity_gives_a_constant_datacube(dtype):
    rig = rsocl.Rig.paper_array(4, (6, 6), t_e=1e-4, t_r=3e-5)
    truth = _scene(rig)
    res, _ = _solve(
        rig,
        truth,
        dtype=dtype,
        lam=1e12,
        eta=0.2,
        iterations=10,
        tv_iterations=400,
        regularizer_options={"temporal_weight": 1.0},
    )
    cube = res.datacube
    assert cube.std() < 1e-2 * truth.std()
    assert cube.mean() == pytest.approx(truth.mean(), rel=0.1)


@pytest.mark.parametrize("temporal_weight", [0.0, 1.0, 3.0, 30.0])
def test_a_large_denoising_weight_stays_bounded(dtype, temporal_weight):
    """lam / eta = 112 on a 7-camera rig of 41x11 pixels (short exposures): with scikit-image's TV
    step the ADMM diverged here (PSNR -3 to -28 dB, values up to 167); TV's default step keeps it sound."""
    from rsocl.analysis.metrics import psnr
    from rsocl.model.scenes import builtin_scene

    rig = rsocl.Rig(
        [rsocl.Camera(angle=a, t_e=21e-6, t_r=21e-6) for a in (215, 284, 328, 248, 68, 353, 103)], shape=(41, 11)
    )
    truth = builtin_scene(rig.shape, rig.T)
    g = RollingShutterOperator(rig).forward(truth)
    res = rsocl.reconstruct(
        g,
        rig,
        lam=3.0,
        regularizer_options={"temporal_weight": temporal_weight},
        tune=False,
        iterations=200,
        dtype=dtype,
    )
    assert res.params["lam"] / res.params["eta"] > 100
    cube = res.datacube
    assert -0.5 < cube.min() and cube.max() < 1.5
    assert psnr(cube, truth, data_range=1.0) > 15.0


@pytest.mark.parametrize("eta", [0.0, 1e9])
def test_eta_extremes(eta):
    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=1e-4, t_r=3e-5)
    truth = _scene(rig)
    if eta == 0.0:
        res, _ = _solve(rig, truth, eta=eta, lam=0.01, iterations=20)
        assert res.history["residual"][-1] < 0.05
    else:
        # a huge penalty freezes theta at its start (zero): refused, naming eta, not returned as a result
        with pytest.raises(FloatingPointError, match=r"ADMM never moved: .* eta = 1e\+09 and lam = 0.01"):
            _solve(rig, truth, eta=eta, lam=0.01, iterations=20)


def test_denormal_intensities(dtype, recwarn):
    rig = rsocl.Rig.paper_array(4, (10, 10), t_e=1e-4, t_r=3e-5)
    truth = _scene(rig) * 1e-38
    res, g = _solve(rig, truth, dtype=dtype, lam=1e-40, eta=1e-40)
    assert np.abs(res.datacube).max() < 1e-30
    scale = [w for w in recwarn if "where float32 holds the squares" in str(w.message)]
    assert len(scale) == (dtype == "float32")  # float32 is told to use float64 for data this far from 1


@pytest.mark.filterwarnings("ignore:g. snapshots of camera:UserWarning")  # raw 16-bit counts, on purpose
def test_sixteen_bit_data_in_float32():
    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=1e-4, t_r=3e-5)
    scale = 65535.0 * rig.exposure_subframes
    truth = _scene(rig) * 65535.0
    g = ref.forward(rig, truth)
    assert g.max() <= scale
    res = rsocl.reconstruct(g, rig, lam=0.1 * 65535, eta=0.2, iterations=40, tune=False)
    assert np.all(np.isfinite(res.datacube))
    assert res.history["residual"][-1] < 0.1
    small = rsocl.reconstruct(g / 65535.0, rig, lam=0.1, eta=0.2, iterations=40, tune=False)
    np.testing.assert_allclose(res.datacube / 65535.0, small.datacube, atol=1e-3)


def test_all_zero_snapshots():
    rig = rsocl.Rig.paper_array(4, (8, 8), t_e=1e-4, t_r=3e-5)
    res = rsocl.reconstruct(np.zeros((4, 8, 8)), rig, iterations=5)
    assert not res.datacube.any()
    assert np.all(res.history["residual"] == 0)


def test_float32_and_float64_agree():
    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6)
    truth = _scene(rig)
    a, _ = _solve(rig, truth, dtype="float32", truth=truth)
    b, _ = _solve(rig, truth, dtype="float64", truth=truth)
    assert abs(a.history["psnr"][-1] - b.history["psnr"][-1]) < 0.01
    np.testing.assert_allclose(a.datacube, b.datacube, atol=1e-4)


def test_reduction_is_accurate_for_large_arrays(device):
    import pyopencl.array as cla

    from rsocl.device.reduction import sum_sq_diff

    n = 3_000_000
    x = np.full(n, 1.0 + 2.0**-12, np.float32)
    got = sum_sq_diff(cla.to_device(device.queue, x))
    exact = n * float(np.float32(1.0 + 2.0**-12)) ** 2
    assert got == pytest.approx(exact, rel=1e-7)


def test_nan_in_the_rig_or_data_is_refused_before_any_kernel():
    with pytest.raises(ValueError, match="t_e"):
        rsocl.Camera(0, t_e=float("nan"), t_r=1e-5)
    with pytest.raises(ValueError, match="angle"):
        rsocl.Camera(float("inf"), t_e=1e-4, t_r=1e-5)
    rig = rsocl.Rig.paper_array(4, (8, 8), t_e=1e-4, t_r=3e-5)
    bad = np.ones((4, 8, 8))
    bad[0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="NaN or inf"):
        rsocl.reconstruct(bad, rig)
    with pytest.raises(ValueError, match="NaN or inf"):
        RollingShutterOperator(rig).forward(np.full((rig.T, 8, 8), np.nan))


@pytest.mark.parametrize("projection", ["exact", "paper"])
def test_saturated_pixels_are_lower_bounds_not_values(projection):
    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6)
    base = np.random.default_rng(0).random(rig.shape) * 0.5
    truth = np.broadcast_to(base, (rig.T,) + rig.shape).copy()
    truth[7:10, 4:10, 4:10] = 3.0  # a brief flash far above full scale
    g = ref.forward(rig, truth)
    level = rig.exposure_subframes * 1.0  # full scale of a [0, 1] scene
    clipped = np.minimum(g, level)
    assert 0.05 < (g >= level).mean() < 0.2
    # from the truth, the clipped values taken as values pull the flash down; as lower bounds they do not
    kw = dict(iterations=5, projection=projection, lam=0.01, eta=0.2 if projection == "exact" else 5.0, tune=False)
    naive = rsocl.reconstruct(clipped, rig, x0=truth, **kw)
    flagged = rsocl.reconstruct(clipped, rig, x0=truth, saturation=level, **kw)
    assert flagged.params["saturated_pixels"] == int((clipped >= level).sum())
    flash = np.zeros(truth.shape, bool)
    flash[7:10, 4:10, 4:10] = True
    mse = [np.mean((r.datacube - truth)[flash] ** 2) for r in (naive, flagged)]
    assert mse[1] < 0.3 * mse[0]
    # the residual is taken over the unsaturated pixels only, and they are fitted
    assert flagged.history["residual"][-1] < 0.05


def test_saturation_that_leaves_nothing_is_refused():
    rig = rsocl.Rig.paper_array(2, (4, 4), t_e=1e-4, t_r=3e-5)
    with pytest.raises(ValueError, match="saturation"):
        rsocl.reconstruct(np.ones((2, 4, 4)), rig, saturation=0.5)
    g = np.ones((2, 4, 4))
    g[0, 0, :2] = 0.0  # only dark pixels stay below the level
    with pytest.warns(UserWarning, match=r"keeps only snapshot pixels that are 0 \(the brightest is 1\)"):
        rsocl.reconstruct(g, rig, saturation=0.5, iterations=2, tune=False)


def test_saturation_that_marks_most_samples_clipped_warns_in_snapshot_units():
    # a level given in scene units (1.0 for white) on snapshots whose white reads t_e/dt
    rig = rsocl.Rig.paper_array(2, (8, 8), t_e=1.8e-4, t_r=3.5e-5)
    truth = rsocl.builtin_scene(rig.shape, rig.T)
    g = rsocl.simulate(truth, rig)
    assert (g >= 1.0).mean() > 0.5
    with pytest.warns(
        UserWarning, match=r"saturation = 1\.0 marks \d+ % of the snapshot samples as clipped.*white scene reads 5\.14"
    ):
        rsocl.reconstruct(g, rig, saturation=1.0, iterations=2, tune=False)
    level = float(np.percentile(g, 75))  # a quarter clipped: no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rsocl.reconstruct(g, rig, saturation=level, iterations=2, tune=False)


def test_simulate_warns_when_bit_depth_saturates_most_samples():
    rig = rsocl.Rig.paper_array(2, (8, 8), t_e=1.8e-4, t_r=3.5e-5)
    raw = np.round(rsocl.builtin_scene(rig.shape, rig.T) * 4095.0)  # raw counts, not [0, 1]
    with pytest.warns(UserWarning, match=r"bit_depth = 12 saturates \d+ % .*truth peaks at 4\d{3}"):
        g = rsocl.simulate(raw, rig, bit_depth=12)
    assert np.all(g == rsocl.model.simulate.full_scale(rig))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rsocl.simulate(raw / 4095.0, rig, bit_depth=12)


def test_subframes_no_camera_samples_are_not_modelled_and_hold_the_first_solved_one(device):
    # every camera triggers 40 sub-frames late: those 40 carry no information
    cams = [rsocl.Camera(a, t_e=1e-4, t_r=3e-5, t_a=40 * 3e-5) for a in (0, 90, 180, 270)]
    rig = rsocl.Rig(cams, (10, 10))
    assert rig.sampled_range().start == 40 and rig.T == rig.sampled_range().stop
    truth = _scene(rig)  # it changes before the cameras start too
    g = ref.forward(rig, truth)
    op = RollingShutterOperator(rig, device=device, dtype="float64", subframes=rig.sampled_range())
    assert op.domain_shape == (rig.T - 40, 10, 10)
    np.testing.assert_allclose(op.forward(truth[40:]), g, rtol=1e-12)
    np.testing.assert_allclose(op.adjoint(g), ref.adjoint(rig, g)[40:], rtol=1e-12)
    res = rsocl.reconstruct(g, rig, iterations=30, lam=0.01, truth=truth, dtype="float64")
    assert res.params["solved_subframes"] == [40, rig.T]
    np.testing.assert_array_equal(res.datacube[:40], np.broadcast_to(res.datacube[40], (40, 10, 10)))
    assert res.datacube[40].any()
    # the history's PSNR is the returned datacube's, held sub-frames included
    assert res.history["psnr"][-1] == pytest.approx(rsocl.analysis.metrics.psnr(res.datacube, truth), abs=1e-6)
    assert res.history["residual"][-1] < 0.05
    # a batch of two sets: each set's history is its datacube's PSNR
    sets = np.stack([g, ref.forward(rig, truth[::-1].copy())])
    truths = np.stack([truth, truth[::-1]])
    batch = rsocl.reconstruct(sets, rig, iterations=30, lam=0.01, truth=truths, dtype="float64")
    for s in range(2):
        np.testing.assert_array_equal(batch.datacube[s, :40], np.broadcast_to(batch.datacube[s, 40], (40, 10, 10)))
        assert batch.history["psnr"][-1, s] == pytest.approx(
            rsocl.analysis.metrics.psnr(batch.datacube[s], truths[s]), abs=1e-6
        )


def test_gap_in_float32_on_nearly_singular_blocks_stays_sound():
    """GAP (eta = 0) divides the data residual by the eigenvalues of each pixel's camera block. Here
    (6 cameras at scattered angles, exposure shorter than a row's time) some lie 1e-10 to 1e-8 below
    their block's largest: kept in float32, where the residual carries 1e-7 rounding, they made the
    data step diverge within 4 iterations even with the identity as denoiser (residual 1e4)."""
    angles = (210.9, 80.6, 229.7, 279.2, 268.3, 55.7)
    rig = rsocl.Rig([rsocl.Camera(a, t_e=0.848 * 35e-6, t_r=35e-6) for a in angles], (30, 5))
    g = ref.forward(rig, builtin_scene(rig.shape, rig.T, dtype=np.float64))
    runs = {
        dtype: rsocl.reconstruct(g, rig, iterations=30, eta=0.0, dtype=dtype, tune=False, tv_iterations=1)
        for dtype in ("float32", "float64")
    }
    for res in runs.values():  # TV of one iteration is the identity: f = P(f), a projection
        assert res.history["residual"].max() < 1e-3 and np.abs(res.datacube).max() < 1.5
    # float32 leaves out the directions below 1e-6 of their block's largest (float64 those below
    # 1e-10): the two agree except on the few voxels such directions reach
    close = np.isclose(runs["float32"].datacube, runs["float64"].datacube, atol=1e-3)
    assert close.mean() > 0.99
    res = rsocl.reconstruct(g, rig, iterations=30, eta=0.0, tune=False)
    assert res.history["residual"][-1] < 0.2 and np.abs(res.datacube).max() < 1.5


def test_a_mistyped_call_is_a_value_error_naming_the_argument():
    rig = rsocl.Rig.paper_array(4, (8, 8), t_e=1.8e-4, t_r=3.5e-5)
    g = ref.forward(rig, _scene(rig))
    with pytest.raises(ValueError, match="rig must be an rsocl.Rig, got NoneType"):
        interp3d(g, None)
    with pytest.raises(ValueError, match="g contains 256 NaN"):
        interp3d(np.full(g.shape, np.nan), rig)
    with pytest.raises(ValueError, match=r"cameras must be a list of Camera, got one Camera; pass \[camera\]"):
        rsocl.Rig(rsocl.Camera(0, t_e=1e-4, t_r=1e-5), (5, 5))
    with pytest.raises(ValueError, match="cameras must be a list of Camera, got NoneType"):
        rsocl.Rig(None, (5, 5))
    with pytest.raises(ValueError, match="dt = 10000000000.0 s is so long .* that the rig has no sub-frame"):
        rsocl.Rig([rsocl.Camera(0, t_e=1.8e-4, t_r=3.5e-5)], (8, 8), dt=1e10)
    # a 0-d array is its one value
    assert rsocl.reconstruct(g, rig, lam=np.array(0.1), iterations=2, tune=False).params["lam"] == pytest.approx(0.1)
    # an earlier choice of TV's options does not apply to another regularizer: said before any run
    tuning = Tuning.from_params(rsocl.reconstruct(g, rig, iterations=2).params["tuning"])
    with pytest.raises(ValueError, match=r"tune: the earlier Tuning chose \['temporal_weight'\], options 'wavelet'"):
        rsocl.reconstruct(g, rig, "wavelet", tune=tuning)
