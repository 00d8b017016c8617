"""The parameter search with its folds and candidates run as batches (rsocl.solver.search_batch), forced
on the CPU device here: the same scores to rounding and the same choices as one candidate and one fold
after the other; and TV's per-set temporal weights that let candidates share a batch."""

import numpy as np
import pyopencl.array as cla
import pytest

import rsocl
from rsocl.device.context import Device
from rsocl.model import reference as ref
from rsocl.model.curvature import default_scale
from rsocl.model.scenes import builtin_scene
from rsocl.solver.crossval import SearchSpace, tune_parameters
from rsocl.solver.search_batch import BatchedFolds, batches_pay

SHAPE = (16, 20)


def _search(runner, dtype, make=None):
    from rsocl.solver.problem import check_problem, check_settings, stage_on_device
    from rsocl.solver.request import make_regularizer

    rig = rsocl.Rig.paper_array(4, SHAPE, t_e=0.18e-3, t_r=35e-6)
    g = ref.forward(rig, builtin_scene(rig.shape, rig.T))
    tv = make_regularizer("tv")
    problem = check_problem(g, rig)
    settings = check_settings(iterations=20).settled_for(tv, dtype, scale=default_scale(rig))
    staged = stage_on_device(problem, tv, settings, dtype=dtype, start=True)
    lam = settings.lam
    space = SearchSpace({"temporal_weight": (1.0, 3.0, 30.0)}, (0.3 * lam, lam, 3 * lam))
    return tune_parameters(
        staged.op,
        staged.g,
        problem.g,
        make or (lambda options: make_regularizer("tv", options)),
        space,
        eta=settings.eta,
        iterations=8,
        patterns=[(8, 0), (4, 0), (4, 2)],
        runner=runner,
    )


def test_batched_folds_score_and_choose_as_the_folds_one_after_the_other(dtype):
    one_by_one = _search(None, dtype)
    batched = _search(BatchedFolds(), dtype)
    assert batched.chosen == one_by_one.chosen and batched.folds == 3
    keys = [{k: v for k, v in c.items() if k not in ("score", "blend")} for c in one_by_one.candidates]
    assert [{k: v for k, v in c.items() if k not in ("score", "blend")} for c in batched.candidates] == keys
    tol = 1e-4 if dtype == "float32" else 1e-10
    np.testing.assert_allclose(
        [c["score"] for c in batched.candidates], [c["score"] for c in one_by_one.candidates], rtol=tol
    )
    np.testing.assert_allclose(batched.blend, one_by_one.blend, rtol=tol, atol=tol)


def _spy_batches(monkeypatch, regs=None):
    """The candidates of every batch BatchedFolds runs, as lists of lam values (and each batch's
    regularizer appended to ``regs``)."""
    import rsocl.solver.search_batch as search_batch

    batches = []
    real = search_batch.BatchedFolds._run

    def spy(self, op, g_device, folds, reg, lams, *args):
        batches.append(list(lams))
        if regs is not None:
            regs.append(reg)
        return real(self, op, g_device, folds, reg, lams, *args)

    monkeypatch.setattr(search_batch.BatchedFolds, "_run", spy)
    return batches


def test_candidates_of_a_round_share_a_batch_and_choose_as_one_at_a_time(monkeypatch):
    batches = _spy_batches(monkeypatch)
    together = _search(BatchedFolds(), "float32")
    rounds = list(batches)
    batches.clear()
    alone = _search(BatchedFolds(capacity=1), "float32")
    assert all(len(b) == 1 for b in batches) and len(batches) > len(rounds)
    # the coarse temporal weights in one batch, then the midpoints with the lam round of every weight
    # the midpoints may leave chosen in another: the lam round finds its scores ready
    assert len(rounds) == 2 and len(rounds[0]) == 3 and 3 <= len(rounds[1]) <= 8
    assert together.chosen == alone.chosen
    keys = [{k: v for k, v in c.items() if k not in ("score", "blend")} for c in alone.candidates]
    assert [{k: v for k, v in c.items() if k not in ("score", "blend")} for c in together.candidates] == keys
    np.testing.assert_allclose(
        [c["score"] for c in together.candidates], [c["score"] for c in alone.candidates], rtol=1e-5
    )


