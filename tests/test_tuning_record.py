"""An earlier choice given back as ``tune=Tuning(...)``, and the record ``Tuning.from_params`` reads: checked
before any device work, with errors that name ``tune`` or ``params["tuning"]``; what a run records runs again."""

import json

import numpy as np
import pytest

import rsocl
from rsocl.solver import pipeline
from rsocl.solver.crossval import Tuning
from rsocl.solver.request import make_request


@pytest.fixture(scope="module")
def capture():
    rig = rsocl.Rig.paper_array(4, shape=(12, 12), t_e=180e-6, t_r=35e-6)
    g = rsocl.RollingShutterOperator(rig).forward(rsocl.builtin_scene(rig.shape, rig.T))
    return rig, g


@pytest.fixture
def no_staging(monkeypatch):
    """Staging on the device fails the test: a check that passes it came too late."""

    def staged(*args, **kwargs):
        raise AssertionError("the problem was staged on the device before the check")

    monkeypatch.setattr(pipeline, "stage_on_device", staged)


BAD_CHOICES = [
    (Tuning(chosen={"temporal_weight": 3.0}), r"tune\.chosen must hold 'lam'"),
    (Tuning(chosen={"lam": float("nan")}), r"tune\.chosen\['lam'\] must be finite"),
    (Tuning(chosen={"lam": -0.1}), r"tune\.chosen\['lam'\] must be >= 0, got -0\.1"),
    (Tuning(chosen={"lam": None}), r"tune\.chosen\['lam'\] must be a finite real number"),
    (Tuning(chosen={"lam": "0.1"}), r"tune\.chosen\['lam'\] must be a finite real number"),
    (Tuning(chosen={"lam": 0.1, "temporal_weight": -1.0}), r"tune\.chosen\['temporal_weight'\] = -1\.0 .*\[0, 1000"),
    (Tuning(chosen={"lam": 0.1, "temporal_weight": float("inf")}), r"tune\.chosen\['temporal_weight'\]"),
    (Tuning(chosen={"lam": 0.1, "step": 5.0}), r"tune\.chosen\['step'\] = 5\.0 .*\[0\.01, 1\.0\]"),
    (Tuning(chosen={"lam": 0.1, "colour": 1.0}), r"tune: the earlier Tuning chose \['colour'\]"),
    (Tuning(chosen=None), r"tune\.chosen must be a dict"),
    (Tuning(chosen={"lam": 0.1}, blend=2.0), r"tune\.blend must be in \[0, 1\] or None, got 2\.0"),
    (Tuning(chosen={"lam": 0.1}, blend=-0.5), r"tune\.blend must be in \[0, 1\] or None, got -0\.5"),
    (Tuning(chosen={"lam": 0.1}, blend=float("nan")), r"tune\.blend must be in \[0, 1\] or None, got nan"),
    (Tuning(chosen={"lam": 0.1}, blend="half"), r"tune\.blend must be in \[0, 1\] or None, got 'half'"),
]


@pytest.mark.parametrize("choice, message", BAD_CHOICES)
def test_a_bad_earlier_choice_is_refused_before_the_device_naming_tune(capture, no_staging, choice, message):
    rig, g = capture
    with pytest.raises(ValueError, match=message):
        make_request(rig, tune=choice)
    with pytest.raises(ValueError, match=message):
        rsocl.reconstruct(g, rig, iterations=3, tune=choice)
    with pytest.raises(ValueError, match=message):
        rsocl.reconstruct_sets(np.stack([g, g]), rig, iterations=3, tune=choice)


def test_the_regularizers_own_checks_judge_the_chosen_options(capture, no_staging):
    """An option value the regularizer's constructor refuses (beyond its Option's range) is refused too."""
    rig, _ = capture
    with pytest.raises(ValueError, match=r"tune\.chosen\['mode'\] = '4d' .*'dct'.*mode must be one of"):
        make_request(rig, "dct", tune=Tuning(chosen={"lam": 0.1, "mode": "4d"}))
    assert make_request(rig, "dct", tune=Tuning(chosen={"lam": 0.1, "mode": "2d"})).tune.chosen["mode"] == "2d"


def test_a_choice_without_lam_runs_when_the_caller_gives_lam(capture):
    rig, g = capture
    with_lam = rsocl.reconstruct(g, rig, iterations=3, lam=0.05, tune=Tuning(chosen={"temporal_weight": 2.0}))
    assert with_lam.params["lam"] == 0.05 and with_lam.params["regularizer_options"]["temporal_weight"] == 2.0
    request = make_request(rig, tune=Tuning(chosen={"lam": 0, "temporal_weight": 2}, blend=1))
    assert request.tune.chosen == {"lam": 0.0, "temporal_weight": 2} and request.tune.blend == 1.0
    assert isinstance(request.tune.chosen["lam"], float) and isinstance(request.tune.blend, float)


def test_what_a_run_records_runs_again_bit_for_bit(capture):
    """``params["tuning"]`` through JSON and ``Tuning.from_params`` reruns to the same cube; the recorded
    ``params["blend"]`` and ``params["tuning"]["blend"]`` are accepted when given back."""
    rig, g = capture
    first = rsocl.reconstruct(g, rig, iterations=8)
    record = json.loads(json.dumps(first.params, allow_nan=False))
    choice = Tuning.from_params(record["tuning"])
    assert choice.blend == first.params["tuning"]["blend"] is not None
    again = rsocl.reconstruct(g, rig, iterations=8, tune=choice)
    np.testing.assert_array_equal(again.datacube, first.datacube)
    assert again.params["blend"] == first.params["blend"] and again.params["tuning"] == first.params["tuning"]
    given = rsocl.reconstruct(g, rig, iterations=8, tune=choice, blend=record["blend"])
    np.testing.assert_array_equal(given.datacube, first.datacube)
    for blend in (0.0, 1.0, None):
        rsocl.reconstruct(g, rig, iterations=2, tune=Tuning(chosen={"lam": 0.1}, blend=blend))


def test_from_params_names_the_record_it_expects(capture):
    rig, g = capture
    fixed = rsocl.reconstruct(g, rig, iterations=2, tune=False)
    tuned = rsocl.reconstruct(g, rig, iterations=2)
    assert fixed.params["tuning"] is None
    expected = r'params\["tuning"\] must be the record of a tuned run, a dict with a "chosen" dict'
    with pytest.raises(ValueError, match=expected + r".*got None: a run with tune=False"):
        Tuning.from_params(fixed.params["tuning"])
    with pytest.raises(ValueError, match=expected + r'.*got the whole Result\.params: pass result\.params\["tuning"\]'):
        Tuning.from_params(tuned.params)
    without = {k: v for k, v in tuned.params["tuning"].items() if k != "chosen"}
    with pytest.raises(ValueError, match=expected + r".*got a dict with no 'chosen'"):
        Tuning.from_params(without)
    with pytest.raises(ValueError, match=expected + r".*got a dict with chosen = None"):
        Tuning.from_params({**tuned.params["tuning"], "chosen": None})
    with pytest.raises(ValueError, match=expected + r".*got a str"):
        Tuning.from_params("tuning")
    assert Tuning.from_params(tuned.params["tuning"]).chosen == tuned.params["tuning"]["chosen"]
