"""Accurate sums of squares of device arrays.

Each work item adds a strided slice with Kahan compensation in the widest type
the device has (double where ``cl_khr_fp64`` exists), work groups reduce in
local memory, and the host adds the few hundred partials with ``math.fsum``.
Only the partials cross to the host, and :func:`sum_sq_diff_async` lets the host go on
enqueuing work while they do.
"""

from __future__ import annotations

import math

import numpy as np

from rsocl.device.context import c_type, device_for_queue

__all__ = ["sum_sq_diff", "sum_sq_diff_async", "PendingSum"]

LOCAL_SIZE = 64
MAX_GROUPS = 256


class PendingSum:
    """A sum of squares enqueued on the device, its partials on their way to the host.

    :meth:`result` waits for them and adds them with ``math.fsum``. Until then the host
    is free to enqueue more work, so the device never idles on a read-back.
    """

    def __init__(self, host, event):
        self._host, self._event, self._value = host, event, None

    def result(self) -> float:
        """The sum, as a Python float (waits for the device the first time)."""
        if self._value is None:
            self._event.wait()
            self._value = math.fsum(self._host.astype(np.float64).tolist())
        return self._value


def sum_sq_diff_async(a, b=None, weights=None) -> PendingSum:
    """:func:`sum_sq_diff` without waiting: enqueue it and return a :class:`PendingSum`.

    Each call has its own partials buffer, so several may be in flight at once.
    """
    import pyopencl as cl

    for name, other in (("b", b), ("weights", weights)):
        if other is not None and (other.shape != a.shape or other.dtype != a.dtype):
            raise ValueError(f"{name} must match a ({a.shape}, {a.dtype}), got {other.shape}, {other.dtype}")
    dev = device_for_queue(a.queue)
    acc = dev.acc_dtype
    prog = dev.program(["reduce.cl"], REAL=c_type(a.dtype), ACC=c_type(acc))
    local = min(LOCAL_SIZE, 1 << (int(dev.device.max_work_group_size).bit_length() - 1))
    groups = max(1, min(MAX_GROUPS, -(-a.size // local)))
    partials = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE, groups * acc.itemsize)
    prog.sum_sq_diff(a.queue, (groups * local,), (local,), a.data, None if b is None else b.data,
                     None if weights is None else weights.data, partials,
                     cl.LocalMemory(local * acc.itemsize), np.int32(a.size))
    host = np.empty(groups, acc)
    event = cl.enqueue_copy(a.queue, host, partials, is_blocking=False)
    return PendingSum(host, event)


def sum_sq_diff(a, b=None, weights=None) -> float:
    """``sum(weights * (a - b)**2)`` of device arrays, as a Python float.

    ``b`` None: ``a**2``; ``weights`` None: all ones.
    """
    return sum_sq_diff_async(a, b, weights).result()
