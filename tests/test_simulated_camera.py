"""The simulated camera backend: the forward model, each sensor effect, and the camera contract."""

import numpy as np
import pytest

from rsocl.common import registry as plugins
from rsocl.hardware.backend import CameraDisconnected, CameraError, CameraTimeout
from rsocl.model import reference
from rsocl.model.rig import Camera, Rig
from rsocl.model.scenes import builtin_scene
from rsocl_plugins.simulated import SimulatedCamera

SHAPE = (12, 10)
T_E, T_R = 180e-6, 35e-6


def _config(**extra):
    cfg = {"shape": list(SHAPE), "angle": 90.0, "t_e": T_E, "t_r": T_R}
    cfg.update(extra)
    return cfg


def _frames(cfg, n=1, mode="software"):
    with SimulatedCamera(cfg) as cam:
        cam.set_trigger(mode)
        cam.start()
        return [cam.capture() for _ in range(n)]


def _rig(angle=90.0, t_e=T_E, t_a=0.0, gain=1.0, row_map=None):
    return Rig([Camera(angle, t_e=t_e, t_r=T_R, t_a=t_a, gain=gain, row_map=row_map)], SHAPE)


def _flat(value, T):
    return np.full((T,) + SHAPE, value)


def test_registered_in_the_camera_group():
    assert plugins.load("rsocl.cameras", "simulated") is SimulatedCamera
    assert "simulated" in plugins.available("rsocl.cameras")


@pytest.mark.parametrize("geometry", ["angle 0", "angle 90", "angle 45", "row_map"])
def test_frames_equal_the_forward_model(geometry):
    if geometry == "row_map":
        row_map = np.random.default_rng(3).uniform(0, 11, SHAPE)
        cfg = {"shape": list(SHAPE), "row_map": row_map, "t_e": T_E, "t_r": T_R, "t_a": 7e-6, "gain": 1.3}
        camera = Camera(t_e=T_E, t_r=T_R, t_a=7e-6, gain=1.3, row_map=row_map)
    else:
        angle = float(geometry.split()[1])
        cfg = _config(angle=angle, t_a=7e-6, gain=1.3)
        camera = Camera(angle, t_e=T_E, t_r=T_R, t_a=7e-6, gain=1.3)
    rig = Rig([camera], SHAPE)
    frames = _frames(cfg, 2)
    for k, frame in enumerate(frames):  # each trigger advances the built-in scene: new seed per set
        truth = builtin_scene(SHAPE, rig.T, dtype=np.float64, seed=k)
        expected = reference.forward(rig, truth)[0]
        assert frame.image.dtype == np.float32 and frame.pixel_format == "Float32"
        np.testing.assert_allclose(frame.image, expected, rtol=1e-5, atol=1e-5)
        assert frame.meta["set"] == k and frame.meta["registered"] is True
        assert frame.timestamp == pytest.approx(k * rig.T * rig.dt + 7e-6)
    assert not np.allclose(frames[0].image, frames[1].image)


def test_array_scene_wraps_and_scene_frames_pads():
    rig = _rig()
    scene = np.random.default_rng(1).uniform(size=(2 * rig.T,) + SHAPE)
    frames = _frames(_config(scene=scene, scene_frames=rig.T), 3)
    for k, frame in enumerate(frames):
        block = scene[(k % 2) * rig.T : (k % 2 + 1) * rig.T]
        np.testing.assert_allclose(frame.image, reference.forward(rig, block)[0], rtol=1e-5, atol=1e-5)
    with SimulatedCamera(_config(scene=scene, scene_frames=rig.T)) as cam:
        assert cam.scene_truth(1).shape == (rig.T,) + SHAPE
        np.testing.assert_array_equal(cam.scene_truth(2), scene[: rig.T])


