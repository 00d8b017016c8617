"""The ADMM's residual in one launch (kernels/residual.cl) against the NumPy forward model, and the
runs that keep residuals on the device against the runs that read each one."""

import numpy as np
import pytest
from same_arithmetic import assert_same_arithmetic

import rsocl
from rsocl.model import reference as ref
from rsocl.model.operator import RollingShutterOperator
from rsocl.solver.admm import PROJECT_DEFERRED
from rsocl.solver.residuals import DeviceResiduals


def _want(rig, theta, g, w):
    """``‖g - H theta‖ / ‖g‖`` over the weights ``w`` per set (``‖H theta‖`` where ``g`` is 0), in NumPy."""
    out = []
    for t, gs, ws in zip(theta, g, w):
        d = gs - ref.forward(rig, t)
        g2 = np.sum(ws * gs**2)
        r2 = np.sum(ws * d**2)
        out.append(np.sqrt(r2 / g2) if g2 > 0 else np.sqrt(r2))
    return np.array(out)


# (9, 11): blocks cut by both edges of the ROI; (8, 16): whole blocks only
@pytest.mark.parametrize("shape", [(9, 11), (8, 16)])
@pytest.mark.parametrize("weighted", [False, True])
@pytest.mark.parametrize("sets", [None, 3])
def test_device_residual_matches_the_numpy_forward_model(device, dtype, rng, shape, weighted, sets):
    import pyopencl.array as cla

    rig = rsocl.Rig.paper_array(3, shape, t_e=1e-4, t_r=3e-5)
    op = RollingShutterOperator(rig, device=device, dtype=dtype)
    batch = sets or 1
    theta = rng.random((batch,) + op.domain_shape)
    g = np.stack([ref.forward(rig, t) for t in rng.random((batch,) + op.domain_shape)])
    if sets:
        g[1] = 0  # an all-zero set: the absolute residual
    w = (rng.random(g.shape) > 0.3).astype(float) if weighted else np.ones_like(g)
    cut = (lambda a: a) if sets else (lambda a: a[0])

    def dev(a):
        return cla.to_device(op.queue, np.ascontiguousarray(cut(a), dtype=op.dtype))

    res = DeviceResiduals(op, dev(g), dev(w) if weighted else None, sets, slots=3)
    theta_dev = dev(theta)
    zeros = dev(np.zeros_like(theta))
    res.enqueue(zeros, 0), res.enqueue(theta_dev, 2), res.enqueue(zeros, 1)  # every slot read is written
    got = [np.atleast_1d(r) for r in res.read(3).result()]
    # the reference works on the stored (rounded) values
    stored = lambda a: cut(a).astype(op.dtype).astype(np.float64).reshape((batch,) + a.shape[1:])  # noqa: E731
    want = _want(rig, stored(theta), stored(g), stored(w))
    tol = 2e-6 if dtype == "float32" else 1e-12
    np.testing.assert_allclose(got[2], want, rtol=tol)
    zero = _want(rig, 0 * stored(theta), stored(g), stored(w))  # 1, and 0 for an all-zero set
    np.testing.assert_allclose(got[0], zero, rtol=tol), np.testing.assert_allclose(got[1], zero, rtol=tol)


def test_slots_read_together_equal_slots_read_alone(device, rng):
    import pyopencl.array as cla

    rig = rsocl.Rig.paper_array(4, (10, 9), t_e=1e-4, t_r=3e-5)
    op = RollingShutterOperator(rig, device=device, dtype="float64")
    g = cla.to_device(op.queue, ref.forward(rig, rng.random(op.domain_shape)))
    cubes = [cla.to_device(op.queue, rng.random(op.domain_shape)) for _ in range(4)]
    res = DeviceResiduals(op, g, None, None, slots=4)
    alone = []
    for theta in cubes:
        res.enqueue(theta, 0)
        alone.append(res.read(1).result()[0])
    for slot, theta in enumerate(cubes):
        res.enqueue(theta, slot)
    assert res.read(4).result() == alone
    with pytest.raises(ValueError, match="slots must be >= 1"):
        DeviceResiduals(op, g, None, None, slots=0)
    with pytest.raises(ValueError, match=r"slot must be in \[0, 3\]"):
        res.enqueue(cubes[0], 4)


