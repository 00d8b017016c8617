"""Total-variation regularizer: Chambolle's projection algorithm as OpenCL kernels."""

from __future__ import annotations

import numpy as np

from rsocl.device import pool
from rsocl.device.context import device_for_queue
from rsocl.device.launch import batch_launches, voxel_launches
from rsocl.device.program import c_type
from rsocl.solver.regularizer import Option, Regularizer
from rsocl_plugins import tv_fused, tv_plain

__all__ = ["TV"]

#: Work items per work group of the TV kernels (blocks of whole rows, rsocl.device.launch.voxel_launches),
#: at most (measured: docs/regularizer_defaults.md).
GROUP = 512

#: Default of the ``step`` option: Chambolle's step as a fraction of scikit-image's ``1 / (2 (2 + w²))``
#: (see :class:`TV`).
STEP = 0.9

#: Default of the ``fused`` option: the device's choice, :func:`device_fused`.
FUSED = -1

#: ``fused`` of the device's choice on a device that is not a CPU. The plain path, whose folded passes
#: (the ADMM's dual update in the TV's last primal step, that step and ``u = f - b`` in the projection) are fewer
#: launches: whole reconstructions on an NVIDIA GPU ran slower with the fused TV at every batch size
#: (docs/gpu/tv_fused.md). ``benchmarks/launches.py`` measures both paths on a device.
GPU_FUSED = 0


#: Default of the ``one_launch`` option: the device's choice, :func:`device_one_launch`.
ONE_LAUNCH = -1

#: ``one_launch`` of the device's choice on a device that is not a CPU: one launch per Chambolle
#: iteration (``tv_step``), which halves the plain path's launches and the bytes it moves per iteration;
#: on a CPU device its recomputed neighbours cost more than the launch. Measured, with 2 (``tv_step2``)
#: against it: docs/regularizer_defaults.md.
GPU_ONE_LAUNCH = 1

#: On a device that is not a CPU, the plain path's first two Chambolle iterations in one launch
#: (``tv_first2``, :mod:`rsocl_plugins.tv_plain`) where it takes one launch per iteration or per two, on
#: batches of at most :data:`GPU_FIRST_TWO_VOXELS` voxels: a launch less per call, and only the first
#: iteration's bytes. Its thirteen dual steps per voxel cost more device time than the launch it saves on
#: a CPU device and on larger batches. ``benchmarks/launches.py`` and ``benchmarks/peer.py`` time both
#: (docs/gpu.md).
GPU_FIRST_TWO = True

#: The most voxels (sets × sub-frames × rows × columns) of a batch whose TV takes ``tv_first2`` under
#: :data:`GPU_FIRST_TWO`: where a GPU's loop is still bound by its launches (measurements: docs/gpu.md).
GPU_FIRST_TWO_VOXELS = 1 << 19


def device_one_launch(device) -> int:
    """``one_launch`` that the default (:data:`ONE_LAUNCH`) stands for on ``device`` (an rsocl Device): 0 on a
    CPU device, :data:`GPU_ONE_LAUNCH` on others."""
    return 0 if device.is_cpu else GPU_ONE_LAUNCH


def device_fused(device) -> int:
    """``fused`` that the default (:data:`FUSED`) stands for on ``device`` (an rsocl Device): 0 on a CPU
    device, :data:`GPU_FUSED` on others."""
    return 0 if device.is_cpu else GPU_FUSED


def edge_weights(n: int, dtype) -> np.ndarray:
    """``xnext`` of ``tv.cl``: 1 where a column has a right neighbour (x < n - 1), else 0."""
    return (np.arange(n) < n - 1).astype(dtype)


def launches(prog, device, T: int, m: int, n: int):
    """Exact launch grids of the TV kernels of ``prog`` (no bounds test in them), in work groups
    of whole rows up to :data:`GROUP`, capped by what ``device`` (an rsocl Device) and the kernels allow."""
    kernels = (prog.tv_primal, prog.tv_dual, prog.tv_dual_first, prog.tv_primal_update, prog.tv_step, prog.tv_first2)
    group = device.group_limit(*kernels, cap=GROUP)
    return voxel_launches(T, m, n, group=group, max_x=device.max_work_item_sizes[0])


