"""Spatial tiles of the reference grid: geometry, halos, sub-rigs, and blending.

A tile owns a ``core`` block of reference pixels; it is reconstructed over the core plus a
``halo`` of neighbouring pixels on every side (clipped at the grid's edges), then the halo is
cropped off and the core is placed into the whole datacube. Each core is owned by exactly one
tile, so a chunked store whose spatial chunks are the tiles gets every chunk from one task.

The tile's rig is the full rig cut to the tile (:meth:`rsocl.model.rig.Rig.crop`): every
camera's row map is the full one, cut, so each pixel keeps the exposure start
``t_a + r*t_r + k*t_d`` it has in the whole capture and the sub-frame indices of the tile are
those of the whole datacube. Only the sub-frames that the tile's exposure windows touch
(:meth:`rsocl.model.rig.Rig.sampled_range` of the tile's rig) are modelled; the tile's result
is that range, at its offset in the global ``T``. Each pixel of the tile holds the first modelled
sub-frame's value before that range and the last one's after it (nothing is measured there; a
constant continuation adds no temporal variation), as an untiled reconstruction holds its solved
range (:mod:`rsocl.solver.held`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from rsocl.model.rig import Rig
from rsocl.solver.held import held_index

__all__ = [
    "check_local",
    "rig_digest",
    "DEFAULT_HALO",
    "Tile",
    "TileGrid",
    "tile_grid",
    "check_tile",
    "check_halo",
    "tile_rig",
    "place",
    "expand",
    "core_block",
]

#: Halo on every side of a tile, pixels (how far tiles with it differ from the untiled run:
#: docs/scale.md).
DEFAULT_HALO = 16


@dataclass(frozen=True)
class Tile:
    """One tile of a :class:`TileGrid`.

    Attributes
    ----------
    index : (int, int)
        Row and column of the tile in the grid.
    core : (int, int, int, int)
        ``(y0, y1, x0, x1)``: the reference pixels the tile owns, rows ``y0..y1-1`` and
        columns ``x0..x1-1``.
    outer : (int, int, int, int)
        The core grown by the halo and clipped to the grid, same convention: the pixels the
        tile is reconstructed over.
    """

    index: tuple
    core: tuple
    outer: tuple

    @property
    def core_slices(self) -> tuple:
        """``(rows, cols)`` slices of the core in the whole grid."""
        y0, y1, x0, x1 = self.core
        return slice(y0, y1), slice(x0, x1)

    @property
    def outer_slices(self) -> tuple:
        """``(rows, cols)`` slices of the reconstructed block in the whole grid."""
        y0, y1, x0, x1 = self.outer
        return slice(y0, y1), slice(x0, x1)

    @property
    def inner_slices(self) -> tuple:
        """``(rows, cols)`` slices of the core within the reconstructed block."""
        y0, y1, x0, x1 = self.core
        oy, _, ox, _ = self.outer
        return slice(y0 - oy, y1 - oy), slice(x0 - ox, x1 - ox)

    @property
    def roi(self) -> tuple:
        """``(y, x, height, width)`` of the reconstructed block (the ROI of :meth:`~rsocl.model.rig.Rig.crop`)."""
        y0, y1, x0, x1 = self.outer
        return (y0, x0, y1 - y0, x1 - x0)

    @property
    def outer_shape(self) -> tuple:
        y0, y1, x0, x1 = self.outer
        return (y1 - y0, x1 - x0)

    def describe(self) -> str:
        """``tile (r, c) (rows y0..y1-1, columns x0..x1-1)``."""
        y0, y1, x0, x1 = self.core
        return f"tile {self.index} (rows {y0}..{y1 - 1}, columns {x0}..{x1 - 1})"


@dataclass(frozen=True)
class TileGrid:
    """Tiles of ``tile = (H, W)`` pixels covering a ``shape = (m, n)`` grid, row-major.

    The last row and column of tiles are smaller when ``H`` or ``W`` does not divide the grid.
    """

    shape: tuple
    tile: tuple
    halo: int

    @property
    def grid(self) -> tuple:
        """Tiles per column and per row, ``(ny, nx)``."""
        (m, n), (h, w) = self.shape, self.tile
        return (-(-m // h), -(-n // w))

    def __len__(self) -> int:
        ny, nx = self.grid
        return ny * nx

    def __iter__(self):
        (m, n), (h, w), halo = self.shape, self.tile, self.halo
        ny, nx = self.grid
        for iy in range(ny):
            for ix in range(nx):
                y0, x0 = iy * h, ix * w
                y1, x1 = min(m, y0 + h), min(n, x0 + w)
                outer = (max(0, y0 - halo), min(m, y1 + halo), max(0, x0 - halo), min(n, x1 + halo))
                yield Tile((iy, ix), (y0, y1, x0, x1), outer)

    def __getitem__(self, index) -> Tile:
        iy, ix = index
        ny, nx = self.grid
        if not (0 <= iy < ny and 0 <= ix < nx):
            raise IndexError(f"tile index {index} outside the {ny}x{nx} grid")
        return list(self)[iy * nx + ix]


def check_tile(tile, shape, name="tile") -> tuple:
    """``tile`` as ``(H, W)`` ints with ``1 <= H <= m`` and ``1 <= W <= n``; ValueError naming ``name``."""
    m, n = shape
    try:
        h, w = (int(v) for v in tile)
        ok = all(float(v) == int(v) for v in tile)
    except (TypeError, ValueError):
        ok = False
    if not ok or not (1 <= h <= m and 1 <= w <= n):
        raise ValueError(f"{name} must be (H, W) pixels with 1 <= H <= m = {m} and 1 <= W <= n = {n}, got {tile!r}")
    return (h, w)


def check_halo(halo, shape, name="halo") -> int:
    """``halo`` as an int in ``[0, max(m, n)]`` pixels; ValueError naming ``name``. None: the default,
    :data:`DEFAULT_HALO` or the grid's larger side where that is smaller (a halo is clipped at the
    grid's edges, so more would change nothing)."""
    limit = max(shape)
    if halo is None:
        return min(DEFAULT_HALO, limit)
    try:
        value = int(halo)
        ok = float(halo) == value
    except (TypeError, ValueError):
        ok = False
    if not ok or not 0 <= value <= limit:
        raise ValueError(f"{name} must be a whole number of pixels in [0, {limit}], got {halo!r}")
    return value


