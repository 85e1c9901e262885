"""Numerical hard cases: degenerate faces, slivers, area spreads, huge coordinates, warp ends.

Every statistical test runs at level ALPHA = 1e-3 with a fixed seed and is paired with a
broken sampler (or precision) that must fail the same test. Benchmark-scale versions of
the heavy cases (10 million faces, 10^8 draws) are in benchmarks/hard_cases.py.
"""

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import scatter_cli
from scatter_cli.api import prepare
from scatter_cli.sampling.plan import SamplePlan
from scatter_cli.sampling.sources import RandomSource
from scatter_cli.loading.load import load_surface
from scatter_cli.sampling.warps import square_to_triangle

from testkit.hardcheck import (ALPHA, area_groups, exact_face_errors, pooled_pvalue, recover_bary,
                                  spread_triangles, triangles_mesh, two_sum_le_one, uniform_in_triangle_pvalue)
from .doubles import Float32CdfPlan, UnweightedSource

ON_FACE_UNITS = 4  # "a few ulps": at most 4 roundings of a coordinate away from the face


def world_tri(mesh, face):
    return np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)[face]]


def assert_on_faces(points, tri, units=ON_FACE_UNITS):
    dtype = np.asarray(points).dtype
    dist, over = exact_face_errors(np.asarray(points, np.float64), tri, dtype=dtype)
    assert dist.max() <= units, f"point off its face's plane by {dist.max():.2f} roundings"
    assert over.max() <= units, f"barycentric outside [0, 1] by {over.max():.2f} roundings"


# ---------------------------------------------------------------- zero-area faces


def degenerate_mesh():
    """Two good faces and every kind of zero-area face, interleaved."""
    v = np.array([
        [0, 0, 0], [1, 0, 0], [0, 1, 0],            # 0-2: a good triangle
        [2, 2, 2], [3, 3, 3], [5, 5, 5],            # 3-5: collinear (exact zero cross product)
        [0.1, 0.2, 0.3], [0.2, 0.4, 0.6], [0.3, 0.6, 0.9],  # 6-8: collinear up to rounding
        [1, 0, 0],                                   # 9: duplicate of vertex 1
        [7, 7, 7],                                   # 10: one point
        [0, 0, 1], [1, 0, 1], [0, 1, 1],             # 11-13: a second good triangle
    ], dtype=np.float64)
    f = np.array([
        [3, 4, 5],    # collinear
        [0, 1, 2],    # good
        [0, 0, 1],    # repeated vertex index
        [1, 9, 2],    # duplicated vertex: 1 and 9 are the same point... but 2 is elsewhere
        [1, 9, 1],    # duplicated vertices only
        [10, 10, 10], # all one index
        [6, 7, 8],    # collinear, inexact coordinates
        [11, 12, 13], # good
        [9, 1, 9],
    ])
    return trimesh.Trimesh(v, f, process=False)


@pytest.mark.slow
def test_zero_area_faces_get_no_points_and_nothing_is_nan():
    mesh = degenerate_mesh()
    s = scatter_cli.sample(mesh, 200_000, attributes=("face", "bary", "normal"), seed=1, precision="float64")
    assert np.isfinite(s.points).all() and np.isfinite(s.bary).all() and np.isfinite(s.normal).all()
    # face 3 ([1, 9, 2]) is a real triangle (1 and 9 coincide but 2 does not) only if 9 != 1
    # in space: they coincide, so it has zero area too
    assert set(np.unique(s.face)) == {1, 7}
    np.testing.assert_allclose(np.bincount(s.face, minlength=9)[[1, 7]].sum(), 200_000)
    assert_on_faces(s.points, world_tri(mesh, s.face))
    np.testing.assert_allclose(s.bary.sum(axis=1), 1.0, rtol=0, atol=4e-16)


def test_info_counts_zero_area_faces():
    from scatter_cli.commands.info import describe

    report = describe(degenerate_mesh())
    assert report["faces"] == 9
    assert report["zero_area_faces"] + 2 >= 9 - 1  # the inexact collinear face may round to 1e-17
    assert report["non_finite_faces"] == 0


