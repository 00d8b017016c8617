"""Layer 1, the OpenCL device: context, program building, kernel objects, launch grids, reductions.

Imports only :mod:`rsocl.common`. The names below are the device layer's public face, used by
the model, the solver and regularizer plugins (``from rsocl.device import get_device, c_type``).
"""

from rsocl.device.context import INSTALL_HINT, Device, NoOpenCLError, device_for_queue, get_device, list_devices
from rsocl.device.launch import (
    batch_launches,
    block_grid,
    element_launches,
    exact_launches,
    flat_tile_grid,
    voxel_grid,
    voxel_launches,
)
from rsocl.device.program import Kernels, c_type, kernel_source

__all__ = [
    "Device",
    "Kernels",
    "get_device",
    "device_for_queue",
    "list_devices",
    "c_type",
    "kernel_source",
    "NoOpenCLError",
    "INSTALL_HINT",
    "batch_launches",
    "block_grid",
    "element_launches",
    "exact_launches",
    "flat_tile_grid",
    "voxel_grid",
    "voxel_launches",
]
