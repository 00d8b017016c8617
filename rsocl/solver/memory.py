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
from rsocl.model.operator import geometry_bytes
from rsocl.solver.admm import state_bytes

__all__ = ["per_set_value", "match_batch", "memory_bytes", "batch_memory", "problem_bytes", "workspace_memory"]


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


def problem_bytes(cube, K: int, dtype, sets: int, *, truth=False, start=False) -> int:
    """Device bytes a staged problem of ``sets`` sets of ``cube = (T, m, n)`` holds beside the solver:
    the operator's geometry (:func:`~rsocl.model.operator.geometry_bytes`), the snapshots
    (``K m n`` values per set), and per set the ground truth (``truth``) and the start cube kept
    beside theta (``start``: a given ``x0``, or the self-tuned run's ``interp3d`` start)."""
    cube = tuple(int(v) for v in cube)
    itemsize = np.dtype(dtype).itemsize
    pixels = cube[1] * cube[2]
    cube_bytes = int(np.prod(cube)) * itemsize
    return geometry_bytes(K, pixels, dtype) + sets * (K * pixels * itemsize + (int(truth) + int(start)) * cube_bytes)


def workspace_memory(cube, dtype, reg, sets: int) -> int:
    """Device bytes of ``reg``'s workspace for ``sets`` sets of ``cube``: a regularizer that takes
    batches (``reg.batched``) allocates it for the whole batch; the others work set by set, through
    two work arrays of one set."""
    cube = tuple(int(v) for v in cube)
    if getattr(reg, "batched", False):
        return reg.workspace_bytes((sets,) + cube, dtype)
    return reg.workspace_bytes(cube, dtype) + (2 * int(np.prod(cube)) * np.dtype(dtype).itemsize if sets > 1 else 0)


def batch_memory(cube, K: int, dtype, reg, projection: str, sets: int, *, truth=False, own_inverse=False,
                 start=False):
    """``(largest buffer, total)`` device bytes of an ADMM run on ``sets`` sets of ``cube = (T, m, n)``:
    the staged problem (:func:`problem_bytes`, with the ground truth when ``truth`` and a start cube
    when ``start``), the solver's arrays (:func:`~rsocl.solver.admm.state_bytes`) and the
    regularizer's workspace (:func:`workspace_memory`). Small per-set values (step lengths) and
    the partial sums of reductions are not counted.
    """
    cube = tuple(int(v) for v in cube)
    itemsize = np.dtype(dtype).itemsize
    cube_bytes = int(np.prod(cube)) * itemsize
    work = workspace_memory(cube, dtype, reg, sets)
    total = (problem_bytes(cube, K, dtype, sets, truth=truth, start=start)
             + state_bytes(cube, K, dtype, projection, sets, own_inverse) + work)
    return max(sets * cube_bytes, work if getattr(reg, "batched", False) else 0), total


def memory_bytes(op, reg, projection: str, sets: int, *, truth=False, own_inverse=False, start=False):
    """:func:`batch_memory` for the operator ``op`` (its solved sub-frames, channels and dtype)."""
    return batch_memory(op.domain_shape, op.K, op.dtype, reg, projection, sets, truth=truth, own_inverse=own_inverse,
                        start=start)