def test_only_zero_area_faces_is_a_clear_error():
    mesh = trimesh.Trimesh(np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2.0]]), np.array([[0, 1, 2], [0, 0, 1]]), process=False)
    with pytest.raises(scatter_cli.ScatterError, match="non-zero, finite area"):
        scatter_cli.sample(mesh, 10)


# ---------------------------------------------------------------- slivers


def sliver_mesh():
    """Faces of area 1 sharing edges with slivers of aspect ratio 1e8, some of area 1e-20."""
    base = np.sqrt(2e-12)  # base 1e8 h, area base h / 2 = 1e-20
    h = base * 1e-8
    v = np.array([
        [0, 0, 0], [1, 0, 0], [0, 2, 0],                 # 0-2: area 1
        [1, 2e-8, 0],                                    # 3: sliver on edge 0-1: base 1, height 2e-8, area 1e-8
        [1 + base, 0, 0], [1 + base / 2, h, 0],          # 4-5: a sliver of area 1e-20 at vertex 1
        [1e4, 0, 1], [0, 0, 1], [5e3, 2e-4, 1],          # 6-8: base 1e4, height 2e-4: area 1, aspect 5e7
        [0, 0, 3], [1e4, 0, 3], [1e4, 1e-4, 3.0],        # 9-11: long thin right triangle, area 0.5
    ], dtype=np.float64)
    f = np.array([[0, 1, 2], [1, 0, 3], [4, 5, 1], [6, 7, 8], [9, 10, 11]])
    return trimesh.Trimesh(v, f, process=False)


@pytest.mark.slow
def test_slivers_next_to_big_faces():
    mesh = sliver_mesh()
    tri = np.asarray(mesh.vertices)[mesh.faces]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert areas[2] < 1e-19 and areas[1] < 2e-8
    n = 1_000_000
    s = scatter_cli.sample(mesh, n, attributes=("face", "bary"), seed=2, precision="float64")
    assert np.isfinite(s.points).all() and np.isfinite(s.bary).all()
    counts = np.bincount(s.face, minlength=5)
    assert counts[2] == 0  # expects 4e-15 points
    assert pooled_pvalue(counts, n * areas / areas.sum()) > ALPHA
    assert_on_faces(s.points, world_tri(mesh, s.face))


@pytest.mark.slow
def test_points_on_slivers_alone_stay_on_them():
    """A mesh of only slivers (aspect 1e8, areas 1e-20 to 1) so every point lands on one."""
    rng = np.random.default_rng(3)
    tris = []
    for base in (1.41e-6, 1e-2, 1.0, 1e4):
        for _ in range(10):
            a = rng.normal(size=3) * base
            u = rng.normal(size=3); u /= np.linalg.norm(u)
            w = np.cross(u, rng.normal(size=3)); w /= np.linalg.norm(w)
            t = rng.random()
            tris.append([a, a + base * u, a + t * base * u + base * 1e-8 * w])
    mesh = triangles_mesh(np.array(tris))
    s = scatter_cli.sample(mesh, 50_000, attributes=("face",), seed=4, precision="float64")
    assert np.isfinite(s.points).all()
    assert_on_faces(s.points, world_tri(mesh, s.face))
    # the tiny slivers get points too when they are all there is
    small = scatter_cli.sample(triangles_mesh(np.array(tris[:10])), 2000, attributes=("face",), seed=4, precision="float64")
    assert len(np.unique(small.face)) > 5
    assert_on_faces(small.points, world_tri(triangles_mesh(np.array(tris[:10])), small.face))


# ---------------------------------------------------------------- areas over 18 decades


def face_counts(source, faces):
    counts = np.zeros(faces)
    for a in range(0, source.count, 1 << 20):
        counts += np.bincount(source.draw(a, min(source.count, a + (1 << 20))).face, minlength=faces)
    return counts


