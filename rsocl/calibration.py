"""Calibration of a camera array: registration, row time and photometric gain.

Three independent measurements, each from ordinary frames of the cameras:

*Spatial* (a target with ``n >= 4`` marker dots, one frame per camera)
    :func:`detect_markers` finds the dots' sub-pixel centroids and orders
    them by the markers' identity; :func:`estimate_homography` fits the
    homography from the reference ROI to each camera's sensor;
    :func:`warp_to_reference` resamples a camera's frames onto the reference
    grid, and :func:`row_map_from_homography` gives the camera's row-time map
    ``r(y, x)`` (``MODEL.md``: the sensor row of the mapped reference pixel
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
``MODEL.md``'s convention). A homography ``H`` is a 3x3 array mapping
reference ``(x, y, 1)`` to sensor ``w * (X, Y, 1)``; it is the ``params`` of a
:class:`skimage.transform.ProjectiveTransform`, normalised to ``H[2, 2] = 1``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import validation as check
from .atomic import atomic_path

__all__ = [
    "detect_markers", "order_markers", "estimate_homography", "project_points", "reprojection_error",
    "homography_difference", "homography_angle", "rotation_homography", "row_map_from_homography",
    "warp_to_reference", "reference_outline", "CameraRegistration", "register_camera", "band_period",
    "estimate_row_time", "check_row_time", "flat_field_gain", "marker_overlay_png",
]

#: Default start of the marker order: the marker nearest the top-left
#: direction from the markers' centre (angle of ``(-1, -1)`` in image
#: coordinates, y down), radians.
_TOP_LEFT = math.atan2(-1.0, -1.0)
#: ``reference="largest"`` needs the largest marker's area to exceed the
#: second largest by this factor, else the reference marker is ambiguous.
LARGEST_MARGIN = 1.2


# ---------------------------------------------------------------------- helpers
def _image(name: str, image) -> np.ndarray:
    image = check.finite_array(name, image)
    if image.ndim != 2 or 0 in image.shape:
        raise ValueError(f"{name} must be a non-empty 2-D image (rows, columns), got shape {image.shape}")
    return image.astype(np.float64, copy=False)


def _points(name: str, points, minimum: int = 1) -> np.ndarray:
    points = check.finite_array(name, points).astype(np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or points.shape[0] < minimum:
        raise ValueError(f"{name} must be an (N, 2) array of (x, y) points with N >= {minimum}, "
                         f"got shape {points.shape}")
    return points


def _homography(name: str, H) -> np.ndarray:
    H = check.finite_array(name, H).astype(np.float64)
    if H.shape != (3, 3):
        raise ValueError(f"{name} must be a 3x3 homography, got shape {H.shape}")
    if abs(np.linalg.det(H)) < 1e-12 * max(1.0, float(np.abs(H).max())) ** 3:
        raise ValueError(f"{name} is singular (determinant {np.linalg.det(H):.3g}); it maps the plane onto a line")
    return H


def _shape(shape) -> tuple:
    try:
        m, n = shape
    except (TypeError, ValueError):
        raise ValueError(f"shape must be (m, n) rows and columns, got {shape!r}") from None
    return check.positive_int("shape[0] (rows m)", m), check.positive_int("shape[1] (columns n)", n)


def _origin(frame_origin) -> tuple:
    try:
        x0, y0 = frame_origin
    except (TypeError, ValueError):
        raise ValueError(f"frame_origin must be (x, y) pixels, got {frame_origin!r}") from None
    return check.finite("frame_origin[0]", x0), check.finite("frame_origin[1]", y0)


def _reference_grid(shape) -> np.ndarray:
    """``(m*n, 2)`` array of the reference pixel centres ``(x, y)``, row-major."""
    m, n = shape
    y, x = np.mgrid[0:m, 0:n]
    return np.column_stack([x.ravel(), y.ravel()]).astype(np.float64)


def _transform(H):
    from skimage.transform import ProjectiveTransform

    return ProjectiveTransform(matrix=H)


# ---------------------------------------------------------------------- markers
def _marker_order(points: np.ndarray, first, angle, mirrored) -> np.ndarray:
    centre = points.mean(axis=0)
    theta = np.arctan2(points[:, 1] - centre[1], points[:, 0] - centre[0])
    if first is None:
        start = _TOP_LEFT + math.radians(check.finite("angle", angle))
        first = int(np.argmin(np.abs(np.angle(np.exp(1j * (theta - start))))))
    elif isinstance(first, bool) or not isinstance(first, (int, np.integer)) or not 0 <= first < len(points):
        raise ValueError(f"first must be an index in [0, {len(points) - 1}], got {first!r}")
    sign = -1.0 if mirrored else 1.0
    turn = np.mod(sign * (theta - theta[int(first)]), 2 * np.pi)
    turn[int(first)] = -1.0
    return np.argsort(turn, kind="stable")


def order_markers(points, *, first=None, angle=0.0, mirrored=False) -> np.ndarray:
    """Order marker points by their position around the markers' centre.

    Parameters
    ----------
    points : array_like, shape (N, 2)
        Marker positions ``(x, y)``, pixels.
    first : int, optional
        Index (into ``points``) of the marker that comes first, e.g. the one
        marker that is larger than the others. When omitted the first marker
        is the one nearest the top-left direction from the centre, turned by
        ``angle``.
    angle : float
        Expected rotation of the camera relative to the reference, degrees
        (``Camera.angle`` of ``MODEL.md``). It turns the "top-left" start, so
        that a camera rotated by ``angle`` lists the same physical markers in
        the same order as the reference. Ignored when ``first`` is given.
    mirrored : bool
        The camera sees the target mirrored (e.g. through a beam splitter):
        count counter-clockwise instead of clockwise. The geometric start
        (``angle``) assumes an unmirrored view, so give ``first`` (e.g.
        ``reference="largest"`` in :func:`detect_markers`) for mirrored
        cameras.

    Returns
    -------
    ndarray of float64, shape (N, 2)
        The points, starting at the first marker and going clockwise as seen
        on the image (x right, y down), i.e. by increasing
        ``atan2(y - cy, x - cx)`` around their centre ``(cx, cy)``.

    Notes
    -----
    A rotation of the camera turns every marker's angle around the centre by
    the same amount, so the cyclic order is invariant; only the start needs
    the markers' identity (``first``) or the expected rotation (``angle``).
    The geometric start is ambiguous when two markers are equally near the
    start direction (a square of markers turned by 45° from ``angle``): use
    a target with an identifiable marker for such cameras.
    """
    points = _points("points", points)
    return points[_marker_order(points, first, angle, mirrored)]


def detect_markers(image, n=4, *, polarity="bright", threshold=None, smooth=1.0, min_area=4,
                   reference=None, angle=0.0, mirrored=False, return_areas=False):
    """Find ``n`` marker dots in a frame and return their ordered centroids.

    Parameters
    ----------
    image : array_like, shape (rows, columns)
        One camera frame of the target (any real dtype).
    n : int
        Number of markers (>= 4 for a homography).
    polarity : {"bright", "dark"}
        Bright dots on a darker background, or dark dots on a brighter one.
    threshold : float, optional
        Intensity (in ``image`` units) separating dots from background; for
        ``polarity="dark"`` dots are *below* it. Default: the background
        (median) plus the larger of 6 noise sigmas (median absolute
        deviation) and 20 % of the brightest dot's contrast, measured on the
        image smoothed by ``smooth``. Dots dimmer than that need an explicit
        threshold.
    smooth : float
        Gaussian sigma (pixels) of the smoothing used for segmentation only;
        0 disables it. Centroids are always weighted by the raw image.
    min_area : int
        Blobs smaller than this (pixels) are ignored as noise.
    reference : {None, "largest"}
        How the first marker is identified. ``None``: geometrically, the one
        nearest the top-left of the markers' centre after turning by
        ``angle`` (see :func:`order_markers`). ``"largest"``: the target has
        one marker larger than the others (area at least
        :data:`LARGEST_MARGIN` times the second largest); it comes first,
        whatever the camera's rotation. List the reference points the same
        way: the large marker first.
    angle : float
        Expected camera rotation, degrees, for ``reference=None``.
    mirrored : bool
        Count counter-clockwise (mirrored view).
    return_areas : bool
        Also return the blobs' areas (pixels), in the same order.

    Returns
    -------
    points : ndarray of float64, shape (n, 2)
        Intensity-weighted centroids ``(x, y)`` (pixel centres at integer
        coordinates), starting at the first marker and going clockwise on the
        image.
    areas : ndarray of int, shape (n,)
        Only with ``return_areas``.

    Raises
    ------
    ValueError
        If fewer than ``n`` blobs are found, a chosen blob touches the frame
        edge (its centroid would be biased), or ``reference="largest"`` finds
        no clearly largest marker.

    Notes
    -----
    The dots are the ``n`` largest connected regions of
    ``smoothed > threshold`` (8-connectivity), largest by area. Each
    centroid is ``sum(w * p) / sum(w)`` over its region with
    ``w = image - threshold`` clipped at 0: the weights fall continuously to
    zero at the region's edge, so the pixel grid adds no bias (measured
    < 0.01 px for Gaussian dots of sigma 2.6 px without noise). A dot seen
    in perspective has its centroid slightly off the image of its centre
    (about 0.05 px for 3 % perspective); keep the dots small.
    """
    from scipy import ndimage
    from skimage.measure import label, regionprops

    image = _image("image", image)
    n = check.positive_int("n", n)
    polarity = check.choice("polarity", polarity, {"bright", "dark"})
    smooth = check.non_negative("smooth", smooth, "pixels")
    min_area = check.positive_int("min_area", min_area)
    if reference is not None:
        check.choice("reference", reference, {"largest"})
    signed = image if polarity == "bright" else -image
    smoothed = ndimage.gaussian_filter(signed, smooth) if smooth > 0 else signed
    background = float(np.median(smoothed))
    if threshold is None:
        noise = 1.4826 * float(np.median(np.abs(smoothed - background)))
        level = background + max(6.0 * noise, 0.2 * (float(smoothed.max()) - background))
    else:
        level = check.finite("threshold", threshold)
        level = level if polarity == "bright" else -level
    labels = label(smoothed > level, connectivity=2)
    regions = [r for r in regionprops(labels) if r.area >= min_area]
    if len(regions) < n:
        raise ValueError(f"found {len(regions)} marker blob(s) of >= {min_area} pixels, need {n}; threshold "
                         f"{level if polarity == 'bright' else -level:.6g} ({polarity} dots). Check the "
                         f"polarity, or pass threshold=")
    regions.sort(key=lambda r: r.area, reverse=True)
    chosen = regions[:n]
    weights = np.clip(signed - level, 0.0, None)
    rows, cols = image.shape
    centroids, areas = [], []
    for region in chosen:
        coords = region.coords
        r0, c0, r1, c1 = region.bbox
        if r0 == 0 or c0 == 0 or r1 == rows or c1 == cols:
            cy, cx = region.centroid
            raise ValueError(f"marker blob near (x, y) = ({cx:.1f}, {cy:.1f}) touches the frame edge; its centroid "
                             f"would be biased. Move the target or crop the frame")
        w = weights[coords[:, 0], coords[:, 1]]
        if w.sum() <= 0:
            w = np.ones(len(coords))
        centroids.append([np.dot(w, coords[:, 1]) / w.sum(), np.dot(w, coords[:, 0]) / w.sum()])
        areas.append(int(region.area))
    centroids = np.asarray(centroids, dtype=np.float64)
    areas = np.asarray(areas)
    first = None
    if reference == "largest":
        if n > 1 and areas[0] < LARGEST_MARGIN * areas[1]:
            raise ValueError(f"reference='largest': the two largest markers have areas {areas[0]} and {areas[1]} "
                             f"pixels (ratio {areas[0] / areas[1]:.2f} < {LARGEST_MARGIN}); cannot tell which "
                             f"one is the reference marker")
        first = 0
    order = _marker_order(centroids, first, angle, mirrored)
    if return_areas:
        return centroids[order], areas[order]
    return centroids[order]


# ---------------------------------------------------------------------- homography
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
        raise ValueError(f"reference_points and sensor_points must hold the same markers, got {len(src)} and "
                         f"{len(dst)} points")
    for name, pts in (("reference_points", src), ("sensor_points", dst)):
        centred = pts - pts.mean(axis=0)
        if len(pts) == 4:
            triples = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]
            scale = max(float(np.abs(centred).max()), 1e-300) ** 2
            for a, b, c in triples:
                u, v = pts[b] - pts[a], pts[c] - pts[a]
                if abs(u[0] * v[1] - u[1] * v[0]) < 1e-6 * scale:
                    raise ValueError(f"{name}: points {a}, {b}, {c} are collinear; a homography needs four "
                                     f"points with no three on a line")
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
        raise ValueError(f"reference_points and sensor_points must have the same shape, got "
                         f"{reference_points.shape} and {sensor_points.shape}")
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
    """Homography of an ideal camera rotated by ``angle`` degrees (``MODEL.md`` convention).

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
    dx, dy = (check.finite("shift[0]", shift[0]), check.finite("shift[1]", shift[1]))
    to_sensor = np.array([[1, 0, (sn - 1) / 2 + dx], [0, 1, (sm - 1) / 2 + dy], [0, 0, 1]], dtype=np.float64)
    return to_sensor @ rotate @ to_centre


