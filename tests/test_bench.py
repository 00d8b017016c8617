"""rsocl bench: one point, the interp3d baseline, the Pareto front, the writers, the command end to end."""

import argparse
import csv
import math

import imageio.v3 as iio
import numpy as np
import pytest

from rsocl.bench.run import (
    BASELINE,
    COLUMNS,
    HEADER,
    BenchPoint,
    build_points,
    device_memory_bytes,
    interp3d,
    pareto_front,
    parse_sweep,
    run_bench,
    run_point,
    write_outputs,
)
from rsocl.cli import bench as bench_cli
from rsocl.model.operator import RollingShutterOperator
from rsocl.model.rig import Rig

FILES = ("bench.csv", "iterations.csv", "bench.md", "pareto.png", "cameras.png", "iterations.png")


@pytest.fixture(scope="module")
def still_scene(tmp_path_factory):
    """A video whose frames are all the same image: a scene constant in time."""
    rng = np.random.default_rng(3)
    frame = (rng.uniform(0, 255, (20, 20))).astype(np.uint8)
    path = tmp_path_factory.mktemp("scene") / "still.npz"
    np.savez(path, video=np.repeat(frame[None], 5, axis=0))
    return str(path)


def test_single_point_row():
    point = BenchPoint(shape=16, iterations=5)
    row = run_point(point, {}, with_history=True)
    assert set(COLUMNS) <= set(row)
    rig = point.rig()
    assert row["T"] == rig.T and row["T_se"] == rig.T_se and row["subframes_evaluated"] == rig.T
    assert row["regularizer"] == "tv" and row["cameras"] == 4 and row["roi"] == 16 and row["iterations"] == 5
    assert 5 < row["psnr"] < 60 and 0 < row["ssim_mean"] <= 1
    assert len(row["ssim_per_subframe"]) == rig.T
    assert row["ssim_mean"] == pytest.approx(np.mean(row["ssim_per_subframe"]))
    assert row["seconds"] > 0 and 0 < row["seconds_per_iteration"] <= row["seconds"]
    assert len(row["_history"]["psnr"]) == 5
    assert row["_history"]["psnr"][-1] == pytest.approx(row["psnr"], abs=1e-3)  # same truth, same window
    # memory: the buffers rsocl allocates, by hand for TV (3 planes of workspace and xnext)
    K, (m, n), T = 4, rig.shape, rig.T
    by_hand = 4 * K * m * n + 4 * K * m * n + 3 * K * 4 + 4 * K * m * n  # geometry (length: whole, rest) + snapshots
    by_hand += 4 * (4 * T * m * n) + 2 * 4 * K * m * n + 4 * K * K * m * n  # theta b f u, H theta, inverse
    by_hand += 16  # per-set eta and dual switch
    from rsocl.device import get_device

    copies = 1 if get_device().is_cpu else 2  # the dual in two copies where a Chambolle iteration is one launch
    by_hand += copies * 3 * 4 * T * m * n + 4 * n  # TV workspace
    # the timed run is a user's run, without the ground truth on the device
    assert row["peak_device_memory_bytes"] == by_hand == device_memory_bytes(rig, "tv", "float32", with_truth=False)
    assert run_point(point, {})["_history"] is None  # no history asked, no extra run
    # a self-tuned point also holds its interp3d start (T m n values), or more while it searches
    tuned = run_point(BenchPoint(shape=16, iterations=5, tune=True), {})
    assert tuned["peak_device_memory_bytes"] == device_memory_bytes(rig, "tv", "float32", with_truth=False, tuned=True)
    assert tuned["peak_device_memory_bytes"] >= by_hand + 4 * T * m * n


@pytest.mark.parametrize("cameras, t_e", [(4, 180e-6), (2, 180e-6), (4, 1e-3), (4, 1e-9)])
def test_a_point_left_at_the_default_weights_runs_what_a_user_gets(cameras, t_e):
    """lam and eta left out are reconstruct's own for the point's rig (scaled away from the paper's
    configuration), in the fixed and the self-tuned run: at t_e = 1 ns a literal eta = 0.2 never moved ADMM."""
    from rsocl.model.curvature import default_scale

    point = BenchPoint(shape=12, iterations=5, cameras=cameras, t_e=t_e)
    scale = default_scale(point.rig())
    row = run_point(point, {})
    assert row["lam"] == pytest.approx(0.1 * scale) and row["eta"] == pytest.approx(0.2 * scale)
    tuned = run_point(BenchPoint(shape=12, iterations=20, cameras=cameras, t_e=t_e, tune=True), {})
    assert tuned["eta"] == pytest.approx(0.2 * scale) and np.isfinite(tuned["psnr"])
    if t_e > 1e-6:  # a given eta of 0.3 does not move ADMM at 1 ns, which reconstruct says
        given = run_point(BenchPoint(shape=12, iterations=5, cameras=cameras, t_e=t_e, lam=0.05, eta=0.3), {})
        assert (given["lam"], given["eta"]) == (0.05, 0.3)


