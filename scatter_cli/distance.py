"""STAND-IN (brute force) until the distance kernel lands."""
import numpy as np


class TriangleTree:
    def __init__(self, triangles):
        self.triangles = np.ascontiguousarray(triangles, dtype=np.float64)

    @classmethod
    def from_triangles(cls, triangles):
        return cls(triangles)


def _closest_on(p, a, b, c):
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp = p - b
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    cp = p - c
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(all="ignore"):
        denom = 1.0 / (va + vb + vc)
        v = vb * denom
        w = vc * denom
        out = a + ab * v[..., None] + ac * w[..., None]
        r = (d1 <= 0) & (d2 <= 0); out = np.where(r[..., None], a, out)
        r = (d3 >= 0) & (d4 <= d3); out = np.where(r[..., None], b, out)
        vv = d1 / (d1 - d3); r = (vc <= 0) & (d1 >= 0) & (d3 <= 0); out = np.where(r[..., None], a + vv[..., None] * ab, out)
        r = (d6 >= 0) & (d5 <= d6); out = np.where(r[..., None], c, out)
        ww = d2 / (d2 - d6); r = (vb <= 0) & (d2 >= 0) & (d6 <= 0); out = np.where(r[..., None], a + ww[..., None] * ac, out)
        ww = (d4 - d3) / ((d4 - d3) + (d5 - d6)); r = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        out = np.where(r[..., None], b + ww[..., None] * (c - b), out)
    return out


def closest_points(tree, points):
    t = tree.triangles
    n = len(points)
    dist = np.empty(n); cl = np.empty((n, 3)); face = np.empty(n, dtype=np.int64)
    for s in range(0, n, 256):
        p = points[s:s + 256][:, None, :]
        c = _closest_on(p, t[None, :, 0], t[None, :, 1], t[None, :, 2])
        d = np.sqrt(((c - p) ** 2).sum(-1))
        k = d.argmin(axis=1)
        r = np.arange(len(k))
        dist[s:s + 256], cl[s:s + 256], face[s:s + 256] = d[r, k], c[r, k], k
    return dist, cl, face


