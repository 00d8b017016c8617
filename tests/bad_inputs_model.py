"""Bad rigs, times in the wrong unit, memory bombs and solver values that cannot run (table of
tests/test_bad_inputs.py). The sizes are beyond any machine's memory (terabytes), so that every case
fails the same way everywhere."""

import json

import numpy as np

import rsocl

from test_bad_inputs import Bad

T_E, T_R = 1.8e-4, 3.5e-5


def _small():
    return rsocl.Rig.paper_array(4, (8, 8), T_E, T_R)


def _reconstruct(**kw):
    def run(tmp):
        rig = _small()
        g = rsocl.RollingShutterOperator(rig).forward(np.full((rig.T,) + rig.shape, 0.5))
        return rsocl.reconstruct(g, rig, tune=False, **kw)

    return run


def _batch_result():
    rig = _small()
    g = rsocl.RollingShutterOperator(rig).forward(np.full((2, rig.T) + rig.shape, 0.5))
    return rsocl.reconstruct(g, rig, tune=False, iterations=2)


def _capture(tmp, shape=None, row_map_shape=None):
    """``tmp/cap.h5``: a capture of a 2-camera 8x8 rig whose stored rig claims ``shape`` or whose stored row
    map claims ``row_map_shape`` (written sparse: the file stays small)."""
    import h5py

    from rsocl.files.hdf5 import save_capture

    rows = rsocl.Camera(0, t_e=T_E, t_r=T_R).rows((8, 8))
    rig = rsocl.Rig([rsocl.Camera(90, t_e=T_E, t_r=T_R), rsocl.Camera(t_e=T_E, t_r=T_R, row_map=rows)], (8, 8))
    save_capture(tmp / "cap.h5", np.zeros((2, 8, 8)), rig)
    with h5py.File(tmp / "cap.h5", "r+") as h5:
        if shape is not None:
            data = json.loads(h5.attrs["rig"])
            data["shape"] = list(shape)
            h5.attrs["rig"] = json.dumps(data)
        if row_map_shape is not None:
            del h5["rig_row_maps/1"]
            h5.create_dataset("rig_row_maps/1", shape=row_map_shape, dtype="f8", chunks=(64, 64))


