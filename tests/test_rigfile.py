"""The TOML rig file: round trips, homography row maps, the TOML writer and error messages."""

import math
import sys

import numpy as np
import pytest

from rsocl.files.rigfile import RigFile, load_rigfile, save_rigfile
from rsocl.files.toml_writer import dumps_toml
from rsocl.model.rig import Camera, Rig
from rsocl.model.row_map import row_map_from_homography

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

SHAPE = (9, 7)
T_E, T_R = 180e-6, 35e-6 / 3


def _rotation(angle, shape=SHAPE, offset=(3.0, 5.0)):
    """Rotation by ``angle`` degrees of (x, y) image coordinates, then a shift: reference -> sensor."""
    a = math.radians(angle)
    return np.array([[math.cos(a), -math.sin(a), offset[0]], [math.sin(a), math.cos(a), offset[1]], [0, 0, 1.0]])


@pytest.fixture
def rigfile(tmp_path):
    row_map = np.random.default_rng(2).uniform(0, 8, SHAPE) + 1 / 3
    cameras = [
        {
            "backend": "simulated",
            "name": 'left "A" ✓',
            "angle": 45.0,
            "t_e": T_E / 7,
            "t_r": T_R,
            "t_a": 1e-5 / 3,
            "gain": 1.1,
            "roi": [1, 2, 7, 9],
            "pixel_format": "Mono16",
            "config": {"scene": "builtin", "sensor": {"bit_depth": 12, "read_noise": 0.01}, "fail_after": None},
        },
        {
            "backend": "aravis",
            "address": "10.0.0.2",
            "homography": _rotation(90.0).tolist(),
            "t_e": T_E,
            "t_r": T_R,
            "config": {"packet_size": 9000, "weird key": [1, 2.5, "x"]},
        },
        {"backend": "simulated", "row_map": row_map, "t_e": 1e-4, "t_r": T_R * 2},
        {"backend": "v4l2", "angle": 270, "t_e": 2.2e-5, "t_r": T_R, "frames": 2, "t_d": SHAPE[1] * T_R + 1e-7},
    ]
    return RigFile(shape=SHAPE, cameras=cameras, dt=T_R * 1.3, mask="binary")


def test_a_row_map_an_earlier_rig_file_names_is_not_replaced_by_another(tmp_path):
    # rsocl calibrate keeps the earlier rig file (its TOML) beside the new one: its copied row map must stay
    maps = [np.arange(SHAPE[0] * SHAPE[1], dtype=float).reshape(SHAPE) * f for f in (0.5, 0.25)]
    files = []
    for i, row_map in enumerate(maps):
        cameras = [{"backend": "simulated", "row_map": row_map, "t_e": T_E, "t_r": T_R}]
        save_rigfile(tmp_path / "rig.toml", RigFile(shape=SHAPE, cameras=cameras))
        files.append((tmp_path / "rig.toml").read_text())
        (tmp_path / f"earlier{i}.toml").write_text(files[-1])  # the earlier file, as keeping() keeps it
    for i, row_map in enumerate(maps):
        np.testing.assert_array_equal(load_rigfile(tmp_path / f"earlier{i}.toml").rig().row_map(0), row_map)
    save_rigfile(tmp_path / "rig.toml", RigFile(shape=SHAPE, cameras=[dict(cameras[0], row_map=maps[0])]))
    assert "rig.camera0.rows.npy" in (tmp_path / "rig.toml").read_text()  # the same map: the same file


def test_round_trip(tmp_path, rigfile):
    path = tmp_path / "rig.toml"
    assert save_rigfile(path, rigfile) == path
    text = path.read_text()
    assert text.startswith("# rsocl rig file. Units: seconds")
    assert "[[camera]]" in text and "[camera.config.sensor]" in text and "fail_after" not in text
    assert (tmp_path / "rig.camera2.rows.npy").exists()
    loaded = load_rigfile(path)
    assert loaded.rig() == rigfile.rig()
    assert loaded.shape == SHAPE and loaded.dt == rigfile.dt and loaded.mask == "binary"
    assert loaded.cameras[0]["name"] == 'left "A" ✓'
    assert loaded.cameras[0]["roi"] == [1, 2, 7, 9] and loaded.cameras[0]["pixel_format"] == "Mono16"
    assert loaded.cameras[0]["config"] == {"scene": "builtin", "sensor": {"bit_depth": 12, "read_noise": 0.01}}
    assert loaded.cameras[1]["config"] == {"packet_size": 9000, "weird key": [1, 2.5, "x"], "address": "10.0.0.2"}
    np.testing.assert_array_equal(loaded.homography(1), _rotation(90.0))
    assert loaded.cameras[2]["row_map_file"] == "rig.camera2.rows.npy"
    assert loaded.rig().cameras[3].frames == 2
    # saving elsewhere: a row map outside the new folder is copied beside the new file
    other = tmp_path / "sub" / "again.toml"
    other.parent.mkdir()
    save_rigfile(other, loaded)
    again = load_rigfile(other)
    assert again.cameras[2]["row_map_file"] == "again.camera2.rows.npy"
    assert again.rig() == rigfile.rig()
    # a RigFile made from a Rig
    rig = Rig([Camera(a, t_e=T_E, t_r=T_R, t_a=2e-6) for a in (0, 90, 180)], SHAPE)
    save_rigfile(tmp_path / "from_rig.toml", RigFile.from_rig(rig))
    assert load_rigfile(tmp_path / "from_rig.toml").rig() == rig


