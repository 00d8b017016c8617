"""The wavelet kernels against PyWavelets (periodized orthonormal DWT, soft thresholding)."""

import warnings

import numpy as np
import pytest

pywt = pytest.importorskip("pywt")

from rsocl_plugins.wavelet import WAVELETS, Wavelet, axis_levels, filters  # noqa: E402

NAMES = sorted(WAVELETS)


def _tol(dtype, fp32, fp64):
    return fp32 if dtype == "float32" else fp64


def _dev(device, x, dtype):
    import pyopencl.array as cla

    return cla.to_device(device.queue, np.ascontiguousarray(x, dtype=dtype))


def _pywt_coeffs(x, name, levels, axes):
    with warnings.catch_warnings():  # pywt warns when a level exceeds its own (stricter) maximum
        warnings.simplefilter("ignore", UserWarning)
        return pywt.wavedecn(x, name, mode="periodization", level=levels, axes=axes)


def _blocks(x, plan, fn):
    """Apply ``fn(block_of_x, axes)`` to each block of frames of the plan; identity where nothing is transformed."""
    parts = [
        fn(x[t0 : t0 + frames], axes) if plan.levels and axes else x[t0 : t0 + frames].copy()
        for t0, frames, axes in plan.blocks
    ]
    assert sum(p.shape[0] for p in parts) == x.shape[0]
    return np.concatenate(parts)


def _pywt_mallat(x, name, plan):
    """pywt's coefficients of each block placed in the in-place (Mallat) layout."""

    def one(b, axes):
        arr, _ = pywt.coeffs_to_array(_pywt_coeffs(b, name, plan.levels, axes), axes=axes)
        assert arr.shape == b.shape
        return arr

    return _blocks(x, plan, one)


def _pywt_denoise(x, name, plan, weight):
    def one(b, axes):
        coeffs = _pywt_coeffs(b, name, plan.levels, axes)
        coeffs = [coeffs[0]] + [{k: pywt.threshold(v, weight, mode="soft") for k, v in d.items()} for d in coeffs[1:]]
        return pywt.waverecn(coeffs, name, mode="periodization", axes=axes)

    return _blocks(x, plan, one)


@pytest.mark.parametrize("name", NAMES)
def test_filters_are_pywt_filters(name):
    ours, theirs = filters(name), pywt.Wavelet(name)
    for key in ("dec_lo", "dec_hi", "rec_lo", "rec_hi"):
        # bit-identical to PyWavelets >= 1.8; older releases carry constants ~3e-13 apart
        np.testing.assert_allclose(ours[key], np.array(getattr(theirs, key)), rtol=0, atol=1e-12, err_msg=key)
    # orthonormal: unit norm, orthogonal to its even shifts
    lo = ours["dec_lo"]
    assert np.dot(lo, lo) == pytest.approx(1, abs=1e-14)
    for s in range(2, len(lo), 2):
        assert np.dot(lo[s:], lo[:-s]) == pytest.approx(0, abs=1e-14)


