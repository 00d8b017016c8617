"""ADMM on the device against the NumPy reference ADMM, and reconstruct()'s contract."""

import warnings

import numpy as np
import pytest
from same_arithmetic import assert_same_arithmetic

import rsocl
from rsocl.model import reference as ref
from rsocl.model.scenes import builtin_scene
from rsocl_plugins.tv import STEP


@pytest.fixture(scope="module")
def problem():
    rig = rsocl.Rig.paper_array(4, (10, 9), t_e=1e-4, t_r=3e-5)
    rng = np.random.default_rng(5)
    truth = rng.random((rig.T,) + rig.shape)
    return rig, truth, ref.forward(rig, truth)


# projection="paper" at small eta is unstable on these random cubes (the run warns): the test
# compares the maths, not the result
@pytest.mark.filterwarnings("ignore:ADMM ended unstable:RuntimeWarning")
@pytest.mark.parametrize("projection", ["exact", "paper"])
@pytest.mark.parametrize("eta", [0.3, 0.0])
def test_device_admm_matches_reference(problem, dtype, projection, eta):
    rig, truth, g = problem
    kw = dict(iterations=6, lam=0.05, eta=eta, tv_iterations=4, projection=projection)
    got = rsocl.reconstruct(g, rig, dtype=dtype, regularizer_options={"temporal_weight": 2.5}, **kw).datacube
    want = ref.admm(rig, g, temporal_weight=2.5, step=STEP, **kw)
    tol = 2e-4 if dtype == "float32" else 1e-10
    np.testing.assert_allclose(got, want, atol=tol * np.abs(want).max())


def test_reference_exact_step_solves_the_data_term(problem):
    rig, truth, g = problem
    # eta = 0 (GAP): f = v + Hᵀ (H Hᵀ)⁺ (g - H v) reproduces g exactly wherever it can
    f = ref.project(rig, np.zeros_like(truth), g, eta=0.0)
    np.testing.assert_allclose(ref.forward(rig, f), g, atol=1e-9)


def test_history_and_psnr_improve(problem):
    rig, truth, g = problem
    res = rsocl.reconstruct(g, rig, iterations=25, lam=0.02, eta=0.2, truth=truth, tune=False)
    h = res.history
    assert set(h) == {"residual", "time", "psnr"} and len(h["residual"]) == 25 == res.iterations
    assert np.all(np.diff(h["time"]) >= 0)
    assert h["residual"][-1] < h["residual"][0]
    assert h["psnr"][-1] > h["psnr"][0]
    # the recorded residual is the real one
    r = np.linalg.norm(ref.forward(rig, res.datacube) - g) / np.linalg.norm(g)
    assert h["residual"][-1] == pytest.approx(r, rel=1e-3)
    # and PSNR is rsocl.analysis.metrics.psnr of the returned datacube
    assert h["psnr"][-1] == pytest.approx(rsocl.analysis.metrics.psnr(res.datacube, truth), abs=1e-3)
    assert res.params["regularizer"] == "tv" and res.params["projection"] == "exact"
    assert res.trimmed.shape[0] == rig.T_se


def test_recovers_a_scene_better_than_backprojection():
    from rsocl.model.scenes import builtin_scene

    rig = rsocl.Rig.paper_array(4, (24, 24), t_e=0.18e-3, t_r=35e-6)
    truth = builtin_scene(rig.shape, rig.T)
    g = rsocl.RollingShutterOperator(rig).forward(truth)
    res = rsocl.reconstruct(g, rig, iterations=60, truth=truth)
    # a still image: each pixel's mean intensity over the exposure, repeated in time
    still = np.broadcast_to(g.mean(axis=0) / rig.exposure_subframes, truth.shape)
    assert res.history["psnr"][-1] > rsocl.analysis.metrics.psnr(still, truth) + 3
    assert res.history["psnr"][-1] > 18


