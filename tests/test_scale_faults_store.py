"""A Zarr store removed and built again at the same path, in one process: each run writes through its
own store's arrays (the tasks carry the store's identity), never through arrays opened on the old one."""

import shutil

import numpy as np
import pytest

import rsocl
from rsocl.model.scenes import builtin_scene
from rsocl.scale import reconstruct_tiled
from rsocl.scale import store as store_module
from rsocl.scale.store import load_store, store_id
from rsocl.scale.tiled import TilesFailed

zarr = pytest.importorskip("zarr")


def _problem(shape=(24, 24)):
    rig = rsocl.Rig.paper_array(4, shape, t_e=1.8e-4, t_r=3.5e-5)
    return rig, rsocl.RollingShutterOperator(rig).forward(builtin_scene(shape, rig.T, seed=3))


@pytest.mark.parametrize(
    "first, second",
    [
        (dict(tile=(8, 8)), dict(tile=(16, 16), dtype="float64")),  # the QA reproducer
        (dict(tile=(8, 8)), dict(tile=(12, 12))),  # another tile
        (dict(tile=(12, 12)), dict(tile=(12, 12), dtype="float64")),  # another dtype, same chunks' grid
    ],
)
def test_a_store_built_again_at_the_same_path_is_written_through_its_own_arrays(tmp_path, first, second):
    rig, g = _problem()
    kwargs = dict(halo=4, iterations=3, tune=False)
    out = tmp_path / "rec.zarr"
    reconstruct_tiled(g, rig, out=out, **kwargs, **first)
    old = store_id(out)
    shutil.rmtree(out)  # as "holds another reconstruction ... remove it or choose another path" says
    result = reconstruct_tiled(g, rig, out=out, **kwargs, **second)
    assert store_id(out) not in (None, old)
    stored = load_store(out)
    assert stored.complete and stored.tiling["tile"] == list(second["tile"])
    expected = reconstruct_tiled(g, rig, **kwargs, **second).datacube
    assert np.asarray(stored.datacube[...]).dtype == expected.dtype
    np.testing.assert_array_equal(np.asarray(result.datacube[...]), expected)
    resumed = reconstruct_tiled(g, rig, out=out, **kwargs, **second)  # complete: nothing is redone
    assert resumed.skipped == len(stored.tiles[0].reshape(-1, 6)) and not resumed.pieces


def test_a_task_refuses_to_write_into_a_store_other_than_the_one_its_run_prepared(tmp_path, monkeypatch):
    rig, g = _problem()
    out = tmp_path / "rec.zarr"
    prepare = store_module.prepare_store

    def replaced_after_preparing(path, spec, name="out"):
        return prepare(path, spec, name)[0], "0" * 32  # the id of a store other than the one at path

    monkeypatch.setattr(store_module, "prepare_store", replaced_after_preparing)
    with pytest.raises(TilesFailed) as info:
        reconstruct_tiled(g, rig, out=out, tile=(12, 12), halo=4, iterations=3, tune=False, retries=0)
    text = str(info.value)
    assert text.startswith("4 task(s) failed, 0 kept in ") and "was removed or replaced by another one" in text
    assert not np.any(load_store(out).tiles[..., 0]) and not np.any(np.asarray(load_store(out).datacube[...]))
    monkeypatch.undo()
    resumed = reconstruct_tiled(g, rig, out=out, tile=(12, 12), halo=4, iterations=3, tune=False)
    assert len(resumed.pieces) == 4 and load_store(out).complete


def test_a_store_written_before_stores_had_an_identity_is_resumed(tmp_path):
    rig, g = _problem()
    kwargs = dict(tile=(12, 12), halo=4, iterations=3, tune=False)
    out = tmp_path / "rec.zarr"
    whole = reconstruct_tiled(g, rig, out=out, **kwargs)
    group = zarr.open_group(str(out), mode="r+")
    group.attrs.put({k: v for k, v in group.attrs.items() if k != "store_id"})
    group["tiles"][0, 1, 0] = np.zeros(6)
    assert store_id(out) is None
    resumed = reconstruct_tiled(g, rig, out=out, **kwargs)
    assert [p.index for p in resumed.pieces] == [(1, 0)] and load_store(out).complete
    np.testing.assert_array_equal(np.asarray(resumed.datacube[...]), np.asarray(whole.datacube[...]))


def test_prepare_store_gives_the_id_of_the_store_it_made_or_checked(tmp_path, monkeypatch):
    # the id the tasks carry comes from the same step that made or checked the store, not a later read
    rig, g = _problem()
    out = tmp_path / "rec.zarr"
    prepare, given = store_module.prepare_store, []

    def spy(path, spec, name="out"):
        result = prepare(path, spec, name)
        given.append(result[1])
        return result

    monkeypatch.setattr(store_module, "prepare_store", spy)
    kwargs = dict(tile=(12, 12), halo=4, iterations=3, tune=False)
    reconstruct_tiled(g, rig, out=out, **kwargs)  # made
    resumed = reconstruct_tiled(g, rig, out=out, **kwargs)  # checked: every tile already there
    assert given == [store_id(out)] * 2 and given[0] is not None and resumed.skipped == 4
