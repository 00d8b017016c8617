"""What one task does: reconstruct one tile of one set, on this process's own OpenCL device.

A task carries only what is particular to it (the set, the tile, where its snapshots are); the
rig travels once per worker as a :class:`RigPayload` and each process rebuilds the rig and the
tiles' rigs once (:func:`_rig_for`). Each process opens its OpenCL context once and keeps it
(:func:`rsocl.device.get_device` caches it); with several GPUs and no device asked for, worker
``i`` of a cluster takes GPU ``i mod (number of GPUs)``. Tasks that share a process take turns
on its device (one lock per device): kernels keep their by-value arguments between launches,
so two solvers must not launch on one device at once.
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass, field, replace

import numpy as np

from rsocl.device.context import Device, get_device, list_devices
from rsocl.model.rig import Rig
from rsocl.scale.tiles import Tile, core_block, rig_digest, tile_rig
from rsocl.solver.crossval import Tuning

__all__ = ["TileSettings", "RigPayload", "FileBlock", "Job", "Piece", "solve_tile", "worker_device"]


@dataclass(frozen=True)
class TileSettings:
    """The solver settings of the whole capture, applied as they are to every tile.

    ``lam`` and ``eta`` are settled (never None) so that no tile picks its own; a self-tuned
    run puts the values chosen once for the capture here (:mod:`rsocl.scale.tuning_tile`). Either may
    be one value per set (a tuple), of which each set's tasks take their own (:meth:`for_set`). ``start``
    is each tile's first iterate: ``"zeros"``, or ``"interp3d"`` (the
    :func:`~rsocl.model.interpolation.interp3d` interpolation of the tile's own snapshots over
    its rig, computed on the device; the start of a tuned :func:`rsocl.reconstruct`). ``blend`` moves
    each tile's result back towards its start (:func:`rsocl.reconstruct`'s ``blend``; 1: not at all), as
    the capture's search chose it. ``quality`` names the rung (:mod:`rsocl.solver.ladder`) whose
    static-part fix a tile started from the interpolation gets, as the untiled tuned run does; that fix
    measures ``frame_levels`` (one :class:`~rsocl.solver.static.Levels` per set, of the whole frame; None:
    each tile its own snapshots), so that a tile marks the pixels the run in one piece marks.
    """

    regularizer: str
    options: dict
    iterations: int
    lam: float | tuple[float, ...]
    eta: float | tuple[float, ...]
    tv_iterations: int | None
    projection: str
    dtype: str
    saturation: float | None
    device: str | Device | None
    start: str = "zeros"
    blend: float = 1.0
    quality: str = "balanced"
    frame_levels: tuple | None = None

    def for_set(self, set_index) -> TileSettings:
        """The settings of set ``set_index``'s tasks: its own ``lam`` and ``eta`` where they are per set."""

        def own(value):
            return value[set_index] if isinstance(value, tuple) else value

        return replace(self, lam=own(self.lam), eta=own(self.eta))


@dataclass(frozen=True)
class RigPayload:
    """The whole capture's rig as plain data (:meth:`Rig.to_dict`) with a key naming it."""

    key: str
    data: dict

    @classmethod
    def of(cls, rig: Rig) -> RigPayload:
        """The payload of ``rig``, keyed by the SHA-256 of its description and row maps."""
        data = rig.to_dict()
        return cls(rig_digest(data), data)


@dataclass(frozen=True)
class FileBlock:
    """Snapshots read by the task itself from an HDF5 capture file (on storage the workers share).

    ``dataset`` is ``"snapshots"`` ``(K, m, n)`` or ``"snapshot_sets"`` ``(S, K, m, n)`` (then
    ``set_index`` picks the set).
    """

    path: str
    dataset: str
    set_index: int | None = None

    def read(self, tile: Tile) -> np.ndarray:
        import h5py

        rows, cols = tile.outer_slices
        with h5py.File(self.path, "r") as h5:
            data = h5[self.dataset]
            if self.set_index is None:
                return data[:, rows, cols]
            return data[self.set_index, :, rows, cols]


@dataclass(frozen=True)
class Job:
    """One task: tile ``tile`` of set ``set_index`` (None for a single-set capture).

    ``source`` is the tile's block of snapshots ``(K, h, w)`` or a :class:`FileBlock`;
    ``span`` the sub-frames the whole capture samples, ``(first, stop)``; ``store`` the Zarr
    store the task writes its chunks to (None: the block is returned) and ``store_id`` that
    store's identity (:func:`rsocl.scale.store.store_id`: the task writes only into the store
    that has it).
    """

    set_index: int | None
    tile: Tile
    source: object
    span: tuple
    store: str | None = None
    store_id: str | None = None

    @property
    def label(self) -> str:
        where = self.tile.describe()
        return where if self.set_index is None else f"{where} of set {self.set_index}"

    def snapshots(self) -> np.ndarray:
        if isinstance(self.source, FileBlock):
            return self.source.read(self.tile)
        return np.asarray(self.source)


@dataclass
class Piece:
    """A solved tile: its core over sub-frames ``start..stop-1`` (``block``, None once stored)."""

    set_index: int | None
    index: tuple
    start: int
    stop: int
    block: np.ndarray | None
    seconds: float
    iterations: int
    residual: float
    device: str
    process: int = field(default_factory=os.getpid)


