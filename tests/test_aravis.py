"""The ``aravis`` camera backend (``rsocl_plugins.aravis``).

Three layers:

- pure functions and config checks: always run;
- the in-process Aravis ``Fake`` camera, and an array of four ``arv-fake-gv-camera-0.8``
  GigE Vision cameras on 127.0.0.1 .. 127.0.0.4: run by ``tests/aravis_netns_helper.py``
  inside a private network namespace (``unshare --net``, only ``lo`` up), because Aravis'
  discovery broadcasts on every network interface. One helper process per layer; its JSON
  report is checked here, one test per behaviour.

Skips (with the reason) where Aravis, PyGObject, ``unshare``/``ip`` or the fake GigE camera
are missing. ``RSOCL_REQUIRE_ARAVIS=1`` (set by CI, which installs them) turns those skips
into failures.
"""

from __future__ import annotations

import functools
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rsocl.hardware.backend import CameraError
from rsocl_plugins.aravis import AravisCamera
from rsocl_plugins.aravis_formats import convert_buffer

HELPER = Path(__file__).with_name("aravis_netns_helper.py")
REQUIRE = os.environ.get("RSOCL_REQUIRE_ARAVIS") == "1"
INSTALL = (
    "apt-get install gir1.2-aravis-0.8 aravis-tools libgirepository1.0-dev libcairo2-dev pkg-config "
    "gcc python3-dev iproute2 util-linux; pip install 'PyGObject<3.51'"
)


def _unavailable(reason):
    if REQUIRE:
        pytest.fail(f"{reason} (RSOCL_REQUIRE_ARAVIS=1: {INSTALL})")
    pytest.skip(f"{reason}; to run these tests: {INSTALL}")


@functools.lru_cache(maxsize=1)
def _aravis_problem():
    try:
        import gi

        gi.require_version("Aravis", "0.8")
        from gi.repository import Aravis  # noqa: F401
    except (ImportError, ValueError) as exc:
        return f"Aravis 0.8 through PyGObject is not importable ({type(exc).__name__}: {exc})"
    return None


@functools.lru_cache(maxsize=1)
def _netns_prefix():
    """``unshare`` arguments that give a private network namespace here, or a reason string."""
    for tool in ("unshare", "ip"):
        if shutil.which(tool) is None:
            return f"'{tool}' is not installed"
    tried = []
    for prefix in (["unshare", "--net"], ["unshare", "--map-root-user", "--net"]):
        try:
            res = subprocess.run(prefix + ["sh", "-c", "ip link set lo up"], capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.SubprocessError) as exc:
            tried.append(f"{' '.join(prefix)}: {exc}")
            continue
        if res.returncode == 0:
            return prefix
        tried.append(f"{' '.join(prefix)}: {res.stderr.strip() or res.returncode}")
    return "cannot make a private network namespace (" + "; ".join(tried) + ")"


