"""The TV's last launch left to the ADMM's next projection (``Regularizer.deferred_primal_on``), on the
paths a GPU takes (the test device read as one that is not a CPU): the same datacube, residuals and
choices as with the TV's own last launch, whatever reads ``theta`` between iterations (bit for bit on a
CPU, within a few units in the last place on a GPU: ``same_arithmetic``)."""

import numpy as np
import pytest
from same_arithmetic import assert_same_arithmetic

import rsocl
import rsocl_plugins.tv as tv_module
from rsocl.model import reference as ref
from rsocl.solver.admm import ADMM
from rsocl_plugins.tv import TV


@pytest.fixture(scope="module")
def problem():
    rig = rsocl.Rig.paper_array(4, (9, 11), t_e=1e-4, t_r=3e-5)
    truth = np.random.default_rng(3).random((rig.T,) + rig.shape)
    return rig, ref.forward(rig, truth), truth


def _undeferred(monkeypatch):
    monkeypatch.setattr(TV, "deferred_primal_on", lambda self, device: None)


def _run(rig, g, **kw):
    kw = {"iterations": 7, "lam": 0.05, "eta": 0.3, "tune": False, **kw}
    return rsocl.reconstruct(g, rig, **kw)


@pytest.mark.parametrize(
    "options",
    [{}, {"temporal_weight": 0.0}, {"one_launch": 2}, {"one_launch": 0}, {"iterations": 3}],
    ids=["default", "2-D", "pairs", "two-launches", "3-iterations"],
)
def test_one_set_equals_the_tvs_own_last_launch(device, not_cpu, problem, monkeypatch, options):
    rig, g, _ = problem
    deferred = _run(rig, g, regularizer_options=options)
    _undeferred(monkeypatch)
    own = _run(rig, g, regularizer_options=options)
    assert_same_arithmetic(deferred.datacube, own.datacube, device)
    assert_same_arithmetic(deferred.history["residual"], own.history["residual"], device, np.float32)


def test_a_batch_with_a_set_without_dual_update_equals_the_tvs_own(device, not_cpu, problem, monkeypatch):
    rig, g, _ = problem
    batch = np.stack([g, 1.3 * g, 0.7 * g])
    kw = {"lam": [0.05, 0.2, 0.01], "eta": [0.3, 0.0, 0.1]}  # eta = 0: that set's dual is not updated
    deferred = _run(rig, batch, **kw)
    _undeferred(monkeypatch)
    own = _run(rig, batch, **kw)
    assert_same_arithmetic(deferred.datacube, own.datacube, device)


@pytest.mark.parametrize("reader", ["callback", "truth"])
def test_runs_that_read_theta_every_iteration_equal_the_tvs_own(not_cpu, problem, monkeypatch, reader):
    rig, g, truth = problem
    seen = []
    kw = {"callback": lambda it, r, theta: seen.append(float(theta.get().sum()))} if reader == "callback" else {}
    deferred = _run(rig, g, truth=truth if reader == "truth" else None, **kw)
    first = list(seen)
    seen.clear()
    _undeferred(monkeypatch)
    own = _run(rig, g, truth=truth if reader == "truth" else None, **kw)
    assert np.array_equal(deferred.datacube, own.datacube)  # theta read: the TV's own launch each time
    assert seen == first
    if reader == "truth":
        assert np.array_equal(deferred.history["psnr"], own.history["psnr"])


class OwnLast(TV):
    """The TV with its own last launch."""

    def deferred_primal_on(self, device):
        return None


def _solver(rig, g, reg):
    import pyopencl.array as cla

    op = rsocl.RollingShutterOperator(rig, subframes=rig.sampled_range())
    return ADMM(op, cla.to_device(op.queue, g.astype(np.float32)), reg, lam=0.05, eta=0.3), op


def test_theta_read_between_steps_makes_the_deferred_launch_once(device, not_cpu, problem):
    rig, g, _ = problem
    solver, _ = _solver(rig, g, TV())
    reference, _ = _solver(rig, g, OwnLast())
    for _ in range(3):
        solver.step()
        reference.step()
    assert solver._pending and not reference._pending
    assert_same_arithmetic(solver.theta.get(), reference.theta.get(), device)  # read: the deferred launch is made
    assert not solver._pending
    for _ in range(2):  # the next projection does not make it again
        solver.step()
        reference.step()
    assert_same_arithmetic(solver.theta.get(), reference.theta.get(), device)
    assert_same_arithmetic(solver.b.get(), reference.b.get(), device)


def test_a_restart_with_a_denoiser_the_projection_does_not_fit_stops_deferring(not_cpu, problem):
    import pyopencl.array as cla

    rig, g, _ = problem
    solver, op = _solver(rig, g, TV(temporal_weight=3.0))
    x0 = cla.zeros(op.queue, op.domain_shape, np.float32)
    solver.step()
    solver.restart(TV(temporal_weight=0.0), 0.05, x0)  # 2-D: the program's projection takes three planes
    assert solver._defines is None
    fresh, _ = _solver(rig, g, TV(temporal_weight=0.0))
    for _ in range(4):
        solver.step()
        fresh.step()
    assert np.allclose(solver.theta.get(), fresh.theta.get(), rtol=0, atol=1e-6)


def test_a_bound_call_that_does_not_defer_is_run_as_it_is(not_cpu, problem, monkeypatch):
    rig, g, _ = problem
    bind = TV.bind
    monkeypatch.setattr(TV, "bind", lambda self, x, w, out, dual=None, defer=False: bind(self, x, w, out, dual))
    kept = _run(rig, g)
    _undeferred(monkeypatch)
    assert np.array_equal(kept.datacube, _run(rig, g).datacube)


def test_the_search_chooses_as_with_the_tvs_own_last_launch(device, not_cpu, problem, monkeypatch):
    rig, g, _ = problem
    tuned = rsocl.reconstruct(g, rig, iterations=12)
    _undeferred(monkeypatch)
    own = rsocl.reconstruct(g, rig, iterations=12)
    assert tuned.params["tuning"]["chosen"] == own.params["tuning"]["chosen"]
    assert_same_arithmetic(tuned.datacube, own.datacube, device)


def test_a_cpu_device_keeps_the_tvs_own_last_launch(device):
    assert TV().deferred_primal_on(device) is None or not device.is_cpu
    assert tv_module.TV(fused=2).deferred_primal_on(device) is None
