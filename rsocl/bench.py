"""``rsocl bench``: what each setting buys in quality (PSNR, SSIM) and costs in time and memory.

A *point* (:class:`BenchPoint`) fixes every knob: scene, number of cameras (the paper's angle
order), ROI, sub-frame duration ``dt``, ADMM and inner denoiser iterations, regularizer, dtype
and device. :func:`run_point` simulates the capture, reconstructs it and measures it; a sweep
varies one knob at a time around a default point; :func:`write_outputs` writes ``bench.csv``,
``iterations.csv``, ``bench.md`` and three PNG plots (:mod:`rsocl.bench_plots`).

How a point is measured
-----------------------
* **One capture, one ground truth.** The scene is turned into a datacube with the benchmark
  protocol (:func:`rsocl.scenes.load_scene`) on the *reference grid*: the rig of the point
  with ``dt = t_r`` (the finest sub-frame the cameras resolve). The snapshots are the
  float64 forward model of that datacube. They do not depend on the ``dt`` or the ROI the
  reconstruction chooses, exactly as with real cameras.
* **Coarser ``dt``** (``dt_factor`` × ``t_r``) reconstructs the same snapshots on fewer,
  longer sub-frames (the snapshots divided by ``dt_factor``, so that the datacube keeps the
  [0, 1] scale the solver's defaults assume); for the metrics each reference sub-frame takes
  the value of the coarse sub-frame that holds its centre, so the PSNR counts the temporal
  detail a coarse ``dt`` gives up.
* **A tighter ROI** is a centred ``roi × roi`` crop of the ``shape × shape`` grid
  (:func:`rsocl.plan.crop_rig`: the crop keeps the full sensor's row times, so sub-frames no
  cropped pixel samples drop out). Its snapshots and truth are the crop of the full ones; its
  metrics cover the crop's sampled sub-frames, and ``psnr_full_roi`` is the PSNR of the
  full-ROI reconstruction (same other knobs) over the same pixels and sub-frames.
* Metrics (:func:`rsocl.metrics.psnr`, :func:`rsocl.metrics.ssim`: peak 1) cover the
  sub-frames some camera samples (all ``T`` for an uncropped rig).
* **Time**: ``seconds`` is the wall time of the whole :func:`rsocl.reconstruct` call (host to
  device transfers, the per-pixel inverse blocks, the iterations with their residual and
  PSNR monitoring, and the copy back); the first-time kernel compilation is excluded by one
  warm-up iteration per combination of rig, regularizer, dtype and device.
  ``seconds_per_iteration`` is the ADMM loop alone (``history["time"][-1] / iterations``).
* **Memory**: PoCL exposes no allocation counter, so ``peak_device_memory_bytes`` is the
  exact sum of the buffers rsocl allocates for the run (see :func:`device_memory_bytes`).

The baseline ``interp3d`` (:func:`interp3d`) needs no solver: each snapshot pixel divided by
its exposure length estimates the scene at the middle of its exposure window, and each
pixel is interpolated linearly in time between its ``C`` samples.
"""

from __future__ import annotations

import csv
import io
import math
import os
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from .atomic import atomic_path

__all__ = ["BenchPoint", "BenchResult", "SWEEPS", "BASELINE", "run_point", "interp3d", "device_memory_bytes",
           "build_points", "run_bench", "pareto_front", "markdown", "write_csv", "write_outputs",
           "add_bench_parser", "cmd_bench"]

US = 1e-6
#: Name of the baseline's rows in the ``regularizer`` column.
BASELINE = "interp3d"
#: Sweep name -> the :class:`BenchPoint` field it varies.
SWEEPS = {"cameras": "cameras", "iterations": "iterations", "tv_iterations": "tv_iterations",
          "regularizer": "regularizer", "dtype": "dtype", "dt": "dt_factor", "roi": "roi", "device": "device"}
#: Columns of ``bench.csv``, in order.
COLUMNS = ("scene", "sweep", "label", "regularizer", "cameras", "shape", "roi", "dt_factor", "dt_us", "iterations",
           "tv_iterations", "dtype", "device", "lam", "eta", "T", "T_se", "subframes_evaluated", "psnr",
           "ssim_mean", "seconds", "seconds_per_iteration", "peak_device_memory_bytes", "psnr_full_roi",
           "ssim_per_subframe")
#: Drop from the best PSNR accepted by the "pick for speed" line, dB.
SPEED_PICK_DB = 1.0