def _npy(path, shape):
    """A .npy file whose header claims ``shape`` (float64), holding 8 bytes of data."""
    with open(path, "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False, "shape": shape})
        fh.write(b"\0" * 8)


def _rig_file(tmp, shape="[8, 8]", camera="t_e = 1.8e-4\nt_r = 3.5e-5\n"):
    (tmp / "rig.toml").write_text(f'[rig]\nshape = {shape}\n\n[[camera]]\nbackend = "simulated"\n{camera}')


def _load_video(tmp):
    from rsocl.model.scenes import load_video

    return load_video(tmp / "video.npy")


def _huge_batch(tmp):
    rig = rsocl.Rig.paper_array(1, (2000, 2000), t_e=0.9, t_r=T_R)  # T = 27,714 sub-frames
    return rsocl.reconstruct(np.zeros((10, 1, 2000, 2000), np.float32), rig, tune=False)  # 4.4 TB of datacubes


CASES = [
    # times in the wrong unit
    Bad(
        "api-t-e-in-us-as-seconds",
        ["cameras[0].t_e = 180 s", "did you mean 180 µs"],
        api=lambda tmp: rsocl.Rig.paper_array(4, shape=(64, 64), t_e=180, t_r=35e-6),
    ),
    Bad(
        "api-t-e-one-hour",
        ["cameras[1].t_e", "sub-frames", "seconds"],
        api=lambda tmp: rsocl.Rig([rsocl.Camera(0, t_e=T_E, t_r=T_R), rsocl.Camera(0, t_e=3600, t_r=T_R)], (8, 8)),
    ),
    Bad(
        "api-t-a-in-us-as-seconds",
        ["cameras[0].t_a = 1000 s", "sub-frames"],
        api=lambda tmp: rsocl.Rig([rsocl.Camera(0, t_e=T_E, t_r=T_R, t_a=1000)], (8, 8)),
    ),
    Bad("api-t-e-negative", ["t_e", "> 0"], api=lambda tmp: rsocl.Camera(0, t_e=-1.8e-4, t_r=T_R)),
    Bad("api-t-r-missing", ["t_r"], api=lambda tmp: rsocl.Camera(0, t_e=T_E)),
    Bad("api-dt-below-t-r", ["dt", "t_r"], api=lambda tmp: rsocl.Rig.paper_array(4, (8, 8), T_E, T_R, dt=1e-6)),
    Bad("api-frames-zero", ["frames", ">= 1"], api=lambda tmp: rsocl.Camera(0, t_e=T_E, t_r=T_R, frames=0)),
    Bad("api-camera-fps-zero", ["camera_fps", "> 0"], api=lambda tmp: _small().effective_fps(0)),
    Bad(
        "cli-capture-rig-file-t-e-100-s",
        ["t_e = 100 s", "did you mean 100 µs"],
        argv=["capture", "--rig", "{tmp}/rig.toml", "--out", "{tmp}/c.h5"],
        setup=lambda tmp: _rig_file(tmp, camera="t_e = 100\nt_r = 3.5e-5\n"),
    ),
    Bad("cli-info-t-e-us-absurd", ["--t-e-us", "give the exposure in µs"], argv=["info", "--t-e-us", "1e12"]),
    # memory bombs: the API, a capture's stored rig, .npy files, rig files
    Bad(
        "api-rig-shape-beyond-memory",
        ["shape (1000000, 1000000)", "host memory"],
        api=lambda tmp: rsocl.Rig.paper_array(4, (10**6, 10**6), T_E, T_R),
    ),
    Bad(
        "api-reconstruct-batch-beyond-memory",
        ["rig shape 2000x2000 and T = ", "10 sets", "host memory"],
        api=_huge_batch,
    ),
    Bad(
        "api-stored-rig-shape-beyond-memory",
        ["cap.h5", "stored rig", "shape (100000, 100000)", "host memory"],
        api=lambda tmp: __import__("rsocl.files.hdf5", fromlist=["x"]).load_capture_rig(tmp / "cap.h5"),
        setup=lambda tmp: _capture(tmp, shape=(100000, 100000)),
    ),
    Bad(
        "cli-info-stored-rig-beyond-memory",
        ["cap.h5", "shape (100000, 100000)", "host memory"],
        argv=["info", "--capture", "{tmp}/cap.h5"],
        setup=lambda tmp: _capture(tmp, shape=(100000, 100000)),
    ),
    Bad(
        "cli-reconstruct-stored-rig-beyond-memory",
        ["cap.h5", "shape (100000, 100000)", "host memory"],
        argv=["reconstruct", "{tmp}/cap.h5", "--out", "{tmp}/r.h5"],
        setup=lambda tmp: _capture(tmp, shape=(100000, 100000)),
    ),
    Bad(
        "api-stored-row-map-beyond-memory",
        ["cap.h5", "rig_row_maps/1", "host memory"],
        api=lambda tmp: __import__("rsocl.files.hdf5", fromlist=["x"]).load_capture(tmp / "cap.h5"),
        setup=lambda tmp: _capture(tmp, row_map_shape=(500000, 500000)),
    ),
    Bad(
        "api-npy-video-of-1e11-elements",
        ["path", "video.npy", "100,000,000,000 elements", "host memory"],
        api=_load_video,
        setup=lambda tmp: _npy(tmp / "video.npy", (10, 100000, 100000)),
    ),
    Bad(
        "api-npy-video-truncated",
        ["path", "video.npy", "truncated or damaged"],
        api=_load_video,
        setup=lambda tmp: _npy(tmp / "video.npy", (4, 32, 32)),
    ),
    Bad(
        "cli-simulate-npy-of-1e11-elements",
        ["video.npy", "host memory"],
        argv=["simulate", "{tmp}/video.npy", "--out", "{tmp}/s.h5"],
        setup=lambda tmp: _npy(tmp / "video.npy", (10, 100000, 100000)),
    ),
    Bad(
        "cli-capture-row-map-file-of-1e11-elements",
        ["row_map_file", "rows.npy", "host memory"],
        argv=["capture", "--rig", "{tmp}/rig.toml", "--out", "{tmp}/c.h5"],
        setup=lambda tmp: (
            _npy(tmp / "rows.npy", (10, 100000, 100000)),
            _rig_file(tmp, camera='row_map_file = "rows.npy"\nt_e = 1.8e-4\nt_r = 3.5e-5\n'),
        ),
    ),
    Bad(
        "cli-capture-rig-file-shape-beyond-memory",
        ["shape = [1000000, 1000000]", "host memory"],
        argv=["capture", "--rig", "{tmp}/rig.toml", "--out", "{tmp}/c.h5"],
        setup=lambda tmp: _rig_file(tmp, shape="[1000000, 1000000]"),
    ),
    # solver values that cannot run
    Bad(
        "api-eta-that-never-moves",
        ["never moved", "eta = 1e+30", "lam = 0.1", "choose eta"],
        api=_reconstruct(eta=1e30, lam=0.1),
        errors=(FloatingPointError,),
    ),
    Bad(
        "cli-demo-eta-that-never-moves",
        ["never moved", "eta = 1e+30"],
        argv=["demo", "--fast", "--eta", "1e30", "--shape", "8", "8", "--quiet", "--out", "{tmp}/d"],
    ),
    Bad("api-eta-negative", ["eta"], api=_reconstruct(eta=-0.2)),
    Bad("api-lam-nan", ["lam"], api=_reconstruct(lam=float("nan"))),
    Bad("api-projection-unknown", ["projection", "exact", "paper"], api=_reconstruct(projection="diagonal")),
    Bad("api-saturation-negative", ["saturation", "> 0"], api=_reconstruct(saturation=-1.0)),
    # the small public helpers name their parameter too
    Bad("row-map-camera-out-of-range", ["camera", "[0, 3]"], api=lambda tmp: _small().row_map(9)),
    Bad("row-map-roi-outside-the-grid", ["roi", "8x8"], api=lambda tmp: _small().row_map(0, (6, 6, 5, 5))),
    Bad("simulate-without-a-rig", ["rig", "rsocl.Rig"], api=lambda tmp: rsocl.simulate(np.zeros((13, 8, 8)), None)),
    Bad(
        "operator-subframes-not-a-slice",
        ["subframes", "slice"],
        api=lambda tmp: rsocl.RollingShutterOperator(_small(), subframes=3),
    ),
    Bad(
        "ragged-row-map",
        ["row_map", "rectangular"],
        api=lambda tmp: rsocl.Camera(t_e=T_E, t_r=T_R, row_map=[[0.0, 1.0], [2.0]]),
    ),
    Bad("result-set-not-an-integer", ["index", "integer"], api=lambda tmp: _batch_result().set(1.5)),
]
