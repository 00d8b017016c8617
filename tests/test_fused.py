"""The fused TV (several Chambolle iterations per launch on local-memory tiles) against the plain TV,
and rsocl on a device with lower limits than the one it runs on (no fp64, small work groups and
local memory). Small sizes: these tests also run under Oclgrind."""

import numpy as np
import pytest

import rsocl
from rsocl.model import reference as ref
from rsocl.testing import check_regularizer
from rsocl_plugins.tv import STEP, TV

#: Local memory and work-group limits of a small device: tiles of a few hundred voxels with halos.
SMALL_GROUP = dict(max_work_group_size=16, max_work_item_sizes=(8, 8, 8))


def _tol(dtype):
    return 1e-6 if dtype == "float32" else 1e-13


@pytest.fixture(scope="module")
def small(device):
    """``device`` presenting 16 work items per group (8 along each axis) and no fp64."""
    return device.limited(fp64=False, **SMALL_GROUP)


def _both(dev, x, weight, **options):
    """Plain and fused TV of host array ``x`` on ``dev``, and the fused plan."""
    import pyopencl.array as cla

    xd = cla.to_device(dev.queue, x)
    plain = TV(**options).denoise(xd, weight).get()
    fused = TV(fused=3, **options)
    return plain, fused.denoise(xd, weight).get(), fused.fused_plan(xd)


@pytest.mark.parametrize(
    "shape, local_bytes, temporal_weight",
    [
        ((5, 7, 9), 4096, 3.0),  # one set, tiles 1 x 7 x 5: halos along x
        ((2, 3, 5, 11), 2048, 1.0),  # a batch, tiles with halos along x and t, three launches
        ((5, 7, 9), 2048, 0.0),  # 2-D per sub-frame
    ],
)
def test_fused_tv_equals_plain_tv(device, dtype, rng, shape, local_bytes, temporal_weight):
    local_bytes *= np.dtype(dtype).itemsize // 4  # as many values in either dtype
    dev = device.limited(local_mem_bytes=local_bytes, **SMALL_GROUP)
    x = rng.random(shape).astype(dtype)
    weight = 0.2 if len(shape) == 3 else np.array([0.2, 0.6])
    plain, fused, plan = _both(dev, x, weight, iterations=7, temporal_weight=temporal_weight)
    assert plan is not None and len(plan.launches) >= 2
    assert plan.local[0] * plan.local[1] <= 16 and max(plan.local) <= 8
    assert plan.local_values() * x.itemsize <= local_bytes
    np.testing.assert_allclose(fused, plain, rtol=0, atol=_tol(dtype))
    want = ref.tv_chambolle(x[0] if x.ndim == 4 else x, 0.2, 7, temporal_weight, STEP)
    np.testing.assert_allclose(fused[0] if x.ndim == 4 else fused, want, atol=1e-4 if dtype == "float32" else 1e-10)


def test_too_little_local_memory_takes_the_plain_path(device, rng):
    dev = device.limited(local_mem_bytes=256)
    x = rng.random((3, 5, 7)).astype(np.float32)
    plain, fused, plan = _both(dev, x, 0.3, iterations=5)
    assert plan is None
    np.testing.assert_array_equal(fused, plain)


def test_one_iteration_and_weight_zero(device, rng):
    x = rng.random((3, 5, 7)).astype(np.float32)
    plain, fused, _ = _both(device, x, 0.3, iterations=1)
    np.testing.assert_array_equal(fused, plain)
    plain, fused, _ = _both(device, x, 0.0, iterations=4)
    np.testing.assert_array_equal(fused, x)


def test_fused_tv_keeps_the_regularizer_contract(small):
    assert check_regularizer(TV, options={"fused": 3, "iterations": 6}, device=small) == ["float32"]


@pytest.mark.parametrize("projection", ["exact", "paper"])
def test_fused_admm_equals_plain_admm(device, dtype, projection):
    rig = rsocl.Rig.paper_array(4, (7, 9), t_e=1e-4, t_r=3e-5)
    truth = np.random.default_rng(5).random((2, rig.T) + rig.shape)
    g = np.stack([ref.forward(rig, t) for t in truth])
    local_bytes = 8192 * np.dtype(dtype).itemsize // 4  # tiles of one sub-frame: two launches
    kw = dict(
        iterations=4,
        lam=[0.05, 0.1],
        eta=[0.3, 0.0],
        tv_iterations=5,
        projection=projection,
        dtype=dtype,
        device=device.limited(local_mem_bytes=local_bytes, **SMALL_GROUP),
        tune=False,
    )
    import pyopencl.array as cla

    cube = cla.zeros(kw["device"].queue, (2, rig.T) + rig.shape, dtype)
    assert TV(fused=2, iterations=5).fused_plan(cube) is not None  # the fused path is taken
    plain = rsocl.reconstruct(g, rig, regularizer_options={"fused": 0}, **kw).datacube
    fused = rsocl.reconstruct(g, rig, regularizer_options={"fused": 2}, **kw).datacube
    np.testing.assert_allclose(fused, plain, rtol=0, atol=10 * _tol(dtype) * np.abs(plain).max())


def test_a_device_without_fp64(small):
    assert not small.has_fp64 and small.acc_dtype == np.float32
    rig = rsocl.Rig.paper_array(4, (6, 5), t_e=1e-4, t_r=3e-5)
    g = ref.forward(rig, np.random.default_rng(2).random((rig.T,) + rig.shape))
    kw = dict(iterations=3, lam=0.05, eta=0.3, tv_iterations=3, tune=False)
    got = rsocl.reconstruct(g, rig, device=small, **kw).datacube
    np.testing.assert_allclose(got, rsocl.reconstruct(g, rig, **kw).datacube, rtol=0, atol=1e-5)
    with pytest.raises(ValueError, match="float64"):
        rsocl.reconstruct(g, rig, device=small, dtype="float64", **kw)
    with pytest.raises(ValueError, match="float64"):
        small.program(["tv.cl"], REAL="double", TEMPORAL=1)


def test_limits_are_validated(device):
    with pytest.raises(ValueError, match="max_work_group_size"):
        device.limited(max_work_group_size=0)
    with pytest.raises(ValueError, match="local_mem_bytes"):
        device.limited(local_mem_bytes=-1)
    assert device.limited(max_work_group_size=1 << 40).max_work_group_size == device.max_work_group_size


@pytest.mark.parametrize("fp64", [False, "no", "No", "false", np.False_])
def test_fp64_no_hides_fp64_and_float64_is_refused(device, fp64):
    dev = device.limited(fp64=fp64)
    assert not dev.has_fp64 and dev.acc_dtype == np.float32
    rig = rsocl.Rig.paper_array(4, (6, 5), t_e=1e-4, t_r=3e-5)
    g = ref.forward(rig, np.random.default_rng(2).random((rig.T,) + rig.shape))
    with pytest.raises(ValueError, match="dtype='float64' needs cl_khr_fp64"):
        rsocl.reconstruct(g, rig, device=dev, dtype="float64", iterations=2, tune=False)


def test_fp64_yes_keeps_what_the_device_has_and_other_values_are_refused(device):
    for fp64 in (True, "yes", "TRUE"):
        assert device.limited(fp64=fp64).has_fp64 == device.has_fp64
    for fp64 in ("maybe", 0, 1, 2.0):
        with pytest.raises(ValueError, match=r"fp64 must be True or False \(or 'yes' or 'no'\), got "):
            device.limited(fp64=fp64)
