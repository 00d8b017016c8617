"""rsocl.device.kernel.Kernel: by-value arguments set only when they change, buffers on every call."""

import numpy as np
import pytest

from rsocl.device.kernel import Kernel
from rsocl.device.program import Kernels

SOURCE = """
__kernel void fill(__global float *x, float value, int add)
{
    x[get_global_id(0)] = value + (float)add;
}
"""


@pytest.fixture()
def program(device):
    import pyopencl as cl

    return Kernels(cl.Program(device.context, SOURCE).build())


def _fill(kernel, queue, buf, value, add, **kw):
    kernel(queue, buf.shape, None, buf.data, np.float32(value), np.int32(add), **kw)
    return buf.get()


def test_changed_values_are_set_and_unchanged_ones_kept(program, device):
    import pyopencl.array as cla

    q = device.queue
    buf = cla.empty(q, 67, np.float32)
    assert isinstance(program.fill, Kernel) and program.fill is program.fill
    for value, add in [(1, 0), (2, 0), (2, 0), (2, 5), (1, 0), (1, 0), (np.nan, 0), (3, 0)]:
        got = _fill(program.fill, q, buf, value, add)
        np.testing.assert_array_equal(got, np.full(67, np.float32(value) + add, np.float32))


def test_buffers_are_set_on_every_call(program, device):
    import pyopencl.array as cla

    q = device.queue
    a, b = cla.zeros(q, 16, np.float32), cla.zeros(q, 16, np.float32)
    _fill(program.fill, q, a, 3, 0)
    np.testing.assert_array_equal(_fill(program.fill, q, b, 3, 0), np.full(16, 3, np.float32))
    np.testing.assert_array_equal(a.get(), np.full(16, 3, np.float32))


def test_set_arg_passes_through_and_keeps_the_record(program, device):
    import pyopencl as cl
    import pyopencl.array as cla

    q = device.queue
    buf = cla.empty(q, 8, np.float32)
    fill = program.fill
    _fill(fill, q, buf, 1, 0)
    fill.set_args(buf.data, np.float32(4), np.int32(0))  # as a user of the raw API would
    cl.enqueue_nd_range_kernel(q, fill.kernel, (8,), None)
    np.testing.assert_array_equal(buf.get(), np.full(8, 4, np.float32))
    np.testing.assert_array_equal(_fill(fill, q, buf, 1, 0), np.ones(8, np.float32))  # 1 again: set again


def test_offsets_wait_for_and_attributes(program, device):
    import pyopencl.array as cla

    q = device.queue
    buf = cla.zeros(q, 8, np.float32)
    event = program.fill(q, (4,), None, buf.data, np.float32(2), np.int32(0), global_offset=(4,))
    program.fill(q, (4,), None, buf.data, np.float32(2), np.int32(1), wait_for=[event])
    np.testing.assert_array_equal(buf.get(), [3, 3, 3, 3, 2, 2, 2, 2])
    assert program.fill.function_name == "fill" and "fill" in repr(program.fill)
    with pytest.raises(AttributeError):
        _ = program.fill._private


def test_array_arguments_are_set_on_every_call(device):
    # an array passed by value may be changed in place between calls: it must not be remembered
    import pyopencl as cl
    import pyopencl.array as cla

    prog = Kernels(
        cl.Program(
            device.context,
            """
        __kernel void put(__global float *x, float2 v) { x[0] = v.x; x[1] = v.y; }""",
        ).build()
    )
    q = device.queue
    buf = cla.zeros(q, 2, np.float32)
    v = np.array([1, 2], np.float32)
    prog.put(q, (1,), None, buf.data, v)
    np.testing.assert_array_equal(buf.get(), [1, 2])
    v[:] = [5, 6]
    prog.put(q, (1,), None, buf.data, v)
    np.testing.assert_array_equal(buf.get(), [5, 6])