# ---------------------------------------------------------------------- points
@dataclass(frozen=True)
class BenchPoint:
    """Every knob of one measurement.

    Attributes
    ----------
    scene : str
        ``"builtin"`` or a video file (see :func:`rsocl.scenes.load_scene`).
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
    lam, eta : float
        ADMM weights (defaults of :func:`rsocl.reconstruct`).
    t_e, t_r : float
        Exposure and row time of every camera, seconds.
    """

    scene: str = "builtin"
    cameras: int = 4
    shape: int = 64
    roi: int | None = None
    dt_factor: float = 1.0
    iterations: int = 200
    tv_iterations: int | None = 10
    regularizer: str = "tv"
    dtype: str = "float32"
    device: str | None = None
    lam: float = 0.1
    eta: float = 0.2
    t_e: float = 180e-6
    t_r: float = 35e-6

    def __post_init__(self):
        from . import validation as check

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
            check.positive_int("iterations", self.iterations)
        if self.tv_iterations is not None:
            check.positive_int("tv_iterations", self.tv_iterations)
        check.positive("t_e", self.t_e, "seconds")
        check.positive("t_r", self.t_r, "seconds")

    @property
    def roi_size(self) -> int:
        return self.shape if self.roi is None else self.roi

    @property
    def is_baseline(self) -> bool:
        return self.regularizer == BASELINE

    def rig(self, dt_factor=None):
        """The rig of this point (``dt_factor`` overrides the point's; 1 gives the reference grid)."""
        from .plan import crop_rig
        from .rig import Rig

        k = self.dt_factor if dt_factor is None else dt_factor
        full = Rig.paper_array(self.cameras, (self.shape, self.shape), t_e=self.t_e, t_r=self.t_r,
                               dt=k * self.t_r)
        if self.roi is None:
            return full
        return crop_rig(full, self.crop_box())

    def crop_box(self):
        """``(y, x, height, width)`` of the centred ROI."""
        offset = (self.shape - self.roi_size) // 2
        return (offset, offset, self.roi_size, self.roi_size)


def _scene_name(scene) -> str:
    return "builtin" if scene == "builtin" else Path(str(scene)).name


# ---------------------------------------------------------------------- the baseline
def interp3d(g, rig) -> np.ndarray:
    """The 3-D interpolation baseline: a ``(T, m, n)`` datacube from the snapshots alone.

    Snapshot pixel ``g[k, y, x]`` divided by its gain and exposure length (``t_e/dt``
    sub-frames) is the mean of the scene over its exposure window, taken as the scene's
    value at the window's middle, ``(start + end) / 2``. Each pixel then has ``K``
    samples scattered in time (one per camera, at its own row time); the estimate of
    sub-frame ``s`` is the linear interpolation of those samples at the sub-frame's centre
    ``s + 1/2``, constant before the first and after the last sample. Samples at equal
    times count with equal weight. This is the natural 3-D interpolation of the
    scattered space-time samples, done per pixel; it is exact for a scene constant in time.

    Parameters
    ----------
    g : array_like, shape (K, m, n)
        Snapshots of ``rig``.
    rig : Rig

    Returns
    -------
    ndarray of float64, shape (T, m, n)
    """
    g = np.asarray(g, dtype=np.float64)
    K = rig.n_channels
    if g.shape != (K,) + rig.shape:
        raise ValueError(f"g must have shape (K, m, n) = {(K,) + rig.shape}, got {g.shape}")
    win = rig.windows
    length = win.length[:, None, None]
    centre = win.index + win.fraction + length / 2.0
    values = g / (win.gain[:, None, None] * length)
    T = rig.T
    if K == 1:
        return np.repeat(values, T, axis=0)
    order = np.argsort(centre, axis=0, kind="stable")
    times = np.take_along_axis(centre, order, axis=0)
    values = np.take_along_axis(values, order, axis=0)
    query = np.arange(T, dtype=np.float64) + 0.5
    hi = np.zeros((T,) + rig.shape, dtype=np.int64)
    for k in range(K):                                   # samples at or before each query time
        hi += times[k][None] <= query[:, None, None]
    hi = np.clip(hi, 1, K - 1)
    lo = hi - 1
    t_lo, t_hi = np.take_along_axis(times, lo, axis=0), np.take_along_axis(times, hi, axis=0)
    v_lo, v_hi = np.take_along_axis(values, lo, axis=0), np.take_along_axis(values, hi, axis=0)
    span = t_hi - t_lo
    w = np.where(span > 0, (query[:, None, None] - t_lo) / np.where(span > 0, span, 1.0), 0.5)
    w = np.clip(w, 0.0, 1.0)
    return v_lo + w * (v_hi - v_lo)


# ---------------------------------------------------------------------- memory
def device_memory_bytes(rig, regularizer="tv", dtype="float32", *, device=None, projection="exact",
                        tv_iterations=None, with_truth=True) -> int:
    """Device memory of one :func:`rsocl.reconstruct` run, bytes.

    PoCL (like OpenCL itself) exposes no allocation counter, so this is the exact sum of the
    buffers rsocl allocates for the run and keeps until its end: the operator's geometry
    (exposure-start index and fraction per channel and pixel, length and gain per channel),
    the snapshots, the ground truth when given (for the PSNR history), the solver's arrays
    (:meth:`rsocl.admm.ADMM.buffers_bytes`: theta, b, f, u, H·theta, the per-pixel inverse
    blocks) and the regularizer's workspace (``workspace_bytes``). The Gram blocks, a
    temporary of the inverse's size freed before the inverse is stored, and the few partial
    sums of the reductions are not counted.
    """
    from .admm import ADMM
    from .operator import RollingShutterOperator
    from .reconstruct import _regularizer

    solved = rig.sampled_range()
    op = RollingShutterOperator(rig, device=device, dtype=dtype, subframes=solved)
    reg = _regularizer(regularizer, None, tv_iterations)
    item = op.dtype.itemsize
    kmn = op.K * op.mn
    cube = op.T * op.mn * item
    geometry = kmn * 4 + kmn * item + 2 * op.K * item
    total = geometry + kmn * item + ADMM.buffers_bytes(op, projection) + reg.workspace_bytes(op.domain_shape, op.dtype)
    if with_truth:
        total += cube
    return int(total)


