"""Device memory of one :func:`rsocl.solver.reconstruct` run, for ``rsocl bench``."""

from __future__ import annotations

__all__ = ["device_memory_bytes"]


def device_memory_bytes(rig, regularizer="tv", dtype="float32", *, device=None, projection="exact",
                        tv_iterations=None, with_truth=True) -> int:
    """Device memory of one :func:`rsocl.solver.reconstruct` run, bytes.

    PoCL (like OpenCL itself) exposes no allocation counter, so this is the exact sum of the
    buffers rsocl allocates for the run and keeps until its end: the operator's geometry
    (exposure-start index and fraction per channel and pixel, length and gain per channel),
    the snapshots, the ground truth when given (for the PSNR history), the solver's arrays
    (:meth:`rsocl.solver.admm.ADMM.buffers_bytes`: theta, b, f, u, H·theta, the per-pixel inverse
    blocks) and the regularizer's workspace (``workspace_bytes``). The Gram blocks, a
    temporary of the inverse's size freed before the inverse is stored, and the few partial
    sums of the reductions are not counted.
    """
    from rsocl.solver.admm import ADMM
    from rsocl.model.operator import RollingShutterOperator
    from rsocl.solver.reconstruct import make_regularizer

    solved = rig.sampled_range()
    op = RollingShutterOperator(rig, device=device, dtype=dtype, subframes=solved)
    reg = make_regularizer(regularizer, None, tv_iterations)
    item = op.dtype.itemsize
    kmn = op.K * op.mn
    cube = op.T * op.mn * item
    geometry = kmn * 4 + kmn * item + 2 * op.K * item
    total = geometry + kmn * item + ADMM.buffers_bytes(op, projection) + reg.workspace_bytes(op.domain_shape, op.dtype)
    if with_truth:
        total += cube
    return int(total)
