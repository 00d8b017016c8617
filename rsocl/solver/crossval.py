"""Parameters from the data: block cross-validation on the snapshots, no ground truth.

The criterion
-------------
The reference grid is cut into square blocks of ``block`` pixels; in each block one channel
(camera) is held out of the data term, the channel changing from block to block
(:func:`holdout`). An ADMM run on the remaining snapshot pixels, with candidate parameters,
predicts the held-out ones as ``H theta``; the criterion is the relative prediction error
``‖g - H theta‖ / ‖g‖`` over the held-out pixels. No ground truth enters: only the snapshots,
the rig and the saturation mask. When one pattern of blocks leaves a camera never held out (more
cameras than the pattern's blocks hold out), patterns with the held-out channels shifted are
pooled until every camera is held out somewhere (:func:`default_patterns`).

Why blocks of one channel: a camera reads a whole line at one instant, so a held-out pixel
whose line neighbours were fitted is predicted from them (same instant, one pixel away)
whatever the temporal prior; random single pixels reward spatial smoothing and pick
temporal weights that lose up to 2 dB (measured on Runner, Traffic and the built-in scene).
Whole blocks force the prediction through the other cameras and through time, as the
sub-frames no camera sees are reconstructed in a real capture. Noise in the held-out
pixels adds the same constant to every candidate's error, so the criterion stays unbiased.

Why cross-validation rather than GCV or SURE: both need the noise level (SURE) or the trace
of the reconstruction's Jacobian, which for ADMM with TV (a nonlinear map) takes a
Monte-Carlo divergence estimate, i.e. extra perturbed runs per candidate; held-out pixels
need neither. GCV and SURE were not measured against it.

The search
----------
Coordinate search in log space: each tunable option of the regularizer (TV:
``temporal_weight``, :attr:`rsocl.solver.regularizer.Regularizer.tunable`) over its coarse
values at the recommended ``lam``, then the geometric midpoints next to the best value; then
``lam`` times 0.3 and 3. Every candidate starts from the same warm start (:func:`interp3d` of
the fitted pixels) and runs ``iterations`` ADMM steps; the data step's inverse blocks are
computed once for all candidates. Values the caller fixed are not searched.

The blend with the interpolation
--------------------------------
The same held-out pixels also choose how far the result moves from its start, the
:func:`interp3d` interpolation of the snapshots: the returned estimate is
``x0 + blend (theta - x0)`` with ``blend`` in [0, 1]. The prediction of a blend is the same blend
of the predictions (``H`` is linear), so its held-out error is a quadratic in ``blend``, minimised
in closed form from each candidate's own runs: ``blend = <g - H x0, H theta - H x0> /
‖H theta - H x0‖²`` over the held-out pixels, clipped to [0, 1], with ``x0`` the fold's warm
start. It costs one more reduction per candidate and fold, no run. It pays where the solver
fits noise or invents detail that the interpolation of smooth motion does not. Measured with the
ground truth (self-tuned runs of 200 iterations; PSNR of the blend minus the unblended result,
mean / worst / best; multi-camera rigs of ``benchmarks/tv_step.py``'s random generator; noise:
Poisson at N photo-electrons at full scale plus 1 % read noise):

- designed on seeds 100-139 x built-in scene and Runner at 1 frame per sub-frame: N = 1000,
  +0.28 / -0.19 / +2.12 dB, runs below ``interp3d`` 21 -> 10 of 74; noiseless +0.01 / -0.09 /
  +0.31 dB;
- checked on seeds 160-199 x Traffic at 1 and the slow built-in scene: N = 300, +0.28 / -0.32 /
  +2.34 dB, below ``interp3d`` 18 -> 10 of 74; noiseless +0.02 / -0.16 / +0.47 dB;
- checked on seeds 140-159 x Runner at 2 and Traffic at 0.5: N = 1000, +0.21 / -0.65 / +2.14 dB
  (10 -> 6 of 30 below); N = 30, +0.25 / -0.03 / +1.36 dB (3 -> 1); noiseless -0.02 / -0.36 / +0.25 dB;
- the paper array's 12 scenes of ``benchmarks/quality.py`` (64x64 and 128x128), noiseless and with
  N = 1000: +0.02 / -0.01 / +0.25 dB (``benchmarks/tuning_blend.py``, ``docs/tuning_blend.md``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from rsocl.common import validation as check
from rsocl.device.reduction import sum_sq_diff
from rsocl.model.interpolation_device import interp3d_device
from rsocl.solver.admm import ADMM

__all__ = ["LAM_FACTORS", "FOLDS", "MIN_BLOCK", "CANDIDATE_FRACTION", "holdout", "default_block", "default_folds",
           "fold_patterns", "default_patterns", "fold_masks", "can_hold_out", "Tuning", "tune_parameters",
           "applied_blend"]

#: ``lam`` candidates, as factors of the recommended ``lam`` (TV: 0.03, 0.1, 0.3).
LAM_FACTORS = (0.3, 1.0, 3.0)
#: Hold-out patterns pooled at least (:func:`default_folds`; more when one pattern leaves a camera
#: never held out): fold ``k`` shifts the held-out cameras by ``k*P // folds``.
FOLDS = 1
#: Smallest hold-out block side, pixels, where the grid allows (:func:`default_block`).
MIN_BLOCK = 16
#: ADMM iterations per candidate, as a fraction of the final run's iterations, split among the
#: hold-out patterns (at least 10 each): at the default 200 iterations, 50; the search's 8
#: candidates cost about 2 final runs. Against other fractions (self-tuned PSNR minus this one's, mean
#: / worst; runs below ``interp3d``): on 120 random rigs of ``benchmarks/tv_step.py`` (built-in scene
#: and Runner) 0.5 gives -0.02 / -0.97 dB (9 below, against 8), 0.125 -0.01 / -0.85 dB (11 below),
#: 0.0625 -0.07 / -1.44 dB (14 below); on 15 paper-array cases of ``benchmarks/quality.py`` 0.125
#: gives -0.03 / -0.50 dB (Traffic at 0.5 frame per sub-frame) and 0.0625 -0.18 / -0.63 dB.
CANDIDATE_FRACTION = 0.25


def default_block(shape) -> int:
    """Side of the hold-out blocks, pixels: a quarter of the grid's smaller side, but at least
    :data:`MIN_BLOCK` pixels and at most half the side (and at least 2).

    Blocks of a quarter of the side spread each camera's held-out pixels over the image, so every
    camera is tested on moving and on still parts of the scene; with blocks of half the side, each
    of 4 cameras is held out of one quadrant only and the choice follows that quadrant's content.
    Blocks of a few pixels let the held-out pixels be predicted from fitted neighbours, which
    rewards spatial smoothing, hence the floor. Measured with ``benchmarks/tuning_design.py`` and
    the quality benchmarks at equal search cost (the choice's PSNR minus the best point of the
    grid, mean / worst; a quarter of the side against half of it, the previous rule):

    - 16 cases at 64x64 with 200 iterations, rigs rotated other than the paper's 0/90/180/270
      degrees and 3 or 7 cameras (``docs/tuning_design_64.md``): -0.10 / -0.41 dB against
      -0.17 / -1.03 dB;
    - ``benchmarks/quality.py`` (paper array, 64x64 and 128x128, 16 cases): -0.03 / -0.52 dB
      against -0.07 / -0.76 dB;
    - 64 cases at 48x48, 100 iterations (``docs/tuning_design.md``, where the floor gives blocks
      of a third of the side): a quarter -0.07 / -0.62 dB, a third -0.09 / -1.10 dB, half
      -0.11 / -1.14 dB;
    - ``benchmarks/tuning_configs.py`` (16x16 to 48x32 pixels, where the floor keeps the blocks
      of the previous rule): a quarter of the side lost to the fixed defaults by up to 1.41 dB
      (mean +0.02 dB over them) against up to 0.62 dB (mean +0.26 dB) with the floor.
    """
    return max(2, min(int(round(min(shape) / 2)), max(MIN_BLOCK, int(round(min(shape) / 4)))))


def default_folds(shape, channels: int, block: int | None = None, minimum: int = None) -> int:
    """Hold-out patterns :func:`tune_parameters` pools by default: ``minimum`` (None: :data:`FOLDS`),
    or more until every camera is held out of some block (fold ``k`` shifts the held-out channels by
    ``k*P // folds``). A camera never held out would never test the candidates.

    One pattern by default: splitting the same candidate iterations between two patterns (each
    camera tested on twice the blocks, each run half as long) was no better across sizes in
    ``benchmarks/tuning_design.py`` (mean / worst loss to the grid's best, blocks of a quarter of
    the side: -0.07 / -0.51 dB at 48x48, -0.19 / -0.78 dB at 64x64, against -0.07 / -0.62 and
    -0.10 / -0.41 dB with one pattern), nor was pooling blocks of half and of a quarter of the side.
    """
    m, n = check.grid_shape("shape", shape)
    channels = check.positive_int("channels", channels)
    block = default_block((m, n)) if block is None else check.positive_int("block", block)
    blocks = (-(-m // block), -(-n // block))              # the pattern on the grid of blocks
    period = max(channels, 2)
    minimum = FOLDS if minimum is None else check.positive_int("minimum", minimum)
    for folds in range(min(minimum, period), period + 1):
        covered = np.zeros(channels, bool)
        for _, shift in fold_patterns(channels, 1, folds):
            covered |= holdout(blocks, channels, 1, shift=shift).any(axis=(1, 2))
        if covered.all():
            return folds
    return period


def holdout(shape, channels: int, block: int | None = None, shift: int = 0) -> np.ndarray:
    """Snapshot pixels held out of the fit, ``(channels, m, n)`` bool (True: held out).

    Block ``(i, j)`` (rows ``i*block ...``, columns ``j*block ...``) holds out channel
    ``(i + s*j + shift) mod P`` with ``P = max(channels, 2)`` and ``s = 2`` for ``P >= 4``, else 1; a
    value ``>= channels`` (one camera only) holds out nothing there. With ``K >= 2`` channels
    every pixel keeps ``K - 1`` of them.
    """
    m, n = check.grid_shape("shape", shape)
    channels = check.positive_int("channels", channels)
    block = default_block((m, n)) if block is None else check.positive_int("block", block)
    period = max(channels, 2)
    step = 2 if period >= 4 else 1
    i = np.arange(m)[:, None] // block
    j = np.arange(n)[None, :] // block
    which = (i + step * j + int(shift)) % period
    return np.stack([which == k for k in range(channels)])


def fold_patterns(channels: int, block: int, folds: int) -> list:
    """``folds`` hold-out patterns of blocks of ``block`` pixels, ``[(block, shift), ...]``: fold ``k``
    shifts the held-out channels by ``k*P // folds`` (:func:`holdout`)."""
    period = max(channels, 2)
    return [(int(block), (k * period) // int(folds)) for k in range(int(folds))]


def default_patterns(shape, channels: int, scales=None) -> list:
    """The hold-out patterns :func:`tune_parameters` pools by default, ``[(block, shift), ...]``:
    :func:`default_folds` patterns of :func:`default_block` blocks. ``scales`` (``(fraction,
    count)`` pairs, for comparing designs) pools instead, per scale, blocks of that fraction of the
    grid's smaller side (at least 2 pixels) in :func:`default_folds` patterns (at least ``count``);
    a pattern two scales share (small grids) is used once."""
    m, n = check.grid_shape("shape", shape)
    channels = check.positive_int("channels", channels)
    if scales is None:
        block = default_block((m, n))
        return fold_patterns(channels, block, default_folds((m, n), channels, block))
    patterns = []
    for fraction, count in scales:
        block = max(2, int(round(min(m, n) * fraction)))
        for pattern in fold_patterns(channels, block, default_folds((m, n), channels, block, minimum=count)):
            if pattern not in patterns:
                patterns.append(pattern)
    return patterns


def fold_masks(shape, channels: int, usable, patterns):
    """Per hold-out pattern ``(block, shift)``, ``(fit, scored)``: the usable snapshot pixels
    (``(channels, m, n)`` bool) that fit the candidates and those held out to score them."""
    for block, shift in patterns:
        held = holdout(shape, channels, block, shift=shift)
        yield usable & ~held, usable & held


def can_hold_out(shape, channels: int, valid=None) -> bool:
    """Whether every default hold-out pattern (:func:`default_patterns`) keeps snapshot pixels both
    to fit and to score, among the ``valid`` ones (None: all). Not so for one camera on a grid of
    2x2 pixels or fewer, whose one block holds the only camera out."""
    usable = np.ones((channels,) + tuple(shape), bool) if valid is None else np.asarray(valid, bool)
    return all(fit.any() and scored.any()
               for fit, scored in fold_masks(shape, channels, usable, default_patterns(shape, channels)))


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
        Options set without a search (in ``chosen`` too): a rig with one snapshot per pixel gets
        the regularizer's :attr:`~rsocl.solver.regularizer.Regularizer.one_snapshot` values.
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
    def from_params(cls, record: dict) -> "Tuning":
        """The choice recorded by :meth:`as_params` (e.g. ``Result.params["tuning"]``), to run again with."""
        candidates = [{k: (math.inf if k == "score" and v is None else v) for k, v in c.items()}
                      for c in record.get("candidates", [])]
        return cls(dict(record["chosen"]), candidates, dict(record.get("fixed", {})),
                   record.get("iterations_per_candidate", 0), record.get("block", 0),
                   record.get("held_out_pixels", 0), record.get("seconds", 0.0), record.get("folds", 1),
                   dict(record.get("preset", {})), record.get("blend"))

    def as_params(self) -> dict:
        """A JSON-ready record for :attr:`rsocl.solver.result.Result.params`."""
        return {"criterion": "block cross-validation: relative error of held-out snapshot pixels",
                "chosen": dict(self.chosen), "fixed": dict(self.fixed),
                "candidates": [{k: (v if math.isfinite(v) else None) for k, v in c.items()} for c in self.candidates],
                "iterations_per_candidate": self.iterations, "block": self.block, "held_out_pixels": self.held_out,
                "folds": self.folds, "seconds": self.seconds, "preset": dict(self.preset), "blend": self.blend}


def _midpoints(values, best):
    """Geometric midpoints between ``best`` and its neighbours in the sorted coarse ``values``."""
    values = sorted(values)
    k = values.index(best)
    out = []
    for other in (values[k - 1] if k > 0 else None, values[k + 1] if k + 1 < len(values) else None):
        if other is not None and other > 0 and best > 0:
            out.append(float(math.sqrt(best * other)))
    return out


def tune_parameters(op, g_device, g, rig, make_regularizer, *, tunable, lam, eta, projection="exact",
                    valid=None, iterations=60, block=None, folds=None, patterns=None, fixed=None, preset=None,
                    progress=False) -> Tuning:
    """Search the parameters that predict held-out snapshot pixels best (see the module doc).

    Parameters
    ----------
    op : RollingShutterOperator
        The staged operator (its sub-frames are the ones solved).
    g_device : pyopencl.array.Array
        Snapshots on the device, ``(K, m, n)``.
    g : ndarray
        The same snapshots on the host (for the warm start).
    rig : Rig
    make_regularizer : callable
        ``make_regularizer(options)`` -> a Regularizer with those option values.
    tunable : dict of str -> sequence of float
        Options to search and their coarse candidate values (log spaced, > 0).
    lam : float or sequence of float
        The ``lam`` to use, or its candidates (the middle one is tried first).
    eta : float
    projection : {"exact", "paper"}
    valid : ndarray of bool or None
        Snapshot pixels usable at all (saturated ones left out).
    iterations : int
        ADMM iterations per candidate and hold-out pattern.
    block, folds : int or None
        Blocks of ``block`` pixels (default :func:`default_block`) in ``folds`` patterns (default
        :func:`default_folds`); fold ``k`` shifts the held-out channels by ``k*P // folds``
        (:func:`holdout`), so with 2 folds and 4 cameras each block leaves out a camera and
        then the opposite one. Both None (and no ``patterns``): :func:`default_patterns`.
    patterns : list of (int, int) or None
        The hold-out patterns as ``(block, shift)`` pairs, instead of ``block`` and ``folds``.
        The criterion pools the held-out errors of all patterns.
    fixed : dict or None
        Parameters the caller fixed, recorded in the result.
    preset : dict or None
        Regularizer options set without a search: given to every candidate, recorded in the
        result's ``chosen`` and ``preset``.
    progress : bool
        Show a progress bar (tqdm) over the candidates.

    Returns
    -------
    Tuning
    """
    import pyopencl.array as cla

    start = time.perf_counter()
    iterations = check.positive_int("tuning iterations", iterations)
    preset = dict(preset or {})
    lams = [float(lam)] if np.isscalar(lam) else [float(v) for v in lam]
    if patterns is None and block is None and folds is None:
        patterns = default_patterns(rig.shape, rig.n_channels)
    elif patterns is None:
        block = default_block(rig.shape) if block is None else check.positive_int("block", block)
        folds = default_folds(rig.shape, rig.n_channels, block) if folds is None else folds
        patterns = fold_patterns(rig.n_channels, block, check.positive_int("folds", folds))
    elif block is not None or folds is not None:
        raise ValueError("give the hold-out patterns or block and folds, not both")
    patterns = [(check.positive_int("pattern block", b), int(shift)) for b, shift in patterns]
    if not patterns:
        raise ValueError("patterns must hold at least one (block, shift) pair, got none")
    blocks = sorted({b for b, _ in patterns}, reverse=True)
    held_out = 0
    usable = np.ones((rig.n_channels,) + rig.shape, bool) if valid is None else np.asarray(valid, bool)
    solved = _solved(rig, op)
    parts = []                    # per fold: fitted pixels, warm start, held-out weights, solver, H x0
    for (block, _), (fit, scored) in zip(patterns, fold_masks(rig.shape, rig.n_channels, usable, patterns)):
        if not scored.any() or not fit.any():
            raise ValueError(f"tuning needs snapshot pixels to fit and to hold out; with block = {block} pixels on "
                             f"a {rig.shape[0]}x{rig.shape[1]} grid there are {int(fit.sum())} and {int(scored.sum())}"
                             "; fix lam and the regularizer's options or pass tune=False")
        x0 = interp3d_device(op, g, fit, solved)
        held_out += int(scored.sum())
        weights = cla.to_device(op.queue, np.ascontiguousarray(scored, dtype=op.dtype))
        start_prediction = cla.empty_like(g_device)
        op.forward_into(x0, start_prediction)
        parts.append([fit, x0, weights, None, start_prediction])
    scale = sum(sum_sq_diff(g_device, weights=part[2]) for part in parts)
    start_err = sum(sum_sq_diff(g_device, part[4], weights=part[2]) for part in parts)     # |g - H x0|^2
    current = {"lam": lams[len(lams) // 2], **{name: float(sorted(values)[(len(values) - 1) // 2])
                                                for name, values in tunable.items()}}
    scores, blends = {}, {}
    candidates = []

    bar = None
    if progress:
        from tqdm.auto import tqdm

        planned = sum(len(v) + 2 for v in tunable.values()) + max(len(lams) - 1, 0) + 1
        bar = tqdm(total=planned, desc="tuning", unit="candidate", leave=False, disable=None)

    def score(point):
        key = tuple(sorted(point.items()))
        if key in scores:
            return scores[key]
        reg = make_regularizer({**preset, **{k: v for k, v in point.items() if k != "lam"}})
        err = moved = 0.0
        for part in parts:
            fit, x0, weights, solver, start_prediction = part
            if solver is None:
                part[3] = solver = ADMM(op, g_device, reg, lam=point["lam"], eta=eta, projection=projection, x0=x0,
                                        valid=fit)
            else:
                solver.restart(reg, point["lam"], x0)
            for _ in range(iterations):
                solver.step()
            op.forward_into(solver.theta, solver.hx)
            err += sum_sq_diff(g_device, solver.hx, weights=weights)
            moved += sum_sq_diff(solver.hx, start_prediction, weights=weights)
        value = float(math.sqrt(err / scale)) if scale > 0 else float(math.sqrt(err))
        if not math.isfinite(value):
            value = math.inf
        scores[key] = value
        blends[key] = _blend(start_err, moved, err)
        candidates.append({**preset, **point, "score": value, "blend": blends[key]})
        if bar is not None:
            bar.update(1)
            bar.set_postfix(best=f"{min(scores.values()):.4g}")
        return value

    try:
        for name, values in tunable.items():
            coarse = sorted(float(v) for v in values)
            for v in coarse:
                score({**current, name: v})
            best = min(coarse, key=lambda v: score({**current, name: v}))            # run above: cached
            refined = coarse + _midpoints(coarse, best)
            for v in refined:
                score({**current, name: v})
            current[name] = min(refined, key=lambda v: score({**current, name: v}))
        for v in lams:
            score({**current, "lam": v})
        current["lam"] = min(lams, key=lambda v: score({**current, "lam": v}))
    finally:
        if bar is not None:
            bar.close()
    return Tuning(chosen={**preset, **current}, candidates=candidates, fixed=dict(fixed or {}), iterations=iterations,
                  block=blocks[0] if len(blocks) == 1 else blocks, held_out=held_out,
                  seconds=time.perf_counter() - start, folds=len(patterns), preset=preset,
                  blend=blends[tuple(sorted(current.items()))])


def applied_blend(tuning) -> float:
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


def _solved(rig, op) -> slice:
    """The sub-frames ``op`` models, as a slice of the rig's ``T``."""
    solved = rig.sampled_range()
    if solved.stop - solved.start != op.T:
        raise ValueError(f"the operator models {op.T} sub-frames, the rig samples {solved.stop - solved.start}")
    return solved