# ---------------------------------------------------------------------- one point
def _device_of(spec):
    from .device import get_device

    return get_device(spec)


def _data(point: BenchPoint, cache: dict):
    """Reference rig, truth and snapshots of the point's capture (cached), and the metric window."""
    from .operator import RollingShutterOperator
    from .scenes import load_scene

    key = ("data", point.scene, point.cameras, point.shape, point.roi, point.t_e, point.t_r, point.device)
    if key not in cache:
        full = replace(point, roi=None).rig(dt_factor=1.0)
        scene_key = ("scene", point.scene, point.shape, full.T)
        if scene_key not in cache:
            cache[scene_key] = load_scene(point.scene, full.shape, full.T)
        truth = cache[scene_key]
        ref = point.rig(dt_factor=1.0)
        if point.roi is not None:
            y, x, h, w = point.crop_box()
            truth = truth[:ref.T, y:y + h, x:x + w]
        truth = np.ascontiguousarray(truth, dtype=np.float64)
        device = _device_of(point.device)
        op = RollingShutterOperator(ref, device=device, dtype="float64" if device.has_fp64 else "float32")
        g = np.asarray(op.forward(truth), dtype=np.float64)
        cache[key] = (ref, truth, g, ref.sampled_range())
    return cache[key]


def _reference_index(rig, ref):
    """For each reference sub-frame: the sub-frame of ``rig`` (same time origin) holding its centre."""
    k = rig.dt / ref.dt
    index = np.floor((np.arange(ref.T) + 0.5) / k + 1e-9).astype(np.int64)
    return np.clip(index, 0, rig.T - 1)


def _own_grid_truth(truth_ref, rig, ref):
    """The reference truth sampled at the centres of ``rig``'s sub-frames (for the PSNR history)."""
    if rig.T == ref.T and math.isclose(rig.dt, ref.dt):
        return truth_ref
    k = rig.dt / ref.dt
    index = np.clip(np.floor((np.arange(rig.T) + 0.5) * k + 1e-9).astype(np.int64), 0, ref.T - 1)
    return truth_ref[index]


def _metrics(estimate_ref, truth_ref, window):
    from .metrics import psnr, ssim

    est, tru = estimate_ref[window], truth_ref[window]
    mean_ssim, per = ssim(est, tru, data_range=1.0)
    return psnr(est, tru, data_range=1.0), mean_ssim, per


def _row(point: BenchPoint, rig, window, **values) -> dict:
    row = {
        "scene": _scene_name(point.scene), "sweep": "", "label": "", "regularizer": point.regularizer,
        "cameras": point.cameras, "shape": point.shape, "roi": point.roi_size, "dt_factor": point.dt_factor,
        "dt_us": rig.dt / US, "iterations": point.iterations, "tv_iterations": point.tv_iterations,
        "dtype": point.dtype, "device": "", "lam": point.lam, "eta": point.eta, "T": rig.T, "T_se": rig.T_se,
        "subframes_evaluated": window.stop - window.start, "psnr_full_roi": None,
    }
    row.update(values)
    row["_point"] = point
    return row


def _full_roi_psnr(point, cache, window, truth_ref):
    if point.roi is None:
        return None
    full = cache.get(("cube", replace(point, roi=None)))
    if full is None:
        return None
    from .metrics import psnr

    y, x, h, w = point.crop_box()
    return psnr(full[window, y:y + h, x:x + w], truth_ref[window], data_range=1.0)


def run_point(point: BenchPoint, truth_cache: dict | None = None) -> dict:
    """Measure one point; returns its row (see :data:`COLUMNS`; ``_history`` holds the run's history).

    ``truth_cache`` (a dict, reused across points) keeps scenes, snapshots, warm-up marks and
    the full-ROI reconstructions the crops are compared with.
    """
    from .reconstruct import reconstruct

    cache = {} if truth_cache is None else truth_cache
    ref, truth_ref, g, window = _data(point, cache)
    if point.is_baseline:
        start = time.perf_counter()
        estimate = interp3d(g, ref)
        seconds = time.perf_counter() - start
        psnr_value, mean_ssim, per = _metrics(estimate, truth_ref, window)
        if point.roi is None:
            cache[("cube", point)] = estimate
        return _row(point, ref, window, psnr=psnr_value, ssim_mean=mean_ssim, ssim_per_subframe=per,
                    seconds=seconds, seconds_per_iteration=None, peak_device_memory_bytes=0,
                    device="host (NumPy)", dtype="float64", iterations=0, tv_iterations=None,
                    dt_factor=1.0, dt_us=ref.dt / US, psnr_full_roi=_full_roi_psnr(point, cache, window, truth_ref),
                    _history=None)

    rig = point.rig()
    truth_own = _own_grid_truth(truth_ref, rig, ref)
    # a sub-frame of k*t_r integrates k times the light of one of t_r: scale the snapshots so
    # that the datacube stays in [0, 1] (the scale rsocl's lam and eta assume, README)
    g_scaled = g * (ref.dt / rig.dt)
    kwargs = dict(regularizer=point.regularizer, lam=point.lam, eta=point.eta, tv_iterations=point.tv_iterations,
                  device=point.device, dtype=point.dtype, truth=truth_own)
    warm = ("warm",) + tuple(v for f, v in asdict(point).items() if f not in ("scene", "iterations", "lam", "eta"))
    if warm not in cache:
        reconstruct(g_scaled, rig, iterations=1, **kwargs)
        cache[warm] = True
    start = time.perf_counter()
    result = reconstruct(g_scaled, rig, iterations=point.iterations, **kwargs)
    seconds = time.perf_counter() - start
    estimate = result.datacube.astype(np.float64)[_reference_index(rig, ref)]
    psnr_value, mean_ssim, per = _metrics(estimate, truth_ref, window)
    if point.roi is None:
        cache[("cube", point)] = estimate
    memory = device_memory_bytes(rig, point.regularizer, point.dtype, device=point.device,
                                 tv_iterations=point.tv_iterations, with_truth=True)
    return _row(point, rig, window, psnr=psnr_value, ssim_mean=mean_ssim, ssim_per_subframe=per, seconds=seconds,
                seconds_per_iteration=float(result.history["time"][-1]) / result.iterations,
                peak_device_memory_bytes=memory, device=result.params["device"],
                psnr_full_roi=_full_roi_psnr(point, cache, window, truth_ref), _history=result.history)


