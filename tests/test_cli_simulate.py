"""``rsocl simulate``: the device precision it is given, the memory of the whole run checked before
anything is allocated, and its progress bar."""

import re
import sys

import pytest

import rsocl
from rsocl.cli.main import main

SMALL = ["--shape", "16", "16"]


def _spy_operator_dtype(monkeypatch) -> list:
    """Record the ``dtype`` every forward operator of :func:`rsocl.simulate` is built with."""
    import rsocl.model.simulate as sim

    seen = []
    real = sim.RollingShutterOperator

    def spy(rig, *args, **kwargs):
        seen.append(kwargs.get("dtype"))
        return real(rig, *args, **kwargs)

    monkeypatch.setattr(sim, "RollingShutterOperator", spy)
    return seen


def test_simulate_runs_the_forward_model_in_the_dtype_given(tmp_path, monkeypatch, has_fp64):
    seen = _spy_operator_dtype(monkeypatch)
    dtypes = ["float32", "float64"] if has_fp64 else ["float32"]
    for dtype in dtypes:
        out = tmp_path / f"{dtype}.h5"
        assert main(["simulate", "builtin", "--out", str(out), *SMALL, "--dtype", dtype, "--quiet"]) == 0
    assert seen == dtypes  # --dtype float32 ran in float64 where the device has fp64
    assert main(["simulate", "builtin", "--out", str(tmp_path / "default.h5"), *SMALL, "--quiet"]) == 0
    assert seen[-1] == ("float64" if has_fp64 else "float32")  # no --dtype: rsocl.simulate's own default


def _limit(monkeypatch, nbytes):
    from rsocl.common import memory

    monkeypatch.setattr(memory, "host_memory_bytes", lambda: nbytes)


def _frames_limit(err):
    found = re.search(r"--frames must be 1\.\.([\d,]+)", err)
    assert found, err
    return int(found.group(1).replace(",", ""))


def test_frames_whose_whole_run_does_not_fit_are_refused_before_the_rig_is_built(tmp_path, capsys, monkeypatch):
    import rsocl.cli.simulate as cli_simulate
    import rsocl.model.rig as rig_module
    from rsocl.model.plausible import RIG_BYTES_PER_PIXEL

    limit = 64 * 2**20
    _limit(monkeypatch, limit)
    frames = 1000
    # each of the separate checks passes: the rig's row maps and windows, the float32 datacube
    T = 16 * frames + 5  # 16 rows of 35 µs between frames, sub-frames of 35 µs
    assert 4 * frames * 16 * 16 * RIG_BYTES_PER_PIXEL < limit and 4 * T * 16 * 16 < limit
    built = []

    class Spy(rig_module.Rig):
        def __init__(self, cameras, *args, **kwargs):
            built.append(max(cam.frames for cam in cameras))
            super().__init__(cameras, *args, **kwargs)

    monkeypatch.setattr(rig_module, "Rig", Spy)
    monkeypatch.setattr(cli_simulate, "scene_datacube", lambda *a: pytest.fail("the scene was built"))
    out = tmp_path / "c.h5"
    assert main(["simulate", "builtin", "--out", str(out), *SMALL, "--frames", str(frames), "--dtype", "float32"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert "rsocl simulate: error: --frames 1000: simulating 4 x 1000 snapshots of 16 x 16" in err, err
    assert "more than this machine's 64.0 MiB" in err
    assert "at --shape 16 16, --cameras 4, --t-d-us 560 and --dtype float32" in err
    assert 1 < _frames_limit(err) < frames
    assert max(built) == 1 and not out.exists()  # the one-frame rig only: no multi-frame rig, no scene, no file
    # float64 arithmetic needs more memory per frame: a lower bound
    assert main(["simulate", "builtin", "--out", str(out), *SMALL, "--frames", "1000", "--dtype", "float64"]) == 2
    assert _frames_limit(capsys.readouterr().err) < _frames_limit(err)


def test_the_frames_bound_in_the_message_is_the_one_enforced(tmp_path, capsys, monkeypatch):
    _limit(monkeypatch, 64 * 2**20)
    out = tmp_path / "c.h5"
    assert main(["simulate", "builtin", "--out", str(out), *SMALL, "--frames", "100000"]) == 2
    most = _frames_limit(capsys.readouterr().err)
    assert main(["simulate", "builtin", "--out", str(out), *SMALL, "--frames", str(most + 1)]) == 2
    assert f"--frames {most + 1}:" in capsys.readouterr().err
    assert main(["simulate", "builtin", "--out", str(out), *SMALL, "--frames", str(most)]) == 0
    assert f"4 cameras x {most} frames" in capsys.readouterr().out


def test_one_frame_whose_run_does_not_fit_names_the_shape(tmp_path, capsys, monkeypatch):
    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=180e-6, t_r=35e-6)
    _limit(monkeypatch, 100_000)  # the rig (20 KiB) and its datacube (4 T m n bytes) fit, the run not
    assert rig.datacube_bytes() < 100_000
    out = tmp_path / "c.h5"
    assert main(["simulate", "builtin", "--out", str(out), *SMALL]) == 2
    err = capsys.readouterr().err
    assert "--shape 16 16: simulating 4 x 1 snapshots of 16 x 16" in err, err
    assert "not even one frame fits: choose a smaller --shape or a longer --dt-us" in err
    assert not out.exists()


def test_simulate_draws_a_progress_bar_over_its_steps_on_a_terminal(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    argv = ["simulate", "builtin", "--out", str(tmp_path / "c.h5"), *SMALL, "--frames", "3"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    for step in ("rig", "scene", "snapshots", "writing"):
        assert f"simulate ({step})" in captured.err, captured.err
    assert "4/4" not in captured.out and "wrote" in captured.out
    assert main(argv + ["--quiet"]) == 0  # --quiet: no bar, the result line only
    captured = capsys.readouterr()
    assert captured.err == "" and captured.out.startswith(f"wrote {tmp_path / 'c.h5'}: ")
    assert len(captured.out.splitlines()) == 1
