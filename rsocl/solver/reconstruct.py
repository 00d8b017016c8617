"""``reconstruct``: what a user runs. Five named steps: check the inputs, stage them on the
device, choose what the caller left unset from the data, run the ADMM iterations, collect the
result (:func:`~rsocl.solver.request.make_request`, then :mod:`rsocl.solver.pipeline`'s ``prepare``,
``tune`` and ``run``).

**Batches.** ``g`` of shape ``(B, K, m, n)`` holds ``B`` sets of one rig and is reconstructed in
one run: every kernel launch serves the whole batch, each set is solved as if alone (the same
result to float rounding) and the datacube is ``(B, T, m, n)`` (:class:`~rsocl.solver.result.Result`). ``lam`` and
``eta`` are one number or one per set; ``x0`` and ``truth`` one ``(T, m, n)`` cube for every set
or ``(B, T, m, n)``; the callback's residual and ``tol`` act per set (each set stops at its own iteration).
:func:`rsocl.solver.sets.reconstruct_sets` sizes batches to the device.

**Self-tuning** (``tune=True``, the default). ``lam`` and the regularizer's tunable options that
the caller left unset are chosen from the snapshots alone by block cross-validation on held-out
snapshot pixels (:mod:`rsocl.solver.crossval`; no ground truth is used), and the run starts from
:func:`rsocl.model.interpolation.interp3d` unless ``x0`` is given (``docs/solver-notes.md``).
Values the caller gives (``lam``, ``regularizer_options``, a regularizer instance's options) are
kept. The chosen values and every candidate's criterion are in ``Result.params["tuning"]``. A
batch is tuned on its first set and the choice serves every set.
"""

from __future__ import annotations

import time

from rsocl.common.hints import ArrayLike, Callback, DTypeLike, Options, PerSet
from rsocl.device.context import Device
from rsocl.model.rig import Rig
from rsocl.solver.crossval import Tuning
from rsocl.solver.ladder import DEFAULT_QUALITY
from rsocl.solver.pipeline import prepare, tune_and_run
from rsocl.solver.problem import check_problem
from rsocl.solver.regularizer import Regularizer
from rsocl.solver.request import make_request
from rsocl.solver.result import Result

__all__ = ["reconstruct", "Result"]


