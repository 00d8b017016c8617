"""A tiled reconstruction in a Zarr store: chunks owned by tiles, completion marks, resuming.

Layout (a Zarr v3 group)
------------------------
- array ``datacube``: ``[T, m, n]`` (one set) or ``[S, T, m, n]`` (``S`` sets), float32 or
  float64, fill 0; chunks ``(tc, H, W)`` (``(1, tc, H, W)``) where ``(H, W)`` is the tile, so
  every chunk belongs to one tile, and ``tc`` sub-frames make a chunk of about
  :data:`CHUNK_BYTES`;
- array ``tiles``: ``[S, ny, nx, 6]`` float64 (``S = 1`` for one set), one chunk per tile:
  ``done`` (1 once the tile's data are written, else 0), the first and one-past-last solved
  sub-frame, seconds, iterations and final residual of the tile's run;
- arrays ``rig_row_maps/<camera>`` for cameras with a row map;
- the attributes of an HDF5 reconstruction file (:mod:`rsocl.files.hdf5_reconstruction`): ``rsocl_file =
  "reconstruction"``, ``format_version``, ``rig`` (JSON; row maps referenced as
  ``{"dataset": "rig_row_maps/<camera>"}``), ``params`` (JSON), and the readable copies ``T``,
  ``T_se``, ``dt``, ``mask``, ``n_cameras``, ``n_channels``, ``shape``; plus ``rig_digest`` (the
  SHA-256 of the rig with its row maps, :func:`~rsocl.scale.tiles.rig_digest`), ``tiling``
  (JSON: tile, halo, grid, sets) and ``input_digest`` (SHA-256 of the snapshots), and ``store_id``, a
  random token written when the store is built: the tasks of a run carry it (:func:`store_id`)
  and write only into the store that has it, so a store removed and built again at the same path
  (by another run of the same process or of a long-lived cluster) is never written through
  arrays opened on the old one.

A task writes its tile's chunks of ``datacube`` (the sub-frames the capture samples; chunks
outside them are never written and read as 0), then the tile's chunk of ``tiles`` (each chunk
file is written to a temporary name and renamed): a tile reads as done only once its data are
complete. Running the same reconstruction on an existing store redoes only the tiles not
done; a store of another reconstruction (different rig or row maps, settings, tiling or
snapshots) is refused, and a path holding anything but a store of the same rig, tiling, dtype and
parameters known before the search is refused before the input is read (:func:`check_store`). A
store without ``rig_digest`` (an earlier format) is compared by the row maps it holds.

A new store is built under a hidden sibling name, ``.NAME.partial-<host>-<pid>-<random>``, and
renamed to ``NAME`` once its arrays and attributes are written, so the path holds either nothing
or a complete store whatever moment the run is killed at; such a sibling left by a killed run is
removed by the next run on the same host, and never blocks one.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rsocl.files.atomic import fsync_directory, fsync_file, owned_prefix, remove_stale
from rsocl.files.hdf5_header import FORMAT_VERSION
from rsocl.model.rig import Rig
from rsocl.scale.store_params import differing_params
from rsocl.scale.tiles import expand, rig_digest

__all__ = [
    "CHUNK_BYTES",
    "require_zarr",
    "check_store_path",
    "check_store",
    "StoreSpec",
    "prepare_store",
    "store_id",
    "tiles_done",
    "write_piece",
    "load_store",
    "StoredReconstruction",
]

#: Target size of one chunk of ``datacube``, bytes.
CHUNK_BYTES = 4 * 2**20
_ROW_MAPS = "rig_row_maps"
#: columns of the ``tiles`` array
TILE_FIELDS = ("done", "start", "stop", "seconds", "iterations", "residual")
#: attributes that must match for a store to be resumed
_IDENTITY = ("rsocl_file", "rig", "rig_digest", "tiling", "input_digest", "dtype")
#: the part of it known before the input is read and the parameters are chosen (:func:`check_store`)
KNOWN_FIRST = ("rsocl_file", "rig", "rig_digest", "tiling", "dtype")


def require_zarr(name="out"):
    """The ``zarr`` module (v3); ValueError naming ``name`` when it is missing."""
    try:
        import zarr
    except ImportError:
        raise ValueError(
            f"{name}: writing a Zarr store needs zarr >= 3 (Python >= 3.11): pip install 'rsocl[dask]'"
        ) from None
    if int(zarr.__version__.split(".")[0]) < 3:
        raise ValueError(f"{name}: rsocl writes Zarr v3 stores with zarr >= 3, found zarr {zarr.__version__}")
    return zarr


def check_store_path(path, name="out") -> Path:
    """``path`` as a Path whose folder exists and which is not a plain file; errors name ``name``."""
    path = Path(os.fspath(path))
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(f"{name}: directory {str(parent)!r} does not exist (writing {str(path)!r})")
    if path.exists() and not path.is_dir():
        raise ValueError(f"{name}: {str(path)!r} is a file, not a Zarr store (a folder)")
    return path


@dataclass(frozen=True)
class StoreSpec:
    """What a store holds: the rig, the grid of tiles, the sets, the parameters and the input's digest."""

    rig: Rig
    tile: tuple
    halo: int
    grid: tuple
    sets: int | None
    dtype: str
    params: dict
    input_digest: str

    @property
    def prefix_shape(self) -> tuple:
        return () if self.sets is None else (self.sets,)

    def chunks(self) -> tuple:
        h, w = self.tile
        itemsize = np.dtype(self.dtype).itemsize
        tc = int(min(self.rig.T, max(1, CHUNK_BYTES // (h * w * itemsize))))
        return tuple(1 for _ in self.prefix_shape) + (tc, h, w)

    def attributes(self) -> dict:
        rig = self.rig
        data = rig.to_dict()
        for index, camera in enumerate(data["cameras"]):
            if camera.get("row_map") is not None:
                camera["row_map"] = {"dataset": f"{_ROW_MAPS}/{index}"}
        tiling = {"tile": list(self.tile), "halo": self.halo, "grid": list(self.grid), "sets": self.sets}
        return {
            "rsocl_file": "reconstruction",
            "format_version": FORMAT_VERSION,
            "rig": json.dumps(data, allow_nan=False),
            "rig_digest": rig_digest(rig.to_dict()),
            "T": rig.T,
            "T_se": rig.T_se,
            "dt": rig.dt,
            "mask": rig.mask,
            "n_cameras": rig.C,
            "n_channels": rig.n_channels,
            "shape": list(rig.shape),
            "params": json.dumps(self.params),
            "tiling": json.dumps(tiling),
            "input_digest": self.input_digest,
            "dtype": self.dtype,
        }


def prepare_store(path, spec: StoreSpec, name="out") -> tuple[np.ndarray, str | None]:
    """Create the store at ``path``, or open the one there for the same reconstruction.

    Returns the ``done`` marks, ``(S, ny, nx)`` bool (``S = 1`` for one set), and the ``store_id`` of
    the store those marks and that check are of (None for a store written before stores had one), for
    the run's tasks to carry (:func:`write_piece`). Raises ValueError naming ``name`` when ``path``
    holds something else.
    """
    zarr = require_zarr(name)
    path = check_store_path(path, name)
    marks = (spec.sets or 1,) + tuple(spec.grid)
    if not _holds_files(path):
        _remove_leftovers(path)
        identity = _create(zarr, path, spec)
        if identity is not None:
            return np.zeros(marks, dtype=bool), identity
    return _resume(zarr, path, spec, name)


def check_store(path, spec: StoreSpec, name="out", keys=KNOWN_FIRST) -> Path:
    """``path`` checked as :func:`check_store_path` does; where it holds files, ValueError naming ``name``
    unless they are an rsocl reconstruction store whose attributes ``keys`` (default: the rig with its
    row maps, the tiling and the dtype, all known before the input is read) are ``spec``'s, and whose
    parameters hold those of ``spec.params`` (the ones known before the search; of a dict, its entries:
    :func:`~rsocl.scale.store_params.differing_params`). Nothing is written."""
    zarr = require_zarr(name)
    path = check_store_path(path, name)
    if _holds_files(path):
        _open_same(zarr, path, spec, name, keys, "r", params="known")
    return path


def _holds_files(path: Path) -> bool:
    return path.is_dir() and any(path.iterdir())


def _open_same(zarr, path: Path, spec: StoreSpec, name: str, keys: tuple, mode: str, params: str):
    """The group of the store at ``path``, opened with ``mode``; ValueError naming ``name`` unless it is an
    rsocl store whose attributes ``keys`` are ``spec``'s, and its parameters too: ``params`` "all" of them,
    or "known", those ``spec.params`` holds."""
    try:
        group = zarr.open_group(str(path), mode=mode)
    except Exception as exc:
        raise ValueError(f"{name}: {str(path)!r} exists and is not a Zarr store ({exc})") from None
    found, attrs = dict(group.attrs), spec.attributes()
    if found.get("rsocl_file") != "reconstruction":
        raise ValueError(f"{name}: {str(path)!r} is not an rsocl reconstruction store; choose another path")
    if "rig_digest" not in found and "rig" in found:  # an earlier format, without it: its row maps
        found["rig_digest"] = _held_rig_digest(group, found["rig"])
    differ = [key for key in keys if key != "rsocl_file" and found.get(key) != attrs[key]]
    if "rig_digest" in differ:  # it covers the rig's description too: alone, it names the row maps
        differ[differ.index("rig_digest")] = "" if "rig" in differ else "rig row maps"
    differ = [key for key in differ if key]
    stored, run = json.loads(found.get("params", "{}")), json.loads(attrs["params"])
    differ += differing_params(stored, run, known_only=params == "known")
    if differ:
        raise ValueError(
            f"{name}: {str(path)!r} holds another reconstruction (it differs in "
            f"{', '.join(differ)}); remove it or choose another path"
        )
    return group


def _held_rig(group, text: str) -> Rig:
    """The rig of a store's ``rig`` attribute (``text``), its row maps read from the store's arrays."""
    data = json.loads(text)
    for camera in data["cameras"]:
        ref = camera.get("row_map")
        if isinstance(ref, dict):
            camera["row_map"] = np.asarray(group[ref["dataset"]][...], dtype=np.float64)
    return Rig.from_dict(data)


def _held_rig_digest(group, text: str) -> str | None:
    """The ``rig_digest`` of the rig a store holds (:func:`_held_rig`); None where it cannot be read."""
    try:
        return rig_digest(_held_rig(group, text).to_dict())
    except (KeyError, TypeError, ValueError):
        return None


def _resume(zarr, path: Path, spec: StoreSpec, name: str) -> tuple[np.ndarray, str | None]:
    """The ``done`` marks and ``store_id`` of the store at ``path``; ValueError naming ``name`` unless it is
    ``spec``'s."""
    group = _open_same(zarr, path, spec, name, _IDENTITY, "r+", params="all")
    return np.asarray(group["tiles"][..., 0]) > 0, group.attrs.get("store_id")


def tiles_done(path) -> tuple[int, int] | None:
    """``(done, total)``: the tile tasks the store at ``path`` marks complete, and all of them; None where
    there is no store (a run stopped before it was built)."""
    zarr = require_zarr()
    try:
        marks = np.asarray(zarr.open_group(str(path), mode="r")["tiles"][..., 0]) > 0
    except (FileNotFoundError, KeyError):
        return None
    return int(marks.sum()), int(marks.size)


def _partial_prefix(path: Path) -> str:
    return f".{path.name}.partial-"


def _create(zarr, path: Path, spec: StoreSpec) -> str | None:
    """Build the store beside ``path`` and rename it there; its ``store_id``, or None when another process
    made one first."""
    tmp = path.with_name(f"{owned_prefix(_partial_prefix(path))}{secrets.token_hex(4)}")
    os.mkdir(tmp)
    try:
        group = zarr.open_group(str(tmp), mode="w")
        shape = spec.prefix_shape + (spec.rig.T,) + spec.rig.shape
        group.create_array("datacube", shape=shape, chunks=spec.chunks(), dtype=spec.dtype, fill_value=0)
        marks = (spec.sets or 1,) + tuple(spec.grid)
        group.create_array(
            "tiles",
            shape=marks + (len(TILE_FIELDS),),
            chunks=(1, 1, 1, len(TILE_FIELDS)),
            dtype="float64",
            fill_value=0,
        )
        for index, camera in enumerate(spec.rig.cameras):
            if camera.row_map is not None:
                group.create_array(f"{_ROW_MAPS}/{index}", data=spec.rig.row_map(index))
        identity = secrets.token_hex(16)
        group.attrs.put({**spec.attributes(), "store_id": identity})
        for folder, _, files in os.walk(tmp):
            for file in files:
                fsync_file(Path(folder) / file)
        try:
            os.replace(tmp, path)
        except OSError:
            if not _holds_files(path):
                raise
            shutil.rmtree(tmp, ignore_errors=True)
            return None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    fsync_directory(path.parent)
    return identity


def _remove_leftovers(path: Path) -> None:
    """Remove the partial stores of ``path`` left by runs on this host whose process is gone (POSIX)."""
    remove_stale(path.parent if str(path.parent) else Path("."), _partial_prefix(path), r"[0-9a-f]{8}")


def store_id(path) -> str | None:
    """The ``store_id`` of the store at ``path`` (None for a store written before stores had one)."""
    zarr = require_zarr()
    return zarr.open_group(str(path), mode="r").attrs.get("store_id")


#: the arrays of the store last written by this process: ``(path, store_id)`` -> (datacube, tiles)
_OPEN: dict = {}


def _arrays(path: str, identity: str | None):
    """The ``datacube`` and ``tiles`` arrays of the store at ``path`` whose ``store_id`` is ``identity``.

    The store's ``store_id`` is read on every call (one small file); its arrays are kept per process
    by path and identity, so a store built again at ``path`` is opened afresh, and a store without
    an identity (``identity`` None) is opened on every call. Raises ValueError when the store at
    ``path`` is not the one with ``identity`` (it was removed or replaced).
    """
    zarr = require_zarr()
    try:
        group = zarr.open_group(path, mode="r+")
        found = group.attrs.get("store_id")
    except FileNotFoundError:
        group = found = None
    if group is None or found != identity:
        raise ValueError(
            f"out: the Zarr store {path!r} was removed or replaced by another one while this run wrote it; "
            f"run again to resume into the store now there"
        )
    key = (path, identity)
    arrays = _OPEN.get(key)
    if arrays is None:
        arrays = (group["datacube"], group["tiles"])
        if identity is not None:
            _OPEN.clear()
            _OPEN[key] = arrays
    return arrays


def write_piece(path: str, tile, piece, span: tuple, identity: str | None = None) -> None:
    """Write a solved tile's core over every sub-frame (:func:`expand`: its first and last modelled
    sub-frames held before and after them; ``span``, the capture's sampled sub-frames, checks the
    piece), then mark it done (run by the task itself).

    ``identity`` is the ``store_id`` of the store the run prepared (:func:`store_id`); ValueError
    when the store at ``path`` is another one.
    """
    datacube, marks = _arrays(path, identity)
    prefix = () if piece.set_index is None else (piece.set_index,)
    T = datacube.shape[len(prefix)]
    rows, cols = tile.core_slices
    block = expand(np.asarray(piece.block, dtype=datacube.dtype), piece.start, 0, T, span)
    datacube[prefix + (slice(0, T), rows, cols)] = block
    s = piece.set_index or 0
    marks[(s,) + tuple(tile.index)] = np.array(
        [1, piece.start, piece.stop, piece.seconds, piece.iterations, piece.residual], dtype=np.float64
    )


@dataclass(frozen=True)
class StoredReconstruction:
    """A store read back: ``datacube`` (a Zarr array, read lazily), ``rig``, ``params``, ``tiling``,
    ``tiles`` (``(S, ny, nx, 6)`` float64, columns :data:`TILE_FIELDS`)."""

    datacube: object
    rig: Rig
    params: dict
    tiling: dict
    tiles: np.ndarray

    @property
    def complete(self) -> bool:
        return bool(np.all(self.tiles[..., 0] > 0))


def load_store(path) -> StoredReconstruction:
    """Open a store written by :func:`prepare_store` and :func:`write_piece`."""
    zarr = require_zarr("path")
    path = Path(os.fspath(path))
    if not path.is_dir():
        raise FileNotFoundError(f"path: Zarr store {str(path)!r} does not exist")
    group = zarr.open_group(str(path), mode="r")
    attrs = dict(group.attrs)
    if attrs.get("rsocl_file") != "reconstruction":
        raise ValueError(f"path: {str(path)!r} is not an rsocl reconstruction store")
    return StoredReconstruction(
        group["datacube"],
        _held_rig(group, attrs["rig"]),
        json.loads(attrs["params"]),
        json.loads(attrs["tiling"]),
        np.asarray(group["tiles"][...]),
    )
