"""The checked inputs of a reconstruction and their device buffers.

:func:`check_problem` and :func:`check_settings` validate everything a user passes to
:func:`rsocl.reconstruct` before any device work; :func:`stage_on_device` builds the operator
for the sampled sub-frames, checks that the run fits the device, and uploads the arrays.
"""

from __future__ import annotations

import numbers
import warnings
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from rsocl.analysis.metrics import default_data_range
from rsocl.common import validation as check
from rsocl.common.hints import ArrayLike
from rsocl.common.memory import check_host_memory
from rsocl.device import pool
from rsocl.model.curvature import full_scales
from rsocl.model.operator import RollingShutterOperator
from rsocl.model.plausible import warn_float32_scale
from rsocl.model.rig import Rig
from rsocl.model.simulate import check_fits_dtype
from rsocl.solver.checks import check_callback
from rsocl.solver.held import HeldSumSquares
from rsocl.solver.inverse import own_inverses
from rsocl.solver.memory import memory_bytes

if TYPE_CHECKING:
    import pyopencl.array as cla

__all__ = [
    "DEFAULTS",
    "PAPER_ETA",
    "MAX_ITERATIONS",
    "CLIPPED_SHARE_WARN",
    "Problem",
    "Settings",
    "Staged",
    "per_set_value",
    "match_batch",
    "check_problem",
    "check_settings",
    "check_weight_ratio",
    "check_representable",
    "stage_on_device",
]

#: Defaults for data scaled to [0, 1] per sub-frame intensity (snapshots then lie in
#: [0, t_e/dt]): 200 ADMM iterations, ``lam = 0.1``, ``eta = 0.2``, 10 inner TV iterations
#: (measured in ``benchmarks/solver_settings.py``); :func:`rsocl.solver.reconstruct` tunes ``lam``
#: from the data unless given.
DEFAULTS: dict = {"iterations": 200, "lam": 0.1, "eta": 0.2, "tv_iterations": 10}
#: Default ``eta`` of the paper's diagonal projection (``projection="paper"``, docs/model.md Eq. 15), for
#: the paper's configuration (scaled like the others): about the data term's curvature ``psi`` there
#: (5.02), below which the diagonal step diverges (measured in ``docs/paper_projection.md``).
PAPER_ETA = 5.0
#: Most ADMM iterations a run takes: runs converge within hundreds, and a larger count is a slip
#: (``10**12`` would run for ever, its search first) that is refused before anything runs.
MAX_ITERATIONS = 1_000_000
#: Share of the snapshot samples at or above ``saturation`` over which a warning says so: a level given in
#: scene units (1.0 for white) instead of snapshot units marks most samples clipped.
CLIPPED_SHARE_WARN = 0.5


@dataclass(frozen=True)
class Problem:
    """Checked host arrays: snapshots ``g`` ``(K, m, n)``, the rig, and the optional extras.

    ``valid`` marks the snapshot pixels below the saturation (None: all of them): the others enter
    the run's data step one-sided (:class:`~rsocl.solver.admm.ADMM`'s ``saturated``) and are left out
    of its residual; the warm start and the parameter search take them as recorded; ``x0`` and
    ``truth`` are ``(T, m, n)`` or None; ``interpolate``: the run starts from the ``interp3d``
    interpolation of the snapshots (the caller's ``x0="interp3d"``). A batch of ``batch`` sets has a
    leading axis of that length on ``g``, ``valid``, ``x0`` and ``truth`` (``batch`` is None for one set).
    ``warn``: whether staging it warns of the data (:func:`check_representable`).
    """

    g: np.ndarray
    rig: Rig
    valid: np.ndarray | None = None
    x0: np.ndarray | None = None
    truth: np.ndarray | None = None
    saturation: float | None = None
    batch: int | None = None
    interpolate: bool = False
    warn: bool = True