def test_callback_tol_and_x0(problem):
    rig, truth, g = problem
    seen = []

    def stop_at_three(it, residual, theta):
        seen.append((it, residual, theta.shape))
        return it == 2

    res = rsocl.reconstruct(g, rig, iterations=50, callback=stop_at_three)
    assert res.iterations == 3 and [s[0] for s in seen] == [0, 1, 2]
    assert seen[0][2] == (rig.T,) + rig.shape
    res = rsocl.reconstruct(g, rig, iterations=500, tol=1e-3, tune=False)
    assert 1 < res.iterations < 500
    # starting from the truth with no regularization keeps the data term at zero
    res = rsocl.reconstruct(g, rig, iterations=2, lam=0.0, eta=0.5, x0=truth, dtype="float64")
    assert res.history["residual"][0] < 1e-6


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(iterations=0), "iterations"),
        (dict(lam=-1), "lam"),
        (dict(eta=float("nan")), "eta"),
        (dict(projection="diag"), "projection"),
        (dict(tv_iterations=0), "tv_iterations"),
        (dict(tol=-1), "tol"),
        (dict(regularizer="nope"), "available"),
        (dict(callback=3), "callback"),
        (dict(dtype="float16"), "dtype"),
        (dict(dtype="foo"), "dtype must be 'float32' or 'float64', got 'foo'"),
        (dict(dtype=None), "dtype must be 'float32' or 'float64', got None"),
        (dict(regularizer_options={"bogus": 1}), "unknown option"),
    ],
)
def test_bad_arguments_are_named(problem, kwargs, match):
    rig, truth, g = problem
    with pytest.raises(ValueError, match=match):
        rsocl.reconstruct(g, rig, **kwargs)


def test_bad_data_is_refused_before_any_kernel(problem):
    rig, truth, g = problem
    bad = g.copy()
    bad[1, 2, 3] = np.nan
    with pytest.raises(ValueError, match="g contains 1 NaN"):
        rsocl.reconstruct(bad, rig)
    with pytest.raises(ValueError, match="g must have shape"):
        rsocl.reconstruct(g[:3], rig)
    with pytest.raises(ValueError, match="x0 must have shape"):
        rsocl.reconstruct(g, rig, x0=np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="truth contains"):
        rsocl.reconstruct(g, rig, truth=np.full((rig.T,) + rig.shape, np.inf))


def test_tv_iterations_do_not_silently_miss_an_instance(problem):
    from rsocl_plugins.dct import DCT
    from rsocl_plugins.tv import TV

    rig, truth, g = problem
    with pytest.raises(ValueError, match="tv_iterations applies to a regularizer given by name"):
        rsocl.reconstruct(g, rig, regularizer=TV(iterations=10), tv_iterations=3, tune=False)
    with pytest.raises(ValueError, match="tv_iterations applies to a regularizer given by name"):
        rsocl.reconstruct(g, rig, regularizer=DCT(), tv_iterations=3, tune=False)
    res = rsocl.reconstruct(g, rig, regularizer=TV(iterations=4), tv_iterations=4, iterations=2, tune=False)
    assert res.params["regularizer_options"]["iterations"] == 4


@pytest.mark.filterwarnings("ignore:g. snapshots of camera:UserWarning")  # far off scale, on purpose
def test_values_beyond_float32_are_refused_by_name(problem):
    rig, truth, g = problem
    with pytest.raises(ValueError, match=r"g holds values up to 1e\+39, beyond float32's largest.*float64"):
        rsocl.reconstruct(g * 0 + 1e39, rig, tune=False)
    with pytest.raises(ValueError, match="x0 holds values"):
        rsocl.reconstruct(g, rig, x0=np.full((rig.T,) + rig.shape, -1e39), tune=False)
    res = rsocl.reconstruct(g * 1e30, rig, iterations=2, tune=False, dtype="float64")
    assert np.isfinite(res.datacube).all()


def test_paper_projection_divergence_is_reported():
    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6)
    g = np.ones((4, 16, 16)) * 3.0
    with pytest.raises(FloatingPointError, match="projection='paper'"):
        rsocl.reconstruct(g, rig, iterations=300, lam=1e3, eta=1e-3, projection="paper", tune=False)


