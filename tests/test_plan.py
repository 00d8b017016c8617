import numpy as np
import pytest

import rsocl
from rsocl.cli.main import main
from rsocl.solver.plan import plan


def test_crop_keeps_real_start_times():
    rig = rsocl.Rig.paper_array(4, (20, 30), t_e=1e-4, t_r=3e-5)
    sub = rig.crop((5, 7, 6, 8))
    np.testing.assert_array_equal(sub.start_times(), rig.start_times()[:, 5:11, 7:15])
    # only the sub-frames the crop's rows are read in are solved
    assert sub.sampled_range().stop - sub.sampled_range().start < rig.T
    with pytest.raises(ValueError, match="roi"):
        rig.crop((15, 0, 10, 5))
    with pytest.raises(ValueError, match=r"roi must be \(y, x, height, width\), 4 whole numbers of pixels"):
        rig.crop((2.7, 1.2, 2, 2))  # not cut to (2, 1, 2, 2)
    assert rig.crop(np.array([5.0, 7, 6, 8])).shape == (6, 8)


def test_plan_picks_the_coarsest_dt_that_resolves_the_motion(device):
    rig = rsocl.Rig.paper_array(4, (32, 32), t_e=0.18e-3, t_r=35e-6)
    p = plan(rig, speed=1 / (3.5 * 35e-6), measure=False)  # 1 px per 3.5 t_r
    assert p.dt == pytest.approx(3 * 35e-6)
    assert p.proposed.rig.T < rig.T
    p = plan(rig, fps=1 / 70e-6, measure=False)
    assert p.dt == pytest.approx(70e-6)
    p = plan(rig, speed=1e9, measure=False)  # too fast: dt = t_r, and says so
    assert p.dt == pytest.approx(35e-6) and any("below t_r" in n for n in p.notes)


@pytest.mark.parametrize("speed", [1e-12, 300.0])
def test_a_still_scene_gets_one_subframe_not_a_dt_beyond_the_exposures(device, speed):
    rig = rsocl.Rig.paper_array(4, (32, 32), t_e=0.18e-3, t_r=35e-6)
    p = plan(rig, speed=speed, measure=False)
    span = float(rig.windows.end.max()) * rig.dt
    assert p.dt == pytest.approx(37 * 35e-6) and span <= p.dt < span + 35e-6
    assert p.proposed.rig.T == 1 and any("one sub-frame" in n for n in p.notes)
    assert plan(rig, speed=1 / 36e-6, measure=False).proposed.rig.T > 1  # 1 px per 36 µs: dt = t_r


def test_plan_reports_memory_and_time_of_both_problems(device):
    rig = rsocl.Rig.paper_array(4, (48, 48), t_e=0.18e-3, t_r=35e-6)
    p = plan(rig, roi=(8, 8, 16, 16), iterations=10)
    assert p.proposed.memory_bytes < p.full.memory_bytes / 4
    assert p.proposed.subframes < p.full.subframes
    assert p.full.seconds_per_iteration > 0 and p.proposed.seconds == pytest.approx(
        p.proposed.seconds_per_iteration * 10
    )


def test_the_timed_iterations_run_after_the_same_call_once(device, monkeypatch):
    """The time per iteration is the iterations' own: the timed call runs after an identical one, which
    builds the programs and lets the runtime compile what it compiles at a kernel's first launches
    (PoCL: seconds on a cold cache, 50x the iterations at 64x64; a 1-iteration call does not launch all)."""
    import rsocl.solver.reconstruct as solver

    calls = []
    run = solver.reconstruct

    def recorded(g, rig, **kwargs):
        calls.append((g.shape, rig, kwargs))
        return run(g, rig, **kwargs)

    monkeypatch.setattr(solver, "reconstruct", recorded)
    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6)
    p = plan(rig, iterations=10, device=device)
    assert len(calls) == 4 and p.full.seconds_per_iteration > 0  # two per problem: as given, proposed
    for first, timed in (calls[0:2], calls[2:4]):
        assert first[0] == timed[0] and first[1] is timed[1] and first[2] == timed[2]


