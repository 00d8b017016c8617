"""``reconstruct``: the user-facing ADMM run, with checks, history and a progress bar."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from rsocl.common import validation as check
from rsocl.solver.admm import ADMM
from rsocl.model.operator import RollingShutterOperator
from rsocl.analysis.metrics import default_data_range
from rsocl.common.registry import load
from rsocl.device.reduction import sum_sq_diff
from rsocl.solver.regularizer import Regularizer
from rsocl.model.rig import Rig

__all__ = ["reconstruct", "Result", "DEFAULTS"]

#: Defaults for data scaled to [0, 1] per sub-frame intensity (snapshots then lie in
#: [0, t_e/dt]); chosen by measurement on the shared videos (benchmarks/quality.py, README);
#: the TV regularizer's own defaults: 10 inner iterations, temporal weight 3.
DEFAULTS = {"iterations": 200, "lam": 0.1, "eta": 0.2, "tv_iterations": 10}


@dataclass
class Result:
    """A reconstruction.

    Attributes
    ----------
    datacube : ndarray, shape (T, m, n)
        The estimate ``theta`` (same intensity units as the scene).
    history : dict of str -> ndarray
        Per iteration: ``residual`` (``‖g - H theta‖/‖g‖``), ``time`` (seconds since
        the start, wall clock, when the host has that iteration's residual: the device
        has finished it), and ``psnr`` (dB, when a ground truth was given).
    rig : Rig
    params : dict
        Everything needed to repeat the run.
    """

    datacube: np.ndarray
    history: dict
    rig: Rig
    params: dict = field(default_factory=dict)

    @property
    def iterations(self) -> int:
        return len(self.history["residual"])

    @property
    def trimmed(self) -> np.ndarray:
        """The ``T_se`` sub-frames kept by the rig's trimming rule."""
        return self.datacube[self.rig.kept_subframes()]


def _regularizer(regularizer, options, tv_iterations):
    options = dict(options or {})
    if isinstance(regularizer, Regularizer):
        if options:
            raise ValueError("regularizer_options apply to a regularizer given by name, not to an instance")
        return regularizer
    if not isinstance(regularizer, str):
        raise ValueError(f"regularizer must be a name or a Regularizer, got {regularizer!r}")
    cls = load("rsocl.regularizers", regularizer)
    if tv_iterations is not None:
        if "iterations" not in getattr(cls, "options", {}):
            raise ValueError(f"tv_iterations applies to iterative denoisers; {regularizer!r} has no 'iterations'")
        options.setdefault("iterations", tv_iterations)
    return cls(**options)