SOURCES = {
    "scatter": lambda surface, n, seed: RandomSource(SamplePlan(surface), n, seed),
    "unweighted": lambda surface, n, seed: UnweightedSource(SamplePlan(surface), n, seed),
    "float32 CDF": lambda surface, n, seed: RandomSource(Float32CdfPlan(surface), n, seed),
}


@pytest.fixture(scope="module")
def wide_mesh():
    """200,000 faces with areas log-uniform over 1e-12 .. 1e6 (the CI-size version of 10^7)."""
    rng = np.random.default_rng(5)
    exps = rng.uniform(-12, 6, 200_000)
    tri, areas = spread_triangles(exps)
    return load_surface(triangles_mesh(tri)), areas


@pytest.mark.slow
@pytest.mark.parametrize("kind,should_pass", [("scatter", True), ("unweighted", False), ("float32 CDF", False)])
def test_face_shares_follow_areas_from_1e_minus_12_to_1e6(wide_mesh, kind, should_pass):
    surface, areas = wide_mesh
    n = 4_000_000
    counts = face_counts(SOURCES[kind](surface, n, 6), surface.face_count)
    obs, exp = area_groups(areas, counts, n)
    p = pooled_pvalue(obs, exp)
    assert (p > ALPHA) == should_pass, (p, obs, exp.round(1))
    if should_pass:
        # and per face, pooled smallest-expectation first
        assert pooled_pvalue(counts, n * areas / areas.sum()) > ALPHA


# ---------------------------------------------------------------- huge coordinates


def small_mesh(offset=0.0):
    """An irregular closed mesh about 1 across (an icosphere with jittered vertices)."""
    ico = trimesh.creation.icosphere(subdivisions=1)
    v = np.asarray(ico.vertices) * 0.5 + np.random.default_rng(7).normal(scale=0.03, size=ico.vertices.shape)
    return trimesh.Trimesh(v + offset, np.asarray(ico.faces), process=False)


@pytest.fixture(scope="module")
def at_origin():
    return scatter_cli.sample(small_mesh(), 200_000, attributes=("face",), seed=8, precision="float64")


@pytest.mark.slow
@pytest.mark.parametrize("offset", [0.0, 1e3, 1e6, 1e8])
def test_huge_coordinates_points_on_faces_and_uniform(offset, at_origin):
    mesh = small_mesh(np.array([offset, -offset, 0.5 * offset]))
    s = scatter_cli.sample(mesh, 200_000, attributes=("face",), seed=8)  # precision auto
    assert s.points.dtype == (np.float32 if offset == 0 else np.float64)
    p = s.points.astype(np.float64)
    tri = world_tri(mesh, s.face)
    assert_on_faces(s.points, tri)
    # the same faces and positions as at the origin, up to a few roundings of the offset
    np.testing.assert_array_equal(s.face, at_origin.face)
    moved = p - np.array([offset, -offset, 0.5 * offset])
    assert np.abs(moved - at_origin.points).max() <= 4 * float(np.spacing(np.asarray(max(offset, 1.0), s.points.dtype)))
    b1, b2 = recover_bary(p, tri)
    assert uniform_in_triangle_pvalue(b1, b2) > ALPHA


@pytest.mark.parametrize("offset", [1e6, 1e8])
def test_float32_at_huge_coordinates_fails_the_same_test(offset):
    """The paired failure: forcing float32 far from the origin snaps points to a grid."""
    mesh = small_mesh(np.array([offset, -offset, 0.5 * offset]))
    s = scatter_cli.sample(mesh, 200_000, attributes=("face",), seed=8, precision="float32")
    b1, b2 = recover_bary(s.points.astype(np.float64), world_tri(mesh, s.face))
    assert uniform_in_triangle_pvalue(b1, b2) < ALPHA


@pytest.mark.slow
def test_scene_translated_far_away():
    """The offset in a node transform (georeferenced glTF) rather than in the vertices."""
    mesh = small_mesh()
    scene = trimesh.Scene()
    m = np.eye(4)
    m[:3, 3] = [4.2e6, -1.3e6, 7e5]
    scene.add_geometry(mesh, transform=m, geom_name="tile")
    s = scatter_cli.sample(scene, 50_000, attributes=("face",), seed=9)
    assert s.points.dtype == np.float64
    tri = world_tri(mesh, s.face) + m[:3, 3]
    assert_on_faces(s.points, tri)
    b1, b2 = recover_bary(s.points, tri)
    assert uniform_in_triangle_pvalue(b1, b2) > ALPHA


