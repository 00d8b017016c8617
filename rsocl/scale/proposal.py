"""Propose a tiling for a reconstruction: tile size, halo, tasks, per-task memory, total time.

Each tile's cost follows from its own rig (the full rig cut to the tile plus its halo): the
sub-frames its exposure windows touch times its pixels. The proposal takes the largest square
tile (from :data:`CANDIDATES`, cut to the grid) whose largest task fits the device: its largest
buffer within the device's largest allocation and all its buffers within ``budget`` (default:
half the device's memory, room for the host's copies and a second task). The time is measured
on the largest tile (3 iterations, after one to compile) and scaled, per modelled voxel, to
every tile, set and iteration.
"""

from __future__ import annotations

from dataclasses import dataclass

from rsocl.device.context import get_device
from rsocl.model.rig import Rig
from rsocl.scale.tiles import check_halo, check_tile, tile_grid, tile_rig
from rsocl.solver.memory import memory_need
from rsocl.solver.pipeline import make_regularizer
from rsocl.solver.plan import estimate

__all__ = ["CANDIDATES", "Tiling", "tiling_cost", "propose_tiling", "format_tiling"]

#: Tile sides tried, pixels, largest first.
CANDIDATES = (1024, 768, 512, 384, 256, 192, 128, 96, 64, 48, 32, 16)


@dataclass
class Tiling:
    """A proposed tiling and its cost.

    ``memory_bytes``/``buffer_bytes``: device memory of the largest task, all buffers and the
    largest one; ``voxels``: sub-frames times pixels modelled over all tiles of one set (the
    untiled problem models ``untiled_voxels``); ``seconds_per_iteration``: measured on the
    largest tile (None when not measured).
    """

    rig: Rig
    tile: tuple
    halo: int
    grid: tuple
    sets: int
    memory_bytes: int
    buffer_bytes: int
    voxels: int
    untiled_voxels: int
    worst_voxels: int
    iterations: int
    budget_bytes: int
    seconds_per_iteration: float | None = None

    @property
    def tasks(self) -> int:
        return self.grid[0] * self.grid[1] * self.sets

    @property
    def seconds(self) -> float | None:
        """Estimated device time of every task, one device, seconds."""
        if self.seconds_per_iteration is None:
            return None
        per_voxel = self.seconds_per_iteration / self.worst_voxels
        return per_voxel * self.voxels * self.iterations * self.sets


def tiling_cost(rig: Rig, tile, halo, *, regularizer="tv", dtype="float32", projection="exact"):
    """``(largest task's total bytes, its largest buffer, modelled voxels, the largest tile, its voxels)``.

    Each tile's sampled sub-frames come from the whole rig's windows (:meth:`Rig.sampled_range` of
    the tile's ROI); only the largest tile's rig is built, for its memory. ``regularizer``: a
    registry name (default options) or the configured instance (:mod:`rsocl.solver.memory`).
    """
    worst, most, voxels = None, 0, 0
    for t in tile_grid(rig.shape, tile, halo):
        solved = rig.sampled_range(t.roi)  # the tile's rig's, from the whole rig's windows
        h, w = t.outer_shape
        v = (solved.stop - solved.start) * h * w
        voxels += v
        if v > most:
            worst, most = t, v
    assert worst is not None  # tile_grid yields at least one tile
    largest, total = memory_need(
        tile_rig(rig, worst), make_regularizer(regularizer), dtype=dtype, projection=projection
    )
    return total, largest, voxels, worst, most


