"""The OpenCL operator against the NumPy reference, and the dot test, on many rigs."""

import numpy as np
import pytest

import rsocl
from rsocl import Camera, Rig, RollingShutterOperator
from rsocl.model import reference as ref
from rsocl.model.windows import kernel_windows, weighted_bounds
from rsocl.testing import dottest

TOL = {"float32": 1e-5, "float64": 1e-12}


def _rigs():
    yield "paper4-square", Rig.paper_array(4, (12, 12), t_e=0.18e-3, t_r=35e-6)
    yield "paper4-binary", Rig.paper_array(4, (9, 11), t_e=0.18e-3, t_r=35e-6, mask="binary")
    yield "one-camera", Rig.paper_array(1, (7, 5), t_e=1e-4, t_r=3e-5)
    yield "eight-oblique", Rig.paper_array(8, (8, 10), t_e=1e-4, t_r=3e-5)
    yield "eight-oblique-binary", Rig.paper_array(8, (6, 9), t_e=1e-4, t_r=3e-5, mask="binary")
    yield (
        "fractional-te-offset-gain",
        Rig(
            [
                Camera(0, t_e=1.37e-4, t_r=3e-5, t_a=1.1e-5, gain=1.3),
                Camera(30, t_e=0.9e-4, t_r=3e-5, gain=0.7),
                Camera(200, t_e=2.1e-4, t_r=3e-5, t_a=4e-5),
            ],
            (10, 7),
        ),
    )
    yield "dt-binning", Rig.paper_array(4, (11, 6), t_e=1.6e-4, t_r=3e-5, dt=7.3e-5)
    yield "dt-binning-binary", Rig.paper_array(3, (5, 13), t_e=1.6e-4, t_r=3e-5, dt=7.3e-5, mask="binary")
    yield "te-multiple-of-tr", Rig.paper_array(2, (6, 6), t_e=4 * 3e-5, t_r=3e-5)
    yield "te-multiple-binary", Rig.paper_array(2, (6, 6), t_e=4 * 3e-5, t_r=3e-5, mask="binary")
    yield "short-exposure", Rig.paper_array(4, (6, 8), t_e=0.1 * 3e-5, t_r=3e-5)
    yield (
        "multi-frame",
        Rig([Camera(0, t_e=5e-5, t_r=1e-5, frames=3, t_d=1.2e-4), Camera(90, t_e=5e-5, t_r=1e-5)], (8, 8)),
    )
    yield (
        "row-map",
        Rig(
            [
                Camera(t_e=6e-5, t_r=2e-5, row_map=np.random.default_rng(0).uniform(0, 9, (5, 6))),
                Camera(90, t_e=6e-5, t_r=2e-5),
            ],
            (5, 6),
        ),
    )
    # exposures that end exactly on a sub-frame start (dt = 3 t_r): the binary rule counts that sub-frame
    for t_e in (1.0, 40.0):
        yield (
            f"binary-ends-on-starts-te{t_e:g}tr",
            Rig(
                [
                    Camera(a, t_e=t_e * 3.5e-5, t_r=3.5e-5, gain=g, t_a=ta * 3.5e-5)
                    for a, g, ta in [(0, 1.0, 0.0), (30, 0.5, 3.3), (137, 2.0, 1.1), (45, 1.7, 0.0)]
                ],
                (11, 9),
                dt=3 * 3.5e-5,
                mask="binary",
            ),
        )
    yield "binary-dt-7.3tr", Rig.paper_array(4, (11, 9), t_e=3 * 3.5e-5, t_r=3.5e-5, dt=7.3 * 3.5e-5, mask="binary")
    yield "one-row", Rig.paper_array(4, (1, 9), t_e=1e-4, t_r=3e-5)
    yield "one-column", Rig.paper_array(4, (9, 1), t_e=1e-4, t_r=3e-5)
    yield "one-pixel", Rig.paper_array(2, (1, 1), t_e=1e-4, t_r=3e-5)


RIGS = dict(_rigs())


def _rel(a, b):
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)


