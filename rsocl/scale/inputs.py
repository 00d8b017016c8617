"""The snapshots of a tiled reconstruction: arrays in memory, or a capture file read tile by tile.

Either source hands each task only its tile's block (:meth:`block`), gives the SHA-256 digest
of all its snapshots (a store records it, so that a resumed run is known to have the same
input) and counts the saturated pixels. :func:`scan` also refuses a set holding NaN or inf,
or no pixel below saturation, naming the set (:meth:`where`), before any task runs.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from rsocl.common import validation as check
from rsocl.files.hdf5_header import complete_set_count, open_checked, read_rig, real_dataset
from rsocl.model.rig import Rig
from rsocl.scale.work import FileBlock

__all__ = ["ArraySets", "CaptureSets", "scan"]


def _digest_update(digest, array) -> None:
    array = np.ascontiguousarray(array, dtype=np.float64)
    digest.update(str(array.shape).encode())
    digest.update(array.tobytes())


class ArraySets:
    """Snapshots ``(K, m, n)`` (one set) or ``(S, K, m, n)`` (``S`` sets) in memory.

    ``n_sets`` is None for one set given as ``(K, m, n)``.
    """

    def __init__(self, g, rig: Rig, name="g"):
        g = np.asarray(g)
        expected = (rig.n_channels,) + rig.shape
        if g.shape == expected:
            self.n_sets = None
        elif g.ndim == 4 and g.shape[1:] == expected and g.shape[0] >= 1:
            self.n_sets = g.shape[0]
        else:
            raise ValueError(
                f"{name} must have shape (K, m, n) = {expected} or (S, K, m, n) with S >= 1 sets "
                f"for this rig, got {g.shape}"
            )
        self.g, self.rig, self.name = g, rig, name
        for set_index, one in self.sets():
            check.finite_array(self.where(set_index), one)

    def where(self, set_index) -> str:
        """The snapshots of set ``set_index`` (None: the only set) as an error message names them."""
        return self.name if set_index is None else f"{self.name}[{set_index}] (set {set_index})"

    def sets(self):
        """``(set index or None, snapshots (K, m, n))`` for every set."""
        if self.n_sets is None:
            yield None, self.g
        else:
            yield from enumerate(self.g)

    def block(self, set_index, tile):
        rows, cols = tile.outer_slices
        g = self.g if set_index is None else self.g[set_index]
        return np.ascontiguousarray(g[:, rows, cols])


class CaptureSets:
    """A capture file (:mod:`rsocl.files.hdf5`, format 1) whose snapshots each task reads itself.

    Parameters
    ----------
    path : str or os.PathLike
        The capture file (HDF5), on storage every worker can read.
    all_sets : bool
        Every set of ``snapshot_sets`` ``(S, K, m, n)`` (a capture of several sets) instead of
        the first set, ``snapshots`` ``(K, m, n)``.
    """

    def __init__(self, path, all_sets=False, name="capture"):
        with open_checked(path, "capture", name) as h5:
            self.path = Path(h5.filename)
            self.rig = read_rig(h5, f"{name}: {str(self.path)!r}")
            complete = complete_set_count(h5, f"{name}: {str(self.path)!r}")  # refuses a capture with none
            self.dataset = "snapshot_sets" if all_sets else "snapshots"
            if self.dataset not in h5:
                hint = " (it holds one set: leave out --sets)" if all_sets else ""
                raise ValueError(f"{name}: {str(self.path)!r} has no dataset {self.dataset!r}{hint}")
            shape = real_dataset(
                h5, self.dataset, f"{name}: {str(self.path)!r}", (self.rig.n_channels,) + self.rig.shape
            ).shape
            self.has_truth = "truth" in h5
        self.n_sets = min(shape[0], complete) if all_sets else None  # the complete sets only

    def where(self, set_index) -> str:
        """The snapshots of set ``set_index`` (None: dataset ``snapshots``) as an error message names them."""
        which = f"dataset {self.dataset!r}" if set_index is None else f"set {set_index} of dataset {self.dataset!r}"
        return f"capture {str(self.path)!r}: {which}"

    def sets(self):
        import h5py

        with h5py.File(self.path, "r") as h5:
            data = h5[self.dataset]
            if self.n_sets is None:
                yield None, data[()]
            else:
                for s in range(self.n_sets):
                    yield s, data[s]

    def block(self, set_index, tile):
        return FileBlock(str(self.path.resolve()), self.dataset, set_index)

    def truth(self):
        """The capture's ground truth ``(T, m, n)`` (set 0), or None."""
        import h5py

        if not self.has_truth:
            return None
        with h5py.File(self.path, "r") as h5:
            return h5["truth"][()]


def scan(source, saturation=None) -> tuple:
    """One pass over every set of ``source``: ``(SHA-256 hex digest, saturated pixel count, levels)``, with
    ``levels`` each set's :class:`~rsocl.solver.static.Levels` (the static-part fix's measures of the
    whole frame, which every tile takes).

    A ValueError naming the set (:meth:`where`) when a set holds NaN or inf, or when none of its
    pixels is below ``saturation`` (nothing to fit, as :func:`rsocl.reconstruct` refuses it).
    """
    from rsocl.solver.static import levels

    digest, saturated, measured = hashlib.sha256(), 0, []
    for set_index, g in source.sets():
        check.finite_array(source.where(set_index), g)
        _digest_update(digest, g)
        measured.append(levels(g))
        if saturation is None:
            continue
        valid = g < saturation
        if not valid.any():
            raise ValueError(
                f"every snapshot pixel of {source.where(set_index)} is >= saturation = "
                f"{saturation!r}: nothing left to fit"
            )
        saturated += int(valid.size - np.count_nonzero(valid))
    return digest.hexdigest(), saturated, tuple(measured)
