"""Exact quantities of a piecewise-flat surface: equal-area slabs (their heights found by
:mod:`scatter_cli.stats.slabs`), moments and quadrature.

A surface is ``tri`` ``(F, 3, 3) float64`` (vertex ``k`` of face ``f`` is ``tri[f, k]``)
and ``areas`` ``(F,) float64``; faces of zero area contribute nothing. Everything is a
closed form per triangle, vectorised over faces and points. Used by ``scatter check``
(through :mod:`scatter_cli.stats.uniformity`), ``scatter bench`` and the tests (tests/exact_reference.py
holds what only the tests use).
"""

import numpy as np

from .slabs import solve_heights as _solve_heights

# Upper bound on the entries of one (faces x values) work matrix; each chunk
# holds a handful of such temporaries, so this keeps them to tens of MB.
CHUNK_ENTRIES = 1 << 21
# The slabs scatter check counts in reach their target areas to 2^-SLAB_ITERATIONS of a
# slab's area (or, at a jump of the area, that fraction of their first bracket).
SLAB_ITERATIONS = 12

# Unordered coordinate pairs for second central moments: xx, yy, zz, xy, xz, yz.
COV_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))

_TINY = 1e-300

# Dunavant's 6-point rule on the triangle, exact to degree 4 (the fourth moments):
# barycentric nodes (6, 3) and weights (6,) summing to 1.
_A, _B = 0.445948490915965, 0.091576213509771
DEGREE4_NODES = np.array([[1 - 2 * _A, _A, _A], [_A, 1 - 2 * _A, _A], [_A, _A, 1 - 2 * _A],
                          [1 - 2 * _B, _B, _B], [_B, 1 - 2 * _B, _B], [_B, _B, 1 - 2 * _B]])
DEGREE4_WEIGHTS = np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)
DEGREE4_WEIGHTS /= DEGREE4_WEIGHTS.sum()


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
    if not keep.all():
        tri, areas = tri[keep], areas[keep]
    if len(tri) == 0:
        raise ValueError("surface has zero area")
    lo, hi = _box(tri)
    return tri, areas, 0.5 * (lo + hi)


def _box(tri):
    """Lowest and highest coordinates (3,), (3,) of the corners of tri (F, 3, 3) (column by
    column: a reduction across rows of an (n, 3) array is many times slower)."""
    corners = tri.reshape(-1, 3)
    return (np.array([corners[:, k].min() for k in range(3)]),
            np.array([corners[:, k].max() for k in range(3)]))


def _sorted_heights(centred, d):
    """Vertex heights (F, 3) along d of the faces ``centred`` (F, 3, 3), each row sorted
    (a sorting network: the same values as np.sort, a fraction of its time)."""
    v = centred.reshape(-1, 3)
    h = (v[:, 0] * d[0] + v[:, 1] * d[1] + v[:, 2] * d[2]).reshape(-1, 3)
    a, b, c = h[:, 0], h[:, 1], h[:, 2]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    out = np.empty_like(h)
    np.minimum(lo, c, out=out[:, 0])
    mid = np.maximum(lo, c)
    np.minimum(mid, hi, out=out[:, 1])
    np.maximum(mid, hi, out=out[:, 2])
    return out


