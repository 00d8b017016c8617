"""Parameters chosen from the data (rsocl.solver.crossval, rsocl.solver.holdout): the criterion, the search,
the defaults."""

import inspect

import numpy as np
import pytest

import rsocl
from rsocl.model import reference as ref
from rsocl.model.curvature import default_scale
from rsocl.solver.crossval import SearchSpace, tune_parameters
from rsocl.solver.holdout import holdout

SHAPE = (24, 24)


def _rig():
    return rsocl.Rig.paper_array(4, SHAPE, t_e=0.18e-3, t_r=35e-6)


def _static(rig):
    from rsocl.model.scenes import builtin_scene

    frame = builtin_scene(rig.shape, rig.T)[:1]
    return np.repeat(frame, rig.T, axis=0).astype(np.float64)


def _independent(rig, seed=0):
    """Every sub-frame an independent random image of 6x6-pixel blocks: nothing carries over in time."""
    blocks = np.random.default_rng(seed).uniform(0.1, 0.9, (rig.T, SHAPE[0] // 6, SHAPE[1] // 6))
    return np.kron(blocks, np.ones((6, 6)))


def test_holdout_keeps_all_but_one_channel_per_pixel():
    held = holdout((20, 30), 4, block=5)
    assert held.shape == (4, 20, 30)
    assert np.all(held.sum(axis=0) == 1)  # one channel held out everywhere
    assert all(held[k].any() for k in range(4))  # every channel is held out somewhere
    one = holdout((8, 8), 1, block=2)
    assert one.any() and not one.all()  # one camera: half the blocks fitted
    with pytest.raises(ValueError, match="block"):
        holdout((8, 8), 4, block=0)


@pytest.mark.parametrize("channels", range(1, 13))
@pytest.mark.parametrize("shape", [(16, 16), (24, 40), (48, 32), (8, 200)])
def test_default_folds_hold_out_every_camera_with_as_few_patterns_as_that_takes(channels, shape):
    from rsocl.solver.holdout import FOLDS, default_folds

    period = max(channels, 2)

    def covered(folds):
        held = np.zeros(channels, bool)
        for k in range(folds):
            held |= holdout(shape, channels, shift=(k * period) // folds).any(axis=(1, 2))
        return held.all()

    folds = default_folds(shape, channels)
    assert FOLDS <= folds <= period and covered(folds)
    assert folds == FOLDS or not covered(folds - 1)


def test_the_search_pools_the_default_folds_and_records_them():
    """16x16 pixels (blocks of 8x8): one pattern holds out each of 4 cameras, one camera of each
    pixel; 8 cameras take two patterns, 12 cameras on 4x4 pixels (2x2 blocks of 2x2) three."""
    from rsocl.model.scenes import builtin_scene
    from rsocl.solver.holdout import default_folds

    for cameras, folds in [(8, 2), (4, 1)]:
        rig = rsocl.Rig.paper_array(cameras, (16, 16), t_e=0.18e-3, t_r=35e-6)
        record = rsocl.reconstruct(ref.forward(rig, builtin_scene(rig.shape, rig.T)), rig, iterations=12).params[
            "tuning"
        ]
        assert record["folds"] == folds and record["block"] == 8
        assert record["held_out_pixels"] == folds * 16 * 16  # one camera of each pixel per fold
    assert default_folds((4, 4), 12) == 3


def test_default_blocks_are_a_quarter_of_the_side_within_16_px_and_half_the_side():
    from rsocl.solver.holdout import MIN_BLOCK, default_block

    assert MIN_BLOCK == 16
    sides = {
        (3, 3): 2,
        (4, 4): 2,
        (16, 16): 8,
        (24, 40): 12,
        (48, 32): 16,
        (48, 48): 16,
        (64, 64): 16,
        (100, 64): 16,
        (128, 128): 32,
        (1024, 1280): 256,
    }
    assert {shape: default_block(shape) for shape in sides} == sides


def test_default_patterns_take_each_scale_once():
    from rsocl.solver.holdout import default_block, default_patterns

    assert default_patterns((16, 16), 4) == [(default_block((16, 16)), 0)]
    assert default_patterns((16, 16), 4, scales=((0.5, 1), (0.25, 2))) == [(8, 0), (4, 0), (4, 2)]
    assert default_patterns((4, 4), 4, scales=((0.5, 1), (0.25, 1))) == [(2, 0)]  # both scales: 2x2 blocks


def test_the_search_pools_given_patterns_of_several_block_sizes():
    from rsocl.solver.problem import check_problem, check_settings, stage_on_device
    from rsocl.solver.request import make_regularizer

    rig = _rig()
    g = ref.forward(rig, _static(rig))
    tv = make_regularizer("tv")
    problem = check_problem(g, rig)
    settings = check_settings(iterations=20).settled_for(tv, "float32", scale=default_scale(rig))
    staged = stage_on_device(problem, tv, settings, start=True)
    args = (
        staged.op,
        staged.g,
        problem.g,
        lambda options: make_regularizer("tv", options),
        SearchSpace({"temporal_weight": (1.0, 30.0)}, settings.lam),
    )
    kwargs = dict(eta=settings.eta, iterations=10)
    record = tune_parameters(*args, patterns=[(12, 0), (6, 0), (6, 2)], **kwargs)
    assert record.block == [12, 6] and record.folds == 3 and record.held_out == 3 * SHAPE[0] * SHAPE[1]
    assert record.chosen["temporal_weight"] == 30.0  # a static scene
    with pytest.raises(ValueError, match="at least one"):
        tune_parameters(*args, patterns=[], **kwargs)
    with pytest.raises(ValueError, match="pattern block"):
        tune_parameters(*args, patterns=[(0, 0)], **kwargs)


def test_static_scene_picks_a_strong_temporal_weight():
    rig = _rig()
    res = rsocl.reconstruct(ref.forward(rig, _static(rig)), rig, iterations=30)
    assert res.params["tuning"]["chosen"]["temporal_weight"] >= 10


def test_independent_frames_pick_a_weak_temporal_weight():
    rig = _rig()
    res = rsocl.reconstruct(ref.forward(rig, _independent(rig)), rig, iterations=30)
    assert res.params["tuning"]["chosen"]["temporal_weight"] <= 3


def test_no_ground_truth_reaches_the_tuning():
    # the search takes no truth at all, and a run with truth=None chooses what a run with one does
    assert "truth" not in inspect.signature(tune_parameters).parameters
    rig = _rig()
    truth = _static(rig) * 0.5 + 0.5 * _independent(rig)
    g = ref.forward(rig, truth)
    blind = rsocl.reconstruct(g, rig, iterations=20, truth=None)
    seen = rsocl.reconstruct(g, rig, iterations=20, truth=truth)
    record = blind.params["tuning"]
    assert record["chosen"] == seen.params["tuning"]["chosen"]
    assert blind.params["lam"] == record["chosen"]["lam"]
    assert blind.params["regularizer_options"]["temporal_weight"] == record["chosen"]["temporal_weight"]
    assert blind.params["start"] == "interp3d"
    assert len(record["candidates"]) >= 6 and all(c["score"] > 0 for c in record["candidates"])
    assert min(c["score"] for c in record["candidates"]) == pytest.approx(
        next(
            c["score"]
            for c in record["candidates"]
            if c["lam"] == record["chosen"]["lam"] and c["temporal_weight"] == record["chosen"]["temporal_weight"]
        )
    )


def test_values_the_caller_fixes_win():
    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=1e-4, t_r=3e-5)
    g = ref.forward(rig, np.random.default_rng(3).random((rig.T,) + rig.shape))
    both = rsocl.reconstruct(g, rig, iterations=12, lam=0.05, regularizer_options={"temporal_weight": 2.0})
    assert both.params["tuning"] is None and both.params["start"] == "zeros"
    weight = rsocl.reconstruct(g, rig, iterations=12, regularizer_options={"temporal_weight": 2.0})
    assert weight.params["regularizer_options"]["temporal_weight"] == 2.0
    assert weight.params["tuning"]["fixed"] == {"temporal_weight": 2.0}
    assert all(set(c) == {"lam", "score", "blend"} for c in weight.params["tuning"]["candidates"])  # only lam searched
    lam = rsocl.reconstruct(g, rig, iterations=12, lam=0.05)
    assert lam.params["lam"] == 0.05 and {c["lam"] for c in lam.params["tuning"]["candidates"]} == {0.05}
    fast = rsocl.reconstruct(g, rig, iterations=12, tune=False)
    assert fast.params["tuning"] is None
    lam = 0.1 * default_scale(rig)  # t_e/dt = 3.3: psi scales the defaults
    assert (fast.params["lam"], fast.params["regularizer_options"]["temporal_weight"]) == (lam, 3.0)


def test_an_instance_keeps_the_options_it_was_made_with_and_the_search_chooses_the_others():
    from rsocl_plugins.tv import TV

    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=1e-4, t_r=3e-5)
    g = ref.forward(rig, np.random.default_rng(3).random((rig.T,) + rig.shape))
    by_name = rsocl.reconstruct(g, rig, "tv", iterations=12)
    plain = rsocl.reconstruct(g, rig, TV(), iterations=12)  # as by name: temporal_weight searched
    assert plain.params["tuning"] == by_name.params["tuning"] | {"seconds": plain.params["tuning"]["seconds"]}
    np.testing.assert_array_equal(plain.datacube, by_name.datacube)
    made = rsocl.reconstruct(g, rig, TV(temporal_weight=2.0), iterations=12, lam=0.05)
    assert made.params["tuning"] is None and made.params["regularizer_options"]["temporal_weight"] == 2.0


def test_tuning_survives_blank_and_saturated_captures():
    rig = rsocl.Rig.paper_array(2, (12, 12), t_e=1e-4, t_r=3e-5)
    blank = rsocl.reconstruct(np.zeros((2, 12, 12)), rig, iterations=10)
    assert not blank.datacube.any() and blank.params["tuning"]["chosen"]
    g = ref.forward(rig, np.random.default_rng(4).random((rig.T,) + rig.shape))
    level = np.quantile(g, 0.9)
    res = rsocl.reconstruct(np.minimum(g, level), rig, iterations=10, saturation=level)
    assert np.all(np.isfinite(res.datacube)) and res.params["saturated_pixels"] > 0


@pytest.mark.parametrize("shape", [(2, 2), (1, 1), (1, 2)])
def test_one_camera_on_a_tiny_grid_takes_the_one_snapshot_preset_or_else_the_fixed_defaults_with_a_warning(shape):
    """One camera holds nothing out on 2x2 pixels or fewer. TV's one-snapshot preset needs no search, so it
    applies as on a larger grid (from interp3d); a regularizer that would search there runs the fixed defaults."""
    import warnings

    from rsocl.solver.holdout import can_hold_out

    rig = rsocl.Rig.paper_array(1, shape, t_e=1e-4, t_r=3e-5)
    g = ref.forward(rig, np.random.default_rng(3).random((rig.T,) + rig.shape))
    assert not can_hold_out(rig.shape, 1) and can_hold_out((3, 3), 1) and can_hold_out(shape, 2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = rsocl.reconstruct(g, rig, iterations=5)
    assert res.params["tuning"]["chosen"]["temporal_weight"] == 10.0 and res.params["start"] == "interp3d"
    with pytest.warns(UserWarning, match=f"1-camera rig on {shape[0]}x{shape[1]} pixels leave no pixels to hold out"):
        res = rsocl.reconstruct(g, rig, "dct", iterations=5)
    assert res.params["tuning"] is None and res.params["start"] == "zeros"
    np.testing.assert_array_equal(res.datacube, rsocl.reconstruct(g, rig, "dct", iterations=5, tune=False).datacube)
    assert not can_hold_out((4, 4), 4, valid=np.zeros((4, 4, 4), bool))


def test_an_earlier_choice_runs_again_without_a_search():
    """``tune=<Tuning>`` applies a recorded choice (values and interp3d start) as the tuned run did."""
    from rsocl.solver.crossval import Tuning

    rig = _rig()
    g = ref.forward(rig, _static(rig))
    first = rsocl.reconstruct(g, rig, iterations=12)
    again = rsocl.reconstruct(g, rig, iterations=12, tune=Tuning.from_params(first.params["tuning"]))
    assert again.params["tuning"]["chosen"] == first.params["tuning"]["chosen"]
    assert again.params["start"] == "interp3d" and again.params["lam"] == first.params["lam"]
    np.testing.assert_allclose(again.datacube, first.datacube, atol=1e-6 * np.abs(first.datacube).max())
    fixed = rsocl.reconstruct(g, rig, iterations=12, tune=False)
    assert np.abs(fixed.datacube - first.datacube).max() > 1e-3 * np.abs(first.datacube).max()
    # values the caller fixes win over the earlier choice's, as they do over a search
    choice = Tuning.from_params(first.params["tuning"])
    mine = rsocl.reconstruct(g, rig, iterations=12, tune=choice, lam=0.07, regularizer_options={"temporal_weight": 0.5})
    assert mine.params["lam"] == 0.07 and mine.params["regularizer_options"]["temporal_weight"] == 0.5
    from rsocl_plugins.tv import TV

    mine = rsocl.reconstruct(g, rig, iterations=12, tune=choice, regularizer=TV(temporal_weight=0.5))
    assert mine.params["regularizer_options"]["temporal_weight"] == 0.5
    assert mine.params["lam"] == first.params["lam"]
    for bad in ("yes", 1, None):
        with pytest.raises(ValueError, match="tune must be True, False"):
            rsocl.reconstruct(g, rig, iterations=2, tune=bad)


def test_the_blend_minimises_the_held_out_error_of_the_mix():
    """``_blend`` from the three sums of squares is the arg-min over [0, 1] of the mix's held-out error."""
    from rsocl.solver.crossval import _blend

    rng = np.random.default_rng(4)
    g, start = rng.random(200), rng.random(200)
    for run in (g + 0.3 * (start - g) + 0.05 * rng.random(200), start + 2.0 * (g - start), start - 0.5 * (g - start)):
        sums = (np.sum((g - start) ** 2), np.sum((run - start) ** 2), np.sum((g - run) ** 2))
        alphas = np.linspace(0.0, 1.0, 100001)
        errors = [np.sum((g - start - a * (run - start)) ** 2) for a in alphas[::1000]]
        assert _blend(*sums) == pytest.approx(alphas[::1000][int(np.argmin(errors))], abs=0.01)
    assert _blend(1.0, 2.0, 0.5) == pytest.approx(0.625)  # (1 + 2 - 0.5) / 2 / 2
    assert _blend(1.0, 1.0, 4.0) == 0.0  # moving away from the data: the start
    assert _blend(1.0, 0.25, 0.0) == 1.0  # clipped at the run's own result
    assert _blend(1.0, 0.0, 1.0) == 1.0 and _blend(1.0, np.inf, np.inf) == 1.0


def test_a_noisy_still_scene_blends_towards_the_interpolation():
    """Shot noise on a scene that barely changes: the solver fits noise that the interpolation averages
    out, the held-out pixels say so, and the returned estimate (recorded as the history's last entry)
    is the mix, several dB above the solver's own result."""
    from rsocl.analysis.metrics import psnr
    from rsocl.model.scenes import builtin_scene
    from rsocl.model.simulate import full_scale
    from rsocl.solver.crossval import Tuning

    rig = rsocl.Rig([rsocl.Camera(a, t_e=3e-4, t_r=3e-5) for a in (0, 90, 180)], SHAPE)
    truth = builtin_scene(rig.shape, 1)[0][None] * np.linspace(0.9, 1.1, rig.T)[:, None, None]
    scale = full_scale(rig)
    g = np.random.default_rng(3).poisson(ref.forward(rig, truth).clip(0) * 300 / scale) * scale / 300
    tuned = rsocl.reconstruct(g, rig, truth=truth, iterations=60)
    blend = tuned.params["blend"]
    assert tuned.params["tuning"]["blend"] == blend and 0.0 < blend < 0.6
    assert tuned.history["psnr"][-1] == pytest.approx(psnr(tuned.datacube, truth), abs=1e-6)
    choice = Tuning.from_params(tuned.params["tuning"])
    assert choice.blend == blend
    own = rsocl.reconstruct(g, rig, truth=truth, iterations=60, tune=choice, blend=1.0)
    assert own.params["blend"] == 1.0 and psnr(tuned.datacube, truth) > psnr(own.datacube, truth) + 2.0
    again = rsocl.reconstruct(g, rig, iterations=60, tune=choice)  # the recorded choice's blend
    np.testing.assert_allclose(again.datacube, tuned.datacube, atol=1e-5)
    # the same mix asked for by hand, from the same start, without a search
    start = rsocl.model.interpolation.interp3d(g, rig)
    fixed = dict(
        lam=tuned.params["lam"],
        regularizer_options={"temporal_weight": tuned.params["tuning"]["chosen"]["temporal_weight"]},
    )
    unmixed = rsocl.reconstruct(g, rig, iterations=60, tune=False, x0=start, **fixed).datacube
    mixed = rsocl.reconstruct(g, rig, iterations=60, tune=False, x0=start, blend=blend, **fixed).datacube
    np.testing.assert_allclose(mixed, start + blend * (unmixed - start), atol=1e-5)
    # a blend of the caller's on a self-tuned run: towards the interpolation the run starts from
    half = rsocl.reconstruct(g, rig, iterations=60, tune=choice, blend=0.5)
    assert half.params["blend"] == 0.5 and half.params["start"] == "interp3d"
    np.testing.assert_allclose(half.datacube, start + 0.5 * (own.datacube - start), atol=1e-5)


def test_blend_is_checked_and_needs_a_start():
    rig = _rig()
    g = ref.forward(rig, _static(rig))
    for bad in (-0.1, 1.5, float("nan"), "half"):
        with pytest.raises(ValueError, match=r"blend must be"):
            rsocl.reconstruct(g, rig, iterations=2, blend=bad)
    with pytest.raises(
        ValueError, match="blend = 0.5 moves the result towards the run's start, and this run starts from zeros"
    ):
        rsocl.reconstruct(g, rig, iterations=2, tune=False, blend=0.5)
    assert rsocl.reconstruct(g, rig, iterations=2, tune=False).params["blend"] == 1.0
    # a start of the caller's: the search's blend (measured against the interpolation) is not applied
    given = rsocl.reconstruct(g, rig, iterations=12, x0=np.zeros((rig.T,) + rig.shape))
    assert given.params["tuning"]["blend"] is not None and given.params["blend"] == 1.0


def test_a_search_that_would_not_fit_is_refused_before_it_runs(monkeypatch):
    """The search's buffers count beside the staged problem: a device with room for the run but
    not for the search refuses the search (naming the way out) before any candidate runs, and
    still runs with fixed values. (For a batch the run needs more than the search on its first
    set: test_the_memory_counts_bound_what_the_search_and_the_run_hold.)"""
    from rsocl.solver import pipeline, search_batch
    from rsocl.solver.memory import memory_bytes, search_peak
    from rsocl.solver.request import make_regularizer

    monkeypatch.setattr(search_batch, "CANDIDATES", 1)  # on a GPU: the smallest batch the search can make
    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=1e-4, t_r=3e-5)
    g = ref.forward(rig, np.random.default_rng(5).random((rig.T,) + rig.shape))
    device = rsocl.device.get_device()
    op = rsocl.RollingShutterOperator(rig, device=device, subframes=rig.sampled_range())
    reg = make_regularizer("tv")
    run = memory_bytes(op, reg, "exact", 1, start=True)[1]
    peak = search_peak(op, reg, "exact", None)
    assert run < peak
    monkeypatch.setattr(type(device), "global_mem_bytes", property(lambda self: peak - 1))
    monkeypatch.setattr(pipeline, "tune_parameters", lambda *a, **k: pytest.fail("the search ran"))
    with pytest.raises(ValueError, match=r"choosing the parameters from the data .* tune=False"):
        rsocl.reconstruct(g, rig, iterations=4, device=device)
    fixed = rsocl.reconstruct(g, rig, iterations=4, device=device, tune=False)
    assert np.all(np.isfinite(fixed.datacube))
    given = rsocl.reconstruct(
        g, rig, iterations=4, device=device, lam=0.1, regularizer_options={"temporal_weight": 3.0}
    )
    assert given.params["tuning"] is None


def _live_device_bytes():
    """Bytes of the distinct device buffers behind every live ``pyopencl.array.Array``."""
    import gc

    import pyopencl.array as cla

    buffers = {}
    for obj in gc.get_objects():
        if isinstance(obj, cla.Array) and obj.base_data is not None:
            buffers[obj.base_data.int_ptr] = obj.base_data.size
    return sum(buffers.values())


@pytest.mark.parametrize(
    "cameras, batch, truth, x0, saturated, regularizer",
    [
        (4, None, False, False, False, "tv"),
        (4, None, True, True, False, "tv"),
        (8, None, False, False, False, "tv"),
        (4, 3, False, False, False, "tv"),
        (4, 3, True, False, True, "tv"),
        (4, 3, False, False, False, "tv-fused"),
        (4, None, False, False, False, "tv-gpu"),
        (4, None, False, False, False, "dct"),
        (4, None, False, False, False, "wavelet"),
    ],
)
def test_the_memory_counts_bound_what_the_search_and_the_run_hold(
    cameras, batch, truth, x0, saturated, regularizer, monkeypatch
):
    """For TV (plain and fused), DCT and wavelets: the device arrays alive while the search runs and
    while the run iterates stay within the counts the device is checked against (search_peak;
    memory_bytes with the start cube), and the counts exceed them by no more than the valid-pixel
    mask they count always and a few small per-set values: neither an under-count (an allocation
    failure mid-run) nor a refusal of what fits. On a GPU, or the device read as one (``tv-gpu``), where
    the search runs candidates x folds as batches, the counts bound what it holds."""
    from rsocl.device.context import Device
    from rsocl.solver import folds as folds_module
    from rsocl.solver import search_batch
    from rsocl.solver.holdout import default_patterns
    from rsocl.solver.inverse import own_inverses
    from rsocl.solver.memory import memory_bytes, search_peak
    from rsocl.solver.request import make_regularizer

    rig = rsocl.Rig.paper_array(cameras, (12, 16), t_e=1e-4, t_r=3e-5)
    cube = np.random.default_rng(5).random((rig.T,) + rig.shape)
    g = ref.forward(rig, cube)
    sets = batch or 1
    if batch is not None:
        g, cube = np.stack([g * (1 + 0.1 * b) for b in range(batch)]), np.stack([cube] * batch)
    saturation = float(np.quantile(g, 0.9)) if saturated else None
    op = rsocl.RollingShutterOperator(rig, subframes=rig.sampled_range())
    name, options = ("tv", {"fused": 2}) if regularizer == "tv-fused" else (regularizer, None)
    if regularizer == "tv-gpu":
        name = "tv"
        monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    gpu = not rsocl.get_device().is_cpu  # a GPU's search runs candidates x folds as batches
    reg = make_regularizer(name, options)
    own = own_inverses("exact", 0.2, None, sets)  # saturated samples stay in the shared blocks
    run_count = memory_bytes(op, reg, "exact", sets, truth=truth, own_inverse=own, start=True)[1]
    search_count = search_peak(op, reg, "exact", batch, truth=truth, start=x0)
    snap = op.K * op.mn * op.dtype.itemsize
    peak = {"search": 0, "run": 0}

    class Probe(folds_module.ADMM):  # every buffer exists once a candidate's first step ran
        def step(self):
            if self.iteration <= 1:
                peak["search"] = max(peak["search"], _live_device_bytes() - base)
            return super().step()

    def callback(iteration, residual, theta):
        peak["run"] = max(peak["run"], _live_device_bytes() - base)

    monkeypatch.setattr(folds_module, "ADMM", Probe)
    monkeypatch.setattr(search_batch, "ADMM", Probe)
    base = _live_device_bytes()
    result = rsocl.reconstruct(
        g,
        rig,
        name,
        regularizer_options=options,
        iterations=3,
        callback=callback,
        truth=cube if truth else None,
        x0=cube if x0 else None,
        saturation=saturation,
    )
    assert result.params["tuning"] is not None and peak["search"] > 0 and peak["run"] > 0
    small = 256  # per-set step lengths, eta, flags: uncounted
    assert peak["search"] <= search_count + small
    assert peak["run"] <= run_count + small
    folds = result.params["tuning"]["folds"]
    assert folds == len(default_patterns(rig.shape, rig.n_channels))
    if not gpu:  # the GPU's count holds the largest batch of candidates the search may make
        assert search_count - peak["search"] <= snap * (folds if batch is None else 0) + small
    assert run_count - peak["run"] <= (0 if saturated else sets * snap) + small
    if batch is not None and not gpu:  # the run's own check covers its search (a GPU's is checked on its own)
        assert search_count < run_count


@pytest.mark.parametrize("cameras, shape", [(2, (16, 16)), (3, (16, 24)), (6, (16, 16)), (8, (20, 12))])
def test_the_tuned_default_beats_interpolation_on_other_rigs(cameras, shape):
    """Arrays other than the paper's four cameras, non-square grids: the search runs, records a
    choice among its candidates, and the result is closer to the truth than interp3d."""
    from rsocl.analysis.metrics import psnr
    from rsocl.model.interpolation import interp3d
    from rsocl.model.scenes import builtin_scene
    from rsocl.solver.holdout import default_block

    rig = rsocl.Rig.paper_array(cameras, shape, t_e=0.18e-3, t_r=35e-6)
    truth = builtin_scene(rig.shape, rig.T)
    g = ref.forward(rig, truth)
    res = rsocl.reconstruct(g, rig, iterations=40)
    record = res.params["tuning"]
    assert record["block"] == default_block(shape) and record["held_out_pixels"] > 0
    assert any(
        c["lam"] == record["chosen"]["lam"] and c["temporal_weight"] == record["chosen"]["temporal_weight"]
        for c in record["candidates"]
    )
    assert psnr(res.datacube, truth) > psnr(interp3d(g, rig), truth) + 0.5


def test_the_search_summary_says_how_pixels_were_held_out(tmp_path):
    """The tuning plot's second title line: block, folds, held-out pixels, iterations, candidates, time."""
    from rsocl.analysis.tuning_plot import search_summary, tuning_plot
    from rsocl.model.scenes import builtin_scene

    rig = rsocl.Rig.paper_array(8, (16, 16), t_e=0.18e-3, t_r=35e-6)
    record = rsocl.reconstruct(ref.forward(rig, builtin_scene(rig.shape, rig.T)), rig, iterations=40).params["tuning"]
    line = search_summary(record)
    assert line.startswith(
        "blocks of 8 px, 2 hold-out folds, 512 held-out pixels, 10 iterations per candidate and fold"
    )
    assert f"{len(record['candidates'])} candidates" in line and line.endswith(" s")
    one = {**record, "folds": 1, "iterations_per_candidate": 20}
    assert "1 hold-out fold, 512 held-out pixels, 20 iterations per candidate, " in search_summary(one)
    sizes = {**record, "block": [8, 4]}
    assert search_summary(sizes).startswith("blocks of 8 and 4 px, 2 hold-out folds")
    assert "fold" in search_summary({"candidates": []})  # an older record without these keys
    assert "blend with the interpolation 0.25" in search_summary({**record, "blend": 0.25})
    assert tuning_plot(tmp_path / "t.png", record).stat().st_size > 0


def test_one_camera_of_several_frames_takes_the_preset_weight_and_searches_lam_alone():
    """A camera's frames far apart in time do not let the criterion rank temporal weights either
    (docs/one_camera_frames.md): the weight is the one-camera preset and the search chooses lam."""
    from rsocl_plugins.tv import TV

    weight = TV.one_snapshot["temporal_weight"]
    rig = rsocl.Rig([rsocl.Camera(90, t_e=0.18e-3, t_r=35e-6, frames=3, t_d=2e-3)], SHAPE)
    record = rsocl.reconstruct(ref.forward(rig, _static(rig)), rig, iterations=20).params["tuning"]
    assert record["preset"] == {"temporal_weight": weight} and record["chosen"]["temporal_weight"] == weight
    assert {c["temporal_weight"] for c in record["candidates"]} == {weight}
    assert len({c["lam"] for c in record["candidates"]}) > 1


def test_one_snapshot_per_pixel_sets_the_temporal_weight_and_runs_no_search(tmp_path, capsys):
    """With one camera a held-out block of the only snapshot is predicted across space alone: the
    temporal weight comes from ``TV.one_snapshot``, not from the criterion; lam, which hardly matters
    then, keeps its default: no search runs."""
    from rsocl.cli.main import main
    from rsocl.solver.crossval import Tuning
    from rsocl_plugins.tv import TV

    weight = TV.one_snapshot["temporal_weight"]
    rig = rsocl.Rig([rsocl.Camera(30, t_e=0.18e-3, t_r=35e-6)], SHAPE)
    g = ref.forward(rig, _static(rig))
    tuned = rsocl.reconstruct(g, rig, iterations=20)
    record = tuned.params["tuning"]
    assert record["preset"] == {"temporal_weight": weight} and record["chosen"]["temporal_weight"] == weight
    assert (
        record["candidates"] == []
        and tuned.params["lam"] == rsocl.reconstruct(g, rig, iterations=1, tune=False).params["lam"]
    )
    assert Tuning.from_params(record).preset == {"temporal_weight": weight}
    # a regularizer without a one-snapshot preset still has lam searched
    dct = rsocl.reconstruct(g, rig, "dct", iterations=20).params["tuning"]
    assert not dct["preset"] and len({c["lam"] for c in dct["candidates"]}) == 3
    # the caller's weight wins; with lam fixed too nothing is searched, and the run uses the preset weight
    given = rsocl.reconstruct(g, rig, iterations=5, regularizer_options={"temporal_weight": 2.0})
    assert given.params["regularizer_options"]["temporal_weight"] == 2.0 and not given.params["tuning"]["preset"]
    fixed = rsocl.reconstruct(g, rig, iterations=5, lam=0.1)
    assert fixed.params["tuning"]["candidates"] == []
    assert fixed.params["regularizer_options"]["temporal_weight"] == weight
    # two cameras: the weight is searched as always
    two = rsocl.Rig.paper_array(2, SHAPE, t_e=0.18e-3, t_r=35e-6)
    searched = rsocl.reconstruct(ref.forward(two, _static(two)), two, iterations=20).params["tuning"]
    assert len({c["temporal_weight"] for c in searched["candidates"]}) > 1 and not searched["preset"]
    # the CLI says what was set and plots only a search it ran
    cap = tmp_path / "one.h5"
    assert main(["simulate", "builtin", "--out", str(cap), "--shape", "16", "16", "--cameras", "1"]) == 0
    assert main(["reconstruct", str(cap), "--out", str(tmp_path / "r.h5"), "--iterations", "5", "--lam", "0.1"]) == 0
    assert f"temporal_weight = {weight:.3g}" in capsys.readouterr().out and not (tmp_path / "r-tuning.png").exists()
