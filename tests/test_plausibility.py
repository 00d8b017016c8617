"""Inputs that are possible but implausible: refused before work when they cannot run, warned when they can.

Times in the wrong unit, rigs and files larger than the machine, a run that never moved, snapshots
far above their full scale, the paper's projection at its default eta, the effective frame rate
of multi-frame captures.
"""

import numpy as np
import pytest

import rsocl
from rsocl.analysis.metrics import psnr
from rsocl.cli.main import main
from rsocl.common import memory
from rsocl.model import reference as ref
from rsocl.model.curvature import default_scale
from rsocl.model.operator import RollingShutterOperator
from rsocl.model.scenes import builtin_scene
from rsocl.model.simulate import full_scale


@pytest.fixture
def small_machine(monkeypatch):
    """A machine of 1 GiB, for every host-memory check."""
    monkeypatch.setattr(memory, "host_memory_bytes", lambda: 2**30)


# ---------------------------------------------------------------------- times in the wrong unit (item 11)
def test_an_exposure_in_us_given_as_seconds_is_refused_naming_the_unit():
    with pytest.warns(UserWarning, match=r"t_e = 180 s is longer than 1 s"):
        with pytest.raises(
            ValueError,
            match=r"cameras\[0\]\.t_e = 180 s is 5,142,857 sub-frames .* did you mean "
            r"180 µs \(t_e=0.00018\)\?",
        ):
            rsocl.Rig.paper_array(4, shape=(64, 64), t_e=180, t_r=35e-6)


def test_a_row_time_in_us_given_as_seconds_is_warned_in_one_line_naming_t_r():
    with pytest.warns(
        UserWarning,
        match=r"^camera t_r = 35 s is longer than 1 ms per row; times are in seconds: "
        r"did you mean 35 µs \(t_r=3.5e-05\)\?$",
    ) as caught:
        rsocl.Rig.paper_array(4, shape=(16, 16), t_e=180e-6, t_r=35)
    assert all("\n" not in str(w.message) for w in caught)


@pytest.mark.parametrize(
    "kwargs, said",
    [
        (dict(t_r=35e-3), r"camera t_r = 0\.035 s is longer than 1 ms per row; .*did you mean 0\.035 ms"),
        (dict(t_a=20.0), r"camera t_a = 20 s is longer than 1 s \(the trigger offset\); .*did you mean 20 µs"),
        (dict(t_d=3.0, frames=2), r"camera t_d = 3 s is longer than 1 s \(the frame period\); .*did you mean 3 ms"),
    ],
)
def test_a_time_in_ms_or_a_trigger_offset_or_frame_period_in_us_is_warned_with_its_likely_unit(kwargs, said):
    with pytest.warns(UserWarning, match=said):
        rsocl.Camera(0, **{"t_e": 180e-6, "t_r": 35e-6, **kwargs})


def test_an_exposure_of_seconds_is_warned_and_kept():
    with pytest.warns(UserWarning, match=r"camera t_e = 2 s is longer than 1 s.*did you mean 2 µs"):
        camera = rsocl.Camera(0, t_e=2.0, t_r=35e-6)
    assert camera.t_e == 2.0


def test_plausible_times_warn_nothing(recwarn):
    rsocl.Rig.paper_array(4, shape=(16, 16), t_e=1.0, t_r=1e-3)
    assert not [w for w in recwarn if issubclass(w.category, UserWarning)]


# ---------------------------------------------------------------------- memory (items 12, 13)
def test_a_rig_larger_than_the_host_is_refused_before_its_arrays(small_machine):
    cams = [rsocl.Camera(a, t_e=1.8e-4, t_r=3.5e-5) for a in (0, 90)]
    with pytest.raises(
        ValueError,
        match=r"^shape \(30000, 30000\): a rig of 2 camera\(s\) on 30000 x 30000 pixels "
        r".* needs at least 33.5 GiB of host memory, more than this machine's 1.0 GiB",
    ):
        rsocl.Rig(cams, (30000, 30000))


