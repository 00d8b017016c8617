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

Config keys (seconds, degrees)
------------------------------
``scene`` (``"builtin"``), ``scene_seed`` (0), ``scene_frames`` (default: this
camera's own ``T``), ``scene_sets`` (1, videos only), ``shape`` ``[m, n]`` of the
reference ROI = the simulated sensor (required unless ``row_map`` or an array
scene gives it), ``angle`` (0) or ``row_map`` (``(m, n)`` rows), ``t_e``, ``t_r``
(required), ``t_a`` (0), ``gain`` (1), ``dt`` (default ``t_r``), ``mask``
(``"exact"``), ``pixel_format`` (default: ``Float32`` without ``bit_depth``,
else ``Mono8``/``Mono16``), ``sensor`` (below), ``fail_after``, ``device`` and
``dtype`` (OpenCL device spec, default rsocl's default device; ``float64`` when
the device has it), ``index`` (camera index in the rig, mixed into the noise
seed so that cameras draw independent noise), ``address`` (ignored, a label),
``exposure_range`` ``[shortest, longest]`` (s; default: any exposure): as a real
device does, :meth:`~rsocl.hardware.backend.CameraBackend.set_exposure` clamps to it,
renders with the clamped exposure and returns it.

Sensor model: the ``sensor`` table, each effect off by default (:mod:`rsocl_plugins.simulated_sensor`).

``Frame.meta`` carries ``set`` (set index), ``frame_id``, ``t_a`` (the offset
actually used), ``full_scale`` (model value of the largest integer level, so
``image / (2**bit_depth - 1) * full_scale`` converts back to model units),
``exposure`` and ``registered = True`` (frames are on the reference grid).
``fail_after = N`` makes the ``N``-th :meth:`read` raise
:class:`~rsocl.hardware.backend.CameraDisconnected` (and every later call, as a camera
that went away). The simulated camera never waits: :meth:`read` with no
pending trigger raises :class:`~rsocl.hardware.backend.CameraTimeout` at once.
"""

from __future__ import annotations

import functools
import numbers
import os

import numpy as np

from rsocl.common import validation as check
from rsocl.hardware.backend import CameraBackend, CameraDisconnected, CameraError, CameraTimeout, Frame
from rsocl_plugins.simulated_sensor import SENSOR_KEYS, apply_sensor, sensor_bits

__all__ = ["SimulatedCamera"]

_CONFIG_KEYS = {
    "scene",
    "scene_seed",
    "scene_frames",
    "scene_sets",
    "shape",
    "angle",
    "row_map",
    "t_e",
    "t_r",
    "t_a",
    "gain",
    "dt",
    "mask",
    "pixel_format",
    "sensor",
    "fail_after",
    "device",
    "dtype",
    "index",
    "address",
    "exposure_range",
}


@functools.lru_cache(maxsize=16)
def _builtin(shape, T, seed):
    from rsocl.model.scenes import builtin_scene

    cube = builtin_scene(shape, T, dtype=np.float64, seed=seed)
    cube.setflags(write=False)
    return cube


def _int(name, value, minimum):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


class SimulatedCamera(CameraBackend):
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

    # ------------------------------------------------------------------ config
    def _key(self, key):
        return f"{self.name}: config[{key!r}]"

    def _parse(self, cfg):
        check.unknown_keys(self.name, cfg, _CONFIG_KEYS)
        k = self._key
        for key in ("t_e", "t_r"):
            if cfg.get(key) is None:
                raise ValueError(f"{k(key)} is required (seconds)")
        self.t_e = check.positive(k("t_e"), cfg["t_e"], "seconds")
        self.t_r = check.positive(k("t_r"), cfg["t_r"], "seconds")
        self.t_a = check.non_negative(k("t_a"), cfg.get("t_a", 0.0), "seconds")
        self.gain = check.positive(k("gain"), cfg.get("gain", 1.0))
        self.dt = check.positive(k("dt"), cfg.get("dt", self.t_r), "seconds")
        self.mask = check.choice(k("mask"), cfg.get("mask", "exact"), {"exact", "binary"})
        if "angle" in cfg and cfg.get("row_map") is not None:
            raise ValueError(f"{self.name}: give config 'angle' or 'row_map', not both")
        self.angle = check.finite(k("angle"), cfg.get("angle", 0.0))
        self.row_map = None
        if cfg.get("row_map") is not None:
            self.row_map = check.finite_array(k("row_map"), cfg["row_map"]).astype(np.float64)
            if self.row_map.ndim != 2:
                raise ValueError(f"{k('row_map')} must be a 2-D array of rows, got shape {self.row_map.shape}")

        scene = cfg.get("scene", "builtin")
        self.scene_array = None
        if isinstance(scene, np.ndarray):
            self.scene_array = check.finite_array(k("scene"), scene).astype(np.float64)
            if self.scene_array.ndim != 3 or 0 in self.scene_array.shape:
                raise ValueError(f"{k('scene')} array must be (frames, m, n), got shape {self.scene_array.shape}")
        elif not isinstance(scene, (str, os.PathLike)):
            raise ValueError(f"{k('scene')} must be 'builtin', a video path or a (frames, m, n) array, got {scene!r}")
        self.scene = scene if self.scene_array is None else "array"

        shape = cfg.get("shape")
        if shape is None:
            if self.row_map is not None:
                shape = self.row_map.shape
            elif self.scene_array is not None:
                shape = self.scene_array.shape[1:]
            else:
                raise ValueError(f"{k('shape')} ([m, n], pixels of the reference ROI) is required")
        try:
            m, n = shape
        except (TypeError, ValueError):
            raise ValueError(f"{k('shape')} must be [m, n], got {shape!r}") from None
        self.shape = (check.positive_int(k("shape") + "[0]", m), check.positive_int(k("shape") + "[1]", n))
        if self.row_map is not None and self.row_map.shape != self.shape:
            raise ValueError(f"{k('row_map')} has shape {self.row_map.shape}, config 'shape' is {self.shape}")
        if self.scene_array is not None and self.scene_array.shape[1:] != self.shape:
            raise ValueError(
                f"{k('scene')} frames have shape {self.scene_array.shape[1:]}, config 'shape' is {self.shape}"
            )
        self.scene_seed = _int(k("scene_seed"), cfg.get("scene_seed", 0), 0)
        self.scene_sets = _int(k("scene_sets"), cfg.get("scene_sets", 1), 1)
        frames = cfg.get("scene_frames")
        self.scene_frames = None if frames is None else _int(k("scene_frames"), frames, 1)
        self.index = _int(k("index"), cfg.get("index", 0), 0)
        fail_after = cfg.get("fail_after")
        self.fail_after = None if fail_after is None else _int(k("fail_after"), fail_after, 1)
        self.exposure_range = None
        if cfg.get("exposure_range") is not None:
            try:
                low, high = cfg["exposure_range"]
            except (TypeError, ValueError):
                raise ValueError(
                    f"{k('exposure_range')} must be [shortest, longest] in seconds, got {cfg['exposure_range']!r}"
                ) from None
            low = check.positive(k("exposure_range") + "[0]", low, "seconds")
            high = check.positive(k("exposure_range") + "[1]", high, "seconds")
            if high < low:
                raise ValueError(
                    f"{k('exposure_range')} must be [shortest, longest] with shortest <= longest, "
                    f"got {cfg['exposure_range']!r}"
                )
            self.exposure_range = (low, high)
        self.device_spec = cfg.get("device")
        self.dtype = cfg.get("dtype")

        sensor = cfg.get("sensor") or {}
        if not isinstance(sensor, dict):
            raise ValueError(f"{k('sensor')} must be a table of sensor options, got {sensor!r}")
        check.unknown_keys(self.name, sensor, SENSOR_KEYS, what="sensor option")
        s = {key: sensor.get(key) for key in SENSOR_KEYS}
        sk = lambda key: f"{self.name}: sensor[{key!r}]"  # noqa: E731
        if s["shot_noise_photons"] is not None:
            s["shot_noise_photons"] = check.positive(sk("shot_noise_photons"), s["shot_noise_photons"])
        s["read_noise"] = check.non_negative(sk("read_noise"), s["read_noise"] or 0.0, "(fraction of full scale)")
        if s["bit_depth"] is not None:
            s["bit_depth"] = check.positive_int(sk("bit_depth"), s["bit_depth"], maximum=16)
        if s["saturation"] is not None:
            s["saturation"] = check.positive(sk("saturation"), s["saturation"])
        s["trigger_jitter"] = check.non_negative(sk("trigger_jitter"), s["trigger_jitter"] or 0.0, "seconds")
        s["seed"] = _int(sk("seed"), 0 if s["seed"] is None else s["seed"], 0)
        self.sensor = s

        default_format = "Float32" if s["bit_depth"] is None else ("Mono8" if s["bit_depth"] <= 8 else "Mono16")
        self.pixel_format = cfg.get("pixel_format", default_format)
        if self.pixel_format not in self.pixel_formats:
            raise ValueError(
                f"{k('pixel_format')} must be one of {list(self.pixel_formats)}, got {self.pixel_format!r}"
            )
        if self.pixel_format == "Mono8" and (s["bit_depth"] or 8) > 8:
            raise ValueError(
                f"{self.name}: pixel_format 'Mono8' holds at most 8 bits, sensor bit_depth is {s['bit_depth']}"
            )
        try:
            own_T = self._rig(self.t_e, self.t_a).T
        except ValueError as exc:
            raise ValueError(f"{self.name}: {exc}") from None
        if self.scene_frames is None:
            self.scene_frames = own_T
        from rsocl.common.memory import check_host_memory

        m, n = self.shape
        frames = self.scene_frames * (self.scene_sets if self.scene_array is None and self.scene != "builtin" else 1)
        check_host_memory(
            8 * frames * m * n,
            f"{k('scene_frames')} = {self.scene_frames} (t_e = {self.t_e:g} s, "
            f"dt = {self.dt:g} s: the camera's own T = {own_T:,})",
            f"its scene of {frames:,} x {m} x {n} float64 sub-frames",
            "choose fewer scene_frames, a shorter t_e or a longer dt",
        )

    # ------------------------------------------------------------------ model
    def _rig(self, t_e, t_a):
        from rsocl.model.rig import Camera, Rig

        camera = Camera(self.angle, t_e=t_e, t_r=self.t_r, t_a=t_a, gain=self.gain, row_map=self.row_map)
        return Rig([camera], self.shape, dt=self.dt, mask=self.mask)

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
        """Model value of full scale: ``saturation``, else ``t_e/dt`` (white scene, unit gain)."""
        sat = self.sensor["saturation"]
        return float(sat) if sat is not None else self.t_e / self.dt

    def scene_truth(self, set_index: int = 0) -> np.ndarray:
        """The ``(scene_frames, m, n)`` datacube (float64, [0, 1]) that set ``set_index`` sees."""
        set_index = _int("set_index", set_index, 0)
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

    def _set_pixel_format(self, pixel_format):
        self._alive()
        if pixel_format == "Mono8" and (self.sensor["bit_depth"] or 8) > 8:
            raise CameraError(
                f"{self.name}: pixel format Mono8 holds at most 8 bits, sensor bit_depth is {self.sensor['bit_depth']}"
            )
        self.pixel_format = pixel_format

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
            "registered": self._roi is None or self._roi == (0, 0) + self.shape[::-1],
        }
        return Frame(
            image=np.ascontiguousarray(image),
            timestamp=set_index * self.scene_frames * self.dt + t_a,
            pixel_format=self.pixel_format,
            bit_depth=self._bits(),
            meta=meta,
        )
