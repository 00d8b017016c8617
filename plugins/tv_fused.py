"""The TV plugin's fused path: several Chambolle iterations per launch on tiles in local memory.

``kernels/tv_fused.cl`` gives each work group a tile of the datacube with a halo (temporal
blocking): it runs up to ``fused`` dual updates in local memory and writes back the tile's
interior. A denoising call of ``I`` iterations (``I - 1`` dual updates and the final primal) is a
few launches instead of ``2 I - 1``, and the datacube crosses global memory once per launch.

:func:`plan` sizes the tiles from the device's local memory and work-group limits, queried, never
assumed: it picks, for each number of updates per launch up to ``fused``, the tile whose regions
(interior and halo) load the fewest voxels, and keeps the choice that moves the fewest bytes. When
no tile moves fewer bytes than the plain path (a device with little local memory), it returns
None and the plugin takes the plain path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Launch", "FusedPlan", "plan", "schedule", "plain_values", "enqueue"]

#: A plan is kept only when it moves at most this share of the plain path's bytes.
KEEP_BELOW = 0.9


@dataclass(frozen=True)
class Launch:
    """One launch: ``updates`` dual updates; the first starts from p = 0, the final writes the output."""

    updates: int
    first: bool
    final: bool

    def halos(self, temporal: bool):
        """Halo layers ``(below, above)`` along y and x, and along t (none without a temporal term)."""
        below = self.updates + int(self.final) - int(self.first)
        space = (below, self.updates)
        return space, (space if temporal else (0, 0))

    @property
    def mode(self) -> int:
        """``mode`` of ``tv_fused`` (bit 0: p = 0, bit 1: final; bit 2, the ADMM dual, is the caller's)."""
        return int(self.first) | (2 * int(self.final))


def schedule(iterations: int, per_launch: int) -> tuple:
    """The launches of one denoising call: ``iterations - 1`` updates in balanced launches of at most
    ``per_launch``, then the final primal (in the last launch)."""
    updates = int(iterations) - 1
    count = max(1, math.ceil(updates / per_launch)) if updates else 1
    sizes = [updates // count + (1 if i < updates % count else 0) for i in range(count)]
    return tuple(Launch(u, i == 0, i == count - 1) for i, u in enumerate(sizes))


def plain_values(iterations: int, temporal: bool) -> int:
    """Values read or written per voxel by one denoising call on the plain path (``tv.cl``).

    ``tv_dual_first`` reads the input and writes p; each ``tv_primal`` reads the input and p and
    writes the output; each ``tv_dual`` reads the output and p and writes p (neighbours counted
    once, as from cache). One iteration is a copy.
    """
    planes = 3 if temporal else 2
    if iterations == 1:
        return 2
    return (1 + planes) + (iterations - 1) * (planes + 2) + (iterations - 2) * (1 + 2 * planes)


def _covered(extent: int, tile: int, below: int, above: int) -> int:
    """Voxels along one axis that the regions of all tiles of ``tile`` load (halos clipped to the axis)."""
    return sum(min(start + tile + above, extent) - max(start - below, 0) for start in range(0, extent, tile))


@dataclass(frozen=True)
class FusedPlan:
    """Tiles, work groups and launches of the fused path for one datacube shape and device."""

    tile: tuple  # interior (AX, AY, AT), voxels
    local: tuple  # work group (LX, LY)
    cap: int  # voxels of the largest region (each local array's length)
    launches: tuple  # Launch, in order
    temporal: bool
    shape: tuple  # (sets, T, m, n)

    @property
    def arrays(self) -> int:
        return 5 if self.temporal else 4

    def local_values(self) -> int:
        """Length of the kernel's local memory argument, values (arrays with their guard values)."""
        return self.arrays * (self.cap + 1) + 1

    def tiles_t(self) -> int:
        return -(-self.shape[1] // self.tile[2])

    def grid(self):
        """Global and local sizes of ``tv_fused``."""
        sets, T, m, n = self.shape
        (ax, ay, _), (lx, ly) = self.tile, self.local
        return (-(-n // ax) * lx, -(-m // ay) * ly, sets * self.tiles_t()), (lx, ly, 1)

    def loaded(self, launch: Launch) -> float:
        """Voxels the regions of ``launch`` load, per voxel of the datacube (1 = no halo)."""
        _, T, m, n = self.shape
        (below, above), (t_below, t_above) = launch.halos(self.temporal)
        ax, ay, at = self.tile
        return (_covered(n, ax, below, above) * _covered(m, ay, below, above) * _covered(T, at, t_below, t_above)) / (
            n * m * T
        )

    def values(self, dual: bool = False) -> float:
        """Values read or written from global memory per voxel by one denoising call.

        Each launch reads the input and (unless it is the first) p over its regions, and writes
        p (or, the final one, the output: with ``dual`` also the ADMM's b and f) over the interiors.
        """
        planes = 3 if self.temporal else 2
        total = 0.0
        for launch in self.launches:
            total += self.loaded(launch) * (1 + (0 if launch.first else planes))
            total += (1 + (2 if dual else 0)) if launch.final else planes
        return total

    def p_buffers(self) -> int:
        """Dual arrays in global memory: none for one launch, one for two, two (read, write) for more."""
        return min(len(self.launches) - 1, 2)


def plan(
    shape, itemsize: int, iterations: int, fused: int, temporal: bool, *, local_bytes: int, group: int, max_items
) -> FusedPlan | None:
    """The fused plan for a datacube ``shape = (sets, T, m, n)`` within the device's limits, or None.

    ``local_bytes``: local memory a work group may use (the device's, less what the kernel
    reserves); ``group``: most work items per work group (device and kernel); ``max_items``: most
    along dimensions 0 and 1. Tries 1 to ``fused`` updates per launch and returns the plan that
    moves the fewest bytes, when that is below :data:`KEEP_BELOW` of the plain path's.
    """
    sets, T, m, n = (int(v) for v in shape)
    arrays = 5 if temporal else 4
    cap_max = (int(local_bytes) // int(itemsize) - 1) // arrays - 1
    limit = KEEP_BELOW * plain_values(iterations, temporal)
    best, best_values = None, math.inf
    for per_launch in range(1, max(1, int(fused)) + 1):
        launches = schedule(iterations, per_launch)
        halos = [launch.halos(temporal) for launch in launches]
        below, above = max(h[0][0] for h in halos), max(h[0][1] for h in halos)
        t_below, t_above = max(h[1][0] for h in halos), max(h[1][1] for h in halos)
        choice = _tile(T, m, n, below, above, t_below, t_above, cap_max)
        if choice is None:
            continue
        tile, cap = choice
        rx, ry = min(tile[0] + below + above, n), min(tile[1] + below + above, m)
        lx = max(1, min(rx, int(max_items[0]), int(group)))
        ly = max(1, min(ry, int(max_items[1]), int(group) // lx))
        candidate = FusedPlan(tile, (lx, ly), cap, launches, bool(temporal), (sets, T, m, n))
        values = candidate.values()
        if values < best_values:
            best, best_values = candidate, values
        if len(launches) == 1:
            break
    return best if best is not None and best_values <= limit else None


def _sizes(extent: int) -> list:
    """Tile lengths worth trying along an axis of ``extent``: powers of two below it, and the whole axis."""
    sizes = {extent}
    size = 1
    while size < extent:
        sizes.add(size)
        size *= 2
    return sorted(sizes)


def _tile(T, m, n, below, above, t_below, t_above, cap_max):
    """The interior ``(AX, AY, AT)`` whose regions load the fewest voxels, with its region's size; None
    when no region fits ``cap_max`` voxels. Ties go to longer rows (contiguous, vectorisable)."""
    best, best_key = None, None
    for ax in _sizes(n):
        rx = min(ax + below + above, n)
        cover_x = _covered(n, ax, below, above)
        for ay in _sizes(m):
            ry = min(ay + below + above, m)
            if rx * ry > cap_max:
                break
            cover_xy = cover_x * _covered(m, ay, below, above)
            for at in _sizes(T):
                rt = min(at + t_below + t_above, T)
                if rx * ry * rt > cap_max:
                    break
                key = (cover_xy * _covered(T, at, t_below, t_above), -ax, -ay)
                if best_key is None or key < best_key:
                    best, best_key = ((ax, ay, at), rx * ry * rt), key
    return best


def enqueue(prog, plan: FusedPlan, x, steps, out, buffers, dual, update: bool):
    """Enqueue the launches of ``plan`` (``tv_fused`` of ``prog``): ``out = denoise(x)`` with the per-set
    ``steps`` of ``tv.cl``, on the dual ``buffers`` (``plan.p_buffers()`` of them, at least one), and with
    ``update`` the ADMM's dual update of ``dual = (b, f, on)`` in the last launch (without it, any three
    arrays of the right types: they are not written). Returns ``out``."""
    import pyopencl as cl

    sets, T, m, n = plan.shape
    b, f, on = dual
    local = cl.LocalMemory(plan.local_values() * x.dtype.itemsize)
    gsize, lsize = plan.grid()
    for i, launch in enumerate(plan.launches):
        (below, above), (t_below, t_above) = launch.halos(plan.temporal)
        p_in, p_out = buffers[(i - 1) % len(buffers)], buffers[i % len(buffers)]
        mode = launch.mode | (4 if update and launch.final else 0)
        sizes = (T, m, n, sets, plan.tiles_t(), *plan.tile, below, above, t_below, t_above, launch.updates, mode)
        prog.instance("tv_fused", i)(
            x.queue,
            gsize,
            lsize,
            x.data,
            p_in.data,
            p_out.data,
            out.data,
            b.data,
            f.data,
            on.data,
            steps.data,
            *(np.int32(v) for v in (*sizes, plan.cap)),
            local,
        )
    return out