@pytest.mark.parametrize("angle", [0.0, 90.0, 180.0, 270.0, 45.0, 135.0, 30.0])
def test_homography_row_map_is_the_angles_from_the_first_sensor_row_read(angle):
    expected = Camera(angle, t_e=T_E, t_r=T_R).rows(SHAPE)
    y, x = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    a = math.radians(angle)
    sensor_rows = math.sin(a) * x + math.cos(a) * y + 100.0  # rows of _rotation(angle, offset=(3, 100))
    first = float(sensor_rows.min())
    got = row_map_from_homography(_rotation(angle, offset=(3.0, 100.0)), SHAPE)
    np.testing.assert_allclose(got, sensor_rows, atol=1e-12)  # docs/model.md: the sensor row
    from_first = row_map_from_homography(_rotation(angle, offset=(3.0, 100.0)), SHAPE, first_row=first)
    assert_same = np.testing.assert_array_equal if angle % 90 == 0 else np.testing.assert_allclose
    assert_same(from_first, expected)
    np.testing.assert_array_equal(row_map_from_homography(-2.0 * _rotation(angle, offset=(3.0, 100.0)), SHAPE), got)


def test_pixels_a_homography_maps_above_the_first_row_read_get_its_time():
    """Not read by the camera (capture registers them as 0), they take row 0; the rest keep theirs."""
    got = row_map_from_homography(_rotation(0.0, offset=(0.0, 40.0)), SHAPE, first_row=43)
    y = np.arange(SHAPE[0], dtype=float)[:, None] + np.zeros(SHAPE)
    np.testing.assert_array_equal(got, np.maximum(y - 3, 0))


def test_identity_and_rotation_homography_in_a_rig_file(tmp_path):
    text = f"""
[rig]
shape = [{SHAPE[0]}, {SHAPE[1]}]

[[camera]]
backend = "simulated"
homography = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
t_e = {T_E!r}
t_r = {T_R!r}

[[camera]]
backend = "simulated"
homography = [[0, -1, 8], [1, 0, 0], [0, 0, 1]]
t_e = {T_E!r}
t_r = {T_R!r}
"""
    (tmp_path / "rig.toml").write_text(text)
    rig = load_rigfile(tmp_path / "rig.toml").rig()
    np.testing.assert_array_equal(rig.row_map(0), Camera(0.0, t_e=T_E, t_r=T_R).rows(SHAPE))
    np.testing.assert_array_equal(rig.row_map(1), Camera(90.0, t_e=T_E, t_r=T_R).rows(SHAPE))
    # a perspective homography: still rows >= 0 from 0; one that sends pixels behind the camera is refused
    H = np.array([[1, 0, 0], [0.02, 1, 0], [0.01, 0.0, 1]])
    r = row_map_from_homography(H, SHAPE)
    assert r.min() == 0 and np.all(np.isfinite(r))
    with pytest.raises(ValueError, match="behind the camera"):
        row_map_from_homography([[1, 0, 0], [0, 1, 0], [-1, 0, 1]], SHAPE)


def test_backends_pass_the_model_to_simulated_cameras(rigfile):
    backends = rigfile.backends()
    assert [b for b, _ in backends] == ["simulated", "aravis", "simulated", "v4l2"]
    rig = rigfile.rig()
    sim = backends[0][1]
    assert sim["angle"] == 45.0 and sim["t_e"] == T_E / 7 and sim["t_a"] == 1e-5 / 3 and sim["gain"] == 1.1
    assert sim["shape"] == list(SHAPE) and sim["dt"] == rig.dt and sim["mask"] == "binary"
    assert sim["scene_frames"] == rig.T and sim["index"] == 0 and sim["sensor"]["bit_depth"] == 12
    np.testing.assert_array_equal(backends[2][1]["row_map"], rig.row_map(2))
    assert "angle" not in backends[2][1]
    assert backends[1][1] == {"packet_size": 9000, "weird key": [1, 2.5, "x"], "address": "10.0.0.2"}


