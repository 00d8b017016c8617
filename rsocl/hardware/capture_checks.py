"""What :func:`rsocl.hardware.capture.capture_sets` checks of a rig file's settings against its cameras before
it makes the capture file: each refusal names the rig file's key and what it may be.

A camera declares the pixel formats it delivers (:attr:`~rsocl.hardware.backend.CameraBackend.pixel_formats`,
which its config may narrow: a simulated sensor of more than 8 bits has no ``Mono8``) and, where its backend
can tell, the size of its sensor (:attr:`~rsocl.hardware.backend.CameraBackend.sensor_size`: a simulated
camera's before it opens, an Aravis or V4L2 camera's once open). :func:`check_pixel_formats` refuses a
``pixel_format`` the camera does not deliver, :func:`check_rois` a ``roi`` that does not lie on the sensor;
the capture runs both before the cameras open and :func:`check_rois` again once they are.
"""

from __future__ import annotations

from rsocl.hardware.backend import CameraError

__all__ = ["check_pixel_formats", "check_rois", "in_file"]


def in_file(rigfile) -> str:
    """``"<rig file>: "``, how a message about a key of ``rigfile`` starts (``""`` for a rig file made in memory)."""
    return f"{rigfile.path}: " if rigfile.path is not None else ""


def check_pixel_formats(rigfile, cameras) -> None:
    """Refuse a rig file's ``pixel_format`` that its camera does not deliver (its ``pixel_formats``), naming
    ``camera[i].pixel_format`` and the formats it may be."""
    for i, (spec, cam) in enumerate(zip(rigfile.cameras, cameras)):
        wanted, known = spec.get("pixel_format"), tuple(getattr(cam, "pixel_formats", ()))
        if wanted and known and wanted not in known:
            raise ValueError(f"{in_file(rigfile)}camera[{i}].pixel_format must be one of {list(known)}, got {wanted!r}")


def check_rois(rigfile, cameras) -> None:
    """Refuse a rig file's ``roi`` that does not lie on its camera's sensor, where the camera tells its size
    (a camera that cannot, or whose answer fails, is left to :meth:`~rsocl.hardware.backend.CameraBackend.set_roi`),
    naming ``camera[i].roi`` and its bounds."""
    for i, (spec, cam) in enumerate(zip(rigfile.cameras, cameras)):
        roi = spec.get("roi")
        if not roi:
            continue
        try:
            size = cam.sensor_size
        except CameraError:
            continue
        if size is None:
            continue
        x, y, width, height = roi
        sensor_w, sensor_h = size
        if x + width > sensor_w or y + height > sensor_h:
            raise ValueError(
                f"{in_file(rigfile)}camera[{i}].roi = {list(roi)} ([x, y, width, height]) must lie on the "
                f"{sensor_w}x{sensor_h} (width x height) sensor of {cam.name}: x + width <= {sensor_w} and "
                f"y + height <= {sensor_h}"
            )
