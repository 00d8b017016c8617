import json
import os
import re

import h5py
import numpy as np
import pytest

from rsocl.files.atomic import atomic_path
from rsocl.files.hdf5 import (
    Capture,
    Reconstruction,
    load_capture,
    load_capture_rig,
    load_reconstruction,
    save_capture,
    save_reconstruction,
)
from rsocl.model.rig import Camera, Rig

SHAPE = (9, 7)


@pytest.fixture
def rig():
    """Angle camera, row-map camera, multi-frame camera; awkward floats everywhere."""
    rng = np.random.default_rng(5)
    t_r = 35e-6 / 3
    row_map = rng.uniform(0, SHAPE[0] - 1, size=SHAPE) + 1 / 3
    cameras = [
        Camera(45.0, t_e=0.18e-3 / 7, t_r=t_r, t_a=1e-5 / 3, gain=1.1),
        Camera(t_e=0.1e-3, t_r=t_r, gain=0.9, row_map=row_map),
        Camera(90.0, t_e=2.2e-5, t_r=t_r, t_a=2e-6, frames=2, t_d=SHAPE[1] * t_r + 1e-7),
    ]
    return Rig(cameras, SHAPE, dt=t_r * 1.3, mask="binary")


@pytest.fixture
def snapshots(rig):
    return np.random.default_rng(6).uniform(size=(rig.n_channels,) + SHAPE).astype(np.float32)


@pytest.fixture
def truth(rig):
    return np.random.default_rng(8).uniform(size=(rig.T,) + SHAPE)


def _listing(directory):
    return sorted(p.name for p in directory.iterdir())


# ---------------------------------------------------------------------- capture
def test_capture_round_trip(tmp_path, rig, snapshots, truth):
    assert rig.n_channels == 4 and rig.cameras[2].frames == 2
    path = tmp_path / "cap.h5"
    meta = {"scene": "builtin", "sigma": np.float64(0.01), "n": np.int64(3), "list": [1, 2.5], "none": None}
    assert save_capture(path, snapshots, rig, truth=truth, attrs=meta) == path
    assert _listing(tmp_path) == ["cap.h5"]
    cap = load_capture(path)
    assert isinstance(cap, Capture)
    assert cap.rig == rig
    assert cap.rig is not rig
    # floats survive exactly (JSON repr round trip), so the timing is bit-identical
    assert cap.rig.dt == rig.dt and cap.rig.cameras[0].t_a == rig.cameras[0].t_a
    assert cap.rig.T == rig.T and cap.rig.mask == "binary"
    np.testing.assert_array_equal(cap.rig.start_times(), rig.start_times())
    np.testing.assert_array_equal(cap.rig.cameras[1].row_map, rig.cameras[1].row_map)
    assert cap.snapshots.dtype == np.float32
    np.testing.assert_array_equal(cap.snapshots, snapshots)
    np.testing.assert_array_equal(cap.truth, truth)
    assert cap.meta == {"scene": "builtin", "sigma": 0.01, "n": 3, "list": [1, 2.5], "none": None}
    with pytest.raises(AttributeError):  # dataclasses.FrozenInstanceError
        cap.meta = {}  # frozen dataclass


def test_capture_layout(tmp_path, rig, snapshots):
    path = save_capture(tmp_path / "cap.h5", snapshots, rig)
    with h5py.File(path, "r") as h5:
        assert h5.attrs["rsocl_file"] == "capture"
        assert h5.attrs["format_version"] == 1
        assert h5.attrs["T"] == rig.T and h5.attrs["T_se"] == rig.T_se
        assert h5.attrs["dt"] == rig.dt and h5.attrs["mask"] == "binary"
        assert h5.attrs["n_cameras"] == 3
        stored = json.loads(h5.attrs["rig"])
        assert [c["row_map"] for c in stored["cameras"]] == [None, {"dataset": "rig_row_maps/1"}, None]
        assert h5["rig_row_maps/1"].dtype == np.float64
        np.testing.assert_array_equal(h5["rig_row_maps/1"][()], rig.cameras[1].row_map)
        assert "truth" not in h5 and h5["snapshots"].shape == (4,) + SHAPE
    cap = load_capture(path)
    assert cap.truth is None and cap.meta == {}


