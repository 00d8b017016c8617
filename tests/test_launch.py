"""Launch grids: exact covers with no padding, so kernels need no bounds test."""

import pytest

from rsocl import device
from rsocl.device import launch


@pytest.mark.parametrize("extent", [1, 2, 7, 8, 50, 64, 67, 128, 130, 131, 4099])
def test_exact_launches_cover_the_extent_once(extent):
    launches = launch.exact_launches(extent)
    covered = []
    for offset, size, local in launches:
        assert size % local == 0 and 1 <= local <= 64
        covered.extend(range(offset, offset + size))
    assert covered == list(range(extent))
    assert len(launches) == 1 or launches[0][2] == 64  # a remainder launch only after full groups
    # every voxel of a (T, m, n) grid exactly once: split rows, or blocks of whole rows
    for gsize, lsize, _offset in launch.voxel_launches(3, 2, extent):
        assert gsize[1:] == (2, 3) and lsize[2] == 1 and gsize[0] % lsize[0] == 0
        assert lsize[1] == 1 or lsize[0] == extent


def test_exact_launches_rejects_an_empty_extent():
    with pytest.raises(ValueError, match="extent must be >= 1"):
        launch.exact_launches(0)


def test_device_module_still_offers_the_grids():
    # plugins written against the first release import the grids from rsocl.device
    assert device.voxel_grid is launch.voxel_grid and device.exact_launches is launch.exact_launches


@pytest.mark.parametrize(
    "m, n, group",
    [
        (128, 128, 512),
        (64, 64, 512),
        (50, 50, 512),
        (53, 8, 512),
        (7, 1, 512),
        (3, 700, 512),
        (3, 130, 64),
        (6, 64, 64),
    ],
)
def test_voxel_launches_take_blocks_of_whole_rows_when_they_fit(m, n, group):
    T = 3
    launches = launch.voxel_launches(T, m, n, group=group)
    seen = []
    for (gx, gy, gt), (lx, ly, lt), (ox, oy, ot) in launches:
        assert gx % lx == 0 and gy % ly == 0 and gt % lt == 0 and lx * ly * lt <= group
        seen += [(x, y) for x in range(ox, ox + gx) for y in range(oy, oy + gy)]
        assert (gy, gt, oy, ot) == (m, T, 0, 0)
    assert sorted(seen) == [(x, y) for x in range(n) for y in range(m)]  # every voxel exactly once
    if n <= group:
        ((_, (lx, ly, _), _),) = launches
        assert lx == n and m % ly == 0 and n * ly <= group
        assert not [d for d in range(ly + 1, m + 1) if m % d == 0 and n * d <= group]  # the largest block


@pytest.mark.parametrize(
    "m, n, width, rows", [(128, 128, 8, 4), (50, 50, 8, 4), (13, 13, 4, 4), (3, 7, 8, 4), (1, 1, 8, 4), (9, 1000, 8, 4)]
)
def test_block_grid_blocks_cover_every_pixel_once(m, n, width, rows):
    (gx, gy, gk), (lx, ly, lk) = launch.block_grid(m, n, width, rows, channels=3)
    assert gx % lx == 0 and gy % ly == 0 and gk % lk == 0 and gk == 3 and lx * ly * lk <= 64
    seen = []
    for bx in range(gx):  # each work item's block, clipped as the kernels clip it
        for by in range(gy):
            x0, y0 = bx * width, by * rows
            seen += [(y, x) for y in range(y0, min(y0 + rows, m)) for x in range(x0, min(x0 + width, n))]
    assert sorted(seen) == [(y, x) for y in range(m) for x in range(n)]
    assert gy - ly < -(-m // rows) <= gy and gx - lx < -(-n // width) <= gx  # padding: less than one group


def test_block_grid_rejects_empty_shapes():
    with pytest.raises(ValueError, match="m, n, width, rows and group must be >= 1"):
        launch.block_grid(0, 5, 8, 4)


@pytest.mark.parametrize("pixels, width", [(100, 8), (16384, 8), (3, 4)])
def test_flat_tile_grid_keeps_its_flat_tiles_for_plugins(pixels, width):
    (gx, gk), (lx, lk) = launch.flat_tile_grid(pixels, width, channels=2)
    assert gk == 2 and gx % lx == 0 and lx <= 64 and gx - lx < -(-pixels // width) <= gx
