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
    # row_map_file = "cam0_rows.npy"   (a .npy (m, n) row map, in the rig file's folder or below)
    # homography = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]   (3x3, reference pixel -> sensor pixel)
    t_e = 1.8e-04             # exposure, s (required)
    t_r = 3.5e-05             # row readout time, s (required)
    t_a = 0.0                 # trigger offset, s (default 0)
    gain = 1.0                # photometric gain (default 1)
    roi = [0, 0, 64, 64]      # sensor ROI x, y, width, height (optional)
    pixel_format = "Mono16"   # optional
    # t_d, frames: multi-frame cameras (see rsocl.Camera)

    [camera.config]           # backend settings, passed to the backend as they are
    scene = "builtin"         # (never a model key: angle, t_e, ... in [[camera]], shape, dt, mask in [rig])

Every key, its unit and its table, and an example per backend: ``docs/rig-files.md``.
Only one of ``angle``, ``row_map_file`` and ``homography`` may be given (none
means ``angle = 0``). A homography maps a reference pixel centre ``(x, y)``
(column, row; pixel centres at integer coordinates) to full-sensor coordinates
``(x', y')`` (before the ROI); the camera row of the pixel is ``y'``, less the top row of the
camera's ``roi`` (the first row it reads; 0 without one) (docs/model.md). Content errors raise
:class:`ValueError` naming the file, the camera index and the key, e.g.
``rig.toml: camera[2].t_e must be > 0 seconds, got -1.0``.

TOML has no null: keys whose value is None are left out when writing.
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rsocl.common import validation as check
from rsocl.files.atomic import atomic_path
from rsocl.files.rigfile_schema import CAMERA_KEYS, check_camera, check_rig_table, closest, resolve_path, to_camera
from rsocl.files.toml_writer import dumps_toml
from rsocl.model.rig import Camera, Rig

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["RigFile", "load_rigfile", "save_rigfile"]

