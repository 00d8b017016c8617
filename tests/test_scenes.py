from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from skimage.color import rgb2gray
from skimage.transform import resize

from rsocl.model.scenes import benchmark_protocol, builtin_scene, load_scene, load_video

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture
def video():
    """uint8 [5, 24, 30] with structure (so resizing matters)."""
    rng = np.random.default_rng(7)
    return rng.integers(0, 256, size=(5, 24, 30), dtype=np.uint8)


def _resized(frame, shape):
    return resize(frame, shape, order=1, anti_aliasing=True)


# ---------------------------------------------------------------------- builtin scene
def test_builtin_scene_shape_range_determinism():
    a = builtin_scene((32, 40), 20)
    assert a.shape == (20, 32, 40) and a.dtype == np.float32
    assert a.min() >= 0.0 and a.max() <= 1.0
    assert a.max() == pytest.approx(1.0)  # the disc is white
    np.testing.assert_array_equal(a, builtin_scene((32, 40), 20))
    assert not np.array_equal(a, builtin_scene((32, 40), 20, seed=1))
    b = builtin_scene((32, 40), 20, dtype=np.float64)
    assert b.dtype == np.float64
    np.testing.assert_allclose(b, a, atol=1e-6)


def test_builtin_scene_moves_noticeably():
    T, n = 55, 64
    a = builtin_scene((64, n), T)
    # the disc (the only pixels at full brightness) crosses the frame left to right
    xs = []
    for s in (5, T - 6):
        ys_, xs_ = np.nonzero(a[s] > 0.99)
        assert xs_.size > 10
        xs.append(xs_.mean())
    assert xs[1] - xs[0] > n / 2
    # every sub-frame differs from the previous one by a visible amount
    change = np.abs(np.diff(a, axis=0)).max(axis=(1, 2))
    assert np.all(change > 0.2)
    # antialiased edges: intermediate values exist around the disc
    edge = a[T // 2]
    assert np.count_nonzero((edge > 0.6) & (edge < 0.99)) > 10


@pytest.mark.parametrize("shape, T", [((16, 16), 2500), ((5, 70), 1600), ((1, 1), 7)])
def test_builtin_scene_renders_the_same_frames_in_chunks_as_one_at_a_time(monkeypatch, shape, T):
    import rsocl.model.scenes as scenes

    chunked = scenes.builtin_scene(shape, T, seed=3, dtype=np.float64)
    assert scenes._CHUNK_VALUES // (shape[0] * shape[1]) < T or shape == (1, 1)  # several chunks
    monkeypatch.setattr(scenes, "_CHUNK_VALUES", 1)  # one sub-frame per chunk
    assert np.array_equal(chunked, scenes.builtin_scene(shape, T, seed=3, dtype=np.float64))


def test_builtin_scene_other_shapes():
    assert builtin_scene((7, 3), 2).shape == (2, 7, 3)
    assert builtin_scene((1, 1), 1).shape == (1, 1, 1)
    assert builtin_scene((20, 50), 3).shape == (3, 20, 50)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(shape=(0, 5)), "shape"),
        (dict(shape=(5,)), "shape"),
        (dict(T=0), "T"),
        (dict(dtype=np.int32), "dtype"),
        (dict(seed=-1), "seed"),
        (dict(seed=1.5), "seed"),
    ],
)
def test_builtin_scene_rejects_bad_arguments(kwargs, name):
    with pytest.raises(ValueError, match=name):
        builtin_scene(**kwargs)


# ---------------------------------------------------------------------- load_video
def test_load_npz_and_npy(tmp_path, video):
    np.savez(tmp_path / "v.npz", video=video, other=np.zeros(3))
    out = load_video(tmp_path / "v.npz")
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out, video)
    np.savez(tmp_path / "k.npz", clip=video)
    np.testing.assert_array_equal(load_video(str(tmp_path / "k.npz"), key="clip"), video)
    np.save(tmp_path / "v.npy", video)
    np.testing.assert_array_equal(load_video(tmp_path / "v.npy"), video)


