"""A point of ``rsocl bench``: every knob of one measurement (:class:`BenchPoint`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from rsocl.solver.problem import DEFAULTS, MAX_ITERATIONS

__all__ = ["BenchPoint", "BenchResult", "BASELINE", "US", "on_iterations_line", "seconds_text"]

US = 1e-6
#: Name of the baseline's rows in the ``regularizer`` column.
BASELINE = "interp3d"


@dataclass(frozen=True)
class BenchPoint:
    """Every knob of one measurement.

    Attributes
    ----------
    scene : str
        ``"builtin"`` or a video file (see :func:`rsocl.model.scenes.load_scene`).
    cameras : int
        1..8, the paper's angle order (0, 90, 180, 270, 45, 135, 225, 315 degrees).
    shape : int
        Side of the square reference grid the scene is resized to, pixels.
    roi : int or None
        Side of the centred crop that is reconstructed, pixels; None (or ``shape``): all.
    dt_factor : float
        Sub-frame duration in units of ``t_r`` (>= 1).
    iterations, tv_iterations : int
        ADMM iterations and inner denoiser iterations (None for a regularizer without an
        ``iterations`` option, and for the baseline).
    regularizer : str
        Registry name, or :data:`BASELINE` for the 3-D interpolation.
    dtype : str
        ``"float32"`` or ``"float64"``.
    device : str or None
        OpenCL device spec (``"P:D"``); None: rsocl's choice.
    lam, eta : float or None
        ADMM weights, >= 0 (``eta = 0`` runs GAP); None (default): :func:`rsocl.solver.reconstruct`'s
        own for the point's rig (0.1 and 0.2 at the paper's configuration, scaled by the data term's
        curvature, as a user who leaves them out gets).
    t_e, t_r : float
        Exposure and row time of every camera, seconds.
    tune : bool
        True: the self-tuned default of :func:`rsocl.solver.reconstruct` (``lam`` and the
        regularizer's tunable options chosen from the snapshots, warm start from interp3d;
        ``lam`` above is then ignored); False: the fixed settings.
    quality : str or None
        A rung of :mod:`rsocl.solver.ladder` (``"fast"``, ``"balanced"``, ``"best"``): the self-tuned
        run of that rung at its own iterations (``iterations``, ``lam`` and ``tune`` are then
        ignored); None: ``tune`` decides.
    """

    scene: str = "builtin"
    cameras: int = 4
    shape: int = 64
    roi: int | None = None
    dt_factor: float = 1.0
    iterations: int = DEFAULTS["iterations"]
    tv_iterations: int | None = DEFAULTS["tv_iterations"]
    regularizer: str = "tv"
    dtype: str = "float32"
    device: str | None = None
    lam: float | None = None
    eta: float | None = None
    t_e: float = 180e-6
    t_r: float = 35e-6
    tune: bool = False
    quality: str | None = None

    def __post_init__(self):
        from rsocl.common import validation as check
        from rsocl.solver.ladder import check_quality

        if self.quality is not None:
            check_quality(self.quality)

        check.positive_int("cameras", self.cameras, maximum=8)
        check.positive_int("shape", self.shape)
        roi = self.roi
        if roi is not None:
            roi = check.positive_int("roi", roi)
            if roi > self.shape:
                raise ValueError(f"roi must be <= shape = {self.shape} pixels (a crop of the grid), got {roi}")
        object.__setattr__(self, "roi", None if roi == self.shape else roi)
        object.__setattr__(self, "dt_factor", float(check.positive("dt_factor", self.dt_factor)))
        if self.dt_factor < 1 - 1e-9:
            raise ValueError(f"dt_factor must be >= 1 (dt >= t_r), got {self.dt_factor!r}")
        if self.regularizer != BASELINE:
            check.positive_int("iterations", self.iterations, MAX_ITERATIONS)
        if self.tv_iterations is not None:
            check.positive_int("tv_iterations", self.tv_iterations)
        check.positive("t_e", self.t_e, "seconds")
        check.positive("t_r", self.t_r, "seconds")
        check.choice("dtype", self.dtype, {"float32", "float64"})
        if self.lam is not None:
            check.non_negative("lam", self.lam)
        if self.eta is not None:
            check.non_negative("eta", self.eta, "(0 runs GAP)")

    @property
    def roi_size(self) -> int:
        return self.shape if self.roi is None else self.roi

    @property
    def is_baseline(self) -> bool:
        return self.regularizer == BASELINE

    def rig(self, dt_factor=None):
        """The rig of this point (``dt_factor`` overrides the point's; 1 gives the reference grid)."""
        from rsocl.model.rig import Rig

        k = self.dt_factor if dt_factor is None else dt_factor
        full = Rig.paper_array(self.cameras, (self.shape, self.shape), t_e=self.t_e, t_r=self.t_r, dt=k * self.t_r)
        if self.roi is None:
            return full
        return full.crop(self.crop_box())

    def crop_box(self):
        """``(y, x, height, width)`` of the centred ROI."""
        offset = (self.shape - self.roi_size) // 2
        return (offset, offset, self.roi_size, self.roi_size)


def seconds_text(seconds: float) -> str:
    """A time in seconds as the text and plots write it (the number, without the unit): three
    significant digits, never in exponent notation (``0.0464``, ``12.3``, ``1230``), so that the
    ratios printed beside two times agree with them."""
    import numpy as np

    return np.format_float_positional(float(seconds), precision=3, unique=False, fractional=False, trim="-")


def _scene_name(scene) -> str:
    return "builtin" if scene == "builtin" else Path(str(scene)).name


def on_iterations_line(point, default) -> bool:
    """Whether ``point`` differs from ``default`` in its iteration count at most: the points
    whose PSNR history the iterations plot draws."""
    return replace(point, iterations=default.iterations) == default


@dataclass
class BenchResult:
    """Rows of a run and what the writers need besides."""

    rows: list
    default: BenchPoint
    notes: list = field(default_factory=list)
    seconds: float = 0.0
    device: str = ""
    #: The default point's seconds measured at the start and again at the end of the run: a
    #: gauge of the timing noise (other load on the machine).
    timing_check: tuple | None = None
    #: 1-minute load average at the start and at the end of the run (None where unavailable).
    load: tuple | None = None
    #: The interrupt (KeyboardInterrupt: Ctrl-C, SIGTERM) that ended the run before its last point,
    #: with ``rows`` those measured before it; None for a run that ended on its own.
    interrupted: BaseException | None = None

    def history(self):
        """History of the longest run whose knobs other than ``iterations`` are the default's."""
        best = None
        for row in self.rows:
            point = row["_point"]
            if row.get("_history") is None or not on_iterations_line(point, self.default):
                continue
            if best is None or point.iterations > best["_point"].iterations:
                best = row
        return None if best is None else best["_history"]
