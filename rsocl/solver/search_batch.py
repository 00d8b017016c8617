"""The parameter search's folds as one batch: a candidate runs on every hold-out pattern at once.

The folds of :func:`rsocl.solver.crossval.tune_parameters` are independent ADMM runs of the same
shape: the same snapshots and regularizer, each with its own fitted pixels, warm start and held-out
weights. :class:`BatchedFolds` stacks them into one batch of sets (the fitted pixels as each set's
valid pixels, :class:`~rsocl.solver.admm.ADMM`), so a candidate costs the launches of one run
instead of one per fold. Each set computes what its fold computes alone; the sums over the folds are
added in the same order, so the scores agree to float rounding and the search makes the same
choices. :func:`batches_pay` says on which devices the search takes it: where launches, not the
kernels' work, dominate a small run (not on a CPU device).
"""

from __future__ import annotations

import numpy as np

from rsocl.device.reduction import sum_sq_diff
from rsocl.solver.admm import ADMM

__all__ = ["BatchedFolds", "batches_pay", "batch_bytes"]


def batches_pay(device) -> bool:
    """Whether the search runs its folds as one batch on ``device`` (an rsocl Device): on a device that is
    not a CPU, where a batch costs the launches of one set."""
    return not device.is_cpu


def batch_bytes(op, folds: int) -> int:
    """Device bytes :class:`BatchedFolds` holds beside the folds' own arrays: per fold a copy of the
    snapshots, of the held-out weights and of the start's prediction, and of the warm start."""
    itemsize = np.dtype(op.dtype).itemsize
    snap = op.K * int(np.prod(op.domain_shape[1:])) * itemsize
    return int(folds) * (3 * snap + int(np.prod(op.domain_shape)) * itemsize)


class BatchedFolds:
    """A runner for :func:`~rsocl.solver.crossval.tune_parameters` (called as
    :func:`~rsocl.solver.crossval.run_folds`) that runs a candidate on all folds as one batch.

    The batch (its stacked snapshots, warm starts, weights and predictions, and one
    :class:`~rsocl.solver.admm.ADMM` of one set per fold) is made by the first candidate and
    restarted for the next ones.

    Examples
    --------
    >>> from rsocl.solver.search_batch import BatchedFolds
    >>> runner = BatchedFolds()       # tune_parameters(..., runner=runner)
    """

    def __init__(self):
        self.solver = None

    def _stack(self, op, arrays):
        """One device array of the ``arrays`` (device arrays of one shape) end to end."""
        import pyopencl as cl
        import pyopencl.array as cla

        out = cla.empty(op.queue, (len(arrays),) + arrays[0].shape, arrays[0].dtype)
        for i, a in enumerate(arrays):
            cl.enqueue_copy(op.queue, out.data, a.data, dst_offset=i * a.nbytes, byte_count=a.nbytes)
        return out

    def __call__(self, op, g_device, folds, reg, lam, *, eta, projection, iterations):
        sets = len(folds)
        if self.solver is None:
            self.g = self._stack(op, [g_device] * sets)
            self.x0 = self._stack(op, [fold.x0 for fold in folds])
            self.weights = self._stack(op, [fold.weights for fold in folds])
            self.predictions = self._stack(op, [fold.start_prediction for fold in folds])
            valid = np.stack([np.asarray(fold.fit, bool) for fold in folds])
            self.solver = ADMM(op, self.g, reg, lam=lam, eta=eta, projection=projection, x0=self.x0, valid=valid)
        else:
            self.solver.restart(reg, lam, self.x0)
        solver = self.solver
        for _ in range(iterations):
            solver.step()
        op.forward_into(solver.theta, solver.hx)
        errs = sum_sq_diff(self.g, solver.hx, weights=self.weights, sets=sets)
        moved = sum_sq_diff(solver.hx, self.predictions, weights=self.weights, sets=sets)
        err_sum = moved_sum = 0.0
        for e, mv in zip(errs.tolist(), moved.tolist()):  # in fold order, as one fold after the other
            err_sum += e
            moved_sum += mv
        return err_sum, moved_sum
