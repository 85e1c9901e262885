"""Every option, and every combination, that is wrong whatever the mesh is refused before
the file is read (a large mesh is not loaded and planned only to be refused)."""

import pytest

from scatter_cli import api
from scatter_cli.errors import ScatterUsageError

from .conftest import run_scatter

WRONG_FOR_ANY_MESH = {
    "--poisson with --radius": dict(poisson=True, radius=0.5),
    "--radius with --density": dict(radius=0.5, density=10.0),
    "--method with --poisson": dict(method="stratified", poisson=True),
    "--method with --radius": dict(method="sobol", radius=0.5),
    "--method with --weight": dict(method="stratified", weight="vertex-color:r"),
    "sobol past 2^32": dict(count=2**32 + 1, method="sobol"),
    "an unknown weight": dict(weight="curvature:r"),
    "too many --poisson points": dict(count=10**8, poisson=True),
    "oversampling below 0": dict(poisson=True, oversampling=-2),
    "count and density": dict(count=10, density=1.0),
}


def refuse_to_load(*args, **kwargs):
    raise AssertionError("the file was read before the options were checked")


@pytest.mark.parametrize("options", list(WRONG_FOR_ANY_MESH.values()), ids=list(WRONG_FOR_ANY_MESH))
def test_wrong_options_are_refused_before_the_file_is_read(monkeypatch, options):
    monkeypatch.setattr(api, "load_surface", refuse_to_load)
    with pytest.raises(ScatterUsageError):
        api.prepare("never-read.ply", **options)


def test_right_options_do_read_the_file(monkeypatch):
    # the same check with options that are fine: the loader is reached (the test can fail)
    monkeypatch.setattr(api, "load_surface", refuse_to_load)
    with pytest.raises(AssertionError, match="was read"):
        api.prepare("never-read.ply", 10, poisson=True)


def test_the_command_names_the_option_not_the_missing_file(tmp_path):
    proc = run_scatter("sample", tmp_path / "missing.ply", "--poisson", "--radius", 0.5)
    err = proc.stderr.decode()
    assert proc.returncode == 2 and err.startswith("error: give either --poisson") and len(err.splitlines()) == 1
