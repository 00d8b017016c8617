"""Total-variation regularizer: Chambolle's projection algorithm as OpenCL kernels."""

from __future__ import annotations

import numpy as np

from rsocl.device import device_for_queue
from rsocl.regularizer import Option, Regularizer

__all__ = ["TV"]


class TV(Regularizer):
    """Isotropic TV (Chambolle), as ``skimage.restoration.denoise_tv_chambolle`` with ``eps=0``.

    ``temporal_weight = 1`` is 3-D spatio-temporal TV; ``0`` is 2-D TV on each
    sub-frame; other values scale the temporal finite difference.
    """

    name = "tv"
    options = {
        "iterations": Option(10, "iterations", "Chambolle iterations per denoising call", 1, 100000),
        "temporal_weight": Option(1.0, "", "weight of the temporal difference (0: 2-D per sub-frame)", 0, 1e3),
    }

    def workspace_bytes(self, shape, dtype) -> int:
        planes = 3 if self.temporal_weight > 0 else 2
        return 2 * planes * int(np.prod(shape)) * np.dtype(dtype).itemsize

    def _denoise(self, x, weight, out):
        import pyopencl as cl
        import pyopencl.array as cla

        T, m, n = x.shape
        real = "double" if x.dtype == np.float64 else "float"
        temporal = int(self.temporal_weight > 0 and T > 1)
        dev = device_for_queue(x.queue)
        prog = dev.program(["tv.cl"], REAL=real, TEMPORAL=temporal)
        planes = 3 if temporal else 2
        key = (x.shape, x.dtype.str, planes, x.queue.int_ptr)
        cache = self.__dict__.setdefault("_buffers", {})
        if key not in cache:
            cache.clear()
            cache[key] = (cla.empty(x.queue, (planes,) + x.shape, x.dtype),
                          cla.empty(x.queue, (planes,) + x.shape, x.dtype))
        p_in, p_out = cache[key]
        wt = float(self.temporal_weight) if temporal else 0.0
        tau = 1.0 / (2.0 * (2.0 + wt * wt))
        scalar = x.dtype.type
        gsize = (n, m, T)
        cl.enqueue_fill_buffer(x.queue, p_in.data, scalar(0), 0, p_in.nbytes)
        for _ in range(self.iterations - 1):
            prog.tv_step(x.queue, gsize, None, x.data, p_in.data, p_out.data, scalar(tau),
                         scalar(tau / weight), scalar(wt), np.int32(T), np.int32(m), np.int32(n))
            p_in, p_out = p_out, p_in
        prog.tv_primal_out(x.queue, gsize, None, x.data, p_in.data, out.data, scalar(wt),
                           np.int32(T), np.int32(m), np.int32(n))
        return out

