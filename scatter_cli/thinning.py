"""Poisson-disk thinning of a candidate point set, Euclidean distance in 3D.

Candidates are points drawn uniformly on a surface. A subset is kept so that kept points
are at least ``radius`` apart, least crowded candidates first (:mod:`.greedy`), over the
pairs that a uniform grid finds (:mod:`.pairs`); an exact count is reached by a radius
search and a trim (:mod:`.exact_count`); :mod:`.spacing` measures the result. How it
works and the figures behind its constants: docs/poisson.md.
"""

import math

import numpy as np

from .exact_count import search_radius, trim_to_count
from .greedy import PairGraph
from .pairs import as_points, cross_pairs
from .spacing import hex_spacing, nearest_distances


def thin_by_radius(points, radius):
    """Indices (m,) int64, ascending, of a maximal Poisson-disk subset.

    points (n, 3) float64.  Every pair of kept points is >= radius apart
    (Euclidean), and every candidate lies within radius of a kept point.
    """
    pts = as_points(points)
    radius = float(radius)
    if not radius > 0 or not math.isfinite(radius):
        raise ValueError(f"radius must be a positive finite number, got {radius}")
    n = pts.shape[0]
    kept = np.zeros(n, dtype=bool)
    todo = np.arange(n)
    for _ in range(n + 1):
        if todo.size == 0:
            break
        sub = pts if todo.size == n else pts[todo]
        graph = PairGraph(sub, radius)
        new = graph.active[graph.kept(radius)]
        kept[todo[new]] = True
        # capped-out points may be uncovered; only they need a geometric query
        active = np.zeros(sub.shape[0], dtype=bool)
        active[graph.active] = True
        rest = np.flatnonzero(~active)
        hit, _, _ = cross_pairs(sub[rest], sub[new], radius)
        uncovered = np.ones(rest.size, dtype=bool)
        uncovered[hit] = False
        todo = todo[rest[uncovered]]
    return np.flatnonzero(kept).astype(np.int64)


def thin_to_count(points, count, area):
    """Exactly ``count`` points, spread as far apart as the candidates allow.

    points (n, 3) float64 candidates, uniform on a surface of area ``area``.
    Returns (indices (count,) int64 ascending, d_min float): d_min is the
    minimum pairwise distance of the kept points (inf for count < 2).

    The radius is searched so that the least-crowded-first greedy keeps slightly more
    than count; the surplus is then removed from the closest pairs.
    """
    pts = as_points(points)
    n = pts.shape[0]
    count = int(count)
    if count < 0:
        raise ValueError(f"count must be >= 0, got {count}")
    if count > n:
        raise ValueError(f"count={count} is more than the {n} candidate points; sample more candidates")
    if not area > 0:
        raise ValueError(f"area must be positive, got {area}")
    if count == n or count < 2:
        idx = np.arange(count, dtype=np.int64)
        return idx, float(nearest_distances(pts[idx], hex_spacing(area, max(count, 1))).min(initial=np.inf))
    d_hex = hex_spacing(area, count)
    lo, lo_idx, hi = search_radius(pts, count, d_hex)
    return trim_to_count(pts, lo_idx, lo, hi, d_hex, count)
