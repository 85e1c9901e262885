"""How well spread a point set is: nearest-neighbour distances and the relative radius."""

import math

import numpy as np

from .pairs import as_points, bounding_box, cross_pairs, all_pairs

def relative_radius(d_min, area, count):
    """Lagae & Dutré (2008) relative radius rho = d_min / d_hex.

    d_hex = sqrt(2 A / (sqrt(3) N)) is the spacing of a hexagonal packing of
    N points on area A; rho near 0.75 to 0.85 is good Poisson-disk quality.
    """
    if count <= 0 or area <= 0:
        raise ValueError("relative_radius needs count > 0 and area > 0")
    return float(d_min) / hex_spacing(area, count)


def hex_spacing(area, count):
    return math.sqrt(2.0 * area / (math.sqrt(3.0) * count))


def nearest_distances(points, guess):
    """Nearest-neighbour distance (n,) float64 of each point (inf if n < 2).

    Starts with pairs closer than ``guess`` and doubles the radius only for
    points still without a neighbour.  Meant for well-spread sets: dense
    clusters make the first pair list long.
    """
    n = points.shape[0]
    nn = np.full(n, np.inf)
    if n < 2:
        return nn
    lo, hi = bounding_box(points)
    extent = float((hi - lo).max())
    radius = max(guess, extent * 1e-9, np.finfo(float).tiny)
    i, j, d = all_pairs(points, radius)
    np.minimum.at(nn, i, d)
    np.minimum.at(nn, j, d)
    for _ in range(80):
        todo = np.flatnonzero(~np.isfinite(nn))
        if todo.size == 0:
            break
        radius *= 2.0
        q, r, d = cross_pairs(points[todo], points, radius)
        other = todo[q] != r
        np.minimum.at(nn, todo[q[other]], d[other])
    return nn


def spacing_stats(points, area):
    """Spacing of a point set on a surface of area A.

    points (n, 3) float64.  Returns {"count", "d_min", "mean_nn", "rho"}:
    minimum and mean nearest-neighbour distance (Euclidean) and the relative
    radius rho = d_min / d_hex.  With fewer than 2 points distances are inf
    and rho is nan.
    """
    pts = as_points(points)
    n = pts.shape[0]
    if n < 2:
        return {"count": n, "d_min": math.inf, "mean_nn": math.inf, "rho": math.nan}
    nn = nearest_distances(pts, hex_spacing(area, n))
    d_min = float(nn.min())
    return {
        "count": n,
        "d_min": d_min,
        "mean_nn": float(nn.mean()),
        "rho": relative_radius(d_min, area, n),
    }
