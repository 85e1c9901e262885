"""The square-root warp is uniform on the triangle; the naive warp is not.

Mitsuba-style chi-square test: the triangle is cut into k*k congruent sub-triangles
(bins), the expected count of each bin is N times the integral of the target PDF over
it (a Gauss-Legendre rule through the collapsed square; exact for the constant PDF),
and Pearson's statistic is compared with the chi-square law at level ALPHA.
"""

import numpy as np
import pytest

from scatter_cli.sampling import warps
from scatter_cli.stats.chisquare import chi2_gof

ALPHA = 1e-3
N = 200_000
K = 16  # sub-triangles per side: K*K bins


def bin_index(b, k=K):
    """Sub-triangle of the k*k subdivision holding each point b (n, 2)."""
    x, y = b[:, 0] * k, b[:, 1] * k
    i = np.clip(np.floor(x).astype(int), 0, k - 1)
    j = np.clip(np.floor(y).astype(int), 0, k - 1)
    upper = (x - i) + (y - j) > 1  # the inverted sub-triangle of cell (i, j)
    return (i * k + j) * 2 + upper


def bin_integrals(pdf, k=K, order=8):
    """Integral of pdf over each sub-triangle, (2 k k,) array indexed like bin_index."""
    g, w = np.polynomial.legendre.leggauss(order)
    g, w = (g + 1) / 2, w / 2
    s, t = np.meshgrid(g, g, indexing="ij")
    ws = np.outer(w, w)
    # collapsed square -> reference triangle: (s, t) -> (s, (1 - s) t), Jacobian (1 - s)
    ref = np.stack([s.ravel(), ((1 - s) * t).ravel()], 1)
    wref = (ws * (1 - s)).ravel()
    out = np.zeros(2 * k * k)
    for i in range(k):
        for j in range(k):
            for upper in (0, 1):
                if i + j > k - 1 - upper:
                    continue
                if upper:  # corners (i+1, j+1), (i, j+1), (i+1, j)
                    o = np.array([i + 1, j + 1]); e1 = np.array([-1, 0]); e2 = np.array([0, -1])
                else:
                    o = np.array([i, j]); e1 = np.array([1, 0]); e2 = np.array([0, 1])
                pts = (o + ref[:, :1] * e1 + ref[:, 1:] * e2) / k
                out[(i * k + j) * 2 + upper] = np.sum(wref * pdf(pts)) / k**2
    return out


def warp_pvalue(warp, target_pdf, seed):
    """The pooled chi-square's p-value of N warped points against ``target_pdf`` (bins
    pooled smallest first until each expects 5; the bins outside the triangle left out)."""
    u = np.random.default_rng(seed).random((N, 2))
    observed = np.bincount(bin_index(warp(u)), minlength=2 * K * K)
    expected = bin_integrals(target_pdf)
    keep = expected > 0
    return chi2_gof(observed[keep], expected[keep], smallest_first=True)[2]


def uniform_pdf(b):
    return warps.square_to_triangle_pdf(b)


def test_bin_integrals_sum_to_one():
    assert bin_integrals(uniform_pdf).sum() == pytest.approx(1.0, abs=1e-12)
    nonzero = bin_integrals(uniform_pdf)
    nonzero = nonzero[nonzero > 0]
    assert np.allclose(nonzero, 1 / K**2)


UNIFORM_WARPS = ["sqrt", "fold", "lowdist"]


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("name", UNIFORM_WARPS)
def test_uniform_warps_pass(name, seed):
    warp, pdf, _ = warps.WARPS[name]
    assert warp_pvalue(warp, pdf, seed) > ALPHA
    assert warp_pvalue(warp, uniform_pdf, seed) > ALPHA


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_naive_warp_fails_the_same_test(seed):
    assert warp_pvalue(warps.naive_square_to_triangle, uniform_pdf, seed) < ALPHA


def test_naive_warp_matches_its_own_pdf():
    # The PDF beside the naive warp is right: the warp passes against it (the test is fair).
    assert warp_pvalue(warps.naive_square_to_triangle, warps.naive_square_to_triangle_pdf, 4) > ALPHA


@pytest.mark.parametrize("name", list(warps.WARPS))
def test_pdf_is_inverse_jacobian(name):
    """pdf(W(u)) |det dW/du| = number of preimages (1; 2 for the two-to-one fold):
    the PDF beside each warp is its true density."""
    warp, pdf, _ = warps.WARPS[name]
    u = np.random.default_rng(5).uniform(0.01, 0.99, (1000, 2))
    h = 1e-6
    d1 = (warp(u + [h, 0]) - warp(u - [h, 0])) / (2 * h)
    d2 = (warp(u + [0, h]) - warp(u - [0, h])) / (2 * h)
    det = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    np.testing.assert_allclose(pdf(warp(u)) * det, 2.0 if name == "fold" else 1.0, rtol=1e-5)


@pytest.mark.parametrize("name", ["sqrt", "lowdist", "naive"])
def test_inverse_round_trips(name):
    warp, _, inverse = warps.WARPS[name]
    u = np.random.default_rng(6).random((100_000, 2))
    np.testing.assert_allclose(inverse(warp(u)), u, atol=1e-9)
    b = warp(u)
    np.testing.assert_allclose(warp(inverse(b)), b, atol=1e-12)


def test_fold_inverse_is_a_right_inverse():
    """The fold is two-to-one: inverse(warp(u)) is u or its mirror 1 - u."""
    warp, _, inverse = warps.WARPS["fold"]
    u = np.random.default_rng(7).random((100_000, 2))
    b = warp(u)
    np.testing.assert_allclose(warp(inverse(b)), b, atol=1e-12)
    back = inverse(b)
    mirrored = u.sum(1) > 1
    np.testing.assert_allclose(back[~mirrored], u[~mirrored], atol=1e-12)
    np.testing.assert_allclose(back[mirrored], 1 - u[mirrored], atol=1e-12)


@pytest.mark.parametrize("name", ["sqrt", "fold", "lowdist"])
def test_warp_stays_in_triangle_at_the_ends_of_its_domain(name):
    edge = np.array([0.0, 1e-300, 2.0**-53, 0.5, np.nextafter(1.0, 0), float(np.nextafter(np.float32(1), np.float32(0)))])
    u = np.stack(np.meshgrid(edge, edge), -1).reshape(-1, 2)
    b = warps.WARPS[name][0](u)
    assert np.isfinite(b).all()
    assert (b >= 0).all() and (b.sum(1) <= 1).all()
    b0 = 1 - b.sum(1)
    assert (b0 >= 0).all()
