"""The tile a tiled reconstruction is tuned on: one choice for every tile and set.

:func:`rsocl.reconstruct` chooses ``lam`` and the regularizer's tunable options from the
snapshots (:func:`rsocl.solver.pipeline.tune`). A tiled run makes that choice once, in the client,
before any task is submitted: on the tile whose core is nearest the grid's centre (its block
with the halo, over its own rig, cut as every tile is by :func:`rsocl.scale.tiles.tile_rig`), of
the first set; the next nearest when every pixel of that block is saturated. Every tile of
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

__all__ = ["by_distance_to_centre", "tune_tiles"]


def by_distance_to_centre(grid: TileGrid) -> list:
    """The tiles, nearest the grid's centre first (by their cores' centres; ties in row-major order)."""
    m, n = grid.shape

    def distance(tile: Tile):
        y0, y1, x0, x1 = tile.core
        return ((y0 + y1) - m) ** 2 + ((x0 + x1) - n) ** 2

    return sorted(grid, key=distance)


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
    or what the caller left unset chosen on the centre tile of the first set.

    Parameters
    ----------
    source : rsocl.scale.inputs.ArraySets or rsocl.scale.inputs.CaptureSets
    grid : TileGrid
    request : rsocl.solver.request.Request
        The whole capture's request (its rig, settings settled for that rig, ``tune``); the search
        runs on this process's device (:func:`~rsocl.scale.work.worker_device` of its device).
    saturation : float or None
        Snapshot value from which a pixel is left out, as :func:`rsocl.reconstruct`'s.

    Returns
    -------
    rsocl.solver.crossval.Tuning or None
        None when the request does not tune or nothing was left to choose.
    """
    if request.tune is not True:
        return request.tune if isinstance(request.tune, Tuning) else None
    tile, g = _tuning_block(source, grid, saturation)
    problem = check_problem(g, tile_rig(request.rig, tile), saturation=saturation)
    return tune(prepare(replace(request, device=worker_device(request.device)), problem, start=False))