@pytest.mark.slow
def test_auto_precision_switch_is_reported(tmp_path):
    from .conftest import run_scatter

    near = tmp_path / "near.ply"
    far = tmp_path / "far.ply"
    small_mesh().export(near)
    small_mesh(np.array([1e6, 0, 0])).export(far)
    out = tmp_path / "o.ply"
    proc = run_scatter("sample", near, "-n", 10, "-o", out, check=True)
    assert b"float64" not in proc.stderr and b"property float x" in out.read_bytes()[:300]
    proc = run_scatter("sample", far, "-n", 10, "-o", out, check=True)
    assert b"float64" in proc.stderr and b"property double x" in out.read_bytes()[:300]
    assert len(proc.stderr.decode().strip().splitlines()) == 1
    # a stray far-away vertex no face uses does not count (the sampled surface's box)
    stray = small_mesh()
    stray = trimesh.Trimesh(np.vstack([stray.vertices, [[1e9, 1e9, 1e9]]]), stray.faces, process=False)
    assert scatter_cli.sample(stray, 10).points.dtype == np.float32


def signed_zero_vertices(n, seed):
    """(n, 3): column 0 only signed zeros (both bounds a zero), column 1 zeros and
    positives (the minimum a zero), column 2 anything down to infinities."""
    rng = np.random.default_rng(seed)
    v = np.empty((n, 3))
    v[:, 0] = rng.choice([-0.0, 0.0], n)
    v[:, 1] = rng.choice([-0.0, 0.0, 1.0, 2.5], n)
    v[:, 2] = rng.choice([-0.0, 0.0, -np.inf, np.inf, 1.0], n) * rng.standard_normal(n)
    return v


def compiled_bounds(v):
    """sampling.plan.column_bounds with its kernel (skipped where it is not built)."""
    from scatter_cli.sampling import plan

    if plan._kernel is None:
        pytest.skip("_csampling is not built")
    return plan.column_bounds(v)


