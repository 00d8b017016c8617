"""The package's face: ``import rsocl`` gives every name the README uses, and
:func:`rsocl.testing.dottest` checks an operator against its adjoint.

The README's names are resolved in a fresh interpreter that runs only ``import rsocl``, so a
name that works only because some other module happened to be imported first fails here.
"""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import rsocl
from rsocl.common.registry import GROUPS
from rsocl.testing import dottest

README = Path(__file__).resolve().parents[1] / "README.md"
DOTTED = re.compile(r"\brsocl(?:\.[A-Za-z_]\w*)+")
FROM_IMPORT = re.compile(r"^\s*from (rsocl(?:\.\w+)*) import \(?([\w, ]+)\)?", re.M)


def _code_blocks(text):
    return re.findall(r"```python\n(.*?)```", text, re.S)


def _readme_names():
    """``(code, prose)``: the dotted ``rsocl.`` names of the README's Python blocks (``from rsocl.x
    import a`` gives ``rsocl.x.a``), and those of its inline code elsewhere."""
    text = README.read_text(encoding="utf-8")
    blocks = _code_blocks(text)
    code = set()
    for block in blocks:
        code |= set(DOTTED.findall(block))
        for module, names in FROM_IMPORT.findall(block):
            code |= {f"{module}.{name.strip()}" for name in names.split(",") if name.strip()}
    prose_text = re.sub(r"```.*?```", "", text, flags=re.S)
    prose = {name for span in re.findall(r"`([^`\n]+)`", prose_text) for name in DOTTED.findall(span)}
    prose -= set(GROUPS)  # entry-point group names, not Python names
    return sorted(code), sorted(prose - code)


def _resolve_fresh(names, *, import_modules):
    """Names that do not resolve as attributes after ``import rsocl`` alone in a fresh interpreter
    (with ``import_modules``, a module prefix may be imported first, as for ``rsocl.model.reference``)."""
    script = f"""
import importlib, json, sys
import rsocl
missing = []
for name in {names!r}:
    parts = name.split(".")
    obj = rsocl
    try:
        for i, part in enumerate(parts[1:], 2):
            if {import_modules!r} and not hasattr(obj, part):
                importlib.import_module(".".join(parts[:i]))
            obj = getattr(obj, part)
    except (AttributeError, ImportError) as error:
        missing.append(f"{{name}} ({{error}})")
print(json.dumps(missing))
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_readme_code_uses_names_of_import_rsocl():
    code, _ = _readme_names()
    assert "rsocl.reconstruct" in code and "rsocl.Option" in code, code  # the blocks were read
    missing = _resolve_fresh(code, import_modules=False)
    assert not missing, f"names in the README's Python blocks that `import rsocl` does not give: {missing}"


def test_readme_prose_names_exist():
    _, prose = _readme_names()
    assert "rsocl.load_capture" in prose and "rsocl.testing.dottest" in prose, prose
    missing = _resolve_fresh(prose, import_modules=True)
    assert not missing, f"names in the README's text that do not exist: {missing}"


def test_readme_uses_the_face_for_public_names():
    """A name the face exports is written ``rsocl.NAME`` in the README, not by its module path."""
    code, prose = _readme_names()
    deep = [
        n
        for n in code + prose
        if n.count(".") >= 2 and n.rsplit(".", 1)[1] in rsocl.__all__ and not n.startswith("rsocl.testing.")
    ]
    assert not deep, f"write these as rsocl.NAME: {deep}"


def test_every_exported_name_resolves():
    missing = [name for name in rsocl.__all__ if not hasattr(rsocl, name)]
    assert not missing, missing
    for name in (
        "load_capture",
        "save_capture",
        "load_reconstruction",
        "save_reconstruction",
        "reconstruct_sets",
        "psnr",
        "ssim",
        "Regularizer",
        "Option",
        "builtin_scene",
        "interp3d",
    ):
        assert name in rsocl.__all__, name
    assert callable(rsocl.testing.dottest)


def test_import_rsocl_loads_no_heavy_dependency():
    """h5py, scikit-image, pyopencl, matplotlib and SciPy load on first use, not with ``import rsocl``."""
    heavy = ("h5py", "skimage", "pyopencl", "matplotlib", "scipy")
    script = f"import sys, rsocl; print(sorted(m for m in {heavy!r} if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]", done.stdout


# ------------------------------------------------------------------ dottest
def test_dottest_passes_on_the_operator(device, dtype):
    rig = rsocl.Rig(
        [rsocl.Camera(a, t_e=1e-4, t_r=3e-5, gain=g) for a, g in ((0, 1.0), (33, 0.7), (250, 1.3))], shape=(7, 9)
    )
    op = rsocl.RollingShutterOperator(rig, device=device, dtype=dtype)
    assert dottest(op) is True
    assert dottest(op, seed=3, rtol=1e-3) is True


class _Diagonal:
    domain_shape = range_shape = (2, 3, 4)

    def __init__(self, factor=1.0):
        self.d, self.factor = np.linspace(0.5, 2.0, 24).reshape(2, 3, 4), factor

    def forward(self, x):
        return self.d * x

    def adjoint(self, y):
        return self.factor * self.d * y


class _Shift:
    """``A x`` shifts by one along the last axis; its adjoint shifts back."""

    def forward(self, x):
        return np.concatenate([np.zeros(x.shape[:-1] + (1,)), x], axis=-1)

    def adjoint(self, y):
        return y[..., 1:]


def test_dottest_finds_a_wrong_adjoint():
    assert dottest(_Diagonal()) is True
    assert dottest(_Diagonal(1.001), raiseerror=False) is False
    with pytest.raises(AssertionError, match="dot test failed"):
        dottest(_Diagonal(1.001))
    assert dottest(_Diagonal(1.001), rtol=0.01) is True


def test_dottest_with_explicit_shapes():
    assert dottest(_Shift(), (3, 4), (3, 5)) is True
    with pytest.raises(AssertionError, match="range_shape"):
        dottest(_Shift(), (3, 4), (3, 4))


def test_the_readmes_rsocl_info_block_is_what_the_command_prints(capsys):
    """Every ``$ rsocl info ...`` of the README's console blocks is followed by the command's whole output."""
    from rsocl.cli.main import main

    blocks = re.findall(r"```console\n\$ rsocl (info [^\n]*)\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert blocks, "the README shows no `rsocl info` run"
    for command, shown in blocks:
        assert main(command.split()) == 0
        assert capsys.readouterr().out == shown, f"README's `rsocl {command}` differs from what it prints"