CASES = [
    ((8, 16, 32), "3d", 0),
    ((8, 16, 32), "2d", 0),
    ((6, 16, 8), "3d", 0),
    ((5, 16, 16), "3d", 0),
    ((4, 8, 24), "2d", 0),
    ((16, 8, 8), "3d", 2),
    ((8, 16, 16), "2d", 1),
    ((8, 7, 9), "3d", 0),
    # T not a multiple of 2**levels: a 3-D block of leading frames and a 2-D block
    ((11, 8, 8), "3d", 0),
    ((13, 16, 8), "3d", 0),
    ((11, 8, 7), "3d", 0),
]


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("shape, mode, levels", CASES)
def test_transform_matches_pywt(device, dtype, rng, name, shape, mode, levels):
    w = Wavelet(wavelet=name, mode=mode, levels=levels)
    plan = w.plan(shape)
    assert plan.levels > 0
    x = rng.standard_normal(shape)
    c = w.transform(_dev(device, x, dtype))
    assert c.shape == shape and c.dtype == np.dtype(dtype)
    want = _pywt_mallat(x, name, plan)
    tol = _tol(dtype, 1e-5, 1e-10)
    np.testing.assert_allclose(c.get(), want, rtol=tol, atol=tol * np.abs(want).max())
    # the inverse of pywt's coefficients is x again
    back = w.inverse(_dev(device, want, dtype)).get()
    np.testing.assert_allclose(back, x, atol=_tol(dtype, 1e-5, 1e-12) * np.abs(x).max())


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(
    "shape, mode",
    [
        ((8, 32, 16), "3d"),
        ((3, 16, 32), "2d"),
        ((16, 5, 3), "3d"),
        ((12, 24, 8), "3d"),
        ((13, 16, 16), "3d"),
        ((11, 8, 7), "3d"),
    ],
)
def test_perfect_reconstruction(device, dtype, rng, name, shape, mode):
    w = Wavelet(wavelet=name, mode=mode)
    x = rng.random(shape)
    xd = _dev(device, x, dtype)
    c = w.transform(xd)
    r = w.inverse(c)
    np.testing.assert_allclose(r.get(), x, atol=_tol(dtype, 1e-5, 1e-12))
    np.testing.assert_array_equal(xd.get(), x.astype(dtype))  # the input is not modified
    # orthonormal: energy is preserved
    assert np.linalg.norm(c.get()) == pytest.approx(np.linalg.norm(x), rel=_tol(dtype, 1e-5, 1e-12))


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(
    "shape, mode, levels, split",
    [
        ((8, 16, 32), "3d", 0, True),
        ((8, 16, 32), "2d", 0, True),
        ((5, 16, 16), "3d", 0, True),
        ((16, 8, 8), "3d", 2, True),
        ((8, 7, 9), "3d", 0, True),
        ((13, 16, 8), "3d", 0, True),
        ((11, 8, 7), "3d", 0, True),
        ((13, 16, 8), "3d", 0, False),
    ],
)
@pytest.mark.parametrize("weight", [0.05, 0.3])
def test_denoise_matches_pywt(device, dtype, rng, name, shape, mode, levels, split, weight):
    w = Wavelet(wavelet=name, mode=mode, levels=levels, split_time=split)
    x = rng.random(shape)
    got = w.denoise(_dev(device, x, dtype), weight)
    assert got.shape == shape and got.dtype == np.dtype(dtype)
    want = _pywt_denoise(x, name, w.plan(shape), weight)
    np.testing.assert_allclose(got.get(), want, atol=_tol(dtype, 1e-5, 1e-10))
    assert np.abs(got.get() - x).max() > 1e-3  # it did something


def test_denoise_writes_out(device, rng):
    import pyopencl.array as cla

    x = rng.random((4, 16, 16))
    xd = _dev(device, x, "float32")
    out = cla.zeros_like(xd)
    w = Wavelet(wavelet="db2")
    assert w.denoise(xd, 0.1, out=out) is out
    np.testing.assert_allclose(out.get(), w.denoise(xd, 0.1).get(), atol=0)
    np.testing.assert_allclose(out.get(), _pywt_denoise(x, "db2", w.plan(x.shape), 0.1), atol=1e-5)


def test_out_that_is_x_is_refused(device, rng):
    # the paper's T = 69 splits the time axis: the trailing 2-D block's first pass would read x as it writes it
    xd = _dev(device, rng.random((69, 8, 8)), "float32")
    before = xd.get()
    for call in (lambda w: w.denoise(xd, 0.1, out=xd), lambda w: w.transform(xd, out=xd)):
        with pytest.raises(ValueError, match="wavelet: out must be another buffer than x"):
            call(Wavelet())
    np.testing.assert_array_equal(xd.get(), before)


def test_large_weight_keeps_the_approximation(device, rng):
    # haar on every level of 16x16 sub-frames: the approximation is the frame's mean
    x = rng.random((3, 16, 16))
    got = (
        Wavelet(wavelet="haar", mode="2d")
        .denoise(_dev(device, x, "float64" if device.has_fp64 else "float32"), 1e6)
        .get()
    )
    np.testing.assert_allclose(got, np.broadcast_to(x.mean(axis=(1, 2), keepdims=True), x.shape), atol=1e-5)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("shape, mode", [((4, 16, 16), "3d"), ((3, 8, 16), "2d"), ((8, 7, 9), "2d")])
