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
