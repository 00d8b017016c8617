"""``benchmarks/search_launches.py``: counts, timed rounds and the same choices, on a tiny frame."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import search_launches  # noqa: E402


def test_page_has_counts_times_and_ratios(tmp_path):
    out = tmp_path / "search_launches.md"
    search_launches.main(["--sizes", "8", "--rounds", "2", "--out", str(out)])
    text = out.read_text()
    rows = [line.split(" | ") for line in text.splitlines() if line.startswith("| 8×8 |")]
    assert [row[1] for row in rows] == ["fixed", "tuned, rounds batched", "tuned, one candidate per batch"]
    assert rows[0][-1] == "1.00 (1.00-1.00) |"  # the fixed run against itself
    launches = [int(row[2]) for row in rows]
    assert launches[0] < launches[1] < launches[2]  # the search adds launches; one candidate at a time more
    assert "the two searches chose the same values" in text


def test_bad_rounds_are_refused():
    with pytest.raises(SystemExit, match="--rounds >= 1"):
        search_launches.main(["--sizes", "8", "--rounds", "0"])
