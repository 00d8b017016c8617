"""The TV kernels against scikit-image's Chambolle TV and the NumPy reference."""

import numpy as np
import pytest
from skimage.restoration import denoise_tv_chambolle

from rsocl.model import reference as ref
from rsocl_plugins.tv import STEP, TV


def _denoise(device, x, weight, dtype, **options):
    import pyopencl.array as cla

    out = TV(**options).denoise(cla.to_device(device.queue, x.astype(dtype)), weight)
    assert isinstance(out, cla.Array) and out.dtype == np.dtype(dtype) and out.shape == x.shape
    return out.get()


@pytest.mark.parametrize("shape", [(7, 13, 17), (1, 9, 6), (5, 1, 8), (4, 6, 1), (3, 5, 67), (2, 3, 130)])
@pytest.mark.parametrize("iterations", [1, 2, 15])
@pytest.mark.parametrize("one_launch", [0, 1, 2])
def test_3d_matches_skimage(device, dtype, rng, shape, iterations, one_launch):
    x = rng.random(shape)
    options = dict(iterations=iterations, temporal_weight=1.0, step=1.0, one_launch=one_launch)
    got = _denoise(device, x, 0.25, dtype, **options)
    want = denoise_tv_chambolle(x.astype(dtype), weight=0.25, eps=0, max_num_iter=iterations)
    np.testing.assert_allclose(got, want, atol=1e-4 if dtype == "float32" else 1e-10)


@pytest.mark.parametrize("iterations", [1, 3, 20])
@pytest.mark.parametrize("one_launch", [0, 1, 2])
def test_2d_per_subframe_matches_skimage(device, dtype, rng, iterations, one_launch):
    x = rng.random((5, 12, 10))
    options = dict(iterations=iterations, temporal_weight=0.0, step=1.0, one_launch=one_launch)
    got = _denoise(device, x, 0.4, dtype, **options)
    want = np.stack([denoise_tv_chambolle(f.astype(dtype), weight=0.4, eps=0, max_num_iter=iterations) for f in x])
    np.testing.assert_allclose(got, want, atol=1e-4 if dtype == "float32" else 1e-10)


@pytest.mark.parametrize("temporal_weight, step", [(0.3, STEP), (2.0, STEP), (2.0, 0.4), (1.0, 1.0)])
@pytest.mark.parametrize("one_launch", [0, 1, 2])
def test_temporal_weight_and_step_match_reference(device, dtype, rng, temporal_weight, step, one_launch):
    x = rng.random((6, 8, 9))
    options = {"one_launch": one_launch} if step == STEP else {"step": step, "one_launch": one_launch}
    got = _denoise(device, x, 0.2, dtype, iterations=12, temporal_weight=temporal_weight, **options)
    want = ref.tv_chambolle(x, 0.2, 12, temporal_weight, step)
    np.testing.assert_allclose(got, want, atol=1e-4 if dtype == "float32" else 1e-10)


@pytest.mark.parametrize("temporal_weight", [0.0, 30.0])
def test_default_step_damps_the_most_oscillating_mode(device, rng, temporal_weight):
    """At a weight large against the image's differences, scikit-image's step (at the edge of
    stability) leaves the mode alternating between neighbours undamped; the default step removes it."""
    shape = (8, 6, 6)
    if temporal_weight:
        x = np.where(np.arange(shape[0]) % 2 == 0, 1.0, -1.0)[:, None, None] * np.ones(shape)
    else:
        x = np.where(np.indices(shape[1:]).sum(axis=0) % 2 == 0, 1.0, -1.0) * np.ones(shape)
    x += 0.01 * rng.random(shape)
    options = dict(iterations=10, temporal_weight=temporal_weight)
    edge = _denoise(device, x, 100.0, "float64", step=1.0, **options)
    default = _denoise(device, x, 100.0, "float64", **options)
    assert np.abs(default).max() < 0.2 and np.abs(edge).max() > 0.35  # the input's amplitude: 1


