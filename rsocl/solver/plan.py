"""Size a reconstruction to the scene before running it: ``dt``, ROI, ``T_se``, memory, time.

What the user knows of the scene decides how much of the datacube is worth
modelling:

* the **ROI of the motion** crops the reference grid; the cropped cameras keep
  their real row times (the crop's row map is the full one, cut), so the
  sub-frames nobody samples inside the crop drop out as well;
* the **largest speed** (pixels per second) bounds the sub-frame: an object
  should move at most ``blur_pixels`` (default 1) within one, so
  ``dt <= blur_pixels / speed``;
* the **frame rate wanted** bounds it too: ``dt <= 1 / fps``.

The coarsest ``dt`` (a whole multiple of ``t_r``) within both bounds gives the
fewest sub-frames that still resolve the motion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rsocl.common import validation as check
from rsocl.model.rig import Rig
from rsocl.solver.ladder import DEFAULT_QUALITY, check_quality
from rsocl.solver.memory import device_limit, memory_need
from rsocl.solver.request import make_regularizer
from rsocl.solver.search_cost import search_seconds

__all__ = ["Plan", "Estimate", "plan", "estimate", "format_plan"]


@dataclass
class Estimate:
    """Cost of reconstructing one rig: sub-frames, device memory (bytes), seconds.

    ``fits`` is False when the largest buffer or the total exceeds the device (``limit`` says
    which); the time is then not measured. ``search_seconds``: the self-tuned default's parameter
    search (:func:`rsocl.solver.search_cost.search_seconds`), None when not measured.
    """

    rig: Rig
    subframes: int
    memory_bytes: int
    seconds_per_iteration: float | None
    iterations: int
    fits: bool = True
    limit: str | None = None
    search_seconds: float | None = None

    @property
    def seconds(self) -> float | None:
        """A fixed run's iterations, seconds (None: not measured)."""
        return None if self.seconds_per_iteration is None else self.seconds_per_iteration * self.iterations

    @property
    def tuned_seconds(self) -> float | None:
        """The self-tuned default's: the search and the run, seconds (None: not measured)."""
        if self.seconds is None or self.search_seconds is None:
            return None
        return self.search_seconds + self.seconds


@dataclass
class Plan:
    """The proposal of :func:`plan` beside the unplanned problem."""

    full: Estimate
    proposed: Estimate
    dt: float
    roi: tuple
    notes: list = field(default_factory=list)
    quality: str = DEFAULT_QUALITY


def estimate(
    rig: Rig,
    *,
    iterations=200,
    regularizer="tv",
    regularizer_options=None,
    dtype="float32",
    device=None,
    measure=True,
    projection="exact",
    search=False,
    quality=DEFAULT_QUALITY,
) -> Estimate:
    """Memory (from the buffer sizes, :func:`rsocl.solver.memory.memory_need` of the configured
    regularizer: a name takes ``regularizer_options`` over its defaults, an instance its own) and, when ``measure`` and
    it fits, time per iteration (3 timed iterations), of a fixed run (``tune=False``: no parameter search);
    with ``search`` too, the ``quality`` rung's parameter search on the built-in scene
    (:func:`rsocl.solver.search_cost.search_seconds`), which searches the options a name leaves unset, as
    :func:`rsocl.reconstruct` does."""
    from rsocl.device.context import get_device
    from rsocl.solver.reconstruct import reconstruct

    dev = get_device(device)
    dev.real_dtype(dtype)
    configured = make_regularizer(regularizer, regularizer_options)
    solved = rig.sampled_range()
    largest, memory = memory_need(rig, configured, dtype=dtype, projection=projection)
    limit = device_limit(dev, largest, memory)
    per_iteration = None
    if measure and limit is None:
        g = np.zeros((rig.n_channels,) + rig.shape)
        for _ in range(2):  # the first call builds every program the timed one runs (a build takes seconds)
            result = reconstruct(g, rig, regularizer=configured, iterations=3, device=dev, dtype=dtype, tune=False)
        per_iteration = result.history["time"][-1] / 3
    searched = None
    if measure and limit is None and search:
        searched = search_seconds(
            rig,
            iterations=iterations,
            regularizer=regularizer,
            regularizer_options=regularizer_options,
            dtype=dtype,
            device=dev,
            quality=quality,
        )
    return Estimate(rig, solved.stop - solved.start, memory, per_iteration, iterations, limit is None, limit, searched)