def test_plan_command(capsys):
    assert main(["plan", "--shape", "32", "32", "--roi", "0", "0", "16", "16", "--speed", "5000", "--no-measure"]) == 0
    out = capsys.readouterr().out
    assert "device memory" in out and "proposed ROI" in out
    assert main(["plan", "--speed", "-1"]) == 2
    assert "speed must be > 0" in capsys.readouterr().err


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--tile", "0", "4"], r"--tile must be \(H, W\) pixels with 1 <= H <= m = 32 and 1 <= W <= n = 32"),
        (["--roi", "0", "0", "8", "16", "--tile", "16", "9"], r"--tile must be .* 1 <= W <= n = 8, got \[16, 9\]"),
        (["--halo", "-1"], r"--halo must be a whole number of pixels in \[0, 32\], got -1"),
        (["--sets", "0"], r"--sets must be an integer >= 1, got 0"),
        (["--memory-mib", "-5"], r"--memory-mib must be > 0 MiB, got -5.0"),
        (["--memory-mib", "nan"], r"--memory-mib must be finite"),
        (["--iterations", "-3"], r"--iterations must be an integer >= 1 and <= 1000000, got -3"),
        (["--blur", "0"], r"--blur must be > 0 pixels, got 0.0"),
    ],
)
def test_plan_checks_every_option_before_printing_or_measuring(capsys, monkeypatch, extra, match):
    import re

    from rsocl.solver import plan as plan_module

    calls, real = [], plan_module.plan
    monkeypatch.setattr(plan_module, "plan", lambda *a, **k: calls.append(a) or real(*a, **k))
    assert main(["plan", "--shape", "32", "32", "--no-measure"] + extra) == 2
    captured = capsys.readouterr()
    assert re.search(match, captured.err), captured.err
    assert captured.out == "" and not calls


def test_plan_with_a_memory_budget_proposes_tiles_even_when_the_grid_fits_the_device(capsys):
    assert main(["plan", "--shape", "48", "48", "--no-measure", "--memory-mib", "2", "--halo", "2"]) == 0
    out = capsys.readouterr().out
    assert "tiling:" in out and "budget 2.0 MiB" in out
    assert main(["plan", "--shape", "48", "48", "--no-measure", "--memory-mib", "0.001"]) == 2
    err = capsys.readouterr().err
    assert "fits the budget of 0.0 MiB per task" in err and "--memory-mib" in err and "tile:" not in err


def test_plan_in_python_checks_iterations_and_blur():
    from rsocl.solver.plan import plan

    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6)
    with pytest.raises(ValueError, match="iterations"):
        plan(rig, iterations=-3, measure=False)
    with pytest.raises(ValueError, match="blur_pixels"):
        plan(rig, blur_pixels=0, measure=False)


def _memory_mib(out: str, column: int) -> float:
    """The ``device memory`` row of ``rsocl plan``'s table: ``column`` 0 (as given) or 1 (proposed), MiB."""
    row = next(line for line in out.splitlines() if line.startswith("device memory"))
    return [float(v) for v in row.split() if v.replace(".", "").isdigit()][column]


