"""The self-tuning step of :func:`rsocl.solver.reconstruct`: what the caller left unset
(``lam``, the regularizer's :attr:`~rsocl.solver.regularizer.Regularizer.tunable` options) is
chosen from the snapshots by :func:`rsocl.solver.crossval.tune_parameters`, and the run then
starts from the :func:`~rsocl.model.interpolation.interp3d` interpolation of the snapshots.

A batch of sets of one rig is tuned on its first set, and the chosen values apply to every set
(one capture, one setting); per-set ``lam`` or ``eta`` given by the caller are kept.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from rsocl.common import validation as check
from rsocl.model.interpolation_device import interp3d_device
from rsocl.solver.admm import state_bytes
from rsocl.solver.memory import memory_bytes, problem_bytes, workspace_memory
from rsocl.solver.problem import stage_on_device
from rsocl.solver.regularizer import Regularizer
from rsocl.solver.crossval import CANDIDATE_FRACTION, LAM_FACTORS, Tuning, can_hold_out, default_patterns, tune_parameters

__all__ = ["check_tune", "check_blend", "tune_and_start", "choose_unset", "chosen_options", "search_memory", "search_peak",
           "starts_from_interpolation", "interpolation_start"]


def check_tune(tune, reg=None):
    """``tune`` checked: ``True``/``False`` (a bool), or an earlier :class:`Tuning` to run with; with
    ``reg`` (the regularizer to run), a Tuning must have chosen options ``reg`` has."""
    if isinstance(tune, Tuning):
        foreign = sorted(set(chosen_options(tune)) - set(reg.values)) if reg is not None else []
        if foreign:
            raise ValueError(f"tune: the earlier Tuning chose {foreign}, options {reg.name!r} does not have "
                             f"(it has {sorted(reg.values)}); pass tune=True to choose for {reg.name!r}, or "
                             "tune=False for its fixed defaults")
        return tune
    if isinstance(tune, (bool, np.bool_)):
        return bool(tune)
    raise ValueError(f"tune must be True, False or an rsocl.solver.crossval.Tuning, got {tune!r}")


def check_blend(blend, has_start: bool):
    """``blend`` checked in [0, 1] (None: the search's choice, passes). A value below 1 moves the result
    towards the run's start, so it needs one (``has_start``: ``x0`` given, or the interpolation a
    self-tuned run starts from, :func:`starts_from_interpolation`); a run from zeros refuses it."""
    if blend is None:
        return None
    blend = check.in_range("blend", blend, 0.0, 1.0)
    if blend < 1 and not has_start:
        raise ValueError(f"blend = {blend:g} moves the result towards the run's start, and this run starts from "
                         "zeros (tune=False, or nothing left to choose from the data): give the start as x0 (an "
                         "array or 'interp3d'), or leave blend None")
    return blend


def _first(value):
    """The first set's value of a per-set tuple, else the value."""
    return value[0] if isinstance(value, tuple) else value


def chosen_options(tuning) -> dict:
    """The regularizer options a :class:`Tuning` chose (its ``chosen`` without ``lam``)."""
    return {k: v for k, v in tuning.chosen.items() if k != "lam"}


def with_options(regularizer, reg, user_options, options, tv_iterations, make):
    """``reg``'s kind with ``options`` over the caller's ones (``make``: the name -> instance factory)."""
    if isinstance(regularizer, Regularizer):
        return type(reg)(**{**reg.values, **options})
    return make(regularizer, {**dict(user_options or {}), **options}, tv_iterations)


def _given(regularizer, reg, user_options) -> set:
    """Names of the regularizer options the caller fixed: every option of an instance, else those
    in ``user_options``. They are neither searched nor replaced by an earlier choice."""
    return set(reg.values) if isinstance(regularizer, Regularizer) else set(user_options or {})


def _to_search(settings, regularizer, reg, user_options, fixed_lam):
    """``(tunable, lam, fixed)`` of the search, or None when the caller left nothing to choose."""
    given = _given(regularizer, reg, user_options)
    tunable = {k: v for k, v in getattr(reg, "tunable", {}).items() if k not in given}
    lam0 = _first(settings.lam)
    if fixed_lam is None:
        lam = [lam0 * f for f in LAM_FACTORS] if lam0 > 0 else lam0
    else:
        lam = _first(fixed_lam)
    if (not tunable and np.isscalar(lam)) or (np.isscalar(lam) and lam == 0):
        return None                    # nothing to choose; lam = 0 makes the regularizer's options moot
    fixed = {k: v for k, v in reg.values.items() if k in given}
    if fixed_lam is not None:
        fixed["lam"] = lam
    return tunable, lam, fixed


