"""The TOML rig file: the camera array, its timing and how to reach each camera.

Units: seconds for every time (``dt``, ``t_e``, ``t_r``, ``t_a``, ``t_d``),
degrees for ``angle``, pixels for ``shape`` and ``roi``.

Schema
------
.. code-block:: toml

    [rig]
    shape = [64, 64]          # rows m, columns n of the reference ROI (required)
    dt = 3.5e-05              # sub-frame duration, s (optional, default: smallest t_r)
    mask = "exact"            # "exact" (default) or "binary"

    [[camera]]                # one table per camera, in channel order (camera index 0, 1, ...)
    backend = "simulated"     # entry point name in the rsocl.cameras group (required)
    name = "left"             # optional label
    address = "10.0.0.2"      # optional shortcut for config.address
    angle = 90.0              # rotation, degrees; or one of:
    # row_map_file = "cam0_rows.npy"   (a .npy (m, n) row map, relative to the rig file)
    # homography = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]   (3x3, reference pixel -> sensor pixel)
    t_e = 1.8e-04             # exposure, s (required)
    t_r = 3.5e-05             # row readout time, s (required)
    t_a = 0.0                 # trigger offset, s (default 0)
    gain = 1.0                # photometric gain (default 1)
    roi = [0, 0, 64, 64]      # sensor ROI x, y, width, height (optional)
    pixel_format = "Mono16"   # optional
    # t_d, frames: multi-frame cameras (see rsocl.Camera)

    [camera.config]           # backend settings, passed to the backend as they are
    scene = "builtin"

Only one of ``angle``, ``row_map_file`` and ``homography`` may be given (none
means ``angle = 0``). A homography maps a reference pixel centre ``(x, y)``
(column, row; pixel centres at integer coordinates) to full-sensor coordinates
``(x', y')`` (before the ROI); the camera row of the pixel is ``y'``, shifted so
that the smallest over the reference ROI is 0 (MODEL.md). Content errors raise
:class:`ValueError` naming the file, the camera index and the key, e.g.
``rig.toml: camera[2].t_e must be > 0 seconds, got -1.0``.

TOML has no null: keys whose value is None are left out when writing.
"""

from __future__ import annotations

import math
import numbers
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rsocl.common import validation as check
from rsocl.files.atomic import atomic_path
from rsocl.model.rig import Camera, Rig, _snap

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["RigFile", "load_rigfile", "save_rigfile", "row_map_from_homography", "dumps_toml"]

RIG_KEYS = ("shape", "dt", "mask")
CAMERA_KEYS = ("backend", "name", "address", "angle", "row_map_file", "homography", "t_e", "t_r", "t_a", "t_d",
               "frames", "gain", "roi", "pixel_format", "config")
_GEOMETRY = ("angle", "row_map_file", "homography", "row_map")

#: Model keys the rig file passes on to ``simulated`` cameras (see :meth:`RigFile.backends`).
SIMULATED_MODEL_KEYS = ("shape", "dt", "mask", "t_e", "t_r", "t_a", "gain", "angle", "row_map", "scene_frames",
                        "index")


