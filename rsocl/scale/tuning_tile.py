"""The tile a tiled reconstruction is tuned on: one choice for every tile and set.

:func:`rsocl.reconstruct` chooses ``lam`` and the regularizer's tunable options from the
snapshots (:func:`rsocl.solver.pipeline.tune`). A tiled run makes that choice once, in the client,
before any task is submitted, on the first set: on the block of :data:`TUNE_SIDE` pixels a side
(or a tile's reconstructed block where that is larger; the whole grid where it is smaller) centred
on the grid, over its own rig, cut as every tile is by :func:`rsocl.scale.tiles.tile_rig`; where
that search does not fit the device or every pixel of the block is saturated, on the tile whose
core is nearest the grid's centre (its block with the halo), the next nearest when every pixel of
that one is saturated. One small tile is a poor sample of the scene: its choice can differ from
the whole frame's (docs/scale_tuning.md). Every tile of
every set then runs with the chosen values, so neighbouring tiles cannot differ in their
settings, and starts from the
:func:`~rsocl.model.interpolation.interp3d` interpolation of its own snapshots, as the untiled
tuned run does. A single tile covering the grid therefore runs exactly as
``rsocl.reconstruct(g, rig)``.
"""

from __future__ import annotations

from dataclasses import replace

from rsocl.scale.tiles import Tile, TileGrid, tile_rig
from rsocl.scale.work import Job, worker_device
from rsocl.solver.pipeline import Request, Tuning, check_problem, prepare, tune

__all__ = ["TUNE_SIDE", "by_distance_to_centre", "tuning_crop", "tune_tiles"]

#: Side, pixels, of the centred block a tiled run chooses its parameters on (measured in
#: ``docs/scale_tuning.md``).
TUNE_SIDE = 128


def by_distance_to_centre(grid: TileGrid) -> list:
    """The tiles, nearest the grid's centre first (by their cores' centres; ties in row-major order)."""
    m, n = grid.shape

    def distance(tile: Tile):
        y0, y1, x0, x1 = tile.core
        return ((y0 + y1) - m) ** 2 + ((x0 + x1) - n) ** 2

    return sorted(grid, key=distance)


def tuning_crop(grid: TileGrid) -> Tile:
    """The block the search runs on: :data:`TUNE_SIDE` pixels a side, or a tile's reconstructed block
    (core and halo) where that is larger, within the grid, centred on it (``core == outer``)."""
    (m, n), (h, w), halo = grid.shape, grid.tile, grid.halo
    rows, cols = min(m, max(TUNE_SIDE, h + 2 * halo)), min(n, max(TUNE_SIDE, w + 2 * halo))
    y0, x0 = (m - rows) // 2, (n - cols) // 2
    box = (y0, y0 + rows, x0, x0 + cols)
    return Tile((-1, -1), box, box)


def _crop_block(source, grid: TileGrid, saturation):
    """:func:`tuning_crop` and its snapshots of the first set, or None when every pixel is saturated."""
    crop = tuning_crop(grid)
    set_index = None if source.n_sets is None else 0
    g = Job(set_index, crop, source.block(set_index, crop), (0, 0)).snapshots()
    return (crop, g) if saturation is None or (g < saturation).any() else None


def _search(block, request: Request, saturation):
    """The search of ``request`` on ``block`` (a tile and its snapshots), on this process's device."""
    tile, g = block
    problem = check_problem(g, tile_rig(request.rig, tile), saturation=saturation)
    return tune(prepare(replace(request, device=worker_device(request.device)), problem, start=False))


def _tuning_block(source, grid: TileGrid, saturation):
    """The tile to tune on and its snapshots of the first set: the nearest the centre with a pixel
    below saturation (the nearest when every tile is saturated: :func:`check_problem` says so)."""
    set_index = None if source.n_sets is None else 0
    nearest = None
    for tile in by_distance_to_centre(grid):
        g = Job(set_index, tile, source.block(set_index, tile), (0, 0)).snapshots()
        if saturation is None or (g < saturation).any():
            return tile, g
        nearest = nearest or (tile, g)
    return nearest


def tune_tiles(source, grid: TileGrid, request: Request, saturation=None):
    """The choice every tile runs with: the request's earlier :class:`~rsocl.solver.crossval.Tuning`,
    or what the caller left unset chosen on the centre block of the first set (module doc).

    Parameters
    ----------
    source : rsocl.scale.inputs.ArraySets or rsocl.scale.inputs.CaptureSets
    grid : TileGrid
    request : rsocl.solver.request.Request
        The whole capture's request (its rig, settings settled for that rig, ``tune``); the search
        runs on this process's device (:func:`~rsocl.scale.work.worker_device` of its device).
    saturation : float or None
        Snapshot value at and above which a pixel is clipped, as :func:`rsocl.reconstruct`'s.

    Returns
    -------
    rsocl.solver.crossval.Tuning or None
        None when the request does not tune or nothing was left to choose.
    """
    if request.tune is not True:
        return request.tune if isinstance(request.tune, Tuning) else None
    crop = _crop_block(source, grid, saturation)
    if crop is not None:
        try:
            return _search(crop, request, saturation)
        except ValueError as exc:
            if "device" not in str(exc):  # only a search too large for the device falls back
                raise
    return _search(_tuning_block(source, grid, saturation), request, saturation)