def reconstruct(g, rig: Rig, regularizer="tv", *, iterations=None, lam=None, eta=None, tv_iterations=None,
                projection="exact", device=None, dtype="float32", callback=None, x0=None, tol=None,
                truth=None, regularizer_options=None, saturation=None, progress=False) -> Result:
    """Reconstruct the ``(T, m, n)`` datacube from snapshots ``g`` ``(K, m, n)`` with ADMM.

    Parameters
    ----------
    g : array_like, shape (K, m, n)
        Snapshots registered on the reference grid, in the units of the forward
        model (a scene in [0, 1] gives snapshots in [0, t_e/dt]).
    rig : Rig
    regularizer : str or Regularizer
        Registry name (``"tv"``) or an instance.
    iterations : int
        ADMM iterations (default 200).
    lam : float
        Regularization strength, >= 0 (default: the regularizer's ``recommended`` value,
        else 0.1, for data in [0, 1]).
    eta : float
        ADMM penalty, >= 0 (default likewise, else 0.2); ``0`` runs GAP (denoiser weight ``lam``).
    tv_iterations : int
        Inner iterations of an iterative denoiser (default: the regularizer's own, 10 for TV).
    projection : {"exact", "paper"}
        Exact per-pixel ``(eta I + H Hᵀ)⁻¹`` or the paper's diagonal (Eq. 15).
    device, dtype
        OpenCL device spec and ``"float32"``/``"float64"``.
    callback : callable or None
        ``callback(iteration, residual, theta)`` after each iteration (``theta`` is a
        device array); returning True stops the run.
    x0 : array_like or None
        Initial estimate ``(T, m, n)``; zeros by default.
    tol : float or None
        Stop when the relative change of the residual between iterations is below ``tol``.
    truth : array_like or None
        Ground truth ``(T, m, n)``: adds per-iteration PSNR (dB; peak 1 for data in
        [0, 1], see :func:`rsocl.analysis.metrics.default_data_range`).
    regularizer_options : dict or None
        Options of a regularizer given by name.
    saturation : float or None
        Snapshot value (same units as ``g``) at or above which a pixel is flagged as
        saturated and left out of the data term; None keeps every pixel.
    progress : bool
        Show a progress bar (tqdm).
    """
    import pyopencl.array as cla

    if not isinstance(rig, Rig):
        raise ValueError(f"rig must be an rsocl.Rig, got {type(rig).__name__}")
    iterations = check.positive_int("iterations", DEFAULTS["iterations"] if iterations is None else iterations)
    if lam is not None:
        lam = check.non_negative("lam", lam)
    if eta is not None:
        eta = check.non_negative("eta", eta)
    if tv_iterations is not None:
        tv_iterations = check.positive_int("tv_iterations", tv_iterations)
    projection = check.choice("projection", projection, {"exact", "paper"})
    if tol is not None:
        tol = check.non_negative("tol", tol)
    if callback is not None and not callable(callback):
        raise ValueError(f"callback must be callable, got {callback!r}")
    g = check.finite_array("g", g)
    expected = (rig.n_channels,) + rig.shape
    if g.shape != expected:
        raise ValueError(f"g must have shape (K, m, n) = {expected} for this rig, got {g.shape}")
    cube = (rig.T,) + rig.shape
    valid = None
    if saturation is not None:
        saturation = check.positive("saturation", saturation, "(snapshot units)")
        valid = g < saturation
        if not valid.any():
            raise ValueError(f"every snapshot pixel is >= saturation = {saturation!r}: nothing left to fit")
    if x0 is not None:
        x0 = check.finite_array("x0", x0)
        if x0.shape != cube:
            raise ValueError(f"x0 must have shape (T, m, n) = {cube}, got {x0.shape}")
    if truth is not None:
        truth = check.finite_array("truth", truth)
        if truth.shape != cube:
            raise ValueError(f"truth must have shape (T, m, n) = {cube}, got {truth.shape}")
    reg = _regularizer(regularizer, regularizer_options, tv_iterations)
    # a regularizer may recommend its own lam/eta (measured for it); else the global defaults
    recommended = {**DEFAULTS, **getattr(reg, "recommended", {})}
    lam = recommended["lam"] if lam is None else lam
    eta = recommended["eta"] if eta is None else eta
    if np.dtype(dtype).name not in reg.dtypes:
        raise ValueError(f"dtype {np.dtype(dtype).name!r} is not supported by regularizer {reg!r}; "
                         f"supported: {list(reg.dtypes)}")

    # model only the sub-frames some camera samples; the others stay zero in the result
    solved = rig.sampled_range()
    op = RollingShutterOperator(rig, device=device, dtype=dtype, subframes=solved)
    solved_cube = (op.T,) + rig.shape
    cube_bytes = int(np.prod(solved_cube)) * op.dtype.itemsize
    need = ADMM.buffers_bytes(op, projection) + reg.workspace_bytes(solved_cube, op.dtype)
    if truth is not None:
        need += cube_bytes
    op.device.check_fits(f"ADMM with {reg.name} on T={op.T} x {rig.shape[0]} x {rig.shape[1]} "
                         f"({op.dtype.name})", cube_bytes, total_bytes=need)

    queue = op.queue
    g_dev = cla.to_device(queue, np.ascontiguousarray(g, dtype=op.dtype))
    x0_dev = None if x0 is None else cla.to_device(queue, np.ascontiguousarray(x0[solved], dtype=op.dtype))
    truth_dev = None
    if truth is not None:
        truth_dev = cla.to_device(queue, np.ascontiguousarray(truth[solved], dtype=op.dtype))
        data_range = default_data_range(truth)
        # squared error of the sub-frames left at zero, added to the device's sum
        unsolved_sq = sum(float(np.sum(part.astype(np.float64) ** 2))
                          for part in (truth[:solved.start], truth[solved.stop:]))

    solver = ADMM(op, g_dev, reg, lam=lam, eta=eta, projection=projection, x0=x0_dev, valid=valid)
    history = {"residual": [], "time": []}
    if truth is not None:
        history["psnr"] = []
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=iterations, desc=f"ADMM-{reg.name}", unit="it", leave=False, mininterval=0.5,
                   disable=None)

    def record(it, residual):
        """Book iteration ``it``'s residual; True when the run should stop after it."""
        if not math.isfinite(residual):
            hint = (" The paper's diagonal step (projection='paper') is stable only when eta is large "
                    f"against psi (max psi = {float(op.psi.max()):.3g}); use projection='exact' or raise eta."
                    if projection == "paper" else " Check lam, eta and the data scale.")
            raise FloatingPointError(f"ADMM diverged at iteration {it + 1}: the residual is {residual}.{hint}")
        history["residual"].append(residual)
        history["time"].append(time.perf_counter() - start)
        if truth_dev is not None:
            mse = (sum_sq_diff(solver.theta, truth_dev) + unsolved_sq) / truth.size
            history["psnr"].append(10 * math.log10(data_range ** 2 / mse) if mse > 0 else math.inf)
        if bar is not None:
            bar.update(1)
            bar.set_postfix(residual=f"{residual:.3g}", **({"psnr": f"{history['psnr'][-1]:.2f}"}
                                                            if truth is not None else {}))
        if callback is not None and callback(it, residual, solver.theta):
            return True
        if tol is not None and it > 0:
            prev = history["residual"][-2]
            if abs(prev - residual) <= tol * max(residual, np.finfo(float).tiny):
                return True
        return False

    # With nothing to look at theta between iterations (no callback, no truth, no tol), the
    # residual of iteration it is read while the device runs iteration it + 1: the host never
    # waits on an idle device (measured: 30 % of the time at 50x50, 5 % at 128x128).
    pipelined = callback is None and truth_dev is None and tol is None
    queue.finish()
    start = time.perf_counter()
    try:
        pending = None
        for it in range(iterations):
            solver.step()
            current = solver.residual_async()
            if not pipelined:
                if record(it, current.result()):
                    break
            else:
                if pending is not None:
                    record(it - 1, pending.result())
                pending = current
        if pending is not None:                     # pipelined: the last iteration's residual
            record(iterations - 1, pending.result())
    finally:
        if bar is not None:
            bar.close()
    datacube = np.zeros(cube, dtype=op.dtype)
    datacube[solved] = solver.theta.get()
    if not np.all(np.isfinite(datacube)):
        raise FloatingPointError("the reconstruction produced NaN or inf; check lam/eta and the data scale")
    params = {"regularizer": reg.name, "regularizer_options": dict(reg.values), "iterations": iterations,
              "lam": lam, "eta": eta, "projection": projection, "dtype": op.dtype.name,
              "device": op.device.name, "tol": tol, "saturation": saturation,
              "saturated_pixels": 0 if valid is None else int(valid.size - valid.sum()),
              "solved_subframes": [solved.start, solved.stop]}
    return Result(datacube, {k: np.asarray(v) for k, v in history.items()}, rig, params)