class TV(Regularizer):
    """Isotropic total variation: Chambolle's projection, as ``skimage.restoration.denoise_tv_chambolle``.

    The ADMM's prior step ``theta = argmin_x ½‖x - v‖² + weight·TV(x)`` on the device, ``eps=0``.
    A batch ``(B, T, m, n)`` is denoised in the launches of one set, each set on its own (no
    temporal difference across a set boundary) with its own weight.

    Options
    -------
    iterations : int
        Chambolle iterations per call, 1..100000 (default 10).
    temporal_weight : float
        Weight of the temporal difference, 0..1000: ``1`` is scikit-image's 3-D TV, ``0`` 2-D TV on
        each sub-frame (default 3). The sets of one batch may each have their own (all above 0, or all 0):
        :meth:`for_sets <rsocl.solver.regularizer.Regularizer.for_sets>`, :meth:`temporal_weights`.
    step : float
        Dual step ``tau`` as a fraction of scikit-image's ``1 / (2 (2 + w²))`` for temporal weight
        ``w``, 0.01..1 (default 0.9; ``1`` is scikit-image's step, at the edge of stability).
    fused : int
        Most iterations per launch on tiles held in local memory, with the ADMM's dual update folded
        into the last launch (:mod:`rsocl_plugins.tv_fused`, same result to float rounding);
        0: the plain path; -1..1000, default -1: the device's choice (:func:`device_fused`: the plain path
        on every device, :data:`GPU_FUSED`). A device whose local memory is too small for tiles that
        save bytes takes the plain path.
    one_launch : int
        The plain path's launches: 1: one per Chambolle iteration, from one copy of the dual into another
        (:mod:`rsocl_plugins.tv_plain`); 2: one per two iterations (about 13 times the arithmetic per
        launch); 0: two per iteration on one copy; -1..2, default -1: the device's choice
        (:func:`device_one_launch`: two on a CPU device, one on others). Same result to float rounding.

    Examples
    --------
    >>> import numpy as np, pyopencl.array as cla, rsocl
    >>> from rsocl_plugins.tv import TV
    >>> queue = rsocl.get_device().queue
    >>> x = cla.to_device(queue, np.random.default_rng(0).random((5, 8, 8), dtype=np.float32))
    >>> y = TV(temporal_weight=1.0).denoise(x, 0.1).get()        # weight: lam / eta in the ADMM
    >>> y.shape, bool(y.std() < x.get().std())
    ((5, 8, 8), True)

    In a reconstruction: ``rsocl.reconstruct(g, rig, regularizer="tv", regularizer_options=
    {"temporal_weight": 0.0})`` (2-D TV).

    The defaults and the measurements behind them: ``docs/regularizer_defaults.md``.
    """

    name = "tv"
    batched = True
    tunable = {"temporal_weight": (1.0, 3.0, 10.0, 30.0)}
    per_set_options = ("temporal_weight",)
    #: One camera (one frame or several): temporal weight 10, not searched (docs/regularizer_defaults.md).
    one_snapshot = {"temporal_weight": 10.0}
    options = {
        "iterations": Option(10, "iterations", "Chambolle iterations per denoising call", 1, 100000),
        "temporal_weight": Option(
            3.0, "", "weight of the temporal difference (0: 2-D per sub-frame, 1: scikit-image's 3-D TV)", 0, 1e3
        ),
        "step": Option(
            STEP,
            "",
            "Chambolle step as a fraction of scikit-image's 1/(2(2 + w^2)) (1: scikit-image's step)",
            0.01,
            1.0,
        ),
        "fused": Option(
            FUSED,
            "iterations",
            "most Chambolle iterations per launch on tiles in local memory "
            "(0: the plain path, two launches per iteration; "
            "-1: the device's choice)",
            -1,
            1000,
        ),
        "one_launch": Option(
            ONE_LAUNCH,
            "",
            "the plain path in one launch per Chambolle iteration on two copies of the dual (1), "
            "in one per two iterations (2), in two on one copy (0), or as the device chooses (-1)",
            -1,
            2,
        ),
    }

    #: Both paths take the ADMM's dual update into their last launch (:meth:`denoise_and_update`).
    fuses_dual = True

    @property
    def planes(self) -> int:
        return 3 if self.temporal_weight > 0 else 2

    def workspace_bytes(self, shape, dtype, device=None) -> int:
        # the dual p (planes of the input's size; two copies on the fused path and on the one-launch plain
        # path, which read one and write the other) and xnext (n values); the device's choices (-1)
        # counted for ``device``, or as on a CPU without one
        fused = self.fused if self.fused >= 0 else (0 if device is None else device_fused(device))
        one = self.one_launch if self.one_launch >= 0 else (0 if device is None else device_one_launch(device))
        copies = 2 if fused > 0 or one > 0 else 1
        return (copies * self.planes * int(np.prod(shape)) + int(shape[-1])) * np.dtype(dtype).itemsize

    def temporal_weights(self, sets: int) -> np.ndarray:
        """The temporal weight of each of ``sets`` sets (float64; 0 for 2-D TV): the option's, or one per
        set for an instance of :meth:`for_sets`.

        Raises ValueError when the instance holds weights for another number of sets.
        """
        own = self.__dict__.get("_set_weights")
        if own is None:
            return np.full(sets, float(self.temporal_weight) if self.planes == 3 else 0.0)
        if len(own) != sets:
            raise ValueError(f"{self.name}: this instance holds temporal weights for {len(own)} sets, got {sets}")
        return np.array(own, dtype=np.float64)

    @classmethod
    def _for_sets(cls, instances):
        """Per-set temporal weights (:meth:`Regularizer.for_sets`), all 3-D or all 2-D."""
        weights = [float(r.temporal_weight) for r in instances]
        if len({w > 0 for w in weights}) > 1:
            return None  # 2-D and 3-D sets have different kernels
        combined = cls(**instances[0].values)
        combined.__dict__["_set_weights"] = tuple(weights)
        return combined

    def _steps(self, queue, weights, dtype):
        """The per-set ``(tau, tau / weight, temporal weight)`` of ``tv.cl`` on the device (``tau`` and
        ``tau / weight`` 0 for weight 0; ``tau / weight`` at most the largest finite value of ``dtype``, so
        that a weight too small for it still gives ``0 · tau / weight = 0`` at a zero gradient)."""
        w = np.asarray(weights, dtype=np.float64)
        wt = self.temporal_weights(len(w))
        cache = self.__dict__.setdefault("_step_cache", {})
        key = (w.tobytes(), np.dtype(dtype).str, queue.int_ptr)
        if key not in cache:
            if len(cache) > 8:
                cache.clear()
            on = w > 0
            tau = float(self.step) / (2.0 * (2.0 + wt * wt))
            with np.errstate(over="ignore"):
                ratio = np.minimum(tau / np.where(on, w, 1.0), float(np.finfo(dtype).max))
            steps = np.stack([np.where(on, tau, 0.0), np.where(on, ratio, 0.0), wt], axis=1)
            cache[key] = pool.to_device(queue, steps.astype(dtype).ravel())
        return cache[key]

    def _program(self, x, name):
        temporal = int(self.temporal_weight > 0)
        return device_for_queue(x.queue).program([name], REAL=c_type(x.dtype), TEMPORAL=temporal)

    def fuses_dual_on(self, device) -> bool:
        """Whether an ADMM on ``device`` should leave its dual update to :meth:`denoise_and_update`: on the
        fused path, and on a device that is not a CPU (one launch less per iteration); on a CPU the
        plain path's separate passes are faster (docs/launches.md)."""
        fused = device_fused(device) if self.fused < 0 else self.fused
        return fused > 0 or not device.is_cpu

    def deferred_primal_on(self, device) -> dict | None:
        """:meth:`Regularizer.deferred_primal_on <rsocl.solver.regularizer.Regularizer.deferred_primal_on>`:
        ``{"TEMPORAL": 0 or 1}`` on a device that is not a CPU, on the plain path with 2 iterations or more
        (its last launch, ``tv_primal_update``, goes to the ADMM's projection: one launch less per iteration)."""
        fused = device_fused(device) if self.fused < 0 else self.fused
        if device.is_cpu or fused > 0 or self.iterations < 2:
            return None
        return {"TEMPORAL": int(self.temporal_weight > 0)}

    def fused_plan(self, x):
        """The :class:`~rsocl_plugins.tv_fused.FusedPlan` for device array ``x`` (None: the plain path)."""
        import pyopencl as cl

        cache = self.__dict__.setdefault("_plans", {})
        dev = device_for_queue(x.queue)
        fused = device_fused(dev) if self.fused < 0 else self.fused
        if fused == 0:
            return None
        limits = (dev.local_mem_bytes, dev.max_work_group_size, dev.max_work_item_sizes)
        key = (x.shape, x.dtype.str, x.queue.int_ptr, self.iterations, self.fused, self.planes, limits)
        if key not in cache:
            kernel = self._program(x, "tv_fused.cl").tv_fused
            reserved = int(kernel.get_work_group_info(cl.kernel_work_group_info.LOCAL_MEM_SIZE, dev.device))
            shape = x.shape if x.ndim == 4 else (1,) + x.shape
            # a CPU runs a work group's items as loops split at barriers: one item per group runs
            # each row of a tile as one contiguous (vectorised) loop
            found = tv_fused.plan(
                shape,
                x.dtype.itemsize,
                self.iterations,
                fused,
                self.planes == 3,
                local_bytes=dev.local_mem_bytes - reserved,
                group=1 if dev.is_cpu else dev.group_limit(kernel),
                max_items=dev.max_work_item_sizes,
            )
            cache[key] = found
        return cache[key]

    def _buffers(self, x, copies):
        """The dual p (``copies`` of it) and xnext, once per shape, dtype and queue."""
        cache = self.__dict__.setdefault("_dual", {})
        key = (x.shape, x.dtype.str, self.planes, copies, x.queue.int_ptr)
        if key not in cache:
            cache.clear()
            cache[key] = (
                [pool.empty(x.queue, (self.planes,) + x.shape, x.dtype) for _ in range(copies)],
                pool.to_device(x.queue, edge_weights(x.shape[-1], x.dtype)),
            )
        return cache[key]

    def _denoise(self, x, weight, out):
        return self._run(x, weight, out, None)

    def denoise_and_update(self, u, weight, theta, b, f, dual):
        """``theta = denoise(u, weight)``, then the ADMM's next dual update: ``b = theta - u`` and
        ``f = theta + b`` in the sets where ``dual`` (a device int array, one per set) is set, else
        ``f = theta``. That is the last launch's work (the fused path's last launch, the plain path's last
        primal step); with one Chambolle iteration, one more pass."""
        weights = self.check_weights(weight, u.shape[0] if u.ndim == 4 else None)
        self._check_like(u, theta=theta, b=b, f=f)
        return self._run(u, weights if u.ndim == 4 else float(weights[0]), theta, (b, f, dual))

    def _check_like(self, u, **arrays):
        """Raise unless every one of ``arrays`` has ``u``'s shape and dtype and ``theta`` (the output, when
        given) is another buffer than ``u``."""
        for name, array in arrays.items():
            if array.shape != u.shape or array.dtype != u.dtype:
                raise ValueError(f"{self.name}: {name} must match u ({u.shape}, {u.dtype}), got {array.shape}")
        if "theta" in arrays and arrays["theta"].base_data.int_ptr == u.base_data.int_ptr:
            raise ValueError("out must be another buffer than x (every TV iteration reads x)")

    def bind(self, x, weight, out, dual=None, defer=False):
        """:meth:`Regularizer.bind <rsocl.solver.regularizer.Regularizer.bind>`: on the plain path, the
        arguments checked and the launches bound once (:mod:`rsocl_plugins.tv_plain`); a call then only
        enqueues them, without the last one with ``defer`` and ``dual`` (:meth:`deferred_primal_on`)."""
        weights, out = self._checked(x, weight, out)
        self._check_like(x, theta=out, **({} if dual is None else {"b": dual[0], "f": dual[1]}))
        plain = self.iterations > 1 and (self.fused == 0 or self.fused_plan(x) is None)
        if not plain or (dual is None and not np.any(weights)):
            return super().bind(x, weight, out, dual)
        sets = x.shape[0] if x.ndim == 4 else 1
        steps = self._steps(x.queue, np.broadcast_to(weights, (sets,)), x.dtype)
        prog, grids, arrays, plan = self._plain_parts(x, steps, out, dual)
        return tv_plain.Bound(x.queue, prog, grids, arrays, self.iterations, defer=defer, **plan)

    def _run(self, x, weight, out, dual):
        self._check_like(x, theta=out)
        sets = x.shape[0] if x.ndim == 4 else 1
        steps = self._steps(x.queue, np.broadcast_to(weight, (sets,)), x.dtype)
        plan = self.fused_plan(x) if self.fused != 0 else None
        if plan is not None:
            buffers, _ = self._buffers(x, max(1, plan.p_buffers()))
            adm = dual if dual is not None else (out, out, self._no_dual(x.queue))
            return tv_fused.enqueue(
                self._program(x, "tv_fused.cl"), plan, x, steps, out, buffers, adm, dual is not None
            )
        self._run_plain(x, steps, out, dual)
        if dual is not None and self.iterations == 1:  # no primal step to take it
            b, f, on = dual
            prog = self._program(x, "tv_fused.cl")
            per_set = x.size // sets
            dev = device_for_queue(x.queue)
            for gsize, lsize, offset in batch_launches(per_set, sets, dev.group_limit(prog.dual_from_u, cap=64)):
                prog.dual_from_u(
                    x.queue,
                    gsize,
                    lsize,
                    out.data,
                    x.data,
                    b.data,
                    f.data,
                    on.data,
                    np.int32(per_set),
                    global_offset=offset,
                )
        return out

    def one_launch_on(self, device) -> int:
        """``one_launch`` of the plain path on ``device`` (:func:`device_one_launch` for -1): 0 (two launches
        per Chambolle iteration), 1 (one) or 2 (one per two iterations)."""
        return int(device_one_launch(device) if self.one_launch < 0 else self.one_launch)

    def _plain_parts(self, x, steps, out, dual):
        """``(prog, grids, arrays, plan)``: the arguments of :func:`rsocl_plugins.tv_plain.sequence` (and
        :class:`~rsocl_plugins.tv_plain.Bound`) but ``iterations``, ``plan`` its keywords ``one_launch`` and
        ``first2`` (:data:`GPU_FIRST_TWO` on a device that is not a CPU, for ``x`` of at most
        :data:`GPU_FIRST_TWO_VOXELS` voxels)."""
        dev = device_for_queue(x.queue)
        one = self.one_launch_on(dev)
        prog = self._program(x, "tv.cl")
        grids = self.__dict__.setdefault("_grids", {})
        key = (x.shape, x.dtype.str, x.queue.int_ptr, dev.max_work_group_size)  # the grid fits prog of this dtype
        if key not in grids:
            grids.clear()
            grids[key] = launches(prog, dev, (x.shape[0] if x.ndim == 4 else 1) * x.shape[-3], *x.shape[-2:])
        p, xnext = self._buffers(x, 2 if one else 1)
        arrays = tv_plain.Arrays(x, out, steps, tuple(p), xnext, None if dual is None else tuple(dual))
        first2 = GPU_FIRST_TWO and not dev.is_cpu and x.size <= GPU_FIRST_TWO_VOXELS
        return prog, grids[key], arrays, {"one_launch": one, "first2": first2}

    def _run_plain(self, x, steps, out, dual=None):
        import pyopencl as cl

        if self.iterations == 1:  # out = x + d(0)
            cl.enqueue_copy(x.queue, out.data, x.data)
            return out
        prog, grids, arrays, plan = self._plain_parts(x, steps, out, dual)
        tv_plain.enqueue(x.queue, tv_plain.sequence(prog, grids, arrays, self.iterations, **plan))
        return out

    def _no_dual(self, queue):
        """A one-value int array for ``tv_fused``'s ``dual`` argument when there is no ADMM update."""
        import pyopencl.array as cla

        cache = self.__dict__.setdefault("_zero", {})
        if queue.int_ptr not in cache:
            cache[queue.int_ptr] = cla.zeros(queue, 1, np.int32)
        return cache[queue.int_ptr]
