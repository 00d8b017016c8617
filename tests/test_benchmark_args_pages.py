"""Benchmarks' arguments: ``tiled_tuning.py``'s interface and page, the sizes and scenes ``quality.py`` and
``ladder.py`` have cases for, ``scale.py``'s sensor shape, tile and seam picture, ``solver_settings.py``'s
usage line; the commit a page names (``provenance.py``). Refusals come before anything runs and name the option."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))

import ladder  # noqa: E402
import quality  # noqa: E402
import saturation  # noqa: E402
import scale  # noqa: E402
import solver_settings  # noqa: E402
import tiled_tuning  # noqa: E402
from provenance import DOCS  # noqa: E402

RUNNER = tiled_tuning.DATA / "runner40.npz"


def _refused(main, argv, capsys, *words):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    for word in words:
        assert word in err, err
    return err


# ---------------------------------------------------------------------- tiled_tuning.py
def test_tiled_tuning_help_runs():
    done = subprocess.run(
        [sys.executable, str(BENCH / "tiled_tuning.py"), "--help"], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "--cases" in done.stdout and "--out" in done.stdout


def test_tiled_tuning_defaults_without_arguments(tmp_path):
    (tmp_path / "runner40.npz").touch()
    args = tiled_tuning.parse_args(["--data", str(tmp_path)])
    assert args.cases == [(128, 64), (256, 128)]
    assert args.runs == ["untiled", "block", "tile"]
    assert args.out == DOCS / "scale_tuning.md"


@pytest.mark.parametrize("text", ["128", "128/0", "64/128", "8/4", "a/b", "128x64"])
def test_tiled_tuning_refuses_a_bad_case(text, tmp_path, capsys):
    (tmp_path / "runner40.npz").touch()
    _refused(tiled_tuning.parse_args, ["--data", str(tmp_path), "--cases", text], capsys, "--cases", "SIDE/TILE")


def test_tiled_tuning_refuses_missing_data_and_out_folder(tmp_path, capsys):
    _refused(tiled_tuning.parse_args, ["--data", str(tmp_path)], capsys, "--data", "runner40.npz")
    (tmp_path / "runner40.npz").touch()
    out = tmp_path / "no" / "page.md"
    _refused(tiled_tuning.parse_args, ["--data", str(tmp_path), "--out", str(out)], capsys, "--out")


@pytest.mark.skipif(not RUNNER.is_file(), reason="needs ../shared/data/runner40.npz")
def test_tiled_tuning_writes_its_page(tmp_path):
    out = tmp_path / "scale_tuning.md"
    assert tiled_tuning.main(["--cases", "32/16", "--runs", "untiled", "block", "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0] == "# Where a tiled run chooses its parameters"
    assert any(line.startswith("- command: `python benchmarks/tiled_tuning.py --cases 32/16") for line in lines)
    rows = [line for line in lines if line.startswith("| 32x32 |")]
    assert [row.split(" | ")[2] for row in rows] == ["untiled", "centre block (the whole grid)"]


def test_tiled_tuning_block_label_names_the_crop():
    side = tiled_tuning.tuning_tile.TUNE_SIDE
    assert tiled_tuning.block_label(side, side // 2) == "centre block (the whole grid)"
    assert tiled_tuning.block_label(4 * side, side // 2) == f"centre block ({side}x{side})"


# ---------------------------------------------------------------------- quality.py, ladder.py
@pytest.mark.parametrize("sizes", [["16"], ["64", "96"]])
def test_quality_refuses_sizes_without_cases(sizes, tmp_path, capsys):
    out = tmp_path / "quality.md"
    err = _refused(quality.main, ["--sizes", *sizes, "--out", str(out)], capsys, "--sizes", "64 and 128")
    assert sizes[-1] in err
    assert not out.exists()


def test_quality_sizes_are_the_cases():
    assert quality.SIZES == (64, 128)


def test_ladder_refuses_sizes_scenes_and_empty_selections(tmp_path, capsys):
    out = tmp_path / "ladder.md"
    _refused(ladder.main, ["--sizes", "16", "--scenes", "builtin", "--out", str(out)], capsys, "--sizes", "64 and 128")
    _refused(ladder.main, ["--scenes", "nowhere", "--out", str(out)], capsys, "--scenes", "nowhere", "builtin")
    _refused(
        ladder.main, ["--sizes", "128", "--scenes", "traffic48@2", "--out", str(out)], capsys, "--sizes", "--scenes"
    )
    assert not out.exists()


def test_ladder_selects_the_cases_of_its_sizes_and_scenes():
    import argparse

    picked = ladder.selected(argparse.Namespace(sizes=[128], scenes=["builtin"]))
    assert picked == [("builtin", 128, "none"), ("builtin", 128, "poisson")]
    assert len(ladder.selected(argparse.Namespace(sizes=[64, 128], scenes=None))) == len(quality.CASES)


# ---------------------------------------------------------------------- scale.py
@pytest.mark.parametrize("shape", [["8", "64"], ["64", "0"]])
def test_scale_refuses_a_small_sensor_shape(shape, tmp_path, capsys):
    results = tmp_path / "scale.json"
    argv = ["--parts", "sensor", "--sensor-shape", *shape, "--results", str(results)]
    _refused(scale.main, argv, capsys, "--sensor-shape", ">= 16")
    assert not results.exists()


def test_scale_refuses_a_missing_results_folder(tmp_path, capsys):
    _refused(scale.main, ["--parts", "seams", "--results", str(tmp_path / "no" / "s.json")], capsys, "--results")


def test_scale_seam_picture_goes_beside_the_results(tmp_path):
    class Args:
        results, picture = str(tmp_path / "s.json"), None

    assert scale.picture_path(Args) == tmp_path / "scale_seams.png"
    Args.results = str(scale.RESULTS)
    assert scale.picture_path(Args) == DOCS / "scale_seams.png"
    Args.picture = str(tmp_path / "elsewhere.png")
    assert scale.picture_path(Args) == tmp_path / "elsewhere.png"


def test_scale_sensor_below_the_tile_runs_in_a_tile_that_fits(tmp_path):
    pytest.importorskip("zarr", reason="the sensor part writes a Zarr store: pip install 'rsocl[dask]'")
    results = tmp_path / "scale.json"
    argv = ["--parts", "sensor", "--sensor-shape", "32", "48", "--sensor-iterations", "1"]
    scale.main([*argv, "--results", str(results), "--workdir", str(tmp_path)])
    sensor = json.loads(results.read_text())["sensor"]
    assert sensor["shape"] == [32, 48] and sensor["complete"]
    assert "--tile 32 48" in sensor["command"]
    assert not (tmp_path / "scale.md").exists()


# ---------------------------------------------------------------------- solver_settings.py
def test_solver_settings_usage_points_out_at_its_own_page():
    usage = next(line for line in solver_settings.__doc__.splitlines() if "benchmarks/solver_settings.py" in line)
    assert "--out docs/solver_settings.md" in usage


# ---------------------------------------------------------------------- saturation.py
def test_saturation_writes_its_summary_and_every_case(tmp_path, monkeypatch):
    monkeypatch.setattr(saturation, "scene_names", lambda: ["builtin"])  # the shared videos may be here or not
    monkeypatch.setattr(saturation, "ITERATIONS", 20)
    out = tmp_path / "saturation.md"
    saturation.main(["--sizes", "12", "--seeds", "--levels", "80", "--out", str(out)])
    page = out.read_text()
    assert "| 80th percentile (on average 20 % of the samples clipped) | 2 |" in page
    assert page.count("| paper 12x12 | builtin |") == 2  # noiseless and noisy
    with pytest.raises(SystemExit):
        saturation.main(["--levels", "100", "--out", str(out)])


# ---------------------------------------------------------------------- provenance.py
def test_git_revision_is_dirty_for_code_but_not_for_pages(tmp_path, monkeypatch):
    """A page's header names the commit measured: edits to the pages the scripts write (docs/, Markdown) leave
    it clean, an edit to anything else makes it ``-dirty``."""
    from provenance import git_revision

    monkeypatch.delenv("RSOCL_GIT_COMMIT", raising=False)
    git = ["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(git[:3] + ["init", "-q"], check=True)
    for name in ("docs/page.md", "docs/plot.png", "README.md", "rsocl/code.py"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("a\n")
    subprocess.run(git + ["add", "."], check=True)
    subprocess.run(git + ["commit", "-q", "-m", "c"], check=True)
    head = subprocess.run(git + ["rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    for name in ("docs/page.md", "docs/plot.png", "README.md"):
        (tmp_path / name).write_text("b\n")
    (tmp_path / "untracked.py").write_text("b\n")
    assert git_revision(tmp_path) == head
    (tmp_path / "rsocl/code.py").write_text("b\n")
    assert git_revision(tmp_path) == head + "-dirty"


def test_ladder_times_its_runs_in_rounds_of_alternating_order():
    """Seconds are medians over the rounds, the time over the fixed run's a median of ratios within a round,
    the order reverses every other round, and a PSNR that moves between rounds is an error."""
    order, slow = [], {"fixed": 2.0}

    def run(label, kwargs):
        order.append(label)
        seconds = slow.get(label, 1.0) * (3.0 if len(order) <= len(ladder.RUNS) else 1.0)  # a slow first round
        return {"psnr": 20.0, "ssim": 0.5, "seconds": seconds, "search": seconds / 2, "iterations": 200}

    out = ladder.timed_rounds(run, 3)
    labels = [label for label, _ in ladder.RUNS]
    assert order == labels + labels[::-1] + labels
    assert out["fixed"]["seconds"] == 2.0 and out["fast"]["seconds"] == 1.0 and out["fast"]["search"] == 0.5
    assert out["fast"]["ratio"] == 0.5 and out["fast"]["ratio_range"] == [0.5, 0.5]
    assert out["fixed"]["ratio"] == 1.0
    psnrs = iter([20.0] * len(labels) + [20.5] * len(labels))
    with pytest.raises(RuntimeError, match="PSNR differs between rounds"):
        ladder.timed_rounds(
            lambda label, kw: {"psnr": next(psnrs), "ssim": 0, "seconds": 1, "search": 0, "iterations": 1}, 2
        )
