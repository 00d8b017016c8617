"""The parameter search as batches: a candidate runs on every hold-out pattern at once, and the
candidates of one round of the search run together.

The folds of :func:`rsocl.solver.crossval.tune_parameters` are independent ADMM runs of the same
shape: the same snapshots and regularizer, each with its own fitted pixels, warm start and held-out
weights. :class:`BatchedFolds` stacks them into one batch of sets (the fitted pixels as each set's
valid pixels, :class:`~rsocl.solver.admm.ADMM`), so a candidate costs the launches of one run
instead of one per fold. Candidates whose regularizers combine into one (:meth:`Regularizer.for_sets
<rsocl.solver.regularizer.Regularizer.for_sets>`: TV's temporal weight may differ from set to set)
run as one batch of candidates x folds (:meth:`BatchedFolds.run_many`), up to
:func:`candidate_capacity` candidates at a time. Each set computes what its fold computes alone; the
sums over the folds are added in the same order, so the scores agree to float rounding and the search
makes the same choices. :func:`batches_pay` says on which devices the search takes it: where
launches, not the kernels' work, dominate a small run (not on a CPU device).
"""

from __future__ import annotations

import numpy as np

from rsocl.device import pool
from rsocl.device.reduction import sum_sq_diff_async
from rsocl.solver.admm import ADMM

__all__ = ["BatchedFolds", "batches_pay", "batch_bytes", "candidate_capacity", "CANDIDATES", "CANDIDATE_VOXELS"]

#: Candidates one batch of the search holds at most: the largest round of the TV search (two midpoints
#: and three ``lam`` values for each of the three temporal weights the midpoints may leave chosen).
CANDIDATES = 8
#: Voxels of one batch of the search (candidates x folds sets) at most: the largest batch of sets
#: :func:`rsocl.solver.sets.batch_size` gives a GPU (``GPU_BATCH_VOXELS``).
CANDIDATE_VOXELS = 2**24


def batches_pay(device) -> bool:
    """Whether the search runs its folds as one batch on ``device`` (an rsocl Device): on a device that is
    not a CPU, where a batch costs the launches of one set."""
    return not device.is_cpu


#: Datacubes of device memory one set of the search's batch takes at most: the ADMM's four, the TV's dual
#: in two copies of three planes, the warm start's copy and one to spare.
CUBES_PER_SET = 12
#: Share of the device's global memory the candidates of one batch may take.
MEMORY_SHARE = 0.25


def candidate_capacity(op, folds: int) -> int:
    """Candidates :class:`BatchedFolds` runs in one batch with ``folds`` hold-out patterns on ``op``'s
    datacube: :data:`CANDIDATES`, fewer where ``candidates x folds`` sets would pass
    :data:`CANDIDATE_VOXELS` or :data:`MEMORY_SHARE` of the device's memory at :data:`CUBES_PER_SET`
    datacubes a set (at least 1)."""
    voxels = int(folds) * int(np.prod(op.domain_shape))
    by_voxels = CANDIDATE_VOXELS // max(voxels, 1)
    by_memory = int(MEMORY_SHARE * op.device.global_mem_bytes) // max(voxels * CUBES_PER_SET * op.dtype.itemsize, 1)
    return max(1, min(CANDIDATES, by_voxels, by_memory))


def batch_bytes(op, folds: int) -> int:
    """Device bytes :class:`BatchedFolds` holds beside the folds' own arrays: per fold a copy of the
    snapshots, of the held-out weights and of the start's prediction, and of the warm start."""
    itemsize = np.dtype(op.dtype).itemsize
    snap = op.K * int(np.prod(op.domain_shape[1:])) * itemsize
    return int(folds) * (3 * snap + int(np.prod(op.domain_shape)) * itemsize)


