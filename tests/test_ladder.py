"""The quality ladder (rsocl.solver.ladder): every rung at least the interpolation, iterations from
the data, the search's share of the time, the static-part fix, the crop of large frames."""

from dataclasses import replace

import numpy as np
import pytest

import rsocl
import rsocl.solver.ladder as ladder
from rsocl.analysis.metrics import psnr
from rsocl.model import reference as ref
from rsocl.model.interpolation import interp3d
from rsocl.model.scenes import builtin_scene
from rsocl.solver.static import static_mask

SHAPE = (32, 32)


def _rig(shape=SHAPE):
    return rsocl.Rig.paper_array(4, shape, t_e=1.8e-4, t_r=3.5e-5)


def _moving(rig):
    return builtin_scene(rig.shape, rig.T, dtype=np.float64)


def _still(rig):
    """The built-in scene's first sub-frame held still: the interpolation is exact (to float32)."""
    return np.repeat(builtin_scene(rig.shape, 1, dtype=np.float64), rig.T, axis=0)


def _drifting(rig):
    """The built-in scene's first sub-frame held still, its brightness drifting by a few percent."""
    return _still(rig) * np.linspace(0.97, 1.03, rig.T)[:, None, None]


def _snapshots(rig, truth):
    return ref.forward(rig, truth).astype(np.float32)


@pytest.mark.parametrize("quality", ladder.QUALITIES)
@pytest.mark.parametrize("scene", [_moving, _still, _drifting])
def test_every_rung_is_at_least_the_interpolation(quality, scene):
    """On a still scene the interpolation is exact, and the rungs keep it to float32 precision; on the
    drifting one the fast rung (no static fix, one candidate) may lose a little of it, within the
    issue's 0.3 dB of ``interp3d`` (docs/quality_ladder.md)."""
    rig = _rig()
    truth = scene(rig)
    g = _snapshots(rig, truth)
    floor = min(psnr(interp3d(g, rig), truth), 100.0)
    if scene is _drifting and quality == "fast":
        floor -= 0.3
    result = rsocl.reconstruct(g, rig, quality=quality)
    assert result.params["quality"] == quality and result.params["start"] == "interp3d"
    assert result.iterations == ladder.RUNGS[quality].iterations
    assert psnr(result.datacube, truth) >= floor


def test_a_rung_sets_its_search():
    rig = _rig()
    g = _snapshots(rig, _moving(rig))
    fast = rsocl.reconstruct(g, rig, quality="fast").params["tuning"]
    assert len(fast["candidates"]) == 1 and set(fast["chosen"]) == {"lam"}
    assert fast["iterations_per_candidate"] == max(10, round(0.25 * 100 / fast["folds"]))
    best = rsocl.reconstruct(g, rig, quality="best", iterations=20).params["tuning"]
    assert best["folds"] >= 2 and "temporal_weight" in best["chosen"] and len(best["candidates"]) > 3


def test_a_large_frame_is_searched_on_its_centre_block():
    rig = _rig((96, 96))
    g = _snapshots(rig, builtin_scene(rig.shape, rig.T))
    balanced = rsocl.reconstruct(g, rig, iterations=20).params["tuning"]
    assert balanced["folds"] >= 2 and 0 < balanced["held_out_pixels"] <= 4 * 48 * 48
    whole = rsocl.reconstruct(g, rig, iterations=20, quality="best").params["tuning"]
    assert whole["held_out_pixels"] > 4 * 48 * 48


def test_auto_iterations_stop_when_the_residual_settles_and_say_how_many():
    rig = _rig()
    g = _snapshots(rig, _moving(rig))
    result = rsocl.reconstruct(g, rig, iterations="auto")
    ran = result.params["iterations_run"]
    assert ladder.AUTO_MIN <= ran < ladder.AUTO_CAP and ran == result.iterations
    assert result.params["auto_iterations"] is True and result.params["iterations"] == ladder.AUTO_CAP
    # the last record is the returned (blended, fixed) estimate's; a run without them shows the rule
    plain = rsocl.reconstruct(g, rig, iterations="auto", tune=False, x0="interp3d")
    residual = list(plain.history["residual"])
    ran = plain.params["iterations_run"]
    assert ran == len(residual) < ladder.AUTO_CAP
    assert ladder.auto_stop(residual) and not any(ladder.auto_stop(residual[:i]) for i in range(ran))


