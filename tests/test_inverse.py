"""The exact projection's inverse blocks on the device (kernels/inverse.cl) against NumPy's eigh."""

import numpy as np
import pyopencl.array as cla
import pytest

import rsocl
from rsocl.device import get_device
from rsocl.model.operator import RollingShutterOperator
from rsocl.solver import inverse
from rsocl.solver.inverse import RCOND, block_inverse, device_block_inverse, inverse_blocks, inverts_on_device

pytestmark = pytest.mark.skipif(not get_device().has_fp64, reason="the device inverse needs cl_khr_fp64")


def _grams(K, pixels, seed):
    """``(pixels, K, K)`` symmetric positive semi-definite blocks of every rank 0..K, scales 1e-3..1e3,
    with repeated eigenvalues (equal rows of the factor) and all-zero blocks among them."""
    rng = np.random.default_rng(seed)
    blocks = []
    for i in range(pixels):
        rank = i % (K + 1)
        a = rng.standard_normal((K, max(rank, 1))) * (rank > 0)
        if i % 5 == 1 and K > 1:
            a[1] = a[0]  # two cameras with the same windows
        blocks.append(a @ a.T * 10.0 ** rng.uniform(-3, 3))
    if K > 1:
        blocks[3] = np.eye(K) * 2.5  # one eigenvalue K times
    return np.stack(blocks)


def _on_device(queue, grams, dtype, shape):
    """``grams`` ``(pixels, K, K)`` as the device's ``(K, K, m, n)`` layout, stored in ``dtype``."""
    K = grams.shape[-1]
    stored = np.ascontiguousarray(np.moveaxis(grams, 0, -1).reshape((K, K) + shape), dtype=dtype)
    return stored, cla.to_device(queue, stored)


def _host(stored, eta, rcond, keep=None):
    """The oracle: block_inverse of the stored blocks, masked as the ADMM does, as ``(K, K, m, n)``."""
    gram = np.moveaxis(stored.astype(np.float64), (0, 1), (-2, -1))
    if keep is None:
        return np.moveaxis(block_inverse(gram, eta, rcond), (-2, -1), (0, 1))
    k = np.moveaxis(keep.astype(np.float64), 0, -1)
    mask = k[..., :, None] * k[..., None, :]
    return np.moveaxis(block_inverse(gram * mask, eta, rcond) * mask, (-2, -1), (0, 1))


def _assert_close(got, want, dtype):
    """Per block: within float32 rounding of its largest entry, or 1e-9 of it in float64."""
    tol = 4 * np.finfo(np.float32).eps if dtype == np.float32 else 1e-9
    scale = np.abs(want).max(axis=(0, 1), keepdims=True)
    assert np.all(np.abs(got - want) <= tol * scale + 1e-300), np.abs(got - want).max()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("K", [1, 2, 4, 7, 16])
def test_matches_numpy_eigh_on_blocks_of_every_rank(K, dtype):
    dev = get_device()
    queue = dev.queue
    shape = (6, 7)
    stored, gram = _on_device(queue, _grams(K, 42, K), dtype, shape)
    etas = [0.0, 1e-12, 0.2, 50.0]
    rcond = RCOND[np.dtype(dtype).name]
    out = device_block_inverse(dev, queue, gram, etas, rcond).get()
    assert out.shape == (4, K, K) + shape and out.dtype == dtype
    for i, eta in enumerate(etas):
        _assert_close(out[i], _host(stored, eta, rcond), dtype)
    zero = np.all(stored == 0, axis=(0, 1))  # unsampled pixels: GAP leaves them at zero
    assert zero.any() and np.all(out[0][:, :, zero] == 0)


@pytest.mark.parametrize("per_set", [False, True])
def test_left_out_pixels_per_set_and_shared(per_set):
    dev = get_device()
    queue = dev.queue
    K, shape, dtype = 4, (5, 9), np.float32
    stored, gram = _on_device(queue, _grams(K, 45, 7), dtype, shape)
    rng = np.random.default_rng(1)
    keep = rng.random(((3,) if per_set else ()) + (K,) + shape) > 0.3
    valid = cla.to_device(queue, keep.astype(dtype))
    etas = [0.1, 0.0, 2.0]
    out = device_block_inverse(dev, queue, gram, etas, RCOND["float32"], valid).get()
    for i, eta in enumerate(etas):
        want = _host(stored, eta, RCOND["float32"], keep[i] if per_set else keep)
        _assert_close(out[i], want, dtype)
        left = ~(keep[i] if per_set else keep)  # (K, m, n): the row and column of a left-out pixel are zero
        assert np.all(np.moveaxis(out[i], 1, -1)[left] == 0) and np.all(np.moveaxis(out[i], 0, -1)[left] == 0)


