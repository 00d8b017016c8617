"""The ADMM of docs/model.md (Eqs. 11-15) with all state on the OpenCL device.

One iteration is the data step in three launches (``admm_dual``: dual update and
``v = theta + b``; ``admm_project``: ``f = v + Hᵀ(eta I + H Hᵀ)⁻¹(g - H v)`` per pixel;
``admm_difference``: ``u = f - b``) and the regularizer's ``theta = denoise(u, lam/eta)``; a
regularizer that fuses the dual update (the TV) takes the first and last of them into its own and the
projection's launches. The residual of the history is one more launch (:mod:`rsocl.solver.residuals`),
or, in a run that reads the residuals a group at a time, the next iteration's projection computes it
(``step(residual_slot=...)``). A regularizer that defers its last launch (the TV on a GPU:
:meth:`~rsocl.solver.regularizer.Regularizer.deferred_primal_on`) leaves it to the next iteration's
projection, which makes it at its pixels first; ``theta`` read between iterations makes it then.
A batch of sets runs every launch once for all of them. Nothing crosses to the host but
the few partial sums of the history.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rsocl.common import validation as check
from rsocl.device import pool
from rsocl.device.launch import batch_launches, element_launches
from rsocl.device.program import c_type
from rsocl.model.operator import RollingShutterOperator
from rsocl.solver.inverse import inverse_blocks, one_sided_program
from rsocl.solver.residuals import DeviceResiduals

__all__ = ["ADMM", "RESIDUAL_SLOTS", "GPU_PROJECT_LANES", "lanes_that_fit"]

#: Iterations whose residuals the device holds before the host reads them in one copy, in a run that
#: does not look at each residual (:meth:`ADMM.residual_into`, :meth:`ADMM.read_residuals`).
RESIDUAL_SLOTS = 8
#: Index of ``admm_project``'s ``deferred`` flag (built with ``DEFER_PRIMAL``; the final dual, the steps and
#: the dual flags before it): ``kernels/admm.cl``.
PROJECT_DEFERRED = 23
#: Work items per block of the projection (``PROJECT_LANES``, ``kernels/admm.cl``) on a device that is not a
#: CPU, where the regularizer fuses the dual update: they share the passes over a block's whole column (the
#: deferred primal step, ``u = f - b``); fewer where the work group would not fit. A power of two; the
#: count ``benchmarks/lanes_choice.py`` chose on a GPU: docs/gpu.md.
GPU_PROJECT_LANES = 4


def lanes_that_fit(lanes: int, local: tuple, group_limit: int, max_items_1: int) -> int:
    """The largest power of two up to ``lanes`` whose work groups of ``local`` blocks (``(LX, LY, 1)``) times the
    lanes stay within ``group_limit`` work items and ``max_items_1`` along dimension 1 (at least 1)."""
    fit = 1
    while 2 * fit <= lanes and local[0] * local[1] * 2 * fit <= group_limit and local[1] * 2 * fit <= max_items_1:
        fit *= 2
    return fit


def _per_set(name, value, sets):
    """``value`` as a float64 array of ``sets`` values (a number is every set's)."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return np.full(sets, float(arr))
    if arr.shape != (sets,):
        raise ValueError(f"{name} must be a number or one value per set ({sets}), got shape {arr.shape}")
    return arr.copy()


def _denoiser_weights(lams, etas):
    """The denoiser's weight per set: ``lam / eta``, or ``lam`` where ``eta = 0`` (GAP)."""
    return np.where(etas > 0, lams / np.where(etas > 0, etas, 1.0), lams)


def _residual_weights(valid, saturated):
    """The snapshot pixels the residual counts, and that the data step takes two-sided: ``valid`` (None:
    all) less the ``saturated`` ones; ``valid`` itself where none is saturated."""
    if saturated is None or not np.any(saturated):
        return valid
    unsaturated = ~np.asarray(saturated, dtype=bool)
    return unsaturated if valid is None else valid & unsaturated


class ADMM:
    """ADMM state on the device; :meth:`step` runs one iteration.

    Parameters
    ----------
    op : RollingShutterOperator
    g : pyopencl.array.Array
        Snapshots ``(K, m, n)`` on the device, or a batch of ``B`` sets ``(B, K, m, n)``: every
        kernel then serves the whole batch in one launch, and the state has a leading batch axis.
    regularizer : rsocl.solver.regularizer.Regularizer
    lam, eta : float or sequence of float
        Regularization and penalty (``eta = 0``: GAP, no dual variable; denoiser weight ``lam``);
        for a batch, one number for every set or one per set.
    projection : {"exact", "paper"}
    x0 : pyopencl.array.Array or None
        Initial ``theta`` (the state's shape); zeros when None.
    valid : ndarray of bool, shape of ``g``, or None
        Snapshot pixels that enter the data term; the others (e.g. the held-out pixels of the
        parameter search) are left out: their rows of ``H`` are dropped from the data step.
    saturated : ndarray of bool, shape of ``g``, or None
        Snapshot pixels clipped by the sensor, whose true value is at least the recorded one: they
        enter the data step one-sided (the estimate is pulled up to them, never down;
        ``docs/model.md``, saturated pixels), and the residual leaves them out.

    When the regularizer takes the dual update into its own launches on this device
    (``regularizer.fuses_dual_on(device)``: the TV on its fused path or on a GPU), the projection
    also writes the denoiser's input ``u = f - b`` and the denoiser's last launch
    makes the next iteration's dual update (``b = theta - u``, ``f = theta + b``): no separate
    passes for either after the first iteration.
    """

    def __init__(
        self,
        op: RollingShutterOperator,
        g,
        regularizer,
        *,
        lam,
        eta,
        projection="exact",
        x0=None,
        valid=None,
        saturated=None,
    ):
        import pyopencl as cl

        self.op, self.g, self.regularizer, self.projection = op, g, regularizer, projection
        self.batched = g.ndim == 4
        self.sets = op.sets_of(g, op.range_shape)
        self.lams, self.etas = _per_set("lam", lam, self.sets), _per_set("eta", eta, self.sets)
        self.weights = _denoiser_weights(self.lams, self.etas)
        queue = op.queue
        batch = (self.sets,) if self.batched else ()
        shape = batch + op.domain_shape
        valid = None if valid is None or np.all(valid) else np.asarray(valid, dtype=bool)
        rows = None if valid is None else pool.to_device(queue, valid.astype(op.dtype))
        self.one_sided = saturated is not None and bool(np.any(saturated))
        weights = _residual_weights(valid, saturated)
        self.valid = rows if weights is valid else pool.to_device(queue, weights.astype(op.dtype))
        self.own_inverse, self.inverse = inverse_blocks(op, projection, self.etas, valid, self.sets, rows)
        self.eta_device = pool.to_device(queue, self.etas.astype(op.dtype))
        self.dual_on = pool.to_device(queue, (self.etas > 0).astype(np.int32))
        self._pending = False  # the denoiser's last launch left to the next projection (deferred)
        self._theta = pool.zeros(queue, shape, op.dtype) if x0 is None else pool.copy(x0)
        self.b = pool.zeros(queue, shape, op.dtype)
        self.f = pool.copy(self._theta)
        self.u = pool.empty(queue, shape, op.dtype)
        self.hx = pool.empty(queue, batch + op.range_shape, op.dtype)
        self.fused = bool(regularizer.fuses_dual_on(op.device))
        self._defines = regularizer.deferred_primal_on(op.device) if self.fused else None
        self.lanes = GPU_PROJECT_LANES if self.fused and not op.device.is_cpu else 1
        while True:  # once more with fewer lanes where the projection's work groups would not fit
            self.program = self._build(projection)
            sets = self.sets if self.batched else None
            self.residuals = DeviceResiduals(
                op, g, self.valid, sets, RESIDUAL_SLOTS, kernels=(self.program.admm_project,)
            )
            self.blocks = op.block_grid(self.sets, kernels=(self.program.admm_project, self.residuals.kernel))
            limit = op.device.group_limit(self.program.admm_project)
            fit = lanes_that_fit(self.lanes, self.blocks[1], limit, op.device.max_work_item_sizes[1])
            if fit == self.lanes:
                break
            self.lanes = fit
        (gx, gy, sets), (lx, ly, _) = self.blocks
        self.project_grid = ((gx, gy * self.lanes, sets), (lx, ly * self.lanes, 1))
        self.per_set = int(np.prod(op.domain_shape))
        dev, prog = op.device, self.program  # exact grids: no bounds tests
        self.voxels = batch_launches(self.per_set, self.sets, dev.group_limit(prog.admm_dual, cap=64))
        self.elements = element_launches(self.sets * self.per_set, dev.group_limit(prog.admm_difference, cap=64))
        scratch = self._scratch_bytes()
        self.folds_residual = scratch <= dev.local_mem_bytes // 2
        self._scratch = cl.LocalMemory(scratch if self.folds_residual else self.residuals.acc.itemsize)
        self.iteration = 0
        self._denoiser: Any = None  # the regularizer's bound call, made at the first step
        self._bind_kernels()
        cl.enqueue_barrier(queue)

    def _build(self, projection):
        """The ADMM's program on this operator's device: the residual, the TV's primal step where the projection
        makes the denoiser's deferred last launch, and admm.cl with ``self.lanes`` lanes per block."""
        op = self.op
        deferred = {} if self._defines is None else {"DEFER_PRIMAL": 1, **self._defines}
        gap_files, gap = one_sided_program(projection, self.etas, self.one_sided, op.dtype)
        return op.device.program(
            ["residual.cl"] + (["tv.cl"] if deferred else []) + gap_files + ["admm.cl"],
            REAL=c_type(op.dtype),
            ACC=c_type(op.device.acc_dtype),
            MASK_BINARY=int(op.rig.mask == "binary"),
            NCH=op.K,
            PROJECTION_EXACT=int(projection == "exact"),
            PROJECT_LANES=self.lanes,
            SATURATED=int(self.one_sided),
            **gap,
            **op.tile_defines,
            **deferred,
        )

    def _scratch_bytes(self) -> int:
        """Local memory of a projection that adds the residual: one sum per channel and work item."""
        if self.blocks[0][:2] != self.residuals.grid[0][:2] or self.blocks[1] != self.residuals.grid[1]:
            raise RuntimeError(
                f"the projection's blocks {self.blocks} differ from the residual's {self.residuals.grid}"
            )
        return self.op.K * int(np.prod(self.blocks[1])) * self.residuals.acc.itemsize

    def _bind_kernels(self):
        """This solver's own kernel objects (rsocl.device.Kernels.lease), their arguments set once: a
        step enqueues them and sets only the by-value arguments that change (the first iteration's flags)."""
        op, prog = self.op, self.program
        self._dual = prog.lease("admm_dual", self)
        self._dual.set_args(
            self._theta.data, self.b.data, self.f.data, self.dual_on.data, np.int32(0), np.int32(self.per_set)
        )
        self._project = prog.lease("admm_project", self)
        self._project.set_args(
            self.f.data,
            self.g.data,
            *op._geometry(),
            self.inverse.data,
            self.eta_device.data,
            np.int32(self.own_inverse),
            self.b.data,
            self.u.data,
            np.int32(self.fused),
            self._theta.data,
            None if self.valid is None else self.valid.data,
            self.residuals.partials,
            self._scratch,
            np.int32(op.T),
            np.int32(op.L),
            *op._shape_args(),
            *(() if self._defines is None else (None, None, self.dual_on.data, np.int32(0))),
        )
        self._difference = prog.lease("admm_difference", self)
        self._difference.set_args(self.f.data, self.b.data, self.u.data)

    @property
    def theta(self):
        """The estimate (a device array): where the denoiser's last launch waits for the next projection,
        it is enqueued now (:meth:`settle`)."""
        self.settle()
        return self._theta

    def settle(self):
        """Enqueue the denoiser's deferred last launch, if one waits: ``theta``, ``b`` and ``f`` as a
        denoiser that does not defer leaves them."""
        if self._pending:
            self._denoiser.finish()
            self._pending = False

    @property
    def g_norm2(self):
        """``‖g‖²`` over the valid snapshot pixels: a float, or one per set (float64 array) for a batch."""
        return self.residuals.g_norm2

    @property
    def lam(self):
        """``lam``: a float, or one per set (array) for a batch."""
        return self.lams if self.batched else float(self.lams[0])

    @property
    def eta(self):
        """``eta``: a float, or one per set (array) for a batch."""
        return self.etas if self.batched else float(self.etas[0])

    @property
    def weight(self):
        """The denoiser's weight ``lam / eta`` (``lam`` where ``eta = 0``): a float, or one per set."""
        return self.weights if self.batched else float(self.weights[0])

    def restart(self, regularizer, lam, x0):
        """Start over from ``theta = x0`` (a device array, copied) with another regularizer and
        ``lam`` (one number, or one per set); the data step (its inverse blocks, ``eta``, ``valid``) is kept."""
        import pyopencl as cl

        self.regularizer = regularizer
        self.fused = bool(regularizer.fuses_dual_on(self.op.device))
        if self._defines is not None and (
            not self.fused or regularizer.deferred_primal_on(self.op.device) != self._defines
        ):
            self._defines = None  # this program's projection does not fit the new regularizer's last step
            self._project.set_arg(PROJECT_DEFERRED, np.int32(0))
        self.lams = _per_set("lam", lam, self.sets)
        self.weights = _denoiser_weights(self.lams, self.etas)
        self._pending = False  # theta, b and f are written here
        for dest in (self._theta, self.f):
            cl.enqueue_copy(self.op.queue, dest.data, x0.data)
        cl.enqueue_fill_buffer(self.op.queue, self.b.data, np.zeros(1, self.op.dtype), 0, self.b.nbytes)
        self.iteration = 0
        self._denoiser = None

    def step(self, residual_slot: int | None = None):
        """One ADMM iteration (enqueued; nothing is read back).

        ``residual_slot``: also put the residual of the estimate as it is before this iteration (the
        previous iteration's) in that device slot (0 .. :data:`RESIDUAL_SLOTS` - 1, as
        :meth:`residual_into`), in the projection's launch where its local memory allows.
        """
        queue = self.op.queue
        if residual_slot is not None:
            self.residuals.check_slot(residual_slot)
            if not self.folds_residual:
                self.residuals.enqueue(self.theta, residual_slot)
        if not (self.fused and self.iteration > 0):  # else the denoiser made the dual update
            self._dual.set_arg(4, np.int32(self.iteration > 0))
            for gsize, lsize, offset in self.voxels:
                self._dual.enqueue(queue, gsize, lsize, offset)
        folded = residual_slot if residual_slot is not None and self.folds_residual else -1
        self._project.set_arg(11, np.int32(self.fused))  # set only when it changes
        if self._defines is not None:  # the projection makes the denoiser's deferred last launch first
            self._project.set_arg(PROJECT_DEFERRED, np.int32(self._pending))
        self._project.enqueue(queue, *self.project_grid, (0, 0, folded + 1))  # the slot is the offset: kernels/admm.cl
        self._pending = False
        if not self.fused:
            for gsize, lsize, offset in self.elements:
                self._difference.enqueue(queue, gsize, lsize, offset)
        if self._denoiser is None:  # theta = denoise(u), with the dual update when fused: bound once
            self._bind_denoiser()
        self._denoiser()
        self._pending = self._defines is not None
        self.iteration += 1

    def _bind_denoiser(self):
        if not self.fused:
            self._denoiser = self.regularizer.bind(self.u, self.weight, self._theta, None)
            return
        dual = (self.b, self.f, self.dual_on)
        if self._defines is None:
            self._denoiser = self.regularizer.bind(self.u, self.weight, self._theta, dual)
            return
        self._denoiser = self.regularizer.bind(self.u, self.weight, self._theta, dual, defer=True)
        deferred = getattr(self._denoiser, "deferred", None)
        if deferred is None:  # the regularizer made its last launch after all
            self._defines = None
            self._project.set_arg(PROJECT_DEFERRED, np.int32(0))
            return
        p_last, steps = deferred
        self._project.set_arg(PROJECT_DEFERRED - 3, p_last.data)
        self._project.set_arg(PROJECT_DEFERRED - 2, steps.data)

    def blend_towards(self, x0, alpha: float):
        """``theta = x0 + alpha (theta - x0)`` (enqueued): the estimate moved back towards the start ``x0``
        (a device array of ``theta``'s shape), ``alpha`` in [0, 1] (1: unchanged)."""
        alpha = self.theta.dtype.type(check.in_range("blend", alpha, 0.0, 1.0))
        self._per_voxel(self.program.admm_blend, x0, alpha)

    def pull_towards(self, x0, weights: np.ndarray):
        """``theta += w (x0 - theta)`` (enqueued), ``w`` per set and pixel: ``weights`` ``(sets, m, n)``, each
        in [0, 1] (0: unchanged); ``x0`` a device array of ``theta``'s shape."""
        weights = np.ascontiguousarray(weights, dtype=self.theta.dtype)
        if weights.shape != (self.sets,) + self.op.domain_shape[1:]:
            raise ValueError(f"weights must be {(self.sets,) + self.op.domain_shape[1:]}, got {weights.shape}")
        w = pool.to_device(self.op.queue, weights)
        self._per_voxel(self.program.admm_pull, x0, w.data, np.int64(self.per_set), np.int64(weights[0].size))

    def _per_voxel(self, kernel, x0, *args):
        """Launch ``kernel(theta, x0, *args)`` with one work item per voxel of the batch."""
        if x0.shape != self.theta.shape or x0.dtype != self.theta.dtype:
            raise ValueError(
                f"x0 must match theta ({self.theta.shape}, {self.theta.dtype}), got {x0.shape}, {x0.dtype}"
            )
        for gsize, lsize, offset in element_launches(
            self.sets * self.per_set, self.op.device.group_limit(kernel, cap=64)
        ):
            kernel(self.op.queue, gsize, lsize, self.theta.data, x0.data, *args, global_offset=offset)

    def residual(self):
        """Relative data residual ``‖g - H theta‖ / ‖g‖`` over the valid snapshot pixels (one per set
        for a batch). When ``g`` (of a set) is all zero the absolute ``‖H theta‖`` is returned.
        """
        return self.residual_async().result()

    def residual_async(self) -> PendingResidual:
        """Enqueue :meth:`residual` of the current ``theta``; ``.result()`` waits for it.

        The next :meth:`step` may be enqueued before the result is read: the device
        works on it while the partial sums travel to the host.
        """
        self.residuals.enqueue(self.theta, 0)
        return PendingResidual(self.residuals.read(1))

    def residual_into(self, slot: int):
        """Enqueue the residual of the current ``theta`` into device slot ``slot`` (0 .. :data:`RESIDUAL_SLOTS` - 1);
        :meth:`read_residuals` reads the slots. One launch; nothing is read back."""
        self.residuals.enqueue(self.theta, slot)

    def read_residuals(self, count: int):
        """Enqueue the copy of the residuals in slots ``0 .. count - 1``; ``.result()`` waits and gives
        one residual (as :meth:`residual`) per slot, in slot order."""
        return self.residuals.read(count)


class PendingResidual:
    """A residual of :meth:`ADMM.residual_async` on its way to the host."""

    def __init__(self, pending):
        self._pending = pending

    def result(self):
        """The residual: a float, or one per set (float64 array) for a batch."""
        return self._pending.result()[0]
