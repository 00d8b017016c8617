"""How the v4l2 backend's config errors name the rig file's keys: ``config['buffers']``, as the aravis backend
does; against the ioctl-level fake of tests/test_v4l2.py where a device is needed."""

from __future__ import annotations

from contextlib import ExitStack

import pytest

from rsocl.hardware.backend import CameraError
from rsocl_plugins.v4l2 import V4L2Camera
from rsocl_plugins.v4l2_formats import PIXEL_FORMATS

from test_v4l2 import FakeV4L2Device

READ = str(list(PIXEL_FORMATS))  # the formats the backend reads, as its messages list them


@pytest.fixture
def make_fake():
    pytest.importorskip("linuxpy.video.device", reason='linuxpy not installed (pip install "rsocl[v4l2]")')
    with ExitStack() as stack:
        yield lambda **kw: stack.enter_context(FakeV4L2Device(**kw))


@pytest.mark.parametrize(
    "config, message",
    [
        ({"buffers": 0}, "v4l2 /dev/video0: config['buffers'] must be an integer in 1..32, got 0"),
        ({"buffers": 2.5}, "v4l2 /dev/video0: config['buffers'] must be an integer in 1..32, got 2.5"),
        ({"pixel_format": "MJPEG"}, f"v4l2 /dev/video0: config['pixel_format'] must be one of {READ}, got 'MJPEG'"),
        ({"pixel_format": ["Y16"]}, f"v4l2 /dev/video0: config['pixel_format'] must be one of {READ}, got ['Y16']"),
        ({"width": 0}, "v4l2 /dev/video0: config['width'] must be a positive integer (pixels), got 0"),
        ({"height": "480"}, "v4l2 /dev/video0: config['height'] must be a positive integer (pixels), got '480'"),
        ({"device": -1}, "v4l2 camera: config['device'] must be an index >= 0 or a path like /dev/video0, got -1"),
        ({"address": 2.5}, "v4l2 camera: config['address'] must be a path like /dev/video0 or an index >= 0, got 2.5"),
        (
            {"address": "/dev/video2", "device": 3},
            "v4l2 camera: config['address'] = '/dev/video2' (/dev/video2) and config['device'] = 3 (/dev/video3) "
            "name different devices; give one of them (a path like /dev/video0 or an index)",
        ),
    ],
)
def test_config_errors_name_the_key_as_config_key(config, message):
    with pytest.raises(ValueError) as info:
        V4L2Camera(config)
    assert str(info.value) == message


def test_a_rig_file_config_error_names_the_camera_and_its_config_key(tmp_path):
    from rsocl.hardware.capture import capture_sets

    rig = tmp_path / "rig.toml"
    rig.write_text(
        '[rig]\nshape = [6, 12]\n\n[[camera]]\nbackend = "v4l2"\naddress = "/dev/video7"\nangle = 0.0\n'
        "t_e = 0.01\nt_r = 0.001\n\n[camera.config]\nbuffers = 64\n"
    )
    with pytest.raises(ValueError) as info:
        capture_sets(rig, tmp_path / "c.h5")
    assert str(info.value) == "camera 0 (v4l2 /dev/video7): config['buffers'] must be an integer in 1..32, got 64"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]


def test_a_pixel_format_the_device_lacks_names_the_config_key(make_fake):
    fake = make_fake(formats=("GREY", "YUYV"))
    with pytest.raises(CameraError) as info:
        V4L2Camera({"device": fake.path, "pixel_format": "Y16"}).open()
    assert str(info.value) == (
        f"v4l2 {fake.path}: config['pixel_format'] = 'Y16': the device does not offer Y16; it offers ['GREY', 'YUYV']"
    )
    assert fake.file.closed and "S_FMT" not in fake.log
