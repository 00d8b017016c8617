"""The quality ladder: named settings from cheap to thorough, each defined here and only here.

A rung (:class:`Rung`) says how many ADMM iterations the run takes, how the search chooses ``lam``
and the regularizer's options from the snapshots (:class:`Search`: the ``lam`` candidates, whether
the options are searched, the hold-out folds, the iterations per candidate, a central crop for
large frames), and how strongly the static part of the scene is pulled back to the interpolation
of the snapshots (:mod:`rsocl.solver.static`). Every rung starts from the ``interp3d``
interpolation and blends its result with it by the held-out choice, so a cheaper rung gives less
of the solver's gain but keeps what the snapshots already give.

``iterations="auto"`` (:data:`AUTO`) stops the final run when the residual has settled
(:func:`auto_stop`), with :data:`AUTO_CAP` iterations at most.

What each rung was measured to give, in time and quality: ``docs/quality_ladder.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from rsocl.solver.crossval import CANDIDATE_FRACTION, LAM_FACTORS
from rsocl.solver.holdout import default_block, default_folds, fold_patterns

__all__ = [
    "Search",
    "Crop",
    "Rung",
    "RUNGS",
    "QUALITIES",
    "DEFAULT_QUALITY",
    "AUTO",
    "AUTO_CAP",
    "AUTO_MIN",
    "AUTO_WINDOW",
    "AUTO_TOL",
    "check_quality",
    "check_iterations",
    "rung",
    "auto_stop",
    "auto_settled",
]


@dataclass(frozen=True)
class Search:
    """How the search chooses ``lam`` and the options the caller left unset.

    Attributes
    ----------
    lam_factors : tuple of float
        The ``lam`` candidates as factors of the settled ``lam``.
    options : bool
        Whether the regularizer's tunable options are searched (False: its defaults).
    folds : int or None
        Hold-out patterns pooled at least (None: :data:`rsocl.solver.holdout.FOLDS`).
    fraction : float
        ADMM iterations per candidate as a fraction of the run's iterations, split among the folds
        (at least 10 per fold).
    """

    lam_factors: tuple = LAM_FACTORS
    options: bool = True
    folds: int | None = None
    fraction: float = CANDIDATE_FRACTION

    def patterns(self, shape, channels: int) -> list:
        """The hold-out patterns ``[(block, shift), ...]`` on a grid of ``shape`` pixels."""
        block = default_block(shape)
        return fold_patterns(channels, block, default_folds(shape, channels, block, minimum=self.folds))

    def candidate_iterations(self, iterations: int, folds: int) -> int:
        """ADMM iterations per candidate and fold for a run of ``iterations``."""
        return max(10, round(self.fraction * iterations / folds))


@dataclass(frozen=True)
class Crop:
    """The search on a central block of a large frame: ``side`` pixels a side, cut as the tiled path
    cuts its centre block, for frames whose smaller side is at least ``from_side``, with ``search``."""

    side: int
    from_side: int
    search: Search

    def box(self, shape) -> tuple | None:
        """``(y, x, height, width)`` of the block on a grid of ``shape``, or None when not cropped."""
        m, n = shape
        if min(m, n) < self.from_side:
            return None
        return ((m - self.side) // 2, (n - self.side) // 2, self.side, self.side)


@dataclass(frozen=True)
class Rung:
    """One named setting of the ladder.

    Attributes
    ----------
    name : str
    iterations : int
        ADMM iterations of the final run when the caller gives none.
    search : Search
        The search on the whole frame.
    crop : Crop or None
        The search on a central block instead, for large frames.
    static : float
        In [0, 1]: how far the static part of the scene moves back to the interpolation
        (:func:`rsocl.solver.static.static_fix`); 0: not at all.
    auto : bool
        Whether ``iterations="auto"`` is allowed.
    """

    name: str
    iterations: int
    search: Search = field(default_factory=Search)
    crop: Crop | None = None
    static: float = 0.0
    auto: bool = True

    def search_for(self, shape) -> tuple:
        """``(search, box)``: the search to run on a frame of ``shape`` and its crop box (None: whole frame)."""
        box = None if self.crop is None else self.crop.box(shape)
        return (self.search, None) if box is None or self.crop is None else (self.crop.search, box)


RUNGS = {
    "fast": Rung("fast", 100, Search(lam_factors=(3.0,), options=False), auto=False),
    "balanced": Rung("balanced", 200, Search(), Crop(48, 96, Search(folds=2, fraction=0.5)), static=0.75),
    "best": Rung("best", 200, Search(folds=2, fraction=0.5), static=0.75),
}
#: The rung names, cheapest first.
QUALITIES = tuple(RUNGS)
DEFAULT_QUALITY = "balanced"

#: ``iterations`` value that stops the run from the data (:func:`auto_stop`).
AUTO = "auto"
#: Most iterations of an ``iterations="auto"`` run.
AUTO_CAP = 400
#: Fewest iterations of an ``iterations="auto"`` run.
AUTO_MIN = 30
#: Iterations over which the residual's change is measured.
AUTO_WINDOW = 20
#: Relative change of the residual over :data:`AUTO_WINDOW` iterations under which the run stops.
AUTO_TOL = 1e-4


def check_quality(quality) -> str:
    """``quality`` checked: one of :data:`QUALITIES`.

    Raises
    ------
    ValueError
        Naming ``quality`` and the allowed names.
    """
    if not isinstance(quality, str) or quality not in RUNGS:
        raise ValueError(f"quality must be one of {', '.join(QUALITIES)}, got {quality!r}")
    return quality


def rung(quality: str) -> Rung:
    """The :class:`Rung` named ``quality`` (:func:`check_quality`)."""
    return RUNGS[check_quality(quality)]


def check_iterations(iterations, quality: str) -> tuple:
    """``(iterations, auto)``: the final run's iterations (None: the rung's) and whether they stop from
    the data. ``iterations="auto"`` gives :data:`AUTO_CAP` and True.

    Raises
    ------
    ValueError
        Naming ``iterations`` when it is neither a positive integer nor ``"auto"``, or ``"auto"`` on a
        rung that refuses it; naming ``quality`` when it is not a rung.
    """
    step = rung(quality)
    if isinstance(iterations, str):
        if iterations != AUTO:
            raise ValueError(f"iterations must be a positive integer or 'auto', got {iterations!r}")
        if not step.auto:
            allowed = ", ".join(name for name, r in RUNGS.items() if r.auto)
            raise ValueError(
                f"iterations='auto' applies to quality {allowed}; quality {quality!r} runs a fixed count "
                f"({step.iterations}): give a number"
            )
        return AUTO_CAP, True
    return (step.iterations if iterations is None else iterations), False


def auto_stop(residuals) -> bool:
    """Whether an ``iterations="auto"`` run stops after the last of ``residuals`` (one per iteration, a
    number or one per set): at least :data:`AUTO_MIN` iterations ran and every set's residual changed
    by less than :data:`AUTO_TOL` of itself over the last :data:`AUTO_WINDOW` iterations
    (:func:`auto_settled`).

    Examples
    --------
    >>> auto_stop([1.0] * 40), auto_stop([1.0] * 10)
    (True, False)
    """
    import numpy as np

    return bool(np.all(auto_settled(residuals)))


def auto_settled(residuals):
    """Per set (a bool array for residuals of a batch, else a bool): whether that set's residual has
    settled as :func:`auto_stop` asks, after the last of ``residuals``."""
    import numpy as np

    if len(residuals) < max(AUTO_MIN, AUTO_WINDOW + 1):
        shape = np.shape(residuals[-1]) if len(residuals) else ()
        return np.zeros(shape, bool) if shape else False
    last = np.asarray(residuals[-1], dtype=np.float64)
    before = np.asarray(residuals[-1 - AUTO_WINDOW], dtype=np.float64)
    settled = np.abs(before - last) < AUTO_TOL * np.maximum(np.abs(last), np.finfo(float).tiny)
    return settled if last.ndim else bool(settled)
