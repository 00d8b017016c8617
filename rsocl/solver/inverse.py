"""The inverse blocks of the ADMM's data step: ``(eta I + M)⁻¹`` per pixel (docs/model.md, Eq. 13).

``M`` is the pixel's ``K×K`` block of ``H Hᵀ`` (``K`` snapshots). :func:`inverse_blocks` makes them on
the device where it can (``kernels/inverse.cl``: a cyclic Jacobi eigen-decomposition in float64, one
work item per pixel) and on the host otherwise (:func:`block_inverse`, NumPy's ``eigh``): a device
without ``cl_khr_fp64``, or more than :data:`DEVICE_CHANNELS` snapshots. Both drop the directions
below ``rcond`` of the block's largest eigenvalue (:data:`RCOND`), so they are the same
pseudo-inverse to float64 rounding. The paper's diagonal step (``projection="paper"``) needs no
inverse: its blocks are ``psi`` (Eq. 15).
"""

from __future__ import annotations

import numpy as np

from rsocl.device import pool
from rsocl.device.launch import element_launches
from rsocl.device.program import c_type

__all__ = [
    "RCOND",
    "DEVICE_CHANNELS",
    "block_inverse",
    "own_inverses",
    "inverse_blocks",
    "inverts_on_device",
    "device_block_inverse",
    "one_sided_program",
]

#: Eigenvalues of ``eta I + M`` below this fraction of the largest one (per pixel) are
#: treated as zero: the pseudo-inverse of GAP, and no 1/eta blow-up for a tiny eta. Per storage
#: dtype of the run: the data step divides the residual ``g - H v``, which carries that dtype's
#: rounding, by these eigenvalues. In float32, directions down to 1e-8 of the largest made GAP
#: diverge within 4 iterations even with the identity as denoiser (6 cameras at random angles,
#: ``t_e`` = 0.85 ``t_r``, 30x5 pixels, where 16 of 879 eigenvalues lie between 1e-10 and 1e-7
#: of their block's largest); from 1e-7 on it held, at 1e-6 with a margin of 10.
RCOND = {"float64": 1e-10, "float32": 1e-6}

#: Snapshots (``K``) up to which the device computes the blocks: each work item holds two ``K×K``
#: float64 matrices in private memory (4 KiB at 16); beyond, the host does.
DEVICE_CHANNELS = 16


def block_inverse(gram: np.ndarray, eta: float, rcond: float = RCOND["float64"]) -> np.ndarray:
    """``(eta I + M)⁻¹`` for each symmetric per-pixel block of ``gram`` (``(..., K, K)``), in float64.

    Computed from the eigen-decomposition ``M = V diag(λ) Vᵀ`` as
    ``V diag(1/(eta + λ)) Vᵀ``, with the directions where ``eta + λ`` is below
    ``rcond`` (:data:`RCOND` of the run's dtype) times the block's largest eigenvalue left out.
    For ``eta = 0`` (GAP) this is the pseudo-inverse: pixels no camera samples and cameras with
    identical windows give a zero or least-norm update, never a division by zero;
    for a tiny ``eta`` the unsampled directions stay at zero instead of ``1/eta``.

    >>> block_inverse(np.array([[[2.0, 0.0], [0.0, 0.0]]]), 0.0)[0]
    array([[0.5, 0. ],
           [0. , 0. ]])
    """
    gram = np.asarray(gram, dtype=np.float64)
    lam, vec = np.linalg.eigh(gram)
    lam = np.clip(lam, 0.0, None) + eta
    top = lam.max(axis=-1, keepdims=True)
    keep = lam > rcond * top
    inv = np.where(keep, 1.0 / np.where(keep, lam, 1.0), 0.0)
    return np.einsum("...ij,...j,...kj->...ik", vec, inv, vec)


