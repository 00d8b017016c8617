"""An OpenCL kernel that sets a by-value argument only when its value changes.

pyopencl's ``kernel(queue, grid, local, *args)`` sets every argument on every launch, and setting
a by-value argument (a size, a step length) costs host time on the cores that also run the
kernels (measured: ``docs/implementation_notes.md``). Most of them are the same from one launch to the next, so
:class:`Kernel` remembers what it set and sets only what changed. :class:`rsocl.device.Kernels` hands out these kernels.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Kernel"]

#: by-value arguments that can be remembered: they cannot change after they were passed (an array
#: can, so arrays are set on every call)
_IMMUTABLE = (np.generic, bytes, int, float)


class Kernel:
    """Wraps a ``pyopencl.Kernel``; called like it: ``kernel(queue, global, local, *args, global_offset=)``.

    Buffers, local memory, ``None`` and NumPy arrays are set on every call; a by-value argument that
    cannot change once passed (a NumPy scalar, ``bytes``) is set when its value or its type differs
    from the one this object set last. The record is exact as long
    as every argument goes through this object: :meth:`set_arg` and :meth:`set_args` pass through
    and update it. Other attributes (``get_work_group_info``, ``function_name``, ...) are the
    wrapped kernel's. An object serves one thread at a time (its arguments are one set, as an OpenCL
    kernel's are): :class:`rsocl.device.Kernels` gives each thread objects of its own.
    """

    def __init__(self, kernel):
        import pyopencl as cl

        self._cl = cl
        self.kernel = kernel
        self._values = {}

    def set_arg(self, index: int, value):
        """Set argument ``index`` (an immutable by-value one only if it changed)."""
        if not isinstance(value, _IMMUTABLE):  # buffers, local memory, None, arrays: always
            self.kernel.set_arg(index, value)
            self._values.pop(index, None)
            return
        old = self._values.get(index)
        if old is None or type(old) is not type(value) or not old == value:
            self.kernel.set_arg(index, value)
            self._values[index] = value

    def set_args(self, *args):
        """Set the arguments ``0 .. len(args) - 1``, each as :meth:`set_arg` does."""
        for index, value in enumerate(args):
            self.set_arg(index, value)

    def __call__(self, queue, global_size, local_size, *args, global_offset=None, wait_for=None):
        self.set_args(*args)
        return self._cl.enqueue_nd_range_kernel(
            queue, self.kernel, global_size, local_size, global_work_offset=global_offset, wait_for=wait_for
        )

    def enqueue(self, queue, global_size, local_size, global_offset=None):
        """Enqueue the kernel with the arguments as they were last set (no argument is set): for a
        kernel launched many times in a row with the same arguments, set once with :meth:`set_args`."""
        return self._cl.enqueue_nd_range_kernel(
            queue, self.kernel, global_size, local_size, global_work_offset=global_offset
        )

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.__dict__["kernel"], name)

    def __repr__(self):
        return f"rsocl.device.kernel.Kernel({self.kernel.function_name!r})"
