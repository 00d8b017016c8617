"""Camera plugin faults found by QA: Aravis triggers and ROIs changed by refused requests, a V4L2 ROI lost or
cut from scaled frames, V4L2 frame gaps lost with skipped frames. Aravis against a small fake ArvDevice (no
PyGObject needed); V4L2 against tests/test_v4l2.py's fake driver."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from rsocl.hardware.backend import CameraError
from rsocl_plugins.aravis import AravisCamera
from rsocl_plugins.v4l2 import V4L2Camera

from test_v4l2 import FakeV4L2Device


class _GError(Exception):
    def __init__(self, message):
        super().__init__(message)
        self.domain, self.code, self.message = "arv-gc-error-quark", 1, message


class _Device:
    """Enumerations (``values``, ``value``) and integers (``lo``, ``hi``: numbers or functions of the device)."""

    def __init__(self, features):
        self.features, self.log = features, []

    def is_feature_available(self, f):
        return f in self.features

    def dup_available_enumeration_feature_values_as_strings(self, f):
        return list(self.features[f]["values"])

    def set_string_feature_value(self, f, v):
        if v not in self.features[f]["values"]:
            raise _GError(f"{f}: no value {v}")
        self.log.append((f, v))
        self.features[f]["value"] = v

    def get_string_feature_value(self, f):
        return self.features[f]["value"]

    def get_integer_feature_value(self, f):
        return self.features[f]["value"]

    def get_integer_feature_bounds(self, f):
        lo, hi = self.features[f]["lo"], self.features[f]["hi"]
        return (lo(self) if callable(lo) else lo), (hi(self) if callable(hi) else hi)

    def get_integer_feature_increment(self, f):
        return 1

    def set_integer_feature_value(self, f, v):
        lo, hi = self.get_integer_feature_bounds(f)
        if not lo <= v <= hi:
            raise _GError(f"{f} = {v} outside [{lo}, {hi}]")
        self.log.append((f, v))
        self.features[f]["value"] = v


def _aravis(features):
    cam = AravisCamera({}, name="fake")
    cam._aravis = SimpleNamespace()
    cam._glib = SimpleNamespace(Error=_GError)
    cam._device, cam._camera, cam._open = _Device(features), SimpleNamespace(), True
    return cam


def _value(name):
    return lambda device: device.features[name]["value"]


def test_aravis_free_run_turns_the_trigger_off_on_a_camera_without_trigger_selector():
    cam = _aravis(
        {
            "TriggerMode": {"values": ["Off", "On"], "value": "Off"},
            "TriggerSource": {"values": ["Software", "Line1"], "value": "Line1"},
            "TriggerSoftware": {},
        }
    )
    cam.set_trigger("software")
    assert cam._device.features["TriggerMode"]["value"] == "On"
    cam.set_trigger("free")
    assert cam._device.features["TriggerMode"]["value"] == "Off"


def test_aravis_refused_roi_or_trigger_source_leave_the_camera_as_it_was():
    roi = {"OffsetX": 192, "OffsetY": 144, "Width": 640, "Height": 480}
    features = {
        "Width": {"value": 640, "lo": 16, "hi": lambda d: 1024 - d.features["OffsetX"]["value"]},
        "Height": {"value": 480, "lo": 16, "hi": lambda d: 768 - d.features["OffsetY"]["value"]},
        "OffsetX": {"value": 192, "lo": 0, "hi": lambda d: 1024 - d.features["Width"]["value"]},
        "OffsetY": {"value": 144, "lo": 0, "hi": lambda d: 768 - d.features["Height"]["value"]},
        "TriggerMode": {"values": ["Off", "On"], "value": "Off"},
        "TriggerSource": {"values": ["Software", "Line1"], "value": "Line1"},
    }
    cam = _aravis(features)
    with pytest.raises(CameraError, match=r"ROI OffsetX = 912 is outside the device's range \[0, 768\]"):
        cam.set_roi(912, 0, 256, 256)
    assert {f: features[f]["value"] for f in roi} == roi
    with pytest.raises(
        CameraError, match=r"TriggerSource cannot be 'Line9'; the device offers \['Software', 'Line1'\]"
    ):
        cam.set_trigger("line", "Line9")
    assert features["TriggerMode"]["value"] == "Off"


def test_aravis_sensor_size_is_widthmax_heightmax_else_the_sensor_features_once_open():
    sizes = {"WidthMax": 1024, "HeightMax": 768, "SensorWidth": 2048, "SensorHeight": 1536}
    cam = _aravis({f: {"value": v} for f, v in sizes.items()})
    assert cam.sensor_size == (1024, 768)  # binned: the ROI's bounds, not the physical sensor
    cam = _aravis({f: {"value": v} for f, v in sizes.items() if f.startswith("Sensor")})
    assert cam.sensor_size == (2048, 1536)
    assert _aravis({"WidthMax": {"value": 1024}}).sensor_size is None
    assert AravisCamera({}, name="closed").sensor_size is None  # known once open


class _SmallerY16(FakeV4L2Device):
    """A driver whose GREY frames are 12x6 and whose Y16 frames only 8x4."""

    def _update_format(self):
        super()._update_format()
        if self.raw.PixelFormat(self.fmt["pixelformat"]).name == "Y16":
            bpl = 2 * 8 + self.pad
            self.fmt.update(width=8, height=4, bytesperline=bpl, sizeimage=bpl * 4)


def test_v4l2_a_roi_that_a_new_pixel_format_does_not_fit_is_an_error_not_dropped():
    with _SmallerY16(formats=("GREY", "Y16")) as fake, V4L2Camera({"device": fake.path}) as cam:
        cam.set_roi(8, 3, 4, 3)
        with pytest.raises(CameraError, match=r"the ROI \[8, 3, 4, 3\] does not fit the Y16 frames of 8x4"):
            cam.set_pixel_format("Y16")


class _HalfScaler(FakeV4L2Device):
    """A driver with the selection API that bins 2x2: its frames are half its crop in each direction."""

    def _update_format(self):
        w, h = self.crop[2] // 2, self.crop[3] // 2
        self.fmt.update(width=w, height=h, bytesperline=w + self.pad, sizeimage=(w + self.pad) * h)


def test_v4l2_a_sensor_pixel_roi_is_not_cut_from_scaled_frames():
    with _HalfScaler(sensor=(20, 10), selection=True, formats=("GREY",)) as fake:
        with V4L2Camera({"device": fake.path}) as cam:
            with pytest.raises(CameraError, match="scales its 20x10 sensor area to 10x5 frames"):
                cam.set_roi(2, 1, 6, 4)


def test_v4l2_frames_lost_before_a_skipped_frame_count_on_the_next_one():
    with FakeV4L2Device() as fake, V4L2Camera({"device": fake.path}) as cam:
        cam.set_trigger("free")
        cam.start()
        fake.emit(np.full((6, 12), 1))
        assert cam.read(1.0).meta["dropped"] == 0
        fake.emit(np.full((6, 12), 2), skip=2, error=True)  # the driver lost 2 frames, then a corrupt one
        fake.emit(np.full((6, 12), 3))
        meta = cam.read(1.0).meta
        assert (meta["dropped"], meta["skipped"]) == (2, 1)
        fake.emit(np.full((6, 12), 4))
        assert cam.read(1.0).meta["dropped"] == 0
