"""rsocl: compressive high-speed imaging with an array of rotated rolling-shutter cameras.

Describe the array with :class:`Camera` and :class:`Rig`, apply the row-timed
shutter operator with :class:`RollingShutterOperator`, and recover the
high-speed datacube with :func:`reconstruct` (ADMM on an OpenCL device).
Conventions: ``docs/model.md`` (conventions, equations, units), summarised in the README.
"""

from rsocl.model.operator import RollingShutterOperator
from rsocl.solver.reconstruct import Result, reconstruct
from rsocl.model.rig import Camera, Rig

__version__ = "0.1.0"
__all__ = ["Camera", "Rig", "RollingShutterOperator", "reconstruct", "Result", "__version__"]