class BatchedFolds:
    """A runner for :func:`~rsocl.solver.crossval.tune_parameters` (called as
    :func:`~rsocl.solver.folds.run_folds`) that runs a candidate on all folds as one batch, and with
    :meth:`run_many` several candidates on all folds as one batch.

    The batch (its stacked snapshots, warm starts, weights and predictions, and one
    :class:`~rsocl.solver.admm.ADMM` of one set per candidate and fold) is made for the first batch of
    its size and restarted for the next ones; a batch of another size grows its stacks from the last
    one's. A runner serves one search: the same snapshots and folds in every call.

    Parameters
    ----------
    capacity : int or None
        Candidates per batch at most; None: :func:`candidate_capacity`.

    Examples
    --------
    >>> from rsocl.solver.search_batch import BatchedFolds
    >>> runner = BatchedFolds()       # tune_parameters(..., runner=runner)
    """

    def __init__(self, capacity: int | None = None):
        self.solver, self.candidates, self.capacity = None, 0, capacity
        self.g = self.x0 = self.weights = self.predictions = None

    @staticmethod
    def _repeat(op, block, count, old=None):
        """One device array of ``count`` copies of ``block`` (device arrays of one shape) end to end: the
        block's arrays copied in once, or ``old`` (this function's result for fewer copies) copied whole,
        then the filled part copied after itself until full: ``len(block) + log2(count)`` copies or so,
        not ``count x len(block)``."""
        import pyopencl as cl

        size, total = block[0].nbytes, count * len(block)
        out = pool.empty(op.queue, (total,) + block[0].shape, block[0].dtype)
        if old is not None and old.shape[1:] == block[0].shape and old.shape[0] <= total:
            cl.enqueue_copy(op.queue, out.data, old.data, byte_count=old.nbytes)
            filled = old.shape[0]
        else:
            for i, a in enumerate(block):
                cl.enqueue_copy(op.queue, out.data, a.data, dst_offset=i * size, byte_count=size)
            filled = len(block)
        while filled < total:  # whole blocks: filled and total are multiples of len(block)
            step = min(filled, total - filled)
            cl.enqueue_copy(op.queue, out.data, out.data, dst_offset=filled * size, byte_count=step * size)
            filled += step
        return out

    def __call__(self, op, g_device, folds, reg, lam, *, eta, projection, iterations):
        return self.run_many(op, g_device, folds, [reg], [lam], eta=eta, projection=projection, iterations=iterations)[
            0
        ]

    def run_many(self, op, g_device, folds, regs, lams, *, eta, projection, iterations) -> list:
        """``[(err, moved), ...]``: :func:`~rsocl.solver.folds.run_folds` of each candidate ``(regs[i],
        lams[i])``, in batches of candidates whose regularizers combine (:meth:`Regularizer.for_sets
        <rsocl.solver.regularizer.Regularizer.for_sets>`), at most ``capacity`` candidates each."""
        capacity = self.capacity or candidate_capacity(op, len(folds))
        results: list = [None] * len(regs)
        todo = list(range(len(regs)))
        while todo:
            group = [todo[0]]
            reg = self._combined(regs, group, len(folds))
            for i in todo[1:]:
                wider = self._combined(regs, group + [i], len(folds)) if len(group) < capacity else None
                if wider is not None:
                    group, reg = group + [i], wider
            batch = self._run(op, g_device, folds, reg, [lams[i] for i in group], eta, projection, iterations)
            for i, result in zip(group, batch):
                results[i] = result
            todo = [i for i in todo if i not in group]
        return results

    @staticmethod
    def _combined(regs, group, folds):
        """The regularizer of candidates ``group`` with ``folds`` sets each (None: they do not combine)."""
        return type(regs[group[0]]).for_sets([regs[i] for i in group for _ in range(folds)])

    def _run(self, op, g_device, folds, reg, lams, eta, projection, iterations):
        count, F = len(lams), len(folds)
        if self.solver is None or self.candidates != count:
            self.solver = None  # freed before the new batch; the stacks grow from the last batch's
            stacks = (self.g, self.x0, self.weights, self.predictions)
            blocks = [[g_device]] + [[getattr(f, key) for f in folds] for key in ("x0", "weights", "start_prediction")]
            self.g, self.x0, self.weights, self.predictions = (
                self._repeat(op, block, count * F // len(block), old) for block, old in zip(blocks, stacks)
            )
            stacks = None
            valid = np.stack([np.asarray(fold.fit, bool) for fold in folds] * count)
            per_set = np.repeat(np.asarray(lams, np.float64), F)
            self.solver = ADMM(op, self.g, reg, lam=per_set, eta=eta, projection=projection, x0=self.x0, valid=valid)
            self.candidates = count
        else:
            self.solver.restart(reg, np.repeat(np.asarray(lams, np.float64), F), self.x0)
        solver = self.solver
        for _ in range(iterations):
            solver.step()
        op.forward_into(solver.theta, solver.hx)
        sets = count * F
        pending = (  # both enqueued before the host waits: one wait for the batch
            sum_sq_diff_async(self.g, solver.hx, weights=self.weights, sets=sets),
            sum_sq_diff_async(solver.hx, self.predictions, weights=self.weights, sets=sets),
        )
        errs, moved = (p.result().tolist() for p in pending)
        out = []
        for c in range(count):
            err_sum = moved_sum = 0.0
            for e, mv in zip(errs[c * F : (c + 1) * F], moved[c * F : (c + 1) * F]):  # in fold order
                err_sum += e
                moved_sum += mv
            out.append((err_sum, moved_sum))
        return out
