"""Sharp edges of a triangle list: the edges whose two faces meet at an angle of at
least ``--sharp-angle`` degrees, and every boundary edge (one face) and non-manifold
edge (three faces or more).

Edges join faces that share two corner **positions** (equal coordinates, -0.0 and 0.0
alike), not two vertex numbers, so a file that repeats each corner per face (STL, a
split glTF) has the sharp edges of its welded twin; faces of zero or non-finite area
have no edges. An edge is named by its lowest corner slot ``s = 3 f + k``: the lowest
face ``f`` that has it, running from that face's corner ``k`` to its corner ``k + 1 mod
3``. So the edges, their order and their direction depend on the positions and the
face order only, never on how the vertices are numbered.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core import native
from ..core.elementary import atan2
from ..surface.topology import welded

SHARP_ANGLE = 15.0  # degrees: the default --sharp-angle
_kernel = native.kernel("_cedges")


@dataclass
class EdgeSlots:
    """The edges of a triangle list, in head order: head, second, count (E,) int64, each
    edge's lowest slot, its next one (-1 for a boundary edge) and how many it has; rest
    (R,) int64, the slots after the second of the edges with more (non-manifold ones),
    edge after edge, each edge's in slot order."""

    head: np.ndarray
    second: np.ndarray
    count: np.ndarray
    rest: np.ndarray

    def members(self, index):
        """For the edges ``index`` (k,) int64: [(k,) int64] their slots after the second,
        one array per step (-1 where an edge has no more)."""
        offsets = np.cumsum(np.maximum(self.count - 2, 0)) - np.maximum(self.count - 2, 0)
        extra = np.maximum(self.count[index] - 2, 0)
        return [np.where(extra > step, self.rest[np.minimum(offsets[index] + step, max(len(self.rest) - 1, 0))], -1)
                for step in range(int(extra.max(initial=0)))]


