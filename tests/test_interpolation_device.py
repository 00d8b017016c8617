"""interp3d on the device (kernels/interp.cl) against the NumPy reference, and the x0="interp3d" start."""

import numpy as np
import pytest

import rsocl
from rsocl.model.interpolation import interp3d
from rsocl.model.interpolation_device import interp3d_device
from rsocl.model.rig import Camera, Rig

#: largest difference to the float64 reference, relative to its largest value
TOLERANCE = {"float32": 1e-4, "float64": 1e-12}


def _reference(g, rig, valid, solved):
    sets = g if g.ndim == 4 else g[None]
    masks = [None] * len(sets) if valid is None else (valid if valid.ndim == 4 else valid[None])
    out = np.stack([interp3d(one, rig, valid=mask)[solved] for one, mask in zip(sets, masks)])
    return out if g.ndim == 4 else out[0]


def _check(rig, g, valid, solved, dtype, device):
    op = rsocl.RollingShutterOperator(rig, device=device, dtype=dtype)
    ref = _reference(g, rig, valid, slice(None) if solved is None else solved)
    got = interp3d_device(op, g, valid, solved).get()
    assert got.shape == ref.shape and got.dtype == np.dtype(dtype)
    assert np.isfinite(got).all()
    assert np.abs(got - ref).max() <= TOLERANCE[dtype] * np.abs(ref).max()


@pytest.mark.parametrize("cameras", [1, 2, 3, 4, 8])
@pytest.mark.parametrize("mask", ["exact", "binary"])
@pytest.mark.parametrize("t_e", [0.05e-3, 0.18e-3, 1e-3])
def test_matches_the_reference_on_paper_arrays(cameras, mask, t_e, dtype, device, rng):
    rig = Rig.paper_array(cameras, (9, 11), t_e=t_e, t_r=35e-6, mask=mask)
    g = rng.random((cameras,) + rig.shape)
    _check(rig, g, None, None, dtype, device)
    _check(rig, g, None, slice(2, max(3, rig.T - 1)), dtype, device)


def test_matches_the_reference_with_left_out_samples_and_batches(dtype, device, rng):
    # pixels keep 0, 1, 2, ... samples: the fallback mean, a constant, interpolation
    rig = Rig.paper_array(4, (7, 13), t_e=0.18e-3, t_r=35e-6)
    g = rng.random((3, 4) + rig.shape)
    valid = rng.random(g.shape) > 0.55
    valid[1, :, 0, 0] = False  # set 1, pixel (0, 0): no sample
    valid[2, 1:, 3, 4] = False  # set 2, pixel (3, 4): one sample
    _check(rig, g, valid, None, dtype, device)
    _check(rig, g, valid, slice(1, rig.T - 2), dtype, device)
    _check(rig, g[2], valid[2], None, dtype, device)


def test_matches_the_reference_on_oblique_cameras_gains_offsets_and_equal_times(dtype, device, rng):
    cams = [
        Camera(0, 1.8e-4, 3.5e-5, gain=0.5),
        Camera(90, 1.8e-4, 3.5e-5, t_a=2e-5, gain=2.0),
        Camera(0, 1.8e-4, 3.5e-5),  # the first camera's twin: equal sample times
        Camera(33, 2.5e-4, 3.0e-5),
        Camera(180, 1.0e-4, 3.5e-5, t_a=1e-5),
    ]
    rig = Rig(cams, (12, 10))
    g = rng.random((5,) + rig.shape) * 3
    _check(rig, g, None, None, dtype, device)
    _check(rig, g, rng.random(g.shape) > 0.3, None, dtype, device)


@pytest.mark.parametrize("frames", [8, 200])
def test_late_sub_frames_of_a_long_multi_frame_capture_are_as_close_as_early_ones(frames, dtype, device, rng):
    # T = 6683 and 189540: a sample time held as one float32 would be off by up to 8e-3 of a sub-frame
    cams = [Camera(a, 1.8e-4, 3.5e-5, frames=frames, t_d=1 / 30) for a in (0, 90, 180, 270)]
    rig = Rig(cams, (5, 6))
    g = rng.random((rig.n_channels,) + rig.shape)
    op = rsocl.RollingShutterOperator(rig, device=device, dtype=dtype)
    ref = interp3d(g, rig)
    for solved in (slice(0, 300), slice(rig.T - 300, rig.T)):
        got = interp3d_device(op, g, None, solved).get()
        assert np.abs(got - ref[solved]).max() <= 8 * np.finfo(dtype).eps * np.abs(ref).max()


