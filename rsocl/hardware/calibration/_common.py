"""Input checks and small helpers shared by the calibration modules."""

from __future__ import annotations

import numpy as np

from rsocl.common import validation as check


def _image(name: str, image) -> np.ndarray:
    image = check.finite_array(name, image)
    if image.ndim != 2 or 0 in image.shape:
        raise ValueError(f"{name} must be a non-empty 2-D image (rows, columns), got shape {image.shape}")
    return image.astype(np.float64, copy=False)


def _points(name: str, points, minimum: int = 1) -> np.ndarray:
    points = check.finite_array(name, points).astype(np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or points.shape[0] < minimum:
        raise ValueError(
            f"{name} must be an (N, 2) array of (x, y) points with N >= {minimum}, got shape {points.shape}"
        )
    return points


def _homography(name: str, H) -> np.ndarray:
    H = check.finite_array(name, H).astype(np.float64)
    if H.shape != (3, 3):
        raise ValueError(f"{name} must be a 3x3 homography, got shape {H.shape}")
    if abs(np.linalg.det(H)) < 1e-12 * max(1.0, float(np.abs(H).max())) ** 3:
        raise ValueError(f"{name} is singular (determinant {np.linalg.det(H):.3g}); it maps the plane onto a line")
    return H


def _shape(shape) -> tuple:
    return check.grid_shape("shape", shape)


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
