"""``rsocl.device.pool``: device buffers reused across calls, never a different result."""

import sys
from pathlib import Path

import numpy as np
import pytest

import rsocl
from rsocl.device import get_device, pool
from rsocl.model import reference as ref
from rsocl.model.scenes import builtin_scene

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import call_cost  # noqa: E402


@pytest.fixture
def queue():
    return get_device().queue


def test_a_freed_buffer_is_handed_out_again(queue):
    own = pool.BufferPool(queue)
    a = own(4000)
    assert own.made == 1
    del a
    b = own(4000)  # the same size: the same buffer
    assert own.made == 1 and own.held_bytes == 0
    c = own(3999)  # each size is a class of its own: never more bytes than asked
    assert own.made == 2 and c.size == 3999
    del b, c


def test_buffers_above_the_largest_are_made_each_time(queue):
    own = pool.BufferPool(queue, largest=1000)
    for _ in range(3):
        own(2000)
    assert own.made == 3 and own.held_bytes == 0


def test_held_buffers_stay_within_the_cap(queue):
    own = pool.BufferPool(queue, held=10_000)
    a, b = own(8192), own(8192)
    del a, b
    assert own.held_bytes >= 16384  # freed, held until the next allocation
    c = own(8192)  # would hold more than the cap: the held ones go back first
    assert own.held_bytes == 0 and own.made == 3
    del c
    own.release()
    assert own.held_bytes == 0


def test_a_device_short_of_memory_gets_the_held_buffers_back_first(queue):
    import pyopencl as cl

    own = pool.BufferPool(queue, largest=10_000)
    a = own(8192)
    del a
    assert own.held_bytes == 8192
    made = own._plain
    calls = []

    def short_once(nbytes):
        calls.append(own.held_bytes)
        if len(calls) == 1:
            raise cl.MemoryError("clCreateBuffer", cl.status_code.MEM_OBJECT_ALLOCATION_FAILURE, "short")
        return made(nbytes)

    own._plain = short_once
    big = own(20_000)
    assert calls == [8192, 0] and big.size == 20_000


@pytest.mark.parametrize("nbytes", [0, -8])
def test_bad_sizes_are_refused(queue, nbytes):
    with pytest.raises(ValueError, match="nbytes must be > 0"):
        pool.BufferPool(queue)(nbytes)


def test_arrays_from_the_pool_hold_what_was_put_in(queue):
    host = np.arange(37, dtype=np.float32)
    a = pool.to_device(queue, host)
    assert np.array_equal(pool.copy(a).get(), host)
    assert np.array_equal(pool.zeros(queue, (5, 3), np.int32).get(), np.zeros((5, 3), np.int32))
    assert pool.empty(queue, (4,), np.float64).shape == (4,)


def _case(m=12):
    rig = rsocl.Rig.paper_array(4, (m, m), 0.18e-3, 35e-6)
    return rig, ref.forward(rig, builtin_scene(rig.shape, rig.T)).astype(np.float32)


def _run(rig, g, **kw):
    return rsocl.reconstruct(g, rig, iterations=6, tune=False, x0="interp3d", **kw).datacube


@pytest.fixture
def made_each_call(monkeypatch):
    monkeypatch.setattr(pool, "ON_CPU", True)  # the CPU device of the tests pools as a GPU does

    def use(flag):
        monkeypatch.setattr(pool, "LARGEST_BYTES", 0 if flag else 64 * 2**20)

    return use


@pytest.mark.parametrize("as_gpu", [False, True])
def test_a_cpu_device_makes_its_buffers_and_other_devices_pool_them(monkeypatch, as_gpu):
    from rsocl.device.context import Device

    if as_gpu:
        monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    rig, g = _case()
    own = pool.pool_for(get_device().queue)
    own.release()  # what earlier tests left
    _run(rig, g)
    before = own.made
    _run(rig, g)
    assert (own.made == before) == (as_gpu or not get_device().is_cpu)
    if not as_gpu and get_device().is_cpu:
        assert own.made - before > 10 and own.held_bytes == 0


def test_a_warm_call_makes_no_buffer_and_gives_the_same_datacube(made_each_call):
    rig, g = _case()
    made_each_call(True)
    plain = _run(rig, g)
    made_each_call(False)
    own = pool.pool_for(get_device().queue)
    _run(rig, g)
    before = own.made
    pooled = _run(rig, g)
    assert own.made == before
    assert np.array_equal(pooled, plain)


def test_reused_buffers_full_of_nan_change_nothing(made_each_call, monkeypatch):
    """No code may read a buffer it did not write: the pool hands out what the last user left."""
    rig, g = _case()
    made_each_call(True)
    plain = _run(rig, g)
    made_each_call(False)
    queue = get_device().queue
    own = pool.pool_for(queue)
    sizes = []
    allocate = pool.BufferPool.__call__

    def recording(self, nbytes):
        sizes.append(int(nbytes))
        return allocate(self, nbytes)

    monkeypatch.setattr(pool.BufferPool, "__call__", recording)
    _run(rig, g)
    monkeypatch.setattr(pool.BufferPool, "__call__", allocate)
    assert len(sizes) > 10
    own.release()
    dirty = [pool.empty(queue, (-(-n // 4),), np.float32) for n in sizes]
    for a in dirty:
        a.fill(np.nan)
    del dirty  # freed into the pool, full of NaN, in every size class a call takes
    assert np.array_equal(_run(rig, g), plain)


def test_call_cost_page_compares_both_ways(tmp_path):
    out = tmp_path / "call_cost.md"
    call_cost.main(["--sizes", "6", "--rounds", "2", "--calls", "1", "--out", str(out)])
    text = out.read_text()
    assert "One buffer of" in text and "made / pooled" in text
    rows = [line for line in text.splitlines() if line.startswith("| 6×6")]
    assert len(rows) == len(call_cost.ITERATIONS)
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert float(cells[3].split()[0]) > 0 and float(cells[5].split()[0]) > 0
        made_pooled, made_plain = (int(v) for v in cells[6].split(","))
        assert made_pooled == 0 and made_plain > 0
        assert cells[7] == "yes"


@pytest.mark.parametrize("args", [["--rounds", "0"], ["--calls", "0"], ["--sizes", "1"]])
def test_call_cost_refuses_bad_counts(args, capsys):
    with pytest.raises(SystemExit):
        call_cost.main(args)
    assert "must be >=" in capsys.readouterr().err