@pytest.mark.parametrize("iterations", [8, 19])
def test_residuals_read_in_groups_equal_the_waited_ones(device, iterations):
    # 19 iterations: groups of RESIDUAL_SLOTS and a last, shorter one
    rig = rsocl.Rig.paper_array(4, (10, 9), t_e=1e-4, t_r=3e-5)
    g = ref.forward(rig, np.random.default_rng(3).random((rig.T,) + rig.shape))
    kw = dict(iterations=iterations, lam=0.05, eta=0.3, tv_iterations=3, dtype="float64", tune=False)
    fast = rsocl.reconstruct(np.stack([g, 0.5 * g]), rig, **kw)
    waited = rsocl.reconstruct(np.stack([g, 0.5 * g]), rig, callback=lambda it, r, theta: False, **kw)
    assert np.shape(fast.history["residual"]) == (iterations, 2)
    assert_same_arithmetic(fast.history["residual"], waited.history["residual"], device)
    assert_same_arithmetic(fast.datacube, waited.datacube, device)


def _solver(device, rig, g, valid, dtype):
    import pyopencl.array as cla

    from rsocl.solver.admm import ADMM
    from rsocl_plugins.tv import TV

    op = RollingShutterOperator(rig, device=device, dtype=dtype)
    g_dev = cla.to_device(op.queue, np.ascontiguousarray(g, dtype=op.dtype))
    return ADMM(op, g_dev, TV(iterations=3), lam=(0.05, 0.1), eta=(0.3, 0.2), valid=valid)


# float32 sums in float64, or in float32 on a device without fp64; "no room": the device's local memory too small
# for the projection's sums, so the residual keeps its own launch
@pytest.mark.parametrize("case", ["float64", "float32", "float32 without fp64", "gpu", "no room"])
def test_the_projection_puts_the_residual_the_separate_launch_gives(device, monkeypatch, case):
    rig = rsocl.Rig.paper_array(4, (10, 9), t_e=1e-4, t_r=3e-5)  # blocks cut by both edges
    rng = np.random.default_rng(5)
    g = np.stack([ref.forward(rig, rng.random((rig.T,) + rig.shape)) for _ in range(2)])
    valid = rng.random(g.shape) > 0.2
    dtype = "float32" if case.startswith("float32") else "float64"
    if case == "float32 without fp64":
        device = device.limited(fp64=False)
    elif case == "no room":
        device = device.limited(local_mem_bytes=256)
    elif case == "gpu":  # the dual update folded into the TV's and the projection's launches
        from rsocl.device.context import Device

        monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    folded, alone = _solver(device, rig, g, valid, dtype), _solver(device, rig, g, valid, dtype)
    assert folded.folds_residual == (case != "no room")
    slots = folded.residuals.slots
    for it in range(11):  # the residual of iteration it - 1, in the next iteration's projection
        folded.step(residual_slot=None if it == 0 else (it - 1) % slots)
        alone.step()
        alone.residual_into(it % slots)
    folded.residual_into(10 % slots)
    assert_same_arithmetic(folded.theta.get(), alone.theta.get(), device)
    sums = folded.read_residuals(slots).result(), alone.read_residuals(slots).result()
    assert_same_arithmetic(*sums, device, np.dtype(dtype))
    with pytest.raises(ValueError, match=r"slot must be in \[0, 7\]"):
        folded.step(residual_slot=slots)


def test_steps_after_the_first_set_no_argument_of_the_projection(device):
    """Each iteration's residual goes to its own slot without a by-value argument changing (the slot is the
    launch's global offset): on PoCL setting one costs several times a launch's host time."""
    rig = rsocl.Rig.paper_array(4, (10, 9), t_e=1e-4, t_r=3e-5)
    rng = np.random.default_rng(6)
    g = np.stack([ref.forward(rig, rng.random((rig.T,) + rig.shape)) for _ in range(2)])
    solver = _solver(device, rig, g, None, "float32")
    solver.step()
    first = dict(solver._project._values)
    solver.step(residual_slot=0)
    set_once = dict(solver._project._values)  # on a GPU the second step sets the deferred TV step's flag
    assert {k for k, v in set_once.items() if first.get(k) != v} <= {PROJECT_DEFERRED}
    for it in range(2, 2 * solver.residuals.slots + 2):
        solver.step(residual_slot=(it - 1) % solver.residuals.slots)
    assert solver._project._values == set_once
