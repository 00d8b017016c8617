"""Outputs of demo, calibrate, simulate and capture lose nothing a user has (a capture is refused before any
work, an earlier result is kept as ``<stem>.earlier-<UTC time><suffix>``), and the loaders read only the sets
a capture completed."""

import hashlib
import shutil
import warnings

import h5py
import numpy as np
import pytest

from rsocl.cli.main import main
from rsocl.files.hdf5 import file_kind, load_capture, load_reconstruction, load_snapshot_sets, save_capture
from rsocl.files.rigfile import RigFile, save_rigfile
from rsocl.hardware.capture import CaptureFailed, capture_sets
from rsocl.hardware.capture_file import load_raw
from rsocl.model.rig import Rig
from rsocl.scale.inputs import CaptureSets

SHAPE = (16, 16)
DEMO = ["demo", "--shape", "16", "16", "--iterations", "3", "--fixed", "--quiet"]


def _md5(path):
    return hashlib.md5(path.read_bytes()).hexdigest()


def _rig(folder, configs=None):
    path = folder / "rig.toml"
    save_rigfile(path, RigFile.from_rig(Rig.paper_array(4, SHAPE, t_e=180e-6, t_r=35e-6), configs=configs))
    return path


def _error_lines(err):
    return [line for line in err.splitlines() if ": error:" in line]


def _no_work(*args, **kwargs):
    raise AssertionError("the command worked before refusing its output")


@pytest.fixture(scope="module")
def three_sets(tmp_path_factory):
    """A capture of 3 sets from simulated cameras, made once; tests copy it."""
    folder = tmp_path_factory.mktemp("three")
    return capture_sets(_rig(folder), folder / "three.h5", sets=3)


@pytest.fixture(scope="module")
def reconstruction(tmp_path_factory, three_sets):
    """A reconstruction file, made once; tests copy it."""
    folder = tmp_path_factory.mktemp("rec")
    out = folder / "rec.h5"
    assert (
        main(["reconstruct", str(three_sets), "--out", str(out), "--first-set-only", "--fast", "--iterations", "2"])
        == 0
    )
    return out


# ---------------------------------------------------------------------- 1. rsocl demo
@pytest.mark.parametrize(
    "name, kind", [("demo.h5", "camera"), ("demo.h5", "simulated"), ("subframes.png", "simulated")]
)
def test_demo_refuses_a_capture_at_one_of_its_names_before_any_work(
    three_sets, tmp_path, capsys, monkeypatch, name, kind
):
    target = tmp_path / name
    if kind == "camera":
        shutil.copy(three_sets, target)
    else:
        rig = Rig.paper_array(4, SHAPE, t_e=180e-6, t_r=35e-6)
        save_capture(target, np.zeros((rig.n_channels,) + SHAPE), rig)
    before = _md5(target)
    monkeypatch.setattr("rsocl.cli.demo.run_reconstruction", _no_work)
    monkeypatch.setattr("rsocl.cli.demo.rig_from", _no_work)
    assert main([*DEMO, "--out", str(tmp_path)]) == 2
    [line] = _error_lines(capsys.readouterr().err)
    assert line.startswith(f"rsocl demo: error: --out {str(target)!r} ") and "it is kept" in line
    assert ("12 frame(s) from cameras" if kind == "camera" else "is a capture file") in line
    assert _md5(target) == before and [p.name for p in tmp_path.iterdir()] == [name]


def test_a_second_demo_keeps_the_earlier_demo_file(tmp_path, capsys):
    out = tmp_path / "d"
    assert main([*DEMO, "--out", str(out)]) == 0
    first = (out / "demo.h5").read_bytes()
    assert main([*DEMO[:-1], "--out", str(out)]) == 0
    [kept] = out.glob("demo.earlier-*.h5")
    assert kept.read_bytes() == first and load_reconstruction(out / "demo.h5").datacube.shape[1:] == SHAPE
    assert capsys.readouterr().out.rstrip().endswith(f"(the earlier file there is kept as {kept})")


# ---------------------------------------------------------------------- 2. rsocl calibrate
@pytest.fixture
def calibration(tmp_path):
    camera = '[[camera]]\nbackend = "simulated"\nangle = 0.0\nt_e = 1.8e-04\nt_r = 3.5e-05\n'
    (tmp_path / "rig.toml").write_text("[rig]\nshape = [16, 16]\n" + camera * 2)  # two cameras the markers fit
    ref = np.array([[2.0, 2.0], [13.0, 2.0], [13.0, 13.0], [2.0, 13.0], [4.0, 9.0]])
    np.savez(tmp_path / "markers.npz", frames=np.zeros((2,) + SHAPE), markers=np.stack([ref, ref + 0.5]))
    return [
        "calibrate",
        "--rig",
        str(tmp_path / "rig.toml"),
        "--frames",
        str(tmp_path / "markers.npz"),
        "--markers-ref",
        *"2,2 13,2 13,13 2,13 4,9".split(),
        "--quiet",
    ]


