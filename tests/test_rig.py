import math

import numpy as np
import pytest

from rsocl import Camera, Rig
from rsocl.model.rig import PAPER_ANGLES


def test_paper_simulation_figures():
    rig = Rig.paper_array(4, (50, 50), t_e=0.18e-3, t_r=35e-6)
    # docs/model.md: T = ceil(max end / dt) with dt = t_r; the last row starts at 49 t_r.
    assert rig.T == math.ceil((49 * 35e-6 + 0.18e-3) / 35e-6) == 55
    assert rig.N_s == 6
    assert rig.exposure_subframes == pytest.approx(0.18e-3 / 35e-6)  # 5.14, the exact rule
    assert rig.dt == 35e-6
    assert rig.compression_ratio == rig.T_se / 4
    assert rig.effective_fps(67.0) == pytest.approx(67.0 * rig.T_se)


def test_paper_experiment_exposure_count():
    # docs/model.md's formula N_s = ceil(t_e / t_r); 200/26 = 7.7 (the paper quotes 7 for its capture)
    rig = Rig.paper_array(4, (50, 50), t_e=200e-6, t_r=26e-6)
    assert rig.N_s == math.ceil(200 / 26) == 8


@pytest.mark.parametrize(
    "angle, expected",
    [
        (0, lambda y, x, m, n: y),
        (90, lambda y, x, m, n: x),
        (180, lambda y, x, m, n: m - 1 - y),
        (270, lambda y, x, m, n: n - 1 - x),
    ],
)
def test_row_maps_of_the_four_orientations(angle, expected):
    m, n = 5, 7
    r = Camera(angle, t_e=1e-4, t_r=1e-5).rows((m, n))
    y, x = np.mgrid[:m, :n]
    np.testing.assert_array_equal(r, expected(y, x, m, n))


def test_oblique_row_map_starts_at_zero():
    r = Camera(45, t_e=1e-4, t_r=1e-5).rows((4, 4))
    assert r.min() == 0
    assert r[0, 0] == 0 and r[-1, -1] == pytest.approx(3 * math.sqrt(2))


def test_paper_angle_order():
    rig = Rig.paper_array(8, (6, 6), t_e=1e-4, t_r=1e-5)
    assert [c.angle for c in rig.cameras] == list(PAPER_ANGLES)


def test_start_times_and_windows():
    cam = Camera(0, t_e=1e-4, t_r=2e-5, t_a=3e-5)
    rig = Rig([cam], (4, 2), dt=4e-5)
    start = rig.start_times()
    np.testing.assert_allclose(start[0, :, 0], 3e-5 + 2e-5 * np.arange(4))
    w = rig.windows
    np.testing.assert_allclose(w.index + w.fraction, start / 4e-5, atol=1e-12)
    assert rig.T == math.ceil((3e-5 + 3 * 2e-5 + 1e-4) / 4e-5)
    assert rig.window_length == math.ceil(1e-4 / 4e-5) + 1


def test_exact_multiple_exposure_has_integer_edges():
    # t_e = 3 t_r: floating point must not create a spurious extra sub-frame
    rig = Rig.paper_array(1, (10, 3), t_e=3 * 35e-6, t_r=35e-6)
    assert rig.T == 9 + 3
    assert np.all(rig.windows.fraction == 0)


