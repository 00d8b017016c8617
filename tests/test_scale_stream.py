"""A multi-frame capture as a stream of overlapping time windows."""

import numpy as np
import pytest

import rsocl
from rsocl.analysis.metrics import psnr
from rsocl.model.rig import Camera, Rig
from rsocl.model.scenes import builtin_scene
from rsocl.scale import reconstruct_tiled
from rsocl.scale.stream import frame_windows, reconstruct_stream, window_channels


def _rig(frames=3, shape=(20, 24)):
    t_r, t_e = 3.5e-5, 1.8e-4
    t_d = shape[0] * t_r  # continuous readout: frame k+1 starts as frame k's readout ends
    return Rig([Camera(a, t_e=t_e, t_r=t_r, t_d=t_d, frames=frames) for a in (0, 90, 180, 270)], shape)


def test_windows_cover_every_frame_and_keep_every_exposure():
    assert frame_windows(5, 2, 1) == [(0, 2), (1, 3), (2, 4), (3, 5)]
    assert frame_windows(5, 3, 1) == [(0, 3), (2, 5)]
    assert frame_windows(4, 3, 0) == [(0, 3), (1, 4)]
    rig = _rig()
    for k0, k1 in frame_windows(3, 2, 1):
        sub = rig.frames_window(k0, k1)
        channels = window_channels(rig, k0, k1)
        np.testing.assert_allclose(sub.start_times(), rig.start_times()[channels], rtol=0, atol=1e-15)
        np.testing.assert_array_equal(sub.windows.index, rig.windows.index[channels])
    with pytest.raises(ValueError, match=r"overlap must be a whole number of frames in \[0, window - 1 = 1\]"):
        frame_windows(3, 2, 2)
    with pytest.raises(ValueError, match="window"):
        frame_windows(3, 4, 0)


def test_a_stream_of_windows_matches_the_whole_capture():
    rig = _rig()
    truth = builtin_scene(rig.shape, rig.T, seed=1)
    g = rsocl.RollingShutterOperator(rig).forward(truth)
    whole = rsocl.reconstruct(g, rig, iterations=20, tune=False).datacube
    stream = reconstruct_stream(g, rig, window=2, overlap=1, iterations=20, tune=False)
    assert stream.datacube.shape == whole.shape and len(stream.windows) == 2
    assert all(b - a < rig.T for a, b in stream.spans)  # each window models part of the capture
    sampled = rig.sampled_range()
    assert np.all(stream.owner[sampled] >= 0)
    assert psnr(stream.datacube, truth) > psnr(whole, truth) - 0.3
    one = reconstruct_stream(g, rig, window=3, overlap=0, iterations=20, tile=(10, 12), halo=4, tune=False)
    np.testing.assert_array_equal(
        one.datacube, reconstruct_tiled(g, rig, tile=(10, 12), halo=4, iterations=20, tune=False).datacube
    )


def test_a_streams_window_results_hold_their_own_subframes_so_memory_grows_with_the_capture():
    """Each window's result covered the capture from time 0 to its end and all were kept: memory grew with
    the square of the capture (1.7 GB for 120 frames of 32x32 whose result is 15 MiB)."""
    rig = _rig(frames=8, shape=(12, 12))
    g = rsocl.RollingShutterOperator(rig).forward(builtin_scene(rig.shape, rig.T, seed=3))
    stream = reconstruct_stream(g, rig, window=2, overlap=1, iterations=3, tune=False)
    assert len(stream.results) == 7
    for w, (result, (start, stop)) in enumerate(zip(stream.results, stream.spans)):
        assert result.datacube.shape == (stop - start,) + rig.shape
        mine = np.nonzero(stream.owner == w)[0]
        mine = mine[(mine >= start) & (mine < stop)]
        np.testing.assert_array_equal(result.datacube[mine - start], stream.datacube[mine])
    held = sum(r.datacube.nbytes for r in stream.results)
    assert held <= 2.5 * stream.datacube.nbytes  # windows of 2 frames overlapping by 1: each sub-frame twice


def test_default_windows_fit_any_capture():
    assert frame_windows(1) == [(0, 1)] and frame_windows(3) == [(0, 2), (1, 3)]
    assert frame_windows(3, 1) == [(0, 1), (1, 2), (2, 3)]
    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=1.8e-4, t_r=3.5e-5)  # one frame per camera
    g = rsocl.RollingShutterOperator(rig).forward(builtin_scene(rig.shape, rig.T, seed=4))
    stream = reconstruct_stream(g, rig, iterations=5, tune=False)
    np.testing.assert_array_equal(stream.datacube, rsocl.reconstruct(g, rig, iterations=5, tune=False).datacube)


def test_a_stream_into_a_zarr_store_is_refused_before_anything_runs(tmp_path):
    rig = _rig(frames=3, shape=(12, 12))
    g = rsocl.RollingShutterOperator(rig).forward(builtin_scene(rig.shape, rig.T, seed=1))
    with pytest.raises(
        ValueError,
        match=r"out: a stream of frame windows is assembled in memory .*writes no Zarr "
        r"store, got out='.*s.zarr'; leave out out",
    ):
        reconstruct_stream(g, rig, window=2, iterations=3, tune=False, out=str(tmp_path / "s.zarr"))
    assert list(tmp_path.iterdir()) == []