def test_calibrate_png_must_be_a_png_and_never_an_hdf5_file(three_sets, reconstruction, tmp_path, calibration, capsys):
    shutil.copy(three_sets, tmp_path / "cap.h5")
    shutil.copy(three_sets, tmp_path / "cap.png")
    shutil.copy(reconstruction, tmp_path / "rec.png")
    before = {p.name: _md5(p) for p in tmp_path.iterdir()}
    for png, words in (
        ("cap.h5", "--png must name a .png file (the overlay is written as a PNG), got "),
        ("cap.png", "cap.png' holds 12 frame(s) from cameras"),
        ("rec.png", "rec.png' is a reconstruction file; it is never replaced"),
    ):
        assert main([*calibration, "--out", str(tmp_path / "new.toml"), "--png", str(tmp_path / png)]) == 2
        [line] = _error_lines(capsys.readouterr().err)
        assert "--png" in line and words in line, line
    assert {p.name: _md5(p) for p in tmp_path.iterdir()} == before  # no rig file, no picture
    assert main([*calibration, "--out", str(tmp_path / "new.toml"), "--png", str(tmp_path / "over.PNG")]) == 0
    assert (tmp_path / "over.PNG").read_bytes().startswith(b"\x89PNG") and (tmp_path / "new.toml").is_file()


@pytest.mark.parametrize("kind", ["camera capture", "capture", "reconstruction", "HDF5"])
def test_calibrate_out_never_replaces_an_hdf5_file(three_sets, reconstruction, tmp_path, calibration, capsys, kind):
    out = tmp_path / "out.h5"
    if kind == "camera capture":
        shutil.copy(three_sets, out)
    elif kind == "capture":
        rig = Rig.paper_array(4, SHAPE, t_e=180e-6, t_r=35e-6)
        save_capture(out, np.zeros((rig.n_channels,) + SHAPE), rig)
    elif kind == "reconstruction":
        shutil.copy(reconstruction, out)
    else:
        with h5py.File(out, "w") as h5:
            h5["x"] = np.arange(3)
    assert file_kind(out) == kind
    before = {p.name: _md5(p) for p in tmp_path.iterdir()}
    assert main([*calibration, "--out", str(out)]) == 2
    [line] = _error_lines(capsys.readouterr().err)
    assert line.startswith(f"rsocl calibrate: error: --out {str(out)!r} ") and "it is kept" in line
    assert {p.name: _md5(p) for p in tmp_path.iterdir()} == before


# ---------------------------------------------------------------------- 3. rsocl simulate, rsocl capture
@pytest.mark.parametrize("picture", ["x.gif", "x-tuning.png"])
@pytest.mark.parametrize("out", ["x.h5", "x.zarr"])
def test_reconstruct_never_draws_a_picture_over_a_capture(three_sets, tmp_path, capsys, monkeypatch, picture, out):
    import rsocl.cli.reconstruct as reconstruct

    shutil.copy(three_sets, tmp_path / picture)  # a capture from cameras under a picture's name
    before = _md5(tmp_path / picture)
    monkeypatch.setattr(reconstruct, "run_reconstruction", _no_work)
    argv = ["reconstruct", str(three_sets), "--out", str(tmp_path / out), "--first-set-only", "--quiet"]
    assert main(argv) == 2
    [line] = _error_lines(capsys.readouterr().err)
    assert f"'{tmp_path / picture}' holds 12 frame(s) from cameras (rsocl capture)" in line, line
    assert _md5(tmp_path / picture) == before and not (tmp_path / out).exists()


@pytest.mark.parametrize("command", ["capture", "simulate"])
def test_a_capture_must_have_an_hdf5_name(tmp_path, capsys, command):
    argv = ["capture", "--rig", str(_rig(tmp_path))] if command == "capture" else ["simulate", "builtin"]
    assert main([*argv, "--out", str(tmp_path / "x.gif"), "--quiet"]) == 2
    assert _error_lines(capsys.readouterr().err) == [
        f"rsocl {command}: error: --out must name an HDF5 file (.h5, .hdf5, .hdf, .he5), got '{tmp_path / 'x.gif'}'"
    ]
    assert not (tmp_path / "x.gif").exists()


def test_simulate_keeps_an_earlier_reconstruction_or_other_file(reconstruction, tmp_path, capsys):
    rec = tmp_path / "rec.h5"
    shutil.copy(reconstruction, rec)
    notes = tmp_path / "notes.h5"
    notes.write_text("my notes")
    for path, earlier in ((rec, reconstruction.read_bytes()), (notes, b"my notes")):
        assert main(["simulate", "builtin", "--out", str(path), "--shape", "12", "12"]) == 0
        [kept] = tmp_path.glob(f"{path.stem}.earlier-*.h5")
        assert kept.read_bytes() == earlier and file_kind(path) == "capture"
        assert capsys.readouterr().out.rstrip().endswith(f"(the earlier file there is kept as {kept})")
    assert main(["simulate", "builtin", "--out", str(rec), "--shape", "12", "12", "--quiet"]) == 0
    assert len(list(tmp_path.glob("rec.earlier-*.h5"))) == 1  # a simulated capture is replaced


