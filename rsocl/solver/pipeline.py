"""The solver's public steps: :func:`prepare` a checked problem on the device, :func:`tune` what the
caller left unset, :func:`run` the ADMM iterations.

:func:`rsocl.reconstruct`, :func:`rsocl.solver.sets.reconstruct_sets` and the tiles of
:mod:`rsocl.scale` all go through them with a :class:`~rsocl.solver.request.Request`::

    request = make_request(rig, lam=None)          # checked once
    prepared = prepare(request, check_problem(g, rig))
    result = run(prepared, tune(prepared))

:func:`tune` chooses ``lam`` and the regularizer's tunable options the caller left unset from the
snapshots (:func:`rsocl.solver.crossval.tune_parameters`); a batch of sets is tuned on its first
set and the choice serves every set (one capture, one setting). :func:`run` then starts from the
``interp3d`` interpolation of the snapshots unless the caller gave ``x0``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, replace

import numpy as np

from rsocl.model.interpolation_device import interp3d_device
from rsocl.solver.admm import ADMM
from rsocl.solver.crossval import Tuning, applied_blend, tune_parameters
from rsocl.solver.holdout import can_hold_out
from rsocl.solver.iterate import collect, run_iterations
from rsocl.solver.memory import memory_bytes, search_memory, search_peak
from rsocl.solver.problem import Problem, Staged, check_problem, stage_on_device
from rsocl.solver.request import Request, first_value, make_regularizer, make_request, run_params
from rsocl.solver.result import Result
from rsocl.solver.search_batch import BatchedFolds, batches_pay
from rsocl.solver.static import static_fix

__all__ = [
    "Prepared",
    "prepare",
    "tune",
    "tune_with",
    "run",
    "tune_and_run",
    "check_problem",
    "make_request",
    "make_regularizer",
    "Request",
    "Tuning",
    "run_params",
    "applied_blend",
]


@dataclass
class Prepared:
    """A request and its checked problem, staged on the device."""

    request: Request
    problem: Problem
    staged: Staged


def prepare(request: Request, problem: Problem, *, start: bool | None = None) -> Prepared:
    """Stage ``problem`` (:func:`~rsocl.solver.problem.check_problem`) on the request's device.

    Parameters
    ----------
    request : Request
    problem : rsocl.solver.problem.Problem
        The checked snapshots (and ``x0``, ``truth``, saturation) of one set or a batch.
    start : bool or None
        Whether the memory check counts a start cube beside a given ``x0``; None: when the run
        will have one (the caller's ``x0="interp3d"``, or the search's interpolation start).

    Raises
    ------
    ValueError
        When the run would not fit the device (naming the sizes), or a value is beyond the dtype.
    """
    if start is None:
        start = problem.interpolate or request.starts_from_interpolation
    staged = stage_on_device(
        problem, request.regularizer, request.settings, device=request.device, dtype=request.dtype, start=start
    )
    return Prepared(request, problem, staged)


def tune(prepared: Prepared) -> Tuning | None:
    """The values to run with: the request's earlier :class:`~rsocl.solver.crossval.Tuning`, or those
    chosen from the snapshots by the search (on the first set of a batch); None when the request
    does not tune or the caller left nothing to choose.

    The search's memory beside the staged problem is checked against the device before it runs;
    when a search is needed and the snapshots leave no pixels to hold out (one camera on 2x2 pixels or
    fewer, with a regularizer that has no one-snapshot preset for what it would search) a warning says
    so and None is returned.
    """
    choice = prepared.request.tune
    if choice is False:
        return None
    if isinstance(choice, Tuning):
        return choice
    return _search_first_set(prepared)


def tune_with(prepared: Prepared, search) -> Tuning | None:
    """:func:`tune`'s search of one set with ``search`` (a :class:`~rsocl.solver.ladder.Search`) over the
    whole of ``prepared``'s frame: how :func:`tune` searches the central block of a large frame, here on
    a problem that holds only that block (:mod:`rsocl.solver.search_cost`)."""
    return _choose_unset(prepared, search=search)


def run(prepared: Prepared, tuning: Tuning | None = None) -> Result:
    """Run the ADMM iterations with ``tuning``'s values (None: the request's) and collect the result.

    Values the caller fixed (``lam``, options) win over ``tuning``'s. The run starts from the
    caller's ``x0``, else from the ``interp3d`` interpolation when tuned or asked for, else from
    zeros; the result is blended towards that start by the request's ``blend`` (None: the
    search's). A tuned run from the interpolation then moves the static part of the scene back
    towards it by the rung's ``static`` weight (:mod:`rsocl.solver.static`; ``params["static_pixels"]``).
    ``params`` is :func:`~rsocl.solver.request.run_params`'s record with the saturated pixels, the
    solved sub-frames and the iterations that ran (``iterations_run``).
    """
    request, problem, staged = prepared.request, prepared.problem, prepared.staged
    reg, settings = request.settled(tuning)
    if (tuning is not None or problem.interpolate) and staged.x0 is None:
        staged.x0 = interpolation_start(problem, staged)
    solver = ADMM(
        staged.op,
        staged.g,
        reg,
        lam=settings.lam,
        eta=settings.eta,
        projection=settings.projection,
        x0=staged.x0,
        saturated=None if problem.valid is None else ~problem.valid,
    )
    blend = request.blend
    if blend is None:
        blend = applied_blend(tuning) if problem.x0 is None and staged.x0 is not None else 1.0
    start = "x0" if problem.x0 is not None else ("interp3d" if staged.x0 is not None else "zeros")
    static: dict = {}
    fix = None
    if tuning is not None and start == "interp3d" and request.rung.static > 0:

        def fix(solver):
            static["static_pixels"] = static_fix(solver, staged.x0, problem.g, request.rung.static)
            return bool(np.any(static["static_pixels"]))

    history = run_iterations(
        solver, staged, settings, progress=request.progress, blend=blend, auto=request.auto, fix=fix
    )
    datacube, extra = collect(solver, staged, problem)
    extra.update(static)
    params = run_params(
        request,
        reg,
        settings,
        lam=_plain(solver.lam),
        eta=_plain(solver.eta),
        device=staged.op.device.name,
        saturation=problem.saturation,
        tuning=tuning,
        blend=blend,
        start=start,
    )
    extra["iterations_run"] = len(history["residual"])
    return Result(datacube, history, problem.rig, {**params, **extra})


def tune_and_run(prepared: Prepared, started: float | None = None) -> Result:
    """:func:`run` with :func:`tune`'s values, timed: ``params["search_seconds"]`` is the wall time of
    the search (about 0 without one), ``params["seconds"]`` the whole time since ``started`` (a
    :func:`time.perf_counter` reading; None: since the search began), seconds."""
    begun = time.perf_counter()
    tuning = tune(prepared)
    searched = time.perf_counter() - begun
    result = run(prepared, tuning)
    result.params["search_seconds"] = searched
    result.params["seconds"] = time.perf_counter() - (begun if started is None else started)
    return result


def _plain(value):
    """A float, or a list of floats (one per set): what the parameters of a result hold."""
    return value.tolist() if isinstance(value, np.ndarray) else value


def interpolation_start(problem, staged):
    """``interp3d`` of the snapshots over the solved sub-frames, on the device (one per set of a batch).
    Saturated samples enter with their clipped value: a lower bound, nearer the truth than an interpolation
    across them (``docs/saturation.md``)."""
    return interp3d_device(staged.op, problem.g, None, staged.solved)


def _choose_unset(prepared: Prepared, checked=False, search=None):
    """Run :func:`tune_parameters` over what the caller left unset on one set; None when nothing is.

    ``prepared`` holds one set. The request's rung (:mod:`rsocl.solver.ladder`) sets the search: its
    ``lam`` candidates, hold-out folds and iterations per candidate; on a frame its crop applies to,
    the search runs on that central block (over the block's own rig). Unless
    ``checked`` (the caller did it, for a batch), the search's memory beside the staged problem is
    checked first. A rig of one camera gets the regularizer's
    :attr:`~rsocl.solver.regularizer.Regularizer.one_snapshot` values instead of a search for them;
    with one snapshot per pixel, when those leave only ``lam`` unset, the settled ``lam`` without a
    search (``docs/solver-notes.md``, one camera).
    """
    request, problem, staged = prepared.request, prepared.problem, prepared.staged
    settings, rig = request.settings, problem.rig
    space = request.search_space()
    if space is None:
        return None
    if len(rig.cameras) == 1:  # one camera, one frame or several: the criterion cannot rank priors in time
        reg = request.regularizer  # its preset applies on every rung, whether the rung searches options or not
        unset = set(getattr(reg, "tunable", {})) - request.given.option_names(reg)
        preset = {k: float(v) for k, v in getattr(reg, "one_snapshot", {}).items() if k in unset}
        space = replace(space, tunable={k: v for k, v in space.tunable.items() if k not in preset}, preset=preset)
        if rig.n_channels == 1 and not space.tunable and (preset or np.isscalar(space.lam)):
            # the caller fixed lam, or the preset leaves only lam, which hardly matters here (see the docstring)
            lam = space.lam if isinstance(space.lam, (float, int, np.number)) else first_value(settings.lam)
            return Tuning(chosen={**preset, "lam": float(lam)}, fixed=space.fixed, preset=preset)
    if not can_hold_out(rig.shape, rig.n_channels):
        warnings.warn(
            f"the snapshots of a {rig.n_channels}-camera rig on {rig.shape[0]}x"
            f"{rig.shape[1]} pixels leave no pixels to hold out for choosing the parameters: "
            "the run uses the fixed defaults (as tune=False); fix lam and the regularizer's options to "
            "silence this",
            UserWarning,
            stacklevel=5,
        )
        return None
    if search is None:
        search, box = request.rung.search_for(rig.shape)
        if box is not None:
            return _choose_unset(_cropped(prepared, box), checked, search)
    if not checked:
        _check_search_fits(prepared)
    patterns = search.patterns(rig.shape, rig.n_channels)
    base = request.rung.iterations if request.auto else settings.iterations
    return tune_parameters(
        staged.op,
        staged.g,
        problem.g,
        request.with_options,
        space,
        eta=first_value(settings.eta),
        projection=settings.projection,
        valid=None,  # clipped samples as recorded: one-sided only in the run (docs/saturation.md)
        iterations=search.candidate_iterations(base, len(patterns)),
        patterns=patterns,
        progress=request.progress,
        runner=BatchedFolds() if batches_pay(staged.op.device) else None,
    )


def _cropped(prepared: Prepared, box) -> Prepared:
    """``prepared``'s single set cut to ``box = (y, x, height, width)`` and staged on its own."""
    y, x, h, w = box
    problem = prepared.problem
    cut = (..., slice(y, y + h), slice(x, x + w))
    one = replace(
        problem,
        g=np.ascontiguousarray(problem.g[cut]),
        rig=problem.rig.crop(box),
        valid=None if problem.valid is None else np.ascontiguousarray(problem.valid[cut]),
        x0=None,
        truth=None,
    )
    return prepare(prepared.request, one, start=False)


def _check_search_fits(prepared: Prepared):
    """Raise before the search when it and the staged problem together would not fit the device."""
    problem, reg, projection = prepared.problem, prepared.request.regularizer, prepared.request.settings.projection
    op = prepared.staged.op
    peak = search_peak(
        op, reg, projection, problem.batch, truth=problem.truth is not None, start=problem.x0 is not None
    )
    extra = search_memory(op, reg, projection, problem.batch)
    largest = memory_bytes(op, reg, projection, 1)[0]
    op.device.check_fits(
        f"choosing the parameters from the data (ADMM with {reg.name} on "
        f"T={op.T} x {problem.rig.shape[0]} x {problem.rig.shape[1]}, "
        f"{extra / 2**20:.1f} MiB beside the staged problem's {(peak - extra) / 2**20:.1f} MiB)",
        largest,
        total_bytes=peak,
        dtype=op.dtype,
        also="fix lam and the regularizer's options or pass tune=False (rsocl reconstruct --fixed)",
    )


def _search_first_set(prepared: Prepared):
    """:func:`_choose_unset` on the problem, or on the first set of a batch (staged on its own)."""
    request, problem = prepared.request, prepared.problem
    if problem.batch is None:
        return _choose_unset(prepared)
    if request.search_space() is None:
        return None
    _check_search_fits(prepared)
    one = replace(
        problem,
        g=problem.g[0],
        valid=None if problem.valid is None else problem.valid[0],
        x0=None,
        truth=None,
        batch=None,
    )
    first = replace(
        request,
        settings=replace(
            request.settings, lam=first_value(request.settings.lam), eta=first_value(request.settings.eta)
        ),
    )
    return _choose_unset(prepare(first, one, start=False), checked=True)
