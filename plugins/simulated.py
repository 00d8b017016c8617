"""The ``simulated`` camera backend: frames rendered through the forward model, the test double.

A :class:`SimulatedCamera` is one rolling-shutter camera of docs/model.md looking at a
scene. Each trigger renders one frame: the snapshot of a single-camera
:class:`~rsocl.model.rig.Rig` (same ``angle`` or ``row_map``, ``t_e``, ``t_r``, ``t_a``,
``gain``, ``dt``, ``mask``), computed on the OpenCL device by
:class:`~rsocl.model.operator.RollingShutterOperator`, then passed through a sensor
model that applies only the effects that are asked for.

Scene time
----------
Set ``k`` (the ``k``-th trigger, from 0) sees ``scene_frames`` sub-frames of the
scene starting at scene time ``k * scene_frames * dt``:

- ``scene = "builtin"``: :func:`rsocl.model.scenes.builtin_scene` of ``scene_frames``
  sub-frames, regenerated with seed ``scene_seed + k`` for set ``k``;
- ``scene = "<video path>"``: :func:`rsocl.model.scenes.load_scene` resamples the video
  to ``scene_sets * scene_frames`` sub-frames; set ``k`` takes the block
  ``k mod scene_sets`` (the video wraps around);
- ``scene = <array (F, m, n)>`` (Python callers): sub-frame ``s`` of set ``k`` is
  frame ``(k*scene_frames + s) mod F``.

Every camera of a rig that shares ``scene``, ``scene_seed``, ``scene_frames``
and ``dt`` sees the same datacube, so their frames form one consistent capture;
:meth:`SimulatedCamera.scene_truth` returns that datacube. The rig file fills
these keys in from the rig (see :meth:`rsocl.files.rigfile.RigFile.backends`).

Config keys: :mod:`rsocl_plugins.simulated_config`; sensor model: the ``sensor`` table, each effect off
by default (:mod:`rsocl_plugins.simulated_sensor`).

``Frame.meta`` carries ``set`` (set index), ``frame_id``, ``t_a`` (the offset
actually used), ``full_scale`` (model value of the largest integer level, so
``image / (2**bit_depth - 1) * full_scale`` converts back to model units),
``exposure`` and ``registered = True`` (frames are on the reference grid: the simulated sensor *is*
the reference grid, whatever the camera's ``angle``, ``row_map`` or homography). A ROI
(:meth:`~rsocl.hardware.backend.CameraBackend.set_roi`) cuts a window out of that grid (the camera's
``sensor_size`` is the grid's ``(n, m)``, known before it opens); its frames carry
``roi = [x, y, width, height]`` (pixels), which the capture uses to put them back in place (0 outside).
``fail_after = N`` makes the ``N``-th :meth:`read` raise
:class:`~rsocl.hardware.backend.CameraDisconnected` (and every later call, as a camera
that went away). The simulated camera never waits: :meth:`read` with no
pending trigger raises :class:`~rsocl.hardware.backend.CameraTimeout` at once.
"""

from __future__ import annotations

import functools

import numpy as np

from rsocl.hardware.backend import CameraBackend, CameraDisconnected, CameraError, CameraTimeout, Frame
from rsocl_plugins.simulated_config import SimulatedConfig, check_int
from rsocl_plugins.simulated_sensor import apply_sensor, sensor_bits

__all__ = ["SimulatedCamera"]


@functools.lru_cache(maxsize=16)
def _builtin(shape, T, seed):
    from rsocl.model.scenes import builtin_scene

    cube = builtin_scene(shape, T, dtype=np.float64, seed=seed)
    cube.setflags(write=False)
    return cube