def test_candidates_whose_regularizers_do_not_combine_run_in_groups(monkeypatch):
    """A regularizer without per-set options (here TV with none declared): candidates that differ in an
    option run in batches of their own, those that differ only in lam together; the same choices."""
    from rsocl_plugins.tv import TV

    class WholeBatchTV(TV):
        per_set_options = ()

    regs = []
    batches = _spy_batches(monkeypatch, regs)
    grouped = _search(BatchedFolds(), "float32", make=lambda options: WholeBatchTV(**options))
    assert all(type(r) is WholeBatchTV and "_set_weights" not in r.__dict__ for r in regs)  # one weight a batch
    assert any(len(b) > 1 for b in batches) and len(batches) > 2  # lam variants together, weights apart
    alone = _search(BatchedFolds(capacity=1), "float32")
    assert grouped.chosen == alone.chosen


def test_the_self_tuned_run_batches_its_search_only_where_batches_pay(device, monkeypatch):
    batches = _spy_batches(monkeypatch)
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: True))  # as a CPU device, whatever it is
    assert not batches_pay(device)  # a CPU device: candidates and folds one after the other
    rig = rsocl.Rig.paper_array(4, SHAPE, t_e=0.18e-3, t_r=35e-6)
    g = ref.forward(rig, builtin_scene(rig.shape, rig.T))
    cpu = rsocl.reconstruct(g, rig, iterations=20, device=device)
    assert not batches
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    gpu = rsocl.reconstruct(g, rig, iterations=20, device=device)
    assert batches and max(len(b) for b in batches) > 1
    assert gpu.params["tuning"]["chosen"] == cpu.params["tuning"]["chosen"]
    assert gpu.params["tuning"]["folds"] == cpu.params["tuning"]["folds"]


@pytest.mark.parametrize(
    "path", [dict(fused=0, one_launch=0), dict(fused=0, one_launch=1), dict(fused=0, one_launch=2), dict(fused=3)]
)
def test_tv_with_a_temporal_weight_per_set_denoises_each_set_as_alone(device, path):
    from rsocl_plugins.tv import TV

    rng = np.random.default_rng(5)
    x = rng.random((3, 9, 10, 12)).astype(np.float32)
    weights = [1.0, 3.0, 30.0]
    combined = TV.for_sets([TV(temporal_weight=w, iterations=6, **path) for w in weights])
    np.testing.assert_array_equal(combined.temporal_weights(3), weights)
    x_dev = cla.to_device(device.queue, x)
    got = combined.denoise(x_dev, [0.1, 0.2, 0.05]).get()
    for i, (w, lam) in enumerate(zip(weights, [0.1, 0.2, 0.05])):
        alone = TV(temporal_weight=w, iterations=6, **path).denoise(cla.to_device(device.queue, x[i]), lam).get()
        np.testing.assert_array_equal(got[i], alone)
    with pytest.raises(ValueError, match="temporal weights for 3 sets"):
        combined.denoise(cla.to_device(device.queue, x[:2]), 0.1)


def test_which_regularizers_combine_for_a_batch():
    from rsocl_plugins.dct import DCT
    from rsocl_plugins.tv import TV

    one = TV(temporal_weight=3.0)
    assert TV.for_sets([one, TV(temporal_weight=3.0)]) is one  # equal options: the first
    assert TV.for_sets([TV(temporal_weight=1.0), TV(temporal_weight=3.0, iterations=5)]) is None
    assert TV.for_sets([TV(temporal_weight=0.0), TV(temporal_weight=3.0)]) is None  # 2-D and 3-D
    assert TV.for_sets([one, DCT()]) is None
    assert DCT.for_sets([DCT(), DCT()]) is not None


@pytest.mark.parametrize("blocks", [1, 3])
def test_stacks_repeat_their_block_and_grow_from_a_smaller_stack(device, blocks):
    # the batch's stacks: count copies of a block of arrays end to end, made by doubling, or grown from
    # the stack of an earlier, smaller batch; a stack of another shape is not grown from
    from types import SimpleNamespace

    op = SimpleNamespace(queue=device.queue)
    host = np.random.default_rng(blocks).random((blocks, 3, 5)).astype(np.float32)
    block = [cla.to_device(device.queue, a) for a in host]
    last = None
    for count in (1, 2, 3, 4, 7, 8, 9):
        fresh = BatchedFolds._repeat(op, block, count)
        np.testing.assert_array_equal(fresh.get(), np.tile(host, (count, 1, 1)))
        grown = BatchedFolds._repeat(op, block, count, last)
        np.testing.assert_array_equal(grown.get(), np.tile(host, (count, 1, 1)))
        last = grown
    np.testing.assert_array_equal(BatchedFolds._repeat(op, block, 2, last).get(), np.tile(host, (2, 1, 1)))
    other = cla.zeros(device.queue, (2, 3, 4), np.float32)
    np.testing.assert_array_equal(BatchedFolds._repeat(op, block, 2, other).get(), np.tile(host, (2, 1, 1)))