def test_load_video_errors(tmp_path, video):
    np.savez(tmp_path / "v.npz", video=video)
    with pytest.raises(ValueError, match="'clip'.*not found"):
        load_video(tmp_path / "v.npz", key="clip")
    np.savez(tmp_path / "flat.npz", video=video[0])
    with pytest.raises(ValueError, match="3-D"):
        load_video(tmp_path / "flat.npz")
    np.savez(tmp_path / "empty.npz", video=video[:0])
    with pytest.raises(ValueError, match="empty"):
        load_video(tmp_path / "empty.npz")
    (tmp_path / "v.avi").write_bytes(b"\0" * 16)
    with pytest.raises(ValueError, match="suffix"):
        load_video(tmp_path / "v.avi")
    with pytest.raises(FileNotFoundError):
        load_video(tmp_path / "missing.npz")


def test_load_multipage_tiff(tmp_path, video):
    iio.imwrite(tmp_path / "v.tif", video)
    out = load_video(tmp_path / "v.tif")
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out, video)
    # one page per series (as some writers do) is read page by page as well
    import tifffile

    with tifffile.TiffWriter(tmp_path / "pages.tiff") as writer:
        for frame in video:
            writer.write(frame)
    np.testing.assert_array_equal(load_video(tmp_path / "pages.tiff"), video)
    # a single page is a one-frame video
    iio.imwrite(tmp_path / "one.tif", video[0])
    np.testing.assert_array_equal(load_video(tmp_path / "one.tif"), video[:1])


def test_load_gif_gray_and_rgb(tmp_path, video):
    iio.imwrite(tmp_path / "g.gif", video, duration=50, loop=0)
    out = load_video(tmp_path / "g.gif")
    assert out.shape == video.shape and out.dtype == np.uint8
    np.testing.assert_array_equal(out, video)
    # pure colours (exact in a GIF palette) go through rgb2gray, staying uint8
    rgb = np.zeros((3, 8, 8, 3), dtype=np.uint8)
    for f in range(3):
        rgb[f, :, :, f] = 255
        rgb[f, :4, :4] = (10 * f, 10 * f, 10 * f)  # a frame-dependent patch: no frame merging
    iio.imwrite(tmp_path / "c.gif", rgb, duration=50, loop=0)
    gray = load_video(tmp_path / "c.gif")
    assert gray.shape == (3, 8, 8) and gray.dtype == np.uint8
    expected = np.rint(rgb2gray(rgb) * 255).astype(np.uint8)
    np.testing.assert_array_equal(gray, expected)
    assert gray[0, -1, -1] == round(0.2125 * 255)  # red weight


# ---------------------------------------------------------------------- protocol
def test_protocol_shapes_range_and_end_frames(video):
    out = benchmark_protocol(video, (12, 10), 9)
    assert out.shape == (9, 12, 10) and out.dtype == np.float32
    assert out.min() >= 0 and out.max() <= 1
    first = _resized(video[0] / 255.0, (12, 10))
    last = _resized(video[-1] / 255.0, (12, 10))
    np.testing.assert_allclose(out[0], first, atol=1e-6)
    np.testing.assert_allclose(out[-1], last, atol=1e-6)
    # sub-frame 2 of 9 sits at source position 2*4/8 = 1.0 exactly: frame 1
    np.testing.assert_allclose(out[2], _resized(video[1] / 255.0, (12, 10)), atol=1e-6)