# ---------------------------------------------------------------------- per-process state
_LOCKS: dict = {}
_LOCKS_GUARD = threading.Lock()


def _lock_for(device) -> threading.Lock:
    with _LOCKS_GUARD:
        return _LOCKS.setdefault(id(device), threading.Lock())


def _worker_index():
    """This process's worker number in a dask.distributed cluster (its name), else None."""
    try:
        from distributed import get_worker

        name = get_worker().name
    except (ImportError, ValueError):
        return None
    try:
        return int(name)
    except (TypeError, ValueError):
        return None


def worker_device(spec=None):
    """The device of this process: ``spec`` when given; else ``RSOCL_DEVICE``/``PYOPENCL_CTX``; else,
    in a cluster worker named ``i`` with several GPUs, GPU ``i mod (number of GPUs)``; else the default."""
    if spec is not None or os.environ.get("RSOCL_DEVICE") or os.environ.get("PYOPENCL_CTX"):
        return get_device(spec)
    index = _worker_index()
    if index is not None:
        import pyopencl as cl

        gpus = [f"{pi}:{di}" for pi, di, _, dev in list_devices() if dev.type & cl.device_type.GPU]
        if len(gpus) > 1:
            return get_device(gpus[index % len(gpus)])
    return get_device(None)


_RIGS: dict = {}
_TILE_RIGS: dict = {}
#: tile rigs kept per process (the oldest go first)
MAX_TILE_RIGS = 256


def _rig_for(payload: RigPayload, tile: Tile) -> Rig:
    """The rig of ``tile``, built once per process from the capture's rig (built once too)."""
    key = (payload.key, tile.outer)
    with _LOCKS_GUARD:
        if key not in _TILE_RIGS:
            full = _RIGS.get(payload.key)
            if full is None:
                _RIGS.clear()
                full = _RIGS[payload.key] = Rig.from_dict(payload.data)
            if len(_TILE_RIGS) >= MAX_TILE_RIGS:
                del _TILE_RIGS[next(iter(_TILE_RIGS))]
            _TILE_RIGS[key] = tile_rig(full, tile)
        return _TILE_RIGS[key]


# ---------------------------------------------------------------------- the task
def _start(settings: TileSettings):
    """The tile's first iterate as :func:`rsocl.reconstruct` takes it: None (zeros) or ``"interp3d"``."""
    if settings.start not in ("zeros", "interp3d"):
        raise ValueError(f"start must be 'zeros' or 'interp3d', got {settings.start!r}")
    return None if settings.start == "zeros" else "interp3d"


def _unfitted(job: Job, rig, g, solved: slice, settings: TileSettings, device) -> Piece:
    """The piece of a tile with no snapshot pixel below saturation: the ``interp3d`` interpolation of its
    clipped snapshots (each a lower bound of its pixel's value), over its core."""
    from rsocl.model.interpolation import interp3d

    block = core_block(interp3d(g, rig), job.tile, solved).astype(settings.dtype, copy=False)
    return Piece(job.set_index, job.tile.index, solved.start, solved.stop, block, 0.0, 0, 0.0, device.name)


def solve_tile(job: Job, payload: RigPayload, settings: TileSettings) -> Piece:
    """Reconstruct ``job``'s tile with the capture's settings; write it to the store or return it.

    A tile with no snapshot pixel below ``settings.saturation`` is not solved: it takes the interpolation
    of its clipped snapshots, 0 iterations and residual 0.
    """
    from rsocl.solver.reconstruct import reconstruct
    from rsocl.solver.static import frame_levels

    rig = _rig_for(payload, job.tile)
    settings = settings.for_set(job.set_index)
    solved = rig.sampled_range()
    g = job.snapshots()
    x0 = _start(settings)
    device = worker_device(settings.device)
    if settings.saturation is not None and not np.any(g < settings.saturation):
        piece = _unfitted(job, rig, g, solved, settings, device)
    else:
        measured = None if settings.frame_levels is None else settings.frame_levels[job.set_index or 0]
        with _lock_for(device), frame_levels(measured):
            began = time.perf_counter()
            result = reconstruct(
                g,
                rig,
                settings.regularizer,
                iterations=settings.iterations,
                lam=settings.lam,
                eta=settings.eta,
                tv_iterations=settings.tv_iterations,
                projection=settings.projection,
                device=device,
                dtype=settings.dtype,
                regularizer_options=settings.options,
                saturation=settings.saturation,
                x0=x0,
                # the capture's settings, never a tile's own choice; a tile started from the interpolation
                # runs as tuned with them (its rung's static-part fix)
                tune=False if x0 is None else Tuning(chosen={}),
                blend=settings.blend,
                quality=settings.quality,
            )
            seconds = time.perf_counter() - began
        piece = Piece(
            job.set_index,
            job.tile.index,
            solved.start,
            solved.stop,
            core_block(result.datacube, job.tile, solved),
            seconds,
            result.iterations,
            float(result.history["residual"][-1]),
            device.name,
        )
    if job.store is not None:
        from rsocl.scale.store import write_piece

        write_piece(job.store, job.tile, piece, job.span, job.store_id)
        piece.block = None
    return piece