def test_toml_writer_round_trips():
    data = {
        "top": 1,
        "f": 1e-5,
        "big": 5e16,
        "neg": -0.0,
        "inf": math.inf,
        "b": True,
        "s": 'q"uote\\back\nline\t✓\x01',
        "odd key": "x",
        "list": [1, [2, 3], ["a", "b"]],
        "inline": [{"a": 1}, 2],
        "table": {"x": 1.5, "empty": {}, "sub": {"y": [1.0, 2.0]}, "skip": None},
        "arr": [{"k": 1, "t": {"z": "deep"}}, {"k": 2}],
        "np": np.float32(0.5),
        "npa": np.arange(3),
        "tuple": (1, 2),
    }
    back = tomllib.loads(dumps_toml(data))
    expected = dict(data, np=0.5, npa=[0, 1, 2], tuple=[1, 2])
    expected["table"] = {"x": 1.5, "empty": {}, "sub": {"y": [1.0, 2.0]}}
    assert back == expected
    assert math.isnan(tomllib.loads(dumps_toml({"n": math.nan}))["n"])
    with pytest.raises(ValueError, match="no null"):
        dumps_toml({"a": [1, None]})
    with pytest.raises(ValueError, match="cannot write"):
        dumps_toml({"a": object()})


BASE = f"""
[rig]
shape = [9, 7]

[[camera]]
backend = "simulated"
angle = 0
t_e = {T_E!r}
t_r = {T_R!r}

[[camera]]
backend = "simulated"
angle = 90
t_e = {T_E!r}
t_r = {T_R!r}
"""


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("angle = 90\nt_e = 0.00018", "angle = 90\nt_e = -1.0", r"camera\[1\]\.t_e must be > 0 seconds"),
        ("angle = 90\nt_e = 0.00018", "angle = 90", r"camera\[1\]\.t_e is required"),
        ('backend = "simulated"\nangle = 0', "angle = 0", r"camera\[0\]\.backend .* is required"),
        ("angle = 90", "angle = 90\nexposure = 1", r"camera\[1\] has unknown key\(s\) \['exposure'\]"),
        ("angle = 90", "angle = 90\nhomography = [[1,0,0],[0,1,0],[0,0,1]]", r"camera\[1\]: give only one of"),
        ("angle = 90", "homography = [[1,0],[0,1]]", r"camera\[1\]\.homography: homography must be a 3x3"),
        ("angle = 90", 'row_map_file = "missing.npy"', r"camera\[1\]\.row_map_file: file .*missing\.npy.* does not"),
        ("angle = 90", "angle = 90\nroi = [0, 0, 0, 5]", r"camera\[1\]\.roi .*\[2\] must be an integer >= 1"),
        ("angle = 90", 'angle = "ninety"', r"camera\[1\]\.angle must be a finite real number"),
        ("angle = 90", "angle = 90\nt_a = -1e-6", r"camera\[1\]\.t_a must be >= 0 seconds"),
        ("angle = 90", "angle = 90\nframes = 2", r"camera\[1\]: t_d .* is required when frames > 1"),
        ("angle = 90\nt_e = 0.00018", "angle = 90\nt_e = 1e-5\nframes = 2\nt_d = 1e-9", r"camera\[1\]\.t_d must be >="),
        ("angle = 90", "angle = 90\nt_a = 500.0", r"camera\[1\]\.t_a = 500 s makes the rig span"),
        ("shape = [9, 7]", "shape = [9]", r"rig\.shape must be a list of 2 integers"),
        ("shape = [9, 7]", "shape = [9, 7]\ndt = 1e-6", r"dt must be >= t_r"),
        ("shape = [9, 7]", "shape = [9, 7]\nmask = 'fuzzy'", r"rig\.mask must be one of"),
        ("[rig]", "[rigg]", r"unknown top-level key"),
        ("[rig]", "[rig", r"not valid TOML"),
    ],
)
def test_bad_content_names_camera_and_key(tmp_path, old, new, message):
    text = BASE.replace(old, new, 1)
    assert text != BASE
    path = tmp_path / "rig.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as info:
        load_rigfile(path)
    assert str(path) in str(info.value)


def test_row_map_file_is_checked(tmp_path):
    np.save(tmp_path / "rows.npy", np.zeros((3, 3)))
    path = tmp_path / "rig.toml"
    path.write_text(BASE.replace("angle = 90", 'row_map_file = "rows.npy"'))
    with pytest.raises(ValueError, match=r"camera\[1\]\.row_map_file has shape \(3, 3\)"):
        load_rigfile(path)
    (tmp_path / "rows.npy").write_bytes(b"")  # an empty file
    with pytest.raises(ValueError, match=r"camera\[1\]\.row_map_file: .*rows.npy' is not a readable .npy array"):
        load_rigfile(path)
    np.save(tmp_path / "rows.npy", np.arange(63.0).reshape(9, 7))
    assert load_rigfile(path).rig().row_map(1)[8, 6] == 62.0
    with pytest.raises(FileNotFoundError):
        load_rigfile(tmp_path / "nope.toml")
    path.write_text("[rig]\nshape = [9, 7]\n")
    with pytest.raises(ValueError, match="no camera"):
        load_rigfile(path)
