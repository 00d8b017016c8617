"""``benchmarks/launch_cost.py``: every variant is timed and compared with the trivial kernel."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import launch_cost  # noqa: E402


def test_page_has_every_variant_with_its_ratio(tmp_path):
    out = tmp_path / "launch_cost.md"
    launch_cost.main(["--rounds", "2", "--launches", "20", "--shape", "8", "--out", str(out)])
    rows = [line for line in out.read_text().splitlines() if line.startswith("| ") and "µs" not in line]
    assert [row.split(" | ")[0].lstrip("| ") for row in rows] == list(launch_cost.VARIANTS)
    assert rows[0].endswith("| 1.00 (1.00, 1.00) |")  # the trivial kernel against itself
    assert all(float(row.split(" | ")[1].split()[0]) > 0 for row in rows)


@pytest.mark.parametrize("args", [["--rounds", "0"], ["--launches", "0"], ["--shape", "1"]])
def test_bad_counts_are_refused(args, capsys):
    with pytest.raises(SystemExit):
        launch_cost.main(args)
    assert "--rounds and --launches must be >= 1, --shape >= 2" in capsys.readouterr().err
