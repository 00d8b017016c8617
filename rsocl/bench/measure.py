"""One point of ``rsocl bench``: simulate its capture, reconstruct it, measure it (:func:`run_point`).

How a point is measured
-----------------------
* **One capture, one ground truth.** The scene is turned into a datacube with the benchmark
  protocol (:func:`rsocl.model.scenes.load_scene`) on the *reference grid*: the rig of the point
  with ``dt = t_r`` (the finest sub-frame the cameras resolve). The snapshots are the
  float64 forward model of that datacube. They do not depend on the ``dt`` or the ROI the
  reconstruction chooses, exactly as with real cameras.
* **Coarser ``dt``** (``dt_factor`` × ``t_r``) reconstructs the same snapshots on fewer,
  longer sub-frames (the snapshots divided by ``dt_factor``, so that the datacube keeps the
  [0, 1] scale the solver's defaults assume); for the metrics each reference sub-frame takes
  the value of the coarse sub-frame that holds its centre, so the PSNR counts the temporal
  detail a coarse ``dt`` gives up.
* **A tighter ROI** is a centred ``roi × roi`` crop of the ``shape × shape`` grid
  (:meth:`rsocl.model.rig.Rig.crop`: the crop keeps the full sensor's row times, so sub-frames no
  cropped pixel samples drop out). Its snapshots and truth are the crop of the full ones; its
  metrics cover the crop's sampled sub-frames, and ``psnr_full_roi`` is the PSNR of the
  full-ROI reconstruction (same other knobs) over the same pixels and sub-frames.
* Metrics (:func:`rsocl.analysis.metrics.psnr`, :func:`rsocl.analysis.metrics.ssim`: peak 1) cover the
  sub-frames some camera samples (all ``T`` for an uncropped rig).
* **Time**: ``seconds`` is the wall time of the whole :func:`rsocl.solver.reconstruct` call (host to
  device transfers, the per-pixel inverse blocks, the iterations with their residual and
  PSNR monitoring, and the copy back); the first-time kernel compilation is excluded by one
  warm-up iteration per combination of rig, regularizer, dtype and device.
  ``seconds_per_iteration`` is the ADMM loop alone (``history["time"][-1] / iterations``).
* **Memory**: PoCL exposes no allocation counter, so ``peak_device_memory_bytes`` is the
  exact sum of the buffers rsocl allocates for the run (see :func:`device_memory_bytes`).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, replace

import numpy as np

from rsocl.bench.memory import device_memory_bytes
from rsocl.bench.point import US, BenchPoint, _scene_name
from rsocl.model.interpolation import interp3d

__all__ = ["run_point"]


def _device_of(spec):
    from rsocl.device.context import get_device

    return get_device(spec)


def _data(point: BenchPoint, cache: dict):
    """Reference rig, truth and snapshots of the point's capture (cached), and the metric window."""
    from rsocl.model.operator import RollingShutterOperator
    from rsocl.model.scenes import load_scene

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
            truth = truth[: ref.T, y : y + h, x : x + w]
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
    from rsocl.analysis.metrics import psnr, ssim

    est, tru = estimate_ref[window], truth_ref[window]
    mean_ssim, per = ssim(est, tru, data_range=1.0)
    return psnr(est, tru, data_range=1.0), mean_ssim, per


