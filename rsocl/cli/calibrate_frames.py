"""The frame files ``rsocl calibrate`` reads (:mod:`rsocl.cli.calibrate`): markers, flicker and flat fields.

File layouts (``FRAMES`` for ``--frames``, ``--flicker`` and ``--flat``):

* ``.npz``: key ``frames`` holding a ``(C, rows, columns)`` array (or
  ``(C, K, rows, columns)``: ``K`` frames per camera), or keys ``camera0``,
  ``camera1``, ... one per camera (sizes may differ). For ``--frames`` an
  optional key ``markers`` ``(C, N, 2)`` gives the markers' ``(x, y)`` in
  each frame instead of detecting them, in the order of ``--markers-ref``;
* ``.npy``: one array as for the ``frames`` key; for ``--flicker`` a single
  2-D frame applies to every camera;
* a folder: one file per camera (``.npy``, ``.png``, ``.tif``, ``.tiff``),
  in name order.

Frames are raw sensor images after the camera's ROI (``roi = [x, y, w, h]``
in the rig file gives their offset on the sensor).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["load_frames", "one_frame", "parse_points", "per_camera"]

_IMAGE_SUFFIXES = (".npy", ".png", ".tif", ".tiff")


def parse_points(tokens) -> np.ndarray:
    """``["x,y", "x,y x,y", ...]`` -> ``(N, 2)`` float64 (points may also be separated by ';' or spaces)."""
    points = []
    for token in tokens:
        for item in str(token).replace(";", " ").split():
            parts = item.split(",")
            try:
                if len(parts) != 2:
                    raise ValueError
                points.append([float(parts[0]), float(parts[1])])
            except ValueError:
                raise ValueError(f"--markers-ref points must be 'x,y' pairs of numbers, got {item!r}") from None
    if not points:
        raise ValueError("--markers-ref needs at least 4 'x,y' points")
    out = np.asarray(points, dtype=np.float64)
    if not np.all(np.isfinite(out)):
        raise ValueError("--markers-ref points must be finite")
    return out


def _read_image(path: Path, what: str) -> np.ndarray:
    from rsocl.common.validation import reading

    if path.suffix.lower() == ".npy":
        with reading(what, path, "a .npy array"):
            array = np.load(path, allow_pickle=False)
        if not isinstance(array, np.ndarray):
            array.close()
            raise ValueError(f"{what}: {str(path)!r} is an .npz archive, not one NumPy array (.npy)")
        return array
    import warnings

    import imageio.v3 as iio

    with reading(what, path, "an image"), warnings.catch_warnings():
        # a file no plugin reads makes imageio try them all; its legacy ones warn of their own deprecation
        warnings.simplefilter("ignore", DeprecationWarning)
        image = np.asarray(iio.imread(path))
    if image.ndim == 3 and image.shape[-1] in (3, 4):  # colour image of a grey target
        image = image[..., :3].mean(axis=-1)
    return image


def load_frames(path, what="--frames"):
    """Read per-camera frames; returns ``(frames, extras)`` with ``extras`` the other .npz arrays.

    ``frames`` is a list with one float64 array per camera: ``(rows, columns)``
    or ``(K, rows, columns)``. A 2-D ``.npy`` gives a one-element list.
    """
    from rsocl.common.validation import reading

    path = Path(os.fspath(path))
    if not path.exists():
        raise FileNotFoundError(f"{what}: {str(path)!r} does not exist")
    extras = {}
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES and p.is_file())
        if not files:
            raise ValueError(f"{what}: folder {str(path)!r} holds no {', '.join(_IMAGE_SUFFIXES)} file")
        frames = [_read_image(p, what) for p in files]
    elif path.suffix.lower() == ".npz":
        with reading(what, path, "an .npz archive"):
            data = np.load(path, allow_pickle=False)
        if not hasattr(data, "files"):
            raise ValueError(f"{what}: {str(path)!r} holds one NumPy array (.npy), not an .npz archive")
        with data:
            keys = list(data.keys())

            def array(key):
                with reading(what, path, f"an .npz archive (array {key!r})"):
                    return np.asarray(data[key])

            if "frames" in keys:
                frames = list(array("frames"))
            else:
                cameras = sorted(
                    (k for k in keys if k.startswith("camera") and k[6:].isdigit()), key=lambda k: int(k[6:])
                )
                if not cameras:
                    raise ValueError(
                        f"{what}: {str(path)!r} has neither a 'frames' key nor 'camera0', 'camera1', ... (keys: {keys})"
                    )
                if [int(k[6:]) for k in cameras] != list(range(len(cameras))):
                    raise ValueError(
                        f"{what}: {str(path)!r} has keys {cameras}; expected camera0 .. camera{len(cameras) - 1}"
                    )
                frames = [array(k) for k in cameras]
            extras = {k: array(k) for k in keys if k != "frames" and not k.startswith("camera")}
    elif path.suffix.lower() in _IMAGE_SUFFIXES:
        array = _read_image(path, what)
        frames = [array] if array.ndim == 2 else list(array)
    else:
        raise ValueError(f"{what}: {str(path)!r} must be a .npz, .npy or image file, or a folder of them")
    out = []
    for c, frame in enumerate(frames):
        frame = np.asarray(frame)
        if frame.dtype.kind not in "biuf" or frame.ndim not in (2, 3) or 0 in frame.shape:
            raise ValueError(
                f"{what}: camera {c}: expected a real (rows, columns) frame or a (K, rows, columns) "
                f"stack, got {frame.dtype} array of shape {frame.shape}"
            )
        out.append(frame.astype(np.float64))
    return out, extras


def one_frame(frame: np.ndarray) -> np.ndarray:
    """A single frame: the mean of a stack (less noise), or the frame itself."""
    return frame.mean(axis=0) if frame.ndim == 3 else frame


def per_camera(frames, C, what):
    """``frames`` when it holds one entry per camera of the rig (``C``), else a ValueError naming ``what``."""
    if len(frames) != C:
        raise ValueError(f"{what}: the rig file has {C} cameras but {len(frames)} frame(s) were given")
    return frames