def edge_slots(vertices, faces, valid, normals=None, limit=np.inf) -> EdgeSlots:
    """The :class:`EdgeSlots` of the ``valid`` (F,) bool faces of ``faces`` (F, 3) int64
    over ``vertices`` (V, 3) float64, by corner position; but for the pairs of faces whose
    unit ``normals`` (F, 3) float64 have a dot product of ``limit`` or more (flat enough
    not to be sharp: most edges of a mesh)."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    valid = np.ascontiguousarray(valid, dtype=bool)
    normals = np.zeros((len(faces), 3)) if normals is None else np.ascontiguousarray(normals, dtype=np.float64)
    if _kernel is None:
        return _numpy_edge_slots(np.asarray(vertices, dtype=np.float64), faces, valid, normals, limit)
    out = [np.empty(3 * len(faces), np.int64) for _ in range(4)]
    edges, rests = _kernel.edges(np.ascontiguousarray(vertices, dtype=np.float64), faces, valid, normals,
                                 float(limit), native.worker_count(), *out)
    head, second, count, rest = out
    return EdgeSlots(head[:edges], second[:edges], count[:edges], rest[:rests])


def _numpy_edge_slots(vertices, faces, valid, normals, limit):
    """:func:`edge_slots` with NumPy: the same arrays as the kernel."""
    good = np.flatnonzero(valid)
    empty = np.empty(0, np.int64)
    if not len(good):
        return EdgeSlots(empty, empty, empty, empty)
    position = welded(vertices, faces[good])  # numbers of distinct positions
    a, b = position.reshape(-1), position[:, [1, 2, 0]].reshape(-1)
    slot = (3 * good[:, None] + np.arange(3)).reshape(-1)
    edge = a != b
    a, b, slot = a[edge], b[edge], slot[edge]
    if not len(slot):
        return EdgeSlots(empty, empty, empty, empty)
    key = np.minimum(a, b) * (int(position.max()) + 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")  # within an edge, its slots stay in slot order
    key, slot = key[order], slot[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    count = np.diff(np.r_[start, len(slot)])
    second = np.where(count > 1, slot[np.minimum(start + 1, len(slot) - 1)], -1)
    f1, f2 = slot[start] // 3, second // 3
    cols = [np.ascontiguousarray(normals[:, c]) for c in range(3)]
    dot = cols[0][f1] * cols[0][f2] + cols[1][f1] * cols[1][f2] + cols[2][f1] * cols[2][f2]
    keep = np.flatnonzero((count != 2) | ~(dot >= limit))
    keep = keep[np.argsort(slot[start[keep]], kind="stable")]
    start, count, second = start[keep], count[keep], second[keep]
    rest = [slot[s + 2 : s + c] for s, c in zip(start[count > 2].tolist(), count[count > 2].tolist())]
    return EdgeSlots(slot[start], second, count, np.concatenate(rest) if rest else empty)


@dataclass
class SharpEdges:
    """The sharp edges of one triangle list, in slot order.

    slot: (E,) int64 the lowest corner slot of each edge (face ``slot // 3``, from its
    corner ``slot % 3`` to the next); kind: (E,) int8, 1 boundary, 2 two faces at the
    angle or more, 3 non-manifold; angle: (E,) float64 degrees between the two faces'
    normals (NaN unless kind 2); normal: (E, 3) float64 the normalized sum of the unit
    normals of the edge's faces, or the lowest face's where that sum is zero.
    """

    slot: np.ndarray
    kind: np.ndarray
    angle: np.ndarray
    normal: np.ndarray

    @property
    def face(self):
        return self.slot // 3

    @property
    def corner(self):
        return self.slot % 3

    def __len__(self):
        return len(self.slot)

    def ends(self, vertices, faces):
        """(a, b): the (E, 3) float64 positions each edge runs from and to."""
        f, k = self.face, self.corner
        return vertices[faces[f, k]], vertices[faces[f, (k + 1) % 3]]


def sharp_edges(vertices, faces, normals, angle: float = SHARP_ANGLE) -> SharpEdges:
    """The :class:`SharpEdges` of a triangle list, vertices (V, 3) float64 and faces (F, 3)
    int64, at ``angle`` degrees, from its unit face normals (F, 3) float64 (zero where a
    face has no area or a non-finite corner; in the frame the angle is measured in)."""
    # Most pairs of faces are far from the angle: their dot product settles them and
    # they are never listed; the others get the angle itself (the dot product's margin is
    # far beyond its rounding).
    limit = math.cos(math.radians(angle)) + 1e-6
    valid = (normals[:, 0] != 0) | (normals[:, 1] != 0) | (normals[:, 2] != 0)  # (np.any on axis 1 is slower)
    edges = edge_slots(vertices, faces, valid, normals, limit)
    kind = np.where(edges.count == 1, 1, np.where(edges.count == 2, 2, 3)).astype(np.int8)
    two = np.flatnonzero(kind == 2)
    degrees = np.full(len(edges.head), np.nan)
    degrees[two] = angle_between(normals[edges.head[two] // 3], normals[edges.second[two] // 3])
    sharp = np.flatnonzero((kind != 2) | (degrees >= angle))
    return SharpEdges(edges.head[sharp], kind[sharp], degrees[sharp], edge_normals(edges, sharp, normals))


def angle_between(n1, n2):
    """(m,) float64 degrees between unit vectors (m, 3) (atan2 of the cross product's
    length and the dot product: accurate for small angles and for angles near 180)."""
    cross = np.cross(n1, n2)
    sine = np.sqrt(np.einsum("ij,ij->i", cross, cross))
    return np.degrees(atan2(sine, np.einsum("ij,ij->i", n1, n2)))


def edge_normals(edges: EdgeSlots, index, normals):
    """(k, 3) float64: for the edges ``index`` (k,), the normalized sum of the unit normals
    of all their faces, or the lowest face's normal where the sum is zero (a fin: two
    faces back to back)."""
    lowest = normals[edges.head[index] // 3]
    total = lowest.copy()
    for slot in [edges.second[index], *edges.members(index)]:
        on = np.flatnonzero(slot >= 0)
        total[on] += normals[slot[on] // 3]
    length = np.sqrt(np.einsum("ij,ij->i", total, total))
    flat = length <= 1e-9
    with np.errstate(invalid="ignore", divide="ignore"):
        total /= length[:, None]
    total[flat] = lowest[flat]
    return total


def is_similarity(matrix, tolerance=1e-9) -> bool:
    """Whether the (4, 4) ``matrix`` (or None) keeps angles: a rotation, mirror,
    uniform scale and translation (A^T A = s^2 I, within ``tolerance`` of s^2)."""
    if matrix is None:
        return True
    a = np.asarray(matrix, dtype=np.float64)[:3, :3]
    g = a.T @ a
    s2 = float(np.trace(g)) / 3.0
    return s2 > 0 and math.isfinite(s2) and float(np.abs(g - s2 * np.eye(3)).max()) <= tolerance * s2