def propose_tiling(
    rig: Rig,
    *,
    tile=None,
    halo=None,
    sets=1,
    iterations=200,
    regularizer="tv",
    dtype="float32",
    projection="exact",
    device=None,
    budget_bytes=None,
    measure=True,
) -> Tiling:
    """The tiling of ``rig`` for ``device``: ``tile`` checked, or the largest that fits proposed.

    Parameters
    ----------
    tile : (int, int) or None
        Tile to cost; None proposes one.
    halo : int or None
        Pixels on every side of a tile (None: :func:`rsocl.scale.tiles.check_halo`'s default).
    sets : int
        Sets to reconstruct (each the same tasks).
    budget_bytes : int or None
        Device memory one task may use, bytes (default: half the device's memory).

    Raises
    ------
    ValueError
        When the given tile (or the smallest candidate) does not fit (naming ``tile``).
    """
    dev = get_device(device)
    dev.real_dtype(dtype)
    halo = check_halo(halo, rig.shape)
    sets = int(sets)
    if sets < 1:
        raise ValueError(f"sets must be >= 1, got {sets}")
    budget = int(dev.global_mem_bytes // 2 if budget_bytes is None else budget_bytes)
    m, n = rig.shape
    kwargs = dict(regularizer=regularizer, dtype=dtype, projection=projection)

    def fits(cost):
        return cost[1] <= dev.max_alloc_bytes and cost[0] <= min(budget, dev.global_mem_bytes)

    if tile is not None:
        tile = check_tile(tile, rig.shape)
        cost = tiling_cost(rig, tile, halo, **kwargs)
        if not fits(cost):
            raise ValueError(
                f"tile: a task of tile {tile[0]}x{tile[1]} with halo {halo} needs "
                f"{cost[0] / 2**20:.1f} MiB (largest buffer {cost[1] / 2**20:.1f} MiB), above the "
                f"budget of {budget / 2**20:.1f} MiB or the device's limits ({dev.name})"
            )
    else:
        for side in sorted({min(c, m) for c in CANDIDATES} | {min(c, n) for c in CANDIDATES}, reverse=True):
            tile = (min(side, m), min(side, n))
            cost = tiling_cost(rig, tile, halo, **kwargs)
            if fits(cost):
                break
        else:
            hint = (
                "raise budget_bytes (rsocl plan --memory-mib) or dt (fewer sub-frames)"
                if budget_bytes is not None
                else "raise dt (fewer sub-frames) or use a device with more memory"
            )
            raise ValueError(
                f"no tile of {CANDIDATES[-1]} pixels a side or more fits the budget of "
                f"{budget / 2**20:.1f} MiB per task on {dev.name}; {hint}"
            )
    total, largest, voxels, worst, worst_voxels = cost
    untiled = rig.sampled_range()
    result = Tiling(
        rig,
        tile,
        halo,
        tile_grid(rig.shape, tile, halo).grid,
        sets,
        total,
        largest,
        voxels,
        (untiled.stop - untiled.start) * m * n,
        worst_voxels,
        iterations,
        budget,
    )
    if measure:
        sub = tile_rig(rig, worst)
        result.seconds_per_iteration = estimate(
            sub,
            iterations=iterations,
            regularizer=regularizer,
            dtype=dtype,
            device=dev,
            measure=True,
            projection=projection,
        ).seconds_per_iteration
    return result


def format_tiling(t: Tiling) -> str:
    """The proposal as a few lines of text."""
    lines = [
        f"tiling: {t.tile[0]} x {t.tile[1]} pixels with a halo of {t.halo} "
        f"({t.grid[0]} x {t.grid[1]} tiles{f' x {t.sets} sets' if t.sets > 1 else ''} = {t.tasks} tasks)",
        f"per-task device memory: {t.memory_bytes / 2**20:.1f} MiB at most (largest buffer "
        f"{t.buffer_bytes / 2**20:.1f} MiB; budget {t.budget_bytes / 2**20:.1f} MiB)",
        f"modelled voxels: {t.voxels / t.untiled_voxels:.2f}x the untiled problem's "
        f"({t.voxels:,} against {t.untiled_voxels:,}, halos included, per set)",
    ]
    if t.seconds_per_iteration is not None and t.seconds is not None:
        lines.append(
            f"time: {t.seconds_per_iteration * 1e3:.1f} ms/iteration measured on the largest tile; "
            f"all {t.tasks} tasks x {t.iterations} iterations on one device: about {t.seconds:.0f} s "
            f"({t.seconds / 60:.1f} min); N devices (--workers N): about 1/N of it"
        )
    lines.append(
        f"run it: rsocl reconstruct CAPTURE --out rec.zarr --tile {t.tile[0]} {t.tile[1]}"
        + (f" --halo {t.halo}" if t.halo != check_halo(None, t.rig.shape) else "")
        + (" --sets" if t.sets > 1 else "")
    )
    return "\n".join(lines)
