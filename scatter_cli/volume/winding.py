"""Generalized winding numbers of a triangle surface at points, fast.

The winding number of a surface at a point q (Jacobson et al. 2013) is the sum over its
triangles of their signed solid angles seen from q, over 4 pi: 1 inside a closed
outward-oriented surface, 0 outside, 2 inside two nested shells, and a smooth value in
between near the holes of an open one. ``w >= 0.5`` is the inside test of ``--sign
winding``.

It is evaluated as Barill et al. 2018 ("Fast winding numbers for soups and clouds") do:
a tree over the triangles holds, for each node, the Taylor expansion (orders 0, 1 and 2)
of its triangles' solid angles about the node's area-weighted centre. A node farther
from q than ``accuracy`` times its radius adds its expansion; a nearer one opens, down
to the leaves, whose triangles add their exact solid angle (van Oosterom and Strackee's
formula). The tree splits the triangles along the Morton order of their centroids, at
the highest bit where a node's first and last codes differ (Karras 2012).

The sum at a point is the same float64 sum whatever the threads or chunks: its terms
are the nodes' and triangles' terms in the tree's preorder (a leaf's triangles in tree
order), added one by one from 0. The compiled kernel ``_cwinding`` walks the tree
depth-first in that order; the NumPy path below walks all points of a chunk down the
tree in step, adding each point's next term in the same order, and does the same
float64 operations (its own arctangent, as the kernel's, from + - * / only), so the two
give the same bytes (tests/test_winding.py holds them to it). The kernel also computes
the tree's per-triangle moments, their sums over each node, the nodes' expansions and
radii, the same values as the NumPy functions named.
"""

from __future__ import annotations

import numpy as np

from ..core import native
from ..core.elementary import atan2

_kernel = native.kernel("_cwinding")

LEAF = 8  # triangles at most in a leaf
ACCURACY = 2.0  # a node is far when farther than this times its radius (Barill's beta)
ORDER = 2  # terms of the far-field expansion: 0 (dipole), 1, 2
CHUNK = 1 << 18  # points per call of the kernel (larger: nearer neighbours walk together)
NUMPY_CHUNK = 1 << 16  # points per step of the NumPy path, at most CHUNK
FIELDS = 28  # float64 fields of a node, see _node_fields

INV2PI = 0.15915494309189535  # 1 / (2 pi), as in _cwinding.c
INV4PI = 0.07957747154594767  # 1 / (4 pi)


class WindingTree:
    """The tree of a triangle surface for :func:`winding_numbers`.

    ``WindingTree(vertices (V, 3) float64, faces (F, 3) int64)``, or
    ``WindingTree(triangles (F, 3, 3) float64)`` (world-space triangles: the instances of
    a scene concatenated). Triangles with a non-finite coordinate or zero area add
    nothing to a winding number and are left out.

    Attributes: ``triangles`` (T, 9) float64 in tree order, ``face`` (T,) int64 their
    input indices, ``nodes`` (N, FIELDS) float64 and ``links`` (N, 3) int64 (the index
    after the node's subtree, its first triangle, its triangle count: 0 for an inner
    node), in preorder.
    """

    def __init__(self, vertices, faces=None):
        v = np.asarray(vertices, dtype=np.float64)
        tri = v.reshape(-1, 3, 3) if faces is None else np.take(v, np.asarray(faces, dtype=np.int64), axis=0)
        an, centroid = _faces(tri)
        keep = (an[:, 0] != 0) | (an[:, 1] != 0) | (an[:, 2] != 0)
        if not (np.isfinite(tri).all() and np.isfinite(an).all()):  # (row by row only when needed: slower)
            keep &= np.isfinite(tri).all(axis=(1, 2)) & np.isfinite(an).all(axis=1)
        self.face = np.flatnonzero(keep)
        if len(self.face) < len(tri):
            tri, an, centroid = (np.compress(keep, a, axis=0) for a in (tri, an, centroid))
        codes = _morton(centroid)
        order = _stable_order(codes)
        self.face, tri, an, centroid = (np.take(a, order, axis=0) for a in (self.face, tri, an, centroid))
        self.triangles = np.ascontiguousarray(tri.reshape(-1, 9))
        start, end, skip = _layout(codes[order], LEAF)
        self.links = np.stack([skip, start, np.where(skip == np.arange(len(skip)) + 1, end - start, 0)], axis=1)
        self.nodes = _node_fields(tri, an, centroid, start, end, skip)

    def __len__(self):
        return len(self.triangles)


