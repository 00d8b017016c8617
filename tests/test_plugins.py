"""The plugin registry, the regularizer conformance check, and a real third-party distribution."""

import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pyopencl as cl
import pytest
from pyopencl import enqueue_copy as bound_enqueue_copy  # bound before any check patches pyopencl

import rsocl
from rsocl.common import registry as plugins
from rsocl.testing import check_regularizer

ROOT = Path(__file__).resolve().parents[1]
BUILTIN = ["tv", "wavelet", "dct"]


def _fake_distribution(folder: Path, dist: str, entry: str, module: str, body: str):
    """A minimal installed distribution (dist-info + module) on a sys.path folder."""
    info = folder / f"{dist.replace('-', '_')}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[rsocl.regularizers]\n{entry} = {module}:Thing\n")
    (folder / f"{module}.py").write_text(textwrap.dedent(body))


def test_builtin_regularizers_are_listed_without_importing_them():
    code = (
        "import sys, rsocl.common.registry as p; names = sorted(p.available('rsocl.regularizers'));"
        "print(names, any(m.startswith('rsocl_plugins.') for m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    for name in BUILTIN:
        assert repr(name) in out
    assert out.strip().endswith("False")
    info = plugins.available("rsocl.regularizers")["tv"]
    assert info.distribution == "rsocl" and info.value == "rsocl_plugins.tv:TV"


@pytest.mark.parametrize("name", BUILTIN)
def test_builtin_regularizers_conform(name, device):
    cls = plugins.load("rsocl.regularizers", name)
    assert cls.name == name
    checked = check_regularizer(cls, device=device)
    assert "float32" in checked


@pytest.mark.parametrize(
    "weights, match",
    [
        ((), r"weights must be a sequence of at least one denoising weight >= 0, got \(\)"),
        ([], r"weights must be a sequence of at least one denoising weight >= 0, got \[\]"),
        (0.5, r"weights must be a sequence of at least one denoising weight >= 0, got 0.5"),
        ("0.5", r"weights must be a sequence .*got '0.5'"),
        ((0.1, -0.5), r"weights\[1\] must be >= 0, got -0.5"),
        ((np.nan,), r"weights\[0\] must be finite"),
    ],
)
def test_conformance_check_refuses_bad_weights_before_running(weights, match, monkeypatch):
    import rsocl.testing

    monkeypatch.setattr(rsocl.testing, "get_device", lambda *a: pytest.fail("the device was reached"))
    with pytest.raises(ValueError, match=match):
        check_regularizer(plugins.load("rsocl.regularizers", "tv"), weights=weights)


def test_conformance_check_catches_a_bad_regularizer(device):
    from rsocl.solver.regularizer import Regularizer

    class Doubling(Regularizer):
        name = "doubling"

        def _denoise(self, x, weight, out):
            out.set(2 * x.get())  # expansive, and through the host
            return out

    with pytest.raises(AssertionError, match="host"):
        check_regularizer(Doubling, device=device)


def _host_copy(x, h):
    bound_enqueue_copy(x.queue, h, x.data)


def _host_copy_rect(x, h):
    cl.enqueue_copy(x.queue, h, x.data, buffer_origin=(0, 0), host_origin=(0, 0), region=(x.nbytes, 1))


def _host_map(x, h):
    mapped, _ = cl.enqueue_map_buffer(x.queue, x.data, cl.map_flags.READ, 0, x.shape, x.dtype)
    h[...] = mapped
    del mapped


def _host_map_to_host(x, h):
    h[...] = x.map_to_host()


@pytest.mark.parametrize(
    "read, how",
    [
        (_host_copy, "enqueue_copy"),
        (_host_copy_rect, "enqueue_copy"),
        (_host_map, "enqueue_map_buffer"),
        (_host_map_to_host, "enqueue_map_buffer"),
    ],
)
def test_conformance_check_catches_every_read_back_to_the_host(device, read, how):
    import pyopencl._cl as _cl
    import pyopencl.array as cla

    from rsocl.solver.regularizer import Option, Regularizer

    class ThroughHost(Regularizer):
        name = "throughhost"
        options = {"center": Option(0.0)}

        def _denoise(self, x, weight, out):
            h = np.empty(x.shape, x.dtype)
            read(x, h)
            out.set(((h + weight * self.center) / (1 + weight)).astype(x.dtype))
            return out

    before = {name: getattr(_cl, name) for name in ("_enqueue_read_buffer", "enqueue_map_buffer")}
    with pytest.raises(AssertionError, match=re.escape(f"copied device data to the host ({how})")):
        check_regularizer(ThroughHost, device=device)
    assert {name: getattr(_cl, name) for name in before} == before  # the patches are undone
    assert cl.enqueue_map_buffer is _cl.enqueue_map_buffer
    x = cla.to_device(device.queue, np.arange(4.0, dtype=np.float32).reshape(1, 1, 4))
    h = np.zeros((1, 1, 4), np.float32)
    read(x, h)
    assert h.ravel().tolist() == [0, 1, 2, 3] and x.get().shape == (1, 1, 4)


@pytest.mark.parametrize("value", [float("inf"), "inf", "1e400", -float("inf"), 10**400, "nan"])
def test_an_integer_option_given_a_non_finite_value_is_a_value_error_naming_it_and_its_range(value):
    tv = plugins.load("rsocl.regularizers", "tv")
    with pytest.raises(ValueError, match=r"option iterations must be .*an integer in \[1, 100000\], got "):
        tv(iterations=value)
    with pytest.raises(ValueError, match=r"option fused must be .*in \["):
        tv(fused=value)


def test_an_integer_option_given_inf_on_the_command_line_is_a_one_line_error(tmp_path, capsys):
    from rsocl.cli.main import main

    cap = tmp_path / "cap.h5"
    assert main(["simulate", "builtin", "--out", str(cap), "--shape", "8", "8", "--cameras", "2", "--quiet"]) == 0
    for opt in ("iterations=inf", "fused=1e400"):
        assert main(["reconstruct", str(cap), "--out", str(tmp_path / "rec.h5"), "--reg-opt", opt]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and f"option {opt.split('=')[0]} must be finite" in err, err
    assert not (tmp_path / "rec.h5").exists()


@pytest.mark.parametrize("default", [None, (1, 2), [0.5], {"a": 1}, b"x", 1j])
def test_an_option_whose_default_is_not_bool_int_float_or_str_fails_the_check_and_refuses_values(default):
    # a plugin declaring one still loads (its runs without the option work); the conformance check fails
    # on it and a value given for it is a ValueError naming the option, not a TypeError
    from rsocl.solver.regularizer import Option, Regularizer

    class Seeded(Regularizer):
        name = "seeded"
        options = {"seed": Option(default)}

    with pytest.raises(AssertionError, match=r"option 'seed': the default must be a bool, int, float or str"):
        check_regularizer(Seeded)
    with pytest.raises(ValueError, match="option seed"):
        Seeded(seed="3")


@pytest.mark.parametrize(
    "default, value, match",
    [
        (True, "maybe", r"option flag must be a boolean, got 'maybe'"),
        (True, np.array([1, 0]), r"option flag must be a boolean"),
        (3, "x", r"option flag must be an integer in \[-inf, inf\], got 'x'"),
        (3, [1, 2], r"option flag must be an integer in \[-inf, inf\]"),
        (0.5, None, r"option flag must be a number in \[-inf, inf\], got None"),
    ],
)
def test_option_conversion_failures_are_value_errors_naming_the_option(default, value, match):
    from rsocl.solver.regularizer import Option

    with pytest.raises(ValueError, match=match):
        Option(default).convert("flag", value)
    assert Option(np.int64(3)).convert("flag", "7") == 7 and Option(np.float32(0.5)).convert("flag", 2) == 2.0
    assert Option("a").convert("flag", 3) == "3" and Option(3).convert("flag", 10**20) == 10**20


def test_unknown_name_lists_the_available_ones():
    with pytest.raises(plugins.PluginError, match=r"available: \[.*'tv'"):
        plugins.load("rsocl.regularizers", "no-such-thing")
    with pytest.raises(ValueError, match="group must be one of"):
        plugins.available("rsocl.nothing")


def test_broken_plugin_is_reported_and_others_keep_working(tmp_path, monkeypatch):
    _fake_distribution(
        tmp_path,
        "broken-rsocl-plugin",
        "broken",
        "broken_rsocl_module",
        "raise ImportError('needs the missing package frobnicate')\n",
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    rows = {name: (info, state) for info, name, state in plugins.status("rsocl.regularizers")}
    info, state = rows["broken"]
    assert info.distribution == "broken-rsocl-plugin"
    assert state.startswith("broken") and "frobnicate" in state
    assert rows["tv"][1] == "ok"
    with pytest.raises(plugins.PluginError, match="broken-rsocl-plugin.*frobnicate"):
        plugins.load("rsocl.regularizers", "broken")
    rig = rsocl.Rig.paper_array(2, (6, 6), t_e=1e-4, t_r=3e-5)
    g = rsocl.RollingShutterOperator(rig).forward(np.ones((rig.T, 6, 6)))
    assert rsocl.reconstruct(g, rig, iterations=2).datacube.shape == (rig.T, 6, 6)


def test_two_distributions_claiming_one_name_is_an_error_for_that_name_only(tmp_path, monkeypatch):
    _fake_distribution(tmp_path / "a", "shrink-one", "shrinky", "shrink_one", "Thing = object\n")
    _fake_distribution(tmp_path / "b", "shrink-two", "shrinky", "shrink_two", "Thing = object\n")
    monkeypatch.syspath_prepend(str(tmp_path / "a"))
    monkeypatch.syspath_prepend(str(tmp_path / "b"))
    with pytest.raises(plugins.PluginError, match=r"'shrinky'.*shrink-one 0.1 and shrink-two 0.1"):
        plugins.load("rsocl.regularizers", "shrinky")
    assert "shrinky" not in plugins.available("rsocl.regularizers")
    assert plugins.load("rsocl.regularizers", "dct").name == "dct"  # the others stay usable
    rows = [state for info, name, state in plugins.status("rsocl.regularizers") if name == "shrinky"]
    assert len(rows) == 2 and all("claimed by" in s for s in rows)


@pytest.mark.parametrize(
    "body, cause",
    [
        ("import sys\nsys.exit(3)\n", "SystemExit: 3"),
        ("Thing = 42\n", "TypeError: .* is 42, not a subclass of rsocl.solver.regularizer.Regularizer"),
        ("def Thing(**kw):\n    return 'x'\n", "not a subclass of rsocl.solver.regularizer.Regularizer"),
    ],
)
def test_a_plugin_that_exits_or_is_not_a_regularizer_is_broken_and_the_others_work(tmp_path, monkeypatch, body, cause):
    _fake_distribution(tmp_path, "odd-plugin", "odd", "odd_rsocl_module", body)
    monkeypatch.syspath_prepend(str(tmp_path))
    rows = {name: state for info, name, state in plugins.status("rsocl.regularizers")}
    assert re.search(cause, rows["odd"]) and rows["tv"] == "ok"
    with pytest.raises(plugins.PluginError, match="odd-plugin.*" + cause):
        plugins.load("rsocl.regularizers", "odd")
    rig = rsocl.Rig.paper_array(2, (6, 6), t_e=1e-4, t_r=3e-5)
    g = rsocl.RollingShutterOperator(rig).forward(np.ones((rig.T, 6, 6)))
    with pytest.raises(ValueError, match="odd-plugin"):
        rsocl.reconstruct(g, rig, "odd", iterations=2)


@pytest.fixture(scope="module")
def example_plugin_installed():
    """pip-install the example third-party distribution into this environment, remove it after."""
    source = ROOT / "plugins" / "example_plugin"
    cmd = [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", str(source)]
    try:  # build offline with what the environment has, else let pip fetch the build backend
        import setuptools  # noqa: F401
        import wheel  # noqa: F401

        cmd.insert(4, "--no-build-isolation")
    except ImportError:
        pass
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    for build in source.glob("build"):
        shutil.rmtree(build, ignore_errors=True)
    yield
    subprocess.run([sys.executable, "-m", "pip", "uninstall", "--quiet", "-y", "rsocl-example-shrink"], check=True)


def _rsocl(*args):
    return subprocess.run([sys.executable, "-m", "rsocl.cli", *args], capture_output=True, text=True, timeout=300)


def test_third_party_plugin_end_to_end(example_plugin_installed, tmp_path, device):
    listing = _rsocl("plugins")
    assert listing.returncode == 0, listing.stderr
    line = next(ln for ln in listing.stdout.splitlines() if ln.strip().startswith("shrink"))
    assert "rsocl-example-shrink" in line and line.rstrip().endswith("ok")
    cap, rec = tmp_path / "cap.h5", tmp_path / "rec.h5"
    assert _rsocl("simulate", "builtin", "--out", str(cap), "--shape", "12", "12", "--quiet").returncode == 0
    run = _rsocl(
        "reconstruct",
        str(cap),
        "--out",
        str(rec),
        "--regularizer",
        "shrink",
        "--reg-opt",
        "center=0.5",
        "--iterations",
        "5",
        "--quiet",
    )
    assert run.returncode == 0, run.stderr
    from rsocl.files.hdf5 import load_reconstruction

    result = load_reconstruction(rec)
    assert result.params["regularizer"] == "shrink"
    assert result.params["regularizer_options"] == {"center": 0.5}
    check_regularizer(plugins.load("rsocl.regularizers", "shrink"), device=device)


@pytest.mark.parametrize("name", ["wavelet", "tv"])
def test_threads_sharing_one_regularizer_instance_get_the_results_they_get_alone(name):
    """An instance caches its device buffers and launch settings: two threads running with it at
    once took each other's (wrong results of up to 16 on data in [0, 1], or a KeyError); they take
    turns on :attr:`Regularizer.in_use`."""
    import threading

    from rsocl.common.registry import load

    rig = rsocl.Rig.paper_array(4, (32, 32), t_e=1.8e-4, t_r=3.5e-5)
    other = rsocl.Rig.paper_array(3, (16, 20), t_e=1.8e-4, t_r=3.5e-5)
    jobs = [
        (rsocl.RollingShutterOperator(r).forward(rsocl.builtin_scene(r.shape, r.T, seed=s)) * k, r)
        for r, s, k in ((rig, 1, 1.0), (rig, 2, 0.5), (other, 3, 1.0))
    ]
    cls = load("rsocl.regularizers", name)
    alone = [rsocl.reconstruct(g, r, regularizer=cls(), iterations=30, tune=False).datacube for g, r in jobs]

    def run(i, shared, out, failed):
        try:
            out[i] = rsocl.reconstruct(*jobs[i], regularizer=shared, iterations=30, tune=False).datacube
        except Exception as exc:  # noqa: BLE001 - the test reports it
            failed.append(exc)

    for _ in range(3):
        shared, out, failed = cls(), {}, []
        threads = [threading.Thread(target=run, args=(i, shared, out, failed)) for i in range(3)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert not failed, failed
        for i in range(3):
            np.testing.assert_array_equal(out[i], alone[i])
