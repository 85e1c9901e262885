"""STAND-IN (brute force) until the winding kernel lands."""
import numpy as np


class WindingTree:
    def __init__(self, triangles):
        self.triangles = np.ascontiguousarray(triangles, dtype=np.float64)


def winding_numbers(tree, points):
    t = tree.triangles
    out = np.empty(len(points))
    for s in range(0, len(points), 256):
        p = points[s:s + 256][:, None, :]
        a, b, c = t[None, :, 0] - p, t[None, :, 1] - p, t[None, :, 2] - p
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        det = (a * np.cross(b, c)).sum(-1)
        den = la * lb * lc + (a * b).sum(-1) * lc + (b * c).sum(-1) * la + (c * a).sum(-1) * lb
        out[s:s + 256] = np.arctan2(det, den).sum(axis=1) / (2 * np.pi)
    return out