def winding_numbers(tree: WindingTree, points, *, accuracy: float = ACCURACY, order: int = ORDER) -> np.ndarray:
    """(n,) float64 winding numbers of ``tree``'s surface at ``points`` (n, 3) float64.

    ``accuracy``: a node is summed by its expansion of order ``order`` (0, 1 or 2) when
    the point is farther than ``accuracy`` times the node's radius (larger: slower and
    closer to exact; ``math.inf``: every triangle's exact solid angle). A point with a
    non-finite coordinate gets NaN. The result is a pure
    function of the inputs, whatever the threads or chunks."""
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if order not in (0, 1, 2) or not accuracy > 0:
        raise ValueError("winding_numbers: order is 0, 1 or 2 and accuracy positive")
    out = np.zeros(len(points))
    if _kernel is not None:  # (it walks the points in an order of its own)
        for at in range(0, len(points), CHUNK):
            _kernel.winding(points[at:at + CHUNK], tree.nodes, tree.links, tree.triangles, float(accuracy),
                            int(order), native.worker_count(), out[at:at + CHUNK])
        return out
    step = min(CHUNK, NUMPY_CHUNK)
    for at in range(0, len(points), step):
        # in Morton order: neighbouring points walk the same nodes (the sums do not change)
        near = at + _stable_order(_morton(points[at:at + step]))
        out[near] = _numpy_winding(points[near], tree, float(accuracy), int(order))
    return out


# ---- the tree ----

def _spread(x):
    """(n,) uint64 with the low 21 bits of ``x`` spread to every third bit."""
    x = x & np.uint64(0x1FFFFF)
    for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
        x = (x | (x << np.uint64(shift))) & np.uint64(mask)
    return x


def _morton(p):
    """(n,) uint64 Morton codes of ``p`` (n, 3) float64 on a 2^21 grid over the box of
    its finite rows (the others: 0). The kernel's ``morton`` computes the same codes."""
    if _kernel is not None:
        return _kernel.morton(np.ascontiguousarray(p, dtype=np.float64))
    finite = np.isfinite(p).all(axis=1)
    if not finite.any():
        return np.zeros(len(p), np.uint64)
    lo, hi = p[finite].min(axis=0), p[finite].max(axis=0)
    with np.errstate(all="ignore"):
        rel = (np.where(finite[:, None], p, lo) - lo) / (hi - lo)
    q = (np.nan_to_num(np.clip(rel, 0.0, 1.0), nan=0.0) * (2.0**21 - 1)).astype(np.uint64)
    return (_spread(q[:, 0]) << np.uint64(2)) | (_spread(q[:, 1]) << np.uint64(1)) | _spread(q[:, 2])


def _stable_order(codes):
    """(n,) int64: np.argsort(codes, kind="stable") of ``codes`` (n,) uint64 (Morton codes,
    below 2^63), by the kernel's radix sort when built."""
    if _kernel is not None:
        return _kernel.order(codes)
    return np.argsort(codes, kind="stable")


def _top_bit(x):
    """(n,) uint64 index of the highest set bit of each ``x`` (n,) uint64 > 0."""
    b = np.zeros(len(x), np.uint64)
    for shift in (32, 16, 8, 4, 2, 1):
        b += np.where((x >> (b + np.uint64(shift))) != 0, np.uint64(shift), np.uint64(0))
    return b


