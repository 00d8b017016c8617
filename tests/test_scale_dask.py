"""Tiles and sets on a dask.distributed LocalCluster (127.0.0.1 only) and in Zarr stores.

One cluster of 2 worker processes serves the whole module (starting one costs seconds).
"""

import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import rsocl
from rsocl.model.scenes import builtin_scene
from rsocl.scale import reconstruct_tiled
from rsocl.scale.store import load_store
from rsocl.scale.tiled import TilesFailed

distributed = pytest.importorskip("distributed")
zarr = pytest.importorskip("zarr")


@pytest.fixture(scope="module")
def cluster():
    cluster = distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address="127.0.0.1:0",
        silence_logs=logging.ERROR,
    )
    client = distributed.Client(cluster)
    yield cluster, client
    client.close()
    cluster.close()


def _problem(shape, sets=None, seed=0):
    rig = rsocl.Rig.paper_array(4, shape, t_e=1.8e-4, t_r=3.5e-5)
    op = rsocl.RollingShutterOperator(rig)
    if sets is None:
        return rig, op.forward(builtin_scene(shape, rig.T, seed=seed))
    return rig, np.stack([op.forward(builtin_scene(shape, rig.T, seed=seed + s)) for s in range(sets)])


def test_local_and_distributed_schedulers_give_the_same_numbers(cluster):
    rig, g = _problem((30, 36), sets=2)
    kwargs = dict(tile=(15, 18), halo=6, iterations=8, tune=False)
    local = reconstruct_tiled(g, rig, **kwargs)
    remote = reconstruct_tiled(g, rig, scheduler=cluster[0].scheduler_address, **kwargs)
    assert remote.datacube.shape == (2, rig.T) + rig.shape and len(remote.pieces) == 8
    assert len({p.process for p in remote.pieces}) >= 1 and all(p.process != os.getpid() for p in remote.pieces)
    np.testing.assert_array_equal(remote.datacube, local.datacube)


def test_each_worker_keeps_one_opencl_context(cluster):
    rig, g = _problem((24, 24))
    reconstruct_tiled(g, rig, tile=(8, 8), halo=4, iterations=2, scheduler=cluster[0].scheduler_address)

    def contexts():
        from rsocl.device import context

        return context._device_for.cache_info().currsize

    assert list(cluster[1].run(contexts).values()) == [1, 1]


def test_a_store_written_by_workers_matches_the_in_memory_result(cluster, tmp_path):
    rig, g = _problem((26, 31), sets=2)
    kwargs = dict(tile=(13, 16), halo=5, iterations=6)
    memory = reconstruct_tiled(g, rig, **kwargs)
    stored = reconstruct_tiled(g, rig, out=tmp_path / "rec.zarr", scheduler=cluster[0].scheduler_address, **kwargs)
    back = load_store(tmp_path / "rec.zarr")
    assert back.complete and back.datacube.shape == memory.datacube.shape
    assert back.datacube.chunks[2:] == (13, 16) and back.rig == rig and back.params["tile"] == [13, 16]
    np.testing.assert_array_equal(np.asarray(stored.datacube[...]), memory.datacube)


def test_a_partly_written_store_resumes_and_matches_a_clean_run(tmp_path):
    rig, g = _problem((28, 28))
    kwargs = dict(tile=(14, 14), halo=5, iterations=6)
    clean = reconstruct_tiled(g, rig, out=tmp_path / "clean.zarr", **kwargs)
    partial = tmp_path / "partial.zarr"
    reconstruct_tiled(g, rig, out=partial, **kwargs)
    group = zarr.open_group(str(partial), mode="r+")
    group["tiles"][0, 1, 0, 0] = 0  # tile (1, 0) not marked done: as if killed after writing
    group["tiles"][0, 0, 1, 0] = 0  # tile (0, 1): killed while writing, its data garbage
    group["datacube"][:, :14, 14:] = 7.0
    resumed = reconstruct_tiled(g, rig, out=partial, **kwargs)
    assert resumed.skipped == 2 and sorted(p.index for p in resumed.pieces) == [(0, 1), (1, 0)]
    np.testing.assert_array_equal(np.asarray(resumed.datacube[...]), np.asarray(clean.datacube[...]))
    with pytest.raises(ValueError, match="holds another reconstruction .*params.iterations"):
        reconstruct_tiled(g, rig, out=partial, **{**kwargs, "iterations": 7})


