"""Accurate sums of squares of device arrays.

Each work item adds a strided slice with Kahan compensation in the widest type
the device has (double where ``cl_khr_fp64`` exists), work groups reduce in
local memory, and the host adds the few hundred partials with ``math.fsum``.
Only the partials cross to the host.
"""

from __future__ import annotations

import math

import numpy as np

from .device import c_type, device_for_queue

__all__ = ["sum_sq_diff"]

LOCAL_SIZE = 64
MAX_GROUPS = 256


def sum_sq_diff(a, b=None, weights=None) -> float:
    """``sum(weights * (a - b)**2)`` of device arrays, as a Python float.

    ``b`` None: ``a**2``; ``weights`` None: all ones.
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
    key = ("partials", groups, acc.str)
    cache = dev.__dict__.setdefault("_reduction_buffers", {})
    if key not in cache:
        cache[key] = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE, groups * acc.itemsize)
    partials = cache[key]
    prog.sum_sq_diff(a.queue, (groups * local,), (local,), a.data, None if b is None else b.data,
                     None if weights is None else weights.data, partials,
                     cl.LocalMemory(local * acc.itemsize), np.int32(a.size))
    host = np.empty(groups, acc)
    cl.enqueue_copy(a.queue, host, partials)
    return math.fsum(host.astype(np.float64).tolist())
