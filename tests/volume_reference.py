"""Brute-force references for volume labels, O(points x faces), written apart from the
kernels they check: the exact winding number as a sum of solid angles, and the exact
point-triangle distance as the least of the in-plane projection and the three edges."""

import numpy as np


def solid_angle_winding(triangles, points, block=128):
    """(n,) float64: sum over triangles (T, 3, 3) of the signed solid angle / 4 pi."""
    out = np.empty(len(points))
    for s in range(0, len(points), block):
        p = points[s : s + block, None, :]
        a, b, c = (triangles[None, :, k] - p for k in range(3))
        la, lb, lc = (np.sqrt((x * x).sum(-1)) for x in (a, b, c))
        det = (a * np.cross(b, c)).sum(-1)
        den = la * lb * lc + (a * b).sum(-1) * lc + (b * c).sum(-1) * la + (c * a).sum(-1) * lb
        out[s : s + block] = 2.0 * np.arctan2(det, den).sum(axis=1) / (4.0 * np.pi)
    return out


def _segment_distance(p, a, b):
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300), 0.0, 1.0)
    return np.sqrt(((a + t[..., None] * ab - p) ** 2).sum(-1))


def triangle_distance(points, triangles):
    """Distance from points (..., 3) to triangles (..., 3, 3), broadcast against each
    other: (...) float64."""
    a, b, c = triangles[..., 0, :], triangles[..., 1, :], triangles[..., 2, :]
    n = np.cross(b - a, c - a)
    n /= np.sqrt((n * n).sum(-1))[..., None]
    h = ((points - a) * n).sum(-1)
    q = points - h[..., None] * n
    # inside the triangle when q is on the inner side of all three edges
    inside = np.ones(h.shape, dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= (np.cross(v - u, q - u) * n).sum(-1) >= 0
    edges = np.minimum(np.minimum(_segment_distance(points, a, b), _segment_distance(points, b, c)),
                       _segment_distance(points, c, a))
    return np.where(inside, np.abs(h), edges)


def exact_distance(triangles, points, block=128):
    """(n,) float64 distance from each point to the nearest triangle, and (n,) its index
    (the lowest among ties within 1e-12 of the distance)."""
    dist = np.empty(len(points))
    face = np.empty(len(points), dtype=np.int64)
    for s in range(0, len(points), block):
        d = triangle_distance(points[s : s + block, None, :], triangles)
        best = d.min(axis=1)
        dist[s : s + block] = best
        face[s : s + block] = (d <= best[:, None] * (1 + 1e-12) + 1e-300).argmax(axis=1)
    return dist, face
