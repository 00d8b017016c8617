"""The v4l2 backend's 10- and 12-bit greyscale formats (``Y10``, ``Y12``) and the packed formats it refuses,
against the ioctl-level fake of tests/test_v4l2.py."""

from __future__ import annotations

import re
from contextlib import ExitStack

import numpy as np
import pytest

from rsocl.hardware.backend import CameraError
from rsocl_plugins.v4l2 import V4L2Camera
from rsocl_plugins.v4l2_formats import convert_frame

from test_v4l2 import PAD, FakeV4L2Device, capture_while_sending, sensor_image

READ = "['GREY', 'Y16', 'Y12', 'Y10', 'YUYV']"  # the formats the backend reads, as its messages list them


@pytest.fixture
def make_fake():
    pytest.importorskip("linuxpy.video.device", reason='linuxpy not installed (pip install "rsocl[v4l2]")')
    with ExitStack() as stack:
        yield lambda **kw: stack.enter_context(FakeV4L2Device(**kw))


def levels(fake, bits, seed=0):
    """A sensor image of ``bits``-bit levels (0..2**bits - 1), both ends included."""
    image = sensor_image(fake, high=2**bits, seed=seed)
    image[0, 0], image[-1, -1] = 0, 2**bits - 1
    return image


# ====================================================================== Y10, Y12
def test_convert_frame_reads_y10_and_y12_words_without_their_padding():
    # 2x2 pixels, 4 bytes of padding per line; each pixel one little-endian 16-bit word
    y10 = bytes([0xFF, 0x03, 0x00, 0x02, 0xEE, 0xEE, 0xEE, 0xEE, 0x01, 0x00, 0x34, 0x01, 0xEE, 0xEE, 0xEE, 0xEE])
    out = convert_frame(y10, "Y10", 2, 2, 8)
    assert out.dtype == np.uint16 and out.tolist() == [[1023, 512], [1, 0x134]]
    y12 = bytes([0xFF, 0x0F, 0xBC, 0x0A, 0xEE, 0xEE, 0x00, 0x00, 0x00, 0x08])  # the last line's padding omitted
    out = convert_frame(y12, "Y12", 2, 2, 6)
    assert out.dtype == np.uint16 and out.tolist() == [[4095, 0xABC], [0, 2048]]


@pytest.mark.parametrize("name, bits, pad", [("Y10", 10, 6), ("Y12", 12, 2)])
def test_a_device_offering_only_y10_or_y12_delivers_its_levels_and_bit_depth(make_fake, name, bits, pad):
    fake = make_fake(formats=(name,), pad=pad)
    images = [levels(fake, bits, seed) for seed in range(3)]
    with V4L2Camera({"device": fake.path, "buffers": 3}) as cam:
        assert cam.device_formats == (name,) and cam.pixel_format == name and fake.pixel_format == name
        assert cam._fmt["bpl"] == 12 * 2 + pad  # padded rows: bytesperline past the 12 pixels' 24 bytes
        cam.set_trigger("free")
        cam.start()
        for image in images:
            assert fake.emit(image)
        for image in images:
            frame = cam.read(timeout=1.0)
            assert frame.pixel_format == name and frame.bit_depth == bits
            assert frame.image.dtype == np.uint16 and frame.image.shape == (6, 12)
            np.testing.assert_array_equal(frame.image, image)  # no 0xEEEE padding word in it
            assert frame.image.max() == 2**bits - 1 and PAD * 257 not in frame.image


def test_the_fake_pads_y10_rows_with_words_the_image_must_not_hold(make_fake):
    fake = make_fake(formats=("Y10",), sensor=(2, 1), pad=4)
    with V4L2Camera({"device": fake.path}) as cam:
        assert cam.pixel_format == "Y10"
        cam.start()
        fake.emit(np.array([[1023, 5]]))
        buffer = bytes(fake.buffers[0]["mm"][:8])
        assert buffer == bytes([0xFF, 0x03, 0x05, 0x00, PAD, PAD, PAD, PAD])
        assert cam.read(1.0).image.tolist() == [[1023, 5]]


@pytest.mark.parametrize(
    "offered, chosen",
    [(("YUYV", "Y10", "Y12"), "Y12"), (("Y10", "YUYV"), "Y10"), (("Y12", "Y16"), "Y16"), (("Y10", "GREY"), "GREY")],
)
def test_the_default_format_is_grey_then_the_deepest_16_bit_word_then_yuyv(make_fake, offered, chosen):
    fake = make_fake(formats=offered)
    with V4L2Camera({"device": fake.path}) as cam:
        assert cam.pixel_format == chosen


