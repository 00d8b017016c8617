"""Equality of two runs that make the same arithmetic through different kernels (a step folded into
another launch, a residual summed in the projection or on its own).

On a CPU device (PoCL) such runs give the same bits. A GPU compiler may contract ``a * b + c`` into one
``fma`` in one kernel and not in the other, and a reduction folded into another kernel groups its sums
by that kernel's work groups: the runs then differ by a few units in the last place, as NVIDIA's
OpenCL does on an H100.
"""

import numpy as np
import pyopencl as cl

#: Units in the last place (of the largest value compared) two such runs may differ by off a CPU.
ULPS = 16


def assert_same_arithmetic(actual, desired, device, precision=None):
    """Assert ``actual`` equals ``desired``: bit for bit where ``device`` is a CPU, else within
    :data:`ULPS` units in the last place of the largest ``|desired|``, in ``precision``, the dtype the
    values were computed in (None: ``desired``'s; a float32 run's residuals come as float64). The
    device's own type decides, whatever a test patched ``Device.is_cpu`` to."""
    actual, desired = np.asarray(actual), np.asarray(desired)
    if device.device.type & cl.device_type.CPU:
        np.testing.assert_array_equal(actual, desired)
        return
    assert actual.shape == desired.shape and actual.dtype == desired.dtype, (actual.shape, desired.shape)
    step = ULPS * np.finfo(precision or desired.dtype).eps * float(np.max(np.abs(desired), initial=0.0))
    np.testing.assert_allclose(actual, desired, rtol=0, atol=step)
