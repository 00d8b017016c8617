"""Total-variation regularizer: Chambolle's projection algorithm as OpenCL kernels."""

from __future__ import annotations

import numpy as np

from rsocl.device.context import c_type, device_for_queue
from rsocl.device.launch import voxel_launches
from rsocl.solver.regularizer import Option, Regularizer

__all__ = ["TV"]

#: Work items per work group of the TV kernels (blocks of whole rows, rsocl.device.launch.voxel_launches),
#: at most: about 512 voxels ran 7-15 % faster than half rows of 64 on PoCL (64x64 to 128x128).
GROUP = 512


def edge_weights(n: int, dtype) -> np.ndarray:
    """``xnext`` of ``tv.cl``: 1 where a column has a right neighbour (x < n - 1), else 0."""
    return (np.arange(n) < n - 1).astype(dtype)


def launches(prog, device, T: int, m: int, n: int):
    """Exact launch grids of the TV kernels of ``prog`` (no bounds test in them), in work groups
    of whole rows up to :data:`GROUP`, capped by what ``device`` and the kernels allow."""
    import pyopencl as cl

    group = min([GROUP, device.max_work_group_size] + [
        k.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, device)
        for k in (prog.tv_primal, prog.tv_dual, prog.tv_dual_first)])
    return voxel_launches(T, m, n, group=group)


class TV(Regularizer):
    """Isotropic TV (Chambolle), as ``skimage.restoration.denoise_tv_chambolle`` with ``eps=0``.

    ``temporal_weight = 1`` is scikit-image's 3-D TV; ``0`` is 2-D TV on each
    sub-frame; other values scale the temporal finite difference. The default, 3,
    was measured on the shared videos (paper array, 64x64, 200 iterations, PSNR in
    dB): Runner 19.80 / 22.61 / 23.67 and Traffic 16.90 / 18.57 / 18.58 for weights
    1 / 3 / 5, while on the fast built-in scene (1.4 px per sub-frame) 1 is best
    (18.2 / 17.7 / 17.1): 3 keeps most of the gain on real videos.
    """

    name = "tv"
    tunable = {"temporal_weight": (1.0, 3.0, 10.0, 30.0)}
    options = {
        "iterations": Option(10, "iterations", "Chambolle iterations per denoising call", 1, 100000),
        "temporal_weight": Option(3.0, "", "weight of the temporal difference (0: 2-D per sub-frame, "
                                           "1: scikit-image's 3-D TV)", 0, 1e3),
    }

    def workspace_bytes(self, shape, dtype) -> int:
        planes = 3 if self.temporal_weight > 0 else 2          # the dual p, and xnext (n values)
        return (planes * int(np.prod(shape)) + int(shape[-1])) * np.dtype(dtype).itemsize

    def _denoise(self, x, weight, out):
        import pyopencl as cl
        import pyopencl.array as cla

        if out.base_data.int_ptr == x.base_data.int_ptr:
            raise ValueError("out must be another buffer than x (every TV iteration reads x)")
        T, m, n = x.shape
        temporal = int(self.temporal_weight > 0)
        prog = device_for_queue(x.queue).program(["tv.cl"], REAL=c_type(x.dtype), TEMPORAL=temporal)
        planes = 3 if temporal else 2
        cache = self.__dict__.setdefault("_dual", {})
        key = (x.shape, x.dtype.str, planes, x.queue.int_ptr)
        if key not in cache:                        # once per shape, dtype and queue
            cache.clear()
            cache[key] = (cla.empty(x.queue, (planes,) + x.shape, x.dtype),
                          cla.to_device(x.queue, edge_weights(n, x.dtype)), launches(prog, x.queue.device, T, m, n))
        p, xnext, grids = cache[key]
        wt = float(self.temporal_weight) if temporal else 0.0
        tau = 1.0 / (2.0 * (2.0 + wt * wt))
        real_t = x.dtype.type
        sizes = (np.int32(T), np.int32(m), np.int32(n))

        def each(kernel, *args):
            for gsize, lsize, offset in grids:
                kernel(x.queue, gsize, lsize, *args, *sizes, global_offset=offset)

        steps = (real_t(tau), real_t(tau / weight), real_t(wt))
        if self.iterations == 1:                    # out = x + d(0)
            cl.enqueue_copy(x.queue, out.data, x.data)
            return out
        # iteration 0 from p = 0 (out = x): one kernel that only writes p
        each(prog.tv_dual_first, x.data, p.data, xnext.data, *steps)
        for i in range(1, self.iterations):
            each(prog.tv_primal, x.data, p.data, out.data, real_t(wt))
            if i < self.iterations - 1:
                each(prog.tv_dual, out.data, p.data, xnext.data, *steps)
        return out
