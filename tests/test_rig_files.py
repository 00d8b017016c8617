"""Rig files as users write them: the examples in examples/rigs, keys in the wrong table, binary
files, row-map files outside the rig file's folder, and docs/rig-files.md covering every key."""

import os
from pathlib import Path

import numpy as np
import pytest

from rsocl.cli.main import main
from rsocl.files.rigfile import load_rigfile
from rsocl.files.rigfile_schema import CAMERA_KEYS, MISPLACED_CONFIG_KEYS, RIG_KEYS

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples" / "rigs").glob("*.toml"))

BASE = """[rig]
shape = [8, 8]

[[camera]]
backend = "simulated"
angle = 0.0
t_e = 1.8e-04
t_r = 3.5e-05

[[camera]]
backend = "simulated"
angle = 90.0
t_e = 1.8e-04
t_r = 3.5e-05
"""


def test_there_is_an_example_rig_file_for_every_backend():
    backends = {cam["backend"] for path in EXAMPLES for cam in load_rigfile(path).cameras}
    assert {"simulated", "aravis", "v4l2"} <= backends, [p.name for p in EXAMPLES]


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_every_example_loads_and_the_simulated_ones_capture(path, tmp_path, capsys):
    from rsocl.files.hdf5 import load_capture

    rigfile = load_rigfile(path)
    rig = rigfile.rig()
    assert rig.T >= 1 and rig.C == len(rigfile.cameras)
    if {cam["backend"] for cam in rigfile.cameras} != {"simulated"}:
        return  # hardware: loading and checking is what CI can do
    out = tmp_path / "cap.h5"
    assert main(["capture", "--rig", str(path), "--out", str(out), "--quiet"]) == 0, capsys.readouterr().err
    capture = load_capture(out)
    assert capture.rig == rig  # angles, homographies and times as the file says
    assert capture.snapshots.shape == (rig.n_channels,) + rig.shape
    assert np.all(np.isfinite(capture.snapshots)) and capture.snapshots.max() > 0


@pytest.mark.parametrize(
    "key, value, table",
    [
        ("angle", "90.0", "[[camera]]"),
        ("t_e", "1e-4", "[[camera]]"),
        ("t_r", "3.5e-5", "[[camera]]"),
        ("t_a", "0.0", "[[camera]]"),
        ("gain", "2.0", "[[camera]]"),
        ("roi", "[0, 0, 8, 8]", "[[camera]]"),
        ("row_map_file", '"rows.npy"', "[[camera]]"),
        ("dt", "3.5e-5", "[rig]"),
        ("shape", "[8, 8]", "[rig]"),
        ("mask", '"binary"', "[rig]"),
    ],
)
def test_a_model_key_in_camera_config_is_refused_saying_where_it_belongs(tmp_path, key, value, table):
    path = tmp_path / "rig.toml"
    path.write_text(BASE + f"\n[camera.config]\n{key} = {value}\n")
    with pytest.raises(ValueError) as info:
        load_rigfile(path)
    message = str(info.value)
    assert message.startswith(f"{path}: camera[1].config.{key} belongs in the {table} table"), message
    assert "\n" not in message


def test_angle_in_camera_config_is_never_silently_dropped(tmp_path, capsys):
    """The simulated camera rendered a config angle while the capture recorded the camera's own."""
    path = tmp_path / "rig.toml"
    path.write_text(BASE.replace("angle = 90.0\n", "") + "\n[camera.config]\nangle = 90.0\n")
    assert main(["capture", "--rig", str(path), "--out", str(tmp_path / "c.h5")]) == 2
    err = capsys.readouterr().err
    assert "camera[1].config.angle belongs in the [[camera]] table (camera[1].angle = ...)" in err
    assert not (tmp_path / "c.h5").exists()


@pytest.mark.parametrize(
    "old, new, message",
    [
        (
            "t_r = 3.5e-05\n",
            "t_r = 3.5e-05\ndt = 3.5e-05\n",
            r"camera\[0\]\.dt belongs in the \[rig\] table \(rig\.dt = \.\.\.\), not in \[\[camera\]\]",
        ),
        (
            "shape = [8, 8]\n",
            "shape = [8, 8]\nt_e = 1e-4\n",
            r"rig\.t_e belongs in each \[\[camera\]\] table \(camera\[i\]\.t_e = \.\.\.\), not in \[rig\]",
        ),
        (
            "t_r = 3.5e-05\n",
            't_r = 3.5e-05\nscene = "builtin"\n',
            r"camera\[0\] has unknown key\(s\) \['scene'\].*the backend's own settings go in its \[camera\.config\]",
        ),
        ("t_r = 3.5e-05\n", "t_r = 3.5e-05\nt_ee = 1e-4\n", r"\('t_ee': did you mean 't_e'\?\)"),
        ("shape = [8, 8]\n", 'shape = [8, 8]\nmsak = "binary"\n', r"\[rig\].*\('msak': did you mean 'mask'\?\)"),
        ("[[camera]]", "[[cameras]]", r"top-level key\(s\) \['cameras'\] \('cameras': did you mean 'camera'\?\)"),
    ],
)
def test_a_key_in_the_wrong_table_says_where_it_belongs(tmp_path, old, new, message):
    path = tmp_path / "rig.toml"
    path.write_text(BASE.replace(old, new, 1))
    with pytest.raises(ValueError, match=message):
        load_rigfile(path)


