"""Tiles: geometry, exact row times of a tile's rig, tiled against untiled, bad input, faults, plan.

Runs in this process (no cluster): Dask's local scheduler when Dask is installed, else the
in-process loop; both are exercised.
"""

import importlib.util

import numpy as np
import pytest

import rsocl
from rsocl.model.curvature import default_scale
from rsocl.model.rig import Camera, Rig
from rsocl.model.scenes import builtin_scene
from rsocl.scale import reconstruct_tiled, tile_grid
from rsocl.scale import runner as runner_module
from rsocl.scale.tiled import TilesFailed
from rsocl.scale.tiles import expand, tile_rig

ITER = 25


def _problem(rig, seed=0):
    truth = builtin_scene(rig.shape, rig.T, seed=seed)
    return rsocl.RollingShutterOperator(rig).forward(truth), truth


def test_tiles_partition_the_grid_and_halos_are_clipped():
    grid = tile_grid((37, 45), (16, 20), 5)
    assert grid.grid == (3, 3) and len(grid) == 9
    owner = np.zeros((37, 45), dtype=int)
    for t in grid:
        rows, cols = t.core_slices
        owner[rows, cols] += 1
        oy0, oy1, ox0, ox1 = t.outer
        y0, y1, x0, x1 = t.core
        assert oy0 == max(0, y0 - 5) and oy1 == min(37, y1 + 5) and ox0 == max(0, x0 - 5) and ox1 == min(45, x1 + 5)
        inner = t.inner_slices
        assert inner[0].stop - inner[0].start == y1 - y0 and inner[1].stop - inner[1].start == x1 - x0
    assert np.all(owner == 1)
    assert grid[2, 2].core == (32, 37, 40, 45)


def test_a_tile_rig_keeps_every_pixel_s_row_times():
    cams = [Camera(a, t_e=1.8e-4, t_r=3.5e-5, t_a=t_a) for a, t_a in ((0, 0.0), (90, 1e-5), (30, 0.0), (250, 2e-5))]
    rig = Rig(cams, (33, 41))
    for t in tile_grid(rig.shape, (12, 15), 4):
        sub = tile_rig(rig, t)
        rows, cols = t.outer_slices
        np.testing.assert_array_equal(sub.start_times(), rig.start_times()[:, rows, cols])
        np.testing.assert_array_equal(sub.windows.index, rig.windows.index[:, rows, cols])
        solved = sub.sampled_range()
        assert rig.sampled_range().start <= solved.start < solved.stop <= rig.sampled_range().stop


def test_expand_holds_the_first_and_last_modelled_subframe():
    block = np.arange(3 * 2 * 2, dtype=np.float32).reshape(3, 2, 2) + 1
    out = expand(block, 4, 0, 10, (2, 9))
    np.testing.assert_array_equal(out[4:7], block)
    for t in range(4):  # before the block, inside the capture's span or not
        np.testing.assert_array_equal(out[t], block[0])
    for t in range(7, 10):
        np.testing.assert_array_equal(out[t], block[-1])
    np.testing.assert_array_equal(expand(block, 4, 3, 8, (2, 9)), out[3:8])
    with pytest.raises(ValueError, match="outside the sampled"):
        expand(block, 1, 0, 10, (2, 9))


