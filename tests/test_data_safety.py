"""Nothing a user has is lost, and faults end in one line: derived outputs never replace an input, a
partial capture is never truncated, stale temporaries of dead processes go, multi-set captures are read
explicitly, and full disks, locks and kernel-cache races end cleanly."""

import errno
import hashlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import types
import warnings

import h5py
import numpy as np
import pytest

from rsocl.cli.main import main
from rsocl.files.atomic import OutputError, owned_prefix, process_running, remove_stale
from rsocl.files.hdf5 import load_capture, load_snapshot_sets, save_capture
from rsocl.files.rigfile import RigFile, save_rigfile
from rsocl.hardware.capture import capture_sets
from rsocl.model.rig import Rig

SHAPE = (16, 16)


def _md5(path):
    return hashlib.md5(path.read_bytes()).hexdigest()


def _rig_file(folder, shape=SHAPE):
    path = folder / f"rig{shape[0]}.toml"
    save_rigfile(path, RigFile.from_rig(Rig.paper_array(4, shape, t_e=180e-6, t_r=35e-6)))
    return path


@pytest.fixture(scope="module")
def three_sets(tmp_path_factory):
    """A capture of 3 sets (simulated cameras), made once; tests copy it."""
    folder = tmp_path_factory.mktemp("three")
    return capture_sets(_rig_file(folder), folder / "three.h5", sets=3)


def _error_lines(err):
    return [line for line in err.splitlines() if ": error:" in line]


def _dead_pid():
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    assert not process_running(child.pid)
    return child.pid


