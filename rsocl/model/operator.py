"""The matrix-free row-timed shutter operator ``H`` on an OpenCL device.

``H`` maps a datacube ``f[T, m, n]`` to snapshots ``g[K, m, n]`` (docs/model.md,
Eqs. 5-10). Nothing of size ``K×T×m×n`` is stored: each pixel's weights are
computed on the fly from its exposure start (two ``(K, m, n)`` maps) and only
its exposure window is visited.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from rsocl.common import validation as check
from rsocl.common.hints import ArrayLike, DTypeLike
from rsocl.device import pool
from rsocl.device.context import Device, check_process, get_device
from rsocl.device.kernel import Kernel
from rsocl.device.launch import block_grid, element_launches
from rsocl.device.program import c_type
from rsocl.model.rig import Rig
from rsocl.model.windows import kernel_windows

if TYPE_CHECKING:
    import pyopencl.array as cla

__all__ = ["RollingShutterOperator", "geometry_bytes"]

#: Pixels per work item on a CPU device (one explicit vector of this many lanes): 32 bytes per load.
VECTOR_WIDTH = {"float32": 8, "float64": 4}
#: rows per work item of the forward, adjoint and ADMM projection kernels on a CPU device (``TILE_R``)
BLOCK_ROWS = 4
#: ``(pixels, rows)`` per work item of those kernels on a device that is not a CPU (``TILE_W``, ``TILE_R``):
#: measured in docs/gpu/blocks.md.
GPU_BLOCK = (1, 1)


def block_shape(device, dtype) -> tuple[int, int]:
    """``(TILE_W, TILE_R)``: pixels along a row and rows per work item of the block kernels (forward,
    adjoint, residual, ADMM projection) on ``device`` (an rsocl Device) for ``dtype``:
    :data:`VECTOR_WIDTH` × :data:`BLOCK_ROWS` on a CPU device (explicit vectors for its SIMD units),
    :data:`GPU_BLOCK` on others (many work items on neighbouring addresses)."""
    if device.is_cpu:
        return VECTOR_WIDTH[np.dtype(dtype).name], BLOCK_ROWS
    width, rows = (int(v) for v in GPU_BLOCK)
    return width, rows


def geometry_bytes(K: int, pixels: int, dtype) -> int:
    """Device bytes of an operator's geometry for ``K`` channels of ``pixels`` pixels each: the
    exposure-start index (int32) and fraction per channel and pixel, the window length (whole
    sub-frames and the rest) and gain per channel (:class:`RollingShutterOperator`'s ``first``,
    ``frac``, ``length``, ``gain``; :func:`~rsocl.model.windows.kernel_windows`)."""
    itemsize = np.dtype(dtype).itemsize
    return int(K) * int(pixels) * (4 + itemsize) + 3 * int(K) * itemsize


class RollingShutterOperator:
    """``H`` and ``Hᵀ`` of a :class:`~rsocl.model.rig.Rig` on an OpenCL device.

    Parameters
    ----------
    rig : Rig
        The camera array.
    device : str, Device or None
        OpenCL device (see :func:`rsocl.device.get_device`).
    dtype : {"float32", "float64"}
        Arithmetic and storage type on the device.
    subframes : slice or None
        Model only these sub-frames (``step`` 1): the datacube is then
        ``(stop - start, m, n)``. Default: all ``T``. Sub-frames outside must carry no
        weight for the model to stay exact (see :meth:`Rig.sampled_range`).

    Notes
    -----
    ``forward`` and ``adjoint`` accept NumPy arrays (and return NumPy arrays) or
    ``pyopencl.array.Array`` (and return device arrays, with no host copy). A leading batch
    axis (``(B, T, m, n)`` -> ``(B, K, m, n)`` and back) runs ``B`` sets in one launch.
    Their cost is about ``K*m*n*(t_e/dt + 1)`` weight evaluations.

    Raises
    ------
    ValueError
        If ``rig`` is not a :class:`~rsocl.model.rig.Rig`, ``dtype`` is unknown or not supported by
        the device, ``subframes`` is not a non-empty slice with step 1, or the datacube does not fit
        the device.

    Examples
    --------
    >>> import numpy as np, rsocl
    >>> rig = rsocl.Rig.paper_array(4, shape=(16, 16), t_e=180e-6, t_r=35e-6)
    >>> op = rsocl.RollingShutterOperator(rig)
    >>> op.domain_shape, op.range_shape
    ((21, 16, 16), (4, 16, 16))
    >>> g = op.forward(np.ones(op.domain_shape))           # a constant scene
    >>> bool(np.allclose(g, 180e-6 / 35e-6))                # every snapshot pixel sees t_e/dt sub-frames
    True
    >>> rsocl.testing.dottest(op)                           # Hᵀ is the transpose of H
    True
    """

    def __init__(
        self, rig: Rig, device: str | Device | None = None, dtype: DTypeLike = "float32", subframes: slice | None = None
    ) -> None:
        if not isinstance(rig, Rig):
            raise ValueError(f"rig must be an rsocl.Rig, got {type(rig).__name__}")
        self.rig = rig
        self.device = get_device(device)
        self.dtype = self.device.real_dtype(dtype)
        self.queue = self.device.queue
        m, n = rig.shape
        subframes = slice(0, rig.T) if subframes is None else subframes
        if not isinstance(subframes, slice):
            raise ValueError(f"subframes must be a slice of range({rig.T}) or None, got {subframes!r}")
        start, stop, step = subframes.indices(rig.T)
        if step != 1 or stop <= start:
            raise ValueError(f"subframes must be a non-empty slice of range({rig.T}) with step 1, got {subframes}")
        self.subframes = slice(start, stop)
        self.K, self.T, self.mn = rig.n_channels, stop - start, m * n
        self.L = rig.window_length
        itemsize = self.dtype.itemsize
        self.device.check_fits(
            f"a datacube of T={self.T} x {m} x {n} in {self.dtype.name}", self.T * m * n * itemsize, dtype=self.dtype
        )
        win = rig.windows
        self.first = pool.to_device(self.queue, (win.index - start).astype(np.int32))
        frac, length = kernel_windows(win, rig.mask, self.dtype)
        self.frac = pool.to_device(self.queue, frac)
        self.length = pool.to_device(self.queue, length)
        self.gain = pool.to_device(self.queue, win.gain.astype(self.dtype))
        #: pixels per row of a work item's block of the forward, adjoint and ADMM projection kernels, and
        #: rows per block (:func:`block_shape`)
        self.vector_width, self.block_rows = block_shape(self.device, self.dtype)
        self.program = self.device.program(
            ["operator.cl"],
            REAL=c_type(self.dtype),
            ACC=c_type(self.device.acc_dtype),
            MASK_BINARY=int(rig.mask == "binary"),
            **self.tile_defines,
        )
        self._psi: cla.Array | None = None

    @property
    def domain_shape(self) -> tuple[int, int, int]:
        """``(T, m, n)``."""
        return (self.T,) + self.rig.shape

    @property
    def range_shape(self) -> tuple[int, int, int]:
        """``(K, m, n)``."""
        return (self.K,) + self.rig.shape

    # ------------------------------------------------------------------ helpers
    def _to_device(self, x, shape, name):
        """``x`` on the device and whether it was there; ``shape`` or a batch of it (a leading axis)."""
        import pyopencl.array as cla

        check_process()  # an operator made before a fork: a clear error in the child, not a wait for ever
        on_device = isinstance(x, cla.Array)
        if not on_device:
            x = check.finite_array(name, x)
        if x.shape[-3:] != shape or x.ndim not in (3, 4) or (x.ndim == 4 and x.shape[0] < 1):
            raise ValueError(
                f"{name} must have shape {shape} or (B, {', '.join(map(str, shape))}) for a batch "
                f"of B >= 1 sets, got {x.shape}"
            )
        if on_device:
            if x.dtype != self.dtype:
                raise ValueError(f"{name} must have dtype {self.dtype.name} on the device, got {x.dtype}")
            return x, True
        return pool.to_device(self.queue, np.asarray(x, dtype=self.dtype), wait=True), False

    def empty(self, shape: tuple[int, ...]) -> cla.Array:
        """An uninitialised device array of this operator's dtype."""
        return pool.empty(self.queue, shape, self.dtype)

    @property
    def tile_defines(self) -> dict[str, int]:
        """Program definitions of the block kernels (``TILE_W`` pixels by ``TILE_R`` rows)."""
        return {"TILE_W": self.vector_width, "TILE_R": self.block_rows}

    def block_grid(self, channels: int = 1, kernels: tuple = ()) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """Global and local sizes of a kernel with one work item per block of pixels (and channel).

        Work groups stay within the device's limits and those of this operator's block kernels and
        of ``kernels`` (others launched on the same grid).
        """
        m, n = self.rig.shape
        group = self.device.group_limit(self.program.forward, self.program.adjoint_scatter, *kernels, cap=64)
        return block_grid(
            m, n, self.vector_width, self.block_rows, channels, group=group, max_items=self.device.max_work_item_sizes
        )

    def element_launches(self, count: int, kernel: Kernel) -> list:
        """:func:`rsocl.device.launch.element_launches` within the device's and ``kernel``'s limits."""
        return element_launches(count, self.device.group_limit(kernel, cap=64))

    def sets_of(self, array: cla.Array, per_set: tuple[int, ...]) -> int:
        """How many sets a device array holds: its size over ``per_set`` (a domain or range shape)."""
        return array.size // int(np.prod(per_set))

    def _shape_args(self):
        """``(m, n)`` as kernel arguments."""
        return tuple(np.int32(v) for v in self.rig.shape)

    def _geometry(self):
        return (self.first.data, self.frac.data, self.length.data, self.gain.data)

    # ------------------------------------------------------------------ H, Hᵀ
    def forward_into(self, f: cla.Array, out: cla.Array) -> cla.Array:
        """``out = H f`` for device arrays (no checks, no allocation); a batch in one launch."""
        sets = self.sets_of(f, self.domain_shape)
        self.program.forward(
            self.queue,
            *self.block_grid(self.K * sets),
            f.data,
            out.data,
            *self._geometry(),
            np.int32(self.K),
            np.int32(self.T),
            np.int32(self.L),
            *self._shape_args(),
        )
        return out

    def adjoint_into(self, g: cla.Array, out: cla.Array, base: cla.Array | None = None) -> cla.Array:
        """``out = base + Hᵀ g`` (``base`` may be None) for device arrays; a batch in one launch."""
        import pyopencl as cl

        if base is None:
            for gsize, lsize, offset in self.element_launches(out.size, self.program.zero):
                self.program.zero(self.queue, gsize, lsize, out.data, global_offset=offset)
        elif base is not out:
            # the ignore: pyopencl's stub types Array.data as an optional holder; an allocated array's is a Buffer
            cl.enqueue_copy(self.queue, out.data, base.data)  # type: ignore[arg-type]
        self.program.adjoint_scatter(
            self.queue,
            *self.block_grid(self.sets_of(g, self.range_shape)),
            g.data,
            out.data,
            *self._geometry(),
            np.int32(self.K),
            np.int32(self.T),
            np.int32(self.L),
            *self._shape_args(),
        )
        return out

    def forward(self, f: ArrayLike | cla.Array) -> np.ndarray | cla.Array:
        """Snapshots ``H f``: ``(T, m, n)`` -> ``(K, m, n)`` (or a batch, ``(B, T, m, n)`` -> ``(B, K, m, n)``)."""
        f_dev, on_device = self._to_device(f, self.domain_shape, "f")
        out = self.forward_into(f_dev, self.empty(f_dev.shape[:-3] + self.range_shape))
        return out if on_device else out.get()

    def adjoint(self, g: ArrayLike | cla.Array) -> np.ndarray | cla.Array:
        """Back-projection ``Hᵀ g``: ``(K, m, n)`` -> ``(T, m, n)`` (or a batch, with a leading axis)."""
        g_dev, on_device = self._to_device(g, self.range_shape, "g")
        out = self.adjoint_into(g_dev, self.empty(g_dev.shape[:-3] + self.domain_shape))
        return out if on_device else out.get()

    # ------------------------------------------------------------------ H Hᵀ
    def psi_device(self) -> cla.Array:
        """Diagonal of ``H Hᵀ`` on the device, ``(K, m, n)``."""
        if self._psi is None:
            out = self.empty(self.range_shape)
            self.program.psi(
                self.queue,
                (self.mn, self.K),
                None,
                out.data,
                *self._geometry(),
                np.int32(self.T),
                np.int32(self.L),
                np.int32(self.mn),
            )
            self._psi = out
        return self._psi

    @property
    def psi(self) -> np.ndarray:
        """Diagonal of ``H Hᵀ``, ``(K, m, n)`` NumPy array (docs/model.md Eq. 16)."""
        return self.psi_device().get()

    def gram(self) -> np.ndarray:
        """Per-pixel ``K×K`` blocks of ``H Hᵀ`` as a ``(m, n, K, K)`` NumPy array."""
        return np.moveaxis(self.gram_device().get(), (0, 1), (2, 3))

    def gram_device(self):
        """Per-pixel ``K×K`` blocks of ``H Hᵀ`` as a ``(K, K, m, n)`` device array (enqueued)."""
        out = self.empty((self.K, self.K) + self.rig.shape)
        self.program.gram(
            self.queue,
            (self.mn,),
            None,
            out.data,
            *self._geometry(),
            np.int32(self.K),
            np.int32(self.T),
            np.int32(self.L),
            np.int32(self.mn),
        )
        return out

    def __repr__(self):
        return f"RollingShutterOperator({self.rig!r}, device={self.device.name!r}, dtype={self.dtype.name!r})"
