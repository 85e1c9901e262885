"""`scatter bench`: exact integrals, bias detection, repeatability and the command."""

import json

import numpy as np
import pytest
from scipy import stats as sps

from scatter_cli.commands import bench
from scatter_cli.stats.measures import smooth_test_function
from scatter_cli.loading.load import load_surface

from .conftest import run_scatter, run_user

ALPHA = 1e-3


def brute_force(tri, f, k=24):
    """Integral of f over triangles (F, 3, 3): the edge-midpoint rule (exact to degree 2)
    on each of k*k congruent sub-triangles."""
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    lo = (i + j <= k - 1).ravel()
    hi = (i + j <= k - 2).ravel()
    i, j = i.ravel(), j.ravel()
    corners = np.concatenate([
        np.stack([np.c_[i, j], np.c_[i + 1, j], np.c_[i, j + 1]], 1)[lo],
        np.stack([np.c_[i + 1, j + 1], np.c_[i, j + 1], np.c_[i + 1, j]], 1)[hi],
    ]) / k  # (k*k, 3, 2) sub-triangle corners in (b1, b2)
    b = (0.5 * (corners + np.roll(corners, 1, axis=1))).reshape(-1, 2)  # edge midpoints
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    pts = tri[:, None, 0] + b[None, :, :1] * e1[:, None] + b[None, :, 1:] * e2[:, None]
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    vals = f(pts.reshape(-1, 3)).reshape(len(tri), len(b), -1)
    return np.einsum("f,fqc->c", area, vals) / len(b)


@pytest.fixture(scope="module", params=["sphere", "far", "random"])
def case(request):
    if request.param == "random":
        rng = np.random.default_rng(3)
        tri = rng.normal(size=(40, 3, 3)) * [3.0, 1.0, 0.5] + [2.0, -1.0, 0.5]
    else:
        mesh = bench.icosphere(2, bench.FAR_OFFSET if request.param == "far" else 0.0)
        tri = mesh.triangles
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return tri, areas, bench.exact_values(tri, areas)


@pytest.mark.slow
def test_exact_values_match_brute_force_quadrature(case):
    tri, areas, exact = case
    area = areas.sum()
    c = exact.centroid

    def integrand(p):
        d = p - c
        f = smooth_test_function(p, exact.bounds)
        return np.column_stack([d, (d[:, :, None] * d[:, None, :]).reshape(-1, 9), f])

    got = brute_force(tri, integrand) / area
    scale = exact.diagonal
    np.testing.assert_allclose(got[:3], 0.0, atol=1e-9 * scale)  # c is the centroid
    np.testing.assert_allclose(got[3:12].reshape(3, 3), exact.second, rtol=1e-9, atol=1e-9 * np.abs(exact.second).max())
    # The midpoint rule's error on the smooth function falls as 1/k^2.
    assert abs(got[12] - exact.smooth) < 1e-4 * exact.smooth_rms


@pytest.mark.slow
def test_exact_values_match_a_high_count_estimate(case):
    """Five standard errors, from the sample itself, on every estimated integral."""
    tri, areas, exact = case
    from scatter_cli.api import sample
    from .conftest import triangles_mesh

    n = 1_000_000
    x = sample(triangles_mesh(tri), n, seed=2, precision="float64").points
    d = x - exact.centroid
    values = np.column_stack([d, (d[:, :, None] * d[:, None, :]).reshape(-1, 9),
                              smooth_test_function(x, exact.bounds)])
    truth = np.concatenate([np.zeros(3), exact.second.ravel(), [exact.smooth]])
    se = values.std(axis=0) / np.sqrt(n)
    assert (np.abs(values.mean(axis=0) - truth) < 5 * se + 1e-12 * exact.diagonal**2).all()


