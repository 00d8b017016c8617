"""The static fix (rsocl.solver.static) and the blend with the start (ADMM.blend_towards) on the device against
their formulas in NumPy."""

import numpy as np
import pytest

import rsocl
from rsocl.model import reference as ref
from rsocl.model.operator import RollingShutterOperator
from rsocl.solver.static import static_fix, static_mask


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
