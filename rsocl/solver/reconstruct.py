"""``reconstruct``: what a user runs. Five named steps: check the inputs, stage them on the
device, choose what the caller left unset from the data, run the ADMM iterations, collect the
result (:mod:`rsocl.solver.problem`, :mod:`rsocl.solver.autotune`, :mod:`rsocl.solver.iterate`).

**Batches.** ``g`` of shape ``(B, K, m, n)`` holds ``B`` sets of one rig and is reconstructed in
one run: every kernel launch serves the whole batch, each set is solved as if alone (the same
result to float rounding) and the datacube is ``(B, T, m, n)`` (:class:`Result`). ``lam`` and
``eta`` are one number or one per set; ``x0`` and ``truth`` one ``(T, m, n)`` cube for every set
or ``(B, T, m, n)``; the callback's residual and ``tol`` act per set.
:func:`rsocl.solver.sets.reconstruct_sets` sizes batches to the device.

**Self-tuning** (``tune=True``, the default). ``lam`` and the regularizer's tunable options that
the caller left unset are chosen from the snapshots alone by block cross-validation on held-out
snapshot pixels (:mod:`rsocl.solver.tuning`; no ground truth is used), and the run starts from
:func:`rsocl.model.interpolation.interp3d` unless ``x0`` is given (measured in
``benchmarks/quality.py``: -0.12 to +0.01 dB at 64x64, +0.1 to +0.7 dB at 128x128 over a zero
start). Values the caller gives (``lam``, ``regularizer_options``, a regularizer instance's
options) are kept. The chosen values and every candidate's criterion are in
``Result.params["tuning"]``. A batch is tuned on its first set and the choice serves every set.
"""

from __future__ import annotations

from rsocl.common.registry import load
from rsocl.model.curvature import default_scale
from rsocl.model.rig import Rig
from rsocl.solver.admm import ADMM
from rsocl.solver.autotune import check_blend, check_tune, interpolation_start, starts_from_interpolation, tune_and_start
from rsocl.solver.iterate import collect, run_iterations
from rsocl.solver.problem import DEFAULTS, check_problem, check_settings, stage_on_device
from rsocl.solver.regularizer import Regularizer
from rsocl.solver.result import Result
from rsocl.solver.tuning import applied_blend

__all__ = ["reconstruct", "make_regularizer", "Result", "DEFAULTS"]


def make_regularizer(regularizer, options=None, tv_iterations=None) -> Regularizer:
    """A regularizer instance from a registry name (with options) or an instance (without)."""
    options = dict(options or {})
    if isinstance(regularizer, Regularizer):
        if options:
            raise ValueError("regularizer_options apply to a regularizer given by name, not to an instance")
        if tv_iterations is not None and tv_iterations != getattr(regularizer, "iterations", None):
            raise ValueError(f"tv_iterations applies to a regularizer given by name; the instance {regularizer!r} "
                             "keeps its own options (set its 'iterations' when making it)")
        return regularizer
    if not isinstance(regularizer, str):
        raise ValueError(f"regularizer must be a name or a Regularizer, got {regularizer!r}")
    cls = load("rsocl.regularizers", regularizer)
    if tv_iterations is not None:
        if "iterations" not in getattr(cls, "options", {}):
            raise ValueError(f"tv_iterations applies to iterative denoisers; {regularizer!r} has no 'iterations'")
        if "iterations" in options:
            made = cls(**options)
            if made.iterations != tv_iterations:
                raise ValueError(f"tv_iterations = {tv_iterations!r} and regularizer_options['iterations'] = "
                                 f"{options['iterations']!r} disagree; give the inner iterations once")
            return made
        options["iterations"] = tv_iterations
    return cls(**options)


