"""Faulty plugins and distributions: each is refused with one error naming it, and the rest keep working."""

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

import rsocl
from rsocl.common import registry
from rsocl.hardware.backend import CameraBackend, CameraError
from rsocl.solver.regularizer import Option, Regularizer
from rsocl.testing import check_regularizer, dottest

#: every hook a camera backend implements
CAMERA_HOOKS = (
    "_open_device _close_device _set_exposure _set_roi _set_pixel_format _set_trigger _start _stop _trigger _read"
)
HOOKS = "".join(f"    def {hook}(self, *args):\n        pass\n" for hook in CAMERA_HOOKS.split())


def _distribution(folder: Path, dist: str, entry_points: str, module: str = "", body: str = ""):
    """A minimal installed distribution on the sys.path folder ``folder``: dist-info and, when given, a module."""
    info = folder / f"{dist.replace('-', '_')}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(entry_points)
    if module:
        (folder / f"{module}.py").write_text(textwrap.dedent(body))


def _run_tv():
    rig = rsocl.Rig.paper_array(2, (6, 6), t_e=1e-4, t_r=3e-5)
    g = rsocl.RollingShutterOperator(rig).forward(np.ones((rig.T, 6, 6)))
    return rsocl.reconstruct(g, rig, "tv", iterations=2).datacube.shape == (rig.T, 6, 6)


# ------------------------------------------------------------------ 1: a malformed entry_points.txt
def test_a_malformed_entry_points_file_of_any_distribution_is_skipped_with_a_warning_naming_it(
    tmp_path, monkeypatch, capsys
):
    from rsocl.cli.main import main

    _distribution(tmp_path, "unrelated-tool", "[console_scripts]\nbroken-script\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.warns(UserWarning, match=r"distribution unrelated-tool 0\.1: its entry points .*entry_points\.txt"):
        names = registry.available("rsocl.regularizers")
    assert {"tv", "wavelet", "dct"} <= set(names)
    assert registry.load("rsocl.regularizers", "tv").name == "tv"
    rows = registry.status("rsocl.cameras")
    assert any(info is None and "unrelated-tool" in state and state.startswith("broken") for info, _, state in rows)
    assert main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"\?\s+broken: distribution unrelated-tool 0\.1", out) and "simulated" in out
    assert _run_tv()


