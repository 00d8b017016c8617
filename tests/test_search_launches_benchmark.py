"""``benchmarks/search_launches.py``: counts, timed rounds and the same choices, on a tiny frame."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import search_launches  # noqa: E402


def test_page_has_counts_times_and_ratios(tmp_path):
    out = tmp_path / "search_launches.md"
    search_launches.main(["--sizes", "8", "--scenes", "builtin", "builtin-fast", "--rounds", "2", "--out", str(out)])
    text = out.read_text()
    for scene in ("builtin", "builtin-fast"):
        rows = [line.split(" | ") for line in text.splitlines() if line.startswith(f"| {scene} | 8×8 |")]
        assert [row[2] for row in rows] == ["fixed", "tuned, rounds batched", "tuned, one candidate per batch"]
        assert rows[0][-1] == "1.00 (1.00-1.00) |"  # the fixed run against itself
        batches = [int(b) for b in rows[1][3].split(", ")]
        assert len(batches) >= 2 and all(b >= 1 for b in batches) and rows[0][3] == rows[2][3] == ""
        launches = [int(row[4]) for row in rows]
        assert launches[0] < launches[1] < launches[2]  # the search adds launches; one candidate at a time more
        assert f"- {scene}, 8×8" in text
    assert text.count("the two searches chose the same values") == 2


def test_a_scene_without_its_video_is_refused(monkeypatch):
    monkeypatch.setattr(search_launches, "available", lambda name: name.startswith("builtin"))
    with pytest.raises(SystemExit, match=r"--scenes: \['runner40@1'\] need their videos"):
        search_launches.main(["--sizes", "8", "--scenes", "builtin", "runner40@1"])


def test_bad_rounds_are_refused():
    with pytest.raises(SystemExit, match="--rounds >= 1"):
        search_launches.main(["--sizes", "8", "--rounds", "0"])
