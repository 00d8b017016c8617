"""Launch grids: exact covers with no padding, so kernels need no bounds test."""

import pytest

from rsocl import device, launch


@pytest.mark.parametrize("extent", [1, 2, 7, 8, 50, 64, 67, 128, 130, 131, 4099])
def test_exact_launches_cover_the_extent_once(extent):
    launches = launch.exact_launches(extent)
    covered = []
    for offset, size, local in launches:
        assert size % local == 0 and 1 <= local <= 64
        covered.extend(range(offset, offset + size))
    assert covered == list(range(extent))
    assert len(launches) == 1 or launches[0][2] == 64        # a remainder launch only after full groups
    # every voxel of a (T, m, n) grid exactly once, rows as work groups
    for gsize, lsize, offset in launch.voxel_launches(3, 2, extent):
        assert gsize[1:] == (2, 3) and lsize[1:] == (1, 1) and gsize[0] % lsize[0] == 0


def test_exact_launches_rejects_an_empty_extent():
    with pytest.raises(ValueError, match="extent must be >= 1"):
        launch.exact_launches(0)


def test_device_module_still_offers_the_grids():
    # plugins written against the first release import the grids from rsocl.device
    assert device.voxel_grid is launch.voxel_grid and device.exact_launches is launch.exact_launches
