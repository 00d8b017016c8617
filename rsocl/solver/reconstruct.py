"""``reconstruct``: what a user runs. Four named steps: check the inputs, stage them on the
device, run the ADMM iterations, collect the result (:mod:`rsocl.solver.problem`,
:mod:`rsocl.solver.iterate`)."""

from __future__ import annotations

from rsocl.common.registry import load
from rsocl.model.rig import Rig
from rsocl.solver.admm import ADMM
from rsocl.solver.autotune import tune_and_start
from rsocl.solver.iterate import collect, run_iterations
from rsocl.solver.problem import DEFAULTS, check_problem, check_settings, stage_on_device
from rsocl.solver.regularizer import Regularizer
from rsocl.solver.result import Result

__all__ = ["reconstruct", "make_regularizer", "Result", "DEFAULTS"]


def make_regularizer(regularizer, options=None, tv_iterations=None) -> Regularizer:
    """A regularizer instance from a registry name (with options) or an instance (without)."""
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
                truth=None, regularizer_options=None, saturation=None, tune=True, progress=False) -> Result:
    """Reconstruct the ``(T, m, n)`` datacube from snapshots ``g`` ``(K, m, n)`` with ADMM.

    A batch of ``B`` sets of the same rig, ``g`` of shape ``(B, K, m, n)``, is reconstructed in one
    run: every kernel launch serves the whole batch, each set is solved as if alone (same result to
    float rounding), and the result's datacube is ``(B, T, m, n)`` (see :class:`Result`;
    :func:`rsocl.solver.sets.reconstruct_sets` sizes batches to the device).

    Parameters
    ----------
    g : array_like, shape (K, m, n) or (B, K, m, n)
        Snapshots registered on the reference grid, in the units of the forward
        model (a scene in [0, 1] gives snapshots in [0, t_e/dt]).
    rig : Rig
    regularizer : str or Regularizer
        Registry name (``"tv"``) or an instance.
    iterations : int
        ADMM iterations (default 200).
    lam : float or sequence of float
        Regularization strength, >= 0 (default: the regularizer's ``recommended`` value,
        else 0.1, for data in [0, 1]); for a batch, one number or one per set.
    eta : float or sequence of float
        ADMM penalty, >= 0 (default likewise, else 0.2); ``0`` runs GAP (denoiser weight ``lam``);
        for a batch, one number or one per set.
    tv_iterations : int
        Inner iterations of an iterative denoiser (default: the regularizer's own, 10 for TV).
    projection : {"exact", "paper"}
        Exact per-pixel ``(eta I + H Hᵀ)⁻¹`` or the paper's diagonal (Eq. 15).
    device, dtype
        OpenCL device spec and ``"float32"``/``"float64"``.
    callback : callable or None
        ``callback(iteration, residual, theta)`` after each iteration (``theta`` is a
        device array; for a batch ``residual`` has one value per set); returning True stops the run.
    x0 : array_like or None
        Initial estimate ``(T, m, n)`` (for a batch: every set's, or ``(B, T, m, n)``); zeros by default.
    tol : float or None
        Stop when the relative change of the residual between iterations is below ``tol``
        (for a batch: in every set).
    truth : array_like or None
        Ground truth ``(T, m, n)`` (for a batch ``(B, T, m, n)``, or one for every set): adds
        per-iteration PSNR (dB; peak 1 for data in [0, 1], see
        :func:`rsocl.analysis.metrics.default_data_range`).
    regularizer_options : dict or None
        Options of a regularizer given by name.
    saturation : float or None
        Snapshot value (same units as ``g``) at or above which a pixel is flagged as
        saturated and left out of the data term; None keeps every pixel.
    progress : bool
        Show a progress bar (tqdm).
    tune : bool
        True (default): choose ``lam`` and the regularizer's tunable options (TV:
        ``temporal_weight``) that the caller left unset from the snapshots alone, by block
        cross-validation on held-out snapshot pixels (:mod:`rsocl.solver.tuning`; no ground
        truth is used), then run with them from :func:`rsocl.model.interpolation.interp3d`
        unless ``x0`` is given (measured in ``benchmarks/quality.py``: -0.12 to +0.01 dB at
        64x64, +0.2 to +0.7 dB at 128x128 over a zero start). Values the caller gives
        (``lam``, ``regularizer_options``, a regularizer instance's options) are kept. The
        chosen values and every candidate's criterion are in ``Result.params["tuning"]``. A
        batch is tuned on its first set and the choice applies to every set
        (:mod:`rsocl.solver.autotune`). False: the fixed defaults, zero start.
    """
    problem = check_problem(g, rig, x0=x0, truth=truth, saturation=saturation)
    settings = check_settings(iterations=iterations, lam=lam, eta=eta, tv_iterations=tv_iterations,
                              projection=projection, tol=tol, callback=callback)
    reg = make_regularizer(regularizer, regularizer_options, settings.tv_iterations)
    fixed_lam = settings.lam
    settings = settings.settled_for(reg, dtype).for_batch(problem.batch)
    staged = stage_on_device(problem, reg, settings, device=device, dtype=dtype)
    tuning = None
    if tune:
        reg, settings, tuning = tune_and_start(problem, staged, settings, regularizer, reg, regularizer_options,
                                               fixed_lam, make=make_regularizer, device=device, dtype=dtype,
                                               progress=progress)
    solver = ADMM(staged.op, staged.g, reg, lam=settings.lam, eta=settings.eta, projection=settings.projection,
                  x0=staged.x0, valid=problem.valid)
    history = run_iterations(solver, staged, settings, progress=progress)
    result = collect(solver, staged, problem, settings, reg, history)
    result.params["tuning"] = tuning.as_params() if tuning is not None else None
    result.params["start"] = "x0" if problem.x0 is not None else ("interp3d" if tuning is not None else "zeros")
    return result

