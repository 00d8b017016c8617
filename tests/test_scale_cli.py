"""``rsocl reconstruct`` with tiles, sets and Zarr stores; outputs and the scheduler checked first."""

import re

import h5py
import numpy as np
import pytest

import rsocl
from rsocl.cli.main import main
from rsocl.files.hdf5 import load_reconstruction, save_capture
from rsocl.model.scenes import builtin_scene
from rsocl.scale import reconstruct_tiled
from rsocl.scale import tiled as tiled_module

zarr = pytest.importorskip("zarr")


@pytest.fixture
def capture(tmp_path):
    """A capture file of a 20x26 paper array with its truth and 3 sets (``snapshot_sets``)."""
    rig = rsocl.Rig.paper_array(4, (20, 26), t_e=1.8e-4, t_r=3.5e-5)
    op = rsocl.RollingShutterOperator(rig)
    truths = [builtin_scene(rig.shape, rig.T, seed=s) for s in range(3)]
    sets = np.stack([op.forward(t) for t in truths])
    path = tmp_path / "cap.h5"
    save_capture(path, sets[0], rig, truth=truths[0])
    with h5py.File(path, "r+") as h5:
        h5["snapshot_sets"] = sets
    return path, rig, sets


def test_reconstruct_into_a_zarr_store_by_tiles(capture, tmp_path, capsys):
    path, rig, sets = capture
    out = tmp_path / "rec.zarr"
    args = ["reconstruct", str(path), "--out", str(out), "--tile", "10", "13", "--halo", "4", "--iterations", "5"]
    assert main(args) == 0
    assert "4 tile task(s)" in capsys.readouterr().out
    group = zarr.open_group(str(out), mode="r")
    assert group["datacube"].shape == (rig.T,) + rig.shape and group["datacube"].chunks[1:] == (10, 13)
    assert group.attrs["rsocl_file"] == "reconstruction" and group.attrs["T"] == rig.T
    expected = reconstruct_tiled(sets[0], rig, tile=(10, 13), halo=4, iterations=5).datacube
    np.testing.assert_array_equal(group["datacube"][...], expected)
    assert main(args) == 0  # the same command on a complete store redoes nothing
    assert "0 tile task(s) in" in capsys.readouterr().out.replace(", 4 already in the store", "")


def test_no_truth_and_a_zarr_store(capture, tmp_path, capsys):
    path, rig, _ = capture
    out = tmp_path / "rec.zarr"
    assert (
        main(
            [
                "reconstruct",
                str(path),
                "--out",
                str(out),
                "--tile",
                "10",
                "26",
                "--halo",
                "4",
                "--iterations",
                "3",
                "--fast",
                "--no-truth",
            ]
        )
        == 0
    )
    assert "PSNR" not in capsys.readouterr().out
    group = zarr.open_group(str(out), mode="r")
    assert "datacube" in group and "truth" not in group and not any("truth" in key for key in group.attrs)


def test_every_set_into_one_store(capture, tmp_path):
    path, rig, sets = capture
    out = tmp_path / "sets.zarr"
    assert (
        main(
            [
                "reconstruct",
                str(path),
                "--out",
                str(out),
                "--sets",
                "--tile",
                "20",
                "26",
                "--halo",
                "0",
                "--iterations",
                "4",
                "--fixed",
                "--quiet",
            ]
        )
        == 0
    )
    cube = zarr.open_group(str(out), mode="r")["datacube"]
    assert cube.shape == (3, rig.T) + rig.shape
    for s in range(3):
        np.testing.assert_array_equal(cube[s], rsocl.reconstruct(sets[s], rig, iterations=4, tune=False).datacube)


