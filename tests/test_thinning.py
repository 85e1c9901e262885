"""Tests for scatter_cli.sampling.poisson.thinning: spacing, maximality, exact counts, quality,
coarse uniformity and determinism.  All random inputs use fixed seeds."""

import math

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from scatter_cli.stats.chisquare import chi2_gof
from scatter_cli.sampling.poisson.spacing import relative_radius, spacing_stats
from scatter_cli.sampling.poisson.thinning import thin_by_radius, thin_to_count

from .conftest import SAMPLES

SPHERE_AREA = 4.0 * math.pi


def sphere_points(n, seed):
    """(n, 3) float64 uniform on the unit sphere (normalised Gaussians)."""
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1)[:, None]


def mesh_points(mesh, n, seed):
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(pts, dtype=np.float64)


def brute_min_distance(p):
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    return d.min()


def kd_min_distance(p):
    d, _ = cKDTree(p).query(p, 2)
    return d[:, 1].min()


def assert_poisson_disk(points, kept, radius):
    """Kept points >= radius apart and every candidate within radius of one."""
    q = points[kept]
    assert np.unique(kept).size == kept.size
    if kept.size > 1:
        dmin = brute_min_distance(q) if kept.size <= 2000 else kd_min_distance(q)
        assert dmin >= radius
    _, nearest = cKDTree(q).query(points, 1)
    # the thinning's own criterion, squared and summed in the same order: a candidate
    # exactly at sqrt-rounded distance R must still be strictly inside
    diff = points - q[nearest]
    d2 = diff[:, 0] ** 2 + diff[:, 1] ** 2 + diff[:, 2] ** 2
    assert d2.max() < radius * radius


# --- thin_by_radius -------------------------------------------------------


@pytest.mark.parametrize("n, radius", [(500, 0.3), (3000, 0.1), (40000, 0.02)])
def test_by_radius_sphere_spacing_and_maximal(n, radius):
    p = sphere_points(n, seed=n)
    kept = thin_by_radius(p, radius)
    assert kept.dtype == np.int64
    assert np.all(np.diff(kept) > 0)
    assert_poisson_disk(p, kept, radius)


@pytest.mark.slow
@pytest.mark.parametrize(
    "mesh",
    [
        trimesh.creation.torus(major_radius=1.0, minor_radius=0.3),
        trimesh.creation.capsule(height=1.0, radius=0.4),
        trimesh.creation.box(extents=(1.0, 2.0, 0.5)),
    ],
    ids=["torus", "capsule", "box"],
)
def test_by_radius_meshes(mesh):
    p = mesh_points(mesh, 20000, seed=7)
    assert_poisson_disk(p, thin_by_radius(p, 0.05), 0.05)


@pytest.mark.slow
def test_thin_wall_uses_3d_distance():
    # two parallel plates 0.01 apart: a surface-only (per-plate) thinning
    # would keep points facing each other across the wall
    wall = trimesh.creation.box(extents=(1.0, 1.0, 0.01))
    p = mesh_points(wall, 20000, seed=3)
    radius = 0.05
    kept = thin_by_radius(p, radius)
    assert_poisson_disk(p, kept, radius)
    top = p[kept][:, 2] > 0
    # both plates keep points, yet no top/bottom pair is closer than radius
    assert 0 < top.sum() < kept.size
    d, _ = cKDTree(p[kept][top]).query(p[kept][~top], 1)
    assert d.min() >= radius
    idx, d_min = thin_to_count(p, 150, wall.area)
    assert idx.size == 150 and kd_min_distance(p[idx]) == pytest.approx(d_min)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(0, 120),
    radius=st.floats(0.01, 3.0),
    seed=st.integers(0, 2**32 - 1),
    clustered=st.booleans(),
)
def test_by_radius_property(n, radius, seed, clustered):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1, 1, size=(n, 3))
    if clustered and n:
        p = np.round(p, 1)  # many exact duplicates
    kept = thin_by_radius(p, radius)
    if n == 0:
        assert kept.size == 0
        return
    assert_poisson_disk(p, kept, radius)


def test_by_radius_degenerate():
    p = sphere_points(100, seed=1)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError):
            thin_by_radius(p, bad)
    assert thin_by_radius(p, 10.0).size == 1
    assert thin_by_radius(np.zeros((0, 3)), 0.1).size == 0
    assert thin_by_radius(np.zeros((1000, 3)), 0.1).size == 1
    with pytest.raises(ValueError):
        thin_by_radius(np.zeros((4, 2)), 0.1)


def test_checker_can_fail():
    p = sphere_points(3000, seed=8)
    kept = thin_by_radius(p, 0.1)
    with pytest.raises(AssertionError):  # not maximal: one kept point dropped
        assert_poisson_disk(p, kept[1:], 0.1)
    with pytest.raises(AssertionError):  # too close: spacing of a larger radius asked
        assert_poisson_disk(p, kept, 0.2)


# --- thin_to_count --------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("count", [2, 17, 500, 2999, 3000])
def test_to_count_exact(count):
    p = sphere_points(3000, seed=11)
    idx, d_min = thin_to_count(p, count, SPHERE_AREA)
    assert idx.dtype == np.int64 and idx.size == count
    assert np.unique(idx).size == count
    assert d_min == pytest.approx(brute_min_distance(p[idx]))


