"""Real Aravis checks of the ``aravis`` camera backend, run inside a private network namespace.

Run by ``tests/test_aravis.py`` as::

    unshare --net sh -c 'ip link set lo up && exec python tests/aravis_netns_helper.py fake|gige WORKDIR'

Aravis' discovery broadcasts on every network interface, so this script refuses to run
unless the only network interface it can see is ``lo`` (a fresh namespace from
``unshare --net``): no packet can leave loopback.

``fake``  the in-process Aravis ``Fake`` interface (GigE Vision and USB3 Vision interfaces
          disabled before anything else).
``gige``  four ``arv-fake-gv-camera-0.8`` processes on 127.0.0.1 .. 127.0.0.4 (lo gets the
          extra addresses; GigE Vision's control port 3956 is fixed, so one camera per
          address) acting as an array; camera 1 runs a modified GenICam file (``ExposureTime``
          instead of ``ExposureTimeAbs``, ``Mono12``, a constant ``SensorReadoutTime``).
          Every camera process is killed at the end (and by the kernel if this script dies).

Each check is recorded, never raised: the script prints one JSON object
``{check: {"ok": bool, "error": traceback or None, ...facts}}`` on its last stdout line and
exits 0; the pytest side asserts on it. Every wait is bounded.
"""

from __future__ import annotations

import ctypes
import json
import signal
import socket
import subprocess
import sys
import time
import traceback
from pathlib import Path

FAKE_GV = "arv-fake-gv-camera-0.8"
ADDRESSES = ["127.0.0.1", "127.0.0.2", "127.0.0.3", "127.0.0.4"]
SHAPE = (48, 64)  # rows, columns of every ROI in the array checks
READOUT_US = 1920.0  # constant SensorReadoutTime of the modified camera: 40 us per row at Height 48
# The fake cameras draw a diagonal ramp scaled by 1 + gain + log10(exposure / 10 ms): below about
# 1.4 ms every pixel is 0, so the checks expose for 2 ms to see real data flow.
EXPOSURE = 2e-3


# ---------------------------------------------------------------------- safety
def network_interfaces():
    # if_nameindex asks the kernel about this process's network namespace (/sys/class/net
    # shows the namespace sysfs was mounted in, usually the host's).
    return sorted(name for _, name in socket.if_nameindex())


def require_private_netns():
    names = network_interfaces()
    if names != ["lo"]:
        sys.stderr.write(
            f"refusing to run: network interfaces {names} are visible; Aravis discovery would "
            "broadcast on them. Run inside 'unshare --net'.\n"
        )
        sys.exit(3)


def ip_link():
    try:
        return subprocess.run(["ip", "-o", "link", "show"], capture_output=True, text=True, timeout=5).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        return f"ip failed: {exc}"


# ---------------------------------------------------------------------- checks
class Checks:
    def __init__(self):
        self.results = {}

    def run(self, name, fn, *args):
        t0 = time.monotonic()
        facts = {}
        try:
            out = fn(facts, *args)
            ok, error = True, None
        except BaseException as exc:  # noqa: BLE001 - every failure is reported to pytest
            if isinstance(exc, KeyboardInterrupt):
                raise
            out, ok, error = None, False, "".join(traceback.format_exception(exc))
        facts.update(ok=ok, error=error, seconds=round(time.monotonic() - t0, 3))
        self.results[name] = facts
        return out


def expect(condition, message):
    if not condition:
        raise AssertionError(message)


def expect_raises(kind, fn, *args):
    try:
        fn(*args)
    except kind as exc:
        return exc
    raise AssertionError(f"{getattr(fn, '__name__', fn)}{args} did not raise {kind.__name__}")


def frame_facts(frame):
    img = frame.image
    return {
        "shape": list(img.shape),
        "dtype": str(img.dtype),
        "pixel_format": frame.pixel_format,
        "bit_depth": frame.bit_depth,
        "min": int(img.min()),
        "max": int(img.max()),
        "timestamp": frame.timestamp,
        "meta": frame.meta,
        "writeable": bool(img.flags.writeable),
    }


