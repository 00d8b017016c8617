"""The plugin registry, the regularizer conformance check, and a real third-party distribution."""

import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

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
    _fake_distribution(tmp_path, "impostor-tv", "tv", "impostor_tv", "Thing = object\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(plugins.PluginError, match=r"'tv'.*impostor-tv.*rsocl|'tv'.*rsocl.*impostor-tv"):
        plugins.load("rsocl.regularizers", "tv")
    assert "tv" not in plugins.available("rsocl.regularizers")
    assert plugins.load("rsocl.regularizers", "dct").name == "dct"  # the others stay usable
    rows = [state for info, name, state in plugins.status("rsocl.regularizers") if name == "tv"]
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
