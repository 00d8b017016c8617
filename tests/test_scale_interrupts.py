"""Interrupts of tiled runs: the task in progress stops and is not retried, and a local cluster's workers are
out of the terminal's Ctrl-C."""

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

import rsocl
from rsocl.model.scenes import builtin_scene
from rsocl.scale import reconstruct_tiled
from rsocl.scale import runner as runner_module
from rsocl.solver.stop import Stopped, check_stop, stopping


@pytest.fixture
def _sigint_raises():
    """SIGINT raises KeyboardInterrupt, as in an interactive run (a suite started as a background job of a
    non-interactive shell has it ignored)."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def _problem(shape=(16, 16)):
    rig = rsocl.Rig.paper_array(4, shape, t_e=1.8e-4, t_r=3.5e-5)
    return rig, rsocl.RollingShutterOperator(rig).forward(builtin_scene(shape, rig.T, seed=0))


def test_a_run_of_a_thread_whose_stop_event_is_set_raises_stopped_at_its_next_booking():
    rig, g = _problem()
    event = threading.Event()
    event.set()  # before the run: it stops at its first booking (the first group of residuals read)
    with stopping(event), pytest.raises(Stopped):
        rsocl.reconstruct(g, rig, iterations=5, tune=False)
    seen = []

    def callback(it, residual, theta):
        seen.append(it)
        if it == 2:
            event.set()  # as another thread would

    event.clear()
    with stopping(event), pytest.raises(Stopped):
        rsocl.reconstruct(g, rig, iterations=10, tune=False, callback=callback)
    assert seen == [0, 1, 2]
    check_stop()  # outside the block: no event
    assert rsocl.reconstruct(g, rig, iterations=3, tune=False).iterations == 3


@pytest.mark.usefixtures("_sigint_raises")
def test_an_interrupt_stops_the_tile_in_progress_waits_for_it_and_retries_nothing(monkeypatch):
    pytest.importorskip("dask")
    rig, g = _problem()
    calls = []

    def slow(job, payload, settings):
        calls.append(job.label)
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C while this task runs
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            check_stop()
            time.sleep(0.005)
        raise AssertionError("the task was never stopped")

    monkeypatch.setattr(runner_module, "solve_tile", slow)
    with pytest.raises(KeyboardInterrupt):
        reconstruct_tiled(g, rig, tile=(8, 8), halo=2, iterations=5, tune=False, retries=2)
    assert len(calls) == 1  # no attempt after the interrupt, no other tile
    assert not [t for t in threading.enumerate() if t.name.startswith("rsocl-tiles")]  # waited for


def test_processes_started_while_a_local_cluster_starts_ignore_sigint():
    probe = [sys.executable, "-c", "import signal; print(signal.getsignal(signal.SIGINT) is signal.SIG_IGN)"]
    before = signal.getsignal(signal.SIGINT)
    with runner_module._sigint_ignored():
        inside = subprocess.run(probe, capture_output=True, text=True, check=True).stdout.strip()
    assert inside == "True" and signal.getsignal(signal.SIGINT) is before
    outside = subprocess.run(probe, capture_output=True, text=True, check=True).stdout.strip()
    assert outside == str(before is signal.SIG_IGN)
