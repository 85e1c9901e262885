"""Thinning to an exact count: search the radius whose greedy set is a little larger than
the count, then trim the surplus from the closest pairs.

The constants below were chosen from measurements described in docs/poisson.md.
"""

import math

import numpy as np

from .greedy import PairGraph
from .pairs import all_pairs
from .spacing import nearest_distances

# The first radius tried, relative to d_hex, with k candidates a point: GUESS_A - GUESS_B / k
# (aimed a little below the radius that keeps exactly the count).
GUESS_A, GUESS_B = 0.8275, 0.54
COUNT_SLACK = 0.06  # stop the search once the surplus is below this fraction of the count
TRIM_REACH = 1.1  # the surplus is trimmed from the pairs closer than this times the radius reached
SEARCH_STEPS = 30
REACH = 1.04  # pair graph reach relative to the radius tried; a miss only costs a rebuild


def search_radius(pts, count, d_hex):
    """The radius search: secant steps in log r, kept inside a bracket, until the
    least-crowded-first greedy keeps between count and count * (1 + COUNT_SLACK) points.

    pts (n, 3) float64 candidates, count < n. Returns (lo, lo_idx, hi): the largest radius
    tried that keeps at least ``count`` (0 if none), its kept indices (m,) ascending, and
    the smallest radius tried that keeps fewer (inf if none).
    """
    n = pts.shape[0]
    radius = max(GUESS_A - GUESS_B * count / n, 0.05) * d_hex
    slack = max(1, int(count * COUNT_SLACK))
    aim = count + 0.5 * slack
    graph = None
    lo, lo_idx = 0.0, np.arange(n)
    hi, hi_count = math.inf, 0
    for _ in range(SEARCH_STEPS):
        if graph is None or radius >= graph.reach:
            graph = _pair_graph(pts, REACH * radius, count)
        kept = graph.active[graph.kept(radius)]
        if kept.size >= count:
            lo, lo_idx = radius, kept
            if kept.size - count <= slack:
                break
        else:
            hi, hi_count = radius, kept.size
        radius = _next_radius(lo, lo_idx.size, hi, hi_count, aim)
        if radius is None:
            break
    return lo, np.sort(lo_idx), hi


def trim_to_count(pts, lo_idx, lo, hi, d_hex, count):
    """Exactly ``count`` of the points ``lo_idx`` (m,) found at radius ``lo``: the surplus
    removed from the closest pairs. Returns (indices (count,) int64 ascending, d_min)."""
    reach = min(hi, TRIM_REACH * lo) if lo > 0 else 2.0 * d_hex
    i, j, d = all_pairs(pts[lo_idx], reach)
    final = _trim(np.ones(lo_idx.size, dtype=bool), i, j, d, count)
    idx = lo_idx[final].astype(np.int64)
    both = final[i] & final[j]
    d_min = float(d[both].min()) if both.any() else float(nearest_distances(pts[idx], reach).min())
    return idx, d_min


def _trim(kept, i, j, d, target):
    """Remove points from ``kept`` (n,) bool until exactly ``target`` remain,
    always taking a point of the currently closest pairs first.

    Edges i, j, d (m,) sorted by d; edges with an end not kept are ignored.
    """
    kept = kept.copy()
    n = kept.size
    for _ in range(n + 1):
        need = int(kept.sum()) - target
        if need <= 0:
            break
        both = kept[i] & kept[j]
        i, j, d = i[both], j[both], d[both]
        if i.size == 0:
            # everything is farther apart than the pair list reaches
            kept[np.flatnonzero(kept)[-need:]] = False
            break
        nn = np.full(n, np.inf)
        np.minimum.at(nn, i, d)
        np.minimum.at(nn, j, d)
        crowd = np.bincount(i, minlength=n) + np.bincount(j, minlength=n)
        # badness: closest neighbour first, then most neighbours, then larger index
        worse = (nn[i] < nn[j]) | ((nn[i] == nn[j]) & ((crowd[i] > crowd[j]) | ((crowd[i] == crowd[j]) & (i > j))))
        spared = np.zeros(n, dtype=bool)
        spared[np.where(worse, j, i)] = True
        worst = np.zeros(n, dtype=bool)
        worst[i] = True
        worst[j] = True
        worst &= ~spared
        cand = np.flatnonzero(worst)
        if cand.size > need:  # only the need worst are ranked in full
            cand = cand[nn[cand] <= np.partition(nn[cand], need - 1)[need - 1]]
        kept[cand[np.lexsort((-cand, -crowd[cand], nn[cand]))][:need]] = False
    return kept


def _pair_graph(pts, reach, count):
    """PairGraph of the capped candidates, or of all of them when the cap would leave
    fewer than ``count``."""
    graph = PairGraph(pts, reach)
    if graph.active.size < count:
        graph = PairGraph(pts, reach, capped=False)
    return graph


def _next_radius(lo, lo_count, hi, hi_count, aim):
    """Next radius inside the bracket (lo, hi), or None once it has collapsed.

    Counts fall roughly like a power of r: interpolate log count linearly in
    log r between the bracket ends, or assume count ~ r**-2 when one end is
    open; fall back to bisection when the step lands outside the bracket.
    """
    if math.isfinite(hi) and hi - lo <= 1e-12 * hi:
        return None
    if lo > 0 and math.isfinite(hi) and hi_count > 0:
        t = math.log(lo_count / aim) / math.log(lo_count / hi_count)
        radius = lo * (hi / lo) ** t
    elif lo > 0:
        radius = lo * math.sqrt(lo_count / aim)
    else:
        radius = hi * math.sqrt(max(hi_count, 1) / aim)
    if not lo < radius < hi:
        radius = 2.0 * lo if not math.isfinite(hi) else 0.5 * (lo + hi)
    if radius == lo:
        return None
    return radius