def test_interp3d_exact_for_a_scene_constant_in_time(still_scene):
    row = run_point(BenchPoint(scene=still_scene, shape=16, regularizer=BASELINE, iterations=0, tv_iterations=None), {})
    assert row["psnr"] == math.inf or row["psnr"] > 60
    assert row["ssim_mean"] == pytest.approx(1.0, abs=1e-6)
    assert row["peak_device_memory_bytes"] == 0 and row["seconds"] >= 0
    # directly, with one camera, eight cameras and a cropped (row-map) rig
    image = np.random.default_rng(0).uniform(size=(12, 12))
    for rig in (
        Rig.paper_array(1, (12, 12), 180e-6, 35e-6),
        Rig.paper_array(8, (12, 12), 180e-6, 35e-6),
        Rig.paper_array(4, (12, 12), 180e-6, 35e-6).crop((2, 2, 8, 8)),
    ):
        cube = np.repeat(image[None, : rig.shape[0], : rig.shape[1]], rig.T, axis=0)
        g = RollingShutterOperator(rig, dtype="float64").forward(cube)
        np.testing.assert_allclose(interp3d(g, rig), cube, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "t_e, dt, some_empty",
    [
        (26e-6, 87.5e-6, True),
        (28e-6, 35e-6, False),
        (180e-6, 35e-6, False),
        (180e-6, 87.5e-6, False),
        (1.7e-3, 35e-6, False),
    ],
)
def test_interp3d_exact_for_a_constant_scene_under_the_binary_mask(t_e, dt, some_empty):
    # a binary window averages the sub-frames whose start it holds: their count, not t_e/dt
    image = np.random.default_rng(1).uniform(0.2, 1.0, size=(9, 11))
    rig = Rig.paper_array(4, image.shape, t_e, 35e-6, mask="binary", dt=dt)
    cube = np.repeat(image[None], rig.T, axis=0)
    g = RollingShutterOperator(rig, dtype="float64").forward(cube)
    empty = g == 0  # rows start between sub-frames (dt > t_r): a short window may hold none
    assert empty.any() == some_empty and not empty.all()
    seen = ~empty.all(axis=0)  # a pixel no camera saw is not observed at all
    assert seen.mean() > 0.7
    np.testing.assert_allclose(interp3d(g, rig)[:, seen], cube[:, seen], rtol=0, atol=1e-12)


def test_interp3d_times_a_binary_sample_at_the_middle_of_its_sub_frames():
    rig = Rig.paper_array(2, (6, 6), 180e-6, 35e-6, mask="binary")
    win = rig.windows
    first, last = np.ceil(win.index + win.fraction), np.minimum(np.floor(win.end), rig.T - 1)
    ramp = np.arange(rig.T, dtype=np.float64) + 0.5  # the scene is its own time
    g = RollingShutterOperator(rig, dtype="float64").forward(np.broadcast_to(ramp[:, None, None], (rig.T,) + rig.shape))
    est = interp3d(g, rig)
    y, x = 5, 0
    lo, hi = sorted(((first[k, y, x] + last[k, y, x]) / 2 + 0.5) for k in range(2))
    inside = np.flatnonzero((ramp >= lo) & (ramp <= hi))
    assert inside.size > 2
    np.testing.assert_allclose(est[inside, y, x], ramp[inside], rtol=0, atol=1e-12)


def test_interp3d_is_linear_in_time_between_samples():
    rig = Rig.paper_array(2, (6, 6), 180e-6, 35e-6)
    win = rig.windows
    centre = win.index + win.fraction + win.length[:, None, None] / 2
    g = np.stack([np.full(rig.shape, 1.0), np.full(rig.shape, 3.0)]) * win.length[:, None, None]
    est = interp3d(g, rig)
    y, x = 5, 0  # camera 0 late, camera 1 early at this pixel
    t0, t1 = centre[0, y, x], centre[1, y, x]
    assert t1 < t0
    s = int(np.floor((t0 + t1) / 2))  # a sub-frame centre between the two samples
    expected = 3.0 + (s + 0.5 - t1) / (t0 - t1) * (1.0 - 3.0)
    assert est[s, y, x] == pytest.approx(expected)
    assert est[0, y, x] == pytest.approx(3.0) and est[-1, y, x] == pytest.approx(1.0)  # held outside


