"""Exact closest points on a triangle surface, through a bounding-volume hierarchy.

``TriangleTree`` holds world-space triangles in float64 and a tree of boxes over them;
``closest_points(tree, points)`` gives each point's distance to the surface, its closest
surface point and the face that point lies on. The answer is a pure function of the
triangles and the point: the face whose computed squared distance is the least, ties
going to the lowest face index. The tree only decides which faces need not be looked
at: a box is skipped when it is farther than the best distance so far by more than a
bound on the rounding of the distances, so no tree, chunking or thread count changes a
byte.

The point-triangle distance is Ericson's region method (Real-Time Collision Detection,
5.1.5): the closest point is a vertex, a point of an edge or of the interior, each always
on the triangle; where rounding puts a point in no region (slivers, overflow) the closest
of the three edges is taken.

The tree: a complete binary tree over leaves of ``LEAF`` faces (the leaf count rounded
up to a power of two, the extra leaves empty), node i's children 2i+1 and 2i+2; each
node's faces split across the longest side of their box centres' box (median_order).
Queries follow one Morton curve through all the points of a call (in chunks of CHUNK),
every query's walk starting bounded by the previous one's answer. Scenes are
concatenated triangles: instances are copied, not shared.

The compiled kernel ``_cvolume`` does the same float64 operations in the same order
(tests/test_distance.py holds both paths to the same bytes) and builds the same tree;
``SCATTER_NUMPY=1`` runs the NumPy code, a level-by-level walk of the tree for blocks of
points (some hundred times slower).
"""

from __future__ import annotations

import threading

import numpy as np

from ..core import native

_kernel = native.kernel("_cvolume")

LEAF = 8
# Points up to this many times the surface's largest coordinate keep every product in
# the distance (fourth powers of coordinates) finite.
LIMIT = 1e60
# Boxes within this much (times the largest coordinate) of the best distance are looked
# into: far more than the rounding of a distance or a box distance.
SLACK = 1e-12
# Points per call of the kernel (the working memory of a call grows with it), and per
# block on the NumPy path.
CHUNK = 1 << 16
BLOCK = 2048
# A triangle is thin when its least height is under this share of its longest side.
THIN = 0.1


class TriangleTree:
    """Triangles (faces of ``vertices``) and a tree of boxes over them.

    ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64 (F >= 1, indices in 0..V-1).
    ``TriangleTree.from_triangles(triangles (F, 3, 3))`` takes a triangle soup. Face i of
    the answers is row i of ``faces``. Raises ValueError on bad shapes, indices out of
    range, and non-finite coordinates. The triangles are kept scaled by a power of two
    (``unit``, exact) to coordinates of at most 1, so that no scale over- or underflows.
    """

    def __init__(self, vertices, faces):
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError("vertices: not (V, 3)")
        if faces.ndim != 2 or faces.shape[1] != 3 or not np.issubdtype(faces.dtype, np.integer):
            raise ValueError("faces: not (F, 3) integers")
        if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
            raise ValueError("faces: vertex index out of range")
        self._build(vertices[faces.astype(np.int64)])

    @classmethod
    def from_triangles(cls, triangles):
        """The tree of a triangle soup ``triangles`` (F, 3, 3)."""
        triangles = np.asarray(triangles, dtype=np.float64)
        if triangles.ndim != 3 or triangles.shape[1:] != (3, 3):
            raise ValueError("triangles: not (F, 3, 3)")
        tree = cls.__new__(cls)
        tree._build(triangles)
        return tree

    def _build(self, tri):
        if len(tri) == 0:
            raise ValueError("no faces")
        if not np.isfinite(tri).all():
            raise ValueError("triangles: coordinates must be finite")
        # the triangles scaled by a power of two (exactly) to coordinates of at most 1
        self.unit = 2.0 ** -int(np.frexp(max(-tri.min(), tri.max()))[1])
        tri = tri * self.unit
        self.order = median_order(tri, LEAF)
        self.triangles = np.take(tri.reshape(-1, 9), self.order, axis=0)  # (whole rows: faster than tri[order])
        self.thin = thin_faces(self.triangles)
        self.lo, self.hi = node_boxes(self.triangles, LEAF)
        self.leaf = LEAF
        self.scale = float(max(-tri.min(), tri.max()))
        self._wide = None

    _making = threading.Lock()  # one wide tree made, however many chunk threads ask for it at once

    def wide(self):
        """The kernel's own form of the tree (made at the first query, not pickled), or None
        without the kernel."""
        if self._wide is None and _kernel is not None:
            with self._making:
                if self._wide is None:
                    self._wide = _kernel.wide(self.triangles, self.order, self.thin, self.lo, self.hi, self.leaf)
        return self._wide

    def __getstate__(self):
        return {**self.__dict__, "_wide": None}

    @property
    def face_count(self):
        return len(self.order)


