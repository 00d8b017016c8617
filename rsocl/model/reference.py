"""NumPy reference of the forward model, its adjoint, TV and ADMM: the test oracle.

Written for clarity, not speed: the shutter weights are built densely as a
``(K, T, m, n)`` array straight from the definitions of ``docs/model.md``. The
OpenCL code must agree with these functions to rounding.
"""

from __future__ import annotations

import numpy as np

from rsocl.model.rig import Rig

__all__ = ["weights", "forward", "adjoint", "psi", "gram", "tv_chambolle", "project", "admm"]


def weights(rig: Rig) -> np.ndarray:
    """Dense shutter weights ``w[k, s, y, x]`` (float64), without gains.

    ``exact``: ``|[s, s+1) ∩ [start, end]|`` in units of ``dt``;
    ``binary``: ``1`` if ``start <= s <= end`` (times in units of ``dt``).
    """
    win = rig.windows
    start = (win.index + win.fraction)[:, None]
    end = win.end[:, None]
    s = np.arange(rig.T, dtype=np.float64)[None, :, None, None]
    if rig.mask == "exact":
        return np.clip(np.minimum(s + 1.0, end) - np.maximum(s, start), 0.0, None)
    return ((s >= start) & (s <= end)).astype(np.float64)


def _gained(rig: Rig) -> np.ndarray:
    return weights(rig) * rig.windows.gain[:, None, None, None]


def forward(rig: Rig, f: np.ndarray) -> np.ndarray:
    """``g[k, y, x] = gain[k] * sum_s w[k, s, y, x] f[s, y, x]``; ``f`` is ``(T, m, n)``."""
    return np.einsum("ksyx,syx->kyx", _gained(rig), np.asarray(f, dtype=np.float64))


def adjoint(rig: Rig, g: np.ndarray) -> np.ndarray:
    """``f[s, y, x] = sum_k gain[k] w[k, s, y, x] g[k, y, x]``; ``g`` is ``(K, m, n)``."""
    return np.einsum("ksyx,kyx->syx", _gained(rig), np.asarray(g, dtype=np.float64))


def psi(rig: Rig) -> np.ndarray:
    """Diagonal of ``H Hᵀ``: ``gain[k]^2 sum_s w[k, s, y, x]^2``, ``(K, m, n)``."""
    return np.sum(_gained(rig) ** 2, axis=1)


def gram(rig: Rig) -> np.ndarray:
    """Per-pixel blocks of ``H Hᵀ``, ``M[y, x, k, l]``, shape ``(m, n, K, K)``."""
    w = _gained(rig)
    return np.einsum("ksyx,lsyx->yxkl", w, w)


#: The pseudo-inverse's cutoff of :func:`project`: a block's eigenvalues below this fraction of its largest
#: are dropped, as rsocl's float64 runs drop them (``rsocl.solver.inverse.RCOND``; float32 runs: 1e-6).
RCOND = 1e-10


def project(rig: Rig, v, g, eta: float, projection: str = "exact", saturated=None, rcond: float = RCOND) -> np.ndarray:
    """The ADMM data step ``f = v + Hᵀ (eta I + H Hᵀ)⁻¹ (g - H v)`` (docs/model.md Eq. 12).

    ``projection="paper"`` uses the diagonal ``psi`` instead (Eq. 15). Singular
    blocks (``eta = 0``) use the pseudo-inverse, whose eigenvalues below ``rcond`` of the block's largest are
    dropped (:data:`RCOND`: float64's cutoff; give 1e-6 to check a float32 run); nothing is divided by zero.
    ``saturated`` (bool, shape of ``g``): those samples enter one-sided (docs/model.md, saturated pixels).
    """
    r = np.asarray(g, dtype=np.float64) - forward(rig, v)
    if projection == "paper":
        if saturated is not None:  # the terms separate: the clamp is the exact one-sided step
            r = np.where(saturated, np.maximum(r, 0.0), r)
        d = eta + psi(rig)
        z = np.divide(r, d, out=np.zeros_like(r), where=d > 0)
    elif saturated is not None and np.any(saturated):
        z = _one_sided(rig, r, eta, saturated)
    else:
        K = rig.n_channels
        block = gram(rig) + eta * np.eye(K)
        z = np.einsum("yxkl,lyx->kyx", np.linalg.pinv(block, rcond=rcond, hermitian=True), r)
    return np.asarray(v, dtype=np.float64) + adjoint(rig, z)


