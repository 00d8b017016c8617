"""DCT regularizer: soft thresholding of orthonormal DCT coefficients, as OpenCL kernels."""

from __future__ import annotations

import numpy as np

from rsocl.device.context import device_for_queue
from rsocl.device.launch import voxel_grid
from rsocl.device.pool import same_memory
from rsocl.device.program import c_type
from rsocl.solver.regularizer import Option, Regularizer

__all__ = ["DCT", "dct_matrix"]

MODES = ("2d", "3d")


def dct_matrix(L: int) -> np.ndarray:
    """The orthonormal DCT-II matrix ``C`` of length ``L`` (float64): ``X = C @ x``, ``x = C.T @ X``."""
    k = np.arange(L)[:, None]
    j = np.arange(L)[None, :]
    C = np.cos(np.pi * (2 * j + 1) * k / (2.0 * L)) * np.sqrt(2.0 / L)
    C[0] /= np.sqrt(2.0)
    return C


class DCT(Regularizer):
    """Orthonormal DCT-II with soft thresholding of every coefficient but the DC one.

    ``denoise(x, weight)`` transforms ``x`` with the orthonormal DCT-II (as
    ``scipy.fft.dctn(x, type=2, norm="ortho")``), soft-thresholds every
    coefficient except the DC coefficient of each block (or of each frame) by
    ``weight``, and applies the inverse (orthonormal DCT-III). It is the proximal
    operator of ``weight * ||non-DC DCT coefficients||_1`` for an orthonormal
    transform, hence non-expansive.

    Options
    -------
    mode : "3d" (default) or "2d"
        ``"3d"`` transforms along t, y and x; ``"2d"`` transforms each sub-frame
        along y and x on its own (every sub-frame keeps its own DC coefficient).
    block : int, default 0
        ``0`` transforms the whole frame (each axis over its full length).
        ``b > 0`` transforms independent ``b x b`` blocks (``b x b x b`` in 3-D:
        also ``b`` sub-frames in time) starting at multiples of ``b``. Where ``b``
        does not divide an axis, the last block along it is shorter and is
        transformed with its own, smaller length, so any shape works; ``b`` larger
        than an axis means that axis is taken whole.

    Cost: each of the 2 x (2 or 3) one-axis passes does ``L`` multiply-adds per
    voxel, ``L`` the block length along that axis (the axis length for the whole
    frame), plus one thresholding pass; device memory is one work array of the
    input's size and the basis tables (``2 L^2`` values per length that occurs).
    The defaults, :attr:`recommended` and the measured quality and time:
    ``docs/regularizer_defaults.md``.

    ``transform(x)`` and ``inverse(c)`` expose the forward and inverse transforms
    (device arrays in, new device arrays out).
    """

    name = "dct"
    #: its transform spans the whole frame (or blocks placed from the frame's corner): not tiled
    local = False
    #: ``lam`` and ``eta`` when the caller gives none (docs/regularizer_defaults.md)
    recommended = {"lam": 0.3, "eta": 0.2}
    options = {
        "mode": Option("3d", "", "'3d': DCT along t, y, x; '2d': DCT of each sub-frame along y, x"),
        "block": Option(0, "pixels", "block size along every transformed axis (0: whole frame)", 0, 65536),
    }

    def __init__(self, **options):
        super().__init__(**options)
        mode = str(self.values["mode"]).lower()
        if mode not in MODES:
            raise ValueError(f"option mode must be one of {list(MODES)}, got {self.values['mode']!r}")
        self.values["mode"] = mode

    # -- geometry ---------------------------------------------------------------------------------
    def _blocks(self, shape):
        """Block size per axis (t, y, x); 1 along t in 2-D mode (no transform along t)."""
        T, m, n = shape
        b = int(self.block)
        sizes = [N if b == 0 else min(b, N) for N in (T, m, n)]
        if self.mode == "2d":
            sizes[0] = 1
        return tuple(sizes)

    def _lengths(self, shape):
        """The transform lengths that occur along the transformed axes (full and partial blocks)."""
        lengths = set()
        for N, b in zip(shape, self._blocks(shape)):
            if b > 1:
                lengths.add(b)
                if N % b:
                    lengths.add(N % b)  # the shorter last block (length 1: the identity)
        return sorted(lengths)

    def _table_size(self, shape):
        return sum(2 * L * L for L in self._lengths(shape))

    def workspace_bytes(self, shape, dtype, device=None) -> int:
        itemsize = np.dtype(dtype).itemsize
        return (int(np.prod(shape)) + self._table_size(shape)) * itemsize

    # -- device resources -------------------------------------------------------------------------
    def _resources(self, x):
        """(program, table buffer, {L: (forward offset, inverse offset)}, work array), cached."""
        import pyopencl.array as cla

        cache = self.__dict__.setdefault("_cache", {})
        key = (x.shape, x.dtype.str, x.queue.int_ptr, self.mode, self.block)
        if key not in cache:
            cache.clear()
            prog = device_for_queue(x.queue).program(["dct.cl"], REAL=c_type(x.dtype))
            parts, offsets, pos = [], {}, 0
            for L in self._lengths(x.shape):
                C = dct_matrix(L)
                # Both stored as tab[i * L + o]: i summed over, o the output index.
                parts += [C.T.ravel(), C.ravel()]  # forward: C[o][i] at [i][o]; inverse: C[i][o]
                offsets[L] = (pos, pos + L * L)
                pos += 2 * L * L
            table = np.concatenate(parts) if parts else np.zeros(1)
            tab = cla.to_device(x.queue, table.astype(x.dtype))
            work = cla.empty(x.queue, x.shape, x.dtype)
            cache[key] = (prog, tab, offsets, work)
        return cache[key]

    def _passes(self, shape):
        """Axes (kernel numbering: 0 x, 1 y, 2 t) with a transform of length > 1."""
        bt, by, bx = self._blocks(shape)
        return [axis for axis, b in ((0, bx), (1, by), (2, bt)) if b > 1]

    def _run(self, src, passes, inverse, first_dst, other, res):
        """Apply the 1-D transforms of ``passes`` in turn, ping-ponging first_dst/other; returns the result."""
        prog, tab, offsets, _ = res
        T, m, n = src.shape
        blocks = dict(zip((2, 1, 0), self._blocks(src.shape)))
        dims = (np.int32(T), np.int32(m), np.int32(n))
        lengths = {0: n, 1: m, 2: T}
        chunk = 64 // src.dtype.itemsize  # outputs per work item (CH in dct.cl)
        which = 1 if inverse else 0
        dsts = (first_dst, other)
        cur = src
        for k, axis in enumerate(passes):
            b = blocks[axis]
            part = lengths[axis] % b
            off_full = np.int32(offsets[b][which])
            off_part = np.int32(offsets[part][which] if part else 0)  # unused when b divides the axis
            dst = dsts[k % 2]
            if axis == 0:
                items = -(-n // b) * -(-b // chunk)
                gsize, lsize = voxel_grid(T, m, items)
                values = (np.int32(b), off_full, off_part, *dims)
                # one kernel object per pass: its by-value arguments are set once (rsocl.device.kernel)
                prog.instance("dct_x", values)(src.queue, gsize, lsize, cur.data, dst.data, tab.data, *values)
            else:
                gsize, lsize = voxel_grid(T, m, -(-n // chunk))
                values = (np.int32(axis), np.int32(b), off_full, off_part, *dims)
                prog.instance("dct_strided", values)(src.queue, gsize, lsize, cur.data, dst.data, tab.data, *values)
            cur = dst
        return cur

    # -- public -----------------------------------------------------------------------------------
    def transform(self, x):
        """Forward blocked DCT-II of the device array ``x`` (T, m, n); a new device array."""
        return self._apply(x, inverse=False)

    def inverse(self, c):
        """Inverse blocked DCT (DCT-III) of the device array ``c`` (T, m, n); a new device array."""
        return self._apply(c, inverse=True)

    def _apply(self, x, inverse):
        import pyopencl as cl
        import pyopencl.array as cla

        self._check(x)
        res = self._resources(x)
        out = cla.empty_like(x)
        passes = self._passes(x.shape)
        if not passes:
            cl.enqueue_copy(x.queue, out.data, x.data)
            return out
        # End in `out`: with P passes the first writes out when P is odd.
        first, other = (out, res[3]) if len(passes) % 2 else (res[3], out)
        return self._run(x, passes, inverse, first, other, res)

    def _check(self, x):
        import pyopencl.array as cla

        if not isinstance(x, cla.Array) or x.ndim != 3:
            raise ValueError(f"{self.name}: expected a pyopencl.array.Array of shape (T, m, n)")
        if np.dtype(x.dtype).name not in self.dtypes:
            raise ValueError(f"{self.name}: dtype {x.dtype} not supported; supported: {list(self.dtypes)}")

    def _denoise(self, x, weight, out):
        import pyopencl as cl

        T, m, n = x.shape
        res = self._resources(x)
        prog, work = res[0], res[3]
        passes = self._passes(x.shape)
        bt, by, bx = self._blocks(x.shape)
        gsize, lsize = voxel_grid(T, m, n)
        if not passes:  # every coefficient is a DC coefficient: the identity (out may be x)
            if not same_memory(out, x):
                cl.enqueue_copy(x.queue, out.data, x.data)
            return out
        # 2P launches alternate work/out and the last one writes `out`: pass k (1-based) writes
        # `out` when k is even. x is read only by the first pass, so out may alias x.
        coeffs = self._run(x, passes, False, work, out, res)
        prog.dct_soft_threshold(
            x.queue,
            gsize,
            lsize,
            coeffs.data,
            x.dtype.type(weight),
            np.int32(bt),
            np.int32(by),
            np.int32(bx),
            np.int32(T),
            np.int32(m),
            np.int32(n),
        )
        other = out if coeffs is work else work
        return self._run(coeffs, passes, True, other, coeffs, res)
