"""The checked inputs of a reconstruction and their device buffers.

:func:`check_problem` and :func:`check_settings` validate everything a user passes to
:func:`rsocl.reconstruct` before any device work; :func:`stage_on_device` builds the operator
for the sampled sub-frames, checks that the run fits the device, and uploads the arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from rsocl.analysis.metrics import default_data_range
from rsocl.common import validation as check
from rsocl.model.operator import RollingShutterOperator
from rsocl.model.rig import Rig
from rsocl.solver.admm import ADMM

__all__ = ["DEFAULTS", "Problem", "Settings", "Staged", "check_problem", "check_settings", "stage_on_device"]

#: Defaults for data scaled to [0, 1] per sub-frame intensity (snapshots then lie in
#: [0, t_e/dt]): 200 ADMM iterations, ``lam = 0.1``, ``eta = 0.2``, 10 inner TV iterations
#: (measured in ``benchmarks/solver_settings.py``); :func:`rsocl.solver.reconstruct` tunes ``lam``
#: from the data unless given.
DEFAULTS = {"iterations": 200, "lam": 0.1, "eta": 0.2, "tv_iterations": 10}


@dataclass(frozen=True)
class Problem:
    """Checked host arrays: snapshots ``g`` ``(K, m, n)``, the rig, and the optional extras.

    ``valid`` marks the snapshot pixels that enter the data term (None: all of them);
    ``x0`` and ``truth`` are ``(T, m, n)`` or None.
    """

    g: np.ndarray
    rig: Rig
    valid: np.ndarray | None = None
    x0: np.ndarray | None = None
    truth: np.ndarray | None = None
    saturation: float | None = None


@dataclass(frozen=True)
class Settings:
    """Checked solver settings; ``lam``/``eta`` are None until :meth:`settled_for` a regularizer."""

    iterations: int
    lam: float | None
    eta: float | None
    tv_iterations: int | None
    projection: str
    tol: float | None
    callback: object

    def settled_for(self, reg, dtype) -> "Settings":
        """``lam``/``eta`` filled from the regularizer's recommendation, else :data:`DEFAULTS`.

        Raises ValueError when the regularizer does not support ``dtype``.
        """
        if np.dtype(dtype).name not in reg.dtypes:
            raise ValueError(f"dtype {np.dtype(dtype).name!r} is not supported by regularizer {reg!r}; "
                             f"supported: {list(reg.dtypes)}")
        recommended = {**DEFAULTS, **getattr(reg, "recommended", {})}
        return replace(self, lam=recommended["lam"] if self.lam is None else self.lam,
                       eta=recommended["eta"] if self.eta is None else self.eta)


def _cube(name, value, shape):
    if value is None:
        return None
    value = check.finite_array(name, value)
    if value.shape != shape:
        raise ValueError(f"{name} must have shape (T, m, n) = {shape}, got {value.shape}")
    return value


def check_problem(g, rig, *, x0=None, truth=None, saturation=None) -> Problem:
    """Validate the snapshots and the arrays that go with them against ``rig``."""
    if not isinstance(rig, Rig):
        raise ValueError(f"rig must be an rsocl.Rig, got {type(rig).__name__}")
    g = check.finite_array("g", g)
    expected = (rig.n_channels,) + rig.shape
    if g.shape != expected:
        raise ValueError(f"g must have shape (K, m, n) = {expected} for this rig, got {g.shape}")
    valid = None
    if saturation is not None:
        saturation = check.positive("saturation", saturation, "(snapshot units)")
        valid = g < saturation
        if not valid.any():
            raise ValueError(f"every snapshot pixel is >= saturation = {saturation!r}: nothing left to fit")
    cube = (rig.T,) + rig.shape
    return Problem(g, rig, valid, _cube("x0", x0, cube), _cube("truth", truth, cube), saturation)


def check_settings(*, iterations=None, lam=None, eta=None, tv_iterations=None, projection="exact", tol=None,
                   callback=None) -> Settings:
    """Validate the solver settings (None keeps a default)."""
    if callback is not None and not callable(callback):
        raise ValueError(f"callback must be callable, got {callback!r}")
    return Settings(
        iterations=check.positive_int("iterations", DEFAULTS["iterations"] if iterations is None else iterations),
        lam=None if lam is None else check.non_negative("lam", lam),
        eta=None if eta is None else check.non_negative("eta", eta),
        tv_iterations=None if tv_iterations is None else check.positive_int("tv_iterations", tv_iterations),
        projection=check.choice("projection", projection, {"exact", "paper"}),
        tol=None if tol is None else check.non_negative("tol", tol),
        callback=callback)


@dataclass
class Staged:
    """A problem on the device: the operator over the ``solved`` sub-frames and its arrays.

    ``truth``, ``data_range`` and ``unsolved_sq`` (the squared error of the sub-frames left
    at zero) are set only when a ground truth was given.
    """

    op: RollingShutterOperator
    solved: slice
    g: object
    x0: object = None
    truth: object = None
    data_range: float = 1.0
    unsolved_sq: float = 0.0


def stage_on_device(problem: Problem, reg, settings: Settings, *, device=None, dtype="float32") -> Staged:
    """Build the operator for the sampled sub-frames, check the memory, upload the arrays.

    Only the sub-frames some camera samples are modelled; the others stay zero in the result.
    Raises an error naming the sizes when the run would not fit the device.
    """
    import pyopencl.array as cla

    rig = problem.rig
    solved = rig.sampled_range()
    op = RollingShutterOperator(rig, device=device, dtype=dtype, subframes=solved)
    solved_cube = (op.T,) + rig.shape
    cube_bytes = int(np.prod(solved_cube)) * op.dtype.itemsize
    need = ADMM.buffers_bytes(op, settings.projection) + reg.workspace_bytes(solved_cube, op.dtype)
    if problem.truth is not None:
        need += cube_bytes
    op.device.check_fits(f"ADMM with {reg.name} on T={op.T} x {rig.shape[0]} x {rig.shape[1]} "
                         f"({op.dtype.name})", cube_bytes, total_bytes=need)

    def upload(array):
        return cla.to_device(op.queue, np.ascontiguousarray(array, dtype=op.dtype))

    staged = Staged(op, solved, upload(problem.g), None if problem.x0 is None else upload(problem.x0[solved]))
    truth = problem.truth
    if truth is not None:
        staged.truth = upload(truth[solved])
        staged.data_range = default_data_range(truth)
        staged.unsolved_sq = sum(float(np.sum(part.astype(np.float64) ** 2))
                                 for part in (truth[:solved.start], truth[solved.stop:]))
    return staged