def test_auto_stop_needs_the_fewest_iterations_and_a_settled_window():
    assert not ladder.auto_stop([1.0] * (ladder.AUTO_MIN - 1))
    assert ladder.auto_stop([1.0] * ladder.AUTO_MIN)
    falling = list(np.linspace(1.0, 0.5, 60))
    assert not ladder.auto_stop(falling)
    assert not ladder.auto_stop([[1.0, x] for x in falling])  # a batch stops when every set settled


def test_the_search_share_of_the_time_is_in_the_result():
    rig = _rig()
    g = _snapshots(rig, _moving(rig))
    tuned = rsocl.reconstruct(g, rig, iterations=20)
    assert 0 < tuned.search_seconds < tuned.seconds
    assert tuned.seconds >= tuned.search_seconds + tuned.history["time"][-1]
    assert tuned.params["seconds"] == tuned.seconds and tuned.params["search_seconds"] == tuned.search_seconds
    fixed = rsocl.reconstruct(g, rig, iterations=20, tune=False)
    assert fixed.params["tuning"] is None and fixed.search_seconds < fixed.seconds


def _without_static_fix(monkeypatch):
    monkeypatch.setitem(ladder.RUNGS, "balanced", replace(ladder.RUNGS["balanced"], static=0.0))


def test_the_static_fix_brings_a_still_background_back(monkeypatch):
    rig = _rig()
    truth = _moving(rig)
    g = _snapshots(rig, truth)
    fixed = rsocl.reconstruct(g, rig)
    _without_static_fix(monkeypatch)
    plain = rsocl.reconstruct(g, rig)
    still = np.all(truth == truth[:1], axis=0) & static_mask(g)
    assert fixed.params["static_pixels"] == int(static_mask(g).sum()) > 0 and still.any()
    assert np.abs(fixed.datacube - truth)[:, still].mean() < np.abs(plain.datacube - truth)[:, still].mean()
    assert psnr(fixed.datacube, truth) >= psnr(plain.datacube, truth) - 0.1


def test_the_static_fix_leaves_a_moving_scene_alone(monkeypatch):
    rig = _rig()
    rng = np.random.default_rng(0)
    texture = rng.random((SHAPE[0], SHAPE[1] + rig.T))
    truth = np.stack([texture[:, t : t + SHAPE[1]] for t in range(rig.T)])  # every pixel changes
    g = _snapshots(rig, truth)
    assert not static_mask(g).any()
    fixed = rsocl.reconstruct(g, rig, iterations=20)
    _without_static_fix(monkeypatch)
    plain = rsocl.reconstruct(g, rig, iterations=20)
    assert fixed.params["static_pixels"] == 0
    np.testing.assert_array_equal(fixed.datacube, plain.datacube)


def test_a_batch_gets_the_static_fix_per_set():
    rig = _rig()
    g = np.stack([_snapshots(rig, _moving(rig)), _snapshots(rig, _still(rig))])
    result = rsocl.reconstruct(g, rig, iterations=20)
    assert result.params["static_pixels"] == [int(static_mask(one).sum()) for one in g]
    one = rsocl.reconstruct(
        g[1], rig, iterations=20, tune=rsocl.solver.crossval.Tuning.from_params(result.params["tuning"])
    )
    np.testing.assert_allclose(result.datacube[1], one.datacube, atol=1e-5)


