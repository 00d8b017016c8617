"""The static fix (rsocl.solver.static) and the blend with the start (ADMM.blend_towards) on the device against
their formulas in NumPy."""

import numpy as np
import pytest

import rsocl
from rsocl.model import reference as ref
from rsocl.model.operator import RollingShutterOperator
from rsocl.solver.static import noise_level, point_mask, static_fix, static_mask, static_weights


def _snapshots(rig, rng, sets):
    """Snapshots ``(K, m, n)`` or ``(sets, K, m, n)`` of scenes with a still half, the left one in even sets,
    the right one in odd sets; the other half moves."""
    out = []
    half = rig.shape[1] // 2
    for s in range(sets or 1):
        cube = np.repeat(rng.random((1,) + rig.shape), rig.T, axis=0)
        moving = slice(half, None) if s % 2 == 0 else slice(None, half)
        cube[:, :, moving] = rng.random((rig.T, rig.shape[0], rig.shape[1] - half if s % 2 == 0 else half))
        out.append(ref.forward(rig, cube))
    return np.stack(out) if sets else out[0]


def _solver(device, g, dtype="float32"):
    """An ADMM on snapshots ``g`` of :func:`_rig`, and its operator."""
    import pyopencl.array as cla

    from rsocl.solver.admm import ADMM
    from rsocl_plugins.tv import TV

    op = RollingShutterOperator(_rig(), device=device, dtype=dtype)
    return ADMM(op, cla.to_device(op.queue, g.astype(op.dtype)), TV(iterations=2), lam=0.1, eta=0.2), op


def _rig():
    return rsocl.Rig.paper_array(4, (9, 12), t_e=1e-4, t_r=3e-5)


@pytest.mark.parametrize("sets", [None, 2])
@pytest.mark.parametrize("weight", [0.0, 0.4, 1.0])
def test_the_static_fix_pulls_static_pixels_towards_the_start(device, dtype, rng, sets, weight):
    import pyopencl.array as cla

    rig = _rig()
    g = _snapshots(rig, rng, sets)
    solver, op = _solver(device, g, dtype)
    theta = rng.random(solver.theta.shape).astype(op.dtype)
    start = rng.random(solver.theta.shape).astype(op.dtype)
    solver.theta.set(theta)
    counts = static_fix(solver, cla.to_device(op.queue, start), g, weight)
    masks = np.stack([static_mask(one) for one in g]) if sets else static_mask(g)[None]
    assert not any(point_mask(one).any() for one in (g if sets else [g]))  # random textures hold no points
    assert counts == ([int(m.sum()) for m in masks] if sets else int(masks[0].sum()))
    half = rig.shape[1] // 2
    assert masks[0, :, : half - 1].any() and not masks[0, :, half + 1 :].any()
    assert not sets or (masks[1, :, half + 1 :].any() and not masks[1, :, : half - 1].any())
    w = (weight * masks[:, None]).reshape((-1, 1) + rig.shape) if sets else weight * masks
    want = theta + w.astype(op.dtype) * (start - theta)
    np.testing.assert_allclose(solver.theta.get(), want, rtol=1e-6, atol=1e-6)
    kept = ~np.broadcast_to(masks[:, None] if sets else masks, want.shape) | (weight == 0)
    np.testing.assert_array_equal(solver.theta.get()[kept], theta[kept])


def test_the_pull_needs_a_start_and_weights_of_the_estimates_shape(device, rng):
    import pyopencl.array as cla

    rig = _rig()
    g = _snapshots(rig, rng, None)
    solver, op = _solver(device, g)
    start = cla.to_device(op.queue, np.zeros((rig.T - 1,) + rig.shape, op.dtype))
    with pytest.raises(ValueError, match="x0 must match theta"):
        static_fix(solver, start, g, 0.5)
    with pytest.raises(ValueError, match=r"weights must be \(1, 9, 12\), got \(9, 12\)"):
        solver.pull_towards(cla.to_device(op.queue, np.zeros((rig.T,) + rig.shape, op.dtype)), np.zeros(rig.shape))