class SimulatedCamera(SimulatedConfig, CameraBackend):
    """A rolling-shutter camera rendered through the forward model (see the module docstring)."""

    backend = "simulated"
    pixel_formats = ("Mono8", "Mono16", "Float32")

    def __init__(self, config=None, name=None):
        super().__init__(config, name)
        self._parse(self.config)
        self._device = None
        self._operators = {}
        self._video = None
        self._started = False
        self._pending = []
        self._next_set = 0
        self._reads = 0
        self._gone = False
        self._roi = None
        self._rng = np.random.default_rng([self.sensor["seed"], self.index])

    # ------------------------------------------------------------------ model
    def _operator(self, t_a):
        from rsocl.model.operator import RollingShutterOperator

        key = (self.t_e, t_a)
        op = self._operators.get(key)
        if op is None:
            dtype = self.dtype or ("float64" if self._device.has_fp64 else "float32")
            op = RollingShutterOperator(self._rig(self.t_e, t_a), device=self._device, dtype=dtype)
            if len(self._operators) > 4:
                self._operators.clear()
            self._operators[key] = op
        return op

    @property
    def full_scale(self) -> float:
        """Model value of full scale: ``saturation``, else a white scene's value at unit gain (``t_e/dt``; with
        the binary mask, the most sub-frame starts an exposure holds: :func:`rsocl.model.curvature.white_levels`)."""
        sat = self.sensor["saturation"]
        return float(sat) if sat is not None else self.white

    def scene_truth(self, set_index: int = 0) -> np.ndarray:
        """The ``(scene_frames, m, n)`` datacube (float64, [0, 1]) that set ``set_index`` sees."""
        set_index = check_int("set_index", set_index, 0)
        T = self.scene_frames
        if self.scene_array is not None:
            F = self.scene_array.shape[0]
            return self.scene_array[(set_index * T + np.arange(T)) % F]
        if self.scene == "builtin":
            return _builtin(self.shape, T, self.scene_seed + set_index)
        if self._video is None:
            from rsocl.model.scenes import load_scene

            self._video = load_scene(self.scene, self.shape, T * self.scene_sets).astype(np.float64)
        block = set_index % self.scene_sets
        return self._video[block * T : (block + 1) * T]

    def render(self, set_index: int, t_a: float | None = None) -> np.ndarray:
        """Noise-free model frame ``(m, n)`` float64 of set ``set_index`` with trigger offset ``t_a`` (s)."""
        if self._device is None:
            from rsocl.device.context import get_device

            self._device = get_device(self.device_spec)
        op = self._operator(self.t_a if t_a is None else float(t_a))
        truth = self.scene_truth(set_index)
        T = op.rig.T
        if T > truth.shape[0]:  # a late (jittered) trigger runs past the scene: hold the last sub-frame
            truth = np.concatenate([truth, np.repeat(truth[-1:], T - truth.shape[0], axis=0)])
        return np.asarray(op.forward(np.ascontiguousarray(truth[:T])), dtype=np.float64)[0]

    def _sensor(self, g):
        return apply_sensor(g, self.sensor, self.full_scale, self.pixel_format, self._rng)

    def _bits(self):
        return sensor_bits(self.sensor["bit_depth"], self.pixel_format)

    # ------------------------------------------------------------------ hooks
    def _alive(self):
        if self._gone:
            raise CameraDisconnected(f"{self.name}: simulated camera disconnected")

    def _open_device(self):
        from rsocl.device.context import get_device

        self._gone = False
        self._device = get_device(self.device_spec)
        self.scene_truth(0)  # a missing or bad video fails at open, not mid-run

    def _close_device(self):
        self._started = False
        self._pending.clear()
        self._operators.clear()

    def _set_exposure(self, seconds):
        self._alive()
        if self.exposure_range is not None:
            seconds = min(max(seconds, self.exposure_range[0]), self.exposure_range[1])
        self.t_e = seconds
        return seconds

    def _set_roi(self, x, y, width, height):
        self._alive()
        if self._started:
            raise CameraError(f"{self.name}: stop acquisition before changing the ROI")
        m, n = self.shape
        if x + width > n or y + height > m:
            raise CameraError(
                f"{self.name}: ROI x={x}, y={y}, {width}x{height} exceeds the {n}x{m} (width x height) simulated sensor"
            )
        self._roi = (x, y, width, height)

    def _set_pixel_format(self, pixel_format):  # one of pixel_formats: no Mono8 above 8 bits
        self._alive()
        self.pixel_format = pixel_format

    def _sensor_size(self):  # the simulated sensor is the reference grid
        return self.shape[1], self.shape[0]

    def _set_trigger(self, mode, source):
        self._alive()
        if mode == "line":
            raise CameraError(f"{self.name}: a simulated camera has no trigger lines; use 'software' or 'free'")

    def _readout_time(self):
        return self.t_r

    def _start(self):
        self._alive()
        self._started = True

    def _stop(self):
        self._started = False
        self._pending.clear()

    def _trigger(self):
        self._alive()
        if not self._started:
            raise CameraError(f"{self.name}: acquisition not started (call start() first)")
        if self._trigger_mode != "software":
            raise CameraError(f"{self.name}: software trigger in {self._trigger_mode!r} trigger mode")
        self._pending.append(self._next_trigger())

    def _next_trigger(self):
        jitter = self.sensor["trigger_jitter"]
        t_a = self.t_a + (self._rng.normal(0.0, jitter) if jitter > 0 else 0.0)
        item = (self._next_set, max(0.0, t_a))
        self._next_set += 1
        return item

    def _read(self, timeout):
        self._alive()
        self._reads += 1
        if self.fail_after is not None and self._reads >= self.fail_after:
            self._gone = True
            raise CameraDisconnected(
                f"{self.name}: simulated disconnection on read {self._reads} (fail_after={self.fail_after})"
            )
        if not self._started:
            raise CameraError(f"{self.name}: acquisition not started (call start() first)")
        if not self._pending:
            if self._trigger_mode == "free":
                self._pending.append(self._next_trigger())
            else:
                raise CameraTimeout(f"{self.name}: no frame within {timeout:g} s (no trigger pending)")
        set_index, t_a = self._pending.pop(0)
        image = self._sensor(self.render(set_index, t_a))
        if self._roi is not None:
            x, y, w, h = self._roi
            image = image[y : y + h, x : x + w]
        meta = {
            "set": set_index,
            "frame_id": self._reads - 1,
            "t_a": t_a,
            "full_scale": self.full_scale,
            "exposure": self.t_e,
            "registered": True,  # rendered on the reference grid, whatever the camera's geometry
        }
        if self._roi is not None and self._roi != (0, 0) + self.shape[::-1]:
            meta["roi"] = list(self._roi)  # where the frame lies on the reference grid
        return Frame(
            image=np.ascontiguousarray(image),
            timestamp=set_index * self.scene_frames * self.dt + t_a,
            pixel_format=self.pixel_format,
            bit_depth=self._bits(),
            meta=meta,
        )