@pytest.mark.parametrize("name", sorted(RIGS))
def test_matches_reference_and_dot_test(name, dtype, device, rng):
    rig = RIGS[name]
    op = RollingShutterOperator(rig, device=device, dtype=dtype)
    f = rng.random((rig.T,) + rig.shape)
    g = rng.random((rig.n_channels,) + rig.shape)
    tol = TOL[dtype]
    assert op.forward(f).shape == (rig.n_channels,) + rig.shape
    assert op.forward(f).dtype == np.dtype(dtype)
    assert _rel(op.forward(f), ref.forward(rig, f)) < tol
    assert _rel(op.adjoint(g), ref.adjoint(rig, g)) < tol
    assert _rel(op.psi, ref.psi(rig)) < tol
    assert _rel(op.gram(), ref.gram(rig)) < tol
    # dot test <H f, g> = <f, Hᵀ g>, with the device's own results
    assert dottest(op, rtol=10 * tol)


def test_weights_are_overlap_fractions():
    rig = RIGS["fractional-te-offset-gain"]
    w = ref.weights(rig)
    assert w.min() >= 0 and w.max() <= 1
    # each pixel's exact weights add up to its exposure in sub-frames (nothing clipped at T)
    np.testing.assert_allclose(w.sum(axis=1), rig.windows.length[:, None, None] * np.ones(rig.shape))
    # non-zero weights are consecutive and at most ceil(t_e/dt) + 1 long
    nz = w > 0
    assert nz.sum(axis=1).max() <= rig.window_length
    first, last = rig.sampled_window()
    np.testing.assert_array_equal(nz.sum(axis=1), last - first + 1)


def test_binary_rule_is_the_papers():
    rig = Rig.paper_array(1, (3, 1), t_e=3e-5 * 2.5, t_r=3e-5, mask="binary")
    w = ref.weights(rig)[0, :, :, 0]
    # row y starts at s = y and ends at y + 2.5: samples y, y+1, y+2
    expected = np.zeros((rig.T, 3))
    for y in range(3):
        expected[y : y + 3, y] = 1
    np.testing.assert_array_equal(w, expected)


@pytest.mark.parametrize("length", [2000.3, 20000.3])
@pytest.mark.parametrize("mask", ["exact", "binary"])
def test_a_long_exposure_keeps_its_last_weight(length, mask, dtype, device):
    # H^T of a unit snapshot is the pixel's weights: the last one, 0.3 of a sub-frame, to float32's rounding
    rig = Rig([Camera(0, t_e=length * 1e-5, t_r=1e-5)], (2, 1), mask=mask)
    op = RollingShutterOperator(rig, device=device, dtype=dtype)
    g = np.zeros((1, 2, 1))
    g[0, 1, 0] = 1.0
    np.testing.assert_allclose(op.adjoint(g), ref.adjoint(rig, g), rtol=0, atol=TOL[dtype])


@pytest.mark.parametrize("dtype_name", ["float32", "float64"])
def test_kernel_windows_give_the_hosts_binary_bounds(dtype_name):
    # the kernels' binary test, in their real type, on windows whose ends fall on sub-frame starts
    real = np.dtype(dtype_name).type
    for dt_rows, te_rows in [(3, 1), (3, 40), (7.3, 3), (1, 5.5), (2.5, 0.4), (1, 1)]:
        offsets = [(0, 0), (90, 1.1), (200, 3.3)]
        cameras = [Camera(a, t_e=te_rows * 3.5e-5, t_r=3.5e-5, t_a=ta * 3.5e-5) for a, ta in offsets]
        rig = Rig(cameras, (7, 6), dt=dt_rows * 3.5e-5, mask="binary")
        win = rig.windows
        frac, length = kernel_windows(win, "binary", dtype_name)
        first, last = weighted_bounds(win, "binary")
        j = np.arange(rig.window_length + 1, dtype=np.float64)[:, None, None, None]
        taken = (real(j) >= frac) & (real(j) - length[:, 0, None, None] <= frac + length[:, 1, None, None])
        expected = (win.index + j >= first) & (win.index + j <= last)
        np.testing.assert_array_equal(taken, expected, err_msg=f"dt = {dt_rows} t_r, t_e = {te_rows} t_r")


