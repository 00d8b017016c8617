"""Building OpenCL programs from the kernels shipped with rsocl, and the built program's kernels.

:func:`build_program` joins ``common.cl`` and the named ``kernels/*.cl`` files (found with
:mod:`importlib.resources`, so wheel and editable installs alike) under ``#define`` lines of
the real type and options, builds them for OpenCL C 1.2 and returns :class:`Kernels`, whose kernels
are created once. :meth:`rsocl.device.Device.program` caches one build per device and definitions.
"""

from __future__ import annotations

import re
import threading
import warnings
import weakref
from importlib import resources

import numpy as np

from rsocl.device.kernel import Kernel

__all__ = ["BUILD_OPTIONS", "Kernels", "build_program", "c_type", "kernel_source", "meaningful_log"]


def c_type(dtype) -> str:
    """OpenCL C name of a float32/float64 NumPy dtype (``"float"`` or ``"double"``)."""
    return "double" if np.dtype(dtype) == np.float64 else "float"


def kernel_source(name: str) -> str:
    """Text of ``kernels/<name>`` from the installed package (wheel or editable)."""
    return resources.files("rsocl.kernels").joinpath(name).read_text(encoding="utf-8")


#: A build-log line that says nothing about the program: NVIDIA's OpenCL (drivers from about 550 on)
#: writes it for every kernel of every program it compiles (``docs/implementation_notes.md``).
_DRIVER_NOISE = re.compile(
    r"Warning: Function \w+ is a kernel, so overriding noinline attribute\. "
    r"The function may be inlined when called\."
)


def meaningful_log(log: str) -> str:
    """A program's build log without blank lines and the driver's noise (:data:`_DRIVER_NOISE`)."""
    return "\n".join(line for line in log.splitlines() if line.strip() and not _DRIVER_NOISE.search(line))


#: OpenCL 1.2, with subnormal numbers flushed to zero: TV spreading a bright point through a black
#: background decays into float32 subnormals, on which a CPU takes 10-40x longer (a 64x64 star field:
#: 45 s instead of 6.8 s self-tuned, the same PSNR and choices); nothing rsocl computes needs them.
BUILD_OPTIONS = ["-cl-std=CL1.2", "-cl-denorms-are-zero"]


def build_program(context, files, defines) -> Kernels:
    """Build ``common.cl`` + ``files`` with ``defines``; warn only for a build log beyond :data:`_DRIVER_NOISE`."""
    import pyopencl as cl

    lines = []
    uses_double = any(v == "double" for _, v in defines)
    if uses_double:
        lines.append("#pragma OPENCL EXTENSION cl_khr_fp64 : enable")
    lines += [f"#define {k} {v}" for k, v in defines]
    lines.append(f"#define REAL_IS_DOUBLE {int(dict(defines).get('REAL') == 'double')}")
    source = "\n".join(lines) + "\n" + "\n".join(kernel_source(f) for f in ("common.cl",) + tuple(files))
    for attempt in (1, 2):  # once more on a failed clBuildProgram: processes filling PoCL's kernel cache
        program = cl.Program(context, source)  # together can read another's half-written entry
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                program.build(options=BUILD_OPTIONS)
                break
            except cl.Error as exc:
                if attempt == 2 or "clBuildProgram" not in str(exc):
                    raise
    if caught:
        said = any(meaningful_log(program.get_build_info(dev, cl.program_build_info.LOG)) for dev in context.devices)
        for w in caught:
            if said or not issubclass(w.category, cl.CompilerWarning):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return Kernels(program)


class Kernels:
    """A built program whose kernels are created once and reused (``prog.forward(queue, ...)``).

    Each is an :class:`rsocl.device.kernel.Kernel`: called like a ``pyopencl.Kernel``, it sets a by-value
    argument only when its value changes (:mod:`rsocl.device.kernel`).

    **Threads.** OpenCL lets threads share a program and a queue but not a kernel object: an argument
    one thread sets would be the one another thread's launch takes. The kernels of ``prog.NAME`` and of
    :meth:`instance` are therefore each thread's own (made on a thread's first use and freed with the
    thread), and :meth:`lease` hands an object to one owner at a time; threads can reconstruct side by
    side with one program and one queue.
    """

    def __init__(self, program):
        self.program = program
        self._kernels = threading.local()  # attributes: this thread's kernel objects, by name
        self._instances = threading.local()  # attributes: this thread's instances, by (name, key)

    #: at most this many instances of :meth:`instance` are kept per program and thread (the oldest go first)
    MAX_INSTANCES = 256

    def instance(self, name: str, key):
        """A kernel object ``name`` of its own for ``key`` (any hashable) and this thread, made once.

        A kernel launched with a few recurring sets of by-value arguments (one per pass of a
        multi-pass transform, say) sets each set once when every set has its own instance: pass
        the by-value arguments themselves, or what determines them, as ``key``.
        """
        instances = self._instances.__dict__
        k = (name, key)
        if k not in instances:
            kernel = self._create(name)
            if len(instances) >= self.MAX_INSTANCES:
                del instances[next(iter(instances))]
            instances[k] = kernel
        return instances[k]

    def lease(self, name: str, owner) -> Kernel:
        """A kernel object ``name`` for ``owner`` (any object that can be weakly referenced) alone, while
        ``owner`` lives; then it goes back to this program's pool and a later owner gets it.

        For an object made again and again (a solver per call and per search candidate) that sets every
        argument it uses once and then only enqueues: its kernel objects are reused, not created each
        time (creating one costs tens of launches on PoCL: docs/implementation_notes.md).
        """
        pool = self.__dict__.setdefault("_pool", {}).setdefault(name, [])
        try:
            kernel = pool.pop()  # one step, so that two threads never get one object
        except IndexError:
            kernel = self._create(name)
        weakref.finalize(owner, pool.append, kernel)
        return kernel

    def _create(self, name: str) -> Kernel:
        import pyopencl as cl

        try:
            return Kernel(cl.Kernel(self.program, name))
        except cl.Error as exc:
            raise AttributeError(f"no kernel {name!r} in this program") from exc

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        kernels = self.__dict__["_kernels"].__dict__
        try:
            return kernels[name]
        except KeyError:
            kernel = kernels[name] = self._create(name)
            return kernel
