"""PresetKernel: by-value arguments set once, buffers every call, and its own kernel instance."""

import numpy as np
import pytest

from rsocl.device import Kernels
from rsocl.launch import element_launches
from rsocl.preset import PresetKernel

SOURCE = """
__kernel void fill(__global float *x, float value, int add)
{
    x[get_global_id(0)] = value + (float)add;
}
"""


@pytest.fixture(scope="module")
def program(device):
    import pyopencl as cl

    return Kernels(cl.Program(device.context, SOURCE).build())


def _fill(kernel, queue, buf, value, add):
    import pyopencl as cl

    kernel(queue, buf.data, np.float32(value), np.int32(add))
    out = np.empty(buf.shape, np.float32)
    cl.enqueue_copy(queue, out, buf.data)
    return out


def test_changed_values_are_set_and_unchanged_ones_kept(program, device):
    import pyopencl.array as cla

    q = device.queue
    buf = cla.empty(q, 67, np.float32)                    # 67 (prime): two launches (exact grids)
    fill = PresetKernel(program, "fill", element_launches(67))
    assert len(fill.launches) == 2
    for value, add in [(1, 0), (2, 0), (2, 0), (2, 5), (1, 0), (1, 0)]:
        np.testing.assert_array_equal(_fill(fill, q, buf, value, add), np.full(67, value + add, np.float32))


def test_buffers_are_set_on_every_call(program, device):
    import pyopencl.array as cla

    q = device.queue
    a, b = cla.zeros(q, 16, np.float32), cla.zeros(q, 16, np.float32)
    fill = PresetKernel(program, "fill", element_launches(16))
    _fill(fill, q, a, 3, 0)
    np.testing.assert_array_equal(_fill(fill, q, b, 3, 0), np.full(16, 3, np.float32))
    np.testing.assert_array_equal(a.get(), np.full(16, 3, np.float32))


def test_instances_do_not_share_arguments(program, device):
    import pyopencl.array as cla

    q = device.queue
    buf = cla.empty(q, 8, np.float32)
    one, two = (PresetKernel(program, "fill", element_launches(8)) for _ in range(2))
    for _ in range(2):                                    # alternate: neither may see the other's value
        np.testing.assert_array_equal(_fill(one, q, buf, 1, 0), np.ones(8, np.float32))
        np.testing.assert_array_equal(_fill(two, q, buf, 2, 0), np.full(8, 2, np.float32))
        # nor a plain call through the shared program object
        program.fill(q, (8,), None, buf.data, np.float32(7), np.int32(0))
    assert "fill" in repr(one)