@pytest.mark.parametrize("rows", [1, 7, 64, 1 << 16, "kernel"])
@pytest.mark.parametrize("n", [1, 6, 7, 8, 9, 63, 64, 65, 1000])
def test_column_bounds_are_numpys_bit_for_bit(n, rows):
    """The blocked bounds (precision, LAS offsets) are v.min/max(axis=0)'s, signed zeros
    and infinities included, whatever the block size, and so are the kernel's (four runs
    of rows, then the four in order); NaN wins as in NumPy."""
    from scatter_cli.surface.model import column_bounds

    for seed in range(4):
        v = signed_zero_vertices(n, seed)
        if seed == 3:
            v[n // 2, 1] = np.nan
        lo, hi = compiled_bounds(v) if rows == "kernel" else column_bounds(v, rows)
        assert lo.tobytes() == v.min(axis=0).tobytes() and hi.tobytes() == v.max(axis=0).tobytes()


@given(st.lists(st.sampled_from([-0.0, 0.0, 1.0, -1.0, np.inf, -np.inf, np.nan, 5e-324]), min_size=3, max_size=120))
def test_the_kernels_bounds_are_numpys_on_any_values(values):
    v = np.array(values[: len(values) // 3 * 3]).reshape(-1, 3)
    lo, hi = compiled_bounds(v)
    assert lo.tobytes() == v.min(axis=0).tobytes() and hi.tobytes() == v.max(axis=0).tobytes()


def test_four_runs_combined_first_to_last_are_needed():
    """The paired failure: the four runs combined last to first give the other zero
    where the ties fall in two runs (the kernel must combine them in order)."""
    v = np.zeros((8, 3))
    v[:4] = -0.0  # runs of 2 rows: the first two runs hold -0.0, the last two 0.0
    runs = [v[k * 2:(k + 1) * 2].min(axis=0) for k in range(4)]
    backwards = np.minimum.reduce(runs[::-1])
    assert backwards.tobytes() != v.min(axis=0).tobytes() == compiled_bounds(v)[0].tobytes()


def test_column_bounds_without_the_last_block_fail_the_same_check():
    """The paired failure: bounds that skip the last partial block (a loop over whole
    blocks only) miss the extremes in it."""
    from scatter_cli.surface.model import column_bounds

    v = np.random.default_rng(0).standard_normal((65, 3))
    v[64] = [-9.0, 9.0, -9.0]
    lo, hi = column_bounds(v[:64], 8)  # what such a loop sees of v with blocks of 8
    assert lo.tobytes() != v.min(axis=0).tobytes() and hi.tobytes() != v.max(axis=0).tobytes()


# ---------------------------------------------------------------- the warp at the ends


ONE_MINUS = np.nextafter(1.0, 0.0)
ONE_MINUS_F32 = float(np.nextafter(np.float32(1.0), np.float32(0.0)))
SPECIAL_U = [0.0, 5e-324, 2.0**-1074, 2.0**-53, 2.0**-52, 1e-300, 1e-17, 0.25, 0.5, 0.75,
             1 - 2.0**-30, ONE_MINUS_F32, ONE_MINUS]
adversarial_u = st.one_of(st.sampled_from(SPECIAL_U), st.floats(0.0, ONE_MINUS),
                          st.integers(0, 2**53 - 1).map(lambda k: k * 2.0**-53))


def check_warp(u):
    b = square_to_triangle(u)
    b1, b2 = b[:, 0], b[:, 1]
    assert (b1 >= 0).all() and (b2 >= 0).all()
    assert two_sum_le_one(b1, b2).all(), "b1 + b2 > 1"
    b0 = 1.0 - b1 - b2
    assert (b0 >= 0).all()
    assert np.abs((b0 + b1 + b2) - 1.0).max() <= 2 * np.finfo(float).eps
    return b


@pytest.mark.slow
@settings(max_examples=400, deadline=None)
@given(st.lists(st.tuples(adversarial_u, adversarial_u), min_size=1, max_size=64))
def test_warp_stays_in_the_triangle_for_adversarial_u(pairs):
    check_warp(np.array(pairs, dtype=np.float64))


def test_warp_ends_exhaustively():
    u = np.array([(a, b) for a in SPECIAL_U for b in SPECIAL_U])
    b = check_warp(u)
    # u1 = 0 is the vertex v1; u1 -> 1 approaches the edge v0 v2
    assert (b[u[:, 0] == 0] == [1.0, 0.0]).all()
    assert (b[u[:, 0] == ONE_MINUS, 0] <= 2**-53).all()


@pytest.mark.slow
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(adversarial_u, adversarial_u), min_size=1, max_size=16),
       st.floats(-1e8, 1e8), st.integers(0, 2**32 - 1))
def test_points_at_the_warp_ends_stay_on_random_triangles(pairs, offset, tseed):
    rng = np.random.default_rng(tseed)
    tri = rng.normal(size=(1, 3, 3)) * 10.0 ** rng.uniform(-3, 3) + offset
    plan = SamplePlan(load_surface(triangles_mesh(tri)))
    b = square_to_triangle(np.array(pairs))
    raw = plan.place(0, np.zeros(len(b), np.int64), b, want_bary=True)
    assert np.isfinite(raw.points).all()
    assert_on_faces(raw.points, np.repeat(tri, len(b), axis=0))
    assert (raw.bary >= 0).all()


def test_a_million_draws_none_outside_the_unit_triangle():
    """On v0 = 0, e1 = x, e2 = y the point is (b1, b2, 0) exactly: inside means exactly inside.
    (10^8 draws: benchmarks/hard_cases.py.)"""
    plan = SamplePlan(load_surface(triangles_mesh([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]])))
    for start in range(0, 1_000_000, 250_000):
        p = plan.draw(start, start + 250_000, seed=10).points
        assert (p[:, 0] >= 0).all() and (p[:, 1] >= 0).all() and (p[:, 2] == 0).all()
        assert two_sum_le_one(p[:, 0], p[:, 1]).all()