# ---------------------------------------------------------------------- sweeps
#: Sweep values of the full run; iterations and roi as fractions of the default point's.
FULL = {"cameras": [1, 2, 3, 4, 5, 6, 7, 8], "iterations": [0.125, 0.25, 0.5, 1.0, 1.5],
        "tv_iterations": [2, 5, 10, 20], "dt": [1, 2, 3, 4], "roi": [0.5, 0.75, 1.0]}
#: The ``--quick`` run: fewer values, the sweeps that show the trade.
QUICK = {"cameras": [1, 2, 4, 8], "iterations": [0.1, 0.25, 0.5, 1.0], "tv_iterations": [2, 5, 10],
         "dt": [1, 2, 4], "roi": [0.5, 0.75, 1.0], "regularizer": ["tv"]}


def _canonical_device(spec):
    """``"P:D"`` of the device ``spec`` selects (so one device is one point whatever its spelling)."""
    from .device import list_devices

    dev = _device_of(spec).device
    for pi, di, _, d in list_devices():
        if d == dev:
            return f"{pi}:{di}"
    return spec


def _default_values(name, default: BenchPoint, quick: bool, notes: list):
    from .device import list_devices
    from .plugins import available

    table = QUICK if quick else FULL
    if name in table:
        values = table[name]
        if name == "iterations":
            return sorted({max(1, round(f * default.iterations)) for f in values})
        if name == "roi":
            return sorted({max(4, round(f * default.shape)) for f in values})
        return list(values)
    if name == "regularizer":
        return list(available("rsocl.regularizers"))
    if name == "dtype":
        if _device_of(default.device).has_fp64:
            return ["float32", "float64"]
        notes.append(f"dtype: device {_device_of(default.device).name} has no fp64; float32 only")
        return ["float32"]
    if name == "device":
        return [f"{pi}:{di}" for pi, di, _, _ in list_devices()]
    if name == "tv_iterations":
        return list(FULL["tv_iterations"])
    raise ValueError(f"unknown sweep {name!r}; known: {sorted(SWEEPS)}")


