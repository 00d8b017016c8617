"""The hold-out patterns of the parameter search: which snapshot pixels fit and which score.

The reference grid is cut into square blocks of ``block`` pixels; in each block one channel
(camera) is held out of the data term, the channel changing from block to block
(:func:`holdout`). When one pattern leaves a camera never held out, patterns with the held-out
channels shifted are pooled until every camera is held out somewhere (:func:`default_patterns`).
The search that scores candidates on them is :mod:`rsocl.solver.crossval`; why blocks of one
channel: ``docs/solver-notes.md``.
"""

from __future__ import annotations

import numpy as np

from rsocl.common import validation as check

__all__ = [
    "FOLDS",
    "MIN_BLOCK",
    "holdout",
    "default_block",
    "default_folds",
    "fold_patterns",
    "default_patterns",
    "fold_masks",
    "can_hold_out",
]

#: Hold-out patterns pooled at least (:func:`default_folds`; more when one pattern leaves a camera
#: never held out): fold ``k`` shifts the held-out cameras by ``k*P // folds``.
FOLDS = 1
#: Smallest hold-out block side, pixels, where the grid allows (:func:`default_block`).
MIN_BLOCK = 16


def default_block(shape) -> int:
    """Side of the hold-out blocks, pixels: a quarter of the grid's smaller side, but at least
    :data:`MIN_BLOCK` pixels and at most half the side (and at least 2).

    Blocks of a quarter of the side test every camera on moving and on still parts of the scene;
    the floor keeps held-out pixels from being predicted by their fitted neighbours. The
    measurements behind the rule: ``docs/solver-notes.md`` (hold-out blocks).
    """
    return max(2, min(int(round(min(shape) / 2)), max(MIN_BLOCK, int(round(min(shape) / 4)))))


def default_folds(shape, channels: int, block: int | None = None, minimum: int | None = None) -> int:
    """Hold-out patterns :func:`tune_parameters` pools by default: ``minimum`` (None: :data:`FOLDS`),
    or more until every camera is held out of some block (fold ``k`` shifts the held-out channels by
    ``k*P // folds``). A camera never held out would never test the candidates.

    One pattern by default (the comparison with more: ``docs/solver-notes.md``, hold-out blocks).
    """
    m, n = check.grid_shape("shape", shape)
    channels = check.positive_int("channels", channels)
    block = default_block((m, n)) if block is None else check.positive_int("block", block)
    blocks = (-(-m // block), -(-n // block))  # the pattern on the grid of blocks
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
    return all(
        fit.any() and scored.any()
        for fit, scored in fold_masks(shape, channels, usable, default_patterns(shape, channels))
    )
