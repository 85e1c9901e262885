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
from ..surface.topology import welded

SHARP_ANGLE = 15.0  # degrees: the default --sharp-angle
_kernel = native.kernel("_cedges")


def edge_links(vertices, faces, valid):
    """(first, next), each (3 F,) int64: for the corner slots of the ``valid`` (F,) bool
    faces of ``faces`` (F, 3) int64 over ``vertices`` (V, 3) float64, ``first[s]`` is
    the lowest slot of the edge of slot ``s`` (by position) and ``next[s]`` the next
    slot of that edge in slot order, -1 after its last; -1 and -1 for other slots."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    valid = np.ascontiguousarray(valid, dtype=bool)
    if _kernel is None:
        return _numpy_links(np.asarray(vertices, dtype=np.float64), faces, valid)
    first, nxt = np.empty(3 * len(faces), np.int64), np.empty(3 * len(faces), np.int64)
    _kernel.links(np.ascontiguousarray(vertices, dtype=np.float64), faces, valid, first, nxt)
    return first, nxt


def _numpy_links(vertices, faces, valid):
    """:func:`edge_links` with NumPy: the same arrays as the kernel."""
    first, nxt = np.full(3 * len(faces), -1, np.int64), np.full(3 * len(faces), -1, np.int64)
    good = np.flatnonzero(valid)
    if not len(good):
        return first, nxt
    position = welded(vertices, faces[good])  # numbers of distinct positions
    a, b = position.reshape(-1), position[:, [1, 2, 0]].reshape(-1)
    slot = (3 * good[:, None] + np.arange(3)).reshape(-1)
    edge = a != b
    a, b, slot = a[edge], b[edge], slot[edge]
    if not len(slot):
        return first, nxt
    key = np.minimum(a, b) * (int(position.max()) + 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")  # within an edge, its slots stay in slot order
    key, slot = key[order], slot[order]
    starts = np.r_[True, key[1:] != key[:-1]]
    first[slot] = slot[np.flatnonzero(starts)][np.cumsum(starts) - 1]
    follows = np.flatnonzero(~starts[1:])  # row i + 1 is on the same edge as row i
    nxt[slot[follows]] = slot[follows + 1]
    return first, nxt


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


def sharp_edges(links, normals, angle: float = SHARP_ANGLE) -> SharpEdges:
    """The :class:`SharpEdges` of a triangle list from its :func:`edge_links` and its
    unit face normals (F, 3) float64 (in the frame the angle is measured in)."""
    first, nxt = links
    head = np.flatnonzero(first == np.arange(len(first)))
    second = nxt[head]
    third = np.where(second >= 0, nxt[np.maximum(second, 0)], -1)
    kind = np.where(second < 0, 1, np.where(third < 0, 2, 3)).astype(np.int8)
    two = np.flatnonzero(kind == 2)
    # Most pairs are far from the angle: their dot product settles them; the rest get
    # the angle itself (the dot product's margin is far beyond its rounding).
    cols = [np.ascontiguousarray(normals[:, c]) for c in range(3)]
    f1, f2 = head[two] // 3, second[two] // 3
    dot = sum(np.take(col, f1) * np.take(col, f2) for col in cols)
    near = np.flatnonzero(dot < math.cos(math.radians(angle)) + 1e-6)
    degrees = np.full(len(head), np.nan)
    degrees[two[near]] = angle_between(normals[f1[near]], normals[f2[near]])
    sharp = np.flatnonzero((kind != 2) | (degrees >= angle))
    head, kind, degrees = head[sharp], kind[sharp], degrees[sharp]
    return SharpEdges(head, kind, degrees, edge_normals(head, nxt, normals))


def angle_between(n1, n2):
    """(m,) float64 degrees between unit vectors (m, 3) (atan2 of the cross product's
    length and the dot product: accurate for small angles and for angles near 180)."""
    cross = np.cross(n1, n2)
    sine = np.sqrt(np.einsum("ij,ij->i", cross, cross))
    return np.degrees(np.arctan2(sine, np.einsum("ij,ij->i", n1, n2)))


def edge_normals(head, nxt, normals):
    """(E, 3) float64: for each edge (its lowest slot ``head``), the normalized sum of the
    unit normals of all its faces (following ``nxt``), or the lowest face's normal where
    the sum is zero (a fin: two faces back to back)."""
    lowest = normals[head // 3]
    total = lowest.copy()
    slot = nxt[head]
    while True:
        on = np.flatnonzero(slot >= 0)
        if not len(on):
            break
        total[on] += normals[slot[on] // 3]
        slot = np.where(slot >= 0, nxt[np.maximum(slot, 0)], -1)
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