def test_binary_ties_keep_interpolation_exact_on_a_constant_scene(device):
    # simulate (the device's H) and interp3d (the host's Eq. 4) must see the same windows
    rig = RIGS["binary-ends-on-starts-te1tr"]
    g = rsocl.simulate(np.full((rig.T,) + rig.shape, 0.7), rig, device=device)
    np.testing.assert_allclose(rsocl.interp3d(g, rig), 0.7, atol=1e-9)


def test_late_exposure_starts_keep_their_offset_from_sub_frame_starts():
    # a long capture with a trigger offset of 0.004 sub-frames: every start is t_a + k t_d, off every
    # sub-frame boundary, and stays so to rounding (a tolerance relative to the time would move late ones)
    from fractions import Fraction

    t_r, t_d = 35e-6, 1 / 67
    cam = Camera(0, t_e=180e-6, t_r=t_r, t_a=0.004 * t_r, frames=8000, t_d=t_d)
    win = Rig([cam], (1, 1)).windows
    start = (win.index + win.fraction)[:, 0, 0]
    exact = np.array([float((Fraction(0.004 * t_r) + k * Fraction(t_d)) / Fraction(t_r)) for k in range(8000)])
    np.testing.assert_allclose(start, exact, rtol=0, atol=1e-8)
    # and a start that is a whole number of sub-frames up to rounding still lands on it
    on = Rig([Camera(0, t_e=3 * t_r, t_r=t_r, t_a=0.000105)], (2, 2)).windows
    np.testing.assert_array_equal(on.fraction, 0.0)
    np.testing.assert_array_equal(on.index[0, :, 0], [3, 4])


def test_device_arrays_stay_on_device(device, rng):
    import pyopencl.array as cla

    rig = RIGS["paper4-square"]
    op = RollingShutterOperator(rig, device=device)
    f = rng.random((rig.T,) + rig.shape).astype(np.float32)
    f_dev = cla.to_device(device.queue, f)
    g_dev = op.forward(f_dev)
    assert isinstance(g_dev, cla.Array)
    back = op.adjoint(g_dev)
    assert isinstance(back, cla.Array) and back.shape == (rig.T,) + rig.shape
    np.testing.assert_allclose(back.get(), op.adjoint(op.forward(f)), rtol=1e-6)


def test_shape_and_dtype_errors(device):
    import pyopencl.array as cla

    rig = RIGS["paper4-square"]
    op = RollingShutterOperator(rig, device=device)
    with pytest.raises(ValueError, match=r"f must have shape"):
        op.forward(np.zeros((rig.T + 1,) + rig.shape))
    with pytest.raises(ValueError, match=r"g must have shape"):
        op.adjoint(np.zeros((3,) + rig.shape))
    with pytest.raises(ValueError, match="dtype"):
        op.forward(cla.zeros(device.queue, (rig.T,) + rig.shape, np.int32))
    with pytest.raises(ValueError, match="dtype must be"):
        RollingShutterOperator(rig, device=device, dtype="float16")
    with pytest.raises(ValueError, match="rig must be"):
        RollingShutterOperator("rig", device=device)


@pytest.mark.filterwarnings("ignore:camera t_e = .* is longer than 1 s:UserWarning")  # a long exposure, on purpose
def test_datacube_too_large_for_device_is_refused(device):
    # an exposure of twice as many 10 µs sub-frames of m x m (float32) as the device's largest
    # buffer holds (2 GiB on PoCL's 1 GiB limit, 40 GiB on an H100's 20 GiB), m grown until the
    # exposure spans at most half of MAX_WINDOW sub-frames, so that limit is not the one met
    from rsocl.model.plausible import MAX_WINDOW

    m = 64
    while 2 * device.max_alloc_bytes // (m * m * 4) > MAX_WINDOW // 2:
        m *= 2
    subframes = 2 * device.max_alloc_bytes // (m * m * 4)
    rig = Rig([Camera(0, t_e=subframes * 1e-5, t_r=1e-5)], (m, m))
    with pytest.raises(ValueError, match="largest allocation"):
        RollingShutterOperator(rig, device=device)


