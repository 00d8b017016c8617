"""The ADMM's data residual ``‖g - H theta‖ / ‖g‖``, kept on the device until the host reads it.

One launch of ``residual_partials`` (``kernels/residual.cl``) computes ``H theta`` and the weighted
sum of squares of ``g - H theta`` block by block, and leaves one partial per work group in a
*slot* of a device buffer; a kernel named in ``kernels`` (the ADMM's projection) may write the same
partials from its own launch on the same blocks and work groups (:attr:`DeviceResiduals.grid`).
A run that looks at each residual reads one slot per iteration; a run that does not writes the
residuals of ``slots`` iterations into their own slots and reads them in one copy
(:meth:`DeviceResiduals.read`), while the device goes on with the next iterations. The host adds
the partials with ``math.fsum``, so the value does not depend on how it was read. The queue must
be in order (rsocl's queues are): a slot is written again only after the copy enqueued before it.
"""

from __future__ import annotations

import math

import numpy as np

from rsocl.device import pool
from rsocl.device.program import c_type
from rsocl.device.reduction import PendingSum, sum_sq_diff_async

__all__ = ["DeviceResiduals", "PendingResiduals"]


class DeviceResiduals:
    """Residuals of ``theta`` against the snapshots ``g`` of ``op``, in ``slots`` device slots.

    Parameters
    ----------
    op : rsocl.model.operator.RollingShutterOperator
    g : pyopencl.array.Array
        Snapshots ``(K, m, n)`` or a batch ``(B, K, m, n)``.
    valid : pyopencl.array.Array or None
        Weights of the snapshot pixels (1 where a pixel enters the data term), ``g``'s shape; None: all.
    sets : int or None
        ``B`` for a batch (one residual per set), None for one set.
    slots : int
        Iterations whose residuals the device holds at once, >= 1.
    kernels : tuple of pyopencl.Kernel
        Other kernels that write the slots on this object's blocks and work groups: the work groups
        stay within their limits too.

    Examples
    --------
    >>> import numpy as np, rsocl, pyopencl.array as cla
    >>> from rsocl.model.operator import RollingShutterOperator
    >>> rig = rsocl.Rig.paper_array(2, (8, 8), 0.18e-3, 35e-6)
    >>> op = RollingShutterOperator(rig)
    >>> theta = cla.to_device(op.queue, np.ones(op.domain_shape, np.float32))
    >>> res = DeviceResiduals(op, op.forward(theta), None, None, slots=1)
    >>> res.enqueue(theta, 0); res.read(1).result()
    [0.0]
    """

    def __init__(self, op, g, valid, sets, slots: int, kernels: tuple = ()):
        import pyopencl as cl

        self.op, self.g, self.valid, self.sets = op, g, valid, sets
        self.slots = int(slots)
        if self.slots < 1:
            raise ValueError(f"slots must be >= 1, got {slots!r}")
        dev = op.device
        self.acc = dev.acc_dtype
        self.program = dev.program(
            ["residual.cl"],
            REAL=c_type(op.dtype),
            ACC=c_type(self.acc),
            MASK_BINARY=int(op.rig.mask == "binary"),
            **op.tile_defines,
        )
        kernel = self.program.lease("residual_partials", self)
        channels = op.K * (sets or 1)
        self.grid = op.block_grid(channels, kernels=(kernel, *kernels))
        gsize, lsize = self.grid
        self.per_slot = int(np.prod([size // local for size, local in zip(gsize, lsize)]))
        self.partials = pool.buffer(op.queue, self.slots * self.per_slot * self.acc.itemsize)
        self.local = cl.LocalMemory(int(lsize[0] * lsize[1]) * self.acc.itemsize)
        self._g_norm2 = sum_sq_diff_async(g, weights=valid, sets=sets)  # waited for at the first read
        self.kernel = kernel  # this object's own: its arguments are set here once
        self._theta = None  # the buffer argument 0 holds (the estimate whose residual is enqueued)
        kernel.set_args(
            None,
            g.data,
            None if valid is None else valid.data,
            *op._geometry(),
            self.partials,
            self.local,
            np.int32(0),
            np.int32(op.K),
            np.int32(op.T),
            np.int32(op.L),
            *op._shape_args(),
        )

    def enqueue(self, theta, slot: int):
        """Enqueue the residual of device array ``theta`` into ``slot`` (0 .. slots - 1); nothing is read."""
        self.check_slot(slot)
        if theta.data is not self._theta:  # an ADMM passes the same buffer every iteration: set once
            self.kernel.set_arg(0, theta.data)
            self._theta = theta.data
        self.kernel.set_arg(9, np.int32(slot))
        self.kernel.enqueue(self.op.queue, *self.grid)

    @property
    def g_norm2(self):
        """``‖g‖²`` over the valid pixels: a float, or one per set (float64 array) for a batch (waits for it)."""
        return self._g_norm2.result()

    def check_slot(self, slot: int):
        """ValueError unless ``slot`` is one of this object's slots (0 .. slots - 1)."""
        if not 0 <= slot < self.slots:
            raise ValueError(f"slot must be in [0, {self.slots - 1}], got {slot!r}")

    def read(self, count: int) -> PendingResiduals:
        """Enqueue the copy of slots ``0 .. count - 1`` to the host (not waited for)."""
        import pyopencl as cl

        host = np.empty(int(count) * self.per_slot, self.acc)
        event = cl.enqueue_copy(self.op.queue, host, self.partials, is_blocking=False)
        return PendingResiduals(host, event, int(count), self.sets, self._g_norm2)


class PendingResiduals:
    """Residuals of ``count`` slots on their way to the host; :meth:`result` waits for them."""

    def __init__(self, host, event, count, sets, g_norm2: PendingSum):
        self._host, self._event, self._count, self._sets, self._g_norm2 = host, event, count, sets, g_norm2
        self._values: list | None = None

    def result(self) -> list:
        """One residual per slot read: a float, or one per set (float64 array) for a batch.

        Relative to ``‖g‖`` over the valid pixels; where ``g`` (of a set) is all zero, ``‖H theta‖``.
        """
        if self._values is None:
            self._event.wait()
            rows = self._host.astype(np.float64).reshape(self._count, self._sets or 1, -1)
            g2 = np.atleast_1d(np.asarray(self._g_norm2.result(), dtype=np.float64))
            values = []
            for slot in rows:
                r2 = np.array([math.fsum(row.tolist()) for row in slot])
                r = np.sqrt(np.where(g2 > 0, r2 / np.where(g2 > 0, g2, 1.0), r2))
                values.append(float(r[0]) if self._sets is None else r)
            self._values = values
        return self._values