# ---------------------------------------------------------------------- homography
def row_map_from_homography(H, shape) -> np.ndarray:
    """Camera row ``r(y, x)`` (rows, float64, min 0) of a camera registered by homography ``H``.

    Parameters
    ----------
    H : array_like, shape (3, 3)
        Maps homogeneous reference pixel centres ``(x, y, 1)`` (column, row) to
        sensor coordinates ``(x', y', w)``; the sensor row is ``y'/w``.
    shape : (int, int)
        ``(m, n)`` of the reference ROI.

    Returns
    -------
    ndarray, shape (m, n)
        ``y'/w - min(y'/w)``; values within 1e-9 of an integer are snapped to
        it (as :meth:`rsocl.Camera.rows` does), so a rotation by a multiple of
        90 degrees gives exactly the row map of that ``angle``.

    Raises
    ------
    ValueError
        If ``H`` is not a finite 3x3 matrix, or the ROI crosses its horizon
        (``w`` is 0 somewhere or changes sign; ``H`` and ``-H`` are the same).
    """
    H = check.finite_array("homography", H).astype(np.float64)
    if H.shape != (3, 3):
        raise ValueError(f"homography must be a 3x3 matrix, got shape {H.shape}")
    m, n = shape
    y, x = np.mgrid[0:m, 0:n].astype(np.float64)
    w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    if np.all(w < 0):  # H and -H are the same homography
        H, w = -H, -w
    if not np.all(w > 0):
        raise ValueError("homography maps part of the reference ROI to infinity or behind the camera "
                         f"(w <= 0 at {int(np.count_nonzero(w <= 0))} pixel(s))")
    r = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w
    r = r - r.min()
    return _snap(r)


# ---------------------------------------------------------------------- validation
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


def _check_rig_table(rig):
    if not isinstance(rig, dict):
        raise ValueError(f"[rig] must be a table, got {rig!r}")
    unknown = sorted(set(rig) - set(RIG_KEYS))
    if unknown:
        raise ValueError(f"[rig] has unknown key(s) {unknown}; known: {list(RIG_KEYS)}")
    if "shape" not in rig:
        raise ValueError("rig.shape = [m, n] (rows, columns of the reference ROI, pixels) is required")
    out = {"shape": tuple(_int_list("rig.shape", rig["shape"], 2, (1, 1)))}
    out["dt"] = None if rig.get("dt") is None else check.positive("rig.dt", rig["dt"], "seconds")
    out["mask"] = check.choice("rig.mask", rig.get("mask", "exact"), {"exact", "binary"})
    return out


def _check_camera(i, cam, shape, base_dir):
    """A normalised copy of camera table ``i`` (raises ValueError naming ``camera[i].key``)."""
    if not isinstance(cam, dict):
        raise ValueError(f"camera[{i}] must be a table, got {cam!r}")
    unknown = sorted(set(cam) - set(CAMERA_KEYS) - {"row_map"})
    if unknown:
        raise ValueError(f"camera[{i}] has unknown key(s) {unknown}; known: {list(CAMERA_KEYS)}")
    out = {}
    backend = cam.get("backend")
    if not isinstance(backend, str) or not backend:
        raise ValueError(f"{_where(i, 'backend')} (camera plugin name, e.g. 'simulated') is required, got "
                         f"{backend!r}")
    out["backend"] = backend
    if cam.get("name") is not None:
        if not isinstance(cam["name"], str):
            raise ValueError(f"{_where(i, 'name')} must be a string, got {cam['name']!r}")
        out["name"] = cam["name"]
    config = cam.get("config", {})
    if not isinstance(config, dict):
        raise ValueError(f"{_where(i, 'config')} must be a table of backend settings, got {config!r}")
    config = dict(config)
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
        try:
            row_map_from_homography(array, shape)
        except ValueError as exc:
            raise ValueError(f"{_where(i, 'homography')}: {exc}") from None
        out["homography"] = array.tolist()
    elif "row_map_file" in geometry:
        name = cam["row_map_file"]
        if not isinstance(name, (str, os.PathLike)):
            raise ValueError(f"{_where(i, 'row_map_file')} must be a path string, got {name!r}")
        out["row_map_file"] = os.fspath(name)
        out["row_map"] = _load_row_map(i, _resolve(name, base_dir), shape)
    elif "row_map" in geometry:  # built in Python, written as a .npy file by save_rigfile
        out["row_map"] = _check_row_map(i, "row_map", cam["row_map"], shape)

    for key, required, default in (("t_e", True, None), ("t_r", True, None), ("t_a", False, 0.0),
                                   ("gain", False, 1.0), ("t_d", False, None)):
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
    try:
        _camera(out)
    except ValueError as exc:
        raise ValueError(f"camera[{i}]: {exc}") from None
    return out


