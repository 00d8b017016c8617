"""The DCT regularizer's kernels against scipy.fft's orthonormal DCT-II and a scipy reference prox."""

import numpy as np
import pytest
import scipy.fft as sf

from rsocl_plugins.dct import DCT

SHAPES = [(55, 64, 64), (1, 16, 16), (8, 7, 9)]
MODES = {"3d": (0, 1, 2), "2d": (1, 2)}


def _tol(dtype):
    return 1e-5 if dtype == "float32" else 1e-10


def _dev(device, x, dtype):
    import pyopencl.array as cla

    return cla.to_device(device.queue, np.ascontiguousarray(x, dtype=dtype))


def _blocks(shape, block, axes):
    """Slices of the independent blocks: b along the transformed axes (shorter at the edges),
    whole along the others (2-D mode: all sub-frames at once, transformed along y and x only)."""
    sizes = [(block or N) if ax in axes else N for ax, N in enumerate(shape)]
    starts = [range(0, N, b) for N, b in zip(shape, sizes)]
    for t0 in starts[0]:
        for y0 in starts[1]:
            for x0 in starts[2]:
                yield tuple(slice(s, s + b) for s, b in zip((t0, y0, x0), sizes))


def _reference_denoise(x, weight, block, axes):
    """scipy: per block dctn, soft-threshold all but the DC coefficient(s), idctn."""
    out = np.empty_like(x)
    for sl in _blocks(x.shape, block, axes):
        c = sf.dctn(x[sl], type=2, norm="ortho", axes=axes)
        shrunk = np.sign(c) * np.maximum(np.abs(c) - weight, 0)
        dc = (slice(None), 0, 0) if len(axes) == 2 else (0, 0, 0)  # 2-D: one DC per sub-frame
        shrunk[dc] = c[dc]
        out[sl] = sf.idctn(shrunk, type=2, norm="ortho", axes=axes)
    return out


# n = 29, 45, 24, 20: every code path of the kernels (64-byte chunks, single vectors, scalars at the edges)
@pytest.mark.parametrize("shape", SHAPES + [(5, 30, 29), (3, 4, 45), (3, 5, 24), (2, 3, 20)])
@pytest.mark.parametrize("mode", ["3d", "2d"])
def test_whole_frame_transform_matches_scipy(device, dtype, rng, shape, mode):
    x = rng.standard_normal(shape)
    reg = DCT(mode=mode, block=0)
    got = reg.transform(_dev(device, x, dtype))
    assert got.dtype == np.dtype(dtype) and got.shape == shape
    want = sf.dctn(x.astype(dtype).astype(np.float64), type=2, norm="ortho", axes=MODES[mode])
    np.testing.assert_allclose(got.get(), want, rtol=0, atol=_tol(dtype))


@pytest.mark.parametrize(
    "shape,block",
    [
        ((8, 7, 9), 4),
        ((13, 20, 18), 8),
        ((5, 11, 6), 3),
        ((3, 9, 10), 1),
        ((6, 5, 4), 100),
        ((55, 64, 64), 8),
        ((9, 30, 29), 24),
        ((5, 33, 70), 32),
    ],
)
@pytest.mark.parametrize("mode", ["3d", "2d"])
def test_block_transform_matches_scipy_per_block(device, dtype, rng, shape, block, mode):
    x = rng.standard_normal(shape)
    axes = MODES[mode]
    got = DCT(mode=mode, block=block).transform(_dev(device, x, dtype)).get()
    xd = x.astype(dtype).astype(np.float64)
    want = np.full(shape, np.nan)
    partial = 0
    for sl in _blocks(shape, block, axes):
        want[sl] = sf.dctn(xd[sl], type=2, norm="ortho", axes=axes)
        partial += any(s.stop > N for s, N in zip(sl, shape))
    np.testing.assert_allclose(got, want, rtol=0, atol=_tol(dtype))
    if shape == (13, 20, 18):
        assert partial > 0  # partial edge blocks were exercised


