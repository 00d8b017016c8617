"""The rsocl command end to end, in-process (main(argv)) and once as a console script."""

import subprocess
import sys

import numpy as np
import pytest

import rsocl
from rsocl.cli.main import main
from rsocl.files.hdf5 import load_capture, load_reconstruction


def test_info_paper_figures(capsys):
    assert main(["info", "--cameras", "4", "--shape", "50", "50", "--t-e-us", "180", "--t-r-us", "35"]) == 0
    out = capsys.readouterr().out
    assert "T (sub-frames)           55" in out
    assert "N_s = ceil(t_e/t_r)      6" in out
    assert "13.75x" in out


def test_info_capture_reads_the_rig_of_the_capture_and_refuses_rig_options(tmp_path, capsys):
    import rsocl
    from rsocl.files.hdf5 import save_capture

    rig = rsocl.Rig.paper_array(2, (9, 7), t_e=1e-4, t_r=3e-5)
    cap = tmp_path / "cap.h5"
    save_capture(cap, np.zeros((rig.n_channels,) + rig.shape), rig)
    assert main(["info", "--capture", str(cap), "--camera-fps", "30"]) == 0
    out = capsys.readouterr().out
    assert "ROI                      9 x 7 pixels" in out and "cameras                  2 " in out
    assert "effective fps at 30 fps" in out
    # a rig option would be ignored: refused, named, even at its default value (--shape 50 50)
    for extra, named in (
        (["--shape", "50", "50"], "--shape"),
        (["--cameras=2"], "--cameras"),
        (["--t-e-us", "100", "--mask", "binary", "--t-e-us", "90"], "--t-e-us, --mask"),
        (["--sha", "9", "7"], "--shape"),
        (["--dt-us", "30", "--t-r-us", "30"], "--dt-us, --t-r-us"),
    ):
        assert main(["info", "--capture", str(cap), *extra]) == 2
        captured = capsys.readouterr()
        assert captured.err.startswith(f"rsocl info: error: {named} cannot be used with --capture: ")
        assert captured.err.count("\n") == 1 and not captured.out, captured.err
    assert main(["info", "--shape", "9", "7", "--cameras", "2"]) == 0  # without --capture they apply
    assert "9 x 7 pixels" in capsys.readouterr().out


def test_an_output_that_would_replace_the_input_or_cannot_be_made_is_refused_first(tmp_path, capsys, monkeypatch):
    import os
    import tempfile

    from rsocl.files.atomic import output_path

    video = tmp_path / "v.npz"
    np.savez(video, video=np.random.default_rng(0).random((8, 12, 12)))
    before = video.read_bytes()
    assert main(["simulate", str(video), "--out", str(video), "--shape", "12", "12"]) == 2
    assert "is the scene it reads" in capsys.readouterr().err and video.read_bytes() == before
    os.symlink(video, tmp_path / "link.npz")
    with pytest.raises(ValueError, match="is the scene it reads"):
        output_path(tmp_path / "link.npz", "--out", inputs=(("scene", video),))

    def refuse(*args, **kwargs):  # a folder that takes no new file (read-only, chattr +i)
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    with pytest.raises(ValueError, match=r"--out: cannot create files in .* \(Permission denied\)"):
        output_path(tmp_path / "new.h5", "--out")
    assert main(["simulate", "builtin", "--out", str(tmp_path / "c.h5"), "--shape", "12", "12"]) == 2
    assert "cannot create files" in capsys.readouterr().err and not (tmp_path / "c.h5").exists()
    monkeypatch.undo()
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".probe")]


