"""ADMM-TV for a rolling-shutter camera array in plain PyTorch (CPU): the peer of ``bench_admm.py``.

The same algorithm as ``numpy_admm_tv.py`` (dense shutter mask ``W[C, T, m, n]``, the exact
per-pixel projection with ``C×C`` inverse blocks computed once, scikit-image's 3-D Chambolle TV
with ``eps=0``), written the way a PyTorch user would write it: tensors on the CPU, whole-array
expressions, no custom kernels, no ``torch.compile``. It is the strongest plain version measured,
so that a ratio against it does not flatter rsocl:

- the Chambolle loop is scikit-image's ``_denoise_tv_chambolle_nd`` without its energy (with
  ``eps=0`` the energy never stops the loop), with scikit-image's in-place updates
  (``p -= tau g; p /= norm``) kept as in-place tensor operations: 2-4x faster than the same loop
  with a new tensor per expression (64x64x69, float32, measured on the 2-core VM of
  ``docs/bench_admm.md``);
- forward ``sum_s W v`` and adjoint ``sum_c W z`` are a broadcast product and a sum:
  ``torch.einsum`` routes these shapes through permuted batched matrix products, 10-18x slower
  here; the ``C×C`` blocks are applied with ``einsum`` (a batch of tiny products, as fast as
  ``matmul``).

Threads: PyTorch's default (``torch.get_num_threads()``, the machine's cores) unless ``threads``
is given.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from numpy_admm_tv import psnr, shutter_mask


def tv_chambolle(image: torch.Tensor, weight: float, iterations: int) -> torch.Tensor:
    """scikit-image's ``denoise_tv_chambolle(image, weight, eps=0, max_num_iter=iterations)`` (n-D)."""
    ndim = image.ndim
    p = torch.zeros((ndim,) + tuple(image.shape), dtype=image.dtype)
    g = torch.zeros_like(p)
    norm = torch.empty_like(image)
    tau = 1.0 / (2.0 * ndim)
    out = image.clone()
    for i in range(iterations):
        if i > 0:                                  # out = image - div(p), as scikit-image's d
            torch.sum(p, 0, out=out)
            out.neg_()
            for ax in range(ndim):
                out.narrow(ax, 1, image.shape[ax] - 1).add_(p[ax].narrow(ax, 0, image.shape[ax] - 1))
            out.add_(image)
        for ax in range(ndim):                     # g = grad(out), 0 at the far edge of each axis
            n = image.shape[ax]
            torch.sub(out.narrow(ax, 1, n - 1), out.narrow(ax, 0, n - 1), out=g[ax].narrow(ax, 0, n - 1))
        torch.sum(g * g, 0, out=norm)
        norm.sqrt_().mul_(tau / weight).add_(1.0)
        p.sub_(g, alpha=tau).div_(norm)
    return out


def admm_tv(g, rig, *, iterations, lam, eta, tv_iterations, dtype=torch.float32, truth=None, threads=None):
    """Reconstruct ``(T, m, n)`` from snapshots ``g`` ``(C, m, n)``; as ``numpy_admm_tv.admm_tv``.

    Returns ``(theta as a NumPy array, psnr_history, seconds_per_iteration)``; the time covers
    the loop only (the mask and inverse blocks are built before it, the PSNR outside it).
    """
    if threads is not None:
        torch.set_num_threads(int(threads))
    C, T = len(rig.channels), rig.T
    W = torch.from_numpy(shutter_mask(rig)).to(dtype)
    M = torch.einsum("csyx,dsyx->yxcd", W, W)
    Minv = torch.linalg.inv(eta * torch.eye(C, dtype=dtype) + M)
    gt = torch.as_tensor(np.asarray(g), dtype=dtype)
    theta = torch.zeros((T,) + tuple(rig.shape), dtype=dtype)
    b = torch.zeros_like(theta)
    weight = lam / eta
    history, elapsed = [], 0.0
    with torch.no_grad():
        for _ in range(iterations):
            t0 = time.perf_counter()
            v = theta + b
            r = gt - (W * v).sum(1)
            z = torch.einsum("yxcd,dyx->cyx", Minv, r)
            f = v + (W * z[:, None]).sum(0)
            theta = tv_chambolle(f - b, weight, tv_iterations)
            b = b - (f - theta)
            elapsed += time.perf_counter() - t0
            if truth is not None:
                history.append(psnr(theta.numpy(), truth))
    return theta.numpy(), history, elapsed / iterations


if __name__ == "__main__":
    import rsocl
    from rsocl.model.scenes import builtin_scene

    rig = rsocl.Rig.paper_array(4, (64, 64), 0.18e-3, 35e-6)
    truth = builtin_scene(rig.shape, rig.T, dtype=np.float64)
    g = np.einsum("csyx,syx->cyx", shutter_mask(rig), truth)
    theta, history, sec = admm_tv(g, rig, iterations=30, lam=0.1, eta=0.2, tv_iterations=10, truth=truth)
    print(f"{rig}: PSNR {history[-1]:.2f} dB after {len(history)} iterations, {sec * 1e3:.1f} ms/iteration "
          f"({torch.get_num_threads()} threads)")
