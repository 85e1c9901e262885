"""The stratified and Sobol methods: correct sequences, unbiased, and more accurate than random.

Statistical tests use fixed seeds and level ALPHA; each is paired with a case that
must fail it (the naive warp, or two equally good samplers).
"""

import numpy as np
import pytest
from scipy import stats as sps
from scipy.stats import qmc

import scatter_cli
from scatter_cli.commands import bench
from scatter_cli.sampling import methods, warps
from scatter_cli.api import prepare
from scatter_cli.errors import ScatterUsageError
from scatter_cli.sampling.plan import SamplePlan
from scatter_cli.loading.load import load_surface
from scatter_cli.stats.chisquare import chi2_gof

from .conftest import spread_triangles, triangles_mesh
from .test_warps import bin_index

ALPHA = 1e-3


def test_unscrambled_sobol_matches_the_reference_sequence():
    """Joe & Kuo's first three dimensions, in Gray-code order, as scipy generates them."""
    ours = methods.sobol_integers(0, 4096) / 2.0**32
    ref = qmc.Sobol(3, scramble=False).random(4096)
    np.testing.assert_array_equal(ours, ref)


def test_sobol_chunks_join_into_the_whole_sequence():
    whole = methods.sobol_uniforms(0, 10_000, 4)
    parts = np.concatenate([methods.sobol_uniforms(a, min(a + 777, 10_000), 4) for a in range(0, 10_000, 777)])
    np.testing.assert_array_equal(whole, parts)


def _cells(u, k):
    """Counts (k*k,) of the points u (n, 2) in the k x k grid of the unit square."""
    return np.bincount((np.floor(u[:, 0] * k) * k + np.floor(u[:, 1] * k)).astype(int), minlength=k * k)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_scrambled_sobol_keeps_the_net_property(seed):
    """Owen scrambling keeps (0, m, 2)-nets: 2^12 points, one in each of the 64 x 64 cells
    of dimensions 0 and 1, and in each 2^-a x 2^-(12-a) box."""
    u = methods.sobol_uniforms(0, 1 << 12, seed)
    for a in range(13):
        i = np.floor(u[:, 0] * 2**a).astype(int) * 2 ** (12 - a) + np.floor(u[:, 1] * 2 ** (12 - a)).astype(int)
        assert (np.bincount(i, minlength=1 << 12) == 1).all()
    # must fail: i.i.d. points are no net
    assert not (_cells(np.random.default_rng(seed).random((1 << 12, 2)), 64) == 1).all()


@pytest.mark.slow
def test_scrambling_depends_on_the_seed_and_each_point_is_uniform():
    """The first point of each seed's sequence is uniform over seeds (chi-square, 16 x 16 cells)."""
    first = np.array([methods.sobol_uniforms(0, 1, s)[0] for s in range(4000)])
    for d in [(0, 1), (1, 2)]:
        counts = _cells(first[:, d], 16)
        assert chi2_gof(counts, np.ones(len(counts)))[2] > ALPHA
    # must fail: the unscrambled first point is always 0
    assert chi2_gof(_cells(np.zeros((4000, 2)), 16), np.ones(256))[2] < ALPHA


def test_sobol_count_limit():
    mesh = triangles_mesh(spread_triangles([0.0])[0])
    with pytest.raises(ScatterUsageError, match="2\\^32"):
        prepare(mesh, 2**32 + 1, method="sobol")
    prepare(mesh, 2**32, method="sobol")  # the limit itself is fine


def _plan(exponents=(0.0, -0.4, 0.3, -1.0, 0.6)):
    tri, areas = spread_triangles(exponents)
    return SamplePlan(load_surface(triangles_mesh(tri))), areas


@pytest.mark.parametrize("count", [1, 7, 100, 12345])
def test_stratified_face_counts_are_floor_or_ceil_of_expected(count):
    plan, areas = _plan()
    for seed in range(5):
        used, b = methods.stratified_draws(plan, count, 0, count, seed)
        got = np.bincount(used, minlength=len(areas))
        expected = count * areas / areas.sum()
        assert ((got == np.floor(expected)) | (got == np.ceil(expected))).all()
        assert got.sum() == count
        assert (np.diff(used) >= 0).all()