def plan(
    rig: Rig,
    *,
    roi=None,
    speed=None,
    fps=None,
    blur_pixels=1.0,
    iterations=200,
    regularizer="tv",
    regularizer_options=None,
    dtype="float32",
    device=None,
    measure=True,
    quality=DEFAULT_QUALITY,
) -> Plan:
    """Propose ``dt`` and ROI for ``rig`` and a scene; estimate both problems' cost.

    The cost of each: memory, and when ``measure``, the time of a fixed run and of the self-tuned
    default, whose parameter search (the ``quality`` rung's) is timed on the built-in scene
    (:func:`rsocl.solver.search_cost.search_seconds`; how close it comes: ``docs/plan_search.md``).

    Parameters
    ----------
    roi : (y, x, height, width) or None
        Where the motion is, reference pixels; None keeps the whole grid.
    speed : float or None
        Largest image speed in the scene, pixels per second.
    fps : float or None
        Sub-frame rate wanted, Hz.
    blur_pixels : float
        Motion allowed within one sub-frame, pixels.
    regularizer, regularizer_options : str or Regularizer, dict or None
        A registry name with options over its defaults, or the configured instance, as
        :func:`rsocl.reconstruct` takes them: the options decide its workspace (:mod:`rsocl.solver.memory`),
        and the search chooses those left unset.
    quality : {"fast", "balanced", "best"}
        The rung of the self-tuned run costed (:mod:`rsocl.solver.ladder`).
    """
    iterations = check.positive_int("iterations", iterations)
    quality = check_quality(quality)
    blur_pixels = check.positive("blur_pixels", blur_pixels, "(pixels)")
    notes = []
    t_r = max(cam.t_r for cam in rig.cameras)
    bound = math.inf
    if speed is not None:
        speed = check.positive("speed", speed, "pixels/s")
        blur_pixels = check.positive("blur_pixels", blur_pixels, "pixels")
        bound = min(bound, blur_pixels / speed)
        notes.append(
            f"speed {speed:g} px/s with {blur_pixels:g} px per sub-frame: dt <= {blur_pixels / speed * 1e6:.6g} µs"
        )
    if fps is not None:
        fps = check.positive("fps", fps, "Hz")
        bound = min(bound, 1.0 / fps)
        notes.append(f"{fps:g} sub-frames/s wanted: dt <= {1e6 / fps:.6g} µs")
    if math.isinf(bound):
        k = None
        notes.append("no speed or frame rate given: dt kept")
    else:
        k = max(1, math.floor(bound / t_r * (1 + 1e-9)))
        span = float(rig.windows.end.max()) * rig.dt  # the latest exposure end, s
        longest = max(1, math.ceil(span / t_r * (1 - 1e-9)))
        if k > longest:
            notes.append(
                f"the motion allows dt <= {bound * 1e6:.4g} µs, longer than the exposures' span of "
                f"{span * 1e6:.4g} µs: dt = {longest} t_r, one sub-frame (a still image)"
            )
            k = longest
        if bound < t_r:
            notes.append(
                f"the motion needs dt <= {bound * 1e6:.2f} µs, below t_r = {t_r * 1e6:.2f} µs: "
                f"dt = t_r, with {t_r / bound:.1f}x the blur asked for"
            )
    dt = rig.dt if k is None else k * t_r
    roi = (0, 0) + rig.shape if roi is None else tuple(int(v) for v in roi)
    proposed = rig.crop(roi, dt=dt)
    kwargs = dict(
        iterations=iterations,
        regularizer=regularizer,
        regularizer_options=regularizer_options,
        dtype=dtype,
        device=device,
        measure=measure,
        search=True,
        quality=quality,
    )
    full = estimate(rig, **kwargs)
    new = estimate(proposed, **kwargs)
    return Plan(full, new, dt, roi, notes, quality)


def _secs(seconds: float) -> str:
    return f"{seconds:.2f} s" if seconds < 1 else f"{seconds:.1f} s"


def format_plan(p: Plan) -> str:
    """A small table: the unplanned problem beside the proposal."""

    def col(e: Estimate):
        secs = (
            "-"
            if e.seconds_per_iteration is None
            else f"{e.seconds_per_iteration * 1e3:.1f} ms x {e.iterations} = {e.seconds:.1f} s"
        )
        tuned, search, fixed, total = "-", e.search_seconds, e.seconds, e.tuned_seconds
        if search is not None and fixed is not None and total is not None:
            tuned = f"{_secs(search)} search + {_secs(fixed)} = {_secs(total)}"
        if not e.fits:
            secs = tuned = "does not fit the device: tile it"
        return [
            f"{e.rig.shape[0]} x {e.rig.shape[1]}",
            f"{e.rig.dt * 1e6:g} µs",
            f"{e.rig.T}",
            f"{e.subframes}",
            f"{e.rig.T_se}",
            f"{e.rig.compression_ratio:.1f}x",
            f"{e.memory_bytes / 2**20:.1f} MiB",
            secs,
            tuned,
        ]

    rows = [
        "ROI",
        "dt",
        "T",
        "sub-frames solved",
        "T_se",
        "compression",
        "device memory, fixed run",
        "time, fixed run",
        f"time, self-tuned ({p.quality})",
    ]
    a, b = col(p.full), col(p.proposed)
    width = max(len(r) for r in rows)
    wa = max(len(v) for v in a + ["as given"])
    lines = [f"{'':<{width}}  {'as given':<{wa}}  proposed"]
    lines += [f"{r:<{width}}  {x:<{wa}}  {y}" for r, x, y in zip(rows, a, b)]
    y, x, h, w = p.roi
    lines.append(
        f"proposed ROI (x, y, width, height, as rsocl plan --roi and a rig file's roi): {x} {y} {w} {h}; "
        f"in Python: rig.crop(({y}, {x}, {h}, {w})), (y, x, height, width)"
    )
    lines += [f"note: {n}" for n in p.notes]
    lines.append(
        "note: memory is a fixed run's (tune=False, --fixed); the self-tuned default runs its parameter search "
        "first, timed here on the built-in scene (docs/plan_search.md), which can take more memory"
    )
    lines += [
        f"note: the {label} problem does not fit one device: it needs {e.limit}"
        for label, e in (("given", p.full), ("proposed", p.proposed))
        if not e.fits
    ]
    return "\n".join(lines)