def _layout(codes, leaf):
    """The nodes over triangles sorted by ``codes`` (T,) uint64, in preorder: (start,
    end, skip) (N,) int64 each, a node's triangles start..end-1, skip the index after
    its subtree. A node of more than ``leaf`` triangles splits where the highest
    differing bit of its codes turns on (in the middle when all codes are equal). The
    kernel's ``layout`` makes the same nodes."""
    if _kernel is not None:
        return _kernel.layout(codes, leaf)
    if not len(codes):
        return (np.zeros(0, np.int64),) * 3
    levels = []  # per depth: start, end, index of the left child in the next depth (-1: leaf)
    s, e = np.array([0]), np.array([len(codes)])
    while len(s):
        inner = e - s > leaf
        si, ei = s[inner], e[inner]
        first, last = codes[si], codes[ei - 1]
        diff = first ^ last
        equal = diff == 0
        top = _top_bit(np.where(equal, np.uint64(1), diff))
        m = np.searchsorted(codes, (last >> top) << top)
        m = np.where(equal, (si + ei) // 2, m)
        child = np.full(len(s), -1)
        child[inner] = 2 * np.arange(len(si))
        levels.append((s, e, child))
        s = np.stack([si, m], axis=1).ravel()
        e = np.stack([m, ei], axis=1).ravel()
    size = np.zeros(0, np.int64)  # subtree sizes, bottom-up
    sizes = []
    for s, e, child in reversed(levels):
        inner = child >= 0
        n = np.ones(len(s), np.int64)
        n[inner] += size[child[inner]] + size[child[inner] + 1]
        sizes.append(n)
        size = n
    sizes.reverse()
    starts, ends, skips, ids = [], [], [], []
    pre = np.array([0])
    for (s, e, child), n in zip(levels, sizes):
        starts.append(s), ends.append(e), skips.append(pre + n), ids.append(pre)
        inner = child >= 0
        pre = np.empty(2 * inner.sum(), np.int64)
        if len(pre):  # left child just after its parent, right child after the left's subtree
            pre[0::2] = ids[-1][inner] + 1
            pre[1::2] = ids[-1][inner] + 1 + sizes[len(ids)][child[inner]]
    ids = np.concatenate(ids)
    start, end, skip = (np.empty(len(ids), np.int64) for _ in range(3))
    start[ids], end[ids], skip[ids] = np.concatenate(starts), np.concatenate(ends), np.concatenate(skips)
    return start, end, skip


def _subtree_sums(rows, start, skip):
    """(N, K) per node: the sums of ``rows`` (K, T) float64 over its triangles, from its
    leaves up. The kernel's ``subtree_sums`` computes the same values."""
    if _kernel is not None:
        out = np.empty((len(skip), len(rows)))
        _kernel.subtree_sums(rows, start, skip, out)
        return out
    leaf = skip == np.arange(len(skip)) + 1
    out = np.zeros((len(skip), len(rows)))
    out[leaf] = np.add.reduceat(rows, start[leaf], axis=1).T
    _up(out, leaf, skip, np.add)
    return out


def _up(out, leaf, skip, join):
    """Fill ``out``'s inner nodes from their children (left: i + 1, right: skip[i + 1]),
    deepest first."""
    inner = np.flatnonzero(~leaf)
    depth = _depths(skip)
    for d in range(depth.max(initial=0), -1, -1):
        k = inner[depth[inner] == d]
        out[k] = join(out[k + 1], out[skip[k + 1]])


def _depths(skip):
    """(N,) int64 depth of each node of a preorder tree given by ``skip``."""
    n = len(skip)
    depth = np.zeros(n, np.int64)
    leaf = skip == np.arange(n) + 1
    frontier = np.array([0]) if n else np.zeros(0, np.int64)
    d = 0
    while len(frontier):
        depth[frontier] = d
        inner = frontier[~leaf[frontier]]
        frontier = np.stack([inner + 1, skip[inner + 1]], axis=1).ravel()
        d += 1
    return depth


PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))  # the components kept of a symmetric 3x3