#: Model keys the rig file passes on to ``simulated`` cameras (see :meth:`RigFile.backends`).
SIMULATED_MODEL_KEYS = ("shape", "dt", "mask", "t_e", "t_r", "t_a", "gain", "angle", "row_map", "scene_frames", "index")


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
        rig = check_rig_table({"shape": list(self.shape), "dt": self.dt, "mask": self.mask})
        self.shape, self.dt, self.mask = rig["shape"], rig["dt"], rig["mask"]
        if not isinstance(self.cameras, (list, tuple)) or not self.cameras:
            raise ValueError("cameras must hold at least one [[camera]] table")
        if self.path is not None:
            self.path = Path(os.fspath(self.path))
        base = self.path.parent if self.path is not None else None
        self.cameras = [check_camera(i, dict(cam), self.shape, base) for i, cam in enumerate(self.cameras)]
        self.rig()  # whole-rig checks (dt >= t_r, multi-frame t_d)

    # ------------------------------------------------------------------ views
    def camera(self, index: int) -> Camera:
        """The :class:`~rsocl.model.rig.Camera` of camera ``index``."""
        return to_camera(self.cameras[index], self.shape)

    def rig(self) -> Rig:
        """The :class:`~rsocl.model.rig.Rig` this file describes."""
        cams = [self.camera(i) for i in range(len(self.cameras))]
        try:
            return Rig(cams, self.shape, dt=self.dt, mask=self.mask)
        except ValueError as exc:  # the model's cameras[i] is this file's i-th [[camera]] table
            raise ValueError(re.sub(r"\bcameras\[(\d+)\]", r"camera[\1]", str(exc))) from None

    def homography(self, index: int):
        """The 3x3 homography (reference -> sensor) of camera ``index``, or None."""
        H = self.cameras[index].get("homography")
        return None if H is None else np.asarray(H, dtype=np.float64)

    def scene_path(self, index: int):
        """The video file a ``simulated`` camera ``index`` shows (``config.scene``), resolved against the rig
        file's folder when it is relative (as ``row_map_file`` is); None for ``"builtin"`` or no scene."""
        scene = self.cameras[index]["config"].get("scene")
        if self.cameras[index]["backend"] != "simulated" or not _is_video_path(scene):
            return None
        return resolve_path(scene, self.path.parent if self.path is not None else None)

    def backends(self) -> list:
        """``[(backend name, config dict)]``, one per camera, in camera order.

        ``config`` is a copy of the camera's ``[camera.config]`` table (plus
        ``address``). A ``simulated`` camera is a model of the rig itself: a relative ``scene`` path is
        resolved against the rig file's folder (:meth:`scene_path`), and its config also receives, where
        it does not set them, the model keys
        :data:`SIMULATED_MODEL_KEYS`: ``shape``, ``dt``, ``mask``, ``t_e``,
        ``t_r``, ``t_a``, ``gain``, ``angle`` or ``row_map``, ``scene_frames``
        (the rig's ``T``, so every camera sees the same datacube) and ``index``.
        """
        rig = self.rig()
        out = []
        for i, cam in enumerate(self.cameras):
            config = dict(cam["config"])
            if cam["backend"] == "simulated":
                if _is_video_path(config.get("scene")):
                    config["scene"] = os.fspath(self.scene_path(i))
                model = {
                    "shape": list(self.shape),
                    "dt": rig.dt,
                    "mask": rig.mask,
                    "t_e": cam["t_e"],
                    "t_r": cam["t_r"],
                    "t_a": cam.get("t_a", 0.0),
                    "gain": cam.get("gain", 1.0),
                    "scene_frames": rig.T,
                    "index": i,
                }
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
    def from_rig(cls, rig: Rig, backend="simulated", configs=None) -> RigFile:
        """A rig file for ``rig`` with every camera on ``backend`` (``configs``: one config dict per camera)."""
        if configs is None:
            configs = [{} for _ in rig.cameras]
        if len(configs) != rig.C:
            raise ValueError(f"configs must hold one dict per camera ({rig.C}), got {len(configs)}")
        cameras = []
        for cam, config in zip(rig.cameras, configs):
            d = {
                "backend": backend,
                "t_e": cam.t_e,
                "t_r": cam.t_r,
                "t_a": cam.t_a,
                "gain": cam.gain,
                "config": dict(config or {}),
            }
            if cam.frames > 1:
                d["frames"] = cam.frames
            if cam.t_d is not None:
                d["t_d"] = cam.t_d
            if cam.row_map is not None:
                d["row_map"] = cam.row_map
            else:
                d["angle"] = cam.angle
            cameras.append(d)
        return cls(shape=rig.shape, cameras=cameras, dt=rig.dt, mask=rig.mask)


