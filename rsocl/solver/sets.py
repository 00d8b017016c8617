"""Many snapshot sets of one rig: batches sized to the device, run one batch after another.

:func:`batch_size` is the largest batch whose arrays fit the device's memory (and its largest
buffer); :func:`reconstruct_sets` reconstructs ``S`` sets ``(S, K, m, n)`` in batches of that size
with :func:`rsocl.solver.reconstruct.reconstruct` and returns one batch :class:`Result` of all of
them. A batch fills a device that one set leaves idle (a GPU) and shares each launch's overhead
among its sets; on a CPU device it is also kept within :data:`CACHE_FRACTION` of the device's
global memory cache (the measurements behind these limits: ``docs/solver-notes.md``, batch sizes).
"""

from __future__ import annotations

import time

import numpy as np

from rsocl.common import validation as check
from rsocl.common.hints import ArrayLike, Callback, DTypeLike, Options, PerSet
from rsocl.device.context import Device, get_device
from rsocl.model.rig import Rig
from rsocl.solver.crossval import Tuning
from rsocl.solver.inverse import own_inverses
from rsocl.solver.ladder import DEFAULT_QUALITY
from rsocl.solver.memory import batch_memory
from rsocl.solver.pipeline import prepare, tune_and_run
from rsocl.solver.problem import check_problem, check_representable
from rsocl.solver.regularizer import Regularizer
from rsocl.solver.request import make_regularizer, make_request
from rsocl.solver.result import Result

__all__ = ["batch_size", "reconstruct_sets", "MAX_BATCH", "GPU_BATCH_VOXELS", "CACHE_FRACTION"]

#: The largest batch :func:`batch_size` proposes on a CPU device unless told otherwise: a larger
#: batch delays the first results; 32 sets of the paper configuration are 4.4 M voxels per launch.
MAX_BATCH = 32
#: On a device other than a CPU (a GPU), a batch may hold more than :data:`MAX_BATCH` sets, up to
#: this many voxels in all: one set leaves such a device idle between launches, and sets per second
#: keep rising well past 32 sets (``docs/solver-notes.md``, batch sizes).
GPU_BATCH_VOXELS = 2**24
#: On a CPU device, a batch's arrays take at most this share of the global memory cache
#: (``CL_DEVICE_GLOBAL_MEM_CACHE_SIZE``; at least one set; ``docs/solver-notes.md``, batch sizes).
CACHE_FRACTION = 0.75


