"""The self-tuning step of a tiled reconstruction: one choice for every tile and set.

:func:`rsocl.reconstruct` chooses ``lam`` and the regularizer's tunable options from the
snapshots (:mod:`rsocl.solver.pipeline`). A tiled run makes that choice once, in the client,
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

from rsocl.scale.tiles import Tile, TileGrid, tile_rig
from rsocl.scale.work import Job, worker_device
from rsocl.solver.pipeline import choose_unset, chosen_options
from rsocl.solver.problem import check_problem, stage_on_device
from rsocl.solver.reconstruct import make_regularizer

__all__ = ["by_distance_to_centre", "tune_tiles", "tuned_options"]


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


def tune_tiles(source, rig, grid: TileGrid, regularizer: str, settings, fixed_lam, regularizer_options, *,
               device=None, dtype="float32", saturation=None, progress=False):
    """Choose what the caller left unset on the centre tile of the first set.

    Parameters
    ----------
    source : rsocl.scale.inputs.ArraySets or rsocl.scale.inputs.CaptureSets
    rig : Rig
        The whole capture's rig.
    grid : TileGrid
    regularizer : str
        Registry name.
    settings : rsocl.solver.problem.Settings
        Checked and settled for the regularizer (every tile's ``iterations``, ``eta``, ...).
    fixed_lam : float or None
        The caller's ``lam`` (None: searched).
    regularizer_options : dict or None
        The caller's options (these are not searched).
    device, dtype, saturation, progress
        As :func:`rsocl.reconstruct`; the search runs on this process's device.

    Returns
    -------
    rsocl.solver.crossval.Tuning or None
        None when nothing was left to choose.
    """
    tile, g = _tuning_block(source, grid, saturation)
    problem = check_problem(g, tile_rig(rig, tile), saturation=saturation)
    reg = make_regularizer(regularizer, regularizer_options, settings.tv_iterations)
    staged = stage_on_device(problem, reg, settings, device=worker_device(device), dtype=dtype)
    return choose_unset(problem, staged, settings, regularizer, reg, regularizer_options, fixed_lam,
                        make_regularizer, progress=progress)


def tuned_options(tuning, regularizer_options) -> dict:
    """The regularizer options every tile runs with: the caller's, with the chosen ones over them."""
    return {**dict(regularizer_options or {}), **({} if tuning is None else chosen_options(tuning))}
