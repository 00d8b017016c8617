"""The TV's plain path: Chambolle's iterations on one work item per voxel (``kernels/tv.cl``), bound once.

Three ways through the same arithmetic (``one_launch``):

- 0: two launches per iteration on one copy of the dual ``p``: ``tv_primal`` writes the primal, then
  ``tv_dual`` reads it and updates ``p`` in place;
- 1: one launch per iteration on two copies of ``p``: ``tv_step`` reads one copy and writes the
  other, each work item computing the primal of its voxel and of its three next neighbours itself, so
  no launch writes the primal. Fewer launches and fewer bytes, more arithmetic;
- 2: one launch per two iterations on two copies of ``p``: ``tv_step2``, each work item also stepping
  the dual of the twelve voxels around it that the second iteration reads (an odd count of steps ends
  with one ``tv_step``). Half the launches of 1 for about 13 times its arithmetic.

All start from ``p = 0``: the first iteration is ``tv_dual_first``, or with ``first2`` (and 1 or 2, and
at least 3 iterations) the first two are one launch (``tv_first2``, reading only the input: the bytes
of ``tv_dual_first``, each work item stepping the dual of the twelve voxels around it from ``p = 0``
itself). All end with the primal of the last ``p`` (``tv_primal``, or ``tv_primal_update`` when the
ADMM's dual update is folded in). A run of ``iterations`` Chambolle iterations is ``2 iterations - 2``
launches with 0, ``iterations`` with 1 and ``2 + ceil((iterations - 2) / 2)`` with 2; with ``first2``
and at least 3 iterations, ``iterations - 1`` with 1 and ``2 + ceil((iterations - 3) / 2)`` with 2; for
each launch grid of :func:`rsocl_plugins.tv.launches`. A :class:`Bound` call that defers its last
launch to the ADMM's projection makes one less.

:func:`sequence` sets every kernel argument and returns the launches; :class:`Bound` keeps them with
their arrays for a caller that runs the denoiser many times on the same arrays.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import pyopencl.array as cla

__all__ = ["Arrays", "Bound", "sequence", "enqueue", "final_dual", "first_two"]


@dataclass(frozen=True)
class Arrays:
    """The device arrays a plain TV run reads and writes: input ``x`` and output ``out`` (``(T, m, n)``
    or ``(B, T, m, n)``), the per-set ``steps`` of ``tv.cl`` (step lengths and temporal weight), the
    dual copies ``p`` (one, or two for ``one_launch`` 1 and 2), ``xnext``, and the ADMM's ``(b, f, dual)`` when
    its dual update is folded in."""

    x: cla.Array
    out: cla.Array
    steps: cla.Array
    p: tuple
    xnext: cla.Array
    dual: tuple | None = None


def sequence(prog, grids, arrays: Arrays, iterations: int, one_launch: int, owner=None, first2=False) -> list:
    """The launches ``(kernel, global, local, offset)`` of one plain TV run of ``iterations`` (>= 2)
    Chambolle iterations on ``arrays``, every argument set; ``one_launch`` 0, 1 or 2 and ``first2``: the
    module docstring.

    With an ``owner`` the kernel objects are its own while it lives (``prog.lease``): enqueuing the list
    again runs the denoiser again on the arrays' current contents (:class:`Bound`). Without one they are
    the program's objects for calls that enqueue their sequence at once (the next sequence made without
    an owner sets their arguments again).
    """
    if iterations < 2:
        raise ValueError(f"iterations must be >= 2 for a launch sequence, got {iterations}")
    one_launch = int(one_launch)
    if one_launch not in (0, 1, 2):
        raise ValueError(f"one_launch must be 0, 1 or 2, got {one_launch}")
    copies = 2 if one_launch else 1
    if len(arrays.p) != copies:
        raise ValueError(f"one_launch={one_launch} takes {copies} dual copies, got {len(arrays.p)}")
    x, out = arrays.x, arrays.out
    sets = x.shape[0] if x.ndim == 4 else 1
    T, m, n = x.shape[-3:]
    sizes = (np.int32(T), np.int32(m), np.int32(n), np.int32(sets))
    made = itertools.count()

    def bound(name, *args):
        kernel = prog.lease(name, owner) if owner is not None else prog.instance(name, ("tv_plain", next(made)))
        kernel.set_args(*args)
        return [(kernel, gsize, lsize, offset) for gsize, lsize, offset in grids]

    p0 = arrays.p[0]
    steps, xnext = arrays.steps.data, arrays.xnext.data
    if first_two(iterations, one_launch, first2):
        launches = bound("tv_first2", x.data, p0.data, xnext, steps, *sizes)
    else:
        launches = bound("tv_dual_first", x.data, p0.data, xnext, steps, *sizes)
    if one_launch:
        pa, pb = arrays.p
        kinds = _steps(iterations, one_launch, first2)
        ping_pong = {}  # (kernel, direction): its launches, bound once
        for k, name in enumerate(kinds):
            if (name, k % 2) not in ping_pong:
                src, dst = (pa, pb) if k % 2 == 0 else (pb, pa)
                ping_pong[name, k % 2] = bound(name, x.data, src.data, dst.data, xnext, steps, *sizes)
            launches += ping_pong[name, k % 2]
        last = final_dual(arrays, iterations, one_launch, first2)
    else:
        primal = bound("tv_primal", x.data, p0.data, out.data, steps, *sizes)
        dual = bound("tv_dual", out.data, p0.data, xnext, steps, *sizes)
        for _ in range(iterations - 2):
            launches += primal + dual
        last = p0
    if arrays.dual is None:
        launches += bound("tv_primal", x.data, last.data, out.data, steps, *sizes)
    else:  # the last primal step makes the ADMM's dual update
        b, f, on = arrays.dual
        launches += bound("tv_primal_update", x.data, last.data, out.data, steps, *sizes, b.data, f.data, on.data)
    return launches


def first_two(iterations: int, one_launch: int, first2: bool) -> bool:
    """Whether :func:`sequence` makes the first two Chambolle iterations in one launch (``tv_first2``)."""
    return bool(first2) and bool(one_launch) and iterations >= 3


def _steps(iterations: int, one_launch: int, first2: bool) -> list:
    """The kernels (``tv_step2``, ``tv_step``) that step the dual after the first launch, ping-pong
    between the two copies of ``p`` from the first."""
    left = iterations - (3 if first_two(iterations, one_launch, first2) else 2)
    doubles = left // 2 if one_launch == 2 else 0
    return ["tv_step2"] * doubles + ["tv_step"] * (left - 2 * doubles)


def final_dual(arrays: Arrays, iterations: int, one_launch: int, first2: bool = False):
    """The copy of ``p`` in ``arrays`` that holds the dual after :func:`sequence`'s launches (its last primal
    step reads it)."""
    if not one_launch:
        return arrays.p[0]
    return arrays.p[len(_steps(iterations, one_launch, first2)) % 2]


def enqueue(queue, launches) -> None:
    """Enqueue the launches of :func:`sequence` on ``queue``, in order."""
    for kernel, gsize, lsize, offset in launches:
        kernel.enqueue(queue, gsize, lsize, offset)


class Bound:
    """A plain TV run bound to its arrays (the arguments of :func:`sequence`, ``owner`` aside): calling it
    enqueues the launches, made with kernel objects of its own, on ``queue``. It holds the arrays, so
    none of them, the dual copies included, is released while it lives.

    With ``defer`` (and the ADMM's dual update folded in, ``arrays.dual``), a call leaves out the last
    launch (``tv_primal_update``: the output and the dual update from the final dual): the caller's next
    launch makes it (the ADMM's projection, ``kernels/admm.cl``), reading :attr:`deferred`, or
    :meth:`finish` enqueues it. Without, :attr:`deferred` is None."""

    def __init__(self, queue, prog, grids, arrays: Arrays, iterations: int, one_launch: int, defer=False, first2=False):
        self.queue, self.arrays = queue, arrays
        self.launches = sequence(prog, grids, arrays, iterations, one_launch, owner=self, first2=first2)
        self.last: list = []
        #: ``(p, steps)``: the final dual (``tv.cl``'s layout) and the per-set steps, for the deferred step.
        self.deferred = None
        if defer and arrays.dual is not None:
            self.launches, self.last = self.launches[: -len(grids)], self.launches[-len(grids) :]
            self.deferred = (final_dual(arrays, iterations, one_launch, first2), arrays.steps)

    def __call__(self) -> None:
        enqueue(self.queue, self.launches)

    def finish(self) -> None:
        """Enqueue the deferred last launch (nothing without :attr:`deferred`)."""
        enqueue(self.queue, self.last)