def row_map_from_homography(H, shape) -> np.ndarray:
    """Row-time map ``r(y, x)`` of a camera from its registration (``MODEL.md``).

    Parameters
    ----------
    H : array_like, shape (3, 3)
        Homography from reference ``(x, y)`` to the camera's sensor ``(x, y)``.
    shape : (int, int)
        ``(m, n)`` of the reference ROI.

    Returns
    -------
    ndarray of float64, shape (m, n)
        The sensor row (``Y``, in sensor rows) of each mapped reference pixel
        centre, minus its minimum over the ROI (first row read is 0); values
        within 1e-9 of an integer are snapped to it. Pass it as
        ``Camera(row_map=...)``. For a rotation (:func:`rotation_homography`)
        it equals ``Camera(angle).rows(shape)``. This is
        :func:`rsocl.rigfile.row_map_from_homography` (one implementation for
        the rig file and calibration); ``H`` is first scaled to
        ``H[2, 2] = 1`` so that ``H`` and ``-H`` give the same map.

    Raises
    ------
    ValueError
        If the ROI crosses the homography's horizon (some pixel maps to
        infinity or behind the camera).
    """
    from .rigfile import row_map_from_homography as rigfile_row_map

    H = _homography("H", H)
    shape = _shape(shape)
    if H[2, 2] != 0:
        H = H / H[2, 2]
    return rigfile_row_map(H, shape)


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
    border = np.concatenate([
        np.column_stack([left + t * (right - left), np.full(samples, top)]),
        np.column_stack([np.full(samples, right), top + t * (bottom - top)]),
        np.column_stack([right - t * (right - left), np.full(samples, bottom)]),
        np.column_stack([np.full(samples, left), bottom - t * (bottom - top)]),
    ])
    return project_points(H, border) - np.asarray(_origin(frame_origin))


