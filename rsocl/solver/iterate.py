"""Running the ADMM iterations of a staged problem, and collecting the result.

:func:`run_iterations` books each iteration's residual (and PSNR with a ground truth) in a
history, drives the progress bar, the callback and the ``tol`` stop; :func:`collect` reads the
estimate back and assembles the :class:`~rsocl.solver.result.Result`.
"""

from __future__ import annotations

import math
import time

import numpy as np

from rsocl.device.reduction import sum_sq_diff
from rsocl.solver.result import Result

__all__ = ["run_iterations", "collect"]


class _History:
    """Per-iteration records of a run; :meth:`record` says when the run should stop."""

    def __init__(self, solver, staged, settings, total_size, bar):
        self.solver, self.staged, self.settings, self.bar = solver, staged, settings, bar
        self.total_size = total_size
        self.values = {"residual": [], "time": []}
        if staged.truth is not None:
            self.values["psnr"] = []
        self.start = time.perf_counter()

    def _diverged(self, it, residual):
        if self.settings.projection == "paper":
            psi = float(self.staged.op.psi.max())
            hint = (" The paper's diagonal step (projection='paper') is stable only when eta is large "
                    f"against psi (max psi = {psi:.3g}); use projection='exact' or raise eta.")
        else:
            hint = " Check lam, eta and the data scale."
        return FloatingPointError(f"ADMM diverged at iteration {it + 1}: the residual is {residual}.{hint}")

    def record(self, it, residual) -> bool:
        """Book iteration ``it``'s residual; True when the run should stop after it."""
        if not math.isfinite(residual):
            raise self._diverged(it, residual)
        values, staged, settings = self.values, self.staged, self.settings
        values["residual"].append(residual)
        values["time"].append(time.perf_counter() - self.start)
        if staged.truth is not None:
            mse = (sum_sq_diff(self.solver.theta, staged.truth) + staged.unsolved_sq) / self.total_size
            values["psnr"].append(10 * math.log10(staged.data_range ** 2 / mse) if mse > 0 else math.inf)
        if self.bar is not None:
            self.bar.update(1)
            extra = {"psnr": f"{values['psnr'][-1]:.2f}"} if "psnr" in values else {}
            self.bar.set_postfix(residual=f"{residual:.3g}", **extra)
        if settings.callback is not None and settings.callback(it, residual, self.solver.theta):
            return True
        if settings.tol is not None and it > 0:
            prev = values["residual"][-2]
            if abs(prev - residual) <= settings.tol * max(residual, np.finfo(float).tiny):
                return True
        return False


def run_iterations(solver, staged, settings, *, progress=False) -> dict:
    """Run up to ``settings.iterations`` ADMM steps; the history as a dict of arrays.

    With nothing to look at ``theta`` between iterations (no callback, no truth, no tol), the
    residual of iteration ``it`` is read while the device runs iteration ``it + 1``: the host
    never waits on an idle device.
    """
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=settings.iterations, desc=f"ADMM-{solver.regularizer.name}", unit="it", leave=False,
                   mininterval=0.5, disable=None)
    rig = staged.op.rig
    history = _History(solver, staged, settings, rig.T * rig.shape[0] * rig.shape[1], bar)
    pipelined = settings.callback is None and staged.truth is None and settings.tol is None
    staged.op.queue.finish()
    history.start = time.perf_counter()
    try:
        pending = None
        for it in range(settings.iterations):
            solver.step()
            current = solver.residual_async()
            if not pipelined:
                if history.record(it, current.result()):
                    break
            else:
                if pending is not None:
                    history.record(it - 1, pending.result())
                pending = current
        if pending is not None:                     # pipelined: the last iteration's residual
            history.record(settings.iterations - 1, pending.result())
    finally:
        if bar is not None:
            bar.close()
    return {k: np.asarray(v) for k, v in history.values.items()}


def collect(solver, staged, problem, settings, reg, history) -> Result:
    """The datacube (unsolved sub-frames zero), checked finite, with the run's parameters."""
    op, solved, rig = staged.op, staged.solved, problem.rig
    datacube = np.zeros((rig.T,) + rig.shape, dtype=op.dtype)
    datacube[solved] = solver.theta.get()
    if not np.all(np.isfinite(datacube)):
        raise FloatingPointError("the reconstruction produced NaN or inf; check lam/eta and the data scale")
    valid = problem.valid
    params = {"regularizer": reg.name, "regularizer_options": dict(reg.values), "iterations": settings.iterations,
              "lam": settings.lam, "eta": settings.eta, "projection": settings.projection,
              "dtype": op.dtype.name, "device": op.device.name, "tol": settings.tol,
              "saturation": problem.saturation,
              "saturated_pixels": 0 if valid is None else int(valid.size - valid.sum()),
              "solved_subframes": [solved.start, solved.stop]}
    return Result(datacube, history, rig, params)