# ---------------------------------------------------------------------- Fake interface
def fake_checks(workdir):
    from gi.repository import Aravis  # noqa: F401  (import_aravis did require_version)

    from rsocl.hardware.backend import CameraError, CameraTimeout
    from rsocl_plugins.aravis import AravisCamera
    from rsocl_plugins.aravis_discovery import discover

    checks = Checks()
    config = {"address": "Fake_1", "interfaces": ["Fake"]}

    def c_discover(facts):
        devices = discover(["Fake"])
        facts["devices"] = devices
        expect([d["id"] for d in devices] == ["Fake_1"], f"Fake interface devices: {devices}")

    def c_capture(facts):
        with AravisCamera(config, name="fake") as cam:
            facts["info"] = cam.device_info
            facts["readout_time"] = cam.readout_time
            facts["exposure"] = cam.set_exposure(2e-3)
            cam.set_roi(8, 4, SHAPE[1], SHAPE[0])
            cam.set_trigger("software")
            for fmt in ("Mono8", "Mono16"):
                cam.set_pixel_format(fmt)
                cam.start()
                frames = [cam.capture(2.0) for _ in range(2)]
                cam.stop()
                facts[fmt] = [frame_facts(f) for f in frames]

    def c_errors(facts):
        with AravisCamera(config, name="fake") as cam:
            facts["mono12"] = str(expect_raises(CameraError, cam.set_pixel_format, "Mono12"))
            facts["exposure"] = str(expect_raises(CameraError, cam.set_exposure, 1000.0))
            facts["roi"] = str(expect_raises(CameraError, cam.set_roi, 0, 0, 100000, 8))
            facts["line"] = str(expect_raises(CameraError, cam.set_trigger, "line", "Line7"))
            cam.set_trigger("line", "Line0")
            expect_raises(CameraError, cam.read, 0.1)  # not started
        facts["open"] = str(
            expect_raises(CameraError, AravisCamera({"address": "NoSuchCamera", "interfaces": ["Fake"]}).open)
        )

    def c_timeout(facts):
        # Aravis' Fake stream ignores TriggerMode (it runs at 25 Hz when triggered), so the
        # timeout path is exercised free-running at 2 frames/s: two reads of 0.2 s back to
        # back cannot both get a frame. (A low rate also slows stop(): Aravis' Fake stream
        # thread sleeps until the next frame before it notices the stop.)
        with AravisCamera(config, name="fake") as cam:
            cam.set_trigger("free")
            cam._device.set_float_feature_value("AcquisitionFrameRate", 2.0)
            cam.start()
            outcomes = []
            for _ in range(2):
                t0 = time.monotonic()
                try:
                    cam.read(0.2)
                    outcomes.append("frame")
                except CameraTimeout as exc:
                    outcomes.append(f"timeout after {time.monotonic() - t0:.2f} s: {exc}")
            cam.stop()
            facts["outcomes"] = outcomes
            expect(any(o.startswith("timeout") for o in outcomes), f"no CameraTimeout: {outcomes}")

    def c_roi_beyond_sensor(facts):
        # The Fake camera's sensor (SensorWidth x SensorHeight, 2048 x 2048) is known once it is open: a roi
        # beyond it is refused then, before any capture file is made, and the camera is closed again.
        from rsocl.hardware.capture import capture_sets

        folder = workdir / "roi-beyond-sensor"
        folder.mkdir()
        (folder / "rig.toml").write_text(
            "\n".join(
                [
                    "[rig]",
                    f"shape = [{SHAPE[0]}, {SHAPE[1]}]",
                    "",
                    "[[camera]]",
                    'backend = "aravis"',
                    "angle = 0.0",
                    f"t_e = {EXPOSURE}",
                    "t_r = 4e-05",
                    f"roi = [2000, 0, {SHAPE[1]}, {SHAPE[0]}]",
                    "",
                    "[camera.config]",
                    'address = "Fake_1"',
                    'interfaces = ["Fake"]',
                    "",
                ]
            )
        )
        facts["refusal"] = str(expect_raises(ValueError, capture_sets, folder / "rig.toml", folder / "c.h5"))
        facts["files"] = sorted(p.name for p in folder.iterdir())
        with AravisCamera(config, name="fake") as cam:  # it opens again: the refusal closed it
            facts["sensor_size"] = list(cam.sensor_size)

    checks.run("discover", c_discover)
    checks.run("capture", c_capture)
    checks.run("errors", c_errors)
    checks.run("timeout", c_timeout)
    checks.run("roi_beyond_sensor", c_roi_beyond_sensor)
    return checks.results


