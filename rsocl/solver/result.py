"""The :class:`Result` of a reconstruction: the datacube, its per-iteration history, the rig, the parameters."""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field

import numpy as np

from rsocl.model.rig import Rig

__all__ = ["Result"]


@dataclass
class Result:
    """A reconstruction: of one set, or of a batch of sets of the same rig.

    Attributes
    ----------
    datacube : ndarray, shape (T, m, n), or (B, T, m, n) for a batch
        The estimate ``theta`` (same intensity units as the scene).
    history : dict of str -> ndarray
        Per iteration: ``residual`` (``‖g - H theta‖/‖g‖``), ``time`` (seconds since
        the start, wall clock, when the host has that iteration's residual: the device
        has finished it), and ``psnr`` (dB, when a ground truth was given). For a batch
        each is ``(iterations, B)``: one column per set, NaN after the iteration at which a
        set stopped (``tol``, ``iterations="auto"``) while others ran on.
    rig : Rig
    params : dict
        Everything needed to repeat the run (for a batch: ``lam``, ``eta`` and
        ``saturated_pixels`` one per set, ``sets`` the number of sets), with ``quality`` (the rung),
        ``iterations_run``, ``seconds`` (the whole run) and ``search_seconds`` (the search's share),
        wall clock; ``static_pixels`` where the static-part fix ran (:mod:`rsocl.solver.static`).
    """

    datacube: np.ndarray
    history: dict
    rig: Rig
    params: dict = field(default_factory=dict)

    @property
    def iterations(self) -> int:
        return len(self.history["residual"])

    @property
    def seconds(self) -> float | None:
        """Wall time of the whole reconstruction, seconds (search included); None when not recorded."""
        return self.params.get("seconds")

    @property
    def search_seconds(self) -> float | None:
        """Wall time of the parameter search, seconds (0 when none ran); None when not recorded."""
        return self.params.get("search_seconds")

    @property
    def batch(self) -> int | None:
        """Number of sets of a batch; None for a single set."""
        return self.datacube.shape[0] if self.datacube.ndim == 4 else None

    @property
    def trimmed(self) -> np.ndarray:
        """The ``T_se`` sub-frames kept by the rig's trimming rule (of every set of a batch)."""
        return self.datacube[..., self.rig.kept_subframes(), :, :]

    def set(self, index: int) -> Result:
        """Set ``index`` of a batch as a single-set :class:`Result`: its column of the history up to its
        own last iteration, and its ``iterations_run``."""
        if self.batch is None:
            raise ValueError("set() needs a batch result (datacube (B, T, m, n)); this one holds one set")
        if isinstance(index, bool) or not isinstance(index, numbers.Integral) or not -self.batch <= index < self.batch:
            raise ValueError(
                f"index must be an integer in [0, {self.batch - 1}] for a batch of {self.batch} sets, got {index!r}"
            )
        params = dict(self.params)
        params.pop("sets", None)
        for key in ("lam", "eta", "saturated_pixels"):
            if isinstance(params.get(key), list):
                params[key] = params[key][index]
        history = {key: np.asarray(values)[:, index] for key, values in self.history.items()}
        ran = len(history["residual"])  # less the records after the set stopped (NaN: tol, "auto", other batches)
        while ran > 0 and np.isnan(history["residual"][ran - 1]):
            ran -= 1
        if ran < len(history["residual"]):
            history = {key: values[:ran] for key, values in history.items()}
            params["iterations_run"] = ran
        return Result(self.datacube[index], history, self.rig, params)

    def sets(self) -> list:
        """Every set of a batch as a single-set :class:`Result` (:meth:`set`); ``[self]`` for one set."""
        return [self] if self.batch is None else [self.set(i) for i in range(self.batch)]
