"""Accurate sums of squares of device arrays.

Each work item adds a strided slice with Kahan compensation in the widest type
the device has (double where ``cl_khr_fp64`` exists), work groups reduce in
local memory, and the host adds the few hundred partials with ``math.fsum``.
Only the partials cross to the host, and :func:`sum_sq_diff_async` lets the host go on
enqueuing work while they do. With ``sets=B`` the arrays are ``B`` sets end to end and one launch
gives each set its own sum.
"""

from __future__ import annotations

import math

import numpy as np

from rsocl.device import pool
from rsocl.device.context import device_for_queue
from rsocl.device.program import c_type

__all__ = ["sum_sq_diff", "sum_sq_diff_async", "PendingSum"]

LOCAL_SIZE = 64
MAX_GROUPS = 256


class PendingSum:
    """A sum of squares enqueued on the device, its partials on their way to the host.

    :meth:`result` waits for them and adds them with ``math.fsum``. Until then the host
    is free to enqueue more work, so the device never idles on a read-back.
    """

    def __init__(self, host, event, sets=None):
        self._host, self._event, self._value, self._sets = host, event, None, sets

    def result(self):
        """The sum, as a Python float, or one per set (float64 array) for ``sets=B`` (waits the first time)."""
        if self._value is None:
            self._event.wait()
            rows = self._host.astype(np.float64).reshape(self._sets or 1, -1)
            sums = [math.fsum(row.tolist()) for row in rows]
            self._value = sums[0] if self._sets is None else np.array(sums)
        return self._value


def sum_sq_diff_async(a, b=None, weights=None, sets=None) -> PendingSum:
    """:func:`sum_sq_diff` without waiting: enqueue it and return a :class:`PendingSum`.

    Each call has its own partials buffer, so several may be in flight at once.
    """
    import pyopencl as cl

    for name, other in (("b", b), ("weights", weights)):
        if other is not None and (other.shape != a.shape or other.dtype != a.dtype):
            raise ValueError(f"{name} must match a ({a.shape}, {a.dtype}), got {other.shape}, {other.dtype}")
    count = 1 if sets is None else int(sets)
    if count < 1 or a.size % count:
        raise ValueError(f"sets must be >= 1 and divide the {a.size} elements of a, got {sets!r}")
    per_set = a.size // count
    dev = device_for_queue(a.queue)
    acc = dev.acc_dtype
    prog = dev.program(["reduce.cl"], REAL=c_type(a.dtype), ACC=c_type(acc))
    local = 1 << (dev.group_limit(prog.sum_sq_diff, cap=LOCAL_SIZE).bit_length() - 1)  # a power of two
    groups = max(1, min(max(1, MAX_GROUPS // count), -(-per_set // local)))
    partials = pool.buffer(a.queue, count * groups * acc.itemsize)
    prog.sum_sq_diff(
        a.queue,
        (groups * local, count),
        (local, 1),
        a.data,
        None if b is None else b.data,
        None if weights is None else weights.data,
        partials,
        cl.LocalMemory(local * acc.itemsize),
        np.int32(per_set),
    )
    host = np.empty(count * groups, acc)
    event = cl.enqueue_copy(a.queue, host, partials, is_blocking=False)
    return PendingSum(host, event, sets)


def sum_sq_diff(a, b=None, weights=None, sets=None):
    """``sum(weights * (a - b)**2)`` of device arrays, as a Python float.

    ``b`` None: ``a**2``; ``weights`` None: all ones. ``sets=B``: the arrays hold ``B`` sets end to
    end (a leading batch axis); the result is then one sum per set, a float64 array of ``B``.
    """
    return sum_sq_diff_async(a, b, weights, sets).result()
