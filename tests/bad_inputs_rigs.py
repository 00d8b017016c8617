"""Bad rig files, calibration inputs and simulate/plan options (table of tests/test_bad_inputs.py)."""

import numpy as np

from test_bad_inputs import Bad

CAMERA0 = 'backend = "simulated"\nangle = 0.0\nt_e = 1.8e-04\nt_r = 3.5e-05\n'
CAMERA1 = 'backend = "simulated"\nangle = 90.0\nt_e = 1.8e-04\nt_r = 3.5e-05\n'


def _rig_text(rig="shape = [8, 8]\n", camera0=CAMERA0, camera1=CAMERA1, extra=""):
    return f"[rig]\n{rig}\n[[camera]]\n{camera0}\n[[camera]]\n{camera1}{extra}"


def _writes(name="rig.toml", **parts):
    def setup(tmp):
        (tmp / name).write_text(_rig_text(**parts), encoding="utf-8")

    return setup


def _capture(name="rig.toml"):
    return ["capture", "--rig", "{tmp}/" + name, "--out", "{tmp}/cap.h5"]


def _config(table):
    """A rig file whose camera 1 has ``table`` (TOML lines) as its [camera.config]."""
    return _writes(extra=f"\n[camera.config]\n{table}\n")


def _binary(tmp):
    (tmp / "rig.toml").write_bytes(b"\x89HDF\r\n\x1a\n\x00\xff" + bytes(range(200)))


def _outside(tmp):
    np.save(tmp / "rows.npy", np.zeros((8, 8)))
    (tmp / "sub").mkdir()
    (tmp / "sub" / "rig.toml").write_text(
        _rig_text(camera1=CAMERA1.replace("angle = 90.0", 'row_map_file = "../rows.npy"'))
    )


def _absolute(tmp):
    np.save(tmp / "rows.npy", np.zeros((8, 8)))
    (tmp / "rig.toml").write_text(
        _rig_text(camera1=CAMERA1.replace("angle = 90.0", f'row_map_file = "{tmp / "rows.npy"}"'))
    )


REF = np.array([[2.0, 2.0], [13.0, 2.0], [13.0, 13.0], [2.0, 13.0]])
REF_ARG = ";".join(f"{x:g},{y:g}" for x, y in REF)


def _markers(order1=(0, 1, 2, 3)):
    """A 2-camera rig file (16 x 16) and a --frames file whose camera 1 markers come in ``order1``."""

    def setup(tmp):
        (tmp / "rig.toml").write_text(_rig_text(rig="shape = [16, 16]\n", camera1=CAMERA0))
        np.savez(tmp / "markers.npz", frames=np.zeros((2, 16, 16)), markers=np.stack([REF, REF[list(order1)]]))

    return setup


def _calibrate(*extra):
    return ["calibrate", "--rig", "{tmp}/rig.toml", "--frames", "{tmp}/markers.npz", "--markers-ref", REF_ARG, *extra]


def _rigfile_api(**camera):
    def call(tmp):
        from rsocl.files.rigfile import RigFile

        cam = {"backend": "simulated", "t_e": 1.8e-4, "t_r": 3.5e-5, **camera}
        return RigFile(shape=(8, 8), cameras=[cam])

    return call


def _load(name):
    def call(tmp):
        from rsocl.files.rigfile import load_rigfile

        return load_rigfile(tmp / name)

    return call


