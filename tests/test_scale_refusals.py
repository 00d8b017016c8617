"""What the scale-out checks refuse, and when: a store of another rig (its row maps included), an ``out``
that is not a store of the same rig, tiling and dtype, or of other settings known before the search (before
the input is read), a tile too large for the device (the one modelling the most sub-frames), an interrupt
before the store is checked, and ``--halo`` on a stream of windows run in one piece."""

import re

import numpy as np
import pytest

import rsocl
from rsocl.cli.main import main
from rsocl.files.hdf5 import save_capture
from rsocl.model.scenes import builtin_scene
from rsocl.scale import reconstruct_tiled
from rsocl.scale import runner as runner_module
from rsocl.scale import tiled as tiled_module
from rsocl.scale.store import StoreSpec, load_store, prepare_store, store_id

zarr = pytest.importorskip("zarr")

KW = dict(tile=(16, 16), halo=4, iterations=3, tune=False, lam=0.05, eta=1.0)


def _rig(row_map, shape=(32, 32)):
    cameras = [rsocl.Camera(row_map=row_map, t_e=1.8e-4, t_r=3.5e-5)]
    cameras += [rsocl.Camera(angle=a, t_e=1.8e-4, t_r=3.5e-5) for a in (90, 180, 270)]
    return rsocl.Rig(cameras, shape)


def _two_rigs(shape=(32, 32)):
    """Two rigs that differ only in camera 0's row map (recalibrated: read bottom to top), same ``T``."""
    rows = np.repeat(np.arange(shape[0], dtype=float)[:, None], shape[1], axis=1)
    a, b = _rig(rows, shape), _rig(np.flipud(rows), shape)
    assert a.T == b.T and a.to_dict()["cameras"][1:] == b.to_dict()["cameras"][1:] and a != b
    return a, b


class _Read(Exception):
    """Raised by the spies standing for the input scan and the tuning search."""


def _unread(monkeypatch):
    """The input scan and the tuning search, replaced by spies that raise :class:`_Read`."""

    def read(*args, **kwargs):
        raise _Read

    monkeypatch.setattr(tiled_module, "scan", read)
    monkeypatch.setattr(tiled_module, "tune_tiles", read)


def test_a_store_is_not_resumed_with_a_rig_whose_row_maps_changed(tmp_path):
    a, b = _two_rigs()
    g = rsocl.RollingShutterOperator(a).forward(builtin_scene(a.shape, a.T, seed=1))
    out = tmp_path / "rec.zarr"
    reconstruct_tiled(g, a, out=out, **KW)
    before, stored = store_id(out), np.asarray(load_store(out).datacube[...])
    message = re.escape(f"out: {str(out)!r} holds another reconstruction (it differs in rig row maps)")
    with pytest.raises(ValueError, match=message):
        reconstruct_tiled(g, b, out=out, **KW)
    # the same check where the store is opened to be resumed, with the input's digest and the parameters
    params, digest = load_store(out).params, zarr.open_group(str(out), mode="r").attrs["input_digest"]
    same = StoreSpec(a, (16, 16), 4, (2, 2), None, "float32", params, digest)
    assert prepare_store(out, same)[0].all()
    with pytest.raises(ValueError, match=message):
        prepare_store(out, StoreSpec(b, (16, 16), 4, (2, 2), None, "float32", params, digest))
    assert store_id(out) == before and np.array_equal(np.asarray(load_store(out).datacube[...]), stored)


def test_a_store_written_before_stores_recorded_the_rig_digest_is_compared_by_its_row_maps(tmp_path):
    a, b = _two_rigs()
    g = rsocl.RollingShutterOperator(a).forward(builtin_scene(a.shape, a.T, seed=1))
    out = tmp_path / "rec.zarr"
    whole = reconstruct_tiled(g, a, out=out, **KW)
    group = zarr.open_group(str(out), mode="r+")
    group.attrs.put({k: v for k, v in group.attrs.items() if k != "rig_digest"})
    group["tiles"][0, 1, 1] = np.zeros(6)
    with pytest.raises(ValueError, match=r"holds another reconstruction \(it differs in rig row maps\)"):
        reconstruct_tiled(g, b, out=out, **KW)
    resumed = reconstruct_tiled(g, a, out=out, **KW)  # its own rig: resumed
    assert [p.index for p in resumed.pieces] == [(1, 1)] and load_store(out).complete
    np.testing.assert_array_equal(np.asarray(resumed.datacube[...]), np.asarray(whole.datacube[...]))