def _chunks(n_rows, row_size, budget=CHUNK_ENTRIES):
    step = max(1, budget // max(1, row_size))
    for start in range(0, n_rows, step):
        yield slice(start, min(n_rows, start + step))


def _split(h, areas, k, iterations=48, least_nudge=0.0):
    """Interior edges (k-1,) of k equal-area slabs over sorted heights h, and
    the area below each edge; an edge at a jump of the area sits at least
    ``least_nudge`` above it."""
    lo0, hi0 = float(h[:, 0].min()), float(h[:, 2].max())
    extent = hi0 - lo0
    if extent <= 0:
        return np.full(k - 1, hi0), np.full(k - 1, areas.sum())
    nudge = max(1e-11 * extent + 1e-13 * max(abs(lo0), abs(hi0)), least_nudge)
    hi, area_at = _solve_heights(h, areas, areas.sum() * np.arange(1, k) / k, iterations, pad=nudge)
    inner = np.minimum(hi + nudge, hi0)
    return inner, area_at(inner)


def _edges(h, inner):
    return np.concatenate(([h[:, 0].min()], inner, [h[:, 2].max()]))


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


def rounding(tri):
    """How far a computed height of a point on the surface ``tri`` (F, 3, 3) may be from
    the exact one: 2^-38 of the largest coordinate, thousands of ulps (a sampler's point
    on a face lies within a few ulps of it, a height adds a few more)."""
    return 2.0**-38 * max(float(np.abs(tri).max()), _TINY)


def slabs(tri, areas, directions, k, iterations=SLAB_ITERATIONS, progress=None):
    """[(direction (3,), edges (j+1,), exact probabilities (j,))] for each of the
    directions (m, 3): about k equal-area slabs along each, as ``equal_area_slabs``
    finds them, made robust to rounding.

    edges[0] and edges[j] are the lowest and highest heights of the surface. An interior
    edge where the area jumps (a face flat in the direction) sits just above the flat
    face, so the face's points fall below it whatever their rounding; interior edges
    within :func:`rounding` of the highest height or of the edge below are dropped, so
    that no slab of zero probability lies where a rounded point of the surface can
    fall (j <= k). The area below each edge is within 2^-iterations of a slab of its
    target (:func:`slab_heights.solve_heights`): the edges only need to be near
    equal-area, the probabilities are exact for the edges found.
    ``progress(i, m)`` is called before direction i of m.
    """
    dirs = np.asarray(directions, dtype=float).reshape(-1, 3)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    tri, areas, ref = _kept(tri, areas)
    total = areas.sum()
    tol = rounding(tri)
    centred = tri - ref
    out = []
    for i, d in enumerate(dirs):  # a handful of directions
        if progress:
            progress(i, len(dirs))
        h, off = _sorted_heights(centred, d), float(ref @ d)
        inner, below = _split(h, areas, int(k), iterations, 2.0 * tol)
        top = float(h[:, 2].max())
        keep = inner < top - tol
        keep[1:] &= np.diff(inner) > tol
        inner, below = inner[keep], below[keep]
        below = np.maximum.accumulate(np.clip(below / total, 0.0, 1.0))
        prob = np.diff(np.concatenate(([0.0], below, [1.0])))
        out.append((d, _edges(h, inner) + off, prob))
    return out


# ---------------------------------------------------------------------------
# Moments


def centred_moments(tri, areas):
    """(ref (3,), mean - ref (3,), covariance (3,3), kept tri, kept areas)."""
    tri, areas, ref = _kept(tri, areas)
    v = tri - ref
    w = areas / areas.sum()
    s = v[:, 0] + v[:, 1] + v[:, 2]
    mean = w @ (s / 3.0)
    # Per triangle E[x x^T] = (sum_i v_i v_i^T + s s^T) / 12, s = v0 + v1 + v2.
    corners = v.reshape(-1, 3)
    second = ((corners * np.repeat(w, 3)[:, None]).T @ corners + (s * w[:, None]).T @ s) / 12.0
    cov = second - np.outer(mean, mean)
    cov = 0.5 * (cov + cov.T)
    return ref, mean, cov, tri, areas


def surface_covariance(tri, areas):
    """Exact mean (3,) and covariance (3, 3) of a uniform point on the surface."""
    ref, mean, cov, _, _ = centred_moments(tri, areas)
    return ref + mean, cov


def fourth_central_moments(tri_c, areas):
    """E[(x_i)^2 (x_j)^2] (6,) for COV_PAIRS, surface already centred at its mean."""
    i = np.array([p[0] for p in COV_PAIRS])
    j = np.array([p[1] for p in COV_PAIRS])
    tri_c = np.asarray(tri_c, dtype=float)
    areas = np.asarray(areas, dtype=float)
    total = np.zeros((3, 3))
    for sl in _chunks(len(tri_c), len(DEGREE4_WEIGHTS), budget=1 << 18):
        sq = (np.matmul(DEGREE4_NODES, tri_c[sl]) ** 2).reshape(-1, 3)  # the rule's points, squared
        w = (areas[sl, None] * DEGREE4_WEIGHTS).ravel()
        total += (sq * w[:, None]).T @ sq  # [i, j]: sum of w x_i^2 x_j^2
    return total[i, j] / areas.sum()


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