def _run_helper(mode, workdir, timeout):
    problem = _aravis_problem()
    if problem:
        _unavailable(problem)
    prefix = _netns_prefix()
    if isinstance(prefix, str):
        _unavailable(prefix)
    if mode == "gige" and shutil.which("arv-fake-gv-camera-0.8") is None:
        _unavailable("arv-fake-gv-camera-0.8 (Debian package aravis-tools) is not installed")
    cmd = prefix + ["sh", "-c", 'ip link set lo up && exec "$0" "$@"', sys.executable, str(HELPER), mode, str(workdir)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        pytest.fail(
            f"aravis helper '{mode}' did not finish within {timeout} s\nstdout:\n{out[-3000:]}\nstderr:\n{err[-3000:]}"
        )
    if proc.returncode != 0:
        pytest.fail(
            f"aravis helper '{mode}' exited with {proc.returncode}\nstdout:\n{out[-3000:]}\nstderr:\n{err[-3000:]}"
        )
    lines = [line for line in out.splitlines() if line.strip()]
    try:
        results = json.loads(lines[-1])
    except (IndexError, ValueError):
        pytest.fail(f"aravis helper '{mode}' printed no JSON report\nstdout:\n{out[-3000:]}\nstderr:\n{err[-3000:]}")
    results["_stderr"] = err
    return results


def _check(results, name):
    facts = results[name]
    assert facts["ok"], f"check {name!r} failed:\n{facts['error']}\nhelper stderr:\n{results['_stderr'][-2000:]}"
    return facts


# ---------------------------------------------------------------------- no Aravis needed
@pytest.mark.parametrize("padding", [0, 3])
def test_convert_buffer_formats(padding):
    h, w = 3, 5
    rng = np.random.default_rng(0)
    for fmt, dtype, top in (("Mono8", np.uint8, 255), ("Mono12", np.uint16, 4095), ("Mono16", np.uint16, 65535)):
        image = rng.integers(0, top + 1, size=(h, w)).astype(dtype)
        little = image.astype(np.dtype(dtype).newbyteorder("<")).view(np.uint8).reshape(h, -1)
        rows = np.concatenate([little, np.full((h, padding), 0xEE, np.uint8)], axis=1)
        out = convert_buffer(rows.tobytes(), fmt, w, h, padding)
        assert out.dtype == np.dtype(dtype) and out.dtype.isnative
        assert out.shape == (h, w)
        np.testing.assert_array_equal(out, image)
        assert out.flags.writeable and out.flags.c_contiguous


def test_convert_buffer_last_row_padding_optional_and_short_buffer():
    data = bytes(range(2 * 4 + 1 + 4))  # 2 rows of 4, 1 padding byte after row 0 only
    np.testing.assert_array_equal(convert_buffer(data, "Mono8", 4, 2, 1), [[0, 1, 2, 3], [5, 6, 7, 8]])
    with pytest.raises(CameraError, match="too small"):
        convert_buffer(b"\x00" * 7, "Mono16", 2, 2)
    with pytest.raises(CameraError, match="not supported"):
        convert_buffer(b"\x00" * 4, "Mono12p", 2, 2)


def test_config_validation():
    cam = AravisCamera(
        {"address": " 10.0.0.2 ", "interfaces": ["GigEVision"], "buffers": 3, "packet_size": 9000}, name="c"
    )
    assert (cam.address, cam.interfaces, cam.buffers, cam.packet_size) == ("10.0.0.2", ["GigEVision"], 3, 9000)
    assert AravisCamera().buffers == 8 and AravisCamera().address is None
    for bad, match in (
        ({"adress": "x"}, r"unknown config key 'adress' \(did you mean 'address'\?\)"),
        ({"address": 5}, "address"),
        ({"interfaces": "Fake"}, "interfaces"),
        ({"interfaces": []}, "interfaces"),
        ({"buffers": 0}, "buffers"),
        ({"buffers": True}, "buffers"),
        ({"packet_size": 100}, "packet_size"),
    ):
        with pytest.raises(ValueError, match=match):
            AravisCamera(bad, name="c")


def test_missing_pygobject_is_a_clear_camera_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "gi", None)  # import gi -> ImportError
    cam = AravisCamera({"address": "Fake_1"}, name="cam0")
    with pytest.raises(CameraError, match=r"PyGObject.*gir1\.2-aravis-0\.8.*rsocl\[aravis\]"):
        cam.open()
    assert "closed" in repr(cam)


def test_a_read_waits_its_timeout_in_slices_so_an_interrupt_or_a_lost_camera_ends_it_early():
    import rsocl_plugins.aravis as aravis

    class Stream:  # never delivers a frame; after 3 waits the camera is lost
        def __init__(self):
            self.waits = []

        def timeout_pop_buffer(self, microseconds):
            self.waits.append(microseconds)
            if len(self.waits) == 3:
                cam._lost = True

    cam = AravisCamera({"address": "Fake_1"}, name="cam0")
    cam._stream, cam._lost = Stream(), False
    cam._gone = lambda: CameraError("cam0: lost")
    with pytest.raises(CameraError, match="cam0: lost"):
        cam._read(30.0)
    assert cam._stream.waits == [int(aravis.WAIT_SLICE * 1e6)] * 3  # 0.3 s of a 30 s timeout


