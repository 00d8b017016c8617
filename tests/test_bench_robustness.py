"""rsocl bench as a user meets it: an interrupt, a scene that is no video, the numbers of its text and plots."""

import csv

import numpy as np
import pytest

from rsocl.cli.main import main

SMALL = ["bench", "--quick", "--shape", "12", "--iterations", "2", "--quiet"]


def _interrupt_after(monkeypatch, calls, exception=KeyboardInterrupt):
    """``run_point`` that raises ``exception`` on its call number ``calls + 1``."""
    from rsocl.bench import run as bench_run

    real, seen = bench_run.run_point, []

    def point(*args, **kwargs):
        seen.append(args[0])
        if len(seen) > calls:
            raise exception()
        return real(*args, **kwargs)

    monkeypatch.setattr(bench_run, "run_point", point)


@pytest.mark.parametrize(
    "exception, word, status", [(KeyboardInterrupt, "interrupted", 130), (None, "terminated", 143)]
)
def test_an_interrupt_keeps_the_points_measured_before_it(tmp_path, capsys, monkeypatch, exception, word, status):
    from rsocl.common.interrupts import Terminated

    _interrupt_after(monkeypatch, 3, exception or Terminated)
    out = tmp_path / "b"
    assert main(SMALL + ["--sweep", "cameras=1,2,3", "--out", str(out)]) == status
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"rsocl bench: {word}: written with the points measured before it (3)")
    assert str(out / "bench.csv") in err[0]
    with open(out / "bench.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["label"] for r in rows] == ["default", "C=1", "C=2"]
    assert "interrupted: 3 of the 8 points measured, the others not" in (out / "bench.md").read_text(encoding="utf-8")


def test_an_interrupt_before_any_reconstruction_writes_nothing(tmp_path, capsys, monkeypatch):
    _interrupt_after(monkeypatch, 0)
    out = tmp_path / "b"
    assert main(SMALL + ["--sweep", "cameras=1", "--out", str(out)]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["rsocl bench: interrupted: no reconstruction point measured, nothing written"]
    assert not out.exists()


@pytest.mark.parametrize(
    "name, video, match",
    [
        (
            "image.tif",
            np.full((16, 16), 200, np.uint8),
            r"holds 1 frame; rsocl bench needs a video of at least 2 frames",
        ),
        ("one.npz", np.zeros((1, 16, 16)), r"holds 1 frame; rsocl bench needs a video of at least 2 frames"),
        ("nan.npz", np.full((4, 16, 16), np.nan), r"contains 1024 NaN or inf value\(s\)"),
    ],
)
def test_a_scene_that_is_no_video_is_refused_before_any_point(tmp_path, capsys, monkeypatch, name, video, match):
    """A still image (a one-page TIFF) gave every point an infinite PSNR; a NaN video failed every point."""
    import re

    import imageio.v3 as iio

    from rsocl.bench import run as bench_run

    path = tmp_path / name
    if name.endswith(".tif"):
        iio.imwrite(path, video)
    else:
        np.savez(path, video=video)
    calls = []
    monkeypatch.setattr(bench_run, "run_point", lambda *a, **k: calls.append(a))
    out = tmp_path / "b"
    assert main(SMALL + ["--scene", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1 and err[0].startswith(f"rsocl bench: error: --scene {str(path)!r}") and re.search(match, err[0])
    )
    assert not calls and not out.exists()


def _result(seconds):
    """A run of a 12x12 grid whose times are replaced by ``seconds`` in the order of its rows (default, it=2,
    dt=2t_r, interp3d, ROI 8, interp3d ROI 8), the default's second timing ``seconds[-1]``."""
    from rsocl.bench.run import BenchPoint, run_bench

    result = run_bench(BenchPoint(shape=12, iterations=4), ["iterations=2", "dt=1,2", "roi=8"], progress=False)
    for row, value in zip(result.rows, seconds):
        row["seconds"] = value
    result.timing_check = (result.rows[0]["seconds"], seconds[-1])
    return result


#: Times of a quick run on a fast machine: hundredths of a second.
QUICK_SECONDS = [0.0464, 0.0103, 0.0308, 0.0024, 0.0171, 0.0007, 0.0548]


def test_the_times_the_text_states_agree_with_its_ratios():
    """Times at two decimals read '0.02 s instead of 0.05 s (×0.34)' and '0.05 s ... 0.05 s (18% apart)'."""
    import re

    from rsocl.bench.run import markdown

    text = markdown(_result(QUICK_SECONDS))
    ratios = re.findall(r"([\d.]+) s instead of ([\d.]+) s \(×([\d.]+)\)", text)
    assert len(ratios) == 2  # dt = 2 t_r and ROI 8
    for shown, base, ratio in ratios:
        assert float(shown) / float(base) == pytest.approx(float(ratio), abs=0.006), (shown, base, ratio)
    a, b, apart = re.search(
        r"took ([\d.]+) s at the start and ([\d.]+) s when timed again at the end \((\d+)%", text
    ).groups()
    assert abs(float(b) - float(a)) / min(float(a), float(b)) * 100 == pytest.approx(int(apart), abs=0.6)
    assert "0.0464 s" in text and "0.0103 s" in text


def test_the_iterations_plot_labels_each_run_with_its_time(tmp_path, monkeypatch):
    """Its labels read '0.0 s' for every run of a quick bench."""
    from matplotlib.axes import Axes

    from rsocl.bench.run import write_outputs

    labels, real = [], Axes.annotate
    monkeypatch.setattr(Axes, "annotate", lambda self, text, *a, **k: labels.append(text) or real(self, text, *a, **k))
    result = _result(QUICK_SECONDS)
    write_outputs(result, tmp_path)
    assert {"0.0464 s", "0.0103 s"} <= set(labels)  # the default and it=2


def test_every_sweep_has_a_colour_of_its_own_in_the_pareto_plot():
    """tune and quality were both drawn gray, two legend entries alike."""
    from rsocl.bench.plots import COLOURS
    from rsocl.bench.run import SWEEPS

    assert set(SWEEPS) | {"default", "baseline"} <= set(COLOURS)
    assert len(set(COLOURS.values())) == len(COLOURS)


#: Columns of bench.csv that hold no quantity of a unit: text, counts, ratios, weights.
UNITLESS = {
    "scene", "sweep", "label", "regularizer", "cameras", "dt_factor", "iterations", "tv_iterations", "dtype",
    "device", "lam", "eta", "T", "T_se", "subframes_evaluated", "ssim_mean", "ssim_per_subframe",
}  # fmt: skip


def test_every_number_of_the_tables_has_its_unit(tmp_path):
    """bench.csv's psnr, psnr_full_roi, shape and roi, iterations.csv's psnr and bench.md's ROI said none."""
    import re

    from rsocl.bench.run import write_outputs

    write_outputs(_result(QUICK_SECONDS), tmp_path)
    header = (tmp_path / "bench.csv").read_text(encoding="utf-8").splitlines()[0].split(",")
    with_units = [name for name in header if name not in UNITLESS]
    assert with_units and all(re.search(r"(_db|_px|_us|seconds.*|_bytes)$", name) for name in with_units), with_units
    assert "psnr_db" in header and "roi_px" in header
    assert (tmp_path / "iterations.csv").read_text(encoding="utf-8").startswith("iteration,psnr_db,residual,seconds\n")
    table = next(line for line in (tmp_path / "bench.md").read_text(encoding="utf-8").splitlines() if "| point" in line)
    assert "| ROI (px) |" in table and "| PSNR (dB) |" in table and "| memory (MiB) |" in table


def test_the_text_says_whether_the_default_point_is_fixed_or_self_tuned():
    """It called the fixed lam 'rsocl's defaults', while rsocl's default self-tunes lam."""
    from dataclasses import replace

    from rsocl.bench.run import BenchResult, markdown

    result = _result(QUICK_SECONDS)
    fixed = markdown(result).splitlines()[2]
    assert "fixed settings from zeros, as `rsocl reconstruct --fixed` (rsocl's default self-tunes" in fixed
    assert "lam and eta: the fixed defaults for each point's rig" in fixed
    tuned = markdown(BenchResult(result.rows, replace(result.default, tune=True))).splitlines()[2]
    assert "self-tuned as rsocl's default (lam chosen from each point's snapshots" in tuned
    assert "fixed" not in tuned
