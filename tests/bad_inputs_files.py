"""Bad files, captures and outputs (table of tests/test_bad_inputs.py): --out collisions (per-set names
included), unreadable, corrupt, missing or wrong-kind files, partial captures, multi-set selection."""

import os

import numpy as np

import rsocl
from rsocl.files.hdf5 import load_capture, save_capture, save_reconstruction

from test_bad_inputs import Bad

FAST = ["--fast", "--iterations", "2", "--quiet"]


def _rig():
    return rsocl.Rig.paper_array(2, (8, 8), 0.18e-3, 35e-6)


def _capture(name, sets=1, nan_set=None):
    """``setup``: a capture ``name`` of ``sets`` sets (dataset ``snapshot_sets`` when more than one)."""

    def make(tmp):
        import h5py

        rig = _rig()
        stack = np.random.default_rng(0).random((sets, rig.n_channels) + rig.shape)
        path = save_capture(tmp / name, stack[0], rig)
        if sets > 1:
            if nan_set is not None:
                stack[nan_set, 0, 0, 0] = np.nan
            with h5py.File(path, "r+") as h5:
                h5.create_dataset("snapshot_sets", data=stack)
        return path

    return make


def _nan_snapshot(name):
    """``setup``: a capture ``name`` of one set whose dataset ``snapshots`` holds a NaN."""

    def make(tmp):
        import h5py

        path = _capture(name)(tmp)
        with h5py.File(path, "r+") as h5:
            h5["snapshots"][0, 0, 0] = np.nan
        return path

    return make


def _both(*setups):
    def make(tmp):
        for setup in setups:
            setup(tmp)

    return make


def _link(kind, source, name):
    def make(tmp):
        (os.link if kind == "hard" else os.symlink)(tmp / source, tmp / name)

    return make


def _bytes(name, data):
    def make(tmp):
        (tmp / name).write_bytes(data)

    return make