def choose_unset(problem, staged, settings, regularizer, reg, user_options, fixed_lam, make, progress=False,
                 checked=False):
    """Run :func:`tune_parameters` over what the caller left unset on one set; None when nothing is.

    ``problem`` and ``staged`` are one set, checked and staged; ``settings`` are settled
    (:meth:`~rsocl.solver.problem.Settings.settled_for`); ``fixed_lam`` is the caller's ``lam``
    (None: searched). ``lam`` candidates are the settled ``lam`` times
    :data:`~rsocl.solver.crossval.LAM_FACTORS`; each candidate runs
    :data:`~rsocl.solver.crossval.CANDIDATE_FRACTION` of ``settings.iterations``, split among the
    hold-out patterns (:func:`~rsocl.solver.crossval.default_patterns`; at least 10 per pattern). When the
    folds leave no pixels to fit or to score (:func:`~rsocl.solver.crossval.can_hold_out`: one camera
    on 2x2 pixels or fewer, or too few valid pixels) a warning says so and None is returned.
    Unless ``checked`` (the caller did it, for a batch), the search's memory beside the staged
    problem (:func:`search_peak`) is checked against the device before anything runs. A rig with
    one snapshot per pixel gets the regularizer's
    :attr:`~rsocl.solver.regularizer.Regularizer.one_snapshot` values instead of a search for them, and
    when those leave only ``lam`` unset, the settled ``lam`` without a search: with one snapshot per
    pixel and TV's preset (temporal weight 10), ``lam`` from 0.3 to 10 times the settled value changed
    PSNR by at most 0.07 dB (6 one-camera rigs of ``benchmarks/tv_step.py``, built-in scene and
    Runner, noiseless and with Poisson noise of 300 and 30 photons at full scale; 36 cases), while the
    search for it took most of the tuned run's time.
    """
    search = _to_search(settings, regularizer, reg, user_options, fixed_lam)
    if search is None:
        return None
    if not can_hold_out(problem.rig.shape, problem.rig.n_channels, problem.valid):
        warnings.warn(f"the snapshots of a {problem.rig.n_channels}-camera rig on {problem.rig.shape[0]}x"
                      f"{problem.rig.shape[1]} pixels leave no pixels to hold out for choosing the parameters: "
                      "the run uses the fixed defaults (as tune=False); fix lam and the regularizer's options to "
                      "silence this", UserWarning, stacklevel=5)
        return None
    tunable, lam, fixed = search
    preset = {}
    if problem.rig.n_channels == 1:         # one snapshot per pixel: the criterion cannot rank priors in time
        preset = {k: float(v) for k, v in getattr(reg, "one_snapshot", {}).items() if k in tunable}
        tunable = {k: v for k, v in tunable.items() if k not in preset}
        if not tunable and (preset or np.isscalar(lam)):
            # the caller fixed lam, or the preset leaves only lam, which hardly matters here (see the docstring)
            return Tuning(chosen={**preset, "lam": float(lam if np.isscalar(lam) else _first(settings.lam))},
                          fixed=fixed, preset=preset)
    if not checked:
        _check_search_fits(problem, staged, settings, reg)
    patterns = default_patterns(problem.rig.shape, problem.rig.n_channels)
    return tune_parameters(
        staged.op, staged.g, problem.g, problem.rig,
        lambda options: with_options(regularizer, reg, user_options, options, settings.tv_iterations, make),
        tunable=tunable, lam=lam, eta=_first(settings.eta), projection=settings.projection, valid=problem.valid,
        iterations=max(10, round(CANDIDATE_FRACTION * settings.iterations / len(patterns))), patterns=patterns,
        fixed=fixed, preset=preset, progress=progress)


def interpolation_start(problem, staged):
    """``interp3d`` of the snapshots over the solved sub-frames, on the device (one per set of a batch)."""
    return interp3d_device(staged.op, problem.g, problem.valid, staged.solved)


def search_memory(op, reg, projection: str, batch) -> int:
    """Device bytes the search allocates beside the staged problem, freed before the run's solver is
    made: per hold-out pattern (:func:`~rsocl.solver.crossval.default_patterns`) one set's ADMM arrays, its
    warm start, its warm start's prediction of the snapshots, held-out weights and regularizer
    workspace (a fold's solver keeps the previous candidate's regularizer until its own turn); and for
    a batch (``batch`` sets, None: one set) the first set staged on its own (operator geometry and
    snapshots)."""
    cube = op.domain_shape
    itemsize = np.dtype(op.dtype).itemsize
    snap = op.K * int(np.prod(cube[1:])) * itemsize
    per_fold = (state_bytes(cube, op.K, op.dtype, projection, 1) + int(np.prod(cube)) * itemsize + 2 * snap
                + workspace_memory(cube, op.dtype, reg, 1))
    extra = len(default_patterns(op.rig.shape, op.K)) * per_fold
    if batch is not None:
        extra += problem_bytes(cube, op.K, op.dtype, 1)
    return extra