def _one_sided(rig: Rig, r, eta: float, saturated) -> np.ndarray:
    """``z`` of the exact data step with the ``saturated`` samples one-sided (``f = v + Hᵀ z``), pixel by pixel:
    the minimiser of ``½ Σ_two-sided (r - M z)² + ½ Σ_saturated max(r - M z, 0)² + ½ eta zᵀ M z`` found by
    trying every set of active saturated samples (solved with the pseudo-inverse of ``eta I + M``'s sub-block,
    not the inverse blocks the kernels use) until one meets the optimality conditions. ``eta = 0`` is the limit
    ``eta → 0⁺`` (docs/model.md, saturated pixels), where an active set's sub-block may be singular."""
    from itertools import combinations

    M = gram(rig)
    z = np.zeros_like(r)
    for y, x in np.ndindex(rig.shape):
        rp, sat = r[:, y, x], np.asarray(saturated[:, y, x], bool)
        m = M[y, x]
        two = np.flatnonzero(~sat)
        ones = np.flatnonzero(sat)
        top_m = max(np.diag(m).max(), np.finfo(float).tiny)
        for count in range(len(ones), -1, -1):
            for chosen in combinations(ones, count):
                zz = _active_step(m, rp, eta, np.sort(np.concatenate([two, np.asarray(chosen, int)])))
                after = rp - m @ zz  # each sample's residual after the step
                tol = 1e-9 * (np.abs(rp).max() + np.abs(m) @ np.abs(zz))  # over the rounding of r - M z
                # an active saturated sample needs a residual >= 0 after the step, and where it is 0 a multiplier
                # z_k >= 0 (with eta > 0 the residual is eta z_k; at eta = 0 a residual left by a singular
                # sub-block makes z_k grow as residual / eta); an inactive one's residual after the step <= 0
                if all(after[k] > tol[k] or (after[k] >= -tol[k] and zz[k] >= -tol[k] / top_m) for k in chosen) and all(
                    after[k] <= tol[k] for k in ones if k not in chosen
                ):
                    z[:, y, x] = zz
                    break
            else:
                continue
            break
    return z


def _active_step(m: np.ndarray, r: np.ndarray, eta: float, active: np.ndarray) -> np.ndarray:
    """``z`` with the samples ``active`` only: ``z_A = (eta I + M_AA)⁺ r_A`` (the pseudo-inverse: the least-norm
    solution of a singular sub-block at ``eta = 0``), 0 elsewhere."""
    zz = np.zeros(len(r))
    if len(active):
        sub = m[np.ix_(active, active)] + eta * np.eye(len(active))
        zz[active] = np.linalg.pinv(sub, rcond=RCOND, hermitian=True) @ r[active]
    return zz


def tv_chambolle(image, weight: float, iterations: int, temporal_weight: float = 1.0, step: float = 1.0) -> np.ndarray:
    """Chambolle's isotropic TV of a ``(T, m, n)`` array, as ``skimage.restoration.denoise_tv_chambolle``.

    With ``temporal_weight = 1`` and ``step = 1`` this is scikit-image's 3-D algorithm
    (``eps = 0``: exactly ``iterations`` iterations); with ``0`` it is its 2-D algorithm on
    each sub-frame. Other values scale the temporal finite difference, with the step
    ``tau = step / (2 (2 + temporal_weight²))`` (rsocl's TV plugin takes ``step`` 0.9 by default).
    """
    image = np.asarray(image, dtype=np.float64)
    if weight == 0:
        return image.copy()
    axis_weight = (float(temporal_weight), 1.0, 1.0)
    tau = float(step) / (2.0 * (2.0 + axis_weight[0] ** 2))
    p = np.zeros((3,) + image.shape)
    out = image
    for i in range(iterations):
        if i > 0:
            d = -(axis_weight[0] * p[0] + p[1] + p[2])
            d[1:] += axis_weight[0] * p[0, :-1]
            d[:, 1:] += p[1, :, :-1]
            d[:, :, 1:] += p[2, :, :, :-1]
            out = image + d
        g = np.zeros_like(p)
        g[0, :-1] = axis_weight[0] * np.diff(out, axis=0)
        g[1, :, :-1] = np.diff(out, axis=1)
        g[2, :, :, :-1] = np.diff(out, axis=2)
        norm = np.sqrt((g**2).sum(axis=0))
        p = (p - tau * g) / (1.0 + norm * (tau / weight))
    return out


def admm(
    rig: Rig,
    g,
    *,
    iterations: int,
    lam: float,
    eta: float,
    tv_iterations: int,
    temporal_weight: float = 1.0,
    projection: str = "exact",
    x0=None,
    step: float = 1.0,
    saturated=None,
    rcond: float = RCOND,
) -> np.ndarray:
    """The ADMM-TV of docs/model.md with the reference pieces above; returns ``theta``.

    ``eta = 0`` is GAP: the dual ``b`` stays zero and the TV weight is ``lam``. ``step``: the TV
    step of :func:`tv_chambolle`. ``saturated``: the samples :func:`project` takes one-sided; ``rcond``: its
    pseudo-inverse's cutoff.
    """
    theta = np.zeros((rig.T,) + rig.shape) if x0 is None else np.asarray(x0, dtype=np.float64).copy()
    b = np.zeros_like(theta)
    weight = lam / eta if eta > 0 else lam
    for _ in range(iterations):
        v = theta + b
        f = project(rig, v, g, eta, projection, saturated, rcond)
        theta = tv_chambolle(f - b, weight, tv_iterations, temporal_weight, step)
        if eta > 0:
            b = b - (f - theta)
    return theta