def test_reconstruct_refuses_a_datacube_larger_than_the_host_naming_shape_T_and_sets(monkeypatch):
    rig = rsocl.Rig.paper_array(4, (64, 64), t_e=1.8e-4, t_r=3.5e-5)
    g = np.zeros((3, rig.n_channels) + rig.shape, np.float32)
    need = 4 * 3 * rig.T * 64 * 64
    monkeypatch.setattr(memory, "host_memory_bytes", lambda: need - 1)
    with pytest.raises(
        ValueError,
        match=rf"^rig shape 64x64 and T = {rig.T}: the 3 sets x {rig.T} x 64 x 64 float32 "
        r"datacube needs at least",
    ):
        rsocl.reconstruct(g, rig, tune=False)


def test_a_capture_whose_stored_rig_is_larger_than_the_host_is_refused_naming_the_file(tmp_path, small_machine, capsys):
    import h5py

    from rsocl.files.hdf5 import load_capture_rig, save_capture

    rig = rsocl.Rig.paper_array(2, (8, 8), t_e=1.8e-4, t_r=3.5e-5)
    cap = tmp_path / "cap.h5"
    save_capture(cap, np.zeros((rig.n_channels,) + rig.shape), rig)
    with h5py.File(cap, "r+") as h5:
        h5.attrs["rig"] = h5.attrs["rig"].replace('"shape": [8, 8]', '"shape": [20000, 20000]')
    with pytest.raises(
        ValueError,
        match=r"cap.h5: the stored rig is not valid: shape \(20000, 20000\): a rig of 2 "
        r"camera\(s\) .* more than this machine's 1.0 GiB",
    ):
        load_capture_rig(cap)
    for argv in (["info", "--capture", str(cap)], ["reconstruct", str(cap), "--out", str(tmp_path / "r.h5")]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "cap.h5" in err and "the stored rig is not valid: shape (20000, 20000)" in err, err
        assert err.count("\n") == 1, err


def test_a_stored_row_map_claiming_more_than_the_host_is_refused_before_it_is_read(tmp_path, small_machine):
    import h5py

    from rsocl.files.hdf5 import load_capture_rig, save_capture

    rows = rsocl.Camera(0, t_e=1.8e-4, t_r=3.5e-5).rows((8, 8))
    rig = rsocl.Rig([rsocl.Camera(t_e=1.8e-4, t_r=3.5e-5, row_map=rows)], (8, 8))
    cap = tmp_path / "cap.h5"
    save_capture(cap, np.zeros((1, 8, 8)), rig)
    with h5py.File(cap, "r+") as h5:
        del h5["rig_row_maps/0"]
        h5.create_dataset("rig_row_maps/0", shape=(100000, 100000), dtype="f8", chunks=(100, 100))  # 80 GB, unwritten
    with pytest.raises(
        ValueError,
        match=r"cap.h5: the stored rig is not valid: row map 'rig_row_maps/0': its "
        r"\(100000, 100000\) float64 array needs at least 74.5 GiB",
    ):
        load_capture_rig(cap)


def _npy_claiming(path, shape):
    """A .npy file whose header claims ``shape`` (float64) and which holds 8 bytes of data."""
    header = {"descr": "<f8", "fortran_order": False, "shape": shape}
    with open(path, "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, header)
        fh.write(b"\0" * 8)


def test_a_npy_claiming_ten_billion_elements_is_refused_naming_the_file(tmp_path, small_machine):
    from rsocl.model.scenes import load_video

    video = tmp_path / "video.npy"
    _npy_claiming(video, (10, 100000, 10000))
    with pytest.raises(
        ValueError,
        match=r"^path: '.*video.npy': the 10 x 100000 x 10000 float64 array its header "
        r"claims \(10,000,000,000 elements\) needs at least 74.5 GiB",
    ):
        load_video(video)


def test_a_npy_whose_header_claims_more_than_the_file_holds_is_refused_as_damaged(tmp_path):
    from rsocl.model.scenes import load_video

    video = tmp_path / "video.npy"
    _npy_claiming(video, (4, 100, 100))
    with pytest.raises(
        ValueError,
        match=r"claims a 4 x 100 x 100 float64 array \(312.5 KiB\), the file holds "
        r"8.0 KiB|the file holds 0.0 KiB of data: it is truncated or damaged",
    ):
        load_video(video)


def test_a_row_map_file_claiming_ten_billion_elements_is_refused_naming_the_key(tmp_path, small_machine):
    from rsocl.files.rigfile import load_rigfile

    _npy_claiming(tmp_path / "rows.npy", (100000, 100000))
    rig = tmp_path / "rig.toml"
    rig.write_text(
        '[rig]\nshape = [8, 8]\n\n[[camera]]\nbackend = "simulated"\nrow_map_file = "rows.npy"\n'
        "t_e = 1.8e-4\nt_r = 3.5e-5\n"
    )
    with pytest.raises(ValueError, match=r"camera\[0\]\.row_map_file: '.*rows.npy': the 100000 x 100000 float64 array"):
        load_rigfile(rig)


def test_a_rig_file_with_t_e_of_100_s_is_refused_before_capture(tmp_path, capsys):
    rig = tmp_path / "rig.toml"
    rig.write_text('[rig]\nshape = [64, 64]\n\n[[camera]]\nbackend = "simulated"\nt_e = 100\nt_r = 3.5e-5\n')
    assert main(["capture", "--rig", str(rig), "--out", str(tmp_path / "c.h5")]) == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if ": error:" in line]
    assert len(errors) == 1 and "t_e = 100 s is 2,857,143 sub-frames" in errors[0], err
    assert "did you mean 100 µs" in errors[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]


# ---------------------------------------------------------------------- a run that never moved (item 5)
def _demo(shape=(16, 16), cameras=4):
    rig = rsocl.Rig.paper_array(cameras, shape, t_e=1.8e-4, t_r=3.5e-5)
    truth = builtin_scene(rig.shape, rig.T)
    return rig, truth, RollingShutterOperator(rig).forward(truth)


def test_a_run_that_never_moved_is_an_error_naming_eta_lam_and_the_range():
    rig, _, g = _demo()
    with pytest.raises(
        FloatingPointError,
        match=r"^ADMM never moved: the residual stayed at \[1\] over 10 "
        r"iterations with eta = 1e\+30 and lam = 0.1: .* choose eta up to "
        r"about 4 psi = ",
    ):
        rsocl.reconstruct(g, rig, eta=1e30, lam=0.1, tune=False)
    with pytest.raises(FloatingPointError, match=r"never moved in set\(s\) \[1\]"):  # per set of a batch
        rsocl.reconstruct(np.stack([g, g]), rig, eta=[0.2, 1e30], lam=0.1, tune=False, iterations=4)


@pytest.mark.parametrize("eta", [0.0, None])
def test_a_run_at_its_fixed_point_from_the_first_iteration_is_a_result(eta):
    """One camera and one sub-frame: the data fix the estimate, GAP (eta = 0) lands on the same point every
    iteration and its residual stays put; that is not the stall of an eta far above psi."""
    rig = rsocl.Rig.paper_array(1, (1, 7), t_e=1e-6, t_r=3e-5)
    assert rig.T == 1
    g = ref.forward(rig, np.random.default_rng(0).random((rig.T,) + rig.shape))
    result = rsocl.reconstruct(g, rig, tune=False, iterations=12, eta=eta, lam=0.1)
    res = np.asarray(result.history["residual"])
    assert np.all(np.isfinite(result.datacube)) and len(res) == 12 and res[-1] > 0
    if eta == 0.0:
        np.testing.assert_allclose(res, res[0], rtol=1e-6)  # still from the first iteration on: a fixed point
    with pytest.raises(FloatingPointError, match=r"ADMM never moved: .* eta = 1e\+30"):  # far above psi: refused
        rsocl.reconstruct(g, rig, tune=False, iterations=12, eta=1e30, lam=0.1)


def test_a_run_from_the_interpolation_that_never_moved_is_an_error():
    rig, _, g = _demo()
    with pytest.raises(FloatingPointError, match="ADMM never moved"):
        rsocl.reconstruct(g, rig, eta=1e30, lam=0.1, tune=False, x0="interp3d")


def test_a_moving_run_and_all_zero_snapshots_are_not_stalls():
    rig, truth, g = _demo()
    result = rsocl.reconstruct(g, rig, tune=False, iterations=12)
    assert psnr(result.datacube, truth) > 14
    zero = rsocl.reconstruct(np.zeros_like(g), rig, tune=False, iterations=3)
    assert not zero.datacube.any()


def test_the_stall_and_far_checks_read_psi_only_for_a_run_they_may_flag(monkeypatch):
    """psi is a launch and a read back: a run that moves and ends near the data (one set or a batch, run past
    the stall check's 10 records) never makes it; a run that stood still does, to name it."""
    made = []
    psi_device = RollingShutterOperator.psi_device
    monkeypatch.setattr(RollingShutterOperator, "psi_device", lambda self: made.append(1) or psi_device(self))
    rig, _, g = _demo()
    rsocl.reconstruct(g, rig, tune=False, iterations=20)
    rsocl.reconstruct(np.stack([g, g]), rig, lam=[0.1, 0.2], tune=False, iterations=20)
    assert made == []
    with pytest.raises(FloatingPointError, match="ADMM never moved"):
        rsocl.reconstruct(g, rig, eta=1e30, lam=0.1, tune=False)
    assert made


def test_a_run_whose_eta_keeps_it_far_from_the_data_is_warned(recwarn):
    # eta 2000 psi: the residual moves a few per cent, not the 1e-6 of a stall, and the cube stays near 0
    rig, truth, g = _demo()
    psi = float(np.max(RollingShutterOperator(rig).psi))
    said = r"^ADMM ended far from the data: the residual is 0\.9\d* after 20 iterations with eta = \d[\d.e+]*, "
    with pytest.warns(RuntimeWarning, match=said):
        rsocl.reconstruct(g, rig, eta=2000 * psi, lam=0.1, tune=False, iterations=20)
    with pytest.warns(RuntimeWarning, match=r"far from the data in set\(s\) \[1\]"):
        rsocl.reconstruct(np.stack([g, g]), rig, eta=[0.2, 2000 * psi], lam=0.1, tune=False, iterations=20)
    recwarn.clear()
    rsocl.reconstruct(g, rig, eta=2000 * psi, lam=0.1, tune=False, iterations=20, x0=truth)  # a start that fits
    rsocl.reconstruct(g, rig, tune=False, iterations=20)
    assert not [w for w in recwarn if "far from the data" in str(w.message)]


def test_the_cli_reports_a_run_that_never_moved_in_one_line(tmp_path, capsys):
    assert (
        main(["demo", "--fast", "--eta", "1e30", "--shape", "16", "16", "--quiet", "--out", str(tmp_path / "d")]) == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("rsocl demo: error: ADMM never moved") and err.count("\n") == 1, err
    assert "eta = 1e+30" in err


# ---------------------------------------------------------------------- snapshots off their full scale (item 5)
def test_one_camera_far_above_its_full_scale_is_warned_in_one_line():
    rig, _, g = _demo()
    g = g.copy()
    g[2] *= 100
    full = rig.cameras[2].t_e / rig.dt
    with pytest.warns(
        UserWarning,
        match=rf"^g: snapshots of camera 2 reach .*, \d+(\.\d+)? times its full scale "
        rf"{full:.4g} ",
    ) as caught:
        rsocl.reconstruct(g, rig, tune=False, iterations=3)
    assert len([w for w in caught if "full scale" in str(w.message)]) == 1


def test_a_camera_whose_binary_windows_hold_no_subframe_does_not_hide_anothers_full_scale(recwarn):
    t_r = 1e-5  # camera 0: 0.3 t_r from 0.2 t_r into a sub-frame, no sub-frame start inside: full scale 0
    cameras = [rsocl.Camera(0, t_e=0.3 * t_r, t_r=t_r, t_a=0.2 * t_r), rsocl.Camera(90, t_e=3 * t_r, t_r=t_r)]
    rig = rsocl.Rig(cameras, (6, 7), mask="binary")
    g = ref.forward(rig, np.random.default_rng(0).random((rig.T,) + rig.shape))
    g[1] *= 1000
    with pytest.warns(UserWarning, match=r"^g: snapshots of camera 1 reach .*, \d+ times its full scale 4 "):
        rsocl.reconstruct(g, rig, tune=False, lam=0.1, eta=0.2, iterations=2)
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]  # no 0/0 from camera 0


def test_snapshots_within_their_full_scale_or_saturated_warn_nothing(recwarn):
    rig, _, g = _demo()
    rsocl.reconstruct(g, rig, tune=False, iterations=3)
    g = g.copy()
    g[2, :4] = 1e6  # saturated pixels are left out of the data term
    rsocl.reconstruct(g, rig, tune=False, iterations=3, saturation=1e5)
    assert not [w for w in recwarn if "full scale" in str(w.message)]


@pytest.mark.parametrize("mask", ["exact", "binary"])
def test_a_white_scene_reaches_the_full_scale_and_is_not_clipped(mask):
    # binary: the paper array's exposures hold 6 sub-frame starts, above t_e/dt = 5.14
    rig = rsocl.Rig.paper_array(4, (12, 12), t_e=180e-6, t_r=35e-6, mask=mask)
    white = np.ones((rig.T,) + rig.shape)
    g = rsocl.simulate(white, rig)
    assert full_scale(rig) == pytest.approx(g.max(), rel=1e-12)
    assert full_scale(rig) == pytest.approx(6.0 if mask == "binary" else 180 / 35, rel=1e-12)
    grey = rsocl.simulate(0.9 * white, rig, bit_depth=12)
    np.testing.assert_allclose(grey, 0.9 * g, atol=full_scale(rig) / 4095)


# ---------------------------------------------------------------------- the paper's projection (item 9)
@pytest.mark.parametrize("cameras", [4, 8])
def test_the_paper_projection_converges_at_its_defaults_on_the_demo(cameras):
    rig, truth, g = _demo((64, 64), cameras)
    result = rsocl.reconstruct(g, rig, projection="paper", tune=False)
    assert result.params["eta"] == pytest.approx(5.0 * default_scale(rig))
    assert psnr(result.datacube, truth) > 17.0


def test_the_demo_with_the_paper_projection_converges_at_its_defaults(tmp_path, capsys):
    assert main(["demo", "--projection", "paper", "--quiet", "--out", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    assert float(out.split("PSNR ")[1].split(" dB")[0]) > 17.0


# ---------------------------------------------------------------------- effective frame rate (item 8)
def test_the_effective_fps_of_a_multi_frame_rig_counts_its_frames(tmp_path, capsys):
    from rsocl.files.hdf5 import save_capture

    t_r = 3.5e-5
    rig = rsocl.Rig([rsocl.Camera(a, t_e=1.8e-4, t_r=t_r, t_d=12 * t_r, frames=4) for a in (0, 90)], (10, 10))
    assert rig.effective_fps(67.0) == pytest.approx(67.0 * rig.T_se / 4)
    cap = tmp_path / "cap.h5"
    save_capture(cap, np.zeros((rig.n_channels,) + rig.shape), rig)
    assert main(["info", "--capture", str(cap), "--camera-fps", "67"]) == 0
    line = [text for text in capsys.readouterr().out.splitlines() if text.startswith("effective fps")][0]
    assert line.split()[-1] == f"{67.0 * rig.T_se / 4:,.0f}"


def test_a_simulated_camera_whose_scene_exceeds_the_host_is_refused_before_capture(tmp_path, capsys, monkeypatch):
    from rsocl_plugins.simulated import SimulatedCamera

    # scene_frames is the API's (a rig file sets it from the rig, tests/test_rig_files.py)
    config = {"shape": [64, 64], "t_e": 1.8e-4, "t_r": 3.5e-5, "scene_frames": 1000000000}
    with pytest.raises(ValueError) as info, SimulatedCamera(config, name="camera 0 (simulated)"):
        pass
    message = str(info.value)
    assert (
        "config['scene_frames'] = 1000000000 (t_e = 0.00018 s, dt = 3.5e-05 s: the camera's own T = 69): "
        "its scene of 1,000,000,000 x 64 x 64 float64 sub-frames needs" in message
    ), message
    assert "\n" not in message
    rig = tmp_path / "rig.toml"
    rig.write_text('[rig]\nshape = [64, 64]\n\n[[camera]]\nbackend = "simulated"\nt_e = 10\nt_r = 3.5e-5\n')
    monkeypatch.setattr(memory, "host_memory_bytes", lambda: 2**30)
    assert main(["capture", "--rig", str(rig), "--out", str(tmp_path / "c.h5")]) == 2
    err = capsys.readouterr().err
    assert "rsocl capture: warning: camera t_e = 10 s is longer than 1 s" in err, err
    assert (
        "scene_frames'] = 285778 (t_e = 10 s, dt = 3.5e-05 s: the camera's own T = 285,778): "
        "its scene of 285,778 x 64 x 64 float64" in err
    ), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]


def test_an_npz_video_claiming_ten_billion_elements_is_refused_naming_the_file_and_key(tmp_path, small_machine):
    import io
    import zipfile

    from rsocl.model.scenes import load_video

    member = io.BytesIO()
    np.lib.format.write_array_header_1_0(member, {"descr": "<f8", "fortran_order": False, "shape": (10, 10**5, 10**4)})
    member.write(b"\0" * 8)
    with zipfile.ZipFile(tmp_path / "video.npz", "w") as archive:
        archive.writestr("video.npy", member.getvalue())
    with pytest.raises(
        ValueError,
        match=r"^path: '.*video.npz'\['video'\]: the 10 x 100000 x 10000 float64 array its "
        r"header claims \(10,000,000,000 elements\)",
    ):
        load_video(tmp_path / "video.npz")


def test_the_far_eta_warning_counts_each_sets_own_iterations():
    rig, _, g = _demo()
    psi = float(np.max(RollingShutterOperator(rig).psi))
    with pytest.warns(RuntimeWarning, match=r"far from the data in set\(s\) \[1\]: .* after \d iterations "):
        batch = rsocl.reconstruct(
            np.stack([g, g]), rig, eta=[0.2, 2000 * psi], lam=0.1, tune=False, iterations=30, tol=1e-2
        )
    assert batch.set(1).params["iterations_run"] < batch.params["iterations_run"]


def test_simulate_asks_for_fp64_only_where_the_device_has_it(device):
    rig = rsocl.Rig.paper_array(4, (8, 8), t_e=180e-6, t_r=35e-6)
    truth = builtin_scene(rig.shape, rig.T)
    no_fp64 = device.limited(fp64=False)
    np.testing.assert_allclose(rsocl.simulate(truth, rig, device=no_fp64), ref.forward(rig, truth), rtol=1e-6)
    with pytest.raises(ValueError, match="needs cl_khr_fp64"):
        rsocl.simulate(truth, rig, device=no_fp64, dtype="float64")


def test_an_exposure_of_astronomically_many_subframes_is_one_short_line():
    import rsocl

    with pytest.raises(ValueError) as info:
        rsocl.Rig([rsocl.Camera(0, t_e=1e-4, t_r=1e-300)], (4, 4))
    said = str(info.value)
    assert "is 1e+296 sub-frames of dt = 1e-300 s" in said and "choose a longer dt (t_r unless given)" in said
    assert len(said) < 250