def test_the_memory_check_costs_the_tile_modelling_the_most_subframes(monkeypatch, device):
    from rsocl.scale.tiles import tile_grid, tile_rig
    from rsocl.solver.memory import memory_need
    from rsocl.solver.pipeline import make_regularizer

    shape, tile, halo = (96, 96), (32, 32), 8
    rig = rsocl.Rig.paper_array(4, shape, t_e=1.8e-4, t_r=3.5e-5)
    g = rsocl.RollingShutterOperator(rig).forward(builtin_scene(shape, rig.T, seed=0))
    grid = tile_grid(shape, tile, halo)
    reg = make_regularizer("tv")
    need = {t.index: memory_need(tile_rig(rig, t), reg, dtype="float32", projection="exact")[1] for t in grid}
    widest = max(grid, key=lambda t: t.outer_shape[0] * t.outer_shape[1]).index  # the centre tile
    assert need[widest] < max(need.values())  # an edge tile models more sub-frames
    memory = (need[widest] + max(need.values())) // 2  # the centre tile fits, the edge tiles do not
    monkeypatch.setattr(type(device), "global_mem_bytes", property(lambda self: int(memory)))
    ran = []

    def solve(job, *args):
        ran.append(job.tile.index)
        raise RuntimeError("a tile ran")

    monkeypatch.setattr(runner_module, "solve_tile", solve)
    with pytest.raises(ValueError, match=r"^tile: a tile of 32x32 \(tile \(\d, \d\) .*choose a smaller tile"):
        reconstruct_tiled(g, rig, tile=tile, halo=halo, iterations=3, tune=False, retries=0, device=device)
    assert ran == []


@pytest.mark.parametrize(
    "first, second, match",
    [
        (None, {}, r"exists and is not a Zarr store"),  # a folder of the user's files
        ("group", {}, r"is not an rsocl reconstruction store; choose another path"),
        ({}, {"tile": (8, 16)}, r"holds another reconstruction \(it differs in tiling\)"),
        ({}, {"halo": 2}, r"holds another reconstruction \(it differs in tiling\)"),
        ({}, {"dtype": "float64"}, r"holds another reconstruction \(it differs in dtype\)"),
        ({}, {"rig": "other"}, r"holds another reconstruction \(it differs in rig, tiling\)"),
        ({}, {"rig": "row maps"}, r"holds another reconstruction \(it differs in rig row maps\)"),
    ],
)
def test_an_out_holding_anything_but_this_rig_tiling_and_dtype_is_refused_before_the_input_is_read(
    tmp_path, monkeypatch, first, second, match, has_fp64
):
    if second.get("dtype") == "float64" and not has_fp64:
        pytest.skip("the device has no float64")
    a, b = _two_rigs()
    g = rsocl.RollingShutterOperator(a).forward(builtin_scene(a.shape, a.T, seed=1))
    out = tmp_path / "rec.zarr"
    out.mkdir()
    if first is None:
        (out / "notes.txt").write_text("my notes, not a store\n")
    elif first == "group":
        zarr.open_group(str(out), mode="w").attrs["mine"] = 1
    else:
        out.rmdir()
        reconstruct_tiled(g, a, out=out, **KW)
    held = sorted(p.relative_to(out) for p in out.rglob("*"))
    _unread(monkeypatch)
    rig, snapshots = a, g
    if second.get("rig") == "row maps":
        rig = b
    elif second.get("rig"):
        rig = rsocl.Rig.paper_array(4, (32, 40), t_e=1.8e-4, t_r=3.5e-5)
        snapshots = np.zeros((rig.n_channels,) + rig.shape)
    kwargs = {**KW, **{k: v for k, v in second.items() if k != "rig"}}
    with pytest.raises(ValueError, match=f"^out: {re.escape(repr(str(out)))} {match}"):
        reconstruct_tiled(snapshots, rig, out=out, **kwargs)
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == held