def test_capture_keeps_an_earlier_reconstruction_and_says_so(reconstruction, tmp_path):
    out = tmp_path / "rec.h5"
    shutil.copy(reconstruction, out)
    with pytest.warns(UserWarning, match=r"rec\.h5: the earlier file there is kept as .*rec\.earlier-.*\.h5$"):
        assert capture_sets(_rig(tmp_path), out, sets=1) == out
    [kept] = tmp_path.glob("rec.earlier-*.h5")
    assert kept.read_bytes() == reconstruction.read_bytes() and file_kind(out) == "camera capture"
    failed = tmp_path / "failed.h5"
    shutil.copy(reconstruction, failed)
    with pytest.raises(
        CaptureFailed, match=r"are in .*failed\.h5; the earlier file there is kept as .*failed\.earlier-"
    ):
        capture_sets(_rig(tmp_path, configs=[{}, {"fail_after": 1}, {}, {}]), failed, sets=2)
    assert next(tmp_path.glob("failed.earlier-*.h5")).read_bytes() == reconstruction.read_bytes()


# ---------------------------------------------------------------------- 4, 5. the loaders read complete sets only
def test_only_the_complete_sets_are_read(three_sets, tmp_path, capsys):
    path = tmp_path / "c.h5"
    shutil.copy(three_sets, path)
    with h5py.File(path, "a") as h5:
        h5.attrs["sets_complete"] = 2  # the third row: a set the capture never completed
        h5.attrs["capture_status"] = "running"
    with pytest.warns(UserWarning, match=r"c\.h5: 2 of the 3 sets in 'snapshot_sets' are complete .*'running'"):
        sets = load_snapshot_sets(path)
    np.testing.assert_array_equal(sets, load_snapshot_sets(three_sets)[:2])
    assert load_raw(path).snapshot_sets.shape[0] == 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match=r"set_index must be in \[0, 1\]"):
            load_capture(path, set_index=2)
    out = tmp_path / "r.h5"
    assert main(["reconstruct", str(path), "--out", str(out), "--fast", "--iterations", "2", "--quiet"]) == 0
    assert sorted(p.name for p in tmp_path.glob("r-set*.h5")) == ["r-set000.h5", "r-set001.h5"]
    with pytest.warns(UserWarning, match="2 of the 3 sets"):  # the tiled path reads the complete sets too
        assert CaptureSets(path, all_sets=True).n_sets == 2


def test_a_capture_whose_first_set_never_completed_is_refused(tmp_path, capsys, monkeypatch):
    from rsocl.hardware import capture_file

    class FullDisk:  # set 0's truth cannot be written: after its snapshots, before the count says it is complete
        def __array__(self, *args, **kwargs):
            raise OSError(28, "No space left on device")

    monkeypatch.setattr(capture_file, "room_for", lambda truth, folder, sets_bytes, warn, file_size=0: FullDisk())
    out = tmp_path / "c.h5"
    with pytest.raises(CaptureFailed, match="write failed in set 0"):
        capture_sets(_rig(tmp_path), out, sets=3)
    with h5py.File(out, "r") as h5:
        assert h5.attrs["sets_complete"] == 0 and h5["snapshot_sets"].shape[0] == 1
        assert "snapshots" not in h5 and "truth" not in h5  # set 0's datasets only under temporary names
    for load in (load_capture, load_snapshot_sets):
        with pytest.raises(ValueError, match=r"c\.h5: no set of this capture is complete \(capture_status 'failed': "):
            load(out)
    assert main(["reconstruct", str(out), "--out", str(tmp_path / "r.h5"), "--fast", "--iterations", "2"]) == 2
    [line] = _error_lines(capsys.readouterr().err)
    assert "no set of this capture is complete" in line and "No space left on device" in line
    assert not (tmp_path / "r.h5").exists()


def test_a_complete_capture_holds_no_temporary_dataset(three_sets):
    with h5py.File(three_sets, "r") as h5:
        assert "snapshots" in h5 and "truth" in h5 and not [name for name in h5 if name.endswith(".writing")]


def test_an_unreadable_meta_attribute_is_warned_about_and_left_out(three_sets, tmp_path, monkeypatch):
    import rsocl.files.hdf5 as hdf5_module

    real = hdf5_module.json_attr

    def damaged(h5, name, source):
        if name == "meta":
            raise OSError("Unable to synchronously read attribute (address of object past end of allocation)")
        return real(h5, name, source)

    monkeypatch.setattr(hdf5_module, "json_attr", damaged)
    partial = tmp_path / "c.h5.partial"
    shutil.copy(three_sets, partial)
    with pytest.warns(UserWarning, match=r"c\.h5\.partial: attribute 'meta' cannot be read \(.*past end") as record:
        capture = load_capture(partial, set_index=1)
    assert len(record) == 1 and capture.meta == {}
    np.testing.assert_array_equal(capture.snapshots, load_snapshot_sets(three_sets)[1])
