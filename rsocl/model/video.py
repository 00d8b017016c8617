"""Video files read as they are stored: ``[frames, h, w]`` in the file's dtype, RGB made gray.

:func:`load_video` reads the files of :data:`VIDEO_SUFFIXES`; :mod:`rsocl.model.scenes` turns a
video into a datacube (:func:`rsocl.model.scenes.benchmark_protocol`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rsocl.common import validation as check
from rsocl.common.hints import PathLike
from rsocl.common.memory import check_npy_size

__all__ = ["load_video", "VIDEO_SUFFIXES"]

#: File name suffixes :func:`load_video` understands (lower case).
VIDEO_SUFFIXES = (".npz", ".npy", ".tif", ".tiff", ".gif")


def _to_frames(array: np.ndarray, source: str, *, rgb_last: bool) -> np.ndarray:
    """Check a ``[frames, h, w]`` stack; ``[frames, h, w, 3|4]`` (RGB/RGBA) becomes gray, in the input
    dtype (integer RGB goes through :func:`skimage.color.rgb2gray`, rounded back to its scale)."""
    if array.dtype.kind not in "uif":
        raise ValueError(f"{source}: video must hold real numbers (integer or float), got dtype {array.dtype}")
    if rgb_last and array.ndim == 4 and array.shape[-1] in (3, 4):
        array = _rgb_to_gray(array[..., :3])
    if array.ndim != 3:
        raise ValueError(
            f"{source}: video must be 3-D [frames, h, w] (or [frames, h, w, 3|4] RGB), "
            f"got {array.ndim}-D shape {array.shape}"
        )
    if 0 in array.shape:
        raise ValueError(f"{source}: video must not be empty, got shape {array.shape}")
    return array


def _rgb_to_gray(rgb: np.ndarray) -> np.ndarray:
    if np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 0], rgb[..., 2]):
        return np.ascontiguousarray(rgb[..., 0])  # already gray: exact
    from skimage.color import rgb2gray

    if rgb.dtype.kind in "ui":
        top = np.iinfo(rgb.dtype).max
        gray = rgb2gray(rgb.astype(np.float64) / top)
        return np.clip(np.rint(gray * top), 0, top).astype(rgb.dtype)
    return rgb2gray(rgb).astype(rgb.dtype)


def _read_tiff(path: Path) -> np.ndarray:
    import tifffile  # a dependency of scikit-image

    stacks = []
    with check.reading("path", path, "a TIFF video"):
        tif = tifffile.TiffFile(path)
    with tif:
        with check.reading("path", path, "a TIFF video"):
            all_series = list(tif.series)
        for series in all_series:
            with check.reading("path", path, "a TIFF video"):
                data = series.asarray()
            axes = series.axes
            if "S" in axes:  # samples (RGB) axis: move last, then gray
                data = np.moveaxis(data, axes.index("S"), -1)
                axes = axes.replace("S", "") + "S"
                if data.shape[-1] in (3, 4):
                    data = _rgb_to_gray(data[..., :3])
                elif data.shape[-1] == 1:
                    data = data[..., 0]
                else:
                    raise ValueError(f"{path}: TIFF has {data.shape[-1]} samples per pixel; expected 1, 3 or 4")
            if data.ndim < 2:
                raise ValueError(f"{path}: TIFF series with shape {data.shape} is not an image")
            stacks.append(data.reshape((-1,) + data.shape[-2:]))
    if not stacks:
        raise ValueError(f"{path}: TIFF holds no images")
    shapes = {s.shape[1:] for s in stacks}
    if len(shapes) != 1:
        raise ValueError(f"{path}: TIFF pages have different sizes {sorted(shapes)}; a video needs one frame size")
    return np.concatenate(stacks, axis=0)


def load_video(path: PathLike, *, key: str = "video") -> np.ndarray:
    """Read a video file as ``[frames, h, w]`` in its stored dtype.

    Supported files (by suffix, case-insensitive):

    - ``.npz``: the array stored under ``key``;
    - ``.npy``: the array in the file (``key`` is ignored);
    - ``.tif`` / ``.tiff``: every page of a multi-page TIFF, in order;
    - ``.gif``: every frame of an animated GIF.

    RGB or RGBA frames (a trailing axis of 3 or 4; for TIFF, the samples axis) are converted to gray
    with :func:`skimage.color.rgb2gray`, keeping the dtype (integers are rounded back to their
    scale; frames whose three channels are equal are taken as they are).

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    key : str
        Array name inside a ``.npz`` archive.

    Returns
    -------
    ndarray, shape (frames, h, w)
        The video, original dtype (e.g. uint8).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the suffix is not supported, the file cannot be read as its suffix
        says (empty, truncated, corrupt, a folder; the message names the file),
        ``key`` is missing from the archive, or the array is not
        ``[frames, h, w]`` (or RGB of that), is empty, or is not real-valued.
    """
    path = check.existing_file("path", path, "video file")
    suffix = path.suffix.lower()
    source = str(path)
    if suffix == ".npz":
        with check.reading("path", source, "an .npz video archive"):
            archive = np.load(path, allow_pickle=False)
        if not hasattr(archive, "files"):
            raise ValueError(f"path: {source!r} holds one NumPy array (.npy), not an .npz archive; name it .npy")
        with archive:
            if key not in archive.files:
                raise ValueError(f"key {key!r} not found in {source}; the archive holds {sorted(archive.files)}")
            check_npy_size("path", path, key)
            with check.reading("path", source, f"an .npz video archive (array {key!r})"):
                video = archive[key]
        return _to_frames(video, f"{source}[{key!r}]", rgb_last=True)
    if suffix == ".npy":
        check_npy_size("path", path)
        with check.reading("path", source, "a .npy video array"):
            video = np.load(path, allow_pickle=False)
        if not isinstance(video, np.ndarray):
            video.close()
            raise ValueError(f"path: {source!r} is an .npz archive, not one NumPy array (.npy); name it .npz")
        return _to_frames(video, source, rgb_last=True)
    if suffix in (".tif", ".tiff"):
        return _to_frames(_read_tiff(path), source, rgb_last=False)
    if suffix == ".gif":
        import imageio.v3 as iio

        with check.reading("path", source, "a GIF video"):
            video = np.asarray(iio.imread(path, index=None, plugin="pillow", extension=".gif"))
        if video.ndim == 2 or (video.ndim == 3 and video.shape[-1] in (3, 4)):
            video = video[None]  # a single frame
        return _to_frames(video, source, rgb_last=True)
    raise ValueError(
        f"path: unsupported video file suffix {path.suffix!r} ({source}); supported: {', '.join(VIDEO_SUFFIXES)}"
    )