@pytest.fixture
def capture(tmp_path):
    """A capture file of a 32x32 paper array."""
    rig = rsocl.Rig.paper_array(4, (32, 32), t_e=1.8e-4, t_r=3.5e-5)
    truth = builtin_scene(rig.shape, rig.T, seed=2)
    path = tmp_path / "cap.h5"
    save_capture(path, rsocl.RollingShutterOperator(rig).forward(truth), rig, truth=truth)
    return path


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--tile", "8", "16"], r"holds another reconstruction \(it differs in tiling\)"),
        (["--tile", "16", "16", "--halo", "2"], r"holds another reconstruction \(it differs in tiling\)"),
        (["--dtype", "float64"], r"holds another reconstruction \(it differs in dtype\)"),  # the tile not given
        ([], r"holds another reconstruction \(it differs in rig\)"),  # another capture's store
        (["--not-a-store"], r"exists and is not a Zarr store"),
    ],
)
def test_the_cli_refuses_a_foreign_out_naming_it_before_the_input_is_read(
    capture, tmp_path, monkeypatch, capsys, extra, match
):
    out = tmp_path / "rec.zarr"
    common = ["--iterations", "2", "--fixed", "--quiet", "--no-truth"]
    if extra == ["--not-a-store"]:
        out.mkdir()
        (out / "notes.txt").write_text("my notes\n")
        extra = ["--tile", "16", "16"]
    elif extra == []:
        other = rsocl.Rig.paper_array(4, (32, 32), t_e=1.8e-4, t_r=3.0e-5)
        save_capture(tmp_path / "other.h5", np.zeros((other.n_channels,) + other.shape), other)
        assert main(["reconstruct", str(tmp_path / "other.h5"), "--out", str(out), "--tile", "16", "16", *common]) == 0
    else:
        assert main(["reconstruct", str(capture), "--out", str(out), "--tile", "16", "16", *common]) == 0
    held = sorted((p.relative_to(out), p.stat().st_mtime_ns) for p in out.rglob("*"))
    capsys.readouterr()
    calls = []
    monkeypatch.setattr(tiled_module, "scan", lambda *a: calls.append(a))
    monkeypatch.setattr(tiled_module, "tune_tiles", lambda *a: calls.append(a))
    assert main(["reconstruct", str(capture), "--out", str(out), *common, *extra]) == 2
    err = capsys.readouterr().err
    assert re.match(f"rsocl reconstruct: error: --out: {re.escape(repr(str(out)))} {match}", err), err
    assert not calls and sorted((p.relative_to(out), p.stat().st_mtime_ns) for p in out.rglob("*")) == held