@dataclass(frozen=True)
class Settings:
    """Checked solver settings; ``lam``/``eta`` are None until :meth:`settled_for` a regularizer."""

    iterations: int
    lam: float | tuple[float, ...] | None
    eta: float | tuple[float, ...] | None
    tv_iterations: int | None
    projection: str
    tol: float | None
    callback: object

    def settled_for(self, reg, dtype, scale: float = 1.0) -> Settings:
        """``lam``/``eta`` filled from the regularizer's recommendation, else :data:`DEFAULTS` (``eta``
        of the paper's projection: :data:`PAPER_ETA`), times ``scale``
        (:func:`rsocl.model.curvature.default_scale` of the rig: the data term's curvature against
        the paper's configuration, for which the defaults hold). A default ``lam`` is not
        scaled for a set the caller runs as GAP (``eta = 0``), whose denoiser weight is ``lam``
        itself: with per-set ``eta`` mixing GAP and ADMM sets, the default ``lam`` is per set too,
        so each set gets the ``lam`` it gets on its own.

        Raises ValueError when the regularizer does not support ``dtype``.
        """
        dtype = check.real_dtype("dtype", dtype)
        if dtype.name not in reg.dtypes:
            raise ValueError(
                f"dtype {dtype.name!r} is not supported by regularizer {reg!r}; supported: {list(reg.dtypes)}"
            )
        recommended = {**DEFAULTS, **getattr(reg, "recommended", {})}
        default_eta = PAPER_ETA if self.projection == "paper" else recommended["eta"]
        eta = default_eta * scale if self.eta is None else self.eta
        lam = self.lam
        if lam is None:
            lams = recommended["lam"] * np.where(np.asarray(eta, dtype=np.float64) == 0, 1.0, scale)  # GAP: unscaled
            lam = float(lams.flat[0]) if np.all(lams == lams.flat[0]) else tuple(float(v) for v in lams)
        return replace(self, lam=lam, eta=eta)

    def for_batch(self, batch) -> Settings:
        """These settings for a problem of ``batch`` sets (None: one set); per-set values are checked
        against the count, and ``lam / eta`` against overflow (:func:`check_weight_ratio`); a ValueError
        naming the parameter."""
        for name in ("lam", "eta"):
            match_batch(name, getattr(self, name), batch)
        if self.lam is not None and self.eta is not None:
            check_weight_ratio(self.lam, self.eta)
        return self


def check_weight_ratio(lam, eta, lam_name: str = "lam") -> None:
    """Raise a ValueError naming ``lam`` (as ``lam_name``), ``eta`` (and the set, for per-set values) and the
    range of ``eta`` where ``eta > 0`` and the denoiser's weight ``lam / eta`` overflows float64 (``eta`` below
    ``lam / 1.8e308``); ``eta = 0`` (GAP) takes ``lam`` itself."""
    lams, etas = np.broadcast_arrays(
        np.atleast_1d(np.asarray(lam, np.float64)), np.atleast_1d(np.asarray(eta, np.float64))
    )
    with np.errstate(over="ignore"):
        ratio = lams / np.where(etas > 0, etas, 1.0)
    bad = np.nonzero((etas > 0) & ~np.isfinite(ratio))[0]
    if bad.size:
        i, top = int(bad[0]), float(np.finfo(np.float64).max)
        where = f" of set {i}" if isinstance(lam, tuple) or isinstance(eta, tuple) else ""
        raise ValueError(
            f"lam / eta{where} overflows ({lam_name} = {float(lams[i])!r}, eta = {float(etas[i])!r}): "
            f"eta must be 0 (GAP) or at least lam / {top:.3g} = {lams[i] / top:.3g} (or lam at most eta * {top:.3g})"
        )


def per_set_value(name: str, value):
    """A number ``>= 0`` (a float), or a sequence of them, one per set (a tuple of floats)."""
    if isinstance(value, numbers.Number) or np.ndim(value) == 0:
        return check.non_negative(name, value)
    if isinstance(value, (str, bytes)) or np.ndim(value) != 1 or len(value) == 0:
        raise ValueError(f"{name} must be a number >= 0 or a sequence of them, one per set, got {value!r}")
    return tuple(check.non_negative(f"{name}[{i}]", v) for i, v in enumerate(value))


def match_batch(name: str, value, batch):
    """Check that a per-set ``value`` (a tuple) has one entry per set of a batch of ``batch`` (None: one set)."""
    if not isinstance(value, tuple):
        return
    if batch is None:
        raise ValueError(
            f"{name} has {len(value)} values (one per set), but g holds one set (K, m, n); "
            f"give g as (B, K, m, n) for a batch, or one number"
        )
    if len(value) != batch:
        raise ValueError(f"{name} must have one value per set: {batch} for this batch, got {len(value)}")


def _cube(name, value, shape, batch=None):
    """``value`` checked as a ``(T, m, n)`` cube; for a batch also ``(B, T, m, n)`` (a single cube is every set's)."""
    if value is None:
        return None
    value = check.finite_array(name, value)
    if batch is not None and value.shape == (batch,) + shape:
        return value
    if value.shape != shape:
        extra = "" if batch is None else f" or (B, T, m, n) = {(batch,) + shape} for this batch"
        raise ValueError(f"{name} must have shape (T, m, n) = {shape}{extra}, got {value.shape}")
    return value if batch is None else np.broadcast_to(value, (batch,) + shape)


#: Snapshots above this many times their channel's full scale (the value of a white scene,
#: ``gain * t_e / dt``) get a warning: data not in [0, 1] per sub-frame, or a camera in other units.
OFF_SCALE = 10.0