@pytest.mark.parametrize(
    "argv, quality",
    [([], "balanced"), (["--quality", "best"], "best"), (["--fast"], "fast"), (["--quality", "fast"], "fast")],
)
def test_the_command_line_runs_a_rung_and_says_its_times(tmp_path, capsys, argv, quality):
    from rsocl.cli.main import main
    from rsocl.files.hdf5 import load_reconstruction, save_capture

    rig = _rig((16, 16))
    cap, out = tmp_path / "cap.h5", tmp_path / "rec.h5"
    save_capture(cap, _snapshots(rig, _moving(rig)), rig)
    assert main(["reconstruct", str(cap), "--out", str(out), "--iterations", "12", "--quiet", *argv]) == 0
    line = capsys.readouterr().out
    params = load_reconstruction(out).params
    assert params["quality"] == quality and params["tuning"] is not None and params["start"] == "interp3d"
    assert 0 < params["search_seconds"] < params["seconds"]
    assert (
        "12 iterations in " in line
        and f"(search {params['search_seconds']:.2f} s of {params['seconds']:.2f} s total)" in line
    )


def test_the_command_line_takes_auto_iterations(tmp_path, capsys):
    from rsocl.cli.main import main
    from rsocl.files.hdf5 import load_reconstruction, save_capture

    rig = _rig((16, 16))
    cap, out = tmp_path / "cap.h5", tmp_path / "rec.h5"
    save_capture(cap, _snapshots(rig, _moving(rig)), rig)
    assert main(["reconstruct", str(cap), "--out", str(out), "--iterations", "auto", "--quiet"]) == 0
    params = load_reconstruction(out).params
    assert params["auto_iterations"] is True and params["iterations_run"] < ladder.AUTO_CAP
    assert f"{params['iterations_run']} iterations in " in capsys.readouterr().out


def test_every_rung_gives_one_camera_the_regularizers_preset():
    rig = rsocl.Rig([rsocl.Camera(0, t_e=1.8e-4, t_r=3.5e-5)], (16, 16))
    g = _snapshots(rig, _moving(rig))
    for quality in ladder.QUALITIES:
        result = rsocl.reconstruct(g, rig, quality=quality, iterations=12)
        assert result.params["tuning"]["preset"] == {"temporal_weight": 10.0}
        assert result.params["regularizer_options"]["temporal_weight"] == 10.0


def test_sets_and_tiles_follow_the_rung():
    from rsocl.scale import reconstruct_tiled
    from rsocl.solver.sets import reconstruct_sets

    rig = _rig((16, 16))
    g = np.stack([_snapshots(rig, _moving(rig)), _snapshots(rig, _still(rig))])
    sets = reconstruct_sets(g, rig, quality="fast", batch=1)
    assert sets.params["quality"] == "fast" and sets.iterations == ladder.RUNGS["fast"].iterations
    assert len(sets.params["tuning"]["candidates"]) == 1 and sets.search_seconds < sets.seconds
    one = rsocl.reconstruct(g[0], rig, quality="fast")
    np.testing.assert_allclose(sets.datacube[0], one.datacube, atol=1e-5)
    tiled = reconstruct_tiled(g[1], rig, tile=(16, 16), halo=0, quality="best", iterations=12)
    alone = rsocl.reconstruct(g[1], rig, quality="best", iterations=12)
    assert tiled.params["quality"] == "best" and tiled.tuning.folds == alone.params["tuning"]["folds"] >= 2
    np.testing.assert_allclose(tiled.datacube, alone.datacube, atol=1e-5)


def test_rsocl_bench_sweeps_the_rungs():
    from rsocl.bench.point import BenchPoint
    from rsocl.bench.run import parse_sweep, run_bench

    assert parse_sweep("quality=fast,best") == ("quality", ["fast", "best"])
    with pytest.raises(ValueError, match="quality must be one of fast, balanced, best"):
        BenchPoint(quality="medium")
    result = run_bench(BenchPoint(shape=16), ["quality"], progress=False, repeat_default=False, baseline=False)
    rows = {row["label"]: row for row in result.rows}
    assert set(rows) == {"default", "quality fast", "quality balanced", "quality best"}
    assert rows["quality fast"]["iterations"] == ladder.RUNGS["fast"].iterations
    assert all(5 < row["psnr"] < 60 and row["seconds"] > 0 for row in rows.values())
