"""Are points uniform on a surface? The summaries ``scatter check`` prints.

Counts in exact equal-area slabs along several directions (chi-square) and the sample
moments against their exact values (z-scores), combined by Bonferroni. The exact
quantities are :mod:`scatter_cli.exact`, the tests :mod:`scatter_cli.chisquare`.
"""

import math

import numpy as np

from . import exact
from .chisquare import chi2_gof, chi2_two_sample


def normal_sf(z):
    """Two-sided p-value P(|Z| >= |z|) of standard-normal z-scores (any shape)."""
    z = np.asarray(z, dtype=float)
    p = np.frompyfunc(lambda v: math.erfc(abs(v) / math.sqrt(2.0)), 1, 1)(z)
    p = np.asarray(p, dtype=float)
    return float(p) if p.ndim == 0 else p


def moment_z_scores(points, tri, areas):
    """z-scores of a sample's moments against the exact surface values.

    points (n, 3).  Returns ``(z_mean (3,), z_cov (6,))``: the sample mean per
    coordinate, standardised with the exact covariance, and the unbiased
    sample covariance in COV_PAIRS order (xx, yy, zz, xy, xz, yz),
    standardised with the exact fourth central moments (asymptotic variance
    (mu_iijj - sigma_ij^2) / n).  Each is ~N(0, 1) for large n under a
    uniform sampler.  Zero-variance components (e.g. z on a flat mesh) give
    z ~ 0 unless the sample leaves the surface.
    """
    ref, mean, cov, tri_k, areas_k = exact.centred_moments(tri, areas)
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    n = len(pts)
    if n < 2:
        raise ValueError("moment_z_scores: need at least two points")
    x = pts - (ref + mean)
    xbar = x.mean(axis=0)
    xc = x - xbar
    sample_cov = xc.T @ xc / (n - 1)
    scale = float(np.ptp(tri_k.reshape(-1, 3), axis=0).max())
    se_mean = np.maximum(np.sqrt(np.diag(cov) / n), 1e-12 * scale)
    z_mean = xbar / se_mean
    fourth = exact.fourth_central_moments(tri_k - (ref + mean), areas_k)
    want = np.array([cov[i, j] for i, j in exact.COV_PAIRS])
    got = np.array([sample_cov[i, j] for i, j in exact.COV_PAIRS])
    se_cov = np.sqrt(np.maximum(fourth - want**2, 0.0) / n)
    se_cov = np.maximum(se_cov, 1e-12 * scale**2)
    return z_mean, (got - want) / se_cov


def default_directions():
    """The three axes and the four body diagonals, as unit rows (7, 3)."""
    axes = np.eye(3)
    diag = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1]], dtype=float) / math.sqrt(3.0)
    return np.vstack((axes, diag))


def _bonferroni(pvalues):
    p = [x for x in pvalues if x is not None]
    return min(1.0, len(p) * min(p)) if p else 1.0


def _per_slab_direction(tri, areas, directions, k, test):
    """The report fields k, directions, slab_statistic, slab_dof, slab_p and p_slabs of
    ``test(d, edges, prob) -> (stat, dof, p)`` over the k equal-area slabs along each
    direction (default: 3 axes + 4 diagonals); p is None where pooling left one bin."""
    dirs, stats, dofs, ps = [], [], [], []
    for d, edges, prob in exact.slabs(tri, areas, default_directions() if directions is None else directions, k):
        stat, dof, p = test(d, edges, prob)
        dirs.append(d.tolist())
        stats.append(stat)
        dofs.append(dof)
        ps.append(p if dof > 0 else None)
    return {"k": int(k), "directions": dirs, "slab_statistic": stats, "slab_dof": dofs, "slab_p": ps,
            "p_slabs": _bonferroni(ps)}


def region_test(points, tri, areas, k=32, directions=None, min_expected=5.0):
    """Test that points (n, 3) are uniform on the surface.

    For each direction (default: 3 axes + 4 diagonals) the points are counted
    in k equal-area slabs and compared with the exact slab areas by
    ``chi2_gof``; moments are compared by ``moment_z_scores``.  Returns a dict
    of plain Python values:
    n, k, directions (list of 3-lists), slab_statistic, slab_dof, slab_p
    (one per direction; p is None where pooling left one bin), p_slabs
    (Bonferroni minimum over directions), z_mean (3), z_cov (6, COV_PAIRS
    order), p_moments (Bonferroni over the 9 z-scores) and p (Bonferroni over
    every test above).  Reject uniformity at level alpha when p < alpha.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    n = len(pts)
    slabs = _per_slab_direction(
        tri, areas, directions, k, lambda d, edges, prob: chi2_gof(exact.slab_counts(pts, d, edges), prob * n, min_expected))
    z_mean, z_cov = moment_z_scores(pts, tri, areas)
    p_z = normal_sf(np.concatenate((z_mean, z_cov))).tolist()
    return {
        "n": n,
        **slabs,
        "z_mean": z_mean.tolist(),
        "z_cov": z_cov.tolist(),
        "p_moments": _bonferroni(p_z),
        "p": _bonferroni(slabs["slab_p"] + p_z),
    }


def two_sample_test(points_a, points_b, tri, areas, k=32, directions=None, min_expected=5.0):
    """Test that two samples (na, 3), (nb, 3) on the same surface share a distribution.

    Uses the exact equal-area slabs of ``region_test`` with
    ``chi2_two_sample`` per direction, and z-scores of the difference of the
    sample means using the exact covariance.  Returns a dict: na, nb, k,
    directions, slab_statistic, slab_dof, slab_p, p_slabs, z_mean_diff (3),
    p_means (Bonferroni over the 3) and p (Bonferroni over all tests).
    """
    a = np.asarray(points_a, dtype=float).reshape(-1, 3)
    b = np.asarray(points_b, dtype=float).reshape(-1, 3)
    slabs = _per_slab_direction(
        tri, areas, directions, k,
        lambda d, edges, _: chi2_two_sample(exact.slab_counts(a, d, edges), exact.slab_counts(b, d, edges), min_expected))
    ref, _, cov, tri_k, _ = exact.centred_moments(tri, areas)
    scale = float(np.ptp(tri_k.reshape(-1, 3), axis=0).max())
    se = np.maximum(np.sqrt(np.diag(cov) * (1.0 / len(a) + 1.0 / len(b))), 1e-12 * scale)
    z = ((a - ref).mean(axis=0) - (b - ref).mean(axis=0)) / se
    p_z = normal_sf(z).tolist()
    return {
        "na": len(a),
        "nb": len(b),
        **slabs,
        "z_mean_diff": z.tolist(),
        "p_means": _bonferroni(p_z),
        "p": _bonferroni(slabs["slab_p"] + p_z),
    }
