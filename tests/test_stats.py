"""Tests for the statistics of scatter check: scatter_cli.stats.measures, .chisquare and .uniformity.

Statistical tests use fixed seeds and the significance level ALPHA; every
bound below is one that a wrong formula would exceed.
"""

import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy import stats as sps

from scatter_cli.stats import chisquare, measures as surface_measures, uniformity

from . import exact_reference

ALPHA = 1e-3


# ---------------------------------------------------------------------------
# helpers


def arrays(mesh):
    return np.array(mesh.triangles, dtype=float), np.array(mesh.area_faces, dtype=float)


def barycentric_points(tri, faces, rng):
    u1, u2 = rng.random(len(faces)), rng.random(len(faces))
    b1 = 1.0 - np.sqrt(u1)
    b2 = np.sqrt(u1) * u2
    v0, v1, v2 = tri[faces, 0], tri[faces, 1], tri[faces, 2]
    return v0 + b1[:, None] * (v1 - v0) + b2[:, None] * (v2 - v0)


def sample_uniform(tri, areas, n, rng):
    """Correct sampler: face by area, then uniform inside the face."""
    cum = np.cumsum(areas)
    faces = np.minimum(np.searchsorted(cum, rng.random(n) * cum[-1], side="right"), len(cum) - 1)
    return barycentric_points(tri, faces, rng)


def sample_face_uniform(tri, n, rng):
    """Wrong sampler: every face equally likely whatever its area."""
    return barycentric_points(tri, rng.integers(0, len(tri), n), rng)


def capsule():
    return trimesh.creation.capsule(height=2.0, radius=0.5, count=[16, 16])


def sphere():
    return trimesh.creation.uv_sphere(radius=1.0, count=[24, 24])


def offset_box():
    box = trimesh.creation.box(extents=[1.0, 2.0, 0.5])
    box.apply_translation([1e5, -3e5, 2e5])
    return box


def test_meshes_have_unequal_face_areas():
    for mesh in (capsule(), sphere()):
        _, areas = arrays(mesh)
        assert areas.max() > 5 * areas.min()


# ---------------------------------------------------------------------------
# distribution functions


def test_normal_sf_is_two_sided():
    z = np.array([-5.0, -1.96, 0.0, 0.5, 3.0, 8.0])
    assert np.allclose(uniformity.normal_sf(z), 2 * sps.norm.sf(np.abs(z)), rtol=1e-13, atol=0)
    assert uniformity.normal_sf(1.959963984540054) == pytest.approx(0.05, rel=1e-12)


def test_chi2_gof_matches_scipy_without_pooling():
    rng = np.random.default_rng(5)
    expected = rng.uniform(20, 80, 12)
    observed = rng.poisson(expected)
    expected = expected * observed.sum() / expected.sum()
    stat, dof, p = chisquare.chi2_gof(observed, expected)
    ref = sps.chisquare(observed, expected)
    assert dof == 11
    assert stat == pytest.approx(ref.statistic, rel=1e-12)
    assert p == pytest.approx(ref.pvalue, rel=1e-9)


def test_chi2_gof_pools_small_bins_in_order():
    expected = np.array([1.0, 2.0, 3.0, 10.0, 1.0, 1.0])  # -> [1+2+3], [10+1+1]
    observed = np.array([0, 4, 4, 6, 2, 2])
    stat, dof, p = chisquare.chi2_gof(observed, expected, min_expected=5)
    e = np.array([6.0, 12.0])
    o = np.array([8.0, 10.0])
    assert dof == 1
    assert stat == pytest.approx(float(((o - e) ** 2 / e).sum()), rel=1e-14)
    assert p == pytest.approx(sps.chi2.sf(stat, 1), rel=1e-10)
    # probabilities are rescaled to the observed total
    assert chisquare.chi2_gof(observed, expected / expected.sum())[0] == pytest.approx(stat, rel=1e-12)
    assert chisquare.chi2_gof([3, 1], [2, 2]) == (0.0, 0, 1.0)