@pytest.mark.parametrize("mask", ["exact", "binary"])
@pytest.mark.parametrize("shape", [(16, 16), (13, 13), (3, 7), (10, 16), (8, 21)])
def test_tiles_and_cut_windows_match_zero_padded_reference(shape, mask, dtype, device, rng):
    # The kernels take blocks of 4 rows x VW pixels per work item; blocks cut by the right
    # edge (8x21), the bottom edge (10x16), both (13x13) or smaller than a block (3x7) take the
    # scalar loops. A sub-frame range cuts windows at both ends (first < 0, and windows
    # running past T). All must equal H on the zero-padded datacube.
    rig = Rig(
        [
            Camera(0, t_e=1.6e-4, t_r=3e-5),
            Camera(90, t_e=1.6e-4, t_r=3e-5, t_a=2e-5),
            Camera(45, t_e=1.6e-4, t_r=3e-5),
            Camera(200, t_e=0.5e-4, t_r=3e-5, gain=0.8),
        ],
        shape,
        mask=mask,
    )
    cut = slice(3, rig.T - 4)
    op = RollingShutterOperator(rig, device=device, dtype=dtype, subframes=cut)
    assert (rig.windows.index - cut.start).min() < 0  # some windows start before the range
    # the vector kernels rely on every window ending before L (no per-lane range test)
    w = rig.windows
    assert w.fraction.min() >= 0 and (w.fraction + w.length[:, None, None]).max() < rig.window_length
    f_cut = rng.random(op.domain_shape)
    f_full = np.zeros((rig.T,) + rig.shape)
    f_full[cut] = f_cut
    g = rng.random(op.range_shape)
    tol = TOL[dtype]
    assert _rel(op.forward(f_cut), ref.forward(rig, f_full)) < tol
    assert _rel(op.adjoint(g), ref.adjoint(rig, g)[cut]) < tol


# the default, one pixel per work item, on the frames of the tile test above (13x13: blocks cut by both
# edges, 3x7: smaller than a block, 8x21: cut by the right edge); other layouts (vectors, several rows)
# once each, marked slow, so Oclgrind's run (-m 'not slow') checks the default alone
LAYOUTS = [((1, 1), (13, 13)), ((1, 1), (3, 7)), ((1, 1), (8, 21))] + [
    pytest.param(block, shape, marks=pytest.mark.slow)
    for block, shape in [((2, 1), (13, 13)), ((1, 3), (8, 21)), ((4, 2), (13, 13)), ((8, 4), (3, 7))]
]


@pytest.mark.parametrize(("block", "shape"), LAYOUTS)
def test_gpu_block_layouts_match_the_reference(block, shape, dtype, device, rng, monkeypatch):
    """On a device that is not a CPU the block kernels take ``GPU_BLOCK`` pixels x rows per work item
    (one pixel by default); every layout, whole blocks and blocks cut by the edges, equals H, Hᵀ and
    the residual of the reference, and a reconstruction equals the CPU layout's."""
    import rsocl
    from rsocl.device.context import Device
    from rsocl.model import operator as operator_module

    rig = Rig([Camera(0, t_e=1.6e-4, t_r=3e-5), Camera(90, t_e=1.6e-4, t_r=3e-5, t_a=2e-5)], shape)
    f = rng.random((rig.T,) + shape)
    g = ref.forward(rig, f)
    opts = dict(iterations=4, lam=0.1, eta=0.2, tune=False, device=device, dtype=dtype)
    base = rsocl.reconstruct(g, rig, **opts)
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    monkeypatch.setattr(operator_module, "GPU_BLOCK", block)
    op = RollingShutterOperator(rig, device=device, dtype=dtype)
    assert (op.vector_width, op.block_rows) == block
    tol = TOL[dtype]
    assert _rel(op.forward(f), g) < tol
    assert _rel(op.adjoint(g), ref.adjoint(rig, g)) < tol
    res = rsocl.reconstruct(g, rig, **opts)
    assert _rel(res.datacube, base.datacube) < 10 * tol
    assert _rel(res.history["residual"], base.history["residual"]) < 10 * tol  # summed in other groups