def test_multi_frame_channels_and_t_d_rule():
    cam = Camera(0, t_e=1e-4, t_r=1e-5, frames=2, t_d=2e-4)
    rig = Rig([cam, Camera(90, t_e=1e-4, t_r=1e-5)], (10, 10))
    assert rig.n_channels == 3 and rig.channels == [(0, 0), (0, 1), (1, 0)]
    np.testing.assert_allclose(rig.start_times()[1] - rig.start_times()[0], 2e-4)
    with pytest.raises(ValueError, match="t_d"):
        # needs t_d >= 10 rows * 1e-5 - 2e-5 = 8e-5 s
        Rig([Camera(0, t_e=2e-5, t_r=1e-5, frames=2, t_d=7e-5)], (10, 10))
    Rig([Camera(0, t_e=2e-5, t_r=1e-5, frames=2, t_d=8e-5)], (10, 10))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(t_e=1e-4, t_r=0), "t_r"),
        (dict(t_e=-1, t_r=1e-5), "t_e"),
        (dict(t_e=float("nan"), t_r=1e-5), "t_e"),
        (dict(t_e=1e-4, t_r=float("inf")), "t_r"),
        (dict(t_e=1e-4, t_r=1e-5, t_a=-1e-6), "t_a"),
        (dict(t_e=1e-4, t_r=1e-5, gain=0), "gain"),
        (dict(t_e=1e-4, t_r=1e-5, frames=0), "frames"),
        (dict(t_e=1e-4, t_r=1e-5, frames=2), "t_d"),
        (dict(t_e=1e-4), "t_r"),
    ],
)
def test_camera_validation_names_the_parameter(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Camera(0, **kwargs)


def test_rig_validation():
    cam = Camera(0, t_e=1e-4, t_r=1e-5)
    with pytest.raises(ValueError, match="dt must be >= t_r"):
        Rig([cam], (4, 4), dt=5e-6)
    with pytest.raises(ValueError, match=r"shape\[0\]"):
        Rig([cam], (0, 4))
    with pytest.raises(ValueError, match="shape"):
        Rig([cam], 4)
    with pytest.raises(ValueError, match="mask"):
        Rig([cam], (4, 4), mask="soft")
    with pytest.raises(ValueError, match="cameras"):
        Rig([], (4, 4))
    with pytest.raises(ValueError, match="n_cameras"):
        Rig.paper_array(9, (4, 4))
    with pytest.raises(ValueError, match="row_map"):
        Rig([Camera(t_e=1e-4, t_r=1e-5, row_map=np.zeros((3, 3)))], (4, 4))
    with pytest.raises(ValueError, match="row_map"):
        Camera(t_e=1e-4, t_r=1e-5, row_map=np.full((3, 3), np.nan))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(t_e=1e-4, t_r=35e-6, t_a=1e3), r"cameras\[1\].t_a = 1000 s makes the rig span T = 28,571,\d+ sub-frames"),
        (dict(t_e=1e-4, t_r=35e-6, frames=3, t_d=400), r"cameras\[1\].t_d x \(frames - 1\) = 800 s makes the rig span"),
        (dict(t_e=1e-4, t_r=1e3), r"cameras\[1\].t_r x its 7 rows = 7000 s makes the rig span"),
    ],
)
@pytest.mark.filterwarnings("ignore:camera t_[rad] = .* is longer than 1:UserWarning")  # on purpose
def test_a_time_that_makes_T_absurd_is_refused_naming_it_and_T(kwargs, match):
    from rsocl.model.rig import MAX_T

    with pytest.raises(ValueError, match=match) as info:
        Rig([Camera(0, t_e=1e-4, t_r=35e-6), Camera(0, **kwargs)], (8, 8), dt=35e-6)
    assert f"above the {MAX_T:,} a rig may span" in str(info.value)
    assert Rig([Camera(0, t_e=1e-5, t_r=1e-5, t_a=(MAX_T - 1) * 1e-5)], (1, 1)).T == MAX_T  # the bound is allowed


def test_dt_binning_reduces_T():
    fine = Rig.paper_array(4, (40, 40), t_e=0.18e-3, t_r=35e-6)
    coarse = Rig.paper_array(4, (40, 40), t_e=0.18e-3, t_r=35e-6, dt=70e-6)
    assert coarse.T == math.ceil((39 * 35e-6 + 0.18e-3) / 70e-6) < fine.T


def test_trimming_drops_subframes_few_cameras_sample():
    # Two cameras, one delayed by 20 rows: the first 20 sub-frames only see camera 0.
    cams = [Camera(0, t_e=1e-4, t_r=1e-5), Camera(0, t_e=1e-4, t_r=1e-5, t_a=2e-4)]
    rig = Rig(cams, (30, 4))
    counts = rig.cameras_per_subframe()
    assert counts.max() == 2 and rig.min_cameras == 1
    assert rig.T_se == rig.T  # ceil(2/2) = 1 camera suffices
    rig4 = Rig(cams + [Camera(0, t_e=1e-4, t_r=1e-5, t_a=4e-4)], (30, 4))
    kept = rig4.kept_subframes()
    assert rig4.min_cameras == 2
    counts = rig4.cameras_per_subframe()
    assert counts[kept.start] >= 2 and counts[kept.stop - 1] >= 2
    assert np.all(counts[: kept.start] < 2) and np.all(counts[kept.stop :] < 2)
    assert (kept.start, kept.stop) == (20, 59)  # camera 0 alone before, camera 2 alone after
    assert rig4.T_se == 39 < rig4.T


def test_dict_round_trip_is_exact():
    cams = [
        Camera(33.3, t_e=1.1e-4, t_r=2.7e-5, t_a=1e-6, gain=1.2),
        Camera(t_e=1e-4, t_r=2e-5, row_map=np.arange(12.0).reshape(3, 4)),
    ]
    rig = Rig(cams, (3, 4), dt=3e-5, mask="binary")
    again = Rig.from_dict(rig.to_dict())
    assert again == rig
    np.testing.assert_array_equal(again.start_times(), rig.start_times())