def test_chi2_two_sample_matches_contingency_table():
    rng = np.random.default_rng(6)
    a = rng.poisson(rng.uniform(30, 90, 9))
    b = rng.poisson(rng.uniform(60, 200, 9))
    stat, dof, p = chisquare.chi2_two_sample(a, b)
    ref = sps.chi2_contingency(np.vstack((a, b)), correction=False)
    assert dof == ref.dof == 8
    assert stat == pytest.approx(ref.statistic, rel=1e-12)
    assert p == pytest.approx(ref.pvalue, rel=1e-9)
    # a bin with almost nothing is pooled into its neighbour
    stat2, dof2, _ = chisquare.chi2_two_sample(np.append(a, 1), np.append(b, 0))
    assert dof2 == 8 and stat2 >= 0


# ---------------------------------------------------------------------------
# height distribution


def lattice_fraction_below(v, d, t, n=600):
    """Brute force: centroids of the n^2 congruent sub-triangles of a triangle,
    fraction with height <= t (error below ~2/n)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    up = i + j <= n - 1
    down = i + j <= n - 2
    b_up = np.column_stack(((i[up] + 1 / 3) / n, (j[up] + 1 / 3) / n))
    b_down = np.column_stack(((i[down] + 2 / 3) / n, (j[down] + 2 / 3) / n))
    b = np.vstack((b_up, b_down))
    pts = v[0] + b[:, :1] * (v[1] - v[0]) + b[:, 1:] * (v[2] - v[0])
    hts = pts @ d
    return np.array([(hts <= s).mean() for s in t])


def test_height_cdf_single_triangle_against_lattice():
    rng = np.random.default_rng(7)
    v = rng.normal(size=(3, 3))
    area = 0.5 * np.linalg.norm(np.cross(v[1] - v[0], v[2] - v[0]))
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    h = np.sort(v @ d)
    t = np.linspace(h[0] - 0.1, h[2] + 0.1, 41)
    got = exact_reference.height_cdf(v[None], np.array([area]), d, t)
    brute = lattice_fraction_below(v, d, t) * area
    assert np.max(np.abs(got - brute)) < 2.0 / 600 * area
    at_middle = exact_reference.height_cdf(v[None], np.array([area]), d, h[1])
    assert at_middle == pytest.approx(area * (h[1] - h[0]) / (h[2] - h[0]), rel=1e-12)


def test_height_cdf_equal_heights_have_no_nan():
    d = np.array([0.0, 0.0, 1.0])
    flat = np.array([[0, 0, 1.0], [1, 0, 1.0], [0, 1, 1.0]])
    base_low = np.array([[0, 0, 0.0], [1, 0, 0.0], [0, 0, 2.0]])  # h0 == h1
    base_high = np.array([[0, 0, 0.0], [1, 0, 2.0], [0, 0, 2.0]])  # h1 == h2
    tri = np.stack((flat, base_low, base_high, flat))
    areas = np.array([0.5, 1.0, 1.0, 0.0])  # last face has zero area
    t = np.array([-1.0, 0.0, 0.5, 1.0 - 1e-12, 1.0, 1.5, 2.0, 3.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = exact_reference.height_cdf(tri, areas, d, t)
    flat_part = 0.5 * (t >= 1.0)
    low_part = np.where(t >= 2, 1.0, (1 - (2 - t) ** 2 / 4) * (t >= 0))
    high_part = np.where(t >= 2, 1.0, t**2 / 4 * (t >= 0))
    assert np.allclose(got, flat_part + low_part + high_part, rtol=0, atol=1e-12)
    assert exact_reference.height_cdf(tri, areas, d, np.zeros((2, 3))).shape == (2, 3)


@pytest.mark.slow
def test_height_cdf_matches_monte_carlo_dkw():
    """sup |ECDF - F| <= eps with probability 1 - ALPHA (DKW inequality)."""
    tri, areas = arrays(capsule())
    rng = np.random.default_rng(8)
    n = 10**6
    pts = sample_uniform(tri, areas, n, rng)
    eps = math.sqrt(math.log(2 / ALPHA) / (2 * n))
    for d in ([0.0, 0.0, 1.0], [0.3, -0.5, 0.8]):
        d = np.array(d) / np.linalg.norm(d)
        hts = np.sort(pts @ d)
        t = np.linspace(hts[0], hts[-1], 2001)
        ecdf = np.searchsorted(hts, t, side="right") / n
        cdf = exact_reference.height_cdf(tri, areas, d, t) / areas.sum()
        assert np.max(np.abs(ecdf - cdf)) < eps


@pytest.mark.parametrize(
    "make, k",
    [(capsule, 7), (capsule, 32), (sphere, 32), (lambda: trimesh.creation.icosphere(3), 50)],
)
def test_equal_area_slabs_hold_equal_areas(make, k):
    tri, areas = arrays(make())
    rng = np.random.default_rng(9)
    for d in np.vstack((np.eye(3), rng.normal(size=(2, 3)))):
        edges = exact_reference.equal_area_slabs(tri, areas, d, k)
        hts = tri @ (d / np.linalg.norm(d))
        assert edges.shape == (k + 1,)
        assert np.all(np.diff(edges) > 0)
        assert edges[0] == pytest.approx(hts.min(), abs=1e-12)
        assert edges[-1] == pytest.approx(hts.max(), abs=1e-12)
        shares = np.diff(exact_reference.height_cdf(tri, areas, d, edges)) / areas.sum()
        assert np.allclose(shares, 1.0 / k, rtol=1e-8, atol=0)
        assert np.allclose(exact_reference.slab_probabilities(tri, areas, d, edges), 1.0 / k, rtol=1e-8, atol=0)


def test_equal_area_slabs_on_box_with_flat_faces():
    tri, areas = arrays(trimesh.creation.box())
    for d in np.eye(3):
        # the end faces are steps of 1/6: quarters are still reachable
        edges = exact_reference.equal_area_slabs(tri, areas, d, 4)
        assert np.allclose(edges, [-0.5, -0.375, 0.0, 0.375, 0.5], atol=1e-9)
        assert np.allclose(exact_reference.slab_probabilities(tri, areas, d, edges), 0.25, atol=1e-9)


def test_slab_counts_convention():
    edges = np.array([0.0, 1.0, 2.0, 3.0])
    hts = np.array([-1.0, 0.0, 0.5, 1.0, 1.5, 3.0, 4.0])
    pts = np.column_stack((np.zeros_like(hts), np.zeros_like(hts), hts))
    assert surface_measures.slab_counts(pts, [0, 0, 2.0], edges).tolist() == [4, 1, 2]


# ---------------------------------------------------------------------------
# the exact slabs against every face's closed form


def _face_areas(tri):
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def _slab_mesh(name):
    """Meshes where no halving lands on its target within rounding: a noisy terrain (many
    faces crossing every level), a triangle soup, a soup of coordinates rounded to 0.1
    (faces flat along the axes: jumps of the area) and a sphere far from the origin."""
    rng = np.random.default_rng(5)
    if name == "terrain":
        n = 40
        x, y = np.meshgrid(np.linspace(0, 10, n), np.linspace(0, 10, n))
        z = np.sin(x / 2) * np.cos(y / 3) + rng.normal(0, 0.05, x.shape)
        i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
        faces = np.r_[np.c_[i, i + 1, i + n], np.c_[i + 1, i + n + 1, i + n]]
        return np.c_[x.ravel(), y.ravel(), z.ravel()][faces]
    if name == "soup":
        return rng.normal(size=(600, 3, 3))
    if name == "rounded soup":
        return np.round(rng.normal(size=(600, 3, 3)), 1)
    return np.array(trimesh.creation.icosphere(3).triangles) * 1e3 + 5e6


def _same_slabs(a, b, tol=1e-13):
    """Whether two ``surface_measures.slabs`` results have the same edges, bit for bit, and
    probabilities within tol."""
    return len(a) == len(b) and all(
        np.array_equal(ea, eb) and np.allclose(pa, pb, rtol=0, atol=tol) for (_, ea, pa), (_, eb, pb) in zip(a, b)
    )


def _slabs(tri, monkeypatch=None, solve=None):
    with monkeypatch.context() if monkeypatch else _no_patch() as m:
        if solve:
            m.setattr(surface_measures, "_solve_heights", solve)
        return surface_measures.slabs(tri, _face_areas(tri), uniformity.default_directions(), 32)


class _no_patch:
    def __enter__(self):
        return None

    def __exit__(self, *exc):
        return False


def _direct(solve=None):
    return exact_reference.with_direct_areas(solve or surface_measures._solve_heights)


@pytest.mark.parametrize("name", ["terrain", "soup", "rounded soup", "far sphere"])
def test_exact_slab_areas_equal_every_faces_sum(name, monkeypatch):
    """The slabs' probabilities (the area below each edge from the faces gathered per
    bracket: wholly below, or the closed form of each face crossing) equal the area below
    the same edges summed over every face's closed form within 1e-13: at a million
    points a share off by 1e-13 moves an expected count by 1e-7, far below what the
    chi-square test can see. And the slabs hold equal areas: each within 2^-12 of a
    slab of its 1/32 (SLAB_ITERATIONS), none merged."""
    tri = _slab_mesh(name)
    fast = _slabs(tri)
    assert _same_slabs(fast, _slabs(tri, monkeypatch, _direct()))
    for _, edges, prob in fast:
        assert len(prob) == 32
        assert np.abs(prob * 32 - 1).max() <= 2.0**-surface_measures.SLAB_ITERATIONS


@pytest.mark.slow
def test_the_slab_checks_fail_a_wrong_area_and_an_off_by_one_slab(monkeypatch):
    """The checks above fail an area function missing part of one face (2e-13 of the
    area: twice the tolerance), probabilities shifted by one slab, edges shifted by one
    target (a slab of twice the area next to one of none) and a solver stopped early."""
    tri = _slab_mesh("terrain")
    fast = _slabs(tri)
    total = _face_areas(tri).sum()
    solve = surface_measures._solve_heights

    def wrong_area(h, areas, targets, iterations, pad=0.0):
        hi, area_at = _direct(solve)(h, areas, targets, iterations, pad)
        return hi, lambda t: area_at(t) - np.where(np.arange(len(t)) == 5, 2e-13 * total, 0.0)

    def shifted(h, areas, targets, iterations, pad=0.0):
        hi, area_at = solve(h, areas, targets, iterations, pad)
        return np.r_[hi[1:], hi[-1:]], area_at

    def early(h, areas, targets, iterations, pad=0.0):
        return solve(h, areas, targets, 4, pad)

    def equal(slabs):
        return all(len(p) == 32 and np.abs(p * 32 - 1).max() <= 2.0**-surface_measures.SLAB_ITERATIONS
                   for _, _, p in slabs)

    assert _same_slabs(fast, _slabs(tri, monkeypatch, _direct())) and equal(fast)
    assert not _same_slabs(fast, _slabs(tri, monkeypatch, wrong_area))
    assert not _same_slabs(fast, [(d, e, np.roll(p, 1)) for d, e, p in fast])
    assert not equal(_slabs(tri, monkeypatch, shifted))
    assert not equal(_slabs(tri, monkeypatch, early))


@pytest.mark.slow
def test_exact_slabs_survive_a_wrong_first_guess(monkeypatch):
    """Brackets around a wrong first guess (every target guessed at the lowest height)
    widen until they hold their targets: the same equal-area slabs with exact areas.
    Brackets that are not widened (a single try) leave slabs that are not."""
    import functools

    from scatter_cli.stats import slabs as slab_heights

    tri = _slab_mesh("terrain")
    monkeypatch.setattr(slab_heights, "_guess",
                        lambda h, areas, targets, lo0, hi0: (np.full(len(targets), lo0), 1e-3 * (hi0 - lo0)))
    got = _slabs(tri)
    assert _same_slabs(got, _slabs(tri, monkeypatch, _direct()))
    assert all(len(p) == 32 and np.abs(p * 32 - 1).max() <= 2.0**-surface_measures.SLAB_ITERATIONS for _, _, p in got)
    monkeypatch.setattr(slab_heights, "_bracket", functools.partial(slab_heights._bracket, tries=0))
    assert not all(len(p) == 32 and np.abs(p * 32 - 1).max() <= 2.0**-surface_measures.SLAB_ITERATIONS
                   for _, _, p in _slabs(tri))


@pytest.mark.parametrize("name", ["box", "three boxes", "torus"])
def test_exact_slab_probabilities_are_the_shares_of_their_edges(name):
    """On symmetric meshes a halving can land on its target within rounding, where either
    neighbouring step is an equally good edge; whichever is found, its probabilities are
    the exact shares of the slabs between the edges (every face's closed form)."""
    if name == "torus":
        tri = np.array(trimesh.creation.torus(2, 0.5).triangles)
    else:
        count = 3 if name == "three boxes" else 1
        tri = np.concatenate([trimesh.creation.box().apply_translation((3 * i, 0, 0.5 * i)).triangles
                              for i in range(count)])
    areas = _face_areas(tri)
    for d, edges, prob in surface_measures.slabs(tri, areas, uniformity.default_directions(), 32):
        assert np.allclose(prob, exact_reference.slab_probabilities(tri, areas, d, edges), rtol=0, atol=1e-13)


# ---------------------------------------------------------------------------
# moments


def unit_square():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    tri = np.stack((v[[0, 1, 2]], v[[0, 2, 3]]))
    return tri, np.array([0.5, 0.5])


def test_surface_moments_exact_square_and_cube():
    mean, second = exact_reference.surface_moments(*unit_square())
    assert np.allclose(mean, [0.5, 0.5, 0.0], atol=1e-15)
    assert np.allclose(second, [[1 / 3, 1 / 4, 0], [1 / 4, 1 / 3, 0], [0, 0, 0]], atol=1e-15)

    tri, areas = arrays(trimesh.creation.box())
    mean, second = exact_reference.surface_moments(tri + 0.5, areas)  # cube [0, 1]^3
    assert np.allclose(mean, 0.5, atol=1e-15)
    # E[x^2]: faces x=0 -> 0, x=1 -> 1, four others -> 1/3; E[xy] = 1/4
    expect = np.full((3, 3), 0.25) + np.eye(3) * (7 / 18 - 0.25)
    assert np.allclose(second, expect, atol=1e-14)


def test_surface_covariance_survives_large_offsets():
    tri, areas = arrays(capsule())
    mean0, cov0 = surface_measures.surface_covariance(tri, areas)
    mean1, cov1 = surface_measures.surface_covariance(tri + 1e8, areas)
    assert np.allclose(mean1 - 1e8, mean0, atol=1e-6)
    assert np.allclose(cov1, cov0, atol=1e-6 * np.abs(cov0).max())


@pytest.mark.slow
def test_surface_moments_against_monte_carlo():
    """10^7 uniform points; all 3 mean and 6 second-moment z-scores within
    the Bonferroni bound for ALPHA."""
    mesh = trimesh.creation.cone(radius=1.0, height=2.0, sections=24)
    mesh.apply_translation([0.3, -1.0, 2.0])
    tri, areas = arrays(mesh)
    mean, second = exact_reference.surface_moments(tri, areas)
    rng = np.random.default_rng(10)
    pairs = surface_measures.COV_PAIRS
    n, chunk = 10**7, 10**6
    s1 = np.zeros(3)
    s2 = np.zeros(len(pairs))
    s4 = np.zeros(len(pairs))
    for _ in range(n // chunk):
        p = sample_uniform(tri, areas, chunk, rng)
        prod = np.column_stack([p[:, i] * p[:, j] for i, j in pairs])
        s1 += p.sum(axis=0)
        s2 += prod.sum(axis=0)
        s4 += (prod**2).sum(axis=0)
    cov = second - np.outer(mean, mean)
    z_mean = (s1 / n - mean) / np.sqrt(np.diag(cov) / n)
    m2 = s2 / n
    exact2 = np.array([second[i, j] for i, j in pairs])
    z_second = (m2 - exact2) / np.sqrt((s4 / n - m2**2) / n)
    bound = sps.norm.isf(ALPHA / (2 * 9))
    assert np.all(np.abs(z_mean) < bound), z_mean
    assert np.all(np.abs(z_second) < bound), z_second


def test_moment_z_scores_flag_face_uniform_sampling():
    tri, areas = arrays(sphere())
    rng = np.random.default_rng(11)
    bound = sps.norm.isf(ALPHA / (2 * 9))
    z_mean, z_cov = uniformity.moment_z_scores(sample_uniform(tri, areas, 50_000, rng), tri, areas)
    assert np.all(np.abs(z_mean) < bound) and np.all(np.abs(z_cov) < bound)
    # uv-sphere faces shrink towards the poles: face-uniform points crowd there
    z_mean, z_cov = uniformity.moment_z_scores(sample_face_uniform(tri, 50_000, rng), tri, areas)
    assert z_cov[2] > bound


def test_moment_z_scores_flat_mesh_is_finite():
    tri, areas = unit_square()
    pts = sample_uniform(tri, areas, 5000, np.random.default_rng(12))
    z_mean, z_cov = uniformity.moment_z_scores(pts, tri, areas)
    assert np.all(np.isfinite(z_mean)) and np.all(np.isfinite(z_cov))
    assert abs(z_mean[2]) < 1e-3 and np.all(np.abs(z_cov[[2, 4, 5]]) < 1e-3)


# ---------------------------------------------------------------------------
# quadrature


@pytest.mark.parametrize("order", range(1, 11))
def test_triangle_quadrature_exact_to_its_degree(order):
    nodes, weights = surface_measures.triangle_quadrature(order)
    assert nodes.shape == (order * (order + 1), 3) and weights.shape == (order * (order + 1),)
    assert np.all(nodes >= 0) and np.allclose(nodes.sum(axis=1), 1.0, atol=1e-15)
    assert np.all(weights > 0) and weights.sum() == pytest.approx(1.0, rel=1e-14)
    x, y = nodes[:, 1], nodes[:, 2]
    degree = 2 * order - 1
    for a in range(degree + 1):
        for b in range(degree + 1 - a):
            # mean of x^a y^b over the reference triangle
            mean = 2.0 * math.factorial(a) * math.factorial(b) / math.factorial(a + b + 2)
            assert weights @ (x**a * y**b) == pytest.approx(mean, rel=1e-12, abs=1e-15)
    beyond = 2.0 * math.factorial(degree + 1) / math.factorial(degree + 3)
    assert abs(weights @ y ** (degree + 1) - beyond) > 1e-13 * beyond  # the degree is tight


def test_surface_integral_reproduces_moments():
    tri, areas = arrays(capsule())
    mean, second = exact_reference.surface_moments(tri, areas)
    got = surface_measures.surface_integral(lambda p: np.column_stack((p, p[:, [0, 1, 2]] * p[:, [0, 0, 2]])), tri, areas, 2)
    total = areas.sum()
    assert np.allclose(got[:3] / total, mean, atol=1e-13)
    assert np.allclose(got[3:] / total, [second[0, 0], second[0, 1], second[2, 2]], rtol=1e-12)


def subdivide(tri, times):
    """Split every triangle into four by its edge midpoints (same surface)."""
    for _ in range(times):
        m01, m12, m20 = (tri[:, 0] + tri[:, 1]) / 2, (tri[:, 1] + tri[:, 2]) / 2, (tri[:, 2] + tri[:, 0]) / 2
        tri = np.concatenate(
            (
                np.stack((tri[:, 0], m01, m20), axis=1),
                np.stack((m01, tri[:, 1], m12), axis=1),
                np.stack((m20, m12, tri[:, 2]), axis=1),
                np.stack((m01, m12, m20), axis=1),
            )
        )
    return tri


@pytest.mark.slow
def test_surface_integral_converges_for_smooth_function():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.apply_scale([1.0, 0.7, 1.3])
    tri, areas = arrays(mesh)
    f = lambda p: surface_measures.smooth_test_function(p, mesh.bounds)
    values = np.array([surface_measures.surface_integral(f, tri, areas, order) for order in range(1, 9)])
    errors = np.abs(values[:-1] - values[-1])
    assert errors[-1] < 1e-12 * abs(values[-1])
    assert np.all(errors[1:5] < errors[0:4])  # monotone while above round-off
    # independent reference: a 64-fold finer split of the same surface, low order
    fine = subdivide(tri, 3)
    fine_areas = 0.5 * np.linalg.norm(np.cross(fine[:, 1] - fine[:, 0], fine[:, 2] - fine[:, 0]), axis=1)
    assert surface_measures.surface_integral(f, fine, fine_areas, 3) == pytest.approx(values[-1], rel=1e-9)
    # and Monte Carlo: z-score within the ALPHA bound
    rng = np.random.default_rng(13)
    sample = f(sample_uniform(tri, areas, 10**6, rng)) * areas.sum()
    z = (sample.mean() - values[-1]) / (sample.std() / math.sqrt(len(sample)))
    assert abs(z) < sps.norm.isf(ALPHA / 2)


def test_smooth_test_function_is_scale_free():
    pts = np.random.default_rng(14).uniform(-1, 1, (100, 3))
    bounds = np.array([[-1.0, -1, -1], [1, 1, 1]])
    a = surface_measures.smooth_test_function(pts, bounds)
    b = surface_measures.smooth_test_function(pts * 1e3 + 5e6, bounds * 1e3 + 5e6)
    assert a.shape == (100,) and np.allclose(a, b, atol=1e-9)
    assert np.ptp(a) > 0.5


# ---------------------------------------------------------------------------
# region tests


@pytest.mark.parametrize("make", [capsule, sphere, offset_box])
@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_region_test_accepts_uniform_samples(make, seed):
    tri, areas = arrays(make())
    pts = sample_uniform(tri, areas, 20_000, np.random.default_rng(seed))
    out = uniformity.region_test(pts, tri, areas)
    assert out["p"] > ALPHA, out
    assert len(out["slab_p"]) == 7 and len(out["z_cov"]) == 6
    assert all(dof >= 1 for dof in out["slab_dof"])


@pytest.mark.parametrize("make", [capsule, sphere])
def test_region_test_rejects_face_uniform_sampler(make):
    tri, areas = arrays(make())
    pts = sample_face_uniform(tri, 20_000, np.random.default_rng(15))
    out = uniformity.region_test(pts, tri, areas)
    assert out["p"] < ALPHA, out
    assert out["p_slabs"] < ALPHA


@pytest.mark.parametrize("make", [capsule, sphere])
def test_two_sample_test(make):
    tri, areas = arrays(make())
    rng = np.random.default_rng(16)
    a = sample_uniform(tri, areas, 20_000, rng)
    b = sample_uniform(tri, areas, 35_000, rng)
    bad = sample_face_uniform(tri, 35_000, rng)
    assert uniformity.two_sample_test(a, b, tri, areas)["p"] > ALPHA
    assert uniformity.two_sample_test(a, bad, tri, areas)["p"] < ALPHA


def test_fourth_moments_rule_agrees_with_the_product_rule():
    """The 6-point degree-4 rule of the fourth moments against the 12-point product rule
    (exact to degree 5) on random triangles; a degree-3 rule (the broken variant: the
    order-2 product rule) is off by far more."""
    rng = np.random.default_rng(1)
    tri, areas = rng.normal(size=(50, 3, 3)), rng.random(50) + 0.1
    i = np.array([p[0] for p in surface_measures.COV_PAIRS])
    j = np.array([p[1] for p in surface_measures.COV_PAIRS])
    f = lambda p: p[:, i] ** 2 * p[:, j] ** 2  # noqa: E731
    want = surface_measures.surface_integral(f, tri, areas, order=3) / areas.sum()
    assert np.allclose(surface_measures.fourth_central_moments(tri, areas), want, rtol=1e-13, atol=0)
    assert not np.allclose(surface_measures.surface_integral(f, tri, areas, order=2) / areas.sum(), want, rtol=1e-6, atol=0)


# ---------------------------------------------------------------------------
# one harness

OWN_CHI_SQUARE = re.compile(r"chisquare\(|chi2_contingency|chi2\.sf|chdtrc|gammaincc")


def own_chi_squares(files):
    """The files (name -> text) that compute a chi-square p-value themselves."""
    return sorted(name for name, text in files.items() if OWN_CHI_SQUARE.search(text))


def test_every_chi_square_goes_through_the_one_harness():
    """Tests, benchmarks and the package compute chi-squares with scatter_cli.stats.chisquare
    (this file compares that harness with SciPy's, so it alone may call SciPy's)."""
    root = Path(__file__).resolve().parents[1]
    files = {p.relative_to(root).as_posix(): p.read_text()
             for folder in ("scatter_cli", "tests", "benchmarks") for p in (root / folder).rglob("*.py")}
    assert own_chi_squares(files) == ["scatter_cli/stats/chisquare.py", "tests/test_stats.py"]
    files["tests/test_new.py"] = "assert stats.chisquare(counts).pvalue > ALPHA"  # a test with its own
    assert "tests/test_new.py" in own_chi_squares(files)