def search_peak(op, reg, projection: str, batch, *, truth=False, start=False) -> int:
    """Device bytes held while the search runs: the staged problem of ``batch`` sets (None: one set;
    :func:`~rsocl.solver.memory.problem_bytes`, with a ground truth and a given start cube per set
    when ``truth``, ``start``) and :func:`search_memory`."""
    held = problem_bytes(op.domain_shape, op.K, op.dtype, batch or 1, truth=truth, start=start)
    return held + search_memory(op, reg, projection, batch)


def starts_from_interpolation(tune, settings, regularizer, reg, user_options, fixed_lam) -> bool:
    """Whether :func:`tune_and_start` will give the run an ``interp3d`` start (when the caller gave no
    ``x0``): ``tune`` is an earlier :class:`Tuning`, or True with something left to choose."""
    if tune is False:
        return False
    return isinstance(tune, Tuning) or _to_search(settings, regularizer, reg, user_options, fixed_lam) is not None


def _check_search_fits(problem, staged, settings, reg):
    """Raise before the search when it and the staged problem together would not fit the device."""
    op = staged.op
    peak = search_peak(op, reg, settings.projection, problem.batch, truth=problem.truth is not None,
                       start=problem.x0 is not None)
    extra = search_memory(op, reg, settings.projection, problem.batch)
    largest = memory_bytes(op, reg, settings.projection, 1)[0]
    op.device.check_fits(f"choosing the parameters from the data (ADMM with {reg.name} on "
                         f"T={op.T} x {problem.rig.shape[0]} x {problem.rig.shape[1]}, "
                         f"{extra / 2**20:.1f} MiB beside the staged problem's {(peak - extra) / 2**20:.1f} MiB)",
                         largest, total_bytes=peak, dtype=op.dtype,
                         also="fix lam and the regularizer's options or pass tune=False (rsocl reconstruct --fast)")


def _search_first_set(problem, staged, settings, regularizer, reg, user_options, fixed_lam, make, device, dtype,
                      progress):
    """:func:`choose_unset` on the problem, or on the first set of a batch (staged on its own)."""
    if problem.batch is None:
        return choose_unset(problem, staged, settings, regularizer, reg, user_options, fixed_lam, make, progress)
    if _to_search(settings, regularizer, reg, user_options, fixed_lam) is None:
        return None
    _check_search_fits(problem, staged, settings, reg)
    one = replace(problem, g=problem.g[0], valid=None if problem.valid is None else problem.valid[0],
                  x0=None, truth=None, batch=None)
    one_staged = stage_on_device(one, reg, replace(settings, lam=_first(settings.lam), eta=_first(settings.eta)),
                                 device=device, dtype=dtype)
    return choose_unset(one, one_staged, settings, regularizer, reg, user_options, fixed_lam, make, progress,
                        checked=True)


def tune_and_start(problem, staged, settings, regularizer, reg, user_options, fixed_lam, *, make, device, dtype,
                   choice=None, progress=False):
    """Choose the unset parameters from the snapshots (or run with ``choice``, an earlier
    :class:`~rsocl.solver.crossval.Tuning`, without a search) and set the warm start.

    Returns ``(reg, settings, tuning)``: the regularizer and settings to run with, and the
    :class:`~rsocl.solver.crossval.Tuning` record (None when nothing was left to choose; then
    ``reg``, ``settings`` and ``staged`` are unchanged). Values the caller fixed (``lam``, options)
    win over an earlier choice's. ``staged.x0`` becomes the interpolation start unless the caller
    gave ``x0``.
    """
    tuning = choice if choice is not None else _search_first_set(
        problem, staged, settings, regularizer, reg, user_options, fixed_lam, make, device, dtype, progress)
    if tuning is None:
        return reg, settings, None
    given = _given(regularizer, reg, user_options)
    options = {k: v for k, v in chosen_options(tuning).items() if k not in given}
    reg = with_options(regularizer, reg, user_options, options, settings.tv_iterations, make)
    if fixed_lam is None:
        settings = replace(settings, lam=tuning.chosen["lam"])
    if staged.x0 is None:
        staged.x0 = interpolation_start(problem, staged)
    return reg, settings, tuning