@pytest.mark.parametrize("projection", ["exact", "paper"])
def test_inverse_blocks_on_device_and_host_agree_for_a_batch(projection):
    rig = rsocl.Rig.paper_array(4, (11, 13), 1e-4, 3e-5)
    op = RollingShutterOperator(rig, dtype=np.float32)
    keep = np.random.default_rng(0).random((3, 4) + rig.shape) > 0.2
    for valid, etas in [
        (None, np.full(3, 0.3)),
        (keep, np.array([0.1, 0.2, 0.3])),
        (keep[:1].repeat(3, 0), np.zeros(3)),
    ]:
        own_h, host = inverse_blocks(op, projection, etas, valid, 3, on_device=False)
        own_d, dev = inverse_blocks(op, projection, etas, valid, 3, on_device=True)
        assert own_h == own_d and host.shape == dev.shape
        host, dev = host.get(), dev.get()
        assert np.all((host == np.inf) == (dev == np.inf))
        finite = np.isfinite(host)
        assert np.allclose(dev[finite], host[finite], rtol=0, atol=4e-7 * np.abs(host[finite]).max())


@pytest.mark.not_under_oclgrind("a whole reconstruction; the other tests here run the device blocks at every rank")
def test_the_reconstruction_with_device_blocks_equals_the_host_ones(monkeypatch):
    rig = rsocl.Rig.paper_array(4, (9, 10), 1e-4, 3e-5)
    g = np.random.default_rng(2).random((2, 4) + rig.shape)
    kw = dict(iterations=5, lam=0.05, eta=[0.2, 0.4], tune=False, saturation=float(np.quantile(g, 0.9)))
    on_device = rsocl.reconstruct(g, rig, **kw).datacube
    monkeypatch.setattr(inverse, "inverts_on_device", lambda device, K: False)
    on_host = rsocl.reconstruct(g, rig, **kw).datacube
    np.testing.assert_allclose(on_device, on_host, rtol=0, atol=2e-6 * np.abs(on_host).max())


def test_without_fp64_or_beyond_sixteen_snapshots_the_host_inverts():
    dev = get_device()
    assert inverts_on_device(dev, 4) and inverts_on_device(dev, inverse.DEVICE_CHANNELS)
    assert not inverts_on_device(dev, inverse.DEVICE_CHANNELS + 1)
    assert not inverts_on_device(dev.limited(fp64=False), 4)
    gram = cla.zeros(dev.queue, (17, 17, 2, 2), np.float32)
    with pytest.raises(ValueError, match="K in \\[1, 16\\]"):
        device_block_inverse(dev, dev.queue, gram, [0.1], 1e-6)
    cameras = [rsocl.Camera(angle, t_e=1e-4, t_r=3e-5) for angle in [0, 90, 180, 270] * 4 + [0]]
    rig = rsocl.Rig(cameras, (4, 5))
    op = RollingShutterOperator(rig, dtype=np.float32)
    own, blocks = inverse_blocks(op, "exact", np.array([0.3]), None, 1)  # the host's, as before
    want = np.moveaxis(block_inverse(op.gram(), 0.3, RCOND["float32"]), (2, 3), (0, 1))
    np.testing.assert_allclose(blocks.get(), want, rtol=0, atol=1e-7 * np.abs(want).max())


def test_bad_shapes_are_refused():
    dev = get_device()
    gram = cla.zeros(dev.queue, (3, 3, 2, 2), np.float32)
    with pytest.raises(ValueError, match="valid must be"):
        device_block_inverse(dev, dev.queue, gram, [0.1, 0.2], 1e-6, cla.zeros(dev.queue, (3, 3, 2, 2), np.float32))
    with pytest.raises(ValueError, match="gram must be"):
        device_block_inverse(dev, dev.queue, cla.zeros(dev.queue, (3, 2, 2, 2), np.float32), [0.1], 1e-6)


@pytest.mark.parametrize("dtype, offset", [("float32", 1e-3), ("float64", 1e-5)])
def test_a_gap_step_drops_the_directions_below_its_precisions_cutoff_as_the_reference_told_so(dtype, offset):
    """Two cameras whose windows differ by ``offset`` row times: their blocks' smallest eigenvalues lie at about
    0.1 offset² of the largest, below the precision's cutoff (``RCOND``) and above NumPy's own (1e-15)."""
    from rsocl.model import reference as ref

    assert ref.RCOND == RCOND["float64"]  # the reference's default is float64's cutoff
    t_r = 3.5e-5
    cameras = [rsocl.Camera(0, t_e=1.8e-4, t_r=t_r), rsocl.Camera(0, t_e=1.8e-4, t_r=t_r, t_a=offset * t_r)]
    rig = rsocl.Rig(cameras + [rsocl.Camera(90, t_e=1.8e-4, t_r=t_r)], (6, 6))
    ratios = np.linalg.eigvalsh(ref.gram(rig))
    ratios = ratios[..., 0] / ratios[..., -1]
    assert np.any((ratios > 1e-14) & (ratios < RCOND[dtype]))  # directions the cutoff drops
    g = ref.forward(rig, np.random.default_rng(0).random((rig.T,) + rig.shape))
    got = rsocl.reconstruct(g, rig, dtype=dtype, tune=False, iterations=1, lam=0.0, eta=0.0).datacube
    zero = np.zeros((rig.T,) + rig.shape)
    want = ref.project(rig, zero, g, 0.0, rcond=RCOND[dtype])
    scale = np.abs(want).max()
    assert np.abs(got - want).max() <= (1e-4 if dtype == "float32" else 1e-9) * scale
    assert np.abs(got - ref.project(rig, zero, g, 0.0, rcond=1e-15)).max() > 1e-2 * scale  # the cutoff matters
