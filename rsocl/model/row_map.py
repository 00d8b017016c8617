"""The row-time map of a camera registered by a homography (reference pixel -> sensor pixel).

``docs/model.md``: a calibrated camera's row map ``r(y, x)`` is the sensor row of the mapped
reference pixel centre, shifted so that the first row read is 0. Rig files give cameras by
``homography`` and the calibration measures them; both get their row maps here.
"""

from __future__ import annotations

import numpy as np

from rsocl.common import validation as check
from rsocl.model.rig import _snap

__all__ = ["row_map_from_homography"]


def row_map_from_homography(H, shape) -> np.ndarray:
    """Camera row ``r(y, x)`` (rows, float64, min 0) of a camera registered by homography ``H``.

    Parameters
    ----------
    H : array_like, shape (3, 3)
        Maps homogeneous reference pixel centres ``(x, y, 1)`` (column, row) to
        sensor coordinates ``(x', y', w)``; the sensor row is ``y'/w``.
    shape : (int, int)
        ``(m, n)`` of the reference ROI.

    Returns
    -------
    ndarray, shape (m, n)
        ``y'/w - min(y'/w)``; values within 1e-9 of an integer are snapped to
        it (as :meth:`rsocl.Camera.rows` does), so a rotation by a multiple of
        90 degrees gives exactly the row map of that ``angle``.

    Raises
    ------
    ValueError
        If ``H`` is not a finite 3x3 matrix, or the ROI crosses its horizon
        (``w`` is 0 somewhere or changes sign; ``H`` and ``-H`` are the same).
    """
    H = check.finite_array("homography", H).astype(np.float64)
    if H.shape != (3, 3):
        raise ValueError(f"homography must be a 3x3 matrix, got shape {H.shape}")
    m, n = shape
    y, x = np.mgrid[0:m, 0:n].astype(np.float64)
    w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    if np.all(w < 0):  # H and -H are the same homography
        H, w = -H, -w
    if not np.all(w > 0):
        raise ValueError(
            "homography maps part of the reference ROI to infinity or behind the camera "
            f"(w <= 0 at {int(np.count_nonzero(w <= 0))} pixel(s))"
        )
    r = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w
    r = r - r.min()
    return _snap(r)
