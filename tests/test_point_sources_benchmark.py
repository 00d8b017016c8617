"""``benchmarks/point_sources.py``: its scenes (a point at the centre, static and moving points) and its usage."""

import subprocess
import sys
from pathlib import Path

import numpy as np

import rsocl

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))

import point_sources  # noqa: E402


def _rig():
    return rsocl.Rig.paper_array(2, (16, 16), t_e=point_sources.T_E, t_r=point_sources.T_R)


def test_static_point_at_the_centre_holds_every_sub_frame():
    rig = _rig()
    cube = point_sources.point_scene(rig, 1, 0.0, True)
    assert cube.shape == (rig.T, 16, 16)
    assert np.all(cube[:, 8, 8] == 1.0)
    assert cube.sum() == rig.T


def test_moving_points_move_and_keep_one_pixel_each():
    rig = _rig()
    cube = point_sources.point_scene(rig, 3, 0.3, False, seed=1)
    assert np.all(cube.sum(axis=(1, 2)) <= 3) and np.all(cube.sum(axis=(1, 2)) >= 1)
    assert not np.array_equal(cube[0], cube[-1])
    assert not np.array_equal(cube, point_sources.point_scene(rig, 3, 0.3, False, seed=2))


def test_help_names_the_options():
    done = subprocess.run(
        [sys.executable, str(BENCH / "point_sources.py"), "--help"], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "--seeds" in done.stdout and "--out" in done.stdout
