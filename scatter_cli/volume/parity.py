"""Inside or outside a closed surface by the parity of ray crossings, majority of rays.

``parity_inside(tree, points, rays=3)`` casts ``rays`` rays from each point, in fixed
directions drawn from a fixed seed (none along an axis or a diagonal, so the rays do
not run along the edges of axis-aligned meshes), counts each ray's crossings with the
triangles of ``tree`` (distance.TriangleTree) and calls the point inside when most rays
cross an odd number of times. On a closed surface every ray gives the exact answer; the
majority only guards against rays that run within rounding of an edge's line or along a
face. A point outside the box of the surface is outside, with no ray cast (for an open
surface a ray from there may cross it once).

A crossing is the watertight ray-triangle test of Woop, Benthin and Wald (2013) in
float64: the triangle's vertices, moved to the point and sheared so that the ray runs
along an axis, give three edge functions that two faces sharing an edge compute equal
and opposite. A ray through an edge or a vertex (an edge function exactly 0) counts for
the faces that would contain the point moved by an infinitesimal (eps^2, eps) in the
sheared plane, so it crosses a closed surface there once (or twice where it only
touches it, at a silhouette). A crossing at distance 0 (the point on a face) does not count.

The compiled kernel ``_cvolume`` does the same operations; ``SCATTER_NUMPY=1`` runs the
NumPy code below, a level-by-level walk of the tree for blocks of points.
"""

from __future__ import annotations

import numpy as np

from . import distance
from ..core import native

_kernel = native.kernel("_cvolume")

SEED = 29
# Points per block on the NumPy path.
BLOCK = 1024


def directions(rays):
    """(rays, 3) float64 unit vectors from the fixed seed, each component at least 0.1
    in magnitude and no two within 0.1 in magnitude of each other (not along an axis, a
    face diagonal or a body diagonal)."""
    rng = np.random.default_rng(SEED)
    out = []
    while len(out) < rays:
        d = rng.normal(size=3)
        d /= np.sqrt(d @ d)
        a = np.sort(np.abs(d))
        if a[0] >= 0.1 and np.diff(a).min() >= 0.1:
            out.append(d)
    return np.array(out).reshape(-1, 3)


def shears(dirs):
    """axes (K, 3) int64 (kx, ky, kz: kz the largest component), shear (K, 3) float64
    (d[kx] / d[kz], d[ky] / d[kz], 1 / d[kz]) and inverse (K, 3) float64 (1 / d)."""
    kz = np.abs(dirs).argmax(axis=1)
    axes = np.stack([(kz + 1) % 3, (kz + 2) % 3, kz], axis=1).astype(np.int64)
    rows = np.arange(len(dirs))
    dz = dirs[rows, kz]
    shear = np.stack([dirs[rows, axes[:, 0]] / dz, dirs[rows, axes[:, 1]] / dz, 1.0 / dz], axis=1)
    return axes, np.ascontiguousarray(shear), np.ascontiguousarray(1.0 / dirs)


def parity_inside(tree, points, rays=3, dirs=None):
    """(n,) bool: whether most of ``rays`` rays from each of ``points`` (n, 3) float64
    cross the surface of ``tree`` an odd number of times. ``dirs`` (K, 3) replaces the
    fixed directions (for tests)."""
    points = distance.check_points(tree, points)
    if dirs is None:
        if not 1 <= rays <= 64:
            raise ValueError("rays: 1 to 64")
        dirs = directions(rays)
    axes, shear, inverse = shears(np.asarray(dirs, dtype=np.float64).reshape(-1, 3))
    pad = distance.tolerance(tree, points)
    inside = np.empty(len(points), dtype=bool)
    if _kernel is not None:
        for i in range(0, len(points), distance.CHUNK):
            # near points in turn: their rays walk the same nodes (the answers do not change)
            visit = i + distance.visit_order(points[i:i + distance.CHUNK])
            out = np.empty(len(visit), dtype=bool)
            _kernel.crossings(tree.triangles, tree.order, tree.thin, tree.lo, tree.hi, tree.leaf, points[visit], axes,
                              shear, inverse, pad, out, native.worker_count())
            inside[visit] = out
        return inside
    boxed = ((points >= tree.lo[0]) & (points <= tree.hi[0])).all(axis=1)
    inside[:] = False
    at = np.flatnonzero(boxed)
    for i in range(0, len(at), BLOCK):
        inside[at[i:i + BLOCK]] = _inside_numpy(tree, points[at[i:i + BLOCK]], axes, shear, inverse, pad)
    return inside