# ---------------------------------------------------------------------- files
def load_rigfile(path, check_shape=None) -> RigFile:
    """Read and check a TOML rig file (see the module docstring for the schema).

    Parameters
    ----------
    path : str or os.PathLike
    check_shape : callable or None
        Called as ``check_shape(shape, cameras)`` with the checked ``[rig] shape`` ``(m, n)`` and
        the number of ``[[camera]]`` tables, before any row map is read or the rig is built (e.g.
        to refuse a shape whose rig would not fit the host's memory); a ValueError it raises is
        raised naming the file.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is not a UTF-8 TOML file or its content breaks the schema (a key in the wrong
        table, a ``row_map_file`` outside the file's folder); the message names the file, the
        camera index and the key.
    """
    path = check.existing_file("", path, "rig file")
    try:
        with open(path, "rb") as handle:
            data = tomllib.load(handle)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:  # a binary file (an .h5, a .npy, an image)
        raise ValueError(
            f"{path}: not a TOML rig file (byte {exc.object[exc.start]:#04x} at offset {exc.start} is not UTF-8 text)"
        ) from None
    try:
        unknown = sorted(set(data) - {"rig", "camera"})
        if unknown:
            raise ValueError(
                f"unknown top-level key(s) {unknown}{closest(unknown, ('rig', 'camera'))}; expected [rig] and "
                "[[camera]] tables"
            )
        if "rig" not in data:
            raise ValueError("the [rig] table (shape = [m, n], optional dt, mask) is missing")
        cameras = data.get("camera")
        if not isinstance(cameras, list) or not cameras:
            raise ValueError("no camera: add at least one [[camera]] table")
        rig = check_rig_table(data["rig"])
        if check_shape is not None:
            check_shape(rig["shape"], len(cameras))
        for i, cam in enumerate(cameras):
            if isinstance(cam, dict) and "row_map" in cam:
                raise ValueError(f"camera[{i}] has unknown key 'row_map'; use row_map_file = \"<file>.npy\"")
        return RigFile(shape=rig["shape"], cameras=cameras, dt=rig["dt"], mask=rig["mask"], path=path)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def save_rigfile(path, rigfile: RigFile) -> Path:
    """Write ``rigfile`` as TOML to ``path``, atomically.

    ``row_map_file`` names are rewritten relative to the new file's folder; cameras holding a
    ``row_map`` array, or a ``row_map_file`` outside that folder (a rig file reads only its own
    folder and below), get it written next to the file as ``<stem>.camera<i>.rows.npy``
    (atomically too) and referenced from it; where that file holds another map, which an earlier rig
    file may name, the copy is ``<stem>.camera<i>.rows-<hash>.npy`` instead and the earlier file stays.
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
        relative = None
        if cam.get("row_map_file") is not None:
            source = resolve_path(cam["row_map_file"], old_base).resolve()
            try:
                relative = Path(os.path.relpath(source, folder.resolve()))
            except ValueError:  # another drive (Windows)
                relative = None
            if relative is not None and ".." not in relative.parts:
                table["row_map_file"] = relative.as_posix()
        if "row_map_file" not in table and cam.get("row_map") is not None:
            # an array, or a file outside the new folder (a rig file reads only its folder and below): a copy beside it
            name = _row_map_name(folder, f"{path.stem}.camera{i}", cam["row_map"])
            arrays[name] = cam["row_map"]
            table["row_map_file"] = name
        table.pop("address", None)
        if table.get("frames") == 1:
            del table["frames"]
        if cam["config"]:
            table["config"] = _config_for(rigfile, i, folder)
        tables.append(table)
    rig: dict = {"shape": list(rigfile.shape)}
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


def _row_map_name(folder: Path, stem: str, row_map) -> str:
    """``<stem>.rows.npy``, unless a file of that name in ``folder`` holds another map (an earlier rig file, a
    kept one, may name it): then ``<stem>.rows-<12 hex digits of the map's SHA-256>.npy``, which no other map
    takes."""
    name, values = f"{stem}.rows.npy", np.asarray(row_map, dtype=np.float64)
    try:
        there = np.load(folder / name, allow_pickle=False)
    except (OSError, ValueError):  # no file there, or none that is a map: nothing an earlier file reads
        return name
    if isinstance(there, np.ndarray) and there.shape == values.shape and np.array_equal(there, values):
        return name
    return f"{stem}.rows-{hashlib.sha256(np.ascontiguousarray(values).tobytes()).hexdigest()[:12]}.npy"


def _is_video_path(scene) -> bool:
    return isinstance(scene, (str, os.PathLike)) and os.fspath(scene) != "builtin"


def _config_for(rigfile: RigFile, index: int, folder: Path) -> dict:
    """Camera ``index``'s config as written to a rig file in ``folder``: a relative simulated ``scene`` path
    rewritten relative to ``folder``, so that it names the same file."""
    config = dict(rigfile.cameras[index]["config"])
    scene = config.get("scene")
    source = rigfile.scene_path(index)
    if source is not None and isinstance(scene, (str, os.PathLike)) and not Path(scene).is_absolute():
        source = source.resolve()
        try:
            config["scene"] = Path(os.path.relpath(source, folder.resolve())).as_posix()
        except ValueError:  # another drive (Windows)
            config["scene"] = str(source)
    return config


_HEADER = "# rsocl rig file. Units: seconds (dt, t_e, t_r, t_a, t_d), degrees (angle), pixels (shape, roi).\n\n"
