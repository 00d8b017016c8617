"""``reconstruct_tiled``: a reconstruction split into tiles (and sets), run as Dask tasks.

Every input is checked before anything is computed: the snapshots against the rig, the solver
settings (:func:`~rsocl.solver.request.make_request`, as for :func:`rsocl.reconstruct`: ``lam``/``eta``
settled once, from the regularizer's recommendation, for every tile), the tile and halo, the output
path (a store already there: its rig, tiling, dtype and the parameters known before the search), and
the scheduler (connected to first). With ``tune`` (the default, as for :func:`rsocl.reconstruct`) what
the caller left unset is then chosen once from the centre tile of the first set
(:mod:`rsocl.scale.tuning_tile`) and every task runs with that choice.
"""

from __future__ import annotations

import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from rsocl.common import validation as check
from rsocl.device.context import Device
from rsocl.model.rig import Rig
from rsocl.scale.inputs import ArraySets, CaptureSets, scan
from rsocl.scale.run_settings import known_params, tile_settings
from rsocl.scale.runner import RETRIES, Engine, non_negative_int
from rsocl.scale.tiles import check_halo, check_local, place, tile_grid
from rsocl.scale.tuning_tile import tune_tiles
from rsocl.scale.work import Job, RigPayload
from rsocl.solver.memory import device_limit
from rsocl.solver.pipeline import Tuning, make_request

__all__ = ["reconstruct_tiled", "TiledResult", "TilesFailed"]


@dataclass
class TiledResult:
    """A tiled reconstruction.

    Attributes
    ----------
    datacube : ndarray or zarr.Array
        ``(T, m, n)``, or ``(S, T, m, n)`` for ``S`` sets; a Zarr array when written to a store.
    rig : Rig
    params : dict
        The settings every tile ran with, the tile and halo; ``"tuning"`` the record of the
        choice (:meth:`rsocl.solver.crossval.Tuning.as_params`, None when not tuned) and
        ``"start"`` every tile's first iterate (``"interp3d"`` or ``"zeros"``).
    pieces : list of rsocl.scale.work.Piece
        The tasks run now (blocks dropped), with their sub-frames, seconds and residual.
    skipped : int
        Tasks already done in the store, not run again.
    failures : list of rsocl.scale.runner.Failure
    seconds : float
        Wall-clock time of the run (the tuning included), seconds.
    store : Path or None
    tuning : rsocl.solver.crossval.Tuning or None
        The values chosen for every tile, None when not tuned.
    """

    datacube: object
    rig: Rig
    params: dict
    pieces: list = field(default_factory=list)
    skipped: int = 0
    failures: list = field(default_factory=list)
    seconds: float = 0.0
    store: Path | None = None
    tuning: Tuning | None = None

    @property
    def trimmed(self):
        """The ``T_se`` sub-frames kept by the rig's trimming rule (of every set)."""
        return self.datacube[..., self.rig.kept_subframes(), :, :]


class TilesFailed(RuntimeError):
    """Some tasks failed on every attempt; ``result`` holds the others (and ``failures``).

    The message says where the solved tasks are: in the store (``out``), where a re-run redoes only
    the failed ones, or only in ``result`` (in memory, nothing written); then one line per failure.
    """

    def __init__(self, result: TiledResult):
        self.result = result
        solved = len(result.pieces) + result.skipped
        if result.store:
            kept = f"{solved} kept in {result.store} (run again to redo only the failed ones)"
        else:
            kept = (
                f"{solved} solved, held in memory in this exception's result only (nothing written; with "
                f"out= a Zarr store the solved tiles are kept there and a re-run redoes only the failed ones)"
            )
        super().__init__(f"{len(result.failures)} task(s) failed, {kept}:\n  " + "\n  ".join(self.lines))

    @property
    def lines(self) -> list:
        """One line per failed task: its tile (and set), attempts and cause."""
        return [str(f) for f in self.result.failures]


def _source(snapshots, rig):
    if isinstance(snapshots, CaptureSets):
        if snapshots.rig != rig:
            raise ValueError("rig must be the capture file's rig (CaptureSets.rig)")
        return snapshots
    return ArraySets(snapshots, rig)


def _check_tile_memory(rig, grid, reg, dtype, projection, device):
    """ValueError naming ``tile`` when the tile needing the most device memory, the one modelling the most
    sub-frames times pixels (:func:`~rsocl.scale.proposal.tiling_cost`), would not fit this process's
    device."""
    from rsocl.device.context import get_device
    from rsocl.scale.proposal import tiling_cost

    dev = get_device(device)
    dev.real_dtype(dtype)
    total, largest, _, worst, voxels = tiling_cost(
        rig, grid.tile, grid.halo, regularizer=reg, dtype=dtype, projection=projection
    )
    limit = device_limit(dev, largest, total)
    if limit is not None:
        h, w = worst.outer_shape
        raise ValueError(
            f"tile: a tile of {grid.tile[0]}x{grid.tile[1]} ({worst.describe()}: {h}x{w} with the halo, "
            f"{voxels // (h * w)} sub-frames) needs {limit} ({dev.name}); choose a smaller tile (rsocl plan "
            f"proposes one)"
        )


