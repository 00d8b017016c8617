"""The solver's public steps: make_request -> prepare -> tune -> run, as rsocl.reconstruct runs them."""

import numpy as np
import pytest

import rsocl
from rsocl.model import reference as ref
from rsocl.model.scenes import builtin_scene
from rsocl.solver.pipeline import check_problem, make_request, prepare, run, tune


def _capture():
    rig = rsocl.Rig.paper_array(4, (16, 16), t_e=0.18e-3, t_r=35e-6)
    return rig, ref.forward(rig, builtin_scene(rig.shape, rig.T))


def test_the_steps_give_what_reconstruct_gives():
    rig, g = _capture()
    request = make_request(rig, iterations=10)
    prepared = prepare(request, check_problem(g, rig))
    choice = tune(prepared)
    result = run(prepared, choice)
    whole = rsocl.reconstruct(g, rig, iterations=10)
    np.testing.assert_array_equal(result.datacube, whole.datacube)
    assert choice is not None and result.params["tuning"]["chosen"] == whole.params["tuning"]["chosen"]
    timed = {"tuning", "seconds", "search_seconds"}  # reconstruct times its steps
    assert {k: v for k, v in result.params.items() if k not in timed} == {
        k: v for k, v in whole.params.items() if k not in timed
    }


def test_a_request_settles_once_and_keeps_what_the_caller_fixed():
    rig, g = _capture()
    fixed = make_request(rig, lam=0.05, regularizer_options={"temporal_weight": "2"}, tune=False)
    assert fixed.settings.lam == 0.05 and fixed.given.lam == 0.05 and fixed.regularizer.temporal_weight == 2.0
    assert fixed.search_space() is None and not fixed.starts_from_interpolation
    open_ = make_request(rig)
    space = open_.search_space()
    assert open_.given.lam is None and set(space.tunable) == {"temporal_weight"} and len(space.lam) == 3
    per_set = make_request(rig, sets=3, eta=[0.0, 0.2, 0.4], tune=False)
    part = per_set.for_sets(slice(1, 3))
    assert part.sets == 2 and part.settings.eta == (0.2, 0.4)
    assert part.settings.lam == make_request(rig, sets=2, eta=[0.2, 0.4], tune=False).settings.lam
    with pytest.raises(ValueError, match="blend = 0.5 moves the result towards the run's start"):
        make_request(rig, tune=False, blend=0.5)
    with pytest.raises(ValueError, match="lam has 2 values"):
        make_request(rig, lam=[0.1, 0.2])
