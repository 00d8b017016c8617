"""ADMM-TV for a rolling-shutter camera array in plain PyTorch: the peer of ``bench_admm.py`` (CPU)
and of ``peer.py`` (any torch device, a GPU above all).

The same algorithm as ``numpy_admm_tv.py`` (dense shutter mask ``W[C, T, m, n]``, the exact
per-pixel projection with ``C×C`` inverse blocks computed once, Chambolle's 3-D TV with
``eps=0``), written the way a PyTorch user would write it: tensors on one device, whole-array
expressions, no custom kernels. It is the strongest plain version measured, so that a ratio
against it does not flatter rsocl:

- the Chambolle loop is scikit-image's ``_denoise_tv_chambolle_nd`` without its energy (with
  ``eps=0`` the energy never stops the loop) and without its last dual update, which no output
  reads; scikit-image's in-place updates (``p -= tau g; p /= norm``) are kept as in-place tensor
  operations: 2-4x faster than the same loop with a new tensor per expression (64x64x69,
  float32, measured on the 2-core VM of ``docs/bench_admm.md``);
- forward ``sum_s W v`` and adjoint ``sum_c W z`` are a broadcast product and a sum:
  ``torch.einsum`` routes these shapes through permuted batched matrix products, 10-18x slower
  on that CPU; the ``C×C`` blocks are applied with ``einsum`` (a batch of tiny products).

rsocl's TV options are parameters: ``temporal_weight`` scales the temporal difference (0: 2-D TV
per sub-frame) and ``step`` is Chambolle's step as a fraction of scikit-image's
``1 / (2 (2 + w²))``, as ``plugins/tv.py`` and ``kernels/tv.cl`` define them. The defaults
(1 and 1) are scikit-image's 3-D TV, which ``bench_admm.py`` compares; rsocl's own defaults are
3 and 0.9. A batch of sets ``(B, C, m, n)`` is reconstructed in the same expressions, each set on
its own (no temporal difference across sets), as rsocl's batch path does.

Threads: PyTorch's default (``torch.get_num_threads()``, the machine's cores) unless ``threads``
is given.
"""

from __future__ import annotations

import time

import numpy as np

try:
    import torch
except ImportError:
    if __name__ == "__main__":  # run as a script: one line, no traceback
        raise SystemExit("torch_admm_tv.py needs PyTorch (pip install torch); without it the peer is skipped") from None
    raise
from numpy_admm_tv import psnr, shutter_mask

__all__ = ["tv_chambolle", "Peer", "admm_tv", "synchronize", "compiling"]


def compiling() -> bool:
    """Whether ``torch.compile`` is tracing the caller (False on a torch without ``torch.compiler``)."""
    check = getattr(getattr(torch, "compiler", None), "is_compiling", None)
    return bool(check()) if check is not None else False


