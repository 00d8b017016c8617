"""The projection's lanes (``PROJECT_LANES``, ``rsocl.solver.admm.GPU_PROJECT_LANES``): several work items per
block share the passes over its column, on the paths a GPU takes (the test device read as one that is not a
CPU). Every voxel's arithmetic is the same for any number of lanes, so the datacube and the residuals are the
ones of one lane (bit for bit on a CPU, within a few units in the last place on a GPU: ``same_arithmetic``)."""

import numpy as np
import pytest
from same_arithmetic import assert_same_arithmetic

import rsocl
import rsocl.model.operator as operator_module
import rsocl.solver.admm as admm_module
from rsocl.device.context import Device
from rsocl.model import reference as ref
from rsocl.solver.admm import lanes_that_fit


@pytest.fixture(scope="module")
def problem():
    """Paper array on a 9 x 11 grid, snapshots of random sub-frames."""
    rig = rsocl.Rig.paper_array(4, (9, 11), t_e=1e-4, t_r=3e-5)
    return rig, ref.forward(rig, np.random.default_rng(5).random((rig.T,) + rig.shape))


def _run(rig, g, monkeypatch, lanes, **kw):
    monkeypatch.setattr(admm_module, "GPU_PROJECT_LANES", lanes)
    kw = {"iterations": 6, "lam": 0.05, "eta": 0.3, "tune": False, **kw}
    return rsocl.reconstruct(g, rig, **kw)


@pytest.mark.parametrize("lanes", [2, 4, 8])
@pytest.mark.parametrize("block", [(1, 1), (8, 4)], ids=["pixel", "8x4-blocks"])
def test_lanes_give_the_datacube_and_residuals_of_one_lane(
    device, not_cpu, problem, monkeypatch, admm_made, lanes, block
):
    rig, g = problem
    monkeypatch.setattr(operator_module, "GPU_BLOCK", block)  # 8 x 4 blocks: 9 x 11 pixels cut two of them
    one = _run(rig, g, monkeypatch, 1)
    many = _run(rig, g, monkeypatch, lanes)
    # all the lanes asked, or the most whose work groups fit (a GPU's work groups of pixels may be 16 x 16)
    first, second = admm_made
    limit = device.group_limit(second.program.admm_project)
    assert first.lanes == 1
    assert second.lanes == lanes_that_fit(lanes, second.blocks[1], limit, device.max_work_item_sizes[1]) >= 2
    assert_same_arithmetic(many.datacube, one.datacube, device)
    assert_same_arithmetic(many.history["residual"], one.history["residual"], device, np.float32)


def test_a_batch_with_a_set_without_dual_update_gives_one_lanes_datacube(device, not_cpu, problem, monkeypatch):
    rig, g = problem
    batch = np.stack([g, 1.3 * g, 0.7 * g])
    kw = {"lam": [0.05, 0.2, 0.01], "eta": [0.3, 0.0, 0.1]}  # eta = 0: that set's dual is not updated
    one = _run(rig, batch, monkeypatch, 1, **kw)
    many = _run(rig, batch, monkeypatch, 4, **kw)
    assert_same_arithmetic(many.datacube, one.datacube, device)
    assert_same_arithmetic(many.history["residual"], one.history["residual"], device, np.float32)


@pytest.mark.not_under_oclgrind("the CPU lane choice of whole runs; the one-lane kernels run in the kept tests")
def test_a_cpu_device_and_a_regularizer_that_does_not_fuse_take_one_lane(problem, monkeypatch, admm_lanes):
    rig, g = problem
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: True))  # as a CPU device, whatever it is
    _run(rig, g, monkeypatch, 4)
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    _run(rig, g, monkeypatch, 4, regularizer="dct")  # no fused dual update: no column passes
    _run(rig, g, monkeypatch, 4)
    assert admm_lanes == [1, 1, 4]


def test_lanes_shrink_to_the_devices_work_group_limit(device, not_cpu, problem, monkeypatch, admm_lanes):
    rig, g = problem
    one = _run(rig, g, monkeypatch, 1)
    small = device.limited(max_work_group_size=16)  # groups of 11 blocks: one lane fits
    few = _run(rig, g, monkeypatch, 8, device=small)
    assert admm_lanes == [1, 1]
    assert_same_arithmetic(few.datacube, one.datacube, device)


@pytest.mark.parametrize(
    "lanes, local, limit, max_1, expected",
    [
        (8, (50, 1, 1), 1024, 1024, 8),
        (8, (50, 1, 1), 256, 1024, 4),  # 50 x 8 = 400 > 256
        (8, (50, 1, 1), 1024, 4, 4),  # dimension 1 holds 4 items at most
        (6, (16, 4, 1), 1024, 1024, 4),  # a power of two, up to the lanes asked for
        (8, (64, 1, 1), 64, 64, 1),
        (1, (1, 1, 1), 1024, 1024, 1),
    ],
)
def test_lanes_that_fit(lanes, local, limit, max_1, expected):
    assert lanes_that_fit(lanes, local, limit, max_1) == expected


@pytest.mark.not_under_oclgrind(
    "two self-tuned calls that compare lanes choices; the lanes kernels run in the kept tests"
)
def test_a_self_tuned_call_makes_one_lanes_choices_and_datacube(device, not_cpu, problem, monkeypatch, admm_lanes):
    rig, g = problem
    monkeypatch.setattr(admm_module, "GPU_PROJECT_LANES", 1)
    one = rsocl.reconstruct(g, rig, iterations=8)  # the search's batches restart their solvers per round
    monkeypatch.setattr(admm_module, "GPU_PROJECT_LANES", 4)
    many = rsocl.reconstruct(g, rig, iterations=8)
    half = len(admm_lanes) // 2  # each call: the search's batch solvers and the final run's
    assert half >= 2 and admm_lanes == [1] * half + [4] * half
    assert many.params["tuning"]["chosen"] == one.params["tuning"]["chosen"]
    assert_same_arithmetic(many.datacube, one.datacube, device)
