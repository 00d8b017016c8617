"""Packaging: the kernels are package data found through importlib.resources, and the wheel
built from this tree ships them (as ``rsocl/kernels/*.cl``), the bundled plugins and the
entry points.

The wheel is built offline (``pip wheel --no-deps --no-build-isolation --no-index``) from a
copy of the tree in ``tmp_path``, so the source tree gets no ``build/`` or ``*.egg-info``
and stale build output cannot leak into the wheel. It needs setuptools with a
``bdist_wheel`` command in the running environment (setuptools >= 70.1, or older
setuptools plus ``wheel``); without them the test is skipped, unless ``RSOCL_CI=1``
(set by ``.ci/run``), where a skip would hide a packaging regression and it fails instead.
Takes about 5 s.
"""

import configparser
import importlib.util
import os
import shutil
import subprocess
import sys
import zipfile
from importlib import resources
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
KERNELS = ("admm.cl", "common.cl", "interp.cl", "operator.cl", "reduce.cl", "residual.cl", "tv.cl", "tv_fused.cl")
# What must never reach the wheel (the copy for the build leaves these out too).
IGNORE = shutil.ignore_patterns(
    ".git",
    "build",
    "dist",
    "*.egg-info",
    "__pycache__",
    "*.pyc",
    ".pytest_cache",
    ".venv",
    "venv",
    "out",
    "*.h5",
    "rsocl-demo",
)


# ------------------------------------------------------------------ installed package
def test_kernels_are_package_resources():
    from rsocl.device.program import kernel_source

    root = resources.files("rsocl.kernels")
    names = {entry.name for entry in root.iterdir()}
    missing = sorted(set(KERNELS) - names)
    assert not missing, f"kernel sources not found through importlib.resources('rsocl.kernels'): {missing}"
    for name in KERNELS:
        text = root.joinpath(name).read_text(encoding="utf-8")
        assert "__kernel" in text or name == "common.cl", f"{name} has no kernel"
        assert kernel_source(name) == text


def test_kernel_sources_are_plain_opencl_c():
    """OpenCL C compilers choke on a BOM or non-ASCII outside comments; keep the files clean."""
    for name in KERNELS:
        raw = resources.files("rsocl.kernels").joinpath(name).read_bytes()
        assert not raw.startswith(b"\xef\xbb\xbf"), f"{name} starts with a UTF-8 BOM"
        raw.decode("utf-8")


# ------------------------------------------------------------------ the wheel
def _can_build_wheels():
    """Reason why a --no-build-isolation wheel build cannot work here, or None."""
    if importlib.util.find_spec("setuptools") is None:
        return "setuptools is not installed"
    import setuptools

    major_minor = tuple(int(part) for part in setuptools.__version__.split(".")[:2] if part.isdigit())
    if major_minor < (70, 1) and importlib.util.find_spec("wheel") is None:
        return f"setuptools {setuptools.__version__} needs the 'wheel' package for bdist_wheel"
    return None


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    if not (ROOT / "pyproject.toml").is_file():
        pytest.skip(f"no source tree at {ROOT}")
    reason = _can_build_wheels()
    if reason:
        if os.environ.get("RSOCL_CI") == "1":
            pytest.fail(f"cannot build the wheel: {reason} (pip install -U setuptools wheel)")
        pytest.skip(f"cannot build the wheel offline: {reason}")
    tmp = tmp_path_factory.mktemp("wheel")
    src, dist = tmp / "src", tmp / "dist"
    shutil.copytree(ROOT, src, ignore=IGNORE)
    cmd = [
        sys.executable,
        "-m",
        "pip",
        "wheel",
        "--no-deps",
        "--no-build-isolation",
        "--no-index",
        "--disable-pip-version-check",
        "-q",
        "-w",
        str(dist),
        str(src),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"{' '.join(cmd)} failed:\n{done.stdout}\n{done.stderr}"
    wheels = sorted(dist.glob("rsocl-*.whl"))
    assert len(wheels) == 1, f"expected one rsocl wheel in {dist}, got {[w.name for w in dist.iterdir()]}"
    return wheels[0]


def _entry_points(zf):
    name = next(n for n in zf.namelist() if n.endswith(".dist-info/entry_points.txt"))
    parser = configparser.ConfigParser(delimiters=("=",))
    parser.optionxform = str
    parser.read_string(zf.read(name).decode("utf-8"))
    return {section: dict(parser[section]) for section in parser.sections()}


def test_wheel_ships_kernels_and_plugins(wheel):
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
    expected = {f"rsocl/kernels/{k}" for k in KERNELS} | {
        "rsocl/__init__.py",
        "rsocl/kernels/__init__.py",
        "rsocl_plugins/__init__.py",
        "rsocl_plugins/tv.py",
    }
    missing = sorted(expected - names)
    assert not missing, f"{wheel.name} lacks {missing}"
    # Every kernel source in the tree is shipped, under the package, not at the top level.
    in_tree = {f"rsocl/kernels/{p.name}" for p in (ROOT / "kernels").glob("*.cl")}
    assert not sorted(in_tree - names), f"{wheel.name} lacks {sorted(in_tree - names)}"
    stray = sorted(n for n in names if n.split("/")[0] in ("kernels", "plugins", "tests", "benchmarks", "docs"))
    assert not stray, f"{wheel.name} has files outside the rsocl / rsocl_plugins packages: {stray[:10]}"


def test_wheel_entry_points(wheel):
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
        groups = _entry_points(zf)
    regularizers = groups.get("rsocl.regularizers", {})
    assert regularizers.get("tv", "").replace(" ", "") == "rsocl_plugins.tv:TV", groups
    assert groups.get("console_scripts", {}).get("rsocl", "").replace(" ", "") == "rsocl.cli.main:entry", groups
    # Every entry point must name a module the wheel actually contains.
    for group, entries in groups.items():
        for key, target in entries.items():
            module = target.split(":")[0].strip()
            path = module.replace(".", "/")
            assert f"{path}.py" in names or f"{path}/__init__.py" in names, (
                f"entry point [{group}] {key} = {target}: module {module} is not in {wheel.name}"
            )
