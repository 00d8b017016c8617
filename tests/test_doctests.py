"""The ``Examples`` of the public API's docstrings run, and give what they show.

Each module's doctests run on rsocl's default device (as the other tests), with small shapes and
few iterations. A module listed here with no example fails, so an example cannot vanish unseen.
"""

import doctest
import importlib

import pytest

import rsocl

MODULES = [
    "rsocl",
    "rsocl.testing",
    "rsocl.model.camera",
    "rsocl.model.rig",
    "rsocl.model.operator",
    "rsocl.model.interpolation",
    "rsocl.model.scenes",
    "rsocl.model.simulate",
    "rsocl.analysis.metrics",
    "rsocl.files.hdf5",
    "rsocl.files.hdf5_reconstruction",
    "rsocl.common.validation",
    "rsocl_plugins.tv",
]

#: Public names whose docstring must hold a runnable ``Examples`` section.
WITH_EXAMPLES = [
    "Camera",
    "Rig",
    "RollingShutterOperator",
    "interp3d",
    "builtin_scene",
    "benchmark_protocol",
    "simulate",
    "psnr",
    "ssim",
    "save_capture",
    "save_reconstruction",
]


@pytest.mark.parametrize("name", MODULES)
def test_examples_run(name):
    module = importlib.import_module(name)
    flags = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
    result = doctest.testmod(module, optionflags=flags, report=False, raise_on_error=False)
    assert result.attempted > 0, f"{name} has no example"
    assert result.failed == 0, (
        f"{result.failed} of {result.attempted} examples of {name} failed (run python -m doctest -v on it)"
    )


@pytest.mark.parametrize("name", WITH_EXAMPLES)
def test_public_names_have_examples(name):
    doc = getattr(rsocl, name).__doc__ or ""
    assert "Examples\n" in doc and ">>> " in doc, f"rsocl.{name}'s docstring has no Examples section"


def test_every_public_name_is_documented():
    bare = [
        name
        for name in rsocl.__all__
        if name != "__version__" and len((getattr(rsocl, name).__doc__ or "").strip()) < 20
    ]
    assert not bare, f"public names without a docstring: {bare}"