def test_tv_beats_interp3d_on_the_builtin_scene():
    cache = {}
    tv = run_point(BenchPoint(shape=24, cameras=4, iterations=60), cache)
    base = run_point(BenchPoint(shape=24, cameras=4, regularizer=BASELINE, iterations=0, tv_iterations=None), cache)
    assert base["psnr"] < tv["psnr"] - 1.0


def test_coarser_dt_keeps_the_intensity_scale(still_scene):
    cache = {}
    fine = run_point(BenchPoint(scene=still_scene, shape=12, iterations=30), cache)
    coarse = run_point(BenchPoint(scene=still_scene, shape=12, iterations=30, dt_factor=2), cache)
    assert coarse["T"] < fine["T"] and coarse["dt_us"] == pytest.approx(70.0)
    assert coarse["subframes_evaluated"] == fine["subframes_evaluated"]  # both on the dt = t_r truth
    assert coarse["psnr"] > fine["psnr"] - 3.0  # unscaled: ~6 dB lower


def test_roi_crop_is_compared_with_the_full_roi_on_the_same_pixels():
    cache = {}
    full = run_point(BenchPoint(shape=16, iterations=5), cache)
    crop = run_point(BenchPoint(shape=16, roi=8, iterations=5), cache)
    assert crop["roi"] == 8 and crop["subframes_evaluated"] < full["subframes_evaluated"]
    assert crop["psnr_full_roi"] is not None and 5 < crop["psnr_full_roi"] < 60
    assert full["psnr_full_roi"] is None


def test_pareto_front_on_synthetic_rows():
    rows = [
        {"seconds": 1.0, "psnr": 20.0},
        {"seconds": 2.0, "psnr": 19.0},  # 1 dominated by 0
        {"seconds": 0.5, "psnr": 15.0},
        {"seconds": 4.0, "psnr": 25.0},
        {"seconds": 4.0, "psnr": 24.0},  # same time, lower PSNR
        {"seconds": 3.0, "psnr": float("nan")},
        {"seconds": None, "psnr": 30.0},
        {"seconds": 8.0, "psnr": math.inf},
    ]
    assert pareto_front(rows) == [2, 0, 3, 7]
    assert pareto_front([]) == []


def test_points_and_sweep_parsing():
    assert parse_sweep("cameras=1, 2,8") == ("cameras", [1, 2, 8])
    assert parse_sweep("dt=1.5") == ("dt", [1.5])
    assert parse_sweep("tv-iterations") == ("tv_iterations", None)
    with pytest.raises(ValueError, match="--sweep must be one of"):
        parse_sweep("speed")
    with pytest.raises(ValueError, match="roi must be <= shape"):
        BenchPoint(shape=16, roi=20)
    default = BenchPoint(shape=16, iterations=8)
    points, notes = build_points(default, ["cameras=1,4", "roi=8,16,32", "regularizer=tv,nope"])
    pts = [p for p, _ in points]
    assert pts[0] == default and len(set(pts)) == len(pts)
    assert BenchPoint(shape=16, iterations=8, cameras=1) in pts
    assert sum(p.regularizer == BASELINE for p in pts) == 3  # C=4, C=1, ROI 8
    assert pts[-1].roi == 8 and pts[-2].roi == 8  # crops last, after the full ROI
    assert any("roi=32" in n for n in notes) and any("nope" in n for n in notes)
    assert parse_sweep("tune=false,1") == ("tune", [False, True])
    with pytest.raises(ValueError, match="true/false"):
        parse_sweep("tune=maybe")


def test_self_tuned_point_beside_the_fixed_one():
    default = BenchPoint(shape=16, iterations=10)
    result = run_bench(default, ["tune"], progress=False, repeat_default=False)
    rows = {r["label"]: r for r in result.rows}
    assert set(rows) == {"default", "self-tuned", BASELINE}
    tuned, fixed = rows["self-tuned"], rows["default"]
    assert fixed["lam"] == 0.1 and any(tuned["lam"] == pytest.approx(v) for v in (0.03, 0.1, 0.3))
    assert tuned["seconds"] > 0 and 5 < tuned["psnr"] < 60
    assert tuned["regularizer_options"]["temporal_weight"] > 0