def test_rsocl_reconstruct_window(tmp_path, capsys):
    from rsocl.cli.main import main
    from rsocl.files.hdf5 import load_reconstruction, save_capture

    rig = _rig(frames=3, shape=(16, 16))
    truth = builtin_scene(rig.shape, rig.T, seed=2)
    save_capture(tmp_path / "cap.h5", rsocl.RollingShutterOperator(rig).forward(truth), rig, truth=truth)
    out = tmp_path / "stream.h5"
    assert (
        main(
            [
                "reconstruct",
                str(tmp_path / "cap.h5"),
                "--out",
                str(out),
                "--window",
                "2",
                "--iterations",
                "5",
                "--quiet",
            ]
        )
        == 0
    )
    assert "2 window(s) of 2 frame(s)" in capsys.readouterr().out
    back = load_reconstruction(out)
    assert back.datacube.shape == (rig.T,) + rig.shape and back.params["windows"] == [[0, 2], [1, 3]]
    assert (tmp_path / "stream-tuning.png").is_file()
    assert (
        main(
            [
                "reconstruct",
                str(tmp_path / "cap.h5"),
                "--out",
                str(tmp_path / "one.h5"),
                "--window",
                "1",
                "--iterations",
                "3",
                "--fast",
                "--quiet",
            ]
        )
        == 0
    )  # the default overlap follows --window
    assert load_reconstruction(tmp_path / "one.h5").params["overlap"] == 0
    assert main(["reconstruct", str(tmp_path / "cap.h5"), "--out", str(tmp_path / "s.zarr"), "--window", "2"]) == 2
    assert "--window: a stream of frame windows is written to an HDF5 file" in capsys.readouterr().err


def test_a_stream_with_gaps_between_frames_fills_every_subframe_from_the_nearest_window():
    # frames 3 readouts apart and every camera late by 5 rows: sub-frames before the first exposure
    # and between frames are sampled by no window; each holds its nearest window's modelled sub-frame
    t_r, t_e, shape = 3.5e-5, 1.8e-4, (12, 12)
    rig = Rig(
        [Camera(a, t_e=t_e, t_r=t_r, t_a=5 * t_r, t_d=3 * shape[0] * t_r, frames=3) for a in (0, 90, 180, 270)], shape
    )
    g = rsocl.RollingShutterOperator(rig).forward(builtin_scene(rig.shape, rig.T, seed=3))
    stream = reconstruct_stream(g, rig, window=1, overlap=0, iterations=10, tune=False)
    assert np.all(stream.owner >= 0) and stream.datacube.shape == (rig.T,) + shape
    first = stream.spans[0][0]
    assert first == 5
    np.testing.assert_array_equal(stream.datacube[:first], np.broadcast_to(stream.datacube[first], (first,) + shape))
    gaps = [s for s in range(first, rig.T) if not any(a <= s < b for a, b in stream.spans)]
    assert gaps  # the rig leaves sub-frames between frames unsampled
    for s in gaps:
        a, b = stream.spans[stream.owner[s]]
        np.testing.assert_array_equal(stream.datacube[s], stream.datacube[min(max(s, a), b - 1)])


def test_a_stream_whose_window_fails_ends_in_one_error_naming_the_window(tmp_path, capsys, monkeypatch):
    from rsocl.cli.main import main
    from rsocl.files.hdf5 import save_capture
    from rsocl.scale import runner as runner_module

    rig = _rig(frames=3, shape=(16, 16))
    save_capture(tmp_path / "cap.h5", rsocl.RollingShutterOperator(rig).forward(builtin_scene(rig.shape, rig.T)), rig)
    solve, calls = runner_module.solve_tile, []

    def second_window_fails(job, *args):
        calls.append(job)
        if len(calls) > 1:
            raise FloatingPointError("ADMM diverged")
        return solve(job, *args)

    monkeypatch.setattr(runner_module, "solve_tile", second_window_fails)
    out = tmp_path / "stream.h5"
    argv = ["reconstruct", str(tmp_path / "cap.h5"), "--out", str(out), "--window", "1", "--iterations", "3"]
    assert main(argv + ["--fixed", "--retries", "0", "--quiet"]) == 1
    err = capsys.readouterr().err
    first, *rest = err.strip().splitlines()
    assert first == (
        f"rsocl reconstruct: error: window 2/3 (frames 1..1) failed: 1 task(s) failed, 0 solved and discarded, "
        f"with the 1 window(s) done before it; nothing was written to {out} (a stream's --out is written once "
        f"every window is solved):"
    ), err
    assert len(rest) == 1 and rest[0].startswith("  tile (0, 0) ") and "FloatingPointError: ADMM diverged" in rest[0]
    assert "Traceback" not in err and not out.exists()


def test_a_streams_params_hold_the_whole_captures_subframes_and_saturated_pixels():
    t_r, shape = 3.5e-5, (12, 12)
    cameras = [Camera(a, t_e=1.8e-4, t_r=t_r, t_d=shape[0] * t_r, frames=3) for a in (0, 90, 180, 270)]
    rig = Rig(cameras, shape)
    g = rsocl.RollingShutterOperator(rig).forward(builtin_scene(shape, rig.T, seed=2))
    level = float(np.percentile(g, 90))
    stream = reconstruct_stream(g, rig, window=2, overlap=1, iterations=3, tune=False, saturation=level)
    first = stream.results[0].params
    span = rig.sampled_range()
    assert stream.params["solved_subframes"] == [span.start, span.stop] != first["solved_subframes"]
    assert stream.params["saturated_pixels"] == int(np.count_nonzero(g >= level)) > first["saturated_pixels"]
    assert stream.params["lam"] == first["lam"]
