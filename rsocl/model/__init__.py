"""Layer 2, the forward model: the rig and its row timing (:mod:`~rsocl.model.rig`, exposure windows
in :mod:`~rsocl.model.windows`), the row-timed shutter operator on the device
(:mod:`~rsocl.model.operator`), its dense NumPy reference, test scenes (:mod:`~rsocl.model.scenes`;
video files: :mod:`~rsocl.model.video`) and simulated snapshots. Conventions: the project's
``docs/model.md``.

Imports :mod:`rsocl.common` and :mod:`rsocl.device`.
"""

from rsocl.model.operator import RollingShutterOperator
from rsocl.model.rig import Camera, Rig

__all__ = ["Camera", "Rig", "RollingShutterOperator"]
