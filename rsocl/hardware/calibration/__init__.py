"""Calibration of a camera array: registration, row time and photometric gain.

Three independent measurements, each from ordinary frames of the cameras:

*Spatial* (a target with ``n >= 4`` marker dots, one frame per camera)
    :func:`detect_markers` finds the dots' sub-pixel centroids and orders
    them by the markers' identity; :func:`estimate_homography` fits the
    homography from the reference ROI to each camera's sensor;
    :func:`warp_to_reference` resamples a camera's frames onto the reference
    grid, and :func:`row_map_from_homography` gives the camera's row-time map
    ``r(y, x)`` (``docs/model.md``: the sensor row of the mapped reference pixel
    centre). :func:`register_camera` runs the whole chain for one frame.
*Temporal* (a frame of a light flickering at a known frequency)
    a rolling shutter records the flicker as horizontal bands;
    :func:`estimate_row_time` measures their period ``P`` (rows) and returns
    ``t_r = 1 / (f * P)``; :func:`check_row_time` compares it with the value
    the rig file states.
*Photometric* (flat-field frames)
    :func:`flat_field_gain` gives each camera's gain relative to camera 0.

:func:`marker_overlay_png` draws the registered markers over each camera's
frame, to check a calibration by eye.

Coordinates
-----------
Points are ``(x, y)`` pairs in pixels, ``x`` the column and ``y`` the row,
with the centre of pixel ``[i, j]`` at ``(x, y) = (j, i)`` (scikit-image's and
``docs/model.md``'s convention). A homography ``H`` is a 3x3 array mapping
reference ``(x, y, 1)`` to sensor ``w * (X, Y, 1)``; it is the ``params`` of a
:class:`skimage.transform.ProjectiveTransform`, normalised to ``H[2, 2] = 1``.
"""

from rsocl.hardware.calibration.homography import (
    CameraRegistration,
    estimate_homography,
    homography_angle,
    homography_difference,
    project_points,
    reference_outline,
    register_camera,
    reprojection_error,
    rotation_homography,
    row_map_from_homography,
    warp_to_reference,
)
from rsocl.hardware.calibration.markers import LARGEST_MARGIN, detect_markers, order_markers  # noqa: F401 (LARGEST_MARGIN)
from rsocl.hardware.calibration.overlay import marker_overlay_png
from rsocl.hardware.calibration.photometric import flat_field_gain
from rsocl.hardware.calibration.timing import band_period, check_row_time, estimate_row_time

__all__ = [
    "detect_markers",
    "order_markers",
    "estimate_homography",
    "project_points",
    "reprojection_error",
    "homography_difference",
    "homography_angle",
    "rotation_homography",
    "row_map_from_homography",
    "warp_to_reference",
    "reference_outline",
    "CameraRegistration",
    "register_camera",
    "band_period",
    "estimate_row_time",
    "check_row_time",
    "flat_field_gain",
    "marker_overlay_png",
]
