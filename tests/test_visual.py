import imageio.v3 as iio
import numpy as np
import pytest

from rsocl.analysis import visual
from rsocl.analysis.visual import channel_titles, comparison_gif, datacube_montage, snapshot_montage
from rsocl.model.rig import Camera, Rig


@pytest.fixture
def cubes():
    rng = np.random.default_rng(9)
    truth = rng.uniform(0.1, 0.9, size=(6, 10, 16))
    estimate = truth + rng.normal(0, 0.2, truth.shape)  # goes outside [0, 1]: tests the common range
    return truth, estimate


def _unit8(array, low, high):
    return np.rint(np.clip((array - low) / (high - low), 0, 1) * 255).astype(np.uint8)


def _upscale(image, scale):
    return np.repeat(np.repeat(image, scale, axis=0), scale, axis=1)


def _gray(frames):
    frames = np.asarray(frames)
    return frames[..., 0] if frames.ndim == 4 else frames


def test_comparison_gif_side_by_side(tmp_path, cubes):
    truth, estimate = cubes
    scale, gap = 8, 4  # gap = scale // 2
    path = comparison_gif(tmp_path / "cmp.gif", truth, estimate, fps=10, scale=scale)
    assert path == tmp_path / "cmp.gif"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cmp.gif"]
    frames = _gray(iio.imread(path, index=None))
    T, m, n = truth.shape
    strip = visual._STRIP
    assert frames.shape == (T, strip + m * scale + strip, 2 * n * scale + gap)
    low = min(truth.min(), estimate.min())
    high = max(truth.max(), estimate.max())
    body = slice(strip, strip + m * scale)
    for s in (0, T - 1):
        np.testing.assert_array_equal(frames[s, body, : n * scale], _upscale(_unit8(truth[s], low, high), scale))
        np.testing.assert_array_equal(
            frames[s, body, n * scale + gap :], _upscale(_unit8(estimate[s], low, high), scale)
        )
    assert frames[0, :strip].max() > 128  # a title was drawn
    meta = iio.immeta(path)
    assert meta["loop"] == 0 and meta["duration"] == 100


def test_comparison_gif_estimate_alone_and_small(tmp_path, cubes):
    _, estimate = cubes
    path = comparison_gif(tmp_path / "alone.gif", None, estimate, scale=2, fps=25)
    frames = _gray(iio.imread(path, index=None))
    assert frames.shape[0] == estimate.shape[0]
    assert frames.shape[2] == estimate.shape[2] * 2
    assert iio.immeta(path)["duration"] == 40
    # too narrow for any text: just the images
    tiny = comparison_gif(tmp_path / "tiny.gif", None, estimate[:, :3, :4], scale=1)
    frames = _gray(iio.imread(tiny, index=None))
    assert frames.shape == (estimate.shape[0], 3, 4)


@pytest.mark.parametrize("side, scale", [(64, 4), (128, 4), (129, 3), (256, 2), (300, 1)])
def test_the_default_scale_keeps_a_panel_within_512_pixels(tmp_path, side, scale):
    """At 4 a 256 x 256 capture of 150 sub-frames took 1 GB to encode; panels stay within GIF_PANEL."""
    estimate = np.random.default_rng(0).random((2, side, side // 2))
    frames = _gray(iio.imread(comparison_gif(tmp_path / "g.gif", None, estimate), index=None))
    assert frames.shape[2] == (side // 2) * scale and side * scale <= visual.GIF_PANEL


def test_comparison_gif_rejects_bad_input(tmp_path, cubes):
    truth, estimate = cubes
    path = tmp_path / "x.gif"
    with pytest.raises(ValueError, match="shape"):
        comparison_gif(path, truth[:-1], estimate)
    with pytest.raises(ValueError, match="fps"):
        comparison_gif(path, truth, estimate, fps=0)
    with pytest.raises(ValueError, match="scale"):
        comparison_gif(path, truth, estimate, scale=0)
    with pytest.raises(ValueError, match="estimate"):
        comparison_gif(path, None, np.full((2, 3, 3), np.inf))
    assert list(tmp_path.iterdir()) == []


def test_channel_titles():
    t_r = 1e-5
    rig = Rig(
        [
            Camera(0, t_e=3e-5, t_r=t_r),
            Camera(90, t_e=3e-5, t_r=t_r, frames=2, t_d=1e-4),
            Camera(t_e=3e-5, t_r=t_r, row_map=np.zeros((4, 5))),
        ],
        (4, 5),
    )
    assert channel_titles(rig) == [
        "camera 0 (0°)",
        "camera 1 (90°) frame 0",
        "camera 1 (90°) frame 1",
        "camera 2 (row map)",
    ]


def test_snapshot_montage(tmp_path):
    rig = Rig.paper_array(3, shape=(12, 16))
    snaps = np.random.default_rng(10).uniform(size=(3, 12, 16))
    path = snapshot_montage(tmp_path / "snaps.png", snaps, rig=rig)
    image = iio.imread(path)
    assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 300
    assert sorted(p.name for p in tmp_path.iterdir()) == ["snaps.png"]
    snapshot_montage(tmp_path / "titled.png", snaps, titles=["a", "b", "c"])
    assert iio.imread(tmp_path / "titled.png").ndim == 3
    with pytest.raises(ValueError, match="titles"):
        snapshot_montage(tmp_path / "bad.png", snaps, titles=["a"])
    with pytest.raises(ValueError, match="rig"):
        snapshot_montage(tmp_path / "bad.png", snaps[:2], rig=rig)
    assert not (tmp_path / "bad.png").exists()


def test_datacube_montage(tmp_path, cubes):
    truth, estimate = cubes
    with_truth = iio.imread(datacube_montage(tmp_path / "both.png", estimate, truth=truth, every=2))
    alone = iio.imread(datacube_montage(tmp_path / "alone.png", estimate, every=2))
    assert with_truth.ndim == 3 and alone.ndim == 3
    assert with_truth.shape[0] > alone.shape[0]  # the truth row adds height
    wrapped = iio.imread(datacube_montage(tmp_path / "wrap.png", estimate, every=1, max_columns=3))
    assert wrapped.shape[0] > alone.shape[0]  # 6 panels on 2 rows
    with pytest.raises(ValueError, match="truth"):
        datacube_montage(tmp_path / "bad.png", estimate, truth=truth[:, :-1])
    with pytest.raises(ValueError, match="every"):
        datacube_montage(tmp_path / "bad.png", estimate, every=0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["alone.png", "both.png", "wrap.png"]


def test_a_gif_that_cannot_be_written_fails_once_and_leaves_nothing(tmp_path, cubes, monkeypatch):
    # a full disk: one OSError from the write, no second failure when the encoder is collected, no file
    import errno
    import gc
    import pathlib
    import sys

    truth, estimate = cubes

    def full(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    unraisable = []
    monkeypatch.setattr(pathlib.Path, "write_bytes", full)
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)
    with pytest.raises(OSError, match="No space left"):
        comparison_gif(tmp_path / "rec.gif", truth, estimate)
    gc.collect()
    assert unraisable == [] and list(tmp_path.iterdir()) == []