def _resolve(name, base_dir):
    path = Path(os.fspath(name))
    return path if path.is_absolute() or base_dir is None else Path(base_dir) / path


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
    try:
        array = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{_where(i, 'row_map_file')}: {str(path)!r} is not a readable .npy array ({exc})") from None
    return _check_row_map(i, "row_map_file", array, shape)


def _camera(cam, shape=None) -> Camera:
    """The :class:`~rsocl.model.rig.Camera` of a normalised camera dict."""
    row_map = cam.get("row_map")
    if cam.get("homography") is not None and shape is not None:
        row_map = row_map_from_homography(cam["homography"], shape)
    angle = cam.get("angle", 0.0)
    return Camera(angle, t_e=cam["t_e"], t_r=cam["t_r"], t_a=cam.get("t_a", 0.0), t_d=cam.get("t_d"),
                  gain=cam.get("gain", 1.0), frames=cam.get("frames", 1), row_map=row_map)


# ---------------------------------------------------------------------- RigFile
@dataclass
class RigFile:
    """The content of a rig file.

    Attributes
    ----------
    shape : (int, int)
        ``(m, n)`` of the reference ROI, pixels.
    cameras : list of dict
        One dict per ``[[camera]]`` table (keys of the schema; ``config`` is a
        dict). A camera may hold a ``row_map`` array instead of a
        ``row_map_file`` (written as a .npy file by :func:`save_rigfile`).
    dt : float or None
        Sub-frame duration, seconds (None: the smallest ``t_r``).
    mask : str
        ``"exact"`` or ``"binary"``.
    path : Path or None
        The file it was loaded from; ``row_map_file`` names are relative to its folder.
    """

    shape: tuple
    cameras: list = field(default_factory=list)
    dt: float | None = None
    mask: str = "exact"
    path: Path | None = None

    def __post_init__(self):
        rig = _check_rig_table({"shape": list(self.shape), "dt": self.dt, "mask": self.mask})
        self.shape, self.dt, self.mask = rig["shape"], rig["dt"], rig["mask"]
        if not isinstance(self.cameras, (list, tuple)) or not self.cameras:
            raise ValueError("cameras must hold at least one [[camera]] table")
        if self.path is not None:
            self.path = Path(os.fspath(self.path))
        base = self.path.parent if self.path is not None else None
        self.cameras = [_check_camera(i, dict(cam), self.shape, base) for i, cam in enumerate(self.cameras)]
        self.rig()  # whole-rig checks (dt >= t_r, multi-frame t_d)

    # ------------------------------------------------------------------ views
    def camera(self, index: int) -> Camera:
        """The :class:`~rsocl.model.rig.Camera` of camera ``index``."""
        return _camera(self.cameras[index], self.shape)

    def rig(self) -> Rig:
        """The :class:`~rsocl.model.rig.Rig` this file describes."""
        cams = [self.camera(i) for i in range(len(self.cameras))]
        return Rig(cams, self.shape, dt=self.dt, mask=self.mask)

    def homography(self, index: int):
        """The 3x3 homography (reference -> sensor) of camera ``index``, or None."""
        H = self.cameras[index].get("homography")
        return None if H is None else np.asarray(H, dtype=np.float64)

    def backends(self) -> list:
        """``[(backend name, config dict)]``, one per camera, in camera order.

        ``config`` is a copy of the camera's ``[camera.config]`` table (plus
        ``address``). A ``simulated`` camera is a model of the rig itself, so its
        config also receives, where it does not set them, the model keys
        :data:`SIMULATED_MODEL_KEYS`: ``shape``, ``dt``, ``mask``, ``t_e``,
        ``t_r``, ``t_a``, ``gain``, ``angle`` or ``row_map``, ``scene_frames``
        (the rig's ``T``, so every camera sees the same datacube) and ``index``.
        """
        rig = self.rig()
        out = []
        for i, cam in enumerate(self.cameras):
            config = dict(cam["config"])
            if cam["backend"] == "simulated":
                model = {"shape": list(self.shape), "dt": rig.dt, "mask": rig.mask, "t_e": cam["t_e"],
                         "t_r": cam["t_r"], "t_a": cam.get("t_a", 0.0), "gain": cam.get("gain", 1.0),
                         "scene_frames": rig.T, "index": i}
                if "angle" not in config and "row_map" not in config:
                    if rig.cameras[i].row_map is not None:
                        model["row_map"] = rig.row_map(i)
                    else:
                        model["angle"] = rig.cameras[i].angle
                for key, value in model.items():
                    config.setdefault(key, value)
            out.append((cam["backend"], config))
        return out

    @classmethod
    def from_rig(cls, rig: Rig, backend="simulated", configs=None) -> "RigFile":
        """A rig file for ``rig`` with every camera on ``backend`` (``configs``: one config dict per camera)."""
        if configs is None:
            configs = [{} for _ in rig.cameras]
        if len(configs) != rig.C:
            raise ValueError(f"configs must hold one dict per camera ({rig.C}), got {len(configs)}")
        cameras = []
        for cam, config in zip(rig.cameras, configs):
            d = {"backend": backend, "t_e": cam.t_e, "t_r": cam.t_r, "t_a": cam.t_a, "gain": cam.gain,
                 "config": dict(config or {})}
            if cam.frames > 1:
                d.update(frames=cam.frames, t_d=cam.t_d)
            if cam.row_map is not None:
                d["row_map"] = cam.row_map
            else:
                d["angle"] = cam.angle
            cameras.append(d)
        return cls(shape=rig.shape, cameras=cameras, dt=rig.dt, mask=rig.mask)


