"""Poisson-disk thinning through the API and the command: spacing, maximality, exact
counts, quality (rho), coarse-scale uniformity, determinism."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

import scatter_cli
from scatter_cli import api
from scatter_cli.stats import uniformity
from scatter_cli.commands.check import world_triangles
from scatter_cli.loading.load import load_surface
from scatter_cli.sampling.poisson.spacing import relative_radius

from .conftest import run_scatter

ALPHA = 1e-3


def min_distance(points):
    d, _ = cKDTree(points).query(points, k=2)
    return d[:, 1].min()


@pytest.mark.slow
@pytest.mark.parametrize("name,radius", [("skull.ply", 0.35), ("koala.obj", 0.08), ("cesiummilktruck.glb", 0.1)])
def test_radius_mode_is_spaced_and_maximal(sample_mesh, name, radius):
    run = api.prepare(sample_mesh(name), radius=radius, precision="float64", seed=2)
    kept = run.kept.points
    assert min_distance(kept) >= radius
    # maximal: every candidate is within R of a kept point
    candidates = run.source.candidates.draw(0, run.info["candidates"]).points
    d, _ = cKDTree(kept).query(candidates)
    assert d.max() < radius
    assert run.count == len(kept) > 10


@pytest.mark.parametrize("name,count", [("skull.ply", 3000), ("koala.obj", 20000), ("spot_triangulated.obj", 5000)])
def test_exact_count_and_rho(sample_mesh, name, count):
    s = scatter_cli.sample(sample_mesh(name), count, poisson=True, precision="float64", seed=1)
    assert len(s.points) == count
    d = min_distance(s.points)
    assert d == pytest.approx(s.info["d_min"])
    area = s.info["area"]
    assert relative_radius(d, area, count) >= 0.75


def test_exact_count_rho_on_a_sphere():
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=5)
    s = scatter_cli.sample(sphere, 10000, poisson=True, precision="float64")
    assert len(s.points) == 10000
    assert relative_radius(min_distance(s.points), sphere.area, 10000) >= 0.75


def face_order_thinning(candidates, count):
    """A wrong thinning: keeps the candidates of the lowest-numbered faces."""
    raw = candidates.draw(0, candidates.count)
    return raw.points[np.argsort(raw.face, kind="stable")[:count]]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["skull.ply", "koala.obj"])
def test_thinned_set_is_uniform_at_coarse_scale(sample_mesh, name):
    surface = load_surface(sample_mesh(name))
    tri, areas = world_triangles(surface)
    good = scatter_cli.sample(surface, 5000, poisson=True, precision="float64", seed=3).points
    # coarse scale: 8 equal-area slabs per direction, far wider than the disk radius
    assert uniformity.region_test(good, tri, areas, k=8)["p_slabs"] > ALPHA
    candidates = api.prepare(surface, 50_000, precision="float64", seed=3).source
    assert uniformity.region_test(face_order_thinning(candidates, 5000), tri, areas, k=8)["p_slabs"] < ALPHA


def test_thinning_with_attributes_and_scene(sample_mesh):
    s = scatter_cli.sample(sample_mesh("cesiummilktruck.glb"), 800, poisson=True, attributes=("normal", "object", "face"))
    assert len(s.points) == 800 and s.normal.shape == (800, 3) and s.object.max() >= 3
    np.testing.assert_allclose(np.linalg.norm(s.normal, axis=1), 1, atol=1e-6)


def test_thinned_points_keep_their_face_and_weights(sample_mesh):
    # Candidates are drawn without barycentric weights unless an attribute needs them.
    surface = load_surface(sample_mesh("skull.ply"))
    s = scatter_cli.sample(surface, 2000, poisson=True, attributes=("face", "bary"), precision="float64")
    g = surface.geometries[0]
    rebuilt = np.einsum("ij,ijk->ik", s.bary, g.vertices[g.faces[s.face]])
    extent = np.ptp(g.vertices, axis=0).max()
    np.testing.assert_allclose(rebuilt, s.points, rtol=0, atol=1e-9 * extent)


@pytest.mark.slow
@pytest.mark.parametrize("args", [["--poisson", "-n", "700"], ["--radius", "0.5"]])
def test_command_is_deterministic_across_chunk_sizes(sample_mesh, tmp_path, args):
    outs = []
    for chunk in ["1000000", "77"]:
        out = tmp_path / f"o{chunk}.ply"
        run_scatter("sample", sample_mesh("skull.ply"), *args, "--seed", 5, "-a", "face", "--chunk-size", chunk, "-o", out, check=True)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]


@pytest.mark.slow
def test_radius_larger_than_the_mesh_gives_one_point(sample_mesh):
    proc = run_scatter("sample", sample_mesh("icosahedron_binary.stl"), "--radius", 100, "-f", "xyz", check=True)
    assert len(proc.stdout.splitlines()) == 1


@pytest.mark.slow
def test_tiny_radius_is_a_clear_error(sample_mesh):
    proc = run_scatter("sample", sample_mesh("skull.ply"), "--radius", 1e-5)
    # too small for this mesh's area: a failure of the mesh (exit 1), as in a batch
    assert proc.returncode == 1 and proc.stderr.decode().startswith("error: --radius")


@pytest.mark.slow
def test_poisson_and_radius_together_is_a_usage_error(sample_mesh):
    proc = run_scatter("sample", sample_mesh("skull.ply"), "--radius", 1, "--poisson")
    assert proc.returncode == 2 and b"error:" in proc.stderr


@pytest.mark.slow
def test_stats_report_rho(sample_mesh, tmp_path):
    import json

    run_scatter("sample", sample_mesh("skull.ply"), "--poisson", "-n", 1000, "-o", tmp_path / "p.ply", "--stats", tmp_path / "s.json", check=True)
    info = json.loads((tmp_path / "s.json").read_text())
    assert info["count"] == 1000 and info["rho"] > 0.7 and info["mean_nn"] > info["d_min"] > 0


@pytest.mark.slow
def test_check_poisson_against_pymeshlab(sample_mesh):
    pytest.importorskip("pymeshlab")
    from scatter_cli.commands.check import run_check

    lines = []
    assert run_check(sample_mesh("skull.ply"), count=5000, poisson=True, out=lines.append) == 0, "\n".join(lines)
    assert any("relative radius" in l for l in lines)
    lines = []
    assert run_check(sample_mesh("skull.ply"), count=5000, radius=0.3, out=lines.append) == 0, "\n".join(lines)