def test_a_store_cut_short_while_created_is_absent_and_a_rerun_makes_it(tmp_path, monkeypatch):
    rig, g = _problem((20, 20))
    kwargs = dict(tile=(10, 10), halo=4, iterations=3, tune=False)
    store = tmp_path / "rec.zarr"

    def killed(*args, **kwargs):
        raise RuntimeError("killed while writing the attributes")

    monkeypatch.setattr(zarr.Group, "update_attributes", killed)
    with pytest.raises(RuntimeError, match="killed"):
        reconstruct_tiled(g, rig, out=store, **kwargs)
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []
    ended = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True, check=True
    )
    prefix = f".rec.zarr.partial-{socket.gethostname()}-"
    dead = tmp_path / f"{prefix}{int(ended.stdout)}-0123abcd"  # left by a killed run
    alive = tmp_path / f"{prefix}{os.getpid()}-4567abcd"  # a run creating the store now
    for leftover in (dead, alive):
        leftover.mkdir()
        (leftover / "zarr.json").write_text("{}")
    result = reconstruct_tiled(g, rig, out=store, **kwargs)
    assert load_store(store).complete and len(result.pieces) == 4
    np.testing.assert_array_equal(np.asarray(result.datacube[...]), reconstruct_tiled(g, rig, **kwargs).datacube)
    assert not dead.exists() and alive.exists()


def _tiles_done(store) -> int:
    """Tiles marked done in ``store`` (0 while it is being created)."""
    try:
        return int(np.asarray(zarr.open_group(str(store), mode="r")["tiles"][..., 0]).sum())
    except Exception:  # noqa: BLE001 - not there yet
        return 0


def test_a_worker_killed_mid_run_and_every_chunk_is_still_correct(cluster, tmp_path):
    cluster_, client = cluster
    rig, g = _problem((48, 48))
    kwargs = dict(tile=(16, 16), halo=6, iterations=40, tune=False)
    reference = reconstruct_tiled(g, rig, **kwargs).datacube
    store = tmp_path / "rec.zarr"
    outcome = {}

    def run():
        try:
            outcome["result"] = reconstruct_tiled(
                g, rig, out=store, scheduler=cluster_.scheduler_address, retries=0, **kwargs
            )
        except Exception as exc:  # noqa: BLE001 - reported by the assertion below
            outcome["error"] = exc

    thread = threading.Thread(target=run)
    thread.start()
    deadline = time.monotonic() + 120
    killed = None
    while killed is None and time.monotonic() < deadline and thread.is_alive():
        time.sleep(0.05)
        busy = [w for w, keys in client.processing().items() if keys]
        done = _tiles_done(store) >= 1
        if busy and done:
            pids = client.run(os.getpid, workers=busy[:1])
            killed = pids[busy[0]]
            os.kill(killed, signal.SIGKILL)
    thread.join(240)
    assert killed is not None, "the run ended before a worker could be killed"
    assert "error" not in outcome, outcome.get("error")
    assert len(outcome["result"].pieces) == 9
    back = load_store(store)
    assert back.complete
    np.testing.assert_array_equal(np.asarray(back.datacube[...]), reference)
    client.wait_for_workers(2, timeout=60)


def test_a_failing_tile_on_the_cluster_is_reported_with_its_index_and_cause(cluster, tmp_path):
    from dataclasses import replace

    from rsocl.files.hdf5 import save_capture
    from rsocl.scale.inputs import CaptureSets

    rig, g = _problem((32, 32))
    save_capture(tmp_path / "cap.h5", g, rig)

    class Moved(CaptureSets):  # the workers look for tile (1, 1)'s snapshots in a missing file
        def block(self, set_index, tile):
            block = super().block(set_index, tile)
            return replace(block, path=str(tmp_path / "moved.h5")) if tile.index == (1, 1) else block

    with pytest.raises(TilesFailed) as info:
        reconstruct_tiled(
            Moved(tmp_path / "cap.h5"),
            rig,
            tile=(16, 16),
            halo=4,
            iterations=4,
            retries=1,
            tune=False,
            out=tmp_path / "rec.zarr",
            scheduler=cluster[0].scheduler_address,
        )
    assert "tile (1, 1) (rows 16..31, columns 16..31) failed after 2 attempt(s)" in str(info.value)
    assert "moved.h5" in str(info.value)
    assert "run again to redo only the failed ones" in str(info.value)
    marks = load_store(tmp_path / "rec.zarr").tiles[0, ..., 0]
    np.testing.assert_array_equal(marks, [[1, 1], [1, 0]])


def test_a_warning_of_the_tiles_on_workers_is_raised_in_the_client_once(cluster, recwarn):
    rig, g = _problem((16, 16))
    kwargs = dict(tile=(8, 8), halo=2, iterations=4, tune=False, eta=1e6, lam=0.1)
    reconstruct_tiled(g, rig, scheduler=cluster[0].scheduler_address, **kwargs)
    far = [w for w in recwarn if "ended far from the data" in str(w.message)]
    assert len(far) == 1 and far[0].category is RuntimeWarning, [str(w.message) for w in recwarn]