def test_tiled_holds_the_subframes_before_every_camera_starts_as_untiled_does(tmp_path):
    rig = Rig([Camera(a, t_e=1.8e-4, t_r=3.5e-5, t_a=6 * 3.5e-5) for a in (0, 90, 180, 270)], (24, 28))
    first = rig.sampled_range().start
    assert first == 6
    g, truth = _problem(rig)
    untiled = rsocl.reconstruct(g, rig, iterations=ITER, tune=False).datacube
    tiled = reconstruct_tiled(g, rig, tile=(12, 14), halo=8, iterations=ITER, tune=False).datacube
    for cube in (untiled, tiled):
        np.testing.assert_array_equal(cube[:first], np.broadcast_to(cube[first], (first,) + rig.shape))
    if importlib.util.find_spec("zarr") is not None:  # a store holds the same sub-frames
        from rsocl.scale.store import load_store

        reconstruct_tiled(g, rig, tile=(12, 14), halo=8, iterations=ITER, tune=False, out=tmp_path / "late.zarr")
        np.testing.assert_array_equal(np.asarray(load_store(tmp_path / "late.zarr").datacube[:]), tiled)
    np.testing.assert_array_equal(
        reconstruct_tiled(g, rig, tile=(24, 28), halo=0, iterations=ITER, tune=False).datacube, untiled
    )


def _assert_close_to_untiled(result, untiled, grid):
    """Where a tile models the sub-frames, it is the untiled reconstruction (of its set) up to the
    halo's crop; away from the first and last sub-frames a tile models (which few of its pixels
    sample: within one exposure, window_length sub-frames, of an end that is not the capture's)
    the difference is small."""
    span, edge = result.rig.sampled_range(), result.rig.window_length
    for piece in result.pieces:
        rows, cols = grid[piece.index].core_slices
        tiled = result.datacube if piece.set_index is None else result.datacube[piece.set_index]
        expected = untiled if piece.set_index is None else untiled[piece.set_index]
        cut = (slice(piece.start, piece.stop), rows, cols)
        diff = np.abs(tiled[cut] - expected[cut])
        lo = edge if piece.start > span.start else 0
        hi = diff.shape[0] - (edge if piece.stop < span.stop else 0)
        assert diff[lo:hi].max() < 3e-2 and diff.max() < 0.1, (piece.index, diff[lo:hi].max(), diff.max())


@pytest.mark.parametrize(
    "angles, shape, tile",
    [
        ((0, 90, 180, 270), (37, 45), (16, 20)),  # odd sizes, uneven last tiles
        ((0, 45, 135, 250), (34, 39), (17, 13)),  # oblique angles
    ],
)
def test_tiled_matches_untiled(angles, shape, tile):
    rig = Rig([Camera(a, t_e=1.8e-4, t_r=3.5e-5) for a in angles], shape)
    g, truth = _problem(rig)
    untiled = rsocl.reconstruct(g, rig, iterations=ITER, tune=False).datacube
    result = reconstruct_tiled(g, rig, tile=tile, halo=12, iterations=ITER, tune=False)
    tiled = result.datacube
    assert tiled.shape == untiled.shape and tiled.dtype == untiled.dtype
    assert len(result.pieces) == len(tile_grid(shape, tile, 12)) and not result.failures
    _assert_close_to_untiled(result, untiled, tile_grid(shape, tile, 12))
    from rsocl.analysis.metrics import psnr

    assert psnr(tiled, truth) > psnr(untiled, truth) - 0.1
    # the settings of the whole capture, once for every tile
    scale = default_scale(rig)  # the whole rig's, not a tile's
    assert result.params["lam"] == 0.1 * scale and result.params["eta"] == 0.2 * scale
    assert result.params["tile"] == list(tile)


