"""The least-crowded-first greedy: a maximal Poisson-disk subset of a pair graph.

Candidates are taken from the least crowded first (crowding = sum of
``1 - d / (2 radius)`` over undecided neighbours closer than ``radius``), in rounds that
recount the crowding as points are kept and their neighbours drop out. This packs more
points per radius than random-order dart throwing (figures: docs/poisson.md). The
compiled kernel runs the same greedy with the same result.
"""

import numpy as np

from ...core import native
from . import pairs
from .pairs import CELL_CAP, Grid, capped_mask, cell_side, frame_for, self_pairs

# Crowding weights are rounded to multiples of 1 / CROWD_SCALE: integer sums are
# exact in any order, so the compiled kernel and numpy rank points the same way.
CROWD_SCALE = 65536.0
# Each round takes 1 / ROUND_SHARE of the undecided points (at least ROUND_LEAST): smaller
# shares follow the crowding more closely, in more rounds (figures: docs/poisson.md).
ROUND_SHARE, ROUND_LEAST = 16, 64


def _weights(d, radius):
    """Crowding weights (m,) float64 of edges of length d (m,) < radius: 1 - d / (2 radius)
    in units of 1 / CROWD_SCALE, rounded down (whole numbers)."""
    return np.floor((1.0 - d * (1.0 / (2.0 * radius))) * CROWD_SCALE)


def in_priority_order(n, i, j, priority):
    """Maximal independent set of the graph (i, j), taken greedily in
    ascending ``priority`` (n,) with ties broken by index.

    Computed in parallel rounds: a vertex joins when it precedes every
    undecided neighbour, then its neighbours drop out.  The result equals the
    sequential greedy; each round decides at least one vertex.
    Returns kept (n,) bool.
    """
    rank = np.empty(n, dtype=np.int64)
    rank[np.argsort(priority, kind="stable")] = np.arange(n)
    undecided = np.ones(n, dtype=bool)
    kept = np.zeros(n, dtype=bool)
    for _ in range(n + 1):
        if i.size == 0:
            break
        blocked = np.zeros(n, dtype=bool)
        blocked[np.where(rank[i] < rank[j], j, i)] = True
        join = undecided & ~blocked
        kept |= join
        undecided &= ~join
        undecided[i[join[j]]] = False
        undecided[j[join[i]]] = False
        live = undecided[i] & undecided[j]
        i, j = i[live], j[live]
    return kept | undecided


def least_crowded_first(n, i, j, d, radius):
    """Kept (n,) bool: a maximal Poisson-disk set over the pair graph (edges shorter than
    radius), least crowded candidates first, crowding counted again as the set grows.

    In rounds: the crowding of each undecided point over its undecided neighbours; the
    least crowded share (_round_share of them, ties included) taken greedily in ascending
    crowding, ties by index; their neighbours drop out. Taking sparse spots first packs
    more points per radius than random-order dart throwing, and recounting as points go
    packs more again (docs/poisson.md).
    """
    w = _weights(d, radius)
    undecided = np.ones(n, dtype=bool)
    kept = np.zeros(n, dtype=bool)
    for _ in range(n + 1):
        left = np.flatnonzero(undecided)
        if left.size == 0:
            break
        live = undecided[i] & undecided[j]
        i, j, w = i[live], j[live], w[live]
        crowd = np.bincount(i, w, n) + np.bincount(j, w, n)
        share = _round_share(left.size)
        take = undecided.copy()
        if share < left.size:
            take &= crowd <= np.partition(crowd[left], share - 1)[share - 1]
        inside = take[i] & take[j]
        new = in_priority_order(n, i[inside], j[inside], crowd) & take
        kept |= new
        undecided &= ~take
        undecided[i[new[j]]] = False
        undecided[j[new[i]]] = False
    return kept


def _round_share(left):
    """How many of ``left`` undecided points a round takes (ties may add more)."""
    return max(ROUND_LEAST, -(-left // ROUND_SHARE))


class PairGraph:
    """The pairs closer than ``reach`` among candidates ``points`` (n, 3) float64.

    With ``capped``, only the first CELL_CAP points (input order) of each cell of side
    reach / 2 take part; ``active`` (a,) int64 lists them, ascending. ``kept(radius)``
    is the least-crowded-first greedy over the pairs shorter than radius <= reach.
    """

    def __init__(self, points, reach, capped=True):
        self.reach = reach
        frame = frame_for(cell_side(reach, 2), points)
        if pairs._kernel is not None:
            out = pairs._kernel.grid(points, frame.lo.astype(np.float64), float(frame.size), CELL_CAP if capped else 0)
            self.active, self._grid = out[0], out[1:]
            return
        if capped:
            grid = Grid(points, frame)
            mask = capped_mask(points, reach, grid)
            if not mask.all():
                self.active = np.flatnonzero(mask)
                self._ijd = self_pairs(points[self.active], reach)
                return
        self.active = np.arange(points.shape[0])
        self._ijd = self_pairs(points, reach)

    def kept(self, radius):
        """Indices (k,) into ``active`` of the greedy maximal set at ``radius``."""
        if pairs._kernel is not None:
            kept = np.empty(self.active.size, dtype=bool)
            pairs._kernel.greedy(*self._grid, self.reach, radius, kept, ROUND_SHARE, ROUND_LEAST, native.worker_count())
            return np.flatnonzero(kept)
        i, j, d = self._ijd
        short = d < radius
        return np.flatnonzero(least_crowded_first(self.active.size, i[short], j[short], d[short], radius))