def test_capture_validation(tmp_path, rig, snapshots, truth):
    path = tmp_path / "cap.h5"
    with pytest.raises(ValueError, match="snapshots"):
        save_capture(path, snapshots[:3], rig)
    with pytest.raises(ValueError, match="snapshots"):
        save_capture(path, snapshots[:, :, :-1], rig)
    with pytest.raises(ValueError, match="truth"):
        save_capture(path, snapshots, rig, truth=truth[:-1])
    with pytest.raises(ValueError, match="attrs"):
        save_capture(path, snapshots, rig, attrs={"x": object()})
    with pytest.raises(ValueError, match="attrs"):
        save_capture(path, snapshots, rig, attrs={1: "a"})
    with pytest.raises(ValueError, match="rig"):
        save_capture(path, snapshots, rig.to_dict())
    assert _listing(tmp_path) == []


def test_capture_rig_is_read_without_the_snapshots(tmp_path, rig, snapshots, truth):
    path = save_capture(tmp_path / "cap.h5", snapshots, rig, truth=truth)
    header = load_capture_rig(path)
    assert header == load_capture(path).rig == rig
    np.testing.assert_array_equal(header.cameras[1].row_map, rig.cameras[1].row_map)
    with h5py.File(path, "a") as h5:  # no snapshots at all: the rig is still read
        del h5["snapshots"]
    assert load_capture_rig(path) == rig
    with pytest.raises(ValueError, match="snapshots"):
        load_capture(path)
    with pytest.raises(ValueError, match="reconstruction"):
        load_capture_rig(save_reconstruction(tmp_path / "rec.h5", truth, rig))
    with pytest.raises(FileNotFoundError):
        load_capture_rig(tmp_path / "missing.h5")


def test_load_rejects_wrong_files(tmp_path, rig, snapshots, truth):
    cap = save_capture(tmp_path / "cap.h5", snapshots, rig)
    rec = save_reconstruction(tmp_path / "rec.h5", truth, rig)
    with pytest.raises(ValueError, match="reconstruction"):
        load_capture(rec)
    with pytest.raises(ValueError, match="capture"):
        load_reconstruction(cap)
    (tmp_path / "junk.h5").write_bytes(b"not hdf5 at all")
    with pytest.raises(ValueError, match="HDF5"):
        load_capture(tmp_path / "junk.h5")
    with h5py.File(tmp_path / "plain.h5", "w") as h5:
        h5["x"] = 1
    with pytest.raises(ValueError, match="not an rsocl file"):
        load_capture(tmp_path / "plain.h5")
    with h5py.File(cap, "a") as h5:
        h5.attrs["format_version"] = 2
    with pytest.raises(ValueError, match="format_version"):
        load_capture(cap)
    with pytest.raises(FileNotFoundError):
        load_capture(tmp_path / "missing.h5")


def test_a_batch_or_a_zarr_store_is_pointed_to_what_saves_or_reads_it(tmp_path, rig, truth):
    with pytest.raises(ValueError, match=r"got a batch of 2 sets .*: save each set on its own \(a batch Result's set"):
        save_reconstruction(tmp_path / "rec.h5", np.stack([truth, truth]), rig)
    (tmp_path / "rec.zarr").mkdir()
    with pytest.raises(ValueError, match=r"is a directory, not a reconstruction file \(a Zarr store .*load_store"):
        load_reconstruction(tmp_path / "rec.zarr")