def thin_faces(tri):
    """(F,) uint8: whether each triangle of ``tri`` (F, 9) is thin: its least height under
    THIN times its longest side (then Ericson's regions may be confused by rounding, and
    its three edges are tried too)."""
    if _kernel is not None:
        return _kernel.thin(tri)
    a, b, c = tri[:, 0:3], tri[:, 3:6], tri[:, 6:9]
    ab, ac, bc = b - a, c - a, c - b
    n = np.cross(ab, ac)
    longest = np.maximum(np.maximum(_dot(ab, ab), _dot(ac, ac)), _dot(bc, bc))
    return np.ascontiguousarray(_dot(n, n) <= THIN * THIN * longest * longest).view(np.uint8)


def leaf_count(nf, leaf):
    """the leaves of a tree over nf faces: the least power of two holding them"""
    leaves = 1
    while leaves * leaf < nf:
        leaves *= 2
    return leaves


def median_order(tri, leaf):
    """(F,) int64: the faces in tree order. Node by node from the root, the faces of a
    node are split across the longest side of their centres' box: the first child takes
    its share of leaves' worth of faces with the least centre along that side (ties by
    face index). Each leaf's faces in index order."""
    nf = len(tri)
    leaves = leaf_count(nf, leaf)
    if _kernel is not None:
        return _kernel.order(np.ascontiguousarray(tri.reshape(nf, 9)), leaf, leaves)
    lo = np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2])  # (not tri.min(axis=1): a slow reduction)
    hi = np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2])
    centre = lo * 0.5 + hi * 0.5
    order = np.arange(nf)
    size = leaves * leaf
    while size > leaf:
        c = centre[order]
        seg = np.arange(nf) // size
        starts = np.arange(0, nf, size)
        span = np.maximum.reduceat(c, starts) - np.minimum.reduceat(c, starts)
        axis = span.argmax(axis=1)
        order = order[np.lexsort((order, c[np.arange(nf), axis[seg]], seg))]
        size //= 2
    return order[np.lexsort((order, np.arange(nf) // leaf))]


def visit_order(points):
    """(n,) int64: ``points`` (n, 3) along a Morton curve (ties by index), so that each
    query starts from a near one's answer. It changes the time, not the answer."""
    if _kernel is not None:
        return _kernel.visit(points)
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    c0, c1 = points.min(axis=0), points.max(axis=0)
    span = np.where(c1 > c0, c1 - c0, 1.0)
    cells = np.clip(((points - c0) / span * 1024.0).astype(np.int64), 0, 1023).astype(np.uint64)
    code = (spread_bits(cells[:, 0]) << np.uint64(2)) | (spread_bits(cells[:, 1]) << np.uint64(1)) | spread_bits(cells[:, 2])
    return np.argsort(code, kind="stable").astype(np.int64)


def spread_bits(x):
    """(n,) uint64 < 2^21 -> the same bits, two zero bits after each."""
    for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
        x = (x | (x << np.uint64(shift))) & np.uint64(mask)
    return x


def node_boxes(tri, leaf):
    """(N, 3), (N, 3) float64: the boxes of the complete tree over ``tri`` (F, 9) in leaves
    of ``leaf`` faces, N = 2 L - 1 for L leaves (a power of two); empty: lo +inf, hi -inf."""
    nf = len(tri)
    leaves = leaf_count(nf, leaf)
    if _kernel is not None:
        return _kernel.boxes(tri, leaf, leaves)
    pts = np.full((leaves * leaf * 3, 3), np.inf)
    pts[: 3 * nf] = tri.reshape(-1, 3)
    lo = _rows_min(pts.reshape(leaves, 3 * leaf, 3))
    pts[3 * nf:] = -np.inf
    hi = _rows_max(pts.reshape(leaves, 3 * leaf, 3))
    los, his = [lo], [hi]
    while len(lo) > 1:
        lo, hi = np.minimum(lo[0::2], lo[1::2]), np.maximum(hi[0::2], hi[1::2])
        los.append(lo)
        his.append(hi)
    return np.ascontiguousarray(np.concatenate(los[::-1])), np.ascontiguousarray(np.concatenate(his[::-1]))


def _rows_min(a):
    """a (m, k, 3) -> (m, 3) least over k, one row at a time (faster than a.min(axis=1))"""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        np.minimum(out, a[:, j], out=out)
    return out


def _rows_max(a):
    """a (m, k, 3) -> (m, 3) greatest over k"""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        np.maximum(out, a[:, j], out=out)
    return out


def check_points(tree, points):
    """``points`` in the tree's unit: (n, 3) float64, C order; ValueError unless they
    are finite and within LIMIT times the tree's largest coordinate."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError("points: not (n, 3)")
    points = np.ascontiguousarray(points * tree.unit)
    if len(points) and (not np.isfinite(points).all() or np.abs(points).max() > LIMIT):
        raise ValueError(f"points: coordinates must be finite and within {LIMIT:g} times the surface's")
    return points


def tolerance(tree, points):
    """The slack of the tree walk for ``points``: SLACK times the largest coordinate."""
    return SLACK * max(tree.scale, float(np.abs(points).max()) if len(points) else 0.0)


def closest_points(tree, points):
    """Distance (n,) float64, closest point (n, 3) float64 and its face (n,) int64 of
    ``points`` (n, 3) float64 on the surface of ``tree``."""
    points = check_points(tree, points)
    n = len(points)
    dist, closest, face = np.empty(n), np.empty((n, 3)), np.empty(n, dtype=np.int64)
    tol = tolerance(tree, points)
    if _kernel is not None:
        # one Morton curve through all the points, walked CHUNK points at a time (gathered in
        # its order): the denser the points, the more each walk shares with the one before
        visit = visit_order(points)
        for i in range(0, n, CHUNK):
            rows = visit[i:i + CHUNK]
            m = len(rows)
            part_dist, part_closest, part_face = np.empty(m), np.empty((m, 3)), np.empty(m, dtype=np.int64)
            _kernel.closest(tree.triangles, tree.order, tree.thin, tree.lo, tree.hi, tree.leaf,
                            np.take(points, rows, axis=0), np.arange(m), tol, part_dist, part_closest, part_face,
                            native.worker_count(), tree.wide())
            dist[rows], face[rows] = part_dist, part_face
            _whole_rows(closest)[rows] = _whole_rows(part_closest)
    else:
        for i in range(0, n, BLOCK):
            dist[i:i + BLOCK], closest[i:i + BLOCK], face[i:i + BLOCK] = _closest_numpy(tree, points[i:i + BLOCK], tol)
    return dist / tree.unit, closest / tree.unit, face


def _whole_rows(a):
    """(n,) view of the rows of ``a`` (n, k) C-contiguous, each one item: NumPy moves a
    row in one copy where fancy indexing of ``a`` itself goes element by element."""
    return a.view(np.dtype((np.void, a.strides[0]))).reshape(len(a))


def _dot(u, v):
    return u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1] + u[:, 2] * v[:, 2]


def _segment(a, u, p):
    """closest points (m, 3) of segments a + s u to p, and their squared distances (m,)"""
    uu = _dot(u, u)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(uu > 0, _dot(p - a, u) / np.where(uu > 0, uu, 1.0), 0.0)
    s = np.where(s < 0, 0.0, np.where(s > 1, 1.0, s))
    q = a + s[:, None] * u
    d = p - q
    return q, _dot(d, d)


def closest_on(tri, thin, p):
    """Closest points (m, 3) of triangles ``tri`` (m, 9), thin or not (m,), to points
    ``p`` (m, 3), and the squared distances (m,) (+inf where NaN): the kernel's
    closest_on, pair by pair."""
    a, b, c = tri[:, 0:3], tri[:, 3:6], tri[:, 6:9]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp = p - b
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    cp, bc = p - c, c - b
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        vc, vb, va = d1 * d4 - d3 * d2, d5 * d2 - d1 * d6, d3 * d6 - d5 * d4
        den_ab, den_ac = d1 - d3, d2 - d6
        e = d4 - d3
        den_bc = e + (d5 - d6)
        den = va + vb + vc
        regions = [
            (d1 <= 0) & (d2 <= 0),
            (d3 >= 0) & (d4 <= d3),
            (vc <= 0) & (d1 >= 0) & (d3 <= 0),
            (d6 >= 0) & (d5 <= d6),
            (vb <= 0) & (d2 >= 0) & (d6 <= 0),
            (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
            (va >= 0) & (vb >= 0) & (vc >= 0) & (den > 0),
        ]
        which = np.select(regions, np.arange(7), 7)
        q = np.empty_like(p)
        for r, fill in enumerate((
            lambda m: a[m],
            lambda m: b[m],
            lambda m: a[m] + _ratio(d1[m], den_ab[m])[:, None] * ab[m],
            lambda m: c[m],
            lambda m: a[m] + _ratio(d2[m], den_ac[m])[:, None] * ac[m],
            lambda m: b[m] + _ratio(e[m], den_bc[m])[:, None] * bc[m],
            lambda m: a[m] + ab[m] * (vb[m] / den[m])[:, None] + ac[m] * (vc[m] / den[m])[:, None],
            lambda m: _edges(a[m], b[m], ab[m], bc[m], ac[m], p[m]),
        )):
            m = which == r
            if m.any():
                q[m] = fill(m)
        d = p - q
        dd = _dot(d, d)
        t = thin.astype(bool)
        if t.any():
            for start, u in ((a, ab), (b, bc), (a, ac)):
                r, de = _segment(start[t], u[t], p[t])
                m = de < dd[t]
                rows = np.flatnonzero(t)[m]
                q[rows], dd[rows] = r[m], de[m]
    return q, np.where(np.isnan(dd), np.inf, dd)


def _ratio(num, den):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den != 0, num / np.where(den != 0, den, 1.0), 0.0)


def _edges(a, b, ab, bc, ac, p):
    """the closest of the three edges' closest points (ties: AB, BC, CA)"""
    q, best = _segment(a, ab, p)
    for start, u in ((b, bc), (a, ac)):
        r, d = _segment(start, u, p)
        m = d < best
        q[m], best[m] = r[m], d[m]
    return q


def _box_d2(lo, hi, p):
    """squared distances (m,) of points p (m, 3) to boxes lo, hi (m, 3): the kernel's box_d2"""
    with np.errstate(invalid="ignore"):
        g = np.maximum(lo - p, p - hi)
    g = np.where(g > 0, g, 0.0)
    return g[:, 0] * g[:, 0] + g[:, 1] * g[:, 1] + g[:, 2] * g[:, 2]


def _box_far2(lo, hi, p):
    """squared distances (m,) of points p to the farthest corner of their boxes"""
    g = np.maximum(np.abs(p - lo), np.abs(hi - p))
    return g[:, 0] * g[:, 0] + g[:, 1] * g[:, 1] + g[:, 2] * g[:, 2]


def _greedy_bound(tree, points):
    """(n,) squared distances of points to some face: the faces of the leaf reached by
    always taking the nearer child (a bound on the least distance that prunes early)."""
    leaves = (len(tree.lo) + 1) // 2
    node = np.zeros(len(points), dtype=np.int64)
    while len(node) and node[0] < leaves - 1:
        left = 2 * node + 1
        nearer = _box_d2(tree.lo[left], tree.hi[left], points) <= _box_d2(tree.lo[left + 1], tree.hi[left + 1], points)
        node = np.where(nearer, left, left + 1)
    slot = ((node - (leaves - 1)) * tree.leaf)[:, None] + np.arange(tree.leaf)
    rows = np.repeat(np.arange(len(points)), tree.leaf)
    slot = slot.ravel()
    keep = slot < tree.face_count
    rows, slot = rows[keep], slot[keep]
    seed = np.full(len(points), np.inf)
    np.minimum.at(seed, rows, closest_on(tree.triangles[slot], tree.thin[slot], points[rows])[1])
    return seed


def _closest_numpy(tree, points, tol):
    """closest_points for one block, level by level: (point, node) pairs whose box may hold
    a face within the least farthest-corner distance of the point's boxes (plus tol)."""
    n = len(points)
    seed = _greedy_bound(tree, points)
    query, node = np.arange(n), np.zeros(n, dtype=np.int64)
    leaves = (len(tree.lo) + 1) // 2
    while node.size and node[0] < leaves - 1:
        query, node = np.repeat(query, 2), (2 * np.repeat(node, 2) + 1) + np.tile([0, 1], len(node))
        p, lo, hi = points[query], tree.lo[node], tree.hi[node]
        near, far = _box_d2(lo, hi, p), _box_far2(lo, hi, p)
        starts = np.flatnonzero(np.r_[True, query[1:] != query[:-1]])
        reach = np.sqrt(np.minimum(np.minimum.reduceat(far, starts), seed[query[starts]])) + tol
        keep = near <= np.repeat(reach * reach, np.diff(np.r_[starts, len(query)]))
        query, node = query[keep], node[keep]
    slot = ((node - (leaves - 1)) * tree.leaf)[:, None] + np.arange(tree.leaf)
    query = np.repeat(query, tree.leaf)
    slot = slot.ravel()
    keep = slot < tree.face_count
    query, slot = query[keep], slot[keep]
    q, d2 = closest_on(tree.triangles[slot], tree.thin[slot], points[query])
    face = tree.order[slot]
    first = np.lexsort((face, d2, query))
    head = first[np.r_[True, query[first][1:] != query[first][:-1]]]
    return np.sqrt(d2[head]), q[head], face[head]
