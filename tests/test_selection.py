"""Faces are chosen with probability proportional to their area, exactly.

Chi-square tests at level ALPHA of per-face counts against exact areas, on meshes whose
face areas span many orders of magnitude; each is paired with a sampler that drops the
area weights and must fail the same test.
"""

import numpy as np
import pytest

from scatter_cli.sampling.plan import SamplePlan
from scatter_cli.sampling.sources import RandomSource
from scatter_cli.loading.load import load_surface

from testkit.hardcheck import pooled_pvalue
from .conftest import spread_triangles, triangles_mesh
from .doubles import UnweightedSource

ALPHA = 1e-3


def face_counts(source, faces):
    """(faces,) points per face over all of ``source``'s points."""
    counts = np.zeros(faces)
    for start in range(0, source.count, 1 << 18):
        raw = source.draw(start, min(source.count, start + (1 << 18)))
        counts += np.bincount(raw.face, minlength=faces)
    return counts


def area_weighted(surface, n, seed=0):
    return RandomSource(SamplePlan(surface), n, seed)


def unweighted(surface, n, seed=0):
    return UnweightedSource(SamplePlan(surface), n, seed)


@pytest.fixture(scope="module")
def spread_plan_inputs():
    # areas from 1e-6 to 1e6, four faces per decade
    tri, areas = spread_triangles(np.repeat(np.arange(-6, 7), 4))
    return load_surface(triangles_mesh(tri)), areas


@pytest.mark.parametrize("seed", [0, 1])
def test_face_counts_follow_areas_over_twelve_decades(spread_plan_inputs, seed):
    surface, areas = spread_plan_inputs
    n = 2_000_000
    counts = face_counts(area_weighted(surface, n, seed), surface.face_count)
    assert pooled_pvalue(counts, n * areas / areas.sum()) > ALPHA
    assert counts[areas < 1e-6 * areas.sum() / n].sum() <= 3  # no spurious hits on tiny faces


def test_dropping_area_weights_fails_the_same_test(spread_plan_inputs):
    surface, areas = spread_plan_inputs
    n = 2_000_000
    counts = face_counts(unweighted(surface, n), surface.face_count)
    assert pooled_pvalue(counts, n * areas / areas.sum()) < ALPHA


def test_real_mesh_face_counts_follow_areas(sample_mesh):
    surface = load_surface(sample_mesh("pediment_join_plate_12.stl"))  # area ratio 9.4e6, 12 zero-area faces
    tri = surface.geometries[0].vertices[surface.geometries[0].faces]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    n = 1_000_000
    counts = face_counts(area_weighted(surface, n), surface.face_count)
    assert counts[areas == 0].sum() == 0
    assert pooled_pvalue(counts, n * areas / areas.sum()) > ALPHA
    assert pooled_pvalue(face_counts(unweighted(surface, n), surface.face_count), n * areas / areas.sum()) < ALPHA


def test_tiny_faces_get_their_share_next_to_huge_ones():
    # 1000 faces of area 1e-12 beside one of area 1: together they hold 1e-9 of the area,
    # which float32 accumulation would round away; float64 keeps their CDF steps.
    tri, areas = spread_triangles(np.r_[0.0, np.full(1000, -12.0)])
    plan = SamplePlan(load_surface(triangles_mesh(tri)))
    steps = np.diff(np.r_[0.0, plan.cdf])
    np.testing.assert_allclose(steps[1:], 1e-12, rtol=1e-3)


def select_reference(plan, u):
    """The definition: searchsorted on the CDF, clipped to the last face."""
    return np.minimum(np.searchsorted(plan.cdf, u * plan.cdf[-1], side="right"), len(plan.cdf) - 1)


def adversarial_u(plan):
    """Draws at and just around every CDF step, and the ends of [0, 1)."""
    edges = plan.cdf / plan.cdf[-1]
    u = np.concatenate([edges, np.nextafter(edges, 0), np.nextafter(edges, 1), [0.0, 2.0**-53, np.nextafter(1.0, 0)]])
    return u[(u >= 0) & (u < 1)]


