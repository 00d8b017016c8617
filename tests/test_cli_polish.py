"""The command line around the commands: entry points, output to pipes and files, plugin status,
multi-frame simulation, the ROI order, and the example script away from the shared data."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rsocl.cli.main import main

ROOT = Path(__file__).resolve().parents[1]


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def test_python_dash_m_rsocl_runs_the_command():
    done = subprocess.run(
        [sys.executable, "-m", "rsocl", "--help"], capture_output=True, text=True, env=_env(), timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: rsocl") and "plugins" in done.stdout


def test_a_reader_that_stops_reading_ends_the_command_quietly():
    # the read end is closed before rsocl writes anything (it imports every plugin first): its output meets EPIPE
    proc = subprocess.Popen(
        [sys.executable, "-m", "rsocl", "plugins"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env()
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141, err
    assert err == "", err


def test_the_demo_folder_is_ignored_by_git():
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    done = subprocess.run(["git", "-C", str(ROOT), "check-ignore", "-q", "rsocl-demo/demo.gif"])
    assert done.returncode == 0, "rsocl-demo/ (rsocl demo's default --out) is not in .gitignore"


def test_plugins_reports_a_camera_backend_whose_library_is_missing(monkeypatch, capsys):
    from rsocl.common.registry import status

    monkeypatch.setitem(sys.modules, "gi", None)  # import gi -> ImportError
    monkeypatch.setitem(sys.modules, "linuxpy", None)
    monkeypatch.setitem(sys.modules, "linuxpy.video", None)
    rows = {name: state for info, name, state in status("rsocl.cameras")}
    assert rows["simulated"] == "ok"
    assert rows["aravis"].startswith("missing dependency: ") and "PyGObject" in rows["aravis"], rows
    assert rows["v4l2"].startswith("missing dependency: ") and "linuxpy" in rows["v4l2"], rows
    assert main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert "v4l2" in out and "missing dependency" in out


def test_capture_draws_no_progress_bar_off_a_terminal(tmp_path, capsys):
    from rsocl.files.rigfile import RigFile, save_rigfile
    from rsocl.model.rig import Rig

    save_rigfile(tmp_path / "rig.toml", RigFile.from_rig(Rig.paper_array(2, (8, 8), t_e=1e-4, t_r=3e-5)))
    assert main(["capture", "--rig", str(tmp_path / "rig.toml"), "--out", str(tmp_path / "c.h5"), "--sets", "2"]) == 0
    captured = capsys.readouterr()  # stderr is not a terminal here
    assert captured.err == "", captured.err
    assert "wrote" in captured.out


def test_simulate_frames_makes_a_capture_that_window_reconstructs(tmp_path, capsys):
    from rsocl.files.hdf5 import load_capture_rig

    cap = tmp_path / "m.h5"
    assert (
        main(
            [
                "simulate",
                "builtin",
                "--shape",
                "8",
                "8",
                "--cameras",
                "2",
                "--frames",
                "3",
                "--out",
                str(cap),
                "--quiet",
            ]
        )
        == 0
    )
    rig = load_capture_rig(cap)
    assert [cam.frames for cam in rig.cameras] == [3, 3] and rig.n_channels == 6
    rows = max(float(rig.row_map(i).max()) + 1 for i in range(rig.C))
    assert rig.cameras[0].t_d == pytest.approx(rows * 35e-6)
    assert (
        main(
            [
                "reconstruct",
                str(cap),
                "--window",
                "2",
                "--out",
                str(tmp_path / "r.h5"),
                "--fast",
                "--iterations",
                "2",
                "--quiet",
            ]
        )
        == 0
    )
    assert (tmp_path / "r.h5").exists()
    # --t-d-us only with several frames, and long enough for the readout
    assert main(["simulate", "builtin", "--shape", "8", "8", "--t-d-us", "400", "--out", str(tmp_path / "x.h5")]) == 2
    assert "--t-d-us" in capsys.readouterr().err
    assert (
        main(
            [
                "simulate",
                "builtin",
                "--shape",
                "8",
                "8",
                "--frames",
                "2",
                "--t-d-us",
                "1",
                "--out",
                str(tmp_path / "x.h5"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "--frames 2 --t-d-us 1" in err and "t_d must be >=" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.h5").exists()


def test_simulate_says_when_it_resizes_a_video(tmp_path, capsys):
    video = tmp_path / "v.npy"
    np.save(video, np.random.default_rng(0).integers(0, 255, (5, 20, 24), dtype=np.uint8))
    assert main(["simulate", str(video), "--shape", "8", "8", "--cameras", "1", "--out", str(tmp_path / "c.h5")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rsocl simulate: warning: "), err
    assert "5 frames of 20x24 resized to T = " in err[0] and "of 8x8" in err[0] and "--shape 20 24" in err[0]


def test_plan_roi_is_x_y_width_height_as_in_a_rig_file(capsys):
    from rsocl.cli.plan import roi_from

    assert roi_from([2, 5, 16, 8], (32, 40)) == (5, 2, 8, 16)  # -> (y, x, height, width) of the API
    assert main(["plan", "--shape", "16", "32", "--roi", "4", "2", "24", "8", "--no-measure"]) == 0
    out = capsys.readouterr().out
    assert "proposed ROI (x, y, width, height, as rsocl plan --roi and a rig file's roi): 4 2 24 8; " in out
    assert "in Python: rig.crop((2, 4, 8, 24)), (y, x, height, width)" in out
    # a block that fits only in the other order is refused, saying the order
    assert main(["plan", "--shape", "16", "32", "--roi", "2", "4", "8", "24", "--no-measure"]) == 2
    err = capsys.readouterr().err
    assert "--roi is X Y WIDTH HEIGHT" in err and "got 2 4 8 24" in err


def test_the_shuffled_example_says_where_its_data_is_expected(tmp_path):
    script = ROOT / "examples" / "shuffled_rolling_shutter.py"
    done = subprocess.run(
        [sys.executable, str(script), "--data", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        env=_env(),
        timeout=120,
    )
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    assert "missing.npz" in lines[0] and "--data" in lines[0] and "wine_shuffled_rs_real.npz" in lines[0]
    assert not (tmp_path / "out").exists()
