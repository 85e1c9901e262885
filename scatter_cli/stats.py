"""Exact surface quantities and goodness-of-fit tests for surface samplers.

A "surface" is given as ``tri`` ``(F, 3, 3) float64`` (vertex ``k`` of face
``f`` is ``tri[f, k]``) and ``areas`` ``(F,) float64``; faces of zero area
contribute nothing.  Everything here is exact for the piecewise-flat surface
(closed forms per triangle) and is vectorised over faces and points; only
numpy and the standard library are imported because every CLI call pays for
imports.

Used by ``scatter check`` (``region_test``, ``two_sample_test``), by
``scatter bench`` (``surface_integral``, ``smooth_test_function``) and by the
tests.
"""

import math

import numpy as np

# Upper bound on the entries of one (faces x values) work matrix; each chunk
# holds a handful of such temporaries, so this keeps them to tens of MB.
CHUNK_ENTRIES = 1 << 21

# Unordered coordinate pairs for second central moments: xx, yy, zz, xy, xz, yz.
COV_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))

_EPS = np.finfo(float).eps
_TINY = 1e-300


# ---------------------------------------------------------------------------
# Distribution functions


def _stirling_correction(a):
    """lgamma(a) - ((a - 1/2) log a - a + log(2 pi)/2) for an array ``a > 0``."""
    a = np.asarray(a, dtype=float)
    out = np.empty_like(a)
    big = a >= 10.0
    ab = a[big]
    r = 1.0 / (ab * ab)
    # Stirling series B_2n / (2n (2n-1) a^(2n-1)); truncation < 1e-15 for a >= 10.
    out[big] = (1.0 / ab) * (
        1.0 / 12
        - r * (1.0 / 360 - r * (1.0 / 1260 - r * (1.0 / 1680 - r * (1.0 / 1188 - r * 691.0 / 360360))))
    )
    small = a[~big]
    lg = np.array([math.lgamma(v) for v in small.tolist()], dtype=float)  # loop over dof values only
    out[~big] = lg - ((small - 0.5) * np.log(small) - small + 0.5 * math.log(2 * math.pi))
    return out


def _log_gamma_prefactor(a, x):
    """log(x^a e^-x / Gamma(a)), written so that large ``a`` does not cancel."""
    with np.errstate(divide="ignore"):
        t = (x - a) / a
        # a log(x/a) + a - x == a (log1p(t) - t); the rest is Stirling's formula.
        return a * (np.log1p(t) - t) + 0.5 * np.log(a) - 0.5 * math.log(2 * math.pi) - _stirling_correction(a)


def _lower_series(a, x, log_d):
    """P(a, x) by the power series; meant for x < a + 1."""
    term = 1.0 / a
    total = term.copy()
    active = np.arange(a.size)
    n = 0
    limit = 1000 + int(30 * math.sqrt(float(a.max(initial=1.0))))
    while active.size:
        n += 1
        if n > limit:
            raise RuntimeError("chi2_sf: series did not converge")
        term[active] *= x[active] / (a[active] + n)
        total[active] += term[active]
        active = active[term[active] > total[active] * _EPS * 0.5]
    return np.exp(log_d) * total


def _upper_fraction(a, x, log_d):
    """Q(a, x) by its continued fraction (modified Lentz); meant for x >= a + 1.

    Q = D / (b1 + c2/(b2 + c3/(b3 + ...))) with b_n = x + 2n - 1 - a,
    c_n = -(n - 1)(n - 1 - a) and D = x^a e^-x / Gamma(a).
    """
    f = x + 1.0 - a
    f = np.where(np.abs(f) < _TINY, _TINY, f)
    c = f.copy()
    d = np.zeros_like(f)
    active = np.arange(a.size)
    n = 1
    limit = 1000 + int(30 * math.sqrt(float(a.max(initial=1.0))))
    while active.size:
        n += 1
        if n > limit:
            raise RuntimeError("chi2_sf: continued fraction did not converge")
        aa, xx = a[active], x[active]
        b = xx + 2 * n - 1 - aa
        cn = -(n - 1) * (n - 1 - aa)
        dd = b + cn * d[active]
        dd = np.where(np.abs(dd) < _TINY, _TINY, dd)
        cc = b + cn / c[active]
        cc = np.where(np.abs(cc) < _TINY, _TINY, cc)
        dd = 1.0 / dd
        delta = cc * dd
        d[active] = dd
        c[active] = cc
        f[active] *= delta
        active = active[np.abs(delta - 1.0) > _EPS]
    return np.exp(log_d - np.log(f))


