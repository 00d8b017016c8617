"""The config of a ``simulated`` camera (:mod:`rsocl_plugins.simulated`): its keys, parsed and checked.

Config keys (seconds, degrees)
------------------------------
``scene`` (``"builtin"``, or a video file that must exist; a rig file resolves a relative path against its
folder), ``scene_seed`` (0), ``scene_frames`` (default: this
camera's own ``T``), ``scene_sets`` (1, videos only), ``shape`` ``[m, n]`` of the
reference ROI = the simulated sensor (required unless ``row_map`` or an array
scene gives it), ``angle`` (0) or ``row_map`` (``(m, n)`` rows), ``t_e``, ``t_r``
(required), ``t_a`` (0), ``gain`` (1), ``dt`` (default ``t_r``), ``mask``
(``"exact"``), ``pixel_format`` (default: ``Float32`` without ``bit_depth``,
else ``Mono8``/``Mono16``; a ``bit_depth`` above 8 leaves ``Mono8`` out of the camera's
``pixel_formats``), ``sensor`` (:mod:`rsocl_plugins.simulated_sensor`),
``fail_after``, ``device`` and ``dtype`` (OpenCL device spec, default rsocl's
default device; ``float64`` when the device has it), ``index`` (camera index in
the rig, mixed into the noise seed so that cameras draw independent noise),
``address`` (ignored, a label), ``exposure_range`` ``[shortest, longest]`` (s;
default: any exposure): as a real device does,
:meth:`~rsocl.hardware.backend.CameraBackend.set_exposure` clamps to it, renders
with the clamped exposure and returns it.

Every key is checked when the camera is made (:meth:`SimulatedConfig._parse`), before anything is
rendered; an error names the camera and the key.
"""

from __future__ import annotations

import numbers
import os

import numpy as np

from rsocl.common import validation as check
from rsocl.model.rig import Rig
from rsocl_plugins.simulated_sensor import SENSOR_KEYS

__all__ = ["CONFIG_KEYS", "SimulatedConfig", "check_int"]

#: The keys a simulated camera's config may hold.
CONFIG_KEYS = {
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


def check_int(name, value, minimum):
    """``value`` as an ``int`` when it is an integer (not a bool) of at least ``minimum``, else a ValueError
    naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


class SimulatedConfig:
    """The checked config of a simulated camera, as attributes (``t_e``, ``t_r``, ``shape``, ``scene``,
    ``sensor``, ...), and the one-camera :class:`~rsocl.model.rig.Rig` it describes.

    A mixin of :class:`rsocl_plugins.simulated.SimulatedCamera`, which calls :meth:`_parse` with its
    config when it is made; ``name`` and ``pixel_formats`` are the camera's (:meth:`_parse` narrows the
    latter to those its sensor's ``bit_depth`` allows).
    """

    name: str
    pixel_formats: tuple[str, ...]

    def _key(self, key):
        return f"{self.name}: config[{key!r}]"

    def _parse(self, cfg):
        from rsocl.model.curvature import white_levels
        from rsocl.model.simulate import MAX_PHOTONS, check_photons

        check.unknown_keys(self.name, cfg, CONFIG_KEYS)
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
        elif scene != "builtin" and not os.path.isfile(scene):
            raise ValueError(
                f"{k('scene')}: video file {os.fspath(scene)!r} does not exist (in a rig file, a relative path "
                "is relative to the rig file's folder)"
            )
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
        self.scene_seed = check_int(k("scene_seed"), cfg.get("scene_seed", 0), 0)
        self.scene_sets = check_int(k("scene_sets"), cfg.get("scene_sets", 1), 1)
        frames = cfg.get("scene_frames")
        self.scene_frames = None if frames is None else check_int(k("scene_frames"), frames, 1)
        self.index = check_int(k("index"), cfg.get("index", 0), 0)
        fail_after = cfg.get("fail_after")
        self.fail_after = None if fail_after is None else check_int(k("fail_after"), fail_after, 1)
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
        dtype = cfg.get("dtype")
        self.dtype = None if dtype is None else check.choice(k("dtype"), dtype, {"float32", "float64"})

        sensor = cfg.get("sensor") or {}
        if not isinstance(sensor, dict):
            raise ValueError(f"{k('sensor')} must be a table of sensor options, got {sensor!r}")
        check.unknown_keys(self.name, sensor, SENSOR_KEYS, what="sensor option")
        s = {key: sensor.get(key) for key in SENSOR_KEYS}
        sk = lambda key: f"{self.name}: sensor[{key!r}]"  # noqa: E731
        if s["shot_noise_photons"] is not None:
            s["shot_noise_photons"] = check_photons(sk("shot_noise_photons"), s["shot_noise_photons"])
        s["read_noise"] = check.non_negative(sk("read_noise"), s["read_noise"] or 0.0, "(fraction of full scale)")
        if s["bit_depth"] is not None:
            s["bit_depth"] = check.positive_int(sk("bit_depth"), s["bit_depth"], maximum=16)
        if s["saturation"] is not None:
            s["saturation"] = check.positive(sk("saturation"), s["saturation"])
        s["trigger_jitter"] = check.non_negative(sk("trigger_jitter"), s["trigger_jitter"] or 0.0, "seconds")
        s["seed"] = check_int(sk("seed"), 0 if s["seed"] is None else s["seed"], 0)
        self.sensor = s
        if (s["bit_depth"] or 8) > 8:  # Mono8 holds at most 8 bits: this camera delivers the others
            self.pixel_formats = tuple(f for f in self.pixel_formats if f != "Mono8")

        default_format = "Float32" if s["bit_depth"] is None else ("Mono8" if s["bit_depth"] <= 8 else "Mono16")
        self.pixel_format = cfg.get("pixel_format", default_format)
        if self.pixel_format == "Mono8" and (s["bit_depth"] or 8) > 8:
            raise ValueError(
                f"{self.name}: pixel_format 'Mono8' holds at most 8 bits, sensor bit_depth is {s['bit_depth']}"
            )
        if self.pixel_format not in self.pixel_formats:
            raise ValueError(
                f"{k('pixel_format')} must be one of {list(self.pixel_formats)}, got {self.pixel_format!r}"
            )
        try:
            own = self._rig(self.t_e, self.t_a)
        except ValueError as exc:
            raise ValueError(f"{self.name}: {exc}") from None
        own_T = own.T
        self.white = float(white_levels(own)[0])  # a white scene's value at unit gain
        full = s["saturation"] if s["saturation"] is not None else self.white
        photons = s["shot_noise_photons"]
        if photons is not None and photons * self.gain * self.white / full > MAX_PHOTONS:
            most = MAX_PHOTONS * full / (self.gain * self.white)
            raise ValueError(
                f"{sk('shot_noise_photons')} must be at most {most:.3g} here: a white scene's mean "
                f"(photons x gain x white / full scale) must stay within the Poisson sampler's {MAX_PHOTONS:g}, "
                f"got {photons!r}"
            )
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

    def _rig(self, t_e, t_a):
        from rsocl.model.rig import Camera

        camera = Camera(self.angle, t_e=t_e, t_r=self.t_r, t_a=t_a, gain=self.gain, row_map=self.row_map)
        return CameraOfRig([camera], self.shape, dt=self.dt, mask=self.mask)


class CameraOfRig(Rig):
    """The rig of one camera of a larger rig: its ``dt``, the larger rig's, may be below this camera's ``t_r``
    (the larger rig's smallest ``t_r`` bounds it)."""

    _part_of_larger = True