@pytest.fixture(scope="module")
def tiny_result():
    default = BenchPoint(shape=12, iterations=4)
    return run_bench(default, ["cameras=1,4", "iterations=2,4", "dt=1,2", "roi=8"], progress=False)


def test_writers_produce_csv_markdown_and_pngs(tmp_path, tiny_result):
    assert not tiny_result.notes
    files = write_outputs(tiny_result, tmp_path)
    assert sorted(f.name for f in files) == sorted(FILES)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(FILES)  # no temporary files left
    with open(tmp_path / "bench.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == len(tiny_result.rows) and tuple(rows[0]) == HEADER
    assert {r["regularizer"] for r in rows} == {"tv", BASELINE}
    default = next(r for r in rows if r["label"] == "default")
    assert float(default["psnr_db"]) > 0 and len(default["ssim_per_subframe"].split()) == int(default["T"])
    with open(tmp_path / "iterations.csv", newline="") as handle:
        its = list(csv.DictReader(handle))
    assert len(its) == 4 and float(its[-1]["psnr_db"]) == pytest.approx(float(default["psnr_db"]), abs=1e-3)
    md = (tmp_path / "bench.md").read_text(encoding="utf-8")
    assert "| point |" in md and "dt = 2·t_r" in md and "ROI 8×8" in md
    assert "pick for speed" in md and "pick for quality" in md and "interp3d" in md
    for name in ("pareto.png", "cameras.png", "iterations.png"):
        image = iio.imread(tmp_path / name)
        assert image.ndim == 3 and image.shape[0] > 100 and image.std() > 0


def test_a_second_write_keeps_the_earlier_tables(tmp_path, tiny_result):
    write_outputs(tiny_result, tmp_path)
    before = {name: (tmp_path / name).read_bytes() for name in ("bench.csv", "iterations.csv", "bench.md")}
    kept = []
    files = write_outputs(tiny_result, tmp_path, kept)
    assert sorted(f.name for f in files) == sorted(FILES)
    assert sorted(p.name.split(".earlier-")[0] for p in kept) == ["bench", "bench", "iterations"]
    assert {p.suffix for p in kept} == {".csv", ".md"}
    for path in kept:  # each the earlier table, byte for byte
        assert path.read_bytes() == before[path.name.split(".earlier-")[0] + path.suffix]
    assert len(list(tmp_path.iterdir())) == len(FILES) + 3  # the pictures are drawn anew


def test_writers_without_sweeps_still_write_every_file(tmp_path):
    result = run_bench(BenchPoint(shape=10, iterations=2), ["dtype=float32"], baseline=False, progress=False)
    files = write_outputs(result, tmp_path)
    assert sorted(f.name for f in files) == sorted(FILES)
    assert "(no dt or roi sweep in this run)" in (tmp_path / "bench.md").read_text(encoding="utf-8")


def test_cmd_bench_quick_end_to_end(tmp_path, capsys):
    parser = argparse.ArgumentParser(prog="rsocl")
    bench_cli.add_parser(parser.add_subparsers(dest="command"))
    out = tmp_path / "b"
    args = parser.parse_args(
        [
            "bench",
            "--quick",
            "--shape",
            "12",
            "--iterations",
            "4",
            "--out",
            str(out),
            "--quiet",
            "--sweep",
            "cameras=1,2",
            "--sweep",
            "dt",
            "--sweep",
            "roi",
        ]
    )
    assert args.func is bench_cli.cmd_bench
    assert bench_cli.cmd_bench(args) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(FILES)
    line = capsys.readouterr().out
    assert "points in" in line and "quality:" in line
    with open(out / "bench.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert {int(r["cameras"]) for r in rows} == {1, 2, 4}
    assert {float(r["dt_factor"]) for r in rows} == {1.0, 2.0, 4.0}
    assert {int(r["roi_px"]) for r in rows} == {6, 9, 12}


def test_ssim_of_an_roi_under_3_pixels_is_reported_as_not_available(tmp_path):
    parser = argparse.ArgumentParser(prog="rsocl")
    bench_cli.add_parser(parser.add_subparsers(dest="command"))
    out = tmp_path / "b"
    args = parser.parse_args(
        ["bench", "--quick", "--shape", "12", "--iterations", "3", "--out", str(out), "--quiet", "--sweep", "roi=2"]
    )
    assert bench_cli.cmd_bench(args) == 0
    text = (out / "bench.md").read_text()
    assert "nan" not in text and "| n/a |" in text and "SSIM n/a: the ROI's frames are under 3 pixels" in text


def test_cmd_bench_missing_scene(tmp_path):
    parser = argparse.ArgumentParser(prog="rsocl")
    bench_cli.add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["bench", "--scene", str(tmp_path / "nope.npz"), "--out", str(tmp_path)])
    with pytest.raises(FileNotFoundError, match="nope.npz"):
        bench_cli.cmd_bench(args)


BENCH_SMALL = ["bench", "--quick", "--shape", "12", "--iterations", "2", "--sweep", "cameras=1", "--quiet"]


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--lam", "-1"], r"--lam must be >= 0, got -1.0"),
        (["--eta", "-0.5"], r"--eta must be >= 0 \(0 runs GAP\), got -0.5"),
        (["--t-r-us", "-3"], r"--t-r-us must be > 0 µs, got -3.0"),
        (["--t-e-us", "0"], r"--t-e-us must be > 0 µs, got 0.0"),
        (["--t-e-us", "1e9"], r"--t-e-us 1e\+09 µs is 28,571,429 sub-frames of 35 µs, more than the 1,048,576"),
        (["--cameras", "9"], r"--cameras must be an integer >= 1 and <= 8, got 9"),
        (["--tv-iterations", "0"], r"--tv-iterations must be an integer >= 1, got 0"),
        (["--sweep", "roi=13"], r"--sweep roi=13: roi must be <= shape = 12 pixels"),
        (["--sweep", "cameras=0"], r"--sweep cameras=0: cameras must be an integer >= 1 and <= 8, got 0"),
        (["--sweep", "dt=0.5"], r"--sweep dt=0.5: dt_factor must be >= 1"),
        (["--sweep", "dtype=float16"], r"--sweep dtype=float16: dtype must be one of \['float32', 'float64'\]"),
        (["--sweep", "regularizer=nope"], r"--sweep regularizer=nope: .*nope"),
    ],
)
def test_cmd_bench_refuses_bad_values_before_running(tmp_path, capsys, monkeypatch, extra, match):
    import re

    from rsocl.bench import run as bench_run
    from rsocl.cli.main import main

    calls, real = [], bench_run.run_point
    monkeypatch.setattr(bench_run, "run_point", lambda *a, **k: calls.append(a) or real(*a, **k))
    assert main(BENCH_SMALL + ["--out", str(tmp_path / "b")] + extra) == 2
    err = capsys.readouterr().err
    assert re.search(match, err) and len(err.strip().splitlines()) == 1, err
    assert not calls and not (tmp_path / "b").exists()