@pytest.mark.parametrize("name", ["Y10", "Y12"])
def test_y10_and_y12_are_set_by_name(make_fake, name):
    fake = make_fake(formats=("GREY", "Y10", "Y12"))
    with V4L2Camera({"device": fake.path, "pixel_format": name}) as cam:
        assert cam.pixel_format == name and fake.pixel_format == name
        cam.set_pixel_format("GREY")
        cam.set_pixel_format(name)
        assert fake.pixel_format == name and cam._fmt["bpl"] == 12 * 2 + fake.pad


def _capture(fake, tmp_path, image, camera_keys="", config_keys=""):
    """capture_sets of 2 sets on a one-camera rig file of ``fake`` (6x12, t_e = 10 ms, t_r = dt = 1 ms, so a
    white scene is 10 model units), the fake sending ``image`` every 5 ms; returns the capture file."""
    rig = tmp_path / "rig.toml"
    rig.write_text(
        f'[rig]\nshape = [6, 12]\n\n[[camera]]\nbackend = "v4l2"\naddress = "{fake.path}"\nangle = 0.0\n'
        f"t_e = 0.01\nt_r = 0.001\n{camera_keys}\n[camera.config]\n{config_keys}\n"
    )
    return capture_while_sending(fake, image, rig, tmp_path / "capture.h5", 2)


@pytest.mark.parametrize(
    "name, bits, camera_keys, config_keys",
    [("Y10", 10, 'pixel_format = "Y10"', ""), ("Y12", 12, "", 'pixel_format = "Y12"')],
)
def test_a_rig_file_captures_y10_and_y12_in_model_units_by_their_bit_depth(
    make_fake, tmp_path, name, bits, camera_keys, config_keys
):
    from rsocl.files.hdf5 import load_capture
    from rsocl.hardware.capture_file import load_raw

    fake = make_fake(formats=("GREY", "Y16", "Y10", "Y12"), pad=6)  # the rig file's choice, not the default GREY
    image = levels(fake, bits)
    out = _capture(fake, tmp_path, image, camera_keys, config_keys)
    raw = load_raw(out)
    assert raw.status == "complete" and raw.sets_complete == 2 and fake.pixel_format == name
    assert raw.frames[0].dtype == np.uint16 and raw.frames[0].shape == (2, 6, 12)
    for frame, meta in zip(raw.frames[0], raw.frame_meta[0]):
        np.testing.assert_array_equal(frame, image)
        assert meta["pixel_format"] == name and meta["bit_depth"] == bits
    # model units: the top level 2**bits - 1 is full scale, t_e / dt = 10 sub-frames of a white scene
    expected = image / (2**bits - 1) * 10.0
    np.testing.assert_allclose(load_capture(out, set_index=0).snapshots[0], expected, rtol=1e-13, atol=0)
    np.testing.assert_allclose(raw.snapshot_sets[:, 0], [expected, expected], rtol=1e-13, atol=0)
    assert raw.snapshot_sets[0, 0].max() == pytest.approx(10.0, rel=1e-13)


# ====================================================================== packed formats, refused
@pytest.mark.parametrize(
    "offered, how",
    [
        (("Y10P",), r"Y10P is packed \(MIPI CSI-2 packed, 4 pixels in 5 bytes\)"),
        (("MJPEG", "Y10BPACK"), r"Y10BPACK is packed \(bit-packed big endian, 4 pixels in 5 bytes\)"),
        (("Y12P",), r"Y12P is packed \(MIPI CSI-2 packed, 2 pixels in 3 bytes\)"),
    ],
)
def test_a_device_offering_only_a_packed_format_is_refused_naming_what_is_read(make_fake, offered, how):
    fake = make_fake(formats=offered)
    with pytest.raises(CameraError) as info:
        V4L2Camera({"device": fake.path}).open()
    assert re.fullmatch(
        rf"v4l2 {fake.path}: the device offers {re.escape(str(list(offered)))}, none of which this backend reads "
        rf"\({re.escape(READ)}\); {how}, which this backend does not unpack \(it reads Y10 and Y12, one pixel per "
        r"16-bit word\)",
        str(info.value),
    ), str(info.value)
    assert fake.file.closed and "S_FMT" not in fake.log


def test_a_packed_pixel_format_in_the_config_is_refused_naming_what_is_read():
    with pytest.raises(ValueError) as info:
        V4L2Camera({"pixel_format": "Y10P"})
    assert str(info.value) == (
        f"v4l2 /dev/video0: config['pixel_format'] must be one of {READ}, got 'Y10P'; Y10P is packed (MIPI CSI-2 "
        "packed, 4 pixels in 5 bytes), which this backend does not unpack (it reads Y10 and Y12, one pixel per "
        "16-bit word)"
    )