# ---------------------------------------------------------------- topology


@pytest.mark.slow
def test_polygons_and_quads_are_triangulated_in_file_order(tmp_path):
    path = tmp_path / "poly.obj"
    path.write_text("v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nv 3 0.5 0\nv 0 0 1\nv 1 0 1\nv 0 1 1\n"
                    "f 1 2 3 4\nf 2 5 3\nf 6 7 8\n")
    mesh = trimesh.load(path, process=False)
    assert len(mesh.faces) == 4
    s = scatter_cli.sample(path, 100_000, attributes=("face",), seed=11, precision="float64")
    tri = world_tri(mesh, s.face)
    assert_on_faces(s.points, tri)
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    all_areas = 0.5 * np.linalg.norm(np.cross(*(np.asarray(mesh.vertices)[mesh.faces][:, 1:] -
                                               np.asarray(mesh.vertices)[mesh.faces][:, :1]).transpose(1, 0, 2)), axis=1)
    assert pooled_pvalue(np.bincount(s.face, minlength=4), 100_000 * all_areas / all_areas.sum()) > ALPHA
    assert np.isclose(areas.max(), 1.0)


def test_ply_quads(tmp_path):
    path = tmp_path / "quads.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    s = scatter_cli.sample(path, 1000, seed=1)
    assert np.isfinite(s.points).all() and (s.points[:, :2] >= 0).all() and (s.points[:, :2] <= 1).all()


