"""Device buffers reused from one call to the next: a memory pool per rsocl device (its queue).

A reconstruction makes a few dozen device arrays (the snapshots, the operator's geometry, the
ADMM's and the regularizer's arrays, the inverse blocks, scratch for reductions) and frees them when
it returns. Where creating and releasing an OpenCL buffer is a device allocation and release (a GPU
driver's; a release may wait for the device), a stream of small calls, a live camera's, pays for
them on every call. On such devices (not a CPU, unless :data:`ON_CPU`) rsocl's arrays therefore come
from :class:`BufferPool`: a :class:`pyopencl.tools.MemoryPool` that keeps freed buffers and hands
them out again for requests of their size class.

The pool holds at most :data:`HELD_BYTES` (or :data:`HELD_SHARE` of the device's memory, the smaller)
of freed buffers; a buffer above :data:`LARGEST_BYTES` is never pooled: its call is long, and its
memory goes back to the device when it is freed. Where the device refuses such a buffer, the
held ones are given back and the allocation is tried once more (pyopencl's pool does so for its
own). :func:`release` gives the held buffers back (to make room for another program on the
device). Set :data:`LARGEST_BYTES` to 0 to pool nothing.

The pool's size classes are exact (:data:`SIZE_BITS`): a buffer is reused for a request of its very size,
and the pool takes no byte more than asked, so the memory counts of :mod:`rsocl.solver.memory` hold.

A pooled buffer is reused on the queue it was made for: rsocl's queues are in order, so a reused
buffer is written only after every command enqueued on it before. Its contents are not cleared:
what needs zeros fills them (``zeros``).

Calls per buffer, measured: ``docs/call_cost.md``.
"""

from __future__ import annotations

import numpy as np

from rsocl.device.context import device_for_queue

__all__ = [
    "BufferPool",
    "LARGEST_BYTES",
    "HELD_BYTES",
    "HELD_SHARE",
    "ON_CPU",
    "pool_for",
    "release",
    "empty",
    "zeros",
    "to_device",
    "buffer",
    "copy",
    "same_memory",
]

#: Largest buffer the pool hands out, bytes; larger ones are made and released each time. 0: no pooling.
LARGEST_BYTES = 64 * 2**20
#: Most bytes of freed buffers the pool keeps, and the share of the device's global memory (the smaller wins).
#: Whether a CPU device pools too. There a buffer's creation is a host allocation, and a call takes the
#: same time with or without the pool (``docs/call_cost.md``), which would only hold memory.
ON_CPU = False
HELD_BYTES = 512 * 2**20
HELD_SHARE = 1 / 8
#: Significant bits of a size class of :class:`pyopencl.tools.MemoryPool`: every size up to 2**26 bytes
#: (64 MiB, :data:`LARGEST_BYTES` at most) is a class of its own.
SIZE_BITS = 26