def test_a_finite_blow_up_is_reported_as_divergence():
    # the paper's diagonal step with 8 cameras at the default eta grows without bound but stays finite
    rig = rsocl.Rig.paper_array(8, (16, 16), t_e=0.18e-3, t_r=35e-6)
    g = ref.forward(rig, builtin_scene(rig.shape, rig.T, dtype=np.float64))
    with pytest.raises(FloatingPointError, match=r"diverged at iteration \d+: .*1000 times.*projection='paper'"):
        rsocl.reconstruct(g, rig, iterations=40, projection="paper", tune=False)
    batch = np.stack([g, g])
    with pytest.raises(FloatingPointError, match=r"in set\(s\) \[1\]"):
        rsocl.reconstruct(batch, rig, iterations=40, projection="paper", eta=[50.0, 0.2], tune=False)
    assert np.isfinite(rsocl.reconstruct(g, rig, iterations=40, tune=False).datacube).all()


def test_a_bounded_unstable_run_gets_a_warning():
    # the paper's diagonal step at eta = 1e-3 with 4 cameras: the residual climbs from 0.35 to
    # about 240 and stays there (below the 1000x of a divergence), the values reach hundreds
    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=5 * 35e-6, t_r=35e-6)
    g = ref.forward(rig, builtin_scene(rig.shape, rig.T, dtype=np.float64))
    said = r"ended unstable: the last residual \d[\d.e+]* is above 1.*projection='paper'"
    with pytest.warns(RuntimeWarning, match=said):
        res = rsocl.reconstruct(g, rig, iterations=30, eta=1e-3, projection="paper", tune=False)
    assert res.history["residual"][-1] > 10 and np.isfinite(res.datacube).all()
    with pytest.warns(RuntimeWarning, match=r"ended unstable in set\(s\) \[0\]"):
        rsocl.reconstruct(np.stack([g, g]), rig, iterations=30, eta=[1e-3, 0.2], projection="paper", tune=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rsocl.reconstruct(g, rig, iterations=30, projection="paper", tune=False)
        rsocl.reconstruct(g, rig, iterations=30, eta=1e-3, tune=False)


def test_a_start_far_from_the_data_is_not_taken_for_divergence(problem):
    rig, truth, g = problem
    res = rsocl.reconstruct(g, rig, iterations=20, x0=1e5 * np.ones((rig.T,) + rig.shape), tune=False)
    assert res.history["residual"][0] > 1e3 and res.history["residual"][-1] < res.history["residual"][0]


def test_regularizer_recommendations_fill_unset_lam_and_eta(problem):
    from rsocl.model.curvature import default_scale

    rig, truth, g = problem
    scale = default_scale(rig)  # t_e/dt = 3.3 here: the defaults scale with psi
    assert 0.5 < scale < 0.7
    res = rsocl.reconstruct(g, rig, regularizer="dct", iterations=2, tune=False)
    assert (res.params["lam"], res.params["eta"]) == (pytest.approx(0.3 * scale), pytest.approx(0.2 * scale))
    res = rsocl.reconstruct(g, rig, regularizer="dct", iterations=2, lam=0.05)
    assert res.params["lam"] == 0.05
    res = rsocl.reconstruct(g, rig, iterations=2, tune=False)
    assert (res.params["lam"], res.params["eta"]) == (pytest.approx(0.1 * scale), pytest.approx(0.2 * scale))


def test_pipelined_residuals_equal_the_waited_ones(device, problem):
    # Without callback, truth or tol, reconstruct reads each residual while the device runs
    # the next iteration; the history must be the one of the run that waits every time.
    rig, truth, g = problem
    kw = dict(iterations=7, lam=0.05, eta=0.3, tv_iterations=3, dtype="float64", tune=False)
    fast = rsocl.reconstruct(g, rig, **kw)
    seen = []
    waited = rsocl.reconstruct(g, rig, callback=lambda it, r, theta: seen.append(it) and False, **kw)
    assert seen == list(range(7))
    assert len(fast.history["residual"]) == len(fast.history["time"]) == 7
    assert_same_arithmetic(fast.history["residual"], waited.history["residual"], device)
    assert_same_arithmetic(fast.datacube, waited.datacube, device)
    assert np.all(np.diff(fast.history["time"]) >= 0)


@pytest.mark.parametrize(
    "sequence",
    [
        [0.5, 0.4, 0.45, 300.0, 0.3, 600.0],  # growth beyond GROWTH times max(smallest, 1) at 600
        [0.5, float("nan")],
        [float("nan")],
        [float("inf"), 0.2],
        [2.0, 1.5, 1600.0],
    ],
)
def test_growth_check_of_one_set_equals_that_of_a_batch(sequence):
    """The divergence check books one set's residual in plain Python: every flag and every smallest-so-far
    equals the array path's on a batch of one set."""
    import types

    from rsocl.solver.iterate import _History

    staged = types.SimpleNamespace(truth=None)
    settings = types.SimpleNamespace(callback=None, tol=None, projection="exact")
    one, batch = _History(None, staged, settings, 1, None), _History(None, staged, settings, 1, None)
    for value in sequence:
        flag = one._grown(float(value))
        flags = batch._grown(np.array([value]))
        assert bool(flag) == bool(flags[0]), value
        assert np.array_equal(np.atleast_1d(one.lowest), batch.lowest, equal_nan=True), value


def test_a_callback_of_the_wrong_signature_is_refused_before_the_search(monkeypatch):
    import rsocl.solver.reconstruct as reconstruct_module

    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=180e-6, t_r=35e-6)
    g = ref.forward(rig, builtin_scene(rig.shape, rig.T, dtype=np.float64))
    monkeypatch.setattr(reconstruct_module, "tune_and_run", lambda *a: pytest.fail("the run started"))
    with pytest.raises(ValueError, match=r"callback must take \(iteration, residual, theta\), got .*lambda"):
        rsocl.reconstruct(g, rig, callback=lambda iteration: None)
    with pytest.raises(ValueError, match=r"callback must be callable, got 3"):
        rsocl.reconstruct(g, rig, callback=3)