def test_tiles_into_an_hdf5_file(capture, tmp_path):
    path, rig, _ = capture
    out = tmp_path / "rec.h5"
    assert (
        main(["reconstruct", str(path), "--out", str(out), "--tile", "10", "26", "--iterations", "3", "--quiet"]) == 0
    )
    assert load_reconstruction(out).datacube.shape == (rig.T,) + rig.shape and out.with_suffix(".gif").is_file()
    assert (tmp_path / "rec-tuning.png").is_file()  # tuned (no --fast): the search's plot, as untiled
    assert (
        main(
            [
                "reconstruct",
                str(path),
                "--out",
                str(tmp_path / "t.zarr"),
                "--tile",
                "10",
                "26",
                "--iterations",
                "3",
                "--quiet",
            ]
        )
        == 0
    )
    assert (tmp_path / "t-tuning.png").is_file()


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--out", "{tmp}/missing/rec.zarr"], "--out: directory .*missing.* does not exist"),
        (["--out", "{tmp}/missing/rec.h5"], "--out"),
        (["--out", "{tmp}/rec.h5", "--sets"], r"--out: every set \(--sets\) goes to a Zarr store"),
        (["--out", "{tmp}/rec.zarr", "--scheduler", "tcp://127.0.0.1:9"], "scheduler: cannot reach"),
        (["--out", "{tmp}/rec.zarr", "--workers", "0"], "workers must be"),
        (["--out", "{tmp}/rec.zarr", "--tile", "0", "4"], r"tile must be \(H, W\)"),
        (["--out", "{capture}"], r"--out .*cap.h5' is the capture it reads"),
        (["--out", "{tmp}/rec.h5", "--gif", "{tmp}/rec.h5"], r"--gif .*rec.h5' is the --out file"),
        (["--out", "{tmp}/rec.h5", "--gif", "{capture}"], r"--gif .*is the capture it reads"),
        (["--out", "{tmp}/rec.h5", "--gif", "{tmp}/anim.png"], r"--gif must name a \.gif file .*anim.png"),
        (["--out", "{tmp}/taken.h5"], r"--gif's NAME-tuning.png must name a file, .*taken-tuning.png' is a directory"),
        (
            ["--out", "{tmp}/taken.zarr"],
            r"--out's NAME-tuning.png must name a file, .*taken-tuning.png' is a directory",
        ),
    ],
)
def test_outputs_and_scheduler_are_checked_before_anything_is_computed(
    capture, tmp_path, monkeypatch, capsys, extra, match
):
    from rsocl.scale import runner

    monkeypatch.setattr(runner, "CONNECT_TIMEOUT", 1)
    calls = []
    monkeypatch.setattr(runner, "solve_tile", lambda *a: calls.append(a))
    monkeypatch.setattr(tiled_module, "scan", lambda *a: calls.append(a))
    monkeypatch.setattr("rsocl.cli.reconstruct.run_reconstruction", lambda *a: calls.append(a))
    path = capture[0]
    before = path.read_bytes()
    (tmp_path / "taken-tuning.png").mkdir()
    argv = ["reconstruct", str(path), "--iterations", "2"] + [
        e.replace("{tmp}", str(tmp_path)).replace("{capture}", str(path)) for e in extra
    ]
    assert main(argv) == 2
    assert path.read_bytes() == before
    err = capsys.readouterr().err
    assert re.search(match, err), err
    assert not calls