def chi2_sf(x, dof):
    """Survival function of the chi-square distribution, P(X > x).

    Equals the regularised upper incomplete gamma function Q(dof/2, x/2).
    ``x`` and ``dof`` broadcast (any shapes); ``dof > 0``.  Uses the power
    series of P below x/2 < dof/2 + 1 and the continued fraction of Q above,
    with the Gamma prefactor evaluated via Stirling's series so large ``dof``
    keep ~1e-12 relative accuracy.  Returns a float for scalar input.
    """
    x = np.asarray(x, dtype=float)
    dof = np.asarray(dof, dtype=float)
    if np.any(dof <= 0):
        raise ValueError("chi2_sf: dof must be positive")
    xb, db = np.broadcast_arrays(x, dof)
    shape = xb.shape
    a = db.ravel() / 2.0
    h = xb.ravel() / 2.0
    out = np.ones(a.size)
    out[np.isnan(h)] = np.nan
    out[h == np.inf] = 0.0
    work = np.isfinite(h) & (h > 0)
    low = work & (h < a + 1.0)
    high = work & ~low
    if low.any():
        aa, hh = a[low], h[low]
        out[low] = 1.0 - _lower_series(aa, hh, _log_gamma_prefactor(aa, hh))
    if high.any():
        aa, hh = a[high], h[high]
        out[high] = _upper_fraction(aa, hh, _log_gamma_prefactor(aa, hh))
    out = np.clip(out, 0.0, 1.0).reshape(shape)
    return float(out) if out.ndim == 0 else out


def normal_sf(z):
    """Two-sided p-value P(|Z| >= |z|) of standard-normal z-scores (any shape)."""
    z = np.asarray(z, dtype=float)
    p = np.frompyfunc(lambda v: math.erfc(abs(v) / math.sqrt(2.0)), 1, 1)(z)
    p = np.asarray(p, dtype=float)
    return float(p) if p.ndim == 0 else p


# ---------------------------------------------------------------------------
# Chi-square tests


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


def chi2_gof(observed, expected, min_expected=5.0):
    """Pearson goodness of fit of counts ``observed`` (k,) to ``expected`` (k,).

    ``expected`` is rescaled to sum to ``observed.sum()`` (so probabilities
    may be passed).  Consecutive bins are pooled in order until each pooled
    bin expects at least ``min_expected``; a short tail joins the last pooled
    bin.  Returns ``(statistic, dof, p)`` with ``dof = pooled bins - 1``;
    with fewer than two pooled bins the result is ``(0.0, 0, 1.0)``.
    """
    obs = np.asarray(observed, dtype=float).ravel()
    exp = np.asarray(expected, dtype=float).ravel()
    if obs.shape != exp.shape:
        raise ValueError("chi2_gof: observed and expected differ in length")
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


# ---------------------------------------------------------------------------
# Height distribution along a direction


def _unit(d):
    d = np.asarray(d, dtype=float).reshape(3)
    norm = np.linalg.norm(d)
    if not norm > 0:
        raise ValueError("direction must be a non-zero 3-vector")
    return d / norm


def _kept(tri, areas):
    """Faces with positive area (F', 3, 3), their areas (F',) and the
    bounding-box centre (3,) that heights and moments are taken about, so
    large coordinates do not swamp them."""
    tri = np.asarray(tri, dtype=float)
    areas = np.asarray(areas, dtype=float)
    keep = areas > 0
    tri, areas = tri[keep], areas[keep]
    if len(tri) == 0:
        raise ValueError("surface has zero area")
    return tri, areas, 0.5 * (tri.min(axis=(0, 1)) + tri.max(axis=(0, 1)))


def _heights(tri, ref, d):
    """Sorted vertex heights (F, 3) about ref, and the offset ref.d removed."""
    d = _unit(d)
    return np.sort((tri - ref) @ d, axis=1), float(ref @ d)


def _face_heights(tri, areas, d):
    """Sorted heights (F', 3) and areas (F',) of the faces with positive
    area, and the height offset removed from the heights."""
    tri, areas, ref = _kept(tri, areas)
    h, off = _heights(tri, ref, d)
    return h, areas, off