def test_camera_contract():
    cam = SimulatedCamera(_config(), name="sim")
    with pytest.raises(CameraError, match="not open"):
        cam.trigger()
    with cam:
        assert cam.readout_time == T_R
        with pytest.raises(CameraError, match="not started"):
            cam.trigger()
        cam.start()
        with pytest.raises(CameraTimeout, match="no trigger"):
            cam.read(0.1)
        with pytest.raises(CameraError, match="trigger lines"):
            cam.set_trigger("line", "Line1")
        assert cam.set_exposure(T_E / 2) == T_E / 2
        frame = cam.capture()
        np.testing.assert_allclose(
            frame.image,
            reference.forward(_rig(t_e=T_E / 2), cam.scene_truth(0)[: _rig(t_e=T_E / 2).T])[0],
            rtol=1e-5,
            atol=1e-5,
        )
        cam.set_trigger("free")
        assert cam.read(0.1).meta["set"] == 1  # free running: no trigger needed
        with pytest.raises(CameraError, match="stop acquisition"):
            cam.set_roi(0, 0, 4, 4)
        cam.stop()
        cam.set_roi(2, 3, 5, 4)
        cam.set_trigger("software")
        cam.start()
        cropped = cam.capture()
        assert cropped.image.shape == (4, 5) and cropped.meta["registered"] is True  # a window on the grid
        assert cropped.meta["roi"] == [2, 3, 5, 4]
        with pytest.raises(CameraError, match="exceeds"):
            cam.stop()
            cam.set_roi(8, 0, 5, 4)
    with pytest.raises(ValueError, match="unknown config key"):
        SimulatedCamera(_config(exposure=1.0))
    with pytest.raises(ValueError, match="unknown sensor option"):
        SimulatedCamera(_config(sensor={"noise": 1}))
    with pytest.raises(ValueError, match=r"config\['t_e'\] is required"):
        SimulatedCamera({"shape": [4, 4], "t_r": T_R})
    with pytest.raises(ValueError, match="t_e.*> 0"):
        SimulatedCamera(_config(t_e=-1.0))


def test_bit_depth_levels():
    clean = _frames(_config())[0].image.astype(np.float64)
    fs = T_E / T_R
    for bits, dtype, fmt in ((4, np.uint8, "Mono8"), (12, np.uint16, "Mono16")):
        frame = _frames(_config(sensor={"bit_depth": bits}))[0]
        assert frame.image.dtype == dtype and frame.pixel_format == fmt and frame.bit_depth == bits
        levels = 2**bits - 1
        assert frame.image.max() <= levels
        np.testing.assert_array_equal(frame.image, np.rint(np.clip(clean, 0, fs) / fs * levels))
        assert frame.meta["full_scale"] == pytest.approx(fs)
        back = frame.image * (frame.meta["full_scale"] / levels)
        assert np.abs(back - clean).max() <= fs / levels / 2 + 1e-4
    as_float = _frames(_config(sensor={"bit_depth": 3}, pixel_format="Float32"))[0]
    steps = as_float.image / (fs / 7)
    np.testing.assert_allclose(steps, np.rint(steps), atol=1e-4)
    assert len(np.unique(as_float.image)) <= 8
    mono16 = _frames(_config(pixel_format="Mono16"))[0]
    assert mono16.image.dtype == np.uint16 and mono16.bit_depth == 16
    with pytest.raises(ValueError, match="Mono8"):
        SimulatedCamera(_config(sensor={"bit_depth": 12}, pixel_format="Mono8"))


def test_saturation_clips():
    clean = _frames(_config())[0].image
    level = float(np.percentile(clean, 60))
    clipped = _frames(_config(sensor={"saturation": level}))[0].image
    np.testing.assert_allclose(clipped, np.minimum(clean, level), rtol=1e-6)
    assert np.mean(clipped == np.float32(level)) > 0.3
    dn = _frames(_config(sensor={"saturation": level, "bit_depth": 8}))[0]
    assert dn.meta["full_scale"] == level
    assert np.all(dn.image[clean >= level] == 255)


def test_noise_statistics():
    rig = _rig(angle=0.0)
    scene = _flat(0.5, rig.T)
    clean = reference.forward(rig, scene)[0]  # flat: 0.5 * t_e/dt everywhere
    fs = T_E / T_R
    big = {
        "shape": [64, 64],
        "angle": 0.0,
        "t_e": T_E,
        "t_r": T_R,
        "scene": np.full((rig.T, 64, 64), 0.5),
        "scene_frames": rig.T,
    }
    sigma = 0.02
    read = _frames(dict(big, sensor={"read_noise": sigma, "seed": 1}))[0].image - clean[0, 0]
    assert abs(read.mean()) < 3 * sigma * fs / 64
    assert read.std() == pytest.approx(sigma * fs, rel=0.1)
    photons = 400.0
    shot = _frames(dict(big, sensor={"shot_noise_photons": photons, "seed": 2}))[0].image.astype(np.float64)
    assert shot.mean() == pytest.approx(clean[0, 0], rel=0.01)
    assert shot.var() == pytest.approx(clean[0, 0] * fs / photons, rel=0.1)
    electrons = shot * photons / fs
    np.testing.assert_allclose(electrons, np.rint(electrons), atol=1e-3)
    # noise is seeded: same seed and index -> same frame; another camera index -> other noise
    again = _frames(dict(big, sensor={"read_noise": sigma, "seed": 1}))[0].image - clean[0, 0]
    np.testing.assert_array_equal(read, again)
    other = _frames(dict(big, sensor={"read_noise": sigma, "seed": 1}, index=1))[0].image - clean[0, 0]
    assert not np.array_equal(read, other)