@pytest.mark.slow
@pytest.mark.parametrize("dup_seed,should_pass", [(12, True)])
def test_duplicate_faces_count_twice_and_non_manifold_and_flipped(dup_seed, should_pass):
    """Three faces on one edge (non-manifold), one listed twice, one flipped: shares 1:1:2:1."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]], dtype=np.float64)
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [0, 1, 4], [2, 1, 0]])
    mesh = trimesh.Trimesh(v, f, process=False)
    n = 300_000
    s = scatter_cli.sample(mesh, n, attributes=("face", "normal"), seed=dup_seed, precision="float64")
    counts = np.bincount(s.face, minlength=5)
    assert pooled_pvalue(counts, np.full(5, n / 5)) > ALPHA
    # the paired failure: treating the duplicate as one face (shares 1:1:1:1 over 4 faces)
    merged = np.array([counts[0], counts[1], counts[2] + counts[3], counts[4]])
    assert pooled_pvalue(merged, np.full(4, n / 4)) < ALPHA
    # the flipped face's normal points the other way
    assert np.allclose(s.normal[s.face == 0], [0, 0, 1]) and np.allclose(s.normal[s.face == 4], [0, 0, -1])
    assert_on_faces(s.points, world_tri(mesh, s.face))


def test_single_triangle_and_unreferenced_vertices():
    one = trimesh.Trimesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]), np.array([[0, 1, 2]]), process=False)
    s = scatter_cli.sample(one, 1000, attributes=("face", "bary"), seed=13)
    assert (s.face == 0).all() and len(s.points) == 1000
    stray = trimesh.Trimesh(np.array([[np.nan, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0.0], [1e30, 0, 0]]),
                            np.array([[1, 2, 3]]), process=False)
    t = scatter_cli.sample(stray, 1000, seed=13)
    assert t.points.dtype == np.float32 and np.isfinite(t.points).all()
    np.testing.assert_array_equal(t.points, s.points)  # stray vertices change nothing


def test_non_finite_vertices_skip_their_faces():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 0], [np.inf, 1, 1], [0, -np.inf, 0]], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 4, 2], [3, 4, 5], [1, 5, 2]])
    warnings = []
    run = prepare(trimesh.Trimesh(v, f, process=False), 5000, attributes=("face",), warn=warnings.append)
    s = run.collect()
    assert (s.face == 0).all() and np.isfinite(s.points).all()
    assert len(warnings) == 1 and "4 faces" in warnings[0] and "non-finite" in warnings[0]
    with pytest.raises(scatter_cli.ScatterError, match="non-zero, finite area"):
        scatter_cli.sample(trimesh.Trimesh(v, f[1:], process=False), 10)


# ---------------------------------------------------------------- properties over random meshes


@st.composite
def random_meshes(draw):
    """Random triangle soups with shared vertices, degenerate faces, a random placement."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    nv = draw(st.integers(3, 30))
    nf = draw(st.integers(1, 40))
    scale = 10.0 ** draw(st.integers(-6, 6))
    offset = draw(st.sampled_from([0.0, 1.0, 1e3, 1e6, 1e8])) * rng.normal(size=3)
    v = rng.normal(size=(nv, 3)) * scale + offset
    f = rng.integers(0, nv, size=(nf, 3))
    if draw(st.booleans()):  # make some faces degenerate
        k = rng.integers(0, nf, size=max(1, nf // 4))
        f[k, 2] = f[k, 1]
    return v, f


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(random_meshes(), st.integers(0, 3000), st.integers(0, 2**63), st.integers(1, 5000),
       st.sampled_from(["auto", "float64", "float32"]), st.booleans())
def test_random_meshes_invariants(mesh_arrays, count, seed, chunk, precision, in_scene):
    v, f = mesh_arrays
    tri = v[f]
    doubled = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    mesh = trimesh.Trimesh(v, f, process=False)
    matrix = np.eye(4)
    if in_scene:  # a rotation and a translation in a node
        q, _ = np.linalg.qr(np.random.default_rng(seed % 2**32).normal(size=(3, 3)))
        matrix[:3, :3] = q
        matrix[:3, 3] = np.random.default_rng(seed % 7).normal(size=3) * 100
        scene = trimesh.Scene()
        scene.add_geometry(mesh, transform=matrix)
        source = scene
    else:
        source = mesh
    if not (doubled > 0).any():
        with pytest.raises(scatter_cli.ScatterError):
            scatter_cli.sample(source, count, seed=seed)
        return
    if precision == "float32" and np.abs(v).max() > 1e30:
        return
    a = scatter_cli.sample(source, count, seed=seed, attributes=("face", "bary"), precision=precision)
    b = scatter_cli.sample(source, count, seed=seed, attributes=("face", "bary"), precision=precision, chunk_size=chunk)
    assert len(a.points) == count and a.points.shape == (count, 3)  # counts exact
    assert np.isfinite(a.points).all() and np.isfinite(a.bary).all()  # finite output
    assert a.points.tobytes() == b.points.tobytes() and a.face.tobytes() == b.face.tobytes()  # determinism
    assert (doubled[a.face] > 0).all()  # only faces with area
    if count and a.points.dtype == np.float64:
        world = tri[a.face] @ matrix[:3, :3].T + matrix[:3, 3]
        # a rotation adds one rounding of the local coordinates, scaled by |R| = 1
        assert_on_faces(a.points, world, units=ON_FACE_UNITS + (8 if in_scene else 0))


@pytest.mark.slow
def test_rotated_scene_bytes_do_not_depend_on_chunk_size():
    """Regression: the node matrix was applied with a BLAS product, whose rounding depends
    on the number of rows, so --chunk-size changed the output bytes of rotated instances."""
    rng = np.random.default_rng(14)
    scene = trimesh.Scene()
    m = np.eye(4)
    m[:3, :3], _ = np.linalg.qr(rng.normal(size=(3, 3)))
    m[:3, 3] = [1e3, 2, 3]
    scene.add_geometry(trimesh.Trimesh(rng.normal(size=(30, 3)), rng.integers(0, 30, (40, 3)), process=False), transform=m)
    ref = scatter_cli.sample(scene, 5000, seed=3, precision="float64").points.tobytes()
    for chunk in (1, 2, 3, 7, 16, 999):
        assert scatter_cli.sample(scene, 5000, seed=3, precision="float64", chunk_size=chunk).points.tobytes() == ref