def test_more_weight_smooths_more(device, rng):
    x = rng.random((6, 16, 16))
    tv = [np.abs(np.diff(_denoise(device, x, w, "float32", iterations=30), axis=2)).sum() for w in (0.05, 0.5)]
    assert tv[1] < 0.5 * tv[0]


def test_weight_zero_is_identity(device, rng):
    x = rng.random((3, 5, 4))
    np.testing.assert_array_equal(_denoise(device, x, 0.0, "float32"), x.astype(np.float32))


def test_options_are_validated():
    with pytest.raises(ValueError, match=r"option step must be in \[0.01, 1.0\], got 1.5"):
        TV(step=1.5)
    with pytest.raises(ValueError, match="iterations"):
        TV(iterations=0)
    with pytest.raises(ValueError, match="temporal_weight"):
        TV(temporal_weight=-1)
    with pytest.raises(ValueError, match="unknown option"):
        TV(lambda_=1)


def test_input_is_validated(device):
    import pyopencl.array as cla

    with pytest.raises(ValueError, match="pyopencl.array.Array"):
        TV().denoise(np.zeros((2, 2, 2)), 0.1)
    with pytest.raises(ValueError, match="shape"):
        TV().denoise(cla.zeros(device.queue, (2, 2), np.float32), 0.1)
    with pytest.raises(ValueError, match="weight"):
        TV().denoise(cla.zeros(device.queue, (2, 2, 2), np.float32), -1.0)
    x = cla.zeros(device.queue, (2, 2, 2), np.float32)
    with pytest.raises(ValueError, match="out must be another buffer than x"):
        TV().denoise(x, 0.1, out=x)


def test_workspace_bytes_counts_the_dual_and_the_edge_weights():
    # p: 3 planes in 3-D, 2 in 2-D; xnext: one value per column; two copies of p in one launch per iteration
    assert TV().workspace_bytes((5, 7, 9), np.float32) == (3 * 5 * 7 * 9 + 9) * 4
    assert TV(temporal_weight=0).workspace_bytes((5, 7, 9), np.float64) == (2 * 5 * 7 * 9 + 9) * 8
    assert TV(one_launch=1).workspace_bytes((5, 7, 9), np.float32) == (2 * 3 * 5 * 7 * 9 + 9) * 4


@pytest.mark.parametrize("iterations", [2, 3, 4, 11])
def test_one_launch_per_iteration_equals_two_on_a_batch(device, dtype, rng, iterations):
    # tv_step from one copy of p into the other (either parity of the last copy), per-set weights
    # (one of them 0), against the two-launch path: the same arithmetic, so equal to rounding
    import pyopencl.array as cla

    x = cla.to_device(device.queue, rng.random((3, 6, 7, 9)).astype(dtype))
    weights = np.array([0.3, 0.0, 1.5])
    two = TV(iterations=iterations, temporal_weight=2.5, one_launch=0).denoise(x, weights).get()
    one = TV(iterations=iterations, temporal_weight=2.5, one_launch=1).denoise(x, weights).get()
    np.testing.assert_allclose(one, two, atol=1e-6 if dtype == "float32" else 1e-13)
    np.testing.assert_array_equal(one[1], x.get()[1])


def test_a_plain_sequence_names_its_launch_mode_and_dual_copies(device):
    import pyopencl.array as cla

    from rsocl_plugins import tv_plain

    tv = TV(iterations=4, one_launch=2)
    x = cla.zeros(device.queue, (3, 4, 5), np.float32)
    prog, grids, arrays, plan = tv._plain_parts(x, tv._steps(device.queue, [0.2], x.dtype), cla.empty_like(x), None)
    assert plan["one_launch"] == 2 and len(arrays.p) == 2
    with pytest.raises(ValueError, match="one_launch must be 0, 1 or 2, got 3"):
        tv_plain.sequence(prog, grids, arrays, 4, 3)
    with pytest.raises(ValueError, match="one_launch=0 takes 1 dual copies, got 2"):
        tv_plain.sequence(prog, grids, arrays, 4, 0)


