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
in the rig file gives their offset on the sensor). ``--flat`` also takes an ``rsocl capture`` file
(HDF5: ``.h5``, ``.hdf5``, ``.hdf``, ``.he5``, or any file of HDF5's signature): its raw frames are
converted to one unit for every camera (:func:`load_flats`); the frames of other files must be in one
unit for all cameras (raw levels of cameras of one bit depth, or ``DN / (2**bit_depth - 1)``), and raw
levels of cameras of different bit depths are refused.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["NEEDS", "check_needs", "load_frames", "load_flats", "one_frame", "parse_points", "per_camera"]

#: The files of a folder that :func:`load_frames` reads as frames.
IMAGE_SUFFIXES = (".npy", ".png", ".tif", ".tiff")


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


def _is_hdf5(path) -> bool:
    """Whether ``path`` names an HDF5 file: by its suffix (:data:`~rsocl.files.hdf5_header.HDF5_SUFFIXES`), or
    by its signature whatever its suffix."""
    import h5py

    from rsocl.files.hdf5_header import HDF5_SUFFIXES

    path = Path(os.fspath(path))
    return path.suffix.lower() in HDF5_SUFFIXES or (path.is_file() and h5py.is_hdf5(path))


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
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
        if not files:
            raise ValueError(f"{what}: folder {str(path)!r} holds no {', '.join(IMAGE_SUFFIXES)} file")
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
    elif path.suffix.lower() in IMAGE_SUFFIXES:
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


#: The options that act only with a measurement's input, by that input: given without it, they are
#: refused rather than ignored (an option at its default value is not counted as given).
NEEDS = {
    "--frames": ("--markers-ref", "--identify", "--mirrored", "--polarity", "--threshold", "--png", "--force"),
    "--flicker": ("--flicker-hz", "--tolerance", "--force"),
    "--flat": ("--dark",),
}


def check_needs(args, parser_defaults: dict) -> None:
    """Refuse options that act only with a measurement whose input (:data:`NEEDS`) is not given, naming
    them and the input; ``parser_defaults`` maps each option's destination to its default. An option that
    acts with several inputs (``--force``) is refused when none of them is given."""
    inputs_of: dict = {}
    for needed, options in NEEDS.items():
        for option in options:
            inputs_of.setdefault(option, []).append(needed)
    present = {needed for needed in NEEDS if getattr(args, _dest(needed)) is not None}
    what = {"--frames": "frames of the marker target", "--flicker": "frames of the flickering light"}
    for options in NEEDS.values():
        given = [
            o
            for o in options
            if getattr(args, _dest(o)) != parser_defaults.get(_dest(o)) and not present & set(inputs_of[o])
        ]
        if given:
            inputs = inputs_of[given[0]]
            given = [o for o in given if inputs_of[o] == inputs]
            one = len(given) == 1
            raise ValueError(
                f"{', '.join(given)} {'needs' if one else 'need'} {' or '.join(inputs)} "
                f"({' or '.join(what.get(i, 'flat-field frames') for i in inputs)}); "
                f"without {'it' if len(inputs) == 1 else 'them'} {'it does' if one else 'they do'} nothing"
            )


def _dest(option: str) -> str:
    return option.lstrip("-").replace("-", "_")


#: Bits per pixel of the pixel formats a rig file names (a float format has none).
_FORMAT_BITS = {
    **{"Mono8": 8, "Mono10": 10, "Mono12": 12, "Mono14": 14, "Mono16": 16},  # aravis, simulated
    **{"GREY": 8, "Y10": 10, "Y12": 12, "Y16": 16, "YUYV": 8},  # v4l2
}


def _bit_depth(camera: dict):
    """The bit depth camera table ``camera`` delivers, as the rig file tells it (None: unknown or float)."""
    bits = _FORMAT_BITS.get(camera.get("pixel_format") or camera["config"].get("pixel_format"))
    sensor = camera["config"].get("sensor") if camera["backend"] == "simulated" else None
    if isinstance(sensor, dict) and sensor.get("bit_depth") is not None:
        bits = int(sensor["bit_depth"])
    return bits


def load_flats(path, rigfile, dark: float):
    """Flat-field frames of every camera in one unit, and the dark level in it, for ``--flat``.

    Parameters
    ----------
    path : str or os.PathLike
        An ``rsocl capture`` file (``.h5``) or a file or folder of :func:`load_frames`.
    rigfile : RigFile
        The rig being calibrated (its cameras, their pixel formats).
    dark : float
        ``--dark``: in the frames' units; for a capture file, a fraction of full scale.

    Returns
    -------
    (frames, darks, saturation) : (list of ndarray, ndarray of float64, list of float or None)
        Per camera. A capture file's raw frames are converted as the capture converts them
        (``raw / (2**bit_depth - 1) * full_scale``, model units) and divided by the camera's white level
        (``t_e / dt``; binary mask: :func:`rsocl.model.curvature.white_levels`), so their levels are
        ``gain * light`` whatever the bit depth and exposure.
        Other frames are taken as they are: they must be in one unit for every camera.
        ``saturation`` is the level, in the frames' units, at or above which a pixel is clipped: half a level
        below the top raw level (``2**bit_depth - 1``) of integer frames whose bit depth the capture file or
        the rig file gives and which they do not exceed; None where it is unknown (float frames).

    Raises
    ------
    ValueError
        Integer levels (raw DN) from cameras the rig file gives different bit depths: gains from them
        would be off by ``2**`` the difference.
    """
    C = len(rigfile.cameras)
    if not _is_hdf5(path):
        frames = per_camera(load_frames(path, "--flat")[0], C, "--flat")
        bits = [_bit_depth(camera) for camera in rigfile.cameras]
        integer = [bool(np.array_equal(f, np.round(f))) for f in frames]  # raw levels
        tops = [
            None if b is None or not i or f.max() > 2**b - 1 else 2**b - 1.5 for b, i, f in zip(bits, integer, frames)
        ]
        if len({b for b in bits if b is not None}) > 1 and all(integer):
            depths = ", ".join(f"camera {c}: {b}" for c, b in enumerate(bits) if b is not None)
            raise ValueError(
                f"--flat: the cameras deliver different bit depths ({depths}) and the frames hold raw levels, "
                "which would put 2**(the difference) into the gains; give the rsocl capture file (.h5) of the "
                "flat field, or frames in one unit for all cameras (DN / (2**bit_depth - 1))"
            )
        return frames, np.full(C, dark), tops
    from rsocl.files.hdf5 import load_capture_rig
    from rsocl.hardware.capture_raw import load_raw
    from rsocl.model.curvature import white_levels

    raw, rig = load_raw(path), load_capture_rig(path)
    if not any(f.size for f in raw.frames):
        raise ValueError(
            f"--flat: {path} holds no raw frames (a capture from rsocl simulate keeps snapshots only): give "
            "one from rsocl capture, or an image per camera"
        )
    if raw.sets_complete < 1:
        raise ValueError(
            f"--flat: {path} holds no complete set (capture status {raw.status!r}): its frames are not a flat "
            "field to trust; capture the flat field again"
        )
    kept = [np.asarray(s) < raw.sets_complete for s in raw.sets]  # the frames of complete sets only
    frames = per_camera([f[k] for f, k in zip(raw.frames, kept)], C, "--flat")
    missing = [c for c, f in enumerate(frames) if not len(f)]
    if missing:
        raise ValueError(f"--flat: {path} holds no frame of a complete set from camera(s) {missing}")
    metas_kept = [[m for m, keep in zip(metas, k) if keep] for metas, k in zip(raw.frame_meta, kept)]
    out, darks, tops = [], [], []
    for c, (frame, metas) in enumerate(zip(frames, metas_kept)):
        exposure = white_levels(rig)[c]  # the white scene's level, as the capture converts frames
        full_scale = float(metas[0].get("full_scale") or exposure)
        top = None
        if frame.dtype.kind in "biu":
            levels = 2 ** int(metas[0]["bit_depth"]) - 1
            value = frame.astype(np.float64) * (full_scale / levels)
            top = (levels - 0.5) * (full_scale / levels) / exposure
        else:
            value = frame.astype(np.float64)
        out.append(value / exposure)
        darks.append(dark * full_scale / exposure)
        tops.append(top)
    return out, np.asarray(darks), tops