def parse_sweep(text: str):
    """``"NAME"`` or ``"NAME=v1,v2,..."`` -> (name, values or None)."""
    name, _, values = str(text).partition("=")
    name = name.strip().replace("-", "_")
    if name not in SWEEPS:
        raise ValueError(f"--sweep must be one of {sorted(SWEEPS)} (optionally NAME=v1,v2,...), got {text!r}")
    if not values.strip():
        return name, None
    kind = {"cameras": int, "iterations": int, "tv_iterations": int, "roi": int, "dt": float}.get(name, str)
    try:
        return name, [kind(v.strip()) for v in values.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--sweep {name}: values must be {kind.__name__}s separated by commas, got {values!r}") \
            from None


def _regularizer_point(default: BenchPoint, name: str):
    """The default point with regularizer ``name`` (inner iterations only where it has them)."""
    from .plugins import load

    cls = load("rsocl.regularizers", name)
    iterative = "iterations" in getattr(cls, "options", {})
    return replace(default, regularizer=name, tv_iterations=default.tv_iterations if iterative else None)


def build_points(default: BenchPoint, sweeps=None, *, quick=False, baseline=True):
    """Points of the requested sweeps around ``default``, deduplicated, default first.

    Parameters
    ----------
    sweeps : iterable of str or (name, values) or None
        Sweep names (``"cameras"``) or ``"NAME=v1,v2"`` strings or ``(name, values)`` pairs;
        None: every sweep (``--quick``: the quick set).
    baseline : bool
        Add an ``interp3d`` point for every capture (cameras, ROI) of the run.

    Returns
    -------
    points : list of (BenchPoint, sweep labels)
    notes : list of str
        Values left out (a broken regularizer, a ROI larger than the grid, no fp64, ...).
    """
    notes = []
    if sweeps is None:
        sweeps = list(QUICK) if quick else list(SWEEPS)
    requested = []
    for item in sweeps:
        name, values = parse_sweep(item) if isinstance(item, str) else (item[0], item[1])
        requested.append((name, values if values is not None else _default_values(name, default, quick, notes)))
    order, labels = [default], {default: ["default"]}

    def add(point, label):
        if point not in labels:
            order.append(point)
            labels[point] = []
        if label not in labels[point]:
            labels[point].append(label)

    for name, values in requested:
        knob = SWEEPS[name]
        for value in values:
            try:
                if knob == "regularizer":
                    point = _regularizer_point(default, value)
                elif knob == "device":
                    point = replace(default, device=_canonical_device(value))
                else:
                    point = replace(default, **{knob: value})
            except Exception as exc:                      # a broken plugin, an out-of-range value
                notes.append(f"{name}={value}: skipped ({type(exc).__name__}: {exc})")
                continue
            add(point, name)
    if baseline:
        for point in list(order):
            base = replace(default, cameras=point.cameras, roi=point.roi, regularizer=BASELINE, iterations=0,
                           tv_iterations=None, dtype="float64", dt_factor=1.0, device=default.device)
            add(base, "baseline")
    order.sort(key=lambda p: p.roi is not None)             # full-ROI runs first: the crops compare with them
    return [(p, labels[p]) for p in order], notes


def _label(point: BenchPoint, default: BenchPoint) -> str:
    parts = [] if not point.is_baseline else [BASELINE]
    if point.cameras != default.cameras:
        parts.append(f"C={point.cameras}")
    if point.roi_size != default.roi_size:
        parts.append(f"ROI {point.roi_size}")
    if point.is_baseline:
        return " ".join(parts)
    if point.regularizer != default.regularizer:
        parts.append(point.regularizer)
    if point.iterations != default.iterations:
        parts.append(f"it={point.iterations}")
    if point.tv_iterations != default.tv_iterations and point.regularizer == default.regularizer:
        parts.append(f"inner={point.tv_iterations}")
    if point.dtype != default.dtype:
        parts.append(point.dtype)
    if point.dt_factor != default.dt_factor:
        parts.append(f"dt={point.dt_factor:g}t_r")
    if point.device != default.device:
        parts.append(f"dev {point.device}")
    return " ".join(parts) or "default"


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

    def history(self):
        """History of the longest run whose knobs other than ``iterations`` are the default's."""
        best = None
        for row in self.rows:
            point = row["_point"]
            if row.get("_history") is None or replace(point, iterations=self.default.iterations) != self.default:
                continue
            if best is None or point.iterations > best["_point"].iterations:
                best = row
        return None if best is None else best["_history"]


def run_bench(default: BenchPoint, sweeps=None, *, quick=False, baseline=True, progress=True, cache=None,
              repeat_default=True) -> BenchResult:
    """Build the points (:func:`build_points`) and measure each (:func:`run_point`).

    With ``repeat_default`` the default point is timed once more at the end
    (:attr:`BenchResult.timing_check`), which shows how much the times drift with the
    machine's other load.

    A point that fails (a broken plugin, a dtype the regularizer lacks, a problem too large
    for the device) is left out with a note; the others are measured.
    """
    from tqdm.auto import tqdm

    start = time.perf_counter()
    load_start = _load()
    default = replace(default, device=_canonical_device(default.device))
    points, notes = build_points(default, sweeps, quick=quick, baseline=baseline)
    cache = {} if cache is None else cache
    rows = []
    bar = tqdm(points, desc="rsocl bench", unit="point", disable=None if progress else True, leave=False)
    try:
        for point, labels in bar:
            bar.set_postfix_str(_label(point, default))
            try:
                row = run_point(point, cache)
            except (KeyboardInterrupt, MemoryError):
                raise
            except Exception as exc:
                notes.append(f"{_label(point, default)}: failed ({type(exc).__name__}: {exc})")
                continue
            row["sweep"] = "|".join(labels)
            row["label"] = _label(point, default)
            rows.append(row)
    finally:
        bar.close()
    timing_check = None
    first = next((r for r in rows if r["_point"] == default), None)
    if repeat_default and first is not None and len(rows) > 1:
        timing_check = (first["seconds"], run_point(default, cache)["seconds"])
    device = _device_of(default.device).name
    return BenchResult(rows, default, notes, time.perf_counter() - start, device, timing_check,
                       (load_start, _load()))


def _load():
    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return None


# ---------------------------------------------------------------------- analysis
def _finite(value) -> bool:
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def pareto_front(rows, x="seconds", y="psnr"):
    """Indices of the rows no other row beats: less or equal ``x`` and more or equal ``y``, one strictly.

    Rows whose ``x`` or ``y`` is missing or NaN are ignored. Returned in increasing ``x``.
    """
    candidates = [i for i, r in enumerate(rows) if _finite(r.get(x)) and _finite(r.get(y))]
    candidates.sort(key=lambda i: (float(rows[i][x]), -float(rows[i][y])))
    front, best = [], -math.inf
    for i in candidates:
        if float(rows[i][y]) > best:
            front.append(i)
            best = float(rows[i][y])
    return front


def _comparable(row, default: BenchPoint) -> bool:
    """Rows of the same capture as the default (same cameras and ROI): the user's choices."""
    point = row["_point"] if "_point" in row else None
    if point is not None:
        return point.cameras == default.cameras and point.roi_size == default.roi_size and point.shape == default.shape
    return int(row["cameras"]) == default.cameras and int(row["roi"]) == default.roi_size


def _default_row(result: BenchResult):
    for row in result.rows:
        if row["_point"] == result.default:
            return row
    return None


def _varied(result: BenchResult, knob: str, *, baseline=False):
    """Rows that differ from the default (or its baseline) in ``knob`` only, sorted by that knob."""
    default = result.default
    if baseline:
        default = replace(default, regularizer=BASELINE, iterations=0, tv_iterations=None, dtype="float64",
                          dt_factor=1.0)
    out = []
    for row in result.rows:
        point = row["_point"]
        if replace(point, **{knob: getattr(default, knob)}) == default:
            out.append(row)
    key = (lambda r: r["_point"].roi_size) if knob == "roi" else (lambda r: getattr(r["_point"], knob))
    return sorted(out, key=key)


def _reconstructions(result: BenchResult):
    """Reconstruction rows (no baseline) of the default's capture: what a user chooses between."""
    return [r for r in result.rows if not r["_point"].is_baseline and _comparable(r, result.default)]


def picks(result: BenchResult):
    """``(speed row, quality row)`` among the reconstructions of the default's capture (None when empty).

    Quality: the highest PSNR. Speed: the fastest point of the Pareto front (PSNR against
    seconds) within :data:`SPEED_PICK_DB` of that PSNR.
    """
    rows = _reconstructions(result)
    if not rows:
        return None, None
    front = [rows[i] for i in pareto_front(rows)]
    quality = max(rows, key=lambda r: r["psnr"])
    speed = next((r for r in front if r["psnr"] >= quality["psnr"] - SPEED_PICK_DB), quality)
    return speed, quality


# ---------------------------------------------------------------------- writers
def _fmt(value, digits=6):
    if value is None:
        return ""
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return f"{value:.{digits}g}"
    if isinstance(value, np.ndarray):
        return " ".join(f"{v:.4f}" for v in value)
    return str(value)


def write_csv(path, rows) -> Path:
    """``bench.csv``: one line per row, :data:`COLUMNS` (SSIM per sub-frame space-separated)."""
    path = Path(os.fspath(path))
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _fmt(row.get(k)) for k in COLUMNS})
    with atomic_path(path) as tmp:
        tmp.write_text(buffer.getvalue(), encoding="utf-8")
    return path


