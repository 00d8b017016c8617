"""Wavelet regularizer: soft thresholding in an orthonormal wavelet basis, as OpenCL kernels.

The denoiser is ``W^T soft(W x, weight)``: a multi-level orthonormal discrete
wavelet transform ``W`` with periodization (PyWavelets' ``mode="periodization"``),
soft thresholding of every detail coefficient by ``weight`` (the coarsest
approximation band is kept), and the inverse transform. For an orthonormal
``W`` this is the proximal operator of ``weight * ||detail coefficients of x||_1``,
so it is non-expansive.

The transform is separable: ``mode="2d"`` transforms along y and x of each
sub-frame (sub-frames are independent), ``mode="3d"`` also along t, with one
number of levels for all transformed axes (as ``pywt.wavedecn``). A spatial
axis whose length is odd, or shorter than the filter, cannot be transformed: it
is left untouched (the transform acts on the other axes, as
``pywt.wavedecn(axes=...)`` without it). A number of sub-frames T that is not a
multiple of ``2**levels`` (T = 69 for the paper's 4-camera array at 64 x 64)
is split, by default, into a leading block of frames transformed in 3-D and
the remaining frames transformed in 2-D; both are orthonormal, so the
denoiser stays an exact prox. See :meth:`Wavelet.plan`.
"""

from __future__ import annotations

import numpy as np

from rsocl.device.context import device_for_queue
from rsocl.device.launch import voxel_grid
from rsocl.device.pool import same_memory
from rsocl.solver.regularizer import Option, Regularizer
from rsocl_plugins.wavelet_filters import MODES, WAVELETS, Plan, axis_levels, filters
from rsocl_plugins.wavelet_passes import analysis_levels, approximation_box, copy_frames, synthesis_levels

__all__ = ["Wavelet", "Plan", "WAVELETS", "filters", "axis_levels"]