# ---------------------------------------------------------------------- 1. derived names never replace inputs
@pytest.mark.parametrize("how", ["copy", "hard link", "symlink"])
def test_a_per_set_name_that_is_the_capture_is_refused_before_any_work(three_sets, tmp_path, capsys, how):
    source = tmp_path / "m-set000.h5"
    if how == "copy":
        shutil.copy(three_sets, source)
        capture, out = source, tmp_path / "m.h5"
    else:
        capture = tmp_path / "c.h5"
        shutil.copy(three_sets, capture)
        (os.link if how == "hard link" else os.symlink)(capture, tmp_path / "m-set001.h5")
        out = tmp_path / "m.h5"
    before = {p.name: _md5(p) for p in tmp_path.iterdir()}
    rc = main(["reconstruct", str(capture), "--out", str(out), "--fast", "--iterations", "2", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err
    [line] = _error_lines(err)
    assert "--out's set" in line and "capture it reads" in line and "of 3 sets" in line
    assert {p.name: _md5(p) for p in tmp_path.iterdir()} == before


def test_a_reconstruction_never_replaces_another_capture(three_sets, tmp_path, capsys):
    shutil.copy(three_sets, tmp_path / "c.h5")
    shutil.copy(three_sets, tmp_path / "other.h5")
    before = _md5(tmp_path / "other.h5")
    assert (
        main(
            [
                "reconstruct",
                str(tmp_path / "c.h5"),
                "--out",
                str(tmp_path / "other.h5"),
                "--first-set-only",
                "--fast",
                "--iterations",
                "2",
                "--quiet",
            ]
        )
        == 2
    )
    assert "--out" in capsys.readouterr().err and _md5(tmp_path / "other.h5") == before


def test_per_set_outputs_are_written_when_they_collide_with_nothing(three_sets, tmp_path, capsys):
    shutil.copy(three_sets, tmp_path / "m-set000.h5")
    assert (
        main(
            [
                "reconstruct",
                str(tmp_path / "m-set000.h5"),
                "--out",
                str(tmp_path / "r.h5"),
                "--fast",
                "--iterations",
                "2",
                "--quiet",
            ]
        )
        == 0
    )
    assert sorted(p.name for p in tmp_path.glob("r-set*.h5")) == ["r-set000.h5", "r-set001.h5", "r-set002.h5"]


def test_a_capture_from_cameras_is_never_replaced_by_a_simulation_or_another_capture(three_sets, tmp_path, capsys):
    out = tmp_path / "take1.h5"
    shutil.copy(three_sets, out)
    before = _md5(out)
    assert main(["simulate", "builtin", "--out", str(out), "--shape", "16", "16", "--quiet"]) == 2
    [line] = _error_lines(capsys.readouterr().err)
    assert line == (
        f"rsocl simulate: error: --out {str(out)!r} holds 12 frame(s) from cameras (rsocl capture); a capture "
        "from cameras is never replaced: it is kept, move it or choose another --out"
    )
    with pytest.raises(ValueError, match=r"^out .* holds 12 frame\(s\) from cameras"):
        capture_sets(_rig_file(tmp_path), out, sets=1)
    assert _md5(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig16.toml", "take1.h5"]  # no partial, no temporary


def test_a_simulated_capture_may_be_replaced(tmp_path, capsys):
    out = tmp_path / "sim.h5"
    for seed in (0, 1):
        argv = ["simulate", "builtin", "--out", str(out), "--shape", "12", "12", "--quiet"]
        assert main([*argv, "--noise", "gaussian", "--sigma", "0.1", "--seed", str(seed)]) == 0
        assert load_capture(out).meta["seed"] == seed
    assert capture_sets(_rig_file(tmp_path, (12, 12)), out, sets=1) == out  # rsocl capture over a simulation
    assert load_capture(out).meta["status"] == "complete"


def test_camera_frames_counts_only_frames_from_cameras(three_sets, tmp_path, monkeypatch):
    import rsocl.files.hdf5_kinds as kinds_module
    from rsocl.files.hdf5 import camera_frames, refuse_camera_capture

    sim = tmp_path / "sim.h5"
    save_capture(sim, np.zeros((4,) + SHAPE), Rig.paper_array(4, SHAPE, t_e=180e-6, t_r=35e-6))
    (tmp_path / "text.h5").write_text("not HDF5")
    for path in (tmp_path / "absent.h5", tmp_path, tmp_path / "text.h5", sim):
        assert camera_frames(path) is None
        refuse_camera_capture(path)  # nothing to keep
    assert camera_frames(three_sets) == 12  # 4 cameras x 3 sets

    def unreadable(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(kinds_module, "open", unreadable, raising=False)
    with pytest.raises(PermissionError):
        camera_frames(sim)
    with pytest.raises(ValueError, match=r"--out .* cannot be read to tell .* \(Permission denied\); it is kept"):
        refuse_camera_capture(sim)


def test_a_second_reconstruction_to_one_name_keeps_the_earlier_result(three_sets, tmp_path, capsys):
    from rsocl.files.hdf5 import load_reconstruction

    capture = tmp_path / "c.h5"
    shutil.copy(three_sets, capture)
    out = tmp_path / "r.h5"
    argv = ["reconstruct", str(capture), "--out", str(out), "--first-set-only", "--fast"]
    assert main([*argv, "--iterations", "2"]) == 0
    first = out.read_bytes()
    capsys.readouterr()
    assert main([*argv, "--iterations", "3"]) == 0
    [kept] = tmp_path.glob("r.earlier-*.h5")
    assert kept.read_bytes() == first and len(load_reconstruction(kept).history["residual"]) == 2
    assert len(load_reconstruction(out).history["residual"]) == 3
    assert capsys.readouterr().out.rstrip().endswith(f"(the earlier file there is kept as {kept})")


def test_the_earlier_per_set_results_are_kept_too(three_sets, tmp_path, capsys):
    capture = tmp_path / "c.h5"
    shutil.copy(three_sets, capture)
    argv = ["reconstruct", str(capture), "--out", str(tmp_path / "r.h5"), "--fast", "--iterations", "2"]
    assert main(argv) == 0 and main(argv) == 0
    kept = sorted(p.name for p in tmp_path.glob("r-set*.earlier-*.h5"))
    assert [name.split(".")[0] for name in kept] == ["r-set000", "r-set001", "r-set002"]
    assert "(the 3 earlier files there are kept as <stem>.earlier-<UTC time><suffix>: " in capsys.readouterr().out


def test_an_earlier_file_keeps_its_bytes_by_a_link_or_a_copy(tmp_path, monkeypatch):
    from rsocl.files.atomic import atomic_path, keeping

    path = tmp_path / "r.h5"
    path.write_bytes(b"earlier")
    inode = path.stat().st_ino
    with keeping(path, "earlier") as kept:
        with atomic_path(path) as tmp:
            tmp.write_bytes(b"new")
    assert kept.read_bytes() == b"earlier" and path.read_bytes() == b"new"
    assert kept.stat().st_ino == inode  # a hard link: no byte copied

    def no_links(*args, **kwargs):
        raise OSError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_links)
    with keeping(path, "earlier") as copy:
        path.write_bytes(b"newer")
    assert copy.read_bytes() == b"new" and copy != kept and copy.stat().st_ino != path.stat().st_ino
    with pytest.raises(RuntimeError), keeping(path, "earlier") as gone:  # a failed write: no second name left
        raise RuntimeError
    assert not gone.exists() and path.read_bytes() == b"newer"


@pytest.mark.parametrize("links", [True, False])
def test_a_block_that_fails_after_replacing_the_file_leaves_the_earlier_one_its_name(tmp_path, monkeypatch, links):
    from rsocl.files.atomic import atomic_path, keeping

    if not links:
        monkeypatch.setattr(os, "link", lambda *a, **k: (_ for _ in ()).throw(OSError(errno.EPERM, "no links")))
    path = tmp_path / "r.h5"
    path.write_bytes(b"earlier")
    with pytest.raises(KeyboardInterrupt), keeping(path, "earlier") as kept:
        with atomic_path(path) as tmp:
            tmp.write_bytes(b"new")
        raise KeyboardInterrupt  # Ctrl-C after the rename, before the block ends
    assert path.read_bytes() == b"new" and kept.read_bytes() == b"earlier"


def test_kept_note_words():
    from rsocl.cli.outputs import kept_note

    assert kept_note([None, None]) == ""
    assert kept_note(["a.earlier-1.h5"]) == " (the earlier file there is kept as a.earlier-1.h5)"
    assert kept_note(["a.earlier-1.h5", None, "b.earlier-1.h5"]).startswith(" (the 2 earlier files there are kept")


# ---------------------------------------------------------------------- 2. a partial capture is never truncated
def _complete_sets(path) -> int:
    """``sets_complete`` of a capture file another process is writing, read past its lock (0 while
    the file is missing or caught mid-write)."""
    try:
        with h5py.File(path, "r", locking=False) as h5:
            return int(h5.attrs.get("sets_complete", 0))
    except (OSError, KeyError, ValueError):
        return 0


def test_a_partial_capture_left_by_a_kill_is_kept_and_refused(tmp_path):
    rig = _rig_file(tmp_path)
    out = tmp_path / "k.h5"
    partial = tmp_path / "k.h5.partial"
    child = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rsocl.cli",
            "capture",
            "--rig",
            str(rig),
            "--out",
            str(out),
            "--sets",
            "100000",
            "--quiet",
        ],
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 120
        while _complete_sets(partial) < 1 and time.monotonic() < deadline:
            assert child.poll() is None, child.stderr.read()
            time.sleep(0.05)
        # while it runs, a second capture to the same --out is refused: the first holds the file's lock
        with pytest.raises(ValueError, match=r"out: .*k\.h5\.partial' is being written by another capture"):
            capture_sets(rig, out, sets=1)
        with pytest.raises(ValueError, match=r"path: .*k\.h5\.partial' is being written by another process"):
            load_capture(partial)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
        child.stderr.close()
    with h5py.File(partial, "r") as h5:
        sets = int(h5.attrs["sets_complete"])
    assert sets >= 1
    before = _md5(partial)
    with pytest.raises(
        ValueError,
        match=rf"out: .*k\.h5\.partial' holds {sets} complete set\(s\) of an earlier "
        r"capture that did not end; it is kept",
    ):
        capture_sets(rig, out, sets=2)
    assert _md5(partial) == before and not out.exists()
    assert load_snapshot_sets(partial).shape[0] >= sets  # still a readable capture


def test_a_partial_capture_is_refused_by_the_command(three_sets, tmp_path, capsys):
    rig = _rig_file(tmp_path)
    partial = tmp_path / "k.h5.partial"
    shutil.copy(three_sets, partial)
    before = _md5(partial)
    assert main(["capture", "--rig", str(rig), "--out", str(tmp_path / "k.h5"), "--quiet"]) == 2
    [line] = _error_lines(capsys.readouterr().err)
    assert "k.h5.partial' holds 3 complete set(s)" in line and _md5(partial) == before


# ---------------------------------------------------------------------- 3. stale temporaries
def test_stale_hdf5_temporaries_of_dead_processes_are_removed_live_ones_kept(tmp_path):
    dead = tmp_path / f"out.h5.{socket.gethostname()}-{_dead_pid()}-abcd1234.tmp"
    live = tmp_path / f"out.h5.{socket.gethostname()}-{os.getppid()}-abcd1234.tmp"
    other_host = tmp_path / f"out.h5.elsewhere-{_dead_pid()}-abcd1234.tmp"
    other_name = tmp_path / f"other.h5.{socket.gethostname()}-{_dead_pid()}-abcd1234.tmp"
    for path in (dead, live, other_host, other_name):
        path.write_bytes(b"half written")
    rig = Rig.paper_array(2, (4, 4), t_e=180e-6, t_r=35e-6)
    save_capture(tmp_path / "out.h5", np.zeros((rig.n_channels, 4, 4)), rig)
    assert not dead.exists()
    assert live.exists() and other_host.exists() and other_name.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["out.h5", live.name, other_host.name, other_name.name])


def test_a_temporary_is_named_by_its_owner_and_remove_stale_spares_folders_of_live_processes(tmp_path):
    assert owned_prefix("x.") == f"x.{socket.gethostname()}-{os.getpid()}-"
    mine = tmp_path / f"{owned_prefix('.s.zarr.partial-')}0123abcd"
    gone = tmp_path / f".s.zarr.partial-{socket.gethostname()}-{_dead_pid()}-0123abcd"
    for folder in (mine, gone):
        folder.mkdir()
        (folder / "zarr.json").write_text("{}")
    assert remove_stale(tmp_path, ".s.zarr.partial-", r"[0-9a-f]{8}") == [gone]
    assert mine.is_dir() and not gone.exists()


# ---------------------------------------------------------------------- 7. multi-set captures read explicitly
def test_load_capture_of_several_sets_is_explicit(three_sets):
    sets = load_snapshot_sets(three_sets)
    with pytest.warns(UserWarning, match=r"holds 3 sets; load_capture reads set 0 \(set_index=0"):
        implicit = load_capture(three_sets)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        first = load_capture(three_sets, set_index=0)
        last = load_capture(three_sets, set_index=2)
    np.testing.assert_array_equal(implicit.snapshots, sets[0])
    np.testing.assert_array_equal(first.snapshots, sets[0])
    np.testing.assert_array_equal(last.snapshots, sets[2])
    assert first.truth is not None and last.truth is None  # the stored truth is set 0's
    for bad, match in (
        (3, r"set_index must be in \[0, 2\]"),
        (-1, "set_index must be an integer >= 0"),
        (True, "set_index must be an integer"),
        (1.0, "set_index must be an integer"),
    ):
        with pytest.raises(ValueError, match=match):
            load_capture(three_sets, set_index=bad)


def test_load_capture_of_one_set_does_not_warn(tmp_path):
    rig = Rig.paper_array(2, (4, 4), t_e=180e-6, t_r=35e-6)
    path = save_capture(tmp_path / "one.h5", np.ones((rig.n_channels, 4, 4)), rig)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load_capture(path).snapshots.shape == (rig.n_channels, 4, 4)
        assert load_capture(path, set_index=0).snapshots.shape == (rig.n_channels, 4, 4)
    with pytest.raises(ValueError, match=r"set_index must be in \[0, 0\]"):
        load_capture(path, set_index=1)


# ---------------------------------------------------------------------- 14. faults as one line
def _disk_full(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_while_reconstructing_is_one_line_and_keeps_the_earlier_result(
    three_sets, tmp_path, capsys, monkeypatch
):
    capture = tmp_path / "c.h5"
    shutil.copy(three_sets, capture)
    out = tmp_path / "r.h5"
    out.write_bytes(b"an earlier result")
    monkeypatch.setattr("rsocl.files.hdf5_reconstruction.write_header", _disk_full)
    rc = main(
        ["reconstruct", str(capture), "--out", str(out), "--first-set-only", "--fast", "--iterations", "2", "--quiet"]
    )
    err = capsys.readouterr().err
    assert rc == 1 and "Traceback" not in err
    [line] = _error_lines(err)
    assert f"cannot write {str(out)!r}: No space left on device (errno 28); the existing file is unchanged" in line
    assert out.read_bytes() == b"an earlier result"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.h5", "r.h5"]  # no temporary left


def test_a_full_disk_while_simulating_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("rsocl.files.hdf5.write_header", _disk_full)
    rc = main(
        ["simulate", "builtin", "--shape", "8", "8", "--cameras", "2", "--out", str(tmp_path / "s.h5"), "--quiet"]
    )
    [line] = _error_lines(capsys.readouterr().err)
    assert rc == 1 and "s.h5'" in line and "no file was made" in line
    assert list(tmp_path.iterdir()) == []


def test_output_error_is_an_oserror_naming_the_file():
    exc = OutputError("/x/r.h5", OSError(errno.EACCES, "Permission denied\nmore"), existed=False)
    assert isinstance(exc, OSError) and exc.errno == errno.EACCES and exc.filename == "/x/r.h5"
    assert str(exc) == "cannot write '/x/r.h5': Permission denied (errno 13); no file was made"
    unnumbered = OutputError("r.h5", OSError("HDF5: cannot\nclose"), existed=True)
    assert str(unnumbered) == "cannot write 'r.h5': HDF5: cannot close; the existing file is unchanged"


def test_a_lock_or_permission_fault_is_one_line_naming_the_file():
    from rsocl.cli.main import fault_line

    locked = BlockingIOError(errno.EAGAIN, "Unable to synchronously open file (unable to lock file)", "c.h5")
    assert fault_line(locked).startswith("'c.h5': another process holds its lock")
    denied = fault_line(PermissionError(errno.EACCES, "Permission denied", "/ro/r.h5"))
    assert (
        denied == "'/ro/r.h5': Permission denied (errno 13); outputs replace a file only once complete, so the "
        "files already there are unchanged"
    )


def test_a_write_error_during_capture_keeps_the_sets_and_is_one_line(tmp_path, capsys, monkeypatch):
    from rsocl.hardware import capture_file

    real = capture_file.CaptureWriter.add_raw

    def add_raw(self, index, set_index, frame, camera):
        if set_index == 2:
            raise OSError(errno.ENOSPC, "Can't write data (file write failed\n, errno = 28)")
        return real(self, index, set_index, frame, camera)

    monkeypatch.setattr(capture_file.CaptureWriter, "add_raw", add_raw)
    rig = _rig_file(tmp_path)
    assert main(["capture", "--rig", str(rig), "--out", str(tmp_path / "f.h5"), "--sets", "5", "--quiet"]) == 1
    [line] = _error_lines(capsys.readouterr().err)
    assert "write failed in set 2: OSError: [Errno 28] No space left on device" in line
    assert "2 complete set(s) and the failure are in" in line
    assert load_snapshot_sets(tmp_path / "f.h5").shape[0] == 2


POSIX = pytest.mark.skipif(os.name != "posix", reason="file-size limits (RLIMIT_FSIZE) are POSIX")


def _limited(limit):
    """A ``preexec_fn`` under which no file of the child may grow past ``limit`` bytes (EFBIG, as a full disk)."""
    import resource

    def refuse_large_files():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return refuse_large_files


@POSIX
def test_capture_on_a_disk_that_refuses_writes_ends_in_one_line_not_a_crash(tmp_path):
    rig = _rig_file(tmp_path, shape=(64, 64))
    capture_sets(rig, tmp_path / "warm.h5", sets=1)  # the kernels built (and cached) without the limit
    out = tmp_path / "f.h5"
    out.write_bytes(b"an earlier capture")
    # the capture's own look at the limit blinded (it ends the capture before a set the limit has no room for:
    # tests/test_capture_file_limit.py), so that HDF5's write itself is refused
    blind = (
        "import sys; from rsocl.hardware import capture_room; capture_room.file_size_limit = lambda: None; "
        "from rsocl.cli.main import entry; sys.exit(entry(sys.argv[1:]))"
    )
    run = subprocess.run(
        [sys.executable, "-c", blind, "capture", "--rig", str(rig), "--out", str(out), "--sets", "40", "--quiet"],
        preexec_fn=_limited(3_000_000),
        capture_output=True,
        text=True,
        timeout=300,
    )  # no file may grow past 3 MB: the capture needs more
    assert run.returncode == 1, (run.returncode, run.stderr)  # not a crash (-11, 139)
    assert "Traceback" not in run.stderr and "Exception ignored" not in run.stderr
    [line] = _error_lines(run.stderr)
    assert "[Errno 27] File too large" in line and "f.h5.partial' is kept as written" in line
    assert "'" + str(out) + "' is unchanged" in line
    assert out.read_bytes() == b"an earlier capture"


def test_a_kernel_build_is_retried_once_on_a_cache_race(device, monkeypatch):
    import uuid

    import pyopencl as cl

    from rsocl.device import program as progmod

    real_build, real_source = cl.Program.build, progmod.kernel_source
    calls = []
    text = f"/* {uuid.uuid4().hex} */\n__kernel void nothing(__global float *x) {{ }}\n"
    monkeypatch.setattr(progmod, "kernel_source", lambda name: text if name == "fake.cl" else real_source(name))

    def flaky(fail_times):
        def build(self, *args, **kwargs):
            calls.append(1)
            if len(calls) <= fail_times:
                raise cl.RuntimeError("clBuildProgram failed: BUILD_PROGRAM_FAILURE (PoCL cache race)")
            return real_build(self, *args, **kwargs)

        return build

    monkeypatch.setattr(cl.Program, "build", flaky(1))
    progmod.build_program(device.context, ("fake.cl",), (("REAL", "float"),))
    assert len(calls) == 2
    calls.clear()
    monkeypatch.setattr(cl.Program, "build", flaky(2))
    with pytest.raises(cl.RuntimeError, match="clBuildProgram"):
        progmod.build_program(device.context, ("fake.cl",), (("REAL", "float"),))
    assert len(calls) == 2  # once more, not again and again


def test_a_tiled_runs_error_goes_to_stderr(three_sets, tmp_path, capsys, monkeypatch):
    from rsocl.scale import tiled

    class Failed(tiled.TilesFailed):
        def __init__(self):
            self.result = types.SimpleNamespace(pieces=[1, 2], skipped=1, failures=["tile (0, 0): boom"], store=None)
            RuntimeError.__init__(self, "1 task(s) failed, 3 solved")

    def fail(*args, **kwargs):
        raise Failed()

    monkeypatch.setattr(tiled, "reconstruct_tiled", fail)
    shutil.copy(three_sets, tmp_path / "c.h5")
    rc = main(
        [
            "reconstruct",
            str(tmp_path / "c.h5"),
            "--out",
            str(tmp_path / "r.h5"),
            "--tile",
            "8",
            "8",
            "--first-set-only",
            "--fast",
            "--iterations",
            "2",
            "--quiet",
        ]
    )
    captured = capsys.readouterr()
    assert rc == 1 and "error" not in captured.out
    said = f"rsocl reconstruct: error: 1 task(s) failed, 3 solved and discarded; nothing was written to {tmp_path}"
    assert said in captured.err
    assert captured.err.endswith("\n  tile (0, 0): boom\n") and not (tmp_path / "r.h5").exists()


@POSIX
def test_simulate_on_a_disk_that_refuses_writes_is_one_line_and_keeps_the_earlier_file(tmp_path, capsys):
    argv = ["simulate", "builtin", "--shape", "96", "96", "--quiet"]
    assert main([*argv, "--out", str(tmp_path / "warm.h5")]) == 0  # kernels built without the limit
    out = tmp_path / "s.h5"
    out.write_bytes(b"an earlier capture")
    run = subprocess.run(
        [sys.executable, "-m", "rsocl.cli", *argv, "--out", str(out)],
        capture_output=True,
        text=True,
        preexec_fn=_limited(1_500_000),
        timeout=300,
    )
    assert run.returncode == 1 and "Traceback" not in run.stderr, run.stderr
    [line] = _error_lines(run.stderr)
    assert (
        line == f"rsocl simulate: error: cannot write {str(out)!r}: File too large (errno 27); the existing "
        "file is unchanged"
    )
    assert out.read_bytes() == b"an earlier capture"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.h5", "warm.h5"]


def test_a_close_that_cannot_write_is_an_oserror_with_its_errno(tmp_path, monkeypatch):
    import h5py

    def close(self):
        raise RuntimeError(
            "Can't decrement id ref count (unable to extend file properly, errno = 28, "
            "error message = 'No space left on device')"
        )

    monkeypatch.setattr(h5py.File, "close", close)
    rig = Rig.paper_array(2, (4, 4), t_e=180e-6, t_r=35e-6)
    with pytest.raises(OutputError, match=r"cannot write .*one\.h5': No space left on device \(errno 28\); no file"):
        save_capture(tmp_path / "one.h5", np.zeros((rig.n_channels, 4, 4)), rig)
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_part_way_through_the_sets_says_which_are_written(three_sets, tmp_path, capsys, monkeypatch):
    from rsocl.files import hdf5_reconstruction

    real = hdf5_reconstruction.save_reconstruction

    def save(path, *args, **kwargs):
        if "set002" in str(path):
            raise OutputError(path, OSError(errno.ENOSPC, "No space left on device"), existed=False)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(hdf5_reconstruction, "save_reconstruction", save)
    shutil.copy(three_sets, tmp_path / "c.h5")
    rc = main(
        [
            "reconstruct",
            str(tmp_path / "c.h5"),
            "--out",
            str(tmp_path / "r.h5"),
            *"--fast --iterations 2 --quiet".split(),
        ]
    )
    [line] = _error_lines(capsys.readouterr().err)
    assert rc == 1 and line.startswith(f"rsocl reconstruct: error: cannot write {str(tmp_path / 'r-set002.h5')!r}")
    assert line.endswith(f"no file was made; sets 0 to 1 are written ({tmp_path / 'r-set000.h5'} ..)")
    assert sorted(p.name for p in tmp_path.glob("r-set*")) == ["r-set000.h5", "r-set001.h5"]
    capsys.readouterr()
    assert (
        main(["reconstruct", str(tmp_path / "c.h5"), "--out", str(tmp_path / "r.h5"), *"--fast --iterations 2".split()])
        == 1
    )
    [line] = _error_lines(capsys.readouterr().err)  # again: sets 0 and 1 replaced, their earlier files kept
    kept = sorted(tmp_path.glob("r-set*.earlier-*.h5"))
    assert [p.name.split(".")[0] for p in kept] == ["r-set000", "r-set001"]
    assert line.endswith(
        f"sets 0 to 1 are written ({tmp_path / 'r-set000.h5'} ..), the 2 earlier files there are kept as "
        f"<stem>.earlier-<UTC time><suffix>: {kept[0]} .."
    )
