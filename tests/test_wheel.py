"""The wheel that a plain ``pip install .`` builds holds every subpackage of scatter_cli
(every folder with an ``__init__.py``) and every kernel of native.KERNELS, compiled, in
its package's folder. Building it takes a minute (pip sets up the build requirements and
the kernels compile): marked slow."""

import shutil
import sys
import zipfile
from pathlib import Path

import pytest

from scatter_cli.core import native

from .conftest import run_user

ROOT = Path(__file__).resolve().parents[1]
LEFT_BEHIND = (".git", ".venv", "build", "dist", "*.egg-info", "__pycache__", "*.so", ".pytest_cache", ".hypothesis",
               "bench-out")


def packages(root=ROOT):
    """The folders of ``root``/scatter_cli with an __init__.py, as paths in a wheel."""
    return sorted(p.parent.relative_to(root).as_posix() for p in (root / "scatter_cli").rglob("__init__.py"))


def wheel_gaps(names, folders, kernels):
    """What a wheel holding the files ``names`` lacks: the package ``folders`` without their
    __init__.py, and the kernels (native.KERNELS) without a compiled module in their package."""
    missing = [f"{folder}/__init__.py" for folder in folders if f"{folder}/__init__.py" not in names]
    for name, entry in kernels.items():
        stem = "/".join([*entry.package.split("."), name]) + "."
        if not any(n.startswith(stem) and n.endswith((".so", ".pyd")) for n in names):
            missing.append(stem + "so")
    return missing


@pytest.mark.slow
def test_the_wheel_holds_every_subpackage_and_every_kernel(tmp_path):
    source = tmp_path / "source"  # a fresh checkout's files: no kernel built in place
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(*LEFT_BEHIND))
    run_user([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"), str(source)],
             check=True, timeout=900)
    (wheel,) = (tmp_path / "dist").glob("*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert not wheel_gaps(names, packages(), native.KERNELS)


def test_a_package_or_kernel_missing_from_the_wheel_is_reported():
    whole = {f"{f}/__init__.py" for f in packages()}
    whole |= {"/".join([*e.package.split("."), k]) + ".cpython-311-x86_64-linux-gnu.so" for k, e in native.KERNELS.items()}
    assert wheel_gaps(whole, packages(), native.KERNELS) == []
    assert wheel_gaps(whole - {"scatter_cli/volume/__init__.py"}, packages(), native.KERNELS) == [
        "scatter_cli/volume/__init__.py"]
    gone = native.KERNELS | {"_cgone": native.Kernel("scatter_cli.sampling", ("plan",))}  # a kernel setup.py did not build
    assert wheel_gaps(whole, packages(), gone) == ["scatter_cli/sampling/_cgone.so"]
