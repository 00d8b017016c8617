"""OpenCL device selection (programs are built by :mod:`rsocl.device.program`).

Selection order: an explicit ``device`` argument, the ``RSOCL_DEVICE`` environment variable,
``PYOPENCL_CTX``, else the first GPU, else the first CPU. A device spec is ``"P:D"`` (platform and
device index, as ``rsocl devices`` prints them), ``"P"`` (first device of platform P), or a
case-insensitive substring of the platform or device name (``"pocl"``, ``"nvidia"``, ``"cpu"``, ``"gpu"``).
An empty or blank spec, given or in ``RSOCL_DEVICE``, counts as none: the next in that order chooses.
"""

from __future__ import annotations

import functools
import os
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from rsocl.common import validation as check
from rsocl.common.validation import positive_int as check_positive
from rsocl.device.program import build_program

if TYPE_CHECKING:
    import pyopencl as cl

__all__ = [
    "Device",
    "check_process",
    "get_device",
    "device_for_queue",
    "list_devices",
    "NoOpenCLError",
    "INSTALL_HINT",
]

INSTALL_HINT = 'install an OpenCL runtime, e.g. the CPU one that ships as a wheel: pip install "rsocl[pocl]"'


class NoOpenCLError(RuntimeError):
    """No usable OpenCL platform or device was found."""


def _cl():
    try:
        import pyopencl as cl
    except ImportError as exc:  # pragma: no cover - pyopencl is a dependency
        raise NoOpenCLError(f"pyopencl is not importable ({exc}); {INSTALL_HINT}") from exc
    return cl


#: The process in which rsocl first called the OpenCL runtime (None: none yet), and the lock under which a
#: device or a program is made (threads asking for one at once share the one that the first makes).
_RUNTIME_PID: int | None = None
_MAKING = threading.RLock()


def check_process() -> None:
    """Raise a RuntimeError in a process forked from one in which rsocl had called the OpenCL runtime.

    OpenCL runtimes do not survive a fork: the child's calls wait for threads of the parent's runtime
    that the child does not have (PoCL's wait for ever, even on a context the child makes itself).
    Processes started with ``spawn`` or ``forkserver``, or forked before rsocl's first OpenCL call, are
    free to use it.
    """
    global _RUNTIME_PID
    pid = os.getpid()
    if _RUNTIME_PID is None:
        _RUNTIME_PID = pid
    elif _RUNTIME_PID != pid:
        raise RuntimeError(
            f"this process ({pid}) was forked from process {_RUNTIME_PID} after rsocl had started the OpenCL "
            "runtime there, and OpenCL runtimes do not survive a fork (their calls would wait for ever): start "
            "worker processes with the 'spawn' or 'forkserver' method (multiprocessing.get_context('spawn').Pool(), "
            "ProcessPoolExecutor(mp_context=...)), or before rsocl's first call in the parent"
        )


def list_devices() -> list[tuple[int, int, cl.Platform, cl.Device]]:
    """Every OpenCL device, ``(P, D, platform, device)`` (``"P:D"`` of :func:`get_device`); ``[]`` when none.

    Raises RuntimeError in a process forked after rsocl called the OpenCL runtime (:func:`check_process`)."""
    cl = _cl()
    check_process()
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return []
    found = []
    for pi, platform in enumerate(platforms):
        try:
            devices = platform.get_devices()
        except cl.Error:
            continue
        for di, dev in enumerate(devices):
            found.append((pi, di, platform, dev))
    return found


def _blank(spec) -> bool:
    """Whether ``spec`` is None or an empty or blank string (no choice: the selection order's next)."""
    return spec is None or (isinstance(spec, str) and not spec.strip())


