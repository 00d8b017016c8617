"""``benchmarks/blocks.py``: the block layouts it sweeps compute the same datacube, its page, its errors."""

import argparse
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import blocks  # noqa: E402

from rsocl.model import operator  # noqa: E402


def test_layouts_give_the_same_datacube_and_a_page(tmp_path):
    saved = operator.GPU_BLOCK
    out = tmp_path / "blocks.md"
    args = ["--cases", "size8", "--size-iterations", "2", "--rounds", "2", "--layouts", "8x4", "1x1", "2x3"]
    blocks.main([*args, "--as-gpu", "--out", str(out)])
    lines = out.read_text().splitlines()
    assert "| case | 8×4 | 1×1 | 2×3 |" in lines
    same = lines[lines.index(next(line for line in lines if line.startswith("## Same results"))) + 4]
    assert same.startswith("| one set 8×8") and all(float(c) < 1e-6 for c in same.strip("| ").split(" | ")[1:])
    assert operator.GPU_BLOCK == saved  # the sweep restores the default


@pytest.mark.parametrize("text", ["3x1", "1x0", "1", "axb"])
def test_bad_layout_names_the_form(text):
    with pytest.raises(argparse.ArgumentTypeError, match="layout|WxR"):
        blocks.layout(text)


def test_a_cpu_device_needs_as_gpu(device, capsys):
    if not device.is_cpu:
        pytest.skip("the device is not a CPU")
    with pytest.raises(SystemExit):
        blocks.main(["--cases", "size8", "--layouts", "8x4", "1x1"])
    assert "--as-gpu" in capsys.readouterr().err