@pytest.mark.filterwarnings("ignore:g. snapshots of camera 0 reach:UserWarning")  # 1e19 is off-scale, on purpose
def test_float64_runs_hold_data_far_from_one_as_the_reference_does(device):
    """TV's square roots start from a float estimate; float64 data of 1e-18 or 1e19 (squares beyond float's
    range) keep the reference's result, scaled."""
    if not device.has_fp64:
        pytest.skip(f"device {device.name} has no cl_khr_fp64")
    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=180e-6, t_r=35e-6)
    g = ref.forward(rig, builtin_scene(rig.shape, rig.T, dtype=np.float64))
    want = ref.admm(rig, g, iterations=5, lam=0.1, eta=0.2, tv_iterations=10, temporal_weight=3.0, step=STEP)
    for scale in (1e-18, 1e19):
        got = rsocl.reconstruct(
            g * scale,
            rig,
            iterations=5,
            lam=0.1 * scale,
            eta=0.2,
            tune=False,
            dtype="float64",
            regularizer_options={"temporal_weight": 3.0},
            device=device,
        ).datacube
        assert np.abs(got / scale - want).max() < 1e-10 * np.abs(want).max(), scale


@pytest.mark.parametrize("scale, warned", [(1e19, True), (1e-17, True), (1.0, False), (1e16, False)])
def test_float32_warns_of_data_beyond_its_squares(device, scale, warned):
    rig = rsocl.Rig.paper_array(2, (6, 6), t_e=180e-6, t_r=35e-6)
    g = ref.forward(rig, builtin_scene(rig.shape, rig.T, dtype=np.float64)) * scale
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        rsocl.reconstruct(g, rig, iterations=2, lam=0.1 * scale, tune=False, device=device)
    said = [str(w.message) for w in seen if "float32 holds the squares" in str(w.message)]
    assert len(said) == int(warned), said
    assert not warned or "use dtype='float64' (--dtype float64)" in said[0]