def _pick(spec: str | None, what: str = "device"):
    """The pyopencl device ``spec`` names (None or blank: the first GPU, else CPU); a ValueError that names
    ``what`` (where the spec came from: ``"device"``, ``"RSOCL_DEVICE"``) and lists the devices."""
    cl = _cl()
    found = list_devices()
    if not found:
        raise NoOpenCLError(f"no OpenCL platform with a device was found; {INSTALL_HINT}")
    if _blank(spec):
        # simulators (Oclgrind) claim every device type: never pick one unasked
        real = [e for e in found if "oclgrind" not in e[2].name.lower()] or found
        for kind in (cl.device_type.GPU, cl.device_type.CPU):
            for entry in real:
                if entry[3].type & kind:
                    return entry[3]
        return real[0][3]
    spec = str(spec).strip()
    parts = spec.split(":")
    if all(part.isdigit() for part in parts) and 1 <= len(parts) <= 2:
        pi = int(parts[0])
        di = int(parts[1]) if len(parts) == 2 else 0
        for entry in found:
            if entry[0] == pi and entry[1] == di:
                return entry[3]
    else:
        low = spec.lower()
        for entry in found:
            dev = entry[3]
            kinds = cl.device_type.to_string(dev.type).lower()
            text = f"{entry[2].name} {entry[2].vendor} {dev.name} {dev.vendor}".lower()
            if low in text or low in kinds:
                return dev
    given = f"{what}={spec!r}" if what.isupper() else f"{what} {spec!r}"
    raise ValueError(f"{given} matches no OpenCL device; available: {_listing(found)}")


def _listing(found) -> str:
    """The devices of :func:`list_devices` ``found`` as an error message lists them: ``P:D platform / device``."""
    return "; ".join(f"{pi}:{di} {p.name} / {d.name}" for pi, di, p, d in found)