def test_each_set_s_tiles_run_with_that_set_s_lam_and_eta(tmp_path):
    rig = Rig([Camera(a, t_e=1.8e-4, t_r=3.5e-5) for a in (0, 90, 180, 270)], (30, 34))
    sets = np.stack([_problem(rig, seed=s)[0] for s in range(2)])
    values = dict(lam=(0.02, 0.3), eta=(0.2, 0.4))
    untiled = rsocl.reconstruct(sets, rig, iterations=ITER, tune=False, **values).datacube
    kwargs = dict(tile=(15, 17), halo=12, iterations=ITER, tune=False, **values)
    result = reconstruct_tiled(sets, rig, **kwargs)
    assert len(result.pieces) == 8 and result.params["lam"] == (0.02, 0.3) and result.params["eta"] == (0.2, 0.4)
    _assert_close_to_untiled(result, untiled, tile_grid(rig.shape, (15, 17), 12))
    if importlib.util.find_spec("zarr") is not None:  # a store of per-set values resumes
        reconstruct_tiled(sets, rig, out=tmp_path / "sets.zarr", **kwargs)
        assert reconstruct_tiled(sets, rig, out=tmp_path / "sets.zarr", **kwargs).skipped == 8
    with pytest.raises(ValueError, match=r"lam must have one value per set: 2 for this batch, got 3"):
        reconstruct_tiled(sets, rig, **{**kwargs, "lam": (0.1, 0.2, 0.3)})
    with pytest.raises(ValueError, match=r"eta has 2 values \(one per set\), but g holds one set"):
        reconstruct_tiled(sets[0], rig, **{**kwargs, "lam": 0.1})


def test_one_tile_covering_the_grid_is_the_untiled_reconstruction():
    rig = rsocl.Rig.paper_array(4, (24, 28), t_e=1.8e-4, t_r=3.5e-5)
    g, _ = _problem(rig)
    untiled = rsocl.reconstruct(g, rig, iterations=ITER, tune=False)
    tiled = reconstruct_tiled(g, rig, tile=(24, 28), halo=0, iterations=ITER, tune=False)
    np.testing.assert_array_equal(tiled.datacube, untiled.datacube)
    assert tiled.params["device"] == untiled.params["device"]  # the device the task ran on, none being asked for


@pytest.mark.parametrize("name", ["dct", "wavelet"])
def test_a_regularizer_that_is_not_local_is_refused_in_tiles_and_runs_in_one(name):
    """A whole-frame transform denoises each tile differently (0.5-1.7 from the untiled run on data
    in [0, 1]); one tile covering the grid is the run in one piece."""
    rig = rsocl.Rig.paper_array(4, (24, 28), t_e=1.8e-4, t_r=3.5e-5)
    g, _ = _problem(rig)
    with pytest.raises(ValueError, match=rf"regularizer '{name}' is not local .* 4 tiles would each denoise"):
        reconstruct_tiled(g, rig, tile=(12, 14), halo=4, iterations=3, tune=False, regularizer=name)
    whole = reconstruct_tiled(g, rig, tile=(24, 28), halo=0, iterations=3, tune=False, regularizer=name)
    untiled = rsocl.reconstruct(g, rig, iterations=3, tune=False, regularizer=name).datacube
    np.testing.assert_array_equal(whole.datacube, untiled)


def test_sets_and_the_in_process_loop_give_the_same_numbers(monkeypatch):
    rig = rsocl.Rig.paper_array(4, (24, 30), t_e=1.8e-4, t_r=3.5e-5)
    sets = np.stack([_problem(rig, seed=s)[0] for s in range(3)])
    kwargs = dict(tile=(12, 16), halo=8, iterations=10, tune=False)
    local = reconstruct_tiled(sets, rig, **kwargs)
    assert local.datacube.shape == (3, rig.T) + rig.shape
    for s in range(3):
        np.testing.assert_array_equal(local.datacube[s], reconstruct_tiled(sets[s], rig, **kwargs).datacube)
    monkeypatch.setattr(runner_module, "have_dask", lambda: False)
    assert runner_module.Engine().mode == "process"
    np.testing.assert_array_equal(reconstruct_tiled(sets, rig, **kwargs).datacube, local.datacube)