def test_the_configured_regularizer_is_counted_by_plan_and_by_the_tiling_decision(monkeypatch, capsys):
    """TV with ``fused = N`` keeps a second dual buffer (three planes of the datacube): ``rsocl plan
    --reg-opt fused=N`` counts it, and so does ``rsocl reconstruct``'s decision to run in tiles: a
    device with room for the plain run but not for the fused one tiles only the fused run."""
    from argparse import Namespace

    from rsocl.cli import tiling
    from rsocl.scale.runner import SCHEDULER_ENV
    from rsocl.solver.memory import memory_need
    from rsocl.solver.request import make_regularizer

    rig = rsocl.Rig.paper_array(4, (64, 64), t_e=0.18e-3, t_r=35e-6)
    solved = rig.sampled_range()
    dual = 3 * (solved.stop - solved.start) * 64 * 64 * 4  # one more copy of TV's dual, float32
    plain = memory_need(rig, make_regularizer("tv"))[1]
    fused = memory_need(rig, make_regularizer("tv", {"fused": "2"}))[1]
    assert fused - plain == dual
    assert main(["plan", "--shape", "64", "64", "--no-measure"]) == 0
    given = _memory_mib(capsys.readouterr().out, 0)
    assert main(["plan", "--shape", "64", "64", "--no-measure", "--reg-opt", "fused=2"]) == 0
    assert _memory_mib(capsys.readouterr().out, 0) == pytest.approx(given + dual / 2**20, abs=0.06)

    device = rsocl.device.get_device()
    monkeypatch.setattr(type(device), "global_mem_bytes", property(lambda self: (plain + fused) // 2))
    monkeypatch.delenv(SCHEDULER_ENV, raising=False)
    args = Namespace(
        tile=None,
        sets=False,
        workers=None,
        scheduler=None,
        out="rec.h5",
        regularizer="tv",
        reg_opt=[],
        tv_iterations=None,
        dtype="float32",
        projection="exact",
        device=None,
    )
    capture = Namespace(rig=rig)
    assert not tiling._wants_tiles(args, capture)
    assert tiling._wants_tiles(Namespace(**{**vars(args), "reg_opt": ["fused=2"]}), capture)


@pytest.mark.parametrize("sets, flag", [(3, True), (1, False)])
def test_plan_run_it_command_includes_sets_when_there_are_several(capsys, sets, flag):
    argv = ["plan", "--shape", "40", "24", "--tile", "7", "5", "--halo", "30", "--no-measure", "--sets", str(sets)]
    assert main(argv) == 0
    run_it = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("run it:"))
    assert run_it.startswith("run it: rsocl reconstruct CAPTURE --out rec.zarr --tile 7 5")
    assert run_it.endswith(" --sets") is flag


def test_without_a_speed_or_frame_rate_the_rigs_dt_is_kept_and_the_table_says_what_it_costs(capsys):
    # dt = 50 µs is not a multiple of t_r = 35 µs: "dt kept" keeps it as it is
    assert (
        main(["plan", "--shape", "16", "16", "--t-e-us", "180", "--t-r-us", "35", "--dt-us", "50", "--no-measure"]) == 0
    )
    out = capsys.readouterr().out
    assert next(line for line in out.splitlines() if line.startswith("dt ")).split()[1:] == ["50", "µs", "50", "µs"]
    assert "note: no speed or frame rate given: dt kept" in out
    assert "device memory, fixed run" in out and "the self-tuned default runs its parameter search first" in out


def test_info_says_how_many_kept_sub_frames_between_the_ends_too_few_cameras_see():
    from rsocl.cli.info import _kept_line

    C = rsocl.Camera
    late = [C(a, t_e=180e-6, t_r=35e-6, t_a=2e-3 if a >= 180 else 0.0) for a in (0, 90, 180, 270)]
    rig = rsocl.Rig(late, (16, 16))
    assert _kept_line(rig) == "78 (sub-frames 0..77, the first and last seen by >= 2 cameras; 36 between them by fewer)"
    assert _kept_line(rsocl.Rig.paper_array(4, (50, 50), t_e=180e-6, t_r=35e-6)) == (
        "55 (sub-frames 0..54, each seen by >= 2 cameras)"
    )


def test_info_names_capture_in_its_errors(tmp_path, capsys):
    (tmp_path / "bad.h5").write_text("x")
    for path in (tmp_path / "none.h5", tmp_path / "bad.h5"):
        assert main(["info", "--capture", str(path)]) == 2
        assert capsys.readouterr().err.startswith("rsocl info: error: --capture: ")


@pytest.mark.parametrize("shape, cut", [((32, 40), (32, 40)), ((100, 120), (48, 48))])
def test_the_search_is_timed_on_the_block_a_real_run_searches_with_the_whole_rigs_settings(
    device, monkeypatch, shape, cut
):
    """As :func:`rsocl.solver.pipeline.tune`: a frame the rung crops is searched on its central block with the
    crop's search, under the whole rig's request (its lam and eta); an untimed search first, then the timed one."""
    import rsocl.solver.pipeline as pipeline
    from rsocl.solver.ladder import rung
    from rsocl.solver.search_cost import WARM_ITERATIONS, search_seconds

    seen, real = [], pipeline.tune_with
    monkeypatch.setattr(pipeline, "tune_with", lambda p, s: seen.append((p, s)) or real(p, s))
    rig = rsocl.Rig.paper_array(4, shape, t_e=0.18e-3, t_r=35e-6)
    assert search_seconds(rig, iterations=30, device=device) > 0
    want, box = rung("balanced").search_for(shape)
    assert [p.problem.rig.shape for p, _ in seen] == [cut, cut] and all(s is want for _, s in seen)
    assert (box is None) == (cut == shape)
    assert [p.request.settings.iterations for p, _ in seen] == [WARM_ITERATIONS, 30]
    assert all(p.request.search_space().tunable for p, _ in seen)  # TV's temporal weight, as reconstruct searches
    assert all(p.request.rig is rig for p, _ in seen)


def test_plan_costs_the_self_tuned_run_as_its_search_and_the_iterations(device, monkeypatch, capsys):
    import rsocl.solver.plan as plan_module

    quality, given = [], []

    def searched(rig, **kw):
        quality.append(kw["quality"])
        given.append((kw["regularizer"], kw["regularizer_options"]))
        return 1.25

    monkeypatch.setattr(plan_module, "search_seconds", searched)
    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6)
    p = plan(rig, iterations=10, device=device, quality="best")
    assert quality == ["best", "best"] and given == [("tv", None)] * 2  # a name: its options are searched
    for e in (p.full, p.proposed):
        assert e.search_seconds == 1.25 and e.tuned_seconds == pytest.approx(1.25 + e.seconds)
    assert "time, self-tuned (best)" in plan_module.format_plan(p)
    assert plan(rig, iterations=10, measure=False).full.tuned_seconds is None
    with pytest.raises(ValueError, match="quality must be one of fast, balanced, best"):
        plan(rig, quality="slow", measure=False)
    argv = ["plan", "--shape", "16", "16", "--quality", "fast", "--iterations", "10", "--reg-opt", "temporal_weight=3"]
    assert main(argv) == 0
    assert quality[-2:] == ["fast", "fast"] and given[-1] == ("tv", {"temporal_weight": "3"})
    out = capsys.readouterr().out
    assert "1.2 s search + " in out and "time, self-tuned (fast)" in out
