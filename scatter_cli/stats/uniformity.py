"""Are points uniform on a surface? The summaries ``scatter check`` prints.

Counts in exact equal-area slabs along several directions (chi-square) and the sample
moments against their exact values (z-scores), combined by Bonferroni. The exact
quantities are :mod:`scatter_cli.stats.measures`, the tests :mod:`scatter_cli.stats.chisquare`.
"""

import math

import numpy as np

from . import measures as surface_measures
from .chisquare import chi2_gof, chi2_two_sample


def normal_sf(z):
    """Two-sided p-value P(|Z| >= |z|) of standard-normal z-scores (any shape)."""
    z = np.asarray(z, dtype=float)
    p = np.frompyfunc(lambda v: math.erfc(abs(v) / math.sqrt(2.0)), 1, 1)(z)
    p = np.asarray(p, dtype=float)
    return float(p) if p.ndim == 0 else p


class ExactMoments:
    """The exact moments of a uniform point on the surface ``tri`` (F, 3, 3), ``areas``
    (F,), computed once for every sample tested: ``centre`` (3,) (the exact mean),
    ``cov`` (3, 3), ``fourth`` (6,) (E[x_i^2 x_j^2] about the mean, COV_PAIRS order) and
    ``scale`` (the largest extent, for the floors of the standard errors)."""

    def __init__(self, tri, areas):
        ref, mean, self.cov, tri_k, areas_k = surface_measures.centred_moments(tri, areas)
        self.centre = ref + mean
        lo, hi = surface_measures._box(tri_k)
        self.scale = float((hi - lo).max())
        self.fourth = surface_measures.fourth_central_moments(tri_k - self.centre, areas_k)


def moment_z_scores(points, tri, areas, moments=None):
    """z-scores of a sample's moments against the exact surface values.

    points (n, 3).  Returns ``(z_mean (3,), z_cov (6,))``: the sample mean per
    coordinate, standardised with the exact covariance, and the unbiased
    sample covariance in COV_PAIRS order (xx, yy, zz, xy, xz, yz),
    standardised with the exact fourth central moments (asymptotic variance
    (mu_iijj - sigma_ij^2) / n).  Each is ~N(0, 1) for large n under a
    uniform sampler.  Zero-variance components (e.g. z on a flat mesh) give
    z ~ 0 unless the sample leaves the surface. ``moments``: the surface's
    :class:`ExactMoments`, when already computed.
    """
    m = moments or ExactMoments(tri, areas)
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    n = len(pts)
    if n < 2:
        raise ValueError("moment_z_scores: need at least two points")
    x = pts - m.centre
    xbar = x.mean(axis=0)
    xc = x - xbar
    sample_cov = xc.T @ xc / (n - 1)
    se_mean = np.maximum(np.sqrt(np.diag(m.cov) / n), 1e-12 * m.scale)
    z_mean = xbar / se_mean
    want = np.array([m.cov[i, j] for i, j in surface_measures.COV_PAIRS])
    got = np.array([sample_cov[i, j] for i, j in surface_measures.COV_PAIRS])
    se_cov = np.sqrt(np.maximum(m.fourth - want**2, 0.0) / n)
    se_cov = np.maximum(se_cov, 1e-12 * m.scale**2)
    return z_mean, (got - want) / se_cov


def default_directions():
    """The three axes and the four body diagonals, as unit rows (7, 3)."""
    axes = np.eye(3)
    diag = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1]], dtype=float) / math.sqrt(3.0)
    return np.vstack((axes, diag))


def _bonferroni(pvalues):
    p = [x for x in pvalues if x is not None]
    return min(1.0, len(p) * min(p)) if p else 1.0