def write_iterations_csv(path, history) -> Path:
    """``iterations.csv``: iteration, PSNR (dB), relative residual, seconds since the start."""
    path = Path(os.fspath(path))
    buffer = io.StringIO()
    buffer.write("iteration,psnr,residual,seconds\n")
    if history is not None:
        psnr_values = history.get("psnr", [math.nan] * len(history["residual"]))
        for i, (p, r, t) in enumerate(zip(psnr_values, history["residual"], history["time"]), start=1):
            buffer.write(f"{i},{_fmt(float(p))},{_fmt(float(r))},{_fmt(float(t))}\n")
    with atomic_path(path) as tmp:
        tmp.write_text(buffer.getvalue(), encoding="utf-8")
    return path


def _num(value, spec):
    if value is None:
        return "–"
    if isinstance(value, float) and math.isinf(value):
        return "∞"
    return format(value, spec)


def _ratio(a, b):
    return a / b if b else math.nan


def tradeoff_lines(result: BenchResult):
    """Sentences on what coarser ``dt`` and a tighter ROI buy in time and cost in PSNR."""
    base = _default_row(result)
    lines = []
    if base is None:
        return ["(the default point did not run)"]
    if result.timing_check:                      # the reference time: the mean of the default's two timings
        base = dict(base, seconds=sum(result.timing_check) / 2)
        lines.append(f"Times against the default point's mean of its two timings, {base['seconds']:.2f} s.")
        lines.append("")
    for row in _varied(result, "dt_factor"):
        p = row["_point"]
        if p == result.default:
            continue
        lines.append(
            f"- **dt = {p.dt_factor:g}·t_r = {row['dt_us']:.0f} µs** (T {base['T']} → {row['T']}): "
            f"{row['seconds']:.2f} s instead of {base['seconds']:.2f} s (×{_ratio(row['seconds'], base['seconds']):.2f}), "
            f"memory ×{_ratio(row['peak_device_memory_bytes'], base['peak_device_memory_bytes']):.2f}; "
            f"PSNR {_num(row['psnr'], '.2f')} dB vs {_num(base['psnr'], '.2f')} dB "
            f"({row['psnr'] - base['psnr']:+.2f} dB against the same dt = t_r ground truth), "
            f"SSIM {row['ssim_mean']:.3f} vs {base['ssim_mean']:.3f}.")
    for row in _varied(result, "roi"):
        p = row["_point"]
        if p == result.default:
            continue
        full = row["psnr_full_roi"]
        diff = "" if full is None else f" ({row['psnr'] - full:+.2f} dB)"
        lines.append(
            f"- **ROI {p.roi_size}×{p.roi_size}** (centred crop of {p.shape}×{p.shape}, "
            f"{row['subframes_evaluated']} sub-frames sampled instead of {base['subframes_evaluated']}): "
            f"{row['seconds']:.2f} s instead of {base['seconds']:.2f} s (×{_ratio(row['seconds'], base['seconds']):.2f}), "
            f"memory ×{_ratio(row['peak_device_memory_bytes'], base['peak_device_memory_bytes']):.2f}; "
            f"PSNR in the crop {_num(row['psnr'], '.2f')} dB vs {_num(full, '.2f')} dB for the full-ROI "
            f"reconstruction over the same pixels and sub-frames{diff}.")
    return lines if any(line.startswith("- ") for line in lines) else ["(no dt or roi sweep in this run)"]