def warn_off_scale(g, rig, valid=None) -> None:
    """Warn (``UserWarning``, one line) when some snapshot channel of ``g`` (``(K, m, n)`` or a batch) peaks
    above :data:`OFF_SCALE` times its full scale ``gain * t_e / dt`` (:func:`~rsocl.model.curvature.full_scales`;
    over the ``valid`` pixels: those below the saturation), naming the highest such camera. A channel whose
    exposures hold no sub-frame (full scale 0: a binary window between two sub-frame starts) is not compared."""
    full = full_scales(rig)
    values = np.abs(g) if valid is None else np.where(valid, np.abs(g), 0.0)
    peak = np.max(values.reshape((-1, rig.n_channels, g.shape[-2] * g.shape[-1])), axis=(0, 2))
    ratio = np.divide(peak, full, out=np.zeros_like(peak, dtype=np.float64), where=full > 0)
    k = int(np.argmax(ratio))
    if ratio[k] > OFF_SCALE:
        camera, frame = rig.channels[k]
        which = f"camera {camera}" + (f" (frame {frame})" if rig.cameras[camera].frames > 1 else "")
        warnings.warn(
            f"g: snapshots of {which} reach {peak[k]:.4g}, {ratio[k]:.3g} times its full scale "
            f"{full[k]:.4g} (a white scene): rsocl works on data in [0, 1] per sub-frame; "
            "scale that camera's snapshots (or its gain)",
            UserWarning,
            stacklevel=3,
        )


def check_problem(
    g: ArrayLike,
    rig: Rig,
    *,
    x0: ArrayLike | str | None = None,
    truth: ArrayLike | None = None,
    saturation: float | None = None,
    warn: bool = True,
) -> Problem:
    """Validate the snapshots and the arrays that go with them against ``rig``.

    ``g`` is ``(K, m, n)``, or ``(B, K, m, n)`` for a batch of ``B`` sets of the same rig; ``x0`` an
    array, ``"interp3d"`` (the interpolation of the snapshots, made on the device) or None. ``warn=False``:
    none of the data's warnings (off scale, saturation, float32's range), here or when it is staged.
    """
    interpolate = isinstance(x0, str)
    if interpolate and x0 != "interp3d":
        raise ValueError(f"x0 must be an array (T, m, n), 'interp3d' or None, got {x0!r}")
    if interpolate:
        x0 = None
    if not isinstance(rig, Rig):
        raise ValueError(f"rig must be an rsocl.Rig, got {type(rig).__name__}")
    g = check.finite_array("g", g)
    expected = (rig.n_channels,) + rig.shape
    batch = g.shape[0] if g.ndim == 4 and g.shape[1:] == expected else None
    if g.shape != expected and (batch is None or batch < 1):
        raise ValueError(
            f"g must have shape (K, m, n) = {expected} for this rig, or (B, K, m, n) = "
            f"(B, {', '.join(map(str, expected))}) for a batch of B >= 1 sets, got {g.shape}"
        )
    m, n = rig.shape
    sets = f"{batch} sets x " if batch else ""
    check_host_memory(
        4 * (batch or 1) * rig.T * m * n,
        f"rig shape {m}x{n} and T = {rig.T}",
        f"the {sets}{rig.T} x {m} x {n} float32 datacube",
        "choose a smaller grid, fewer sets or a run in tiles (rsocl.scale)",
    )
    valid = None
    if saturation is not None:
        saturation = check.positive("saturation", saturation, "(snapshot units)")
        valid = g < saturation
        empty = ~valid.reshape(batch or 1, -1).any(axis=1)
        if empty.any():
            which = "" if batch is None else f" of set(s) {np.flatnonzero(empty).tolist()}"
            raise ValueError(f"every snapshot pixel{which} is >= saturation = {saturation!r}: nothing left to fit")
        dark = ~np.where(valid, g != 0, False).reshape(batch or 1, -1).any(axis=1)
        if dark.any() and warn:
            which = "" if batch is None else f" of set(s) {np.flatnonzero(dark).tolist()}"
            warnings.warn(
                f"saturation = {saturation!r} keeps only snapshot pixels that are 0{which} (the brightest is "
                f"{float(np.max(g)):.4g}): the reconstruction will be zero; saturation is in snapshot units",
                UserWarning,
                stacklevel=3,
            )
        elif warn:
            _warn_mostly_clipped(g, rig, valid, saturation, batch)
    if warn:
        warn_off_scale(g, rig, valid)
    cube = (rig.T,) + rig.shape
    start, known = _cube("x0", x0, cube, batch), _cube("truth", truth, cube, batch)
    return Problem(g, rig, valid, start, known, saturation, batch, interpolate, warn)


