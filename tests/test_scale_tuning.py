"""A tiled run chooses its parameters once, as rsocl.reconstruct does, and every tile uses that choice."""

import numpy as np
import pytest

import rsocl
import rsocl.solver.reconstruct as reconstruct_module
from rsocl.model.scenes import builtin_scene
from rsocl.scale import reconstruct_tiled, tile_grid, tuning_tile
from rsocl.scale.stream import reconstruct_stream
from rsocl.scale.tiles import tile_rig
from rsocl.scale.tuning_tile import TUNE_SIDE, by_distance_to_centre, tuning_crop

ITER = 12


def _problem(rig, seed=0):
    truth = builtin_scene(rig.shape, rig.T, seed=seed)
    return rsocl.RollingShutterOperator(rig).forward(truth), truth


def _record_calls(monkeypatch):
    """Every tile's call of rsocl.reconstruct: its lam, options, start and tune flag."""
    calls = []
    real = reconstruct_module.reconstruct

    def recording(g, rig, *args, **kwargs):
        calls.append(
            {
                "lam": kwargs["lam"],
                "options": dict(kwargs["regularizer_options"]),
                "tune": kwargs["tune"],
                "x0": kwargs.get("x0"),
                "g": np.array(g),
                "rig": rig,
            }
        )
        return real(g, rig, *args, **kwargs)

    monkeypatch.setattr(reconstruct_module, "reconstruct", recording)
    return calls


def test_a_single_tile_over_the_grid_is_the_untiled_tuned_reconstruction():
    rig = rsocl.Rig.paper_array(4, (20, 24), t_e=1.8e-4, t_r=3.5e-5)
    g, _ = _problem(rig)
    untiled = rsocl.reconstruct(g, rig, iterations=ITER)
    tiled = reconstruct_tiled(g, rig, tile=rig.shape, halo=0, iterations=ITER)
    assert untiled.params["tuning"] is not None and untiled.params["start"] == "interp3d"
    assert tiled.params["tuning"]["chosen"] == untiled.params["tuning"]["chosen"]
    assert tiled.params["lam"] == untiled.params["lam"] == untiled.params["tuning"]["chosen"]["lam"]
    assert tiled.params["regularizer_options"] == untiled.params["regularizer_options"]
    assert tiled.params["start"] == "interp3d"
    np.testing.assert_allclose(tiled.datacube, untiled.datacube, atol=1e-5)
    fixed = rsocl.reconstruct(g, rig, iterations=ITER, tune=False).datacube
    assert np.abs(fixed - untiled.datacube).max() > 1e-3  # the tolerance above tells tuned from fixed
    assert tiled.params["blend"] == untiled.params["blend"]


def test_tiles_return_the_blend_the_search_chose():
    """Shot noise on a still scene makes the search blend towards the interpolation; every tile returns
    that blend of its own run, so one tile over the grid is still the untiled result."""
    rig = rsocl.Rig([rsocl.Camera(a, t_e=3e-4, t_r=3e-5) for a in (0, 90, 180)], (24, 24))
    truth = builtin_scene(rig.shape, 1)[0][None] * np.linspace(0.9, 1.1, rig.T)[:, None, None]
    g = np.random.default_rng(3).poisson(rsocl.RollingShutterOperator(rig).forward(truth).clip(0) * 30) / 30
    untiled = rsocl.reconstruct(g, rig, iterations=ITER)
    assert untiled.params["blend"] < 0.9
    tiled = reconstruct_tiled(g, rig, tile=rig.shape, halo=0, iterations=ITER)
    assert tiled.params["blend"] == untiled.params["blend"] == tiled.params["tuning"]["blend"]
    np.testing.assert_allclose(tiled.datacube, untiled.datacube, atol=1e-5)
    # the caller's blend replaces the search's, in every tile, as untiled
    choice = rsocl.solver.crossval.Tuning.from_params(untiled.params["tuning"])
    for blend in (1.0, 0.25):
        mine = reconstruct_tiled(g, rig, tile=rig.shape, halo=0, iterations=ITER, tune=choice, blend=blend)
        assert mine.params["blend"] == blend != untiled.params["blend"]
        whole = rsocl.reconstruct(g, rig, iterations=ITER, tune=choice, blend=blend).datacube
        np.testing.assert_allclose(mine.datacube, whole, atol=1e-5)
        assert np.abs(whole - untiled.datacube).max() > 1e-3