def test_instances_have_their_own_arguments(program, device):
    import pyopencl.array as cla

    q = device.queue
    buf = cla.empty(q, 8, np.float32)
    one, two = program.instance("fill", 1), program.instance("fill", 2)
    assert one is program.instance("fill", 1) and one is not two and one is not program.fill
    for _ in range(2):  # alternate: neither may keep the other's value
        np.testing.assert_array_equal(_fill(one, q, buf, 1, 0), np.ones(8, np.float32))
        np.testing.assert_array_equal(_fill(two, q, buf, 2, 0), np.full(8, 2, np.float32))
        np.testing.assert_array_equal(_fill(program.fill, q, buf, 7, 0), np.full(8, 7, np.float32))
    with pytest.raises(AttributeError, match="no kernel 'nope'"):
        program.instance("nope", 0)


def test_instances_are_bounded(program, monkeypatch):
    monkeypatch.setattr(Kernels, "MAX_INSTANCES", 3)
    first = program.instance("fill", 0)
    for key in range(1, 5):
        program.instance("fill", key)
    assert len(program._instances.__dict__) == 3 and program.instance("fill", 4) is program.instance("fill", 4)
    assert program.instance("fill", 0) is not first  # the oldest went first, and comes back anew


def test_enqueue_launches_with_the_arguments_last_set(program, device):
    import pyopencl.array as cla

    q = device.queue
    a, b = cla.zeros(q, 8, np.float32), cla.zeros(q, 8, np.float32)
    fill = program.fill
    fill.set_args(a.data, np.float32(2), np.int32(1))
    fill.enqueue(q, (8,), None)
    np.testing.assert_array_equal(a.get(), np.full(8, 3, np.float32))
    fill.set_args(b.data, np.float32(2), np.int32(1))  # value arguments unchanged, the buffer changed
    fill.enqueue(q, (8,), None)
    np.testing.assert_array_equal(b.get(), np.full(8, 3, np.float32))


def test_a_leased_kernel_is_its_owners_alone_and_goes_to_the_next_owner_after_it(device):
    import gc

    prog = device.program(["tv.cl"], REAL="float", TEMPORAL=1)

    class Owner:
        pass

    first, second = Owner(), Owner()
    a, b = prog.lease("tv_step", first), prog.lease("tv_step", second)
    assert a is not b and a.function_name == "tv_step"
    assert prog.lease("tv_step", first) is not a  # a second lease of one owner: another object
    del first
    gc.collect()
    third = Owner()
    got = {id(prog.lease("tv_step", third)), id(prog.lease("tv_step", third))}
    assert id(a) in got and id(b) not in got  # the gone owner's objects, never the live owner's


def test_a_thread_launches_with_the_arguments_it_set_whatever_other_threads_set(program, device):
    # OpenCL kernel objects hold one set of arguments: threads launching one kernel have objects of their own
    import threading

    import pyopencl.array as cla

    q = device.queue
    mine, theirs = cla.zeros(q, 8, np.float32), cla.zeros(q, 8, np.float32)
    fill, one = program.fill, program.instance("fill", 1)
    fill.set_args(mine.data, np.float32(1), np.int32(0))
    one.set_args(mine.data, np.float32(3), np.int32(0))
    seen = []

    def other():  # between this thread's setting and its launch
        seen.extend([program.fill, program.instance("fill", 1)])
        program.fill(q, (8,), None, theirs.data, np.float32(2), np.int32(0))
        program.instance("fill", 1)(q, (8,), None, theirs.data, np.float32(4), np.int32(1))

    thread = threading.Thread(target=other)
    thread.start()
    thread.join()
    fill.enqueue(q, (8,), None)
    np.testing.assert_array_equal(mine.get(), np.full(8, 1, np.float32))
    one.enqueue(q, (8,), None)
    np.testing.assert_array_equal(mine.get(), np.full(8, 3, np.float32))
    np.testing.assert_array_equal(theirs.get(), np.full(8, 5, np.float32))
    assert seen[0] is not fill and seen[1] is not one
    assert program.fill is fill and program.instance("fill", 1) is one  # this thread's, kept
