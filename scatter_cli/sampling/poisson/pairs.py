"""Pairs of points closer than a radius, found through a uniform grid (3D, Euclidean).

Cell coordinates are packed into int64 keys, sorted with NumPy and looked up with
``searchsorted``; every loop runs over the few cell offsets, never over points. The
compiled kernel ``_cthinning`` (when built) finds the same pairs; ``all_pairs`` takes it.
"""

import numpy as np

from ...core import native

_kernel = native.kernel("_cthinning")  # the one switch: greedy.py and the tests use it too

# Cell keys pack (x, y, z) cell coordinates into 21 bits each of an int64.
# Cells start at 2 so that offsets down to -2 never go negative.
BITS = 21
MAX_CELLS = (1 << BITS) - 8
_OFFSETS_ALL = [(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)]
# Pair search uses cells of side radius / 2: the 5 x 5 columns of cells around a point,
# each a contiguous run of keys in z, cover its ball with fewer wasted candidates than
# 3 x 3 x 3 cells of side radius (docs/poisson.md).
_COLUMNS_HALF = [(dx, dy) for dx in range(-2, 3) for dy in range(-2, 3) if (dx, dy) > (0, 0)]
# At most this many candidates per cell of side radius / 2 take part in the
# pair graph; the others are handled by a coverage query.  Bounds memory on
# clustered or duplicated input (all points inside one radius -> no n**2).
CELL_CAP = 24


def as_points(points):
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {pts.shape}")
    if not np.isfinite(pts).all():
        raise ValueError("points must be finite")
    return pts


class Frame:
    """A grid over a bounding box: cell side >= ``size``, widened if needed so
    that every axis has fewer than 2**21 cells (keys stay unique, no wrap)."""

    def __init__(self, lo, hi, size):
        extent = float(np.max(hi - lo)) if lo.size else 0.0
        self.size = max(size, extent / (MAX_CELLS - 8), np.finfo(float).tiny)
        self.lo = lo

    def keys(self, points):
        """(n,) int64 cell keys of points (n, 3) float64."""
        c = np.floor((points - self.lo) / self.size).astype(np.int64) + 2
        np.clip(c, 0, MAX_CELLS, out=c)
        return (c[:, 0] << (2 * BITS)) | (c[:, 1] << BITS) | c[:, 2]


def _offset_key(dx, dy, dz):
    return (dx << (2 * BITS)) + (dy << BITS) + dz


def cell_side(reach, parts):
    """The side of grid cells for finding pairs closer than ``reach`` within ``parts``
    cells: a hair over reach / parts, so that rounding in the cell coordinates (at most
    2**-30 of a cell) cannot put such a pair ``parts + 1`` cells apart."""
    return reach / parts * (1.0 + 1e-7)


def frame_for(size, *arrays):
    pts = [a for a in arrays if a.shape[0]]
    if not pts:
        return Frame(np.zeros(3), np.zeros(3), size)
    lo = np.min([bounding_box(a)[0] for a in pts], axis=0)
    hi = np.max([bounding_box(a)[1] for a in pts], axis=0)
    return Frame(lo, hi, size)


def bounding_box(a):
    """(lo, hi): (3,) minimum and maximum of each column of ``a`` (n, 3), one column at a
    time (20 times faster than ``a.min(axis=0)``)."""
    return np.array([a[:, k].min() for k in range(3)]), np.array([a[:, k].max() for k in range(3)])


class Grid:
    """Points bucketed by cell: ``order`` sorts points by key, cell ``c`` holds
    ``order[start[c]:start[c] + count[c]]``; ``ukeys`` (cells,) sorted int64."""

    def __init__(self, points, frame):
        keys = frame.keys(points)
        self.order = np.argsort(keys, kind="stable")
        self.sorted_keys = sk = keys[self.order]
        first = np.ones(sk.size, dtype=bool)
        first[1:] = sk[1:] != sk[:-1]
        self.start = np.flatnonzero(first)
        self.count = np.diff(np.append(self.start, sk.size))
        self.ukeys = sk[self.start]
        # cell index of each sorted point
        self.cell_of_sorted = np.cumsum(first) - 1

    def find(self, keys):
        """Cell index (m,) int64 for each int64 key, -1 where the cell is empty."""
        if self.ukeys.size == 0:
            return np.full(keys.shape, -1, dtype=np.int64)
        pos = np.searchsorted(self.ukeys, keys)
        pos = np.minimum(pos, self.ukeys.size - 1)
        return np.where(self.ukeys[pos] == keys, pos, -1)