def markdown(result: BenchResult) -> str:
    """``bench.md``: the table, what coarser dt and a tighter ROI buy, and the picks."""
    d = result.default
    devices = {r["device"] for r in result.rows if not r["_point"].is_baseline}
    show_device = len(devices) > 1
    lines = [f"# rsocl bench: {_scene_name(d.scene)}", "",
             f"Paper array (angles 0, 90, 180, 270, 45, 135, 225, 315 in that order), t_e = {d.t_e / US:g} µs, "
             f"t_r = {d.t_r / US:g} µs, scene resized to {d.shape}×{d.shape} (benchmark protocol). "
             f"Default point: {d.cameras} cameras, dt = {d.dt_factor:g}·t_r, {d.regularizer} "
             f"({d.iterations} iterations, {d.tv_iterations} inner), {d.dtype}, lam = {d.lam:g}, eta = {d.eta:g}. "
             f"Device: {result.device}; {os.cpu_count()} CPU cores; whole run {result.seconds:.0f} s.", ""]
    if result.load and None not in result.load:
        timing = (f"Load average {result.load[0]:.1f} at the start and {result.load[1]:.1f} at the end of the run "
                  f"on {os.cpu_count()} cores")
        if result.timing_check:
            a, b = result.timing_check
            timing += (f"; the default point took {a:.2f} s at the start and {b:.2f} s when timed again at the end "
                       f"({abs(b - a) / min(a, b) * 100:.0f}% apart): read time differences smaller than that as noise")
        lines += [timing + ".", ""]
    lines += ["PSNR (dB, peak 1) and SSIM (mean over sub-frames) against the dt = t_r ground truth, over the "
             "sub-frames some camera samples; seconds: the whole `reconstruct` call, compile excluded; "
             "ms/it: the ADMM loop alone; memory: the exact sum of the device buffers rsocl allocates "
             "(PoCL has no allocation counter). `interp3d`: per-pixel linear interpolation in time of the "
             "snapshots (no solver). T follows the capture (the 45° cameras, 5 to 8, read longer diagonals) "
             "and the scene is resampled to it by the protocol.", ""]
    head = ["point", "regularizer", "cameras", "ROI", "dt (µs)", "iterations", "inner", "dtype"]
    head += ["device"] if show_device else []
    head += ["T", "PSNR (dB)", "SSIM", "seconds", "ms/it", "memory (MiB)"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in result.rows:
        base = row["_point"].is_baseline
        cells = [row["label"], row["regularizer"], str(row["cameras"]), f"{row['roi']}", f"{row['dt_us']:.0f}",
                 "–" if base else str(row["iterations"]), "–" if row["tv_iterations"] is None else str(row["tv_iterations"]),
                 "–" if base else row["dtype"]]
        cells += [row["device"]] if show_device else []
        spi = row["seconds_per_iteration"]
        cells += [str(row["T"]), _num(row["psnr"], ".2f"), f"{row['ssim_mean']:.3f}", f"{row['seconds']:.3g}",
                  "–" if spi is None else f"{spi * 1e3:.1f}",
                  f"{row['peak_device_memory_bytes'] / 2**20:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "## What coarser dt and a tighter ROI buy", ""] + tradeoff_lines(result)
    speed, quality = picks(result)
    lines += ["", "## Which settings to pick", ""]
    if quality is None:
        lines.append("(no reconstruction of the default capture ran)")
    else:
        lines.append(f"- **pick for quality:** {quality['label']} — {_num(quality['psnr'], '.2f')} dB, "
                     f"SSIM {quality['ssim_mean']:.3f}, {quality['seconds']:.2f} s.")
        lines.append(f"- **pick for speed:** {speed['label']} — the fastest point of the Pareto front within "
                     f"{SPEED_PICK_DB:g} dB of the best: {_num(speed['psnr'], '.2f')} dB, SSIM {speed['ssim_mean']:.3f}, "
                     f"{speed['seconds']:.2f} s.")
        coarse = [r for r in (quality, speed) if r["_point"].dt_factor > 1]
        if coarse:
            k = coarse[0]["_point"].dt_factor
            lines.append(f"- a pick with dt = {k:g}·t_r delivers {1e-3 / (k * d.t_r):.1f} k sub-frames/s instead of "
                         f"{1e-3 / d.t_r:.1f} k; its PSNR, against the dt = t_r ground truth, says this scene has "
                         "little detail faster than that (a video with fewer frames than T is smooth in time).")
        interp = [r for r in result.rows if r["_point"].is_baseline and _comparable(r, d)]
        if interp:
            b = interp[0]
            lines.append(f"- the baseline `interp3d` gives {_num(b['psnr'], '.2f')} dB (SSIM {b['ssim_mean']:.3f}) in "
                         f"{b['seconds'] * 1e3:.1f} ms: the reconstruction buys "
                         f"{quality['psnr'] - b['psnr']:+.2f} dB at best, {speed['psnr'] - b['psnr']:+.2f} dB "
                         "with the speed pick.")
        recs = _reconstructions(result)
        front = [recs[i] for i in pareto_front(recs)]
        lines.append("- Pareto front of the reconstructions (PSNR against seconds, default capture), fastest first: "
                     + ", ".join(f"{r['label']} ({_num(r['psnr'], '.1f')} dB, {r['seconds']:.2g} s)" for r in front)
                     + ".")
    if result.notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in result.notes]
    return "\n".join(lines) + "\n"


def write_outputs(result: BenchResult, out) -> list:
    """Write ``bench.csv``, ``iterations.csv``, ``bench.md``, ``pareto.png``, ``cameras.png``, ``iterations.png``."""
    from . import bench_plots

    out = Path(os.fspath(out))
    out.mkdir(parents=True, exist_ok=True)
    files = [write_csv(out / "bench.csv", result.rows), write_iterations_csv(out / "iterations.csv", result.history())]
    md = out / "bench.md"
    with atomic_path(md) as tmp:
        tmp.write_text(markdown(result), encoding="utf-8")
    files.append(md)
    d = result.default
    comparable = [r for r in result.rows if _comparable(r, d)]
    recs = _reconstructions(result)
    title = f"{_scene_name(d.scene)}, {d.shape}×{d.shape}"
    files.append(bench_plots.pareto_plot(out / "pareto.png", result.rows, comparable,
                                         [recs[i] for i in pareto_front(recs)], title=title))
    files.append(bench_plots.cameras_plot(out / "cameras.png", _varied(result, "cameras"),
                                          _varied(result, "cameras", baseline=True), title=title))
    baseline = [r for r in comparable if r["_point"].is_baseline]
    files.append(bench_plots.iterations_plot(out / "iterations.png", result.history(), _varied(result, "iterations"),
                                             baseline[0]["psnr"] if baseline else None, title=title))
    return files


# ---------------------------------------------------------------------- command line
def add_bench_parser(subparsers):
    """Add ``rsocl bench`` to the ``rsocl`` command's sub-parsers."""
    import argparse

    p = subparsers.add_parser(
        "bench", help="sweep settings on a scene: PSNR/SSIM against seconds and memory; CSV, Markdown, plots",
        description="Measure what each setting buys: sweeps one knob at a time around a default point "
                    "(4 cameras, 64x64, 200 ADMM-TV iterations with 10 inner, float32, dt = t_r), with a "
                    "3-D interpolation baseline; writes bench.csv, iterations.csv, bench.md, pareto.png, "
                    "cameras.png and iterations.png.")
    p.add_argument("--scene", default="builtin", help="'builtin' or a video file (.npz key 'video', .tif, .gif)")
    p.add_argument("--sweep", action="append", default=None, metavar="NAME[=V1,V2,...]",
                   help=f"sweep to run, repeatable: {', '.join(SWEEPS)} (default: all; --quick: "
                        f"{', '.join(QUICK)})")
    p.add_argument("--quick", action="store_true",
                   help="32x32, 100 iterations, fewer values: about a minute on 2 CPU cores")
    p.add_argument("--out", default="rsocl-bench", help="output folder (default ./rsocl-bench)")
    p.add_argument("--device", default=None, help="OpenCL device for every point but the device sweep")
    p.add_argument("--t-e-us", type=float, default=180.0, help="exposure time, µs (default 180)")
    p.add_argument("--t-r-us", type=float, default=35.0, help="row readout time, µs (default 35)")
    p.add_argument("--lam", type=float, default=None, help="regularization weight (default rsocl's)")
    p.add_argument("--eta", type=float, default=None, help="ADMM penalty (default rsocl's)")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no table, only the result line")
    # testing and tuning knobs: the default point's grid side, cameras and iterations
    p.add_argument("--shape", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--cameras", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--iterations", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--tv-iterations", type=int, default=None, help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_bench)
    return p


def default_point(args) -> BenchPoint:
    """The default point of a ``rsocl bench`` command line."""
    from .reconstruct import DEFAULTS

    scene = args.scene
    if scene != "builtin" and not Path(scene).exists():
        raise FileNotFoundError(f"--scene: video file {scene!r} does not exist")
    quick = bool(args.quick)

    def pick(value, fallback):
        return fallback if value is None else value

    return BenchPoint(
        scene=scene, cameras=pick(args.cameras, 4), shape=pick(args.shape, 32 if quick else 64),
        iterations=pick(args.iterations, 100 if quick else DEFAULTS["iterations"]),
        tv_iterations=pick(args.tv_iterations, DEFAULTS["tv_iterations"]),
        device=_canonical_device(args.device), lam=pick(args.lam, DEFAULTS["lam"]), eta=pick(args.eta, DEFAULTS["eta"]),
        t_e=args.t_e_us * US, t_r=args.t_r_us * US)


def cmd_bench(args) -> int:
    """``rsocl bench``: run the sweeps and write the files."""
    default = default_point(args)
    sweeps = None if not args.sweep else [parse_sweep(s) for s in args.sweep]
    result = run_bench(default, sweeps, quick=args.quick, progress=not args.quiet)
    if not result.rows:
        raise ValueError("no point could be measured: " + "; ".join(result.notes))
    files = write_outputs(result, args.out)
    if not args.quiet:
        print(markdown(result))
        print("wrote " + ", ".join(str(f) for f in files))
    else:
        speed, quality = picks(result)
        text = f"{len(result.rows)} points in {result.seconds:.0f} s; wrote {Path(args.out) / 'bench.md'}"
        if quality is not None:
            text += (f"; quality: {quality['label']} {_num(quality['psnr'], '.2f')} dB; "
                     f"speed: {speed['label']} {_num(speed['psnr'], '.2f')} dB in {speed['seconds']:.2f} s")
        print(text)
    return 0