# shapes with one voxel along an axis, rows of one pixel and of more than a work group; even and odd
# counts of steps (an odd count ends with one tv_step after the pairs)
@pytest.mark.parametrize("shape", [(3, 6, 7, 9), (2, 1, 9, 6), (2, 5, 1, 8), (2, 4, 6, 1), (1, 3, 5, 67)])
@pytest.mark.parametrize("temporal_weight", [2.5, 0.0])
@pytest.mark.parametrize("iterations", [2, 3, 4, 5, 11])
def test_two_iterations_per_launch_equal_one_per_launch(device, dtype, rng, shape, temporal_weight, iterations):
    # tv_step2 steps the dual of the voxels around its own itself: the same arithmetic as two
    # tv_step launches, so the same values, on a batch with per-set weights (one of them 0)
    import pyopencl.array as cla

    x = cla.to_device(device.queue, rng.random(shape).astype(dtype))
    weights = np.array([0.3, 0.0, 1.5])[: shape[0]]
    one = TV(iterations=iterations, temporal_weight=temporal_weight, one_launch=1).denoise(x, weights).get()
    pairs = TV(iterations=iterations, temporal_weight=temporal_weight, one_launch=2).denoise(x, weights).get()
    np.testing.assert_array_equal(pairs, one)


@pytest.mark.parametrize("shape", [(3, 6, 7, 9), (2, 1, 9, 6), (2, 5, 1, 8), (2, 4, 6, 1), (1, 3, 5, 67)])
@pytest.mark.parametrize("temporal_weight", [2.5, 0.0])
@pytest.mark.parametrize("one_launch", [1, 2])
@pytest.mark.parametrize("iterations", [3, 4, 7])
def test_the_first_two_iterations_in_one_launch_equal_two_launches(
    device, dtype, rng, monkeypatch, shape, temporal_weight, one_launch, iterations
):
    # tv_first2 steps the dual of the voxels around its own from p = 0 itself: what tv_dual_first and
    # then tv_step compute, so the same values, on a batch with per-set weights (one of them 0)
    import pyopencl.array as cla

    from rsocl.device.context import Device
    from rsocl_plugins import tv as tv_module

    x = cla.to_device(device.queue, rng.random(shape).astype(dtype))
    weights = np.array([0.3, 0.0, 1.5])[: shape[0]]
    tv = TV(iterations=iterations, temporal_weight=temporal_weight, one_launch=one_launch)
    monkeypatch.setattr(tv_module, "GPU_FIRST_TWO", False)  # on any device
    assert _first_launch(tv, x, weights) == ("tv_dual_first", {1: iterations, 2: 2 + (iterations - 1) // 2}[one_launch])
    separate = tv.denoise(x, weights).get()
    monkeypatch.setattr(tv_module, "GPU_FIRST_TWO", True)
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    assert _first_launch(tv, x, weights) == ("tv_first2", {1: iterations - 1, 2: 2 + (iterations - 2) // 2}[one_launch])
    np.testing.assert_array_equal(tv.denoise(x, weights).get(), separate)
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: True))  # a CPU keeps the two launches
    assert _first_launch(tv, x, weights)[0] == "tv_dual_first"


def test_the_first_two_iterations_take_one_launch_on_batches_up_to_a_size(device, monkeypatch):
    # GPU_FIRST_TWO_VOXELS: tv_first2 where a GPU's loop is bound by its launches, two launches on larger batches
    import pyopencl.array as cla

    from rsocl.device.context import Device
    from rsocl_plugins import tv as tv_module

    assert tv_module.GPU_FIRST_TWO_VOXELS >= 2 * 55 * 50 * 50  # two paper sets (T = 55, 50×50) take it
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    x = cla.zeros(device.queue, (2, 3, 5, 7), np.float32)
    tv = TV(iterations=4)
    monkeypatch.setattr(tv_module, "GPU_FIRST_TWO_VOXELS", x.size)
    assert _first_launch(tv, x, [0.2, 0.3])[0] == "tv_first2"
    monkeypatch.setattr(tv_module, "GPU_FIRST_TWO_VOXELS", x.size - 1)
    assert _first_launch(tv, x, [0.2, 0.3]) == ("tv_dual_first", 4)


def _first_launch(tv, x, weights):
    """The name of the first kernel of ``tv``'s plain sequence on ``x`` and the count of its launches."""
    import pyopencl.array as cla

    from rsocl_plugins import tv_plain

    prog, grids, arrays, plan = tv._plain_parts(x, tv._steps(x.queue, weights, x.dtype), cla.empty_like(x), None)
    names = [k.function_name for k, *_ in tv_plain.sequence(prog, grids, arrays, tv.iterations, **plan)]
    return names[0], len(names) // len(grids)


@pytest.mark.parametrize("one_launch", [0, 1, 2])
def test_a_bound_call_denoises_what_the_arrays_hold_when_it_runs(device, rng, one_launch):
    import pyopencl.array as cla

    tv = TV(iterations=6, one_launch=one_launch)
    a, b = rng.random((2, 4, 8, 8)).astype(np.float32)
    x = cla.to_device(device.queue, a)
    out = cla.empty_like(x)
    run = tv.bind(x, 0.2, out)
    run()
    want = TV(iterations=6).denoise(cla.to_device(device.queue, a), 0.2).get()
    np.testing.assert_allclose(out.get(), want, atol=1e-6)
    x.set(b)  # new contents, the same array: the bound launches read them
    run()
    want = TV(iterations=6).denoise(cla.to_device(device.queue, b), 0.2).get()
    np.testing.assert_allclose(out.get(), want, atol=1e-6)
    with pytest.raises(ValueError, match="out must match x"):
        tv.bind(x, 0.2, cla.empty(device.queue, (4, 8, 7), np.float32))
    with pytest.raises(ValueError, match="weight must be finite and >= 0"):
        tv.bind(x, -1.0, out)
    with pytest.raises(ValueError, match="out must be another buffer than x"):
        tv.bind(x, 0.2, x)


@pytest.mark.parametrize("fused, one_launch", [(0, 0), (0, 1), (0, 2), (3, 0)])
@pytest.mark.parametrize("iterations", [1, 2, 7])
@pytest.mark.parametrize("bound", [False, True])
def test_denoise_and_update_is_denoise_then_the_admm_dual_update(
    device, dtype, rng, fused, one_launch, iterations, bound
):
    # the plain path's last primal step (tv_primal_update) and the fused path's last launch make
    # b = theta - u, f = theta + b in the sets with a dual, f = theta in the others
    import pyopencl.array as cla

    q = device.queue
    u = rng.random((3, 5, 9, 11))
    weights = np.array([0.2, 0.0, 0.5])
    on = np.array([1, 1, 0], np.int32)
    tv = TV(iterations=iterations, temporal_weight=2.0, fused=fused, one_launch=one_launch)
    want = tv.denoise(cla.to_device(q, u.astype(dtype)), weights).get()
    dev = {k: cla.to_device(q, v.astype(dtype)) for k, v in (("u", u), ("theta", 0 * u), ("b", u + 3), ("f", u + 5))}
    arrays = (dev["u"], weights, dev["theta"], dev["b"], dev["f"], cla.to_device(q, on))
    if bound:  # the ADMM's way: bound once (rsocl.solver.regularizer.Regularizer.bind), then called
        tv.bind(*arrays[:3], arrays[3:])()
    else:
        tv.denoise_and_update(*arrays)
    u_stored = u.astype(dtype)
    tol = 1e-6 if dtype == "float32" else 1e-13
    np.testing.assert_allclose(dev["theta"].get(), want, atol=tol)
    b_want = np.where(on[:, None, None, None] == 1, want - u_stored, (u + 3).astype(dtype))
    f_want = np.where(on[:, None, None, None] == 1, want + b_want, want)
    np.testing.assert_allclose(dev["b"].get(), b_want, atol=tol)
    np.testing.assert_allclose(dev["f"].get(), f_want, atol=tol)
