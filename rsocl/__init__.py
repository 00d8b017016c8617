"""rsocl: compressive high-speed imaging with an array of rotated rolling-shutter cameras.

Describe the array with :class:`Camera` and :class:`Rig`, apply the row-timed
shutter operator with :class:`RollingShutterOperator`, and recover the
high-speed datacube with :func:`reconstruct` (ADMM on an OpenCL device), or many
sets of snapshots with :func:`reconstruct_sets`. Around them: test scenes
(:func:`builtin_scene`, :func:`load_scene`), simulated snapshots (:func:`simulate`),
the per-pixel interpolation :func:`interp3d`, quality metrics (:func:`psnr`, :func:`ssim`),
HDF5 files (:func:`load_capture`, :func:`save_capture`, :func:`save_reconstruction`,
:func:`load_reconstruction`), the regularizer contract (:class:`Regularizer`, :class:`Option`)
and OpenCL devices (:func:`get_device`, :func:`list_devices`). :mod:`rsocl.testing` holds
the checks an operator or plugin author runs (:func:`rsocl.testing.dottest`,
:func:`rsocl.testing.check_regularizer`).

Conventions: ``docs/model.md`` (conventions, equations, units), summarised in the README.

Examples
--------
>>> import rsocl
>>> rig = rsocl.Rig.paper_array(4, shape=(16, 16), t_e=180e-6, t_r=35e-6)
>>> truth = rsocl.builtin_scene(rig.shape, rig.T)
>>> g = rsocl.simulate(truth, rig)
>>> g.shape
(4, 16, 16)
>>> result = rsocl.reconstruct(g, rig, iterations=5, lam=0.1, eta=0.2, tune=False)
>>> result.datacube.shape == truth.shape
True
"""

from rsocl import testing
from rsocl.analysis.metrics import psnr, ssim
from rsocl.device.context import get_device, list_devices
from rsocl.files.hdf5 import Capture, load_capture, save_capture
from rsocl.files.hdf5_reconstruction import Reconstruction, load_reconstruction, save_reconstruction
from rsocl.model.interpolation import interp3d
from rsocl.model.operator import RollingShutterOperator
from rsocl.model.rig import Camera, Rig
from rsocl.model.scenes import benchmark_protocol, builtin_scene, load_scene
from rsocl.model.simulate import simulate
from rsocl.model.video import load_video
from rsocl.solver.reconstruct import Result, reconstruct
from rsocl.solver.regularizer import Option, Regularizer
from rsocl.solver.sets import batch_size, reconstruct_sets

__version__ = "0.1.0"
__all__ = [
    "Camera",
    "Rig",
    "RollingShutterOperator",  # the model
    "reconstruct",
    "reconstruct_sets",
    "batch_size",
    "Result",  # the solver
    "Regularizer",
    "Option",  # regularizer plugins
    "builtin_scene",
    "load_video",
    "load_scene",
    "benchmark_protocol",
    "simulate",  # scenes, snapshots
    "interp3d",
    "psnr",
    "ssim",  # baseline, metrics
    "load_capture",
    "save_capture",
    "load_reconstruction",
    "save_reconstruction",  # HDF5 files
    "Capture",
    "Reconstruction",
    "get_device",
    "list_devices",  # OpenCL devices
    "testing",
    "__version__",
]