def test_protocol_linear_time_interpolation():
    video = np.zeros((2, 6, 6), dtype=np.uint8)
    video[1] = 200
    out = benchmark_protocol(video, (6, 6), 5)
    expected = np.array([0, 50, 100, 150, 200]) / 255.0
    np.testing.assert_allclose(out[:, 3, 3], expected, atol=1e-6)
    # midpoint between two structured frames is their mean
    rng = np.random.default_rng(0)
    video = rng.integers(0, 256, size=(3, 16, 16), dtype=np.uint8)
    out = benchmark_protocol(video, (8, 8), 5)  # s=1 at position 0.5
    mid = 0.5 * (_resized(video[0] / 255.0, (8, 8)) + _resized(video[1] / 255.0, (8, 8)))
    np.testing.assert_allclose(out[1], mid, atol=1e-6)


def test_protocol_scaling_rules():
    floats = np.linspace(-3.0, 5.0, 2 * 4 * 4).reshape(2, 4, 4)
    out = benchmark_protocol(floats, (4, 4), 2)
    assert out[0].min() == pytest.approx(0.0) and out[-1].max() == pytest.approx(1.0)
    np.testing.assert_allclose(out[0], (floats[0] + 3) / 8, atol=1e-6)
    assert np.all(benchmark_protocol(np.full((3, 4, 4), 7.5), (4, 4), 3) == 0)
    signed = np.full((1, 4, 4), -100, dtype=np.int16)
    signed[0, 0] = 32767
    out = benchmark_protocol(signed, (4, 4), 1)
    assert out.min() == 0.0 and out[0, 0].max() == pytest.approx(1.0)
    u16 = np.full((1, 3, 3), 65535 // 2, dtype=np.uint16)
    assert benchmark_protocol(u16, (3, 3), 2)[1, 1, 1] == pytest.approx(0.5, abs=1e-4)


def test_protocol_single_frame_and_T1(video):
    out = benchmark_protocol(video[:1], (6, 5), 4)
    for s in range(4):
        np.testing.assert_array_equal(out[s], out[0])
    out = benchmark_protocol(video, (6, 5), 1)
    np.testing.assert_allclose(out[0], _resized(video[0] / 255.0, (6, 5)), atol=1e-6)
    # upsampling in space is allowed
    assert benchmark_protocol(video, (50, 60), 2).shape == (2, 50, 60)


def test_protocol_rejects_bad_input(video):
    with pytest.raises(ValueError, match="video"):
        benchmark_protocol(video[0], (4, 4), 3)
    with pytest.raises(ValueError, match="video"):
        benchmark_protocol(np.full((2, 3, 3), np.nan), (4, 4), 3)
    with pytest.raises(ValueError, match="T"):
        benchmark_protocol(video, (4, 4), 0)
    with pytest.raises(ValueError, match="shape"):
        benchmark_protocol(video, (4, -1), 3)


# ---------------------------------------------------------------------- load_scene
def test_load_scene_builtin_and_file(tmp_path, video):
    np.testing.assert_array_equal(load_scene("builtin", (16, 16), 7), builtin_scene((16, 16), 7))
    np.savez(tmp_path / "v.npz", video=video)
    out = load_scene(tmp_path / "v.npz", (8, 8), 6)
    np.testing.assert_array_equal(out, benchmark_protocol(video, (8, 8), 6))
    with pytest.raises(FileNotFoundError):
        load_scene(str(tmp_path / "nope.npz"), (8, 8), 6)
    with pytest.raises(ValueError, match="spec"):
        load_scene(3, (8, 8), 6)


@pytest.mark.shared_data
def test_runner_benchmark_protocol():
    path = SHARED_DATA / "runner40.npz"
    if not path.exists():
        pytest.skip(f"{path} not available")
    raw = load_video(path)
    assert raw.shape == (40, 256, 256) and raw.dtype == np.uint8
    cube = load_scene(path, (50, 50), 58)
    assert cube.shape == (58, 50, 50) and cube.dtype == np.float32
    assert 0 <= cube.min() and cube.max() <= 1
    np.testing.assert_allclose(cube[0], _resized(raw[0] / 255.0, (50, 50)), atol=1e-6)
    np.testing.assert_allclose(cube[-1], _resized(raw[-1] / 255.0, (50, 50)), atol=1e-6)