# ---------------------------------------------------------------------- files
def load_rigfile(path) -> RigFile:
    """Read and check a TOML rig file (see the module docstring for the schema).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is not valid TOML or its content breaks the schema; the message
        names the file, the camera index and the key.
    """
    path = Path(os.fspath(path))
    if not path.is_file():
        raise FileNotFoundError(f"rig file {str(path)!r} does not exist")
    try:
        with open(path, "rb") as handle:
            data = tomllib.load(handle)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None
    try:
        unknown = sorted(set(data) - {"rig", "camera"})
        if unknown:
            raise ValueError(f"unknown top-level key(s) {unknown}; expected [rig] and [[camera]] tables")
        if "rig" not in data:
            raise ValueError("the [rig] table (shape = [m, n], optional dt, mask) is missing")
        cameras = data.get("camera")
        if not isinstance(cameras, list) or not cameras:
            raise ValueError("no camera: add at least one [[camera]] table")
        rig = _check_rig_table(data["rig"])
        for i, cam in enumerate(cameras):
            if isinstance(cam, dict) and "row_map" in cam:
                raise ValueError(f"camera[{i}] has unknown key 'row_map'; use row_map_file = \"<file>.npy\"")
        return RigFile(shape=rig["shape"], cameras=cameras, dt=rig["dt"], mask=rig["mask"], path=path)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def save_rigfile(path, rigfile: RigFile) -> Path:
    """Write ``rigfile`` as TOML to ``path``, atomically.

    ``row_map_file`` names are rewritten relative to the new file's folder;
    cameras holding a ``row_map`` array get it written next to the file as
    ``<stem>.camera<i>.rows.npy`` (atomically too) and referenced from it.
    Loading the result gives an equal :meth:`RigFile.rig`.
    """
    if not isinstance(rigfile, RigFile):
        raise ValueError(f"rigfile must be a RigFile, got {type(rigfile).__name__}")
    path = Path(os.fspath(path))
    folder = path.parent if str(path.parent) else Path(".")
    old_base = rigfile.path.parent if rigfile.path is not None else None
    tables = []
    arrays = {}
    for i, cam in enumerate(rigfile.cameras):
        table = {key: cam[key] for key in CAMERA_KEYS if key in cam and key not in ("config", "row_map_file")}
        if cam.get("row_map_file") is not None:
            source = _resolve(cam["row_map_file"], old_base).resolve()
            try:
                table["row_map_file"] = Path(os.path.relpath(source, folder.resolve())).as_posix()
            except ValueError:  # another drive (Windows)
                table["row_map_file"] = str(source)
        elif cam.get("row_map") is not None:
            name = f"{path.stem}.camera{i}.rows.npy"
            arrays[name] = cam["row_map"]
            table["row_map_file"] = name
        table.pop("address", None)
        if table.get("frames") == 1:
            del table["frames"]
        if cam["config"]:
            table["config"] = cam["config"]
        tables.append(table)
    rig = {"shape": list(rigfile.shape)}
    if rigfile.dt is not None:
        rig["dt"] = rigfile.dt
    rig["mask"] = rigfile.mask
    text = _HEADER + dumps_toml({"rig": rig, "camera": tables})
    for name, array in arrays.items():
        with atomic_path(folder / name) as tmp:
            with open(tmp, "wb") as handle:
                np.save(handle, np.asarray(array, dtype=np.float64))
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