def test_keys_the_rig_fills_in_are_refused_in_a_simulated_config(tmp_path):
    path = tmp_path / "rig.toml"
    path.write_text(BASE + "\n[camera.config]\nscene_frames = 5\n")
    with pytest.raises(ValueError, match=r"camera\[1\]\.config\.scene_frames is set from the rig"):
        load_rigfile(path)
    assert set(MISPLACED_CONFIG_KEYS) >= set(RIG_KEYS) | {"angle", "t_e", "t_r"}


def test_a_binary_file_is_not_a_rig_file(tmp_path, capsys):
    path = tmp_path / "capture.h5"
    path.write_bytes(b"\x89HDF\r\n\x1a\n\x00\x00\xff\xfe" + bytes(range(256)))
    with pytest.raises(ValueError) as info:
        load_rigfile(path)
    assert str(info.value) == f"{path}: not a TOML rig file (byte 0x89 at offset 0 is not UTF-8 text)"
    assert main(["capture", "--rig", str(path), "--out", str(tmp_path / "c.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"rsocl capture: error: {path}: not a TOML rig file (byte 0x89 at offset 0 is not UTF-8 text)"]


def test_row_map_file_stays_in_the_rig_files_folder(tmp_path):
    rig_dir = tmp_path / "rigs"
    (rig_dir / "maps").mkdir(parents=True)
    rows = np.add.outer(np.arange(8.0), np.zeros(8))
    np.save(rig_dir / "maps" / "rows.npy", rows)
    np.save(tmp_path / "outside.npy", rows)
    path = rig_dir / "rig.toml"
    path.write_text(BASE.replace("angle = 90.0", 'row_map_file = "maps/rows.npy"'))
    np.testing.assert_array_equal(load_rigfile(path).rig().row_map(1), rows)  # below the folder: read
    for name in ("../outside.npy", "maps/../../outside.npy", str(tmp_path / "outside.npy")):
        path.write_text(BASE.replace("angle = 90.0", f'row_map_file = "{name}"'))
        with pytest.raises(
            ValueError,
            match=r"camera\[1\]\.row_map_file must (name a file in the rig file's "
            r"folder or below it|be a path relative to the rig file's folder)",
        ):
            load_rigfile(path)
    if hasattr(os, "symlink"):
        os.symlink(tmp_path / "outside.npy", rig_dir / "link.npy")  # a link that leaves it
        path.write_text(BASE.replace("angle = 90.0", 'row_map_file = "link.npy"'))
        with pytest.raises(ValueError, match=r"camera\[1\]\.row_map_file must name a file in the rig file's folder"):
            load_rigfile(path)


def test_docs_name_every_key_and_its_table():
    text = (ROOT / "docs" / "rig-files.md").read_text(encoding="utf-8")
    for key in RIG_KEYS + tuple(k for k in CAMERA_KEYS if k != "config"):
        assert f"`{key}`" in text, key
    for example in EXAMPLES:
        assert f"examples/rigs/{example.name}" in text, example.name
    assert "x, y, width, height" in text


def test_the_full_examples_of_the_docs_load(tmp_path):
    import re

    text = (ROOT / "docs" / "rig-files.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```toml\n(.*?)```", text, flags=re.S)
    backends = set()
    for k, block in enumerate(blocks):
        path = tmp_path / f"doc{k}.toml"
        path.write_text(block, encoding="utf-8")
        rigfile = load_rigfile(path)
        backends |= {cam["backend"] for cam in rigfile.cameras}
        assert rigfile.rig().T >= 1
    assert backends == {"simulated", "aravis", "v4l2"}


def test_a_rig_file_made_from_a_rig_gives_the_rig_back(tmp_path):
    # t_d of a one-frame camera included: it leaves the model as it is, and the rig compares equal
    from rsocl import Camera, Rig
    from rsocl.files.rigfile import RigFile

    rig = Rig([Camera(0, 1.8e-4, 3.5e-5, t_d=6e-4), Camera(90, 1.8e-4, 3.5e-5, t_a=1e-5)], (8, 8))
    assert RigFile.from_rig(rig).rig() == rig