def _node_fields(tri, an, centroid, start, end, skip):
    """(N, FIELDS) float64 per node: centre (0:3), radius (3), sum of area-weighted
    normals (4:7), the first-order moment's trace (7) and quadratic form's coefficients
    (8:14), the second-order moment's linear (14:17) and cubic form's coefficients
    (17:27). The moments are summed about the middle of the box, then moved to each
    node's centre."""
    n = len(skip)
    if not n:
        return np.zeros((n, FIELDS))
    # (the box of the centroids column by column: a reduction along axis 0 is slow)
    lo, hi = (np.array([reduce(centroid[:, k]) for k in range(3)]) for reduce in (np.min, np.max))
    origin = 0.5 * (lo + hi)
    raw = _moments(tri, an, centroid, origin)
    fields = _expansions(_subtree_sums(raw, start, skip), origin)
    fields[:, 3] = _radii(tri, fields[:, 0:3], start, end, skip)
    return fields


def _expansions(sums, origin):
    """(N, FIELDS) float64: each node's fields but its radius (left 0), from its sums (N,
    34) of _moments's rows about ``origin`` (3,). The kernel's ``expansions`` computes the
    same values."""
    fields = np.zeros((len(sums), FIELDS))
    if _kernel is not None:
        _kernel.expansions(sums, origin, fields)
        return fields
    sums = np.ascontiguousarray(sums.T)  # (34, N): rows, as _moments's
    c = sums[1:4] / sums[0]
    a0, a1 = sums[4:7], sums[7:16].reshape(3, 3, -1)
    m = a1 - a0[:, None, :] * c[None, :, :]
    s = {}  # s[i, j, k] = sum of an_i (x - c)_j (x - c)_k, j <= k
    for k, (j, l) in enumerate(PAIRS):
        for i in range(3):
            s[i, j, l] = s[i, l, j] = (sums[16 + 6 * i + k] - a1[i, j] * c[l] - a1[i, l] * c[j]
                                       + a0[i] * c[j] * c[l])
    fields[:, 0:3] = (c + origin[:, None]).T
    fields[:, 4:7] = a0.T
    fields[:, 7] = m[0, 0] + m[1, 1] + m[2, 2]
    fields[:, 8:14] = np.stack([m[0, 0], m[1, 1], m[2, 2], m[0, 1] + m[1, 0], m[0, 2] + m[2, 0], m[1, 2] + m[2, 1]],
                               axis=1)
    for k in range(3):  # 2 sum_i s_iik + sum_j s_kjj
        fields[:, 14 + k] = 2.0 * (s[0, 0, k] + s[1, 1, k] + s[2, 2, k]) + s[k, 0, 0] + s[k, 1, 1] + s[k, 2, 2]
    x, y, z = 0, 1, 2
    fields[:, 17:27] = np.stack([  # sum_ijk s_ijk r_i r_j r_k by monomial: xxx yyy zzz xxy xxz yyx yyz zzx zzy xyz
        s[x, x, x], s[y, y, y], s[z, z, z], 2 * s[x, x, y] + s[y, x, x], 2 * s[x, x, z] + s[z, x, x],
        2 * s[y, y, x] + s[x, y, y], 2 * s[y, y, z] + s[z, y, y], 2 * s[z, z, x] + s[x, z, z],
        2 * s[z, z, y] + s[y, z, z], 2 * (s[x, y, z] + s[y, x, z] + s[z, x, y])], axis=1)
    return fields


def _moments(tri, an, centroid, origin):
    """(34, T) float64 rows of per-triangle values, summed over each node: area, area times
    the centroid about ``origin`` (3,), area-weighted normal ``an`` (T, 3), its products with
    the centroid, and with the second moments of the triangle ``tri`` (T, 3, 3) about the
    origin. The kernel's ``moments`` computes the same values."""
    raw = np.empty((34, len(tri)))
    if _kernel is not None:
        _kernel.moments(np.ascontiguousarray(tri.reshape(-1, 9)), np.ascontiguousarray(an),
                        np.ascontiguousarray(centroid), np.ascontiguousarray(origin), raw)
        return raw
    p = np.ascontiguousarray((centroid - origin).T)  # (3, T): rows of per-triangle values, summed along them
    u = [np.ascontiguousarray((tri[:, v] - centroid).T) for v in range(3)]  # corners about the centroid
    an_t = np.ascontiguousarray(an.T)
    raw[0] = _norms(an)
    raw[1:4] = raw[0] * p
    raw[4:7] = an_t
    raw[7:16] = (an_t[:, None, :] * p[None, :, :]).reshape(9, -1)
    for k, (i, j) in enumerate(PAIRS):  # E[(x - o)_i (x - o)_j] over the triangle
        second = p[i] * p[j] + (u[0][i] * u[0][j] + u[1][i] * u[1][j] + u[2][i] * u[2][j]) / 12.0
        raw[16 + k:34:6] = an_t * second
    return raw


