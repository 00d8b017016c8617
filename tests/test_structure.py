"""The package's shape, read from its source: few parameters per function, and rsocl.scale on the
solver's public names only."""

import ast
from pathlib import Path

import rsocl

PACKAGE = Path(rsocl.__file__).parent
#: Most parameters a function takes; a public entry point's keyword-only arguments are not counted.
MOST_PARAMETERS = 12
#: Most lines of a module of the package or its built-in plugins.
MOST_LINES = 400


def _modules(folder=PACKAGE):
    return sorted(folder.rglob("*.py"))


def _public(tree) -> set:
    """Names in the module's ``__all__``."""
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            return {ast.literal_eval(e) for e in node.value.elts}
    return set()


def _too_many(path, root=PACKAGE.parent):
    """``(name, line, count)`` of each function with more than :data:`MOST_PARAMETERS` parameters, its
    keyword-only ones left out for the module's public functions (``__all__``)."""
    tree = ast.parse(path.read_text())
    public = _public(tree)
    found = []
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            functions = [(f, False) for f in node.body if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))]
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            functions = [(node, node.name in public)]
        else:
            continue
        for function, entry in functions:
            for inner in ast.walk(function):
                if not isinstance(inner, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                a = inner.args
                count = len(a.posonlyargs) + len(a.args) + (a.vararg is not None) + (a.kwarg is not None)
                if not (entry and inner is function):
                    count += len(a.kwonlyargs)
                if count > MOST_PARAMETERS:
                    found.append((f"{path.relative_to(root)}:{inner.name}", inner.lineno, count))
    return found


def test_no_function_takes_more_than_twelve_parameters():
    found = [hit for path in _modules() for hit in _too_many(path)]
    assert not found, f"functions with more than {MOST_PARAMETERS} parameters: {found}"


def test_the_count_sees_what_it_should(tmp_path):
    source = tmp_path / "m.py"
    args = ", ".join(f"a{i}" for i in range(13))
    source.write_text(
        f'__all__ = ["entry"]\n\ndef entry(x, *, {args}):\n    pass\n\n'
        f"def helper(x, *, {args}):\n    pass\n\nclass C:\n    def method(self, {args}):\n        pass\n"
    )
    assert [name for name, _, _ in _too_many(source, tmp_path)] == ["m.py:helper", "m.py:method"]


def test_scale_imports_only_public_solver_names():
    """rsocl.scale goes through the solver's public API: no name with a leading underscore, and every
    name it imports from a solver module is in that module's ``__all__``."""
    found = []
    for path in _modules(PACKAGE / "scale"):
        for node in ast.walk(ast.parse(path.read_text())):
            if not (isinstance(node, ast.ImportFrom) and (node.module or "").startswith("rsocl.solver")):
                continue
            module = PACKAGE.parent.joinpath(*node.module.split(".")).with_suffix(".py")
            public = _public(ast.parse(module.read_text()))
            found += [
                f"{path.name}: {node.module}.{alias.name}"
                for alias in node.names
                if alias.name.startswith("_") or alias.name not in public
            ]
    assert not found, found


def test_every_module_stays_small():
    plugins = PACKAGE.parent / "plugins"
    sizes = {
        str(p.relative_to(PACKAGE.parent)): len(p.read_text().splitlines())
        for p in _modules(PACKAGE) + (_modules(plugins) if plugins.is_dir() else [])
    }
    assert len(sizes) > 80, sorted(sizes)
    assert all(n <= MOST_LINES for n in sizes.values()), {k: n for k, n in sizes.items() if n > MOST_LINES}