def _chunks(n_rows, row_size, budget=CHUNK_ENTRIES):
    step = max(1, budget // max(1, row_size))
    for start in range(0, n_rows, step):
        yield slice(start, min(n_rows, start + step))


def _below_fraction(h0, h1, h2, t):
    """Fraction of a triangle with sorted vertex heights h0 <= h1 <= h2 lying
    at height <= t (all arguments broadcast)."""
    # Each branch is used only where its denominator is positive (h0 <= t < h1
    # needs h1 > h0; h1 <= t < h2 needs h2 > h1), so the substituted 1.0 never
    # reaches the result; a face flat in the direction becomes a step.
    den_lo = (h1 - h0) * (h2 - h0)
    den_hi = (h2 - h0) * (h2 - h1)
    lower = (t - h0) ** 2 / np.where(den_lo > 0, den_lo, 1.0)
    upper = 1.0 - (h2 - t) ** 2 / np.where(den_hi > 0, den_hi, 1.0)
    return np.where(t >= h2, 1.0, np.where(t >= h1, upper, np.where(t >= h0, lower, 0.0)))


def _cdf_from_heights(h, areas, s):
    """Area with height <= s for each s in (m,), from sorted heights (F, 3)."""
    s = np.asarray(s, dtype=float).ravel()
    out = np.zeros(s.size)
    for sl in _chunks(len(h), s.size):
        frac = _below_fraction(h[sl, 0, None], h[sl, 1, None], h[sl, 2, None], s[None, :])
        out += areas[sl] @ frac
    return out


class _Sorted:
    """Faces sorted by lowest and by highest vertex height, with running areas:
    bounds the area function cheaply, area(h2 <= t) <= A(t) <= area(h0 <= t)."""

    def __init__(self, h, areas):
        o0, o2 = np.argsort(h[:, 0], kind="stable"), np.argsort(h[:, 2], kind="stable")
        self.h0, self.h2 = h[o0, 0], h[o2, 2]
        self.cum0 = np.concatenate(([0.0], np.cumsum(areas[o0])))
        self.cum2 = np.concatenate(([0.0], np.cumsum(areas[o2])))

    def bracket(self, targets, floor):
        """(lo, hi) per target with A(lo) < target <= A(hi) (up to rounding)."""
        i_hi = np.minimum(np.searchsorted(self.cum2[1:], targets, side="left"), len(self.h2) - 1)
        hi = self.h2[i_hi]
        # The first face whose start lifts the upper bound to the target; lo is
        # the next lower distinct start height, where even the bound is short.
        i_lo = np.minimum(np.searchsorted(self.cum0[1:], targets, side="left"), len(self.h0) - 1)
        j = np.searchsorted(self.h0, self.h0[i_lo], side="left")
        lo = np.where(j > 0, self.h0[np.maximum(j - 1, 0)], floor)
        return np.minimum(lo, hi), hi

    def area_below(self, t):
        """Area of faces lying wholly at height <= t."""
        return self.cum2[np.searchsorted(self.h2, t, side="right")]


def _solve_heights(h, areas, targets, iterations, pad=0.0, budget=4 * CHUNK_ENTRIES):
    """Heights (m,) where the area function reaches each of targets (m,), by
    vectorised bisection, and the area function for heights (m,) each no more
    than ``pad`` above its solution.  Each bracket only involves the faces
    straddling it, so the work is those faces rather than all F per target."""
    lo0 = float(h[:, 0].min())
    extent = float(h[:, 2].max()) - lo0
    table = _Sorted(h, areas)
    lo, hi = table.bracket(targets, lo0 - extent)
    # Straddling faces per target, concatenated: (face index, target index).
    masks = [(h[:, 2] > l) & (h[:, 0] <= u + pad) for l, u in zip(lo.tolist(), hi.tolist())]
    sizes = [int(m.sum()) for m in masks]
    if sum(sizes) > budget:  # long faces everywhere: plain chunked evaluation
        area_at = lambda t: _cdf_from_heights(h, areas, t)
    else:
        faces = np.concatenate([np.nonzero(m)[0] for m in masks]) if masks else np.zeros(0, np.intp)
        owner = np.repeat(np.arange(len(targets)), sizes)
        h_sel, a_sel = h[faces], areas[faces]
        base = table.area_below(lo)

        def area_at(t):
            frac = _below_fraction(h_sel[:, 0], h_sel[:, 1], h_sel[:, 2], t[owner])
            return base + np.bincount(owner, a_sel * frac, minlength=len(targets))

    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        below = area_at(mid) < targets
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    return hi, area_at


def _split(h, areas, k, iterations=48):
    """Interior edges (k-1,) of k equal-area slabs over sorted heights h, and
    the area below each edge."""
    lo0, hi0 = float(h[:, 0].min()), float(h[:, 2].max())
    extent = hi0 - lo0
    if extent <= 0:
        return np.full(k - 1, hi0), np.full(k - 1, areas.sum())
    nudge = 1e-11 * extent + 1e-13 * max(abs(lo0), abs(hi0))
    hi, area_at = _solve_heights(h, areas, areas.sum() * np.arange(1, k) / k, iterations, pad=nudge)
    inner = np.minimum(hi + nudge, hi0)
    return inner, area_at(inner)


def height_cdf(tri, areas, d, t):
    """Area of the surface whose height x.d is <= t.

    tri (F, 3, 3), areas (F,), d (3,) direction (normalised here), t any
    shape; returns an array of t's shape (float for scalar t).  Divide by
    ``areas.sum()`` for the CDF of the height of a uniform surface point.
    """
    h, a, off = _face_heights(tri, areas, d)
    t = np.asarray(t, dtype=float)
    out = _cdf_from_heights(h, a, t.ravel() - off).reshape(t.shape)
    return float(out) if out.ndim == 0 else out


def equal_area_slabs(tri, areas, d, k, iterations=48):
    """Edges (k+1,) of k slabs along d that each hold 1/k of the area.

    edges[0] and edges[k] are the lowest and highest surface heights; the
    k-1 interior edges are found together by bisection on the exact area
    function.  Where the area jumps (faces flat in d) an exact split may not
    exist; the edge then sits just above the jump, so use
    ``slab_probabilities`` for the exact share of each slab.  Interior edges
    are nudged up by ~1e-11 of the extent so points lying on a flat face at an
    edge's height fall below it whatever their rounding.
    """
    k = int(k)
    if k < 1:
        raise ValueError("equal_area_slabs: k must be >= 1")
    tri, areas, ref = _kept(tri, areas)
    h, off = _heights(tri, ref, d)
    inner, _ = _split(h, areas, k, iterations)
    return _edges(h, inner) + off


def _edges(h, inner):
    return np.concatenate(([h[:, 0].min()], inner, [h[:, 2].max()]))


def slab_probabilities(tri, areas, d, edges):
    """Exact probability (k,) that a uniform surface point falls in each slab
    of ``edges`` (k+1,): slab 0 is (-inf, e1], slab j is (e_j, e_j+1], the last
    is (e_k-1, inf) — the same convention as ``slab_counts``."""
    h, a, off = _face_heights(tri, areas, d)
    inner = _cdf_from_heights(h, a, np.asarray(edges, dtype=float)[1:-1] - off) / a.sum()
    # Rounding in the per-face sums can make the CDF step back by an ulp: keep it monotone.
    inner = np.maximum.accumulate(np.clip(inner, 0.0, 1.0))
    return np.diff(np.concatenate(([0.0], inner, [1.0])))


def slab_counts(points, d, edges):
    """Counts (k,) of points (n, 3) per slab of ``edges`` (k+1,) along d.

    Slab j holds heights in (e_j, e_j+1]; heights below e_1 count in slab 0
    and heights above e_k-1 in the last slab.
    """
    edges = np.asarray(edges, dtype=float)
    k = edges.size - 1
    hts = np.asarray(points, dtype=float).reshape(-1, 3) @ _unit(d)
    idx = np.clip(np.searchsorted(edges, hts, side="left") - 1, 0, k - 1)
    return np.bincount(idx, minlength=k)


# ---------------------------------------------------------------------------
# Moments


def _centred_moments(tri, areas):
    """(ref (3,), mean - ref (3,), covariance (3,3), kept tri, kept areas)."""
    tri, areas, ref = _kept(tri, areas)
    v = tri - ref
    w = areas / areas.sum()
    s = v.sum(axis=1)
    mean = w @ (s / 3.0)
    # Per triangle E[x x^T] = (sum_i v_i v_i^T + s s^T) / 12, s = v0 + v1 + v2.
    second = (np.einsum("f,fki,fkj->ij", w, v, v) + np.einsum("f,fi,fj->ij", w, s, s)) / 12.0
    cov = second - np.outer(mean, mean)
    cov = 0.5 * (cov + cov.T)
    return ref, mean, cov, tri, areas


def surface_moments(tri, areas):
    """Exact mean (3,) and second moment E[x x^T] (3, 3) of a uniform point
    on the surface.  Computed about the bounding-box centre; for large
    coordinates prefer ``surface_covariance``, which never forms E[x x^T]."""
    ref, mean, cov, _, _ = _centred_moments(tri, areas)
    mu = ref + mean
    return mu, cov + np.outer(mu, mu)


def surface_covariance(tri, areas):
    """Exact mean (3,) and covariance (3, 3) of a uniform point on the surface."""
    ref, mean, cov, _, _ = _centred_moments(tri, areas)
    return ref + mean, cov


def _fourth_central(tri_c, areas):
    """E[(x_i)^2 (x_j)^2] (6,) for COV_PAIRS, surface already centred at its mean."""
    i = np.array([p[0] for p in COV_PAIRS])
    j = np.array([p[1] for p in COV_PAIRS])
    # Degree-4 integrand: the order-3 rule (exact to degree 5) is exact.
    total = surface_integral(lambda p: p[:, i] ** 2 * p[:, j] ** 2, tri_c, areas, order=3)
    return total / areas.sum()


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
    ref, mean, cov, tri_k, areas_k = _centred_moments(tri, areas)
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
    fourth = _fourth_central(tri_k - (ref + mean), areas_k)
    exact = np.array([cov[i, j] for i, j in COV_PAIRS])
    got = np.array([sample_cov[i, j] for i, j in COV_PAIRS])
    se_cov = np.sqrt(np.maximum(fourth - exact**2, 0.0) / n)
    se_cov = np.maximum(se_cov, 1e-12 * scale**2)
    return z_mean, (got - exact) / se_cov


# ---------------------------------------------------------------------------
# Quadrature


def triangle_quadrature(order):
    """Rule on the triangle: barycentric nodes (q, 3) and weights (q,) summing to 1.

    Gauss-Legendre through the collapsed (Duffy) map (u, v) -> (u, (1-u) v):
    ``order`` points along v and ``order + 1`` along u (the Jacobian 1-u adds
    one degree), q = order (order + 1); exact for polynomials of total degree
    <= 2 order - 1.
    """
    order = int(order)
    if order < 1:
        raise ValueError("triangle_quadrature: order must be >= 1")
    gu, wu = np.polynomial.legendre.leggauss(order + 1)
    gv, wv = np.polynomial.legendre.leggauss(order)
    u, wu = 0.5 * (gu + 1.0), 0.5 * wu
    v, wv = 0.5 * (gv + 1.0), 0.5 * wv
    x = np.repeat(u, order)
    y = np.outer(1.0 - u, v).ravel()
    # Reference triangle has area 1/2; the factor 2 makes weights sum to 1.
    w = (2.0 * (1.0 - u) * wu)[:, None] * wv[None, :]
    nodes = np.column_stack((1.0 - x - y, x, y))
    return nodes, w.ravel()


def surface_integral(f, tri, areas, order=4):
    """Integral of f over the surface with the ``triangle_quadrature(order)`` rule.

    f maps points (m, 3) to values (m,) or (m, c); returns a float or (c,).
    Faces are processed in chunks so at most ~256k points exist at once.
    """
    tri = np.asarray(tri, dtype=float)
    areas = np.asarray(areas, dtype=float)
    nodes, weights = triangle_quadrature(order)
    q = len(weights)
    total = 0.0
    for sl in _chunks(len(tri), q, budget=1 << 18):
        pts = np.einsum("qk,fkj->fqj", nodes, tri[sl]).reshape(-1, 3)
        vals = np.asarray(f(pts), dtype=float)
        vals = vals.reshape((sl.stop - sl.start, q) + vals.shape[1:])
        total = total + np.einsum("f,q,fq...->...", areas[sl], weights, vals)
    return float(total) if np.ndim(total) == 0 else total


def smooth_test_function(points, bounds):
    """Smooth non-polynomial test integrand: points (n, 3) -> (n,).

    With ``bounds`` (2, 3) (min and max corners, e.g. ``mesh.bounds``) the
    coordinates are mapped to u = (p - centre) / half, half being half the
    largest box side, so u lies in [-1, 1]^3 whatever the mesh's size, and
    f = exp(0.7 u_x - 0.4 u_y) cos(1.3 u_y + 0.6 u_z) + sin(1.9 u_z + 0.8 u_x + 0.3).
    It is entire (fast quadrature convergence) and of order one on the mesh.
    """
    bounds = np.asarray(bounds, dtype=float).reshape(2, 3)
    centre = bounds.mean(axis=0)
    half = max(0.5 * float((bounds[1] - bounds[0]).max()), _TINY)
    u = (np.asarray(points, dtype=float).reshape(-1, 3) - centre) / half
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    return np.exp(0.7 * x - 0.4 * y) * np.cos(1.3 * y + 0.6 * z) + np.sin(1.9 * z + 0.8 * x + 0.3)


# ---------------------------------------------------------------------------
# Summaries for `scatter check`


def default_directions():
    """The three axes and the four body diagonals, as unit rows (7, 3)."""
    axes = np.eye(3)
    diag = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1]], dtype=float) / math.sqrt(3.0)
    return np.vstack((axes, diag))


