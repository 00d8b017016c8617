"""The parameter search: block cross-validation on the snapshots, no ground truth.

Candidate parameters run ADMM on the snapshot pixels that a hold-out pattern
(:mod:`rsocl.solver.holdout`) keeps, and are scored by how well ``H theta`` predicts the held-out
ones: the relative prediction error ``‖g - H theta‖ / ‖g‖`` over the held-out pixels. Only the
snapshots, the rig and the saturation mask enter.

The search is a coordinate search in log space: each tunable option of the regularizer (TV:
``temporal_weight``, :attr:`rsocl.solver.regularizer.Regularizer.tunable`) over its coarse
values at the middle ``lam``, then the geometric midpoints next to the best value; then ``lam``
over its candidates. Every candidate starts from the same warm start (``interp3d`` of the fitted
pixels) and runs ``iterations`` ADMM steps; values the caller fixed are not searched. A runner that
takes several candidates at once (``run_many``: :class:`rsocl.solver.search_batch.BatchedFolds`) gets
each round's candidates in one call, the ``lam`` round's run ahead with the last option's midpoints;
the search books and chooses exactly as one candidate at a time.

The same held-out pixels choose how far the result moves from its start: the returned estimate
is ``x0 + blend (theta - x0)``, ``blend`` in [0, 1], whose held-out error is a quadratic in
``blend`` (``H`` is linear), minimised in closed form per candidate (:func:`_blend`).

Why this criterion and design, and what they were measured to give: ``docs/solver-notes.md``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from rsocl.common import validation as check
from rsocl.device.reduction import sum_sq_diff_async
from rsocl.solver.folds import make_fold, run_folds
from rsocl.solver.holdout import default_patterns, fold_masks

__all__ = [
    "LAM_FACTORS",
    "CANDIDATE_FRACTION",
    "SearchSpace",
    "Tuning",
    "tune_parameters",
    "run_folds",
    "applied_blend",
]

#: ``lam`` candidates, as factors of the recommended ``lam`` (TV: 0.03, 0.1, 0.3).
LAM_FACTORS = (0.3, 1.0, 3.0)
#: ADMM iterations per candidate, as a fraction of the final run's iterations, split among the
#: hold-out patterns (at least 10 each): at the default 200 iterations, 50; the search's 8
#: candidates cost about 2 final runs (other fractions compared: ``docs/solver-notes.md``).
CANDIDATE_FRACTION = 0.25


@dataclass
class SearchSpace:
    """What :func:`tune_parameters` searches.

    Attributes
    ----------
    tunable : dict of str -> sequence of float
        Options to search and their coarse candidate values (log spaced, > 0).
    lam : float or sequence of float
        The ``lam`` to use, or its candidates (the middle one is tried first).
    fixed : dict
        Parameters the caller fixed (not searched), recorded in the result.
    preset : dict
        Regularizer options set without a search: given to every candidate, recorded in the
        result's ``chosen`` and ``preset``.
    """

    tunable: dict
    lam: float | list[float] | tuple[float, ...]
    fixed: dict = field(default_factory=dict)
    preset: dict = field(default_factory=dict)


@dataclass
class Tuning:
    """What :func:`tune_parameters` chose and why.

    Attributes
    ----------
    chosen : dict
        ``lam`` and the tuned options (e.g. ``temporal_weight``) with the smallest criterion.
    candidates : list of dict
        Every candidate run, in order: its ``lam``, options and ``score`` (the relative
        prediction error of the held-out snapshot pixels).
    fixed : dict
        Parameters the caller fixed (not searched).
    iterations : int
        ADMM iterations per candidate.
    block : int or list of int
        Side of the hold-out blocks, pixels (the sides, largest first, when patterns of several
        sides were pooled).
    held_out : int
        Snapshot pixels held out (over all folds).
    folds : int
        Hold-out patterns pooled (:func:`default_patterns`).
    seconds : float
        Wall time of the whole search, seconds.
    preset : dict
        Options set without a search (in ``chosen`` too): a rig of one camera gets the
        regularizer's :attr:`~rsocl.solver.regularizer.Regularizer.one_snapshot` values.
    blend : float or None
        The chosen candidate's blend with the interpolation, in [0, 1] (module doc): the run that
        starts from :func:`interp3d` returns ``x0 + blend (theta - x0)``. None: no search ran.
    """

    chosen: dict
    candidates: list = field(default_factory=list)
    fixed: dict = field(default_factory=dict)
    iterations: int = 0
    block: int | list = 0
    held_out: int = 0
    seconds: float = 0.0
    folds: int = 1
    preset: dict = field(default_factory=dict)
    blend: float | None = None

    @classmethod
    def from_params(cls, record: dict) -> Tuning:
        """The choice recorded by :meth:`as_params` (e.g. ``Result.params["tuning"]``), to run again with.

        Raises
        ------
        ValueError
            Naming ``params["tuning"]``, when ``record`` is not such a record: None (a run that did not
            tune), the whole ``Result.params``, or a dict without a ``chosen`` dict.
        """
        _check_record(record)
        candidates = [
            {k: (math.inf if k == "score" and v is None else v) for k, v in c.items()}
            for c in record.get("candidates", [])
        ]
        return cls(
            dict(record["chosen"]),
            candidates,
            dict(record.get("fixed", {})),
            record.get("iterations_per_candidate", 0),
            record.get("block", 0),
            record.get("held_out_pixels", 0),
            record.get("seconds", 0.0),
            record.get("folds", 1),
            dict(record.get("preset", {})),
            record.get("blend"),
        )

    def as_params(self) -> dict:
        """A JSON-ready record for :attr:`rsocl.solver.result.Result.params`."""
        return {
            "criterion": "block cross-validation: relative error of held-out snapshot pixels",
            "chosen": dict(self.chosen),
            "fixed": dict(self.fixed),
            "candidates": [{k: (v if math.isfinite(v) else None) for k, v in c.items()} for c in self.candidates],
            "iterations_per_candidate": self.iterations,
            "block": self.block,
            "held_out_pixels": self.held_out,
            "folds": self.folds,
            "seconds": self.seconds,
            "preset": dict(self.preset),
            "blend": self.blend,
        }


def _check_record(record) -> None:
    """ValueError naming ``params["tuning"]`` unless ``record`` is a dict with a ``chosen`` dict."""
    expected = 'params["tuning"] must be the record of a tuned run, a dict with a "chosen" dict'
    if record is None:
        raise ValueError(f"{expected}, got None: a run with tune=False (or nothing to choose) records no choice")
    if not isinstance(record, dict):
        raise ValueError(f"{expected}, got a {type(record).__name__}")
    if "chosen" not in record and "tuning" in record:
        raise ValueError(f'{expected}, got the whole Result.params: pass result.params["tuning"]')
    if not isinstance(record.get("chosen"), dict):
        got = "no 'chosen'" if "chosen" not in record else f"chosen = {record['chosen']!r}"
        raise ValueError(f"{expected}, got a dict with {got} (keys {sorted(record, key=str)})")


def _midpoints(values, best):
    """Geometric midpoints between ``best`` and its neighbours in the sorted coarse ``values``."""
    values = sorted(values)
    k = values.index(best)
    out = []
    for other in (values[k - 1] if k > 0 else None, values[k + 1] if k + 1 < len(values) else None):
        if other is not None and other > 0 and best > 0:
            out.append(float(math.sqrt(best * other)))
    return out


def tune_parameters(
    op,
    g_device,
    g,
    make_regularizer,
    space: SearchSpace,
    *,
    eta,
    projection="exact",
    valid=None,
    iterations=60,
    patterns=None,
    progress=False,
    runner=None,
) -> Tuning:
    """Search the parameters that predict held-out snapshot pixels best (see the module doc).

    Parameters
    ----------
    op : RollingShutterOperator
        The staged operator (its sub-frames are the ones solved; ``op.rig`` the rig).
    g_device : pyopencl.array.Array
        Snapshots on the device, ``(K, m, n)``.
    g : ndarray
        The same snapshots on the host (for the warm start).
    make_regularizer : callable
        ``make_regularizer(options)`` -> a Regularizer with those option values.
    space : SearchSpace
        What to search (options, ``lam``), and what the caller fixed or a preset sets.
    eta : float
    projection : {"exact", "paper"}
    valid : ndarray of bool or None
        Snapshot pixels usable at all (None: all; :func:`rsocl.reconstruct` passes all, clipped ones as
        recorded).
    iterations : int
        ADMM iterations per candidate and hold-out pattern.
    patterns : list of (int, int) or None
        The hold-out patterns as ``(block, shift)`` pairs
        (:func:`~rsocl.solver.holdout.fold_patterns`); None: :func:`~rsocl.solver.holdout.default_patterns`.
        The criterion pools the held-out errors of all patterns.
    progress : bool
        Show a progress bar (tqdm) over the candidates.
    runner : callable or None
        How a candidate runs on the folds, called as :func:`run_folds` is; None: :func:`run_folds`, one
        fold after the other (:class:`rsocl.solver.search_batch.BatchedFolds` runs them as one batch).

    Returns
    -------
    Tuning

    Raises
    ------
    ValueError
        When a pattern leaves no pixels to fit or to score, or the patterns are empty or bad.
    """
    start = time.perf_counter()
    iterations = check.positive_int("tuning iterations", iterations)
    rig = op.rig
    preset = dict(space.preset)
    lam = space.lam
    lams = [float(lam)] if isinstance(lam, (float, int, np.number)) else [float(v) for v in lam]
    if patterns is None:
        patterns = default_patterns(rig.shape, rig.n_channels)
    patterns = [(check.positive_int("pattern block", b), int(shift)) for b, shift in patterns]
    if not patterns:
        raise ValueError("patterns must hold at least one (block, shift) pair, got none")
    blocks = sorted({b for b, _ in patterns}, reverse=True)
    usable = np.ones((rig.n_channels,) + rig.shape, bool) if valid is None else np.asarray(valid, bool)
    folds, held_out = [], 0
    for (block, _), (fit, scored) in zip(patterns, fold_masks(rig.shape, rig.n_channels, usable, patterns)):
        folds.append(make_fold(op, g_device, g, block, fit, scored))
        held_out += int(scored.sum())
    # held-out sums of |g|^2 and |g - H x0|^2, enqueued now and read when the first candidate is scored,
    # so the host enqueues the first round meanwhile; added in fold order
    pending = [
        (
            sum_sq_diff_async(g_device, weights=fold.weights),
            sum_sq_diff_async(g_device, fold.start_prediction, weights=fold.weights),
        )
        for fold in folds
    ]
    tunable = space.tunable
    current = {
        "lam": lams[len(lams) // 2],
        **{name: float(sorted(values)[(len(values) - 1) // 2]) for name, values in tunable.items()},
    }
    scores: dict = {}
    blends: dict = {}
    candidates = []

    bar = None
    if progress:
        from tqdm.auto import tqdm

        planned = sum(len(v) + 2 for v in tunable.values()) + max(len(lams) - 1, 0) + 1
        bar = tqdm(total=planned, desc="tuning", unit="candidate", leave=False, disable=None)

    ready: dict = {}  # (err, moved) of candidates run ahead in a batch, until score() books them
    many = getattr(runner, "run_many", None)

    def regularizer(point):
        return make_regularizer({**preset, **{k: v for k, v in point.items() if k != "lam"}})

    def prefetch(points):
        """Run the ``points`` not yet scored as one batch where the runner takes several (``run_many``)."""
        todo = {tuple(sorted(p.items())): p for p in points}
        todo = {k: p for k, p in todo.items() if k not in scores and k not in ready}
        if many is None or len(todo) < 2:
            return
        points = list(todo.values())
        kw = dict(eta=eta, projection=projection, iterations=iterations)
        results = many(op, g_device, folds, [regularizer(p) for p in points], [p["lam"] for p in points], **kw)
        ready.update(zip(todo, results))

    def score(point):
        key = tuple(sorted(point.items()))
        if key in scores:
            return scores[key]
        if key in ready:
            err, moved = ready.pop(key)
        else:
            err, moved = (runner or run_folds)(
                op,
                g_device,
                folds,
                regularizer(point),
                point["lam"],
                eta=eta,
                projection=projection,
                iterations=iterations,
            )
        scale = sum(p[0].result() for p in pending)  # PendingSum reads once
        value = float(math.sqrt(err / scale)) if scale > 0 else float(math.sqrt(err))
        if not math.isfinite(value):
            value = math.inf
        scores[key] = value
        blends[key] = _blend(sum(p[1].result() for p in pending), moved, err)
        candidates.append({**preset, **point, "score": value, "blend": blends[key]})
        if bar is not None:
            bar.update(1)
            bar.set_postfix(best=f"{min(scores.values()):.4g}")
        return value

    try:
        for index, (name, values) in enumerate(tunable.items()):
            coarse = sorted(float(v) for v in values)
            prefetch([{**current, name: v} for v in coarse])
            for v in coarse:
                score({**current, name: v})
            best = min(coarse, key=lambda v: score({**current, name: v}))  # run above: cached
            refined = coarse + _midpoints(coarse, best)
            ahead = [{**current, name: v} for v in refined]
            if index == len(tunable) - 1:  # the lam round next: its candidates for each value the round may choose
                ahead += [{**current, name: v, "lam": lam} for v in [best] + _midpoints(coarse, best) for lam in lams]
            prefetch(ahead)
            for v in refined:
                score({**current, name: v})
            current[name] = min(refined, key=lambda v: score({**current, name: v}))
        prefetch([{**current, "lam": v} for v in lams])
        for v in lams:
            score({**current, "lam": v})
        current["lam"] = min(lams, key=lambda v: score({**current, "lam": v}))
    finally:
        if bar is not None:
            bar.close()
    return Tuning(
        chosen={**preset, **current},
        candidates=candidates,
        fixed=dict(space.fixed),
        iterations=iterations,
        block=blocks[0] if len(blocks) == 1 else blocks,
        held_out=held_out,
        seconds=time.perf_counter() - start,
        folds=len(patterns),
        preset=preset,
        blend=blends[tuple(sorted(current.items()))],
    )


def applied_blend(tuning: Tuning | None) -> float:
    """The blend a run that starts from the interpolation applies with ``tuning`` (a :class:`Tuning` or
    None): the search's, or 1 (the solver's own result) without a search or a recorded blend."""
    return 1.0 if tuning is None or tuning.blend is None else float(tuning.blend)


def _blend(start_err: float, moved: float, err: float) -> float:
    """The ``blend`` in [0, 1] that minimises the held-out error of ``x0 + blend (theta - x0)``, from the
    held-out sums of squares ``‖g - H x0‖²`` (``start_err``), ``‖H theta - H x0‖²`` (``moved``) and
    ``‖g - H theta‖²`` (``err``): ``<g - H x0, H theta - H x0> / moved``, the inner product by
    polarisation. 1 (the run's own result) when the run did not move or its error is not finite."""
    if not (math.isfinite(err) and math.isfinite(moved)) or moved <= 0:
        return 1.0
    return float(min(1.0, max(0.0, 0.5 * (start_err + moved - err) / moved)))
