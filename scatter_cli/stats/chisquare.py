"""Pearson chi-square tests of counts in bins, pooled: goodness of fit and two samples.

The one pooled chi-square of the project: ``scatter check``, the benchmarks and the
tests call these. P-values come from SciPy (``pip install scipy``),
imported when a test runs.
"""

import numpy as np


def chi2_sf(x, dof):
    """P(X > x) for X chi-square with ``dof`` degrees of freedom (SciPy's)."""
    from scipy.special import chdtrc

    return float(chdtrc(dof, x))


def _pool_groups(weight, min_weight):
    """Group labels (len(weight),) merging consecutive bins until each group's
    ``weight`` reaches ``min_weight``; a short tail joins the last full group."""
    labels = np.empty(len(weight), dtype=np.intp)
    group, acc, last_closed = 0, 0.0, -1
    for i, w in enumerate(weight.tolist()):  # loop over bins (few), not points
        labels[i] = group
        acc += w
        if acc >= min_weight:
            last_closed = group
            group += 1
            acc = 0.0
    if last_closed >= 0:
        labels[labels > last_closed] = last_closed
    else:
        labels[:] = 0
    return labels


def chi2_gof(observed, expected, min_expected=5.0, smallest_first=False):
    """Pearson goodness of fit of counts ``observed`` (k,) to ``expected`` (k,).

    ``expected`` is rescaled to sum to ``observed.sum()`` (so probabilities
    may be passed).  Consecutive bins are pooled in order (``smallest_first``:
    in order of increasing expectation, for bins with no order of their own
    such as faces) until each pooled bin expects at least ``min_expected``; a
    short tail joins the last pooled bin.  Returns ``(statistic, dof, p)`` with
    ``dof = pooled bins - 1``; with fewer than two pooled bins the result is
    ``(0.0, 0, 1.0)``.
    """
    obs = np.asarray(observed, dtype=float).ravel()
    exp = np.asarray(expected, dtype=float).ravel()
    if obs.shape != exp.shape:
        raise ValueError("chi2_gof: observed and expected differ in length")
    if smallest_first:
        order = np.argsort(exp, kind="stable")
        obs, exp = obs[order], exp[order]
    if np.any(exp < 0) or exp.sum() <= 0:
        raise ValueError("chi2_gof: expected must be non-negative with positive sum")
    exp = exp * (obs.sum() / exp.sum())
    labels = _pool_groups(exp, min_expected)
    groups = labels.max() + 1 if labels.size else 0
    o = np.bincount(labels, obs, minlength=groups)
    e = np.bincount(labels, exp, minlength=groups)
    if groups < 2:
        return 0.0, 0, 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.where(e > 0, (o - e) ** 2 / np.where(e > 0, e, 1.0), np.where(o > 0, np.inf, 0.0))
    stat = float(terms.sum())
    dof = int(groups - 1)
    return stat, dof, chi2_sf(stat, dof)


def chi2_two_sample(counts_a, counts_b, min_expected=5.0):
    """Chi-square homogeneity test of two count vectors (k,) over the same bins.

    The samples may have different sizes.  Bins are pooled in order (as in
    ``chi2_gof``) until the smaller sample expects at least ``min_expected``
    in each.  Returns ``(statistic, dof, p)``, ``dof = pooled bins - 1``.
    """
    a = np.asarray(counts_a, dtype=float).ravel()
    b = np.asarray(counts_b, dtype=float).ravel()
    if a.shape != b.shape:
        raise ValueError("chi2_two_sample: count vectors differ in length")
    na, nb = a.sum(), b.sum()
    if na <= 0 or nb <= 0:
        raise ValueError("chi2_two_sample: both samples must be non-empty")
    n = na + nb
    labels = _pool_groups((a + b) * (min(na, nb) / n), min_expected)
    groups = labels.max() + 1
    if groups < 2:
        return 0.0, 0, 1.0
    ga = np.bincount(labels, a, minlength=groups)
    gb = np.bincount(labels, b, minlength=groups)
    col = ga + gb
    ea, eb = col * (na / n), col * (nb / n)
    stat = float((((ga - ea) ** 2) / ea).sum() + (((gb - eb) ** 2) / eb).sum())
    dof = int(groups - 1)
    return stat, dof, chi2_sf(stat, dof)