CASES = [
    # keys in the wrong table
    Bad("rig-config-angle", ["camera[1].config.angle", "[[camera]]"], argv=_capture(), setup=_config("angle = 90.0")),
    Bad("rig-config-t_e", ["camera[1].config.t_e", "[[camera]]"], argv=_capture(), setup=_config("t_e = 1e-4")),
    Bad("rig-config-t_r", ["camera[1].config.t_r", "[[camera]]"], argv=_capture(), setup=_config("t_r = 3e-5")),
    Bad("rig-config-dt", ["camera[1].config.dt", "[rig]"], argv=_capture(), setup=_config("dt = 3.5e-5")),
    Bad("rig-config-shape", ["camera[1].config.shape", "[rig]"], argv=_capture(), setup=_config("shape = [8, 8]")),
    Bad(
        "rig-config-scene_frames", ["camera[1].config.scene_frames"], argv=_capture(), setup=_config("scene_frames = 5")
    ),
    Bad(
        "rig-config-unknown-sensor-option",
        ["read_nois", "read_noise"],
        argv=_capture(),
        setup=_config("[camera.config.sensor]\nread_nois = 0.1"),
        rc=2,
    ),
    Bad(
        "api-rigfile-config-angle",
        ["camera[0].config.angle", "[[camera]]"],
        api=_rigfile_api(angle=0.0, config={"angle": 90.0}),
    ),
    Bad(
        "rig-dt-in-camera", ["camera[0].dt", "[rig]"], argv=_capture(), setup=_writes(camera0=CAMERA0 + "dt = 3.5e-5\n")
    ),
    Bad(
        "rig-t_e-in-rig", ["rig.t_e", "[[camera]]"], argv=_capture(), setup=_writes(rig="shape = [8, 8]\nt_e = 1e-4\n")
    ),
    Bad(
        "rig-scene-in-camera",
        ["scene", "[camera.config]"],
        argv=_capture(),
        setup=_writes(camera0=CAMERA0 + 'scene = "builtin"\n'),
    ),
    # unknown keys and tables
    Bad(
        "rig-unknown-camera-key",
        ["camera[1]", "exposure"],
        argv=_capture(),
        setup=_writes(camera1=CAMERA1 + "exposure = 1e-4\n"),
    ),
    Bad("rig-unknown-rig-key", ["[rig]", "fps"], argv=_capture(), setup=_writes(rig="shape = [8, 8]\nfps = 30\n")),
    Bad(
        "rig-unknown-top-level-table",
        ["unknown top-level", "cameras"],
        argv=_capture(),
        setup=_writes(extra="\n[cameras]\nx = 1\n"),
    ),
    Bad(
        "rig-missing-rig-table",
        ["[rig]", "shape"],
        argv=_capture(),
        setup=lambda tmp: (tmp / "rig.toml").write_text("[[camera]]\n" + CAMERA0),
    ),
    Bad(
        "rig-no-camera",
        ["[[camera]]"],
        argv=_capture(),
        setup=lambda tmp: (tmp / "rig.toml").write_text("[rig]\nshape = [8, 8]\n"),
    ),
    # units and types
    Bad(
        "rig-t_e-negative",
        ["camera[0].t_e", "> 0 seconds"],
        argv=_capture(),
        setup=_writes(camera0=CAMERA0.replace("t_e = 1.8e-04", "t_e = -1.8e-04")),
    ),
    Bad(
        "rig-t_r-string",
        ["camera[0].t_r"],
        argv=_capture(),
        setup=_writes(camera0=CAMERA0.replace("t_r = 3.5e-05", 't_r = "35 us"')),
    ),
    Bad(
        "rig-t_e-missing",
        ["camera[1].t_e", "required"],
        argv=_capture(),
        setup=_writes(camera1=CAMERA1.replace("t_e = 1.8e-04\n", "")),
    ),
    Bad(
        "rig-angle-string",
        ["camera[1].angle"],
        argv=_capture(),
        setup=_writes(camera1=CAMERA1.replace("angle = 90.0", 'angle = "ninety"')),
    ),
    Bad("rig-shape-one-value", ["rig.shape", "2 integers"], argv=_capture(), setup=_writes(rig="shape = [8]\n")),
    Bad("rig-mask-unknown", ["rig.mask"], argv=_capture(), setup=_writes(rig='shape = [8, 8]\nmask = "fuzzy"\n')),
    Bad("rig-dt-below-row-time", ["dt", "t_r"], argv=_capture(), setup=_writes(rig="shape = [8, 8]\ndt = 1e-6\n")),
    Bad(
        "rig-two-geometries",
        ["camera[1]", "angle", "homography"],
        argv=_capture(),
        setup=_writes(camera1=CAMERA1 + "homography = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n"),
    ),
    Bad("rig-frames-without-t_d", ["t_d", "frames"], argv=_capture(), setup=_writes(camera1=CAMERA1 + "frames = 2\n")),
    # ROI
    Bad(
        "rig-roi-three-values",
        ["camera[1].roi", "x, y, width, height"],
        argv=_capture(),
        setup=_writes(camera1=CAMERA1 + "roi = [0, 0, 8]\n"),
    ),
    Bad(
        "rig-roi-zero-width",
        ["camera[1].roi", "[2] must be an integer >= 1"],
        argv=_capture(),
        setup=_writes(camera1=CAMERA1 + "roi = [0, 0, 0, 8]\n"),
    ),
    Bad(
        "plan-roi-outside-the-grid",
        ["--roi is X Y WIDTH HEIGHT", "got 0 0 8 24"],
        argv=["plan", "--shape", "16", "32", "--roi", "0", "0", "8", "24", "--no-measure"],
    ),
    # files
    Bad("rig-binary-file", ["rig.toml", "not a TOML rig file"], argv=_capture(), setup=_binary),
    Bad("api-rig-binary-file", ["not a TOML rig file", "offset 0"], api=_load("rig.toml"), setup=_binary),
    Bad("rig-file-missing", ["rig file", "nothing.toml"], argv=_capture("nothing.toml")),
    Bad(
        "rig-row-map-file-dotdot",
        ["camera[1].row_map_file", "rig file's folder"],
        argv=_capture("sub/rig.toml"),
        setup=_outside,
    ),
    Bad("rig-row-map-file-absolute", ["camera[1].row_map_file", "absolute"], argv=_capture(), setup=_absolute),
    # calibration
    Bad(
        "calibrate-swapped-markers",
        ["camera 1", "markers 1 (13,2) and 2 (13,13) look swapped"],
        argv=_calibrate(),
        setup=_markers((0, 2, 1, 3)),
    ),
    Bad(
        "calibrate-markers-a-turn-apart",
        ["camera 1", "camera[1].angle = 0"],
        argv=_calibrate(),
        setup=_markers((1, 2, 3, 0)),
    ),
    Bad(
        "calibrate-mirrored-out-of-range",
        ["--mirrored", "[0, 1]", "[5]"],
        argv=_calibrate("--mirrored", "5"),
        setup=_markers(),
    ),
    Bad(
        "calibrate-mirrored-camera-is-not",
        ["camera 1", "not in a mirror"],
        argv=_calibrate("--mirrored", "1"),
        setup=_markers(),
    ),
    # simulate
    Bad(
        "simulate-frames-zero",
        ["--frames", ">= 1"],
        argv=["simulate", "builtin", "--shape", "8", "8", "--frames", "0", "--out", "{tmp}/s.h5"],
    ),
    Bad(
        "simulate-t-d-without-frames",
        ["--t-d-us", "--frames"],
        argv=["simulate", "builtin", "--shape", "8", "8", "--t-d-us", "300", "--out", "{tmp}/s.h5"],
    ),
    Bad(
        "simulate-t-d-too-short",
        ["--t-d-us 1", "t_d must be >="],
        argv=["simulate", "builtin", "--shape", "8", "8", "--frames", "2", "--t-d-us", "1", "--out", "{tmp}/s.h5"],
    ),
    Bad(
        "simulate-frames-beyond-a-rig",
        ["--frames 100000000", "sub-frames"],
        argv=["simulate", "builtin", "--shape", "8", "8", "--frames", "100000000", "--out", "{tmp}/s.h5"],
    ),
    Bad(
        "simulate-frames-beyond-memory",
        ["--frames 2000000", "host memory"],
        argv=[
            "simulate",
            "builtin",
            "--shape",
            "512",
            "512",
            "--t-r-us",
            "1",
            "--t-e-us",
            "1",
            "--dt-us",
            "512",
            "--frames",
            "2000000",
            "--out",
            "{tmp}/s.h5",
        ],
    ),
    Bad(
        "simulate-t-d-negative",
        ["--t-d-us", "> 0"],
        argv=["simulate", "builtin", "--shape", "8", "8", "--frames", "2", "--t-d-us", "-5", "--out", "{tmp}/s.h5"],
    ),
]
