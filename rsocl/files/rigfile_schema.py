"""The tables of a rig file checked against its schema and normalised (see :mod:`rsocl.files.rigfile`).

Every error is a :class:`ValueError` naming the table and key (``camera[2].t_e``); times are
seconds, angles degrees, shapes and ROIs pixels.
"""

from __future__ import annotations

import difflib
import numbers
import os
from pathlib import Path

import numpy as np

from rsocl.common import validation as check
from rsocl.common.memory import check_npy_size
from rsocl.model.rig import Camera
from rsocl.model.row_map import row_map_from_homography

__all__ = [
    "RIG_KEYS",
    "CAMERA_KEYS",
    "MISPLACED_CONFIG_KEYS",
    "check_rig_table",
    "closest",
    "check_camera",
    "resolve_path",
    "to_camera",
]

#: Keys of the ``[rig]`` table.
RIG_KEYS = ("shape", "dt", "mask")
#: Keys of a ``[[camera]]`` table, in the order a rig file is written.
CAMERA_KEYS = (
    "backend",
    "name",
    "address",
    "angle",
    "row_map_file",
    "homography",
    "t_e",
    "t_r",
    "t_a",
    "t_d",
    "frames",
    "gain",
    "roi",
    "pixel_format",
    "config",
)
_GEOMETRY = ("angle", "row_map_file", "homography", "row_map")
#: Keys refused in a ``[camera.config]`` table, with the table they belong in: the model reads them
#: from ``[rig]`` and ``[[camera]]`` only (a simulated camera would render with a config ``angle``
#: while the capture records the camera's own).
MISPLACED_CONFIG_KEYS = {
    **{key: "[rig]" for key in RIG_KEYS},
    **{
        key: "[[camera]]"
        for key in (
            "angle",
            "row_map_file",
            "row_map",
            "homography",
            "t_e",
            "t_r",
            "t_a",
            "t_d",
            "frames",
            "gain",
            "roi",
        )
    },
}
#: Keys the rig file fills in for a ``simulated`` camera from the rig itself; refused in its config.
RIG_FILLED_KEYS = ("scene_frames", "index")


def _where(i, key):
    return f"camera[{i}].{key}"


def _int_list(name, value, length, minimum):
    if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != length:
        raise ValueError(f"{name} must be a list of {length} integers, got {value!r}")
    out = []
    for j, v in enumerate(value):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Integral) or v < minimum[j]:
            raise ValueError(f"{name}[{j}] must be an integer >= {minimum[j]}, got {v!r}")
        out.append(int(v))
    return out


def closest(unknown, known) -> str:
    """`` ('KEY': did you mean 'NEAR'?)`` for each of the ``unknown`` keys with a close one in ``known``
    (``difflib.get_close_matches``), or ``""``."""
    close = {key: difflib.get_close_matches(str(key), list(known), n=1) for key in unknown}
    return "".join(f" ({key!r}: did you mean {close[key][0]!r}?)" for key in unknown if close[key])


def check_rig_table(rig) -> dict:
    """The ``[rig]`` table normalised: ``shape`` (tuple of 2 ints), ``dt`` (seconds or None), ``mask``."""
    if not isinstance(rig, dict):
        raise ValueError(f"[rig] must be a table, got {rig!r}")
    unknown = sorted(set(rig) - set(RIG_KEYS))
    for key in unknown:
        if key in CAMERA_KEYS:
            raise ValueError(f"rig.{key} belongs in each [[camera]] table (camera[i].{key} = ...), not in [rig]")
    if unknown:
        raise ValueError(f"[rig] has unknown key(s) {unknown}{closest(unknown, RIG_KEYS)}; known: {list(RIG_KEYS)}")
    if "shape" not in rig:
        raise ValueError("rig.shape = [m, n] (rows, columns of the reference ROI, pixels) is required")
    out: dict = {"shape": tuple(_int_list("rig.shape", rig["shape"], 2, (1, 1)))}
    out["dt"] = None if rig.get("dt") is None else check.positive("rig.dt", rig["dt"], "seconds")
    out["mask"] = check.choice("rig.mask", rig.get("mask", "exact"), {"exact", "binary"})
    return out