def _slabs(tri, areas, directions, k):
    """[(direction, edges (k+1,), exact probabilities (k,))] per direction."""
    dirs = default_directions() if directions is None else np.asarray(directions, dtype=float).reshape(-1, 3)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    tri, areas, ref = _kept(tri, areas)
    total = areas.sum()
    out = []
    for d in dirs:  # a handful of directions
        h, off = _heights(tri, ref, d)
        inner, below = _split(h, areas, int(k))
        below = np.maximum.accumulate(np.clip(below / total, 0.0, 1.0))
        prob = np.diff(np.concatenate(([0.0], below, [1.0])))
        out.append((d, _edges(h, inner) + off, prob))
    return out


def _bonferroni(pvalues):
    p = [x for x in pvalues if x is not None]
    return min(1.0, len(p) * min(p)) if p else 1.0


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
    stats, dofs, ps, dirs = [], [], [], []
    for d, edges, prob in _slabs(tri, areas, directions, k):
        stat, dof, p = chi2_gof(slab_counts(pts, d, edges), prob * n, min_expected)
        dirs.append(d.tolist())
        stats.append(stat)
        dofs.append(dof)
        ps.append(p if dof > 0 else None)
    z_mean, z_cov = moment_z_scores(pts, tri, areas)
    p_z = normal_sf(np.concatenate((z_mean, z_cov))).tolist()
    return {
        "n": n,
        "k": int(k),
        "directions": dirs,
        "slab_statistic": stats,
        "slab_dof": dofs,
        "slab_p": ps,
        "p_slabs": _bonferroni(ps),
        "z_mean": z_mean.tolist(),
        "z_cov": z_cov.tolist(),
        "p_moments": _bonferroni(p_z),
        "p": _bonferroni(ps + p_z),
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
    stats, dofs, ps, dirs = [], [], [], []
    for d, edges, _ in _slabs(tri, areas, directions, k):
        stat, dof, p = chi2_two_sample(slab_counts(a, d, edges), slab_counts(b, d, edges), min_expected)
        dirs.append(d.tolist())
        stats.append(stat)
        dofs.append(dof)
        ps.append(p if dof > 0 else None)
    ref, _, cov, tri_k, _ = _centred_moments(tri, areas)
    scale = float(np.ptp(tri_k.reshape(-1, 3), axis=0).max())
    se = np.maximum(np.sqrt(np.diag(cov) * (1.0 / len(a) + 1.0 / len(b))), 1e-12 * scale)
    z = ((a - ref).mean(axis=0) - (b - ref).mean(axis=0)) / se
    p_z = normal_sf(z).tolist()
    return {
        "na": len(a),
        "nb": len(b),
        "k": int(k),
        "directions": dirs,
        "slab_statistic": stats,
        "slab_dof": dofs,
        "slab_p": ps,
        "p_slabs": _bonferroni(ps),
        "z_mean_diff": z.tolist(),
        "p_means": _bonferroni(p_z),
        "p": _bonferroni(ps + p_z),
    }