@pytest.mark.slow
def test_to_count_degenerate():
    p = sphere_points(50, seed=2)
    with pytest.raises(ValueError, match="more than the 50 candidate"):
        thin_to_count(p, 51, SPHERE_AREA)
    with pytest.raises(ValueError):
        thin_to_count(p, -1, SPHERE_AREA)
    with pytest.raises(ValueError):
        thin_to_count(p, 10, 0.0)
    idx, d_min = thin_to_count(p, 50, SPHERE_AREA)
    assert np.array_equal(idx, np.arange(50))
    assert d_min == pytest.approx(brute_min_distance(p))
    assert thin_to_count(p, 0, SPHERE_AREA)[0].size == 0
    assert thin_to_count(p, 1, SPHERE_AREA)[0].size == 1
    assert thin_to_count(np.zeros((0, 3)), 0, 1.0)[0].size == 0
    dup = np.zeros((300, 3))
    idx, d_min = thin_to_count(dup, 7, 1.0)
    assert idx.size == 7 and np.unique(idx).size == 7 and d_min == 0.0


# Quality: 10x oversampling must reach rho >= 0.75 (pymeshlab: about 0.76).
@pytest.mark.parametrize("count", [2000, 10000])
def test_to_count_rho_sphere(count):
    p = sphere_points(10 * count, seed=count)
    idx, d_min = thin_to_count(p, count, SPHERE_AREA)
    assert idx.size == count
    assert kd_min_distance(p[idx]) == pytest.approx(d_min)
    assert relative_radius(d_min, SPHERE_AREA, count) >= 0.75
    # the same threshold rejects a plain random subset
    random_subset = np.arange(count)
    assert relative_radius(kd_min_distance(p[random_subset]), SPHERE_AREA, count) < 0.75


def _skull():
    return trimesh.load(SAMPLES / "skull.ply", force="mesh")


@pytest.mark.parametrize(
    "make",
    [
        lambda: trimesh.creation.torus(major_radius=1.0, minor_radius=0.3),
        lambda: trimesh.creation.capsule(height=1.0, radius=0.4),
        _skull,
    ],
    ids=["torus", "capsule", "skull"],
)
def test_to_count_rho_meshes(make):
    mesh = make()
    count = 5000
    p = mesh_points(mesh, 10 * count, seed=5)
    idx, d_min = thin_to_count(p, count, mesh.area)
    assert idx.size == count
    assert relative_radius(d_min, mesh.area, count) >= 0.75


# --- coarse uniformity ------------------------------------------------------


def chi2_equal_cells_pass(labels, cells):
    """Whether counts in ``cells`` equally likely cells pass chi-square at alpha = 0.001."""
    return chi2_gof(np.bincount(labels, minlength=cells), np.ones(cells))[2] > 1e-3


def sphere_uniform_at_coarse_scale(q):
    """Chi-square at alpha = 0.001 of counts in the 8 octants and in 10 z-slabs
    of equal height (equal areas by Archimedes).  True if both pass."""
    octant = (q[:, 0] > 0) * 4 + (q[:, 1] > 0) * 2 + (q[:, 2] > 0)
    slab = np.clip(((q[:, 2] + 1.0) * 5.0).astype(int), 0, 9)
    return chi2_equal_cells_pass(octant, 8) and chi2_equal_cells_pass(slab, 10)


def test_uniform_at_coarse_scale_and_must_fail_case():
    p = sphere_points(40000, seed=21)
    count = 4000
    idx, _ = thin_to_count(p, count, SPHERE_AREA)
    assert sphere_uniform_at_coarse_scale(p[idx])
    kept = thin_by_radius(p, 0.05)
    assert sphere_uniform_at_coarse_scale(p[kept])
    # a thinning that keeps candidates in sorted-by-x order is not uniform
    bad = np.argsort(p[:, 0], kind="stable")[:count]
    assert not sphere_uniform_at_coarse_scale(p[bad])
    # nor is one that keeps a random half of the x < 0.2 candidates only
    rng = np.random.default_rng(5)
    tilted = np.flatnonzero((p[:, 0] < 0.2) & (rng.random(p.shape[0]) < 0.5))[:count]
    assert not sphere_uniform_at_coarse_scale(p[tilted])


# --- determinism ------------------------------------------------------------


def test_deterministic():
    p = sphere_points(30000, seed=4)
    a = thin_by_radius(p, 0.03)
    b = thin_by_radius(p.copy(), 0.03)
    assert a.tobytes() == b.tobytes()
    i1, d1 = thin_to_count(p, 3000, SPHERE_AREA)
    i2, d2 = thin_to_count(np.array(p, order="F"), 3000, SPHERE_AREA)
    assert i1.tobytes() == i2.tobytes() and d1 == d2


# --- statistics -----------------------------------------------------------


def test_relative_radius_of_hex_lattice_is_one():
    a = 0.1
    ii, jj = np.meshgrid(np.arange(60), np.arange(60), indexing="ij")
    x = a * (ii + 0.5 * (jj % 2))
    y = a * (math.sqrt(3) / 2) * jj
    p = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    area = p.shape[0] * (math.sqrt(3) / 2) * a * a
    stats = spacing_stats(p, area)
    assert stats["d_min"] == pytest.approx(a)
    assert stats["mean_nn"] == pytest.approx(a)
    assert stats["rho"] == pytest.approx(1.0)
    assert relative_radius(a, area, p.shape[0]) == pytest.approx(1.0)


def test_spacing_stats_matches_kdtree():
    p = sphere_points(5000, seed=9)
    stats = spacing_stats(p, SPHERE_AREA)
    d, _ = cKDTree(p).query(p, 2)
    assert stats["d_min"] == pytest.approx(d[:, 1].min())
    assert stats["mean_nn"] == pytest.approx(d[:, 1].mean())
    # an isolated far point still gets its true nearest neighbour
    far = np.vstack([p, [[50.0, 0.0, 0.0]]])
    assert spacing_stats(far, SPHERE_AREA)["mean_nn"] == pytest.approx(
        cKDTree(far).query(far, 2)[0][:, 1].mean()
    )
    assert math.isnan(spacing_stats(p[:1], SPHERE_AREA)["rho"])
