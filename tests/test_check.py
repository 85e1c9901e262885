"""`scatter check` passes this tool on real meshes and fails a sampler that drops area weights."""

import numpy as np
import pytest

pytest.importorskip("pymeshlab")

from scatter_cli.check import ALPHA, run_check  # noqa: E402
from scatter_cli.sampling import SamplePlan  # noqa: E402
from scatter_cli.loaders import load_surface  # noqa: E402

from .conftest import run_scatter  # noqa: E402
from .doubles import UnweightedSource  # noqa: E402

MESHES = ["skull.ply", "koala.obj", "spot_triangulated.obj", "cesiummilktruck.glb"]


def unweighted_sampler(surface, count, seed):
    return UnweightedSource(SamplePlan(surface), count, seed).draw(0, count).points


@pytest.mark.parametrize("name", MESHES)
def test_check_passes_on_real_meshes(sample_mesh, name):
    lines = []
    assert run_check(sample_mesh(name), count=50_000, seed=1, out=lines.append) == 0, "\n".join(lines)
    assert lines[-1].startswith("PASS")


@pytest.mark.parametrize("name", ["skull.ply", "koala.obj", "cesiummilktruck.glb"])
def test_check_fails_when_area_weights_are_dropped(sample_mesh, name):
    lines = []
    code = run_check(load_surface(sample_mesh(name)), count=50_000, seed=1, sampler=unweighted_sampler, out=lines.append)
    assert code == 1, "\n".join(lines)
    assert lines[-1].startswith("FAIL")


def test_check_command_exit_code_and_table(sample_mesh):
    proc = run_scatter("check", sample_mesh("hemisphere.off"), "-n", 20000)
    out = proc.stdout.decode()
    assert proc.returncode == 0, out + proc.stderr.decode()
    assert "pymeshlab" in out and "two-sample" in out and f"alpha = {ALPHA:g}" in out
