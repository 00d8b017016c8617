"""``benchmarks/peer.py``'s rsocl runs beside its defaults (``--tv-one-launch``, ``--no-first-two``,
``--project-lanes``): their
columns, their ratio to rsocl's defaults and their equality check, with or without torch."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import peer  # noqa: E402

ARGS = ["--cases", "size8", "--sizes", "8", "--size-iterations", "2", "--rounds", "2", "--modes", "eager"]
ARGS += ["--torch-device", "cpu"]


def test_one_launch_variant_has_its_column_ratio_and_check(tmp_path):
    assert peer.variant_options("rsocl one_launch=2") == {"one_launch": 2}
    assert peer.variant_options("rsocl") is None
    out = tmp_path / "peer.md"
    peer.main([*ARGS, "--tv-one-launch", "2", "--out", str(out)])
    lines = out.read_text().splitlines()
    times = lines.index("## Times (median of the rounds)")
    assert "rsocl one_launch=2" in lines[times + 2].split("|")[3]
    ratio_head = next(line for line in lines if line.startswith("| case | rsocl one_launch=2 / rsocl"))
    ratio_row = lines[lines.index(ratio_head) + 2]
    median = float(ratio_row.split("|")[2].split()[0])
    assert median > 0
    same = [line for line in lines if line.startswith("| one set 8×8") and " dB, " in line]
    assert len(same) == 1
    delta, largest = same[0].split("|")[3].split(" dB, ")
    assert abs(float(delta)) < 1e-4 and float(largest) < 1e-5  # the same iterations, TV launched differently


def test_no_first_two_variant_runs_the_tv_first_iteration_on_its_own(tmp_path, monkeypatch):
    import rsocl_plugins.tv as tv_module
    from rsocl.device.context import Device

    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))  # where GPU_FIRST_TWO applies
    seen = []
    real = tv_module.TV._plain_parts

    def spy(self, *args):
        parts = real(self, *args)
        seen.append(parts[3]["first2"])
        return parts

    monkeypatch.setattr(tv_module.TV, "_plain_parts", spy)
    with peer.variant_context(peer.NO_FIRST_TWO):
        assert tv_module.GPU_FIRST_TWO is False
    with peer.variant_context("rsocl"):
        assert tv_module.GPU_FIRST_TWO is True
    assert tv_module.GPU_FIRST_TWO is True and peer.is_variant(peer.NO_FIRST_TWO) and not peer.is_variant("rsocl")
    out = tmp_path / "peer.md"
    peer.main([*ARGS, "--no-first-two", "--out", str(out)])
    assert True in seen and False in seen
    lines = out.read_text().splitlines()
    assert any(line.startswith("| case | rsocl first2=off / rsocl") for line in lines)
    same = [line for line in lines if line.startswith("| one set 8×8") and " dB, " in line]
    delta, largest = same[0].split("|")[3].split(" dB, ")
    assert abs(float(delta)) < 1e-4 and float(largest) < 1e-5


def test_project_lanes_variant_runs_its_lanes_and_checks_equality(tmp_path, monkeypatch, admm_lanes):
    import rsocl.solver.admm as admm_module
    from rsocl.device.context import Device

    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))  # where GPU_PROJECT_LANES applies
    monkeypatch.setattr(admm_module, "GPU_PROJECT_LANES", 1)  # rsocl's defaults at one lane, the variant at 4
    with peer.variant_context("rsocl lanes=4"):
        assert admm_module.GPU_PROJECT_LANES == 4
    assert admm_module.GPU_PROJECT_LANES == 1 and peer.is_variant("rsocl lanes=4")
    out = tmp_path / "peer.md"
    peer.main([*ARGS, "--project-lanes", "4", "--out", str(out)])
    assert 4 in admm_lanes and 1 in admm_lanes
    lines = out.read_text().splitlines()
    assert any(line.startswith("| case | rsocl lanes=4 / rsocl") for line in lines)
    same = [line for line in lines if line.startswith("| one set 8×8") and " dB, " in line]
    delta, largest = same[0].split("|")[3].split(" dB, ")
    assert abs(float(delta)) < 1e-4 and float(largest) < 1e-5


@pytest.mark.parametrize("value", ["3", "0"])
def test_bad_project_lanes_value_names_the_option(value):
    with pytest.raises(SystemExit, match="--project-lanes: powers of two"):
        peer.main([*ARGS, "--project-lanes", value])


def test_variant_cases_leave_other_cases_without_the_variant(tmp_path):
    out = tmp_path / "peer.md"
    peer.main([*ARGS, "--tv-one-launch", "2", "--variant-cases", "paper", "--out", str(out)])
    text = out.read_text()
    assert "rsocl one_launch=2" not in text  # size8 is not among the variant's cases


@pytest.mark.parametrize("value", ["3", "-1"])
def test_bad_one_launch_value_names_the_option(value):
    with pytest.raises(SystemExit, match="--tv-one-launch: values 0, 1 or 2"):
        peer.main([*ARGS, "--tv-one-launch", value])