def _signed(surface, exact, method, warp, seeds, n=200_000):
    """Per seed, the signed errors of the smooth mean and of the trace of the second moments."""
    run = bench.our_sampler(surface, method, warp)
    out = []
    for s in seeds:
        x = run(n, s)
        d = x - exact.centroid
        out.append([smooth_test_function(x, exact.bounds).mean() - exact.smooth,
                    np.einsum("ij,ij->", d, d) / n - np.trace(exact.second)])
    return np.array(out)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["random", "sobol"])
def test_bench_integrals_detect_the_naive_warps_bias(method):
    """t-test over 8 seeds that the estimates' mean error is zero (Bonferroni over the
    two integrals): rejected for the naive warp, not for the square-root warp."""
    mesh = bench.icosphere(3)
    surface = load_surface(mesh)
    exact = bench.exact_values(mesh.triangles, mesh.area_faces)

    def pvalue(warp):
        e = _signed(surface, exact, method, warp, range(8))
        p = sps.ttest_1samp(e, 0.0, axis=0).pvalue
        return min(1.0, 2 * p.min())

    assert pvalue("naive") < ALPHA
    assert pvalue("sqrt") > ALPHA  # must-fail pair: the uniform warp is not flagged


def test_slope_fit():
    rows = [{"n": n, "error": 3.0 * n**-0.5} for n in (100, 1000, 10000)]
    assert bench.fit_slope(rows) == pytest.approx(-0.5)


@pytest.mark.slow
def test_same_seed_same_errors(tmp_path):
    mesh = tmp_path / "sphere.ply"
    bench.icosphere(2).export(mesh)
    kw = dict(meshes=[str(mesh)], counts=[100, 1000], repeats=2, seed=7, want_plot=False, log=lambda m: None,
              quick=True)  # (the quick Poisson rows: 10^3 points, not 10^4 and 10^5)
    a = bench.run_bench(out=tmp_path / "a", **kw)
    b = bench.run_bench(out=tmp_path / "b", **kw)
    rows = lambda rep: {r["variant"]: [row["error"] for row in r["rows"]] for r in rep["results"]
                        if not r["variant"].startswith("pymeshlab")}
    assert rows(a) == rows(b)
    assert {"random/sqrt/64", "stratified/sqrt/64", "sobol/sqrt/64", "sobol/naive/64"} <= set(rows(a))


@pytest.mark.slow
def test_quick_bench_command_writes_all_three_outputs(tmp_path):
    out = tmp_path / "bench"
    proc = run_scatter("bench", "--quick", "--out", out, timeout=900)
    assert proc.returncode == 0, proc.stderr.decode()
    assert (out / "bench.png").stat().st_size > 10_000
    report = json.loads((out / "bench.json").read_text())
    variants = {r["variant"] for r in report["results"]}
    assert {"random/sqrt/64", "stratified/sqrt/64", "sobol/sqrt/64", "sobol/fold/64", "sobol/lowdist/64",
            "sobol/naive/64", "random/sqrt/32"} <= variants
    assert len({r["mesh"] for r in report["results"]}) == 3
    text = (out / "bench.md").read_text()
    assert "| variant | slope |" in text
    assert "poisson" in text.lower()
    for mesh in {p["mesh"] for p in report["poisson"]}:
        rho = {p["oversampling"]: p["rho"] for p in report["poisson"] if p["mesh"] == mesh}
        assert rho[15] > rho[3]  # more candidates buy a larger spacing
    assert "stratified/sqrt/64" in proc.stdout.decode()


@pytest.mark.slow
def test_bench_without_matplotlib_says_how_to_install(tmp_path):
    import sys

    code = ("import sys; sys.modules['matplotlib'] = None; from scatter_cli.cli import main; "
            f"sys.exit(main(['bench', '--quick', '--out', {str(tmp_path)!r}]))")
    proc = run_user([sys.executable, "-c", code])
    assert proc.returncode == 1
    assert "pip install" in proc.stderr.decode() and "matplotlib" in proc.stderr.decode()


@pytest.mark.slow
def test_bench_rejects_bad_counts(tmp_path):
    proc = run_scatter("bench", "--counts", "10,abc", "--out", tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.decode().startswith("error:")
