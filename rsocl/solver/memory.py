"""Device memory of a reconstruction, bytes: the one count every check and plan uses.

A run of ``B`` sets of one rig (a batch: a leading axis of ``B`` sets on the snapshots and the
datacube) holds the staged problem (:func:`problem_bytes`), the ADMM's arrays
(:func:`state_bytes`) and the configured regularizer's workspace (:func:`workspace_memory`,
from the instance's own options: TV with ``fused = k > 0`` keeps a second dual buffer);
:func:`batch_memory` adds them up and :func:`memory_need` does so for a rig before anything is
allocated. A self-tuned run also holds its parameter search beside the staged problem
(:func:`search_memory`, :func:`search_peak`). :func:`device_limit` says why a count does not fit
a device. :mod:`rsocl.solver.sets` sizes batches with these counts, ``rsocl plan`` and the
tiling decision (:mod:`rsocl.scale.proposal`) cost problems and tiles with them.
"""

from __future__ import annotations

import inspect

import numpy as np

from rsocl.model.operator import geometry_bytes
from rsocl.solver.holdout import default_patterns
from rsocl.solver.search_batch import batch_bytes, batches_pay, candidate_capacity

__all__ = [
    "state_bytes",
    "problem_bytes",
    "workspace_memory",
    "batch_memory",
    "memory_bytes",
    "memory_need",
    "search_memory",
    "search_peak",
    "device_limit",
]


def state_bytes(cube, K: int, dtype, projection: str, sets: int = 1, own_inverse: bool = False) -> int:
    """Device memory of :class:`~rsocl.solver.admm.ADMM`'s own arrays, bytes: theta, b, f, u (``cube``
    each), H·theta, the mask of valid snapshot pixels (counted always; allocated when some pixel is
    left out) and the per-set values of each of ``sets`` sets, and the inverse blocks (one set of
    them, or one per set)."""
    itemsize = np.dtype(dtype).itemsize
    per_cube = int(np.prod(cube)) * itemsize
    snap = K * int(np.prod(cube[1:])) * itemsize
    inverse = snap * K if projection == "exact" else snap
    return sets * (4 * per_cube + 2 * snap + 16) + inverse * (sets if own_inverse else 1)


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


def _workspace(reg, shape, dtype, device):
    """``reg.workspace_bytes`` on ``device`` where the regularizer's count takes one (TV's device default)."""
    if device is not None and "device" in inspect.signature(reg.workspace_bytes).parameters:
        return reg.workspace_bytes(shape, dtype, device=device)
    return reg.workspace_bytes(shape, dtype)


def workspace_memory(cube, dtype, reg, sets: int, device=None) -> int:
    """Device bytes of ``reg``'s workspace for ``sets`` sets of ``cube`` on ``device`` (None: counted as
    the regularizer counts without one): a regularizer that takes batches (``reg.batched``) allocates
    it for the whole batch; the others work set by set, through two work arrays of one set."""
    cube = tuple(int(v) for v in cube)
    if getattr(reg, "batched", False):
        return _workspace(reg, (sets,) + cube, dtype, device)
    return _workspace(reg, cube, dtype, device) + (2 * int(np.prod(cube)) * np.dtype(dtype).itemsize if sets > 1 else 0)


def batch_memory(
    cube, K: int, dtype, reg, projection: str, sets: int, *, truth=False, own_inverse=False, start=False, device=None
):
    """``(largest buffer, total)`` device bytes of an ADMM run on ``sets`` sets of ``cube = (T, m, n)``:
    the staged problem (:func:`problem_bytes`, with the ground truth when ``truth`` and a start cube
    when ``start``), the solver's arrays (:func:`state_bytes`) and the regularizer's workspace
    (:func:`workspace_memory`, on ``device`` when given). Small per-set values (step lengths) and
    the partial sums of reductions are not counted.
    """
    cube = tuple(int(v) for v in cube)
    itemsize = np.dtype(dtype).itemsize
    cube_bytes = int(np.prod(cube)) * itemsize
    work = workspace_memory(cube, dtype, reg, sets, device)
    total = (
        problem_bytes(cube, K, dtype, sets, truth=truth, start=start)
        + state_bytes(cube, K, dtype, projection, sets, own_inverse)
        + work
    )
    return max(sets * cube_bytes, work if getattr(reg, "batched", False) else 0), total