def _expand(rows, first, counts):
    """For each r, emit (rows[r], first[r] + t) for t < counts[r]; returns two (m,) arrays."""
    counts = np.maximum(counts, 0)
    total = int(counts.sum())
    a = np.repeat(rows, counts)
    shift = np.repeat(first - (np.cumsum(counts) - counts), counts)
    return a, np.arange(total, dtype=a.dtype) + shift


def index_dtype(n):
    return np.int32 if n < (1 << 31) - 1 else np.int64


def self_pairs(points, radius, grid=None):
    """All pairs closer than ``radius``: (i, j, d), i < j in input numbering.

    i, j (m,) int32 (int64 beyond 2**31 points); d (m,) float64.  ``grid``
    may pass in ``Grid(points, frame_for(cell_side(radius, 2), points))`` if already built.
    """
    n = points.shape[0]
    itype = index_dtype(n)
    if n < 2:
        empty = np.empty(0, dtype=itype)
        return empty, empty, np.empty(0)
    if grid is None:
        grid = Grid(points, frame_for(cell_side(radius, 2), points))
    # one contiguous array per axis: 1-D gathers are much cheaper than row gathers
    x, y, z = (np.ascontiguousarray(points[grid.order, k]) for k in range(3))
    cell = grid.cell_of_sorted
    uk = grid.ukeys
    # point ranges per cell, looked up once per cell rather than per point
    bounds = np.append(grid.start, n).astype(itype)
    rows = np.arange(n, dtype=itype)
    r2 = radius * radius
    ii, jj, dd = [], [], []
    for dx, dy in [(0, 0)] + _COLUMNS_HALF:
        base = uk + _offset_key(dx, dy, 0)
        last = bounds[np.searchsorted(uk, base + 2, side="right")][cell]
        if (dx, dy) == (0, 0):
            first = rows + 1  # later points of the own column only
        else:
            first = bounds[np.searchsorted(uk, base - 2, side="left")][cell]
        a, b = _expand(rows, first, last - first)
        d2 = (x[a] - x[b]) ** 2
        d2 += (y[a] - y[b]) ** 2
        d2 += (z[a] - z[b]) ** 2
        keep = d2 < r2
        ii.append(a[keep])
        jj.append(b[keep])
        dd.append(np.sqrt(d2[keep]))
    order = grid.order.astype(itype)
    a = order[np.concatenate(ii)]
    b = order[np.concatenate(jj)]
    return np.minimum(a, b), np.maximum(a, b), np.concatenate(dd)


def cross_pairs(query, ref, radius):
    """Pairs (q, r, d) with |query[q] - ref[r]| < radius; (m,) int64, int64, float64."""
    empty = np.empty(0, dtype=np.int64)
    if query.shape[0] == 0 or ref.shape[0] == 0:
        return empty, empty, np.empty(0)
    frame = frame_for(cell_side(radius, 1), query, ref)
    grid = Grid(ref, frame)
    qkeys = frame.keys(query)
    qq, rr, dd = [], [], []
    for off in _OFFSETS_ALL:
        target = grid.find(qkeys + _offset_key(*off))
        rows = np.flatnonzero(target >= 0)
        tc = target[rows]
        a, b = _expand(rows, grid.start[tc], grid.count[tc])
        b = grid.order[b]
        diff = query[a] - ref[b]
        d2 = np.einsum("ij,ij->i", diff, diff)
        keep = d2 < radius * radius
        qq.append(a[keep])
        rr.append(b[keep])
        dd.append(np.sqrt(d2[keep]))
    return np.concatenate(qq), np.concatenate(rr), np.concatenate(dd)


def capped_mask(points, radius, grid=None):
    """Bool (n,) mask: the first ``CELL_CAP`` points (input order) of each cell of side radius/2."""
    if grid is None:
        grid = Grid(points, frame_for(cell_side(radius, 2), points))
    rank = np.arange(points.shape[0]) - grid.start[grid.cell_of_sorted]
    mask = np.empty(points.shape[0], dtype=bool)
    mask[grid.order] = rank < CELL_CAP
    return mask


def all_pairs(points, radius):
    """All pairs closer than ``radius``: (i, j, d), i < j, as self_pairs (the kernel's
    search when it is built)."""
    if _kernel is None:
        return self_pairs(points, radius)
    frame = frame_for(cell_side(radius, 2), points)
    grid = _kernel.grid(points, frame.lo.astype(np.float64), float(frame.size), 0)[1:]
    i, j, d = _kernel.pairs(*grid, radius)
    itype = index_dtype(points.shape[0])
    return i.astype(itype), j.astype(itype), d
