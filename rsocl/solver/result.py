"""The :class:`Result` of a reconstruction: the datacube, its per-iteration history, the rig, the parameters."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rsocl.model.rig import Rig

__all__ = ["Result"]


@dataclass
class Result:
    """A reconstruction.

    Attributes
    ----------
    datacube : ndarray, shape (T, m, n)
        The estimate ``theta`` (same intensity units as the scene).
    history : dict of str -> ndarray
        Per iteration: ``residual`` (``‖g - H theta‖/‖g‖``), ``time`` (seconds since
        the start, wall clock, when the host has that iteration's residual: the device
        has finished it), and ``psnr`` (dB, when a ground truth was given).
    rig : Rig
    params : dict
        Everything needed to repeat the run.
    """

    datacube: np.ndarray
    history: dict
    rig: Rig
    params: dict = field(default_factory=dict)

    @property
    def iterations(self) -> int:
        return len(self.history["residual"])

    @property
    def trimmed(self) -> np.ndarray:
        """The ``T_se`` sub-frames kept by the rig's trimming rule."""
        return self.datacube[self.rig.kept_subframes()]