def test_a_blend_below_1_needs_the_interpolation_start():
    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=1.8e-4, t_r=3.5e-5)
    g, _ = _problem(rig)
    for bad in (-0.5, 2.0, float("nan")):
        with pytest.raises(ValueError, match="blend must be"):
            reconstruct_tiled(g, rig, tile=(6, 6), iterations=2, blend=bad)
    for kwargs in (dict(tune=False), dict(lam=0.1, regularizer_options={"temporal_weight": 3.0})):
        with pytest.raises(
            ValueError, match="blend = 0.5 moves the result towards the run's start, and this run starts from zeros"
        ):
            reconstruct_tiled(g, rig, tile=(6, 6), iterations=2, blend=0.5, **kwargs)
    assert reconstruct_tiled(g, rig, tile=(6, 6), iterations=2, tune=False, blend=1.0).params["blend"] == 1.0


def test_every_tile_of_every_set_gets_the_choice_made_on_the_centre_block_of_the_first_set(monkeypatch, tmp_path):
    pytest.importorskip("zarr")
    from rsocl.scale.store import load_store

    rig = rsocl.Rig.paper_array(4, (30, 36), t_e=1.8e-4, t_r=3.5e-5)
    sets = np.stack([_problem(rig, seed=s)[0] for s in range(2)])
    grid = tile_grid(rig.shape, (10, 12), 4)
    assert tuning_crop(grid).outer == (0, 30, 0, 36)  # under TUNE_SIDE a side: the whole grid
    expected = rsocl.reconstruct(sets[0], rig, iterations=ITER).params["tuning"]["chosen"]
    calls = _record_calls(monkeypatch)
    result = reconstruct_tiled(sets, rig, tile=(10, 12), halo=4, iterations=ITER, out=tmp_path / "rec.zarr")
    assert result.tuning.chosen == expected
    assert len(calls) == 2 * len(grid)
    options = {k: v for k, v in expected.items() if k != "lam"}
    for call in calls:  # one setting for every tile and set, each from its own interpolation
        assert call["lam"] == expected["lam"] and call["options"] == options
        assert call["tune"] is not True and not call["tune"].chosen  # no tile searches: it runs the capture's values
        assert call["x0"] == "interp3d"
    stored = load_store(tmp_path / "rec.zarr").params
    assert stored["tuning"]["chosen"] == expected and stored["lam"] == expected["lam"]
    assert stored["start"] == "interp3d"
    again = reconstruct_tiled(sets, rig, tile=(10, 12), halo=4, iterations=ITER, out=tmp_path / "rec.zarr")
    assert again.skipped == 2 * len(grid) and not again.pieces  # resumed, nothing redone


def test_fixed_settings_when_not_tuned_or_when_nothing_is_left_to_choose(monkeypatch):
    rig = rsocl.Rig.paper_array(4, (20, 24), t_e=1.8e-4, t_r=3.5e-5)
    g, _ = _problem(rig)
    calls = _record_calls(monkeypatch)
    fixed = reconstruct_tiled(g, rig, tile=(10, 12), halo=4, iterations=4, tune=False)
    assert fixed.tuning is None and fixed.params["tuning"] is None and fixed.params["start"] == "zeros"
    assert all(c["x0"] is None and c["options"] == {} for c in calls)
    assert fixed.params["lam"] == rsocl.reconstruct(g, rig, iterations=4, tune=False).params["lam"]
    calls.clear()
    given = reconstruct_tiled(
        g, rig, tile=(10, 12), halo=4, iterations=4, lam=0.05, regularizer_options={"temporal_weight": 2.0}
    )
    assert given.tuning is None and given.params["start"] == "zeros" and given.params["lam"] == 0.05
    assert all(c["lam"] == 0.05 and c["options"] == {"temporal_weight": 2.0} for c in calls)
    with pytest.raises(ValueError, match="tune must be True, False or"):
        reconstruct_tiled(g, rig, tile=(10, 12), tune="yes")