def homography_angle(H, shape) -> float:
    """Rotation of a camera implied by its homography, degrees in (-180, 180].

    The direction in which the sensor sees the reference x axis at the
    centre of a reference ROI of ``shape``: ``atan2(dY, dX)`` of the mapped
    unit step. For :func:`rotation_homography` ``(angle)`` it is ``angle``
    (``MODEL.md``'s ``Camera.angle``), whatever the scale, shift and a small
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
        Spline interpolation order (1: bilinear).
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
    order = int(order)
    cval = check.finite("cval", cval)
    x0, y0 = _origin(frame_origin)
    transform = _transform(np.array([[1, 0, -x0], [0, 1, -y0], [0, 0, 1.0]]) @ H)
    stack = frame.reshape((-1,) + frame.shape[-2:]).astype(np.float64, copy=False)
    out = np.stack([warp(image, transform, output_shape=shape, order=order, cval=cval, preserve_range=True,
                         clip=False) for image in stack])
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
        return float(np.sqrt(np.mean(self.errors ** 2)))

    def row_map(self, shape) -> np.ndarray:
        """Row-time map for a reference ROI of ``shape`` (see :func:`row_map_from_homography`)."""
        return row_map_from_homography(self.homography, shape)

    def warp(self, frame, shape, **options) -> np.ndarray:
        """``frame`` on the reference grid (see :func:`warp_to_reference`)."""
        return warp_to_reference(frame, self.homography, shape, **options)


def register_camera(frame, reference_points, *, sensor_points=None, frame_origin=(0, 0), reference=None, angle=0.0,
                    mirrored=False, **detect_options) -> CameraRegistration:
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
        rotation, degrees, used to start the geometric order).
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
        sensor = detect_markers(frame, len(reference_points), reference=reference, angle=angle,
                                mirrored=mirrored, **detect_options) + np.asarray(_origin(frame_origin))
    H = estimate_homography(ordered_reference, sensor)
    return CameraRegistration(H, ordered_reference, sensor)


# ---------------------------------------------------------------------- row time
def _sinusoid_fit(profile: np.ndarray, frequency: float):
    """Least-squares fit of offset + linear trend + a cos + b sin at ``frequency``; returns (rss, coefficients)."""
    k = np.arange(profile.size, dtype=np.float64)
    phase = 2 * np.pi * frequency * k
    design = np.column_stack([np.ones_like(k), (k - k.mean()) / profile.size, np.cos(phase), np.sin(phase)])
    coefficients, *_ = np.linalg.lstsq(design, profile, rcond=None)
    residual = profile - design @ coefficients
    return float(residual @ residual), coefficients


def band_period(profile, *, min_periods=2.0) -> float:
    """Period, in samples, of the dominant sinusoid of a 1-D profile.

    The initial estimate is the peak of the Hann-windowed, zero-padded FFT
    (linear trend removed), refined by parabolic interpolation of the log
    magnitude; the final value minimises the residual of a least-squares fit
    of ``offset + trend + a cos + b sin`` over the frequency, within one FFT
    bin of the peak.

    Parameters
    ----------
    profile : array_like, shape (N,)
        E.g. the row means of a frame.
    min_periods : float
        Fewest whole periods the profile must hold (the lowest frequency
        searched is ``min_periods / N``).

    Returns
    -------
    float
        Period in samples (> 2, the Nyquist limit).

    Raises
    ------
    ValueError
        If the profile is too short or no significant periodic band is found.
    """
    from scipy.optimize import minimize_scalar

    profile = check.finite_array("profile", profile).astype(np.float64).ravel()
    N = profile.size
    min_periods = check.positive("min_periods", min_periods)
    if N < 8:
        raise ValueError(f"profile must hold at least 8 samples, got {N}")
    k = np.arange(N, dtype=np.float64)
    detrended = profile - np.polyval(np.polyfit(k, profile, 1), k)
    pad = 16 * (1 << int(math.ceil(math.log2(N))))
    spectrum = np.abs(np.fft.rfft(detrended * np.hanning(N), pad))
    freqs = np.fft.rfftfreq(pad)
    valid = freqs >= min_periods / N
    if not valid.any() or spectrum[valid].max() <= 0:
        raise ValueError("profile has no periodic component (flat after removing its trend)")
    index = int(np.flatnonzero(valid)[np.argmax(spectrum[valid])])
    f0 = freqs[index]
    if 0 < index < len(spectrum) - 1:
        a, b, c = np.log(spectrum[index - 1:index + 2] + 1e-300)
        denominator = a - 2 * b + c
        if denominator < 0:
            f0 = freqs[index] + 0.5 * (a - c) / denominator * (freqs[1] - freqs[0])
    low, high = max(f0 - 1.0 / N, 0.5 / N), min(f0 + 1.0 / N, 0.5)
    best = minimize_scalar(lambda f: _sinusoid_fit(profile, f)[0], bounds=(low, high), method="bounded",
                           options={"xatol": 1e-9})
    frequency = float(best.x)
    rss, coefficients = _sinusoid_fit(profile, frequency)
    amplitude = float(np.hypot(coefficients[2], coefficients[3]))
    noise = math.sqrt(rss / max(N - 5, 1))
    if amplitude < 5 * noise * math.sqrt(2.0 / N):
        raise ValueError(f"no significant band found: fitted amplitude {amplitude:.3g} against a residual of "
                         f"{noise:.3g} per sample")
    if frequency < min_periods / N or frequency >= 0.5:
        raise ValueError(f"band period {1 / frequency:.3g} samples is outside the measurable range "
                         f"(2 .. {N / min_periods:.3g})")
    return 1.0 / frequency


def estimate_row_time(frame, flicker_hz, *, axis=0, min_periods=2.0) -> float:
    """Row readout time from a frame of a flickering light, seconds.

    A rolling shutter starts row ``r`` at ``r * t_r``, so a light whose
    intensity oscillates at ``flicker_hz`` paints bands with a period of
    ``P = 1 / (flicker_hz * t_r)`` rows; hence ``t_r = 1 / (flicker_hz * P)``.

    Parameters
    ----------
    frame : array_like, shape (rows, columns)
        A raw sensor frame (not registered: its rows are the sensor's rows)
        of an evenly lit scene under the flickering light.
    flicker_hz : float
        Frequency of the intensity oscillation, Hz. Lamps on AC mains flicker
        at twice the mains frequency (100 Hz on 50 Hz mains, 120 Hz on 60 Hz).
    axis : int
        Axis of ``frame`` along which the sensor rows run (0 for a frame
        stored as rows x columns, 1 for a transposed one).
    min_periods : float
        Fewest band periods the frame must show (see :func:`band_period`).

    Returns
    -------
    float
        ``t_r``, seconds.

    Notes
    -----
    The period is measured on the profile of row means
    (:func:`band_period`), so it must span more than 2 rows
    (``flicker_hz * t_r < 0.5``) and the frame at least ``min_periods``
    periods. An exposure time that is a whole number of flicker periods
    averages the bands away.
    """
    frame = _image("frame", frame)
    flicker_hz = check.positive("flicker_hz", flicker_hz, "Hz")
    if axis not in (0, 1, -1, -2):
        raise ValueError(f"axis must be 0 or 1, got {axis!r}")
    profile = frame.mean(axis=1 if axis in (0, -2) else 0)
    return 1.0 / (flicker_hz * band_period(profile, min_periods=min_periods))


def check_row_time(estimated, expected, tolerance=0.01, *, raise_error=True) -> str:
    """Compare a measured row time with the stated one.

    Parameters
    ----------
    estimated, expected : float
        Measured and stated ``t_r``, seconds.
    tolerance : float
        Largest accepted relative difference ``|estimated/expected - 1|``.
    raise_error : bool
        Raise on a mismatch (default); otherwise return the message.

    Returns
    -------
    str
        A one-line report, starting with ``"t_r ok"`` or ``"t_r mismatch"``.

    Raises
    ------
    ValueError
        On a mismatch, when ``raise_error``.
    """
    estimated = check.positive("estimated", estimated, "seconds")
    expected = check.positive("expected", expected, "seconds")
    tolerance = check.non_negative("tolerance", tolerance)
    relative = estimated / expected - 1.0
    detail = (f"measured {estimated * 1e6:.4g} µs, rig file {expected * 1e6:.4g} µs "
              f"({relative * 100:+.2f} %, tolerance {tolerance * 100:g} %)")
    if abs(relative) <= tolerance:
        return "t_r ok: " + detail
    message = ("t_r mismatch: " + detail + "; check the flicker frequency (lamps flicker at twice the mains "
               "frequency) and the camera's readout settings")
    if raise_error:
        raise ValueError(message)
    return message


# ---------------------------------------------------------------------- photometric
def flat_field_gain(frames, *, relative_to=0, dark=0.0, region=0.5, trim=0.1) -> np.ndarray:
    """Photometric gain of each camera from flat-field frames.

    Parameters
    ----------
    frames : sequence of array_like, or array_like
        One entry per camera: a flat-field frame ``(rows, columns)`` or a
        stack of them ``(K, rows, columns)`` (frames may differ in size
        between cameras). An array ``(C, rows, columns)`` or
        ``(C, K, rows, columns)`` is accepted too. All cameras must see the
        same uniform light with the same exposure time.
    relative_to : int or "mean"
        Camera whose gain is 1 (default camera 0), or ``"mean"`` for gains
        whose mean is 1.
    dark : float or sequence of float
        Dark level (black offset) subtracted from each camera's frames, in
        intensity units; one value, or one per camera.
    region : float
        Fraction (0, 1] of each axis, centred, over which the level is
        measured (vignetting grows towards the edges).
    trim : float
        Fraction [0, 0.5) cut from each tail before averaging (robust
        against hot pixels and dust).

    Returns
    -------
    ndarray of float64, shape (C,)
        Gains, dimensionless (``Camera.gain``).

    Raises
    ------
    ValueError
        If a camera's dark-subtracted level is not positive.
    """
    from scipy.stats import trim_mean

    if isinstance(frames, np.ndarray):
        frames = list(frames)
    frames = [check.finite_array(f"frames[{c}]", f) for c, f in enumerate(frames)]
    if not frames:
        raise ValueError("frames must hold at least one camera's flat field")
    C = len(frames)
    region = check.in_range("region", region, 1e-6, 1.0)
    trim = check.finite("trim", trim)
    if not 0 <= trim < 0.5:
        raise ValueError(f"trim must be in [0, 0.5), got {trim!r}")
    darks = np.broadcast_to(np.asarray(dark, dtype=np.float64), (C,)) if np.ndim(dark) == 0 else \
        check.finite_array("dark", dark).astype(np.float64)
    if darks.shape != (C,):
        raise ValueError(f"dark must be one value or one per camera ({C}), got shape {darks.shape}")
    levels = np.empty(C)
    for c, flat in enumerate(frames):
        if flat.ndim not in (2, 3) or 0 in flat.shape:
            raise ValueError(f"frames[{c}] must be a (rows, columns) frame or a (K, rows, columns) stack, "
                             f"got shape {flat.shape}")
        rows, cols = flat.shape[-2:]
        dr, dc = (rows - max(1, round(rows * region))) // 2, (cols - max(1, round(cols * region))) // 2
        centre = flat[..., dr:rows - dr, dc:cols - dc].astype(np.float64)
        levels[c] = float(trim_mean(centre.ravel(), trim)) - darks[c]
        if not levels[c] > 0:
            raise ValueError(f"camera {c}: flat-field level minus dark is {levels[c]:.6g}, must be > 0 "
                             f"(is the dark level right, is the light on?)")
    if relative_to == "mean":
        return levels / levels.mean()
    if isinstance(relative_to, bool) or not isinstance(relative_to, (int, np.integer)) or not 0 <= relative_to < C:
        raise ValueError(f"relative_to must be a camera index in [0, {C - 1}] or 'mean', got {relative_to!r}")
    return levels / levels[int(relative_to)]


# ---------------------------------------------------------------------- picture
def marker_overlay_png(path, frames, detected, reprojected=None, *, outlines=None, titles=None, cmap="gray",
                       dpi=100) -> Path:
    """Write a PNG of each camera's frame with its markers drawn over it.

    Detected markers are circles, numbered in marker order; markers
    reprojected from the reference grid through the fitted homography are
    crosses. Each panel has its own display range (1st to 99.9th
    percentile), since cameras differ in exposure.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ``.png`` (written atomically).
    frames : sequence of array_like
        One 2-D frame per camera (sizes may differ).
    detected : sequence of array_like, shape (N, 2)
        Detected ``(x, y)`` per camera.
    reprojected : sequence of array_like, shape (N, 2), optional
        Reprojected ``(x, y)`` per camera (None entries are skipped).
    outlines : sequence of array_like, shape (K, 2), optional
        A closed polygon per camera (None entries are skipped), drawn as a
        cyan line: e.g. the reference ROI's border mapped onto the frame
        (:func:`reference_outline`).
    titles : sequence of str, optional
        Panel titles; default ``"camera c"``.
    cmap : str
        Matplotlib colormap name.
    dpi : int
        Resolution, dots per inch (>= 10).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    frames = [_image(f"frames[{c}]", f) for c, f in enumerate(frames)]
    C = len(frames)
    if C == 0:
        raise ValueError("frames must hold at least one frame")
    if len(detected) != C:
        raise ValueError(f"detected must hold one point set per frame ({C}), got {len(detected)}")
    detected = [_points(f"detected[{c}]", d) for c, d in enumerate(detected)]
    if reprojected is None:
        reprojected = [None] * C
    if len(reprojected) != C:
        raise ValueError(f"reprojected must hold one point set per frame ({C}), got {len(reprojected)}")
    reprojected = [None if r is None else _points(f"reprojected[{c}]", r) for c, r in enumerate(reprojected)]
    if outlines is None:
        outlines = [None] * C
    if len(outlines) != C:
        raise ValueError(f"outlines must hold one polygon per frame ({C}), got {len(outlines)}")
    outlines = [None if o is None else _points(f"outlines[{c}]", o) for c, o in enumerate(outlines)]
    if titles is None:
        titles = [f"camera {c}" for c in range(C)]
    if isinstance(titles, str) or len(titles) != C:
        raise ValueError(f"titles must be a sequence of one str per frame ({C})")
    dpi = check.positive_int("dpi", dpi)
    if dpi < 10:
        raise ValueError(f"dpi must be >= 10, got {dpi}")

    ncols = min(C, 4)
    nrows = math.ceil(C / ncols)
    aspect = max(f.shape[0] / f.shape[1] for f in frames)
    panel = 3.0
    figure = Figure(figsize=(ncols * panel, nrows * panel * aspect + 0.6), layout="constrained")
    axes = figure.subplots(nrows, ncols, squeeze=False)
    for index, ax in enumerate(axes.ravel()):
        ax.set_xticks([])
        ax.set_yticks([])
        if index >= C:
            ax.set_axis_off()
            continue
        frame = frames[index]
        low, high = np.percentile(frame, [1.0, 99.9])
        if high <= low:
            high = low + 1.0
        ax.imshow(frame, cmap=cmap, vmin=low, vmax=high, interpolation="nearest")
        if outlines[index] is not None:
            closed = np.vstack([outlines[index], outlines[index][:1]])
            ax.plot(closed[:, 0], closed[:, 1], color="cyan", linewidth=1.0)
        points = detected[index]
        ax.scatter(points[:, 0], points[:, 1], s=90, facecolors="none", edgecolors="lime", linewidths=1.2)
        for k, (x, y) in enumerate(points):
            ax.annotate(str(k), (x, y), xytext=(6, 6), textcoords="offset points", color="yellow", fontsize=8)
        if reprojected[index] is not None:
            ax.scatter(reprojected[index][:, 0], reprojected[index][:, 1], s=50, marker="x", c="red",
                       linewidths=1.2)
        ax.set_xlim(-0.5, frame.shape[1] - 0.5)
        ax.set_ylim(frame.shape[0] - 0.5, -0.5)
        ax.set_title(str(titles[index]), fontsize=9)
    handles = [Line2D([], [], marker="o", linestyle="", markerfacecolor="none", markeredgecolor="lime",
                      label="detected"),
               Line2D([], [], marker="x", linestyle="", color="red", label="reprojected from reference")]
    if any(o is not None for o in outlines):
        handles.append(Line2D([], [], color="cyan", label="reference ROI"))
    try:
        figure.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8)
    except ValueError:  # matplotlib < 3.7 has no "outside" legend placement
        figure.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8)
    path = Path(os.fspath(path))
    FigureCanvasAgg(figure)
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png", dpi=dpi, facecolor="white")
    return path
