""":func:`~rsocl.model.interpolation.interp3d` computed on the OpenCL device.

The host finds each pixel's samples and sorts them by time (:func:`rsocl.model.interpolation.samples`,
``K`` values per pixel); one kernel launch (``kernels/interp.cl``) then writes every voxel of the
sub-frames asked for, for a whole batch of sets, straight into a device array: the warm start of a
self-tuned run, of each hold-out fold of the search, and of each tile. The NumPy
:func:`~rsocl.model.interpolation.interp3d` is the reference it is tested against.
"""

from __future__ import annotations

import numpy as np

from rsocl.device import pool
from rsocl.device.launch import batch_launches
from rsocl.device.program import c_type
from rsocl.model.interpolation import samples

__all__ = ["interp3d_device"]


def interp3d_device(op, g, valid=None, solved=None, *, out=None):
    """``interp3d`` of snapshots ``g`` over sub-frames ``solved``, on ``op``'s device and in its dtype.

    Parameters
    ----------
    op : rsocl.RollingShutterOperator
        Gives the rig, device, queue and dtype.
    g : array_like
        Snapshots ``(K, m, n)``, or a batch ``(B, K, m, n)`` (host arrays, units of ``g``).
    valid : array_like of bool or None
        Samples to use, the shape of ``g`` (None: all); as for ``interp3d``.
    solved : slice or None
        Sub-frames to write (indices into ``0 .. T-1``, step 1; None: all ``T``).
    out : pyopencl.array.Array or None
        Where to write, ``(len, m, n)`` (or ``(B, len, m, n)``) in ``op.dtype``; None: a new array.

    Returns
    -------
    pyopencl.array.Array
        ``(len(solved), m, n)``, or ``(B, len(solved), m, n)`` for a batch.
    """
    rig, queue, dtype = op.rig, op.queue, np.dtype(op.dtype)
    g = np.asarray(g, dtype=np.float64)
    one = g.ndim == 3
    K, shape = rig.n_channels, rig.shape
    if g.shape[-3:] != (K,) + shape or g.ndim not in (3, 4):
        raise ValueError(f"g must have shape (K, m, n) = {(K,) + shape} or (B, K, m, n), got {g.shape}")
    sets = g[None] if one else g
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != g.shape:
            raise ValueError(f"valid must have the shape of g {g.shape}, got {valid.shape}")
        valid = valid[None] if one else valid
    solved = slice(0, rig.T) if solved is None else solved
    first, stop = solved.indices(rig.T)[:2]
    length, B, mn = stop - first, len(sets), shape[0] * shape[1]
    if length < 1 or solved.step not in (None, 1):
        raise ValueError(f"solved must be a non-empty slice of 0 .. {rig.T - 1} with step 1, got {solved}")
    times, values = np.empty((B, K) + shape), np.empty((B, K) + shape)
    inverse = np.zeros((B, max(K - 1, 1)) + shape)
    count, fallback = np.empty((B,) + shape, dtype=np.int32), np.empty(B)
    for b in range(B):
        mask = None if valid is None or valid[b].all() else valid[b]
        found = samples(sets[b], rig, mask)
        times[b], values[b], count[b], fallback[b] = found.times, found.values, found.count, found.fallback
        with np.errstate(invalid="ignore", divide="ignore"):  # left-out samples: inf - inf
            span = np.diff(found.times, axis=0)
            inverse[b, : K - 1] = np.where(np.isfinite(span) & (span > 0), 1.0 / span, 0.0)
    want = (B, length) + shape
    if out is None:
        out = pool.empty(queue, want[1:] if one else want, dtype)
    elif out.dtype != dtype or out.size != int(np.prod(want)):
        raise ValueError(
            f"out must hold {want[1:] if one else want} values of {dtype.name}, got {out.shape} {out.dtype}"
        )
    kept = np.isfinite(times)  # a kept time is whole + part (kernels/interp.cl); the rest are not read
    whole = np.floor(np.where(kept, times, 0.0))
    up = [
        pool.to_device(queue, np.asarray(a, dtype=t))
        for a, t in (
            (whole, np.int32),
            (np.where(kept, times - whole, 0.0), dtype),
            (values, dtype),
            (inverse, dtype),
            (count, np.int32),
            (fallback, dtype),
        )
    ]
    prog = op.device.program(["interp.cl"], REAL=c_type(dtype), NCH=K)
    kernel = prog.interp3d
    per_set = length * mn
    group = op.device.group_limit(kernel, cap=64)
    for gsize, local, offset in batch_launches(per_set, B, group):
        kernel(
            queue,
            gsize,
            local,
            *(a.data for a in up),
            out.data,
            np.int32(first),
            np.int64(per_set),
            np.int64(mn),
            global_offset=offset,
        )
    return out
