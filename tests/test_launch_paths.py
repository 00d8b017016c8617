"""The ADMM's launch paths: the CPU device's (separate dual and difference passes, the plain TV in two
launches per Chambolle iteration) and the ones of other devices (the dual update and u = f - b folded
into the TV's and the projection's launches; the plain TV in one launch per iteration, or the fused
TV), run here by making the device read as a GPU. Against the NumPy reference ADMM; the launch counts
per iteration of each, and that a self-tuned call launches no ``pyopencl.array`` arithmetic."""

from contextlib import contextmanager

import numpy as np
import pytest

import rsocl
import rsocl_plugins.tv as tv_module
from rsocl.device.context import Device
from rsocl.model import reference as ref
from rsocl_plugins.tv import GPU_FUSED, GPU_ONE_LAUNCH, STEP, TV, device_fused, device_one_launch

#: ``fused`` of the fewer-launch path that a GPU run measures against the plain one (benchmarks/launches.py)
LEAN = 16


@pytest.fixture(scope="module")
def problem():
    rig = rsocl.Rig.paper_array(4, (10, 9), t_e=1e-4, t_r=3e-5)
    truth = np.random.default_rng(11).random((rig.T,) + rig.shape)
    return rig, ref.forward(rig, truth)


@contextmanager
def counting(module=None):
    """Count the kernel enqueues made through ``module.enqueue_nd_range_kernel`` (None: ``pyopencl``'s, the one
    rsocl's kernels call) while the block runs; yields a one-item list."""
    import pyopencl as cl

    module = cl if module is None else module
    count, saved = [0], module.enqueue_nd_range_kernel

    def counted(*args, **kwargs):
        count[0] += 1
        return saved(*args, **kwargs)

    module.enqueue_nd_range_kernel = counted
    try:
        yield count
    finally:
        module.enqueue_nd_range_kernel = saved


def _launches_per_iteration(rig, g, device):
    counts = []
    for iterations in (9, 17):
        with counting() as count:
            rsocl.reconstruct(g, rig, iterations=iterations, lam=0.05, eta=0.3, tune=False, device=device)
        counts.append(count[0])
    return (counts[1] - counts[0]) / 8


def test_the_device_default_of_fused(device, monkeypatch):
    assert device_fused(device) == 0  # a CPU: the plain path
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    assert device_fused(device) == GPU_FUSED == 0  # other devices: as measured
    monkeypatch.setattr(tv_module, "GPU_FUSED", LEAN)
    assert device_fused(device) == LEAN


def test_the_device_default_of_one_launch(device, monkeypatch):
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: True))  # as a CPU device, whatever it is
    assert device_one_launch(device) == 0 and not TV().one_launch_on(device)  # a CPU: two launches
    assert TV(one_launch=1).one_launch_on(device)
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    assert device_one_launch(device) == GPU_ONE_LAUNCH == 1 and TV().one_launch_on(device)
    assert not TV(one_launch=0).one_launch_on(device)


@pytest.mark.parametrize("eta", [0.3, 0.0])
@pytest.mark.parametrize("path", ["one launch", "pairs", "lean"])
def test_gpu_path_matches_the_reference(problem, not_cpu, monkeypatch, dtype, eta, path):
    # the default of other devices (the plain TV in one launch per iteration), the plain TV in one
    # launch per two iterations, and the fused TV
    if path == "lean":
        monkeypatch.setattr(tv_module, "GPU_FUSED", LEAN)
    elif path == "pairs":
        monkeypatch.setattr(tv_module, "GPU_ONE_LAUNCH", 2)
    rig, g = problem
    kw = dict(iterations=6, lam=0.05, eta=eta, tv_iterations=4)
    got = rsocl.reconstruct(g, rig, dtype=dtype, device=not_cpu, regularizer_options={"temporal_weight": 2.5}, **kw)
    want = ref.admm(rig, g, temporal_weight=2.5, step=STEP, **kw)
    tol = 2e-4 if dtype == "float32" else 1e-10
    np.testing.assert_allclose(got.datacube, want, atol=tol * np.abs(want).max())


