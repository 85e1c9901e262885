"""Poisson-disk thinning of a candidate point set, Euclidean distance in 3D.

Candidates are points drawn uniformly on a surface. A subset is kept so that kept points
are at least ``radius`` apart, least crowded candidates first (:mod:`.greedy`), over the
pairs that a uniform grid finds (:mod:`.pairs`); an exact count is reached by a radius
search and a trim (:mod:`.exact_count`); :mod:`.spacing` measures the result. How it
works and the figures behind its constants: docs/poisson.md.

The policy lives here too: how many candidates a thinning draws (:func:`candidate_count`),
the source of the kept points (:class:`ThinnedSource`, from :func:`thinned` or, for
``--stable``, :func:`dart_thrown`).
"""

from __future__ import annotations

import math
import time

import numpy as np

from . import greedy, pairs
from ...errors import ScatterError, ScatterUsageError
from .count_search import search_radius, trim_to_count
from .greedy import PairGraph
from .pairs import as_points, cross_pairs
from ...core.native import in_blocks
from ..plan import RawChunk
from .spacing import hex_spacing, nearest_distances, relative_radius

# Candidates drawn per output point before thinning: more buy a larger spacing (rho) for
# more time (docs/how-it-samples.md: oversampling).
OVERSAMPLING = 8  # for --poisson -n N
SMALL_SET, SMALL_SET_OVERSAMPLING = 5_000, 15  # for --poisson sets of up to SMALL_SET points
RADIUS_OVERSAMPLING = 5  # for --radius: times the most points an R-spaced set can hold
MAX_CANDIDATES = 50_000_000  # a larger thinning job is refused


def poisson_candidates(count, oversampling=None, usage=False) -> int:
    """Candidates to draw for ``--poisson -n count``. Past MAX_CANDIDATES: a usage error
    when the count was given (``usage``), else (a ``--density`` count) a failure of the mesh."""
    need = (oversampling or (SMALL_SET_OVERSAMPLING if count <= SMALL_SET else OVERSAMPLING)) * count
    return _bounded(need, f"--poisson -n {count:,} is too many points", ScatterUsageError if usage else ScatterError)


def radius_candidates(area, radius, source, oversampling=None) -> int:
    """Candidates to draw for ``--radius radius`` over ``area``: no R-spaced set holds more
    than the hexagonal packing of spacing R. Past MAX_CANDIDATES: a failure of the mesh."""
    bound = area / (math.sqrt(3) / 2 * radius * radius)
    if bound < 1:
        return RADIUS_OVERSAMPLING
    return _bounded((oversampling or RADIUS_OVERSAMPLING) * bound,
                    f"--radius {radius:g} is too small for {source} (area {area:.6g})", ScatterError)


def candidate_count(area, count, radius, source, oversampling=None) -> int:
    """How many uniform candidates to draw before thinning (``area`` unused without ``radius``)."""
    if radius is not None:
        return radius_candidates(area, radius, source, oversampling)
    return poisson_candidates(count, oversampling)


def _bounded(need, what, error):
    if need > MAX_CANDIDATES:
        raise error(f"{what}: thinning would need {need:,.0f} candidates, more than {MAX_CANDIDATES:,}")
    return max(1, int(math.ceil(need)))


class ThinnedSource:
    """The points of ``kept`` (a RawChunk starting at 0), chosen out of ``candidates``."""

    stats = None

    def __init__(self, kept: RawChunk, candidates):
        self.kept, self.candidates = kept, candidates
        self.count = len(kept.points)
        self.area = candidates.area

    def draw(self, start: int, stop: int) -> RawChunk:
        return self.kept.slice(start, stop)


def thinned(candidates, count: int | None = None, radius: float | None = None):
    """A Poisson-disk subset of all the points of ``candidates`` (a source): (ThinnedSource, info).

    ``radius`` given: a maximal set with no two points closer than it; else exactly
    ``count`` points, spaced as far apart as the search reaches. ``info`` holds
    ``count``, ``candidates``, ``radius``, (exact count) ``d_min`` and ``rho``, and the
    ``timings`` of drawing and of thinning.
    """
    t = time.perf_counter()
    blocks = in_blocks(candidates.draw, candidates.count)
    points = np.concatenate([b.points for b in blocks]) if len(blocks) > 1 else blocks[0].points
    t1 = time.perf_counter()
    if radius is not None:
        index, d_min = thin_by_radius(points, radius), None
    else:
        index, d_min = thin_to_count(points, count, candidates.area)
    source = ThinnedSource(_take(blocks, index), candidates)
    info = {"count": source.count, "candidates": candidates.count, "radius": radius}
    if d_min is not None:
        info.update(d_min=d_min, rho=relative_radius(d_min, candidates.area, source.count))
    info["timings"] = {"candidates": t1 - t, "thinning": time.perf_counter() - t1}
    return source, info


def _take(blocks, index):
    """Rows ``index`` (k,) ascending of the chunks ``blocks`` end to end, as one chunk."""
    ends = np.cumsum([len(b.points) for b in blocks])
    cuts = np.searchsorted(index, ends)
    return RawChunk.join([b.take(part - (end - len(b.points)))
                          for b, part, end in zip(blocks, np.split(index, cuts[:-1]), ends)])


def dart_thrown(source, radius):
    """A :class:`ThinnedSource` of ``source``'s points, each kept in order when no point
    kept before it lies within ``radius``: every kept pair at least R apart, every point
    within R of a kept one, and the kept set is as local as the order (``--stable --radius``)."""
    raw = source.draw(0, source.count)
    i, j, _ = pairs.all_pairs(raw.points, radius)
    kept = np.flatnonzero(greedy.in_priority_order(len(raw.points), i, j, np.arange(len(raw.points))))
    return ThinnedSource(raw.take(kept), source)


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