def test_block_transform_is_not_whole_frame(device, rng):
    """Blocks are independent: the block transform differs from the whole-frame one."""
    x = rng.standard_normal((8, 16, 16))
    got = DCT(block=8).transform(_dev(device, x, "float64" if device.has_fp64 else "float32")).get()
    assert np.abs(got - sf.dctn(x, type=2, norm="ortho")).max() > 0.1


@pytest.mark.parametrize("shape", SHAPES + [(13, 20, 18)])
@pytest.mark.parametrize("block", [0, 8, 5])
@pytest.mark.parametrize("mode", ["3d", "2d"])
def test_perfect_reconstruction(device, dtype, rng, shape, block, mode):
    x = rng.standard_normal(shape)
    reg = DCT(mode=mode, block=block)
    back = reg.inverse(reg.transform(_dev(device, x, dtype)))
    assert back.dtype == np.dtype(dtype) and back.shape == shape
    np.testing.assert_allclose(back.get(), x.astype(dtype), rtol=0, atol=_tol(dtype))


@pytest.mark.parametrize("shape", [(8, 7, 9), (1, 16, 16), (13, 20, 18)])
@pytest.mark.parametrize("block", [0, 8, 4])
@pytest.mark.parametrize("mode", ["3d", "2d"])
def test_denoise_matches_scipy_reference(device, dtype, rng, shape, block, mode):
    x = rng.standard_normal(shape)
    weight = 0.4
    got = DCT(mode=mode, block=block).denoise(_dev(device, x, dtype), weight)
    assert got.dtype == np.dtype(dtype) and got.shape == shape
    want = _reference_denoise(x.astype(dtype).astype(np.float64), weight, block, MODES[mode])
    np.testing.assert_allclose(got.get(), want, rtol=0, atol=_tol(dtype))
    assert np.abs(want - x).max() > 0.1  # the threshold did something


def test_denoise_large_frame_matches_scipy_reference(device, rng):
    x = rng.standard_normal((55, 64, 64))
    got = DCT(block=0).denoise(_dev(device, x, "float32"), 0.5).get()
    want = _reference_denoise(x.astype(np.float32).astype(np.float64), 0.5, 0, (0, 1, 2))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)


def test_denoise_keeps_dc_and_kills_small_coefficients(device, rng):
    x = rng.standard_normal((8, 8, 8)) * 0.01 + 3.0
    got = DCT(block=0).denoise(_dev(device, x, "float32"), 1.0).get()
    np.testing.assert_allclose(got, np.full(x.shape, x.astype(np.float32).mean()), atol=1e-5)


def test_denoise_writes_out_and_allows_aliasing(device, rng):
    import pyopencl.array as cla

    x = rng.standard_normal((6, 10, 12))
    want = _reference_denoise(x.astype(np.float32).astype(np.float64), 0.3, 4, (0, 1, 2))
    out = cla.empty(device.queue, x.shape, np.float32)
    res = DCT(block=4).denoise(_dev(device, x, "float32"), 0.3, out=out)
    assert res is out
    np.testing.assert_allclose(out.get(), want, atol=1e-5)
    xd = _dev(device, x, "float32")
    DCT(block=4).denoise(xd, 0.3, out=xd)  # in place
    np.testing.assert_allclose(xd.get(), want, atol=1e-5)


@pytest.mark.parametrize("mode", ["3d", "2d"])
def test_weight_zero_is_identity(device, dtype, rng, mode):
    x = rng.random((5, 9, 7))
    got = DCT(mode=mode, block=4).denoise(_dev(device, x, dtype), 0.0).get()
    np.testing.assert_array_equal(got, x.astype(dtype))


@pytest.mark.parametrize("weight, block", [(0.0, 4), (0.3, 1)])
def test_an_identity_in_place_leaves_x_as_it_is(device, dtype, rng, weight, block):
    # weight 0 (the base class) and blocks of one coefficient (DCT's own): out=x is no overlapping copy
    x = rng.random((5, 9, 7))
    xd = _dev(device, x, dtype)
    assert DCT(block=block).denoise(xd, weight, out=xd) is xd
    np.testing.assert_array_equal(xd.get(), x.astype(dtype))