def tv_chambolle(
    image: torch.Tensor, weight: float, iterations: int, *, temporal_weight: float = 1.0, step: float = 1.0
) -> torch.Tensor:
    """Chambolle's isotropic TV of ``image`` ``(..., T, m, n)`` over its last three axes (t, y, x).

    Every leading index (a set of a batch) is denoised on its own. With ``temporal_weight = 1``
    and ``step = 1`` this is scikit-image's ``denoise_tv_chambolle(image, weight, eps=0,
    max_num_iter=iterations)`` of a 3-D image; ``temporal_weight = w`` multiplies the temporal
    difference by ``w`` (``0``: 2-D TV of each sub-frame) and the dual step is
    ``tau = step / (2 (2 + w²))``, as rsocl's ``TV(temporal_weight=w, step=step)``.
    """
    wt = float(temporal_weight)
    axes = ((-3, wt), (-2, 1.0), (-1, 1.0)) if wt > 0 else ((-2, 1.0), (-1, 1.0))
    tau = float(step) / (2.0 * (2.0 + wt * wt))
    out = image.clone()
    if iterations <= 1:  # out = image + div(0)
        return out
    p = torch.zeros((len(axes),) + tuple(image.shape), dtype=image.dtype, device=image.device)
    g = torch.zeros_like(p)
    norm = torch.empty_like(image)
    for i in range(iterations):
        if i > 0:  # out = image - div_w(p), as scikit-image's d
            if wt in (0.0, 1.0):
                torch.sum(p, 0, out=out)
            else:
                torch.add(p[1], p[2], out=out).add_(p[0], alpha=wt)
            torch.sub(image, out, out=out)
            for k, (ax, w) in enumerate(axes):
                n = image.shape[ax]
                out.narrow(ax, 1, n - 1).add_(p[k].narrow(ax, 0, n - 1), alpha=w)
        if i == iterations - 1:  # the last dual update is never read: not made
            break
        for k, (ax, w) in enumerate(axes):  # g = w grad(out), 0 at the far edge of each axis
            n = image.shape[ax]
            if compiling():  # torch.compile traces no strided out=: a copy it fuses
                g[k].narrow(ax, 0, n - 1).copy_(out.narrow(ax, 1, n - 1) - out.narrow(ax, 0, n - 1))
            else:
                torch.sub(out.narrow(ax, 1, n - 1), out.narrow(ax, 0, n - 1), out=g[k].narrow(ax, 0, n - 1))
            if w != 1.0:
                g[k].mul_(w)
        torch.sum(g * g, 0, out=norm)
        norm.sqrt_().mul_(tau / weight).add_(1.0)
        p.sub_(g, alpha=tau).div_(norm)
    return out


class Peer:
    """One ADMM-TV problem on a torch device: the dense mask, the inverse blocks and the snapshots.

    Parameters
    ----------
    g : array_like, shape (C, m, n) or (B, C, m, n)
        Snapshots of one set or of a batch of sets (units of ``numpy_admm_tv.admm_tv``).
    rig : rsocl.Rig
        Only its timing is read (``numpy_admm_tv.shutter_mask``).
    lam, eta : float
        Regularization and ADMM penalty (> 0); the TV weight is ``lam / eta``.
    tv_iterations : int
        Chambolle iterations per ADMM iteration.
    dtype : torch.dtype
        Arithmetic type of the loop (the mask and the inverse blocks are computed in float64 and
        stored in it, as rsocl does).
    device : str or torch.device
        Where the tensors live.
    temporal_weight, step : float
        The TV's options (:func:`tv_chambolle`).

    :meth:`step` is one ADMM iteration as a pure function of ``(theta, b)`` (it writes none of its
    inputs), so that the same code runs eagerly, captured in a CUDA graph or through
    ``torch.compile``. ``g`` is a tensor that :meth:`load` overwrites in place.
    """

    def __init__(
        self, g, rig, *, lam, eta, tv_iterations, dtype=torch.float32, device="cpu", temporal_weight=1.0, step=1.0
    ):
        g = np.asarray(g)
        C, T = len(rig.channels), rig.T
        if g.shape[-3:] != (C,) + tuple(rig.shape) or g.ndim not in (3, 4):
            raise ValueError(f"g must be (C, m, n) = {(C,) + tuple(rig.shape)} or (B, C, m, n), got {g.shape}")
        self.device, self.dtype = torch.device(device), dtype
        W = shutter_mask(rig)  # float64
        M = np.einsum("csyx,dsyx->yxcd", W, W)
        Minv = np.linalg.inv(eta * np.eye(C) + M)
        self.W = torch.as_tensor(W, dtype=dtype, device=self.device)
        self.Minv = torch.as_tensor(Minv, dtype=dtype, device=self.device)
        self.g = torch.as_tensor(g, dtype=dtype, device=self.device).clone()
        self.shape = tuple(g.shape[:-3]) + (T,) + tuple(rig.shape)
        self.weight = lam / eta
        self.tv_iterations, self.temporal_weight, self.tv_step = int(tv_iterations), float(temporal_weight), float(step)

    def zeros(self) -> torch.Tensor:
        """A zero datacube of the problem's shape ``(T, m, n)`` or ``(B, T, m, n)`` (the start)."""
        return torch.zeros(self.shape, dtype=self.dtype, device=self.device)

    def load(self, g) -> None:
        """Copy new snapshots (a NumPy array of ``g``'s shape) into ``g`` (host to device)."""
        self.g.copy_(torch.from_numpy(np.ascontiguousarray(g, dtype=np.dtype(str(self.dtype).split(".")[-1]))))

    def step(self, theta: torch.Tensor, b: torch.Tensor):
        """One ADMM iteration from ``(theta, b)``; returns the new ``(theta, b)``."""
        v = theta + b
        r = self.g - (self.W * v.unsqueeze(-4)).sum(-3)  # g - H v
        z = torch.einsum("yxcd,...dyx->...cyx", self.Minv, r)  # (eta I + H Hᵀ)⁻¹ r per pixel
        f = v + (self.W * z.unsqueeze(-3)).sum(-4)  # v + Hᵀ z
        theta = tv_chambolle(
            f - b, self.weight, self.tv_iterations, temporal_weight=self.temporal_weight, step=self.tv_step
        )
        return theta, b - (f - theta)