def test_trimmed_keeps_the_subframes_of_every_set(tmp_path):
    delays = (0, 12, 24, 36)  # rows each camera starts late: the ends are trimmed
    rig = Rig([Camera(a, t_e=1.8e-4, t_r=3.5e-5, t_a=d * 3.5e-5) for a, d in zip((0, 90, 180, 270), delays)], (16, 18))
    kept = rig.kept_subframes()
    assert 0 < kept.start and kept.stop < rig.T
    sets = np.stack([_problem(rig, seed=s)[0] for s in range(2)])
    kwargs = dict(tile=(8, 9), halo=4, iterations=3, tune=False)
    results = [reconstruct_tiled(sets, rig, **kwargs)]
    if importlib.util.find_spec("zarr") is not None:
        results.append(reconstruct_tiled(sets, rig, out=tmp_path / "sets.zarr", **kwargs))
    for result in results:
        trimmed = np.asarray(result.trimmed)
        assert trimmed.shape == (2, rig.T_se) + rig.shape
        for s in range(2):
            np.testing.assert_array_equal(trimmed[s], np.asarray(result.datacube[s])[kept])
    one = reconstruct_tiled(sets[1], rig, **kwargs)
    np.testing.assert_array_equal(one.trimmed, one.datacube[kept])


def test_a_failing_tile_is_retried_then_reported_and_the_others_are_kept(monkeypatch):
    rig = rsocl.Rig.paper_array(4, (32, 32), t_e=1.8e-4, t_r=3.5e-5)
    g, _ = _problem(rig)
    solve = runner_module.solve_tile

    def failing(job, *args):
        if job.tile.index == (0, 0):
            raise RuntimeError("out of device memory")
        return solve(job, *args)

    monkeypatch.setattr(runner_module, "solve_tile", failing)
    with pytest.raises(TilesFailed) as info:
        reconstruct_tiled(g, rig, tile=(16, 16), halo=4, iterations=5, retries=1)
    exc = info.value
    assert "tile (0, 0) (rows 0..15, columns 0..15) failed after 2 attempt(s)" in str(exc)
    assert "RuntimeError: out of device memory" in str(exc) and "3 kept" not in str(exc)
    assert str(exc).startswith("1 task(s) failed, 3 solved, held in memory in this exception's result only (nothing")
    result = exc.result
    assert [f.index for f in result.failures] == [(0, 0)]
    assert sorted(p.index for p in result.pieces) == [(0, 1), (1, 0), (1, 1)]
    assert np.all(result.datacube[:, :16, :16] == 0) and np.any(result.datacube[:, 16:, 16:] != 0)


