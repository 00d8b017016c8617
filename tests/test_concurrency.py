"""rsocl from several threads at once, and in processes forked after it used OpenCL.

Threads share one device (context, queue, programs): each result equals the same call's alone, the device
and a program asked for at once are made once, and the process's warning filters stay as they were. A
process forked after rsocl called the OpenCL runtime gets a clear error instead of waiting for ever.
"""

import os
import select
import signal
import sys
import threading
import time
import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import rsocl
from rsocl.device import context
from rsocl.model import reference

from conftest import SMALL


@pytest.fixture()
def switching():
    """Threads switched as often as the interpreter can (every few bytecodes), so that a step another
    thread may come between shows."""
    before = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)
    yield
    sys.setswitchinterval(before)


def _rigs(count):
    side = 10 if SMALL else 24
    return [rsocl.Rig.paper_array(4, (side + 4 * k, side + 2 * k), t_e=1.8e-4, t_r=3.5e-5) for k in range(count)]


@pytest.mark.not_under_oclgrind("threads' host logic; the operator's kernels run in test_operator.py")
def test_operators_used_from_threads_give_each_its_own_result(device, switching):
    rigs = _rigs(4)
    ops = [rsocl.RollingShutterOperator(r) for r in rigs]
    rng = np.random.default_rng(3)
    xs = [rng.random(op.domain_shape, dtype=np.float32) for op in ops]
    ys = [rng.random(op.range_shape, dtype=np.float32) for op in ops]
    alone = [(op.forward(x), op.adjoint(y)) for op, x, y in zip(ops, xs, ys)]

    def wrong(k, op):  # ``op``: the shared operator or one of the thread's own
        bad = 0
        for _ in range(10 if SMALL else 40):
            bad += not np.array_equal(op.forward(xs[k]), alone[k][0])
            bad += not np.array_equal(op.adjoint(ys[k]), alone[k][1])
        return bad

    with ThreadPoolExecutor(4) as pool:
        shared = list(pool.map(lambda k: wrong(k, ops[k]), range(4)))
        own = list(pool.map(lambda k: wrong(k, rsocl.RollingShutterOperator(rigs[k])), range(4)))
    assert shared == own == [0, 0, 0, 0]
    assert all(np.array_equal(op.forward(x), a[0]) for op, x, a in zip(ops, xs, alone))  # and alone again after


@pytest.mark.not_under_oclgrind("whole runs from threads (host logic); their kernels run in the other tests")
@pytest.mark.parametrize("tune", [False, True], ids=["fixed", "tuned"])
def test_reconstructions_from_threads_equal_each_alone_bit_for_bit(device, switching, tune):
    rigs = _rigs(3 if tune else 4)
    sets = [reference.forward(r, rsocl.builtin_scene(r.shape, r.T)) for r in rigs]
    kw = dict(iterations=8 if tune else 30, tv_iterations=4, tune=tune)

    def run(k):
        return rsocl.reconstruct(sets[k], rigs[k], **kw).datacube

    alone = [run(k) for k in range(len(rigs))]
    with ThreadPoolExecutor(len(rigs)) as pool:
        together = list(pool.map(run, range(len(rigs))))
    assert [np.array_equal(a, b) for a, b in zip(alone, together)] == [True] * len(rigs)


def _at_once(count, call):
    """``call()`` from ``count`` threads released together; their results."""
    start = threading.Barrier(count)

    def one(_):
        start.wait()
        return call()

    with ThreadPoolExecutor(count) as pool:
        return list(pool.map(one, range(count)))


def test_threads_asking_for_the_device_at_once_share_one(device, monkeypatch):
    import functools

    monkeypatch.setattr(context, "_device_for", functools.cache(context._device_for.__wrapped__))  # none made yet
    pick = context._pick

    def slow_pick(*args):  # as slow as a GPU's first context: the threads all come while it is made
        time.sleep(0.2)
        return pick(*args)

    monkeypatch.setattr(context, "_pick", slow_pick)
    made = _at_once(4, rsocl.get_device)
    assert len({id(d) for d in made}) == 1 and len({d.context.int_ptr for d in made}) == 1


def test_threads_asking_for_a_program_at_once_share_one_build(device):
    fresh = device.limited()  # a program cache of its own, empty
    built = _at_once(4, lambda: fresh.program(["reduce.cl"], REAL="float", ACC="float"))
    assert len({id(p) for p in built}) == 1


def test_reconstruct_sets_leaves_the_warning_filters_to_other_threads(device):
    rig = _rigs(1)[0]
    g = reference.forward(rig, rsocl.builtin_scene(rig.shape, rig.T))
    before, during = list(warnings.filters), []

    def look(iteration, residual, theta):  # while the batch runs, as another thread would see them
        during.append(list(warnings.filters))

    rsocl.reconstruct_sets(np.stack([g, g]), rig, batch=1, iterations=2, tune=False, callback=look)
    assert during and all(f == before for f in during)


def _in_a_fork(child, seconds=60):
    """Run ``child()`` (returning a short text) in a forked process; its text, or None when it did not end in
    ``seconds`` (then it is killed)."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never back into pytest
        try:
            os.close(read)
            try:
                said = child()
            except BaseException as exc:  # noqa: BLE001 - the parent reads what happened
                said = f"{type(exc).__name__}: {exc}"
            os.write(write, said.encode()[:4000])
        finally:
            os._exit(0)
    os.close(write)
    try:
        ready, _, _ = select.select([read], [], [], seconds)
        text = os.read(read, 4000).decode() if ready else None
    finally:
        os.close(read)
    if text is None:
        os.kill(pid, signal.SIGKILL)
    deadline = time.monotonic() + seconds
    while os.waitpid(pid, os.WNOHANG) == (0, 0) and time.monotonic() < deadline:
        time.sleep(0.05)
    return text


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")
def test_a_process_forked_after_opencl_was_used_is_told_so_and_does_not_hang(device):
    rig = _rigs(1)[0]
    op = rsocl.RollingShutterOperator(rig)
    x = np.ones(op.domain_shape, np.float32)
    op.forward(x)  # the runtime is started in this process

    def child():
        said = []
        for call in (lambda: op.forward(x), lambda: rsocl.reconstruct(op.forward(x), rig, iterations=2)):
            try:
                call()
                said.append("ran")
            except RuntimeError as exc:
                said.append(str(exc))
        return "\n".join(said)

    said = _in_a_fork(child)
    assert said is not None, "the forked child hung"
    lines = said.splitlines()
    assert len(lines) == 2 and all("was forked from process" in line and "'spawn'" in line for line in lines), said
    np.testing.assert_array_equal(op.forward(x), op.forward(x))  # the parent goes on