def test_weight_zero_is_identity(device, dtype, rng, name, shape, mode):
    x = rng.random(shape)
    got = Wavelet(wavelet=name, mode=mode).denoise(_dev(device, x, dtype), 0.0)
    assert got.shape == shape and got.dtype == np.dtype(dtype)
    np.testing.assert_array_equal(got.get(), x.astype(dtype))


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("mode", ["2d", "3d"])
def test_non_expansive(device, dtype, rng, name, mode):
    w = Wavelet(wavelet=name, mode=mode)
    shape = (8, 16, 16)
    for trial in range(5):
        x, y = rng.random(shape), rng.random(shape)
        if trial % 2:
            y = x + 0.05 * rng.standard_normal(shape)
        weight = [0.01, 0.1, 0.5][trial % 3]
        dx = w.denoise(_dev(device, x, dtype), weight).get().astype(np.float64)
        dy = w.denoise(_dev(device, y, dtype), weight).get().astype(np.float64)
        assert np.linalg.norm(dx - dy) <= np.linalg.norm(x - y) * (1 + _tol(dtype, 1e-5, 1e-12))
        # a prox of a non-negative function never moves a point further from another
        # denoised point than it was (firm non-expansiveness implies this inner product bound)
        assert np.vdot(dx - dy, x - y) >= np.linalg.norm(dx - dy) ** 2 * (1 - _tol(dtype, 1e-4, 1e-10))


@pytest.mark.parametrize("name", NAMES)
def test_2d_mode_keeps_subframes_independent(device, dtype, rng, name):
    w = Wavelet(wavelet=name, mode="2d")
    x = rng.random((5, 16, 24))
    stack = w.denoise(_dev(device, x, dtype), 0.2).get()
    alone = np.stack([w.denoise(_dev(device, f[None], dtype), 0.2).get()[0] for f in x])
    np.testing.assert_allclose(stack, alone, atol=_tol(dtype, 1e-6, 1e-13))
    # and 3-D mode does couple them (T = 8 can be transformed)
    x8 = rng.random((8, 16, 24))
    d2 = w.denoise(_dev(device, x8, dtype), 0.2).get()
    d3 = Wavelet(wavelet=name, mode="3d").denoise(_dev(device, x8, dtype), 0.2).get()
    assert np.abs(d2 - d3).max() > 1e-3


@pytest.mark.parametrize(
    "name, mode, shape, expected",
    [
        ("haar", "3d", (55, 64, 64), (6, (1, 2))),  # odd T: the time axis is left untouched
        ("db2", "3d", (55, 64, 64), (5, (1, 2))),
        ("db4", "3d", (55, 64, 64), (4, (1, 2))),  # 64 / 2**3 = 8 taps at the coarsest level
        ("haar", "2d", (55, 64, 64), (6, (1, 2))),
        ("haar", "3d", (1, 16, 16), (4, (1, 2))),
        ("db2", "3d", (1, 16, 16), (3, (1, 2))),
        ("db4", "3d", (1, 16, 16), (2, (1, 2))),
        ("haar", "3d", (8, 7, 9), (3, (0,))),  # only t can be transformed
        ("db2", "3d", (8, 7, 9), (2, (0,))),
        ("db4", "3d", (8, 7, 9), (1, (0,))),
        ("haar", "2d", (8, 7, 9), (0, ())),  # nothing can: the denoiser is the identity
        ("haar", "3d", (16, 64, 64), (4, (0, 1, 2))),  # one level count for all axes
        ("haar", "3d", (2, 64, 64), (1, (0, 1, 2))),
        ("db4", "3d", (4, 64, 64), (4, (1, 2))),  # T = 4 is shorter than 8 taps
        ("haar", "2d", (3, 96, 40), (3, (1, 2))),  # 40 = 8 * 5
    ],
)
def test_levels_auto_choice(name, mode, shape, expected):
    plan = Wavelet(wavelet=name, mode=mode).plan(shape)
    assert plan[:2] == expected and plan.blocks == ((0, shape[0], expected[1]),)
    assert Wavelet(wavelet=name, mode=mode, split_time=False).plan(shape) == plan