def test_workers_above_four_per_core_are_refused_before_a_cluster_starts(capture, tmp_path, monkeypatch, capsys):
    import os

    distributed = pytest.importorskip("distributed")
    from rsocl.scale import runner

    started = []

    class NoCluster:  # --workers 100000 on 2 cores ran until killed
        def __init__(self, *args, **kwargs):
            started.append(kwargs)
            raise RuntimeError("a LocalCluster was started")

    monkeypatch.setattr(distributed, "LocalCluster", NoCluster)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    path = capture[0]
    argv = ["reconstruct", str(path), "--out", str(tmp_path / "rec.zarr"), "--iterations", "2", "--fast", "--workers"]
    assert main(argv + ["100000"]) == 2
    err = capsys.readouterr().err
    assert f"workers must be an integer in [1, {4 * cores}]" in err and "got 100000" in err
    assert main(argv + [str(4 * cores + 1)]) == 2
    assert f"got {4 * cores + 1}" in capsys.readouterr().err
    assert not started and not (tmp_path / "rec.zarr").exists()
    assert runner.max_workers() == 4 * cores
    assert runner.Engine(workers=4 * cores).workers == 4 * cores  # the cap itself is allowed


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_set_holding_nan_or_inf_is_refused_naming_it_before_any_tile_runs(
    capture, tmp_path, monkeypatch, capsys, bad
):
    from rsocl.scale import runner

    path, _, sets = capture
    sets = sets.copy()
    sets[1, 2, 3, 4] = bad
    with h5py.File(path, "r+") as h5:
        h5["snapshot_sets"][...] = sets
    calls = []
    monkeypatch.setattr(runner, "solve_tile", lambda *a: calls.append(a))
    out = tmp_path / "rec.zarr"
    assert (
        main(
            [
                "reconstruct",
                str(path),
                "--sets",
                "--out",
                str(out),
                "--tile",
                "10",
                "13",
                "--iterations",
                "2",
                "--fast",
                "--quiet",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "set 1 of dataset 'snapshot_sets' contains 1 NaN or inf value(s)" in err and "cap.h5" in err, err
    assert not calls and not out.exists()
    with pytest.raises(ValueError, match=r"g\[1\] \(set 1\) contains 1 NaN or inf value\(s\)"):
        reconstruct_tiled(sets, rsocl.Rig.paper_array(4, (20, 26), t_e=1.8e-4, t_r=3.5e-5), tile=(10, 13))


def test_a_tiled_run_with_a_truth_says_psnr_and_ssim_and_writes_the_gif(capture, tmp_path, capsys):
    path, rig, _ = capture
    common = ["--tile", "10", "26", "--halo", "4", "--iterations", "3", "--fast"]
    assert main(["reconstruct", str(path), "--out", str(tmp_path / "rec.zarr"), *common]) == 0
    out = capsys.readouterr().out
    assert "PSNR " in out and " dB, SSIM 0." in out and "2 tile task(s)" in out, out
    assert (tmp_path / "rec.gif").is_file()
    assert main(["reconstruct", str(path), "--out", str(tmp_path / "sets.zarr"), "--sets", *common]) == 0
    assert "set 0: PSNR " in capsys.readouterr().out and (tmp_path / "sets.gif").is_file()
    assert main(["reconstruct", str(path), "--out", str(tmp_path / "rec.h5"), *common]) == 0
    assert ", SSIM 0." in capsys.readouterr().out and (tmp_path / "rec.gif").is_file()
    assert main(["reconstruct", str(path), "--out", str(tmp_path / "none.zarr"), "--no-truth", *common]) == 0
    assert not (tmp_path / "none.gif").exists()
    assert (
        main(["reconstruct", str(path), "--out", str(tmp_path / "bad.zarr"), "--gif", str(tmp_path / "a.png"), *common])
        == 2
    )
    assert "--gif must name a .gif file" in capsys.readouterr().err and not (tmp_path / "bad.zarr").exists()


def test_a_failing_tile_says_what_was_kept_hdf5_nothing_zarr_the_solved_tiles(capture, tmp_path, capsys, monkeypatch):
    from rsocl.scale import runner as runner_module

    path, _, _ = capture
    solve = runner_module.solve_tile

    def corner_fails(job, *args):
        if job.tile.index == (0, 0):
            raise RuntimeError("out of device memory")
        return solve(job, *args)

    monkeypatch.setattr(runner_module, "solve_tile", corner_fails)
    argv = ["reconstruct", str(path), "--tile", "10", "13", "--halo", "3", "--iterations", "3", "--fixed"]
    argv += ["--retries", "0", "--quiet", "--no-truth", "--first-set-only"]
    h5 = tmp_path / "rec.h5"
    assert main(argv + ["--out", str(h5)]) == 1
    err = capsys.readouterr().err
    first, *rest = err.strip().splitlines()
    assert first == (
        f"rsocl reconstruct: error: 1 task(s) failed, 3 solved and discarded; nothing was written to {h5} (an "
        f"HDF5 --out is written once every task is solved; a Zarr --out, e.g. rec.zarr, keeps solved tiles and "
        f"a re-run redoes only the failed ones):"
    ), err
    assert len(rest) == 1 and rest[0].startswith("  tile (0, 0) ") and "RuntimeError: out of device memory" in rest[0]
    assert " kept" not in err and sorted(p.name for p in tmp_path.iterdir()) == ["cap.h5"]
    store = tmp_path / "rec.zarr"
    assert main(argv + ["--out", str(store)]) == 1
    first = capsys.readouterr().err.splitlines()[0]
    assert (
        first
        == f"rsocl reconstruct: error: 1 task(s) failed, 3 kept in {store} (run again to redo only the failed ones):"
    )
    monkeypatch.undo()
    assert main(argv + ["--out", str(store)]) == 0  # the failed tile alone
    assert capsys.readouterr().out.startswith("1 tile task(s) in ") and rsocl.scale.store.load_store(store).complete


def test_an_interrupted_tiled_run_says_how_many_tiles_the_store_kept(capture, tmp_path, capsys, monkeypatch):
    # Ctrl-C during the third of four tiles: the store keeps two, the line says so, and a re-run finishes
    from rsocl.scale import runner as runner_module

    path, _, _ = capture
    solve, calls = runner_module.solve_tile, []

    def interrupted_at_the_third(job, *args):
        calls.append(job.tile.index)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return solve(job, *args)

    monkeypatch.setattr(runner_module, "solve_tile", interrupted_at_the_third)
    argv = ["reconstruct", str(path), "--tile", "10", "13", "--halo", "3", "--iterations", "3", "--fixed"]
    argv += ["--retries", "0", "--quiet", "--no-truth", "--first-set-only"]
    store, h5 = tmp_path / "rec.zarr", tmp_path / "rec.h5"
    assert main(argv + ["--out", str(store)]) == 130
    assert capsys.readouterr().err == (
        f"rsocl reconstruct: interrupted: 2 of 4 tile task(s) kept in {store}; the same command again redoes "
        "only the others\n"
    )
    monkeypatch.setattr(runner_module, "solve_tile", solve)
    assert main(argv + ["--out", str(store)]) == 0
    calls.clear()
    monkeypatch.setattr(runner_module, "solve_tile", interrupted_at_the_third)
    assert main(argv + ["--out", str(h5)]) == 130
    assert capsys.readouterr().err.endswith(
        f"interrupted: nothing written to {h5} (an HDF5 --out is written once every task is solved)\n"
    )


def test_the_gif_beside_a_store_is_named_as_the_outs_when_no_gif_was_given(capture, tmp_path, capsys):
    path, _, _ = capture
    (tmp_path / "rec.gif").mkdir()  # where the GIF beside rec.zarr would go
    argv = ["reconstruct", str(path), "--out", str(tmp_path / "rec.zarr"), "--tile", "10", "13", "--first-set-only"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("rsocl reconstruct: error: --out's NAME.gif must name a file") and "--gif" not in err, err


def test_a_zarr_run_without_truth_or_gif_leaves_the_stored_datacube_on_disk(capture, tmp_path, capsys, monkeypatch):
    """The whole sensor's datacube is GiBs: with no truth to compare and no GIF to draw, the run does not read
    the store back into memory once its tiles are done."""
    import dataclasses

    path, _, _ = capture
    real, reads = tiled_module.reconstruct_tiled, []

    class Untouchable:
        def __init__(self, array):
            self.shape, self.array = array.shape, array

        def __array__(self, *args, **kwargs):
            reads.append("whole")
            return np.asarray(self.array)

        def __getitem__(self, key):
            reads.append(key)
            return self.array[key]

    def watched(*args, **kwargs):
        result = real(*args, **kwargs)
        return dataclasses.replace(result, datacube=Untouchable(result.datacube))

    monkeypatch.setattr(tiled_module, "reconstruct_tiled", watched)
    common = ["--tile", "10", "26", "--halo", "4", "--iterations", "3", "--fast"]
    assert main(["reconstruct", str(path), "--out", str(tmp_path / "none.zarr"), "--no-truth", *common]) == 0
    assert "2 tile task(s)" in capsys.readouterr().out and reads == []
    assert main(["reconstruct", str(path), "--out", str(tmp_path / "rec.zarr"), *common]) == 0
    assert "PSNR " in capsys.readouterr().out and reads == ["whole"]  # with the truth: read once, to compare
