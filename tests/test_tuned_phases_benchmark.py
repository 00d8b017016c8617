"""``benchmarks/tuned_phases.py``: a self-tuned call's time phase by phase beside a fixed run's, on a tiny frame."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import tuned_phases  # noqa: E402


def _rows(text):
    lines = [line for line in text.splitlines() if line.startswith("| builtin")]
    return [[c.strip() for c in line.strip("|").split("|")] for line in lines]


def test_page_has_every_phase_and_sums_the_call(tmp_path):
    out = tmp_path / "tuned_phases.md"
    tuned_phases.main(["--size", "12", "--rounds", "1", "--scenes", "builtin", "--out", str(out)])
    rows = _rows(out.read_text())
    phases, waited, bound, free = rows[:-3], rows[-3], rows[-2], rows[-1]
    assert [row[2] for row in phases] == tuned_phases.ORDER
    by = {row[2]: row for row in phases}
    # the search's phases belong to the tuned call alone; each batch is a GPU-path batch of 50 iterations
    assert by["search: batch"][4] == "–" and by["search: batch"][3] == "2"
    assert float(by["search: batch"][8]) >= 2 * 50 * 9 and float(by["search: batch"][9]) > 0
    fixed_run, tuned_run = float(by["run: iterations"][5]), float(by["run: iterations"][8])
    assert fixed_run > 0 and abs(tuned_run - fixed_run) <= 0.01 * fixed_run  # the same iterations
    for col, total in ((4, waited[4]), (7, waited[7])):  # fixed and tuned: the phases add up to the call
        parts = [float(row[col]) for row in phases if row[col] != "–"]
        assert sum(parts) == pytest.approx(float(total.strip("*")), rel=0.02, abs=0.05)
    assert "(×" in free[7]
    # the bound: the tuned call with the batches' time replaced by their host time in step
    tuned_total, batch = float(waited[7].strip("*")), by["search: batch"]
    expected = tuned_total - float(batch[7]) + float(batch[9])
    value, ratio = bound[7].split(" (×")
    assert float(value.strip("*")) == pytest.approx(expected, rel=0.02, abs=0.05)
    assert float(ratio.rstrip(")")) == pytest.approx(float(value.strip("*")) / float(waited[4].strip("*")), rel=0.02)
    assert float(value.strip("*")) < tuned_total


@pytest.mark.parametrize("args", [["--size", "4"], ["--rounds", "0"]])
def test_bad_arguments_are_refused(args):
    with pytest.raises(SystemExit):
        tuned_phases.main(args)