def test_gain_scales_frames():
    one = _frames(_config())[0].image
    two = _frames(_config(gain=2.0))[0].image
    np.testing.assert_allclose(two, 2 * one, rtol=1e-6)
    # quantised: full scale is t_e/dt whatever the gain, so DN double (and saturate)
    dn1 = _frames(_config(sensor={"bit_depth": 10}))[0].image.astype(int)
    dn2 = _frames(_config(gain=2.0, sensor={"bit_depth": 10}))[0].image.astype(int)
    unclipped = dn2 < 1023
    assert np.all(np.abs(dn2[unclipped] - 2 * dn1[unclipped]) <= 1)
    assert np.all(2 * dn1[~unclipped] >= 1022) and (~unclipped).any()


def test_trigger_jitter_moves_the_exposure():
    steady = _frames(_config(t_a=50e-6), 3)
    jitter = 20e-6
    cfg = _config(t_a=50e-6, sensor={"trigger_jitter": jitter, "seed": 4})
    with SimulatedCamera(cfg) as cam:
        cam.start()
        shaky = [cam.capture() for _ in range(3)]
        truths = [cam.scene_truth(k) for k in range(3)]
    offsets = [f.meta["t_a"] for f in shaky]
    assert len(set(offsets)) == 3 and all(o >= 0 for o in offsets)
    assert max(abs(o - 50e-6) for o in offsets) < 5 * jitter
    for k, frame in enumerate(shaky):
        assert not np.allclose(frame.image, steady[k].image)
        rig = _rig(t_a=frame.meta["t_a"])
        truth = truths[k]  # a late trigger holds the last sub-frame
        truth = np.concatenate([truth, np.repeat(truth[-1:], max(0, rig.T - truth.shape[0]), axis=0)])[: rig.T]
        np.testing.assert_allclose(frame.image, reference.forward(rig, truth)[0], rtol=1e-5, atol=1e-5)
    assert [f.meta["t_a"] for f in steady] == [50e-6] * 3


def test_fail_after_disconnects():
    with SimulatedCamera(_config(fail_after=2)) as cam:
        cam.start()
        cam.capture()
        with pytest.raises(CameraDisconnected, match="read 2"):
            cam.capture()
        with pytest.raises(CameraDisconnected):
            cam.trigger()
    assert not cam._open


def test_a_camera_slower_than_its_rigs_dt_renders_its_own_windows():
    # a rig of cameras at t_r = 35 and 40 µs has dt = 35 µs: the slower camera's frames use that dt too
    slow = Camera(90.0, t_e=T_E, t_r=40e-6)
    rig = Rig([Camera(0.0, t_e=T_E, t_r=T_R), slow], SHAPE)
    (frame,) = _frames(_config(t_r=40e-6, dt=rig.dt, scene_frames=rig.T))
    truth = builtin_scene(SHAPE, rig.T, dtype=np.float64, seed=0)
    np.testing.assert_allclose(frame.image, reference.forward(rig, truth)[1], rtol=1e-5, atol=1e-5)


def test_full_scale_of_the_binary_mask_is_a_white_scenes_value():
    # t_e / dt = 5.14 sub-frames, and the paper's Eq. 4 counts the 6 sub-frame starts an exposure holds
    from rsocl.model.curvature import full_scales

    rig = Rig([Camera(90.0, t_e=T_E, t_r=T_R)], SHAPE, mask="binary")
    white = np.ones((rig.T,) + SHAPE)
    cfg = _config(mask="binary", scene=white, sensor={"bit_depth": 12}, pixel_format="Mono16")
    (frame,) = _frames(cfg)
    assert frame.meta["full_scale"] == full_scales(rig)[0] == 6.0
    assert frame.image.max() == 4095  # white is full scale, not clipped below it


def test_sensor_and_dtype_keys_beyond_their_ranges_are_refused_when_the_camera_is_made():
    with pytest.raises(ValueError, match=r"sensor\['shot_noise_photons'\] must be in \(0, 1e\+18\]"):
        SimulatedCamera(_config(sensor={"shot_noise_photons": 1e20}), name="sim")
    with pytest.raises(ValueError, match=r"sensor\['shot_noise_photons'\] must be at most 1.25e\+17 here"):
        SimulatedCamera(_config(gain=8.0, sensor={"shot_noise_photons": 1e18, "saturation": T_E / T_R}))
    for dtype in ("float16", "int32", 5):
        with pytest.raises(ValueError, match=r"sim: config\['dtype'\] must be one of \['float32', 'float64'\]"):
            SimulatedCamera(_config(dtype=dtype), name="sim")