def _row(point: BenchPoint, rig, window, **values) -> dict:
    row = {
        "scene": _scene_name(point.scene),
        "sweep": "",
        "label": "",
        "regularizer": point.regularizer,
        "cameras": point.cameras,
        "shape": point.shape,
        "roi": point.roi_size,
        "dt_factor": point.dt_factor,
        "dt_us": rig.dt / US,
        "iterations": point.iterations,
        "tv_iterations": point.tv_iterations,
        "dtype": point.dtype,
        "device": "",
        "lam": point.lam,
        "eta": point.eta,
        "T": rig.T,
        "T_se": rig.T_se,
        "subframes_evaluated": window.stop - window.start,
        "psnr_full_roi": None,
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
    from rsocl.analysis.metrics import psnr

    y, x, h, w = point.crop_box()
    return psnr(full[window, y : y + h, x : x + w], truth_ref[window], data_range=1.0)


def run_point(point: BenchPoint, truth_cache: dict | None = None, with_history: bool = False) -> dict:
    """Measure one point; returns its row (see :data:`COLUMNS`).

    ``truth_cache`` (a dict, reused across points) keeps scenes, snapshots, warm-up marks and
    the full-ROI reconstructions the crops are compared with. The timed run is the one a
    user makes (no ground truth, so no per-iteration PSNR to wait for); ``with_history``
    adds an untimed run with the truth, whose history (PSNR per iteration) goes to
    ``_history``.
    """
    from rsocl.solver.reconstruct import reconstruct

    cache = {} if truth_cache is None else truth_cache
    ref, truth_ref, g, window = _data(point, cache)
    if point.is_baseline:
        start = time.perf_counter()
        estimate = interp3d(g, ref)
        seconds = time.perf_counter() - start
        psnr_value, mean_ssim, per = _metrics(estimate, truth_ref, window)
        if point.roi is None:
            cache[("cube", point)] = estimate
        return _row(
            point,
            ref,
            window,
            psnr=psnr_value,
            ssim_mean=mean_ssim,
            ssim_per_subframe=per,
            seconds=seconds,
            seconds_per_iteration=None,
            peak_device_memory_bytes=0,
            device="host (NumPy)",
            dtype="float64",
            iterations=0,
            tv_iterations=None,
            dt_factor=1.0,
            dt_us=ref.dt / US,
            psnr_full_roi=_full_roi_psnr(point, cache, window, truth_ref),
            _history=None,
        )

    rig = point.rig()
    truth_own = _own_grid_truth(truth_ref, rig, ref)
    # a sub-frame of k*t_r integrates k times the light of one of t_r: scale the snapshots so
    # that the datacube stays in [0, 1] (the scale rsocl's lam and eta assume, README)
    g_scaled = g * (ref.dt / rig.dt)
    tuned = point.tune or point.quality is not None
    kwargs: dict = dict(
        regularizer=point.regularizer,
        lam=None if tuned else point.lam,
        eta=point.eta,
        tv_iterations=point.tv_iterations,
        device=point.device,
        dtype=point.dtype,
        tune=tuned,
    )
    if point.quality is not None:
        kwargs["quality"] = point.quality
    iterations = None if point.quality is not None else point.iterations  # a rung runs its own
    warm = ("warm",) + tuple(v for f, v in asdict(point).items() if f not in ("scene", "iterations", "lam", "eta"))
    if warm not in cache:  # the programs built, and a first launch of each kernel (PoCL compiles then)
        reconstruct(g_scaled, rig, iterations=3 if iterations is None else min(iterations, 3), **kwargs)
        cache[warm] = True
    start = time.perf_counter()
    result = reconstruct(g_scaled, rig, iterations=iterations, **kwargs)
    seconds = time.perf_counter() - start
    history = None
    if with_history:
        history = reconstruct(g_scaled, rig, iterations=iterations, truth=truth_own, **kwargs).history
    estimate = result.datacube.astype(np.float64)[_reference_index(rig, ref)]
    psnr_value, mean_ssim, per = _metrics(estimate, truth_ref, window)
    if point.roi is None:
        cache[("cube", point)] = estimate
    memory = device_memory_bytes(
        rig,
        point.regularizer,
        point.dtype,
        device=point.device,
        tv_iterations=point.tv_iterations,
        with_truth=False,
        tuned=result.params["tuning"] is not None,
    )
    return _row(
        point,
        rig,
        window,
        psnr=psnr_value,
        ssim_mean=mean_ssim,
        ssim_per_subframe=per,
        seconds=seconds,
        iterations=result.iterations,
        lam=result.params["lam"],
        eta=result.params["eta"],
        regularizer_options=result.params["regularizer_options"],
        seconds_per_iteration=float(result.history["time"][-1]) / result.iterations,
        peak_device_memory_bytes=memory,
        device=result.params["device"],
        psnr_full_roi=_full_roi_psnr(point, cache, window, truth_ref),
        _history=history,
    )