@pytest.mark.parametrize("exponents", [[0, 0, 0], [6, -6, 0, -12, 3], list(range(-12, 7))])
def test_select_equals_searchsorted_and_never_overruns(exponents):
    tri, _ = spread_triangles(exponents)
    plan = SamplePlan(load_surface(triangles_mesh(tri)))
    u = np.concatenate([adversarial_u(plan), np.random.default_rng(1).random(100_000)])
    got = plan.select(u)
    np.testing.assert_array_equal(got, select_reference(plan, u))
    assert got.max() < plan.faces_used


def test_zero_area_faces_are_never_chosen():
    tri, _ = spread_triangles([0, 0, 0, 0])
    zero = np.zeros((3, 3, 3))
    zero[0] = [[0, 0, 9], [1, 0, 9], [2, 0, 9]]  # collinear
    zero[1] = [[5, 5, 5]] * 3  # one point
    zero[2] = [[0, 0, 7], [0, 0, 7], [1, 1, 7]]  # repeated vertex
    mesh = np.concatenate([zero[:1], tri[:2], zero[1:2], tri[2:], zero[2:]])  # last face has zero area
    plan = SamplePlan(load_surface(triangles_mesh(mesh)))
    u = np.concatenate([adversarial_u(plan), [np.nextafter(1.0, 0)] * 3])
    faces = plan.place(0, plan.select(u), np.full((len(u), 2), 0.25)).face
    assert not np.isin(faces, [0, 3, 6]).any()


# ---------------------------------------------------------------------------
# --object and object_index: the index is the one `scatter info` lists, under --object too


def three_cubes(path, instanced=False):
    """A GLB of three unit cubes 3 apart, nodes node0..node2 (one mesh each, or one mesh
    placed three times)."""
    import trimesh

    from testkit.gltfwrite import glb_bytes

    box = trimesh.creation.box()
    meshes = [(box.vertices, box.faces)] * (1 if instanced else 3)
    nodes = []
    for k in range(3):
        matrix = np.eye(4)
        matrix[0, 3] = 3 * k
        nodes.append((0 if instanced else k, matrix))
    path.write_bytes(glb_bytes(meshes, nodes))
    return path


def info_indices(path):
    import json

    from .conftest import run_scatter

    objects = json.loads(run_scatter("info", path, "--json", check=True).stdout)["objects"]
    return {o["name"]: o["index"] for o in objects}


@pytest.mark.slow
@pytest.mark.parametrize("instanced", [False, True])
def test_object_index_under_object_is_the_index_info_lists(tmp_path, instanced):
    import scatter_cli

    from .conftest import run_scatter, scatter_in_process

    path = three_cubes(tmp_path / "three_cubes.glb", instanced)
    listed = info_indices(path)
    assert sorted(listed.values()) == [0, 1, 2] and listed["node0"] != 0  # the case main got wrong
    for k, (name, index) in enumerate(listed.items()):  # (the first in a real process)
        out = tmp_path / f"{name}.csv"
        (run_scatter if k == 0 else scatter_in_process)("sample", path, "--object", name, "-a", "object", "-n", "200",
                                                        "-o", out, check=True)
        written = np.loadtxt(out, delimiter=",", skiprows=1)[:, 3]
        assert set(written.tolist()) == {index}, name
    both = scatter_cli.sample(path, 2000, objects=["node0", "node2"], attributes=["object"])
    assert set(both.object.tolist()) == {listed["node0"], listed["node2"]}
    # the points of each index lie on that node's cube (x in 3k +- 0.5)
    for name in ("node0", "node2"):
        x = both.points[both.object == listed[name], 0]
        centre = 3 * int(name[-1])
        assert np.all(np.abs(x - centre) <= 0.5 + 1e-6), name