def side(e, ex, ey):
    """(m,) int8 sign of edge functions e, a zero taking the sign for a point moved by
    (eps^2, eps) along the edge direction (ex, ey): the kernel's side()"""
    tie = np.where(ex < 0, 1, np.where(ex > 0, -1, np.where(ey > 0, 1, np.where(ey < 0, -1, 0))))
    return np.where(e > 0, 1, np.where(e < 0, -1, tie)).astype(np.int8)


def crosses(tri, p, axes, shear):
    """(m,) bool: whether the ray from p (m, 3) along the sheared axis (axes (m, 3),
    shear (m, 3)) crosses triangle tri (m, 9) at a distance > 0: the kernel's crosses()"""
    rows = np.arange(len(p))[:, None]
    x, y, z = [], [], []
    for v in range(3):
        vert = tri[:, 3 * v:3 * v + 3]
        ax = vert[rows[:, 0], axes[:, 0]] - p[rows[:, 0], axes[:, 0]]
        ay = vert[rows[:, 0], axes[:, 1]] - p[rows[:, 0], axes[:, 1]]
        az = vert[rows[:, 0], axes[:, 2]] - p[rows[:, 0], axes[:, 2]]
        x.append(ax - shear[:, 0] * az)
        y.append(ay - shear[:, 1] * az)
        z.append(shear[:, 2] * az)
    u, v, w = x[2] * y[1] - y[2] * x[1], x[0] * y[2] - y[0] * x[2], x[1] * y[0] - y[1] * x[0]
    su, sv, sw = side(u, x[2] - x[1], y[2] - y[1]), side(v, x[0] - x[2], y[0] - y[2]), side(w, x[1] - x[0], y[1] - y[0])
    tt = u * z[0] + v * z[1] + w * z[2]
    return (su != 0) & (su == sv) & (su == sw) & np.where(su > 0, tt > 0, tt < 0)


def _ray_box(lo, hi, p, inverse, pad):
    """(m,) bool: whether rays from p meet the boxes grown by pad: the kernel's ray_box()"""
    a, b = (lo - pad - p) * inverse, (hi + pad - p) * inverse
    mn, mx = np.where(a < b, a, b), np.where(a < b, b, a)
    near = np.maximum(np.maximum(np.maximum(-np.inf, mn[:, 0]), mn[:, 1]), mn[:, 2])
    far = np.minimum(np.minimum(np.minimum(np.inf, mx[:, 0]), mx[:, 1]), mx[:, 2])
    return (near <= far) & (far >= 0) & (lo[:, 0] <= hi[:, 0])


def _inside_numpy(tree, points, axes, shear, inverse, pad):
    """parity_inside for one block: (point, ray, node) triples walked down the tree."""
    n, k = len(points), len(axes)
    query = np.arange(n * k)  # point query // k, ray query % k
    node = np.zeros(n * k, dtype=np.int64)
    leaves = (len(tree.lo) + 1) // 2
    keep = _ray_box(tree.lo[node], tree.hi[node], points[query // k], inverse[query % k], pad)
    query, node = query[keep], node[keep]
    while node.size and node[0] < leaves - 1:
        query, node = np.repeat(query, 2), (2 * np.repeat(node, 2) + 1) + np.tile([0, 1], len(node))
        keep = _ray_box(tree.lo[node], tree.hi[node], points[query // k], inverse[query % k], pad)
        query, node = query[keep], node[keep]
    slot = (((node - (leaves - 1)) * tree.leaf)[:, None] + np.arange(tree.leaf)).ravel()
    query = np.repeat(query, tree.leaf)
    keep = slot < tree.face_count
    query, slot = query[keep], slot[keep]
    ray = query % k
    hit = crosses(tree.triangles[slot], points[query // k], axes[ray], shear[ray])
    odd = np.bincount(query[hit], minlength=n * k) % 2
    return 2 * odd.reshape(n, k).sum(axis=1) > k
