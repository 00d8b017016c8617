"""Device memory of one :func:`rsocl.solver.reconstruct` run, for ``rsocl bench``."""

from __future__ import annotations

__all__ = ["device_memory_bytes"]


def device_memory_bytes(
    rig,
    regularizer="tv",
    dtype="float32",
    *,
    device=None,
    projection="exact",
    tv_iterations=None,
    with_truth=True,
    tuned=False,
) -> int:
    """Device memory of one :func:`rsocl.solver.reconstruct` run, bytes.

    PoCL (like OpenCL itself) exposes no allocation counter, so this is the count the run is
    checked by before it starts (:func:`rsocl.solver.memory.batch_memory` of one set): the
    operator's geometry (exposure-start index and fraction per channel and pixel, length and
    gain per channel), the snapshots, the ground truth when given (``with_truth``, for the PSNR
    history), the start cube of a self-tuned run (``tuned``: its ``interp3d`` start), the
    solver's arrays (:func:`rsocl.solver.memory.state_bytes`: theta, b, f, u, H·theta, the
    valid-pixel mask, the per-pixel inverse blocks) and the regularizer's workspace
    (``workspace_bytes``). The Gram blocks, a temporary of the inverse's size freed
    before the inverse is stored, and the few partial sums of the reductions are not counted.
    For a self-tuned run the peak is the larger of the run and of its parameter search beside
    the staged problem (:func:`rsocl.solver.memory.search_peak`).
    """
    from rsocl.model.operator import RollingShutterOperator
    from rsocl.solver.memory import memory_bytes, search_peak
    from rsocl.solver.request import make_regularizer

    op = RollingShutterOperator(rig, device=device, dtype=dtype, subframes=rig.sampled_range())
    reg = make_regularizer(regularizer, None, tv_iterations)
    run = memory_bytes(op, reg, projection, 1, truth=with_truth, start=tuned)[1]
    if not tuned:
        return int(run)
    return int(max(run, search_peak(op, reg, projection, None, truth=with_truth, start=False)))