_HEADER = "# rsocl rig file. Units: seconds (dt, t_e, t_r, t_a, t_d), degrees (angle), pixels (shape, roi).\n\n"


# ---------------------------------------------------------------------- TOML writer
_BARE = re.compile(r"^[A-Za-z0-9_-]+$")
_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _toml_string(text: str) -> str:
    out = []
    for ch in text:
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _toml_key(key) -> str:
    if not isinstance(key, str):
        raise ValueError(f"TOML keys must be strings, got {key!r}")
    return key if _BARE.match(key) else _toml_string(key)


def _toml_value(value, where) -> str:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        value = float(value)
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, (str, os.PathLike)):
        return _toml_string(os.fspath(value))
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v, f"{where}[{j}]") for j, v in enumerate(value)) + "]"
    if isinstance(value, dict):
        items = [f"{_toml_key(k)} = {_toml_value(v, f'{where}.{k}')}" for k, v in value.items() if v is not None]
        return "{" + ", ".join(items) + "}" if items else "{}"
    if value is None:
        raise ValueError(f"{where}: TOML has no null; leave the key out instead of None")
    raise ValueError(f"{where}: cannot write a {type(value).__name__} to TOML ({value!r})")


def _is_table(value):
    return isinstance(value, dict)


def _is_table_array(value):
    return isinstance(value, (list, tuple)) and bool(value) and all(isinstance(v, dict) for v in value)


def _write_table(lines, header, table, array=False):
    scalars = [(k, v) for k, v in table.items() if v is not None and not _is_table(v) and not _is_table_array(v)]
    if header is not None:
        if lines:
            lines.append("")
        lines.append(f"[[{header}]]" if array else f"[{header}]")
    for key, value in scalars:
        lines.append(f"{_toml_key(key)} = {_toml_value(value, (header + '.' if header else '') + str(key))}")
    for key, value in table.items():
        name = _toml_key(key) if header is None else f"{header}.{_toml_key(key)}"
        if _is_table(value):
            _write_table(lines, name, value)
        elif _is_table_array(value):
            for item in value:
                _write_table(lines, name, item, array=True)


def dumps_toml(data: dict) -> str:
    """TOML text of ``data`` (nested dicts become tables, lists of dicts arrays of tables).

    Supports str, int, float (including inf and nan), bool, lists, dicts and
    NumPy scalars/arrays; keys whose value is None are left out. The output
    reads back with :mod:`tomllib` to equal data (tuples become lists).
    """
    if not isinstance(data, dict):
        raise ValueError(f"data must be a dict, got {type(data).__name__}")
    lines = []
    _write_table(lines, None, data)
    return "\n".join(lines) + "\n"