def check_local(regularizer, pieces: int, what: str = "tiles") -> None:
    """Refuse to split a run into ``pieces`` > 1 ``what`` with a regularizer that is not
    :attr:`~rsocl.solver.regularizer.Regularizer.local`: each piece would denoise with its own
    transform, which differs from the whole by as much as the signal (0.5-1.7 on data in [0, 1])."""
    if pieces > 1 and not getattr(regularizer, "local", True):
        raise ValueError(
            f"regularizer {regularizer.name!r} is not local (its transform spans the whole frame), so {pieces} "
            f"{what} would each denoise differently from a run in one piece: use regularizer 'tv' for a run "
            f"in {what}, or a tile that covers the grid"
        )


def tile_grid(shape, tile, halo=None) -> TileGrid:
    """The :class:`TileGrid` of ``tile = (H, W)`` pixels with ``halo`` pixels on every side."""
    shape = tuple(int(v) for v in shape)
    return TileGrid(shape, check_tile(tile, shape), check_halo(halo, shape))


def rig_digest(data: dict) -> str:
    """The SHA-256 (hex) of a rig's description ``data`` (:meth:`Rig.to_dict <rsocl.model.rig.Rig.to_dict>`),
    its cameras' row maps included: what names the whole capture's rig to the tasks and in a store."""
    digest = hashlib.sha256(repr({**data, "cameras": None}).encode())
    for camera in data["cameras"]:
        digest.update(repr({k: v for k, v in camera.items() if k != "row_map"}).encode())
        if camera["row_map"] is not None:
            digest.update(np.ascontiguousarray(camera["row_map"], dtype=np.float64).tobytes())
    return digest.hexdigest()


def tile_rig(rig: Rig, tile: Tile) -> Rig:
    """The rig of ``tile``'s reconstructed block: the same cameras, row maps cut from the full ones."""
    return rig.crop(tile.roi)


def expand(block, start: int, lo: int, hi: int, span: tuple) -> np.ndarray:
    """``block`` (sub-frames ``start..start+len(block)-1``) over sub-frames ``lo..hi-1``: the first
    sub-frame of the block is held before it and the last after it (:func:`rsocl.solver.held.held_index`).
    The block must lie within ``span = (first, stop)``, the capture's sampled sub-frames.
    """
    stop = start + block.shape[0]
    first, last = span
    if not (first <= start < stop <= last):
        raise ValueError(f"block sub-frames {start}..{stop - 1} lie outside the sampled {first}..{last - 1}")
    return block[held_index(hi, slice(start, stop))[lo:hi]]


def place(datacube, tile: Tile, start: int, block, span: tuple) -> None:
    """Write ``block``, the core of ``tile`` over sub-frames ``start..start+len(block)-1``, into the
    core of ``datacube`` ``(T, m, n)``, every sub-frame (see :func:`expand`)."""
    rows, cols = tile.core_slices
    datacube[:, rows, cols] = expand(block, start, 0, datacube.shape[0], span)


def core_block(datacube, tile: Tile, solved: slice) -> np.ndarray:
    """The core of ``tile`` over sub-frames ``solved`` from the tile's own ``(T_tile, h, w)`` datacube."""
    rows, cols = tile.inner_slices
    return np.ascontiguousarray(datacube[solved, rows, cols])