def _radii(tri, centre, start, end, skip):
    """(N,) float64: at the leaves, the distance from the centre to the farthest corner of
    their triangles; above, a bound of it by the triangles' own spheres (about their
    centroids), one depth at a time (each triangle lies in one node of each depth down to
    its leaf). The kernel's ``radii`` computes the same values."""
    n = len(skip)
    r = np.zeros(n)
    if not n:
        return r
    if _kernel is not None:
        _kernel.radii(np.ascontiguousarray(tri.reshape(-1, 9)), np.ascontiguousarray(centre), start, end, skip, r)
        return r
    depth = _depths(skip)
    leaf = np.flatnonzero(skip == np.arange(n) + 1)
    size = end[leaf] - start[leaf]
    owner = np.repeat(leaf, size)
    corner = tri - centre[owner][:, None, :]
    r[leaf] = np.maximum.reduceat(_norms(corner.reshape(-1, 3)).reshape(-1, 3).max(axis=1), start[leaf])
    g = (tri[:, 0] + tri[:, 1] + tri[:, 2]) / 3.0
    rho = _norms((tri - g[:, None, :]).reshape(-1, 3)).reshape(-1, 3).max(axis=1)
    bottom = np.repeat(depth[leaf], size)  # the depth of each triangle's leaf
    inner = np.flatnonzero(skip != np.arange(n) + 1)
    gx, gy, gz = (np.ascontiguousarray(g[:, k]) for k in range(3))
    cx, cy, cz = (np.ascontiguousarray(centre[:, k]) for k in range(3))
    for d in range(int(depth[inner].max(initial=-1)) + 1):
        k = inner[depth[inner] == d]  # in preorder: their ranges in order, disjoint, covering these triangles
        deeper = bottom > d
        at = slice(None) if deeper.all() else np.flatnonzero(deeper)
        who = np.repeat(k, end[k] - start[k])
        ox, oy, oz = gx[at] - cx[who], gy[at] - cy[who], gz[at] - cz[who]
        far = np.sqrt(ox * ox + oy * oy + oz * oz) + rho[at]
        r[k] = np.maximum.reduceat(far, np.cumsum(end[k] - start[k]) - (end[k] - start[k]))
    r[np.isnan(r)] = np.nan  # (one NaN, whichever the operations made: a NaN radius never makes a node far)
    return r


def _faces(tri):
    """(area normals (T, 3), centroids (T, 3)) float64 of the triangles ``tri`` (T, 3, 3):
    :func:`_area_normals`, and (a + b + c) / 3. The kernel's ``faces`` computes the same
    values."""
    if _kernel is not None:
        return _kernel.faces(np.ascontiguousarray(tri.reshape(-1, 9)))
    return _area_normals(tri), (tri[:, 0] + tri[:, 1] + tri[:, 2]) / 3.0


def _area_normals(tri):
    """(T, 3) float64: half the cross product of the edges from the first corner of each
    triangle of ``tri`` (T, 3, 3), as ``0.5 * np.cross`` computes it, without its slow
    general path."""
    u, v = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    an = np.empty((len(tri), 3))
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        an[:, k] = 0.5 * (u[:, i] * v[:, j] - u[:, j] * v[:, i])
    return an


def _norms(v):
    """(m,) float64 lengths of ``v`` (m, 3): sqrt of x*x + y*y + z*z, added left to right
    (as numpy's sum over a row of three does, without its slow reduction loop)."""
    return np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2])