def check_settings(
    *, iterations=None, lam=None, eta=None, tv_iterations=None, projection="exact", tol=None, callback=None
) -> Settings:
    """Validate the solver settings (None keeps a default); ``lam``/``eta`` may give one value per set
    (see :func:`per_set_value`; :meth:`Settings.for_batch` checks the count)."""
    if callback is not None:
        check_callback(callback)
    return Settings(
        iterations=check.positive_int(
            "iterations", DEFAULTS["iterations"] if iterations is None else iterations, MAX_ITERATIONS
        ),
        lam=None if lam is None else per_set_value("lam", lam),
        eta=None if eta is None else per_set_value("eta", eta),
        tv_iterations=None if tv_iterations is None else check.positive_int("tv_iterations", tv_iterations),
        projection=check.choice("projection", projection, {"exact", "paper"}),
        tol=None if tol is None else check.non_negative("tol", tol),
        callback=callback,
    )


@dataclass
class Staged:
    """A problem on the device: the operator over the ``solved`` sub-frames and its arrays.

    ``truth``, ``data_range`` and ``held`` (the error of the sub-frames outside ``solved``, which
    hold the nearest solved one: :class:`~rsocl.solver.held.HeldSumSquares`) are set only when a ground
    truth was given; for a batch ``data_range`` is one per set.
    """

    op: RollingShutterOperator
    solved: slice
    g: cla.Array
    x0: cla.Array | None = None
    truth: cla.Array | None = None
    data_range: float | np.ndarray = 1.0
    held: HeldSumSquares | None = None


def check_representable(problem: Problem, dtype):
    """Raise a ValueError naming the array when ``g``, ``x0`` or ``truth`` holds values beyond the
    largest finite value of ``dtype`` (float64 data above 3.4e38 run in float32 would turn into inf); unless
    ``problem.warn`` is False, warn of float32 snapshots of a scale it does not hold (:func:`warn_float32_scale`)."""
    for name in ("g", "x0", "truth"):
        check_fits_dtype(name, getattr(problem, name), dtype)
    if problem.warn:
        warn_float32_scale(problem.g, dtype)


def stage_on_device(problem: Problem, reg, settings: Settings, *, device=None, dtype="float32", start=False) -> Staged:
    """Build the operator for the sampled sub-frames, check the memory, upload the arrays.

    Only the sub-frames some camera samples are modelled; the others hold the nearest modelled one
    in the result (:mod:`rsocl.solver.held`).
    Raises an error naming the sizes when the run would not fit the device; the count
    (:func:`~rsocl.solver.memory.memory_bytes`) includes a start cube per set when the problem has
    an ``x0`` or ``start`` says one will be made after staging (the self-tuned run's ``interp3d`` start).
    """
    check_representable(problem, dtype)
    rig = problem.rig
    solved = rig.sampled_range()
    op = RollingShutterOperator(rig, device=device, dtype=dtype, subframes=solved)
    sets = problem.batch or 1
    own = own_inverses(settings.projection, settings.eta, None, sets)  # saturated pixels stay in the blocks
    largest, need = memory_bytes(
        op,
        reg,
        settings.projection,
        sets,
        truth=problem.truth is not None,
        own_inverse=own,
        start=bool(start) or problem.x0 is not None,
    )
    batch = "" if problem.batch is None else f"{sets} sets of "
    op.device.check_fits(
        f"ADMM with {reg.name} on {batch}T={op.T} x {rig.shape[0]} x {rig.shape[1]} ({op.dtype.name})",
        largest,
        total_bytes=need,
        dtype=op.dtype,
    )

    def upload(array):
        return pool.to_device(op.queue, np.asarray(array, dtype=op.dtype))

    cut = (Ellipsis, solved, slice(None), slice(None))
    staged = Staged(op, solved, upload(problem.g), None if problem.x0 is None else upload(problem.x0[cut]))
    truth = problem.truth
    if truth is not None:
        staged.truth = upload(truth[cut])
        staged.held = HeldSumSquares(truth, solved, rig.T)
        if problem.batch is None:
            staged.data_range = default_data_range(truth)
        else:
            staged.data_range = np.array([default_data_range(t) for t in truth])
    return staged


def _warn_mostly_clipped(g, rig, valid, saturation, batch) -> None:
    """Warn when more than :data:`CLIPPED_SHARE_WARN` of a set's snapshot samples are at or above ``saturation``."""
    share = 1.0 - valid.reshape(batch or 1, -1).mean(axis=1)
    worst = int(np.argmax(share))
    if share[worst] <= CLIPPED_SHARE_WARN:
        return
    from rsocl.model.simulate import full_scale

    try:
        white = f" (a white scene reads {full_scale(rig):.4g} on this rig)"
    except ValueError:
        white = ""
    which = "" if batch is None else f" of set {worst}"
    warnings.warn(
        f"saturation = {saturation!r} marks {100 * share[worst]:.0f} % of the snapshot samples{which} as clipped "
        f"(fitted only as lower bounds); saturation is the level the sensor clips at, in snapshot units{white}",
        UserWarning,
        stacklevel=4,
    )