def test_entry_point():
    from rsocl.common.registry import load

    assert load("rsocl.cameras", "aravis") is AravisCamera
    assert AravisCamera.pixel_formats == ("Mono8", "Mono12", "Mono16")


# ---------------------------------------------------------------------- Aravis Fake interface
@pytest.fixture(scope="module")
def fake(tmp_path_factory):
    return _run_helper("fake", tmp_path_factory.mktemp("aravis-fake"), timeout=90)


def _assert_only_loopback(netns):
    """The helper ran where loopback is the only interface (no broadcast leaves the machine)."""
    assert netns["interfaces"] == ["lo"], netns
    assert [line.split(":")[1].strip() for line in netns["ip_link"].splitlines()] == ["lo"], netns["ip_link"]


def test_fake_runs_in_a_private_namespace(fake):
    _assert_only_loopback(fake["netns"])


def test_fake_discover(fake):
    assert [d["id"] for d in _check(fake, "discover")["devices"]] == ["Fake_1"]


def test_fake_mono8_mono16_exposure_roi(fake):
    facts = _check(fake, "capture")
    assert facts["exposure"] == pytest.approx(2e-3)  # ExposureTimeAbs (us) -> seconds
    assert facts["readout_time"] is None  # the Fake camera has no SensorReadoutTime
    for fmt, dtype, bits in (("Mono8", "uint8", 8), ("Mono16", "uint16", 16)):
        frames = facts[fmt]
        assert len(frames) == 2
        for f in frames:
            assert (f["shape"], f["dtype"], f["pixel_format"], f["bit_depth"]) == ([48, 64], dtype, fmt, bits)
            assert f["max"] > 0 and f["writeable"]
            assert f["meta"]["roi"] == [8, 4, 64, 48]
            assert f["meta"]["exposure"] == pytest.approx(2e-3)
            assert f["timestamp"] > 0
        assert frames[1]["meta"]["frame_id"] > frames[0]["meta"]["frame_id"]


def test_fake_errors(fake):
    facts = _check(fake, "errors")
    assert "has no pixel format 'Mono12'" in facts["mono12"] and "Mono16" in facts["mono12"]
    assert "outside the device's range" in facts["exposure"] and "ExposureTimeAbs" in facts["exposure"]
    assert "ROI Width = 100000" in facts["roi"]
    assert "Line7" in facts["line"] and "Line0" in facts["line"]
    assert "NoSuchCamera" in facts["open"] and "Fake_1" in facts["open"]


def test_fake_a_roi_beyond_the_sensor_is_refused_once_the_camera_opens_before_any_file(fake):
    facts = _check(fake, "roi_beyond_sensor")
    assert facts["files"] == ["rig.toml"] and facts["sensor_size"] == [2048, 2048]
    assert facts["refusal"].endswith(
        "rig.toml: camera[0].roi = [2000, 0, 64, 48] ([x, y, width, height]) must lie on the 2048x2048 "
        "(width x height) sensor of camera 0 (aravis Fake_1): x + width <= 2048 and y + height <= 2048"
    )


def test_fake_timeout(fake):
    outcomes = _check(fake, "timeout")["outcomes"]
    assert any("no frame within 0.2 s" in o for o in outcomes), outcomes


# ---------------------------------------------------------------------- GigE Vision array
@pytest.fixture(scope="module")
def gige(tmp_path_factory):
    return _run_helper("gige", tmp_path_factory.mktemp("aravis-gige"), timeout=150)


def test_gige_runs_in_a_private_namespace(gige):
    _assert_only_loopback(gige["netns"])
    addresses = _check(gige, "start")["ip_addr"]
    for i in range(1, 5):
        assert f"127.0.0.{i}/8" in addresses
    assert {line.split()[1] for line in addresses.splitlines()} == {"lo"}, addresses