# ---- the NumPy path: the kernel's float64 operations, in its order ----

def _triangle_terms(tri, q):
    """(m,) float64 solid angles over 2 pi of triangles ``tri`` (m, 9) seen from ``q``
    (m, 3): van Oosterom and Strackee's formula."""
    ax, ay, az = tri[:, 0] - q[:, 0], tri[:, 1] - q[:, 1], tri[:, 2] - q[:, 2]
    bx, by, bz = tri[:, 3] - q[:, 0], tri[:, 4] - q[:, 1], tri[:, 5] - q[:, 2]
    cx, cy, cz = tri[:, 6] - q[:, 0], tri[:, 7] - q[:, 1], tri[:, 8] - q[:, 2]
    la = np.sqrt(ax * ax + ay * ay + az * az)
    lb = np.sqrt(bx * bx + by * by + bz * bz)
    lc = np.sqrt(cx * cx + cy * cy + cz * cz)
    det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
    ab = ax * bx + ay * by + az * bz
    bc = bx * cx + by * cy + bz * cz
    ca = cx * ax + cy * ay + cz * az
    den = la * lb * lc + ab * lc + bc * la + ca * lb
    return atan2(det, den) * INV2PI


def _far_terms(f, r, d2, order):
    """(m,) float64 expansions of nodes with fields ``f`` (m, FIELDS) at offsets ``r``
    (m, 3) (centre - point), ``d2`` (m,) their squared lengths."""
    rx, ry, rz = r[:, 0], r[:, 1], r[:, 2]
    id2 = 1.0 / d2
    id3 = id2 / np.sqrt(d2)
    w = (f[:, 4] * rx + f[:, 5] * ry + f[:, 6] * rz) * id3
    if order >= 1:
        quad = (f[:, 8] * rx + f[:, 11] * ry + f[:, 12] * rz) * rx + (f[:, 9] * ry + f[:, 13] * rz) * ry + f[:, 10] * rz * rz
        w = w + (f[:, 7] - 3.0 * quad * id2) * id3
    if order >= 2:
        lin = f[:, 14] * rx + f[:, 15] * ry + f[:, 16] * rz
        cub = ((f[:, 17] * rx + f[:, 20] * ry + f[:, 21] * rz) * (rx * rx)
               + (f[:, 18] * ry + f[:, 22] * rx + f[:, 23] * rz) * (ry * ry)
               + (f[:, 19] * rz + f[:, 24] * rx + f[:, 25] * ry) * (rz * rz) + f[:, 26] * rx * ry * rz)
        w = w + (7.5 * cub * id2 - 1.5 * lin) * id2 * id3
    return w * INV4PI


def _numpy_winding(points, tree, beta, order):
    """(n,) float64: winding_numbers for one chunk, all points walking down the tree in
    step (each adds its next term: a far node's expansion, or a leaf's triangles one by
    one), as the kernel walks each point."""
    nodes, links, tri = tree.nodes, tree.links, tree.triangles
    acc = np.zeros(len(points))
    todo = np.arange(len(points)) if len(nodes) else np.zeros(0, np.int64)
    at = np.zeros(len(points), np.int64)
    with np.errstate(all="ignore"):
        while len(todo):
            node = at[todo]
            f = nodes[node]
            r = f[:, 0:3] - points[todo]
            d2 = r[:, 0] * r[:, 0] + r[:, 1] * r[:, 1] + r[:, 2] * r[:, 2]
            t = beta * f[:, 3]
            far = d2 > t * t
            acc[todo[far]] += _far_terms(f[far], r[far], d2[far], order)
            count = np.where(far, 0, links[node, 2])
            for k in range(int(count.max(initial=0))):
                sel = np.flatnonzero(count > k)
                who = todo[sel]
                acc[who] += _triangle_terms(tri[links[node[sel], 1] + k], points[who])
            at[todo] = np.where(far | (links[node, 2] > 0), links[node, 0], node + 1)
            todo = todo[at[todo] < len(nodes)]
    acc[np.isnan(acc)] = np.nan
    return acc