def test_a_directory_or_a_damaged_file_gets_a_one_line_error_naming_it(tmp_path):
    from rsocl.files.rigfile import load_rigfile
    from rsocl.model.scenes import load_scene
    from rsocl.scale.inputs import CaptureSets

    folder = tmp_path / "cap.h5"
    folder.mkdir()
    for call, message in (
        (load_capture, "path: '.*cap.h5' is a directory, not a capture file"),
        (load_reconstruction, "path: '.*cap.h5' is a directory, not a reconstruction file"),
        (CaptureSets, "capture: '.*cap.h5' is a directory, not a capture file"),
        (load_rigfile, "'.*cap.h5' is a directory, not a rig file"),
        (lambda p: load_scene(p, (8, 8), 4), "path: '.*cap.h5' is a directory, not a video file"),
    ):
        with pytest.raises(ValueError, match=f"^{message}$"):
            call(folder)
    (tmp_path / "junk.h5").write_bytes(b"not hdf5 at all")
    for call in (load_capture, CaptureSets):
        with pytest.raises(ValueError, match=r"'.*junk.h5' is not a readable HDF5 file \(OSError: ") as info:
            call(tmp_path / "junk.h5")
        assert "\n" not in str(info.value)  # h5py's message has several lines: the first one is kept


# ---------------------------------------------------------------------- reconstruction
def test_reconstruction_round_trip(tmp_path, rig, truth):
    estimate = (truth + 0.01).astype(np.float32)
    history = {"residual": np.geomspace(1, 1e-3, 5), "psnr": np.arange(5.0), "a": np.array([1, 2], np.int32)}
    params = {"lam": 0.1, "eta": 0.2, "iterations": 5, "regularizer": "tv3d"}
    path = save_reconstruction(tmp_path / "rec.h5", estimate, rig, params=params, history=history, truth=truth)
    rec = load_reconstruction(path)
    assert isinstance(rec, Reconstruction)
    assert rec.rig == rig
    np.testing.assert_array_equal(rec.datacube, estimate)
    assert rec.datacube.dtype == np.float32
    np.testing.assert_array_equal(rec.truth, truth)
    assert rec.params == params
    assert list(rec.history) == ["residual", "psnr", "a"]  # saved order, not alphabetical
    for name, trace in history.items():
        np.testing.assert_array_equal(rec.history[name], trace)
        assert rec.history[name].dtype == trace.dtype
    with h5py.File(path, "r") as h5:
        assert h5.attrs["rsocl_file"] == "reconstruction" and h5.attrs["format_version"] == 1


def test_reconstruction_minimal_and_trimmed(tmp_path, rig, truth):
    kept = rig.kept_subframes()
    path = save_reconstruction(tmp_path / "rec.h5", truth[kept], rig)
    rec = load_reconstruction(path)
    assert rec.datacube.shape == (rig.T_se,) + SHAPE
    assert rec.params == {} and rec.history == {} and rec.truth is None


def test_reconstruction_validation(tmp_path, rig, truth):
    path = tmp_path / "rec.h5"
    with pytest.raises(ValueError, match="datacube"):
        save_reconstruction(path, truth[:, :-1], rig)
    with pytest.raises(ValueError, match="datacube"):
        save_reconstruction(path, np.zeros((rig.T + 1,) + SHAPE), rig)
    with pytest.raises(ValueError, match="truth"):
        save_reconstruction(path, truth, rig, truth=truth[1:])
    with pytest.raises(ValueError, match="history"):
        save_reconstruction(path, truth, rig, history={"r": np.zeros((2, 2))})
    with pytest.raises(ValueError, match="history"):
        save_reconstruction(path, truth, rig, history={"a/b": np.zeros(2)})
    with pytest.raises(ValueError, match="params"):
        save_reconstruction(path, truth, rig, params={"f": lambda: 0})
    assert _listing(tmp_path) == []


# ---------------------------------------------------------------------- atomicity
class _DiskFull(RuntimeError):
    pass


