"""Builders and checks shared by the hard-case tests (tests/) and benchmarks/hard_cases.py:
meshes of separate triangles, the exact on-face test, the in-triangle chi-square (through scatter_cli.stats.chisquare).

Here, in testkit/, so that tests and benchmarks never import each other."""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from scatter_cli.stats.chisquare import chi2_gof

EPS = np.finfo(np.float64).eps
ALPHA = 1e-3  # significance level of every statistical test in the hard-case suite


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def exact_face_errors(points, tri, limit=400, seed=0, dtype=np.float64):
    """Distance to the plane and barycentric overshoot of points, in exact arithmetic.

    points: (n, 3) float64; tri: (n, 3, 3) float64, the world corners of each point's face.
    Up to ``limit`` points (a fixed random subset) are checked with Fractions, so the check
    itself adds no rounding. Returns (distance / unit, overshoot / bary_unit) arrays where
    ``unit = spacing(largest coordinate) + eps * longest edge`` is one rounding of a point
    on that face (in ``dtype``, the output precision) and ``bary_unit = unit * longest edge / (2 area)`` what such a rounding does
    to a barycentric coordinate: "within k units" means "on the face up to k roundings".
    """
    points, tri = np.asarray(points, np.float64), np.asarray(tri, np.float64)
    idx = np.arange(len(points))
    if len(idx) > limit:
        idx = np.random.default_rng(seed).choice(len(idx), limit, replace=False)
    dist, over = [], []
    for i in idx:
        v = [tuple(Fraction(float(x)) for x in tri[i, k]) for k in range(3)]
        p = tuple(Fraction(float(x)) for x in points[i])
        e1 = tuple(a - b for a, b in zip(v[1], v[0]))
        e2 = tuple(a - b for a, b in zip(v[2], v[0]))
        d = tuple(a - b for a, b in zip(p, v[0]))
        n = _cross(e1, e2)
        nn = _dot(n, n)
        assert nn > 0, "exact check on a zero-area face"
        b1 = _dot(_cross(d, e2), n) / nn
        b2 = _dot(_cross(e1, d), n) / nn
        b0 = 1 - b1 - b2
        h2 = _dot(d, n) ** 2 / nn
        edges = tri[i] - np.roll(tri[i], 1, axis=0)
        longest = float(np.sqrt((edges**2).sum(axis=1)).max())
        scale = float(max(np.abs(tri[i]).max(), np.abs(points[i]).max()))
        unit = float(np.spacing(np.asarray(scale, dtype))) + float(np.finfo(dtype).eps) * longest
        bary_unit = unit * longest / float(np.sqrt(float(nn)))
        dist.append(float(np.sqrt(float(h2))) / unit)
        over.append(float(max(-min(b0, b1, b2), max(b0, b1, b2) - 1, 0)) / bary_unit)
    return np.asarray(dist), np.asarray(over)


def pooled_pvalue(observed, expected, min_expected=5.0):
    """The p-value of the pooled chi-square (scatter_cli.stats.chisquare.chi2_gof) of counts
    in bins with no order of their own (faces, area groups): pooled smallest expectation
    first."""
    return chi2_gof(observed, expected, min_expected, smallest_first=True)[2]


def bary_bins(b1, b2, k=16):
    """Index of the sub-triangle (of the k*k equal-area ones) holding (b1, b2); -1 outside."""
    x, y = np.asarray(b1) * k, np.asarray(b2) * k
    i = np.clip(np.floor(x).astype(int), 0, k - 1)
    j = np.clip(np.floor(y).astype(int), 0, k - 1)
    upper = (x - i) + (y - j) > 1
    return (i * k + j) * 2 + upper


def uniform_in_triangle_pvalue(b1, b2, k=16):
    """Chi-square p-value that barycentric (b1, b2) are uniform over the triangle."""
    idx = bary_bins(b1, b2, k)
    counts = np.bincount(idx, minlength=2 * k * k)
    valid = np.zeros(2 * k * k, bool)
    for i in range(k):
        for j in range(k - i):
            valid[(i * k + j) * 2] = True
            if i + j < k - 1:
                valid[(i * k + j) * 2 + 1] = True
    if counts[~valid].sum():
        return 0.0
    return chi2_gof(counts[valid], np.ones(int(valid.sum())))[2]


def recover_bary(points, tri):
    """Float64 barycentric (b1, b2) of points on well-shaped faces (n, 3, 3), relative to v0."""
    d = np.asarray(points, np.float64) - tri[:, 0]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    g11, g12, g22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    r1, r2 = (d * e1).sum(1), (d * e2).sum(1)
    det = g11 * g22 - g12 * g12
    return (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det


def two_sum_le_one(x, y):
    """Exact test of x + y <= 1 for float64 arrays (TwoSum error term, no rounding)."""
    s = x + y
    bb = s - x
    err = (x - (s - bb)) + (y - bb)
    return (s < 1) | ((s == 1) & (err <= 0))


def triangles_mesh(tri):
    """A trimesh.Trimesh of separate triangles: tri (F, 3, 3) float64."""
    import trimesh

    tri = np.asarray(tri, dtype=np.float64)
    return trimesh.Trimesh(tri.reshape(-1, 3), np.arange(len(tri) * 3).reshape(-1, 3), process=False)


def awkward_mesh(seed):
    """(vertices (n, 3), faces (m, 3)): random faces with repeated corners, collinear
    corners, huge and tiny coordinates and non-finite vertices."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(400, 3)) * rng.choice([1e-300, 1.0, 1e150, 1e300], (400, 1))
    v[:3] = [[0, 0, 0], [1, 1, 1], [2, 2, 2]]
    v[5], v[6] = np.nan, [np.inf, 0, 0]
    f = rng.integers(0, len(v), (3000, 3))
    f[:4] = [[0, 1, 2], [3, 3, 4], [5, 7, 8], [6, 9, 10]]
    return v, f


def spread_triangles(exponents):
    """Right triangles with areas 10**e, one per exponent, each in its own plane z = index.

    Returns (tri (F, 3, 3), areas (F,)).
    """
    exponents = np.asarray(exponents, dtype=np.float64)
    legs = np.sqrt(2 * 10.0**exponents)
    tri = np.zeros((len(legs), 3, 3))
    tri[:, 1, 0] = legs
    tri[:, 2, 1] = legs
    tri[:, :, 2] = np.arange(len(legs))[:, None]
    return tri, 10.0**exponents


def area_groups(areas, counts, n):
    """Observed and expected counts (g,) of faces grouped by area decade."""
    decade = np.floor(np.log10(areas)).astype(int)
    keys = np.unique(decade)
    obs = np.array([counts[decade == k].sum() for k in keys])
    exp = np.array([n * areas[decade == k].sum() / areas.sum() for k in keys])
    return obs, exp
