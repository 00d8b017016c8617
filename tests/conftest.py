"""Shared fixtures: the OpenCL device under test (and read as one that is not a CPU), the shared data folder.

The device is rsocl's default choice (``RSOCL_DEVICE`` / ``PYOPENCL_CTX`` respected),
so CI can run the same tests on PoCL and under Oclgrind. ``RSOCL_TEST_SMALL=1``
shrinks the problem sizes for slow simulated devices.
"""

import os
from pathlib import Path

import numpy as np
import pytest

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
SMALL = os.environ.get("RSOCL_TEST_SMALL") == "1"


@pytest.fixture(scope="session")
def device():
    from rsocl.device.context import get_device

    return get_device()


@pytest.fixture(scope="session")
def has_fp64(device):
    return device.has_fp64


@pytest.fixture(params=["float32", "float64"])
def dtype(request, device):
    if request.param == "float64" and not device.has_fp64:
        pytest.skip(f"device {device.name} has no cl_khr_fp64")
    return request.param


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.fixture()
def not_cpu(monkeypatch, device):
    """The test device, read as a device that is not a CPU (the GPU defaults apply to it)."""
    from rsocl.device.context import Device

    monkeypatch.setattr(Device, "is_cpu", property(lambda self: False))
    assert not device.is_cpu
    return device


def _recording_admm(monkeypatch, what):
    """A list that gets ``what(admm)`` of every :class:`rsocl.solver.admm.ADMM` made from now on, in order."""
    from rsocl.solver.admm import ADMM

    made = []
    init = ADMM.__init__

    def recording(self, *args, **kwargs):
        init(self, *args, **kwargs)
        made.append(what(self))

    monkeypatch.setattr(ADMM, "__init__", recording)
    return made


@pytest.fixture()
def admm_lanes(monkeypatch):
    """The projection lanes (``ADMM.lanes``) of every :class:`rsocl.solver.admm.ADMM` made in the test, in order."""
    return _recording_admm(monkeypatch, lambda admm: admm.lanes)


@pytest.fixture()
def admm_made(monkeypatch):
    """Every :class:`rsocl.solver.admm.ADMM` made in the test, in order."""
    return _recording_admm(monkeypatch, lambda admm: admm)


def shared_video(name):
    path = SHARED_DATA / f"{name}.npz"
    if not path.exists():
        pytest.skip(f"shared data {path} not present")
    return path


def pytest_collection_modifyitems(config, items):
    """Each ``not_under_oclgrind`` mark says why the test is left out there (``.ci/run``'s step 3 reads them)."""
    for item in items:
        for mark in item.iter_markers("not_under_oclgrind"):
            if not (mark.args and isinstance(mark.args[0], str) and mark.args[0].strip()):
                raise pytest.UsageError(f"{item.nodeid}: @pytest.mark.not_under_oclgrind(reason) needs its reason")