class Wavelet(Regularizer):
    """Soft thresholding of orthonormal wavelet detail coefficients (periodized DWT).

    Options
    -------
    wavelet : "haar", "db2" or "db4" (PyWavelets' names; db2 has 4 taps, db4 8)
    mode : "2d" (y, x of each sub-frame) or "3d" (t, y, x)
    levels : maximum number of levels; 0 = as many as the shape allows (:meth:`plan`)
    split_time : 3-D mode with T not a multiple of ``2**levels``: transform the
        leading frames that are in 3-D and the rest in 2-D (True), or let the
        time axis limit the levels / stay untouched (False)

    In the ADMM the threshold is ``weight = lam / eta``; the defaults (haar, 3-D) and the
    measurements behind them: ``docs/regularizer_defaults.md``.

    Besides :meth:`denoise`, :meth:`transform` and :meth:`inverse` expose the
    forward and inverse transforms on device arrays, with the coefficients of
    each block in the in-place (Mallat) layout of ``pywt.coeffs_to_array(
    pywt.wavedecn(block, wavelet, mode="periodization", level=L, axes=axes), axes=axes)``.
    The ``out`` of :meth:`denoise` and :meth:`transform` must be another buffer than ``x``: their analysis
    passes read ``x`` while they write.
    """

    name = "wavelet"
    #: its transform spans the whole frame (or blocks placed from the frame's corner): not tiled
    local = False
    options = {
        "wavelet": Option("haar", "", "wavelet: haar, db2 or db4 (PyWavelets names)"),
        "mode": Option("3d", "", "2d: transform y and x of each sub-frame; 3d: also t"),
        "levels": Option(0, "levels", "maximum decomposition levels (0: as many as the shape allows)", 0, 30),
        "split_time": Option(
            True,
            "",
            "3d with T not a multiple of 2**levels: leading frames in 3-D, "
            "the rest in 2-D (else the time axis limits the levels)",
        ),
    }

    def __init__(self, **options):
        super().__init__(**options)
        if self.wavelet not in WAVELETS:
            raise ValueError(f"option wavelet must be one of {sorted(WAVELETS)}, got {self.wavelet!r}")
        if self.mode not in MODES:
            raise ValueError(f"option mode must be one of {sorted(MODES)}, got {self.mode!r}")

    # ------------------------------------------------------------------ planning
    def plan(self, shape) -> Plan:
        """The :class:`Plan` for a ``(T, m, n)`` input.

        Each axis takes at most :func:`axis_levels` levels (its length divisible
        by ``2**L`` and at least the filter length at the coarsest level). Axes
        that take none (odd length, or shorter than the filter) are left
        untouched; the others share one level count, the smallest of their
        maxima, capped by the ``levels`` option when it is not 0 (the rule of
        ``pywt.wavedecn`` on the transformable axes). When no axis qualifies the
        plan has 0 levels and the denoiser is the identity (all coefficients are
        approximation).

        In 3-D mode with ``split_time`` (default), the time axis does not limit
        the spatial levels ``L``: when T is not a multiple of ``2**L`` the first
        ``T' = 2**L * floor(T / 2**L)`` frames are transformed in 3-D and the last
        ``T - T'`` in 2-D (two blocks), provided ``T' / 2**(L-1)`` is at least
        the filter length; otherwise the rule above applies to t as well.
        """
        if len(shape) != 3:
            raise ValueError(f"shape must be (T, m, n), got {shape}")
        T = int(shape[0])
        flen = len(WAVELETS[self.wavelet]["dec_lo"])
        cap = int(self.levels) or None
        most = {a: axis_levels(int(shape[a]), flen) for a in MODES[self.mode]}
        spatial = tuple(a for a in (1, 2) if most.get(a, 0) > 0)
        if self.mode == "3d" and self.split_time and spatial:
            L = min(min(most[a] for a in spatial), cap or 64)
            head = (T >> L) << L
            if most[0] < L and head < T and head and head >> (L - 1) >= flen:
                return Plan(L, (0,) + spatial, ((0, head, (0,) + spatial), (head, T - head, spatial)))
        axes = tuple(a for a, lv in most.items() if lv > 0)
        if not axes:
            return Plan(0, (), ((0, T, ()),))
        L = min(min(most[a] for a in axes), cap or 64)
        return Plan(L, axes, ((0, T, axes),))

    def workspace_bytes(self, shape, dtype, device=None) -> int:
        return int(np.prod(shape)) * np.dtype(dtype).itemsize if self.plan(shape).levels else 0

    # ------------------------------------------------------------------ device work
    def _program(self, queue, dtype):
        double = np.dtype(dtype) == np.float64
        suffix = "" if double else "f"
        coeffs = WAVELETS[self.wavelet]
        literal = lambda cs: "{" + ", ".join(repr(float(c)) + suffix for c in cs) + "}"  # noqa: E731
        return device_for_queue(queue).program(
            ["wavelet.cl"],
            REAL="double" if double else "float",
            FLEN=len(coeffs["dec_lo"]),
            DEC_LO=literal(coeffs["dec_lo"]),
            DEC_HI=literal(coeffs["dec_hi"]),
        )

    def _workspace(self, x):
        import pyopencl.array as cla

        cache = self.__dict__.setdefault("_work", {})
        key = (x.shape, x.dtype.str, x.queue.int_ptr)
        if key not in cache:
            cache.clear()
            cache[key] = cla.empty(x.queue, x.shape, x.dtype)
        return cache[key]

    def _check(self, x, out):
        import pyopencl.array as cla

        if not isinstance(x, cla.Array) or x.ndim != 3:
            raise ValueError(f"{self.name}: expected a (T, m, n) pyopencl.array.Array")
        if np.dtype(x.dtype).name not in self.dtypes:
            raise ValueError(f"{self.name}: dtype {x.dtype} not supported; supported: {list(self.dtypes)}")
        if out is None:
            return cla.empty_like(x)
        if out.shape != x.shape or out.dtype != x.dtype:
            raise ValueError(f"{self.name}: out must match x ({x.shape}, {x.dtype}), got {out.shape}, {out.dtype}")
        return out

    def _analyse(self, x, coeffs, other):
        """Coefficients of ``x`` into the buffer ``coeffs`` (``other``: scratch of the same size)."""
        import pyopencl as cl

        plan = self.plan(x.shape)
        if not plan.levels:
            cl.enqueue_copy(x.queue, coeffs, x.data)
            return plan
        prog = self._program(x.queue, x.dtype)
        for block in plan.blocks:
            if not block[2]:
                copy_frames(x.queue, coeffs, x.data, x.shape, block, x.dtype.itemsize)
                continue
            bufs = [coeffs, other] if len(block[2]) % 2 else [other, coeffs]
            analysis_levels(prog, x.queue, x.data, bufs, x.shape, x.dtype.itemsize, plan.levels, block)
        return plan

    def _synthesise(self, prog, queue, plan, coeffs, other, out, shape, itemsize):
        """Inverse of the coefficients in ``coeffs`` (overwritten) into ``out``, which is
        ``coeffs`` or ``other``; a block whose result lands in the other one is copied."""
        for block in plan.blocks:
            res = (
                synthesis_levels(prog, queue, [coeffs, other], 0, shape, itemsize, plan.levels, block)
                if block[2]
                else 0
            )
            if [coeffs, other][res] is not out:
                copy_frames(queue, out, [coeffs, other][res], shape, block, itemsize)

    def transform(self, x, out=None):
        """Forward transform of the device array ``x`` (T, m, n): the coefficients of each
        block of :meth:`plan` in Mallat layout (a copy of ``x`` when nothing is transformed). ``out``, when
        given, must be another buffer than ``x`` (ValueError)."""
        out = self._check(x, out)
        self._not_x(x, out)
        self._analyse(x, out.data, self._workspace(x).data)
        return out

    def inverse(self, c, out=None):
        """Inverse of :meth:`transform`: ``c`` (T, m, n) coefficients (not modified)."""
        import pyopencl as cl

        out = self._check(c, out)
        plan = self.plan(c.shape)
        if not plan.levels:
            cl.enqueue_copy(c.queue, out.data, c.data)
            return out
        work = self._workspace(c)
        cl.enqueue_copy(c.queue, work.data, c.data)
        self._synthesise(
            self._program(c.queue, c.dtype), c.queue, plan, work.data, out.data, out.data, c.shape, c.dtype.itemsize
        )
        return out

    def _not_x(self, x, out):
        if same_memory(out, x):
            raise ValueError(f"{self.name}: out must be another buffer than x (the analysis reads x as it writes)")

    def _denoise(self, x, weight, out):
        import pyopencl as cl

        self._not_x(x, out)
        plan = self.plan(x.shape)
        if not plan.levels:  # nothing can be transformed: all coefficients are approximation
            cl.enqueue_copy(x.queue, out.data, x.data)
            return out
        queue = x.queue
        _, m, n = x.shape
        itemsize = x.dtype.itemsize
        prog = self._program(queue, x.dtype)
        # coefficients in `out` when the first block has an even number of axes, else in
        # the workspace: its inverse then lands in `out` without a copy
        work = self._workspace(x).data
        coeffs, other = (out.data, work) if len(plan.axes) % 2 == 0 else (work, out.data)
        self._analyse(x, coeffs, other)
        for block in plan.blocks:
            if not block[2]:
                continue
            t0, frames, _ = block
            at, ay, ax = approximation_box(block, x.shape, plan.levels)
            gsize, lsize = voxel_grid(frames, m, n)
            values = tuple(np.int32(v) for v in (m, n, t0, frames, at, ay, ax))
            prog.instance("soft_threshold", values)(queue, gsize, lsize, coeffs, x.dtype.type(weight), *values)
        self._synthesise(prog, queue, plan, coeffs, other, out.data, x.shape, itemsize)
        return out