def test_gige_fake_cameras_stopped(gige):
    stopped = gige["stopped"]
    assert stopped["ok"] and len(stopped["returncodes"]) == 4, stopped


def test_gige_discover_four_cameras(gige):
    devices = _check(gige, "discover")["devices"]
    assert sorted((d["address"], d["serial"]) for d in devices) == [(f"127.0.0.{i}", f"GV0{i}") for i in range(1, 5)]


def test_gige_array_software_trigger(gige):
    facts = _check(gige, "array")
    assert [i["serial"] for i in facts["info"]] == ["GV01", "GV02", "GV03", "GV04"]
    assert all(i["protocol"] == "GigEVision" for i in facts["info"])
    # camera 1 runs the modified GenICam file: SFNC ExposureTime, SensorReadoutTime (1920 us / 48 rows)
    assert facts["exposure"] == pytest.approx([2e-3] * 4)
    assert facts["readout_time"][1] == pytest.approx(40e-6)
    assert facts["readout_time"][0] is None and facts["readout_time"][2] is None
    assert facts["timeout_seconds"] == pytest.approx(0.3, abs=0.2)
    expected = [("Mono16", "uint16", 16), ("Mono12", "uint16", 12), ("Mono8", "uint8", 8), ("Mono16", "uint16", 16)]
    sets = facts["sets"]
    assert len(sets) == 3
    for frames in sets:
        for f, (fmt, dtype, bits) in zip(frames, expected):
            assert (f["shape"], f["dtype"], f["pixel_format"], f["bit_depth"]) == ([48, 64], dtype, fmt, bits)
            assert f["meta"]["roi"] == [0, 0, 64, 48]
            if fmt != "Mono12":  # the fake camera draws nothing in formats it does not know
                assert f["max"] > 0
    for cam in range(4):  # one frame per trigger, none lost
        ids = [frames[cam]["meta"]["frame_id"] for frames in sets]
        assert ids == list(range(ids[0], ids[0] + 3)), ids


def test_gige_capture_sets_four_cameras(gige):
    facts = _check(gige, "capture")
    if "skipped" in facts:
        pytest.skip(facts["skipped"])
    assert facts["status"] == "complete" and facts["sets_complete"] == 2
    assert facts["raw_shapes"] == [[2, 48, 64]] * 4
    assert facts["raw_dtypes"] == ["uint16", "uint16", "uint8", "uint16"]
    assert facts["sets"] == [[0, 1]] * 4
    assert facts["snapshot_sets"] == [2, 4, 48, 64] and facts["snapshots"] == [4, 48, 64]
    assert facts["rig_cameras"] == 4
    assert facts["warnings"] == []  # exposure and the reported readout time match the rig file
    for i, (attrs, meta, cam) in enumerate(zip(facts["raw_attrs"], facts["frame_meta"], facts["cameras"])):
        fmt, bits = [("Mono16", 16), ("Mono12", 12), ("Mono8", 8), ("Mono16", 16)][i]
        assert attrs["backend"] == "aravis" and attrs["pixel_format"] == fmt and attrs["bit_depth"] == bits
        assert attrs["exposure"] == pytest.approx(2e-3) and attrs["roi"] == [0, 0, 64, 48]
        assert json.loads(attrs["config"])["address"] == f"127.0.0.{i + 1}"
        assert meta["device_id"] == f"GV0{i + 1}" and meta["roi"] == [0, 0, 64, 48]
        assert cam["readout_time"] == (pytest.approx(40e-6) if i == 1 else None)


def test_gige_disconnect(gige):
    facts = _check(gige, "disconnect")
    assert "write_register timeout" in facts["trigger_error"]  # register access after Aravis' retries
    assert "device is gone" in facts["read_error"]  # the heartbeat's control-lost signal
    assert facts["read_detected_after"] < 20