def test_an_interrupt_before_the_store_is_checked_says_nothing_was_computed(capture, tmp_path, capsys, monkeypatch):
    out = tmp_path / "rec.zarr"
    argv = ["reconstruct", str(capture), "--out", str(out), "--tile", "16", "16", "--quiet", "--no-truth"]
    assert main(argv + ["--iterations", "2", "--fixed"]) == 0
    held, marks = store_id(out), load_store(out).tiles.copy()
    capsys.readouterr()

    def ctrl_c(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(tiled_module, "tune_tiles", ctrl_c)  # Ctrl-C where the search runs, its input unchecked
    assert main(argv + ["--iterations", "2", "--fixed"]) == 130
    assert capsys.readouterr().err == (
        f"rsocl reconstruct: interrupted: nothing computed; the store at {out} (not checked yet) is unchanged\n"
    )
    assert store_id(out) == held and np.array_equal(load_store(out).tiles, marks)
    fresh = tmp_path / "fresh.zarr"
    with pytest.raises(KeyboardInterrupt, match=f"^nothing computed; no store made at {re.escape(str(fresh))}$"):
        reconstruct_tiled(np.zeros((4, 32, 32)), load_store(out).rig, out=fresh, tile=(16, 16))
    assert not fresh.exists()


def test_halo_on_a_stream_of_windows_without_tiles_is_refused(tmp_path, capsys):
    from rsocl.model.rig import Camera, Rig

    shape, t_r = (16, 16), 3.5e-5
    rig = Rig([Camera(a, t_e=1.8e-4, t_r=t_r, t_d=shape[0] * t_r, frames=3) for a in (0, 90, 180, 270)], shape)
    truth = builtin_scene(shape, rig.T, seed=2)
    save_capture(tmp_path / "cap.h5", rsocl.RollingShutterOperator(rig).forward(truth), rig, truth=truth)
    out = tmp_path / "s.h5"
    argv = ["reconstruct", str(tmp_path / "cap.h5"), "--out", str(out), "--window", "2", "--iterations", "2"]
    assert main(argv + ["--fixed", "--quiet", "--halo", "4"]) == 2
    assert capsys.readouterr().err == (
        "rsocl reconstruct: error: --halo applies to a run in tiles (--tile H W; also --sets, --workers, "
        "--scheduler, a Zarr --out or a capture too large for the device) or windows in tiles (--window with "
        "--tile); without --tile each window of --window runs in one piece, where --halo would be ignored\n"
    )
    assert not out.exists()
    assert main(argv + ["--fixed", "--quiet", "--halo", "4", "--tile", "8", "16"]) == 0  # windows in tiles


def _spied(monkeypatch):
    """The input scan and the tuning search, replaced by spies that record their calls and raise :class:`_Read`."""
    calls = []

    def read(*args, **kwargs):
        calls.append(args)
        raise _Read

    monkeypatch.setattr(tiled_module, "scan", read)
    monkeypatch.setattr(tiled_module, "tune_tiles", read)
    return calls


@pytest.mark.parametrize(
    "second, differ",
    [
        ({"iterations": 4}, "params.iterations"),
        ({"lam": 0.1}, "params.lam"),
        ({"eta": 0.5}, "params.eta"),
        ({"quality": "best"}, "params.quality"),
        ({"projection": "paper"}, "params.projection"),
        ({"saturation": 1e6}, "params.saturation"),
        ({"regularizer_options": {"temporal_weight": 10.0}}, "params.regularizer_options.temporal_weight"),
        ({"tv_iterations": 5}, "params.regularizer_options.iterations"),
        ({"tune": True}, "params.start"),  # a search would run: zero start in the store, the interpolation here
        ({"tune": True, "quality": "best", "regularizer_options": {"step": 0.5}}, "params.quality, "),
    ],
)
def test_a_store_of_other_settings_is_refused_before_the_input_is_read_and_the_search(
    tmp_path, monkeypatch, second, differ
):
    a, _ = _two_rigs()
    g = rsocl.RollingShutterOperator(a).forward(builtin_scene(a.shape, a.T, seed=1))
    out = tmp_path / "rec.zarr"
    reconstruct_tiled(g, a, out=out, **KW)
    held = sorted((p.relative_to(out), p.stat().st_mtime_ns) for p in out.rglob("*"))
    calls = _spied(monkeypatch)
    message = f"^out: {re.escape(repr(str(out)))} holds another reconstruction \\(it differs in {re.escape(differ)}"
    with pytest.raises(ValueError, match=message) as caught:
        reconstruct_tiled(g, a, out=out, **{**KW, **second})
    assert calls == [] and sorted((p.relative_to(out), p.stat().st_mtime_ns) for p in out.rglob("*")) == held
    assert "params.device" not in str(caught.value) and "params.tuning" not in str(caught.value)


def test_a_tuned_store_is_refused_on_known_settings_before_the_search_and_resumed_by_the_same_run(
    tmp_path, monkeypatch
):
    a, _ = _two_rigs()
    g = rsocl.RollingShutterOperator(a).forward(builtin_scene(a.shape, a.T, seed=1))
    out = tmp_path / "rec.zarr"
    tuned = dict(tile=(16, 16), halo=4, iterations=3, quality="fast", regularizer_options={"step": 0.8})
    whole = reconstruct_tiled(g, a, out=out, **tuned)
    assert whole.tuning is not None and whole.params["start"] == "interp3d"
    group = zarr.open_group(str(out), mode="r+")
    group["tiles"][0, 1, 0] = np.zeros(6)  # a tile left undone
    real_scan, real_tune = tiled_module.scan, tiled_module.tune_tiles
    calls = _spied(monkeypatch)
    for other, differ in [
        ({"iterations": 4}, "params.iterations"),
        ({"regularizer_options": {"step": 0.7}}, "params.regularizer_options.step"),
        ({"tune": False}, "params.lam, params.start"),  # the fixed run's lam: not the one the search chose
    ]:
        with pytest.raises(ValueError, match=rf"holds another reconstruction \(it differs in {re.escape(differ)}\)"):
            reconstruct_tiled(g, a, out=out, **{**tuned, **other})
    assert calls == []
    monkeypatch.setattr(tiled_module, "scan", real_scan)
    monkeypatch.setattr(tiled_module, "tune_tiles", real_tune)
    resumed = reconstruct_tiled(g, a, out=out, **tuned)  # the same run: the undone tile only, the same choice
    assert [p.index for p in resumed.pieces] == [(1, 0)] and resumed.skipped == 3 and load_store(out).complete
    assert resumed.tuning.chosen == whole.tuning.chosen
    np.testing.assert_array_equal(np.asarray(resumed.datacube[...]), np.asarray(whole.datacube[...]))


def test_the_cli_refuses_a_store_of_other_settings_before_the_search(capture, tmp_path, monkeypatch, capsys):
    out = tmp_path / "rec.zarr"
    argv = ["reconstruct", str(capture), "--out", str(out), "--tile", "16", "16", "--quiet", "--no-truth"]
    assert main(argv + ["--iterations", "2", "--fixed"]) == 0
    held = sorted((p.relative_to(out), p.stat().st_mtime_ns) for p in out.rglob("*"))
    capsys.readouterr()
    calls = _spied(monkeypatch)
    assert main(argv + ["--iterations", "2", "--quality", "best"]) == 2  # tuned, on another rung
    err = capsys.readouterr().err
    assert re.search(r"holds another reconstruction \(it differs in params\.quality, params\.start\)", err), err
    assert calls == [] and sorted((p.relative_to(out), p.stat().st_mtime_ns) for p in out.rglob("*")) == held
    group = zarr.open_group(str(out), mode="r+")
    group["tiles"][0, 0, 1] = np.zeros(6)
    monkeypatch.undo()
    assert main(argv + ["--iterations", "2", "--fixed"]) == 0  # the same command resumes it
    assert load_store(out).complete
