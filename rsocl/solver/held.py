"""Sub-frames no camera samples hold the nearest solved sub-frame.

When every camera of a rig starts exposing late (all trigger offsets ``t_a`` above a sub-frame),
the first sub-frames of the ``(T, m, n)`` datacube fall before any exposure: no snapshot carries
information about them. rsocl models only :meth:`rsocl.model.rig.Rig.sampled_range` and gives each
sub-frame outside it the value of the nearest modelled one, at every pixel: the estimate
:func:`rsocl.model.interpolation.interp3d` makes there, and a continuation that adds no temporal
variation. (The tiles of :mod:`rsocl.scale` continue their own ranges the same way.)

What holding gives against zero-filling: ``docs/solver-notes.md`` (sub-frames no camera samples).
"""

from __future__ import annotations

import numpy as np

__all__ = ["held_index", "hold", "HeldSumSquares"]


def held_index(T: int, solved: slice) -> np.ndarray:
    """For each of the ``T`` sub-frames, the index into the ``solved`` ones whose value it takes:
    itself inside ``solved``, the first solved one before it, the last after it."""
    return np.clip(np.arange(int(T)) - solved.start, 0, solved.stop - solved.start - 1)


def hold(block: np.ndarray, solved: slice, T: int) -> np.ndarray:
    """The ``(..., T, m, n)`` datacube from ``block`` ``(..., len(solved), m, n)``, the ``solved`` sub-frames
    (``block`` itself when they are all ``T``)."""
    if solved.start == 0 and solved.stop == int(T):
        return block
    return block[..., held_index(T, solved), :, :]


class HeldSumSquares:
    """Squared error, against a ground truth, of the sub-frames outside ``solved``, from the two
    solved sub-frames they hold: ``sum_t |truth_t - x|^2 = L |x - mean_t truth_t|^2 + sum_t |truth_t - mean|^2``
    over the ``L`` held sub-frames of each end, so only the end planes are read back per call.

    ``truth`` is ``(T, m, n)`` or ``(B, T, m, n)``; calling it with the device estimate over the
    solved sub-frames (``(T', m, n)`` or ``(B, T', m, n)``) gives a float, or one per set.
    """

    def __init__(self, truth, solved: slice, T: int):
        truth = np.asarray(truth, dtype=np.float64)
        self.batched = truth.ndim == 4
        self.ends = []  # (position in the solved range, count, mean planes, spread per set)
        last = solved.stop - solved.start - 1
        for position, frames in ((0, slice(0, solved.start)), (last, slice(solved.stop, int(T)))):
            part = truth[..., frames, :, :]
            count = part.shape[-3]
            if count:
                mean = part.mean(axis=-3)
                spread = np.sum((part - mean[..., None, :, :]) ** 2, axis=(-3, -2, -1))
                self.ends.append((position, count, mean, spread))

    def __bool__(self) -> bool:
        return bool(self.ends)

    def __call__(self, theta):
        total = 0.0
        for position, count, mean, spread in self.ends:
            if self.batched:
                plane = np.stack([theta[s][position].get() for s in range(theta.shape[0])]).astype(np.float64)
            else:
                plane = theta[position].get().astype(np.float64)
            total = total + count * np.sum((plane - mean) ** 2, axis=(-2, -1)) + spread
        return total
