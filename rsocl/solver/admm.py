"""The ADMM of MODEL.md (Eqs. 11-15) with all state on the OpenCL device.

One iteration is the data step in three launches (``admm_dual``: dual update and
``v = theta + b``; ``admm_project``: ``f = v + Hᵀ(eta I + H Hᵀ)⁻¹(g - H v)`` per pixel;
``admm_difference``: ``u = f - b``) and the regularizer's ``theta = denoise(u, lam/eta)``. Nothing
crosses to the host but the few partial sums of the history.
"""

from __future__ import annotations

import numpy as np

from rsocl.device.context import c_type
from rsocl.device.launch import element_launches
from rsocl.model.operator import RollingShutterOperator
from rsocl.device.reduction import sum_sq_diff, sum_sq_diff_async

__all__ = ["ADMM", "block_inverse"]


#: Eigenvalues of ``eta I + M`` below this fraction of the largest one (per pixel) are
#: treated as zero: the pseudo-inverse of GAP, and no 1/eta blow-up for a tiny eta.
RCOND = 1e-10


def block_inverse(gram: np.ndarray, eta: float) -> np.ndarray:
    """``(eta I + M)⁻¹`` for each symmetric per-pixel block of ``gram`` (``(..., K, K)``), in float64.

    Computed from the eigen-decomposition ``M = V diag(λ) Vᵀ`` as
    ``V diag(1/(eta + λ)) Vᵀ``, with the directions where ``eta + λ`` is below
    ``RCOND`` times the block's largest eigenvalue left out. For ``eta = 0``
    (GAP) this is the pseudo-inverse: pixels no camera samples and cameras with
    identical windows give a zero or least-norm update, never a division by zero;
    for a tiny ``eta`` the unsampled directions stay at zero instead of ``1/eta``.
    """
    gram = np.asarray(gram, dtype=np.float64)
    lam, vec = np.linalg.eigh(gram)
    lam = np.clip(lam, 0.0, None) + eta
    top = lam.max(axis=-1, keepdims=True)
    keep = lam > RCOND * top
    inv = np.where(keep, 1.0 / np.where(keep, lam, 1.0), 0.0)
    return np.einsum("...ij,...j,...kj->...ik", vec, inv, vec)