@dataclass(eq=False)
class Device:
    """An OpenCL device with its context and in-order queue.

    Attributes
    ----------
    context, queue, device : pyopencl objects
    has_fp64 : bool
        Whether the device supports ``cl_khr_fp64``.
    limits : dict
        Lower limits than the device reports, to run as a smaller device would (see :meth:`limited`).
    """

    context: cl.Context
    queue: cl.CommandQueue
    device: cl.Device
    limits: dict = field(default_factory=dict)

    def limited(self, *, fp64=None, max_work_group_size=None, local_mem_bytes=None, max_work_item_sizes=None) -> Device:
        """This device as one with lower limits would present itself: its own queue and program cache.

        ``fp64=False`` (or ``"no"``) hides ``cl_khr_fp64`` (``True``, ``"yes"``: as the device has
        it); the sizes (work items, bytes) cap what the device reports. Every launch-size and
        local-memory decision of rsocl then follows the lower limits, as on a GPU that has them;
        the kernels still run on this device.
        """
        limits = dict(self.limits)
        given = {
            "fp64": fp64,
            "max_work_group_size": max_work_group_size,
            "local_mem_bytes": local_mem_bytes,
            "max_work_item_sizes": max_work_item_sizes,
        }
        for name, value in given.items():
            if value is None:
                continue
            if name == "fp64":
                limits[name] = _yes_or_no(name, value)
            elif name == "max_work_item_sizes":
                limits[name] = tuple(check_positive(name, v) for v in value)
            else:
                limits[name] = check_positive(name, value)
        cl = _cl()
        found = Device(self.context, cl.CommandQueue(self.context, self.device), self.device, limits)
        _BY_QUEUE[found.queue.int_ptr] = found
        return found

    @property
    def name(self) -> str:
        return f"{self.device.platform.name.strip()} / {self.device.name.strip()}"

    @property
    def has_fp64(self) -> bool:
        if self.limits.get("fp64") is False:
            return False
        return "cl_khr_fp64" in self.device.extensions or bool(getattr(self.device, "double_fp_config", 0))

    @property
    def acc_dtype(self) -> np.dtype:
        """Accumulator of reductions: float64 where the device has it, else float32."""
        return np.dtype(np.float64) if self.has_fp64 else np.dtype(np.float32)

    @property
    def max_alloc_bytes(self) -> int:
        """Largest single buffer, bytes (``CL_DEVICE_MAX_MEM_ALLOC_SIZE``)."""
        return int(self.device.max_mem_alloc_size)

    @property
    def global_mem_bytes(self) -> int:
        """Device memory, bytes (``CL_DEVICE_GLOBAL_MEM_SIZE``)."""
        return int(self.device.global_mem_size)

    @property
    def cache_bytes(self) -> int:
        """Global memory cache, bytes (``CL_DEVICE_GLOBAL_MEM_CACHE_SIZE``; 0 when the device reports none)."""
        return int(getattr(self.device, "global_mem_cache_size", 0) or 0)

    @property
    def is_cpu(self) -> bool:
        """Whether the device is a CPU (``CL_DEVICE_TYPE_CPU``)."""
        return bool(self.device.type & _cl().device_type.CPU)

    @property
    def max_work_group_size(self) -> int:
        """Most work items in a work group (``CL_DEVICE_MAX_WORK_GROUP_SIZE``)."""
        return min(int(self.device.max_work_group_size), self.limits.get("max_work_group_size", 1 << 62))

    @property
    def max_work_item_sizes(self) -> tuple:
        """Most work items of a work group along each dimension (``CL_DEVICE_MAX_WORK_ITEM_SIZES``)."""
        own = self.limits.get("max_work_item_sizes", ())
        return tuple(
            min(int(v), own[i]) if i < len(own) else int(v) for i, v in enumerate(self.device.max_work_item_sizes)
        )

    @property
    def local_mem_bytes(self) -> int:
        """Local memory of a work group, bytes (``CL_DEVICE_LOCAL_MEM_SIZE``)."""
        return min(int(self.device.local_mem_size), self.limits.get("local_mem_bytes", 1 << 62))

    def group_limit(self, *kernels, cap: int | None = None) -> int:
        """Most work items per work group for every one of ``kernels`` on this device (and ``cap``).

        The device's maximum, and each kernel's own (``CL_KERNEL_WORK_GROUP_SIZE``: a GPU lowers it
        for a kernel that needs many registers). Kernels are ``pyopencl.Kernel`` or
        :class:`rsocl.device.kernel.Kernel`.
        """
        import pyopencl as cl

        known = self.__dict__.setdefault("_kernel_groups", {})
        sizes = [self.max_work_group_size] + ([] if cap is None else [int(cap)])
        for kernel in kernels:
            key = (kernel.int_ptr, kernel.function_name)
            if key not in known:
                known[key] = int(kernel.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, self.device))
            sizes.append(known[key])
        return max(1, min(sizes))

    def real_dtype(self, dtype) -> np.dtype:
        """Validate ``dtype`` (``"float32"`` or ``"float64"``) for this device."""
        dt = check.real_dtype("dtype", dtype)
        if dt == np.float64 and not self.has_fp64:
            raise ValueError(
                f"dtype='float64' needs cl_khr_fp64, which device {self.name!r} does not support; "
                "use dtype='float32' or another device"
            )
        return dt

    def check_fits(self, what: str, nbytes: int, total_bytes: int | None = None, dtype=None, also: str = ""):
        """Raise a ``ValueError`` with the numbers when a buffer (or all of them) would not fit.

        ``dtype`` (the buffers' type) adds the hint to use float32 when it is float64; ``also`` is
        one more way out, put first in the hint.
        """
        hint = f"{also}, " if also else ""
        hint += "reduce the ROI (shape), raise dt"
        if dtype is not None and np.dtype(dtype) == np.float64:
            hint += ", use float32"
        hint += ", or split it into tiles (rsocl plan proposes them; rsocl reconstruct --tile H W)"
        if nbytes > self.max_alloc_bytes:
            raise ValueError(
                f"{what} needs a buffer of {nbytes / 2**20:.1f} MiB, above the device's "
                f"largest allocation of {self.max_alloc_bytes / 2**20:.1f} MiB ({self.name}); {hint}"
            )
        if total_bytes is not None and total_bytes > self.global_mem_bytes:
            raise ValueError(
                f"{what} needs {total_bytes / 2**20:.1f} MiB of device memory in all, above the "
                f"device's {self.global_mem_bytes / 2**20:.1f} MiB ({self.name}); {hint}"
            )

    def program(self, files, **defines):
        """Build (once per device and definitions, one build at a time) the program of ``common.cl`` + ``files``."""
        key = (tuple(files), tuple(sorted(defines.items())))
        if self.limits.get("fp64") is False and "double" in defines.values():
            raise ValueError(f"dtype='float64' needs cl_khr_fp64, which device {self.name!r} does not support")
        cache = self.__dict__.setdefault("_programs", {})
        found = cache.get(key)
        if found is None:
            with _MAKING:  # threads asking for a program at once share one build
                found = cache.get(key)
                if found is None:
                    found = cache[key] = build_program(self.context, key[0], key[1])
        return found


