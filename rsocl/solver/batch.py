"""Per-set values and device memory of a batch: ``B`` snapshot sets of one rig solved together.

A batch has a leading axis of ``B`` sets on the snapshots ``(B, K, m, n)`` and on the datacube
``(B, T, m, n)``; every kernel serves the whole batch in one launch. ``lam`` and ``eta`` may be one
number for every set or one per set. :func:`memory_bytes` is what a batch needs on the device;
:mod:`rsocl.solver.sets` sizes batches to a device and runs many sets through them.
"""

from __future__ import annotations

import numbers

import numpy as np

from rsocl.common import validation as check
from rsocl.solver.admm import state_bytes

__all__ = ["per_set_value", "match_batch", "memory_bytes", "batch_memory"]


def per_set_value(name: str, value):
    """A number ``>= 0`` (a float), or a sequence of them, one per set (a tuple of floats)."""
    if isinstance(value, numbers.Number) or np.ndim(value) == 0:
        return check.non_negative(name, value)
    if isinstance(value, (str, bytes)) or np.ndim(value) != 1 or len(value) == 0:
        raise ValueError(f"{name} must be a number >= 0 or a sequence of them, one per set, got {value!r}")
    return tuple(check.non_negative(f"{name}[{i}]", v) for i, v in enumerate(value))


def match_batch(name: str, value, batch):
    """Check that a per-set ``value`` (a tuple) has one entry per set of a batch of ``batch`` (None: one set)."""
    if not isinstance(value, tuple):
        return
    if batch is None:
        raise ValueError(f"{name} has {len(value)} values (one per set), but g holds one set (K, m, n); "
                         f"give g as (B, K, m, n) for a batch, or one number")
    if len(value) != batch:
        raise ValueError(f"{name} must have one value per set: {batch} for this batch, got {len(value)}")


def batch_memory(cube, K: int, dtype, reg, projection: str, sets: int, *, truth=False, own_inverse=False):
    """``(largest buffer, total)`` device bytes of an ADMM run on ``sets`` sets of ``cube = (T, m, n)``.

    A regularizer that takes batches (``reg.batched``) allocates its workspace for the whole batch;
    the others work set by set, through two work arrays of one set.
    """
    cube = tuple(int(v) for v in cube)
    itemsize = np.dtype(dtype).itemsize
    cube_bytes = int(np.prod(cube)) * itemsize
    if getattr(reg, "batched", False):
        work = reg.workspace_bytes((sets,) + cube, dtype)
    else:
        work = reg.workspace_bytes(cube, dtype) + (2 * cube_bytes if sets > 1 else 0)
    total = state_bytes(cube, K, dtype, projection, sets, own_inverse) + work
    if truth:
        total += sets * cube_bytes
    return max(sets * cube_bytes, work if getattr(reg, "batched", False) else 0), total


def memory_bytes(op, reg, projection: str, sets: int, *, truth=False, own_inverse=False):
    """:func:`batch_memory` for the operator ``op`` (its solved sub-frames, channels and dtype)."""
    return batch_memory(op.domain_shape, op.K, op.dtype, reg, projection, sets, truth=truth, own_inverse=own_inverse)
