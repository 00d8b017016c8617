"""The array (rig) of rolling-shutter cameras (:mod:`rsocl.model.camera`) sharing one reference ROI.

Conventions follow ``docs/model.md``: sub-frame ``s`` covers ``[s*dt, (s+1)*dt)``;
the exposure of reference pixel ``(y, x)`` in frame ``k`` of a camera starts at
``t_a + r(y, x)*t_r + k*t_d`` seconds and lasts ``t_e`` seconds, where
``r(y, x)`` is the camera row that sees it (the rows read after the trigger before it).

A *channel* is one snapshot: one frame of one camera. Single-frame rigs have
one channel per camera; a camera with ``frames=F`` contributes ``F`` channels,
camera-major.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from functools import cached_property

import numpy as np

from rsocl.common import validation as check
from rsocl.model.camera import SNAP, Camera, _snap
from rsocl.model.plausible import check_rig_memory, check_window
from rsocl.model.windows import ExposureWindows, exposure_windows, weighted_bounds

__all__ = ["Camera", "Rig", "ExposureWindows", "PAPER_ANGLES", "MAX_T"]

#: The paper's camera order for arrays of 1..8 cameras (degrees).
PAPER_ANGLES = (0.0, 90.0, 180.0, 270.0, 45.0, 135.0, 225.0, 315.0)

#: The most sub-frames ``T`` a rig may span. 2**24 sub-frames are 9.8 minutes at dt = 35 µs (a
#: multi-frame capture of 39,000 frames at 67 fps); a datacube of one pixel over them is 64 MiB,
#: and the per-sub-frame counts of trimming (:meth:`Rig.cameras_per_subframe`) stay small. The
#: kernels index sub-frames with 32-bit integers (below 2**31). A larger ``T`` comes from a time
#: in the wrong unit (an exposure, trigger offset or frame period in µs given as seconds), and is
#: refused naming it before anything of size ``T`` is allocated.
MAX_T = 2**24


def _nonempty_bounds(first, last, T: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~rsocl.model.windows.weighted_bounds`' ``(first, last)`` cut to the sub-frames ``0 .. T-1``:
    ``last < first`` where a window gives none of them a weight."""
    return np.maximum(first, 0.0), np.minimum(last, T - 1.0)