_WORDS = {"yes": True, "true": True, "no": False, "false": False}


def _yes_or_no(name: str, value) -> bool:
    """``value`` as a bool: True/False or the words yes/no, true/false (any case); ValueError naming ``name``."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, str) and value.strip().lower() in _WORDS:
        return _WORDS[value.strip().lower()]
    raise ValueError(f"{name} must be True or False (or 'yes' or 'no'), got {value!r}")


@functools.cache
def _device_for(spec: str | None, env: str | None, ctx_env: str | None) -> Device:
    """The device of ``spec``, else of ``RSOCL_DEVICE`` (``env``), else of ``PYOPENCL_CTX`` (``ctx_env``)."""
    cl = _cl()
    env = None if _blank(env) else env
    if spec is None and ctx_env and env is None:
        try:
            ctx = cl.create_some_context(interactive=False)
        except (cl.Error, RuntimeError, ValueError) as exc:  # pyopencl's words for a PYOPENCL_CTX that matches nothing
            raise ValueError(
                f"PYOPENCL_CTX={ctx_env!r} matches no OpenCL device ({' '.join(str(exc).split())}); "
                f"available: {_listing(list_devices())} (RSOCL_DEVICE or --device choose one too)"
            ) from None
        dev = ctx.devices[0]
    else:
        dev = _pick(spec, "device") if spec is not None else _pick(env, "RSOCL_DEVICE")
        ctx = cl.Context([dev])
    found = Device(ctx, cl.CommandQueue(ctx), dev)
    _BY_QUEUE[found.queue.int_ptr] = found
    return found


def get_device(device: str | Device | None = None) -> Device:
    """The OpenCL device to compute on, with its context, in-order queue and program cache.

    Parameters
    ----------
    device : Device, str or None
        A :class:`Device`, a spec (``"P:D"``, ``"P"`` or a name substring, as the module says), or
        None: the module's selection order (so does an empty or blank spec, as ``--device ""``).

    Returns
    -------
    Device
        Cached: calls with one spec (without one: with the same ``RSOCL_DEVICE`` and ``PYOPENCL_CTX``)
        share one context, queue and program cache, threads asking at once too.

    Raises
    ------
    ValueError
        If ``device`` is neither a Device, a string nor None, or it (or ``RSOCL_DEVICE``, named when it
        chose) matches no device (the message lists them).
    NoOpenCLError
        If no OpenCL platform has a device (the message says what to install).
    RuntimeError
        In a process forked after rsocl called the OpenCL runtime (:func:`check_process`).
    """
    check_process()
    if isinstance(device, Device):
        return device
    if device is not None and not isinstance(device, str):
        raise ValueError(f"device must be a spec string like '0:0' or 'pocl', or an rsocl Device; got {device!r}")
    spec = None if _blank(device) else device
    chosen_by = (os.environ.get("RSOCL_DEVICE"), os.environ.get("PYOPENCL_CTX")) if spec is None else (None, None)
    with _MAKING:
        return _device_for(spec, *chosen_by)


_BY_QUEUE: dict = {}


def device_for_queue(queue) -> Device:
    """The :class:`Device` that owns ``queue``; a queue made outside rsocl is wrapped once.

    Regularizers receive device arrays only and use this to reach the program cache.
    """
    key = queue.int_ptr
    if key not in _BY_QUEUE:
        _BY_QUEUE[key] = Device(queue.context, queue, queue.device)
    return _BY_QUEUE[key]