def reconstruct(
    g: ArrayLike,
    rig: Rig,
    regularizer: str | Regularizer = "tv",
    *,
    iterations: int | str | None = None,
    lam: PerSet | None = None,
    eta: PerSet | None = None,
    tv_iterations: int | None = None,
    projection: str = "exact",
    device: str | Device | None = None,
    dtype: DTypeLike = "float32",
    callback: Callback | None = None,
    x0: ArrayLike | str | None = None,
    tol: float | None = None,
    truth: ArrayLike | None = None,
    regularizer_options: Options | None = None,
    saturation: float | None = None,
    tune: bool | Tuning = True,
    blend: float | None = None,
    progress: bool = False,
    quality: str = DEFAULT_QUALITY,
) -> Result:
    """Reconstruct the ``(T, m, n)`` datacube from snapshots ``g`` ``(K, m, n)`` with ADMM.

    For a batch of sets, ``g`` ``(B, K, m, n)`` -> ``(B, T, m, n)``; ``lam``, ``eta`` may then be one
    value per set and ``x0``, ``truth`` one cube per set (module doc). Data in [0, 1] per sub-frame.

    Parameters
    ----------
    g : array_like
        Snapshots on the reference grid (a scene in [0, 1] gives values in [0, t_e/dt]).
    rig : Rig
    regularizer : str or Regularizer
        Registry name (``"tv"``) or an instance; ``regularizer_options``: options of a named one. The
        options given (by name, or when making the instance) are kept; the search chooses the others.
    iterations : int or "auto"
        ADMM iterations, 1 to :data:`rsocl.solver.problem.MAX_ITERATIONS` (default: the ``quality`` rung's);
        ``"auto"``: until the residual settles, with a cap (:func:`rsocl.solver.ladder.auto_stop`; the count
        that ran is ``Result.params["iterations_run"]``).
        ``tv_iterations``: inner denoiser iterations (default: :data:`rsocl.solver.problem.DEFAULTS`).
    lam, eta : float
        Regularization strength and ADMM penalty, >= 0 (default: the regularizer's
        ``recommended``, else :data:`~rsocl.solver.problem.DEFAULTS` (``eta``
        :data:`~rsocl.solver.problem.PAPER_ETA` with ``projection="paper"``), for the paper's
        configuration; other rigs scale both by :func:`rsocl.model.curvature.default_scale`, the
        data term's curvature relative to it); ``eta = 0`` runs GAP (denoiser weight ``lam``).
    projection : {"exact", "paper"}
        Exact per-pixel ``(eta I + H Hᵀ)⁻¹`` or the paper's diagonal (Eq. 15).
    device, dtype, progress
        OpenCL device spec, ``"float32"``/``"float64"``, and a progress bar (tqdm).
    callback : callable or None
        ``callback(iteration, residual, theta)`` after each iteration; True stops the run. For a batch
        ``residual`` holds one value per set, NaN for a set that has stopped (``tol``, ``"auto"``); that
        set's slice of ``theta`` runs on until the batch stops and is then put back to its stop.
    x0 : array_like, "interp3d" or None
        Start ``(T, m, n)``; ``"interp3d"``: the interpolation of the snapshots in time
        (:func:`rsocl.model.interpolation.interp3d`, computed on the device); None (default): zeros,
        or ``"interp3d"`` when tuned.
    truth : array_like or None
        Ground truth ``(T, m, n)``: adds PSNR in dB (peak 1 for data in [0, 1]) to the history.
    tol : float or None
        Stop when the residual's relative change between iterations is below ``tol``.
    saturation : float or None
        Snapshot value (units of ``g``) at and above which a pixel is clipped: its value is a lower
        bound, which the data step meets one-sided (``docs/model.md``, saturated pixels; measured:
        ``docs/saturation.md``).
    tune : bool or Tuning
        Choose ``lam`` and the tunable options (TV: ``temporal_weight``) the caller left unset
        from the snapshots alone (:func:`rsocl.solver.pipeline.tune`); a ``Tuning``: run with that
        earlier choice, without a search; False: fixed defaults.
    quality : {"fast", "balanced", "best"}
        The rung of the speed/quality ladder a tuned run follows: its iterations, its search and the
        static-part fix (:mod:`rsocl.solver.ladder`; measured in ``docs/quality_ladder.md``).
    blend : float or None
        In [0, 1]: return ``x0 + blend (theta - x0)``, the solver's result moved back towards the
        run's start: ``x0`` when given, else the interpolation a self-tuned run starts from (a run
        from zeros refuses a blend below 1); 1 returns the solver's result as it is. None
        (default): the blend the search chose on the same held-out pixels
        (:mod:`rsocl.solver.crossval`) when the run starts from the interpolation, else 1. Recorded
        in ``Result.params["blend"]``.

    ``Result.seconds`` is the whole run's wall time and ``Result.search_seconds`` the search's share.

    A run whose residual ``‖g - H theta‖ / ‖g‖`` turns NaN or grows past 1000 times its smallest
    raises ``FloatingPointError``; one that stays bounded but ends above 1 and 10 times its
    smallest (the paper's diagonal step at small ``eta``) returns with a ``RuntimeWarning``.
    """
    started = time.perf_counter()
    problem = check_problem(g, rig, x0=x0, truth=truth, saturation=saturation)
    request = make_request(
        rig,
        regularizer,
        sets=problem.batch,
        x0_given=x0 is not None,
        iterations=iterations,
        lam=lam,
        eta=eta,
        tv_iterations=tv_iterations,
        projection=projection,
        tol=tol,
        callback=callback,
        dtype=dtype,
        device=device,
        regularizer_options=regularizer_options,
        tune=tune,
        blend=blend,
        progress=progress,
        quality=quality,
    )
    with request.regularizer.in_use:  # an instance another thread runs with: its turn first
        return tune_and_run(prepare(request, problem), started)
