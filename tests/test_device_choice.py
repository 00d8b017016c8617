"""Where a device spec came from, and an empty spec: RSOCL_DEVICE is named, a blank spec counts as none."""

import pyopencl as cl
import pytest

from rsocl.device import context as devmod


class _Platform:
    name = "NVIDIA CUDA"
    vendor = "NVIDIA Corporation"


class _GPU:
    name = "NVIDIA H100 80GB HBM3"
    vendor = "NVIDIA Corporation"
    type = cl.device_type.GPU


@pytest.fixture
def fresh(monkeypatch):
    """No device variable set, and get_device's cache empty before and after."""
    monkeypatch.delenv("RSOCL_DEVICE", raising=False)
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    devmod._device_for.cache_clear()
    yield monkeypatch
    devmod._device_for.cache_clear()


def test_an_rsocl_device_that_matches_nothing_is_named_in_the_error(fresh, capsys):
    from rsocl.cli.main import main

    fresh.setenv("RSOCL_DEVICE", "no-such-accelerator")
    with pytest.raises(
        ValueError, match=r"^RSOCL_DEVICE='no-such-accelerator' matches no OpenCL device; available: 0:0"
    ):
        devmod.get_device(None)
    assert main(["devices"]) == 2
    assert "rsocl devices: error: RSOCL_DEVICE='no-such-accelerator'" in capsys.readouterr().err
    with pytest.raises(ValueError, match=r"^device 'no-such-accelerator' matches no OpenCL device"):
        devmod.get_device("no-such-accelerator")  # a spec given is not the variable


def test_a_change_of_rsocl_device_in_the_process_is_seen(fresh):
    chosen = devmod.get_device(None)  # cached for these variables
    fresh.setenv("RSOCL_DEVICE", "no-such-accelerator")
    with pytest.raises(ValueError, match=r"^RSOCL_DEVICE='no-such-accelerator'"):
        devmod.get_device(None)
    fresh.delenv("RSOCL_DEVICE")
    assert devmod.get_device(None) is chosen  # the same variables: the same device, context and programs
    assert devmod.get_device("0:0") is devmod.get_device("0:0")


@pytest.mark.parametrize("blank", ["", "  "])
def test_a_blank_spec_is_the_default_choice_not_the_first_device(fresh, blank):
    real = devmod.list_devices()
    fresh.setattr(devmod, "list_devices", lambda: real + [(len(real), 0, _Platform(), _GPU())])
    assert devmod._pick(None).name == _GPU.name
    assert devmod._pick(blank).name == _GPU.name


@pytest.mark.parametrize("blank", ["", "  "])
def test_a_blank_spec_leaves_the_choice_to_rsocl_device_in_the_api_and_the_cli(fresh, blank, capsys, tmp_path):
    from rsocl.cli.main import main

    fresh.setenv("RSOCL_DEVICE", "no-such-accelerator")
    with pytest.raises(ValueError, match=r"^RSOCL_DEVICE='no-such-accelerator'"):
        devmod.get_device(blank)
    cap = tmp_path / "cap.h5"
    fresh.delenv("RSOCL_DEVICE")
    assert main(["simulate", "builtin", "--out", str(cap), "--shape", "8", "8", "--cameras", "2", "--quiet"]) == 0
    fresh.setenv("RSOCL_DEVICE", "no-such-accelerator")
    devmod._device_for.cache_clear()
    args = ["reconstruct", str(cap), "--out", str(tmp_path / "rec.h5"), "--iterations", "2", "--quiet"]
    assert main([*args, "--device", blank]) == 2
    assert "RSOCL_DEVICE='no-such-accelerator' matches no OpenCL device" in capsys.readouterr().err
    fresh.setenv("RSOCL_DEVICE", blank)  # blank here is unset too: the default choice
    devmod._device_for.cache_clear()
    assert devmod.get_device(None).name == devmod.get_device(blank).name
