"""One rolling-shutter camera: its timing, gain and the row that reads each reference pixel.

Conventions follow ``docs/model.md``: the exposure of reference pixel ``(y, x)`` in frame ``k``
starts at ``t_a + r(y, x)*t_r + k*t_d`` seconds and lasts ``t_e`` seconds, where ``r(y, x)`` is
the camera row that sees it (the rows read after the trigger before it).
:class:`~rsocl.model.rig.Rig` puts cameras together into an array.
"""

from __future__ import annotations

import math

import numpy as np

from rsocl.common import validation as check
from rsocl.common.hints import ArrayLike
from rsocl.model.plausible import warn_unlikely_times

__all__ = ["Camera", "SNAP"]

#: Relative tolerance under which a time, in units of ``dt``, is snapped to the
#: nearest integer, so that e.g. ``t_e = 3*t_r`` gives window edges exactly on
#: sub-frame boundaries despite binary floating point.
SNAP = 1e-12


def _snap(values):
    values = np.asarray(values, dtype=np.float64)
    nearest = np.rint(values)
    return np.where(np.abs(values - nearest) <= SNAP * np.maximum(1.0, np.abs(values)), nearest, values)


class Camera:
    """One rolling-shutter camera of the array.

    Parameters
    ----------
    angle : float
        Rotation relative to the reference camera, degrees. ``0`` reads rows
        top to bottom, ``90`` left to right, ``180`` bottom to top, ``270``
        right to left. Ignored when ``row_map`` is given.
    t_e : float
        Exposure time of every row, seconds (> 0).
    t_r : float
        Readout time between consecutive rows, seconds (> 0).
    t_a : float
        Trigger offset of this camera, seconds (>= 0).
    t_d : float or None
        Frame period for multi-frame captures, seconds. Required when
        ``frames > 1``.
    gain : float
        Photometric gain (> 0), dimensionless.
    frames : int
        Number of consecutive frames captured per trigger (>= 1).
    row_map : array_like or None
        Optional ``(m, n)`` map of the camera row, in rows, that reads each
        reference pixel (from calibration, or a coded exposure design). Values
        must be finite and >= 0; it replaces ``angle``.

    Raises
    ------
    ValueError
        If a value is out of its range (the message names it), or ``t_d`` is missing with ``frames > 1``.

    Examples
    --------
    >>> from rsocl import Camera
    >>> Camera(90, t_e=180e-6, t_r=35e-6).rows((2, 3))      # 90 degrees: reads left to right
    array([[0., 1., 2.],
           [0., 1., 2.]])
    """

    def __init__(
        self,
        angle: float = 0.0,
        t_e: float | None = None,
        t_r: float | None = None,
        t_a: float = 0.0,
        t_d: float | None = None,
        gain: float = 1.0,
        frames: int = 1,
        row_map: ArrayLike | None = None,
    ) -> None:
        if t_e is None:
            raise ValueError("t_e (exposure time, seconds) is required")
        if t_r is None:
            raise ValueError("t_r (row readout time, seconds) is required")
        self.angle = check.finite("angle", angle)
        self.t_e = check.positive("t_e", t_e, "seconds")
        self.t_r = check.positive("t_r", t_r, "seconds")
        self.t_a = check.non_negative("t_a", t_a, "seconds")
        self.gain = check.positive("gain", gain)
        self.frames = check.positive_int("frames", frames)
        if t_d is not None:
            t_d = check.positive("t_d", t_d, "seconds")
        elif self.frames > 1:
            raise ValueError(f"t_d (frame period, seconds) is required when frames > 1 (frames={self.frames})")
        self.t_d = t_d
        warn_unlikely_times("camera", self.t_e, self.t_r, self.t_a, self.t_d)
        if row_map is not None:
            row_map = check.finite_array("row_map", row_map).astype(np.float64)
            if row_map.ndim != 2 or row_map.size == 0:
                raise ValueError(f"row_map must be a non-empty 2-D array, got shape {row_map.shape}")
            if row_map.min() < 0:
                raise ValueError(f"row_map values must be >= 0 rows, got minimum {row_map.min()!r}")
        self.row_map = row_map

    def rows(self, shape: tuple[int, int]) -> np.ndarray:
        """Camera row ``r(y, x)`` (rows read after the trigger before the pixel's, float64) for a ROI of ``shape``."""
        m, n = shape
        if self.row_map is not None:
            if self.row_map.shape != (m, n):
                raise ValueError(f"row_map has shape {self.row_map.shape}, the rig's shape is {(m, n)}")
            return self.row_map.copy()
        u = np.arange(m, dtype=np.float64)[:, None] - (m - 1) / 2.0
        v = np.arange(n, dtype=np.float64)[None, :] - (n - 1) / 2.0
        a = math.radians(self.angle)
        r = u * math.cos(a) + v * math.sin(a)
        r = r - r.min()
        return _snap(r)

    def to_dict(self) -> dict:
        """Plain-data description (seconds, degrees); ``row_map`` stays an array."""
        return {
            "angle": self.angle,
            "t_e": self.t_e,
            "t_r": self.t_r,
            "t_a": self.t_a,
            "t_d": self.t_d,
            "gain": self.gain,
            "frames": self.frames,
            "row_map": self.row_map,
        }

    @classmethod
    def from_dict(cls, data: dict) -> Camera:
        return cls(**data)

    def __eq__(self, other):
        if not isinstance(other, Camera):
            return NotImplemented
        a, b = self.to_dict(), other.to_dict()
        ra, rb = a.pop("row_map"), b.pop("row_map")
        if (ra is None) != (rb is None):
            return False
        return a == b and (ra is None or np.array_equal(ra, rb))

    def __repr__(self):
        where = "row_map" if self.row_map is not None else f"angle={self.angle:g}"
        extra = f", frames={self.frames}, t_d={self.t_d:g}" if self.frames > 1 else ""
        return f"Camera({where}, t_e={self.t_e:g}, t_r={self.t_r:g}, t_a={self.t_a:g}, gain={self.gain:g}{extra})"
