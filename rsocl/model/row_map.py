"""The row-time map of a camera registered by a homography (reference pixel -> sensor pixel).

``docs/model.md``: a calibrated camera's row map ``r(y, x)`` is the sensor row of the mapped
reference pixel centre, counted from the first row the camera reads after its trigger (sensor row 0,
or the top row of a sensor ``roi``). Rig files give cameras by ``homography`` and the calibration
measures them; both get their row maps here.
"""

from __future__ import annotations

import numpy as np

from rsocl.common import validation as check
from rsocl.model.rig import _snap

__all__ = ["row_map_from_homography"]


def row_map_from_homography(H, shape, first_row: float = 0.0) -> np.ndarray:
    """Camera row ``r(y, x)`` (rows, float64, >= 0) of a camera registered by homography ``H``.

    Parameters
    ----------
    H : array_like, shape (3, 3)
        Maps homogeneous reference pixel centres ``(x, y, 1)`` (column, row) to
        sensor coordinates ``(x', y', w)``; the sensor row is ``y'/w``.
    shape : (int, int)
        ``(m, n)`` of the reference ROI.
    first_row : float
        Sensor row the camera reads first after its trigger, rows: 0, or the top row ``y`` of
        the sensor ``roi`` the camera reads (default 0).

    Returns
    -------
    ndarray, shape (m, n)
        ``y'/w - first_row``, the rows read before each pixel's, so that the pixel's exposure
        starts ``r t_r`` after ``t_a``. A pixel mapped above ``first_row`` is not read (capture
        registers it as 0, as any pixel outside a camera's frame) and gets 0. Values within 1e-9
        of an integer are snapped to it (as :meth:`rsocl.Camera.rows` does), so a rotation by a
        multiple of 90 degrees onto a sensor of the ROI's size gives exactly the row map of that
        ``angle``.

    Raises
    ------
    ValueError
        If ``H`` is not a finite 3x3 matrix, or the ROI crosses its horizon (``w`` is 0 somewhere
        or changes sign; ``H`` and ``-H`` are the same).

    Examples
    --------
    >>> row_map_from_homography([[1, 0, 0], [0, 1, 100], [0, 0, 1]], (2, 3))  # ROI 100 rows down
    array([[100., 100., 100.],
           [101., 101., 101.]])
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
    first_row = check.finite("first_row", first_row)
    r = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w - first_row
    return _snap(np.maximum(r, 0.0))  # above the first row read: not read (registered as 0), given its time