def test_simulate_reconstruct_round_trip(tmp_path, capsys):
    cap = tmp_path / "cap.h5"
    rec = tmp_path / "rec.h5"
    assert (
        main(
            [
                "simulate",
                "builtin",
                "--out",
                str(cap),
                "--shape",
                "16",
                "20",
                "--cameras",
                "2",
                "--noise",
                "gaussian",
                "--sigma",
                "0.001",
                "--bit-depth",
                "12",
                "--quiet",
            ]
        )
        == 0
    )
    capture = load_capture(cap)
    assert capture.snapshots.shape == (2, 16, 20) and capture.rig.C == 2
    assert capture.truth.shape == (capture.rig.T, 16, 20)
    assert (
        main(
            [
                "reconstruct",
                str(cap),
                "--out",
                str(rec),
                "--iterations",
                "15",
                "--quiet",
                "--reg-opt",
                "temporal_weight=0.5",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "PSNR" in out and "15 iterations" in out
    result = load_reconstruction(rec)
    assert result.datacube.shape == capture.truth.shape
    assert result.params["regularizer_options"]["temporal_weight"] == 0.5
    assert len(result.history["residual"]) == 15
    assert (tmp_path / "rec.gif").exists()
    assert result.rig == capture.rig
    # lam was not given: chosen from the snapshots, recorded in the file, plotted next to the GIF
    assert result.params["tuning"]["fixed"] == {"temporal_weight": 0.5}
    assert result.params["lam"] == result.params["tuning"]["chosen"]["lam"]
    assert (tmp_path / "rec-tuning.png").stat().st_size > 0
    fast = tmp_path / "fast.h5"
    assert main(["reconstruct", str(cap), "--out", str(fast), "--iterations", "5", "--quiet", "--fixed"]) == 0
    assert load_reconstruction(fast).params["tuning"] is None and not (tmp_path / "fast-tuning.png").exists()
    # --blend: the caller's blend with the interpolation replaces the search's
    for blend in ("1", "0.3"):
        mixed = tmp_path / f"blend{blend}.h5"
        assert (
            main(
                [
                    "reconstruct",
                    str(cap),
                    "--out",
                    str(mixed),
                    "--iterations",
                    "15",
                    "--quiet",
                    "--reg-opt",
                    "temporal_weight=0.5",
                    "--blend",
                    blend,
                ]
            )
            == 0
        )
        assert load_reconstruction(mixed).params["blend"] == float(blend)


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--blend", "1.5"], "--blend must be in [0.0, 1.0], got 1.5"),
        (["--blend", "nan"], "--blend must be finite"),
        (
            ["--fixed", "--blend", "0.5"],
            "--blend 0.5 moves the result towards the interpolation a self-tuned run starts "
            "from; --fixed runs from zeros: leave out --fixed or --blend",
        ),
        (
            ["--lam", "0.1", "--reg-opt", "temporal_weight=3", "--blend", "0.5"],
            "--blend 0.5 moves the result towards the run's start, and this run starts from zeros (--fixed, or "
            "nothing left to choose from the data): drop --fixed, or a value you gave that the search would "
            "choose (--lam, --reg-opt), so that the run starts from the interpolation; or leave out --blend\n",
        ),
    ],
)
def test_a_blend_is_checked_before_any_work(tmp_path, capsys, extra, match):
    cap, out = tmp_path / "one.h5", tmp_path / "rec.h5"
    _capture_with_truth(cap, "one")
    assert main(["reconstruct", str(cap), "--out", str(out), "--iterations", "2", "--quiet", *extra]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(f"rsocl reconstruct: error: {match}"), captured.err
    assert sorted(p.name for p in tmp_path.iterdir()) == [cap.name]


def test_a_warning_is_one_line_naming_the_command(tmp_path, capsys):
    # the paper's diagonal step at eta = 1e-3 ends unstable: the run finishes, writes its files and
    # says so on one line, as errors are said (no source file, no line of code)
    cap, rec = tmp_path / "cap.h5", tmp_path / "rec.h5"
    assert main(["simulate", "builtin", "--out", str(cap), "--shape", "16", "16", "--quiet"]) == 0
    capsys.readouterr()
    assert (
        main(
            [
                "reconstruct",
                str(cap),
                "--out",
                str(rec),
                "--iterations",
                "30",
                "--fast",
                "--quiet",
                "--projection",
                "paper",
                "--eta",
                "0.001",
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert err.startswith("rsocl reconstruct: warning: ADMM ended unstable: the last residual") and err.count("\n") == 1
    assert rec.exists()


def test_errors_are_reported_not_raised(tmp_path, capsys):
    assert main(["info", "--t-r-us", "0"]) == 2
    assert "--t-r-us must be > 0 µs, got 0.0" in capsys.readouterr().err
    assert main(["info", "--cameras", "9"]) == 2
    assert "--cameras must be an integer >= 1 and <= 8, got 9" in capsys.readouterr().err
    assert main(["simulate", "builtin", "--out", str(tmp_path / "c.h5"), "--cameras", "0"]) == 2
    assert "--cameras must be an integer >= 1 and <= 8, got 0" in capsys.readouterr().err
    assert main(["reconstruct", str(tmp_path / "missing.h5"), "--out", str(tmp_path / "x.h5")]) == 2
    assert "missing.h5" in capsys.readouterr().err
    assert main(["simulate", "builtin", "--out", str(tmp_path / "c.h5"), "--noise", "poisson"]) == 2
    assert "photons" in capsys.readouterr().err
    assert not (tmp_path / "c.h5").exists()


def test_ssim_of_frames_too_small_for_it_is_said_not_printed_as_nan(tmp_path, capsys):
    assert main(["demo", "--shape", "2", "2", "--iterations", "5", "--out", str(tmp_path), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "SSIM n/a (frames under 3 pixels a side)" in out and "nan" not in out


def test_demo_of_one_camera_writes_no_search_plot_where_no_search_ran(tmp_path, capsys):
    # one snapshot per pixel: TV's preset weight and the default lam, no candidates to plot
    assert main(["demo", "--cameras", "1", "--shape", "12", "12", "--iterations", "5", "--out", str(tmp_path)]) == 0
    assert "chosen from the snapshots: temporal_weight = 10" in capsys.readouterr().out
    assert (tmp_path / "demo.h5").is_file() and not (tmp_path / "demo-tuning.png").exists()
    assert (
        main(
            [
                "demo",
                "--cameras",
                "2",
                "--shape",
                "12",
                "12",
                "--iterations",
                "5",
                "--out",
                str(tmp_path / "two"),
                "--quiet",
            ]
        )
        == 0
    )
    assert (tmp_path / "two" / "demo-tuning.png").is_file()


def test_a_run_without_a_search_moves_an_earlier_runs_search_plot_aside(tmp_path, capsys):
    # demo-tuning.png beside a new demo.h5 of a --fixed run would be read as that run's search
    small = ["--cameras", "2", "--shape", "8", "8", "--iterations", "5", "--out", str(tmp_path)]
    assert main(["demo", "--quiet", *small]) == 0
    plot = (tmp_path / "demo-tuning.png").read_bytes()
    assert main(["demo", "--fixed", *small]) == 0
    assert not (tmp_path / "demo-tuning.png").exists()
    (moved,) = tmp_path.glob("demo-tuning.earlier-*.png")
    assert moved.read_bytes() == plot and f"to {moved}" in capsys.readouterr().out
    assert len(list(tmp_path.glob("demo.earlier-*.h5"))) == 1
    assert main(["demo", "--fixed", *small]) == 0  # nothing there to move this time
    assert len(list(tmp_path.glob("demo-tuning.earlier-*.png"))) == 1 and "search plot" not in capsys.readouterr().out


def test_devices_and_plugins_list(capsys):
    assert main(["devices"]) == 0
    assert "0:0" in capsys.readouterr().out
    assert main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert "tv" in out and "ok" in out


@pytest.mark.slow
def test_demo_console_script(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "rsocl.cli",
            "demo",
            "--out",
            str(tmp_path),
            "--shape",
            "32",
            "32",
            "--iterations",
            "40",
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "PSNR" in proc.stdout
    for name in ("demo.gif", "snapshots.png", "subframes.png", "demo.h5", "demo-tuning.png"):
        assert (tmp_path / name).stat().st_size > 0
    psnr = float(proc.stdout.split("PSNR ")[1].split(" dB")[0])
    assert psnr > 15


def test_a_capture_of_several_sets_is_reconstructed_in_batches(tmp_path, capsys):
    import h5py

    import rsocl
    from rsocl.files.hdf5 import save_capture
    from rsocl.model import reference as ref

    rig = rsocl.Rig.paper_array(2, (9, 7), t_e=1e-4, t_r=3e-5)
    rng = np.random.default_rng(4)
    sets = np.stack([ref.forward(rig, rng.random((rig.T,) + rig.shape)) for _ in range(3)])
    cap, rec = tmp_path / "sets.h5", tmp_path / "rec.h5"
    save_capture(cap, sets[0], rig)
    with h5py.File(cap, "a") as h5:  # as rsocl capture writes it: every set, registered
        h5.create_dataset("snapshot_sets", data=sets)
    assert (
        main(
            [
                "reconstruct",
                str(cap),
                "--out",
                str(rec),
                "--iterations",
                "4",
                "--batch",
                "2",
                "--dtype",
                "float64",
                "--fixed",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "3 sets in batches of 2" in out and "set 2: 4 iterations" in out
    for i in range(3):
        got = load_reconstruction(tmp_path / f"rec-set{i:03d}.h5").datacube
        one = rsocl.reconstruct(sets[i], rig, iterations=4, dtype="float64", tune=False).datacube
        np.testing.assert_allclose(got, one, atol=1e-10 * np.abs(one).max())
    assert (tmp_path / "rec.gif").exists() and not rec.exists()
    assert main(["reconstruct", str(cap), "--out", str(rec), "--batch", "0"]) == 2
    assert "--batch must be >= 1" in capsys.readouterr().err
    one_set = tmp_path / "one.h5"  # refused on a capture of one set too, before any work
    save_capture(one_set, sets[0], rig)
    assert main(["reconstruct", str(one_set), "--out", str(tmp_path / "one-rec.h5"), "--batch", "-1"]) == 2
    captured = capsys.readouterr()
    assert "--batch must be >= 1" in captured.err and not captured.out and not (tmp_path / "one-rec.h5").exists()


def _capture_with_truth(path, mode):
    """A capture file with its ground truth (``mode`` "sets": 3 sets; "window": 3 frames per camera)."""
    import h5py

    import rsocl
    from rsocl.files.hdf5 import save_capture
    from rsocl.model.rig import Camera, Rig
    from rsocl.model.scenes import builtin_scene

    if mode == "window":
        t_r = 3.5e-5
        rig = Rig([Camera(a, t_e=1.8e-4, t_r=t_r, t_d=12 * t_r, frames=3) for a in (0, 90, 180, 270)], (12, 10))
    else:
        rig = rsocl.Rig.paper_array(2, (12, 10), t_e=1e-4, t_r=3e-5)
    op = rsocl.RollingShutterOperator(rig)
    truths = [builtin_scene(rig.shape, rig.T, seed=s) for s in range(3 if mode == "sets" else 1)]
    save_capture(path, op.forward(truths[0]), rig, truth=truths[0])
    if mode == "sets":
        with h5py.File(path, "a") as h5:  # as rsocl capture writes it; the truth is set 0's
            h5.create_dataset("snapshot_sets", data=np.stack([op.forward(t) for t in truths]))
    return truths[0]


@pytest.mark.parametrize(
    "mode, extra",
    [
        ("one", []),
        ("sets", ["--batch", "2"]),
        ("tiles", ["--tile", "6", "10", "--halo", "2"]),
        ("window", ["--window", "2", "--tile", "6", "10", "--halo", "2"]),
    ],
)
def test_no_truth_keeps_the_truth_out_of_the_reconstruction(tmp_path, capsys, mode, extra):
    import h5py

    cap = tmp_path / "cap.h5"
    truth = _capture_with_truth(cap, mode)
    first = (lambda out: out.with_name(f"{out.stem}-set000{out.suffix}")) if mode == "sets" else (lambda out: out)
    common = ["--iterations", "3", "--fast", "--quiet", *extra]

    with_truth = tmp_path / "with.h5"  # without --no-truth the capture's truth is kept and used
    assert main(["reconstruct", str(cap), "--out", str(with_truth), *common]) == 0
    assert "PSNR" in capsys.readouterr().out
    np.testing.assert_array_equal(load_reconstruction(first(with_truth)).truth, truth)

    rec = tmp_path / "rec.h5"
    assert main(["reconstruct", str(cap), "--out", str(rec), "--no-truth", *common]) == 0
    assert "PSNR" not in capsys.readouterr().out
    written = sorted(tmp_path.glob("rec*.h5"))
    assert written == ([first(rec).with_name(f"rec-set{i:03d}.h5") for i in range(3)] if mode == "sets" else [rec])
    for path in written:
        result = load_reconstruction(path)
        assert result.truth is None and "psnr" not in result.history
        with h5py.File(path, "r") as h5:
            assert "truth" not in h5


def _unreadable_files(folder):
    """Files whose suffix promises a video or frames but whose content is empty, truncated or not that format."""
    np.savez(folder / "whole.npz", video=np.zeros((3, 8, 8)))
    whole = (folder / "whole.npz").read_bytes()
    files = {
        "empty.npz": b"",
        "truncated.npz": whole[: len(whole) // 2],
        "empty.gif": b"",
        "corrupt.gif": b"GIF89a\x08\x00",
        "empty.npy": b"",
        "empty.tif": b"",
        "noise.gif": bytes(range(256)),
    }
    for name, data in files.items():
        (folder / name).write_bytes(data)
    np.savez(folder / "objects.npz", video=np.array([{"a": 1}], dtype=object))
    np.save(folder / "single.npz.npy", np.zeros((3, 8, 8)))
    (folder / "single.npz.npy").rename(folder / "single.npz")
    (folder / "dir.npz").mkdir()
    return sorted(list(files) + ["objects.npz", "single.npz", "dir.npz"])


def test_an_unreadable_video_or_frames_file_is_a_one_line_error_naming_it(tmp_path, capsys, monkeypatch):
    from rsocl.bench import run as bench_run

    out = tmp_path / "cap.h5"
    for name in _unreadable_files(tmp_path):
        assert main(["simulate", str(tmp_path / name), "--out", str(out), "--shape", "8", "8"]) == 2, name
        err = capsys.readouterr().err
        assert err.startswith("rsocl simulate: error: path: ") and name in err, err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
        assert not out.exists()
    calls = []
    monkeypatch.setattr(bench_run, "run_point", lambda *a, **k: calls.append(a))
    for name in ("empty.npz", "corrupt.gif"):  # bench reads the scene before any point runs
        assert (
            main(
                [
                    "bench",
                    "--scene",
                    str(tmp_path / name),
                    "--quick",
                    "--shape",
                    "8",
                    "--iterations",
                    "2",
                    "--out",
                    str(tmp_path / "b"),
                ]
            )
            == 2
        )
        err = capsys.readouterr().err
        assert name in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "b").exists() and not calls
    rig = tmp_path / "rig.toml"
    rig.write_text('[rig]\nshape = [8, 8]\n\n[[camera]]\nbackend = "simulated"\nt_e = 1.8e-4\nt_r = 3.5e-5\n')
    for name in ("empty.npz", "truncated.npz", "objects.npz", "single.npz", "empty.npy", "empty.gif"):
        frames = tmp_path / name
        if name == "empty.gif":  # a folder of frames holding one unreadable image
            (tmp_path / "frames").mkdir()
            frames = tmp_path / "frames" / "camera0.png"
            frames.write_bytes(b"")
            frames = frames.parent
        assert main(["calibrate", "--rig", str(rig), "--out", str(tmp_path / "new.toml"), "--flat", str(frames)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("rsocl calibrate: error: --flat: ") and len(err.strip().splitlines()) == 1, err
        assert (name if frames.suffix else "camera0.png") in err and not (tmp_path / "new.toml").exists()


def test_a_shape_beyond_the_host_memory_is_refused_before_allocating(tmp_path, capsys, monkeypatch):
    from rsocl.common import memory
    from rsocl.model import scenes

    monkeypatch.setattr(memory, "host_memory_bytes", lambda: 2**30)  # a 1 GiB machine
    for argv in (
        ["info"],
        ["plan", "--no-measure"],
        ["simulate", "builtin", "--out", str(tmp_path / "c.h5")],
        ["demo", "--out", str(tmp_path / "demo"), "--fast"],
    ):
        assert main(argv + ["--shape", "100000", "100000"]) == 2, argv  # was a MemoryError traceback
        err = capsys.readouterr().err
        assert "--shape 100000 100000: a rig of 4 camera(s) on 100000 x 100000 pixels" in err, err
        assert "at least 745.1 GiB of host memory, more than this machine's 1.0 GiB" in err
        assert len(err.strip().splitlines()) == 1
    # the rig fits, its T x 400 x 400 datacube does not (at least 4 T 400^2 bytes as float32)
    import rsocl

    T = rsocl.Rig.paper_array(2, (400, 400), t_e=180e-6, t_r=35e-6).T
    monkeypatch.setattr(memory, "host_memory_bytes", lambda: 128 * 2**20)
    small = ["--shape", "400", "400", "--cameras", "2"]
    assert main(["simulate", "builtin", "--out", str(tmp_path / "c.h5")] + small) == 2
    err = capsys.readouterr().err
    assert f"--shape 400 400: the {T} x 400 x 400 float32 datacube" in err, err
    assert f"at least {4 * T * 400 * 400 / 2**20:.1f} MiB of host memory, more than this machine's 128.0 MiB" in err
    assert main(["demo", "--out", str(tmp_path / "demo"), "--fast"] + small) == 2
    assert f"--shape 400 400: the {T} x 400 x 400 float32 datacube" in capsys.readouterr().err
    assert main(["bench", "--shape", "400", "--cameras", "2", "--out", str(tmp_path / "b")]) == 2
    assert f"--shape 400: the {T} x 400 x 400 float32 datacube" in capsys.readouterr().err
    assert not [p for p in tmp_path.iterdir()]
    # memory that runs out part way anyway: one line, exit 1
    monkeypatch.undo()

    def exhausted(*args, **kwargs):
        raise MemoryError("Unable to allocate 3.00 GiB for an array")

    monkeypatch.setattr(scenes, "load_scene", exhausted)
    assert main(["simulate", "builtin", "--out", str(tmp_path / "c.h5"), "--shape", "8", "8"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("rsocl simulate: error: out of host memory (Unable to allocate 3.00 GiB for an array)")
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "c.h5").exists()


def test_an_out_folder_that_is_a_file_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    from rsocl.bench import run as bench_run

    calls = []
    monkeypatch.setattr("rsocl.cli.demo.run_reconstruction", lambda *a, **k: calls.append(a))
    monkeypatch.setattr(bench_run, "run_point", lambda *a, **k: calls.append(a))
    existing = tmp_path / "results"
    existing.write_text("keep me")
    for out, match in (
        (existing, f"--out must name a folder (several files are written into it), {str(existing)!r} is a file"),
        (existing / "sub", f"--out: {str(existing)!r} is a file, so the folder"),
    ):
        for argv in (["demo", "--shape", "8", "8", "--fast"], ["bench", "--quick", "--shape", "8"]):
            assert main(argv + ["--out", str(out)]) == 2, argv  # was a FileExistsError traceback
            err = capsys.readouterr().err
            assert err.startswith(f"rsocl {argv[0]}: error: {match}") and len(err.strip().splitlines()) == 1, err
    assert not calls and existing.read_text() == "keep me"


def test_reg_opt_iterations_and_tv_iterations_that_disagree_are_refused(tmp_path, capsys, monkeypatch):
    cap = tmp_path / "cap.h5"
    assert main(["simulate", "builtin", "--out", str(cap), "--shape", "8", "8", "--cameras", "2", "--quiet"]) == 0
    from rsocl.cli import options

    runs = []

    def spy(args, *rest):
        runs.append(args)
        return options.run_reconstruction(args, *rest)

    monkeypatch.setattr("rsocl.cli.demo.run_reconstruction", spy)
    monkeypatch.setattr("rsocl.cli.reconstruct.run_reconstruction", spy)
    commands = (
        ["demo", "--out", str(tmp_path / "demo"), "--shape", "8", "8", "--cameras", "2"],
        ["reconstruct", str(cap), "--out", str(tmp_path / "rec.h5")],
    )
    for argv in commands:  # TV ran 5 inner iterations, --tv-iterations 3 was ignored
        assert main(argv + ["--iterations", "2", "--fast", "--reg-opt", "iterations=5", "--tv-iterations", "3"]) == 2
        err = capsys.readouterr().err
        assert (
            f"rsocl {argv[0]}: error: --reg-opt iterations=5 and --tv-iterations 3 both set the regularizer's "
            "inner iterations, to different values; give one of them"
        ) in err, err
    assert not runs and not (tmp_path / "rec.h5").exists() and not (tmp_path / "demo").exists()
    for argv in commands:  # the same value twice is no conflict
        assert (
            main(argv + ["--iterations", "2", "--fast", "--reg-opt", "iterations=3", "--tv-iterations", "3", "--quiet"])
            == 0
        )
        capsys.readouterr()
    assert [a.tv_iterations for a in runs] == [3, 3]
    assert load_reconstruction(tmp_path / "rec.h5").params["regularizer_options"]["iterations"] == 3


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--reg-opt", "step=1.5"], "option step must be in [0.01, 1.0], got '1.5'"),
        (["--reg-opt", "temporal_wieght=3"], "unknown option"),
        (["--regularizer", "nope"], "unknown regularizer 'nope'"),
        (["--regularizer", "dct", "--tv-iterations", "3"], "--tv-iterations applies to iterative denoisers"),
    ],
)
def test_regularizer_and_its_options_are_checked_before_any_work(tmp_path, capsys, extra, match):
    cap = tmp_path / "cap.h5"
    assert main(["simulate", "builtin", "--out", str(cap), "--shape", "8", "8", "--cameras", "2", "--quiet"]) == 0
    capsys.readouterr()  # simulate's result line
    commands = (
        ["demo", "--out", str(tmp_path / "demo"), "--shape", "8", "8"],
        ["reconstruct", str(cap), "--out", str(tmp_path / "rec.h5")],
    )
    for argv in commands:  # the demo simulated and printed its rig first
        assert main(argv + extra) == 2
        captured = capsys.readouterr()
        assert captured.out == "", captured.out
        err = captured.err
        assert err.startswith(f"rsocl {argv[0]}: error: ") and match in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "demo").exists() and not (tmp_path / "rec.h5").exists()


@pytest.mark.parametrize(
    "extra, match",
    [
        (
            ["--noise", "gaussian"],
            "--noise gaussian needs --sigma (the standard deviation as a fraction of full scale, "
            ">= 0); it has no default",
        ),
        (
            ["--noise", "poisson"],
            "--noise poisson needs --photons (photo-electrons at full scale, > 0); it has no default",
        ),
        (["--sigma", "0.01"], "--sigma applies to --noise gaussian only; with --noise none it would be ignored"),
        (["--noise", "poisson", "--photons", "100", "--sigma", "0.01"], "--sigma applies to --noise gaussian only"),
        (["--noise", "gaussian", "--sigma", "0.01", "--photons", "100"], "--photons applies to --noise poisson only"),
        (["--noise", "gaussian", "--sigma", "-0.1"], "--sigma must be >= 0 (fraction of full scale), got -0.1"),
        (["--noise", "poisson", "--photons", "0"], "--photons must be > 0 photo-electrons, got 0.0"),
        (["--bit-depth", "40"], "--bit-depth must be an integer >= 1 and <= 32, got 40"),
        (
            ["--noise", "poisson", "--photons", "1e30"],
            "--photons must be in (0, 1e+18] photo-electrons at full scale "
            "(the Poisson sampler's largest mean), got 1e+30",
        ),
        (["--seed", "-1"], "--seed must be an integer >= 0, got -1"),
    ],
)
def test_simulate_noise_options_are_complete_and_consistent_before_any_work(
    tmp_path, capsys, monkeypatch, extra, match
):
    from rsocl.model import scenes

    calls, real = [], scenes.load_scene
    monkeypatch.setattr(scenes, "load_scene", lambda *a, **k: calls.append(a) or real(*a, **k))
    out = tmp_path / "c.h5"
    assert main(["simulate", "builtin", "--out", str(out), "--shape", "8", "8"] + extra) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rsocl simulate: error: {match}"), err
    assert len(err.strip().splitlines()) == 1 and not calls and not out.exists()


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--t-r-us", "-3"], "--t-r-us must be > 0 µs, got -3.0"),  # was 't_r must be > 0 seconds, got -3e-06'
        (["--t-e-us", "0"], "--t-e-us must be > 0 µs, got 0.0"),
        (["--t-e-us", "inf"], "--t-e-us must be finite, got inf"),
        (["--dt-us", "-1"], "--dt-us must be > 0 µs, got -1.0"),
        (["--dt-us", "20"], "--dt-us must be >= --t-r-us = 35 µs (a sub-frame lasts at least one row time), got 20"),
        (["--t-r-us", "10", "--dt-us", "9.5"], "--dt-us must be >= --t-r-us = 10 µs"),
        (
            ["--t-e-us", "1e12"],
            "--t-e-us 1e+12 µs is 28,571,428,572 sub-frames of 35 µs, more than the 1,048,576 one "
            "exposure may span; give the exposure in µs",
        ),
        (["--t-e-us", "1e12", "--dt-us", "5e4"], "--t-e-us 1e+12 µs is 20,000,000 sub-frames of 50000 µs"),
    ],
)
def test_time_errors_use_the_microseconds_of_the_option(capsys, extra, match):
    for command in (["info"], ["plan", "--no-measure"]):
        assert main(command + ["--shape", "8", "8"] + extra) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"rsocl {command[0]}: error: {match}") and "seconds" not in err, err


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--lam", "-1"], "--lam must be >= 0, got -1.0"),
        (["--eta", "nan"], "--eta must be finite, got nan"),
        (["--tile", "0", "4"], "--tile must be (H, W) pixels with 1 <= H <= m = 12"),
        (["--device", "no-such-device"], "--device 'no-such-device' matches no OpenCL device"),
    ],
)
def test_an_api_check_on_an_option_names_the_option_as_typed(tmp_path, capsys, extra, match):
    cap = tmp_path / "one.h5"
    _capture_with_truth(cap, "one")
    assert main(["reconstruct", str(cap), "--out", str(tmp_path / "rec.h5"), "--quiet", *extra]) == 2
    assert capsys.readouterr().err.startswith(f"rsocl reconstruct: error: {match}")


@pytest.mark.parametrize(
    "fps, match", [("-1", "--camera-fps must be > 0 Hz, got -1.0"), ("nan", "--camera-fps must be finite, got nan")]
)
def test_info_names_the_camera_frame_rate_as_typed(capsys, fps, match):
    assert main(["info", "--shape", "8", "8", "--camera-fps", fps]) == 2
    assert capsys.readouterr().err.startswith(f"rsocl info: error: {match}")


@pytest.mark.parametrize(
    "capture, extra, match",
    [
        ("one", ["--overlap", "1"], "--overlap applies to --window (the frames consecutive windows share)"),
        ("one", ["--tile", "6", "10", "--overlap", "1"], "--overlap applies to --window"),
        (
            "one",
            ["--halo", "2"],
            "--halo applies to a run in tiles (--tile H W; also --sets, --workers, --scheduler, a "
            "Zarr --out or a capture too large for the device) or windows in tiles (--window with "
            "--tile); this capture runs in one piece, where --halo would be ignored",
        ),
        (
            "one",
            ["--retries", "1"],
            "--retries applies to a run in tiles (--tile H W; also --sets, --workers, --scheduler, "
            "a Zarr --out or a capture too large for the device) or windows (--window), whose "
            "tiles run as tasks; this capture runs in one piece, where --retries would be ignored",
        ),
        (
            "sets",
            ["--tile", "6", "10", "--batch", "2"],
            "--batch applies to the sets of a capture reconstructed in one "
            "piece; a run in tiles runs every tile of every set",
        ),
        (
            "one",
            ["--window", "1", "--batch", "2"],
            "--batch applies to the sets of a capture reconstructed in one piece; "
            "--window reconstructs set 0, window by window",
        ),
        (
            "one",
            ["--batch", "2"],
            "--batch applies to a capture of several sets reconstructed together; the capture "
            "holds one set, where --batch would be ignored",
        ),
        (
            "sets",
            ["--first-set-only", "--batch", "2"],
            "--batch applies to a capture of several sets reconstructed "
            "together; --first-set-only reconstructs set 0 only",
        ),
    ],
)
def test_options_the_run_would_ignore_are_refused_before_any_work(tmp_path, capsys, capture, extra, match):
    cap, out = tmp_path / f"{capture}.h5", tmp_path / "rec.h5"
    _capture_with_truth(cap, capture)
    assert main(["reconstruct", str(cap), "--out", str(out), "--iterations", "2", "--fast", "--quiet", *extra]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(f"rsocl reconstruct: error: {match}"), captured.err
    assert not captured.out and sorted(p.name for p in tmp_path.iterdir()) == [cap.name]


def test_options_that_contradict_each_other_on_a_capture_are_refused_before_any_work(tmp_path, capsys):
    from rsocl.cli.main import main

    sets, one = tmp_path / "sets.h5", tmp_path / "one.h5"
    _capture_with_truth(sets, "sets")
    _capture_with_truth(one, "one")
    cases = [
        (
            [str(sets), "--out", str(tmp_path / "a.zarr"), "--sets", "--first-set-only"],
            "--sets and --first-set-only contradict each other",
        ),
        ([str(one), "--out", str(tmp_path / "c.h5"), "--window", "1", "--workers", "2"], "--workers: the windows"),
    ]
    for extra, message in cases:
        capsys.readouterr()
        assert main(["reconstruct", *extra, "--iterations", "2", "--fast", "--quiet"]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, err
    assert not any(p.suffix == ".zarr" for p in tmp_path.iterdir())  # nothing was started
    pytest.importorskip("zarr")
    run = ["--halo", "2", "--iterations", "2", "--fast", "--quiet"]
    assert main(["reconstruct", str(sets), "--out", str(tmp_path / "d.zarr"), *run]) == 0
    assert "the capture holds 3 sets; the store gets set 0" in capsys.readouterr().err  # said, even --quiet
    assert main(["reconstruct", str(sets), "--out", str(tmp_path / "e.zarr"), "--first-set-only", *run]) == 0
    assert "3 sets" not in capsys.readouterr().err
    # tiles into an HDF5 file, and a stream of windows, take set 0 too: said as well
    assert main(["reconstruct", str(sets), "--out", str(tmp_path / "f.h5"), "--tile", "8", "8", *run]) == 0
    assert "the capture holds 3 sets; a tiled run into an HDF5 file reconstructs set 0" in capsys.readouterr().err
    stream = ["--window", "1", "--tile", "8", "8", *run]  # windows in tiles (--halo applies)
    assert main(["reconstruct", str(sets), "--out", str(tmp_path / "g.h5"), *stream]) == 0
    assert "the capture holds 3 sets; --window reconstructs set 0" in capsys.readouterr().err
    assert main(["reconstruct", str(sets), "--out", str(tmp_path / "h.h5"), "--first-set-only", *stream]) == 0
    assert "3 sets" not in capsys.readouterr().err


def test_inner_iterations_given_twice_must_agree_in_python(device):
    rig = rsocl.Rig.paper_array(4, (8, 8), t_e=0.18e-3, t_r=35e-6)
    g = np.ones((4, 8, 8))
    with pytest.raises(ValueError, match=r"tv_iterations = 3 and regularizer_options\['iterations'\] = 5 disagree"):
        rsocl.reconstruct(
            g, rig, iterations=1, tv_iterations=3, regularizer_options={"iterations": 5}, tune=False, device=device
        )
    assert (
        rsocl.reconstruct(
            g, rig, iterations=1, tv_iterations=5, regularizer_options={"iterations": 5}, tune=False, device=device
        ).params["regularizer_options"]["iterations"]
        == 5
    )


def test_a_gif_that_cannot_be_written_says_the_reconstruction_is(tmp_path, capsys, monkeypatch):
    # a full disk after the result: one line naming the GIF, its failure and the written (and kept) result
    import errno

    import rsocl.analysis.visual as visual
    from rsocl.files.atomic import OutputError

    def full(path, *args, **kwargs):
        raise OutputError(path, OSError(errno.ENOSPC, "No space left on device"), existed=False)

    cap, rec = tmp_path / "cap.h5", tmp_path / "rec.h5"
    assert main(["simulate", "builtin", "--out", str(cap), "--shape", "12", "12", "--quiet"]) == 0
    quick = ["--fixed", "--iterations", "2", "--quiet"]
    assert main(["reconstruct", str(cap), "--out", str(rec), *quick]) == 0
    capsys.readouterr()
    monkeypatch.setattr(visual, "comparison_gif", full)
    assert main(["reconstruct", str(cap), "--out", str(rec), *quick]) != 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot write" in err and "rec.gif" in err and "No space left" in err, err
    assert f"{rec} written, the earlier" in err and load_reconstruction(rec).datacube.shape[1:] == (12, 12), err


def test_an_interrupt_while_writing_sets_says_which_are_written_and_which_are_older(tmp_path, capsys, monkeypatch):
    import h5py

    import rsocl.cli.reconstruct as command
    from rsocl.files.hdf5 import save_capture
    from rsocl.model import reference as ref

    rig = rsocl.Rig.paper_array(2, (9, 7), t_e=1e-4, t_r=3e-5)
    rng = np.random.default_rng(5)
    sets = np.stack([ref.forward(rig, rng.random((rig.T,) + rig.shape)) for _ in range(4)])
    cap, rec = tmp_path / "sets.h5", tmp_path / "rec.h5"
    save_capture(cap, sets[0], rig)
    with h5py.File(cap, "a") as h5:
        h5.create_dataset("snapshot_sets", data=sets)
    run = ["reconstruct", str(cap), "--out", str(rec), "--iterations", "2", "--fixed", "--quiet"]
    assert main(run) == 0  # an earlier run's four set files
    saved = command.save_result
    calls = []

    def interrupted_at_the_third(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return saved(*args, **kwargs)

    monkeypatch.setattr(command, "save_result", interrupted_at_the_third)
    capsys.readouterr()
    assert main([*run, "--lam", "0.3"]) == 130
    err = capsys.readouterr().err
    kept = sorted(tmp_path.glob("rec-set*.earlier-*.h5"))  # sets 0 and 1's earlier files
    assert len(kept) == 2 and kept[0].name.startswith("rec-set000.earlier-")
    assert err == (
        f"rsocl reconstruct: interrupted: sets 0 to 1 written ({tmp_path / 'rec-set000.h5'} ..); 2 of the files "
        f"of sets 2 to 3 are an earlier run's ({tmp_path / 'rec-set002.h5'} ..), the 2 earlier files there are "
        f"kept as <stem>.earlier-<UTC time><suffix>: {kept[0]} ..\n"
    )


def test_sigterm_ends_a_command_as_ctrl_c_does_saying_what_was_kept(tmp_path, capsys, monkeypatch):
    import os
    import signal

    import rsocl.cli.reconstruct as command

    cap, rec = tmp_path / "cap.h5", tmp_path / "rec.h5"
    assert main(["simulate", "builtin", "--out", str(cap), "--shape", "12", "12", "--quiet"]) == 0
    before = signal.getsignal(signal.SIGTERM)

    def terminated(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        raise AssertionError("SIGTERM did not end the command")

    monkeypatch.setattr(command, "run_reconstruction", terminated)
    capsys.readouterr()
    assert main(["reconstruct", str(cap), "--out", str(rec), "--fixed", "--quiet"]) == 143
    assert capsys.readouterr().err == "rsocl reconstruct: terminated: nothing written\n" and not rec.exists()
    assert signal.getsignal(signal.SIGTERM) is before  # main put the handler back


def test_an_interrupt_while_drawing_the_pictures_says_the_result_is_written(tmp_path, capsys, monkeypatch):
    import rsocl.analysis.visual as visual

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    cap, rec = tmp_path / "cap.h5", tmp_path / "rec.h5"
    assert main(["simulate", "builtin", "--out", str(cap), "--shape", "12", "12", "--quiet"]) == 0
    monkeypatch.setattr(visual, "comparison_gif", interrupted)
    capsys.readouterr()
    assert main(["reconstruct", str(cap), "--out", str(rec), "--fixed", "--iterations", "2", "--quiet"]) == 130
    assert capsys.readouterr().err == f"rsocl reconstruct: interrupted: {rec} written; the pictures are not all drawn\n"
    assert rec.exists()


def test_saturation_is_checked_first_and_reaches_the_solver(tmp_path, capsys):
    cap, out = tmp_path / "one.h5", tmp_path / "rec.h5"
    _capture_with_truth(cap, "one")
    assert main(["reconstruct", str(cap), "--out", str(out), "--saturation", "0", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rsocl reconstruct: error: --saturation must be > 0"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == [cap.name]
    g = load_capture(cap).snapshots
    level = float(np.percentile(g, 80))
    argv = ["reconstruct", str(cap), "--out", str(out), "--iterations", "3", "--fixed", "--quiet"]
    assert main([*argv, "--saturation", repr(level)]) == 0
    assert load_reconstruction(out).params["saturated_pixels"] == int((g >= level).sum()) > 0