def synchronize(device) -> None:
    """Wait for the work queued on ``device`` (a no-op on the CPU)."""
    device = torch.device(device)
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def admm_tv(
    g,
    rig,
    *,
    iterations,
    lam,
    eta,
    tv_iterations,
    dtype=torch.float32,
    truth=None,
    threads=None,
    device="cpu",
    temporal_weight=1.0,
    step=1.0,
):
    """Reconstruct ``(T, m, n)`` from snapshots ``g`` ``(C, m, n)``; as ``numpy_admm_tv.admm_tv``.

    ``device``, ``temporal_weight`` and ``step``: see :class:`Peer`. Returns ``(theta as a NumPy
    array, psnr_history, seconds_per_iteration)``; the time covers the loop only (the mask and
    inverse blocks are built before it, the PSNR outside it), the device synchronized at the end
    of each iteration.
    """
    if threads is not None:
        torch.set_num_threads(int(threads))
    history, elapsed = [], 0.0
    with torch.no_grad():
        peer = Peer(
            g,
            rig,
            lam=lam,
            eta=eta,
            tv_iterations=tv_iterations,
            dtype=dtype,
            device=device,
            temporal_weight=temporal_weight,
            step=step,
        )
        theta, b = peer.zeros(), peer.zeros()
        for _ in range(iterations):
            synchronize(peer.device)
            t0 = time.perf_counter()
            theta, b = peer.step(theta, b)
            synchronize(peer.device)
            elapsed += time.perf_counter() - t0
            if truth is not None:
                history.append(psnr(theta.cpu().numpy(), truth))
    return theta.cpu().numpy(), history, elapsed / iterations


if __name__ == "__main__":
    import argparse

    import rsocl
    from rsocl.model.scenes import builtin_scene

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=64, help="frame side, pixels (default 64)")
    parser.add_argument("--iterations", type=int, default=30, help="ADMM iterations (default 30)")
    cli = parser.parse_args()
    rig = rsocl.Rig.paper_array(4, (cli.size, cli.size), 0.18e-3, 35e-6)
    truth = builtin_scene(rig.shape, rig.T, dtype=np.float64)
    g = np.einsum("csyx,syx->cyx", shutter_mask(rig), truth)
    theta, history, sec = admm_tv(g, rig, iterations=cli.iterations, lam=0.1, eta=0.2, tv_iterations=10, truth=truth)
    print(
        f"{rig}: PSNR {history[-1]:.2f} dB after {len(history)} iterations, {sec * 1e3:.1f} ms/iteration "
        f"({torch.get_num_threads()} threads)"
    )