K = 4  # sub-triangles per side inside each face


def region_pvalue(draws, warp, n=600, runs=300):
    """Bonferroni p-value that each (face, sub-triangle) region's mean count over
    ``runs`` seeds equals its exact expectation (t-tests with the empirical variance:
    stratified counts are not multinomial, so Pearson's variance would not apply)."""
    plan, areas = _plan()
    regions = len(areas) * 2 * K * K
    counts = np.empty((runs, regions))
    for seed in range(runs):
        used, b = draws(plan, n, 0, n, seed, warp)
        counts[seed] = np.bincount(used * 2 * K * K + bin_index(b, K), minlength=regions)
    inside = np.zeros(2 * K * K, dtype=bool)
    i, j = np.meshgrid(np.arange(K), np.arange(K), indexing="ij")
    inside[((i * K + j) * 2)[i + j <= K - 1]] = True
    inside[((i * K + j) * 2 + 1)[i + j <= K - 2]] = True
    expected = (n * areas / areas.sum())[:, None] * inside[None, :] / K**2
    expected = expected.ravel()
    mean, sd = counts.mean(0), counts.std(0, ddof=1)
    fixed = sd == 0
    if np.any(np.abs(mean[fixed] - expected[fixed]) > 1e-9):
        return 0.0
    t = (mean[~fixed] - expected[~fixed]) / (sd[~fixed] / np.sqrt(runs))
    p = 2 * sps.t.sf(np.abs(t), runs - 1)
    return min(1.0, p.min() * len(p))


@pytest.mark.slow
@pytest.mark.parametrize("method", ["random", "stratified", "sobol"])
def test_methods_are_unbiased_per_region(method):
    assert region_pvalue(methods.DRAWS[method], warps.square_to_triangle) > ALPHA


@pytest.mark.slow
@pytest.mark.parametrize("method", ["stratified", "sobol"])
def test_naive_warp_fails_the_region_test(method):
    assert region_pvalue(methods.DRAWS[method], warps.naive_square_to_triangle) < ALPHA


@pytest.fixture(scope="module")
def sphere():
    mesh = bench.icosphere(3)
    surface = load_surface(mesh)
    tri = mesh.triangles
    return surface, bench.exact_values(tri, mesh.area_faces)


def _errors(surface, exact, method, seeds, n=100_000):
    run = bench.our_sampler(surface, method)
    return np.array([bench.errors(run(n, s), exact)["error"] for s in seeds])


@pytest.mark.slow
@pytest.mark.parametrize("method", ["stratified", "sobol"])
def test_stratified_and_sobol_beat_random_at_1e5_on_the_sphere(sphere, method):
    """One-sided Mann-Whitney test over 12 seeds each: the method's errors are smaller
    than random's at level ALPHA."""
    surface, exact = sphere
    ours = _errors(surface, exact, method, range(12))
    rand = _errors(surface, exact, "random", range(12))
    assert sps.mannwhitneyu(ours, rand, alternative="less").pvalue < ALPHA


@pytest.mark.slow
def test_the_error_comparison_does_not_reject_for_equal_samplers(sphere):
    """must fail: random against random (other seeds) is not found better."""
    surface, exact = sphere
    a = _errors(surface, exact, "random", range(12))
    b = _errors(surface, exact, "random", range(100, 112))
    assert sps.mannwhitneyu(a, b, alternative="less").pvalue > ALPHA


@pytest.mark.slow
def test_api_methods_sample_the_surface(sample_mesh):
    from scatter_cli.stats import uniformity
    from scatter_cli.commands.check import world_triangles

    surface = load_surface(sample_mesh("spot_triangulated.obj"))
    tri, areas = world_triangles(surface)
    for method in ("stratified", "sobol"):
        pts = scatter_cli.sample(surface, 50_000, method=method, precision="float64", seed=1).points
        assert uniformity.region_test(pts, tri, areas)["p_slabs"] > ALPHA
