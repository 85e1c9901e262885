"""Scenes: world-space transforms (non-uniform scale changes areas), instancing without
copies, --object selection and the per-point object index.

Two-sample tests compare voxel counts (the two-sample chi-square of
scatter_cli.stats.chisquare) at significance ALPHA,
each with a paired must-fail case.
"""

import numpy as np
import pytest
import trimesh
from scipy import stats

import scatter_cli
from scatter_cli.errors import ScatterError, ScatterUsageError
from scatter_cli.sampling.plan import SamplePlan
from scatter_cli.loading.load import load_surface
from scatter_cli.stats.chisquare import chi2_gof, chi2_two_sample

from .conftest import SAMPLES, run_scatter, scaled_scene

ALPHA = 1e-3


def two_sample_p(a, b, bins=5):
    """p-value that point sets a, b (n, 3) come from one distribution: voxel counts, chi-square."""
    lo = np.minimum(a.min(0), b.min(0))
    hi = np.maximum(a.max(0), b.max(0))
    edges = [np.linspace(lo[i], hi[i] + 1e-9, bins + 1) for i in range(3)]
    ca = np.histogramdd(a, edges)[0].ravel()
    cb = np.histogramdd(b, edges)[0].ravel()
    keep = (ca + cb) > 0
    return chi2_two_sample(ca[keep], cb[keep])[2]


def flattened_sample(mesh, n, seed):
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return pts


def test_instanced_geometry_is_stored_once():
    surface = load_surface(scaled_scene())
    assert len(surface.instances) == 4 and len(surface.geometries) == 2
    plan = SamplePlan(surface)
    assert plan.parts[0].tri is plan.parts[1].tri is plan.parts[2].tri


def test_world_area_includes_non_uniform_scale():
    scene = scaled_scene()
    s = scatter_cli.sample(scene, 10)
    assert s.info["area"] == pytest.approx(scene.to_mesh().area, rel=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("which", ["scaled", "cesiummilktruck.glb"])
def test_scene_and_flattened_mesh_give_the_same_distribution(which):
    scene = scaled_scene() if which == "scaled" else trimesh.load(SAMPLES / which, process=False)
    n = 40_000
    ours = scatter_cli.sample(scene, n, precision="float64", seed=11).points
    flat = flattened_sample(scene.to_mesh(), n, seed=12)
    assert two_sample_p(ours, flat) > ALPHA


def test_must_fail_instances_weighted_by_local_area():
    # Sampling each instance in proportion to its local (untransformed) area, then
    # placing the points, ignores what the non-uniform scale does to areas: caught.
    scene = scaled_scene()
    n = 40_000
    parts, local = [], []
    for node in scene.graph.nodes_geometry:
        m, g = scene.graph[node]
        local.append(scene.geometry[g].area)
    counts = np.random.default_rng(0).multinomial(n, np.array(local) / sum(local))
    for node, k in zip(scene.graph.nodes_geometry, counts):
        m, g = scene.graph[node]
        p, _ = trimesh.sample.sample_surface(scene.geometry[g], k, seed=int(k))
        parts.append(p @ m[:3, :3].T + m[:3, 3])
    wrong = np.concatenate(parts)
    flat = flattened_sample(scene.to_mesh(), n, seed=12)
    assert two_sample_p(wrong, flat) < ALPHA


def test_object_index_counts_follow_world_areas():
    scene = scaled_scene()
    areas = np.array([scene.geometry[scene.graph[nd][1]].copy().apply_transform(scene.graph[nd][0]).area
                      for nd in scene.graph.nodes_geometry])
    s = scatter_cli.sample(scene, 30_000, attributes=("object",), seed=13)
    counts = np.bincount(s.object, minlength=4)
    assert chi2_gof(counts, areas)[2] > ALPHA
    local = np.array([scene.geometry[scene.graph[nd][1]].area for nd in scene.graph.nodes_geometry])
    assert chi2_gof(counts, local)[2] < ALPHA  # must-fail


@pytest.mark.slow
def test_object_selection_by_geometry_and_node_name(tmp_path):
    path = SAMPLES / "cesiummilktruck.glb"
    surface = load_surface(path)
    wheels = [k for k, i in enumerate(surface.instances) if surface.geometries[i.geometry].name == "Wheels"]
    assert len(wheels) == 2
    s = scatter_cli.sample(path, 4000, objects=["Wheels"], attributes=("object",), seed=14)
    assert sorted(np.unique(s.object).tolist()) == wheels  # the indices `scatter info` lists
    c = np.bincount(s.object)[wheels]
    assert stats.binomtest(int(c[0]), int(c.sum()), 0.5).pvalue > ALPHA  # equal world areas
    node = surface.instances[wheels[0]].name
    one = scatter_cli.sample(path, 100, objects=[node], attributes=("object",))
    assert np.all(one.object == wheels[0])
    with pytest.raises(ScatterError, match="Nope") as refused:  # a failure of this mesh, not a usage error
        scatter_cli.sample(path, 10, objects=["Nope"])
    assert not isinstance(refused.value, ScatterUsageError)
    proc = run_scatter("sample", path, "-n", "50", "--object", "Wheels", "-a", "object,color", "-o", tmp_path / "w.csv")
    assert proc.returncode == 0, proc.stderr
    rows = np.loadtxt(tmp_path / "w.csv", delimiter=",", skiprows=1)
    assert rows.shape == (50, 8)


def test_scene_attributes_per_instance_share_geometry_tables():
    scene = scaled_scene()
    s = scatter_cli.sample(scene, 2000, attributes=("smooth-normal", "object"), precision="float64", seed=15)
    np.testing.assert_allclose(np.linalg.norm(s.normal, axis=1), 1.0, atol=1e-12)
    # On the stretched sphere the smooth normal is the gradient direction of the ellipsoid, roughly.
    m = scene.graph["rock_stretched"][0]
    sel = s.object == 1
    local = (s.points[sel] - m[:3, 3]) @ np.linalg.inv(m[:3, :3]).T
    grad = local @ np.linalg.inv(m[:3, :3])
    grad /= np.linalg.norm(grad, axis=1, keepdims=True)
    assert np.median((grad * s.normal[sel]).sum(1)) > 0.95