def one_sided_program(projection: str, etas, one_sided: bool, dtype) -> tuple[list, dict]:
    """The files and definitions that admm.cl's one-sided step at ``eta = 0`` needs: ``jacobi.cl``, and
    ``GAP_ONE_SIDED`` with the run's :data:`RCOND`, where some set has ``eta = 0`` and saturated samples under
    the exact projection (its step solves ``M_AA⁺ r_A`` per round); none otherwise.

    >>> one_sided_program("exact", [0.2, 0.0], True, np.float32)
    (['jacobi.cl'], {'GAP_ONE_SIDED': 1, 'GAP_RCOND': '1e-06'})
    """
    if not (one_sided and projection == "exact" and np.any(np.asarray(etas) == 0)):
        return [], {}
    return ["jacobi.cl"], {"GAP_ONE_SIDED": 1, "GAP_RCOND": repr(RCOND[np.dtype(dtype).name])}


def own_inverses(projection: str, etas, valid, sets: int) -> bool:
    """Whether every set of a batch of ``sets`` needs its own inverse blocks: the rule
    :class:`~rsocl.solver.admm.ADMM` allocates by and the memory counts use.

    One set of blocks serves the batch unless the valid snapshot pixels differ between sets
    (``valid``: None for all pixels, or booleans of ``sets`` equal-sized sets), or, for the exact
    projection, whose blocks hold ``eta``, ``etas`` (one value or one per set) differ.
    """
    if sets <= 1:
        return False
    if projection == "exact" and len(set(np.ravel(etas).tolist())) > 1:
        return True
    if valid is None:
        return False
    valid = np.asarray(valid, dtype=bool).reshape(sets, -1)
    return bool((valid != valid[:1]).any())


def inverts_on_device(device, K: int) -> bool:
    """Whether :func:`inverse_blocks` computes the exact blocks on ``device`` (an rsocl Device) for
    ``K`` snapshots: with ``cl_khr_fp64`` and ``K`` up to :data:`DEVICE_CHANNELS`."""
    return bool(device.has_fp64) and 1 <= int(K) <= DEVICE_CHANNELS


def inverse_blocks(op, projection: str, etas, valid, sets: int, valid_device=None, *, on_device=None):
    """``(own, blocks)``: whether each set has its own blocks (:func:`own_inverses`), and the data
    step's blocks as a device array of ``op``'s dtype, ``(K, K, m, n)`` (exact) or ``(K, m, n)``
    (paper's ``psi``), with a leading axis of one block set per set when ``own``.

    Parameters
    ----------
    op : rsocl.RollingShutterOperator
    projection : {"exact", "paper"}
    etas : ndarray
        ``eta`` per set (float64, ``sets`` values, each >= 0).
    valid : ndarray of bool or None
        Snapshot pixels that enter the data term, ``(sets, K, m, n)`` or ``(K, m, n)``; None: all.
        A left-out pixel's row and column of its block are zero (paper: its ``psi`` is infinite).
    sets : int
        Sets of the batch (1 for one set).
    valid_device : pyopencl.array.Array or None
        ``valid`` already on the device (``op``'s dtype, 1 where valid); uploaded here when None.
    on_device : bool or None
        Compute the exact blocks on the device (True) or the host (False); None: the device where
        :func:`inverts_on_device`.
    """
    valid = None if valid is None or np.all(valid) else np.asarray(valid, dtype=bool).reshape((-1,) + op.range_shape)
    own = own_inverses(projection, etas, valid, sets)
    count = sets if own else 1
    if projection == "paper":
        psi = op.psi
        blocks = [psi if valid is None else np.where(valid[i if own else 0], psi, np.inf) for i in range(count)]
        return own, _upload(op, np.stack(blocks) if own else blocks[0])
    if on_device is None:
        on_device = inverts_on_device(op.device, op.K)
    if not on_device:
        return own, _upload(op, _host_blocks(op, etas, valid, own, count))
    if valid is None:
        valid_device = None
    elif valid_device is None:
        valid_device = pool.to_device(op.queue, np.asarray(valid, dtype=op.dtype))
    if valid_device is not None and not own:
        valid_device = valid_device.reshape((-1, op.K) + op.rig.shape)[0]  # every set's is set 0's
    blocks = device_block_inverse(
        op.device, op.queue, op.gram_device(), etas[:count], RCOND[op.dtype.name], valid_device
    )
    return own, blocks if own else blocks[0]


