"""The package's layers (``scatter_cli.LAYERS``): no module imports one of a later layer,
function-level imports included, and no two modules import each other in a cycle.

Every module of the package is parsed (nothing is imported), so the test sees what the
code says, not what one run happens to load."""

import ast
import shutil
from pathlib import Path

import pytest

import scatter_cli

PACKAGE = Path(scatter_cli.__file__).resolve().parent


def module_names(root=PACKAGE):
    """{dotted name under the package ("" for the package itself): path} of every module."""
    names = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        names[".".join(parts)] = path
    return names


def imports_of(name, path, modules):
    """The package modules that module ``name`` imports anywhere in its text."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)] if node.level > 1 else package
                target = ".".join(base + ([node.module] if node.module else []))
            elif node.module and (node.module + ".").startswith("scatter_cli."):
                target = node.module[len("scatter_cli."):]
            elif node.module == "scatter_cli":
                target = ""
            else:
                continue
            for alias in node.names:  # `from . import native`: the names may be modules
                sub = f"{target}.{alias.name}".lstrip(".")
                found.add(sub if sub in modules else target)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("scatter_cli."):
                    found.add(alias.name[len("scatter_cli."):])
    return {m for m in found if m in modules and m != name}


def layer_of(name, layers):
    """The index of the layer of module ``name``: its longest entry that names it or a
    folder above it; None for the package itself (``__init__``), which sits on top."""
    best, rank = None, -1
    for index, entries in enumerate(layers):
        for entry in entries:
            if (name == entry or name.startswith(entry + ".")) and len(entry) > rank:
                best, rank = index, len(entry)
    return best


def backward_imports(root=PACKAGE, layers=scatter_cli.LAYERS):
    """[(module, what it imports)] where the import goes to a later layer, plus modules
    that no layer names."""
    modules = module_names(root)
    wrong = []
    for name, path in modules.items():
        if name == "":
            continue
        mine = layer_of(name, layers)
        if mine is None:
            wrong.append((name, "<no layer>"))
            continue
        for other in sorted(imports_of(name, path, modules)):
            theirs = layer_of(other, layers)
            if theirs is not None and theirs > mine:
                wrong.append((name, other))
    return wrong


def cycle(root=PACKAGE):
    """One import cycle among the package's modules (a list of names), or None."""
    modules = module_names(root)
    graph = {name: imports_of(name, path, modules) - {""} for name, path in modules.items() if name}
    state = {}

    def visit(name, trail):
        state[name] = "open"
        for other in sorted(graph[name]):
            if state.get(other) == "open":
                return trail[trail.index(other):] + [other]
            if other not in state:
                found = visit(other, trail + [other])
                if found:
                    return found
        state[name] = "done"
        return None

    for name in sorted(graph):
        if name not in state:
            found = visit(name, [name])
            if found:
                return found
    return None


@pytest.mark.slow
def test_no_module_imports_one_of_a_later_layer():
    assert backward_imports() == []


@pytest.mark.slow
def test_no_import_cycle():
    assert cycle() is None


def test_every_layer_names_something_that_exists():
    modules = module_names()
    for entries in scatter_cli.LAYERS:
        for entry in entries:
            assert any(m == entry or m.startswith(entry + ".") for m in modules), entry


def test_at_most_about_fifteen_modules_at_the_top():
    top = [p for p in PACKAGE.glob("*.py")]
    assert len(top) <= 15, sorted(p.name for p in top)


@pytest.fixture
def copy(tmp_path):
    shutil.copytree(PACKAGE, tmp_path / "scatter_cli", ignore=shutil.ignore_patterns("*.so", "__pycache__"))
    return tmp_path / "scatter_cli"


@pytest.mark.slow
def test_a_backward_import_inside_a_function_fails(copy):
    """The broken variant: the surface model importing the loader in a function."""
    with open(copy / "surface" / "model.py", "a") as f:
        f.write("\n\ndef load(path):\n    from ..loading.load import load_surface\n\n    return load_surface(path)\n")
    assert backward_imports(copy) == [("surface.model", "loading.load")]


@pytest.mark.slow
def test_a_backward_absolute_import_fails(copy):
    with open(copy / "core" / "hashing.py", "a") as f:
        f.write("\nimport scatter_cli.sampling.plan\n")
    assert backward_imports(copy) == [("core.hashing", "sampling.plan")]


@pytest.mark.slow
def test_a_module_outside_every_layer_fails(copy):
    (copy / "stray").mkdir()
    (copy / "stray" / "__init__.py").write_text("")
    assert ("stray", "<no layer>") in backward_imports(copy)


@pytest.mark.slow
def test_the_cycle_finder_sees_a_function_level_import(copy):
    with open(copy / "sampling" / "warps.py", "a") as f:
        f.write("\n\ndef plan():\n    from . import plan\n\n    return plan\n")
    assert cycle(copy) in (["sampling.plan", "sampling.warps", "sampling.plan"],
                           ["sampling.warps", "sampling.plan", "sampling.warps"])
