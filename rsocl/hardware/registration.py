"""A camera's frame on the rig's reference grid, in model units: what ``rsocl capture`` stores as a set's snapshot.

Integer levels become model units (``raw / (2**bit_depth - 1) * full_scale``); a frame with a homography in
the rig file is warped to the reference grid (:func:`rsocl.hardware.calibration.warp_to_reference`), and a
frame the camera registered itself but cut to its ROI is put back in its place.
"""

from __future__ import annotations

import numpy as np

from rsocl.files.rigfile import RigFile
from rsocl.model.curvature import white_levels

__all__ = ["register", "in_grid"]


def register(rigfile: RigFile, rig, index: int, frame) -> np.ndarray:
    """Frame of camera ``index`` on the reference grid, model units, float64 ``(m, n)``."""
    cam = rigfile.cameras[index]
    image = np.asarray(frame.image)
    if image.dtype.kind in "biu":
        levels = 2 ** int(frame.bit_depth) - 1
        full_scale = frame.meta.get("full_scale")
        if full_scale is None:  # a white scene at unit gain: the exposure the device applied, in sub-frames
            full_scale = white_levels(rig)[index]
        value = image.astype(np.float64) * (float(full_scale) / levels)
    else:
        value = image.astype(np.float64)
    H = rigfile.homography(index)
    registered = frame.meta.get("registered", False)
    if registered and frame.meta.get("roi") is not None and value.shape != rig.shape:
        value = in_grid(value, frame.meta["roi"], rig.shape, index)
    if H is not None and not registered:
        from rsocl.hardware.calibration import warp_to_reference

        origin = tuple(cam["roi"][:2]) if cam.get("roi") else (0, 0)
        value = warp_to_reference(value, H, rig.shape, frame_origin=origin, order=1, cval=0.0)
    if value.shape != rig.shape:
        raise ValueError(
            f"camera {index}: frame shape {value.shape} is not the rig's shape {rig.shape} "
            "and the rig file gives no homography to register it"
        )
    if not np.all(np.isfinite(value)):
        raise ValueError(f"camera {index}: frame has NaN or inf values")
    return value


def in_grid(value, roi, shape, index) -> np.ndarray:
    """A frame already on the reference grid but cut to ``roi`` (``[x, y, width, height]``, pixels) put back
    in its place on a grid of ``shape`` ``(m, n)``, 0 outside."""
    x, y, width, height = (int(v) for v in roi)
    if value.shape != (height, width) or x < 0 or y < 0 or x + width > shape[1] or y + height > shape[0]:
        raise ValueError(
            f"camera {index}: a registered frame of shape {value.shape} with roi [x, y, width, height] = "
            f"{[x, y, width, height]} does not fit the rig's shape {shape}"
        )
    grid = np.zeros(shape)
    grid[y : y + height, x : x + width] = value
    return grid
