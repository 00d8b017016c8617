"""Scenes of ``benchmarks/quality.py``: the built-in scene and the shared videos at several motion speeds.

A video becomes a datacube of ``T`` sub-frames at ``frames_per_subframe`` source frames per
sub-frame (:func:`video_at_speed`): sub-frame ``s`` is the source at frame position
``s * frames_per_subframe``, linearly interpolated between frames, the video played forwards
then backwards when the positions run past its end (a runner of 40 frames covers 69 sub-frames
at 1 frame per sub-frame by turning back once). A crop of the source frames (a ROI) before the
resize to the grid multiplies the motion in pixels per sub-frame by the zoom.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rsocl.model.scenes import builtin_scene, load_video

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"

#: Crops ``(y, x, height, width)`` of the 256x256 source frames where the videos move most.
CROPS = {"runner40": (0, 0, 128, 128), "traffic48": (128, 64, 128, 128)}


def video_at_speed(video, shape, T, frames_per_subframe, crop=None) -> np.ndarray:
    """A ``(T, m, n)`` float32 datacube in [0, 1] from a ``(F, h, w)`` uint8 video.

    Parameters
    ----------
    video : ndarray, shape (F, h, w)
        Source frames (integers are divided by their dtype maximum).
    shape : (int, int)
        Grid ``(m, n)``, pixels.
    T : int
        Sub-frames.
    frames_per_subframe : float
        Source frames per sub-frame (> 0): the motion speed.
    crop : (y, x, height, width) or None
        Part of the source frames to resize to the grid.
    """
    from skimage.transform import resize

    video = np.asarray(video)
    if video.dtype.kind in "ui":
        video = video.astype(np.float64) / np.iinfo(video.dtype).max
    if crop is not None:
        y, x, h, w = crop
        video = video[:, y : y + h, x : x + w]
    F = video.shape[0]
    position = np.arange(T, dtype=np.float64) * float(frames_per_subframe)
    period = 2 * (F - 1)
    folded = np.mod(position, period)
    folded = np.where(folded > F - 1, period - folded, folded)  # forwards, then backwards
    lower = np.minimum(np.floor(folded).astype(np.int64), F - 2)
    fraction = folded - lower
    cache = {}

    def frame(i):
        if i not in cache:
            cache[i] = resize(video[i], shape, order=1, anti_aliasing=True, mode="reflect", preserve_range=True)
        return cache[i]

    out = np.empty((T,) + tuple(shape), dtype=np.float32)
    for s in range(T):
        i, f = int(lower[s]), float(fraction[s])
        out[s] = np.clip((1 - f) * frame(i) + f * frame(i + 1) if f > 0 else frame(i), 0.0, 1.0)
    return out


def scene_names():
    """Names of every scene, in report order (builtin first; a video's need ``../shared/data``)."""
    names = ["builtin", "builtin-slow", "builtin-fast"]
    for video in ("runner40", "traffic48"):
        names += [f"{video}@0.5", f"{video}@1", f"{video}@2", f"{video}-crop@1"]
    return names


def make_scene(name, shape, T) -> np.ndarray:
    """The datacube of scene ``name`` (see :func:`scene_names`) on an ``(m, n)`` grid with ``T`` sub-frames.

    ``builtin``: :func:`rsocl.model.scenes.builtin_scene`; ``builtin-slow``: the middle ``T`` of
    the same scene rendered on ``2T`` sub-frames (half the speed); ``builtin-fast``: the scene
    rendered on ``ceil(T/2)`` sub-frames, played forwards then backwards (twice the speed). ``VIDEO@k``: the whole
    frame at ``k`` source frames per sub-frame; ``VIDEO-crop@k``: the crop of :data:`CROPS`
    (2x zoom).
    """
    if name == "builtin":
        return builtin_scene(shape, T)
    if name == "builtin-slow":
        return builtin_scene(shape, 2 * T)[T // 2 : T // 2 + T]
    if name == "builtin-fast":
        half = builtin_scene(shape, (T + 1) // 2)
        return np.concatenate([half, half[::-1]])[:T]
    video, _, speed = name.partition("@")
    crop = CROPS[video[: -len("-crop")]] if video.endswith("-crop") else None
    path = video_path(name)
    if not path.exists():
        raise FileNotFoundError(f"scene {name!r} needs {path}")
    return video_at_speed(load_video(path), shape, T, float(speed), crop)


def video_path(name) -> Path | None:
    """The video file scene ``name`` is made from (``DATA/VIDEO.npz``), None for the built-in scenes."""
    if "@" not in name:
        return None
    return DATA / f"{name.partition('@')[0].removesuffix('-crop')}.npz"


def available(name) -> bool:
    """Whether scene ``name`` can be made here: a built-in scene, or a video found in ``../shared/data``."""
    path = video_path(name)
    return path is None or path.exists()


def noisy(g, rig, *, photons=1000.0, read=0.01, seed=0) -> np.ndarray:
    """Snapshots with shot noise (``photons`` photo-electrons at full scale) and Gaussian read
    noise (``read`` times full scale), the full scale being :func:`rsocl.model.simulate.full_scale`."""
    from rsocl.model.simulate import full_scale

    scale = full_scale(rig)
    rng = np.random.default_rng(seed)
    g = np.clip(np.asarray(g, dtype=np.float64), 0.0, None)
    return rng.poisson(g * (photons / scale)) * (scale / photons) + rng.normal(0.0, read * scale, g.shape)


def case_data(scene, rig, photons=None):
    """``(truth, g)``: the datacube of ``scene`` on ``rig``'s grid and its simulated snapshots, with
    :func:`noisy` noise at ``photons`` photo-electrons at full scale, 1 % read noise and seed 1 (None:
    noiseless)."""
    from rsocl.model.simulate import simulate

    truth = make_scene(scene, rig.shape, rig.T)
    g = simulate(truth, rig)
    if photons is not None:
        g = noisy(g, rig, photons=photons, read=0.01, seed=1)
    return truth, g