@pytest.mark.not_under_oclgrind("whole runs; test_project_lanes.py runs the GPU path's batch kernels")
def test_gpu_path_of_a_batch_equals_its_sets_on_the_cpu_path(problem, device, monkeypatch):
    rig, g = problem
    batch = np.stack([g, 0.5 * g, 2 * g])
    kw = dict(iterations=5, lam=(0.05, 0.1, 0.02), eta=(0.3, 0.0, 0.2), tune=False, dtype="float64")
    cpu = rsocl.reconstruct(batch, rig, device=device, **kw)
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    gpu = rsocl.reconstruct(batch, rig, device=device, **kw)
    np.testing.assert_allclose(gpu.datacube, cpu.datacube, atol=1e-10 * np.abs(cpu.datacube).max())
    np.testing.assert_allclose(gpu.history["residual"], cpu.history["residual"], rtol=1e-9)


@pytest.mark.not_under_oclgrind("counts the launches of every path; their kernels run in the kept tests")
def test_launches_per_iteration_of_each_path(problem, device, monkeypatch):
    rig, g = problem
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: True))  # as a CPU device, whatever it is
    # CPU: admm_dual, admm_project (with the residual of the previous iteration's estimate),
    # admm_difference, the plain TV of 10 iterations (1 + 9 + 8)
    assert _launches_per_iteration(rig, g, device) == 21
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    # other devices, plain TV (GPU_FUSED) in one launch per Chambolle iteration (GPU_ONE_LAUNCH): the
    # projection with u = f - b and the residual, which first makes the TV's last primal step and the
    # dual update of the iteration before, and the TV without that last launch: its first two iterations
    # in one launch (tv_first2), then one tv_step per iteration (1 + 1 + 7)
    assert GPU_FUSED == 0 and GPU_ONE_LAUNCH == 1 and _launches_per_iteration(rig, g, device) == 9
    # the same TV in one launch per two iterations (1 + tv_first2 + 3 tv_step2 + 1 tv_step)
    monkeypatch.setattr(tv_module, "GPU_ONE_LAUNCH", 2)
    assert _launches_per_iteration(rig, g, device) == 6
    # the same TV in two launches per iteration (1 + 1 + 8 + 8)
    monkeypatch.setattr(tv_module, "GPU_ONE_LAUNCH", 0)
    assert _launches_per_iteration(rig, g, device) == 18
    # the fused TV: the projection, the fused TV
    monkeypatch.setattr(tv_module, "GPU_FUSED", LEAN)
    plan = TV().fused_plan(_cube(device, rig))
    assert plan is not None
    assert _launches_per_iteration(rig, g, device) == 1 + len(plan.launches) <= 11


def _cube(device, rig):
    import pyopencl.array as cla

    return cla.zeros(device.queue, (rig.sampled_range().stop - rig.sampled_range().start,) + rig.shape, np.float32)


def test_memory_counts_the_dual_buffers_of_the_devices_choice(device, monkeypatch):
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: True))  # as a CPU device, whatever it is
    shape, plain = (12, 16, 16), TV().workspace_bytes((12, 16, 16), np.float32)
    assert TV().workspace_bytes(shape, np.float32, device=device) == plain  # the CPU's plain path
    assert TV(fused=3).workspace_bytes(shape, np.float32, device=device) > plain
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    one_launch = TV(one_launch=1).workspace_bytes(shape, np.float32)
    assert one_launch > plain  # two copies of the dual
    # GPU_FUSED: the plain path; GPU_ONE_LAUNCH: in one launch per iteration
    assert TV().workspace_bytes(shape, np.float32, device=device) == one_launch
    assert TV(one_launch=0).workspace_bytes(shape, np.float32, device=device) == plain
    monkeypatch.setattr(tv_module, "GPU_FUSED", LEAN)
    assert TV().workspace_bytes(shape, np.float32, device=device) == TV(fused=3).workspace_bytes(shape, np.float32)
    assert TV(fused=0).workspace_bytes(shape, np.float32, device=device) == one_launch
    assert TV(fused=0, one_launch=0).workspace_bytes(shape, np.float32, device=device) == plain