def reconstruct(g, rig: Rig, regularizer="tv", *, iterations=None, lam=None, eta=None, tv_iterations=None,
                projection="exact", device=None, dtype="float32", callback=None, x0=None, tol=None,
                truth=None, regularizer_options=None, saturation=None, tune=True, blend=None,
                progress=False) -> Result:
    """Reconstruct the ``(T, m, n)`` datacube from snapshots ``g`` ``(K, m, n)`` with ADMM.

    For a batch of sets, ``g`` ``(B, K, m, n)`` -> ``(B, T, m, n)``; ``lam``, ``eta`` may then be one
    value per set and ``x0``, ``truth`` one cube per set (module doc). Data in [0, 1] per sub-frame.

    Parameters
    ----------
    g : array_like
        Snapshots on the reference grid (a scene in [0, 1] gives values in [0, t_e/dt]).
    rig : Rig
    regularizer : str or Regularizer
        Registry name (``"tv"``) or an instance; ``regularizer_options``: options of a named one.
    iterations : int
        ADMM iterations (default 200); ``tv_iterations``: inner denoiser iterations (TV: 10).
    lam, eta : float
        Regularization strength and ADMM penalty, >= 0 (default: the regularizer's
        ``recommended``, else 0.1 and 0.2 (``eta`` 5 with ``projection="paper"``,
        :data:`rsocl.solver.problem.PAPER_ETA`), for the paper's configuration; other rigs scale both
        by :func:`rsocl.model.curvature.default_scale`, the data term's curvature relative to
        it); ``eta = 0`` runs GAP (denoiser weight ``lam``).
    projection : {"exact", "paper"}
        Exact per-pixel ``(eta I + H Hᵀ)⁻¹`` or the paper's diagonal (Eq. 15).
    device, dtype, progress
        OpenCL device spec, ``"float32"``/``"float64"``, and a progress bar (tqdm).
    callback : callable or None
        ``callback(iteration, residual, theta)`` after each iteration; True stops the run.
    x0 : array_like, "interp3d" or None
        Start ``(T, m, n)``; ``"interp3d"``: the interpolation of the snapshots in time
        (:func:`rsocl.model.interpolation.interp3d`, computed on the device); None (default): zeros,
        or ``"interp3d"`` when tuned.
    truth : array_like or None
        Ground truth ``(T, m, n)``: adds PSNR in dB (peak 1 for data in [0, 1]) to the history.
    tol : float or None
        Stop when the residual's relative change between iterations is below ``tol``.
    saturation : float or None
        Snapshot value (units of ``g``) from which a pixel is left out of the data term.
    tune : bool or Tuning
        Choose ``lam`` and the tunable options (TV: ``temporal_weight``) the caller left unset
        from the snapshots alone (:mod:`rsocl.solver.autotune`); a ``Tuning``: run with that
        earlier choice, without a search; False: fixed defaults.
    blend : float or None
        In [0, 1]: return ``x0 + blend (theta - x0)``, the solver's result moved back towards the
        run's start: ``x0`` when given, else the interpolation a self-tuned run starts from (a run
        from zeros refuses a blend below 1); 1 returns the solver's result as it is. None
        (default): the blend the search chose on the same held-out pixels
        (:mod:`rsocl.solver.tuning`) when the run starts from the interpolation, else 1. Recorded
        in ``Result.params["blend"]``.

    A run whose residual ``‖g - H theta‖ / ‖g‖`` turns NaN or grows past 1000 times its smallest
    raises ``FloatingPointError``; one that stays bounded but ends above 1 and 10 times its
    smallest (the paper's diagonal step at small ``eta``) returns with a ``RuntimeWarning``.
    """
    interpolate = isinstance(x0, str)
    if interpolate and x0 != "interp3d":
        raise ValueError(f"x0 must be an array (T, m, n), 'interp3d' or None, got {x0!r}")
    problem = check_problem(g, rig, x0=None if interpolate else x0, truth=truth, saturation=saturation)
    tune = check_tune(tune)
    settings = check_settings(iterations=iterations, lam=lam, eta=eta, tv_iterations=tv_iterations,
                              projection=projection, tol=tol, callback=callback)
    reg = make_regularizer(regularizer, regularizer_options, settings.tv_iterations)
    tune = check_tune(tune, reg)
    fixed_lam = settings.lam
    settings = settings.settled_for(reg, dtype, scale=default_scale(rig)).for_batch(problem.batch)
    start = interpolate or starts_from_interpolation(tune, settings, regularizer, reg, regularizer_options, fixed_lam)
    blend = check_blend(blend, x0 is not None or start)
    staged = stage_on_device(problem, reg, settings, device=device, dtype=dtype, start=start)
    tuning = None
    if tune is not False:
        reg, settings, tuning = tune_and_start(problem, staged, settings, regularizer, reg, regularizer_options,
                                               fixed_lam, make=make_regularizer, device=device, dtype=dtype,
                                               choice=None if tune is True else tune, progress=progress)
    if interpolate and staged.x0 is None:
        staged.x0 = interpolation_start(problem, staged)
    solver = ADMM(staged.op, staged.g, reg, lam=settings.lam, eta=settings.eta, projection=settings.projection,
                  x0=staged.x0, valid=problem.valid)
    if blend is None:
        blend = applied_blend(tuning) if problem.x0 is None and staged.x0 is not None else 1.0
    history = run_iterations(solver, staged, settings, progress=progress, blend=blend)
    result = collect(solver, staged, problem, settings, reg, history)
    result.params["tuning"] = tuning.as_params() if tuning is not None else None
    result.params["blend"] = blend
    result.params["start"] = "x0" if problem.x0 is not None else ("interp3d" if staged.x0 is not None else "zeros")
    return result