class BufferPool:
    """An allocator of device buffers on ``queue`` (a pyopencl in-order queue) that reuses freed ones.

    Called with a size in bytes, it returns a buffer (a pooled one up to ``largest`` bytes, a plain
    :class:`pyopencl.Buffer` above), usable wherever pyopencl takes a buffer, and as the
    ``allocator`` of a :class:`pyopencl.array.Array`.

    Parameters
    ----------
    queue : pyopencl.CommandQueue
    largest : int or None
        Largest pooled buffer, bytes (0: none, at most 2**:data:`SIZE_BITS`); None: :data:`LARGEST_BYTES`
        as it is at each call.
    held : int or None
        Most bytes of freed buffers kept; None: the smaller of :data:`HELD_BYTES` and
        :data:`HELD_SHARE` of the device's memory.

    Examples
    --------
    >>> import numpy as np, pyopencl.array as cla
    >>> from rsocl.device import get_device
    >>> from rsocl.device.pool import BufferPool
    >>> pool = BufferPool(get_device().queue)
    >>> a = cla.empty(get_device().queue, (1000,), np.float32, allocator=pool)
    >>> del a
    >>> pool.held_bytes > 0
    True
    """

    def __init__(self, queue, largest: int | None = None, held: int | None = None):
        import pyopencl as cl
        import pyopencl.tools as cl_tools

        self.queue, self._largest = queue, largest
        self.enabled = True  # False: every buffer made and released as pyopencl would (pool_for's choice)
        if held is None:
            held = min(HELD_BYTES, int(HELD_SHARE * int(queue.device.global_mem_size)))
        self.held = int(held)
        # the pool's own buffers are allocated when made, so that it sees a shortage and frees what it holds
        self._pool = cl_tools.MemoryPool(cl_tools.ImmediateAllocator(queue), SIZE_BITS)
        self._cl = cl
        self.made = 0  # buffers made by the device (pooled ones made once, and every unpooled one)

    @property
    def largest(self) -> int:
        """Largest pooled buffer, bytes (sizes above 2**:data:`SIZE_BITS` would be rounded up: never pooled)."""
        if not self.enabled:
            return 0
        return min(LARGEST_BYTES if self._largest is None else int(self._largest), 2**SIZE_BITS)

    @property
    def held_bytes(self) -> int:
        """Bytes of freed buffers the pool keeps now."""
        return int(self._pool.managed_bytes - self._pool.active_bytes)

    def __call__(self, nbytes: int):
        nbytes = int(nbytes)
        if nbytes <= 0:
            raise ValueError(f"nbytes must be > 0, got {nbytes}")
        if nbytes > self.largest:  # made outside the pool, as pyopencl makes a buffer
            self.made += 1
            try:
                return self._plain(nbytes)
            except self._cl.MemoryError:  # the device refused it: the held buffers go back first
                self._pool.free_held()
                return self._plain(nbytes)
        if self.held_bytes + nbytes > self.held:  # a new buffer may follow: keep what is held within the cap
            self._pool.free_held()
        before = self._pool.managed_bytes
        out = self._pool.allocate(nbytes)
        if self._pool.managed_bytes > before:
            self.made += 1
        return out

    def _plain(self, nbytes: int):
        return self._cl.Buffer(self.queue.context, self._cl.mem_flags.READ_WRITE, nbytes)

    def release(self):
        """Give every held (freed) buffer back to the device."""
        self._pool.free_held()


def pool_for(queue) -> BufferPool:
    """The :class:`BufferPool` of ``queue``'s rsocl device (made at the first call): one that pools on a
    device that is not a CPU, and on a CPU device with :data:`ON_CPU` (else it makes every buffer)."""
    device = device_for_queue(queue)
    pool = device.__dict__.get("_buffer_pool")
    if pool is None:
        pool = device.__dict__["_buffer_pool"] = BufferPool(device.queue)
    pool.enabled = ON_CPU or not device.is_cpu
    return pool


def release(queue) -> None:
    """Give the held buffers of ``queue``'s pool back to the device (nothing when it has no pool)."""
    pool = device_for_queue(queue).__dict__.get("_buffer_pool")
    if pool is not None:
        pool.release()


def empty(queue, shape, dtype):
    """An uninitialised device array from ``queue``'s pool (:func:`pyopencl.array.empty`)."""
    import pyopencl.array as cla

    return cla.empty(queue, shape, dtype, allocator=pool_for(queue))


def zeros(queue, shape, dtype):
    """A device array of zeros from ``queue``'s pool (:func:`pyopencl.array.zeros`)."""
    import pyopencl.array as cla

    return cla.zeros(queue, shape, dtype, allocator=pool_for(queue))


def to_device(queue, array, *, wait: bool = False):
    """A device copy of host ``array`` (C-contiguous) from ``queue``'s pool; the copy is not waited
    for unless ``wait`` (pyopencl keeps ``array`` alive until it is done)."""
    import pyopencl.array as cla

    return cla.to_device(queue, np.ascontiguousarray(array), allocator=pool_for(queue), async_=not wait)


def buffer(queue, nbytes: int):
    """A raw device buffer of ``nbytes`` bytes from ``queue``'s pool."""
    return pool_for(queue)(nbytes)


def copy(array):
    """A device copy of device ``array`` (a pyopencl Array) from its queue's pool (enqueued)."""
    import pyopencl as cl

    out = empty(array.queue, array.shape, array.dtype)
    if array.nbytes:
        cl.enqueue_copy(array.queue, out.data, array.data, byte_count=array.nbytes)
    return out


def same_memory(a, b) -> bool:
    """Whether device arrays ``a`` and ``b`` (pyopencl Arrays) start at the same place of the same buffer:
    a copy of one onto the other would overlap."""
    return (getattr(a.base_data, "int_ptr", None), a.offset) == (getattr(b.base_data, "int_ptr", None), b.offset)
