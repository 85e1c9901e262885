"""The distribution's name: ours, free on the package index, and the one every hint names."""

import re
import tomllib

import pytest

import scatter_cli
from tests.conftest import ROOT, run_scatter

TAKEN = "scatter-cli"  # an unrelated project on the package index


@pytest.mark.slow
def test_the_distribution_is_named_once_and_read_by_version():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["name"] == scatter_cli.DISTRIBUTION != TAKEN
    proc = run_scatter("--version", check=True)
    assert proc.stdout.decode().strip() == f"scatter {project['version']}"


def test_no_hint_installs_the_other_project():
    """Hints name packages (pip install usd-core) or this distribution's extras, never the
    name that belongs to another project."""
    texts = [*ROOT.joinpath("scatter_cli").rglob("*.py"), *ROOT.joinpath("docs").glob("*.md"), ROOT / "README.md",
             ROOT / "pyproject.toml"]
    offenders = [str(p.relative_to(ROOT)) for p in texts if TAKEN in p.read_text()]
    assert not offenders
    hints = [m for p in ROOT.joinpath("scatter_cli").rglob("*.py") for m in re.findall(r"pip install [^\"')]+", p.read_text())]
    assert hints and not [h for h in hints if "[" in h and not h.startswith("pip install 'dask[")]
