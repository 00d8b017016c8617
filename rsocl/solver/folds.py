"""The hold-out folds of the parameter search: each pattern's fitted pixels, warm start and
held-out weights on the device (:func:`make_fold`), and one candidate run on them (:func:`run_folds`).

The search itself is :func:`rsocl.solver.crossval.tune_parameters`; its patterns come from
:mod:`rsocl.solver.holdout`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rsocl.device import pool
from rsocl.device.reduction import sum_sq_diff_async
from rsocl.model.interpolation_device import interp3d_device
from rsocl.solver.admm import ADMM

__all__ = ["Fold", "make_fold", "run_folds"]


@dataclass
class Fold:
    """One hold-out pattern's state during the search: the snapshot pixels that fit the candidates
    (``fit``), its warm start ``x0`` and that start's prediction ``H x0`` of the snapshots, the
    held-out pixels as weights on the device, and the pattern's solver (made by its first candidate)."""

    fit: np.ndarray
    x0: object
    weights: object
    start_prediction: object
    solver: object = None


def run_folds(op, g_device, folds, reg, lam, *, eta, projection, iterations):
    """``(err, moved)``: one candidate (regularizer ``reg``, ``lam``) run ``iterations`` ADMM steps on each
    fold in turn, its held-out sums of squares ``‖g - H theta‖²`` and ``‖H theta - H x0‖²`` added over the
    folds in order (read once every fold is enqueued). Each fold keeps its solver and restarts it for the
    next candidate."""
    pending = []  # each fold's sums, read after every fold is enqueued; added in fold order
    for fold in folds:
        if fold.solver is None:
            fold.solver = ADMM(op, g_device, reg, lam=lam, eta=eta, projection=projection, x0=fold.x0, valid=fold.fit)
        else:
            fold.solver.restart(reg, lam, fold.x0)
        solver = fold.solver
        for _ in range(iterations):
            solver.step()
        op.forward_into(solver.theta, solver.hx)
        pending.append(
            (
                sum_sq_diff_async(g_device, solver.hx, weights=fold.weights),
                sum_sq_diff_async(solver.hx, fold.start_prediction, weights=fold.weights),
            )
        )
    err = moved = 0.0
    for fold_err, fold_moved in pending:
        err += fold_err.result()
        moved += fold_moved.result()
    return err, moved


def make_fold(op, g_device, g, block, fit, scored) -> Fold:
    """A hold-out pattern's :class:`Fold`: its warm start (``interp3d`` of the fitted pixels), that
    start's prediction and the held-out weights on the device."""
    import pyopencl.array as cla

    rig = op.rig
    if not scored.any() or not fit.any():
        raise ValueError(
            f"tuning needs snapshot pixels to fit and to hold out; with block = {block} pixels on "
            f"a {rig.shape[0]}x{rig.shape[1]} grid there are {int(fit.sum())} and {int(scored.sum())}"
            "; fix lam and the regularizer's options or pass tune=False"
        )
    x0 = interp3d_device(op, g, fit, _solved(rig, op))
    weights = pool.to_device(op.queue, np.asarray(scored, dtype=op.dtype))
    start_prediction = cla.empty_like(g_device)
    op.forward_into(x0, start_prediction)
    return Fold(fit, x0, weights, start_prediction)


def _solved(rig, op) -> slice:
    """The sub-frames ``op`` models, as a slice of the rig's ``T``."""
    solved = rig.sampled_range()
    if solved.stop - solved.start != op.T:
        raise ValueError(f"the operator models {op.T} sub-frames, the rig samples {solved.stop - solved.start}")
    return solved