@pytest.mark.parametrize("sets", [None, 2])
@pytest.mark.parametrize("alpha", [0.0, 0.35, 1.0])
def test_the_blend_moves_every_voxel_towards_the_start(device, dtype, rng, sets, alpha):
    import pyopencl.array as cla

    solver, op = _solver(device, _snapshots(_rig(), rng, sets), dtype)
    theta = rng.random(solver.theta.shape).astype(op.dtype)
    start = rng.random(solver.theta.shape).astype(op.dtype)
    solver.theta.set(theta)
    solver.blend_towards(cla.to_device(op.queue, start), alpha)
    want = start + op.dtype.type(alpha) * (theta - start)
    np.testing.assert_allclose(solver.theta.get(), want, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("alpha", [-0.1, 1.5])
def test_a_blend_outside_0_to_1_is_refused(device, rng, alpha):
    import pyopencl.array as cla

    solver, op = _solver(device, _snapshots(_rig(), rng, None))
    with pytest.raises(ValueError, match=rf"blend must be in \[0.0, 1.0\], got {alpha}"):
        solver.blend_towards(cla.to_device(op.queue, np.zeros(solver.theta.shape, op.dtype)), alpha)


# ---------------------------------------------------------------------------------------- point sources
def _points(rig, places, speed=0.0, sigma=None):
    """Datacube of single bright pixels (1 on 0) at ``places``, moving ``speed`` pixels per sub-frame to the right
    (wrapping); blurred by a Gaussian of ``sigma`` pixels and scaled to peak 1 when given."""
    from scipy.ndimage import gaussian_filter

    cube = np.zeros((rig.T,) + rig.shape)
    for t in range(rig.T):
        for y, x in places:
            cube[t, y, int(round(x + speed * t)) % rig.shape[1]] = 1.0
    if sigma is not None:
        cube = np.stack([gaussian_filter(f, sigma) for f in cube])
        cube /= cube.max()
    return cube


def _noisy(g, rig, photons, read, seed):
    from rsocl.model.simulate import full_scale

    scale = full_scale(rig)
    rng = np.random.default_rng(seed)
    return rng.poisson(np.clip(g, 0, None) * photons / scale) * (scale / photons) + rng.normal(0, read * scale, g.shape)


def _paper(cameras=4, side=32):
    return rsocl.Rig.paper_array(cameras, (side, side), t_e=1.8e-4, t_r=3.5e-5)


@pytest.mark.parametrize("cameras", [2, 4, 8])
@pytest.mark.parametrize("sigma", [None, 1.0])
def test_a_static_point_under_noise_is_found_with_its_window(cameras, sigma):
    rig = _paper(cameras)
    places = [(16, 16), (7, 23)]
    g = _noisy(ref.forward(rig, _points(rig, places, sigma=sigma)), rig, photons=100, read=0.01, seed=cameras)
    assert not static_mask(g)[16, 16]  # the cameras disagree by more than the static mask's 2 %
    mask = point_mask(g)
    for y, x in places:
        assert mask[y - 2 : y + 3, x - 2 : x + 3].all()
    assert mask.sum() == 2 * 25


@pytest.mark.parametrize("cameras", [2, 4, 8])
def test_moving_points_textures_and_flat_noise_have_no_points(cameras):
    rig = _paper(cameras)
    moving = ref.forward(rig, _points(rig, [(10, 5), (22, 20)], speed=0.3))
    assert not point_mask(moving).any()
    texture = ref.forward(rig, rsocl.builtin_scene(rig.shape, rig.T))
    assert not point_mask(texture).any() and not point_mask(_noisy(texture, rig, 300, 0.01, 1)).any()
    flat = _noisy(ref.forward(rig, np.full((rig.T,) + rig.shape, 0.5)), rig, 300, 0.01, 2)
    assert not point_mask(flat).any()


def test_one_camera_or_a_grid_smaller_than_the_window_has_no_points():
    g = np.zeros((1, 12, 12))
    g[0, 6, 6] = 5.0
    assert not point_mask(g).any()
    g = np.zeros((4, 6, 12))
    g[:, 3, 6] = 5.0
    assert not point_mask(g).any()


def test_noise_level_is_the_noise_of_one_camera():
    rng = np.random.default_rng(3)
    g = np.repeat(rng.random((1, 64, 64)), 4, axis=0) + rng.normal(0, 0.05, (4, 64, 64))
    assert noise_level(g) == pytest.approx(0.05, rel=0.1)
    assert noise_level(np.repeat(rng.random((1, 8, 8)), 3, axis=0)) == 0.0


def test_static_weights_give_points_their_weight_and_nothing_at_weight_zero():
    g = np.zeros((4, 16, 16))
    g[:, 8, 8] = 5.0
    w = static_weights(g, 0.6)
    assert np.all(w[6:11, 6:11] == 1.0) and w[2, 2] == 0.6  # the black surround: static
    assert not static_weights(g, 0.0).any()


@pytest.mark.not_under_oclgrind("a whole self-tuned reconstruction, over 10 min under Oclgrind; no kernel of its own")
@pytest.mark.parametrize("cameras", [2, 4])
def test_the_default_keeps_a_static_point_under_noise_as_the_interpolation_does(cameras):
    rig = _paper(cameras)
    truth = _points(rig, [(16, 16)])
    g = _noisy(ref.forward(rig, truth), rig, photons=100, read=0.01, seed=0)
    result = rsocl.reconstruct(g, rig)
    start = rsocl.interp3d(g, rig)
    assert result.params["static_pixels"] >= 25
    np.testing.assert_allclose(result.datacube[:, 14:19, 14:19], start[:, 14:19, 14:19], rtol=1e-5, atol=1e-5)
    assert result.datacube[:, 16, 16].mean() > 0.9
    assert rsocl.psnr(result.datacube, truth) > rsocl.psnr(start, truth) - 1.0


def test_a_tile_under_its_frames_levels_marks_the_pixels_the_whole_frame_marks():
    from rsocl.solver.static import frame_levels, levels

    g = np.ones((4, 24, 24))
    g[:, :, 10:] = 0.2  # a dark right part with no bright pixel of its own
    g[0, 5, 18] = 0.21  # cameras that disagree by 0.01: static against the dark half's level, not the frame's
    block = g[:, :, 11:]  # a tile of columns 12.. with a halo of one column (the mask's erosion)
    whole = static_weights(g, 0.75)[:, 12:]
    assert not np.array_equal(static_weights(block, 0.75)[:, 1:], whole)  # its own bright level is 0.2
    with frame_levels(levels(g)):
        np.testing.assert_array_equal(static_weights(block, 0.75)[:, 1:], whole)


@pytest.mark.not_under_oclgrind("four self-tuned tile runs: minutes under Oclgrind; the levels are host code")
def test_every_tile_of_a_tiled_run_fixes_its_static_part_with_the_whole_frames_levels(monkeypatch):
    import rsocl.solver.pipeline as pipeline
    import rsocl.solver.static as static
    from rsocl.scale import reconstruct_tiled

    rig = rsocl.Rig.paper_array(4, (24, 24), t_e=1.8e-4, t_r=3.5e-5)
    g = RollingShutterOperator(rig).forward(rsocl.builtin_scene(rig.shape, rig.T, seed=1))
    seen, fix = [], pipeline.static_fix

    def spy(solver, start, snapshots, weight):
        seen.append((static._FRAME.get(), snapshots.shape))
        return fix(solver, start, snapshots, weight)

    monkeypatch.setattr(pipeline, "static_fix", spy)
    reconstruct_tiled(g, rig, tile=(12, 12), halo=4, iterations=3)
    assert len(seen) == 4 and all(shape == (4, 16, 16) for _, shape in seen)
    assert all(measured == static.levels(g) for measured, _ in seen)
    assert static._FRAME.get() is None  # outside the tiles' runs
