"""Homographies from the reference ROI to each camera's sensor (the *spatial* calibration).

:func:`estimate_homography` fits the homography from the reference ROI to
each camera's sensor; :func:`warp_to_reference` resamples a camera's frames
onto the reference grid, and :func:`row_map_from_homography` gives the
camera's row-time map ``r(y, x)`` (``docs/model.md``: the sensor row of the mapped
reference pixel centre). :func:`register_camera` runs the whole chain for one
frame. Coordinates are as described in :mod:`rsocl.hardware.calibration`.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from rsocl.common import validation as check
from rsocl.hardware.calibration._common import _homography, _origin, _points, _reference_grid, _shape, _transform
from rsocl.hardware.calibration.markers import detect_markers, order_markers
from rsocl.hardware.calibration.pairing import check_pairing
from rsocl.model.row_map import row_map_from_homography as model_row_map


def estimate_homography(reference_points, sensor_points) -> np.ndarray:
    """Homography from reference ``(x, y)`` to sensor ``(x, y)``, least squares.

    Parameters
    ----------
    reference_points : array_like, shape (N, 2)
        Marker positions on the reference grid, pixels (N >= 4).
    sensor_points : array_like, shape (N, 2)
        The same markers, in the same order, on the camera's sensor, pixels.

    Returns
    -------
    ndarray of float64, shape (3, 3)
        ``H`` with ``H[2, 2] = 1``, from
        :meth:`skimage.transform.ProjectiveTransform` estimation (normalised
        DLT). Four points give an exact fit; more are fitted in the least
        squares sense.

    Raises
    ------
    ValueError
        If the point sets differ in length, have fewer than 4 points, or are
        degenerate (three collinear out of four, coincident points).
    """
    from skimage.transform import ProjectiveTransform

    src = _points("reference_points", reference_points, minimum=4)
    dst = _points("sensor_points", sensor_points, minimum=4)
    if src.shape != dst.shape:
        raise ValueError(
            f"reference_points and sensor_points must hold the same markers, got {len(src)} and {len(dst)} points"
        )
    for name, pts in (("reference_points", src), ("sensor_points", dst)):
        centred = pts - pts.mean(axis=0)
        if len(pts) == 4:
            triples = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]
            scale = max(float(np.abs(centred).max()), 1e-300) ** 2
            for a, b, c in triples:
                u, v = pts[b] - pts[a], pts[c] - pts[a]
                if abs(u[0] * v[1] - u[1] * v[0]) < 1e-6 * scale:
                    raise ValueError(
                        f"{name}: points {a}, {b}, {c} are collinear; a homography needs four "
                        f"points with no three on a line"
                    )
        elif np.linalg.matrix_rank(centred, tol=1e-6 * max(float(np.abs(centred).max()), 1e-300)) < 2:
            raise ValueError(f"{name}: all points lie on a line")
    if hasattr(ProjectiveTransform, "from_estimate"):
        transform = ProjectiveTransform.from_estimate(src, dst)
        ok = bool(transform)
        reason = str(transform) if not ok else ""
    else:  # scikit-image < 0.26
        transform = ProjectiveTransform()
        ok = bool(transform.estimate(src, dst))
        reason = "estimation failed"
    if not ok or not np.all(np.isfinite(transform.params)) or transform.params[2, 2] == 0:
        raise ValueError(f"could not estimate a homography from these points ({reason})")
    H = np.array(transform.params, dtype=np.float64)
    return H / H[2, 2]


def project_points(H, points) -> np.ndarray:
    """Map ``(x, y)`` points through the homography ``H``; returns ``(N, 2)`` float64."""
    H = _homography("H", H)
    points = _points("points", points)
    homogeneous = np.column_stack([points, np.ones(len(points))]) @ H.T
    w = homogeneous[:, 2]
    if np.any(np.abs(w) < 1e-12):
        raise ValueError("H maps some points to infinity (they lie on its horizon line)")
    return homogeneous[:, :2] / w[:, None]


def reprojection_error(H, reference_points, sensor_points) -> np.ndarray:
    """Distance, sensor pixels, between ``H(reference_points)`` and ``sensor_points``, per point (``(N,)``).

    With exactly four markers the fit is exact and this is ~0; it measures
    the fit only with more markers. Compare homographies with
    :func:`homography_difference`.
    """
    reference_points = _points("reference_points", reference_points)
    sensor_points = _points("sensor_points", sensor_points)
    if reference_points.shape != sensor_points.shape:
        raise ValueError(
            f"reference_points and sensor_points must have the same shape, got "
            f"{reference_points.shape} and {sensor_points.shape}"
        )
    return np.hypot(*(project_points(H, reference_points) - sensor_points).T)


def homography_difference(H_a, H_b, shape) -> float:
    """Largest distance, sensor pixels, between where ``H_a`` and ``H_b`` map a reference pixel centre.

    The maximum is over every pixel centre of a reference ROI of ``shape``
    ``(m, n)``: the registration error a snapshot would suffer by using
    ``H_a`` for a camera whose true homography is ``H_b``.
    """
    grid = _reference_grid(_shape(shape))
    return float(np.hypot(*(project_points(H_a, grid) - project_points(H_b, grid)).T).max())


def rotation_homography(angle, shape, *, sensor_shape=None, scale=1.0, shift=(0.0, 0.0)) -> np.ndarray:
    """Homography of an ideal camera rotated by ``angle`` degrees (``docs/model.md`` convention).

    The sensor row of reference point ``(x, y)`` is
    ``Y = (y - cy) cos(angle) + (x - cx) sin(angle)`` times ``scale`` plus the
    sensor centre row, i.e. the rotated camera of :class:`rsocl.Camera`;
    ``X = (x - cx) cos(angle) - (y - cy) sin(angle)`` (a proper rotation).
    The reference centre ``((n-1)/2, (m-1)/2)`` goes to the sensor centre of
    ``sensor_shape`` (default ``shape``) plus ``shift`` ``(dx, dy)`` pixels.
    Useful for synthetic tests and as a starting guess.
    """
    m, n = _shape(shape)
    sm, sn = _shape(sensor_shape if sensor_shape is not None else shape)
    a = math.radians(check.finite("angle", angle))
    scale = check.positive("scale", scale)
    # Snap quarter turns (cos 90° is 6e-17 in floating point) so their row maps are exact.
    cos, sin = (float(round(v)) if abs(v - round(v)) < 1e-12 else v for v in (math.cos(a), math.sin(a)))
    to_centre = np.array([[1, 0, -(n - 1) / 2], [0, 1, -(m - 1) / 2], [0, 0, 1]], dtype=np.float64)
    rotate = np.array([[scale * cos, -scale * sin, 0], [scale * sin, scale * cos, 0], [0, 0, 1]], dtype=np.float64)
    if np.ndim(shift) != 1 or len(shift) != 2:
        raise ValueError(f"shift must be (dx, dy) in pixels, got {shift!r}")
    dx, dy = (check.finite("shift[0]", shift[0]), check.finite("shift[1]", shift[1]))
    to_sensor = np.array([[1, 0, (sn - 1) / 2 + dx], [0, 1, (sm - 1) / 2 + dy], [0, 0, 1]], dtype=np.float64)
    return to_sensor @ rotate @ to_centre


def row_map_from_homography(H, shape, first_row: float = 0.0) -> np.ndarray:
    """Row-time map ``r(y, x)`` of a camera from its registration (``docs/model.md``).

    Parameters
    ----------
    H : array_like, shape (3, 3)
        Homography from reference ``(x, y)`` to the camera's sensor ``(x, y)``.
    shape : (int, int)
        ``(m, n)`` of the reference ROI.
    first_row : float
        Sensor row the camera reads first after its trigger, rows (0, or the top row of a
        sensor ROI it reads; default 0).

    Returns
    -------
    ndarray of float64, shape (m, n)
        The sensor row (``Y``, in sensor rows) of each mapped reference pixel
        centre, less ``first_row``: how many rows the camera reads before it (0 for a
        pixel above ``first_row``, which the camera does not read); values
        within 1e-9 of an integer are snapped to it. Pass it as
        ``Camera(row_map=...)``. For a rotation (:func:`rotation_homography`)
        it is ``Camera(angle).rows(shape)`` plus the sensor row of the ROI's first
        row read. This is
        :func:`rsocl.model.row_map.row_map_from_homography` (one implementation for
        the rig file and calibration); ``H`` is first scaled to
        ``H[2, 2] = 1`` so that ``H`` and ``-H`` give the same map.

    Raises
    ------
    ValueError
        If the ROI crosses the homography's horizon (some pixel maps to
        infinity or behind the camera).
    """
    H = _homography("H", H)
    shape = _shape(shape)
    if H[2, 2] != 0:
        H = H / H[2, 2]
    return model_row_map(H, shape, first_row)


def reference_outline(H, shape, *, frame_origin=(0, 0), samples=16) -> np.ndarray:
    """The border of the reference ROI mapped onto a camera frame, ``(4 * samples, 2)`` ``(x, y)``.

    The ROI's outer pixel edges (``-0.5`` to ``n - 0.5``, ``-0.5`` to
    ``m - 0.5``) are sampled ``samples`` times per side (a homography keeps
    lines straight, but the picture may be cropped) and mapped through ``H``,
    minus ``frame_origin``. For :func:`marker_overlay_png`.
    """
    m, n = _shape(shape)
    samples = check.positive_int("samples", samples)
    t = np.arange(samples) / samples
    left, top, right, bottom = -0.5, -0.5, n - 0.5, m - 0.5
    border = np.concatenate(
        [
            np.column_stack([left + t * (right - left), np.full(samples, top)]),
            np.column_stack([np.full(samples, right), top + t * (bottom - top)]),
            np.column_stack([right - t * (right - left), np.full(samples, bottom)]),
            np.column_stack([np.full(samples, left), bottom - t * (bottom - top)]),
        ]
    )
    return project_points(H, border) - np.asarray(_origin(frame_origin))


def homography_angle(H, shape) -> float:
    """Rotation of a camera implied by its homography, degrees in (-180, 180].

    The direction in which the sensor sees the reference x axis at the
    centre of a reference ROI of ``shape``: ``atan2(dY, dX)`` of the mapped
    unit step. For :func:`rotation_homography` ``(angle)`` it is ``angle``
    (``docs/model.md``'s ``Camera.angle``), whatever the scale, shift and a small
    perspective.
    """
    H = _homography("H", H)
    m, n = _shape(shape)
    centre = np.array([[(n - 1) / 2, (m - 1) / 2], [(n - 1) / 2 + 1.0, (m - 1) / 2]])
    (x0, y0), (x1, y1) = project_points(H, centre)
    return math.degrees(math.atan2(y1 - y0, x1 - x0))


def warp_to_reference(frame, H, shape, *, frame_origin=(0, 0), order=1, cval=0.0) -> np.ndarray:
    """Sample a camera frame on the reference grid.

    Parameters
    ----------
    frame : array_like, shape (rows, columns) or (..., rows, columns)
        Sensor frame(s); leading axes (e.g. frames of a multi-frame capture)
        are warped one by one.
    H : array_like, shape (3, 3)
        Homography from reference ``(x, y)`` to sensor ``(x, y)``: it is the
        ``inverse_map`` of :func:`skimage.transform.warp`.
    shape : (int, int)
        ``(m, n)`` of the reference ROI.
    frame_origin : (float, float)
        Sensor ``(x, y)`` of the frame's pixel ``[0, 0]``: the offset of a
        camera ROI (``roi = [x, y, width, height]`` in the rig file), since
        ``H`` maps to full-sensor coordinates.
    order : int
        Spline interpolation order, an integer in [0, 5] (1: bilinear).
    cval : float
        Value of reference pixels that map outside the sensor.

    Returns
    -------
    ndarray of float64, shape (..., m, n)
        The registered snapshot(s), in the frame's intensity units.
    """
    from skimage.transform import warp

    frame = check.finite_array("frame", frame)
    if frame.ndim < 2 or 0 in frame.shape:
        raise ValueError(f"frame must be a non-empty (rows, columns) image or a stack of them, got {frame.shape}")
    H = _homography("H", H)
    shape = _shape(shape)
    if isinstance(order, bool) or not isinstance(order, numbers.Integral) or not 0 <= int(order) <= 5:
        raise ValueError(f"order must be an integer in [0, 5] (spline order, 1: bilinear), got {order!r}")
    order = int(order)
    cval = check.finite("cval", cval)
    x0, y0 = _origin(frame_origin)
    transform = _transform(np.array([[1, 0, -x0], [0, 1, -y0], [0, 0, 1.0]]) @ H)
    stack = frame.reshape((-1,) + frame.shape[-2:]).astype(np.float64, copy=False)
    out = np.stack(
        [
            warp(image, transform, output_shape=shape, order=order, cval=cval, preserve_range=True, clip=False)
            for image in stack
        ]
    )
    return out.reshape(frame.shape[:-2] + shape)


@dataclass(frozen=True)
class CameraRegistration:
    """One camera's registration to the reference grid.

    Attributes
    ----------
    homography : ndarray, shape (3, 3)
        Reference ``(x, y)`` -> sensor ``(x, y)``, ``H[2, 2] = 1``.
    reference_points : ndarray, shape (N, 2)
        Marker positions on the reference grid, in marker order.
    sensor_points : ndarray, shape (N, 2)
        The markers as detected (or given) on the sensor, same order.
    """

    homography: np.ndarray
    reference_points: np.ndarray
    sensor_points: np.ndarray

    @property
    def reprojected(self) -> np.ndarray:
        """The reference markers mapped onto the sensor, ``(N, 2)``."""
        return project_points(self.homography, self.reference_points)

    @property
    def errors(self) -> np.ndarray:
        """Reprojection error of each marker, sensor pixels."""
        return reprojection_error(self.homography, self.reference_points, self.sensor_points)

    @property
    def rms_error(self) -> float:
        """Root-mean-square reprojection error, sensor pixels."""
        return float(np.sqrt(np.mean(self.errors**2)))

    def row_map(self, shape) -> np.ndarray:
        """Row-time map for a reference ROI of ``shape`` (see :func:`row_map_from_homography`)."""
        return row_map_from_homography(self.homography, shape)

    def warp(self, frame, shape, **options) -> np.ndarray:
        """``frame`` on the reference grid (see :func:`warp_to_reference`)."""
        return warp_to_reference(frame, self.homography, shape, **options)


def register_camera(
    frame,
    reference_points,
    *,
    sensor_points=None,
    frame_origin=(0, 0),
    reference=None,
    angle=0.0,
    mirrored=False,
    **detect_options,
) -> CameraRegistration:
    """Detect the markers in one camera frame (or take them as given) and fit its homography.

    Parameters
    ----------
    frame : array_like or None
        The camera's frame of the marker target; may be None when
        ``sensor_points`` is given.
    reference_points : array_like, shape (N, 2)
        Marker positions on the reference grid. With ``reference=None`` they
        are put in the geometric order of :func:`order_markers` (angle 0), so
        any order will do; with ``reference="largest"`` the reference
        (largest) marker must come first and the others are ordered
        clockwise after it.
    sensor_points : array_like, shape (N, 2), optional
        Marker positions on the sensor (full-sensor coordinates), already in
        the order of ``reference_points`` (as given): detection is skipped.
    frame_origin : (float, float)
        Sensor ``(x, y)`` of the frame's pixel ``[0, 0]`` (a camera ROI's
        offset): added to the detected positions, so that the homography maps
        to full-sensor coordinates as the rig file expects.
    reference, angle, mirrored, **detect_options
        Passed to :func:`detect_markers` (``angle``: the camera's nominal
        rotation, degrees, used to start the geometric order). ``mirrored``
        also says which turning sense the markers' triangles must keep.

    Raises
    ------
    ValueError
        If the markers are paired as no camera sees them
        (:func:`~rsocl.hardware.calibration.pairing.check_pairing`), or
        :func:`estimate_homography` refuses them.
    """
    reference_points = _points("reference_points", reference_points, minimum=4)
    if sensor_points is not None:
        sensor = _points("sensor_points", sensor_points, minimum=4)
        ordered_reference = reference_points
    else:
        if frame is None:
            raise ValueError("register_camera needs a frame or sensor_points")
        first = 0 if reference == "largest" else None
        ordered_reference = order_markers(reference_points, first=first)
        sensor = detect_markers(
            frame, len(reference_points), reference=reference, angle=angle, mirrored=mirrored, **detect_options
        ) + np.asarray(_origin(frame_origin))
    check_pairing(ordered_reference, sensor, mirrored=mirrored)  # four markers would fit any pairing exactly
    H = estimate_homography(ordered_reference, sensor)
    return CameraRegistration(H, ordered_reference, sensor)
