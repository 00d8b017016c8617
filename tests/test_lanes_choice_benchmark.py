"""``benchmarks/lanes_choice.py``: the projection's lanes timed per case, and the count the timings choose;
``benchmarks/provenance.py``'s ``RSOCL_BENCH_PROJECT_LANES``, which runs later benchmarks with that count."""

import re
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import lanes_choice  # noqa: E402
import provenance  # noqa: E402


def _busy(**cases):
    """``{case: {1: 100, lanes: 100 * ratio, ...}}`` from ``case={lanes: ratio}``."""
    return {name: {1: 100.0, **{n: 100.0 * r for n, r in ratios.items()}} for name, ratios in cases.items()}


def test_the_count_with_the_smallest_mean_is_chosen():
    chosen, scores = lanes_choice.choose(_busy(a={2: 0.9, 4: 0.6}, b={2: 0.95, 4: 0.8}))
    assert chosen == 4
    assert scores[1] == (1.0, 1.0)
    assert scores[4][0] == pytest.approx((0.6 * 0.8) ** 0.5) and scores[4][1] == pytest.approx(0.8)


def test_a_count_that_slows_one_case_beyond_the_tolerance_is_not_chosen():
    busy = _busy(small={4: 0.5, 8: 0.4}, large={4: 1.02, 8: 1.2})
    assert lanes_choice.choose(busy)[0] == 4  # 8 has the smaller mean but slows the large frame by 20 %
    assert lanes_choice.choose(busy, tolerance=0.01)[0] == 1


def test_one_lane_stays_where_no_count_gains_enough():
    assert lanes_choice.choose(_busy(a={2: 0.99, 4: 0.98}, b={2: 1.0, 4: 0.99}))[0] == 1
    assert lanes_choice.choose(_busy(a={4: 0.98}), min_gain=0.01)[0] == 4


def test_equal_means_take_fewer_lanes():
    assert lanes_choice.choose(_busy(a={2: 0.8, 4: 0.8}))[0] == 2


def test_counts_not_timed_in_every_case_are_left_out():
    chosen, scores = lanes_choice.choose({"a": {1: 100.0, 4: 50.0}, "b": {1: 100.0}})
    assert chosen == 1 and set(scores) == {1}


def test_the_baseline_is_required():
    with pytest.raises(ValueError, match="one lane"):
        lanes_choice.choose({"a": {2: 1.0, 4: 2.0}})


def test_the_page_times_every_count_and_the_choice_file_holds_its_choice(tmp_path, monkeypatch, admm_lanes):
    import rsocl.solver.admm as admm_module

    monkeypatch.setattr(admm_module, "GPU_PROJECT_LANES", 1)  # restored to it after the run
    out, choice = tmp_path / "lanes.md", tmp_path / "choice.txt"
    chosen = lanes_choice.main(
        ["--as-gpu", "--cases", "6x1", "6x2", "--lanes", "1", "2", "--iterations", "2", "--rounds", "2"]
        + ["--out", str(out), "--choice", str(choice)]
    )
    text = out.read_text()
    rows = [line for line in text.splitlines() if line.startswith("| 6×6")]
    assert [row.split("|")[1].strip() for row in rows] == ["6×6", "6×6, 2 sets"]
    for row in rows:  # one lane's column over itself is 1
        assert row.split("|")[3].strip().endswith("(1.00)")
    assert sorted(set(admm_lanes)) == [1, 2] and len(admm_lanes) == 2 * 2 * 2  # cases x counts x rounds
    assert admm_module.GPU_PROJECT_LANES == 1
    assert choice.read_text().strip() == str(chosen) and chosen in (1, 2)
    assert re.search(rf"Chosen: \*\*{chosen}\*\*", text)


@pytest.mark.parametrize(
    "args",
    [["--lanes", "2", "4"], ["--lanes", "1", "3"], ["--iterations", "0"], ["--cases", "1x1"], ["--cases", "50"]]
    + [["--budget", "0"]],
)
def test_bad_arguments_are_refused(args, capsys):
    with pytest.raises(SystemExit):
        lanes_choice.main(args)
    assert re.search(r"--lanes|--iterations|a case|--budget", capsys.readouterr().err)


def test_the_environment_sets_the_lanes_and_the_header_says_so(monkeypatch):
    import rsocl.solver.admm as admm_module

    monkeypatch.setattr(admm_module, "GPU_PROJECT_LANES", 1)
    monkeypatch.setenv(provenance.LANES_ENV, "4")
    assert provenance.apply_settings() == [
        "- projection lanes on a device that is not a CPU: 4 (set by RSOCL_BENCH_PROJECT_LANES; rsocl's: 1)"
    ]
    assert admm_module.GPU_PROJECT_LANES == 4


@pytest.mark.parametrize("value", ["3", "0", "four", "-2"])
def test_a_bad_lane_count_in_the_environment_is_refused(monkeypatch, value):
    import rsocl.solver.admm as admm_module

    monkeypatch.setattr(admm_module, "GPU_PROJECT_LANES", 1)
    monkeypatch.setenv(provenance.LANES_ENV, value)
    with pytest.raises(ValueError, match="RSOCL_BENCH_PROJECT_LANES must be a power of two"):
        provenance.apply_settings()
    assert admm_module.GPU_PROJECT_LANES == 1


def test_without_the_environment_nothing_is_set(monkeypatch):
    import rsocl.solver.admm as admm_module

    monkeypatch.setattr(admm_module, "GPU_PROJECT_LANES", 1)
    monkeypatch.delenv(provenance.LANES_ENV, raising=False)
    assert provenance.apply_settings() == [] and admm_module.GPU_PROJECT_LANES == 1


def test_a_count_the_work_groups_cannot_hold_is_shown_with_the_lanes_taken(tmp_path, monkeypatch):
    import rsocl.solver.admm as admm_module

    monkeypatch.setattr(admm_module, "lanes_that_fit", lambda lanes, *limits: min(lanes, 2))
    out = tmp_path / "lanes.md"
    lanes_choice.main(
        ["--as-gpu", "--cases", "6x1", "--lanes", "1", "4", "--iterations", "1", "--rounds", "1"] + ["--out", str(out)]
    )
    row = next(line for line in out.read_text().splitlines() if line.startswith("| 6×6"))
    one, four = (cell.strip() for cell in row.split("|")[3:5])
    assert "taken" not in one and four.endswith("[2 taken]")


def test_cases_past_the_budget_are_named_and_left_out_of_the_choice(tmp_path):
    out = tmp_path / "lanes.md"
    argv = ["--as-gpu", "--cases", "6x1", "6x2", "4x1", "--lanes", "1", "2", "--iterations", "1", "--rounds", "1"]
    lanes_choice.main([*argv, "--budget", "1e-9", "--out", str(out)])
    text = out.read_text()
    assert [
        line.split("|")[1].strip() for line in text.splitlines() if line.startswith("| 6×6") or line.startswith("| 4×4")
    ] == ["6×6"]
    assert "not timed, past the budget of 1e-09 s: 6×6, 2 sets; 4×4." in text


def test_a_cpu_device_takes_one_lane_and_the_page_says_so(device, tmp_path):
    out = tmp_path / "lanes.md"
    lanes_choice.main(["--cases", "6x1", "--lanes", "1", "2", "--iterations", "1", "--rounds", "1", "--out", str(out)])
    row = next(line for line in out.read_text().splitlines() if line.startswith("| 6×6"))
    two = row.split("|")[4].strip()
    assert two.endswith("[1 taken]") == device.is_cpu  # the device's own choices: one lane on a CPU
