"""Reconstructions larger than one device, and many of them: tiles with halos, run as tasks of a
Dask graph (locally or on a dask.distributed cluster), results in memory or in a Zarr store;
multi-frame captures as a stream of overlapping time windows."""

from rsocl.scale.stream import StreamResult, reconstruct_stream
from rsocl.scale.tiled import TiledResult, TilesFailed, reconstruct_tiled
from rsocl.scale.tiles import DEFAULT_HALO, Tile, TileGrid, tile_grid

__all__ = [
    "reconstruct_tiled",
    "TiledResult",
    "TilesFailed",
    "reconstruct_stream",
    "StreamResult",
    "DEFAULT_HALO",
    "Tile",
    "TileGrid",
    "tile_grid",
]