def memory_bytes(op, reg, projection: str, sets: int, *, truth=False, own_inverse=False, start=False):
    """:func:`batch_memory` for the operator ``op`` (its solved sub-frames, channels and dtype)."""
    return batch_memory(
        op.domain_shape,
        op.K,
        op.dtype,
        reg,
        projection,
        sets,
        truth=truth,
        own_inverse=own_inverse,
        start=start,
        device=op.device,
    )


def memory_need(rig, regularizer, *, dtype="float32", projection="exact", start=True) -> tuple:
    """``(largest buffer, total)`` device bytes of reconstructing ``rig``'s sampled sub-frames.

    From the shapes alone (nothing is allocated), by the count :func:`rsocl.reconstruct` checks
    before it runs (:func:`batch_memory` of one set): the operator's geometry and the snapshots,
    the datacube over :meth:`Rig.sampled_range`, the solver's arrays, the workspace of
    ``regularizer`` (the configured instance, whose options decide it) and, with ``start`` (the
    self-tuned default's ``interp3d`` start, or a given ``x0``), the start cube.
    """
    solved = rig.sampled_range()
    domain = (solved.stop - solved.start,) + rig.shape
    return batch_memory(domain, rig.n_channels, dtype, regularizer, projection, 1, start=start)


def search_memory(op, reg, projection: str, batch) -> int:
    """Device bytes the search allocates beside the staged problem, freed before the run's solver is
    made: per hold-out pattern (:func:`~rsocl.solver.holdout.default_patterns`) one set's ADMM arrays, its
    warm start, its warm start's prediction of the snapshots, held-out weights and regularizer
    workspace (a fold's solver keeps the previous candidate's regularizer until its own turn); where
    batches pay, the solver of the candidates x folds batch (:func:`~rsocl.solver.search_batch.candidate_capacity`
    candidates) and its stacked copies (:func:`~rsocl.solver.search_batch.batch_bytes`); and for
    a batch (``batch`` sets, None: one set) the first set staged on its own (operator geometry and
    snapshots)."""
    cube = op.domain_shape
    itemsize = np.dtype(op.dtype).itemsize
    snap = op.K * int(np.prod(cube[1:])) * itemsize
    solver = state_bytes(cube, op.K, op.dtype, projection, 1) + workspace_memory(cube, op.dtype, reg, 1, op.device)
    per_fold = solver + int(np.prod(cube)) * itemsize + 2 * snap
    folds = len(default_patterns(op.rig.shape, op.K))
    extra = folds * per_fold
    if batches_pay(op.device):  # candidates x folds run as one batch (rsocl.solver.search_batch)
        candidates = candidate_capacity(op, folds)
        extra += (candidates - 1) * folds * solver + batch_bytes(op, candidates * folds)
    if batch is not None:
        extra += problem_bytes(cube, op.K, op.dtype, 1)
    return extra


def search_peak(op, reg, projection: str, batch, *, truth=False, start=False) -> int:
    """Device bytes held while the search runs: the staged problem of ``batch`` sets (None: one set;
    :func:`problem_bytes`, with a ground truth and a given start cube per set when ``truth``,
    ``start``) and :func:`search_memory`."""
    held = problem_bytes(op.domain_shape, op.K, op.dtype, batch or 1, truth=truth, start=start)
    return held + search_memory(op, reg, projection, batch)


def device_limit(device, largest: int, total: int) -> str | None:
    """Why buffers of ``largest`` and ``total`` bytes do not fit ``device`` (None when they fit)."""
    if largest > device.max_alloc_bytes:
        return (
            f"a buffer of {largest / 2**20:.1f} MiB, above the device's largest allocation of "
            f"{device.max_alloc_bytes / 2**20:.1f} MiB"
        )
    if total > device.global_mem_bytes:
        return f"{total / 2**20:.1f} MiB in all, above the device's {device.global_mem_bytes / 2**20:.1f} MiB"
    return None
