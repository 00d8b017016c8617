"""The device passes of the separable periodized DWT: one analysis or synthesis pass along an
axis of a box of sub-frames, box copies, and the level loops of one block of a wavelet plan.

Buffers are ``pyopencl`` buffers holding ``(T, m, n)`` arrays; a block is ``(t0, frames, axes)``
of :class:`rsocl_plugins.wavelet_filters.Plan`.
"""

from __future__ import annotations

import numpy as np

from rsocl.device.launch import voxel_grid

__all__ = ["approximation_box", "copy_box", "copy_frames", "run_pass", "analysis_levels", "synthesis_levels"]


def approximation_box(block, shape, level):
    """Approximation box ``(ct, cy, cx)`` of ``block`` after ``level`` levels."""
    _, frames, axes = block
    sizes = (frames, int(shape[1]), int(shape[2]))
    return tuple(s >> level if a in axes else s for a, s in enumerate(sizes))


def copy_box(queue, dst, src, shape, t0, box, itemsize):
    """Copy the sub-box ``[t0, t0 + ct) x [0, cy) x [0, cx)`` from ``src`` to ``dst``."""
    import pyopencl as cl

    _, m, n = shape
    ct, cy, cx = box
    pitches = (n * itemsize, m * n * itemsize)
    cl.enqueue_copy(
        queue,
        dst,
        src,
        src_origin=(0, 0, t0),
        dst_origin=(0, 0, t0),
        region=(cx * itemsize, cy, ct),
        src_pitches=pitches,
        dst_pitches=pitches,
    )


def copy_frames(queue, dst, src, shape, block, itemsize):
    """Copy the sub-frames ``[t0, t0 + frames)`` of ``block`` from ``src`` to ``dst``."""
    import pyopencl as cl

    t0, frames, _ = block
    plane = int(shape[1]) * int(shape[2]) * itemsize
    cl.enqueue_copy(queue, dst, src, byte_count=frames * plane, src_offset=t0 * plane, dst_offset=t0 * plane)


def run_pass(prog, name, queue, src, dst, axis, shape, t0, box):
    _, m, n = shape
    ct, cy, cx = box
    gsize, lsize = voxel_grid(ct, cy, cx)
    values = tuple(np.int32(v) for v in (axis, m, n, t0, ct, cy, cx))
    # one kernel object per pass: its by-value arguments are set once, not on every call
    prog.instance(name, values)(queue, gsize, lsize, src, dst, *values)


def analysis_levels(prog, queue, src, bufs, shape, itemsize, levels, block):
    """Analysis of ``block`` of ``src`` over ``levels``; returns the index i of ``bufs``
    holding its coefficients, ``(len(axes) - 1) % 2``.

    Level 0 ping-pongs ``src -> bufs[0] -> bufs[1] -> ...``; deeper levels work
    on the shrinking approximation box and keep the result in ``bufs[i]`` (a
    box copy when the number of axes is odd). ``src`` is only read, and
    nothing outside the block is written.
    """
    t0, _, axes = block
    cur = (len(axes) - 1) % 2
    for level in range(levels):
        box = approximation_box(block, shape, level)
        if level == 0:
            s = src
            for i, a in enumerate(axes):
                run_pass(prog, "dwt_analysis", queue, s, bufs[i % 2], a, shape, t0, box)
                s = bufs[i % 2]
            continue
        s = cur
        for i, a in enumerate(axes):
            d = 1 - cur if i % 2 == 0 else cur
            run_pass(prog, "dwt_analysis", queue, bufs[s], bufs[d], a, shape, t0, box)
            s = d
        if s != cur:
            copy_box(queue, bufs[cur], bufs[s], shape, t0, box, itemsize)
    return cur


def synthesis_levels(prog, queue, bufs, cur, shape, itemsize, levels, block):
    """Synthesis of ``block`` from the coefficients in ``bufs[cur]`` (overwritten); returns
    the index of the buffer holding the result: ``cur`` for an even number of axes, else ``1 - cur``."""
    t0, _, axes = block
    s = cur
    for level in reversed(range(levels)):
        box = approximation_box(block, shape, level)
        s = cur
        for i, a in enumerate(reversed(axes)):
            d = 1 - cur if i % 2 == 0 else cur
            run_pass(prog, "dwt_synthesis", queue, bufs[s], bufs[d], a, shape, t0, box)
            s = d
        if level > 0 and s != cur:
            copy_box(queue, bufs[cur], bufs[s], shape, t0, box, itemsize)
    return s