def test_cmd_bench_fails_when_every_reconstruction_point_is_skipped(tmp_path, capsys, monkeypatch):
    from rsocl.bench import run as bench_run
    from rsocl.cli.main import main

    real = bench_run.run_point

    def lost(point, cache, **kwargs):  # the baseline runs, every reconstruction fails
        if not point.is_baseline:
            raise RuntimeError(f"device lost (C={point.cameras})")
        return real(point, cache, **kwargs)

    monkeypatch.setattr(bench_run, "run_point", lost)
    assert main(BENCH_SMALL + ["--out", str(tmp_path / "b")]) == 1
    captured = capsys.readouterr()
    assert "rsocl bench: error: no reconstruction point could be measured" in captured.err
    assert "default: failed (RuntimeError: device lost (C=4))" in captured.err
    assert "C=1: failed (RuntimeError: device lost (C=1))" in captured.err
    assert not (tmp_path / "b").exists()
    # some points measured: exit 0, and with --quiet the skipped ones are said on stderr
    monkeypatch.setattr(
        bench_run,
        "run_point",
        lambda point, cache, **kwargs: (
            lost(point, cache, **kwargs) if point.cameras == 1 else real(point, cache, **kwargs)
        ),
    )
    assert main(BENCH_SMALL + ["--out", str(tmp_path / "b")]) == 0
    captured = capsys.readouterr()
    assert "points in" in captured.out
    assert "rsocl bench: note: C=1: failed (RuntimeError: device lost (C=1))" in captured.err


def test_a_point_of_more_iterations_than_a_run_takes_is_refused_when_made():
    with pytest.raises(ValueError, match=r"iterations must be an integer >= 1 and <= 1000000, got 2000000"):
        BenchPoint(shape=16, iterations=2_000_000)