def check_camera(i, cam, shape, base_dir):
    """A normalised copy of camera table ``i`` (raises ValueError naming ``camera[i].key``)."""
    if not isinstance(cam, dict):
        raise ValueError(f"camera[{i}] must be a table, got {cam!r}")
    unknown = sorted(set(cam) - set(CAMERA_KEYS) - {"row_map"})
    for key in unknown:
        if key in RIG_KEYS:
            raise ValueError(
                f"{_where(i, key)} belongs in the [rig] table (rig.{key} = ...), not in [[camera]]; "
                "it is the same for every camera"
            )
    if unknown:
        raise ValueError(
            f"camera[{i}] has unknown key(s) {unknown}{closest(unknown, CAMERA_KEYS)}; known: {list(CAMERA_KEYS)}; the "
            "backend's own settings go in its [camera.config] table"
        )
    out = {}
    backend = cam.get("backend")
    if not isinstance(backend, str) or not backend:
        raise ValueError(f"{_where(i, 'backend')} (camera plugin name, e.g. 'simulated') is required, got {backend!r}")
    out["backend"] = backend
    if cam.get("name") is not None:
        if not isinstance(cam["name"], str):
            raise ValueError(f"{_where(i, 'name')} must be a string, got {cam['name']!r}")
        out["name"] = cam["name"]
    config = cam.get("config", {})
    if not isinstance(config, dict):
        raise ValueError(f"{_where(i, 'config')} must be a table of backend settings, got {config!r}")
    config = dict(config)
    _check_config_keys(i, config, backend)
    if cam.get("address") is not None:
        if "address" in config:
            raise ValueError(f"camera[{i}]: give 'address' or 'config.address', not both")
        config["address"] = cam["address"]
    out["config"] = config

    geometry = [key for key in _GEOMETRY if cam.get(key) is not None]
    if "row_map_file" in geometry and "row_map" in geometry:
        geometry.remove("row_map")  # the array loaded from that file: reload it
    if len(geometry) > 1:
        raise ValueError(f"camera[{i}]: give only one of 'angle', 'row_map_file', 'homography'; got {geometry}")
    if "angle" in geometry:
        out["angle"] = check.finite(_where(i, "angle"), cam["angle"])
    elif "homography" in geometry:
        H = cam["homography"]
        try:
            array = np.asarray(H, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{_where(i, 'homography')} must be a 3x3 list of numbers, got {H!r}") from None
        _check_invertible(i, array)
        out["homography"] = array.tolist()  # its row map is checked with the roi, below
    elif "row_map_file" in geometry:
        name = cam["row_map_file"]
        if not isinstance(name, (str, os.PathLike)):
            raise ValueError(f"{_where(i, 'row_map_file')} must be a path string, got {name!r}")
        out["row_map_file"] = os.fspath(name)
        out["row_map"] = _load_row_map(i, _inside(i, name, base_dir), shape)
    elif "row_map" in geometry:  # built in Python, written as a .npy file by save_rigfile
        out["row_map"] = _check_row_map(i, "row_map", cam["row_map"], shape)

    for key, required, default in (
        ("t_e", True, None),
        ("t_r", True, None),
        ("t_a", False, 0.0),
        ("gain", False, 1.0),
        ("t_d", False, None),
    ):
        value = cam.get(key)
        if value is None:
            if required:
                raise ValueError(f"{_where(i, key)} is required (seconds)")
            if default is not None:
                out[key] = default
            continue
        if key == "t_a":
            out[key] = check.non_negative(_where(i, key), value, "seconds")
        else:
            out[key] = check.positive(_where(i, key), value, "" if key == "gain" else "seconds")
    out["frames"] = check.positive_int(_where(i, "frames"), cam.get("frames", 1))
    if cam.get("roi") is not None:
        out["roi"] = _int_list(_where(i, "roi") + " ([x, y, width, height])", cam["roi"], 4, (0, 0, 1, 1))
    if cam.get("pixel_format") is not None:
        if not isinstance(cam["pixel_format"], str):
            raise ValueError(f"{_where(i, 'pixel_format')} must be a string, got {cam['pixel_format']!r}")
        out["pixel_format"] = cam["pixel_format"]
    if out.get("homography") is not None:
        try:
            homography_row_map(out, shape)
        except ValueError as exc:
            raise ValueError(f"{_where(i, 'homography')}: {exc}") from None
    try:
        to_camera(out)
    except ValueError as exc:
        raise ValueError(f"camera[{i}]: {exc}") from None
    return out


def _check_invertible(i, H):
    """Refuse a singular 3x3 homography (it maps the plane onto a line), naming ``camera[i].homography``;
    the calibration's test. Other shapes and NaN are left to the row map's own check."""
    if H.shape != (3, 3) or not np.all(np.isfinite(H)):
        return
    det = float(np.linalg.det(H))
    if abs(det) < 1e-12 * max(1.0, float(np.abs(H).max())) ** 3:
        raise ValueError(
            f"{_where(i, 'homography')} is singular (determinant {det:.3g}): it maps the reference grid onto "
            "a line; a camera's homography must be invertible (rsocl calibrate measures it)"
        )


def _check_config_keys(i, config, backend):
    """Refuse model keys put in ``[camera.config]``, naming the table each belongs in."""
    for key in config:
        table = MISPLACED_CONFIG_KEYS.get(key)
        if table is not None:
            where = f"rig.{key}" if table == "[rig]" else _where(i, key)
            raise ValueError(
                f"{_where(i, 'config')}.{key} belongs in the {table} table ({where} = ...), not in "
                "[camera.config]; move it there"
            )
        if backend == "simulated" and key in RIG_FILLED_KEYS:
            raise ValueError(
                f"{_where(i, 'config')}.{key} is set from the rig (its sub-frames T and the camera's "
                "order) for every simulated camera; leave it out"
            )


def resolve_path(name, base_dir) -> Path:
    """``name`` relative to ``base_dir`` (the rig file's folder), unless absolute or ``base_dir`` is None."""
    path = Path(os.fspath(name))
    return path if path.is_absolute() or base_dir is None else Path(base_dir) / path


def _inside(i, name, base_dir) -> Path:
    """``row_map_file`` ``name`` resolved inside ``base_dir`` (the rig file's folder, or below it);
    an absolute path or one that leaves the folder (``..``, a link out) is refused naming the key."""
    path = Path(os.fspath(name))
    if base_dir is None:
        return path
    if path.is_absolute():
        raise ValueError(
            f"{_where(i, 'row_map_file')} must be a path relative to the rig file's folder, "
            f"got the absolute path {str(name)!r}"
        )
    base = Path(base_dir).resolve()
    full = (base / path).resolve()
    if full != base and base not in full.parents:
        raise ValueError(
            f"{_where(i, 'row_map_file')} must name a file in the rig file's folder or below it, got {str(name)!r}"
        )
    return Path(base_dir) / path


def _check_row_map(i, key, array, shape):
    array = check.finite_array(_where(i, key), array).astype(np.float64)
    if array.shape != tuple(shape):
        raise ValueError(f"{_where(i, key)} has shape {array.shape}, the rig's shape is {tuple(shape)}")
    if array.min() < 0:
        raise ValueError(f"{_where(i, key)} values must be >= 0 rows, got minimum {array.min()!r}")
    return array


def _load_row_map(i, path, shape):
    if not path.is_file():
        raise ValueError(f"{_where(i, 'row_map_file')}: file {str(path)!r} does not exist")
    check_npy_size(_where(i, "row_map_file"), path)
    try:
        array = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:  # EOFError: an empty file
        raise ValueError(f"{_where(i, 'row_map_file')}: {str(path)!r} is not a readable .npy array ({exc})") from None
    return _check_row_map(i, "row_map_file", array, shape)


def homography_row_map(cam, shape) -> np.ndarray:
    """The row map of a normalised camera dict's ``homography`` on a grid of ``shape``: the sensor row of each
    reference pixel less the first row the camera reads, the top row of its ``roi`` (0 without one)."""
    first_row = cam["roi"][1] if cam.get("roi") is not None else 0
    return row_map_from_homography(cam["homography"], shape, first_row)


def to_camera(cam, shape=None) -> Camera:
    """The :class:`~rsocl.model.rig.Camera` of a normalised camera dict."""
    row_map = cam.get("row_map")
    if cam.get("homography") is not None and shape is not None:
        row_map = homography_row_map(cam, shape)
    angle = cam.get("angle", 0.0)
    return Camera(
        angle,
        t_e=cam["t_e"],
        t_r=cam["t_r"],
        t_a=cam.get("t_a", 0.0),
        t_d=cam.get("t_d"),
        gain=cam.get("gain", 1.0),
        frames=cam.get("frames", 1),
        row_map=row_map,
    )