def _truncated(name):
    def make(tmp):
        path = _capture("whole.h5")(tmp)
        data = path.read_bytes()
        (tmp / name).write_bytes(data[: len(data) // 2])

    return make


def _reconstruction(name):
    def make(tmp):
        rig = _rig()
        save_reconstruction(tmp / name, np.zeros((rig.T,) + rig.shape), rig)

    return make


def _rigfile(tmp):
    from rsocl.files.rigfile import RigFile, save_rigfile

    save_rigfile(tmp / "rig.toml", RigFile.from_rig(rsocl.Rig.paper_array(2, (8, 8), 0.18e-3, 35e-6)))


def _folder(name):
    def make(tmp):
        (tmp / name).mkdir()

    return make


def _capture_to(out):
    def call(tmp):
        from rsocl.hardware.capture import capture_sets

        return capture_sets(tmp / "rig.toml", tmp / out, sets=1)

    return call


def _load(name, **kw):
    return lambda tmp: load_capture(tmp / name, **kw)


CASES = [
    # ------------------------------------------------------------------ derived names never replace an input
    Bad(
        "reconstruct-set-name-is-the-capture",
        ["--out", "m-set000.h5", "capture it reads"],
        argv=["reconstruct", "{tmp}/m-set000.h5", "--out", "{tmp}/m.h5", *FAST],
        setup=_capture("m-set000.h5", 3),
    ),
    Bad(
        "reconstruct-last-set-name-is-the-capture",
        ["--out", "set 2", "capture it reads"],
        argv=["reconstruct", "{tmp}/r-set002.h5", "--out", "{tmp}/r.h5", *FAST],
        setup=_capture("r-set002.h5", 3),
    ),
    Bad(
        "reconstruct-set-name-hard-link-to-capture",
        ["--out", "set 1"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/m.h5", *FAST],
        setup=_both(_capture("c.h5", 3), _link("hard", "c.h5", "m-set001.h5")),
    ),
    Bad(
        "reconstruct-set-name-symlink-to-capture",
        ["--out", "set 0"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/m.h5", *FAST],
        setup=_both(_capture("c.h5", 2), _link("soft", "c.h5", "m-set000.h5")),
    ),
    Bad(
        "reconstruct-out-is-the-capture",
        ["--out", "capture"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/c.h5", *FAST],
        setup=_capture("c.h5"),
    ),
    Bad(
        "reconstruct-out-hard-link-to-the-capture",
        ["--out", "capture"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/same.h5", *FAST],
        setup=_both(_capture("c.h5"), _link("hard", "c.h5", "same.h5")),
    ),
    Bad(
        "reconstruct-out-is-another-capture",
        ["--out", "is a capture file"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/other.h5", *FAST],
        setup=_both(_capture("c.h5"), _capture("other.h5", 2)),
    ),
    Bad(
        "reconstruct-set-name-is-another-capture",
        ["--out's set 1", "is a capture file"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/m.h5", *FAST],
        setup=_both(_capture("c.h5", 2), _capture("m-set001.h5")),
    ),
    Bad(
        "reconstruct-gif-is-the-capture",
        ["--gif", "capture"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/r.h5", "--gif", "{tmp}/c.h5", *FAST],
        setup=_capture("c.h5"),
    ),
    Bad(
        "reconstruct-out-folder-missing",
        ["--out", "does not exist"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/no/r.h5", *FAST],
        setup=_capture("c.h5"),
    ),
    Bad(
        "reconstruct-out-is-a-folder",
        ["--out", "directory"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/d", *FAST],
        setup=_both(_capture("c.h5"), _folder("d")),
    ),
    # ------------------------------------------------------------------ unreadable, corrupt, wrong-kind captures
    Bad(
        "reconstruct-capture-not-hdf5",
        ["junk.h5", "not a readable HDF5 file"],
        argv=["reconstruct", "{tmp}/junk.h5", "--out", "{tmp}/r.h5", *FAST],
        setup=_bytes("junk.h5", b"not hdf5 " * 9),
    ),
    Bad(
        "reconstruct-capture-empty",
        ["empty.h5", "not a readable HDF5 file"],
        argv=["reconstruct", "{tmp}/empty.h5", "--out", "{tmp}/r.h5", *FAST],
        setup=_bytes("empty.h5", b""),
    ),
    Bad(
        "reconstruct-capture-truncated",
        ["half.h5", "not a readable HDF5 file"],
        argv=["reconstruct", "{tmp}/half.h5", "--out", "{tmp}/r.h5", *FAST],
        setup=_truncated("half.h5"),
    ),
    Bad(
        "reconstruct-capture-is-a-reconstruction",
        ["rec.h5", "expected an rsocl 'capture' file"],
        argv=["reconstruct", "{tmp}/rec.h5", "--out", "{tmp}/r.h5", *FAST],
        setup=_reconstruction("rec.h5"),
    ),
    Bad(
        "reconstruct-capture-is-a-folder",
        ["d.h5", "directory"],
        argv=["reconstruct", "{tmp}/d.h5", "--out", "{tmp}/r.h5", *FAST],
        setup=_folder("d.h5"),
    ),
    Bad(
        "reconstruct-capture-set-with-nan",
        ["snapshot_sets", "finite"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/r.h5", *FAST],
        setup=_capture("c.h5", 3, nan_set=1),
    ),
    Bad(
        "reconstruct-capture-snapshots-with-nan",
        ["c.h5", "dataset 'snapshots'", "1 NaN", "finite"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/r.h5", *FAST],
        setup=_nan_snapshot("c.h5"),
    ),
    # ------------------------------------------------------------------ multi-set selection
    Bad(
        "reconstruct-batch-zero",
        ["--batch", ">= 1"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/r.h5", "--batch", "0", *FAST],
        setup=_capture("c.h5", 3),
    ),
    Bad(
        "reconstruct-sets-and-first-set-only",
        ["--sets", "--first-set-only"],
        argv=["reconstruct", "{tmp}/c.h5", "--out", "{tmp}/r.zarr", "--sets", "--first-set-only", *FAST],
        setup=_capture("c.h5", 3),
    ),
    Bad(
        "api-load-capture-set-beyond",
        ["set_index", "[0, 2]", "3 set(s)"],
        api=_load("c.h5", set_index=3),
        setup=_capture("c.h5", 3),
    ),
    Bad(
        "api-load-capture-set-negative",
        ["set_index", ">= 0"],
        api=_load("c.h5", set_index=-1),
        setup=_capture("c.h5", 3),
    ),
    Bad(
        "api-load-capture-set-not-int",
        ["set_index", "integer"],
        api=_load("c.h5", set_index="1"),
        setup=_capture("c.h5", 3),
    ),
    Bad(
        "api-load-capture-set-of-one-set-capture",
        ["set_index", "[0, 0]"],
        api=_load("c.h5", set_index=1),
        setup=_capture("c.h5"),
    ),
    Bad(
        "api-load-capture-missing",
        ["missing.h5", "does not exist"],
        api=_load("missing.h5"),
        errors=(FileNotFoundError,),
    ),
    Bad(
        "api-load-capture-of-a-reconstruction",
        ["rec.h5", "capture"],
        api=_load("rec.h5"),
        setup=_reconstruction("rec.h5"),
    ),
    Bad(
        "api-save-capture-over-a-folder",
        ["path", "directory"],
        api=lambda tmp: save_capture(tmp / "d", np.zeros((2, 8, 8)), _rig()),
        setup=_folder("d"),
    ),
    # ------------------------------------------------------------------ partial captures, capture outputs
    Bad(
        "capture-partial-left-by-a-kill",
        ["out", "k.h5.partial", "holds 3 complete set(s)", "kept"],
        argv=["capture", "--rig", "{tmp}/rig.toml", "--out", "{tmp}/k.h5", "--quiet"],
        setup=_both(_rigfile, _capture("k.h5.partial", 3)),
    ),
    Bad(
        "capture-partial-unreadable",
        ["out", "k.h5.partial", "not readable", "kept"],
        argv=["capture", "--rig", "{tmp}/rig.toml", "--out", "{tmp}/k.h5", "--quiet"],
        setup=_both(_rigfile, _bytes("k.h5.partial", b"\x89HDF\r\n\x1a\n cut short")),
    ),
    Bad(
        "api-capture-partial-left",
        ["out", "k.h5.partial", "holds 1 complete set(s)"],
        api=_capture_to("k.h5"),
        setup=_both(_rigfile, _capture("k.h5.partial")),
    ),
    Bad(
        "capture-out-is-the-rig-file",
        ["--out", "is the --rig it reads"],
        argv=["capture", "--rig", "{tmp}/rig.toml", "--out", "{tmp}/rig.toml", "--quiet"],
        setup=_rigfile,
    ),
    Bad(
        "capture-out-folder-missing",
        ["out", "does not exist"],
        argv=["capture", "--rig", "{tmp}/rig.toml", "--out", "{tmp}/no/k.h5", "--quiet"],
        setup=_rigfile,
    ),
    Bad(
        "capture-rig-missing",
        ["missing.toml"],
        argv=["capture", "--rig", "{tmp}/missing.toml", "--out", "{tmp}/k.h5", "--quiet"],
    ),
]