def test_a_worker_of_several_threads_runs_its_tasks_one_at_a_time_each_noting_its_own_warnings(monkeypatch):
    import warnings
    from concurrent.futures import ThreadPoolExecutor

    from rsocl.scale import runner

    running, most = [0], [0]

    def solve(job, payload, settings):  # tasks of staggered lengths, each warning once in the middle
        running[0] += 1
        most[0] = max(most[0], running[0])
        time.sleep(0.02 * job)
        warnings.warn(f"task {job} warns", UserWarning, stacklevel=2)
        time.sleep(0.08 - 0.02 * job)
        running[0] -= 1
        return job

    monkeypatch.setattr(runner, "solve_tile", solve)
    shown = (warnings.showwarning, getattr(warnings, "_showwarnmsg_impl", None))  # how the worker shows warnings
    with ThreadPoolExecutor(4) as pool:  # as `dask worker` runs tasks: one thread per core
        results = list(pool.map(lambda job: runner._solve_noting_warnings(job, None, None), range(4)))
    assert results == [(j, ((UserWarning, f"task {j} warns"),)) for j in range(4)] and most[0] == 1
    assert (warnings.showwarning, getattr(warnings, "_showwarnmsg_impl", None)) == shown  # not a dead task's list


def test_an_unreachable_scheduler_is_an_error_before_anything_runs(monkeypatch, tmp_path):
    from rsocl.scale import runner

    monkeypatch.setattr(runner, "CONNECT_TIMEOUT", 1)
    rig, g = _problem((16, 16))
    calls = []
    monkeypatch.setattr(runner, "solve_tile", lambda *a: calls.append(a))
    with pytest.raises(ValueError, match="scheduler: cannot reach a dask.distributed scheduler at 'tcp://127.0.0.1:9'"):
        reconstruct_tiled(g, rig, tile=(8, 8), scheduler="tcp://127.0.0.1:9", out=tmp_path / "rec.zarr")
    assert not calls and not (tmp_path / "rec.zarr").exists()
    monkeypatch.setenv("RSOCL_SCHEDULER", "tcp://127.0.0.1:9")  # what the user set is what the message names
    with pytest.raises(ValueError, match=r"^RSOCL_SCHEDULER: cannot reach .*or unset RSOCL_SCHEDULER for the local"):
        reconstruct_tiled(g, rig, tile=(8, 8))
    with pytest.raises(ValueError, match=r"^workers asks for a local cluster of 2 while RSOCL_SCHEDULER="):
        reconstruct_tiled(g, rig, tile=(8, 8), workers=2)
    monkeypatch.setenv("RSOCL_SCHEDULER", "garbage::::")
    with pytest.raises(ValueError, match=r"^RSOCL_SCHEDULER must be the address of a dask.distributed scheduler"):
        reconstruct_tiled(g, rig, tile=(8, 8))
    monkeypatch.delenv("RSOCL_SCHEDULER")
    # a malformed address is refused before any connection is tried
    for address in ("synchronous", "tcp://localhost", "127.0.0.1"):
        with pytest.raises(ValueError, match=rf"scheduler must be the address .*got '{address}' \(missing port"):
            reconstruct_tiled(g, rig, tile=(8, 8), scheduler=address)
    assert not calls


def test_a_device_object_is_refused_for_workers_and_serves_tasks_in_this_process(
    cluster, device, tmp_path, monkeypatch
):
    from rsocl.scale import runner

    rig, g = _problem((16, 16))
    kwargs = dict(tile=(8, 8), halo=4, iterations=2, tune=False, device=device)
    calls = []
    monkeypatch.setattr(runner, "solve_tile", lambda *a: calls.append(a))
    for where in (dict(workers=1), dict(scheduler=cluster[0].scheduler_address)):
        with pytest.raises(
            ValueError,
            match=r"device must be a device spec string for the workers of .*e.g. 'pocl', "
            r"'0:0' or 'nvidia' .*got a Device \(",
        ):
            reconstruct_tiled(g, rig, **kwargs, **where)
    assert not calls
    monkeypatch.undo()
    stored = reconstruct_tiled(g, rig, out=tmp_path / "rec.zarr", **kwargs)
    assert stored.params["device"] == device.name == load_store(tmp_path / "rec.zarr").params["device"]
    np.testing.assert_array_equal(np.asarray(stored.datacube[...]), reconstruct_tiled(g, rig, **kwargs).datacube)


def test_rsocl_reconstruct_on_the_cluster_of_rsocl_scheduler_and_on_its_own_workers(
    cluster, tmp_path, monkeypatch, capsys
):
    from rsocl.cli.main import main
    from rsocl.files.hdf5 import save_capture

    rig, g = _problem((18, 20))
    save_capture(tmp_path / "cap.h5", g, rig)
    expected = reconstruct_tiled(g, rig, tile=(9, 10), halo=3, iterations=3, tune=False).datacube
    args = [
        "reconstruct",
        str(tmp_path / "cap.h5"),
        "--tile",
        "9",
        "10",
        "--halo",
        "3",
        "--iterations",
        "3",
        "--fixed",
        "--quiet",
    ]
    monkeypatch.setenv("RSOCL_SCHEDULER", cluster[0].scheduler_address)
    assert main(args + ["--out", str(tmp_path / "env.zarr")]) == 0
    monkeypatch.delenv("RSOCL_SCHEDULER")
    assert main(args + ["--out", str(tmp_path / "own.zarr"), "--workers", "1"]) == 0
    for name in ("env.zarr", "own.zarr"):
        np.testing.assert_array_equal(load_store(tmp_path / name).datacube[...], expected)
    assert "4 tile task(s)" in capsys.readouterr().out