class Regions:
    """The regions points are counted in: about k exact equal-area slabs along each
    direction (default: 3 axes + 4 diagonals; see :func:`surface_measures.slabs`), with their exact
    probabilities, computed once for every sample tested.

    Rounding: a point within :func:`surface_measures.rounding` of a slab's edge counts in the slab
    it is on (no edge lies within rounding of a flat face or of the surface's ends), and
    a point further than that beyond the surface's lowest or highest height along a
    direction is off the surface.
    """

    def __init__(self, tri, areas, k=32, directions=None, progress=None):
        dirs = default_directions() if directions is None else np.asarray(directions, dtype=float).reshape(-1, 3)
        self.k = int(k)
        self.tol = surface_measures.rounding(np.asarray(tri, dtype=float))
        tell = progress and (lambda i, m: progress(f"exact regions, direction {i + 1}/{m}"))
        self.slabs = surface_measures.slabs(tri, areas, dirs, self.k, progress=tell)

    def counts(self, points):
        """([(j,) int64 counts per slab, one array per direction], points off the surface)
        of points (n, 3)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        out, off = [], np.zeros(len(pts), dtype=bool)
        for d, edges, _ in self.slabs:
            h = pts @ d
            off |= (h < edges[0] - self.tol) | (h > edges[-1] + self.tol)
            out.append(surface_measures.slab_counts(pts, d, edges))
        return out, int(np.count_nonzero(off))


def _per_slab_direction(regions, test):
    """The report fields k, directions, slab_statistic, slab_dof, slab_p and p_slabs of
    ``test(j, prob) -> (stat, dof, p)`` over the slabs of each direction of ``regions``
    (j: the direction's index); p is None where pooling left one bin."""
    dirs, stats, dofs, ps = [], [], [], []
    for j, (d, _, prob) in enumerate(regions.slabs):
        stat, dof, p = test(j, prob)
        dirs.append(d.tolist())
        stats.append(stat)
        dofs.append(dof)
        ps.append(p if dof > 0 else None)
    return {"k": regions.k, "directions": dirs, "slab_statistic": stats, "slab_dof": dofs, "slab_p": ps,
            "p_slabs": _bonferroni(ps)}


def region_test(points, tri, areas, k=32, directions=None, min_expected=5.0, regions=None, moments=None):
    """Test that points (n, 3) are uniform on the surface.

    For each direction (default: 3 axes + 4 diagonals) the points are counted
    in about k equal-area slabs (:class:`Regions`) and compared with the exact
    slab areas by ``chi2_gof``; moments are compared by ``moment_z_scores``.
    ``regions`` and ``moments`` (:class:`ExactMoments`): the surface's, when
    already computed. Returns a dict of plain Python values:
    n, k, directions (list of 3-lists), slab_statistic, slab_dof, slab_p
    (one per direction; p is None where pooling left one bin), p_slabs
    (Bonferroni minimum over directions), off_surface (points beyond the
    surface's extent by more than rounding) and p_off (0 when there are any,
    else None), z_mean (3), z_cov (6, COV_PAIRS order), p_moments (Bonferroni
    over the 9 z-scores) and p (Bonferroni over every test above).  Reject
    uniformity at level alpha when p < alpha.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    n = len(pts)
    regions = regions or Regions(tri, areas, k, directions)
    counts, off = regions.counts(pts)
    slabs = _per_slab_direction(regions, lambda j, prob: chi2_gof(counts[j], prob * n, min_expected))
    z_mean, z_cov = moment_z_scores(pts, tri, areas, moments)
    p_z = normal_sf(np.concatenate((z_mean, z_cov))).tolist()
    p_off = 0.0 if off else None
    return {
        "n": n,
        **slabs,
        "off_surface": off,
        "p_off": p_off,
        "z_mean": z_mean.tolist(),
        "z_cov": z_cov.tolist(),
        "p_moments": _bonferroni(p_z),
        "p": _bonferroni(slabs["slab_p"] + p_z + [p_off]),
    }


def two_sample_test(points_a, points_b, tri, areas, k=32, directions=None, min_expected=5.0, regions=None,
                    moments=None):
    """Test that two samples (na, 3), (nb, 3) on the same surface share a distribution.

    Uses the regions of ``region_test`` with ``chi2_two_sample`` per direction,
    and z-scores of the difference of the sample means using the exact
    covariance.  Returns a dict: na, nb, k, directions, slab_statistic,
    slab_dof, slab_p, p_slabs, z_mean_diff (3), p_means (Bonferroni over the
    3), p (Bonferroni over all tests) and, when p < 0.05, ``worst``: the slab
    where the samples differ most (:func:`worst_slab`).
    """
    a = np.asarray(points_a, dtype=float).reshape(-1, 3)
    b = np.asarray(points_b, dtype=float).reshape(-1, 3)
    regions = regions or Regions(tri, areas, k, directions)
    m = moments or ExactMoments(tri, areas)
    ca, _ = regions.counts(a)
    cb, _ = regions.counts(b)
    slabs = _per_slab_direction(regions, lambda j, _: chi2_two_sample(ca[j], cb[j], min_expected))
    se = np.maximum(np.sqrt(np.diag(m.cov) * (1.0 / len(a) + 1.0 / len(b))), 1e-12 * m.scale)
    z = ((a - m.centre).mean(axis=0) - (b - m.centre).mean(axis=0)) / se
    p_z = normal_sf(z).tolist()
    out = {
        "na": len(a),
        "nb": len(b),
        **slabs,
        "z_mean_diff": z.tolist(),
        "p_means": _bonferroni(p_z),
        "p": _bonferroni(slabs["slab_p"] + p_z),
    }
    if out["p"] < 0.05:
        out["worst"] = worst_slab(regions, ca, cb)
    return out


def worst_slab(regions, counts_a, counts_b):
    """Where two samples' slab counts (per direction, as :meth:`Regions.counts` gives
    them) differ most, and which sample fits the exact areas there: a dict with
    direction (3-list), low and high (the slab's heights), share (its exact
    probability), count_a, count_b, expected_a, expected_b, z_a and z_b (each count's
    z-score against its exact expectation, inf where a slab of no area holds points)."""
    best = None
    for (d, edges, prob), a, b in zip(regions.slabs, counts_a, counts_b):
        a, b = a.astype(float), b.astype(float)
        na, nb = a.sum(), b.sum()
        col = a + b
        ea, eb = col * (na / (na + nb)), col * (nb / (na + nb))
        with np.errstate(divide="ignore", invalid="ignore"):
            term = np.where(col > 0, (a - ea) ** 2 / np.where(ea > 0, ea, 1) + (b - eb) ** 2 / np.where(eb > 0, eb, 1), 0)
        s = int(np.argmax(term))
        if best is None or term[s] > best[0]:
            best = (float(term[s]), d, edges, prob, s, a[s], b[s], na, nb)
    _, d, edges, prob, s, a, b, na, nb = best
    p = float(prob[s])
    return {"direction": d.tolist(), "low": float(edges[s]), "high": float(edges[s + 1]), "share": p,
            "count_a": int(a), "count_b": int(b), "expected_a": na * p, "expected_b": nb * p,
            "z_a": _z(a, na, p), "z_b": _z(b, nb, p)}


def _z(count, n, p):
    """z-score of a binomial count against n trials of probability p."""
    sd = math.sqrt(n * p * (1.0 - p))
    if sd > 0:
        return (count - n * p) / sd
    return 0.0 if count == n * p else math.inf