def _fail_on_dataset(monkeypatch):
    def boom(self, name, *args, **kwargs):
        raise _DiskFull(f"simulated failure writing {name}")

    monkeypatch.setattr(h5py.Group, "create_dataset", boom)


def _replace(path, edit):
    with h5py.File(path, "a") as h5:
        edit(h5)


def _dataset(name, value):
    def edit(h5):
        if name in h5:
            del h5[name]
        h5[name] = value

    return edit


@pytest.mark.parametrize(
    "edit, match",
    [
        (_dataset("datacube", np.full((4,) + SHAPE, np.nan)), "datacube contains 252 NaN or inf value"),
        (_dataset("datacube", np.zeros(SHAPE)), r"datacube must be 3-D \[T, m, n\]"),
        (_dataset("truth", np.zeros((3,) + SHAPE)), r"truth must have shape \(4, 9, 7\) \(the datacube's shape\)"),
        (lambda h5: h5.attrs.__setitem__("params", "[1, 2]"), "params must be a JSON object, got list"),
        (_dataset("history/residual", np.zeros((2, 2))), r"history\['residual'\] must be a 1-D real array"),
    ],
)
def test_a_damaged_reconstruction_is_refused_on_loading_naming_the_file(tmp_path, rig, truth, edit, match):
    path = save_reconstruction(tmp_path / "r.h5", truth[:4], rig, truth=truth[:4])
    _replace(path, edit)
    with pytest.raises(ValueError, match=f"^{re.escape(str(path))}: damaged: {match}"):
        load_reconstruction(path)


def test_a_reconstruction_longer_than_the_rig_is_refused_on_loading(tmp_path, rig, truth):
    path = save_reconstruction(tmp_path / "r.h5", truth, rig)
    _replace(path, _dataset("datacube", np.zeros((rig.T + 5,) + SHAPE)))
    with pytest.raises(ValueError, match=rf"damaged: datacube must have shape .* 1 <= T <= rig.T = {rig.T}"):
        load_reconstruction(path)


@pytest.mark.parametrize("bad", ["short", "nan"])
def test_a_captures_damaged_truth_is_refused_on_loading(tmp_path, rig, snapshots, truth, bad):
    path = save_capture(tmp_path / "c.h5", snapshots, rig, truth=truth)
    value = truth[:3] if bad == "short" else np.full_like(truth, np.nan)
    _replace(path, _dataset("truth", value))
    with pytest.raises(ValueError, match=f"^{re.escape(str(path))}: damaged: truth"):
        load_capture(path)


def test_failed_write_leaves_nothing(tmp_path, rig, snapshots, monkeypatch):
    _fail_on_dataset(monkeypatch)
    with pytest.raises(_DiskFull):
        save_capture(tmp_path / "cap.h5", snapshots, rig)
    assert _listing(tmp_path) == []


def test_failed_write_keeps_existing_file(tmp_path, rig, snapshots, truth, monkeypatch):
    path = save_capture(tmp_path / "cap.h5", snapshots, rig, attrs={"version": "good"})
    rec = save_reconstruction(tmp_path / "rec.h5", truth, rig, params={"version": "good"})
    _fail_on_dataset(monkeypatch)
    with pytest.raises(_DiskFull):
        save_capture(path, snapshots * 0, rig, attrs={"version": "bad"})
    with pytest.raises(_DiskFull):
        save_reconstruction(rec, truth * 0, rig, params={"version": "bad"})
    monkeypatch.undo()
    assert _listing(tmp_path) == ["cap.h5", "rec.h5"]
    cap = load_capture(path)
    assert cap.meta == {"version": "good"}
    np.testing.assert_array_equal(cap.snapshots, snapshots)
    assert load_reconstruction(rec).params == {"version": "good"}


