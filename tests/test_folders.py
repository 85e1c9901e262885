"""Tests and benchmarks do not import each other; what both use is in testkit/, which
imports neither. Every Python file of the three folders is parsed, imports inside
functions and child scripts held in strings included."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# folder -> the folders its files may not import
APART = {"tests": ("benchmarks",), "benchmarks": ("tests",), "testkit": ("tests", "benchmarks")}


def imported_names(text):
    """Every module that an absolute import names in ``text``, or in code held in one of
    its strings (the script of a child process)."""
    names = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            names.append(node.module)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and "import" in node.value:
            try:
                names += imported_names(node.value)
            except SyntaxError:
                pass
    return names


def crossings(root):
    """[(file, module)]: each import of a folder that APART keeps it from, by its package
    name or by a module's bare name (a folder put on sys.path)."""
    stems = {folder: {p.stem for p in (root / folder).rglob("*.py")} for folder in APART}
    found = []
    for folder, banned in APART.items():
        for path in sorted((root / folder).rglob("*.py")):
            for name in imported_names(path.read_text()):
                top = name.split(".")[0]
                if top in banned or any(top in stems[b] and top not in stems[folder] for b in banned):
                    found.append((path.relative_to(root).as_posix(), name))
    return found


@pytest.mark.slow
def test_tests_and_benchmarks_do_not_import_each_other():
    assert not crossings(ROOT)


def test_an_import_across_is_reported(tmp_path):
    # (the names filled in at run time: as written here, this file imports nothing across)
    texts = {"tests": "from {benchmarks}.harness import run\n",
             "benchmarks": 'CHILD = """\nimport numpy\nfrom {tests}.conftest import SAMPLES\n"""\n',
             "testkit": "def f():\n    import sys\n    sys.path.insert(0, 'benchmarks')\n    import {harness}\n"}
    for folder, text in texts.items():
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "a.py").write_text(text.format(benchmarks="benchmarks", tests="tests", harness="harness"))
    (tmp_path / "benchmarks" / "harness.py").write_text("import testkit\n")  # allowed
    assert crossings(tmp_path) == [("tests/a.py", "benchmarks.harness"), ("benchmarks/a.py", "tests.conftest"),
                                   ("testkit/a.py", "harness")]
