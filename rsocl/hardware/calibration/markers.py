"""Marker detection and ordering (the *spatial* calibration's first step).

:func:`detect_markers` finds the dots' sub-pixel centroids of a target with
``n >= 4`` marker dots and orders them by the markers' identity
(:func:`order_markers`).
"""

from __future__ import annotations

import math

import numpy as np

from rsocl.common import validation as check
from rsocl.hardware.calibration._common import _image, _points

#: Default start of the marker order: the marker nearest the top-left
#: direction from the markers' centre (angle of ``(-1, -1)`` in image
#: coordinates, y down), radians.
_TOP_LEFT = math.atan2(-1.0, -1.0)
#: ``reference="largest"`` needs the largest marker's area to exceed the
#: second largest by this factor, else the reference marker is ambiguous.
LARGEST_MARGIN = 1.2


def _marker_order(points: np.ndarray, first, angle, mirrored) -> np.ndarray:
    centre = points.mean(axis=0)
    theta = np.arctan2(points[:, 1] - centre[1], points[:, 0] - centre[0])
    if first is None:  # a mirror turns the reference's y axis the other way: its top-left lies at -_TOP_LEFT
        start = (-_TOP_LEFT if mirrored else _TOP_LEFT) + math.radians(check.finite("angle", angle))
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
        (``Camera.angle`` of ``docs/model.md``). It turns the "top-left" start, so
        that a camera rotated by ``angle`` lists the same physical markers in
        the same order as the reference. Ignored when ``first`` is given.
        For a mirrored camera, ``angle`` is the direction in which it sees
        the reference x axis (:func:`~rsocl.hardware.calibration.homography_angle`
        of its homography): the start is then where a mirror puts the
        reference's top-left.
    mirrored : bool
        The camera sees the target mirrored (e.g. through a beam splitter):
        count counter-clockwise instead of clockwise, from the mirrored
        start.

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


def detect_markers(
    image,
    n=4,
    *,
    polarity="bright",
    threshold=None,
    smooth=1.0,
    min_area=4,
    reference=None,
    angle=0.0,
    mirrored=False,
    return_areas=False,
):
    """Find ``n`` marker dots in a frame and return their ordered centroids.

    Parameters
    ----------
    image : array_like, shape (rows, columns)
        One camera frame of the target (any real dtype).
    n : int or None
        Number of markers (>= 4 for a homography); None: every blob found
        (the markers of a reference frame, however many the target has).
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
    zero at the region's edge, so the pixel grid adds no bias. A dot seen
    in perspective has its centroid slightly off the image of its centre;
    keep the dots small (measured: ``docs/implementation_notes.md``).
    """
    from scipy import ndimage
    from skimage.measure import label, regionprops

    image = _image("image", image)
    n = None if n is None else check.positive_int("n", n)
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
    if n is None:
        n = len(regions)
    if len(regions) < max(n, 1):
        raise ValueError(
            f"found {len(regions)} marker blob(s) of >= {min_area} pixels, need {max(n, 1)}; threshold "
            f"{level if polarity == 'bright' else -level:.6g} ({polarity} dots). Check the "
            f"polarity, or give a threshold (--threshold on the command line)"
        )
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
            raise ValueError(
                f"marker blob near (x, y) = ({cx:.1f}, {cy:.1f}) touches the frame edge; its centroid "
                f"would be biased. Move the target or crop the frame"
            )
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
            raise ValueError(
                f"reference='largest': the two largest markers have areas {areas[0]} and {areas[1]} "
                f"pixels (ratio {areas[0] / areas[1]:.2f} < {LARGEST_MARGIN}); cannot tell which "
                f"one is the reference marker"
            )
        first = 0
    order = _marker_order(centroids, first, angle, mirrored)
    if return_areas:
        return centroids[order], areas[order]
    return centroids[order]
