"""The parameter search with its folds run as one batch (rsocl.solver.search_batch), forced on the
CPU device here: the same scores to rounding and the same choices as the folds run one after the other."""

import numpy as np

import rsocl
from rsocl.device.context import Device
from rsocl.model import reference as ref
from rsocl.model.curvature import default_scale
from rsocl.model.scenes import builtin_scene
from rsocl.solver.crossval import SearchSpace, tune_parameters
from rsocl.solver.search_batch import BatchedFolds, batches_pay

SHAPE = (16, 20)


def _search(runner, dtype):
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
        lambda options: make_regularizer("tv", options),
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


def test_the_self_tuned_run_batches_its_search_only_where_batches_pay(device, monkeypatch):
    import rsocl.solver.search_batch as search_batch

    assert not batches_pay(device)  # the CPU device: folds one after the other
    calls = []
    real = search_batch.BatchedFolds.__call__

    def spy(self, *args, **kwargs):
        calls.append(1)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(search_batch.BatchedFolds, "__call__", spy)
    rig = rsocl.Rig.paper_array(4, SHAPE, t_e=0.18e-3, t_r=35e-6)
    g = ref.forward(rig, builtin_scene(rig.shape, rig.T))
    cpu = rsocl.reconstruct(g, rig, iterations=20, device=device)
    assert not calls
    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    gpu = rsocl.reconstruct(g, rig, iterations=20, device=device)
    assert calls
    assert gpu.params["tuning"]["chosen"] == cpu.params["tuning"]["chosen"]
    assert gpu.params["tuning"]["folds"] == cpu.params["tuning"]["folds"]