@pytest.mark.parametrize("tune", [False, True])
def test_a_tile_with_every_pixel_saturated_holds_the_interpolation_of_its_clipped_snapshots(tune):
    from rsocl.model.interpolation import interp3d
    from rsocl.model.reference import forward

    rig = rsocl.Rig.paper_array(4, (48, 48), t_e=1.8e-4, t_r=3.5e-5)
    g, _ = _problem(rig)
    g = g.copy()
    g[:, :20, :20] = 1e6  # tile (0, 0) with its halo: every pixel saturated, only lower bounds to fit
    kwargs = dict(iterations=ITER, saturation=1e5, tune=tune)
    untiled = rsocl.reconstruct(g, rig, **kwargs).datacube
    result = reconstruct_tiled(g, rig, tile=(16, 16), halo=4, **kwargs)
    assert not result.failures and len(result.pieces) == 9
    held = next(p for p in result.pieces if p.index == (0, 0))
    assert held.iterations == 0 and held.residual == 0.0
    start = interp3d(g, rig)[:, :16, :16]  # the clipped values as they are: the untiled run's start there
    np.testing.assert_allclose(result.datacube[:, :16, :16], start, rtol=1e-6)
    if tune:  # the untiled run starts there and keeps it: its predictions already meet the lower bounds
        np.testing.assert_allclose(untiled[:, :8, :8], start[:, :8, :8], rtol=1e-6)
    else:  # from zeros, the untiled run is pulled up to the bounds, never down below them
        assert np.all(forward(rig, untiled)[:, :8, :8] >= 0.999e6)
        grid = tile_grid(rig.shape, (16, 16), 4)
        result.pieces = [p for p in result.pieces if max(p.index) == 2]
        _assert_close_to_untiled(result, untiled, grid)  # the tiles whose halo keeps clear of it
    sets = np.stack([np.full_like(g, 1e6), g])
    with pytest.raises(ValueError, match=r"every snapshot pixel of g\[0\] \(set 0\) is >= saturation = 100000.0"):
        reconstruct_tiled(sets, rig, tile=(16, 16), halo=4, **kwargs)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(tile=(0, 8)), r"tile must be \(H, W\) pixels with 1 <= H <= m = 20 and 1 <= W <= n = 24"),
        (dict(tile=(8, 25)), r"tile must be .* 1 <= W <= n = 24, got \(8, 25\)"),
        (dict(tile=(8, 8), halo=-1), r"halo must be a whole number of pixels in \[0, 24\]"),
        (dict(tile=(8, 8), workers=0), "workers must be"),
        (dict(tile=(8, 8), retries=-1), "retries must be a whole number >= 0"),
        (dict(tile=(8, 8), regularizer="nope"), "nope"),
        (dict(tile=(8, 8), lam=-1), "lam must be"),
        (dict(tile=(8, 8), saturation=-1, tune=False), r"saturation must be > 0 \(snapshot units\), got -1"),
        (dict(tile=(8, 8), saturation=float("nan"), tune=False), "saturation must be finite"),
        (dict(tile=(8, 8), saturation="x", tune=False), "saturation must be a finite real number, got 'x'"),
    ],
)
def test_bad_input_names_the_parameter(kwargs, match):
    rig = rsocl.Rig.paper_array(4, (20, 24), t_e=1.8e-4, t_r=3.5e-5)
    g = np.zeros((4, 20, 24))
    if kwargs.get("retries") is not None:
        kwargs["iterations"] = 1
    with pytest.raises(ValueError, match=match):
        reconstruct_tiled(g, rig, **kwargs)
    with pytest.raises(ValueError, match=r"g must have shape \(K, m, n\) = \(4, 20, 24\) or \(S, K, m, n\)"):
        reconstruct_tiled(np.zeros((3, 20, 24)), rig, tile=(8, 8))


def test_bad_retries_leave_no_store_behind(tmp_path):
    pytest.importorskip("zarr")
    rig = rsocl.Rig.paper_array(4, (20, 24), t_e=1.8e-4, t_r=3.5e-5)
    with pytest.raises(ValueError, match="retries must be a whole number >= 0"):
        reconstruct_tiled(np.zeros((4, 20, 24)), rig, tile=(8, 8), retries=-1, tune=False, out=tmp_path / "a.zarr")
    assert not (tmp_path / "a.zarr").exists()


def test_the_fits_message_suggests_float32_only_for_float64(device):
    with pytest.raises(ValueError) as info:
        device.check_fits("x", device.max_alloc_bytes + 1, dtype="float32")
    assert "float32" not in str(info.value) and "tiles" in str(info.value)
    with pytest.raises(ValueError, match="use float32"):
        device.check_fits("x", device.max_alloc_bytes + 1, dtype="float64")


@pytest.mark.slow
def test_plan_proposes_a_tiling_for_the_whole_sensor(capsys, monkeypatch, device):
    from rsocl.cli.main import main

    # a device of PoCL's size (1 GiB largest buffer, 4 GiB in all): the whole sensor does not fit
    # it in one piece (it does fit an 80 GB GPU)
    monkeypatch.setattr(type(device), "max_alloc_bytes", property(lambda self: 2**30))
    monkeypatch.setattr(type(device), "global_mem_bytes", property(lambda self: 4 * 2**30))
    assert main(["plan", "--shape", "1024", "1280", "--t-r-us", "26", "--no-measure"]) == 0
    out = capsys.readouterr().out
    assert "does not fit the device: tile it" in out and "use float32" not in out
    assert "tiling:" in out and "tasks" in out and "per-task device memory" in out
    assert main(["plan", "--shape", "64", "64", "--tile", "32", "32", "--sets", "3", "--iterations", "4"]) == 0
    out = capsys.readouterr().out
    assert "2 x 2 tiles x 3 sets = 12 tasks" in out and "ms/iteration measured on the largest tile" in out
    assert main(["plan", "--shape", "64", "64", "--tile", "65", "32", "--no-measure"]) == 2
    assert "tile must be (H, W)" in capsys.readouterr().err