@pytest.mark.parametrize("block", [0, 4])
@pytest.mark.parametrize("mode", ["3d", "2d"])
def test_non_expansive(device, dtype, rng, block, mode):
    reg = DCT(mode=mode, block=block)
    for _ in range(5):
        a, b = rng.standard_normal((2, 6, 12, 10))
        b = a + rng.uniform(0.01, 1) * b
        da = reg.denoise(_dev(device, a, dtype), 0.5).get().astype(np.float64)
        db = reg.denoise(_dev(device, b, dtype), 0.5).get().astype(np.float64)
        assert np.linalg.norm(da - db) <= np.linalg.norm(a - b) * (1 + 1e-5)


@pytest.mark.parametrize("block", [0, 4])
def test_2d_treats_subframes_independently(device, dtype, rng, block):
    x = rng.standard_normal((6, 12, 10))
    reg = DCT(mode="2d", block=block)
    whole = reg.denoise(_dev(device, x, dtype), 0.3).get()
    for s in range(x.shape[0]):
        alone = reg.denoise(_dev(device, x[s : s + 1], dtype), 0.3).get()[0]
        np.testing.assert_allclose(whole[s], alone, rtol=0, atol=_tol(dtype))
    y = x.copy()
    y[3] += 5 * rng.standard_normal(y[3].shape)  # changing one sub-frame leaves the others alone
    other = reg.denoise(_dev(device, y, dtype), 0.3).get()
    np.testing.assert_array_equal(np.delete(other, 3, axis=0), np.delete(whole, 3, axis=0))
    # ... whereas 3-D mode couples them
    three = DCT(mode="3d", block=block)
    assert (
        np.abs(
            three.denoise(_dev(device, y, dtype), 0.3).get()[0] - three.denoise(_dev(device, x, dtype), 0.3).get()[0]
        ).max()
        > 1e-3
    )


def test_workspace_bytes(device):
    reg = DCT(block=8)
    shape = (13, 20, 18)
    # one work array plus forward and inverse tables of lengths 8, 5 (t), 4 (y), 2 (x)
    assert reg.workspace_bytes(shape, np.float32) == (13 * 20 * 18 + 2 * (64 + 25 + 16 + 4)) * 4
    assert reg.workspace_bytes(shape, np.float64) == 2 * reg.workspace_bytes(shape, np.float32)
    assert DCT(block=0).workspace_bytes((4, 6, 6), np.float32) == (144 + 2 * (16 + 36)) * 4
    assert DCT(block=0, mode="2d").workspace_bytes((4, 6, 6), np.float32) == (144 + 2 * 36) * 4


def test_registered_as_plugin():
    from rsocl.common.registry import load

    assert load("rsocl.regularizers", "dct") is DCT
    assert DCT.name == "dct"


def test_options_are_validated():
    assert DCT().mode == "3d" and DCT(mode="2D").mode == "2d"
    assert DCT(block="16").block == 16
    with pytest.raises(ValueError, match="mode"):
        DCT(mode="4d")
    with pytest.raises(ValueError, match="block"):
        DCT(block=-1)
    with pytest.raises(ValueError, match="block"):
        DCT(block=2.5)
    with pytest.raises(ValueError, match="unknown option"):
        DCT(iterations=3)


def test_input_is_validated(device):
    import pyopencl.array as cla

    with pytest.raises(ValueError, match="pyopencl.array.Array"):
        DCT().denoise(np.zeros((2, 2, 2)), 0.1)
    with pytest.raises(ValueError, match="shape"):
        DCT().denoise(cla.zeros(device.queue, (2, 2), np.float32), 0.1)
    with pytest.raises(ValueError, match="weight"):
        DCT().denoise(cla.zeros(device.queue, (2, 2, 2), np.float32), -1.0)
    with pytest.raises(ValueError):
        DCT().transform(np.zeros((2, 2, 2)))