class Rig:
    """An array of rolling-shutter cameras sharing one reference ROI.

    Parameters
    ----------
    cameras : sequence of Camera
        The cameras, in channel order.
    shape : (int, int)
        ``(m, n)``: rows and columns of the common reference ROI, pixels.
    dt : float or None
        Sub-frame duration, seconds. Defaults to the smallest ``t_r``; must
        not be smaller than it.
    mask : {"exact", "binary"}
        Shutter weights: exact overlap fraction, or the paper's Eq. 4.

    Raises
    ------
    ValueError
        If ``cameras`` is not a non-empty list of :class:`Camera`, ``shape`` or ``dt`` is out of
        range, a multi-frame camera's ``t_d`` is too short, or ``T`` would exceed :data:`MAX_T`.

    Examples
    --------
    The paper's simulation (``docs/model.md``, section *Paper figures to reproduce*):

    >>> from rsocl import Rig
    >>> rig = Rig.paper_array(4, shape=(50, 50), t_e=180e-6, t_r=35e-6)
    >>> rig.T, rig.N_s, rig.T_se, rig.compression_ratio
    (55, 6, 55, 13.75)
    >>> round(rig.effective_fps(67))                        # Hz, cameras at 67 fps
    3685
    """

    #: Whether ``dt`` may be below every camera's ``t_r``: set by a subclass that models cameras of a larger rig.
    _part_of_larger = False

    def __init__(
        self, cameras: Camera | Sequence[Camera], shape: tuple[int, int], dt: float | None = None, mask: str = "exact"
    ) -> None:
        if isinstance(cameras, Camera):
            raise ValueError("cameras must be a list of Camera, got one Camera; pass [camera]")
        try:
            cameras = list(cameras)
        except TypeError:
            raise ValueError(f"cameras must be a list of Camera, got {type(cameras).__name__}") from None
        if not cameras:
            raise ValueError("cameras must hold at least one Camera, got an empty list")
        for i, cam in enumerate(cameras):
            if not isinstance(cam, Camera):
                raise ValueError(f"cameras[{i}] must be a Camera, got {type(cam).__name__}")
        self.cameras = cameras
        self.shape = check.grid_shape("shape", shape)
        check_rig_memory(len(cameras), self.shape, f"shape {self.shape}")
        t_r_min = min(cam.t_r for cam in cameras)
        if dt is None:
            dt = t_r_min
        dt = check.positive("dt", dt, "seconds")
        if dt < t_r_min * (1 - SNAP) and not self._part_of_larger:
            raise ValueError(f"dt must be >= t_r = {t_r_min!r} s (the smallest row time), got {dt!r}")
        self.dt = dt
        self.mask = check.choice("mask", mask, {"exact", "binary"})
        for i, cam in enumerate(cameras):
            check_window(f"cameras[{i}].t_e", cam.t_e, dt)
        self._rows = [cam.rows(self.shape) for cam in cameras]
        for i, (cam, r) in enumerate(zip(cameras, self._rows)):
            rows_read = float(r.max()) + 1.0
            if cam.frames > 1 and cam.t_d is not None and cam.t_d < rows_read * cam.t_r - cam.t_e:
                raise ValueError(
                    f"cameras[{i}].t_d must be >= rows*t_r - t_e = {rows_read:g}*{cam.t_r:g} - {cam.t_e:g} = "
                    f"{rows_read * cam.t_r - cam.t_e:g} s in multi-frame mode, got {cam.t_d!r}"
                )
        self._windows = exposure_windows(
            self.start_times(),
            np.array([self.cameras[c].t_e for c, _ in self.channels]),
            np.array([self.cameras[c].gain for c, _ in self.channels]),
            dt,
        )
        ends = self._windows.end
        self.T = int(math.ceil(float(_snap(ends.max()))))
        if self.T > MAX_T:
            seconds, name = self._longest_time()
            raise ValueError(
                f"{name} = {seconds:g} s makes the rig span T = {self.T:,} sub-frames of dt = "
                f"{self.dt:g} s, above the {MAX_T:,} a rig may span (rsocl.model.rig.MAX_T); "
                "times are in seconds: choose a shorter one or a longer dt"
            )
        if self.T < 1:
            raise ValueError(
                f"dt = {self.dt!r} s is so long against the exposures (longest t_e = "
                f"{max(c.t_e for c in cameras):g} s) that the rig has no sub-frame; choose a dt "
                "near the row time t_r"
            )

    def _longest_time(self) -> tuple:
        """``(seconds, name)`` of the longest of the times that add up to the latest exposure end:
        a camera's ``t_e``, ``t_a``, ``(frames - 1) * t_d`` or readout of its rows."""
        times = []
        for i, (cam, rows) in enumerate(zip(self.cameras, self._rows)):
            times += [
                (cam.t_e, f"cameras[{i}].t_e"),
                (cam.t_a, f"cameras[{i}].t_a"),
                ((cam.frames - 1) * (cam.t_d or 0.0), f"cameras[{i}].t_d x (frames - 1)"),
                (float(rows.max()) * cam.t_r, f"cameras[{i}].t_r x its {float(rows.max()):g} rows"),
            ]
        return max(times, key=lambda item: item[0])

    # ------------------------------------------------------------------ construction
    @classmethod
    def paper_array(
        cls,
        n_cameras: int = 4,
        shape: tuple[int, int] = (50, 50),
        t_e: float = 0.18e-3,
        t_r: float = 35e-6,
        dt: float | None = None,
        mask: str = "exact",
    ) -> Rig:
        """The paper's array: ``n_cameras`` (1..8) at angles 0, 90, 180, 270, 45, 135, 225, 315.

        ``shape`` in pixels, ``t_e``, ``t_r`` and ``dt`` in seconds (``dt`` and ``mask`` as in
        :class:`Rig`); raises ``ValueError`` naming a value out of range. Cameras with other
        settings (offsets ``t_a``, gains, several frames) are built as :class:`Camera` and given to
        :class:`Rig`. Example: the class's.
        """
        n_cameras = check.positive_int("n_cameras", n_cameras, maximum=len(PAPER_ANGLES))
        cams = [Camera(angle, t_e=t_e, t_r=t_r) for angle in PAPER_ANGLES[:n_cameras]]
        return cls(cams, shape, dt=dt, mask=mask)

    # ------------------------------------------------------------------ channels
    @property
    def channels(self) -> list:
        """``(camera index, frame index)`` of each snapshot, camera-major."""
        return [(c, k) for c, cam in enumerate(self.cameras) for k in range(cam.frames)]

    @property
    def n_channels(self) -> int:
        """Number of snapshots ``K`` (cameras times frames)."""
        return sum(cam.frames for cam in self.cameras)

    @property
    def C(self) -> int:
        """Number of cameras."""
        return len(self.cameras)

    # ------------------------------------------------------------------ timing
    def start_times(self) -> np.ndarray:
        """Exposure start of every channel and pixel, seconds, ``(K, m, n)`` float64."""
        out = np.empty((self.n_channels,) + self.shape)
        for i, (c, k) in enumerate(self.channels):
            cam = self.cameras[c]
            out[i] = cam.t_a + self._rows[c] * cam.t_r + k * (cam.t_d or 0.0)
        return out

    def row_map(self, camera: int, roi: tuple[int, int, int, int] | None = None) -> np.ndarray:
        """Row map ``r(y, x)`` of camera ``camera``, rows: a copy of the whole ``(m, n)`` map, or with
        ``roi = (y, x, height, width)`` (pixels, inside the grid) of that block only.

        Raises ``ValueError`` naming ``camera`` outside ``0 .. cameras - 1``, or ``roi`` outside the grid."""
        count = len(self.cameras)
        if isinstance(camera, bool) or not isinstance(camera, numbers.Integral) or not 0 <= camera < count:
            raise ValueError(f"camera must be an integer in [0, {count - 1}], got {camera!r}")
        rows = self._rows[int(camera)]
        if roi is not None:
            y, x, h, w = self._checked_roi(roi)
            rows = rows[y : y + h, x : x + w]
        return rows.copy()

    def _checked_roi(self, roi) -> tuple[int, int, int, int]:
        """``roi = (y, x, height, width)`` as ints (whole pixels) inside the grid; else a ValueError naming ``roi``."""
        (m, n), values = self.shape, (tuple(roi) if np.ndim(roi) == 1 else ())
        if len(values) != 4 or not all(isinstance(v, numbers.Real) and float(v).is_integer() for v in values):
            raise ValueError(f"roi must be (y, x, height, width), 4 whole numbers of pixels, got {roi!r}")
        y, x, h, w = (int(v) for v in values)
        if not (0 <= y and 0 <= x and h >= 1 and w >= 1 and y + h <= m and x + w <= n):
            raise ValueError(f"roi must be (y, x, height, width) inside the {m}x{n} grid, got {tuple(roi)}")
        return y, x, h, w

    @property
    def windows(self) -> ExposureWindows:
        """Exposure windows in units of ``dt`` (see :class:`ExposureWindows`)."""
        return self._windows

    @property
    def window_length(self) -> int:
        """Longest per-pixel loop a kernel runs: ``ceil(max t_e/dt) + 1`` sub-frames."""
        return int(math.ceil(float(self._windows.length.max()))) + 1

    def sampled_window(self) -> tuple[np.ndarray, np.ndarray]:
        """First and last sub-frame with a non-zero weight, per channel and pixel.

        Returns
        -------
        first, last : ndarray of int, shape (K, m, n)
            Inclusive sub-frame indices (``first`` in ``[0, T-1]``); ``last = first - 1`` (no sub-frame)
            for a window with no weight, a ``binary`` one that holds no sub-frame start of ``0 .. T-1``.
        """
        first, last = _nonempty_bounds(*weighted_bounds(self._windows, self.mask), self.T)
        empty = last < first
        first = np.minimum(first, self.T - 1)
        last = np.where(empty, first - 1, last)
        return first.astype(np.int64), last.astype(np.int64)

    @cached_property
    def _pixel_bounds(self) -> tuple:
        """``(first, last, end)``: the first and the last sub-frame with a non-zero weight per channel and
        pixel (``(K, m, n)``, not clipped to ``[0, T-1]``), and per pixel the latest window end, sub-frames."""
        first, last = weighted_bounds(self._windows, self.mask)
        return first, last, self._windows.end.max(axis=0)

    def sampled_range(self, roi: tuple[int, int, int, int] | None = None) -> slice:
        """Sub-frames some camera samples at some pixel: ``slice(first, last + 1)``.

        Sub-frames outside it carry no information; the solver leaves them out and gives them the
        nearest sub-frame it solved (:mod:`rsocl.solver.held`). With ``roi = (y, x, height, width)``
        (pixels, inside the grid): the sampled range of the rig cut to that block
        (:meth:`crop`, whose cameras keep every pixel's exposure times), without
        building it. Windows with no weight (``binary`` ones that hold no sub-frame start) count for
        nothing; where no window has any weight, the last sub-frame, so that the range is never empty.
        """
        first, last, end = self._pixel_bounds
        T = self.T
        if roi is not None:
            y, x, h, w = (int(v) for v in roi)
            m, n = self.shape
            if not (0 <= y and 0 <= x and h >= 1 and w >= 1 and y + h <= m and x + w <= n):
                raise ValueError(f"roi must be (y, x, height, width) inside the {m}x{n} grid, got {tuple(roi)}")
            block = (slice(y, y + h), slice(x, x + w))
            first, last, end = first[(Ellipsis,) + block], last[(Ellipsis,) + block], end[block]
            T = int(math.ceil(float(_snap(end.max()))))
        first, last = _nonempty_bounds(first, last, T)
        held = first <= last
        if not held.any():  # no window holds a sub-frame: the last one, so that the range is never empty
            return slice(T - 1, T)
        return slice(int(first[held].min()), int(last[held].max()) + 1)

    @property
    def N_s(self) -> int:
        """Sub-frames one exposure spans under the paper's rule, ``ceil(t_e/t_r)`` (largest over cameras)."""
        return max(int(math.ceil(float(_snap(cam.t_e / cam.t_r)))) for cam in self.cameras)

    @property
    def exposure_subframes(self) -> float:
        """Exposure in sub-frames, ``t_e/dt`` (largest over cameras); the exact rule's N_s."""
        return float(self._windows.length.max())

    def cameras_per_subframe(self) -> np.ndarray:
        """How many cameras sample each sub-frame at some pixel, ``(T,)`` int."""
        first, last = self.sampled_window()
        counts = np.zeros(self.T, dtype=np.int64)
        for c in range(self.C):
            seen = np.zeros(self.T + 1, dtype=np.int64)
            for i, (cc, _) in enumerate(self.channels):
                if cc != c:
                    continue
                np.add.at(seen, first[i].ravel(), 1)
                np.add.at(seen, last[i].ravel() + 1, -1)
            counts += np.cumsum(seen)[: self.T] > 0
        return counts

    @property
    def min_cameras(self) -> int:
        """Trimming threshold: a sub-frame needs at least ``ceil(C/2)`` cameras to be kept."""
        return max(1, math.ceil(self.C / 2))

    def kept_subframes(self) -> slice:
        """The sub-frames kept after trimming (``T_se`` of them).

        Rule: drop the leading and trailing sub-frames that fewer than
        :attr:`min_cameras` cameras sample (at any pixel); interior ones are kept.
        """
        ok = np.nonzero(self.cameras_per_subframe() >= self.min_cameras)[0]
        if ok.size == 0:
            return slice(0, 0)
        return slice(int(ok[0]), int(ok[-1]) + 1)

    @property
    def T_se(self) -> int:
        """Sub-frames kept after trimming (see :meth:`kept_subframes`)."""
        kept = self.kept_subframes()
        return kept.stop - kept.start

    @property
    def compression_ratio(self) -> float:
        """``T_se / K``: reconstructed sub-frames per snapshot."""
        return self.T_se / self.n_channels

    @property
    def subframe_rate(self) -> float:
        """Sub-frames per second, ``1/dt`` (Hz)."""
        return 1.0 / self.dt

    def effective_fps(self, camera_fps: float) -> float:
        """Effective frame rate, ``camera_fps * T_se / frames`` (Hz), for cameras running at ``camera_fps``:
        the ``T_se`` sub-frames span the ``frames`` frames of a trigger (the most of any camera)."""
        frames = max(cam.frames for cam in self.cameras)
        return check.positive("camera_fps", camera_fps, "Hz") * self.T_se / frames

    def datacube_bytes(self, itemsize: int = 4) -> int:
        """Bytes of one ``(T, m, n)`` datacube at ``itemsize`` bytes per value."""
        return self.T * self.shape[0] * self.shape[1] * itemsize

    # ------------------------------------------------------------------ rigs made from this one
    def crop(self, roi, dt=None) -> Rig:
        """This rig restricted to ``roi = (y, x, height, width)`` of its reference grid, pixels, NumPy's order (a
        rig file's ``roi`` is ``x, y, width, height``), and sub-frames of ``dt`` seconds (None keeps this rig's).

        Each camera's row map is cut from the whole one (not re-zeroed), so the exposure start
        times are those of the whole sensor readout.
        """
        y, x, h, w = self._checked_roi(roi)
        cams = [
            Camera(**{**cam.to_dict(), "row_map": self.row_map(c, (y, x, h, w))}) for c, cam in enumerate(self.cameras)
        ]
        return Rig(cams, (h, w), dt=self.dt if dt is None else dt, mask=self.mask)

    def frames_window(self, k0: int, k1: int) -> Rig:
        """The rig of frames ``k0..k1-1`` of every camera, on this rig's sub-frame grid (same ``dt``):
        each trigger offset moves to ``t_a + k0*t_d``, so every exposure keeps its absolute start."""
        cams = [
            Camera.from_dict({**cam.to_dict(), "t_a": cam.t_a + k0 * (cam.t_d or 0.0), "frames": k1 - k0})
            for cam in self.cameras
        ]
        return Rig(cams, self.shape, dt=self.dt, mask=self.mask)

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict:
        """Plain-data description; see :meth:`from_dict`."""
        return {
            "shape": list(self.shape),
            "dt": self.dt,
            "mask": self.mask,
            "cameras": [cam.to_dict() for cam in self.cameras],
        }

    @classmethod
    def from_dict(cls, data: dict) -> Rig:
        cams = [Camera.from_dict(dict(c)) for c in data["cameras"]]
        return cls(cams, tuple(data["shape"]), dt=data["dt"], mask=data["mask"])

    def __eq__(self, other):
        if not isinstance(other, Rig):
            return NotImplemented
        return (
            self.shape == other.shape
            and self.dt == other.dt
            and self.mask == other.mask
            and self.cameras == other.cameras
        )

    def __repr__(self):
        return (
            f"Rig({self.C} cameras, shape={self.shape}, dt={self.dt:g} s, mask={self.mask!r}, "
            f"T={self.T}, T_se={self.T_se})"
        )
