"""Device selection, install hints, fp64 checks."""

import pytest

from rsocl.device import context as devmod
from rsocl.device import program as progmod


def test_default_device_and_spec_forms(device):
    found = devmod.list_devices()
    assert found, "the test environment must have an OpenCL device"
    pi, di, platform, dev = found[0]
    assert devmod._pick(f"{pi}:{di}") == dev
    assert devmod._pick(str(pi)) == dev
    assert devmod._pick(dev.name.strip()[:6].lower()) is not None
    if "pocl" in platform.vendor.lower():
        assert devmod._pick("pocl") == dev  # the vendor names it
    assert devmod.get_device(device) is device
    assert devmod.get_device(None).name == device.name


def test_unknown_spec_lists_devices():
    with pytest.raises(ValueError, match="matches no OpenCL device; available: 0:0"):
        devmod._pick("no-such-accelerator")
    with pytest.raises(ValueError, match="device must be"):
        devmod.get_device(3.5)


def test_a_pyopencl_ctx_that_matches_nothing_is_one_line_listing_the_devices(monkeypatch, capsys):
    from rsocl.cli.main import main

    monkeypatch.delenv("RSOCL_DEVICE", raising=False)
    monkeypatch.setenv("PYOPENCL_CTX", "no-such-platform")
    devmod._device_for.cache_clear()
    try:
        with pytest.raises(
            ValueError, match=r"^PYOPENCL_CTX='no-such-platform' matches no OpenCL device .*available: 0:0"
        ):
            devmod.get_device(None)
        assert main(["devices"]) == 2  # the list still printed, then the one line
        captured = capsys.readouterr()
        assert " 0:0 " in captured.out and captured.err.startswith("rsocl devices: error: PYOPENCL_CTX=")
    finally:
        devmod._device_for.cache_clear()


def test_no_platform_says_how_to_install(monkeypatch):
    monkeypatch.setattr(devmod, "list_devices", lambda: [])
    with pytest.raises(devmod.NoOpenCLError, match=r'pip install "rsocl\[pocl\]"'):
        devmod._pick(None)


def test_fp64_on_a_device_without_it_is_a_clear_error(device, monkeypatch):
    monkeypatch.setattr(devmod.Device, "has_fp64", property(lambda self: False))
    with pytest.raises(ValueError, match="cl_khr_fp64"):
        device.real_dtype("float64")
    assert device.real_dtype("float32").name == "float32"
    with pytest.raises(ValueError, match="dtype must be"):
        device.real_dtype("int8")


def test_rsocl_device_environment_variable(monkeypatch):
    monkeypatch.setenv("RSOCL_DEVICE", "no-such-accelerator")
    with pytest.raises(ValueError, match="no-such-accelerator"):
        devmod._device_for.__wrapped__(None, "no-such-accelerator", None)  # uncached: other tests keep their device


def test_fits_check_names_the_numbers(device):
    with pytest.raises(ValueError, match=r"MiB.*largest allocation"):
        device.check_fits("a test buffer", device.max_alloc_bytes + 1)
    with pytest.raises(ValueError, match="device memory in all"):
        device.check_fits("a test problem", 10, total_bytes=device.global_mem_bytes + 1)
    device.check_fits("a small buffer", 1024, total_bytes=2048)


def test_kernels_ship_as_package_data():
    for name in ("common.cl", "operator.cl", "tv.cl", "admm.cl", "reduce.cl"):
        assert "__kernel" in progmod.kernel_source(name) or name == "common.cl"


NVIDIA_LOG = (
    "(): Warning: Function admm_dual is a kernel, so overriding noinline attribute. The function may be "
    "inlined when called.\n(): Warning: Function admm_project is a kernel, so overriding noinline attribute. "
    "The function may be inlined when called.\n\n"
)


def test_the_drivers_noinline_notice_is_not_a_meaningful_log():
    assert progmod.meaningful_log(NVIDIA_LOG) == ""
    assert (
        progmod.meaningful_log(NVIDIA_LOG + "<kernel>:3:9: warning: unused variable 'x'\n")
        == "<kernel>:3:9: warning: unused variable 'x'"
    )


def _build_with_log(device, monkeypatch, text, log):
    """Build a program whose source is ``text`` on ``device``, its build log read as ``log`` (None: as built)."""
    import uuid
    import warnings

    import pyopencl as cl

    real = progmod.kernel_source
    text = f"/* {uuid.uuid4().hex} */\n{text}"  # a new source each time: no driver's cache of built programs
    monkeypatch.setattr(progmod, "kernel_source", lambda name: text if name == "fake.cl" else real(name))
    if log is not None:
        monkeypatch.setattr(cl.Program, "get_build_info", lambda self, dev, what: log)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        progmod.build_program(device.context, ("fake.cl",), (("REAL", "float"),))
    return [w for w in caught if issubclass(w.category, cl.CompilerWarning)]


def test_a_build_warning_reaches_the_user_but_not_the_drivers_noise(device, monkeypatch):
    source = '#warning "rsocl: a warning of the program"\n__kernel void fake(__global float *a) { a[0] = 1.0f; }\n'
    genuine = _build_with_log(device, monkeypatch, source, None)
    assert genuine, "a #warning in the source must surface as pyopencl's CompilerWarning"
    assert _build_with_log(device, monkeypatch, source, NVIDIA_LOG) == []
    assert len(_build_with_log(device, monkeypatch, source, NVIDIA_LOG + "warning: else\n")) == len(genuine)


def test_programs_flush_subnormals_so_a_point_on_black_costs_no_more_than_a_scene():
    """TV spreading a bright point through a black background decayed into float32 subnormals, 10-40x
    slower on a CPU: every program is built with -cl-denorms-are-zero, and PoCL's CPU device flushes."""
    import numpy as np
    import pyopencl as cl

    import rsocl
    from rsocl.device import get_device

    built = []
    real = cl.Program.build

    def recorded(self, options=(), *args, **kwargs):
        built.append(list(options))
        return real(self, options, *args, **kwargs)

    device = get_device()
    rig = rsocl.Rig.paper_array(4, (32, 32), t_e=1.8e-4, t_r=3.5e-5)
    truth = np.zeros((rig.T,) + rig.shape)
    truth[:, 16, 16] = 1.0  # without the flag: 1399 subnormal values, the smallest 1e-45
    g = rsocl.RollingShutterOperator(rig).forward(truth)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cl.Program, "build", recorded)
        mp.delitem(device.__dict__, "_programs", raising=False)  # built anew
        x = rsocl.reconstruct(
            g, rig, iterations=100, tune=False, regularizer_options={"temporal_weight": 30.0}, x0="interp3d"
        )
    assert built and all("-cl-denorms-are-zero" in options for options in built)
    values = np.abs(x.datacube[x.datacube != 0])
    if device.is_cpu and "portable" in device.name.lower():
        assert values.min() >= np.finfo(np.float32).tiny  # no subnormal left