def test_equal_sample_times_give_their_mean(device):
    rig = Rig([Camera(0, 1.8e-4, 3.5e-5), Camera(0, 1.8e-4, 3.5e-5)], (4, 5))
    g = np.stack([np.full(rig.shape, 1.0), np.full(rig.shape, 3.0)])
    op = rsocl.RollingShutterOperator(rig, device=device)
    out = interp3d_device(op, g).get()
    length = rig.windows.length[0]
    np.testing.assert_allclose(out, 2.0 / length, rtol=1e-6)


def test_every_sample_at_one_time_counts_with_equal_weight(device):
    # three identical cameras: one time per pixel, whose value is the mean of all three samples
    rig = Rig([Camera(0, 1.8e-4, 3.5e-5)] * 3, (4, 5))
    g = np.stack([np.zeros(rig.shape), np.zeros(rig.shape), np.full(rig.shape, 3.0)])
    op = rsocl.RollingShutterOperator(rig, device=device)
    length = rig.windows.length[0]
    np.testing.assert_allclose(interp3d(g, rig), 1.0 / length, rtol=1e-12)
    np.testing.assert_allclose(interp3d_device(op, g).get(), 1.0 / length, rtol=1e-6)


def test_groups_of_equal_times_interpolate_between_their_means(device):
    # the paper array's diagonal pixels: cameras 0 and 90 read them at one time, 180 and 270 at another
    rig = Rig.paper_array(4, (4, 4), t_e=0.18e-3, t_r=35e-6)
    g = np.stack([np.full(rig.shape, v) for v in (1.0, 3.0, 5.0, 7.0)]) * rig.windows.length[:, None, None]
    ref = interp3d(g, rig)[:, 0, 0]
    times = np.sort(rsocl.model.interpolation.samples(g, rig).times[:, 0, 0])
    centres = np.arange(rig.T) + 0.5
    expected = np.interp(centres, times[:2], [2.0, 6.0])  # the means of 1, 3 and of 5, 7, and a line between
    np.testing.assert_allclose(ref, expected, rtol=1e-12)
    op = rsocl.RollingShutterOperator(rig, device=device)
    np.testing.assert_allclose(interp3d_device(op, g).get()[:, 0, 0], expected, rtol=1e-5)


def test_bad_arguments_are_refused(device):
    rig = Rig.paper_array(4, (6, 6), t_e=0.18e-3, t_r=35e-6)
    op = rsocl.RollingShutterOperator(rig, device=device)
    g = np.ones((4,) + rig.shape)
    with pytest.raises(ValueError, match=r"g must have shape \(K, m, n\)"):
        interp3d_device(op, g[:3])
    with pytest.raises(ValueError, match="valid must have the shape of g"):
        interp3d_device(op, g, np.ones((4, 6, 5), bool))
    with pytest.raises(ValueError, match="solved must be a non-empty slice"):
        interp3d_device(op, g, None, slice(3, 3))
    with pytest.raises(ValueError, match="out must hold"):
        interp3d_device(op, g, None, None, out=interp3d_device(op, g, None, slice(0, 2)))


def test_reconstruct_starts_from_the_interpolation_when_asked(device, rng):
    rig = Rig.paper_array(4, (12, 14), t_e=0.18e-3, t_r=35e-6)
    g = np.stack(
        [rsocl.RollingShutterOperator(rig, device=device).forward(rng.random((rig.T,) + rig.shape)) for _ in range(2)]
    )
    kwargs = dict(iterations=3, tune=False, device=device)
    on_device = rsocl.reconstruct(g, rig, x0="interp3d", **kwargs)
    from_host = rsocl.reconstruct(g, rig, x0=np.stack([interp3d(one, rig) for one in g]), **kwargs)
    zeros = rsocl.reconstruct(g, rig, **kwargs)
    assert on_device.params["start"] == "interp3d" and from_host.params["start"] == "x0"
    assert zeros.params["start"] == "zeros"
    np.testing.assert_allclose(on_device.datacube, from_host.datacube, atol=1e-4 * np.abs(from_host.datacube).max())
    assert np.abs(zeros.datacube - from_host.datacube).max() > 1e-2 * np.abs(from_host.datacube).max()
    with pytest.raises(ValueError, match="x0 must be an array .* 'interp3d' or None, got 'linear'"):
        rsocl.reconstruct(g[0], rig, x0="linear", **kwargs)
