"""``benchmarks/kernel_times.py``: every kernel of an iteration with its device time, on a tiny frame."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import kernel_times  # noqa: E402


def _rows(text):
    return [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines() if line.startswith("| 6×6")]


@pytest.mark.parametrize("as_gpu", [False, True])
def test_page_names_each_kernel_and_sums_an_iteration(device, tmp_path, as_gpu):
    out = tmp_path / "kernel_times.md"
    kernel_times.main(["--sizes", "6", "--iterations", "3", "--out", str(out)] + (["--as-gpu"] if as_gpu else []))
    rows = _rows(out.read_text())
    kernels, total = rows[:-1], rows[-1]
    names = {row[2].strip("`") for row in kernels}
    gpu_path = as_gpu or not device.is_cpu
    assert "admm_project" in names and ("tv_first2" if gpu_path else "tv_dual_first") in names
    launches = sum(float(row[3]) for row in kernels)
    assert float(total[3]) == launches
    if gpu_path:  # the GPU path: the projection (with the TV's last primal step), tv_first2, 7 tv_step
        assert launches == 9 and names == {"admm_project", "tv_first2", "tv_step"}
    busy, span = (float(part.split()[1]) for part in total[4].split(",")[:2])
    assert 0 < busy <= span * 1.001
    assert sum(float(row[5].rstrip(" %")) for row in kernels) == pytest.approx(100, abs=len(kernels))


def test_a_batch_takes_the_same_launches_per_iteration_as_one_set(tmp_path):
    out = tmp_path / "kernel_times.md"
    kernel_times.main(["--sizes", "6", "--sets", "1", "3", "--iterations", "2", "--as-gpu", "--out", str(out)])
    text = out.read_text()
    assert "B copies of the snapshots" in text
    rows = _rows(text)
    one = [row for row in rows if row[0] == "6×6"]
    batch = [row for row in rows if row[0] == "6×6, 3 sets"]
    assert one and batch and len(one) + len(batch) == len(rows)
    # the batch runs every kernel once for all its sets
    assert {row[2]: row[3] for row in batch} == {row[2]: row[3] for row in one}


def test_lanes_are_set_for_the_run_and_restored(tmp_path, monkeypatch, admm_lanes):
    import rsocl.solver.admm as admm_module

    monkeypatch.setattr(admm_module, "GPU_PROJECT_LANES", 1)
    out = tmp_path / "kernel_times.md"
    kernel_times.main(["--sizes", "6", "--lanes", "4", "--iterations", "2", "--as-gpu", "--out", str(out)])
    assert admm_lanes == [4] and admm_module.GPU_PROJECT_LANES == 1
    assert "Projection lanes where the device is not a CPU: 4." in out.read_text()


@pytest.mark.parametrize("args", [["--iterations", "0"], ["--sizes", "1"], ["--sets", "0"], ["--lanes", "3"]])
def test_bad_counts_are_refused(args, capsys):
    with pytest.raises(SystemExit):
        kernel_times.main(args)
    assert "must be >=" in capsys.readouterr().err