# ------------------------------------------------------------------ 9: a third party claiming a built-in's name
def test_a_third_party_claiming_a_builtin_name_leaves_the_builtin_in_use_and_is_named(tmp_path, monkeypatch):
    _distribution(tmp_path, "third-clash", "[rsocl.regularizers]\ntv = third_clash_mod:Thing\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert registry.available("rsocl.regularizers")["tv"].distribution == "rsocl"
    with pytest.warns(UserWarning, match=r"third-clash 0\.1 declares 'tv'.*rsocl's built-in is used") as caught:
        cls = registry.load("rsocl.regularizers", "tv")
    assert cls.__module__ == "rsocl_plugins.tv"
    assert not any("uninstall" in str(w.message) for w in caught)
    rows = [(info.distribution, state) for info, name, state in registry.status("rsocl.regularizers") if name == "tv"]
    assert ("rsocl", "ok") in rows
    assert any(d == "third-clash" and s.startswith("ignored: ") for d, s in rows)
    assert _run_tv()


# ------------------------------------------------------------------ 2: no _denoise
def test_a_regularizer_without_denoise_is_broken_in_the_registry_and_fails_the_check(tmp_path, monkeypatch):
    body = "from rsocl import Regularizer\nclass Thing(Regularizer):\n    name = 'nomethod'\n"
    _distribution(
        tmp_path, "third-nomethod", "[rsocl.regularizers]\nnomethod = nomethod_mod:Thing\n", "nomethod_mod", body
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    state = {name: s for _, name, s in registry.status("rsocl.regularizers")}["nomethod"]
    assert state.startswith("broken") and "does not implement _denoise" in state
    with pytest.raises(registry.PluginError, match=r"'nomethod'.*third-nomethod 0\.1.*does not implement _denoise"):
        registry.load("rsocl.regularizers", "nomethod")

    class NoMethod(Regularizer):
        name = "nomethod"

    with pytest.raises(AssertionError, match="must implement _denoise"):
        check_regularizer(NoMethod)
    with pytest.raises(NotImplementedError, match="NoMethod does not implement _denoise"):
        NoMethod()._denoise(None, 1.0, None)


# ------------------------------------------------------------------ 3: a kernel that fails to build
class _BadKernel(Regularizer):
    name = "badkernel"

    def _denoise(self, x, weight, out):
        import pyopencl as cl

        cl.Program(x.queue.context, "__kernel void k(__global float *x) { x[0] = undefined_thing; }").build()
        return out


def test_a_kernel_that_fails_to_build_is_one_error_naming_the_regularizer(device):
    import pyopencl.array as cla

    x = cla.to_device(device.queue, np.ones((2, 3, 3), np.float32))
    with pytest.raises(
        registry.PluginError, match=r"regularizer 'badkernel' \(.*_BadKernel\) failed in _denoise: "
    ) as e:
        _BadKernel().denoise(x, 0.5)
    assert "\n" not in str(e.value) and "BUILD_PROGRAM_FAILURE" in str(e.value)
    with pytest.raises(AssertionError, match=r"float32: regularizer 'badkernel'.*failed in _denoise"):
        check_regularizer(_BadKernel, device=device)


# ------------------------------------------------------------------ 4: camera backends
def test_a_camera_backend_missing_hooks_is_broken_naming_them(tmp_path, monkeypatch):
    body = "from rsocl.hardware.backend import CameraBackend\nclass Thing(CameraBackend):\n    backend = 'nohooks'\n"
    body += "    def _open_device(self):\n        pass\n    def _close_device(self):\n        pass\n"
    _distribution(tmp_path, "third-cams", "[rsocl.cameras]\nnohooks = cams_mod:Thing\n", "cams_mod", body)
    monkeypatch.syspath_prepend(str(tmp_path))
    state = {name: s for _, name, s in registry.status("rsocl.cameras")}["nohooks"]
    assert state.startswith("broken") and "does not implement _set_exposure, _set_roi" in state
    with pytest.raises(registry.PluginError, match=r"'nohooks'.*third-cams 0\.1.*does not implement _set_exposure"):
        registry.load("rsocl.cameras", "nohooks")

    class Partial(CameraBackend):
        def _open_device(self):
            pass

    cam = Partial({}, name="camera 0").open()
    with pytest.raises(CameraError, match="Partial does not implement _set_exposure"):
        cam.set_exposure(1e-3)


def test_a_camera_backend_whose_constructor_raises_is_one_error_naming_the_camera_and_backend(tmp_path, monkeypatch):
    body = "from rsocl.hardware.backend import CameraBackend\nclass Thing(CameraBackend):\n    backend = 'badinit'\n"
    body += "    def __init__(self, config=None, name=None):\n        super().__init__(config, name)\n"
    body += "        self.address = self.config['address']\n" + HOOKS
    _distribution(tmp_path, "third-badinit", "[rsocl.cameras]\nbadinit = badinit_mod:Thing\n", "badinit_mod", body)
    monkeypatch.syspath_prepend(str(tmp_path))
    cls = registry.load("rsocl.cameras", "badinit")
    with pytest.raises(
        registry.PluginError,
        match=r"camera 0 \(badinit\): backend 'badinit' \(badinit_mod\.Thing from third-badinit 0\.1\) could not be "
        r"set up: KeyError: 'address'",
    ):
        cls({}, name="camera 0 (badinit)")
    assert cls({"address": "x"}, name="camera 0").address == "x"


# ------------------------------------------------------------------ 5, 6: option declarations
@pytest.mark.parametrize(
    "option, match",
    [
        (Option(5, minimum=10, maximum=1), r"option 'iters': the range is empty: minimum 10 > maximum 1"),
        (Option(-1.0, minimum=0.0, maximum=1.0), r"option 'iters': the default -1\.0 is not a value"),
        (Option(0.5, minimum="0"), r"option 'iters': minimum must be a real number or None, got '0'"),
        (Option(0.5, maximum=float("nan")), r"option 'iters': maximum must be a real number or None"),
        (3, r"option 'iters' must be declared as rsocl\.solver\.regularizer\.Option"),
    ],
)
def test_a_bad_option_declaration_names_the_regularizer_and_option(tmp_path, monkeypatch, option, match):
    class Bad(Regularizer):
        name = "badoption"
        options = {"iters": option}

        def _denoise(self, x, weight, out):
            return out

    with pytest.raises(AssertionError, match=match):
        check_regularizer(Bad)
    with pytest.raises(ValueError, match=r"regularizer 'badoption' \(.*Bad\): " + match):
        Bad()
    decl = "Option(5, minimum=10, maximum=1)" if isinstance(option, Option) else "3"
    body = f"""\
        from rsocl import Option, Regularizer
        class Thing(Regularizer):
            name = 'badoption'
            options = {{'iters': {decl}}}
            def _denoise(self, x, weight, out):
                return out
        """
    _distribution(
        tmp_path, "third-badoption", "[rsocl.regularizers]\nbadoption = badopt_mod:Thing\n", "badopt_mod", body
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(registry.PluginError, match=r"'badoption'.*third-badoption 0\.1.*option 'iters'"):
        registry.load("rsocl.regularizers", "badoption")
    state = {name: s for _, name, s in registry.status("rsocl.regularizers")}["badoption"]
    assert state.startswith("broken") and "option 'iters'" in state


def test_the_registry_requires_every_hook_of_a_camera_backend():
    assert registry.REQUIRED["rsocl.cameras"] == tuple(CAMERA_HOOKS.split())


def test_valid_option_declarations_pass():
    for opt in (Option(3, minimum=1, maximum=10), Option(0.5, minimum=0), Option(True), Option("a"), Option(2.0)):
        opt.check("x")
    for name in ("tv", "wavelet", "dct"):
        registry.load("rsocl.regularizers", name).check_options()


# ------------------------------------------------------------------ 7: batches
class _OneWeightForAll(Regularizer):
    name = "batchedwrong"
    batched = True

    def _denoise(self, x, weight, out):
        out[...] = x / (1.0 + float(np.ravel(weight)[0]))  # one weight for every set
        return out


def test_the_check_fails_a_batched_regularizer_whose_sets_differ_from_alone(device):
    with pytest.raises(AssertionError, match=r"set 1 of a batch .* differs from that set denoised alone"):
        check_regularizer(_OneWeightForAll, device=device)

    class SetBySet(_OneWeightForAll):  # the same map, handed one set at a time
        batched = False

    assert "float32" in check_regularizer(SetBySet, device=device)


# ------------------------------------------------------------------ 8: dottest
def test_dottest_fails_an_adjoint_wrong_at_one_pixel_per_frame():
    rig = rsocl.Rig.paper_array(4, shape=(128, 128), t_e=180e-6, t_r=35e-6)
    op = rsocl.RollingShutterOperator(rig)

    class WrongAdjoint:
        domain_shape, range_shape, dtype = op.domain_shape, op.range_shape, op.dtype

        def forward(self, x):
            return op.forward(x)

        def adjoint(self, y):
            a = np.array(op.adjoint(y))
            a[:, 0, 0] = 0
            return a

    assert dottest(op) is True
    assert dottest(WrongAdjoint(), raiseerror=False) is False
