"""ADMM-TV for a rolling-shutter camera array in plain NumPy + scikit-image.

This is the baseline of ``bench_admm.py``: the reconstruction written the way a
user would write it from the paper (Guzmán, Meza, Vera, Optics Express 2021) and
``docs/model.md``, with no rsocl code in the loop. It only reads the rig's timing
(per-pixel exposure start times, ``dt``, exposure time ``t_e`` and gain of each
camera); the shutter weights, the forward model, its adjoint, the exact per-pixel
projection and the loop are all written here with NumPy, and the TV step is
``skimage.restoration.denoise_tv_chambolle`` (3-D, spatio-temporal).

The ADMM (docs/model.md, Eqs. 11-15), with ``theta = b = 0`` at the start::

    v     = theta + b
    f     = v + Hᵀ (eta I + H Hᵀ)⁻¹ (g - H v)       # exact, one C×C block per pixel
    theta = denoise_tv_chambolle(f - b, weight=lam/eta)
    b     = b - (f - theta)

and ``theta`` after the last iteration is the estimate.

It is deliberately plain: the dense ``W[C, T, m, n]`` mask is kept in memory and
each step is one or two NumPy expressions. Run this file to reconstruct the
built-in scene on the paper's 4-camera array.
"""

from __future__ import annotations

import math
import time

import numpy as np
from skimage.restoration import denoise_tv_chambolle


def shutter_mask(rig) -> np.ndarray:
    """Dense shutter weights ``W[c, s, y, x]`` (float64), gains included.

    Sub-frame ``s`` covers ``[s*dt, (s+1)*dt)``; pixel ``(y, x)`` of camera ``c`` is
    exposed during ``[start, start + t_e]``. The weight is the overlap of the two
    intervals as a fraction of ``dt`` (docs/model.md, ``mask="exact"``), in [0, 1].
    """
    if rig.mask != "exact":
        raise ValueError("this baseline implements the exact overlap mask only")
    start = rig.start_times() / rig.dt  # (C, m, n), in sub-frames
    t_e = np.array([rig.cameras[c].t_e for c, _ in rig.channels]) / rig.dt  # (C,)
    gain = np.array([rig.cameras[c].gain for c, _ in rig.channels])  # (C,)
    end = start + t_e[:, None, None]

    s = np.arange(rig.T, dtype=np.float64)[None, :, None, None]  # (1, T, 1, 1)
    overlap = np.minimum(s + 1.0, end[:, None]) - np.maximum(s, start[:, None])
    W = np.clip(overlap, 0.0, None)  # (C, T, m, n)
    return W * gain[:, None, None, None]


def forward(W, f):
    """Snapshots ``g[c] = sum_s W[c, s] * f[s]``."""
    return np.einsum("csyx,syx->cyx", W, f)


def adjoint(W, g):
    """Back-projection ``f[s] = sum_c W[c, s] * g[c]``."""
    return np.einsum("csyx,cyx->syx", W, g)


def psnr(x, truth, peak=1.0):
    mse = np.mean((np.asarray(x, dtype=np.float64) - np.asarray(truth, dtype=np.float64)) ** 2)
    return math.inf if mse == 0 else 10.0 * math.log10(peak * peak / mse)


def admm_tv(g, rig, *, iterations, lam, eta, tv_iterations, dtype=np.float64, truth=None):
    """Reconstruct the ``(T, m, n)`` datacube from the snapshots ``g`` ``(C, m, n)``.

    Parameters
    ----------
    g : array_like, shape (C, m, n)
        Snapshots on the reference grid (a scene in [0, 1] gives values in [0, t_e/dt]).
    rig : rsocl.Rig
        Only its timing is used: ``start_times()``, ``dt``, ``T``, and each camera's
        ``t_e`` and ``gain``.
    iterations : int
        ADMM iterations.
    lam, eta : float
        Regularization strength and ADMM penalty (> 0); the TV weight is ``lam / eta``.
    tv_iterations : int
        Chambolle iterations per TV call (``eps=0``: exactly that many).
    dtype : NumPy float dtype
        Arithmetic type of the whole loop.
    truth : array_like or None
        Ground truth ``(T, m, n)`` on the [0, 1] scale: fills the PSNR history
        (computed outside the timed part).

    Returns
    -------
    theta : ndarray, shape (T, m, n)
        The estimate after the last iteration.
    psnr_history : list of float
        PSNR (dB, peak 1) of ``theta`` after each iteration; empty without ``truth``.
    seconds_per_iteration : float
        Mean wall-clock time of one ADMM iteration (setup and PSNR excluded).
    """
    C, m, n = len(rig.channels), rig.shape[0], rig.shape[1]
    T = rig.T
    g = np.asarray(g, dtype=dtype)
    assert g.shape == (C, m, n), f"g must have shape {(C, m, n)}, got {g.shape}"

    # Setup: dense mask, and the per-pixel inverse (eta I + M)^-1 with M = H Hᵀ restricted to a pixel.
    W = shutter_mask(rig).astype(dtype)
    M = np.einsum("csyx,dsyx->yxcd", W, W)  # (m, n, C, C)
    Minv = np.linalg.inv(eta * np.eye(C, dtype=dtype) + M)  # (m, n, C, C)

    theta = np.zeros((T, m, n), dtype=dtype)
    b = np.zeros((T, m, n), dtype=dtype)
    weight = lam / eta
    psnr_history = []
    elapsed = 0.0
    for _ in range(iterations):
        t0 = time.perf_counter()
        v = theta + b
        r = g - forward(W, v)
        z = np.einsum("yxcd,dyx->cyx", Minv, r)
        f = v + adjoint(W, z)
        theta = denoise_tv_chambolle(f - b, weight=weight, eps=0, max_num_iter=tv_iterations)
        b = b - (f - theta)
        elapsed += time.perf_counter() - t0
        if truth is not None:
            psnr_history.append(psnr(theta, truth))
    return theta, psnr_history, elapsed / iterations


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
    g = forward(shutter_mask(rig), truth)
    theta, history, sec = admm_tv(g, rig, iterations=cli.iterations, lam=0.1, eta=0.2, tv_iterations=10, truth=truth)
    print(f"{rig}: PSNR {history[-1]:.2f} dB after {len(history)} iterations, {sec * 1e3:.1f} ms/iteration")