class ADMM:
    """ADMM state on the device; :meth:`step` runs one iteration.

    Parameters
    ----------
    op : RollingShutterOperator
    g : pyopencl.array.Array
        Snapshots ``(K, m, n)`` on the device.
    regularizer : rsocl.solver.regularizer.Regularizer
    lam, eta : float
        Regularization and penalty (``eta = 0``: GAP, no dual variable; denoiser weight ``lam``).
    projection : {"exact", "paper"}
    x0 : pyopencl.array.Array or None
        Initial ``theta``; zeros when None.
    valid : ndarray of bool, shape (K, m, n), or None
        Snapshot pixels that enter the data term; the others (e.g. saturated ones)
        are left out: their rows of ``H`` are dropped from the projection.
    """

    def __init__(self, op: RollingShutterOperator, g, regularizer, *, lam, eta, projection="exact", x0=None,
                 valid=None):
        import pyopencl as cl
        import pyopencl.array as cla

        self.op, self.g, self.regularizer = op, g, regularizer
        self.lam, self.eta, self.projection = float(lam), float(eta), projection
        self.weight = self.lam / self.eta if self.eta > 0 else self.lam
        queue, shape = op.queue, op.domain_shape
        self.valid = None
        if valid is not None and not np.all(valid):
            self.valid = cla.to_device(queue, np.ascontiguousarray(valid, dtype=op.dtype))
        if projection == "exact":
            gram = op.gram()
            if self.valid is not None:
                keep = np.moveaxis(np.asarray(valid, dtype=np.float64), 0, -1)      # (m, n, K)
                mask = keep[..., :, None] * keep[..., None, :]
                inverse = block_inverse(gram * mask, self.eta) * mask
            else:
                inverse = block_inverse(gram, self.eta)
            inverse = np.moveaxis(inverse, (2, 3), (0, 1))
            self.inverse = cla.to_device(queue, np.ascontiguousarray(inverse, dtype=op.dtype))
        elif self.valid is not None:
            psi = np.where(valid, op.psi, np.inf)    # r / (eta + inf) = 0: left out
            self.inverse = cla.to_device(queue, np.ascontiguousarray(psi, dtype=op.dtype))
        else:
            self.inverse = op.psi_device()
        self.theta = cla.zeros(queue, shape, op.dtype) if x0 is None else x0.copy()
        self.b = cla.zeros(queue, shape, op.dtype)
        self.f = self.theta.copy()
        self.u = cla.empty(queue, shape, op.dtype)
        self.hx = cla.empty(queue, op.range_shape, op.dtype)
        self.program = op.device.program(
            ["admm.cl"], REAL=c_type(op.dtype), MASK_BINARY=int(op.rig.mask == "binary"),
            NCH=op.K, PROJECTION_EXACT=int(projection == "exact"), **op.tile_defines)
        self.voxels = element_launches(int(np.prod(shape)))     # exact grids: no bounds tests
        self.g_norm2 = sum_sq_diff(g, weights=self.valid)
        self.iteration = 0
        cl.enqueue_barrier(queue)

    @staticmethod
    def buffers_bytes(op: RollingShutterOperator, projection: str) -> int:
        """Device memory of the solver's own arrays (theta, b, f, u, H·theta, inverse blocks), bytes."""
        cube = int(np.prod(op.domain_shape)) * op.dtype.itemsize
        snap = int(np.prod(op.range_shape)) * op.dtype.itemsize
        inverse = snap * op.K if projection == "exact" else snap
        return 4 * cube + 2 * snap + inverse

    def restart(self, regularizer, lam, x0):
        """Start over from ``theta = x0`` (a device array, copied) with another regularizer and
        ``lam``; the data step (its inverse blocks, ``eta``, ``valid``) is kept."""
        import pyopencl as cl

        self.regularizer, self.lam = regularizer, float(lam)
        self.weight = self.lam / self.eta if self.eta > 0 else self.lam
        for dest in (self.theta, self.f):
            cl.enqueue_copy(self.op.queue, dest.data, x0.data)
        cl.enqueue_fill_buffer(self.op.queue, self.b.data, np.zeros(1, self.op.dtype), 0, self.b.nbytes)
        self.iteration = 0

    def step(self):
        """One ADMM iteration (enqueued; nothing is read back)."""
        op = self.op
        update_dual = np.int32(self.eta > 0 and self.iteration > 0)
        for gsize, lsize, offset in self.voxels:
            self.program.admm_dual(op.queue, gsize, lsize, self.theta.data, self.b.data, self.f.data, update_dual,
                                   global_offset=offset)
        self.program.admm_project(
            op.queue, *op.block_grid(), self.f.data, self.g.data, *op._geometry(), self.inverse.data,
            op.dtype.type(self.eta), np.int32(op.T), np.int32(op.L), *op._shape_args())
        for gsize, lsize, offset in self.voxels:
            self.program.admm_difference(op.queue, gsize, lsize, self.f.data, self.b.data, self.u.data,
                                         global_offset=offset)
        self.regularizer.denoise(self.u, self.weight, out=self.theta)
        self.iteration += 1

    def residual(self) -> float:
        """Relative data residual ``‖g - H theta‖ / ‖g‖`` over the valid snapshot pixels.

        When ``g`` is all zero the absolute ``‖H theta‖`` is returned.
        """
        return self.residual_async().result()

    def residual_async(self) -> "PendingResidual":
        """Enqueue :meth:`residual` of the current ``theta``; ``.result()`` waits for it.

        The next :meth:`step` may be enqueued before the result is read: the device
        works on it while the partial sums travel to the host.
        """
        self.op.forward_into(self.theta, self.hx)
        return PendingResidual(sum_sq_diff_async(self.g, self.hx, weights=self.valid), self.g_norm2)


class PendingResidual:
    """A residual of :meth:`ADMM.residual_async` on its way to the host."""

    def __init__(self, pending, g_norm2):
        self._pending, self._g_norm2 = pending, g_norm2

    def result(self) -> float:
        r2 = self._pending.result()
        if self._g_norm2 == 0:
            return float(np.sqrt(r2))
        return float(np.sqrt(r2 / self._g_norm2))
