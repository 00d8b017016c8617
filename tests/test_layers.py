"""The package's folders are layers: a module imports only from its own layer or the ones below.

Read from the source with ``ast`` (nothing is imported), so a new upward import or an import
circle fails here before it can hide behind a lazy import.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "rsocl"

#: bottom to top; the package's faces (rsocl/__init__.py, ``python -m rsocl``) and rsocl.testing sit above all
LAYERS = ["common", "device", "model", "files", "analysis", "solver", "scale", "hardware", "bench", "cli"]
FACES = {"rsocl", "rsocl.__main__", "rsocl.testing"}


def _module_name(path: Path) -> str:
    parts = ("rsocl",) + path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, module: str):
    """Absolute names of the rsocl modules that ``path`` imports (relative imports resolved)."""
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names if a.name.split(".")[0] == "rsocl")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            if name.split(".")[0] != "rsocl":
                continue
            yield name
            for alias in node.names:  # "from rsocl.model import rig" imports a module
                if (ROOT.parent / Path(*f"{name}.{alias.name}".split("."))).with_suffix(".py").exists():
                    yield f"{name}.{alias.name}"


def _layer(module: str):
    parts = module.split(".")
    if module in FACES or len(parts) < 2:
        return None
    return LAYERS.index(parts[1]) if parts[1] in LAYERS else None


MODULES = {_module_name(p): p for p in sorted(ROOT.rglob("*.py"))}
GRAPH = {m: sorted(set(_imports(p, m))) for m, p in MODULES.items()}


def test_every_module_lives_in_a_layer():
    loose = [m for m in MODULES if m not in FACES and _layer(m) is None]
    assert not loose, f"modules outside the layer folders {LAYERS}: {loose}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if m not in FACES))
def test_imports_go_down_or_sideways(module):
    here = _layer(module)
    up = [
        f"{dep} (layer {LAYERS[_layer(dep)]})"
        for dep in GRAPH[module]
        if _layer(dep) is not None and _layer(dep) > here
    ]
    assert not up, f"{module} (layer {LAYERS[here]}) imports from a higher layer: {up}"


def test_no_import_circle():
    state, stack = {}, []

    def visit(m):
        state[m] = "open"
        stack.append(m)
        for dep in GRAPH.get(m, ()):
            dep = dep if dep in MODULES else dep.rsplit(".", 1)[0]
            if dep == m or dep not in MODULES:
                continue
            if state.get(dep) == "open":
                circle = stack[stack.index(dep) :] + [dep]
                # a package's __init__ re-exporting its own modules is not a circle
                if not all(x == dep or x.startswith(dep + ".") for x in circle):
                    raise AssertionError("import circle: " + " -> ".join(circle))
            elif dep not in state:
                visit(dep)
        stack.pop()
        state[m] = "done"

    for m in MODULES:
        if m not in state:
            visit(m)


def test_the_public_api_is_where_it_was():
    import rsocl
    import rsocl.testing

    for name in ("Camera", "Rig", "RollingShutterOperator", "reconstruct", "Result"):
        assert hasattr(rsocl, name), name
    assert callable(rsocl.testing.check_regularizer)