# ---------------------------------------------------------------------- GigE Vision array
def _die_with_parent():
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def _udp_bound(address, port):
    want = "".join(f"{int(b):02X}" for b in reversed(address.split("."))) + f":{port:04X}"
    try:
        with open("/proc/net/udp") as fh:
            return any(line.split()[1] == want for line in fh.readlines()[1:])
    except OSError:
        return False


def start_fake_cameras(workdir, xml_for):
    """One ``arv-fake-gv-camera-0.8`` per address; ``xml_for(i)`` gives a GenICam file or None."""
    procs = []
    for i, address in enumerate(ADDRESSES):
        if address != "127.0.0.1":
            subprocess.run(["ip", "addr", "add", f"{address}/8", "dev", "lo"], check=True, timeout=5)
        args = [FAKE_GV, "-i", address, "-s", f"GV{i + 1:02d}"]
        xml = xml_for(i)
        if xml is not None:
            args += ["-g", str(xml)]
        log = open(workdir / f"fake-gv-{i + 1}.log", "wb")
        procs.append(
            subprocess.Popen(
                args, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, preexec_fn=_die_with_parent
            )
        )
        log.close()
    deadline = time.monotonic() + 10
    for address, proc in zip(ADDRESSES, procs):
        while not _udp_bound(address, 3956):
            if proc.poll() is not None:
                raise RuntimeError(f"{FAKE_GV} on {address} exited with {proc.returncode}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"{FAKE_GV} on {address} did not bind UDP port 3956 within 10 s")
            time.sleep(0.05)
    return procs


def stop_fake_cameras(procs):
    for proc in procs:
        if proc.poll() is None:
            proc.terminate()
    deadline = time.monotonic() + 3
    for proc in procs:
        try:
            proc.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


def modified_genicam(workdir):
    """The fake camera's own GenICam XML with SFNC ``ExposureTime``, ``Mono12`` and ``SensorReadoutTime``."""
    from rsocl_plugins.aravis_discovery import import_aravis

    Aravis, _ = import_aravis()
    Aravis.disable_interface("GigEVision")
    Aravis.disable_interface("USB3Vision")
    Aravis.enable_interface("Fake")
    xml = Aravis.Camera.new("Fake_1").get_device().get_genicam_xml()[0]
    Aravis.disable_interface("Fake")
    Aravis.enable_interface("GigEVision")
    for old, new in (
        ('<Float Name="ExposureTimeAbs"', '<Float Name="ExposureTime"'),
        ("<pFeature>ExposureTimeAbs</pFeature>", "<pFeature>ExposureTime</pFeature>"),
        (
            '<EnumEntry Name="Mono16" NameSpace="Standard">',
            '<EnumEntry Name="Mono12" NameSpace="Standard">\n\t\t\t<Value>17825797</Value>\n'
            '\t\t</EnumEntry>\n\t\t<EnumEntry Name="Mono16" NameSpace="Standard">',
        ),
        (
            "</RegisterDescription>",
            '\t<Float Name="SensorReadoutTime" NameSpace="Custom">\n'
            f"\t\t<Value>{READOUT_US}</Value>\n\t\t<Unit>us</Unit>\n\t</Float>\n</RegisterDescription>",
        ),
    ):
        if xml.count(old) != 1:
            raise RuntimeError(f"fake camera GenICam XML: expected one {old!r}, found {xml.count(old)}")
        xml = xml.replace(old, new)
    path = workdir / "fake-sfnc.xml"
    path.write_text(xml)
    return path


def write_rig(path, formats, interfaces):
    lines = ["[rig]", f"shape = [{SHAPE[0]}, {SHAPE[1]}]", "dt = 4e-05", ""]
    for i, (address, fmt) in enumerate(zip(ADDRESSES, formats)):
        lines += [
            "[[camera]]",
            'backend = "aravis"',
            f'name = "gv{i + 1}"',
            f"angle = {90.0 * i}",
            f"t_e = {EXPOSURE}",
            "t_r = 4e-05",
            f"roi = [0, 0, {SHAPE[1]}, {SHAPE[0]}]",
            f'pixel_format = "{fmt}"',
            "",
            "[camera.config]",
            f'address = "{address}"',
            f"interfaces = {json.dumps(interfaces)}",
            "buffers = 4",
            "",
        ]
    path.write_text("\n".join(lines))


def gige_checks(workdir):
    from rsocl.hardware.backend import CameraDisconnected, CameraTimeout
    from rsocl_plugins.aravis import AravisCamera
    from rsocl_plugins.aravis_discovery import discover, import_aravis

    import_aravis()
    checks = Checks()
    interfaces = ["GigEVision"]
    formats = ["Mono16", "Mono12", "Mono8", "Mono16"]
    xml = checks.run("genicam", lambda facts: modified_genicam(workdir))
    procs = []
    try:
        procs = checks.run("start", lambda facts: start_fake_cameras(workdir, lambda i: xml if i == 1 else None))
        if procs is None:
            return checks.results
        checks.results["start"]["ip_addr"] = subprocess.run(
            ["ip", "-o", "addr", "show"], capture_output=True, text=True, timeout=5
        ).stdout

        def c_discover(facts):
            devices = discover(interfaces)
            facts["devices"] = devices
            expect(sorted(d["address"] for d in devices) == ADDRESSES, f"devices found: {devices}")

        def c_array(facts):
            cams = [
                AravisCamera({"address": a, "interfaces": interfaces, "buffers": 4}, name=f"gv{i + 1}")
                for i, a in enumerate(ADDRESSES)
            ]
            try:
                for cam in cams:
                    cam.open()
                facts["info"] = [cam.device_info for cam in cams]
                facts["exposure"] = [cam.set_exposure(EXPOSURE) for cam in cams]
                for cam, fmt in zip(cams, formats):
                    cam.set_roi(0, 0, SHAPE[1], SHAPE[0])
                    cam.set_pixel_format(fmt)
                    cam.set_trigger("software")
                    cam.start()
                facts["readout_time"] = [cam.readout_time for cam in cams]
                # nothing is triggered yet: every camera must time out
                t0 = time.monotonic()
                expect_raises(CameraTimeout, cams[0].read, 0.3)
                facts["timeout_seconds"] = round(time.monotonic() - t0, 3)
                sets = []
                for _ in range(3):
                    for cam in cams:  # triggers back to back, as rsocl capture does
                        cam.trigger()
                    sets.append([frame_facts(cam.read(2.0)) for cam in cams])
                facts["sets"] = sets
                for cam in cams:  # exactly one frame per trigger: nothing left over
                    expect_raises(CameraTimeout, cam.read, 0.2)
            finally:
                for cam in cams:
                    cam.close()

        def c_capture(facts):
            try:
                from rsocl.hardware.capture import capture_sets
                from rsocl.hardware.capture_file import load_raw
            except ImportError as exc:
                facts["skipped"] = f"rsocl.hardware.capture not available: {exc}"
                return
            from rsocl.files.hdf5 import load_capture

            rig = workdir / "rig.toml"
            write_rig(rig, formats, interfaces)
            out = capture_sets(rig, workdir / "capture.h5", sets=2, timeout=2.0)
            raw = load_raw(out)
            cap = load_capture(out, set_index=0)
            facts.update(
                path=str(out),
                status=raw.status,
                sets_complete=raw.sets_complete,
                raw_shapes=[list(f.shape) for f in raw.frames],
                raw_dtypes=[str(f.dtype) for f in raw.frames],
                sets=[s.tolist() for s in raw.sets],
                frame_meta=[m[0] for m in raw.frame_meta],
                cameras=raw.meta.get("cameras"),
                warnings=raw.meta.get("warnings"),
                snapshot_sets=None if raw.snapshot_sets is None else list(raw.snapshot_sets.shape),
                snapshots=list(cap.snapshots.shape),
                rig_cameras=cap.rig.C,
            )
            import h5py

            with h5py.File(out, "r") as h5:
                facts["raw_attrs"] = [
                    {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in h5[f"raw/{i}"].attrs.items()}
                    for i in range(len(ADDRESSES))
                ]

        def c_disconnect(facts):
            # Camera 3 in software-trigger mode: its next register access (TriggerSoftware) times
            # out after Aravis' retries. Camera 4 free-running, only read: Aravis' heartbeat
            # raises control-lost. Both must end in CameraDisconnected, and stay there.
            sw = AravisCamera({"address": ADDRESSES[2], "interfaces": interfaces}, name="gv3")
            free = AravisCamera({"address": ADDRESSES[3], "interfaces": interfaces}, name="gv4")
            try:
                for cam, mode in ((sw, "software"), (free, "free")):
                    cam.open()
                    cam.set_trigger(mode)
                    cam.start()
                    facts[f"before_{cam.name}"] = list(cam.capture(2.0).image.shape)
                for proc in procs[2:]:
                    proc.kill()
                for proc in procs[2:]:
                    proc.wait(timeout=5)
                t0 = time.monotonic()
                facts["trigger_error"] = str(expect_raises(CameraDisconnected, sw.trigger))
                facts["trigger_detected_after"] = round(time.monotonic() - t0, 3)
                expect_raises(CameraDisconnected, sw.read, 0.1)  # stays gone
                timeouts = 0
                while True:
                    try:
                        free.read(0.5)
                    except CameraDisconnected as exc:
                        facts["read_error"] = str(exc)
                        break
                    except CameraTimeout:
                        timeouts += 1
                    if time.monotonic() - t0 > 20:
                        raise AssertionError(f"no CameraDisconnected from reads within 20 s ({timeouts} timeouts)")
                facts["read_detected_after"] = round(time.monotonic() - t0, 3)
                facts["timeouts_before"] = timeouts
                expect_raises(CameraDisconnected, free.trigger)
            finally:
                t1 = time.monotonic()
                sw.close()  # must not raise for a lost device
                free.close()
                facts["close_seconds"] = round(time.monotonic() - t1, 3)

        checks.run("discover", c_discover)
        checks.run("array", c_array)
        checks.run("capture", c_capture)
        checks.run("disconnect", c_disconnect)
    finally:
        stop_fake_cameras(procs or [])
        checks.results["stopped"] = {
            "ok": all(p.poll() is not None for p in procs or []),
            "returncodes": [p.returncode for p in procs or []],
            "error": None,
        }
    return checks.results


def main(argv):
    if len(argv) != 3 or argv[1] not in ("fake", "gige"):
        sys.stderr.write(f"usage: {argv[0]} fake|gige WORKDIR\n")
        return 2
    require_private_netns()
    workdir = Path(argv[2])
    workdir.mkdir(parents=True, exist_ok=True)
    # Before any Aravis discovery: only the interfaces the check needs.
    from rsocl_plugins.aravis_discovery import import_aravis

    Aravis, _ = import_aravis()
    Aravis.disable_interface("USB3Vision")
    if argv[1] == "fake":
        Aravis.disable_interface("GigEVision")
        Aravis.enable_interface("Fake")
        results = fake_checks(workdir)
    else:
        Aravis.disable_interface("Fake")
        results = gige_checks(workdir)
    results["netns"] = {
        "ok": network_interfaces() == ["lo"],
        "interfaces": network_interfaces(),
        "ip_link": ip_link(),
        "error": None,
    }
    sys.stdout.write("\n" + json.dumps(results, default=repr) + "\n")
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