@pytest.mark.not_under_oclgrind("a self-tuned call that counts launches; the kernels it launches run in the kept tests")
@pytest.mark.parametrize("cpu", [True, False])
def test_a_self_tuned_call_launches_only_rsocl_kernels(problem, device, monkeypatch, cpu):
    """Every launch of a self-tuned call (search, run, static fix, blend) goes through rsocl's kernels, none
    through ``pyopencl.array`` arithmetic or its generated invokers (they call ``pyopencl._cl`` directly)."""
    import pyopencl._cl as _cl

    monkeypatch.setattr(Device, "is_cpu", property(lambda self: cpu))
    rig = problem[0]
    image = np.random.default_rng(12).random(rig.shape)
    g = ref.forward(rig, np.repeat(image[None], rig.T, axis=0))  # a still scene: the static fix runs
    with counting() as ours, counting(_cl) as other:
        result = rsocl.reconstruct(g, rig, iterations=12, device=device)
    assert ours[0] > 12 and other[0] == 0
    assert result.params["tuning"] is not None and result.params["static_pixels"] > 0


@pytest.mark.parametrize("projection", ["exact", "paper"])
@pytest.mark.parametrize("eta", [0.3, 0.0])
@pytest.mark.parametrize("gpu", [False, True])
def test_saturated_samples_enter_one_sided_as_in_the_reference(
    problem, device, monkeypatch, dtype, projection, eta, gpu
):
    # from a start above the truth, the clamp r = max(g - H v, 0) acts at the clipped samples; the CPU path
    # and the GPU path (the projection's block and pixel loops, the deferred primal step) both follow it
    if gpu:
        monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    if projection == "paper":
        eta = eta + 5.0  # the diagonal step is stable only for eta large against psi
    rig, g = problem
    level = float(np.percentile(g, 70))
    clipped = np.minimum(g, level)
    x0 = 1.5 * np.random.default_rng(11).random((rig.T,) + rig.shape)
    # float32 GAP: after a few iterations rounding puts a sample at its bound on the other side of it than
    # float64 does, and the runs part by 1e-3; two iterations compare the step itself
    iterations = 2 if dtype == "float32" and eta == 0 else 6
    kw = dict(iterations=iterations, lam=0.05, eta=eta, tv_iterations=4, projection=projection, x0=x0)
    got = rsocl.reconstruct(
        clipped, rig, dtype=dtype, device=device, saturation=level, regularizer_options={"temporal_weight": 2.5}, **kw
    )
    want = ref.admm(rig, clipped, temporal_weight=2.5, step=STEP, saturated=clipped >= level, **kw)
    two_sided = ref.admm(rig, clipped, temporal_weight=2.5, step=STEP, **kw)
    assert np.abs(two_sided - want).max() > 0.05 * np.abs(want).max()  # the clamp acted
    tol = 2e-4 if dtype == "float32" else 1e-10
    np.testing.assert_allclose(got.datacube, want, atol=tol * np.abs(want).max())


@pytest.mark.not_under_oclgrind("whole runs; test_gap_saturation.py runs this batch step")
@pytest.mark.filterwarnings("ignore:saturation = .* marks:UserWarning")  # the 1.3 g set: over half clipped
def test_a_batch_with_saturation_equals_its_sets(problem, device):
    rig, g = problem
    level = float(np.percentile(g, 80))
    batch = np.minimum(np.stack([g, 0.7 * g, 1.3 * g]), level)  # a different share clipped in each set
    x0 = np.ones((rig.T,) + rig.shape)
    kw = dict(iterations=5, lam=0.05, eta=0.3, tune=False, dtype="float64", device=device, saturation=level, x0=x0)
    together = rsocl.reconstruct(batch, rig, **kw)
    for i, one in enumerate(batch):
        alone = rsocl.reconstruct(one, rig, **kw)
        np.testing.assert_allclose(together.datacube[i], alone.datacube, atol=1e-10 * np.abs(alone.datacube).max())