@pytest.mark.parametrize(
    "name, shape, levels, head",
    [
        ("haar", (69, 64, 64), 6, 64),  # the paper's 4-camera array at 64 x 64: T = 69
        ("db2", (69, 64, 64), 5, 64),
        ("db4", (69, 64, 64), 4, 64),
        ("haar", (70, 64, 64), 6, 64),  # 70 = 2 * 35 would allow only 1 level without the split
        ("db4", (69, 16, 16), 2, 68),
        ("db2", (11, 8, 8), 2, 8),
    ],
)
def test_levels_with_time_split(name, shape, levels, head):
    plan = Wavelet(wavelet=name).plan(shape)
    assert plan.levels == levels and plan.axes == (0, 1, 2)
    assert plan.blocks == ((0, head, (0, 1, 2)), (head, shape[0] - head, (1, 2)))
    # without the split the time axis is untouched (odd T) or limits the levels (T = 70)
    plain = Wavelet(wavelet=name, split_time=False).plan(shape)
    assert plain.blocks == ((0, shape[0], plain.axes),)
    assert plain.axes == (1, 2) if shape[0] % 2 else plain.levels == 1
    # the split is not used in 2-D mode
    assert Wavelet(wavelet=name, mode="2d").plan(shape).axes == (1, 2)


def test_levels_option_caps_and_rule():
    assert Wavelet(wavelet="haar", levels=2, split_time=False).plan((55, 64, 64))[:2] == (2, (1, 2))
    assert Wavelet(wavelet="haar", levels=2).plan((55, 64, 64)).blocks == ((0, 52, (0, 1, 2)), (52, 3, (1, 2)))
    assert Wavelet(wavelet="haar", levels=20).plan((55, 64, 64))[:2] == (6, (1, 2))
    assert Wavelet(wavelet="haar", levels=3).plan((69, 64, 64)).blocks == ((0, 64, (0, 1, 2)), (64, 5, (1, 2)))
    assert Wavelet(wavelet="haar", levels=2).plan((69, 64, 64)).blocks == ((0, 68, (0, 1, 2)), (68, 1, (1, 2)))
    for flen in (2, 4, 8):
        for length in range(1, 130):
            L = axis_levels(length, flen)
            ok = lambda lv, length=length, flen=flen: length % 2**lv == 0 and length // 2 ** (lv - 1) >= flen  # noqa: E731
            assert (L == 0 or ok(L)) and not ok(L + 1), (length, flen, L)


def test_untransformable_shape_is_identity(device, rng):
    x = rng.random((8, 7, 9))
    w = Wavelet(wavelet="haar", mode="2d")
    np.testing.assert_array_equal(w.denoise(_dev(device, x, "float32"), 0.5).get(), x.astype(np.float32))
    assert w.workspace_bytes(x.shape, np.float32) == 0


def test_workspace_bytes():
    assert Wavelet().workspace_bytes((55, 64, 64), np.float32) == 55 * 64 * 64 * 4
    assert Wavelet().workspace_bytes((8, 16, 16), np.float64) == 8 * 16 * 16 * 8


def test_options_are_validated():
    with pytest.raises(ValueError, match="wavelet"):
        Wavelet(wavelet="db3")
    with pytest.raises(ValueError, match="mode"):
        Wavelet(mode="4d")
    with pytest.raises(ValueError, match="levels"):
        Wavelet(levels=-1)
    with pytest.raises(ValueError, match="levels"):
        Wavelet(levels=1.5)
    with pytest.raises(ValueError, match="unknown option"):
        Wavelet(threshold=1)


def test_input_is_validated(device):
    import pyopencl.array as cla

    with pytest.raises(ValueError, match="pyopencl.array.Array"):
        Wavelet().denoise(np.zeros((2, 2, 2)), 0.1)
    with pytest.raises(ValueError, match="shape"):
        Wavelet().denoise(cla.zeros(device.queue, (2, 2), np.float32), 0.1)
    with pytest.raises(ValueError, match="weight"):
        Wavelet().denoise(cla.zeros(device.queue, (2, 2, 2), np.float32), -1.0)


def test_registered_as_plugin():
    import rsocl.common.registry

    assert rsocl.common.registry.load("rsocl.regularizers", "wavelet") is Wavelet


def test_reconstruct_with_wavelet_improves_psnr():
    import rsocl
    from rsocl.model import reference as ref

    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=1e-4, t_r=3e-5)
    truth = np.clip(np.linspace(0, 1, 16)[None, None, :] + np.zeros((rig.T,) + rig.shape), 0, 1)
    g = ref.forward(rig, truth)
    res = rsocl.reconstruct(
        g,
        rig,
        regularizer="wavelet",
        regularizer_options={"wavelet": "db2"},
        iterations=20,
        lam=0.02,
        eta=0.2,
        truth=truth,
    )
    assert res.params["regularizer"] == "wavelet"
    assert res.history["psnr"][-1] > res.history["psnr"][0]