def test_a_stream_runs_every_window_with_the_first_windows_choice():
    from rsocl.model.rig import Camera, Rig

    rig = Rig([Camera(a, t_e=1.8e-4, t_r=3.5e-5, frames=3, t_d=12 * 3.5e-5) for a in (0, 90, 180, 270)], (12, 12))
    g, _ = _problem(rig)
    stream = reconstruct_stream(g, rig, window=2, overlap=1, iterations=ITER, halo=0)
    first, second = stream.results
    assert first.tuning is not None and second.tuning is first.tuning
    assert second.params["lam"] == first.params["lam"] and second.params["start"] == "interp3d"
    assert second.params["regularizer_options"] == first.params["regularizer_options"]


def test_the_block_tuned_on_is_centred_and_at_least_tune_side_or_one_tile():
    crop = tuning_crop(tile_grid((300, 500), (64, 64), 16))
    assert crop.outer == crop.core == (86, 86 + TUNE_SIDE, 186, 186 + TUNE_SIDE)
    assert tuning_crop(tile_grid((300, 500), (200, 100), 16)).outer == (34, 266, 184, 316)  # one tile's 232 x 132
    assert tuning_crop(tile_grid((40, 300), (20, 20), 4)).outer == (0, 40, 86, 214)


def test_small_tiles_tune_on_the_centre_block_not_on_one_tile(monkeypatch):
    """Tiles of 10x12 pixels of a 30x36 grid: the search sees the whole grid (under TUNE_SIDE), so the
    choice is the untiled run's, where one tile's block (18x20) chose differently."""
    rig = rsocl.Rig.paper_array(4, (30, 36), t_e=1.8e-4, t_r=3.5e-5)
    g, _ = _problem(rig, seed=1)
    seen = []
    search = tuning_tile._search
    monkeypatch.setattr(
        tuning_tile, "_search", lambda block, *a: seen.append(block[0].outer_shape) or search(block, *a)
    )
    tiled = reconstruct_tiled(g, rig, tile=(10, 12), halo=4, iterations=ITER, tune=True)
    assert seen == [(30, 36)]
    assert tiled.tuning.chosen == rsocl.reconstruct(g, rig, iterations=ITER).params["tuning"]["chosen"]
    centre = by_distance_to_centre(tile_grid(rig.shape, (10, 12), 4))[0]
    one_tile = rsocl.reconstruct(
        g[:, centre.outer_slices[0], centre.outer_slices[1]], tile_rig(rig, centre), iterations=ITER
    ).params["tuning"]["chosen"]
    assert one_tile != tiled.tuning.chosen


def test_a_centre_block_too_large_for_the_device_falls_back_to_the_centre_tile(monkeypatch):
    rig = rsocl.Rig.paper_array(4, (30, 36), t_e=1.8e-4, t_r=3.5e-5)
    g, _ = _problem(rig)
    seen = []
    search = tuning_tile._search

    def small_device(block, *args):
        seen.append(block[0].outer_shape)
        if block[0].outer_shape == (30, 36):
            raise ValueError("choosing the parameters needs 9.0 MiB of device memory in all, above the device's 8 MiB")
        return search(block, *args)

    monkeypatch.setattr(tuning_tile, "_search", small_device)
    grid = tile_grid(rig.shape, (10, 12), 4)
    centre = by_distance_to_centre(grid)[0]
    tiled = reconstruct_tiled(g, rig, tile=(10, 12), halo=4, iterations=ITER)
    assert seen == [(30, 36), centre.outer_shape]
    assert (
        tiled.tuning.chosen
        == rsocl.reconstruct(
            g[:, centre.outer_slices[0], centre.outer_slices[1]], tile_rig(rig, centre), iterations=ITER
        ).params["tuning"]["chosen"]
    )