def test_atomic_path_success_and_failure(tmp_path):
    target = tmp_path / "out.bin"
    with atomic_path(target) as tmp:
        assert tmp.parent == tmp_path
        assert tmp.name.startswith("out.bin.") and tmp.name.endswith(".tmp")
        assert not target.exists()
        tmp.write_bytes(b"first")
    assert target.read_bytes() == b"first"
    umask = os.umask(0o022)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask
    os.chmod(target, 0o640)
    with pytest.raises(KeyError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"second, half written")
            raise KeyError("boom")
    assert target.read_bytes() == b"first"
    assert _listing(tmp_path) == ["out.bin"]
    with atomic_path(str(target)) as tmp:
        tmp.write_bytes(b"third")
    assert target.read_bytes() == b"third"
    assert target.stat().st_mode & 0o777 == 0o640  # existing permissions kept
    with pytest.raises(FileNotFoundError):
        with atomic_path(tmp_path / "no" / "such" / "dir.bin"):
            pass


@pytest.mark.parametrize(
    "damage, match",
    [
        (lambda h5: h5.attrs.__delitem__("rig"), "attribute 'rig' is missing"),
        (lambda h5: h5.attrs.__setitem__("rig", "[1]"), "the stored rig description is damaged"),
        (lambda h5: h5.attrs.__setitem__("rig", 5), "the stored rig description is damaged"),
        (lambda h5: h5.attrs.__setitem__("rig", "{bad"), "the stored rig description is damaged"),
        (
            lambda h5: h5.attrs.__setitem__(
                "rig", re.sub(r'"t_e": [-+.e0-9]+', '"t_e": -1.0', h5.attrs["rig"], count=1)
            ),
            "the stored rig is not valid: .*t_e must be > 0",
        ),
        (lambda h5: h5.attrs.__setitem__("meta", "{bad"), "attribute 'meta' is not valid JSON"),
        (lambda h5: (h5.__delitem__("snapshots"), h5.create_group("snapshots")), "'snapshots' must be a dataset"),
        (
            lambda h5: (h5.__delitem__("snapshots"), h5.create_dataset("snapshots", data=np.full((2, 3), b"x"))),
            "'snapshots' must hold real numbers",
        ),
        (
            lambda h5: (h5.__delitem__("snapshots"), h5.create_dataset("snapshots", data=np.zeros((3, 4)))),
            r"'snapshots' has shape \(3, 4\), the rig needs",
        ),
    ],
)
def test_a_damaged_capture_is_a_value_error_naming_the_file(tmp_path, rig, snapshots, damage, match):
    from rsocl.cli.main import main
    from rsocl.scale.inputs import CaptureSets

    cap = save_capture(tmp_path / "cap.h5", snapshots, rig)
    with h5py.File(cap, "a") as h5:
        damage(h5)
    with pytest.raises(ValueError, match=match) as info:
        load_capture(cap)
    assert "cap.h5" in str(info.value)
    if "snapshots" not in match and "meta" not in match:  # the rig: the reader of tiled runs too
        with pytest.raises(ValueError, match=match):
            CaptureSets(cap)
    assert main(["reconstruct", str(cap), "--out", str(tmp_path / "r.h5"), "--iterations", "2", "--fast"]) == 2


def test_a_damaged_reconstruction_is_a_value_error_naming_the_file(tmp_path, rig, truth):
    rec = save_reconstruction(tmp_path / "rec.h5", truth, rig, params={"lam": 0.1}, history={"psnr": np.ones(3)})
    with h5py.File(rec, "a") as h5:
        h5.attrs["params"] = "{bad"
    with pytest.raises(ValueError, match="rec.h5: attribute 'params' is not valid JSON"):
        load_reconstruction(rec)
    rec = save_reconstruction(tmp_path / "rec2.h5", truth, rig, history={"psnr": np.ones(3)})
    with h5py.File(rec, "a") as h5:
        del h5["history"]
        h5["history"] = np.ones(3)
    with pytest.raises(ValueError, match="'history' must be a group of datasets"):
        load_reconstruction(rec)
