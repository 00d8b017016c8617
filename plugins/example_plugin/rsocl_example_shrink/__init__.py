"""An rsocl regularizer shipped by a third party: shrink towards a constant."""

import numpy as np
import pyopencl as cl

from rsocl import Option, Regularizer

__all__ = ["Shrink"]

SOURCE = """
__kernel void shrink(__global const REAL *x, __global REAL *out, REAL weight, REAL center, int n)
{
    int i = get_global_id(0);
    if (i < n) out[i] = (x[i] + weight * center) / ((REAL)1 + weight);
}
"""


class Shrink(Regularizer):
    """Prox of ``(weight/2)·‖x − center‖²``: ``(x + weight·center) / (1 + weight)``."""

    name = "shrink"
    options = {"center": Option(0.0, "intensity", "value every voxel is pulled towards")}
    dtypes = ("float32", "float64")

    def _denoise(self, x, weight, out):
        real = "double" if x.dtype == np.float64 else "float"
        programs = self.__dict__.setdefault("_programs", {})
        key = (x.queue.context.int_ptr, real)
        if key not in programs:
            options = [f"-DREAL={real}"]
            src = ("#pragma OPENCL EXTENSION cl_khr_fp64 : enable\n" if real == "double" else "") + SOURCE
            programs[key] = cl.Kernel(cl.Program(x.queue.context, src).build(options=options), "shrink")
        scalar = x.dtype.type
        programs[key](x.queue, (x.size,), None, x.data, out.data, scalar(weight), scalar(self.center), np.int32(x.size))
        return out