@contextmanager
def _before_the_store(out):
    """Around a run into the store at ``out``: yields a list the run appends the store to once it has
    checked (or made) it; an interrupt before then that says nothing yet is re-raised, of its own type,
    saying that nothing was computed and what is at ``out``."""
    checked = []
    try:
        yield checked
    except KeyboardInterrupt as exc:
        if out is None or checked or str(exc):
            raise
        path = Path(os.fspath(out))
        held = path.is_dir() and any(path.iterdir())
        where = f"the store at {out} (not checked yet) is unchanged" if held else f"no store made at {out}"
        raise type(exc)(f"nothing computed; {where}") from None


def _check_device(device, engine):
    """ValueError naming ``device`` when it is a :class:`~rsocl.device.Device` and the tasks run in
    other processes (a cluster's workers), which open their own OpenCL contexts from a spec."""
    if isinstance(device, Device) and engine.mode == "distributed":
        raise ValueError(
            f"device must be a device spec string for the workers of {engine.description} (each "
            f"worker process opens its own OpenCL context), e.g. 'pocl', '0:0' or 'nvidia' (rsocl "
            f"devices lists them), or None to let each worker choose; got a Device ({device.name})"
        )


def reconstruct_tiled(
    snapshots,
    rig: Rig,
    regularizer="tv",
    *,
    tile,
    halo=None,
    iterations=None,
    lam=None,
    eta=None,
    tv_iterations=None,
    projection="exact",
    device=None,
    dtype="float32",
    regularizer_options=None,
    saturation=None,
    out=None,
    scheduler=None,
    workers=None,
    retries=RETRIES,
    tune=True,
    blend=None,
    progress=False,
    quality="balanced",
) -> TiledResult:
    """Reconstruct ``snapshots`` tile by tile (and set by set) as tasks of a Dask graph.

    Parameters
    ----------
    snapshots : array_like or CaptureSets
        ``(K, m, n)`` (one set), ``(S, K, m, n)`` (``S`` sets) or a capture file read by the
        tasks themselves (:class:`rsocl.scale.inputs.CaptureSets`).
    rig : Rig
    regularizer : str
        Registry name (tasks build their own instance).
    tile : (int, int)
        Core of a tile, ``(H, W)`` pixels: ``1 <= H <= m``, ``1 <= W <= n``.
    halo : int
        Pixels added on every side of a tile and cropped off after (default None: 16, or the grid's
        larger side where that is smaller).
    iterations, lam, eta, tv_iterations, projection, dtype, regularizer_options, saturation
        As :func:`rsocl.reconstruct`, for every tile; ``lam`` and ``eta`` may give one value per
        set (``S`` of them), every tile of a set running with that set's. A set with no pixel
        below ``saturation`` is refused (as untiled); a tile with none (its halo included) is not
        solved and holds the ``interp3d`` interpolation of its clipped samples, the untiled
        tuned run's start there (:func:`~rsocl.scale.work.solve_tile`).
    device : str, Device or None
        OpenCL device spec for every task; None lets each worker choose (:func:`worker_device`).
        A :class:`~rsocl.device.Device` serves tasks run in this process only (not with
        ``scheduler`` or ``workers``: a ValueError).
    out : str, os.PathLike or None
        Zarr store to write (each task writes its own chunks; an existing store of the same
        reconstruction is resumed). None: the datacube is assembled in memory.
    scheduler, workers
        See :class:`rsocl.scale.runner.Engine`.
    retries : int
        Extra attempts of a failing task (>= 0).
    tune : bool or rsocl.solver.crossval.Tuning
        True (default): ``lam`` and the regularizer's tunable options that are left unset are
        chosen from the snapshots once, in this process, before any task runs, on the tile
        nearest the grid's centre (with its halo, over its own rig) of the first set, as
        :func:`rsocl.reconstruct` chooses them (:mod:`rsocl.scale.tuning_tile`); every tile of every
        set then runs with the chosen values and starts from the interpolation of its own
        snapshots. A single tile covering the grid gives ``rsocl.reconstruct(g, rig)``. The
        search costs about 1.75 runs of one tile. A :class:`~rsocl.solver.crossval.Tuning` (an
        earlier run's choice, e.g. the first window of a stream) is applied as it is. False:
        the fixed defaults, zero start. The record is in ``params["tuning"]`` (and a store's
        ``params`` attribute).
    blend : float or None
        As :func:`rsocl.reconstruct`: every tile returns ``start + blend (theta - start)``; None
        (default): the search's choice (1 without a search). Below 1 it needs the interpolation
        start of a self-tuned run.
    progress : bool
        A progress bar over the tuning candidates and the tasks.
    quality : {"fast", "balanced", "best"}
        The rung of :mod:`rsocl.solver.ladder` the search and every tile follow (iterations, search);
        ``iterations="auto"`` is refused (every tile runs the same count).

    Raises
    ------
    TilesFailed
        When tasks still fail after their retries; the other tiles are kept (in the store).
    ValueError
        Before anything is read or computed, for an input out of range (naming it), and for an
        ``out`` holding anything but a store of this rig (row maps included), tiling, dtype and
        parameters known before the search (all but what it chooses:
        :func:`~rsocl.scale.run_settings.known_params`); once the parameters are chosen, for a
        store of other snapshots or parameters.
    KeyboardInterrupt
        An interrupt before the store at ``out`` is checked says so: nothing computed, the store
        unchanged.
    """
    if not isinstance(rig, Rig):
        raise ValueError(f"rig must be an rsocl.Rig, got {type(rig).__name__}")
    source = _source(snapshots, rig)
    if not isinstance(regularizer, str):
        raise ValueError(
            f"regularizer must be a registry name for a tiled reconstruction (each task builds its "
            f"own), got {regularizer!r}"
        )
    retries = non_negative_int("retries", retries)
    if saturation is not None:
        saturation = check.positive("saturation", saturation, "(snapshot units)")
    request = make_request(
        rig,
        regularizer,
        sets=source.n_sets,
        iterations=iterations,
        lam=lam,
        eta=eta,
        tv_iterations=tv_iterations,
        projection=projection,
        dtype=dtype,
        device=device,
        regularizer_options=regularizer_options,
        tune=tune,
        blend=blend,
        progress=progress,
        quality=quality,
    )
    if request.auto:
        raise ValueError(
            "iterations='auto' applies to rsocl.reconstruct and reconstruct_sets; a tiled run gives every "
            "tile one count: give a number"
        )
    grid = tile_grid(rig.shape, tile, check_halo(halo, rig.shape))
    check_local(request.regularizer, len(grid))
    engine = Engine(scheduler, workers)
    _check_device(device, engine)
    with _before_the_store(out) as checked:  # an interrupt before the store is checked leaves it as it was
        store = None
        if out is not None:  # an existing store: its rig, tiling, dtype and settings, before the input is read
            from rsocl.scale.store import StoreSpec, check_store

            dtype_name, before = str(np.dtype(request.dtype)), known_params(request, saturation, grid)
            known = StoreSpec(rig, grid.tile, grid.halo, grid.grid, source.n_sets, dtype_name, before, "")
            store = check_store(out, known, "out").absolute()  # workers may run in another folder
        if engine.mode != "distributed":
            _check_tile_memory(rig, grid, request.regularizer, dtype, request.settings.projection, device)
        span = rig.sampled_range()
        with engine:  # a cluster is reached (or started) before the input is read
            began = time.perf_counter()
            digest, saturated, measured = scan(source, saturation)
            tuning = tune_tiles(source, grid, request, saturation)
            settings, params = tile_settings(request, tuning, saturation)
            settings = replace(settings, frame_levels=measured)  # every tile's static-part fix: its frame's
            params.update(
                {
                    "saturated_pixels": saturated,
                    "solved_subframes": [span.start, span.stop],
                    "tile": list(grid.tile),
                    "halo": grid.halo,
                }
            )
            done = np.zeros((source.n_sets or 1,) + grid.grid, dtype=bool)
            identity = None
            if store is not None:
                from rsocl.scale.store import prepare_store

                spec = StoreSpec(rig, grid.tile, grid.halo, grid.grid, source.n_sets, settings.dtype, params, digest)
                done, identity = prepare_store(store, spec)  # the id of the store this run checked
                checked.append(store)
            sets = [None] if source.n_sets is None else list(range(source.n_sets))
            jobs = [
                Job(s, t, source.block(s, t), (span.start, span.stop), None if store is None else str(store), identity)
                for s in sets
                for t in grid
                if not done[(s or 0,) + t.index]
            ]
            payload = RigPayload.of(rig)
            pieces, failures = engine.run(
                jobs,
                payload,
                settings,
                retries=retries,
                progress=progress,
                desc="tiles" if source.n_sets is None else "tiles x sets",
            )
            seconds = time.perf_counter() - began
    if store is not None:
        from rsocl.scale.store import load_store

        datacube = load_store(store).datacube
    else:
        cube = (rig.T,) + rig.shape
        datacube = np.zeros(((source.n_sets,) if source.n_sets else ()) + cube, dtype=settings.dtype)
        tiles = {t.index: t for t in grid}
        for piece in pieces:
            target = datacube if piece.set_index is None else datacube[piece.set_index]
            place(target, tiles[piece.index], piece.start, piece.block, (span.start, span.stop))
            piece.block = None
    if params.get("device") is None and pieces:  # none asked for: the devices the tasks ran on
        devices = sorted({piece.device for piece in pieces})
        params["device"] = devices[0] if len(devices) == 1 else devices
    result = TiledResult(datacube, rig, params, pieces, int(done.sum()), failures, seconds, store, tuning)
    if failures:
        raise TilesFailed(result)
    return result