def batch_size(
    rig: Rig,
    regularizer: str | Regularizer = "tv",
    *,
    sets: int | None = None,
    dtype: DTypeLike = "float32",
    device: str | Device | None = None,
    projection: str = "exact",
    truth: bool = False,
    own_inverse: bool = False,
    start: bool = False,
    limit: int | None = None,
    memory_fraction: float = 0.8,
    regularizer_options: Options | None = None,
    cache_fraction: float = CACHE_FRACTION,
) -> int:
    """The largest number of sets of ``rig`` that one batch may hold on ``device``.

    Parameters
    ----------
    rig : Rig
    regularizer, regularizer_options
        As for :func:`rsocl.solver.reconstruct.reconstruct`.
    sets : int or None
        Sets to reconstruct: the batch holds no more than that.
    dtype, device, projection
        As for ``reconstruct``.
    truth : bool
        Whether a ground truth goes with every set (one more datacube each).
    own_inverse : bool
        Whether every set has its own projection blocks (per-set ``eta`` of the exact projection).
    start : bool
        Whether every set has a start cube beside its iterate (a given ``x0``, or the self-tuned
        run's ``interp3d`` start): one more datacube each, counted against the global memory; it
        is read once, so the cache limit leaves it out.
    limit : int or None
        At most this many sets. None (default): :data:`MAX_BATCH` on a CPU device; on other devices
        (GPUs) the most sets within :data:`GPU_BATCH_VOXELS` voxels, and at least :data:`MAX_BATCH`.
    memory_fraction : float
        Share of the device's global memory the batch may take, in (0, 1].
    cache_fraction : float or None
        On a CPU device, share of its global memory cache the batch may take (at least one set), in
        (0, 1]; default :data:`CACHE_FRACTION`. None: no cache limit (and none on other devices).

    Raises
    ------
    ValueError
        When not even one set fits (the message gives the sizes), or on a bad argument.
    """
    if not isinstance(rig, Rig):
        raise ValueError(f"rig must be an rsocl.Rig, got {type(rig).__name__}")
    if limit is not None:
        limit = check.positive_int("limit", limit)
    if sets is not None:
        sets = check.positive_int("sets", sets)
    fraction = check.in_range("memory_fraction", memory_fraction, 1e-6, 1.0)
    if cache_fraction is not None:
        cache_fraction = check.in_range("cache_fraction", cache_fraction, 1e-6, 1.0)
    projection = check.choice("projection", projection, {"exact", "paper"})
    dev = get_device(device)
    dt = dev.real_dtype(dtype)
    reg = make_regularizer(regularizer, regularizer_options)
    solved = rig.sampled_range()
    cube = (solved.stop - solved.start,) + rig.shape
    if limit is None:
        limit = MAX_BATCH if dev.is_cpu else max(MAX_BATCH, GPU_BATCH_VOXELS // int(np.prod(cube)))
    if sets is not None:
        limit = min(limit, sets)

    def need(b, with_start=bool(start)):
        return batch_memory(
            cube, rig.n_channels, dt, reg, projection, b, truth=truth, own_inverse=own_inverse, start=with_start
        )

    largest, total = need(1)
    dev.check_fits(
        f"ADMM with {reg.name} on T={cube[0]} x {rig.shape[0]} x {rig.shape[1]} ({dt.name})", largest, total_bytes=total
    )
    budget = fraction * dev.global_mem_bytes
    cache = None
    if cache_fraction is not None and dev.is_cpu and dev.cache_bytes > 0:
        cache = cache_fraction * dev.cache_bytes

    def fits(b):
        largest, total = need(b)
        return largest <= dev.max_alloc_bytes and total <= budget and (cache is None or need(b, False)[1] <= cache)

    best, above = 1, limit + 1  # memory grows with the batch: bisect for the largest that fits
    while above - best > 1:
        middle = (best + above) // 2
        best, above = (middle, above) if fits(middle) else (best, middle)
    return best


def reconstruct_sets(
    g: ArrayLike,
    rig: Rig,
    *,
    batch: int | None = None,
    lam: PerSet | None = None,
    eta: PerSet | None = None,
    x0: ArrayLike | str | None = None,
    truth: ArrayLike | None = None,
    progress: bool = False,
    device: str | Device | None = None,
    dtype: DTypeLike = "float32",
    regularizer: str | Regularizer = "tv",
    regularizer_options: Options | None = None,
    projection: str = "exact",
    iterations: int | str | None = None,
    tv_iterations: int | None = None,
    callback: Callback | None = None,
    tol: float | None = None,
    saturation: float | None = None,
    tune: bool | Tuning = True,
    blend: float | None = None,
    quality: str = DEFAULT_QUALITY,
) -> Result:
    """Reconstruct ``S`` sets ``g`` ``(S, K, m, n)`` in batches of ``batch`` sets (default: :func:`batch_size`).

    ``lam``/``eta`` are one number or one per set; ``x0``/``truth`` one ``(T, m, n)`` cube for every set
    or ``(S, T, m, n)``; the other arguments are :func:`rsocl.solver.reconstruct.reconstruct`'s, checked
    once for every batch (:func:`~rsocl.solver.request.make_request`), ``quality`` included. A self-tuned
    run (the default) chooses its values on the first set, and every later batch runs with them, each set from its own
    ``interp3d`` start. Returns one batch :class:`Result` of all ``S`` sets: datacube ``(S, T, m, n)``,
    every history entry ``(iterations, S)`` (``time`` counts from the start of each set's batch; with
    ``tol`` a batch that stopped early is padded with NaN), ``params["batch"]`` the batch size (at most the
    number of sets). Every set's snapshots are checked, and warned of, once before the first batch runs.
    """
    g = np.asarray(g)
    if g.ndim != 4 or g.shape[0] < 1:
        raise ValueError(f"g must hold S >= 1 sets, (S, K, m, n), got shape {g.shape}")
    count = g.shape[0]
    for name, value in {"lam": lam, "eta": eta}.items():
        if value is not None and np.ndim(value) == 1 and np.size(value) != count:
            raise ValueError(f"{name} must have one value per set: {count} sets, got {np.size(value)}")
    cubes = {"x0": x0, "truth": truth}
    for name, cube in cubes.items():
        if cube is not None and np.ndim(cube) == 4 and np.shape(cube)[0] != count:
            raise ValueError(f"{name} must have one cube per set: {count} sets, got {np.shape(cube)[0]}")
    request = make_request(
        rig,
        regularizer,
        sets=count,
        x0_given=x0 is not None,
        iterations=iterations,
        lam=lam,
        eta=eta,
        tv_iterations=tv_iterations,
        projection=projection,
        tol=tol,
        callback=callback,
        dtype=dtype,
        device=device,
        regularizer_options=regularizer_options,
        tune=tune,
        blend=blend,
        quality=quality,
    )  # the bar counts sets, not each batch's iterations
    if batch is None:
        if saturation is not None:
            check.positive("saturation", saturation, "(snapshot units)")
        own = own_inverses(projection, 0.0 if eta is None else eta, None, count)  # saturated pixels stay in the blocks
        batch = batch_size(
            rig,
            request.regularizer,
            sets=count,
            dtype=dtype,
            device=device,
            projection=projection,
            truth=truth is not None,
            own_inverse=own,
            start=x0 is not None or tune is not False,
        )
    batch = min(check.positive_int("batch", batch), count)
    _check_every_set(g, rig, x0, truth, saturation, request.dtype)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=count, desc="sets", unit="set", leave=False, disable=None)
    results = []
    started = time.perf_counter()
    try:
        for start in range(0, count, batch):
            part = slice(start, min(start + batch, count))
            pick = {k: (np.asarray(v)[part] if v is not None and np.ndim(v) == 4 else v) for k, v in cubes.items()}
            with request.regularizer.in_use:  # an instance in use elsewhere: its turn first
                # the data's warnings were given for every set above: not again (by an argument, not a warning
                # filter, which would be every thread's)
                problem = check_problem(
                    g[part], rig, x0=pick["x0"], truth=pick["truth"], saturation=saturation, warn=False
                )
                results.append(tune_and_run(prepare(request.for_sets(part), problem), started))
            if start == 0 and results[0].params.get("tuning"):
                # one capture, one setting: the first batch's choice serves the later batches
                request = request.with_tuning(Tuning.from_params(results[0].params["tuning"]))
            if bar is not None:
                bar.update(part.stop - part.start)
    finally:
        if bar is not None:
            bar.close()
    return _joined(results, batch)


