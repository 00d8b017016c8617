"""Launch grids: global and local sizes (and offsets) for rsocl's kernels.

Voxel-parallel kernels (TV, the ADMM's element-wise passes, the copy reference) run on exact
grids with no bounds test (:func:`exact_launches`); the operator's tile kernels take one work
item per block of pixels (:func:`block_grid`); :func:`voxel_grid` pads, for kernels that test
their bounds.
"""

from __future__ import annotations

__all__ = [
    "voxel_grid",
    "exact_launches",
    "element_launches",
    "batch_launches",
    "voxel_launches",
    "flat_tile_grid",
    "block_grid",
]


def voxel_grid(T: int, m: int, n: int):
    """Global and local sizes for one work item per voxel of a ``(T, m, n)`` array.

    Rows of up to 64 columns form a work group (PoCL vectorises along it; GPUs
    get a warp-sized multiple); the global size is padded and kernels check bounds.
    """
    lx = min(64, -(-n // 8) * 8)
    return ((-(-n // lx) * lx, m, T), (lx, 1, 1))


def exact_launches(extent: int, group: int = 64):
    """Launches ``(offset, size, local)`` that cover ``range(extent)`` exactly, with no padding.

    Kernels launched this way need no bounds test. On CPU devices that matters: PoCL
    turns a per-work-item ``if (i >= n) return`` into masked loads and stores (measured:
    ``docs/implementation_notes.md``). The local size is
    the largest divisor of ``extent`` up to ``group``; when that is below 8 (a prime
    extent, say), a second launch with a global offset takes the remainder.
    """
    extent, group = int(extent), int(group)
    if extent < 1:
        raise ValueError(f"extent must be >= 1, got {extent}")
    local = next(d for d in range(min(group, extent), 0, -1) if extent % d == 0)
    if local >= 8 or local == extent:
        return [(0, extent, local)]
    main = extent // group * group
    return [(0, main, group), (main, extent - main, extent - main)]


def element_launches(count: int, group: int = 64):
    """:func:`exact_launches` as ``(global, local, offset)`` of a 1-D kernel over ``count`` items."""
    return [((size,), (local,), (offset,)) for offset, size, local in exact_launches(count, group)]


def batch_launches(count: int, sets: int, group: int = 64):
    """:func:`element_launches` of a 2-D kernel: ``count`` items of each of ``sets`` sets (dimension 1)."""
    sets = int(sets)
    if sets < 1:
        raise ValueError(f"sets must be >= 1, got {sets}")
    return [((size, sets), (local, 1), (offset, 0)) for offset, size, local in exact_launches(count, group)]


def voxel_launches(T: int, m: int, n: int, group: int = 64, max_x: int | None = None):
    """``(global, local, offset)`` launches, one work item per voxel of ``(T, m, n)``, no padding.

    When a whole row fits in ``group`` work items, a work group is a block of whole rows,
    ``(n, rows)`` with ``rows`` the largest divisor of ``m`` that keeps ``n * rows <= group``:
    one launch, whatever ``n``. PoCL vectorises along the row, so larger blocks of whole rows run
    faster (``docs/implementation_notes.md``). Otherwise rows are split as :func:`exact_launches` says. ``group`` must
    not exceed what the device and kernel allow, nor ``max_x`` the device's work items along
    dimension 0 (``CL_DEVICE_MAX_WORK_ITEM_SIZES[0]``; None: no other limit than ``group``).
    """
    T, m, n, group = int(T), int(m), int(n), int(group)
    row = group if max_x is None else min(group, int(max_x))
    if n <= row:
        rows = next(d for d in range(min(m, group // n), 0, -1) if m % d == 0)
        return [((n, m, T), (n, rows, 1), (0, 0, 0))]
    return [((size, m, T), (local, 1, 1), (offset, 0, 0)) for offset, size, local in exact_launches(n, row)]


def flat_tile_grid(pixels: int, width: int, channels: int = 1):
    """Global and local sizes for one work item per tile of ``width`` pixels (and channel).

    Flat tiles of ``width`` neighbouring pixels (flat index), 64 tiles per work group; the
    global size is padded and kernels check bounds. rsocl's own operator kernels take blocks
    of rows (:func:`block_grid`); this grid serves plugins that work on flat tiles.
    """
    tiles = -(-int(pixels) // int(width))
    lx = min(64, tiles)
    return ((-(-tiles // lx) * lx, int(channels)), (lx, 1))


def block_grid(m: int, n: int, width: int, rows: int, channels: int = 1, group: int = 64, max_items=None):
    """Global and local sizes for one work item per block of ``rows x width`` pixels (and channel).

    The operator and ADMM kernels take a block of ``rows`` (their ``TILE_R``) rows of
    ``width`` (their ``TILE_W``) neighbouring pixels per work item, in explicit vectors. A work
    group is up to ``group`` blocks: up to ``group`` of one block row, or several whole block
    rows. The global size is padded (less than one work group per dimension) and kernels check
    bounds; blocks cut by the ROI's right or bottom edge take the kernels' per-pixel loops.
    ``max_items``: the device's most work items along dimensions 0 and 1 (None: ``group``).
    """
    m, n, width, rows, group = int(m), int(n), int(width), int(rows), int(group)
    if min(m, n, width, rows, group) < 1:
        raise ValueError(f"m, n, width, rows and group must be >= 1, got {m}, {n}, {width}, {rows}, {group}")
    max_x, max_y = (group, group) if max_items is None else (int(max_items[0]), int(max_items[1]))
    tiles, block_rows = -(-n // width), -(-m // rows)
    lx = min(group, tiles, max_x)
    groups_y = -(-block_rows // max(1, min(group // lx, max_y)))  # as few groups as fit, of balanced size
    ly = -(-block_rows // groups_y)
    return ((-(-tiles // lx) * lx, groups_y * ly, int(channels)), (lx, ly, 1))