def _tiling_cost_of_tile_rigs(rig, tile, halo, **kwargs):
    """:func:`rsocl.scale.proposal.tiling_cost` counted on every tile's own rig (:func:`tile_rig`)."""
    from rsocl.solver.memory import memory_need
    from rsocl.solver.request import make_regularizer

    worst, voxels = (0, 0, None, 0), 0
    for t in tile_grid(rig.shape, tile, halo):
        sub = tile_rig(rig, t)
        solved = sub.sampled_range()
        v = (solved.stop - solved.start) * sub.shape[0] * sub.shape[1]
        voxels += v
        if v > worst[3]:
            largest, total = memory_need(
                sub,
                make_regularizer(kwargs.get("regularizer", "tv")),
                **{k: x for k, x in kwargs.items() if k != "regularizer"},
            )
            worst = (total, largest, t, v)
    total, largest, t, v = worst
    return total, largest, voxels, t, v


@pytest.mark.parametrize(
    "rig",
    [
        rsocl.Rig.paper_array(4, (37, 45), t_e=1.8e-4, t_r=3.5e-5),
        Rig(
            [Camera(a, t_e=2.3e-4, t_r=3.1e-5, t_a=t_a) for a, t_a in ((0, 0), (45, 4e-5), (135, 1.1e-4), (250, 0))],
            (34, 39),
            dt=7.3e-5,
            mask="binary",
        ),
        Rig(
            [
                Camera(0, t_e=1e-4, t_r=3e-5, frames=2, t_d=1.2e-3),
                Camera(row_map=np.random.default_rng(3).uniform(0, 50, (30, 41)), t_e=1.5e-4, t_r=3e-5, t_a=2e-5),
            ],
            (30, 41),
        ),
    ],
)
def test_the_proposed_tiling_and_each_tile_s_range_are_those_of_the_tile_s_own_rig(rig, monkeypatch, device):
    from rsocl.scale import proposal

    for tile, halo in (((16, 20), 5), ((7, 9), 0), ((11, 13), 12), (rig.shape, 0)):
        for t in tile_grid(rig.shape, tile, halo):
            sub = tile_rig(rig, t)
            assert rig.sampled_range(t.roi) == sub.sampled_range(), t
            for c in range(rig.C):
                np.testing.assert_array_equal(rig.row_map(c, t.roi), rig.row_map(c)[t.outer_slices])
        for kwargs in (dict(), dict(regularizer="tv", dtype="float64", projection="paper")):
            assert proposal.tiling_cost(rig, tile, halo, **kwargs) == _tiling_cost_of_tile_rigs(
                rig, tile, halo, **kwargs
            )
    assert rig.sampled_range((0, 0) + rig.shape) == rig.sampled_range()
    with pytest.raises(ValueError, match=r"roi must be \(y, x, height, width\) inside the"):
        rig.sampled_range((1, 0) + rig.shape)
    budget = proposal.tiling_cost(rig, (16, 16), 4)[0]  # the smallest candidate just fits
    proposed = proposal.propose_tiling(rig, halo=4, device=device, budget_bytes=budget, measure=False)
    monkeypatch.setattr(proposal, "tiling_cost", _tiling_cost_of_tile_rigs)
    assert proposed == proposal.propose_tiling(rig, halo=4, device=device, budget_bytes=budget, measure=False)
    assert proposed.tile == (16, 16)