def _check_every_set(g, rig, x0, truth, saturation, dtype) -> None:
    """Every set's snapshots (and ``x0``, ``truth``) checked, and warned of, once before the first batch runs: a
    set holding NaN or inf is refused naming it, instead of after the batches before it ran."""
    if g.dtype.kind == "f":
        finite = np.isfinite(g).reshape(g.shape[0], -1).all(axis=1)
        if not finite.all():
            bad = np.flatnonzero(~finite)
            more = " ..." if bad.size > 10 else ""
            raise ValueError(
                f"g: set(s) {bad[:10].tolist()}{more} of {g.shape[0]} hold NaN or inf values; all values must be finite"
            )
    check_representable(check_problem(g, rig, x0=x0, truth=truth, saturation=saturation), dtype)


def _joined(results, batch) -> Result:
    """One batch :class:`Result` from the results of consecutive batches."""
    longest = max(r.iterations for r in results)
    history = {}
    for key in results[0].history:
        columns = []
        for r in results:
            values = np.asarray(r.history[key], dtype=np.float64)
            pad = np.full((longest - len(values),) + values.shape[1:], np.nan)
            columns.append(np.concatenate([values, pad]))
        history[key] = np.concatenate(columns, axis=1)
    params = dict(results[0].params)
    for key in ("lam", "eta", "saturated_pixels", "static_pixels"):
        if key not in params:
            continue
        per_set = [r.params[key] for r in results]
        if any(isinstance(v, list) for v in per_set):
            params[key] = [x for r, v in zip(results, per_set) for x in (v if isinstance(v, list) else [v] * r.batch)]
    params["sets"] = sum(r.batch for r in results)
    params["seconds"] = results[-1].params["seconds"]  # each counts from the start of the whole run
    params["search_seconds"] = sum(r.params["search_seconds"] for r in results)
    params["iterations_run"] = max(r.params["iterations_run"] for r in results)
    params["batch"] = batch
    datacube = np.concatenate([r.datacube for r in results])
    return Result(datacube, history, results[0].rig, params)