def _upload(op, blocks):
    return pool.to_device(op.queue, np.asarray(blocks, dtype=op.dtype))


def _host_blocks(op, etas, valid, own, count):
    """The exact blocks by :func:`block_inverse`, ``(count, K, K, m, n)`` when ``own`` else ``(K, K, m, n)``."""
    gram = op.gram()
    rcond = RCOND[op.dtype.name]
    blocks = []
    for i in range(count):
        if valid is None:
            inverse = block_inverse(gram, etas[i], rcond)
        else:
            keep = np.moveaxis(valid[i if own else 0].astype(np.float64), 0, -1)  # (m, n, K)
            mask = keep[..., :, None] * keep[..., None, :]
            inverse = block_inverse(gram * mask, etas[i], rcond) * mask
        blocks.append(np.moveaxis(inverse, (2, 3), (0, 1)))
    return np.stack(blocks) if own else blocks[0]


def device_block_inverse(device, queue, gram, etas, rcond: float, valid=None):
    """:func:`block_inverse` of every pixel's block of ``gram`` on the device: ``(count, K, K, m, n)``
    device array of ``gram``'s dtype, one block set per value of ``etas`` (``count`` of them).

    Parameters
    ----------
    device : rsocl.device.Device
        With ``cl_khr_fp64`` (the decomposition runs in float64; :func:`inverts_on_device`).
    queue : pyopencl.CommandQueue
    gram : pyopencl.array.Array
        ``(K, K, m, n)``, symmetric blocks (float32 or float64), ``K`` up to :data:`DEVICE_CHANNELS`.
    etas : sequence of float
        ``eta`` (>= 0) of each block set.
    rcond : float
        Eigenvalues of ``eta I + M`` below ``rcond`` times the block's largest are dropped (:data:`RCOND`).
    valid : pyopencl.array.Array or None
        ``(K, m, n)`` or ``(count, K, m, n)`` of ``gram``'s dtype, non-zero where a snapshot pixel
        enters the data term (a left-out one's row and column of the block are zero); None: all.

    Raises
    ------
    ValueError
        When the shapes do not match, ``K`` is beyond :data:`DEVICE_CHANNELS` or the device lacks fp64.
    """
    K, mn = int(gram.shape[0]), int(np.prod(gram.shape[2:]))
    if gram.ndim != 4 or gram.shape[1] != K:
        raise ValueError(f"gram must be (K, K, m, n), got shape {gram.shape}")
    if not inverts_on_device(device, K):
        raise ValueError(
            f"the device inverse needs cl_khr_fp64 and K in [1, {DEVICE_CHANNELS}]; got K = {K} on "
            f"{device.name!r} (fp64: {device.has_fp64})"
        )
    etas = np.ascontiguousarray(np.atleast_1d(np.asarray(etas, np.float64)))
    count = len(etas)
    if valid is not None and valid.shape not in ((K,) + gram.shape[2:], (count, K) + gram.shape[2:]):
        raise ValueError(f"valid must be (K, m, n) or ({count}, K, m, n), got shape {valid.shape}")
    program = device.program(["jacobi.cl", "inverse.cl"], REAL=c_type(gram.dtype), NCH=K, INV_REAL="double")
    kernel = program.block_inverse
    out = pool.empty(queue, (count, K, K) + gram.shape[2:], gram.dtype)
    etas_device = pool.to_device(queue, etas)
    stride = K if valid is not None and valid.ndim == 4 else 0  # planes of mn from one set's valid to the next
    for gsize, lsize, offset in element_launches(count * mn, device.group_limit(kernel, cap=64)):
        kernel(
            queue,
            gsize,
            lsize,
            gram.data,
            gram.data if valid is None else valid.data,  # not read without valid
            np.int32(valid is not None),
            np.int32(stride),
            etas_device.data,
            np.float64(rcond),
            out.data,
            np.int32(mn),
            global_offset=offset,
        )
    return out
